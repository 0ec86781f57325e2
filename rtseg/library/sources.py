"""Library examples from source folders (``rtseg learn LIB --from DIR``), and example keys.

A *source folder* is laid out like ``../shared/data/cmu_single``, ``hdm05`` or ``bandai``:
``index.tsv`` (take, subject, format, behaviour) with the takes in ``bvh/`` or ``amc/``
(``rtseg.evaluation.splice.read_source_index``), any frame rate (cmu_single and hdm05 120 Hz, bandai
30 Hz), any rig whose joints map to the configured feature profile (the canonical skeleton,
``rtseg.core.rig``).  Every take is one behaviour of one person (``subject``); rest frames at
its ends are dropped (``rtseg.evaluation.blend.trim_bounds``).

- A take at least ``min_example_s`` long (after the trim) is one example.
- Shorter takes (HDM05's clips hold ONE squat, one hop: 0.5-7.5 s) of one person, behaviour
  and skeleton are joined in take-name order with the 0.3 s slerp cross-fade the spliced
  performances use (``rtseg.evaluation.splice.SpliceConfig.join_fade_s``), into one example (its
  ``take``: the member names joined by ``+``), as a spliced segment of that behaviour joins
  them.  A lone short take (nothing of its person and behaviour to join it with) is an
  example of its own: the library keeps it when one window fits (``min_s`` after
  ``edge_s`` off each end), else notes it.

Every example has a ``key``: a content hash (sha256, 16 hex digits) of the motion it covers
- joint names, frame rate and the local rotations of its frames - so learning the same
example twice, from the same file or a copy of it, is recognised (``rtseg learn`` reports
"N already in the library").
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, Iterable

from rtseg.core.posture import rest_meta
from rtseg.labels.truth import MOCAP6_NAMES, truth_labels
from rtseg.library.examples import (Example, joined_key, label_runs, motion_key, posture_rows,
                                   take_rows)

log = logging.getLogger(__name__)

#: a take at least this long (s, after its rest frames are dropped) is an example of its
#: own; shorter takes of one person and behaviour are joined.  The library's shortest
#: window (``min_s`` 1 s) plus ``edge_s`` (0.5 s) cut from each end: 2 s.
MIN_EXAMPLE_S = 2.0


def source_folders(root: str | Path) -> list[Path]:
    """``root`` itself when it holds ``index.tsv``, else its subfolders that are source
    folders (``rtseg.labels.takes.is_source_folder``: ``index.tsv`` beside ``bvh/`` or
    ``amc/``; not a ``spliced/`` folder of performances), sorted."""
    from rtseg.labels.takes import is_source_folder
    root = Path(root)
    if (root / "index.tsv").is_file():
        return [root]
    if not root.is_dir():
        return []
    return sorted(p for p in root.iterdir() if p.is_dir() and is_source_folder(p))


def examples_from_source(src: str | Path, config: Any, people: Iterable[str] | None = None,
                         takes: Iterable[str] | None = None,
                         notes: list[str] | None = None,
                         min_example_s: float = MIN_EXAMPLE_S) -> list[Any]:
    """Examples (``rtseg.library.examples.Example``) of one source folder (module doc);
    ``people`` / ``takes``: keep only these subjects / take names; ``notes`` gets one line
    per take left out."""
    from rtseg.evaluation.splice import (SpliceConfig, build_groups, clip_of, crossfade, load_sources,
                              read_source_index)
    from rtseg.core.take import Take
    keep_p = None if people is None else {str(p) for p in people}
    keep_t = None if takes is None else {str(t) for t in takes}
    rows = [r for r in read_source_index(src)
            if (keep_p is None or r.subject in keep_p) and (keep_t is None or r.name in keep_t)]
    load_sources(rows)
    notes = notes if notes is not None else []
    out: list[Example] = []
    # the groups of takes that may be joined (one format, joint set, frame rate); pools too
    # short for a spliced segment are dropped there, so group here, keeping every take
    cfg = SpliceConfig(min_segment_s=0.0, min_fade_s=0.0)
    for g in build_groups(rows, cfg):
        join = int(round(SpliceConfig().join_fade_s * g.frame_rate))
        for (subject, behaviour), pool in sorted(g.pools.items()):
            pending: list[tuple[Any, Example]] = []      # (take, example) too short alone
            need = min_example_s * g.frame_rate          # fed rows (one per frame)
            for r in sorted(pool.takes, key=lambda r: r.name):
                rows_of = _rows_or_note(r.take, r.name, config, notes)
                if rows_of is None:
                    continue
                X, index, profile = rows_of
                e = Example(behaviour, r.name, subject, X, index, r.trim, profile,
                            float(g.frame_rate), motion_key(r.take, *r.trim))
                i, j = e.rows()
                if j - i >= need:
                    e.P = posture_rows(r.take, index)
                    out.append(e)
                else:
                    pending.append((r, e))
            if len(pending) < 2:
                # nothing to join it with: an example of its own, kept by the library
                # when one window fits (``LibraryBuilder.add`` notes it otherwise)
                for r, e in pending:
                    e.P = posture_rows(r.take, e.index)
                    out.append(e)
                continue
            short = [r for r, _ in pending]
            clip = clip_of(short[0])
            for r in short[1:]:
                clip, _ = crossfade(clip, clip_of(r), max(1, min(join, len(clip), r.n_frames)),
                                    g.roots)
            t0 = short[0].take
            take = Take(joint_names=list(g.joint_names), parents=list(g.parents),
                        frame_rate=g.frame_rate, quats=clip.quats, root_position=clip.root,
                        space=t0.space, length_unit=t0.length_unit,
                        source="+".join(r.name for r in short), meta=rest_meta(t0))
            X, index, profile = take_rows(take, config)
            key = joined_key(motion_key(r.take, *r.trim) for r in short)
            e = Example(behaviour, "+".join(r.name for r in short), subject, X, index,
                        (0, take.n_frames), profile, float(g.frame_rate), key)
            i, j = e.rows()
            if j - i < need:
                notes.append(f"{e.take} {behaviour}: {len(short)} short takes joined are "
                             f"still shorter than {min_example_s:g} s; left out")
                continue
            e.P = posture_rows(take, index)
            out.append(e)
            log.info("%s %s: %d short takes joined into one example of %d frames",
                     subject, behaviour, len(short), take.n_frames)
    return out


def _rows_or_note(take: Any, name: str, config: Any, notes: list[str] | None
                  ) -> tuple[Any, Any, str] | None:
    """``take_rows`` of ``take``, or None with a line in ``notes`` when the configuration's
    feature profile cannot be computed on its rig (a joint it needs is missing)."""
    from rtseg.core.rig import RigError
    try:
        return take_rows(take, config)
    except (KeyError, RigError) as exc:
        if notes is not None:
            why = str(exc.args[0] if isinstance(exc, KeyError) and exc.args else exc)
            notes.append(f"{name}: left out: {why.split('; available')[0]}")
        return None


def examples_from_dir(data_dir: str | Path, config: Any,
                      people: Iterable[str] | None = None,
                      takes: Iterable[str] | None = None,
                      notes: list[str] | None = None) -> list[Example]:
    """Examples of every labelled take in ``data_dir`` (module doc); ``people``/``takes``:
    keep only these subjects / take names; ``notes`` gets a line per take left out."""
    root = Path(data_dir)
    keep_p = None if people is None else {str(p) for p in people}
    keep_t = None if takes is None else {str(t) for t in takes}
    out: list[Example] = []
    sources = source_folders(root)
    for src in sources:
        out += examples_from_source(src, config, keep_p, keep_t, notes)
    if (root / "index.tsv").is_file():
        return out
    from rtseg.labels.takes import find_labelled_takes
    try:
        labelled = find_labelled_takes(root, ("cmu", "tsseg4d", "spliced"))
    except FileNotFoundError:
        if sources:                      # a parent of source folders only
            return out
        raise
    for lt in labelled:
        who = lt.name.split("_")[0]           # SS of SS_TT; a spliced segment: its subject
        if (keep_t is not None and lt.name not in keep_t) or \
                (keep_p is not None and lt.group != "spliced" and who not in keep_p):
            continue
        take = lt.load()
        rows_of = _rows_or_note(take, lt.name, config, notes)
        if rows_of is None:
            continue
        X, index, profile = rows_of
        P = posture_rows(take, index)
        truth = truth_labels(lt, take.n_frames)
        mocap6 = "mocap6" in lt.labels.source
        for a, b, lab in label_runs(truth):
            if lab in ("?", "") or lab.startswith("s") and lab[1:].isdigit():
                continue
            name = MOCAP6_NAMES.get(lab, lab) if mocap6 else lab
            person = _segment_subject(take, a, b) or who
            if keep_p is not None and person not in keep_p:
                continue
            out.append(Example(name, lt.name, person, X, index, (a, b),
                               profile, float(take.frame_rate), motion_key(take, a, b), P))
    return out


def _segment_subject(take: Any, a: int, b: int) -> str | None:
    """Who performs frames ``[a, b)`` of a spliced performance (``benchmarks/splice.py``):
    the ``subject`` of its ``segment_sources`` entry holding the run's middle frame (a
    performance's name, ``same_000``, names no one); None for any other take."""
    mid = (a + b) // 2
    for seg in take.meta.get("segment_sources") or []:
        if isinstance(seg, dict) and seg.get("subject") and \
                int(seg.get("start", 0)) <= mid < int(seg.get("stop", -1)):
            return str(seg["subject"])
    return None
