"""Archives of takes: find the takes (``runner``), run one task per take (``records``) in
this process or on Dask (``executors``), and keep the records (``store``: JSON lines or
Parquet).

May import ``rtseg.detectors``, ``rtseg.identity``, ``rtseg.labels``, ``rtseg.core`` and
the drivers' readers (``rtseg.drivers.readers``)."""

from rtseg.archive.runner import (
    TAKE_EXTENSIONS,
    SESSION_HEADER,
    discover_takes,
    ArchiveRun,
    run_archive,
)

__all__ = [
    "TAKE_EXTENSIONS",
    "SESSION_HEADER",
    "discover_takes",
    "ArchiveRun",
    "run_archive",
]
