"""Session recording: every frame a live session received, plus its cuts and events, in a
folder that stays readable if the process is killed mid-write.

Writing (the live loop's side)
------------------------------
::

    rec = SessionRecorder(dir, joint_names, parents, space="global", frame_rate=100.0,
                          meta={"source": url}, flush_interval_s=0.5)
    rec.record_frame(frame)       # every Frame received, valid or not, in arrival order
    rec.record_cut(cut_event)     # a CutEvent (rtseg.events), appended at once
    rec.record_event(status_or_dropout_event_or_dict)
    rec.poll()                    # call when idle: flushes buffered frames if due
    rec.close()                   # flush, mark the session closed cleanly

``rec.start_monotonic`` is the session's time origin (``time.monotonic()`` at creation,
or the ``start_monotonic`` argument); use it for ``CutEvent.time``.  No method raises
because of bad input or a full disk: bad frames and write errors are counted in
``rec.stats`` and logged (rate-limited).  Not for use from several threads at once beyond
the internal lock (calls are serialised).

Folder layout (format version 1; see docs/formats.md)
-----------------------------------------------------
- ``session.json`` - header, written atomically (temp file, fsync, rename) at start and
  rewritten at ``close()`` with ``"closed": true`` and the final counters.
- ``frames.bin``  - fixed-size little-endian records, one per received frame, appended.
  Record: ``magic u4 = b"RTSF"``, ``recv_time f8`` (monotonic s), ``source_time f8``
  (NaN if none), ``seq i8``, ``flags u1`` (bit0 seq present, bit1 source time present,
  bit2 root position present), ``valid u1[ceil(J/8)]`` (bit j of the joint mask,
  little bit order), ``root f8[3]``, ``quats f8|f4[J*4]`` (x, y, z, w per joint),
  ``crc u4`` = zlib.crc32 of the record's preceding bytes.
- ``cuts.jsonl`` / ``events.jsonl`` - one JSON object per line (``CutEvent.to_dict()``,
  status/dropout/log dicts with a ``"type"``), each line written and flushed at once.

Durability: frames are packed into an in-memory buffer by the caller's thread and written
with one ``os.write`` when ``flush_interval_s`` has passed or ``max_buffer_frames`` are
buffered (no per-frame syscalls), so a killed process loses at most the last
``flush_interval_s`` of frames.  ``fsync=True`` also fsyncs on each flush (survives power
loss; may stall the caller for milliseconds on slow disks).

Reading
-------
``read_session(dir) -> Take`` (quats (F, J, 4) float64, valid (F, J), frame_rate nominal or
estimated from recv_time, ``meta`` with ``recv_time``/``source_time``/``seq`` arrays,
``session_time``, ``cuts``, ``events``, ``torn_records``, ...).  A torn final record (or
any record failing its magic/CRC) is skipped and counted, never raised.
``read_session_cuts(dir) -> list[CutEvent]``.  ``is_session_dir(path)``.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import math
import os
import struct
import threading
import time
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from rtseg.events import BehaviourEvent, CutEvent, DropoutEvent, StatusEvent, event_from_dict
from rtseg.frame import Frame
from rtseg.take import Take

log = logging.getLogger("rtseg.recording")

FORMAT_NAME = "rtseg-session"
FORMAT_VERSION = 1
HEADER_FILE = "session.json"
FRAMES_FILE = "frames.bin"
CUTS_FILE = "cuts.jsonl"
EVENTS_FILE = "events.jsonl"
MAGIC = b"RTSF"
_MAGIC_U32 = struct.unpack("<I", MAGIC)[0]

FLAG_SEQ = 1
FLAG_SOURCE_TIME = 2
FLAG_ROOT = 4

_HEAD = struct.Struct("<4sddqB")      # magic, recv_time, source_time, seq, flags
_ROOT = struct.Struct("<3d")
_CRC = struct.Struct("<I")
_NO_ROOT = _ROOT.pack(math.nan, math.nan, math.nan)


def record_dtype(n_joints: int, quat_dtype: str = "<f8") -> np.dtype:
    """numpy dtype of one ``frames.bin`` record (packed, little-endian)."""
    nv = (n_joints + 7) // 8
    return np.dtype([
        ("magic", "<u4"), ("recv_time", "<f8"), ("source_time", "<f8"), ("seq", "<i8"),
        ("flags", "u1"), ("valid", "u1", (nv,)), ("root", "<f8", (3,)),
        ("quats", quat_dtype, (n_joints, 4)), ("crc", "<u4")])


@dataclass
class RecorderStats:
    """frames: records written or buffered; flushes: buffer writes; bad_frames: frames
    refused (wrong shape); write_errors: failed writes (frames lost in them are counted in
    lost_frames); cuts / events: lines appended."""
    frames: int = 0
    flushes: int = 0
    bad_frames: int = 0
    write_errors: int = 0
    lost_frames: int = 0
    cuts: int = 0
    events: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if hasattr(o, "item"):
        return o.item()
    if isinstance(o, (set, tuple)):
        return list(o)
    if isinstance(o, Path):
        return str(o)
    return repr(o)


def _json_line(obj: Mapping[str, Any]) -> str:
    def fix(v: Any) -> Any:
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: fix(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [fix(x) for x in v]
        return v
    return json.dumps(fix(dict(obj)), default=_json_default, ensure_ascii=False) + "\n"


def _atomic_write_json(path: Path, obj: Mapping[str, Any]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    data = json.dumps(obj, indent=1, default=_json_default, ensure_ascii=False).encode("utf-8")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        os.write(fd, data)
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    try:
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


class SessionRecorder:
    """Record a live session into the folder ``directory`` (created; must not exist or be
    empty - a recording is never overwritten: FileExistsError naming it).

    joint_names, parents, space ("global" | "local"): as the source reports them.
    frame_rate: nominal Hz or None (the reader then estimates it from receive times).
    meta: JSON-serialisable extras stored in the header (source URL, suit profile, ...).
    quat_dtype: "<f8" (default, exact replay) or "<f4" (half the size).
    flush_interval_s / max_buffer_frames: flush policy (see module docstring).
    fsync: fsync frames and event files at each flush.
    start_monotonic: the session's time origin (default ``time.monotonic()`` now).
    """

    def __init__(self, directory: str | Path, joint_names: Sequence[str],
                 parents: Sequence[int], space: str = "global",
                 frame_rate: float | None = None, meta: Mapping[str, Any] | None = None,
                 *, quat_dtype: str = "<f8", flush_interval_s: float = 0.5,
                 max_buffer_frames: int = 1000, fsync: bool = False,
                 start_monotonic: float | None = None) -> None:
        self.dir = Path(directory)
        self.joint_names = [str(n) for n in joint_names]
        self.parents = [int(p) for p in parents]
        if len(self.parents) != len(self.joint_names):
            raise ValueError(f"session {self.dir}: {len(self.joint_names)} joint names but "
                             f"{len(self.parents)} parents")
        if space not in ("global", "local"):
            raise ValueError(f"session {self.dir}: space must be 'global' or 'local', not {space!r}")
        if quat_dtype not in ("<f8", "<f4"):
            raise ValueError(f"session {self.dir}: quat_dtype must be '<f8' or '<f4'")
        if not flush_interval_s > 0:
            raise ValueError(f"session {self.dir}: flush_interval_s must be > 0")
        if self.dir.exists() and (not self.dir.is_dir() or any(self.dir.iterdir())):
            raise FileExistsError(f"recording folder {self.dir} already exists and is not empty")
        self.dir.mkdir(parents=True, exist_ok=True)

        self.n_joints = len(self.joint_names)
        self.quat_dtype = quat_dtype
        self.dtype = record_dtype(self.n_joints, quat_dtype)
        self.record_size = self.dtype.itemsize
        self.flush_interval_s = float(flush_interval_s)
        self.max_buffer_frames = max(1, int(max_buffer_frames))
        self.fsync = bool(fsync)
        self.start_monotonic = time.monotonic() if start_monotonic is None else float(start_monotonic)
        self.start_wall_time = time.time()
        self.stats = RecorderStats()
        self._lock = threading.RLock()
        self._buf = bytearray()
        self._nbuf = 0
        self._last_flush = time.monotonic()
        self._size = 0
        self._closed = False
        self._last_log: dict[str, float] = {}

        self.header: dict[str, Any] = {
            "format": FORMAT_NAME, "version": FORMAT_VERSION,
            "joint_names": self.joint_names, "parents": self.parents, "space": space,
            "frame_rate": None if frame_rate is None else float(frame_rate),
            "start_wall_time": self.start_wall_time,
            "start_wall_iso": _dt.datetime.fromtimestamp(
                self.start_wall_time, _dt.timezone.utc).isoformat(),
            "start_monotonic": self.start_monotonic,
            "frames_file": FRAMES_FILE,
            "record": {"size": self.record_size, "quat_dtype": quat_dtype,
                       "fields": [[n, str(self.dtype.fields[n][0])] for n in self.dtype.names]},
            "flush_interval_s": self.flush_interval_s,
            "meta": dict(meta or {}),
            "closed": False,
        }
        try:
            import rtseg
            self.header["rtseg_version"] = rtseg.__version__
        except Exception:   # noqa: BLE001
            pass
        _atomic_write_json(self.dir / HEADER_FILE, self.header)
        self._fd = os.open(self.dir / FRAMES_FILE, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        self._cuts = open(self.dir / CUTS_FILE, "a", encoding="utf-8")
        self._events = open(self.dir / EVENTS_FILE, "a", encoding="utf-8")

    # -- helpers ------------------------------------------------------------------------
    def _warn(self, key: str, msg: str) -> None:
        now = time.monotonic()
        if now - self._last_log.get(key, -1e9) >= 5.0:
            self._last_log[key] = now
            log.warning("session %s: %s", self.dir, msg)

    @property
    def session_time(self) -> float:
        """Seconds since the session's start (monotonic clock)."""
        return time.monotonic() - self.start_monotonic

    # -- frames ---------------------------------------------------------------------------
    def record_frame(self, frame: Frame) -> None:
        """Append one received frame (valid or not).  Never raises for bad input: a frame
        whose quats are not (J, 4) or valid not (J,) is counted in ``stats.bad_frames``."""
        try:
            q = np.asarray(frame.quats)
            v = np.asarray(frame.valid, dtype=bool)
            if q.shape != (self.n_joints, 4) or v.shape != (self.n_joints,):
                raise ValueError(f"quats {q.shape} / valid {v.shape}, expected "
                                 f"({self.n_joints}, 4) / ({self.n_joints},)")
            flags = 0
            seq = 0
            st = math.nan
            if frame.seq is not None:
                flags |= FLAG_SEQ
                seq = int(frame.seq)
            if frame.source_time is not None:
                flags |= FLAG_SOURCE_TIME
                st = float(frame.source_time)
            root = _NO_ROOT
            if frame.root_position is not None:
                r = np.asarray(frame.root_position, dtype=np.float64).reshape(3)
                root = _ROOT.pack(*r.tolist())
                flags |= FLAG_ROOT
            body = b"".join((
                _HEAD.pack(MAGIC, float(frame.recv_time), st, seq, flags),
                np.packbits(v, bitorder="little").tobytes(),
                root,
                q.astype(self.quat_dtype, copy=False).tobytes()))
        except (ValueError, TypeError, OverflowError, struct.error) as exc:
            with self._lock:
                self.stats.bad_frames += 1
                self._warn("bad", f"frame not recorded: {exc}")
            return
        with self._lock:
            if self._closed:
                self.stats.lost_frames += 1
                return
            self._buf += body
            self._buf += _CRC.pack(zlib.crc32(body))
            self._nbuf += 1
            self.stats.frames += 1
            if (self._nbuf >= self.max_buffer_frames
                    or time.monotonic() - self._last_flush >= self.flush_interval_s):
                self._flush_locked()

    def poll(self) -> None:
        """Flush buffered frames if the flush interval has passed (call when idle)."""
        with self._lock:
            if self._nbuf and time.monotonic() - self._last_flush >= self.flush_interval_s:
                self._flush_locked()

    def flush(self) -> None:
        """Write buffered frames now (and fsync if enabled)."""
        with self._lock:
            self._flush_locked()

    def _flush_locked(self) -> None:
        self._last_flush = time.monotonic()
        if not self._buf or self._closed and self._fd < 0:
            return
        data = memoryview(bytes(self._buf))
        n = self._nbuf
        self._buf.clear()
        self._nbuf = 0
        written = 0
        try:
            while written < len(data):
                written += os.write(self._fd, data[written:])
            if self.fsync:
                os.fsync(self._fd)
            self._size += written
            self.stats.flushes += 1
        except OSError as exc:
            self.stats.write_errors += 1
            lost = n - written // self.record_size
            self.stats.lost_frames += lost
            self._warn("write", f"writing {FRAMES_FILE} failed ({exc}); {lost} frames lost")
            # Cut a partial record off so later records stay aligned.
            try:
                os.ftruncate(self._fd, self._size + (written // self.record_size) * self.record_size)
                self._size += (written // self.record_size) * self.record_size
            except OSError:
                pass

    # -- events ---------------------------------------------------------------------------
    def _append_line(self, fh: Any, obj: Mapping[str, Any], counter: str) -> None:
        try:
            line = _json_line(obj)
        except (TypeError, ValueError) as exc:
            self._warn("encode", f"event not recorded: {exc}")
            return
        with self._lock:
            if self._closed:
                return
            try:
                fh.write(line)
                fh.flush()
                if self.fsync:
                    os.fsync(fh.fileno())
                setattr(self.stats, counter, getattr(self.stats, counter) + 1)
            except (OSError, ValueError) as exc:
                self.stats.write_errors += 1
                self._warn("write-events", f"writing {Path(fh.name).name} failed: {exc}")

    def record_cut(self, ev: CutEvent) -> None:
        """Append a cut event to ``cuts.jsonl`` (written and flushed at once)."""
        self._append_line(self._cuts, ev.to_dict(), "cuts")

    def record_event(self, ev: StatusEvent | DropoutEvent | BehaviourEvent | Mapping[str, Any]
                     ) -> None:
        """Append a status/dropout/behaviour event, or a dict (``"type"`` defaults to ``"log"``), to
        ``events.jsonl``; ``time`` (session s) and ``wall_time`` are added if missing."""
        if isinstance(ev, (StatusEvent, DropoutEvent, CutEvent, BehaviourEvent)):
            d = ev.to_dict()
        else:
            d = dict(ev)
            d.setdefault("type", "log")
        if d.get("time") is None:
            d["time"] = self.session_time
        d.setdefault("wall_time", time.time())
        self._append_line(self._events, d, "events")

    def record_log(self, message: str, level: str = "info", **fields: Any) -> None:
        """Append a ``{"type": "log", "level": .., "message": ..}`` line to events.jsonl."""
        self.record_event({"type": "log", "level": level, "message": message, **fields})

    # -- end ------------------------------------------------------------------------------
    def close(self) -> None:
        """Flush everything, close the files and rewrite session.json with ``closed: true``,
        the end time and the counters.  Idempotent."""
        with self._lock:
            if self._closed:
                return
            self._flush_locked()
            self._closed = True
            try:
                if self.fsync:
                    os.fsync(self._fd)
            except OSError:
                pass
            os.close(self._fd)
            self._fd = -1
            for fh in (self._cuts, self._events):
                try:
                    fh.close()
                except OSError:
                    pass
            self.header.update({
                "closed": True, "end_wall_time": time.time(),
                "duration_s": time.monotonic() - self.start_monotonic,
                "frames": self.stats.frames - self.stats.lost_frames,
                "stats": self.stats.as_dict()})
            try:
                _atomic_write_json(self.dir / HEADER_FILE, self.header)
            except OSError as exc:
                log.warning("session %s: cannot finalise %s: %s", self.dir, HEADER_FILE, exc)

    def __enter__(self) -> "SessionRecorder":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class RecorderLogHandler(logging.Handler):
    """A logging handler that appends log records to a recorder's ``events.jsonl``
    (``{"type": "log", "level": "warning", "logger": "...", "message": "..."}``).
    Attach it to the ``rtseg`` logger for the length of a session."""

    def __init__(self, recorder: SessionRecorder, level: int = logging.WARNING) -> None:
        super().__init__(level)
        self.recorder = recorder
        self._busy = threading.local()

    def emit(self, record: logging.LogRecord) -> None:
        if getattr(self._busy, "on", False):
            return                          # a log line from inside the recorder itself
        self._busy.on = True
        try:
            self.recorder.record_log(record.getMessage(), level=record.levelname.lower(),
                                     logger=record.name)
        except Exception:   # noqa: BLE001
            self.handleError(record)
        finally:
            self._busy.on = False


# -- reading ----------------------------------------------------------------------------------

def is_session_dir(path: str | Path) -> bool:
    """True if ``path`` is a folder holding a recorded session (has session.json)."""
    p = Path(path)
    return p.is_dir() and (p / HEADER_FILE).is_file()


def read_session_header(directory: str | Path) -> dict[str, Any]:
    """The parsed ``session.json``; ValueError naming the file if missing or invalid."""
    path = Path(directory) / HEADER_FILE
    try:
        header = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{path}: not a recorded session (no {HEADER_FILE})") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: cannot read session header: {exc}") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT_NAME:
        raise ValueError(f"{path}: not an rtseg session header (format != {FORMAT_NAME!r})")
    if header.get("version") != FORMAT_VERSION:
        raise ValueError(f"{path}: unsupported session format version {header.get('version')!r} "
                         f"(this rtseg reads version {FORMAT_VERSION})")
    for key in ("joint_names", "parents", "space"):
        if key not in header:
            raise ValueError(f"{path}: missing key {key!r}")
    return header


def _read_records(path: Path, dtype: np.dtype) -> tuple[np.ndarray, int, int]:
    """(records, torn_records, corrupt_bytes) from frames.bin.  Records failing their
    magic or CRC are skipped (resynchronising on the next good record); a partial or bad
    run at the end counts as torn records."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return np.zeros(0, dtype), 0, 0
    rs = dtype.itemsize
    n = len(data) // rs
    recs = np.frombuffer(data, dtype=dtype, count=n)
    ok = recs["magic"] == _MAGIC_U32
    if ok.all():
        crc = np.fromiter((zlib.crc32(data[i * rs:(i + 1) * rs - 4]) for i in range(n)),
                          dtype=np.uint32, count=n)
        ok = crc == recs["crc"]
    if ok.all():
        tail = len(data) - n * rs
        return recs.copy(), (1 if tail else 0), 0
    # Slow path: walk the file, resynchronising on magic + CRC.
    good: list[int] = []
    bad_spans: list[tuple[int, int]] = []
    pos = 0
    while pos + rs <= len(data):
        rec = data[pos:pos + rs]
        if rec[:4] == MAGIC and zlib.crc32(rec[:-4]) == _CRC.unpack(rec[-4:])[0]:
            good.append(pos)
            pos += rs
            continue
        nxt = data.find(MAGIC, pos + 1)
        end = len(data) if nxt < 0 else nxt
        bad_spans.append((pos, end))
        pos = end
    out = np.frombuffer(b"".join(data[p:p + rs] for p in good), dtype=dtype).copy()
    last_good_end = (good[-1] + rs) if good else 0
    torn_bytes = len(data) - max(last_good_end, 0)
    corrupt = sum(e - s for s, e in bad_spans if e <= last_good_end)
    torn = 0
    if torn_bytes > 0:
        torn = max(1, -(-torn_bytes // rs))
    return out, torn, corrupt


def _read_jsonl(path: Path) -> tuple[list[dict[str, Any]], int, int]:
    """(objects, bad_lines, torn_lines): a final line without newline or not parsing is
    torn (process killed mid-write); other bad lines are logged with their number."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return [], 0, 0
    lines = text.split("\n")
    out, bad, torn = [], 0, 0
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        last = i == len(lines) - 1
        try:
            obj = json.loads(line)
            if not isinstance(obj, dict):
                raise ValueError("not an object")
        except ValueError as exc:
            if last:
                torn += 1
            else:
                bad += 1
                log.warning("%s:%d: bad line skipped: %s", path, i + 1, exc)
            continue
        out.append(obj)
    return out, bad, torn


def read_session_cuts(directory: str | Path) -> list[CutEvent]:
    """The cut events a session recorded, in order (a torn last line is skipped)."""
    objs, _, _ = _read_jsonl(Path(directory) / CUTS_FILE)
    cuts = []
    for o in objs:
        try:
            ev = event_from_dict(o)
        except (ValueError, TypeError) as exc:
            log.warning("%s: cut line skipped: %s", Path(directory) / CUTS_FILE, exc)
            continue
        if isinstance(ev, CutEvent):
            cuts.append(ev)
    return cuts


def read_session_behaviours(directory: str | Path) -> list[BehaviourEvent]:
    """The behaviour messages (``rtseg.identity``) a session recorded in events.jsonl, in
    order (decisions and corrections)."""
    objs, _, _ = _read_jsonl(Path(directory) / EVENTS_FILE)
    out = []
    for o in objs:
        if o.get("type") != "behaviour":
            continue
        try:
            ev = event_from_dict(o)
        except (ValueError, TypeError) as exc:
            log.warning("%s: behaviour line skipped: %s", Path(directory) / EVENTS_FILE, exc)
            continue
        out.append(ev)
    return out


def _estimate_rate(recv_time: np.ndarray) -> float | None:
    d = np.diff(recv_time)
    d = d[np.isfinite(d) & (d > 0)]
    if d.size == 0:
        return None
    return float(1.0 / np.median(d))


def read_session(directory: str | Path) -> Take:
    """Read a recorded session folder as a ``Take``.

    quats (F, J, 4) float64 in received order; valid (F, J); frame_rate: the header's
    nominal rate, else estimated from the median receive interval (else 1.0);
    root_position when the source sent one (gaps filled with the last value).
    ``meta`` holds: ``recv_time`` (F,) monotonic s; ``session_time`` (F,) s since session
    start; ``source_time`` (F,) (NaN where none); ``seq`` (F,) int64 (-1 where none);
    ``cuts`` (list of CutEvent); ``events`` (list of dicts); ``header``; ``closed_cleanly``;
    ``torn_records``, ``corrupt_bytes``, ``torn_lines``; ``frame_rate_source``
    ("nominal" | "estimated" | "default"); ``estimated_frame_rate``.
    """
    d = Path(directory)
    header = read_session_header(d)
    names = [str(n) for n in header["joint_names"]]
    parents = [int(p) for p in header["parents"]]
    rec = header.get("record", {})
    qdt = rec.get("quat_dtype", "<f8")
    if qdt not in ("<f8", "<f4"):
        raise ValueError(f"{d / HEADER_FILE}: bad record.quat_dtype {qdt!r}")
    dtype = record_dtype(len(names), qdt)
    if rec.get("size", dtype.itemsize) != dtype.itemsize:
        raise ValueError(f"{d / HEADER_FILE}: record.size {rec.get('size')} does not match "
                         f"{len(names)} joints ({dtype.itemsize} bytes)")
    recs, torn, corrupt = _read_records(d / header.get("frames_file", FRAMES_FILE), dtype)
    if torn:
        log.info("session %s: %d torn record(s) at the end of %s ignored", d, torn, FRAMES_FILE)
    if corrupt:
        log.warning("session %s: %d corrupt bytes in %s skipped", d, corrupt, FRAMES_FILE)

    F, J = recs.shape[0], len(names)
    quats = recs["quats"].astype(np.float64).reshape(F, J, 4)
    valid = np.unpackbits(recs["valid"], axis=1, count=J, bitorder="little").astype(bool) \
        if F else np.zeros((0, J), bool)
    flags = recs["flags"]
    recv_time = recs["recv_time"].astype(np.float64)
    source_time = np.where(flags & FLAG_SOURCE_TIME, recs["source_time"], np.nan)
    seq = np.where(flags & FLAG_SEQ, recs["seq"], -1).astype(np.int64)

    root = None
    has_root = (flags & FLAG_ROOT) != 0
    if has_root.any():
        root = recs["root"].astype(np.float64).copy()
        idx = np.where(has_root, np.arange(F), -1)
        np.maximum.accumulate(idx, out=idx)
        first = int(np.argmax(has_root))
        idx[idx < 0] = first
        root = root[idx]

    est = _estimate_rate(recv_time)
    nominal = header.get("frame_rate")
    if nominal is not None and float(nominal) > 0:
        rate, rate_src = float(nominal), "nominal"
    elif est is not None:
        rate, rate_src = est, "estimated"
    else:
        rate, rate_src = 1.0, "default"

    cut_objs, bad_c, torn_c = _read_jsonl(d / CUTS_FILE)
    events, bad_e, torn_e = _read_jsonl(d / EVENTS_FILE)
    cuts = []
    for o in cut_objs:
        try:
            ev = event_from_dict(o)
            if isinstance(ev, CutEvent):
                cuts.append(ev)
        except (ValueError, TypeError):
            bad_c += 1
    start = float(header.get("start_monotonic", recv_time[0] if F else 0.0))
    meta: dict[str, Any] = {
        "recv_time": recv_time, "session_time": recv_time - start,
        "source_time": source_time, "seq": seq,
        "cuts": cuts, "events": events, "header": header,
        "closed_cleanly": bool(header.get("closed", False)),
        "torn_records": torn, "corrupt_bytes": corrupt,
        "torn_lines": torn_c + torn_e, "bad_lines": bad_c + bad_e,
        "frame_rate_source": rate_src, "estimated_frame_rate": est,
        "session_meta": header.get("meta", {}),
    }
    return Take(joint_names=names, parents=parents, frame_rate=rate, quats=quats,
                root_position=root, space=header["space"], valid=valid,
                length_unit="m" if root is not None else "unknown",
                source=str(d), meta=meta)
