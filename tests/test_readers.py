"""Take readers: hand-checked values, real CMU files, every ReaderError path, CRLF, npz."""

from __future__ import annotations

import math
import re
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.core import quat as Q
from rtseg.drivers.readers import ReaderError, read_take, write_take
from rtseg.drivers.readers.amc import read_amc, read_asf
from rtseg.drivers.readers.bvh import read_bvh
from rtseg.drivers.readers.npz_take import read_npz, write_npz
from rtseg.core.take import Take

S = math.sqrt(0.5)

# ---------------------------------------------------------------------------------------
# Tiny hand-written ASF/AMC.  Bone "a": axis rotated 90° about z, dof rx.  Bone "b" (child
# of a): plain axis, dof rx ry rz.  Bone "c": no dof.
ASF = """# tiny test skeleton
:version 1.10
:name TEST
:units
  mass 1.0
  length 0.45
  angle deg
:documentation
  free text: is ignored
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name a
     direction 0 1 0
     length 2.0
     axis 0 0 90 XYZ
     dof rx
     limits (-180.0 180.0)
  end
  begin
     id 2
     name b
     direction 1 0 0
     length 1.0
     axis 0 0 0 XYZ
     dof rx ry rz
     limits (-10.0 10.0)
            (-20.0 20.0)
            (-inf inf)
  end
  begin
     id 3
     name c
     direction 0 0 1
     length 0.5
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root a
    a b c
  end
"""

AMC = """# made by hand
:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0 0 90
a 90
b 90 0 90
2
root 4 5 6 0 0 0
a 0
b 0 0 0
"""


def _write(tmp_path: Path, name: str, text: str, crlf: bool = False) -> Path:
    p = tmp_path / name
    p.write_bytes((text.replace("\n", "\r\n") if crlf else text).encode())
    return p


@pytest.fixture
def tiny(tmp_path: Path) -> tuple[Path, Path]:
    return _write(tmp_path, "T.asf", ASF), _write(tmp_path, "T_01.amc", AMC)


def test_tiny_asf_amc_hand_checked(tiny):
    asf, amc = tiny
    take = read_take(amc)  # finds T.asf beside T_01.amc
    assert take.joint_names == ["root", "a", "b", "c"]
    assert take.parents == [-1, 0, 1, 1]
    assert take.space == "local" and take.frame_rate == 120.0
    q = take.quats
    # root: rz = 90 -> rotation of 90° about z.
    np.testing.assert_allclose(q[0, 0], [0, 0, S, S], atol=1e-12)
    # a: M = Rx(90) in an axis frame C = Rz(90): C·M·C⁻¹ is 90° about C·x = +y.
    np.testing.assert_allclose(q[0, 1], [0, S, 0, S], atol=1e-12)
    # b: M = Rz(90)·Rx(90) -> (0,0,s,c) ⊗ (s,0,0,c) = (.5, .5, .5, .5)  (Rx·Rz would give y = -.5)
    np.testing.assert_allclose(q[0, 2], [0.5, 0.5, 0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose(q[:, 3], [[0, 0, 0, 1]] * 2, atol=0)  # no dofs: identity
    np.testing.assert_allclose(q[1], [[0, 0, 0, 1]] * 4, atol=1e-12)
    np.testing.assert_allclose(take.root_position, [[1, 2, 3], [4, 5, 6]])
    assert take.meta["first_frame_number"] == 1
    assert take.meta["metres_per_unit"] == pytest.approx(0.0254 / 0.45)
    np.testing.assert_allclose(take.meta["bone_offsets"][1], [0, 2, 0])
    sk = read_asf(asf)
    assert sk.bones["b"].limits == [(-10.0, 10.0), (-20.0, 20.0), (-math.inf, math.inf)]
    assert sk.bones["a"].dof == ["rx"] and sk.angle_unit == "deg"


def test_radians_root_order_and_frame_rate_override(tmp_path):
    asf = ASF.replace("angle deg", "angle rad").replace("axis 0 0 90 XYZ", f"axis 0 0 {math.pi / 2} XYZ")
    asf = asf.replace("order TX TY TZ RX RY RZ", "order RZ RY RX TZ TY TX")
    amc = (":FULLY-SPECIFIED\n:RADIANS\n7\n"
           f"root {math.pi / 2} 0 0 3 2 1\na {math.pi / 2}\nb {math.pi / 2} 0 {math.pi / 2}\n")
    a = _write(tmp_path, "R.asf", asf)
    m = _write(tmp_path, "R_02.amc", amc)
    take = read_amc(m, a, frame_rate=60.0)
    assert take.frame_rate == 60.0
    np.testing.assert_allclose(take.quats[0, 0], [0, 0, S, S], atol=1e-12)  # rz first column
    np.testing.assert_allclose(take.quats[0, 1], [0, S, 0, S], atol=1e-12)
    np.testing.assert_allclose(take.quats[0, 2], [0.5, 0.5, 0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose(take.root_position, [[1, 2, 3]])
    assert take.meta["first_frame_number"] == 7


def test_symlinked_amc_finds_its_skeleton_beside_the_link_else_beside_the_target(tmp_path):
    """A folder of links to AMC takes (an archive laid out with symlinks) without their
    ASF: the skeleton beside the file linked to is used; one beside the link wins."""
    data = tmp_path / "data"
    data.mkdir()
    _write(data, "T.asf", ASF)
    _write(data, "T_01.amc", AMC)
    lay = tmp_path / "lay"
    lay.mkdir()
    (lay / "my take.amc").symlink_to(data / "T_01.amc")
    assert read_take(lay / "my take.amc").n_frames == 2
    from rtseg.drivers.readers.amc import skeleton_for
    assert skeleton_for(lay / "my take.amc") == data / "T.asf"
    _write(lay, "my take.asf", ASF)
    assert skeleton_for(lay / "my take.amc") == lay / "my take.asf"
    (tmp_path / "plain").mkdir()
    with pytest.raises(ReaderError, match="no skeleton given"):
        skeleton_for(_write(tmp_path / "plain", "T_01.amc", AMC))


def test_amc_degrees_header_overrides_asf_radians(tmp_path):
    asf = ASF.replace("angle deg", "angle rad").replace("axis 0 0 90 XYZ", f"axis 0 0 {math.pi / 2} XYZ")
    take = read_amc(_write(tmp_path, "T_01.amc", AMC), _write(tmp_path, "T.asf", asf))
    np.testing.assert_allclose(take.quats[0, 1], [0, S, 0, S], atol=1e-12)


def test_crlf_files_read_the_same(tmp_path, tiny):
    ref = read_take(tiny[1])
    d = tmp_path / "crlf"
    d.mkdir()
    _write(d, "T.asf", ASF, crlf=True)
    take = read_take(_write(d, "T_01.amc", AMC, crlf=True))
    np.testing.assert_array_equal(take.quats, ref.quats)
    np.testing.assert_array_equal(take.root_position, ref.root_position)


# Every ASF error path: (replace this, with that) -> message fragment and line number.
ASF_ERRORS = [
    ("     dof rx\n", "     dof rx qq\n", "unknown dof 'qq'", 22),
    ("    a b c\n", "    a b zz\n", "unknown bone 'zz' in hierarchy", 46),
    ("    root a\n", "    nobody a\n", "unknown bone 'nobody' in hierarchy", 45),
    ("     length 2.0\n", "     length two\n", "'two' is not a number", 20),
    ("     length 2.0\n", "     length inf\n", "length: 'inf' is not a finite number", 20),
    ("     id 3\n", "     id nan\n", "id: 'nan' is not a finite number", 37),
    ("     direction 1 0 0\n", "     direction 1 0\n", "direction needs 3 numbers", 28),
    ("     axis 0 0 90 XYZ\n", "     axis 0 0 90 XYQ\n", "axis order", 21),
    ("  angle deg\n", "  angle grad\n", "angle unit", 7),
    ("     limits (-180.0 180.0)\n", "     limits (-180.0 180.0) (1 2)\n", "limits must be 1 pairs", 23),
    ("            (-inf inf)\n", "            (-inf nope)\n", "non-numeric limit", 32),
    ("     name b\n", "     name a\n", "bone name 'a' used twice", 35),
    ("     id 3\n", "     id 3\n     colour red\n", "unknown bone field 'colour'", 38),
    (":root\n", ":rooot\n", "unknown section ':rooot'", 10),
    ("   order TX TY TZ RX RY RZ\n", "   order TX TY TZ RX RY RW\n", "root order", 11),
    ("    a b c\n", "    a b c\n    root c\n", "second parent", 47),
]


@pytest.mark.parametrize("old,new,fragment,line", ASF_ERRORS)
def test_asf_errors_name_file_line_problem(tmp_path, old, new, fragment, line):
    assert old in ASF
    p = _write(tmp_path, "bad.asf", ASF.replace(old, new, 1))
    with pytest.raises(ReaderError) as ei:
        read_asf(p)
    msg = str(ei.value)
    assert fragment in msg
    assert msg.startswith(f"{p}:{line}:"), msg
    assert ei.value.line == line and isinstance(ei.value, ValueError)


@pytest.mark.parametrize("old,new,fragment", [
    (":hierarchy\n  begin\n    root a\n    a b c\n  end\n", "", "no :hierarchy section"),
    ("    a b c\n", "    a b\n", "bone 'c' has no parent"),
    (":root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n   orientation 0 0 0\n", "",
     "no :root section"),
    ("     dof rx ry rz\n", "     dof rx ry rz\n", None),  # control: unchanged file reads
])
def test_asf_whole_file_errors(tmp_path, old, new, fragment):
    p = _write(tmp_path, "bad.asf", ASF.replace(old, new, 1))
    if fragment is None:
        assert read_asf(p).bones["b"].dof == ["rx", "ry", "rz"]
        return
    with pytest.raises(ReaderError, match=re.escape(fragment)) as ei:
        read_asf(p)
    assert str(p) in str(ei.value)


AMC_ERRORS = [
    ("a 90\n", "a 90 1\n", "bone 'a' has 2 values, expected 1 (rx)", 6),
    ("b 90 0 90\n", "b 90 zero 90\n", "value 'zero' is not a number", 7),
    ("b 0 0 0\n", "q 0 0 0\n", "unknown bone 'q'", 11),
    ("2\n", "3\n", "frame number 3 out of order (previous frame 1, expected 2)", 8),
    ("b 90 0 90\n", "b 90 0 90\nb 1 2 3\n", "bone 'b' given twice in frame 1", 8),
    ("b 90 0 90\n2\n", "2\n", "frame 1 (line 4) has no line for bone 'b'", 7),
    (":DEGREES\n1\n", "1\n:DEGREES\n", "header keyword ':DEGREES' after motion data", 4),
    (":DEGREES\n", ":DEGREES\nroot 1 2 3 0 0 0\n", "bone line before the first frame number", 4),
    (":DEGREES\n", ":DEGREES\nhello\n", "unexpected text before the first frame number", 4),
    (":DEGREES\n", ":GRADIANS\n", "unknown header keyword ':GRADIANS'", 3),
    ("1\nroot", "1 extra\nroot", "frame number line has extra text", 4),
    ("a 0\n", "a nan\n", "non-finite value in frame 2", 8),
]


@pytest.mark.parametrize("old,new,fragment,line", AMC_ERRORS)
def test_amc_errors_name_file_line_problem(tmp_path, old, new, fragment, line):
    assert old in AMC
    asf = _write(tmp_path, "T.asf", ASF)
    p = _write(tmp_path, "T_09.amc", AMC.replace(old, new, 1))
    with pytest.raises(ReaderError) as ei:
        read_amc(p, asf)
    msg = str(ei.value)
    assert fragment in msg, msg
    assert msg.startswith(f"{p}:{line}:"), msg


AMC3 = AMC + "3\nroot 7 8 9 0 0 0\na 10\nb 1 2 3\n"


@pytest.mark.parametrize("cut, line, problem", [
    ("3\nroot 7 8 9 0 0 0\na 10\nb 1 2", 15, "bone 'b' has 2 values, expected 3"),
    # a value cut short that still parses: the frame is short of bone b
    ("3\nroot 7 8 9 0 0 0\na 1", 14, "frame 3 (line 12) has no line for bone 'b'"),
    ("3\nroot 7 8 9 0 0 0\na 10\nb 1 2 3e", 15, "value '3e' is not a number"),
    ("3\nroot 7 8 9 0 0 0\n", 13, "frame 3 (line 12) has no line for bone 'a'"),
    ("3\nroot 7 8 9 0 0 0\na 10\nb", 15, "bone 'b' has 0 values"),
    ("3\nroot 7 8 9 0 0 0\na 10\nlfe", 15, "unknown bone 'lfe'"),
    ("3\n", 12, "frame 3 (line 12) has no line for bone 'root'"),
])
def test_truncated_amc_reads_the_whole_frames_and_warns_with_the_line(
        tmp_path, caplog, cut, line, problem):
    """A file cut short - inside the last frame's last line (no line break after it) or
    after a whole line - gives the frames before that frame, with one warning naming the
    line and the problem; the same wrong line followed by a line break, or followed by
    more frames, is still an error."""
    asf = _write(tmp_path, "T.asf", ASF)
    whole = read_amc(_write(tmp_path, "T_01.amc", AMC3), asf)
    p = _write(tmp_path, "T_09.amc", AMC + cut)
    with caplog.at_level("WARNING", logger="rtseg.readers"):
        take = read_amc(p, asf)
    assert take.n_frames == 2 and np.array_equal(take.quats, whole.quats[:2])
    assert take.meta["truncated"] == {"line": line, "frame": 3,
                                      "problem": take.meta["truncated"]["problem"]}
    assert problem in take.meta["truncated"]["problem"]
    msgs = [r.getMessage() for r in caplog.records]
    assert len(msgs) == 1 and msgs[0].startswith(f"{p}:{line}: the file ends inside frame 3")
    assert "read the 2 whole frames before it" in msgs[0]
    if not cut.endswith("\n") and "has no line" not in problem:
        # the same line ended by a line break is a whole line: wrong, not cut short
        with pytest.raises(ReaderError, match=re.escape(problem)):
            read_amc(_write(tmp_path, "T_10.amc", AMC + cut + "\n"), asf)
        with pytest.raises(ReaderError, match=re.escape(problem)):
            read_amc(_write(tmp_path, "T_11.amc", AMC + cut + "\n4\n"), asf)


@pytest.mark.realdata
def test_real_truncated_86_01_keeps_its_whole_frames(data_dir, tmp_path, caplog):
    """86_01.amc cut at 2 000 000 bytes (inside frame 2608): its 2607 whole frames are
    read, equal to the full file's first 2607, with a warning naming line 78222."""
    full = read_amc(data_dir / "cmu" / "86_01.amc", data_dir / "cmu" / "86.asf")
    cut = tmp_path / "86_01.amc"
    cut.write_bytes((data_dir / "cmu" / "86_01.amc").read_bytes()[:2_000_000])
    with caplog.at_level("WARNING", logger="rtseg.readers"):
        take = read_amc(cut, data_dir / "cmu" / "86.asf")
    assert take.n_frames == 2607
    assert np.array_equal(take.quats, full.quats[:2607])
    assert any(f"{cut}:78222: the file ends inside frame 2608" in r.getMessage()
               for r in caplog.records)


def test_amc_missing_skeleton_and_other_file_errors(tmp_path):
    amc = _write(tmp_path, "77_01.amc", AMC)
    with pytest.raises(ReaderError, match=r"no skeleton given and none found beside it "
                       r"\(looked for 77\.asf, 77_01\.asf\)$"):   # each name once
        read_take(amc)
    asf = _write(tmp_path, "T.asf", ASF)
    with pytest.raises(ReaderError, match="skeleton without motion"):
        read_take(asf)
    with pytest.raises(ReaderError, match="no motion frames"):
        read_amc(_write(tmp_path, "e.amc", ":FULLY-SPECIFIED\n:DEGREES\n"), asf)
    with pytest.raises(ReaderError, match="file not found"):
        read_amc(tmp_path / "absent.amc", asf)
    with pytest.raises(ReaderError, match="unknown take format '.xyz'"):
        read_take(_write(tmp_path, "x.xyz", "nothing"))
    # a BVH given as the skeleton is named for what it is
    bvh = _write(tmp_path, "86_01.bvh", "HIERARCHY\nROOT Hips\n{\n}\nMOTION\n")
    with pytest.raises(ReaderError, match=r"86_01\.bvh:1: is a BVH file \(it starts with "
                       r"HIERARCHY\), not an ASF skeleton: an \.amc take needs its Acclaim "
                       r"\.asf"):
        read_take(amc, skeleton=bvh)
    # Explicit skeleton beats the missing neighbour.
    assert read_take(amc, skeleton=asf).n_frames == 2


# ---------------------------------------------------------------------------------------
# Real CMU data.

def _amc_frame_values(amc: Path, frame: int) -> dict[str, list[float]]:
    """Independent mini-parser: the lines of one frame."""
    out: dict[str, list[float]] = {}
    inside = False
    for line in amc.read_text().splitlines():
        t = line.split()
        if not t or t[0].startswith(("#", ":")):
            continue
        if t[0].isdigit():
            if inside:
                break
            inside = int(t[0]) == frame
            continue
        if inside:
            out[t[0]] = [float(v) for v in t[1:]]
    return out


def _asf_axes(asf: Path) -> dict[str, tuple[list[float], list[str]]]:
    text = asf.read_text()
    out = {}
    for block in re.findall(r"begin(.*?)end", text.split(":bonedata")[1].split(":hierarchy")[0], re.S):
        name = re.search(r"name\s+(\S+)", block).group(1)
        axis = [float(v) for v in re.search(r"axis\s+(\S+)\s+(\S+)\s+(\S+)", block).groups()]
        dof = re.search(r"dof\s+([^\n]+)", block)
        out[name] = (axis, dof.group(1).split() if dof else [])
    return out


@pytest.mark.realdata
def test_real_86_01_frame1_matches_scipy_matrices(data_dir):
    amc = data_dir / "cmu" / "86_01.amc"
    take = read_take(amc)
    assert take.n_frames == 4579 and take.n_joints == 31
    values = _amc_frame_values(amc, 1)
    axes = _asf_axes(data_dir / "cmu" / "86.asf")
    checked = 0
    for name, (axis, dof) in axes.items():
        # Acclaim: C = Rz·Ry·Rx of the axis, M = Rz·Ry·Rx of the dofs (scipy extrinsic 'xyz').
        C = Rotation.from_euler("xyz", axis, degrees=True).as_matrix()
        angles = dict(zip(dof, values.get(name, [])))
        M = Rotation.from_euler("xyz", [angles.get(k, 0.0) for k in ("rx", "ry", "rz")],
                                degrees=True).as_matrix()
        expected = C @ M @ C.T
        got = Rotation.from_quat(take.quats[0, take.joint_index(name)]).as_matrix()
        np.testing.assert_allclose(got, expected, atol=1e-12, err_msg=name)
        checked += 1
    assert checked == 30
    root = values["root"]
    np.testing.assert_allclose(take.root_position[0], root[:3])
    np.testing.assert_allclose(Rotation.from_quat(take.quats[0, 0]).as_matrix(),
                               Rotation.from_euler("xyz", root[3:], degrees=True).as_matrix(), atol=1e-12)


@pytest.mark.realdata
def test_real_86_01_forward_kinematics_is_a_standing_person(data_dir):
    """World orientations chained from L = C·M·C⁻¹ put the head 1.5-1.9 m above the toes."""
    take = read_take(data_dir / "cmu" / "86_01.amc")
    g = Q.global_from_local(take.quats[:1], take.parents)[0]
    off = take.meta["bone_offsets"]
    pos = np.zeros((take.n_joints, 3))
    for j, p in enumerate(take.parents):
        pos[j] = take.root_position[0] if p < 0 else pos[p] + Rotation.from_quat(g[j]).apply(off[j])
    m = take.meta["metres_per_unit"]
    height = (pos[take.joint_index("head"), 1] - min(pos[take.joint_index("ltoes"), 1],
                                                     pos[take.joint_index("rtoes"), 1])) * m
    assert 1.5 < height < 1.9


@pytest.mark.realdata
def test_real_crlf_subject_13(data_dir):
    assert b"\r\n" in (data_dir / "cmu" / "13.asf").read_bytes()[:200]
    take = read_take(data_dir / "cmu" / "13_31.amc")
    assert take.n_frames == 3017
    assert np.all(np.isfinite(take.quats))
    np.testing.assert_allclose(np.linalg.norm(take.quats, axis=-1), 1.0, atol=1e-12)


# ---------------------------------------------------------------------------------------
# BVH

BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Yrotation Xposition Yposition Zposition Xrotation Zrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 5 0
      CHANNELS 3 Xposition Yposition Zposition
      End Site
      {
        OFFSET 0 2 0
      }
    }
  }
  JOINT Leg {
    OFFSET 1 0 0
    CHANNELS 1 Xrotation
    End Site { OFFSET 0 -4 0 }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
90 1 2 3 0 0   90 90 0   7 8 9   45
0 4 5 6 0 0    0 0 0     0 0 0   0
"""


def test_bvh_unusual_channel_order_hand_checked(tmp_path):
    take = read_bvh(_write(tmp_path, "t.bvh", BVH))
    assert take.joint_names == ["Hips", "Spine", "Head", "Leg"]
    assert take.parents == [-1, 0, 1, 0]
    assert take.frame_rate == pytest.approx(30.0, rel=1e-5)
    q = take.quats
    np.testing.assert_allclose(q[0, 0], [0, S, 0, S], atol=1e-12)  # Yrotation 90
    # Spine: Zrotation 90 then Xrotation 90 -> Rz·Rx = (0,0,s,c) ⊗ (s,0,0,c) = (.5,.5,.5,.5)
    np.testing.assert_allclose(q[0, 1], [0.5, 0.5, 0.5, 0.5], atol=1e-12)
    np.testing.assert_allclose(q[0, 2], [0, 0, 0, 1])  # positions only
    np.testing.assert_allclose(q[0, 3], [math.sin(math.pi / 8), 0, 0, math.cos(math.pi / 8)], atol=1e-12)
    np.testing.assert_allclose(take.root_position, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_allclose(take.meta["joint_positions"]["Head"], [[7, 8, 9], [0, 0, 0]])
    np.testing.assert_allclose(take.meta["end_sites"]["Leg"], [0, -4, 0])
    np.testing.assert_allclose(take.meta["offsets"][1], [0, 10, 0])
    crlf = read_take(_write(tmp_path, "c.bvh", BVH, crlf=True), frame_rate=100)
    np.testing.assert_array_equal(crlf.quats, take.quats)
    assert crlf.frame_rate == 100


BVH_ERRORS = [
    ("0 4 5 6 0 0    0 0 0     0 0 0   0\n", "0 4 5 6 0 0    0 0 0     0 0 0\n",
     "frame 2 has 12 values, expected 13", 30),
    ("90 1 2 3", "90 1 two 3", "value 'two' is not a number", 29),
    ("Frames: 2", "Frames: 1", "'Frames: 1' but 2 frame lines follow", 27),
    ("Frames: 2", "Frames: many", "Frames: 'many' is not an integer", 27),
    ("Frame Time: 0.0333333", "Frame Time: 0", "Frame Time 0 must be a positive number", 28),
    ("Frame Time: 0.0333333", "Frame Time: inf", "Frame Time inf must be a positive number", 28),
    ("Frame Time: 0.0333333", "Frame Time: 1e-320", "Frame Time 1e-320 must be a positive", 28),
    ("OFFSET 0 10 0", "OFFSET 0 nan 0", "OFFSET value 'nan' is not a finite number", 8),
    ("CHANNELS 1 Xrotation", "CHANNELS 1 Wrotation", "unknown channel 'Wrotation'", 22),
    ("CHANNELS 1 Xrotation", "CHANNELS x Xrotation", "CHANNELS count 'x' is not an integer", 22),
    ("OFFSET 0 10 0", "OFFSET 0 ten 0", "OFFSET value 'ten' is not a number", 8),
    ("JOINT Head", "JOINT Spine", "joint name 'Spine' used twice", 10),
    ("  JOINT Leg {", "  JOINT Leg ", "expected '{' after JOINT Leg, got 'OFFSET'", 21),
    ("      End Site", "      End Sight", "expected 'End Site', got 'End Sight'", 14),
    ("  OFFSET 0 0 0\n", "  OFFSET 0 0 0\n  WEIGHT 3\n", "unexpected 'WEIGHT' in HIERARCHY", 5),
]


@pytest.mark.parametrize("old,new,fragment,line", BVH_ERRORS)
def test_bvh_errors_name_file_line_problem(tmp_path, old, new, fragment, line):
    assert old in BVH
    p = _write(tmp_path, "bad.bvh", BVH.replace(old, new, 1))
    with pytest.raises(ReaderError) as ei:
        read_bvh(p)
    msg = str(ei.value)
    assert fragment in msg, msg
    assert msg.startswith(f"{p}:{line}:"), msg


@pytest.mark.parametrize("text,fragment", [
    ("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n", "no MOTION section"),
    ("ROOT a\n{\n}\nMOTION\nFrames: 0\nFrame Time: 1\n", "does not start with HIERARCHY"),
    ("HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\nMOTION\nFrames: 0\nFrame Time: 1\n", "unclosed '{'"),
    ("HIERARCHY\nMOTION\nFrames: 0\nFrame Time: 1\n", "HIERARCHY has no ROOT"),
    ("HIERARCHY\nROOT a\n{\n}\nMOTION\nFrame Time: 1\n", "lacks 'Frames:'"),
])
def test_bvh_structure_errors(tmp_path, text, fragment):
    p = _write(tmp_path, "bad.bvh", text)
    with pytest.raises(ReaderError, match=re.escape(fragment)) as ei:
        read_bvh(p)
    assert str(p) in str(ei.value)


# ---------------------------------------------------------------------------------------
# npz

def _random_take(frames: int = 20, joints: int = 5, seed: int = 0) -> Take:
    rng = np.random.default_rng(seed)
    q = Rotation.random(frames * joints, random_state=seed).as_quat().reshape(frames, joints, 4)
    valid = rng.random((frames, joints)) > 0.1
    return Take(joint_names=[f"J{i}" for i in range(joints)], parents=[-1, 0, 1, 1, 0],
                frame_rate=90.0, quats=q, root_position=rng.normal(size=(frames, 3)),
                space="global", valid=valid, length_unit="m", source="memory",
                meta={"frame_labels": np.arange(frames) // 5, "performer": "A", "n": 3,
                      "not_storable": object()})


def test_npz_round_trip(tmp_path, caplog):
    take = _random_take()
    p = write_take(tmp_path / "t.npz", take)
    assert "not_storable" in caplog.text  # skipped with a warning naming the key
    back = read_take(p)
    assert back.joint_names == take.joint_names and back.parents == take.parents
    assert back.frame_rate == 90.0 and back.space == "global" and back.length_unit == "m"
    np.testing.assert_array_equal(back.quats, take.quats)
    np.testing.assert_array_equal(back.root_position, take.root_position)
    np.testing.assert_array_equal(back.valid, take.valid)
    np.testing.assert_array_equal(back.meta["frame_labels"], take.meta["frame_labels"])
    assert back.meta["performer"] == "A" and back.meta["n"] == 3
    assert back.meta["original_source"] == "memory" and "not_storable" not in back.meta
    # float32 storage: half precision loss only, read back as float64; rate override.
    p32 = write_npz(tmp_path / "t32.npz", take, dtype=np.float32)
    b32 = read_npz(p32, frame_rate=30)
    assert b32.quats.dtype == np.float64 and b32.frame_rate == 30
    np.testing.assert_allclose(b32.quats, take.quats, atol=1e-7)
    with np.load(p32, allow_pickle=False) as z:
        assert z["quats"].dtype == np.float32 and int(z["format_version"]) == 1


def test_npz_minimal_without_optionals(tmp_path):
    p = tmp_path / "m.npz"
    np.savez(p, format_version=1, joint_names=np.array(["a", "b"]), parents=np.array([-1, 0]),
             frame_rate=50.0, quats=np.tile([0, 0, 0, 1.0], (3, 2, 1)), space="local")
    take = read_take(p)
    assert take.n_frames == 3 and take.root_position is None and take.valid is None


@pytest.mark.parametrize("change,fragment", [
    ({"format_version": 2}, "format_version 2 not supported"),
    ({"quats": np.zeros((3, 3, 4))}, "'quats' must be (frames, 2, 4)"),
    ({"quats": np.zeros((3, 2, 4), dtype=np.int32)}, "'quats' must be float32 or float64"),
    ({"quats": np.full((3, 2, 4), np.nan)}, "non-finite"),
    ({"parents": np.array([-1, 5])}, "joint 'b' has invalid parent index 5"),
    ({"space": "world"}, "space must be 'local' or 'global'"),
    ({"frame_rate": -1.0}, "frame_rate must be positive"),
    ({"frame_rate": np.array([1.0, 2.0])}, "'frame_rate' must be a scalar"),
    ({"meta_json": "{nope"}, "'meta_json' is not valid JSON"),
    ({"root_position": np.zeros((2, 3))}, "root_position must be (3, 3)"),
])
def test_npz_errors(tmp_path, change, fragment):
    arrays = dict(format_version=1, joint_names=np.array(["a", "b"]), parents=np.array([-1, 0]),
                  frame_rate=50.0, quats=np.tile([0, 0, 0, 1.0], (3, 2, 1)), space="local")
    arrays.update(change)
    p = tmp_path / "bad.npz"
    np.savez(p, **arrays)
    with pytest.raises(ReaderError, match=re.escape(fragment)) as ei:
        read_npz(p)
    assert str(p) in str(ei.value)


def test_npz_not_a_take(tmp_path):
    p = tmp_path / "other.npz"
    np.savez(p, x=np.zeros(3))
    with pytest.raises(ReaderError, match="missing array 'format_version'"):
        read_npz(p)
    junk = _write(tmp_path, "junk.npz", "this is not a zip")
    with pytest.raises(ReaderError, match="not a readable .npz"):
        read_npz(junk)
    with pytest.raises(ValueError, match="writes .npz only"):
        write_take(tmp_path / "t.bvh", _random_take())


# ---------------------------------------------------------------------------------------
# tsseg4d CSV

@pytest.mark.realdata
def test_csv_real_tsseg4d_matches_amc_angles(data_dir):
    csv = data_dir / "tsseg4d" / "86_01.csv"
    if not csv.is_file():
        pytest.skip(f"{csv} absent")
    take = read_take(csv)
    assert take.joint_names == ["lhumerus", "rhumerus", "lfemur", "rfemur"]
    assert take.parents == [-1] * 4 and take.space == "local" and take.frame_rate == 120.0
    labels = take.meta["frame_labels"]
    assert labels.dtype == np.int64 and labels.shape == (take.n_frames,)
    # Rotation about x by the column's angle, which is the AMC rx of that bone.
    angles = 2 * np.degrees(np.arctan2(take.quats[..., 0], take.quats[..., 3]))
    np.testing.assert_allclose(take.quats[..., 1:3], 0)
    frame1 = _amc_frame_values(data_dir / "cmu" / "86_01.amc", 1)
    frame3 = _amc_frame_values(data_dir / "cmu" / "86_01.amc", 3)
    for k, bone in enumerate(take.joint_names):
        assert angles[0, k] == pytest.approx(frame1[bone][0], abs=1e-9)
        assert angles[2, k] == pytest.approx(frame3[bone][0], abs=1e-9)
    assert len(np.unique(labels)) >= 2


def test_csv_hand_written_and_errors(tmp_path):
    p = _write(tmp_path, "x.csv", "90,0,-90,180,3\r\n0,0,0,0,4\r\n")
    take = read_take(p, frame_rate=10)
    np.testing.assert_allclose(take.quats[0, 0], [S, 0, 0, S], atol=1e-12)
    np.testing.assert_allclose(take.quats[0, 2], [-S, 0, 0, S], atol=1e-12)
    np.testing.assert_allclose(take.quats[0, 3], [1, 0, 0, 0], atol=1e-12)
    np.testing.assert_array_equal(take.meta["frame_labels"], [3, 4])
    assert take.frame_rate == 10
    for text, fragment, line in [
        ("1,2,3,4,0\n1,2,3,0\n", "expected 5 comma-separated values", 2),
        ("1,2,x,4,0\n", "angle 'x' is not a number", 1),
        ("1,2,3,4,0\n1,2,3,4,1.5\n", "label '1.5' is not an integer", 2),
        ("1,2,3,4,walk\n", "label 'walk' is not an integer", 1),
        ("1,2,3,4,0\n1,2,3,4,1e308\n", "label '1e308' is not an integer of 64 bits", 2),
        ("1,2,3,4,inf\n", "label 'inf' is not an integer", 1),
        ("1,inf,3,4,0\n", "non-finite angle", 1),
    ]:
        bad = _write(tmp_path, "bad.csv", text)
        with pytest.raises(ReaderError) as ei:
            read_take(bad)
        assert fragment in str(ei.value) and str(ei.value).startswith(f"{bad}:{line}:")
    with pytest.raises(ReaderError, match="no data lines"):
        read_take(_write(tmp_path, "empty.csv", "\n"))


# ---------------------------------------------------------------------------------------
# Directory dispatch

def test_directory_goes_to_read_session(tmp_path, monkeypatch):
    calls = []
    fake = types.ModuleType("rtseg.recording")

    def read_session(path):
        calls.append(Path(path))
        return _random_take()

    fake.read_session = read_session
    monkeypatch.setitem(sys.modules, "rtseg.recording", fake)
    take = read_take(tmp_path, frame_rate=25)
    assert calls == [tmp_path] and take.frame_rate == 25


def test_directory_without_session_support_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rtseg.recording", None)  # import raises ImportError
    with pytest.raises(ReaderError, match="session reading is unavailable"):
        read_take(tmp_path)


def test_directory_that_is_not_a_session(tmp_path):
    pytest.importorskip("rtseg.recording")
    with pytest.raises(ReaderError) as ei:
        read_take(tmp_path)
    assert str(ei.value).startswith(f"{tmp_path}: ") and "session" in str(ei.value)


@pytest.mark.parametrize("order,axis_of_rotation", [("XYZ", [0, 1, 0]), ("ZYX", [0, 0, 1])])
def test_axis_order_and_translation_dofs(tmp_path, order, axis_of_rotation):
    """axis 90 0 90: XYZ means C = Rz·Rx (x -> y), ZYX means C = Rx·Rz (x -> z).  A bone
    with dof "tx rx" takes its rotation from the second column."""
    asf = ASF.replace("     axis 0 0 90 XYZ\n     dof rx\n     limits (-180.0 180.0)\n",
                      f"     axis 90 0 90 {order}\n     dof tx rx\n     limits (0 1)\n            (-180 180)\n")
    amc = AMC.replace("a 90\n", "a 5 90\n").replace("a 0\n", "a 0 0\n")
    take = read_amc(_write(tmp_path, "T_01.amc", amc), _write(tmp_path, "T.asf", asf))
    np.testing.assert_allclose(take.quats[0, 1], [*(S * np.array(axis_of_rotation)), S], atol=1e-12)
    assert take.meta["dof"]["a"] == ["tx", "rx"]


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=40, deadline=None)
@given(order=st.permutations(["Xrotation", "Yrotation", "Zrotation"]),
       angles=st.lists(st.floats(-180, 180, allow_nan=False), min_size=3, max_size=3))
def test_bvh_any_channel_order_is_matrix_product(tmp_path_factory, order, angles):
    text = ("HIERARCHY\nROOT r\n{\n OFFSET 0 0 0\n CHANNELS 3 " + " ".join(order)
            + "\n End Site\n {\n  OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.01\n"
            + " ".join(repr(a) for a in angles) + "\n")
    p = tmp_path_factory.mktemp("bvh") / "h.bvh"
    p.write_text(text)
    take = read_bvh(p)
    expected = np.eye(3)
    for name, a in zip(order, angles):
        expected = expected @ Rotation.from_euler(name[0].lower(), a, degrees=True).as_matrix()
    np.testing.assert_allclose(Rotation.from_quat(take.quats[0, 0]).as_matrix(), expected, atol=1e-12)
