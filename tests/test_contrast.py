"""The causal contrast detector (rtseg.detectors.contrast), its window models and its
causal peak picker: behaviour on synthetic motion, causality, restarts, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtseg.detectors import make_online, segment_features
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.pca.distance import cross_error as _cross_error
from rtseg.detectors.pca.distance import pca_model as _pca_model
from rtseg.detectors.peaks import CausalPeaks
from rtseg.detectors.window_models import (
    WindowStats, fit, pca_distance, pca_error, ppca_distance, ppca_msq,
)
from rtseg.core.features import take_features
from rtseg.simulators.synth.motion import synthesize

FR = 120.0


@pytest.fixture(scope="module")
def perf():
    """A synthetic performance with 4 changes and its pose features."""
    res = synthesize("idle:5,walk:6,punch:6,squat:6,jumping_jacks:6", seed=4)
    return res, take_features(res.take)


# ---------------------------------------------------------------- window models
def test_window_stats_from_sums_equal_direct():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(50, 6))
    s = WindowStats.of(X)
    Z = X - X.mean(axis=0)
    assert s.n == 50
    np.testing.assert_allclose(s.mean, X.mean(axis=0))
    np.testing.assert_allclose(s.scatter, Z.T @ Z, atol=1e-10)


def test_block_windows_give_each_windows_statistics_and_fit_it_once():
    """The contrast detector's store (rtseg.detectors.block_windows): windows of whole
    blocks from the prefix-sum ring equal their rows' statistics (about any reference
    frame), while their prefixes are in the ring; a model is fitted once, kept until
    pruned, and a reset starts the blocks again."""
    from rtseg.detectors.block_windows import BlockWindows
    rng = np.random.default_rng(5)
    X = rng.normal(size=(200, 4)) @ rng.normal(size=(4, 4))
    ref = X[0]
    bw = BlockWindows(4, step=10, capacity=8, pca_energy=0.9)
    for k in range(20):
        bw.add(k, X[10 * k:10 * k + 10] - ref)
    for lo, hi in ((13, 20), (15, 17), (19, 20)):      # within the last 8 prefixes
        s, direct = bw.stats(lo, hi), WindowStats.of(X[10 * lo:10 * hi])
        assert s.n == direct.n
        np.testing.assert_allclose(s.mean + ref, direct.mean, atol=1e-9)
        np.testing.assert_allclose(s.scatter, direct.scatter, atol=1e-8)
    m = bw.model(14, 18)
    assert bw.model(14, 18) is m and bw.fits == 1
    bw.prune(15)
    assert bw.model(14, 18) is not m and bw.fits == 2
    bw.reset()
    assert bw.fits == 0 and not bw.models
    bw.add(0, X[:10] - ref)
    assert bw.stats(0, 1).n == 10
    np.testing.assert_allclose(bw.stats(0, 1).mean + ref, X[:10].mean(axis=0), atol=1e-9)


def test_pca_error_equals_the_frame_wise_projection_error():
    """From statistics alone, the same number as projecting every frame (pca.py)."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(120, 8)) @ rng.normal(size=(8, 8))
    B = rng.normal(size=(90, 8)) @ rng.normal(size=(8, 8)) + 0.3
    ma = fit(WindowStats.of(A), pca_energy=0.9)
    assert pca_error(WindowStats.of(B), ma) == pytest.approx(
        _cross_error(B, _pca_model(A, 0.9)), rel=1e-9)
    assert pca_error(WindowStats.of(A), ma) == pytest.approx(1.0, rel=1e-9)


def test_ppca_msq_equals_the_frame_wise_mahalanobis_mean():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(200, 5)) * [3.0, 2.0, 1.0, 0.5, 0.2]
    B = rng.normal(size=(80, 5)) + 1.0
    m = fit(WindowStats.of(A), ppca_energy=0.95)
    mu = A.mean(axis=0)
    C = (m.ppca_basis * m.ppca_var) @ m.ppca_basis.T + m.ppca_sigma2 * (
        np.eye(5) - m.ppca_basis @ m.ppca_basis.T)
    Z = B - mu
    direct = float(np.mean(np.einsum("ij,jk,ik->i", Z, np.linalg.inv(C), Z)))
    assert ppca_msq(WindowStats.of(B), m) == pytest.approx(direct, rel=1e-9)


def test_distances_small_within_a_motion_large_between():
    rng = np.random.default_rng(3)
    t = np.arange(600) / FR
    walk = np.stack([np.sin(2 * np.pi * 1.0 * t + k) for k in range(6)], axis=1)
    wave = np.stack([np.sin(2 * np.pi * 2.3 * t + 2 * k) * (k % 2) for k in range(6)], axis=1)
    walk += rng.normal(scale=0.01, size=walk.shape)
    wave += rng.normal(scale=0.01, size=wave.shape)
    a, b, c = (fit(WindowStats.of(X)) for X in (walk[:300], walk[300:], wave[:300]))
    assert pca_distance(a, b) < 2.0 < pca_distance(a, c)
    assert ppca_distance(a, b) < ppca_distance(a, c)
    assert pca_distance(a, c) == pytest.approx(pca_distance(c, a))


# ---------------------------------------------------------------- peak picker
def test_peaks_threshold_hold_and_once():
    pk = CausalPeaks(threshold=2.0, hold=30, min_gap=50, drop=0.0)
    prof = [1, 1.5, 2.5, 3.0, 2.9, 2.8, 2.7, 2.6, 1.0, 1.0]
    out = [pk.update(10 * i, v, 10 * i + 100) for i, v in enumerate(prof)]
    peaks = [p for p in out if p is not None]
    assert len(peaks) == 1
    p = peaks[0]
    assert (p.position, p.value) == (30, 3.0)
    assert p.confirmed_at == 60 + 100        # 30 frames of positions after the maximum


def test_peaks_drop_confirms_early_and_min_gap_separates():
    pk = CausalPeaks(threshold=2.0, hold=100, min_gap=40, drop=0.5)
    seq = [(0, 1.0), (10, 4.0), (20, 1.5), (30, 5.0), (40, 1.0), (50, 1.0), (60, 6.0),
           (70, 1.0)]
    got = [p for p in (pk.update(pos, v, pos) for pos, v in seq) if p is not None]
    # 4.0 confirmed by the drop to 1.5; 5.0 at 30 is only 20 after it: refused; 6.0 at 60 ok
    assert [(p.position, p.value, p.confirmed_at) for p in got] == [(10, 4.0, 20), (60, 6.0, 70)]


def test_peaks_need_to_beat_the_recent_past():
    """The slow shoulder of a peak already sent is not a new change once min_gap has
    passed: a candidate must exceed every value of the preceding min_gap frames."""
    pk = CausalPeaks(threshold=1.0, hold=10, min_gap=30, drop=0.0)
    vals = [9.0, 8.9, 8.8, 8.7, 8.6, 8.5, 8.4]
    got = [p for p in (pk.update(10 * i, v, 10 * i) for i, v in enumerate(vals)) if p]
    assert [(p.position, p.value) for p in got] == [(0, 9.0)]
    # a rise above the shoulder after it is a new change
    assert pk.update(70, 9.5, 70) is None and pk.update(80, 2.0, 80).position == 70


def test_peaks_reset_and_validation():
    pk = CausalPeaks(threshold=1.0, hold=10, min_gap=0, drop=0.0)
    assert pk.update(0, 5.0, 0) is None
    pk.reset()
    assert pk.update(10, 0.5, 10) is None and pk.update(20, 0.4, 20) is None
    with pytest.raises(ValueError):
        CausalPeaks(1.0, hold=-1, min_gap=0)
    with pytest.raises(ValueError):
        CausalPeaks(1.0, hold=1, min_gap=0, drop=1.0)


# ---------------------------------------------------------------- detector
def test_finds_every_synthetic_change_within_half_a_second(perf):
    res, X = perf
    cuts = make_online("contrast", FR).run(X)
    mids = [t.mid for t in res.transitions]
    assert len(cuts) == len(mids), ([c.frame for c in cuts], mids)
    for c, m in zip(cuts, mids):
        assert abs(c.frame - m) <= 0.5 * FR
        delay = (c.detected_at - m) / FR
        assert 0 < delay <= 1.75 + 1.0 + 0.125 + 0.5      # after window + hold (+ a step)
        assert 0.0 <= c.confidence <= 1.0 and c.score >= 2.0 and c.method == "contrast"


def test_no_cut_in_one_long_behaviour():
    res = synthesize("walk:40", seed=5)
    assert make_online("contrast", FR).run(take_features(res.take)) == []


def test_causal_a_prefix_gives_the_cuts_already_sent(perf):
    """A cut never depends on frames after the one that produced it: running any prefix
    gives exactly the cuts of the full run that were produced within the prefix."""
    _, X = perf
    full = make_online("contrast", FR, keep_trace=True)
    cuts = full.run(X)
    assert cuts
    for n in sorted({c.detected_at + 1 for c in cuts} | {1000, 2345, len(X) - 1}):
        part = make_online("contrast", FR, keep_trace=True)
        got = part.run(X[:n])
        assert got == [c for c in cuts if c.detected_at < n]
        # and the contrast profile itself is the same up to the prefix
        assert part.trace == full.trace[:len(part.trace)]


def _quiet_runs(det, X):
    """Feed X; (cut frames by update number, quiet count before each update)."""
    sent, quiet = [], []
    for i, x in enumerate(X):
        quiet.append(det.quiet_frames)
        if det.update(x) is not None:
            sent.append(i)
    return sent, np.array(quiet)


@pytest.mark.parametrize("kw", [{}, {"gate_threshold": 0.0},
                                {"gate_threshold": 1e9},
                                {"confirm_reach_s": 1.0, "confirm_level": 2.0},
                                {"confirm_reach_s": 1.0, "confirm_level": 2.0,
                                 "pre_after_s": 1.5, "pre_level": 4.0}])
def test_quiet_frames_never_hide_a_cut(perf, kw):
    """quiet_frames is a promise the live loop relies on: none of the next that many
    frames sends a cut (without the gate, with a gate dropping
    every cut, with the short-look confirmation and the pre-look).  Most frames are quiet, so the promise is worth having."""
    _, X = perf
    from rtseg.detectors import load_params
    p = dict(load_params()["contrast"], **kw)
    det = ContrastDetector.from_params(p, FR)
    sent, quiet = _quiet_runs(det, X)
    for i, q in enumerate(quiet):
        assert not any(i <= c < i + q for c in sent), (i, q, sent)
    assert (quiet > 0).mean() > 0.85          # about one frame in a step may send
    assert quiet.max() == det.step + 1
    if kw.get("gate_threshold") == 1e9:
        assert not sent and det.gate.dropped > 0     # held cuts were decided on time
    else:
        assert sent


def test_offline_segment_runs_the_same_core(perf):
    _, X = perf
    live = make_online("contrast", FR).run(X)
    assert [c.frame for c in segment_features(X, "contrast", FR)] == [c.frame for c in live]


@pytest.mark.parametrize("preset", [None, "full"])
def test_restart_forgets_the_segment_and_keeps_the_frame_count(perf, preset):
    """After a restart the cuts are a fresh detector's, counted on (with the short-look
    confirmation and the pre-look, the defaults, and without them, ``full``).  The residual and relative floors outlive restarts
    by design (a gap is not a new performer), so they are off here: with them the cuts may
    differ by what they learnt before the gap."""
    from rtseg.detectors import load_params
    _, X = perf
    p = {**load_params(preset)["contrast"], "residual_floor": 0.0, "relative_floor": 0.0}
    det = ContrastDetector.from_params(p, FR)
    det.run(X[:1000])
    det.restart()
    cuts = det.run(X[1000:])
    fresh = ContrastDetector.from_params(p, FR).run(X[1000:])
    assert len(fresh) >= 3
    assert [(c.frame, c.detected_at) for c in cuts] == \
        [(c.frame + 1000, c.detected_at + 1000) for c in fresh]


def test_non_finite_frame_restarts_and_is_counted(perf):
    _, X = perf
    det = make_online("contrast", FR)
    Y = X.copy()
    Y[700, 3] = np.nan
    cuts = det.run(Y)
    assert det.rejected_frames == 1
    assert all(c.frame > 700 for c in cuts if c.detected_at > 700)
    with pytest.raises(ValueError):
        det.update(np.zeros(X.shape[1] + 1))


def test_frame_rate_scales_the_windows():
    det = make_online("contrast", 60.0, {"confirm_reach_s": 1.0, "pre_after_s": 1.5})
    # 0.125 s -> 8 frames (7.5 rounded half to even); 3 s -> 22 blocks; 2 s -> 15 blocks;
    # the pre-look's 1.5 s -> 11 blocks (90 / 8 = 11.25), the reach's 1 s -> 8; hold 2 s -> 120
    assert (det.step, det.wa, det.wb, det.pre.after, det.pre.reach) == (8, 22, 15, 11, 8)
    assert det.delay_frames == 15 * 8 + 120 + 8


@pytest.mark.parametrize("kw", [dict(step=0), dict(before=10), dict(after=5),
                                dict(min_before=400), dict(threshold=0.0),
                                dict(threshold=math.nan), dict(reference_dims=0)])
def test_bad_parameters_are_refused(kw):
    with pytest.raises(ValueError):
        ContrastDetector(**kw)


def test_distances_equal_the_two_distance_functions():
    from rtseg.detectors.window_models import distances
    rng = np.random.default_rng(9)
    a = fit(WindowStats.of(rng.normal(size=(200, 7)) @ rng.normal(size=(7, 7))))
    b = fit(WindowStats.of(rng.normal(size=(150, 7)) + 0.5))
    p, q = distances(a, b)
    assert p == pytest.approx(pca_distance(a, b), rel=1e-12)
    assert q == pytest.approx(ppca_distance(a, b), rel=1e-12)


# ---------------------------------------------------------------- sending
def _sender():
    # full look: threshold 2, hold 20; changes at least 50 frames apart
    from rtseg.detectors.sender import CutSender
    return CutSender(2.0, hold=20, min_gap=50, drop=0.5)


def assert_same_changes_sooner(res, sooner, later) -> None:
    """Both cut lists find every labelled change of ``res``, ``sooner``'s within 0.5 s of
    the labelled middles, and ``sooner``'s are sent at least 0.25 s sooner (median)."""
    mids = [t.mid for t in res.transitions]
    assert len(sooner) == len(later) == len(mids)
    for c, m in zip(sooner, mids):
        assert abs(c.frame - m) <= 0.5 * FR
    d_sooner = np.median([c.detected_at - c.frame for c in sooner])
    d_later = np.median([c.detected_at - c.frame for c in later])
    assert d_sooner < d_later - 0.25 * FR, (d_sooner, d_later)


def test_shipped_fast_parameters_cut_sooner(perf):
    """``--params fast`` (config/fast.toml): the same synthetic changes, each within 0.5 s
    of the labelled middle, sent sooner than with the full look (``--params full``) and
    none later than with the defaults."""
    from rtseg.detectors import load_params
    res, X = perf
    fast = load_params("fast")["contrast"]
    assert fast["pre_after_s"] > 0 and fast != load_params()["contrast"]
    cuts = ContrastDetector.from_params(fast, FR).run(X)
    assert_same_changes_sooner(res, cuts,
                               ContrastDetector.from_params(load_params("full")["contrast"],
                                                            FR).run(X))
    defaults = ContrastDetector.from_params(load_params()["contrast"], FR).run(X)
    assert len(defaults) == len(cuts)
    assert all(a.detected_at <= b.detected_at for a, b in zip(cuts, defaults))


def test_two_cuts_confirmed_on_one_frame_go_out_one_frame_apart(perf):
    """When one frame's step sends two changes (>= min_gap apart: the full look's
    maximum and the pre-look's), the detector returns the first on that frame and the
    second on the next, whose detected_at says so; none is lost."""
    from rtseg.detectors.peaks import Peak
    from rtseg.detectors.sender import SentPeak
    _, X = perf
    det = make_online("contrast", FR, {"gate_threshold": 0})   # the looks alone
    look = det._look_full
    fired = []

    def both(c):
        look(c)
        if not fired and c * det.step > 600:
            fired.append(det._t - 1)
            pos = det._seg0 + c * det.step
            det._out.extend([SentPeak(Peak(pos - 300, 9.0, det._t - 1), False, 9.0),
                             SentPeak(Peak(pos, 50.0, det._t - 1), True, 3.0)])

    det._look_full = both
    out = [(i, det.update(x)) for i, x in enumerate(X[:1500])]
    cuts = [(i, c) for i, c in out if c is not None and i >= fired[0]]
    assert len(cuts) >= 2, cuts
    (i1, c1), (i2, c2) = cuts[:2]
    assert i1 == fired[0] and i2 == i1 + 1 and c1.detected_at == i1 and c2.detected_at == i2
    assert c1.frame < c2.frame
    assert c1.confidence == pytest.approx(1 - det.threshold / 9.0)
    assert c2.score == 3.0 and c2.confidence == pytest.approx(1 - det.threshold / 3.0)


# ---------------------------------------------------------------- gate drops
def test_a_forgotten_peak_keeps_no_later_one_away():
    """The gate dropped the first cut: the picker's min_gap no longer counts from it, but a
    later maximum must still beat the values before it."""
    pk = CausalPeaks(threshold=2.0, hold=100, min_gap=40, drop=0.5)
    first = [p for p in (pk.update(pos, v, pos) for pos, v in ((0, 1.0), (10, 4.0), (20, 1.5)))
             if p]
    assert [p.position for p in first] == [10]
    pk.forget(10)
    got = [p for p in (pk.update(pos, v, pos) for pos, v in ((30, 3.0), (40, 5.0), (50, 1.0)))
           if p]
    assert [(p.position, p.value) for p in got] == [(40, 5.0)]   # 3.0 < 4.0 within min_gap


def test_the_sender_forgets_a_dropped_cut():
    ec = _sender()
    for pos, v in ((100, 1.0), (105, 3.0), (110, 1.0)):
        sent = ec.update_full(pos, v, pos + 70)
    assert sent is not None and sent.peak.position == 105
    # a second change 30 frames later (less than min_gap 50) is refused while 105 stands ...
    kept = _sender()
    for pos, v in ((100, 1.0), (105, 3.0), (110, 1.0)):
        kept.update_full(pos, v, pos + 70)
    assert [kept.update_full(p, v, p + 70) for p, v in ((130, 4.0), (135, 1.0))][1] is None
    # ... and sent once the gate dropped it
    ec.forget(105)
    out = [ec.update_full(p, v, p + 70) for p, v in ((130, 4.0), (135, 1.0))]
    assert out[1] is not None and out[1].peak.position == 130


def test_a_cut_the_gate_drops_does_not_hide_the_change_after_it():
    """A premature cut the gate drops must not keep the true change, under
    min_gap later, from being cut (the synthetic performance resampled to 30 fps has one)."""
    from rtseg.core.resample import resample_take
    from rtseg.detectors import load_params
    from rtseg.evaluation.online import fed_features, live_config
    perf = synthesize(seed=3)
    take = resample_take(perf.take, 30.0)
    cfg, _ = live_config(methods=["contrast"])
    X, _, _ = fed_features(take, cfg)
    det = ContrastDetector.from_params(load_params()["contrast"], 30.0)
    cuts = [c.frame / 30.0 for c in det.run(X)]
    dropped = [b / 30.0 for b, _, sent in det.gate.decisions if not sent]
    assert dropped, "the take should hold a cut the gate drops"
    # the change after the dropped cut, and under min_gap (2 s) from it, is cut
    after = next(t for t in perf.transitions if t.lo / 120.0 > dropped[0])
    assert after.lo / 120.0 - dropped[0] < 2.0
    assert any(after.lo / 120.0 - 0.5 <= c <= after.hi / 120.0 + 0.5 for c in cuts)


# ---------------------------------------------------------------- warm-started window fits
def test_warm_started_pca_fit_follows_the_exact_one():
    """Windows sliding over the synthetic performance (every 1/8 s): the model warm
    started from the previous window's gives, within 1 %, the exact fit's
    projection errors; without a warm start it is the exact fit."""
    from rtseg.detectors.window_models import fit_pca
    X = take_features(synthesize(seed=1).take)
    warm = None
    worst = 0.0
    for lo in range(0, len(X) - 600, 15):
        s = WindowStats.of(X[lo:lo + 360])
        exact, approx = fit(s), fit_pca(s, warm=warm)
        assert fit_pca(s).pca_basis.shape == exact.pca_basis.shape and fit_pca(s).exact
        y = WindowStats.of(X[lo + 360:lo + 600])
        worst = max(worst, abs(pca_error(y, approx) / pca_error(y, exact) - 1))
        warm = approx
    assert worst < 0.01
    assert warm is not None and not warm.exact
