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

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.core import quat as Q
from rtseg.core.profiles import SuitProfile
from rtseg.core.skeletons import MAPS, SkeletonMap, candidates, rank_families, resolve_names
from rtseg.core.take import Take

__all__ = ["SkeletonMap", "MAPS", "RetargetError", "ImuModel", "Retargeted",
           "forward_kinematics", "detect_family", "resolve", "retarget"]


class RetargetError(ValueError):
    """A take cannot be mapped onto a suit (names the unmapped bones)."""


def detect_family(take_names: list[str], bones: tuple[str, ...]) -> SkeletonMap:
    """The map resolving most of ``bones`` from ``take_names`` (ties: most signature joints,
    then the order of :data:`MAPS`: cmu-asf, unity, cmu-bvh, mixamo, so plain
    HumanBodyBones names win a tie).  RetargetError if none resolves any."""
    ranked = rank_families(take_names, bones)
    best = ranked[0][0] if ranked else None
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
            smap = None
    cols = resolve_names(names, bones, smap) if smap is not None else [-1] * len(bones)
    fam = smap.name if smap is not None else "topology"
    if family is None and min(cols, default=0) < 0:
        # names alone left bones out: the rig's canonical joints by names and topology
        # (rtseg.core.rig, as the readers map any humanoid rig), when they place more
        topo = topology_columns(take, suit)
        if topo is not None and sum(c >= 0 for c in topo) > sum(c >= 0 for c in cols):
            cols, fam = topo, "topology"
    for k, j in overrides.items():
        cols[k] = j
    if not any(c >= 0 for c in cols):
        raise RetargetError(
            f"take {where}: no joint for any of suit {suit.name!r}'s bones: no known skeleton "
            f"family ({', '.join(MAPS)}) names them and the rig's canonical joints cannot be "
            f"found by names and topology; joints in the take: {', '.join(names)}; pass a "
            f"joint map (suit bone -> take joint)")
    missing = tuple(b for b, c in zip(bones, cols) if c < 0)
    if smap is None:
        smap = MAPS["unity"]
    if missing and not allow_missing:
        wanted = "; ".join(f"{b} (looked for {' or '.join(candidates(b, smap)) or 'nothing: not in the map'})"
                           for b in missing)
        raise RetargetError(
            f"take {where} (skeleton map {smap.name!r}) has no joint for {len(missing)} of "
            f"suit {suit.name!r}'s bones: {wanted}; joints in the take: {', '.join(names)}. "
            f"Map them (suit bone -> take joint) or allow missing sensors")
    return Resolution(fam, tuple(cols), missing)


def topology_columns(take: Take, suit: SuitProfile) -> list[int] | None:
    """``Resolution.columns`` by canonical joints (``rtseg.core.rig.map_rig`` of the suit's
    bones and of the take's joints, by names and topology): each canonical joint's suit bone
    gets the take's, and the first bone below each lower arm and leg (hand, foot) the take's
    first joint below it; other bones -1.  None when either rig cannot be mapped."""
    from rtseg.core.rig import CANONICAL, RigError, map_rig
    sp, tp = [int(p) for p in suit.parents], [int(p) for p in take.parents]
    try:
        rs = map_rig(list(suit.bones), sp)
        rt = map_rig(list(take.joint_names), tp)
    except RigError:
        return None
    cols = [-1] * len(suit.bones)
    for c in CANONICAL:
        cols[rs.index[c]] = rt.index[c]
    ends_t = rt.ends(tp)
    for end, k in rs.ends(sp).items():
        if end in ends_t:
            cols[k] = ends_t[end]
    return cols


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
    minute of take time, about world +Y), ``seed`` (NumPy generator seed); and what a raw
    sensor reports instead of its segment's rotation from the T-pose
    (``rtseg.core.suit_calibration`` undoes it): ``mount_deg`` (each sensor sits on its
    segment turned by a random rotation of up to this many degrees), ``up`` (the sensors'
    world up axis: "y", or "z" as a BNO055's) and ``heading_deg`` (the performer's heading
    in that world)."""
    noise_deg: float = 0.0
    drift_deg_per_min: float = 0.0
    seed: int = 0
    mount_deg: float = 0.0
    up: str = "y"
    heading_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("noise_deg", "drift_deg_per_min", "mount_deg"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"IMU {name} must be a finite number >= 0, got {v}")
        if self.mount_deg > 180:
            raise ValueError(f"IMU mount_deg is at most 180, got {self.mount_deg}")
        if self.up not in ("y", "z"):
            raise ValueError(f"IMU up must be y or z, got {self.up!r}")
        if not np.isfinite(self.heading_deg):
            raise ValueError(f"IMU heading_deg must be finite, got {self.heading_deg}")

    @property
    def enabled(self) -> bool:
        return self.noise_deg > 0 or self.drift_deg_per_min > 0 or self.raw

    @property
    def raw(self) -> bool:
        """Whether the sensors report raw orientations (mounting, up axis or heading)."""
        return self.mount_deg > 0 or self.up != "y" or self.heading_deg != 0

    @classmethod
    def parse(cls, spec: str | None) -> "ImuModel":
        """``"noise=0.5,drift=3,seed=1,mount=180,up=z,heading=40"`` (degrees, degrees per
        minute); empty: no errors."""
        kw: dict[str, float | int | str] = {}
        keys = {"noise": "noise_deg", "drift": "drift_deg_per_min", "seed": "seed",
                "mount": "mount_deg", "up": "up", "heading": "heading_deg"}
        for part in filter(None, (p.strip() for p in (spec or "").split(","))):
            key, eq, val = part.partition("=")
            key = key.strip()
            if not eq or key not in keys:
                raise ValueError(f"IMU spec {spec!r}: expected noise=DEG, drift=DEG_PER_MIN, "
                                 f"seed=N, mount=DEG, up=y|z, heading=DEG, got {part!r}")
            if key == "up":
                kw["up"] = val.strip().lower()
                continue
            try:
                kw[keys[key]] = int(val) if key == "seed" else float(val)
            except ValueError:
                raise ValueError(f"IMU spec {spec!r}: {key} needs a number, got {val!r}") from None
        return cls(**kw)

    def mounts(self, sensors: int) -> np.ndarray:
        """(sensors, 4) each sensor's mounting rotation (uniform axis, angle up to
        ``mount_deg``), deterministic for the seed."""
        rng = np.random.default_rng([self.seed, 1])
        axis = rng.standard_normal((sensors, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        angle = rng.uniform(0.0, np.deg2rad(self.mount_deg), sensors)
        return Rotation.from_rotvec(axis * angle[:, None]).as_quat()

    def apply(self, q: np.ndarray, frame_rate: float) -> np.ndarray:
        """``q`` (frames, sensors, 4) global orientations -> the same with this model's
        errors: drift_y(t) ⊗ q ⊗ noise, then as a raw sensor reports it:
        B^-1 ⊗ that ⊗ mount^-1 (B: ``rtseg.core.suit_calibration``'s, from ``up`` and
        ``heading_deg``).  Deterministic for a given seed and shape."""
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
        if self.raw:
            from rtseg.core.suit_calibration import world_rotation
            b = world_rotation(self.up, self.heading_deg)
            out = Q.multiply(Q.multiply(Q.conjugate(b), out), Q.conjugate(self.mounts(S)))
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

    def bone_offsets(self, rest_positions: np.ndarray) -> np.ndarray:
        """Each sensor's rest location minus its suit parent's (the local positions a VMC
        sender sends), (sensors, 3), from the take's joint rest locations
        ``rest_positions`` (``rtseg.core.posture.RestPose.positions``, the take's units);
        zero for roots and unmapped sensors, and from the nearest mapped ancestor when the
        parent is unmapped."""
        R = np.asarray(rest_positions, dtype=np.float64)
        out = np.zeros((len(self.columns), 3))
        parents = self.suit.parents
        for k, c in enumerate(self.columns):
            p = parents[k]
            while p >= 0 and self.columns[p] < 0:
                p = parents[p]
            if c >= 0 and p >= 0:
                out[k] = R[c] - R[self.columns[p]]
        return out

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
