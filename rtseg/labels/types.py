"""Label data types: :class:`Transition`, :class:`TransitionLabels` and :class:`LabelError`.

Frame convention: every frame number is **0-based** at the take's own frame rate, the same
numbering as ``Take.quats[i]`` and ``Cut.frame``; a :class:`Transition` is the inclusive
range ``[lo, hi]`` of cut frames accepted as one behaviour change, ``mid`` the labelled
boundary itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

#: Tolerance (frames) around a point label: 0.5 s at 120 fps, as the data README asks.
DEFAULT_TOLERANCE = 60


class LabelError(ValueError):
    """A label file that cannot be read as asked; the message names file and line."""

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = str(path)
        self.line = line
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {message}")


def integer_label(token: str) -> int | None:
    """A label token as an integer (``"3"``, ``"3.0"``, ``"3e0"``), or None when it is not
    an integral finite number (``"x"``, ``"2.5"``, ``"nan"``, ``"inf"``)."""
    try:
        return int(token)
    except ValueError:
        pass
    try:
        value = float(token)
    except ValueError:
        return None
    if not math.isfinite(value) or value != int(value):
        return None
    return int(value)


@dataclass(frozen=True)
class Transition:
    """One labelled behaviour change.

    lo, hi: inclusive range of 0-based cut frames accepted as this transition.
    mid: the labelled boundary frame (0-based); lo <= mid <= hi.
    before, after: behaviour names of the segments on either side ("" when unknown).
    """
    lo: int
    hi: int
    mid: int
    before: str = ""
    after: str = ""

    def __post_init__(self) -> None:
        if not self.lo <= self.mid <= self.hi:
            raise ValueError(f"transition needs lo <= mid <= hi, got {self.lo}, {self.mid}, {self.hi}")

    def contains(self, frame: int) -> bool:
        """True when a cut at ``frame`` is a correct detection of this transition."""
        return self.lo <= frame <= self.hi

    @property
    def width(self) -> int:
        """Number of accepted cut frames."""
        return self.hi - self.lo + 1


@dataclass
class TransitionLabels:
    """The labelled transitions of one take.

    take: take name, e.g. "86_01".
    transitions: sorted by ``mid``.
    n_frames: take length in frames stated or implied by the labels (None if unknown).
    kind: "ranges" (human ranges) or "tolerance" (points widened by ``tolerance`` frames).
    source: the label file (and block) they came from.
    repairs: human-readable notes of every slip repaired or rejected while reading.
    """
    take: str
    transitions: list[Transition]
    n_frames: int | None = None
    kind: str = "ranges"
    tolerance: int | None = None
    source: str = ""
    repairs: list[str] = field(default_factory=list)

    @property
    def description(self) -> str:
        if self.kind == "ranges":
            return f"ranges from {self.source}"
        return f"points +/-{self.tolerance} frames from {self.source}"



__all__ = ["DEFAULT_TOLERANCE", "LabelError", "Transition", "TransitionLabels", "integer_label"]
