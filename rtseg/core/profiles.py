"""Skeleton profiles (which joints make the pose feature vector) and suit profiles.

Skeleton profiles live in ``config/skeletons.toml``; suit profiles (sensor id -> bone,
hierarchy, rate) in ``config/suits.toml``.  Joint names match case-insensitively; a
profile joint may have aliases tried in order when its own name is absent.

The default is the pseudo-profile ``canonical``: any humanoid rig mapped to rtseg's
canonical joints (``rtseg.core.rig``), the same 12 segments on every rig.  Named profiles select
a rig's own joints: ``cmu14`` (the paper's 14 CMU joints), ``unity`` (their 12
HumanBodyBones equivalents on the 17-sensor suit), ``tsseg4d`` (the four CSV channels), and
the pseudo-profile ``all`` (every joint of the take, in take order).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from rtseg.config import ConfigError, config_dir, load_toml

ALL = "all"
#: any humanoid rig mapped to the canonical joints (``rtseg.core.rig``): the default
CANONICAL = "canonical"
#: Named profiles tried when the rig cannot be mapped (channel sets that are no skeleton).
AUTO_ORDER = ("tsseg4d", "vrchat")


@dataclass(frozen=True)
class SkeletonProfile:
    name: str
    joints: tuple[str, ...]
    aliases: dict[str, tuple[str, ...]] = field(default_factory=dict)
    description: str = ""


@dataclass(frozen=True)
class SuitProfile:
    """A suit: ``sensor_ids[k]`` carries bone ``bones[k]`` whose parent is ``bones[parents[k]]``
    (-1 for the root).  Parents come before children.  ``frame_rate`` in Hz."""

    name: str
    sensor_ids: tuple[int, ...]
    bones: tuple[str, ...]
    parents: tuple[int, ...]
    frame_rate: float
    description: str = ""

    def index_of_sensor(self, sensor_id: int) -> int:
        try:
            return self.sensor_ids.index(sensor_id)
        except ValueError:
            raise KeyError(f"sensor id {sensor_id} not in suit {self.name!r}") from None


def _skeleton_file(path: str | Path | None) -> Path:
    return Path(path) if path is not None else config_dir() / "skeletons.toml"


@lru_cache(maxsize=8)
def _load_profiles(path: str) -> dict[str, SkeletonProfile]:
    data = load_toml(path)
    profiles = data.get("profiles")
    if not isinstance(profiles, dict) or not profiles:
        raise ConfigError(f"{path}: no [profiles.<name>] tables")
    out: dict[str, SkeletonProfile] = {}
    for name, spec in profiles.items():
        joints = spec.get("joints") if isinstance(spec, dict) else None
        if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
            raise ConfigError(f"{path}: profiles.{name}.joints must be a non-empty list of names")
        if len({j.lower() for j in joints}) != len(joints):
            raise ConfigError(f"{path}: profiles.{name}.joints names a joint twice")
        aliases_raw = spec.get("aliases", {})
        if not isinstance(aliases_raw, dict):
            raise ConfigError(f"{path}: profiles.{name}.aliases must be a table")
        lowered = {j.lower(): j for j in joints}
        aliases: dict[str, tuple[str, ...]] = {}
        for joint, alts in aliases_raw.items():
            if joint.lower() not in lowered:
                raise ConfigError(f"{path}: profiles.{name}.aliases.{joint}: not a joint of the profile")
            if not isinstance(alts, list) or not all(isinstance(a, str) for a in alts):
                raise ConfigError(f"{path}: profiles.{name}.aliases.{joint} must be a list of names")
            aliases[lowered[joint.lower()]] = tuple(alts)
        out[name] = SkeletonProfile(name, tuple(joints), aliases, str(spec.get("description", "")))
    for reserved in (ALL, CANONICAL):
        if reserved in out:
            raise ConfigError(f"{path}: profile name {reserved!r} is reserved")
    return out


def profiles(path: str | Path | None = None) -> dict[str, SkeletonProfile]:
    """All skeleton profiles of ``config/skeletons.toml`` (or ``path``)."""
    return dict(_load_profiles(str(_skeleton_file(path))))


def get_profile(name: str, path: str | Path | None = None) -> SkeletonProfile:
    known = _load_profiles(str(_skeleton_file(path)))
    if name == CANONICAL:
        raise KeyError(f"profile {CANONICAL!r} maps a whole rig (rtseg.core.rig.map_rig); it has no "
                       f"joint list of its own")
    try:
        return known[name]
    except KeyError:
        raise KeyError(f"unknown skeleton profile {name!r}; known: {CANONICAL}, "
                       f"{', '.join(sorted(known))}, {ALL}") from None


def skeleton_profile(name: str, path: str | Path | None = None) -> list[str]:
    """Canonical joint names of profile ``name`` (``"all"`` has none fixed: use ``resolve_joints``)."""
    if name == ALL:
        raise KeyError(f"profile {ALL!r} selects every joint of a take; it has no fixed joint list")
    return list(get_profile(name, path).joints)


def _find(joint: str, alts: tuple[str, ...], lowered: dict[str, int]) -> int | None:
    for candidate in (joint, *alts):
        i = lowered.get(candidate.lower())
        if i is not None:
            return i
    return None


def resolve_joints(profile: str, joint_names: list[str], path: str | Path | None = None) -> list[int]:
    """Indices into ``joint_names`` of the profile's joints, in profile order.

    Raises ``KeyError`` naming the first missing joint and the profile.
    """
    if profile == ALL:
        return list(range(len(joint_names)))
    prof = get_profile(profile, path)
    lowered: dict[str, int] = {}
    for i, n in enumerate(joint_names):
        lowered.setdefault(n.lower(), i)
    out = []
    for joint in prof.joints:
        alts = prof.aliases.get(joint, ())
        i = _find(joint, alts, lowered)
        if i is None:
            also = f" (or {', '.join(alts)})" if alts else ""
            raise KeyError(f"joint {joint!r}{also} of skeleton profile {profile!r} is missing; "
                           f"available: {', '.join(joint_names)}")
        out.append(i)
    return out


def choose_profile(joint_names: list[str], parents: list[int] | None = None,
                   path: str | Path | None = None) -> str:
    """``"canonical"`` when the skeleton maps to the canonical joints (``rtseg.core.rig``), else
    the first named profile of ``AUTO_ORDER`` whose channels are all present (``tsseg4d``,
    ``vrchat``); else ``rtseg.core.rig.RigError`` (one line naming what could not be mapped; never
    a silent fall-back to every joint).  Without ``parents`` the joints are taken as roots
    (no hierarchy: no canonical map)."""
    from rtseg.core.rig import RigError, map_rig
    parents = list(parents) if parents is not None else [-1] * len(joint_names)
    try:
        map_rig(joint_names, parents)
        return CANONICAL
    except RigError as err:
        name = named_profile(joint_names, path)
        if name is None:
            raise err
        return name


def named_profile(joint_names: list[str], path: str | Path | None = None) -> str | None:
    """The first profile of ``AUTO_ORDER`` whose channels are all in ``joint_names``, or None."""
    known = _load_profiles(str(_skeleton_file(path)))
    for name in AUTO_ORDER:
        if name in known:
            try:
                resolve_joints(name, joint_names, path)
                return name
            except KeyError:
                continue
    return None


def suit_profile(name: str = "default17", path: str | Path | None = None) -> SuitProfile:
    """Suit ``name`` from ``config/suits.toml`` (or ``path``), validated."""
    p = Path(path) if path is not None else config_dir() / "suits.toml"
    data = load_toml(p)
    suits = data.get("suits", {})
    if name not in suits:
        raise KeyError(f"{p}: unknown suit {name!r}; known: {', '.join(sorted(suits)) or 'none'}")
    spec = suits[name]
    where = f"{p}: suits.{name}"
    sensors = spec.get("sensors")
    if not isinstance(sensors, list) or not sensors:
        raise ConfigError(f"{where}.sensors must be a non-empty list")
    try:
        rate = float(spec.get("frame_rate", 0))
    except (TypeError, ValueError):
        raise ConfigError(f"{where}.frame_rate must be a number") from None
    if not rate > 0:
        raise ConfigError(f"{where}.frame_rate must be positive")
    ids: list[int] = []
    bones: list[str] = []
    parent_names: list[str] = []
    for k, s in enumerate(sensors):
        if not isinstance(s, dict) or "id" not in s or "bone" not in s:
            raise ConfigError(f"{where}.sensors[{k}] needs id and bone")
        sid, bone = s["id"], s["bone"]
        if not isinstance(sid, int) or not 0 <= sid <= 255:
            raise ConfigError(f"{where}.sensors[{k}].id must be an integer 0..255")
        if sid in ids:
            raise ConfigError(f"{where}.sensors[{k}].id {sid} used twice")
        if not isinstance(bone, str) or not bone or bone.lower() in (b.lower() for b in bones):
            raise ConfigError(f"{where}.sensors[{k}].bone must be a new non-empty name")
        ids.append(sid)
        bones.append(bone)
        parent_names.append(str(s.get("parent", "")))
    lowered = {b.lower(): i for i, b in enumerate(bones)}
    parents: list[int] = []
    for k, pn in enumerate(parent_names):
        if not pn:
            parents.append(-1)
            continue
        if pn.lower() not in lowered:
            raise ConfigError(f"{where}.sensors[{k}].parent {pn!r} is not a bone of the suit")
        pi = lowered[pn.lower()]
        if pi >= k:
            raise ConfigError(f"{where}.sensors[{k}].parent {pn!r} must be listed before {bones[k]!r}")
        parents.append(pi)
    return SuitProfile(name, tuple(ids), tuple(bones), tuple(parents), rate,
                       str(spec.get("description", "")))
