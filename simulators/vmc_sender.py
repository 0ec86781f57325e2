"""Simulated VMC performer: send a Take as VMC over OSC/UDP at its frame rate.

``VmcSender(take, host, port, rate=None, faults=None, loop=False)`` sends, from a thread,
one skeleton per frame the way VMC performers (VirtualMotionCapture, SlimeVR, mocopi
bridges) do: ``/VMC/Ext/Root/Pos``, one ``/VMC/Ext/Bone/Pos`` per bone, ``/VMC/Ext/T``,
``/VMC/Ext/OK``, packed into bundles of at most ``max_datagram`` bytes (one skeleton may
span several datagrams).

What is sent: the take is retargeted to the bones of ``suit`` (a ``config/suits.toml``
profile, Unity ``HumanBodyBones`` names, default ``default17`` - the receiver's default
too) by :func:`rtseg.simulators.retarget.retarget`: a named skeleton map (CMU ASF/AMC,
CMU BVH, Mixamo, Unity humanoid; detected or ``skeleton_map``) picks the take joint of
each bone, forward kinematics gives its global orientation (optional IMU noise / drift),
and each bone is sent **relative to its parent in the suit's hierarchy**
(q_parent⁻¹ ⊗ q_child, rtseg's right-handed Y-up frame, scalar-last), which is how the
VMC receiver (``osc://...?format=vmc&suit=...``) chains them.  Take joints that no bone
uses are listed in ``.skipped_joints``.  ``take.root_position`` is sent as the Root/Pos
position (scaled to metres when the take says how: ``meta["metres_per_unit"]`` or a known
``length_unit``).  Bone positions are each bone's rest offset from its parent bone (the
take's rest geometry, ``rtseg.core.posture.RestPose``, in metres), as a VRM avatar's local
positions are; zero when the take has no rest geometry.  The hips' position is zero (the
root's place travels in Root/Pos).

Clock: ``/VMC/Ext/T`` is the take's frame clock: slot ``k`` carries T = ``k / rate`` and
is sent ``k / (rate * speed)`` seconds after start, so ``speed`` > 1 replays faster while
T still advances in take seconds.  Frames where a bone's take joint is not valid omit
that bone.

Faults: ``faults`` is a :class:`rtseg.simulators.faults.FaultConfig`, a ``FaultInjector``
or a CLI spec (``"drop=0.05,jitter=0.002,dropout=LeftHand:1:0.5,corrupt=0.001"``).  One
injector *message* is one frame slot (index = slot, time = slot / rate): ``drop`` drops
all datagrams of the frame, ``corrupt`` flips bytes anywhere in them, ``jitter`` delays
the frame, ``dropout`` omits the bone (sensor = HumanBodyBones name, or index into
``bone_names``; a bone not sent is a ValueError listing those sent), ``unplug`` stops sending during its windows (recorded as lost).  Every frame slot is recorded in
``.sent_log`` (:class:`SentFrame`), including dropped ones, so tests can compare what
was sent with what arrived.
"""

from __future__ import annotations

import argparse
import logging
import socket
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from rtseg.drivers.osc.vmc.codec import (DEFAULT_MAX_DATAGRAM, DEFAULT_PORT, canonical_bone_name,
                                        encode_frame)
from rtseg.core.posture import RestPose
from rtseg.core.profiles import SuitProfile, suit_profile
from rtseg.simulators.retarget import ImuModel, retarget
from rtseg.core.take import Take

log = logging.getLogger("rtseg.simulators.vmc")

#: Metres per unit for ``Take.length_unit`` values the sender converts.
UNIT_SCALE = {"m": 1.0, "metre": 1.0, "metres": 1.0, "meter": 1.0, "meters": 1.0,
              "cm": 0.01, "mm": 0.001, "in": 0.0254, "inch": 0.0254, "inches": 0.0254}


def metres_per_unit(take: Take, default: float = 1.0) -> float:
    """Metres per unit of ``take``'s lengths (``meta["metres_per_unit"]`` or
    ``length_unit``; ``default`` when neither says)."""
    scale = take.meta.get("metres_per_unit")
    if not isinstance(scale, (int, float)) or not scale > 0:
        scale = UNIT_SCALE.get(str(take.length_unit).lower(), default)
    return float(scale)


def rest_offsets(take: Take, retargeted: Any) -> np.ndarray | None:
    """Each suit bone's rest offset from its parent bone in metres, (bones, 3)
    (``Retargeted.bone_offsets`` of the take's rest geometry, ``RestPose``), or None when
    the take has none: the local positions an avatar's bones have."""
    rest = RestPose.find(take)
    if rest is None:
        return None
    return retargeted.bone_offsets(rest.positions) * metres_per_unit(take)


def root_metres(take: Take, default: float = 1.0) -> np.ndarray | None:
    """``take.root_position`` in metres (``metres_per_unit``)."""
    if take.root_position is None:
        return None
    return np.asarray(take.root_position, dtype=np.float64) * metres_per_unit(take, default)


def take_clock(take: Take, rate: float | None, speed: float) -> tuple[float, float]:
    """(frames per second of the take's clock: ``rate`` or the take's, send speed factor);
    ValueError for a non-positive rate or a speed that is not a positive finite number."""
    out_rate = float(rate) if rate is not None else float(take.frame_rate)
    if not out_rate > 0:
        raise ValueError(f"rate must be positive, got {rate}")
    if not (isinstance(speed, (int, float)) and 0 < speed < float("inf")):
        raise ValueError(f"speed must be a positive number, got {speed!r}")
    return out_rate, float(speed)


class SenderThread:
    """Lifecycle of the simulated network senders: ``start()`` opens the transport
    (default: a UDP socket to ``self.host``:``self.port``) and runs ``_run`` in a daemon
    thread ``rtseg-<name>-sender``; ``stop()`` ends it and closes the transport; ``wait()``;
    a context manager.  ``_send`` sends datagrams, counting failures in ``send_errors``
    (``_send_failed`` is told of each).  Call ``_init_thread()`` in ``__init__``."""

    name = "vmc"

    def _init_thread(self) -> None:
        self.sent_log: list = []
        self.send_errors = 0
        self._stop = threading.Event()
        self.done = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None

    def _run(self) -> None:
        raise NotImplementedError

    # -- transport
    def _open(self) -> None:
        infos = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)
        family, _, _, _, self._addr = infos[0]
        self._sock = socket.socket(family, socket.SOCK_DGRAM)

    def _send(self, dgrams: list[bytes]) -> None:
        for d in dgrams:
            try:
                self._sock.sendto(d, self._addr)
            except OSError as exc:      # e.g. ICMP port unreachable from a closed port
                self.send_errors += 1
                self._send_failed(exc)

    def _send_failed(self, exc: OSError) -> None:
        """Called after each failed datagram (``send_errors`` already counts it)."""

    def _close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    # -- lifecycle
    def start(self):
        if self._thread is not None:
            raise RuntimeError(f"{type(self).__name__} already started")
        self._open()
        self._thread = threading.Thread(target=self._run, name=f"rtseg-{self.name}-sender",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop sending, join the thread, close the transport.  Safe to call twice."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self._close()

    def wait(self, timeout: float | None = None) -> bool:
        """Block until a non-looping take has been sent; True if finished."""
        return self.done.wait(timeout)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


@dataclass(slots=True)
class SentFrame:
    """One scheduled frame slot.  ``slot`` counts from 0 over loops; ``index`` is the take
    frame; ``source_time`` the T sent (s); ``send_time`` monotonic s of the send (None if
    dropped); ``omitted`` bones left out (dropout / invalid); ``corrupted`` if a fault
    damaged bytes of a datagram."""
    slot: int
    index: int
    source_time: float
    send_time: float | None
    datagrams: int
    dropped: bool = False
    omitted: tuple[str, ...] = ()
    corrupted: bool = False


class VmcSender(SenderThread):
    """Send ``take`` as VMC to ``host:port`` from a background thread (see module doc).

    ``rate``: frames per second of the take's clock (default ``take.frame_rate``);
    ``speed``: send that many times faster (T keeps the take's clock).  ``loop``: start over
    at the end (T keeps increasing).  ``suit``, ``skeleton_map``, ``joint_map`` (suit bone
    -> take joint), ``imu`` (``ImuModel`` or spec) and ``allow_missing``: retargeting, see
    :func:`rtseg.simulators.retarget.retarget`.  ``start()``/``stop()``/``wait()``, or use
    as a context manager.  ``ok``: ``/VMC/Ext/OK`` arguments (None to omit),
    ``send_time``: include ``/VMC/Ext/T``; ``send_root``: include ``/VMC/Ext/Root/Pos``.
    """

    def __init__(self, take: Take, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 rate: float | None = None, faults: Any = None, loop: bool = False, *,
                 speed: float = 1.0, suit: str | SuitProfile = "default17",
                 skeleton_map: str | None = None, joint_map: dict[str, str] | None = None,
                 imu: ImuModel | str | None = None, allow_missing: bool = False,
                 max_datagram: int = DEFAULT_MAX_DATAGRAM,
                 ok: tuple[int, ...] | None = (1, 3, 0, 1), send_time: bool = True,
                 send_root: bool = True) -> None:
        self.take = take
        self.host = host
        self.port = int(port)
        self.rate, self.speed = take_clock(take, rate, speed)
        self.loop = loop
        self.max_datagram = max_datagram
        self.ok = ok
        self.send_time = send_time
        self.send_root = send_root
        self.suit = suit if isinstance(suit, SuitProfile) else suit_profile(suit)
        imu_model = ImuModel.parse(imu) if isinstance(imu, str) or imu is None else imu
        self.retargeted = rt = retarget(take, self.suit, skeleton_map, joint_map, imu_model,
                                        allow_missing)
        sent = np.flatnonzero(rt.present)
        for k in sent:
            if canonical_bone_name(self.suit.bones[k]) is None:
                raise ValueError(f"suit {self.suit.name!r} bone {self.suit.bones[k]!r} is not a "
                                 f"HumanBodyBones name: VMC cannot carry it")
        self.bone_names = [canonical_bone_name(self.suit.bones[k]) for k in sent]
        used = {rt.columns[k] for k in sent}
        self.skipped_joints = [n for j, n in enumerate(take.joint_names) if j not in used]
        self._quats = np.ascontiguousarray(rt.local()[:, sent, :])
        self._valid = None if rt.valid[:, sent].all() else rt.valid[:, sent]
        self._root = root_metres(take) if send_root else None
        offsets = rest_offsets(take, rt)
        #: Bone local positions sent (metres; the take's rest geometry), or None: zeros.
        self.bone_positions = None if offsets is None else np.ascontiguousarray(offsets[sent])
        #: The FaultInjector in use (its ``record`` says what was damaged), or None.
        self.injector = _make_injector(faults)
        if self.injector is not None:
            from rtseg.simulators.faults import check_dropout_targets
            check_dropout_targets(self.injector.config, range(len(self.bone_names)),
                                  self.bone_names, what="bone",
                                  where=f"the bones sent for suit {self.suit.name}",
                                  id_kind="indices")
        self._init_thread()

    def _send_failed(self, exc: OSError) -> None:
        if self.send_errors == 1:
            log.warning("VMC sender: send to %s:%d failed: %s", self.host, self.port, exc)

    # -- encoding

    def encode(self, index: int, source_time: float,
               omit: set[int] | frozenset[int] = frozenset()) -> tuple[list[bytes], tuple[str, ...]]:
        """Datagrams for take frame ``index`` sent with T = ``source_time``, leaving out
        bone indices ``omit`` (and bones invalid in the take)."""
        include = np.ones(len(self.bone_names), dtype=bool)
        if self._valid is not None:
            include &= self._valid[index]
        for b in omit:
            include[b] = False
        omitted = tuple(n for n, keep in zip(self.bone_names, include) if not keep)
        dgrams = encode_frame(
            self._quats[index], self.bone_names,
            time=source_time if self.send_time else None,
            root_position=None if self._root is None else self._root[index],
            ok=self.ok, include=None if include.all() else include,
            bone_positions=self.bone_positions,
            max_datagram=self.max_datagram)
        return dgrams, omitted

    # -- thread

    def _silent_bones(self, t: float) -> frozenset[int]:
        silent = self.injector.silent_sensors(t) if self.injector else ()
        out = set()
        for sensor in silent:
            if isinstance(sensor, int):
                if 0 <= sensor < len(self.bone_names):
                    out.add(sensor)
            else:
                bone = canonical_bone_name(str(sensor))
                if bone in self.bone_names:
                    out.add(self.bone_names.index(bone))
        return frozenset(out)

    def _run(self) -> None:
        n = self._quats.shape[0]
        period = 1.0 / self.rate               # take seconds per slot (T)
        wall = period / self.speed             # wall seconds per slot
        inj = self.injector
        t0 = time.monotonic()
        slot = 0
        try:
            while not self._stop.is_set():
                if slot >= n and not self.loop:
                    break
                index = slot % n
                t_sched = slot * period
                jitter = inj.jitter() if inj else 0.0
                delay = t0 + slot * wall + jitter - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                if inj and inj.unplugged(t_sched):
                    inj.mark_lost(slot, "unplugged")
                    self.sent_log.append(SentFrame(slot, index, t_sched, None, 0, dropped=True))
                    slot += 1
                    continue
                dgrams, omitted = self.encode(index, t_sched, self._silent_bones(t_sched))
                corrupted = False
                if inj:
                    # one fault-injector message = one frame (all its datagrams)
                    lengths = [len(d) for d in dgrams]
                    joined = inj.process(slot, b"".join(dgrams))
                    if joined is None:
                        self.sent_log.append(SentFrame(slot, index, t_sched, None, 0,
                                                       dropped=True, omitted=omitted))
                        slot += 1
                        continue
                    corrupted = slot in inj.record.corrupted
                    cuts = np.cumsum([0] + lengths)
                    dgrams = [joined[a:b] for a, b in zip(cuts[:-1], cuts[1:])]
                sent_at = time.monotonic()
                self._send(dgrams)
                self.sent_log.append(SentFrame(slot, index, t_sched, sent_at, len(dgrams),
                                               omitted=omitted, corrupted=corrupted))
                slot += 1
        finally:
            self.done.set()


# --------------------------------------------------------------------------- faults

def _make_injector(faults: Any):
    """A FaultInjector from a FaultInjector, FaultConfig, CLI spec string, or None."""
    if faults is None:
        return None
    from rtseg.simulators.faults import FaultConfig, FaultInjector
    if isinstance(faults, FaultInjector):
        return faults
    if isinstance(faults, (FaultConfig, str)):
        inj = FaultInjector(faults)
        return inj if inj.config.enabled else None
    raise TypeError(f"faults must be a FaultConfig, FaultInjector or spec string, not {type(faults)!r}")


# --------------------------------------------------------------------------- command line

def take_parser(prog: str, description: str) -> argparse.ArgumentParser:
    """A sender's command line: ``--take FILE`` or ``--script`` (the synthesiser's)."""
    p = argparse.ArgumentParser(prog=prog, description=description)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--take", help="take file (any format rtseg reads)")
    src.add_argument("--script", default="idle:3,walk:6,punch:4,squat:4",
                     help="synthesiser script behaviour:seconds,... (default %(default)s)")
    return p


def send_until_done(sender: SenderThread) -> None:
    """Run ``sender`` until its take is sent (never with loop) or Ctrl-C."""
    with sender:
        try:
            while not sender.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass


def serve(args, take: Take, host) -> tuple[str, list[str]]:
    """``rtseg simulate vmc``: send ``take`` (``host``: a
    :class:`rtseg.commands.simulate.Host`); returns (stop reason, summary lines)."""
    out = host.out
    args.port = host.port(DEFAULT_PORT, faults=True)
    sender = VmcSender(take, args.host, args.port, faults=args.faults or None, loop=args.loop,
                       speed=args.speed, suit=args.suit, **host.retarget_kw)
    out(f"  {sender.retargeted.describe(take.joint_names)}")
    out(f"VMC sender: {len(sender.bone_names)} bones to udp {args.host}:{args.port} "
        f"at {sender.rate:g} Hz (T in take seconds), sent at x{sender.speed:g}")
    out(f"  receive it with: rtseg live \"osc://{args.host}:{args.port}?format=vmc"
        f"&suit={sender.suit.name}&rate={sender.rate:g}\"")
    reason, elapsed = host.drive(sender)
    log = list(sender.sent_log)
    sent = [f for f in log if not f.dropped]
    lines = [f"sent {len(sent)} frames ({sum(f.datagrams for f in sent)} datagrams) in "
             f"{elapsed:.2f} s; {len(log) - len(sent)} dropped by faults, "
             f"{sum(1 for f in sent if f.corrupted)} corrupted, "
             f"{sum(1 for f in sent if f.omitted)} with bones omitted, "
             f"{sender.send_errors} send errors"]
    if sent:
        lines.append(f"take frames {sent[0].index}..{sent[-1].index}, "
                     f"last T {sent[-1].source_time:.3f} s")
    return reason, lines


def main(argv: list[str] | None = None) -> int:
    """``python -m rtseg.simulators.vmc_sender``: send a synthetic or recorded take."""
    p = take_parser("python -m rtseg.simulators.vmc_sender", "Send a take as VMC over OSC/UDP.")
    p.add_argument("--skeleton", help="ASF skeleton for --take .amc")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=DEFAULT_PORT)
    p.add_argument("--rate", type=float, help="frames per second (default: the take's)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="send this many times faster; /VMC/Ext/T keeps the take's clock")
    p.add_argument("--loop", action="store_true", help="repeat forever")
    p.add_argument("--seed", type=int, default=0, help="synthesiser seed")
    p.add_argument("--faults", help="fault spec, e.g. drop=0.02,jitter=0.002,dropout=LeftHand:2:1")
    args = p.parse_args(argv)
    if args.take:
        from rtseg.drivers.readers import read_take
        take = read_take(args.take, skeleton=args.skeleton)
    else:
        from rtseg.simulators.synth.motion import synthesize
        take = synthesize(args.script, seed=args.seed).take
    sender = VmcSender(take, args.host, args.port, rate=args.rate, faults=args.faults,
                       loop=args.loop, speed=args.speed)
    send_until_done(sender)
    print(f"sent {sum(1 for f in sender.sent_log if not f.dropped)} frames to "
          f"{args.host}:{args.port}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
