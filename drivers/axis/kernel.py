"""The optional compiled kernel of the Axis decoder's pose maths (``_axis_kernel``, built
from ``drivers/axis/_axis_kernel.c`` at install when a C compiler is there), behind numpy-shaped
calls.

For one frame the numpy path of :mod:`rtseg.drivers.axis.pose` (Euler terms, then pointer
jumping) is about twenty numpy calls at their per-call floor, ~24 µs of a text frame's
~52; the kernel does the same arithmetic in a loop, ~2 µs.  Its local quaternions are
numpy's bit for bit (the same products, summed as numpy's matmul sums them); its global
ones compose joint by joint and so differ from the pointer jumping's in the last bits
(within 1e-15; the same float32 values in ``tests/test_axis.py``).  Every path of
``rtseg.drivers.axis.pose`` uses one or the other, so a frame alone and in a batch stay bit-identical.

``ENABLED`` is True when the module was built, unless the environment variable
``RTSEG_NO_KERNEL`` is set to anything but ``0`` or empty (tests and
``benchmarks/decode.py --no-kernel`` compare the two paths).  Quaternions are float64,
scalar-last; a joint's parent precedes it.
"""

from __future__ import annotations

import os

import numpy as np

try:
    from rtseg.drivers.axis import _axis_kernel as _C
except ImportError:          # not built (no compiler at install): the pose maths use numpy
    _C = None

#: the kernel is built
AVAILABLE = _C is not None
#: rtseg.drivers.axis.pose calls the kernel (read at each call; tests switch it)
ENABLED = AVAILABLE and os.environ.get("RTSEG_NO_KERNEL", "") in ("", "0")

_PARENTS: dict[tuple[int, ...], np.ndarray] = {}


def _parents(parents: tuple[int, ...]) -> np.ndarray:
    """``parents`` as the kernel's int64 buffer (kept per tuple; the kernel checks that
    each is -1 or precedes its joint, ValueError otherwise)."""
    arr = _PARENTS.get(parents)
    if arr is None:
        arr = _PARENTS[parents] = np.array(parents, dtype=np.int64)
    return arr


def fk(local: np.ndarray, parents: tuple[int, ...]) -> np.ndarray:
    """(..., J, 4) parent-relative quaternions -> (..., J, 4) global ones
    (global_j = global_parent ⊗ local_j)."""
    local = np.ascontiguousarray(local, dtype=np.float64)
    J = len(parents)
    if local.shape[-2:] != (J, 4):
        raise ValueError(f"local quaternions must be (..., {J}, 4), got {local.shape}")
    out = np.empty(local.shape)
    _C.fk(local, 4, 4 * J, _parents(parents), out)
    return out


def euler_fk(u: np.ndarray, per_frame: int, axes: tuple[int, int, int, float],
             parents: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Local and global quaternions, each (F, J, 4), from ``u`` (6, F x per_frame): the
    cosines then the sines of the half angles of each joint's three Euler angles (rows
    cos a, cos b, cos c, sin a, sin b, sin c), ``per_frame`` triples a frame of which the
    first J = len(parents) are its joints.  ``axes``: the order's axes (0 x, 1 y, 2 z)
    and its parity (+1.0 for a cyclic order, else -1.0)."""
    J = len(parents)
    F = u.shape[1] // per_frame
    loc = np.empty((F, J, 4))
    glob = np.empty((F, J, 4))
    a, b, c, eps = axes
    _C.euler_fk(u, per_frame, a, b, c, eps, _parents(parents), loc, glob)
    return loc, glob


__all__ = ["AVAILABLE", "ENABLED", "fk", "euler_fk"]
