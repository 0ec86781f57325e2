"""rtseg.identity.names.SegmentNamer: which fed rows a segment is named from, and the
refusal of a library of other feature dims."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from rtseg.identity.names import SegmentNamer
from rtseg.library.behaviours import UNKNOWN


class _Recording:
    """A stand-in library that records the window it is asked to name."""

    def __init__(self, dims: int) -> None:
        self.dims = dims
        self.windows: list[np.ndarray] = []

    def name(self, W: np.ndarray, frame_rate: float, scale: float = 1.0):
        self.windows.append(W.copy())

        class _N:
            name, distance = "walk", 1.25
        return _N()


FR = 100.0


def _fed(namer: SegmentNamer, n: int) -> None:
    for i in range(n):
        namer.update(i, np.array([float(i), -float(i)]))


def _namer(**kw) -> tuple[SegmentNamer, _Recording]:
    lib = _Recording(2)
    nm = SegmentNamer(lib, FR, skip_s=0.5, max_window_s=3.0, min_window_s=1.0, **kw)
    assert nm.start(2)
    return nm, lib


def test_named_rows_skip_the_first_half_second_in_frame_order():
    nm, lib = _namer()
    _fed(nm, 1000)
    assert nm.name(600, 799) == ("walk", 1.25)
    W = lib.windows[-1]
    assert W[:, 0].tolist() == list(range(650, 800))      # boundary + 0.5 s .. decision
    assert np.array_equal(W[:, 1], -W[:, 0])


def test_short_segment_keeps_its_first_rows():
    nm, _ = _namer()
    _fed(nm, 1000)
    W = nm.rows(900, 979)                 # 0.3 s after the skip: less than min_window_s
    assert W[:, 0].tolist() == list(range(900, 980))


def test_window_is_capped_at_max_window_and_survives_the_ring_wrapping():
    nm, _ = _namer()
    _fed(nm, 5000)                        # the ring (3 s + 0.5 s + 1 s + block) wrapped many times
    W = nm.rows(4560, 4999)
    assert W[:, 0].tolist() == list(range(4610, 4910))   # 3 s from boundary + 0.5 s
    old = nm.rows(4400, 4999)             # the ring holds 4.6 s: older rows are gone
    assert old[:, 0].tolist() == list(range(4540, 4750))


def test_fewer_than_two_rows_is_unknown_without_asking_the_library():
    nm, lib = _namer()
    _fed(nm, 10)
    assert nm.name(9, 9) == (UNKNOWN, float("inf"))
    assert lib.windows == []


def test_library_of_other_dims_is_refused_with_a_warning(caplog):
    nm = SegmentNamer(_Recording(56), FR)
    with caplog.at_level(logging.WARNING, logger="rtseg.identity.names"):
        assert not nm.start(42)
    assert "56 feature dims" in caplog.text and "42" in caplog.text


def test_tracker_library_is_fixed_once_rows_flow():
    from rtseg.identity.tracker import IdentityTracker
    tr = IdentityTracker(FR, library=_Recording(2))
    assert tr.library is not None and tr.namer is not None
    tr.update(0, np.zeros(2))
    with pytest.raises(RuntimeError):
        tr.library = None


class _OnePerson:
    """A stand-in library calibrated on one person (threshold 2.0) that records the
    threshold factor each naming is given and answers with the next distance."""

    metric = "model"

    def __init__(self, one_person: bool, distances: list[float]) -> None:
        self.dims = 2
        self.one_person_calibration = one_person
        self.scales: list[float] = []
        self._d = list(distances)

    def rule_threshold(self, posture: bool) -> float:
        return 2.0

    def name(self, W, frame_rate, P=None, scale=1.0):
        self.scales.append(scale)
        d = self._d.pop(0)

        class _N:
            name, distance = ("walk" if d <= 2.0 * scale else UNKNOWN), d
        return _N()


@pytest.mark.parametrize("one_person", [True, False])
def test_the_performers_scale_is_the_median_distance_over_the_threshold(one_person, caplog):
    """A library calibrated on one person: each naming's threshold is multiplied by the
    median, over the segments decided so far, of their distance over the threshold, when
    above 1; a segment without a name (inf) does not count.  Any other library: 1."""
    lib = _OnePerson(one_person, [4.0, 6.0, math.inf, 5.0, 1.0])   # ratios 2, 3, -, 2.5, 0.5
    nm = SegmentNamer(lib, FR)
    assert nm.start(2)
    _fed(nm, 1000)
    with caplog.at_level(logging.INFO, logger="rtseg.identity.names"):
        for _ in range(5):
            nm.decided(nm.name(600, 799)[1])
    told = [r for r in caplog.records if "performer's segments lie" in r.getMessage()]
    assert len(told) == (1 if one_person else 0)      # once, when the scale first applies
    if one_person:
        # before any decision 1; then median(2) = 2, median(2, 3) = 2.5, still 2.5 (inf
        # left out), median(2, 3, 2.5) = 2.5
        assert lib.scales == [1.0, 2.0, 2.5, 2.5, 2.5]
        assert nm.scale == 2.25                       # median(2, 3, 2.5, 0.5)
    else:
        assert lib.scales == [1.0] * 5 and nm.scale == 1.0


def test_a_performer_nearer_than_the_threshold_keeps_it():
    """Ratios below 1 never lower the threshold (the scale is at least 1)."""
    lib = _OnePerson(True, [0.5, 0.5, 0.5])
    nm = SegmentNamer(lib, FR)
    assert nm.start(2)
    _fed(nm, 1000)
    for _ in range(3):
        nm.decided(nm.name(600, 799)[1])
    assert lib.scales == [1.0, 1.0, 1.0] and nm.scale == 1.0
