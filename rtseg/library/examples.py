"""Labelled examples for a behaviour library (``rtseg learn``), from takes or data folders.

Every example's feature rows are the rows the live pipeline feeds its detectors on the
take (``rtseg.evaluation.online.fed_features``: the session configuration's profile and
calibration), so a library learned here describes what ``rtseg live`` sees.  Frames are
0-based take frames; a labelled range is [a, b).

Sources of labels (``examples_from_dir``):

- a source folder with ``index.tsv`` laid out like ``../shared/data/cmu_single``,
  ``hdm05`` or ``bandai``, or a folder holding such folders: each take one behaviour of one
  person, any format, rig and frame rate (``rtseg.library.sources``: short clips of one
  person and behaviour joined);
- a folder laid out like ``../shared/data``: also the labelled takes of ``rtseg.labels.takes``
  (cmu86 behaviour names, mocap6 exercise names - ``MOCAP6_NAMES`` -, tsseg4d label ids,
  spliced performances' behaviour names), each run of one label one example.

Every example carries a content ``key`` (``rtseg.library.sources.motion_key``): ``learn``
keeps one example per key, and ``rtseg learn`` adds none already in the library.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from rtseg.library.behaviours import DEFAULT_METRIC, Library
from rtseg.library.builder import LibraryBuilder

log = logging.getLogger(__name__)


@dataclass
class Example:
    """One labelled range of one take's live feature rows.  ``person``: who performs
    (the subject), ``take``: the take's name, ``frames``: [a, b) in take frames."""
    name: str
    take: str
    person: str
    X: np.ndarray                    # the take's fed feature rows
    index: np.ndarray                # take frame of each row
    frames: tuple[int, int]
    profile: str
    frame_rate: float
    key: str = ""                    # content hash of the motion (rtseg.library.sources)
    P: np.ndarray | None = None      # posture rows of X's frames (rtseg.core.posture), or None

    def rows(self) -> tuple[int, int]:
        """[i, j) rows of X covering the take frames [a, b)."""
        a, b = self.frames
        return int(np.searchsorted(self.index, a)), int(np.searchsorted(self.index, b))


def take_rows(take: Any, config: Any) -> tuple[np.ndarray, np.ndarray, str]:
    """(fed rows, take frame per row, feature profile) of a take under ``config``."""
    from rtseg.core.features import PoseFeatures
    from rtseg.evaluation.online import fed_features
    profile = PoseFeatures(take.joint_names, take.parents, take.space,
                           profile=config["features.profile"] or None).profile
    X, index, _ = fed_features(take, config)
    return X, index, profile


def posture_rows(take: Any, index: np.ndarray) -> np.ndarray | None:
    """The posture rows (``rtseg.core.posture``) of the take frames ``index`` (one per fed
    row), or None when the take's rest geometry is unknown or its rig has no posture."""
    from rtseg.core.posture import Posture
    post = Posture.find(take)
    if post is None:
        return None
    idx = np.asarray(index, dtype=np.int64)
    return post.transform(take.quats[idx]) if len(idx) else np.zeros((0, 0))


def example_of_take(path: str | Path, name: str, config: Any,
                    frames: tuple[int, int] | None = None, skeleton: str | None = None,
                    person: str = "", segment: int | None = None) -> Example:
    """An example from a take file (``rtseg.core.take.read_take``): frames [a, b), or segment
    ``segment`` of a session recording as the session numbered it
    (``rtseg.recording.reader.session_segment_frames``), or the whole take without its
    rest frames at the ends."""
    from rtseg.evaluation.blend import trim_bounds
    from rtseg.drivers.readers import read_take
    take = read_take(path, skeleton=skeleton)
    X, index, profile = take_rows(take, config)
    n = take.n_frames
    if segment is not None:
        from rtseg.recording.reader import session_segment_frames
        frames = session_segment_frames(path, segment, n)
    if frames is None:
        frames = trim_bounds(take.quats, take.frame_rate) if take.n_joints > 1 else (0, n)
    a, b = int(frames[0]), int(frames[1])
    if not 0 <= a < b <= n:
        raise ValueError(f"{path}: --frames {a}:{b} outside the take (0:{n})")
    stem = Path(path).stem
    return Example(name, stem, person or stem.split("_")[0], X, index, (a, b), profile,
                   float(take.frame_rate), motion_key(take, a, b), posture_rows(take, index))


def synthetic_examples(behaviours: Sequence[str], seeds: Sequence[int], config: Any,
                       seconds: float = 8.0, frame_rate: float = 120.0) -> list[Example]:
    """Examples of ``behaviours`` performed by synthetic performers
    (``rtseg.simulators.synth.motion``), one performance of ``seconds`` per behaviour each per
    seed (a seed varies tempo, amplitude and style: a performer of its own, ``person``
    ``synth<seed>``), as ``rtseg learn`` would take them from those performances' takes."""
    from rtseg.simulators.synth.motion import synthesize
    script = ",".join(f"{b}:{seconds:g}" for b in behaviours)
    out: list[Example] = []
    for seed in seeds:
        res = synthesize(script, frame_rate=frame_rate, seed=int(seed))
        X, index, profile = take_rows(res.take, config)
        P = posture_rows(res.take, index)
        for a, b, name in label_runs(res.frame_names()):
            out.append(Example(name, f"synth{seed}", f"synth{seed}", X, index, (a, b),
                               profile, float(frame_rate), motion_key(res.take, a, b), P))
    return out


def label_runs(labels: Sequence[Any]) -> list[tuple[int, int, str]]:
    """[(a, b, label)] runs of equal per-frame labels."""
    lab = [str(v) for v in labels]
    ch = [0] + [i for i in range(1, len(lab)) if lab[i] != lab[i - 1]] + [len(lab)]
    return [(a, b, lab[a]) for a, b in zip(ch[:-1], ch[1:]) if b > a]


def unique_examples(examples: Sequence[Example], known: dict[str, str] | None = None
                    ) -> tuple[list[Example], list[Example]]:
    """(new, repeated): ``examples`` whose ``key`` is neither in ``known`` ({key: name}, a
    library's) nor held by an earlier example of the list, and the others.  Examples
    without a key are always new."""
    seen = dict(known or {})
    new, rep = [], []
    for e in examples:
        if e.key and e.key in seen:
            rep.append(e)
            continue
        if e.key:
            seen[e.key] = e.name
        new.append(e)
    return new, rep


def learn(examples: Sequence[Example], profile: str | None = None,
          threshold: float | None = None, metric: str | None = None,
          **windows: float) -> tuple[Library, list[str]]:
    """A library from ``examples`` of one feature profile (``profile``, default the one
    with the most examples named by a word, then the most examples; examples of other
    profiles are left out and listed).  A library in which a behaviour would be named by a
    number (labels that are only ids, such as the tsseg4d states) is refused: ValueError.
    ``metric``: the library's distance (``rtseg.library.behaviours.METRICS``; default
    ``DEFAULT_METRIC``).  ``windows``: ``LibraryBuilder`` window options.  Examples of any
    frame rate mix (the library's ``frame_rate`` is the most common one); an example of the
    same ``key`` as an earlier one is learned once (noted).  Returns (library, notes)."""
    if not examples:
        raise ValueError("no labelled examples to learn from")
    if profile is None:
        counts: dict[str, tuple[int, int]] = {}
        for e in examples:
            named, n = counts.get(e.profile, (0, 0))
            counts[e.profile] = (named + (not e.name.isdigit()), n + 1)
        profile = max(counts, key=lambda p: (*counts[p], p))
    use = [e for e in examples if e.profile == profile]
    other: dict[tuple[str, str], int] = {}          # (take, profile) -> examples left out
    for e in examples:
        if e.profile != profile:
            other[(e.take, e.profile)] = other.get((e.take, e.profile), 0) + 1
    notes = [f"{t}: {n} example(s) of feature profile {p!r}, not {profile!r}; left out"
             for (t, p), n in other.items()]
    if not use:
        raise ValueError(f"no example has feature profile {profile!r} "
                         f"(they have {', '.join(sorted({e.profile for e in examples}))})")
    numbered = sorted({e.name for e in use if e.name.isdigit()}, key=int)
    if numbered:
        raise ValueError(f"{len(numbered)} behaviour(s) would be named by a number "
                         f"({', '.join(numbered[:5])}{', ...' if len(numbered) > 5 else ''}: "
                         f"labels that are only ids); learn from takes whose labels name "
                         f"the behaviours, or leave those takes out")
    use, repeated = unique_examples(use)
    notes += [f"{e.take} [{e.frames[0]}:{e.frames[1]}) {e.name}: the same motion as an "
              f"earlier example; learned once" for e in repeated]
    rates = [e.frame_rate for e in use]
    rate = max(set(rates), key=lambda r: (rates.count(r), r))
    use, short = learnable(use, **windows)
    notes += short
    if not use:
        raise ValueError("no example long enough to learn from"
                         + (f" ({'; '.join(short[:3])})" if short else ""))
    b = LibraryBuilder(profile, use[0].X.shape[1], rate, **windows)
    for e in use:
        i, j = e.rows()
        b.add(e.X[i:j], e.name, e.take, None, e.frame_rate,
              info={"frames": list(e.frames), "person": e.person,
                    "frame_rate": round(float(e.frame_rate), 2),
                    **({"key": e.key} if e.key else {})},
              posture=None if e.P is None else e.P[i:j])
    notes += b.skipped
    return b.build(threshold, metric or DEFAULT_METRIC), notes


def learnable(examples: Sequence[Example], **windows: float) -> tuple[list[Example], list[str]]:
    """The examples long enough to give at least one library window (``LibraryBuilder``
    window options ``windows``, its defaults for the others), and a note for each of the
    others, in take frames."""
    b = LibraryBuilder("", 1, 1.0, **windows)
    keep, notes = [], []
    for e in examples:
        i, j = e.rows()
        if b.windows(0, j - i, e.frame_rate):
            keep.append(e)
        else:
            notes.append(b.too_short(e.take, e.frames[0], e.frames[1], e.name))
    return keep, notes


def motion_key(take: Any, a: int, b: int) -> str:
    """Content hash (16 hex digits) of frames [a, b) of ``take``: joint names, frame rate
    (to 0.01 Hz) and the rotations, rounded to 1e-6."""
    h = hashlib.sha256()
    h.update("\x1f".join(map(str, take.joint_names)).encode())
    h.update(f"|{float(take.frame_rate):.2f}|".encode())
    q = np.round(np.asarray(take.quats[a:b], dtype=np.float64), 6) + 0.0   # -0.0 -> 0.0
    h.update(np.ascontiguousarray(q).tobytes())
    return h.hexdigest()[:16]


def joined_key(keys: Iterable[str]) -> str:
    """Key of an example joined from takes of these keys (in order)."""
    return hashlib.sha256("+".join(keys).encode()).hexdigest()[:16]
