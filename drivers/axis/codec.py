"""Noitom Axis Neuron / Axis Studio "BVH broadcast": bytes <-> skeleton frames (no sockets).

Axis streams the BVH motion line of each frame, per avatar, in two encodings
(sources: the Axis Neuron user manual's "BVH data" section as implemented by
sojamo/axis-streamer ``src/bvh/BvhStream.js`` and ``BvhConstants.js``, ISC licence):

**Binary** (UDP, default port 7002), little-endian, a 64-byte header then ``data count``
float32 values::

    offset type      field
    0      u16       token 0xDDFF (bytes FF DD)
    2      4 x u8    data version: build, revision, minor, major (1.1.0.0 = 00 00 01 01)
    6      u16       data count (number of f32 values that follow)
    8      u8        with displacement (1: 6 channels per joint)
    9      u8        with reference (1: 6 leading values for the reference bone)
    10     u32       avatar index
    14     32 bytes  avatar name, ASCII, NUL padded
    46     u32       frame index
    50     3 x u32   reserved
    62     u16       token 0xEEFF (bytes FF EE)
    64     f32 x n   values

On macOS Axis Neuron splits a frame over two datagrams (the first 1024 bytes long);
:class:`BinaryAssembler` joins the parts.

**Text** (TCP, Axis is the server, default port 7001): frames separated by ``||``; each is
``<avatar index> <avatar name> <value> <value> ...`` separated by white space.

Values: 59 joints (:data:`JOINTS`, the BVH hierarchy of Axis Neuron's skeleton, parents in
:data:`PARENTS`).  With displacement each joint has 6 channels - position x y z (cm) then
the three rotation angles (degrees) in the configured Euler order (default ``YXZ``, the BVH
channel order ``Yrotation Xrotation Zrotation``): 354 values.  Without displacement: the
root position (3) and 3 angles per joint: 180 values.  With reference, 6 more values (the
reference bone's position and rotation) come first (360 / 186).  The text format has no
flags: its layout is inferred from the value count, which is unambiguous.

Frames and conventions: BVH's right-handed Y-up world; a joint's rotation is relative to its
parent (``space = "local"``) and is R = R_a(angle0) R_b(angle1) R_c(angle2) for order "abc"
(intrinsic, as :mod:`rtseg.drivers.readers.bvh` reads BVH channels); quaternions float64
scalar-last.  The root position is returned in metres (``unit_scale`` = 0.01 per cm).

The skeleton and the pose maths (Euler angles -> quaternions, forward kinematics, a frame's
values -> poses) live in :mod:`rtseg.drivers.axis.pose`; their public names are importable
from here too.

Errors: decoders raise :class:`AxisError` whose ``kind`` is the SourceStats counter it
belongs to (``corrupt``: bad tokens, truncated or unparsable bytes; ``bad_messages``: a
well-formed frame whose value count fits no layout) - never any other exception.  Joints
with non-finite angles come back invalid.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from rtseg.drivers.axis.pose import (JOINTS, PARENTS, euler_to_quat, global_pose, poses,
                                     quat_to_euler, to_pose, to_poses)

__all__ = ["JOINTS", "PARENTS", "TEXT_PORT", "BINARY_PORT", "HEADER", "TOKEN1", "TOKEN2",
           "AxisError", "AxisFrame", "layout", "value_count", "decode_binary",
           "encode_binary", "euler_to_quat", "quat_to_euler", "to_pose", "to_poses",
           "poses", "global_pose", "BinaryAssembler", "SUIT_SEGMENTS"]

TEXT_PORT = 7001
BINARY_PORT = 7002
TOKEN1 = 0xDDFF
TOKEN2 = 0xEEFF
#: the 64-byte header (see module docstring)
HEADER = struct.Struct("<H4BHBBI32sIIIIH")
assert HEADER.size == 64

#: Unity HumanBodyBones suit bone (``config/suits.toml`` suit ``axis``) -> Axis joint that
#: carries the same body segment (the simulator's map; Chest is the thorax the arms hang
#: from, Spine3)
SUIT_SEGMENTS: dict[str, str] = {
    "Hips": "Hips", "Spine": "Spine", "Chest": "Spine3", "Neck": "Neck", "Head": "Head",
    **{f"{s}{b}": f"{s}{a}" for s in ("Left", "Right") for b, a in (
        ("Shoulder", "Shoulder"), ("UpperArm", "Arm"), ("LowerArm", "ForeArm"),
        ("Hand", "Hand"), ("UpperLeg", "UpLeg"), ("LowerLeg", "Leg"), ("Foot", "Foot"))},
}


class AxisError(ValueError):
    """Bytes that are not a usable frame.  ``kind``: the SourceStats counter it belongs to."""

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind


@dataclass(slots=True)
class AxisFrame:
    """One decoded frame: ``values`` (data count,) float64 as sent (float32 exact for
    binary), ``with_disp``/``with_ref`` layout flags, ``frame_index`` (binary only),
    ``version`` (major, minor, revision, build) (binary only), ``finite``: whether every
    value is finite when the decoder knows it (None: not checked)."""
    avatar_index: int
    avatar_name: str
    values: np.ndarray
    with_disp: bool
    with_ref: bool
    frame_index: int | None = None
    version: tuple[int, int, int, int] | None = None
    finite: bool | None = None


def value_count(with_disp: bool, with_ref: bool, joints: int = len(JOINTS)) -> int:
    """Values per frame for a layout (354, 360, 180 or 186 for 59 joints)."""
    return (6 * joints if with_disp else 3 + 3 * joints) + (6 if with_ref else 0)


def layout(count: int, joints: int = len(JOINTS)) -> tuple[bool, bool]:
    """(with_disp, with_ref) of a frame of ``count`` values; AxisError if none fits."""
    for disp in (True, False):
        for ref in (False, True):
            if value_count(disp, ref, joints) == count:
                return disp, ref
    raise AxisError("bad_messages", f"{count} values fit no layout of {joints} joints "
                    f"(expected {value_count(True, False, joints)}, "
                    f"{value_count(True, True, joints)}, {value_count(False, False, joints)} "
                    f"or {value_count(False, True, joints)})")


# --------------------------------------------------------------------------- binary

def binary_length(data: bytes) -> int | None:
    """Total bytes of the binary frame starting ``data`` (from its header), or None if
    ``data`` does not start with token 0xDDFF or is shorter than 8 bytes."""
    if len(data) < 8 or data[0] != 0xFF or data[1] != 0xDD:
        return None
    return HEADER.size + 4 * (data[6] | (data[7] << 8))


def decode_binary(data: bytes, joints: int = len(JOINTS)) -> AxisFrame:
    """One binary frame (header + values, exactly), see the module docstring."""
    if len(data) < HEADER.size:
        raise AxisError("corrupt", f"{len(data)} bytes: shorter than the 64-byte header")
    (tok1, build, rev, minor, major, count, disp, ref, avatar, name, frame, _r0, _r1, _r2,
     tok2) = HEADER.unpack_from(data)
    if tok1 != TOKEN1 or tok2 != TOKEN2:
        raise AxisError("corrupt", f"header tokens {tok1:#06x}/{tok2:#06x}, expected "
                        f"0xddff/0xeeff")
    if len(data) != HEADER.size + 4 * count:
        raise AxisError("corrupt", f"header announces {count} values "
                        f"({HEADER.size + 4 * count} bytes), got {len(data)} bytes")
    want = value_count(bool(disp), bool(ref), joints)
    if disp > 1 or ref > 1 or count != want:
        raise AxisError("bad_messages", f"{count} values with displacement={disp}, "
                        f"reference={ref}: expected {want} for {joints} joints")
    values = np.frombuffer(data, dtype="<f4", count=count, offset=HEADER.size)
    finite = bool(np.isfinite(values).all())
    if finite:
        values = values.astype(np.float64)
    else:
        with np.errstate(invalid="ignore"):   # signalling NaNs stay NaN, quietly
            values = values.astype(np.float64)
    return AxisFrame(avatar, name.split(b"\0", 1)[0].decode("ascii", "replace"),
                     values, bool(disp), bool(ref), frame, (major, minor, rev, build), finite)


def encode_binary(values: np.ndarray, *, with_disp: bool = True, with_ref: bool = False,
                  avatar_index: int = 0, avatar_name: str = "Avatar00",
                  frame_index: int = 0, version: tuple[int, int, int, int] = (1, 1, 0, 0)
                  ) -> bytes:
    """Header + float32 values (``version`` as (major, minor, revision, build))."""
    v = np.ascontiguousarray(values, dtype="<f4")
    major, minor, rev, build = version
    head = HEADER.pack(TOKEN1, build, rev, minor, major, v.size, int(with_disp), int(with_ref),
                       avatar_index & 0xFFFFFFFF, avatar_name.encode("ascii")[:32],
                       frame_index & 0xFFFFFFFF, 0, 0, 0, TOKEN2)
    return head + v.tobytes()


class BinaryAssembler:
    """Datagrams -> complete binary frames (bytes), joining a frame split over several
    datagrams (header datagram first).  ``feed`` returns (frames, errors) where errors are
    AxisError for datagrams that cannot belong to a frame; an incomplete frame older than
    ``timeout`` s is abandoned (``flush`` reports it)."""

    def __init__(self, timeout: float = 0.1, max_bytes: int = 1 << 18) -> None:
        self.timeout = timeout
        self.max_bytes = max_bytes
        self._pending = bytearray()
        self._want = 0
        self._since = 0.0

    def feed(self, data: bytes, now: float) -> tuple[list[bytes], list[AxisError]]:
        errors: list[AxisError] = []
        n = binary_length(data)
        if n is not None:                           # a new frame starts
            if self._pending:
                errors.append(AxisError("corrupt", "frame cut short by the next header"))
                self._pending.clear()
            if len(data) >= n:
                if len(data) > n:
                    errors.append(AxisError("corrupt", f"{len(data) - n} bytes after the "
                                            "frame"))
                return [bytes(data[:n])], errors
            if n > self.max_bytes:
                return [], [AxisError("corrupt", f"header announces {n} bytes")]
            self._pending += data
            self._want, self._since = n, now
            return [], errors
        if not self._pending:
            return [], [AxisError("corrupt", f"{len(data)}-byte datagram without header")]
        self._pending += data
        if len(self._pending) < self._want:
            return [], errors
        frame = bytes(self._pending[:self._want])
        extra = len(self._pending) - self._want
        self._pending.clear()
        if extra:
            errors.append(AxisError("corrupt", f"{extra} bytes after the frame"))
        return [frame], errors

    def flush(self, now: float) -> AxisError | None:
        if self._pending and now - self._since > self.timeout:
            self._pending.clear()
            return AxisError("corrupt", "frame incomplete (continuation datagram lost)")
        return None
