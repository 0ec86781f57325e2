"""Reader of ``labels/cmu86_transitions.txt``: human transition ranges per take.

Blocks ``86 NN`` followed by lines ``behaviour lo mid hi`` (1-based frames; each ``n``
becomes ``n - 1``).  ``mid`` is the last frame of the segment named on the line, ``[lo,
hi]`` the range in which the change to the next segment happens; the last line of a block
repeats the trial length and is not a transition.  Inconsistent lines (``lo`` before the
previous boundary, ``lo > mid``, ``mid > hi``) are repaired or rejected with a logged
warning naming the line, or raise :class:`~rtseg.labels.types.LabelError` in strict mode.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from rtseg.labels.types import LabelError, Transition, TransitionLabels

log = logging.getLogger("rtseg.labels.takes")

SLIP_POLICIES = ("repair", "reject", "strict")


#: slip notes already logged (they name file, line and action), so re-reading a file
#: does not repeat them
_warned: set[str] = set()

_BLOCK_RE = re.compile(r"^\s*(\d+)\s+(\d+)\s*$")


def _check_policy(strict: bool, on_slip: str) -> str:
    if strict:
        return "strict"
    if on_slip not in SLIP_POLICIES:
        raise ValueError(f"on_slip must be one of {SLIP_POLICIES}, not {on_slip!r}")
    return on_slip


def warn_repairs(labels: TransitionLabels) -> None:
    """Log each slip note of ``labels.repairs`` as a warning, once per process."""
    for note in labels.repairs:
        if note not in _warned:
            _warned.add(note)
            log.warning("label slip %s", note)


def read_cmu86_transitions(path: str | Path, *, strict: bool = False,
                           on_slip: str = "repair", warn: bool = True
                           ) -> dict[str, TransitionLabels]:
    """Read a ``cmu86_transitions.txt``-style file: {take name "SS_TT": TransitionLabels}.

    on_slip: what to do with an inconsistent line -
      ``"repair"`` (default): ``lo > mid`` or ``mid > hi`` -> the three numbers are sorted so
      lo <= mid <= hi; ``lo`` before the previous line's boundary (its ``mid``) -> ``lo`` is
      set to this line's ``mid`` (the only end of the range still credible; another copy of
      86_04 reads ``5052 5052 5092``, the same shape).  A line whose ``mid`` is not after
      the previous ``mid`` cannot be repaired and is rejected.
      ``"reject"``: the inconsistent line's transition is dropped (the segment names stay).
      ``"strict"`` (or ``strict=True``): raise :class:`LabelError` naming file and line.
    Every repair or rejection is listed in ``TransitionLabels.repairs`` and (``warn``,
    the default) logged as a warning naming the file line and block line, once per
    process; ``warn=False`` leaves the logging to the caller (:func:`warn_repairs`), so
    a command warns only about the blocks of the takes it uses.
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
        if warn:
            warn_repairs(out[name])
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
        repairs.append(f"{where}: {problem}; {action}")

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



def _looks_like_ranges(path: Path) -> bool:
    """True when the file's first non-blank line is a ``SS TT`` block header."""
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for line in fh:
            if line.strip():
                return bool(_BLOCK_RE.match(line))
    return False


__all__ = ["SLIP_POLICIES", "read_cmu86_transitions", "load_cmu86_transitions"]
