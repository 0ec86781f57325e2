"""Ring buffer: order, copy-free contiguous windows, overrun detection by absolute index."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rtseg.core.ringbuffer import RingBuffer


def fill(ring: RingBuffer, n: int, start: int = 0) -> None:
    for i in range(start, start + n):
        ring.append(np.full(ring.width, float(i)), recv_time=i * 0.01, source_time=i * 0.5,
                    seq=i, valid=np.array([i % 2 == 0, True]))


def test_window_is_ordered_view_after_wrap():
    ring = RingBuffer(8, 3, valid_width=2)
    fill(ring, 21)
    w = ring.window(5)
    assert w.start == 16 and len(w) == 5
    np.testing.assert_array_equal(w.data[:, 0], [16, 17, 18, 19, 20])
    np.testing.assert_array_equal(w.seq, [16, 17, 18, 19, 20])
    np.testing.assert_allclose(w.recv_time, np.arange(16, 21) * 0.01)
    np.testing.assert_allclose(w.source_time, np.arange(16, 21) * 0.5)
    np.testing.assert_array_equal(w.valid[:, 0], [True, False, True, False, True])
    # A view into the ring's storage, contiguous, not a copy.
    assert w.data.base is not None and np.shares_memory(w.data, ring._data)
    assert w.data.flags["C_CONTIGUOUS"]
    full = ring.window(100)
    assert len(full) == 8 and full.start == 13
    np.testing.assert_array_equal(full.data[:, 1], np.arange(13, 21))


def test_window_of_partly_filled_ring_and_empty():
    ring = RingBuffer(10, 2)
    assert len(ring.window(4)) == 0
    fill(ring, 3)
    w = ring.window(4)
    np.testing.assert_array_equal(w.data[:, 0], [0, 1, 2])
    assert ring.oldest == 0 and ring.head == 3


def test_views_stay_valid_until_lapped():
    ring = RingBuffer(6, 1)
    fill(ring, 4)
    w = ring.window(3)                      # frames 1, 2, 3
    fill(ring, 3, start=4)                  # 4, 5, 6: frame 0 overwritten, 1..3 still held
    np.testing.assert_array_equal(w.data[:, 0], [1, 2, 3])


def test_get_absolute_range_and_refusal():
    ring = RingBuffer(4, 1)
    fill(ring, 10)
    np.testing.assert_array_equal(ring.get(7, 10).data[:, 0], [7, 8, 9])
    with pytest.raises(IndexError):
        ring.get(5, 8)                      # 5 was overwritten
    with pytest.raises(IndexError):
        ring.get(9, 11)                     # 10 does not exist yet
    assert ring.recv_time_at(9) == pytest.approx(0.09)
    assert ring.recv_time_at(2) is None


def test_cursor_reads_everything_then_detects_overrun():
    ring = RingBuffer(5, 1)
    cur = ring.cursor()
    fill(ring, 3)
    w = cur.read()
    assert (w.start, len(w), w.lost) == (0, 3, 0)
    fill(ring, 9, start=3)                  # producer laps the reader: head 12, oldest 7
    assert ring.overwritten == 7
    assert cur.backlog == 9
    w = cur.read(max_frames=2)
    assert w.lost == 4 and w.start == 7 and cur.overruns == 4
    np.testing.assert_array_equal(w.data[:, 0], [7, 8])
    w = cur.read()
    assert w.lost == 0
    np.testing.assert_array_equal(w.data[:, 0], [9, 10, 11])
    assert cur.backlog == 0


def test_append_refuses_wrong_width():
    ring = RingBuffer(4, 3)
    with pytest.raises(ValueError, match="3"):
        ring.append(np.zeros(2), 0.0)
    with pytest.raises(ValueError):
        RingBuffer(0, 3)


def test_wait_wakes_on_append_from_other_thread():
    ring = RingBuffer(16, 1)
    assert not ring.wait(0, timeout=0.01)
    t = threading.Timer(0.05, lambda: fill(ring, 1))
    t.start()
    try:
        assert ring.wait(0, timeout=5.0)
    finally:
        t.join()


@settings(max_examples=60, deadline=None)
@given(capacity=st.integers(1, 12), n=st.integers(0, 60), k=st.integers(0, 20))
def test_window_matches_reference(capacity, n, k):
    ring = RingBuffer(capacity, 2)
    fill(ring, n)
    w = ring.window(k)
    expect = np.arange(n)[max(0, n - min(k, capacity)):]
    np.testing.assert_array_equal(w.data[:, 0], expect)
    assert w.start == (expect[0] if len(expect) else n)
    assert ring.overwritten == max(0, n - capacity)


def test_drop_older_skips_the_oldest_waiting_frames():
    ring = RingBuffer(8, 2)
    for i in range(6):
        ring.append(np.full(2, float(i)), recv_time=10.0 + i)
    cur = ring.cursor(0)
    assert cur.drop_older(9.0) == 0                    # none older
    assert cur.drop_older(12.5) == 3                   # frames 0, 1, 2 (received 10, 11, 12)
    assert cur.drop_older(20.0, limit=1) == 1          # at most limit, oldest first
    w = cur.read()
    assert (w.start, len(w), w.lost) == (4, 2, 0)
    assert cur.drop_older(100.0) == 0                  # nothing waiting
    # lapped and dropping: the overwritten frames are still reported lost by read()
    for i in range(6, 20):
        ring.append(np.full(2, float(i)), recv_time=10.0 + i)
    assert ring.oldest == 12 and cur.position == 6
    assert cur.drop_older(24.5) == 3                   # 12, 13, 14 of those held
    w = cur.read()
    assert (w.start, w.lost) == (15, 6) and cur.overruns == 6
    assert w.data[0, 0] == 15.0
