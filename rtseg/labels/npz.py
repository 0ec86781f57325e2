"""Reader of the transition ranges an rtseg ``.npz`` take carries in its own meta (spliced
performances, saved synthetic takes).  Frames are 0-based.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rtseg.labels.types import LabelError, Transition, TransitionLabels


def read_take_transitions(path: str | Path) -> TransitionLabels | None:
    """The transition ranges an rtseg ``.npz`` take carries itself, or None when it carries
    none (it is then not a labelled take).

    ``meta["transitions"]`` (in ``meta_json``) lists ``[lo, mid, hi, before, after]``
    (0-based frames, ``[lo, hi]`` the accepted range: for a spliced performance
    (``rtseg.evaluation.splice``) the cross-fade span, for a saved synthetic take its blend span);
    ``meta["frame_labels"]`` (``meta__frame_labels``) one label per frame.  Both are
    checked against each other: the labels must change exactly at the ``mid`` frames and
    nowhere else, ranges must be ordered and inside the take - else :class:`LabelError`.
    Only these two arrays are read, not the motion.
    """
    import json
    import zipfile
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            if "meta_json" not in z.files:
                return None
            meta = json.loads(str(z["meta_json"].item()))
            if "transitions" not in meta:
                return None
            if "meta__frame_labels" not in z.files:
                raise LabelError(path, None, "meta transitions without meta__frame_labels")
            fl = np.asarray(z["meta__frame_labels"])
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        if isinstance(exc, LabelError):
            raise
        raise LabelError(path, None, f"not a readable .npz take ({exc})") from None
    if fl.ndim != 1 or fl.size == 0:
        raise LabelError(path, None, f"frame_labels must be 1-D and non-empty, got shape {fl.shape}")
    out: list[Transition] = []
    for i, t in enumerate(meta["transitions"]):
        try:
            lo, mid, hi = (int(v) for v in t[:3])
            before, after = (str(v) for v in (list(t[3:5]) + ["", ""])[:2])
            tr = Transition(lo, hi, mid, before, after)
        except (TypeError, ValueError) as exc:
            raise LabelError(path, None, f"transition {i} {t!r}: {exc}") from None
        if not (0 <= tr.lo and tr.hi < fl.size) or (out and tr.lo <= out[-1].hi):
            raise LabelError(path, None, f"transition {i} [{tr.lo}, {tr.hi}] is outside the take "
                             f"of {fl.size} frames or overlaps the previous one")
        out.append(tr)
    changes = (np.flatnonzero(fl[1:] != fl[:-1]) + 1).tolist()
    if changes != [t.mid for t in out]:
        raise LabelError(path, None, f"frame labels change at {changes[:6]}..., the transitions' "
                         f"mids are {[t.mid for t in out][:6]}...")
    return TransitionLabels(take=path.stem, transitions=out, n_frames=int(fl.size),
                            kind="ranges", source=f"{path.name} meta transitions")



__all__ = ["read_take_transitions"]
