"""VMC over OSC: a lean OSC 1.0 parser, a reference encoder and the frame assembler.

VMC ("Virtual Motion Capture" protocol) sends a skeleton as OSC messages over UDP:

- ``/VMC/Ext/Bone/Pos ,sfffffff`` -- HumanBodyBones name, local position x y z,
  local rotation quaternion x y z w, in Unity's **left-handed**, Y-up frame.
- ``/VMC/Ext/Root/Pos ,sfffffff`` (v2.1 adds 6 floats: scale, offset -- ignored) -- root pose.
- ``/VMC/Ext/T ,f`` -- sender time in seconds.
- ``/VMC/Ext/OK ,i`` (``iii``/``iiii``) -- loaded, calibration state, calibration mode,
  tracking status.

One skeleton is larger than one datagram (~1500 bytes), so a frame spans several
Modules: :mod:`~rtseg.drivers.osc.codec` (OSC 1.0 parser and encoder),
:mod:`~rtseg.drivers.osc.vmc.bones` (HumanBodyBones names),
:mod:`~rtseg.drivers.osc.vmc.encode` (VMC reference encoder),
:mod:`~rtseg.drivers.osc.vmc.frames` (the frame closing rules),
:mod:`~rtseg.drivers.osc.vmc.template` (whole-frame datagram layouts) and this one
(:class:`VmcAssembler`: datagrams in, frames out).  Their public names are importable from
here as before.


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
for malformed OSC -- a bundle whose element sizes do not tile it, as a truncated datagram's
do not, is dropped whole before any of its elements is used, and so is a bundle that is a
strict prefix of one of the last 4 bundles received (a copy cut at an element boundary,
which parses) -- ``bad_messages`` for known addresses with too few / wrongly typed
arguments, ``unknown_names`` for bone names not in the profile, ``bad_values`` for NaN /
non-unit quaternions and non-finite positions or times).
"""

from __future__ import annotations

import math
from functools import partial
from typing import Sequence

from rtseg.drivers.base import SourceStats
from rtseg.drivers.osc.codec import (_BUNDLE, _F32, _I32, _MAX_DEPTH, DEFAULT_MAX_DATAGRAM,
                                     OscMessage, OscParseError, encode_bundle, encode_message,
                                     pack_bundles, parse_message, parse_packet)
from rtseg.drivers.osc.vmc.bones import HUMAN_BODY_BONES, canonical_bone_name
from rtseg.drivers.osc.vmc.encode import (_BONE_HEAD, _F7, _I4, _OK_HEAD4, _ROOT_HEAD,
                                            _TIME_HEAD, BONE_ADDRESS, OK_ADDRESS,
                                            ROOT_ADDRESS, TIME_ADDRESS, encode_frame,
                                            encode_pose_message)
from rtseg.drivers.osc.vmc.frames import MAX_TIME, VmcFrameRules
from rtseg.drivers.osc.vmc.template import _Template, build_template
from rtseg.core.frame import Frame

_MISSING = object()

#: UDP port of a VMC receiver ("Marionette") that no URL or option names otherwise
DEFAULT_PORT = 39539


#: Bundles remembered to recognise a truncated copy of one of them.
RECENT_BUNDLES = 4


def bundle_structure_error(data: bytes, start: int, end: int, depth: int) -> str | None:
    """Why the OSC bundle in ``data[start:end]`` is malformed as a structure (header,
    element sizes that do not tile it exactly, nesting too deep), or None when every
    element, nested bundles included, lies whole inside it.  Element contents are not
    parsed here; this walk lets a truncated bundle be dropped before any element is used."""
    if depth >= _MAX_DEPTH:
        return f"bundles nested deeper than {_MAX_DEPTH}"
    if end - start < 16:
        return "truncated bundle header"
    pos = start + 16
    unpack_i = _I32.unpack_from
    while pos < end:
        if pos + 4 > end:
            return f"truncated bundle element size at byte {pos}"
        size = unpack_i(data, pos)[0]
        pos += 4
        if size <= 0 or size & 3 or pos + size > end:
            return f"bad bundle element size {size} at byte {pos - 4}"
        if data.startswith(_BUNDLE, pos):
            problem = bundle_structure_error(data, pos, pos + size, depth + 1)
            if problem is not None:
                return problem
        pos += size
    return None


class VmcAssembler(VmcFrameRules):
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
    the first) with ``valid`` False; ``source_time`` from T, monotonic across sender restarts: when T goes back or jumps ahead
    by more than ``MAX_CLOCK_JUMP`` s the reported clock starts a new segment one frame
    period after the last reported time (warned, counted in ``stats.clock_restarts``) -
    except a frame whose T lies at most ``LATE_WINDOW`` s behind the last one's and that
    arrives within ``LATE_SILENCE`` s of it (reordered or repeated on the way): that frame is
    dropped (``stats.bad_messages``) and the clock goes on (when the next frame goes on from
    the dropped one, the frame before them had a damaged T: a clock restart there);
    ``seq`` counts frames from 0,
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
                 stats: SourceStats | None = None, fast: bool = True,
                 parents: Sequence[int] | None = None) -> None:
        super().__init__(bone_names, quiet=quiet, unit_tolerance=unit_tolerance,
                         continuous=continuous, time_order=time_order, burst=burst,
                         stats=stats, parents=parents)
        self.fast = fast
        # the last few bundles received: one arriving as a strict prefix of one of them is a
        # truncated copy (a valid bundle cut at an element boundary still parses)
        self._recent: list[bytes] = []
        self._templates: dict[int, _Template | None] = {}
        #: Frames decoded by the whole-frame fast path (diagnostics).
        self.fast_frames = 0

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
            problem = bundle_structure_error(data, 0, n, 0)
            if problem is not None:
                # dropped whole: no element of a bundle that does not parse is used
                self._corrupt(f"bundle dropped whole: {problem}")
                return out
            for prev in self._recent:
                if len(prev) > n and prev.startswith(data):
                    self._corrupt(f"bundle of {n} bytes is a truncated copy of one of "
                                  f"{len(prev)} bytes received before it; dropped whole")
                    return out
            recent = self._recent
            recent.append(data)
            if len(recent) > RECENT_BUNDLES:
                del recent[0]
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
        offsets = self.offsets
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
                        if offsets.capturing:
                            offsets.note(idx, px, py, -pz)
                        if n_got == nb:
                            self._n_got = n_got
                            self._maybe_complete()
                            n_got = self._n_got
                    else:
                        name = padded.rstrip(b"\x00").decode("utf-8", "replace")
                        self._bad_value(f"bone {name!r}: quaternion norm² {n2}")
                    pos = stop
                    continue
                if idx == -3:
                    stats.unknown_names += 1
                    if offsets.capturing:
                        px, py, pz = unpack_7(data, stop - 28)[:3]
                        offsets.note_extra(padded.rstrip(b"\x00").decode("utf-8", "replace"),
                                           px, py, -pz)
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

    def _build_template(self, data: bytes) -> _Template | None:
        """Layout of ``data`` if it is one whole frame in the simple form (cached per
        datagram size, at most 64 sizes; None is cached too)."""
        n = len(data)
        if len(self._templates) >= 64:
            self._templates.clear()
        self._templates[n] = None
        tpl = build_template(data, self._padded_index, partial(self._unknown, count=False),
                             self._root_bone, self.n_bones, self._sends_root)
        if tpl is not None:
            self._templates[n] = tpl
        return tpl

    def _apply_template(self, tpl: _Template, tup: tuple) -> bool:
        """Apply a whole-frame datagram of a known layout (``tup``: its unpacked fields);
        False, with nothing changed, if any value is bad, so the message-by-message path
        can count it exactly."""
        tol = self.unit_tolerance
        t = tup[tpl.t_at]
        if not abs(t) <= MAX_TIME:
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
        if self.offsets.capturing:
            for idx, k in tpl.bones:
                self.offsets.note(idx, tup[k], tup[k + 1], -tup[k + 2])
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


__all__ = [
    "BONE_ADDRESS", "ROOT_ADDRESS", "TIME_ADDRESS", "OK_ADDRESS", "DEFAULT_MAX_DATAGRAM",
    "DEFAULT_PORT",
    "HUMAN_BODY_BONES", "canonical_bone_name", "OscParseError", "OscMessage",
    "parse_message", "parse_packet", "encode_message", "encode_bundle", "pack_bundles",
    "encode_pose_message", "encode_frame", "VmcAssembler", "bundle_structure_error",
]
