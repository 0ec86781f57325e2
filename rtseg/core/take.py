"""The take: a recorded (or replayed) motion, the one object every reader returns.

Conventions
-----------
- ``quats``: float64 array (frames, joints, 4), unit quaternions, scalar-last (x, y, z, w).
- ``space`` says what the rotations are relative to:
  ``"local"``  - each joint relative to its parent (ASF/AMC, BVH, VMC bone rotations);
  ``"global"`` - each joint relative to the world (IMU sensor orientations).
- ``parents[j]`` is the index of joint j's parent, -1 for a root.  Joint 0 is the root when
  the take has a hierarchy; its rotation is the body orientation.
- ``root_position``: (frames, 3) float64 in the file's length units (``length_unit`` says
  which, metres where known), or None.
- ``valid``: optional (frames, joints) bool; False where a sensor did not report.
- Frame i is at time ``i / frame_rate`` seconds from the start of the take.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Take:
    joint_names: list[str]
    parents: list[int]
    frame_rate: float
    quats: np.ndarray
    root_position: np.ndarray | None = None
    space: str = "local"
    valid: np.ndarray | None = None
    length_unit: str = "unknown"
    source: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.quats = np.asarray(self.quats, dtype=np.float64)
        if self.quats.ndim != 3 or self.quats.shape[2] != 4:
            raise ValueError(f"quats must be (frames, joints, 4), got {self.quats.shape}")
        if self.quats.shape[1] != len(self.joint_names):
            raise ValueError(
                f"{self.quats.shape[1]} joints of quaternions but {len(self.joint_names)} names")
        if len(self.parents) != len(self.joint_names):
            raise ValueError("parents and joint_names differ in length")
        if self.space not in ("local", "global"):
            raise ValueError(f"space must be 'local' or 'global', not {self.space!r}")
        if self.frame_rate <= 0:
            raise ValueError(f"frame_rate must be positive, got {self.frame_rate}")
        if self.root_position is not None:
            self.root_position = np.asarray(self.root_position, dtype=np.float64)
            if self.root_position.shape != (self.n_frames, 3):
                raise ValueError(
                    f"root_position must be ({self.n_frames}, 3), got {self.root_position.shape}")
        if self.valid is not None:
            self.valid = np.asarray(self.valid, dtype=bool)
            if self.valid.shape != self.quats.shape[:2]:
                raise ValueError(f"valid must be {self.quats.shape[:2]}, got {self.valid.shape}")

    @property
    def n_frames(self) -> int:
        return int(self.quats.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.quats.shape[1])

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return self.n_frames / self.frame_rate

    def joint_index(self, name: str) -> int:
        """Index of a joint by name, case-insensitive; KeyError naming the take if absent."""
        lowered = [n.lower() for n in self.joint_names]
        try:
            return lowered.index(name.lower())
        except ValueError:
            raise KeyError(f"joint {name!r} not in take {self.source or '<memory>'}") from None

    def slice(self, start: int, stop: int) -> "Take":
        """Frames [start, stop) as a new take sharing nothing with this one."""
        return Take(
            joint_names=list(self.joint_names), parents=list(self.parents),
            frame_rate=self.frame_rate, quats=self.quats[start:stop].copy(),
            root_position=None if self.root_position is None else self.root_position[start:stop].copy(),
            space=self.space,
            valid=None if self.valid is None else self.valid[start:stop].copy(),
            length_unit=self.length_unit, source=self.source, meta=dict(self.meta))
