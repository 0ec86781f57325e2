"""What the simulators and the demo report is what happened: TCP simulators wait for their
peer (or say each frame they wrote to nobody), the serial suit reports its waiting apart
from its sending, and a demo whose loop cannot keep up with ``--speed`` says so (and one
that processed nothing fails).  Real processes, a real pty and real TCP sockets."""

from __future__ import annotations

import re
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import serial

from rtseg.drivers import open_source
from rtseg.drivers.serial.codec import SerialFrameDecoder
from vendor_helpers import free_port

REPO = Path(__file__).resolve().parent.parent
SYNTH = "idle:2,walk:2"          # 480 frames at 120 Hz


class _Simulator:
    """``rtseg simulate ARGS`` in a subprocess; its stdout collected by a thread."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "rtseg.cli", "simulate", *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, cwd=REPO)
        self.lines: list[str] = []
        self.errors: list[str] = []
        self._readers = [threading.Thread(target=self._read, args=(pipe, into), daemon=True)
                         for pipe, into in ((self.proc.stdout, self.lines),
                                            (self.proc.stderr, self.errors))]
        for r in self._readers:
            r.start()

    @staticmethod
    def _read(pipe, into: list[str]) -> None:
        for line in pipe:
            into.append(line)

    def wait_for(self, text: str, timeout: float = 30.0) -> None:
        """Until a line of stdout holds ``text``."""
        deadline = time.monotonic() + timeout
        while not any(text in ln for ln in self.lines):
            assert time.monotonic() < deadline and self.proc.poll() is None, self.lines
            time.sleep(0.02)

    def finish(self, timeout: float = 30.0) -> tuple[int, str, str]:
        """(exit status, stdout, stderr); killed if it does not end in ``timeout`` s."""
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for r in self._readers:
            r.join(5)
        return self.proc.returncode, "".join(self.lines), "".join(self.errors)


def _read_all(src, first: float = 20.0, quiet: float = 1.0) -> list:
    frames, f = [], src.read(timeout=first)
    while f is not None:
        frames.append(f)
        f = src.read(timeout=quiet)
    return frames


def _receive_late(sim: "_Simulator", waiting: str, url: str, late: float = 1.5):
    """Once ``sim`` prints ``waiting``, wait ``late`` s, then read every frame from ``url``;
    (frames, returncode, stdout, stderr) of the finished simulator."""
    src = None
    try:
        sim.wait_for(waiting)
        time.sleep(late)
        src = open_source(url)
        frames = _read_all(src)
    finally:
        if src is not None:
            src.close()
        rc, out, err = sim.finish()
    return frames, rc, out, err


def test_axis_text_simulator_waits_for_its_client_and_every_frame_arrives():
    """The receiver connects 1.5 s after the simulator started listening: nothing is lost, and the
    summary says how long it waited and that every frame it sent was taken."""
    port = free_port(socket.SOCK_STREAM)
    sim = _Simulator("axis", "--axis-format", "text", "--synth", SYNTH, "--speed", "4",
                     "--port", str(port))
    frames, rc, out, err = _receive_late(
        sim, "sending starts when the first client connects",
        f"axis://127.0.0.1:{port}?format=text&rate=120&backoff=0.05&queue=10000")
    assert rc == 0, err
    assert len(frames) == 480, out
    waited = float(re.search(r"waited ([\d.]+) s for a client before sending", out).group(1))
    assert waited >= 1.0, out
    assert re.search(r"^sent 480 frames \(\d+ bytes\) in [\d.]+ s; 0 send errors", out,
                     re.M), out


def test_axis_text_simulator_without_waiting_counts_the_frames_nobody_took():
    """``--no-wait`` and no client at all: the summary does not claim any frame was sent."""
    port = free_port(socket.SOCK_STREAM)
    rc, out, err = _Simulator("axis", "--axis-format", "text", "--synth", SYNTH, "--speed",
                              "4", "--port", str(port), "--no-wait").finish(60)
    assert rc == 0, err
    assert "frames written before a client connects are lost" in out
    assert re.search(r"^sent 0 frames \(0 bytes\) in [\d.]+ s; 480 frames lost: no client "
                     r"was connected", out, re.M), out


def test_mvn_tcp_simulator_waits_for_its_receiver():
    """MVN over TCP connects to the receiver: started 1.5 s before it listens, the
    simulator holds the take until it can connect, and no frame is lost."""
    port = free_port(socket.SOCK_STREAM)
    sim = _Simulator("mvn", "--transport", "tcp", "--synth", SYNTH, "--speed", "4",
                     "--port", str(port))
    frames, rc, out, err = _receive_late(sim, "waiting for the receiver to listen",
                                         f"mvn://127.0.0.1:{port}?transport=tcp&queue=10000")
    assert rc == 0, err
    assert "waiting for the receiver to listen" in out
    assert len(frames) == 480, out
    waited = float(re.search(r"waited ([\d.]+) s for a receiver before sending", out).group(1))
    assert waited >= 1.0, out
    assert re.search(r"^sent 480 frames \(480 datagrams\) in [\d.]+ s; 0 send errors", out,
                     re.M), out


def test_serial_simulator_reports_waiting_apart_from_sending(tmp_path):
    """The reader opens the pty 3 s after the simulator printed its path; the 4 s take goes out at
    x4.  The summary gives the wait, and a sending time (shorter than it) that does not
    count the wait."""
    link = tmp_path / "suit"
    sim = _Simulator("serial", "--synth", SYNTH, "--speed", "4", "--link", str(link),
                     "--linger", "2")
    try:
        sim.wait_for("read it with: rtseg live serial://")
        time.sleep(3.0)
        port = serial.Serial(str(link), timeout=0.05)
        dec, frames = SerialFrameDecoder(), []
        deadline = time.monotonic() + 15
        while len(frames) < 480 and time.monotonic() < deadline:
            frames += [f for f in dec.feed(port.read(4096)) if f.msg_type == 1]
        port.close()
    finally:
        rc, out, err = sim.finish()
    assert rc == 0, err
    assert len(frames) == 480
    waited = float(re.search(r"waited ([\d.]+) s for a reader to open the device", out).group(1))
    sending = float(re.search(r"sent 480 frame messages in ([\d.]+) s", out).group(1))
    assert waited >= 2.5, out
    assert sending < waited, out


def _demo(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rtseg.cli", "demo", "--no-osc",
                           "--no-monitor", "--quiet", "--no-identity", *args],
                          capture_output=True, text=True, timeout=120, cwd=REPO)


def test_demo_that_processed_no_frame_fails():
    """A suit whose every frame is lost on the link (``--faults drop=1``): no frame is
    processed, and the demo says so, and why, and exits 1."""
    proc = _demo("--duration", "1.5", "--faults", "drop=1")
    assert "0 processed" in proc.stderr
    assert proc.returncode == 1, proc.stderr
    assert ("rtseg demo: error: no frame processed (0 received) in " in proc.stderr
            and "--faults drop=1 let none through" in proc.stderr), proc.stderr


def test_demo_faster_than_the_loop_warns_with_the_speed_reached():
    """``--speed 1000``: 60 s of performance in 60 ms of wall-clock time, more than the
    loop processes - the demo says how much it processed and the speed it reached (or, if
    it processed nothing, fails as above)."""
    proc = _demo("--speed", "1000")
    processed = int(re.search(r"(\d+) processed", proc.stderr).group(1))
    if processed == 0:
        assert proc.returncode == 1 and "no frame processed" in proc.stderr
        return
    assert proc.returncode == 0, proc.stderr
    m = re.search(r"rtseg demo: warning: processed (\d+) of the 7200 frames of 60 s of "
                  r"performance \(\d+ %\) in [\d.]+ s: the loop reached x([\d.]+) of real "
                  r"time", proc.stderr)
    assert m, proc.stderr
    assert int(m.group(1)) == processed and float(m.group(2)) < 1000
