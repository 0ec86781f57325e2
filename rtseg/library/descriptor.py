"""The descriptor distance of version-1 behaviour libraries (``metric = "descriptor"``,
``rtseg.library.behaviours``): a hand-made descriptor of a window of pose-feature rows,
compared after standardising each dim by the library's ``scale``.

Descriptor of a window W (frames, 4J) of pose-feature rows (unit quaternions per joint,
frame rate ``fr`` Hz), three groups, all logarithms:

- ``spread`` (J): per joint log(sqrt(sum of the 4 components' variances) + 0.01) - about
  half the joint's angular spread in rad; unchanged by any fixed rotation before or after
  the joint's rotation (rest pose, axis conventions);
- ``speed`` (J): per joint log(mean |q[t+1] - q[t]| x fr + 0.05) - about half its mean
  angular speed in rad/s; unchanged by the same fixed rotations;
- ``dims`` (4J): per feature dim log(std + 0.005) - which axes each joint moves about.

Descriptor distance between a query q and an example e: each dim standardised by the
library's ``scale`` (per-dim std over all its windows, floored at ``SCALE_FLOOR``), then
``sqrt(mean over groups of mean over the group's dims of z^2)``.
"""

from __future__ import annotations

import numpy as np

#: the descriptor's groups, in order
GROUPS = ("spread", "speed", "dims")
#: the floor under a library's per-dim scale
SCALE_FLOOR = 0.05
#: a name's distance under the descriptor: the mean of its k nearest windows'
K_NEAREST = 3


def descriptor(W: np.ndarray, frame_rate: float) -> np.ndarray:
    """Descriptor (6J,) of a window W (frames >= 2, 4J) of feature rows (module doc):
    spread (J), speed (J), dims (4J) concatenated."""
    W = np.asarray(W, dtype=np.float64)
    n, d = W.shape
    if n < 2 or d % 4:
        raise ValueError(f"a descriptor needs >= 2 frames of 4J features, got {W.shape}")
    J = d // 4
    var = W.var(axis=0)
    spread = np.log(np.sqrt(var.reshape(J, 4).sum(axis=1)) + 0.01)
    step = np.linalg.norm(np.diff(W, axis=0).reshape(n - 1, J, 4), axis=2)
    speed = np.log(step.mean(axis=0) * float(frame_rate) + 0.05)
    dims = np.log(np.sqrt(var) + 0.005)
    return np.concatenate([spread, speed, dims])


def group_slices(dims: int) -> list[slice]:
    """Slices of the descriptor groups for ``dims`` feature dims (4J)."""
    J = dims // 4
    return [slice(0, J), slice(J, 2 * J), slice(2 * J, 6 * J)]
