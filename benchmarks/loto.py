"""Leave-one-take-out choice of the live (contrast) detector's parameters, and their
sensitivity.

    python3 benchmarks/loto.py [DATA] [--synth-seeds 0 1 2 3 4 5] [--json]
    python3 benchmarks/loto.py [DATA] --select-on SPLICED_DIR [...]   # chosen on other people
    python3 benchmarks/loto.py ../shared/data --nested --max-median 2.0 --fix step_s=0.125 \
        --fix bound_before=0
    python3 benchmarks/loto.py ../shared/data --max-median 2.0 --fix step_s=0.125 \
        --fix after_s=2.0 --fix hold_s=1.0 --fix drop=0.5 \
        --loto-spliced SPLICED_SAME SPLICED_MIXED
                                                      # what chose the shipped set (~16 min)

Every take of DATA (a folder laid out like ../shared/data: its cmu and tsseg4d groups) and
the synthetic performances (``rtseg.simulators.synth.motion``, the default script, one per seed)
goes once through the live pipeline (``rtseg.evaluation.online``: the same features as
``rtseg live``); the features fed to the detector are kept, and every candidate parameter
set runs the real ``ContrastDetector`` on them (the contrast profile is computed once per
window geometry - step, after window; the cut picker ``CutSender`` is replayed on it per
threshold/hold/drop, and the script checks that this gives the same cuts, sent on the same
frames, as full detector runs of the shipped defaults with and without the gate).  The
short-look confirmation and the pre-look are not in its grid (``benchmarks/lopo.py
--grid confirm`` / ``prelook`` choose them).  Cut placement
(``place_radius_s``) is not replayed: every set, the shipped one included, is scored with
placement off (``benchmarks/lopo.py`` scores the whole detector, placement included).  Sets whose before windows
are bounded by the last cut sent (``bound_before``) depend on their own cuts: they are
full detector runs (about 7 s per set over the labelled and synthetic takes, 20 s with the
40 spliced performances) - hold the other grid parameters with ``--fix`` to keep such a
grid small.  ``--fix KEY=VALUE`` holds
one grid parameter at one value (the shipped set holds the step at 1/8 s: the speed target
leaves no room for the 1/12 s step's 1.5x window fits).

A parameter set is scored on a set of takes by the mean over those takes of each take's F1
at +-0.5 s (``--objective takes``: every performance counts once, as it does when it is the
one held out; ``pooled`` and ``groups`` are the earlier rules, kept for comparison), and
only counts when its median / p90 detection delay over the labelled takes (cmu, tsseg4d)
is <= 2.5 / 3.5 s (``--max-median S``: <= S / S + 1 s).  Ties go to the shorter after window, then to the
lower median delay over the training takes, then to the first set in grid order.
Leave-one-take-out: for each take name (86_01 holds out its cmu and tsseg4d versions
together), the best set on the other takes is scored on it; the held-out cuts are pooled
per group.  Leave-one-person-out likewise holds out every take of one subject (86, 13, 14;
the synthetic performances always train).  Also printed: the set chosen on every take
(what should ship), each fold's choice with its margin over the runner-up, and the F1 of
the shipped defaults as each parameter moves alone.

``--select-on DIR ...`` adds a choice made on other people only: the spliced performances
of each DIR (``benchmarks/splice.py`` output from ``cmu_single``, people other than 86, 13
and 14) and the synthetic ones pick the set by the same objective and delay budget, and it
is scored on every take of DATA, none of which took part in the choice.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rtseg.detectors import load_params
from rtseg.detectors.contrast import ContrastDetector
from rtseg.detectors.sender import CutSender
from rtseg.evaluation.scoring import pooled_tally, tally
from rtseg.labels.takes import find_labelled_takes
from rtseg.evaluation.online import fed_features, live_config, to_take_frames
from rtseg.simulators.synth.motion import DEFAULT_SCRIPT, synthesize

TOL_S = 0.5
OBJECTIVES = ("takes", "pooled", "groups")   # objective() kinds; --nested chooses among them
MAX_MEDIAN_S, MAX_P90_S = 2.5, 3.5
#: frames after a block's last frame at which the detector makes the full look of the
#: position that block completes (its third queued step, ``ContrastDetector._block_done``)
LOOK_STEP = 2
GRID = {                       # the candidates: grid step, after window, the peak picker,
    "step_s": [0.0833333333, 0.125],
    "after_s": [1.5, 1.75, 2.0],
    "threshold": [1.5, 2.0, 2.5, 3.0],
    "hold_s": [0.5, 0.75, 1.0],
    "drop": [0.5, 0.75],
    "gate_threshold": [0.0, 3.5, 4.5, 5.5],      # the same-behaviour gate (0: off)
    "bound_before": [0.0, 1.0],                  # before windows bounded by the last cut sent
}


def grid_configs() -> list[dict]:
    """Every combination of GRID, once.  The gate threshold varies fastest (``main``
    replays the gate on each cut list)."""
    keys = list(GRID)
    return [dict(zip(keys, v)) for v in itertools.product(*GRID.values())]


@dataclass
class Case:
    """One take: features fed to the detector (session index of each), the transitions."""
    key: str            # group/name
    name: str           # take name (the LOTO unit)
    group: str
    frame_rate: float
    X: np.ndarray
    index: np.ndarray   # session frame of each fed row
    transitions: list
    restarts: int


def load_cases(data: Path | None, seeds: list[int]) -> list[Case]:
    cfg, _ = live_config(methods=["contrast"])
    cases = []
    if data is not None:
        for t in find_labelled_takes(data, ("cmu", "tsseg4d")):
            take = t.load()
            X, idx, rs = fed_features(take, cfg)
            cases.append(Case(f"{t.group}/{t.name}", t.name, t.group, take.frame_rate, X, idx,
                              list(t.transitions), rs))
    for s in seeds:
        res = synthesize(DEFAULT_SCRIPT, seed=s)
        X, idx, rs = fed_features(res.take, cfg)
        cases.append(Case(f"synthetic/seed{s}", f"synth{s}", "synthetic", res.take.frame_rate,
                          X, idx, list(res.transitions), rs))
    return cases


def load_other_people(folders: list[Path]) -> list[Case]:
    """The spliced performances of each folder (``benchmarks/splice.py`` output: people
    other than those of the labelled takes), group ``spliced``; each performance is a take."""
    cfg, _ = live_config(methods=["contrast"])
    cases = []
    for folder in folders:
        for t in find_labelled_takes(folder, ("spliced",)):
            take = t.load()
            X, idx, rs = fed_features(take, cfg)
            cases.append(Case(f"spliced/{folder.name}/{t.name}", f"{folder.name}/{t.name}",
                              "spliced", take.frame_rate, X, idx, list(t.transitions), rs))
        if not any(c.key.startswith(f"spliced/{folder.name}/") for c in cases):
            print(f"loto: no spliced performances in {folder}", file=sys.stderr)
    return cases


def detector(p: dict, fr: float) -> ContrastDetector:
    return ContrastDetector.from_params(p, fr, keep_trace=True)


def peaks_on_trace(det: ContrastDetector, p: dict, fr: float) -> list[tuple[int, int]]:
    """(cut frame, detected frame) of the cut picker (``CutSender``) with ``p`` replayed on
    a run's profile (clean take: the full look's value at c is known at c + after - 1 + 2:
    the detector queues a completed block's work one step a frame - the next position's
    before window, c's after window, then the look; a second cut of the same frame goes
    out with the next frame, as in the detector)."""
    pk: CutSender = detector(p, fr).peaks      # the picker a detector with p would use
    lag = det.wb * det.step - 1 + LOOK_STEP
    out = []
    last_now = None
    for pos, v, _ in det.trace:
        now = pos + lag
        sent = pk.update_full(pos, v, now)
        if sent is not None:
            at = now + 1 if now == last_now else now
            out.append((sent.peak.position, at))
            last_now = now
    return out


def gated(p: dict, case: Case, cuts: list[tuple[int, int]], memo: dict) -> list[tuple[int, int]]:
    """The cuts that pass the same-behaviour gate of a detector with ``p`` (all of them
    when its threshold is 0), replayed on the case's rows (``SameBehaviourGate.replay``);
    ``memo`` keeps each case's window distances across thresholds."""
    if not p["gate_threshold"]:
        return cuts
    gate = detector(p, case.frame_rate).gate
    gate.memo = memo.setdefault(case.key, {})
    return gate.replay(case.X, cuts)


def counts(case: Case, cuts: list[tuple[int, int]]) -> tuple[int, int, int, int, list[float]]:
    """``tally`` of cuts given in fed-row frames, mapped to take frames."""
    return tally(to_take_frames(cuts, case.index), case.transitions, case.frame_rate, TOL_S)


def objective(res: dict, cases: list[Case], kind: str = "takes") -> float:
    """``takes``: the mean over the takes of each take's F1 (each performance counts once,
    however long); ``pooled``: F1 over every transition of the takes (each counts once,
    whatever its take, so long takes weigh more); ``groups``: the mean of the groups' pooled
    F1.  Minus 1 when the median / p90 delay over the real takes (else all) exceeds the
    budget."""
    allrows = pooled_tally(_real_rows(res, cases))
    ok = (allrows["delay_median"] or 0) <= MAX_MEDIAN_S and (allrows["delay_p90"] or 0) <= MAX_P90_S
    if kind == "takes":
        f = float(np.mean([pooled_tally([res[c.key]])["f1"] for c in cases]))
    elif kind == "pooled":
        f = pooled_tally([res[c.key] for c in cases])["f1"]
    else:
        groups = sorted({c.group for c in cases})
        f = float(np.mean([pooled_tally([res[c.key] for c in cases if c.group == g])["f1"]
                           for g in groups]))
    return f - (0 if ok else 1.0)


def _real_rows(res: dict, cases: list[Case]) -> list:
    """The tallies of the labelled takes of ``cases`` (cmu, tsseg4d); without any, of the
    other non-synthetic ones (spliced); without those, of all."""
    return ([res[c.key] for c in cases if c.group in ("cmu", "tsseg4d")]
            or [res[c.key] for c in cases if c.group != "synthetic"]
            or [res[c.key] for c in cases])


def real_delay(res: dict, cases: list[Case]) -> float:
    """Median delay over the real takes of ``cases`` (all, when none is real); the last
    tie-break of a choice: of equally good sets, the one that cuts sooner."""
    return pooled_tally(_real_rows(res, cases))["delay_median"] or 0.0


def person(case: Case) -> str:
    """The subject of a real take (CMU names SS_TT), the performance itself for synthetic
    and spliced ones."""
    return case.name if case.group in ("synthetic", "spliced") else case.name.split("_")[0]


def main() -> int:
    global MAX_MEDIAN_S, MAX_P90_S
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    ap.add_argument("--synth-seeds", type=int, nargs="*", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--objective", choices=list(OBJECTIVES), default="takes",
                    help="what a parameter set maximises on the training takes: the mean of "
                         "the takes' F1 (default), F1 over all their transitions pooled, or "
                         "the mean of the groups' F1")
    ap.add_argument("--nested", action="store_true",
                    help="also choose the objective itself inside each fold: an inner "
                         "leave-one-take-out over the fold's training takes scores each "
                         "objective (pooled F1 of its inner held-out real takes) and the "
                         "best one picks the fold's set (the held-out figure of the whole "
                         "procedure, rule choice included)")
    ap.add_argument("--select-on", type=Path, nargs="+", metavar="DIR", default=[],
                    help="also choose the set on other people only: the spliced performances "
                         "of each DIR (benchmarks/splice.py output) and the synthetic ones, "
                         "then score it on every take of DATA, none of which took part")
    ap.add_argument("--loto-spliced", type=Path, nargs="+", metavar="DIR", default=[],
                    help="spliced performances (benchmarks/splice.py output) that join the "
                         "leave-one-take-out as takes of their own (group spliced; the delay "
                         "budget stays on the labelled takes)")
    ap.add_argument("--max-median", type=float, default=MAX_MEDIAN_S, metavar="S",
                    help=f"delay budget: a set counts only when its median delay over the "
                         f"real takes is at most S seconds (default {MAX_MEDIAN_S}; p90 at most "
                         f"S + 1)")
    ap.add_argument("--fix", action="append", default=[], metavar="KEY=VALUE",
                    help="hold one grid parameter at one value (repeatable), e.g. "
                         "step_s=0.125 when a speed target rules the finer step out")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    for item in args.fix:
        key, _, value = item.partition("=")
        if key not in GRID:
            ap.error(f"--fix: {key!r} is not a grid parameter ({', '.join(GRID)})")
        try:
            GRID[key] = [float(value)]
        except ValueError:
            ap.error(f"--fix {item!r}: the value must be a number")
    MAX_MEDIAN_S, MAX_P90_S = args.max_median, args.max_median + 1.0
    data = Path(args.data)
    if not (data / "cmu").is_dir() and not (data / "tsseg4d").is_dir():
        print(f"loto: no labelled takes in {data}; synthetic performances only", file=sys.stderr)
        data = None
    cases = load_cases(data, args.synth_seeds)
    cases += load_other_people(args.loto_spliced)
    others = load_other_people(args.select_on)
    # the replayed picker and gate give unplaced cuts: every set here, the shipped one
    # included, is scored without cut placement (benchmarks/lopo.py runs the full detector)
    base = dict(load_params()["contrast"], place_radius_s=0.0)
    keys = list(GRID)
    configs = grid_configs()
    if not any(all(base[k] == c[k] for k in keys) for c in configs):
        configs.append({k: base[k] for k in keys})
    results: dict[tuple, dict] = {}
    traces: dict[tuple, ContrastDetector] = {}
    ungated: dict[str, tuple] = {}           # case -> (set without the gate, its cuts)
    memo: dict[str, dict] = {}               # case -> the gate's window distances
    for cfgv in configs:
        p = {**base, **cfgv}
        geo = (p["step_s"], p["after_s"])
        res = {}
        for case in cases + others:
            if case.restarts or p["bound_before"]:   # a gap, or windows that depend on the
                # cuts sent: the detector itself, gate and all
                d2 = detector(p, case.frame_rate)
                res[case.key] = counts(case, [(c.frame, c.detected_at) for c in d2.run(case.X)])
                continue
            if (geo, case.key) not in traces:
                det = detector({**p, "gate_threshold": 0.0}, case.frame_rate)
                det.run(case.X)
                traces[(geo, case.key)] = det
            plain = tuple(v for k, v in cfgv.items() if k != "gate_threshold")
            if ungated.get(case.key, (None,))[0] != plain:
                ungated[case.key] = (plain, peaks_on_trace(traces[(geo, case.key)], p,
                                                           case.frame_rate))
            res[case.key] = counts(case, gated(p, case, ungated[case.key][1], memo))
        results[tuple(cfgv[k] for k in keys)] = res
    # the shortcut equals a full detector run for the shipped defaults with unbounded
    # windows (the same cuts, sent on the same frames), with and without the gate (bounded
    # sets are full runs: nothing to check)
    unb = {**base, "bound_before": 0.0}
    for p in (unb, {**unb, "gate_threshold": 0.0}):
        for case in cases + others:
            full = [(c.frame, c.detected_at) for c in detector(p, case.frame_rate).run(case.X)]
            if not case.restarts:
                geo = (p["step_s"], p["after_s"])
                if (geo, case.key) not in traces:      # a geometry --fix left out
                    traces[(geo, case.key)] = detector({**p, "gate_threshold": 0.0},
                                                       case.frame_rate)
                    traces[(geo, case.key)].run(case.X)
                det = traces[(geo, case.key)]
                cuts = gated(p, case, peaks_on_trace(det, p, case.frame_rate), {})
                assert full == cuts, case.key

    def best(train: list[Case], kind: str | None = None) -> tuple:
        kind = kind or args.objective
        return max(results, key=lambda k: (objective(results[k], train, kind),
                                           -k[keys.index("after_s")],
                                           -real_delay(results[k], train)))

    def nested_choice(train: list[Case]) -> tuple[str, tuple]:
        """The objective whose inner leave-one-take-out over ``train`` scores best (pooled
        F1 of the inner held-out real takes; ties: the order of OBJECTIVES), and the set it
        chooses on all of ``train``."""
        inner_names = sorted({c.name for c in train})
        scores = {}
        for kind in OBJECTIVES:
            rows = []
            for m in inner_names:
                k = best([c for c in train if c.name != m], kind)
                rows += [results[k][c.key] for c in train
                         if c.name == m and c.group != "synthetic"]
            scores[kind] = pooled_tally(rows)["f1"] if rows else 0.0
        kind = max(OBJECTIVES, key=lambda o: scores[o])
        return kind, best(train, kind)

    def margin(train: list[Case], k: tuple) -> float:
        """How far the chosen set's objective leads the best other set's (0: a tie)."""
        top = objective(results[k], train, args.objective)
        return top - max(objective(results[o], train, args.objective) for o in results if o != k)

    chosen_all = best(cases)
    names = sorted({c.name for c in cases})
    held: dict[str, tuple] = {}
    folds = {}
    for n in names:
        train = [c for c in cases if c.name != n]
        k = best(train)
        held_rows = [results[k][c.key] for c in cases if c.name == n]
        folds[n] = {**dict(zip(keys, k)), "held_out_f1": round(pooled_tally(held_rows)["f1"], 3),
                    "margin": round(margin(train, k), 4)}
        for c in cases:
            if c.name == n:
                held[c.key] = results[k][c.key]
    groups = sorted({c.group for c in cases})
    nested_held: dict[str, tuple] = {}
    nested_folds = {}
    if args.nested:
        for n in names:
            kind, k = nested_choice([c for c in cases if c.name != n])
            nested_folds[n] = {"objective": kind, **dict(zip(keys, k))}
            for c in cases:
                if c.name == n:
                    nested_held[c.key] = results[k][c.key]
    lopo_held: dict[str, tuple] = {}
    lopo_folds = {}
    for subject in sorted({person(c) for c in cases if c.group not in ("synthetic", "spliced")}):
        k = best([c for c in cases if person(c) != subject])
        lopo_folds[subject] = dict(zip(keys, k))
        for c in cases:
            if person(c) == subject:
                lopo_held[c.key] = results[k][c.key]
    shipped = tuple(base[k] for k in keys)
    report = {
        "tolerance_s": TOL_S,
        "objective": args.objective,
        "loto": {g: pooled_tally([held[c.key] for c in cases if c.group == g]) for g in groups},
        "shipped": {"params": dict(zip(keys, shipped)),
                    **{g: pooled_tally([results[shipped][c.key] for c in cases if c.group == g])
                       for g in groups}},
        "chosen_on_all": {"params": dict(zip(keys, chosen_all)),
                          **{g: pooled_tally([results[chosen_all][c.key] for c in cases if c.group == g])
                             for g in groups}},
        "folds": folds,
        "lopo": {g: pooled_tally([lopo_held[c.key] for c in cases if c.group == g])
                 for g in groups if any(c.key in lopo_held for c in cases if c.group == g)},
        "lopo_folds": lopo_folds,
        "nested": {g: pooled_tally([nested_held[c.key] for c in cases if c.group == g])
                   for g in groups} if args.nested else None,
        "nested_folds": nested_folds or None,
        "sensitivity": {},
        "other_people": None,
    }
    if others:
        train = others + [c for c in cases if c.group == "synthetic"]
        k = best(train)
        tested = [g for g in groups if g != "synthetic"]
        report["other_people"] = {
            "chose": dict(zip(keys, k)), "margin": round(margin(train, k), 4),
            "performances": len(others),
            "spliced (in sample)": pooled_tally([results[k][c.key] for c in others]),
            **{g: pooled_tally([results[k][c.key] for c in cases if c.group == g]) for g in tested}}
    for i, k in enumerate(keys):
        rows = []
        for v in GRID[k]:
            cfgk = tuple(v if j == i else shipped[j] for j in range(len(keys)))
            if cfgk in results:
                rows.append({"value": v, **{g: pooled_tally([results[cfgk][c.key] for c in cases
                                                        if c.group == g]) for g in groups}})
        report["sensitivity"][k] = rows
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    fmt = lambda s: (f"F1 {s['f1']:.3f} (strict {s['strict_f1']:.3f}), delay "
                     f"{s['delay_median'] if s['delay_median'] is not None else float('nan'):.2f}/"
                     f"{s['delay_p90'] if s['delay_p90'] is not None else float('nan'):.2f} s, "
                     f"{s['cuts']} cuts / {s['transitions']} transitions")
    print(f"leave-one-take-out over {len(names)} takes ({', '.join(names)}), "
          f"{len(results)} parameter sets, objective {args.objective}, F1 at +-{TOL_S} s:")
    for g in groups:
        print(f"  held-out {g:<10} {fmt(report['loto'][g])}")
    if args.nested:
        print("nested (objective chosen inside each fold by an inner leave-one-take-out):")
        for g in groups:
            print(f"  held-out {g:<10} {fmt(report['nested'][g])}")
        for n, f in nested_folds.items():
            print(f"  fold without {n:<8} chose {f}")
    if report["lopo"]:
        print("leave-one-person-out (subjects " + ", ".join(lopo_folds) + "):")
        for g, row in report["lopo"].items():
            print(f"  held-out {g:<10} {fmt(row)}")
        for subject, f in lopo_folds.items():
            print(f"  fold without subject {subject} chose {f}")
    print(f"shipped defaults {report['shipped']['params']}:")
    for g in groups:
        print(f"  {g:<19} {fmt(report['shipped'][g])}")
    print(f"chosen on all takes {report['chosen_on_all']['params']}")
    for n, f in folds.items():
        print(f"  fold without {n:<8} chose {f}")
    if others:
        o = report["other_people"]
        print(f"chosen on other people only ({o['performances']} spliced performances of "
              f"{', '.join(str(d) for d in args.select_on)} + synthetic): {o['chose']}, "
              f"margin {o['margin']}")
        for g, row in o.items():
            if isinstance(row, dict) and "f1" in row:
                print(f"  {g:<19} {fmt(row)}")
    print("sensitivity (one parameter moved from the shipped defaults):")
    for k, rows in report["sensitivity"].items():
        for r in rows:
            print(f"  {k:<10} {r['value']:<6} " + " | ".join(
                f"{g} {r[g]['f1']:.3f} d{r[g]['delay_median'] or 0:.2f}/{r[g]['delay_p90'] or 0:.2f}"
                for g in groups))
    return 0


if __name__ == "__main__":
    sys.exit(main())
