"""The rtseg serial wire format: constants, status bits, COBS/CRC framing and the encoder.

The format itself (message types, header, Q14 records, COBS and CRC-16 framing, the text
line form) is specified in :mod:`rtseg.drivers.serial.codec`'s docstring.  Encoders take
**scalar-last (x, y, z, w)** quaternions and write **w, x, y, z** on the wire.
"""

from __future__ import annotations

import struct
from binascii import crc_hqx
from typing import Sequence

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


__all__ = [
    "VERSION", "MSG_FRAME", "MSG_STATUS", "MSG_INFO", "Q14_SCALE", "Q14_RESOLUTION",
    "NORM_TOLERANCE", "STATUS_VALID", "STATUS_ERROR", "STATUS_DEFAULT", "status_bits",
    "calibration_level", "crc16", "cobs_encode", "cobs_decode", "frame_body", "pack_message",
    "encode_frame", "encode_status", "encode_info", "encode_text_frame",
]
