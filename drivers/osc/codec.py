"""OSC 1.0 on the wire: a lean parser and a reference encoder (used by the VMC and VRChat
codecs).

:func:`parse_packet` / :func:`parse_message` turn datagram bytes into :class:`OscMessage`
objects and raise :class:`OscParseError` (a ``ValueError``) on malformed bytes;
:func:`encode_message`, :func:`encode_bundle` and :func:`pack_bundles` build datagrams
(big-endian, 4-byte aligned, as OSC 1.0 specifies).  Numbers are passed through unchanged:
no unit or frame conversion happens here.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

#: Default UDP payload limit of the encoder: 1500-byte Ethernet MTU minus IPv4 (20) and
#: UDP (8) headers, so no datagram is IP-fragmented.
DEFAULT_MAX_DATAGRAM = 1472


class OscParseError(ValueError):
    """Malformed OSC bytes (bad padding, sizes, type tags, truncated arguments)."""


# --------------------------------------------------------------------------- OSC parsing

@dataclass(slots=True)
class OscMessage:
    """One parsed OSC message.  ``timetag`` is the enclosing bundle's raw NTP time tag
    (64-bit int, 1 = immediately) or None for a bare message."""
    address: str
    tags: str
    args: tuple[Any, ...]
    timetag: int | None = None


_BUNDLE = b"#bundle\x00"
_I32 = struct.Struct(">i")
_U64 = struct.Struct(">Q")
_F32 = struct.Struct(">f")
_F64 = struct.Struct(">d")
_I64 = struct.Struct(">q")
#: Fixed-size numeric type tags: tag -> (struct, what the error message calls it).
_NUMERIC = {"f": (_F32, "float"), "i": (_I32, "int"), "d": (_F64, "double"),
            "h": (_I64, "int64"), "t": (_U64, "time tag")}
_MAX_DEPTH = 8


def _read_string(data: bytes, pos: int, end: int) -> tuple[bytes, int]:
    """OSC-string at ``pos``: bytes up to the NUL, and the 4-aligned position after it."""
    nul = data.find(b"\x00", pos, end)
    if nul < 0:
        raise OscParseError(f"unterminated OSC string at byte {pos}")
    nxt = pos + ((nul - pos) & ~3) + 4
    if nxt > end:
        raise OscParseError(f"OSC string at byte {pos} overruns its padding")
    return data[pos:nul], nxt


def _decode(raw: bytes) -> str:
    return raw.decode("utf-8", errors="replace")


def parse_message(data: bytes, start: int = 0, end: int | None = None,
                  timetag: int | None = None, max_args: int | None = None) -> OscMessage:
    """Parse the OSC message in ``data[start:end]``.

    Type tags understood: i f d h s S b t c r m T F N I and arrays ``[ ]``.  A message with
    no type-tag string (OSC 1.0 allows it) has no arguments.  ``max_args`` stops after that
    many top-level arguments (the rest are surplus and left unparsed).
    Raises :class:`OscParseError`.
    """
    end = len(data) if end is None else end
    if start < 0 or end > len(data) or (end - start) < 4 or (end - start) & 3:
        raise OscParseError(f"OSC message length {end - start} is not a positive multiple of 4")
    if data[start:start + 1] != b"/":
        raise OscParseError("OSC address does not start with '/'")
    raw_addr, pos = _read_string(data, start, end)
    address = _decode(raw_addr)
    if pos == end:
        return OscMessage(address, "", (), timetag)
    raw_tags, pos = _read_string(data, pos, end)
    if raw_tags[:1] != b",":
        raise OscParseError(f"{address}: type tag string does not start with ','")
    tags = _decode(raw_tags[1:])
    top: list[Any] = []
    stack: list[list[Any]] = [top]
    for tag in tags:
        if max_args is not None and len(stack) == 1 and len(top) >= max_args:
            break
        numeric = _NUMERIC.get(tag)
        if numeric is not None:
            st, what = numeric
            if pos + st.size > end:
                raise OscParseError(f"{address}: truncated {what} argument")
            val = st.unpack_from(data, pos)[0]
            pos += st.size
        elif tag in "sS":
            raw, pos = _read_string(data, pos, end)
            val = _decode(raw)
        elif tag == "b":
            if pos + 4 > end:
                raise OscParseError(f"{address}: truncated blob size")
            size = _I32.unpack_from(data, pos)[0]
            pos += 4
            if size < 0 or pos + size > end:
                raise OscParseError(f"{address}: blob of {size} bytes overruns the message")
            val = data[pos:pos + size]
            pos += (size + 3) & ~3
            if pos > end:
                raise OscParseError(f"{address}: blob padding overruns the message")
        elif tag in "crm":
            if pos + 4 > end:
                raise OscParseError(f"{address}: truncated {tag!r} argument")
            val = data[pos:pos + 4] if tag != "c" else chr(_I32.unpack_from(data, pos)[0] & 0x10FFFF)
            pos += 4
        elif tag == "T":
            val = True
        elif tag == "F":
            val = False
        elif tag == "N":
            val = None
        elif tag == "I":
            val = math.inf
        elif tag == "[":
            arr: list[Any] = []
            stack[-1].append(arr)
            stack.append(arr)
            continue
        elif tag == "]":
            if len(stack) < 2:
                raise OscParseError(f"{address}: unbalanced ']' in type tags")
            stack.pop()
            continue
        else:
            raise OscParseError(f"{address}: unknown type tag {tag!r}")
        stack[-1].append(val)
    else:
        if len(stack) != 1:
            raise OscParseError(f"{address}: unbalanced '[' in type tags")
    return OscMessage(address, tags, tuple(top), timetag)


def parse_packet(data: bytes) -> list[OscMessage]:
    """All messages of an OSC packet (bare message or bundle, nested bundles flattened in
    order).  Raises :class:`OscParseError` on malformed bytes."""
    out: list[OscMessage] = []
    _parse_into(bytes(data), 0, len(data), None, out, 0)
    return out


def _parse_into(data: bytes, start: int, end: int, timetag: int | None,
                out: list[OscMessage], depth: int) -> None:
    if data.startswith(_BUNDLE, start):
        if depth >= _MAX_DEPTH:
            raise OscParseError(f"bundles nested deeper than {_MAX_DEPTH}")
        if end - start < 16:
            raise OscParseError("truncated bundle header")
        tt = _U64.unpack_from(data, start + 8)[0]
        pos = start + 16
        while pos < end:
            if pos + 4 > end:
                raise OscParseError(f"truncated bundle element size at byte {pos}")
            size = _I32.unpack_from(data, pos)[0]
            pos += 4
            if size <= 0 or size & 3 or pos + size > end:
                raise OscParseError(f"bad bundle element size {size} at byte {pos - 4}")
            _parse_into(data, pos, pos + size, tt, out, depth + 1)
            pos += size
    else:
        out.append(parse_message(data, start, end, timetag))


# --------------------------------------------------------------------------- encoding

def _pad_string(s: str | bytes) -> bytes:
    raw = s.encode("utf-8") if isinstance(s, str) else bytes(s)
    if b"\x00" in raw:
        raise ValueError(f"OSC string must not contain NUL: {raw!r}")
    return raw + b"\x00" * (4 - (len(raw) & 3))


def encode_message(address: str, tags: str, args: Sequence[Any]) -> bytes:
    """One OSC message.  ``tags`` without the leading comma, one of i f d h s b T F N per
    argument.  numpy scalars are accepted (converted with ``float()``/``int()``)."""
    if len(tags) != len(args):
        raise ValueError(f"{address}: {len(tags)} type tags for {len(args)} arguments")
    parts = [_pad_string(address), _pad_string("," + tags)]
    for tag, arg in zip(tags, args):
        if tag == "f":
            parts.append(_F32.pack(float(arg)))
        elif tag == "i":
            parts.append(_I32.pack(int(arg)))
        elif tag == "d":
            parts.append(_F64.pack(float(arg)))
        elif tag == "h":
            parts.append(_I64.pack(int(arg)))
        elif tag == "s":
            parts.append(_pad_string(str(arg)))
        elif tag == "b":
            blob = bytes(arg)
            parts.append(_I32.pack(len(blob)) + blob + b"\x00" * (-len(blob) & 3))
        elif tag in "TFN":
            pass
        else:
            raise ValueError(f"{address}: cannot encode type tag {tag!r}")
    return b"".join(parts)


def encode_bundle(elements: Iterable[bytes], timetag: int = 1) -> bytes:
    """An OSC bundle of already encoded messages/bundles (time tag 1 = immediately)."""
    parts = [_BUNDLE, _U64.pack(timetag)]
    for el in elements:
        parts.append(_I32.pack(len(el)))
        parts.append(el)
    return b"".join(parts)


def pack_bundles(elements: Sequence[bytes], max_datagram: int = DEFAULT_MAX_DATAGRAM,
                 timetag: int = 1) -> list[bytes]:
    """Split messages, in order, over as few bundles of at most ``max_datagram`` bytes as
    possible.  ValueError if one message cannot fit."""
    out: list[bytes] = []
    cur: list[bytes] = []
    size = 16
    for el in elements:
        need = 4 + len(el)
        if 16 + need > max_datagram:
            raise ValueError(f"OSC message of {len(el)} bytes does not fit in {max_datagram}")
        if size + need > max_datagram and cur:
            out.append(encode_bundle(cur, timetag))
            cur, size = [], 16
        cur.append(el)
        size += need
    if cur:
        out.append(encode_bundle(cur, timetag))
    return out


__all__ = [
    "DEFAULT_MAX_DATAGRAM", "OscParseError", "OscMessage", "parse_message", "parse_packet",
    "encode_message", "encode_bundle", "pack_bundles",
]
