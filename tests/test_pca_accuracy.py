"""PCA offline variants: "scan" (default: the two-sided PCA contrast scanned over the take)
and "paper" (the online pass), the parameters that select them, and the retired "verified"
variant's keys refused."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.config import ConfigError
from rtseg.detectors import make_online, method_params, segment_features

FPS = 120.0


def behaviour(rng: np.random.Generator, n: int, dim: int, freq: float = 1.0,
              amp: float = 0.3, noise: float = 0.01) -> np.ndarray:
    """A periodic behaviour: a 2-D oscillation along its own random directions, plus a
    slow amplitude swing (the within-behaviour excursions of d) and sensor noise."""
    t = np.arange(n) / FPS
    swing = 1.0 + 0.6 * np.sin(2 * np.pi * 0.15 * t + rng.uniform(0, 6))
    U = rng.normal(size=(2, dim)) * amp
    osc = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t)], 1)
    return 0.3 * rng.normal(size=dim) + swing[:, None] * (osc @ U) + noise * rng.normal(size=(n, dim))


def two_behaviours(seed: int, la: int = 1500, lb: int = 1500, dim: int = 24
                   ) -> tuple[np.ndarray, int]:
    rng = np.random.default_rng(seed)
    return np.concatenate([behaviour(rng, la, dim, 1.0), behaviour(rng, lb, dim, 0.8)]), la


def test_paper_variant_is_the_online_pass():
    X, la = two_behaviours(3, la=1200, lb=1200)
    rng = np.random.default_rng(9)
    X = np.concatenate([X, behaviour(rng, 1200, X.shape[1], 1.3)])
    paper = [c.frame for c in segment_features(X, "pca", FPS, {"variant": "paper"})]
    online = [c.frame for c in make_online("pca", FPS).run(X)]
    assert paper == online and paper


def test_the_scan_finds_the_changes_with_fewer_false_cuts_than_the_paper():
    better = "scan"
    n_true = hits_v = hits_p = extra_v = extra_p = 0
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        parts = [behaviour(rng, 1500, 24, f) for f in (1.0, 0.7, 1.2, 0.9)]
        X = np.concatenate(parts)
        truth = [1500, 3000, 4500]
        n_true += len(truth)
        for variant in ("paper", better):
            frames = [c.frame for c in segment_features(X, "pca", FPS, {"variant": variant})]
            hits = sum(any(abs(f - t) <= 120 for f in frames) for t in truth)
            extra = sum(all(abs(f - t) > 120 for t in truth) for f in frames)
            if variant == "paper":
                hits_p, extra_p = hits_p + hits, extra_p + extra
            else:
                hits_v, extra_v = hits_v + hits, extra_v + extra
    assert extra_p >= 4, "premise: the online pass over-segments the swinging behaviours"
    assert extra_v <= extra_p // 2, (extra_v, extra_p)
    assert hits_v >= hits_p and hits_v >= n_true - 2, (hits_v, hits_p, n_true)


@pytest.mark.parametrize("key,value,word", [
    ("variant", "fancy", "variant"), ("min_contrast", -1.0, "min_contrast"),
    ("scan_step_s", 0.0, "scan_step_s"), ("energy", True, "energy"),
    # the retired "verified" variant and its keys are refused, naming the key
    ("variant", "verified", "variant"), ("verify_ratio", 4.0, "unknown key 'verify_ratio'"),
    ("verify_window_s", 4.0, "unknown key 'verify_window_s'"),
    ("min_segment_s", 1.0, "unknown key 'min_segment_s'")])
def test_bad_params_name_the_key(key, value, word):
    with pytest.raises(ConfigError, match=word):
        method_params("pca", {key: value})


def test_defaults_select_the_scan_variant():
    p = method_params("pca")
    assert p["variant"] == "scan" and p["min_contrast"] > 1.0
    assert len(p["scan_windows_s"]) >= 1 and p["scan_step_s"] < min(p["scan_windows_s"])


@pytest.mark.parametrize("value", [[], [0.0], [2.0, -1.0], "3.0", [True], 3.0])
def test_bad_scan_windows_are_rejected(value):
    with pytest.raises(ConfigError, match="scan_windows_s"):
        method_params("pca", {"scan_windows_s": value})


def test_scan_contrast_peaks_at_the_change_and_stays_low_inside_behaviours():
    from rtseg.detectors.pca.scan import contrast_profile, scan_cuts
    X, la = two_behaviours(5, la=2400, lb=2400)
    f, k = contrast_profile(X, [300, 360, 420], 10, 0.9)
    assert f[0] == 300 and np.all(np.diff(f) == 10)      # from the shortest window
    at = int(np.argmax(k))
    assert abs(f[at] - la) <= 30 and k[at] > 3.0, (f[at], k[at])
    inside = k[(np.abs(f - la) > 900) & np.isfinite(k)]
    assert inside.size and np.median(inside) < 1.5, np.median(inside)
    found = scan_cuts(X, [300, 360, 420], 10, 2.0, 0.9)
    assert [abs(c - la) <= 30 for c, _ in found] == [True]
    # too short for any outer window: nothing can be checked
    assert scan_cuts(X[:600], [300, 360, 420], 10, 2.0, 0.9) is None


@pytest.mark.parametrize("dim", [1, 2, 4, 8])
def test_scan_on_few_noise_like_dims_has_no_false_cuts(dim):
    """With few dims of white noise every direction is needed for 90 % of the variance; a
    window model keeping all of them explains any frames exactly and the contrast is 0/0
    rounding noise (before the fix: 3-6 cuts in 3000 frames of pure noise).  The model
    leaves one varying direction out (1 dim: the mean alone)."""
    rng = np.random.default_rng(dim)
    for _ in range(3):
        assert segment_features(0.01 * rng.normal(size=(3000, dim)), "pca", FPS) == []
    step = np.vstack([np.zeros((1500, dim)), np.ones((1500, dim))])
    cuts = [c.frame for c in segment_features(step + 0.01 * rng.normal(size=(3000, dim)),
                                              "pca", FPS)]
    assert any(abs(c - 1500) <= 20 for c in cuts), cuts
    if dim == 1:
        assert len(cuts) == 1, cuts
    else:
        # the one residual direction of a noise window is random, so a window holding part
        # of the step can score high: at most one extra cut, within two windows of it
        assert len(cuts) <= 2 and all(abs(c - 1500) <= 840 for c in cuts), cuts


def test_a_take_too_short_to_scan_gets_the_paper_forward_pass():
    from rtseg.detectors.pca.scan import scan_cuts
    # 740 frames: under 2.5 x the shortest default window (300 frames), so no position has
    # a whole window before it and a whole outer window
    X, la = two_behaviours(6, la=370, lb=370)
    assert scan_cuts(X, [300, 360, 420], 10, 2.0, 0.9) is None
    # a low k_sigma makes the forward pass cut, so the fallback is really exercised
    args = {"k_sigma": 1.0}
    scan = segment_features(X, "pca", FPS, {"variant": "scan", **args})
    paper = segment_features(X, "pca", FPS, {"variant": "paper", **args})
    assert scan and [(c.frame, c.detected_at) for c in scan] == \
        [(c.frame, c.detected_at) for c in paper]
    # 750 frames can be scanned: the scan's own result (at most one cut, at a maximum)
    X, la = two_behaviours(6, la=375, lb=375)
    assert scan_cuts(X, [300, 360, 420], 10, 2.0, 0.9) is not None
    scanned = segment_features(X, "pca", FPS, {"variant": "scan", **args})
    assert [c.frame for c in scanned] != [c.frame for c in
                                          segment_features(X, "pca", FPS, {"variant": "paper", **args})]


def test_scan_windows_are_put_on_the_step_grid():
    """Window lengths are rounded to whole steps so the scan's windows recur (fitted once);
    at 120 fps the defaults are already whole steps, at 100 fps 3 s = 300 -> 304 frames."""
    from rtseg.detectors._scan import on_grid
    assert on_grid(360, 10) == 360 and on_grid(300, 8) == 304 and on_grid(250, 8) == 248
    assert on_grid(3, 8) == 8 and on_grid(5, 1) == 5
    # the offline result at 100 fps equals a run whose windows are given on the grid
    X, la = two_behaviours(7, la=1500, lb=1500)
    on = [c.frame for c in segment_features(X, "pca", 100.0)]
    given = [c.frame for c in segment_features(
        X, "pca", 100.0, {"scan_windows_s": [2.48, 3.04, 3.52]})]
    assert on == given and any(abs(c - la) <= 30 for c in on)


def test_scan_windows_shorter_than_two_frames_are_a_clear_error():
    from rtseg.detectors.pca.scan import contrast_profile
    X, _ = two_behaviours(8, la=600, lb=600)
    with pytest.raises(ValueError, match="scan windows must be >= 2 frames"):
        contrast_profile(X, [1, 300], 10, 0.9)
    with pytest.raises(ValueError, match="scan windows must be >= 2 frames"):
        segment_features(X, "pca", FPS, {"scan_windows_s": [0.001], "scan_step_s": 0.001})
