"""Bad input is counted *and shown*: corrupt serial frames on a real pty
and junk UDP datagrams on a real socket reach the summary (text and dict), the
``/rtseg/input`` OSC message (received here over a real UDP socket), the status events of
the JSON-lines log, and the session recording; ``/rtseg/status`` keeps its ``ifii`` form.
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time
from pathlib import Path

from osc_collector import OscCollector

from rtseg.drivers import open_source
from rtseg.core.events import INPUT_COUNTERS
from rtseg.live.session import LiveSession
from rtseg.publishers.osc.message import encode_message
from rtseg.recording import read_session
from rtseg.live.config import from_dict
from rtseg.simulators.serial_device import SerialSuit
from rtseg.simulators.synth.motion import synthesize

RATE = 120.0
SPEED = 4.0


def config(tmp_path: Path, port: int) -> object:
    return from_dict({"output": {"osc": [f"127.0.0.1:{port}"],
                                 "jsonl": str(tmp_path / "events.jsonl")},
                      "recording": {"dir": str(tmp_path / "rec")},
                      "status": {"interval": 0.2}}, origin="test")


def run(session: LiveSession) -> tuple[threading.Thread, dict]:
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("summary", session.run()), daemon=True)
    t.start()
    return t, box


def check_shown(summary, rx: OscCollector, tmp_path: Path) -> list[int]:
    """The counters agree across summary, OSC, JSON lines and recording; returns them in
    ``INPUT_COUNTERS`` order (the final values)."""
    final = [summary.input[k] for k in INPUT_COUNTERS]
    c = summary.input
    assert (f"bad input: {c['corrupt']} corrupt ({c['crc_failures']} CRC), "
            f"{c['bad_messages']} bad messages, {c['bad_values']} bad values, "
            f"{c['unknown_names']} unknown names") in summary.text()
    # OSC: /rtseg/status unchanged (ifii), /rtseg/input iiiii right after it, never falling
    assert not rx.malformed, "a datagram was not one well-formed OSC message"
    status = rx.get("/rtseg/status")
    assert status and all(t == "ifii" and len(a) == 4 for t, a in status)
    inputs = rx.get("/rtseg/input")
    assert inputs and all(t == "iiiii" for t, _ in inputs)
    seq = [a for _, a in inputs]
    assert all(all(x <= y for x, y in zip(p, q)) for p, q in zip(seq, seq[1:]))
    assert all(x <= y for x, y in zip(seq[-1], final))
    order = [addr for addr, _, _ in rx.messages if addr in ("/rtseg/status", "/rtseg/input")]
    assert all(order[i - 1] == "/rtseg/status" for i, a in enumerate(order) if a == "/rtseg/input")
    # JSON lines: every status line carries the counters; the last (alive 0) = last OSC
    lines = [json.loads(ln) for ln in (tmp_path / "events.jsonl").read_text().splitlines()]
    st = [d for d in lines if d["type"] == "status"]
    assert st[-1]["alive"] == 0
    assert [st[-1][k] for k in INPUT_COUNTERS] == seq[-1]
    # recording: the same status events
    rec = [e for e in read_session(tmp_path / "rec").meta["events"] if e.get("type") == "status"]
    assert [rec[-1][k] for k in INPUT_COUNTERS] == seq[-1]
    return final


def test_corrupt_serial_frames_on_a_pty_are_shown(tmp_path):
    take = synthesize("idle:2,walk:2", frame_rate=RATE, seed=1).take
    play_s = take.n_frames / (RATE * SPEED)
    suit = SerialSuit(take, rate=RATE, speed=SPEED, faults="corrupt=0.003,seed=5")
    rx = OscCollector()
    try:
        path = suit.start()
        session = LiveSession(f"serial://{path}?rate={RATE:g}", config(tmp_path, rx.port),
                              handle_signals=False)
        t, box = run(session)
        assert suit.wait_done(play_s + 15)
        time.sleep(0.4)
        session.stop("test done")
        t.join(10)
    finally:
        suit.stop()
        rx.close()
    summary = box["summary"]
    corrupted = sum(1 for m in suit.sent_log if m.fate == "corrupted")
    assert corrupted >= 10, "the fault injector corrupted too few messages to test"
    corrupt, crc, bad_msgs, bad_values, unknown = check_shown(summary, rx, tmp_path)
    # each damaged message is refused once (a hit delimiter can merge two into one, a
    # damaged length byte can split one): the count is of the order of what was damaged
    assert corrupted // 2 <= corrupt <= 2 * corrupted
    assert 0 < crc <= corrupt
    assert summary.dropped > 0          # frames lost to the damage are counted apart
    assert unknown == 0


def test_junk_udp_datagrams_are_shown(tmp_path):
    rx = OscCollector()
    source = open_source("osc://127.0.0.1:0?format=vmc")
    n_junk, n_badtype, n_unknown, n_nan = 400, 30, 20, 10
    try:
        session = LiveSession(source, config(tmp_path, rx.port), handle_signals=False)
        t, box = run(session)
        time.sleep(0.3)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            dest = ("127.0.0.1", source.port)
            for i in range(n_junk):          # not OSC: no leading '/', or not 4-byte aligned
                tx.sendto(bytes([1 + i % 200]) * (4 * (1 + i % 7) + (i % 2) * 3), dest)
                if i % 50 == 0:
                    time.sleep(0.01)
            for _ in range(n_badtype):
                tx.sendto(encode_message("/VMC/Ext/Bone/Pos", "s", ["Hips"]), dest)
            for _ in range(n_unknown):
                tx.sendto(encode_message("/VMC/Ext/Bone/Pos", "sfffffff",
                                         ["Tail", 0, 0, 0, 0, 0, 0, 1]), dest)
            for _ in range(n_nan):
                tx.sendto(encode_message("/VMC/Ext/Bone/Pos", "sfffffff",
                                         ["Hips", 0, 0, 0, math.nan, 0, 0, 1]), dest)
        time.sleep(0.6)                      # at least two status intervals
        session.stop("test done")
        t.join(10)
    finally:
        rx.close()
    summary = box["summary"]
    counts = check_shown(summary, rx, tmp_path)
    assert counts == [n_junk, 0, n_badtype, n_nan, n_unknown]
    assert summary.dropped == 0 and summary.frames_received == 0
    # the final /rtseg/input already had every count (sent before the source closed)
    assert rx.get("/rtseg/input")[-1][1] == counts


def test_clean_input_sends_no_input_message(tmp_path):
    rx = OscCollector()
    try:
        session = LiveSession("sim://synth?script=idle:2&speed=4", config(tmp_path, rx.port),
                              handle_signals=False)
        summary = session.run()
    finally:
        rx.close()
    assert rx.get("/rtseg/status") and not rx.get("/rtseg/input")
    assert summary.input == dict.fromkeys(INPUT_COUNTERS, 0)
    assert "bad input: 0 corrupt (0 CRC)" in summary.text()


def test_console_status_line_shows_bad_input():
    import io
    from rtseg.commands.live import Console
    from rtseg.core.events import StatusEvent
    err = io.StringIO()
    con = Console(out=io.StringIO(), err=err)
    con(StatusEvent(frame_rate=120.0, time=1.0))
    con._last_plain = 0.0
    con(StatusEvent(frame_rate=120.0, time=2.0, corrupt=8005, crc_failures=8000, unknown_names=1))
    lines = err.getvalue().splitlines()
    assert "bad input" not in lines[0]
    assert "bad input: 8005 corrupt (8000 CRC), 0 bad messages, 0 bad values, 1 unknown names" \
        in lines[1]
