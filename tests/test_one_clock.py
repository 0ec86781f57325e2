"""One clock for everything a session reports: ``rtseg demo`` at ``--speed 4`` with faults
(corrupt bytes, lost frames, an unplug, a sensor dropout) through the simulated suit on a
real pty; the times of cuts, behaviour decisions, dropouts and status on the console, in
the JSON lines, over OSC (real UDP) and in the recording are the same numbers, on the
performance's clock (the suit's device clock), never the wall clock or a count of the
frames received (which frame loss shifts)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from osc_collector import OscCollector

from rtseg.recording import read_session, read_session_behaviours

REPO = Path(__file__).resolve().parent.parent
SPEED = 4.0
SCRIPT = "idle:5,walk:7,punch:7,walk:6"          # changes at 5, 12 and 19 s
CHANGES = (5.0, 12.0, 19.0)
FAULTS = "corrupt=0.0003,drop=0.02,unplug=15:0.5,dropout=5:2.5:1.5,seed=3"

CUT = re.compile(r"^cut #(\d+)\s+\S+\s+segment (\d+)\s+frame (\d+)\s+t=\s*([\d.]+) s", re.M)
BEHAVIOUR = re.compile(r"^behaviour\s+(\S+).* segment (\d+)\s+from frame (\d+)\s+"
                       r"decided t=\s*([\d.]+) s", re.M)
DROPOUT = re.compile(r"^rtseg: dropout: (\S+) (lost|restored) at t=([\d.]+) s", re.M)
STATUS = re.compile(r"^rtseg live:\s+([\d.]+) s \|", re.M)


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("clock")
    jsonl, rec = tmp / "events.jsonl", tmp / "rec"
    with OscCollector(linger=0.5) as rx:
        proc = subprocess.run(
            [sys.executable, "-m", "rtseg.cli", "demo", "--speed", f"{SPEED:g}",
             "--script", SCRIPT, "--duration", "25", "--faults", FAULTS, "--no-monitor",
             "--no-names",
             "--osc", f"127.0.0.1:{rx.port}",
             "--target", f"udp:127.0.0.1:{rx.port},standard=off,template=/clock/{{label}} time",
             "--jsonl", str(jsonl), "--record", str(rec)],
            capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = [json.loads(ln) for ln in jsonl.read_text().splitlines()]
    return proc, lines, rx, rec


def test_cut_times_agree_everywhere_and_follow_the_device_clock(session):
    proc, lines, rx, rec = session
    console = [(int(e), int(s), int(f), float(t)) for e, s, f, t in CUT.findall(proc.stdout)]
    assert len(console) >= 2, proc.stdout
    jl = [d for d in lines if d["type"] == "cut" and d["wire"]]
    osc = rx.args("/rtseg/cut")
    tk = read_session(rec)
    recorded = [c for c in tk.meta["cuts"] if c.wire]
    assert len(jl) == len(osc) == len(recorded) == len(console)
    for (event, segment, frame, t), d, o, r in zip(console, jl, osc, recorded):
        assert (d["event"], d["segment"], d["frame"]) == (event, segment, frame)
        assert (o[0], o[1]) == (event, segment) and r.frame == frame
        assert round(d["time"], 3) == pytest.approx(t, abs=1.5e-3)
        assert o[2] == pytest.approx(d["time"], abs=1e-3)         # float32 on the wire
        assert r.time == d["time"]
    # on the suit's device clock, counted from the first frame's arrival: the frames lost
    # to drops and corruption before a cut do not move it (frame / rate would)
    src = tk.meta["source_time"]
    t0 = float(tk.meta["session_time"][0])          # the first frame's arrival
    lost = 0
    for d in jl:
        on_device = src[d["frame"]] - src[0]
        assert d["time"] == pytest.approx(t0 + on_device, abs=2e-3)
        lost = max(lost, round(on_device * 120) - d["frame"])
    assert lost > 10, "the faults should have cost frames before the last cut"
    # each cut lies near a true change (CHANGES: s of performance after the first
    # frame's arrival), not at a wall-clock time a quarter of that
    for d in jl:
        assert min(abs(d["time"] - t0 - c) for c in CHANGES) < 1.0, d


def test_behaviour_times_agree_everywhere(session):
    proc, lines, rx, rec = session
    console = [(b, int(s), int(f), float(t)) for b, s, f, t in BEHAVIOUR.findall(proc.stdout)]
    jl = [d for d in lines if d["type"] == "behaviour"]
    osc = [(a, args) for a, _, args in rx.messages if a.startswith("/clock/")]
    recorded = read_session_behaviours(rec)
    assert len(console) >= 2 and len(console) == len(jl) == len(osc) == len(recorded)
    for (b, seg, frame, t), d, (addr, args), r in zip(console, jl, osc, recorded):
        assert (d["behaviour"], d["segment"], d["frame"]) == (b, seg, frame)
        assert round(d["time"], 3) == pytest.approx(t, abs=1.5e-3)
        assert args[0] == pytest.approx(d["time"], abs=1e-3)
        assert r.time == d["time"]
    times = [d["time"] for d in jl]
    assert times == sorted(times)
    # decided on the performance's clock: each after its segment's cut, within the
    # identity decision window (a few seconds of performance), not a quarter of it
    cuts = {d["segment"]: d["time"] for d in lines if d["type"] == "cut" and d["wire"]}
    for d in jl:
        if d["segment"] in cuts:
            assert 0.5 < d["time"] - cuts[d["segment"]] < 4.0, (d, cuts)


def test_dropout_and_status_times_agree_everywhere(session):
    proc, lines, rx, rec = session
    console = [(n, w == "lost", float(t)) for n, w, t in DROPOUT.findall(proc.stderr)]
    jl = [d for d in lines if d["type"] == "dropout"]
    events = read_session(rec).meta["events"]
    recorded = [e for e in events if e.get("type") == "dropout"]
    assert [(d["name"], d["lost"]) for d in jl] == [(n, lost) for n, lost, _ in console]
    assert [(d["name"], d["lost"], d["time"]) for d in jl] == \
        [(e["name"], e["lost"], e["time"]) for e in recorded]
    for (_, _, t), d in zip(console, jl):
        assert round(d["time"], 2) == pytest.approx(t, abs=0.006)
    # sensor 5 is silent from 2.5 s to 4.0 s of performance (after the first frame's
    # arrival, t0): lost after 0.5 s of it
    t0 = float(read_session(rec).meta["session_time"][0])
    joint = [d for d in jl if d["name"] != "source"]
    assert [d["lost"] for d in joint[:2]] == [True, False], jl
    assert 2.9 < joint[0]["time"] - t0 < 3.3 and 3.9 < joint[1]["time"] - t0 < 4.3, (t0, joint)
    # status: non-decreasing; the last is the performance's time when the session ended,
    # 4x the wall-clock time since the first frame
    status = [d for d in lines if d["type"] == "status"]
    times = [d["time"] for d in status]
    wall = float(re.search(r"session ended \(duration reached\) after ([\d.]+) s",
                           proc.stderr).group(1))
    assert times == sorted(times)
    assert times[-1] == pytest.approx(t0 + SPEED * (wall - t0), abs=0.6), (times, t0, wall)
    shown = [float(t) for t in STATUS.findall(proc.stderr)]
    for t in shown:
        assert any(abs(round(s, 1) - t) < 0.051 for s in times), (t, times)
    # every time in events.jsonl on one clock: none past the end, none before 0
    assert all(0.0 <= d["time"] <= times[-1] + 1e-9 for d in lines if "time" in d)


# ------------------------------------------------------------------ SessionClock alone
def test_clock_follows_the_source_and_counts_lost_frames():
    from rtseg.live.clock import SessionClock
    clk = SessionClock(100.0, 120.0)
    # sent 4x faster than the 120 Hz device clock; frames 3-5 lost on the way
    kept = [i for i in range(12) if i not in (3, 4, 5)]
    times = [clk.feed(n, 100.5 + i / 480.0, 7.0 + i / 120.0) for n, i in enumerate(kept)]
    assert times[0] == pytest.approx(0.5)
    assert times[-1] == pytest.approx(0.5 + 11 / 120.0)
    assert clk.time_of(3) == pytest.approx(0.5 + 6 / 120.0)     # session frame 3 = sent 6
    assert clk.segments == 0


def test_clock_that_goes_back_starts_a_segment_and_times_stay_monotonic():
    from rtseg.live.clock import SessionClock
    clk = SessionClock(0.0, 60.0)
    t = [clk.feed(i, 1.0 + i / 60.0, 50.0 + i / 60.0) for i in range(10)]
    # the sender restarted: its clock is back at 0
    t += [clk.feed(10 + i, 1.0 + (10 + i) / 60.0, i / 60.0) for i in range(10)]
    assert all(b > a for a, b in zip(t, t[1:])), t
    assert clk.segments == 1 and "went back" in clk.last_break
    assert t[10] - t[9] == pytest.approx(1 / 60.0)      # the receive clock's step
    assert t[19] - t[10] == pytest.approx(9 / 60.0)     # then the source clock again
    # a jump far ahead of what arrived (an hour in a frame) is a segment too
    t2 = clk.feed(20, 1.0 + 20 / 60.0, 3600.0)
    assert clk.segments == 2 and t2 - t[-1] == pytest.approx(1 / 60.0)


def test_a_time_reported_in_a_silence_is_never_after_the_next_frame():
    from rtseg.live.clock import SessionClock
    clk = SessionClock(0.0, 60.0, silence_s=0.5)
    for i in range(5):
        clk.feed(i, 1.0 + i / 60.0, i / 60.0)
    last = clk.time_of(4)
    assert clk.now(1.0 + 4 / 60.0 + 0.2) == last             # frames flowing: its time
    lost_at = clk.now(1.0 + 4 / 60.0 + 0.6, report=True)    # a dropout in the silence
    assert lost_at == pytest.approx(last + 0.6)
    # the sender comes back with its clock continued from its last time (a restart the
    # source stitched): the frame is not placed before the moment already reported
    t = clk.feed(5, 1.0 + 4 / 60.0 + 1.0, 5 / 60.0)
    assert t >= lost_at
    # a source without a clock runs on the receive clock
    bare = SessionClock(10.0, 100.0)
    assert [bare.feed(i, 10.25 + i * 0.01, None) for i in range(3)] == \
        pytest.approx([0.25, 0.26, 0.27])


def test_a_frame_without_a_time_among_timed_ones_shifts_nothing():
    from rtseg.live.clock import SessionClock
    clk = SessionClock(0.0, 120.0)
    # 4x faster than the device clock; frame 5 arrives without its time (a T lost)
    t = [clk.feed(i, 0.1 + i / 480.0, None if i == 5 else 2.0 + i / 120.0)
         for i in range(10)]
    assert all(b > a for a, b in zip(t, t[1:]))
    assert t[9] - t[0] == pytest.approx(9 / 120.0) and clk.segments == 0


def test_a_restarted_vmc_sender_keeps_every_reported_time_going_forward(tmp_path):
    """A VMC sender stops, is silent for longer than the dropout limit, and starts again
    from /VMC/Ext/T = 0 on a new socket (a restarted app), over real UDP: the session's
    status, dropout and frame times never go back - the source stitches its clock and the
    frames after the silence come after the moments reported during it."""
    import socket
    import threading
    import time as _time

    from tests.test_vmc_edge_faults import _send_run
    from tests.test_vmc_live import make_take

    from rtseg.drivers import open_source
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    src = open_source("osc://127.0.0.1:0?format=vmc&rate=60&queue=4096")
    log = tmp_path / "events.jsonl"
    cfg = from_dict({"output": {"osc": [], "jsonl": str(log)}, "status": {"interval": 0.2},
                     "calibration": {"mode": "none"}}, origin="test")
    session = LiveSession(src, cfg, handle_signals=False)
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("s", session.run()), daemon=True)
    t.start()
    _time.sleep(0.3)
    take = make_take(90, seed=4)
    addr = ("127.0.0.1", src.port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s1:
        _send_run(s1, addr, take, pause=1 / 60.0)
    _time.sleep(1.5)                           # silent: the source is reported lost
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s2:
        _send_run(s2, addr, take, pause=1 / 60.0)
    _time.sleep(0.5)
    session.stop("test done")
    t.join(10)
    assert src.stats.clock_restarts == 1 and box["s"].frames_received == 180
    lines = [json.loads(ln) for ln in log.read_text().splitlines()]
    reported = [(d["type"], d["time"]) for d in lines if d["type"] in ("status", "dropout")]
    times = [t for _, t in reported]
    assert times == sorted(times), reported
    lost = [d for d in lines if d["type"] == "dropout" and d["name"] == "source"]
    assert [d["lost"] for d in lost[:2]] == [True, False]
    # the frame that ended the silence is placed after the moment the loss was reported
    assert lost[1]["time"] >= lost[0]["time"] + 0.4
    # and the frames after it go on by the sender's 60 Hz clock
    clk = session.clock
    assert clk.time_of(179) - clk.time_of(90) == pytest.approx(89 / 60.0, abs=0.02)
