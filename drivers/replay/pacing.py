"""Replaying a take as a live source: absolute-schedule pacing shared by ``file://`` and
``sim://`` sources.

Pacing
------
Frame ``k`` (counted from the first frame delivered, across loops) is due at
``t0 + offset_k / speed`` on ``time.monotonic()``, where ``t0`` is the time of the first
``read`` and ``offset_k`` is ``k / frame_rate`` (nominal timing) or the recorded receive
time of the frame relative to the first (recorded timing, session folders).  Every due time
is computed from ``t0``, never from the previous frame, so the schedule does not drift
however late individual reads are; a consumer that falls behind gets the overdue frames at
once (nothing is dropped, as a real driver's buffer would hold them).  ``speed=0`` delivers
frames as fast as they are read (``as_fast_as_read``): a live session then reads them only
as fast as it processes them (backpressure, ``rtseg.live.intake``), so none is lost or
dropped as late and the cuts are those of the take offline.

Frames
------
``Frame.quats`` (J, 4) scalar-last in the replay's ``space``; ``valid`` (J,) from the
take's ``valid`` (all True without one) - rows not valid hold the last valid value
(identity before the first), as the ``Frame`` contract says; ``seq`` = the frame's index in
the take (plus ``n_frames`` per completed loop, so it keeps increasing); ``source_time`` =
``seq / frame_rate`` s; ``recv_time`` = ``time.monotonic()`` at delivery;
``root_position`` (3,) when the take has one.  With recorded timing of a session, ``seq``
and ``source_time`` are the recorded ones where the session had them.

``read`` raises ``EOFError`` after the last frame (unless looping) and after ``close``.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Mapping

import numpy as np

from rtseg.core import quat
from rtseg.core.posture import RestPose
from rtseg.drivers.base import Source, SourceError
from rtseg.drivers.options import flag_option, number_option
from rtseg.core.frame import Frame
from rtseg.core.take import Take


class Pacer:
    """Absolute schedule: item ``k`` is due at ``t0 + offsets[k % n] + loop * period``,
    all divided by ``speed``.  ``t0`` is fixed by :meth:`start` (first call of :meth:`due`).

    offsets: (n,) seconds from the first item, non-decreasing; period: seconds one pass
    lasts when looping (last offset + one nominal frame interval).  speed > 0, or 0 for
    "as fast as possible" (every item due at once).
    """

    def __init__(self, offsets: np.ndarray, period: float, speed: float = 1.0,
                 clock=time.monotonic) -> None:
        offsets = np.asarray(offsets, dtype=np.float64)
        if offsets.ndim != 1 or offsets.size == 0:
            raise ValueError("Pacer needs at least one offset")
        if not np.all(np.isfinite(offsets)) or np.any(np.diff(offsets) < 0):
            raise ValueError("Pacer offsets must be finite and non-decreasing")
        if not (speed >= 0 and np.isfinite(speed)):
            raise ValueError(f"speed must be >= 0 (0 = as fast as possible), got {speed}")
        self.offsets = offsets - offsets[0]
        self.period = float(period)
        self.speed = float(speed)
        self.clock = clock
        self.t0: float | None = None

    @classmethod
    def nominal(cls, n: int, frame_rate: float, speed: float = 1.0, clock=time.monotonic) -> "Pacer":
        """Frames evenly spaced at ``frame_rate`` Hz."""
        return cls(np.arange(n) / frame_rate, n / frame_rate, speed, clock)

    def start(self, now: float | None = None) -> float:
        if self.t0 is None:
            self.t0 = self.clock() if now is None else now
        return self.t0

    def due(self, k: int) -> float:
        """Monotonic time at which item ``k`` (0-based, counting loops) is due."""
        t0 = self.start()
        if self.speed == 0:
            return t0
        n = self.offsets.size
        loop, i = divmod(int(k), n)
        return t0 + (loop * self.period + self.offsets[i]) / self.speed

    def set_speed(self, speed: float, k: int) -> None:
        """Change speed keeping item ``k`` due now (the schedule stays absolute from here)."""
        if not (speed >= 0 and np.isfinite(speed)):
            raise ValueError(f"speed must be >= 0, got {speed}")
        now = self.clock()
        n = self.offsets.size
        loop, i = divmod(int(k), n)
        self.speed = float(speed)
        self.t0 = now - ((loop * self.period + self.offsets[i]) / speed if speed else 0.0)


class ReplaySource(Source):
    """A ``Take`` delivered frame by frame in real time (or ``speed`` times faster).

    take: the motion.  speed: 1 = real time, N = N times faster, 0 = as fast as read.
    loop: start again from the first frame after the last.  start/stop: seconds of the
    take to play (stop None = to the end).  space: "local"/"global" to convert the take's
    rotations (None keeps the take's).  timing: "nominal" (frame_rate) or "recorded" (the
    take's ``meta["recv_time"]``, a recorded session's receive times).
    """

    def __init__(self, take: Take, *, speed: float = 1.0, loop: bool = False,
                 start: float = 0.0, stop: float | None = None, space: str | None = None,
                 timing: str = "nominal", name: str = "") -> None:
        super().__init__()
        self.name = name or take.source or "<take>"
        if take.n_frames == 0:
            raise SourceError(f"{self.name}: the take has no frames")
        # min(): a start or stop far past the end (1e308 s) is the end, not an overflow
        a = int(round(min(start * take.frame_rate, take.n_frames))) if start else 0
        b = (take.n_frames if stop is None
             else int(round(min(stop * take.frame_rate, take.n_frames))))
        if not 0 <= a < take.n_frames:
            raise SourceError(f"{self.name}: start={start} s is outside the take "
                              f"(0 to {take.duration:.3f} s)")
        if b <= a:
            raise SourceError(f"{self.name}: stop={stop} s must be after start={start} s")
        b = min(b, take.n_frames)
        self.take = take
        self.first_frame = a
        self.joint_names = list(take.joint_names)
        self.parents = list(take.parents)
        self.frame_rate = float(take.frame_rate)
        self.space = take.space if space is None else space
        self.rest_pose = RestPose.find(take)
        q = take.quats[a:b]
        if self.space != take.space:
            if self.space == "global":
                q = quat.global_from_local(q, self.parents)
            elif self.space == "local":
                q = quat.local_from_global(q, self.parents)
            else:
                raise SourceError(f"{self.name}: space must be 'local' or 'global', not {space!r}")
            q = quat.make_continuous(quat.normalize(q), axis=0)
        self._quats = np.ascontiguousarray(q)
        self._valid = None if take.valid is None else np.ascontiguousarray(take.valid[a:b])
        self._root = None if take.root_position is None else take.root_position[a:b]
        n = b - a
        self._seq = np.arange(a, b, dtype=np.int64)
        self._src_time: np.ndarray = self._seq / self.frame_rate
        if timing == "recorded":
            rt = take.meta.get("recv_time")
            if rt is None or np.shape(rt) != (take.n_frames,):
                raise SourceError(f"{self.name}: timing=recorded needs the take's recorded "
                                  f"receive times (a session folder recorded by rtseg live)")
            rt = np.maximum.accumulate(np.asarray(rt, dtype=np.float64)[a:b])
            period = rt[-1] - rt[0] + 1.0 / self.frame_rate
            self.pacer = Pacer(rt, period, speed)
            seq = take.meta.get("seq")
            st = take.meta.get("source_time")
            if seq is not None and np.shape(seq) == (take.n_frames,):
                s = np.asarray(seq, dtype=np.int64)[a:b]
                self._seq = np.where(s >= 0, s, self._seq)
            if st is not None and np.shape(st) == (take.n_frames,):
                s = np.asarray(st, dtype=np.float64)[a:b]
                self._src_time = np.where(np.isfinite(s), s, self._src_time)
            self._recorded = True
        elif timing == "nominal":
            self.pacer = Pacer.nominal(n, self.frame_rate, speed)
            self._recorded = False
        else:
            raise SourceError(f"{self.name}: timing must be 'nominal' or 'recorded', not {timing!r}")
        self.loop = bool(loop)
        self.n_frames = n
        self.delivered = 0          # frames delivered so far (all loops)
        self._last_good = np.tile(quat.IDENTITY, (len(self.joint_names), 1))
        self._all_valid = np.ones(len(self.joint_names), dtype=bool)
        self._closed = threading.Event()

    # ------------------------------------------------------------------ state
    @property
    def speed(self) -> float:
        return self.pacer.speed

    @property
    def as_fast_as_read(self) -> bool:
        """True at ``speed=0`` (see ``Source.as_fast_as_read``)."""
        return self.pacer.speed == 0

    @property
    def position(self) -> int:
        """Index (in the take) of the next frame to deliver."""
        return self.first_frame + self.delivered % self.n_frames

    @property
    def loops(self) -> int:
        """Completed passes over the take."""
        return self.delivered // self.n_frames

    @property
    def finished(self) -> bool:
        return self._closed.is_set() or (not self.loop and self.delivered >= self.n_frames)

    def set_speed(self, speed: float) -> None:
        """Change the replay speed from the next frame on."""
        self.pacer.set_speed(speed, self.delivered)

    # ------------------------------------------------------------------ Source
    def read(self, timeout: float | None = None) -> Frame | None:
        """The next frame when it is due; None if it is not due within ``timeout`` s."""
        if self._closed.is_set():
            raise EOFError(f"{self.name}: source closed")
        k = self.delivered
        if not self.loop and k >= self.n_frames:
            raise EOFError(f"{self.name}: end of take after {self.n_frames} frames")
        wait = self.pacer.due(k) - self.pacer.clock()
        if wait > 0:
            if timeout is not None and timeout < wait:
                if timeout > 0:
                    self._closed.wait(timeout)
                return None
            if self._closed.wait(wait):
                raise EOFError(f"{self.name}: source closed")
        return self._make(k)

    def _make(self, k: int) -> Frame:
        loop, i = divmod(k, self.n_frames)
        q = self._quats[i]
        if self._valid is not None:
            v = self._valid[i].copy()
            if not v.all():
                self._last_good[v] = q[v]
                q = self._last_good.copy()
            else:
                self._last_good[:] = q
                q = q.copy()
        else:
            v = self._all_valid.copy()
            q = q.copy()
        if self._recorded:
            seq = int(self._seq[i]) + loop * (int(self._seq[-1]) + 1)
            st = float(self._src_time[i]) + loop * self.pacer.period
        else:
            seq = int(self._seq[i]) + loop * self.n_frames
            st = seq / self.frame_rate
        root = None if self._root is None else self._root[i].copy()
        self.delivered = k + 1
        self.count("frames_ok")
        return Frame(recv_time=time.monotonic(), quats=q, valid=v, source_time=st, seq=seq,
                     root_position=root)

    def close(self) -> None:
        self._closed.set()


# ---------------------------------------------------------------------- URL options

#: Options every replay source understands.
REPLAY_OPTIONS = {"speed", "loop", "start", "stop", "space"}


#: accepted range of each numeric option of the replay sources (``rate``: above zero)
RANGES = {"speed": (0.0, math.inf), "start": (0.0, math.inf), "stop": (0.0, math.inf),
          "seed": (0, 2**32 - 1), "rate": (1e-3, 1e5), "noise": (0.0, math.inf)}
#: ``sim://`` synthesises every frame of its script up front: its ``rate`` is a suit's
#: (100 kHz over the default script's 62 s is 6 million frames, more memory than a machine has)
SIM_RANGES = {**RANGES, "rate": (1.0, 1000.0)}


def replay_kwargs(scheme: str, options: Mapping[str, str]) -> dict:
    """speed / loop / start / stop / space from URL options, validated (errors name
    ``scheme``)."""
    space = options.get("space") or None       # empty: the default, as for numbers
    if space is not None and space not in ("local", "global"):
        raise SourceError(f"{scheme}:// option space={space!r}: expected local or global")
    return {"speed": number_option(scheme, options, "speed", 1.0, float, RANGES),
            "loop": flag_option(scheme, options, "loop"),
            "start": number_option(scheme, options, "start", 0.0, float, RANGES),
            "stop": number_option(scheme, options, "stop", None, float, RANGES), "space": space}


__all__ = ["Pacer", "RANGES", "SIM_RANGES", "ReplaySource", "REPLAY_OPTIONS", "replay_kwargs"]
