"""``rtseg simulate``: end to end, as a user runs it (a subprocess), read through a real pty
by pyserial and through a real UDP socket."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import serial

from rtseg.core import quat
from rtseg.cli import main
from rtseg.drivers.serial.codec import SerialFrameDecoder
from rtseg.simulators.synth.motion import synthesize

SCRIPT = "idle:2,walk:2"
SEED = 4


def _spawn(*args: str, preexec_fn=None) -> subprocess.Popen:
    # -u: unbuffered, so a simulator that does not stop shows how far it got
    return subprocess.Popen([sys.executable, "-u", "-m", "rtseg.cli", "simulate", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=os.getcwd(), preexec_fn=preexec_fn)


def _read_until(proc: subprocess.Popen, pattern: str, timeout: float = 20.0) -> tuple[re.Match, list[str]]:
    """Read stdout lines until one matches ``pattern``; (match, lines so far).

    The lines are read by a thread that stops at the match, so what the pipe holds after
    it stays in ``proc.stdout`` for ``_finish``.  (A selector on the pipe cannot be used:
    ``readline`` may have buffered the next lines already, and the selector then waits for
    output that the simulator - blocked on a pty nobody reads yet - never writes.)"""
    lines: list[str] = []
    found: list[re.Match] = []

    def read() -> None:
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))
            m = re.search(pattern, line)
            if m:
                found.append(m)
                return

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout)
    if found:
        return found[0], list(lines)
    proc.kill()
    reader.join(5.0)
    raise AssertionError(f"no line matching {pattern!r}; got {lines}; stderr: {proc.stderr.read()}")


def _finish(proc: subprocess.Popen, timeout: float = 45.0) -> tuple[int, str, str]:
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


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def test_ctrl_c_stops_a_simulator_started_with_sigint_ignored(tmp_path):
    """A process started while its parent ignores SIGINT (a caller inside system(3), a
    shell's background job) inherits the ignored disposition; Ctrl-C must still stop it
    with its summary.  (In full suite runs the pty test's simulator was started with
    SIGINT and SIGQUIT ignored, /proc SigIgn 0x1001006, and ran on past its 45 s.)"""
    link = tmp_path / "suit"
    proc = _spawn("serial", "--synth", SCRIPT, "--seed", str(SEED), "--link", str(link),
                  "--loop", preexec_fn=_ignore_sigint)
    try:
        _read_until(proc, r"^serial device: (\S+)")
        status = Path(f"/proc/{proc.pid}/status").read_text()
        ignored = int(re.search(r"^SigIgn:\s*([0-9a-f]+)", status, re.M).group(1), 16)
        assert ignored & (1 << (signal.SIGINT - 1)) == 0, "SIGINT still ignored after start"
        with serial.Serial(str(link), timeout=0.05) as port:
            deadline = time.monotonic() + 10.0
            got = 0
            while got < 2000 and time.monotonic() < deadline:
                got += len(port.read(4096))
        assert got >= 2000
        proc.send_signal(signal.SIGINT)
        rc, out, err = _finish(proc, timeout=20.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert rc == 0, err
    assert "stopped: interrupted" in out
    assert not link.exists()


def test_simulate_vmc_through_a_real_udp_socket(tmp_path):
    from rtseg.drivers.osc.source import OscVmcSource

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
    assert main(["simulate", *argv]) in (1, 2)        # an error exit (2 for usage errors)
    assert fragment in capsys.readouterr().err


@pytest.mark.parametrize("device", ["vmc", "mvn", "axis"])
def test_simulate_host_that_does_not_resolve_is_named(device, capsys):
    """An unknown ``--host`` is one line naming it, before anything is sent (no errno
    text)."""
    assert main(["simulate", device, "--synth", "idle:2", "--host", "no-such-host.invalid"]) == 2
    err = capsys.readouterr().err
    assert "--host 'no-such-host.invalid': not an address, and no host of that name" in err
    assert "[Errno" not in err


def _link_cases(tmp_path):
    """(--link value, the line it must give): paths where no symlink can be made."""
    (tmp_path / "folder").mkdir()
    (tmp_path / "plain").write_text("keep me")
    missing = tmp_path / "no" / "such" / "suit"
    return [
        (missing, f"--link {missing}: cannot create the link: folder {missing.parent} "
                  f"does not exist"),
        (tmp_path / "plain" / "suit", f"--link {tmp_path / 'plain' / 'suit'}: cannot "
                                      f"create the link: {tmp_path / 'plain'} is not a folder"),
        (tmp_path / "folder", f"--link {tmp_path / 'folder'}: is a folder; give the path of "
                              f"the link to create"),
        (tmp_path / "plain", f"--link {tmp_path / 'plain'}: a file that is not a link is there"),
        ("", "--link '': an empty path"),
    ]


@pytest.mark.parametrize("case", range(5))
def test_simulate_link_that_cannot_be_made_is_named(tmp_path, capsys, case):
    """``--link`` where no symlink can be made - a missing folder, a file for a folder, a
    folder or a plain file at the path, an empty path - is one line naming the option and
    its value, exit 2, before anything is synthesised (no errno text); nothing is
    created or replaced."""
    link, line = _link_cases(tmp_path)[case]
    assert main(["simulate", "serial", "--synth", "idle:2", "--link", str(link)]) == 2
    out, err = capsys.readouterr()
    assert err.startswith(f"rtseg simulate: error: {line}"), err
    assert len(err.splitlines()) == 1 and "Errno" not in err and "transitions" not in out
    assert (tmp_path / "plain").read_text() == "keep me"
    assert not (tmp_path / "no").exists() and list((tmp_path / "folder").iterdir()) == []


def test_serial_suit_link_it_cannot_make_is_one_line(tmp_path):
    """The suit itself (``rtseg demo``, tests, benchmarks): a link under a plain file is a
    ValueError in words - the ``.new`` twin it clears first used to raise the raw errno
    text - and the pty is closed again."""
    from rtseg.simulators.serial_device import SerialSuit
    (tmp_path / "plain").write_text("")
    link = tmp_path / "plain" / "suit"
    suit = SerialSuit(synthesize("idle:2", seed=0).take, link=link)
    with pytest.raises(ValueError) as ei:
        suit.start()
    assert str(ei.value) == (f"device link {link}: cannot create it: {tmp_path / 'plain'} "
                             f"is not a folder")
    assert not suit.plugged


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


# --------------------------------------------------------------------------- recorded takes

CMU_AMC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "data",
                       "cmu", "86_01.amc")
needs_cmu = pytest.mark.skipif(not os.path.exists(CMU_AMC),
                               reason=f"CMU take 86_01 not found at {CMU_AMC}")
#: The first 15 s of 86_01 (walk, jump, walk: labelled changes at frames 550 and 1150),
#: sent 10x faster than real time.
REPLAY = ["--take", CMU_AMC, "--end", "15", "--speed", "10"]
REPLAY_FRAMES = 1800


def _live(url: str, tmp_path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "rtseg.cli", "live", url, "--no-osc", "--quiet",
         "--jsonl", str(tmp_path / "events.jsonl"), "--record", str(tmp_path / "rec"),
         "--duration", "60"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=os.getcwd())


def _stop_live(live: subprocess.Popen) -> tuple[int, str, str]:
    live.send_signal(signal.SIGINT)
    try:
        out, err = live.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        live.kill()
        out, err = live.communicate()
        raise AssertionError(f"rtseg live did not stop on SIGINT; stderr {err!r}")
    return live.returncode, out, err


def _check_replay(tmp_path, err: str, sent_frames: int) -> list[dict]:
    """What reached the live loop: every frame with every sensor valid, the take's own
    clock in the source times, and at least one cut.  Returns the cut events."""
    import json

    from rtseg.recording import read_session
    tk = read_session(tmp_path / "rec")
    assert tk.n_frames >= 0.98 * sent_frames, (tk.n_frames, sent_frames, err)
    assert tk.valid is None or tk.valid.all(), \
        f"stale sensors: {[tk.joint_names[j] for j in np.flatnonzero(~tk.valid.all(0))]}"
    # --speed 10: the stream's clock is the take's (1/120 s a frame) although the frames
    # arrived ~10x faster
    # (UDP may drop a datagram under load: a lost frame is a step of whole frames)
    st = tk.meta["source_time"]
    steps = np.diff(st) * 120.0
    assert np.allclose(steps, np.round(steps), atol=2e-3) and steps.min() > 0.5, \
        np.unique(np.round(np.diff(st), 6))
    assert np.mean(np.round(steps) == 1) >= 0.98
    recv = tk.meta["recv_time"]
    assert (recv[-1] - recv[0]) < 0.5 * (st[-1] - st[0])
    events = [json.loads(line) for line in (tmp_path / "events.jsonl").read_text().splitlines()]
    lost = [e for e in events if e["type"] == "dropout" and e.get("lost") and e.get("name") != "source"]
    assert not lost, f"sensor dropouts reported: {lost}"
    # status while frames flow and the source is not reported lost (before the first frame
    # and after the last one the whole source is lost, which is not a stale sensor)
    source_lost, playing = False, []
    for e in events:
        if e["type"] == "dropout" and e.get("name") == "source":
            source_lost = bool(e.get("lost"))
        elif e["type"] == "status" and e["frame_rate"] > 0 and not source_lost:
            playing.append(e)
    assert all(e["stale_joints"] == 0 for e in playing), playing
    cuts = [e for e in events if e["type"] == "cut"]
    assert cuts, f"no cut from {tk.n_frames} frames of 86_01; stderr {err!r}"
    return cuts


@needs_cmu
def test_cmu_take_replays_through_the_serial_suit_into_rtseg_live(tmp_path):
    link = tmp_path / "suit"
    sim = _spawn("serial", *REPLAY, "--link", str(link))
    live = None
    try:
        m, lines = _read_until(sim, r"^serial device: (\S+)")
        assert any("skeleton map cmu-asf" in ln and "Chest<-thorax" in ln for ln in lines), lines
        live = _live(f"serial://{link}", tmp_path)
        rc, out, err = _finish(sim, timeout=30.0)
        assert rc == 0, err
        assert f"sent {REPLAY_FRAMES} frame messages" in out, out
        time.sleep(0.3)
        lrc, lout, lerr = _stop_live(live)
    finally:
        for p in (sim, live):
            if p is not None and p.poll() is None:
                p.kill()
                p.communicate()
    assert lrc == 0, lerr
    _check_replay(tmp_path, lerr, REPLAY_FRAMES)


def _free_udp_port() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_bound(port: int, proc: subprocess.Popen, timeout: float = 20.0) -> None:
    """Until something has bound UDP ``port`` on 127.0.0.1 (our own bind fails)."""
    import socket
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()[1]
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                return
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on udp 127.0.0.1:{port}")


@needs_cmu
def test_cmu_take_replays_as_vmc_into_rtseg_live(tmp_path):
    port = _free_udp_port()
    # a 4 MB socket buffer and a deep queue: the 10x-speed burst must survive a loaded
    # machine (with the OS default buffer, 1/3 of the datagrams were lost once under load)
    live = _live(f"osc://127.0.0.1:{port}?format=vmc&rcvbuf=4194304&queue=10000", tmp_path)
    sim = None
    try:
        _wait_bound(port, live)
        time.sleep(0.3)      # the session's reader thread is up once the port is bound
        sim = _spawn("vmc", *REPLAY, "--port", str(port))
        rc, out, err = _finish(sim, timeout=30.0)
        assert rc == 0, err
        assert "VMC sender: 17 bones" in out and "skeleton map cmu-asf" in out, out
        assert f"sent {REPLAY_FRAMES} frames" in out, out
        time.sleep(0.3)
        lrc, lout, lerr = _stop_live(live)
    finally:
        for p in (sim, live):
            if p is not None and p.poll() is None:
                p.kill()
                p.communicate()
    assert lrc == 0, lerr
    _check_replay(tmp_path, lerr, REPLAY_FRAMES)


def test_simulate_take_errors_name_the_unmapped_bones(tmp_path, capsys):
    from rtseg.drivers.readers import write_take
    from rtseg.core.take import Take
    q = np.tile([0.0, 0.0, 0.0, 1.0], (10, 3, 1))
    path = write_take(tmp_path / "odd.npz", Take(["Hips", "Spine", "Tail"], [-1, 0, 1], 120.0, q))
    assert main(["simulate", "vmc", "--take", str(path), "--port", "9"]) in (1, 2)
    err = capsys.readouterr().err
    assert "skeleton map 'unity'" in err and "Chest (looked for Chest or UpperChest)" in err
    assert "Hips (" not in err
    for argv, fragment in [
        (["--speed", "0"], "--speed must be a positive number"),
        (["--imu", "noise=x"], "noise needs a number"),
        (["--joint-map", "Head"], "--joint-map: expected BONE=JOINT"),
        (["--start", "5", "--end", "4"], "--start/--end select no frame"),
    ]:
        assert main(["simulate", "vmc", "--synth", "idle:2", "--port", "9", *argv]) in (1, 2), argv
        assert fragment in capsys.readouterr().err, argv
