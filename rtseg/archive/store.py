"""Where ``rtseg segment --out`` keeps its records: one JSON object a line (``.jsonl``), or
a Parquet table (``.parquet``, needs pyarrow).

A record is one method on one take (see ``rtseg.archive.runner.take_records``).  Its key is
``(path, method)``: ``path`` is the take's absolute path, so a rerun from another working
directory still recognises the takes already done.

Resumability: JSON lines are appended and flushed as each take completes, so a run killed
at any point keeps every take finished before it (a torn last line is dropped on the next
open).  Parquet files cannot be appended, so a Parquet run journals its records to
``FILE.partial.jsonl`` beside it and writes the table when the run ends; the next run
reads both.  ``finish()`` rewrites the output sorted by (path, method order), the last
record of a key winning, so a resumed run and a single uninterrupted one leave the same
file (elapsed times apart).
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any, Iterable, Sequence

log = logging.getLogger(__name__)

FORMATS = (".jsonl", ".parquet")
Key = tuple[str, str]


def record_key(rec: dict[str, Any]) -> Key:
    return (str(rec.get("path", "")), str(rec.get("method", "")))


def _need_pyarrow(path: Path) -> Any:
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet as pq
    except ImportError:
        raise ValueError(f"{path}: writing .parquet needs pyarrow (pip install pyarrow); "
                         f"or write JSON lines: --out {path.with_suffix('.jsonl')}") from None
    return pq


def check_output_path(path: str | Path) -> Path:
    """The output path, or ValueError when its format is unknown or unavailable."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in FORMATS:
        raise ValueError(f"{p}: --out must end in .jsonl or .parquet, not {ext or '(none)'!r}")
    if ext == ".parquet":
        _need_pyarrow(p)
    if p.is_dir():
        raise ValueError(f"{p}: --out is a directory")
    return p


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """Records of a JSON-lines file; unparsable lines (a run killed mid-write) are skipped
    with a warning."""
    out: list[dict[str, Any]] = []
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return out
    bad = 0
    for line in text.splitlines():
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError:
            bad += 1
            continue
        if isinstance(obj, dict):
            out.append(obj)
        else:
            bad += 1
    if bad:
        log.warning("%s: %d unreadable line(s) skipped (a torn write?)", path, bad)
    return out


def _truncate_torn_tail(path: Path) -> None:
    """Cut a partial last line (no newline) so appends start on a fresh line."""
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        return
    if size == 0:
        return
    with open(path, "rb+") as fh:
        fh.seek(-1, os.SEEK_END)
        if fh.read(1) == b"\n":
            return
        data = path.read_bytes()
        keep = data.rfind(b"\n") + 1
        fh.truncate(keep)
    log.warning("%s: torn last line dropped (%d bytes)", path, size - keep)


class RecordStore:
    """Records already in ``path`` and the appending of new ones.

    methods: the order of methods for the final sort.
    """

    def __init__(self, path: str | Path, methods: Sequence[str] = ()) -> None:
        self.path = check_output_path(path)
        self.parquet = self.path.suffix.lower() == ".parquet"
        self.journal = (self.path.with_name(self.path.name + ".partial.jsonl")
                        if self.parquet else self.path)
        self.order = {m: k for k, m in enumerate(methods)}
        self.records: dict[Key, dict[str, Any]] = {}
        for rec in self._existing():
            self.records[record_key(rec)] = rec
        self._fh = None

    def _existing(self) -> list[dict[str, Any]]:
        recs: list[dict[str, Any]] = []
        if self.parquet and self.path.exists():
            pq = _need_pyarrow(self.path)
            try:
                recs.extend(pq.read_table(self.path).to_pylist())
            except Exception as exc:  # pyarrow raises several types for a bad file
                raise ValueError(f"{self.path}: cannot read existing records: {exc}") from None
        if self.journal.exists():
            recs.extend(read_jsonl(self.journal))
        return recs

    def done(self, path: str, method: str, retry_errors: bool = False) -> bool:
        rec = self.records.get((path, method))
        return rec is not None and not (retry_errors and rec.get("error"))

    def append(self, recs: Iterable[dict[str, Any]]) -> None:
        """Write records now (flushed), so a killed run keeps them."""
        if self._fh is None:
            self.journal.parent.mkdir(parents=True, exist_ok=True)
            _truncate_torn_tail(self.journal)
            self._fh = open(self.journal, "a", encoding="utf-8")
        for rec in recs:
            self.records[record_key(rec)] = rec
            self._fh.write(json.dumps(rec, allow_nan=False, separators=(",", ":")) + "\n")
        self._fh.flush()

    def sorted_records(self) -> list[dict[str, Any]]:
        return sorted(self.records.values(),
                      key=lambda r: (str(r.get("path", "")),
                                     self.order.get(r.get("method"), len(self.order)),
                                     str(r.get("method", ""))))

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def finish(self) -> None:
        """Rewrite the output sorted, one record per key (atomically: temp file, rename)."""
        self.close()
        if not self.records and not self.path.exists():
            return                      # nothing ran (e.g. no scheduler): no empty file
        recs = self.sorted_records()
        tmp = self.path.with_name(self.path.name + ".tmp")
        if self.parquet:
            import pyarrow as pa
            pq = _need_pyarrow(self.path)
            pq.write_table(pa.Table.from_pylist(recs), tmp)
            os.replace(tmp, self.path)
            self.journal.unlink(missing_ok=True)
        else:
            with open(tmp, "w", encoding="utf-8") as fh:
                for rec in recs:
                    fh.write(json.dumps(rec, allow_nan=False, separators=(",", ":")) + "\n")
            os.replace(tmp, self.path)


class StreamSink:
    """Records as JSON lines on a stream (stdout) as they complete: nothing to resume."""

    def __init__(self, stream: Any) -> None:
        self.stream = stream
        self.records: dict[Key, dict[str, Any]] = {}

    def done(self, path: str, method: str, retry_errors: bool = False) -> bool:
        return False

    def append(self, recs: Iterable[dict[str, Any]]) -> None:
        for rec in recs:
            self.stream.write(json.dumps(rec, allow_nan=False, separators=(",", ":")) + "\n")
        self.stream.flush()

    def finish(self) -> None:
        pass


def load_records(path: str | Path) -> list[dict[str, Any]]:
    """Every record of an output file (``.jsonl`` or ``.parquet``, with its journal)."""
    store = RecordStore(path)
    return store.sorted_records()
