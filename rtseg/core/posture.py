"""Body posture: where the head, shoulders, elbows, wrists, hips, knees and ankles are,
relative to the pelvis, in a frame that turns with the body's heading.

Unlike the pose features (``rtseg.core.features``: each segment's rotation relative to the
segment it hangs from, in the rig's own joint frames), posture is the same on every rig
that moves the same way: it is computed by forward kinematics from the rig's rest geometry,
so rest-pose conventions, joint axes (ASF ``axis``), extra joints (clavicles, a second
spine joint) and units drop out.  It tells behaviours apart by *where the body is* (arms
raised, crouched, bent to the floor), which rotation speeds alone do not.

Rows, ``DIM`` = 3 x len(``POINTS``) values a frame, float64:

- each point's position minus the pelvis (the midpoint of the two hip joints);
- in the body frame (left, up, forward): ``up`` the world's up axis (``RestPose.up``, +Y
  for ASF/AMC and BVH), ``left`` the horizontal direction from the right hip to the left
  hip, ``forward`` = left x up (so the frame turns with the heading but not with a bend
  or a fall: lying down is lying down);
- in leg lengths: hip to knee plus knee to ankle at rest (the left leg), so people of any
  size and files of any unit compare.

Forward kinematics (both ASF/AMC and BVH semantics): with ``positions`` the joints' rest
locations (every rotation the identity, root at the origin), joint j lies at
p_j = p_parent + G_parent (x) (r_j - r_parent), G_j = G_parent (x) q_j (``space="local"``;
global inputs are G directly).  ASF rotations are used as the reader stores them
(C M C^-1: in world-aligned axes), BVH as read.

A rig whose rest geometry is unknown (an IMU suit's sensors, a recording without it) has
no posture: :meth:`RestPose.of_take` raises :class:`PostureError` saying so, and callers
go without (the library then names by rotations alone, ``rtseg.library``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.core.rig import END_OF, RigError, map_rig

#: The points of a posture row, in order; each is a rig joint's location (module doc).
POINTS: tuple[str, ...] = (
    "head", "chest",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle")
DIM = 3 * len(POINTS)
#: the world's up axis of ASF/AMC and BVH files
UP = (0.0, 1.0, 0.0)
#: point -> the canonical joint at that location (``rtseg.core.rig``); wrists and ankles
#: are the first joint below the lower arm / lower leg
_AT = {"head": "head", "chest": "chest",
       **{f"{s}_{p}": f"{s}_{c}" for s in ("left", "right")
          for p, c in (("shoulder", "upper_arm"), ("elbow", "lower_arm"),
                       ("hip", "upper_leg"), ("knee", "lower_leg"))}}
#: wrist and ankle -> the limb end (``rtseg.core.rig.END_OF``) at them
_END = {f"{s}_{p}": f"{s}_{e}" for s in ("left", "right")
        for p, e in (("wrist", "hand"), ("ankle", "foot"))}


class PostureError(ValueError):
    """A take or rig whose posture cannot be computed (one line: what is missing)."""


@dataclass(frozen=True)
class RestPose:
    """A rig's rest geometry: ``positions`` (J, 3) each joint's location with every
    rotation the identity and the root at the origin (the file's units), ``up`` the world's
    up axis (unit vector)."""
    positions: np.ndarray
    up: tuple[float, float, float] = UP

    @classmethod
    def of_take(cls, take: Any) -> "RestPose":
        """The rest geometry of a take read from ASF/AMC (``meta["bone_offsets"]``: each
        bone's direction x length, which the joints below it start from) or BVH
        (``meta["offsets"]``: each joint from its parent), or kept by rtseg
        (``meta["rest_positions"]``); PostureError when the take has none."""
        meta, parents = take.meta, list(take.parents)
        J = len(parents)
        _check_order(parents, take.source)
        kept = meta.get("rest_positions")
        if kept is not None and np.shape(kept) == (J, 3):
            return cls(np.asarray(kept, dtype=np.float64))
        fmt = meta.get("format")
        if fmt == "asf/amc" and np.shape(meta.get("bone_offsets")) == (J, 3):
            bone = np.asarray(meta["bone_offsets"], dtype=np.float64)
            step = [np.zeros(3) if p < 0 or parents[p] < 0 else bone[p] for p in parents]
        elif fmt == "bvh" and np.shape(meta.get("offsets")) == (J, 3):
            step = meta["offsets"]
        else:
            raise PostureError(f"{take.source or 'take'}: no rest geometry (bone offsets) "
                               f"to compute a posture from")
        return cls.from_offsets(step, parents)

    @classmethod
    def from_offsets(cls, offsets: Any, parents: Sequence[int]) -> "RestPose":
        """The rest geometry of a rig whose joint j lies ``offsets[j]`` (J, 3) from its
        parent at rest (BVH ``OFFSET``s, a stream's bone translations; the roots' own
        offsets are left out: roots at the origin).  ``parents`` before children."""
        off = np.asarray(offsets, dtype=np.float64)
        pos = np.zeros((len(parents), 3))
        for j, p in enumerate(parents):
            if p >= 0:
                pos[j] = pos[p] + off[j]
        return cls(pos)

    @classmethod
    def from_world(cls, positions: np.ndarray, orientations: np.ndarray,
                   parents: Sequence[int]) -> "RestPose":
        """The rest geometry of a rig from one frame of its joints' world ``positions``
        (J, 3) and global ``orientations`` (J, 4, scalar-last), as streams that send both
        give them (Xsens MVN): a joint's position relative to its parent, in the parent's
        frame, is the same in every pose (rigid segments), so it is the parent's step at
        rest.  ``parents`` before children; PostureError otherwise or for non-finite
        values."""
        P = np.asarray(positions, dtype=np.float64)
        G = np.asarray(orientations, dtype=np.float64)
        _check_order(parents)
        if P.shape != (len(parents), 3) or G.shape != (len(parents), 4) or not (
                np.isfinite(P).all() and np.isfinite(G).all()):
            raise PostureError(f"world positions {P.shape} and orientations {G.shape} of "
                               f"{len(parents)} joints, finite, needed")
        R = Rotation.from_quat(G).as_matrix()
        steps = [np.zeros(3) if p < 0 else R[p].T @ (P[j] - P[p])
                 for j, p in enumerate(parents)]
        return cls.from_offsets(steps, parents)

    @classmethod
    def find(cls, take: Any) -> "RestPose | None":
        """``of_take``, or None when the take has no rest geometry."""
        try:
            return cls.of_take(take)
        except PostureError:
            return None


def _check_order(parents: Sequence[int], where: str = "") -> None:
    """PostureError unless every joint comes after its parent (the order of every reader,
    as ``rtseg.core.quat.global_from_local`` requires)."""
    if any(p >= j for j, p in enumerate(parents)):
        raise PostureError(f"{where or 'rig'}: a joint comes before its parent; posture "
                           f"needs parents first")


def rest_meta(take: Any) -> dict[str, Any]:
    """``{"rest_positions": (J, 3)}`` of ``take``'s rest geometry for the meta of a take
    made from it (joined clips, spliced performances); {} when it has none."""
    rest = RestPose.find(take)
    return {} if rest is None else {"rest_positions": rest.positions.copy()}


class Posture:
    """Posture rows (module doc) of one rig: ``joint_names`` and ``parents`` as the take's
    or the source's, ``rest`` its rest geometry, ``space`` "local" or "global".

    ``points``: point -> rig joint name.  Raises ``rtseg.core.rig.RigError`` when the rig
    cannot be mapped, PostureError when a wrist or ankle has no joint below it."""

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int], rest: RestPose,
                 space: str = "local") -> None:
        names, parents = list(joint_names), [int(p) for p in parents]
        if np.shape(rest.positions) != (len(names), 3):
            raise PostureError(f"rest geometry of {np.shape(rest.positions)} for "
                               f"{len(names)} joints")
        _check_order(parents)
        rig = map_rig(names, parents)
        at = {p: rig.index[c] for p, c in _AT.items()}
        ends = rig.ends(parents)
        for p, e in _END.items():
            if e not in ends:
                c = END_OF[e]
                raise PostureError(f"{c} ({rig.joints[c]}) has no joint below it: no "
                                   f"{p.replace('_', ' ')}")
            at[p] = ends[e]
        self.space = space
        self.parents = parents
        self.points = {p: names[at[p]] for p in POINTS}
        self._cols = np.array([at[p] for p in POINTS])
        # only the joints on the way from the root to a point are needed
        need: set[int] = set()
        for j in self._cols:
            while j >= 0 and j not in need:
                need.add(int(j))
                j = parents[j]
        self._order = sorted(need)                   # parents first (_check_order)
        R = np.asarray(rest.positions, dtype=np.float64)
        self._step = {j: R[j] - R[parents[j]] for j in self._order if parents[j] >= 0}
        up = np.asarray(rest.up, dtype=np.float64)
        self.up = up / np.linalg.norm(up)
        li, ri = at["left_hip"], at["right_hip"]
        leg = (np.linalg.norm(R[at["left_knee"]] - R[li])
               + np.linalg.norm(R[at["left_ankle"]] - R[at["left_knee"]]))
        if not leg > 0:
            raise PostureError("rest geometry gives the left leg no length")
        self.leg_length = float(leg)
        self._hips = (li, ri)

    @classmethod
    def for_take(cls, take: Any) -> "Posture":
        """The posture of ``take``'s rig (PostureError without rest geometry)."""
        return cls(take.joint_names, take.parents, RestPose.of_take(take), take.space)

    @classmethod
    def find(cls, take: Any) -> "Posture | None":
        """``for_take``, or None when the take has no rest geometry or its rig no posture
        (it cannot be mapped, or a wrist or ankle has no joint below it)."""
        try:
            return cls.for_take(take)
        except (PostureError, RigError):
            return None

    def transform(self, quats: np.ndarray) -> np.ndarray:
        """Rows (frames, ``DIM``) of rotations ``quats`` (frames, J, 4) (module doc)."""
        q = np.asarray(quats, dtype=np.float64)
        F = q.shape[0]
        R = Rotation.from_quat(q[:, self._order].reshape(-1, 4)).as_matrix().reshape(
            F, len(self._order), 3, 3)                          # (F, needed, 3, 3)
        G: dict[int, np.ndarray] = {}
        P: dict[int, np.ndarray] = {}
        par = self.parents
        for k, j in enumerate(self._order):
            p = par[j]
            if p < 0:
                G[j] = R[:, k]
                P[j] = np.zeros((F, 3))
                continue
            G[j] = R[:, k] if self.space == "global" else np.matmul(G[p], R[:, k])
            P[j] = P[p] + np.matmul(G[p], self._step[j])
        pts = np.stack([P[int(j)] for j in self._cols], axis=1)          # (F, points, 3)
        li, ri = self._hips
        pelvis = 0.5 * (P[li] + P[ri])
        up = self.up
        left = P[li] - P[ri]
        left = left - (left @ up)[:, None] * up
        n = np.linalg.norm(left, axis=1, keepdims=True)
        left = np.where(n > 1e-12, left / np.where(n > 1e-12, n, 1.0), _any_normal(up))
        fwd = np.cross(left, up)
        basis = np.stack([left, np.broadcast_to(up, left.shape), fwd], axis=1)   # (F, 3, 3)
        rel = pts - pelvis[:, None, :]
        out = np.einsum("fij,fpj->fpi", basis, rel) / self.leg_length
        return out.reshape(F, DIM)

    def report(self) -> dict:
        """JSON-ready: point -> rig joint, the leg length in the rig's units."""
        return {"points": dict(self.points), "leg_length": round(self.leg_length, 6)}


def world_positions(orientations: np.ndarray, parents: Sequence[int], offsets: Any,
                    root: np.ndarray | None = None) -> np.ndarray:
    """Joint positions (frames, J, 3) by forward kinematics: joint j at its parent's
    position plus the parent's global orientation (``orientations`` (frames, J, 4),
    scalar-last) applied to ``offsets[j]`` (J, 3), its step from the parent at rest; the
    roots at ``root`` (frames, 3) or the origin.  ``parents`` before children."""
    G = np.asarray(orientations, dtype=np.float64)
    F, J = G.shape[:2]
    off = np.asarray(offsets, dtype=np.float64)
    R = Rotation.from_quat(G.reshape(-1, 4)).as_matrix().reshape(F, J, 3, 3)
    pos = np.zeros((F, J, 3))
    for j, p in enumerate(parents):
        if p >= 0:
            pos[:, j] = pos[:, p] + R[:, p] @ off[j]
        elif root is not None:
            pos[:, j] = root
    return pos


def _any_normal(up: np.ndarray) -> np.ndarray:
    """A unit vector at right angles to ``up`` (the heading when the hips are vertical)."""
    a = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    v = a - (a @ up) * up
    return v / np.linalg.norm(v)


def take_posture(take: Any) -> np.ndarray:
    """Posture rows (frames, ``DIM``) of a whole take (PostureError without rest geometry)."""
    return Posture.for_take(take).transform(take.quats)


def window_descriptor(P: np.ndarray) -> np.ndarray:
    """Descriptor (2 x ``DIM``,) of a window of posture rows P (frames >= 1, ``DIM``): each
    value's mean and standard deviation over the window, leg lengths."""
    P = np.asarray(P, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != DIM or not len(P):
        raise ValueError(f"a posture descriptor needs (frames, {DIM}) rows, got {P.shape}")
    return np.concatenate([P.mean(axis=0), P.std(axis=0)])
