"""The live session's end (``rtseg.live.session``, "Shutdown"): the reader joined, the
frames already received processed, the source closed before the counters are written, the
final status, publishers and recorder closed, the ``SessionSummary``.

:class:`SessionShutdown` is a part of :class:`rtseg.live.session.LiveSession` (a base class;
it uses the session's ``source``, ``pipeline``, ``publishers``, ``recorder``, ``_cursor``,
``_stop``, ``_reader_thread`` and its processing, status and loss counters).  Times are
monotonic seconds.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from rtseg.live.stats import SessionSummary
from rtseg.live.summary import session_summary

log = logging.getLogger("rtseg.live.session")

#: at the end, rounds of processing what was received (a reader thread that outlived its
#: join could go on adding frames)
DRAIN_ROUNDS = 4


class SessionShutdown:
    """The end of a :class:`~rtseg.live.session.LiveSession`."""

    def _finish(self) -> SessionSummary:
        """Stop reading (the reader thread joined), shut everything down; the summary."""
        self._stop.set()
        if self._reader_thread is not None:
            self._reader_thread.join(timeout=5.0)
        self._drain()
        return self._shutdown()

    def _drain(self) -> None:
        """At the end: the frames received but not yet processed are processed (a reader
        thread's last frames, or those the loop read between two frames of its last
        batch), so every frame received is recorded and processed."""
        if self.pipeline is None or not hasattr(self, "_cursor"):
            return                                 # setup failed before the loop state
        try:
            for _ in range(DRAIN_ROUNDS):
                backlog = self._cursor.backlog
                if backlog <= 0:
                    break
                self._process_window(self._cursor.read(backlog), time.monotonic())
        except Exception as exc:  # pragma: no cover - defensive: the shutdown must go on
            log.warning("processing the last frames failed: %s", exc)

    def _shutdown(self) -> SessionSummary:
        """Close the source first (its threads stop counting drops), then the final
        status, the recording's session counters, publishers and recorder: the counts
        written, sent and returned are the same."""
        now = time.monotonic()
        self._close("source", self.source)
        # no final status when setup failed before the loop state existed (e.g. the
        # recording folder could not be created after the publishers were built)
        if (self.pipeline is not None and self.publishers is not None
                and hasattr(self, "_status_t")):
            try:
                self._emit(self._status(now, alive=0))
            except Exception as exc:  # pragma: no cover - defensive
                log.warning("final status failed: %s", exc)
        if self.recorder is not None and hasattr(self.recorder, "note_session"):
            try:
                self.recorder.note_session(self.loss_counts())
                rest = getattr(self.source, "rest_pose", None)
                if rest is None and self.pipeline is not None:
                    rest = self.pipeline.posture.geometry     # the standard T-pose's
                if rest is not None:
                    self.recorder.note_rest(rest.positions)
            except Exception as exc:  # pragma: no cover - defensive
                log.warning("session counters or rest geometry not recorded: %s", exc)
        self._close("publishers", self.publishers)
        self._close("recorder", self.recorder)
        summary = session_summary(self, now)
        log.info("%s", summary.text())
        return summary

    @staticmethod
    def _close(name: str, obj: Any) -> None:
        """``obj.close()``; a failure logged, never raised (the shutdown goes on)."""
        if obj is None:
            return
        try:
            obj.close()
        except Exception as exc:
            log.warning("closing %s failed: %s", name, exc)


__all__ = ["DRAIN_ROUNDS", "SessionShutdown"]
