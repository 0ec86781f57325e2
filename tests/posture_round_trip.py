"""Shared by the rig-geometry tests of the live sources (VMC, mocopi, Axis, MVN): a take
with rest geometry sent by a simulator over real UDP on 127.0.0.1 and read back by the
source, and how far the posture of what came back lies from the take's own."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from rtseg.core.posture import Posture, take_posture

from test_library_posture import swing
from test_vmc_live import read_all


def posture_back(source: Any, sender: Callable[[Any, int], Any], seconds: float = 3.0
                 ) -> tuple[int, int, Any, float]:
    """Send a swing take (``sender(take, port)``, used as a context manager) to ``source``
    (closed here) and read it back: (frames read, frames sent, the source's
    ``rest_pose``, the largest difference, leg lengths, between the posture rows of the
    frames read - by that rest pose - and the take's)."""
    take = swing(80.0, 3, seconds=seconds)
    try:
        with sender(take, source.port) as snd:
            snd.wait(10.0)
        frames = read_all(source)
        rest = source.rest_pose
    finally:
        source.close()
    if rest is None or not frames:
        return len(frames), take.n_frames, rest, float("inf")
    rows = Posture(source.joint_names, source.parents, rest, source.space).transform(
        np.stack([f.quats for f in frames]))
    ref = take_posture(take)[[f.seq for f in frames]]
    return len(frames), take.n_frames, rest, float(np.abs(rows - ref).max())
