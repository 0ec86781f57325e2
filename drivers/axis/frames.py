"""Noitom Axis: decoded :class:`~rtseg.drivers.axis.codec.AxisFrame` -> rtseg ``Frame``
(no sockets): :class:`AxisFrames` (avatar choice, Euler -> quaternions, forward kinematics
for ``space="global"``, counters), :class:`TextStream` (what the text source runs on each
TCP read) and :class:`_BinaryAdapter` (what the binary source runs on its datagrams).

Frames: the 59 Axis joints, ``space`` global (world orientations, BVH rotations chained by
forward kinematics) or local (the BVH's parent-relative rotations), right-handed Y-up,
scalar-last float64; ``root_position`` = Hips position in metres; ``seq`` = binary frame
index (text: count of frames received); ``valid`` False for joints whose angles are not
finite (in global space also for their descendants).  ``AxisFrames.rest``: the avatar's rest
geometry from the position channels of a stream with displacement (each joint's offset
from its parent), None without them.  See :mod:`rtseg.drivers.axis.source`
for the sources and their options.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from rtseg.drivers.axis.codec import (JOINTS, PARENTS, AxisError, AxisFrame, BinaryAssembler,
                                      decode_binary, global_pose, poses, to_pose)
from rtseg.drivers.axis.pose import rest_pose
from rtseg.drivers.axis.text import TextSplitter, decode_texts
from rtseg.drivers.vendor_seq import SeqGaps
from rtseg.core.frame import Frame
from rtseg.core.posture import RestPose

log = logging.getLogger("rtseg.drivers.axis")

_ALL_VALID = np.ones(len(JOINTS), dtype=bool)
#: frames with displacement looked at for the rest geometry before giving up
REST_TRIES = 8


class AxisFrames:
    """Decoded :class:`AxisFrame` -> rtseg ``Frame`` of the selected avatar (shared by both
    transports).  ``count(field, n, message)``: the source's counter method."""

    def __init__(self, count, avatar: str | None = None, order: str = "YXZ",
                 unit_scale: float = 0.01, rate: float = 60.0, space: str = "local") -> None:
        """``space``: what this converter returns (the sources pass ``global`` by
        default)."""
        self._count = count
        self.space = space
        self.avatar = avatar
        self.order = order
        self.unit_scale = unit_scale
        self.rate = rate
        self.other_avatars = 0
        self.avatar_seen: tuple[int, str] | None = None
        self.received = 0
        self._last = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (len(JOINTS), 1))
        self._log_at: dict[str, float] = {}
        self._gaps = SeqGaps(32, name="Axis", counter="frame index", logger=log)
        #: the avatar's rest geometry (``rtseg.core.posture.RestPose``) from the first
        #: frame with displacement that gives one (``pose.rest_pose``), else None
        self.rest: RestPose | None = None
        self._rest_tries = 0
        #: True once the stream is known to give no rest geometry (a frame without
        #: displacement, or ``REST_TRIES`` with it that gave none)
        self.no_geometry = False

    def warn(self, key: str, now: float, msg: str, *args) -> None:
        if now - self._log_at.get(key, -math.inf) >= 5.0:
            self._log_at[key] = now
            log.warning(msg, *args)

    def error(self, exc: AxisError, now: float) -> None:
        self._count(exc.kind)
        self.warn(exc.kind, now, "Axis: frame dropped (%s): %s", exc.kind, exc)

    def _seq(self, f: AxisFrame, now: float) -> int | None:
        """The frame's ``seq``: the binary frame index (a forward jump adds 1 to ``gaps``
        and the frames skipped to ``dropped``; an index the receive clock cannot explain,
        or backwards, is a damaged or restarted counter: 1 in ``counter_jumps``, the last
        trusted index + 1 returned; :class:`rtseg.drivers.vendor_seq.SeqGaps`), or for text
        the count of frames so far.  None for a frame repeated or reordered on the way (an
        index repeating the last one or a few behind it): dropped, 1 in ``bad_messages``."""
        self.received += 1
        if f.frame_index is None:
            return self.received - 1
        step = self._gaps.step(f.frame_index, now)
        if step.late:
            self._count("bad_messages")
            self.warn("late", now, "Axis: frame index %d repeated or late (after %s): "
                      "dropped", f.frame_index, self._gaps.last)
            return None
        if step.jumps:                             # damaged or restarted (SeqGaps logs)
            self._count("counter_jumps", step.jumps)
        if step.missing:
            self._count("gaps")
            self._count("dropped", step.missing)
            self.warn("gap", now, "Axis: %d frame(s) missing before frame index %d",
                      step.missing, f.frame_index)
        return step.seq

    def _selected(self, f: AxisFrame) -> bool:
        if self.avatar is None:
            if self.avatar_seen is None:
                self.avatar_seen = (f.avatar_index, f.avatar_name)
                log.info("Axis: following avatar %d %r (choose with ?avatar=)",
                         f.avatar_index, f.avatar_name)
            return (f.avatar_index, f.avatar_name) == self.avatar_seen
        return self.avatar == f.avatar_name or self.avatar == str(f.avatar_index)

    def frame(self, f: AxisFrame, now: float) -> Frame | None:
        """The Frame of ``f``, or None (another avatar's frame, counted)."""
        if not self._selected(f):
            self.other_avatars += 1
            return None
        return self._convert(f, now)

    def _note_rest(self, f: AxisFrame) -> None:
        """Take the rest geometry from ``f`` (the first few frames with displacement)."""
        if self.rest is not None or self.no_geometry:
            return
        if not f.with_disp:
            self.no_geometry = True
            return
        self._rest_tries += 1
        self.rest = rest_pose(f.values, f.with_ref, self.unit_scale)
        self.no_geometry = self.rest is None and self._rest_tries >= REST_TRIES

    def _convert(self, f: AxisFrame, now: float) -> Frame | None:
        seq = self._seq(f, now)
        if seq is None:                       # repeated or late: dropped, counted
            return None
        self._note_rest(f)
        if not (f.finite or (f.finite is None and np.isfinite(f.values).all())):
            return self._convert_bad(f, now, seq)
        q, self._last, pos = poses(f.values, f.with_disp, f.with_ref, self.order,
                                   self.unit_scale, self.space)
        return Frame(recv_time=now, quats=q, valid=_ALL_VALID.copy(),
                     source_time=None if f.frame_index is None else seq / self.rate,
                     seq=seq, root_position=pos)

    def _convert_bad(self, f: AxisFrame, now: float, seq: int) -> Frame:
        """A frame with non-finite values: those joints invalid (their last good local
        rotation kept; in global space their descendants invalid too), counted."""
        q, valid, pos = to_pose(f, self.order, self.unit_scale)   # fresh arrays
        if np.count_nonzero(valid) != valid.size:
            n = int(np.count_nonzero(~valid))
            self._count("bad_values", n)
            self.warn("bad", now, "Axis: %d joint(s) with non-finite angles; marked invalid", n)
            q[~valid] = self._last[~valid]
        self._last = q
        if self.space == "global":
            q = global_pose(q)
            if not valid.all():               # a world orientation chains its ancestors'
                for j, p in enumerate(PARENTS):
                    if p >= 0 and not valid[p]:
                        valid[j] = False
        return Frame(recv_time=now, quats=q, valid=valid,
                     source_time=None if f.frame_index is None else seq / self.rate,
                     seq=seq, root_position=pos)

    def many(self, items: list[AxisFrame | AxisError], now: float) -> list[Frame]:
        """:meth:`frame` of each decoded frame (AxisErrors are counted), in order; runs
        of frames of one layout with finite values are converted together (one Euler ->
        quaternion pass and, for ``space=global``, one forward-kinematics pass), giving
        the same values as frame by frame."""
        out: list[Frame] = []
        run: list[AxisFrame] = []
        for f in items:
            if isinstance(f, AxisError):
                self.error(f, now)
                continue
            if not self._selected(f):
                self.other_avatars += 1
                continue
            if run and (f.with_disp, f.with_ref, f.values.size) != (
                    run[0].with_disp, run[0].with_ref, run[0].values.size):
                self._run(run, now, out)
                run = []
            run.append(f)
        if run:
            self._run(run, now, out)
        return out

    def _run(self, run: list[AxisFrame], now: float, out: list[Frame]) -> None:
        values = None if len(run) == 1 else np.array([f.values for f in run])  # (not np.stack: 5x)
        if values is None or not (all(f.finite for f in run) or np.isfinite(values).all()):
            for f in run:                                    # one, or non-finite values
                frame = self._convert(f, now)
                if frame is not None:                        # None: repeated or late
                    out.append(frame)
            return
        seqs = [self._seq(f, now) for f in run]          # None: repeated or late, dropped
        if None in seqs:                                 # (before any pose is worked out)
            keep = [k for k, seq in enumerate(seqs) if seq is not None]
            if not keep:
                return
            run, values, seqs = [run[k] for k in keep], values[keep], [seqs[k] for k in keep]
        f0 = run[0]
        self._note_rest(f0)
        q, local, root = poses(values, f0.with_disp, f0.with_ref, self.order,
                               self.unit_scale, self.space)
        self._last = local[-1]
        for k, (f, seq) in enumerate(zip(run, seqs)):
            out.append(Frame(recv_time=now, quats=q[k], valid=_ALL_VALID.copy(),
                             source_time=None if f.frame_index is None
                             else seq / self.rate, seq=seq,
                             root_position=root[k]))


class TextStream:
    """What :class:`AxisTextSource` runs on each TCP read: bytes -> frames split on
    ``||`` -> decoded together (:func:`~rtseg.drivers.axis.text.decode_texts`) ->
    :meth:`AxisFrames.many`.  A run of 64 KiB without ``||`` is discarded and counted
    (``corrupt``)."""

    def __init__(self, frames: AxisFrames) -> None:
        self.frames = frames
        self.splitter = TextSplitter()

    def feed(self, data: bytes, now: float) -> list[Frame]:
        before = self.splitter.overflows
        chunks = self.splitter.feed(data)
        if self.splitter.overflows != before:
            self.frames.error(AxisError("corrupt", "no '||' within 64 KiB; discarded"), now)
        return self.frames.many(decode_texts(chunks), now) if chunks else []

    def reset(self, now: float = 0.0) -> None:
        """Forget a partial frame (the connection closed): a frame cut short by the close
        is a frame lost, 1 in ``dropped`` (text frames carry no number that would show
        it)."""
        if self.splitter.partial:
            self.frames.error(AxisError("dropped", "frame cut short by the connection "
                                                   "closing"), now)
        self.splitter.reset()


class _BinaryAdapter:
    """``feed``/``flush`` for :class:`OscUdpSource`: datagrams -> Frames; ``feed_many``
    decodes several datagrams and converts their frames together (one Euler and one
    forward-kinematics pass per run of same-layout frames, as for the frames of a text
    read)."""

    def __init__(self, frames: AxisFrames) -> None:
        self.frames = frames
        self.joiner = BinaryAssembler()

    def feed(self, data: bytes, now: float) -> list[Frame]:
        """One datagram (the frame-by-frame path: no batch bookkeeping)."""
        out: list[Frame] = []
        chunks, errors = self.joiner.feed(data, now)
        for e in errors:
            self.frames.error(e, now)
        for chunk in chunks:
            try:
                fr = self.frames.frame(decode_binary(chunk), now)
            except AxisError as e:
                self.frames.error(e, now)
                continue
            if fr is not None:
                out.append(fr)
        return out

    def feed_many(self, datagrams, now: float) -> list[Frame]:
        items: list[AxisFrame | AxisError] = []
        for data in datagrams:
            chunks, errors = self.joiner.feed(data, now)
            items.extend(errors)
            for chunk in chunks:
                try:
                    items.append(decode_binary(chunk))
                except AxisError as e:
                    items.append(e)
        return self.frames.many(items, now) if items else []

    def flush(self, now: float, force: bool = False) -> list[Frame]:
        e = self.joiner.flush(now)
        if e is not None:
            self.frames.error(e, now)
        return []


__all__ = ["AxisFrames", "TextStream"]
