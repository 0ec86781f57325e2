#!/usr/bin/env python3
"""Where an Axis text frame's time goes, step by step (microseconds per frame).

    python3 benchmarks/axis_steps.py [--frames 3000] [--repeat 5] [--cpu-time] [--no-kernel] [--json]

The Axis text source's pipeline (``rtseg.drivers.axis.source.TextStream``) taken apart into
its steps - split on ``||``, field check, orjson, arrays, ``AxisFrame`` stack, Euler
half-angles, products and forward kinematics (in the compiled kernel where it is built,
else numpy), ``Frame`` objects - each timed around it, for 4 KiB and 64 KiB reads in local
and global space.  Per step the minimum over ``--repeat`` passes; the frames the steps make
are checked bit for bit against ``TextStream``'s (a mismatch raises).  ``--no-kernel``:
the numpy path even where the kernel is built (``RTSEG_NO_KERNEL=1``); ``--cpu-time``:
this process's CPU time instead of the wall clock.  Frames: ``codec_feeds.axis_values``
(59 joints, smooth motion, zero bone offsets).  Throughput of the whole codecs:
``benchmarks/decode.py``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from codec_feeds import axis_values, numpy_axis_path

READ_4K = 4096
#: timer around each step: wall clock, or this process's CPU time with --cpu-time
_clock = time.perf_counter


def axis_steps(n: int, repeat: int) -> dict:
    """Where an Axis text frame's time goes: the text source's pipeline (``TextStream``)
    taken apart into its steps, each timed with ``_clock`` around it, for 4 KiB and
    64 KiB reads in local and global space; the minimum over ``repeat`` passes of each
    step, in microseconds per frame.  The steps call the same functions as the pipeline
    (the frames' values are checked against ``TextStream``'s bit for bit)."""
    from rtseg.drivers.axis import pose as P
    from rtseg.drivers.axis import codec as A
    from rtseg.drivers.axis import text as T
    from rtseg.drivers.axis.source import AxisFrames, TextStream
    from rtseg.core.frame import Frame
    v = axis_values(n)
    stream = b"".join(T.encode_text(v[i]) for i in range(n))
    out: dict = {}
    for chunk in (READ_4K, 65536):
        reads = [stream[k:k + chunk] for k in range(0, len(stream), chunk)] + [b"||"]
        for space in ("local", "global"):
            best: dict[str, float] = {}
            for _ in range(repeat):
                acc = dict.fromkeys(("split", "fields_check", "orjson", "array",
                                     "axisframe_stack", "euler", "fk", "frame"), 0.0)
                split, conv = T.TextSplitter(), AxisFrames(lambda *a: None, space=space)
                frames = []
                for d in reads:
                    t0 = _clock()
                    chunks = split.feed(d)
                    t1 = _clock()
                    acc["split"] += t1 - t0
                    if not chunks:
                        continue
                    heads, rows = [], []
                    for c in chunks:
                        index, name, body = T._fields(c)
                        heads.append((index, name))
                        rows.append(body.translate(T._TO_JSON, T._NOT_JSON))
                    t2 = _clock()
                    lists = T._json_lists(rows)
                    t3 = _clock()
                    arrays = [T._array(x) for x in lists]
                    t4 = _clock()
                    fs = [A.AxisFrame(i, nm, x, *A.layout(x.size), finite=True)
                          for (i, nm), x in zip(heads, arrays)]
                    vals = arrays[0] if len(fs) == 1 else np.array(arrays)
                    t5 = _clock()
                    kernel = P.axis_kernel
                    if kernel.ENABLED:
                        # the compiled kernel: half-angle cosines and sines in numpy
                        # ("euler"), products and forward kinematics in C ("fk"; the
                        # local quaternions come out of the same call)
                        if vals.ndim == 1:
                            half = vals.take(P._angle_index(True, False, 59)[:, :-1])
                            np.multiply(half, P._HALF_RAD, out=half)
                        else:
                            half = P._half_angles(P._channels(vals, True, False, 59)[1])
                        u = P._cos_sin(half)
                        root = vals[..., :3]
                        t6 = _clock()
                        loc, q = kernel.euler_fk(u, 59, P._order_axes("YXZ"), P.PARENTS)
                        q = (loc if space == "local" else q).reshape(vals.shape[:-1] + (59, 4))
                        t7 = _clock()
                    else:
                        if space == "local" or vals.ndim == 2:
                            root, angles = P._channels(vals, True, False, 59)
                            tt = P._euler_terms(angles, identity_row=space == "global")
                        else:
                            half = vals.take(P._angle_index(True, False, 59))
                            np.multiply(half, P._HALF_RAD, out=half)
                            half[:, -1] = 0.0
                            tt = P._half_terms(half)
                            root = vals[:3]
                        T_, T4 = P._euler_tables("YXZ")
                        if space == "local":
                            q = (tt.T @ T_).reshape(angles.shape[:-1] + (4,))
                            t6 = t7 = _clock()
                        else:                            # quaternion pointer jumping
                            q = (tt.T @ T4).reshape(vals.shape[:-1] + (60, 16))
                            t6 = _clock()
                            q = P._fk(q)
                            t7 = _clock()
                    pos = root * 0.01
                    qs, ps = ([q], [pos]) if vals.ndim == 1 else (list(q), list(pos))
                    frames += [Frame(0.0, qs[k], P._ALL_VALID.copy(), None, conv._seq(f, 0.0),
                                     ps[k]) for k, f in enumerate(fs)]
                    t8 = _clock()
                    for key, dt in (("fields_check", t2 - t1), ("orjson", t3 - t2),
                                    ("array", t4 - t3), ("axisframe_stack", t5 - t4),
                                    ("euler", t6 - t5), ("fk", t7 - t6), ("frame", t8 - t7)):
                        acc[key] += dt
                for key, dt in acc.items():
                    best[key] = min(best.get(key, dt), dt)
            ref = TextStream(AxisFrames(lambda *a: None, space=space))
            want = [f for d in reads for f in ref.feed(d, 0.0)]
            if [f.quats.tobytes() for f in want] != [f.quats.tobytes() for f in frames]:
                raise RuntimeError("Axis steps: frames differ from TextStream's")
            row = {k: round(x / n * 1e6, 2) for k, x in best.items()}
            row["total"] = round(sum(best.values()) / n * 1e6, 2)
            out[f"{'4k' if chunk == READ_4K else '64k'}_{space}"] = row
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=3000, help="frames per pass (default 3000)")
    p.add_argument("--repeat", type=int, default=5, help="passes; the minimum per step is "
                   "reported (default 5)")
    p.add_argument("--cpu-time", action="store_true", help="time with this process's CPU "
                   "time (time.process_time) instead of the wall clock")
    p.add_argument("--no-kernel", action="store_true", help="the numpy path even where "
                   "the compiled kernel is built")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args(argv)
    if args.frames < 10 or args.repeat < 1:
        p.error("--frames must be >= 10 and --repeat >= 1")
    if args.no_kernel:
        numpy_axis_path()
    if args.cpu_time:
        global _clock
        _clock = time.process_time
    steps = axis_steps(args.frames, args.repeat)
    if args.json:
        print(json.dumps(steps))
        return 0
    for key, row in steps.items():
        print(f"axis text {key}: " + ", ".join(f"{k} {x}" for k, x in row.items())
              + " us/frame")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
