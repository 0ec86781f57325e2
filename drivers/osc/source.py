"""Live VMC input over OSC/UDP: ``osc://HOST:PORT?format=vmc&suit=default17&quiet=0.02``.

rtseg listens as a VMC receiver ("Marionette", default UDP 39539) on **127.0.0.1** unless
another address is written: ``osc://`` and ``osc://:39541`` listen on loopback only (a
sender on the same machine); ``osc://0.0.0.0:39539`` (every IPv4 interface),
``osc://[::]:39539`` or an interface address must be given explicitly to receive from
other machines - and then anyone who can reach that port can send poses and so fire cues:
restrict senders with ``allow=``.  One reader thread
blocks on the socket, feeds every datagram in arrival order to a
:class:`rtseg.drivers.osc.vmc.codec.VmcAssembler`, and queues the completed frames; ``read``
takes them off the queue.  (No threaded OSC server: it would handle datagrams in parallel
and could reorder the parts of a skeleton.)

``osc://HOST:PORT?format=vrchat`` instead reads VRChat-style OSC trackers (head + 8
trackers, world orientations, default port 9000; options quiet, queue, rate, rcvbuf and
``root=head|1..8``, the tracker whose position is ``Frame.root_position``); see
:mod:`rtseg.drivers.osc.vrchat`.

URL options (VMC)
-----------------
``format``   ``vmc`` (default) or ``vrchat``.
``suit``     suit profile in ``config/suits.toml`` giving bone order and hierarchy
             (default ``default17``).
``quiet``    seconds without datagrams after which an open frame is closed (default 0.02).
``queue``    frames held for ``read`` (default 256).  **Drop policy**: when full, the
             *oldest* queued frame is discarded (a live segmenter wants the newest data),
             counted in ``stats.dropped`` and logged.
``rate``     nominal frame rate in Hz to report as ``frame_rate`` (VMC does not announce it;
             default: unknown, None).
``rcvbuf``   SO_RCVBUF in bytes (default ``DEFAULT_RCVBUF``, 4 MiB; the kernel caps it at
             ``net.core.rmem_max``, and ``.rcvbuf`` is what it granted).  The socket's
             buffer is what holds datagrams while the reader thread waits for a core:
             the OS default (about 200 KB on Linux) holds three 64 KB datagrams, so a
             sender of oversized junk and a reader paused for 25 ms lose valid frames.
``tolerance``  accepted | |q|² - 1 | for incoming quaternions (default 0.05); accepted ones
             are renormalised.
``time_order``  ``last`` (default: ``/VMC/Ext/T`` follows the bones it stamps, as
             VirtualMotionCapture sends it) or ``first`` (T opens each frame); see
             ``VmcAssembler``.
``burst``    seconds within which the datagrams of one frame arrive (default 0.004): a root
             arriving later than this after a frame's first bone starts a new frame.
``allow``    senders accepted, comma separated addresses or CIDR networks
             (``allow=192.168.1.20,10.0.0.0/24``; default: any sender that can reach the
             bound address).  Datagrams from others are dropped before decoding, counted in
             ``stats.refused_senders`` and logged once per sender address.  (Both formats.)
``senders``  one stream per sender (both formats): ``one`` (default) follows the first
             sender (address and port) and refuses datagrams from any other, counted in
             ``stats.other_senders`` with one warning naming each; once the followed sender
             has been silent for ``SENDER_HANDOVER`` s (a restarted sender gets a new port)
             the next one is followed.  ``newest`` follows the sender that started last (a
             new sender takes over at once; the open frame is closed first).  ``merge``
             decodes every sender's datagrams as one stream (only right when they send
             parts of one skeleton).

Frames: ``space = "local"`` (parent-relative rotations), joints in suit order,
right-handed Y-up scalar-last; ``recv_time`` monotonic s when the frame closed,
``source_time`` = ``/VMC/Ext/T`` (s, sender clock), ``seq`` = frame counter from 0,
``valid`` False for bones absent from that frame (their last value is repeated),
``root_position`` see ``VmcAssembler``.  Port 0 binds an ephemeral port: read ``.port``.
"""

from __future__ import annotations

import logging
import math
import socket
import threading
import time
from collections import deque
from typing import Any, Sequence

from rtseg.core.frame import Frame
from rtseg.core.session_log import start_thread
from rtseg.drivers.base import FrameQueue, QueuedSource, SourceError
from rtseg.drivers.osc.url import (DEFAULT_HOST, Network, allow_option, check_options, is_wide,
                                   load_suit, number_option, parse_location, sender_allowed)
from rtseg.drivers.osc.vmc.codec import DEFAULT_PORT, VmcAssembler
from rtseg.drivers.osc.vrchat import DEFAULT_PORT as VRCHAT_PORT
from rtseg.drivers.osc.vrchat import JOINT_NAMES as VRCHAT_JOINTS
from rtseg.drivers.osc.vrchat import VrchatAssembler

log = logging.getLogger("rtseg.drivers.osc")

FORMATS = ("vmc", "vrchat")
OPTIONS = ("format", "suit", "quiet", "queue", "rate", "rcvbuf", "tolerance", "time_order",
           "burst", "allow", "senders")
VRCHAT_OPTIONS = ("format", "quiet", "queue", "rate", "rcvbuf", "root", "allow", "senders")
#: SO_RCVBUF asked for when the URL gives no ``rcvbuf=`` (bytes; capped by the kernel)
DEFAULT_RCVBUF = 4 << 20
#: ``senders=`` policies (see module docstring)
SENDER_POLICIES = ("one", "newest", "merge")
#: seconds of silence from the followed sender after which another sender is followed
SENDER_HANDOVER = 1.0
#: most datagrams one ``poll`` takes from the socket (the rest wait for the next)
POLL_BURST = 256
#: distinct refused senders remembered (each is logged once); later ones are only counted
MAX_REFUSED_LOGGED = 1024
#: what the kernel charges a socket's receive buffer for a datagram of n bytes, at most
#: (``KERNEL_BYTES_PER_BYTE`` x n + ``KERNEL_BYTES_PER_DATAGRAM``: measured on Linux
#: loopback, 834 bytes for 64 and 8 738 for 4 000)
KERNEL_BYTES_PER_BYTE = 2.5
KERNEL_BYTES_PER_DATAGRAM = 1024
#: frames a VMC source lets wait unread at most (``OscVmcSource.hold_frames``)
HOLD_FRAMES_MAX = 16

class OscUdpSource(QueuedSource):
    """Shared machinery of the OSC sources: a UDP socket read by one thread that feeds an
    assembler (``feed(data, now)`` / ``flush(now)`` returning frames) and a bounded queue
    (drop-oldest).  ``.port`` is the bound port."""

    _asm: Any
    #: name in the drop warning, and the logger it goes to
    _fmt = "VMC"
    _log = log

    def _start(self, host: str, port: int, quiet: float, queue_size: int,
               rcvbuf: int | None, allow: tuple[Network, ...] | None = None,
               senders: str = "merge") -> None:
        """Bind and start the reader.  ``senders``: the ``senders=`` policy; ``merge`` for
        sources whose protocol keys streams itself (MVN characters, actors)."""
        if senders not in SENDER_POLICIES:
            raise SourceError(f"osc:// senders={senders!r}: expected one of "
                              f"{', '.join(SENDER_POLICIES)}")
        self.allow = allow
        self.senders = senders
        #: (host, port) of the sender followed, None before the first datagram
        self.sender: tuple | None = None
        self._sender_last = -math.inf
        self._others: set[tuple] = set()
        self._refused: set[str] = set()
        self._queue = FrameQueue(queue_size)   # drop policy: the oldest frame goes
        #: the kernel's receive-buffer bytes of the datagrams since the last frame, and of
        #: each of the last 64 frames (``hold_frames``)
        self._kernel_bytes = 0.0
        self._frame_costs: deque[float] = deque(maxlen=64)
        self._stop = threading.Event()
        self._closed = False
        self._last_drop_log = -math.inf
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
            family, _, _, _, addr = infos[0]
            self._sock = socket.socket(family, socket.SOCK_DGRAM)
        except (OSError, UnicodeError) as exc:
            raise SourceError(f"osc://{host}:{port}: {exc}") from None
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF,
                                  int(rcvbuf) if rcvbuf else DEFAULT_RCVBUF)
            self._sock.bind(addr)
        except (OSError, OverflowError) as exc:
            self._sock.close()
            raise SourceError(f"cannot listen on UDP {host}:{port}: {exc}") from None
        self.host = host
        self.port: int = self._sock.getsockname()[1]
        #: the receive buffer the kernel granted, bytes (Linux reports twice the request,
        #: its bookkeeping included)
        self.rcvbuf: int = self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        if is_wide(host):
            log.warning("OSC: listening on %s:%d - reachable from other machines; %s",
                        host, self.port,
                        "senders restricted to allow=" + ",".join(map(str, allow)) if allow
                        else "any host that can reach it can send poses (restrict with allow=)")
        # wake up often enough to apply the quiet-gap rule and to notice close()
        self._quiet_wait = max(0.001, min(quiet / 2.0, 0.05))
        self._sock.settimeout(self._quiet_wait)
        self._polled = False
        self._poll_at: float | None = None
        self._thread = start_thread(self._run, name=f"rtseg-osc-{self.port}")

    @property
    def assembler(self) -> Any:
        return self._asm

    def _run(self) -> None:
        sock = self._sock
        while not self._stop.is_set() and not self._polled:
            try:
                data, sender = sock.recvfrom(65536)
            except (socket.timeout, BlockingIOError, InterruptedError):
                self._flush(time.monotonic())
                continue
            except OSError as exc:
                if self._stop.is_set():
                    break
                log.warning("OSC receive error on port %d: %s", self.port, exc)
                time.sleep(0.01)
                continue
            self._datagram(data, sender, time.monotonic())

    def _flush(self, now: float) -> None:
        """Close an open frame left quiet (the assembler's quiet-gap rule)."""
        try:
            frames = self._asm.flush(now)
        except Exception:  # pragma: no cover - a decoder bug must not end the loop
            log.exception("OSC: flushing the open frame failed")
            return
        for frame in frames:
            self._put(frame)

    def _datagram(self, data: bytes, sender: tuple, now: float) -> None:
        """One datagram from ``sender``, received at ``now``: refused (``allow=``, another
        sender) or decoded, its completed frames queued."""
        if self.allow is not None and not sender_allowed(sender[0], self.allow):
            self._refuse(sender[0])
            return
        if self.senders != "merge" and not self._follow(sender[:2], now):
            return
        self._kernel_bytes += KERNEL_BYTES_PER_BYTE * len(data) + KERNEL_BYTES_PER_DATAGRAM
        try:
            frames = self._asm.feed(data, now)
        except Exception:  # a decoder bug must not kill the live loop
            self.count("corrupt")
            log.exception("OSC: datagram of %d bytes crashed the decoder; dropped",
                          len(data))
            return
        if frames:
            self._frame_costs.append(self._kernel_bytes / len(frames))
            self._kernel_bytes = 0.0
        for frame in frames:
            self._put(frame)

    # ------------------------------------------------------------------ polled reading
    # (``rtseg.drivers.base.Source``: the owner's event loop reads the socket instead of
    # the reader thread, with the thread's quiet-gap rule)

    def take_over(self) -> bool:
        """End the reader thread and let the caller poll the socket (False for a subclass
        with a reader loop of its own)."""
        if self._polled:
            return True
        if type(self)._run is not OscUdpSource._run or self._closed \
                or not self._thread.is_alive():
            return False
        self._polled = True
        self._thread.join(timeout=2.0)
        if self._thread.is_alive():          # pragma: no cover - a wedged thread
            self._polled = False
            return False
        self._sock.setblocking(False)
        self._poll_at = time.monotonic() + self._quiet_wait
        return True

    def give_back(self) -> bool:
        """Read in the reader thread again (after ``take_over``)."""
        if not self._polled:
            return True
        if self._closed:
            return False
        self._sock.settimeout(self._quiet_wait)
        self._polled = False
        self._thread = start_thread(self._run, name=f"rtseg-osc-{self.port}")
        return True

    def poll_fds(self) -> tuple[int, ...]:
        return () if self._closed else (self._sock.fileno(),)

    def poll_due(self) -> float | None:
        return self._poll_at

    def poll(self, now: float) -> None:
        """Take the datagrams waiting in the socket (at most ``POLL_BURST``) in arrival
        order; none waiting: the quiet-gap flush, as the reader thread's timeout does."""
        if self._closed:
            return
        sock = self._sock
        got = 0
        while got < POLL_BURST:
            try:
                data, sender = sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                if not self._closed:
                    log.warning("OSC receive error on port %d: %s", self.port, exc)
                break
            got += 1
            self._datagram(data, sender, time.monotonic())
        if got:
            self._poll_at = time.monotonic() + self._quiet_wait
        else:
            self._flush(now)
            self._poll_at = now + self._quiet_wait

    def _follow(self, sender: tuple, now: float) -> bool:
        """Whether a datagram from ``sender`` belongs to the stream followed (switching to
        it when the policy says so); a refused one is counted in ``other_senders``."""
        if sender == self.sender:
            self._sender_last = now
            return True
        if self.sender is None or self.senders == "newest" or \
                now - self._sender_last >= SENDER_HANDOVER:
            if self.sender is not None:
                for frame in self._asm.flush(now, force=True):
                    self._put(frame)
                self._asm.new_sender()
                log.warning("OSC port %d: now following sender %s:%s (was %s:%s)", self.port,
                            sender[0], sender[1], self.sender[0], self.sender[1])
            self.sender = sender
            self._sender_last = now
            self._others.discard(sender)
            return True
        self.count("other_senders")
        if sender not in self._others and len(self._others) < MAX_REFUSED_LOGGED:
            self._others.add(sender)
            log.warning("OSC port %d: a second sender %s:%s refused while following %s:%s "
                        "(senders=one; use senders=newest or senders=merge to change); its "
                        "datagrams are counted in other_senders", self.port, sender[0],
                        sender[1], self.sender[0], self.sender[1])
        return False

    def _refuse(self, host: str) -> None:
        """Count a datagram from a sender outside ``allow``; log each sender once."""
        self.count("refused_senders")
        if host not in self._refused and len(self._refused) < MAX_REFUSED_LOGGED:
            self._refused.add(host)
            log.warning("OSC port %d: datagram from %s refused (not in allow=%s); further "
                        "datagrams from it are counted in refused_senders, not logged",
                        self.port, host, ",".join(map(str, self.allow or ())))

    def _put(self, frame: Frame) -> None:
        if self._queue.put(frame):
            self.count("dropped")
            now = time.monotonic()
            if now - self._last_drop_log > 5.0:
                self._last_drop_log = now
                self._log.warning("%s: reader too slow, dropped oldest queued frame "
                                  "(%d dropped so far)", self._fmt, self.stats.dropped)

    def close(self) -> None:
        """Stop the reader thread, wake blocked readers and close the socket.  Safe to call
        twice."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._queue.close()
        self._thread.join(timeout=2.0)
        self._sock.close()


class OscVmcSource(OscUdpSource):
    """VMC receiver on a UDP socket (see module docstring).  ``.port`` is the bound port."""

    space = "local"

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 suit: str = "default17", bone_names: Sequence[str] | None = None,
                 parents: Sequence[int] | None = None, quiet: float = 0.02,
                 queue_size: int = 256, rate: float | None = None,
                 rcvbuf: int | None = None, tolerance: float = 0.05,
                 time_order: str = "last", burst: float = 0.004,
                 allow: tuple[Network, ...] | None = None, senders: str = "one") -> None:
        super().__init__()
        if bone_names is None:
            bones, pars = load_suit(suit)
        else:
            bones = list(bone_names)
            pars = list(parents) if parents is not None else [-1] * len(bones)
        if len(pars) != len(bones):
            raise SourceError("parents and bone_names differ in length")
        if not quiet > 0:
            raise SourceError(f"quiet must be positive seconds, got {quiet}")
        self.joint_names = bones
        self.parents = pars
        self.frame_rate = rate
        self.suit = suit
        if time_order not in ("last", "first"):
            raise SourceError(f"time_order must be 'last' or 'first', not {time_order!r}")
        self._asm = VmcAssembler(bones, quiet=quiet, unit_tolerance=tolerance,
                                 time_order=time_order, burst=burst, stats=self.stats,
                                 parents=pars)
        self._start(host, port, quiet, queue_size, rcvbuf, allow, senders)

    def hold_frames(self) -> int:
        """Frames that may wait unread (``Source.hold_frames``): 0 until the assembler
        closes frames by their content (``VmcFrameRules.closes_by_content``: batched
        datagrams, all stamped when read, then give the frames they give one by one),
        else as many as half the socket's receive buffer holds at the most the kernel
        charged for a frame's datagrams over the last 64 frames, at most
        ``HOLD_FRAMES_MAX``."""
        if not self._polled or self._closed or not self._asm.closes_by_content:
            return 0
        cost = max(self._frame_costs, default=0.0)
        if cost <= 0:
            return 0
        return min(HOLD_FRAMES_MAX, int(self.rcvbuf // 2 // cost))

    @property
    def ok_state(self) -> tuple[int, ...] | None:
        """Last ``/VMC/Ext/OK`` arguments (loaded, calibration state, mode, tracking)."""
        return self._asm.ok_state

    @property
    def rest_pose(self) -> Any:
        """The sender's rest geometry from the bone positions it sends
        (``rtseg.drivers.osc.vmc.rest``: a ``RestPose`` in profile order), or None before
        the first frames have arrived and when it sends no positions."""
        return self._asm.offsets.rest_pose()

    @property
    def t_pose_without_geometry(self) -> bool:
        """True once the first frames are in without bone positions: VRM avatars' rotations
        are from a T-pose, so names may use the standard T-pose's geometry
        (``rtseg.core.standard_rig``, the live session's facing probe)."""
        offsets = self._asm.offsets
        return not offsets.capturing and offsets.rest_pose() is None


class OscVrchatSource(OscUdpSource):
    """VRChat OSC trackers receiver (``format=vrchat``, default port 9000): joints Head,
    Tracker1..Tracker8, world orientations (``space = "global"``, no hierarchy); see
    :mod:`rtseg.drivers.osc.vrchat`.  ``root``: tracker whose position is
    ``Frame.root_position``."""

    space = "global"

    def __init__(self, host: str = DEFAULT_HOST, port: int = VRCHAT_PORT, *,
                 quiet: float = 0.02, queue_size: int = 256, rate: float | None = None,
                 rcvbuf: int | None = None, root: str | None = None,
                 allow: tuple[Network, ...] | None = None, senders: str = "one") -> None:
        super().__init__()
        if not quiet > 0:
            raise SourceError(f"quiet must be positive seconds, got {quiet}")
        self.joint_names = list(VRCHAT_JOINTS)
        self.parents = [-1] * len(VRCHAT_JOINTS)
        self.frame_rate = rate
        try:
            self._asm = VrchatAssembler(quiet=quiet, root=root, stats=self.stats)
        except ValueError as exc:
            raise SourceError(f"osc:// format=vrchat: {exc}") from None
        self._start(host, port, quiet, queue_size, rcvbuf, allow, senders)


def _num(options: dict[str, str], key: str, default, kind=float):
    return number_option("osc", options, key, default, kind)


def open_url(location: str, options: dict[str, str]) -> OscUdpSource:
    """Open ``osc://location?options`` (see module docstring)."""
    fmt = options.get("format", "vmc").lower() or "vmc"
    if fmt not in FORMATS:
        raise SourceError(f"osc:// format {fmt!r} is not supported; supported: "
                          f"{', '.join(FORMATS)}")
    check_options("osc", options, OPTIONS if fmt == "vmc" else VRCHAT_OPTIONS, fmt)
    allow = allow_option(options)
    senders = options.get("senders", "one").lower() or "one"
    if senders not in SENDER_POLICIES:
        raise SourceError(f"osc:// senders={senders!r}: expected one of "
                          f"{', '.join(SENDER_POLICIES)}")
    if fmt == "vrchat":
        host, port = parse_location(location, VRCHAT_PORT)
        return OscVrchatSource(
            host, port, quiet=_num(options, "quiet", 0.02),
            queue_size=_num(options, "queue", 256, int), rate=_num(options, "rate", None),
            rcvbuf=_num(options, "rcvbuf", None, int), root=options.get("root") or None,
            allow=allow, senders=senders)
    host, port = parse_location(location, DEFAULT_PORT)
    return OscVmcSource(
        host, port, suit=options.get("suit", "default17") or "default17",
        quiet=_num(options, "quiet", 0.02), queue_size=_num(options, "queue", 256, int),
        rate=_num(options, "rate", None), rcvbuf=_num(options, "rcvbuf", None, int),
        tolerance=_num(options, "tolerance", 0.05),
        time_order=options.get("time_order", "last").lower() or "last",
        burst=_num(options, "burst", 0.004), allow=allow, senders=senders)


__all__ = ["DEFAULT_PORT", "OscUdpSource", "OscVmcSource", "OscVrchatSource", "open_url"]
