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


def three_behaviours(seed: int = 0, n: int = 1200) -> tuple[np.ndarray, list[int]]:
    """A far from B and C; B and C close to each other, so k = 2 puts them in one
    component, but separated by 4 standard deviations along one axis."""
    rng = np.random.default_rng(seed)
    means = [np.array([-12.0, 0, 0, 0, 0, 0]), np.zeros(6), np.array([0, 4.0, 0, 0, 0, 0])]
    X = np.concatenate([m + rng.normal(size=(n, 6)) for m in means])
    return X, [n, 2 * n]


def test_split_test_finds_two_behaviours_sharing_a_component():
    X, truth = three_behaviours()
    paper_like = segment_features(X, "gmm", FPS, {"n_components": 2, "split_min_s": 0.0})
    assert [abs(c.frame - truth[0]) <= 30 for c in paper_like] == [True]   # B|C not cut
    cuts = [c.frame for c in segment_features(X, "gmm", FPS, {"n_components": 2})]
    assert len(cuts) == 2
    assert all(abs(f - t) <= 30 for f, t in zip(cuts, truth))


def cyclic(n: int, freq: float, centre: float, rng: np.random.Generator) -> np.ndarray:
    """A periodic movement (one cycle per 1/freq s) around ``centre`` in 6 dims."""
    t = np.arange(n) / FPS
    phase = 2 * np.pi * freq * t
    Y = np.zeros((n, 6))
    Y[:, 0] = centre
    Y[:, 1], Y[:, 2] = 3 * np.sin(phase), 3 * np.cos(phase)
    return Y + 0.2 * rng.normal(size=(n, 6))


def test_split_test_leaves_a_cyclic_behaviour_whole():
    rng = np.random.default_rng(4)
    X = np.concatenate([cyclic(1500, 0.8, 0.0, rng), cyclic(1500, 0.8, 10.0, rng)])
    det = GMMDetector.from_params(method_params("gmm", {"n_components": 2}), FPS)
    assert det.split_min > 0
    cuts = [c.frame for c in det.segment(X)]
    assert len(cuts) == 1 and abs(cuts[0] - 1500) <= 30
    # the split test alone finds no second behaviour inside one cyclic behaviour
    assert det.split_two(X[:1500]) is None


def test_split_needs_frame_wise_agreement():
    """First half pose A; second half blocks of 0.25 s drawn A or B (B 70 %): one change
    after smoothing, but only ~85 % of the frame-wise labels agree with it."""
    rng = np.random.default_rng(2)
    A, B = np.zeros(6), np.array([6.0, 0, 0, 0, 0, 0])
    blocks = [A] * 24 + [B if rng.random() < 0.7 else A for _ in range(24)]
    X = np.concatenate([m + rng.normal(size=(30, 6)) for m in blocks])
    strict = GMMDetector.from_params(method_params("gmm", {"split_agreement": 0.95}), FPS)
    loose = GMMDetector.from_params(method_params("gmm", {"split_agreement": 0.6}), FPS)
    assert strict.split_two(X) is None
    hit = loose.split_two(X)
    assert hit is not None and abs(hit[0] - 720) <= 60
