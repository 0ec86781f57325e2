"""Retargeting: a take's skeleton -> the global orientations of a suit's sensors.

What an IMU suit reports is, per sensor, the **global orientation of the body segment it is
strapped to**.  To replay a recorded take through a simulated suit, each suit bone (Unity
``HumanBodyBones`` names, e.g. ``config/suits.toml`` ``default17``) is given the take joint
that carries the same body segment, through a **named skeleton map** (one per skeleton
family that :func:`rtseg.drivers.readers.read_take` reads), and the take's rotations are
chained through its own hierarchy (forward kinematics) to get that joint's global
orientation.

Skeleton families (:data:`MAPS`; the family is detected from the joint names, or named):

=============  ==========================================================================
``cmu-asf``    CMU / Acclaim ASF/AMC: root, lowerback, thorax, lowerneck, head,
               l/rhumerus, l/rradius, l/rhand, l/rfemur, l/rtibia, l/rfoot
``cmu-bvh``    the CMU BVH conversion ("cgspeed", 31 joints): Hips, LowerBack, Spine1,
               Neck, Head, Left/RightArm, ...ForeArm, ...Hand, ...UpLeg, ...Leg, ...Foot
``mixamo``     Mixamo rigs (``mixamorig:`` / ``mixamorig1:`` prefix optional): Hips, Spine,
               Spine2, Neck, Head, LeftArm, LeftForeArm, LeftHand, LeftUpLeg, LeftLeg, ...
``unity``      Unity humanoid ``HumanBodyBones`` names (also rtseg's own synthetic takes
               and recorded suit sessions): the identity, Chest falls back to UpperChest
``rokoko``     Rokoko Studio body bones: hip, spine, chest, leftUpperArm, leftUpLeg, leftLeg,
               leftToe, ... (sessions recorded from ``rokoko://``)
``daz``        Daz / Poser BVH (CMU's Daz-friendly conversion): hip, abdomen, chest, neck,
               head, l/rCollar, l/rShldr, l/rForeArm, l/rHand, l/rThigh, l/rShin, l/rFoot
``axis``       Axis Neuron / Axis Studio BVH: Hips, Spine, Spine1..3 (Chest = Spine3),
               LeftArm, LeftForeArm, LeftUpLeg, LeftLeg, ... and finger joints
=============  ==========================================================================

Names match case-insensitively.  A map entry lists candidate joints tried in order.  The
segment each suit bone gets: Hips = pelvis; Spine = lumbar (CMU ``lowerback``); Chest =
the thorax the arms hang from (CMU ``thorax``, CMU-BVH ``Spine1``, Mixamo ``Spine2``); Neck
= lower neck; UpperArm / LowerArm / Hand; UpperLeg (thigh) / LowerLeg (shin) / Foot.

Frames and conventions: rotations scalar-last (x, y, z, w), rtseg's right-handed Y-up
world.  ASF/AMC and BVH local rotations are relative to the parent in world-aligned
frames (rest pose = identity), so forward kinematics gives each segment's rotation from
its rest (T-)pose in the world: exactly what a calibrated IMU reports (a fixed mounting
offset would only change the calibration the live loop takes anyway).

IMU imperfections (optional, seeded, :class:`ImuModel`): white orientation noise (a random
rotation with ``noise_deg`` standard deviation per axis, applied in the sensor frame each
frame) and heading drift (each sensor's heading, i.e. rotation about world +Y, drifts at a
constant rate drawn uniformly from ``[-drift, +drift]`` degrees per minute, applied in the
world frame), as magnetometer-free IMUs drift in yaw.  The same seed gives the same stream.

A suit bone that the map cannot resolve is a :class:`RetargetError` naming every
unmapped bone and the joints looked for, unless ``allow_missing`` (those sensors are
then never sent).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg import quat as Q
from rtseg.profiles import SuitProfile
from rtseg.take import Take

__all__ = ["SkeletonMap", "MAPS", "RetargetError", "ImuModel", "Retargeted",
           "forward_kinematics", "detect_family", "resolve", "retarget"]


class RetargetError(ValueError):
    """A take cannot be mapped onto a suit (names the unmapped bones)."""


@dataclass(frozen=True)
class SkeletonMap:
    """A named map: suit bone (HumanBodyBones) -> candidate take joints, tried in order.

    ``prefix``: regular expression stripped from the take's joint names before matching
    (e.g. Mixamo's ``mixamorig:``).  ``signature``: joints peculiar to the family, used to
    break ties when two maps resolve as many bones."""
    name: str
    description: str
    bones: dict[str, tuple[str, ...]]
    prefix: str = ""
    signature: tuple[str, ...] = ()

    def strip(self, joint: str) -> str:
        return re.sub(self.prefix, "", joint) if self.prefix else joint


def _sides(spec: dict[str, tuple[str, ...]]) -> dict[str, tuple[str, ...]]:
    """Expand ``{Left}``/``{l}`` templates into the Left* and Right* entries."""
    out: dict[str, tuple[str, ...]] = {}
    for bone, cands in spec.items():
        if "{Side}" in bone:
            for side, s in (("Left", "l"), ("Right", "r")):
                out[bone.replace("{Side}", side)] = tuple(
                    c.replace("{Side}", side).replace("{s}", s) for c in cands)
        else:
            out[bone] = cands
    return out


MAPS: dict[str, SkeletonMap] = {m.name: m for m in (
    SkeletonMap(
        "cmu-asf", "CMU / Acclaim ASF/AMC skeleton (31 bones)",
        _sides({
            "Hips": ("root",), "Spine": ("lowerback",), "Chest": ("thorax", "upperback"),
            "UpperChest": ("thorax",), "Neck": ("lowerneck", "upperneck"), "Head": ("head",),
            "{Side}Shoulder": ("{s}clavicle",), "{Side}UpperArm": ("{s}humerus",),
            "{Side}LowerArm": ("{s}radius",), "{Side}Hand": ("{s}hand", "{s}wrist"),
            "{Side}UpperLeg": ("{s}femur",), "{Side}LowerLeg": ("{s}tibia",),
            "{Side}Foot": ("{s}foot",), "{Side}Toes": ("{s}toes",),
        }),
        signature=("lhumerus", "rhumerus", "lfemur", "rfemur", "thorax")),
    SkeletonMap(
        "unity", "Unity humanoid HumanBodyBones names (rtseg's synthetic and suit takes)",
        _sides({
            "Hips": ("Hips",), "Spine": ("Spine",), "Chest": ("Chest", "UpperChest"),
            "UpperChest": ("UpperChest", "Chest"), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("{Side}Shoulder",), "{Side}UpperArm": ("{Side}UpperArm",),
            "{Side}LowerArm": ("{Side}LowerArm",), "{Side}Hand": ("{Side}Hand",),
            "{Side}UpperLeg": ("{Side}UpperLeg",), "{Side}LowerLeg": ("{Side}LowerLeg",),
            "{Side}Foot": ("{Side}Foot",), "{Side}Toes": ("{Side}Toes",),
        }),
        signature=("LeftUpperArm", "RightUpperArm", "LeftUpperLeg", "RightUpperLeg")),
    SkeletonMap(
        "cmu-bvh", "CMU BVH conversion (cgspeed, 31 joints)",
        _sides({
            "Hips": ("Hips",), "Spine": ("LowerBack",), "Chest": ("Spine1",),
            "UpperChest": ("Spine1",), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("{Side}Shoulder",), "{Side}UpperArm": ("{Side}Arm",),
            "{Side}LowerArm": ("{Side}ForeArm",), "{Side}Hand": ("{Side}Hand",),
            "{Side}UpperLeg": ("{Side}UpLeg",), "{Side}LowerLeg": ("{Side}Leg",),
            "{Side}Foot": ("{Side}Foot",), "{Side}Toes": ("{Side}ToeBase",),
        }),
        signature=("LowerBack", "LHipJoint", "RHipJoint", "Neck1")),
    SkeletonMap(
        "mixamo", "Mixamo rig (mixamorig: prefix optional)",
        _sides({
            "Hips": ("Hips",), "Spine": ("Spine",), "Chest": ("Spine2",),
            "UpperChest": ("Spine2",), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("{Side}Shoulder",), "{Side}UpperArm": ("{Side}Arm",),
            "{Side}LowerArm": ("{Side}ForeArm",), "{Side}Hand": ("{Side}Hand",),
            "{Side}UpperLeg": ("{Side}UpLeg",), "{Side}LowerLeg": ("{Side}Leg",),
            "{Side}Foot": ("{Side}Foot",), "{Side}Toes": ("{Side}ToeBase",),
        }),
        prefix=r"^mixamorig\d*:", signature=("Spine2", "HeadTop_End")),
    SkeletonMap(
        "xsens-mvn", "Xsens MVN segments (MVNX labels; also the xsens-mvn suit's L3/T12)",
        _sides({
            "Hips": ("Pelvis",), "Spine": ("L5",), "L3": ("L3",), "T12": ("T12",),
            "Chest": ("T8",), "UpperChest": ("T8",), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("{Side}Shoulder",), "{Side}UpperArm": ("{Side}UpperArm",),
            "{Side}LowerArm": ("{Side}ForeArm", "{Side}LowerArm"),
            "{Side}Hand": ("{Side}Hand",), "{Side}UpperLeg": ("{Side}UpperLeg",),
            "{Side}LowerLeg": ("{Side}LowerLeg",), "{Side}Foot": ("{Side}Foot",),
            "{Side}Toes": ("{Side}Toe", "{Side}Toes"),
        }),
        signature=("Pelvis", "L5", "L3", "T12", "T8")),
    SkeletonMap(
        "mocopi", "Sony mocopi bones (root, torso_1..7, neck_1/2, l_up_arm ...)",
        {
            "Hips": ("root",), "Spine": ("torso_2",), "Chest": ("torso_4",),
            "UpperChest": ("torso_6",), "Neck": ("neck_1",), "Head": ("head",),
            **{f"torso_{k}": (f"torso_{k}",) for k in (1, 3, 5, 7)}, "neck_2": ("neck_2",),
            **{f"{side}{hbb}": (f"{s}_{m}",) for side, s in (("Left", "l"), ("Right", "r"))
               for hbb, m in (("Shoulder", "shoulder"), ("UpperArm", "up_arm"),
                              ("LowerArm", "low_arm"), ("Hand", "hand"),
                              ("UpperLeg", "up_leg"), ("LowerLeg", "low_leg"),
                              ("Foot", "foot"), ("Toes", "toes"))},
        },
        signature=("torso_1", "torso_7", "neck_2", "l_up_arm", "r_low_leg")),
    SkeletonMap(
        "rokoko", "Rokoko Studio body bones (hip, spine, chest, leftUpperArm, leftUpLeg, ...; "
        "sessions recorded from rokoko://)",
        _sides({
            "Hips": ("hip",), "Spine": ("spine",), "Chest": ("chest",),
            "UpperChest": ("chest",), "Neck": ("neck",), "Head": ("head",),
            "{Side}Shoulder": ("{Side}Shoulder",), "{Side}UpperArm": ("{Side}UpperArm",),
            "{Side}LowerArm": ("{Side}LowerArm",), "{Side}Hand": ("{Side}Hand",),
            "{Side}UpperLeg": ("{Side}UpLeg",), "{Side}LowerLeg": ("{Side}Leg",),
            "{Side}Foot": ("{Side}Foot",), "{Side}Toes": ("{Side}Toe",),
        }),
        signature=("hip", "leftUpLeg", "rightUpLeg", "leftToe", "rightToe")),
    SkeletonMap(
        "daz", "Daz / Poser BVH rigs (CMU's Daz-friendly conversion: hip, abdomen, chest, "
        "lShldr, lForeArm, lThigh, lShin, ...)",
        _sides({
            "Hips": ("hip",), "Spine": ("abdomen",), "Chest": ("chest",),
            "UpperChest": ("chest",), "Neck": ("neck",), "Head": ("head",),
            "{Side}Shoulder": ("{s}Collar",), "{Side}UpperArm": ("{s}Shldr",),
            "{Side}LowerArm": ("{s}ForeArm",), "{Side}Hand": ("{s}Hand",),
            "{Side}UpperLeg": ("{s}Thigh",), "{Side}LowerLeg": ("{s}Shin",),
            "{Side}Foot": ("{s}Foot",),
        }),
        signature=("abdomen", "lShldr", "rShldr", "lThigh", "rShin")),
    SkeletonMap(
        "axis", "Noitom Axis Neuron / Axis Studio BVH (59 joints: Spine..Spine3, fingers)",
        _sides({
            "Hips": ("Hips",), "Spine": ("Spine",), "Chest": ("Spine3", "Spine2"),
            "UpperChest": ("Spine3",), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("{Side}Shoulder",), "{Side}UpperArm": ("{Side}Arm",),
            "{Side}LowerArm": ("{Side}ForeArm",), "{Side}Hand": ("{Side}Hand",),
            "{Side}UpperLeg": ("{Side}UpLeg",), "{Side}LowerLeg": ("{Side}Leg",),
            "{Side}Foot": ("{Side}Foot",),
        }),
        signature=("Spine3", "RightInHandIndex", "LeftInHandIndex", "RightHandThumb1")),
)}


# --------------------------------------------------------------------------- resolution

def _lookup(take_names: list[str], smap: SkeletonMap) -> dict[str, int]:
    """Lower-cased, prefix-stripped joint name -> first take index."""
    out: dict[str, int] = {}
    for j, n in enumerate(take_names):
        out.setdefault(smap.strip(n).lower(), j)
    return out


def _resolve_with(take_names: list[str], bones: tuple[str, ...], smap: SkeletonMap
                  ) -> list[int]:
    look = _lookup(take_names, smap)
    cols = []
    for b in bones:
        cands = _candidates(b, smap)
        cols.append(next((look[c.lower()] for c in cands if c.lower() in look), -1))
    return cols


def _candidates(bone: str, smap: SkeletonMap) -> tuple[str, ...]:
    """The map's candidate joints for suit ``bone`` (case-insensitive), () if none."""
    low = bone.lower()
    return next((v for k, v in smap.bones.items() if k.lower() == low), ())


def detect_family(take_names: list[str], bones: tuple[str, ...]) -> SkeletonMap:
    """The map resolving most of ``bones`` from ``take_names`` (ties: most signature joints,
    then the order of :data:`MAPS`: cmu-asf, unity, cmu-bvh, mixamo, so plain
    HumanBodyBones names win a tie).  RetargetError if none resolves any."""
    best, best_key = None, (0, 0)
    for smap in MAPS.values():
        found = sum(c >= 0 for c in _resolve_with(take_names, bones, smap))
        look = _lookup(take_names, smap)
        sig = sum(s.lower() in look for s in smap.signature)
        key = (found, sig)
        if found and key > best_key:
            best, best_key = smap, key
    if best is None:
        raise RetargetError(
            f"no known skeleton family ({', '.join(MAPS)}) names any of the suit's bones "
            f"({', '.join(bones)}) in joints {', '.join(take_names)}; pass a joint map "
            f"(suit bone -> take joint)")
    return best


@dataclass(frozen=True)
class Resolution:
    """Which take joint drives each suit sensor.  ``columns[k]``: take joint index for suit
    bone k, -1 when unmapped (only with ``allow_missing``)."""
    family: str
    columns: tuple[int, ...]
    missing: tuple[str, ...]


def resolve(take: Take, suit: SuitProfile, family: str | None = None,
            joint_map: dict[str, str] | None = None, allow_missing: bool = False) -> Resolution:
    """Map each of ``suit``'s bones to a take joint.

    ``family``: a name of :data:`MAPS` (default: detected, :func:`detect_family`).
    ``joint_map``: overrides, suit bone -> take joint name (case-insensitive).  Raises
    RetargetError naming every unmapped suit bone (and the joints looked for) unless
    ``allow_missing``."""
    names = list(take.joint_names)
    where = take.source or "<memory>"
    bones = tuple(suit.bones)
    low_bones = {b.lower(): k for k, b in enumerate(bones)}
    overrides: dict[int, int] = {}
    low_names = {n.lower(): j for j, n in reversed(list(enumerate(names)))}
    for bone, joint in (joint_map or {}).items():
        k = low_bones.get(str(bone).lower())
        if k is None:
            raise RetargetError(f"joint map key {bone!r} is not a bone of suit {suit.name!r} "
                                f"({', '.join(bones)}); the map goes suit bone -> take joint")
        j = low_names.get(str(joint).lower())
        if j is None:
            raise RetargetError(f"joint map {bone}={joint}: take {where} has no joint "
                                f"{joint!r}; its joints: {', '.join(names)}")
        overrides[k] = j
    if family is not None:
        if family not in MAPS:
            raise RetargetError(f"unknown skeleton map {family!r}; known: {', '.join(MAPS)}")
        smap = MAPS[family]
    elif len(overrides) == len(bones):
        smap = MAPS["unity"]
    else:
        rest = tuple(b for k, b in enumerate(bones) if k not in overrides)
        try:
            smap = detect_family(names, rest)
        except RetargetError:
            if not allow_missing:
                raise RetargetError(
                    f"take {where}: no known skeleton family ({', '.join(MAPS)}) names any "
                    f"of suit {suit.name!r}'s bones {', '.join(rest)}; joints in the take: "
                    f"{', '.join(names)}; pass a joint map (suit bone -> take joint)") from None
            smap = MAPS["unity"]
    cols = _resolve_with(names, bones, smap)
    for k, j in overrides.items():
        cols[k] = j
    missing = tuple(b for b, c in zip(bones, cols) if c < 0)
    if missing and not allow_missing:
        wanted = "; ".join(f"{b} (looked for {' or '.join(_candidates(b, smap)) or 'nothing: not in the map'})"
                           for b in missing)
        raise RetargetError(
            f"take {where} (skeleton map {smap.name!r}) has no joint for {len(missing)} of "
            f"suit {suit.name!r}'s bones: {wanted}; joints in the take: {', '.join(names)}. "
            f"Map them (suit bone -> take joint) or allow missing sensors")
    return Resolution(smap.name, tuple(cols), missing)


# --------------------------------------------------------------------------- kinematics

def forward_kinematics(take: Take) -> np.ndarray:
    """Global orientation of every take joint, (frames, joints, 4) scalar-last, unit.

    ``space="local"``: chained from the root, global_j = global_parent(j) ⊗ local_j.
    ``space="global"``: the take's own rotations (normalised)."""
    q = take.quats
    if take.space == "local":
        q = Q.global_from_local(q, list(take.parents))
    return Q.normalize(q)


# --------------------------------------------------------------------------- IMU model

@dataclass(frozen=True)
class ImuModel:
    """IMU imperfections: ``noise_deg`` (std of a white per-axis orientation error, degrees,
    sensor frame), ``drift_deg_per_min`` (heading drift rates drawn from ±this, degrees per
    minute of take time, about world +Y), ``seed`` (NumPy generator seed)."""
    noise_deg: float = 0.0
    drift_deg_per_min: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("noise_deg", "drift_deg_per_min"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"IMU {name} must be a finite number >= 0, got {v}")

    @property
    def enabled(self) -> bool:
        return self.noise_deg > 0 or self.drift_deg_per_min > 0

    @classmethod
    def parse(cls, spec: str | None) -> "ImuModel":
        """``"noise=0.5,drift=3,seed=1"`` (degrees, degrees per minute); empty: no errors."""
        kw: dict[str, float | int] = {}
        keys = {"noise": "noise_deg", "drift": "drift_deg_per_min", "seed": "seed"}
        for part in filter(None, (p.strip() for p in (spec or "").split(","))):
            key, eq, val = part.partition("=")
            if not eq or key.strip() not in keys:
                raise ValueError(f"IMU spec {spec!r}: expected noise=DEG, drift=DEG_PER_MIN, "
                                 f"seed=N, got {part!r}")
            try:
                kw[keys[key.strip()]] = int(val) if key.strip() == "seed" else float(val)
            except ValueError:
                raise ValueError(f"IMU spec {spec!r}: {key} needs a number, got {val!r}") from None
        return cls(**kw)

    def apply(self, q: np.ndarray, frame_rate: float) -> np.ndarray:
        """``q`` (frames, sensors, 4) global orientations -> the same with this model's
        errors: drift_y(t) ⊗ q ⊗ noise.  Deterministic for a given seed and shape."""
        if not self.enabled:
            return q
        F, S = q.shape[:2]
        rng = np.random.default_rng(self.seed)
        rates = rng.uniform(-1.0, 1.0, S) * np.deg2rad(self.drift_deg_per_min) / 60.0
        noise = rng.standard_normal((F, S, 3)) * np.deg2rad(self.noise_deg)
        out = q
        if self.drift_deg_per_min > 0:
            yaw = (np.arange(F) / frame_rate)[:, None] * rates[None, :]       # (F, S) rad
            drift = np.zeros((F, S, 4))
            drift[..., 1] = np.sin(yaw / 2)
            drift[..., 3] = np.cos(yaw / 2)
            out = Q.multiply(drift, out)
        if self.noise_deg > 0:
            n = Rotation.from_rotvec(noise.reshape(-1, 3)).as_quat().reshape(F, S, 4)
            out = Q.multiply(out, n)
        return Q.make_continuous(Q.normalize(out), axis=0)


# --------------------------------------------------------------------------- result

@dataclass
class Retargeted:
    """A take as a suit's sensors.  ``quats`` (frames, sensors, 4) global orientations,
    scalar-last, in suit order; ``valid`` (frames, sensors) bool; ``present`` (sensors,)
    the sensor is mapped; ``family`` the skeleton map used; ``columns`` take joint per
    sensor (-1 unmapped); ``frame_rate`` Hz of the take."""
    suit: SuitProfile
    quats: np.ndarray
    valid: np.ndarray
    present: np.ndarray
    family: str
    columns: tuple[int, ...]
    frame_rate: float
    meta: dict = field(default_factory=dict)

    def local(self) -> np.ndarray:
        """Rotations relative to the suit's parent bones (what VMC sends):
        q_parent⁻¹ ⊗ q_child, (frames, sensors, 4), sign-continuous in time."""
        return Q.make_continuous(Q.local_from_global(self.quats, list(self.suit.parents)), 0)

    def describe(self, take_names: list[str]) -> str:
        pairs = [f"{b}<-{take_names[c]}" for b, c in zip(self.suit.bones, self.columns) if c >= 0]
        miss = [b for b, c in zip(self.suit.bones, self.columns) if c < 0]
        text = f"skeleton map {self.family}: " + ", ".join(pairs)
        return text + (f"; not sent: {', '.join(miss)}" if miss else "")


def retarget(take: Take, suit: SuitProfile, family: str | None = None,
             joint_map: dict[str, str] | None = None, imu: ImuModel | None = None,
             allow_missing: bool = False) -> Retargeted:
    """The suit's sensor orientations over the whole take (see the module docstring)."""
    res = resolve(take, suit, family, joint_map, allow_missing)
    cols = np.array(res.columns)
    present = cols >= 0
    g = forward_kinematics(take)
    S = len(suit.bones)
    quats = np.tile(Q.IDENTITY, (take.n_frames, S, 1))
    quats[:, present] = g[:, cols[present]]
    valid = np.zeros((take.n_frames, S), dtype=bool)
    if take.valid is None:
        valid[:, present] = True
    else:
        # a sensor reports only when its joint and every joint above it were measured
        chain_ok = take.valid.copy()
        if take.space == "local":
            for j, p in enumerate(take.parents):
                if p >= 0:
                    chain_ok[:, j] &= chain_ok[:, p]
        valid[:, present] = chain_ok[:, cols[present]]
    quats = Q.make_continuous(quats, axis=0)
    if imu is not None and imu.enabled:
        quats = imu.apply(quats, take.frame_rate)
    return Retargeted(suit, quats, valid, present, res.family, res.columns, take.frame_rate)
