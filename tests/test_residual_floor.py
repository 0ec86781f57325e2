"""The floor under the contrast detector's window models' own residuals
(``rtseg.detectors.residual``): a running median of the stream's own before windows, that
caps the errors over a near-still model and scales with the stream."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.residual import ResidualFloor
from rtseg.detectors.segmentation import compute_features
from rtseg.detectors.window_models import WindowStats, fit, pca_distance, pca_error
from rtseg.simulators.synth.motion import synthesize


def test_the_floor_is_a_fraction_of_the_running_median():
    """Against numpy's median of the last ``count`` finite values pushed."""
    rng = np.random.default_rng(3)
    f = ResidualFloor(0.25, count=7)
    kept: list[float] = []
    assert f.value == 0.0
    for k in range(300):
        v = float(rng.choice([rng.random(), 1.0, 2.0]))   # repeats too
        if k % 50 == 7:
            assert f.push(float("nan")) == f.value         # ignored
            assert f.push(float("inf")) == f.value
        kept.append(v)
        assert f.push(v) == pytest.approx(0.25 * float(np.median(kept[-7:])), rel=1e-12)
    off = ResidualFloor(0.0)
    assert off.push(5.0) == 0.0
    for bad in (-0.1, 1.0):
        with pytest.raises(ValueError, match="residual_floor"):
            ResidualFloor(bad)


def test_errors_over_a_near_still_model_are_stated_over_the_floor():
    rng = np.random.default_rng(0)
    moving = rng.standard_normal((240, 12)) * np.linspace(1.0, 0.1, 12)
    still = 1e-4 * rng.standard_normal((240, 12)) + 0.3
    m = fit(WindowStats.of(still), pca_energy=0.9)
    y = WindowStats.of(moving)
    plain = pca_error(y, m)
    assert pca_error(y, m, m.pca_own / 2) == plain               # below the own: no effect
    floor = 1000.0 * m.pca_own
    assert pca_error(y, m, floor) == pytest.approx(plain / 1000.0, rel=1e-12)
    a = fit(y, pca_energy=0.9)
    assert pca_distance(a, m, floor) < pca_distance(a, m)


def test_the_cuts_do_not_change_when_the_features_are_scaled():
    """The floor is the stream's own: a stream scaled and shifted gives the same cuts (the
    contrast alone, gate off: the gate's models have an absolute variance floor)."""
    r = synthesize("walk:10,idle:8,punch:10,squat:10", frame_rate=120.0, seed=2)
    X = compute_features(r.take)
    p = {**load_params()["contrast"], "residual_floor": 0.25, "gate_threshold": 0.0}
    runs = []
    for k, shift in ((1.0, 0.0), (7.0, 0.5)):
        det = ContrastDetector.from_params(p, 120.0)
        runs.append([(c.frame, c.detected_at) for x in X * k + shift
                     if (c := det.update(x)) is not None])
        assert det.residual.value > 0
    assert len(runs[0]) >= 3 and runs[0] == runs[1]
