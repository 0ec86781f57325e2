"""The live monitor's server, through real sockets on 127.0.0.1: a LiveSession on a sped-up
synthetic source feeds ``rtseg.monitor.MonitorFeed``; ``MonitorServer`` (aiohttp, its own
thread) serves the page and the WebSocket.  Pages are aiohttp WebSocket clients and raw TCP
sockets (a client that never reads, a malformed frame, a flood of connections).

What must hold: the page gets the cuts the session made, at most 30 messages a second; a
stalled or closed page costs the session no frame; bad requests get a clean refusal while
the session keeps running.
"""

from __future__ import annotations

import asyncio
import base64
import os
import socket
import threading
import time

import numpy as np
import orjson
import pytest

aiohttp = pytest.importorskip("aiohttp", reason="the monitor needs aiohttp (rtseg[monitor])")

from rtseg.core.events import CutEvent  # noqa: E402
from rtseg.live.session import LiveSession  # noqa: E402
from rtseg.monitor import MonitorFeed  # noqa: E402
from rtseg.monitor.server import MonitorServer, parse_address  # noqa: E402
from rtseg.live.config import from_dict  # noqa: E402

SCRIPT = "idle:4,walk:5,punch:5"
SPEED = 4.0


def session_config(max_lag_seconds: float = 0.1, params: str = ""):
    return from_dict({"output": {"osc": []}, "status": {"interval": 0.5},
                      "buffer": {"max_lag_seconds": max_lag_seconds},
                      "detectors": {"params": params}})


class Session:
    """A LiveSession on sim://synth (``SPEED`` x real time) with a monitor on a free port,
    run on a thread."""

    def __init__(self, script: str = SCRIPT, speed: float = SPEED, max_lag_seconds: float = 0.1,
                 params: str = "", **server_args) -> None:
        self.cuts: list[CutEvent] = []
        self.feed = MonitorFeed()
        self.server = MonitorServer(self.feed, "127.0.0.1", 0, **server_args)
        self.url = self.server.start()
        self.session = LiveSession(
            f"sim://synth?script={script}&speed={speed:g}&seed=3",
            session_config(max_lag_seconds, params),
            listeners=[lambda ev: isinstance(ev, CutEvent) and self.cuts.append(ev)],
            handle_signals=False, monitor=self.feed)
        self.summary = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        self.summary = self.session.run()

    @property
    def port(self) -> int:
        return self.server.port

    def join(self, timeout: float = 30.0) -> None:
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "session did not end"
        self.server.stop()


async def read_ws(url: str, seconds: float) -> list[tuple[float, dict]]:
    """Every message of one page for ``seconds`` (or until the server closes)."""
    out = []
    async with aiohttp.ClientSession() as s:
        async with s.ws_connect(url) as ws:
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                try:
                    msg = await ws.receive(timeout=max(0.01, end - time.monotonic()))
                except asyncio.TimeoutError:
                    break
                if msg.type != aiohttp.WSMsgType.TEXT:
                    break
                out.append((time.monotonic(), orjson.loads(msg.data)))
    return out


def test_parse_address():
    assert parse_address(None) == ("127.0.0.1", 8765)
    assert parse_address("9000") == ("127.0.0.1", 9000)
    assert parse_address("0.0.0.0:9001") == ("0.0.0.0", 9001)
    with pytest.raises(ValueError, match="port"):
        parse_address("host:http")
    with pytest.raises(ValueError, match="0..65535"):
        parse_address("70000")


def test_page_gets_the_cuts_the_session_made_batched():
    run = Session()
    msgs = asyncio.run(read_ws(f"ws://127.0.0.1:{run.port}/ws", 14 / SPEED + 3))
    run.join()
    assert run.cuts, "the synthetic performance should give cuts"
    hellos = [m for _, m in msgs if m["type"] == "hello"]
    assert msgs[0][1]["type"] == "hello"
    hello = hellos[-1]       # a page that came before the session started gets a second
    assert len(hello["info"]["joints"]) == 17 and hello["info"]["threshold"] > 0
    batches = [m for _, m in msgs if m["type"] == "batch"]
    page_cuts = [e for m in batches for e in m["events"] if e["kind"] == "cut"]
    assert [c["event"] for c in page_cuts] == [c.event for c in run.cuts]
    assert [c["frame"] for c in page_cuts] == [c.frame for c in run.cuts]
    stat = [p for m in batches for p in m["stat"]]
    assert len(stat) > 20 and all(np.isfinite(v) for _, v in stat)
    assert max(v for _, v in stat) > hello["info"]["threshold"]   # the curve crossed it
    health = [m["health"] for m in batches if "health" in m]
    assert health[-1]["frames"] > 0 and len(health[-1]["stale"]) == 17
    # at most 30 messages in any one second
    times = np.array([t for t, _ in msgs])
    per_second = [np.sum((times >= t) & (times < t + 1.0)) for t in times]
    assert max(per_second) <= 30, max(per_second)
    assert run.summary.frames_processed == run.summary.frames_received


def test_the_page_gets_the_pre_look_with_sooner_cuts():
    """With the pre-look on (``--params fast``) the page also gets its values and its level
    (the pre-look scores every position; its level is pre_level x threshold); with it off
    (``--params full``), neither."""
    from rtseg.detectors import load_params
    fast = load_params("fast")["contrast"]
    for params in ("fast", "full"):
        run = Session(params=params)
        msgs = asyncio.run(read_ws(f"ws://127.0.0.1:{run.port}/ws", 14 / SPEED + 3))
        run.join()
        info = [m for _, m in msgs if m["type"] == "hello"][-1]["info"]
        pre = [p for _, m in msgs if m["type"] == "batch" for p in m.get("pre", [])]
        if params == "fast":
            assert info["pre_level"] == pytest.approx(fast["pre_level"] * fast["threshold"])
            assert len(pre) > 20 and all(np.isfinite(v) and v > 0 for _, v in pre)
        else:
            assert info["pre_level"] is None and not pre


def test_stalled_and_closed_pages_cost_the_session_no_frame():
    # max_lag_seconds 0: no overload thinning, so a frame lost could only be the pages' doing
    run = Session("idle:10,walk:20,punch:20,squat:20", client_queue=4, send_timeout=1.0,
                  send_buffer=2048, speed=16.0, max_lag_seconds=0.0)
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect(("127.0.0.1", run.port))
    stalled.sendall(handshake(run.port))           # upgraded, then never read
    closer = socket.socket()
    closer.connect(("127.0.0.1", run.port))
    closer.sendall(handshake(run.port))
    time.sleep(0.3)
    closer.close()                                 # gone without a close frame
    watcher = asyncio.run(read_ws(f"ws://127.0.0.1:{run.port}/ws", 70 / 16 + 3))
    run.join()
    stalled.close()
    s = run.summary
    assert s.frames_received > 1000
    assert s.frames_processed == s.frames_received and s.overruns == 0 and s.dropped == 0
    assert run.session.stats.monitor_errors == 0
    page_cuts = [e["event"] for _, m in watcher if m["type"] == "batch"
                 for e in m["events"] if e["kind"] == "cut"]
    assert page_cuts == [c.event for c in run.cuts]   # the healthy page saw every cut
    st = run.server.stats
    assert st["dropped"] > 0 or st["slow_closed"] > 0, st   # the stalled page was shed


def test_feed_queue_is_bounded_when_nobody_reads():
    feed = MonitorFeed(interval=0.0, capacity=8)
    s = LiveSession("sim://synth?script=idle:2&speed=2", session_config(),
                    handle_signals=False, monitor=feed)
    summary = s.run()
    assert summary.frames_processed == summary.frames_received == 240
    assert len(feed.drain()) == 8 and feed.dropped_batches == feed.batches - 8 > 0


def handshake(port: int, path: str = "/ws") -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    return (f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n\r\n").encode()


def read_until_closed(sock: socket.socket, timeout: float = 5.0) -> bytes:
    sock.settimeout(timeout)
    data = b""
    try:
        while True:
            chunk = sock.recv(65536)
            if not chunk:
                break
            data += chunk
    except (socket.timeout, ConnectionResetError):
        pass
    return data


def test_bad_requests_are_refused_and_the_session_keeps_running():
    run = Session(max_clients=3)
    base = f"http://127.0.0.1:{run.port}"

    async def http_checks() -> dict:
        out = {}
        async with aiohttp.ClientSession() as s:
            for path in ("/", "/static/uPlot.iife.min.js", "/nope", "/static/../server.py",
                         "/static/secret.txt"):
                async with s.get(base + path) as r:
                    out[path] = r.status
            async with s.post(base + "/", data=b"x") as r:
                out["POST /"] = r.status
            async with s.get(base + "/ws") as r:            # not an upgrade
                out["plain /ws"] = r.status
            # a flood: more pages than allowed
            socks = [await s.ws_connect(base + "/ws") for _ in range(3)]
            try:
                await s.ws_connect(base + "/ws")
                out["4th page"] = 101
            except aiohttp.WSServerHandshakeError as exc:
                out["4th page"] = exc.status
            for w in socks:
                await w.close()
        return out

    codes = asyncio.run(http_checks())
    assert codes["/"] == 200 and codes["/static/uPlot.iife.min.js"] == 200
    assert codes["/nope"] == 404 and codes["/static/secret.txt"] == 404
    assert codes["/static/../server.py"] == 404
    assert codes["POST /"] == 405
    assert codes["plain /ws"] >= 400
    assert codes["4th page"] == 503
    # a malformed WebSocket frame (reserved opcode 0x3, unmasked): the server closes it
    bad = socket.create_connection(("127.0.0.1", run.port))
    bad.sendall(handshake(run.port))
    time.sleep(0.2)
    bad.sendall(b"\x83\x05hello")
    reply = read_until_closed(bad)
    bad.close()
    assert reply.startswith(b"HTTP/1.1 101")
    assert b"\x88" in reply[reply.index(b"\r\n\r\n"):]      # a close frame, then EOF
    # a connection flood of raw sockets that send nothing
    idle = [socket.create_connection(("127.0.0.1", run.port)) for _ in range(50)]
    time.sleep(0.2)
    msgs = asyncio.run(read_ws(f"ws://127.0.0.1:{run.port}/ws", 1.0))
    for s in idle:
        s.close()
    assert msgs and msgs[0][1]["type"] == "hello" and len(msgs) > 5   # still serving
    assert run.thread.is_alive()                                        # still running
    run.join()
    assert run.server.stats["refused"] >= 1 and run.server.stats["bad_frames"] >= 1
    s = run.summary
    assert s.frames_processed == s.frames_received and s.dropped == 0
    assert s.stop_reason == "end of source"


def test_recorded_session_gets_the_same_page(tmp_path):
    rec = tmp_path / "rec"
    feed = MonitorFeed()
    server = MonitorServer(feed, "127.0.0.1", 0)
    server.start()
    first = LiveSession(f"sim://synth?script={SCRIPT}&speed=8&seed=3",
                        from_dict({"output": {"osc": []}, "recording": {"dir": str(rec)},
                                   "buffer": {"max_lag_seconds": 0.0}}),   # no thinning: a page, not load
                        handle_signals=False, monitor=feed)
    result: list = []
    t = threading.Thread(target=lambda: result.append(first.run()), daemon=True)
    t.start()
    msgs = asyncio.run(read_ws(f"ws://127.0.0.1:{server.port}/ws", 14 / 8 + 3))
    t.join(30)
    server.stop()
    recorded = result[0]
    assert recorded.cuts >= 1
    health = [m["health"] for _, m in msgs if m["type"] == "batch" and "health" in m]
    assert health[-1]["recording"] == str(rec) and health[-1]["recording_bytes"] > 0
    feed = MonitorFeed()
    server = MonitorServer(feed, "127.0.0.1", 0)
    server.start()
    cuts: list[CutEvent] = []
    replay = LiveSession(f"file://{rec}?speed=4", session_config(0.0), handle_signals=False,
                         monitor=feed, listeners=[lambda ev: isinstance(ev, CutEvent)
                                                  and cuts.append(ev)])
    t = threading.Thread(target=replay.run, daemon=True)
    t.start()
    msgs = asyncio.run(read_ws(f"ws://127.0.0.1:{server.port}/ws", 14 / 4 + 3))
    t.join(30)
    server.stop()
    hello = [m for _, m in msgs if m["type"] == "hello"][-1]
    assert hello["info"]["source"].startswith("file://") and len(hello["info"]["joints"]) == 17
    page_cuts = [e["frame"] for _, m in msgs if m["type"] == "batch"
                 for e in m["events"] if e["kind"] == "cut"]
    assert page_cuts == [c.frame for c in cuts] and len(cuts) == recorded.cuts


def test_without_aiohttp_monitor_is_refused_and_session_unchanged(tmp_path):
    import subprocess
    import sys
    code = ("import sys; sys.modules['aiohttp'] = None\n"
            "from rtseg.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    args = [sys.executable, "-c", code, "live", "sim://synth?script=idle:2&speed=0",
            "--no-osc", "--quiet"]
    refused = subprocess.run(args + ["--monitor"], capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2
    assert "pip install 'rtseg[monitor]'" in refused.stderr
    plain = subprocess.run(args, capture_output=True, text=True, timeout=60)
    assert plain.returncode == 0 and "240 frames received" in plain.stderr


def test_float_ring_recent_is_the_tail_of_values():
    from rtseg.live.stats import FloatRing
    r = FloatRing(7)
    for total in range(30):
        for n in (0, 1, 3, 7, 9):
            assert list(r.recent(n)) == (list(r.values()[-n:]) if n else [])
        r.append(float(total))


def test_demo_serves_the_monitor_and_prints_its_address():
    import re
    import subprocess
    import sys
    from pathlib import Path
    exe = str(Path(sys.executable).with_name("rtseg"))
    base = [exe, "demo", "--duration", "2", "--speed", "4", "--no-osc", "--no-names",
            "--quiet"]
    on = subprocess.run(base + ["--monitor", "127.0.0.1:0"], capture_output=True, text=True,
                        timeout=120)
    assert on.returncode == 0, on.stderr
    assert re.search(r"rtseg demo: live monitor at http://127\.0\.0\.1:\d+/", on.stderr)
    off = subprocess.run(base + ["--no-monitor"], capture_output=True, text=True, timeout=120)
    assert off.returncode == 0 and "live monitor" not in off.stderr


def test_a_wider_binding_is_said_to_expose_the_session():
    from rtseg.monitor.server import exposure_note
    assert exposure_note("127.0.0.1", 8765) == "" and exposure_note("localhost", 1) == ""
    note = exposure_note("0.0.0.0", 8765)
    assert "0.0.0.0:8765" in note and "anyone who can reach it can watch" in note
