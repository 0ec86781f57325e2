"""A take at another frame rate: the same motion, sampled at ``rate`` frames per second.

Output frame k lies at time k / rate seconds; its rotations are the slerp (shortest path,
per joint) of the two input frames around that time, its root position their linear
interpolation; ``valid`` (when present) is the logical AND of the two.  The last output
frame is the last one at or before the input's last frame time, so no frame is
extrapolated.  Used to check that detectors cut alike at 30, 60, 90 and 120 fps.
"""

from __future__ import annotations

import numpy as np

from rtseg.core.quat import make_continuous, slerp
from rtseg.core.take import Take

__all__ = ["resample_take"]


def resample_take(take: Take, rate: float) -> Take:
    """``take`` resampled to ``rate`` Hz (module docstring); meta gains ``resampled_from``."""
    if not rate > 0:
        raise ValueError(f"rate must be positive, got {rate}")
    n = take.n_frames
    if n == 0:
        raise ValueError("cannot resample an empty take")
    duration = (n - 1) / take.frame_rate
    m = int(np.floor(duration * rate + 1e-9)) + 1
    pos = np.arange(m) * (take.frame_rate / rate)          # input frame position of each output
    lo = np.minimum(np.floor(pos).astype(np.int64), n - 1)
    hi = np.minimum(lo + 1, n - 1)
    w = (pos - lo)[:, None]
    q = make_continuous(take.quats, axis=0)
    quats = slerp(q[lo], q[hi], np.broadcast_to(w, q[lo].shape[:2]))
    root = None
    if take.root_position is not None:
        root = (1.0 - w) * take.root_position[lo] + w * take.root_position[hi]
    valid = None if take.valid is None else take.valid[lo] & take.valid[hi]
    meta = dict(take.meta)
    meta["resampled_from"] = float(take.frame_rate)
    return Take(list(take.joint_names), list(take.parents), float(rate), quats, root, take.space,
                valid, take.length_unit, take.source, meta)
