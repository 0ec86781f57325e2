"""Human labels of behaviour transitions, and the pairing of labelled takes with their motion.

Frame convention
----------------
Every frame number here is **0-based** at the take's own frame rate (120 fps for CMU data),
the same numbering as ``Take.quats[i]`` and ``Cut.frame``.  A :class:`Transition` is the
range ``[lo, hi]`` (both inclusive) of cut frames that count as a correct detection of one
behaviour change; ``mid`` is the labelled boundary itself.

Three label formats are read (see ``../shared/data/README.md``):

* ``labels/cmu86_transitions.txt`` - blocks ``86 NN`` followed by lines
  ``behaviour lo mid hi`` (1-based frames).  ``mid`` is the last frame of the segment named
  on the line, ``[lo, hi]`` the range in which the change to the next segment happens; the
  last line of a block repeats the trial length and is not a transition.  Each 1-based
  number ``n`` becomes ``n - 1``.  Inconsistent lines (``lo`` before the previous boundary,
  ``lo > mid``, ``mid > hi``) are repaired or rejected with a logged warning naming the
  line, or raise :class:`LabelError` in strict mode - never silently.
* ``labels/mocap6/SS_TT.txt`` - one integer label per 12-frame block (whitespace separated);
  block ``b`` starts at frame ``12 b``; a change of label between blocks ``b - 1`` and ``b``
  is a transition at frame ``12 b``, correct within +/- 60 frames.
* per-frame labels (the 5th column of a tsseg4d CSV, or ``take.meta["frame_labels"]``) -
  a change between frames ``f - 1`` and ``f`` is a transition at ``f``, +/- 60 frames.

Modules: :mod:`rtseg.labels.types` (Transition, TransitionLabels, LabelError), one reader
per format - :mod:`rtseg.labels.cmu86`, :mod:`rtseg.labels.mocap6`,
:mod:`rtseg.labels.frames` (per-frame labels), :mod:`rtseg.labels.npz` (ranges an rtseg
take carries) - and this one (pairing labelled takes with their motion, reading a label
file of any format).  Their public names are importable from here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

from rtseg.labels import cmu86 as _cmu86
from rtseg.labels import mocap6 as _mocap6
from rtseg.labels.cmu86 import (SLIP_POLICIES, _looks_like_ranges, load_cmu86_transitions,
                                read_cmu86_transitions)
from rtseg.labels.frames import (labels_from_take, read_frame_label_column, read_frame_labels,
                                 transitions_from_frame_labels)
from rtseg.labels.mocap6 import MOCAP6_BLOCK, MOCAP6_NAMES, read_block_labels
from rtseg.labels.npz import read_take_transitions
from rtseg.labels.types import DEFAULT_TOLERANCE, LabelError, Transition, TransitionLabels

if TYPE_CHECKING:  # pragma: no cover
    from rtseg.core.take import Take

log = logging.getLogger(__name__)

# Private names other modules read from here: the logged-slip set (tests clear it) and
# the integer tokenizer (rtseg.evaluation.identity).
_warned = _cmu86._warned
_int_tokens = _mocap6._int_tokens

# --------------------------------------------------------------------------- pairing

#: "spliced": rtseg .npz takes carrying their own transition ranges (``rtseg.evaluation.splice``),
#: found in the data folder itself or its ``spliced/`` subfolder.
GROUPS = ("cmu", "tsseg4d", "spliced")
_MOTION_SUFFIXES = (".amc", ".bvh", ".npz")


@dataclass
class LabelledTake:
    """A motion file with the transitions to score it against.

    name: take name "SS_TT".  group: "cmu" (full-rotation takes) or "tsseg4d".
    motion: the motion file; skeleton: its ASF (AMC takes) or None.
    labels: the transitions and where they came from (``labels.description``).
    """
    name: str
    group: str
    motion: Path
    skeleton: Path | None
    labels: TransitionLabels

    @property
    def transitions(self) -> list[Transition]:
        return self.labels.transitions

    @property
    def label_source(self) -> str:
        return self.labels.description

    def load(self) -> "Take":
        """Read the motion (``rtseg.core.take.read_take``)."""
        from rtseg.drivers.readers import read_take
        return read_take(self.motion, skeleton=self.skeleton)


def _take_name(path: Path) -> str:
    return path.stem


def _subject(name: str) -> str:
    return name.split("_", 1)[0]


def is_source_folder(path: str | Path) -> bool:
    """Whether ``path`` is a folder of single-behaviour takes laid out like
    ``../shared/data/cmu_single``, ``hdm05`` or ``bandai``: an ``index.tsv`` beside ``bvh/``
    or ``amc/`` (the ``index.tsv`` of spliced performances has neither beside it)."""
    p = Path(path)
    return (p / "index.tsv").is_file() and ((p / "bvh").is_dir() or (p / "amc").is_dir())


def no_takes_hint(data_dir: str | Path) -> str:
    """What to say after "no labelled takes in ``data_dir``": when the folder, or a folder
    in it, holds single-behaviour takes (:func:`is_source_folder`), that they have no
    transitions to score and how to splice them into performances that do; when it is a
    ``cmu/`` or ``tsseg4d/`` folder whose labels lie in its parent's ``labels/``, to give
    the parent; else "" ."""
    root = Path(data_dir)
    subs = sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
    for src in (root, *subs):
        if is_source_folder(src):
            return (f"; {src} holds single-behaviour takes (no transitions to score): "
                    f"splice them into labelled performances with `python3 "
                    f"benchmarks/splice.py {src} OUT` (rtseg.evaluation.splice.generate) and "
                    f"evaluate OUT")
    if root.name in ("cmu", "tsseg4d") and (root.parent / "labels").is_dir() \
            and not (root / "labels").is_dir():
        return (f"; the labels of {root.name}/ are in {root.parent / 'labels'}: give the "
                f"folder that holds both, {root.parent}")
    return ""


def find_labelled_takes(data_dir: str | Path, groups: Iterable[str] = GROUPS, *,
                        strict: bool = False, on_slip: str = "repair",
                        tolerance: int = DEFAULT_TOLERANCE) -> list[LabelledTake]:
    """Every labelled take in a folder laid out like ``../shared/data``.

    ``cmu/SS_TT.amc`` (skeleton ``cmu/SS.asf``; also ``.bvh`` / ``.npz`` takes) is paired with
    its block of ``labels/cmu86_transitions.txt`` when there is one, else with
    ``labels/mocap6/SS_TT.txt`` (+/- ``tolerance``); group "cmu".
    ``tsseg4d/SS_TT.csv`` is paired with its ``cmu86_transitions.txt`` block when there is
    one, else with its own per-frame label column (+/- ``tolerance``); group "tsseg4d".
    ``*.npz`` takes in the folder itself or in ``spliced/`` that carry their own transition
    ranges (:func:`read_take_transitions`; spliced performances) form group "spliced".
    Motion files without labels are skipped with a warning.  Sorted by group, then name.
    Label slips (:func:`read_cmu86_transitions`) are warned about for the blocks of the
    takes returned only.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"data folder {root} does not exist")
    groups = tuple(groups)
    for g in groups:
        if g not in GROUPS:
            raise ValueError(f"unknown group {g!r}; choose from {GROUPS}")
    ranges: dict[str, TransitionLabels] = {}
    for f in sorted((root / "labels").glob("*transitions*.txt")):
        for k, v in read_cmu86_transitions(f, strict=strict, on_slip=on_slip,
                                           warn=False).items():
            if k in ranges:
                log.warning("%s: block %s already read from %s; ignored", f, k, ranges[k].source)
                continue
            ranges[k] = v
    mocap6 = root / "labels" / "mocap6"

    found: list[LabelledTake] = []
    if "cmu" in groups and (root / "cmu").is_dir():
        for path in sorted((root / "cmu").iterdir()):
            if path.suffix.lower() not in _MOTION_SUFFIXES or not path.is_file():
                continue
            name = _take_name(path)
            skeleton = None
            if path.suffix.lower() == ".amc":
                cand = [p for p in path.parent.iterdir()
                        if p.suffix.lower() == ".asf" and p.stem in (_subject(name), name)]
                if not cand:
                    log.warning("%s: no skeleton %s.asf beside it; skipped", path, _subject(name))
                    continue
                skeleton = sorted(cand, key=lambda p: p.stem != name)[0]
            labels = ranges.get(name)
            if labels is None and (mocap6 / f"{name}.txt").is_file():
                labels = read_block_labels(mocap6 / f"{name}.txt", tolerance=tolerance)
            if labels is None:
                log.warning("%s: no labels found (%s block or labels/mocap6/%s.txt); skipped",
                            path, name, name)
                continue
            found.append(LabelledTake(name, "cmu", path, skeleton, labels))
    if "tsseg4d" in groups and (root / "tsseg4d").is_dir():
        for path in sorted(p for p in (root / "tsseg4d").iterdir()
                           if p.suffix.lower() == ".csv" and p.is_file()):
            name = _take_name(path)
            labels = ranges.get(name)
            if labels is None:
                labels = read_frame_labels(path, tolerance=tolerance)
            found.append(LabelledTake(name, "tsseg4d", path, None, labels))
    if "spliced" in groups:
        for folder in (root, root / "spliced"):
            for path in sorted(p for p in folder.glob("*.npz") if p.is_file()) if folder.is_dir() else ():
                labels = read_take_transitions(path)
                if labels is None:
                    log.warning("%s: no transition ranges in its meta; skipped", path)
                    continue
                found.append(LabelledTake(path.stem, "spliced", path, None, labels))
    found.sort(key=lambda t: (GROUPS.index(t.group), t.name))
    for t in found:                 # slips of the blocks used; the others stay quiet
        _cmu86.warn_repairs(t.labels)
    return found


def read_labels_file(path: str | Path, take_name: str, *,
                     tolerance: int = DEFAULT_TOLERANCE) -> TransitionLabels:
    """Labels of take ``take_name`` ("SS_TT") from a label file of any of the three formats,
    told apart by content: a ``.csv`` is per-frame labels (5th column); a file starting
    with an ``SS TT`` block header is a cmu86-style ranges file (the take's block is used);
    otherwise integers per 12-frame block (mocap6)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"label file not found: {path}")
    if path.suffix.lower() == ".csv":
        return read_frame_labels(path, tolerance=tolerance)
    if _looks_like_ranges(path):
        blocks = read_cmu86_transitions(path, warn=False)
        if take_name not in blocks:
            raise LabelError(path, None, f"no block for take {take_name} "
                             f"(blocks: {', '.join(sorted(blocks)) or 'none'})")
        _cmu86.warn_repairs(blocks[take_name])
        return blocks[take_name]
    return read_block_labels(path, tolerance=tolerance)


def find_labels_for(motion: str | Path, *, tolerance: int = DEFAULT_TOLERANCE
                    ) -> TransitionLabels | None:
    """Labels of a motion file found by the ``../shared/data`` layout, or None.

    Looks (in this order) for the take's block in ``<root>/labels/*transitions*.txt``, for
    ``<root>/labels/mocap6/<take>.txt`` (root = the folder above the motion's folder, or the
    motion's own folder), for per-frame labels in a tsseg4d ``.csv`` motion itself, and for
    the transition ranges an rtseg ``.npz`` take carries in its meta (synthetic, spliced).
    """
    motion = Path(motion)
    name = motion.stem
    for root in (motion.parent.parent, motion.parent):
        for f in sorted((root / "labels").glob("*transitions*.txt")):
            blocks = read_cmu86_transitions(f, warn=False)
            if name in blocks:
                _cmu86.warn_repairs(blocks[name])
                return blocks[name]
        m6 = root / "labels" / "mocap6" / f"{name}.txt"
        if m6.is_file():
            return read_block_labels(m6, tolerance=tolerance)
    if motion.suffix.lower() == ".csv":
        return read_frame_labels(motion, tolerance=tolerance)
    if motion.suffix.lower() == ".npz":     # ranges the take carries (as rtseg evaluate reads)
        return read_take_transitions(motion)
    return None


__all__ = [
    "DEFAULT_TOLERANCE", "MOCAP6_BLOCK", "MOCAP6_NAMES", "SLIP_POLICIES", "LabelError",
    "Transition", "TransitionLabels", "read_cmu86_transitions", "load_cmu86_transitions",
    "transitions_from_frame_labels", "read_block_labels", "read_frame_label_column",
    "read_frame_labels", "labels_from_take", "read_take_transitions", "GROUPS",
    "LabelledTake", "find_labelled_takes", "read_labels_file", "find_labels_for",
]
