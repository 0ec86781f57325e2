"""The live monitor's web server: one page, its static files and a WebSocket of batches.

``MonitorServer(feed, host="127.0.0.1", port=8765)`` runs an aiohttp application on its own
thread and event loop (``start()`` returns once the socket is bound, ``stop()`` ends it).
``stop()`` (called once the session has ended) sends every page what the feed still holds,
the session's end event among it, waits (at most ``close_timeout`` seconds) until each page's
queue is written, and only then closes the sockets (code 1000): a page always learns that the
session ended rather than seeing a dropped connection.

- ``GET /``: the page (``static/index.html``); ``GET /static/<name>``: the files shipped
  beside it (uPlot, the page's script and style); anything else is a 404, any other method
  a 405.
- ``GET /ws``: a WebSocket.  The server sends text messages only (JSON): first
  ``{"type": "hello", "info": ..., "history": ...}`` (the session's joints, thresholds, the
  last ``history_s`` seconds of the statistic, the cuts and behaviours so far, the latest
  health), then every ``interval`` seconds (default 0.04: at most 25 messages a second
  whatever the frame rate) one ``{"type": "batch", ...}`` merging what the feed queued.
  What the browser sends is read and ignored (at most 4 KB a message); a malformed frame
  closes that connection.
- At most ``max_clients`` pages at once (default 8); one more gets a 503.  Each page has a
  bounded queue of ``client_queue`` messages: a page that reads too slowly has its queue
  emptied and gets a fresh ``hello`` once it catches up (``stats["dropped"]`` counts the
  messages it missed); a send that blocks for ``send_timeout`` seconds closes it.  Each
  page's socket holds at most about ``send_buffer`` bytes (16 KB: seconds of updates) in
  the kernel and as much in the server's transport, so a page that stops reading is seen
  in seconds.  Nothing
  a page does reaches the session: the feed's own queue is bounded too
  (:class:`rtseg.monitor.feed.MonitorFeed`).

Binding: ``127.0.0.1`` (the default) serves this machine only.  Any other address serves
every host that can reach it: the page is read-only, but it shows the whole session
(joint names, cuts, OSC targets, the recording folder) to anyone on that network.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
import time
from collections import deque
from importlib import resources
from pathlib import Path
from typing import Any

import orjson
from aiohttp import WSMsgType, web

from rtseg.monitor.feed import MonitorFeed

log = logging.getLogger("rtseg.monitor")

__all__ = ["MonitorServer", "STATIC_FILES", "exposure_note", "is_loopback", "parse_address"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
STATIC_FILES = {"index.html": "text/html", "monitor.js": "text/javascript",
                "monitor.css": "text/css", "uPlot.iife.min.js": "text/javascript",
                "uPlot.min.css": "text/css", "uPlot.LICENSE": "text/plain"}
_CSP = ("default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data:; "
        "style-src 'self' 'unsafe-inline'")


def parse_address(text: str | None) -> tuple[str, int]:
    """``[HOST:]PORT`` (or "" / None: the default 127.0.0.1:8765) -> (host, port).
    A bad port raises ValueError naming it."""
    if not text:
        return DEFAULT_HOST, DEFAULT_PORT
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = DEFAULT_HOST, text
    host = host.strip("[]") or DEFAULT_HOST
    try:
        n = int(port)
    except ValueError:
        raise ValueError(f"monitor address {text!r}: the port must be a number") from None
    if not 0 <= n <= 65535:
        raise ValueError(f"monitor address {text!r}: port {n} is not in 0..65535")
    return host, n


def is_loopback(host: str) -> bool:
    return host in ("localhost", "::1") or host.startswith("127.")


def _load_static() -> dict[str, bytes]:
    base = resources.files("rtseg.monitor") / "static"
    return {name: (base / name).read_bytes() for name in STATIC_FILES}


class _Client:
    def __init__(self, ws: web.WebSocketResponse, size: int) -> None:
        self.ws = ws
        # messages to send; None (put once, at stop): the last, the writer ends after it
        self.queue: asyncio.Queue[bytes | None] = asyncio.Queue(maxsize=size)
        self.resync = False
        self.writer: asyncio.Future | None = None


class MonitorServer:
    """The monitor's HTTP/WebSocket server on its own thread (see the module docstring)."""

    def __init__(self, feed: MonitorFeed, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 *, interval: float = 0.04, max_clients: int = 8, client_queue: int = 64,
                 send_timeout: float = 5.0, history_s: float = 30.0,
                 send_buffer: int = 16384, close_timeout: float = 2.0) -> None:
        self.feed = feed
        self.host, self.port = host, int(port)
        self.interval = float(interval)
        self.max_clients = int(max_clients)
        self.client_queue = int(client_queue)
        self.send_timeout = float(send_timeout)
        self.history_s = float(history_s)
        self.send_buffer = int(send_buffer)
        self.close_timeout = float(close_timeout)
        self.stats = {"clients": 0, "connections": 0, "refused": 0, "dropped": 0,
                      "messages": 0, "bad_frames": 0, "slow_closed": 0}
        self._static = _load_static()
        self._clients: set[_Client] = set()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopping: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        # history (server thread only)
        self._stat: deque = deque()
        self._pre: deque = deque()
        self._gated: deque = deque(maxlen=200)
        self._cuts: deque = deque(maxlen=200)
        self._behaviours: dict[int, dict] = {}
        self._health: dict | None = None
        self._now = 0.0
        self._ended = False
        self._announced: dict | None = None     # the feed.info the pages were sent
        self._rec_size = (0.0, 0)       # (when measured, bytes)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    # ------------------------------------------------------------ lifecycle
    def start(self, timeout: float = 10.0) -> str:
        """Bind and serve on a new thread; returns the page's URL.  A bind failure raises
        OSError (the address in use, or not this machine's)."""
        self._thread = threading.Thread(target=self._run, name="rtseg-monitor", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise OSError(f"monitor server on {self.host}:{self.port} did not start")
        if self._error is not None:
            err = self._error
            raise OSError(f"monitor cannot listen on {self.host}:{self.port}: "
                          f"{getattr(err, 'strerror', None) or err}") from err
        return self.url

    def stop(self, timeout: float = 5.0) -> None:
        """Send every page what the feed holds (the session's end), then close them; end
        the thread."""
        loop, ev = self._loop, self._stopping
        if loop is not None and ev is not None and loop.is_running():
            loop.call_soon_threadsafe(ev.set)
        if self._thread is not None:
            self._thread.join(timeout)

    def _run(self) -> None:
        loop = self._loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # bind errors are reported by start()
            self._error = exc
            self._ready.set()
        finally:
            loop.close()

    async def _serve(self) -> None:
        self._stopping = asyncio.Event()
        app = web.Application(client_max_size=4096)
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._file)
        app.router.add_get("/ws", self._ws)
        runner = web.AppRunner(app, access_log=None, handle_signals=False,
                               shutdown_timeout=1.0)
        await runner.setup()
        site = web.TCPSite(runner, self.host, self.port, backlog=64)
        try:
            await site.start()
        except BaseException:
            await runner.cleanup()
            raise
        sock = site._server.sockets[0] if site._server and site._server.sockets else None
        if sock is not None:
            self.port = sock.getsockname()[1]
        self._ready.set()
        pump = asyncio.ensure_future(self._pump())
        await self._stopping.wait()
        pump.cancel()
        try:
            await pump
        except asyncio.CancelledError:
            pass
        await self._flush()
        for c in list(self._clients):
            await c.ws.close()
        await runner.cleanup()

    async def _flush(self) -> None:
        """The feed's last batches (the end of the session) to every page, then each page's
        queue written out (at most ``close_timeout`` seconds) before any socket closes."""
        self._publish()
        writers = []
        for c in list(self._clients):
            self._enqueue(c, None)
            if c.writer is not None and not c.writer.done():
                writers.append(c.writer)
        if writers:
            await asyncio.wait(writers, timeout=self.close_timeout)

    # ------------------------------------------------------------ HTTP
    async def _index(self, request: web.Request) -> web.Response:
        return self._respond("index.html")

    async def _file(self, request: web.Request) -> web.Response:
        name = request.match_info["name"]
        if name not in STATIC_FILES:
            raise web.HTTPNotFound(text=f"no such file: {name}")
        return self._respond(name)

    def _respond(self, name: str) -> web.Response:
        return web.Response(body=self._static[name], content_type=STATIC_FILES[name],
                            headers={"Content-Security-Policy": _CSP,
                                     "Cache-Control": "no-cache"})

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        if len(self._clients) >= self.max_clients:
            self.stats["refused"] += 1
            raise web.HTTPServiceUnavailable(
                text=f"the monitor serves at most {self.max_clients} pages at once")
        ws = web.WebSocketResponse(max_msg_size=4096, heartbeat=10.0, compress=False,
                                   writer_limit=self.send_buffer or 65536)
        sock = request.transport.get_extra_info("socket") if request.transport else None
        if sock is not None and self.send_buffer:
            try:    # a page that stops reading shows up after seconds, not megabytes
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self.send_buffer)
            except OSError:
                pass
        await ws.prepare(request)
        if request.transport is not None:
            request.transport.set_write_buffer_limits(high=self.send_buffer or None)
        client = _Client(ws, self.client_queue)
        self._clients.add(client)
        self.stats["connections"] += 1
        self.stats["clients"] = len(self._clients)
        client.queue.put_nowait(self._hello())
        if self.feed.info:
            self._announced = self.feed.info
        writer = client.writer = asyncio.ensure_future(self._writer(client))
        try:
            async for msg in ws:
                if msg.type == WSMsgType.ERROR:
                    self.stats["bad_frames"] += 1
                    break
        finally:
            writer.cancel()
            self._clients.discard(client)
            self.stats["clients"] = len(self._clients)
            if ws.exception() is not None and not isinstance(ws.exception(),
                                                             asyncio.CancelledError):
                log.info("monitor page closed: %s", ws.exception())
            await ws.close()
        return ws

    async def _writer(self, client: _Client) -> None:
        try:
            while True:
                msg = await client.queue.get()
                if client.resync:       # what it missed: the history (``ended`` with it)
                    client.resync = False
                    await self._send(client, self._hello())
                    if msg is not None:
                        continue
                if msg is None:         # the server stops: all is sent, the socket closes
                    return
                await self._send(client, msg)
        except asyncio.TimeoutError:
            self.stats["slow_closed"] += 1
            log.info("monitor page too slow (a send blocked %.0f s): closed", self.send_timeout)
            await client.ws.close()
        except (ConnectionError, RuntimeError):
            pass

    async def _send(self, client: _Client, msg: bytes) -> None:
        await asyncio.wait_for(client.ws.send_str(msg.decode()), self.send_timeout)
        self.stats["messages"] += 1

    # ------------------------------------------------------------ batches
    async def _pump(self) -> None:
        while True:
            await asyncio.sleep(self.interval)
            self._publish()

    def _publish(self) -> None:
        """What the feed queued, merged into one message for every page."""
        batches = self.feed.drain()
        if not batches:
            return
        merged = self._merge(batches)
        if not self._clients:
            return
        if self.feed.info is not self._announced:     # pages that came before attach
            self._announced = self.feed.info
            hello = self._hello()
            for c in list(self._clients):
                if not c.queue.full():
                    c.queue.put_nowait(hello)
        data = orjson.dumps(merged)
        for c in list(self._clients):
            self._enqueue(c, data)

    def _enqueue(self, c: _Client, data: bytes | None) -> None:
        """``data`` onto a page's queue; a full queue is emptied first and the page gets a
        fresh hello in place of what it missed (``stats["dropped"]``)."""
        if c.queue.full():
            self.stats["dropped"] += c.queue.qsize() + (data is not None)
            while not c.queue.empty():
                c.queue.get_nowait()
            c.resync = True
        c.queue.put_nowait(data)

    def _merge(self, batches: list[dict]) -> dict[str, Any]:
        """One message from the feed's batches; the history is updated with it."""
        out: dict[str, Any] = {"type": "batch", "stat": [], "pre": [], "gated": [],
                               "events": []}
        for b in batches:
            for key in ("stat", "pre", "gated", "events"):
                if key in b:
                    out[key].extend(b[key])
            if "health" in b:
                out["health"] = b["health"]
            self._now = b["now"]
        out["now"] = self._now
        self._stat.extend(out["stat"])
        self._pre.extend(out["pre"])
        self._gated.extend(out["gated"])
        lo = self._now - self.history_s
        for d in (self._stat, self._pre):
            while d and d[0][0] < lo:
                d.popleft()
        for ev in out["events"]:
            if ev["kind"] == "cut":
                self._cuts.append(ev)
            elif ev["kind"] == "behaviour":
                self._behaviours[ev["segment"]] = ev
                if len(self._behaviours) > 1000:
                    del self._behaviours[min(self._behaviours)]
            elif ev["kind"] == "end":
                self._ended = True
        if "health" in out:
            out["health"]["recording_bytes"] = self._recording_size(out["health"])
            out["health"]["monitor"] = dict(self.stats)
            self._health = out["health"]
        return out

    def _recording_size(self, health: dict) -> int | None:
        folder = health.get("recording")
        if not folder:
            return None
        now = time.monotonic()
        if now - self._rec_size[0] >= 1.0:
            total = 0
            try:
                for p in Path(folder).rglob("*"):
                    try:
                        total += p.stat().st_size if p.is_file() else 0
                    except OSError:
                        pass
            except OSError:
                pass
            self._rec_size = (now, total)
        return self._rec_size[1]

    def _hello(self) -> bytes:
        return orjson.dumps({
            "type": "hello", "info": self.feed.info, "now": self._now, "ended": self._ended,
            "history": {"stat": list(self._stat), "pre": list(self._pre),
                        "gated": list(self._gated), "cuts": list(self._cuts),
                        "behaviours": [self._behaviours[k] for k in sorted(self._behaviours)],
                        "health": self._health}})


def exposure_note(host: str, port: int) -> str:
    """What binding ``host`` exposes (for the console), "" on loopback."""
    if is_loopback(host):
        return ""
    return (f"the monitor listens on {host}:{port}, not only this machine: anyone who can "
            f"reach it can watch the session (read-only: cuts, joint names, OSC targets, "
            f"the recording folder)")

