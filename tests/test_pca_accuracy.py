"""PCA offline variants: "scan" (default: the two-sided PCA contrast scanned over the take),
"verified" (forward + backward passes merged, then the two-sided PCA contrast check of their
cuts), "paper" (the online pass), and the parameters that select them."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.config import ConfigError
from rtseg.detectors import make_online, method_params, segment_features
from rtseg.detectors.base import Cut
from rtseg.detectors.pca_scan import cut_contrast, merge_passes, verify_cuts

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


def test_contrast_separates_a_change_from_a_cut_inside_a_behaviour():
    W = 480
    for seed in range(5):
        X, la = two_behaviours(seed)
        change = cut_contrast(X, 0, la, len(X), W, 0.9)
        inside = cut_contrast(X, 0, la // 2, la, W, 0.9)
        assert change > 4.0, (seed, change)
        assert inside < 2.0, (seed, inside)


def test_contrast_is_zero_when_a_side_is_shorter_than_min_len():
    X, la = two_behaviours(0)
    assert cut_contrast(X, la - 50, la, len(X), 480, 0.9, min_len=120) == 0.0
    assert cut_contrast(X, 0, la, la + 50, 480, 0.9, min_len=120) == 0.0
    assert cut_contrast(X, la - 200, la, len(X), 480, 0.9, min_len=120) > 4.0


def test_verify_drops_false_cuts_and_keeps_the_change():
    X, la = two_behaviours(1)
    cuts = [Cut(400, "pca", 0.5), Cut(la - 30, "pca", 0.2), Cut(la, "pca", 0.9),
            Cut(2300, "pca", 0.4)]
    kept = verify_cuts(X, cuts, W=480, min_len=120, ratio=4.0, tau=0.9)
    # la - 30 leaves a 30-frame segment (removed first, lower confidence), 400 and 2300 lie
    # inside a behaviour; the change survives
    assert [c.frame for c in kept] == [la]


def test_verify_keeps_every_cut_at_ratio_zero_except_too_short_segments():
    X, la = two_behaviours(2)
    cuts = [Cut(400, "pca"), Cut(la, "pca"), Cut(la + 40, "pca", 0.1)]
    kept = verify_cuts(X, cuts, W=480, min_len=120, ratio=0.0, tau=0.9)
    assert [c.frame for c in kept] == [400, la, la + 40]      # 0 >= 0: nothing removed
    kept = verify_cuts(X, cuts, W=480, min_len=120, ratio=1e-9, tau=0.9)
    assert [c.frame for c in kept] == [400, la]


def test_merge_passes_pairs_forward_and_backward_cuts_at_their_mean():
    F = [Cut(1000, "pca", 0.7, 1000), Cut(3000, "pca", 0.3, 3000)]
    B = [Cut(940, "pca", 0.5, 940), Cut(2000, "pca", 0.6, 2000)]
    out = merge_passes(F, B, tol=120)
    assert [c.frame for c in out] == [970, 2000, 3000]
    assert out[0].confidence == 0.7 and out[0].detected_at == 970
    # cuts of one pass closer than tol are merged too
    out = merge_passes([Cut(1000, "pca"), Cut(1050, "pca")], [], tol=120)
    assert [c.frame for c in out] == [1025]


def test_paper_variant_is_the_online_pass():
    X, la = two_behaviours(3, la=1200, lb=1200)
    rng = np.random.default_rng(9)
    X = np.concatenate([X, behaviour(rng, 1200, X.shape[1], 1.3)])
    paper = [c.frame for c in segment_features(X, "pca", FPS, {"variant": "paper"})]
    online = [c.frame for c in make_online("pca", FPS).run(X)]
    assert paper == online and paper


@pytest.mark.parametrize("better", ["verified", "scan"])
def test_offline_variants_find_the_changes_with_fewer_false_cuts_than_the_paper(better):
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
    ("variant", "fancy", "variant"), ("verify_ratio", -1.0, "verify_ratio"),
    ("verify_window_s", 0.0, "verify_window_s"), ("min_segment_s", True, "min_segment_s")])
def test_bad_verification_params_name_the_key(key, value, word):
    with pytest.raises(ConfigError, match=word):
        method_params("pca", {key: value})


def test_defaults_select_the_scan_variant():
    p = method_params("pca")
    assert p["variant"] == "scan" and p["min_contrast"] > 1.0
    assert len(p["scan_windows_s"]) >= 1 and p["scan_step_s"] < min(p["scan_windows_s"])
    assert p["verify_ratio"] > 1.0 and p["min_segment_s"] < p["verify_window_s"]


@pytest.mark.parametrize("value", [[], [0.0], [2.0, -1.0], "3.0", [True], 3.0])
def test_bad_scan_windows_are_rejected(value):
    with pytest.raises(ConfigError, match="scan_windows_s"):
        method_params("pca", {"scan_windows_s": value})


def test_scan_contrast_peaks_at_the_change_and_stays_low_inside_behaviours():
    from rtseg.detectors.pca_scan import contrast_profile, scan_cuts
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


def test_scan_falls_back_to_the_verified_variant_on_a_short_take(monkeypatch):
    import rtseg.detectors.pca_scan as pca_mod
    X, la = two_behaviours(6, la=320, lb=320)      # 640 frames: no position has an outer window
    assert pca_mod.scan_cuts(X, [300, 360, 420], 10, 2.0, 0.9) is None
    checked = []
    real = pca_mod.verify_cuts
    monkeypatch.setattr(pca_mod, "verify_cuts",
                        lambda X, cuts, **kw: checked.append(len(cuts)) or real(X, cuts, **kw))
    # a low k_sigma makes the passes propose cuts, so the check really runs
    scan = [c.frame for c in segment_features(X, "pca", FPS, {"variant": "scan", "k_sigma": 1.0})]
    assert checked and checked[0] > 0
    ver = [c.frame for c in segment_features(X, "pca", FPS, {"variant": "verified", "k_sigma": 1.0})]
    assert scan == ver
    checked.clear()
    long_X, _ = two_behaviours(6, la=1500, lb=1500)
    segment_features(long_X, "pca", FPS, {"variant": "scan", "k_sigma": 1.0})
    assert checked == []                            # long enough: scanned, not checked


def test_refine_moves_a_late_cut_to_the_change():
    from rtseg.detectors.pca_scan import refine_cuts
    for seed in range(3):
        X, la = two_behaviours(seed)
        cuts = [Cut(la + 45, "pca", 0.8, la + 45), Cut(la - 700, "pca", 0.3, la - 700)]
        out = refine_cuts(X, cuts, W=480, min_len=120, reach=60, tau=0.9)
        frames = [c.frame for c in out]
        assert abs(frames[1] - la) <= 20, (seed, frames)   # was 45 frames late
        assert abs(frames[0] - (la - 700)) <= 60          # stays within reach
        assert out[1].detected_at == out[1].frame and out[1].confidence == 0.8


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
    from rtseg.detectors.pca_scan import contrast_profile
    X, _ = two_behaviours(8, la=600, lb=600)
    with pytest.raises(ValueError, match="scan windows must be >= 2 frames"):
        contrast_profile(X, [1, 300], 10, 0.9)
    with pytest.raises(ValueError, match="scan windows must be >= 2 frames"):
        segment_features(X, "pca", FPS, {"scan_windows_s": [0.001], "scan_step_s": 0.001})
