"""Writing a recorded session: :class:`SessionRecorder` (frames, cuts, events, the header)
and :class:`RecorderLogHandler` (log records into ``events.jsonl``).

Usage, durability and the folder layout are described in :mod:`rtseg.recording`.  Times
are seconds (``recv_time`` on the monotonic clock), quaternions scalar-last.
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
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from rtseg.core.events import BehaviourEvent, CutEvent, DropoutEvent, StatusEvent
from rtseg.core.frame import Frame
from rtseg.recording.format import (_CRC, _HEAD, _NO_ROOT, _ROOT, CUTS_FILE, EVENTS_FILE,
                                    FLAG_ROOT, FLAG_SEQ, FLAG_SOURCE_TIME, FORMAT_NAME,
                                    FORMAT_VERSION, FRAMES_FILE, HEADER_FILE, MAGIC,
                                    record_dtype)

log = logging.getLogger("rtseg.recording")

@dataclass
class RecorderStats:
    """frames: records written or buffered; flushes: buffer writes; bad_frames: frames
    refused (wrong shape); write_errors: failed writes (frames lost in them are counted in
    lost_frames); cuts / events: lines appended; lost_cuts / lost_events: lines not written
    (a write failed, or the recording had already failed)."""
    frames: int = 0
    flushes: int = 0
    bad_frames: int = 0
    write_errors: int = 0
    lost_frames: int = 0
    cuts: int = 0
    events: int = 0
    lost_cuts: int = 0
    lost_events: int = 0

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


#: bytes the header file is padded to (JSON followed by spaces) when first written, so
#: the final header can overwrite it in place on a full disk
HEADER_RESERVE = 16384


def _header_bytes(obj: Mapping[str, Any], pad_to: int = 0) -> bytes:
    data = json.dumps(obj, indent=1, default=_json_default, ensure_ascii=False).encode("utf-8")
    data += b"\n"
    return data + b" " * max(0, pad_to - len(data))


def _atomic_write_json(path: Path, obj: Mapping[str, Any], pad_to: int = 0) -> None:
    """Write ``obj`` to ``path`` through ``path.tmp`` and a rename (the tmp file is removed
    when the write fails).  Errors are OSErrors naming ``path``."""
    tmp = path.with_name(path.name + ".tmp")
    data = _header_bytes(obj, pad_to)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view):]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
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
        #: session seconds now, from the live session's clock (``rtseg.live.clock``), for
        #: the times of log lines; None: seconds since ``start_monotonic``
        self.clock: Callable[[], float] | None = None
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
        #: None while every write succeeded; else the first failure: ``path``, ``error``,
        #: ``at_frame`` (frames the recording holds: frames 0..at_frame-1 were written)
        self.failure: dict[str, Any] | None = None
        _atomic_write_json(self.dir / HEADER_FILE, self.header, pad_to=HEADER_RESERVE)
        self._fd = os.open(self.dir / FRAMES_FILE, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        self._cuts = open(self.dir / CUTS_FILE, "a", encoding="utf-8")
        self._events = open(self.dir / EVENTS_FILE, "a", encoding="utf-8")

    def _fail(self, path: Path, exc: BaseException) -> None:
        """The first write error: one error line naming the file and the cause; from now
        on nothing more is written (later frames and lines are counted as lost) so what
        the folder holds is a consistent, shorter session."""
        if self.failure is not None:
            return
        at = self._size // self.record_size
        cause = getattr(exc, "strerror", None) or str(exc)
        self.failure = {"path": str(path), "error": cause, "at_frame": at}
        log.error("session %s: recording failed at frame %d: writing %s failed: %s; the "
                  "recording holds %d frames and %d cuts, later frames and cuts are not "
                  "recorded", self.dir, at, path, cause, at, self.stats.cuts)

    @property
    def frames_written(self) -> int:
        """Frames in ``frames.bin`` so far (excluding the unflushed buffer)."""
        return self._size // self.record_size

    # -- helpers ------------------------------------------------------------------------
    def _warn(self, key: str, msg: str) -> None:
        now = time.monotonic()
        if now - self._last_log.get(key, -1e9) >= 5.0:
            self._last_log[key] = now
            log.warning("session %s: %s", self.dir, msg)

    @property
    def session_time(self) -> float:
        """Session seconds now: the live session's clock when it set ``clock``, else
        seconds since the session's start (monotonic clock)."""
        if self.clock is not None:
            try:
                return float(self.clock())
            except Exception:  # pragma: no cover - a log line must never fail on its time
                pass
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
            if self._closed or self.failure is not None:
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
            # Cut a partial record off so the file holds whole records only.
            try:
                os.ftruncate(self._fd, self._size + (written // self.record_size) * self.record_size)
                self._size += (written // self.record_size) * self.record_size
            except OSError:
                pass
            self._fail(self.dir / FRAMES_FILE, exc)

    # -- events ---------------------------------------------------------------------------
    def _append_line(self, fh: Any, obj: Mapping[str, Any], counter: str) -> None:
        try:
            line = _json_line(obj)
        except (TypeError, ValueError) as exc:
            self._warn("encode", f"event not recorded: {exc}")
            return
        lost = "lost_" + counter
        with self._lock:
            if self._closed or self.failure is not None:
                setattr(self.stats, lost, getattr(self.stats, lost) + 1)
                return
            try:
                fh.write(line)
                fh.flush()
                if self.fsync:
                    os.fsync(fh.fileno())
                setattr(self.stats, counter, getattr(self.stats, counter) + 1)
            except (OSError, ValueError) as exc:
                self.stats.write_errors += 1
                setattr(self.stats, lost, getattr(self.stats, lost) + 1)
                self._fail(self.dir / Path(fh.name).name, exc)

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

    def note_session(self, counts: Mapping[str, Any]) -> None:
        """The live session's final counters (frames lost and input refused, by name:
        ``LiveSession.loss_counts``), written to session.json under ``"session"`` at
        :meth:`close`."""
        with self._lock:
            self.header["session"] = dict(counts)

    def note_rest(self, positions: Any) -> None:
        """The source rig's rest geometry (``rtseg.core.posture.RestPose.positions``: (J, 3)
        each joint's rest location, the source's units), written to session.json's
        ``meta["rest_positions"]`` at :meth:`close`: a replay of the recording then has the
        posture the live session had.  ValueError for another shape."""
        rest = np.asarray(positions, dtype=np.float64)
        if rest.shape != (len(self.joint_names), 3) or not np.isfinite(rest).all():
            raise ValueError(f"session {self.dir}: rest geometry of shape {rest.shape} for "
                             f"{len(self.joint_names)} joints")
        with self._lock:
            self.header["meta"]["rest_positions"] = rest.tolist()

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
                except OSError as exc:
                    self._fail(self.dir / Path(fh.name).name, exc)
            self.header.update({
                "closed": True, "end_wall_time": time.time(),
                "duration_s": time.monotonic() - self.start_monotonic,
                "frames": self.frames_written,
                "cuts": self.stats.cuts,
                "recording_failed": self.failure,
                "stats": self.stats.as_dict()})
            path = self.dir / HEADER_FILE
            try:
                _atomic_write_json(path, self.header)
            except OSError as exc:
                # a full disk: overwrite the padded header in place (no new blocks needed)
                data = _header_bytes(self.header)
                try:
                    if len(data) > path.stat().st_size:
                        raise OSError(exc.errno, "final header larger than the space "
                                      "reserved for it", str(path))
                    with open(path, "r+b") as fh:
                        fh.write(data + b" " * (path.stat().st_size - len(data)))
                        fh.flush()
                        os.fsync(fh.fileno())
                except OSError as exc2:
                    log.error("session %s: cannot finalise %s: %s", self.dir, path,
                              exc2.strerror or exc2)

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




__all__ = ["RecorderStats", "SessionRecorder", "RecorderLogHandler"]
