"""The pre-look: strong changes sent from a shorter after window (rtseg.detectors.prelook)."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.core.features import take_features
from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.sender import CutSender
from rtseg.detectors.prelook import PreLook
from rtseg.simulators.synth.motion import synthesize

FR = 120.0


def _profile(peak: int, height: float = 10.0, width: float = 3.0):
    """short(c, L): a hump at block ``peak`` whose height grows with L."""
    return lambda c, L: (1.0 + L / 16.0) * float(np.exp(-((c - peak) / width) ** 2)) * height


def test_a_strong_clear_maximum_is_sent():
    rule = PreLook(after=12, level=4.0, ratio=1.0, reach=8, shortest=8)
    assert rule.on
    v = rule.value(40, 1.25, 0, _profile(40))
    assert v == pytest.approx(_profile(40)(40, 12)) and rule.sent == 1


def test_weak_maxima_rising_flanks_and_falling_ones_are_not():
    rule = PreLook(after=12, level=4.0, ratio=1.0, reach=8, shortest=8)
    assert rule.value(40, 1.25, 0, _profile(40, height=2.0)) is None   # below 4 x 1.25
    assert rule.value(40, 1.25, 0, _profile(42)) is None   # the positions after it score higher
    assert rule.value(40, 1.25, 0, _profile(38)) is None   # one before it scored higher
    # a higher position before q counts within ``reach`` (8 blocks) and from ``first`` on
    before = lambda at: (lambda c, L: 20.0 if c == at else (10.0 if c == 40 else 5.0))  # noqa: E731
    assert rule.value(40, 1.25, 0, before(32)) is None
    assert rule.value(40, 1.25, 0, before(31)) == 10.0
    assert rule.value(40, 1.25, 33, before(32)) == 10.0
    assert rule.sent == 2


def test_the_ratio_and_the_shortest_window():
    # the positions after q at 0.95 of q's value on the same lengths: below ratio 1, not 0.9
    short = lambda c, L: 10.0 if c == 40 else 9.5   # noqa: E731
    assert PreLook(12, 4.0, 1.0, reach=8, shortest=8).value(40, 1.25, 0, short) == 10.0
    assert PreLook(12, 4.0, 0.9, reach=8, shortest=8).value(40, 1.25, 0, short) is None
    # only positions with at least ``shortest`` blocks of after window are asked: with 12
    # blocks and shortest 8, positions 41-44; a higher one at 45 is not seen yet
    late = lambda c, L: 20.0 if c == 45 else (10.0 if c == 40 else 5.0)   # noqa: E731
    assert PreLook(12, 4.0, 1.0, reach=8, shortest=8).value(40, 1.25, 0, late) == 10.0
    assert PreLook(12, 4.0, 1.0, reach=8, shortest=7).value(40, 1.25, 0, late) is None


def test_bad_pre_look_parameters_are_refused():
    assert not PreLook(0, 4.0, 1.0, 0, 8).on
    for bad in (dict(after=-1), dict(reach=0), dict(shortest=0), dict(ratio=0.0),
                dict(ratio=1.5), dict(level=0.0)):
        with pytest.raises(ValueError):
            PreLook(**{**dict(after=12, level=4.0, ratio=1.0, reach=8, shortest=8), **bad})
    p = dict(load_params()["contrast"], confirm_reach_s=1.0)
    with pytest.raises(ValueError, match="pre_after"):
        ContrastDetector.from_params(dict(p, pre_after_s=2.0), FR)     # not under after_s
    with pytest.raises(ValueError, match="confirm_reach_s"):
        ContrastDetector.from_params(dict(p, pre_after_s=1.5, confirm_reach_s=0.0), FR)
    from rtseg.config import ConfigError
    from rtseg.detectors import validate
    with pytest.raises(ConfigError, match="pre_ratio"):
        validate("contrast", {"pre_ratio": 1.5}, "test: ")


def test_send_now_takes_the_full_looks_waiting_maximum():
    cuts = CutSender(1.0, hold=100, min_gap=50, drop=0.1)
    assert cuts.update_full(100, 3.0, 110) is None
    assert cuts.full.candidate == 100
    sent = cuts.send_now(120, 8.0, 130)
    assert sent is not None and sent.peak.position == 120 and sent.strength == 8.0 and sent.prelook
    assert cuts.full.candidate is None                      # dropped: within min_gap
    assert cuts.update_full(140, 9.0, 150) is None          # kept min_gap away
    assert cuts.full.candidate is None
    assert cuts.send_now(160, 9.0, 170) is None             # a cut lies within min_gap
    cuts.update_full(200, 10.0, 210)
    assert cuts.full.candidate == 200                       # min_gap after the sent one


@pytest.fixture(scope="module")
def perf():
    res = synthesize("idle:5,walk:6,punch:6,squat:6,jumping_jacks:6", seed=4)
    return res, take_features(res.take)


ON = dict(confirm_reach_s=1.0, confirm_after_s=1.0, confirm_level=2.0, confirm_ratio=1.0,
          confirm_clear=0.0, pre_after_s=1.5, pre_level=4.0, pre_ratio=0.9)


def _run(X, **kw):
    """The full look (``--params full``: confirmation and pre-look off) with ``kw``."""
    det = ContrastDetector.from_params(dict(load_params("full")["contrast"], **kw), FR)
    return det, det.run(X)


def test_the_detector_sends_strong_changes_before_the_full_look(perf):
    """Every synthetic change is still cut within 0.5 s of its labelled middle, once; the
    pre-look sends some of them sooner than the full look (with its confirmation) does,
    and none later."""
    res, X = perf
    _, full = _run(X, **{k: v for k, v in ON.items() if not k.startswith("pre_")})
    det, pre = _run(X, **ON)
    mids = [t.mid for t in res.transitions]
    assert len(pre) == len(full) == len(mids)
    for c, m in zip(pre, mids):
        assert abs(c.frame - m) <= 0.5 * FR
    assert det.pre.sent >= 2
    assert sum(a.detected_at <= b.detected_at - 2 * det.step for a, b in zip(pre, full)) >= 2
    assert all(a.detected_at <= b.detected_at for a, b in zip(pre, full))


def test_on_by_default_and_a_prefix_gives_the_cuts_already_sent(perf):
    _, X = perf
    assert load_params()["contrast"]["pre_after_s"] > 0
    assert load_params("full")["contrast"]["pre_after_s"] == 0.0
    _, cuts = _run(X, **ON)
    assert cuts
    for n in sorted({c.detected_at + 1 for c in cuts}):
        assert _run(X[:n], **ON)[1] == [c for c in cuts if c.detected_at < n]
