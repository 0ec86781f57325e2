"""Reader of ``labels/mocap6/SS_TT.txt``: one integer label per 12-frame block.

Block ``b`` starts at frame ``12 b`` (0-based); a change of label between blocks ``b - 1``
and ``b`` is a transition at frame ``12 b``, correct within +/- 60 frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rtseg.labels.frames import transitions_from_frame_labels
from rtseg.labels.types import DEFAULT_TOLERANCE, LabelError, TransitionLabels, integer_label

#: Frames per label block in ``labels/mocap6`` (10 labels per second at 120 fps).
MOCAP6_BLOCK = 12
#: Exercise names of the mocap6 label integers.
MOCAP6_NAMES = {
    1: "JumpJack", 2: "Jog", 3: "Squat", 4: "KneeRaise", 5: "ArmCircle", 6: "Twist",
    7: "SideReach", 8: "Box", 9: "UpDown", 10: "ToeTouchOneHand", 11: "SideBend",
    12: "ToeTouchTwoHands",
}


def _int_tokens(path: Path, text: str) -> np.ndarray:
    """Whitespace-separated integers; LabelError naming the line of the first bad token."""
    values = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        for tok in line.split():
            value = integer_label(tok)
            if value is None:
                raise LabelError(path, lineno, f"expected an integer label, got {tok!r}")
            values.append(value)
    return np.asarray(values, dtype=np.int64)


def read_block_labels(path: str | Path, *, block: int = MOCAP6_BLOCK,
                      tolerance: int = DEFAULT_TOLERANCE,
                      n_frames: int | None = None) -> TransitionLabels:
    """Read a ``labels/mocap6/SS_TT.txt`` file: one integer per ``block`` frames."""
    path = Path(path)
    values = _int_tokens(path, path.read_text(encoding="utf-8-sig"))
    if values.size == 0:
        raise LabelError(path, None, "no labels in file")
    names = MOCAP6_NAMES if block == MOCAP6_BLOCK else None
    tr = transitions_from_frame_labels(values, step=block, tolerance=tolerance,
                                       n_frames=n_frames, names=names)
    return TransitionLabels(take=path.stem, transitions=tr,
                            n_frames=n_frames if n_frames is not None else values.size * block,
                            kind="tolerance", tolerance=tolerance,
                            source=f"{path.parent.name}/{path.name}")


__all__ = ["MOCAP6_BLOCK", "MOCAP6_NAMES", "read_block_labels"]
