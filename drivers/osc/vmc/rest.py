"""A VMC sender's rest geometry, from the bone positions it sends.

Each ``/VMC/Ext/Bone/Pos`` carries the bone's **local position**: where the bone starts in
its Unity parent's frame (Unity ``Transform.localPosition``).  On a humanoid avatar these are
constant - the avatar's bone offsets - except the hips' (the body's place in the world).
VRM avatars, which VMC senders drive, rest in a T-pose with every local rotation the identity,
so chaining the offsets from the hips gives every bone's rest location: the rig geometry
``rtseg.core.posture`` needs to tell where the body is (behaviour names by posture).

What is chained: the offsets as first received per bone, until ``CAPTURE_FRAMES`` frames
after every profile bone has been seen (``CAPTURE_LIMIT`` frames at most: a profile bone
never sent hangs at its parent), of the profile's bones and of any other Unity body bone
the sender sends (its shoulders and upper chest when the profile leaves them out: an upper
arm's local position is from its shoulder).  A bone hangs from its
nearest ancestor the sender sent in Unity's humanoid hierarchy (``HUMANOID_PARENTS``); a
profile bone that is not a Unity body bone hangs from its profile parent.  Frame: rtseg's
(right-handed, Y-up; Unity's z negated), the sender's units (metres for every VMC
application known to us).  A sender that sends zero positions (some do) has no rest
geometry: :meth:`BoneOffsets.rest_pose` is then None and names go without posture.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from rtseg.core.posture import RestPose

#: Frames whose bone positions are kept after every profile bone has been seen (a sender's
#: extra bones arrive in every frame; the offsets do not change).
CAPTURE_FRAMES = 8
#: Frames after which capture ends even if a profile bone was never sent (its offset is then
#: taken as zero: it hangs at its parent).
CAPTURE_LIMIT = 120
#: Offsets whose largest length is below this (sender units) are "no positions sent".
ZERO_OFFSETS = 1e-6

#: Unity humanoid body bones and each one's parent in Unity's humanoid hierarchy (an
#: avatar without an optional bone - UpperChest, a shoulder, Neck - hangs its children from
#: the next one up).
HUMANOID_PARENTS: dict[str, str | None] = {
    "Hips": None, "Spine": "Hips", "Chest": "Spine", "UpperChest": "Chest",
    "Neck": "UpperChest", "Head": "Neck"}
for _s in ("Left", "Right"):
    HUMANOID_PARENTS.update({
        f"{_s}Shoulder": "UpperChest", f"{_s}UpperArm": f"{_s}Shoulder",
        f"{_s}LowerArm": f"{_s}UpperArm", f"{_s}Hand": f"{_s}LowerArm",
        f"{_s}UpperLeg": "Hips", f"{_s}LowerLeg": f"{_s}UpperLeg",
        f"{_s}Foot": f"{_s}LowerLeg", f"{_s}Toes": f"{_s}Foot"})
_BODY_LOWER = {n.lower(): n for n in HUMANOID_PARENTS}


class BoneOffsets:
    """The local positions a VMC sender sends (module doc), kept while ``capturing``.

    ``bone_names``: the profile's bones (the assembler's order), ``parents`` their profile
    parents.  ``note(i, x, y, z)`` keeps profile bone ``i``'s first position (rtseg frame),
    ``note_extra(name, ...)`` another Unity body bone's; ``frame_closed()`` counts frames."""

    def __init__(self, bone_names: Sequence[str], parents: Sequence[int] | None = None) -> None:
        self.names = list(bone_names)
        n = len(self.names)
        self.parents = list(parents) if parents is not None else [-1] * n
        self.values = np.zeros((n, 3))
        self.seen = [False] * n
        self.missing = n
        self.extra: dict[str, tuple[float, float, float]] = {}
        self._frames_left = CAPTURE_FRAMES
        self._frames_seen = 0
        #: True while positions are still kept (the assembler asks before each note).
        self.capturing = True
        self._rest: RestPose | None = None
        self._done = False

    def note(self, i: int, x: float, y: float, z: float) -> None:
        if not self.seen[i] and math.isfinite(x + y + z):
            self.values[i] = (x, y, z)
            self.seen[i] = True
            self.missing -= 1

    def note_extra(self, name: str, x: float, y: float, z: float) -> None:
        body = _BODY_LOWER.get(name.lower())
        if body is not None and body not in self.extra and math.isfinite(x + y + z):
            self.extra[body] = (x, y, z)

    def frame_closed(self) -> None:
        self._frames_seen += 1
        if self.missing == 0:
            self._frames_left -= 1
        if self._frames_left <= 0 or self._frames_seen >= CAPTURE_LIMIT:
            self.capturing = False

    def rest_pose(self) -> RestPose | None:
        """The rest geometry (``RestPose``, profile order, hips at the origin) once capture
        has ended (module doc); None before, and when the sender sends no positions.
        Worked out once."""
        if self._done:
            return self._rest
        if self.capturing:
            return None
        self._done = True
        off: dict[str, np.ndarray] = {n: np.asarray(v, dtype=np.float64)
                                      for n, v in self.extra.items()}
        body = [_BODY_LOWER.get(n.lower()) for n in self.names]
        for i, b in enumerate(body):
            off[b or self.names[i]] = self.values[i]
        if max((float(np.linalg.norm(v)) for n, v in off.items() if n != "Hips"),
               default=0.0) < ZERO_OFFSETS:
            return None                   # only the hips' travel: no offsets sent
        pos: dict[str, np.ndarray] = {}

        def place(name: str) -> np.ndarray:
            if name not in pos:
                up = HUMANOID_PARENTS[name]
                while up is not None and up not in off:
                    up = HUMANOID_PARENTS[up]
                pos[name] = np.zeros(3) if up is None else place(up) + off[name]
            return pos[name]

        out = np.zeros((len(self.names), 3))
        for i, b in enumerate(body):
            if b is not None:
                out[i] = place(b)
            elif self.parents[i] >= 0:        # parents come first (profile order)
                out[i] = out[self.parents[i]] + self.values[i]
        self._rest = RestPose(out)
        return self._rest


__all__ = ["BoneOffsets", "HUMANOID_PARENTS", "CAPTURE_FRAMES", "CAPTURE_LIMIT"]
