"""Logging of recurring problems at a bounded rate: a driver that meets a corrupt message a
thousand times a second, or a publisher whose target is down, logs it at most once per
``interval`` seconds per kind, with the number of repeats left out in between.

Shared by the drivers (``rtseg.drivers.serial``) and the publishers (``rtseg.publishers``);
safe to call from several threads (a reader thread and the live loop).
"""

from __future__ import annotations

import logging
import threading
import time

#: a recurring problem of one kind is logged at most this often, s
LOG_INTERVAL_S = 5.0


class RateLimitedLog:
    """``log(key, msg, *args, level=WARNING)``: ``logger.log(level, msg, *args)`` at most once
    per ``interval`` seconds (``time.monotonic``) per ``key``; the next message logged for
    that key says how many were suppressed since the last.  ``msg`` and ``args`` are
    formatted by ``logging`` only when the message is logged."""

    def __init__(self, logger: logging.Logger, interval: float = LOG_INTERVAL_S) -> None:
        self.logger = logger
        self.interval = float(interval)
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._lock = threading.Lock()

    def __call__(self, key: str, msg: str, *args: object, level: int = logging.WARNING) -> None:
        now = time.monotonic()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self.interval:
                self._suppressed[key] = self._suppressed.get(key, 0) + 1
                return
            n = self._suppressed.pop(key, 0)
            self._last[key] = now
        if n:
            if args:
                msg += " (%d similar suppressed in the last %.0f s)"
                args = args + (n, self.interval)
            else:       # msg is already formatted: a '%' in it is text, not a placeholder
                msg = f"{msg} ({n} similar suppressed in the last {self.interval:.0f} s)"
        self.logger.log(level, msg, *args)


__all__ = ["LOG_INTERVAL_S", "RateLimitedLog"]
