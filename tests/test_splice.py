"""Spliced performances (rtseg.evaluation.splice, benchmarks/splice.py) and their group in
rtseg.labels.takes: the splice rules, exact boundaries, seeded byte-identical output, no join
across formats or joint sets, rest-frame trimming, reading back as group "spliced".

The source folders are written here (tiny BVH and ASF/AMC files laid out like
../shared/data/cmu_single), so the tests run on a fresh clone; one test uses the real
folder and skips when it is absent.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtseg.evaluation import splice as S
from rtseg.drivers.readers import read_take, write_take
from rtseg.evaluation.scoring import score
from rtseg.labels.takes import LabelError, find_labelled_takes, read_take_transitions

from conftest import DATA_DIR, REPO

RATE = 120.0

# behaviour -> (frequency Hz, amplitude deg, base deg): slow, distinct motions
STYLE = {"walk": (0.5, 12.0, 20.0), "jump": (0.8, 25.0, 35.0), "punch": (0.3, 8.0, 45.0),
         "dance": (0.6, 18.0, 10.0), "run": (1.0, 10.0, 25.0), "kick": (0.4, 15.0, 30.0),
         "golf": (0.25, 20.0, 15.0)}

BVH7 = [("Hips", -1), ("Spine", 0), ("Head", 1), ("LeftArm", 1), ("RightArm", 1),
        ("LeftUpLeg", 0), ("RightUpLeg", 0)]
BVH8 = BVH7[:2] + [("Chest", 1), ("Head", 2), ("LeftArm", 2), ("RightArm", 2),
                   ("LeftUpLeg", 0), ("RightUpLeg", 0)]
ASF_BONES = [("lowerback", "root"), ("head", "lowerback"), ("lhumerus", "lowerback"),
             ("rhumerus", "lowerback"), ("lfemur", "root")]

# take, subject, format, seconds, behaviour, lead ("tpose": one zero frame; "daz": blend-in)
SOURCES = [
    ("01_01", "01", "bvh", 2.0, "walk", "tpose"), ("01_02", "01", "bvh", 2.0, "walk", "tpose"),
    ("01_03", "01", "bvh", 6.0, "jump", "tpose"), ("01_04", "01", "bvh", 5.0, "punch", "tpose"),
    ("01_05", "01", "bvh", 1.0, "run", "tpose"),      # too short: never used
    ("02_01", "02", "bvh", 5.0, "walk", "tpose"), ("02_02", "02", "bvh", 6.0, "dance", "tpose"),
    ("03_01", "03", "bvh", 5.0, "walk", "daz"), ("03_02", "03", "bvh", 5.0, "dance", "daz"),
    ("04_01", "04", "amc", 5.0, "kick", ""), ("04_02", "04", "amc", 3.0, "kick", ""),
    ("05_01", "05", "amc", 5.0, "golf", ""),
]
LEAD = {"tpose": 1, "daz": 6, "": 0}     # frames of rest / blend-in written before the motion


def _motion(n_joints: int, n: int, behaviour: str, phase: float) -> np.ndarray:
    """(n, joints, 3) Euler angles (deg): base + amp sin(2 pi f t + joint phase)."""
    f, amp, base = STYLE[behaviour]
    t = np.arange(n)[:, None, None] / RATE
    j = np.arange(n_joints)[None, :, None]
    ax = np.arange(3)[None, None, :]
    return base * np.cos(j + ax) + amp * np.sin(2 * np.pi * f * t + phase + 0.7 * j + 1.3 * ax)


def _with_lead(angles: np.ndarray, lead: str) -> np.ndarray:
    if lead == "tpose":
        return np.concatenate([np.zeros_like(angles[:1]), angles])
    if lead == "daz":
        k = LEAD["daz"]
        ramp = np.arange(k)[:, None, None] / k * angles[:1]
        return np.concatenate([ramp, angles])
    return angles


def _bvh_hierarchy(joints: list[tuple[str, int]]) -> str:
    out = []

    def emit(j: int, depth: int) -> None:
        name, parent = joints[j]
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if parent < 0 else 'JOINT'} {name}")
        out.append(pad + "{")
        out.append(f"{pad}  OFFSET 0 {0 if parent < 0 else 5} 0")
        chans = ("6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" if parent < 0
                 else "3 Zrotation Xrotation Yrotation")
        out.append(f"{pad}  CHANNELS {chans}")
        kids = [k for k, (_, p) in enumerate(joints) if p == j]
        for k in kids:
            emit(k, depth + 1)
        if not kids:
            out.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET 0 3 0", pad + "  }"])
        out.append(pad + "}")

    emit(0, 0)
    return "HIERARCHY\n" + "\n".join(out) + "\n"


def _root_track(n: int, yaw: float) -> np.ndarray:
    t = np.arange(n) / RATE
    return np.stack([10 + 3 * t * np.sin(yaw), 17 + 0.2 * np.sin(3 * t), -20 + 3 * t * np.cos(yaw)], 1)


def write_bvh(path: Path, joints: list[tuple[str, int]], behaviour: str, seconds: float,
              lead: str, phase: float) -> None:
    n = int(seconds * RATE)
    ang = _with_lead(_motion(len(joints), n, behaviour, phase), lead)
    ang[:, 0] = _with_lead(np.tile([0.0, 0.0, np.degrees(phase)], (n, 1))[:, None], lead)[:, 0]
    pos = _root_track(len(ang), phase)
    rows = [" ".join(f"{v:.5f}" for v in np.r_[pos[i], ang[i].ravel()]) for i in range(len(ang))]
    path.write_text(_bvh_hierarchy(joints) + f"MOTION\nFrames: {len(ang)}\n"
                    f"Frame Time: {1 / RATE:.7f}\n" + "\n".join(rows) + "\n")


def write_asf(path: Path) -> None:
    bones = "".join(f"  begin\n     id {i + 1}\n     name {b}\n     direction 0 1 0\n"
                    f"     length 1.0\n     axis 0 0 0 XYZ\n     dof rx ry rz\n  end\n"
                    for i, (b, _) in enumerate(ASF_BONES))
    kids: dict[str, list[str]] = {}
    for b, p in ASF_BONES:
        kids.setdefault(p, []).append(b)
    hier = "".join(f"    {p} {' '.join(c)}\n" for p, c in kids.items())
    path.write_text(":version 1.10\n:name T\n:units\n  mass 1.0\n  length 0.45\n  angle deg\n"
                    ":root\n   order TX TY TZ RX RY RZ\n   axis XYZ\n   position 0 0 0\n"
                    "   orientation 0 0 0\n:bonedata\n" + bones +
                    ":hierarchy\n  begin\n" + hier + "  end\n")


def write_amc(path: Path, behaviour: str, seconds: float, phase: float) -> None:
    n = int(seconds * RATE)
    ang = _motion(len(ASF_BONES), n, behaviour, phase)
    pos = _root_track(n, phase)
    lines = ["# synthetic", ":FULLY-SPECIFIED", ":DEGREES"]
    for i in range(n):
        lines.append(str(i + 1))
        lines.append("root " + " ".join(f"{v:.5f}" for v in (*pos[i], 0.0, np.degrees(phase), 0.0)))
        lines += [f"{b} " + " ".join(f"{v:.5f}" for v in ang[i, k]) for k, (b, _) in enumerate(ASF_BONES)]
    path.write_text("\n".join(lines) + "\n")


def make_source(root: Path) -> Path:
    """A folder laid out like cmu_single: index.tsv, bvh/, amc/ (one skeleton per subject)."""
    (root / "bvh").mkdir(parents=True)
    (root / "amc").mkdir()
    rows = ["take\tsubject\tformat\tframes\tfps\tbehaviour\tcmu_description"]
    for i, (take, subj, fmt, sec, beh, lead) in enumerate(SOURCES):
        phase = 0.37 * (i + 1)
        if fmt == "bvh":
            write_bvh(root / "bvh" / f"{take}.bvh", BVH8 if subj == "03" else BVH7, beh, sec, lead, phase)
        else:
            if not (root / "amc" / f"{subj}.asf").exists():
                write_asf(root / "amc" / f"{subj}.asf")
            write_amc(root / "amc" / f"{take}.amc", beh, sec, phase)
        rows.append(f"{take}\t{subj}\t{fmt}\t{int(sec * RATE) + LEAD[lead]}\t120\t{beh}\t{beh}")
    (root / "index.tsv").write_text("\n".join(rows) + "\n")
    return root


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    return make_source(tmp_path_factory.mktemp("single"))


@pytest.fixture(scope="module")
def spliced(source, tmp_path_factory) -> tuple[Path, list[S.Performance]]:
    out = tmp_path_factory.mktemp("spliced")
    return out, S.generate(source, out, seed=3, n=6)


def _sources_of(seg: dict) -> list[tuple[str, int, int]]:
    return [(m.group(1), int(m.group(2)), int(m.group(3)))
            for m in re.finditer(r"(\d\d_\d\d)\[(\d+):(\d+)\]", seg["sources"])]


# --------------------------------------------------------------------------- trimming

def test_trim_bounds_rest_frames():
    rng = np.random.default_rng(0)
    from rtseg.core import quat as Q
    ang = _motion(6, 600, "walk", 0.4)
    q = Q.from_euler("ZXY", ang.reshape(-1, 3)).reshape(600, 6, 4)
    assert S.trim_bounds(q, RATE) == (0, 600)                 # nothing to drop
    ident = np.tile(Q.IDENTITY, (1, 6, 1))
    tpose = np.concatenate([ident, q])                        # BVH T-pose frame
    assert S.trim_bounds(tpose, RATE) == (1, 601)
    zero2 = np.concatenate([ident + rng.normal(0, 0.02, ident.shape), ident, q])  # 07_12 style
    assert S.trim_bounds(Q.normalize(zero2), RATE)[0] == 2
    held = np.concatenate([np.repeat(q[:1], 5, axis=0), q])   # constant frames
    assert S.trim_bounds(held, RATE)[0] == 5
    slow = Q.from_euler("ZXY", (0.2 * ang + 20).reshape(-1, 3)).reshape(600, 6, 4)
    w = (np.arange(6) / 6)[:, None, None]                      # Daz-style blend-in
    blend = S.slerp(np.broadcast_to(Q.IDENTITY, (6, 6, 4)), np.broadcast_to(slow[0], (6, 6, 4)), w[..., 0])
    assert S.trim_bounds(np.concatenate([blend, slow]), RATE)[0] == 6
    tail = np.concatenate([q, ident])                         # rest frame at the end too
    assert S.trim_bounds(tail, RATE) == (0, 600)


def test_load_sources_trims_written_files(source):
    rows = {r.name: r for r in S.load_sources(S.read_source_index(source))}
    for take, _s, _f, sec, _b, lead in SOURCES:
        r = rows[take]
        assert r.trim == (LEAD[lead], LEAD[lead] + int(sec * RATE)), take


# --------------------------------------------------------------------------- rules

def test_splice_rules(spliced, source):
    out, perfs = spliced
    cfg = S.SpliceConfig()
    fmt_of = {t: f for t, _s, f, *_ in SOURCES}
    subj_of = {t: s for t, s, *_ in SOURCES}
    beh_of = {t: b for t, _s, _f, _sec, b, _l in SOURCES}
    assert {p.kind for p in perfs} == {"same", "mixed"}
    for p in perfs:
        segs = p.segments
        assert cfg.min_segments <= len(segs) <= cfg.max_segments
        behaviours = [s["behaviour"] for s in segs]
        assert all(a != b for a, b in zip(behaviours, behaviours[1:])), p.name
        assert "run" not in behaviours                         # 1 s take: too short
        takes = [t for s in segs for t, _a, _b in _sources_of(s)]
        assert len({fmt_of[t] for t in takes}) == 1, p.name    # never across formats
        assert len({t[:2] == "03" for t in takes}) == 1, p.name  # nor across joint sets
        for s in segs:
            assert {beh_of[t] for t, _a, _b in _sources_of(s)} == {s["behaviour"]}
            assert {subj_of[t] for t, _a, _b in _sources_of(s)} == {s["subject"]}
            assert s["pure"][1] - s["pure"][0] >= cfg.min_segment_s * RATE - 1e-9
        subjects = {s["subject"] for s in segs}
        assert len(subjects) == 1 if p.kind == "same" else len(subjects) >= 2
        for lo, mid, hi, before, after in p.transitions:
            assert round(cfg.min_fade_s * RATE) <= hi - lo + 1 <= round(cfg.max_fade_s * RATE)
            assert lo <= mid <= hi and before != after
    # every eligible person / format is used: 01, 02, 03 alone; bvh and amc mixed
    assert {p.segments[0]["subject"] for p in perfs if p.kind == "same"} == {"01", "02", "03"}
    assert {p.take.meta["splice"]["format"] for p in perfs if p.kind == "mixed"} == {"bvh", "amc"}
    index = (out / "index.tsv").read_text().splitlines()
    assert index[0].split("\t") == list(S.INDEX_COLUMNS)
    assert len(index) - 1 == sum(len(p.segments) for p in perfs)


def test_boundaries_and_labels_exact(spliced, source):
    """Outside the fades every non-root joint is exactly the stated source frame; inside a
    fade [lo, hi] it is neither neighbour; labels switch exactly at each mid."""
    out, perfs = spliced
    src = {r.name: r for r in S.load_sources(S.read_source_index(source))}
    checked = 0
    for p in perfs:
        take = read_take(out / f"{p.name}.npz")
        q = take.quats[:, 1:]
        fl = np.asarray(take.meta["frame_labels"])
        names = take.meta["frame_label_names"]
        mids = [t[1] for t in p.transitions]
        assert (np.flatnonzero(np.diff(fl)) + 1).tolist() == mids
        for k, s in enumerate(p.segments):
            assert {names[i] for i in np.unique(fl[s["start"]:s["stop"]])} == {s["behaviour"]}
            parts = _sources_of(s)
            if len(parts) != 1:
                continue                                      # joined short takes
            name, a, b = parts[0]
            piece_start = s["pure"][0] - s["fade_in"]
            ref = src[name].take.quats[a:b, 1:]
            lo_out, hi_out = piece_start, piece_start + (b - a)
            same = np.abs(np.sum(q[lo_out:hi_out] * ref, axis=-1)).min(axis=1) > 1 - 1e-13
            fade_in = np.zeros(b - a, bool)
            fade_in[:s["fade_in"]] = True
            fade_out = np.zeros(b - a, bool)
            if k + 1 < len(p.segments):
                fade_out[(b - a) - p.segments[k + 1]["fade_in"]:] = True
            assert same[~fade_in & ~fade_out].all(), (p.name, k)
            assert not same[fade_in | fade_out].any(), (p.name, k)   # the fades are blends
            checked += 1
        for lo, _mid, hi, *_ in p.transitions:
            assert np.abs(np.diff(take.root_position[lo - 1:hi + 2], axis=0)).max() < 1.0
    assert checked >= 10


def test_seeded_output_byte_identical(source, tmp_path):
    """Two processes with different hash seeds, same --seed: the same bytes; another seed
    differs.  Performance i does not depend on --n."""
    def run(out: Path, seed: int, n: int, hashseed: str) -> None:
        env = {**os.environ, "PYTHONHASHSEED": hashseed}
        subprocess.run([sys.executable, str(REPO / "benchmarks" / "splice.py"), str(source),
                        str(out), "--seed", str(seed), "--n", str(n)], check=True, env=env,
                       capture_output=True)
    run(tmp_path / "a", 5, 3, "1")
    run(tmp_path / "b", 5, 3, "2")
    run(tmp_path / "c", 6, 3, "1")
    run(tmp_path / "d", 5, 1, "3")
    files = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert len(files) == 7 and files == sorted(p.name for p in (tmp_path / "b").iterdir())
    for f in files:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a" / "same_000.npz").read_bytes() != (tmp_path / "c" / "same_000.npz").read_bytes()
    assert (tmp_path / "a" / "mixed_000.npz").read_bytes() == (tmp_path / "d" / "mixed_000.npz").read_bytes()


def test_cli_refuses_foreign_npz_and_bad_source(source, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "other.npz").write_bytes(b"x")
    cmd = [sys.executable, str(REPO / "benchmarks" / "splice.py"), str(source), str(out), "--n", "1"]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 2 and "other.npz" in r.stderr
    r = subprocess.run(cmd + ["--force"], capture_output=True, text=True)
    assert r.returncode == 0 and not (out / "other.npz").exists()
    r = subprocess.run([*cmd[:2], str(tmp_path / "nowhere"), str(out)], capture_output=True, text=True)
    assert r.returncode == 2 and "index.tsv" in r.stderr


def test_cli_on_a_folder_of_one_person(source, tmp_path):
    """--kind both on a folder holding one person: same-person performances only, said."""
    one = tmp_path / "one"
    (one / "bvh").mkdir(parents=True)
    rows = (source / "index.tsv").read_text().splitlines()
    keep = [rows[0]] + [r for r in rows[1:] if r.split("\t")[1] == "01"]
    (one / "index.tsv").write_text("\n".join(keep) + "\n")
    for r in keep[1:]:
        name = r.split("\t")[0]
        (one / "bvh" / f"{name}.bvh").write_bytes((source / "bvh" / f"{name}.bvh").read_bytes())
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, str(REPO / "benchmarks" / "splice.py"), str(one), str(out),
                        "--n", "2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "same-person performances only" in r.stderr
    assert sorted(p.name for p in out.glob("*.npz")) == ["same_000.npz", "same_001.npz"]


# --------------------------------------------------------------------------- labels group

def test_found_as_group_spliced(spliced, tmp_path, caplog):
    out, perfs = spliced
    found = find_labelled_takes(out, ["spliced"])
    assert [t.name for t in found] == sorted(p.name for p in perfs)
    by_name = {p.name: p for p in perfs}
    for lt in found:
        p = by_name[lt.name]
        assert lt.group == "spliced" and lt.labels.kind == "ranges"
        assert [(t.lo, t.mid, t.hi, t.before, t.after) for t in lt.transitions] == p.transitions
        sc = score([t.mid for t in lt.transitions], lt.transitions)
        assert sc.f1 == 1.0
        assert score([t.hi + 1 for t in lt.transitions], lt.transitions).tp == 0  # range = fade
    assert find_labelled_takes(out, ["cmu"]) == []
    # also as the spliced/ subfolder of a data folder
    data = tmp_path / "data"
    (data / "spliced").mkdir(parents=True)
    (data / "spliced" / "x.npz").write_bytes((out / "same_000.npz").read_bytes())
    assert [t.name for t in find_labelled_takes(data, ["spliced"])] == ["x"]
    # a plain take without ranges is skipped with a warning; inconsistent ranges raise
    take = read_take(out / "same_000.npz")
    plain = tmp_path / "plain"
    plain.mkdir()
    meta = dict(take.meta)
    take.meta = {"frame_labels": meta["frame_labels"]}
    write_take(plain / "p.npz", take)
    with caplog.at_level("WARNING"):
        assert find_labelled_takes(plain, ["spliced"]) == []
    assert "no transition ranges" in caplog.text
    bad = meta["transitions"][0]
    take.meta = {**meta, "transitions": [[bad[0], bad[1] + 1, bad[2], bad[3], bad[4]]] + meta["transitions"][1:]}
    write_take(plain / "p.npz", take)
    with pytest.raises(LabelError, match="change at"):
        read_take_transitions(plain / "p.npz")


def test_meta_is_plain_json(spliced):
    out, perfs = spliced
    with np.load(out / f"{perfs[0].name}.npz", allow_pickle=False) as z:
        meta = json.loads(str(z["meta_json"].item()))
        assert meta["splice"]["kind"] == perfs[0].kind
        assert z["meta__frame_labels"].dtype == np.int64
        assert str(z["source"].item()) == f"splice:{perfs[0].name}"


# --------------------------------------------------------------------------- real data

def test_real_cmu_single(tmp_path):
    src = DATA_DIR / "cmu_single"
    if not (src / "index.tsv").is_file():
        pytest.skip(f"real single-behaviour takes not found at {src} "
                    "(set RTSEG_DATA to a folder holding cmu_single/)")
    perfs = S.generate(src, tmp_path, seed=0, n=2)
    rows = {r.name: r for r in S.load_sources(S.read_source_index(src))}
    # cgspeed BVH: the T-pose first frame is dropped; the Daz-style 10_04 blend-in too
    assert all(r.trim[0] == 1 for r in rows.values() if r.fmt == "bvh" and r.name != "10_04")
    assert 1 < rows["10_04"].trim[0] <= 12
    assert all(r.trim[0] == 0 for r in rows.values() if r.fmt == "amc")
    for p in perfs:
        behaviours = [s["behaviour"] for s in p.segments]
        assert all(a != b for a, b in zip(behaviours, behaviours[1:]))
        takes = [t for s in p.segments for t, *_ in _sources_of(s)]
        assert len({rows[t].fmt for t in takes}) == 1 and "10_04" not in takes
        assert "run" not in behaviours                        # 02_03 is 1.4 s
    assert {p.take.meta["splice"]["format"] for p in perfs if p.kind == "mixed"} == {"bvh", "amc"}
    found = find_labelled_takes(tmp_path, ["spliced"])
    assert len(found) == 4 and all(t.labels.kind == "ranges" for t in found)


def test_index_rows_of_blanks_are_skipped_and_errors_name_their_line(tmp_path):
    """A spreadsheet export's rows of spaces or tabs are no takes; a row that lacks a field
    is named by its own line of index.tsv."""
    from source_folders import make_source
    src = make_source(tmp_path / "src", ["p1"], ["walk", "squat"], seconds=3.0)
    index = src / "index.tsv"
    lines = index.read_text().splitlines()
    index.write_text("\n".join(lines[:2] + ["   ", "\t\t\t", ""] + lines[2:]) + "\n")
    assert [r.name for r in S.read_source_index(src)] == ["p1_001", "p1_002"]
    index.write_text("\n".join(lines[:2] + ["\t\t\t", "p1_009\tp1\tbvh"] + lines[2:]) + "\n")
    with pytest.raises(ValueError, match=r"index.tsv:4: empty"):
        S.read_source_index(src)


def test_an_index_row_repeating_a_take_is_logged_and_skipped(tmp_path, caplog):
    """A take listed twice in index.tsv (a copy-paste, or the same file under two
    behaviours) is read once: the later row is skipped with a warning naming both lines,
    so the splicer never uses one take's motion twice."""
    import logging
    from source_folders import make_source
    src = make_source(tmp_path / "src", ["p1"], ["walk", "squat"], seconds=3.0)
    index = src / "index.tsv"
    lines = index.read_text().splitlines()
    twice = lines[1].replace("walk", "run")
    index.write_text("\n".join(lines + [twice]) + "\n")
    with caplog.at_level(logging.WARNING):
        rows = S.read_source_index(src)
    assert [(r.name, r.behaviour) for r in rows] == [("p1_001", "walk"), ("p1_002", "squat")]
    said = [r.getMessage() for r in caplog.records if "already line" in r.getMessage()]
    assert len(said) == 1 and "index.tsv:4: p1_001.bvh is already line 2's take" in said[0]


def test_an_amc_take_is_read_with_its_subject_skeleton(tmp_path, data_dir):
    """amc/<take>.amc goes with amc/<subject>.asf (docs/splice.md), whatever the take is
    called: two people's skeletons beside takes named otherwise."""
    import shutil
    src = tmp_path / "src"
    (src / "amc").mkdir(parents=True)
    hdm = data_dir / "hdm05"
    if not (hdm / "amc").is_dir():
        pytest.skip(f"{hdm} not found")
    rows = ["take\tsubject\tformat\tbehaviour"]
    for person in ("bd", "bk"):
        shutil.copy(hdm / "amc" / f"{person}.asf", src / "amc" / f"{person}.asf")
        amc = sorted((hdm / "amc").glob(f"{person}_00*.amc"))[0]
        name = f"HDM_{person}_squat_007"
        shutil.copy(amc, src / "amc" / f"{name}.amc")
        rows.append(f"{name}\t{person}\tamc\tsquat")
    (src / "index.tsv").write_text("\n".join(rows) + "\n")
    got = S.load_sources(S.read_source_index(src))
    assert [r.take.n_frames > 0 for r in got] == [True, True]


def test_lopo_caches_performances_by_the_source_path_and_contents(tmp_path):
    """benchmarks/lopo.py keys its cache of spliced performances on the source: two folders
    of one name, or one folder changed, never share what was spliced."""
    import importlib.util
    from source_folders import make_source
    spec = importlib.util.spec_from_file_location(
        "lopo_bench", Path(__file__).resolve().parents[1] / "benchmarks" / "lopo.py")
    lopo = importlib.util.module_from_spec(spec)
    sys.modules["lopo_bench"] = lopo              # its dataclasses look their module up
    spec.loader.exec_module(lopo)
    a = make_source(tmp_path / "a" / "hdm05", ["p1"], ["walk", "squat"], seconds=3.0)
    b = make_source(tmp_path / "b" / "hdm05", ["p1"], ["walk", "squat"], seconds=3.0)
    key_a = lopo._cache_key(a)
    assert key_a == lopo._cache_key(a) and key_a != lopo._cache_key(b)
    (a / "index.tsv").write_text((a / "index.tsv").read_text() + "\n")
    assert lopo._cache_key(a) != key_a


def test_a_take_that_cannot_be_read_is_skipped_not_the_source(tmp_path, caplog):
    """An empty BVH file or one of no frames is logged and left out, as a missing file is;
    the rest of the source is read."""
    import logging
    from source_folders import make_source
    src = make_source(tmp_path / "src", ["p1"], ["walk", "squat", "wave"], seconds=3.0)
    (src / "bvh" / "p1_002.bvh").write_text("")
    with caplog.at_level(logging.WARNING):
        rows = S.load_sources(S.read_source_index(src))
    assert [r.name for r in rows] == ["p1_001", "p1_003"]
    assert any("p1_002.bvh: cannot be read" in r.getMessage() for r in caplog.records)


def test_a_person_without_material_is_named_when_left_out(tmp_path, caplog):
    """Someone whose takes are all too short for a segment is not silently dropped."""
    import logging
    from source_folders import make_source
    src = make_source(tmp_path / "src", ["p1", "p2"], ["walk", "squat"], seconds=4.0)
    make_source(tmp_path / "short", ["p3"], ["walk", "squat"], seconds=1.6, seed0=7)
    lines = (tmp_path / "short" / "index.tsv").read_text().splitlines()[1:]
    for f in (tmp_path / "short" / "bvh").iterdir():
        f.rename(src / "bvh" / f.name)
    with open(src / "index.tsv", "a") as fh:
        fh.write("\n".join(lines) + "\n")
    with caplog.at_level(logging.WARNING):
        S.generate(src, tmp_path / "out", n=1, kinds=("same",))
    assert any("p3 left out: no behaviour with material" in r.getMessage()
               for r in caplog.records)


def test_a_missing_take_is_warned_about_once(tmp_path, caplog):
    """Commands read a source's index several times (learn, library_loto): its missing file
    is said once."""
    import logging
    from source_folders import make_source
    src = make_source(tmp_path / "src", ["p1"], ["walk", "squat"], seconds=3.0)
    (src / "bvh" / "p1_002.bvh").unlink()
    with caplog.at_level(logging.WARNING):
        for _ in range(3):
            assert [r.name for r in S.read_source_index(src)] == ["p1_001"]
    assert sum("p1_002.bvh not found" in r.getMessage() for r in caplog.records) == 1


def test_a_source_without_a_readable_take_says_so(tmp_path):
    """A source whose index lists only missing or unreadable files: "no take to splice",
    nothing written, and splice.py does not call it a folder of one person (it said "holds
    one person per format", then "no person has two behaviours")."""
    from source_folders import make_source
    src = make_source(tmp_path / "src", ["p1", "p2"], ["walk", "squat"], seconds=3.0)
    files = sorted((src / "bvh").iterdir())
    files[0].write_text("")
    for f in files[1:]:
        f.unlink()
    with pytest.raises(ValueError, match="no take to splice"):
        S.generate(src, tmp_path / "out", n=1)
    assert not (tmp_path / "out").exists()
    r = subprocess.run([sys.executable, str(REPO / "benchmarks" / "splice.py"), str(src),
                        str(tmp_path / "out"), "--n", "1"], capture_output=True, text=True)
    assert r.returncode == 2 and "no take to splice" in r.stderr
    assert "one person" not in r.stderr and not (tmp_path / "out").exists()


def test_two_processes_splicing_into_one_folder_leave_whole_files(source, tmp_path):
    """Two benchmarks that share a cache may splice the same performances into one folder
    at once (``benchmarks/lopo.py`` twice): each file appears whole, by an atomic rename,
    so both finish, every file is the bytes one process alone writes, and no temporary
    file is left."""
    def start(out: Path) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, str(REPO / "benchmarks" / "splice.py"),
                                 str(source), str(out), "--seed", "4", "--n", "6"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    shared = tmp_path / "shared"
    procs = [start(shared), start(shared)]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err.decode()
    alone = tmp_path / "alone"
    assert start(alone).wait(timeout=300) == 0
    names = sorted(p.name for p in alone.iterdir())
    assert sorted(p.name for p in shared.iterdir()) == names      # nothing else left
    for name in names:
        assert (shared / name).read_bytes() == (alone / name).read_bytes(), name
    assert oct((shared / names[0]).stat().st_mode & 0o777) == oct(0o644)


def test_a_write_that_fails_leaves_no_file(tmp_path, monkeypatch):
    """``replace_bytes``: a write that fails before its rename (here the rename itself)
    leaves neither the target nor its temporary file; one that succeeds leaves the file."""
    target = tmp_path / "x.npz"

    def no_rename(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(S.os, "replace", no_rename)
    with pytest.raises(OSError, match="disk full"):
        S.replace_bytes(target, b"whole")
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    S.replace_bytes(target, b"whole")
    assert target.read_bytes() == b"whole" and [p.name for p in tmp_path.iterdir()] == ["x.npz"]
