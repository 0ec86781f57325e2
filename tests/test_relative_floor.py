"""The contrast detector's floor set by the stream's own recent changes
(``rtseg.detectors.relative``): a quiet behaviour's drift inside a performance of very
distinct behaviours is no change, a change out of the quiet behaviour still is."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.relative import ENERGY_CHANGE, EnergyChanges, EnergyRange, RelativeFloor
from rtseg.evaluation.online import fed_features
from rtseg.live.config import load_session_config
from rtseg.simulators.synth.motion import synthesize

RATE = 120.0


def test_energy_range_is_the_range_of_the_last_span_values_since_the_cut_off():
    """Against a scan of a plain list: the last ``span`` values pushed, those before the
    latest cut-off left out for good, the new value included; ties and repeats too."""
    rng = np.random.default_rng(5)
    r = EnergyRange(span=7)
    kept: list[tuple[int, float]] = []            # (position, energy) pushed, in order
    cut_off = 0
    for position in range(400):
        if rng.random() < 0.05:                   # a cut: earlier positions leave
            cut_off = max(cut_off, position - int(rng.integers(0, 4)))
            r.drop_before(cut_off)
        e = float(rng.integers(1, 6)) if rng.random() < 0.3 else float(rng.random())
        window = [v for p, v in kept[-7:] if p >= cut_off]
        assert r.range_with(e) == (min(window + [e]), max(window + [e]))
        r.push(position, e)
        kept.append((position, e))
    with pytest.raises(ValueError, match="span"):
        EnergyRange(0)


def test_no_floor_until_warm_then_a_fraction_of_the_median():
    f = RelativeFloor(0.1, count=4, warm=3)
    assert f.floor == 0.0 and f.admits(0.01)
    for s in (50.0, 70.0):
        f.sent(s)
    assert f.floor == 0.0                       # two cuts sent: not warm yet
    f.sent(90.0)
    assert f.floor == pytest.approx(7.0)        # 0.1 x median(50, 70, 90)
    assert not f.admits(6.9, frame=1234) and f.refused == 1
    assert f.refusals == [(1234, 6.9, pytest.approx(7.0))]   # what benchmarks/errors.py reads
    assert f.admits(7.0)
    for s in (2.0, 2.0, 2.0):                   # the oldest scores leave the median
        f.sent(s)
    assert f.floor == pytest.approx(0.2)        # 0.1 x median(90, 2, 2, 2)


def test_an_energy_change_is_admitted_whatever_its_contrast():
    f = RelativeFloor(0.5, warm=1)
    f.sent(100.0)
    assert not f.admits(10.0, energy=1.0)
    assert not f.admits(10.0, energy=ENERGY_CHANGE * 0.99)
    assert f.admits(10.0, energy=ENERGY_CHANGE)            # the motion grew
    assert f.admits(10.0, energy=1.0 / ENERGY_CHANGE)      # ... or calmed down
    assert f.refused == 2


def test_fraction_zero_admits_everything_and_bad_fractions_are_refused():
    f = RelativeFloor(0.0, warm=1)
    f.sent(1000.0)
    assert f.admits(1e-9)
    for bad in (-0.1, 1.0, 2.0):
        with pytest.raises(ValueError, match="relative_floor"):
            RelativeFloor(bad)


def _cuts_s(X: np.ndarray, index: np.ndarray, fraction: float) -> list[float]:
    p = {**load_params()["contrast"], "relative_floor": fraction}
    det = ContrastDetector.from_params(p, RATE)
    return [float(index[c.frame]) / RATE for x in X if (c := det.update(x)) is not None]


def test_a_drift_inside_idle_is_no_change_and_the_change_out_of_it_is():
    # three vigorous behaviours (changes of contrast 40-170), 18 s of idle, then punching
    script = [("jump", 8.0), ("run", 8.0), ("kick", 8.0), ("idle", 18.0), ("punch", 8.0)]
    take = synthesize(script, frame_rate=RATE, seed=1).take
    X, index, _ = fed_features(take, load_session_config())
    changes = [8.0, 16.0, 24.0, 42.0]
    off, on = _cuts_s(X, index, 0.0), _cuts_s(X, index, 0.1)

    def found(cuts):
        return all(any(abs(c - t) <= 1.0 for c in cuts) for t in changes)

    def inside_idle(cuts):
        return [c for c in cuts if 26.0 < c < 40.0]

    assert found(off) and inside_idle(off), off     # without the floor: a false cut in idle
    assert found(on) and not inside_idle(on), on    # with it: none, and idle -> punch kept


def test_the_detector_counts_its_refusals_and_logs_them(caplog):
    script = [("jump", 8.0), ("run", 8.0), ("kick", 8.0), ("idle", 18.0), ("punch", 8.0)]
    take = synthesize(script, frame_rate=RATE, seed=1).take
    X, _, _ = fed_features(take, load_session_config())
    det = ContrastDetector.from_params(load_params()["contrast"], RATE)
    with caplog.at_level("INFO", logger="rtseg.detectors"):
        for x in X:
            det.update(x)
    assert det.relative.refused >= 1
    assert sum("below" in r.getMessage() and "median" in r.getMessage()
               for r in caplog.records) == det.relative.refused


def test_the_energy_change_is_measured_against_the_segments_range():
    e = EnergyChanges(span=8, keep=3)
    for c, ea in enumerate((1.0, 2.0, 1.5)):
        assert e.look(c, ea, ea) == 1.0                      # within the range so far
    assert e.look(3, 1.5, 5.0) == pytest.approx(2.5)         # over the highest (2)
    assert e.look(4, 1.5, 0.4) == pytest.approx(0.4)         # under the lowest (1)
    assert e.look(5, 1.5, 1.9) == 1.0
    # after a cut, the windows that straddle it leave the range: only this position's
    assert e.look(8, 1.0, 1.9, cut_off=8) == pytest.approx(1.9)
    # the newest ``keep`` looks are remembered by position
    assert e.at(8) == pytest.approx(1.9) and e.at(5) == 1.0 and e.at(4) == pytest.approx(0.4)
    assert e.at(3) == 1.0                     # 2.5, but no longer among the newest 3