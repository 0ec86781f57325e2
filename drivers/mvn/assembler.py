"""Xsens MVN: MXTP messages -> rtseg frames of one character (:class:`MvnAssembler`).

The wire format (header, type-02 items, frame conventions) is in
:mod:`rtseg.drivers.mvn.codec`; this module rebuilds frames from messages, whatever
carried them (UDP datagrams, or the messages a TCP stream is cut into by
:class:`rtseg.drivers.mvn.codec.MxtpStream`).  Pure bytes -> frames, no sockets.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from rtseg.drivers.base import SourceStats
from rtseg.drivers.mvn.codec import (ITEM_02, UNIT_EXACT, MvnParseError, MxtpHeader,
                                     _PCOLS, _QCOLS, from_mvn_pos, from_mvn_quat,
                                     parse_header, parse_meta, parse_pose, parse_scaling,
                                     payload_of)
from rtseg.drivers.vendor_seq import SeqGaps
from rtseg.core.frame import Frame

log = logging.getLogger("rtseg.drivers.mvn")

__all__ = ["MvnAssembler", "LATE_WINDOW"]


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
    late: counted in ``bad_messages`` (nothing is lost: its sample was emitted, whole or
    with that datagram's segments invalid) and discarded; one further back is taken as the
    sender restarting its counter and starts a new frame.

    Per frame: ``quats`` (J, 4) rtseg frame, global; segments not received hold their last
    value with ``valid`` False (a sample counter that jumps forward adds 1 to
    ``stats.gaps`` and the samples skipped to ``stats.dropped``; a jump the receive clock
    cannot explain, or backwards, is a damaged or restarted counter: 1 in
    ``stats.counter_jumps``, nothing in ``dropped``, ``seq`` = the last trusted counter + 1,
    :class:`rtseg.drivers.vendor_seq.SeqGaps`); ``seq`` = sample counter; ``source_time`` =
    time code / 1000 (s); ``root_position`` = position of the first joint (the pelvis),
    metres, rtseg frame.  Quaternions with | |q|^2 - 1 | > ``unit_tolerance`` or
    non-finite values are counted in ``bad_values`` and marked invalid; accepted ones more
    than ``UNIT_EXACT`` off unit are renormalised.  ``continuous``: flip signs so each
    joint's dot with its previous value is >= 0.  :meth:`feed` never raises on any input.
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
        #: (positions (n, 3) m, orientations (n, 4)) of the first frame with every segment
        #: valid, rtseg frame, suit order: the rig geometry the source's ``rest_pose``
        #: works out; None before
        self.first_pose: tuple[np.ndarray, np.ndarray] | None = None
        #: latest type-24 centre of mass (rtseg frame, m) or None
        self.center_of_mass: tuple[float, float, float] | None = None
        #: latest type-25 time code text (``HH:MM:SS.mmm``) or None
        self.timecode: str | None = None
        #: frames emitted before all their datagrams arrived (missing segments invalid)
        self.incomplete_frames = 0
        #: characters seen (any type), to list in error messages
        self.characters_seen: set[int] = set()
        self._gaps = SeqGaps(32, name="MVN", counter="sample counter", logger=log)

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
            self._count("bad_messages", f"datagram of sample {hdr.sample} arrived after "
                        f"sample {newest} (late or repeated); dropped")
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
        step = self._gaps.step(p.sample, now)
        if step.jumps:                         # damaged or restarted (SeqGaps logs)
            self.stats.counter_jumps += step.jumps
        missing, seq = step.missing, step.seq
        if missing:                            # whole frames the sender numbered, lost
            self.stats.gaps += 1
            self.stats.dropped += missing
            if "gap" not in self._warned:
                self._warned.add("gap")
                log.warning("MVN: %d frame(s) missing before sample %d (further gaps "
                            "counted in gaps / dropped, not logged)", missing, p.sample)
        parts = [p.parts[i] for i in sorted(p.parts)] if len(p.parts) > 1 else \
            list(p.parts.values())
        # (np.concatenate would convert to native byte order; joining bytes keeps it)
        items = parts[0] if len(parts) == 1 else \
            np.frombuffer(b"".join(x.tobytes() for x in parts), dtype=ITEM_02)
        fast = self._emit_fast(items, p, now, seq)
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
            if self.first_pose is None and valid.all():
                full = np.zeros((self.n, 3))
                full[rows] = from_mvn_pos(np.asarray(sel_pos, dtype=np.float64))
                self.first_pose = (full, q.copy())
        self._q = q
        return Frame(recv_time=now, quats=q, valid=valid, source_time=p.time_ms / 1000.0,
                     seq=seq, root_position=root)

    def _emit_fast(self, items: np.ndarray, p: _Partial, now: float, seq: int) -> Frame | None:
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
        if self.first_pose is None:
            self.first_pose = (raw[:, _PCOLS].copy(), q.copy())
        pos = raw[self._root_row, _PCOLS]
        return Frame(recv_time=now, quats=q, valid=self._all_valid.copy(),
                     source_time=p.time_ms / 1000.0, seq=seq,
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
