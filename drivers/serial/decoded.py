"""Decoded serial messages and the checks both serial decoders share.

:class:`DecodedFrame` (quaternions **scalar-last (x, y, z, w)** float64, unit length where
valid), :class:`DecoderStats` (drop counters), sensor-id lookup, quaternion validation and
``key=value`` info parsing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Iterable

import numpy as np


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
    ``complete``: True when the frame holds exactly the decoder's ``known_ids``, in that
    order, every one valid (the usual frame of a healthy suit: readers may then take
    ``quats`` as the suit's rows without a lookup).
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
    complete: bool = False


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


# whole-array reductions without the ndarray-method dispatch (one frame's arrays are small)
_min, _max = np.minimum.reduce, np.maximum.reduce


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
    lo, hi = (1.0 - tol) ** 2, (1.0 + tol) ** 2
    if len(sq) and _min(sq) >= lo and _max(sq) <= hi:
        # every norm within the tolerance (the usual frame): valid as claimed, none bad
        valid, n_bad = claims_valid, 0
    else:
        valid = claims_valid & (sq >= lo) & (sq <= hi)
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


__all__ = ["DecodedFrame", "DecoderStats", "parse_info"]
