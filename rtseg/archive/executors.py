"""Where the per-take tasks of ``rtseg.archive.runner`` run: in this process, on a local Dask
cluster (``dask.distributed.LocalCluster``, worker processes, one thread each), or on a
running Dask scheduler; and the progress line on stderr.

Dask is optional (``pip install 'rtseg[scale]'``).  Without it ``workers`` falls back to
this process with a warning and ``scheduler`` is a clear error.  One task per take: the
task's arguments are the take's path, its method names and the (small) parameter dicts;
its result is the take's records.  A task that dies on its worker (the worker crashed or
was killed) is a record with the error, like any other failed take.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import time
import warnings
from typing import Any, Callable, Iterator, Sequence, TextIO

log = logging.getLogger(__name__)


def have_dask() -> bool:
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        return False
    return True


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A ``dask.distributed.Client``: connected to ``scheduler`` (an address such as
    ``tcp://10.0.0.5:8786``), or to a new local cluster of ``workers`` processes with one
    thread each, listening on 127.0.0.1 only (its status page on a free port), closed on
    exit."""
    from dask.distributed import Client, LocalCluster
    root = logging.getLogger().getEffectiveLevel()
    # Dask logs every worker start and stop at INFO: shown with -v only
    logging.getLogger("distributed").setLevel(logging.ERROR if root >= logging.WARNING
                                              else root)
    if scheduler:
        client = Client(scheduler, timeout="30s")
        try:
            yield client
        finally:
            client.close()
        return
    cluster = LocalCluster(n_workers=int(workers or 1), threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address="127.0.0.1:0",
                           silence_logs=logging.CRITICAL)
    try:
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def backend_of(workers: int | None, scheduler: str | None) -> str:
    """"dask" or "in-process"; ValueError when ``scheduler`` is given without Dask."""
    if not scheduler and not workers:
        return "in-process"
    if have_dask():
        return "dask"
    if scheduler:
        raise ValueError("--scheduler needs Dask: pip install 'rtseg[scale]' "
                         "(or drop --scheduler to run in this process)")
    warnings.warn("Dask is not installed (pip install 'rtseg[scale]'): --workers ignored, "
                  "running in this process", RuntimeWarning, stacklevel=3)
    return "in-process"


def map_tasks(fn: Callable[..., Any], items: Sequence[Any], kwargs: dict[str, Any] | None = None,
              workers: int | None = None, scheduler: str | None = None, client: Any = None
              ) -> Iterator[tuple[int, Any, BaseException | None]]:
    """Run ``fn(item, **kwargs)`` for every item, one task each, and yield ``(index,
    result, None)`` or ``(index, None, exception)`` as each completes (in-process: in
    order; Dask: in completion order).  ``fn`` must be importable by name (a module-level
    function) and items and results small: they travel through the scheduler.  Stopping
    the iteration cancels the tasks not yet done.  ``client``: a running
    ``dask.distributed.Client`` to use instead of starting one."""
    kwargs = kwargs or {}
    backend = "dask" if client is not None else backend_of(workers, scheduler)
    if backend == "in-process" or not items:
        for i, item in enumerate(items):
            try:
                res = fn(item, **kwargs)
            except Exception as exc:  # noqa: BLE001 - the caller decides, as with Dask
                yield i, None, exc
            else:
                yield i, res, None
        return
    from dask.distributed import as_completed
    with (contextlib.nullcontext(client) if client is not None
          else dask_client(workers, scheduler)) as client:
        futures = client.map(fn, list(items), pure=False, **kwargs)
        pending = {f.key: (i, f) for i, f in enumerate(futures)}
        del futures
        try:
            for fut in as_completed([f for _, f in pending.values()]):
                i, _ = pending.pop(fut.key)
                try:
                    res, exc = fut.result(), None
                except Exception as e:  # noqa: BLE001 - raised by the task or a lost worker
                    res, exc = None, e
                fut.release()
                yield i, res, exc
        finally:
            if pending:
                client.cancel([f for _, f in pending.values()])


def _records_task(item: tuple[str, list[str]], **kwargs: Any) -> list[dict[str, Any]]:
    from rtseg.archive.records import take_records
    return take_records(item[0], item[1], **kwargs)


def run_tasks(todo: Sequence[tuple[str, list[str]]], kwargs: dict[str, Any],
              workers: int | None = None, scheduler: str | None = None,
              stats: Any = None, client: Any = None
              ) -> Iterator[tuple[str, list[dict[str, Any]]]]:
    """Yield ``(path, records)`` for each ``(path, methods)`` of ``todo`` as it completes
    (``map_tasks`` of ``rtseg.archive.records.take_records``).  A task lost on its worker gives
    error records.  ``client``: a running Dask client (benchmarks: start-up timed apart)."""
    from rtseg.archive.records import error_record
    if stats is not None:
        backend = "dask" if client is not None else backend_of(workers, scheduler)
        stats.backend = backend if backend == "in-process" else (
            f"dask scheduler {scheduler}" if scheduler else
            f"dask LocalCluster {workers} workers" if workers else "dask client")
        if backend == "in-process":
            workers = scheduler = None       # warned once already
    tasks = map_tasks(_records_task, todo, kwargs, workers, scheduler, client)
    with contextlib.closing(tasks):
        for i, recs, exc in tasks:
            path, methods = todo[i]
            if exc is not None:
                recs = [error_record(path, m, f"task failed: {type(exc).__name__}: {exc}")
                        for m in methods]
            yield path, recs


class Progress:
    """``segment: 120/200 takes, 2 failed, 35 skipped, 3.1 takes/s, eta 26 s`` on stderr:
    rewritten in place on a terminal, else one line every ``every_s`` seconds and at the
    end."""

    def __init__(self, total: int, skipped: int = 0, stream: TextIO | None = None,
                 enabled: bool = True, every_s: float = 5.0) -> None:
        self.total = total
        self.skipped = skipped
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.every_s = every_s
        self.done = 0
        self.failed = 0
        self.t0 = time.monotonic()
        self.last = -1e9
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def text(self) -> str:
        dt = time.monotonic() - self.t0
        rate = self.done / dt if dt > 0 else 0.0
        left = self.total - self.done
        eta = f", eta {left / rate:.0f} s" if rate > 0 and left else ""
        return (f"segment: {self.done}/{self.total} takes, {self.failed} failed, "
                f"{self.skipped} skipped, {rate:.2f} takes/s, {dt:.1f} s{eta}")

    def update(self, failed: bool = False) -> None:
        self.done += 1
        self.failed += bool(failed)
        if not self.enabled:
            return
        now = time.monotonic()
        if self.tty:
            self.stream.write("\r" + self.text().ljust(90))
            self.stream.flush()
        elif now - self.last >= self.every_s:
            self.last = now
            self.stream.write(self.text() + "\n")
            self.stream.flush()

    def close(self) -> None:
        if not self.enabled:
            return
        self.stream.write(("\r" + self.text().ljust(90) + "\n") if self.tty
                          else self.text() + "\n")
        self.stream.flush()
