"""Xsens MVN real-time network streaming ("MXTP" over UDP): parser, encoder, frame assembler.

Pure bytes -> frames: no sockets here (see :mod:`rtseg.drivers.mvn_source`).

Wire format (big-endian), as in the "MVN real-time network streaming protocol
specification" and the receivers that follow it (e.g. wouterpot/xsens-to-osc
``server/xsens/read-mxtp.js``):

==========  ====  ==========================================================
offset      type  field
==========  ====  ==========================================================
0           6 B   ``"MXTP"`` + two ASCII digits: message type (``02`` = quaternion pose)
6           u32   sample counter (one per frame; every datagram of a frame repeats it)
10          u8    datagram counter: bits 0-6 index in the frame, bit 7 = last datagram
11          u8    number of items in this datagram
12          u32   time code, ms
16          u8    character (avatar) id
17          u8    body segment count
18          u8    prop count
19          u8    finger tracking segment count
20          2 B   reserved
22          u16   payload size in bytes
24          ...   payload
==========  ====  ==========================================================

Type 02 items, 32 bytes each: segment id i32, position x y z f32 (metres), orientation
quaternion **w x y z** f32 (global, segment -> world).  Body segments have ids 1..23
(:data:`SEGMENT_NAMES`), props and finger segments follow.  A frame may span several
datagrams (same sample counter; the last one carries bit 7); several characters arrive as
separate packets, selected by ``character``.  Types 12 (meta data: ``key:value`` lines),
13 (segment scaling), 24 (centre of mass) and 25 (SMPTE time code) are parsed into
:class:`MvnAssembler` attributes; other types (01 Euler, 03 points, 20-23 kinematics) are
counted in ``skipped_types`` and ignored; nothing is fatal.

Frame conventions at this boundary
----------------------------------
MVN's world is right-handed **Z-up** (X forward at calibration, Y left).  rtseg's is
right-handed **Y-up**: the cyclic relabelling (x, y, z)_mvn -> (y, z, x) maps one onto the
other (a rotation, no mirror): position ``(x, y, z) -> (y, z, x)``, quaternion
``(w, x, y, z) -> (y, z, x, w)`` (scalar-last).  :func:`encode_datagrams` applies the
inverse, so encode -> decode is exact to float32.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from rtseg.drivers.base import SourceStats
from rtseg.frame import Frame

log = logging.getLogger("rtseg.drivers.mvn")

DEFAULT_PORT = 9763
MAGIC = b"MXTP"
HEADER = struct.Struct(">6sIBBIBBBB2xH")
HEADER_SIZE = HEADER.size                     # 24
ITEM_02 = np.dtype([("id", ">i4"), ("pos", ">f4", (3,)), ("quat", ">f4", (4,))])
ITEM_SIZE = ITEM_02.itemsize                  # 32
#: UDP payload limit that avoids IP fragmentation on Ethernet (1500 - 20 - 8)
DEFAULT_MAX_DATAGRAM = 1472
LAST_FLAG = 0x80
#: | |q|^2 - 1 | up to which a quaternion is passed on unchanged (float32 rounding of a unit
#: quaternion stays far below); accepted ones further off are renormalised
UNIT_EXACT = 1e-6
#: columns of a type-02 item read as 8 float32 (id, px, py, pz, qw, qx, qy, qz) that give
#: rtseg's quaternion (y, z, x, w) and position (y, z, x)
_QCOLS = [6, 7, 5, 4]
_PCOLS = [2, 3, 1]

#: Body segment names of MVN, segment id = index + 1.
SEGMENT_NAMES: tuple[str, ...] = (
    "Pelvis", "L5", "L3", "T12", "T8", "Neck", "Head",
    "Right Shoulder", "Right Upper Arm", "Right Forearm", "Right Hand",
    "Left Shoulder", "Left Upper Arm", "Left Forearm", "Left Hand",
    "Right Upper Leg", "Right Lower Leg", "Right Foot", "Right Toe",
    "Left Upper Leg", "Left Lower Leg", "Left Foot", "Left Toe",
)
BODY_SEGMENTS = len(SEGMENT_NAMES)            # 23
#: MVN hierarchy: parent segment id of each body segment id (0 = root)
SEGMENT_PARENTS: dict[int, int] = {
    1: 0, 2: 1, 3: 2, 4: 3, 5: 4, 6: 5, 7: 6,
    8: 5, 9: 8, 10: 9, 11: 10, 12: 5, 13: 12, 14: 13, 15: 14,
    16: 1, 17: 16, 18: 17, 19: 18, 20: 1, 21: 20, 22: 21, 23: 22,
}
KNOWN_TYPES = {"01": "euler pose", "02": "quaternion pose", "03": "point positions",
               "12": "meta data", "13": "scaling", "20": "joint angles",
               "21": "linear segment kinematics", "22": "angular segment kinematics",
               "23": "motion tracker kinematics", "24": "centre of mass", "25": "time code"}


class MvnParseError(ValueError):
    """Malformed MXTP bytes (short header, bad magic, sizes that overrun the datagram)."""


@dataclass(slots=True)
class MxtpHeader:
    """The 24-byte header.  ``index``: datagram index in the frame; ``last``: bit 7."""
    msg_type: str
    sample: int
    index: int
    last: bool
    items: int
    time_ms: int
    character: int
    body_segments: int
    props: int
    finger_segments: int
    payload_size: int


def parse_header(data: bytes) -> MxtpHeader:
    """Header of one datagram; raises :class:`MvnParseError`."""
    if len(data) < HEADER_SIZE:
        raise MvnParseError(f"datagram of {len(data)} bytes is shorter than the 24-byte header")
    (ident, sample, dgram, items, time_ms, char, body, props, fingers,
     size) = HEADER.unpack_from(data)
    if ident[:4] != MAGIC or not ident[4:6].isdigit():
        raise MvnParseError(f"not an MXTP datagram (starts {bytes(data[:6])!r})")
    if size > len(data) - HEADER_SIZE:
        raise MvnParseError(f"payload size {size} overruns the {len(data)}-byte datagram")
    return MxtpHeader(ident[4:6].decode("ascii"), sample, dgram & 0x7F, bool(dgram & LAST_FLAG),
                      items, time_ms, char, body, props, fingers, size)


def payload_of(data: bytes, hdr: MxtpHeader) -> memoryview:
    """The payload bytes.  A payload size of 0 with data present (some senders leave it
    unset) means 'the rest of the datagram'."""
    end = HEADER_SIZE + (hdr.payload_size or (len(data) - HEADER_SIZE))
    return memoryview(data)[HEADER_SIZE:end]


def parse_pose(data: bytes, hdr: MxtpHeader) -> np.ndarray:
    """Type-02 items as a structured array (fields ``id``, ``pos`` (3,), ``quat`` (4,)
    w x y z, MVN frame, big-endian float32).  Raises :class:`MvnParseError` when the items
    do not fit the payload."""
    payload = payload_of(data, hdr)
    need = hdr.items * ITEM_SIZE
    if need > len(payload):
        raise MvnParseError(f"{hdr.items} pose items need {need} bytes, payload has {len(payload)}")
    return np.frombuffer(payload, dtype=ITEM_02, count=hdr.items)


def parse_meta(payload: bytes) -> dict[str, str]:
    """Type-12 meta data: ``key:value`` lines (``name``, ``xmid``, ``color`` ...).  A
    leading u32 string length, as some receivers read it, is honoured when it fits."""
    raw = bytes(payload)
    if len(raw) >= 4:
        n = int.from_bytes(raw[:4], "big")
        if 0 < n <= len(raw) - 4:
            raw = raw[4:4 + n]
    out: dict[str, str] = {}
    for line in raw.decode("utf-8", errors="replace").replace("\r", "\n").split("\n"):
        key, sep, value = line.partition(":")
        if sep and key.strip():
            out[key.strip()] = value.strip().rstrip("\x00")
    return out


def parse_scaling(payload: bytes) -> dict[str, tuple[float, float, float]]:
    """Type-13 segment scaling (null pose): u32 segment count, then per segment a u32 name
    length, the name and a position x y z f32 (MVN frame).  Returns what parsed before any
    truncation (never raises)."""
    raw = bytes(payload)
    out: dict[str, tuple[float, float, float]] = {}
    if len(raw) < 4:
        return out
    count = int.from_bytes(raw[:4], "big")
    pos = 4
    for _ in range(min(count, 4096)):
        if pos + 4 > len(raw):
            break
        n = int.from_bytes(raw[pos:pos + 4], "big")
        if n > 1024 or pos + 4 + n + 12 > len(raw):
            break
        name = raw[pos + 4:pos + 4 + n].decode("utf-8", errors="replace")
        xyz = struct.unpack_from(">3f", raw, pos + 4 + n)
        out[name] = xyz
        pos += 4 + n + 12
    return out


# --------------------------------------------------------------------------- encoder

def to_mvn_quat(q: np.ndarray) -> np.ndarray:
    """rtseg scalar-last Y-up (x, y, z, w) -> MVN Z-up (w, x, y, z)."""
    q = np.asarray(q)
    return np.stack([q[..., 3], q[..., 2], q[..., 0], q[..., 1]], axis=-1)


def from_mvn_quat(q: np.ndarray) -> np.ndarray:
    """MVN Z-up (w, x, y, z) -> rtseg scalar-last Y-up (x, y, z, w) = (y, z, x, w)."""
    q = np.asarray(q)
    return np.stack([q[..., 2], q[..., 3], q[..., 1], q[..., 0]], axis=-1)


def to_mvn_pos(p: np.ndarray) -> np.ndarray:
    """rtseg (x, y, z) Y-up -> MVN (z, x, y) Z-up."""
    p = np.asarray(p)
    return np.stack([p[..., 2], p[..., 0], p[..., 1]], axis=-1)


def from_mvn_pos(p: np.ndarray) -> np.ndarray:
    """MVN (x, y, z) Z-up -> rtseg (y, z, x) Y-up."""
    p = np.asarray(p)
    return np.stack([p[..., 1], p[..., 2], p[..., 0]], axis=-1)


def encode_header(msg_type: str, sample: int, index: int, last: bool, items: int,
                  time_ms: int, character: int, body: int, props: int, fingers: int,
                  payload_size: int) -> bytes:
    return HEADER.pack(MAGIC + msg_type.encode("ascii"), sample & 0xFFFFFFFF,
                       (index & 0x7F) | (LAST_FLAG if last else 0), items, time_ms & 0xFFFFFFFF,
                       character, body, props, fingers, payload_size)


def encode_datagrams(sample: int, time_ms: int, segment_ids: Sequence[int],
                     quats: np.ndarray, positions: np.ndarray | None = None, *,
                     character: int = 0, body_segments: int = BODY_SEGMENTS,
                     props: int = 0, finger_segments: int = 0,
                     max_datagram: int = DEFAULT_MAX_DATAGRAM) -> list[bytes]:
    """One frame as type-02 datagrams of at most ``max_datagram`` bytes.

    ``quats`` (n, 4) global orientations in rtseg's frame (scalar-last, Y-up);
    ``positions`` (n, 3) metres, rtseg frame (default zeros).  Values go out as float32."""
    q = np.asarray(quats, dtype=np.float64)
    n = len(segment_ids)
    if q.shape != (n, 4):
        raise ValueError(f"quats must be ({n}, 4), got {q.shape}")
    per = min(255, (max_datagram - HEADER_SIZE) // ITEM_SIZE)   # items per datagram (u8)
    if per < 1:
        raise ValueError(f"max_datagram {max_datagram} cannot hold one {ITEM_SIZE}-byte item")
    items = np.zeros(n, dtype=ITEM_02)
    items["id"] = np.asarray(segment_ids, dtype=np.int64)
    items["quat"] = to_mvn_quat(q)
    if positions is not None:
        items["pos"] = to_mvn_pos(np.asarray(positions, dtype=np.float64))
    chunks = [items[a:a + per] for a in range(0, max(n, 1), per)] if n else [items[:0]]
    if len(chunks) > 0x80:
        raise ValueError(f"{n} items need {len(chunks)} datagrams; at most 128 per frame")
    out = []
    for k, chunk in enumerate(chunks):
        body = chunk.tobytes()
        out.append(encode_header("02", sample, k, k == len(chunks) - 1, len(chunk), time_ms,
                                 character, body_segments, props, finger_segments, len(body))
                   + body)
    return out


def encode_message(msg_type: str, payload: bytes, *, sample: int = 0, time_ms: int = 0,
                   character: int = 0, items: int = 0) -> bytes:
    """A single-datagram message of any type (meta 12, scaling 13, 24, 25 ...)."""
    return encode_header(msg_type, sample, 0, True, items, time_ms, character, BODY_SEGMENTS,
                         0, 0, len(payload)) + payload


# --------------------------------------------------------------------------- assembler

@dataclass
class _Partial:
    """A frame being reassembled: datagrams by index, the index of the last one."""
    sample: int
    time_ms: int
    first_seen: float
    parts: dict[int, np.ndarray] = field(default_factory=dict)
    last_index: int | None = None

    def complete(self) -> bool:
        return self.last_index is not None and len(self.parts) == self.last_index + 1 and \
            all(i in self.parts for i in range(self.last_index + 1))


class MvnAssembler:
    """Rebuild frames of one character from a stream of MXTP datagrams.

    ``segment_ids[k]``: the MVN segment id carried by output joint k (a suit profile's
    sensor ids).  ``character``: the character id kept (others are counted in
    ``other_characters`` and ignored).  A frame is emitted when all its datagrams (indices
    0..last) have arrived, when a datagram of a newer sample arrives (the open frame is
    emitted with what it holds: missing segments ``valid`` False), or by :meth:`flush`
    ``quiet`` seconds after its first datagram.  A datagram of a sample at most
    ``LATE_WINDOW`` (64) samples older than the newest seen, or of the sample last emitted, is
    late: counted in ``dropped`` and discarded; one further back is taken as the sender
    restarting its counter and starts a new frame.

    Per frame: ``quats`` (J, 4) rtseg frame, global; segments not received hold their last
    value with ``valid`` False; ``seq`` = sample counter; ``source_time`` = time code / 1000
    (s); ``root_position`` = position of the first joint (the pelvis), metres, rtseg frame.
    Quaternions with | |q|^2 - 1 | > ``unit_tolerance`` or non-finite values are counted
    in ``bad_values`` and marked invalid; accepted ones more than ``UNIT_EXACT`` off unit
    are renormalised.  ``continuous``: flip signs so each joint's dot with its previous
    value is >= 0.  :meth:`feed` never raises on any input.
    """

    def __init__(self, segment_ids: Sequence[int], *, character: int = 0,
                 quiet: float = 0.02, unit_tolerance: float = 0.05, continuous: bool = True,
                 stats: SourceStats | None = None) -> None:
        ids = [int(s) for s in segment_ids]
        if not ids or len(set(ids)) != len(ids) or not all(0 <= s < 1 << 16 for s in ids):
            raise ValueError(f"segment ids must be distinct, 0..65535, got {ids}")
        self.segment_ids = ids
        self.n = len(ids)
        self.character = int(character)
        self.quiet = float(quiet)
        self.unit_tolerance = float(unit_tolerance)
        self.continuous = continuous
        self.stats = stats if stats is not None else SourceStats()
        size = max(ids) + 1
        self._lut = np.full(max(size, 256), -1, dtype=np.int64)
        self._lut[ids] = np.arange(self.n)
        self._q = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (self.n, 1))
        #: the suit's ids in order, as they arrive when a sender sends exactly the suit
        self._ids_bytes = np.array(ids, dtype=">i4").tobytes()
        self._all_valid = np.ones(self.n, dtype=bool)
        self._open: _Partial | None = None
        self._last_sample: int | None = None
        self._root_row = 0
        self._warned: set[str] = set()
        #: datagrams of other characters seen (ignored), per character id
        self.other_characters: dict[int, int] = {}
        #: datagrams of types not decoded (01, 03, 20-23, unknown), per type
        self.skipped_types: dict[str, int] = {}
        #: latest type-12 meta data of the selected character (``name``, ``xmid`` ...)
        self.meta: dict[str, str] = {}
        #: latest type-13 scaling: segment name -> null-pose position (rtseg frame, m)
        self.scaling: dict[str, tuple[float, float, float]] = {}
        #: latest type-24 centre of mass (rtseg frame, m) or None
        self.center_of_mass: tuple[float, float, float] | None = None
        #: latest type-25 time code text (``HH:MM:SS.mmm``) or None
        self.timecode: str | None = None
        #: frames emitted before all their datagrams arrived (missing segments invalid)
        self.incomplete_frames = 0
        #: characters seen (any type), to list in error messages
        self.characters_seen: set[int] = set()

    # -- public

    def feed(self, data: bytes, now: float) -> list[Frame]:
        """One datagram received at ``now`` (monotonic s) -> frames it completes."""
        out: list[Frame] = []
        try:
            hdr = parse_header(data)
        except MvnParseError as exc:
            self._count("corrupt", str(exc))
            return out
        self.characters_seen.add(hdr.character)
        if hdr.character != self.character:
            self.other_characters[hdr.character] = self.other_characters.get(hdr.character, 0) + 1
            return out
        t = hdr.msg_type
        if t == "02":
            try:
                items = parse_pose(data, hdr)
            except MvnParseError as exc:
                self._count("corrupt", str(exc))
                return out
            self._pose(hdr, items, now, out)
        elif t in ("12", "13", "24", "25"):
            self._other(t, payload_of(data, hdr))
        else:
            self.skipped_types[t] = self.skipped_types.get(t, 0) + 1
        return out

    def flush(self, now: float, force: bool = False) -> list[Frame]:
        """Emit the open frame if ``quiet`` seconds passed since its first datagram (or
        ``force``)."""
        p = self._open
        if p is not None and (force or now - p.first_seen >= self.quiet):
            self._open = None
            return [self._emit(p, now)]
        return []

    # -- internals

    def _count(self, what: str, message: str) -> None:
        setattr(self.stats, what, getattr(self.stats, what) + 1)
        if what not in self._warned:
            self._warned.add(what)
            log.warning("MVN: %s (further ones counted in %s, not logged)", message, what)

    def _pose(self, hdr: MxtpHeader, items: np.ndarray, now: float, out: list[Frame]) -> None:
        last = self._last_sample
        p = self._open
        newest = p.sample if p is not None else last
        if newest is not None and (_older(hdr.sample, newest) or
                                   (p is None and hdr.sample == last)):
            self._count("dropped", f"datagram of sample {hdr.sample} arrived after sample "
                        f"{newest} (late or repeated); dropped")
            return
        if p is not None and p.sample != hdr.sample:      # a newer sample: close the open one
            self._open = None
            out.append(self._emit(p, now))
            p = None
        if p is None:
            p = self._open = _Partial(hdr.sample, hdr.time_ms, now)
        if hdr.index in p.parts:
            self._count("bad_messages", f"datagram {hdr.index} of sample {hdr.sample} repeated")
            return
        p.parts[hdr.index] = items
        if hdr.last:
            p.last_index = hdr.index
        if p.complete():
            self._open = None
            out.append(self._emit(p, now))

    def _emit(self, p: _Partial, now: float) -> Frame:
        if not p.complete():                  # delivered with the segments it holds
            self.incomplete_frames += 1
            if "incomplete" not in self._warned:
                self._warned.add("incomplete")
                log.warning("MVN: frame of sample %d closed with datagrams missing (have %s); "
                            "its missing segments are marked invalid (further ones counted in "
                            ".incomplete_frames)", p.sample, sorted(p.parts))
        self._last_sample = p.sample
        parts = [p.parts[i] for i in sorted(p.parts)] if len(p.parts) > 1 else \
            list(p.parts.values())
        # (np.concatenate would convert to native byte order; joining bytes keeps it)
        items = parts[0] if len(parts) == 1 else \
            np.frombuffer(b"".join(x.tobytes() for x in parts), dtype=ITEM_02)
        fast = self._emit_fast(items, p, now)
        if fast is not None:
            return fast
        ids = items["id"].astype(np.int64)
        ok = (ids >= 0) & (ids < len(self._lut))
        rows = np.full(len(ids), -1, dtype=np.int64)
        rows[ok] = self._lut[ids[ok]]
        keep = rows >= 0
        valid = np.zeros(self.n, dtype=bool)
        q = self._q.copy()
        root = None
        if keep.any():
            rows = rows[keep]
            with np.errstate(invalid="ignore"):       # signalling NaNs are refused below
                raw = items["quat"][keep].astype(np.float64)
            qq = from_mvn_quat(raw)
            norm2 = np.einsum("ij,ij->i", qq, qq)
            good = np.isfinite(norm2) & (np.abs(norm2 - 1.0) <= self.unit_tolerance)
            if not good.all():
                self.stats.bad_values += int((~good).sum())
                if "bad_values" not in self._warned:
                    self._warned.add("bad_values")
                    log.warning("MVN: non-unit or non-finite quaternion refused (further ones "
                                "counted in bad_values, not logged)")
                rows, qq, norm2 = rows[good], qq[good], norm2[good]
                sel_pos = items["pos"][keep][good]
            else:
                sel_pos = items["pos"][keep]
            off = np.abs(norm2 - 1.0) > UNIT_EXACT     # accepted but not unit: renormalise
            if off.any():
                qq[off] /= np.sqrt(norm2[off])[:, None]
            if self.continuous:
                prev = self._q[rows]
                flip = np.einsum("ij,ij->i", qq, prev) < 0
                qq[flip] *= -1.0
            q[rows] = qq
            valid[rows] = True
            hit = np.flatnonzero(rows == self._root_row)
            if hit.size:
                pos = sel_pos[hit[0]].astype(np.float64)
                if np.isfinite(pos).all():
                    root = from_mvn_pos(pos)
        self._q = q
        return Frame(recv_time=now, quats=q, valid=valid, source_time=p.time_ms / 1000.0,
                     seq=p.sample, root_position=root)

    def _emit_fast(self, items: np.ndarray, p: _Partial, now: float) -> Frame | None:
        """The common case in few numpy operations: exactly the suit's segments, in suit
        order, all finite and unit.  None: use the general path (same result)."""
        if len(items) != self.n or items["id"].tobytes() != self._ids_bytes:
            return None
        with np.errstate(invalid="ignore"):
            raw = items.view(">f4").astype(np.float64).reshape(self.n, 8)
        q = raw[:, _QCOLS]                           # (w, x, y, z) MVN -> (y, z, x, w)
        if not np.abs(np.einsum("ij,ij->i", q, q) - 1.0).max() <= UNIT_EXACT:
            return None                              # NaN fails the comparison too
        if self.continuous:
            dots = np.einsum("ij,ij->i", q, self._q)
            if dots.min() < 0:
                q[dots < 0] *= -1.0
        self._q = q
        pos = raw[self._root_row, _PCOLS]
        return Frame(recv_time=now, quats=q, valid=self._all_valid.copy(),
                     source_time=p.time_ms / 1000.0, seq=p.sample,
                     root_position=pos if np.isfinite(pos).all() else None)

    def _other(self, t: str, payload: memoryview) -> None:
        if t == "12":
            self.meta.update(parse_meta(payload))
        elif t == "13":
            sc = parse_scaling(payload)
            self.scaling = {k: tuple(from_mvn_pos(np.array(v)).tolist()) for k, v in sc.items()}
        elif t == "24":
            if len(payload) >= 12:
                xyz = np.array(struct.unpack_from(">3f", payload), dtype=np.float64)
                if np.isfinite(xyz).all():
                    self.center_of_mass = tuple(from_mvn_pos(xyz).tolist())
                else:
                    self._count("bad_values", "non-finite centre of mass")
            else:
                self._count("bad_messages", f"centre-of-mass payload of {len(payload)} bytes")
        elif t == "25":
            text = bytes(payload).split(b"\x00", 1)[0].decode("ascii", errors="replace")
            self.timecode = text.strip() or None


#: a sample this many or fewer counts behind the newest is late; further back is taken as
#: a restart of the sender's counter (accepted), so one bad counter cannot block the stream
LATE_WINDOW = 64


def _older(a: int, b: int) -> bool:
    """Sample counter ``a`` is shortly before ``b`` (u32, wrapping; within LATE_WINDOW)."""
    d = (b - a) & 0xFFFFFFFF
    return 0 < d <= LATE_WINDOW


def segment_parent_ids(ids: Sequence[int]) -> list[int]:
    """Parent indices (into ``ids``) from MVN's body hierarchy; -1 when the parent segment
    is not among ``ids``."""
    where = {s: k for k, s in enumerate(ids)}
    return [where.get(SEGMENT_PARENTS.get(s, 0), -1) for s in ids]


__all__ = ["MvnAssembler", "MvnParseError", "MxtpHeader", "parse_header", "parse_pose", "payload_of",
           "parse_meta", "parse_scaling", "encode_datagrams", "encode_message",
           "encode_header", "SEGMENT_NAMES", "SEGMENT_PARENTS", "DEFAULT_PORT",
           "from_mvn_quat", "to_mvn_quat", "from_mvn_pos", "to_mvn_pos"]
