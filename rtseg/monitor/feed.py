"""The processing side of the live monitor: what the session hands to the browser page.

:class:`MonitorFeed` is fed by :class:`rtseg.live.session.LiveSession` on its processing thread
through three calls, and never blocks it:

- ``attach(session)`` once the pipeline exists: the joint names, frame rate, the primary
  detector and its thresholds; the contrast detector is asked to keep its statistic
  (``keep_trace``), which the feed then drains (and empties) on every ``tick``;
- ``__call__(event)`` (the feed is a session listener): every cut, behaviour, dropout and
  status event;
- ``tick(session)`` after each processing step: at most every ``interval`` seconds
  (default 0.04 s) one *batch* is queued: the detector statistic points computed since the
  last batch, the events since then, and every ``health_interval`` (0.25 s) an input-health
  snapshot.

The session's final status (``alive=0``, emitted as it shuts down, after its last ``tick``)
becomes an ``{"kind": "end"}`` event and is queued at once in a last batch, with every event
and statistic point not yet queued and a last health snapshot: a batch the server sends every
page before it closes them (:meth:`rtseg.monitor.server.MonitorServer.stop`).

Batches go into a bounded queue (``capacity`` batches) that the server thread empties
(:meth:`drain`); when nobody drains it the oldest batch is dropped and counted
(``dropped_batches``), so a stalled server never grows memory nor slows the loop.

Times in a batch are seconds since the session start (as ``CutEvent.time``).  A statistic
point of the detector at window boundary ``position`` (a frame of the detector's own
count) is placed at the time of the newest processed frame (on the session's clock of cut
times: the source's own when it has one, see ``rtseg.live.emitter``) minus
``(newest detector frame - position) / frame_rate``.  A behaviour's ``start`` is the time of
the primary detector's cut that began its segment (0 for the first segment).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

import numpy as np

from rtseg.core.events import BehaviourEvent, CutEvent, DropoutEvent, StatusEvent

__all__ = ["MonitorFeed"]

#: latency percentiles use at most this many of the newest per-frame latencies
LATENCY_WINDOW = 1200


class MonitorFeed:
    """Bounded, batched hand-over of a live session's state to the monitor server."""

    def __init__(self, interval: float = 0.04, health_interval: float = 0.25,
                 capacity: int = 256) -> None:
        self.interval = float(interval)
        self.health_interval = float(health_interval)
        self.capacity = int(capacity)
        self.info: dict[str, Any] = {}
        self.dropped_batches = 0
        self.batches = 0
        self._q: deque[dict] = deque()
        self._lock = threading.Lock()
        self._events: list[dict] = []
        self._segment_time: dict[int, float] = {0: 0.0}   # primary segment -> its cut's time
        self._det: Any = None
        self._session: Any = None
        self._gate_seen = 0
        self._next = 0.0
        self._next_health = 0.0
        self._health_frames = 0
        self._health_t = 0.0
        self._refused: dict[int, int] = {}

    # ------------------------------------------------------------ session side
    def attach(self, session: Any) -> None:
        """Read what does not change during the session; turn on the primary detector's
        statistic trace."""
        pipe = session.pipeline
        det = pipe.detectors.get(session.primary)
        info: dict[str, Any] = {
            "joints": list(pipe.joint_names), "frame_rate": float(session.frame_rate),
            "primary": session.primary, "methods": list(pipe.detectors),
            "source": session._source_arg if isinstance(session._source_arg, str)
            else type(session.source).__name__,
            "statistic": None, "threshold": None, "pre_level": None,
        }
        if det is not None and hasattr(det, "trace") and hasattr(det, "keep_trace"):
            det.keep_trace = True
            self._det = det
            info["statistic"] = f"{session.primary} statistic"
            info["threshold"] = float(det.threshold)
            pre = getattr(det, "pre", None)
            if pre is not None and pre.on:       # the pre-look's values and its level
                info["pre_level"] = float(pre.level * det.threshold)
        self.info = info
        self._session = session
        self._health_t = time.monotonic()

    def __call__(self, ev: Any) -> None:
        if isinstance(ev, CutEvent):
            if ev.method == self.info.get("primary"):
                self._segment_time[ev.segment] = ev.time
                if len(self._segment_time) > 4096:
                    del self._segment_time[min(self._segment_time)]
            self._events.append({"kind": "cut", "event": ev.event, "method": ev.method,
                                 "segment": ev.segment, "frame": ev.frame,
                                 "time": ev.time, "confidence": ev.confidence,
                                 "wire": bool(ev.wire)})
        elif isinstance(ev, BehaviourEvent):
            self._events.append({"kind": "behaviour", "segment": ev.segment,
                                 "behaviour": ev.behaviour, "name": ev.name,
                                 "frame": ev.frame, "time": ev.time,
                                 "start": self._segment_time.get(ev.segment, 0.0),
                                 "confidence": ev.confidence,
                                 "correction": bool(ev.correction)})
        elif isinstance(ev, DropoutEvent):
            self._events.append({"kind": "dropout", "name": ev.name, "lost": bool(ev.lost),
                                 "time": ev.time})
        elif isinstance(ev, StatusEvent) and not ev.alive:
            self._events.append({"kind": "end", "time": ev.time})
            self._end()

    def _end(self) -> None:
        """Queue the last batch now: no ``tick`` follows the session's final status."""
        if self._session is not None:
            try:
                self.tick(self._session, force=True)
                return
            except Exception:    # a session half shut down: the events still go out
                pass
        if self._events:
            self._put({"now": self._events[-1]["time"], "events": self._events})
            self._events = []

    def tick(self, session: Any, now: float | None = None, force: bool = False) -> None:
        """Queue one batch when ``interval`` has passed since the last (processing thread);
        ``force``: now, with a health snapshot (the session's end)."""
        now = time.monotonic() if now is None else now
        if now < self._next and not force:
            return
        self._next = now + self.interval
        latest = session.clock.latest       # the clock of every event time (source's own)
        t_now = latest[1] if latest is not None else session.clock.now(now)
        batch: dict[str, Any] = {"now": round(session.clock.now(now), 4)}
        det = self._det
        if det is not None:
            rate = self.info["frame_rate"]
            newest = getattr(det, "_t", 0) - 1

            def at(position: int) -> float:
                return round(t_now - (newest - position) / rate, 4)
            if det.trace:
                batch["stat"] = [(at(p), round(float(v), 4)) for p, v, _ in det.trace]
                det.trace.clear()
            if det.trace_pre:
                batch["pre"] = [(at(p), round(float(v), 4)) for p, v, _ in det.trace_pre]
                det.trace_pre.clear()
            gate = getattr(det, "gate", None)
            if gate is not None and len(gate.decisions) > self._gate_seen:
                new = gate.decisions[self._gate_seen:]
                self._gate_seen = len(gate.decisions)
                dropped = [(at(b), round(float(d), 3)) for b, d, sent in new if not sent]
                if dropped:
                    batch["gated"] = dropped
        if now >= self._next_health or force:
            self._next_health = now + self.health_interval
            batch["health"] = self._health(session, now)
        if self._events:        # last: a failure above leaves them for the next batch
            batch["events"], self._events = self._events, []
        self._put(batch)

    def _health(self, session: Any, now: float) -> dict[str, Any]:
        st = session.stats
        dt = max(1e-9, now - self._health_t)
        fps = (st.frames_received - self._health_frames) / dt
        self._health_t, self._health_frames = now, st.frames_received
        lat = st.frame_latency_ms.recent(LATENCY_WINDOW)
        p50, p99 = (np.percentile(lat, [50, 99]) if lat.size else (float("nan"),) * 2)
        ages = session.clock.now(now) - session._last_valid
        lost = session._joint_lost
        targets = []
        for p in getattr(session.publishers, "publishers", ()):
            pst = getattr(p, "stats", None)
            refused = int(getattr(pst, "refused", 0) or 0)
            if hasattr(p, "connected"):
                up = bool(p.connected)
            elif hasattr(p, "_down"):
                up = not p._down
            else:
                up = refused == self._refused.get(id(p), refused)
            self._refused[id(p)] = refused
            targets.append({"target": getattr(p, "target", type(p).__name__), "up": up,
                            **(pst.as_dict() if hasattr(pst, "as_dict") else {})})
        rec = getattr(session.recorder, "dir", None)
        return {
            "frames": st.frames_received, "processed": st.frames_processed,
            "fps": round(fps, 1), "dropped": session.dropped(),
            "input": session.input_counts(),
            "stale": [round(float(a), 2) if l or a > 0.05 else 0 for a, l in zip(ages, lost)],
            "lost": [bool(x) for x in lost], "source_lost": bool(session._source_lost),
            "latency_ms": [None if p50 != p50 else round(float(p50), 3),
                           None if p99 != p99 else round(float(p99), 3)],
            "lag_ms": round(st.lag_s * 1000.0, 1), "cuts": st.cuts,
            "targets": targets, "recording": str(rec) if rec else None,
            "monitor_dropped": self.dropped_batches,
        }

    def _put(self, batch: dict) -> None:
        with self._lock:
            if len(self._q) >= self.capacity:
                self._q.popleft()
                self.dropped_batches += 1
            self._q.append(batch)
            self.batches += 1

    # ------------------------------------------------------------ server side
    def drain(self) -> list[dict]:
        """Every batch queued since the last drain, oldest first (server thread)."""
        with self._lock:
            out = list(self._q)
            self._q.clear()
        return out

    def summary(self) -> dict[str, Any]:
        return {"batches": self.batches, "dropped_batches": self.dropped_batches}

