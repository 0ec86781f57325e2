"""Xsens MVN real-time network streaming ("MXTP" over UDP or TCP): the wire format.

Header and message parsers, the encoder, and :class:`MxtpStream` (a TCP stream cut into
messages).  Frames are rebuilt from messages by
:class:`rtseg.drivers.mvn.assembler.MvnAssembler` (also importable from here).  Pure
bytes, no sockets (see :mod:`rtseg.drivers.mvn.source`).

Wire format (big-endian), as in the "MVN real-time network streaming protocol
specification" and the receivers that follow it (e.g. wouterpot/xsens-to-osc
``server/xsens/read-mxtp.js``):

==========  ====  ==========================================================
offset      type  field
==========  ====  ==========================================================
0           6 B   ``"MXTP"`` + two ASCII digits: message type (``02`` = quaternion pose)
6           u32   sample counter (one per frame; every datagram of a frame repeats it)
10          u8    datagram counter: bits 0-6 index in the frame, bit 7 = last datagram
11          u8    number of items in this datagram
12          u32   time code, ms
16          u8    character (avatar) id
17          u8    body segment count
18          u8    prop count
19          u8    finger tracking segment count
20          2 B   reserved
22          u16   payload size in bytes
24          ...   payload
==========  ====  ==========================================================

Type 02 items, 32 bytes each: segment id i32, position x y z f32 (metres), orientation
quaternion **w x y z** f32 (global, segment -> world).  Body segments have ids 1..23
(:data:`SEGMENT_NAMES`), props and finger segments follow.  A frame may span several
datagrams (same sample counter; the last one carries bit 7); several characters arrive as
separate packets, selected by ``character``.  Types 12 (meta data: ``key:value`` lines),
13 (segment scaling), 24 (centre of mass) and 25 (SMPTE time code) are parsed into
:class:`MvnAssembler` attributes; other types (01 Euler, 03 points, 20-23 kinematics) are
counted in ``skipped_types`` and ignored; nothing is fatal.

Frame conventions at this boundary
----------------------------------
MVN's world is right-handed **Z-up** (X forward at calibration, Y left).  rtseg's is
right-handed **Y-up**: the cyclic relabelling (x, y, z)_mvn -> (y, z, x) maps one onto the
other (a rotation, no mirror): position ``(x, y, z) -> (y, z, x)``, quaternion
``(w, x, y, z) -> (y, z, x, w)`` (scalar-last).  :func:`encode_datagrams` applies the
inverse, so encode -> decode is exact to float32.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Sequence

import numpy as np

DEFAULT_PORT = 9763
MAGIC = b"MXTP"
HEADER = struct.Struct(">6sIBBIBBBB2xH")
HEADER_SIZE = HEADER.size                     # 24
ITEM_02 = np.dtype([("id", ">i4"), ("pos", ">f4", (3,)), ("quat", ">f4", (4,))])
ITEM_SIZE = ITEM_02.itemsize                  # 32
#: UDP payload limit that avoids IP fragmentation on Ethernet (1500 - 20 - 8)
DEFAULT_MAX_DATAGRAM = 1472
LAST_FLAG = 0x80
#: | |q|^2 - 1 | up to which a quaternion is passed on unchanged (float32 rounding of a unit
#: quaternion stays far below); accepted ones further off are renormalised
UNIT_EXACT = 1e-6
#: columns of a type-02 item read as 8 float32 (id, px, py, pz, qw, qx, qy, qz) that give
#: rtseg's quaternion (y, z, x, w) and position (y, z, x)
_QCOLS = [6, 7, 5, 4]
_PCOLS = [2, 3, 1]

#: Body segment names of MVN, segment id = index + 1.
SEGMENT_NAMES: tuple[str, ...] = (
    "Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head",
    "Right Shoulder", "Right Upper Arm", "Right Forearm", "Right Hand",
    "Left Shoulder", "Left Upper Arm", "Left Forearm", "Left Hand",
    "Right Upper Leg", "Right Lower Leg", "Right Foot", "Right Toe",
    "Left Upper Leg", "Left Lower Leg", "Left Foot", "Left Toe",
)
BODY_SEGMENTS = len(SEGMENT_NAMES)            # 23
#: MVN hierarchy: parent segment id of each body segment id (0 = root)
SEGMENT_PARENTS: dict[int, int] = {
    1: 0, 2: 1, 3: 2, 4: 3, 5: 4, 6: 5, 7: 6,
    8: 5, 9: 8, 10: 9, 11: 10, 12: 5, 13: 12, 14: 13, 15: 14,
    16: 1, 17: 16, 18: 17, 19: 18, 20: 1, 21: 20, 22: 21, 23: 22,
}
KNOWN_TYPES = {"01": "euler pose", "02": "quaternion pose", "03": "point positions",
               "12": "meta data", "13": "scaling", "20": "joint angles",
               "21": "linear segment kinematics", "22": "angular segment kinematics",
               "23": "motion tracker kinematics", "24": "centre of mass", "25": "time code"}


class MvnParseError(ValueError):
    """Malformed MXTP bytes (short header, bad magic, sizes that overrun the datagram)."""


@dataclass(slots=True)
class MxtpHeader:
    """The 24-byte header.  ``index``: datagram index in the frame; ``last``: bit 7."""
    msg_type: str
    sample: int
    index: int
    last: bool
    items: int
    time_ms: int
    character: int
    body_segments: int
    props: int
    finger_segments: int
    payload_size: int


def parse_header(data: bytes) -> MxtpHeader:
    """Header of one datagram; raises :class:`MvnParseError`."""
    if len(data) < HEADER_SIZE:
        raise MvnParseError(f"datagram of {len(data)} bytes is shorter than the 24-byte header")
    (ident, sample, dgram, items, time_ms, char, body, props, fingers,
     size) = HEADER.unpack_from(data)
    if ident[:4] != MAGIC or not ident[4:6].isdigit():
        raise MvnParseError(f"not an MXTP datagram (starts {bytes(data[:6])!r})")
    if size > len(data) - HEADER_SIZE:
        raise MvnParseError(f"payload size {size} overruns the {len(data)}-byte datagram")
    return MxtpHeader(ident[4:6].decode("ascii"), sample, dgram & 0x7F, bool(dgram & LAST_FLAG),
                      items, time_ms, char, body, props, fingers, size)


def payload_of(data: bytes, hdr: MxtpHeader) -> memoryview:
    """The payload bytes.  A payload size of 0 with data present (some senders leave it
    unset) means 'the rest of the datagram'."""
    end = HEADER_SIZE + (hdr.payload_size or (len(data) - HEADER_SIZE))
    return memoryview(data)[HEADER_SIZE:end]


def parse_pose(data: bytes, hdr: MxtpHeader) -> np.ndarray:
    """Type-02 items as a structured array (fields ``id``, ``pos`` (3,), ``quat`` (4,)
    w x y z, MVN frame, big-endian float32).  Raises :class:`MvnParseError` when the items
    do not fit the payload."""
    payload = payload_of(data, hdr)
    need = hdr.items * ITEM_SIZE
    if need > len(payload):
        raise MvnParseError(f"{hdr.items} pose items need {need} bytes, payload has {len(payload)}")
    return np.frombuffer(payload, dtype=ITEM_02, count=hdr.items)


def parse_meta(payload: bytes) -> dict[str, str]:
    """Type-12 meta data: ``key:value`` lines (``name``, ``xmid``, ``color`` ...).  A
    leading u32 string length, as some receivers read it, is honoured when it fits."""
    raw = bytes(payload)
    if len(raw) >= 4:
        n = int.from_bytes(raw[:4], "big")
        if 0 < n <= len(raw) - 4:
            raw = raw[4:4 + n]
    out: dict[str, str] = {}
    for line in raw.decode("utf-8", errors="replace").replace("\r", "\n").split("\n"):
        key, sep, value = line.partition(":")
        if sep and key.strip():
            out[key.strip()] = value.strip().rstrip("\x00")
    return out


def parse_scaling(payload: bytes) -> dict[str, tuple[float, float, float]]:
    """Type-13 segment scaling (null pose): u32 segment count, then per segment a u32 name
    length, the name and a position x y z f32 (MVN frame).  Returns what parsed before any
    truncation (never raises)."""
    raw = bytes(payload)
    out: dict[str, tuple[float, float, float]] = {}
    if len(raw) < 4:
        return out
    count = int.from_bytes(raw[:4], "big")
    pos = 4
    for _ in range(min(count, 4096)):
        if pos + 4 > len(raw):
            break
        n = int.from_bytes(raw[pos:pos + 4], "big")
        if n > 1024 or pos + 4 + n + 12 > len(raw):
            break
        name = raw[pos + 4:pos + 4 + n].decode("utf-8", errors="replace")
        xyz = struct.unpack_from(">3f", raw, pos + 4 + n)
        out[name] = xyz
        pos += 4 + n + 12
    return out


# --------------------------------------------------------------------------- encoder

def to_mvn_quat(q: np.ndarray) -> np.ndarray:
    """rtseg scalar-last Y-up (x, y, z, w) -> MVN Z-up (w, x, y, z)."""
    q = np.asarray(q)
    return np.stack([q[..., 3], q[..., 2], q[..., 0], q[..., 1]], axis=-1)


def from_mvn_quat(q: np.ndarray) -> np.ndarray:
    """MVN Z-up (w, x, y, z) -> rtseg scalar-last Y-up (x, y, z, w) = (y, z, x, w)."""
    q = np.asarray(q)
    return np.stack([q[..., 2], q[..., 3], q[..., 1], q[..., 0]], axis=-1)


def to_mvn_pos(p: np.ndarray) -> np.ndarray:
    """rtseg (x, y, z) Y-up -> MVN (z, x, y) Z-up."""
    p = np.asarray(p)
    return np.stack([p[..., 2], p[..., 0], p[..., 1]], axis=-1)


def from_mvn_pos(p: np.ndarray) -> np.ndarray:
    """MVN (x, y, z) Z-up -> rtseg (y, z, x) Y-up."""
    p = np.asarray(p)
    return np.stack([p[..., 1], p[..., 2], p[..., 0]], axis=-1)


def encode_header(msg_type: str, sample: int, index: int, last: bool, items: int,
                  time_ms: int, character: int, body: int, props: int, fingers: int,
                  payload_size: int) -> bytes:
    return HEADER.pack(MAGIC + msg_type.encode("ascii"), sample & 0xFFFFFFFF,
                       (index & 0x7F) | (LAST_FLAG if last else 0), items, time_ms & 0xFFFFFFFF,
                       character, body, props, fingers, payload_size)


def encode_datagrams(sample: int, time_ms: int, segment_ids: Sequence[int],
                     quats: np.ndarray, positions: np.ndarray | None = None, *,
                     character: int = 0, body_segments: int = BODY_SEGMENTS,
                     props: int = 0, finger_segments: int = 0,
                     max_datagram: int = DEFAULT_MAX_DATAGRAM) -> list[bytes]:
    """One frame as type-02 datagrams of at most ``max_datagram`` bytes.

    ``quats`` (n, 4) global orientations in rtseg's frame (scalar-last, Y-up);
    ``positions`` (n, 3) metres, rtseg frame (default zeros).  Values go out as float32."""
    q = np.asarray(quats, dtype=np.float64)
    n = len(segment_ids)
    if q.shape != (n, 4):
        raise ValueError(f"quats must be ({n}, 4), got {q.shape}")
    per = min(255, (max_datagram - HEADER_SIZE) // ITEM_SIZE)   # items per datagram (u8)
    if per < 1:
        raise ValueError(f"max_datagram {max_datagram} cannot hold one {ITEM_SIZE}-byte item")
    items = np.zeros(n, dtype=ITEM_02)
    items["id"] = np.asarray(segment_ids, dtype=np.int64)
    items["quat"] = to_mvn_quat(q)
    if positions is not None:
        items["pos"] = to_mvn_pos(np.asarray(positions, dtype=np.float64))
    chunks = [items[a:a + per] for a in range(0, max(n, 1), per)] if n else [items[:0]]
    if len(chunks) > 0x80:
        raise ValueError(f"{n} items need {len(chunks)} datagrams; at most 128 per frame")
    out = []
    for k, chunk in enumerate(chunks):
        body = chunk.tobytes()
        out.append(encode_header("02", sample, k, k == len(chunks) - 1, len(chunk), time_ms,
                                 character, body_segments, props, finger_segments, len(body))
                   + body)
    return out


def encode_message(msg_type: str, payload: bytes, *, sample: int = 0, time_ms: int = 0,
                   character: int = 0, items: int = 0) -> bytes:
    """A single-datagram message of any type (meta 12, scaling 13, 24, 25 ...)."""
    return encode_header(msg_type, sample, 0, True, items, time_ms, character, BODY_SEGMENTS,
                         0, 0, len(payload)) + payload


# --------------------------------------------------------------------------- TCP stream

class MxtpStream:
    """TCP byte stream -> MXTP messages.  Over TCP (MVN's optional transport) the messages
    are the UDP datagrams sent back to back, each 24-byte header + ``payload size`` bytes
    (a type-02 message whose size field is 0 takes ``items`` x 32 bytes; one whose size is
    neither 0 nor that is a damaged header).  ``feed`` returns the complete messages;
    bytes that do not start a header (damage, a partial message after a reconnect) are
    skipped up to the next ``"MXTP"`` + two digits, and each such resynchronisation is
    counted in ``resyncs`` / ``skipped_bytes``.  A damaged size field of another type can
    swallow up to 64 KiB (its u16 limit) before the stream is in step again."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.resyncs = 0
        self.skipped_bytes = 0

    def feed(self, data: bytes) -> list[bytes]:
        buf = self._buf
        buf += data
        out: list[bytes] = []
        pos = 0
        while len(buf) - pos >= HEADER_SIZE:
            if buf[pos:pos + 4] != MAGIC or not buf[pos + 4:pos + 6].isdigit():
                nxt = self._next_magic(buf, pos + 1)
                self.resyncs += 1
                self.skipped_bytes += nxt - pos
                pos = nxt
                continue
            size = int.from_bytes(buf[pos + 22:pos + 24], "big")
            if buf[pos + 4:pos + 6] == b"02":
                items = buf[pos + 11] * ITEM_SIZE
                if size not in (0, items):         # a damaged header: do not trust it
                    nxt = self._next_magic(buf, pos + 1)
                    self.resyncs += 1
                    self.skipped_bytes += nxt - pos
                    pos = nxt
                    continue
                size = items
            end = pos + HEADER_SIZE + size
            if end > len(buf):
                break
            out.append(bytes(buf[pos:end]))
            pos = end
        if len(buf) - pos < HEADER_SIZE and pos < len(buf) and \
                not MAGIC.startswith(bytes(buf[pos:pos + 4])):
            nxt = self._next_magic(buf, pos + 1)      # a tail that cannot start a header
            self.resyncs += 1
            self.skipped_bytes += nxt - pos
            pos = nxt
        del buf[:pos]
        return out

    @staticmethod
    def _next_magic(buf: bytearray, start: int) -> int:
        """Index of the next ``"MXTP"`` at or after ``start`` (or of a trailing partial
        one), else the end of ``buf``."""
        k = buf.find(MAGIC, start)
        if k >= 0:
            return k
        for tail in (3, 2, 1):                     # "M", "MX", "MXT" at the very end
            if len(buf) - tail >= start and buf.endswith(MAGIC[:tail]):
                return len(buf) - tail
        return len(buf)

    def reset(self) -> None:
        """Forget a partial message (after a reconnect)."""
        self._buf.clear()


def segment_parent_ids(ids: Sequence[int]) -> list[int]:
    """Parent indices (into ``ids``) from MVN's body hierarchy; -1 when the parent segment
    is not among ``ids``."""
    where = {s: k for k, s in enumerate(ids)}
    return [where.get(SEGMENT_PARENTS.get(s, 0), -1) for s in ids]


__all__ = ["MxtpStream", "MvnParseError", "MxtpHeader", "parse_header", "parse_pose", "payload_of",
           "parse_meta", "parse_scaling", "encode_datagrams", "encode_message",
           "encode_header", "SEGMENT_NAMES", "SEGMENT_PARENTS", "DEFAULT_PORT",
           "from_mvn_quat", "to_mvn_quat", "from_mvn_pos", "to_mvn_pos"]
