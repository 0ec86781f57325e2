"""One motion written in several rigs: the synthetic 17-bone take re-expressed with other
rigs' joint names and hierarchies (extra spine, neck, clavicle and hip joints; a rotation
split across two spine joints; a fixed root above the pelvis), as the families of
``rtseg.core.skeletons`` name them, and as 3ds Max Biped names them (no family).  The segments' rotations relative to the segments they hang
from are the same in every variant, so a rig-independent feature gives the same rows."""

from __future__ import annotations

import numpy as np

from rtseg.core import quat as Q
from rtseg.core.take import Take

# (joint, parent, source): source is a bone of the synthetic take (its local rotation),
# None (identity: a joint that never moves), or ("half1"|"half2", bone): the two halves of
# that bone's rotation, whose product is the rotation.
_LIMBS = {
    "cmu-asf": lambda s: [
        (f"{s}hipjoint", "root", None), (f"{s}femur", f"{s}hipjoint", "{Side}UpperLeg"),
        (f"{s}tibia", f"{s}femur", "{Side}LowerLeg"), (f"{s}foot", f"{s}tibia", "{Side}Foot")],
    "cmu-bvh": lambda S: [
        (f"{S[0]}HipJoint", "Hips", None), (f"{S}UpLeg", f"{S[0]}HipJoint", "{Side}UpperLeg"),
        (f"{S}Leg", f"{S}UpLeg", "{Side}LowerLeg"), (f"{S}Foot", f"{S}Leg", "{Side}Foot")],
    "mixamo": lambda S: [
        (f"mixamorig:{S}UpLeg", "mixamorig:Hips", "{Side}UpperLeg"),
        (f"mixamorig:{S}Leg", f"mixamorig:{S}UpLeg", "{Side}LowerLeg"),
        (f"mixamorig:{S}Foot", f"mixamorig:{S}Leg", "{Side}Foot")],
    "bandai": lambda s: [
        (f"UpperLeg_{s}", "Hips", "{Side}UpperLeg"), (f"LowerLeg_{s}", f"UpperLeg_{s}", "{Side}LowerLeg"),
        (f"Foot_{s}", f"LowerLeg_{s}", "{Side}Foot"), (f"Toes_{s}", f"Foot_{s}", None)],
    "biped": lambda s: [
        (f"Bip01 {s} Thigh", "Bip01 Pelvis", "{Side}UpperLeg"),
        (f"Bip01 {s} Calf", f"Bip01 {s} Thigh", "{Side}LowerLeg"),
        (f"Bip01 {s} Foot", f"Bip01 {s} Calf", "{Side}Foot"), (f"Bip01 {s} Toe0", f"Bip01 {s} Foot", None)],
}
_ARMS = {
    "cmu-asf": lambda s: [
        (f"{s}clavicle", "thorax", None), (f"{s}humerus", f"{s}clavicle", "{Side}UpperArm"),
        (f"{s}radius", f"{s}humerus", "{Side}LowerArm"), (f"{s}wrist", f"{s}radius", None),
        (f"{s}hand", f"{s}wrist", "{Side}Hand")],
    "cmu-bvh": lambda S: [
        (f"{S}Shoulder", "Spine1", None), (f"{S}Arm", f"{S}Shoulder", "{Side}UpperArm"),
        (f"{S}ForeArm", f"{S}Arm", "{Side}LowerArm"), (f"{S}Hand", f"{S}ForeArm", "{Side}Hand")],
    "mixamo": lambda S: [
        (f"mixamorig:{S}Shoulder", "mixamorig:Spine2", None),
        (f"mixamorig:{S}Arm", f"mixamorig:{S}Shoulder", "{Side}UpperArm"),
        (f"mixamorig:{S}ForeArm", f"mixamorig:{S}Arm", "{Side}LowerArm"),
        (f"mixamorig:{S}Hand", f"mixamorig:{S}ForeArm", "{Side}Hand")],
    "bandai": lambda s: [
        (f"Shoulder_{s}", "Chest", None), (f"UpperArm_{s}", f"Shoulder_{s}", "{Side}UpperArm"),
        (f"LowerArm_{s}", f"UpperArm_{s}", "{Side}LowerArm"), (f"Hand_{s}", f"LowerArm_{s}", "{Side}Hand")],
    "biped": lambda s: [
        (f"Bip01 {s} Clavicle", "Bip01 Spine2", None),
        (f"Bip01 {s} UpperArm", f"Bip01 {s} Clavicle", "{Side}UpperArm"),
        (f"Bip01 {s} Forearm", f"Bip01 {s} UpperArm", "{Side}LowerArm"),
        (f"Bip01 {s} Hand", f"Bip01 {s} Forearm", "{Side}Hand")],
}
_TORSO = {
    "cmu-asf": [("root", "", "Hips"), ("lowerback", "root", "Spine"),
                ("upperback", "lowerback", ("half1", "Chest")),
                ("thorax", "upperback", ("half2", "Chest")), ("lowerneck", "thorax", "Neck"),
                ("upperneck", "lowerneck", None), ("head", "upperneck", "Head")],
    "cmu-bvh": [("Hips", "", "Hips"), ("LowerBack", "Hips", "Spine"),
                ("Spine", "LowerBack", ("half1", "Chest")), ("Spine1", "Spine", ("half2", "Chest")),
                ("Neck", "Spine1", "Neck"), ("Neck1", "Neck", None), ("Head", "Neck1", "Head")],
    "mixamo": [("mixamorig:Hips", "", "Hips"), ("mixamorig:Spine", "mixamorig:Hips", "Spine"),
               ("mixamorig:Spine1", "mixamorig:Spine", ("half1", "Chest")),
               ("mixamorig:Spine2", "mixamorig:Spine1", ("half2", "Chest")),
               ("mixamorig:Neck", "mixamorig:Spine2", "Neck"),
               ("mixamorig:Head", "mixamorig:Neck", "Head"),
               ("mixamorig:HeadTop_End", "mixamorig:Head", None)],
    "bandai": [("joint_Root", "", None), ("Hips", "joint_Root", "Hips"), ("Spine", "Hips", "Spine"),
               ("Chest", "Spine", "Chest"), ("Neck", "Chest", "Neck"), ("Head", "Neck", "Head")],
    "biped": [("Bip01", "", None), ("Bip01 Pelvis", "Bip01", "Hips"),
              ("Bip01 Spine", "Bip01 Pelvis", "Spine"),
              ("Bip01 Spine1", "Bip01 Spine", ("half1", "Chest")),
              ("Bip01 Spine2", "Bip01 Spine1", ("half2", "Chest")),
              ("Bip01 Neck", "Bip01 Spine2", "Neck"), ("Bip01 Head", "Bip01 Neck", "Head")],
}
_SIDE_ARG = {"cmu-asf": ("l", "r"), "cmu-bvh": ("Left", "Right"), "mixamo": ("Left", "Right"),
             "bandai": ("L", "R"), "biped": ("L", "R")}
#: rigs of named families (``rtseg.core.skeletons``); ``biped`` (3ds Max Biped: names with
#: spaces, "Bip01 L Thigh") is in no family and is mapped by names and topology
RIGS = ("cmu-asf", "cmu-bvh", "mixamo", "bandai")


def _spec(rig: str) -> list[tuple]:
    out = list(_TORSO[rig])
    for table in (_LIMBS, _ARMS):
        for side, arg in zip(("Left", "Right"), _SIDE_ARG[rig]):
            out += [(j, p, src.replace("{Side}", side) if isinstance(src, str) else src)
                    for j, p, src in table[rig](arg)]
    return out


def in_rig(take: Take, rig: str) -> Take:
    """``take`` (the synthetic 17-bone skeleton, local rotations) written in ``rig``."""
    spec = _spec(rig)
    names = [j for j, _, _ in spec]
    parents = [names.index(p) if p else -1 for _, p, _ in spec]
    q = take.quats
    ident = np.broadcast_to(Q.IDENTITY, q[:, 0].shape)
    cols = []
    for _, _, src in spec:
        if src is None:
            cols.append(ident)
        elif isinstance(src, tuple):
            full = q[:, take.joint_index(src[1])]
            half = Q.slerp(ident, full, np.full(full.shape[0], 0.5))
            cols.append(half if src[0] == "half1" else Q.multiply(Q.conjugate(half), full))
        else:
            cols.append(q[:, take.joint_index(src)])
    return Take(names, parents, take.frame_rate, np.stack(cols, axis=1), take.root_position,
                "local", None, take.length_unit, f"{take.source or 'synth'} as {rig}")
