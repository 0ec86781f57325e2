"""``rtseg simulate serial|vmc``: a simulated suit, so everything runs without hardware.

    rtseg simulate serial [--synth SCRIPT | --take FILE [--skeleton ASF]] [--link PATH]
                          [--format rtseg|text] [--faults SPEC] [--loop] [--duration S]
                          [--speed X] [--start S] [--end S] [--imu SPEC] [--map NAME]
    rtseg simulate vmc    [--synth SCRIPT | --take FILE] [--host H] [--port P] ...
    rtseg simulate mvn    [--synth SCRIPT | --take FILE] [--port 9763] [--character N]
                          [--transport udp|tcp] ...
    rtseg simulate mocopi [--synth SCRIPT | --take FILE] [--port 12351] ...
    rtseg simulate rokoko [--synth SCRIPT | --take FILE] [--port 14043] [--actor A,B] [--lz4]
    rtseg simulate axis   [--synth SCRIPT | --take FILE] [--axis-format binary|text] [--port P]

``serial`` serves the take on a pseudo-terminal (``rtseg.simulators.serial_device.SerialSuit``)
and prints its device path - read it with ``rtseg live serial://PATH``.
``vmc`` sends it as VMC over OSC/UDP (``rtseg.simulators.vmc_sender.VmcSender``) to
``--host``:``--port`` (default 127.0.0.1:39539, the VMC receiver port) - read it with
``rtseg live "osc://127.0.0.1:39539?format=vmc"``.
``mvn`` sends Xsens MVN network streaming (``rtseg.simulators.mvn_sender``, suit
``xsens-mvn``, default port 9763) - read it with ``rtseg live mvn://127.0.0.1:9763``
(``--transport tcp``: connects to ``mvn://127.0.0.1:9763?transport=tcp``, which listens);
``mocopi`` sends Sony mocopi packets (``rtseg.simulators.mocopi_sender``, suit ``mocopi``,
default port 12351) - read it with ``rtseg live mocopi://127.0.0.1:12351``.  Their suit
segments a take has no joint for are filled from the parent segment.
``rokoko`` sends Rokoko Studio Live Custom JSON v3 (``rtseg.simulators.rokoko_sender``, suit
``rokoko``, UDP 14043) - read it with ``rtseg live "rokoko://127.0.0.1:14043?rate=R"``;
``axis`` sends Axis Neuron BVH broadcast (``rtseg.simulators.axis_sender``, suit ``axis``):
binary datagrams to UDP 7002, or with ``--axis-format text`` text frames from a TCP server
on 7001 - read it with ``rtseg live "axis://127.0.0.1:7002?rate=R"`` or
``"axis://127.0.0.1:7001?format=text&rate=R"`` (R: the take's frame rate, printed).

A recorded take is retargeted to the suit (``rtseg.simulators.retarget``): the skeleton
family (CMU ASF/AMC, CMU BVH, Mixamo, Daz/Poser, Unity humanoid, the vendor rigs) is
detected from the joint names (or named with ``--map``), each suit sensor gets the global orientation of its body
segment by forward kinematics, optionally with IMU noise and heading drift (``--imu
noise=0.5,drift=3,seed=1``: degrees, degrees per minute) and as raw sensors report it
(``--imu mount=180,up=z,heading=40``: each sensor turned on its segment by up to 180
degrees, a Z-up sensor world, the performer at heading 40; ``rtseg calibrate`` undoes it).  A suit bone the map cannot
place is an error naming it; ``--joint-map Head=upperneck,...`` places it by hand and
``--allow-missing`` sends the suit without it.

``--faults SPEC`` (serial, vmc and the vendor simulators): ``drop``, ``corrupt``,
``jitter`` and ``unplug`` per frame for mvn/mocopi/rokoko/axis (``dropout`` is serial/VMC
only: the vendor formats send whole skeletons); see ``rtseg.simulators.faults``.
``dropout=SENSOR:...`` must name one of the simulator's sensors - serial: a suit sensor id
or bone name, vmc: a bone name or its index among the bones sent - else the run is refused
with an error listing them; the serial summary counts the frames with a sensor dropout.

``--speed X`` sends X times faster while the stream keeps the take's own clock (serial
device time and sequence numbers, VMC ``/VMC/Ext/T``); ``--start``/``--end`` (take
seconds) send only that part of the take.

Without ``--take`` the built-in synthesiser performs ``--synth`` (default: its default
script) with ``--seed``; the exact transition frame ranges (the blend spans) are printed so
cuts can be checked by eye or by script (``--save take.npz`` keeps take and ground truth).
Runs until the take ends (never with ``--loop``), ``--duration`` seconds pass, or Ctrl-C /
SIGTERM, then prints what was sent.  Simulators a receiver must connect to hold the take's
first frame until it does, so a receiver started late loses nothing: ``serial`` until a
reader opens the pty, ``axis --axis-format text`` until a client connects to its TCP
server, ``mvn --transport tcp`` until its receiver accepts the connection (``--no-wait``:
the TCP ones start at once).  The summary gives the time waited apart from the time spent
sending, and for TCP how many frames a connected peer took and how many were written while
none was connected (lost).  ``--duration`` counts the waiting too.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path
from typing import Any, Callable

from rtseg.core.take import Take

DEVICES = ("serial", "vmc", "mvn", "mocopi", "rokoko", "axis")
#: the network devices, each sent by its simulator module's ``serve(args, take, host)``
#: (host: a :class:`Host`); the serial pty is served here
SENDER_MODULES = {device: f"rtseg.simulators.{device}_sender"
                  for device in ("vmc", "mvn", "mocopi", "rokoko", "axis")}


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "simulate", help="run a simulated suit (serial pty or VMC sender) from a take or the synthesiser",
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("device", choices=DEVICES, help="serial: pty speaking rtseg's serial format; "
                   "vmc: VMC over OSC/UDP")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--take", metavar="FILE", help="take to replay (.amc, .bvh, .npz, .csv, "
                     "or a recorded session folder)")
    src.add_argument("--synth", metavar="SCRIPT", help="synthesiser script behaviour:seconds,... "
                     "(default: the synthesiser's default script)")
    p.add_argument("--skeleton", metavar="ASF", help="skeleton of an .amc take "
                   "(default SS.asf beside SS_TT.amc)")
    p.add_argument("--seed", type=int, default=0, help="synthesiser seed (default 0)")
    p.add_argument("--rate", type=float, help="frames per second: the synthesiser's rate, or a "
                   "take's rate (default: the take's own, 120 for the synthesiser)")
    p.add_argument("--faults", default="", metavar="SPEC", help="fault injection, e.g. "
                   "corrupt=0.001,drop=0.01,jitter=0.002,dropout=5:2:1,unplug=10:0.5,seed=1")
    p.add_argument("--speed", type=float, default=1.0, metavar="X",
                   help="send X times faster than real time; the stream's own clock (device "
                   "time, sequence numbers, /VMC/Ext/T) stays the take's (default 1)")
    p.add_argument("--start", type=float, metavar="S", help="send the take from S seconds")
    p.add_argument("--end", type=float, metavar="S", help="send the take up to S seconds")
    p.add_argument("--map", dest="skeleton_map", metavar="NAME",
                   help="skeleton map of a take (cmu-asf, cmu-bvh, mixamo, daz, unity, "
                   "xsens-mvn, mocopi, rokoko, axis; "
                   "default: detected from the joint names)")
    p.add_argument("--joint-map", metavar="BONE=JOINT,...", default="",
                   help="place suit bones on take joints by hand, e.g. Head=upperneck")
    p.add_argument("--allow-missing", action="store_true",
                   help="send the suit without the bones the take has no joint for")
    p.add_argument("--imu", metavar="SPEC", default="",
                   help="IMU errors: noise=DEG (white, per axis), drift=DEG_PER_MIN (heading), "
                   "seed=N; raw sensors: mount=DEG (random mounting), up=y|z, heading=DEG")
    p.add_argument("--loop", action="store_true", help="repeat the take until stopped")
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument("--save", metavar="NPZ", help="also write the take (with the synthesiser's "
                   "ground truth in its meta) to this .npz")
    g = p.add_argument_group("serial")
    g.add_argument("--link", metavar="PATH", help="stable device path (symlink to the pty) "
                   "in an existing folder; a link already there is replaced (default: a "
                   "fresh temporary path)")
    g.add_argument("--format", choices=("rtseg", "text"), default="rtseg",
                   help="wire format (default rtseg binary frames)")
    p.add_argument("--suit", default="default17", help="suit profile (config/suits.toml): "
                   "the sensors (serial) or bones and hierarchy (VMC) sent")
    g.add_argument("--linger", type=float, default=0.5, metavar="S",
                   help="keep the device open S seconds after the last frame (default 0.5)")
    g = p.add_argument_group("vmc")
    g.add_argument("--host", default="127.0.0.1", help="receiver address (default 127.0.0.1)")
    g.add_argument("--port", type=int, default=None, help="receiver UDP port (default 39539; "
                   "mvn 9763, mocopi 12351)")
    p.add_argument("--no-wait", action="store_true",
                   help="TCP simulators (axis --axis-format text, mvn --transport tcp): start "
                   "sending at once instead of waiting for the first connection (frames "
                   "written while none is up are lost, and the summary counts them)")
    g = p.add_argument_group("mvn")
    g.add_argument("--character", type=int, default=0, help="MVN character id (default 0)")
    g.add_argument("--transport", choices=("udp", "tcp"), default="udp",
                   help="MVN over UDP datagrams (default) or a TCP connection to the receiver")
    g = p.add_argument_group("rokoko")
    g.add_argument("--actor", metavar="NAME,...", help="actor name(s), one actor each in every "
                   "payload (default Actor1)")
    g.add_argument("--lz4", action="store_true", help="LZ4-compress each payload")
    g = p.add_argument_group("axis")
    g.add_argument("--axis-format", choices=("binary", "text"), default="binary",
                   help="binary frames to UDP 7002 (default) or text frames served on TCP 7001")
    p.set_defaults(func=run)


def _out(text: str = "") -> None:
    print(text, flush=True)


def load(args: argparse.Namespace):
    """(take, SynthResult or None) chosen by the arguments."""
    if args.rate is not None and not args.rate > 0:
        raise ValueError(f"--rate must be positive, got {args.rate}")
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be positive, got {args.duration}")
    if not (0 < args.speed < float("inf")):
        raise ValueError(f"--speed must be a positive number, got {args.speed}")
    for name in ("start", "end"):
        v = getattr(args, name)
        if v is not None and not (0 <= v < float("inf")):
            raise ValueError(f"--{name} must be a number of seconds >= 0, got {v}")
    if args.faults:
        from rtseg.simulators.faults import FaultConfig
        FaultConfig.parse(args.faults)          # fail before anything starts
    if args.device == "serial" and args.link is not None:
        check_link(args.link)
    from rtseg.simulators.retarget import ImuModel
    ImuModel.parse(args.imu)
    parse_joint_map(args.joint_map)
    if args.take:
        from rtseg.drivers.readers import read_take
        take, result = read_take(args.take, skeleton=args.skeleton, frame_rate=args.rate), None
    else:
        if args.skeleton:
            raise ValueError("--skeleton goes with --take")
        from rtseg.simulators.synth.motion import DEFAULT_SCRIPT, synthesize
        result = synthesize(args.synth or DEFAULT_SCRIPT, frame_rate=args.rate or 120.0,
                            seed=args.seed)
        take = result.take
    return take, result


def parse_joint_map(spec: str) -> dict[str, str]:
    """``"Head=upperneck,Chest=upperback"`` -> {suit bone: take joint}."""
    out: dict[str, str] = {}
    for part in filter(None, (p.strip() for p in spec.split(","))):
        bone, eq, joint = (x.strip() for x in part.partition("="))
        if not eq or not bone or not joint:
            raise ValueError(f"--joint-map: expected BONE=JOINT, got {part!r}")
        out[bone] = joint
    return out


def portion(take: Take, start: float | None, end: float | None) -> Take:
    """Frames of ``take`` from ``start`` to ``end`` seconds (take time)."""
    if start is None and end is None:
        return take
    a = 0 if start is None else int(round(start * take.frame_rate))
    b = take.n_frames if end is None else min(take.n_frames, int(round(end * take.frame_rate)))
    if a >= b:
        raise ValueError(f"--start/--end select no frame of the {take.duration:.2f} s take")
    return take.slice(a, b)


def describe(take: Take, result) -> None:
    """Print the take and, for a synthetic one, its exact transitions."""
    _out(f"take: {take.source or '<memory>'}: {take.n_frames} frames at {take.frame_rate:g} Hz "
         f"({take.duration:.2f} s), {take.n_joints} joints, {take.space} rotations")
    rate = take.frame_rate
    if result is None:
        saved = take.meta.get("transitions")   # a synthetic take saved with --save
        if saved:
            _out(f"transitions recorded in the take ({len(saved)}; frames lo-hi inclusive):")
            for k, (lo, mid, hi, before, after) in enumerate(saved, 1):
                _out(f"  {k:2d} frames {lo:6d}-{hi:<6d} mid {mid:6d} "
                     f"({lo / rate:7.3f}-{hi / rate:7.3f} s)  {before} -> {after}")
        return
    _out(f"script: {take.meta.get('synth_script')}  seed: {take.meta.get('synth_seed')}")
    for s in result.segments:
        _out(f"  segment {s.name:<14s} frames {s.start:6d}-{s.stop - 1:<6d} "
             f"({s.start / rate:7.3f}-{s.stop / rate:7.3f} s)")
    _out(f"transitions ({len(result.transitions)}; frames lo-hi inclusive = blend span, "
         f"mid = scripted boundary):")
    for k, t in enumerate(result.transitions, 1):
        _out(f"  {k:2d} frames {t.lo:6d}-{t.hi:<6d} mid {t.mid:6d} "
             f"({t.lo / rate:7.3f}-{t.hi / rate:7.3f} s)  {t.before} -> {t.after}")


def _run_until(done: Callable[[float], bool], duration: float | None) -> str:
    """Wait until ``done(timeout)`` is True or ``duration`` passes; the reason."""
    deadline = None if duration is None else time.monotonic() + duration
    while True:
        step = 0.1
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                return "duration"
            step = min(step, left)
        if done(step):
            return "end of take"


def _retarget_kw(args) -> dict:
    return {"skeleton_map": args.skeleton_map, "joint_map": parse_joint_map(args.joint_map),
            "imu": args.imu or None, "allow_missing": args.allow_missing}


def check_host(host: str) -> None:
    """``--host`` resolved now: a name or address that does not resolve is a ValueError
    naming it, before anything is sent."""
    import socket
    try:
        socket.getaddrinfo(host, None)
    except (socket.gaierror, UnicodeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        raise ValueError(f"--host {host!r}: not an address, and no host of that name can be "
                         f"found ({why})") from None


def check_link(link: str) -> None:
    """``--link`` checked before any work: a ValueError naming it when the symlink cannot
    be made there - an empty path, a folder that does not exist or is a file, an existing
    folder or file (not a link) at the path itself.  A link already there is replaced."""
    import os
    if not link:
        raise ValueError("--link '': an empty path (give the device path to create, e.g. "
                         "/tmp/rtseg-suit)")
    path = Path(link)
    folder = path.parent
    if path.is_symlink():
        return
    if path.is_dir():
        raise ValueError(f"--link {link}: is a folder; give the path of the link to create, "
                         f"e.g. {path / 'rtseg-suit'}")
    if path.exists():
        raise ValueError(f"--link {link}: a file that is not a link is there (it would be "
                         f"replaced); remove it or choose another path")
    if not folder.exists():
        raise ValueError(f"--link {link}: cannot create the link: folder {folder} does not "
                         f"exist")
    if not folder.is_dir():
        raise ValueError(f"--link {link}: cannot create the link: {folder} is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"--link {link}: cannot create the link: folder {folder} is not "
                         f"writable")


class Host:
    """What a network simulator's ``serve(args, take, host)`` gets from the command: ``out``
    (print a line), ``retarget_kw`` (retargeting options), :meth:`port` and :meth:`drive`."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.out = _out
        self.retarget_kw = _retarget_kw(args)

    def port(self, default: int, lowest: int = 1, faults: bool = False) -> int:
        """``--port`` (``default`` when not given) checked to be ``lowest``..65535; unless
        ``faults``, a ``--faults`` spec is refused (the device cannot inject them)."""
        args = self.args
        port = default if args.port is None else args.port
        if not lowest <= port < 65536:
            raise ValueError(f"--port must be {lowest}..65535, got {port}")
        check_host(args.host)
        if args.faults and not faults:
            raise ValueError(f"--faults is not supported by the {args.device} simulator")
        return port

    def drive(self, sender, start: bool = True) -> tuple[str, float]:
        """Run ``sender`` (``start()`` it unless already started) until its ``wait`` says
        done, ``--duration`` passes or Ctrl-C, then ``stop()`` it: (stop reason, seconds)."""
        t0 = time.monotonic()
        reason = "interrupted"
        if start:
            sender.start()
        try:
            reason = _run_until(sender.wait, self.args.duration)
        except KeyboardInterrupt:
            pass
        finally:
            sender.stop()
        return reason, time.monotonic() - t0

    @staticmethod
    def peer(sender) -> str:
        """What a TCP sender waits for: the ``client`` of a server (Axis text) or the
        ``receiver`` it connects to (MVN)."""
        return "receiver" if getattr(sender, "transport", "") == "tcp" else "client"

    def wait_for_peer(self):
        """The ``wait_client`` / ``wait_server`` value of a TCP simulator: however long
        (inf), unless ``--no-wait`` (0: start the clock at once)."""
        return 0.0 if self.args.no_wait else float("inf")

    @staticmethod
    def summary(sender, elapsed: float, unit: str = "frames", size: str = "datagrams",
                last: str = "take time") -> list[str]:
        """What a vendor sender sent: ``unit`` (frames, payloads) counted with their
        ``size`` (datagrams or bytes), the take frames covered and the ``last`` slot's take
        time (or, for ``last="frame index"``, its slot)."""
        log = list(sender.sent_log)
        amount = sum(s.nbytes if size == "bytes" else s.datagrams for s in log)
        faults: dict[str, int] = {}
        for s in log:
            if s.fault:
                faults[s.fault] = faults.get(s.fault, 0) + 1
        sent = len(log) - faults.get("dropped", 0) - faults.get("unplugged", 0)
        waited = getattr(sender, "waited_s", 0.0)
        sending = getattr(sender, "sending_s", elapsed)
        peer = Host.peer(sender)
        lost = sum(1 for s in log if getattr(s, "delivered", None) is False)
        reach = ""
        if lost:              # TCP, nobody connected: those frames reached no one
            sent -= lost
            amount -= sum(s.nbytes if size == "bytes" else s.datagrams
                          for s in log if s.delivered is False)
            reach = f"; {lost} {unit} lost: no {peer} was connected"
        lines = ([f"waited {waited:.2f} s for a {peer} before sending"]
                 if waited >= 0.005 else [])
        lines += [f"sent {sent} {unit} ({amount} {size}) in {sending:.2f} s{reach}; "
                  f"{sender.send_errors} send errors"
                  + "".join(f"; {v} {k} by faults" for k, v in sorted(faults.items()))]
        if log:
            end = (f"{log[-1].slot}" if last == "frame index"
                   else f"{log[-1].source_time:.3f} s")
            lines.append(f"take frames {log[0].index}..{log[-1].index}, last {last} {end}")
        return lines


def _serve_serial(args, take: Take) -> tuple[str, list[str]]:
    from rtseg.simulators.faults import FaultConfig
    from rtseg.simulators.serial_device import READER_SETTLE_S, SerialSuit

    suit = SerialSuit(take, faults=FaultConfig.parse(args.faults), link=args.link,
                      fmt=args.format, loop=args.loop, suit=args.suit, speed=args.speed,
                      **_retarget_kw(args))
    _out(f"  {suit.retargeted.describe(take.joint_names)}")
    path = suit.start()
    _out(f"serial device: {path} ({len(suit.suit.bones)}-sensor suit {suit.suit.name}, "
         f"{suit.rate:g} Hz device clock, sent at x{suit.speed:g})")
    url = f"serial://{path}" + ("?format=text&baud=115200" if args.format == "text" else "")
    from rtseg.simulators.retarget import ImuModel
    raw = ImuModel.parse(args.imu)
    if raw.raw:
        sep = "&" if "?" in url else "?"
        _out(f"  raw sensors: calibrate with rtseg calibrate {url} --up {raw.up} --out suit.json "
             f"(a T-pose held first: --synth tpose:3,squat:5,...), then read it with: "
             f"rtseg live \"{url}{sep}calibration=suit.json\"")
    else:
        _out(f"  read it with: rtseg live {url}")
    t0 = time.monotonic()
    reason = "interrupted"
    try:
        reason = _run_until(suit.wait_done, args.duration)
        if reason == "end of take" and args.linger > 0:
            time.sleep(args.linger)
    except KeyboardInterrupt:
        pass
    finally:
        suit.stop()
    log = list(suit.sent_log)
    frames = [m for m in log if m.frame >= 0]
    fates: dict[str, int] = {}
    for m in frames:
        fates[m.fate] = fates.get(m.fate, 0) + 1
    started = getattr(suit, "t0", None)        # the clock starts when a reader opens it
    lines = []
    if started is None:
        lines.append(f"no reader opened the device in {time.monotonic() - t0:.2f} s: "
                     f"nothing sent")
    elif started - t0 >= 0.005:
        lines.append(f"waited {started - t0:.2f} s for a reader to open the device "
                     f"(sending starts {READER_SETTLE_S:g} s after it does)")
    sending = (log[-1].send_time - started) if log and started is not None else 0.0
    # frames a fault dropout left a sensor out of (said whenever dropouts are configured)
    dropouts = (f"; {sum(1 for m in frames if m.silenced)} with a sensor dropout"
                if suit.injector.config.dropouts else "")
    lines += [f"sent {len(frames)} frame messages in {sending:.2f} s "
             f"({', '.join(f'{v} {k}' for k, v in sorted(fates.items())) or 'none'})"
             f"{dropouts}; "
             f"{len(log) - len(frames)} device-info messages; {len(suit.unplug_log)} unplug(s)"]
    if frames:
        lines.append(f"take frames {frames[0].frame}..{frames[-1].frame} "
                     f"({len({m.frame for m in frames})} distinct), last seq {frames[-1].seq}")
    return reason, lines


def run(args: argparse.Namespace) -> int:
    take, result = load(args)
    describe(take, result)
    part = portion(take, args.start, args.end)
    if part is not take:
        _out(f"sending {part.n_frames} frames ({part.duration:.2f} s) from "
             f"{(args.start or 0.0):.2f} s")
    if args.save:
        from rtseg.drivers.readers import write_take
        _out(f"saved take to {write_take(args.save, take)}")
    # SIGTERM ends the run like Ctrl-C (device closed, summary printed); Ctrl-C does so even
    # when the process was started with SIGINT ignored (a shell's background job, a caller
    # inside system(3): the disposition is inherited, and Python then leaves it ignored)
    old: dict[int, object] = {}
    try:
        for sig, handler in ((signal.SIGTERM, _raise_interrupt),
                             (signal.SIGINT, signal.default_int_handler)):
            old[sig] = signal.signal(sig, handler)
    except ValueError:  # not the main thread
        pass
    try:
        serve = _serve_serial if args.device == "serial" else _sender(args.device)
        reason, lines = serve(args, part)
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    _out(f"stopped: {reason}")
    for line in lines:
        _out(line)
    return 0


def _sender(device: str) -> Callable:
    """serve(args, take) of a simulator module of ``SENDER_MODULES``."""
    import importlib
    mod = importlib.import_module(SENDER_MODULES[device])
    return lambda args, take: mod.serve(args, take, Host(args))


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


if __name__ == "__main__":  # pragma: no cover
    from rtseg.cli import main
    sys.exit(main(["simulate", *sys.argv[1:]]))
