#!/usr/bin/env python3
"""Leave-one-person-out accuracy of the live (contrast) detector over every person of a
data folder, and the parameter choice made that way.

    python3 benchmarks/lopo.py ../shared/data                 # shipped defaults + LOPO grid
    python3 benchmarks/lopo.py ../shared/data --grid none     # shipped defaults only
    python3 benchmarks/lopo.py ../shared/data --grid none --params fast      # config/fast.toml
    python3 benchmarks/lopo.py ../shared/data --params full --grid confirm --max-median 2.2  # short-look confirmation
    python3 benchmarks/lopo.py ../shared/data --params fast --grid prelook --max-median 2.0  # the pre-look
    python3 benchmarks/lopo.py ../shared/data --grid clear --max-median 2.0  # the shipped set's last choice
    python3 benchmarks/lopo.py DIR --per-person 3 --seeds 0 1 --json

DIR is laid out like ``../shared/data``: ``cmu/`` (full labelled performances, one person
per subject number) and any number of single-behaviour source folders laid out like
``cmu_single/`` (``index.tsv`` with take, subject, format, behaviour; ``bvh/``, ``amc/``),
e.g. ``cmu_single``, ``hdm05``, ``bandai``.  A folder laid out like one source alone works
too.  From each source ``rtseg.evaluation.splice`` builds same-person and mixed performances
(``--per-person`` x people of each kind per seed, cached under ``--cache`` by the source's
path and contents, so another folder of the same name is spliced afresh; a source of one
person gives same-person ones only).  Held-out units: each person with same-person
performances (the cmu takes of one subject are one person), and each mixed performance
holding someone who has none (a person with one behaviour per format); a unit's training
set shares nobody with it, by subject name in any source (``cmu/`` and ``cmu_single/``
both number CMU's subjects, so ``86`` in one is ``86`` in the other; two sources' people
of one name are kept apart from each other's training, never let into it).  Mixed
performances of people who have their own are left out.

Every performance goes once through the live pipeline (``rtseg.evaluation.online.fed_features``:
the features ``rtseg live`` feeds its detectors); every parameter set of the grid then runs
the real ``ContrastDetector`` on those rows.  A set is scored on a group of people by the
mean over its performances of each performance's F1 at +-0.5 s; sets whose median
detection delay over the training people exceeds ``--max-median`` seconds do not count.
Leave-one-person-out: for each person, the best set on the other people is scored on
that person's performances; the held-out cuts are pooled per source and over all.  The
shipped defaults (``config/detectors.toml``) are scored beside it, and every set of the
grid on everyone (``sets``: the grid's accuracy against delay, not a held-out figure) with the
set the same rule chooses on everyone (``chosen_on_everyone``: what to ship).  The same numbers at
the strict tolerance (cut inside the labelled range) and delay median / p90 are given, and
each pooled F1's 95 % interval (``f1_ci95``: the held-out units resampled with
replacement, ``BOOTSTRAP_N`` times).  ``--versus FILE`` also scores another parameter set
on everyone (``versus``) with the paired difference of the two sets' pooled F1 on the same
resamples (``shipped_minus_versus``).
The sets are scored in ``--jobs`` processes (default: one per core), each with one BLAS
thread; the figures do not depend on it.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

if __name__ == "__main__":
    # before numpy loads its BLAS: one BLAS thread per process.  The window models'
    # 48 x 48 algebra gains nothing from more (72 performances x 27 sets: 119 s with one,
    # 125 s with two), and threads in every --jobs process would compete for the cores
    # (--jobs 2: 67 s with one thread each, 187 s with two).  A value already set stays.
    for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_var, "1")
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.evaluation.scoring import pooled_tally, tally
from rtseg.labels.takes import find_labelled_takes
from rtseg.library.sources import source_folders
from rtseg.evaluation.online import fed_features, live_config, to_take_frames
from rtseg.evaluation.splice import SpliceConfig, generate, read_source_index

TOL_S = 0.5
#: the candidates (every combination); the shipped defaults fill the other keys
GRIDS = {
    "none": {},
    "default": {                    # the two thresholds that decide a cut, and the floor
        "threshold": [1.25, 1.5, 1.75],  # under the models' own residuals
        "gate_threshold": [3.5, 4.0, 4.5],
        "residual_floor": [0.1, 0.25, 0.4],
    },
    "placement": {                  # cut placement: off, or its window
        "place_radius_s": [0.0, 1.0],
        "place_window_s": [1.5, 2.0],
    },
    "confirm": {                    # short-look confirmation (--params full), with the after window
        "after_s": [1.875, 2.0],
        "confirm_reach_s": [0.0, 0.875, 1.0],
        "confirm_level": [2.0, 3.0, 4.0],
        "confirm_ratio": [0.9, 1.0],
    },
    "prelook": {                    # the pre-look, at a budget
        "pre_after_s": [0.0, 1.5, 1.75],
        "pre_level": [4.0, 6.0, 8.0],
        "pre_ratio": [0.9, 1.0],
    },
    "clear": {                      # the confirmation only for maxima that stand clear
        "confirm_clear": [0.0, 1.5, 2.0, 3.0],  # and the pre-look's
        "pre_level": [4.0, 6.0, 8.0],            # level
    },
    "hold": {                       # how long a maximum that is not sent sooner waits
        "hold_s": [1.0, 1.5, 2.0, 2.5, 3.0],  # for the contrast to fall, and how far
        "drop": [0.3, 0.4, 0.5],                # it must fall
    },
    "short": {                      # shorter windows and gaps for 2-5 s behaviours
        "threshold": [1.75, 2.0],
        "min_before_s": [1.0, 1.5],
        "min_gap_s": [1.5, 2.0],
    },
}

#: a key that turns a stage off at 0, and the keys that then change nothing: a set with the
#: stage off takes the base's values for them, and a set met twice is scored once
SWITCHES = {"place_radius_s": ("place_window_s",),
            "confirm_reach_s": ("confirm_level", "confirm_ratio"),
            "pre_after_s": ("pre_level", "pre_ratio")}


@dataclass
class Case:
    """One performance: the rows fed to the detector, their take frames, its truth."""
    name: str
    person: str         # the held-out unit: a person, or a mixed performance's name
    persons: frozenset  # everyone in it (training sets share nobody with the unit)
    source: str
    frame_rate: float
    X: np.ndarray
    index: np.ndarray
    transitions: list


def _subjects(src: Path) -> list[str]:
    """The people of a source (``index.tsv`` read as ``splice.py`` reads it: rows whose
    motion file exists)."""
    return sorted({r.subject for r in read_source_index(src)})


def _cache_key(src: Path) -> str:
    """Ten hex digits naming ``src``'s performances in the cache: its resolved path, its
    ``index.tsv`` and the name, size and time of each motion file, so another folder of
    the same name, or this one changed, never reuses what was spliced before."""
    h = hashlib.sha1(str(src.resolve()).encode())
    h.update((src / "index.tsv").read_bytes())
    for p in sorted(src.rglob("*")):
        if p.is_file() and p.suffix.lower() in (".amc", ".asf", ".bvh"):
            st = p.stat()
            h.update(f"{p.relative_to(src)}\t{st.st_size}\t{st.st_mtime_ns}\n".encode())
    return h.hexdigest()[:10]


def load_cases(data: Path, cache: Path, per_person: int, seeds: list[int]) -> list[Case]:
    cfg, _ = live_config(methods=["contrast"])
    cases: list[Case] = []

    def add(take, name, unit, persons, source, transitions):
        X, idx, _ = fed_features(take, cfg)
        cases.append(Case(name, unit, frozenset(persons), source, float(take.frame_rate), X,
                          idx, list(transitions)))

    if (data / "cmu").is_dir():
        for t in find_labelled_takes(data, ("cmu",)):
            who = f"cmu:{t.name.split('_')[0]}"
            add(t.load(), f"cmu/{t.name}", who, [who], "cmu", t.transitions)
    for src in source_folders(data):
        n = per_person * max(1, len(_subjects(src)))
        key = _cache_key(src)
        for seed in seeds:
            out = cache / f"{src.name}-{key}-seed{seed}-n{n}"
            if not (out / "index.tsv").is_file():
                made, why = False, ""
                for kinds in (("same", "mixed"), ("same",)):
                    try:   # a source with one person makes same-person performances only
                        generate(src, out, seed=seed, n=n, kinds=kinds, cfg=SpliceConfig(),
                                 force=True)
                        made = True
                        break
                    except ValueError as exc:
                        why = str(exc)      # the same-person attempt's, when both fail
                if not made:
                    print(f"lopo: {src}: no performance can be spliced: {why}", file=sys.stderr)
                    continue
            same = {p for t in find_labelled_takes(out, ("spliced",)) if t.name.startswith("same")
                    for p in t.load().meta.get("splice", {}).get("subjects", [])}
            for t in find_labelled_takes(out, ("spliced",)):
                take = t.load()
                who = [f"{src.name}:{p}" for p in take.meta.get("splice", {}).get("subjects", ["?"])]
                if t.name.startswith("same"):
                    unit = who[0]
                elif any(p.split(":", 1)[1] not in same for p in who):
                    unit = f"{src.name}/seed{seed}/{t.name}"   # holds someone with one behaviour
                else:
                    continue      # everyone in it is held out through their own performances
                add(take, f"{src.name}/seed{seed}/{t.name}", unit, who, src.name, t.transitions)
    return cases


def detect(case: Case, params: dict, keep_trace: bool = False
           ) -> tuple[ContrastDetector, list[tuple[int, int]]]:
    """The contrast detector with ``params`` run over a performance's fed rows, and its
    (cut frame, detected frame) pairs in rows (``to_take_frames`` makes them take frames)."""
    det = ContrastDetector.from_params(params, case.frame_rate, keep_trace=keep_trace)
    cuts = []
    for i, x in enumerate(case.X):
        c = det.update(x)
        if c is not None:
            cuts.append((c.frame, i))
    return det, cuts


def run(case: Case, params: dict) -> tuple:
    _, cuts = detect(case, params)
    return tally(to_take_frames(cuts, case.index), case.transitions, case.frame_rate, TOL_S)


#: the performances the worker processes of ``score_sets`` score (inherited by fork)
_CASES: list[Case] = []


def _score_set(params: dict) -> dict[str, tuple]:
    return {c.name: run(c, params) for c in _CASES}


def score_sets(cases: list[Case], sets: list[dict], jobs: int = 1,
               progress=None) -> list[dict[str, tuple]]:
    """Every set run on every performance: one ``{performance: tally row}`` per set, in the
    order of ``sets``.  With ``jobs`` > 1 the sets are scored by that many processes (forked,
    so the performances' rows are shared, not copied or pickled); each set's rows are the
    same as one process gives, since a run depends only on its set and performance.
    ``progress(k)`` after each set."""
    global _CASES

    def collect(rows_per_set) -> list[dict[str, tuple]]:
        out = []
        for k, rows in enumerate(rows_per_set):
            out.append(rows)
            if progress is not None:
                progress(k)
        return out

    _CASES = cases
    try:
        if jobs <= 1 or len(sets) < 2 or "fork" not in multiprocessing.get_all_start_methods():
            return collect(map(_score_set, sets))
        with ProcessPoolExecutor(min(jobs, len(sets)),
                                 mp_context=multiprocessing.get_context("fork")) as ex:
            return collect(ex.map(_score_set, sets))
    finally:
        _CASES = []


def subject(person: str) -> str:
    """A person's subject name without its source (``cmu_single:86`` -> ``86``)."""
    return person.split(":", 1)[-1]


def training_cases(cases: list[Case], unit: str) -> list[Case]:
    """The performances a set is chosen on for the held-out ``unit``: those sharing no
    subject name, in any source, with anyone in the unit's performances."""
    who = {subject(p) for c in cases if c.person == unit for p in c.persons}
    return [c for c in cases if not any(subject(p) in who for p in c.persons)]


def _best_set(results: list[dict[str, tuple]], names: list[str], max_median: float) -> int:
    """Index of the set with the best mean F1 over the performances ``names`` among those
    whose median delay there is within ``max_median`` seconds (any set when none is)."""
    best, best_key = 0, None
    for k, res in enumerate(results):
        rows = [res[n] for n in names]
        med = pooled_tally(rows)["delay_median"] or 0.0
        key = (med <= max_median, mean_f1(rows))
        if best_key is None or key > best_key:
            best, best_key = k, key
    return best


def candidate_sets(grid: str, base: dict) -> list[dict]:
    spec = GRIDS[grid]
    if not spec:
        return []
    keys = list(spec)
    out: list[dict] = []
    for v in itertools.product(*spec.values()):
        p = {**base, **dict(zip(keys, v))}
        for switch, inert in SWITCHES.items():
            if switch in p and not p[switch]:
                p.update({k: base[k] for k in inert if k in base})
        if p not in out:
            out.append(p)
    return out


def mean_f1(rows: list) -> float:
    return float(np.mean([pooled_tally([r])["f1"] for r in rows])) if rows else 0.0


def summary(rows: list) -> dict:
    t = pooled_tally(rows)
    return {"f1": round(t["f1"], 4), "strict_f1": round(t["strict_f1"], 4), "cuts": t["cuts"],
            "transitions": t["transitions"],
            "delay_median_s": None if t["delay_median"] is None else round(t["delay_median"], 3),
            "delay_p90_s": None if t["delay_p90"] is None else round(t["delay_p90"], 3)}


#: resamples behind each pooled F1's 95 % interval (``f1_interval``)
BOOTSTRAP_N = 2000


def f1_interval(cases: list[Case], rows: dict[str, tuple], n: int = BOOTSTRAP_N,
                seed: int = 0) -> list[float] | None:
    """95 % percentile interval of the pooled F1 of ``rows`` over ``cases``, from ``n``
    resamples with replacement of the held-out units (a person's performances go
    together: they are not independent of each other); None with fewer than two units.
    The same ``seed`` gives the same interval."""
    counts = _unit_counts(cases, rows)
    if len(counts) < 2:
        return None
    f1 = _resampled_f1(counts, _resamples(len(counts), n, seed))
    return [round(float(v), 4) for v in np.percentile(f1, [2.5, 97.5])]


def f1_difference(cases: list[Case], a: dict[str, tuple], b: dict[str, tuple],
                  n: int = BOOTSTRAP_N, seed: int = 0) -> dict | None:
    """Pooled F1 of ``a`` minus that of ``b`` (two sets' tally rows on the same
    performances) and its 95 % interval, both sets scored on the same resamples of the
    units (a paired comparison); None with fewer than two units."""
    ca, cb = _unit_counts(cases, a), _unit_counts(cases, b)
    if len(ca) < 2:
        return None
    pick = _resamples(len(ca), n, seed)
    d = _resampled_f1(ca, pick) - _resampled_f1(cb, pick)
    point = _resampled_f1(ca, np.arange(len(ca))[None]) - _resampled_f1(cb, np.arange(len(cb))[None])
    return {"f1": round(float(point[0]), 4),
            "ci95": [round(float(v), 4) for v in np.percentile(d, [2.5, 97.5])]}


def _unit_counts(cases: list[Case], rows: dict[str, tuple]) -> np.ndarray:
    """(units, 3): right cuts, cuts and transitions of each held-out unit, in a fixed order."""
    units: dict[str, np.ndarray] = {}
    for c in sorted(cases, key=lambda c: (c.person, c.name)):
        r = rows[c.name]
        units.setdefault(c.person, np.zeros(3))[:] += (r[0], r[1], r[2])
    return np.array(list(units.values())).reshape(-1, 3)


def _resamples(units: int, n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, units, (n, units))


def _resampled_f1(counts: np.ndarray, pick: np.ndarray) -> np.ndarray:
    tp, cuts, trans = counts[pick].sum(axis=1).T
    denom = cuts + trans
    return np.where(denom > 0, 2 * tp / np.maximum(denom, 1), 1.0)


def report(cases: list[Case], rows: dict[str, tuple]) -> dict:
    by_source: dict[str, list[Case]] = {}
    for c in cases:
        by_source.setdefault(c.source, []).append(c)

    def part(group: list[Case]) -> dict:
        return {**summary([rows[c.name] for c in group]), "f1_ci95": f1_interval(group, rows)}
    return {"pooled": part(cases), "sources": {s: part(g) for s, g in sorted(by_source.items())}}


def add_performance_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments that say which performances ``load_cases`` reads: DATA, --per-person,
    --seeds, --cache (shared by the scripts that score them)."""
    p.add_argument("data", type=Path, help="folder laid out like ../shared/data (or one source)")
    p.add_argument("--per-person", type=int, default=2, help="performances per person and seed")
    p.add_argument("--seeds", type=int, nargs="+", default=[0], help="splice seeds")
    p.add_argument("--cache", type=Path, default=Path("/tmp/rtseg-lopo"),
                   help="where spliced performances are kept")


def checked_params(args: argparse.Namespace, prog: str) -> dict | None:
    """The ``[contrast]`` parameters of ``args.params`` (None: the shipped ones), or None
    after one line on stderr when ``args.data`` is no folder or the file is bad."""
    if not args.data.is_dir():
        print(f"{prog}: {args.data} is not a folder", file=sys.stderr)
        return None
    try:
        return load_params(args.params)["contrast"]
    except (OSError, ValueError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return None


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_performance_arguments(p)
    p.add_argument("--grid", choices=list(GRIDS), default="default")
    p.add_argument("--max-median", type=float, default=2.5, help="delay budget (s) of a set")
    p.add_argument("--params", metavar="FILE",
                   help="detector parameters scored as 'shipped' and filling the grid's "
                        "other keys (default config/detectors.toml; 'fast': config/fast.toml)")
    p.add_argument("--versus", metavar="FILE",
                   help="also score these parameters on everyone (a file, or a shipped name "
                        "such as full), beside --params, with the paired difference of "
                        "their pooled F1 and its 95 %% interval")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="parameter sets scored at once, in that many processes (default: "
                        "the machine's cores; 1: in this process)")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    base = checked_params(args, "lopo")     # a bad file: before minutes of reading
    if base is None:
        return 2
    versus_base = None
    if args.versus is not None:
        try:
            versus_base = load_params(args.versus)["contrast"]
        except (OSError, ValueError) as exc:
            print(f"lopo: --versus: {exc}", file=sys.stderr)
            return 2
    t0 = time.perf_counter()
    try:
        cases = load_cases(args.data, args.cache, args.per_person, args.seeds)
    except (OSError, ValueError) as exc:
        print(f"lopo: {exc}", file=sys.stderr)
        return 2
    if not cases:
        print(f"lopo: no labelled takes or single-behaviour sources in {args.data}", file=sys.stderr)
        return 2
    people = sorted({p for c in cases for p in c.persons})
    units = sorted({c.person for c in cases})
    print(f"lopo: {len(cases)} performances of {len(people)} people in {len(units)} held-out units "
          f"({time.perf_counter() - t0:.0f} s to read)", file=sys.stderr)
    shipped = {c.name: run(c, base) for c in cases}
    out: dict = {"people": people, "performances": len(cases), "shipped": report(cases, shipped)}
    if versus_base is not None:
        versus = {c.name: run(c, versus_base) for c in cases}
        out["versus"] = {"params": args.versus, **report(cases, versus),
                         "shipped_minus_versus": f1_difference(cases, shipped, versus)}
    sets = candidate_sets(args.grid, base)
    if sets:
        results = score_sets(cases, sets, args.jobs, lambda k: print(
            f"lopo: set {k + 1}/{len(sets)} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr))
        held: dict[str, tuple] = {}
        choices = {}
        alone = []
        for person in units:
            train = training_cases(cases, person)
            if not train:          # nobody else to choose on: the shipped defaults
                alone.append(person)
                choices[person] = "shipped (no other person to choose on)"
                held.update({c.name: shipped[c.name] for c in cases if c.person == person})
                continue
            best = _best_set(results, [c.name for c in train], args.max_median)
            choices[person] = {key: sets[best][key] for key in GRIDS[args.grid]}
            for c in cases:
                if c.person == person:
                    held[c.name] = results[best][c.name]
        out["sets"] = [{"params": {key: sets[k][key] for key in GRIDS[args.grid]},
                        **report(cases, results[k])} for k in range(len(sets))]
        everyone = _best_set(results, [c.name for c in cases], args.max_median)
        out["held_out"] = report(cases, held)
        out["choices"] = choices
        if alone:
            out["held_out_without_training"] = alone
            print(f"lopo: {', '.join(alone)}: no other person to choose a set on; held out "
                  f"with the shipped defaults", file=sys.stderr)
        out["chosen_on_everyone"] = {key: sets[everyone][key] for key in GRIDS[args.grid]}
        out["chosen_on_everyone_fit"] = report(cases, results[everyone])
    out["seconds"] = round(time.perf_counter() - t0, 1)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    for label in ("held_out", "shipped", "versus", "chosen_on_everyone_fit"):
        if label not in out:
            continue
        r = out[label]
        print(f"{label}: pooled F1 {r['pooled']['f1']:.3f}{_ci(r['pooled'])} (strict "
              f"{r['pooled']['strict_f1']:.3f}), "
              f"delay {r['pooled']['delay_median_s']} / {r['pooled']['delay_p90_s']} s")
        for s, v in r["sources"].items():
            print(f"  {s:12s} F1 {v['f1']:.3f}{_ci(v)} (strict {v['strict_f1']:.3f})  "
                  f"{v['cuts']} cuts / {v['transitions']} transitions  "
                  f"delay {v['delay_median_s']} / {v['delay_p90_s']} s")
    for row in out.get("sets", []):
        r = row["pooled"]
        print(f"set {row['params']}: pooled F1 {r['f1']:.3f} (strict {r['strict_f1']:.3f}), "
              f"delay {r['delay_median_s']} / {r['delay_p90_s']} s")
    if "chosen_on_everyone" in out:
        print(f"chosen on everyone: {out['chosen_on_everyone']}")
    diff = out.get("versus", {}).get("shipped_minus_versus")
    if diff:
        print(f"shipped minus versus ({args.versus}): pooled F1 {diff['f1']:+.3f} "
              f"[95 % {diff['ci95'][0]:+.3f} to {diff['ci95'][1]:+.3f}]")
    return 0


def _ci(part: dict) -> str:
    ci = part.get("f1_ci95")
    return f" [95 % {ci[0]:.3f}-{ci[1]:.3f}]" if ci else ""


if __name__ == "__main__":
    sys.exit(main())
