"""Speed of the pose-feature extractor: PoseFeatures.step (live loop) and .transform (batch).

    python3 benchmarks/bench_features.py [--frames 20000]

Uses random rotations on the 17-sensor suit (global space, unity profile: 12 joints) and
on a local-space rig with a calibration frame, and the CMU skeleton (31 joints, cmu14).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.core.features import PoseFeatures
from rtseg.core.profiles import suit_profile


def bench_step(pf: PoseFeatures, frames: np.ndarray, calibrate: bool) -> tuple[float, float]:
    """(frames per wall second, frames per CPU second of this process)."""
    if calibrate:
        pf.calibrate(frames[0])
    pf.reset()
    t0, c0 = time.perf_counter(), time.process_time()
    for f in frames:
        pf.step(f)
    return len(frames) / (time.perf_counter() - t0), len(frames) / (time.process_time() - c0)


def bench_transform(pf: PoseFeatures, frames: np.ndarray) -> float:
    t0 = time.perf_counter()
    pf.transform(frames)
    return len(frames) / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=20000)
    args = ap.parse_args()
    suit = suit_profile("default17")
    J = len(suit.bones)
    frames = Rotation.random(args.frames * J, random_state=0).as_quat().reshape(args.frames, J, 4)
    cmu_names = ["root", "lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes", "rhipjoint", "rfemur",
                 "rtibia", "rfoot", "rtoes", "lowerback", "upperback", "thorax", "lowerneck",
                 "upperneck", "head", "lclavicle", "lhumerus", "lradius", "lwrist", "lhand",
                 "lfingers", "lthumb", "rclavicle", "rhumerus", "rradius", "rwrist", "rhand",
                 "rfingers", "rthumb"]
    cmu_parents = [-1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14, 15, 13, 17, 18, 19, 20,
                   21, 20, 13, 24, 25, 26, 27, 28, 27]
    cmu_frames = Rotation.random(args.frames * 31, random_state=1).as_quat().reshape(args.frames, 31, 4)
    cases = [
        ("suit17 global  (unity, 12 joints)", PoseFeatures(suit.bones, suit.parents, "global"), frames, False),
        ("suit17 global+calibration       ", PoseFeatures(suit.bones, suit.parents, "global"), frames, True),
        ("suit17 local+calibration (VMC)  ", PoseFeatures(suit.bones, suit.parents, "local"), frames, True),
        ("suit17 global  all 17 joints    ", PoseFeatures(suit.bones, suit.parents, "global", "all"), frames, False),
        ("cmu31 local    (cmu14)          ", PoseFeatures(cmu_names, cmu_parents, "local"), cmu_frames, False),
        ("cmu31 global   (cmu14, axis fr.)", PoseFeatures(cmu_names, cmu_parents, "global",
                                                          axis_quats=Rotation.random(31, random_state=2).as_quat()),
         cmu_frames, False),
    ]
    print(f"{args.frames} frames per case; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cpus")
    for name, pf, fr, cal in cases:
        s, sc = bench_step(pf, fr, cal)
        b = bench_transform(pf, fr)
        print(f"{name}  step {s:8.0f} frames/s (cpu {sc:8.0f})   transform {b:10.0f} frames/s")


if __name__ == "__main__":
    main()
