"""A standard humanoid's T-pose, for sources whose rotations are from a T-pose but which
send no geometry of their own (a VMC sender that sends zero bone positions).

Posture (``rtseg.core.posture``) needs the rig's rest geometry. Where the source gives none
but its rotations are known to be from a T-pose (every local rotation the identity in a
T-pose, rtseg's frame: right-handed, Y up, as VRM avatars' normalised bones are), the
joints' rest locations are taken from :data:`T_POSE`: a symmetric T-pose with straight
legs, its heights and arm spans the mean of six ASF people of ``../shared/data`` (hdm05 bd,
bk, dg; cmu_single 10, 16, 64) in leg lengths, rounded (checked by
``tests/test_standard_rig.py``). Another person's proportions name as well as
the performer's own (``docs/identity.md``, "Posture without the sender's geometry"); the
facing does not: a T-pose facing +Z with the left arm along +X and the same pose turned
half a turn about Y (VRM 0.x and 1.0 avatars face opposite ways) give the same rotations
different meanings. :class:`FacingProbe` tells them apart from the motion itself: in
whichever is right, a bent knee lies in front of the line from the hip to the ankle.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rtseg.core.posture import POINTS, Posture, PostureError, RestPose
from rtseg.core.rig import CANONICAL, END_OF, map_rig

#: Joint locations of the standard T-pose, in leg lengths (hip to knee plus knee to ankle),
#: relative to the midpoint of the hip joints; Y up, the body facing +Z, its left at +X.
#: ``*_hand`` / ``*_foot``: the first joint below the lower arm / leg (wrist, ankle).
T_POSE: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.0, 0.06, 0.0), "spine": (0.0, 0.15, 0.0), "chest": (0.0, 0.42, 0.0),
    "neck": (0.0, 0.58, 0.0), "head": (0.0, 0.80, 0.0)}
for _side, _x in (("left", 1.0), ("right", -1.0)):
    T_POSE.update({
        f"{_side}_upper_arm": (0.24 * _x, 0.63, 0.0), f"{_side}_lower_arm": (0.58 * _x, 0.63, 0.0),
        f"{_side}_hand": (0.80 * _x, 0.63, 0.0),
        f"{_side}_upper_leg": (0.09 * _x, 0.0, 0.0), f"{_side}_lower_leg": (0.09 * _x, -0.47, 0.0),
        f"{_side}_foot": (0.09 * _x, -0.94, 0.0)})

#: A turn of half a revolution about Y: x and z change sign.
_HALF_TURN = np.array([-1.0, 1.0, -1.0])


def standard_rest(joint_names: Sequence[str], parents: Sequence[int],
                  turned: bool = False) -> RestPose:
    """The rest geometry of the rig ``joint_names``/``parents`` (parents first) in the
    standard T-pose (:data:`T_POSE`, leg lengths), turned half a revolution about Y when
    ``turned``. The rig's canonical joints (``rtseg.core.rig.map_rig``) and the joints just
    below its lower arms and legs take the table's locations; any other joint lies at its
    parent's (a clavicle, an upper chest, fingers, toes). ``rtseg.core.rig.RigError`` when
    the rig cannot be mapped, PostureError when a lower arm or leg has no joint below it."""
    names, par = list(joint_names), [int(p) for p in parents]
    rig = map_rig(names, par)
    at: dict[int, str] = {rig.index[c]: c for c in CANONICAL}
    ends = rig.ends(par)
    for end, low in END_OF.items():
        if end not in ends:
            raise PostureError(f"{low} ({rig.joints[low]}) has no joint below it")
        at.setdefault(ends[end], end)
    sign = _HALF_TURN if turned else np.ones(3)
    out = np.zeros((len(names), 3))
    for j, p in enumerate(par):
        if j in at:
            out[j] = np.asarray(T_POSE[at[j]]) * sign
        elif p >= 0:
            out[j] = out[p]
    return RestPose(out)


#: Sampled frames with a bent knee a facing is decided on, at least.
MIN_BENT = 30
#: Share of those that must agree on the knee lying in front.
AGREE = 0.8
#: A knee is bent when hip to ankle is shorter than this x thigh plus shin.
BENT = 0.95
#: In at least a tenth of the frames looked at, the ankles must lie more than this (leg
#: lengths) below the hips' midpoint: legs that never hang down are no T-pose's.
LEGS_DOWN = 0.5

_COL = {p: 3 * i for i, p in enumerate(POINTS)}


class FacingProbe:
    """Which facing of the standard T-pose (module doc) a stream's rotations are from.

    ``observe(quats)`` with one frame's rotations (J, 4), scalar-last, as the source gives
    them (``space``); the caller samples the frames. ``result``: None while undecided, else
    the chosen ``RestPose`` (``turned`` says which). A facing is chosen once at least
    :data:`MIN_BENT` knees were bent, :data:`AGREE` of them in front of the hip-ankle line
    in it, and the legs hung down (:data:`LEGS_DOWN`) in a tenth of the frames. After
    ``max_frames`` frames without that, ``failed`` says why and the probe stops: the
    rotations look like neither facing's."""

    def __init__(self, joint_names: Sequence[str], parents: Sequence[int],
                 space: str = "local", max_frames: int = 1800) -> None:
        self._rests = [standard_rest(joint_names, parents, turned) for turned in (False, True)]
        self._posture = Posture(joint_names, parents, self._rests[0], space)
        self.max_frames = int(max_frames)
        self.frames = 0
        self.bent = 0
        self._front = 0                          # bent knees in front with the first facing
        self._heights: list[float] = []          # ankles' mean height, every frame
        self.result: RestPose | None = None
        self.failed: str | None = None
        self.turned: bool | None = None

    def observe(self, quats: np.ndarray) -> None:
        if self.result is not None or self.failed is not None:
            return
        self.frames += 1
        row = self._posture.transform(np.asarray(quats, dtype=np.float64)[None])[0]
        self._heights.append(0.5 * (row[_COL["left_ankle"] + 1] + row[_COL["right_ankle"] + 1]))
        for side in ("left", "right"):
            h, k, a = (row[_COL[f"{side}_{p}"]:_COL[f"{side}_{p}"] + 3]
                       for p in ("hip", "knee", "ankle"))
            if np.linalg.norm(a - h) < BENT * (np.linalg.norm(k - h) + np.linalg.norm(a - k)):
                self.bent += 1
                # forward is the third axis of a posture row (left, up, forward); the legs
                # are the same in both facings, the body's forward is opposite
                self._front += int(k[2] > 0.5 * (h[2] + a[2]))
        if self.bent >= MIN_BENT and self._decided():
            return
        if self.frames >= self.max_frames:
            self.failed = self._why()

    def _decided(self) -> bool:
        share = self._front / self.bent
        if (share < AGREE and 1.0 - share < AGREE) or -self._low() < LEGS_DOWN:
            return False
        self.turned = share < AGREE
        self.result = self._rests[int(self.turned)]
        return True

    def _low(self) -> float:
        return float(np.percentile(self._heights, 10))

    def _why(self) -> str:
        if self.bent < MIN_BENT:
            return f"{self.bent} bent knees in {self.frames} frames"
        if -self._low() < LEGS_DOWN:
            return (f"the ankles never lie lower than {self._low():+.2f} leg lengths from the "
                    f"hips in a tenth of {self.frames} frames")
        share = self._front / self.bent
        return f"the knees bend forward in {share:.0%} of {self.bent} frames: in neither facing"


__all__ = ["T_POSE", "standard_rest", "FacingProbe", "MIN_BENT", "AGREE", "LEGS_DOWN"]
