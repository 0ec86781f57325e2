"""Several live sessions on one thread (rtseg.live.loop.run_sessions), and the polled
reading of the serial and UDP sources that lets the loop read them without threads.

Real parts: a simulated suit on a real pty opened by pyserial, a VMC sender over real UDP on
127.0.0.1, cuts and status over real UDP to a collector."""

from __future__ import annotations

import json
import select
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from osc_collector import OscCollector
from take_source import TakeSource

from rtseg.drivers import SourceError, open_source
from rtseg.live.config import from_dict
from rtseg.live.loop import run_sessions
from rtseg.live.session import LiveSession, replay_session
from rtseg.recording import read_session
from rtseg.simulators.serial_device import SerialSuit
from rtseg.simulators.synth.motion import synthesize
from rtseg.simulators.vmc_sender import VmcSender

RATE = 120.0
SPEED = 4.0
SCRIPT = "idle:3,walk:4,punch:4,squat:4"      # 15 s of motion, 3 behaviour changes
#: threads of the drivers and of the session that the loop makes unnecessary
READER_THREADS = ("rtseg-reader", "rtseg-serial /", "rtseg-osc-")


@pytest.fixture(scope="module")
def take():
    return synthesize(SCRIPT, frame_rate=RATE, seed=3).take


def config(rec: Path | None, port: int, **extra) -> object:
    raw = {"output": {"osc": [f"127.0.0.1:{port}"]}, "status": {"interval": 0.5},
           "buffer": {"max_lag_seconds": 0.0}}      # every frame processed (compared offline)
    if rec is not None:
        raw["recording"] = {"dir": str(rec)}
    for k, v in extra.items():
        raw.setdefault(k, {}).update(v)
    return from_dict(raw, origin="test")


def poll_frames(src, until, timeout: float = 5.0) -> list:
    """Drive a polled source as the live loop does (poll(2) on its descriptors until its
    due time, ``poll``, ``take``) until ``until(frames)`` or ``timeout``."""
    frames: list = []
    end = time.monotonic() + timeout
    while time.monotonic() < end and not until(frames):
        p = select.poll()
        for fd in src.poll_fds():
            p.register(fd, select.POLLIN)
        due = src.poll_due()
        wait = 0.05 if due is None else min(0.05, max(0.0, due - time.monotonic()))
        p.poll(wait * 1000.0)
        src.poll(time.monotonic())
        src.take(frames)
    return frames


def test_polled_serial_source_reads_every_frame_and_reconnects_after_an_unplug(take):
    suit = SerialSuit(take, rate=200.0, loop=True)
    suit.start(send=False)
    src = open_source(f"serial://{suit.path}?stale=0.1")
    try:
        assert src.wait_connected(2.0)
        assert src.hold_frames() == 0          # read by its thread: nothing may wait
        assert src.take_over() is True
        assert src.hold_frames() == 0          # no frame yet: its size is unknown
        assert not [t for t in threading.enumerate() if t.name.startswith("rtseg-serial /")]
        suit.begin()
        frames = poll_frames(src, lambda fr: len(fr) >= 100)
        assert len(frames) >= 100
        # what may wait unread for the loop's quiet-frame batching: 3 KB of 184-byte
        # frames (fewer when a read held an info message or part of the next frame too)
        assert 4 <= src.hold_frames() <= 3072 // 184
        # in order, none missing, values as sent (Q14 resolution)
        seqs = [f.seq for f in frames]
        assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
        sent = {m.seq: m.frame for m in suit.sent_log if m.frame >= 0}
        g = suit.quats
        for f in frames[:50]:
            want = g[sent[f.seq]]
            d = np.minimum(np.abs(f.quats - want).max(-1), np.abs(f.quats + want).max(-1))
            assert d.max() < 1e-4
        # an unplug: the port is reopened by the polls alone, reading resumes within 1 s
        suit.unplug(0.5)
        poll_frames(src, lambda fr: bool(suit.unplug_log), timeout=5.0)
        assert suit.unplug_log, "device never came back"
        back = suit.unplug_log[0][1]
        after = poll_frames(src, lambda fr: any(f.recv_time > back for f in fr), timeout=3.0)
        first = min(f.recv_time for f in after if f.recv_time > back)
        assert first - back < 1.0
        assert src.stats.reconnects == 1 and src.disconnects == 1
        assert src.stats.gaps >= 1            # the frames sent while unplugged: one gap
    finally:
        src.close()
        suit.stop()


def test_bytes_arriving_after_in_waiting_looked_are_read_not_taken_for_an_unplug(
        take, monkeypatch):
    """A poll that finds nothing counted waiting, then the descriptor ready (the writer's
    bytes reached the port in between), reads them: no false unplug, no frame lost."""
    suit = SerialSuit(take, rate=200.0)
    suit.start(send=False)
    src = open_source(f"serial://{suit.path}")
    try:
        assert src.wait_connected(2.0) and src.take_over() is True
        suit.begin()
        first = poll_frames(src, lambda fr: len(fr) >= 5)
        real = type(src._ser).in_waiting
        looked: list[int] = []

        def late_in_waiting(ser):        # the bytes are there, but not yet when counted
            looked.append(1)
            return 0 if len(looked) <= 3 else real.fget(ser)
        monkeypatch.setattr(type(src._ser), "in_waiting", property(late_in_waiting))
        more = poll_frames(src, lambda fr: len(looked) > 3 and len(fr) >= 20)
    finally:
        src.close()
        suit.stop()
    assert len(looked) > 3
    assert src.disconnects == 0 and src.stats.reconnects == 0
    seqs = [f.seq for f in first + more]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))     # none lost


def test_polled_serial_text_lines_give_every_frame(take):
    """Text lines (``id,w,x,y,z``) read by polls: every frame, in order, values as sent."""
    from rtseg.core.quat import global_from_local
    short = synthesize("idle:1.5", frame_rate=RATE, seed=2).take
    suit = SerialSuit(short, rate=400.0, fmt="text")
    suit.start(send=False)
    src = open_source(f"serial://{suit.path}?format=text&baud=115200")
    try:
        assert src.wait_connected(2.0) and src.take_over() is True
        suit.begin()
        frames = poll_frames(src, lambda fr: suit.wait_done(0) and len(fr) >= short.n_frames,
                             timeout=10.0)
    finally:
        src.close()
        suit.stop()
    assert len(frames) == short.n_frames
    want = global_from_local(short.quats, short.parents)
    got = np.stack([f.quats for f in frames])
    same = np.minimum(np.abs(got - want).max(-1), np.abs(got + want).max(-1))
    assert same.max() < 1e-4
    assert all(f.seq is None and f.valid.all() for f in frames)


def test_polled_vmc_source_assembles_frames_and_closes_the_last_after_the_quiet_gap(take):
    src = open_source("osc://127.0.0.1:0?format=vmc&quiet=0.02")
    sender = VmcSender(take, "127.0.0.1", src.port, rate=RATE, speed=SPEED)
    try:
        assert src.take_over() is True
        assert not [t for t in threading.enumerate() if t.name.startswith("rtseg-osc-")]
        sender.start()
        n = 240
        frames = poll_frames(src, lambda fr: len(fr) >= n, timeout=10.0)
        sender.stop()
        # every frame closed, the last by the quiet-gap rule (no later frame closes it)
        frames += poll_frames(src, lambda fr: False, timeout=0.3)
        assert len(frames) >= n
        assert [f.seq for f in frames] == list(range(len(frames)))
        assert all(f.valid.all() for f in frames)
        assert src.stats.frames_ok == len(frames)
    finally:
        sender.stop()
        src.close()


def run_in_thread(fn) -> tuple[threading.Thread, dict]:
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("out", fn()), daemon=True)
    t.start()
    return t, box


def offline(rec: Path, cfg) -> list[tuple[str, int]]:
    return [(c.cut.method, c.boundary) for c in replay_session(str(rec), cfg)]


def test_two_suits_in_one_thread_each_with_its_detectors_recording_and_tagged_cuts(
        tmp_path, take):
    """A serial suit and a VMC suit in one loop: no reader thread, each session records
    every frame it received, the recording replayed offline gives exactly its live cuts,
    and every cut and status goes out under its source's name."""
    osc = OscCollector()
    suit = SerialSuit(take, rate=RATE, speed=SPEED)
    vmc_src = open_source(f"osc://127.0.0.1:0?format=vmc&rate={RATE:g}")
    sender = VmcSender(take, "127.0.0.1", vmc_src.port, rate=RATE, speed=SPEED)
    log = tmp_path / "events.jsonl"
    seen_threads: set[str] = set()
    try:
        path = suit.start()
        cfgs = {name: config(tmp_path / name, osc.port, output={"jsonl": str(log)})
                for name in ("alice", "bob")}
        sessions = [LiveSession(f"serial://{path}?rate={RATE:g}", cfgs["alice"],
                                handle_signals=False, name="alice"),
                    LiveSession(vmc_src, cfgs["bob"], handle_signals=False, name="bob")]
        t, box = run_in_thread(lambda: run_sessions(sessions, handle_signals=False))
        end = time.monotonic() + 10
        while time.monotonic() < end and not all(s._polled for s in sessions):
            time.sleep(0.01)     # the drivers' own threads end when the loop takes over
        sender.start()
        play = take.n_frames / (RATE * SPEED)
        end = time.monotonic() + play + 10
        while time.monotonic() < end and not (suit.wait_done(0.05) and sender.wait(0.0)):
            seen_threads |= {th.name for th in threading.enumerate()}
        time.sleep(0.3)
        for s in sessions:
            s.stop("test done")
        t.join(15)
        assert not t.is_alive()
        time.sleep(0.2)
    finally:
        suit.stop()
        sender.stop()
        osc.close()
    assert not [n for n in seen_threads if n.startswith(READER_THREADS)], seen_threads
    alice, bob = box["out"]
    for name, summary, session in (("alice", alice, sessions[0]), ("bob", bob, sessions[1])):
        tk = read_session(tmp_path / name)
        assert tk.n_frames == summary.frames_received >= 0.98 * take.n_frames, name
        assert summary.frames_processed == summary.frames_received, name
        expected = offline(tmp_path / name, cfgs[name])
        assert len(expected) >= 2, name
        assert [(c.method, c.frame) for c in tk.meta["cuts"]] == expected, name
        # on the wire under the source's name: one /rtseg/<name>/cut per primary cut
        wire = [e for e in expected if e[0] in session.wire]
        cuts = osc.args(f"/rtseg/{name}/cut")
        assert [c[0] for c in cuts] == list(range(1, len(wire) + 1)), name
        statuses = osc.args(f"/rtseg/{name}/status")
        assert statuses and statuses[0][0] == 1 and statuses[-1][0] == 0, name
    assert not osc.args("/rtseg/cut") and not osc.args("/rtseg/status")
    # the JSON-lines log both sessions write: every event names its source
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert {e["source"] for e in events} == {"alice", "bob"}
    assert sum(1 for e in events if e["type"] == "cut") == alice.cuts + bob.cuts


def test_a_blocking_source_keeps_its_thread_beside_a_polled_one(tmp_path, take):
    """A source without the polling protocol (here a take read as fast as it is read) is
    read by a reader thread; the polled one beside it is not; both finish in one call."""
    osc = OscCollector()
    vmc_src = open_source(f"osc://127.0.0.1:0?format=vmc&rate={RATE:g}")
    sender = VmcSender(take, "127.0.0.1", vmc_src.port, rate=RATE, speed=SPEED)
    short = synthesize("idle:2,walk:2", frame_rate=RATE, seed=1).take
    threaded = TakeSource(short)
    try:
        sessions = [LiveSession(threaded, config(None, osc.port), handle_signals=False,
                                name="file"),
                    LiveSession(vmc_src, config(None, osc.port), handle_signals=False,
                                name="vmc", duration=2.0)]
        sender.start()
        t0 = time.monotonic()
        out = run_sessions(sessions, handle_signals=False)
        took = time.monotonic() - t0
    finally:
        sender.stop()
        osc.close()
    assert sessions[0]._polled is False and sessions[1]._polled is True
    assert out[0].stop_reason == "end of source"
    assert out[0].frames_processed == short.n_frames
    assert out[1].stop_reason == "duration reached" and out[1].frames_received > 100
    assert took < 6.0


def test_a_source_that_cannot_open_stops_the_sessions_already_started(tmp_path):
    osc = OscCollector()
    first = open_source("osc://127.0.0.1:0?format=vmc")
    try:
        sessions = [LiveSession(first, config(None, osc.port), handle_signals=False, name="a"),
                    LiveSession("serial:///nonexistent/rtseg-port", config(None, osc.port),
                                handle_signals=False, name="b")]
        with pytest.raises(SourceError, match="nonexistent"):
            run_sessions(sessions, handle_signals=False)
    finally:
        osc.close()
    # the first session was shut down: its socket is closed, its final status sent
    assert first._closed
    assert sessions[0].stop_reason == "running" or sessions[0]._stop.is_set()
    assert osc.args("/rtseg/a/status")[-1][0] == 0


def test_stop_from_another_thread_wakes_the_loop_at_once():
    """The loop sleeps up to 50 ms per wake-up; stop() wakes it through its pipe."""
    src = open_source("osc://127.0.0.1:0?format=vmc")
    session = LiveSession(src, from_dict({"output": {"osc": []},
                                          "status": {"interval": 30.0}}),
                          handle_signals=False)
    t, box = run_in_thread(session.run)
    time.sleep(0.5)
    t0 = time.monotonic()
    session.stop("test")
    t.join(5)
    assert not t.is_alive()
    assert box["out"].stop_reason == "test"
    assert time.monotonic() - t0 < 0.5


def test_names_must_suit_an_osc_address():
    with pytest.raises(ValueError, match="source name"):
        LiveSession("osc://127.0.0.1:0", from_dict({}), name="a b")
    with pytest.raises(ValueError, match="twice"):
        s = LiveSession("osc://127.0.0.1:0", from_dict({}), handle_signals=False)
        run_sessions([s, s], handle_signals=False)


def test_rtseg_live_runs_several_urls_in_one_process(tmp_path):
    """``rtseg live NAME=URL URL ...``: one session per source, in one process; every
    JSON line names its source, each recording goes to its own sub-folder and each
    summary is printed after its name."""
    import subprocess
    import sys
    log, rec = tmp_path / "events.jsonl", tmp_path / "rec"
    out = subprocess.run(
        [sys.executable, "-m", "rtseg.cli", "live", "left=sim://synth?seed=1",
         "sim://synth?seed=2", "--duration", "2", "--no-osc", "--quiet", "--jsonl", str(log),
         "--record", str(rec)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    events = [json.loads(line) for line in log.read_text().splitlines()]
    assert {e["source"] for e in events} == {"left", "suit2"}
    for name in ("left", "suit2"):
        final = [e for e in events if e["source"] == name and e["type"] == "status"][-1]
        assert final["alive"] == 0
        tk = read_session(rec / name)
        assert tk.n_frames >= 120                      # 2 s at 120 Hz, less start-up
        assert f"{name}: session ended (duration reached)" in out.stderr


def test_sources_tables_in_the_configuration(tmp_path):
    from rtseg.commands.live import source_list
    from rtseg.config import ConfigError
    from rtseg.live.config import load_session_config
    p = tmp_path / "live.toml"
    p.write_text('[[sources]]\nurl = "serial:///dev/ttyUSB0"\nname = "alice"\n'
                 '[[sources]]\nurl = "osc://:39540"\n')
    cfg = load_session_config(p)
    assert cfg.sources == [{"url": "serial:///dev/ttyUSB0", "name": "alice"},
                           {"url": "osc://:39540", "name": ""}]
    assert source_list([], cfg) == [("alice", "serial:///dev/ttyUSB0"),
                                     ("suit2", "osc://:39540")]
    # the command line's URLs replace them; one URL alone stays unnamed
    assert source_list(["osc://:1?format=vmc"], cfg) == [("", "osc://:1?format=vmc")]
    assert source_list(["x=osc://:1"], cfg) == [("x", "osc://:1")]
    with pytest.raises(ConfigError, match="twice"):
        source_list(["a=osc://:1", "a=osc://:2"], cfg)
    for bad, what in (('[[sources]]\nname = "a"\n', "url"),
                      ('[[sources]]\nurl = "osc://:1"\nname = "a b"\n', "name"),
                      ('[[sources]]\nurl = "osc://:1"\nport = 3\n', "unknown key"),
                      ('[[sources]]\nurl = "osc://:1"\nname = "a"\n'
                       '[[sources]]\nurl = "osc://:2"\nname = "a"\n', "twice")):
        p.write_text(bad)
        with pytest.raises(ConfigError, match=what):
            load_session_config(p)


def test_an_overloaded_polled_source_is_read_in_threads_again(tmp_path, take, busy_core):
    """The suit at 60 times its 120 Hz, three detectors on a busy core: the loop cannot
    keep up, drops
    frames for overload, and from then on reads the source in threads (the driver's and
    a reader), so reading and recording go on beside processing; every frame received
    is still recorded, and the drops are counted."""
    suit = SerialSuit(take, rate=RATE, speed=60.0, loop=True)
    try:
        path = suit.start()
        cfg = from_dict({"output": {"osc": []}, "recording": {"dir": str(tmp_path / "rec")},
                         "detectors": {"methods": ["contrast", "pca", "ppca"]},
                         "buffer": {"max_lag_seconds": 0.1}}, origin="test")
        session = LiveSession(f"serial://{path}?rate={RATE:g}", cfg, handle_signals=False,
                              duration=4.0)
        summary = session.run()
    finally:
        suit.stop()
    from rtseg.live.session import HAND_BACK_DROPS
    assert summary.overload_drops >= HAND_BACK_DROPS
    assert session._polled is False and session._reader_thread is not None
    assert read_session(tmp_path / "rec").n_frames == summary.frames_received
    assert summary.frames_received > 1000


def test_the_wake_up_pipe_never_loses_a_wake_up():
    """A thread wakes the loop every 0.2 ms while the loop waits on the pipe and clears
    it whenever it is readable, as run_sessions does: no wait may run its full timeout
    (a wake-up lost between clear() and the read would leave the flag set and every later
    wake-up skipped)."""
    from rtseg.live.loop import Waker
    w = Waker()
    try:
        stop = threading.Event()

        def waker():
            while not stop.is_set():
                w.wake()
                time.sleep(0.0002)
        t = threading.Thread(target=waker, daemon=True)
        t.start()
        p = select.poll()
        p.register(w.rfd, select.POLLIN)
        timeouts = 0
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            if p.poll(200):
                w.clear()
            else:
                timeouts += 1
        stop.set()
        t.join(5)
        assert timeouts == 0, f"{timeouts} waits of 200 ms ran out while woken every 0.2 ms"
    finally:
        w.close()


class _PipeSource:
    """A polled source on a pipe: its read end is the descriptor the loop watches."""

    def __init__(self) -> None:
        import os
        self.rfd, self.wfd = os.pipe()

    def poll_fds(self) -> tuple[int, ...]:
        return (self.rfd,)

    def poll_due(self):
        return None


class _PolledSession:
    def __init__(self) -> None:
        self.source = _PipeSource()
        self.reads: list[str] = []

    def _poll_source(self, now: float) -> None:
        self.reads.append("poll")

    def _read_quiet(self, now: float) -> None:
        self.reads.append("quiet")


def test_loop_leaves_a_quiet_source_unread_until_its_time_or_a_hang_up():
    """SessionLoop.quiet: input waiting on a quiet source wakes nothing until the time
    given, then the source is read once as a batch and watched again; a hang-up (or error)
    on it ends the quiet at once."""
    import os
    from rtseg.live.loop import SessionLoop
    s = _PolledSession()
    loop = SessionLoop([s])
    try:
        loop.add_polled(s)
        os.write(s.source.wfd, b"x")
        assert loop.wait(0.0) == {s}                    # watched: input wakes the loop
        now = time.monotonic()
        loop.quiet(s, now + 0.2)
        assert loop.is_quiet(s)
        assert loop.next_due(now + 0.18) == pytest.approx(0.02)   # it wakes at its time
        t0 = time.monotonic()
        assert loop.wait(0.1) == set()                   # the byte waits unread
        assert time.monotonic() - t0 >= 0.09
        loop.read_sources(set(), time.monotonic())
        assert s.reads == [] and loop.is_quiet(s)        # not before its time
        loop.read_sources(set(), now + 0.2)
        assert s.reads == ["quiet"] and not loop.is_quiet(s)
        assert loop.wait(0.0) == {s}                     # watched again
        loop.quiet(s, time.monotonic() + 10.0)
        os.close(s.source.wfd)                           # the device goes away
        assert loop.wait(1.0) == {s} and not loop.is_quiet(s)
    finally:
        loop.close()
        os.close(s.source.rfd)
