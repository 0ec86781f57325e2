"""Reading a recorded session folder back: the header, the frames (torn or corrupt records
skipped and counted, never raised), the cut and behaviour events, and the whole session as
a :class:`~rtseg.core.take.Take`.  Times are seconds, quaternions scalar-last float64.
"""

from __future__ import annotations

import json
import logging
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from rtseg.core.events import BehaviourEvent, CutEvent, event_from_dict
from rtseg.recording.format import (_CRC, _MAGIC_U32, CUTS_FILE, EVENTS_FILE, FLAG_ROOT,
                                    FLAG_SEQ, FLAG_SOURCE_TIME, FORMAT_NAME, FORMAT_VERSION,
                                    FRAMES_FILE, HEADER_FILE, MAGIC, record_dtype)
from rtseg.core.take import Take

log = logging.getLogger("rtseg.recording")


def is_session_dir(path: str | Path) -> bool:
    """True if ``path`` is a folder holding a recorded session (has session.json)."""
    p = Path(path)
    return p.is_dir() and (p / HEADER_FILE).is_file()


def sessions_inside(path: str | Path) -> str:
    """What to say when ``path`` is not a recorded session but a folder of them (a session
    of several named sources records each in ``DIR/<name>``): "; it holds the sessions
    of a, b (in DIR/<name>): give one", else ""."""
    p = Path(path)
    if not p.is_dir():
        return ""
    inner = sorted(d.name for d in p.iterdir() if is_session_dir(d))
    return (f"; it holds the sessions of {', '.join(inner)} (in {p.name}/<name>): give one"
            if inner else "")


def folder_problem(path: str | Path, command: str, takes: str) -> str | None:
    """Why the folder ``path`` is no take for ``command`` (e.g. "rtseg plot"), in one line:
    a folder of recorded sessions (``rtseg live --record DIR`` with several sources writes
    ``DIR/<name>``: one of them is suggested) or a folder that is no recorded session
    (``takes``: the take formats to name); None for a file, a missing path or one recorded
    session's folder."""
    p = Path(path)
    if not p.is_dir() or is_session_dir(p):
        return None
    inner = sorted(d.name for d in p.iterdir() if is_session_dir(d))
    if inner:
        return (f"{p} is a folder of recorded sessions ({', '.join(inner)}: rtseg live "
                f"--record with several sources), not one take: give one of them, e.g. "
                f"{command} {p / inner[0]}")
    return (f"{p} is a folder but not a recorded session (no session.json in it): give "
            f"a take file ({takes}) or the folder of one recorded session")


def read_session_header(directory: str | Path) -> dict[str, Any]:
    """The parsed ``session.json``; ValueError naming the file if missing or invalid."""
    path = Path(directory) / HEADER_FILE
    try:
        header = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{path}: not a recorded session (no {HEADER_FILE})"
                         + sessions_inside(directory)) from None
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


def session_segment_frames(directory: str | Path, segment: int, n_frames: int) -> tuple[int, int]:
    """Frames [a, b) of segment ``segment`` of a recorded session, as its console and
    ``/rtseg/cut`` numbered it: the primary detector's segment (``meta.primary`` of the
    header; 0 runs from the first frame to its first cut), from its recorded cuts; the last
    one ends at ``n_frames``.  ValueError naming the segments the session has."""
    header = read_session_header(directory)
    primary = (header.get("meta") or {}).get("primary")
    starts = {int(c.segment): int(c.frame) for c in read_session_cuts(directory)
              if primary is None or c.method == primary}
    starts[0] = 0
    last = max(starts)
    if segment not in starts:
        raise ValueError(f"{directory}: no segment {segment}: the session's "
                         f"{primary or 'recorded'} cuts make segments 0..{last}")
    a = starts[segment]
    b = starts.get(segment + 1, int(n_frames))
    if not 0 <= a < b <= n_frames:
        raise ValueError(f"{directory}: segment {segment} spans frames {a}:{b}, outside the "
                         f"{n_frames} recorded frames")
    return a, b


def read_session_behaviours(directory: str | Path) -> list[BehaviourEvent]:
    """The behaviour messages (``rtseg.identity.tracker``) a session recorded in events.jsonl, in
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


def missing_frames(seq: np.ndarray, source_time: np.ndarray, rate: float | None
                   ) -> tuple[int, int] | None:
    """(frames missing, gaps) between the recorded frames, by the source's sequence numbers
    (-1 where none) where consecutive frames carry them, else by its clock at the nominal
    ``rate``; a step back (a wrap, a restart) is not counted.  None when neither tells."""
    ok = (seq[:-1] >= 0) & (seq[1:] >= 0)
    if ok.any():
        step = np.diff(seq)[ok]
    elif rate and np.isfinite(source_time).sum() > 1:
        t = source_time[np.isfinite(source_time)]
        step = np.rint(np.diff(t) * float(rate)).astype(np.int64)
    else:
        return None
    lost = step[step > 1] - 1
    return int(lost.sum()), int(lost.size)


def unclosed_note(directory: Path, header: dict[str, Any], n_frames: int,
                  session_time: np.ndarray, torn: int) -> str:
    """What a reader of a session that was never closed (``closed: false``: the process
    was killed or crashed, or it is still recording) has and has not: the frames read and
    the session time they reach; lost, the frames received after the last flush (at most
    ``flush_interval_s``), a record cut short, and the closing counters."""
    flush = header.get("flush_interval_s")
    last = (f"up to {flush:g} s of frames received before the end"
            if isinstance(flush, (int, float)) else "the frames received after the last flush")
    upto = (f", up to t={float(session_time[-1]):.2f} s" if n_frames else "")
    cut = (f", {torn} record(s) cut short at the end of {FRAMES_FILE}" if torn else "")
    return (f"session {directory} was not closed cleanly (killed, crashed, or still "
            f"recording): {n_frames} frames read{upto}; lost: {last}{cut}, and the session's "
            "closing summary (its frame and drop counters)")


def read_session(directory: str | Path) -> Take:
    """Read a recorded session folder as a ``Take``.

    quats (F, J, 4) float64 in received order; valid (F, J); frame_rate: the header's
    nominal rate, else estimated from the median receive interval (else 1.0);
    root_position when the source sent one (gaps filled with the last value).
    ``meta`` holds: ``recv_time`` (F,) monotonic s; ``session_time`` (F,) s since session
    start; ``source_time`` (F,) (NaN where none); ``seq`` (F,) int64 (-1 where none);
    ``cuts`` (list of CutEvent); ``events`` (list of dicts); ``header``; ``closed_cleanly``;
    ``torn_records``, ``corrupt_bytes``, ``torn_lines``; ``frame_rate_source``
    ("nominal" | "estimated" | "default"); ``estimated_frame_rate``; ``missing_frames`` and
    ``gaps``: frames the source sent that are not in the recording (lost on the way), by its
    sequence numbers or clock, when it has either (``missing_frames``).
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
    if not header.get("closed", False):
        log.warning("%s", unclosed_note(d, header, F, recv_time - start, torn))
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
    gaps = missing_frames(seq, source_time, nominal if rate_src == "nominal" else None)
    if gaps is not None:
        meta["missing_frames"], meta["gaps"] = gaps
    rest = (header.get("meta") or {}).get("rest_positions")
    if rest is not None and np.shape(rest) == (len(names), 3):
        meta["rest_positions"] = np.asarray(rest, dtype=np.float64)   # RestPose.of_take
    return Take(joint_names=names, parents=parents, frame_rate=rate, quats=quats,
                root_position=root, space=header["space"], valid=valid,
                length_unit="m" if root is not None else "unknown",
                source=str(d), meta=meta)


__all__ = ["is_session_dir", "read_session_header", "read_session_cuts",
           "read_session_behaviours", "read_session"]
