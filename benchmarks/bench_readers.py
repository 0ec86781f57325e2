"""Reading speed of the take readers on the real CMU files (../shared/data or $RTSEG_DATA).

    python3 benchmarks/bench_readers.py [--repeat 3]

Prints, per file, the best wall time of ``read_take`` over the repeats and frames per second,
plus the npz round trip of 86_01 and the feature extraction of the whole take.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from rtseg.drivers.readers import read_take, write_take
from rtseg.core.features import take_features

DATA = Path(os.environ.get("RTSEG_DATA", Path(__file__).resolve().parent.parent.parent / "shared" / "data"))


def best(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if not (DATA / "cmu").is_dir():
        raise SystemExit(f"no CMU data at {DATA} (set RTSEG_DATA)")
    files = sorted((DATA / "cmu").glob("*.amc")) + sorted((DATA / "tsseg4d").glob("*.csv"))[:1]
    for f in files:
        t, take = best(lambda f=f: read_take(f), args.repeat)
        print(f"read {f.name:12s} {take.n_frames:6d} frames  {t * 1000:8.1f} ms  {take.n_frames / t:10.0f} frames/s")
    take = read_take(DATA / "cmu" / "86_01.amc")
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "86_01.npz"
        t, _ = best(lambda: write_take(p, take), args.repeat)
        print(f"write 86_01.npz {t * 1000:8.1f} ms  ({p.stat().st_size / 1e6:.2f} MB)")
        t, _ = best(lambda: read_take(p), args.repeat)
        print(f"read  86_01.npz {t * 1000:8.1f} ms")
    t, X = best(lambda: take_features(take), args.repeat)
    print(f"take_features 86_01 -> {X.shape}  {t * 1000:8.1f} ms")


if __name__ == "__main__":
    main()
