"""PPCA offline verification (variant "verified"): the two-sided contrast check of candidate
cuts, its non-maximum rule, the paper variant, and the parameters that select them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtseg.config import ConfigError
from rtseg.detectors import method_params, segment_features
from rtseg.detectors.base import Cut
from rtseg.detectors.ppca.distance import cut_contrast, fit_ppca, mean_distance
from rtseg.detectors.ppca.offline import verify_cuts

FPS = 120.0


def alternating_take(seed: int, dim: int = 24, period_s: float = 4.0, la: int = 3000,
                     lb: int = 1800, noise: float = 0.02) -> tuple[np.ndarray, int]:
    """An alternating-side exercise (la frames) then a different behaviour (lb frames).

    The exercise oscillates at 1.2 Hz along directions of its current side; the side swaps
    every period_s / 2 seconds (2 s > T = 1.25 s: the paper's forward pass cuts at the
    swaps).  Returns X and the true cut frame (la)."""
    rng = np.random.default_rng(seed)
    t = np.arange(la) / FPS
    w = 0.5 * (1 + np.tanh(4 * np.sin(2 * np.pi * t / period_s + 0.5)))[:, None]
    uL, uR = rng.normal(size=(2, 2, dim)) * 0.3
    osc = np.stack([np.sin(2 * np.pi * 1.2 * t), np.cos(2 * np.pi * 1.2 * t)], 1)
    m, off = 0.3 * rng.normal(size=dim), 0.2 * rng.normal(size=dim)
    A = m + w * (osc @ uL) + (1 - w) * (osc @ uR + off)
    tb = np.arange(lb) / FPS
    v = rng.normal(size=(2, dim)) * 0.3
    B = 0.3 * rng.normal(size=dim) + np.stack([np.sin(2 * np.pi * 0.9 * tb),
                                               np.cos(2 * np.pi * 0.9 * tb)], 1) @ v
    return np.concatenate([A, B]) + noise * rng.normal(size=(la + lb, dim)), la


def test_verified_drops_cuts_inside_an_alternating_exercise_and_keeps_the_change():
    inside_paper = inside_verified = found = 0
    for seed in range(8):
        X, la = alternating_take(seed)
        paper = [c.frame for c in segment_features(X, "ppca", FPS, {"variant": "paper"})]
        ver = [c.frame for c in segment_features(X, "ppca", FPS)]
        found += any(abs(f - la) <= 60 for f in ver)
        inside_paper += sum(f < la - 60 for f in paper)
        inside_verified += sum(f < la - 60 for f in ver)
    # the premise: the published method over-segments this exercise (cuts at side swaps)
    assert inside_paper >= 40
    # the scan finds the change in (nearly) every take and almost none of the swaps
    assert found >= 7, found
    assert inside_verified <= 0.05 * inside_paper, (inside_verified, inside_paper)


def blended_take(seed: int, dim: int = 16, la: int = 2400, blend: int = 60
                 ) -> tuple[np.ndarray, int]:
    """Two stationary behaviours of 2 * la frames each, cross-faded over ``blend`` frames
    centred on frame la; returns X and la."""
    rng = np.random.default_rng(seed)
    A = stationary(rng, 2 * la, dim, np.zeros(dim))
    B = stationary(rng, 2 * la, dim, 0.5 * rng.normal(size=dim))
    w = np.clip((np.arange(2 * la) - (la - blend // 2)) / blend, 0, 1)[:, None]
    return (1 - w) * A + w * B, la


def test_scan_places_changes_between_the_forward_and_backward_peaks():
    """A gradual change (blend over 0.5 s): the forward pass peaks early, the backward pass
    late; the verified cut lies between them, nearer the middle of the blend than either."""
    from rtseg.detectors.ppca.online import PPCADetector
    X, la = blended_take(11)
    ver = [c.frame for c in segment_features(X, "ppca", FPS)]
    assert len(ver) == 1 and abs(ver[0] - la) <= 15, ver
    fwd = [c.frame for c in PPCADetector(T=150, delta=10).run(X)]
    bwd = [len(X) - c.frame for c in PPCADetector(T=150, delta=10).run(X[::-1])]
    f = min(fwd, key=lambda g: abs(g - la))
    b = min(bwd, key=lambda g: abs(g - la))
    assert min(f, b) <= ver[0] <= max(f, b)


def test_localise_blends_the_passes_estimate_with_the_anchor():
    """anchor_weight w: (1 - w) x the passes' estimate + w x the anchor; 0 is the passes
    alone, 1 the anchor alone; a change no pass peak is near goes to its anchor."""
    from rtseg.detectors.ppca.offline import localise_cuts
    X, la = blended_take(5)
    args = dict(T=150, delta=10)
    passes = localise_cuts(X, [la], args, reach=150)[0]
    assert abs(passes - la) <= 30
    anchor = la + 90
    assert localise_cuts(X, [la], args, 150, anchors=[anchor], anchor_weight=0.0) == [passes]
    assert localise_cuts(X, [la], args, 150, anchors=[anchor], anchor_weight=1.0) == [anchor]
    third = localise_cuts(X, [la], args, 150, anchors=[anchor], anchor_weight=1 / 3)[0]
    assert third == round(2 / 3 * passes + 1 / 3 * anchor)
    # reach 0: no peak counts; the change goes to its anchor (w > 0) or stays (w = 0)
    assert localise_cuts(X, [la + 7], args, 0, anchors=[anchor], anchor_weight=0.5) == [anchor]
    assert localise_cuts(X, [la + 7], args, 0) == [la + 7]
    with pytest.raises(ValueError, match="anchors"):
        localise_cuts(X, [la], args, 150, anchors=[1, 2], anchor_weight=0.5)
    with pytest.raises(ValueError, match="anchor_weight"):
        localise_cuts(X, [la], args, 150, anchors=[la], anchor_weight=2.0)


def test_scan_cuts_reports_local_maxima_above_the_threshold_one_window_apart():
    from rtseg.detectors.ppca.offline import contrast_profile, scan_cuts
    rng = np.random.default_rng(4)
    dim = 12
    parts = [stationary(rng, 1200, dim, 0.6 * rng.normal(size=dim)) for _ in range(3)]
    X = np.concatenate(parts)
    frames_, k = contrast_profile(X, 360, 10, 0.95)
    assert frames_[0] == 360 and frames_[-1] <= len(X) - 180
    found = scan_cuts(X, 360, 10, 1.3, 0.95)
    assert [abs(f - t) <= 20 for (f, _), t in zip(found, (1200, 2400))] == [True, True]
    assert len(found) == 2 and all(c >= 1.3 for _, c in found)
    assert scan_cuts(X, 360, 10, 1e9, 0.95) == []
    assert scan_cuts(X[:500], 360, 10, 1.3, 0.95) is None   # too short to scan


def stationary(rng: np.random.Generator, n: int, dim: int, mean: np.ndarray) -> np.ndarray:
    t = np.arange(n) / FPS
    mix = rng.normal(size=(2, dim)) * 0.2
    return mean + np.stack([np.sin(2 * np.pi * 1.3 * t), np.cos(2 * np.pi * 0.7 * t)], 1) @ mix \
        + 0.02 * rng.normal(size=(n, dim))


def test_a_long_take_without_a_scanned_change_has_no_cuts():
    """The passes' cuts are only checked one by one (``verify_cuts``) when the take is too
    short to scan; a scanned take with no contrast maximum has no cut, also not one in its
    first window, which the scan leaves out (here a 200-frame still start-up)."""
    rng = np.random.default_rng(2)
    dim = 16
    still = 0.3 * rng.normal(size=dim) + 0.002 * rng.normal(size=(200, dim))
    X = np.concatenate([still, stationary(rng, 3000, dim, np.zeros(dim))])
    paper = [c.frame for c in segment_features(X, "ppca", FPS, {"variant": "paper"})]
    assert any(abs(f - 200) <= 20 for f in paper)        # the passes cut the start-up
    assert segment_features(X, "ppca", FPS) == []


def test_contrast_high_at_a_change_and_about_one_inside_a_behaviour():
    rng = np.random.default_rng(3)
    dim = 16
    X = np.concatenate([stationary(rng, 1500, dim, np.zeros(dim)),
                        stationary(rng, 1500, dim, 0.5 * rng.normal(size=dim))])
    W = 360
    at_change = cut_contrast(X, 1500, W, 0.95)
    inside = [cut_contrast(X, c, W, 0.95) for c in (750, 2250)]
    assert at_change > 3.0
    assert all(k < 1.15 for k in inside), inside


def test_contrast_at_the_take_ends_is_infinite_not_an_error():
    X = np.random.default_rng(0).normal(size=(400, 8))
    assert cut_contrast(X, 200, 360, 0.95) == math.inf    # no outer window on either side
    assert cut_contrast(X, 0, 360, 0.95) == math.inf      # nothing before the cut


def test_verify_keeps_the_stronger_of_two_close_cuts():
    rng = np.random.default_rng(5)
    dim = 16
    X = np.concatenate([stationary(rng, 1500, dim, np.zeros(dim)),
                        stationary(rng, 1500, dim, 0.5 * rng.normal(size=dim))])
    cuts = [Cut(frame=f, method="ppca") for f in (1500, 1620)]
    kept = verify_cuts(X, cuts, 360, 1.15, 0.95)
    assert [c.frame for c in kept] == [1500]
    # far apart, each is judged alone: a cut inside a behaviour still fails the test
    kept = verify_cuts(X, [Cut(frame=700, method="ppca"), Cut(frame=1500, method="ppca")],
                       360, 1.15, 0.95)
    assert [c.frame for c in kept] == [1500]


def test_fit_ppca_distance_of_own_frames_is_about_sqrt_dim():
    rng = np.random.default_rng(1)
    X = rng.normal(size=(5000, 12)) @ np.diag(np.linspace(0.5, 2.0, 12))
    model = fit_ppca(X, 0.95)
    h = mean_distance(model, X)
    assert abs(h - math.sqrt(12)) < 0.3          # E|z| for 12 dims is about 3.4
    assert mean_distance(model, X + 5.0) > 3 * h
    with pytest.raises(ValueError):
        fit_ppca(X[:1], 0.95)


@pytest.mark.parametrize("key,value", [("variant", "bogus"), ("verify_window_s", 0.0),
                                       ("min_contrast", -1.0), ("variant", 3),
                                       ("scan_weight", 1.5),
                                       ("scan_weight", -0.1)])
def test_verification_params_validated(key, value):
    with pytest.raises(ConfigError, match=key):
        method_params("ppca", {key: value})


def test_the_retired_online_check_is_refused_and_the_online_detector_is_the_forward_pass():
    """``online_verify`` (the retired ``VerifiedPPCADetector``) is an unknown key now; the
    online PPCA detector is the paper's forward pass, cutting like the "paper" variant's
    first pass."""
    from rtseg.detectors import make_online
    from rtseg.detectors.ppca.online import PPCADetector
    with pytest.raises(ConfigError, match="unknown key 'online_verify'"):
        method_params("ppca", {"online_verify": True})
    det = make_online("ppca", FPS)
    assert type(det) is PPCADetector and det.T == 150
    X, la = alternating_take(0)
    online = {(c.frame, c.detected_at) for c in det.run(X)}
    # the offline "paper" variant starts from the same forward pass (its later passes' cuts
    # are batch cuts: detected_at == frame)
    paper = segment_features(X, "ppca", FPS, {"variant": "paper"})
    assert online and online <= {(c.frame, c.detected_at) for c in paper}
    assert all(c.detected_at == c.frame for c in paper if (c.frame, c.detected_at) not in online)
