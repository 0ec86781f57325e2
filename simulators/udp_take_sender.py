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

Sending (:class:`UdpTakeSender`): a :class:`rtseg.simulators.stream_sender.StreamSender`
(clock, thread, UDP transport, ``sent_log``) with this retargeting, a ``preamble`` sent
once before the first frame, and a warning logged at the first failed send.  Slot ``k``
carries take time ``k / rate`` and is sent ``k / (rate * speed)`` s after start, so
``speed`` > 1 replays faster while the stream's own clock (sample counter, time code,
``uttm``) keeps the take's.
"""

from __future__ import annotations

import logging

import numpy as np

from rtseg.core import quat as Q
from rtseg.core.profiles import SuitProfile, resolve_joints
from rtseg.simulators.retarget import ImuModel, RetargetError, Retargeted, retarget
from rtseg.simulators.stream_sender import Sent, StreamSender, root_metres
from rtseg.core.take import Take

log = logging.getLogger("rtseg.simulators.udp")

#: one frame slot of ``sent_log`` (``datagrams`` = ``parts``)
SentFrame = Sent


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


class UdpTakeSender(StreamSender):
    """Send a retargeted take over UDP from a thread.  Subclasses implement
    :meth:`encode` (take frame ``index``, ``slot``, take time s -> datagrams) and may
    override :meth:`preamble` (datagrams sent once before the first frame).  Options as
    :class:`StreamSender`; ``filled``: the suit bones filled from their parents."""

    name = "UDP"

    def __init__(self, take: Take, host: str, port: int, suit: str | SuitProfile,
                 **kw) -> None:
        self.host = host
        self.port = int(port)
        super().__init__(take, suit, **kw)

    def _retarget(self, skeleton_map: str | None, joint_map: dict[str, str] | None,
                  imu: ImuModel | None, allow_missing: bool) -> Retargeted:
        rt, self.filled = retarget_filled(self.take, self.suit, skeleton_map, joint_map, imu,
                                          allow_missing)
        return rt

    def _root_metres(self) -> np.ndarray | None:
        return root_metres(self.take)

    def describe(self) -> str:
        rt, names = self.retargeted, self.take.joint_names
        pairs = [f"{b}<-{names[c]}" for b, c in zip(self.suit.bones, rt.columns) if c >= 0]
        text = f"skeleton map {rt.family}: " + ", ".join(pairs)
        return text + (f"; filled from their parents: {', '.join(self.filled)}"
                       if self.filled else "")

    def preamble(self) -> list[bytes]:
        return []

    def _ready(self) -> bool:
        self._send(self.preamble())
        return True

    def _send_failed(self, exc: OSError) -> None:
        if self.send_errors == 1:
            log.warning("%s sender: send to %s:%d failed: %s", self.name, self.host,
                        self.port, exc)


def serve_options(args, host) -> dict:
    """The keyword arguments ``rtseg simulate mvn|mocopi`` gives a :class:`UdpTakeSender`
    (``host``: a :class:`rtseg.commands.simulate.Host`): speed, loop, faults and
    retargeting, and the suit when ``--suit`` names another than the default (its ids must
    fit the format)."""
    kw = dict(speed=args.speed, loop=args.loop, faults=args.faults or None, **host.retarget_kw)
    if args.suit != "default17":
        kw["suit"] = args.suit
    return kw


def serve_sender(args, host, sender: UdpTakeSender, port: int, url: str) -> tuple[str, list[str]]:
    """Announce ``sender`` (what it sends where, the ``rtseg live`` URL that receives it),
    run it until the take ends, ``--duration`` passes or Ctrl-C; (stop reason, summary
    lines)."""
    out = host.out
    out(f"  {sender.describe()}")
    how = getattr(sender, "transport", "udp")
    out(f"{sender.name} sender: {len(sender.suit.bones)}-segment suit {sender.suit.name} to "
        f"{how} {args.host}:{port} at {sender.rate:g} Hz (stream clock in take time), sent at "
        f"x{sender.speed:g}" + (f"; faults {args.faults}" if args.faults else ""))
    out(f"  receive it with: rtseg live \"{url}\"")
    if how == "tcp":
        out(f"  {'not waiting' if args.no_wait else 'waiting'} for the receiver to listen "
            f"on tcp {args.host}:{port}" + (" (--no-wait)" if args.no_wait else ""))
    reason, elapsed = host.drive(sender)
    return reason, host.summary(sender, elapsed)


def cli_take(args) -> Take:
    """The take of a sender's command line: ``--take`` read, or ``--script`` synthesised
    with ``--seed``."""
    if args.take:
        from rtseg.drivers.readers import read_take
        return read_take(args.take)
    from rtseg.simulators.synth.motion import synthesize
    return synthesize(args.script, seed=args.seed).take


def cli_arguments(p, port: int) -> None:
    """``--host``, ``--port`` (default ``port``) for :func:`vmc_sender.take_parser`."""
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=port)


def cli_timing(p) -> None:
    """``--speed``, ``--loop``, ``--seed``."""
    p.add_argument("--speed", type=float, default=1.0)
    p.add_argument("--loop", action="store_true")
    p.add_argument("--seed", type=int, default=0)


__all__ = ["UdpTakeSender", "SentFrame", "retarget_filled", "feature_bones", "root_metres",
           "serve_options", "serve_sender", "cli_take", "cli_arguments", "cli_timing"]
