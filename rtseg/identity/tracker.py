"""Unsupervised behaviour identity, live: which earlier behaviour each new segment is.

``IdentityTracker`` is a streaming object the live pipeline (``rtseg.live.pipeline.Pipeline``)
feeds with every pose-feature row it gives the detectors and with the primary detector's
cuts.  For every segment it decides a behaviour id once - the id of an earlier segment of
the session when the new segment is the same behaviour, else a new id - and may correct it
once when the whole segment is known (at the next cut).

Frames and times
----------------
Frame indices are the pipeline's session indices (0-based among received frames).  The
tracker works in *blocks* of ``step`` fed frames (default 10, 83 ms at 120 Hz): it keeps
running prefix sums (n, sum x, sum x x^T) at every block start in a ring of
``history_s`` seconds (``rtseg.identity.block_sums.BlockSums``), so the statistics of any stretch
of the recent past cost one subtraction, never a pass over frames.  A segment boundary is rounded to the nearest
block start.

Decision
--------
A cut reaches the tracker when the detector reveals it, ``detected - boundary`` frames
after the boundary (1.5-3 s for ``contrast``: its same-behaviour gate holds every cut until
1.5 s of the new segment have arrived), so
the new segment's first frames are already summed.  The segment is decided when at least
``decide_after_s`` seconds of it are summed (at once when the cut arrives that late; with a
library, a segment the library would call ``unknown`` then waits until ``name_after_s`` are
summed, and is decided then whatever the answer): its window [boundary + ``id_skip_s``, decision frame)
(the first 0.5 s, where a cut within the human tolerance may still hold the previous
behaviour, left out when at least 1 s remains), at most ``max_window_s`` long, is fitted
(``window_models.fit``) and compared with every known behaviour's model (all its finished
segments pooled) by

    D(a, b) = sqrt( pca_distance(a, b) x ppca_distance(a, b) / sqrt(d_eff) )

(both factors are about 1 for two windows of one motion; d_eff = the larger number of
varying directions of the two), stated for ``reference_dims`` (8) effective dimensions:
1 + (D - 1) x sqrt(reference_dims / d_eff), so that one threshold serves the 4-channel
(d_eff 8) and the 14-joint (d_eff 48) features.  The default threshold, 5.0 (with
``decide_after_s`` 2.5), was chosen on the default detector's cuts by leave-one-take-out
over the labelled cmu and tsseg4d takes and synthetic performances, the decision at most
2.5 s into the segment (``benchmarks/identity_loto.py``, docs/identity.md).  The nearest
behaviour is taken when D <= ``threshold``, else a new id is made.  The first segment of
the session (before any cut) gets id 1 after ``decide_after_s`` seconds of frames.

Correction
----------
At the next cut the finished segment's full statistics are compared again.  When they
disagree with the decision clearly - the sent behaviour is now farther than
``threshold x correction_margin``, or (a new id was sent) an earlier behaviour is nearer
than ``threshold / correction_margin`` - one correction is sent (``corrections`` counts
them); either way the segment's statistics then join its final behaviour's model.

Names (behaviour library)
-------------------------
With a ``library`` (``rtseg.library.behaviours.Library``, ``rtseg learn``) every decision also names
the segment (``IdentityDecision.name``; the id is the unsupervised one either way):
``rtseg.identity.names.SegmentNamer`` names the rows [boundary + ``name_skip_s``, decision
frame] with the library's nearest name, or ``unknown`` when the segment is unlike every
example.  A correction keeps the segment's name.  With ``exclusive_names`` (default) a name
only earlier segments of other ids hold is sent as ``unknown`` (``names_contested``;
``rtseg.identity.names.NameHolders``) unless the segment is clearly nearer to it than they
were (``names_claimed``); a correction to an id that holds it gives it back
(``names_restored``).

A first look (``first_name_after_s`` > 0, off by default): with a library, a segment the
library names that many seconds in by its threshold times ``first_name_scale`` (<= 1) is
decided then, id and name, sooner than ``decide_after_s``; any other waits for
``decide_after_s`` and the library's own threshold (``first_look_names``,
``first_look_waits``).  ``library_threshold`` replaces ``threshold`` for the ids of a
session with a library.

Cost: per frame one row copy into the block buffer; per block one (step x d)^T (step x d)
product; per decision one eigen-decomposition per changed model (a few per cut).
``benchmarks/identity_speed.py`` measures it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from rtseg.detectors.window_models import (DEFAULT_ID_SKIP_S, DEFAULT_MAX_WINDOW_S,
                                          MIN_WINDOW_S, WindowModel, WindowStats,
                                          behaviour_distance, fit)
from rtseg.identity.block_sums import BlockSums
from rtseg.identity.messages import IdentityDecision, IdentityStats
from rtseg.identity.names import CLAIM_MARGIN, NameHolders, SegmentNamer
from rtseg.library.behaviours import UNKNOWN

#: defaults (also the ``[identity]`` keys of ``config/live.toml``; the decision window's
#: ``DEFAULT_ID_SKIP_S``, ``DEFAULT_MAX_WINDOW_S`` and ``MIN_WINDOW_S`` are
#: ``rtseg.detectors.window_models``', shared with the same-behaviour gate, which decides
#: sooner: ``GATE_DECIDE_S``): seconds of a segment summed before its id is decided, the
#: longer wait of a segment a library cannot name by then, and the distance threshold
DEFAULT_DECIDE_AFTER_S = 2.5
DEFAULT_NAME_AFTER_S = 2.5
DEFAULT_THRESHOLD = 5.0
#: with a library: the first look (seconds; 0 = none) and its factor on the library's
#: threshold - docs/identity.md
DEFAULT_FIRST_NAME_AFTER_S = 0.0
DEFAULT_FIRST_NAME_SCALE = 1.0


@dataclass
class _Segment:
    index: int
    boundary: int
    block: int                        # absolute block index of its first block
    n0: int                           # prefix at that block
    s10: np.ndarray
    s20: np.ndarray
    decide_block: int                 # decide once this many blocks are complete
    behaviour: int = 0                # 0: not decided yet
    created: bool = False
    name: str = ""
    name_distance: float = math.inf
    library_name: str = ""            # the library's answer, before exclusive_names


class IdentityTracker:
    """Streaming unsupervised identity (see module docstring).

    frame_rate: Hz.  method: the detector whose cuts delimit segments ("" = any cut).
    decide_after_s: seconds of the new segment summed before its decision.
    max_window_s: longest decision window (when the cut arrives later than decide_after_s).
    threshold: D at or below which a segment is an earlier behaviour.
    correction_margin: factor (>= 1) by which the full segment must disagree to correct.
    step: frames per block.  history_s: seconds of block sums kept.
    library: a behaviour library naming each segment (module doc, Names).
    name_skip_s: seconds after the boundary left out of the named window.
    name_after_s: with a library, seconds of the new segment summed before the decision
        of a segment the library would call ``unknown`` at decide_after_s (a longer window
        names more segments; a name given at decide_after_s is sent then).
    id_skip_s: seconds after the boundary left out of the decision window when at least
        1 s remains (a cut may lie that far from the change, so its first frames may still
        be the previous behaviour).
    exclusive_names: with a library, a name only earlier segments of other ids hold is
        sent as ``unknown`` (module doc, Names).
    claim_margin: ... unless the segment's library distance is below this x every
        holder's (``rtseg.identity.names.CLAIM_MARGIN``; 0 = never).
    name_threshold_scale: the library's threshold times this (> 0; the operator's scale,
        ``rtseg.identity.names``).
    first_name_after_s: with a library, a segment is decided once this many seconds of it
        are summed when the library names it by its threshold times ``first_name_scale``
        (a stricter look, <= 1); otherwise it waits for ``decide_after_s`` as without
        (0: off).  Module doc, Names.
    library_threshold: the id threshold when a library names the segments (None: the
        ``threshold``).
    """

    def __init__(self, frame_rate: float, method: str = "", *,
                 decide_after_s: float = DEFAULT_DECIDE_AFTER_S,
                 max_window_s: float = DEFAULT_MAX_WINDOW_S,
                 threshold: float = DEFAULT_THRESHOLD, correction_margin: float = 2.0,
                 step: int = 10, history_s: float = 30.0, reference_dims: int = 8,
                 library: Any = None, name_skip_s: float = 0.5,
                 name_after_s: float = DEFAULT_NAME_AFTER_S,
                 id_skip_s: float = DEFAULT_ID_SKIP_S, exclusive_names: bool = True,
                 claim_margin: float = CLAIM_MARGIN,
                 name_threshold_scale: float = 1.0,
                 first_name_after_s: float = DEFAULT_FIRST_NAME_AFTER_S,
                 first_name_scale: float = DEFAULT_FIRST_NAME_SCALE,
                 library_threshold: float | None = None) -> None:
        if not frame_rate > 0:
            raise ValueError(f"frame_rate must be positive, got {frame_rate}")
        if not decide_after_s > 0:
            raise ValueError(f"decide_after_s must be positive, got {decide_after_s}")
        if not threshold > 0:
            raise ValueError(f"threshold must be positive, got {threshold}")
        if correction_margin < 1:
            raise ValueError(f"correction_margin must be >= 1, got {correction_margin}")
        if not name_threshold_scale > 0:
            raise ValueError(f"name_threshold_scale must be positive, got {name_threshold_scale}")
        if first_name_after_s < 0 or not 0 < first_name_scale <= 1:
            raise ValueError(f"first_name_after_s must be >= 0 and first_name_scale in (0, 1], "
                             f"got {first_name_after_s}, {first_name_scale}")
        if library_threshold is not None and not library_threshold > 0:
            raise ValueError(f"library_threshold must be positive, got {library_threshold}")
        self.frame_rate = float(frame_rate)
        self.reference_dims = int(reference_dims)
        self.method = method
        self.block = int(step)
        # the ids' threshold without and with a library (``self.threshold``, set with the
        # library below)
        self._thresholds = (float(threshold), float(library_threshold or threshold))
        self.margin = float(correction_margin)
        self._id_blocks = max(2, int(math.ceil(decide_after_s * frame_rate / step)))
        self._named_blocks = max(self._id_blocks, int(math.ceil(name_after_s * frame_rate / step)))
        self._first_blocks = (min(self._id_blocks,
                                  max(2, int(math.ceil(first_name_after_s * frame_rate / step))))
                              if first_name_after_s > 0 else self._id_blocks)
        self.first_name_scale = float(first_name_scale)
        self.max_blocks = max(self._named_blocks, int(round(max_window_s * frame_rate / step)))
        self.H = max(self.max_blocks + 4, int(math.ceil(history_s * frame_rate / step)))
        self.stats = IdentityStats(name_threshold_scale=float(name_threshold_scale))
        self.events: list[IdentityDecision] = []
        self.history: list[IdentityDecision] = []   # every message, in order
        self._d = 0
        self._behaviours: list[list[Any]] = []       # [n, s1, s2, model or None]
        self._seg: _Segment | None = None
        self._next_seg = 0
        self._holders = NameHolders(exclusive_names, claim_margin)
        self._namer_kw = {"skip_s": name_skip_s, "max_window_s": max_window_s,
                          "min_window_s": MIN_WINDOW_S, "block": step,
                          "threshold_scale": float(name_threshold_scale)}
        self._posture: Any = None     # the session rig's posture (set_posture)
        self.library = library
        self._skip_blocks = max(0, int(round(id_skip_s * frame_rate / step)))
        self._min_blocks = max(2, int(round(MIN_WINDOW_S * frame_rate / step)))

    @property
    def library(self) -> Any:
        """The behaviour library naming segments (None: ids only)."""
        return None if self.namer is None else self.namer.library

    @library.setter
    def library(self, library: Any) -> None:
        if self._d:
            raise RuntimeError("the library is set before the first fed row")
        self.namer = None if library is None else SegmentNamer(
            library, self.frame_rate, **self._namer_kw)
        self.threshold = self._thresholds[library is not None]
        if self.namer is not None:
            self.namer.posture = self._posture

    @property
    def decide_blocks(self) -> int:
        """Blocks of a new segment summed before its first decision attempt (with a library,
        the first look's: ``first_name_after_s``)."""
        return self._id_blocks if self.namer is None else self._first_blocks

    @property
    def quiet_frames(self) -> int:
        """How many of the next fed rows certainly make no decision (the live loop reads
        quiet frames late, in one batch: ``rtseg.live.loop``).  A decision is made only
        when a row completes a block (``update``) or with a cut (``on_cut``, on a frame
        the detector does not promise quiet), so the rows before the one that completes
        the block being filled are quiet; 0 before the first row."""
        if self._d == 0:
            return 0
        return self._sums.to_complete - 1

    # ------------------------------------------------------------------ streaming state
    def _init(self, d: int) -> None:
        self._d = d
        self._sums = BlockSums(d, self.block, self.H)
        if self.namer is not None and not self.namer.start(d):
            self.namer = None

    def set_posture(self, posture: Any) -> None:
        """The session rig's posture (``rtseg.core.posture.Posture``; None: none): with it,
        and a library that names by posture, segments are named by posture too (give
        ``update`` each frame's rotations while ``wants_poses``)."""
        self._posture = posture
        if self.namer is not None:
            self.namer.posture = posture

    @property
    def wants_poses(self) -> bool:
        """Whether ``update`` should be given each frame's rotations (``set_posture``)."""
        return self.namer is not None and self.namer.wants_poses

    def update(self, index: int, x: np.ndarray, pose: np.ndarray | None = None) -> None:
        """One fed feature row ``x`` (d,) of session frame ``index``; ``pose``: the
        frame's rotations (joints, 4) when ``wants_poses``."""
        if self._d == 0:
            self._init(len(x))
        completed = self._sums.add(index, x)
        if self.namer is not None:
            self.namer.update(index, x, pose)
        if self._seg is None:
            self._open(index, 0, self._sums.started - 1)
        if completed:
            seg = self._seg
            if seg.behaviour == 0 and self._sums.started >= seg.decide_block:
                self._attempt(seg, self._sums.started, index)

    def on_cut(self, boundary: int, detected: int, method: str = "") -> None:
        """A cut of the primary detector (``boundary`` = first frame of the new segment)."""
        if self.method and method and method != self.method:
            return
        if self._d == 0:
            return
        blk = self._block_at(boundary)
        seg = self._seg
        if seg is not None:
            end = max(blk, seg.block + 1)
            if seg.behaviour == 0:
                self._decide(seg, min(end, self._complete()), detected)
            self._finish(seg, end, detected)
        self._open(boundary, self._next_seg, blk)
        new = self._seg
        if self._complete() >= new.decide_block:
            self._attempt(new, min(self._complete(), new.block + self.max_blocks), detected)

    def step(self, index: int, x: np.ndarray | None, cuts: Sequence[Any],
             pose: np.ndarray | None = None) -> None:
        """The pipeline hook: the fed row (None when the frame was not fed), the cuts its
        arrival revealed (``PipelineCut``) and the frame's rotations (or None)."""
        if x is not None:
            self.update(index, x, pose)
        for c in cuts:
            self.on_cut(c.boundary, c.detected, c.cut.method)

    def drain(self) -> list[IdentityDecision]:
        """Messages made since the last call, in order."""
        out, self.events = self.events, []
        return out

    # ------------------------------------------------------------------ blocks
    def _complete(self) -> int:
        """Absolute index one past the last complete block."""
        return self._sums.complete()

    def _block_at(self, frame: int) -> int:
        """Absolute block whose start is nearest ``frame`` (within the history)."""
        blk, clamped = self._sums.block_at(frame)
        self.stats.clamped += int(clamped)
        return blk

    def _window(self, seg: _Segment, end: int, skip: int = 0) -> WindowStats | None:
        """Statistics of the segment's blocks [start, end): start = its first block, or
        ``skip`` blocks later when at least ``_min_blocks`` remain after them."""
        n0, s10, s20 = seg.n0, seg.s10, seg.s20
        if skip and end - (seg.block + skip) >= self._min_blocks:
            n0, s10, s20 = self._sums.prefix(seg.block + skip)
        n, s1, s2 = self._sums.prefix(end)
        n -= n0
        if n < 2:
            return None
        return WindowStats.from_sums(n, s1 - s10, s2 - s20)

    # ------------------------------------------------------------------ segments
    def _open(self, boundary: int, index: int, blk: int) -> None:
        n0, s10, s20 = self._sums.prefix(blk)
        self._seg = _Segment(index, boundary, blk, n0, s10.copy(), s20.copy(),
                             blk + self.decide_blocks)
        self._next_seg = index + 1
        self.stats.segments += 1

    def _model(self, j: int) -> WindowModel:
        b = self._behaviours[j]
        if b[3] is None:
            b[3] = fit(WindowStats.from_sums(b[0], b[1], b[2]))
        return b[3]

    def distance(self, a: WindowModel, b: WindowModel) -> float:
        """D(a, b) of the module docstring (``window_models.behaviour_distance``)."""
        return behaviour_distance(a, b, self.reference_dims)

    def _nearest(self, stats: WindowStats) -> tuple[int, float]:
        """(behaviour id, D) of the nearest known behaviour; (0, inf) if none."""
        if not self._behaviours:
            return 0, math.inf
        m = fit(stats)
        best, bd = 0, math.inf
        for j in range(len(self._behaviours)):
            if self._behaviours[j][0] < 2:
                continue
            d = self.distance(m, self._model(j))
            if d < bd:
                best, bd = j + 1, d
        return best, bd

    def _new_behaviour(self) -> int:
        d = self._d
        self._behaviours.append([0, np.zeros(d), np.zeros((d, d)), None])
        self.stats.new_behaviours += 1
        return len(self._behaviours)

    def _confidence(self, matched: bool, dist: float) -> float:
        if not math.isfinite(dist):
            return 0.0
        c = 1.0 - dist / self.threshold if matched else 1.0 - self.threshold / max(dist, 1e-12)
        return float(min(1.0, max(0.0, c)))

    def _emit(self, msg: IdentityDecision) -> None:
        self.events.append(msg)
        self.history.append(msg)

    def _attempt(self, seg: _Segment, end: int, frame: int) -> None:
        """Decide ``seg`` at block ``end`` - unless a library would call it ``unknown``
        before ``name_after_s`` of it are summed: then the decision waits for them (a
        longer window names more segments; a name given sooner stands).  Before
        ``decide_after_s`` (the first look, ``first_name_after_s``) only a name within the
        threshold times ``first_name_scale`` decides it; else it waits for
        ``decide_after_s``."""
        if self.namer is None or end - seg.block >= self._named_blocks:
            self._decide(seg, end, frame)
            return
        first = end - seg.block < self._id_blocks
        naming = self.namer.name(seg.boundary, frame,
                                 self.first_name_scale if first else 1.0)
        if naming[0] == UNKNOWN:
            seg.decide_block = seg.block + (self._id_blocks if first else self._named_blocks)
            self.stats.name_waits += int(not first)
            self.stats.first_look_waits += int(first)
            return
        self.stats.first_look_names += int(first)
        self._decide(seg, end, frame, naming)

    def _decide(self, seg: _Segment, end: int, frame: int,
                naming: tuple[str, float] | None = None) -> None:
        end = min(end, seg.block + self.max_blocks + self._skip_blocks)
        w = self._window(seg, end, self._skip_blocks)
        j, dist = self._nearest(w) if w is not None else (0, math.inf)
        matched = j > 0 and dist <= self.threshold
        if not matched:
            j = self._new_behaviour()
        seg.behaviour, seg.created = j, not matched
        self.stats.decisions += 1
        if self.namer is not None:
            seg.library_name, seg.name_distance = naming or self.namer.name(seg.boundary,
                                                                             int(frame))
            self.stats.posture_namings += int(self.namer.last_by_posture)
            if self.namer.last_scale > 1.0:
                self.stats.names_scaled += 1
                self.stats.largest_scale = max(self.stats.largest_scale, self.namer.last_scale)
            self.namer.decided(seg.name_distance)
            seg.name = self._held_name(seg, seg.library_name)
            if seg.name == UNKNOWN:
                self.stats.names_unknown += 1
            else:
                self.stats.named += 1
        self._emit(IdentityDecision(seg.index, seg.boundary, j, int(frame),
                                    self._confidence(matched, dist), dist, new=not matched,
                                    name=seg.name, name_distance=seg.name_distance))

    def _held_name(self, seg: _Segment, name: str, count: bool = True) -> str:
        """``name`` for ``seg``, or ``unknown`` when other ids hold it (``NameHolders``;
        counted in ``names_contested`` when ``count``)."""
        if name in ("", UNKNOWN) or self._holders.grant(seg, name):
            self.stats.names_claimed = self._holders.claimed
            return name
        self.stats.names_contested += int(count)
        return UNKNOWN

    @property
    def exclusive_names(self) -> bool:
        """A name only other ids hold is sent as ``unknown`` (module doc)."""
        return self._holders.exclusive

    def _finish(self, seg: _Segment, end: int, frame: int) -> None:
        """The segment ended at block ``end``: correct it if clearly wrong, then pool its
        statistics into its behaviour's model."""
        w = self._window(seg, end)
        if w is None:
            return
        sent = seg.behaviour
        known = [j for j in range(len(self._behaviours))
                 if j + 1 != sent or not seg.created]
        m = fit(w)
        dists = {j + 1: self.distance(m, self._model(j)) for j in known
                 if self._behaviours[j][0] >= 2}
        final = sent
        if seg.created:
            if dists:
                j = min(dists, key=dists.get)
                if dists[j] <= self.threshold / self.margin:
                    final = j
        elif dists.get(sent, math.inf) > self.threshold * self.margin:
            j = min(dists, key=dists.get)
            final = j if dists[j] <= self.threshold else 0
        if final != sent:
            if final == 0:
                final = self._new_behaviour()
            self.stats.corrections += 1
            d = dists.get(final, math.inf)
            seg.behaviour = final
            if seg.name == UNKNOWN and seg.library_name not in ("", UNKNOWN):
                # its name was contested; corrected to an id that holds it, it gets it back
                seg.name = self._held_name(seg, seg.library_name, count=False)
                self.stats.names_restored += int(seg.name != UNKNOWN)
            self._emit(IdentityDecision(seg.index, seg.boundary, final, int(frame),
                                        self._confidence(final in dists, d), d,
                                        correction=True, previous=sent,
                                        new=final not in dists, name=seg.name,
                                        name_distance=seg.name_distance))
        b = self._behaviours[final - 1]
        b[0] += w.n
        b[1] = b[1] + w.n * w.mean
        b[2] = b[2] + w.scatter + w.n * np.outer(w.mean, w.mean)
        b[3] = None

    def close(self, frame: int) -> None:
        """End of the stream (offline use): decide the open segment if it is not decided
        yet, then finish it as a cut would (its one correction, if any).  The live loop
        never calls this; its last segment stays open."""
        seg = self._seg
        if seg is None or self._d == 0:
            return
        end = max(self._complete(), seg.block + 1)
        if seg.behaviour == 0:
            self._decide(seg, end, frame)
        self._finish(seg, end, frame)
        self._seg = None

    # ------------------------------------------------------------------ results
    def segment_names(self, corrected: bool = False) -> dict[int, tuple[int, str]]:
        """{segment: (boundary, library name)} of the decisions sent (library only); with
        ``corrected``, the name of a segment's correction when it has one (a contested name
        given back, module doc)."""
        return {m.segment: (m.boundary, m.name) for m in self.history
                if corrected or not m.correction}

    def frame_labels(self, n_frames: int, corrected: bool = False) -> np.ndarray:
        """Per-frame behaviour ids (0 before the first decision) from the messages sent:
        each segment's decided id (``corrected``: its last id) from its boundary on."""
        out = np.zeros(n_frames, dtype=np.int64)
        ids: dict[int, tuple[int, int]] = {}
        for m in self.history:
            if m.correction and not corrected:
                continue
            ids[m.segment] = (m.boundary, m.behaviour)
        segs = sorted(ids.values())
        for i, (b, j) in enumerate(segs):
            e = segs[i + 1][0] if i + 1 < len(segs) else n_frames
            out[max(0, b if i else 0):max(0, e)] = j
        return out


def tracker_options(config: Any) -> dict[str, Any]:
    """The ``IdentityTracker`` keyword arguments a session configuration's ``[identity]``
    section sets (decision time, threshold, naming wait, exclusive names and their claim
    margin, the operator's factor on the library's threshold)."""
    return {"decide_after_s": float(config["identity.decide_after_s"]),
            "threshold": float(config["identity.threshold"]),
            "name_after_s": float(config["identity.name_after_s"]),
            "exclusive_names": bool(config["identity.exclusive_names"]),
            "claim_margin": float(config["identity.claim_margin"]),
            "name_threshold_scale": float(config["identity.name_threshold_scale"]),
            "first_name_after_s": float(config["identity.first_name_after_s"]),
            "first_name_scale": float(config["identity.first_name_scale"]),
            "library_threshold": float(config["identity.library_threshold"]) or None}


def tracker_from_config(config: Any, frame_rate: float, method: str,
                        profile: str | None = None, dims: int | None = None
                        ) -> IdentityTracker | None:
    """The tracker of a session configuration's ``[identity]`` section (None when off).
    ``identity.behaviours`` (a library file, when the key exists and is set) is loaded and
    checked against the session's feature ``profile``/``dims`` when given
    (``rtseg.library.behaviours.LibraryError``, one line, when it does not match)."""
    if not config["identity.enabled"]:
        return None
    library = None
    path = config.values.get("identity", {}).get("behaviours", "")
    if path:
        from rtseg.library.file import load
        library = load(path, profile, dims)
    return IdentityTracker(frame_rate, method, library=library, **tracker_options(config))
