"""Acclaim ASF (skeleton) and AMC (motion) reader, as written by the CMU mocap database.

Conventions (Acclaim / CMU, as in the CMU viewer and Barbič's AMC player)
------------------------------------------------------------------------
- ``axis ax ay az ORDER``: the bone's axis frame C relative to the world-aligned frame.
  The three numbers are the angles about X, Y and Z (in the ASF ``angle`` unit); ORDER is
  the order in which they are applied, so ``XYZ`` (every CMU file) means C = Rz·Ry·Rx.
- ``dof rx ry rz``: AMC values of that bone, in that order.  The motion rotation M is
  expressed in the axis frame and applied in the listed order: ``rx ry rz`` gives
  M = Rz(rz)·Ry(ry)·Rx(rx) (missing dofs are 0).  Translation dofs (tx ty tz l) on
  non-root bones are read and checked but do not contribute to the rotation.
- The take stores for each bone its rotation relative to its parent in world-aligned
  frames: L = C·M·C⁻¹.  Chaining L along the hierarchy (``rtseg.quat.global_from_local``)
  gives each bone's orientation in the world, the same thing an IMU on that bone reports.
- Root: ``order TX TY TZ RX RY RZ`` says which AMC column is which; ``axis XYZ`` is the
  order the root rotations are applied; ``orientation`` is the root axis frame C_root.
  Joint 0 of the take is ``root``; ``root_position`` is the AMC translation plus the ASF
  ``position``, in the file's length unit (see ``length_unit`` and ``meta``).
- ASF/AMC carry no frame rate; CMU captures at 120 Hz, the default here.

Malformed input raises ``ReaderError`` naming the file, line and problem.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rtseg import quat as Q
from rtseg.drivers.readers.errors import ReaderError, read_text_lines
from rtseg.take import Take

DEFAULT_FRAME_RATE = 120.0

_ROT_DOFS = ("rx", "ry", "rz")
_ALL_DOFS = ("rx", "ry", "rz", "tx", "ty", "tz", "l")
_ROOT_CHANNELS = ("tx", "ty", "tz", "rx", "ry", "rz")
_LIMIT_RE = re.compile(r"\(\s*([^\s()]+)\s+([^\s()]+)\s*\)")

# CMU FAQ: ASF/AMC lengths are inches scaled by the ASF ``length`` factor 0.45.
_CMU_METRES_PER_UNIT = 0.0254 / 0.45


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
        return np.array([float(t) for t in tokens[:n]])
    except ValueError:
        bad = next(t for t in tokens[:n] if not _is_number(t))
        raise ReaderError(path, f"{what}: {bad!r} is not a number", lineno) from None


def _is_number(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return False


def _angle_to_deg(values: np.ndarray, unit: str) -> np.ndarray:
    return np.degrees(values) if unit == "rad" else values


def read_asf(path: str | Path) -> AsfSkeleton:
    """Parse an Acclaim ASF skeleton file (CRLF tolerant)."""
    path = Path(path)
    lines = read_text_lines(path)
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


def _euler_quats(axes: str, angles_deg: np.ndarray) -> np.ndarray:
    """R = R_axes[0]·R_axes[1]·... of (F, k) angles in degrees (same as
    ``rtseg.quat.from_euler(axes, angles)``, composed directly: faster for long takes)."""
    angles_deg = np.atleast_2d(np.asarray(angles_deg, dtype=np.float64))
    half = np.radians(angles_deg) * 0.5
    out = None
    for k, a in enumerate(axes.upper()):
        q = np.zeros((angles_deg.shape[0], 4))
        q[:, "XYZ".index(a)] = np.sin(half[:, k])
        q[:, 3] = np.cos(half[:, k])
        out = q if out is None else Q.multiply(out, q)
    if out is None:
        return np.broadcast_to(Q.IDENTITY, (angles_deg.shape[0], 4)).copy()
    return out


def _axis_quat(angles_xyz_deg: np.ndarray, order: str) -> np.ndarray:
    """Quaternion of an ASF ``axis``: rotations about the axes applied in ``order``.

    Applying X then Y then Z (order "XYZ") is R = Rz·Ry·Rx, i.e. intrinsic "ZYX" in
    ``rtseg.quat.from_euler`` terms.
    """
    idx = {"X": 0, "Y": 1, "Z": 2}
    rev = order[::-1]
    return _euler_quats(rev, np.array([[angles_xyz_deg[idx[a]] for a in rev]]))[0]


def _motion_quats(values_deg: np.ndarray, rot_dofs: list[str]) -> np.ndarray:
    """(F, 4) rotation of (F, k) angles listed in application order ``rot_dofs``."""
    if not rot_dofs:
        return np.broadcast_to(Q.IDENTITY, (values_deg.shape[0], 4)).copy()
    axes = "".join(d[1].upper() for d in reversed(rot_dofs))
    return _euler_quats(axes, values_deg[:, ::-1])


def _conjugated(c: np.ndarray, m: np.ndarray) -> np.ndarray:
    """C·M·C⁻¹ for one axis quaternion c and (F, 4) rotations m."""
    if np.allclose(c, Q.IDENTITY):
        return m
    return Q.multiply(Q.multiply(c, m), Q.conjugate(c))


def read_amc(path: str | Path, skeleton: AsfSkeleton | str | Path,
             frame_rate: float | None = None) -> Take:
    """Read an AMC motion file against its ASF skeleton; returns a local-space ``Take``.

    ``frame_rate`` overrides the default 120 Hz (ASF/AMC store no rate).
    """
    path = Path(path)
    sk = skeleton if isinstance(skeleton, AsfSkeleton) else read_asf(skeleton)
    rate = DEFAULT_FRAME_RATE if frame_rate is None else float(frame_rate)
    if not rate > 0:
        raise ReaderError(path, f"frame rate must be positive, got {frame_rate}")

    # Column layout of one frame: root channels, then each bone's dofs.
    layout: dict[str, tuple[int, int]] = {"root": (0, len(sk.root_order))}
    col = len(sk.root_order)
    for name, b in sk.bones.items():
        layout[name] = (col, len(b.dof))
        col += len(b.dof)
    n_cols = col
    must_appear = [n for n, (_, k) in layout.items() if k > 0]
    n_required = len(must_appear)

    lines = read_text_lines(path)
    angle_unit = sk.angle_unit
    rows: list[list[float]] = []
    frame_numbers: list[int] = []
    frame_lines: list[int] = []
    row: list[float] | None = None
    seen: set[str] = set()
    n_seen_required = 0
    fully_specified = False
    layout_get = layout.get

    def close_frame(at_line: int) -> None:
        if row is None or n_seen_required == n_required:
            return
        missing = [n for n in must_appear if n not in seen]
        raise ReaderError(
            path, f"frame {frame_numbers[-1]} (line {frame_lines[-1]}) has no line for bone "
            f"{missing[0]!r}" + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""),
            at_line)

    for lineno, raw in enumerate(lines, start=1):
        tokens = raw.split()
        if not tokens:
            continue
        head = tokens[0]
        spec = layout_get(head)
        if spec is not None and row is not None:  # the common case: one bone's values
            if head in seen:
                raise ReaderError(path, f"bone {head!r} given twice in frame {frame_numbers[-1]}", lineno)
            seen.add(head)
            start, k = spec
            if len(tokens) - 1 != k:
                dofs = " ".join(sk.root_order if head == "root" else sk.bones[head].dof) or "none"
                raise ReaderError(
                    path, f"bone {head!r} has {len(tokens) - 1} values, expected {k} ({dofs})", lineno)
            if k:
                n_seen_required += 1
                try:
                    row[start:start + k] = map(float, tokens[1:])
                except ValueError:
                    bad = next(t for t in tokens[1:] if not _is_number(t))
                    raise ReaderError(path, f"bone {head!r}: value {bad!r} is not a number", lineno) from None
            continue
        if head[0] == "#":
            continue
        if head[0] == ":":
            if row is not None:
                raise ReaderError(path, f"header keyword {head!r} after motion data", lineno)
            kw = head.upper()
            if kw == ":FULLY-SPECIFIED":
                fully_specified = True
            elif kw == ":DEGREES":
                angle_unit = "deg"
            elif kw == ":RADIANS":
                angle_unit = "rad"
            else:
                raise ReaderError(path, f"unknown header keyword {head!r}", lineno)
            continue
        if head.isdigit() or (head[0] == "-" and head[1:].isdigit()):
            if len(tokens) != 1:
                raise ReaderError(path, f"frame number line has extra text: {raw.strip()!r}", lineno)
            number = int(head)
            close_frame(lineno)
            if frame_numbers and number != frame_numbers[-1] + 1:
                raise ReaderError(
                    path, f"frame number {number} out of order (previous frame {frame_numbers[-1]}, "
                    f"expected {frame_numbers[-1] + 1})", lineno)
            frame_numbers.append(number)
            frame_lines.append(lineno)
            row = [0.0] * n_cols
            rows.append(row)
            seen = set()
            n_seen_required = 0
            continue
        if row is None:
            if spec is not None:
                raise ReaderError(path, f"bone line before the first frame number: {raw.strip()!r}", lineno)
            raise ReaderError(path, f"unexpected text before the first frame number: {raw.strip()!r}", lineno)
        raise ReaderError(path, f"unknown bone {head!r} (not in skeleton {sk.path})", lineno)
    close_frame(len(lines))
    if not rows:
        raise ReaderError(path, "no motion frames (no frame number lines)")

    data = np.array(rows, dtype=np.float64)
    if not np.all(np.isfinite(data)):
        f, c = np.argwhere(~np.isfinite(data))[0]
        raise ReaderError(path, f"non-finite value in frame {frame_numbers[f]}", frame_lines[f])
    return _build_take(path, sk, data, layout, angle_unit, rate, frame_numbers[0], fully_specified)


def _build_take(path: Path, sk: AsfSkeleton, data: np.ndarray, layout: dict[str, tuple[int, int]],
                angle_unit: str, rate: float, first_frame: int, fully_specified: bool) -> Take:
    names = sk.joint_order()
    index = {n: i for i, n in enumerate(names)}
    parents = [-1] + [index[sk.parent[n]] for n in names[1:]]
    F = data.shape[0]
    quats = np.empty((F, len(names), 4))
    to_deg = (lambda a: np.degrees(a)) if angle_unit == "rad" else (lambda a: a)
    axis_q = np.empty((len(names), 4))

    # Root.
    r0, rk = layout["root"]
    root_cols = {ch: r0 + i for i, ch in enumerate(sk.root_order)}
    root_rot = [ch for ch in ("r" + a.lower() for a in sk.root_axis_order) if ch in root_cols]
    m = _motion_quats(to_deg(data[:, [root_cols[ch] for ch in root_rot]]), root_rot)
    c = _axis_quat(_angle_to_deg(sk.root_orientation, sk.angle_unit), sk.root_axis_order)
    axis_q[0] = c
    quats[:, 0] = _conjugated(c, m)
    root_position = np.tile(sk.root_position, (F, 1))
    for i, ch in enumerate(("tx", "ty", "tz")):
        if ch in root_cols:
            root_position[:, i] += data[:, root_cols[ch]]

    # Bones.
    offsets = np.zeros((len(names), 3))
    for j, name in enumerate(names[1:], start=1):
        b = sk.bones[name]
        start, k = layout[name]
        cols = [start + i for i, d in enumerate(b.dof) if d in _ROT_DOFS]
        rot = [d for d in b.dof if d in _ROT_DOFS]
        c = _axis_quat(_angle_to_deg(b.axis, sk.angle_unit), b.axis_order)
        axis_q[j] = c
        quats[:, j] = _conjugated(c, _motion_quats(to_deg(data[:, cols]), rot))
        offsets[j] = b.direction * b.length

    meta = {
        "format": "asf/amc",
        "skeleton_path": sk.path,
        "skeleton_name": sk.name,
        "first_frame_number": first_frame,
        "fully_specified": fully_specified,
        "amc_angle_unit": angle_unit,
        "asf_length_scale": sk.length,
        "dof": {"root": list(sk.root_order), **{n: list(b.dof) for n, b in sk.bones.items()}},
        "axis_quats": axis_q,        # C per joint, scalar-last
        "bone_offsets": offsets,     # direction * length per joint, world-aligned, file units
    }
    if abs(sk.length - 0.45) < 1e-9:
        meta["metres_per_unit"] = _CMU_METRES_PER_UNIT
        unit = "asf units (CMU: inches x 0.45; metres_per_unit in meta)"
    else:
        unit = f"asf units (length scale {sk.length:g})"
    return Take(joint_names=names, parents=parents, frame_rate=rate, quats=quats,
                root_position=root_position, space="local", length_unit=unit,
                source=str(path), meta=meta)


def skeleton_for(amc_path: str | Path) -> Path:
    """The ASF that goes with ``SS_TT.amc``: ``SS.asf`` in the same folder, else the only ASF there."""
    amc_path = Path(amc_path)
    stem = amc_path.stem
    candidates = []
    if "_" in stem:
        candidates.append(amc_path.with_name(stem.rsplit("_", 1)[0] + ".asf"))
        candidates.append(amc_path.with_name(stem.split("_", 1)[0] + ".asf"))
    candidates.append(amc_path.with_name(stem + ".asf"))
    for c in candidates:
        if c.is_file():
            return c
        upper = c.with_suffix(".ASF")
        if upper.is_file():
            return upper
    asfs = sorted(p for p in amc_path.parent.glob("*") if p.suffix.lower() == ".asf")
    if len(asfs) == 1:
        return asfs[0]
    tried = ", ".join(c.name for c in candidates)
    raise ReaderError(amc_path, f"no skeleton given and none found beside it (looked for {tried}"
                      + (f"; {len(asfs)} .asf files there, pass skeleton=" if asfs else "") + ")")


def read_asf_amc(amc_path: str | Path, skeleton: str | Path | AsfSkeleton | None = None,
                 frame_rate: float | None = None) -> Take:
    """Read ``SS_TT.amc``; the skeleton defaults to ``SS.asf`` beside it."""
    if skeleton is None:
        skeleton = skeleton_for(amc_path)
    return read_amc(amc_path, skeleton, frame_rate=frame_rate)
