"""Vectorised quaternion helpers.  All quaternions scalar-last (x, y, z, w), float64.

Thin wrappers over ``scipy.spatial.transform.Rotation`` where SciPy does the job, plus the
operations SciPy does not offer (sign continuity over time, Euler chains with arbitrary
axis strings).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions along the last axis; zero-norm rows become identity."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    out = np.where(n > 0, q / np.where(n > 0, n, 1.0), IDENTITY)
    return out


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a ⊗ b (broadcasting), scalar-last."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse of unit quaternions."""
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([-1.0, -1.0, -1.0, 1.0])


def make_continuous(q: np.ndarray, axis: int = 0) -> np.ndarray:
    """Flip signs so that consecutive quaternions along ``axis`` have a non-negative dot.

    q and -q are the same rotation; without this PCA sees jumps that are not motion.
    Works on (frames, ..., 4) arrays, vectorised over everything but ``axis``.
    """
    q = np.array(q, dtype=np.float64, copy=True)
    q = np.moveaxis(q, axis, 0)
    if q.shape[0] > 1:
        dots = np.sum(q[1:] * q[:-1], axis=-1)
        flips = np.cumsum(dots < 0, axis=0) % 2
        sign = np.ones(q.shape[:-1])
        sign[1:] = np.where(flips == 1, -1.0, 1.0)
        q *= sign[..., None]
    return np.moveaxis(q, 0, axis)


def local_from_global(global_q: np.ndarray, parents: list[int]) -> np.ndarray:
    """Parent-relative rotations q_parent⁻¹ ⊗ q_child from global orientations.

    ``global_q``: (..., joints, 4).  Roots (parent -1) keep their global rotation.
    """
    global_q = np.asarray(global_q, dtype=np.float64)
    par = np.asarray(parents)
    parent_q = np.where((par >= 0)[:, None], global_q[..., np.maximum(par, 0), :], IDENTITY)
    return multiply(conjugate(parent_q), global_q)


def global_from_local(local_q: np.ndarray, parents: list[int]) -> np.ndarray:
    """Forward kinematics of rotations: global = global_parent ⊗ local (parents before children)."""
    local_q = np.asarray(local_q, dtype=np.float64)
    out = np.empty_like(local_q)
    for j, p in enumerate(parents):
        if p < 0:
            out[..., j, :] = local_q[..., j, :]
        else:
            if p >= j:
                raise ValueError("parents must come before children")
            out[..., j, :] = multiply(out[..., p, :], local_q[..., j, :])
    return out


def from_euler(axes: str, angles: np.ndarray, degrees: bool = True) -> np.ndarray:
    """Quaternions for intrinsic rotations applied in ``axes`` order (e.g. "ZYX").

    ``angles[..., k]`` is the angle about ``axes[k]``.  The result is
    R = R_axes[0] · R_axes[1] · ... (rotation matrices multiplied left to right), which is
    what BVH channel order and ASF/AMC's M = Rz·Ry·Rx (axes "ZYX") mean.
    """
    angles = np.asarray(angles, dtype=np.float64)
    shape = angles.shape[:-1]
    if not axes:
        return np.broadcast_to(IDENTITY, shape + (4,)).copy()
    rot = Rotation.from_euler(axes.upper(), angles.reshape(-1, len(axes)), degrees=degrees)
    return rot.as_quat().reshape(shape + (4,))


def slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per-element quaternion slerp, shortest path; q0, q1 (..., 4), w broadcast to (...)."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where((dot < 0)[..., None], -q1, q1)
    dot = np.clip(np.abs(dot), 0.0, 1.0)
    theta = np.arccos(dot)
    s = np.sin(theta)
    small = s < 1e-8
    safe = np.where(small, 1.0, s)
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    b = np.where(small, w, np.sin(w * theta) / safe)
    return normalize(a[..., None] * q0 + b[..., None] * q1)
