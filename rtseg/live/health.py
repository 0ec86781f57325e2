"""The live session's health: sensor and source dropouts, the periodic status event and
the loss / refused-input counters.

:class:`SessionHealth` is a part of :class:`rtseg.live.session.LiveSession` (a base class; it uses
the session's ``source``, ``pipeline``, ``ring``, ``stats``, ``config`` and ``_emit``, and
the dropout state ``run`` sets up).  Times: ``now`` is monotonic seconds; joint validity
is tracked and event times are given in session seconds (``SessionClock``), so a joint is
lost after ``gaps.dropout_seconds`` of the source's clock (a replay at ``--speed 4``: of
the take's), a silent source after that long on the wall clock (no frame carries a time).
"""

from __future__ import annotations

import logging

import numpy as np

from rtseg.core.events import INPUT_COUNTERS, SENDER_COUNTERS, DropoutEvent, StatusEvent

#: Shortest span (s) the status's input frame rate is counted over; a shorter one (the last
#: status, sent when the session ends) repeats the last rate, or the whole session's.
RATE_SPAN_S = 0.5

log = logging.getLogger("rtseg.live.session")


class SessionHealth:
    """Dropout tracking, status events and counters of a :class:`~rtseg.live.session.LiveSession`."""

    def _track_dropouts(self, valid: np.ndarray, t: float) -> None:
        """Joint dropouts as of the frame at session time ``t`` with flags ``valid``."""
        if self._source_lost:
            self._source_lost = False
            self._emit(DropoutEvent("source", False, self._now()))
        if self._n_lost == 0 and valid.all():      # fast path: everything reporting
            self._last_valid.fill(t)
            return
        lim = self._dropout_s
        np.copyto(self._last_valid, t, where=valid)
        lost_now = (t - self._last_valid) >= lim
        changed = lost_now != self._joint_lost
        if changed.any():
            names = self.pipeline.joint_names
            for j in np.flatnonzero(changed):
                self._joint_lost[j] = lost_now[j]
                self._n_lost += 1 if lost_now[j] else -1
                if lost_now[j]:
                    self.stats.dropouts += 1
                    log.warning("dropout: %s lost", names[j])
                else:
                    log.info("dropout: %s restored", names[j])
                self._emit(DropoutEvent(names[j], bool(lost_now[j]), self._now()))

    def _check_silence(self, now: float) -> None:
        lim = float(self.config["gaps.dropout_seconds"])
        last = self._last_recv if self._last_recv is not None else self.session_start
        if not self._source_lost and now - last >= lim:
            self._source_lost = True
            self.stats.dropouts += 1
            if self._last_recv is None:
                log.warning("dropout: no frame from the source yet, %.2f s after the start "
                            "(is the sender running?)", now - last)
            else:
                log.warning("dropout: no frames from the source for %.2f s", now - last)
            self._emit(DropoutEvent("source", True, self.clock.now(now, report=True)))

    def dropped(self) -> int:
        """Frames lost since start: the source's counters plus frames the session dropped
        (malformed, overwritten in the ring, dropped under overload)."""
        s = getattr(self.source, "stats", None)
        src = int(getattr(s, "dropped", 0)) if s is not None else 0
        return src + self.stats.bad_frames + self.stats.overruns + self.stats.overload_drops

    def loss_counts(self) -> dict[str, int]:
        """Every count of lost frames and refused input since start, by name: frames
        received and processed, ``dropped`` and its parts the session knows (``overruns``,
        ``overload_drops``, ``bad_frames``), then the source's own counters
        (``SourceStats``: sequence-gap ``dropped`` as ``source_dropped``, ``refused_senders``,
        ``other_senders``, ``clock_restarts``, ...) and ``bad_values`` of the pipeline.
        What ``session.json`` holds under ``"session"`` at the end."""
        st = self.stats
        out = {"frames_received": st.frames_received, "frames_processed": st.frames_processed,
               "dropped": self.dropped(), "overruns": st.overruns,
               "overload_drops": st.overload_drops, "bad_frames": st.bad_frames,
               "max_lag_ms": round(st.max_lag_s * 1000.0, 3)}
        s = getattr(self.source, "stats", None)
        src = s.as_dict() if s is not None and hasattr(s, "as_dict") else {}
        for k, v in src.items():
            out["source_dropped" if k == "dropped" else k] = int(v)
        out.update(self.input_counts())
        return out

    def sender_counts(self) -> dict[str, int]:
        """The source's refusals since start (``SENDER_COUNTERS``: ``allow=``, a second
        sender, clock restarts); 0 for sources without them."""
        s = getattr(self.source, "stats", None)
        return {k: int(getattr(s, k, 0) or 0) for k in SENDER_COUNTERS}

    def input_counts(self) -> dict[str, int]:
        """Input refused since start (``INPUT_COUNTERS``): the source's counters, plus the
        quaternions the pipeline itself replaced as non-finite/zero in ``bad_values``."""
        s = getattr(self.source, "stats", None)
        out = {k: int(getattr(s, k, 0) or 0) for k in INPUT_COUNTERS}
        if self.pipeline is not None:
            out["bad_values"] += int(self.pipeline.stats.bad_values)
        return out

    def _status(self, now: float, alive: int = 1) -> StatusEvent:
        dt = now - self._status_t
        if dt >= RATE_SPAN_S:
            rate = (self.stats.frames_received - self._status_frames) / dt
        else:   # too short a span to count frames over (the last status, at the session's end)
            rate = self._last_rate or self._input_rate()
        self._status_t, self._status_frames = now, self.stats.frames_received
        stale = int(self._joint_lost.sum()) if not self._source_lost else len(self._joint_lost)
        names = tuple(n for n, l in zip(self.pipeline.joint_names, self._joint_lost) if l)
        if self._source_lost:
            names = tuple(self.pipeline.joint_names)
        self._last_rate = rate
        return StatusEvent(alive=alive, frame_rate=float(rate), dropped=self.dropped(),
                           stale_joints=stale, stale_names=names,
                           time=self.clock.now(now, report=True),
                           lag_ms=float(self.stats.lag_s * 1000.0),
                           backlog=int(self.stats.backlog),
                           overload_drops=int(self.stats.overload_drops),
                           **self.sender_counts(), **self.input_counts(),
                           **self.recording_counts())

    def recording_counts(self) -> dict[str, int]:
        """``recording_failed_at`` / ``recording_frames`` / ``recording_cuts`` of the
        status: the frame whose write failed and what the closed recording holds, once a
        write failed; -1 each while it records (or without a recording)."""
        rec = self.recorder
        fail = getattr(rec, "failure", None) if rec is not None else None
        if not fail:
            return {}
        stats = getattr(rec, "stats", None)
        return {"recording_failed_at": int(fail.get("at_frame", -1)),
                "recording_frames": int(getattr(rec, "frames_written", -1)),
                "recording_cuts": int(getattr(stats, "cuts", -1))}

    def _input_rate(self) -> float:
        """Frames per second between the first and the last frame received (0 if < 2)."""
        ring = self.ring
        if ring is None or self.stats.frames_received < 2 or self._first_recv is None:
            return 0.0
        w = ring.window(1)
        span = float(w.recv_time[-1]) - self._first_recv if len(w) else 0.0
        return (ring.head - 1) / span if span > 0 else 0.0


__all__ = ["SessionHealth"]
