"""The live session: source -> ring buffer -> pose features -> online detectors -> cut
events -> publishers.  ``session`` holds :class:`LiveSession`; ``loop`` runs sessions on one
thread (``run_sessions``); ``pipeline`` the per-frame pipeline it shares with offline
replay (``replay``: recorded frames or a session folder through it); ``intake``,
``process``, ``quiet``, ``emitter``, ``health`` its frame intake, processing step,
quiet-frame batching, events and health;
``config`` the ``config/live.toml`` schema; ``outputs`` the publishers of ``[output]``;
``stats`` the run-time counters; ``rate_check`` the declared-frame-rate check.

May import ``rtseg.identity``, ``rtseg.detectors``, ``rtseg.recording``,
``rtseg.publishers``, ``rtseg.core``, ``rtseg.config`` and ``rtseg.drivers``; no command
module."""

from rtseg.live.session import (
    DEFAULT_FRAME_RATE,
    FloatRing,
    LiveSession,
    LiveStats,
    Pipeline,
    PipelineCut,
    PipelineStats,
    SessionSummary,
    build_publishers,
    detector_params,
    make_detectors,
    replay_frames,
    replay_session,
    wire_methods,
    with_suit,
)

__all__ = [
    "DEFAULT_FRAME_RATE",
    "FloatRing",
    "LiveSession",
    "LiveStats",
    "Pipeline",
    "PipelineCut",
    "PipelineStats",
    "SessionSummary",
    "build_publishers",
    "detector_params",
    "make_detectors",
    "replay_frames",
    "replay_session",
    "wire_methods",
    "with_suit",
]
