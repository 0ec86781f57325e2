"""The live session's intake: frames from the source, checked, recorded and appended to
the ring buffer in arrival order, by whichever way the source is read (see
``rtseg.live.loop``): polled by the loop (``Source.take_over``), taken from the queue of a
source whose own thread wakes the loop (``Source.wake_with``), or read by a reader thread
(``Source.read``); and the hand-back of an overloaded polled source to threads.

:class:`SessionInput` is a part of :class:`rtseg.live.session.LiveSession` (a base class; it
uses the session's ``source``, ``ring``, ``recorder``, ``stats``, ``monitor``, ``_warn``,
``_stop``/``_eof`` flags and the state ``_begin`` sets up).  Times are monotonic seconds.

Backpressure: a source that hands over frames as fast as they are read
(``Source.as_fast_as_read``: a file or ``sim://`` replay at ``speed=0``) is read only while
fewer than ``BACKPRESSURE_FRAMES`` frames wait to be processed; its reader thread then
waits for the processing (``SessionProcessing`` wakes it once half of them are done), so
the ring is never lapped and no frame is lost: the session processes every frame of the
take, in order, as offline.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import numpy as np

from rtseg.core.session_log import start_thread

log = logging.getLogger("rtseg.live.session")

#: frames dropped for overload after which a polled source is read in threads again
#: (``LiveSession._hand_back``): a sustained overload, not a stall of a few frames
HAND_BACK_DROPS = 64

#: most frames a source as fast as read (a replay at ``speed=0``) gets ahead of the
#: processing: its reader waits beyond that (at most half the ring), and is woken once
#: half of them are processed.  A few milliseconds of processing: the frames are stamped
#: (``recv_time``) shortly before they are processed
BACKPRESSURE_FRAMES = 64


class SessionInput:
    """Frame intake of a :class:`~rtseg.live.session.LiveSession`."""

    #: the reader waits for the processing (a source as fast as read; module docstring)
    _backpressure = False
    #: absolute index of the next frame the processing takes (kept with backpressure)
    _room_from = 0
    #: frames waiting at which the reader waits, and at which it is woken again
    _room_high = BACKPRESSURE_FRAMES
    _room_low = BACKPRESSURE_FRAMES // 2
    #: set by the processing when the waiting frames are down to ``_room_low``
    _room: threading.Event | None = None

    def _receive(self, frame: Any) -> None:
        """One frame from the source: checked, recorded (every frame received is), appended
        to the ring buffer in arrival order, counted.  A malformed frame is counted in
        ``bad_frames`` and logged, never raised."""
        ring = self.ring
        J = ring.valid_width
        try:
            q = np.asarray(frame.quats, dtype=np.float64).reshape(J, 4)
            v = np.asarray(frame.valid, dtype=bool).reshape(J)
            recv = float(frame.recv_time)
            seq = None if frame.seq is None else int(frame.seq)
            stime = None if frame.source_time is None else float(frame.source_time)
        except (TypeError, ValueError, AttributeError) as exc:
            self.stats.bad_frames += 1
            self._warn("badframe", "malformed frame dropped (%s)", exc)
            return
        if self.recorder is not None:
            with self._rec_lock:
                try:
                    self.recorder.record_frame(frame)
                except Exception as exc:
                    self.stats.record_errors += 1
                    self._warn("record", "recording a frame failed: %s", exc)
        ring.append(q, recv, stime, seq, v)
        if self._rate_check is not None and not self._rate_check.done:
            problem = self._rate_check.feed(recv, stime, seq)
            if problem is not None:
                log.warning("%s", problem)
                chk = self._rate_check
                if chk.on_source_clock and chk.mismatch:
                    self._measured_rate = round(float(chk.measured_hz), 1)
        if self._first_recv is None:
            self._first_recv = recv
        self.stats.frames_received += 1

    def _poll_source(self, now: float) -> None:
        """The loop's read of a polled source (``Source.poll``): what it decoded,
        received in order.  A driver error is counted (``source_errors``) and logged."""
        try:
            self.source.poll(now)
        except Exception as exc:  # a driver bug must not end the session
            self._source_failed(exc)
        self._take_frames()

    def _source_failed(self, exc: Exception) -> None:
        """A source's read raised: counted (``source_errors``) and logged, rate-limited."""
        self.stats.source_errors += 1
        self._warn("source", "source read failed (%s: %s); retrying", type(exc).__name__, exc)

    def _take_frames(self) -> None:
        """The frames a woken source's own thread queued (``Source.wake_with``),
        received in order."""
        got = self._got
        try:
            self.source.take(got)
        except Exception as exc:  # a driver bug must not end the session
            self._source_failed(exc)
        if got:
            for frame in got:
                self._receive(frame)
            got.clear()

    def _reader(self) -> None:
        """Reader thread of a source that must block (``Source.take_over`` False): frames
        received into the ring buffer, the loop woken for each batch."""
        src, ring, wake = self.source, self.ring, self._loop.waker.wake
        assert ring is not None
        try:
            while not self._stop.is_set():
                if self._backpressure and not self._wait_for_room():
                    return
                try:
                    frame = src.read(timeout=0.1)
                except EOFError:
                    self._eof.set()
                    wake()
                    return
                except Exception as exc:  # a driver bug or device error must not end the session
                    self._source_failed(exc)
                    self._stop.wait(0.05)
                    continue
                if frame is None:
                    continue
                self._receive(frame)
                wake()
        except BaseException as exc:  # pragma: no cover - defensive
            self._reader_error = exc
            log.exception("reader thread failed")
            wake()

    def _wait_for_room(self) -> bool:
        """Backpressure (module docstring): wait until fewer than ``_room_high`` frames
        wait to be processed; False if the session stops meanwhile."""
        ring, room = self.ring, self._room
        while ring.head - self._room_from >= self._room_high:
            room.clear()
            if ring.head - self._room_from < self._room_high:   # processed meanwhile
                break
            if self._stop.is_set():
                return False
            room.wait(0.05)
        return not self._stop.is_set()

    def _start_input(self, loop: Any) -> None:
        """Let the loop read the source (``Source.take_over``), or start a reader thread
        for a source that must block; attach the monitor."""
        if self.duration is not None:
            self._deadline = time.monotonic() + self.duration
        if self.monitor is not None:
            self._monitor_call(self.monitor.attach)
        taken = False
        try:
            taken = bool(self.source.take_over())
        except Exception as exc:  # a driver bug: read it in a thread instead
            self._warn("source", "the source cannot be polled (%s: %s); a reader thread "
                       "reads it", type(exc).__name__, exc)
        woken = False
        if not taken:
            try:
                woken = bool(self.source.wake_with(loop.waker.wake))
            except Exception as exc:  # a driver bug: read it in a thread instead
                self._warn("source", "the source cannot wake the loop (%s: %s); a reader "
                           "thread reads it", type(exc).__name__, exc)
        if taken:
            self._polled = True
            # frames its own thread decoded before the hand-over come first
            self._poll_source(time.monotonic())
            loop.add_polled(self)
        elif woken:
            self._woken = True
            self._take_frames()
            loop.add_woken(self)
        else:
            if getattr(self.source, "as_fast_as_read", False) is True:
                # a replay at speed 0: read as fast as processed, never ahead of it
                self._backpressure = True
                self._room = threading.Event()
                self._room_from = self._cursor.position
                self._room_high = max(1, min(BACKPRESSURE_FRAMES, self.ring.capacity // 2))
                self._room_low = self._room_high // 2
            self._reader_thread = start_thread(self._reader, name="rtseg-reader")

    def _hand_back(self) -> None:
        """Overloaded with a polled source (``HAND_BACK_DROPS`` frames dropped to keep
        up): reading goes back to threads for the rest of the session, the source's own
        and a reader thread that records and buffers each frame, so that frames are read
        and recorded while processing runs behind, and a device's small buffer (a pty
        holds 4 KB) is drained however long a batch takes or however little of the CPU
        this thread gets."""
        loop = self._loop
        loop.drop(self)
        self._polled = False
        try:
            ok = bool(self.source.give_back())
        except Exception as exc:  # a driver bug: keep polling
            ok = False
            self._warn("source", "the source cannot read in its thread (%s: %s)",
                       type(exc).__name__, exc)
        if not ok:
            self._polled = True
            loop.add_polled(self)
            return
        log.info("overloaded: the source is read in threads from now on (%d frames "
                 "dropped to keep up)", self.stats.overload_drops)
        self._reader_thread = start_thread(self._reader, name="rtseg-reader")



__all__ = ["BACKPRESSURE_FRAMES", "HAND_BACK_DROPS", "SessionInput"]
