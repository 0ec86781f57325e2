"""rtseg's own take format: a NumPy ``.npz`` of quaternions (specified in docs/formats.md).

Arrays (no pickled objects; ``np.load(allow_pickle=False)`` reads it):

===================  =========================  ==========================================
key                  dtype / shape              meaning
===================  =========================  ==========================================
format_version       int64 scalar               1
joint_names          unicode (J,)               joint names
parents              int64 (J,)                 parent index, -1 for roots
frame_rate           float64 scalar             Hz
quats                float32|float64 (F, J, 4)  unit quaternions, scalar-last x, y, z, w
space                unicode scalar             "local" or "global"
root_position        float64 (F, 3)             optional, in ``length_unit``
valid                bool (F, J)                optional, False where a sensor did not report
length_unit          unicode scalar             optional
source               unicode scalar             optional, where the take came from
meta_json            unicode scalar             optional, JSON of the plain ``Take.meta`` entries
meta__<key>          any numeric (..)           optional, ``Take.meta[key]`` arrays
===================  =========================  ==========================================
"""

from __future__ import annotations

import json
import logging
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from rtseg.drivers.readers.errors import ReaderError
from rtseg.core.take import Take

FORMAT_VERSION = 1
_REQUIRED = ("format_version", "joint_names", "parents", "frame_rate", "quats", "space")
_META_ARRAY = "meta__"
log = logging.getLogger(__name__)


def _plain(value: Any) -> Any:
    """``value`` if JSON can hold it exactly, else raise TypeError."""
    json.dumps(value, allow_nan=True)
    return value


def write_npz(path: str | Path, take: Take, dtype: type = np.float64, compress: bool = True) -> Path:
    """Write ``take`` to ``path`` (.npz).  ``dtype`` float32 halves the size of ``quats``.

    Numeric ``meta`` arrays are stored as ``meta__<key>``; JSON-able meta entries in
    ``meta_json``; anything else is skipped with a logged warning naming the key.
    """
    path = Path(path)
    if np.dtype(dtype) not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError("dtype must be float32 or float64")
    arrays: dict[str, np.ndarray] = {
        "format_version": np.array(FORMAT_VERSION, dtype=np.int64),
        "joint_names": np.array(take.joint_names, dtype=np.str_),
        "parents": np.array(take.parents, dtype=np.int64),
        "frame_rate": np.array(float(take.frame_rate)),
        "quats": np.asarray(take.quats, dtype=dtype),
        "space": np.array(take.space),
        "length_unit": np.array(take.length_unit),
        "source": np.array(take.source),
    }
    if take.root_position is not None:
        arrays["root_position"] = np.asarray(take.root_position, dtype=np.float64)
    if take.valid is not None:
        arrays["valid"] = np.asarray(take.valid, dtype=bool)
    plain: dict[str, Any] = {}
    for key, value in take.meta.items():
        if isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
            arrays[_META_ARRAY + key] = value
            continue
        try:
            plain[key] = _plain(value)
        except (TypeError, ValueError):
            log.warning("%s: meta entry %r (%s) not stored: not an array or JSON value",
                        path, key, type(value).__name__)
    arrays["meta_json"] = np.array(json.dumps(plain))
    save = np.savez_compressed if compress else np.savez
    with open(path, "wb") as fh:
        save(fh, **arrays)
    return path


def _scalar(path: Path, z: Any, key: str, kind: str) -> Any:
    a = z[key]
    if a.shape != ():
        raise ReaderError(path, f"{key!r} must be a scalar, got shape {a.shape}")
    if a.dtype.kind not in kind:
        raise ReaderError(path, f"{key!r} has dtype {a.dtype}, expected kind {kind!r}")
    return a.item()


def read_npz(path: str | Path, frame_rate: float | None = None) -> Take:
    """Read an rtseg ``.npz`` take; ``frame_rate`` overrides the stored rate."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except FileNotFoundError:
        raise ReaderError(path, "file not found") from None
    except IsADirectoryError:
        raise ReaderError(path, "is a directory, not a file") from None
    except OSError as exc:
        raise ReaderError(path, f"cannot read ({exc.strerror or exc})") from None
    if not magic:
        raise ReaderError(path, "empty file (not an .npz take)")
    if magic != b"PK\x03\x04":   # .npz files are zip archives
        raise ReaderError(path, "not a readable .npz file (no zip archive signature)")
    try:
        z = np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise ReaderError(path, f"not a readable .npz file ({exc})") from None
    with z:
        keys = set(z.files)
        missing = [k for k in _REQUIRED if k not in keys]
        if missing:
            raise ReaderError(path, f"missing array {missing[0]!r} (not an rtseg take? "
                              f"found: {', '.join(sorted(keys)) or 'nothing'})")
        try:
            version = _scalar(path, z, "format_version", "iu")
            if version > FORMAT_VERSION or version < 1:
                raise ReaderError(path, f"format_version {version} not supported (this rtseg reads 1..{FORMAT_VERSION})")
            names = z["joint_names"]
            if names.ndim != 1 or names.dtype.kind != "U":
                raise ReaderError(path, "'joint_names' must be a 1-D string array")
            parents = z["parents"]
            if parents.shape != names.shape or parents.dtype.kind not in "iu":
                raise ReaderError(path, f"'parents' must be {names.shape} integers, got {parents.shape} {parents.dtype}")
            bad = [j for j, p in enumerate(parents.tolist()) if not -1 <= p < len(names) or p == j]
            if bad:
                raise ReaderError(path, f"joint {str(names[bad[0]])!r} has invalid parent index {int(parents[bad[0]])}")
            quats = z["quats"]
            if quats.dtype not in (np.float32, np.float64):
                raise ReaderError(path, f"'quats' must be float32 or float64, got {quats.dtype}")
            if quats.ndim != 3 or quats.shape[1:] != (len(names), 4):
                raise ReaderError(path, f"'quats' must be (frames, {len(names)}, 4), got {quats.shape}")
            rate = float(_scalar(path, z, "frame_rate", "fiu"))
            if frame_rate is not None:
                rate = float(frame_rate)
            if not rate > 0:
                raise ReaderError(path, f"frame_rate must be positive, got {rate}")
            space = str(_scalar(path, z, "space", "U"))
            root_position = z["root_position"] if "root_position" in keys else None
            valid = z["valid"] if "valid" in keys else None
            length_unit = str(_scalar(path, z, "length_unit", "U")) if "length_unit" in keys else "unknown"
            source = str(_scalar(path, z, "source", "U")) if "source" in keys else ""
            meta: dict[str, Any] = {}
            if "meta_json" in keys:
                try:
                    meta.update(json.loads(str(_scalar(path, z, "meta_json", "U"))))
                except json.JSONDecodeError as exc:
                    raise ReaderError(path, f"'meta_json' is not valid JSON ({exc})") from None
            for k in keys:
                if k.startswith(_META_ARRAY):
                    meta[k[len(_META_ARRAY):]] = z[k]
        except (zipfile.BadZipFile, OSError, EOFError) as exc:
            raise ReaderError(path, f"corrupt .npz member ({exc})") from None
        except ValueError as exc:
            if isinstance(exc, ReaderError):
                raise
            raise ReaderError(path, f"unreadable array ({exc})") from None
    if not np.all(np.isfinite(quats)):
        raise ReaderError(path, "'quats' holds non-finite values")
    try:
        take = Take(joint_names=[str(n) for n in names], parents=[int(p) for p in parents],
                    frame_rate=rate, quats=quats, root_position=root_position, space=space,
                    valid=valid, length_unit=length_unit, source=str(path), meta=meta)
    except ValueError as exc:
        raise ReaderError(path, str(exc)) from None
    meta.setdefault("format", "npz")
    if source and source != str(path):
        meta.setdefault("original_source", source)
    return take
