"""rtseg.evaluation.errors: each miss gets the first cause that holds, each false cut its
place, on hand-made cuts and profiles (take frames at 100 Hz, tolerance 0.5 s = 50 frames)."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.evaluation.errors import (FALSE_KINDS, MISS_CAUSES, SPANS, attribute,
                                     span_resemblance, tally_errors)
from rtseg.labels.types import Transition

FR = 100.0
T = [Transition(1000, 1100, 1050, "walk", "jump"),
     Transition(2000, 2100, 2050, "jump", "kick"),
     Transition(3000, 3100, 3050, "kick", "walk")]
FLAT_HIGH = [(f, 3.0) for f in range(0, 4000, 10)]      # a profile over threshold everywhere


def test_a_matched_transition_is_no_miss_and_its_cut_no_false_cut():
    e = attribute([1040, 2060, 3020], T, FR, threshold=1.0, contrast=FLAT_HIGH)
    assert e.misses == () and e.false_cuts == ()


def test_each_cause_in_its_order():
    # T[0]: the gate dropped a cut in range and the floor refused one: the gate comes first
    # T[1]: the floor refused one, and the profile stays under the threshold there: the
    #       floor comes first
    # T[2]: the profile is high, a free cut lies 1.2 s after the widened range's end (3150)
    profile = [(f, 0.5 if 1900 <= f <= 2200 else 3.0) for f in range(0, 4000, 10)]
    e = attribute([3270], T, FR, threshold=1.0, contrast=profile, gate_drops=[1010],
                  refusals=[1020, 2040])
    assert [m.cause for m in e.misses] == ["gate dropped", "floor refused", "cut outside"]
    assert e.misses[2].offset_s == pytest.approx(1.2)
    assert (e.misses[0].before, e.misses[0].after) == ("walk", "jump")
    # the cut that lay off T[2] is also a false cut, 1.7 s from its range: inside a segment
    assert [(f.frame, f.kind, f.behaviour) for f in e.false_cuts] == [(3270, "inside", "walk")]
    assert e.false_cuts[0].distance_s == pytest.approx(1.7)


def test_below_threshold_and_no_maximum_sent():
    low = [(f, 0.5 if 1900 <= f <= 2200 else 3.0) for f in range(0, 4000, 10)]
    e = attribute([1050], T, FR, threshold=1.0, contrast=low)
    assert [m.cause for m in e.misses] == ["below threshold", "no maximum sent"]
    # a free cut 1 s before T[2]'s widened range: a negative offset; T[1] lies 7 s from it
    e = attribute([1050, 2850], T, FR, threshold=1.0, contrast=FLAT_HIGH)
    assert [m.cause for m in e.misses] == ["no maximum sent", "cut outside"]
    assert e.misses[1].offset_s == pytest.approx(-1.0)
    # beyond outside_s (2.5 s before it) it explains nothing
    e = attribute([1050, 2700], T, FR, threshold=1.0, contrast=FLAT_HIGH, outside_s=2.0)
    assert [m.cause for m in e.misses][1] == "no maximum sent"


def test_a_matched_cut_does_not_explain_another_miss():
    # the cut at 1040 matches the first; it lies within 2 s of the second's widened range,
    # but it is taken, so the second's miss is not "cut outside"
    t = [Transition(1000, 1100, 1050, "a", "b"), Transition(1240, 1300, 1270, "b", "c")]
    e = attribute([1040], t, FR, threshold=1.0, contrast=FLAT_HIGH)
    assert [m.cause for m in e.misses] == ["no maximum sent"]


def test_false_cuts_near_or_inside_with_the_behaviour_labelled_there():
    e = attribute([1040, 1250, 2600, 2060, 3020], T, FR, threshold=1.0, contrast=FLAT_HIGH)
    assert [(f.frame, f.kind, f.behaviour) for f in e.false_cuts] == [
        (1250, "near", "jump"), (2600, "inside", "kick")]


def test_without_a_profile_misses_are_placed_or_not_sent():
    e = attribute([3300], T, FR)
    assert {m.cause for m in e.misses} <= {"cut outside", "no maximum sent"}


def test_tally_counts_every_cause_and_kind():
    a = attribute([3270], T, FR, threshold=1.0, contrast=FLAT_HIGH, gate_drops=[1010])
    b = attribute([1040, 2600], T, FR, threshold=1.0, contrast=FLAT_HIGH)
    t = tally_errors([a, b])
    assert list(t["miss_causes"]) == list(MISS_CAUSES)
    assert list(t["false_kinds"]) == list(FALSE_KINDS)
    assert t["misses"] == 3 + 2 == sum(t["miss_causes"].values())
    assert t["miss_causes"]["gate dropped"] == 1
    assert t["false_cuts"] == 2 and t["false_inside"] == {"walk": 1, "kick": 1}
    assert t["missed_pairs"]["jump -> kick"] == 2
    assert a.as_dict()["misses"][0]["cause"] == "gate dropped"


def test_bad_frame_rate_is_an_error():
    with pytest.raises(ValueError, match="frame_rate"):
        attribute([], T, 0.0)


def _two_motions(change: int, n: int = 4000, dims: int = 6, seed: int = 0) -> np.ndarray:
    """Rows of one random motion before frame ``change`` and of another, on other
    directions and ten times larger, from it on."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, dims)) * 0.1
    X[:change, :3] += rng.normal(size=(change, 3))
    X[change:, 3:] += 10 * rng.normal(size=(n - change, 3))
    return X


def test_a_cut_outside_says_what_the_span_to_the_range_moves_like():
    """The motion changes at frame 850, before the labelled range (1000-1100): a cut there
    is 'other' (the span to the range already moves like the next behaviour); with the
    motion changing at 1050, inside the range, a cut at 850 lies inside the labelled
    behaviour: 'labelled'.  A cut after the range is judged from the other side."""
    t = [T[0]]
    idx = np.arange(4000) + 7            # the take frame of each row (rows start later)
    early = span_resemblance(_two_motions(850 - 7), idx, FR)
    e = attribute([850], t, FR, threshold=1.0, contrast=FLAT_HIGH, span_like=early)
    assert [(m.cause, m.span) for m in e.misses] == [("cut outside", "other")]
    assert e.misses[0].offset_s == pytest.approx(-1.0)
    on_time = span_resemblance(_two_motions(1050 - 7), idx, FR)
    e = attribute([850], t, FR, threshold=1.0, contrast=FLAT_HIGH, span_like=on_time)
    assert e.misses[0].span == "labelled"
    late = span_resemblance(_two_motions(1250 - 7), idx, FR)      # cut at 1250, motion too
    assert attribute([1250], t, FR, threshold=1.0, contrast=FLAT_HIGH,
                     span_like=late).misses[0].span == "other"
    assert attribute([1250], t, FR, threshold=1.0, contrast=FLAT_HIGH,
                     span_like=on_time).misses[0].span == "labelled"
    counts = tally_errors([e])["outside_span"]
    assert list(counts) == list(SPANS) and counts == {"labelled": 1, "other": 0}
    # a span under 0.25 s is not judged; without span_like nothing is
    assert early(1000 - 10, 1000, 1100) is None
    assert attribute([850], t, FR, threshold=1.0, contrast=FLAT_HIGH).misses[0].span is None
