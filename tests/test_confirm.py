"""Short-look confirmation of the contrast detector's maxima (rtseg.detectors.confirm)."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.core.features import take_features
from rtseg.detectors import load_params
from rtseg.detectors.confirm import ShortConfirmation
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.peaks import CausalPeaks
from rtseg.simulators.synth.motion import synthesize

FR = 120.0


def _profile(peak: int, width: float = 3.0):
    """short(c, L): a hump at block ``peak`` whose height grows with L (a longer after
    window sees more of the change)."""
    return lambda c, L: (1.0 + L / 16.0) * float(np.exp(-((c - peak) / width) ** 2)) * 10.0


def test_a_clean_maximum_is_confirmed_at_its_first_block():
    rule = ShortConfirmation(reach=8, shortest=8)
    short = _profile(peak=40)
    assert rule.first_block(40) == 56
    # one block too soon: not yet
    assert not rule.confirms(40, 10.0, 1.25, newest_full=40, newest=55, full_len=16, short=short)
    assert rule.confirms(40, 10.0, 1.25, newest_full=40, newest=56, full_len=16, short=short)
    assert rule.sent == 1


def test_a_rising_flank_waits_for_the_full_look():
    """The maximum's full value is known at block 40, but the change lies at 44: scored on
    the same short lengths, the positions after 40 score higher, so 40 is not sent."""
    rule = ShortConfirmation(reach=8, shortest=8)
    short = _profile(peak=44)
    for newest in range(56, 60):
        assert not rule.confirms(40, 5.0, 1.25, newest_full=40, newest=newest, full_len=16,
                                 short=short)
    assert rule.sent == 0


def test_level_ratio_and_off():
    short = _profile(peak=40)
    kw = dict(newest_full=40, newest=56, full_len=16, short=short)
    assert not ShortConfirmation(8, 8, level=4.0).confirms(40, 4.9, 1.25, **kw)  # < 4 x 1.25
    assert ShortConfirmation(8, 8, level=4.0).confirms(40, 5.1, 1.25, **kw)
    # a later position at 0.95 of the maximum's short value: below ratio 1, not below 0.9
    flat = lambda c, L: 10.0 if c == 40 else 9.5   # noqa: E731
    kw["short"] = flat
    assert ShortConfirmation(8, 8, ratio=1.0).confirms(40, 10.0, 1.25, **kw)
    assert not ShortConfirmation(8, 8, ratio=0.9).confirms(40, 10.0, 1.25, **kw)
    off = ShortConfirmation(0, 8)
    assert not off.on and not off.confirms(40, 10.0, 1.25, **kw)
    for bad in (dict(reach=-1, shortest=8), dict(reach=8, shortest=0),
                dict(reach=8, shortest=8, ratio=0.0), dict(reach=8, shortest=8, ratio=1.5),
                dict(reach=8, shortest=8, level=-1.0)):
        with pytest.raises(ValueError):
            ShortConfirmation(**bad)


def test_only_a_maximum_that_stands_clear_of_the_profile_before_it_is_sent():
    """``clear``: the maximum's full value against the full values of [c - span, c - reach);
    the reach just before it (its own rising flank) is left out, and a profile forgotten
    at a restart holds nothing back."""
    short = _profile(peak=40)
    kw = dict(newest_full=40, newest=56, full_len=16, short=short)

    def rule_with(profile: dict[int, float]) -> ShortConfirmation:
        rule = ShortConfirmation(reach=8, shortest=8, clear=1.5, span=24)
        for c in range(10, 41):
            rule.note(c, profile.get(c, 1.0))
        return rule

    # a behaviour whose profile rose to 8 two seconds before: 10 is not 1.5 x clear of it
    rule = rule_with({24: 8.0})
    assert not rule.confirms(40, 10.0, 1.25, **kw)
    assert rule.unclear == 1 and rule.sent == 0
    # 13 is; and the same 8 within the reach (block 33, the flank) or before the span
    # (block 15) does not count
    assert rule_with({24: 8.0}).confirms(40, 13.0, 1.25, **kw)
    assert rule_with({33: 9.9}).confirms(40, 10.0, 1.25, **kw)
    assert rule_with({15: 9.9}).confirms(40, 10.0, 1.25, **kw)
    rule = rule_with({24: 8.0})
    rule.reset()
    assert rule.confirms(40, 10.0, 1.25, **kw)
    # off (0) sends it whatever came before
    off = ShortConfirmation(reach=8, shortest=8, clear=0.0, span=24)
    off.note(24, 80.0)
    assert off.confirms(40, 10.0, 1.25, **kw)
    for bad in (dict(clear=0.5, span=24), dict(clear=1.5, span=8)):
        with pytest.raises(ValueError):
            ShortConfirmation(reach=8, shortest=8, **bad)


def test_peaks_confirm_sends_the_waiting_maximum_once():
    p = CausalPeaks(1.0, hold=100, min_gap=50, drop=0.1)
    assert p.confirm(5) is None
    p.update(10, 3.0, 20)
    assert p.candidate == 10 and p.candidate_value == 3.0
    peak = p.confirm(25)
    assert (peak.position, peak.value, peak.confirmed_at) == (10, 3.0, 25)
    assert p.candidate is None and p.confirm(26) is None
    assert p.update(40, 5.0, 50) is None and p.candidate is None      # within min_gap


@pytest.fixture(scope="module")
def perf():
    res = synthesize("idle:5,walk:6,punch:6,squat:6,jumping_jacks:6", seed=4)
    return res, take_features(res.take)


def _run(X, **kw):
    """The full look (``--params full``: confirmation and pre-look off) with ``kw``."""
    det = ContrastDetector.from_params(dict(load_params("full")["contrast"], **kw), FR)
    return det, det.run(X)


def test_the_detector_sends_the_same_changes_sooner(perf):
    """With the confirmation on, every synthetic change is cut where the full look cuts it
    (within a step) and sent sooner: at the maximum's own full look, the after window
    (2 s) plus at most two steps after the cut, where the full look waits for the contrast
    to fall."""
    res, X = perf
    _, later = _run(X)
    det, sooner = _run(X, confirm_reach_s=1.0, confirm_after_s=1.0, confirm_level=2.0,
                       confirm_ratio=0.9)
    mids = [t.mid for t in res.transitions]
    assert len(sooner) == len(later) == len(mids)
    for a, b, m in zip(sooner, later, mids):
        assert abs(a.frame - m) <= 0.5 * FR and abs(a.frame - b.frame) <= det.step
        assert a.detected_at <= b.detected_at
    assert det.confirm.sent >= 2
    d_sooner = np.median([c.detected_at - c.frame for c in sooner]) / FR
    d_later = np.median([c.detected_at - c.frame for c in later]) / FR
    assert d_sooner <= 2.0 + 2 * det.step / FR < d_later, (d_sooner, d_later)


def test_on_by_default_and_a_prefix_gives_the_cuts_already_sent(perf):
    """The shipped defaults turn it on and ``--params full`` off; with it on a cut still
    never depends on frames after the one that sent it."""
    _, X = perf
    assert load_params()["contrast"]["confirm_reach_s"] > 0
    assert load_params("full")["contrast"]["confirm_reach_s"] == 0.0
    kw = dict(confirm_reach_s=1.0, confirm_level=2.0, confirm_ratio=0.9)
    _, cuts = _run(X, **kw)
    assert cuts
    for n in sorted({c.detected_at + 1 for c in cuts}):
        assert _run(X[:n], **kw)[1] == [c for c in cuts if c.detected_at < n]


def test_bad_confirmation_parameters_are_refused():
    from rtseg.config import ConfigError
    from rtseg.detectors import validate
    with pytest.raises(ConfigError, match="confirm_ratio"):
        validate("contrast", {"confirm_ratio": 1.5}, "test: ")
    with pytest.raises(ConfigError, match="confirm_clear"):
        validate("contrast", {"confirm_clear": 0.5}, "test: ")


def test_shipped_defaults_cut_the_same_changes_sooner_than_the_full_look(perf):
    """The defaults are ``--params full`` (config/full.toml) with the confirmation and the
    pre-look on, a longer wait for the fall of a maximum neither sends (2 s and 0.4
    against 1 s and 0.5) and a lower gate (3.5 against 4): the same synthetic changes,
    each cut within 0.5 s of its labelled middle, most of them sent sooner than the full
    look sends them; one the short looks do not send waits up to the 1 s longer hold."""
    res, X = perf
    defaults = load_params()["contrast"]
    full = load_params("full")["contrast"]
    assert defaults["confirm_reach_s"] > 0 and defaults["pre_after_s"] > 0
    assert full["confirm_reach_s"] == 0 and full["pre_after_s"] == 0
    assert (defaults["hold_s"], defaults["drop"]) == (2.0, 0.4)
    assert (full["hold_s"], full["drop"], full["gate_threshold"]) == (1.0, 0.5, 4.0)
    assert defaults["gate_threshold"] == 3.5
    changed = ("confirm_", "pre_", "hold_s", "drop", "gate_threshold")
    assert {k: v for k, v in defaults.items() if not k.startswith(changed)} == \
        {k: v for k, v in full.items() if not k.startswith(changed)}
    sooner = ContrastDetector.from_params(defaults, FR).run(X)
    later = ContrastDetector.from_params(full, FR).run(X)
    assert len(sooner) == len(later) == len(res.transitions)
    for c, t in zip(sooner, res.transitions):
        assert abs(c.frame - t.mid) <= 0.5 * FR
    assert sum(a.detected_at < b.detected_at for a, b in zip(sooner, later)) >= 3
    assert all(a.detected_at <= b.detected_at + 1.0 * FR for a, b in zip(sooner, later))


def test_a_waiting_maximum_keeps_its_own_before_windows(perf):
    """The short looks compare a maximum with itself on shorter after windows: scored on
    the full after window it gives back its own full value (the models it was looked at
    with, kept while it waits - the detector's model cache and prefix ring have moved on
    when it is a second old), for every maximum checked, however old."""
    _, X = perf
    # 1 s before windows: the model cache is pruned every 8 looks and the prefix ring
    # holds 2 x 8 + 16 + 2 blocks, so a maximum a few blocks old has lost both
    det = ContrastDetector.from_params(dict(load_params("full")["contrast"], confirm_reach_s=1.0,
                                            confirm_level=0.0, confirm_clear=0.0, before_s=1.0,
                                            min_before_s=1.0), FR, keep_trace=True)
    checked = []
    orig = det._confirm_short

    def check(c):
        pos = det.peaks.full.candidate
        if pos is not None:
            cb = (pos - det._seg0) // det.step
            full = dict((p, v) for p, v, _ in det.trace)[pos]
            again = det._short(cb, det.wb)
            checked.append((c - cb, abs(again - full) / full))
        return orig(c)

    det._confirm_short = check
    det.run(X)
    ages = [a for a, _ in checked]
    assert checked and max(ages) >= 4, ages          # maxima looked at again blocks later
    assert max(err for _, err in checked) < 0.05, checked
    assert len(det._befores) <= det.peaks.full.hold // det.step + 2
