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

Faults: ``faults`` is a :class:`rtseg.simulators.faults.FaultConfig` (or an injector built
from one) -- drop whole frames, send-time jitter, per-sensor dropouts (bones omitted),
corrupted bytes; see :mod:`rtseg.simulators.faults`.  Every frame slot is recorded in
``.sent_log`` (:class:`SentFrame`), including dropped ones, so tests can compare what
was sent with what arrived.
"""

from __future__ import annotations

import argparse
import logging
import socket
import threading
import time
from dataclasses import dataclass, field
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
                 send_root: bool = True, seed: int = 0) -> None:
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
        self._faults = _make_injector(faults, seed)
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

    def _run(self) -> None:
        n = self._quats.shape[0]
        period = 1.0 / self.rate
        t0 = time.monotonic()
        slot = 0
        try:
            while not self._stop.is_set():
                index = slot % n
                if slot >= n and not self.loop:
                    break
                t_sched = slot * period
                plan = self._faults.plan(slot, len(self.bone_names)) if self._faults else _NO_FAULT
                delay = t0 + t_sched + plan.jitter - time.monotonic()
                if delay > 0 and self._stop.wait(delay):
                    break
                if plan.drop:
                    self.sent_log.append(SentFrame(slot, index, t_sched, None, 0, dropped=True))
                    slot += 1
                    continue
                dgrams, omitted = self.encode(index, t_sched, plan.omit)
                corrupted = False
                if self._faults:
                    dgrams, corrupted = self._faults.corrupt(dgrams)
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

@dataclass(slots=True)
class FramePlan:
    """What the fault injector does to one frame slot."""
    drop: bool = False
    jitter: float = 0.0
    omit: frozenset[int] = field(default_factory=frozenset)


_NO_FAULT = FramePlan()


class _FaultAdapter:
    """Applies a FaultConfig / FaultInjector to VMC frames (bone dropouts instead of sensor
    dropouts, byte corruption on datagrams)."""

    def __init__(self, faults: Any, seed: int) -> None:
        self.faults = faults
        self.rng = np.random.default_rng(getattr(faults, "seed", seed))
        cfg = getattr(faults, "config", faults)
        self.drop = float(_first(cfg, ("drop_rate", "drop_frames", "drop", "p_drop"), 0.0))
        self.jitter = float(_first(cfg, ("jitter_s", "jitter", "jitter_sd"), 0.0))
        self.dropout = float(_first(cfg, ("dropout_rate", "sensor_dropout", "dropout", "p_dropout"), 0.0))
        self.dropout_frames = int(_first(cfg, ("dropout_frames", "dropout_len", "dropout_length"), 30))
        self.corrupt_rate = float(_first(cfg, ("corrupt_rate", "corrupt_bytes", "corrupt", "p_corrupt"), 0.0))
        self._out: dict[int, int] = {}   # bone -> last slot of its dropout

    def __bool__(self) -> bool:
        return bool(self.drop or self.jitter or self.dropout or self.corrupt_rate)

    def plan(self, slot: int, n_bones: int) -> FramePlan:
        rng = self.rng
        if self.dropout > 0:
            for b in np.nonzero(rng.random(n_bones) < self.dropout)[0]:
                self._out.setdefault(int(b), slot + self.dropout_frames - 1)
        omit = frozenset(b for b, end in self._out.items() if end >= slot)
        self._out = {b: end for b, end in self._out.items() if end > slot}
        jitter = abs(float(rng.normal(0.0, self.jitter))) if self.jitter > 0 else 0.0
        return FramePlan(drop=bool(self.drop > 0 and rng.random() < self.drop),
                         jitter=jitter, omit=omit)

    def corrupt(self, dgrams: list[bytes]) -> tuple[list[bytes], bool]:
        if not self.corrupt_rate:
            return dgrams, False
        out, hit = [], False
        for d in dgrams:
            if self.rng.random() < self.corrupt_rate:
                b = bytearray(d)
                for _ in range(int(self.rng.integers(1, 4))):
                    b[int(self.rng.integers(len(b)))] = int(self.rng.integers(256))
                d, hit = bytes(b), True
            out.append(d)
        return out, hit


def _first(obj: Any, names: tuple[str, ...], default: float) -> float:
    for n in names:
        v = obj.get(n) if isinstance(obj, dict) else getattr(obj, n, None)
        if v is not None and not callable(v):
            return v
    return default


def _make_injector(faults: Any, seed: int) -> _FaultAdapter | None:
    if faults is None:
        return None
    adapter = _FaultAdapter(faults, seed)
    return adapter if adapter else None


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
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    if args.take:
        from rtseg.take import load_take
        take = load_take(args.take, skeleton=args.skeleton)
    else:
        from rtseg.simulators.synth import synthesize
        take = synthesize(args.script, seed=args.seed).take
    with VmcSender(take, args.host, args.port, rate=args.rate, loop=args.loop) as sender:
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
