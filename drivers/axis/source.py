"""Live Noitom Axis Neuron / Axis Studio BVH broadcast input.

    axis://127.0.0.1:7001?format=text      TCP client of Axis's BVH server (text frames)
    axis://:7002?format=binary             UDP listener on 127.0.0.1:7002 (binary frames)

See :mod:`rtseg.drivers.axis.codec` for both encodings.  ``format`` defaults to ``binary``;
the default port follows the format (7002 binary, 7001 text).

``format=binary``: rtseg listens on **127.0.0.1** unless the URL writes another address
(``axis://0.0.0.0:7002`` to receive from Axis on another machine - then restrict senders
with ``allow=``).  The socket machinery is the OSC sources'
(:class:`rtseg.drivers.osc.source.OscUdpSource`: one reader thread, ``allow=`` filtering
before decoding, refused senders counted, bounded drop-oldest queue).  A frame split over
several datagrams (Axis Neuron on macOS) is joined.

``format=text``: Axis is the TCP server; rtseg connects to ``host:port`` (default
127.0.0.1:7001) and reads frames separated by ``||``, in reads of up to 64 KiB: a reader
that keeps up gets one frame a read (the direct path), one that fell behind gets many (~25
of the simulator's 2.5 KB frames) and decodes them as one batch
(:class:`~rtseg.drivers.axis.frames.TextStream`: one orjson call, one Euler and one
forward-kinematics pass; the same Frames bit for bit).  A refused connection or a closed
stream is retried with exponential backoff (``backoff`` s doubling up to ``max_backoff``),
as the serial source does after an unplug; each new connection after the first counts in
``stats.reconnects`` and the partial frame before it is discarded.

URL options
-----------
``format``   ``binary`` (default) or ``text``.
``avatar``   avatar to follow: its index (``avatar=1``) or name (``avatar=Avatar01``)
             (default: the first avatar seen).  Frames of other avatars are skipped and
             counted in ``.other_avatars`` (not an error: several performers share a stream).
``order``    Euler order of the rotation channels as configured in Axis (default ``YXZ``).
``rate``     nominal frame rate in Hz (default 60; Axis does not announce it).
             ``source_time`` = binary frame index / rate.
``unit``     length unit of positions: ``cm`` (default, Axis's BVH unit), ``m`` or ``mm``.
``space``    ``global`` (default: world orientations, the BVH rotations chained by
             forward kinematics in the source) or ``local`` (the BVH's parent-relative
             rotations, as sent).  Axis's rotations are relative to the T-pose it
             calibrated (its BVH rest pose), so its world orientations are the features of
             a global IMU suit as they stand; the live loop calibrates *local* sources
             again against their first frames (``calibration.mode = "auto"``), which here
             would re-reference to whatever pose the performer holds when rtseg starts
             (docs/protocols.md, "Default space").
``queue``    frames held for ``read`` (default 256; the oldest is dropped when full,
             counted in ``stats.dropped``).
``rcvbuf``   SO_RCVBUF bytes (binary).  ``allow``: accepted senders (binary).
``backoff``, ``max_backoff``  reconnect delays in seconds (text; default 0.2 and 5).

Frames: the 59 Axis joints (:data:`~rtseg.drivers.axis.codec.JOINTS`) with their hierarchy,
``space = "global"`` (world orientations, right-handed Y-up, scalar-last; BVH
parent-relative rotations with ``space=local``), ``root_position`` = Hips position in
metres, ``seq`` = binary frame index (text: count of frames received), ``valid`` False for
joints whose angles are not finite (in global space also for their descendants, whose
world orientation chains through them).  Counters:
damaged bytes -> ``corrupt``; a frame whose value count fits no layout -> ``bad_messages``;
non-finite angles -> ``bad_values``; a binary frame index that jumps forward -> 1 in
``gaps`` and the frames skipped in ``dropped``.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from typing import Any

from rtseg.drivers.base import FrameQueue, QueuedSource, Source, SourceError
from rtseg.drivers.axis.codec import BINARY_PORT, JOINTS, PARENTS, TEXT_PORT
from rtseg.drivers.axis.frames import AxisFrames, TextStream, _BinaryAdapter
from rtseg.drivers.osc.source import OscUdpSource
from rtseg.drivers.osc.url import (DEFAULT_HOST, Network, allow_option, check_options,
                                   number_option, parse_location, sender_allowed)
from rtseg.core.frame import Frame
from rtseg.core.session_log import start_thread

log = logging.getLogger("rtseg.drivers.axis")

FORMATS = ("binary", "text")
UNITS = {"cm": 0.01, "m": 1.0, "mm": 0.001}
BINARY_OPTIONS = ("format", "avatar", "order", "rate", "unit", "space", "queue", "rcvbuf",
                  "allow")
TEXT_OPTIONS = ("format", "avatar", "order", "rate", "unit", "space", "queue", "backoff",
                "max_backoff")
SPACES = ("local", "global")
#: most datagrams an Axis binary source takes from its socket in one go (see
#: :meth:`AxisBinarySource._run`)
BURST = 64
_RANGES = {"rate": (1e-3, 1e5), "queue": (1, 1_000_000), "rcvbuf": (1, 1 << 30),
           "backoff": (1e-3, 60.0), "max_backoff": (1e-3, 600.0)}


class _AvatarFrames:
    """What both Axis sources read off their ``AxisFrames`` (``self._frames``)."""

    _frames: AxisFrames

    @property
    def other_avatars(self) -> int:
        """Frames of avatars other than the one followed (counted, not delivered)."""
        return self._frames.other_avatars

    @property
    def rest_pose(self) -> Any:
        """The avatar's rest geometry from a stream with displacement
        (``AxisFrames.rest``), or None."""
        return self._frames.rest

    @property
    def t_pose_without_geometry(self) -> bool:
        """True once the stream is known to give no rest geometry (no displacement):
        Axis Neuron's skeleton rests in a T-pose, so names may use the standard T-pose's
        geometry (``rtseg.core.standard_rig``, the live session's facing probe)."""
        return self._frames.no_geometry


class AxisBinarySource(_AvatarFrames, OscUdpSource):
    """Axis binary BVH frames on a UDP socket (see module docstring).  ``.port``: bound
    port."""

    space = "global"

    def __init__(self, host: str = DEFAULT_HOST, port: int = BINARY_PORT, *,
                 avatar: str | None = None, order: str = "YXZ", rate: float = 60.0,
                 unit_scale: float = 0.01, space: str = "global", queue_size: int = 256,
                 rcvbuf: int | None = None, allow: tuple[Network, ...] | None = None) -> None:
        super().__init__()
        self.joint_names = list(JOINTS)
        self.parents = list(PARENTS)
        self.frame_rate = float(rate)
        self.space = space
        self._frames = AxisFrames(self.count, avatar, order, unit_scale, rate, space)
        self._asm = _BinaryAdapter(self._frames)
        self._start(host, port, 0.1, queue_size, rcvbuf, allow)

    def _run(self) -> None:
        """:class:`OscUdpSource`'s reader loop, except that the datagrams already waiting
        in the socket buffer when one arrives (up to :data:`BURST`) are taken with it and
        decoded as one batch (:meth:`_BinaryAdapter.feed_many`): a reader that fell behind
        catches up at the batch rate; one that keeps up sees batches of one."""
        sock, asm, timeout = self._sock, self._asm, self._sock.gettimeout()
        while not self._stop.is_set():
            try:
                data, sender = sock.recvfrom(65536)
            except (socket.timeout, BlockingIOError, InterruptedError):
                try:
                    asm.flush(time.monotonic())
                except Exception:  # pragma: no cover - a decoder bug must not end the loop
                    log.exception("Axis: flushing the open frame failed")
                continue
            except OSError as exc:
                if self._stop.is_set():
                    break
                log.warning("Axis: receive error on port %d: %s", self.port, exc)
                time.sleep(0.01)
                continue
            batch = []
            try:
                sock.settimeout(0.0)                  # take only what is already there
                while True:
                    if self.allow is not None and not sender_allowed(sender[0], self.allow):
                        self._refuse(sender[0])
                    else:
                        batch.append(data)
                    if len(batch) >= BURST:
                        break
                    data, sender = sock.recvfrom(65536)
            except OSError:                           # BlockingIOError: nothing more
                pass
            finally:
                try:
                    sock.settimeout(timeout)
                except OSError:                       # closed meanwhile
                    pass
            if not batch:
                continue
            try:
                frames = (asm.feed(batch[0], time.monotonic()) if len(batch) == 1
                          else asm.feed_many(batch, time.monotonic()))
            except Exception:  # a decoder bug must not kill the live loop
                self.count("corrupt")
                log.exception("Axis: %d datagram(s) crashed the decoder; dropped", len(batch))
                continue
            for frame in frames:
                self._put(frame)

    def _put(self, frame: Frame) -> None:
        if self._queue.put(frame):
            self.count("dropped")
            self._frames.warn("drop", time.monotonic(), "Axis: reader too slow, dropped "
                              "oldest queued frame (%d so far)", self.stats.dropped)


class AxisTextSource(_AvatarFrames, QueuedSource):
    """TCP client of Axis's text BVH server (see module docstring)."""

    space = "global"

    def __init__(self, host: str = DEFAULT_HOST, port: int = TEXT_PORT, *,
                 avatar: str | None = None, order: str = "YXZ", rate: float = 60.0,
                 unit_scale: float = 0.01, space: str = "global", queue_size: int = 256,
                 backoff: float = 0.2, max_backoff: float = 5.0,
                 connect_timeout: float = 2.0) -> None:
        super().__init__()
        self.joint_names = list(JOINTS)
        self.parents = list(PARENTS)
        self.frame_rate = float(rate)
        self.space = space
        self.host, self.port = host, int(port)
        self.backoff, self.max_backoff = float(backoff), float(max(backoff, max_backoff))
        self.connect_timeout = connect_timeout
        self._frames = AxisFrames(self.count, avatar, order, unit_scale, rate, space)
        self._queue = FrameQueue(queue_size)
        self._stop = threading.Event()
        self._closed = False
        self._sock: socket.socket | None = None
        self._sock_lock = threading.Lock()
        #: True while a connection is up
        self.connected = threading.Event()
        self.connections = 0
        self._thread = start_thread(self._run, name=f"rtseg-axis-{host}:{port}")

    def _connect(self) -> socket.socket | None:
        try:
            s = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
        except (OSError, UnicodeError) as exc:
            self._frames.warn("connect", time.monotonic(), "Axis: cannot connect to "
                              "tcp %s:%d (%s); retrying", self.host, self.port, exc)
            return None
        s.settimeout(0.1)
        return s

    def _run(self) -> None:
        delay = self.backoff
        stream = TextStream(self._frames)
        while not self._stop.is_set():
            sock = self._connect()
            if sock is None:
                if self._stop.wait(delay):
                    break
                delay = min(delay * 2.0, self.max_backoff)
                continue
            with self._sock_lock:
                if self._stop.is_set():
                    sock.close()
                    break
                self._sock = sock
            if self.connections:
                self.count("reconnects")
            self.connections += 1
            log.info("Axis: connected to tcp %s:%d", self.host, self.port)
            self.connected.set()
            delay = self.backoff
            self._read(sock, stream)
            stream.reset(time.monotonic())   # a frame cut short by the close: counted
            self.connected.clear()
            with self._sock_lock:
                self._sock = None
            sock.close()
            if not self._stop.is_set():
                log.warning("Axis: tcp %s:%d closed; reconnecting", self.host, self.port)
                if self._stop.wait(delay):
                    break

    def _read(self, sock: socket.socket, stream: TextStream) -> None:
        while not self._stop.is_set():
            try:
                data = sock.recv(65536)
            except socket.timeout:
                continue
            except OSError:
                return
            if not data:
                return
            now = time.monotonic()
            try:
                frames = stream.feed(data, now)
            except Exception:   # pragma: no cover - a decoder bug must not end the loop
                self.count("corrupt")
                log.exception("Axis: text read crashed the decoder; dropped")
                continue
            for fr in frames:
                if self._queue.put(fr):
                    self.count("dropped")
                    self._frames.warn("drop", now, "Axis: reader too slow, dropped oldest "
                                      "queued frame (%d so far)", self.stats.dropped)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        with self._sock_lock:
            if self._sock is not None:
                try:
                    self._sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        self._queue.close()
        self._thread.join(timeout=3.0)


def _num(options: dict[str, str], key: str, default, kind=float):
    return number_option("axis", options, key, default, kind, _RANGES)


def open_url(location: str, options: dict[str, str]) -> Source:
    """Open ``axis://location?options`` (see module docstring)."""
    fmt = (options.get("format") or "binary").lower()
    if fmt not in FORMATS:
        raise SourceError(f"axis:// format {fmt!r} is not supported; supported: "
                          f"{', '.join(FORMATS)}")
    known = BINARY_OPTIONS if fmt == "binary" else TEXT_OPTIONS
    check_options("axis", options, known, fmt)
    order = (options.get("order") or "YXZ").upper()
    if len(order) != 3 or set(order) != set("XYZ"):
        raise SourceError(f"axis:// order={options.get('order')!r}: a permutation of XYZ "
                          f"(as set in Axis's BVH output, default YXZ)")
    space = (options.get("space") or "global").lower()
    if space not in SPACES:
        raise SourceError(f"axis:// space={space!r}: local or global")
    unit = (options.get("unit") or "cm").lower()
    if unit not in UNITS:
        raise SourceError(f"axis:// unit={unit!r}: one of {', '.join(UNITS)}")
    host, port = parse_location(location, BINARY_PORT if fmt == "binary" else TEXT_PORT, "axis")
    kw = dict(avatar=options.get("avatar") or None, order=order,
              rate=_num(options, "rate", 60.0), unit_scale=UNITS[unit], space=space,
              queue_size=_num(options, "queue", 256, int))
    if fmt == "text":
        if port == 0:
            raise SourceError("axis:// format=text connects to Axis's server: give its port "
                              "(default 7001)")
        return AxisTextSource(host, port, backoff=_num(options, "backoff", 0.2),
                              max_backoff=_num(options, "max_backoff", 5.0), **kw)
    allow = allow_option(options, "axis")
    return AxisBinarySource(host, port, rcvbuf=_num(options, "rcvbuf", None, int),
                            allow=allow, **kw)


__all__ = ["AxisBinarySource", "AxisTextSource", "AxisFrames", "TextStream", "open_url"]
