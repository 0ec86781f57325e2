"""End-to-end serial link: simulated suit -> real pty -> SerialSource -> Frame.

For each frame rate, sends ``--seconds`` of a 17-sensor take through a pseudo-terminal and
reports frames received, frames lost, and the delay from each frame's scheduled send time
to its ``Frame.recv_time`` (median, p99; this includes the sender thread's own scheduling
delay), plus the time to resume reading after a simulated unplug.

    python3 benchmarks/serial_link.py [--rates 120,1000,2000] [--seconds 2] [--unplug 0.5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rtseg.drivers import open_source
from rtseg.core.profiles import suit_profile
from rtseg.simulators.serial_device import SerialSuit


def frames_for(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, len(suit_profile().bones), 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def throughput(rate: float, seconds: float, fmt: str) -> str:
    n = int(rate * seconds)
    suit = SerialSuit(frames_for(n), rate=rate, fmt=fmt)
    suit.start(send=False)
    opts = "queue=1000000" + ("&format=text" if fmt == "text" else "")
    src = open_source(f"serial://{suit.path}?{opts}")
    try:
        suit.begin()
        got = []
        deadline = time.monotonic() + seconds + 5
        while len(got) < n and time.monotonic() < deadline:
            f = src.read(0.2)
            if f is not None:
                got.append(f)
        due = suit.t0 + np.arange(len(got)) / rate
        lag = (np.array([f.recv_time for f in got]) - due) * 1e3
        return (f"{fmt:5s} {rate:7.0f} Hz: {len(got)}/{n} frames, lost {src.stats.dropped}, "
                f"delay median {np.median(lag):.2f} ms, p99 {np.percentile(lag, 99):.2f} ms")
    finally:
        src.close()
        suit.stop()


def resume_after_unplug(unplug_s: float) -> float:
    suit = SerialSuit(frames_for(120), rate=120.0, loop=True)
    suit.start(send=False)
    src = open_source(f"serial://{suit.path}")
    try:
        suit.begin()
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            src.read(0.05)
        suit.unplug(unplug_s)
        while not suit.unplug_log:
            src.read(0.01)
        back = suit.unplug_log[0][1]
        while True:
            f = src.read(0.01)
            if f is not None and f.recv_time > back:
                return f.recv_time - back
    finally:
        src.close()
        suit.stop()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rates", default="120,1000,2000", help="frame rates in Hz, comma separated")
    p.add_argument("--seconds", type=float, default=2.0, help="seconds sent per rate")
    p.add_argument("--unplug", default="0.1,0.5,2", help="unplug durations in s, comma separated")
    args = p.parse_args()
    for fmt in ("rtseg", "text"):
        for rate in (float(r) for r in args.rates.split(",")):
            print(throughput(rate, args.seconds, fmt), flush=True)
    for d in (float(x) for x in args.unplug.split(",")):
        print(f"unplugged {d:g} s: reading resumed {1e3 * resume_after_unplug(d):.0f} ms "
              "after the device returned", flush=True)


if __name__ == "__main__":
    main()
