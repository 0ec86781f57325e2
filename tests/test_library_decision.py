"""The library's decision (rtseg.library.calibration.decision_excess, Library.decide): the nearest
name is given when log(d1 / threshold) + MARGIN_WEIGHT x log((d1 / d2) / ratio) <=
MARGIN_LEVEL - a name far nearer than the second may lie a little beyond the threshold, two
names about as near are refused even within it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtseg.library import calibration as B
from rtseg.library.behaviours import UNKNOWN, Library
from rtseg.library.calibration import decision_excess


def _library(names: list[str], threshold: float = 2.0, ratio: float = 1.0,
             calibrated: bool = True) -> Library:
    """A model library of one window per name, decided on given distances only; its
    threshold taken as calibrated (or as the default of one that could not be)."""
    lib = Library(profile="test", dims=4, frame_rate=120.0,
                  descriptors=np.zeros((len(names), 4)), names=list(names),
                  sources=list(range(len(names))),
                  examples=[{"name": n, "source": str(k)} for k, n in enumerate(names)],
                  metric="model", calibration={"calibrated": calibrated})
    lib.threshold, lib.ratio = threshold, ratio
    return lib


def test_without_a_second_name_the_threshold_alone_decides():
    assert decision_excess(1.5, math.inf, 2.0, 1.0) == pytest.approx(math.log(0.75))
    assert decision_excess(2.5, math.inf, 2.0, 1.0) == pytest.approx(math.log(1.25))
    lib = _library(["walk"])
    assert lib.decide(np.array([1.9])).name == "walk"
    assert lib.decide(np.array([2.1])).name == UNKNOWN


def test_the_threshold_scales_the_bound_and_the_excess_moves_the_right_way():
    base = decision_excess(1.8, 2.4, 2.0, 1.0)
    assert decision_excess(1.8, 2.4, 4.0, 1.0) == pytest.approx(base - math.log(2.0))
    # farther nearest name: more excess; farther second name: less
    assert decision_excess(1.9, 2.4, 2.0, 1.0) > base
    assert decision_excess(1.8, 3.0, 2.0, 1.0) < base
    # a calibrated ratio below 1 asks for more margin
    assert decision_excess(1.8, 2.4, 2.0, 0.9) > base
    assert decision_excess(0.0, 1.0, 2.0, 1.0) == -math.inf
    assert decision_excess(1.0, 2.0, 0.0, 1.0) == math.inf


def test_shipped_margin_refuses_a_tie_and_names_a_clear_nearest():
    """With the shipped constants (a negative level, a positive weight): two names equally
    near, both within the threshold, give ``unknown``; a nearest name four times nearer than
    the second is given a little beyond the threshold.  Confidence is 0 at the bound."""
    assert B.MARGIN_WEIGHT > 0 and B.MARGIN_LEVEL < 0
    t = 2.0
    tie = t * math.exp(B.MARGIN_LEVEL / 2)            # within the threshold
    lib = _library(["walk", "punch"], threshold=t)
    got = lib.decide(np.array([tie, tie * 1.0001]))
    assert got.name == UNKNOWN and got.nearest == "walk"
    clear = lib.decide(np.array([1.2 * t, 4.8 * t]))
    assert clear.name == "walk" and 0.0 < clear.confidence < 1.0
    # exactly at the bound: d2 chosen so the margin term cancels the level
    d1 = 0.9 * t
    d2 = d1 / math.exp(B.MARGIN_LEVEL / B.MARGIN_WEIGHT)
    assert decision_excess(d1, d2, d1, 1.0) == pytest.approx(0.0, abs=1e-12)
    at = lib.decide(np.array([d1, d2]), scale=d1 / t * (1 + 1e-9))   # a hair within
    assert at.name == "walk" and at.confidence == pytest.approx(0.0, abs=1e-6)
    assert lib.decide(np.array([d1, d2]), scale=d1 / t * (1 - 1e-9)).name == UNKNOWN


def test_a_farther_second_name_turns_unknown_into_a_name():
    lib = _library(["walk", "punch", "squat"], threshold=2.0)
    d = np.array([2.2, 2.4, 9.0])
    assert lib.decide(d).name == UNKNOWN
    d[1] = 6.0                                        # punch moved away: walk stands out
    assert lib.decide(d).name == "walk"


def test_no_margin_names_beyond_the_cap():
    """However far the second name, a nearest name beyond MARGIN_CAP x the threshold is
    ``unknown``; just within it, the margin decides."""
    t = 2.0
    lib = _library(["walk", "punch"], threshold=t)
    assert lib.decide(np.array([1.05 * B.MARGIN_CAP * t, 1e6])).name == UNKNOWN
    assert lib.decide(np.array([0.95 * B.MARGIN_CAP * t, 1e6])).name == "walk"
    assert decision_excess(0.95 * B.MARGIN_CAP * t, 1e6, t, 1.0) == pytest.approx(math.log(0.95))


def test_a_default_or_given_threshold_keeps_the_threshold_and_ratio_rule():
    """The margin is for calibrated thresholds: an uncalibrated library (the default
    threshold) and a given one (``--threshold``) name when d1 <= threshold and d1 / d2 <=
    ratio, whatever the margin."""
    t = 2.0
    for lib in (_library(["walk", "punch"], threshold=t, ratio=0.9, calibrated=False),
                _library(["walk", "punch"], threshold=t, ratio=0.9)):
        if lib.calibration["calibrated"]:
            lib.calibration["threshold_given"] = True
        assert not lib.calibrated_threshold
        assert lib.decide(np.array([1.2 * t, 10 * t])).name == UNKNOWN      # beyond t
        assert lib.decide(np.array([0.9 * t, 0.95 * t])).name == UNKNOWN    # ratio 0.95 > 0.9
        assert lib.decide(np.array([0.9 * t, 1.1 * t])).name == "walk"      # ratio 0.82
    cal = _library(["walk", "punch"], threshold=t, ratio=0.9)
    assert cal.calibrated_threshold
    assert cal.decide(np.array([1.2 * t, 10 * t])).name == "walk"           # the margin
    assert decision_excess(1.2 * t, 10 * t, t, 0.9, margin=False) == pytest.approx(math.log(1.2))


def _rows(seed: int, freq: float, n: int = 400, fr: float = 60.0) -> np.ndarray:
    """Feature rows of one joint swinging at ``freq`` Hz (unit quaternions, 4 dims)."""
    t = np.arange(n) / fr
    rng = np.random.default_rng(seed)
    a = 0.4 * np.sin(2 * np.pi * freq * t) + 0.01 * rng.standard_normal(n)
    return np.c_[np.sin(a / 2), np.zeros(n), np.zeros(n), np.cos(a / 2)]


def test_rtseg_learn_says_which_decision_a_library_names_by(tmp_path):
    """``rtseg learn --show``'s first line: a calibrated threshold is moved by the margin
    (and capped), a given one is the threshold and ratio rule."""
    from rtseg.commands.learn import describe
    from rtseg.library.builder import LibraryBuilder

    def build(threshold=None):
        b = LibraryBuilder("test", 4, 60.0)
        for seed, who in ((0, "ann"), (1, "bob")):
            for name, freq in (("slow", 0.5), ("fast", 2.0)):
                b.add(_rows(seed, freq), name, f"{who}-{name}", info={"person": who})
        return b.build(threshold=threshold)
    cal = build()
    assert cal.calibrated_threshold
    first = describe(cal, tmp_path / "c.json")[0]
    assert "moved by the margin" in first and f"at most {B.MARGIN_CAP:g} x" in first
    assert "(calibrated)" in first
    given = build(threshold=3.0)
    assert not given.calibrated_threshold
    other = describe(given, tmp_path / "g.json")[0]
    assert "unknown beyond distance 3.000 or ratio" in other and "(given)" in other
    assert "margin" not in other
