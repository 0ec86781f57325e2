"""Shared machinery of the vendor-suit simulators (Rokoko, Axis; MVN and mocopi through
:mod:`rtseg.simulators.udp_take_sender`): a take retargeted onto a suit profile, sent frame
by frame on the take's clock from a background thread.

:class:`StreamSender` retargets the take with :func:`rtseg.simulators.retarget.retarget`
(named skeleton map detected or given, forward kinematics, optional IMU errors) onto a
``config/suits.toml`` profile.  Bones listed as *optional* (e.g. shoulders and toes, which
rtseg's synthetic takes and many recorded skeletons lack) are sent rigid with their parent
when the take has no joint for them; any other unmapped bone is a ``RetargetError`` naming
it, unless ``allow_missing`` (those bones are then sent as not valid).

Clock: slot ``k`` carries take time ``k / rate`` and is sent ``k / (rate * speed)`` s
after start, so ``speed`` > 1 replays faster while the stream's own clock (timestamps,
frame indices) stays the take's.  Subclasses implement ``encode(index, slot, t)`` (the
datagrams or stream chunks of one frame) and may replace the transport (default: UDP
datagrams to ``host:port``; ``_open``, ``_send``, ``_close``, optionally ``_ready``) or the
retargeting policy (``_retarget``).  Every slot is recorded in ``sent_log``.

Faults (``faults``: a :class:`rtseg.simulators.faults.FaultConfig`, ``FaultInjector`` or CLI
spec, as for the serial and VMC simulators): one injector *message* is one frame slot (all
its datagrams / stream bytes).  ``drop`` leaves the frame out, ``corrupt`` flips bytes
anywhere in it (datagram boundaries kept), ``jitter`` sends it up to that many seconds
late (more than a frame period bunches frames into bursts), ``unplug=EVERY:FOR`` stops
sending during the window - and a TCP transport closes its connection at the start of the
window (``_unplug``) and reconnects after it.  ``dropout`` (one sensor silent) is refused:
these formats send whole skeletons.  Each slot's fate is in ``Sent.fault`` (``""``,
``"dropped"``, ``"corrupted"``, ``"unplugged"``) and the injector's ``record``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from rtseg.core import quat as Q
from rtseg.core.profiles import SuitProfile, suit_profile
from rtseg.simulators.retarget import ImuModel, RetargetError, Retargeted, resolve, retarget
from rtseg.simulators.vmc_sender import SenderThread, _make_injector, root_metres, take_clock
from rtseg.core.take import Take

log = logging.getLogger("rtseg.simulators")

__all__ = ["StreamSender", "Sent", "retarget_with_optional", "root_metres", "FAMILY_UNITS"]


@dataclass(slots=True)
class Sent:
    """One frame slot: ``slot`` (from 0 over loops), ``index`` take frame, ``source_time``
    take seconds, ``send_time`` monotonic s (None: not sent), ``parts`` datagrams / chunks
    sent, ``nbytes``, ``fault`` what a fault did to it ("" none, "dropped", "corrupted",
    "unplugged"); ``delivered``: over a TCP transport, whether a connected peer took the
    frame (False: written while nobody was connected, so lost); None over UDP (unknown)."""
    slot: int
    index: int
    source_time: float
    send_time: float | None
    parts: int
    nbytes: int
    fault: str = ""
    delivered: bool | None = None

    @property
    def datagrams(self) -> int:
        """``parts`` (the name the UDP senders' logs use)."""
        return self.parts


def retarget_with_optional(take: Take, suit: SuitProfile, optional: set[str],
                           skeleton_map: str | None = None,
                           joint_map: dict[str, str] | None = None,
                           imu: ImuModel | None = None,
                           allow_missing: bool = False) -> Retargeted:
    """:func:`retarget`, except that ``optional`` bones the take lacks get their parent's
    orientation and validity (rigid with it).  Other missing bones: RetargetError (or, with
    ``allow_missing``, not present and never valid)."""
    res = resolve(take, suit, skeleton_map, joint_map, allow_missing=True)
    required = [b for b in res.missing if b not in optional]
    if required and not allow_missing:
        raise RetargetError(
            f"take {take.source or '<memory>'} (skeleton map {res.family!r}) has no joint for "
            f"suit {suit.name!r} bone(s) {', '.join(required)}; joints in the take: "
            f"{', '.join(take.joint_names)}. Map them (suit bone -> take joint) or allow "
            f"missing bones")
    rt = retarget(take, suit, res.family, joint_map, imu, allow_missing=True)
    for k, bone in enumerate(suit.bones):
        p = suit.parents[k]
        if not rt.present[k] and bone in optional and p >= 0:
            rt.quats[:, k] = rt.quats[:, p]
            rt.valid[:, k] = rt.valid[:, p]
            rt.present[k] = rt.present[p]
    return rt


#: metres per unit of a skeleton family whose files do not say (Axis Neuron BVH: cm)
FAMILY_UNITS = {"axis": 0.01}


class StreamSender(SenderThread):
    """Base of the suit simulators (see module docstring; lifecycle and UDP transport:
    :class:`rtseg.simulators.vmc_sender.SenderThread`).  After construction:
    ``retargeted``, ``quats`` (frames, bones, 4) global orientations in suit order,
    ``valid`` (frames, bones), ``root`` (frames, 3) metres or None, ``rate``, ``speed``."""

    optional: frozenset[str] = frozenset()
    name = "stream"

    def __init__(self, take: Take, suit: str | SuitProfile, *, rate: float | None = None,
                 speed: float = 1.0, loop: bool = False, skeleton_map: str | None = None,
                 joint_map: dict[str, str] | None = None, imu: ImuModel | str | None = None,
                 allow_missing: bool = False, faults=None) -> None:
        #: the FaultInjector in use (its ``record`` says what was damaged), or None
        self.injector = _make_injector(faults)
        if self.injector is not None and self.injector.config.dropouts:
            raise ValueError(f"dropout faults are not supported by the {self.name} simulator "
                             f"(it sends whole skeletons); use drop, corrupt, jitter, unplug")
        self.take = take
        self.rate, self.speed = take_clock(take, rate, speed)
        self.loop = loop
        self.suit = suit if isinstance(suit, SuitProfile) else suit_profile(suit)
        imu_model = ImuModel.parse(imu) if isinstance(imu, str) or imu is None else imu
        self.retargeted = rt = self._retarget(skeleton_map, joint_map, imu_model,
                                              allow_missing)
        self.quats = Q.make_continuous(rt.quats, axis=0)
        self.valid = rt.valid & rt.present[None, :]
        self.root = self._root_metres()
        self.n_frames = take.n_frames
        self._init_thread()
        self.sent_log: list[Sent] = []
        #: monotonic s when the transport opened and when the clock started (after
        #: ``_ready``, e.g. waiting for a TCP peer); None until then
        self.opened_at: float | None = None
        self.clock_started: float | None = None
        #: set by a TCP ``_send``: did a connected peer take the frame (None: UDP)
        self._delivered: bool | None = None

    def _retarget(self, skeleton_map: str | None, joint_map: dict[str, str] | None,
                  imu: ImuModel | None, allow_missing: bool) -> Retargeted:
        """The take on ``self.suit``: :func:`retarget_with_optional` with ``optional``."""
        return retarget_with_optional(self.take, self.suit, set(self.optional), skeleton_map,
                                      joint_map, imu, allow_missing)

    def _root_metres(self) -> np.ndarray | None:
        """The root trajectory sent, metres (a family's own unit when the take says none)."""
        return root_metres(self.take, FAMILY_UNITS.get(self.retargeted.family, 1.0))

    def describe(self) -> str:
        """Which take joint drives each suit bone, which bones go rigid with their parent,
        and which are not sent."""
        rt, names = self.retargeted, self.take.joint_names
        pairs = [f"{b}<-{names[c]}" for b, c in zip(self.suit.bones, rt.columns) if c >= 0]
        rigid = [b for b, c, p in zip(self.suit.bones, rt.columns, rt.present) if c < 0 and p]
        miss = [b for b, p in zip(self.suit.bones, rt.present) if not p]
        text = f"skeleton map {rt.family}: " + ", ".join(pairs)
        if rigid:
            text += f"; rigid with their parent: {', '.join(rigid)}"
        return text + (f"; not sent: {', '.join(miss)}" if miss else "")

    # -- to implement
    def encode(self, index: int, slot: int, t: float) -> list[bytes]:
        raise NotImplementedError

    def _ready(self) -> bool:
        """Called once before the first frame; False ends the run (stopped)."""
        return True

    @property
    def waited_s(self) -> float:
        """Seconds between opening the transport and starting the clock (``_ready``:
        waiting for a TCP peer), 0 before that."""
        if self.opened_at is None or self.clock_started is None:
            return 0.0
        return self.clock_started - self.opened_at

    @property
    def sending_s(self) -> float:
        """Seconds from the clock's start to the last frame sent (0 if none was)."""
        sent = [s.send_time for s in self.sent_log if s.send_time is not None]
        if self.clock_started is None or not sent:
            return 0.0
        return sent[-1] - self.clock_started

    def _unplug(self) -> None:
        """Start of an ``unplug`` fault window (default: nothing - UDP just goes quiet)."""

    def _replug(self) -> None:
        """End of an ``unplug`` fault window."""

    def _run(self) -> None:
        n = self.n_frames
        period = 1.0 / self.rate
        wall = period / self.speed
        inj = self.injector
        unplugged_at: float | None = None
        try:
            self.opened_at = time.monotonic()
            if not self._ready():
                return
            self.clock_started = t0 = time.monotonic()
            slot = 0
            while not self._stop.is_set():
                if slot >= n and not self.loop:
                    break
                jitter = inj.jitter() if inj else 0.0
                delay = t0 + slot * wall + jitter - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                index = slot % n
                t = slot * period
                if inj and inj.unplugged(t):
                    if unplugged_at is None:
                        unplugged_at = t
                        self._unplug()
                    inj.mark_lost(slot, "unplugged")
                    self.sent_log.append(Sent(slot, index, t, None, 0, 0, "unplugged"))
                    slot += 1
                    continue
                if unplugged_at is not None:
                    inj.note_unplug(unplugged_at, t)
                    unplugged_at = None
                    self._replug()
                parts = self.encode(index, slot, t)
                fault = ""
                if inj:
                    parts, fault = self._inject(inj, slot, parts)
                    if fault == "dropped":
                        self.sent_log.append(Sent(slot, index, t, None, 0, 0, fault))
                        slot += 1
                        continue
                sent_at = time.monotonic()
                self._delivered = None
                self._send(parts)
                self.sent_log.append(Sent(slot, index, t, sent_at, len(parts),
                                          sum(len(p) for p in parts), fault,
                                          self._delivered))
                slot += 1
        finally:
            self.done.set()

    @staticmethod
    def _inject(inj, slot: int, parts: list[bytes]) -> tuple[list[bytes], str]:
        """Drop / corrupt faults on one frame's parts (one injector message); the parts
        keep their lengths."""
        joined = inj.process(slot, b"".join(parts))
        if joined is None:
            return [], "dropped"
        if slot not in inj.record.corrupted:
            return parts, ""
        out, at = [], 0
        for p in parts:
            out.append(joined[at:at + len(p)])
            at += len(p)
        return out, "corrupted"
