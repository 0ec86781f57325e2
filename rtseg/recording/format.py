"""The recorded-session folder format (version 1): file names, the ``frames.bin`` record
layout and its flag bits.  The layout is described in :mod:`rtseg.recording` and
docs/formats.md; times are seconds, positions metres, quaternions scalar-last.
"""

from __future__ import annotations

import math
import struct

import numpy as np

FORMAT_NAME = "rtseg-session"
FORMAT_VERSION = 1
HEADER_FILE = "session.json"
FRAMES_FILE = "frames.bin"
CUTS_FILE = "cuts.jsonl"
EVENTS_FILE = "events.jsonl"
MAGIC = b"RTSF"
_MAGIC_U32 = struct.unpack("<I", MAGIC)[0]

FLAG_SEQ = 1
FLAG_SOURCE_TIME = 2
FLAG_ROOT = 4

_HEAD = struct.Struct("<4sddqB")      # magic, recv_time, source_time, seq, flags
_ROOT = struct.Struct("<3d")
_CRC = struct.Struct("<I")
_NO_ROOT = _ROOT.pack(math.nan, math.nan, math.nan)


def record_dtype(n_joints: int, quat_dtype: str = "<f8") -> np.dtype:
    """numpy dtype of one ``frames.bin`` record (packed, little-endian)."""
    nv = (n_joints + 7) // 8
    return np.dtype([
        ("magic", "<u4"), ("recv_time", "<f8"), ("source_time", "<f8"), ("seq", "<i8"),
        ("flags", "u1"), ("valid", "u1", (nv,)), ("root", "<f8", (3,)),
        ("quats", quat_dtype, (n_joints, 4)), ("crc", "<u4")])



__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "HEADER_FILE", "FRAMES_FILE", "CUTS_FILE",
           "EVENTS_FILE", "MAGIC", "FLAG_SEQ", "FLAG_SOURCE_TIME", "FLAG_ROOT", "record_dtype"]
