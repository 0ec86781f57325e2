"""Noitom Axis Neuron's skeleton and its pose maths: the 59 BVH joints and their hierarchy,
Euler angles -> quaternions, forward kinematics, and a frame's values -> poses (no bytes:
:mod:`rtseg.drivers.axis.codec` decodes those and re-exports the public names here).

Frames and conventions: BVH's right-handed Y-up world; a joint's rotation is relative to its
parent (``space = "local"``) and is R = R_a(angle0) R_b(angle1) R_c(angle2) for order "abc"
(intrinsic, as :mod:`rtseg.drivers.readers.bvh` reads BVH channels), angles in degrees;
quaternions float64 scalar-last; global orientations are products down the hierarchy
(global_j = global_parent (x) local_j).  A frame's values: with displacement 6 channels per
joint (position x y z in cm, then the three angles), without it the root position then 3
angles per joint; with reference, 6 more values first (the layouts of
:mod:`rtseg.drivers.axis.codec`).  Root positions come back in metres (``unit_scale`` 0.01
per cm).  With the optional compiled kernel (:mod:`rtseg.drivers.axis.kernel`) the same
values come from C, bit for bit in local space.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rtseg.core.posture import RestPose
from rtseg.drivers.axis import kernel as axis_kernel

__all__ = ["JOINTS", "PARENTS", "euler_to_quat", "quat_to_euler", "global_pose", "poses",
           "to_poses", "to_pose", "rest_pose"]

#: Axis Neuron's 59 BVH joints, in stream order (parents before children).
JOINTS: tuple[str, ...] = (
    "Hips", "RightUpLeg", "RightLeg", "RightFoot", "LeftUpLeg", "LeftLeg", "LeftFoot",
    "Spine", "Spine1", "Spine2", "Spine3", "Neck", "Head",
    *(f"{s}{j}" for s in ("Right", "Left") for j in (
        "Shoulder", "Arm", "ForeArm", "Hand", "HandThumb1", "HandThumb2", "HandThumb3",
        "InHandIndex", "HandIndex1", "HandIndex2", "HandIndex3",
        "InHandMiddle", "HandMiddle1", "HandMiddle2", "HandMiddle3",
        "InHandRing", "HandRing1", "HandRing2", "HandRing3",
        "InHandPinky", "HandPinky1", "HandPinky2", "HandPinky3")),
)


def _parents() -> tuple[int, ...]:
    idx = {n: i for i, n in enumerate(JOINTS)}
    par = {"Hips": None, "RightUpLeg": "Hips", "RightLeg": "RightUpLeg",
           "RightFoot": "RightLeg", "LeftUpLeg": "Hips", "LeftLeg": "LeftUpLeg",
           "LeftFoot": "LeftLeg", "Spine": "Hips", "Spine1": "Spine", "Spine2": "Spine1",
           "Spine3": "Spine2", "Neck": "Spine3", "Head": "Neck"}
    for s in ("Right", "Left"):
        par.update({f"{s}Shoulder": "Spine3", f"{s}Arm": f"{s}Shoulder",
                    f"{s}ForeArm": f"{s}Arm", f"{s}Hand": f"{s}ForeArm",
                    f"{s}HandThumb1": f"{s}Hand", f"{s}HandThumb2": f"{s}HandThumb1",
                    f"{s}HandThumb3": f"{s}HandThumb2"})
        for f in ("Index", "Middle", "Ring", "Pinky"):
            par.update({f"{s}InHand{f}": f"{s}Hand", f"{s}Hand{f}1": f"{s}InHand{f}",
                        f"{s}Hand{f}2": f"{s}Hand{f}1", f"{s}Hand{f}3": f"{s}Hand{f}2"})
    return tuple(-1 if par[n] is None else idx[par[n]] for n in JOINTS)


#: parent index of each of :data:`JOINTS`
PARENTS: tuple[int, ...] = _parents()
_ALL_VALID = np.ones(len(JOINTS), dtype=bool)


# --------------------------------------------------------------------------- rotations

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _check_order(order: str) -> str:
    o = order.upper()
    if len(o) != 3 or set(o) != {"X", "Y", "Z"}:
        raise ValueError(f"Euler order must be a permutation of XYZ, got {order!r}")
    return o


#: half-angle radians per degree
_HALF_RAD = np.pi / 360.0
_EULER_TABLES: dict[str, tuple[np.ndarray, np.ndarray]] = {}
_ORDER_AXES: dict[str, tuple[int, int, int, float]] = {}


def _order_axes(order: str) -> tuple[int, int, int, float]:
    """(a, b, c, parity) of ``order`` = "abc" (axes 0 x, 1 y, 2 z; parity eps +1.0 when the
    order is cyclic, else -1.0)."""
    hit = _ORDER_AXES.get(order)
    if hit is None:
        a, b, c = (_AXIS[x] for x in _check_order(order))
        e = 1.0 if (a, b, c) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
        hit = _ORDER_AXES[order] = (a, b, c, e)
    return hit


def _euler_tables(order: str) -> tuple[np.ndarray, np.ndarray]:
    """(T (8, 4), T4 (8, 16)) of ``order`` = "abc": the 8 products u_a[i] u_b[j] u_c[k] of
    the half-angle (cos, sin) pairs of its three angles (term (2i + j) 2 + k) -> the
    quaternion's x, y, z, w (T), and the same repeated 4 times (T4: :func:`_fk`'s tiled
    form).  Each column has two +-1 entries, so ``terms.T @ T`` is the closed form of
    :func:`euler_to_quat` rounded the same way."""
    hit = _EULER_TABLES.get(order)
    if hit is not None:
        return hit
    a, b, c, e = _order_axes(order)
    T = np.zeros((8, 4))
    T[0, 3], T[7, 3] = 1.0, -e          # w = ca cb cc - eps sa sb sc
    T[4, a], T[3, a] = 1.0, e           # a = sa cb cc + eps ca sb sc
    T[2, b], T[5, b] = 1.0, -e          # b = ca sb cc - eps sa cb sc
    T[1, c], T[6, c] = 1.0, e           # c = ca cb sc + eps sa sb cc
    hit = _EULER_TABLES[order] = (T, np.tile(T, (1, 4)))
    return hit


def _euler_terms(angles: np.ndarray, identity_row: bool = False) -> np.ndarray:
    """(..., 3) degrees (the order's three angles) -> (8, N) products of the half-angle
    cosines and sines of the N triples (see :func:`_euler_tables`); see
    :func:`_half_angles`."""
    return _half_terms(_half_angles(angles, identity_row))


def _half_angles(angles: np.ndarray, identity_row: bool = False) -> np.ndarray:
    """(..., 3) degrees (the order's three angles) -> (3, N) half angles in radians,
    triples along the last axis (long contiguous loops: the numpy calls cost about the same
    for 1 frame or 100).
    ``identity_row``: ``angles`` is (..., J, 3) and each group of J gets a triple of zero
    angles after it (the identity, which :func:`global_pose`'s pointer jumping uses as
    'no ancestor'): N = (J + 1) x the groups."""
    ang = np.asarray(angles, dtype=np.float64)
    if identity_row:
        ang = ang.reshape(-1, ang.shape[-2], 3)                  # (F, J, 3)
        half = np.empty((3, ang.shape[0], ang.shape[1] + 1))
        np.multiply(ang.transpose(2, 0, 1), _HALF_RAD, out=half[:, :, :-1])
        half[:, :, -1] = 0.0
        half = half.reshape(3, -1)
    else:
        ang = ang.reshape(-1, 3)
        half = np.multiply(ang.T, _HALF_RAD, order="C")
    return half


#: rows of _half_terms' (6, N) cosines and sines (cos a, cos b, cos c, sin a, sin b, sin c):
#: the pairs ca cb, ca sb, sa cb, sa sb, then each pair times cc and sc
_PAIR_A = np.array([0, 0, 3, 3], dtype=np.intp)
_PAIR_B = np.array([1, 4, 1, 4], dtype=np.intp)
_TERM_PAIR = np.repeat(np.arange(4, dtype=np.intp), 2)
_TERM_C = np.tile(np.array([2, 5], dtype=np.intp), 4)


def _cos_sin(half: np.ndarray) -> np.ndarray:
    """(3, N) half angles (radians) -> (6, N): their cosines, then their sines."""
    u = np.empty((6, half.shape[1]))
    np.cos(half, out=u[:3])
    np.sin(half, out=u[3:])
    return u


def _half_terms(half: np.ndarray) -> np.ndarray:
    """(3, N) half angles (radians) -> (8, N) products of their cosines and sines (rows
    gathered with take: cheaper than broadcasting's small outer loops)."""
    u = _cos_sin(half)
    p = u.take(_PAIR_A, axis=0)
    p *= u.take(_PAIR_B, axis=0)                      # (4, N): ca cb, ca sb, sa cb, sa sb
    t = p.take(_TERM_PAIR, axis=0)
    t *= u.take(_TERM_C, axis=0)
    return t


def euler_to_quat(order: str, angles: np.ndarray) -> np.ndarray:
    """(..., 3) angles in degrees about ``order``'s axes -> (..., 4) scalar-last quaternions
    of R = R_order[0] R_order[1] R_order[2] (intrinsic; = ``rtseg.core.quat.from_euler``).

    Closed form of e_a(alpha) * e_b(beta) * e_c(gamma) for a permutation (a, b, c) of the
    axes with parity eps (+1 cyclic): w = ca cb cc - eps sa sb sc, a = sa cb cc + eps ca sb
    sc, b = ca sb cc - eps sa cb sc, c = ca cb sc + eps sa sb cc (half-angle sines/cosines):
    the 8 products of one (cos, sin) per axis, then one matrix product with +-1 / 0
    coefficients (exact: each component is the rounded sum of its two products), a few
    numpy calls whatever the batch."""
    angles = np.asarray(angles, dtype=np.float64)
    q = _euler_terms(angles).T @ _euler_tables(order)[0]
    return q.reshape(angles.shape[:-1] + (4,))


def quat_to_euler(order: str, q: np.ndarray) -> np.ndarray:
    """Inverse of :func:`euler_to_quat`: (..., 4) -> (..., 3) degrees."""
    from scipy.spatial.transform import Rotation
    o = _check_order(order)
    q = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat(q.reshape(-1, 4)).as_euler(o, degrees=True).reshape(
        q.shape[:-1] + (3,))


def _ancestor_tables(parents: tuple[int, ...]) -> list[np.ndarray]:
    """Pointer-jumping tables over ``parents``: table r gives each joint's 2^r-th ancestor
    (row J, the identity, stands for 'none'), as many tables as the hierarchy needs."""
    J = len(parents)
    anc = np.array([J if p < 0 else p for p in parents] + [J], dtype=np.intp)
    links = 1 + max(_depth(parents, j) for j in range(J))       # longest root..leaf chain
    tables = []
    while (1 << len(tables)) < links:
        tables.append(anc)
        anc = anc[anc]
    return tables


def _depth(parents: tuple[int, ...], j: int) -> int:
    d = 0
    while parents[j] >= 0:
        d, j = d + 1, parents[j]
    return d


#: a ⊗ b = L(a) b for scalar-last quaternions, L[r, c] = _L_SIGN[r, c] * a[_L_INDEX[r, c]]
#: (rows: x, y, z, w of the product)
_L_INDEX = np.array([[3, 2, 1, 0], [2, 3, 0, 1], [1, 0, 3, 2], [0, 1, 2, 3]], dtype=np.intp)
_L_SIGN = np.array([[1.0, -1.0, 1.0, 1.0], [1.0, 1.0, -1.0, 1.0], [-1.0, 1.0, 1.0, 1.0],
                    [-1.0, -1.0, -1.0, 1.0]])


def _hamilton_table() -> np.ndarray:
    """H (16, 4): (a ⊗ b)[r] = sum over i, k of a[i] b[k] H[4 i + k, r] (:data:`_L_INDEX`
    and :data:`_L_SIGN` rearranged; each column: four +-1 entries, the rest 0)."""
    H = np.zeros((16, 4))
    for r in range(4):
        for c in range(4):
            H[4 * _L_INDEX[r, c] + c, r] = _L_SIGN[r, c]
    return H


_HAMILTON = _hamilton_table()


#: (16, 16): the Hamilton table with its 4 columns repeated 4 times, so a product comes
#: out in :func:`_fk`'s tiled form (column 4 m + k: component k)
_HAMILTON_TILED = np.tile(_HAMILTON, (1, 4))


def _fk_tables(parents: tuple[int, ...]) -> list[np.ndarray]:
    """Per pointer-jumping round of :func:`_fk`, (J + 1, 16) indices into a frame's flat
    tiled quaternions (J + 1, 16) (row J the identity): column 4 i + k of joint j takes
    component i of j's current ancestor (its tiled row's column i)."""
    comp = np.arange(16) // 4
    return [(anc[:, None] * 16 + comp).astype(np.intp) for anc in _ancestor_tables(parents)]


_FK_ANCESTOR = _fk_tables(PARENTS)
_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def global_pose(local: np.ndarray) -> np.ndarray:
    """(..., 59, 4) parent-relative rotations -> global orientations (forward kinematics
    over the Axis hierarchy, global_j = global_parent ⊗ local_j; scalar-last float64).
    See :func:`_fk` (equal to joint-by-joint products to a few ulp), or the compiled
    kernel's joint-by-joint products (:mod:`rtseg.drivers.axis.kernel`)."""
    local = np.asarray(local, dtype=np.float64)
    if axis_kernel.ENABLED:
        return axis_kernel.fk(local, PARENTS)
    lead, J = local.shape[:-2], local.shape[-2]
    q = np.empty(lead + (J + 1, 4))
    q[..., :J, :] = local
    q[..., J, :] = _IDENTITY
    return _fk(np.tile(q, 4))


def _fk(x: np.ndarray) -> np.ndarray:
    """(..., J + 1, 16) local quaternions tiled (column 4 m + k: component k; row J the
    identity) -> (..., J, 4) global ones.

    Pointer jumping on the quaternions, vectorised over all joints (and frames): after
    round r each joint holds the product of the 2^r links ending at it (the identity,
    row J, stands for 'no ancestor'), so the 13-link chains take 4 rounds.  A round is the
    Hamilton product of every joint's ancestor a and itself b: one gather puts a[i] at
    column 4 i + k next to the tiled b[k], one multiply makes the 16 products, one
    (J + 1, 16) @ (16, 16) matrix product per frame with the +-1 table
    :data:`_HAMILTON_TILED` sums them (each component the sum of 4 exact products) back
    into the tiled form.  Per frame, not one product over all frames: BLAS sums a large
    product in another order, and a frame must come out the same alone or in a batch.
    The 4x4 left-product matrix form (the tests' reference) differs in the last bits only."""
    flat = x.shape[:-2] + (-1,)
    for anc in _FK_ANCESTOR:
        p = x.reshape(flat).take(anc, axis=-1)
        p *= x
        x = p @ _HAMILTON_TILED
    return x[..., :-1, :4]


def _channels(values: np.ndarray, with_disp: bool, with_ref: bool, joints: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """(root position (..., 3) as sent, angles (..., joints, 3) degrees): views of
    ``values`` (..., count)."""
    v = values[..., 6:] if with_ref else values
    lead = v.shape[:-1]
    if with_disp:
        ch = v.reshape(lead + (joints, 6))
        return ch[..., 0, :3], ch[..., :, 3:]
    return v[..., :3], v[..., 3:].reshape(lead + (joints, 3))


_ANGLE_INDEX: dict[tuple[bool, bool, int], np.ndarray] = {}


def _angle_index(with_disp: bool, with_ref: bool, joints: int) -> np.ndarray:
    """(3, joints + 1): where each joint's three angles are in a frame's values; the last
    column (any index: its values are overwritten with the identity's zero angles) makes
    room for :func:`global_pose`'s identity row."""
    key = (with_disp, with_ref, joints)
    idx = _ANGLE_INDEX.get(key)
    if idx is None:
        j = np.arange(joints + 1)
        first = (6 if with_ref else 0) + (6 * j + 3 if with_disp else 3 + 3 * j)
        first[-1] = 0
        idx = _ANGLE_INDEX[key] = first[None, :] + np.arange(3)[:, None]
    return idx


def poses(values: np.ndarray, with_disp: bool, with_ref: bool, order: str = "YXZ",
          unit_scale: float = 0.01, space: str = "local", joints: int = len(JOINTS)
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames of one layout, all values finite: ``values`` (..., count) -> (quats (...,
    joints, 4) in ``space``, local quats (..., joints, 4), root positions (..., 3) metres).

    ``space="global"`` (59 Axis joints only) builds the local quaternions straight from the
    Euler angles' half-angle products (one matrix product with the order's +-1 table,
    :func:`_euler_tables`, tiled 4 times), with an identity row after each frame's joints,
    and runs :func:`_fk`'s pointer jumping on them: the same values as
    ``global_pose(euler_to_quat(...))``, about twenty numpy calls per batch.  Local quats
    come back as a view when ``space="global"``.  With the compiled kernel
    (:mod:`rtseg.drivers.axis.kernel`, 59 joints, either space) the half-angle cosines
    and sines go to it and it does the rest (the same local quaternions, global ones joint
    by joint)."""
    T, T4 = _euler_tables(order)
    if joints == len(JOINTS) and axis_kernel.ENABLED:
        r = 6 if with_ref else 0
        if values.ndim == 1:
            half = values.take(_angle_index(with_disp, with_ref, joints)[:, :-1])  # (3, J)
            np.multiply(half, _HALF_RAD, out=half)
        else:
            half = _half_angles(_channels(values, with_disp, with_ref, joints)[1])
        loc, glob = axis_kernel.euler_fk(_cos_sin(half), joints, _order_axes(order), PARENTS)
        shape = values.shape[:-1] + (joints, 4)
        loc = loc.reshape(shape)
        return (loc if space == "local" else glob.reshape(shape), loc,
                values[..., r:r + 3] * unit_scale)
    if values.ndim == 1 and space == "global" and joints == len(JOINTS):
        # one frame (the live case): the angles in one gather, contiguous, the identity's
        # zero angles in the last column
        half = values.take(_angle_index(with_disp, with_ref, joints))     # (3, J + 1)
        np.multiply(half, _HALF_RAD, out=half)
        half[:, -1] = 0.0
        x = _half_terms(half).T @ T4                          # (J + 1, 16) tiled
        r = 6 if with_ref else 0
        return _fk(x), x[:-1, :4], values[r:r + 3] * unit_scale
    root, angles = _channels(values, with_disp, with_ref, joints)
    lead = angles.shape[:-1]
    if space == "local":
        q = (_euler_terms(angles).T @ T).reshape(lead + (4,))
        return q, q, root * unit_scale
    if joints != len(JOINTS):
        raise ValueError(f"space=global needs the {len(JOINTS)} Axis joints, got {joints}")
    t = _euler_terms(angles, identity_row=True)         # (8, F (J + 1))
    x = (t.T @ T4).reshape(lead[:-1] + (joints + 1, 16))  # locals tiled, the identity
    return _fk(x), x[..., :-1, :4], root * unit_scale


def to_poses(values: np.ndarray, with_disp: bool, with_ref: bool, order: str = "YXZ",
             unit_scale: float = 0.01, joints: int = len(JOINTS)
             ) -> tuple[np.ndarray, np.ndarray]:
    """Frames of one layout at once: ``values`` (F, count), all finite -> (local quats
    (F, joints, 4), root positions (F, 3) metres).  Same values as :func:`to_pose` per
    frame (which handles non-finite values)."""
    q, _, root = poses(values, with_disp, with_ref, order, unit_scale, "local", joints)
    return q, root


def to_pose(frame: Any, order: str = "YXZ", unit_scale: float = 0.01,
            joints: int = len(JOINTS)) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(quats (joints, 4) local, valid (joints,), root position (3,) metres or None) of a
    decoded frame (:class:`~rtseg.drivers.axis.codec.AxisFrame`: its ``values``,
    ``with_disp`` and ``with_ref``)."""
    root, angles = _channels(frame.values, frame.with_disp, frame.with_ref, joints)
    if np.isfinite(frame.values[6:] if frame.with_ref else frame.values).all():
        valid = _ALL_VALID.copy() if joints == len(JOINTS) else np.ones(joints, dtype=bool)
        return euler_to_quat(order, angles), valid, root * unit_scale
    valid = np.isfinite(angles).all(axis=1)
    q = euler_to_quat(order, np.where(valid[:, None], angles, 0.0))
    pos = root * unit_scale if np.isfinite(root).all() else None
    return q, valid, pos


def rest_pose(values: np.ndarray, with_ref: bool, unit_scale: float = 0.01
              ) -> RestPose | None:
    """The rig's rest geometry (``RestPose``: each joint's rest location, metres, the Hips
    at the origin) from one frame's values **with displacement**: a joint's position channels are its offset from its
    parent (BVH), the avatar's bone, constant but for the Hips' (the body's travel, left
    out).  None when the values are not finite or every offset is zero (a sender that
    streams displacement without offsets: no rig geometry)."""
    v = np.asarray(values, dtype=np.float64)[6 if with_ref else 0:]
    if v.size != 6 * len(JOINTS) or not np.isfinite(v).all():
        return None
    off = v.reshape(len(JOINTS), 6)[:, :3] * unit_scale
    off[0] = 0.0
    if not np.abs(off).max() > 1e-9:
        return None
    return RestPose.from_offsets(off, PARENTS)
