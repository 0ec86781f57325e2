"""Pose features of Barbič et al. 2004: per selected joint its parent-relative quaternion.

A frame's feature vector concatenates, for each joint of a skeleton profile (see
``rtseg.core.profiles``), the joint's rotation relative to its parent as a unit quaternion
(x, y, z, w), scalar-last: (frames, 4·J) float64.  Root position and orientation are left
out, as in the paper.

- ``space == "global"`` inputs (IMU sensor orientations) are made parent-relative with
  q_parent⁻¹ ⊗ q_child using the take's FULL hierarchy (parents outside the profile count),
  before the profile's joints are selected.  Roots keep their global rotation.
- Optional calibration frame (rig-relative inputs such as VMC, whose local rotations include
  the rig's rest pose): the feature of joint j is q_calib,j⁻¹ ⊗ q_j, so the calibration pose
  maps to identity.
- Sign continuity: q and -q are the same rotation.  The first output frame of each joint is
  made w ≥ 0, then each later quaternion is flipped if its dot product with the previous
  output is negative.  ``transform`` (batch) and ``step`` (one frame at a time, from reset)
  give the same rows.

1-dof bones (radius, tibia in CMU) give components that never vary; they are left in
place: ``constant_dims`` finds them for the detectors.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rtseg.core import quat as Q
from rtseg.core.profiles import CANONICAL, named_profile, resolve_joints
from rtseg.core.rig import CANONICAL_PARENT as CANONICAL_PARENT_OF
from rtseg.core.rig import FEATURE_JOINTS, Rig, RigError, map_rig
from rtseg.core.take import Take

# Left-multiplication matrix of a quaternion a (scalar-last): (a ⊗ b) = L(a) @ b, with
# L(a)[o, t] = SIGN[o, t] * a[GATHER[o, t]].
_GATHER = np.array([[3, 2, 1, 0],   # x: aw bx - az by + ay bz + ax bw
                    [2, 3, 0, 1],   # y: az bx + aw by - ax bz + ay bw
                    [1, 0, 3, 2],   # z: -ay bx + ax by + aw bz + az bw
                    [0, 1, 2, 3]])  # w: -ax bx - ay by - az bz + aw bw
_SIGN = np.array([[1.0, -1.0, 1.0, 1.0],
                  [1.0, 1.0, -1.0, 1.0],
                  [-1.0, 1.0, 1.0, 1.0],
                  [-1.0, -1.0, -1.0, 1.0]])
# L(conj(a)): conj negates x, y, z of a.
_CONJ_SIGN = _SIGN * np.where(_GATHER == 3, 1.0, -1.0)


def left_matrices(a: np.ndarray, conjugate: bool = False) -> np.ndarray:
    """(K, 4, 4) matrices L with L[k] @ b == a[k] ⊗ b (or conj(a[k]) ⊗ b)."""
    a = np.asarray(a, dtype=np.float64)
    return a[:, _GATHER] * (_CONJ_SIGN if conjugate else _SIGN)


def constant_dims(X: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Boolean mask of feature columns whose range over the frames is at most ``tol``."""
    X = np.asarray(X, dtype=np.float64)
    if X.ndim != 2:
        raise ValueError(f"X must be (frames, dims), got {X.shape}")
    if X.shape[0] == 0:
        return np.ones(X.shape[1], dtype=bool)
    return (X.max(axis=0) - X.min(axis=0)) <= tol


def axis_frame_matrices(axis_quats: np.ndarray) -> np.ndarray:
    """(K, 4, 4) matrices A with A[k] @ q == C_k⁻¹ ⊗ q ⊗ C_k (q re-expressed in frame C_k)."""
    c = np.asarray(axis_quats, dtype=np.float64)
    eye = np.eye(4)
    # Column t of A[k] is C_k⁻¹ ⊗ e_t ⊗ C_k.
    cols = Q.multiply(Q.multiply(Q.conjugate(c)[:, None, :], eye[None, :, :]), c[:, None, :])
    return np.swapaxes(cols, 1, 2)


class PoseFeatures:
    """Feature extractor for one skeleton (joint names + parents + rotation space).

    ``joints``: selected joint names (profile order); ``indices``: their positions in the
    input; ``dim`` = 4·len(joints).  Raises ``KeyError`` naming the joint and profile when
    the skeleton lacks a profile joint.

    ``axis_quats`` (J, 4), optional: a fixed frame C_j per joint (ASF/AMC ``meta["axis_quats"]``).
    When given, each parent-relative rotation L_j is re-expressed in that frame,
    C_j⁻¹ ⊗ L_j ⊗ C_j; for ASF/AMC takes this is exactly the AMC dof rotation M, the
    quantity of the paper, and 1- or 2-dof bones then have zero components (up to ~1e-16
    rounding) along their missing axes (``constant_dims`` finds them).  Distances between poses are the same with
    or without it (a fixed orthogonal map per joint).
    """

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], space: str,
                 profile: str | None = None, *, calibration: np.ndarray | None = None,
                 axis_quats: np.ndarray | None = None) -> None:
        joint_names = list(joint_names)
        parents = [int(p) for p in parents]
        if len(parents) != len(joint_names):
            raise ValueError(f"{len(parents)} parents for {len(joint_names)} joints")
        if space not in ("local", "global"):
            raise ValueError(f"space must be 'local' or 'global', not {space!r}")
        for j, p in enumerate(parents):
            if not -1 <= p < len(joint_names) or p == j:
                raise ValueError(f"joint {joint_names[j]!r} has invalid parent index {p}")
        self.joint_names = joint_names
        self.parents = parents
        self.space = space
        #: the canonical mapping (``rtseg.core.rig``) when the profile is ``canonical``
        self.rig: Rig | None = None
        if profile is None:
            # the canonical map when the rig has one, else a named channel profile
            try:
                self.rig = map_rig(joint_names, parents)
                profile = CANONICAL
            except RigError:
                profile = named_profile(joint_names)
                if profile is None:
                    raise
        elif profile == CANONICAL:
            self.rig = map_rig(joint_names, parents)
        self.profile = profile
        n = len(joint_names)
        if self.rig is not None:
            self.indices = np.array(self.rig.feature_indices, dtype=np.intp)
            paths = self.rig.paths
            # parent of each feature joint: its canonical parent
            parent_of = [self.rig.index[p] for p in
                         (CANONICAL_PARENT_OF[j] for j in FEATURE_JOINTS)]
        else:
            self.indices = np.array(resolve_joints(self.profile, joint_names), dtype=np.intp)
            paths = tuple((int(i),) for i in self.indices)
            parent_of = [parents[i] for i in self.indices]
        self.joints = [joint_names[i] for i in self.indices]
        #: the canonical joint each feature block describes (``rtseg.core.rig.FEATURE_JOINTS``), or
        #: the rig's own names for a named profile
        self.feature_joints = list(FEATURE_JOINTS) if self.rig is not None else list(self.joints)
        self.dim = 4 * len(self.indices)
        # Parent of each selected joint, roots pointing at an identity row appended at n.
        self._parent_idx = np.array([p if p >= 0 else n for p in parent_of], dtype=np.intp)
        # local inputs: the rotations composed from just below the parent down to the joint,
        # padded at the front with the identity row n (``rtseg.core.rig.Rig.paths``)
        m = max(len(pth) for pth in paths)
        self._paths = np.array([(n,) * (m - len(pth)) + tuple(pth) for pth in paths],
                               dtype=np.intp)
        self._composed = m > 1
        # flat indices building L(q) of path column t (m-2 down to 0), see left_matrices
        self._path_gathers = [(self._paths[:, t][:, None, None] * 4 + _GATHER).astype(np.intp)
                              for t in range(m - 2, -1, -1)]
        self._ext = np.zeros((n + 1, 4))
        self._ext[n, 3] = 1.0
        self._needs_ext = bool(np.any(self._parent_idx == n))
        self._frame_shape = (n, 4)
        # Flat indices into the (J[+1], 4) frame building L(conj(parent)) of each selected joint.
        self._parent_gather = (self._parent_idx[:, None, None] * 4 + _GATHER).astype(np.intp)
        self.axis_quats: np.ndarray | None = None
        self._axis_M: np.ndarray | None = None
        if axis_quats is not None:
            aq = np.asarray(axis_quats, dtype=np.float64)
            if aq.shape != (n, 4):
                raise ValueError(f"axis_quats must be ({n}, 4), got {aq.shape}")
            self.axis_quats = aq
            sel = aq[self.indices]
            if not np.allclose(np.abs(sel[:, 3]), 1.0):  # all identity: nothing to do
                self._axis_M = axis_frame_matrices(sel)
        self._calib_L: np.ndarray | None = None
        self._post: np.ndarray | None = self._axis_M  # combined (K, 4, 4) map after L
        self._prev: np.ndarray | None = None
        # ``step``'s work buffers (no allocation per frame but the returned row): the
        # (K, 4, 4) left-multiplication matrices, two (K, 4, 1) products used in turn,
        # the selected rows, the sign-continuity dots and signs, and two output rows
        # used in turn (one holds the previous frame's output)
        k = len(self.indices)
        self._mat = np.empty((k, 4, 4))
        self._prod = (np.empty((k, 4, 1)), np.empty((k, 4, 1)))
        self._rows = np.empty((k, 4))
        self._dot = np.empty((k, 1, 1))
        self._sign = np.empty(k)
        self._outs = (np.empty((k, 4)), np.empty((k, 4)))
        self._turn = 0
        if calibration is not None:
            self.calibrate(calibration)

    @classmethod
    def for_take(cls, take: Take, profile: str | None = None) -> "PoseFeatures":
        """Extractor for ``take``'s skeleton (uses ``meta["axis_quats"]`` when present)."""
        aq = take.meta.get("axis_quats")
        if aq is not None and np.shape(aq) != (take.n_joints, 4):
            aq = None
        return cls(take.joint_names, take.parents, take.space, profile, axis_quats=aq)

    # -- state -------------------------------------------------------------------------
    @property
    def calibrated(self) -> bool:
        return self._calib_L is not None

    def reset(self) -> None:
        """Forget the previous frame (sign continuity restarts).  Keeps the calibration."""
        self._prev = None

    def calibrate(self, quats: np.ndarray) -> None:
        """Take this input frame (J, 4) as the reference pose: it maps to identity features.

        Features become q_calib⁻¹ ⊗ q per joint.  Also resets sign continuity.
        ``clear_calibration()`` undoes it.
        """
        ref = self._local_one(self._check_frame(quats))
        if self._axis_M is not None:
            ref = (self._axis_M @ ref[:, :, None])[:, :, 0]
        self._calib_L = left_matrices(ref, conjugate=True)
        self._post = self._calib_L if self._axis_M is None else self._calib_L @ self._axis_M
        self._prev = None

    def clear_calibration(self) -> None:
        self._calib_L = None
        self._post = self._axis_M
        self._prev = None

    # -- per frame ---------------------------------------------------------------------
    def _check_frame(self, quats: np.ndarray) -> np.ndarray:
        q = np.asarray(quats, dtype=np.float64)
        if q.shape != (len(self.joint_names), 4):
            raise ValueError(f"frame must be ({len(self.joint_names)}, 4), got {q.shape}")
        return q

    def _local_one(self, q: np.ndarray) -> np.ndarray:
        """(K, 4) parent-relative rotations of the selected joints of one frame (no calibration)."""
        if self.space == "local":
            if not self._composed:
                return q[self.indices]
            src = self._ext
            src[:-1] = q
            flat = src.reshape(-1)
            out = src[self._paths[:, -1]]
            for g in self._path_gathers:           # left-multiply by the joints above
                out = ((flat[g] * _SIGN) @ out[:, :, None])[:, :, 0]
            return out
        if self._needs_ext:
            src = self._ext
            src[:-1] = q
        else:
            src = q
        L = src.reshape(-1)[self._parent_gather] * _CONJ_SIGN
        return (L @ q[self.indices][:, :, None])[:, :, 0]

    def _local_into(self, q: np.ndarray) -> np.ndarray:
        """``_local_one`` into the work buffers: (K, 4, 1), one of ``_prod``; the same
        arithmetic (gathers, sign tables, ``matmul``), so the same values to the bit."""
        mat, prod = self._mat, self._prod
        if self.space == "local":
            if not self._composed:
                q.take(self.indices, 0, prod[0][:, :, 0])
                return prod[0]
            src = self._ext
            src[:-1] = q
            flat = src.reshape(-1)
            src.take(self._paths[:, -1], 0, prod[0][:, :, 0])
            cur = 0
            for g in self._path_gathers:           # left-multiply by the joints above
                flat.take(g, None, mat)
                np.multiply(mat, _SIGN, out=mat)
                np.matmul(mat, prod[cur], out=prod[1 - cur])
                cur = 1 - cur
            return prod[cur]
        if self._needs_ext:
            src = self._ext
            src[:-1] = q
        else:
            src = q
        src.reshape(-1).take(self._parent_gather, None, mat)
        np.multiply(mat, _CONJ_SIGN, out=mat)
        rows = self._rows
        q.take(self.indices, 0, rows)
        np.matmul(mat, rows[:, :, None], out=self._prod[0])
        return self._prod[0]

    def step(self, quats: np.ndarray) -> np.ndarray:
        """Features (dim,) of one frame (J, 4); the row ``transform`` gives for it in a sequence.

        Keeps the previous output for sign continuity (``reset()`` forgets it).  The work
        happens in preallocated buffers; the row returned is a new array (the caller's).
        """
        q = quats
        if (type(q) is not np.ndarray or q.dtype != np.float64 or q.shape != self._frame_shape
                or not q.flags.c_contiguous):
            q = np.ascontiguousarray(self._check_frame(np.asarray(q, dtype=np.float64)))
        loc = self._local_into(q)
        self._turn = turn = 1 - self._turn
        out = self._outs[turn]
        if self._post is not None:
            np.matmul(self._post, loc, out=out[:, :, None])
        else:
            out[:] = loc[:, :, 0]
        prev = self._prev
        sign = self._sign
        if prev is None:
            np.add(out[:, 3], 0.0, out=sign)
        else:
            # dot(out_k, prev_k) per joint; +0.0 turns -0.0 into +0.0 (no flip, as make_continuous)
            dot = self._dot
            np.matmul(out[:, None, :], prev[:, :, None], out=dot)
            np.add(dot[:, 0, 0], 0.0, out=sign)
        np.copysign(1.0, sign, out=sign)
        out *= sign[:, None]
        self._prev = out
        return out.reshape(-1).copy()

    # -- batch -------------------------------------------------------------------------
    def local_quats(self, quats: np.ndarray) -> np.ndarray:
        """(F, K, 4) rotations of the selected joints (parent-relative, in the axis frames if
        any, calibrated if calibrated), without sign processing."""
        q = np.asarray(quats, dtype=np.float64)
        if q.ndim != 3 or q.shape[1:] != (len(self.joint_names), 4):
            raise ValueError(f"quats must be (frames, {len(self.joint_names)}, 4), got {q.shape}")
        child = q[:, self.indices]
        if self.space == "global":
            par = self._parent_idx
            n = len(self.joint_names)
            parent = np.where((par < n)[:, None], q[:, np.minimum(par, n - 1)], Q.IDENTITY)
            child = Q.multiply(Q.conjugate(parent), child)
        elif self._composed:
            ext = np.concatenate([q, np.broadcast_to(Q.IDENTITY, (q.shape[0], 1, 4))], axis=1)
            child = ext[:, self._paths[:, 0]]
            for t in range(1, self._paths.shape[1]):
                child = Q.multiply(child, ext[:, self._paths[:, t]])
        if self._post is not None:
            child = np.einsum("kot,fkt->fko", self._post, child)
        return child

    def transform(self, quats: np.ndarray) -> np.ndarray:
        """(F, dim) features of (F, J, 4) frames.  Stateless: ignores and keeps ``step``'s state."""
        local = np.array(self.local_quats(quats), dtype=np.float64, copy=True)
        if local.shape[0] == 0:
            return np.zeros((0, self.dim))
        first = local[0]
        first[first[:, 3] < 0] *= -1.0
        local = Q.make_continuous(local, axis=0)
        return local.reshape(local.shape[0], self.dim)

    @property
    def input_joints(self) -> np.ndarray:
        """Sorted indices of the input joints the features read: the feature joints and, for
        global orientations, their (canonical) parents; for local rotations every joint
        composed into a feature joint (``rtseg.core.rig.Rig.paths``)."""
        n = len(self.joint_names)
        need = {int(i) for i in self.indices}
        if self.space == "global":
            need |= {int(p) for p in self._parent_idx if p < n}
        else:
            need |= {int(i) for i in self._paths.reshape(-1) if i < n}
        return np.array(sorted(need), dtype=np.intp)

    def report(self) -> dict:
        """What the features are made of, JSON-ready: ``profile``, ``rig`` (the family
        mapped, ``rtseg.core.rig``; None for a named profile), ``joints`` (feature joint -> the
        rig's joint) and ``composed`` (rig joints folded into a canonical joint's rotation)."""
        if self.rig is not None:
            return {"profile": self.profile, **self.rig.report()}
        return {"profile": self.profile, "rig": None,
                "joints": {j: j for j in self.joints}, "composed": {}}

    def summary(self) -> str:
        """One line for a session log: the profile and the joints used."""
        if self.rig is not None:
            return f"features: {self.dim} values, canonical joints of {self.rig.summary()}"
        return f"features: {self.dim} values, profile {self.profile}: {', '.join(self.joints)}"

    def __repr__(self) -> str:
        return (f"PoseFeatures(profile={self.profile!r}, joints={len(self.joints)}, "
                f"space={self.space!r}, calibrated={self.calibrated})")


#: seconds of a rig-relative (local-space) stream averaged as its calibration pose before
#: the detectors are fed: ``[calibration] seconds`` of the shipped config/live.toml (mode
#: "auto"), which ``live_rows`` reproduces offline
CALIBRATION_S = 0.25


def average_quats(q: np.ndarray) -> np.ndarray:
    """Mean rotation of (n, J, 4) quaternions close to each other: sign-align to the first
    frame, average, normalise (the first-order approximation of the quaternion mean)."""
    ref = q[0]
    signs = np.where(np.sum(q * ref, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    m = np.mean(q * signs, axis=0)
    n = np.linalg.norm(m, axis=-1, keepdims=True)
    return np.where(n > 1e-9, m / np.where(n > 1e-9, n, 1.0), ref)


def live_rows(take: Take, profile: str | None = None,
              seconds: float = CALIBRATION_S) -> tuple[np.ndarray, int]:
    """(rows, first): the features the live session (shipped configuration) feeds its
    detectors on ``take`` and the take frame of the first row.  Rig-relative rotations
    (``space`` "local") are measured from a calibration pose, the mean of the first
    ``seconds`` of frames (at least one), which are not fed (``rtseg.live.pipeline``);
    global orientations are fed from frame 0 as they are."""
    pf = PoseFeatures.for_take(take, profile)
    first = 0
    if take.space == "local" and take.n_frames > 1:
        first = min(take.n_frames - 1, max(1, int(round(seconds * take.frame_rate))))
        pf.calibrate(average_quats(np.asarray(take.quats[:first], dtype=np.float64)))
    return pf.transform(take.quats[first:]), first


def take_features(take: Take, profile: str | None = None) -> np.ndarray:
    """(frames, 4·J) float64 features of a whole take (``profile`` None: canonical when the rig maps, else a named profile).

    Uses the take's ``meta["axis_quats"]`` (ASF/AMC) so features are the AMC dof rotations.
    """
    return PoseFeatures.for_take(take, profile).transform(take.quats)
