#!/usr/bin/env python3
"""Speed of the detectors on one take (default: CMU 86_01, 48-dim features).

    python benchmarks/speed.py [--data DIR] [--repeat N] [--json] [--versus FILE]

The default live detector (``contrast``) runs ONLINE, one ``update()`` per frame; besides
its frames/s the per-frame cost is timed call by call over one pass (median, p99, max in
microseconds: the frames that complete a block and fit the window models are the slow
ones).  PCA and PPCA run ONLINE: one ``update()`` call per frame through ``make_online`` (the
live path), PCA fed the whole take; PCA and PPCA also offline (``pca_offline``,
``ppca_offline``: ``segment_features`` with the default variants, the contrast scans).
GMM runs batch (``segment_features``).  File reading and feature computation are not
timed.  Each figure is the median of ``--repeat`` runs.  Without the data folder a synthetic 8000-frame, 56-dim input (3 behaviours + 8 constant dims) is used,
and the output says so.  Targets: contrast online >= 50 000 frames/s on one core and its
per-frame p99 <= 200 us (issue 30); PCA and PPCA online >= 20 000 frames/s (8000 frames
< 0.4 s); GMM < 2 s for 8000 frames.
Run with OMP_NUM_THREADS=1 (one core, as the live loop's blas_threads = 1); ``--cpu-time``
times the runs in the process's CPU time (the per-frame figures stay wall time).
``--versus FILE`` (detector parameters, TOML or JSON, flat or a ``[contrast]`` table, as
``rtseg evaluate --params``): the contrast detector with those overrides and the shipped one
run alternately ``--repeat`` times each in this process; both medians and their ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def _features(data: Path | None) -> tuple[np.ndarray, float, str]:
    if data is not None:
        amc = data / "cmu" / "86_01.amc"
        if amc.exists():
            from rtseg.detectors.segmentation import compute_features
            from rtseg.drivers.readers import read_take
            take = read_take(amc, skeleton=data / "cmu" / "86.asf")
            return compute_features(take), take.frame_rate, f"CMU 86_01 ({amc})"
    rng = np.random.default_rng(0)
    parts = []
    for L in (2700, 2700, 2600):
        t = np.arange(L) / 120.0
        f = rng.uniform(0.9, 1.4) * np.array([1.0, 2.0, 3.0])
        S = np.concatenate([np.sin(2 * np.pi * f * t[:, None]), np.cos(2 * np.pi * f * t[:, None])], 1)
        parts.append(rng.normal(size=48) * 0.3 + S @ (rng.normal(size=(6, 48)) * 0.15)
                     + 0.01 * rng.normal(size=(L, 48)))
    X = np.zeros((8000, 56))
    X[:, :48] = np.concatenate(parts)
    return X, 120.0, "SYNTHETIC 8000 frames x 56 dims (data folder not found)"


#: the clock of every timing: wall time, or the process's CPU time (``--cpu-time``: steadier
#: on a machine whose other processes take turns on the same cores)
CLOCK = time.perf_counter


def _time(fn, repeat: int) -> tuple[float, int]:
    times, out = [], None
    for _ in range(repeat):
        t0 = CLOCK()
        out = fn()
        times.append(CLOCK() - t0)
    return statistics.median(times), len(out)


def online(method: str, fps: float, rows: list[np.ndarray], params: dict | None = None):
    """A run of the ``method`` detector (``params`` overrides) fed every row, one
    ``update()`` per frame; the run returns its cuts."""
    from rtseg.detectors import make_online

    def run():
        upd = make_online(method, fps, params or {}).update
        return [c for c in map(upd, rows) if c is not None]
    return run


def per_frame(det, rows: list[np.ndarray]) -> dict[str, float]:
    """Microseconds of each ``update()`` call over one pass: median, p99, max."""
    t = np.empty(len(rows))
    clock = time.perf_counter
    upd = det.update
    for i, x in enumerate(rows):
        t0 = clock()
        upd(x)
        t[i] = clock() - t0
    t *= 1e6
    return {"median": round(float(np.median(t)), 2), "p99": round(float(np.percentile(t, 99)), 2),
            "max": round(float(t.max()), 2)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    ap.add_argument("--data", type=Path,
                    default=Path(os.environ.get("RTSEG_DATA", REPO.parent / "shared" / "data")))
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--cpu-time", action="store_true",
                    help="time the runs in process CPU time instead of wall time")
    ap.add_argument("--versus", metavar="FILE",
                    help="contrast parameter overrides timed alternately with the shipped "
                         "set ('fast': config/fast.toml)")
    a = ap.parse_args(argv)
    global CLOCK
    if a.cpu_time:
        CLOCK = time.process_time
    from rtseg.detectors import make_online, segment_features
    if a.versus:             # a bad file: at once, not after the timing runs
        from rtseg.detectors.segmentation import load_params
        try:
            load_params(a.versus, "contrast")
        except (OSError, ValueError) as exc:
            ap.error(f"--versus: {exc}")

    X, fps, what = _features(a.data)
    n = len(X)
    rows = [np.ascontiguousarray(x) for x in X]

    res: dict[str, dict] = {}
    for name, fn in (("contrast", online("contrast", fps, rows)), ("pca", online("pca", fps, rows)),
                     ("ppca", online("ppca", fps, rows)),
                     ("gmm", lambda: segment_features(X, "gmm", fps)),
                     ("pca_offline", lambda: segment_features(X, "pca", fps)),
                     ("ppca_offline", lambda: segment_features(X, "ppca", fps))):
        fn()  # warm-up (imports, BLAS threads)
        med, cuts = _time(fn, a.repeat)
        res[name] = {"frames_per_s": round(n / med, 1), "median_s": round(med, 4),
                     "frames": n, "cuts": cuts}
    res["contrast"]["per_frame_us"] = per_frame(make_online("contrast", fps), rows)
    if a.versus is not None:
        res["versus"] = versus(a.versus, rows, fps, a.repeat)
    if a.json:
        print(json.dumps(res))
    else:
        print(f"input: {what}; {n} frames, {X.shape[1]} dims, median of {a.repeat} runs")
        for name, r in res.items():
            if name == "versus":
                continue
            per8k = r["median_s"] * 8000 / n
            print(f"  {name:13s} {r['frames_per_s']:>10.0f} frames/s  {r['median_s']:.3f} s "
                  f"({per8k:.3f} s per 8000 frames, {r['cuts']} cuts)")
        pf = res["contrast"]["per_frame_us"]
        print(f"  contrast per frame: median {pf['median']:.1f} us, p99 {pf['p99']:.1f} us, "
              f"max {pf['max']:.1f} us (one pass, {n} calls)")
        if "versus" in res:
            v = res["versus"]
            print(f"  contrast, alternately {a.repeat}x each: shipped {v['shipped']:.0f} frames/s, "
                  f"{Path(a.versus).name} {v['other']:.0f} frames/s; shipped / other x{v['ratio']:.2f}")
    return 0


def versus(path: Path, rows: list[np.ndarray], fps: float, repeat: int) -> dict[str, float]:
    """Frames/s (medians) of the shipped contrast detector and one with ``path``'s
    overrides, run alternately; ``ratio`` = shipped / other."""
    from rtseg.detectors.segmentation import load_params
    runs = {"shipped": online("contrast", fps, rows),
            "other": online("contrast", fps, rows, load_params(path, "contrast"))}
    speeds: dict[str, list[float]] = {"shipped": [], "other": []}
    for _ in range(repeat + 1):                 # the first round warms up
        for key, run in runs.items():
            t0 = time.perf_counter()
            run()
            speeds[key].append(len(rows) / (time.perf_counter() - t0))
    s, o = statistics.median(speeds["shipped"][1:]), statistics.median(speeds["other"][1:])
    return {"shipped": round(s, 1), "other": round(o, 1), "ratio": round(s / o, 3)}


if __name__ == "__main__":
    sys.exit(main())
