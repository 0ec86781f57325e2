"""rtseg.evaluation.errors: each miss gets the first cause that holds, each false cut its
place, on hand-made cuts and profiles (take frames at 100 Hz, tolerance 0.5 s = 50 frames)."""

from __future__ import annotations

import pytest

from rtseg.evaluation.errors import FALSE_KINDS, MISS_CAUSES, attribute, tally_errors
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
