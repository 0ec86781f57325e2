"""Held-out scoring of named behaviour libraries.

Every figure names segments of takes the library did not learn from:

- ``name_take``: one take through the live pipeline (``rtseg.evaluation.identity.run_identity``)
  with the library on the identity tracker; each live segment of the primary detector gets
  the name sent at its decision; its truth is the majority of the per-frame labels
  (``truth``) over the segment.
- ``tally``: per segment ``known`` (its true name is in the library) or not; ``accuracy`` =
  known segments named right / known segments, ``unknown_rate`` = known segments named
  ``unknown`` / known segments, ``unknown_correct`` = not-known segments named ``unknown``
  / not-known segments; ``decision_delay_s``: the median and p90 over the known segments
  that start within 1 s of a change of the per-frame truth of (decision frame - that
  change) / frame rate, the time from the labelled transition to the name on the wire.

Protocols (``rtseg.library.examples.Example`` lists in, libraries learned per fold):
leave-one-take-out (``loto``: learn from the other takes), leave-one-person-out
(``lopo``: from the other people), and leave-one-name-out inside either (``hide_names``:
each true name of the held-out take also removed from the library in turn, its segments
must come out ``unknown``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from rtseg.evaluation.identity import decision_delays_after, delay_summary, run_identity
from rtseg.library.behaviours import UNKNOWN, Library
from rtseg.library.examples import Example, learn


@dataclass
class Named:
    """One live segment: take, segment index, boundary frame, true name, name sent."""
    take: str
    segment: int
    boundary: int
    truth: str
    name: str
    distance: float
    known: bool = True
    delay_s: float | None = None      # decision frame - the truth's change it follows, s


@dataclass
class Tally:
    segments: list[Named] = field(default_factory=list)

    def add(self, rows: Sequence[Named]) -> None:
        self.segments.extend(rows)

    def summary(self) -> dict[str, Any]:
        k = [s for s in self.segments if s.known]
        u = [s for s in self.segments if not s.known]
        d = [s.delay_s for s in k if s.delay_s is not None]
        return {"accuracy": _share(sum(s.name == s.truth for s in k), len(k)),
                "unknown_rate": _share(sum(s.name == UNKNOWN for s in k), len(k)),
                "unknown_correct": _share(sum(s.name == UNKNOWN for s in u), len(u)),
                "known_segments": len(k), "unknown_segments": len(u),
                "decision_delay_s": delay_summary(d)}


def named_summary(rows: Sequence[Named]) -> dict[str, Any]:
    """``rtseg evaluate --online --identity --behaviours LIB``'s ``identity.named``: over
    the segments whose true behaviour the library holds (``segments``), the shares sent
    their true name (``accuracy``), ``unknown`` (``unknown_rate``) and another name
    (``wrong_rate``), which sum to 1; ``decision_delay_s`` as ``Tally.summary``; and over
    the segments of behaviours the library lacks (``not_in_library``) the share sent
    ``unknown`` (``unknown_rate``: right for them) and the share given a name."""
    k = [s for s in rows if s.known]
    u = [s for s in rows if not s.known]
    right = sum(s.name == s.truth for s in k)
    unk = sum(s.name == UNKNOWN for s in k)
    d = [s.delay_s for s in k if s.delay_s is not None]
    return {"accuracy": _share(right, len(k)), "unknown_rate": _share(unk, len(k)),
            "wrong_rate": _share(len(k) - right - unk, len(k)), "segments": len(k),
            "decision_delay_s": delay_summary(d),
            "not_in_library": {"segments": len(u),
                               "unknown_rate": _share(sum(s.name == UNKNOWN for s in u), len(u)),
                               "named_rate": _share(sum(s.name != UNKNOWN for s in u), len(u))}}


def _share(a: int, b: int) -> float | None:
    return round(a / b, 4) if b else None


def name_take(take: Any, truth: np.ndarray, library: Library, config: Any,
              key: str) -> list[Named]:
    """The live segments of ``take`` named by ``library`` (module doc)."""
    return named_segments(run_identity(take, config, library), take, truth, library, key)


def named_segments(run: Any, take: Any, truth: np.ndarray, library: Library,
                   key: str) -> list[Named]:
    """The segments of a live run (``rtseg.evaluation.identity.run_identity`` with ``library``)
    with the name each was sent at its decision and its truth: the behaviour of the most
    per-frame ``truth`` labels over the segment (module doc)."""
    n, fr = take.n_frames, float(take.frame_rate)
    segs = sorted(run.tracker.segment_names().items())
    known = set(library.names)
    t = np.asarray(truth, dtype=str)
    changes = np.flatnonzero(t[1:] != t[:-1]) + 1
    out = []
    for i, (seg, (b, name)) in enumerate(segs):
        e = segs[i + 1][1][0] if i + 1 < len(segs) else n
        a = 0 if i == 0 else b
        lab = truth[a:max(e, a + 1)]
        v, c = np.unique(np.asarray(lab, dtype=str), return_counts=True)
        top = str(v[c.argmax()])
        sent = next((m for m in run.tracker.history
                     if m.segment == seg and not m.correction), None)
        dist = sent.name_distance if sent is not None else float("inf")
        after = decision_delays_after([sent], fr, changes) if sent is not None else []
        out.append(Named(key, seg, b, top, name, float(dist), top in known,
                         after[0] if after else None))
    return out


#: set True (benchmarks/library_loto.py --no-reject) to name every segment by its
#: nearest name: the ceiling the rejection rule works under
NO_REJECT = False
#: the libraries' distance (benchmarks/library_loto.py --metric; None: the default)
METRIC: str | None = None
#: the libraries' window options (benchmarks/library_loto.py --step; ``LibraryBuilder``'s)
WINDOWS: dict[str, float] = {}


def fold(examples: Sequence[Example], held: Callable[[Example], bool],
         hide: Sequence[str] = ()) -> tuple[Library | None, list[str]]:
    """A library of the examples not ``held`` and not named in ``hide``."""
    use = [e for e in examples if not held(e) and e.name not in hide]
    if not use:
        return None, []
    lib, notes = learn(use, metric=METRIC, **WINDOWS)
    if NO_REJECT:
        lib.threshold, lib.ratio = float("inf"), 1.0
    return lib, notes


def run_folds(examples: Sequence[Example], units: dict[str, Callable[[Example], bool]],
              takes: dict[str, tuple[Any, np.ndarray]], take_unit: dict[str, str],
              config: Any, hide_names: bool = True, progress: Any = None
              ) -> dict[str, Any]:
    """Held-out naming: for each unit (a take or a person), learn from the examples it
    does not hold, name the live segments of its takes (``takes``: key -> (take, per-frame
    truth)); with ``hide_names``, also once per true name of the unit with that name left
    out of the library (its segments count as not-known).  Returns ``{"held_out":
    summary, "hidden_names": summary, "not_known": summary, "segments": [...],
    "libraries": [...]}`` (``not_known``: every segment whose behaviour its library
    lacked - the held-out folds' and the hidden names' - for ``unknown_correct``; each
    fold's library: ``library_summary``)."""
    main, hidden = Tally(), Tally()
    libraries = []
    for unit, held in units.items():
        lib, _ = fold(examples, held)
        if lib is None:
            continue
        libraries.append(library_summary(lib, unit))
        keys = [k for k, u in take_unit.items() if u == unit]
        for k in keys:
            if progress is not None:
                progress(f"{unit}: {k}")
            take, truth = takes[k]
            main.add(name_take(take, truth, lib, config, k))
        if not hide_names:
            continue
        names = sorted({str(v) for k in keys for v in np.unique(takes[k][1])} & set(lib.names))
        for nm in names:
            lib_h, _ = fold(examples, held, (nm,))
            if lib_h is None:
                continue
            libraries.append(library_summary(lib_h, unit, nm))
            for k in keys:
                if progress is not None:
                    progress(f"{unit}: {k} without {nm}")
                take, truth = takes[k]
                rows = name_take(take, truth, lib_h, config, k)
                hidden.add([r for r in rows if r.truth == nm])
    both = Tally([s for s in main.segments if not s.known] + hidden.segments)
    return {"held_out": main.summary(), "hidden_names": hidden.summary() if hide_names else None,
            "not_known": both.summary(), "segments": [vars(s) for s in main.segments],
            "libraries": libraries}


def library_summary(lib: Library, unit: str, without: str | None = None) -> dict[str, Any]:
    """What a fold's library holds (names, examples, example windows and their length in
    seconds) and the rule it calibrated (``calibrated`` False: no behaviour had a second
    example, the threshold is the metric's default)."""
    return {"unit": unit, "without": without, "names": len(lib.behaviour_names),
            "examples": len(lib.examples), "windows": len(lib.names),
            "window_s": float(lib.window_s),
            "threshold": round(float(lib.threshold), 4) if np.isfinite(lib.threshold) else None,
            "ratio": round(float(lib.ratio), 4),
            "calibrated": bool(lib.calibration.get("calibrated", True)),
            **({"posture_threshold": round(float(lib.posture_rule["threshold"]), 4),
                "posture_ratio": round(float(lib.posture_rule["ratio"]), 4)}
               if lib.names_by_posture else {})}
