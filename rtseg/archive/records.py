"""One archive task and its records: ``take_records`` reads one take, runs the methods on it
and returns one JSON-ready record per method (the record layout: ``rtseg.archive.runner``);
``error_record`` is the record of a take or task that failed.  Run on workers (Dask or this
process): it imports neither the archive runner nor its executors."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Mapping, Sequence


def take_name(path: str) -> str:
    """A take's display name: the file name without extension (a session: its folder)."""
    p = Path(path)
    return p.name if p.is_dir() else p.stem


def param_differences(take: Any, params: Mapping[str, Mapping[str, Any]]
                      ) -> dict[str, list[str]]:
    """For a recorded session whose detectors ran with other parameters
    (``meta["session_meta"]["detector_params"]``) than ``params`` give: method ->
    ``"key = live (now value)"`` for each differing key of each method both have; {} for
    other takes (and recordings made before sessions kept their parameters)."""
    from rtseg.detectors import method_params
    meta = take.meta.get("session_meta") if isinstance(take.meta, dict) else None
    recorded = meta.get("detector_params") if isinstance(meta, dict) else None
    if not isinstance(recorded, dict):
        return {}
    out = {}
    for m, used in params.items():
        live = recorded.get(m)
        if not isinstance(live, dict):
            continue
        now = method_params(m, used)
        diffs = [f"{k} = {live[k]!r} (now {now[k]!r})" for k in sorted(live)
                 if k in now and live[k] != now[k]]
        if diffs:
            out[m] = diffs
    return out


def take_records(path: str, methods: Sequence[str],
                 params: Mapping[str, Mapping[str, Any]] | None = None,
                 profile: str | None = None, skeleton: str | None = None,
                 identify: bool = False, identity_threshold: float | None = None
                 ) -> list[dict[str, Any]]:
    """The task for one take: read ``path``, compute the features once, run ``methods``.

    identify: give each segment its behaviour id (``rtseg.identity.segments.identify_take``;
    a ``behaviour`` field in each segment of the records), with ``identity_threshold``.

    Runs on a worker: reads the file itself; returns small JSON-ready records, one per
    method.  A take that cannot be read or segmented gives records whose ``error`` is the
    message (the exception type prefixed unless it is a reader's or a ValueError).
    """
    from rtseg.identity.segments import identify_take
    from rtseg.detectors.segmentation import segment_take_methods
    from rtseg.drivers.readers import read_take
    t0 = time.perf_counter()
    base = {"take": take_name(path), "path": path}
    try:
        take = read_take(path, skeleton=skeleton)
        if identify:
            results = identify_take(take, list(methods), dict(params or {}), profile=profile,
                                    threshold=identity_threshold)
        else:
            results = segment_take_methods(take, list(methods), dict(params or {}),
                                           profile=profile)
    except Exception as exc:  # noqa: BLE001 - a failed take is a record, never a crash
        msg = str(exc) if isinstance(exc, (ValueError, OSError)) else \
            f"{type(exc).__name__}: {exc}"
        return [error_record(path, m, msg, time.perf_counter() - t0) for m in methods]
    total = round(time.perf_counter() - t0, 4)
    # a recorded session missing frames its source sent: frames and times count the
    # recorded frames (early after each gap), so its records say how many are missing
    lost = take.meta.get("missing_frames") if isinstance(take.meta, dict) else None
    extra = {"missing_frames": int(lost), "gaps": int(take.meta.get("gaps") or 0)} if lost else {}
    # a recorded session whose detectors ran with other parameters than these
    differ = param_differences(take, {m: dict((params or {}).get(m, {})) for m in results})
    out = []
    for m, r in results.items():
        d = r.as_dict()
        out.append({**base, "method": m, "frame_rate": r.frame_rate, "n_frames": r.n_frames,
                    "cuts": d["cuts"], "segments": d["segments"],
                    "elapsed_s": round(r.elapsed_s, 4), "take_elapsed_s": total,
                    **extra, **({"params_differ": differ[m]} if m in differ else {}),
                    "error": None})
    return out


def error_record(path: str, method: str, message: str, elapsed: float = 0.0
                 ) -> dict[str, Any]:
    return {"take": take_name(path), "path": path, "method": method, "frame_rate": None,
            "n_frames": None, "cuts": None, "segments": None, "elapsed_s": None,
            "take_elapsed_s": round(elapsed, 4), "error": message or "failed"}
