#!/usr/bin/env python3
"""Throughput of ``rtseg segment`` on an archive: takes/s with 1 and 2 local Dask workers.

    python benchmarks/archive.py [--takes 200] [--method contrast] [--workers 1,2]
                                 [--archive DIR] [--repeat 1] [--json]

The archive: ``--takes`` synthetic takes of 30-120 s (``rtseg.simulators.synth.motion``, random
behaviour scripts, 120 fps, written with ``write_take`` to ``--archive``, default a folder
in the temp dir kept between runs so the takes are generated once) plus the real takes of
../shared/data/cmu when present.  For each worker count a ``LocalCluster`` (processes, one
thread each) is started (start-up timed apart), every take runs as one task through
``rtseg.archive.executors.run_tasks`` (the code path of ``rtseg segment --workers N``), and the
wall time from submission to the last record gives takes/s.

Worker CPU: the CPU seconds the worker processes used during the run (``cpu_share`` =
that / (wall x workers): below 1 when other processes took the cores) and takes per CPU
second, whose 2/1 ratio shows whether a second worker adds work of its own.

Per-take overhead: (wall x workers - the takes' own compute time measured inside the
tasks) / takes: what scheduling, transfer and idle workers add to each take; and the
round trip of a no-op task on one worker (``--noop`` tasks).  The load average before and
after each run is reported: the machine is shared, and other processes take cores.
The scaling target: 2 workers >= 1.7x the takes/s of 1 worker.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
REAL = REPO.parent / "shared" / "data" / "cmu"


def make_archive(folder: Path, n: int, min_s: float, max_s: float, seed: int = 0) -> list[str]:
    """``n`` synthetic takes of min_s..max_s seconds in ``folder`` (reused when present)."""
    from rtseg.drivers.readers import write_take
    from rtseg.simulators.synth.motion import BEHAVIOURS, synthesize
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    names = list(BEHAVIOURS)
    paths = []
    for k in range(n):
        total = rng.uniform(min_s, max_s)
        parts: list[str] = []
        left = total
        while left > 0:
            d = min(left, rng.uniform(6.0, 15.0))
            if d < 3.0 and parts:        # fold a short tail into the previous item
                name, secs = parts[-1].split(":")
                parts[-1] = f"{name}:{float(secs) + d:.2f}"
                break
            parts.append(f"{names[rng.integers(len(names))]}:{max(d, 3.0):.2f}")
            left -= d
        p = folder / f"{k // 100:03d}" / f"synth_{k:05d}.npz"
        if not p.exists():
            p.parent.mkdir(exist_ok=True)
            write_take(p, synthesize(",".join(parts), seed=seed * 100000 + k).take)
        paths.append(str(p.resolve()))
    return paths


def noop(x: int) -> int:
    return x


def run_once(todo: list[tuple[str, list[str]]], workers: int) -> dict[str, Any]:
    from rtseg.archive.executors import dask_client, run_tasks
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    with dask_client(workers=workers) as client:
        client.wait_for_workers(workers)
        startup = time.perf_counter() - t0
        cpu0 = client.run(time.process_time)
        t1 = time.perf_counter()
        compute, failed = 0.0, 0
        for _, recs in run_tasks(todo, {}, client=client):
            compute += recs[0].get("take_elapsed_s") or 0.0
            failed += any(r.get("error") for r in recs)
        wall = time.perf_counter() - t1
        cpu1 = client.run(time.process_time)
    cpu = sum(cpu1[w] - cpu0.get(w, 0.0) for w in cpu1)
    load1 = os.getloadavg()
    n = len(todo)
    return {"workers": workers, "takes": n, "failed": failed, "startup_s": round(startup, 2),
            "wall_s": round(wall, 2), "takes_per_s": round(n / wall, 3),
            "compute_s": round(compute, 2), "worker_cpu_s": round(cpu, 2),
            # share of its cores the run got: < 1 when other processes take CPU time
            "cpu_share": round(cpu / (wall * workers), 3),
            "takes_per_cpu_s": round(n / cpu, 3) if cpu > 0 else None,
            "overhead_per_take_s": round((wall * workers - compute) / n, 4),
            "load_before": [round(x, 2) for x in load0],
            "load_after": [round(x, 2) for x in load1]}


def noop_overhead(n: int) -> float:
    """Median round trip (s) per no-op task on one worker, tasks submitted together."""
    from dask.distributed import wait
    from rtseg.archive.executors import dask_client
    with dask_client(workers=1) as client:
        client.wait_for_workers(1)
        times = []
        for _ in range(3):
            t0 = time.perf_counter()
            wait(client.map(noop, range(n), pure=False))
            times.append((time.perf_counter() - t0) / n)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--takes", type=int, default=200, help="synthetic takes (default 200)")
    ap.add_argument("--min-s", type=float, default=30.0)
    ap.add_argument("--max-s", type=float, default=120.0)
    ap.add_argument("--method", default="contrast",
                    help="method(s), comma-separated, or all (default contrast)")
    ap.add_argument("--workers", default="1,2", help="worker counts (default 1,2)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per worker count (median)")
    ap.add_argument("--archive", type=Path, help="folder of the synthetic takes "
                    "(default: $TMPDIR/rtseg-archive-bench-N-MIN-MAX, kept)")
    ap.add_argument("--no-real", action="store_true", help="leave out ../shared/data/cmu")
    ap.add_argument("--noop", type=int, default=500, help="no-op tasks for the round trip")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    from rtseg.archive.runner import discover_takes
    from rtseg.detectors.segmentation import METHODS
    methods = list(METHODS) if args.method == "all" else args.method.split(",")
    folder = args.archive or Path(tempfile.gettempdir()) / (
        f"rtseg-archive-bench-{args.takes}-{args.min_s:g}-{args.max_s:g}")
    t0 = time.perf_counter()
    synth = make_archive(folder, args.takes, args.min_s, args.max_s)
    gen_s = time.perf_counter() - t0
    real = [] if args.no_real or not REAL.is_dir() else discover_takes([REAL])
    paths = synth + real
    # longest first: the last takes do not leave one worker idle while the other finishes
    sizes = {p: Path(p).stat().st_size for p in paths}
    paths.sort(key=lambda p: -sizes[p])
    todo = [(p, methods) for p in paths]
    runs: dict[int, list[dict[str, Any]]] = {}
    counts = [int(w) for w in args.workers.split(",")]
    for _ in range(args.repeat):
        for w in counts:                      # interleaved: load changes hit all counts
            r = run_once(todo, w)
            runs.setdefault(w, []).append(r)
            if not args.json:
                print(f"  {w} worker(s): {r['takes_per_s']:.3f} takes/s "
                      f"(wall {r['wall_s']} s, start-up {r['startup_s']} s, "
                      f"cpu share {r['cpu_share']:.2f}, load "
                      f"{r['load_before'][0]} -> {r['load_after'][0]})", file=sys.stderr)
    best = {w: statistics.median(x["takes_per_s"] for x in rs) for w, rs in runs.items()}
    rt = noop_overhead(args.noop) if args.noop else None
    one = runs[counts[0]][0]
    per_take = one["compute_s"] / one["takes"]
    doc = {
        "archive": {"synthetic": len(synth), "real": len(real), "folder": str(folder),
                    "generated_in_s": round(gen_s, 1), "seconds": [args.min_s, args.max_s],
                    "methods": methods},
        "cpus": os.cpu_count(),
        "runs": runs,
        "takes_per_s": best,
        "scaling_2_over_1": (round(best[2] / best[1], 3) if 1 in best and 2 in best else None),
        "cpu_scaling_2_over_1": (round(
            statistics.median(x["takes_per_cpu_s"] for x in runs[2])
            / statistics.median(x["takes_per_cpu_s"] for x in runs[1]), 3)
            if 1 in runs and 2 in runs else None),
        "noop_round_trip_s": None if rt is None else round(rt, 5),
        "compute_per_take_s": round(per_take, 3),
        "archive_10000_hours": {str(w): round(10000 / r / 3600, 2) for w, r in best.items()},
        # CPU time alone (what an idle core would take): 10 000 / takes per CPU second
        "archive_10000_cpu_hours": round(10000 / one["takes_per_cpu_s"] / 3600, 2)
        if one["takes_per_cpu_s"] else None,
    }
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"archive: {len(synth)} synthetic takes ({args.min_s:g}-{args.max_s:g} s) + "
          f"{len(real)} real, methods {','.join(methods)}, {os.cpu_count()} CPUs")
    for w, rs in runs.items():
        r = rs[0]
        print(f"{w} worker(s): {best[w]:.3f} takes/s (median of {len(rs)}), start-up "
              f"{r['startup_s']} s, overhead/take {r['overhead_per_take_s'] * 1000:.1f} ms, "
              f"workers got {r['cpu_share']:.0%} of {w} core(s), "
              f"{r['takes_per_cpu_s']} takes per CPU s, "
              f"load avg {r['load_before'][0]} -> {r['load_after'][0]}")
    if doc["scaling_2_over_1"] is not None:
        print(f"scaling 2 workers / 1 worker: {doc['scaling_2_over_1']:.2f}x (target >= 1.7x)"
              f"; per CPU second {doc['cpu_scaling_2_over_1']:.2f}x (1.0 = no overhead added "
              f"by the second worker; the rest is the cores the machine gave)")
    if rt is not None:
        print(f"no-op task round trip on 1 worker: {rt * 1000:.2f} ms")
    print(f"compute per take: {per_take:.2f} s wall; a 10 000-take archive like this one: "
          + ", ".join(f"{h} h on {w} worker(s)" for w, h in doc["archive_10000_hours"].items())
          + f" at this load; {doc['archive_10000_cpu_hours']} CPU hours, i.e. about "
          f"{doc['archive_10000_cpu_hours']} h / N on N idle cores")
    return 0


if __name__ == "__main__":
    sys.exit(main())
