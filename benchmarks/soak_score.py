"""What ``benchmarks/soak.py --mode cuts`` scores: the long synthetic performance it plays
(``soak_script``), the primary detector's cuts and behaviour ids recorded in the session
process with memory fixed before the session starts (``CutProbe``), and their scores per
session hour against the truth (``score_by_hour``).

Frame numbers: a *message index* is the suit's running message number (the unwrapped
sequence number; frames and the info message the suit sends at start and after each
replug share it); an *absolute frame* counts the suit's frames over all loops of the take
(message index minus the info messages before it).  A session hour is 432 000 absolute
frames (120 Hz).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

RING = 1 << 14               # session indices remembered (cuts arrive within 136 s at 120 Hz)
MAX_EVENTS = 100_000         # cuts / identity messages recorded at most


def soak_script(seconds: float = 600.0, seed: int = 5, lo: float = 5.0,
                hi: float = 20.0, names: Sequence[str] | None = None) -> list[tuple[str, float]]:
    """A synthesiser script of about ``seconds``: behaviours drawn at random from ``names``
    (default: the nine of the synthesiser's default performance), never the same twice in
    a row, the last differing from the first so the loop's junction is a change too, each
    ``lo``..``hi`` seconds long; every behaviour recurs."""
    from rtseg.simulators.synth.motion import DEFAULT_SCRIPT
    from rtseg.simulators.synth.script import parse_script
    names = list(names) if names is not None else [n for n, _ in parse_script(DEFAULT_SCRIPT)]
    rng = np.random.default_rng(seed)
    while True:
        items: list[tuple[str, float]] = []
        total = 0.0
        while total < seconds:
            n = names[int(rng.integers(len(names)))]
            if items and n == items[-1][0]:
                continue
            d = float(np.round(rng.uniform(lo, hi), 1))
            items.append((n, d))
            total += d
        if items[-1][0] != items[0][0]:
            return items


class CutProbe:
    """Wraps ``Pipeline.process`` (after ``Meter.wrap``, whose ``last_abs`` gives each
    frame's message index) and the identity tracker's ``drain``: the primary detector's
    cuts (boundary and detected message index) and every identity message (segment,
    boundary message index, behaviour id), in preallocated arrays."""

    def __init__(self) -> None:
        self.ring = np.full(RING, -1, dtype=np.int64)
        self.cuts = np.full((MAX_EVENTS, 2), -1, dtype=np.int64)
        self.n_cuts = 0
        self.ids = np.full((MAX_EVENTS, 3), -1, dtype=np.int64)
        self.n_ids = 0
        self.late = 0                # cuts / ids whose frame was no longer in the ring

    def _abs(self, index: int, now: int) -> int:
        if now - index >= RING or index < 0:
            self.late += 1
            return -1
        return int(self.ring[index % RING])

    def wrap(self, pipeline: Any, meter: Any) -> None:
        inner = pipeline.process
        primary = pipeline.config["detectors.primary"] or next(iter(pipeline.detectors))
        ring = self.ring

        def process(index, quats, valid, seq=None, recv_time=None, lost=0, source_time=None,
                    **kw):
            out = inner(index, quats, valid, seq, recv_time, lost, source_time, **kw)
            ring[index % RING] = meter.last_abs
            for c in out:
                if c.cut.method == primary and self.n_cuts < MAX_EVENTS:
                    self.cuts[self.n_cuts] = (self._abs(c.boundary, index),
                                              self._abs(c.detected, index))
                    self.n_cuts += 1
            return out

        pipeline.process = process
        ident = pipeline.identity
        if ident is None:
            return
        drain = ident.drain

        def drained():
            out = drain()
            for d in out:
                if self.n_ids < MAX_EVENTS:
                    now = max(d.decided_frame, d.boundary)
                    self.ids[self.n_ids] = (d.segment, self._abs(d.boundary, now), d.behaviour)
                    self.n_ids += 1
            return out

        ident.drain = drained


def to_frames(msg: np.ndarray, info_idx: Sequence[int]) -> np.ndarray:
    """Message indices -> absolute frames (-1 stays -1)."""
    info = np.asarray(sorted(info_idx), dtype=np.int64)
    out = msg - np.searchsorted(info, msg, side="left")
    return np.where(msg >= 0, out, -1)


def truth(n_loop: int, transitions: Sequence[tuple], segments: Sequence[tuple],
          n_frames: int) -> tuple[list, np.ndarray, np.ndarray, list[str]]:
    """The looped take's truth over ``n_frames`` absolute frames: Transition list (the
    loop junctions included, each one frame wide), and for the per-frame labels the
    segment starts, their behaviour codes and the code names."""
    from rtseg.labels.takes import Transition
    first, last = segments[0][0], segments[-1][0]
    out = []
    loops = n_frames // n_loop + 1
    for k in range(loops):
        base = k * n_loop
        if k > 0:
            out.append(Transition(base, base, base, last, first))
        for lo, hi, mid, before, after in transitions:
            out.append(Transition(base + lo, base + hi, base + mid, before, after))
    out = [t for t in out if t.mid < n_frames]
    names = sorted({s[0] for s in segments})
    starts = np.array([s[1] for s in segments], dtype=np.int64)
    codes = np.array([names.index(s[0]) for s in segments], dtype=np.int64)
    return out, starts, codes, names


def score_by_hour(cut_frames: np.ndarray, transitions: list, frames_per_hour: int,
                  n_frames: int, rate: float, tolerance_s: float = 0.5) -> list[float | None]:
    """Live F1 per session hour at +/- ``tolerance_s``: the cuts matched to the transitions
    over the whole run (``rtseg.evaluation.scoring.score`` on widened ranges), then per hour true
    positives and missed transitions by the transition's mid, false cuts by the cut's frame.
    The last hour counts if it holds at least a quarter of an hour of frames."""
    from rtseg.evaluation.scoring import score, widen
    wide = widen(transitions, int(round(tolerance_s * rate)))
    cuts = [int(c) for c in cut_frames if c >= 0]
    s = score(cuts, wide)
    n_hours = max(1, int(np.ceil(n_frames / frames_per_hour)))
    if n_hours > 1 and n_frames - (n_hours - 1) * frames_per_hour < frames_per_hour // 4:
        n_hours -= 1
    tp = np.zeros(n_hours)
    nt = np.zeros(n_hours)
    nc = np.zeros(n_hours)
    for t in transitions:
        h = t.mid // frames_per_hour
        if h < n_hours:
            nt[h] += 1
    for c in cuts:
        h = c // frames_per_hour
        if h < n_hours:
            nc[h] += 1
    for _, j in s.matches:
        h = transitions[j].mid // frames_per_hour
        if h < n_hours:
            tp[h] += 1
    out: list[float | None] = []
    for h in range(n_hours):
        den = nc[h] + nt[h]
        out.append(float(2 * tp[h] / den) if den else None)
    return out


def ari_by_hour(cut_frames: np.ndarray, ids: np.ndarray, starts: np.ndarray,
                codes: np.ndarray, n_loop: int, frames_per_hour: int,
                n_hours: int, n_frames: int) -> list[float | None]:
    """Adjusted Rand index per session hour between the true behaviour of every frame and
    the behaviour id rtseg gave the segment holding it (the last identity message for that
    segment; frames of segments never decided get id 0), over the ``n_frames`` frames
    sent.  Segments start at the identity messages' boundaries."""
    from sklearn.metrics import adjusted_rand_score
    seg_first: dict[int, tuple[int, int]] = {}
    for seg, b, beh in ids:
        if b >= 0:
            seg_first[int(seg)] = (int(b), int(beh))
    bounds = sorted(seg_first.values())
    bstart = np.array([b for b, _ in bounds], dtype=np.int64)
    bid = np.array([i for _, i in bounds], dtype=np.int64)
    out: list[float | None] = []
    for h in range(n_hours):
        f = np.arange(h * frames_per_hour, min((h + 1) * frames_per_hour, n_frames),
                      dtype=np.int64)
        true = codes[np.searchsorted(starts, f % n_loop, side="right") - 1]
        k = np.searchsorted(bstart, f, side="right") - 1
        pred = np.where(k >= 0, bid[np.maximum(k, 0)], 0) if bstart.size else np.zeros_like(f)
        out.append(float(adjusted_rand_score(true, pred)))
    return out


__all__ = ["CutProbe", "ari_by_hour", "score_by_hour", "soak_script", "to_frames", "truth"]


def clean_f1(rate: float = 120.0, params: str = "") -> dict:
    """The live pipeline's F1 (+/- 0.5 s and strict) on one loop of the soak performance,
    offline: every frame of the clean take, no faults, no pty, no loop (``replay_frames``
    with the shipped configuration, or the detector parameters ``params``: a file or a
    shipped name).  The per-hour figures of a soak cannot beat it: what the soak loses
    against it is what the faults and the machine cost."""
    from rtseg.evaluation.scoring import pooled_tally, tally
    from rtseg.live.config import load_session_config
    from rtseg.live.replay import replay_frames
    from rtseg.simulators.synth.motion import synthesize
    r = synthesize(soak_script(), frame_rate=rate, seed=0)
    tk = r.take
    cfg = load_session_config()
    if params:
        cfg["detectors.params"] = params
    valid = np.ones(tk.quats.shape[1], dtype=bool)
    frames = ((tk.quats[i], valid, i, i / rate, i / rate) for i in range(tk.n_frames))
    cuts = replay_frames(frames, tk.joint_names, tk.parents, tk.space, rate, cfg)
    primary = cfg["detectors.primary"] or cfg["detectors.methods"][0]
    found = [(c.boundary, c.detected) for c in cuts if c.cut.method == primary]
    t = pooled_tally([tally(found, r.transitions, rate, 0.5)])
    return {"f1": t["f1"], "strict_f1": t["strict_f1"], "cuts": t["cuts"],
            "transitions": t["transitions"]}
