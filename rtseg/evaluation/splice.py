"""Spliced performances with exact boundaries, built from real single-behaviour takes.

A *source folder* is laid out like ``../shared/data/cmu_single``: ``index.tsv`` (columns
``take``, ``subject``, ``format``, ``behaviour``; others ignored), the takes in
``bvh/<take>.bvh`` and ``amc/<take>.amc`` (skeleton ``amc/<subject>.asf``).  A
*performance* is 4-10 segments, each a stretch of one take (or of short takes of the same
person and behaviour joined with a blend), consecutive segments of different behaviours,
joined by a slerp cross-fade whose span is the labelled transition range.

Frame conventions
-----------------
All frame numbers are 0-based at the sources' frame rate (CMU: 120 fps).  A cross-fade of
``F`` frames between segments k-1 and k occupies output frames ``[lo, lo + F)``; output
frame ``lo + j`` is ``slerp(a, b, w_j)`` per joint on the *local* rotations, with
``w_j = smoothstep((j + 1) / (F + 1))`` (0 < w < 1, so neither end of the fade is a copy).
The transition is ``Transition(lo, hi=lo + F - 1, mid=lo + F // 2)``; the per-frame label
switches from behaviour k-1 to k at ``mid``.  Each segment's *pure* part (frames outside
any fade) is at least ``min_segment_s`` long.

Rules (tested in tests/test_splice.py): never a join across formats, joint sets or frame
rates; no two consecutive segments of the same behaviour; leading/trailing rest frames
dropped (:func:`trim_bounds`); the root is continuous: the incoming piece is turned about
the up axis (Y) to the outgoing heading and shifted on the ground plane to the outgoing
root position at the start of the fade, then root positions are blended with the same
weights.  A *mixed* performance holds at least two people of one format; a change of
person is itself a change of distribution (body proportions, style), so in mixed
performances a detector sees person and behaviour change together, and some segments of
the same behaviour come from different people.

Everything random comes from ``numpy.random.default_rng([seed, kind, index])``, so
performance ``i`` does not depend on ``n``, and the same seed gives byte-identical files
(:func:`write_performance` fixes the zip timestamps; no paths or times are stored).
"""

from __future__ import annotations

import csv
import io
import logging
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from rtseg.core import quat as Q
from rtseg.core.posture import rest_meta
from rtseg.evaluation.blend import (  # noqa: F401  (re-exported)
    Clip, crossfade, fade_weights, slerp, smoothstep, trim_bounds,
)
from rtseg.core.take import Take

log = logging.getLogger(__name__)

KINDS = ("same", "mixed")
FORMAT_SUFFIX = {"bvh": ".bvh", "amc": ".amc"}
SPLICE_VERSION = 1


@dataclass(frozen=True)
class SpliceConfig:
    """Generation parameters; durations in seconds (converted with the sources' rate)."""
    min_segments: int = 4
    max_segments: int = 10
    min_segment_s: float = 2.5    #: shortest pure (unblended) part of a segment
    max_segment_s: float = 8.0    #: longest pure part (when the material allows)
    min_fade_s: float = 0.3
    max_fade_s: float = 1.0
    join_fade_s: float = 0.3      #: blend joining short takes of one person and behaviour


# --------------------------------------------------------------------------- sources

@dataclass
class SourceTake:
    """One row of ``index.tsv`` with its motion, trimmed of rest frames."""
    name: str
    subject: str
    fmt: str
    behaviour: str
    path: Path
    take: Take | None = None
    trim: tuple[int, int] = (0, 0)        #: kept source frames [start, stop)

    @property
    def n_frames(self) -> int:
        return self.trim[1] - self.trim[0]


#: (file, index line) already warned about (missing, or named twice) in this process
_MISSING_SAID: set[tuple[str, int]] = set()


def _skip_once(path: Path, lineno: int, msg: str, *args: Any) -> None:
    """Log the warning for a skipped index row once per process, however often read."""
    if (str(path), lineno) not in _MISSING_SAID:
        _MISSING_SAID.add((str(path), lineno))
        log.warning(msg, *args)


def read_source_index(src: str | Path) -> list[SourceTake]:
    """Rows of ``SRC/index.tsv`` whose motion file exists (missing ones: logged, skipped).
    A row naming a take and format an earlier row named is logged and skipped, so no
    take's motion is used twice.

    Raises ValueError naming the line for a row without take/subject/format/behaviour or
    with a format other than bvh/amc; rows of blanks only are skipped.
    """
    src = Path(src)
    index = src / "index.tsv"
    if not index.is_file():
        raise FileNotFoundError(f"{index} not found (a source folder needs index.tsv, bvh/, amc/)")
    out: list[SourceTake] = []
    first: dict[tuple[str, str], int] = {}     # (format, take) -> the line that named it
    with open(index, encoding="utf-8-sig", newline="") as fh:
        rows = csv.DictReader(fh, delimiter="\t")
        need = ("take", "subject", "format", "behaviour")
        missing = [c for c in need if c not in (rows.fieldnames or [])]
        if missing:
            raise ValueError(f"{index}: missing column(s) {', '.join(missing)}")
        for row in rows:
            lineno = rows.line_num
            vals = {c: (row.get(c) or "").strip() for c in need}
            cells = [x for v in row.values() for x in (v if isinstance(v, list) else [v])]
            if not any(str(x or "").strip() for x in cells):
                continue                  # a blank row (spaces or tabs only)
            if not all(vals.values()):
                raise ValueError(f"{index}:{lineno}: empty {[c for c in need if not vals[c]][0]}")
            fmt = vals["format"].lower()
            if fmt not in FORMAT_SUFFIX:
                raise ValueError(f"{index}:{lineno}: format {fmt!r} is not bvh or amc")
            path = src / fmt / f"{vals['take']}{FORMAT_SUFFIX[fmt]}"
            seen = first.setdefault((fmt, vals["take"]), lineno)
            if seen != lineno:
                _skip_once(path, lineno, "%s:%d: %s is already line %d's take; row skipped",
                           index, lineno, path.name, seen)
                continue
            if not path.is_file():
                _skip_once(path, lineno, "%s:%d: %s not found; take skipped", index, lineno,
                           path)
                continue
            out.append(SourceTake(vals["take"], vals["subject"], fmt, vals["behaviour"], path))
    return out


def load_sources(rows: list[SourceTake]) -> list[SourceTake]:
    """Read every take and set its trim bounds (in place; returns the rows).  A take that
    cannot be read, or holds fewer than two frames, is logged and left out (of ``rows``
    too), as a missing file is: one bad file does not stop a whole source."""
    from rtseg.drivers.readers import ReaderError, read_take
    kept = []
    for r in rows:
        # an AMC take's skeleton: the subject's (amc/<subject>.asf), else found beside it
        asf = r.path.with_name(f"{r.subject}.asf") if r.fmt == "amc" else None
        try:
            r.take = read_take(r.path, skeleton=asf if asf is not None and asf.is_file()
                               else None)
        except (ReaderError, OSError, ValueError) as exc:
            log.warning("%s: cannot be read (%s); take skipped", r.path, exc)
            continue
        if r.take.n_frames < 2:
            log.warning("%s: %d frame(s); take skipped", r.path, r.take.n_frames)
            continue
        if r.take.root_position is None:
            r.take.root_position = np.zeros((r.take.n_frames, 3))
        r.trim = trim_bounds(r.take.quats, r.take.frame_rate)
        if r.trim != (0, r.take.n_frames):
            log.info("%s: rest frames dropped, kept [%d, %d) of %d", r.name, *r.trim,
                     r.take.n_frames)
        kept.append(r)
    rows[:] = kept
    return rows


def skeleton_key(r: SourceTake) -> tuple:
    """Takes may be joined only when this is equal: format, joint names, parents, rate."""
    t = r.take
    return (r.fmt, tuple(t.joint_names), tuple(t.parents), round(float(t.frame_rate), 2))


# --------------------------------------------------------------------------- pieces

def clip_of(r: SourceTake, start: int = 0, stop: int | None = None) -> Clip:
    """Frames [start, stop) of the trimmed take (0 = first kept frame)."""
    a = r.trim[0] + start
    b = r.trim[0] + (r.n_frames if stop is None else stop)
    return Clip(r.take.quats[a:b].copy(), r.take.root_position[a:b].copy(), [f"{r.name}[{a}:{b}]"])


# --------------------------------------------------------------------------- planning

@dataclass
class Pool:
    """The takes of one person and behaviour within one skeleton group."""
    subject: str
    behaviour: str
    takes: list[SourceTake]
    join: int                              #: frames of the blend joining its takes

    @property
    def available(self) -> int:
        """Longest stretch it can give: one take, or all takes joined."""
        lens = [t.n_frames for t in self.takes]
        return max(max(lens), sum(lens) - (len(lens) - 1) * self.join)

    def stretch(self, rng: np.random.Generator, n: int, roots: list[int]) -> Clip:
        """``n`` frames: from one take long enough (uniform choice and start), else from
        the pool's takes in random order joined with ``join``-frame blends."""
        whole = [t for t in self.takes if t.n_frames >= n]
        if whole:
            t = whole[int(rng.integers(len(whole)))]
            s = int(rng.integers(t.n_frames - n + 1))
            return clip_of(t, s, s + n)
        order = rng.permutation(len(self.takes))
        clip = clip_of(self.takes[order[0]])
        for i in order[1:]:
            clip, _ = crossfade(clip, clip_of(self.takes[i]), self.join, roots)
        if len(clip) < n:
            raise ValueError(f"{self.subject}/{self.behaviour}: {len(clip)} frames < {n}")
        s = int(rng.integers(len(clip) - n + 1))
        return Clip(clip.quats[s:s + n], clip.root[s:s + n], clip.parts + [f"window[{s}:{s + n}]"])


@dataclass
class Group:
    """Takes that may be joined: one format, one joint set, one frame rate."""
    fmt: str
    joint_names: list[str]
    parents: list[int]
    frame_rate: float
    length_unit: str
    pools: dict[tuple[str, str], Pool]     #: (subject, behaviour) -> usable pool

    @property
    def roots(self) -> list[int]:
        return [j for j, p in enumerate(self.parents) if p < 0]

    def behaviours(self, subject: str | None = None) -> list[str]:
        return sorted({b for (s, b) in self.pools if subject in (None, s)})

    def subjects(self, behaviour: str | None = None) -> list[str]:
        return sorted({s for (s, b) in self.pools if behaviour in (None, b)})


def build_groups(rows: Sequence[SourceTake], cfg: SpliceConfig) -> list[Group]:
    """Loaded sources grouped by :func:`skeleton_key`; pools too short for a segment with
    two shortest fades are left out (logged)."""
    by_key: dict[tuple, list[SourceTake]] = {}
    for r in rows:
        by_key.setdefault(skeleton_key(r), []).append(r)
    groups = []
    for key in sorted(by_key, key=repr):
        members = by_key[key]
        rate = float(members[0].take.frame_rate)
        join = int(round(cfg.join_fade_s * rate))
        need = int(round(cfg.min_segment_s * rate)) + 2 * int(round(cfg.min_fade_s * rate))
        pools: dict[tuple[str, str], Pool] = {}
        for r in sorted(members, key=lambda r: (r.subject, r.behaviour, r.name)):
            pools.setdefault((r.subject, r.behaviour), Pool(r.subject, r.behaviour, [], join)).takes.append(r)
        for k in sorted(pools):
            if pools[k].available < need:
                log.info("%s %s/%s: %d frames, fewer than %d; not used", key[0], *k,
                         pools[k].available, need)
                del pools[k]
        t0 = members[0].take
        groups.append(Group(key[0], list(t0.joint_names), list(t0.parents), rate,
                            t0.length_unit, pools))
    return groups


@dataclass
class Performance:
    """One spliced performance and its ground truth (frames 0-based, output numbering)."""
    name: str
    kind: str
    take: Take
    segments: list[dict[str, Any]]
    transitions: list[tuple[int, int, int, str, str]]   #: (lo, mid, hi, before, after)


def _cast(groups: Sequence[Group], kind: str, index: int) -> tuple[Group, list[str] | None]:
    """The group (and, for "same", the person) of performance ``index``: the eligible
    options in turn (``index`` modulo their number), so every one is used evenly."""
    if kind == "same":
        options = [(g, s) for g in groups for s in g.subjects() if len(g.behaviours(s)) >= 2]
        if not options:
            raise ValueError("no person has two behaviours with enough material in one format")
        g, s = options[index % len(options)]
        return g, [s]
    options_g = [g for g in groups if len(g.behaviours()) >= 2 and len(g.subjects()) >= 2]
    if not options_g:
        raise ValueError("no format holds two people and two behaviours with enough material")
    return options_g[index % len(options_g)], None


def plan_performance(rng: np.random.Generator, groups: Sequence[Group], kind: str,
                     cfg: SpliceConfig, index: int = 0
                     ) -> tuple[Group, list[Pool], list[int], list[int]]:
    """Choose the group, the pools of the segments (consecutive behaviours differ; a mixed
    performance has two people or more), the fades (frames) and the pure lengths."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    g, people = _cast(groups, kind, index)
    n_seg = int(rng.integers(cfg.min_segments, cfg.max_segments + 1))
    for _ in range(100):
        pools: list[Pool] = []
        prev = None
        for _k in range(n_seg):
            options = [b for b in g.behaviours(people[0] if people else None) if b != prev]
            b = options[int(rng.integers(len(options)))]
            subs = people or g.subjects(b)
            s = subs[int(rng.integers(len(subs)))]
            pools.append(g.pools[(s, b)])
            prev = b
        if kind == "same" or len({p.subject for p in pools}) >= 2:
            break
    else:
        raise ValueError(f"could not draw a {kind} performance with two people")
    rate = g.frame_rate
    min_seg = int(round(cfg.min_segment_s * rate))
    max_seg = int(round(cfg.max_segment_s * rate))
    f_lo, f_hi = int(round(cfg.min_fade_s * rate)), int(round(cfg.max_fade_s * rate))

    # fades[k]: between segments k-1 and k.  Each is bounded so that segment k-1 keeps
    # min_seg pure frames beside its other fade, and segment k keeps room for min_seg and
    # (unless it is the last) a shortest fade on its far side.  Usable pools have
    # available >= min_seg + 2 f_lo, so the bound is never below f_lo.
    fades = [0] * (n_seg + 1)
    for k in range(1, n_seg):
        room_prev = pools[k - 1].available - min_seg - fades[k - 1]
        room_next = pools[k].available - min_seg - (f_lo if k < n_seg - 1 else 0)
        hi = min(f_hi, room_prev, room_next)
        fades[k] = int(rng.integers(f_lo, hi + 1))
    pure = []
    for k in range(n_seg):
        room = pools[k].available - fades[k] - fades[k + 1]
        if room < min_seg:
            raise ValueError(f"{pools[k].subject}/{pools[k].behaviour}: no room for a segment")
        pure.append(int(rng.integers(min_seg, min(max_seg, room) + 1)))
    return g, pools, fades, pure


def make_performance(name: str, kind: str, groups: Sequence[Group], seed: int, index: int,
                     cfg: SpliceConfig = SpliceConfig(), names: Sequence[str] = ()) -> Performance:
    """Performance ``index`` of ``kind`` for ``seed`` (independent of how many are made).

    names: behaviour names in label-id order (default: the group's behaviours, sorted);
    ``take.meta["frame_labels"]`` holds ids into ``take.meta["frame_label_names"]``.
    """
    rng = np.random.default_rng([int(seed), KINDS.index(kind), int(index)])
    g, pools, fades, pure = plan_performance(rng, groups, kind, cfg, index)
    names = list(names) or sorted({b for gg in groups for b in gg.behaviours()})
    roots = g.roots
    out: Clip | None = None
    segments: list[dict[str, Any]] = []
    transitions: list[tuple[int, int, int, str, str]] = []
    starts = []
    for k, pool in enumerate(pools):
        piece = pool.stretch(rng, fades[k] + pure[k] + fades[k + 1], roots)
        if out is None:
            out, s = piece, 0
        else:
            out, s = crossfade(out, piece, fades[k], roots)
            f = fades[k]
            transitions.append((s, s + f // 2, s + f - 1, pools[k - 1].behaviour, pool.behaviour))
        starts.append(s)
        segments.append({"behaviour": pool.behaviour, "subject": pool.subject,
                         "sources": "+".join(piece.parts), "fade_in": fades[k],
                         "pure": [s + fades[k], s + fades[k] + pure[k]]})
    n = len(out)
    mids = [0] + [t[1] for t in transitions] + [n]
    labels = np.empty(n, dtype=np.int64)
    for k, seg in enumerate(segments):
        seg["start"], seg["stop"] = mids[k], mids[k + 1]
        labels[mids[k]:mids[k + 1]] = names.index(seg["behaviour"])
    quats = Q.make_continuous(Q.normalize(out.quats), axis=0)
    meta = {
        "splice": {"version": SPLICE_VERSION, "kind": kind, "seed": int(seed), "index": int(index),
                   "format": g.fmt, "subjects": sorted({p.subject for p in pools}),
                   "fade_weights": "smoothstep((j+1)/(F+1))"},
        "segments": [[s["behaviour"], s["start"], s["stop"]] for s in segments],
        "segment_sources": segments,
        "transitions": [list(t) for t in transitions],
        "frame_label_names": names,
        "frame_labels": labels,
        **rest_meta(pools[0].takes[0].take),
    }
    take = Take(joint_names=list(g.joint_names), parents=list(g.parents), frame_rate=g.frame_rate,
                quats=quats, root_position=out.root, space="local", length_unit=g.length_unit,
                source=f"splice:{name}", meta=meta)
    return Performance(name, kind, take, segments, transitions)


# --------------------------------------------------------------------------- output

_FIXED_TIME = (1980, 1, 1, 0, 0, 0)


def write_performance(path: str | Path, perf: Performance) -> Path:
    """Write the take (rtseg ``.npz``) with fixed zip timestamps: same input, same bytes.
    The file appears whole or not at all (``replace_bytes``)."""
    from rtseg.drivers.readers import write_take
    path = Path(path)
    with tempfile.TemporaryDirectory(dir=path.parent, prefix=".splice-") as tmp:
        first = write_take(Path(tmp) / path.name, perf.take)
        with zipfile.ZipFile(first) as z:
            members = [(i.filename, z.read(i.filename)) for i in z.infolist()]
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for fname, data in members:
            info = zipfile.ZipInfo(fname, date_time=_FIXED_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            z.writestr(info, data)
    return replace_bytes(path, buf.getvalue())


def replace_bytes(path: Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file beside it and an atomic rename,
    so a reader, or another process writing the same performances into the same folder
    (two benchmarks sharing a cache), never sees a part-written file, and a process
    stopped midway leaves the old file or none."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)                 # as a plain write would leave it (mkstemp: 0600)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


INDEX_COLUMNS = ("performance", "kind", "format", "frames", "segment", "behaviour", "subject",
                 "start", "stop", "pure_start", "pure_stop", "fade_in", "sources")


def index_rows(perf: Performance) -> list[list[str]]:
    """One row per segment: labelled span [start, stop), pure span, fade-in frames, and the
    source frames used (``take[a:b]`` in the file's 0-based frame numbers)."""
    fmt = perf.take.meta["splice"]["format"]
    return [[perf.name, perf.kind, fmt, str(perf.take.n_frames), str(k), s["behaviour"],
             s["subject"], str(s["start"]), str(s["stop"]), str(s["pure"][0]), str(s["pure"][1]),
             str(s["fade_in"]), s["sources"]] for k, s in enumerate(perf.segments)]


def generate(src: str | Path, out: str | Path, *, seed: int = 0, n: int = 20,
             kinds: Sequence[str] = KINDS, cfg: SpliceConfig = SpliceConfig(),
             force: bool = False) -> list[Performance]:
    """Build ``n`` performances of each kind from ``src`` into ``out`` (``<kind>_NNN.npz``
    and ``index.tsv``).  Refuses a folder holding other ``.npz`` files unless ``force``
    (then they are removed).  ValueError, ``out`` left alone, when no take of ``src`` can
    be read (every listed file missing or unreadable, or no rows)."""
    out = Path(out)
    wanted = {f"{k}_{i:03d}.npz" for k in kinds for i in range(n)}
    stale = sorted(p for p in out.glob("*.npz") if p.name not in wanted)
    if stale and not force:
        raise ValueError(f"{out} holds other .npz files ({stale[0].name}, ...); "
                         "use another folder or --force to remove them")
    rows = load_sources(read_source_index(src))
    if not rows:
        raise ValueError(f"{src}: no take to splice (index.tsv lists none whose file exists "
                         "and can be read)")
    out.mkdir(parents=True, exist_ok=True)
    for p in stale:
        p.unlink()
    groups = build_groups(rows, cfg)
    gone = sorted({r.subject for r in rows} - {k[0] for g in groups for k in g.pools})
    if gone:
        log.warning("%s: %s left out: no behaviour with material for a segment (%.1f s with "
                    "its fades)", src, ", ".join(gone), cfg.min_segment_s + 2 * cfg.min_fade_s)
    names = sorted({b for g in groups for b in g.behaviours()})
    perfs = []
    for kind in kinds:
        for i in range(n):
            name = f"{kind}_{i:03d}"
            perf = make_performance(name, kind, groups, seed, i, cfg, names)
            write_performance(out / f"{name}.npz", perf)
            perfs.append(perf)
    lines = ["\t".join(INDEX_COLUMNS)] + ["\t".join(r) for p in perfs for r in index_rows(p)]
    replace_bytes(out / "index.tsv", ("\n".join(lines) + "\n").encode("utf-8"))
    return perfs


__all__ = ["SpliceConfig", "SourceTake", "read_source_index", "trim_bounds", "load_sources",
           "build_groups", "Clip", "slerp", "crossfade", "fade_weights", "plan_performance",
           "make_performance", "write_performance", "replace_bytes", "generate", "Performance",
           "KINDS"]
