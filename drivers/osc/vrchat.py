"""VRChat-style OSC trackers: ``/tracking/trackers/{1..8,head}/{position,rotation} ,fff``.

The fallback OSC input (SlimeVR and other full-body-tracking tools can send it; VRChat's
own default port is 9000).  Each tracker sends a **world** position in metres and a world
rotation as Unity Euler angles in degrees, both in Unity's left-handed, Y-up frame.  At most
9 points (head + 8 trackers whose body roles -- hip, chest, feet, knees, elbows -- are
assigned by the receiver's calibration, not by number) and no hierarchy: coarse but usable.

Conventions at this boundary
----------------------------
- Unity ``Quaternion.Euler(x, y, z)`` rotates about Z, then X, then Y (extrinsic), i.e.
  intrinsic Y-X-Z: ``Rotation.from_euler("YXZ", [y, x, z], degrees=True)``.
- Left-handed -> right-handed: quaternion (x, y, z, w) -> (-x, -y, z, w); position
  (x, y, z) -> (x, y, -z).
- Frame joints: ``JOINT_NAMES`` = Head, Tracker1 .. Tracker8; ``space = "global"``; no
  parents.  ``valid`` is True for trackers whose rotation arrived in that frame.

Frames close when a tracker repeats a value kind already held by the open frame, when every
tracker value seen in the last 0.5 s has arrived again, or after ``quiet`` seconds.  Malformed
input is counted like VMC (``corrupt``, ``bad_messages``, ``bad_values``) and never raised.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.drivers.base import SourceStats
from rtseg.drivers.osc.codec import OscParseError, parse_packet
from rtseg.core.frame import Frame

log = logging.getLogger("rtseg.drivers.vrchat")

TRACKERS: tuple[str, ...] = ("head", "1", "2", "3", "4", "5", "6", "7", "8")
JOINT_NAMES: list[str] = ["Head"] + [f"Tracker{i}" for i in range(1, 9)]
DEFAULT_PORT = 9000
_PREFIX = "/tracking/trackers/"


def unity_euler_to_quat(euler_deg: np.ndarray) -> np.ndarray:
    """Unity Euler angles (x, y, z) in degrees, left-handed -> rtseg quaternion (x, y, z, w),
    right-handed.  Works on (..., 3)."""
    e = np.asarray(euler_deg, dtype=np.float64)
    q = Rotation.from_euler("YXZ", e.reshape(-1, 3)[:, [1, 0, 2]], degrees=True).as_quat()
    q *= np.array([-1.0, -1.0, 1.0, 1.0])
    return q.reshape(e.shape[:-1] + (4,))


class VrchatAssembler:
    """Frames of 9 tracker orientations from VRChat OSC tracker datagrams.

    ``root``: tracker ("head", "1".."8") whose position becomes ``Frame.root_position``
    (None: no root position).  ``positions``: last position per tracker, (9, 3), rtseg
    frame, NaN before the first.
    """

    def __init__(self, *, quiet: float = 0.02, root: str | None = None,
                 stats: SourceStats | None = None) -> None:
        if root is not None and root.lower() not in TRACKERS:
            raise ValueError(f"root tracker must be one of {', '.join(TRACKERS)}, not {root!r}")
        self.quiet = float(quiet)
        self.root = None if root is None else TRACKERS.index(root.lower())
        self.stats = stats if stats is not None else SourceStats()
        self.positions = np.full((len(TRACKERS), 3), np.nan)
        self._q = np.tile([0.0, 0.0, 0.0, 1.0], (len(TRACKERS), 1))
        self._got: set[tuple[int, int]] = set()   # (tracker, 0 position / 1 rotation)
        self._expect: set[tuple[int, int]] = set()
        self._seen: dict[tuple[int, int], float] = {}   # last arrival of each value kind
        self.expire = 0.5
        self._seq = 0
        self._last_activity = -math.inf
        self._now = 0.0
        self._out: list[Frame] = []
        self._warned: dict[str, float] = {}

    def _warn(self, key: str, message: str) -> None:
        t = time.monotonic()
        if t - self._warned.get(key, -math.inf) >= 5.0:
            self._warned[key] = t
            log.warning("VRChat OSC: %s", message)

    def feed(self, data: bytes, now: float) -> list[Frame]:
        """Process one datagram received at ``now`` (monotonic s); frames closed by it."""
        self._out = out = []
        self._now = now
        self._last_activity = now
        try:
            messages = parse_packet(data)
        except OscParseError as exc:
            self.stats.corrupt += 1
            self._warn("corrupt", f"malformed OSC dropped: {exc}")
            return out
        for m in messages:
            if not m.address.startswith(_PREFIX):
                continue
            parts = m.address[len(_PREFIX):].split("/")
            if len(parts) != 2 or parts[0].lower() not in TRACKERS or parts[1] not in (
                    "position", "rotation"):
                continue
            tracker = TRACKERS.index(parts[0].lower())
            kind = 0 if parts[1] == "position" else 1
            args = m.args[:3]
            if len(args) < 3 or not all(isinstance(a, (int, float)) and not isinstance(a, bool)
                                        for a in args):
                self.stats.bad_messages += 1
                self._warn("bad", f"{m.address} ,{m.tags}: expected ,fff")
                continue
            vals = [float(a) for a in args]
            if not all(math.isfinite(v) for v in vals):
                self.stats.bad_values += 1
                self._warn("value", f"{m.address}: non-finite value {vals}")
                continue
            if (tracker, kind) in self._got:
                self._close()
            self._got.add((tracker, kind))
            self._seen[(tracker, kind)] = now
            if kind == 0:
                self.positions[tracker] = (vals[0], vals[1], -vals[2])
            else:
                self._q[tracker] = unity_euler_to_quat(np.array(vals))
            if self._expect and self._expect <= self._got:
                self._close()
        return out

    def new_sender(self) -> None:
        """The source now follows another sender (nothing to forget: VRChat OSC carries no
        sender clock)."""

    def flush(self, now: float, force: bool = False) -> list[Frame]:
        """Close the open frame after ``quiet`` seconds without datagrams (or ``force``)."""
        self._out = out = []
        if self._got and (force or now - self._last_activity >= self.quiet):
            self._now = now
            self._close()
        return out

    def _close(self) -> None:
        valid = np.zeros(len(TRACKERS), dtype=bool)
        for tracker, kind in self._got:
            if kind == 1:
                valid[tracker] = True
        rp = None
        if self.root is not None and np.all(np.isfinite(self.positions[self.root])):
            rp = self.positions[self.root].copy()
        self._out.append(Frame(recv_time=self._now, quats=self._q.copy(), valid=valid,
                               seq=self._seq, root_position=rp))
        self._seq += 1
        # a frame is complete when every tracker value seen in the last ``expire`` seconds
        # has arrived again (a tracker that stops reporting drops out of the set)
        self._expect = {key for key, t in self._seen.items() if self._now - t <= self.expire}
        self._got = set()


__all__ = ["VrchatAssembler", "unity_euler_to_quat", "TRACKERS", "JOINT_NAMES", "DEFAULT_PORT"]
