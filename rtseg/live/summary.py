"""The summary of a live session as it ends (:class:`rtseg.live.stats.SessionSummary`):
its counters, the source's, the publishers' and the recording's, gathered from a
:class:`rtseg.live.session.LiveSession` whose parts are closed.  Times are seconds;
latencies milliseconds."""

from __future__ import annotations

import logging
from dataclasses import asdict
from typing import Any

from rtseg.live.stats import SessionSummary, percentile

log = logging.getLogger("rtseg.live.session")


def session_summary(session: Any, now: float) -> SessionSummary:
    """The summary of ``session`` (a ``LiveSession``) at monotonic time ``now``.  Frames
    received = processed + dropped by the session (overruns, overload) + ``unprocessed``
    (arrived as it stopped)."""
    st = session.stats
    dur = now - session.session_start if session.session_start else 0.0
    src_stats = session.source.stats.as_dict() if getattr(session.source, "stats", None) else {}
    rec = getattr(session.recorder, "dir", None) or (session.config["recording.dir"] or None)
    targets = {}
    if session.publishers is not None and hasattr(session.publishers, "stats"):
        try:
            targets = session.publishers.stats()
        except Exception as exc:  # pragma: no cover - defensive
            log.warning("publisher counters unavailable: %s", exc)
    rec_stats = getattr(session.recorder, "stats", None)
    summary = SessionSummary(
        targets=targets, recording_failure=getattr(session.recorder, "failure", None),
        recording_frames=getattr(session.recorder, "frames_written", None),
        recording_cuts=getattr(rec_stats, "cuts", None),
        duration_s=dur, frames_received=st.frames_received,
        frames_processed=st.frames_processed,
        frame_rate=session._input_rate(),
        cuts=st.cuts, cuts_by_method=dict(st.cuts_by_method),
        dropped=session.dropped() if session.pipeline is not None else 0,
        source_stats=src_stats,
        pipeline=asdict(session.pipeline.stats) if session.pipeline else {},
        overruns=st.overruns, bad_frames=st.bad_frames, max_lag_ms=st.max_lag_s * 1000.0,
        overload_drops=st.overload_drops,
        max_lag_setting_ms=getattr(session, "_max_lag", 0.0) * 1000.0,
        latency_ms_p50=percentile(st.frame_latency_ms, 50),
        latency_ms_p99=percentile(st.frame_latency_ms, 99),
        latency_frames=len(st.frame_latency_ms),
        open_latency_ms_p50=percentile(st.open_latency_ms, 50),
        open_latency_ms_p99=percentile(st.open_latency_ms, 99),
        open_latency_frames=len(st.open_latency_ms),
        quiet={"batches": st.quiet_batches, "frames": st.quiet_frames,
               "late_open": st.late_open},
        cut_latency_ms_p50=percentile(st.cut_latency_ms, 50),
        cut_latency_ms_p99=percentile(st.cut_latency_ms, 99),
        recording=str(rec) if rec else None,
        stop_reason=session.stop_reason, wire_cuts=st.wire_cuts,
        unprocessed=max(0, st.frames_received - st.frames_processed - st.overruns
                        - st.overload_drops),
        input=session.input_counts() if session.pipeline is not None else {},
        gated={m: d.gate.dropped for m, d in session.pipeline.detectors.items()
               if getattr(d, "gate", None) is not None} if session.pipeline else {},
        floored={m: d.relative.refused for m, d in session.pipeline.detectors.items()
                 if getattr(d, "relative", None) is not None} if session.pipeline else {},
        identity=(asdict(session.pipeline.identity.stats)
                  if session.pipeline is not None and session.pipeline.identity is not None
                  else {}))
    return summary


__all__ = ["session_summary"]
