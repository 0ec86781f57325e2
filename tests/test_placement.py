"""Cut placement (rtseg.detectors.placement) and the contrast detector's use of it."""

import numpy as np
import pytest

from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.placement import place


def _two_behaviours(n1: int, n2: int, dim: int = 8, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 0.1, (n1, dim))
    b = rng.normal(0.0, 0.1, (n2, dim)) @ np.diag(np.linspace(0.5, 3.0, dim))
    b[:, 0] += 0.3
    return np.vstack([a, b])


def test_place_finds_the_split_of_two_gaussians():
    X = _two_behaviours(200, 180)
    for guess in (150, 190, 240):
        assert abs(place(X, guess, radius=60, stride=1) - 200) <= 3


def test_place_stays_within_radius_and_margin():
    X = _two_behaviours(200, 180)
    assert abs(place(X, 100, radius=20, stride=1) - 100) <= 20
    assert place(X, 1, radius=50, stride=1, margin=10) >= 10
    assert place(X[:3], 1, radius=5, margin=2) == 1      # too short: unchanged


def test_detector_cut_placed_nearer_the_change():
    rng = np.random.default_rng(1)
    fr = 120.0
    t = np.arange(int(16 * fr)) / fr
    X = np.zeros((len(t), 12))
    change = int(8 * fr)
    X[:change, :6] = np.sin(2 * np.pi * 1.0 * t[:change, None] + np.arange(6))
    X[change:, 6:] = 0.7 * np.sin(2 * np.pi * 0.4 * t[change:, None] + np.arange(6))
    X += rng.normal(0, 0.02, X.shape)
    p = dict(load_params()["contrast"], gate_threshold=0.0)
    plain = ContrastDetector.from_params({**p, "place_radius_s": 0.0}, fr).run(X)
    placed = ContrastDetector.from_params({**p, "place_radius_s": 1.0}, fr).run(X)
    assert len(plain) == len(placed) == 1
    assert abs(placed[0].frame - change) <= abs(plain[0].frame - change)
    assert abs(placed[0].frame - change) <= 0.1 * fr


def test_placement_moves_the_default_detectors_cuts_and_never_adds_or_drops_one():
    """With the shipped gate and bounded windows, placement on gives the cuts of placement
    off (same count, same detection frames), each moved at most the radius."""
    from rtseg.evaluation.online import fed_features, live_config
    from rtseg.simulators.synth.motion import synthesize

    take = synthesize("idle:4,walk:5,punch:4,walk:5,squat:5,punch:4", seed=3).take
    X, _, _ = fed_features(take, live_config()[0])
    fr = take.frame_rate
    p = load_params()["contrast"]
    assert p["gate_threshold"] > 0 and p["bound_before"]
    plain = ContrastDetector.from_params({**p, "place_radius_s": 0.0}, fr).run(X)
    placed = ContrastDetector.from_params({**p, "place_radius_s": 1.0}, fr).run(X)
    assert len(plain) >= 3
    assert [c.detected_at for c in placed] == [c.detected_at for c in plain]
    moves = [q.frame - c.frame for c, q in zip(plain, placed)]
    assert all(abs(m) <= fr for m in moves)
    assert any(moves)                                 # placement did act
    assert all(a.frame < b.frame for a, b in zip(placed, placed[1:]))


def test_a_placement_made_in_pieces_gives_the_split_of_one_call():
    """begin / advance / best do the one call's arithmetic: the same split on spans of
    every shape, ``pending`` names the placement held until another replaces it."""
    from rtseg.detectors.placement import Placer
    rng = np.random.default_rng(5)
    for trial in range(60):
        d, n = int(rng.integers(3, 30)), int(rng.integers(12, 400))
        c = int(rng.integers(0, n))
        X = rng.standard_normal((n, d)) * rng.uniform(0.2, 3.0, d)
        X[c:] += rng.standard_normal(d)
        radius, stride = int(rng.integers(1, 100)), int(rng.integers(1, 5))
        one = Placer(d, 400, radius, stride, margin=3)(X, c)
        p = Placer(d, 400, radius, stride, margin=3)
        p.begin(X, c, ("span", trial))
        assert p.pending(("span", trial)) and not p.pending(("span", trial + 1))
        pieces = 1
        while not p.advance():
            pieces += 1
        assert p.done() and p.best() == one
        assert pieces <= 1 + (2 * radius // stride + 1 + 7) // 8
        p(X, c)                                   # a call replaces what was held
        assert not p.pending(("span", trial))


@pytest.mark.parametrize("preset", ["full", None])
def test_work_ahead_changes_no_cut_and_leaves_the_cut_frames_little_to_do(preset):
    """``ContrastDetector.ahead`` between frames (the live loop's idle time) places the
    waiting maximum and fits the gate's window before it: every cut is the one made
    without it (frame, detection frame, score).  With the full look (``full``) every cut
    sent found its placement made ahead; the defaults send most changes on the frame
    whose look finds them (the short-look confirmation, the pre-look), with no frame
    between to work ahead on."""
    from rtseg.evaluation.online import fed_features, live_config
    from rtseg.simulators.synth.motion import synthesize

    take = synthesize("idle:4,walk:5,punch:4,walk:5,squat:5,punch:4", seed=3).take
    X, _, _ = fed_features(take, live_config()[0])
    p = load_params(preset)["contrast"]
    plain = ContrastDetector.from_params(p, take.frame_rate).run(X)
    det = ContrastDetector.from_params(p, take.frame_rate)
    cuts, pieces = [], 0
    for x in X:
        c = det.update(x)
        if c is not None:
            cuts.append(c)
        while det.ahead():
            pieces += 1
    key = [(c.frame, c.detected_at, c.score, c.confidence) for c in plain]
    assert len(plain) >= 3
    assert [(c.frame, c.detected_at, c.score, c.confidence) for c in cuts] == key
    if preset == "full":
        assert det._placement.made_ahead == len(cuts)
        assert det.gate.made_ahead >= len(cuts)      # dropped cuts are decided too
    assert pieces > 10 * len(cuts)
    assert not det.ahead()                           # nothing waits at the end
