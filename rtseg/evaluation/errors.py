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
    (``offset_s``: that cut's signed distance from the range, s; negative = before);
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
from typing import Any, Iterable, Sequence

from rtseg.evaluation.scoring import Transition, score, widen

#: causes of a missed transition, in the order they are tried
MISS_CAUSES = ("gate dropped", "floor refused", "below threshold", "cut outside",
               "no maximum sent")
#: kinds of false cut
FALSE_KINDS = ("near", "inside")


@dataclass(frozen=True)
class Miss:
    """A labelled transition no cut matched: its range, the behaviours either side, the
    cause (``MISS_CAUSES``) and, for ``cut outside``, the nearest unmatched cut's signed
    distance from the widened range (s)."""
    lo: int
    hi: int
    before: str
    after: str
    cause: str
    offset_s: float | None = None


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
              near_s: float = 1.5) -> Errors:
    """The misses and false cuts of ``cuts`` (take frames) against ``transitions`` (module
    docstring).  ``contrast``: the detector's profile as (take frame, value); ``threshold``:
    the value a maximum must reach; ``gate_drops`` / ``refusals``: take frames of the cuts
    the gate dropped and of the maxima the relative floor refused."""
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
        offset = None
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
            else:
                cause = "no maximum sent"
        misses.append(Miss(t.lo, t.hi, t.before, t.after, cause, offset))
    false_cuts = []
    for c in free:
        d = min((0 if t.lo <= c <= t.hi else min(abs(c - t.lo), abs(c - t.hi))
                 for t in transitions), default=None)
        dist = float("inf") if d is None else d / fr
        false_cuts.append(FalseCut(c, "near" if dist <= near_s else "inside",
                                   _behaviour_at(c, transitions), round(dist, 3)))
    return Errors(tuple(misses), tuple(false_cuts))


def tally_errors(errors: Iterable[Errors]) -> dict[str, Any]:
    """Counts over several takes: misses by cause and by behaviour pair ("before -> after"),
    false cuts by kind and, for those ``inside``, by the behaviour they fall in (most
    first)."""
    causes: Counter[str] = Counter()
    pairs: Counter[str] = Counter()
    kinds: Counter[str] = Counter()
    inside: Counter[str] = Counter()
    for e in errors:
        for m in e.misses:
            causes[m.cause] += 1
            pairs[f"{m.before} -> {m.after}"] += 1
        for f in e.false_cuts:
            kinds[f.kind] += 1
            if f.kind == "inside":
                inside[f.behaviour] += 1
    return {"misses": sum(causes.values()),
            "miss_causes": {k: causes[k] for k in MISS_CAUSES},
            "missed_pairs": dict(pairs.most_common()),
            "false_cuts": sum(kinds.values()),
            "false_kinds": {k: kinds[k] for k in FALSE_KINDS},
            "false_inside": dict(inside.most_common())}
