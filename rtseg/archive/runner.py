"""Segment archives of takes: find the takes, run one task per take (in this process, or
on a Dask cluster), and keep one small record per take and method.

- ``discover_takes(PATHS)``: files, folders (searched recursively) and glob patterns to the
  absolute paths of the takes they hold (``.amc .bvh .npz .csv`` files and folders recorded
  by ``rtseg live --record``).
- ``take_records(path, methods, ...)``: the task run for one take: read it, compute its
  features once, run every method on them; returns one record per method.  Any failure
  is a record with ``error`` set, never an exception.
- ``run_archive(...)``: the takes not yet in the output, run in-process or on Dask
  (``rtseg.archive.executors``), records appended as each take completes (``RecordStore``).

Only paths go to the workers and only records come back: each worker reads its take
itself, so nothing large passes through the scheduler.

Record (JSON; frames 0-based at the take's rate, a cut frame is the first frame of a
segment, segment ``[start, end)``, times in s from the take start)::

    {"take": "86_01", "path": "/abs/86_01.amc", "method": "pca",
     "frame_rate": 120.0, "n_frames": 10000,
     "cuts": [{"frame", "time", "confidence", "score", "detected_at"}, ...],
     "segments": [{"index", "start", "end", "start_time", "end_time", "duration"
                   [, "behaviour" with --identify]}, ...],
     "elapsed_s": detector s, "take_elapsed_s": read + features + all methods s,
     ["missing_frames": N, "gaps": G, a recorded session whose source lost frames,]
     ["params_differ": ["key = live (now value)", ...], a recorded session whose
      detector of this method ran with other parameters,]
     "error": null | "message"}
"""

from __future__ import annotations

import contextlib
import glob
import logging
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from rtseg.archive.records import error_record, take_name, take_records  # noqa: F401 (re-exported)

log = logging.getLogger(__name__)

#: file extensions read as takes (``.asf`` is a skeleton, found beside its ``.amc``).
TAKE_EXTENSIONS = (".amc", ".bvh", ".npz", ".csv")
SESSION_HEADER = "session.json"   # rtseg.recording.HEADER_FILE


def _is_session(d: Path) -> bool:
    return (d / SESSION_HEADER).is_file()


def _walk(root: Path) -> Iterable[Path]:
    """Takes under a folder: a recorded session folder is one take; otherwise files with
    a take extension, recursively (hidden entries skipped)."""
    if _is_session(root):
        yield root
        return
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        dirnames[:] = sorted(n for n in dirnames if not n.startswith("."))
        sessions = [n for n in dirnames if _is_session(d / n)]
        for n in sessions:
            yield d / n
        dirnames[:] = [n for n in dirnames if n not in sessions]
        for n in sorted(filenames):
            if not n.startswith(".") and Path(n).suffix.lower() in TAKE_EXTENSIONS:
                yield d / n


def discover_takes(paths: Sequence[str | os.PathLike]) -> list[str]:
    """Absolute take paths from files, folders and globs (``**`` recurses), sorted and
    without repeats; symbolic links are kept as they are named, not followed.  A path that does not exist and matches nothing, or a folder given
    by name that holds no take, is a ValueError."""
    found: dict[str, None] = {}
    for raw in paths:
        text = os.fspath(raw)
        p = Path(text)
        if p.exists():
            matches = [p]
        elif glob.has_magic(text):
            matches = [Path(m) for m in sorted(glob.glob(text, recursive=True))]
            if not matches:
                raise ValueError(f"{text}: no file matches")
        else:
            raise ValueError(f"{text}: no such file or folder")
        for m in matches:
            if m.is_dir():
                takes: Iterable[Path] = _walk(m)
            elif m == p or m.suffix.lower() in TAKE_EXTENSIONS:
                takes = [m]       # a file named explicitly is tried whatever its extension
            else:
                takes = []
            n = 0
            for n, t in enumerate(takes, 1):
                # absolute but not resolved: a symlinked take keeps its own name, and two
                # links to one file are two takes (a layout made of links, docs/offline.md)
                found[os.path.abspath(t)] = None
            if m is p and n == 0 and m.is_dir():
                raise ValueError(f"{text}: no take in this folder (files "
                                 f"{', '.join(TAKE_EXTENSIONS)} or recorded sessions, "
                                 f"searched recursively)")
    return sorted(found)


@dataclass
class ArchiveRun:
    """What ``run_archive`` did: takes found, skipped (already done; ``skipped_failed`` of
    them hold an error from an earlier run), run, failed."""
    found: int = 0
    skipped: int = 0
    skipped_failed: int = 0
    run: int = 0
    failed: int = 0
    wall_s: float = 0.0
    backend: str = "in-process"
    interrupted: bool = False
    computed: list[str] = field(default_factory=list)

    @property
    def rate(self) -> float:
        return self.run / self.wall_s if self.wall_s > 0 else 0.0


def run_archive(paths: Sequence[str], methods: Sequence[str], out: str | os.PathLike | None,
                params: Mapping[str, Mapping[str, Any]] | None = None,
                profile: str | None = None, skeleton: str | None = None,
                workers: int | None = None, scheduler: str | None = None,
                force: bool = False, retry_errors: bool = False, limit: int | None = None,
                progress: bool = True, identify: bool = False,
                identity_threshold: float | None = None,
                on_take: Callable[[str, list[dict[str, Any]]], None] | None = None
                ) -> ArchiveRun:
    """Segment every take of ``paths`` not yet in ``out`` and append its records there
    (``out`` None: JSON lines on stdout as takes complete, nothing skipped).

    workers: run on a local Dask cluster of that many processes (``None``/0: in this
    process); scheduler: address of a running Dask scheduler.  force: redo takes already
    done; retry_errors: redo takes whose records hold an error.  limit: run at most this
    many takes (the rest stay for the next run).  identify / identity_threshold: behaviour
    ids in the records' segments (``take_records``; records made without them count as done,
    so add ``force`` to redo an archive with ids).  on_take(path, records): called in this
    process after each take's records are written (a callback raising stops the run; the
    records written so far stay).  The output is rewritten sorted at the end, also when
    the run is interrupted.
    """
    from rtseg.archive.executors import Progress, have_dask, run_tasks
    from rtseg.archive.store import RecordStore, StreamSink
    if scheduler and not have_dask():
        raise ValueError("--scheduler needs Dask: pip install 'rtseg[scale]' "
                         "(or drop --scheduler to run in this process)")
    store = RecordStore(out, methods) if out is not None else StreamSink(sys.stdout)
    takes = discover_takes(paths)
    stats = ArchiveRun(found=len(takes))
    todo: list[tuple[str, list[str]]] = []
    for t in takes:
        missing = [m for m in methods if force or not store.done(t, m, retry_errors)]
        if missing:
            todo.append((t, missing))
        elif any((store.records.get((t, m)) or {}).get("error") for m in methods):
            stats.skipped_failed += 1
    stats.skipped = len(takes) - len(todo)
    if limit is not None:
        todo = todo[:max(0, int(limit))]
    kwargs = {"params": {m: dict(v) for m, v in (params or {}).items()},
              "profile": profile, "skeleton": skeleton}
    if identify:
        kwargs.update(identify=True, identity_threshold=identity_threshold)
    bar = Progress(len(todo), skipped=stats.skipped, enabled=progress)
    t0 = time.perf_counter()
    try:
        tasks = run_tasks(todo, kwargs, workers=workers, scheduler=scheduler, stats=stats)
        with contextlib.closing(tasks):   # stopping early cancels the tasks not yet done
            for path, recs in tasks:
                store.append(recs)
                failed = any(r.get("error") for r in recs)
                stats.run += 1
                stats.failed += failed
                stats.computed.append(path)
                bar.update(failed)
                if on_take is not None:
                    on_take(path, recs)
    except BaseException:
        stats.interrupted = True
        raise
    finally:
        stats.wall_s = time.perf_counter() - t0
        bar.close()
        store.finish()
    return stats
