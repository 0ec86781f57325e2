"""Label loaders: real files (skipped without ../shared/data) and hand-written ones with
each kind of slip."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from rtseg.labels.takes import (
    GROUPS, LabelError, Transition, find_labelled_takes, labels_from_take, load_cmu86_transitions,
    find_labels_for, read_block_labels, read_cmu86_transitions, read_frame_labels,
    read_labels_file,
    transitions_from_frame_labels,
)
from rtseg.labels import takes as labels_module
from rtseg.core.take import Take


@pytest.fixture(autouse=True)
def fresh_slip_log():
    """Slips are logged once per process and file line; start each test afresh."""
    labels_module._warned.clear()
    yield

CLEAN = """86 01
walk 500 550 600
jump 1100 1150 1200
punch 1500 1500 1500

86 02
run 100 120 140
walk 300 300 300
"""


def write(tmp_path: Path, text: str, name: str = "t.txt") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_clean_block_zero_based_with_behaviours(tmp_path):
    got = read_cmu86_transitions(write(tmp_path, CLEAN))
    assert sorted(got) == ["86_01", "86_02"]
    a = got["86_01"]
    assert a.transitions == [Transition(499, 599, 549, "walk", "jump"),
                             Transition(1099, 1199, 1149, "jump", "punch")]
    assert a.n_frames == 1500 and a.repairs == [] and a.kind == "ranges"
    assert got["86_02"].transitions == [Transition(99, 139, 119, "run", "walk")]


def test_crlf_and_trailing_spaces(tmp_path):
    p = tmp_path / "crlf.txt"
    p.write_bytes(CLEAN.replace("\n", "  \r\n").encode())
    assert load_cmu86_transitions(p)["86_01"][1].mid == 1149


SLIPS = """86 04
walk 970 1019 1100
stand 4000 4074 4130
walk 4060 5050 5090
slap 5830 5870 5930
walk 6000 6000 6000

86 05
walk 760 818 850
jump 3881 3840 4000
walk 4480 4480 4480

86 06
walk 1050 1100 1150
stand_still 1540 1685 1628
run 2000 2000 2000
"""


def test_slips_repaired_and_logged(tmp_path, caplog):
    p = write(tmp_path, SLIPS, "cmu86_transitions.txt")
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        got = read_cmu86_transitions(p)
    # lo before the previous boundary -> lo set to mid
    t = got["86_04"].transitions[2]
    assert (t.lo, t.mid, t.hi) == (5049, 5049, 5089)
    # lo > mid and mid > hi -> reordered
    t = got["86_05"].transitions[1]
    assert (t.lo, t.mid, t.hi) == (3839, 3880, 3999)
    t = got["86_06"].transitions[1]
    assert (t.lo, t.mid, t.hi) == (1539, 1627, 1684)
    msgs = [r.getMessage() for r in caplog.records]
    assert any("cmu86_transitions.txt:4 (86_04 line 3)" in m and "lo set to" in m for m in msgs)
    assert any("cmu86_transitions.txt:10 (86_05 line 2)" in m and "reordered" in m for m in msgs)
    assert any("cmu86_transitions.txt:15 (86_06 line 2)" in m and "mid 1685 > hi 1628" in m
               for m in msgs)
    assert len(got["86_04"].repairs) == 1 and len(got["86_06"].repairs) == 1
    for labels in got.values():
        for t in labels.transitions:
            assert t.lo <= t.mid <= t.hi


def test_slips_rejected_when_asked(tmp_path, caplog):
    p = write(tmp_path, SLIPS)
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        got = read_cmu86_transitions(p, on_slip="reject")
    assert [t.mid for t in got["86_04"].transitions] == [1018, 4073, 5869]
    assert [t.mid for t in got["86_05"].transitions] == [817]
    assert [t.mid for t in got["86_06"].transitions] == [1099]
    assert sum("line rejected" in r.getMessage() for r in caplog.records) == 3


@pytest.mark.parametrize("block,line", [("86_04", 4), ("86_05", 10), ("86_06", 15)])
def test_strict_raises_naming_file_and_line(tmp_path, block, line):
    # keep only the block under test so the first slip met is that one
    text = SLIPS.split("\n\n")
    keep = [b for b in text if b.startswith(block.replace("_", " "))][0]
    offset = SLIPS.split("\n").index(keep.split("\n")[0])
    p = write(tmp_path, "\n" * offset + keep + "\n")
    with pytest.raises(LabelError) as exc:
        read_cmu86_transitions(p, strict=True)
    assert exc.value.line == line
    assert f"{p}:{line}" in str(exc.value)


@pytest.mark.parametrize("bad,line,what", [
    ("86 01\nwalk 1 2\n", 2, "behaviour lo mid hi"),
    ("86 01\nwalk 1 x 3\n", 2, "integers"),
    ("walk 1 2 3\n", 1, "before any"),
    ("86 01\nwalk 0 2 3\nx 9 9 9\n", 2, "1-based"),
])
def test_malformed_lines_raise_even_when_lenient(tmp_path, bad, line, what):
    p = write(tmp_path, bad)
    with pytest.raises(LabelError, match=what) as exc:
        read_cmu86_transitions(p)
    assert exc.value.line == line


def test_block_labels_tokens_and_tolerance(tmp_path):
    # 3 blocks of label 1, 2 of label 6, 1 of 5: changes at blocks 3 and 5
    p = write(tmp_path, "1 1 1\n6 6 5", "13_99.txt")
    lab = read_block_labels(p)
    assert lab.take == "13_99" and lab.kind == "tolerance" and lab.tolerance == 60
    assert [(t.lo, t.mid, t.hi) for t in lab.transitions] == [(0, 36, 71), (0, 60, 71)]
    assert (lab.transitions[0].before, lab.transitions[0].after) == ("JumpJack", "Twist")
    assert lab.n_frames == 72


def test_block_labels_bad_token_names_line(tmp_path):
    p = write(tmp_path, "1 1\n1 x 2\n")
    with pytest.raises(LabelError) as exc:
        read_block_labels(p)
    assert exc.value.line == 2


@pytest.mark.parametrize("token", ["nan", "inf", "-inf", "2.5"])
def test_non_integral_tokens_raise_label_error_naming_the_line(tmp_path, token):
    # "nan" / "inf" used to escape as ValueError / OverflowError without file and line
    blocks = write(tmp_path, f"1 1\n1 {token} 2\n", "13_98.txt")
    with pytest.raises(LabelError) as exc:
        read_block_labels(blocks)
    assert exc.value.line == 2 and repr(token) in str(exc.value)
    csv = write(tmp_path, f"1,2,3,4,0\n1,2,3,4,{token}\n", "13_98.csv")
    with pytest.raises(LabelError) as exc:
        read_frame_labels(csv)
    assert exc.value.line == 2 and repr(token) in str(exc.value)
    assert read_block_labels(write(tmp_path, "1 2.0 3e0\n", "13_97.txt")).n_frames == 36


def test_frame_labels_changes():
    lab = np.array([0] * 200 + [3] * 100 + [0] * 300)
    tr = transitions_from_frame_labels(lab)
    assert [(t.lo, t.mid, t.hi, t.before, t.after) for t in tr] == [
        (140, 200, 260, "0", "3"), (240, 300, 360, "3", "0")]
    assert transitions_from_frame_labels(np.zeros(50, int)) == []


def test_frame_labels_csv_and_take_meta(tmp_path):
    rows = [f"1.0,2.0,3.0,4.0,{0 if i < 150 else 2}" for i in range(400)]
    p = write(tmp_path, "\n".join(rows) + "\n", "86_50.csv")
    lab = read_frame_labels(p)
    assert [t.mid for t in lab.transitions] == [150] and lab.n_frames == 400
    take = Take(["a"], [-1], 120.0, np.tile([0, 0, 0, 1.0], (400, 1, 1)),
                source=str(p), meta={"frame_labels": np.r_[np.zeros(150), np.ones(250)]})
    assert [t.mid for t in labels_from_take(take).transitions] == [150]
    bad = write(tmp_path, "1,2,3,4,0\n1,2,3,4,z\n", "bad.csv")
    with pytest.raises(LabelError) as exc:
        read_frame_labels(bad)
    assert exc.value.line == 2


def test_find_labelled_takes_in_layout(tmp_path, caplog):
    (tmp_path / "cmu").mkdir()
    (tmp_path / "labels" / "mocap6").mkdir(parents=True)
    (tmp_path / "tsseg4d").mkdir()
    for name in ("86_01.amc", "13_29.amc", "77_01.amc", "99_01.amc"):
        (tmp_path / "cmu" / name).write_text("")
    for name in ("86.asf", "13.asf", "77.asf"):
        (tmp_path / "cmu" / name).write_text("")
    (tmp_path / "labels" / "cmu86_transitions.txt").write_text(CLEAN)
    (tmp_path / "labels" / "mocap6" / "13_29.txt").write_text("1 1 2 2")
    rows = "\n".join(f"0,0,0,0,{i // 300}" for i in range(600))
    (tmp_path / "tsseg4d" / "86_02.csv").write_text(rows)
    (tmp_path / "tsseg4d" / "86_03.csv").write_text(rows)
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        found = find_labelled_takes(tmp_path)
    got = [(t.group, t.name, t.labels.kind) for t in found]
    assert got == [("cmu", "13_29", "tolerance"), ("cmu", "86_01", "ranges"),
                   ("tsseg4d", "86_02", "ranges"), ("tsseg4d", "86_03", "tolerance")]
    assert found[1].skeleton == tmp_path / "cmu" / "86.asf"
    assert "ranges from" in found[2].label_source
    assert "+/-60" in found[3].label_source
    msgs = " ".join(r.getMessage() for r in caplog.records)
    assert "77_01.amc: no labels" in msgs and "99_01.amc: no skeleton" in msgs
    assert [t.name for t in find_labelled_takes(tmp_path, groups=["tsseg4d"])] == ["86_02", "86_03"]


# ---------------------------------------------------------------- real files

def test_real_cmu86_file(data_dir, caplog):
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        got = read_cmu86_transitions(data_dir / "labels" / "cmu86_transitions.txt")
    assert sorted(got) == [f"86_{i:02d}" for i in range(1, 15)]
    assert len(got["86_01"].transitions) == 6 and got["86_01"].n_frames == 4579
    assert [t.before for t in got["86_01"].transitions] == [
        "walk", "jump", "walk", "punch", "walk", "leg_kick"]
    # the three known slips, each repaired and logged with its block line
    repaired = {k: v.repairs for k, v in got.items() if v.repairs}
    assert sorted(repaired) == ["86_04", "86_05", "86_06"]
    assert "86_04 line 5" in repaired["86_04"][0]
    assert "86_05 line 4" in repaired["86_05"][0]
    assert "86_06 line 2" in repaired["86_06"][0]
    assert len(caplog.records) == 3
    for v in got.values():
        mids = [t.mid for t in v.transitions]
        assert mids == sorted(mids) and mids[-1] < v.n_frames
    with pytest.raises(LabelError, match=r"cmu86_transitions.txt:38"):
        read_cmu86_transitions(data_dir / "labels" / "cmu86_transitions.txt", strict=True)


def test_real_mocap6_and_tsseg4d(data_dir):
    for name, n in (("13_29", 4592), ("13_31", 3017), ("14_14", 4653)):
        lab = read_block_labels(data_dir / "labels" / "mocap6" / f"{name}.txt")
        assert 0 < len(lab.transitions) < 12
        assert abs(lab.n_frames - n) < 12
        assert all(t.mid % 12 == 0 and t.hi - t.lo == 120 for t in lab.transitions)
    lab = read_frame_labels(data_dir / "tsseg4d" / "86_01.csv")
    assert lab.n_frames == 4579
    ranges = load_cmu86_transitions(data_dir / "labels" / "cmu86_transitions.txt")["86_01"]
    # the independent per-frame annotation agrees with the ranges to within a second
    assert len(lab.transitions) == len(ranges)
    for a, b in zip(lab.transitions, ranges):
        assert abs(a.mid - b.mid) < 120


def test_real_layout_pairs_every_take(data_dir):
    found = find_labelled_takes(data_dir)
    cmu = {t.name: t for t in found if t.group == "cmu"}
    assert sorted(cmu) == ["13_29", "13_31", "14_14", "86_01"]
    assert cmu["86_01"].labels.kind == "ranges" and cmu["13_29"].labels.kind == "tolerance"
    assert cmu["14_14"].skeleton.name == "14.asf"
    ts = {t.name: t for t in found if t.group == "tsseg4d"}
    assert sorted(ts) == ["86_01", "86_02", "86_03", "86_07", "86_08"]
    assert all(t.labels.kind == "ranges" for t in ts.values())


def test_slip_logged_once_per_line_but_always_recorded(tmp_path, caplog):
    p = write(tmp_path, SLIPS)
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        first = read_cmu86_transitions(p)
        again = read_cmu86_transitions(p)
    assert len(caplog.records) == 3
    assert again["86_04"].repairs == first["86_04"].repairs != []


def test_slips_warned_only_for_the_takes_used(tmp_path, caplog):
    """A data folder whose label file has slips in blocks 86_04, 86_05 and 86_06 but whose
    only take is 86_05: finding its takes (what evaluate, plot and learn do) warns about
    86_05's slip alone; the block is still repaired, and a second search does not repeat
    the warning."""
    (tmp_path / "cmu").mkdir()
    (tmp_path / "labels").mkdir()
    (tmp_path / "cmu" / "86_05.amc").write_text("")
    (tmp_path / "cmu" / "86.asf").write_text("")
    (tmp_path / "labels" / "cmu86_transitions.txt").write_text(SLIPS)
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        found = find_labelled_takes(tmp_path)
        find_labelled_takes(tmp_path)
    slips = [r.getMessage() for r in caplog.records if "label slip" in r.getMessage()]
    assert len(slips) == 1 and "(86_05 line 2)" in slips[0], slips
    assert [t.name for t in found] == ["86_05"] and len(found[0].labels.repairs) == 1
    caplog.clear()
    labels_module._warned.clear()
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        lab = find_labels_for(tmp_path / "cmu" / "86_06.amc")          # rtseg plot's search
        read_labels_file(tmp_path / "labels" / "cmu86_transitions.txt", "86_04")
    slips = [r.getMessage() for r in caplog.records if "label slip" in r.getMessage()]
    assert len(slips) == 2 and "(86_06 line 2)" in slips[0] and "(86_04 line 3)" in slips[1]
    assert lab.take == "86_06"


def test_real_layout_warns_no_slip_for_its_takes(data_dir, caplog):
    """The published file's three slips are in 86_04-86_06, of which ../shared/data has no
    take: finding the takes (what evaluate, plot and learn do) warns about none."""
    with caplog.at_level(logging.WARNING, logger="rtseg.labels.takes"):
        found = find_labelled_takes(data_dir, GROUPS)
    assert found
    assert not [r for r in caplog.records if "label slip" in r.getMessage()]


def test_read_labels_file_tells_formats_apart(tmp_path):
    ranges = write(tmp_path, CLEAN, "any_name.txt")
    assert read_labels_file(ranges, "86_02").kind == "ranges"
    with pytest.raises(LabelError, match="no block for take 86_09"):
        read_labels_file(ranges, "86_09")
    blocks = write(tmp_path, "2 2 2 3 3", "x.txt")
    assert [t.mid for t in read_labels_file(blocks, "13_01").transitions] == [36]
    rows = write(tmp_path, "\n".join(f"0,0,0,0,{i // 100}" for i in range(200)), "y.csv")
    assert [t.mid for t in read_labels_file(rows, "86_01").transitions] == [100]
    with pytest.raises(FileNotFoundError):
        read_labels_file(tmp_path / "missing.txt", "86_01")


def test_find_labels_for_motion_in_layout(tmp_path):
    (tmp_path / "cmu").mkdir()
    (tmp_path / "labels" / "mocap6").mkdir(parents=True)
    (tmp_path / "labels" / "cmu86_transitions.txt").write_text(CLEAN)
    (tmp_path / "labels" / "mocap6" / "13_29.txt").write_text("1 2")
    assert find_labels_for(tmp_path / "cmu" / "86_01.amc").kind == "ranges"
    assert find_labels_for(tmp_path / "cmu" / "13_29.amc").transitions[0].mid == 12
    assert find_labels_for(tmp_path / "cmu" / "55_01.bvh") is None


def test_find_labels_for_reads_the_ranges_an_npz_take_carries(tmp_path):
    """``rtseg plot take.npz`` (labels auto) said 'no labels found' for a synthetic take
    saved with its ground truth, which rtseg evaluate scores: the ranges are read too."""
    from rtseg.drivers.readers import write_take
    from rtseg.labels.takes import find_labels_for
    from rtseg.simulators.synth.motion import synthesize
    path = write_take(tmp_path / "s.npz", synthesize("idle:2,walk:2", frame_rate=30).take)
    labels = find_labels_for(path)
    assert labels is not None and len(labels.transitions) == 1
    assert "meta transitions" in labels.source
