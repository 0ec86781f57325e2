#!/usr/bin/env python3
"""Behaviour names sent by live sessions over VMC (real UDP on 127.0.0.1), against the file
replay of the same performances.

    python3 benchmarks/names_over_vmc.py PERF_DIR LIB [--speed S] [--no-positions] [--json]

PERF_DIR: labelled performances (``benchmarks/splice.py`` output, or any folder
``rtseg evaluate --group spliced`` reads); LIB: a behaviour library (``rtseg learn``).
Each performance is sent by the VMC simulator (``rtseg.simulators.vmc_sender.VmcSender``,
``--speed`` times its rate; bone positions = the take's rest offsets, as an avatar's, or
zeros with ``--no-positions``, as a sender without them: the session then takes the
standard T-pose once its facing probe has decided) to a ``LiveSession`` on
``osc://127.0.0.1:PORT?format=vmc`` naming with LIB; and replayed from the file through the
same pipeline (``rtseg.evaluation.identity.run_identity``).  Printed for both: the named
segments' summary (``rtseg.evaluation.library.named_summary``: named right, ``unknown``,
wrong, over the segments whose behaviour LIB holds, and the share of the others sent
``unknown``), and for VMC how many decisions compared posture (the sender's geometry
reached the namer) and the frames received.
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
import threading
import types
from pathlib import Path

from rtseg.evaluation.identity import run_identity
from rtseg.evaluation.library import named_segments, named_summary
from rtseg.evaluation.online import live_config
from rtseg.labels.takes import find_labelled_takes
from rtseg.labels.truth import named_truth_labels
from rtseg.library.file import load
from rtseg.live.config import from_dict
from rtseg.live.session import LiveSession
from rtseg.simulators.vmc_sender import VmcSender


def free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def over_vmc(take, lib_path: str, speed: float, positions: bool) -> tuple[object, dict]:
    """The identity tracker of a live session fed ``take`` over VMC, and its counts."""
    port = free_udp_port()
    cfg = from_dict({"output": {"osc": []},
                     "identity": {"enabled": True, "behaviours": lib_path}}, origin="benchmark")
    seconds = take.n_frames / float(take.frame_rate) / speed
    session = LiveSession(f"osc://127.0.0.1:{port}?format=vmc&rate={take.frame_rate:g}", cfg,
                          handle_signals=False, duration=seconds + 2.0)
    sender = VmcSender(take, "127.0.0.1", port, speed=speed)
    if not positions:
        sender.bone_positions = None
    timer = threading.Timer(0.5, sender.start)     # once the session's socket is bound
    timer.start()
    try:
        session.run()
    finally:
        timer.cancel()
        sender.stop()
    tracker = session.pipeline.identity
    return tracker, {"frames_sent": take.n_frames,
                     "frames_received": session.stats.frames_received,
                     "decisions": tracker.stats.decisions,
                     "posture_namings": tracker.stats.posture_namings}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("perf_dir", type=Path)
    p.add_argument("library", type=Path)
    p.add_argument("--speed", type=float, default=2.0, help="send this many times the rate")
    p.add_argument("--no-positions", action="store_true", help="the sender sends zero positions")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    if not args.speed > 0:
        print("names_over_vmc: --speed must be > 0", file=sys.stderr)
        return 2
    try:
        lib = load(args.library)
        takes = [t for t in find_labelled_takes(args.perf_dir, ("spliced",))]
    except (OSError, ValueError) as exc:
        print(f"names_over_vmc: {exc}", file=sys.stderr)
        return 2
    if not takes:
        print(f"names_over_vmc: no labelled performances in {args.perf_dir}", file=sys.stderr)
        return 2
    cfg, _ = live_config()
    cfg["identity.enabled"] = True
    rows_vmc, rows_file, counts = [], [], []
    for t in takes:
        take = t.load()
        truth = named_truth_labels(t, take.n_frames)
        tracker, c = over_vmc(take, str(args.library), args.speed, not args.no_positions)
        counts.append({"take": t.name, **c})
        rows_vmc += named_segments(types.SimpleNamespace(tracker=tracker), take, truth, lib,
                                   t.name)
        rows_file += named_segments(run_identity(take, cfg, lib), take, truth, lib, t.name)
    out = {"performances": len(takes), "speed": args.speed,
           "positions_sent": not args.no_positions,
           "vmc": named_summary(rows_vmc), "file_replay": named_summary(rows_file),
           "sessions": counts}
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    for key in ("vmc", "file_replay"):
        s = out[key]
        left = s['not_in_library']
        print(f"{key:12s} named right {s['accuracy']}, unknown {s['unknown_rate']}, wrong "
              f"{s['wrong_rate']} of {s['segments']} known segments; missing behaviours "
              + (f"unknown {left['unknown_rate']}" if left['segments'] else "none"))
    for c in counts:
        print(f"  {c['take']}: {c['frames_received']} of {c['frames_sent']} frames, "
              f"{c['posture_namings']} of {c['decisions']} decisions by posture")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
