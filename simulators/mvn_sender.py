"""Simulated Xsens MVN: send a take as MVN real-time network streaming (MXTP type 02).

``MvnSender(take, host, port, character=0, speed=1.0, ...)`` retargets ``take`` onto the
23 body segments of suit ``xsens-mvn`` (:mod:`rtseg.simulators.udp_take_sender`: global
orientations by forward kinematics; segments the take lacks, e.g. L3 or the toes, take
their parent's orientation) and sends, per frame, type-02 datagrams of at most
``max_datagram`` bytes: segment id, world position in metres (``world_positions``: the
pelvis at the take's root, the others placed by the take's rest geometry), orientation w x y z in MVN's Z-up frame (see
:mod:`rtseg.drivers.mvn.codec`).  Sample counter = frame slot; time code = take time in
ms (so ``speed`` > 1 sends faster while the time code keeps the take's clock).  Before the
first frame it sends a type-12 meta datagram (``name:<character_name>``).

``transport="tcp"``: MVN's TCP option - the sender is the TCP **client**: it connects to
``host:port`` (where ``mvn://HOST:PORT?transport=tcp`` listens), sends the meta message then
the same MXTP messages back to back, and reconnects (every 0.2 s while refused) when the
connection drops or an ``unplug`` fault closes it; frames due while it is not connected
are lost (counted in ``send_errors``, and ``Sent.delivered`` False).  ``wait_server``
seconds (``float("inf")``: however long; what ``rtseg simulate mvn --transport tcp`` does by
default): hold the clock until the first connection is made, so a receiver started after
the sender loses no frame (``waited_s`` says how long it waited).

Faults: ``faults=`` as the other vendor simulators
(:mod:`rtseg.simulators.stream_sender`).  Read it with ``rtseg live mvn://127.0.0.1:9763``
(``?character=N`` for another character, ``&transport=tcp`` for TCP).
``python -m rtseg.simulators.mvn_sender --help``.
"""

from __future__ import annotations

import socket
import time

import numpy as np

from rtseg.drivers.mvn.codec import DEFAULT_MAX_DATAGRAM, DEFAULT_PORT, encode_datagrams, \
    encode_message
from rtseg.core.posture import world_positions
from rtseg.core.profiles import SuitProfile
from rtseg.simulators.retarget import ImuModel
from rtseg.simulators.udp_take_sender import (UdpTakeSender, cli_arguments, cli_take,
                                               cli_timing, serve_options, serve_sender)
from rtseg.simulators.vmc_sender import rest_offsets, send_until_done, take_parser
from rtseg.core.take import Take


class MvnSender(UdpTakeSender):
    """Send ``take`` as MVN to ``host:port`` from a background thread (see module doc).

    ``character``: character id in the header; ``max_datagram``: split frames over
    several datagrams above this size (1472 fits the 23 segments in one); ``transport``:
    ``udp`` or ``tcp`` (see module doc); ``rate``/``speed``/``loop``/``faults``/retargeting
    options as :class:`UdpTakeSender`."""

    name = "MVN"
    #: seconds between connection attempts (TCP)
    retry = 0.2

    def __init__(self, take: Take, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 rate: float | None = None, loop: bool = False, *, speed: float = 1.0,
                 character: int = 0, character_name: str = "rtseg",
                 suit: str | SuitProfile = "xsens-mvn", skeleton_map: str | None = None,
                 joint_map: dict[str, str] | None = None, imu: ImuModel | str | None = None,
                 allow_missing: bool = False,
                 max_datagram: int = DEFAULT_MAX_DATAGRAM, transport: str = "udp",
                 faults=None, wait_server: float | None = None) -> None:
        if transport not in ("udp", "tcp"):
            raise ValueError(f"transport must be udp or tcp, not {transport!r}")
        self.transport = transport
        super().__init__(take, host, port, suit, rate=rate, loop=loop, speed=speed,
                         skeleton_map=skeleton_map, joint_map=joint_map, imu=imu,
                         allow_missing=allow_missing, faults=faults)
        #: TCP connections made so far
        self.connections = 0
        self.wait_server = wait_server
        self._next_try = 0.0
        if not 0 <= int(character) <= 255:
            raise ValueError(f"character must be 0..255, got {character}")
        self.character = int(character)
        self.character_name = character_name
        self.max_datagram = int(max_datagram)
        self.segment_ids = list(self.suit.sensor_ids)
        self._quats = np.ascontiguousarray(self.retargeted.quats)
        self._pos = self.world_positions()

    def world_positions(self) -> np.ndarray:
        """(frames, segments, 3) each segment's world position in metres, as MVN sends
        it: the pelvis at the take's root, every other segment where its rest offset from
        its parent (the take's rest geometry) puts it under the parent's orientation; every
        segment at the root when the take has no rest geometry."""
        n, s = self._quats.shape[:2]
        root = np.zeros((n, 3)) if self.root is None else np.asarray(self.root, dtype=float)
        off = rest_offsets(self.take, self.retargeted)
        if off is None:
            return np.repeat(root[:, None], s, axis=1)
        return world_positions(self._quats, self.suit.parents, off, root)

    def preamble(self) -> list[bytes]:
        return [encode_message("12", f"name:{self.character_name}\n".encode(),
                               character=self.character)]

    # -- TCP transport (UDP: the base class's)
    def _open(self) -> None:
        if self.transport == "udp":
            super()._open()

    def _ready(self) -> bool:
        if self.transport == "udp":
            return super()._ready()
        deadline = time.monotonic() + (self.wait_server or 0.0)
        while not self._connect(count=not self.wait_server):
            if not self.wait_server or time.monotonic() >= deadline:
                break
            if self._stop.wait(max(0.0, min(self._next_try - time.monotonic(), 0.2))):
                return False
        return True

    def _connect(self, count: bool = True) -> bool:
        """Connect and send the preamble; False (retried later) if refused (counted in
        ``send_errors`` when ``count``: a frame is lost with it)."""
        now = time.monotonic()
        if now < self._next_try:
            return False
        try:
            sock = socket.create_connection((self.host, self.port), timeout=1.0)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(b"".join(self.preamble()))
        except OSError as exc:
            self._next_try = now + self.retry
            if count:
                self.send_errors += 1
                self._send_failed(exc)
            return False
        self._sock = sock
        self.connections += 1
        return True

    def _send(self, dgrams: list[bytes]) -> None:
        if self.transport == "udp":
            super()._send(dgrams)
            return
        self._delivered = False
        if self._sock is None and not self._connect():
            return
        try:
            self._sock.sendall(b"".join(dgrams))
            self._delivered = True
        except OSError as exc:
            self.send_errors += 1
            self._send_failed(exc)
            self._drop_connection()

    def _drop_connection(self) -> None:
        if self._sock is not None and self.transport == "tcp":
            try:
                self._sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._sock.close()
            self._sock = None

    def _unplug(self) -> None:
        self._drop_connection()

    def encode(self, index: int, slot: int, source_time: float) -> list[bytes]:
        return encode_datagrams(slot, int(round(source_time * 1000.0)), self.segment_ids,
                                self._quats[index], self._pos[index], character=self.character,
                                max_datagram=self.max_datagram)


def serve(args, take: Take, host) -> tuple[str, list[str]]:
    """``rtseg simulate mvn``: send ``take`` over UDP, or ``--transport tcp`` to a receiver
    that listens (``host``: a :class:`rtseg.commands.simulate.Host`); returns (stop reason,
    summary lines)."""
    port = host.port(DEFAULT_PORT, faults=True)
    tcp = args.transport == "tcp"
    sender = MvnSender(take, args.host, port, character=args.character,
                       transport=args.transport,
                       wait_server=host.wait_for_peer() if tcp else None,
                       **serve_options(args, host))
    query = [f"rate={sender.rate:g}"]
    query += [f"character={args.character}"] if args.character else []
    query += ["transport=tcp"] if tcp else []
    url = f"mvn://{args.host}:{port}" + ("?" + "&".join(query) if query else "")
    return serve_sender(args, host, sender, port, url)


def main(argv: list[str] | None = None) -> int:
    """``python -m rtseg.simulators.mvn_sender``: send a synthetic or recorded take."""
    p = take_parser("python -m rtseg.simulators.mvn_sender",
                    "Send a take as Xsens MVN network streaming.")
    cli_arguments(p, DEFAULT_PORT)
    p.add_argument("--character", type=int, default=0)
    cli_timing(p)
    args = p.parse_args(argv)
    sender = MvnSender(cli_take(args), args.host, args.port, loop=args.loop, speed=args.speed,
                       character=args.character)
    send_until_done(sender)
    print(f"sent {len(sender.sent_log)} frames to {args.host}:{args.port}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
