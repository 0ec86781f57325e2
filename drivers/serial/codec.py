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
- unknown message type -> ``bad_messages``, dropped; its sequence number is passed on
  (an empty message of that type), since the sender numbers every message, so it is no
  gap.
- a sensor whose status says valid but whose quaternion norm differs from 1 by more than
  :data:`NORM_TOLERANCE` (0.03; Q14 rounding moves the norm by < 1.5e-4) -> that sensor
  is marked not valid and counted in ``bad_values``; the rest of the frame is kept.
  Accepted quaternions are renormalised to unit length.
- a sensor id not in ``known_ids`` (when given) -> counted in ``unknown_ids``, kept in the
  decoded frame for the caller to ignore.
- bytes before the first delimiter after start/reset are skipped (``skipped_bytes``):
  the receiver cannot know where that message began.  A run of more than
  :data:`MAX_WIRE_BYTES` without a delimiter, before the first delimiter or after one, is
  discarded: 1 in ``corrupt`` per run, its bytes in ``skipped_bytes``.

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

from binascii import crc_hqx
from typing import Iterable

import numpy as np

from rtseg.drivers.serial.decoded import (DecodedFrame, DecoderStats, _check_quats,
                                                _empty_frame, _known_lut, parse_info)
from rtseg.drivers.serial.text import TextLineDecoder
from rtseg.drivers.serial.wire import (
    COMMON, MAX_WIRE_BYTES, MSG_FRAME, MSG_INFO, MSG_STATUS, NORM_TOLERANCE, Q14_RESOLUTION,
    Q14_SCALE, RECORD_SIZE, SENSOR_DTYPE, STATUS_DEFAULT, STATUS_ERROR, STATUS_VALID,
    VERSION, calibration_level, cobs_decode, cobs_encode, crc16, encode_frame, encode_info,
    encode_status, encode_text_frame, frame_body, pack_message, status_bits)
# the remaining wire constants, read by callers as rtseg.drivers.serial.codec.X (listed in __all__)
from rtseg.drivers.serial.wire import HEADER, HEADER_SIZE, MSG_TYPES

#: wire order w, x, y, z -> rtseg's scalar-last x, y, z, w
_WXYZ_TO_XYZW = np.array([1, 2, 3, 0])
_all = np.logical_and.reduce      # without the ndarray-method dispatch (small arrays)


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
    ``feed`` call are converted together with one ``np.frombuffer``, their norms checked
    with a few whole-array reductions when all are within the tolerance (the usual feed).
    Measured for a 17-sensor suit (``python3 benchmarks/decode.py --only serial
    --cpu-time``, 2026-12-05, shared 2-core machine): about 284 000 frames/s fed 4 KB at
    a time and 61 800 frames/s fed one frame per call.
    """

    def __init__(self, known_ids: Iterable[int] | None = None,
                 norm_tolerance: float = NORM_TOLERANCE) -> None:
        self.stats = DecoderStats()
        self.norm_tolerance = float(norm_tolerance)
        self._known = _known_lut(known_ids)
        # the suit's ids in order (bytes; None when they are not distinct): a frame of
        # exactly these is ``complete`` when every record is valid
        self._order = bytes(int(i) for i in known_ids) if known_ids is not None else None
        if self._order is not None and (not self._order or len(set(self._order)) != len(self._order)):
            self._order = None
        self._buf = b""
        self._synced = False
        self._corrupt_at_good = 0     # stats.corrupt when the last intact message was decoded

    @property
    def corrupt_since_good(self) -> int:
        """Damaged messages decoded after the last intact one (all of them before the
        first): frames destroyed that no sequence number has accounted for yet."""
        return self.stats.corrupt - self._corrupt_at_good

    def reset(self) -> None:
        """Forget any partial message and wait for the next delimiter (after a reconnect)."""
        self._buf = b""
        self._synced = False

    @property
    def pending_bytes(self) -> int:
        """Bytes held waiting for a delimiter."""
        return len(self._buf)

    def take_pending(self) -> bytes:
        """The bytes held waiting for a delimiter, forgotten here (for a caller that hands
        the stream to another decoder)."""
        buf, self._buf = self._buf, b""
        return buf

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
                if len(tail) > MAX_WIRE_BYTES:  # too long for a message: noise, discarded
                    stats.corrupt += 1
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
                self._corrupt_at_good = stats.corrupt
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
                self._corrupt_at_good = stats.corrupt
            elif mtype == MSG_INFO:
                text = bytes(dec[8:blen]).decode("utf-8", errors="replace")
                order.append(len(others))
                others.append(_empty_frame(MSG_INFO, seq, time_us, parse_info(text)))
                self._corrupt_at_good = stats.corrupt
            else:    # its number still counts: the sequence numbers every message
                stats.bad_messages += 1
                order.append(len(others))
                others.append(_empty_frame(mtype, seq, time_us))
                self._corrupt_at_good = stats.corrupt
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
        """Convert the sensor records of all frames of one feed at once.  A feed whose
        frames each hold the suit's ids in order, every record valid, gives ``complete``
        frames (and needs no unknown-id count)."""
        rec = np.frombuffer(blocks[0] if len(blocks) == 1 else b"".join(blocks),
                            dtype=SENSOR_DTYPE)
        ids = rec["id"]
        status = rec["status"]
        q = rec["q"].take(_WXYZ_TO_XYZW, axis=1).astype(np.float64)  # scalar-last
        claims = (status & (STATUS_VALID | STATUS_ERROR)) == STATUS_VALID
        q, valid, n_bad = _check_quats(q, claims, self.norm_tolerance, Q14_RESOLUTION, True)
        self.stats.bad_values += n_bad
        order = self._order
        in_order = (order is not None and all(n == len(order) for _, _, n in heads)
                    and ids.tobytes() == order * len(heads))
        if not in_order:
            self._count_unknown(ids)
        complete = in_order and bool(_all(valid))
        out = []
        a = 0
        for seq, time_us, n in heads:
            b = a + n
            out.append(DecodedFrame(MSG_FRAME, seq, time_us, ids[a:b], status[a:b], q[a:b],
                                    valid[a:b], None, complete))
            a = b
        return out




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
    "HEADER", "HEADER_SIZE", "MSG_TYPES", "SENSOR_DTYPE", "MAX_WIRE_BYTES",
]
