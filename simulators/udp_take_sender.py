"""Shared machinery of the vendor-suit simulators (MVN, mocopi): retarget a take onto a
suit whose every segment is sent each frame, and send encoded frames over UDP on the
take's clock.

Retargeting (:func:`retarget_filled`): :func:`rtseg.simulators.retarget.retarget` gives
each suit bone the global orientation of its take joint (forward kinematics, optional IMU
errors).  A vendor suit has segments most takes lack (MVN's L3, shoulders and toes on the
synthesiser's 17 joints, mocopi's 7 torso bones): such a bone is **filled** with its
parent's global orientation (a zero rotation relative to the parent, valid when the
parent is), so the stream stays a complete vendor skeleton.  The bones the pose features
use (the ``unity`` skeleton profile's joints on this suit) must come from the take: a take
without one is a ``RetargetError`` naming it, unless ``allow_missing`` (then they are
filled too).

Clock (:class:`UdpTakeSender`): slot ``k`` carries take time ``k / rate`` and is sent
``k / (rate * speed)`` s after start, so ``speed`` > 1 replays faster while the stream's
own clock (sample counter, time code, ``uttm``) keeps the take's.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from dataclasses import dataclass

import numpy as np

from rtseg import quat as Q
from rtseg.profiles import SuitProfile, resolve_joints, suit_profile
from rtseg.simulators.retarget import ImuModel, RetargetError, Retargeted, retarget
from rtseg.take import Take

log = logging.getLogger("rtseg.simulators.udp")

#: metres per unit for ``Take.length_unit`` values the senders convert
UNIT_SCALE = {"m": 1.0, "metre": 1.0, "metres": 1.0, "meter": 1.0, "meters": 1.0,
              "cm": 0.01, "mm": 0.001, "in": 0.0254, "inch": 0.0254, "inches": 0.0254}


def feature_bones(suit: SuitProfile, profile: str = "unity") -> list[str]:
    """Suit bones that ``profile``'s joints resolve to (empty if it does not resolve)."""
    try:
        return [suit.bones[i] for i in resolve_joints(profile, list(suit.bones))]
    except KeyError:
        return []


def retarget_filled(take: Take, suit: SuitProfile, skeleton_map: str | None = None,
                    joint_map: dict[str, str] | None = None, imu: ImuModel | None = None,
                    allow_missing: bool = False) -> tuple[Retargeted, list[str]]:
    """(retargeted take with every suit bone present, names of the filled bones); see the
    module docstring."""
    rt = retarget(take, suit, skeleton_map, joint_map, imu, allow_missing=True)
    missing = [b for b, p in zip(suit.bones, rt.present) if not p]
    needed = [b for b in feature_bones(suit) if b in missing]
    if needed and not allow_missing:
        raise RetargetError(
            f"take {take.source or '<memory>'} (skeleton map {rt.family!r}) has no joint for "
            f"suit {suit.name!r}'s feature bone(s) {', '.join(needed)}; joints in the take: "
            f"{', '.join(take.joint_names)}. Map them (suit bone -> take joint) or allow "
            f"missing sensors")
    quats, valid = rt.quats.copy(), rt.valid.copy()
    for k, p in enumerate(suit.parents):           # parents come before children
        if rt.present[k]:
            continue
        if p >= 0:
            quats[:, k] = quats[:, p]
            valid[:, k] = valid[:, p]
        else:
            quats[:, k] = Q.IDENTITY
            valid[:, k] = True
    filled = Retargeted(suit, quats, valid, np.ones(len(suit.bones), dtype=bool), rt.family,
                        rt.columns, rt.frame_rate, dict(rt.meta))
    return filled, missing


def root_metres(take: Take) -> np.ndarray | None:
    """The take's root trajectory in metres (``meta["metres_per_unit"]`` or a known
    ``length_unit``; unknown units are taken as metres), or None."""
    if take.root_position is None:
        return None
    scale = take.meta.get("metres_per_unit")
    if not isinstance(scale, (int, float)) or not scale > 0:
        scale = UNIT_SCALE.get(take.length_unit.lower(), 1.0)
    return take.root_position * float(scale)


@dataclass(slots=True)
class SentFrame:
    """One frame slot sent: ``slot`` from 0 over loops, ``index`` take frame,
    ``source_time`` take seconds, ``send_time`` monotonic s, ``datagrams`` count."""
    slot: int
    index: int
    source_time: float
    send_time: float
    datagrams: int


class UdpTakeSender:
    """Send a retargeted take over UDP from a thread.  Subclasses implement
    :meth:`encode` (``slot``, take frame ``index``, take time s -> datagrams) and may
    override :meth:`preamble` (datagrams sent once before the first frame)."""

    name = "UDP"

    def __init__(self, take: Take, host: str, port: int, rate: float | None, loop: bool,
                 speed: float, suit: str | SuitProfile, skeleton_map: str | None,
                 joint_map: dict[str, str] | None, imu: ImuModel | str | None,
                 allow_missing: bool) -> None:
        self.take = take
        self.host = host
        self.port = int(port)
        self.rate = float(rate) if rate is not None else float(take.frame_rate)
        if not self.rate > 0:
            raise ValueError(f"rate must be positive, got {rate}")
        if not (isinstance(speed, (int, float)) and 0 < speed < float("inf")):
            raise ValueError(f"speed must be a positive number, got {speed!r}")
        self.speed = float(speed)
        self.loop = loop
        self.suit = suit if isinstance(suit, SuitProfile) else suit_profile(suit)
        imu_model = ImuModel.parse(imu) if isinstance(imu, str) or imu is None else imu
        self.retargeted, self.filled = retarget_filled(take, self.suit, skeleton_map,
                                                       joint_map, imu_model, allow_missing)
        self.root = root_metres(take)
        self.sent_log: list[SentFrame] = []
        self.send_errors = 0
        self._stop = threading.Event()
        self.done = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None

    def describe(self) -> str:
        rt, names = self.retargeted, self.take.joint_names
        pairs = [f"{b}<-{names[c]}" for b, c in zip(self.suit.bones, rt.columns) if c >= 0]
        text = f"skeleton map {rt.family}: " + ", ".join(pairs)
        return text + (f"; filled from their parents: {', '.join(self.filled)}"
                       if self.filled else "")

    # -- to implement

    def encode(self, slot: int, index: int, source_time: float) -> list[bytes]:
        raise NotImplementedError

    def preamble(self) -> list[bytes]:
        return []

    # -- lifecycle

    def start(self) -> "UdpTakeSender":
        if self._thread is not None:
            raise RuntimeError(f"{type(self).__name__} already started")
        family, _, _, _, self._addr = socket.getaddrinfo(self.host, self.port,
                                                         type=socket.SOCK_DGRAM)[0]
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._thread = threading.Thread(target=self._run, name=f"rtseg-{self.name}-sender",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop sending and join the thread.  Safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a non-looping take has been sent; True if finished."""
        return self.done.wait(timeout)

    def __enter__(self) -> "UdpTakeSender":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _send(self, dgrams: list[bytes]) -> None:
        for d in dgrams:
            try:
                self._sock.sendto(d, self._addr)
            except OSError as exc:      # e.g. ICMP port unreachable: nobody listening yet
                self.send_errors += 1
                if self.send_errors == 1:
                    log.warning("%s sender: send to %s:%d failed: %s", self.name, self.host,
                                self.port, exc)

    def _run(self) -> None:
        n = self.retargeted.quats.shape[0]
        period = 1.0 / self.rate
        wall = period / self.speed
        t0 = time.monotonic()
        slot = 0
        try:
            self._send(self.preamble())
            while not self._stop.is_set():
                if slot >= n and not self.loop:
                    break
                index = slot % n
                delay = t0 + slot * wall - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                dgrams = self.encode(slot, index, slot * period)
                sent_at = time.monotonic()
                self._send(dgrams)
                self.sent_log.append(SentFrame(slot, index, slot * period, sent_at, len(dgrams)))
                slot += 1
        finally:
            self.done.set()


__all__ = ["UdpTakeSender", "SentFrame", "retarget_filled", "feature_bones", "root_metres"]
