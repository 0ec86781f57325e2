"""One thread that runs one or more live sessions: the sources are read, their frames
recorded, buffered and processed, and the events published, all on the calling thread.

How a wake-up goes
------------------
:func:`run_sessions` waits in one ``poll(2)`` on every source that can be polled
(``rtseg.drivers.base.Source.take_over``: a serial port's descriptor, a UDP socket) and on
a wake-up pipe, for at most 50 ms or until the earliest due time (a status event, a
session's duration, a source's own ``poll_due``: a quiet-gap flush, a staleness check, a
reconnect attempt).  Then, for each session whose source is readable or due, the source
decodes what is waiting (``Source.poll``) and the session takes the frames
(``Source.take``): each is recorded and appended to the session's ring buffer in arrival
order (``LiveSession._receive``); then every session processes what its ring holds
(``LiveSession._step``, at most ``buffer.max_batch`` frames per wake-up, and with several
sessions for at most ``TURN_S`` before the next one's turn) and sends its status when
due.  No frame changes threads on the way.

While a session works through a batch, the sources are read again whenever
``PUMP_EVERY_S`` (1 ms) has passed since the last read (:meth:`SessionLoop.pump`, a
``poll`` with no wait): frames are stamped when they are read, so a long batch does not
hold frames in the kernel's buffers (a pty holds about 4 KB), and the overload policy of
``rtseg.live.session`` ("Keeping up") sees them waiting and their age.

Sources that keep a thread of their own because they must block (the TCP clients of
Axis and MVN, Axis binary UDP, a pyserial URL) queue their frames and wake the loop
through the pipe (``Source.wake_with``); the loop takes them as it takes a polled
source's.  A source read only through ``read`` (a file or ``sim://`` replay, a source
object without either protocol) gets a reader thread (``LiveSession._reader``) that
appends to the session's ring buffer and wakes the loop.  A session that falls behind
a polled source for good (``HAND_BACK_DROPS`` frames dropped to keep up) hands it back
to its thread and reads it with a reader thread from then on
(``LiveSession._hand_back``): on a machine short of CPU one thread doing both would
read late, and a device with a small buffer (a pty holds 4 KB) would lose frames.
Either way the ring buffer holds every frame received in arrival order; the recording
gets every frame before it is appended, so ``replay_session`` of a recording reproduces
the live cuts.

Quiet frames
------------
Most frames cannot send anything: the contrast detector looks at a new position once per
``step_s`` (every 15th frame at 120 Hz), and a cut goes out only on a frame that runs a
look, sends a queued cut or decides a cut its gate holds; behaviour identity decides only
when a block of its own completes or with a cut.  After each step a polled
session says how many of the next frames are certainly quiet
(``Pipeline.quiet_frames``, at most what the source's buffer holds:
``Source.hold_frames``) and until when its source may be left unread
(``rtseg.live.quiet``: half a frame period before the last quiet frame is due,
at most ``MAX_DEFER_S``); the loop then watches its descriptors for errors and hang-ups
only (:meth:`SessionLoop.quiet`) and reads the frames that arrived, in one batch, when
that time comes.  The frames that may send are read as they arrive, so no cut, no OSC
message waits; what is saved is the wake-ups in between (each costs reloading the
interpreter's working set into a cold cache, several times a frame's arithmetic).
Batched frames are stamped when read (``recv_time``), up to ``MAX_DEFER_S`` after they
arrived, which the session's clock does not see when frames carry a source time (it
places frames by the source clock); so only frames with a source clock are batched, and
only from sources whose frames do not depend on arrival times (the serial driver, a VMC
source once its frames close by their content).
Off with ``buffer.batch_quiet = false``.  The live monitor then moves in steps of a batch
(about 0.1 s at 120 Hz).

Work ahead
----------
After a wake-up's frames, while no session has a frame waiting and every session's next
frame is promised quiet or not due for a while (``LiveSession._may_work_ahead``), the
loop lets the detectors do, for at most ``AHEAD_S``, work the frame that sends the waiting
cut would otherwise do (``Pipeline.ahead``: the contrast detector's placement of its
waiting maximum and its gate's distance): that frame then sends its cut sooner, with the
same cut (``LiveStats.ahead_pieces`` counts the pieces).

Several sessions in one loop each keep their own source, pipeline (features, detectors,
identity), ring buffer, publishers, recording and counters; they share the thread, the
process's signal handling (SIGINT/SIGTERM stop every session), the BLAS thread limit and
the frozen heap (``_freeze_heap``).  What is logged while the loop works for one session,
and in the threads that session starts (its reader thread, its driver's and publishers'),
carries that session's name (``rtseg.core.session_log``).
"""

from __future__ import annotations

import gc
import logging
import os
import select
import signal
import threading
import time
from typing import Any, Sequence

from rtseg.core.session_log import in_session
from rtseg.live.detector_setup import _blas_limit

log = logging.getLogger("rtseg.live.session")

#: longest wait between two wake-ups, s (stop flags and silence are checked this often)
MAX_WAIT_S = 0.05
#: during a batch, the sources are read again after this long, s (a pty holds 4 KB:
#: 6 ms of a 17-sensor suit sent at 30 times its 120 Hz)
PUMP_EVERY_S = 0.001

#: with several sessions, the longest one processes before the next one's turn, s
TURN_S = 0.002

#: longest the detectors' work ahead takes per wake-up, s (``LiveSession._work_ahead``: done
#: only while no session's frame that may send is due, so it delays none)
AHEAD_S = 0.001

#: longest a source is left unread while its frames cannot send anything, s
#: (``rtseg.live.quiet``; well under ``gaps.max_seconds`` and the staleness times)
MAX_DEFER_S = 0.1

_READ = select.POLLIN | select.POLLPRI | select.POLLERR | select.POLLHUP


def _as(session: Any) -> in_session:
    """``with _as(session):`` - what is logged inside is ``session``'s
    (``rtseg.core.session_log``: its name, "" for an unnamed one)."""
    return in_session(getattr(session, "name", ""))


class Waker:
    """A non-blocking pipe that interrupts the loop's ``poll`` from another thread (a
    reader thread that appended frames, ``LiveSession.stop``).  At most one byte waits
    unread: ``wake`` writes only when none is pending."""

    def __init__(self) -> None:
        self.rfd, self.wfd = os.pipe()
        os.set_blocking(self.rfd, False)
        os.set_blocking(self.wfd, False)
        self._pending = False
        self._closed = False
        self._lock = threading.Lock()     # close() never runs during a write

    def wake(self) -> None:
        if self._pending or self._closed:
            return
        with self._lock:
            if self._closed:
                return
            self._pending = True
            try:
                os.write(self.wfd, b"\0")
            except OSError:      # full: a wake-up is pending anyway
                pass

    def clear(self) -> None:
        """Forget the pending wake-up (before the loop looks at what woke it): the pipe
        is emptied first, then the flag cleared, so a ``wake`` between the two finds the
        flag set and its frames are seen by the look that follows; a ``wake`` after it
        writes again (clearing the flag first would let a byte written meanwhile be read
        with the flag left set, and every later wake-up be skipped)."""
        try:
            while os.read(self.rfd, 512):
                pass
        except OSError:          # BlockingIOError: nothing more to read
            pass
        self._pending = False

    def close(self) -> None:
        with self._lock:
            if not self._closed:
                self._closed = True
                os.close(self.rfd)
                os.close(self.wfd)


class SessionLoop:
    """The poller of :func:`run_sessions`: which descriptors belong to which polled
    session, and the pump that reads them between frames."""

    def __init__(self, sessions: Sequence[Any]) -> None:
        self.sessions = list(sessions)
        self.waker = Waker()
        self._poller = select.poll()
        self._poller.register(self.waker.rfd, select.POLLIN)
        self._fds: dict[int, Any] = {}          # descriptor -> session
        self._watched: dict[int, tuple[int, ...]] = {}   # id(session) -> its descriptors
        self._polled: list[Any] = []            # sessions whose source this loop reads
        self._woken: list[Any] = []             # sessions whose source's thread wakes it
        self._last_pump = 0.0
        #: id(session) -> monotonic time until which its source is left unread (quiet
        #: frames); its descriptors are watched for errors and hang-ups only meanwhile
        self._quiet: dict[int, float] = {}
        #: longest a session processes in one turn when there are several (s; None for
        #: one): the others' frames wait at most about that long per session
        self.turn_s: float | None = TURN_S if len(self.sessions) > 1 else None

    # ------------------------------------------------------------------ descriptors
    def add_polled(self, session: Any) -> None:
        self._polled.append(session)
        self.sync(session)

    def add_woken(self, session: Any) -> None:
        self._woken.append(session)

    def drop(self, session: Any) -> None:
        """Stop watching ``session``'s source (it has stopped)."""
        self._quiet.pop(id(session), None)
        if session in self._polled:
            self._polled.remove(session)
        if session in self._woken:
            self._woken.remove(session)
        for fd in [fd for fd, s in self._fds.items() if s is session]:
            self._unregister(fd)
        self._watched.pop(id(session), None)

    def _unregister(self, fd: int) -> None:
        del self._fds[fd]
        try:
            self._poller.unregister(fd)
        except (KeyError, ValueError, OSError):
            pass

    def sync(self, session: Any) -> None:
        """Watch the descriptors ``session``'s source names now (they change when a
        device is lost and reopened).  ``poll(2)`` keeps no state between calls, so a
        descriptor number reused by a reopened device needs nothing more."""
        try:
            fds = tuple(session.source.poll_fds())
        except Exception:                      # pragma: no cover - a driver bug
            fds = ()
        if self._watched.get(id(session)) == fds:
            return                             # the usual case: nothing changed
        self.resume(session)                   # a reopened device is read at once
        self._watched[id(session)] = fds
        want = set(fds)
        have = {fd for fd, s in self._fds.items() if s is session}
        for fd in have - want:
            self._unregister(fd)
        for fd in want - have:
            if fd in self._fds:                # pragma: no cover - two sources, one fd
                continue
            self._fds[fd] = session
            self._poller.register(fd, _READ)

    # ------------------------------------------------------------------ quiet frames
    def quiet(self, session: Any, until: float) -> None:
        """Leave the polled ``session``'s source unread until ``until`` (monotonic s): its
        next frames cannot send anything (module docstring, "Quiet frames")."""
        if session not in self._polled or id(session) in self._quiet:
            return
        fds = self._watched.get(id(session), ())
        if not fds:
            return
        self._quiet[id(session)] = until
        for fd in fds:
            self._poller.modify(fd, 0)         # errors and hang-ups still wake the loop

    def is_quiet(self, session: Any) -> bool:
        """Whether ``session``'s source is being left unread (``quiet``)."""
        return id(session) in self._quiet

    def resume(self, session: Any) -> None:
        """Read ``session``'s source as frames arrive again."""
        if self._quiet.pop(id(session), None) is None:
            return
        for fd in self._watched.get(id(session), ()):
            if self._fds.get(fd) is session:
                self._poller.modify(fd, _READ)

    def _quiet_now(self, session: Any, now: float) -> bool:
        """Whether ``session``'s source is still left unread at ``now`` (resumed once its
        time has come)."""
        until = self._quiet.get(id(session))
        if until is None:
            return False
        if now < until:
            return True
        self.resume(session)
        return False

    # ------------------------------------------------------------------ reading
    def wait(self, timeout: float) -> set[Any]:
        """Sleep until a descriptor is readable, a wake-up or ``timeout`` s; the polled
        sessions whose source is readable or due."""
        try:
            events = self._poller.poll(max(0.0, timeout) * 1000.0)
        except InterruptedError:               # pragma: no cover - PEP 475 retries
            events = []
        return self._ready(events)

    def _ready(self, events: list[tuple[int, int]]) -> set[Any]:
        ready: set[Any] = set()
        for fd, ev in events:
            if fd == self.waker.rfd:
                self.waker.clear()
                continue
            s = self._fds.get(fd)
            if s is None:
                continue
            if ev & select.POLLNVAL:           # closed under us: forget it
                self._unregister(fd)
                self._watched.pop(id(s), None)     # looked at again after the next poll
            self.resume(s)                     # an error or hang-up is read at once
            ready.add(s)
        return ready

    def read_sources(self, ready: set[Any], now: float) -> None:
        """Take the frames the woken sources' threads queued; poll the sources of
        ``ready`` and those whose ``poll_due`` has come."""
        for s in self._woken:
            with _as(s):
                s._take_frames()
        for s in self._polled:
            with _as(s):
                if s in ready:
                    s._poll_source(now)
                    self.sync(s)
                    continue
                if self._quiet and id(s) in self._quiet:
                    if self._quiet_now(s, now):
                        continue
                    s._read_quiet(now)             # the quiet frames, in one batch
                    self.sync(s)
                    continue
                try:
                    due = s.source.poll_due()
                except Exception:                  # pragma: no cover - a driver bug
                    due = None
                if due is not None and due <= now:
                    s._poll_source(now)
                    self.sync(s)
        self._last_pump = now

    def pump(self, now: float) -> None:
        """Between two frames of a batch: read whatever the polled sources hold (no
        wait), when ``PUMP_EVERY_S`` has passed since the last read."""
        if now - self._last_pump < PUMP_EVERY_S:
            return
        if self._polled:
            self.read_sources(self._ready(self._poller.poll(0)), now)
        else:
            for s in self._woken:
                with _as(s):
                    s._take_frames()
            self._last_pump = now

    def next_due(self, now: float) -> float:
        """Seconds until the earliest due time of the polled sources (``MAX_WAIT_S`` at
        most)."""
        wait = MAX_WAIT_S
        for s in self._polled:
            until = self._quiet.get(id(s)) if self._quiet else None
            if until is not None:
                wait = min(wait, until - now)
                continue
            try:
                due = s.source.poll_due()
            except Exception:                  # pragma: no cover - a driver bug
                continue
            if due is not None:
                wait = min(wait, due - now)
        return wait

    def close(self) -> None:
        self.waker.close()


def _freeze_heap(collect: bool) -> None:
    """Move every object alive now (modules, configuration, the pipeline's arrays) out of
    the garbage collector's reach (``gc.freeze``), after one full collection when
    ``collect``.  A full collection holds the GIL while it walks every tracked object: with
    numpy and scipy loaded that is about 30 ms, during which the reader thread cannot drain
    the serial port or socket (a pty holds ~4 KB: 10 ms of a 17-sensor suit at 20x its
    120 Hz).  Frozen, later collections walk only what the session itself allocates.
    ``LiveSession.run`` undoes it when the session ends (:func:`_thaw_heap`)."""
    if collect:
        gc.collect()
    gc.freeze()


def _thaw_heap(frozen_before: int) -> None:
    """Return what :func:`_freeze_heap` froze to the collector (``gc.unfreeze``) when
    nothing was frozen before the session (``frozen_before``, ``gc.get_freeze_count()``
    then), so a host that runs many sessions in one process still collects the cycles that
    were alive when each started.  A host that froze objects itself keeps them frozen
    (``gc.unfreeze`` cannot release only the session's)."""
    if frozen_before == 0:
        gc.unfreeze()


def run_sessions(sessions: Sequence[Any], handle_signals: bool = True) -> list[Any]:
    """Run ``sessions`` (``rtseg.live.session.LiveSession``) on the calling thread until
    every one has stopped (its duration, the end of its source, ``stop()``, or
    SIGINT/SIGTERM for all when ``handle_signals`` and called from the main thread); their
    ``SessionSummary``s in order.  A session that cannot start (a source that cannot be
    opened) stops every session already started, and its error is raised."""
    sessions = list(sessions)
    if len({id(s) for s in sessions}) != len(sessions):
        raise ValueError("a session appears twice")
    loop = SessionLoop(sessions)
    old_handlers: dict[int, Any] = {}
    if handle_signals and threading.current_thread() is threading.main_thread():
        def on_signal(signum: int, frame: Any) -> None:
            for s in sessions:
                s._on_signal(signum, frame)
        for sig in (signal.SIGINT, signal.SIGTERM):
            old_handlers[sig] = signal.signal(sig, on_signal)
    blas = _blas_limit(int(sessions[0].config["buffer.blas_threads"])) if sessions else None
    frozen_before = gc.get_freeze_count()
    summaries: dict[int, Any] = {}
    started: list[Any] = []
    try:
        _freeze_heap(collect=True)
        for s in sessions:
            started.append(s)
            with _as(s):
                s._begin(loop)
        _freeze_heap(collect=False)
        for s in sessions:
            with _as(s):
                s._start_input(loop)
        running = list(sessions)
        while running:
            now = time.monotonic()
            wait = loop.next_due(now)
            for s in running:
                wait = min(wait, s._wait_s(now))
            ready = loop.wait(wait)
            now = time.monotonic()
            loop.read_sources(ready, now)
            for s in list(running):
                now = time.monotonic()
                if not s._due(now):
                    continue                   # another session's wake-up
                with _as(s):
                    s._step(now)
                    if s._stop.is_set():
                        if loop.is_quiet(s):   # what arrived while it was left unread
                            loop.resume(s)
                            s._read_quiet(time.monotonic())
                            s._step(time.monotonic())
                        running.remove(s)
                        loop.drop(s)
                        summaries[id(s)] = s._finish()
                    elif s._polled and not loop.is_quiet(s):
                        until = s._quiet_until(time.monotonic())
                        if until is not None:
                            loop.quiet(s, until)
            now = time.monotonic()
            if running and all(s._may_work_ahead(now) for s in running):
                end = now + AHEAD_S            # work ahead: no frame that may send is due
                for s in running:
                    with _as(s):
                        s._work_ahead(end)
                    if time.monotonic() >= end:
                        break
    finally:
        for s in started:
            if id(s) not in summaries:
                s._stop.set()
                with _as(s):
                    summaries[id(s)] = s._finish()
        loop.close()
        for sig, h in old_handlers.items():
            signal.signal(sig, h)
        if blas is not None:
            blas.restore_original_limits()
        _thaw_heap(frozen_before)
    return [summaries[id(s)] for s in sessions]


__all__ = ["AHEAD_S", "MAX_DEFER_S", "MAX_WAIT_S", "PUMP_EVERY_S", "TURN_S", "SessionLoop", "Waker", "run_sessions"]
