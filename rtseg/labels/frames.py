"""Per-frame labels: one integer label per frame (the 5th column of a tsseg4d CSV, or a
take's ``meta["frame_labels"]``), and the conversion of any label sequence into
transitions.  A change between frames ``f - 1`` and ``f`` is a transition at ``f``
(0-based), accepted within +/- ``tolerance`` frames.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from rtseg.labels.types import (DEFAULT_TOLERANCE, LabelError, Transition, TransitionLabels,
                                integer_label)

if TYPE_CHECKING:  # pragma: no cover
    from rtseg.core.take import Take


def transitions_from_frame_labels(labels: Sequence[int] | np.ndarray, *, step: int = 1,
                                  tolerance: int = DEFAULT_TOLERANCE,
                                  n_frames: int | None = None,
                                  names: dict[int, str] | None = None) -> list[Transition]:
    """Transitions where a label sequence changes value.

    labels: one label per ``step`` frames (step=1: per frame; step=12: mocap6 blocks).
    A change between entries ``b - 1`` and ``b`` is a transition at frame ``step * b``,
    accepted within ``[f - tolerance, f + tolerance]`` clipped to the take
    (``n_frames``, default ``len(labels) * step``).
    """
    arr = np.asarray(labels)
    if arr.ndim != 1:
        raise ValueError(f"labels must be 1-D, got shape {arr.shape}")
    if tolerance < 0 or step < 1:
        raise ValueError("tolerance must be >= 0 and step >= 1")
    last = (n_frames if n_frames is not None else len(arr) * step) - 1
    change = np.flatnonzero(arr[1:] != arr[:-1]) + 1
    names = names or {}
    out = []
    for b in change:
        f = int(b) * step
        a, z = arr[b - 1].item(), arr[b].item()
        out.append(Transition(max(0, f - tolerance), max(f, min(last, f + tolerance)), f,
                              names.get(a, str(a)), names.get(z, str(z))))
    return out

def read_frame_label_column(path: str | Path, column: int = 4) -> np.ndarray:
    """The integer label column (0-based ``column``, default the 5th) of a headerless CSV,
    one label per frame; LabelError naming the line of a missing or non-integer label."""
    path = Path(path)
    out = []
    with open(path, encoding="utf-8-sig") as fh:
        for lineno, line in enumerate(fh, start=1):
            line = line.strip()
            if not line:
                continue
            parts = line.split(",")
            if len(parts) <= column:
                raise LabelError(path, lineno, f"expected at least {column + 1} columns, got {len(parts)}")
            tok = parts[column].strip()
            value = integer_label(tok)
            if value is None:
                raise LabelError(path, lineno, f"label must be an integer, got {tok!r}")
            out.append(value)
    if not out:
        raise LabelError(path, None, "no rows")
    return np.asarray(out, dtype=np.int64)


def read_frame_labels(path: str | Path, *, column: int = 4,
                      tolerance: int = DEFAULT_TOLERANCE) -> TransitionLabels:
    """Transitions from the per-frame label column of a CSV (tsseg4d layout)."""
    path = Path(path)
    labels = read_frame_label_column(path, column)
    return TransitionLabels(take=path.stem,
                            transitions=transitions_from_frame_labels(labels, tolerance=tolerance),
                            n_frames=int(labels.size), kind="tolerance", tolerance=tolerance,
                            source=f"{path.parent.name}/{path.name} column {column + 1}")


def labels_from_take(take: "Take", *, tolerance: int = DEFAULT_TOLERANCE) -> TransitionLabels | None:
    """Transitions from ``take.meta["frame_labels"]`` (set by readers of labelled formats),
    or None when the take carries no per-frame labels."""
    fl = take.meta.get("frame_labels")
    if fl is None:
        return None
    fl = np.asarray(fl)
    if fl.shape != (take.n_frames,):
        raise ValueError(f"frame_labels of {take.source or '<memory>'} has shape {fl.shape}, "
                         f"take has {take.n_frames} frames")
    return TransitionLabels(take=Path(take.source).stem if take.source else "",
                            transitions=transitions_from_frame_labels(fl, tolerance=tolerance),
                            n_frames=take.n_frames, kind="tolerance", tolerance=tolerance,
                            source="per-frame labels of the take")


__all__ = ["transitions_from_frame_labels", "read_frame_label_column", "read_frame_labels",
           "labels_from_take"]
