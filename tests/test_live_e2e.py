"""End to end, real parts only: a simulated suit on a real pty (or a VMC sender over UDP)
-> LiveSession -> OSC over UDP -> python-osc server AND liblo's oscdump.

The cuts received must equal - in order, none lost, none extra, boundary within ±2 frames -
the cuts the same online detectors give when the recorded session is segmented offline
(``rtseg.live.session.replay_frames``).  With fault injection the session keeps running and the
recording holds every frame the source delivered.  SIGTERM ends ``rtseg live`` cleanly.

Playback is sped up (4x) so each test takes a few seconds; the suit's device clock (and
the VMC sender's /VMC/Ext/T) keep the take's 120 Hz, which the source URL declares, so the
detectors' windows (seconds -> frames) are those of a real suit.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from osc_collector import OscCollector

from rtseg.drivers import open_source
from rtseg.live.session import LiveSession, replay_frames, replay_session
from rtseg.recording import read_session
from rtseg.live.config import from_dict
from rtseg.simulators.serial_device import SerialSuit
from rtseg.simulators.synth.motion import synthesize
from rtseg.simulators.vmc_sender import VmcSender

SCRIPT = "idle:3,walk:4,punch:4,squat:4"      # 15 s of motion, 3 behaviour changes
SPEED = 4.0
RATE = 120.0
REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def take():
    return synthesize(SCRIPT, frame_rate=RATE, seed=3).take


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class OscDump:
    """liblo's oscdump on a port; parsed /rtseg/cut lines."""

    def __init__(self) -> None:
        if shutil.which("oscdump") is None:
            pytest.skip("oscdump (Debian liblo-tools) not installed")
        self.port = free_udp_port()
        self.proc = subprocess.Popen(["oscdump", "-L", str(self.port)], stdout=subprocess.PIPE,
                                     stderr=subprocess.DEVNULL, text=True)
        self.lines: list[str] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()
        # wait until it is really listening: probe until a probe message comes back
        from rtseg.publishers.osc.message import encode_message
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for _ in range(100):
                s.sendto(encode_message("/probe", "i", [1]), ("127.0.0.1", self.port))
                time.sleep(0.05)
                if any("/probe" in ln for ln in self.lines):
                    break
            else:
                self.close()
                pytest.fail("oscdump did not start listening")

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def close(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        self.thread.join(5)

    def cuts(self) -> list[tuple]:
        out = []
        for ln in self.lines:
            parts = ln.split()
            if len(parts) >= 10 and parts[1] == "/rtseg/cut" and parts[2] == "iiffffs":
                out.append((int(parts[3]), int(parts[4]), float(parts[5]), float(parts[6]),
                            float(parts[7]), float(parts[8]), parts[9].strip('"')))
        return out


def session_config(rec: Path, ports: list[int], **extra) -> object:
    raw = {"output": {"osc": [f"127.0.0.1:{p}" for p in ports]},
           "recording": {"dir": str(rec)}, "status": {"interval": 0.5}}
    for k, v in extra.items():
        raw.setdefault(k, {}).update(v)
    return from_dict(raw, origin="test")


def run_in_thread(session: LiveSession) -> tuple[threading.Thread, dict]:
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("summary", session.run()), daemon=True)
    t.start()
    return t, box


def play_through_session(suit: SerialSuit, take, config) -> tuple[LiveSession, object]:
    """A session on the suit's pty while the suit plays ``take`` once; stopped after it
    (the last datagrams given time to arrive): (session, summary)."""
    path = suit.start()
    session = LiveSession(f"serial://{path}?rate={RATE:g}", config, handle_signals=False)
    t, box = run_in_thread(session)
    assert suit.wait_done(take.n_frames / (RATE * SPEED) + 10)
    time.sleep(0.3)
    session.stop("test done")
    t.join(10)
    assert not t.is_alive()
    time.sleep(0.2)       # let the last datagrams arrive
    return session, box["summary"]


def play_vmc_through_session(take, config, **sender_options):
    """A session on an ``osc://`` VMC source while a simulated performer sends ``take`` once
    to it; stopped after it (the last datagrams given time to arrive): (session, summary,
    source, the source's ``hold_frames()`` once the take was sent)."""
    source = open_source(f"osc://127.0.0.1:0?format=vmc&rate={RATE:g}")
    sender = VmcSender(take, "127.0.0.1", source.port, rate=RATE, speed=SPEED,
                       **sender_options)
    try:
        session = LiveSession(source, config, handle_signals=False)
        t, box = run_in_thread(session)
        time.sleep(0.2)
        sender.start()
        assert sender.wait(take.n_frames / (RATE * SPEED) + 10)
        hold = source.hold_frames()
        time.sleep(0.3)
        session.stop("test done")
        t.join(10)
        assert not t.is_alive()
        time.sleep(0.2)
    finally:
        sender.stop()
    return session, box["summary"], source, hold


def offline_cuts(rec: Path, config) -> tuple[list, object]:
    """The recorded session through the same online detectors, offline."""
    tk = read_session(rec)
    m = tk.meta
    st = m["source_time"]
    frames = ((tk.quats[i], tk.valid[i], None if m["seq"][i] < 0 else int(m["seq"][i]),
               float(m["recv_time"][i]), float(st[i]) if np.isfinite(st[i]) else None)
              for i in range(tk.n_frames))
    cuts = replay_frames(frames, tk.joint_names, tk.parents, tk.space, tk.frame_rate, config)
    # the library's own helper gives the same
    assert [(c.cut.method, c.boundary) for c in replay_session(str(rec), config)] == \
        [(c.cut.method, c.boundary) for c in cuts]
    return cuts, tk


def on_wire(expected: list, session: LiveSession) -> list:
    """The offline cuts of the detectors whose cuts the session sends over OSC (by default
    only the primary detector's: one cut per behaviour change)."""
    assert session.wire, "the session names no detector for the wire"
    return [c for c in expected if c.cut.method in session.wire]


def assert_cuts_match(received: list[list], expected: list, tk, what: str) -> None:
    """received: /rtseg/cut argument lists (event, segment, time, conf, latency, delay,
    label); expected: PipelineCuts.  Same order, same methods, boundary ±2 frames.  A cut's
    time is on the source's clock when the source has one (rtseg.live.session: counted from the
    first frame's arrival), else the boundary frame's receive time."""
    st = tk.meta["session_time"]
    src = tk.meta["source_time"]
    if len(src) and np.all(np.isfinite(src)):
        st = st[0] + (src - src[0])
    got = [(r[6], r[2]) for r in received]
    assert [r[0] for r in received] == list(range(1, len(received) + 1)), f"{what}: event numbers"
    assert len(got) == len(expected), (
        f"{what}: {len(got)} cuts received, {len(expected)} expected offline: "
        f"{got} vs {[(c.cut.method, c.boundary) for c in expected]}")
    for (label, t), exp in zip(got, expected):
        assert label == exp.cut.method, f"{what}: method order differs"
        # frames whose time is the boundary time (several frames can share one)
        idx = np.flatnonzero(np.abs(st - t) < 5e-4)
        assert idx.size, f"{what}: no recorded frame at boundary time {t}"
        assert idx.min() - 2 <= exp.boundary <= idx.max() + 2, (
            f"{what}: {label} cut at t={t:.4f} s (frames {idx.min()}..{idx.max()}), "
            f"offline boundary {exp.boundary}")


def test_serial_pty_to_osc_matches_offline(tmp_path, take):
    rec = tmp_path / "session"
    osc, dump = OscCollector(), OscDump()
    suit = SerialSuit(take, rate=RATE, speed=SPEED)
    try:
        # the default detector (primary, on the wire) beside the paper's PCA (log only)
        cfg = session_config(rec, [osc.port, dump.port],
                             detectors={"methods": ["contrast", "pca"]})
        session, summary = play_through_session(suit, take, cfg)
    finally:
        suit.stop()
        osc.close()
        dump.close()
    expected, tk = offline_cuts(rec, cfg)
    assert tk.n_frames == summary.frames_received == session.source.stats.frames_ok
    assert tk.n_frames >= 0.98 * take.n_frames
    assert summary.overruns == 0 and summary.bad_frames == 0
    assert len(expected) >= 4, "the take has 3 behaviour changes; both methods should see some"
    assert session.primary == "contrast"
    assert session.wire == {session.primary}        # default: output.cut_methods = "primary"
    assert not osc.malformed, "a datagram was not one well-formed OSC message"
    assert_cuts_match(osc.cuts(), on_wire(expected, session), tk, "python-osc")
    assert_cuts_match(dump.cuts(), on_wire(expected, session), tk, "oscdump")
    # the recording's own cut log holds every detector's cuts, marked on or off the wire
    assert [c.frame for c in tk.meta["cuts"]] == [c.boundary for c in expected]
    assert [c.wire for c in tk.meta["cuts"]] == [c.cut.method in session.wire for c in expected]
    statuses = osc.args("/rtseg/status")
    assert statuses and statuses[0][0] == 1 and statuses[-1][0] == 0
    # processing latency (arrival of the revealing frame -> send) is small
    assert summary.cut_latency_ms_p50 is not None and summary.cut_latency_ms_p50 < 100


@pytest.mark.parametrize("batch_quiet", [True, False])
def test_quiet_frames_read_in_batches_give_the_same_cuts(tmp_path, take, batch_quiet):
    """The default detector alone promises most frames quiet, and the loop reads those in
    batches (rtseg.live.loop, "Quiet frames"): the cuts on the wire are still exactly the
    offline ones, every frame is recorded, and only promised-quiet frames are counted as
    batched.  Off (buffer.batch_quiet = false), no batch is read."""
    rec = tmp_path / "session"
    osc = OscCollector()
    suit = SerialSuit(take, rate=RATE, speed=SPEED)
    try:
        cfg = session_config(rec, [osc.port], buffer={"batch_quiet": batch_quiet})
        session, summary = play_through_session(suit, take, cfg)
    finally:
        suit.stop()
        osc.close()
    st = session.stats
    expected, tk = offline_cuts(rec, cfg)
    assert tk.n_frames == summary.frames_received >= 0.98 * take.n_frames
    assert len(expected) >= 2
    assert_cuts_match(osc.cuts(), on_wire(expected, session), tk, "python-osc")
    if batch_quiet:
        # most frames are quiet (the detector looks once per 15 frames); with the suit at
        # 4x its rate a batch holds up to 16 frames (the pty's 3 KB)
        assert st.quiet_batches > 10
        assert st.quiet_frames > 0.3 * summary.frames_received
        assert st.quiet_frames + st.late_open <= summary.frames_received
        assert summary.quiet == {"batches": st.quiet_batches, "frames": st.quiet_frames,
                                 "late_open": st.late_open}
        assert f"{st.quiet_frames} quiet frames read in {st.quiet_batches} batches" in \
            summary.text()
    else:
        assert st.quiet_batches == st.quiet_frames == st.late_open == 0
    # the frames that could send were processed as they came (their latency is measured)
    assert 0 < len(st.open_latency_ms) < 0.5 * summary.frames_received
    # between frames the loop worked ahead (placement, the gate's window before), and the
    # cuts above are still exactly the offline ones
    det = session.pipeline.detectors["contrast"]
    assert st.ahead_pieces > 10 and det._placement.made_ahead >= 1


def test_vmc_over_osc_to_osc_matches_offline(tmp_path, take):
    rec = tmp_path / "session"
    osc = OscCollector()
    try:
        cfg = session_config(rec, [osc.port], detectors={"methods": ["contrast", "pca"]})
        session, summary, source, _ = play_vmc_through_session(take, cfg)
    finally:
        osc.close()
    expected, tk = offline_cuts(rec, cfg)
    assert tk.space == "local"
    assert tk.n_frames == summary.frames_received == source.stats.frames_ok
    assert tk.n_frames >= 0.98 * take.n_frames
    assert session.pipeline.stats.calibration_frames == 30    # rig-relative input calibrated
    assert len(expected) >= 4
    assert_cuts_match(osc.cuts(), on_wire(expected, session), tk, "python-osc (VMC input)")


@pytest.mark.parametrize("batch_quiet,send_time", [(True, True), (False, True), (True, False)])
def test_vmc_quiet_frames_read_in_batches_give_the_same_frames_and_cuts(tmp_path, take,
                                                                       batch_quiet, send_time):
    """A VMC source is batched like the serial one once its frames close by their content
    (the sender's T seen, its message order learned): every frame sent is assembled once,
    whole (every bone valid, one T each, in order), and the cuts on the wire are the
    offline ones.  Off, no batch is read; nor from a sender without T (its frames have
    no clock, and the assembler closes some of them by arrival times)."""
    rec = tmp_path / "session"
    osc = OscCollector()
    try:
        cfg = session_config(rec, [osc.port], buffer={"batch_quiet": batch_quiet})
        session, summary, source, hold = play_vmc_through_session(take, cfg,
                                                                  send_time=send_time)
    finally:
        osc.close()
    st = session.stats
    expected, tk = offline_cuts(rec, cfg)
    assert tk.n_frames == summary.frames_received == source.stats.frames_ok
    assert tk.n_frames >= 0.98 * take.n_frames
    assert tk.valid.all(), "a frame lost bones: frames split or merged"
    if send_time:
        assert np.allclose(np.diff(tk.meta["source_time"]), 1.0 / RATE, atol=1e-4)
    assert len(expected) >= 2
    assert_cuts_match(osc.cuts(), on_wire(expected, session), tk, "python-osc (VMC, batched)"
                      if batch_quiet else "python-osc (VMC)")
    if not send_time:
        assert hold == 0 and st.quiet_batches == st.quiet_frames == 0
        return
    assert 1 <= hold <= 16                  # the source could hold frames either way
    if batch_quiet:
        assert st.quiet_batches > 10 and st.quiet_frames > 0.3 * summary.frames_received
        assert st.quiet_frames + st.late_open <= summary.frames_received
    else:
        assert st.quiet_batches == st.quiet_frames == st.late_open == 0


@pytest.mark.parametrize("corrupt,min_cuts", [(0.01, 0), (0.0003, 1)])
def test_faults_session_survives_and_records_every_frame(tmp_path, take, corrupt, min_cuts):
    """1 % corrupt bytes ruin ~80 % of the 173-byte frames (gaps everywhere: the detectors
    keep restarting and rightly place no cut); 0.03 % ruin ~5 %: cuts still come through
    (the unplug at 55 % restarts the contrast detector, which then needs 3 s of motion
    before it checks again, so the last change, ~3 s after the replug, may go unseen)."""
    rec = tmp_path / "session"
    osc = OscCollector()
    play_s = take.n_frames / (RATE * SPEED)
    # unplugged 0.8 s: longer than gaps.dropout_seconds (0.5) plus the reader's reconnect
    # back-off, so the source dropout is always reported (0.4 s was borderline)
    # fault times are the device clock's (the take's 120 Hz): SPEED x the wall clock
    faults = f"corrupt={corrupt},unplug={0.55 * play_s * SPEED:.2f}:{0.8 * SPEED:g},seed=7"
    suit = SerialSuit(take, rate=RATE, speed=SPEED, faults=faults)
    try:
        path = suit.start()
        cfg = session_config(rec, [osc.port])
        session = LiveSession(f"serial://{path}?rate={RATE:g}", cfg, handle_signals=False)
        t, box = run_in_thread(session)
        assert suit.wait_done(play_s + 15)
        time.sleep(0.3)
        assert t.is_alive(), "the session ended by itself"
        session.stop("test done")
        t.join(10)
        time.sleep(0.2)
    finally:
        suit.stop()
        osc.close()
    summary = box["summary"]
    src = session.source.stats
    assert src.corrupt > 0 and src.reconnects >= 1
    assert len(suit.unplug_log) == 1
    tk = read_session(rec)
    # every frame the source delivered is in the recording, in order
    assert tk.n_frames == src.frames_ok == summary.frames_received > 0
    assert tk.meta["closed_cleanly"]
    seq = tk.meta["seq"]
    unplug_end = suit.unplug_log[0][1]
    assert (tk.meta["recv_time"] > unplug_end).sum() > 10, "no frames after the replug"
    assert np.all(np.isin(seq, [m.seq for m in suit.intact_frames()]))
    # gaps restarted the detectors and the live cuts still equal the offline ones
    assert session.pipeline.stats.restarts >= 1
    expected, tk = offline_cuts(rec, cfg)
    assert len(expected) >= min_cuts
    assert_cuts_match(osc.cuts(), on_wire(expected, session), tk, "with faults")
    dropouts = osc.args("/rtseg/dropout")
    assert ["source", 1] in dropouts and ["source", 0] in dropouts


def test_sigterm_ends_rtseg_live_cleanly(tmp_path, take):
    rec = tmp_path / "session"
    osc = OscCollector()
    suit = SerialSuit(take, rate=RATE, speed=SPEED, loop=True)
    proc = None
    try:
        path = suit.start()
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        proc = subprocess.Popen(
            [sys.executable, "-m", "rtseg.cli", "live", f"serial://{path}?rate={RATE:g}",
             "--osc", f"127.0.0.1:{osc.port}", "--record", str(rec)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if not osc.cuts():
                time.sleep(0.1)
                continue
            break
        assert proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGTERM)
        try:
            out, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate(timeout=10)
            pytest.fail(f"rtseg live did not exit within 30 s of SIGTERM; stderr:\n{err}")
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(5)
        suit.stop()
        osc.close()
    assert proc.returncode == 0, err
    assert "session ended (SIGTERM)" in err
    cut_lines = [ln for ln in out.splitlines() if ln.startswith("cut #")]
    assert cut_lines, out
    tk = read_session(rec)
    assert tk.meta["closed_cleanly"] and tk.n_frames > 0
    assert len(tk.meta["cuts"]) == len(cut_lines) == len(osc.cuts())
    assert osc.messages[-1][0] == "/rtseg/status" and osc.messages[-1][2][0] == 0


def test_demo_command_prints_cuts(tmp_path):
    osc = OscCollector()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "rtseg.cli", "demo", "--duration", "16", "--speed", "4",
             "--script", "idle:3,walk:4,punch:4", "--osc", f"127.0.0.1:{osc.port}"],
            capture_output=True, text=True, timeout=60, cwd=REPO)
        time.sleep(0.1)
    finally:
        osc.close()
    assert proc.returncode == 0, proc.stderr
    cut_lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("cut #")]
    assert cut_lines and len(cut_lines) == len(osc.cuts())
    assert "session ended (duration reached)" in proc.stderr


def test_sigkilled_demo_leaves_no_stale_suit_folder(take):
    """A SIGKILLed ``rtseg demo`` cannot remove its pty link folder; the next suit that
    makes one removes it (its process is gone) and keeps the folders of live processes."""
    import re
    import tempfile
    proc = subprocess.Popen(
        [sys.executable, "-m", "rtseg.cli", "demo", "--duration", "60", "--no-osc", "--quiet"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        line = proc.stderr.readline()
        m = re.search(r"simulated suit on (\S+)", line)
        assert m, f"unexpected first line: {line!r}"
        folder = Path(m.group(1)).parent
        assert folder.name.startswith(f"rtseg-serial-{proc.pid}-") and folder.is_dir()
    finally:
        proc.kill()
        proc.wait(10)
    assert folder.is_dir(), "SIGKILL left nothing behind: nothing to test"
    alive = SerialSuit(take)                 # this process: alive, its folder must stay
    try:
        mine = Path(alive.path).parent
        assert mine.is_dir() and mine.name.startswith(f"rtseg-serial-{os.getpid()}-")
        assert not folder.exists()
        other = SerialSuit(take)
        try:
            assert mine.is_dir()
        finally:
            other.stop()
    finally:
        alive.stop()
    assert not mine.exists()
    assert Path(tempfile.gettempdir()) == folder.parent


def test_a_session_ending_while_its_source_is_quiet_reads_what_had_arrived(tmp_path, take):
    """The duration ends while the loop leaves the port unread (quiet frames): the frames
    that arrived before the end are still read, recorded and processed."""
    suit = SerialSuit(take, rate=RATE, loop=True)        # real time: batches of ~0.1 s
    try:
        path = suit.start()
        cfg = session_config(tmp_path / "rec", [])
        session = LiveSession(f"serial://{path}?rate={RATE:g}", cfg, handle_signals=False,
                              duration=3.0)
        summary = session.run()
        deadline = session._deadline
    finally:
        suit.stop()
    assert session.stats.quiet_batches > 5
    # every frame written more than 20 ms before the end (time for the pty to pass it on)
    due = sum(1 for m in suit.sent_log if m.frame >= 0 and m.fate == "intact"
              and m.send_time < deadline - 0.02)
    assert summary.frames_received >= due
    assert summary.frames_processed == summary.frames_received
    assert read_session(tmp_path / "rec").n_frames == summary.frames_received
