"""Acclaim AMC (motion) reader, with its ASF skeleton (``rtseg.drivers.readers.asf``), as
written by the CMU mocap database.

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
  frames: L = C·M·C⁻¹.  Chaining L along the hierarchy (``rtseg.core.quat.global_from_local``)
  gives each bone's orientation in the world, the same thing an IMU on that bone reports.
- Root: ``order TX TY TZ RX RY RZ`` says which AMC column is which; ``axis XYZ`` is the
  order the root rotations are applied; ``orientation`` is the root axis frame C_root.
  Joint 0 of the take is ``root``; ``root_position`` is the AMC translation plus the ASF
  ``position``, in the file's length unit (see ``length_unit`` and ``meta``).
- ASF/AMC carry no frame rate; CMU captures at 120 Hz, the default here.

Malformed input raises ``ReaderError`` naming the file, line and problem, except a file
cut short: when the file ends before the last frame's bones are all given, or its last
line - with no line break after it, a line cut in the middle - is the wrong one, the whole
frames before it are read, the last is dropped, and a warning names the line
(``meta["truncated"]``: that line, the frame number dropped and the problem).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from rtseg.core import quat as Q
from rtseg.drivers.readers.asf import (CMU_METRES_PER_UNIT, ROT_DOFS, AsfBone, AsfSkeleton,
                                       angle_to_deg, read_asf)
from rtseg.drivers.readers.errors import ReaderError, ends_mid_line, is_number, read_text_lines
from rtseg.core.take import Take

__all__ = ["AsfBone", "AsfSkeleton", "read_asf", "read_amc", "read_asf_amc", "skeleton_for",
           "DEFAULT_FRAME_RATE"]

DEFAULT_FRAME_RATE = 120.0

log = logging.getLogger("rtseg.readers")


def _euler_quats(axes: str, angles_deg: np.ndarray) -> np.ndarray:
    """R = R_axes[0]·R_axes[1]·... of (F, k) angles in degrees (same as
    ``rtseg.core.quat.from_euler(axes, angles)``, composed directly: faster for long takes)."""
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
    ``rtseg.core.quat.from_euler`` terms.
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

    last_line = len(lines)                   # the last line holding text
    while last_line and not lines[last_line - 1].strip():
        last_line -= 1
    truncated: dict | None = None
    at_number = at_end = False
    try:
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
                        bad = next(t for t in tokens[1:] if not is_number(t))
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
                at_number = True             # problems here are not a file cut short
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
                at_number = False
                continue
            if row is None:
                if spec is not None:
                    raise ReaderError(path, f"bone line before the first frame number: {raw.strip()!r}", lineno)
                raise ReaderError(path, f"unexpected text before the first frame number: {raw.strip()!r}", lineno)
            raise ReaderError(path, f"unknown bone {head!r} (not in skeleton {sk.path})", lineno)
        at_end = True
        close_frame(len(lines))
    except ReaderError as exc:
        # a file cut short: the last frame's bones end with the file (cut after a whole
        # line), or its last line - with no line break after it - is the one that is wrong
        # (cut in the middle of that line)
        cut = at_end or (not at_number and exc.line is not None and exc.line >= last_line
                         and ends_mid_line(path))
        if not (cut and row is not None and len(rows) > 1):
            raise
        rows.pop()
        dropped = frame_numbers.pop()
        frame_lines.pop()
        truncated = {"line": exc.line, "frame": dropped, "problem": exc.problem}
        log.warning("%s:%d: the file ends inside frame %d (%s): read the %d whole frames "
                    "before it, dropped that one", path, exc.line, dropped, exc.problem,
                    len(rows))
    if not rows:
        raise ReaderError(path, "no motion frames (no frame number lines)")

    data = np.array(rows, dtype=np.float64)
    if not np.all(np.isfinite(data)):
        f, c = np.argwhere(~np.isfinite(data))[0]
        raise ReaderError(path, f"non-finite value in frame {frame_numbers[f]}", frame_lines[f])
    take = _build_take(path, sk, data, layout, angle_unit, rate, frame_numbers[0],
                       fully_specified)
    if truncated is not None:
        take.meta["truncated"] = truncated
    return take


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
    c = _axis_quat(angle_to_deg(sk.root_orientation, sk.angle_unit), sk.root_axis_order)
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
        cols = [start + i for i, d in enumerate(b.dof) if d in ROT_DOFS]
        rot = [d for d in b.dof if d in ROT_DOFS]
        c = _axis_quat(angle_to_deg(b.axis, sk.angle_unit), b.axis_order)
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
        meta["metres_per_unit"] = CMU_METRES_PER_UNIT
        unit = "asf units (CMU: inches x 0.45; metres_per_unit in meta)"
    else:
        unit = f"asf units (length scale {sk.length:g})"
    return Take(joint_names=names, parents=parents, frame_rate=rate, quats=quats,
                root_position=root_position, space="local", length_unit=unit,
                source=str(path), meta=meta)


def skeleton_for(amc_path: str | Path) -> Path:
    """The ASF that goes with ``SS_TT.amc``: ``SS.asf`` in the same folder, else the only ASF
    there; for a symbolic link to an AMC with neither beside the link, the same beside the
    file it points to."""
    amc_path = Path(amc_path)
    if amc_path.is_symlink():
        try:
            return _skeleton_beside(amc_path)
        except ReaderError:
            target = amc_path.resolve()
            try:
                return _skeleton_beside(target)
            except ReaderError:
                pass
    return _skeleton_beside(amc_path)


def _skeleton_beside(amc_path: Path) -> Path:
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
    tried = ", ".join(dict.fromkeys(c.name for c in candidates))   # each name once
    raise ReaderError(amc_path, f"no skeleton given and none found beside it (looked for {tried}"
                      + (f"; {len(asfs)} .asf files there, give one: --skeleton FILE, skeleton=" if asfs else "") + ")")


def read_asf_amc(amc_path: str | Path, skeleton: str | Path | AsfSkeleton | None = None,
                 frame_rate: float | None = None) -> Take:
    """Read ``SS_TT.amc``; the skeleton defaults to ``SS.asf`` beside it."""
    if skeleton is None:
        skeleton = skeleton_for(amc_path)
    return read_amc(amc_path, skeleton, frame_rate=frame_rate)
