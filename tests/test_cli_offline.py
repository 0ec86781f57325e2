"""Offline commands end to end: ``rtseg segment``, ``rtseg evaluate``, ``rtseg plot`` and
``benchmarks/accuracy.py`` through ``rtseg.cli.main`` (one call through the installed
console script), on synthetic takes written to a data folder laid out like ../shared/data,
and on real 86_01 (skipped without the data)."""

from __future__ import annotations

import csv
import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtseg.cli import main
from rtseg.drivers.readers import write_take
from rtseg.evaluation.scoring import score, widen
from rtseg.labels.takes import read_cmu86_transitions
from rtseg.simulators.synth.motion import synthesize

REPO = Path(__file__).resolve().parent.parent
SCRIPT_A = "idle:4,walk:6,punch:6,squat:5"
SCRIPT_B = "walk:5,jumping_jacks:5,arm_circles:5"


def _cmu86_block(name: str, result) -> str:
    """A cmu86_transitions.txt block for a synthetic take (1-based, behaviour lo mid hi)."""
    ss, tt = name.split("_")
    lines = [f"{ss} {tt}"]
    for t in result.transitions:
        lines.append(f"{t.before} {t.lo + 1} {t.mid + 1} {t.hi + 1}")
    n = result.take.n_frames
    lines.append(f"{result.segments[-1].name} {n} {n} {n}")
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory) -> dict:
    """cmu/90_01.npz (labels: cmu86-style ranges), cmu/91_01.npz (labels: mocap6 blocks),
    tsseg4d/90_05.csv (4 channels + per-frame labels)."""
    root = tmp_path_factory.mktemp("data")
    (root / "cmu").mkdir()
    (root / "labels" / "mocap6").mkdir(parents=True)
    (root / "tsseg4d").mkdir()
    a = synthesize(SCRIPT_A, seed=1)
    b = synthesize(SCRIPT_B, seed=2)
    write_take(root / "cmu" / "90_01.npz", a.take)
    write_take(root / "cmu" / "91_01.npz", b.take)
    (root / "labels" / "cmu86_transitions.txt").write_text(_cmu86_block("90_01", a))
    blocks = b.frame_labels()[::12] + 1
    (root / "labels" / "mocap6" / "91_01.txt").write_text(" ".join(map(str, blocks)))
    # four channels: x-angles of upper arms and legs, different rhythm per segment
    rng = np.random.default_rng(3)
    n = 1800
    lab = np.repeat([0, 1, 2], n // 3)
    t = np.arange(n) / 120.0
    freq = np.array([0.5, 1.5, 0.8])[lab]
    amp = np.array([[10, 10, 5, 5], [40, 40, 30, 30], [60, 5, 5, 60]])[lab]
    ang = amp * np.sin(2 * np.pi * freq[:, None] * t[:, None] + np.array([0, np.pi, np.pi, 0]))
    ang += rng.normal(0, 0.5, ang.shape)
    with open(root / "tsseg4d" / "90_05.csv", "w") as fh:
        for row, l in zip(ang, lab):
            fh.write(",".join(f"{v:.4f}" for v in row) + f",{l}\n")
    return {"root": root, "a": a, "b": b}


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


# ------------------------------------------------------------------------ segment

def test_segment_json_all_methods(synth_dir, capsys):
    take = synth_dir["root"] / "cmu" / "90_01.npz"
    rc, out, _ = run_cli(capsys, "segment", take, "--format", "json")
    assert rc == 0
    doc = json.loads(out)
    n = synth_dir["a"].take.n_frames
    assert doc["n_frames"] == n and doc["frame_rate"] == 120.0
    assert sorted(doc["methods"]) == ["contrast", "gmm", "pca", "ppca"]
    for m, r in doc["methods"].items():
        frames = [c["frame"] for c in r["cuts"]]
        assert frames == sorted(set(frames)) and all(0 < f < n for f in frames)
        segs = r["segments"]
        # segments tile the take and start exactly at the cuts
        assert segs[0]["start"] == 0 and segs[-1]["end"] == n
        assert [s["start"] for s in segs[1:]] == frames
        assert all(s["end"] == nxt["start"] for s, nxt in zip(segs, segs[1:]))
        for s in segs:
            assert s["duration"] == pytest.approx((s["end"] - s["start"]) / 120.0, abs=1e-5)
        for c in r["cuts"]:
            assert c["time"] == pytest.approx(c["frame"] / 120.0, abs=1e-5)


def test_segment_table_and_csv(synth_dir, capsys):
    take = synth_dir["root"] / "cmu" / "90_01.npz"
    rc, table, _ = run_cli(capsys, "segment", take, "--method", "gmm")
    assert rc == 0
    assert "2520 frames at 120 fps" in table and "gmm:" in table and "ppca:" not in table
    rc, out, _ = run_cli(capsys, "segment", take, "--method", "gmm", "--format", "csv")
    assert rc == 0
    rows = list(csv.DictReader(io.StringIO(out)))
    assert rows and {r["method"] for r in rows} == {"gmm"}
    assert rows[0]["start_frame"] == "0" and rows[0]["cut_confidence"] == ""
    assert rows[-1]["end_frame"] == "2520"
    # the table lists the same segments as the CSV
    for r in rows:
        assert f"{int(r['start_frame']):>7} {int(r['end_frame']):>7}" in table


def test_segment_params_file_changes_the_result(synth_dir, capsys, tmp_path):
    take = synth_dir["root"] / "cmu" / "90_01.npz"
    strict = tmp_path / "p.toml"
    strict.write_text("[pca]\nmin_contrast = 1000.0\n")
    rc, out, _ = run_cli(capsys, "segment", take, "--method", "pca", "--format", "json",
                         "--params", strict)
    assert rc == 0 and json.loads(out)["methods"]["pca"]["cuts"] == []
    flat = tmp_path / "flat.json"
    flat.write_text(json.dumps({"variant": "paper", "k_sigma": 1000.0}))
    rc, out, _ = run_cli(capsys, "segment", take, "--method", "pca", "--format", "json",
                         "--params", flat)
    assert rc == 0 and json.loads(out)["methods"]["pca"]["cuts"] == []
    bad = tmp_path / "bad.toml"
    bad.write_text("[pca]\nno_such_knob = 1\n")
    rc, _, err = run_cli(capsys, "segment", take, "--method", "pca", "--params", bad)
    assert rc == 2 and "no_such_knob" in err


def test_segment_bad_input_is_a_clear_error(tmp_path, capsys):
    rc, out, err = run_cli(capsys, "segment", tmp_path / "missing.npz")
    assert rc == 2 and out == "" and "missing.npz" in err
    junk = tmp_path / "junk.bvh"
    junk.write_text("this is not a BVH file\n")
    rc, _, err = run_cli(capsys, "segment", junk)
    assert rc == 2 and "junk.bvh" in err


def record_frames(folder, take, rows) -> None:
    """A session recording in ``folder`` of ``take``'s frames ``rows`` (sequence number and
    source clock = the take frame, so left-out rows are frames the source lost)."""
    from rtseg.core.frame import Frame
    from rtseg.recording import SessionRecorder
    fr = take.frame_rate
    rec = SessionRecorder(folder, take.joint_names, take.parents, space=take.space,
                          frame_rate=fr, start_monotonic=0.0)
    for i in rows:
        rec.record_frame(Frame(recv_time=i / fr, quats=take.quats[i],
                               valid=np.ones(take.n_joints, bool), source_time=i / fr, seq=i))
    rec.close()


def test_segment_of_a_recording_with_lost_frames_says_so(synth_dir, capsys, tmp_path):
    """A session recording misses the frames its source lost (sequence gaps): ``rtseg
    segment`` numbers and times the recorded frames, so after a gap its times ran early
    by the frames lost, without a word (a real serial session, 9 % lost: 1.7 s early at
    15 s).  It now warns with the frames lost and the gaps; a recording without gaps (or a
    file take) gives no warning."""
    from rtseg.recording import read_session
    take = synth_dir["a"].take
    keep = [i for i in range(1200) if not (300 <= i < 330 or 600 <= i < 610)]
    for name, rows in (("gappy", keep), ("whole", range(1200))):
        record_frames(tmp_path / name, take, rows)
    tk = read_session(tmp_path / "gappy")
    assert (tk.n_frames, tk.meta["missing_frames"], tk.meta["gaps"]) == (1160, 40, 2)
    rc, out, err = run_cli(capsys, "segment", tmp_path / "gappy", "--method", "pca")
    assert rc == 0 and out.startswith(f"{tmp_path / 'gappy'}: 1160 frames")
    assert "warning" in err and "40 frames that are not in this recording (2 gaps)" in err
    rc, out, err = run_cli(capsys, "segment", tmp_path / "whole", "--method", "pca")
    assert rc == 0 and read_session(tmp_path / "whole").meta["missing_frames"] == 0
    assert "not in this recording" not in err


def test_segment_archive_of_recordings_with_lost_frames_says_so(synth_dir, capsys, tmp_path):
    """The archive path (``rtseg segment DIR --out F``) segmented a recording that misses
    frames its source sent without a word (only the one-take path warned); its records now
    hold missing_frames and gaps and one warning names the recordings."""
    import json
    take = synth_dir["a"].take
    keep = [i for i in range(400) if not 100 <= i < 110]
    for name, rows in (("gappy", keep), ("whole", range(400))):
        record_frames(tmp_path / "recs" / name, take, rows)
    out_file = tmp_path / "r.jsonl"
    rc, out, err = run_cli(capsys, "segment", tmp_path / "recs", "--method", "contrast",
                           "--out", out_file, "--no-progress")
    recs = {r["take"]: r for r in map(json.loads, out_file.read_text().splitlines())}
    assert rc == 0 and (recs["gappy"]["missing_frames"], recs["gappy"]["gaps"]) == (10, 1)
    assert "missing_frames" not in recs["whole"]
    assert "1 recorded session(s) miss frames" in err and "gappy (10)" in err


def test_segment_with_a_bvh_as_skeleton_says_what_a_skeleton_is(tmp_path, capsys):
    """``--skeleton`` given a BVH: one line saying the skeleton must be an ASF and that a
    BVH take carries its own (not "line outside any section: 'HIERARCHY'")."""
    amc = tmp_path / "86_01.amc"
    amc.write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\n")
    bvh = tmp_path / "86_01.bvh"
    bvh.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xrotation "
                   "Yrotation Zrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.0083\n0 0 0\n")
    rc, out, err = run_cli(capsys, "segment", amc, "--skeleton", bvh)
    assert rc == 2 and out == "" and len(err.splitlines()) == 1
    assert f"{bvh}:1: is a BVH file" in err and "not an ASF skeleton" in err
    assert "needs its Acclaim .asf" in err and "a .bvh take carries its own skeleton" in err
    assert "outside any section" not in err


# ------------------------------------------------------------------------ evaluate

def test_evaluate_json_synthetic(synth_dir, capsys):
    root = synth_dir["root"]
    rc, out, err = run_cli(capsys, "evaluate", root, "--json")
    assert rc == 0
    doc = json.loads(out)
    assert sorted(doc) == ["contrast", "gmm", "pca", "ppca"]     # offline: no live_default
    truth = read_cmu86_transitions(root / "labels" / "cmu86_transitions.txt")["90_01"]
    wide = widen(truth.transitions, 60)                           # 0.5 s at 120 fps
    for m, r in doc.items():
        assert r["tolerance_s"] == 0.5 and r["online"] is False
        assert sorted(r["takes"]) == ["90_01", "91_01"]
        assert set(r["pooled"]) >= {"precision", "recall", "f1", "cuts", "transitions", "strict"}
        assert "delay_s" not in r["pooled"]
        assert r["pooled"]["transitions"] == 3 + 2
        assert r["pooled"]["cuts"] == sum(t["cuts"] for t in r["takes"].values())
        tp = sum(t["tp"] for t in r["takes"].values())
        assert r["pooled"]["precision"] == pytest.approx(tp / r["pooled"]["cuts"]
                                                         if r["pooled"]["cuts"] else 1.0)
        a = r["takes"]["90_01"]
        assert a["labels"].startswith("ranges") and a["group"] == "cmu"
        assert r["takes"]["91_01"]["labels"].startswith("points +/-60")
        # the per-take counts are the scoring of the reported cuts against the labels
        # widened by the tolerance; "strict" against the labelled ranges themselves
        s = score(a["cut_frames"], wide)
        assert (a["tp"], a["fp"], a["fn"]) == (s.tp, s.fp, s.fn)
        assert a["strict"]["f1"] == pytest.approx(score(a["cut_frames"], truth.transitions).f1)
        assert len(a["matched"]) == a["tp"]
        by_mid = {t.mid: t for t in wide}
        for mt in a["matched"]:
            assert by_mid[mt["mid"]].contains(mt["cut"]) and mt["cut"] in a["cut_frames"]
    assert "2/2" in err   # progress on stderr, not stdout


def test_evaluate_table_groups_and_benchmark(synth_dir, capsys):
    root = synth_dir["root"]
    rc, out, _ = run_cli(capsys, "evaluate", root, "--method", "pca", "--group", "all",
                         "--no-progress")
    assert rc == 0
    assert "POOLED cmu" in out and "POOLED tsseg4d" in out and "POOLED all" in out
    assert "90_05" in out and "tsseg4d/90_05.csv column 5" in out
    rc, out, err = run_cli(capsys, "evaluate", root, "--method", "pca", "--group", "tsseg4d",
                           "--json")
    assert rc == 0
    doc = json.loads(out)
    assert list(doc["pca"]["takes"]) == ["90_05"]
    assert doc["pca"]["pooled"]["transitions"] == 2

    sys.path.insert(0, str(REPO / "benchmarks"))
    try:
        import accuracy
    finally:
        sys.path.remove(str(REPO / "benchmarks"))
    rc = accuracy.main([str(root), "--method", "pca", "--json", "--no-progress"])
    bench = json.loads(capsys.readouterr().out)
    assert rc == 0 and bench["pca"]["pooled"] == json.loads(
        _evaluate_json(capsys, root, "pca"))["pca"]["pooled"]


def _evaluate_json(capsys, root, method):
    rc, out, _ = run_cli(capsys, "evaluate", root, "--method", method, "--json", "--no-progress")
    assert rc == 0
    return out


def test_evaluate_reports_unreadable_take_and_continues(synth_dir, capsys, tmp_path):
    root = tmp_path / "d"
    shutil.copytree(synth_dir["root"], root)
    (root / "cmu" / "90_02.npz").write_bytes(b"not an npz")
    with open(root / "labels" / "cmu86_transitions.txt", "a") as fh:
        fh.write("\n90 02\nwalk 100 120 140\nrun 500 500 500\n")
    rc, out, err = run_cli(capsys, "evaluate", root, "--method", "pca", "--json", "--no-progress")
    assert rc == 1 and "90_02" in err
    doc = json.loads(out)
    assert sorted(doc["pca"]["takes"]) == ["90_01", "91_01"]
    assert "90_02" in doc["pca"]["errors"]


def test_evaluate_empty_folder(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "evaluate", tmp_path)
    assert rc == 2 and "no labelled takes" in err
    rc, _, err = run_cli(capsys, "evaluate", tmp_path / "nope")
    assert rc == 2 and "does not exist" in err



@pytest.mark.parametrize("n", ["0", "-2", "two"])
def test_evaluate_workers_below_one_is_refused(synth_dir, capsys, n):
    """``--workers 0`` (or less, or not a number) is refused with one line."""
    rc, out, err = run_cli(capsys, "evaluate", synth_dir["root"], "--workers", n)
    assert rc == 2 and out == ""
    assert "argument --workers: " in err
    assert ("must be at least 1" if n != "two" else "not a whole number") in err


def test_evaluate_says_how_to_score_single_behaviour_takes(tmp_path, capsys):
    """A folder of single-behaviour takes (laid out like cmu_single) has no transitions:
    the error says so and names the splicer, for the folder and for its parent."""
    src = tmp_path / "d" / "cmu_single"
    (src / "bvh").mkdir(parents=True)
    (src / "index.tsv").write_text("name\tsubject\tbehaviour\tpath\n")
    rc, _, err = run_cli(capsys, "evaluate", tmp_path / "d")
    assert rc == 2 and "no labelled takes" in err
    assert "single-behaviour takes" in err and f"splice.py {src} OUT" in err
    rc, _, err = run_cli(capsys, "evaluate", src, "--online", "--identity")
    assert rc == 2 and f"splice.py {src} OUT" in err
    rc, _, err = run_cli(capsys, "evaluate", tmp_path)        # nothing of the kind
    assert rc == 2 and "no labelled takes" in err and "splice" not in err


def test_evaluate_names_the_splicer_for_a_parent_of_any_source_folder(tmp_path, capsys):
    """A folder laid out like ../shared/data holding hdm05/ (or bandai/) alone, no
    cmu_single/: the error names that source folder and the splicer, as for cmu_single."""
    src = tmp_path / "d" / "hdm05"
    (src / "amc").mkdir(parents=True)
    (src / "index.tsv").write_text("take\tsubject\tformat\tbehaviour\n")
    for extra in ([], ["--online", "--identity"]):
        rc, _, err = run_cli(capsys, "evaluate", tmp_path / "d", *extra)
        assert rc == 2 and "no labelled takes" in err
        assert f"{src} holds single-behaviour takes" in err and f"splice.py {src} OUT" in err

# ------------------------------------------------------------------------ plot

def test_plot_writes_png(synth_dir, capsys, tmp_path):
    root = synth_dir["root"]
    out = tmp_path / "a.png"
    rc, stdout, _ = run_cli(capsys, "plot", root / "cmu" / "90_01.npz", "-o", out)
    assert rc == 0 and stdout.strip() == str(out)
    data = out.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    # explicit label file of another format, one method
    out2 = tmp_path / "b.png"
    rc, _, _ = run_cli(capsys, "plot", root / "cmu" / "91_01.npz", "--method", "gmm",
                       "--labels", root / "labels" / "mocap6" / "91_01.txt", "-o", out2)
    assert rc == 0 and out2.read_bytes()[:4] == b"\x89PNG"
    rc, _, err = run_cli(capsys, "plot", root / "cmu" / "91_01.npz", "--method", "gmm",
                         "--labels", tmp_path / "nolabels.txt", "-o", out2)
    assert rc == 2 and "nolabels.txt" in err


def _png_title(path: Path) -> str:
    """The ``Title`` tEXt chunk of a PNG (read with Pillow, matplotlib's own dependency)."""
    from PIL import Image
    with Image.open(path) as im:
        return im.info["Title"]


def test_plot_legends_leave_every_panel_clear(synth_dir):
    """Each panel's legend lies outside its axes, right of it: it hides no curve (the scan
    panel's contrast peaks included)."""
    from rtseg.commands.plot import figure, pca_with_band, scan_profiles
    from rtseg.labels.takes import find_labels_for
    from rtseg.detectors.segmentation import compute_features, segment_take
    path = synth_dir["root"] / "cmu" / "90_01.npz"
    take = synth_dir["a"].take
    X = compute_features(take)
    results = {m: segment_take(take, m, None, keep_trace=True, features=X)
               for m in ("pca", "ppca")}
    fig, _ = figure("90_01", take.n_frames, take.frame_rate, results, find_labels_for(path),
                    pca_with_band(X, take.frame_rate, None),
                    scan_profiles(X, take.frame_rate, {"pca": None, "ppca": None}))
    fig.canvas.draw()
    legends = 0
    for ax in fig.axes:
        leg = ax.get_legend()
        if leg is None:
            continue
        legends += 1
        box, area = leg.get_window_extent(), ax.get_window_extent()
        assert box.x0 >= area.x1 - 0.5, (ax.get_title(), box, area)
        # and inside the figure
        assert box.x1 <= fig.bbox.x1 + 0.5 and box.y0 >= fig.bbox.y0 - 0.5
    assert legends == 3
    import matplotlib.pyplot as plt
    plt.close(fig)


@pytest.mark.realdata
def test_plot_title_gives_the_scores_evaluate_gives(data_dir, capsys, tmp_path):
    """86_01, PCA: the plot's title gives evaluate's F1 (P, R) at the default 0.5 s
    tolerance - 1.000, where the strict score is lower - with the strict F1 beside it, both
    labelled; --tolerance 0 makes them one."""
    data = tmp_path / "data"
    (data / "cmu").mkdir(parents=True)
    (data / "labels").mkdir()
    for name in ("86_01.amc", "86.asf"):
        (data / "cmu" / name).symlink_to(data_dir / "cmu" / name)
    (data / "labels" / "cmu86_transitions.txt").symlink_to(
        data_dir / "labels" / "cmu86_transitions.txt")
    rc, out, _ = run_cli(capsys, "evaluate", data, "--method", "pca", "--json",
                         "--no-progress")
    assert rc == 0
    take = json.loads(out)["pca"]["takes"]["86_01"]
    f1, strict = take["f1"], take["strict"]["f1"]
    assert strict < f1                            # the two differ on this take
    png = tmp_path / "p.png"
    rc, _, _ = run_cli(capsys, "plot", data / "cmu" / "86_01.amc", "--method", "pca",
                       "-o", png)
    assert rc == 0
    title = _png_title(png)
    assert "with cuts within ±0.5 s of a labelled range" in title, title
    assert (f"pca: F1 {f1:.3f} (P {take['precision']:.3f}, R {take['recall']:.3f}), "
            f"strict F1 {strict:.3f}") in title, title
    rc, _, _ = run_cli(capsys, "plot", data / "cmu" / "86_01.amc", "--method", "pca",
                       "--tolerance", "0", "-o", png)
    assert rc == 0
    assert f"pca: F1 {strict:.3f}" in _png_title(png) and "±0 s" in _png_title(png)


def _result(method: str, frames: list[int], n_frames: int = 2400):
    """A segmentation result with cuts at ``frames`` (120 fps)."""
    from rtseg.detectors.base import Cut
    from rtseg.detectors.segmentation import SegmentationResult, segments_between
    return SegmentationResult(method, [Cut(f, method) for f in frames],
                              segments_between(frames, n_frames, 120.0), 120.0, n_frames)


def test_plot_title_scores_at_the_default_tolerance_and_labels_it():
    """Three transitions, one cut 30 frames (0.25 s) past its range: the title gives F1
    1.000 at the default +-0.5 s, says so, and gives the strict 0.667 beside it, labelled
    strict - never the strict figures alone."""
    from rtseg.commands.plot import DEFAULT_TOLERANCE_S, score_line
    from rtseg.labels.types import Transition, TransitionLabels
    labels = TransitionLabels("90_01", [Transition(560, 640, 600), Transition(1160, 1240, 1200),
                                        Transition(1760, 1840, 1800)])
    results = {"pca": _result("pca", [600, 1200, 1870])}
    assert DEFAULT_TOLERANCE_S == 0.5
    line = score_line(results, labels, 120.0)
    assert "with cuts within ±0.5 s of a labelled range" in line, line
    assert "pca: F1 1.000 (P 1.000, R 1.000), strict F1 0.667" in line, line
    strict = score_line(results, labels, 120.0, tolerance_s=0.0)
    assert "±0 s" in strict and "pca: F1 0.667 (P 0.667, R 0.667)" in strict, strict


def test_plot_to_a_missing_folder_fails_at_once(synth_dir, capsys, tmp_path, monkeypatch):
    """``plot -o missing/dir/x.png`` is refused before any segmentation, with one line
    naming the folder (no errno text)."""
    import rtseg.commands.plot as plot_cmd
    ran, real = [], plot_cmd.segment_take         # a spy: counts the real calls
    monkeypatch.setattr(plot_cmd, "segment_take",
                        lambda *a, **k: (ran.append(1), real(*a, **k))[1])
    out = tmp_path / "missing" / "dir" / "x.png"
    rc, _, err = run_cli(capsys, "plot", synth_dir["root"] / "cmu" / "90_01.npz", "-o", out)
    assert rc == 2 and not ran
    assert f"rtseg plot: error: cannot write {out}: folder {out.parent} does not exist" in err
    assert "Errno" not in err


def test_plot_without_matplotlib_is_a_clear_error(synth_dir, capsys, tmp_path, monkeypatch):
    for mod in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    out = tmp_path / "x.png"
    rc, _, err = run_cli(capsys, "plot", synth_dir["root"] / "cmu" / "90_01.npz", "-o", out)
    assert rc == 2 and "rtseg[plot]" in err and not out.exists()


def test_pca_band_reproduces_the_detector(synth_dir):
    """The plot's PCA run finds the same cuts as ``rtseg segment`` and its mean/std band
    reproduces the detector's threshold."""
    from rtseg.commands.plot import pca_with_band
    from rtseg.detectors.segmentation import compute_features, segment_take
    take = synth_dir["a"].take
    X = compute_features(take)
    band = pca_with_band(X, take.frame_rate, None)
    # the band is the online pass: the offline "paper" variant (the default "verified"
    # variant adds a backward pass and a check, see docs/detectors.md)
    assert band.cut_frames == segment_take(take, "pca", {"variant": "paper"},
                                           features=X).cut_frames
    tr = band.trace
    assert "mean" in tr and len(tr["mean"]) == len(tr["d"]) > 0
    assert np.allclose(tr["mean"] + 3.0 * tr["std"], tr["threshold"])


def test_scan_profiles_are_the_ones_the_offline_cuts_come_from(synth_dir):
    """The plot's scan panel draws the contrast whose maxima are the offline PCA cuts
    (and PPCA's changes before placement); paper variants have no scan."""
    from rtseg.commands.plot import scan_profiles
    from rtseg.detectors import method_params
    from rtseg.detectors._scan import local_maxima
    from rtseg.detectors.segmentation import compute_features, segment_take
    take = synth_dir["a"].take
    X = compute_features(take)
    prof = scan_profiles(X, take.frame_rate, {"pca": None, "ppca": None})
    assert set(prof) == {"pca", "ppca"}
    p = prof["pca"]
    assert p["threshold"] == method_params("pca")["min_contrast"]
    assert len(p["frame"]) == len(p["contrast"]) > 10
    sep = round(take.frame_rate * sum(method_params("pca")["scan_windows_s"]) / 3)
    maxima = [f for f, _ in local_maxima(p["frame"], p["contrast"], p["threshold"], sep)]
    cuts = segment_take(take, "pca", None, features=X).cut_frames
    assert maxima == cuts and cuts
    q = prof["ppca"]
    ppca_cuts = segment_take(take, "ppca", None, features=X).cut_frames
    big = [f for f, k in zip(q["frame"], q["contrast"]) if np.isfinite(k) and k >= q["threshold"]]
    assert all(any(abs(c - f) <= 180 for f in big) for c in ppca_cuts)
    assert scan_profiles(X, take.frame_rate, {"pca": {"variant": "paper"},
                                              "ppca": {"variant": "paper"}}) == {}


# ------------------------------------------------------------------------ console script

def test_console_script_segment_json(synth_dir):
    exe = shutil.which("rtseg")
    cmd = [exe] if exe else [sys.executable, "-m", "rtseg.cli"]
    proc = subprocess.run(cmd + ["segment", str(synth_dir["root"] / "cmu" / "91_01.npz"),
                                 "--method", "pca", "--format", "json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["n_frames"] == synth_dir["b"].take.n_frames
    assert list(doc["methods"]) == ["pca"]


# ------------------------------------------------------------------------ real data

@pytest.mark.realdata
def test_real_86_01_segment_and_evaluate(data_dir, capsys):
    rc, out, _ = run_cli(capsys, "segment", data_dir / "cmu" / "86_01.amc", "--method", "pca",
                         "--format", "json")
    assert rc == 0
    doc = json.loads(out)
    assert doc["n_frames"] == 4579
    segs = doc["methods"]["pca"]["segments"]
    assert segs[0]["start"] == 0 and segs[-1]["end"] == 4579
    rc, out, _ = run_cli(capsys, "evaluate", data_dir, "--method", "pca", "--json",
                         "--no-progress")
    assert rc == 0
    r = json.loads(out)["pca"]
    assert "86_01" in r["takes"] and r["takes"]["86_01"]["transitions"] == 6
    assert r["takes"]["86_01"]["cut_frames"] == [c["frame"] for c in doc["methods"]["pca"]["cuts"]]
    assert r["pooled"]["transitions"] == sum(t["transitions"] for t in r["takes"].values())
