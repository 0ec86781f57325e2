"""Biovision BVH reader.

Conventions
-----------
- Every ``ROOT``/``JOINT`` becomes a take joint (parents before children, file order); its
  name is the rest of its line up to ``{``, spaces kept (3ds Max Biped: ``Bip01 L Thigh``);
  ``End Site`` blocks are not joints: their offsets go to ``meta["end_sites"]``.
- Rotation channels may come in any order per joint; the joint's rotation relative to its
  parent is the product of the elementary rotations in channel order:
  ``Zrotation Xrotation Yrotation`` gives R = Rz·Rx·Ry (``rtseg.core.quat.from_euler("ZXY")``),
  angles in degrees.  A joint without rotation channels has the identity.
- Position channels may be on any joint and in any order.  The first root's go to
  ``root_position`` (x, y, z, file units, ``None`` if it has none); those of other joints to
  ``meta["joint_positions"][name]`` as (frames, 3) arrays.
- ``Frame Time`` (seconds) gives the frame rate (within ``RATE_SNAP_HZ`` of a whole number:
  that number); ``frame_rate`` overrides it.

Malformed input raises ``ReaderError`` naming the file, the line and the problem, except a
file cut short (as the AMC reader, ``rtseg.drivers.readers.amc``): fewer frame lines than
``Frames:`` declares, the file ending after a whole line, or its last line - with no line
break after it, cut in the middle - short, not a number, or not the last frame declared.
The whole frames before the cut are read and one warning says how many of how many
declared (``meta["truncated"]``: the cut line or None, the frame number dropped or None,
the problem, ``read`` and ``declared``).  A file with no whole frame, more frame lines than
declared, or a bad line before the last stays an error.
"""

from __future__ import annotations

import logging
import math
import re
from pathlib import Path

import numpy as np

from rtseg.core import quat as Q
from rtseg.drivers.readers.errors import ReaderError, ends_mid_line, is_number, read_text_lines
from rtseg.core.take import Take

log = logging.getLogger("rtseg.readers")

_TOKEN_RE = re.compile(r"[{}]|[^\s{}]+")
_CHANNELS = {"xposition": "px", "yposition": "py", "zposition": "pz",
             "xrotation": "X", "yrotation": "Y", "zrotation": "Z"}


class _Joint:
    __slots__ = ("name", "parent", "offset", "channels", "line")

    def __init__(self, name: str, parent: int, line: int) -> None:
        self.name = name
        self.parent = parent
        self.offset = np.zeros(3)
        self.channels: list[str] = []
        self.line = line


#: a rate from ``Frame Time`` within this (Hz) of a whole number is that number (the
#: header's few decimals: 0.0333333 s; 29.97 Hz stays 29.97)
RATE_SNAP_HZ = 1e-3


def read_bvh(path: str | Path, frame_rate: float | None = None) -> Take:
    """Read a BVH file into a local-space ``Take``."""
    path = Path(path)
    lines = read_text_lines(path)
    tokens: list[tuple[str, int]] = []
    motion_line = None
    for lineno, raw in enumerate(lines, start=1):
        if raw.strip().upper() == "MOTION":
            motion_line = lineno
            break
        tokens.extend((t, lineno) for t in _TOKEN_RE.findall(raw))
    if not tokens or tokens[0][0].upper() != "HIERARCHY":
        raise ReaderError(path, "does not start with HIERARCHY (not a BVH file?)",
                          tokens[0][1] if tokens else None)
    if motion_line is None:
        raise ReaderError(path, "no MOTION section")

    joints: list[_Joint] = []
    end_sites: dict[str, np.ndarray] = {}
    stack: list[int | str] = []  # joint index, or "end" for an End Site block
    pos = 1
    n_tok = len(tokens)

    def take_token(what: str) -> tuple[str, int]:
        nonlocal pos
        if pos >= n_tok:
            raise ReaderError(path, f"hierarchy ends early, expected {what}", motion_line)
        tok = tokens[pos]
        pos += 1
        return tok

    def expect_brace(after: str) -> None:
        tok, ln = take_token("'{'")
        if tok != "{":
            raise ReaderError(path, f"expected '{{' after {after}, got {tok!r}", ln)

    pending_end_parent: int | None = None
    names_seen: set[str] = set()
    while pos < n_tok:
        tok, ln = take_token("a keyword")
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            name, nln = take_token("a joint name")
            if name in "{}":
                raise ReaderError(path, f"{tok} without a name", nln)
            while pos < n_tok and tokens[pos][1] == nln and tokens[pos][0] not in ("{", "}"):
                name += " " + tokens[pos][0]     # a name with spaces: "Bip01 L Thigh"
                pos += 1
            if key == "ROOT":
                if stack:
                    raise ReaderError(path, f"ROOT {name!r} inside another joint", ln)
                parent = -1
            else:
                if not stack or stack[-1] == "end":
                    raise ReaderError(path, f"JOINT {name!r} outside a ROOT/JOINT block", ln)
                parent = int(stack[-1])
            if name in names_seen:
                raise ReaderError(path, f"joint name {name!r} used twice", ln)
            names_seen.add(name)
            joints.append(_Joint(name, parent, ln))
            expect_brace(f"{tok} {name}")
            stack.append(len(joints) - 1)
        elif key == "END":
            site, sln = take_token("'Site'")
            if site.upper() != "SITE":
                raise ReaderError(path, f"expected 'End Site', got 'End {site}'", sln)
            if not stack or stack[-1] == "end":
                raise ReaderError(path, "End Site outside a joint", ln)
            pending_end_parent = int(stack[-1])
            expect_brace("End Site")
            stack.append("end")
        elif key == "OFFSET":
            vals = []
            for _ in range(3):
                v, vln = take_token("an OFFSET value")
                try:
                    vals.append(float(v))
                except ValueError:
                    raise ReaderError(path, f"OFFSET value {v!r} is not a number", vln) from None
                if not math.isfinite(vals[-1]):
                    raise ReaderError(path, f"OFFSET value {v!r} is not a finite number", vln)
            if not stack:
                raise ReaderError(path, "OFFSET outside a joint", ln)
            if stack[-1] == "end":
                assert pending_end_parent is not None
                end_sites[joints[pending_end_parent].name] = np.array(vals)
            else:
                joints[int(stack[-1])].offset = np.array(vals)
        elif key == "CHANNELS":
            if not stack or stack[-1] == "end":
                raise ReaderError(path, "CHANNELS outside a ROOT/JOINT block", ln)
            cnt, cln = take_token("the channel count")
            try:
                n = int(cnt)
            except ValueError:
                raise ReaderError(path, f"CHANNELS count {cnt!r} is not an integer", cln) from None
            if not 0 <= n <= 9:
                raise ReaderError(path, f"CHANNELS count {n} out of range", cln)
            chans = []
            for _ in range(n):
                c, chln = take_token("a channel name")
                code = _CHANNELS.get(c.lower())
                if code is None:
                    raise ReaderError(path, f"unknown channel {c!r} (CHANNELS says {n} channels)", chln)
                chans.append(code)
            if len(set(chans)) != len(chans):
                raise ReaderError(path, "channel listed twice", ln)
            joints[int(stack[-1])].channels = chans
        elif tok == "}":
            if not stack:
                raise ReaderError(path, "unmatched '}'", ln)
            stack.pop()
        else:
            raise ReaderError(path, f"unexpected {tok!r} in HIERARCHY", ln)
    if stack:
        raise ReaderError(path, "HIERARCHY has an unclosed '{'", motion_line)
    if not joints:
        raise ReaderError(path, "HIERARCHY has no ROOT")

    # MOTION header.
    idx = motion_line  # 0-based index of the line after MOTION
    header: dict[str, str] = {}
    while idx < len(lines) and not ("frames" in header and "time" in header):
        raw = lines[idx].strip()
        idx += 1
        if not raw:
            continue
        low = raw.lower()
        if low.startswith("frames:"):
            header["frames"] = raw.split(":", 1)[1].strip()
            header["frames_line"] = str(idx)
        elif low.startswith("frame time:"):
            header["time"] = raw.split(":", 1)[1].strip()
            header["time_line"] = str(idx)
        else:
            raise ReaderError(path, f"expected 'Frames:' and 'Frame Time:' after MOTION, got {raw!r}", idx)
    if "frames" not in header or "time" not in header:
        raise ReaderError(path, "MOTION lacks 'Frames:' or 'Frame Time:'", idx)
    try:
        n_frames = int(header["frames"])
    except ValueError:
        raise ReaderError(path, f"Frames: {header['frames']!r} is not an integer",
                          int(header["frames_line"])) from None
    try:
        frame_time = float(header["time"])
    except ValueError:
        raise ReaderError(path, f"Frame Time: {header['time']!r} is not a number",
                          int(header["time_line"])) from None
    if n_frames < 0:
        raise ReaderError(path, f"Frames: {n_frames} is negative", int(header["frames_line"]))
    if frame_rate is not None:
        rate = float(frame_rate)
        if not (rate > 0 and math.isfinite(rate)):
            raise ReaderError(path, f"frame rate must be positive, got {frame_rate}")
    else:
        if not (frame_time > 0 and math.isfinite(frame_time)
                and math.isfinite(1.0 / frame_time)):
            raise ReaderError(path, f"Frame Time {header['time']} must be a positive number "
                                    "of seconds", int(header["time_line"]))
        rate = 1.0 / frame_time
        if abs(rate - round(rate)) < RATE_SNAP_HZ:   # 0.0333333 s is 30 Hz, not 30.00003
            rate = float(round(rate))

    n_ch = sum(len(j.channels) for j in joints)
    data_rows: list[list[str]] = []
    data_lines: list[int] = []
    last_line = len(lines)                   # the last line holding text
    while last_line > idx and not lines[last_line - 1].strip():
        last_line -= 1
    truncated: dict | None = None
    for lineno in range(idx + 1, last_line + 1):
        toks = lines[lineno - 1].split()
        if not toks:
            continue
        frame = len(data_rows) + 1
        problem = (f"frame {frame} has {len(toks)} values, expected {n_ch}"
                   if len(toks) != n_ch else None)
        if lineno == last_line and frame <= n_frames and ends_mid_line(path):
            # the last line, no line break after it: the file was cut inside it.  Dropped
            # when it is wrong, or when frames are still missing (whole-looking, its last
            # number may be cut short); the last frame declared, whole, is kept (a file
            # without a final line break)
            if problem is None:
                bad = next((t for t in toks if not is_number(t)), None)
                if bad is not None:
                    problem = f"value {bad!r} is not a number"
                elif frame < n_frames:
                    problem = (f"its last value may be cut short, {n_frames - frame} "
                               f"more frames declared")
            if problem is not None:
                truncated = {"line": lineno, "frame": frame, "problem": problem}
                break
        if problem is not None:
            raise ReaderError(path, problem, lineno)
        data_rows.append(toks)
        data_lines.append(lineno)
    n_read = len(data_rows)
    if n_read > n_frames or (n_read < n_frames and not n_read):
        what = f"{n_read} frame lines follow" if n_read else "no whole frame line follows"
        if truncated is not None:
            what += f" (line {truncated['line']}, cut: {truncated['problem']})"
        raise ReaderError(path, f"'Frames: {n_frames}' but {what}", int(header["frames_line"]))
    if n_read < n_frames:                   # a file cut short: its whole frames
        if truncated is None:
            truncated = {"line": None, "frame": None,
                         "problem": f"the file ends after line {data_lines[-1]}"}
        truncated.update(read=n_read, declared=n_frames)
        n_frames = n_read
    try:
        data = np.array(data_rows, dtype=np.float64).reshape(n_frames, n_ch)
    except ValueError:
        for row, ln in zip(data_rows, data_lines):
            for t in row:
                try:
                    float(t)
                except ValueError:
                    raise ReaderError(path, f"value {t!r} is not a number", ln) from None
        raise
    if not np.all(np.isfinite(data)):
        r = int(np.argwhere(~np.isfinite(data))[0][0])
        raise ReaderError(path, "non-finite value", data_lines[r])
    if truncated is not None:               # one warning, once the frames read are good
        if truncated["line"] is None:
            log.warning("%s: cut short: the file ends after frame %d (line %d): read %d of "
                        "the %d frames 'Frames:' declares", path, n_frames, data_lines[-1],
                        n_frames, truncated["declared"])
        else:
            log.warning("%s:%d: cut short: the last line (frame %d) was cut (%s), dropped: "
                        "read %d of the %d frames 'Frames:' declares", path,
                        truncated["line"], truncated["frame"], truncated["problem"], n_frames,
                        truncated["declared"])

    # Rotations and positions.
    quats = np.empty((n_frames, len(joints), 4))
    root_position = None
    joint_positions: dict[str, np.ndarray] = {}
    col = 0
    for j, jt in enumerate(joints):
        cols = {c: col + k for k, c in enumerate(jt.channels)}
        col += len(jt.channels)
        rot = [c for c in jt.channels if c in ("X", "Y", "Z")]
        if rot:
            quats[:, j] = Q.from_euler("".join(rot), data[:, [cols[c] for c in rot]], degrees=True)
        else:
            quats[:, j] = Q.IDENTITY
        if any(c in cols for c in ("px", "py", "pz")):
            p = np.zeros((n_frames, 3))
            for a, c in enumerate(("px", "py", "pz")):
                if c in cols:
                    p[:, a] = data[:, cols[c]]
            if jt.parent < 0 and root_position is None:
                root_position = p
            else:
                joint_positions[jt.name] = p
    meta = {
        "format": "bvh",
        "frame_time": frame_time,
        "channels": {jt.name: list(jt.channels) for jt in joints},
        "offsets": np.array([jt.offset for jt in joints]),
        "end_sites": end_sites,
        "joint_positions": joint_positions,
    }
    if truncated is not None:
        meta["truncated"] = truncated
    return Take(joint_names=[jt.name for jt in joints], parents=[jt.parent for jt in joints],
                frame_rate=rate, quats=quats, root_position=root_position, space="local",
                length_unit="bvh units (unspecified by the format; often cm)",
                source=str(path), meta=meta)
