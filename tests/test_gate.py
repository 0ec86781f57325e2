"""The same-behaviour gate (rtseg.detectors.gate): a cut inside one behaviour is dropped, a
cut between two behaviours is sent after the decision time; the offline replay equals
feeding the frames; a restart decides held cuts; the contrast detector with the gate stays
causal."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.detectors import make_online
from rtseg.detectors.base import Cut
from rtseg.detectors.gate import SameBehaviourGate
from rtseg.core.features import take_features
from rtseg.simulators.synth.motion import synthesize

FR = 120.0


def _motion(kind: int, n: int, rng: np.random.Generator, d: int = 8) -> np.ndarray:
    """n frames of one 'behaviour': a periodic motion with its own axes and tempo."""
    t = np.arange(n) / FR
    axes = np.random.default_rng(100 + kind).normal(size=(3, d))
    freq = (0.8, 1.7, 2.9)[kind]
    waves = np.stack([np.sin(2 * np.pi * freq * t), np.cos(2 * np.pi * freq * t),
                      np.sin(4 * np.pi * freq * t)], axis=1)
    return waves @ axes + 0.05 * rng.normal(size=(n, d))


def _feed(gate: SameBehaviourGate, X: np.ndarray, cuts: dict[int, Cut]) -> list[Cut]:
    out = []
    for t, x in enumerate(X):
        gate.push(t, x)
        if t in cuts:
            gate.hold(cuts[t])
        c = gate.poll()
        if c is not None:
            out.append(c)
    return out


def test_a_cut_inside_one_behaviour_is_dropped_and_one_between_two_is_sent():
    rng = np.random.default_rng(0)
    X = np.vstack([_motion(0, 1200, rng), _motion(0, 600, rng), _motion(1, 1200, rng)])
    # a false cut at 1200 (same motion on both sides), a true one at 1800, each revealed
    # 0.5 s after its frame
    cuts = {1260: Cut(1200, "contrast", detected_at=1260),
            1860: Cut(1800, "contrast", detected_at=1860)}
    gate = SameBehaviourGate()
    sent = _feed(gate, X, cuts)
    assert [c.frame for c in sent] == [1800]
    assert sent[0].detected_at == 1800 + gate.decide_after      # held for 1.5 s of it
    assert gate.dropped == 1 and gate.sent == 1
    (b1, d1, s1), (b2, d2, s2) = gate.decisions
    assert (b1, s1, b2, s2) == (1200, False, 1800, True)
    assert d1 <= gate.threshold < d2


def test_a_cut_revealed_after_the_decision_time_goes_out_at_once():
    rng = np.random.default_rng(1)
    X = np.vstack([_motion(0, 1200, rng), _motion(2, 1200, rng)])
    late = 1200 + 300                                           # 2.5 s after the change
    sent = _feed(SameBehaviourGate(), X, {late: Cut(1200, "contrast", detected_at=late)})
    assert [(c.frame, c.detected_at) for c in sent] == [(1200, late)]


def test_restart_decides_the_held_cuts_on_the_frames_so_far():
    rng = np.random.default_rng(2)
    X = np.vstack([_motion(0, 1200, rng), _motion(1, 150, rng)])
    gate = SameBehaviourGate()
    for t, x in enumerate(X):
        gate.push(t, x)
    gate.hold(Cut(1200, "contrast", detected_at=1300))
    assert gate.poll() is None                       # 1.5 s of the segment not in yet
    gate.restart()                           # a gap: decide on the 1.25 s that came
    c = gate.poll()
    assert c is not None and c.frame == 1200 and gate.sent == 1


def test_the_gated_detector_is_causal():
    """A prefix of the frames gives exactly the gated cuts sent within it."""
    res = synthesize("walk:6,punch:6,walk:6,squat:6", seed=2)
    X = take_features(res.take)
    cuts = make_online("contrast", FR).run(X)
    assert cuts
    for n in sorted({c.detected_at + 1 for c in cuts} | {1500, len(X) - 7}):
        assert make_online("contrast", FR).run(X[:n]) == [c for c in cuts if c.detected_at < n]


def test_bad_gate_settings_are_refused():
    with pytest.raises(ValueError, match="threshold"):
        SameBehaviourGate(threshold=0)
    with pytest.raises(ValueError, match="ring"):
        SameBehaviourGate(ring=100)


def test_session_summary_counts_the_cuts_the_gate_held_back():
    from rtseg.live.stats import SessionSummary
    s = SessionSummary(duration_s=1.0, frames_received=120, frames_processed=120,
                       frame_rate=120.0, cuts=2, cuts_by_method={"contrast": 2}, dropped=0,
                       source_stats={}, pipeline={}, overruns=0, bad_frames=0, max_lag_ms=0.0,
                       cut_latency_ms_p50=None, cut_latency_ms_p99=None, recording=None,
                       stop_reason="test", wire_cuts=2, gated={"contrast": 3})
    assert "2 cuts (contrast 2; no OSC target; contrast gate held back 3)" in s.text()
    assert s.as_dict()["gated"] == {"contrast": 3}


def test_a_gap_while_a_cut_is_held_does_not_lose_it():
    """The detector restarts (a gap) while its gate holds a cut: the cut is decided on the
    frames before the gap and goes out with the next frame, not lost.  With a 1 s pre-look
    on, whose cuts come before the gate's decision time."""
    early = {"confirm_reach_s": 1.0, "pre_after_s": 1.0, "pre_level": 2.0}
    res = synthesize("walk:6,punch:6", seed=3)
    X = take_features(res.take)
    full = make_online("contrast", FR, early)
    cuts = full.run(X)
    assert len(cuts) == 1
    c = cuts[0]
    # stop while the cut is held: after the ungated detector made it, before 1.5 s of its
    # segment were in
    ungated = make_online("contrast", FR, {**early, "gate_threshold": 0}).run(X)
    made = ungated[0].detected_at
    assert made < c.frame + full.gate.decide_after
    det = make_online("contrast", FR, early)
    assert det.run(X[:made + 1]) == []
    det.restart()
    out = det.update(X[made + 1])
    # the same change (placement, which reads only the new segment's frames after a
    # restart, may leave it where the look found it: within its 1 s radius)
    assert out is not None and abs(out.frame - c.frame) <= FR and out.detected_at == made + 1


def test_a_decision_worked_out_ahead_is_the_decision_made_on_the_frame():
    """The deciding frame's own row is not in the window after the cut, so
    ``prepare_decision`` before that frame arrives finds the distance the decision finds
    (used, and counted in ``made_ahead``); a wild row on the deciding frame changes
    nothing."""
    rng = np.random.default_rng(3)
    X = np.vstack([_motion(0, 1200, rng), _motion(1, 1200, rng)])
    decide_at = 1200 + 180
    results = []
    for ahead, wild in ((False, False), (True, False), (False, True)):
        Y = X.copy()
        if wild:
            Y[decide_at] = 1e3
        gate = SameBehaviourGate()
        gate.share(np.zeros((gate.ring, Y.shape[1])))
        out = []
        for t, x in enumerate(Y):
            if ahead and t == decide_at:
                assert gate.prepare_decision(1200, t)          # before frame t arrives
                assert not gate.prepare_decision(1200, t)      # once
            gate._rows[t % gate.ring] = x
            c = gate.tick(t, Cut(1200, "contrast", detected_at=1210) if t == 1210 else None)
            if c is not None:
                out.append(c)
        results.append(([(c.frame, c.detected_at) for c in out], gate.decisions,
                         gate.made_ahead))
    (plain, dec, n0), (early, dec_ahead, n1), (wild, dec_wild, _) = results
    assert plain == early == wild == [(1200, decide_at)]
    assert dec == dec_ahead == dec_wild and dec[0][2]
    assert (n0, n1) == (0, 1)
