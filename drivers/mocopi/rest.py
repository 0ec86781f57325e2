"""A mocopi sender's rest geometry, from the bone translations it sends.

Each bone's ``tran`` carries its position local to the parent bone (metres): in the
skeleton packet (``skdf``) the rest pose - every rotation the identity, the positions the
avatar's bone offsets - and in every frame the same offsets (the root's own position
excepted, the body's place in the world).  Chained from the root they give each bone's rest
location: the rig geometry ``rtseg.core.posture`` needs to tell where the body is (behaviour
names by posture).  A skeleton whose rest rotations are not the identity, or offsets that
are all zero, give none (names then go by rotations alone).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rtseg.core.posture import RestPose
from rtseg.drivers.mocopi.codec import BONE_PARENTS, MocopiFrame, MocopiSkeleton

#: | |w| - 1 | up to which a skeleton's rest rotation counts as the identity
REST_IDENTITY_TOL = 1e-3


def rest_pose(bone_ids: Sequence[int], skeleton: MocopiSkeleton | None,
              frame: MocopiFrame | None) -> RestPose | None:
    """The rest locations of the profile's ``bone_ids`` (rows in that order; the root at the
    origin), from ``skeleton`` when one was received, else from the translations of
    ``frame`` with mocopi's own hierarchy (``BONE_PARENTS``); None when neither gives them
    (module doc)."""
    if skeleton is not None:
        ids, pids = skeleton.bone_ids, skeleton.parent_ids
        tran = np.asarray(skeleton.tran, dtype=np.float64)
        if np.any(np.abs(np.abs(tran[:, 3]) - 1.0) > REST_IDENTITY_TOL):
            return None
    elif frame is not None:
        ids = frame.bone_ids
        pids = [BONE_PARENTS[b] if 0 <= b < len(BONE_PARENTS) else -1 for b in ids]
        tran = np.asarray(frame.tran, dtype=np.float64)
    else:
        return None
    local = {int(b): tran[k, 4:7] for k, b in enumerate(ids)}
    parent = {int(b): int(p) for b, p in zip(ids, pids)}
    if not all(np.isfinite(v).all() for v in local.values()):
        return None
    pos: dict[int, np.ndarray] = {}

    def place(b: int, depth: int = 0) -> np.ndarray:
        if b not in pos:
            p = parent.get(b, -1)
            if p < 0 or p not in local or depth > len(local):
                pos[b] = np.zeros(3)         # the root: its translation is the body's travel
            else:
                pos[b] = place(p, depth + 1) + local[b]
        return pos[b]

    if any(int(b) not in local for b in bone_ids):
        return None
    out = np.array([place(int(b)) for b in bone_ids])
    if np.abs(out).max() < 1e-6:
        return None
    return RestPose(out)


__all__ = ["rest_pose", "REST_IDENTITY_TOL"]
