"""``rtseg demo``: the whole live chain on a simulated suit, no hardware needed.

Synthesises a performance (``rtseg.simulators.synth.motion``, default script: idle, walk, punch,
walk, squat, punch, wave, squat, kick: walk, punch and squat recur), plays it as a 17-sensor
IMU suit on a **real pseudo-terminal** (``rtseg.simulators.serial_device.SerialSuit``, rtseg's
binary serial format at 120 Hz), and runs the live session on ``serial://<that pty>`` exactly
as ``rtseg live`` would on a USB suit: pose features, the default live detector (contrast),
cuts sent over OSC to 127.0.0.1:9123 (listen with ``oscdump 9123``) and printed as they
happen, each followed by its behaviour id (``[identity]``, on in the demo unless
``--no-identity``): an earlier segment's id when the behaviour recurs, else a new one.
Without ``--config`` the identity threshold is the synthesiser's
(``rtseg.simulators.synth.motion.IDENTITY_THRESHOLD``, 7.0: its instances of one behaviour differ
more than real repeats), not the mocap default.
Each behaviour line also carries the segment's name from a behaviour library: by default
one the demo learns at start from two other synthetic performers (seeds SEED + 1001 and
SEED + 1002) of idle, walk, punch, squat and wave, so kick (and any other behaviour of a
--script) comes out "unknown"; --behaviours LIB names with a library of rtseg learn;
--no-names gives ids only.
The first behaviour change comes 5 s in, so the first cut appears about 6 s in; the demo
ends by itself after ``--duration`` seconds (default 60).  Ctrl-C stops it cleanly.
"""

from __future__ import annotations

import argparse
import math
import sys

from rtseg.library.file import save as save_library
from rtseg.cli import error_text, positive_float
from rtseg.commands.live import (add_session_arguments, config_from_args, run_session,
                                 start_monitor, use_library)
from rtseg.config import ConfigError

DEFAULT_DURATION = 60.0
#: ``--monitor`` not given: the demo serves the monitor on 127.0.0.1:8765 when it can
MONITOR_AUTO = "auto"
#: The demo's performance: behaviours recur (walk, punch, squat twice) so the behaviour ids
#: printed beside the cuts show a recurring behaviour getting its earlier id back.
DEMO_SCRIPT = "idle:5,walk:7,punch:7,walk:7,squat:7,punch:7,wave:7,squat:7,kick:6"
#: The behaviours of the demo's own library, learned from other synthetic performers: the
#: default script's kick is not among them, so it is named ``unknown``
DEMO_LIBRARY = ("idle", "walk", "punch", "squat", "wave")
#: the library's performers: the performance's seed plus these
LIBRARY_SEED_OFFSETS = (1001, 1002)


def demo_library(seed: int, config, folder: str) -> tuple[str, str]:
    """Learn the demo's behaviour library (module doc) into ``folder``; (path, what it
    holds, for the console)."""
    from pathlib import Path
    from rtseg.library.examples import learn, synthetic_examples
    seeds = [seed + k for k in LIBRARY_SEED_OFFSETS]
    lib, _ = learn(synthetic_examples(DEMO_LIBRARY, seeds, config))
    path = save_library(lib, Path(folder) / "demo_behaviours.json")
    return str(path), (f"{', '.join(DEMO_LIBRARY)} from two other synthetic performers "
                       f"(seeds {seeds[0]} and {seeds[1]}); anything else is named unknown")


def run(args: argparse.Namespace) -> int:
    try:
        cfg = config_from_args(args)
    except ConfigError as exc:
        print(f"rtseg demo: configuration error: {error_text(exc)}", file=sys.stderr)
        return 2
    script = args.script or DEMO_SCRIPT
    if not args.no_identity:
        cfg["identity.enabled"] = True
        if args.config is None:       # the synthesiser's own spread sets its threshold
            from rtseg.simulators.synth.motion import IDENTITY_THRESHOLD
            cfg["identity.threshold"] = IDENTITY_THRESHOLD
    if args.behaviours and not use_library(cfg, args.behaviours, "rtseg demo"):
        return 2
    import tempfile
    with tempfile.TemporaryDirectory(prefix="rtseg-demo-") as tmp:
        held = ""
        if cfg["identity.enabled"] and not args.behaviours and not args.no_names \
                and not cfg.values.get("identity", {}).get("behaviours"):
            path, held = demo_library(args.seed, cfg, tmp)
            cfg["identity.behaviours"] = path
        try:
            return _run(args, cfg, script, held)
        except ConfigError as exc:          # --monitor that cannot run
            print(f"rtseg demo: {error_text(exc)}", file=sys.stderr)
            return 2


def _run(args: argparse.Namespace, cfg, script: str, library: str = "") -> int:
    """The demo proper: synthesise, play on a pty, run the live session on it
    (``library``: what the demo's own library holds, for the console; "" without it)."""
    from rtseg.simulators.faults import FaultConfig
    from rtseg.simulators.serial_device import READER_SETTLE_S, SerialSuit
    from rtseg.simulators.synth.motion import ScriptError, parse_script, synthesize
    try:
        faults = FaultConfig.parse(args.faults)
        items = parse_script(script)
        # a script shorter than --duration is performed again (blended into its own start,
        # its transitions in --truth) rather than the suit jumping back to the first frame
        total = sum(secs for _, secs in items)
        times = max(1, math.ceil(args.duration / total)) if total > 0 else 1
        synth = synthesize(items * times, frame_rate=args.rate, seed=args.seed)
    except (ScriptError, ValueError) as exc:
        print(f"rtseg demo: {exc}", file=sys.stderr)
        return 2
    take = synth.take
    # --speed: frames go out speed x faster while the suit's clock and sequence numbers stay
    # those of the performance, so detector delays (frames / rate) and the t= printed are
    # performance time; --duration is performance time too (wall clock: duration / speed)
    suit = SerialSuit(take, rate=args.rate, speed=args.speed, faults=faults, loop=True)
    path = suit.start()
    try:
        url = f"serial://{path}?rate={args.rate:g}&tpose=1"
        targets = ", ".join(cfg["output.osc"])
        where = (f"cuts go to OSC {targets} (try `oscdump {cfg['output.osc'][0].rsplit(':', 1)[1]}`)"
                 if targets else "no OSC/UDP target")
        print(f"rtseg demo: simulated suit on {path} ({take.n_joints} sensors, "
              f"{args.rate:g} Hz{', faults ' + faults.to_spec() if faults.enabled else ''})",
              file=sys.stderr)
        if args.speed != 1:
            print(f"rtseg demo: --speed {args.speed:g}: frames are sent {args.speed:g}x faster "
                  f"({args.rate * args.speed:g} frames per wall-clock second) on the "
                  f"performance's {args.rate:g} Hz clock; every time (t=, status, dropouts) and "
                  f"detector delays are performance time (divide by {args.speed:g} for "
                  f"wall-clock time), "
                  f"processing times are wall-clock", file=sys.stderr)
        print(f"rtseg demo: script {script}", file=sys.stderr)
        if library:
            print(f"rtseg demo: behaviour library: {library}", file=sys.stderr)
        wall = f" ({args.duration / args.speed:.1f} s)" if args.speed != 1 else ""
        print(f"rtseg demo: reading {url}; {where}; ending after {args.duration:g} s of "
              f"performance{wall}, Ctrl-C to stop", file=sys.stderr)
        if args.truth:
            for tr in synth.transitions:
                if tr.mid / args.rate > args.duration:
                    break
                print(f"truth: {tr.before} -> {tr.after} at frame {tr.mid} "
                      f"(t={tr.mid / args.rate:.2f} s, blend {tr.lo}..{tr.hi})", file=sys.stderr)
        monitor = demo_monitor(args)
        # the session's clock starts when it opens the port, the suit's performance
        # READER_SETTLE_S later (a board booting on the port's DTR): that much more wall time
        return run_session(url, cfg, args.duration / args.speed + READER_SETTLE_S, args.quiet,
                           monitor=monitor,
                           check=lambda summary: speed_check(summary, args))
    finally:
        suit.stop()


#: a demo that processed less than this share of the frames of its ``--duration`` of
#: performance says so (the loop did not keep up with ``--speed``)
KEPT_UP = 0.9


def speed_check(summary, args: argparse.Namespace) -> int:
    """The demo's exit status from its session ``summary``: 1, with one line, when no frame
    was processed; 0 otherwise, with a warning giving the speed the loop reached when it
    processed less than :data:`KEPT_UP` of the ``--duration`` x ``--rate`` frames the
    performance holds (``--speed`` beyond what this machine sustains)."""
    due = int(round(args.duration * args.rate))
    done = summary.frames_processed
    wall = max(summary.duration_s, 1e-9)
    reached = done / args.rate / wall               # performance seconds per wall second
    if done == 0:
        if getattr(args, "faults", None) and not summary.frames_received:
            why = f"--faults {args.faults} let none through"
        else:
            why = (f"--speed {args.speed:g} leaves the session {args.duration / args.speed:.2f} s, "
                   f"too short to start and process any (lower --speed, or raise --duration)")
        print(f"rtseg demo: error: no frame processed ({summary.frames_received} received) "
              f"in {summary.duration_s:.1f} s of wall-clock time: {why}", file=sys.stderr)
        return 1
    if summary.stop_reason != "duration reached":
        return 0                    # stopped by the user or the source: not a speed matter
    # frames lost on the way (--faults, a corrupt link: gaps in the sequence numbers) were
    # never the loop's to keep up with
    lost = max(0, summary.dropped - summary.overload_drops - summary.overruns)
    if done + lost < KEPT_UP * due:
        print(f"rtseg demo: warning: processed {done} of the {due} frames of "
              f"{args.duration:g} s of performance ({100 * done / due:.0f} %) in "
              f"{summary.duration_s:.1f} s: the loop reached x{reached:.1f} of real time "
              f"({done / wall:.0f} frames/s), not the --speed {args.speed:g} asked for; the "
              f"rest was not segmented (start-up counts in a short session: lower --speed "
              f"or raise --duration)", file=sys.stderr)
    return 0


def demo_monitor(args: argparse.Namespace) -> tuple | None:
    """The demo's live monitor: the one ``--monitor`` asks for (an error if it cannot
    run), none with ``--no-monitor``, else 127.0.0.1:8765 when aiohttp is installed and
    the port free (otherwise one line says why there is none)."""
    if args.no_monitor:
        return None
    if args.monitor != MONITOR_AUTO:
        return start_monitor(args.monitor, "rtseg demo")
    try:
        return start_monitor("", "rtseg demo")
    except ConfigError as exc:
        print(f"rtseg demo: no live monitor ({str(exc).removeprefix('--monitor: ')})",
              file=sys.stderr)
        return None


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo", help="live segmentation of a simulated suit on a pseudo-terminal (no hardware)",
        description=__doc__.split("\n\n")[1].replace("``", "").replace("**", ""),
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--script", metavar="SCRIPT",
                   help="behaviours and seconds, e.g. 'idle:5,walk:8,punch:6' "
                        f"(default: {DEMO_SCRIPT})")
    p.add_argument("--faults", metavar="SPEC",
                   help="inject faults into the serial link, e.g. "
                        "'corrupt=0.01,unplug=20:0.5,dropout=5:10:1'")
    p.add_argument("--seed", type=int, default=0, help="synthesiser seed (default 0)")
    p.add_argument("--rate", type=positive_float, default=120.0,
                   help="suit frame rate, Hz (default 120)")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="playback speed factor: frames are sent at rate x speed on the "
                        "performance's own clock, so --duration, t= and detector delays are "
                        "performance time (default 1)")
    p.add_argument("--no-identity", action="store_true",
                   help="do not name behaviours (by default the demo turns [identity] on: each "
                        "segment gets a behaviour id, an earlier segment's when it recurs)")
    p.add_argument("--behaviours", metavar="LIB",
                   help="name segments with this behaviour library (rtseg learn) instead of "
                        "the demo's own")
    p.add_argument("--no-names", action="store_true",
                   help="behaviour ids only: no library (by default the demo learns one from "
                        "other synthetic performers at start)")
    p.add_argument("--truth", action="store_true",
                   help="print the script's true transition frames before starting")
    p.add_argument("--no-monitor", action="store_true",
                   help="serve no live monitor page (by default the demo serves one on "
                        "127.0.0.1:8765 when aiohttp is installed)")
    add_session_arguments(p)
    p.set_defaults(func=run, duration=DEFAULT_DURATION, monitor=MONITOR_AUTO)
