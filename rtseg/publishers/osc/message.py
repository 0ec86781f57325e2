"""A tiny OSC 1.0 message encoder (types i, f, s only) and SLIP framing (OSC 1.1 over TCP).

Why our own: the publishers must control argument types exactly.  python-osc guesses the
type from the Python value, rejects ``numpy.float32`` and sends Python ints above 2**31 as
int64 ('h'), which many show-control receivers do not accept.  Here every argument is
coerced to the declared tag first:

- ``i``: int32, big-endian; numpy/Python ints, bools and floats (rounded) are accepted,
  values outside int32 are clamped; NaN becomes 0.
- ``f``: float32, big-endian; numpy scalars accepted; values beyond float32 range become
  +/-inf; NaN stays NaN.
- ``s``: UTF-8, NUL-terminated, padded to 4 bytes; NUL characters inside are removed.

Messages are plain messages, never bundles.
"""

from __future__ import annotations

import math
import struct
from typing import Any, Iterable

INT32_MIN = -(2 ** 31)
INT32_MAX = 2 ** 31 - 1

_pack_i = struct.Struct(">i").pack
_pack_f = struct.Struct(">f").pack

SLIP_END = 0xC0
SLIP_ESC = 0xDB
SLIP_ESC_END = 0xDC
SLIP_ESC_ESC = 0xDD


def osc_int(v: Any) -> int:
    """Coerce to a Python int in int32 range (clamped)."""
    if hasattr(v, "item"):
        v = v.item()
    if isinstance(v, float):
        if math.isnan(v):
            return 0
        if math.isinf(v):
            return INT32_MAX if v > 0 else INT32_MIN
        v = round(v)
    v = int(v)
    return INT32_MAX if v > INT32_MAX else INT32_MIN if v < INT32_MIN else v


def osc_float(v: Any) -> float:
    """Coerce to a Python float (NaN allowed)."""
    if hasattr(v, "item"):
        v = v.item()
    return float(v)


def osc_str(v: Any) -> str:
    """Coerce to str without NUL characters."""
    if hasattr(v, "item") and not isinstance(v, str):
        v = v.item()
    if isinstance(v, bytes):
        v = v.decode("utf-8", "replace")
    return str(v).replace("\0", "")


def _pad_str(s: str) -> bytes:
    b = s.encode("utf-8") + b"\0"
    return b + b"\0" * (-len(b) % 4)


def _f32(x: float) -> bytes:
    try:
        return _pack_f(x)
    except OverflowError:
        return _pack_f(math.inf if x > 0 else -math.inf)


def encode_message(address: str, typetags: str, args: Iterable[Any]) -> bytes:
    """Encode one OSC message.  ``typetags`` without the leading comma, e.g. ``"iifs"``.

    Raises ValueError for an address not starting with '/', a tag other than i/f/s, or a
    count of arguments that does not match the tags.
    """
    if not address.startswith("/"):
        raise ValueError(f"OSC address must start with '/': {address!r}")
    args = list(args)
    if len(args) != len(typetags):
        raise ValueError(f"{address}: {len(typetags)} type tags but {len(args)} arguments")
    out = [_pad_str(address), _pad_str("," + typetags)]
    for t, a in zip(typetags, args):
        if t == "i":
            out.append(_pack_i(osc_int(a)))
        elif t == "f":
            out.append(_f32(osc_float(a)))
        elif t == "s":
            out.append(_pad_str(osc_str(a)))
        else:
            raise ValueError(f"{address}: unsupported OSC type tag {t!r} (only i, f, s)")
    return b"".join(out)


def slip_encode(packet: bytes) -> bytes:
    """SLIP-frame one packet, END byte before and after (OSC 1.1 "double END")."""
    body = packet.replace(b"\xdb", b"\xdb\xdd").replace(b"\xc0", b"\xdb\xdc")
    return b"\xc0" + body + b"\xc0"


class SlipDecoder:
    """Incremental SLIP decoder: ``feed(bytes)`` returns the complete packets seen so far.

    Empty frames (consecutive END bytes) are skipped; an invalid escape is counted in
    ``errors`` and the byte kept as is.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._esc = False
        self.errors = 0

    def feed(self, data: bytes) -> list[bytes]:
        packets = []
        for b in data:
            if self._esc:
                self._esc = False
                if b == SLIP_ESC_END:
                    self._buf.append(SLIP_END)
                elif b == SLIP_ESC_ESC:
                    self._buf.append(SLIP_ESC)
                else:
                    self.errors += 1
                    self._buf.append(b)
            elif b == SLIP_END:
                if self._buf:
                    packets.append(bytes(self._buf))
                    self._buf.clear()
            elif b == SLIP_ESC:
                self._esc = True
            else:
                self._buf.append(b)
        return packets


def decode_message(packet: bytes) -> tuple[str, str, list[Any]]:
    """Decode a message of i/f/s arguments: (address, typetags without comma, args).

    For tests and diagnostics; raises ValueError on anything malformed.
    """
    def read_str(pos: int) -> tuple[str, int]:
        end = packet.index(b"\0", pos)
        s = packet[pos:end].decode("utf-8")
        return s, (end + 4) & ~3

    try:
        address, pos = read_str(0)
        tags, pos = read_str(pos)
        if not tags.startswith(","):
            raise ValueError("missing type tag string")
        args: list[Any] = []
        for t in tags[1:]:
            if t == "i":
                args.append(struct.unpack_from(">i", packet, pos)[0])
                pos += 4
            elif t == "f":
                args.append(struct.unpack_from(">f", packet, pos)[0])
                pos += 4
            elif t == "s":
                s, pos = read_str(pos)
                args.append(s)
            else:
                raise ValueError(f"unsupported type tag {t!r}")
    except (struct.error, UnicodeDecodeError) as exc:
        raise ValueError(f"malformed OSC message: {exc}") from None
    return address, tags[1:], args
