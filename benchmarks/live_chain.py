"""The real chain the live benchmarks drive (``benchmarks/live.py``): the simulated
17-sensor suit in another process on a real pty (``Suit``), N suits served by one other
process (``Suits``, ``python3 benchmarks/live_chain.py --serve-suits N``), an in-process
source paced at a given rate (``PacedSource``), one session played through them with its
CPU and latency (``run_session``), N sessions on one thread (``run_suits``), the cost of
each stage of a frame (``StageMeter``), and the UDP socket the cuts are sent to
(``sink``).  Times: ``time.monotonic`` seconds; CPU: ``time.process_time`` /
``time.thread_time``.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from rtseg.live.session import LiveSession  # noqa: E402
from rtseg.live.config import from_dict  # noqa: E402


class Suit:
    """The simulated suit in a subprocess; ``path`` is its pty."""

    def __init__(self, rate: float, speed: float = 1.0) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "rtseg.simulators.serial_device", "--rate", f"{rate:g}",
             "--speed", f"{speed:g}"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=REPO)
        line = self.proc.stdout.readline().strip()
        if not line:
            self.close()
            raise RuntimeError("simulated suit did not start")
        self.path = line
        self.t_start = time.monotonic()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)


class Suits:
    """``n`` simulated suits at ``rate`` Hz in one subprocess (``--serve-suits``), one pty
    each; ``paths`` are their devices."""

    def __init__(self, n: int, rate: float = 120.0) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--serve-suits", str(n),
             "--rate", f"{rate:g}"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, text=True, cwd=REPO)
        self.paths = [self.proc.stdout.readline().strip() for _ in range(n)]
        if not all(self.paths):
            self.close()
            raise RuntimeError("simulated suits did not start")

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.proc.stdin.close()         # the server stops when its stdin closes
                self.proc.wait(10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(5)


def serve_suits(n: int, rate: float) -> int:
    """``--serve-suits N``: N suits playing the synthesised performance at ``rate`` Hz,
    each from its own point of it, their frames' phases spread over one frame period;
    prints each pty path; stops when stdin closes."""
    from rtseg.core.take import Take
    from rtseg.simulators.serial_device import SerialSuit
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize(frame_rate=120.0).take
    suits = []
    try:
        for i in range(n):
            # each suit plays the performance from its own point (performers do not move
            # in step: their cuts, and the detector's work, come at different times)
            part = Take(take.joint_names, take.parents, take.frame_rate,
                        np.roll(take.quats, -i * take.n_frames // n, axis=0),
                        space=take.space, source="synth")
            suit = SerialSuit(part, rate=rate, loop=True)
            print(suit.start(), flush=True)
            suits.append(suit)
            time.sleep(1.0 / (rate * n))
        sys.stdin.read()
    finally:
        for suit in suits:
            suit.stop()
    return 0


class StageMeter:
    """Thread CPU time spent in each stage of a session's per-frame path (see the module
    docstring, 1c), installed by wrapping the session's objects' methods."""

    STAGES = ("decode", "receive", "features", "detector", "identity", "pipeline", "publish",
              "ahead")

    def __init__(self) -> None:
        self.us = dict.fromkeys(self.STAGES, 0.0)
        self.active = False

    def reset(self) -> None:
        self.us = dict.fromkeys(self.STAGES, 0.0)
        self.active = True

    def wrap(self, obj: object, name: str, stage: str) -> None:
        inner = getattr(obj, name)
        us = self
        clock = time.thread_time

        def timed(*args, **kwargs):
            t = clock()
            try:
                return inner(*args, **kwargs)
            finally:
                if us.active:
                    us.us[stage] += (clock() - t) * 1e6
        setattr(obj, name, timed)

    def install(self, session: LiveSession) -> None:
        """Wrap the parts of ``session`` once it is open (pipeline and publishers built)."""
        pipe = session.pipeline
        self.wrap(session.source, "poll", "decode")
        self.wrap(session, "_receive", "receive")
        self.wrap(pipe.features, "step", "features")
        for det in pipe.detectors.values():
            self.wrap(det, "update", "detector")
        if pipe.identity is not None:
            self.wrap(pipe.identity, "step", "identity")
        self.wrap(pipe, "process", "pipeline")       # then less the three above
        self.wrap(pipe, "identify_pending", "pipeline")   # identity's step after the cuts
        self.wrap(pipe, "ahead", "ahead")
        for name in ("publish_cut", "publish_status", "publish_dropout", "publish_behaviour"):
            if hasattr(session.publishers, name):
                self.wrap(session.publishers, name, "publish")

    def per_frame(self, frames: int, total_us: float) -> dict[str, float]:
        us = dict(self.us)
        us["pipeline"] -= us["features"] + us["detector"] + us["identity"]
        out = {k: v / max(frames, 1) for k, v in us.items()}
        out["total"] = total_us / max(frames, 1)
        out["loop"] = out["total"] - sum(out[k] for k in self.STAGES)
        return {k: round(v, 1) for k, v in out.items()}


def run_suits(n: int, seconds: float, port: int, warmup: float = 2.0,
              stages: bool = False) -> dict:
    """``n`` suits at 120 Hz, one session each on this thread, for ``warmup + seconds``;
    measured over the last ``seconds``.  ``stages``: one suit, identity on, the
    :class:`StageMeter` installed (its figures under ``"stages_us"``)."""
    from rtseg.live.loop import run_sessions
    suits = Suits(n)
    meter = StageMeter() if stages else None
    try:
        sessions = []
        for i, path in enumerate(suits.paths):
            cfg = config(port)
            if stages:
                cfg["identity.enabled"] = True
            s = LiveSession(f"serial://{path}?rate=120", cfg, handle_signals=False,
                            duration=seconds + warmup, name=f"s{i + 1}" if n > 1 else "")
            if meter is not None:            # once the session is open, before its input
                def start_input(loop, s=s, inner=s._start_input):
                    meter.install(s)
                    inner(loop)
                s._start_input = start_input
            sessions.append(s)
        marks: dict[str, float] = {}
        # CPU clock of the loop thread (this one), readable from the timer's thread
        loop_clock = time.pthread_getcpuclockid(threading.get_ident())

        def start_measuring() -> None:
            for s in sessions:
                restart_counts(s.stats)
            if meter is not None:
                meter.reset()
            marks.update(cpu=time.process_time(), thread=time.clock_gettime(loop_clock),
                         wall=time.monotonic(),
                         frames=sum(s.stats.frames_processed for s in sessions))

        def end_measuring(ev) -> None:   # at the first session's final status
            if getattr(ev, "alive", 1) == 0 and "thread_end" not in marks:
                marks["thread_end"] = time.clock_gettime(loop_clock)
                marks["frames_end"] = sum(s.stats.frames_processed for s in sessions)

        timer = threading.Timer(warmup, start_measuring)
        timer.start()
        sessions[0].listeners.append(end_measuring)
        summaries = run_sessions(sessions, handle_signals=False)
        timer.cancel()
        wall = time.monotonic() - marks["wall"]
        cpu = (time.process_time() - marks["cpu"]) / wall
    finally:
        suits.close()
    lat = np.concatenate([s.stats.open_latency_ms.values() for s in sessions])
    every = np.concatenate([s.stats.frame_latency_ms.values() for s in sessions])
    frames = sum(s.stats.frames_processed for s in sessions) - marks["frames"]
    quiet = {k: sum(quiet_counts(s)[k] for s in sessions)
             for k in ("batches", "frames", "late_open")}
    out = {"suits": n, "seconds": round(wall, 1),
           "cpu_fraction": round(cpu, 4), "cpu_fraction_per_suit": round(cpu / n, 4),
           "fps_per_suit": round(frames / wall / n, 1),
           "latency_ms": pcts(lat), "every_frame_latency_ms": pcts(every), "quiet": quiet,
           "frames": int(frames), "dropped": int(sum(x.dropped for x in summaries)),
           "cuts": int(sum(x.cuts for x in summaries))}
    if meter is not None:
        # CPU of the loop thread only (the process also runs the timer, publishers' TCP
        # threads if any), frames processed
        thread_us = (marks["thread_end"] - marks["thread"]) * 1e6
        out["stages_us"] = meter.per_frame(int(marks["frames_end"] - marks["frames"]),
                                           thread_us)
    return out


def sink() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return s


def config(port: int, batch_quiet: bool = True):
    """The session settings: defaults, OSC to ``port``; ``batch_quiet`` False reads every
    frame as it arrives (``buffer.batch_quiet``)."""
    return from_dict({"output": {"osc": [f"127.0.0.1:{port}"]},
                      "status": {"interval": 1.0},
                      "buffer": {"batch_quiet": batch_quiet}}, origin="benchmark")


class PacedSource:
    """In-process 17-sensor source replaying the synthesised performance at ``rate``
    frames/s (frame k due at t0 + k / rate; ``recv_time`` = when it is handed over).
    Measures the session core (ring buffer, features, detectors, OSC) without a driver."""

    def __new__(cls, rate: float):
        from rtseg.drivers.base import Source
        from rtseg.core.frame import Frame
        from rtseg.core.quat import global_from_local
        from rtseg.simulators.synth.motion import JOINT_NAMES, PARENTS, synthesize

        take = synthesize(frame_rate=120.0).take
        g = global_from_local(take.quats, take.parents)

        class _Paced(Source):
            frame_rate = 120.0
            space = "global"

            def __init__(self) -> None:
                super().__init__()
                self.joint_names, self.parents = list(JOINT_NAMES), list(PARENTS)
                self.k = 0
                self.t0: float | None = None
                self.ok = np.ones(len(JOINT_NAMES), bool)

            def read(self, timeout=None):
                now = time.monotonic()
                if self.t0 is None:
                    self.t0 = now
                due = self.t0 + self.k / rate
                if due > now:
                    if timeout is not None and due - now > timeout:
                        time.sleep(timeout)
                        return None
                    time.sleep(due - now)
                f = Frame(time.monotonic(), g[self.k % len(g)], self.ok, None, self.k & 0xFFFF)
                self.k += 1
                self.stats.frames_ok += 1
                return f

        return _Paced()


def run_session(rate: float, seconds: float, port: int, warmup: float = 1.0,
                kind: str = "serial", monitor: bool = False, batch_quiet: bool = True):
    """Play the suit at ``rate`` for ``warmup + seconds``; latency statistics cover the
    last ``seconds`` only (start-up reads a burst of frames the pty buffered).
    ``monitor``: serve the live monitor (``rtseg.monitor``, in this process) and open its
    page in headless Chromium (another process) during the run; the warm-up is then 3 s
    (the page loads and connects first).
    Returns (session, summary, cpu fraction over the measured part)."""
    # the device clock keeps the take's 120 Hz (the rate= declared), sent rate/120 x faster
    suit = Suit(120.0, speed=rate / 120.0) if kind == "serial" else None
    feed = server = page = sender = None
    try:
        if kind == "vmc":                    # a VMC performer in another process, over UDP
            from rtseg.drivers import open_source
            source = open_source("osc://127.0.0.1:0?format=vmc&rate=120")
            sender = subprocess.Popen(
                [sys.executable, "-m", "rtseg.cli", "simulate", "vmc", "--rate", "120",
                 "--speed", f"{rate / 120.0:g}", "--loop", "--port", str(source.port)],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=REPO)
        else:
            source = f"serial://{suit.path}?rate=120" if suit else PacedSource(rate)
        if monitor:
            from rtseg.monitor import MonitorFeed
            from rtseg.monitor.headless import HeadlessPage
            from rtseg.monitor.server import MonitorServer
            feed = MonitorFeed()
            server = MonitorServer(feed, "127.0.0.1", 0)
            page = HeadlessPage(server.start())
            warmup = max(warmup, 3.0)
        session = LiveSession(source, config(port, batch_quiet), handle_signals=False,
                              duration=seconds + warmup, monitor=feed)
        marks: dict[str, float] = {}

        def start_measuring() -> None:
            restart_counts(session.stats)
            marks.update(cpu=time.process_time(), wall=time.monotonic(),
                         frames=session.stats.frames_received)

        timer = threading.Timer(warmup, start_measuring)
        timer.start()
        summary = session.run()
        timer.cancel()
        cpu = (time.process_time() - marks["cpu"]) / (time.monotonic() - marks["wall"])
        measured_fps = ((session.stats.frames_received - marks["frames"])
                        / (time.monotonic() - marks["wall"]))
        if page is not None:
            pages = page.evaluate("window.rtsegMonitor.cuts.length")
            if pages != summary.cuts:
                print(f"   warning: the page shows {pages} cuts of {summary.cuts}",
                      file=sys.stderr)
    finally:
        if suit is not None:
            suit.close()
        if sender is not None:
            sender.terminate()
            sender.wait(5)
        if page is not None:
            page.close()
        if server is not None:
            server.stop()
    return session, summary, cpu, measured_fps


def restart_counts(st) -> None:
    """Latencies and quiet-frame counts of ``LiveStats`` from the measured part on."""
    st.frame_latency_ms.clear()
    st.open_latency_ms.clear()
    st.cut_latency_ms.clear()
    st.quiet_batches = st.quiet_frames = st.late_open = 0


def quiet_counts(session) -> dict[str, int]:
    st = session.stats
    return {"batches": st.quiet_batches, "frames": st.quiet_frames, "late_open": st.late_open}


def pcts(lat: np.ndarray) -> dict[str, float | None]:
    """p50 / p99 / max of latencies in ms (None when there are none: in a run shorter
    than the detector's first look no frame could send)."""
    if not lat.size:
        return {"p50": None, "p99": None, "max": None}
    return {"p50": round(float(np.percentile(lat, 50)), 3),
            "p99": round(float(np.percentile(lat, 99)), 3), "max": round(float(lat.max()), 3)}


def main(argv: list[str] | None = None) -> int:
    """``--serve-suits N [--rate HZ]``: ``serve_suits`` (the server process of ``Suits``)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--serve-suits", type=int, metavar="N", required=True)
    p.add_argument("--rate", type=float, default=120.0)
    args = p.parse_args(argv)
    return serve_suits(args.serve_suits, args.rate)


if __name__ == "__main__":
    sys.exit(main())
