"""Axis BVH broadcast, **text** encoding: ``||``-separated frames <-> :class:`AxisFrame`.

Each frame is ``<avatar index> <avatar name> <value> <value> ...`` (white space between
fields) and ends at ``||`` (see :mod:`rtseg.drivers.axis.codec` for the layouts and
conventions; this module holds the text side: :func:`decode_text`, :func:`encode_text`,
:class:`TextSplitter` and the number parser :func:`parse_decimals`).

Speed: a frame carries 180-360 decimal numbers, and ``float()`` on each (or numpy's
string casts, or ``np.fromstring``, which cost the same) is most of a 50 us budget.
:func:`decode_texts` first checks a frame's values with one ``bytes.translate`` pass (only
``0-9 . - + e E`` and spaces, which become commas) and parses the frames of a read as
``[[...],[...]]`` with orjson in one call (:func:`_json_lists`, ~7 us for 354 numbers),
then packs each list into a float64 array with ``struct`` (:func:`_array`, ~2.5 us; numpy's
``fromiter`` on the list took ~5): JSON's number grammar is a subset of ``float()``'s and
orjson rounds correctly, so the values are ``float()``'s bit for bit (the integer token
``-0``, which orjson reads as 0, is refused).  What orjson refuses, frame by frame, takes
the previous exact paths: :func:`parse_decimals` reads a frame whose every token is
``[-]digits.digits`` as integers - the token with its point removed, converted by numpy's
integer parser (``np.fromstring``, ~10x cheaper than ``float``) - divided by 10^(digits
after the point), found from the point and space positions in one vectorised pass.  The integer M
(|M| < 2^53) and 10^d (d <= 22) are exact doubles, so that one IEEE division is the
correctly rounded value of the decimal: exactly what ``float()`` returns (Clinger's fast
path).  A frame with any other token (exponents, ``nan``, more digits, ``_``) is read
with ``float()`` token by token, so the values are always ``float()``'s.
"""

from __future__ import annotations

import struct

import numpy as np

from rtseg.drivers.axis.codec import JOINTS, AxisError, AxisFrame, layout, value_count

try:  # a core dependency; where it is missing the integer fast path below does the work
    from orjson import loads as _json_loads
except ImportError:  # pragma: no cover - exercised only where orjson is absent
    _json_loads = None

__all__ = ["decode_text", "decode_texts", "encode_text", "TextSplitter", "parse_decimals"]

#: 10^k, exact in float64 for k <= 22
_POW10 = 10.0 ** np.arange(23)
#: integers up to this magnitude convert to float64 exactly
_EXACT_INT = 1 << 53
#: the bytes of the fast form (anything else: float() token by token)
_FAST_CHARS = b"0123456789 .-"
#: the bytes a frame read as JSON numbers may hold (no brackets, quotes or literals)
_JSON_CHARS = b"0123456789 .-+eE"
#: ``body.translate(_TO_JSON, _NOT_JSON)``: spaces -> commas, and shorter than ``body``
#: exactly when ``body`` holds a byte outside :data:`_JSON_CHARS` (one pass for both)
_TO_JSON = bytes.maketrans(b" ", b",")
_NOT_JSON = bytes(sorted(set(range(256)) - set(_JSON_CHARS)))


def _slow(tokens: list[bytes]) -> np.ndarray:
    """``float()`` of each token; AxisError('corrupt') when one is not a number."""
    try:
        return np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        raise AxisError("corrupt", "a value of the text frame is not a number") from None


def _json_lists(rows: list[bytes]) -> list[list] | None:
    """The numbers of each row as Python numbers, parsed as JSON by orjson in one call for
    all of them, or None (orjson absent, or some token is not a JSON number - a double
    space, ``1.``, ``.5``, ``nan``, ``+1``, ``007``, ``1e999`` ... - or may be the integer
    ``-0``): then the caller reads them with :func:`_fast_values` / :func:`_slow`.

    The values are finite (orjson refuses ``1e999`` and has no NaN or Infinity literal).
    A row is a body translated by :data:`_TO_JSON` (its tokens separated by commas) that
    held only :data:`_JSON_CHARS`, so the text ``[[row0],[row1],...]`` (``[row0]`` for one
    row) can only parse to one list of numbers per row.  JSON's number grammar is a subset
    of ``float()``'s, and orjson rounds correctly (its values are ``float()``'s bit for bit,
    tests/test_axis.py), except that it reads the integer token ``-0`` as 0
    (``float('-0')`` is -0.0): rows with a token without a point are refused when the text
    holds ``-0,`` or ``-0]``."""
    if _json_loads is None:
        return None
    if len(rows) == 1:
        text = b"[" + rows[0] + b"]"
    else:
        text = b"[[" + b"],[".join(rows) + b"]]"
    try:
        parsed = _json_loads(text)
    except ValueError:                     # orjson.JSONDecodeError
        return None
    if len(rows) == 1:
        parsed = [parsed]
        tokens = len(parsed[0])
    else:
        tokens = sum(map(len, parsed))
    if text.count(b".") != tokens and (b"-0," in text or b"-0]" in text):
        return None                        # (a token with two points is not JSON)
    return parsed


#: struct.Struct of n native doubles, for the counts of the Axis layouts (others are made
#: when met, not kept: a fuzzed stream must not grow this)
_DOUBLES: dict[int, struct.Struct] = {}
for _n in {value_count(d, r) for d in (True, False) for r in (True, False)}:
    _DOUBLES[_n] = struct.Struct(f"{_n}d")


def _array(numbers: list) -> np.ndarray:
    """orjson's numbers (floats and ints) -> float64 array, each exactly ``float(x)``
    (``struct``'s ``d`` format takes them through ``PyFloat_AsDouble``, as ``float()``
    does; ~2.5x cheaper than ``np.fromiter`` on a list); OverflowError or struct.error for
    anything else."""
    n = len(numbers)
    packer = _DOUBLES.get(n) or struct.Struct(f"{n}d")
    out = np.empty(n)
    packer.pack_into(out, 0, *numbers)
    return out


def _json_rows(rows: list[bytes]) -> list[np.ndarray] | None:
    """:func:`_json_lists` as float64 arrays (one per row), or None where it refuses."""
    parsed = _json_lists(rows)
    if parsed is None:
        return None
    try:
        return [_array(r) for r in parsed]
    except (OverflowError, TypeError, ValueError, struct.error):   # pragma: no cover
        return None


def _fast_values(body: bytes, checked: bool = False) -> np.ndarray | None:
    """``body``'s numbers if every token is ``[-]digits.digits`` (see the module docstring),
    else None.  ``checked``: the caller made sure ``body`` holds only :data:`_FAST_CHARS`
    with single spaces between tokens and none around them.  Never raises."""
    if not checked and (body.translate(None, _FAST_CHARS) or b"  " in body
                        or body[:1] == b" " or body[-1:] == b" "):
        return None
    if not body or b" -. " in b" " + body + b" ":      # '-.': a token without a digit
        return None
    a = np.frombuffer(body, dtype=np.uint8)
    sp = (a == 32).nonzero()[0]
    dots = (a == 46).nonzero()[0]
    k = sp.size + 1
    if dots.size != k or (k > 1 and ((dots[:-1] >= sp).any() or (dots[1:] <= sp).any())):
        return None                                    # token i must hold dots[i]
    minus = body.count(b"-")
    if minus and minus != body.count(b" -") + (a[0] == 45):
        return None                                    # a '-' inside a token
    # every token is now [-]digits.digits: its digits form an integer
    m = np.fromstring(body.replace(b".", b""), dtype=np.int64, sep=" ")
    if m.size != k:                                    # a token that was only '.'
        return None
    dec = np.empty(k, dtype=np.intp)                   # digits after each point
    np.subtract(sp, dots[:-1], out=dec[:-1])
    dec[-1] = a.size - dots[-1]
    dec -= 1
    if dec.max() >= _POW10.size or m.max() >= _EXACT_INT or m.min() <= -_EXACT_INT:
        return None
    out = m / _POW10[dec]
    if minus and (b"-0" in body or b"-." in body):     # '-0.0' is -0.0, as float() says
        zero = (m == 0).nonzero()[0]
        if zero.size:
            first = np.concatenate(([0], sp + 1))[zero]
            out[zero[a[first] == 45]] = -0.0
    return out


def parse_decimals(body: bytes) -> np.ndarray:
    """Numbers separated by white space -> float64 array, each exactly ``float(token)``
    (see the module docstring); AxisError('corrupt') if a token is not a number."""
    row = body.translate(_TO_JSON, _NOT_JSON)
    if len(row) == len(body):
        rows = _json_rows([row])
        if rows is not None:
            return rows[0]
    out = _fast_values(body)
    return out if out is not None else _slow(body.split())


def _fields(chunk: bytes | str) -> tuple[int, str, bytes]:
    """(avatar index, avatar name, values text) of one frame; AxisError ``corrupt``."""
    if isinstance(chunk, str):
        try:
            chunk = chunk.encode("ascii")
        except UnicodeEncodeError:
            raise AxisError("corrupt", "text frame is not ASCII") from None
    elif not chunk.isascii():
        raise AxisError("corrupt", "text frame is not ASCII")
    text = bytes(chunk).strip()
    if text.endswith(b"||"):
        text = text[:-2].rstrip()
    head = text.split(None, 2)
    if len(head) < 3:
        raise AxisError("corrupt", f"text frame of {len(head)} fields (index, name, values)")
    try:
        index = int(head[0])
    except ValueError:
        raise AxisError("corrupt", f"avatar index {head[0][:20].decode()!r} is not an "
                        "integer") from None
    return index, head[1].decode("ascii"), head[2]


def _plain(body: bytes) -> bool:
    """Only :data:`_FAST_CHARS`, single spaces (``body`` comes stripped)."""
    return not body.translate(None, _FAST_CHARS) and b"  " not in body


def _exact(index: int, name: str, body: bytes, joints: int) -> AxisFrame:
    """The frame of a body orjson did not read: layout from the token count, numbers by
    the integer fast path or ``float()`` token by token."""
    if _plain(body):
        disp, ref = layout(body.count(b" ") + 1, joints)
        values = _fast_values(body, checked=True)
        if values is None:
            values = _slow(body.split())
    else:
        tokens = body.split()
        disp, ref = layout(len(tokens), joints)
        values = _slow(tokens)
    return AxisFrame(index, name, values, disp, ref)


def decode_text(chunk: bytes | str, joints: int = len(JOINTS)) -> AxisFrame:
    """One text frame (the part between two ``||``, or one frame ending in ``||``): index,
    name, values.  AxisError ``corrupt`` (not ASCII, too few fields, a value that is not a
    number) or ``bad_messages`` (a value count that fits no layout)."""
    got = decode_texts([chunk], joints)[0]
    if isinstance(got, AxisError):
        raise got
    return got


def decode_texts(chunks: list[bytes], joints: int = len(JOINTS)
                 ) -> list[AxisFrame | AxisError]:
    """:func:`decode_text` of each chunk (the AxisFrame, or the AxisError it raised), in
    order.  The numbers of all the chunks that hold only JSON number characters are parsed
    by one orjson call (:func:`_json_lists`: what a TCP read holding several frames costs
    once); if it refuses them, each is tried alone, and a chunk orjson refuses is read by
    the exact paths (:func:`_exact`).  A row's count is checked against the layouts before
    its numbers become an array (a count that fits none is ``bad_messages`` either way)."""
    out: list[AxisFrame | AxisError | None] = [None] * len(chunks)
    json: list[tuple[int, int, str, bytes]] = []
    rows: list[bytes] = []
    for i, chunk in enumerate(chunks):
        try:
            index, name, body = _fields(chunk)
            row = body.translate(_TO_JSON, _NOT_JSON)
            if len(row) == len(body):
                json.append((i, index, name, body))
                rows.append(row)
            else:
                out[i] = _exact(index, name, body, joints)
        except AxisError as e:
            out[i] = e
    if not json:
        return out  # type: ignore[return-value]
    parsed = _json_lists(rows)
    if parsed is None and len(rows) > 1:           # some row is not JSON: the others are
        parsed = [(_json_lists([r]) or [None])[0] for r in rows]
    for k, (i, index, name, body) in enumerate(json):
        numbers = None if parsed is None else parsed[k]
        try:
            if numbers is not None:
                disp, ref = layout(len(numbers), joints)
                try:
                    values = _array(numbers)
                except (OverflowError, TypeError, struct.error):  # pragma: no cover
                    numbers = None                  # (orjson gives only numbers)
                else:
                    out[i] = AxisFrame(index, name, values, disp, ref, finite=True)
            if numbers is None:
                out[i] = _exact(index, name, body, joints)
        except AxisError as e:
            out[i] = e
    return out  # type: ignore[return-value]


def encode_text(values: np.ndarray, avatar_index: int = 0, avatar_name: str = "Avatar00"
                ) -> bytes:
    """``<index> <name> v v ... ||`` with each value written as the shortest decimal that
    gives back its float32 exactly."""
    v = np.asarray(values, dtype=np.float32)
    body = " ".join(map(str, v))        # numpy's shortest repr that gives the float32 back
    return f"{avatar_index} {avatar_name} {body} ||".encode("ascii")


def _split_bars(data: bytes) -> list[bytes]:
    """``data.split(b"||")``, from a split on the single byte ``|`` (a memchr scan) with
    the pieces between two adjacent bars taken as separators left to right, as
    ``split(b"||")`` pairs them; a lone ``|`` stays in its piece."""
    pieces = data.split(b"|")
    if len(pieces) == 3 and not pieces[1]:                  # the common read: one '||'
        return [pieces[0], pieces[2]]
    out: list[bytes] = []
    cur = pieces[0]
    i, n = 1, len(pieces)
    while i < n:
        if not pieces[i] and i + 1 < n:                     # '||': a separator
            out.append(cur)
            cur = pieces[i + 1]
            i += 2
        else:                                               # a lone '|'
            cur += b"|" + pieces[i]
            i += 1
    out.append(cur)
    return out


class TextSplitter:
    """Stream bytes -> text frames: splits on ``||``; a run of more than ``max_frame``
    bytes without a separator is discarded (counted by the caller via ``overflows``).

    A read without a separator is only kept (no copy, no scan of what came before); a read
    that completes frames is joined once with the kept partial frame and split once."""

    def __init__(self, max_frame: int = 65536) -> None:
        self.max_frame = max_frame
        self._parts: list[bytes] = []
        self._size = 0
        self.overflows = 0

    def feed(self, data: bytes) -> list[bytes]:
        data = bytes(data)
        if data.find(b"|") < 0:                # (one byte: memchr; '||' costs 20x more)
            if data:
                self._parts.append(data)
                self._size += len(data)
                if self._size > self.max_frame:
                    self.reset()
                    self.overflows += 1
            return []
        if self._parts:
            self._parts.append(data)
            data = b"".join(self._parts)
        frames = _split_bars(data)
        rest = frames.pop()
        self._parts = [rest] if rest else []
        self._size = len(rest)
        if self._size > self.max_frame:
            self.reset()
            self.overflows += 1
        return [f for f in frames if f and not f.isspace()]

    @property
    def partial(self) -> bool:
        """Whether the bytes kept since the last ``||`` hold a frame's start (not only
        white space)."""
        return any(p.strip() for p in self._parts)

    def reset(self) -> None:
        """Forget a partial frame (after a reconnect)."""
        self._parts = []
        self._size = 0
