"""``rtseg evaluate DIR --online --identity --behaviours LIB --json``: ``identity.named``
over the segments the live loop named, on synthetic performances saved as labelled takes
(a library learned from two synthetic performers names two others)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from rtseg.library.file import save as save_library
from rtseg.drivers.readers import write_take
from rtseg.evaluation.library import Named, named_summary
from rtseg.evaluation.online import live_config
from rtseg.simulators.synth.motion import synthesize

from synth_identity import SYNTH_DETECTOR, SYNTH_THRESHOLD
from synth_library import synth_library

LEARN = "walk:8,punch:8,squat:8,wave:8"
PERFORMANCE = "walk:6,kick:6,punch:6,jump:6,squat:6"     # kick and jump: not in the library


def _library(swap: dict[str, str] | None = None):
    """Every behaviour of LEARN by synthetic performers 0 and 4; ``swap`` renames."""
    return synth_library(LEARN, live_config()[0], swap=swap)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("perf")
    for seed in (1, 2):
        write_take(d / f"synth_{seed}.npz", synthesize(PERFORMANCE, seed=seed).take)
    # the synthetic performances' identity threshold and detector settings
    # (tests/synth_identity.py: the shipped detector cuts some synthetic changes early)
    det = "".join(f"{k} = {str(v).lower()}\n" for k, v in SYNTH_DETECTOR.items())
    (d / "live.toml").write_text(f"[identity]\nthreshold = {SYNTH_THRESHOLD}\n"
                                 f"[detectors.contrast]\n{det}")
    return d


def _evaluate(folder: Path, lib: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rtseg.cli", "evaluate", str(folder),
                           "--online", "--identity", "--behaviours", str(lib), "--group",
                           "spliced", "--config", str(folder / "live.toml"), "--no-progress",
                           *extra], capture_output=True, text=True, timeout=600)


def test_named_segments_right_unknown_and_wrong(folder, tmp_path):
    lib = save_library(_library(), tmp_path / "lib.json")
    p = _evaluate(folder, lib, "--json")
    assert p.returncode == 0, p.stderr
    idn = json.loads(p.stdout)["identity"]
    nm = idn["named"]
    # walk, punch, squat of each performance get their names; kick and jump, which the
    # library lacks, come out unknown (the same performances in tests/test_library.py)
    assert nm["segments"] == 6 and nm["accuracy"] == 1.0
    assert nm["unknown_rate"] == 0.0 and nm["wrong_rate"] == 0.0
    assert nm["not_in_library"] == {"segments": 4, "unknown_rate": 1.0, "named_rate": 0.0}
    assert nm["skipped_takes"] == []
    dd = nm["decision_delay_s"]
    assert 0 < dd["decisions"] <= 6 and 0.5 < dd["after_transition_median"] < 4.0
    per = [t["named"] for t in idn["takes"].values()]
    assert sorted(idn["takes"]) == ["synth_1", "synth_2"]
    assert sum(t["segments"] for t in per) == 6
    # the unsupervised ids are still scored beside the names
    assert idn["pooled"]["ari"] > 0.5
    # the table says it in one line
    p = _evaluate(folder, lib)
    assert p.returncode == 0, p.stderr
    assert "named by the library: 6 segments of its behaviours: right 1.0, unknown 0.0, " \
           "wrong 0.0; 4 of other behaviours: unknown 1.0" in p.stdout


def test_names_swapped_in_the_library_are_counted_wrong(folder, tmp_path):
    """The same library with walk and squat named the other way round: the decisions are
    the same, so those segments are sent the other's name - wrong, not unknown."""
    lib = save_library(_library({"walk": "squat", "squat": "walk"}), tmp_path / "swapped.json")
    p = _evaluate(folder, lib, "--json")
    assert p.returncode == 0, p.stderr
    nm = json.loads(p.stdout)["identity"]["named"]
    assert nm["segments"] == 6
    assert nm["accuracy"] == pytest.approx(2 / 6, abs=1e-4)
    assert nm["wrong_rate"] == pytest.approx(4 / 6, abs=1e-4) and nm["unknown_rate"] == 0.0


def test_named_summary_shares():
    rows = [Named("a", 0, 0, "walk", "walk", 1.0), Named("a", 1, 9, "walk", "unknown", 3.0),
            Named("a", 2, 20, "squat", "walk", 1.0), Named("a", 3, 30, "jump", "unknown", 9.0,
                                                          known=False),
            Named("a", 4, 40, "kick", "walk", 1.0, known=False)]
    s = named_summary(rows)
    assert (s["segments"], s["accuracy"], s["unknown_rate"], s["wrong_rate"]) == \
        (3, 0.3333, 0.3333, 0.3333)
    assert s["not_in_library"] == {"segments": 2, "unknown_rate": 0.5, "named_rate": 0.5}


def test_behaviours_needs_identity_and_a_fitting_library(folder, tmp_path):
    lib = save_library(_library(), tmp_path / "lib.json")
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "evaluate", str(folder), "--online",
                        "--behaviours", str(lib), "--group", "spliced"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2 and "add --online --identity" in p.stderr
    doc = json.loads(lib.read_text())
    doc["profile"] = "tsseg4d"
    (tmp_path / "other.json").write_text(json.dumps(doc))
    p = _evaluate(folder, tmp_path / "other.json")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "none of the takes evaluated has those features" in p.stderr
