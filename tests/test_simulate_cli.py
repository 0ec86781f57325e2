"""``rtseg simulate``: end to end, as a user runs it (a subprocess), read through a real pty
by pyserial and through a real UDP socket."""

from __future__ import annotations

import os
import re
import selectors
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import serial

from rtseg import quat
from rtseg.cli import main
from rtseg.drivers.codec_serial import SerialFrameDecoder
from rtseg.simulators.synth import synthesize

SCRIPT = "idle:2,walk:2"
SEED = 4


def _spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "rtseg.cli", "simulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=os.getcwd())


def _read_until(proc: subprocess.Popen, pattern: str, timeout: float = 20.0) -> tuple[re.Match, list[str]]:
    """Read stdout lines until one matches ``pattern``; (match, lines so far)."""
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    lines: list[str] = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            if not sel.select(timeout=max(0.0, deadline - time.monotonic())):
                break
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line.rstrip("\n"))
            m = re.search(pattern, line)
            if m:
                return m, lines
    finally:
        sel.close()
    proc.kill()
    raise AssertionError(f"no line matching {pattern!r}; got {lines}; stderr: {proc.stderr.read()}")


def _finish(proc: subprocess.Popen, timeout: float = 15.0) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        raise AssertionError(f"simulate did not stop; stdout {out!r} stderr {err!r}")
    return proc.returncode, out, err


def _printed_transitions(lines: list[str]) -> list[tuple[int, int, int, str, str]]:
    pat = re.compile(r"^\s*\d+ frames\s+(\d+)-(\d+)\s+mid\s+(\d+) .*\s(\w+) -> (\w+)$")
    return [(int(m[1]), int(m[2]), int(m[3]), m[4], m[5]) for m in map(pat.match, lines) if m]


def test_simulate_serial_through_a_real_pty(tmp_path):
    truth = synthesize(SCRIPT, seed=SEED)
    glob = quat.global_from_local(truth.take.quats, truth.take.parents)  # suit order == synth order
    link = tmp_path / "suit"
    proc = _spawn("serial", "--synth", SCRIPT, "--seed", str(SEED), "--link", str(link), "--loop")
    try:
        m, lines = _read_until(proc, r"^serial device: (\S+)")
        assert m.group(1) == str(link)
        assert _printed_transitions(lines) == [
            (t.lo, t.hi, t.mid, t.before, t.after) for t in truth.transitions]
        port = serial.Serial(str(link), timeout=0.05)
        dec = SerialFrameDecoder()
        frames = []
        deadline = time.monotonic() + 10.0
        while len(frames) < 120 and time.monotonic() < deadline:
            frames += [f for f in dec.feed(port.read(4096)) if f.msg_type == 1]
        port.close()
        proc.send_signal(signal.SIGINT)
        rc, out, err = _finish(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert len(frames) >= 120, f"only {len(frames)} frames arrived; stderr {err!r}"
    for f in frames[-60:]:
        k = round(f.time_us * 120.0 / 1e6) % truth.take.n_frames   # device clock -> take frame
        assert list(f.ids) == list(range(17)) and f.valid.all()
        dots = np.abs(np.sum(f.quats * glob[k], axis=-1))
        assert dots.min() > 1 - 1e-6, (k, dots.min())             # Q14 precision
    seqs = [f.seq for f in frames[-60:]]
    assert np.all(np.diff(seqs) == 1)                               # nothing lost on the way
    assert rc == 0, err
    assert "stopped: interrupted" in out
    m = re.search(r"sent (\d+) frame messages", out)
    assert m and int(m.group(1)) >= len(frames)
    assert not link.exists()                                         # device removed on exit


def test_simulate_vmc_through_a_real_udp_socket(tmp_path):
    from rtseg.drivers.osc_source import OscVmcSource

    truth = synthesize("walk:1.5", seed=SEED)
    src = OscVmcSource("127.0.0.1", 0)
    try:
        proc = _spawn("vmc", "--synth", "walk:1.5", "--seed", str(SEED), "--host", "127.0.0.1",
                      "--port", str(src.port), "--save", str(tmp_path / "t.npz"))
        rc, out, err = _finish(proc, timeout=30.0)
        frames = []
        while True:
            f = src.read(timeout=0.3)
            if f is None:
                break
            frames.append(f)
    finally:
        src.close()
    assert rc == 0, err
    assert "stopped: end of take" in out
    assert re.search(r"sent 180 frames", out), out
    assert len(frames) >= 170                                       # UDP on loopback: ~all
    for f in frames:
        k = round(f.source_time * 120.0)
        dots = np.abs(np.sum(f.quats * truth.take.quats[k], axis=-1))
        assert dots.min() > 1 - 1e-6                                # float32 on the wire
    assert np.allclose(frames[-1].root_position, truth.take.root_position[round(frames[-1].source_time * 120)],
                       atol=1e-5)
    from rtseg.drivers.readers import read_take
    saved = read_take(tmp_path / "t.npz")
    assert np.array_equal(saved.quats, truth.take.quats)


def test_simulate_duration_stops_a_looping_device(tmp_path):
    t = time.monotonic()
    proc = _spawn("serial", "--synth", "idle:2", "--loop", "--duration", "0.5",
                  "--link", str(tmp_path / "d"))
    rc, out, err = _finish(proc)
    assert rc == 0, err
    assert "stopped: duration" in out
    assert time.monotonic() - t < 15.0


@pytest.mark.parametrize("argv, fragment", [
    (["serial", "--synth", "idle:2,fly:3"], "unknown behaviour 'fly'"),
    (["serial", "--take", "no/such/take.npz"], "no/such/take.npz"),
    (["vmc", "--synth", "idle:2", "--duration", "-1"], "--duration must be positive"),
    (["vmc", "--synth", "idle:2", "--skeleton", "x.asf"], "--skeleton goes with --take"),
    (["serial", "--synth", "idle:2", "--faults", "explode=1"], "unknown fault"),
])
def test_simulate_bad_arguments_are_clear_errors(argv, fragment, capsys, tmp_path):
    if "--faults" in argv:
        argv = argv + ["--link", str(tmp_path / "f")]
    assert main(["simulate", *argv]) == 1
    assert fragment in capsys.readouterr().err


def test_simulate_prints_the_transitions_saved_in_a_synthetic_take(tmp_path, capsys):
    import socket

    from rtseg.drivers.readers import write_take

    truth = synthesize("idle:2,walk:2,squat:2", seed=1)
    path = write_take(tmp_path / "synth.npz", truth.take)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    try:
        rc = main(["simulate", "vmc", "--take", str(path), "--port", str(sock.getsockname()[1]),
                   "--duration", "0.2"])
        sock.settimeout(2.0)
        assert sock.recv(65536).startswith(b"#bundle")          # something really arrived
    finally:
        sock.close()
    out = capsys.readouterr().out
    assert rc == 0
    assert _printed_transitions(out.splitlines()) == [
        (t.lo, t.hi, t.mid, t.before, t.after) for t in truth.transitions]
