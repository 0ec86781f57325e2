"""The live session's events: cuts and behaviour decisions from the pipeline turned into
``rtseg.core.events`` objects, and every event published, recorded and shown.

:class:`SessionEvents` is a part of :class:`rtseg.live.session.LiveSession` (a base class; it uses
the session's ``ring``, ``pipeline``, ``publishers``, ``recorder``, ``listeners``,
``stats`` and ``_warn``).  Event times are session seconds from the session's
:class:`rtseg.live.clock.SessionClock` (``clock``: the source's own clock where frames carry
one, counted from the session start), the same for cuts, behaviour decisions, dropouts and
status; ``*_ms`` fields are milliseconds (wall clock); frame indices are 0-based among the
frames received this session.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from rtseg.core.events import BehaviourEvent, CutEvent, DropoutEvent, StatusEvent
from rtseg.live.pipeline import PipelineCut

Event = CutEvent | StatusEvent | DropoutEvent | BehaviourEvent


class SessionEvents:
    """Event building and sending of a :class:`~rtseg.live.session.LiveSession`."""

    def _now(self) -> float:
        """Session seconds now (the latest frame's time while frames flow), reported."""
        return self.clock.now(time.monotonic(), report=True)

    def session_time(self, now: float | None = None) -> float:
        """Session seconds at monotonic ``now`` (default: now) on the clock of every
        event time; never reported (any thread)."""
        return self.clock.now(time.monotonic() if now is None else now)

    def _clock_frame(self, index: int, recv: float, source_time: float | None) -> float:
        """Feed frame ``index`` to the session clock (processing thread, in order); its
        session time.  A new clock segment (the source clock went back or jumped) is
        warned, at most every 5 s."""
        clock = self.clock
        seen = clock.segments
        t = clock.feed(index, recv, source_time)
        if clock.segments != seen:
            self._warn("clock", "session clock: %s at frame %d; times continue from "
                       "%.3f s on the receive clock (segment %d)", clock.last_break, index,
                       t, clock.segments + 1)
        return t

    def _emit(self, ev: Event) -> Event:
        """Publish, record and show one event; returns it as sent (cuts: latency stamped),
        tagged with the session's ``name`` when it has one."""
        if self.name:
            ev.source = self.name
        try:
            if isinstance(ev, CutEvent):
                if ev.wire:
                    ev = self.publishers.publish_cut(ev) or ev.stamped()
                else:
                    ev = ev.stamped()
                    if self._log_pubs is not None:
                        self._log_pubs(ev)
            elif isinstance(ev, StatusEvent):
                self.publishers.publish_status(ev)
            elif isinstance(ev, BehaviourEvent):
                send = getattr(self.publishers, "publish_behaviour", None)
                if send is not None:
                    send(ev)
            else:
                self.publishers.publish_dropout(ev)
        except Exception as exc:
            self.stats.publish_errors += 1
            self._warn("publish", "publishing %s failed: %s", type(ev).__name__, exc)
        if self.recorder is not None:
            with self._rec_lock:
                try:
                    if isinstance(ev, CutEvent):
                        self.recorder.record_cut(ev)
                    else:
                        self.recorder.record_event(ev)
                except Exception as exc:
                    self.stats.record_errors += 1
                    self._warn("record_ev", "recording an event failed: %s", exc)
        for fn in self.listeners:
            try:
                fn(ev)
            except Exception as exc:
                self._warn("listener", "event listener failed: %s", exc)
        return ev

    def _cut_event(self, pc: PipelineCut, detected_recv: float, at_index: int | None = None,
                   at_source_time: float | None = None) -> CutEvent:
        """The event of cut ``pc``, revealed by frame ``at_index`` (received at monotonic
        ``detected_recv``, source clock ``at_source_time`` s or NaN/None)."""
        ring = self.ring
        m = pc.cut.method
        seg = self._segment.get(m, 0) + 1
        self._segment[m] = seg
        wire = m in self.wire
        if wire:
            self._event_no += 1
        b_recv = ring.recv_time_at(pc.boundary) if ring is not None else None
        if b_recv is None:
            b_recv = detected_recv - (pc.detected - pc.boundary) / self.frame_rate
        return CutEvent(
            event=self._event_no if wire else 0, segment=seg, frame=int(pc.boundary),
            time=self._boundary_time(pc.boundary, b_recv, at_index, at_source_time), method=m,
            label=m,
            confidence=float(np.clip(pc.cut.confidence, 0.0, 1.0)),
            detector_delay_ms=float(max(0, pc.detected - pc.boundary) / self.frame_rate * 1000.0),
            boundary_recv_time=float(b_recv), detected_frame=int(pc.detected),
            score=float(pc.cut.score), detected_recv_time=float(detected_recv), wire=wire)

    def _boundary_time(self, index: int, b_recv: float, at_index: int | None = None,
                       at_source_time: float | None = None) -> float:
        """Session seconds of frame ``index`` (``SessionClock.time_of``: on the source's own
        clock when it has one, so a replay sent faster than real time reports the take's
        seconds).  A frame the clock no longer holds (a long detector delay at a high
        input rate) is placed from the revealing frame ``at_index``, one nominal frame
        period per frame.  ``b_recv`` and ``at_source_time`` are not needed (kept for
        callers)."""
        return self.clock.time_of(index, at_index)

    def _behaviour_event(self, d: Any) -> BehaviourEvent:
        """A ``rtseg.identity.tracker.IdentityDecision`` as the event sent (ids as text)."""
        self._behaviour_no = getattr(self, "_behaviour_no", 0) + 1
        return BehaviourEvent(event=self._behaviour_no, segment=int(d.segment),
                              behaviour=str(d.behaviour),
                              name=str(getattr(d, "name", "") or d.behaviour),
                              confidence=float(d.confidence), frame=int(d.boundary),
                              decided_frame=int(d.decided_frame), time=self._now(),
                              correction=bool(d.correction),
                              previous=str(d.previous) if d.correction else "")


__all__ = ["Event", "SessionEvents"]
