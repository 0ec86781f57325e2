"""Before windows bounded by the last cut sent (``[contrast] bound_before``,
rtseg.detectors.contrast): the rule, its purpose (short behaviours get windows of their
own), causality, restarts and the configuration check."""

from __future__ import annotations

import pytest

from rtseg.detectors import make_online
from rtseg.detectors.contrast import ContrastDetector
from rtseg.evaluation.scoring import score, widen
from rtseg.core.features import take_features
from rtseg.live.config import ConfigError
from rtseg.simulators.synth.motion import synthesize

FR = 120.0
#: behaviours of 3.5 s after a long one: 3 s before windows straddle the previous change
SHORT = "walk:8,punch:3.5,squat:3.5,walk:3.5,jump:3.5,punch:3.5"


def test_windows_reach_back_no_further_than_the_last_cut_once_it_is_3_s_old():
    det = ContrastDetector(bound_before=True)            # before 3 s = 24 blocks, min 12
    assert det._width(100) == det.wa                      # no cut sent yet
    det._last_sent = 60
    for c in range(61, 200):
        w = det._width(c)
        if (c - 60) // 2 >= det.wmin:                    # 3 s after the cut and on
            assert c - 2 * w >= 60 and w == min(det.wa, (c - 60) // 2)
        else:                                            # closer: straddle it, as unbounded
            assert w == det.wa
    assert ContrastDetector()._width(100) == det.wa      # unbounded: never shortened


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_short_behaviours_are_found_with_bounded_windows(seed):
    """Every change of 3.5 s behaviours after a long one, no false cut; the same detector
    with unbounded windows misses some over these seeds (the sum is checked below)."""
    res = synthesize(SHORT, seed=seed)
    X = take_features(res.take)
    truth = widen(list(res.transitions), int(0.5 * FR))
    cuts = make_online("contrast", FR, {"bound_before": True, "threshold": 2.0}).run(X)
    s = score([c.frame for c in cuts], truth)
    assert (s.tp, s.fp, s.fn) == (len(truth), 0, 0)


def test_unbounded_windows_miss_some_of_the_short_behaviours():
    found = 0
    for seed in (0, 1, 2):
        res = synthesize(SHORT, seed=seed)
        X = take_features(res.take)
        cuts = make_online("contrast", FR, {"bound_before": False, "threshold": 2.0}).run(X)
        found += score([c.frame for c in cuts],
                       widen(list(res.transitions), int(0.5 * FR))).tp
    assert found < 3 * 5


def test_bounded_detector_is_causal_and_a_restart_forgets_the_cut():
    res = synthesize(SHORT, seed=1)
    X = take_features(res.take)
    p = {"bound_before": True, "threshold": 2.0}
    cuts = make_online("contrast", FR, p).run(X)
    assert len(cuts) >= 4
    for n in sorted({c.detected_at + 1 for c in cuts} | {len(X) - 11}):
        assert make_online("contrast", FR, p).run(X[:n]) == [c for c in cuts if c.detected_at < n]
    det = make_online("contrast", FR, p)
    det.run(X[:cuts[0].detected_at + 1])
    assert det._last_sent is not None
    det.restart()
    assert det._last_sent is None


def test_bound_before_must_be_true_or_false(tmp_path):
    from rtseg.detectors import load_params
    f = tmp_path / "p.toml"
    f.write_text("[contrast]\nbound_before = 1\n")
    with pytest.raises(ConfigError, match="bound_before"):
        load_params(f)
