"""What the identity tracker (``rtseg.identity.tracker``) sends and counts: one identity
message (a decision or a correction) and the session's identity counters."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class IdentityDecision:
    """One identity message: a decision (``correction`` False) or a correction.

    segment: index of the segment in the primary detector's stream (0 = before the first cut).
    boundary: its first frame (session index).
    behaviour: the behaviour id (1-based, in order of first appearance this session).
    previous: for a correction, the id sent before (else 0).
    decided_frame: session index of the frame whose arrival produced this message.
    confidence: 0..1, the margin to the threshold (match: 1 - D / threshold; new id:
        1 - threshold / D; 0 when there was nothing to compare with).
    distance: D to the nearest known behaviour (inf if none).
    new: True when ``behaviour`` was created by this message.
    name: the library's name for the segment (``unknown`` when rejected; "" without a
        library); name_distance: the library distance behind it (inf if none).
    """
    segment: int
    boundary: int
    behaviour: int
    decided_frame: int
    confidence: float
    distance: float
    correction: bool = False
    previous: int = 0
    new: bool = False
    name: str = ""
    name_distance: float = math.inf


@dataclass
class IdentityStats:
    """The session's identity counts (``IdentityTracker.stats``)."""
    segments: int = 0
    decisions: int = 0
    corrections: int = 0
    new_behaviours: int = 0
    clamped: int = 0                  # boundaries older than the history (window shortened)
    name_waits: int = 0               # decisions put off to name_after_s: `unknown` sooner
    first_look_names: int = 0         # decisions made at the first look (first_name_after_s)
    first_look_waits: int = 0         # segments the first look left for decide_after_s
    named: int = 0                    # decisions sent with a library name
    names_unknown: int = 0            # decisions sent as `unknown` (with a library)
    names_contested: int = 0          # of those, names held by other ids only
    names_restored: int = 0           # contested names a correction to a holder's id gave back
    names_claimed: int = 0            # names other ids held, granted as clearly nearer (CLAIM_MARGIN)
    posture_namings: int = 0          # decisions whose naming compared posture too
    names_scaled: int = 0             # namings whose threshold the performer's scale raised
    largest_scale: float = 1.0        # ... the largest such factor
    name_threshold_scale: float = 1.0  # the operator's factor on the library's threshold
