"""The naming decision's margin chosen leave-one-person-out, and its held-out figures.

    python3 benchmarks/names_rule_lopo.py [DATA_DIR] [--seeds 0 1 2] [--rules "W,L,C;..."
        | --sets "OPTIONS;..." | --every] [--out DIR] [--jobs J] [--n N] [--min-left 0.80]
        [--max-wrong 0.05]

A library names a segment when log(d1 / t) + W x log((d1 / d2) / r) <= L and d1 <= C x t
(``rtseg.library.calibration.decision_excess``; ``0,0,1`` is the threshold alone).  For
each rule (W, L, C) of ``--rules`` and each splice seed of ``--seeds`` this runs
``benchmarks/library_loto.py --by-person DATA_DIR --seed K --rule W,L,C [--n N]`` (the shipped
configuration otherwise: live cuts, names decided ``decide_after_s`` into their segment;
about 1.5 minutes a run over ``../shared/data``), ``--jobs`` runs at a time (default 2),
each run's JSON kept in ``--out`` (default ``out/names_rule`` of the checkout, not
versioned) and reused when it is there.

``--sets`` chooses among other settings the same way: each set is options of
``library_loto.py`` for one run (e.g. ``--sets "--posture-weight 0.5 --speed-weight 1;
--posture-weight 0.8 --speed-weight 1"``), scored as a rule is.  ``--every``: every
naming choice at once - the 13 rules of the decision's margin, the claim margins 0, 0.6,
0.8 and 1, the example windows 1.5, 2.5 and 3 s long or every 0.25 and 1 s, and the
names' distance weights (posture 1/2, 2/3, 0.8 x joint speeds 0.5, 1, 1.5), each one
change from the shipped configuration (``EVERY``; 30 sets, 90 runs over seeds 0-2) - so
that each person is scored with the whole configuration chosen without them.

Then, for each scored person P (``by_person`` of every source): the rule chosen without P
is the one naming the most known segments right over the other people, among the rules
whose left-out ``unknown`` share is at least ``--min-left`` and whose wrong share is at
most ``--max-wrong`` on every seed over those people (when no rule meets both on every
seed: the one with the largest smallest left-out ``unknown`` share, ``qualified`` false).
P is scored with it.  Printed (one JSON document): ``held_out`` first - every person's
segments under the rule chosen without them, pooled over seeds and people, and per
source - then ``chosen`` (the rule of each person) and ``everyone`` (each rule's figures
over all people and seeds: not held out).  Figures: ``named_right``, ``unknown``,
``wrong`` (shares of the known segments), ``left_out_unknown`` (share of the segments of
behaviours missing from the library), with their counts.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[1] / "shared" / "data"
#: the rules tried by default: weights 2-6 with levels along the ridge where named right
#: trades one for one against left-out ``unknown`` (docs/history.md, 2026-12-06), caps
#: 1.25-2, and the threshold alone (0, 0, 1)
RULES = ("4,-0.75,1.5;4,-0.65,1.5;4,-0.85,1.5;3,-0.6,1.5;3,-0.75,1.5;5,-0.85,1.5;"
         "5,-1.0,1.5;4,-0.75,1.25;4,-0.75,2;2,-0.45,1.5;2,-0.3,1.5;6,-1.0,1.5;0,0,1")
#: ``--every``: the margin's rules, then the other naming choices, each one change from
#: the shipped configuration (claim margin 0.9, 2 s example windows every 0.5 s, posture
#: weight 2/3, joint-speed weight 1)
EVERY = (";".join(f"--rule {r}" for r in RULES.split(";"))
         + ";--claim-margin 0;--claim-margin 0.6;--claim-margin 0.8;--claim-margin 1"
         + ";--window 1.5;--window 2.5;--window 3;--step 0.25;--step 1"
         + ";--posture-weight 0.5 --speed-weight 0.5;--posture-weight 0.5 --speed-weight 1"
         + ";--posture-weight 0.5 --speed-weight 1.5;--speed-weight 0.5;--speed-weight 1.5"
         + ";--posture-weight 0.8 --speed-weight 0.5;--posture-weight 0.8 --speed-weight 1"
         + ";--posture-weight 0.8 --speed-weight 1.5")


@dataclass
class Counts:
    """Segments of one person (or a pool) under one rule: known ones named right,
    ``unknown`` and wrong; left-out ones and those of them sent ``unknown``."""
    known: int = 0
    right: int = 0
    unknown: int = 0
    wrong: int = 0
    left: int = 0
    left_unknown: int = 0

    def __iadd__(self, o: "Counts") -> "Counts":
        for k in vars(self):
            setattr(self, k, getattr(self, k) + getattr(o, k))
        return self

    def shares(self) -> dict[str, Any]:
        def share(a: int, b: int) -> float | None:
            return round(a / b, 4) if b else None
        return {"named_right": share(self.right, self.known),
                "unknown": share(self.unknown, self.known),
                "wrong": share(self.wrong, self.known),
                "left_out_unknown": share(self.left_unknown, self.left),
                "known_segments": self.known, "left_out_segments": self.left}


@dataclass
class Run:
    """One rule on one seed: each person's counts (``source/person`` keys)."""
    people: dict[str, Counts] = field(default_factory=dict)

    def pool(self, skip: str | None = None) -> Counts:
        c = Counts()
        for p, v in self.people.items():
            if p != skip:
                c += v
        return c


def counts_of(person: dict[str, Any]) -> Counts:
    """A ``by_person`` entry of ``library_loto.py --by-person`` as counts (its shares are
    rounded to 4 decimals, the counts recovered by rounding)."""
    k, lo = person["known"], person["left_out"]
    n, m = int(k.get("segments") or 0), int(lo.get("segments") or 0)

    def of(share: float | None, total: int) -> int:
        return int(round((share or 0.0) * total))
    return Counts(n, of(k.get("accuracy"), n), of(k.get("unknown_rate"), n),
                  of(k.get("wrong_rate"), n), m, of(lo.get("unknown_rate"), m))


def read_run(path: Path) -> Run:
    doc = json.loads(path.read_text())
    run = Run()
    for src, d in doc["sources"].items():
        for person, v in d.get("by_person", {}).items():
            run.people[f"{src}/{person}"] = counts_of(v)
    return run


def set_options(rule: str) -> list[str]:
    """The ``library_loto.py`` options of one rule or set: "W,L,C" is ``--rule W,L,C``,
    anything starting with "--" is options as written."""
    return shlex.split(rule) if rule.startswith("--") else ["--rule", rule]


def run_file(out: Path, rule: str, seed: int, n: int | None = None) -> Path:
    """Where the JSON of ``rule`` (or set) on ``seed`` (``n`` performances a person) is
    kept: named by its options (flags without their dashes, commas as "_")."""
    key = "_".join(a[2:] if a.startswith("--") else a for a in set_options(rule))
    tail = "" if n is None else f"_n{n}"
    return out / f"{key.replace(',', '_').replace('/', '_')}_seed{seed}{tail}.json"


def ensure_run(data: Path, out: Path, rule: str, seed: int, n: int | None = None) -> Path:
    """The JSON of ``rule`` on ``seed``, run now when it is not in ``out`` yet."""
    path = run_file(out, rule, seed, n)
    if path.exists():
        return path
    cmd = [sys.executable, str(HERE / "library_loto.py"), "--by-person", str(data),
           "--seed", str(seed), *set_options(rule)] + ([] if n is None else ["--n", str(n)])
    print(f"names_rule_lopo: {' '.join(cmd[1:])}", file=sys.stderr, flush=True)
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0 or not done.stdout.strip():
        raise RuntimeError(f"{' '.join(cmd)} exited {done.returncode}: "
                           f"{done.stderr.strip().splitlines()[-1:] or ''}")
    tmp = path.with_suffix(".part")
    tmp.write_text(done.stdout)
    tmp.replace(path)
    return path


def qualifies(c: Counts, min_left: float, max_wrong: float) -> bool:
    return (c.left == 0 or c.left_unknown / c.left >= min_left) and \
        (c.known == 0 or c.wrong / c.known <= max_wrong)


def choose(runs: dict[str, list[Run]], person: str, min_left: float,
           max_wrong: float) -> tuple[str, bool]:
    """(rule, qualified) chosen without ``person`` (module doc); ties: the earlier rule."""
    best, best_key = None, None
    for rule, per_seed in runs.items():
        pools = [r.pool(skip=person) for r in per_seed]
        ok = all(qualifies(c, min_left, max_wrong) for c in pools)
        left = min((c.left_unknown / c.left) if c.left else 1.0 for c in pools)
        key = (ok, sum(c.right for c in pools) if ok else left)
        if best_key is None or key > best_key:
            best, best_key = rule, key
    return best, bool(best_key and best_key[0])


def parse(argv: list[str]) -> argparse.Namespace:
    """The command line (module doc); argparse's usage error (exit 2) when it is not one."""
    p = argparse.ArgumentParser(prog="names_rule_lopo.py", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", nargs="?", type=Path, default=DATA)
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    which = p.add_mutually_exclusive_group()
    which.add_argument("--rules", default=RULES)
    which.add_argument("--sets")
    which.add_argument("--every", action="store_const", const=EVERY, dest="sets")
    p.add_argument("--out", type=Path, default=HERE.parent / "out" / "names_rule")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--n", type=int)
    p.add_argument("--min-left", type=float, default=0.80)
    p.add_argument("--max-wrong", type=float, default=0.05)
    args = p.parse_args(argv)
    if args.jobs < 1 or (args.n is not None and args.n < 1):
        p.error("--jobs and --n: at least 1")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(list(sys.argv[1:] if argv is None else argv))
    data = args.data
    if not data.is_dir():
        print(f"names_rule_lopo: {data}: no such folder (a folder laid out like "
              f"../shared/data or one of its source folders)", file=sys.stderr)
        return 2
    rules = [r.strip() for r in (args.sets or args.rules).split(";") if r.strip()]
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(r, s) for r in rules for s in args.seeds]
    try:
        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            paths = list(pool.map(lambda rs: ensure_run(data, out, *rs, args.n), jobs))
    except RuntimeError as exc:
        print(f"names_rule_lopo: {exc}", file=sys.stderr)
        return 1
    runs: dict[str, list[Run]] = {r: [] for r in rules}
    for (r, _), p in zip(jobs, paths):
        runs[r].append(read_run(p))
    people = sorted({p for rs in runs.values() for run in rs for p in run.people})
    chosen: dict[str, dict[str, Any]] = {}
    held, by_source = Counts(), {}          # by_source: source name -> Counts
    for person in people:
        rule, ok = choose(runs, person, args.min_left, args.max_wrong)
        mine = Counts()
        for run in runs[rule]:
            mine += run.people.get(person, Counts())
        held += mine
        src = person.split("/")[0]
        by_source[src] = by_source.get(src, Counts())
        by_source[src] += mine
        chosen[person] = {"rule": rule, "qualified": ok, **mine.shares()}
    everyone = {}
    for r, rs in runs.items():
        c = Counts()
        for run in rs:
            c += run.pool()
        everyone[r] = c.shares()
    print(json.dumps({"held_out": {**held.shares(),
                                   "by_source": {s: c.shares() for s, c in by_source.items()}},
                      "criterion": {"min_left_out_unknown": args.min_left,
                                    "max_wrong": args.max_wrong, "per_seed": True},
                      "seeds": args.seeds, "data": str(data),
                      "chosen": chosen, "everyone": everyone}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
