"""Any humanoid rig -> rtseg's canonical skeleton.

rtseg's pose features describe the same twelve body segments on every rig, each by its
rotation relative to the segment it hangs from (its *canonical parent*):

==================  ==================  ================================================
canonical joint     canonical parent    segment
==================  ==================  ================================================
spine               pelvis              lumbar spine (the first joint above the pelvis)
chest               spine               the thorax the arms hang from
neck                chest               the first joint above the chest towards the head
head                neck                the head
left/right_upper_arm  chest             humerus
left/right_lower_arm  upper arm         forearm
left/right_upper_leg  pelvis            thigh
left/right_lower_leg  upper leg         shin
==================  ==================  ================================================

The rig's joints that lie between a canonical joint and its canonical parent (an upper
spine, a clavicle, a second neck joint, CMU's ``lhipjoint``) are *optional*: they are
composed into the canonical joint's rotation, so ``chest`` relative to ``spine`` is the
same physical rotation whether the rig has one spine joint or three.  The pelvis (the
root's orientation, the heading) is no feature, as in Barbič et al. 2004.

How a rig is mapped (:func:`map_rig`):

1. **By name**: the named families of :mod:`rtseg.core.skeletons` (CMU ASF, the two CMU BVH
   conversions, Mixamo, Unity / VRM / VMC, Xsens MVN, mocopi, Rokoko, Daz / Poser, Axis,
   Bandai) give the head and the four limbs' upper and lower joints.
2. **By names and topology** for a rig no family knows: joint names are split into a side
   (``Left``/``L_``/``_L``/``l`` prefix...) and a part (``forearm``, ``elbow``, ``shin``,
   ``knee``, ``thigh``...); a lower limb joint is found by its part, the upper one is the
   joint it hangs from (twist and roll helpers skipped); left and right must be distinct
   chains.
3. **The torso by topology**, for every rig: pelvis = the joint the two thighs branch
   from, chest = the joint the two arm chains branch from, spine = the first joint on the
   way from pelvis to chest, neck = the first joint on the way from chest to head.

A rig that cannot be mapped raises :class:`RigError` with one line naming what is
missing; there is no silent fall-back to every joint.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Sequence

from rtseg.core.skeletons import rank_families, resolve_names

__all__ = ["CANONICAL", "CANONICAL_PARENT", "END_OF", "FEATURE_JOINTS", "Rig", "RigError",
           "map_rig"]

SIDES = ("left", "right")
#: each limb's end (the first joint below its lower part: wrist, ankle) -> that lower part
END_OF: dict[str, str] = {f"{s}_{end}": f"{s}_{low}" for s in SIDES
                          for end, low in (("hand", "lower_arm"), ("foot", "lower_leg"))}
LIMBS = tuple(f"{s}_{p}" for p in ("upper_arm", "lower_arm", "upper_leg", "lower_leg")
              for s in SIDES)
#: Every canonical joint (pelvis first).
CANONICAL: tuple[str, ...] = ("pelvis", "spine", "chest", "neck", "head", *LIMBS)
#: The joints that make the feature vector, in feature order (4 values each).
FEATURE_JOINTS: tuple[str, ...] = CANONICAL[1:]
CANONICAL_PARENT: dict[str, str] = {
    "spine": "pelvis", "chest": "spine", "neck": "chest", "head": "neck",
    **{f"{s}_upper_arm": "chest" for s in SIDES},
    **{f"{s}_lower_arm": f"{s}_upper_arm" for s in SIDES},
    **{f"{s}_upper_leg": "pelvis" for s in SIDES},
    **{f"{s}_lower_leg": f"{s}_upper_leg" for s in SIDES},
}
# canonical limb / head joint -> the HumanBodyBones name of rtseg.core.skeletons' tables
_HBB = {"head": "Head", **{f"{s}_{p}": f"{s.title()}{h}" for s in SIDES
                           for p, h in (("upper_arm", "UpperArm"), ("lower_arm", "LowerArm"),
                                        ("upper_leg", "UpperLeg"), ("lower_leg", "LowerLeg"))}}
_NAMED = tuple(_HBB)                     # found by name: head and the eight limb joints


class RigError(ValueError):
    """A skeleton that cannot be mapped to the canonical joints (the message says what)."""


@dataclass(frozen=True)
class Rig:
    """A rig mapped to the canonical skeleton.

    ``family``: the named family used (``rtseg.core.skeletons.MAPS``), or ``"topology"``.
    ``joints``: canonical joint -> rig joint name.  ``index``: canonical joint -> rig joint
    index.  ``paths[k]``: for feature joint ``FEATURE_JOINTS[k]``, the rig joint indices
    from just below its canonical parent down to the joint itself (the rotations composed;
    length 1 when the joint hangs directly from its canonical parent).  ``optional``: rig
    joints composed in that way (canonical joint -> names)."""
    family: str
    joints: dict[str, str]
    index: dict[str, int]
    paths: tuple[tuple[int, ...], ...]
    optional: dict[str, tuple[str, ...]] = field(default_factory=dict)

    @property
    def feature_indices(self) -> list[int]:
        return [self.index[j] for j in FEATURE_JOINTS]

    def ends(self, parents: Sequence[int]) -> dict[str, int]:
        """The limbs' ends: ``END_OF``'s hand or foot -> the rig joint just below its lower
        arm or leg (the first one, in joint order, whose parent it is; ``parents`` of the rig
        this was mapped from); an end the rig has no joint for is left out."""
        out = {}
        for end, low in END_OF.items():
            below = [k for k, p in enumerate(parents) if p == self.index[low]]
            if below:
                out[end] = below[0]
        return out

    def report(self) -> dict:
        """JSON-ready description: family, canonical -> rig joint, composed joints."""
        return {"rig": self.family, "joints": dict(self.joints),
                "composed": {k: list(v) for k, v in self.optional.items() if v}}

    def summary(self) -> str:
        """One line for a log: the family and the mapping."""
        pairs = ", ".join(f"{c}={self.joints[c]}" for c in CANONICAL)
        return f"rig {self.family}: {pairs}"


# ------------------------------------------------------------------------ topology helpers

def _ancestors(j: int, parents: Sequence[int]) -> list[int]:
    """j, its parent, ... up to the root."""
    out = []
    seen = set()
    while j >= 0 and j not in seen:
        seen.add(j)
        out.append(j)
        j = parents[j]
    return out


def _lca(a: int, b: int, parents: Sequence[int]) -> int:
    up = set(_ancestors(a, parents))
    for j in _ancestors(b, parents):
        if j in up:
            return j
    return -1


def _path_below(top: int, j: int, parents: Sequence[int]) -> tuple[int, ...] | None:
    """Joints from just below ``top`` down to ``j`` (top-down), None if j is not below top."""
    chain = _ancestors(j, parents)
    if top not in chain or top == j:
        return None
    return tuple(reversed(chain[:chain.index(top)]))


# ------------------------------------------------------------------------ names

_SIDE_PATTERNS = (
    (re.compile(r"^(left|l)(?=[_.\- ]|[A-Z])"), 0), (re.compile(r"^(right|r)(?=[_.\- ]|[A-Z])"), 1),
    (re.compile(r"[_.\- ](l|left)$", re.I), 0), (re.compile(r"[_.\- ](r|right)$", re.I), 1),
    (re.compile(r"^Left|^left"), 0), (re.compile(r"^Right|^right"), 1),
    (re.compile(r"Left"), 0), (re.compile(r"Right"), 1),
    # a side word between separators: 3ds Max Biped "Bip01 L Thigh", "CC_Base_L_Calf"
    (re.compile(r"(?<=[_.\- ])(l|left)(?=[_.\- ])", re.I), 0),
    (re.compile(r"(?<=[_.\- ])(r|right)(?=[_.\- ])", re.I), 1),
)
_PARTS = {   # checked in this order on the side-less, lower-case, alphanumeric name
    "upper_arm": ("upperarm", "uparm", "humerus", "shldr", "bicep"),
    "lower_arm": ("forearm", "lowerarm", "lowarm", "loarm", "radius", "elbow", "ulna"),
    "hand": ("hand", "wrist"),
    "upper_leg": ("upperleg", "upleg", "thigh", "femur"),
    "lower_leg": ("lowerleg", "lowleg", "loleg", "shin", "calf", "knee", "tibia", "crus"),
    "foot": ("foot", "ankle"),
}
_HELPER = re.compile(r"twist|roll|helper|share|end$|nub$|_end|site", re.I)


def _side_and_part(name: str) -> tuple[int | None, str]:
    """(0 left / 1 right / None, lower-case alphanumeric remainder) of a joint name."""
    base = name.split(":")[-1].split("|")[-1]
    side = None
    rest = base
    for pat, s in _SIDE_PATTERNS:
        m = pat.search(base)
        if m:
            side = s
            rest = base[:m.start()] + base[m.end():]
            break
    if side is None:   # CMU-style lowercase l/r prefix: lhumerus, rtibia, lShldr
        low = base.lower()
        for s, ch in ((0, "l"), (1, "r")):
            if low.startswith(ch) and any(low[1:].startswith(w) for ws in _PARTS.values() for w in ws):
                side, rest = s, base[1:]
                break
    return side, re.sub(r"[^a-z0-9]", "", rest.lower())


def _part_of(rest: str) -> str | None:
    for part, words in _PARTS.items():
        if any(w in rest for w in words):
            return part
    if rest in ("arm",):
        return "upper_arm"
    if rest in ("leg",):
        return "lower_leg"
    return None


def _by_topology(names: list[str], parents: Sequence[int]) -> tuple[dict[str, int], list[str]]:
    """Head and limb joints from names and the hierarchy; (found, problems)."""
    found: dict[str, int] = {}
    problems: list[str] = []
    tagged = [(_side_and_part(n), n) for n in names]
    depth = [len(_ancestors(j, parents)) for j in range(len(names))]

    def upper_of(j: int) -> int:
        p = parents[j]
        while p >= 0 and _HELPER.search(names[p]):
            p = parents[p]
        return p

    for s, side in enumerate(SIDES):
        for limb, lower_part, end_part in (("arm", "lower_arm", "hand"), ("leg", "lower_leg", "foot")):
            lows = [j for j, ((sd, rest), n) in enumerate(tagged)
                    if sd == s and _part_of(rest) == lower_part and not _HELPER.search(n)]
            if not lows:      # no forearm / shin by name: the joint the hand / foot hangs from
                ends = [j for j, ((sd, rest), n) in enumerate(tagged)
                        if sd == s and _part_of(rest) == end_part and not _HELPER.search(n)]
                lows = [upper_of(j) for j in ends if upper_of(j) >= 0]
            if not lows:
                problems.append(f"{side} lower {limb}")
                continue
            low = min(lows, key=lambda j: depth[j])
            up = upper_of(low)
            if up < 0:
                problems.append(f"{side} upper {limb}")
                continue
            found[f"{side}_lower_{limb}"] = low
            found[f"{side}_upper_{limb}"] = up
    heads = [j for j, n in enumerate(names)
             if "head" in n.lower() and not _HELPER.search(n) and "top" not in n.lower()]
    if heads:
        found["head"] = min(heads, key=lambda j: depth[j])
    else:
        problems.append("head")
    return found, problems


# ------------------------------------------------------------------------ mapping

def _torso(limbs: dict[str, int], names: list[str], parents: Sequence[int]
           ) -> tuple[dict[str, int], list[str]]:
    """pelvis, chest, spine, neck from the limbs and head; (found, problems)."""
    out: dict[str, int] = {}
    problems: list[str] = []
    la, ra = limbs["left_upper_arm"], limbs["right_upper_arm"]
    ll, rl = limbs["left_upper_leg"], limbs["right_upper_leg"]
    head = limbs["head"]
    pelvis = _lca(ll, rl, parents)
    chest = _lca(la, ra, parents)
    if pelvis < 0 or pelvis in (ll, rl):
        return out, ["pelvis (the thighs do not branch from one joint)"]
    if chest < 0 or chest in (la, ra):
        return out, ["chest (the arms do not branch from one joint)"]
    spine_path = _path_below(pelvis, chest, parents)
    if spine_path is None:
        return out, [f"chest ({names[chest]} is not above the pelvis {names[pelvis]})"]
    if parents[head] == chest and len(spine_path) >= 3:
        # the arms branch from the joint the head hangs from (3ds Max Biped's clavicles hang
        # from its neck link): that joint is the neck, the one below it the chest
        chest = parents[chest]
        spine_path = spine_path[:-1]
    if len(spine_path) < 2:
        problems.append(f"spine (no joint between pelvis {names[pelvis]} and chest {names[chest]})")
    neck_path = _path_below(chest, head, parents)
    if neck_path is None:
        problems.append(f"neck ({names[head]} does not hang from the chest {names[chest]})")
    elif len(neck_path) < 2:
        problems.append(f"neck (no joint between chest {names[chest]} and head {names[head]})")
    if problems:
        return out, problems
    out.update(pelvis=pelvis, chest=chest, spine=spine_path[0], neck=neck_path[0])
    return out, problems


def _check_limbs(idx: dict[str, int], parents: Sequence[int]) -> list[str]:
    """Problems with found limb joints: lower below upper, left and right distinct."""
    bad = []
    for s in SIDES:
        for limb in ("arm", "leg"):
            up, low = idx[f"{s}_upper_{limb}"], idx[f"{s}_lower_{limb}"]
            if _path_below(up, low, parents) is None:
                bad.append(f"{s} lower {limb} does not hang from the {s} upper {limb}")
    for limb in ("upper_arm", "upper_leg"):
        if idx[f"left_{limb}"] == idx[f"right_{limb}"]:
            bad.append(f"left and right {limb.replace('_', ' ')} are one joint")
    return bad


def _assemble(family: str, idx: dict[str, int], names: list[str], parents: Sequence[int]) -> Rig:
    paths, optional = [], {}
    for j in FEATURE_JOINTS:
        p = _path_below(idx[CANONICAL_PARENT[j]], idx[j], parents)
        if p is None:
            raise RigError(f"{j} ({names[idx[j]]}) does not hang from its canonical parent "
                           f"{CANONICAL_PARENT[j]} ({names[idx[CANONICAL_PARENT[j]]]})")
        paths.append(p)
        optional[j] = tuple(names[i] for i in p[:-1])
    return Rig(family, {c: names[idx[c]] for c in CANONICAL}, dict(idx), tuple(paths), optional)


def map_rig(names: Sequence[str], parents: Sequence[int], where: str = "") -> Rig:
    """Map a skeleton (joint names, parent indices, -1 for a root) to the canonical joints.

    Tries the named families best first (:func:`rtseg.core.skeletons.rank_families`), then names
    and topology.  Raises :class:`RigError` (one line: ``where``, what could not be mapped,
    the rig's joints) when no way maps every canonical joint."""
    names = list(names)
    parents = [int(p) for p in parents]
    if len(names) != len(parents):
        raise RigError(f"{len(parents)} parents for {len(names)} joints")
    attempts: list[tuple[str, list[str]]] = []
    ranked = rank_families(names, tuple(_HBB.values()))
    for smap, count in ranked:
        cols = resolve_names(names, tuple(_HBB.values()), smap)
        if count < len(_NAMED):
            missing = [c for c, col in zip(_NAMED, cols) if col < 0]
            attempts.append((smap.name, [m.replace("_", " ") for m in missing]))
            continue
        idx = dict(zip(_NAMED, cols))
        problems = _check_limbs(idx, parents)
        if not problems:
            torso, problems = _torso(idx, names, parents)
            if not problems:
                return _assemble(smap.name, {**idx, **torso}, names, parents)
        attempts.append((smap.name, problems))
    idx, problems = _by_topology(names, parents)
    if not problems:
        problems = _check_limbs(idx, parents)
    if not problems:
        torso, problems = _torso(idx, names, parents)
        if not problems:
            return _assemble("topology", {**idx, **torso}, names, parents)
    attempts.append(("topology", problems))
    best = min(attempts, key=lambda a: len(a[1]))
    shown = ", ".join(names[:40]) + (f", ... ({len(names)} joints)" if len(names) > 40 else "")
    raise RigError(f"{where + ': ' if where else ''}cannot map the skeleton to rtseg's canonical "
                   f"joints (best: {best[0]}, missing {'; '.join(best[1])}); its joints: {shown}. "
                   f"Name a skeleton profile (--profile) or rename the joints")
