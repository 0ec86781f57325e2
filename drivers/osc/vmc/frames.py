"""VMC frame assembly rules: when decoded bone / root / time messages make a frame.

:class:`VmcFrameRules` holds the open frame and applies the closing rules documented on
:class:`rtseg.drivers.osc.vmc.codec.VmcAssembler` (which adds the datagram decoding on top):
per-message handlers (``_on_bone``, ``_on_root``, ``_on_time``), sequence numbering with
gaps estimated from ``/VMC/Ext/T``, bone-name resolution and the drop counters.

Frames come out in rtseg's frame (right-handed, Y-up, scalar-last quaternions); the
handlers receive the raw Unity (left-handed) values and convert them.  Times are seconds:
``now`` is the receiver's monotonic clock, T the sender's clock.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Sequence

import numpy as np

from rtseg.drivers.base import SourceStats
from rtseg.drivers.osc.vmc.rest import BoneOffsets
from rtseg.core.frame import Frame

log = logging.getLogger("rtseg.drivers.vmc")

#: A step of ``/VMC/Ext/T`` larger than this (s), or a step back (but for a late frame,
#: below), is a clock restart: reported times continue from the last one instead of
#: following T.
MAX_CLOCK_JUMP = 3.0
#: A frame whose ``/VMC/Ext/T`` lies at most this far (s) behind the last frame's, and
#: that arrives within ``LATE_SILENCE`` (s, receive clock) of the last frame, arrived late
#: (reordered or repeated on the way): it is dropped, counted in ``bad_messages``, and the
#: clock goes on.  When the next frame goes on from it instead (later than it, still behind
#: the last frame), the last frame's T was the odd one (damaged ahead): that next frame is
#: a clock restart.  So is a step back by more, after a silence, or from a sender the
#: source has just switched to (``new_sender``).
LATE_WINDOW = 1.0
LATE_SILENCE = 0.25
#: ``/VMC/Ext/T`` beyond this (s, about 115 days) is no sender's clock but a damaged value:
#: refused (``bad_values``) like a non-finite one.  Taken as a clock it would restart the
#: reported clock at a magnitude where float64 no longer holds milliseconds.
MAX_TIME = 1e7


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



class VmcFrameRules:
    """The open frame and the rules that close it (see ``VmcAssembler`` for the rules and
    the arguments).  Fed decoded message values; datagram parsing is the subclass's job."""

    def __init__(self, bone_names: Sequence[str], *, quiet: float = 0.02,
                 unit_tolerance: float = 0.05, continuous: bool = True,
                 time_order: str = "last", burst: float = 0.004,
                 stats: SourceStats | None = None,
                 parents: Sequence[int] | None = None) -> None:
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
        #: the bone positions the sender sends: its rest geometry (``rest.BoneOffsets``)
        self.offsets = BoneOffsets(bone_names, parents)
        self._sends_t = False
        self._sends_root = False
        self._last_closed_t: float | None = None
        self._learned = False                 # a frame closed by a change rule was seen
        self._last_activity = -math.inf
        self._seq = 0
        self._prev_t: float | None = None      # T of the last frame closed with one
        self._closed_at = -math.inf            # arrival time of the last frame closed
        self._late_t: float | None = None      # T of the frame just dropped as late
        self._new_clock = False                # the next T is another sender's clock
        self._period: float | None = None      # sender frame period estimated from T, s
        self._t_offset = 0.0                   # reported time = T + offset (clock segments)
        self._last_reported: float | None = None
        self._out: list[Frame] = []
        self._warned: dict[str, float] = {}
        self._unknown_seen: set[bytes] = set()
        #: Last ``/VMC/Ext/OK`` arguments (loaded, calibration state, mode, tracking) or None.
        self.ok_state: tuple[int, ...] | None = None
        #: Last root rotation (rtseg frame, scalar-last) or None.
        self.root_rotation: tuple[float, float, float, float] | None = None

    @property
    def closes_by_content(self) -> bool:
        """Whether frames are now closed by what arrives (the sender's T seen and its
        message order learned: rules 1-4 of ``VmcAssembler`` without a timing rule), so a
        batch of datagrams read together gives the frames they would give read one by
        one (a frame whose root was lost may take the next frame's root then)."""
        return self._sends_t and self._learned

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

    def new_sender(self) -> None:
        """The source now follows another sender: the next frame's ``/VMC/Ext/T`` is that
        sender's clock, so a step back is a clock restart, not a late frame."""
        self._new_clock = True

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

    def _padded_index(self, padded: bytes) -> int:
        """Cached :meth:`_resolve_padded`."""
        idx = self._pcache.get(padded)
        return self._resolve_padded(padded) if idx is None else idx

    def _unknown(self, raw: bytes, count: bool = True) -> None:
        """Count a bone name outside the profile (``raw`` may carry NUL padding); log each
        name once (up to 256 names)."""
        if count:
            self.stats.unknown_names += 1
        if raw not in self._unknown_seen and len(self._unknown_seen) < 256:
            self._unknown_seen.add(raw)
            log.info("VMC: bone %r not in the suit profile; ignored",
                     raw.rstrip(b"\x00")[:64])

    def _on_bone(self, name: str, vals: tuple) -> None:
        raw = name.encode("utf-8", errors="replace")
        idx = self._cache.get(raw)
        if idx is None:
            idx = self._resolve(raw)
        px, py, pz, x, y, z, w = vals
        if idx < 0:
            if self.offsets.capturing:
                self.offsets.note_extra(name, px, py, -pz)
            self._unknown(raw)
            return
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
        if self.offsets.capturing:
            self.offsets.note(idx, px, py, -pz)
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
        if not abs(t) <= MAX_TIME:           # also refuses nan and inf
            self._bad_value(f"time {t} not finite or beyond {MAX_TIME:g} s")
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

    def _restart_clock(self, t: float, dt: float) -> None:
        """``/VMC/Ext/T`` went back or jumped by ``dt`` s: a new segment of the reported
        clock, continuing one frame period after the last reported time."""
        step = self._period or 0.0
        last = self._last_reported if self._last_reported is not None else self._prev_t
        self._t_offset = (last + step) - t
        self.stats.clock_restarts += 1
        log.warning("VMC: /VMC/Ext/T %s by %.3f s (sender restarted?): reported times "
                    "continue from %.3f s (clock segment %d)",
                    "went back" if dt < 0 else "jumped ahead", abs(dt), last + step,
                    self.stats.clock_restarts + 1)

    @property
    def frame_period(self) -> float | None:
        """The sender's frame period in seconds estimated from ``/VMC/Ext/T``, or None."""
        return self._period

    def _close(self) -> None:
        t = self._t
        if t is not None and self._prev_t is not None and not self._new_clock and \
                -LATE_WINDOW <= t - self._prev_t < 0.0 and \
                self._now - self._closed_at < LATE_SILENCE:
            lt = self._late_t
            if lt is None or not 0.0 < t - lt <= LATE_WINDOW:
                self._late_t = t
                self._late(t)
                return
            # it goes on from the frame dropped as late: the frame before them was the odd
            # one (a damaged T ahead): a clock restart here, below
        self._late_t = None
        self._new_clock = False
        self._closed_at = self._now
        if self.offsets.capturing:
            self.offsets.frame_closed()
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
        if t is not None:
            if self._prev_t is not None:
                dt = t - self._prev_t
                if dt < 0.0 or dt > MAX_CLOCK_JUMP:
                    self._restart_clock(t, dt)
                else:
                    self._seq += self._frames_elapsed(dt) - 1
            self._prev_t = t
            t = t + self._t_offset
            self._last_reported = t
        self._out.append(Frame(recv_time=self._now, quats=quats, valid=valid,
                               source_time=t, seq=self._seq, root_position=rp))
        self._seq += 1
        self._last_closed_t = t
        self._clear()

    def _late(self, t: float) -> None:
        """The open frame's T lies behind the last frame's, within ``LATE_WINDOW``: a frame
        reordered or repeated on the way, whose time has passed.  Dropped and counted; the
        clock, the sequence and the frame period are left as they were."""
        self._bad_message(f"a frame of /VMC/Ext/T {t:.3f} s arrived after one of "
                          f"{self._prev_t:.3f} s (late or repeated on the way): dropped")
        self._clear()

    def _clear(self) -> None:
        """Forget the open frame (closed or dropped)."""
        self._got[:] = self._all_false   # in place: _bundle holds a reference
        self._n_got = 0
        self._t = None
        self._root = None


__all__ = ["VmcFrameRules"]
