"""JSON lines: one object per event, to stdout or a file, flushed after every line.

``JsonlPublisher(path="-")`` - ``"-"`` writes to ``sys.stdout`` (looked up at each write,
so redirections made later are honoured); any other path is opened for appending
(parent folders must exist; an unopenable path raises ValueError naming it).

Each line is ``event.to_dict()`` (see ``rtseg.core.events``): ``{"type": "cut", "event": 3,
"segment": 3, "frame": 412, "time": 3.43, "method": "pca", "label": "pca",
"confidence": 0.8, "latency_ms": 12.5, ...}``, ``{"type": "status", ...}``,
``{"type": "dropout", "name": "LeftHand", "lost": true, ...}``; NaN/inf are written as
null so every line is strict JSON.  A write error (closed pipe, full disk) is counted and
logged, never raised.
"""

from __future__ import annotations

import json
import os
import sys
import threading
from typing import IO, Any

from rtseg.core.events import BehaviourEvent, CutEvent, DropoutEvent, StatusEvent
from rtseg.publishers.base import Publisher


class JsonlPublisher(Publisher):
    def __init__(self, path: str = "-") -> None:
        super().__init__()
        self.path = path
        self.target = "jsonl:" + path
        self._fh: IO[str] | None = None
        if path != "-":
            try:
                # a missing folder is made, as for ``--record`` and ``segment --out``
                os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
                self._fh = open(path, "a", encoding="utf-8")
            except OSError as exc:
                raise ValueError(f"output target {self.target}: cannot open: {exc}") from None
        self._lock = threading.Lock()
        self._closed = False

    def _write(self, obj: dict[str, Any]) -> None:
        line = json.dumps(obj, allow_nan=False, ensure_ascii=False) + "\n"
        with self._lock:
            if self._closed:
                self.count("dropped")
                return
            fh = self._fh if self._fh is not None else sys.stdout
            try:
                fh.write(line)
                fh.flush()
            except (OSError, ValueError) as exc:   # ValueError: write to closed file
                self.count("errors")
                self.count("dropped")
                self.warn("write", f"write failed: {exc}")
                return
        self.count("sent")

    def _publish(self, ev: Any) -> None:
        try:
            obj = ev.to_dict()
        except (ValueError, TypeError, AttributeError) as exc:
            self.count("errors")
            self.warn("encode", f"cannot encode event: {exc}")
            return
        try:
            self._write(obj)
        except (ValueError, TypeError) as exc:        # not JSON-serialisable
            self.count("errors")
            self.warn("encode", f"cannot encode event: {exc}")

    def publish_cut(self, ev: CutEvent) -> None:
        self._publish(ev.stamped())

    def publish_status(self, ev: StatusEvent) -> None:
        self._publish(ev)

    def publish_dropout(self, ev: DropoutEvent) -> None:
        self._publish(ev)

    def publish_behaviour(self, ev: BehaviourEvent) -> None:
        self._publish(ev)

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self._fh is not None:
                try:
                    self._fh.close()
                except OSError:
                    pass
