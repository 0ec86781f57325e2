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
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Sequence

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from rtseg.take import Take

log = logging.getLogger(__name__)

#: Tolerance (frames) around a point label: 0.5 s at 120 fps, as the data README asks.
DEFAULT_TOLERANCE = 60
#: Frames per label block in ``labels/mocap6`` (10 labels per second at 120 fps).
MOCAP6_BLOCK = 12
#: Exercise names of the mocap6 label integers.
MOCAP6_NAMES = {
    1: "JumpJack", 2: "Jog", 3: "Squat", 4: "KneeRaise", 5: "ArmCircle", 6: "Twist",
    7: "SideReach", 8: "Box", 9: "UpDown", 10: "ToeTouchOneHand", 11: "SideBend",
    12: "ToeTouchTwoHands",
}

SLIP_POLICIES = ("repair", "reject", "strict")


class LabelError(ValueError):
    """A label file that cannot be read as asked; the message names file and line."""

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = str(path)
        self.line = line
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {message}")


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


# --------------------------------------------------------------------------- cmu86 ranges

#: (file, line, policy) of slips already logged, so re-reading a file does not repeat them.
_warned: set[tuple[str, int, str]] = set()

_BLOCK_RE = re.compile(r"^\s*(\d+)\s+(\d+)\s*$")


def _check_policy(strict: bool, on_slip: str) -> str:
    if strict:
        return "strict"
    if on_slip not in SLIP_POLICIES:
        raise ValueError(f"on_slip must be one of {SLIP_POLICIES}, not {on_slip!r}")
    return on_slip


def read_cmu86_transitions(path: str | Path, *, strict: bool = False,
                           on_slip: str = "repair") -> dict[str, TransitionLabels]:
    """Read a ``cmu86_transitions.txt``-style file: {take name "SS_TT": TransitionLabels}.

    on_slip: what to do with an inconsistent line -
      ``"repair"`` (default): ``lo > mid`` or ``mid > hi`` -> the three numbers are sorted so
      lo <= mid <= hi; ``lo`` before the previous line's boundary (its ``mid``) -> ``lo`` is
      set to this line's ``mid`` (the only end of the range still credible; another copy of
      86_04 reads ``5052 5052 5092``, the same shape).  A line whose ``mid`` is not after
      the previous ``mid`` cannot be repaired and is rejected.
      ``"reject"``: the inconsistent line's transition is dropped (the segment names stay).
      ``"strict"`` (or ``strict=True``): raise :class:`LabelError` naming file and line.
    Every repair or rejection is logged as a warning naming the file line and block line,
    and listed in ``TransitionLabels.repairs``.
    """
    policy = _check_policy(strict, on_slip)
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise LabelError(path, None, f"not UTF-8 text ({exc})") from None

    blocks: dict[str, list[tuple[int, int, str, list[int]]]] = {}
    current: list[tuple[int, int, str, list[int]]] | None = None
    name = ""
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        m = _BLOCK_RE.match(line)
        if m:
            name = f"{int(m.group(1)):02d}_{int(m.group(2)):02d}"
            if name in blocks:
                raise LabelError(path, lineno, f"block {name} appears twice")
            current = blocks[name] = []
            continue
        parts = line.split()
        if current is None:
            raise LabelError(path, lineno, f"segment line before any 'SS TT' block header: {line!r}")
        if len(parts) != 4:
            raise LabelError(path, lineno, f"expected 'behaviour lo mid hi', got {line!r}")
        try:
            nums = [int(p) for p in parts[1:]]
        except ValueError:
            raise LabelError(path, lineno, f"frame numbers must be integers: {line!r}") from None
        if min(nums) < 1:
            raise LabelError(path, lineno, f"frame numbers are 1-based, got {nums}")
        current.append((lineno, len(current) + 1, parts[0], nums))

    out: dict[str, TransitionLabels] = {}
    for name, lines in blocks.items():
        if len(lines) < 1:
            raise LabelError(path, None, f"block {name} has no segment lines")
        out[name] = _block_transitions(path, name, lines, policy)
    return out


def _block_transitions(path: Path, name: str, lines: list[tuple[int, int, str, list[int]]],
                       policy: str) -> TransitionLabels:
    """Turn one block's lines into transitions, handling slips by ``policy``."""
    repairs: list[str] = []
    transitions: list[Transition] = []
    prev_mid = 0  # 1-based boundary of the previous segment (0 = start of take)

    def slip(lineno: int, blockline: int, problem: str, action: str) -> None:
        where = f"{path.name}:{lineno} ({name} line {blockline})"
        if policy == "strict":
            raise LabelError(path, lineno, f"{name} line {blockline}: {problem}")
        note = f"{where}: {problem}; {action}"
        key = (str(path.resolve()), lineno, policy)
        if key not in _warned:  # once per process and file line; always in ``repairs``
            _warned.add(key)
            log.warning("label slip %s", note)
        repairs.append(note)

    *segments, last = lines
    for idx, (lineno, blockline, behaviour, (lo, mid, hi)) in enumerate(segments):
        after = lines[idx + 1][2]
        keep = True
        if lo > mid or mid > hi:
            problem = f"lo {lo} > mid {mid}" if lo > mid else f"mid {mid} > hi {hi}"
            if policy == "repair":
                new = sorted((lo, mid, hi))
                slip(lineno, blockline, problem,
                     f"reordered {lo} {mid} {hi} -> {new[0]} {new[1]} {new[2]} so lo <= mid <= hi")
                lo, mid, hi = new
            else:
                slip(lineno, blockline, problem, "line rejected")
                keep = False
        if keep and lo <= prev_mid:
            problem = f"lo {lo} lies before the previous boundary (mid {prev_mid})"
            if policy == "repair" and mid > prev_mid:
                slip(lineno, blockline, problem, f"lo set to this line's mid {mid}")
                lo = mid
            else:
                slip(lineno, blockline, problem, "line rejected")
                keep = False
        if not keep:
            continue
        prev_mid = mid
        transitions.append(Transition(lo - 1, hi - 1, mid - 1, behaviour, after))

    lineno, blockline, _, (lo, mid, hi) = last
    n_frames = max(lo, mid, hi)
    if not lo == mid == hi:
        slip(lineno, blockline, f"last line should repeat the trial length, got {lo} {mid} {hi}",
             f"trial length taken as {n_frames}")
    if transitions and n_frames <= transitions[-1].mid:
        slip(lineno, blockline, f"trial length {n_frames} is not after the last boundary",
             "trial length unknown")
        n_frames = None
    return TransitionLabels(take=name, transitions=transitions, n_frames=n_frames,
                            kind="ranges", source=f"{path.name} block {name.replace('_', ' ')}",
                            repairs=repairs)


def load_cmu86_transitions(path: str | Path, *, strict: bool = False,
                           on_slip: str = "repair") -> dict[str, list[Transition]]:
    """{take name: transitions} of a ``cmu86_transitions.txt`` file (see
    :func:`read_cmu86_transitions` for the slip policies)."""
    return {k: v.transitions for k, v in
            read_cmu86_transitions(path, strict=strict, on_slip=on_slip).items()}


# --------------------------------------------------------------------------- point labels

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


def _int_tokens(path: Path, text: str) -> np.ndarray:
    """Whitespace-separated integers; LabelError naming the line of the first bad token."""
    values = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        for tok in line.split():
            try:
                values.append(int(tok))
            except ValueError:
                try:
                    fv = float(tok)
                except ValueError:
                    fv = None
                if fv is None or fv != int(fv):
                    raise LabelError(path, lineno, f"expected an integer label, got {tok!r}") from None
                values.append(int(fv))
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
            try:
                out.append(int(tok))
            except ValueError:
                try:
                    fv = float(tok)
                except ValueError:
                    fv = float("nan")
                if not np.isfinite(fv) or fv != int(fv):
                    raise LabelError(path, lineno, f"label must be an integer, got {tok!r}") from None
                out.append(int(fv))
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


def read_take_transitions(path: str | Path) -> TransitionLabels | None:
    """The transition ranges an rtseg ``.npz`` take carries itself, or None when it carries
    none (it is then not a labelled take).

    ``meta["transitions"]`` (in ``meta_json``) lists ``[lo, mid, hi, before, after]``
    (0-based frames, ``[lo, hi]`` the accepted range: for a spliced performance
    (``rtseg.splice``) the cross-fade span, for a saved synthetic take its blend span);
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


# --------------------------------------------------------------------------- pairing

#: "spliced": rtseg .npz takes carrying their own transition ranges (``rtseg.splice``),
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
        """Read the motion (``rtseg.take.load_take``)."""
        from rtseg.take import load_take
        return load_take(self.motion, skeleton=self.skeleton)


def _take_name(path: Path) -> str:
    return path.stem


def _subject(name: str) -> str:
    return name.split("_", 1)[0]


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
        for k, v in read_cmu86_transitions(f, strict=strict, on_slip=on_slip).items():
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
    return found


def _looks_like_ranges(path: Path) -> bool:
    """True when the file's first non-blank line is a ``SS TT`` block header."""
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for line in fh:
            if line.strip():
                return bool(_BLOCK_RE.match(line))
    return False


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
        blocks = read_cmu86_transitions(path)
        if take_name not in blocks:
            raise LabelError(path, None, f"no block for take {take_name} "
                             f"(blocks: {', '.join(sorted(blocks)) or 'none'})")
        return blocks[take_name]
    return read_block_labels(path, tolerance=tolerance)


def find_labels_for(motion: str | Path, *, tolerance: int = DEFAULT_TOLERANCE
                    ) -> TransitionLabels | None:
    """Labels of a motion file found by the ``../shared/data`` layout, or None.

    Looks (in this order) for the take's block in ``<root>/labels/*transitions*.txt``, for
    ``<root>/labels/mocap6/<take>.txt`` (root = the folder above the motion's folder, or the
    motion's own folder), and for per-frame labels in a tsseg4d ``.csv`` motion itself.
    """
    motion = Path(motion)
    name = motion.stem
    for root in (motion.parent.parent, motion.parent):
        for f in sorted((root / "labels").glob("*transitions*.txt")):
            blocks = read_cmu86_transitions(f)
            if name in blocks:
                return blocks[name]
        m6 = root / "labels" / "mocap6" / f"{name}.txt"
        if m6.is_file():
            return read_block_labels(m6, tolerance=tolerance)
    if motion.suffix.lower() == ".csv":
        return read_frame_labels(motion, tolerance=tolerance)
    return None
