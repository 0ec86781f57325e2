"""The posture half of a behaviour library's distance (``rtseg.library.behaviours``).

Each library window keeps a body descriptor (``body_descriptor``): the mean and standard
deviation of its posture rows (``rtseg.core.posture.window_descriptor``, in leg lengths)
and, in libraries of file version 4, each joint's median angular speed
(``rtseg.library.joint_speed``, log(1 + rad/s)) times the library's ``speed_weight``.  A
query window's posture distance to it is the Euclidean distance of the two descriptors.
When both the library and the session have posture (the rig's rest geometry is known), a
name is chosen by the weighted geometric mean of the two distances,

    D = d_model^(1 - w) x (s x d_posture)^w,   w = ``WEIGHT``,
    s = median d_model / median d_posture

over the library's own pairs of windows from different examples, so that D keeps the
model distance's scale (1 for two windows of one motion) whatever the posture's units.
The model distance tells behaviours apart by how the joints turn; the posture by where
the body is (arms up, crouched, bent to the floor), which also carries across people:
leave-one-person-out in ``docs/identity.md``.
"""

from __future__ import annotations

import math

import numpy as np

from rtseg.core.posture import DIM, window_descriptor
from rtseg.library.joint_speed import joint_speeds

#: the posture's share w of the weighted geometric mean (module doc), chosen
#: leave-one-person-out over hdm05, bandai and cmu_single among 0, 1/3, 1/2, 2/3, 0.8 and 1
#: (docs/identity.md, "Posture"): 2/3 for every held-out person with the live cuts
WEIGHT = 2.0 / 3.0


class PostureBank:
    """Posture descriptors of N library windows, (N, k)."""

    def __init__(self, descriptors: np.ndarray) -> None:
        self.descriptors = np.asarray(descriptors, dtype=np.float64)
        if self.descriptors.ndim != 2 or not len(self.descriptors):
            raise ValueError(f"posture descriptors must be (windows, k), got "
                             f"{self.descriptors.shape}")
        self._sq = np.einsum("nk,nk->n", self.descriptors, self.descriptors)
        self._pairwise: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.descriptors)

    def distances(self, q: np.ndarray) -> np.ndarray:
        """Euclidean distance of descriptor q (k,) to every window, (N,)."""
        q = np.asarray(q, dtype=np.float64)
        d2 = self._sq - 2.0 * (self.descriptors @ q) + float(q @ q)
        return np.sqrt(np.maximum(d2, 0.0))

    def pairwise(self) -> np.ndarray:
        """(N, N) distances between the windows (0 on the diagonal; computed once)."""
        if self._pairwise is None:
            D = self.descriptors
            d2 = self._sq[:, None] + self._sq[None, :] - 2.0 * (D @ D.T)
            M = np.sqrt(np.maximum(d2, 0.0))
            M = np.minimum(M, M.T)
            np.fill_diagonal(M, 0.0)
            self._pairwise = M
        return self._pairwise


def posture_scale(model: np.ndarray, posture: np.ndarray, sources: np.ndarray) -> float:
    """s of the module doc: the median model distance over the median posture distance
    of the pairs of windows (``model``, ``posture``: (N, N)) from different examples
    (``sources``: each window's example); 1 when there is no such pair."""
    src = np.asarray(sources)
    mask = src[:, None] != src[None, :]
    m = model[mask]
    p = posture[mask]
    ok = np.isfinite(m) & np.isfinite(p)
    if not ok.any():
        return 1.0
    pm = float(np.median(p[ok]))
    return float(np.median(m[ok])) / pm if pm > 0 else 1.0


def combined(d_model: np.ndarray, d_posture: np.ndarray, scale: float) -> np.ndarray:
    """D of the module doc (inf where the model distance is inf; ``scale`` is s)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        D = (np.maximum(d_model, 0.0) ** (1.0 - WEIGHT)
             * (np.maximum(d_posture, 0.0) * scale) ** WEIGHT)
    return np.where(np.isfinite(d_model), D, math.inf)


def body_descriptor(P: np.ndarray, W: np.ndarray, frame_rate: float,
                    speed_weight: float) -> np.ndarray:
    """The descriptor of one window (module doc): posture rows P (frames, ``DIM``) and the
    same frames' feature rows W (frames, dims) at ``frame_rate`` Hz; the joint speeds are
    left out when ``speed_weight`` is 0 (libraries of file version 3)."""
    d = window_descriptor(P)
    if not speed_weight:
        return d
    W = np.asarray(W, dtype=np.float64)
    speeds = (joint_speeds(W, frame_rate) if len(W) >= 2    # one frame: no turn to measure
              else np.zeros(W.shape[-1] // 4))
    return np.concatenate([d, speed_weight * speeds])


def reweighted(descriptors: np.ndarray, weight: float, new_weight: float) -> np.ndarray:
    """Body descriptors (N, k) made with joint-speed ``weight`` as ``new_weight`` would
    make them (0: posture alone); ``new_weight`` must not exceed a nonzero ``weight``."""
    D = np.asarray(descriptors, dtype=np.float64)
    if new_weight == weight:
        return D
    if not new_weight:
        return D[:, :2 * DIM]
    if not weight:
        raise ValueError("descriptors without joint speeds cannot be given them")
    return np.concatenate([D[:, :2 * DIM], D[:, 2 * DIM:] * (new_weight / weight)], axis=1)
