"""Scoring at a tolerance, detection delays and ``rtseg evaluate --online`` (what the live
loop would have sent), on synthetic takes in a folder laid out like ../shared/data and on
the real cmu takes when present."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rtseg.cli import main
from rtseg.drivers.readers import write_take
from rtseg.evaluation.scoring import detection_delays, score, widen
from rtseg.labels.takes import Transition
from rtseg.evaluation.online import live_config, live_cuts
from rtseg.simulators.synth.motion import synthesize

SCRIPT = "idle:5,walk:6,punch:6,squat:6"


def test_widen_and_tolerance_scoring():
    tr = [Transition(lo=100, hi=150, mid=120), Transition(lo=30, hi=40, mid=35)]
    w = widen(tr, 60)
    assert [(t.lo, t.hi, t.mid) for t in w] == [(40, 210, 120), (0, 100, 35)]
    cuts = [205, 95]                            # both outside the ranges, inside the widened
    assert score(cuts, tr).tp == 0
    assert score(cuts, w).tp == 2
    assert score(cuts, widen(tr, 0)).tp == 0
    with pytest.raises(ValueError):
        widen(tr, -1)


def test_detection_delays_are_from_the_labelled_mid():
    tr = [Transition(lo=100, hi=200, mid=150), Transition(lo=500, hi=600, mid=550)]
    s = score([160, 530, 900], tr)
    d = detection_delays(s, {160: 400, 530: 790, 900: 1000}, tr, 120.0)
    assert d == pytest.approx([(400 - 150) / 120, (790 - 550) / 120])


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    (root / "cmu").mkdir()
    (root / "labels").mkdir()
    res = synthesize(SCRIPT, seed=7)
    write_take(root / "cmu" / "92_01.npz", res.take)
    lines = ["92 01"] + [f"{t.before} {t.lo + 1} {t.mid + 1} {t.hi + 1}" for t in res.transitions]
    n = res.take.n_frames
    lines.append(f"{res.segments[-1].name} {n} {n} {n}")
    (root / "labels" / "cmu86_transitions.txt").write_text("\n".join(lines) + "\n")
    return root, res


def test_evaluate_online_json(synth_dir, capsys):
    root, res = synth_dir
    rc = main(["evaluate", str(root), "--online", "--json", "--no-progress"])
    out = capsys.readouterr().out
    assert rc == 0
    doc = json.loads(out)
    assert doc["live_default"] == "contrast"
    assert sorted(k for k in doc if k != "live_default") == ["contrast", "pca", "ppca"]
    r = doc["contrast"]
    assert r["online"] is True and r["tolerance_s"] == 0.5
    p = r["pooled"]
    assert p["transitions"] == 3 and p["f1"] == 1.0
    assert set(p["strict"]) == {"precision", "recall", "f1"}
    # delays: from each labelled mid to the frame that produced the cut, as live_cuts says
    cfg, _ = live_config(methods=["contrast"])
    cuts = live_cuts(res.take, cfg)["contrast"]
    mids = [t.mid for t in res.transitions]
    expect = sorted((c.detected - min(mids, key=lambda m: abs(m - c.boundary))) / 120.0
                    for c in cuts)
    take = r["takes"]["92_01"]
    assert take["cut_frames"] == [c.boundary for c in cuts]
    assert take["detected_frames"] == [c.detected for c in cuts]
    assert sorted(m["delay_s"] for m in take["matched"]) == pytest.approx(expect, abs=1e-4)
    assert p["delay_s"]["median"] == pytest.approx(float(np.median(expect)))
    assert p["delay_s"]["p90"] == pytest.approx(float(np.percentile(expect, 90)))
    # no cut is known before the 2 s after window has arrived (1.5 s with the pre-look)
    assert 0.5 < p["delay_s"]["median"] < 3.5


def test_evaluate_online_with_the_shipped_parameter_sets(synth_dir, capsys):
    """``--online --params full`` / ``fast`` run the live loop with config/full.toml /
    config/fast.toml: the same changes found, each sent sooner by the defaults than by
    the full look, and by ``fast`` no later than by the defaults."""
    root, _ = synth_dir
    doc = {}
    for name, extra in (("default", []), ("full", ["--params", "full"]),
                        ("fast", ["--params", "fast"])):
        assert main(["evaluate", str(root), "--online", "--json", "--no-progress",
                     "--method", "contrast", *extra]) == 0
        r = json.loads(capsys.readouterr().out)["contrast"]
        assert r.get("params_file") == (extra[1] if extra else None)   # which file, if any
        doc[name] = r["takes"]["92_01"]
    assert doc["fast"]["f1"] == doc["default"]["f1"] == doc["full"]["f1"] == 1.0
    d = {k: sorted(m["delay_s"] for m in v["matched"]) for k, v in doc.items()}
    assert all(f < g for f, g in zip(d["default"], d["full"])), d
    assert all(f <= g for f, g in zip(d["fast"], d["default"])), d


def test_evaluate_tolerance_zero_equals_strict(synth_dir, capsys):
    root, _ = synth_dir
    assert main(["evaluate", str(root), "--tolerance", "0", "--json", "--no-progress",
                 "--method", "pca"]) == 0
    r = json.loads(capsys.readouterr().out)["pca"]["pooled"]
    assert r["f1"] == r["strict"]["f1"] and r["precision"] == r["strict"]["precision"]


@pytest.mark.parametrize("args", [["--tolerance", "-1"], ["--tolerance", "nan"],
                                  ["--online", "--method", "gmm"],
                                  ["--config", "x.toml"],
                                  ["--online", "--params", "x.toml"],
                                  ["--online", "--identity", "--params", "x.toml"]])
def test_evaluate_bad_options_one_line(synth_dir, capsys, args):
    root, _ = synth_dir
    rc = main(["evaluate", str(root), "--no-progress", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("rtseg evaluate:")


@pytest.mark.realdata
def test_real_cmu_online_default_detector(data_dir, capsys):
    """The default live detector on the four cmu takes: the shipped defaults' figure."""
    assert main(["evaluate", str(data_dir), "--online", "--json", "--no-progress",
                 "--method", "contrast"]) == 0
    doc = json.loads(capsys.readouterr().out)
    p = doc["contrast"]["pooled"]
    assert p["transitions"] == 22
    assert p["f1"] >= 0.88, p
    assert p["delay_s"]["median"] <= 2.5 and p["delay_s"]["p90"] <= 3.5, p


def test_tally_and_pooled_tally():
    from rtseg.evaluation.scoring import pooled_tally, tally
    tr = [Transition(lo=100, hi=200, mid=150), Transition(lo=500, hi=600, mid=550)]
    row = tally([(230, 400), (900, 1000)], tr, 120.0, 0.5)       # 230: only within 0.5 s
    assert row[:4] == (1, 2, 2, 0)
    assert row[4] == pytest.approx([(400 - 150) / 120])
    p = pooled_tally([row, tally([], tr, 120.0)])
    assert (p["cuts"], p["transitions"]) == (2, 4)
    assert p["f1"] == pytest.approx(2 * 1 / (2 + 4)) and p["strict_f1"] == 0.0
    assert p["delay_median"] == pytest.approx(250 / 120)


def test_recall_by_length_bins_each_transition_by_its_neighbouring_segments(tmp_path, capsys):
    """benchmarks/recall_by_length.py: a transition counts in the bin of the segment before
    it (and, separately, after it); empty bins say None; a missing folder is exit 2."""
    import sys
    from pathlib import Path
    bench = str(Path(__file__).resolve().parents[1] / "benchmarks")
    sys.path.insert(0, bench)
    try:
        import recall_by_length as rbl
    finally:
        sys.path.remove(bench)
    rows = [("spliced", False, 2.0, 6.0), ("spliced", True, 3.0, 8.0),
            ("spliced", True, 6.0, 2.5), ("spliced", True, 9.0, 4.0)]
    before = rbl.binned(rows, 2)
    assert [(b["transitions"], b["recall"]) for b in before] == [(2, 0.5), (0, None), (1, 1.0), (1, 1.0)]
    after = rbl.binned(rows, 3)
    assert [(b["transitions"], b["recall"]) for b in after] == [(1, 1.0), (1, 1.0), (1, 0.0), (1, 1.0)]
    assert rbl.main([str(tmp_path / "absent")]) == 2
    assert "is not a folder" in capsys.readouterr().err
