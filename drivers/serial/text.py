"""Streaming decoder of the serial text form: ``id,w,x,y,z[,status]`` lines.

How lines group into frames is specified in :mod:`rtseg.drivers.serial.codec`'s docstring.
The wire carries w first; frames come out **scalar-last (x, y, z, w)** float64.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from rtseg.drivers.serial.decoded import (DecodedFrame, DecoderStats, _check_quats,
                                                _known_lut)
from rtseg.drivers.serial.wire import (_WXYZ_TO_XYZW, MSG_FRAME, NORM_TOLERANCE,
                                             STATUS_ERROR, STATUS_VALID)



#: what :func:`parse_record` says of a line that is no record: not one at all (no id) ...
GARBAGE = "garbage"
#: ... or one whose fields are wrong (id out of range, field count, values, status)
BAD = "bad"


def parse_record(line: bytes, max_line: int = 256) -> tuple | str:
    """One stripped, non-blank line ``id,w,x,y,z[,status]``: ``(id, w, x, y, z, status)``
    (status :data:`STATUS_VALID` when absent), else :data:`GARBAGE` (too long, or no integer
    id) or :data:`BAD` (the id out of 0..255, another field count, a value or status that is
    no number, a status out of 0..255)."""
    if len(line) > max_line:
        return GARBAGE
    fields = line.split(b",")
    try:
        sid = int(fields[0])
    except ValueError:
        return GARBAGE
    if not 0 <= sid <= 255 or len(fields) not in (5, 6):
        return BAD
    try:
        w, x, y, z = (float(f) for f in fields[1:5])
        st = int(fields[5]) if len(fields) == 6 else STATUS_VALID
    except ValueError:
        return BAD
    if not 0 <= st <= 255:
        return BAD
    return sid, w, x, y, z, st


class TextLineDecoder:
    """Streaming decoder of ``id,w,x,y,z[,status]`` lines (see ``rtseg.drivers.serial.codec``'s docstring for
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
        rec = parse_record(line, self.MAX_LINE)
        if rec is GARBAGE:
            self.stats.garbage_lines += 1
            return
        if rec is BAD:
            self.stats.bad_messages += 1
            return
        sid, w, x, y, z, st = rec
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


#: fewest record lines that make bytes look like the text format
MIN_TEXT_RECORDS = 8


def count_records(data: bytes | bytearray) -> tuple[int, int]:
    """(record lines ``id,w,x,y,z[,status]``, other lines) among the complete lines of
    ``data``: the first line (it may be the end of one cut short) and the unterminated
    tail are left out, so are blank lines and ``#`` comments."""
    lines = bytes(data).split(b"\n")[1:-1]
    records = other = 0
    for raw in lines:
        line = raw.strip()
        if not line or line.startswith(b"#"):
            continue
        if isinstance(parse_record(line), tuple):     # what the decoder reads as a record
            records += 1
        else:
            other += 1
    return records, other


def looks_like_text(data: bytes | bytearray) -> bool:
    """Whether ``data`` reads as the text format: no zero byte (the binary format's
    delimiter; text never has one), at least :data:`MIN_TEXT_RECORDS` record lines and at
    least three record lines for every other line (a boot log or a banner before them)."""
    if b"\x00" in data:
        return False
    records, other = count_records(data)
    return records >= MIN_TEXT_RECORDS and records >= 3 * other


__all__ = ["BAD", "GARBAGE", "MIN_TEXT_RECORDS", "TextLineDecoder", "count_records",
           "looks_like_text", "parse_record"]
