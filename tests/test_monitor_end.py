"""The end of a live session reaches every monitor page before its socket closes.

A session that ends normally emits a final status (alive=0); the monitor feed turns it into
an ``{"kind": "end"}`` event, and the server must deliver it to every connected page before
closing the socket (code 1000), so that the page says "session ended", stops its clock and
does not claim a disconnection.  Real sessions on ``sim://synth`` (about 1.5 s) with a
monitor on an ephemeral port, read by aiohttp WebSocket clients; the CLI path
(``rtseg live ... --monitor 127.0.0.1:0`` in-process) and, where Chromium exists, the page
itself in headless Chromium.
"""

from __future__ import annotations

import asyncio
import threading
import time

import orjson
import pytest

aiohttp = pytest.importorskip("aiohttp", reason="the monitor needs aiohttp (rtseg[monitor])")

from rtseg.live.config import from_dict  # noqa: E402
from rtseg.live.session import LiveSession  # noqa: E402
from rtseg.monitor import MonitorFeed  # noqa: E402
from rtseg.monitor.server import MonitorServer  # noqa: E402

DURATION = 1.5


async def read_until_closed(url: str, timeout: float = 30.0, clients: int = 1) -> list[dict]:
    """Per client: its messages in order, then ``{"closed": code}`` when the server closed
    the socket (nothing when the timeout came first)."""

    async def one(s: aiohttp.ClientSession) -> list:
        out: list = []
        async with s.ws_connect(url) as ws:
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                try:
                    msg = await ws.receive(timeout=max(0.01, end - time.monotonic()))
                except asyncio.TimeoutError:
                    break
                if msg.type == aiohttp.WSMsgType.TEXT:
                    out.append(orjson.loads(msg.data))
                    continue
                if msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSING,
                                aiohttp.WSMsgType.CLOSED):
                    out.append({"closed": ws.close_code})
                break
        return out

    async with aiohttp.ClientSession() as s:
        return await asyncio.gather(*(one(s) for _ in range(clients)))


def assert_end_before_close(msgs: list[dict]) -> None:
    assert msgs and msgs[0].get("type") == "hello", msgs[:1]
    assert "closed" in msgs[-1], f"the server never closed the socket: {msgs[-3:]}"
    assert msgs[-1]["closed"] == 1000, msgs[-1]
    kinds = [e["kind"] for m in msgs if m.get("type") == "batch" for e in m["events"]]
    assert "end" in kinds, f"no end event before the close; last messages: {msgs[-3:]}"
    assert kinds.count("end") == 1 and kinds[-1] == "end", kinds[-5:]


def test_every_page_gets_the_end_event_before_the_close():
    feed = MonitorFeed()
    server = MonitorServer(feed, "127.0.0.1", 0)
    server.start()
    session = LiveSession(
        "sim://synth?script=idle:4&speed=1&seed=3",
        from_dict({"output": {"osc": []}, "status": {"interval": 0.5}}),
        duration=DURATION, handle_signals=False, monitor=feed)
    result: list = []

    def run() -> None:          # as ``rtseg live``: the server stops when the session ends
        try:
            result.append(session.run())
        finally:
            server.stop()

    t = threading.Thread(target=run, daemon=True)
    t.start()
    try:
        pages = asyncio.run(read_until_closed(f"ws://127.0.0.1:{server.port}/ws", clients=3))
    finally:
        t.join(30)
    assert not t.is_alive() and result and result[0].stop_reason == "duration reached"
    for msgs in pages:
        assert_end_before_close(msgs)
    # what the pages were sent is the whole session: the last batch's clock is its end
    end = [e for m in pages[0] if m.get("type") == "batch" for e in m["events"]
           if e["kind"] == "end"][0]
    assert DURATION - 0.2 <= end["time"] <= DURATION + 1.0, end


def test_cli_live_session_sends_the_end_event(monkeypatch):
    import rtseg.monitor
    from rtseg.cli import main

    started: list = []
    real = rtseg.monitor.start_monitor

    def spy(address):
        feed, server = real(address)
        started.append(server)
        return feed, server

    monkeypatch.setattr(rtseg.monitor, "start_monitor", spy)
    status: list = []
    t = threading.Thread(target=lambda: status.append(main(
        ["live", "sim://synth", "--duration", str(DURATION), "--no-osc", "--quiet",
         "--monitor", "127.0.0.1:0"])), daemon=True)
    t.start()
    deadline = time.monotonic() + 30
    while not started and time.monotonic() < deadline and t.is_alive():
        time.sleep(0.01)
    assert started, "the monitor did not start"
    try:
        (msgs,) = asyncio.run(read_until_closed(f"ws://127.0.0.1:{started[0].port}/ws"))
    finally:
        t.join(30)
    assert status == [0]
    assert_end_before_close(msgs)


def test_page_says_the_session_ended_and_stops_its_clock(monkeypatch):
    from rtseg.monitor.headless import HeadlessPage, find_chromium
    if find_chromium() is None:
        pytest.skip("no chromium on PATH (apt-get install chromium)")
    feed = MonitorFeed()
    server = MonitorServer(feed, "127.0.0.1", 0)
    server.start()
    session = LiveSession(
        "sim://synth?script=idle:10&speed=1&seed=3",
        from_dict({"output": {"osc": []}, "status": {"interval": 0.5}}),
        handle_signals=False, monitor=feed)
    result: list = []

    def run() -> None:
        try:
            result.append(session.run())
        finally:
            server.stop()

    with HeadlessPage(server.url) as page:
        page.wait_for("(document.getElementById('conn') || {}).textContent === 'live'",
                      timeout=20)          # null-safe: the page may not be loaded yet
        t = threading.Thread(target=run, daemon=True)    # the page is up: run the session
        t.start()
        page.wait_for("window.rtsegMonitor && window.rtsegMonitor.info"
                      " && window.rtsegMonitor.info.joints", timeout=20)
        time.sleep(DURATION)
        session.stop("test over")
        t.join(30)
        assert not t.is_alive() and result
        conn = page.wait_for(
            "(() => { const c = document.getElementById('conn').textContent; "
            "return c !== 'live' && c; })()", timeout=10)
        assert conn == "session ended", conn
        time.sleep(1.5)           # no retry claims a disconnection later, the clock stands
        clock = page.evaluate("document.getElementById('clock').textContent")
        time.sleep(0.5)
        assert page.evaluate("document.getElementById('conn').textContent") == "session ended"
        assert page.evaluate("document.getElementById('clock').textContent") == clock
        assert page.evaluate("window.rtsegMonitor.ended") is True
