"""Take readers, one module per file format; all return ``rtseg.core.take.Take``.

``read_take(path)`` picks the reader by extension; ``write_take(path, take)`` writes
rtseg's own ``.npz`` take format.  Malformed input raises ``ReaderError`` (a ValueError)
naming the file, the line and the problem.

May import ``rtseg.core`` and ``rtseg.recording`` (a recorded session folder is a take)."""

from __future__ import annotations

from pathlib import Path

from rtseg.drivers.readers.errors import ReaderError
from rtseg.core.take import Take

READERS = {".amc": "asf/amc", ".bvh": "bvh", ".npz": "npz", ".csv": "tsseg4d csv"}


def read_take(path: str | Path, skeleton: str | Path | None = None,
              frame_rate: float | None = None) -> Take:
    """Read a take, format chosen by extension.

    - ``.amc``: Acclaim motion; ``skeleton`` is its ASF, default ``SS.asf`` beside ``SS_TT.amc``.
    - ``.bvh``: Biovision hierarchy + motion.
    - ``.npz``: rtseg's quaternion take format (``docs/formats.md``).
    - ``.csv``: tsseg4d four-channel CSV with per-frame labels.
    - a directory: a session recorded by ``rtseg live --record`` (``rtseg.recording``).

    ``frame_rate`` (Hz) overrides the file's rate (ASF/AMC, CSV have none; default 120).
    """
    path = Path(path)
    if not path.exists():
        raise ReaderError(path, "file not found")
    if path.is_dir():
        try:
            from rtseg.recording import read_session
        except ImportError as exc:
            raise ReaderError(path, f"is a directory, and session reading is unavailable ({exc})") from None
        try:
            take = read_session(path)
        except ReaderError:
            raise
        except ValueError as exc:  # session errors already name their file
            raise ReaderError(path, str(exc)) from exc
        if frame_rate is not None:
            take.frame_rate = float(frame_rate)
        return take
    ext = path.suffix.lower()
    if ext == ".amc":
        from rtseg.drivers.readers.amc import read_asf_amc
        return read_asf_amc(path, skeleton=skeleton, frame_rate=frame_rate)
    if ext == ".asf":
        raise ReaderError(path, "an ASF file is a skeleton without motion; read the .amc take "
                          "(its skeleton is found beside it, or give it: --skeleton FILE, skeleton=)")
    if ext == ".bvh":
        from rtseg.drivers.readers.bvh import read_bvh
        return read_bvh(path, frame_rate=frame_rate)
    if ext == ".npz":
        from rtseg.drivers.readers.npz_take import read_npz
        return read_npz(path, frame_rate=frame_rate)
    if ext == ".csv":
        from rtseg.drivers.readers.csv_channels import read_csv_channels
        return read_csv_channels(path, frame_rate=frame_rate)
    raise ReaderError(path, f"unknown take format {ext or '(no extension)'!r}; known: "
                      + ", ".join(f"{e} ({n})" for e, n in READERS.items()) + ", or a session folder")


def write_take(path: str | Path, take: Take) -> Path:
    """Write ``take`` in rtseg's ``.npz`` take format; returns the path written."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise ValueError(f"{path}: write_take writes .npz only")
    from rtseg.drivers.readers.npz_take import write_npz
    return write_npz(path, take)


__all__ = ["ReaderError", "read_take", "write_take", "READERS"]
