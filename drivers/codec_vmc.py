"""VMC over OSC: a lean OSC 1.0 parser, a reference encoder and the frame assembler.

VMC ("Virtual Motion Capture" protocol) sends a skeleton as OSC messages over UDP:

- ``/VMC/Ext/Bone/Pos ,sfffffff`` -- HumanBodyBones name, local position x y z,
  local rotation quaternion x y z w, in Unity's **left-handed**, Y-up frame.
- ``/VMC/Ext/Root/Pos ,sfffffff`` (v2.1 adds 6 floats: scale, offset -- ignored) -- root pose.
- ``/VMC/Ext/T ,f`` -- sender time in seconds.
- ``/VMC/Ext/OK ,i`` (``iii``/``iiii``) -- loaded, calibration state, calibration mode,
  tracking status.

One skeleton is larger than one datagram (~1500 bytes), so a frame spans several
datagrams; :class:`VmcAssembler` rebuilds frames from a stream of datagrams.

Frame conventions at this boundary
----------------------------------
Unity (left-handed) -> rtseg (right-handed, Y-up, scalar-last x, y, z, w):
quaternion ``(x, y, z, w) -> (-x, -y, z, w)``, position ``(x, y, z) -> (x, y, -z)``.
The same maps convert back (they are involutions).  Positions are in the sender's units
(metres for every VMC application known to us).

Errors
------
:func:`parse_packet` raises :class:`OscParseError` (a ``ValueError``) on malformed bytes;
:meth:`VmcAssembler.feed` never raises on any input: it counts and drops (``corrupt``
for malformed OSC, ``bad_messages`` for known addresses with too few / wrongly typed
arguments, ``unknown_names`` for bone names not in the profile, ``bad_values`` for NaN /
non-unit quaternions and non-finite positions or times).
"""

from __future__ import annotations

import logging
import math
import operator
import struct
import time
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from rtseg.drivers.base import SourceStats
from rtseg.frame import Frame

log = logging.getLogger("rtseg.drivers.vmc")

BONE_ADDRESS = "/VMC/Ext/Bone/Pos"
ROOT_ADDRESS = "/VMC/Ext/Root/Pos"
TIME_ADDRESS = "/VMC/Ext/T"
OK_ADDRESS = "/VMC/Ext/OK"

#: Default UDP payload limit of the encoder: 1500-byte Ethernet MTU minus IPv4 (20) and
#: UDP (8) headers, so no datagram is IP-fragmented.
DEFAULT_MAX_DATAGRAM = 1472

#: Unity ``HumanBodyBones`` names (enum order, without ``LastBone``).
HUMAN_BODY_BONES: tuple[str, ...] = (
    "Hips", "LeftUpperLeg", "RightUpperLeg", "LeftLowerLeg", "RightLowerLeg", "LeftFoot",
    "RightFoot", "Spine", "Chest", "Neck", "Head", "LeftShoulder", "RightShoulder",
    "LeftUpperArm", "RightUpperArm", "LeftLowerArm", "RightLowerArm", "LeftHand", "RightHand",
    "LeftToes", "RightToes", "LeftEye", "RightEye", "Jaw",
    "LeftThumbProximal", "LeftThumbIntermediate", "LeftThumbDistal",
    "LeftIndexProximal", "LeftIndexIntermediate", "LeftIndexDistal",
    "LeftMiddleProximal", "LeftMiddleIntermediate", "LeftMiddleDistal",
    "LeftRingProximal", "LeftRingIntermediate", "LeftRingDistal",
    "LeftLittleProximal", "LeftLittleIntermediate", "LeftLittleDistal",
    "RightThumbProximal", "RightThumbIntermediate", "RightThumbDistal",
    "RightIndexProximal", "RightIndexIntermediate", "RightIndexDistal",
    "RightMiddleProximal", "RightMiddleIntermediate", "RightMiddleDistal",
    "RightRingProximal", "RightRingIntermediate", "RightRingDistal",
    "RightLittleProximal", "RightLittleIntermediate", "RightLittleDistal",
    "UpperChest",
)
_HBB_LOWER = {n.lower(): n for n in HUMAN_BODY_BONES}


def canonical_bone_name(name: str) -> str | None:
    """The Unity spelling of a HumanBodyBones name matched case-insensitively, else None."""
    return _HBB_LOWER.get(name.lower())


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
_F7 = struct.Struct(">7f")
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


_BONE_HEAD = _pad_string(BONE_ADDRESS) + _pad_string(",sfffffff")
_ROOT_HEAD = _pad_string(ROOT_ADDRESS) + _pad_string(",sfffffff")
_TIME_HEAD = _pad_string(TIME_ADDRESS) + _pad_string(",f")
_OK_HEAD4 = _pad_string(OK_ADDRESS) + _pad_string(",iiii")
_I4 = struct.Struct(">4i")
_ZERO3 = (0.0, 0.0, 0.0)


def encode_pose_message(address: str, name: str, position: Sequence[float],
                        quat: Sequence[float]) -> bytes:
    """``address ,sfffffff`` from a position and quaternion **in rtseg's right-handed
    frame** (scalar-last); converted here to Unity's left-handed frame."""
    px, py, pz = (float(v) for v in position)
    x, y, z, w = (float(v) for v in quat)
    head = _BONE_HEAD if address == BONE_ADDRESS else (
        _ROOT_HEAD if address == ROOT_ADDRESS else _pad_string(address) + _pad_string(",sfffffff"))
    return head + _pad_string(name) + _F7.pack(px, py, -pz, -x, -y, z, w)


def encode_frame(quats: np.ndarray, bone_names: Sequence[str], *,
                 time: float | None = None,
                 root_position: Sequence[float] | None = None,
                 root_rotation: Sequence[float] | None = None,
                 bone_positions: np.ndarray | None = None,
                 ok: Sequence[int] | None = (1, 3, 0, 1),
                 include: Sequence[bool] | None = None,
                 max_datagram: int = DEFAULT_MAX_DATAGRAM) -> list[bytes]:
    """One skeleton pose as VMC datagrams (bundles of at most ``max_datagram`` bytes).

    ``quats``: (J, 4) local rotations, rtseg frame (right-handed, scalar-last);
    ``bone_names``: J HumanBodyBones names as sent.  Order on the wire: Root/Pos (when
    ``root_position`` or ``root_rotation`` is given), one Bone/Pos per bone (``include[j]``
    False omits bone j), T (when ``time`` is given), OK (when ``ok`` is given).
    ``bone_positions``: (J, 3) local positions (default zeros).  Values are float32 on the
    wire.
    """
    q = np.asarray(quats, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4 or q.shape[0] != len(bone_names):
        raise ValueError(f"quats must be ({len(bone_names)}, 4), got {q.shape}")
    msgs: list[bytes] = []
    if root_position is not None or root_rotation is not None:
        msgs.append(encode_pose_message(
            ROOT_ADDRESS, "root", _ZERO3 if root_position is None else root_position,
            (0.0, 0.0, 0.0, 1.0) if root_rotation is None else root_rotation))
    qs = q.tolist()
    pos = None if bone_positions is None else np.asarray(bone_positions, dtype=np.float64).tolist()
    pack = _F7.pack
    for j, name in enumerate(bone_names):
        if include is not None and not include[j]:
            continue
        x, y, z, w = qs[j]
        px, py, pz = _ZERO3 if pos is None else pos[j]
        msgs.append(_BONE_HEAD + _pad_string(name) + pack(px, py, -pz, -x, -y, z, w))
    if time is not None:
        msgs.append(_TIME_HEAD + _F32.pack(float(time)))
    if ok is not None:
        msgs.append(encode_message(OK_ADDRESS, "i" * len(ok), [int(v) for v in ok]))
    return pack_bundles(msgs, max_datagram)


# --------------------------------------------------------------------------- assembling

def _rotate(q: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """Vector ``v`` rotated by unit quaternion ``q`` (scalar-last)."""
    x, y, z, w = q
    vx, vy, vz = v
    # t = 2 * (q_vec x v); v' = v + w t + q_vec x t
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty),
            vy + w * ty + (z * tx - x * tz),
            vz + w * tz + (x * ty - y * tx))


_MISSING = object()


class _Template:
    """Layout of a datagram that carries one whole frame: root (optional), every profile
    bone once, T after the bones, OK and ignored messages anywhere.  Senders repeat the
    same layout every frame with new numbers, so one precompiled ``struct`` unpack reads
    the layout bytes (compared with the template's in one tuple comparison) and every
    value at once."""

    __slots__ = ("st", "checks", "get_checks", "bones", "root_at", "t_at", "ok_at",
                 "hips_at", "n_unknown")

    def unpack(self, data: bytes) -> tuple | None:
        """All fields of ``data``, or None if its layout differs from the template's."""
        tup = self.st.unpack_from(data)
        return tup if self.get_checks(tup) == self.checks else None


class VmcAssembler:
    """Rebuild skeleton frames from a stream of VMC datagrams.

    ``bone_names``: the profile's HumanBodyBones names (matched case-insensitively); frame
    quaternions come out in this order, converted to rtseg's right-handed frame.

    A frame is **closed** (emitted) when, after it has received at least one bone:

    1. ``/VMC/Ext/Root/Pos`` arrives with a pose different from the frame's root, or -- if
       the frame has no root yet -- more than ``burst`` seconds after the frame's first bone
       (the root *leads* each frame in VMC; within one burst of datagrams a late root still
       joins its frame, so datagrams reordered within a frame are fine), or
    2. a bone arrives that this frame already holds (the sender started the next frame), or
    3. ``time_order="first"`` only: ``/VMC/Ext/T`` arrives with a value different from the
       frame's time, or
    4. it is complete: every profile bone received, plus T and root if the sender has been
       seen sending them (closes with no added latency; enabled once rules 1-3 have closed
       one frame, so the sender's message order is known), or
    5. :meth:`flush` is called ``quiet`` seconds or more after the last datagram (a T or
       root left without bones is then forgotten).

    ``time_order``: where a sender puts ``/VMC/Ext/T`` relative to the bones it stamps.
    ``"last"`` (default; VirtualMotionCapture and its followers send Root, Bones, Blend, OK,
    T): a T always sets the open frame's time, overwriting an orphan T left by a frame whose
    bones were lost, and never closes a frame.  ``"first"``: T opens each frame (rule 3).
    Which one is meant cannot be told from message order alone once a datagram is lost, so
    it is a setting, not a guess.  With ``"last"``, T-first senders still decode right when
    they send every profile bone in each frame (rule 4 closes the frame before the next T).

    Per frame: ``quats`` (J, 4) -- bones not received hold their last value (identity before
    the first) with ``valid`` False; ``source_time`` from T; ``seq`` counts frames from 0,
    advancing by the number of sender frames elapsed when T jumps by more than 1.75 of the
    sender's frame period (estimated from T), so frames lost on the network show up as
    sequence gaps (and in ``stats.gaps`` / ``stats.dropped``); ``root_position`` = Root/Pos position + root rotation applied to the root bone's
    local position (the world position of the hips when Root is their parent), or the root
    bone's local position when no Root/Pos was sent, or None when neither was.
    ``continuous``: flip each bone's quaternion sign so its dot with the previous value is
    non-negative (q and -q are the same rotation).

    Speed: bone messages in bundles take a fast path (one ``struct`` unpack each).  A
    datagram that holds a whole frame in a layout seen before (same bundle structure and
    names, new numbers -- what a sender with a small skeleton sends every frame) is decoded
    with one numpy gather (``fast=True``); the result is identical to the message-by-message
    path, which handles everything else and any datagram with a bad value.
    """

    def __init__(self, bone_names: Sequence[str], *, quiet: float = 0.02,
                 unit_tolerance: float = 0.05, continuous: bool = True,
                 time_order: str = "last", burst: float = 0.004,
                 stats: SourceStats | None = None, fast: bool = True) -> None:
        if not bone_names:
            raise ValueError("VmcAssembler needs at least one bone name")
        lowered = [n.lower() for n in bone_names]
        if len(set(lowered)) != len(lowered):
            raise ValueError(f"duplicate bone names (case-insensitive) in {list(bone_names)}")
        self.bone_names = list(bone_names)
        self.n_bones = len(bone_names)
        self.quiet = float(quiet)
        self.unit_tolerance = float(unit_tolerance)
        self.continuous = continuous
        if time_order not in ("last", "first"):
            raise ValueError(f"time_order must be 'last' or 'first', not {time_order!r}")
        self.time_order = time_order
        self.t_last = time_order == "last"
        self.burst = float(burst)
        self.fast = fast
        self._templates: dict[int, _Template | None] = {}
        #: Frames decoded by the whole-frame fast path (diagnostics).
        self.fast_frames = 0
        self._frame_start = -math.inf          # arrival time of the open frame's first bone
        self._t_time = -math.inf               # arrival time of the open frame's T
        self._now = 0.0
        self.stats = stats if stats is not None else SourceStats()
        self._index = {n: i for i, n in enumerate(lowered)}
        self._cache: dict[bytes, int] = {}    # raw name -> index (-1 unknown)
        self._pcache: dict[bytes, int] = {}   # padded name field -> index / -2 / -3
        self._root_bone = self._index.get("hips", 0)
        self._all_false = [False] * self.n_bones
        self._all_true = [True] * self.n_bones
        self._q = [0.0, 0.0, 0.0, 1.0] * self.n_bones   # last value per bone, rtseg frame
        self._got = [False] * self.n_bones
        self._n_got = 0
        self._t: float | None = None          # T of the open frame
        self._root: tuple | None = None       # raw Root/Pos floats of the open frame
        self._last_root: tuple | None = None  # last root pose (rtseg frame): pos, quat
        self._root_bone_pos: tuple | None = None
        self._sends_t = False
        self._sends_root = False
        self._last_closed_t: float | None = None
        self._learned = False                 # a frame closed by a change rule was seen
        self._last_activity = -math.inf
        self._seq = 0
        self._prev_t: float | None = None      # T of the last frame closed with one
        self._period: float | None = None      # sender frame period estimated from T, s
        self._out: list[Frame] = []
        self._warned: dict[str, float] = {}
        self._unknown_seen: set[bytes] = set()
        #: Last ``/VMC/Ext/OK`` arguments (loaded, calibration state, mode, tracking) or None.
        self.ok_state: tuple[int, ...] | None = None
        #: Last root rotation (rtseg frame, scalar-last) or None.
        self.root_rotation: tuple[float, float, float, float] | None = None

    # -- public

    def feed(self, data: bytes, now: float) -> list[Frame]:
        """Process one datagram received at ``now`` (monotonic s); return frames closed by it
        (usually none or one).  Never raises on malformed input: it is counted and dropped."""
        self._out = out = []
        self._last_activity = now
        self._now = now
        n = len(data)
        if n < 4 or n & 3:
            self._corrupt(f"datagram of {n} bytes is not a positive multiple of 4")
            return out
        if data.startswith(_BUNDLE):
            if self.fast and self._n_got == 0 and self._learned and self.t_last and \
                    self._sends_t:
                tpl = self._templates.get(n, _MISSING)
                tup = None
                if tpl is not None and tpl is not _MISSING:
                    tup = tpl.unpack(data)
                if tup is None and (tpl is _MISSING or tpl is not None):
                    tpl = self._build_template(data)     # new or changed layout
                    tup = None if tpl is None else tpl.st.unpack_from(data)
                if tup is not None and self._apply_template(tpl, tup):
                    self.fast_frames += 1
                    return out
            self._bundle(data, 0, n, 0)
        else:
            self._message(data, 0, n)
        return out

    def flush(self, now: float, force: bool = False) -> list[Frame]:
        """Close the open frame if ``quiet`` seconds passed since the last datagram (or
        ``force``); returns the frames closed (0 or 1)."""
        self._out = out = []
        if force or now - self._last_activity >= self.quiet:
            if self._n_got:
                self._now = now
                self._close()
            else:   # a T / root with no bones after it: stale, forget it
                self._t = None
                self._root = None
        return out

    @property
    def pending(self) -> bool:
        """True when a frame has received bones but is not closed yet."""
        return self._n_got > 0

    # -- internals

    def _warn(self, key: str, message: str) -> None:
        t = time.monotonic()
        if t - self._warned.get(key, -math.inf) >= 5.0:
            self._warned[key] = t
            log.warning("VMC: %s", message)

    def _corrupt(self, message: str) -> None:
        self.stats.corrupt += 1
        self._warn("corrupt", f"malformed OSC dropped: {message}")

    def _bad_message(self, message: str) -> None:
        self.stats.bad_messages += 1
        self._warn("bad_message", f"message dropped: {message}")

    def _bad_value(self, message: str) -> None:
        self.stats.bad_values += 1
        self._warn("bad_value", f"value dropped: {message}")

    def _resolve(self, raw: bytes) -> int:
        try:
            name = raw.decode("ascii")
        except UnicodeDecodeError:
            name = None
        idx = -1 if name is None else self._index.get(name.lower(), -1)
        if len(self._cache) < 4096:
            self._cache[raw] = idx
        return idx

    def _resolve_padded(self, padded: bytes) -> int:
        """Index for the padded name field of a fast-path bone message: profile index,
        -1 unknown name, -2 not the exact ``,sfffffff`` layout (use the generic path)."""
        nul = padded.find(b"\x00")
        if nul < 0 or padded != padded[:nul] + b"\x00" * (len(padded) - nul) or \
                len(padded) != (nul & ~3) + 4:
            idx = -2
        else:
            idx = self._resolve(padded[:nul])
            if idx == -1:
                idx = -3   # unknown, counted by the caller after the layout check
        if len(self._pcache) < 4096:
            self._pcache[padded] = idx
        return idx

    def _bundle(self, data: bytes, start: int, end: int, depth: int) -> None:
        if depth >= _MAX_DEPTH:
            self._corrupt(f"bundles nested deeper than {_MAX_DEPTH}")
            return
        if end - start < 16:
            self._corrupt("truncated bundle header")
            return
        pos = start + 16
        unpack_i = _I32.unpack_from
        unpack_7 = _F7.unpack_from
        startswith = data.startswith
        cache_get = self._pcache.get
        got = self._got
        q = self._q
        tol = self.unit_tolerance
        continuous = self.continuous
        nb = self.n_bones
        root_bone = self._root_bone
        sqrt = math.sqrt
        n_got = self._n_got
        stats = self.stats
        unknown_seen = self._unknown_seen
        while pos < end:
            if pos + 4 > end:
                self._corrupt(f"truncated bundle element size at byte {pos}")
                break
            size = unpack_i(data, pos)[0]
            pos += 4
            stop = pos + size
            if size <= 0 or size & 3 or stop > end:
                self._corrupt(f"bad bundle element size {size} at byte {pos - 4}")
                break
            if size >= 64 and startswith(_BONE_HEAD, pos):
                # fast path: exactly '/VMC/Ext/Bone/Pos ,sfffffff' name x y z x y z w
                fpos = stop - 28
                padded = data[pos + 32:fpos]
                idx = cache_get(padded)
                if idx is None:
                    idx = self._resolve_padded(padded)
                if idx >= 0:
                    px, py, pz, x, y, z, w = unpack_7(data, fpos)
                    n2 = x * x + y * y + z * z + w * w
                    if abs(n2 - 1.0) <= tol:
                        if got[idx]:
                            self._n_got = n_got
                            self._learned = True
                            self._close()
                            n_got = 0
                        # Unity (x, y, z, w) -> ours (-x, -y, z, w), renormalised, with
                        # the sign making the dot with the previous value non-negative
                        s = 1.0 / sqrt(n2)
                        i4 = idx * 4
                        if continuous and (z * q[i4 + 2] + w * q[i4 + 3]
                                           - x * q[i4] - y * q[i4 + 1]) < 0.0:
                            s = -s
                        q[i4] = -x * s
                        q[i4 + 1] = -y * s
                        q[i4 + 2] = z * s
                        q[i4 + 3] = w * s
                        got[idx] = True
                        if not n_got:
                            self._frame_start = self._now
                        n_got += 1
                        if idx == root_bone:
                            self._root_bone_pos = (px, py, -pz) if math.isfinite(
                                px + py + pz) else self._root_bone_pos
                        if n_got == nb:
                            self._n_got = n_got
                            self._maybe_complete()
                            n_got = self._n_got
                    else:
                        self._bad_value(f"bone {padded!r}: quaternion norm² {n2}")
                    pos = stop
                    continue
                if idx == -3:
                    stats.unknown_names += 1
                    if padded not in unknown_seen:
                        self._unknown(padded, count=False)
                    pos = stop
                    continue
                # idx == -2: unusual layout, generic path below
            self._n_got = n_got
            if size == 20 and startswith(_TIME_HEAD, pos):
                self._on_time(_F32.unpack_from(data, pos + 16)[0])
            elif size >= 64 and startswith(_ROOT_HEAD, pos):
                nul = data.find(b"\x00", pos + 32, stop - 28)
                if nul >= 0 and pos + 32 + ((nul - pos - 32) & ~3) + 4 == stop - 28:
                    self._on_root(unpack_7(data, stop - 28))
                else:
                    self._message(data, pos, stop)   # unusual layout: generic path
            elif size == 36 and startswith(_OK_HEAD4, pos):
                self.ok_state = _I4.unpack_from(data, pos + 20)
            elif startswith(_BUNDLE, pos):
                self._bundle(data, pos, stop, depth + 1)
            else:
                self._message(data, pos, stop)
            n_got = self._n_got
            pos = stop
        self._n_got = n_got

    def _unknown(self, raw: bytes, count: bool = True) -> None:
        """Count a bone name outside the profile (``raw`` may carry NUL padding); log each
        name once (up to 256 names)."""
        if count:
            self.stats.unknown_names += 1
        if raw not in self._unknown_seen and len(self._unknown_seen) < 256:
            self._unknown_seen.add(raw)
            log.info("VMC: bone %r not in the suit profile; ignored",
                     raw.rstrip(b"\x00")[:64])

    def _message(self, data: bytes, start: int, end: int) -> None:
        """Generic path: any message other than a fast-path bone."""
        if data[start:start + 1] != b"/":
            self._corrupt("OSC address does not start with '/'")
            return
        nul = data.find(b"\x00", start, end)
        if nul < 0:
            self._corrupt("unterminated OSC address")
            return
        addr = data[start:nul]
        if addr == b"/VMC/Ext/T":
            need = 1
        elif addr == b"/VMC/Ext/Bone/Pos" or addr == b"/VMC/Ext/Root/Pos":
            need = 8
        elif addr == b"/VMC/Ext/OK":
            need = 1
        else:
            return  # unknown address: ignored by design
        try:
            msg = parse_message(data, start, end, max_args=4 if need == 1 else need)
        except OscParseError as exc:
            self._corrupt(str(exc))
            return
        args = msg.args
        if len(args) < need:
            self._bad_message(f"{msg.address} ,{msg.tags}: needs {need} arguments")
            return
        if need == 8:
            if not isinstance(args[0], str) or not all(
                    isinstance(a, (int, float)) and not isinstance(a, bool) for a in args[1:8]):
                self._bad_message(f"{msg.address} ,{msg.tags}: expected ,sfffffff")
                return
            vals = tuple(float(a) for a in args[1:8])
            if addr == b"/VMC/Ext/Root/Pos":
                self._on_root(vals)
            else:
                self._on_bone(args[0], vals)
        elif addr == b"/VMC/Ext/T":
            t = args[0]
            if not isinstance(t, (int, float)) or isinstance(t, bool):
                self._bad_message(f"{msg.address} ,{msg.tags}: expected ,f")
                return
            self._on_time(float(t))
        else:
            ints = [a for a in args if isinstance(a, int) and not isinstance(a, bool)]
            if len(ints) != len(args):
                self._bad_message(f"{msg.address} ,{msg.tags}: expected integers")
                return
            self.ok_state = tuple(ints)

    def _on_bone(self, name: str, vals: tuple) -> None:
        raw = name.encode("utf-8", errors="replace")
        idx = self._cache.get(raw)
        if idx is None:
            idx = self._resolve(raw)
        if idx < 0:
            self._unknown(raw)
            return
        px, py, pz, x, y, z, w = vals
        n2 = x * x + y * y + z * z + w * w
        if not abs(n2 - 1.0) <= self.unit_tolerance:
            self._bad_value(f"bone {name!r}: quaternion norm² {n2}")
            return
        if self._got[idx]:
            self._learned = True
            self._close()
        s = 1.0 / math.sqrt(n2)
        x, y, z, w = -x * s, -y * s, z * s, w * s
        q = self._q
        i4 = idx * 4
        if self.continuous and x * q[i4] + y * q[i4 + 1] + z * q[i4 + 2] + w * q[i4 + 3] < 0.0:
            x, y, z, w = -x, -y, -z, -w
        q[i4:i4 + 4] = (x, y, z, w)
        self._got[idx] = True
        if not self._n_got:
            self._frame_start = self._now
        self._n_got += 1
        if idx == self._root_bone and math.isfinite(px + py + pz):
            self._root_bone_pos = (px, py, -pz)
        if self._n_got == self.n_bones:
            self._maybe_complete()

    def _on_root(self, vals: tuple) -> None:
        if not all(math.isfinite(v) for v in vals):
            self._bad_value(f"root pose not finite: {vals}")
            return
        x, y, z, w = vals[3:]
        n2 = x * x + y * y + z * z + w * w
        if not abs(n2 - 1.0) <= self.unit_tolerance:
            self._bad_value(f"root quaternion norm² {n2}")
            return
        if not self._sends_root:
            self._sends_root = True
            self._learned = False
        if self._n_got and ((self._root is not None and vals != self._root) or (
                self._root is None and self._now - self._frame_start > self.burst)):
            self._learned = True
            self._close()
        self._root = vals
        s = 1.0 / math.sqrt(n2)
        self._last_root = ((vals[0], vals[1], -vals[2]), (-x * s, -y * s, z * s, w * s))
        self.root_rotation = self._last_root[1]
        if self._n_got == self.n_bones:
            self._maybe_complete()

    def _on_time(self, t: float) -> None:
        if not math.isfinite(t):
            self._bad_value(f"time {t} not finite")
            return
        if not self._sends_t:
            self._sends_t = True
            self._learned = False    # frames so far closed without T: re-learn the order
        self._t_time = self._now
        if self.t_last:
            # T belongs to the bones before it: it sets (or corrects) the open frame's time
            if not self._n_got and self._root is None and t == self._last_closed_t:
                return  # a repeat of the frame just closed
            self._t = t
        elif self._t is None:
            if not self._n_got and self._root is None and t == self._last_closed_t:
                return  # a repeat of the frame just closed
            self._t = t
        elif t != self._t:
            if self._n_got:
                self._learned = True
                self._close()
            self._t = t
        if self._n_got == self.n_bones:
            self._maybe_complete()

    def _maybe_complete(self) -> None:
        # Only once a frame boundary has been seen (rules 1-3): until then we do not know
        # whether T / root come before or after the bones.
        # With time_order="last" a T counts only if it came after the frame's first bone or
        # in the same burst (an orphan T from a frame whose bones were lost does not).
        if self._learned and (not self._sends_t or (self._t is not None and (
                not self.t_last or self._t_time >= self._frame_start - self.burst))) and (
                self._root is not None or not self._sends_root):
            self._close()

    def _build_template(self, data: bytes) -> _Template | None:
        """Layout of ``data`` if it is one whole frame in the simple form (see _Template)."""
        n = len(data)
        if len(self._templates) >= 64:
            self._templates.clear()
        self._templates[n] = None
        fmt = [">8s8x"]            # '#bundle\0', time tag (may change per datagram: skipped)
        nfield = 1
        check_at = [0]
        bones: list[tuple[int, int]] = []          # (profile index, field of first float)
        root_at = t_at = ok_at = hips_at = None
        n_unknown = 0
        seen = set()
        pos = 16
        unpack_i = _I32.unpack_from
        while pos < n:
            if pos + 4 > n:
                return None
            size = unpack_i(data, pos)[0]
            stop = pos + 4 + size
            if size <= 0 or size & 3 or stop > n:
                return None
            m = pos + 4                               # message start
            if size >= 64 and data.startswith(_BONE_HEAD, m):
                padded = data[m + 32:stop - 28]
                idx = self._pcache.get(padded)
                if idx is None:
                    idx = self._resolve_padded(padded)
                if idx == -2 or (idx >= 0 and (idx in seen or t_at is not None)):
                    return None
                fmt.append(f"{stop - 28 - pos}s")
                check_at.append(nfield)
                nfield += 1
                if idx == -3:
                    n_unknown += 1
                    self._unknown(padded, count=False)
                    fmt.append("28x")
                else:
                    seen.add(idx)
                    if idx == self._root_bone:
                        hips_at = nfield
                    bones.append((idx, nfield))
                    fmt.append("7f")
                    nfield += 7
            elif size >= 64 and data.startswith(_ROOT_HEAD, m):
                nul = data.find(b"\x00", m + 32, stop - 28)
                if (root_at is not None or bones or nul < 0
                        or m + 32 + ((nul - m - 32) & ~3) + 4 != stop - 28):
                    return None
                fmt.append(f"{stop - 28 - pos}s7f")
                check_at.append(nfield)
                root_at = nfield + 1
                nfield += 8
            elif size == 20 and data.startswith(_TIME_HEAD, m):
                if t_at is not None:
                    return None
                fmt.append("20sf")
                check_at.append(nfield)
                t_at = nfield + 1
                nfield += 2
            elif size == 36 and data.startswith(_OK_HEAD4, m):
                fmt.append("24s4i")
                check_at.append(nfield)
                ok_at = nfield + 1
                nfield += 5
            else:
                if data[m:m + 1] != b"/":
                    return None
                nul = data.find(b"\x00", m, stop)
                if nul < 0 or data[m:nul] in (b"/VMC/Ext/T", b"/VMC/Ext/Bone/Pos",
                                              b"/VMC/Ext/Root/Pos", b"/VMC/Ext/OK"):
                    return None           # nested bundle, malformed or unusual layout
                head = (nul & ~3) + 4 - pos              # size word + padded address
                if pos + head > stop:
                    return None
                fmt.append(f"{head}s{stop - pos - head}x")   # its arguments are ignored
                check_at.append(nfield)
                nfield += 1
            pos = stop
        if len(bones) != self.n_bones or t_at is None or (
                root_at is None and self._sends_root):
            return None
        tpl = _Template()
        tpl.st = struct.Struct("".join(fmt))
        if tpl.st.size != n:
            return None
        tpl.get_checks = operator.itemgetter(*check_at)
        tpl.checks = tpl.get_checks(tpl.st.unpack_from(data))
        tpl.bones = bones
        tpl.root_at, tpl.t_at, tpl.ok_at, tpl.hips_at = root_at, t_at, ok_at, hips_at
        tpl.n_unknown = n_unknown
        self._templates[n] = tpl
        return tpl

    def _apply_template(self, tpl: _Template, tup: tuple) -> bool:
        """Apply a whole-frame datagram of a known layout (``tup``: its unpacked fields);
        False, with nothing changed, if any value is bad, so the message-by-message path
        can count it exactly."""
        tol = self.unit_tolerance
        t = tup[tpl.t_at]
        if not math.isfinite(t):
            return False
        for _, k in tpl.bones:
            x, y, z, w = tup[k + 3:k + 7]
            if not abs(x * x + y * y + z * z + w * w - 1.0) <= tol:
                return False
        ra = tpl.root_at
        if (ra is not None) != self._sends_root:
            return False              # the sender changed: let the general path re-learn
        if ra is not None:
            root = tup[ra:ra + 7]
            rx, ry, rz, rw = root[3:]
            rn2 = rx * rx + ry * ry + rz * rz + rw * rw
            if not (abs(rn2 - 1.0) <= tol and math.isfinite(root[0] + root[1] + root[2])):
                return False
            s = 1.0 / math.sqrt(rn2)
            self._root = root
            self._last_root = ((root[0], root[1], -root[2]), (-rx * s, -ry * s, rz * s, rw * s))
            self.root_rotation = self._last_root[1]
        # all values good: apply exactly what the message-by-message path would
        self.stats.unknown_names += tpl.n_unknown
        q = self._q
        continuous = self.continuous
        sqrt = math.sqrt
        for idx, k in tpl.bones:
            x, y, z, w = tup[k + 3:k + 7]
            s = 1.0 / sqrt(x * x + y * y + z * z + w * w)
            i4 = idx * 4
            if continuous and (z * q[i4 + 2] + w * q[i4 + 3] - x * q[i4] - y * q[i4 + 1]) < 0.0:
                s = -s
            q[i4] = -x * s
            q[i4 + 1] = -y * s
            q[i4 + 2] = z * s
            q[i4 + 3] = w * s
        if tpl.hips_at is not None:
            px, py, pz = tup[tpl.hips_at:tpl.hips_at + 3]
            if math.isfinite(px + py + pz):
                self._root_bone_pos = (px, py, -pz)
        self._got[:] = self._all_true
        self._n_got = self.n_bones
        self._frame_start = self._now
        self._t = t
        self._t_time = self._now
        self._close()
        if tpl.ok_at is not None:
            self.ok_state = tup[tpl.ok_at:tpl.ok_at + 4]
        return True

    def _frames_elapsed(self, dt: float) -> int:
        """Sender frames from the previous T to this one (1 normally; k > 1 when frames were
        lost on the way, counted in ``gaps`` / ``dropped``).  The sender's frame period is
        tracked from T steps: dt < 0.6 period resets it, dt < 1.75 period refines it (EMA),
        longer steps are gaps of round(dt / period) - 1 frames."""
        p = self._period
        if not dt > 0:
            return 1                    # same T repeated, or the sender's clock restarted
        if p is None or dt < 0.6 * p:
            self._period = dt
            return 1
        if dt < 1.75 * p:
            self._period = p + 0.05 * (dt - p)
            return 1
        ratio = dt / p
        if not ratio < 1e6:             # a clock jump, not lost frames: start afresh
            self._period = None
            self.stats.gaps += 1
            self._warn("gap", f"/VMC/Ext/T jumped by {dt:.3g} s; frame period re-estimated")
            return 1
        k = max(2, int(ratio + 0.5))
        self.stats.gaps += 1
        self.stats.dropped += k - 1
        self._warn("gap", f"/VMC/Ext/T jumped {dt * 1000:.1f} ms: about {k - 1} frame(s) "
                          f"lost on the way")
        return k

    @property
    def frame_period(self) -> float | None:
        """The sender's frame period in seconds estimated from ``/VMC/Ext/T``, or None."""
        return self._period

    def _close(self) -> None:
        J = self.n_bones
        quats = np.array(self._q, dtype=np.float64).reshape(J, 4)
        valid = np.array(self._got, dtype=bool)
        rp = None
        if self._last_root is not None:
            pos, rot = self._last_root
            if self._root_bone_pos is not None and self._root_bone_pos != (0.0, 0.0, 0.0):
                off = _rotate(rot, self._root_bone_pos)
                rp = np.array((pos[0] + off[0], pos[1] + off[1], pos[2] + off[2]))
            else:
                rp = np.array(pos, dtype=np.float64)
        elif self._root_bone_pos is not None:
            rp = np.array(self._root_bone_pos, dtype=np.float64)
        t = self._t
        if t is not None:
            if self._prev_t is not None:
                self._seq += self._frames_elapsed(t - self._prev_t) - 1
            self._prev_t = t
        self._out.append(Frame(recv_time=self._now, quats=quats, valid=valid,
                               source_time=t, seq=self._seq, root_position=rp))
        self._seq += 1
        self._last_closed_t = t
        self._got[:] = self._all_false   # in place: _bundle holds a reference
        self._n_got = 0
        self._t = None
        self._root = None


__all__ = [
    "BONE_ADDRESS", "ROOT_ADDRESS", "TIME_ADDRESS", "OK_ADDRESS", "DEFAULT_MAX_DATAGRAM",
    "HUMAN_BODY_BONES", "canonical_bone_name", "OscParseError", "OscMessage",
    "parse_message", "parse_packet", "encode_message", "encode_bundle", "pack_bundles",
    "encode_pose_message", "encode_frame", "VmcAssembler",
]
