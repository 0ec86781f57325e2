"""Acclaim ASF skeleton reader, as written by the CMU mocap database (the motion that goes
with it: ``rtseg.drivers.readers.amc``).

- ``units``: ``angle deg|rad``, ``length`` (CMU: 0.45, lengths in inches / 0.45 -
  ``CMU_METRES_PER_UNIT`` metres per unit).
- ``:root``: ``order TX TY TZ RX RY RZ`` says which AMC column is which; ``axis XYZ`` the
  order the root rotations are applied; ``position`` and ``orientation`` the root's offset
  and axis frame.
- ``:bonedata``: per bone its ``direction``, ``length``, ``axis ax ay az ORDER`` (the
  bone's axis frame relative to the world-aligned frame, angles about X, Y and Z applied in
  ORDER), ``dof`` (its AMC channels, in order) and ``limits``.
- ``:hierarchy``: parent then children per line; ``AsfSkeleton.joint_order`` lists the
  bones parents first.

Malformed input raises ``ReaderError`` naming the file, line and problem.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rtseg.drivers.readers.errors import ReaderError, is_number, read_text_lines

ROT_DOFS = ("rx", "ry", "rz")
_ALL_DOFS = ("rx", "ry", "rz", "tx", "ty", "tz", "l")
_ROOT_CHANNELS = ("tx", "ty", "tz", "rx", "ry", "rz")
_LIMIT_RE = re.compile(r"\(\s*([^\s()]+)\s+([^\s()]+)\s*\)")

# CMU FAQ: ASF/AMC lengths are inches scaled by the ASF ``length`` factor 0.45.
CMU_METRES_PER_UNIT = 0.0254 / 0.45


@dataclass
class AsfBone:
    """One ``begin ... end`` block of ``:bonedata``."""

    name: str
    id: int | None = None
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))  # angles about X, Y, Z
    axis_order: str = "XYZ"
    dof: list[str] = field(default_factory=list)
    limits: list[tuple[float, float]] = field(default_factory=list)
    line: int = 0  # where the block starts, for messages


@dataclass
class AsfSkeleton:
    """A parsed ASF file.  Angles are kept in the file's unit (``angle_unit``)."""

    path: str
    name: str = ""
    version: str = ""
    mass: float = 1.0
    length: float = 1.0
    angle_unit: str = "deg"
    root_order: list[str] = field(default_factory=lambda: list(_ROOT_CHANNELS))
    root_axis_order: str = "XYZ"
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    root_orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bones: dict[str, AsfBone] = field(default_factory=dict)  # declaration order
    parent: dict[str, str] = field(default_factory=dict)     # bone -> parent ("root" for top)
    children: dict[str, list[str]] = field(default_factory=dict)

    def joint_order(self) -> list[str]:
        """``root`` then every bone, parents before children, else in declaration order."""
        order = ["root"]
        placed = {"root"}
        pending = list(self.bones)
        while pending:
            rest = [b for b in pending if self.parent[b] not in placed]
            for b in pending:
                if self.parent[b] in placed:
                    order.append(b)
                    placed.add(b)
            if len(rest) == len(pending):
                raise ReaderError(self.path, f"hierarchy has a cycle through {rest[0]!r}")
            pending = [b for b in rest if b not in placed]
        return order


def _floats(path: Path, lineno: int, tokens: list[str], n: int, what: str) -> np.ndarray:
    if len(tokens) < n:
        raise ReaderError(path, f"{what} needs {n} numbers, got {len(tokens)}", lineno)
    try:
        values = np.array([float(t) for t in tokens[:n]])
    except ValueError:
        bad = next(t for t in tokens[:n] if not is_number(t))
        raise ReaderError(path, f"{what}: {bad!r} is not a number", lineno) from None
    if not np.all(np.isfinite(values)):
        bad = tokens[int(np.argmin(np.isfinite(values)))]
        raise ReaderError(path, f"{what}: {bad!r} is not a finite number", lineno)
    return values


def angle_to_deg(values: np.ndarray, unit: str) -> np.ndarray:
    return np.degrees(values) if unit == "rad" else values


def read_asf(path: str | Path) -> AsfSkeleton:
    """Parse an Acclaim ASF skeleton file (CRLF tolerant)."""
    path = Path(path)
    lines = read_text_lines(path)
    first = next((ln.strip() for ln in lines if ln.strip()), "")
    if first.upper() == "HIERARCHY":
        raise ReaderError(path, "is a BVH file (it starts with HIERARCHY), not an ASF "
                          "skeleton: an .amc take needs its Acclaim .asf; a .bvh take carries "
                          "its own skeleton (read the .bvh itself, without a skeleton)", 1)
    sk = AsfSkeleton(path=str(path))
    section = ""
    bone: AsfBone | None = None
    pending_limits: tuple[AsfBone, int, list[str]] | None = None  # bone, line, text so far
    in_hier_block = False
    seen_bonedata = seen_hierarchy = False
    seen_root = False

    def finish_limits() -> None:
        nonlocal pending_limits
        if pending_limits is None:
            return
        b, ln, parts = pending_limits
        pending_limits = None
        text = " ".join(parts)
        pairs = _LIMIT_RE.findall(text)
        leftover = _LIMIT_RE.sub("", text).strip()
        if leftover or len(pairs) != len(b.dof):
            raise ReaderError(
                path, f"bone {b.name!r}: limits must be {len(b.dof)} pairs '(lo hi)', got {text!r}", ln)
        try:
            b.limits = [(float(lo), float(hi)) for lo, hi in pairs]
        except ValueError:
            raise ReaderError(path, f"bone {b.name!r}: non-numeric limit in {text!r}", ln) from None

    for lineno, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tokens = line.split()
        key = tokens[0].lower()

        if line.startswith(":"):
            finish_limits()
            if bone is not None:
                raise ReaderError(path, f"bone {bone.name!r} (line {bone.line}) has no 'end'", lineno)
            section = key[1:]
            if section == "version":
                sk.version = " ".join(tokens[1:])
            elif section == "name":
                sk.name = " ".join(tokens[1:])
            elif section == "bonedata":
                seen_bonedata = True
            elif section == "hierarchy":
                seen_hierarchy = True
            elif section == "root":
                seen_root = True
            elif section in ("units", "documentation"):
                pass
            elif section == "skin":
                pass
            else:
                raise ReaderError(path, f"unknown section {tokens[0]!r}", lineno)
            continue

        if section == "units":
            if len(tokens) != 2:
                raise ReaderError(path, f"units line must be 'name value', got {line!r}", lineno)
            if key == "angle":
                unit = tokens[1].lower()
                if unit in ("deg", "degree", "degrees"):
                    sk.angle_unit = "deg"
                elif unit in ("rad", "radian", "radians"):
                    sk.angle_unit = "rad"
                else:
                    raise ReaderError(path, f"angle unit must be deg or rad, got {tokens[1]!r}", lineno)
            elif key in ("mass", "length"):
                val = _floats(path, lineno, tokens[1:], 1, f"units {key}")[0]
                if val <= 0:
                    raise ReaderError(path, f"units {key} must be positive, got {val}", lineno)
                setattr(sk, key, float(val))
            continue

        if section in ("documentation", "skin", "version", "name"):
            continue

        if section == "root":
            if key == "order":
                order = [t.lower() for t in tokens[1:]]
                bad = [t for t in order if t not in _ROOT_CHANNELS]
                if bad or len(set(order)) != len(order):
                    raise ReaderError(path, f"root order must list distinct TX TY TZ RX RY RZ, got {' '.join(tokens[1:])!r}", lineno)
                sk.root_order = order
            elif key == "axis":
                if len(tokens) != 2 or sorted(tokens[1].upper()) != ["X", "Y", "Z"]:
                    raise ReaderError(path, f"root axis must be an order like XYZ, got {' '.join(tokens[1:])!r}", lineno)
                sk.root_axis_order = tokens[1].upper()
            elif key == "position":
                sk.root_position = _floats(path, lineno, tokens[1:], 3, "root position")
            elif key == "orientation":
                sk.root_orientation = _floats(path, lineno, tokens[1:], 3, "root orientation")
            else:
                raise ReaderError(path, f"unknown root field {tokens[0]!r}", lineno)
            continue

        if section == "bonedata":
            if key == "begin":
                finish_limits()
                if bone is not None:
                    raise ReaderError(path, f"'begin' inside bone {bone.name!r} (line {bone.line})", lineno)
                bone = AsfBone(name="", line=lineno)
                continue
            if bone is None:
                raise ReaderError(path, f"{tokens[0]!r} outside a begin/end block", lineno)
            if key == "end":
                finish_limits()
                if not bone.name:
                    raise ReaderError(path, f"bone block from line {bone.line} has no name", lineno)
                if bone.name.lower() == "root" or bone.name in sk.bones:
                    raise ReaderError(path, f"bone name {bone.name!r} used twice", lineno)
                sk.bones[bone.name] = bone
                bone = None
                continue
            if pending_limits is not None and line.startswith("("):
                pending_limits[2].append(line)
                continue
            finish_limits()
            if key == "id":
                bone.id = int(_floats(path, lineno, tokens[1:], 1, "id")[0])
            elif key == "name":
                if len(tokens) != 2:
                    raise ReaderError(path, f"name must be one word, got {line!r}", lineno)
                bone.name = tokens[1]
            elif key == "direction":
                bone.direction = _floats(path, lineno, tokens[1:], 3, "direction")
            elif key == "length":
                bone.length = float(_floats(path, lineno, tokens[1:], 1, "length")[0])
            elif key == "axis":
                bone.axis = _floats(path, lineno, tokens[1:], 3, "axis")
                order = tokens[4].upper() if len(tokens) > 4 else "XYZ"
                if sorted(order) != ["X", "Y", "Z"]:
                    raise ReaderError(path, f"axis order must be a permutation of XYZ, got {order!r}", lineno)
                bone.axis_order = order
            elif key == "dof":
                dof = [t.lower() for t in tokens[1:]]
                bad = [t for t in dof if t not in _ALL_DOFS]
                if bad:
                    raise ReaderError(path, f"unknown dof {bad[0]!r} (known: {' '.join(_ALL_DOFS)})", lineno)
                if len(set(dof)) != len(dof):
                    raise ReaderError(path, f"repeated dof in {' '.join(tokens[1:])!r}", lineno)
                bone.dof = dof
            elif key == "limits":
                pending_limits = (bone, lineno, [line[len(tokens[0]):]])
            elif key in ("bodymass", "cofmass"):
                pass
            else:
                raise ReaderError(path, f"unknown bone field {tokens[0]!r}", lineno)
            continue

        if section == "hierarchy":
            if key == "begin":
                in_hier_block = True
                continue
            if key == "end":
                in_hier_block = False
                continue
            if not in_hier_block:
                raise ReaderError(path, f"hierarchy line outside begin/end: {line!r}", lineno)
            parent = tokens[0]
            if parent != "root" and parent not in sk.bones:
                raise ReaderError(path, f"unknown bone {parent!r} in hierarchy", lineno)
            for child in tokens[1:]:
                if child not in sk.bones:
                    raise ReaderError(path, f"unknown bone {child!r} in hierarchy", lineno)
                if child in sk.parent:
                    raise ReaderError(
                        path, f"bone {child!r} given a second parent {parent!r} (was {sk.parent[child]!r})", lineno)
                sk.parent[child] = parent
                sk.children.setdefault(parent, []).append(child)
            continue

        raise ReaderError(path, f"line outside any section: {line!r}", lineno)

    finish_limits()
    if bone is not None:
        raise ReaderError(path, f"bone {bone.name!r} (line {bone.line}) has no 'end'")
    if not seen_root:
        raise ReaderError(path, "no :root section (is this an ASF skeleton file?)")
    if not seen_bonedata:
        raise ReaderError(path, "no :bonedata section")
    if not seen_hierarchy:
        raise ReaderError(path, "no :hierarchy section")
    orphans = [b for b in sk.bones if b not in sk.parent]
    if orphans:
        raise ReaderError(path, f"bone {orphans[0]!r} has no parent in :hierarchy")
    sk.joint_order()  # raises on cycles
    return sk
