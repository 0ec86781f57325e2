"""Simulated Axis Neuron / Axis Studio BVH broadcast (``axis://`` reads it).

``AxisSender(take, fmt="binary", host="127.0.0.1", port=7002, ...)`` sends one BVH frame
per take frame in the encodings of :mod:`rtseg.drivers.axis.codec`:

- ``fmt="binary"``: one UDP datagram per frame and avatar (64-byte header + float32
  values; ``split=1024`` cuts each frame into a 1024-byte datagram and the rest, as Axis
  Neuron does on macOS);
- ``fmt="text"``: like Axis, a **TCP server** on ``host:port`` (default 127.0.0.1:7001)
  writing ``<index> <name> v v ... ||`` to every connected client (``port=0``: an
  ephemeral port, read ``.port``).  ``wait_client`` seconds: hold the clock until the
  first client connects (``float("inf")``: however long that takes; ``rtseg simulate
  axis --axis-format text`` waits so by default), so the client receives every frame;
  ``waited_s`` says how long it waited.  Each frame's ``Sent.delivered`` says whether a
  client took it (False: written while no client was connected - lost).

What is sent: the take retargeted (:mod:`rtseg.simulators.stream_sender`) onto suit
``axis`` of ``config/suits.toml`` (HumanBodyBones names, placed on Axis joints through
``rtseg.drivers.axis.codec.SUIT_SEGMENTS``), turned into the 59-joint Axis skeleton: Spine1 and Spine2
split the Spine -> Chest (Spine3) rotation in equal thirds, fingers (and shoulders a take
lacks) are rigid with their parent; each joint's rotation relative to its Axis parent is
written as Euler angles in ``order`` (default YXZ), degrees.  With displacement (default)
the Hips carry the take's root position in cm and the other joints their rest offset from
the parent in cm (the take's rest geometry, zero without one: ``joint_offsets_cm``); without it, root position + 3 angles per joint.  Suit
bones not valid in a frame (``allow_missing``) are sent as NaN angles.

Faults (``faults=``, as the other vendor simulators, :mod:`rtseg.simulators.stream_sender`):
an ``unplug`` window closes the text server's client connections.

Several avatars: ``avatars=[(0, "Avatar00", 0), (1, "Avatar01", 240)]`` sends one frame per
avatar and take frame, each performing the take from its frame offset (wrapping).  The
binary frame index is the take frame slot, so ``rate`` on the receiver gives take time.
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.core import quat as Q
from rtseg.drivers.axis.codec import (BINARY_PORT, JOINTS, PARENTS, SUIT_SEGMENTS, TEXT_PORT,
                                      encode_binary, quat_to_euler)
from rtseg.drivers.axis.text import encode_text
from rtseg.simulators.stream_sender import FAMILY_UNITS, StreamSender
from rtseg.simulators.vmc_sender import metres_per_unit
from rtseg.core.posture import RestPose
from rtseg.core.take import Take

__all__ = ["AxisSender", "axis_globals", "serve"]


def axis_globals(quats: np.ndarray, valid: np.ndarray, suit_bones: tuple[str, ...]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Suit global orientations (frames, bones, 4) -> (frames, 59, 4) global orientations of
    the Axis joints and their validity (see the module docstring)."""
    F = quats.shape[0]
    low = {b.lower(): k for k, b in enumerate(suit_bones)}
    src = {axis: low[b.lower()] for b, axis in SUIT_SEGMENTS.items() if b.lower() in low}
    missing = [a for a in ("Hips", "Spine", "Spine3") if a not in src]
    if missing:
        raise ValueError(f"suit bones {', '.join(suit_bones)} place no {', '.join(missing)}")
    g = np.empty((F, len(JOINTS), 4))
    ok = np.empty((F, len(JOINTS)), dtype=bool)
    for j, name in enumerate(JOINTS):
        if name in src:
            g[:, j], ok[:, j] = quats[:, src[name]], valid[:, src[name]]
        elif name in ("Spine1", "Spine2"):
            sp, ch = src["Spine"], src["Spine3"]
            rel = Q.multiply(Q.conjugate(quats[:, sp]), quats[:, ch])
            frac = 1.0 / 3.0 if name == "Spine1" else 2.0 / 3.0
            part = Rotation.from_quat(rel).as_rotvec() * frac
            g[:, j] = Q.multiply(quats[:, sp], Rotation.from_rotvec(part).as_quat())
            ok[:, j] = valid[:, sp] & valid[:, ch]
        else:                                   # fingers, absent shoulders: rigid with parent
            p = PARENTS[j]
            g[:, j], ok[:, j] = g[:, p], ok[:, p]
    return Q.normalize(g), ok


class AxisSender(StreamSender):
    """Send ``take`` as Axis BVH broadcast (see module docstring)."""

    optional = frozenset({"LeftShoulder", "RightShoulder"})
    name = "axis"

    def __init__(self, take: Take, fmt: str = "binary", host: str = "127.0.0.1",
                 port: int | None = None, *, order: str = "YXZ", displacement: bool = True,
                 avatars: list[tuple[int, str, int]] | None = None, split: int | None = None,
                 wait_client: float | None = None, suit: str = "axis", **kw) -> None:
        if fmt not in ("binary", "text"):
            raise ValueError(f"format must be binary or text, not {fmt!r}")
        super().__init__(take, suit, **kw)
        self.fmt = fmt
        self.host = host
        self.port = int(port if port is not None else (BINARY_PORT if fmt == "binary"
                                                       else TEXT_PORT))
        self.order = order.upper()
        self.displacement = displacement
        self.avatars = list(avatars) if avatars else [(0, "Avatar00", 0)]
        self.split = split
        self.wait_client = wait_client
        g, ok = axis_globals(self.quats, self.valid, self.suit.bones)
        local = Q.make_continuous(Q.local_from_global(g, list(PARENTS)), 0)
        angles = quat_to_euler(self.order, local)                      # (F, 59, 3) degrees
        angles[~ok] = np.nan
        root = (np.zeros((self.n_frames, 3)) if self.root is None else self.root) * 100.0
        if displacement:
            v = np.zeros((self.n_frames, len(JOINTS), 6))
            v[:, :, 3:] = angles
            v[:, :, :3] = self.joint_offsets_cm()
            v[:, 0, :3] = root
            v = v.reshape(self.n_frames, -1)
        else:
            v = np.concatenate([root, angles.reshape(self.n_frames, -1)], axis=1)
        #: (frames, values) float32 as sent
        self.values = v.astype(np.float32)
        self._server: socket.socket | None = None
        self._clients: list[socket.socket] = []
        self._clients_lock = threading.Lock()
        self._accepting = threading.Event()
        self.client_connected = threading.Event()

    def joint_offsets_cm(self) -> np.ndarray:
        """Each Axis joint's rest offset from its parent, cm (59, 3): the take's rest
        geometry (``rtseg.core.posture.RestPose``) at the suit bones, Spine1 and Spine2 a
        third and two thirds of the way from Spine to Spine3, every other joint (fingers,
        absent shoulders) at its parent; zeros when the take has no rest geometry."""
        rest = RestPose.find(self.take)
        out = np.zeros((len(JOINTS), 3))
        if rest is None:
            return out
        scale = 100.0 * metres_per_unit(self.take, FAMILY_UNITS.get(self.retargeted.family, 1.0))
        cols = dict(zip((b.lower() for b in self.suit.bones), self.retargeted.columns))
        at: dict[str, np.ndarray] = {}
        for bone, joint in SUIT_SEGMENTS.items():
            c = cols.get(bone.lower(), -1)
            if c >= 0:
                at[joint] = rest.positions[c] * scale
        pos = np.zeros((len(JOINTS), 3))
        for j, name in enumerate(JOINTS):
            p = PARENTS[j]
            if name in at:
                pos[j] = at[name]
            elif name in ("Spine1", "Spine2") and "Spine" in at and "Spine3" in at:
                frac = 1.0 / 3.0 if name == "Spine1" else 2.0 / 3.0
                pos[j] = at["Spine"] + frac * (at["Spine3"] - at["Spine"])
            elif p >= 0:
                pos[j] = pos[p]
        for j, p in enumerate(PARENTS):
            if p >= 0:
                out[j] = pos[j] - pos[p]
        return out

    def encode(self, index: int, slot: int, t: float) -> list[bytes]:
        n = self.n_frames
        parts = []
        for avatar, name, offset in self.avatars:
            vals = self.values[(index + offset) % n]
            if self.fmt == "text":
                parts.append(encode_text(vals, avatar, name))
                continue
            d = encode_binary(vals, with_disp=self.displacement, avatar_index=avatar,
                              avatar_name=name, frame_index=slot)
            if self.split and len(d) > self.split:
                parts += [d[:self.split], d[self.split:]]
            else:
                parts.append(d)
        return parts

    # -- transport
    def _open(self) -> None:
        if self.fmt == "binary":
            super()._open()
            return
        family, _, _, _, addr = socket.getaddrinfo(self.host, self.port,
                                                   type=socket.SOCK_STREAM)[0]
        srv = socket.socket(family, socket.SOCK_STREAM)
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind(addr)
        srv.listen(4)
        srv.settimeout(0.05)
        self._server = srv
        self.port = srv.getsockname()[1]
        self._accepting.set()
        threading.Thread(target=self._accept, name="rtseg-axis-accept", daemon=True).start()

    def _accept(self) -> None:
        while self._accepting.is_set() and not self._stop.is_set():
            try:
                conn, _ = self._server.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._clients_lock:
                self._clients.append(conn)
            self.client_connected.set()

    def _ready(self) -> bool:
        if self.fmt == "text" and self.wait_client:
            deadline = time.monotonic() + self.wait_client
            while not self.client_connected.wait(0.05):
                if self._stop.is_set() or time.monotonic() > deadline:
                    return not self._stop.is_set()
        return True

    def _send(self, parts: list[bytes]) -> None:
        if self.fmt == "binary":
            super()._send(parts)
            return
        data = b"".join(parts)
        with self._clients_lock:
            clients = list(self._clients)
        took = 0
        for c in clients:
            try:
                c.sendall(data)
                took += 1
            except OSError:                      # the client went away
                self.disconnect(c)
        self._delivered = took > 0

    def disconnect(self, client: socket.socket | None = None) -> int:
        """Close one client (default: all) - what a restart of Axis looks like to rtseg.
        Returns how many were closed."""
        with self._clients_lock:
            gone = [c for c in self._clients if client is None or c is client]
            self._clients = [c for c in self._clients if c not in gone]
        for c in gone:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        return len(gone)

    def _unplug(self) -> None:
        """An ``unplug`` fault: the text server drops its clients (they reconnect; nothing
        is sent until the window ends); binary just goes quiet."""
        if self.fmt == "text":
            self.disconnect()

    @property
    def clients(self) -> int:
        with self._clients_lock:
            return len(self._clients)

    def _close(self) -> None:
        self._accepting.clear()
        super()._close()
        if self._server is not None:
            self._server.close()
            self._server = None
        self.disconnect()


def serve(args, take: Take, host) -> tuple[str, list[str]]:
    """``rtseg simulate axis``: send ``take`` (``host``: a
    :class:`rtseg.commands.simulate.Host`); returns (stop reason, summary lines)."""
    out, retarget_kw = host.out, host.retarget_kw
    fmt = args.axis_format
    port = host.port(BINARY_PORT if fmt == "binary" else TEXT_PORT, lowest=0, faults=True)
    suit = args.suit if args.suit != "default17" else "axis"
    sender = AxisSender(take, fmt, args.host, port, loop=args.loop, speed=args.speed,
                        suit=suit, faults=args.faults or None,
                        wait_client=host.wait_for_peer() if fmt == "text" else None,
                        **retarget_kw)
    out(f"  {sender.describe()}")
    sender.start()
    how = (f"udp {args.host}:{sender.port}" if fmt == "binary"
           else f"a tcp server on {args.host}:{sender.port}")
    out(f"Axis sender: 59-joint BVH frames ({fmt}, {sender.values.shape[1]} values, Euler "
        f"{sender.order}) to {how} at {sender.rate:g} Hz, sent at x{sender.speed:g}")
    out(f"  receive it with: rtseg live \"axis://{args.host}:{sender.port}?format={fmt}"
        f"&rate={sender.rate:g}\"")
    if fmt == "text":
        out("  sending starts when the first client connects" if sender.wait_client
            else "  sending at once (--no-wait): frames written before a client connects "
                 "are lost")
    reason, elapsed = host.drive(sender, start=False)
    return reason, host.summary(sender, elapsed, "frames", "bytes", "frame index")
