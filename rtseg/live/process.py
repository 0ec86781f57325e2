"""The live session's processing step: frames taken from the ring buffer, in order, through
the ``Pipeline``, the oldest dropped under overload (see "Keeping up" in ``rtseg.live.session``).

:class:`SessionProcessing` is a part of :class:`rtseg.live.session.LiveSession` (a base class; it
uses the session's ``pipeline``, ``ring``, ``stats``, ``_emit``, ``_warn``, the event
builders of ``rtseg.live.emitter`` and the dropout tracking of ``rtseg.live.health``, and
the state ``run`` sets up: ``_max_lag`` (s), ``_thin`` (frames), ``_pending_lost``,
``_frame_cost`` (s); and from ``rtseg.live.intake`` the backpressure of a source as fast as
read, ``_backpressure``, ``_room_from``, ``_room_low``, ``_room``: each frame taken
moves ``_room_from`` on and wakes the waiting reader once few frames are left).
Times are monotonic seconds; latencies milliseconds.
"""

from __future__ import annotations

import time

import numpy as np

#: the detectors work ahead before a frame that may send only when it is not due within
#: this long, s (``SessionProcessing._may_work_ahead``; a piece takes at most 0.3 ms)
AHEAD_CLEAR_S = 0.004


class SessionProcessing:
    """Frame processing of a :class:`~rtseg.live.session.LiveSession`."""

    def _overload_drop(self, recv: np.ndarray, i: int, now: float, pending: int,
                       waiting: int) -> int:
        """How many waiting frames, from row ``i`` of the window's receive times ``recv``
        on, to drop before processing the next one (``now``: monotonic s; ``pending``:
        frames already missing before row ``i``; ``waiting``: frames waiting from row
        ``i`` on, in the window and after it).

        Every frame older than ``buffer.max_lag_seconds`` (L) goes.  Frames older than L/2
        go too, at most ``gaps.max_frames`` before each frame processed (a gap the
        detectors go on across), when the loop is overloaded: processing all that is
        waiting, at the measured cost per frame, would take the oldest past L.  A stall
        at a normal rate (a few frames waiting, quickly worked off) drops nothing."""
        hard = self._max_lag
        old_hard = int(np.searchsorted(recv[i:], now - hard, side="left"))
        soft = 0
        if now - float(recv[i]) + waiting * self._frame_cost > hard:
            old_soft = int(np.searchsorted(recv[i:], now - 0.5 * hard, side="left"))
            soft = min(old_soft, max(0, self._thin - pending))
        return max(old_hard, soft)

    def _process_window(self, w, now: float, budget: float | None = None) -> None:
        """Process the frames of window ``w`` in order (``now``: monotonic s when it was
        read), dropping the oldest under overload (``_overload_drop``).  ``budget`` (s):
        stop after that long, the frames left waiting for the session's next turn (the
        loop takes its sessions in turn, so one session's burst of work does not hold
        the others' frames back)."""
        pipe = self.pipeline
        st = self.stats
        J = self.ring.valid_width
        if w.lost:
            st.overruns += w.lost
            self._warn("overrun", "processing fell behind: %d frames overwritten before use "
                       "(treated as a gap)", w.lost)
        pending = self._pending_lost + w.lost     # frames missing before the next processed
        quiet_left = 0                            # next frames promised quiet (below)
        open_lat = st.open_latency_ms
        recv_all = w.recv_time
        n = len(w)
        i = 0
        # between frames, the loop reads the polled sources (rtseg.live.loop: at most
        # once a millisecond), so that frames arriving meanwhile are stamped and waiting
        pump = self._loop.pump if self._loop is not None else None
        end_by = None if budget is None else now + budget
        while i < n:
            if self._max_lag > 0 and now - float(recv_all[i]) > 0.5 * self._max_lag:
                waiting = self.ring.head - (w.start + i)
                drop = min(n - i, self._overload_drop(recv_all, i, now, pending, waiting))
                if drop:
                    st.overload_drops += drop
                    pending += drop
                    i += drop
                    quiet_left = 0                # the promise was for the frames dropped
                    self._warn("overload", "overloaded: frames dropped, oldest first, so "
                               "none waits over %.0f ms (%d so far)", self._max_lag * 1000,
                               st.overload_drops)
                    continue
            index = w.start + i
            recv = float(recv_all[i])
            seq = int(w.seq[i])
            stime = float(w.source_time[i])
            valid = w.valid[i]
            lost, pending = pending, 0
            i += 1
            if self._backpressure:        # a replay at speed 0: its reader may go on
                self._room_from = index + 1
                if not self._room.is_set() and self.ring.head - index <= self._room_low + 1:
                    self._room.set()
            src = stime if stime == stime else None
            # could this frame send?  Asked again once the last promise is used up, so a
            # frame counts as one that could send only when the pipeline, just before it,
            # did not promise it quiet (a frame after missing ones feeds the detectors
            # filled rows too, more than the promise counts: it could send)
            if lost:
                quiet_left = 0
            elif quiet_left <= 0:
                quiet_left = pipe.quiet_frames()
            could_send = quiet_left <= 0
            quiet_left -= 1
            t_frame = self._clock_frame(index, recv, src)      # session seconds
            try:
                # with backpressure the receive clock measures the processing, not the
                # source: its steps are no silence (a restart on them would cut elsewhere
                # than offline, by the machine's load)
                cuts = pipe.process(index, w.data[index - w.start].reshape(J, 4), valid,
                                    None if seq < 0 else seq,
                                    None if self._backpressure else recv, lost, src,
                                    identify=False)
            except Exception as exc:  # never let one frame end the session
                st.bad_frames += 1
                self._warn("process", "frame %d could not be processed (%s: %s); dropped",
                           index, type(exc).__name__, exc)
                continue
            st.frames_processed += 1
            self._track_dropouts(valid, t_frame)
            for pc in cuts:
                ev = self._emit(self._cut_event(pc, recv, index, stime))
                st.cuts += 1
                st.wire_cuts += int(ev.wire)
                st.cuts_by_method[ev.method] = st.cuts_by_method.get(ev.method, 0) + 1
                st.last_cut = ev
                st.cut_latency_ms.append((time.monotonic() - recv) * 1000.0)
            if pipe.identity is not None:
                # after the cuts went out: a cue does not wait for the identity's fits
                pipe.identify_pending()
                for d in pipe.identity.drain():
                    self._emit(self._behaviour_event(d))
            done = time.monotonic()
            st.frame_latency_ms.append((done - recv) * 1000.0)
            if could_send:
                open_lat.append((done - recv) * 1000.0)
            # cost of one frame (s), a running mean over about 64 frames
            self._frame_cost += (done - now - self._frame_cost) / 64.0
            now = done
            if i < n:
                if end_by is not None and done > end_by:
                    self._cursor.position = w.start + i    # the rest: the next turn
                    break
                if pump is not None:
                    pump(done)
        self._pending_lost = pending
        if i:
            now = time.monotonic()
            st.lag_s = now - float(recv_all[i - 1])
            st.max_lag_s = max(st.max_lag_s, st.lag_s)
            self._last_recv = float(recv_all[i - 1])
            last_src = float(w.source_time[i - 1])
            self._last_clocked = last_src == last_src      # not NaN: the frame had a time
            self._last_index = w.start + i - 1

    def _may_work_ahead(self, now: float) -> bool:
        """Whether the detectors may work ahead now (monotonic ``now``): no frame waits,
        and the next one cannot send (``Pipeline.quiet_frames``) or is not due within
        ``AHEAD_CLEAR_S`` (one nominal frame period after the last one's arrival)."""
        pipe = self.pipeline
        if pipe is None or self._cursor.backlog > 0 or self._stop.is_set():
            return False
        if pipe.quiet_frames() >= 1:
            return True
        last = self._last_recv
        return last is not None and last + 1.0 / self.frame_rate - now > AHEAD_CLEAR_S

    def _work_ahead(self, end: float) -> None:
        """The detectors' work ahead (``Pipeline.ahead``), piece by piece until monotonic
        ``end`` or none is left (the loop calls it when every session may,
        ``_may_work_ahead``): so the frame that sends a cut finds its placement and the
        gate's distance worked out (``LiveStats.ahead_pieces`` counts the pieces)."""
        pipe, st = self.pipeline, self.stats
        while pipe.ahead():
            st.ahead_pieces += 1
            if time.monotonic() >= end:
                break


__all__ = ["SessionProcessing"]
