"""Which live session a log record concerns, when one process runs several.

The name of the session at work is a context variable: ``rtseg.live.loop`` sets it
(:class:`in_session`) around everything it does for one session on its thread, and the
threads a session starts - its reader thread, a driver's reader or connection thread, a
TCP publisher's - are started with :func:`start_thread`, which runs them in a copy of the
starting thread's context, so they keep the name of the session that opened them.  The
drivers and publishers never learn the name.  (A source a Python host opened itself before
handing it to a session started its thread outside the session: what that thread logs
carries no name, what the loop logs while reading it does.)

:class:`SessionNames` is a ``logging.Filter`` for a handler: it sets ``record.session`` to
the name ("" outside a named session) and starts the message with ``NAME: `` unless it
starts so already.  ``rtseg live`` with several sources adds it to its stderr handler for
the run (:func:`session_names_shown`), so every warning says whose suit it concerns; a
single source prints its lines unchanged, as its status lines and summary are.
"""

from __future__ import annotations

import contextvars
import logging
import threading
from contextlib import contextmanager
from typing import Any, Callable, Iterator

#: the name of the session whose work is running now ("" for none or an unnamed one)
_SESSION: contextvars.ContextVar[str] = contextvars.ContextVar("rtseg_session", default="")


def current_session() -> str:
    """The name of the session whose work runs now on this thread ("" for none)."""
    return _SESSION.get()


class in_session:
    """``with in_session(name):`` - the records logged inside are ``name``'s.  Nests (the
    loop reads another session's source in the middle of one session's step); a new
    object for each use."""

    __slots__ = ("name", "_token")

    def __init__(self, name: str) -> None:
        self.name = name
        self._token: contextvars.Token[str] | None = None

    def __enter__(self) -> None:
        self._token = _SESSION.set(self.name)

    def __exit__(self, *exc: Any) -> None:
        if self._token is not None:
            _SESSION.reset(self._token)
            self._token = None


def start_thread(target: Callable[[], Any], name: str, daemon: bool = True) -> threading.Thread:
    """A started thread running ``target`` in a copy of the caller's context: what it
    logs belongs to the session that started it (a thread started with ``threading``
    alone begins with an empty context)."""
    ctx = contextvars.copy_context()
    thread = threading.Thread(target=ctx.run, args=(target,), name=name, daemon=daemon)
    thread.start()
    return thread


class SessionNames(logging.Filter):
    """A handler's filter: ``record.session`` is the session the record was logged in
    ("" for none), and a named session's message starts with ``NAME: `` (not twice).
    Runs in the logging thread, as handlers do unless they queue records."""

    def filter(self, record: logging.LogRecord) -> bool:
        name = _SESSION.get()
        record.session = name
        if not name:
            return True
        try:
            message = record.getMessage()
        except Exception:        # a bad format: the handler reports it as it would have
            return True
        if not message.startswith(name + ": "):
            record.msg, record.args = f"{name}: {message}", ()
        return True


@contextmanager
def session_names_shown(logger: logging.Logger | None = None) -> Iterator[None]:
    """Add :class:`SessionNames` to the handlers of ``logger`` (default the root logger,
    where ``logging.basicConfig`` puts the command's stderr handler) for the ``with``
    block, then take it away again."""
    handlers = list((logger or logging.getLogger()).handlers)
    names = SessionNames()
    for h in handlers:
        h.addFilter(names)
    try:
        yield
    finally:
        for h in handlers:
            h.removeFilter(names)


__all__ = ["SessionNames", "current_session", "in_session", "session_names_shown",
           "start_thread"]
