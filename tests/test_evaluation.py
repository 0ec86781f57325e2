"""Scoring: one-to-one maximum matching of cuts to transition ranges, pooled counts."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rtseg.detectors.base import Cut
from rtseg.evaluation.scoring import Score, match, max_matching_size, pooled, score
from rtseg.labels.takes import Transition


def T(lo: int, hi: int, mid: int | None = None) -> Transition:
    return Transition(lo, hi, (lo + hi) // 2 if mid is None else mid)


def test_two_cuts_in_one_range_one_tp_one_fp():
    s = score([100, 120], [T(90, 130)])
    assert (s.tp, s.fp, s.fn) == (1, 1, 0)
    assert s.precision == 0.5 and s.recall == 1.0
    assert s.f1 == pytest.approx(2 * 0.5 / 1.5)
    # the cut nearer the labelled middle is the one matched
    assert score([100, 111], [T(90, 130, 110)]).matches == ((111, 0),)


def test_one_cut_in_two_overlapping_ranges_one_tp():
    s = score([100], [T(50, 150), T(80, 200)])
    assert (s.tp, s.fp, s.fn) == (1, 0, 1)
    assert s.precision == 1.0 and s.recall == 0.5


def test_matching_is_maximum_not_greedy():
    # Nearest-first greedy gives cut 105 to the second range (mid 104), leaving the first
    # range (0..106, mid 0) with only 105 -> greedy finds 1 match; the maximum is 2.
    trans = [T(0, 106, 0), T(100, 200, 104)]
    s = score([105, 150], trans)
    assert s.tp == 2 and s.fp == 0
    assert sorted(j for _, j in s.matches) == [0, 1]


def test_no_cuts_and_no_transitions_conventions():
    s = score([], [T(0, 10)])
    assert (s.tp, s.fp, s.fn, s.precision, s.recall, s.f1) == (0, 0, 1, 1.0, 0.0, 0.0)
    s = score([5, 6], [])
    assert (s.tp, s.fp, s.fn, s.precision, s.recall, s.f1) == (0, 2, 0, 0.0, 1.0, 0.0)
    s = score([], [])
    assert (s.precision, s.recall, s.f1) == (1.0, 1.0, 1.0)


def test_range_bounds_inclusive_and_cut_objects():
    trans = [T(10, 20)]
    assert score([10], trans).tp == 1 and score([20], trans).tp == 1
    assert score([9], trans).tp == 0 and score([21], trans).tp == 0
    assert score([Cut(frame=15, method="pca")], trans).tp == 1


def test_pooled_sums_counts_then_divides():
    a = score([10, 50, 90], [T(0, 20), T(40, 60)])   # tp 2 of 3 cuts, 2 transitions
    b = score([500], [T(0, 20), T(40, 60), T(80, 99)])  # tp 0 of 1 cut, 3 transitions
    p = pooled([a, b])
    assert (p.tp, p.cuts, p.transitions) == (2, 4, 5)
    assert p.precision == 0.5 and p.recall == 0.4
    # not the mean of per-take ratios
    assert p.precision != (a.precision + b.precision) / 2
    assert pooled([]).f1 == 1.0


def test_score_from_counts_rejects_inconsistent():
    with pytest.raises(ValueError):
        Score.from_counts(3, 2, 5)


def brute_force(cuts, trans):
    best = 0
    for k in range(min(len(cuts), len(trans)), 0, -1):
        for cs in itertools.combinations(range(len(cuts)), k):
            for ts in itertools.permutations(range(len(trans)), k):
                if all(trans[t].contains(cuts[c]) for c, t in zip(cs, ts)):
                    return k
    return best


intervals = st.tuples(st.integers(0, 60), st.integers(0, 25)).map(lambda p: T(p[0], p[0] + p[1]))


@settings(max_examples=150, deadline=None)
@given(cuts=st.lists(st.integers(0, 90), max_size=5), trans=st.lists(intervals, max_size=4))
def test_matching_size_is_the_maximum(cuts, trans):
    pairs = match(cuts, trans)
    assert len({c for c, _ in pairs}) == len(pairs) == len({t for _, t in pairs})
    assert all(trans[t].contains(cuts[c]) for c, t in pairs)
    n = brute_force(cuts, trans)
    assert len(pairs) == n == max_matching_size(cuts, trans)
    s = score(cuts, trans)
    assert s.tp + s.fp == len(cuts) and s.tp + s.fn == len(trans)
    assert 0.0 <= s.f1 <= 1.0
