"""``rtseg calibrate``: record an IMU suit's calibration (``rtseg.core.suit_calibration``).

    rtseg calibrate "serial:///dev/ttyUSB0" --up z --out suit.json [--seconds 60] [--hold 1]

The performer holds a T-pose for ``--hold`` seconds, then bends the knees (a squat, walking
on the spot); the command writes the calibration and prints the ``rtseg live`` URL that
applies it (``calibration=FILE``).  ``--up``: the sensors' world up axis (z for a BNO055 in
its fusion mode, y for sensors that report Y up).  Exit 0 with a calibration, 2 without
(one line saying why), as for a bad URL or option.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from urllib.parse import quote

from rtseg.cli import EXIT_USAGE, positive_float
from rtseg.core.suit_calibration import HOLD_S, UP_AXES, CalibrationError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "calibrate", help="record an IMU suit's calibration from a T-pose and knee bends",
        description="Record an IMU suit's sensor-to-segment calibration: hold a T-pose, then "
                    "bend the knees.  The file makes raw sensor orientations (any mounting, "
                    "a Z-up or Y-up sensor world, any heading) segment rotations from the "
                    "T-pose: rtseg live 'serial://...?calibration=FILE'.")
    p.add_argument("source", metavar="SOURCE_URL", help="the suit, e.g. serial:///dev/ttyUSB0")
    p.add_argument("--out", required=True, metavar="FILE", help="calibration file to write (JSON)")
    p.add_argument("--up", choices=sorted(UP_AXES), default="y",
                   help="the sensors' world up axis (default y; z for a BNO055)")
    p.add_argument("--seconds", type=positive_float, default=60.0,
                   help="longest time to wait for the T-pose and the knee bends (default 60)")
    p.add_argument("--hold", type=positive_float, default=HOLD_S,
                   help=f"seconds the T-pose must be held still (default {HOLD_S:g})")
    p.set_defaults(func=run)


def check_out(out: str) -> str | None:
    """Why the calibration cannot be written to ``out`` (one line), or None: checked
    before the performer calibrates, not after.  Tries to open it for appending (an
    existing file is left as it is, a new one removed again)."""
    path = Path(out)
    if path.is_dir():
        return f"--out {out}: is a folder, give a file name (e.g. {path / 'suit.json'})"
    folder = path.parent
    if not folder.is_dir():
        return (f"--out {out}: {folder} is not a folder" if folder.exists() else
                f"--out {out}: folder {folder} does not exist")
    existed = path.exists()
    try:
        with open(path, "a", encoding="utf-8"):
            pass
    except OSError as exc:
        return f"--out {out}: cannot write ({exc.strerror or exc})"
    if not existed:
        try:
            path.unlink()
        except OSError:
            pass
    return None


def live_command(source_url: str, out: str, rate: float | None = None) -> str:
    """The ``rtseg live`` command line that reads ``source_url`` with the calibration
    ``out``: the file percent-encoded in the URL (a ``&``, ``#``, ``+`` or space would cut
    or change it) and the URL quoted for a POSIX shell; ``rate``: the rate the suit's
    clock said, added as ``rate=`` when the URL has none."""
    from rtseg.drivers import parse_url
    url = source_url
    if rate is not None and "rate" not in parse_url(source_url)[2]:
        url += f"{'&' if '?' in url else '?'}rate={round(rate):g}"
    url += f"{'&' if '?' in url else '?'}calibration={quote(out, safe='/')}"
    return f"rtseg live {shlex.quote(url)}"


def run(args: argparse.Namespace) -> int:
    from rtseg.drivers import open_source, parse_url
    from rtseg.drivers.base import SourceError
    from rtseg.live.calibrate import capture, check_source

    def error(message: str) -> int:
        print(f"rtseg calibrate: error: {message}", file=sys.stderr)
        return EXIT_USAGE

    try:
        scheme = parse_url(args.source)[0]
    except SourceError as exc:
        return error(str(exc))
    if scheme != "serial":
        return error(f"{scheme}:// is not an IMU suit: rtseg calibrate calibrates a suit read "
                     f"over serial:// (e.g. serial:///dev/ttyUSB0), whose URL takes "
                     f"calibration=FILE")
    if args.hold >= args.seconds:
        return error(f"--hold {args.hold:g} s leaves no time in --seconds {args.seconds:g} for "
                     f"the knee bends: give --seconds more than --hold")
    problem = check_out(args.out)
    if problem:
        return error(problem)
    try:
        source = open_source(args.source)
    except SourceError as exc:
        return error(str(exc))
    try:
        try:
            check_source(source)
        except CalibrationError as exc:
            return error(str(exc))
        print(f"rtseg calibrate: hold a T-pose (arms out level, legs straight) for "
              f"{args.hold:g} s, then bend the knees a few times", file=sys.stderr)
        try:
            got = capture(source, args.up, args.seconds, args.hold,
                          progress=lambda m: print(f"rtseg calibrate: {m}", file=sys.stderr))
        except CalibrationError as exc:
            return error(str(exc))
    finally:
        source.close()
    if got.calibration is None:
        print(f"rtseg calibrate: error: no calibration from {got.frames} frames: {got.reason}",
              file=sys.stderr)
        return EXIT_USAGE
    got.calibration.save(args.out)
    r = got.report
    print(f"{args.out}: {len(got.calibration.joint_names)} sensors, up {args.up}, heading "
          f"{r['heading_deg']:.1f} degrees from {r['knee_bends']} knee bends (axis "
          f"{r['knee_axis_tilt_deg']:.1f} degrees from level), T-pose at frames "
          f"{r['t_pose_frames'][0]}-{r['t_pose_frames'][1]} of {got.used}")
    print(f"  use it with: {live_command(args.source, args.out, got.measured_rate)}")
    return 0
