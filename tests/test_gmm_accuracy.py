"""GMM detector: posterior smoothing, cut refinement, their parameters, and the paper variant."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.config import ConfigError
from rtseg.detectors import method_params, segment_features
from rtseg.detectors.gmm import GMMDetector, merge_short_runs, moving_mean, refine_changes

FPS = 120.0
PAPER = {"smooth_s": 0.0, "refine_s": 0.0, "min_segment_s": 1.0}


def test_moving_mean_matches_direct_window_mean():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 3))
    w = 7
    out = moving_mean(a, w)
    for i in range(50):
        lo = min(max(i - w // 2, 0), 50)
        hi = min(lo + w, 50)
        np.testing.assert_allclose(out[i], a[lo:hi].mean(axis=0), atol=1e-12)
    np.testing.assert_array_equal(moving_mean(a, 1), a)


def _logp_crossing(n: int, cross: int, k: int = 3, a: int = 0, b: int = 2) -> np.ndarray:
    """Log posteriors favouring component a before ``cross`` and b from it on."""
    p = np.full((n, k), 0.05)
    p[:cross, a] = 0.9
    p[cross:, b] = 0.9
    return np.log(p / p.sum(axis=1, keepdims=True))


def test_refine_moves_cut_to_posterior_crossing():
    n, cross = 600, 300
    lab = np.array([0] * 340 + [2] * 260)          # label change 40 frames late
    out = refine_changes(lab, _logp_crossing(n, cross), radius=60)
    assert list(np.flatnonzero(np.diff(out)) + 1) == [cross]
    assert out[0] == 0 and out[-1] == 2
    # outside the radius the cut can only go as far as the radius allows
    out = refine_changes(lab, _logp_crossing(n, cross), radius=20)
    assert list(np.flatnonzero(np.diff(out)) + 1) == [320]


def test_refine_keeps_min_segment_and_label_order():
    n = 900
    lab = np.array([0] * 300 + [1] * 300 + [2] * 300)
    logp = np.log(np.full((n, 3), 1 / 3))
    logp[:, 1] = np.log(0.01)                       # evidence says: no frame is component 1
    out = refine_changes(lab, logp, radius=250, min_len=120)
    runs = np.flatnonzero(np.diff(out)) + 1
    assert len(runs) == 2
    lengths = np.diff(np.concatenate(([0], runs, [n])))
    assert lengths.min() >= 120
    assert [out[0], out[runs[0]], out[runs[1]]] == [0, 1, 2]


def test_refine_without_changes_or_radius_is_identity():
    lab = np.zeros(100, dtype=int)
    np.testing.assert_array_equal(refine_changes(lab, np.zeros((100, 2)), 10), lab)
    lab2 = np.array([0] * 50 + [1] * 50)
    np.testing.assert_array_equal(refine_changes(lab2, np.zeros((100, 2)), 0), lab2)


def two_behaviours(n1: int = 900, n2: int = 900, seed: int = 0) -> np.ndarray:
    """Two noisy clusters of poses with overlapping tails, so single frames flicker."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n1, 6))
    b = rng.normal(size=(n2, 6)) + np.array([1.6, 0, 0, 0, 0, 0.0])
    return np.concatenate([a, b])


def test_posterior_smoothing_removes_flicker():
    X = two_behaviours()
    det = GMMDetector(n_components=2, min_segment=1, smooth=0)
    flicker = len(det.segment(X))
    det_s = GMMDetector(n_components=2, min_segment=1, smooth=60)
    smooth = det_s.segment(X)
    assert flicker > 20                  # frame-wise argmax changes label all the time
    assert len(smooth) < flicker // 5


def test_default_finds_the_single_change_close_to_truth():
    X = two_behaviours(seed=1)
    cuts = [c.frame for c in segment_features(X, "gmm", FPS, {"n_components": 2})]
    assert len(cuts) == 1 and abs(cuts[0] - 900) <= 30


def test_paper_variant_is_argmax_then_merge():
    rng = np.random.default_rng(3)
    X = np.concatenate([rng.normal(size=(700, 5)) + 3 * (i % 2) for i in range(4)])
    paper = GMMDetector.from_params(method_params("gmm", PAPER), FPS)
    assert paper.smooth == 0 and paper.refine == 0 and paper.min_segment == 120
    cuts = paper.segment(X)
    lab = paper.labels_
    assert [c.frame for c in cuts] == list(np.flatnonzero(np.diff(lab)) + 1)
    # the labels are already merged: merging again changes nothing
    np.testing.assert_array_equal(merge_short_runs(lab, 120), lab)


def test_windows_in_seconds_follow_frame_rate():
    p = method_params("gmm")
    d120 = GMMDetector.from_params(p, 120.0)
    d60 = GMMDetector.from_params(p, 60.0)
    assert d120.smooth == 2 * d60.smooth and d120.refine == 2 * d60.refine
    assert d120.min_segment == round(p["min_segment_s"] * 120)


@pytest.mark.parametrize("key", ["smooth_s", "refine_s"])
def test_negative_windows_rejected(key):
    with pytest.raises(ConfigError, match=key):
        method_params("gmm", {key: -0.5})
    with pytest.raises(ValueError):
        GMMDetector(**{key[:-2]: -1})
