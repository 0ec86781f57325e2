"""Preallocated ring buffer of live frames with copy-free contiguous windows.

What one slot holds
-------------------
- ``data``: (D,) float64 — the frame's payload: flattened quaternions (joints × 4,
  scalar-last x, y, z, w) for the raw input ring, or pose features for a feature ring.
- ``recv_time``: float64 seconds, ``time.monotonic()`` when the frame was complete at the
  receiver (``Frame.recv_time``).
- ``source_time``: float64 seconds on the device's clock, NaN when the source has none.
- ``seq``: int64 sequence number of the source, -1 when the source has none.
- ``valid``: (V,) bool — per-joint valid flags (V = joints; V may be 0).

Every slot is addressed by its **absolute index**: 0 for the first frame ever appended,
counting up without wrapping (int64 never wraps in practice).  ``head`` is the absolute
index the next append will get; the buffer holds absolute indices
``[max(0, head - capacity), head)``.

Layout: mirrored double write
-----------------------------
Each array has ``2 × capacity`` rows.  Appending absolute index ``i`` writes the same
values to rows ``i % capacity`` and ``i % capacity + capacity``.  Then, with
``k = head % capacity``, rows ``[k, k + capacity)`` always hold the last ``capacity``
frames in order, oldest first.  Any window of the most recent ``n ≤ capacity`` frames is
therefore the contiguous slice ``[k + capacity - n, k + capacity)`` of each array: a plain
numpy view, no copy, no concatenation, usable directly by vectorised code.  The price is
two row writes per append (still O(1)) and twice the memory.

Policy when the consumer falls behind
-------------------------------------
The producer never blocks and the buffer never grows.  When it is full, an append
overwrites the oldest slot and ``overwritten`` counts it.  Consumers hold absolute indices
(``Cursor``): a cursor whose position has fallen below ``oldest`` has lost frames; ``read``
skips it forward to ``oldest``, adds the skipped count to ``Cursor.overruns`` and reports
it in ``Window.lost`` so the consumer can treat it as a gap in the input (the live loop
restarts its detectors and counts the frames as dropped).

A consumer that would rather skip old frames than fall behind (the live loop under
overload) calls ``Cursor.drop_older(t)``: the waiting frames received before ``t`` are
skipped, oldest first, and counted by the caller.

Thread safety: one producer thread and any number of consumer threads.  ``append`` and
``Cursor.read`` take a short lock; windows returned to a consumer are views, so a consumer
must finish with a window before the producer can lap it — i.e. read at most
``capacity - margin`` frames at a time (``Cursor.read(max_frames)``), which the live loop
does (its batches are far smaller than the capacity).  ``wait(index, timeout)`` lets a
consumer sleep until frame ``index`` exists.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Window:
    """A run of consecutive frames, as views into the ring (valid until the ring laps it).

    start: absolute index of the first row; lost: frames the reader missed just before
    ``start`` because the producer overwrote them (0 normally).
    """
    start: int
    data: np.ndarray
    recv_time: np.ndarray
    source_time: np.ndarray
    seq: np.ndarray
    valid: np.ndarray
    lost: int = 0

    def __len__(self) -> int:
        return int(self.data.shape[0])

    @property
    def stop(self) -> int:
        """Absolute index one past the last row."""
        return self.start + len(self)


class RingBuffer:
    """Fixed-capacity frame store; see the module docstring for layout and overrun policy.

    capacity: frames kept; width: D, floats per frame; valid_width: V, flags per frame.
    """

    def __init__(self, capacity: int, width: int, valid_width: int = 0) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        if width < 0 or valid_width < 0:
            raise ValueError("width and valid_width must be non-negative")
        self.capacity = int(capacity)
        self.width = int(width)
        self.valid_width = int(valid_width)
        rows = 2 * self.capacity
        self._data = np.zeros((rows, self.width), dtype=np.float64)
        self._recv = np.zeros(rows, dtype=np.float64)
        self._src = np.full(rows, np.nan, dtype=np.float64)
        self._seq = np.full(rows, -1, dtype=np.int64)
        self._valid = np.zeros((rows, self.valid_width), dtype=bool)
        self._head = 0
        self.overwritten = 0
        self._cond = threading.Condition(threading.Lock())

    # ------------------------------------------------------------------ producer side
    def append(self, data: np.ndarray, recv_time: float, source_time: float | None = None,
               seq: int | None = None, valid: np.ndarray | None = None) -> int:
        """Store one frame (O(1), two row writes); return its absolute index.

        ``data`` must have ``width`` elements (any shape, read in C order); ``valid`` must
        have ``valid_width`` elements, or be None for all-valid.
        """
        row = data if type(data) is np.ndarray and data.dtype == np.float64 \
            else np.asarray(data, dtype=np.float64)
        if row.size != self.width:
            raise ValueError(f"frame has {row.size} values, ring width is {self.width}")
        if row.ndim != 1:
            row = row.reshape(-1)
        with self._cond:
            i = self._head
            a = i % self.capacity
            b = a + self.capacity
            self._data[a] = row
            self._data[b] = row
            self._recv[a] = self._recv[b] = recv_time
            st = np.nan if source_time is None else source_time
            self._src[a] = self._src[b] = st
            sq = -1 if seq is None else int(seq)
            self._seq[a] = self._seq[b] = sq
            if self.valid_width:
                if valid is None:
                    self._valid[a] = True
                    self._valid[b] = True
                else:
                    v = valid if type(valid) is np.ndarray and valid.ndim == 1 \
                        else np.asarray(valid, dtype=bool).reshape(-1)
                    self._valid[a] = v
                    self._valid[b] = v
            if i >= self.capacity:
                self.overwritten += 1
            self._head = i + 1
            self._cond.notify_all()
        return i

    # ------------------------------------------------------------------ indices
    @property
    def head(self) -> int:
        """Absolute index of the next frame to be appended (= frames appended so far)."""
        return self._head

    @property
    def oldest(self) -> int:
        """Absolute index of the oldest frame still held."""
        return max(0, self._head - self.capacity)

    def __len__(self) -> int:
        return min(self._head, self.capacity)

    # ------------------------------------------------------------------ reading
    def _slice(self, start: int, stop: int, lost: int = 0) -> Window:
        # Rows of absolute [start, stop) inside the mirrored block ending at head.
        k = self._head % self.capacity
        end_row = k + self.capacity
        a = end_row - (self._head - start)
        b = end_row - (self._head - stop)
        return Window(start, self._data[a:b], self._recv[a:b], self._src[a:b],
                      self._seq[a:b], self._valid[a:b], lost)

    def window(self, n: int) -> Window:
        """The most recent ``min(n, len(self))`` frames, oldest first, as contiguous views."""
        with self._cond:
            n = max(0, min(int(n), len(self)))
            return self._slice(self._head - n, self._head)

    def get(self, start: int, stop: int) -> Window:
        """Frames with absolute indices [start, stop) as views; IndexError if not all held."""
        with self._cond:
            if start < self.oldest or stop > self._head or start > stop:
                raise IndexError(
                    f"frames [{start}, {stop}) not held (ring holds [{self.oldest}, {self._head}))")
            return self._slice(start, stop)

    def recv_time_at(self, index: int) -> float | None:
        """Receive time of absolute frame ``index``, or None if it is no longer held."""
        with self._cond:
            if self.oldest <= index < self._head:
                return float(self._recv[index % self.capacity])
            return None

    def source_time_at(self, index: int) -> float | None:
        """Source-clock time of absolute frame ``index``; None if it is no longer held or
        the source gave none."""
        with self._cond:
            if self.oldest <= index < self._head:
                v = float(self._src[index % self.capacity])
                return v if np.isfinite(v) else None
            return None

    def wait(self, index: int, timeout: float | None) -> bool:
        """Block until frame ``index`` exists (head > index) or ``timeout`` passes."""
        with self._cond:
            return self._cond.wait_for(lambda: self._head > index, timeout)

    def notify(self) -> None:
        """Wake every waiter (used to interrupt consumers on shutdown)."""
        with self._cond:
            self._cond.notify_all()

    def cursor(self, start: int | None = None) -> "Cursor":
        """A reader positioned at absolute index ``start`` (default: the next frame)."""
        return Cursor(self, self._head if start is None else start)


class Cursor:
    """A consumer's position in a ``RingBuffer`` (absolute index of its next frame).

    ``overruns`` counts frames this reader lost because the producer overwrote them first.
    """

    def __init__(self, ring: RingBuffer, position: int) -> None:
        self.ring = ring
        self.position = int(position)
        self.overruns = 0
        self._lapped = 0      # overwritten frames a drop_older() stepped over, for read()

    @property
    def backlog(self) -> int:
        """Frames appended but not yet read by this cursor (may exceed capacity if lapped)."""
        return self.ring.head - self.position

    def drop_older(self, t: float, limit: int | None = None) -> int:
        """Skip the waiting frames received before monotonic time ``t``, oldest first (at
        most ``limit``); return how many were skipped.  Receive times are taken as
        non-decreasing (a binary search).  Frames the producer already overwrote are left
        for :meth:`read` to report in ``Window.lost``."""
        ring = self.ring
        with ring._cond:
            start = max(self.position, ring.oldest)
            if start >= ring._head or ring._recv[start % ring.capacity] >= t:
                return 0                   # nothing waiting, or nothing as old as t
            recv = ring._slice(start, ring._head).recv_time
            k = int(np.searchsorted(recv, t, side="left"))
            if limit is not None:
                k = min(k, max(0, int(limit)))
            if k == 0:
                return 0
            if self.position < start:        # lapped as well: read() would report these
                self._lapped += start - self.position
            self.position = start + k
            return k

    def read(self, max_frames: int | None = None) -> Window:
        """Frames from the cursor's position up to head (at most ``max_frames``), advancing.

        If the producer has lapped the cursor, it jumps to ``ring.oldest`` and the skipped
        count is in ``Window.lost`` (and added to ``overruns``).
        """
        ring = self.ring
        with ring._cond:
            lost, self._lapped = self._lapped, 0
            self.overruns += lost
            oldest = ring.oldest
            if self.position < oldest:
                lost += oldest - self.position
                self.overruns += oldest - self.position
                self.position = oldest
            stop = ring._head
            if max_frames is not None:
                stop = min(stop, self.position + max(0, int(max_frames)))
            w = ring._slice(self.position, stop, lost)
            self.position = stop
            return w
