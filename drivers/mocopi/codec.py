"""Sony mocopi UDP stream ("sony motion format"): the wire format (parser, encoder).

Frames are built from packets by
:class:`rtseg.drivers.mocopi.assembler.MocopiAssembler` (also importable from
here).  Pure bytes, no sockets (see :mod:`rtseg.drivers.mocopi.source`).

A datagram is a sequence of little-endian fields ``u32 length | 4-char tag | value``;
some values are themselves fields (nested).  Per the Sony receiver plugin
(sony/mocopi-receiver-plugin-blender ``models.py``), the unofficial protocol notes of
seagetch/mcp-receiver (``doc/Protocol.md``) and t-34400/mocopi_protocol_supplement (its
sample packets are test fixtures here)::

    head { ftyp "sony motion format", vrsn u8 }
    sndf { ipad 8 bytes, rcvp u16 (receiver port) }
    skdf { bons { bndt { bnid u16, pbid u16, tran 7 x f32 } x 27 } }     skeleton packet
    fram { fnum u32, time u32, [uttm f64], [tmcd ...], btrs { btdt { bnid u16,
           tran 7 x f32 } x 27 } }                                          frame packet

``tran`` = rotation qx qy qz qw then position px py pz (metres), **local to the parent
bone**, right-handed Y-up (the supplement's finding; the Sony plugin mirrors x to reach
Blender/Unity).  That is rtseg's frame already: quaternions pass through unchanged
(scalar-last).  The rest pose of the sample packets carries (0, 0, 0, -1): a sign-flipped
identity, the same rotation as (0, 0, 0, 1).  ``uttm`` (newer apps) is the sender's Unix
time in seconds; ``time`` is a u32 whose unit is not documented (kept raw).  Bone ids
0..26 = :data:`BONE_NAMES`; parents from ``pbid`` (65535 = none).

:class:`MocopiAssembler` turns each ``fram`` datagram into one frame; ``skdf`` updates
``skeleton``; nothing raises on bad input (counted in the stats instead).
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass
from typing import Iterator, Sequence

import numpy as np

log = logging.getLogger("rtseg.drivers.mocopi")

DEFAULT_PORT = 12351
FTYP = b"sony motion format"
#: mocopi bone ids 0..26
BONE_NAMES: tuple[str, ...] = (
    "root", "torso_1", "torso_2", "torso_3", "torso_4", "torso_5", "torso_6", "torso_7",
    "neck_1", "neck_2", "head",
    "l_shoulder", "l_up_arm", "l_low_arm", "l_hand",
    "r_shoulder", "r_up_arm", "r_low_arm", "r_hand",
    "l_up_leg", "l_low_leg", "l_foot", "l_toes",
    "r_up_leg", "r_low_leg", "r_foot", "r_toes",
)
#: parent bone id of each bone id (-1: root), as the mocopi skeleton packet gives them
BONE_PARENTS: tuple[int, ...] = (
    -1, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9,
    7, 11, 12, 13, 7, 15, 16, 17,
    0, 19, 20, 21, 0, 23, 24, 25,
)
NO_PARENT = 0xFFFF
#: | |q|^2 - 1 | up to which a rotation is passed on unchanged (float32 rounding of a unit
#: quaternion stays far below); accepted ones further off are renormalised
UNIT_EXACT = 1e-6
_FIELD = struct.Struct("<I4s")
_TRAN = struct.Struct("<7f")
#: one ``btdt`` record of a frame packet, header included (54 bytes)
BTDT = np.dtype([("len", "<u4"), ("tag", "S4"), ("id_len", "<u4"), ("id_tag", "S4"),
                 ("bnid", "<u2"), ("tr_len", "<u4"), ("tr_tag", "S4"), ("tran", "<f4", (7,))])
_MAX_DEPTH = 6


class MocopiParseError(ValueError):
    """Malformed mocopi bytes (a field overrunning its parent, a missing required field)."""


@dataclass(slots=True)
class MocopiFrame:
    """A decoded ``fram``.  ``bone_ids`` (n,) int; ``tran`` (n, 7) float32 qx qy qz qw px py
    pz; ``uttm`` Unix seconds or None; ``tmcd`` raw time-code bytes or None."""
    fnum: int
    time: int
    uttm: float | None
    tmcd: bytes | None
    bone_ids: np.ndarray
    tran: np.ndarray


@dataclass(slots=True)
class MocopiSkeleton:
    """A decoded ``skdf``: ``bone_ids``, ``parent_ids`` (-1: none) and rest ``tran``."""
    bone_ids: np.ndarray
    parent_ids: np.ndarray
    tran: np.ndarray


@dataclass(slots=True)
class MocopiPacket:
    """One datagram: ``ftyp``/``version`` from ``head``, ``port`` from ``sndf``, and a
    ``frame`` or a ``skeleton`` (or neither for an unknown kind)."""
    ftyp: bytes | None
    version: int | None
    port: int | None
    frame: MocopiFrame | None = None
    skeleton: MocopiSkeleton | None = None


def iter_fields(data: bytes, start: int, end: int) -> Iterator[tuple[bytes, int, int]]:
    """(tag, value start, value end) of each field in ``data[start:end]``; raises
    :class:`MocopiParseError` when a field overruns ``end``."""
    pos = start
    while pos < end:
        if pos + 8 > end:
            raise MocopiParseError(f"{end - pos} stray bytes at offset {pos}")
        length, tag = _FIELD.unpack_from(data, pos)
        vstart = pos + 8
        vend = vstart + length
        if vend > end:
            raise MocopiParseError(f"field {tag!r} at offset {pos} ({length} bytes) overruns "
                                   f"its container ending at {end}")
        yield tag, vstart, vend
        pos = vend


def _children(data: bytes, start: int, end: int) -> dict[bytes, tuple[int, int]]:
    out: dict[bytes, tuple[int, int]] = {}
    for tag, a, b in iter_fields(data, start, end):
        out.setdefault(tag, (a, b))
    return out


def _uint(data: bytes, a: int, b: int, what: str) -> int:
    if not 1 <= b - a <= 8:
        raise MocopiParseError(f"{what} has {b - a} bytes")
    return int.from_bytes(data[a:b], "little")


def _tran(data: bytes, a: int, b: int) -> tuple[float, ...]:
    if b - a != 28:
        raise MocopiParseError(f"tran has {b - a} bytes, expected 28")
    return _TRAN.unpack_from(data, a)


def _bones_generic(data: bytes, a: int, b: int, record: bytes, with_parent: bool):
    ids, pids, trans = [], [], []
    for tag, ra, rb in iter_fields(data, a, b):
        if tag != record:
            continue
        kids = _children(data, ra, rb)
        if b"bnid" not in kids or b"tran" not in kids:
            raise MocopiParseError(f"{record.decode()} without bnid or tran")
        ids.append(_uint(data, *kids[b"bnid"], "bnid"))
        if with_parent:
            if b"pbid" not in kids:
                raise MocopiParseError("bndt without pbid")
            pids.append(_uint(data, *kids[b"pbid"], "pbid"))
        trans.append(_tran(data, *kids[b"tran"]))
    tran = np.array(trans, dtype=np.float32).reshape(-1, 7)
    return np.array(ids, dtype=np.int64), np.array(pids, dtype=np.int64), tran


def _btrs(data: bytes, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Bone ids and tran of a ``btrs`` value: one vectorised read when every record has the
    standard layout (what mocopi sends), else field by field."""
    n, rem = divmod(b - a, BTDT.itemsize)
    if n and not rem:
        rec = np.frombuffer(data, dtype=BTDT, count=n, offset=a)
        if ((rec["len"] == 46).all() and (rec["tag"] == b"btdt").all()
                and (rec["id_len"] == 2).all() and (rec["id_tag"] == b"bnid").all()
                and (rec["tr_len"] == 28).all() and (rec["tr_tag"] == b"tran").all()):
            return rec["bnid"].astype(np.int64), rec["tran"]
    ids, _, tran = _bones_generic(data, a, b, b"btdt", False)
    return ids, tran


def parse_packet(data: bytes) -> MocopiPacket:
    """Decode one datagram; raises :class:`MocopiParseError` on malformed bytes."""
    top = _children(data, 0, len(data))
    ftyp = version = port = None
    if b"head" in top:
        head = _children(data, *top[b"head"])
        if b"ftyp" in head:
            ftyp = bytes(data[slice(*head[b"ftyp"])])
        if b"vrsn" in head:
            version = _uint(data, *head[b"vrsn"], "vrsn")
    if b"sndf" in top:
        sndf = _children(data, *top[b"sndf"])
        if b"rcvp" in sndf:
            port = _uint(data, *sndf[b"rcvp"], "rcvp")
    pkt = MocopiPacket(ftyp, version, port)
    if b"fram" in top:
        fr = _children(data, *top[b"fram"])
        for need in (b"fnum", b"btrs"):
            if need not in fr:
                raise MocopiParseError(f"fram without {need.decode()}")
        fnum = _uint(data, *fr[b"fnum"], "fnum")
        tm = _uint(data, *fr[b"time"], "time") if b"time" in fr else 0
        uttm = None
        if b"uttm" in fr:
            ua, ub = fr[b"uttm"]
            if ub - ua != 8:
                raise MocopiParseError(f"uttm has {ub - ua} bytes, expected 8")
            uttm = struct.unpack_from("<d", data, ua)[0]
        tmcd = bytes(data[slice(*fr[b"tmcd"])]) if b"tmcd" in fr else None
        ids, tran = _btrs(data, *fr[b"btrs"])
        pkt.frame = MocopiFrame(fnum, tm, uttm, tmcd, ids, tran)
    elif b"skdf" in top:
        sk = _children(data, *top[b"skdf"])
        if b"bons" not in sk:
            raise MocopiParseError("skdf without bons")
        ids, pids, tran = _bones_generic(data, *sk[b"bons"], b"bndt", True)
        pids = np.where(pids == NO_PARENT, -1, pids)
        pkt.skeleton = MocopiSkeleton(ids, pids, tran)
    return pkt


@dataclass(slots=True)
class FrameLayout:
    """Where the fields of a frame packet sit, learned from one parsed packet, so packets
    with the same structure decode with one comparison and a few slices.  ``check``: byte
    offsets of every field header, of ``ftyp``/``vrsn`` and of the bone ids; ``expect``
    their values."""
    size: int
    check: np.ndarray
    expect: np.ndarray
    fnum: tuple[int, int]
    time: tuple[int, int] | None
    uttm: int | None
    tmcd: tuple[int, int] | None
    btrs: int
    n: int
    bone_ids: np.ndarray

    def matches(self, data: bytes) -> bool:
        if len(data) != self.size:
            return False
        return bool(np.array_equal(np.frombuffer(data, np.uint8)[self.check], self.expect))

    def decode(self, data: bytes) -> MocopiFrame:
        a, b = self.fnum
        fnum = int.from_bytes(data[a:b], "little")
        tm = int.from_bytes(data[self.time[0]:self.time[1]], "little") if self.time else 0
        uttm = struct.unpack_from("<d", data, self.uttm)[0] if self.uttm is not None else None
        tmcd = bytes(data[self.tmcd[0]:self.tmcd[1]]) if self.tmcd else None
        rec = np.frombuffer(data, dtype=BTDT, count=self.n, offset=self.btrs)
        return MocopiFrame(fnum, tm, uttm, tmcd, self.bone_ids, rec["tran"])


def frame_layout(data: bytes) -> FrameLayout | None:
    """The layout of a frame packet whose bones use the standard 54-byte records, or None.
    Raises :class:`MocopiParseError` like :func:`parse_packet`."""
    check: list[int] = []

    def hdr(pos: int) -> None:
        check.extend(range(pos, pos + 8))

    top = {}
    for tag, a, b in iter_fields(data, 0, len(data)):
        hdr(a - 8)
        top.setdefault(tag, (a, b))
    if b"fram" not in top:
        return None
    for sect in (b"head", b"sndf"):
        if sect in top:
            for tag, a, b in iter_fields(data, *top[sect]):
                hdr(a - 8)
                if tag in (b"ftyp", b"vrsn"):
                    check.extend(range(a, b))
    fr: dict[bytes, tuple[int, int]] = {}
    for tag, a, b in iter_fields(data, *top[b"fram"]):
        hdr(a - 8)
        fr.setdefault(tag, (a, b))
    if b"fnum" not in fr or b"btrs" not in fr or not 1 <= fr[b"fnum"][1] - fr[b"fnum"][0] <= 8:
        return None
    if b"uttm" in fr and fr[b"uttm"][1] - fr[b"uttm"][0] != 8:
        return None
    if b"time" in fr and not 1 <= fr[b"time"][1] - fr[b"time"][0] <= 8:
        return None
    a, b = fr[b"btrs"]
    n, rem = divmod(b - a, BTDT.itemsize)
    if not n or rem:
        return None
    rec = np.frombuffer(data, dtype=BTDT, count=n, offset=a)
    if not ((rec["len"] == 46).all() and (rec["tag"] == b"btdt").all()
            and (rec["id_len"] == 2).all() and (rec["id_tag"] == b"bnid").all()
            and (rec["tr_len"] == 28).all() and (rec["tr_tag"] == b"tran").all()):
        return None
    starts = a + BTDT.itemsize * np.arange(n)
    rel = np.arange(26, dtype=np.int64)             # record headers and bone id bytes
    check.extend((starts[:, None] + rel[None, :]).ravel().tolist())
    idx = np.array(check, dtype=np.int64)
    return FrameLayout(len(data), idx, np.frombuffer(data, np.uint8)[idx].copy(), fr[b"fnum"],
                       fr.get(b"time"), fr[b"uttm"][0] if b"uttm" in fr else None,
                       fr.get(b"tmcd"), a, n, rec["bnid"].astype(np.int64))


# --------------------------------------------------------------------------- encoder

def field(tag: bytes, value: bytes) -> bytes:
    """One ``length | tag | value`` field."""
    return _FIELD.pack(len(value), tag) + value


def _head_sndf(port: int, ipad: bytes) -> bytes:
    return (field(b"head", field(b"ftyp", FTYP) + field(b"vrsn", b"\x01"))
            + field(b"sndf", field(b"ipad", ipad) + field(b"rcvp", struct.pack("<H", port))))


_IPAD = bytes(8)


def encode_frame(fnum: int, quats: np.ndarray, positions: np.ndarray | None = None, *,
                 bone_ids: Sequence[int] | None = None, time: int = 0,
                 uttm: float | None = None, port: int = DEFAULT_PORT,
                 ipad: bytes = _IPAD) -> bytes:
    """A ``fram`` datagram.  ``quats`` (n, 4) local rotations, scalar-last, rtseg frame (=
    mocopi's); ``positions`` (n, 3) local positions in metres (default zeros);
    ``bone_ids`` default 0..n-1; ``time`` u32; ``uttm`` Unix seconds (omitted if None)."""
    q = np.asarray(quats, dtype=np.float64)
    n = q.shape[0]
    ids = np.arange(n) if bone_ids is None else np.asarray(bone_ids)
    if q.shape != (n, 4) or len(ids) != n:
        raise ValueError(f"quats must be (n, 4) with n bone ids, got {q.shape}, {len(ids)} ids")
    rec = np.zeros(n, dtype=BTDT)
    rec["len"], rec["tag"] = 46, b"btdt"
    rec["id_len"], rec["id_tag"], rec["bnid"] = 2, b"bnid", ids
    rec["tr_len"], rec["tr_tag"] = 28, b"tran"
    rec["tran"][:, :4] = q
    if positions is not None:
        rec["tran"][:, 4:] = np.asarray(positions, dtype=np.float64)
    body = (field(b"fnum", struct.pack("<I", fnum & 0xFFFFFFFF))
            + field(b"time", struct.pack("<I", int(time) & 0xFFFFFFFF)))
    if uttm is not None:
        body += field(b"uttm", struct.pack("<d", uttm))
    body += field(b"btrs", rec.tobytes())
    return _head_sndf(port, ipad) + field(b"fram", body)


def encode_skeleton(parent_ids: Sequence[int], rest: np.ndarray, *,
                    bone_ids: Sequence[int] | None = None, port: int = DEFAULT_PORT,
                    ipad: bytes = _IPAD) -> bytes:
    """A ``skdf`` datagram: ``rest`` (n, 7) qx qy qz qw px py pz per bone, parents -1 ->
    65535."""
    rest = np.asarray(rest, dtype=np.float32)
    ids = range(len(parent_ids)) if bone_ids is None else bone_ids
    recs = b"".join(
        field(b"bndt", field(b"bnid", struct.pack("<H", int(i)))
              + field(b"pbid", struct.pack("<H", NO_PARENT if p < 0 else int(p)))
              + field(b"tran", rest[k].astype("<f4").tobytes()))
        for k, (i, p) in enumerate(zip(ids, parent_ids)))
    return _head_sndf(port, ipad) + field(b"skdf", field(b"bons", recs))


__all__ = ["MocopiParseError", "MocopiPacket", "MocopiFrame",
           "MocopiSkeleton", "parse_packet", "iter_fields", "encode_frame", "encode_skeleton",
           "field", "BONE_NAMES", "BONE_PARENTS", "DEFAULT_PORT", "FTYP"]
