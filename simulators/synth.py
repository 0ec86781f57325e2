"""Procedural motion synthesiser: the built-in default suit, so a fresh clone needs no data.

A 17-bone HumanBodyBones skeleton (exactly the ``default17`` profile of ``config/suits.toml``)
performs a *script* of behaviours - ``"idle:4,walk:8,punch:6,squat:6"`` (behaviour:seconds) -
joined by smooth blended transitions whose exact frame ranges are returned as ground truth.

Model
-----
Each behaviour is a parametric pattern of *anatomical joint angles* (degrees; see
:data:`CHANNELS`) driven by a phase variable: gait with left/right legs in antiphase and
arms swinging against the legs, punches alternating arms, kicks on one leg, squats, ...
Every instance of a behaviour gets

- its own tempo (+/- 8 %) and a slowly wandering tempo within it (per-cycle jitter),
- a per-cycle amplitude jitter (interpolated smoothly from cycle to cycle) plus a smaller
  independent per-joint amplitude jitter,
- its own small posture offsets (style), on top of a slow whole-take posture drift,

so a behaviour is *stationary* (same statistics throughout, no cuts inside) but never an
exact loop.  Consecutive behaviours are cross-faded in joint-angle space over a blend span
of 0.4-0.8 s (random per transition, C2 "smootherstep" weight); the blend span is the
transition's range.  Global sensor orientations get white sensor noise (``noise_deg``),
the local rotations are recomputed from them, as an IMU suit would deliver them.

Frames and units
----------------
Right-handed, Y up, metres; the performer faces +Z at heading 0, +X is the performer's left.
Rest pose (all local rotations identity) is a T-pose.  Output quaternions are scalar-last
(x, y, z, w), *local* (parent-relative), sign-continuous in time.  The root position
(Hips, metres) keeps the lowest heel/toe on the floor (y = 0) plus flight for jumps, and
advances along the heading for walk/run.

Interface
---------
``synthesize(script=DEFAULT_SCRIPT, frame_rate=120.0, seed=0) -> SynthResult`` with
``take`` (``rtseg.take.Take``), ``segments`` (``Segment(name, start, stop)``, half-open,
tiling the take at the transition mids) and ``transitions`` (``rtseg.labels.Transition``:
``lo..hi`` inclusive = the blended frames, ``mid``, ``before``, ``after``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from rtseg import quat
from rtseg.labels import Transition
from rtseg.take import Take

# --------------------------------------------------------------------------- skeleton

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


def joint_positions(global_q: np.ndarray, root: np.ndarray | None = None) -> np.ndarray:
    """World joint positions (frames, 17, 3) in metres by forward kinematics of the global
    rotations (frames, 17, 4) and the rest offsets; root at ``root`` (frames, 3) or origin."""
    n = global_q.shape[0]
    pos = np.zeros((n, N_JOINTS, 3))
    if root is not None:
        pos[:, 0] = root
    for j in range(1, N_JOINTS):
        p = PARENTS[j]
        pos[:, j] = pos[:, p] + Rotation.from_quat(global_q[:, p]).apply(OFFSETS[j])
    return pos


# --------------------------------------------------------------------------- helpers

def _vm(phi: np.ndarray, mu: float, kappa: float) -> np.ndarray:
    """Periodic bump in [0, 1] centred at phase ``mu`` (radians); larger kappa = narrower."""
    return np.exp(kappa * (np.cos(phi - mu) - 1.0))


def _smooth_noise(rng: np.random.Generator, n: int, corr_frames: float,
                  shape: tuple[int, ...] = ()) -> np.ndarray:
    """Gaussian-smoothed white noise (n, *shape) with unit standard deviation and a
    correlation length of about ``corr_frames`` frames."""
    sigma = max(float(corr_frames), 0.5)
    # Smooth on a coarse grid (4 samples per sigma), then interpolate: same statistics,
    # a fraction of the cost of a long kernel at full rate.
    step = max(1, int(sigma // 4))
    sig_c = sigma / step
    pad = int(4 * sig_c) + 2
    m = n // step + 2
    w = rng.standard_normal((m + 2 * pad,) + shape)
    sm = gaussian_filter1d(w, sig_c, axis=0, mode="wrap")[pad:pad + m]
    sm *= math.sqrt(2.0 * math.sqrt(math.pi) * sig_c)
    if step == 1:
        return sm[:n]
    return CubicSpline(np.arange(m) * step, sm, axis=0)(np.arange(n))


def _smootherstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


# --------------------------------------------------------------------------- behaviours

PoseFn = Callable[[np.ndarray, np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray]]
LiftFn = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Behaviour:
    """One behaviour's pattern.

    period: seconds per cycle of ``phi`` (2π radians), e.g. one stride of both legs.
    pose(phi, t, rng) -> (posture (17, 4), dynamic (frames, 17, 4)): anatomical angles in
        degrees; the dynamic part is scaled by the per-cycle amplitude jitter.
    speed: forward root speed, m/s.  lift(phi): extra root height (m), e.g. jump flight.
    sided: mirrored at random per instance (lead arm / kicking leg).
    """
    name: str
    period: float
    pose: PoseFn
    description: str
    speed: float = 0.0
    lift: LiftFn | None = None
    sided: bool = False
    tempo_jitter: float = 0.05
    amp_jitter: float = 0.08


def _zeros(n: int) -> tuple[np.ndarray, np.ndarray]:
    post = np.zeros((N_JOINTS, CHANNELS))
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 8.0
    post[J["LeftLowerArm"], FLEX] = post[J["RightLowerArm"], FLEX] = 12.0
    post[J["LeftLowerLeg"], FLEX] = post[J["RightLowerLeg"], FLEX] = 3.0
    return post, np.zeros((n, N_JOINTS, CHANNELS))


def _both(d: np.ndarray, joint: str, ch: int, left: np.ndarray, right: np.ndarray) -> None:
    d[:, J["Left" + joint], ch] = left
    d[:, J["Right" + joint], ch] = right


def _idle(phi, t, rng):
    n = len(phi)
    post, d = _zeros(n)
    fr = 1.0 / np.median(np.diff(t)) if n > 1 else 120.0
    look = _smooth_noise(rng, n, 1.2 * fr)          # head looks around
    sway = _smooth_noise(rng, n, 0.8 * fr, (4,))     # small arm / torso wander
    w = np.sin(phi)                                  # weight shift, one cycle per period
    d[:, J["Hips"], SIDE] = 3.0 * w
    d[:, J["Hips"], TWIST] = 2.0 * sway[:, 3]
    _both(d, "UpperLeg", SIDE, -3.0 * w, 3.0 * w)
    _both(d, "LowerLeg", FLEX, 4.0 * np.maximum(0, -w), 4.0 * np.maximum(0, w))
    d[:, J["Spine"], SIDE] = -2.0 * w
    d[:, J["Chest"], SIDE] = -1.0 * w + 1.0 * sway[:, 0]
    d[:, J["Chest"], FLEX] = 1.2 * np.sin(2 * np.pi * 0.27 * t)  # breathing
    d[:, J["Neck"], TWIST] = 6.0 * look
    d[:, J["Head"], TWIST] = 10.0 * look
    d[:, J["Head"], FLEX] = 3.0 * sway[:, 1]
    _both(d, "UpperArm", FLEX, 3.0 * sway[:, 2], 3.0 * sway[:, 1])
    _both(d, "LowerArm", FLEX, 4.0 * sway[:, 0], 4.0 * sway[:, 3])
    return post, d


def _walk(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["Hips"], FLEX] = 3.0
    post[J["Chest"], FLEX] = 2.0
    post[J["Head"], FLEX] = -2.0
    post[J["LeftUpperLeg"], FLEX] = post[J["RightUpperLeg"], FLEX] = 5.0
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 10.0
    post[J["LeftLowerArm"], FLEX] = post[J["RightLowerArm"], FLEX] = 18.0
    for side, ph in (("Left", phi), ("Right", phi + np.pi)):
        d[:, J[side + "UpperLeg"], FLEX] = 22.0 * np.sin(ph)
        d[:, J[side + "LowerLeg"], FLEX] = 55.0 * _vm(ph, -0.2, 3.0) + 12.0 * _vm(ph, 2.2, 6.0)
        d[:, J[side + "Foot"], FLEX] = 8.0 * np.sin(ph - 1.0)
        d[:, J[side + "UpperArm"], FLEX] = 18.0 * np.sin(ph + np.pi)
        d[:, J[side + "LowerArm"], FLEX] = 10.0 * (1.0 + np.sin(ph + np.pi)) / 2.0
    d[:, J["Hips"], FLEX] = 1.5 * np.sin(2 * phi)
    d[:, J["Hips"], SIDE] = 4.0 * np.sin(phi)
    d[:, J["Hips"], TWIST] = 5.0 * np.sin(phi)
    d[:, J["Spine"], TWIST] = -3.0 * np.sin(phi)
    d[:, J["Chest"], TWIST] = -6.0 * np.sin(phi)
    d[:, J["Chest"], FLEX] = 1.0 * np.sin(2 * phi)
    d[:, J["Head"], TWIST] = 3.0 * np.sin(phi)
    d[:, J["Head"], FLEX] = -1.0 * np.sin(2 * phi)
    return post, d


def _run(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["Hips"], FLEX] = 10.0
    post[J["Spine"], FLEX] = 3.0
    post[J["Chest"], FLEX] = 5.0
    post[J["Head"], FLEX] = -10.0
    post[J["LeftUpperLeg"], FLEX] = post[J["RightUpperLeg"], FLEX] = 18.0
    post[J["LeftUpperArm"], SIDE] = post[J["RightUpperArm"], SIDE] = 15.0
    post[J["LeftUpperArm"], FLEX] = post[J["RightUpperArm"], FLEX] = 5.0
    post[J["LeftLowerArm"], FLEX] = post[J["RightLowerArm"], FLEX] = 90.0
    for side, ph in (("Left", phi), ("Right", phi + np.pi)):
        d[:, J[side + "UpperLeg"], FLEX] = 38.0 * np.sin(ph)
        d[:, J[side + "LowerLeg"], FLEX] = 95.0 * _vm(ph, -0.3, 2.5) + 20.0 * _vm(ph, 2.1, 5.0)
        d[:, J[side + "Foot"], FLEX] = 15.0 * np.sin(ph - 1.2)
        d[:, J[side + "UpperArm"], FLEX] = 35.0 * np.sin(ph + np.pi)
        d[:, J[side + "LowerArm"], FLEX] = 15.0 * np.sin(ph + np.pi)
    d[:, J["Hips"], SIDE] = 5.0 * np.sin(phi)
    d[:, J["Hips"], TWIST] = 8.0 * np.sin(phi)
    d[:, J["Spine"], TWIST] = -5.0 * np.sin(phi)
    d[:, J["Chest"], TWIST] = -10.0 * np.sin(phi)
    d[:, J["Chest"], FLEX] = 2.0 * np.sin(2 * phi)
    d[:, J["Head"], TWIST] = 5.0 * np.sin(phi)
    d[:, J["Neck"], FLEX] = -2.0 * np.sin(2 * phi)
    return post, d


def _run_lift(phi):
    return 0.05 * np.maximum(0.0, -np.cos(2 * phi))


_JUMP_PREP, _JUMP_FLIGHT, _JUMP_LAND = 2 * np.pi * 0.25, 2 * np.pi * 0.50, 2 * np.pi * 0.70


def _jump(phi, t, rng):
    post, d = _zeros(len(phi))
    c = _vm(phi, _JUMP_PREP, 6.0)          # crouch before take-off
    fl = _vm(phi, _JUMP_FLIGHT, 20.0)      # airborne tuck
    ld = 0.7 * _vm(phi, _JUMP_LAND, 12.0)  # landing absorption
    for side in ("Left", "Right"):
        d[:, J[side + "UpperLeg"], FLEX] = 65.0 * c + 45.0 * ld + 25.0 * fl
        d[:, J[side + "LowerLeg"], FLEX] = 80.0 * c + 60.0 * ld + 30.0 * fl
        d[:, J[side + "Foot"], FLEX] = 25.0 * c + 18.0 * ld - 30.0 * fl
        d[:, J[side + "UpperArm"], FLEX] = (-35.0 * _vm(phi, 2 * np.pi * 0.22, 5.0)
                                            + 135.0 * _vm(phi, 2 * np.pi * 0.47, 4.0) - 20.0 * ld)
        d[:, J[side + "UpperArm"], SIDE] = 15.0 * fl
        d[:, J[side + "LowerArm"], FLEX] = 15.0 * c
    d[:, J["Hips"], FLEX] = 28.0 * c + 18.0 * ld
    d[:, J["Spine"], FLEX] = 10.0 * c + 5.0 * ld
    d[:, J["Chest"], FLEX] = 6.0 * c - 6.0 * fl
    d[:, J["Head"], FLEX] = -12.0 * c + 5.0 * ld
    return post, d


def _jump_lift(phi):
    u = (phi / (2 * np.pi)) % 1.0
    return 0.30 * np.maximum(0.0, 1.0 - ((u - 0.51) / 0.11) ** 2)


def _punch(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["Hips"], TWIST] = -15.0            # boxing stance, left foot forward
    post[J["Hips"], FLEX] = 5.0
    post[J["Chest"], TWIST] = 8.0
    post[J["Head"], FLEX] = 10.0
    post[J["Head"], TWIST] = 8.0
    post[J["LeftUpperLeg"], FLEX], post[J["RightUpperLeg"], FLEX] = 22.0, 5.0
    post[J["LeftLowerLeg"], FLEX], post[J["RightLowerLeg"], FLEX] = 18.0, 15.0
    post[J["LeftFoot"], FLEX] = post[J["RightFoot"], FLEX] = 10.0
    for side in ("Left", "Right"):
        post[J[side + "UpperArm"], FLEX] = 45.0
        post[J[side + "UpperArm"], SIDE] = 20.0
        post[J[side + "LowerArm"], FLEX] = 115.0
        post[J[side + "Hand"], FLEX] = 10.0
    el = _vm(phi, 2 * np.pi * 0.2, 9.0)    # left jab
    er = _vm(phi, 2 * np.pi * 0.7, 7.0)    # right cross
    for side, e, reach in (("Left", el, 40.0), ("Right", er, 45.0)):
        d[:, J[side + "UpperArm"], FLEX] = reach * e
        d[:, J[side + "UpperArm"], SIDE] = -10.0 * e
        d[:, J[side + "UpperArm"], TWIST] = 12.0 * e
        d[:, J[side + "LowerArm"], FLEX] = -105.0 * e
        d[:, J[side + "LowerArm"], TWIST] = 60.0 * e
    d[:, J["Chest"], TWIST] = 20.0 * er - 8.0 * el
    d[:, J["Spine"], TWIST] = 10.0 * er - 4.0 * el
    d[:, J["Hips"], TWIST] = 8.0 * er
    d[:, J["RightLowerLeg"], FLEX] = 8.0 * er
    d[:, J["RightFoot"], FLEX] = -10.0 * er
    d[:, J["Head"], TWIST] = -6.0 * er
    return post, d


def _kick(phi, t, rng):
    """Front kicks with the right leg (mirrored for left-leg instances)."""
    post, d = _zeros(len(phi))
    for side in ("Left", "Right"):
        post[J[side + "UpperArm"], FLEX] = 40.0
        post[J[side + "UpperArm"], SIDE] = 25.0
        post[J[side + "LowerArm"], FLEX] = 100.0
    post[J["LeftLowerLeg"], FLEX] = 12.0
    k = _vm(phi, np.pi, 5.0)                           # whole kick envelope
    chamber = _vm(phi, np.pi - 0.65, 9.0) + 0.85 * _vm(phi, np.pi + 0.6, 9.0)
    d[:, J["RightUpperLeg"], FLEX] = 78.0 * k
    d[:, J["RightLowerLeg"], FLEX] = 95.0 * chamber + 8.0 * k
    d[:, J["RightFoot"], FLEX] = -25.0 * k
    d[:, J["LeftLowerLeg"], FLEX] = 10.0 * k
    d[:, J["LeftUpperLeg"], FLEX] = 8.0 * k
    d[:, J["LeftFoot"], FLEX] = 8.0 * k
    d[:, J["Hips"], FLEX] = -14.0 * k
    d[:, J["Hips"], SIDE] = 5.0 * k
    d[:, J["Spine"], FLEX] = -6.0 * k
    d[:, J["Chest"], FLEX] = -4.0 * k
    d[:, J["Head"], FLEX] = 10.0 * k
    for side, s in (("Left", 1.0), ("Right", 0.6)):
        d[:, J[side + "UpperArm"], SIDE] = 20.0 * s * k
        d[:, J[side + "UpperArm"], FLEX] = -15.0 * s * k
    return post, d


def _wave(phi, t, rng):
    """Waving with the right hand above shoulder height (mirrored for left-hand instances)."""
    n = len(phi)
    post, d = _zeros(n)
    fr = 1.0 / np.median(np.diff(t)) if n > 1 else 120.0
    slow = _smooth_noise(rng, n, 1.0 * fr, (3,))
    post[J["RightUpperArm"], SIDE] = 100.0
    post[J["RightUpperArm"], TWIST] = 15.0
    post[J["RightUpperArm"], ROLL] = -80.0
    post[J["RightLowerArm"], FLEX] = 85.0
    post[J["Head"], TWIST] = -8.0
    post[J["Chest"], SIDE] = 4.0
    d[:, J["RightLowerArm"], FLEX] = 28.0 * np.sin(phi)
    d[:, J["RightHand"], FLEX] = 15.0 * np.sin(phi + 0.6)
    d[:, J["RightUpperArm"], SIDE] = 5.0 * np.sin(phi + 0.3) + 3.0 * slow[:, 0]
    d[:, J["RightUpperArm"], ROLL] = 6.0 * np.sin(phi)
    d[:, J["Chest"], SIDE] = 1.0 * np.sin(phi)
    d[:, J["Head"], TWIST] = 4.0 * slow[:, 1]
    d[:, J["Head"], SIDE] = 3.0 * slow[:, 2]
    d[:, J["LeftUpperArm"], FLEX] = 2.0 * slow[:, 2]
    return post, d


def _squat(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["LeftUpperLeg"], SIDE] = post[J["RightUpperLeg"], SIDE] = 12.0
    post[J["LeftUpperLeg"], TWIST] = post[J["RightUpperLeg"], TWIST] = 10.0
    s = ((1.0 - np.cos(phi)) / 2.0) ** 0.8   # depth, with a short hold at the bottom
    for side in ("Left", "Right"):
        d[:, J[side + "UpperLeg"], FLEX] = 112.0 * s
        d[:, J[side + "LowerLeg"], FLEX] = 115.0 * s
        d[:, J[side + "Foot"], FLEX] = 32.0 * s
        d[:, J[side + "UpperArm"], FLEX] = 85.0 * s
        d[:, J[side + "LowerArm"], FLEX] = -8.0 * s
    d[:, J["Hips"], FLEX] = 35.0 * s
    d[:, J["Spine"], FLEX] = 6.0 * s
    d[:, J["Chest"], FLEX] = -6.0 * s
    d[:, J["Neck"], FLEX] = -6.0 * s
    d[:, J["Head"], FLEX] = -12.0 * s
    return post, d


def _arm_circles(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["LeftUpperLeg"], SIDE] = post[J["RightUpperLeg"], SIDE] = 8.0
    for side in ("Left", "Right"):
        post[J[side + "UpperArm"], SIDE] = 90.0
        post[J[side + "LowerArm"], FLEX] = 5.0
        d[:, J[side + "UpperArm"], SIDE] = 22.0 * np.sin(phi)
        d[:, J[side + "UpperArm"], TWIST] = 22.0 * np.cos(phi)
        d[:, J[side + "UpperArm"], ROLL] = 6.0 * np.sin(phi)
        d[:, J[side + "LowerArm"], FLEX] = 4.0 * np.cos(phi)
    d[:, J["Chest"], FLEX] = 1.5 * np.sin(phi)
    d[:, J["Neck"], FLEX] = -1.0 * np.sin(phi)
    d[:, J["Spine"], FLEX] = 1.0 * np.cos(phi)
    return post, d


def _side_bend(phi, t, rng):
    post, d = _zeros(len(phi))
    post[J["LeftUpperLeg"], SIDE] = post[J["RightUpperLeg"], SIDE] = 12.0
    b = np.sin(phi)
    d[:, J["Spine"], SIDE] = 15.0 * b
    d[:, J["Chest"], SIDE] = 14.0 * b
    d[:, J["Neck"], SIDE] = 6.0 * b
    d[:, J["Hips"], SIDE] = -4.0 * b
    up_r = ((1.0 + b) / 2.0) ** 1.5   # bending left: right arm overhead
    up_l = ((1.0 - b) / 2.0) ** 1.5
    _both(d, "UpperArm", SIDE, 160.0 * up_l, 160.0 * up_r)
    _both(d, "LowerArm", FLEX, 15.0 * up_l, 15.0 * up_r)
    _both(d, "UpperLeg", SIDE, -3.0 * b, 3.0 * b)
    return post, d


def _jumping_jacks(phi, t, rng):
    post, d = _zeros(len(phi))
    o = (1.0 - np.cos(phi)) / 2.0      # 0 closed, 1 open
    land = _vm(phi, 0.0, 8.0) + _vm(phi, np.pi, 8.0)
    for side in ("Left", "Right"):
        d[:, J[side + "UpperArm"], SIDE] = 160.0 * o
        d[:, J[side + "LowerArm"], FLEX] = 10.0 * o
        d[:, J[side + "UpperLeg"], SIDE] = 16.0 * o
        d[:, J[side + "UpperLeg"], FLEX] = 12.0 * land
        d[:, J[side + "LowerLeg"], FLEX] = 25.0 * land
        d[:, J[side + "Foot"], FLEX] = 12.0 * land - 15.0 * (1 - land)
    d[:, J["Hips"], FLEX] = 5.0 * land
    d[:, J["Head"], FLEX] = -3.0 * land
    return post, d


def _jacks_lift(phi):
    return 0.06 * np.sin(phi) ** 2


BEHAVIOURS: dict[str, Behaviour] = {b.name: b for b in [
    Behaviour("idle", 4.0, _idle, "standing, weight shifting, looking around", amp_jitter=0.15),
    Behaviour("walk", 1.1, _walk, "walking forward, arms swinging against the legs", speed=1.3),
    Behaviour("run", 0.72, _run, "running, forward lean, elbows bent", speed=3.2, lift=_run_lift),
    Behaviour("jump", 1.4, _jump, "repeated vertical jumps with arm swing", lift=_jump_lift,
              tempo_jitter=0.06, amp_jitter=0.10),
    Behaviour("punch", 1.2, _punch, "boxing stance, left jab and right cross alternating",
              sided=True, tempo_jitter=0.07, amp_jitter=0.10),
    Behaviour("kick", 1.7, _kick, "front kicks with one leg from a guard", sided=True,
              tempo_jitter=0.07, amp_jitter=0.10),
    Behaviour("wave", 0.55, _wave, "waving one hand above the shoulder", sided=True),
    Behaviour("squat", 2.6, _squat, "squats with arms forward", amp_jitter=0.08),
    Behaviour("arm_circles", 1.0, _arm_circles, "arms out to the sides, circling"),
    Behaviour("side_bend", 3.0, _side_bend, "lateral trunk bends, opposite arm overhead",
              amp_jitter=0.05),
    Behaviour("jumping_jacks", 1.0, _jumping_jacks, "jumping jacks", lift=_jacks_lift),
]}

DEFAULT_SCRIPT = "idle:5,walk:8,punch:7,squat:8,run:6,wave:6,jump:7,kick:8,arm_circles:7"
#: Shortest behaviour a script may ask for, seconds (a blend needs room on both sides).
MIN_DURATION = 1.5
#: Blend span range, seconds.
BLEND_RANGE = (0.4, 0.8)


# --------------------------------------------------------------------------- scripts

class ScriptError(ValueError):
    """A synthesiser script that cannot be parsed; the message names the item."""


_ITEM_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_\-]*)\s*:\s*([0-9]*\.?[0-9]+(?:[eE][-+]?\d+)?)\s*s?\s*$")


def parse_script(script: str) -> list[tuple[str, float]]:
    """``"idle:4,walk:8"`` -> ``[("idle", 4.0), ("walk", 8.0)]`` (behaviour, seconds).

    Items are separated by commas (or semicolons); a trailing ``s`` on the seconds is
    allowed; names are case-insensitive and ``-`` equals ``_``.  Raises ``ScriptError``
    naming the offending item for unknown behaviours, bad numbers or too-short durations.
    """
    if not isinstance(script, str) or not script.strip():
        raise ScriptError("empty synthesiser script; expected e.g. 'idle:4,walk:8'")
    items = [p for p in re.split(r"[,;]", script)]
    out: list[tuple[str, float]] = []
    for k, item in enumerate(items, 1):
        if not item.strip():
            raise ScriptError(f"script item {k} is empty in {script!r}")
        m = _ITEM_RE.match(item)
        if not m:
            raise ScriptError(f"script item {k} {item.strip()!r}: expected behaviour:seconds, "
                              f"e.g. 'walk:8'")
        name = m.group(1).lower().replace("-", "_")
        if name not in BEHAVIOURS:
            raise ScriptError(f"script item {k} {item.strip()!r}: unknown behaviour {name!r}; "
                              f"known: {', '.join(BEHAVIOURS)}")
        secs = float(m.group(2))
        if not math.isfinite(secs) or secs < MIN_DURATION:
            raise ScriptError(f"script item {k} {item.strip()!r}: duration must be at least "
                              f"{MIN_DURATION} s")
        out.append((name, secs))
    return out


# --------------------------------------------------------------------------- synthesis

@dataclass(frozen=True)
class Segment:
    """One behaviour instance: frames [start, stop) (boundaries at the transition mids)."""
    name: str
    start: int
    stop: int


@dataclass
class SynthResult:
    """A synthetic take and its exact ground truth.

    transitions: ``rtseg.labels.Transition`` per behaviour change; ``lo..hi`` (inclusive)
    are the frames where the two behaviours are blended, ``mid`` the blend's centre.
    """
    take: Take
    segments: list[Segment]
    transitions: list[Transition]
    script: list[tuple[str, float]] = field(default_factory=list)

    def frame_labels(self) -> np.ndarray:
        """Per-frame segment index (int, 0-based), switching at each transition's mid."""
        out = np.zeros(self.take.n_frames, dtype=np.int64)
        for k, seg in enumerate(self.segments):
            out[seg.start:seg.stop] = k
        return out

    def frame_names(self) -> list[str]:
        """Per-frame behaviour names (switching at the transition mids)."""
        names: list[str] = []
        for seg in self.segments:
            names.extend([seg.name] * (seg.stop - seg.start))
        return names


def _instance_track(beh: Behaviour, t: np.ndarray, frame_rate: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles (n, 17, 4), root lift (n,) and speed (n,) of one behaviour instance at times t."""
    n = len(t)
    period = beh.period * (1.0 + 0.08 * float(np.clip(rng.standard_normal(), -2, 2)))
    # Tempo wanders slowly (correlation ~ one cycle): phase = ∫ 2π f dt.
    tempo = 1.0 + beh.tempo_jitter * np.clip(_smooth_noise(rng, n, period * frame_rate), -2.5, 2.5)
    phi = rng.uniform(0, 2 * np.pi) + np.cumsum(2 * np.pi * tempo / (period * frame_rate))
    # Per-cycle amplitude, interpolated smoothly between cycles.
    cyc = np.floor(phi / (2 * np.pi)).astype(np.int64)
    c0 = cyc.min()
    amps = 1.0 + beh.amp_jitter * np.clip(rng.standard_normal(cyc.max() - c0 + 2), -2.5, 2.5)
    frac = phi / (2 * np.pi) - cyc
    w = (1.0 - np.cos(np.pi * frac)) / 2.0
    amp = amps[cyc - c0] * (1 - w) + amps[cyc - c0 + 1] * w
    joint_amp = 1.0 + 0.05 * _smooth_noise(rng, n, 1.5 * period * frame_rate, (N_JOINTS, 1))
    style = rng.normal(0.0, 2.0, (N_JOINTS, CHANNELS))   # per-instance posture offsets, deg
    post, dyn = beh.pose(phi, t, rng)
    A = post[None] + style[None] + amp[:, None, None] * joint_amp * dyn
    if beh.sided and rng.random() < 0.5:
        A = mirror(A)
    lift = beh.lift(phi) * amp if beh.lift is not None else np.zeros(n)
    speed = np.full(n, beh.speed * beh.period / period)   # faster cadence, faster gait
    return A, lift, speed


def synthesize(script: str | list[tuple[str, float]] = DEFAULT_SCRIPT, frame_rate: float = 120.0,
               seed: int = 0, noise_deg: float = 0.3, drift_deg: float = 1.5) -> SynthResult:
    """Synthesise a take performing ``script`` (see :func:`parse_script`).

    frame_rate: Hz.  seed: every random choice (tempo, amplitudes, blend spans, noise)
    derives from it; the same arguments give bit-identical takes.  noise_deg: standard
    deviation of the white sensor noise on each global orientation (degrees per axis).
    drift_deg: standard deviation of the slow whole-take posture drift (degrees).
    """
    items = parse_script(script) if isinstance(script, str) else list(script)
    if not items:
        raise ScriptError("empty synthesiser script")
    for name, secs in items:
        if name not in BEHAVIOURS:
            raise ScriptError(f"unknown behaviour {name!r}; known: {', '.join(BEHAVIOURS)}")
        if secs < MIN_DURATION:
            raise ScriptError(f"{name}:{secs}: duration must be at least {MIN_DURATION} s")
    if not frame_rate > 0:
        raise ValueError(f"frame_rate must be positive, got {frame_rate}")
    master = np.random.SeedSequence([int(seed), 0x5EED])
    seq_inst, seq_blend, seq_take = master.spawn(3)
    blend_rng = np.random.default_rng(seq_blend)
    take_rng = np.random.default_rng(seq_take)

    bounds = np.round(np.cumsum([0.0] + [s for _, s in items]) * frame_rate).astype(np.int64)
    n = int(bounds[-1])
    # Blend spans: [lo, hi] inclusive, centred on each scripted boundary.
    spans: list[tuple[int, int]] = []
    for k in range(1, len(items)):
        width = max(2, int(round(blend_rng.uniform(*BLEND_RANGE) * frame_rate)))
        lo = int(bounds[k]) - width // 2
        spans.append((lo, lo + width - 1))
    time = np.arange(n) / frame_rate

    A = np.zeros((n, N_JOINTS, CHANNELS))
    lift = np.zeros(n)
    speed = np.zeros(n)
    inst_seqs = seq_inst.spawn(len(items))
    for k, (name, _) in enumerate(items):
        a = spans[k - 1][0] if k > 0 else 0
        b = spans[k][1] + 1 if k < len(items) - 1 else n
        rng = np.random.default_rng(inst_seqs[k])
        Ak, lk, sk = _instance_track(BEHAVIOURS[name], time[a:b], frame_rate, rng)
        # Weight of this instance: ramps up over the previous span, down over the next.
        w = np.ones(b - a)
        idx = np.arange(a, b)
        if k > 0:
            lo, hi = spans[k - 1]
            w *= _smootherstep((idx - lo + 1) / (hi - lo + 2))
        if k < len(items) - 1:
            lo, hi = spans[k]
            w *= 1.0 - _smootherstep((idx - lo + 1) / (hi - lo + 2))
        A[a:b] += w[:, None, None] * Ak
        lift[a:b] += w * lk
        speed[a:b] += w * sk

    # Slow whole-take posture drift (a performer never holds exactly the same posture).
    A += drift_deg * _smooth_noise(take_rng, n, 3.0 * frame_rate, (N_JOINTS, CHANNELS))
    heading = 15.0 * _smooth_noise(take_rng, n, 8.0 * frame_rate)
    A[:, J["Hips"], TWIST] += heading

    local = local_quats(A)
    glob = quat.global_from_local(local, PARENTS)
    # Root: lowest heel/toe on the floor plus flight; forward along the heading.
    pos = joint_positions(glob)
    feet = []
    for f in (J["LeftFoot"], J["RightFoot"]):
        rot = Rotation.from_quat(glob[:, f].reshape(-1, 4))
        for p in FOOT_POINTS:
            feet.append(pos[:, f, 1] + rot.apply(p)[:, 1])
    height = -np.min(np.stack(feet, axis=1), axis=1) + lift
    yaw = np.radians(heading)
    step = speed / frame_rate
    root = np.stack([np.cumsum(step * np.sin(yaw)), height, np.cumsum(step * np.cos(yaw))], axis=1)
    root[:, [0, 2]] -= root[0, [0, 2]]

    if noise_deg > 0:
        noise = Rotation.from_rotvec(
            np.radians(noise_deg) * take_rng.standard_normal((n * N_JOINTS, 3))).as_quat()
        glob = quat.multiply(glob, noise.reshape(n, N_JOINTS, 4))
        local = quat.local_from_global(glob, PARENTS)
    local = quat.normalize(local)
    if n:
        local[0] *= np.where(local[0, :, 3:4] < 0, -1.0, 1.0)
    local = quat.make_continuous(local, axis=0)

    transitions = [Transition(lo=lo, hi=hi, mid=int(bounds[k + 1]) if lo <= bounds[k + 1] <= hi
                              else (lo + hi) // 2, before=items[k][0], after=items[k + 1][0])
                   for k, (lo, hi) in enumerate(spans)]
    cuts = [0] + [t.mid for t in transitions] + [n]
    segments = [Segment(items[k][0], cuts[k], cuts[k + 1]) for k in range(len(items))]
    script_text = ",".join(f"{nm}:{s:g}" for nm, s in items)
    take = Take(
        joint_names=list(JOINT_NAMES), parents=list(PARENTS), frame_rate=float(frame_rate),
        quats=local, root_position=root, space="local", length_unit="m",
        source=f"synth:{script_text}#seed={seed}",
        meta={"synth_script": script_text, "synth_seed": int(seed),
              "segments": [[s.name, s.start, s.stop] for s in segments],
              "transitions": [[t.lo, t.mid, t.hi, t.before, t.after] for t in transitions]})
    result = SynthResult(take=take, segments=segments, transitions=transitions, script=items)
    # Per-frame segment index: lets rtseg.labels.labels_from_take score a saved synthetic take.
    take.meta["frame_labels"] = result.frame_labels()
    return result


__all__ = ["synthesize", "parse_script", "SynthResult", "Segment", "Behaviour", "BEHAVIOURS",
           "DEFAULT_SCRIPT", "JOINT_NAMES", "PARENTS", "FEATURE_JOINTS", "ScriptError",
           "local_quats", "mirror", "joint_positions"]
