"""Blending and trimming for spliced performances (``rtseg.evaluation.splice``).

Quaternions are scalar-last (x, y, z, w) unit quaternions of *local* joint rotations,
arrays (frames, joints, 4); root positions (frames, 3) in the take's length unit; frames
0-based.  Y is the up axis (CMU BVH and ASF/AMC).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.core import quat as Q
from rtseg.core.quat import slerp  # noqa: F401  (re-exported)

UP_AXIS = 1                       #: Y is up in CMU BVH and ASF/AMC


def _angles_deg(q: np.ndarray) -> np.ndarray:
    """Rotation angle (degrees) of unit quaternions (..., 4)."""
    return 2.0 * np.degrees(np.arccos(np.clip(np.abs(q[..., 3]), 0.0, 1.0)))


def _lead_rest(pose: np.ndarray, step: np.ndarray, rest_frac: float, jump: float,
               max_trim: int) -> int:
    """Number of leading frames that are rest/constant/blend-in (see :func:`trim_bounds`)."""
    typical_pose = float(np.median(pose))
    typical_step = float(np.median(step))
    i = 0
    while i < min(max_trim, len(step)):
        rest = pose[i] < rest_frac * typical_pose
        jumpy = step[i] > jump * max(typical_step, 1e-9)
        still = step[i] < 1e-6
        if not (rest or jumpy or still):
            break
        i += 1
    return i


def trim_bounds(quats: np.ndarray, frame_rate: float, *, rest_frac: float = 0.25,
                jump: float = 5.0, max_trim_s: float = 1.0) -> tuple[int, int]:
    """Frames ``[start, stop)`` of a take left after dropping rest frames at either end.

    quats: (frames, joints, 4) local rotations; joint 0 (the root) is not looked at.
    A leading frame is dropped while it is a *rest pose* (mean joint angle from identity
    below ``rest_frac`` x the take's median: a BVH T-pose, an all-zero frame), a *jump*
    (mean joint rotation to the next frame above ``jump`` x the median frame step: the
    T-pose frame before the motion, a blend-in from a rest pose), or *constant* (identical
    to the next frame).  The same test runs backwards from the end.  At most
    ``max_trim_s`` seconds are dropped at each end.
    """
    q = np.asarray(quats, dtype=np.float64)[:, 1:] if quats.shape[1] > 1 else np.asarray(quats)
    n = q.shape[0]
    if n < 3:
        return 0, n
    pose = _angles_deg(q).mean(axis=1)
    dots = np.clip(np.abs(np.sum(q[1:] * q[:-1], axis=-1)), 0.0, 1.0)
    step = (2.0 * np.degrees(np.arccos(dots))).mean(axis=1)   # (frames - 1,) degrees
    max_trim = int(round(max_trim_s * frame_rate))
    start = _lead_rest(pose, step, rest_frac, jump, max_trim)
    end = _lead_rest(pose[::-1], step[::-1], rest_frac, jump, max_trim)
    return start, max(start + 1, n - end)


@dataclass
class Clip:
    """A stretch of motion: local rotations (F, J, 4), root positions (F, 3), and where it
    came from (``"take[start:stop]"`` pieces, source frames)."""
    quats: np.ndarray
    root: np.ndarray
    parts: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.quats.shape[0])


def smoothstep(x: np.ndarray) -> np.ndarray:
    return x * x * (3.0 - 2.0 * x)


def fade_weights(n: int) -> np.ndarray:
    """Weights of the incoming clip over an ``n``-frame fade, strictly inside (0, 1)."""
    return smoothstep(np.arange(1, n + 1) / (n + 1.0))


def _align(a: Clip, at: int, b: Clip, roots: list[int]) -> Clip:
    """``b`` turned about the up axis to ``a``'s heading at frame ``at`` and moved on the
    ground plane so that its first root position is ``a``'s there (height kept)."""
    r = roots[0]
    delta = Q.multiply(a.quats[at, r], Q.conjugate(b.quats[0, r]))
    twist = np.zeros(4)
    twist[UP_AXIS], twist[3] = delta[UP_AXIS], delta[3]
    norm = np.linalg.norm(twist)
    twist = twist / norm if norm > 1e-9 else Q.IDENTITY.copy()
    quats = b.quats.copy()
    quats[:, roots] = Q.multiply(twist, quats[:, roots])
    root = Rotation.from_quat(twist).apply(b.root - b.root[0])
    ground = [i for i in range(3) if i != UP_AXIS]
    root[:, ground] += a.root[at, ground]
    root[:, UP_AXIS] += b.root[0, UP_AXIS]
    return Clip(quats, root, list(b.parts))


def crossfade(a: Clip, b: Clip, n_fade: int, roots: list[int]) -> tuple[Clip, int]:
    """``a`` then ``b``, overlapping by ``n_fade`` frames; returns the clip and the first
    frame of the fade (``len(a) - n_fade``).  Output length ``len(a) + len(b) - n_fade``."""
    if not 0 < n_fade <= min(len(a), len(b)):
        raise ValueError(f"fade of {n_fade} frames does not fit clips of {len(a)} and {len(b)}")
    s = len(a) - n_fade
    b = _align(a, s, b, roots)
    w = fade_weights(n_fade)
    q = slerp(a.quats[s:], b.quats[:n_fade], w[:, None])
    p = (1.0 - w)[:, None] * a.root[s:] + w[:, None] * b.root[:n_fade]
    return Clip(np.concatenate([a.quats[:s], q, b.quats[n_fade:]]),
                np.concatenate([a.root[:s], p, b.root[n_fade:]]), a.parts + b.parts), s


__all__ = ["UP_AXIS", "trim_bounds", "Clip", "smoothstep", "slerp", "fade_weights", "crossfade"]
