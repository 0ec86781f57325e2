"""Test helper: a take's frames fed to a ``LiveSession`` as fast as its loop takes them.

Imported as ``from take_source import TakeSource`` (pytest puts ``tests/`` on the path, as for
``osc_collector``).  No socket, no pty: for tests of what the session does with the frames
(identity, libraries); the real-I/O paths have their own tests.
"""

from __future__ import annotations

import time

import numpy as np

from rtseg.drivers.base import Source
from rtseg.core.frame import Frame


class TakeSource(Source):
    """``take``'s frames in order (seq = frame index, device time = index / 120 s), then
    EOFError; local joint rotations at 120 Hz."""
    space = "local"
    frame_rate = 120.0
    as_fast_as_read = True     # frames as fast as they are read: none is ever late

    def __init__(self, take) -> None:
        super().__init__()
        self.take = take
        self.joint_names = list(take.joint_names)
        self.parents = list(take.parents)
        self.i = 0
        self.valid = np.ones(take.n_joints, dtype=bool)

    def read(self, timeout: float | None = None) -> Frame:
        if self.i >= self.take.n_frames:
            raise EOFError
        i = self.i
        self.i += 1
        self.stats.frames_ok += 1
        if i % 200 == 0:
            time.sleep(0.001)          # let the loop keep up (ring never overwritten)
        return Frame(time.monotonic(), self.take.quats[i], self.valid, i / 120.0, i)
