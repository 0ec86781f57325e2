#!/usr/bin/env python3
"""Behaviour names of a live serial suit whose sensors report raw orientations, with and
without a suit calibration (``rtseg calibrate``, docs/live.md "Calibrating a suit").

    python3 benchmarks/suit_calibration.py [--seeds 1 2 6] [--speed 4]

For each seed, a synthetic performer (``rtseg.simulators.synth``: a 3 s T-pose, then
walk, squat, punch, wave, jump and kick in a seeded order, 6 s each, some twice) is played
on a real pseudo-terminal as the 17-sensor suit (``SerialSuit``, ``--speed`` times real
time), its sensors mounted at random (up to 180 degrees), in a Z-up world, the performer
at heading 40 degrees (``--imu mount=180,up=z,heading=40``).  ``rtseg calibrate`` records
the calibration from it; then four live sessions name the same performance with a library
learned from three other synthetic performers (seeds 3-5, 8 s of each behaviour):

- ``firmware tpose=1``: the suit without raw sensors, read with ``tpose=1`` (what a
  firmware that calibrates gives: the ideal);
- ``raw + calibration``: the raw suit read with ``calibration=FILE``;
- ``raw, tpose=1 declared``: the raw suit read as if T-pose relative;
- ``raw, rotations only``: the raw suit read as it is.

Printed per mode: segments of known behaviours (the live detector's), shares named right,
``unknown`` and wrong (``rtseg.evaluation.library.named_segments``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from rtseg.cli import main as rtseg_main  # noqa: E402
from rtseg.evaluation.library import named_segments  # noqa: E402
from rtseg.evaluation.online import live_config  # noqa: E402
from rtseg.library.examples import learn, synthetic_examples  # noqa: E402
from rtseg.library.file import save  # noqa: E402
from rtseg.live.config import from_dict  # noqa: E402
from rtseg.live.session import LiveSession  # noqa: E402
from rtseg.simulators.serial_device import SerialSuit  # noqa: E402
from rtseg.simulators.synth.motion import synthesize  # noqa: E402

BEHAVIOURS = ["walk", "squat", "punch", "wave", "jump", "kick"]
RATE = 120.0
IMU = "mount=180,up=z,heading=40,seed={seed}"


def run_session(perf, imu, opt: str, library: Path, speed: float) -> LiveSession:
    suit = SerialSuit(perf, rate=RATE, speed=speed, imu=imu)
    link = suit.start()
    try:
        cfg = from_dict({"output": {"osc": []},
                         "identity": {"enabled": True, "behaviours": str(library)}})
        session = LiveSession(f"serial://{link}?rate={RATE:g}{opt}", cfg, handle_signals=False,
                              duration=perf.n_frames / RATE / speed + 0.6)
        session.run()
    finally:
        suit.stop()
    return session


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 6])
    p.add_argument("--speed", type=float, default=4.0)
    args = p.parse_args(argv)
    cfg0, _ = live_config()
    lib, _ = learn(synthetic_examples(BEHAVIOURS, [3, 4, 5], cfg0, seconds=8.0))
    tmp = Path(tempfile.mkdtemp(prefix="rtseg-suitcal-"))
    library = save(lib, tmp / "lib.json")
    rows: dict[str, list] = {}
    for seed in args.seeds:
        order = np.random.default_rng(seed).permutation(BEHAVIOURS + BEHAVIOURS[:3])
        syn = synthesize("tpose:3," + ",".join(f"{b}:6" for b in order), frame_rate=RATE,
                         seed=seed)
        perf, truth = syn.take, np.array(syn.frame_names())
        imu = IMU.format(seed=seed)
        cal = tmp / f"suit{seed}.json"
        suit = SerialSuit(perf, rate=RATE, speed=args.speed, imu=imu)
        link = suit.start()
        try:
            rc = rtseg_main(["calibrate", f"serial://{link}?rate={RATE:g}", "--up", "z",
                             "--out", str(cal), "--seconds", "30"])
        finally:
            suit.stop()
        if rc:
            print(f"seed {seed}: rtseg calibrate failed ({rc})", file=sys.stderr)
            return 1
        for mode, raw, opt in (("firmware tpose=1", False, "&tpose=1"),
                               ("raw + calibration", True, f"&calibration={cal}"),
                               ("raw, tpose=1 declared", True, "&tpose=1"),
                               ("raw, rotations only", True, "")):
            s = run_session(perf, imu if raw else None, opt, library, args.speed)
            named = named_segments(SimpleNamespace(tracker=s.pipeline.identity), perf, truth,
                                   lib, f"seed{seed}")
            rows.setdefault(mode, []).extend(r for r in named if r.known)
    print(f"seeds {args.seeds}, x{args.speed:g}")
    for mode, k in rows.items():
        right = sum(r.name == r.truth for r in k)
        unk = sum(r.name == "unknown" for r in k)
        print(f"{mode:24s} segments {len(k):3d}  named right {right / len(k):.2f}  "
              f"unknown {unk / len(k):.2f}  wrong {(len(k) - right - unk) / len(k):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
