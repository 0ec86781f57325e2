"""Names for live segments from a behaviour library (``rtseg.library.behaviours``): the part of the
identity tracker (``rtseg.identity.tracker.IdentityTracker``) that says *what* a segment is, beside
its unsupervised id.

``SegmentNamer`` keeps a ring of the last ``max_window_s + skip_s + 1`` s of the rows the
tracker is fed (one row copy per frame) and, when the tracker decides a segment, names the
rows [boundary + ``skip_s``, decision frame] - the first ``skip_s`` = 0.5 s, the
transition, left out when at least ``min_window_s`` (1 s) remains; at most
``max_window_s`` (3 s) long - with the library's nearest name, or ``unknown`` when the
segment is unlike every example (``rtseg.library.behaviours.Library.name``: by default the
window-model distance of the segment's per-joint angular velocities to each example
window, a name as near as its nearest window; libraries written before that keep their
descriptor and 3 nearest windows).

``NameHolders`` keeps which behaviour ids hold each name this session (``exclusive_names``,
on by default): a name that only earlier segments of *other* ids hold is sent as
``unknown`` - the tracker, comparing one performer within one session, says the segment is
another behaviour than those, while the library compares across performers; the two
conflict, and a forced wrong name is what null rejection exists to avoid (a behaviour
missing from the library is usually nearest to one the session has already shown) - unless
the segment lies clearly nearer to the name than every segment holding it
(``CLAIM_MARGIN``: its distance below 0.9 x theirs), when both ids hold it: a repeat the
tracker split off, or a real instance after a wrong earlier holder.  A correction of a
refused segment's id to an id that holds the name gives it back.

Frames are the pipeline's session indices (0-based among received frames); the rows are
the pose-feature rows the detectors are fed (``rtseg.core.features``), d columns, of the
library's feature profile.  When the session has posture (``posture``: a
``rtseg.core.posture.Posture`` of the source's rig, whose rest geometry is known) and the
library names by it too, a second ring keeps each frame's rotations (joints x 4, one copy
per frame) and the named window's posture rows are worked out from them in one batch when
the segment is named (``rtseg.library.posture_distance``); a frame fed without its
rotations leaves the segment to the pose features alone.

The performer's scale: a library calibrated on one person's examples
(``Library.one_person_calibration``) has only that person's own other takes as known
cases, and another performer - another body, another style - lies farther from all of them
(bandai's two actors: 2.6 times by the model distance).  ``SegmentNamer`` keeps, for every
segment the tracker decides (``decided``), its nearest name's distance over the threshold
it was judged by, and names each later segment with the threshold times the median of
those ratios when it is above 1 (``scale``): statistics of this session's own segments, no
parameter.  Libraries of several people (calibrated across people), given thresholds and
uncalibrated libraries are named as they are.

The operator's scale (``threshold_scale``, ``[identity] name_threshold_scale``): the
library's threshold times this factor, for every segment of the session - above 1 more
segments get a name and more of them a wrong one, below 1 more are ``unknown``
(docs/identity.md, "How strict the names are").  The performer's scale works on top of it,
as on a library whose threshold were that much larger.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

#: a name only other ids hold is still granted to a segment whose library distance is below
#: this x the nearest holder's (module doc).  Chosen leave-one-person-out among 0 (no
#: claims), 0.6, 0.8, 0.9 and 1 over the eight scored people of ``benchmarks/library_loto.py
#: --by-person ../shared/data`` (``benchmarks/names_rule_lopo.py --sets``; docs/identity.md,
#: "Parameters"): the most known segments named right while left-out ``unknown`` >= 0.80
#: and wrong <= 0.05 on each splice seed; 1 lets too many left-out segments through.
CLAIM_MARGIN = 0.9


class SegmentNamer:
    """Names segments from a ring of recent fed rows (module doc).

    library: a ``rtseg.library.behaviours.Library``.  frame_rate: Hz.  skip_s: seconds after the
    boundary left out of the named window.  max_window_s: longest named window, s.
    min_window_s: the skip is kept only when at least this much remains, s.  block: extra
    rows of slack in the ring (the tracker's block length, frames).  threshold_scale: the
    operator's factor on the library's threshold (module doc), > 0.
    """

    def __init__(self, library: Any, frame_rate: float, *, skip_s: float = 0.5,
                 max_window_s: float = 3.0, min_window_s: float = 1.0,
                 block: int = 10, threshold_scale: float = 1.0) -> None:
        if not threshold_scale > 0:
            raise ValueError(f"threshold_scale must be > 0, got {threshold_scale}")
        self.library = library
        self.threshold_scale = float(threshold_scale)
        self.frame_rate = float(frame_rate)
        self.skip = max(0, int(round(skip_s * frame_rate)))
        self._max_window = int(round(max_window_s * frame_rate))
        self._min_named = max(2, int(round(min_window_s * frame_rate)))
        self._R = self._max_window + self.skip + int(round(frame_rate)) + int(block)
        self._rows: np.ndarray | None = None
        self._ridx = np.full(self._R, -1, dtype=np.int64)
        self._rn = 0
        #: the session rig's posture (``rtseg.core.posture.Posture``), or None
        self.posture: Any = None
        self._poses: np.ndarray | None = None       # each frame's rotations, ring as _rows
        self._has_pose = np.zeros(self._R, dtype=bool)
        #: whether the last ``name`` call compared posture too
        self.last_by_posture = False
        #: the performer's scale the last ``name`` call used (``scale``)
        self.last_scale = 1.0
        self._ratios: list[float] = []     # per decided segment: its distance / threshold
        self._scaled_told = False           # the log said the scale is in use

    @property
    def wants_poses(self) -> bool:
        """Whether ``update`` should be given each frame's rotations: the session has
        posture and the library names by it."""
        return self.posture is not None and bool(getattr(self.library, "names_by_posture",
                                                         False))

    def start(self, d: int) -> bool:
        """Allocate the ring for d-column rows; False (logged) when the library holds
        another number of feature dims - the session's segments then go unnamed."""
        if self.library.dims != d:
            log.warning("behaviour library has %d feature dims, the session's features "
                        "have %d: segments are not named", self.library.dims, d)
            return False
        self._rows = np.zeros((self._R, d))
        if self.threshold_scale != 1.0:
            log.info("segments are named with the behaviour library's threshold x %.3g "
                     "([identity] name_threshold_scale)", self.threshold_scale)
        return True

    def update(self, index: int, x: np.ndarray, pose: np.ndarray | None = None) -> None:
        """One fed row ``x`` (d,) of session frame ``index`` into the ring, with the
        frame's rotations ``pose`` (joints, 4) or None."""
        k = self._rn % self._R
        self._rows[k] = x
        self._ridx[k] = index
        self._rn += 1
        if pose is None:
            self._has_pose[k] = False
            return
        if self._poses is None or self._poses.shape[1:] != np.shape(pose):
            self._poses = np.zeros((self._R, *np.shape(pose)))
            self._has_pose[:] = False
        self._poses[k] = pose
        self._has_pose[k] = True

    def _positions(self, boundary: int, frame: int) -> np.ndarray:
        """Ring positions of the rows named for a segment starting at ``boundary`` decided
        at ``frame`` (module doc), oldest first."""
        lo, hi = boundary + self.skip, frame + 1
        if hi - lo < self._min_named:
            lo = boundary
        hi = min(hi, lo + self._max_window)
        pos = np.flatnonzero((self._ridx >= lo) & (self._ridx < hi))
        return pos[np.argsort(self._ridx[pos], kind="stable")]

    def rows(self, boundary: int, frame: int) -> np.ndarray:
        """The fed rows named for a segment starting at ``boundary`` decided at ``frame``
        (module doc), oldest first, (frames, d)."""
        return self._rows[self._positions(boundary, frame)]

    @property
    def scale(self) -> float:
        """The threshold factor of the next naming (module doc, the performer's scale): 1
        unless the library was calibrated on one person and the segments decided so far
        lie, by their median, beyond its threshold."""
        if not self._ratios or not getattr(self.library, "one_person_calibration", False):
            return 1.0
        return max(1.0, float(np.median(self._ratios)))

    def name(self, boundary: int, frame: int, strictness: float = 1.0) -> tuple[str, float]:
        """(name, library distance) of the segment starting at ``boundary`` when decided
        at ``frame``; (``unknown``, inf) with fewer than 2 rows.  ``strictness``: a further
        factor (<= 1) on the threshold for this naming only (a name decided before
        ``decide_after_s``, ``rtseg.identity.tracker``)."""
        pos = self._positions(boundary, frame)
        if len(pos) < 2:
            from rtseg.library.behaviours import UNKNOWN
            return UNKNOWN, math.inf
        P = None
        if self.posture is not None and self._poses is not None and self._has_pose[pos].all():
            P = self.posture.transform(self._poses[pos])
        self.last_by_posture = P is not None
        self.last_scale = s = self.scale
        if s > 1.0 and not self._scaled_told:
            self._scaled_told = True
            log.info("this performer's segments lie %.2f x the library's threshold from it "
                     "(median so far): names are judged by that from now on (the library's "
                     "examples are of one person)", s)
        W = self._rows[pos]
        args = (W, self.frame_rate) if P is None else (W, self.frame_rate, P)
        f = s * self.threshold_scale * strictness
        nm = self.library.name(*args) if f == 1.0 else self.library.name(*args, scale=f)
        return nm.name, nm.distance

    def decided(self, distance: float) -> None:
        """The tracker decided a segment whose nearest name lay at ``distance`` (the last
        ``name`` call's): its ratio to the threshold it was judged by (the operator's
        scale in, the performer's not) joins the performer's scale (inf, no name: left
        out)."""
        lib = self.library
        if not math.isfinite(distance) or not getattr(lib, "one_person_calibration", False):
            return
        t = lib.rule_threshold(self.last_by_posture) * self.threshold_scale
        if t > 0 and math.isfinite(t):
            self._ratios.append(distance / t)


class NameHolders:
    """Which segments (so which behaviour ids) hold each library name this session.

    exclusive: with False every name is granted (the rule off).  claim_margin: a segment
    this much nearer to a name than every holder may hold it too (``CLAIM_MARGIN``).
    ``claimed`` counts those grants."""

    def __init__(self, exclusive: bool = True, claim_margin: float = CLAIM_MARGIN) -> None:
        self.exclusive = bool(exclusive)
        self.claim_margin = float(claim_margin)
        self.claimed = 0
        self._holders: dict[str, list[Any]] = {}

    def grant(self, seg: Any, name: str) -> bool:
        """May ``seg`` (anything with a ``behaviour`` id, read when asked: corrections
        move it, and a ``name_distance``) carry ``name``?  No when earlier segments hold
        the name, none of them has ``seg``'s id and ``seg`` is not ``claim_margin`` x
        nearer to it than each of them; yes otherwise, and ``seg`` then holds it too."""
        holders = self._holders.setdefault(name, [])
        if self.exclusive and holders and all(h.behaviour != seg.behaviour for h in holders):
            nearest = min(getattr(h, "name_distance", math.inf) for h in holders)
            if not getattr(seg, "name_distance", math.inf) < self.claim_margin * nearest:
                return False
            self.claimed += 1
        holders.append(seg)
        return True
