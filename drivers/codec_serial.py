"""rtseg's serial wire format: the reference encoder and streaming decoders.

This module is the specification.  Firmware authors: implement :func:`encode_frame`
(about 40 lines of C); everything else here is the receiver.

Binary format, version 1
========================

Every message travels as::

    0x00 | COBS( body || crc16 ) | 0x00

- **COBS** (Consistent Overhead Byte Stuffing, Cheshire & Baker 1999) removes every zero
  byte from ``body || crc16`` at a cost of one byte per 254, so 0x00 only ever appears as
  the delimiter.  A zero **before and after** each message lets the receiver
  resynchronise after boot-log text, line noise or a message cut short by a replug: it
  simply waits for the next 0x00.  Two consecutive zeros (one message's tail, the next
  one's head) are normal and ignored.
- **crc16** is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR)
  of ``body`` only, sent **little-endian** like every other field.  In Python:
  ``binascii.crc_hqx(body, 0xFFFF)``; check value: CRC of ``b"123456789"`` is ``0x29B1``.

Body, all fields little-endian::

    offset size type  field
    0      1    u8    version = 1
    1      1    u8    message type: 1 orientation frame, 2 sensor status, 3 device info
    2      2    u16   sequence number, +1 per message of any type, wraps 65535 -> 0
    4      4    u32   device time in microseconds (wraps after ~71.6 minutes)
    8      ...        payload, by message type

Type 1, orientation frame (payload)::

    8      1    u8    n = number of sensor records that follow (0..255)
    9+10k  1    u8    sensor id (suit profile: config/suits.toml)
    10+10k 1    u8    status bits, see below
    11+10k 8    4xi16 quaternion w, x, y, z (scalar FIRST on the wire) in Q14:
                      value = int16 / 16384, so 1.0 = 16384 (the BNO055's native scale)

    body length must be exactly 9 + 10 n bytes.

Status bits (types 1 and 2)::

    bit 0      valid: the quaternion is a usable orientation
    bits 1-2   calibration level 0 (none) .. 3 (fully calibrated), as the BNO055 reports
    bit 3      error: the sensor reported a fault (I2C error, reset); treated as not valid
    bits 4-7   reserved, send 0, ignored by the receiver

Type 2, sensor status (no orientations; e.g. while calibrating)::

    8      1    u8    n
    9+2k   2    u8,u8 sensor id, status bits

Type 3, device info: UTF-8 text ``key=value`` pairs separated by ``;`` (e.g.
``fw=1.2.0;board=esp32;sensors=17;rate=120``), sent at boot and whenever it changes.

Sizes: a 17-sensor frame is 9 + 170 + 2 = 181 bytes before COBS, 183-184 after, 185-186
on the wire with its two delimiters.  At 120 Hz that is ~22 kB/s: use 460800 baud or more
(default 921600 8N1).  A frame of 25 or more sensors is longer than 254 bytes, so COBS
inserts an extra 0xFF block every 254 bytes; the decoder handles that too.

What the receiver does with each message (counters in :class:`DecoderStats`):

- not valid COBS (a code byte pointing past the end) -> ``bad_cobs``
- fewer than 10 bytes after COBS, or type 1/2 length not matching ``n`` -> ``bad_length``
- CRC mismatch -> ``bad_crc``
- version other than 1 -> ``bad_version``
- all of the above also add to ``corrupt`` and the message is dropped; nothing raises.
- unknown message type -> ``bad_messages``, dropped.
- a sensor whose status says valid but whose quaternion norm differs from 1 by more than
  :data:`NORM_TOLERANCE` (0.03; Q14 rounding moves the norm by < 1.5e-4) -> that sensor
  is marked not valid and counted in ``bad_values``; the rest of the frame is kept.
  Accepted quaternions are renormalised to unit length.
- a sensor id not in ``known_ids`` (when given) -> counted in ``unknown_ids``, kept in the
  decoded frame for the caller to ignore.
- bytes before the first delimiter after start/reset are skipped (``skipped_bytes``):
  the receiver cannot know where that message began.  A run of more than
  :data:`MAX_WIRE_BYTES` without a delimiter is discarded as ``corrupt``.

Text format
===========

What hobby sketches print (115200 baud is typical), one sensor per line::

    id,w,x,y,z[,status]\\n

``id`` an integer 0..255, ``w,x,y,z`` decimal floats (scalar first, like the binary
format), ``status`` optional integer with the status bits above (default 1 = valid,
calibration unknown).  ``\\r\\n`` endings and spaces around fields are accepted.

Lines group into frames: the current frame **closes** when

1. a line repeats a sensor id already in the current frame (that line opens the next
   frame) - so a sketch that loops over its sensors needs nothing else;
2. a blank line, or a line starting with ``#``, arrives (send one after each frame to
   cut the latency of rule 1 by a full frame);
3. every id in ``known_ids`` (when given) has been seen;
4. the caller calls :meth:`TextLineDecoder.flush` (the serial source does after a quiet
   gap of a third of the frame period).

Text frames have no sequence number or device clock (``seq`` and ``time_us`` are None),
so the receiver cannot count lost frames on a text link.  Lines that do not start with an
integer (boot logs) count as ``garbage_lines``; lines that do but have the wrong number of
fields or unparseable numbers count as ``bad_messages``; NaN/inf or non-unit quaternions
count in ``bad_values`` exactly as in the binary format.

Conventions at the boundary
===========================

The wire carries **w, x, y, z**; everything this module returns is **scalar-last
(x, y, z, w)** float64, rtseg's internal order.
"""

from __future__ import annotations

import struct
from binascii import crc_hqx
from dataclasses import asdict, dataclass
from typing import Iterable, Sequence

import numpy as np

VERSION = 1
MSG_FRAME = 1
MSG_STATUS = 2
MSG_INFO = 3
MSG_TYPES = {MSG_FRAME: "frame", MSG_STATUS: "status", MSG_INFO: "info"}

Q14_SCALE = 16384.0
"""Q14 fixed point: int16 value / 16384 = float value."""
Q14_RESOLUTION = 1.0 / Q14_SCALE
NORM_TOLERANCE = 0.03
"""Largest accepted | ||q|| - 1 | for a quaternion whose sensor claims to be valid."""

STATUS_VALID = 0x01
STATUS_CAL_SHIFT = 1
STATUS_CAL_MASK = 0x06
STATUS_ERROR = 0x08
STATUS_DEFAULT = STATUS_VALID | (3 << STATUS_CAL_SHIFT)
"""What :func:`encode_frame` sends when no status is given: valid, fully calibrated (0x07)."""

HEADER = struct.Struct("<BBHIB")  # version, type, seq, time_us, n
HEADER_SIZE = HEADER.size  # 9
COMMON = struct.Struct("<BBHI")  # the 8 bytes every message type starts with
RECORD_SIZE = 10
MAX_SENSORS = 255
MAX_BODY_BYTES = HEADER_SIZE + RECORD_SIZE * MAX_SENSORS
MAX_WIRE_BYTES = MAX_BODY_BYTES + 2 + (MAX_BODY_BYTES + 2) // 254 + 2 + 16
"""Longest run of non-zero bytes a valid message can produce; longer runs are noise."""

SENSOR_DTYPE = np.dtype([("id", "u1"), ("status", "u1"), ("q", "<i2", (4,))])
"""One sensor record of a type-1 body, for ``np.frombuffer``."""

_WXYZ_TO_XYZW = [1, 2, 3, 0]


def status_bits(valid: bool = True, calibration: int = 3, error: bool = False) -> int:
    """Compose a status byte: bit 0 valid, bits 1-2 calibration 0..3, bit 3 error."""
    if not 0 <= calibration <= 3:
        raise ValueError(f"calibration must be 0..3, got {calibration}")
    return (STATUS_VALID if valid else 0) | (calibration << STATUS_CAL_SHIFT) | (
        STATUS_ERROR if error else 0)


def calibration_level(status: int | np.ndarray) -> int | np.ndarray:
    """Calibration level 0..3 from status bits."""
    return (status & STATUS_CAL_MASK) >> STATUS_CAL_SHIFT


# --------------------------------------------------------------------------- COBS / CRC


def crc16(body: bytes | bytearray | memoryview) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF).  ``crc16(b"123456789") == 0x29B1``."""
    return crc_hqx(body, 0xFFFF)


def cobs_encode(data: bytes | bytearray) -> bytes:
    """COBS-encode ``data``: the result contains no zero byte and is at most
    ``len(data) + len(data) // 254 + 1`` bytes long."""
    out = bytearray()
    chunks = bytes(data).split(b"\x00")
    last = len(chunks) - 1
    for k, block in enumerate(chunks):
        full = False
        while len(block) >= 254:
            out.append(0xFF)
            out += block[:254]
            block = block[254:]
            full = True
        if k == last and full and not block:
            break  # canonical COBS: no empty block after a final 0xFF block
        out.append(len(block) + 1)
        out += block
    return bytes(out)


def _cobs_decode_general(src: bytes | bytearray) -> bytearray | None:
    """COBS decode handling 0xFF blocks; None if a code points past the end."""
    out = bytearray()
    i, n = 0, len(src)
    while i < n:
        code = src[i]
        if code == 0:
            return None
        end = i + code
        if end > n:
            return None
        out += src[i + 1:end]
        i = end
        if code < 0xFF and i < n:
            out.append(0)
    return out


def cobs_decode(src: bytes | bytearray) -> bytearray | None:
    """Decode one COBS block (no delimiters).  None if ``src`` is not valid COBS.

    Fast path for the common case of no 0xFF code: the decoded message is ``src[1:]`` with
    each later code byte replaced by the zero it stands for, so only code bytes are
    visited.
    """
    n = len(src)
    if n == 0:
        return None
    buf = bytearray(src)
    p = buf[0]
    if p == 0xFF:
        return _cobs_decode_general(src)
    while p < n:
        c = buf[p]
        if c == 0xFF or c == 0:
            return _cobs_decode_general(src)
        buf[p] = 0
        p += c
    if p != n:
        return None
    del buf[0]
    return buf


# --------------------------------------------------------------------------- encoder


def _q14(quats_xyzw: np.ndarray) -> np.ndarray:
    q = np.asarray(quats_xyzw, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"quaternions must be (n, 4) scalar-last, got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("cannot encode NaN/inf quaternions in Q14")
    wxyz = q[:, [3, 0, 1, 2]]
    return np.clip(np.rint(wxyz * Q14_SCALE), -32768, 32767).astype("<i2")


def frame_body(seq: int, time_us: int, ids: Sequence[int], quats_xyzw: np.ndarray,
               status: Sequence[int] | int | None = None) -> bytes:
    """The unframed type-1 body (no CRC, no COBS) - see the module docstring."""
    ids_a = np.asarray(ids, dtype=np.int64).reshape(-1)
    q14 = _q14(quats_xyzw)
    n = len(ids_a)
    if q14.shape[0] != n:
        raise ValueError(f"{n} sensor ids but {q14.shape[0]} quaternions")
    if n > MAX_SENSORS:
        raise ValueError(f"at most {MAX_SENSORS} sensors per frame, got {n}")
    if n and (ids_a.min() < 0 or ids_a.max() > 255):
        raise ValueError("sensor ids must be 0..255")
    if status is None:
        st = np.full(n, STATUS_DEFAULT, dtype=np.uint8)
    else:
        st = np.broadcast_to(np.asarray(status, dtype=np.int64), (n,))
        if n and (st.min() < 0 or st.max() > 255):
            raise ValueError("status must be 0..255")
    rec = np.empty(n, dtype=SENSOR_DTYPE)
    rec["id"] = ids_a
    rec["status"] = st
    rec["q"] = q14
    return HEADER.pack(VERSION, MSG_FRAME, seq & 0xFFFF, int(time_us) & 0xFFFFFFFF, n) + rec.tobytes()


def pack_message(body: bytes | bytearray) -> bytes:
    """Frame any body for the wire: ``0x00 | COBS(body || crc16_le(body)) | 0x00``."""
    crc = crc_hqx(body, 0xFFFF)
    return b"\x00" + cobs_encode(bytes(body) + crc.to_bytes(2, "little")) + b"\x00"


def encode_frame(seq: int, time_us: int, ids: Sequence[int], quats_xyzw: np.ndarray,
                 status: Sequence[int] | int | None = None) -> bytes:
    """One orientation frame (type 1), ready for the wire, delimiters included.

    ``seq`` is taken modulo 2**16 and ``time_us`` (device microseconds) modulo 2**32, so
    callers may pass ever-growing counters.  ``quats_xyzw``: (n, 4) scalar-last unit
    quaternions, written as w, x, y, z in Q14.  ``status``: per-sensor status bits (or one
    value for all); default :data:`STATUS_DEFAULT` (valid, calibration 3).
    """
    return pack_message(frame_body(seq, time_us, ids, quats_xyzw, status))


def encode_status(seq: int, time_us: int, ids: Sequence[int], status: Sequence[int]) -> bytes:
    """A sensor-status message (type 2), delimiters included."""
    ids = list(ids)
    status = list(status)
    if len(ids) != len(status):
        raise ValueError("ids and status differ in length")
    payload = bytes([len(ids)]) + b"".join(bytes([i & 0xFF, s & 0xFF]) for i, s in zip(ids, status))
    return pack_message(COMMON.pack(VERSION, MSG_STATUS, seq & 0xFFFF, int(time_us) & 0xFFFFFFFF) + payload)


def encode_info(seq: int, time_us: int, info: dict[str, str] | str) -> bytes:
    """A device-info message (type 3): ``key=value;...`` UTF-8 text, delimiters included."""
    text = info if isinstance(info, str) else ";".join(f"{k}={v}" for k, v in info.items())
    return pack_message(COMMON.pack(VERSION, MSG_INFO, seq & 0xFFFF, int(time_us) & 0xFFFFFFFF)
                        + text.encode("utf-8"))


def encode_text_frame(ids: Sequence[int], quats_xyzw: np.ndarray,
                      status: Sequence[int] | int | None = None, end_blank: bool = False,
                      decimals: int = 6) -> bytes:
    """Text lines ``id,w,x,y,z,status`` for one frame (scalar-last input, w first on the
    wire); ``end_blank`` appends the optional blank line that closes the frame at once."""
    q = np.asarray(quats_xyzw, dtype=np.float64)
    n = len(ids)
    st = [STATUS_DEFAULT] * n if status is None else list(np.broadcast_to(np.asarray(status), (n,)))
    lines = [f"{int(i)},{w:.{decimals}f},{x:.{decimals}f},{y:.{decimals}f},{z:.{decimals}f},{int(s)}\n"
             for i, (x, y, z, w), s in zip(ids, q, st)]
    if end_blank:
        lines.append("\n")
    return "".join(lines).encode("ascii")


# --------------------------------------------------------------------------- decoded data


@dataclass(slots=True)
class DecodedFrame:
    """One decoded message.

    ``msg_type``: 1 orientation frame, 2 sensor status, 3 device info.
    ``seq``: u16 sequence number, ``time_us``: u32 device microseconds (None for text).
    ``ids`` (n,) uint8, ``status`` (n,) uint8 status bits.
    ``quats`` (n, 4) float64 **scalar-last (x, y, z, w)**, scaled to unit length wherever
    the decoded norm is finite and non-zero (all-zero rows stay zero); only rows with
    ``valid`` set are usable orientations.  All zero for type 2, empty for type 3.
    ``valid`` (n,) bool: status bit 0 set, error bit 3 clear, quaternion finite and within
    :data:`NORM_TOLERANCE` of unit norm.
    ``info``: the ``key=value`` pairs of a type-3 message, else None.
    Arrays may be views into a buffer shared by the frames of one ``feed`` call: copy
    before modifying.
    """
    msg_type: int
    seq: int | None
    time_us: int | None
    ids: np.ndarray
    status: np.ndarray
    quats: np.ndarray
    valid: np.ndarray
    info: dict[str, str] | None = None


@dataclass
class DecoderStats:
    """Counters of a decoder since it was created (``reset`` keeps them).

    frames: orientation frames decoded; messages: messages of any type decoded;
    corrupt: messages dropped for damage (= bad_cobs + bad_crc + bad_length + bad_version
    + discarded overlong runs); bad_values: sensors refused for NaN/inf or non-unit
    quaternions; unknown_ids: sensor records with an id outside ``known_ids``;
    bad_messages: unknown message types, malformed text lines; garbage_lines: text lines
    that are not records at all (boot logs); skipped_bytes: bytes dropped while
    synchronising.
    """
    frames: int = 0
    messages: int = 0
    corrupt: int = 0
    bad_cobs: int = 0
    bad_crc: int = 0
    bad_length: int = 0
    bad_version: int = 0
    bad_values: int = 0
    unknown_ids: int = 0
    bad_messages: int = 0
    garbage_lines: int = 0
    skipped_bytes: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


def _known_lut(known_ids: Iterable[int] | None) -> np.ndarray | None:
    if known_ids is None:
        return None
    lut = np.zeros(256, dtype=bool)
    for i in known_ids:
        if not 0 <= int(i) <= 255:
            raise ValueError(f"sensor id {i} outside 0..255")
        lut[int(i)] = True
    return lut


def _check_quats(q_xyzw: np.ndarray, claims_valid: np.ndarray, tol: float,
                 scale: float = 1.0, integers: bool = False) -> tuple[np.ndarray, np.ndarray, int]:
    """Validate and normalise (n, 4) quaternions in place.

    ``scale`` multiplies the raw values first (1/16384 for Q14 integers); ``integers``
    says the values are small integers (no NaN/inf/overflow possible).  Non-finite rows
    become zero and not valid.  Returns
    (quats, valid, n_bad): every row with a finite non-zero norm is scaled to unit length;
    ``valid`` = claims_valid and | ||q|| - 1 | <= tol (False for NaN/inf); ``n_bad`` counts
    rows that claimed to be valid but failed the norm test.
    """
    if not integers:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            finite = np.isfinite(q_xyzw).all(axis=1)
            q, valid, _ = _check_quats(np.nan_to_num(q_xyzw, nan=0.0, posinf=0.0, neginf=0.0),
                                       claims_valid & finite, tol, scale, True)
            return q, valid, int(np.count_nonzero(claims_valid)) - int(np.count_nonzero(valid))
    # From here on all values are finite and not huge: no floating-point warnings possible.
    sq = np.einsum("ij,ij->i", q_xyzw, q_xyzw)
    if scale != 1.0:
        sq *= scale * scale
    norm_ok = (sq >= (1.0 - tol) ** 2) & (sq <= (1.0 + tol) ** 2)
    valid = claims_valid & norm_ok
    n_bad = int(np.count_nonzero(claims_valid)) - int(np.count_nonzero(valid))
    factor = scale / np.sqrt(np.maximum(sq, 1e-300))
    q_xyzw *= factor[:, None]
    return q_xyzw, valid, n_bad


def _empty_frame(msg_type: int, seq: int | None, time_us: int | None,
                 info: dict[str, str] | None = None) -> DecodedFrame:
    return DecodedFrame(msg_type, seq, time_us, np.zeros(0, np.uint8), np.zeros(0, np.uint8),
                        np.zeros((0, 4)), np.zeros(0, bool), info)


def parse_info(text: str) -> dict[str, str]:
    """``key=value;key=value`` -> dict (items without '=' get the value "")."""
    out: dict[str, str] = {}
    for item in text.split(";"):
        item = item.strip()
        if item:
            k, _, v = item.partition("=")
            out[k.strip()] = v.strip()
    return out


# --------------------------------------------------------------------------- binary decoder


class SerialFrameDecoder:
    """Streaming decoder of the binary format.  Feed it bytes as they arrive, in chunks of
    any size; it returns the complete, intact messages and never raises on bad input.

    ``known_ids``: sensor ids of the suit; others are counted in ``stats.unknown_ids``.
    ``norm_tolerance``: see :data:`NORM_TOLERANCE`.
    ``messages``: which message types to return (default all; the serial source wants
    all three).

    Speed: messages are split on 0x00 with ``bytes.split``, COBS-decoded by visiting only
    code bytes, checked with the C ``crc_hqx``, and the sensor records of all frames of one
    ``feed`` call are converted together with one ``np.frombuffer``.  Measured for a
    17-sensor suit on the shared 2-core build machine (``benchmarks/decode.py``): about
    180 000 frames/s fed 4 KB at a time and 28 000 frames/s fed one frame per call when the
    machine was quiet; 70 000 and 12 000 frames/s under a load average of 9.
    """

    def __init__(self, known_ids: Iterable[int] | None = None,
                 norm_tolerance: float = NORM_TOLERANCE) -> None:
        self.stats = DecoderStats()
        self.norm_tolerance = float(norm_tolerance)
        self._known = _known_lut(known_ids)
        self._buf = b""
        self._synced = False

    def reset(self) -> None:
        """Forget any partial message and wait for the next delimiter (after a reconnect)."""
        self._buf = b""
        self._synced = False

    @property
    def pending_bytes(self) -> int:
        """Bytes held waiting for a delimiter."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[DecodedFrame]:
        """Decode everything completed by ``data``; keep the unfinished tail."""
        if not data:
            return []
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        parts = buf.split(b"\x00")
        tail = parts.pop()
        stats = self.stats
        if not self._synced:
            if not parts:  # still no delimiter seen
                if len(tail) > MAX_WIRE_BYTES:
                    stats.skipped_bytes += len(tail)
                    tail = b""
                self._buf = tail
                return []
            stats.skipped_bytes += len(parts[0])
            parts[0] = b""
            self._synced = True
        if len(tail) > MAX_WIRE_BYTES:  # no delimiter for too long: noise, resynchronise
            stats.corrupt += 1
            stats.skipped_bytes += len(tail)
            tail = b""
            self._synced = False
        self._buf = tail
        return self._decode_parts(parts)

    def _decode_parts(self, parts: list[bytes]) -> list[DecodedFrame]:
        stats = self.stats
        crc = crc_hqx
        unpack_common = COMMON.unpack_from
        heads: list[tuple[int, int, int]] = []  # (seq, time_us, n) of type-1 frames
        blocks: list[bytes] = []
        others: list[DecodedFrame] = []  # messages of types 2/3
        order: list[int] = []  # message kinds in arrival order: -1 frame, else index in others
        for part in parts:
            if not part:
                continue
            dec = cobs_decode(part)
            if dec is None:
                stats.bad_cobs += 1
                stats.corrupt += 1
                continue
            blen = len(dec) - 2
            if blen < 8:
                stats.bad_length += 1
                stats.corrupt += 1
                continue
            if crc(memoryview(dec)[:blen], 0xFFFF) != (dec[blen] | (dec[blen + 1] << 8)):
                stats.bad_crc += 1
                stats.corrupt += 1
                continue
            version, mtype, seq, time_us = unpack_common(dec)
            if version != VERSION:
                stats.bad_version += 1
                stats.corrupt += 1
                continue
            if mtype == MSG_FRAME:
                if blen < 9 or blen != 9 + RECORD_SIZE * dec[8]:
                    stats.bad_length += 1
                    stats.corrupt += 1
                    continue
                heads.append((seq, time_us, dec[8]))
                blocks.append(dec[9:blen])
                order.append(-1)
            elif mtype == MSG_STATUS:
                if blen < 9 or blen != 9 + 2 * dec[8]:
                    stats.bad_length += 1
                    stats.corrupt += 1
                    continue
                raw = np.frombuffer(bytes(dec[9:blen]), dtype=np.uint8).reshape(-1, 2)
                ids = raw[:, 0].copy()
                self._count_unknown(ids)
                st = raw[:, 1].copy()
                msg = DecodedFrame(MSG_STATUS, seq, time_us, ids, st, np.zeros((len(ids), 4)),
                                   np.zeros(len(ids), bool), None)
                order.append(len(others))
                others.append(msg)
            elif mtype == MSG_INFO:
                text = bytes(dec[8:blen]).decode("utf-8", errors="replace")
                order.append(len(others))
                others.append(_empty_frame(MSG_INFO, seq, time_us, parse_info(text)))
            else:
                stats.bad_messages += 1
                continue
        if not order:
            return []
        frames = self._convert(heads, blocks) if heads else []
        stats.messages += len(order)
        stats.frames += len(frames)
        if not others:
            return frames
        out: list[DecodedFrame] = []
        fi = iter(frames)
        for kind in order:
            out.append(next(fi) if kind < 0 else others[kind])
        return out

    def _count_unknown(self, ids: np.ndarray) -> None:
        if self._known is not None and len(ids):
            self.stats.unknown_ids += int(np.count_nonzero(~self._known[ids]))

    def _convert(self, heads: list[tuple[int, int, int]], blocks: list[bytes]) -> list[DecodedFrame]:
        """Convert the sensor records of all frames of one feed at once."""
        rec = np.frombuffer(b"".join(blocks), dtype=SENSOR_DTYPE)
        ids = rec["id"]
        status = rec["status"]
        raw = rec["q"]  # (N, 4) int16, w x y z
        q = np.empty(raw.shape)  # float64, scalar-last
        q[:, :3] = raw[:, 1:]
        q[:, 3] = raw[:, 0]
        claims = (status & (STATUS_VALID | STATUS_ERROR)) == STATUS_VALID
        q, valid, n_bad = _check_quats(q, claims, self.norm_tolerance, Q14_RESOLUTION, True)
        self.stats.bad_values += n_bad
        self._count_unknown(ids)
        out = []
        a = 0
        for seq, time_us, n in heads:
            b = a + n
            out.append(DecodedFrame(MSG_FRAME, seq, time_us, ids[a:b], status[a:b], q[a:b],
                                    valid[a:b], None))
            a = b
        return out


# --------------------------------------------------------------------------- text decoder


class TextLineDecoder:
    """Streaming decoder of ``id,w,x,y,z[,status]`` lines (see the module docstring for
    how lines group into frames).  Never raises on bad input."""

    MAX_LINE = 256
    """Longer runs without a newline are discarded as garbage."""

    def __init__(self, known_ids: Iterable[int] | None = None,
                 norm_tolerance: float = NORM_TOLERANCE) -> None:
        self.stats = DecoderStats()
        self.norm_tolerance = float(norm_tolerance)
        self._known = _known_lut(known_ids)
        self._n_known = 0 if self._known is None else int(self._known.sum())
        self._buf = b""
        self._ids: list[int] = []
        self._seen: set[int] = set()
        self._rows: list[tuple[float, float, float, float]] = []
        self._status: list[int] = []
        self._known_seen = 0

    def reset(self) -> None:
        """Drop the partial line and the partial frame (after a reconnect)."""
        self._buf = b""
        self._clear()

    def _clear(self) -> None:
        self._ids, self._seen, self._rows, self._status = [], set(), [], []
        self._known_seen = 0

    @property
    def has_partial(self) -> bool:
        """True while a frame has records but has not been closed."""
        return bool(self._ids)

    def flush(self) -> list[DecodedFrame]:
        """Close the current partial frame (if any) and return it."""
        if not self._ids:
            return []
        wxyz = np.array(self._rows, dtype=np.float64).reshape(-1, 4)
        q = wxyz[:, _WXYZ_TO_XYZW]
        ids = np.array(self._ids, dtype=np.uint8)
        status = np.array(self._status, dtype=np.uint8)
        claims = (status & (STATUS_VALID | STATUS_ERROR)) == STATUS_VALID
        q, valid, n_bad = _check_quats(q, claims, self.norm_tolerance)
        self.stats.bad_values += n_bad
        if self._known is not None:
            self.stats.unknown_ids += int(np.count_nonzero(~self._known[ids]))
        self._clear()
        self.stats.frames += 1
        self.stats.messages += 1
        return [DecodedFrame(MSG_FRAME, None, None, ids, status, q, valid, None)]

    def feed(self, data: bytes | bytearray | memoryview) -> list[DecodedFrame]:
        """Decode the complete lines in ``data``; keep the unfinished tail."""
        if not data:
            return []
        buf = self._buf + bytes(data) if self._buf else bytes(data)
        lines = buf.split(b"\n")
        tail = lines.pop()
        if len(tail) > self.MAX_LINE:
            self.stats.garbage_lines += 1
            self.stats.skipped_bytes += len(tail)
            tail = b""
        self._buf = tail
        out: list[DecodedFrame] = []
        for line in lines:
            self._line(line, out)
        return out

    def _line(self, raw: bytes, out: list[DecodedFrame]) -> None:
        line = raw.strip()
        if not line or line.startswith(b"#"):
            out.extend(self.flush())
            return
        if len(line) > self.MAX_LINE:
            self.stats.garbage_lines += 1
            return
        fields = line.split(b",")
        try:
            sid = int(fields[0])
        except ValueError:
            self.stats.garbage_lines += 1
            return
        if not 0 <= sid <= 255 or len(fields) not in (5, 6):
            self.stats.bad_messages += 1
            return
        try:
            w, x, y, z = (float(f) for f in fields[1:5])
            st = int(fields[5]) if len(fields) == 6 else STATUS_VALID
        except ValueError:
            self.stats.bad_messages += 1
            return
        if not 0 <= st <= 255:
            self.stats.bad_messages += 1
            return
        if sid in self._seen:
            out.extend(self.flush())
        self._ids.append(sid)
        self._seen.add(sid)
        self._rows.append((w, x, y, z))
        self._status.append(st)
        if self._known is not None and self._known[sid]:
            self._known_seen += 1
            if self._known_seen == self._n_known:
                out.extend(self.flush())


def decoder_for(fmt: str, known_ids: Iterable[int] | None = None,
                norm_tolerance: float = NORM_TOLERANCE) -> SerialFrameDecoder | TextLineDecoder:
    """``"rtseg"`` -> :class:`SerialFrameDecoder`, ``"text"`` -> :class:`TextLineDecoder`."""
    if fmt == "rtseg":
        return SerialFrameDecoder(known_ids, norm_tolerance)
    if fmt == "text":
        return TextLineDecoder(known_ids, norm_tolerance)
    raise ValueError(f"unknown serial format {fmt!r}; known: rtseg, text")


__all__ = [
    "VERSION", "MSG_FRAME", "MSG_STATUS", "MSG_INFO", "Q14_SCALE", "Q14_RESOLUTION",
    "NORM_TOLERANCE", "STATUS_VALID", "STATUS_ERROR", "STATUS_DEFAULT", "status_bits",
    "calibration_level", "crc16", "cobs_encode", "cobs_decode", "frame_body", "pack_message",
    "encode_frame", "encode_status", "encode_info", "encode_text_frame", "DecodedFrame",
    "DecoderStats", "SerialFrameDecoder", "TextLineDecoder", "decoder_for", "parse_info",
]
