"""Leave-one-person-out naming over source folders (``benchmarks/library_loto.py
--by-person DIR``).

For each source folder (``rtseg.library.sources.source_folders``: a folder laid out like
``../shared/data/cmu_single``, ``hdm05`` or ``bandai``, or their parent) and each person P
of it:

- the library is learned (``rtseg.library.examples.learn``, its own calibration) from the
  examples of the OTHER people of the same source (``examples_from_source``);
- ``n`` spliced performances of P alone (``rtseg.evaluation.splice.make_performance`` kind ``same``,
  seed ``seed``: 4-10 segments of P's behaviours, 2.5-8 s each, joined by 0.3-1 s
  cross-fades) go through the live loop with that library (``rtseg.evaluation.library``): every
  live segment's name as sent against the behaviour covering most of it;
- with ``hide``, once more per behaviour of P's performances that the library holds, with
  that behaviour left out of the library: its segments must come out ``unknown``.

Cuts (``cuts``): ``"live"`` - the live loop's own detector (``rtseg.evaluation.identity
.run_identity``), so the figures follow whatever the detector does; ``"truth"`` - an ideal
detector: a cut at every labelled change (the middle of its cross-fade), delivered at that
frame, fed with the performance's live rows to the identity tracker with the library
(``truth_cut_run``).  The segments are then exactly the labelled ones and each name is
decided ``decide_after_s`` (``name_after_s`` when the library would say ``unknown``
sooner) after its change: the library's naming, apart from where the detector cuts.

Per source (and pooled over sources): ``known`` (``rtseg.evaluation.library.named_summary``:
segments of behaviours the library holds named right / unknown / wrong, decision delay
after the change), ``left_out`` (segments of behaviours missing from their library - P's
own behaviours nobody else performs, and the hidden ones: ``unknown_rate``), the same for
each scored person apart (``by_person``: what a rule chosen leave-one-person-out is scored
on), the people scored and skipped, and each fold's library (``library_summary``).

One-person libraries (``one_person``): each held-out person P is named by the library of
each other person O alone, every ordered pair a fold (``by_person`` and ``people`` keyed
"P by O"; a pair whose library holds none of P's performed behaviours is skipped, with
that reason).  A library of one person is calibrated on that person's own takes and
names another person through the performer's scale (``rtseg.identity.names``): this is
how a rule for such libraries is checked beyond bandai, whose libraries are one actor
each anyway.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from rtseg.evaluation.library import Named, library_summary, named_segments, named_summary
from rtseg.library.examples import Example, learn


def person_performances(src: str | Path, person: str, n: int, seed: int) -> list[Any]:
    """``n`` spliced performances (``rtseg.evaluation.splice.Performance``) of ``person`` alone from
    the source folder ``src`` (empty when the person has fewer than two behaviours with
    material enough in one format)."""
    from rtseg.evaluation.splice import (SpliceConfig, build_groups, load_sources, make_performance,
                              read_source_index)
    rows = [r for r in read_source_index(src) if r.subject == person]
    cfg = SpliceConfig()
    groups = build_groups(load_sources(rows), cfg)
    if not any(len(g.behaviours(person)) >= 2 for g in groups):
        return []
    names = sorted({b for g in groups for b in g.behaviours()})
    return [make_performance(f"{person}_{i:03d}", "same", groups, seed, i, cfg, names)
            for i in range(n)]


def _truth(perf: Any) -> np.ndarray:
    names = list(perf.take.meta["frame_label_names"])
    return np.array([names[int(i)] for i in perf.take.meta["frame_labels"]])


#: where the segments of a performance come from (module doc, Cuts)
CUTS = ("live", "truth")


@dataclass
class TruthCutRun:
    """What ``named_segments`` reads of a run: the identity tracker after the take."""
    tracker: Any


def truth_cut_run(take: Any, truth: np.ndarray, config: Any, library: Any,
                  posture: bool = True) -> TruthCutRun:
    """The identity tracker (the session configuration's options, ``library`` naming)
    fed the live rows of ``take`` (``rtseg.library.examples.take_rows``) with a cut at every
    change of the per-frame ``truth``, delivered at that frame (module doc, Cuts);
    ``posture`` False: without the take's rest geometry (``run_identity``)."""
    from rtseg.identity.segments import feed_take, take_posture_of
    from rtseg.identity.tracker import IdentityTracker, tracker_options
    from rtseg.library.examples import take_rows
    X, index, _ = take_rows(take, config)
    posture = take_posture_of(take, library) if posture else None
    t = np.asarray(truth, dtype=str)
    changes = np.flatnonzero(t[1:] != t[:-1]) + 1
    tracker = IdentityTracker(float(take.frame_rate), library=library,
                              **tracker_options(config))
    tracker.set_posture(posture)
    feed_take(tracker, X, index, [(int(c), int(c)) for c in changes if index[0] < c <= index[-1]],
              None if posture is None else take.quats[index])
    return TruthCutRun(tracker)


def lopo_source(src: str | Path, config: Any, n: int = 4, seed: int = 0, hide: bool = True,
                progress: Callable[[str], None] | None = None,
                windows: dict[str, float] | None = None, metric: str | None = None,
                cuts: str = "live", one_person: bool = False,
                posture: bool = True) -> dict[str, Any]:
    """Leave-one-person-out over one source folder (module doc); ``cuts``: ``"live"`` or
    ``"truth"`` (module doc, Cuts); ``one_person``: each held-out person named by the
    library of each other person alone (module doc, One-person libraries); ``posture``
    False: the performances' sessions are not told their rig's rest geometry, as IMU suits
    of unknown geometry, and are named by the model distance alone.  The session
    configuration's ``[identity]`` options apply, ``name_threshold_scale`` among them."""
    from rtseg.evaluation.identity import run_identity
    if cuts not in CUTS:
        raise ValueError(f"cuts {cuts!r}: expected one of {', '.join(CUTS)}")

    def run(perf: Any, truth: np.ndarray, lib: Any) -> Any:
        if cuts == "truth":
            return truth_cut_run(perf.take, truth, config, lib, posture)
        return run_identity(perf.take, config, lib, posture)
    from rtseg.library.sources import examples_from_source
    examples = examples_from_source(src, config)
    people = sorted({e.person for e in examples})
    known: list[Named] = []
    left: list[Named] = []
    libraries: list[dict[str, Any]] = []
    scored, skipped = [], {}
    by_person: dict[str, dict[str, Any]] = {}       # person (or pair) -> summarise()

    def fold(use: Sequence[Example]) -> Any:
        import rtseg.evaluation.library as le
        lib, _ = learn(use, metric=metric, **(windows or {}))
        if le.NO_REJECT:                 # benchmarks/library_loto.py --no-reject: the ceiling
            lib.threshold, lib.ratio = float("inf"), 1.0
            if lib.names_by_posture:
                lib.posture_rule.update(threshold=float("inf"), ratio=1.0)
        return lib

    def score(perfs: Sequence[Any], truths: dict[str, np.ndarray],
              others: Sequence[Example], key: str) -> None:
        """Name the performances ``perfs`` (labels ``truths``) with the library of
        ``others`` (and each behaviour of them left out in turn); the figures go under
        ``key`` of ``by_person``."""
        shown = {str(v) for t in truths.values() for v in np.unique(t)}
        if one_person and not shown & {e.name for e in others}:
            skipped[key] = "the library holds none of the performed behaviours"
            return
        lib = fold(others)
        libraries.append(library_summary(lib, key))
        scored.append(key)
        n_known, n_left = len(known), len(left)
        for perf in perfs:
            if progress is not None:
                progress(f"{Path(src).name} {key}: {perf.name}")
            rows = named_segments(run(perf, truths[perf.name], lib), perf.take,
                                  truths[perf.name], lib, perf.name)
            known.extend(r for r in rows if r.known)
            left.extend(r for r in rows if not r.known)
        if hide:
            for nm in sorted(shown & set(lib.names)):
                use = [e for e in others if e.name != nm]
                if not use:
                    continue
                lib_h = fold(use)
                libraries.append(library_summary(lib_h, key, nm))
                for perf in perfs:
                    if nm not in truths[perf.name]:
                        continue
                    if progress is not None:
                        progress(f"{Path(src).name} {key}: {perf.name} without {nm}")
                    rows = named_segments(run(perf, truths[perf.name], lib_h), perf.take,
                                          truths[perf.name], lib_h, perf.name)
                    left.extend(r for r in rows if r.truth == nm)
        by_person[key] = summarise(known[n_known:], left[n_left:])

    for p in people:
        others = [e for e in examples if e.person != p]
        if not others:
            skipped[p] = "no other person in this source"
            continue
        folds = ([(p, others)] if not one_person else
                 [(f"{p} by {o}", [e for e in others if e.person == o])
                  for o in people if o != p])
        perfs = person_performances(src, p, n, seed)       # once per person, every fold
        if not perfs:
            for key, _ in folds:
                skipped[key] = "fewer than two behaviours with material for a performance"
            continue
        truths = {perf.name: _truth(perf) for perf in perfs}
        for key, use in folds:
            score(perfs, truths, use, key)
    return {"source": str(src), "cuts": cuts, "people": scored, "skipped": skipped,
            **summarise(known, left), "by_person": by_person, "libraries": libraries,
            "segments": [vars(s) for s in known + left]}


def summarise(known: Sequence[Named], left: Sequence[Named]) -> dict[str, Any]:
    """``known`` (``named_summary`` of the segments whose behaviour the library held) and
    ``left_out`` (segments of behaviours missing from their library: count, share sent
    ``unknown``, share sent a name)."""
    k = named_summary(list(known))
    k.pop("not_in_library", None)
    u = len(left)
    unk = sum(s.name == "unknown" for s in left)
    return {"known": k,
            "left_out": {"segments": u, "unknown_rate": round(unk / u, 4) if u else None,
                         "named_rate": round((u - unk) / u, 4) if u else None}}


def lopo_sources(root: str | Path, config: Any, **kw: Any) -> dict[str, Any]:
    """``lopo_source`` over every source folder of ``root``; ``pooled`` over them.
    FileNotFoundError when ``root`` holds none."""
    from rtseg.library.sources import source_folders
    srcs = source_folders(root)
    if not srcs:
        raise FileNotFoundError(f"{root}: no source folder (index.tsv with bvh/ or amc/) in "
                                f"it or its subfolders")
    per = {s.name: lopo_source(s, config, **kw) for s in srcs}
    rows = [Named(**r) for d in per.values() for r in d["segments"]]
    return {"sources": per,
            "pooled": summarise([r for r in rows if r.known], [r for r in rows if not r.known])}
