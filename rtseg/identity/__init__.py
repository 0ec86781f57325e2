"""Behaviour identity: which earlier behaviour each new segment is (``tracker``, live and
offline; ``messages``: what it sends and counts), the names a behaviour library gives them
(``names``), ids for the segments of a recorded take (``segments``) and the running block
sums the tracker's window models use.

May import ``rtseg.core``, ``rtseg.detectors`` and ``rtseg.library``; nothing above them."""

from rtseg.identity.tracker import (
    DEFAULT_DECIDE_AFTER_S,
    DEFAULT_NAME_AFTER_S,
    DEFAULT_ID_SKIP_S,
    DEFAULT_THRESHOLD,
    DEFAULT_MAX_WINDOW_S,
    MIN_WINDOW_S,
    IdentityDecision,
    IdentityStats,
    IdentityTracker,
    tracker_options,
    tracker_from_config,
)

__all__ = [
    "DEFAULT_DECIDE_AFTER_S",
    "DEFAULT_NAME_AFTER_S",
    "DEFAULT_ID_SKIP_S",
    "DEFAULT_THRESHOLD",
    "DEFAULT_MAX_WINDOW_S",
    "MIN_WINDOW_S",
    "IdentityDecision",
    "IdentityStats",
    "IdentityTracker",
    "tracker_options",
    "tracker_from_config",
]
