"""One decoded frame of a live source.

Every source (serial, OSC, file replay, simulator) yields ``Frame`` objects:

- ``recv_time``: ``time.monotonic()`` seconds when the frame was complete at the receiver.
- ``source_time``: the device's own clock in seconds, or None if the source has none.
- ``seq``: the source's sequence number (or frame index for replays), or None.
- ``quats``: (joints, 4) float64 scalar-last unit quaternions in the source's
  ``joint_names`` order; rows where ``valid`` is False hold the last good value (or identity).
- ``valid``: (joints,) bool: this joint's sensor reported a usable value in this frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(slots=True)
class Frame:
    recv_time: float
    quats: np.ndarray
    valid: np.ndarray
    source_time: float | None = None
    seq: int | None = None
    root_position: np.ndarray | None = None
