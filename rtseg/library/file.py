"""A behaviour library file (``rtseg.library.behaviours.Library``): writing (``to_dict``,
``save``) and reading (``load``); ``rtseg.library.save`` / ``rtseg.library.load``.

The file is JSON, data only: ``format`` (``rtseg-behaviour-library``), ``version`` (4;
version-1 files hold the descriptor distance only and are read as descriptor libraries;
version-2 files have no posture; version-3 posture descriptors have no joint speeds),
``profile`` and ``dims`` (the pose-feature profile and its dims), the window settings,
``threshold`` and ``ratio`` (the rejection rule), ``k_nearest`` (a name's distance is the
mean of its k nearest windows'; a file without it reads as 1, the rule its threshold
was calibrated for), ``scale`` (per descriptor dim), per
window its ``names`` / ``sources`` (example index) / ``starts`` / ``descriptors``, the
distance ``metric`` (``model`` or ``descriptor``) and, for ``model``, ``lag_s`` and per
window its ``window_stats`` (``rtseg.library.distance.stats_to_json``: frame count, mean and
upper-triangle scatter of the joints' angular velocities, 3J dims), ``posture`` (per
window its body descriptor, ``rtseg.library.posture_distance.body_descriptor``: 2 x 42
posture values, then J joint speeds when ``posture_speed_weight`` is above 0; absent when
the examples' rest geometry was unknown) with ``posture_rule`` (threshold, ratio and scale
of the model x posture distance, ``rtseg.library.posture_distance``) and
``posture_speed_weight`` (0 or absent: posture alone), and the
``examples`` (name, source, frames, person).  Everything is checked on load; any problem
is one ``LibraryError`` line naming the file.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from rtseg.library.behaviours import FORMAT, GROUPS, METRICS, READS, VERSION, Library, LibraryError
from rtseg.library.distance import LAG_S, stats_from_json, stats_to_json


def to_dict(lib: Library) -> dict[str, Any]:
    """The library as a JSON-ready dict (module doc; floats rounded to 6-7 digits)."""
    return {"format": FORMAT, "version": VERSION, "profile": lib.profile,
            "dims": int(lib.dims), "frame_rate": float(lib.frame_rate),
            "window_s": lib.window_s, "step_s": lib.step_s, "edge_s": lib.edge_s,
            "min_s": lib.min_s, "descriptor": list(GROUPS),
            "threshold": float(lib.threshold) if math.isfinite(lib.threshold) else None,
            "ratio": float(lib.ratio), "k_nearest": int(lib.k_nearest),
            "metric": lib.metric, "lag_s": float(lib.lag_s),
            "calibration": dict(lib.calibration),
            "scale": [round(float(v), 6) for v in lib.scale],
            "names": list(lib.names), "sources": [int(s) for s in lib.sources],
            "starts": [float(s) for s in (lib.starts or [0.0] * len(lib.names))],
            "descriptors": [[round(float(v), 6) for v in row] for row in lib.descriptors],
            **({"window_stats": stats_to_json(lib.window_stats)}
               if lib.metric == "model" else {}),
            **({"posture": [[round(float(v), 6) for v in row] for row in lib.posture],
                "posture_rule": {k: (float(v) if v is not None and math.isfinite(v) else None)
                                 for k, v in lib.posture_rule.items()},
                "posture_speed_weight": float(lib.speed_weight)}
               if lib.has_posture else {}),
            "examples": lib.examples}


def save(lib: Library, path: str | Path) -> Path:
    """Write the library as JSON, atomically (a temporary file renamed); a missing folder
    is made."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps(to_dict(lib), allow_nan=False) + "\n", encoding="utf-8")
    tmp.replace(p)
    return p


#: JSON type of each field: "str", "int", "num" (int or float), a trailing "?" (or null),
#: "[T]" a list of T, "[[num]]" a list of lists of numbers
_TYPES = {"profile": "str", "dims": "int", "frame_rate": "num", "window_s": "num",
          "step_s": "num", "edge_s": "num", "min_s": "num", "threshold": "num?",
          "names": "[str]", "sources": "[int]", "scale": "[num]", "descriptors": "[[num]]",
          "examples": "[dict]"}
#: fields that may be absent (files written before them)
_OPTIONAL_TYPES = {"ratio": "num", "k_nearest": "int", "metric": "str", "lag_s": "num",
                   "starts": "[num]", "calibration": "dict?", "posture": "[[num]]",
                   "posture_rule": "dict", "posture_speed_weight": "num"}
_WHAT = {"str": "a string", "int": "a whole number", "num": "a number", "dict": "an object",
         "[num]": "a list of numbers"}


def _type_ok(value: Any, kind: str) -> bool:
    """Whether a JSON value is of ``kind`` (see ``_TYPES``; lists: their elements too)."""
    if kind.endswith("?"):
        return value is None or _type_ok(value, kind[:-1])
    if kind.startswith("["):
        return isinstance(value, list) and all(_type_ok(v, kind[1:-1]) for v in value)
    if kind == "str":
        return isinstance(value, str)
    if kind == "int":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "num":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, dict)


def _describe(kind: str) -> str:
    if kind.endswith("?"):
        return f"{_describe(kind[:-1])} or null"
    if kind.startswith("["):
        return f"a list of {_describe(kind[1:-1]).split(' ', 1)[1]}s"
    return _WHAT[kind]


def _check_types(doc: dict, p: Path) -> None:
    """One ``LibraryError`` line naming the first field (or list element) of the wrong JSON
    type - a number among the names, a string for dims, ...; nothing is converted."""
    fields = {**_TYPES, **{k: v for k, v in _OPTIONAL_TYPES.items() if k in doc}}
    for key, kind in fields.items():
        if key not in doc:
            raise LibraryError(f"behaviour library {p}: malformed (no {key!r} field)")
        value = doc[key]
        if _type_ok(value, kind):
            continue
        where = key
        if kind.startswith("[") and isinstance(value, list):
            i = next(i for i, v in enumerate(value) if not _type_ok(v, kind[1:-1]))
            where, value = f"{key}[{i}]", value[i]
            kind = kind[1:-1]
        raise LibraryError(f"behaviour library {p}: {where} must be {_describe(kind)}, got "
                           f"{json.dumps(value)[:40]}")


#: library files already warned about (``load``)
_WARNED: set[str] = set()


def load(path: str | Path, profile: str | None = None, dims: int | None = None) -> Library:
    """Read a library file; ``LibraryError`` (one line) when it is not a library of this
    format and version, or (when given) not of ``profile`` / ``dims``."""
    p = Path(path)
    try:
        raw = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise LibraryError(f"behaviour library {p}: cannot read ({exc.strerror or exc})") from None
    try:
        doc = json.loads(raw)
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise LibraryError(f"behaviour library {p}: not a JSON behaviour library") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise LibraryError(f"behaviour library {p}: not a behaviour library "
                           f"(format {doc.get('format') if isinstance(doc, dict) else None!r}, "
                           f"expected {FORMAT!r})")
    if doc.get("version") not in READS:
        raise LibraryError(f"behaviour library {p}: version {doc.get('version')!r} "
                           f"(this rtseg reads versions {', '.join(map(str, READS))}; "
                           f"learn it again)")
    _check_types(doc, p)
    metric = str(doc.get("metric", "descriptor")) if doc["version"] >= 2 else "descriptor"
    try:
        lib = Library(str(doc["profile"]), int(doc["dims"]), float(doc["frame_rate"]),
                      np.asarray(doc["descriptors"], dtype=np.float64),
                      [str(n) for n in doc["names"]], [int(s) for s in doc["sources"]],
                      list(doc["examples"]),
                      scale=np.asarray(doc["scale"], dtype=np.float64),
                      threshold=math.inf if doc["threshold"] is None else float(doc["threshold"]),
                      ratio=float(doc.get("ratio", 1.0)),
                      window_s=float(doc["window_s"]), step_s=float(doc["step_s"]),
                      edge_s=float(doc["edge_s"]), min_s=float(doc["min_s"]),
                      calibration=dict(doc.get("calibration") or {}),
                      starts=[float(x) for x in doc.get("starts") or []],
                      k_nearest=int(doc.get("k_nearest", 1)), metric=metric,
                      lag_s=float(doc.get("lag_s", LAG_S)))
        if metric not in METRICS:
            raise ValueError(f"metric {metric!r} not one of {', '.join(METRICS)}")
        if not (lib.frame_rate > 0 and math.isfinite(lib.frame_rate)):
            raise ValueError(f"frame_rate {lib.frame_rate} not a positive number")
        if not 0 < lib.ratio <= 1:
            raise ValueError(f"ratio {lib.ratio} outside (0, 1]")
        if lib.k_nearest < 1:
            raise ValueError(f"k_nearest {lib.k_nearest} below 1")
    except (KeyError, TypeError, ValueError) as exc:
        raise LibraryError(f"behaviour library {p}: malformed ({type(exc).__name__}: "
                           f"{exc})") from None
    k = 6 * (lib.dims // 4)
    n = len(lib.names)
    if (lib.dims <= 0 or lib.dims % 4 or lib.descriptors.shape != (n, k)
            or lib.scale.shape != (k,) or len(lib.sources) != n or not n
            or (lib.starts and len(lib.starts) != n)
            or any(not 0 <= x < len(lib.examples) for x in lib.sources)
            or not np.all(np.isfinite(lib.descriptors)) or not np.all(lib.scale > 0)):
        raise LibraryError(f"behaviour library {p}: malformed (descriptor, scale or name "
                           f"counts do not agree with {lib.dims} dims)")
    if profile is not None and (lib.profile != profile or (dims is not None and lib.dims != dims)):
        raise LibraryError(f"behaviour library {p}: learned for feature profile "
                           f"{lib.profile!r} ({lib.dims} dims), this session's features are "
                           f"{profile!r} ({dims} dims); learn it from takes of this skeleton")
    if metric == "model":
        try:
            lib.window_stats = stats_from_json(doc["window_stats"], 3 * (lib.dims // 4))
            if len(lib.window_stats) != len(lib.names):
                raise ValueError(f"{len(lib.window_stats)} window statistics for "
                                 f"{len(lib.names)} windows")
            if not lib.lag_s > 0:
                raise ValueError(f"lag_s {lib.lag_s} not positive")
        except (KeyError, TypeError, ValueError, np.linalg.LinAlgError) as exc:
            raise LibraryError(f"behaviour library {p}: malformed ({type(exc).__name__}: "
                               f"{exc})") from None
        try:
            lib.bank                     # the windows' models, fitted once here (not live)
        except (KeyError, TypeError, ValueError, np.linalg.LinAlgError) as exc:
            raise LibraryError(f"behaviour library {p}: malformed ({type(exc).__name__}: "
                               f"{exc})") from None
    if "posture" in doc:
        _load_posture(lib, doc, p)
    if (not math.isfinite(lib.threshold) and not lib.calibration.get("threshold_given")
            and str(p.resolve()) not in _WARNED):
        _WARNED.add(str(p.resolve()))    # once per file (rtseg live checks it, then loads it)
        logging.getLogger(__name__).warning(
            "behaviour library %s has no rejection threshold (it was learned from one "
            "example per behaviour): every segment will get a name; "
            "learn it again ('rtseg learn %s --new ...'), or add an example to it, which "
            "calibrates it anew", p, p)
    return lib


def _load_posture(lib: Library, doc: dict, p: Path) -> None:
    """The body descriptors, rule and joint-speed weight of a version-3 or -4 file
    (LibraryError when malformed)."""
    from rtseg.core.posture import DIM
    P = np.asarray(doc["posture"], dtype=np.float64)
    rule = doc.get("posture_rule") or {}
    t, r, s = rule.get("threshold"), rule.get("ratio"), rule.get("scale")
    w = float(doc.get("posture_speed_weight", 0.0))
    width = 2 * DIM + (lib.dims // 4 if w else 0)
    num = lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)   # noqa: E731
    ok = (lib.metric == "model" and P.shape == (len(lib.names), width)
          and math.isfinite(w) and w >= 0
          and bool(np.all(np.isfinite(P)))
          and (not rule or ((t is None or num(t) and t > 0) and num(r) and 0 < r <= 1
                            and num(s) and s > 0)))
    if not ok:
        raise LibraryError(f"behaviour library {p}: malformed (posture descriptors or rule "
                           f"do not agree with its {len(lib.names)} windows)")
    lib.posture = P
    lib.speed_weight = w
    lib.posture_rule = {} if not rule else {
        "threshold": math.inf if t is None else float(t), "ratio": float(r), "scale": float(s)}
