#!/usr/bin/env python3
"""What one wake-up costs on this machine, apart from rtseg's work: the floor under the live
loop's CPU per suit.

    python3 benchmarks/wakeup.py [--seconds 8] [--rate 120] [--json]

Two measurements, thread CPU time (``time.thread_time``: user + system of the measuring
thread), one process, a writer thread sending one small write to a pty ``--rate`` times a
second:

1. **Empty wake-up**: a loop that sleeps in ``poll(2)`` on the pty and reads what arrived,
   nothing else: µs of CPU per wake-up and its fraction of one core at ``--rate``.  No
   Python program woken at that rate costs less.
2. **The same work hot and woken**: the serial driver's decode of one 17-sensor frame
   (``SerialSource._consume`` + ``take``, no I/O) timed in a tight loop, then once per
   wake-up of the loop above: µs per frame each way and their ratio.  After a sleep the
   caches and branch predictors hold other programs' state (on a virtual machine the
   hypervisor's too), so every wake-up pays for reloading the interpreter's and numpy's
   working set; the ratio says how much that multiplies a frame's Python work.
"""

from __future__ import annotations

import argparse
import json
import os
import pty
import selectors
import sys
import threading
import time
import tty
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


class _Ticker:
    """A thread writing one byte to a pty ``rate`` times a second; ``fd`` is the side to
    read."""

    def __init__(self, rate: float) -> None:
        self._m, self.fd = pty.openpty()
        tty.setraw(self.fd)
        os.set_blocking(self.fd, False)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(1.0 / rate,), daemon=True)
        self._thread.start()

    def _run(self, period: float) -> None:
        t = time.monotonic()
        while not self._stop.is_set():
            t += period
            d = t - time.monotonic()
            if d > 0:
                time.sleep(d)
            os.write(self._m, b"x")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        os.close(self._m)
        os.close(self.fd)


def _woken(seconds: float, rate: float, work=None) -> tuple[int, float, float]:
    """(wake-ups, thread CPU s of the whole loop, thread CPU s inside ``work``)."""
    tick = _Ticker(rate)
    sel = selectors.DefaultSelector()
    sel.register(tick.fd, selectors.EVENT_READ)
    n, in_work = 0, 0.0
    try:
        t_all = time.thread_time()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for _key, _ev in sel.select(0.05):
                os.read(tick.fd, 4096)
                if work is not None:
                    a = time.thread_time()
                    work(n)
                    in_work += time.thread_time() - a
                n += 1
        t_all = time.thread_time() - t_all
    finally:
        sel.close()
        tick.close()
    return n, t_all, in_work


def _decode_work():
    """``work(i)``: the serial driver's handling of one encoded 17-sensor frame."""
    from rtseg.core.profiles import suit_profile
    from rtseg.drivers import open_source
    from rtseg.drivers.serial import codec
    m, s = pty.openpty()
    tty.setraw(s)
    src = open_source(f"serial://{os.ttyname(s)}")
    src.take_over()
    ids = list(suit_profile("default17").sensor_ids)
    rng = np.random.default_rng(0)
    q = rng.normal(size=(4096, len(ids), 4))
    q /= np.linalg.norm(q, axis=2, keepdims=True)
    msgs = [codec.encode_frame(i & 0xFFFF, i * 8333, ids, q[i]) for i in range(4096)]
    out: list = []

    def work(i: int) -> None:
        if i % 4096 == 0:               # the sequence starts again: not a device restart
            src._last_seq = src._last_time_raw = None
        src._consume(msgs[i % 4096], time.monotonic())
        src.take(out)
        out.clear()

    def close() -> None:
        src.close()
        os.close(m)
        os.close(s)
    return work, close


def measure(seconds: float = 8.0, rate: float = 120.0) -> dict:
    n, cpu, _ = _woken(seconds / 2, rate)
    work, close = _decode_work()
    try:
        for i in range(500):             # warm-up, then the tight loop
            work(i)
        t = time.thread_time()
        k = 3000
        for i in range(k):
            work(i)
        hot = (time.thread_time() - t) / k
        nw, _cpu_w, in_work = _woken(seconds / 2, rate, work)
    finally:
        close()
    return {"rate_hz": rate,
            "empty_wakeup_us": round(cpu / max(n, 1) * 1e6, 1),
            "empty_cpu_fraction": round(cpu / (seconds / 2), 4),
            "decode_tight_us": round(hot * 1e6, 1),
            "decode_woken_us": round(in_work / max(nw, 1) * 1e6, 1),
            "woken_over_tight": round(in_work / max(nw, 1) / hot, 2)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=8.0, help="length of both woken loops")
    p.add_argument("--rate", type=float, default=120.0, help="wake-ups per second")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    args = p.parse_args(argv)
    if args.seconds <= 0 or args.rate <= 0:
        p.error("--seconds and --rate must be > 0")
    r = measure(args.seconds, args.rate)
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"empty wake-up at {r['rate_hz']:g} Hz: {r['empty_wakeup_us']} µs of CPU each, "
          f"{100 * r['empty_cpu_fraction']:.2f} % of a core")
    print(f"one frame's serial decode: {r['decode_tight_us']} µs in a tight loop, "
          f"{r['decode_woken_us']} µs once per wake-up (x{r['woken_over_tight']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
