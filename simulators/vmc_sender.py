"""Simulated VMC performer: send a Take as VMC over OSC/UDP at its frame rate.

``VmcSender(take, host, port, rate=None, faults=None, loop=False)`` sends, from a thread,
one skeleton per frame the way VMC performers (VirtualMotionCapture, SlimeVR, mocopi
bridges) do: ``/VMC/Ext/Root/Pos``, one ``/VMC/Ext/Bone/Pos`` per bone, ``/VMC/Ext/T``,
``/VMC/Ext/OK``, packed into bundles of at most ``max_datagram`` bytes (one skeleton may
span several datagrams).

Take conventions: rotations ``take.quats`` in rtseg's right-handed Y-up frame,
scalar-last; ``space="local"`` is sent as is, ``"global"`` is first converted to
parent-relative rotations.  Joint names are matched case-insensitively against Unity
``HumanBodyBones`` and sent in Unity spelling; joints with other names are not sent
(listed in ``.skipped_joints``).  ``take.root_position`` is sent as the Root/Pos position
(scaled to metres when ``take.length_unit`` is a known unit); bone positions are zero.
``/VMC/Ext/T`` is the sender clock: slot ``k`` of the schedule is sent at ``k / rate``
seconds after start and carries T = ``k / rate``.  Frames where ``take.valid`` is False
omit that bone.

Faults: ``faults`` is a :class:`rtseg.simulators.faults.FaultConfig`, a ``FaultInjector``
or a CLI spec (``"drop=0.05,jitter=0.002,dropout=LeftHand:1:0.5,corrupt=0.001"``).  One
injector *message* is one frame slot (index = slot, time = slot / rate): ``drop`` drops
all datagrams of the frame, ``corrupt`` flips bytes anywhere in them, ``jitter`` delays
the frame, ``dropout`` omits the bone (sensor = HumanBodyBones name, or index into
``bone_names``), ``unplug`` stops sending during its windows (recorded as lost).  Every frame slot is recorded in
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

from rtseg import quat
from rtseg.drivers.codec_vmc import DEFAULT_MAX_DATAGRAM, canonical_bone_name, encode_frame
from rtseg.take import Take

log = logging.getLogger("rtseg.simulators.vmc")

#: Metres per unit for ``Take.length_unit`` values the sender converts.
UNIT_SCALE = {"m": 1.0, "metre": 1.0, "metres": 1.0, "meter": 1.0, "meters": 1.0,
              "cm": 0.01, "mm": 0.001, "in": 0.0254, "inch": 0.0254, "inches": 0.0254}


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


class VmcSender:
    """Send ``take`` as VMC to ``host:port`` from a background thread (see module doc).

    ``rate``: frames per second (default ``take.frame_rate``).  ``loop``: start over at the
    end (T keeps increasing).  ``start()``/``stop()``/``wait()``, or use as a context
    manager.  ``ok``: ``/VMC/Ext/OK`` arguments (None to omit), ``send_time``: include
    ``/VMC/Ext/T``; ``send_root``: include ``/VMC/Ext/Root/Pos``.
    """

    def __init__(self, take: Take, host: str = "127.0.0.1", port: int = 39539,
                 rate: float | None = None, faults: Any = None, loop: bool = False, *,
                 max_datagram: int = DEFAULT_MAX_DATAGRAM,
                 ok: tuple[int, ...] | None = (1, 3, 0, 1), send_time: bool = True,
                 send_root: bool = True) -> None:
        self.take = take
        self.host = host
        self.port = int(port)
        self.rate = float(rate) if rate is not None else float(take.frame_rate)
        if not self.rate > 0:
            raise ValueError(f"rate must be positive, got {rate}")
        self.loop = loop
        self.max_datagram = max_datagram
        self.ok = ok
        self.send_time = send_time
        self.send_root = send_root
        names: list[str] = []
        cols: list[int] = []
        self.skipped_joints: list[str] = []
        for j, name in enumerate(take.joint_names):
            bone = canonical_bone_name(name)
            if bone is None:
                self.skipped_joints.append(name)
            elif bone in names:
                raise ValueError(f"take joints {take.joint_names[cols[names.index(bone)]]!r} and "
                                 f"{name!r} both map to HumanBodyBones {bone!r}")
            else:
                names.append(bone)
                cols.append(j)
        if not names:
            raise ValueError(f"no joint of take {take.source or '<memory>'} is a HumanBodyBones "
                             f"name: {', '.join(take.joint_names)}")
        if self.skipped_joints:
            log.info("VMC sender: joints without a HumanBodyBones name not sent: %s",
                     ", ".join(self.skipped_joints))
        self.bone_names = names
        q = take.quats if take.space == "local" else quat.local_from_global(take.quats, take.parents)
        self._quats = np.ascontiguousarray(q[:, cols, :])
        self._valid = None if take.valid is None else take.valid[:, cols]
        self._root = None
        if send_root and take.root_position is not None:
            scale = UNIT_SCALE.get(take.length_unit.lower(), 1.0)
            self._root = take.root_position * scale
        #: The FaultInjector in use (its ``record`` says what was damaged), or None.
        self.injector = _make_injector(faults)
        self.sent_log: list[SentFrame] = []
        self.send_errors = 0
        self._stop = threading.Event()
        self.done = threading.Event()
        self._thread: threading.Thread | None = None
        self._sock: socket.socket | None = None

    # -- lifecycle

    def start(self) -> "VmcSender":
        if self._thread is not None:
            raise RuntimeError("VmcSender already started")
        infos = socket.getaddrinfo(self.host, self.port, type=socket.SOCK_DGRAM)
        family, _, _, _, self._addr = infos[0]
        self._sock = socket.socket(family, socket.SOCK_DGRAM)
        self._thread = threading.Thread(target=self._run, name="rtseg-vmc-sender", daemon=True)
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

    def __enter__(self) -> "VmcSender":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

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
        period = 1.0 / self.rate
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
                delay = t0 + t_sched + jitter - time.monotonic()
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
                for d in dgrams:
                    try:
                        self._sock.sendto(d, self._addr)
                    except OSError as exc:  # e.g. ICMP port unreachable from a closed port
                        self.send_errors += 1
                        if self.send_errors == 1:
                            log.warning("VMC sender: send to %s:%d failed: %s",
                                        self.host, self.port, exc)
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

def main(argv: list[str] | None = None) -> int:
    """``python -m rtseg.simulators.vmc_sender``: send a synthetic or recorded take."""
    p = argparse.ArgumentParser(prog="python -m rtseg.simulators.vmc_sender",
                                description="Send a take as VMC over OSC/UDP.")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--take", help="take file (any format rtseg reads)")
    src.add_argument("--script", default="idle:3,walk:6,punch:4,squat:4",
                     help="synthesiser script behaviour:seconds,... (default %(default)s)")
    p.add_argument("--skeleton", help="ASF skeleton for --take .amc")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=39539)
    p.add_argument("--rate", type=float, help="frames per second (default: the take's)")
    p.add_argument("--loop", action="store_true", help="repeat forever")
    p.add_argument("--seed", type=int, default=0, help="synthesiser seed")
    p.add_argument("--faults", help="fault spec, e.g. drop=0.02,jitter=0.002,dropout=LeftHand:2:1")
    args = p.parse_args(argv)
    if args.take:
        from rtseg.take import load_take
        take = load_take(args.take, skeleton=args.skeleton)
    else:
        from rtseg.simulators.synth import synthesize
        take = synthesize(args.script, seed=args.seed).take
    with VmcSender(take, args.host, args.port, rate=args.rate, faults=args.faults,
                   loop=args.loop) as sender:
        try:
            while not sender.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass
    print(f"sent {sum(1 for f in sender.sent_log if not f.dropped)} frames to "
          f"{args.host}:{args.port}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
