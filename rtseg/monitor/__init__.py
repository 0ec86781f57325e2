"""The live monitor: a page in the browser that shows what a live session's detector sees.

``rtseg live ... --monitor [HOST:]PORT`` (``pip install 'rtseg[monitor]'``, which brings
aiohttp).  :class:`~rtseg.monitor.feed.MonitorFeed` is the processing side (no dependency
beyond numpy): the session feeds it, it queues bounded batches.
:class:`~rtseg.monitor.server.MonitorServer` (aiohttp, its own thread) serves the page, the
uPlot charting library shipped in ``static/`` (MIT, ``static/uPlot.LICENSE``) and a
WebSocket of those batches.  :func:`start_monitor` makes both.

May import ``rtseg.core``."""

from __future__ import annotations

from typing import Any

from rtseg.monitor.feed import MonitorFeed

__all__ = ["MonitorFeed", "MonitorUnavailable", "start_monitor"]


class MonitorUnavailable(RuntimeError):
    """The monitor's server library (aiohttp) is not installed."""


def start_monitor(address: str | None) -> tuple[MonitorFeed, Any]:
    """A feed and its started server for ``[HOST:]PORT`` (None: 127.0.0.1:8765).
    Raises MonitorUnavailable without aiohttp, ValueError for a bad address, OSError when
    the address cannot be bound."""
    try:
        from rtseg.monitor.server import MonitorServer, parse_address
    except ImportError as exc:
        raise MonitorUnavailable(
            f"the live monitor needs aiohttp ({exc.name or exc} is not installed): "
            "pip install 'rtseg[monitor]'") from None
    host, port = parse_address(address)
    feed = MonitorFeed()
    server = MonitorServer(feed, host, port)
    server.start()
    return feed, server
