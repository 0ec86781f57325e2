"""Sony mocopi: datagrams -> rtseg frames (:class:`MocopiAssembler`).

The wire format (nested ``length + tag`` records, ``fram`` / ``skdf`` packets, the learned
frame layout) is in :mod:`rtseg.drivers.mocopi.codec`; this module turns packets into
frames.  Pure bytes -> frames, no sockets.
"""

from __future__ import annotations

import logging
import math
import struct
from typing import Sequence

import numpy as np

from rtseg.drivers.base import SourceStats
from rtseg.drivers.mocopi.codec import (BONE_NAMES, FTYP, UNIT_EXACT, FrameLayout,
                                        MocopiFrame, MocopiParseError, MocopiSkeleton,
                                        frame_layout, parse_packet)
from rtseg.drivers.vendor_seq import SeqGaps
from rtseg.core.frame import Frame

log = logging.getLogger("rtseg.drivers.mocopi")

__all__ = ["MocopiAssembler"]


class MocopiAssembler:
    """Frames from mocopi datagrams: one ``fram`` datagram is one frame.

    ``bone_ids[k]``: mocopi bone id carried by output joint k (a suit profile's sensor
    ids).  Per frame: ``quats`` (J, 4) local rotations, scalar-last (bones absent from the
    packet hold their last value, ``valid`` False); ``seq`` = ``fnum``; ``source_time`` =
    ``uttm`` (Unix s) when sent, else None; ``root_position`` = bone ``root_id``'s ``tran``
    position (metres).  Non-finite or non-unit (| |q|^2 - 1 | > ``unit_tolerance``)
    rotations are counted in ``bad_values`` and marked invalid (accepted ones more than
    ``UNIT_EXACT`` off unit are renormalised); ``continuous`` flips signs
    for a non-negative dot with the previous value (so a sign-flipped identity is
    harmless).  A forward jump of ``fnum`` adds 1 to ``stats.gaps`` and the frames skipped
    to ``stats.dropped`` (:class:`rtseg.drivers.vendor_seq.SeqGaps`); a jump the receive
    clock cannot explain, or backwards, is a damaged or restarted ``fnum``: 1 in
    ``stats.counter_jumps``, nothing in ``dropped``, the frame delivered with ``seq`` = the
    last trusted ``fnum`` + 1.  ``skdf`` packets set ``skeleton``; a ``head.ftyp`` other than
    ``"sony motion format"`` is counted in ``bad_messages``.  :meth:`feed` never raises.
    """

    def __init__(self, bone_ids: Sequence[int] = tuple(range(len(BONE_NAMES))), *,
                 unit_tolerance: float = 0.05, continuous: bool = True, root_id: int = 0,
                 stats: SourceStats | None = None, fast: bool = True) -> None:
        ids = [int(b) for b in bone_ids]
        if not ids or len(set(ids)) != len(ids) or not all(0 <= b < 1 << 16 for b in ids):
            raise ValueError(f"bone ids must be distinct, 0..65535, got {ids}")
        self.bone_ids = ids
        self._ids_arr = np.array(ids, dtype=np.int64)
        self.n = len(ids)
        self.unit_tolerance = float(unit_tolerance)
        self.continuous = continuous
        self.stats = stats if stats is not None else SourceStats()
        self._lut = np.full(1 << 16, -1, dtype=np.int64)
        self._lut[ids] = np.arange(self.n)
        self._root_row = int(self._lut[root_id]) if 0 <= root_id < 1 << 16 else -1
        self._q = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (self.n, 1))
        self._warned: set[str] = set()
        #: last skeleton definition received (``skdf``) or None
        self.skeleton: MocopiSkeleton | None = None
        #: last frame's raw fields (fnum, time, uttm, tmcd) or None
        self.last_frame: MocopiFrame | None = None
        self.fast = fast
        self._layout: FrameLayout | None = None
        self._all_valid = np.ones(self.n, dtype=bool)
        #: frames decoded through a learned layout (diagnostics)
        self.fast_frames = 0
        self._gaps = SeqGaps(32, name="mocopi", counter="fnum", logger=log)

    def _count(self, what: str, n: int, message: str) -> None:
        setattr(self.stats, what, getattr(self.stats, what) + n)
        if what not in self._warned:
            self._warned.add(what)
            log.warning("mocopi: %s (further ones counted in %s, not logged)", message, what)

    def feed(self, data: bytes, now: float) -> list[Frame]:
        """One datagram received at ``now`` (monotonic s) -> [frame] or []."""
        if len(data) < 8:
            self._count("corrupt", 1, f"datagram of {len(data)} bytes holds no field")
            return []
        lay = self._layout
        if lay is not None and lay.matches(data):
            self.fast_frames += 1
            return self._frame(lay.decode(data), now)
        try:
            pkt = parse_packet(data)
            if self.fast and pkt.frame is not None and pkt.ftyp in (None, FTYP):
                self._layout = frame_layout(data)
        except (MocopiParseError, struct.error, ValueError) as exc:
            self._count("corrupt", 1, f"datagram of {len(data)} bytes refused: {exc}")
            return []
        if pkt.ftyp is not None and pkt.ftyp != FTYP:
            self._count("bad_messages", 1, f"unknown format {pkt.ftyp[:32]!r}")
            return []
        if pkt.skeleton is not None:
            self.skeleton = pkt.skeleton
            return []
        if pkt.frame is None:
            self._count("bad_messages", 1, "datagram with neither fram nor skdf")
            return []
        return self._frame(pkt.frame, now)

    def flush(self, now: float, force: bool = False) -> list[Frame]:
        """Nothing to flush: each datagram is a whole frame."""
        return []

    def _frame(self, fr: MocopiFrame, now: float) -> list[Frame]:
        """[the frame of ``fr``], or [] for a frame repeated or reordered on the way."""
        step = self._gaps.step(fr.fnum, now)
        if step.late:
            self._count("bad_messages", 1, f"frame fnum {fr.fnum} repeated or late (after "
                        f"fnum {self._gaps.last}): dropped")
            return []
        self.last_frame = fr
        if step.jumps:                                # damaged or restarted (SeqGaps logs)
            self.stats.counter_jumps += step.jumps
        missing = step.missing
        if missing:                                   # frames the sender numbered, lost
            self.stats.gaps += 1
            self._count("dropped", missing, f"{missing} frame(s) missing before fnum "
                        f"{fr.fnum} (gaps also counted in gaps)")
        seq = step.seq
        fast = self._frame_fast(fr, now, seq)
        if fast is not None:
            return [fast]
        ids = fr.bone_ids
        ok = (ids >= 0) & (ids < len(self._lut))
        rows = np.full(len(ids), -1, dtype=np.int64)
        rows[ok] = self._lut[ids[ok]]
        keep = rows >= 0
        if not ok.all():
            self._count("unknown_names", int((~ok).sum()), "bone id out of range")
        rows = rows[keep]
        with np.errstate(invalid="ignore"):           # signalling NaNs are refused below
            tran = fr.tran[keep].astype(np.float64)
        qq = tran[:, :4]
        norm2 = np.einsum("ij,ij->i", qq, qq)
        good = np.isfinite(norm2) & (np.abs(norm2 - 1.0) <= self.unit_tolerance)
        if not good.all():
            self._count("bad_values", int((~good).sum()), "non-unit or non-finite rotation")
            rows, qq, tran, norm2 = rows[good], qq[good], tran[good], norm2[good]
        off = np.abs(norm2 - 1.0) > UNIT_EXACT         # accepted but not unit: renormalise
        if off.any():
            qq = qq.copy()
            qq[off] /= np.sqrt(norm2[off])[:, None]
        q = self._q.copy()
        if self.continuous and len(rows):
            flip = np.einsum("ij,ij->i", qq, self._q[rows]) < 0
            qq = np.where(flip[:, None], -qq, qq)
        q[rows] = qq
        valid = np.zeros(self.n, dtype=bool)
        valid[rows] = True
        self._q = q
        root = None
        hit = np.flatnonzero(rows == self._root_row)
        if hit.size:
            pos = tran[hit[0], 4:7]
            if np.isfinite(pos).all():
                root = pos.copy()
        st = fr.uttm if fr.uttm is not None and math.isfinite(fr.uttm) else None
        return [Frame(recv_time=now, quats=q, valid=valid, source_time=st, seq=seq,
                      root_position=root)]

    def _frame_fast(self, fr: MocopiFrame, now: float, seq: int) -> Frame | None:
        """Exactly the suit's bones in suit order, all finite and unit: few numpy
        operations.  None: the general path (same result)."""
        if len(fr.bone_ids) != self.n or not np.array_equal(fr.bone_ids, self._ids_arr):
            return None
        with np.errstate(invalid="ignore"):
            tran = fr.tran.astype(np.float64)
        q = tran[:, :4]
        if not np.abs(np.einsum("ij,ij->i", q, q) - 1.0).max() <= UNIT_EXACT:
            return None                              # NaN fails the comparison too
        q = np.ascontiguousarray(q)
        if self.continuous:
            neg = np.einsum("ij,ij->i", q, self._q) < 0
            if neg.any():
                q[neg] *= -1.0
        self._q = q
        root = None
        if self._root_row >= 0:
            pos = tran[self._root_row, 4:7]
            root = pos.copy() if np.isfinite(pos).all() else None
        st = fr.uttm if fr.uttm is not None and math.isfinite(fr.uttm) else None
        return Frame(recv_time=now, quats=q, valid=self._all_valid.copy(), source_time=st,
                     seq=seq, root_position=root)
