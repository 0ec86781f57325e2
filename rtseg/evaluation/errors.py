"""Why cuts are wrong: each labelled transition no cut matched, and each cut that matched
none, with a cause read from what the detector saw.

Scoring is ``rtseg.evaluation.scoring``'s (a cut is right within ``tolerance_s`` of a
labelled transition range, one cut per transition).  ``attribute`` then names, in this
order, the first cause that holds for each **missed** transition (its range widened by the
tolerance, as scored):

``gate dropped``
    the same-behaviour gate dropped a cut inside it (``rtseg.detectors.gate``);
``floor refused``
    the relative floor refused a maximum inside it (``rtseg.detectors.relative``);
``below threshold``
    the detector's profile (the contrast) stayed under its threshold all through it;
``cut outside``
    the profile reached the threshold, and a cut that matched nothing lies at most
    ``outside_s`` beyond the widened range: the change was seen but placed off it
    (``offset_s``: that cut's signed distance from the range, s; negative = before).
    Given ``span_like``, ``span`` says what the motion between that cut and the labelled
    range resembles: ``labelled`` (the behaviour the labels give it: the cut lies inside
    that behaviour) or ``other`` (the behaviour on the far side of the cut: the motion
    changed where the cut is, away from where the labels put it);
``no maximum sent``
    the profile reached the threshold but no cut came near: the peak rule (a higher value
    within ``min_gap`` before, a cut already sent within it) kept it.

Each **false cut** is ``near`` (within ``near_s`` of a labelled range: a second cut of a
change, or one placed off it) or ``inside`` a segment, with the behaviour labelled there.
A detector without a profile or gate (another method) gives empty ``contrast`` and
``gate_drops``: its misses are then ``cut outside`` or ``no maximum sent``.

Frames are 0-based take frames throughout; times in seconds.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from rtseg.evaluation.scoring import Transition, score, widen

#: causes of a missed transition, in the order they are tried
MISS_CAUSES = ("gate dropped", "floor refused", "below threshold", "cut outside",
               "no maximum sent")
#: kinds of false cut
FALSE_KINDS = ("near", "inside")
#: what the motion between a ``cut outside`` and its range resembles
SPANS = ("labelled", "other")
#: ``span_resemblance``: the windows either side it is compared with (s), and the least
#: span or window it judges (s)
SPAN_WINDOW_S = 1.5
SPAN_MIN_S = 0.25


@dataclass(frozen=True)
class Miss:
    """A labelled transition no cut matched: its range, the behaviours either side, the
    cause (``MISS_CAUSES``) and, for ``cut outside``, the nearest unmatched cut's signed
    distance from the widened range (s) and what the motion between them resembles
    (``span``: ``labelled``, ``other``, or None when not judged)."""
    lo: int
    hi: int
    before: str
    after: str
    cause: str
    offset_s: float | None = None
    span: str | None = None


@dataclass(frozen=True)
class FalseCut:
    """A cut that matched no transition: its frame, ``near`` or ``inside``, the behaviour
    labelled at it, and its distance from the nearest labelled range (s)."""
    frame: int
    kind: str
    behaviour: str
    distance_s: float


@dataclass(frozen=True)
class Errors:
    """What ``attribute`` found on one take."""
    misses: tuple[Miss, ...]
    false_cuts: tuple[FalseCut, ...]

    def as_dict(self) -> dict[str, Any]:
        return {"misses": [asdict(m) for m in self.misses],
                "false_cuts": [asdict(f) for f in self.false_cuts]}


def _behaviour_at(frame: int, transitions: Sequence[Transition]) -> str:
    """The behaviour labelled at ``frame``: the one after the last transition whose
    middle it has passed ("" when unlabelled)."""
    name = transitions[0].before if transitions else ""
    for t in transitions:
        if frame >= t.mid:
            name = t.after
    return name or ""


def attribute(cuts: Sequence[int], transitions: Sequence[Transition], frame_rate: float,
              tolerance_s: float = 0.5, *, threshold: float = 0.0,
              contrast: Iterable[tuple[int, float]] = (), gate_drops: Iterable[int] = (),
              refusals: Iterable[int] = (), outside_s: float = 2.0,
              near_s: float = 1.5,
              span_like: Callable[[int, int, int], str | None] | None = None) -> Errors:
    """The misses and false cuts of ``cuts`` (take frames) against ``transitions`` (module
    docstring).  ``contrast``: the detector's profile as (take frame, value); ``threshold``:
    the value a maximum must reach; ``gate_drops`` / ``refusals``: take frames of the cuts
    the gate dropped and of the maxima the relative floor refused; ``span_like(cut, lo,
    hi)``: for a cut outside the range [lo, hi] (take frames), ``labelled`` or ``other``
    (module docstring), or None."""
    fr = float(frame_rate)
    if fr <= 0:
        raise ValueError(f"frame_rate must be positive, got {frame_rate}")
    frames = [int(c) for c in cuts]
    wide = widen(transitions, int(round(tolerance_s * fr)))
    s = score(frames, wide)
    hit_t = {j for _, j in s.matches}
    # the cuts that matched nothing, in order (a frame may repeat)
    free = sorted((Counter(frames) - Counter(c for c, _ in s.matches)).elements())
    profile = [(int(p), float(v)) for p, v in contrast]
    drops, refused = [int(b) for b in gate_drops], [int(b) for b in refusals]
    out_f = int(round(outside_s * fr))
    misses = []
    for j, (t, w) in enumerate(zip(transitions, wide)):
        if j in hit_t:
            continue
        inside = lambda xs: any(w.lo <= x <= w.hi for x in xs)   # noqa: E731
        offset = span = None
        if inside(drops):
            cause = "gate dropped"
        elif inside(refused):
            cause = "floor refused"
        elif profile and max((v for p, v in profile if w.lo <= p <= w.hi),
                             default=-float("inf")) < threshold:
            cause = "below threshold"
        else:
            near = [c for c in free if w.lo - out_f <= c <= w.hi + out_f]
            if near:
                c = min(near, key=lambda x: min(abs(x - w.lo), abs(x - w.hi)))
                offset = round(((c - w.hi) if c > w.hi else (c - w.lo)) / fr, 3)
                cause = "cut outside"
                span = span_like(c, t.lo, t.hi) if span_like is not None else None
            else:
                cause = "no maximum sent"
        misses.append(Miss(t.lo, t.hi, t.before, t.after, cause, offset, span))
    false_cuts = []
    for c in free:
        d = min((0 if t.lo <= c <= t.hi else min(abs(c - t.lo), abs(c - t.hi))
                 for t in transitions), default=None)
        dist = float("inf") if d is None else d / fr
        false_cuts.append(FalseCut(c, "near" if dist <= near_s else "inside",
                                   _behaviour_at(c, transitions), round(dist, 3)))
    return Errors(tuple(misses), tuple(false_cuts))


def span_resemblance(rows: np.ndarray, index: np.ndarray, frame_rate: float,
                     window_s: float = SPAN_WINDOW_S) -> Callable[[int, int, int], str | None]:
    """``attribute``'s ``span_like`` from the rows a detector was fed (``index``: the take
    frame of each row, increasing).  For a cut c before the range [lo, hi] the span [c, lo)
    is compared (``window_models.behaviour_distance``) with the ``window_s`` before c (its
    labelled behaviour) and the ``window_s`` after hi (the other); for a cut after it, the
    span (hi, c] with the ``window_s`` after c and the ``window_s`` before lo.  None when a
    window holds under ``SPAN_MIN_S`` of rows."""
    from rtseg.detectors.window_models import WindowStats, behaviour_distance, fit

    X = np.asarray(rows, dtype=np.float64)
    idx = np.asarray(index)
    w = int(round(window_s * frame_rate))
    least = max(2, int(round(SPAN_MIN_S * frame_rate)))

    def model(a: float, b: float):
        i, j = (int(np.searchsorted(idx, f)) for f in (a, b))
        return fit(WindowStats.of(X[i:j])) if j - i >= least else None

    def like(c: int, lo: int, hi: int) -> str | None:
        if c < lo:
            span, labelled, other = model(c, lo), model(c - w, c), model(hi + 1, hi + 1 + w)
        else:
            span, labelled, other = model(hi + 1, c), model(c, c + w), model(lo - w, lo)
        if span is None or labelled is None or other is None:
            return None
        near_label = behaviour_distance(span, labelled) <= behaviour_distance(span, other)
        return "labelled" if near_label else "other"
    return like


def tally_errors(errors: Iterable[Errors]) -> dict[str, Any]:
    """Counts over several takes: misses by cause (``cut outside`` ones also by ``span``) and
    by behaviour pair ("before -> after"), false cuts by kind and, for those ``inside``, by
    the behaviour they fall in (most first)."""
    causes: Counter[str] = Counter()
    spans: Counter[str] = Counter()
    pairs: Counter[str] = Counter()
    kinds: Counter[str] = Counter()
    inside: Counter[str] = Counter()
    for e in errors:
        for m in e.misses:
            causes[m.cause] += 1
            if m.span is not None:
                spans[m.span] += 1
            pairs[f"{m.before} -> {m.after}"] += 1
        for f in e.false_cuts:
            kinds[f.kind] += 1
            if f.kind == "inside":
                inside[f.behaviour] += 1
    return {"misses": sum(causes.values()),
            "miss_causes": {k: causes[k] for k in MISS_CAUSES},
            "outside_span": {k: spans[k] for k in SPANS},
            "missed_pairs": dict(pairs.most_common()),
            "false_cuts": sum(kinds.values()),
            "false_kinds": {k: kinds[k] for k in FALSE_KINDS},
            "false_inside": dict(inside.most_common())}
