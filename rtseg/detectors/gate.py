"""Same-behaviour gate: a detector's cut is sent only when the motion after it is another
behaviour than the motion just before it.

A change detector fires wherever the motion's statistics change.  Inside one behaviour
that has phases - an arm raised and lowered, a pause in a drink, the arm circles of an
exercise reversing - that is not a behaviour change, and the identity tracker
(``rtseg.identity.tracker``) then gives the new segment the id of the one before it.  The gate asks
that question of every cut before it goes out:

- a cut at boundary b (frame numbers of the detector: frames since its creation) is held
  until ``decide_after`` frames from b have arrived (at once when it arrives later, as
  most full-look cuts do);
- the window after it, [b + ``skip``, decision frame) (from b when fewer than 1 s would
  remain; the deciding frame's own row is left out, so the decision can be worked out
  before that frame arrives: ``prepare_decision``), at most ``max_window`` frames, is
  compared with the ``max_window`` frames
  before b (no further back than the last cut sent or the last restart) by the identity
  tracker's distance (``window_models.behaviour_distance``: PCA x PPCA window models,
  stated for 8 dimensions);
- at or below ``threshold`` the two windows are one behaviour: the cut is dropped
  (``dropped`` counts it, the log says so); above it the cut is sent with ``detected_at``
  = the deciding frame.

The windows and decision time are the identity tracker's own (decision after 1.5 s, 0.5 s
skipped, windows of at most 3 s); the threshold is the detector's ``gate_threshold``
(3.5, ``GATE_THRESHOLD``, chosen leave-one-person-out in ``benchmarks/lopo.py``'s grid;
``--params full`` and ``fast`` keep 4.0; the tracker's own ids threshold is 5.0).  A
dropped cut is handed to ``on_drop`` (the detector forgets it).  Cost: one row copy per
frame into a ring of ``ring`` frames (none of its own when it reads the contrast
detector's ring, ``share``); per held cut two window statistics and two
model fits (about 0.5 ms, once per cut).  A restart (gap) decides the held cuts on the
frames that arrived before it.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import replace
from typing import Callable

import numpy as np

from rtseg.detectors.base import Cut
from rtseg.detectors.window_models import (DEFAULT_ID_SKIP_S, DEFAULT_MAX_WINDOW_S,
                                          MIN_WINDOW_S, WindowModel, WindowStats,
                                          behaviour_distance, fit)

log = logging.getLogger("rtseg.detectors")

#: the gate's decision time (1.5 s of the new segment: sooner than the identity tracker's
#: ids, rtseg.identity.tracker, which wait 2.5 s by default), and the tracker's skipped
#: start, longest window and the least that must remain after the skip, s
GATE_DECIDE_S, GATE_SKIP_S = 1.5, DEFAULT_ID_SKIP_S
GATE_WINDOW_S, GATE_MIN_AFTER_S = DEFAULT_MAX_WINDOW_S, MIN_WINDOW_S
#: the shipped ``[contrast] gate_threshold`` (config/detectors.toml; chosen in
#: benchmarks/lopo.py's grid, docs/live_detector.md)
GATE_THRESHOLD = 3.5


class SameBehaviourGate:
    """Holds a detector's cuts and sends those that change behaviour (module docstring).
    Lengths in frames; frame numbers are the detector's (0-based, since its creation).

    min_after: frames that must remain after ``skip`` for the skip to apply (1 s at 120 Hz).
    ring: frames of rows kept (at least the detector's longest delay + ``max_window``).
    """

    def __init__(self, threshold: float = GATE_THRESHOLD, decide_after: int = 180,
                 skip: int = 60, max_window: int = 360, min_after: int = 120, ring: int = 1200,
                 reference_dims: int = 8, fit_args: dict | None = None,
                 on_drop: Callable[[int], None] | None = None) -> None:
        if not threshold > 0:
            raise ValueError(f"gate threshold must be positive, got {threshold}")
        if ring < max_window + decide_after:
            raise ValueError(f"gate ring ({ring} frames) shorter than its windows")
        self.threshold = float(threshold)
        self.decide_after = int(decide_after)
        self.skip = int(skip)
        self.max_window = int(max_window)
        self.min_after = max(2, int(min_after))
        self.reference_dims = int(reference_dims)
        self.fit_args = dict(fit_args or {})
        self.ring = int(ring)
        self._rows: np.ndarray | None = None
        self._t = 0                      # frames pushed (the next frame's number)
        self._held: deque[Cut] = deque()
        self._out: deque[Cut] = deque()
        self._floor = 0                  # before windows start no earlier than this frame
        self.dropped = 0
        self.sent = 0
        #: ((a, b), model) of the window before a cut fitted ahead (``prepare``)
        self._before: tuple[tuple[int, int], WindowModel] | None = None
        #: ((lo, hi, a, b), distance) of a decision worked out ahead (``prepare_decision``)
        self._ready: tuple[tuple[int, int, int, int], float] | None = None
        #: decisions that found their distance, or their window before, made ahead
        self.made_ahead = 0
        #: (boundary, distance, sent) of every decision, for plots and benchmarks
        self.decisions: list[tuple[int, float, bool]] = []
        #: called with the frame of every cut dropped (the detector forgets it: a dropped
        #: cut does not keep a later change at bay)
        self.on_drop = on_drop

    def push(self, t: int, x: np.ndarray) -> None:
        """The row of frame ``t`` (frames come in order)."""
        if self._rows is None:
            self._rows = np.zeros((self.ring, len(x)))
        self._rows[t % self.ring] = x
        self._t = t + 1

    def frame(self, t: int, x: np.ndarray, cut: Cut | None) -> Cut | None:
        """``push(t, x)``, ``hold(cut)`` when there is one, then ``poll()``: the detector's
        one call a frame (``poll`` only when a cut is held or waits)."""
        self.push(t, x)
        return self.tick(t, cut)

    def share(self, rows: np.ndarray) -> None:
        """Read the rows from ``rows`` (``ring`` x dims), a ring the caller writes frame t
        into at ``t % ring`` before calling ``tick`` (one row copy a frame for both)."""
        if len(rows) != self.ring:
            raise ValueError(f"shared ring of {len(rows)} rows, the gate's is {self.ring}")
        self._rows = rows

    def tick(self, t: int, cut: Cut | None) -> Cut | None:
        """``frame(t, x, cut)`` when frame t's row is already in the shared ring (``share``)."""
        self._t = t + 1
        if cut is not None:
            self._held.append(cut)
        return self.poll() if self._held or self._out else None

    def quiet_frames(self, t: int) -> int | None:
        """Of the frames from number ``t`` on (the next one the detector feeds), how many
        come before one that decides or sends a cut: 0 when a cut waits to go out, None
        when no cut is held."""
        if self._out:
            return 0
        if not self._held:
            return None
        return max(0, self._held[0].frame + self.decide_after - t)

    def hold(self, cut: Cut) -> None:
        """A cut of the detector, to be decided once its new segment has arrived."""
        self._held.append(cut)

    def poll(self) -> Cut | None:
        """After each frame: decide the held cuts whose time has come (in order); the next
        cut to send, if any (two in one frame: the second goes out with the next)."""
        while self._held and self._t - 1 >= self._held[0].frame + self.decide_after:
            self._decide(self._held.popleft(), self._t - 1)
        if not self._out:
            return None
        cut = self._out.popleft()
        return replace(cut, detected_at=max(cut.detected_at, self._t - 1))

    def next_decision(self, t: int) -> int | None:
        """The frame of the held cut that frame ``t`` decides, if any."""
        if self._held and self._held[0].frame + self.decide_after <= t:
            return self._held[0].frame
        return None

    def prepare(self, b: int) -> bool:
        """Fit now the window before a cut at ``b`` decided now (the live loop's work
        ahead, ``ContrastDetector.ahead``): a later decision whose window before is the
        same frames uses it instead of fitting it again.  False when there was nothing
        to fit (no rows, too few frames, already fitted)."""
        if self._rows is None or b > self._t:
            return False
        a = self._windows(b, self._t, self._t)[2]
        if b - a < 2 or self._fitted_before(a, b) is not None:
            return False
        self._before = ((a, b), fit(self._stats(a, b), **self.fit_args))
        return True

    def prepare_decision(self, b: int, t: int) -> bool:
        """Work out now the distance a decision on frame ``t`` (the next frame to come)
        of a cut at ``b`` would find: its windows end before frame t, so they have
        arrived; the decision, if it comes, only compares the distance with the
        threshold.  False when there was nothing to do (no rows, already done)."""
        if self._rows is None or t != self._t:
            return False
        lo, hi, a = self._windows(b, t, t + 1)
        key = (lo, hi, a, b)
        if self._ready is not None and self._ready[0] == key:
            return False
        self._ready = (key, self._distance(lo, hi, a, b))
        return True

    def restart(self) -> None:
        """A gap: decide every held cut on the frames so far; later windows start after."""
        while self._held:
            self._decide(self._held.popleft(), self._t - 1, end=self._t)
        self._floor = self._t

    # ------------------------------------------------------------------ internals
    _span: np.ndarray | None = None            # a window's rows gathered from the ring

    def _stats(self, lo: int, hi: int) -> WindowStats:
        if self._span is None or self._span.shape[1] != self._rows.shape[1]:
            self._span = np.empty((self.max_window, self._rows.shape[1]))
        rows = np.take(self._rows, np.arange(lo, hi) % self.ring, axis=0,
                       out=self._span[:hi - lo])       # a window's rows, in order
        return WindowStats.of(rows)

    def _windows(self, b: int, end: int, pushed: int) -> tuple[int, int, int]:
        """(lo, hi, a): the window after a cut at ``b``, [lo, hi), on the rows before
        frame ``end``, and the start of its window before, [a, b), with ``pushed``
        frames pushed (the ring holds the last ``ring`` of them)."""
        oldest = max(self._floor, pushed - self.ring)
        lo = b + self.skip if end - (b + self.skip) >= self.min_after else b
        return lo, min(end, lo + self.max_window), max(b - self.max_window, oldest)

    def _distance(self, lo: int, hi: int, a: int, b: int) -> float:
        """The distance between the windows [lo, hi) and [a, b) (inf when either holds
        fewer than two frames); the window before's fit made ahead (``prepare``) is
        used when it is of the same frames."""
        if hi - lo < 2 or b - a < 2 or self._rows is None:
            return math.inf
        after = fit(self._stats(lo, hi), **self.fit_args)
        before = self._fitted_before(a, b)
        if before is None:
            before = fit(self._stats(a, b), **self.fit_args)
        return behaviour_distance(after, before, self.reference_dims)

    def _fitted_before(self, a: int, b: int) -> WindowModel | None:
        """The window [a, b)'s model when ``prepare`` fitted it, else None."""
        held = self._before
        return held[1] if held is not None and held[0] == (a, b) else None

    def _decide(self, cut: Cut, now: int, end: int | None = None) -> None:
        """Decide ``cut`` on frame ``now`` from the rows before frame ``end`` (``now``
        itself: the deciding frame's own row is not used, so the work can be done
        before it arrives, ``prepare_decision``)."""
        b = cut.frame
        lo, hi, a = self._windows(b, now if end is None else end, self._t)
        key = (lo, hi, a, b)
        if self._ready is not None and self._ready[0] == key:
            d = self._ready[1]
            self.made_ahead += 1
        else:
            if self._fitted_before(a, b) is not None:
                self.made_ahead += 1
            d = self._distance(lo, hi, a, b)
        same = d <= self.threshold
        self.decisions.append((b, d, not same))
        if same:
            self.dropped += 1
            log.info("%s cut at frame %d dropped: the motion after it is the behaviour "
                     "before it (distance %.2f <= %.2f; %d dropped so far)",
                     cut.method, b, d, self.threshold, self.dropped)
            if self.on_drop is not None:
                self.on_drop(b)
            return
        self.sent += 1
        self._floor = max(self._floor, b)
        self._out.append(replace(cut, detected_at=max(cut.detected_at, now)))
