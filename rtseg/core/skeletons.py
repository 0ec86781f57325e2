"""Named skeleton families: which joint of a rig carries which body segment.

One table per rig family that rtseg reads or receives, keyed by Unity ``HumanBodyBones``
names (the segment names of rtseg's suits): ``Hips`` = pelvis, ``Spine`` = lumbar,
``Chest`` = the thorax the arms hang from, ``Neck``, ``Head``, ``{Side}Shoulder`` =
clavicle, ``{Side}UpperArm`` / ``LowerArm`` / ``Hand``, ``{Side}UpperLeg`` (thigh) /
``LowerLeg`` (shin) / ``Foot`` / ``Toes``.  An entry lists candidate joint names tried in
order; names match case-insensitively after the family's ``prefix`` (a regular
expression, e.g. Mixamo's ``mixamorig:``) is stripped.

Used by :mod:`rtseg.core.rig` (a take's or a stream's skeleton -> rtseg's canonical joints) and
by :mod:`rtseg.simulators.retarget` (a take -> a suit's sensors).

=============  ==========================================================================
``cmu-asf``    CMU / Acclaim ASF/AMC (also HDM05): root, lowerback, upperback, thorax,
               lowerneck, upperneck, head, l/rclavicle, l/rhumerus, l/rradius, l/rfemur, ...
``unity``      Unity humanoid ``HumanBodyBones`` names; VRM / VMC bone names (the same
               names in lowerCamel case); rtseg's synthetic takes and suit sessions
``cmu-bvh``    the CMU BVH conversion "cgspeed" (31 joints): Hips, LowerBack, Spine,
               Spine1, Neck, Neck1, Head, LeftShoulder (clavicle), LeftArm, LeftForeArm, ...
``cmu-bvh-mb`` the other CMU BVH conversion: Hips, Chest, Chest2, LeftCollar (clavicle),
               LeftShoulder (upper arm), LeftElbow, LeftWrist, LeftHip, LeftKnee, LeftAnkle
``mixamo``     Mixamo rigs (``mixamorig:`` / ``mixamorig1:`` prefix optional)
``xsens-mvn``  Xsens MVN segments: Pelvis, L5, L3, T12, T8, Neck, Head, LeftUpperArm, ...
``mocopi``     Sony mocopi: root, torso_1..7, neck_1/2, head, l_up_arm, l_low_arm, ...
``rokoko``     Rokoko Studio body bones: hip, spine, chest, leftUpperArm, leftUpLeg, ...
``daz``        Daz / Poser BVH: hip, abdomen, chest, neck, head, lCollar, lShldr, lThigh, ...
``axis``       Noitom Axis Neuron / Axis Studio: Hips, Spine, Spine1..3, LeftArm, ...
``bandai``     Bandai Namco Research motion dataset: joint_Root, Hips, Spine, Chest, Neck,
               Head, Shoulder_L, UpperArm_L, LowerArm_L, UpperLeg_L, LowerLeg_L, ...
=============  ==========================================================================
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["SkeletonMap", "MAPS", "lookup", "resolve_names", "candidates", "rank_families"]


@dataclass(frozen=True)
class SkeletonMap:
    """A named map: segment (HumanBodyBones name) -> candidate rig joints, tried in order.

    ``prefix``: regular expression stripped from the rig's joint names before matching.
    ``signature``: joints peculiar to the family, used to break ties when two maps resolve
    as many segments."""
    name: str
    description: str
    bones: dict[str, tuple[str, ...]]
    prefix: str = ""
    signature: tuple[str, ...] = ()

    def strip(self, joint: str) -> str:
        return re.sub(self.prefix, "", joint) if self.prefix else joint


def _sides(spec: dict[str, tuple[str, ...]]) -> dict[str, tuple[str, ...]]:
    """Expand ``{Side}`` (Left/Right), ``{s}`` (l/r) and ``{S}`` (L/R) templates."""
    out: dict[str, tuple[str, ...]] = {}
    for bone, cands in spec.items():
        if "{Side}" in bone:
            for side, s in (("Left", "l"), ("Right", "r")):
                out[bone.replace("{Side}", side)] = tuple(
                    c.replace("{Side}", side).replace("{s}", s).replace("{S}", s.upper())
                    for c in cands)
        else:
            out[bone] = cands
    return out


MAPS: dict[str, SkeletonMap] = {m.name: m for m in (
    SkeletonMap(
        "cmu-asf", "CMU / Acclaim ASF/AMC skeleton (31 bones; HDM05 uses the same names)",
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
        "unity", "Unity humanoid HumanBodyBones names, VRM/VMC bones (rtseg's synthetic and suit takes)",
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
        "cmu-bvh-mb", "the other CMU BVH conversion (Chest, Chest2, LeftCollar, LeftShoulder = "
        "upper arm, LeftElbow, LeftHip = thigh, LeftKnee, ...)",
        _sides({
            "Hips": ("Hips",), "Spine": ("Chest",), "Chest": ("Chest2", "Chest3", "Chest4"),
            "UpperChest": ("Chest2",), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("{Side}Collar",), "{Side}UpperArm": ("{Side}Shoulder",),
            "{Side}LowerArm": ("{Side}Elbow",), "{Side}Hand": ("{Side}Wrist",),
            "{Side}UpperLeg": ("{Side}Hip",), "{Side}LowerLeg": ("{Side}Knee",),
            "{Side}Foot": ("{Side}Ankle",), "{Side}Toes": ("{Side}Toe",),
        }),
        signature=("LeftCollar", "RightCollar", "LeftElbow", "LeftKnee", "Chest2")),
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
    SkeletonMap(
        "bandai", "Bandai Namco Research motion dataset rig (joint_Root, Hips, Spine, Chest, "
        "UpperArm_L, LowerArm_L, UpperLeg_L, LowerLeg_L, ...)",
        _sides({
            "Hips": ("Hips",), "Spine": ("Spine",), "Chest": ("Chest",),
            "UpperChest": ("Chest",), "Neck": ("Neck",), "Head": ("Head",),
            "{Side}Shoulder": ("Shoulder_{S}",), "{Side}UpperArm": ("UpperArm_{S}",),
            "{Side}LowerArm": ("LowerArm_{S}",), "{Side}Hand": ("Hand_{S}",),
            "{Side}UpperLeg": ("UpperLeg_{S}",), "{Side}LowerLeg": ("LowerLeg_{S}",),
            "{Side}Foot": ("Foot_{S}",), "{Side}Toes": ("Toes_{S}",),
        }),
        signature=("joint_Root", "UpperArm_L", "UpperLeg_R", "Toes_L")),
)}


def lookup(names: list[str], smap: SkeletonMap) -> dict[str, int]:
    """Lower-cased, prefix-stripped joint name -> first index in ``names``."""
    out: dict[str, int] = {}
    for j, n in enumerate(names):
        out.setdefault(smap.strip(n).lower(), j)
    return out


def candidates(bone: str, smap: SkeletonMap) -> tuple[str, ...]:
    """The map's candidate joints for segment ``bone`` (case-insensitive), () if none."""
    low = bone.lower()
    return next((v for k, v in smap.bones.items() if k.lower() == low), ())


def resolve_names(names: list[str], bones: tuple[str, ...], smap: SkeletonMap) -> list[int]:
    """Index in ``names`` of each of ``bones`` under ``smap`` (-1 where none is found)."""
    look = lookup(names, smap)
    cols = []
    for b in bones:
        cands = candidates(b, smap)
        cols.append(next((look[c.lower()] for c in cands if c.lower() in look), -1))
    return cols


def rank_families(names: list[str], bones: tuple[str, ...]) -> list[tuple[SkeletonMap, int]]:
    """Every family resolving at least one of ``bones``, best first, with its count.

    Best: most of ``bones`` resolved, then most signature joints present, then the order of
    :data:`MAPS` (cmu-asf, unity, cmu-bvh, ...: plain HumanBodyBones names win a tie)."""
    scored = []
    for order, smap in enumerate(MAPS.values()):
        found = sum(c >= 0 for c in resolve_names(names, bones, smap))
        look = lookup(names, smap)
        sig = sum(s.lower() in look for s in smap.signature)
        if found:
            scored.append(((-found, -sig, order), smap, found))
    scored.sort(key=lambda t: t[0])
    return [(smap, found) for _, smap, found in scored]
