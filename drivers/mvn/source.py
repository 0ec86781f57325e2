"""Live Xsens MVN input: ``mvn://HOST:PORT?character=0&allow=...`` (UDP, default port 9763;
``?transport=tcp`` for MVN's TCP option).

Listens on **127.0.0.1** unless another address is written (``mvn://`` and ``mvn://:9763``
are loopback only; ``mvn://0.0.0.0:9763`` receives from other machines, i.e. from MVN
Analyze/Animate on another PC - then restrict senders with ``allow=``).  One reader thread
feeds every datagram, in arrival order, to a
:class:`rtseg.drivers.mvn.assembler.MvnAssembler` (frames spanning several datagrams are
reassembled by sample counter) and queues the frames; ``read`` takes them off the queue.
The socket/thread/queue/allow-list machinery is the OSC sources' (``OscUdpSource``).

URL options
-----------
``character``  character (avatar) id to keep, 0..255 (default 0); other characters'
               datagrams are ignored (counted per id in ``assembler.other_characters``).
``suit``       suit profile in ``config/suits.toml`` whose sensor ids are MVN segment ids
               (default ``xsens-mvn``: the 23 body segments).
``quiet``      seconds after the first datagram of a frame at which an incomplete frame is
               emitted with the segments it holds (default 0.05).
``queue``      frames held for ``read`` (default 256; when full the *oldest* is dropped,
               counted in ``stats.dropped`` and logged).
``rate``       nominal frame rate in Hz to report (default unknown, None).
``rcvbuf``     SO_RCVBUF bytes (default 4 MiB, capped by the kernel: see ``rtseg.drivers.osc.source``).
``tolerance``  accepted | |q|^2 - 1 | (default 0.05).
``allow``      senders accepted, comma separated addresses / CIDR networks; others are
               dropped before decoding, counted in ``stats.refused_senders``, logged once.
``transport``  ``udp`` (default) or ``tcp``.

TCP (``transport=tcp``): MVN's network streamer sends to a destination host:port with
either protocol, so over TCP MVN is the client and rtseg **listens** on HOST:PORT (same
loopback default) and reads one connection at a time (a new one after the previous
closes; each after the first counts in ``stats.reconnects``).  The stream carries the
same MXTP messages back to back (:class:`rtseg.drivers.mvn.codec.MxtpStream` cuts it);
bytes that do not start a message are skipped to the next ``"MXTP"`` header and counted
in ``corrupt`` (one per resynchronisation).  A connection from outside ``allow`` is
closed at once (``refused_senders``).  ``rcvbuf`` does not apply.

Frames: ``space = "global"`` (segment orientations in the world), joints in suit order,
right-handed Y-up scalar-last (converted from MVN's Z-up, see ``rtseg.drivers.mvn.codec``); ``seq`` = MVN
sample counter; ``source_time`` = MVN time code in s; ``root_position`` = pelvis position
(m).  Bad datagrams are counted (``corrupt``, ``bad_values``, ``bad_messages``,
``dropped`` for late ones), never raised.  Port 0 binds an ephemeral port: read ``.port``.
"""

from __future__ import annotations

import logging
import math
import socket
import threading
import time
from typing import Any

import numpy as np

from rtseg.core.posture import PostureError, RestPose
from rtseg.drivers.base import FrameQueue, QueuedSource, SourceError
from rtseg.drivers.mvn.codec import DEFAULT_PORT, MxtpStream
from rtseg.drivers.mvn.assembler import MvnAssembler
from rtseg.core.frame import Frame
from rtseg.core.session_log import start_thread
from rtseg.drivers.osc.source import OscUdpSource
from rtseg.drivers.osc.url import (DEFAULT_HOST, Network, allow_option, check_options, is_wide,
                                   load_suit, parse_location, sender_allowed)
from rtseg.drivers.osc.url import number_option as osc_number_option

log = logging.getLogger("rtseg.drivers.mvn")

OPTIONS = ("character", "suit", "quiet", "queue", "rate", "rcvbuf", "tolerance", "allow",
           "transport")
TCP_OPTIONS = tuple(o for o in OPTIONS if o != "rcvbuf")
TRANSPORTS = ("udp", "tcp")
_RANGES = {"character": (0, 255), "quiet": (1e-4, 60.0), "queue": (1, 1_000_000),
           "rate": (1e-3, 1e5), "rcvbuf": (1, 1 << 30), "tolerance": (0.0, 1.0)}


def number_option(scheme: str, options: dict[str, str], key: str, default, kind=float,
                  ranges: dict[str, tuple[float, float]] = _RANGES):
    """Option ``key`` as ``kind`` within ``ranges[key]``, or ``default`` when absent."""
    return osc_number_option(scheme, options, key, default, kind, ranges)


class VendorUdpSource(OscUdpSource):
    """An ``OscUdpSource`` whose drop log names the format (``_fmt``)."""

    _fmt = "UDP"
    _log = log


class _RigGeometry:
    """``rest_pose`` of an MVN source: the rig's rest geometry from the first frame with
    every segment valid (each segment's world position and orientation:
    ``RestPose.from_world``), None before and when the stream sends no positions."""

    _rest: Any = None
    _rest_done = False                       # the first full frame has been looked at

    @property
    def rest_pose(self) -> Any:
        first = self._asm.first_pose
        if not self._rest_done and first is not None:
            self._rest_done = True
            others = [j for j, p in enumerate(self.parents) if p >= 0]
            if np.abs(first[0][others]).max() > 1e-6:    # else only the pelvis placed
                try:
                    self._rest = RestPose.from_world(first[0], first[1], self.parents)
                except PostureError:
                    pass                     # non-finite values: no geometry
        return self._rest


class MvnSource(_RigGeometry, VendorUdpSource):
    """Xsens MVN receiver (see module docstring).  ``.port`` is the bound port."""

    space = "global"
    _fmt = "MVN"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 suit: str = "xsens-mvn", character: int = 0, quiet: float = 0.05,
                 queue_size: int = 256, rate: float | None = None, rcvbuf: int | None = None,
                 tolerance: float = 0.05, allow: tuple[Network, ...] | None = None) -> None:
        super().__init__()
        bones, parents, ids = _suit_ids(suit)
        if not quiet > 0 or not math.isfinite(quiet):
            raise SourceError(f"quiet must be positive seconds, got {quiet}")
        self.joint_names = bones
        self.parents = parents
        self.segment_ids = ids
        self.frame_rate = rate
        self.suit = suit
        self.character = int(character)
        self._asm = MvnAssembler(ids, character=character, quiet=quiet,
                                 unit_tolerance=tolerance, stats=self.stats)
        self._start(host, port, quiet, queue_size, rcvbuf, allow)


def _suit_ids(suit: str) -> tuple[list[str], list[int], list[int]]:
    bones, parents = load_suit(suit)
    from rtseg.core.profiles import suit_profile
    return bones, parents, list(suit_profile(suit).sensor_ids)


class MvnTcpSource(_RigGeometry, QueuedSource):
    """Xsens MVN receiver over TCP (see module docstring): listens on ``host:port``
    (``.port``: the bound port), one connection at a time."""

    space = "global"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 suit: str = "xsens-mvn", character: int = 0, quiet: float = 0.05,
                 queue_size: int = 256, rate: float | None = None, tolerance: float = 0.05,
                 allow: tuple[Network, ...] | None = None) -> None:
        super().__init__()
        if not quiet > 0 or not math.isfinite(quiet):
            raise SourceError(f"quiet must be positive seconds, got {quiet}")
        self.joint_names, self.parents, ids = _suit_ids(suit)
        self.segment_ids = ids
        self.frame_rate = rate
        self.suit = suit
        self.character = int(character)
        self.allow = allow
        self._asm = MvnAssembler(ids, character=character, quiet=quiet,
                                 unit_tolerance=tolerance, stats=self.stats)
        self._stream = MxtpStream()
        self._queue = FrameQueue(queue_size)
        self._stop = threading.Event()
        self._closed = False
        self._conn: socket.socket | None = None
        self._lock = threading.Lock()
        self._last_log: dict[str, float] = {}
        #: connections accepted so far; True while one is open
        self.connections = 0
        self.connected = threading.Event()
        try:
            family, _, _, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
            self._srv = socket.socket(family, socket.SOCK_STREAM)
        except (OSError, UnicodeError) as exc:
            raise SourceError(f"mvn://{host}:{port}?transport=tcp: {exc}") from None
        try:
            self._srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._srv.bind(addr)
            self._srv.listen(2)
        except (OSError, OverflowError) as exc:
            self._srv.close()
            raise SourceError(f"cannot listen on TCP {host}:{port}: {exc}") from None
        self.host = host
        self.port: int = self._srv.getsockname()[1]
        if is_wide(host):
            log.warning("MVN: listening on tcp %s:%d - reachable from other machines; %s",
                        host, self.port, "senders restricted to allow=" +
                        ",".join(map(str, allow)) if allow else "restrict senders with allow=")
        self._tick = max(0.001, min(quiet / 2.0, 0.05))
        self._srv.settimeout(self._tick)
        self._thread = start_thread(self._run, name=f"rtseg-mvn-tcp-{self.port}")

    @property
    def assembler(self) -> MvnAssembler:
        return self._asm

    def _warn(self, key: str, msg: str, *args) -> None:
        now = time.monotonic()
        if now - self._last_log.get(key, -math.inf) >= 5.0:
            self._last_log[key] = now
            log.warning(msg, *args)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                conn, peer = self._srv.accept()
            except socket.timeout:
                self._deliver(self._asm.flush(time.monotonic()))
                continue
            except OSError:
                if self._stop.is_set():
                    return
                time.sleep(0.01)
                continue
            if self.allow is not None and not sender_allowed(peer[0], self.allow):
                self.count("refused_senders")
                self._warn("refused", "MVN: tcp connection from %s refused (not in allow=%s)",
                           peer[0], ",".join(map(str, self.allow)))
                conn.close()
                continue
            with self._lock:
                if self._stop.is_set():
                    conn.close()
                    return
                self._conn = conn
            if self.connections:
                self.count("reconnects")
            self.connections += 1
            log.info("MVN: tcp connection from %s:%d", peer[0], peer[1])
            self.connected.set()
            self._stream.reset()
            self._read(conn)
            self.connected.clear()
            with self._lock:
                self._conn = None
            conn.close()
            self._deliver(self._asm.flush(time.monotonic(), force=True))
            if not self._stop.is_set():
                self._warn("closed", "MVN: tcp connection from %s closed; waiting for the "
                           "next", peer[0])

    def _read(self, conn: socket.socket) -> None:
        conn.settimeout(self._tick)
        stream, asm = self._stream, self._asm
        while not self._stop.is_set():
            try:
                data = conn.recv(65536)
            except socket.timeout:
                self._deliver(asm.flush(time.monotonic()))
                continue
            except OSError:
                return
            if not data:
                return
            now = time.monotonic()
            before = stream.resyncs
            try:
                frames = []
                for msg in stream.feed(data):
                    frames += asm.feed(msg, now)
            except Exception:   # pragma: no cover - a decoder bug must not end the loop
                self.count("corrupt")
                log.exception("MVN: tcp read crashed the decoder; dropped")
                continue
            if stream.resyncs != before:
                self.count("corrupt", stream.resyncs - before)
                self._warn("resync", "MVN: tcp stream damaged; skipped to the next MXTP "
                           "header (%d bytes skipped so far)", stream.skipped_bytes)
            self._deliver(frames)

    def _deliver(self, frames: list[Frame]) -> None:
        for f in frames:
            if self._queue.put(f):
                self.count("dropped")
                self._warn("drop", "MVN: reader too slow, dropped oldest queued frame (%d "
                           "so far)", self.stats.dropped)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        with self._lock:
            if self._conn is not None:
                try:
                    self._conn.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        self._queue.close()
        self._thread.join(timeout=3.0)
        self._srv.close()


def open_url(location: str, options: dict[str, str]) -> MvnSource | MvnTcpSource:
    """Open ``mvn://location?options`` (see module docstring)."""
    transport = (options.get("transport") or "udp").lower()
    if transport not in TRANSPORTS:
        raise SourceError(f"mvn:// transport={options.get('transport')!r}: udp or tcp")
    check_options("mvn", options, OPTIONS if transport == "udp" else TCP_OPTIONS)
    allow = allow_option(options)
    host, port = parse_location(location, DEFAULT_PORT, "mvn")
    num = number_option
    kw = dict(suit=options.get("suit") or "xsens-mvn",
              character=num("mvn", options, "character", 0, int),
              quiet=num("mvn", options, "quiet", 0.05),
              queue_size=num("mvn", options, "queue", 256, int),
              rate=num("mvn", options, "rate", None),
              tolerance=num("mvn", options, "tolerance", 0.05), allow=allow)
    if transport == "tcp":
        return MvnTcpSource(host, port, **kw)
    return MvnSource(host, port, rcvbuf=num("mvn", options, "rcvbuf", None, int), **kw)


__all__ = ["DEFAULT_PORT", "MvnSource", "MvnTcpSource", "VendorUdpSource", "number_option",
           "open_url"]
