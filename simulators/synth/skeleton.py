"""The synthesiser's skeleton: the default17 suit's bones, rest offsets and anatomical
angle channels, and the maps from angles to rotations and rotations to joint positions.

Frames and units: right-handed, Y up, metres; the performer faces +Z at heading 0, +X is
the performer's left.  Rest pose (all local rotations identity) is a T-pose.  Quaternions
are scalar-last (x, y, z, w); angles are degrees.
"""

from __future__ import annotations

import numpy as np

from rtseg.core import quat
from rtseg.core.posture import world_positions

#: The default17 suit's bones, in sensor-id order (config/suits.toml).
JOINT_NAMES: list[str] = [
    "Hips", "Spine", "Chest", "Neck", "Head",
    "LeftUpperArm", "LeftLowerArm", "LeftHand",
    "RightUpperArm", "RightLowerArm", "RightHand",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot",
    "RightUpperLeg", "RightLowerLeg", "RightFoot",
]
PARENTS: list[int] = [-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15]
J = {name: i for i, name in enumerate(JOINT_NAMES)}
N_JOINTS = len(JOINT_NAMES)

#: Rest-pose (T-pose) bone offsets from the parent joint, metres, in the parent's frame.
OFFSETS = np.array([
    [0.0, 0.0, 0.0],      # Hips (root; height set by the floor contact)
    [0.0, 0.10, 0.0],     # Spine
    [0.0, 0.15, 0.0],     # Chest
    [0.0, 0.25, 0.0],     # Neck
    [0.0, 0.10, 0.0],     # Head
    [0.18, 0.20, 0.0],    # LeftUpperArm (shoulder)
    [0.28, 0.0, 0.0],     # LeftLowerArm (elbow)
    [0.26, 0.0, 0.0],     # LeftHand (wrist)
    [-0.18, 0.20, 0.0],   # RightUpperArm
    [-0.28, 0.0, 0.0],    # RightLowerArm
    [-0.26, 0.0, 0.0],    # RightHand
    [0.09, -0.06, 0.0],   # LeftUpperLeg (hip joint)
    [0.0, -0.42, 0.0],    # LeftLowerLeg (knee)
    [0.0, -0.42, 0.0],    # LeftFoot (ankle)
    [-0.09, -0.06, 0.0],  # RightUpperLeg
    [0.0, -0.42, 0.0],    # RightLowerLeg
    [0.0, -0.42, 0.0],    # RightFoot
])
#: Floor-contact points in the foot's frame (heel, toe), metres.
FOOT_POINTS = np.array([[0.0, -0.07, -0.05], [0.0, -0.07, 0.16]])

# Anatomical angle channels (degrees), per joint kind.  Array A has shape (frames, 17, 4).
#   Hips:                    FLEX pitch (torso forward +), SIDE roll, TWIST yaw (heading)
#   Spine/Chest/Neck/Head:   FLEX forward bend, SIDE lateral bend to the left +, TWIST left +
#   Upper arms:              FLEX forward elevation, SIDE elevation in the frontal plane
#                            (0 arm down, 90 T-pose), TWIST horizontal flexion, ROLL axial
#                            rotation (negative = external)
#   Lower arms:              FLEX elbow flexion, TWIST pronation
#   Hands:                   FLEX wrist flexion, SIDE deviation
#   Upper legs:              FLEX hip flexion (thigh forward +), SIDE abduction, TWIST
#   Lower legs:              FLEX knee flexion
#   Feet:                    FLEX dorsiflexion, SIDE inversion
FLEX, SIDE, TWIST, ROLL = 0, 1, 2, 3
CHANNELS = 4
_TORSO = [J["Hips"], J["Spine"], J["Chest"], J["Neck"], J["Head"]]
_MIRROR = [J[n.replace("Left", "\0").replace("Right", "Left").replace("\0", "Right")]
           for n in JOINT_NAMES]

#: The 12 joints the detectors use (Barbič's joint set mapped to this skeleton).
FEATURE_JOINTS = ["Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm",
                  "RightUpperArm", "RightLowerArm", "LeftUpperLeg", "LeftLowerLeg",
                  "RightUpperLeg", "RightLowerLeg"]


def mirror(A: np.ndarray) -> np.ndarray:
    """Left/right mirror image of anatomical angles (…, 17, 4): limbs swap sides, the
    torso's lateral and twist channels change sign (limb channels are defined symmetric)."""
    out = A[..., _MIRROR, :].copy()
    out[..., _TORSO, SIDE] *= -1.0
    out[..., _TORSO, TWIST] *= -1.0
    return out


def local_quats(A: np.ndarray) -> np.ndarray:
    """Local (parent-relative) quaternions (frames, 17, 4), scalar-last, from anatomical
    angles A (frames, 17, 4) in degrees.  Identity angles give the T-pose's identity."""
    A = np.asarray(A, dtype=np.float64)
    n = A.shape[0]
    q = np.empty((n, N_JOINTS, 4))
    f, s, t, r = (A[..., c] for c in (FLEX, SIDE, TWIST, ROLL))
    st = np.stack
    for j in _TORSO:  # yaw, then pitch, then roll: R = Ry(twist) Rx(flex) Rz(-side)
        q[:, j] = quat.from_euler("YXZ", st([t[:, j], f[:, j], -s[:, j]], -1))
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        ua, la, ha = J[side + "UpperArm"], J[side + "LowerArm"], J[side + "Hand"]
        swing = quat.from_euler("XYZ", st([-f[:, ua], -sign * t[:, ua],
                                           sign * (s[:, ua] - 90.0)], -1))
        q[:, ua] = quat.multiply(swing, quat.from_euler("X", r[:, ua, None]))
        q[:, la] = quat.from_euler("YX", st([-sign * f[:, la], t[:, la]], -1))
        q[:, ha] = quat.from_euler("ZY", st([-sign * f[:, ha], -sign * s[:, ha]], -1))
        ul, ll, ft = J[side + "UpperLeg"], J[side + "LowerLeg"], J[side + "Foot"]
        q[:, ul] = quat.from_euler("XZY", st([-f[:, ul], sign * s[:, ul], sign * t[:, ul]], -1))
        q[:, ll] = quat.from_euler("X", f[:, ll, None])
        q[:, ft] = quat.from_euler("XZ", st([-f[:, ft], sign * s[:, ft]], -1))
    return q


def rest_positions() -> np.ndarray:
    """(17, 3) joint locations of the rest pose (T-pose), metres, the root at the origin:
    the take's rest geometry (``rtseg.core.posture.RestPose``): ``joint_positions`` of
    identity rotations."""
    return joint_positions(np.tile(quat.IDENTITY, (1, N_JOINTS, 1)))[0]


def joint_positions(global_q: np.ndarray, root: np.ndarray | None = None) -> np.ndarray:
    """World joint positions (frames, 17, 3) in metres by forward kinematics of the global
    rotations (frames, 17, 4) and the rest offsets; root at ``root`` (frames, 3) or origin."""
    return world_positions(global_q, PARENTS, OFFSETS, root)



__all__ = ["JOINT_NAMES", "PARENTS", "FEATURE_JOINTS", "local_quats", "mirror",
           "joint_positions"]
