"""Per-frame human behaviour labels of a labelled take, as strings: the ground truth that
behaviour ids and library names are scored against, and the labelled runs a behaviour
library learns from.

- cmu86 ranges (``labels/cmu86_transitions.txt``): the behaviour names, segment k being
  the frames after the previous ``mid`` up to its own ``mid``;
- mocap6 (``labels/mocap6``): the exercise number of each 12-frame block (``MOCAP6_NAMES``
  gives their names);
- tsseg4d: the CSV's own per-frame label column.
"""

from __future__ import annotations

import numpy as np

from rtseg.labels.takes import MOCAP6_BLOCK, LabelledTake, read_frame_label_column, _int_tokens


#: mocap6 exercise numbers -> names (../shared/data/README.md)
MOCAP6_NAMES = {"1": "JumpJack", "2": "Jog", "3": "Squat", "4": "KneeRaise",
                "5": "ArmCircle", "6": "Twist", "7": "SideReach", "8": "Box", "9": "UpDown",
                "10": "ToeTouchOneHand", "11": "SideBend", "12": "ToeTouchTwoHands"}


def truth_labels(lt: LabelledTake, n_frames: int) -> np.ndarray:
    """Per-frame human behaviour labels of a labelled take, as strings (see module doc)."""
    src = lt.labels.source
    if lt.group == "tsseg4d" or (lt.labels.kind == "tolerance" and "column" in src):
        if str(lt.motion).lower().endswith(".csv"):
            lab = read_frame_label_column(lt.motion)
            return _fit_len(np.array([str(v) for v in lab], dtype=object), n_frames)
    if "mocap6" in src:
        path = lt.motion.parent.parent / "labels" / "mocap6" / f"{lt.name}.txt"
        vals = _int_tokens(path, path.read_text(encoding="utf-8-sig"))
        lab = np.repeat(vals, MOCAP6_BLOCK)
        return _fit_len(np.array([str(v) for v in lab], dtype=object), n_frames)
    tr = lt.transitions
    if not tr:
        return np.array(["?"] * n_frames, dtype=object)
    out = np.empty(n_frames, dtype=object)
    prev = 0
    for t in tr:
        out[prev:t.mid + 1] = t.before or f"s{prev}"
        prev = t.mid + 1
    out[prev:] = tr[-1].after or f"s{prev}"
    return out


def named_truth_labels(lt: LabelledTake, n_frames: int) -> np.ndarray:
    """``truth_labels`` with mocap6 exercise numbers as their names (``Jog``, ...): the
    names a behaviour library learned from the labelled takes holds."""
    return np.array([MOCAP6_NAMES.get(str(v), str(v)) for v in truth_labels(lt, n_frames)])


def _fit_len(a: np.ndarray, n: int) -> np.ndarray:
    if len(a) >= n:
        return a[:n]
    return np.concatenate([a, np.repeat(a[-1:], n - len(a))])
