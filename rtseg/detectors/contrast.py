"""Causal two-window contrast detector: rtseg's default live segmenter (not in the paper).

At every position c on a grid of ``step`` frames, once the ``after`` frames from c on have
arrived, the motion just after c is compared with the motion just before it:

    A0 = [c-2w, c-w)   A = [c-w, c)   B = [c, c+after)          (w = before, frames)

    contrast(c) = Dpca(A, B) / Dpca(A0, A),  stated as 1 + (contrast - 1) x sqrt(d_eff / reference_dims)

``Dpca`` is the PCA window distance of ``rtseg.detectors.window_models`` (Barbič et al.
2004, 3.1), d_eff the before window's varying directions.  Near a segment's start (the
stream's, or after a gap: ``restart()``) w shrinks to half the frames so far, down to
``min_before``.  The profile's maxima are picked causally (``rtseg.detectors.peaks``:
at least ``threshold``, ``min_gap`` apart, confirmed after at most ``hold`` frames or once
the profile drops below ``drop`` x the maximum) and each is sent once, as a cut at c.
So a cut is known ``after`` frames plus its confirmation after c (2 s + at most 1 s).
With the short-look confirmation on (``confirm_reach_s`` > 0, ``rtseg.detectors.confirm``;
on by default, off in ``config/full.toml``) a maximum is also sent as soon as the
positions after it, scored on after windows cut short at the newest block, score lower
than it did on the same lengths: at its own full look when it stands clear.

Stages after a maximum, each its own module (all described, with the measurements that
chose them, in docs/live_detector.md): the relative floor (``relative_floor``,
``rtseg.detectors.relative``), the same-behaviour gate (``gate_threshold``,
``rtseg.detectors.gate``: the cut waits for ``gate_decide`` frames of its new segment),
cut placement (``place_radius``, ``rtseg.detectors.placement``); the residual floor
(``residual_floor``, ``rtseg.detectors.residual``) bounds every window model's own error,
the bounded before windows (``bound_before``) keep A0 and A inside the behaviour since the
last cut sent, and the pre-look (``pre_after`` > 0, ``rtseg.detectors.prelook``; on by
default and in ``config/fast.toml``, off in ``config/full.toml``) also scores each position
with a shorter after window and sends a strong change that stands clear there at once.
A cut the gate or
the floor drops is forgotten (it keeps no later maximum away).

Work per frame: each ``step``-frame block's statistics are summed once (one BLAS call),
windows are differences of prefix sums, each window's PCA model is fitted once
(``window_models.fit_pca``, warm-started; ``rtseg.detectors.block_windows``) and reused while in use, and the work a completed
block makes possible is queued and done one step a frame (``_run_steps``), so no frame
fits more than one window; ``detected_at`` says which frame's arrival produced a cut.
``ahead()`` (the live loop, between frames) places the maximum waiting for confirmation and
prepares the gate's decision, so the frame that sends the cut finds that work done; it
never changes a cut, and offline nothing calls it.  Cost: ``benchmarks/speed.py``.

Frames are numbered from the detector's creation.  ``Cut.frame`` = c (placed),
``detected_at`` = the frame whose arrival confirmed it, ``score`` = the contrast at c (for
a cut the pre-look sent, its value on the pre-look's after window), ``confidence`` = 1 - threshold / score (0
at the threshold, -> 1 far above it).  When both looks send a cut on the same frame (two
changes at least ``min_gap`` apart), the second goes out with the next frame; a restart
drops it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace
from typing import Any, Mapping

import numpy as np

from rtseg.detectors.base import Cut, OnlineDetector
from rtseg.detectors.confirm import ShortConfirmation
from rtseg.detectors.prelook import PreLook
from rtseg.detectors.placement import PLACE_MARGIN_S, PLACE_STRIDE_S, RingPlacement
from rtseg.detectors.sender import CutSender, SentPeak
from rtseg.detectors.relative import ENERGY_SPAN, EnergyChanges, RelativeFloor
from rtseg.detectors.residual import RESIDUAL_LOOKS, ResidualFloor
from rtseg.detectors.gate import (GATE_DECIDE_S, GATE_MIN_AFTER_S, GATE_SKIP_S, GATE_WINDOW_S,
                                  SameBehaviourGate)
from rtseg.detectors.block_windows import BlockWindows
from rtseg.detectors.window_models import PcaWindow, pca_distance


_ndarray, _F8, _add_reduce, _isfinite = np.ndarray, np.dtype(np.float64), np.add.reduce, math.isfinite
try:    # np.vdot without its dispatch layer; unlike ndarray.dot it does not warn on overflow
    from numpy._core._multiarray_umath import vdot as _vdot
except ImportError:  # pragma: no cover - numpy < 2
    _vdot = np.vdot


class ContrastDetector(OnlineDetector):
    """Streaming two-window contrast detector.  All lengths in frames (see module docstring)."""

    name = "contrast"
    frame_origin = "creation"

    def __init__(self, step: int = 15, before: int = 360, after: int = 210,
                 min_before: int = 180, threshold: float = 2.0, hold: int = 120,
                 min_gap: int = 240, drop: float = 0.5, pca_energy: float = 0.9,
                 ppca_energy: float = 0.95, noise_floor: float = 1e-6,
                 reference_dims: int = 48, gate_threshold: float = 0.0, gate_decide: int = 180,
                 gate_skip: int = 60,
                 gate_window: int = 360, gate_min_after: int = 120,
                 relative_floor: float = 0.0, residual_floor: float = 0.0,
                 bound_before: bool = False,
                 place_radius: int = 0, place_window: int = 240,
                 place_ridge: float = 0.01, place_stride: int = 4, place_margin: int = 30,
                 confirm_reach: int = 0, confirm_shortest: int = 120,
                 confirm_level: float = 0.0, confirm_ratio: float = 1.0,
                 confirm_clear: float = 0.0,
                 pre_after: int = 0, pre_level: float = 4.0, pre_ratio: float = 1.0,
                 keep_trace: bool = False) -> None:
        if step < 1:
            raise ValueError(f"step must be >= 1 frame, got {step}")
        for key, v in (("before", before), ("after", after), ("min_before", min_before)):
            if v < 2 * step:
                raise ValueError(f"{key} must be at least two steps ({2 * step} frames), got {v}")
        if min_before > before:
            raise ValueError(f"min_before ({min_before}) must not exceed before ({before})")
        if not (threshold > 0 and math.isfinite(threshold)):
            raise ValueError(f"threshold must be positive, got {threshold}")
        self.step = int(step)
        self.wa = max(1, int(round(before / step)))        # before window, blocks
        self.wb = max(1, int(round(after / step)))         # after window, blocks
        self.wmin = max(1, int(round(min_before / step)))  # shortest before window, blocks
        self.threshold = float(threshold)
        if reference_dims < 1:
            raise ValueError(f"reference_dims must be >= 1, got {reference_dims}")
        self.reference_dims = int(reference_dims)
        self.fit_args = dict(pca_energy=float(pca_energy), ppca_energy=float(ppca_energy),
                             noise_floor=float(noise_floor))
        self.peaks = CutSender(threshold, hold=int(hold), min_gap=int(min_gap), drop=drop)
        #: before windows never reach back past the last cut sent (module doc)
        self.bound_before = bool(bound_before)
        #: cut placement (``rtseg.detectors.placement``): radius 0 = off
        if place_radius < 0 or place_window < 1 or place_ridge < 0:
            raise ValueError("place_radius and place_ridge must be >= 0, place_window >= 1")
        self.place_radius, self.place_window = int(place_radius), int(place_window)
        self.place_ridge, self.place_stride = float(place_ridge), max(1, int(place_stride))
        self.place_margin = max(2, int(place_margin))
        #: short-look confirmation of the full look's maxima (``rtseg.detectors.confirm``)
        self.confirm = ShortConfirmation(
            int(round(confirm_reach / step)) if confirm_reach else 0,
            max(2, int(round(confirm_shortest / step))), confirm_level, confirm_ratio,
            confirm_clear, self.wa)
        if pre_after and not 2 * step <= pre_after < after:
            raise ValueError(f"pre_after must be 0 (off) or at least two steps and shorter "
                             f"than after ({after} frames), got {pre_after}")
        #: the pre-look's sooner sends of strong changes (``rtseg.detectors.prelook``)
        self.pre = PreLook(int(round(pre_after / step)) if pre_after else 0, pre_level,
                           pre_ratio, self.confirm.reach, self.confirm.shortest)
        self.keep_trace = keep_trace
        self.trace: list[tuple[int, float, float]] = []
        #: pre-look values when keep_trace: (position, value, frame that made it known)
        self.trace_pre: list[tuple[int, float, int]] = []
        self.rejected_frames = 0
        #: the floor set by the stream's recent changes (``rtseg.detectors.relative``)
        self.relative = RelativeFloor(relative_floor)
        #: the floor under the models' own residuals (``rtseg.detectors.residual``); it
        #: outlives restarts
        self.residual = ResidualFloor(residual_floor, RESIDUAL_LOOKS)
        #: full looks remembered for it: a maximum is sent at most ``hold`` frames after
        #: its value is known
        self._energy_len = int(hold) // self.step + 4
        #: the same-behaviour gate (``rtseg.detectors.gate``), None when off
        self.gate: SameBehaviourGate | None = None
        if gate_threshold > 0:
            self.gate = SameBehaviourGate(
                gate_threshold, decide_after=gate_decide, skip=gate_skip,
                max_window=gate_window, min_after=gate_min_after,
                ring=self.delay_frames + gate_decide + gate_window + 2 * self.step,
                fit_args=self.fit_args, on_drop=self.peaks.forget)
        self._t = 0
        #: ring of the newest frames (the blocks, placement and the gate read it)
        self._rows: np.ndarray | None = None
        self._shared = False                   # the gate reads ``_rows`` (``_alloc``)
        self._dim: int | None = None
        self._buf: np.ndarray | None = None
        #: the prefix-sum ring and window models (``rtseg.detectors.block_windows``)
        self._windows: BlockWindows | None = None
        self.restart()

    @classmethod
    def from_params(cls, p: Mapping[str, Any], frame_rate: float,
                    keep_trace: bool = False) -> "ContrastDetector":
        """From ``[contrast]`` parameters in seconds (``config/detectors.toml``)."""
        from rtseg.detectors.base import frames
        pre = p.get("pre_after_s", 0.0)
        if pre and pre >= p["after_s"]:
            raise ValueError(f"pre_after_s ({pre}) must be shorter than after_s "
                             f"({p['after_s']}): the pre-look sends before the full look")
        if pre and not p.get("confirm_reach_s"):
            raise ValueError(f"pre_after_s ({pre}) needs confirm_reach_s > 0: the positions "
                             f"after a pre-look's maximum are checked that far")
        step = frames(p["step_s"], frame_rate)
        return cls(step=step, before=frames(p["before_s"], frame_rate),
                   after=frames(p["after_s"], frame_rate),
                   min_before=frames(p["min_before_s"], frame_rate),
                   threshold=p["threshold"], hold=frames(p["hold_s"], frame_rate),
                   min_gap=frames(p["min_gap_s"], frame_rate), drop=p["drop"],
                   pca_energy=p["pca_energy"], ppca_energy=p["ppca_energy"],
                   noise_floor=p["noise_floor"], reference_dims=p["reference_dims"],
                   gate_threshold=p["gate_threshold"],
                   gate_decide=frames(GATE_DECIDE_S, frame_rate),
                   gate_skip=frames(GATE_SKIP_S, frame_rate),
                   gate_window=frames(GATE_WINDOW_S, frame_rate),
                   gate_min_after=frames(GATE_MIN_AFTER_S, frame_rate),
                   relative_floor=p.get("relative_floor", 0.0),
                   residual_floor=p.get("residual_floor", 0.0),
                   bound_before=bool(p.get("bound_before", False)),
                   place_radius=frames(p["place_radius_s"], frame_rate) if p.get("place_radius_s") else 0,
                   place_window=frames(p.get("place_window_s", 2.0), frame_rate),
                   place_ridge=p.get("place_ridge", 0.01),
                   place_stride=frames(PLACE_STRIDE_S, frame_rate),
                   place_margin=frames(PLACE_MARGIN_S, frame_rate),
                   confirm_reach=(frames(p["confirm_reach_s"], frame_rate)
                                  if p.get("confirm_reach_s") else 0),
                   confirm_shortest=frames(p.get("confirm_after_s", 1.0), frame_rate),
                   confirm_level=p.get("confirm_level", 0.0),
                   confirm_ratio=p.get("confirm_ratio", 1.0),
                   confirm_clear=p.get("confirm_clear", 0.0),
                   pre_after=(frames(p["pre_after_s"], frame_rate)
                              if p.get("pre_after_s") else 0),
                   pre_level=p.get("pre_level", 4.0), pre_ratio=p.get("pre_ratio", 1.0),
                   keep_trace=keep_trace)

    @property
    def delay_frames(self) -> int:
        """Longest delay from a cut's frame to the frame that sends it."""
        d = self.wb * self.step + self.peaks.full.hold + self.step
        return d if self.gate is None else max(d, self.gate.decide_after)

    @property
    def quiet_frames(self) -> int:
        """How many of the next frames certainly send no cut (``OnlineDetector``).  A cut
        goes out only on a frame that runs a look at a position, sends a queued cut or
        decides a cut the gate holds.  Each frame runs one queued step (while no more than
        a block's frames of them wait); the frame that completes a block queues a window
        fit first and runs it, then the after window's fit and
        the look.  So with no step queued the frames up to the block's completion are
        quiet, and the one after it too (at most ``step`` + 1);
        with steps queued, the frames that run the fits before the first look."""
        if self._out or self._dim is None:
            return 0
        steps = self._steps
        if not steps:
            q = self.step - self._fill + 1
        elif len(steps) > self.step:
            return 0
        else:
            model = self._windows.model
            q = 0
            for fn, _args in steps:
                if fn != model:
                    break
                q += 1
        if self.gate is not None:
            g = self.gate.quiet_frames(self._t)
            if g is not None:
                q = min(q, g)
        return max(q, 0)

    # ------------------------------------------------------------------ state
    def restart(self) -> None:
        """Forget the current segment; the next frame starts a new one."""
        self._seg0 = self._t                 # first frame of the segment
        self._nb = 0                         # whole blocks in the segment
        self._fill = 0                       # frames in the block being filled
        self._ref: np.ndarray | None = None  # the segment's first frame (sums are about it)
        #: the before windows' models of the newest looked-at positions (short looks)
        self._befores: dict[int, tuple[PcaWindow, PcaWindow]] = {}
        #: work queued by completed blocks, one step a frame (``_run_steps``)
        self._steps: deque[tuple[Any, tuple]] = deque()
        self._last_sent: int | None = None   # block position of the last cut sent
        self._last_placed: int | None = None  # frame of the last cut sent, as placed
        self.peaks.reset()
        self.confirm.reset()
        self._out: deque[SentPeak] = deque()  # cuts to send (a queued one is dropped)
        #: the energy change of the newest full looks (``relative.EnergyChanges``)
        self._energy = EnergyChanges(ENERGY_SPAN * self.wa, self._energy_len)
        if self._windows is not None:          # the ring restarts at block 0
            self._windows.reset()
        if self.gate is not None:
            self.gate.restart()

    def _alloc(self, dim: int) -> None:
        self._dim = dim
        self._buf = np.empty((self.step, dim))  # a completed block, about the segment's start
        # one ring of rows, written once a frame: the block being filled, the rows cut
        # placement may look at (``_place_len``) and, when it holds at least as many, the
        # gate's ring (its own length, so it reads what its own ring would hold)
        self._place_len = self.place_window + self.delay_frames + self.step
        n = max(self._place_len if self.place_radius else 0, self.step)
        self._shared = self.gate is not None and self.gate.ring >= n
        if self._shared:
            n = self.gate.ring
        self._rows = np.zeros((n, dim))
        self._ringlen = n
        if self._shared:
            self.gate.share(self._rows)
        if self.place_radius:
            self._placement = RingPlacement(self._rows, self.place_window, self._place_len,
                                            self.place_radius, self.place_stride,
                                            self.place_ridge, self.place_margin)
        # prefixes back to the oldest window a look reads: A0 of the full look's position,
        # or of the pre-look's earliest (``pre.after`` + ``pre.reach`` back)
        cap = 2 * self.wa + max(self.wb, self.pre.after + self.pre.reach) + 2
        self._windows = BlockWindows(dim, self.step, cap, self.fit_args["pca_energy"])

    # ------------------------------------------------------------------ streaming
    def update(self, x: np.ndarray) -> Cut | None:
        """Feed one frame (1-D feature vector); a Cut when a change is confirmed."""
        # a float64 vector of the right width is checked here (``_admit``'s checks, fewer
        # calls: a finite x.x implies a finite sum, and only when it is not is the sum
        # taken); anything else goes through ``_admit``
        if (x.__class__ is _ndarray and x.dtype is _F8 and x.ndim == 1
                and x.shape[0] == self._dim):
            if not _isfinite(_vdot(x, x)) and not _isfinite(_add_reduce(x)):
                return self._reject(x)
        else:
            x = self._admit(x)
            if x is None:
                return None
        t = self._t                                  # this frame's number
        self._t = t + 1
        if self._ref is None:
            self._ref = x.copy()
        self._rows[t % self._ringlen] = x
        fill = self._fill + 1
        if fill == self.step:
            self._fill = 0
            self._block_done(t)
        else:
            self._fill = fill
        if self._steps:
            self._run_steps()
        # two cuts sent on one frame (two changes >= min_gap apart): the second goes out
        # with the next frame, and its detected_at says so
        cut = self._cut(self._out.popleft(), t) if self._out else None
        if cut is not None:
            f = cut.frame
            energy = self._energy.at((f - self._seg0) // self.step)
            if not self.relative.admits(cut.score, energy, f):
                self.peaks.forget(f)                 # as a cut the gate drops
                cut = None
        gate = self.gate
        if gate is not None:
            cut = gate.tick(t, cut) if self._shared else gate.frame(t, x, cut)
        if cut is not None:
            self.relative.sent(cut.score)
            # the windows follow the detector's own grid position, not the placed frame
            self._last_sent = (cut.frame - self._seg0) // self.step
            if self.place_radius:                  # only cuts the gate lets through
                cut = self._placed(cut)
                self._last_placed = cut.frame
        return cut

    def _block_done(self, t: int) -> None:
        """A block (frames up to t) is complete: its sums join the prefix ring, and the work
        it makes possible is queued as steps of about one window fit each (``_run_steps``)."""
        rows, ref, B = self._rows, self._ref, self._buf   # about the segment's first frame
        hi = t % self._ringlen + 1
        lo = hi - self.step
        if lo >= 0:
            np.subtract(rows[lo:hi], ref, out=B)
        else:                                        # the block wraps round the ring
            np.subtract(rows[lo:], ref, out=B[:-lo])
            np.subtract(rows[:hi], ref, out=B[-lo:])
        k = self._nb
        windows = self._windows
        windows.add(k, B)
        model = windows.model
        nb = self._nb = k + 1
        steps = self._steps
        # the before window of position nb (used once its after window is complete)
        if nb >= 2 * self.wmin:
            w = self._width(nb)
            steps.append((model, (nb - w, nb)))
        c = nb - self.wb                             # newest position with a whole B
        if c >= 2 * self.wmin:
            steps.append((model, (c, c + self.wb, "after")))
            steps.append((self._look_full, (c,)))
        cp = nb - self.pre.after                     # newest position the pre-look scores
        if self.pre.after and cp >= 2 * self.wmin:
            steps.append((self._look_pre, (cp,)))

    def _run_steps(self) -> None:
        """One queued step per frame (more when more than a block's frames of them wait), so
        no frame fits more than one window model: a position's profile value is known a few
        frames after its block completes, and the slow frames stay short.  Called only when
        a step waits."""
        steps = self._steps
        fn, args = steps.popleft()
        fn(*args)
        while len(steps) > self.step:
            fn, args = steps.popleft()
            fn(*args)

    def _look_full(self, c: int) -> None:
        """The contrast at block position c, known now: to the peak picker."""
        value = self._contrast(c)
        position = self._seg0 + c * self.step
        if self.keep_trace:
            self.trace.append((position, value, self.threshold))
        self.confirm.note(c, value)
        sent = self.peaks.update_full(position, value, self._t - 1)
        if sent is None and self.confirm.on:
            sent = self._confirm_short(c)
        if sent is not None:
            self._out.append(sent)

    def _confirm_short(self, c: int) -> SentPeak | None:
        """The full look's waiting maximum, sent now when the short looks after it confirm
        it (``rtseg.detectors.confirm``; c: the newest position with a full value)."""
        full = self.peaks.full
        pos = full.candidate
        if pos is None:
            return None
        cb = (pos - self._seg0) // self.step
        if not self.confirm.confirms(cb, full.candidate_value, self.threshold, c, self._nb,
                                     self.wb, self._short):
            return None
        return self.peaks.confirm_full(self._t - 1)

    def _look_pre(self, c: int) -> None:
        """The pre-look at block position c (``rtseg.detectors.prelook``): sent now when
        it stands clear."""
        v = self._short(c, self.pre.after)
        if self.keep_trace:
            self.trace_pre.append((self._seg0 + c * self.step, v, self._t - 1))
        value = self.pre.value(c, self.threshold, 2 * self.wmin, self._short, v)
        if value is not None:
            sent = self.peaks.send_now(self._seg0 + c * self.step, value, self._t - 1)
            if sent is not None:
                self._out.append(sent)

    def _cut(self, sent: SentPeak, at: int) -> Cut:
        """The Cut for a peak sent on frame ``at`` (score and confidence: see the module
        docstring)."""
        v = sent.strength
        conf = 1.0 - self.threshold / v if v > 0 else 0.0
        return Cut(frame=sent.peak.position, method=self.name,
                   confidence=float(min(max(conf, 0.0), 1.0)),
                   detected_at=at, score=float(v))

    def _placed(self, cut: Cut) -> Cut:
        """``cut`` moved to the best two-Gaussian split of the frames within
        ``place_window`` of it (``rtseg.detectors.placement``), never before the segment's
        start nor onto or before the last cut sent."""
        b = self._placement.place(cut.frame, self._t, self._seg0, self._last_placed)
        return cut if b == cut.frame else replace(cut, frame=b)

    def ahead(self) -> bool:
        """One piece of the work the frame that sends the waiting maximum would do, done
        now (the live loop calls it between frames when no frame that may send is due:
        "Work ahead" in the module docstring); False when there is none.  Changes no cut."""
        if self._dim is None:
            return False
        gate, pos, t = self.gate, self.peaks.candidate, self._t
        if gate is not None and self.quiet_frames == 0:
            # the next frame may decide a cut: the held one it decides, else the waiting
            # maximum (a look may confirm it)
            b = gate.next_decision(t)
            b = pos if b is None else b
            if b is not None and gate.prepare_decision(b, t):
                return True
        if pos is None:
            return False
        if self.place_radius and self._placement.ahead(pos, t, self._seg0, self._last_placed):
            return True
        return gate is not None and gate.prepare(pos)

    def _width(self, c: int) -> int:
        """w (blocks) of the before windows at block position c: ``before``, or half the
        blocks so far near a segment's start; with ``bound_before``, also at most half the
        blocks since the last cut sent when that is at least ``min_before`` (closer to the
        cut the windows straddle it, as without the bound)."""
        w = min(self.wa, c // 2)
        L = self._last_sent
        if self.bound_before and L is not None and (c - L) // 2 >= self.wmin:
            w = min(w, (c - L) // 2)
        return w

    def _before(self, c: int) -> tuple[PcaWindow, PcaWindow]:
        """The models of A0 and A at block position c (``_width``)."""
        w = self._width(c)
        model = self._windows.model
        return model(c - 2 * w, c - w), model(c - w, c)

    def _stated(self, k: float, a: PcaWindow) -> float:
        """A ratio k stated for ``reference_dims`` effective dimensions (module doc)."""
        return 1.0 + (max(k, 0.0) - 1.0) * math.sqrt(a.nonnull / self.reference_dims)

    def _contrast(self, c: int) -> float:
        """The contrast at block position c (see the module docstring)."""
        a0, a = self._before(c)
        if self.confirm.on:
            # a waiting maximum's before windows, for its short looks: they may be gone from
            # the models and the prefix ring by then (at most ``hold`` behind the newest)
            befores = self._befores
            befores[c] = (a0, a)
            while len(befores) > self.peaks.full.hold // self.step + 2:
                del befores[next(iter(befores))]
        b = self._windows.model(c, c + self.wb, "after")
        if c % self.wa == 0:     # models no later position uses (none starts before c - 2w)
            self._windows.prune(c + 1 - 2 * self.wa)
        last = self._last_sent          # before windows straddling the last cut left out
        self._energy.look(c, a.stats.trace / a.stats.n, b.stats.trace / b.stats.n,
                          None if last is None else last + 2 * self.wmin)
        return self._ratio(a0, a, b, self.residual.push(a.pca_own))

    def _ratio(self, a0: PcaWindow, a: PcaWindow, b: PcaWindow, f: float) -> float:
        """Dpca(A, B) / Dpca(A0, A) under the residual floor f, stated (module doc)."""
        return self._stated(pca_distance(a, b, f) / max(pca_distance(a0, a, f), 1e-300), a)

    def _short(self, c: int, length: int) -> float:
        """The contrast at block position c with an after window of ``length`` blocks
        (``rtseg.detectors.confirm``; the residual floor as it stands, no look recorded)."""
        a0, a = self._befores.get(c) or self._before(c)
        return self._ratio(a0, a, self._windows.model(c, c + length, "short"),
                           self.residual.value)


def segment_contrast(X: np.ndarray, p: Mapping[str, Any], frame_rate: float,
                     keep_trace: bool = False) -> tuple[list[Cut], list]:
    """Offline: the causal detector run over every row of X, unchanged (offline and live
    give the same cuts).  Returns (cuts, trace of (frame, contrast, threshold))."""
    det = ContrastDetector.from_params(p, frame_rate, keep_trace=keep_trace)
    return det.run(X), det.trace
