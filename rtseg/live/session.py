"""The live session: source -> ring buffer -> pose features -> online detectors -> cut events.

The per-frame work (gaps, calibration, features, detectors) is ``rtseg.live.pipeline.Pipeline``;
this module runs it in a session and publishes what it finds.  Where events go
(publishers, which detectors' cuts go on the wire) is ``rtseg.live.outputs``; the counters and
the summary are ``rtseg.live.stats``.  Their public names (``Pipeline``,
``PipelineCut``, ``make_detectors``, ``replay_frames``, ``replay_session``,
``build_publishers``, ``wire_methods``, ``LiveStats``, ``SessionSummary``) are re-exported
here.  Four parts of ``LiveSession`` live in their own modules: ``rtseg.live.intake``
(frames from the source, recorded and appended to the ring: polled, woken or by a reader
thread), ``rtseg.live.process`` (frames from the ring through the pipeline, overload
drops), ``rtseg.live.emitter`` (cut and behaviour events built, published, recorded) and
``rtseg.live.health`` (dropouts, status events, counters); ``rtseg.live.loop`` runs
sessions.

Threads and data flow
---------------------
``LiveSession.run()`` runs the session on the calling thread (``rtseg.live.loop``, which
also runs several sessions in one thread).  A source that can be polled (serial port, UDP
socket: ``Source.take_over``) is read by that thread when its descriptor is readable:
decoded -> sanity check -> ``recorder`` (every frame received is recorded) ->
``RingBuffer.append`` (raw quaternions, valid flags, receive time, source time/seq).  A
source that must block (a file replay, a TCP client) keeps one **reader thread** that does
the same and wakes the loop.  The loop then takes the frames from the ring in order
through a ``Cursor`` (at most ``buffer.max_batch`` per wake-up) and hands each to the
``Pipeline`` (calibration, gap handling, ``PoseFeatures.step``, every online detector's
``update``).  Cuts become ``CutEvent``s that are published at once (OSC/JSON lines) and
recorded.  Once per ``status.interval`` a ``StatusEvent`` goes out; sensor dropouts produce
``DropoutEvent``s.
With a live monitor (``monitor=``, ``rtseg.monitor.MonitorFeed``) the processing loop
also hands it every event and, after each step, a chance to queue a batch (bounded, at most
25 a second); the monitor's web server runs on its own thread and only reads that queue.

Keeping up
----------
Reading never waits for processing: a reader thread runs beside it, and a polled source is
read again between the frames of a batch (every millisecond at most).  Under overload (frames arrive faster than the
loop processes them) the loop drops the **oldest** waiting frames so that no frame is
processed more than ``buffer.max_lag_seconds`` (L, default 0.1 s; ``--max-lag``) after it
arrived, and cues stay timely: while working off what is waiting (at the measured cost
per frame) would take the oldest past L, waiting frames older than L/2 are dropped at most
``gaps.max_frames`` before each frame processed (a short gap: the detectors go on,
thinned); frames older than L are all dropped (a longer gap: the detectors restart).  A
short stall at a normal rate, soon worked off, drops nothing.  Dropped
frames are counted in ``LiveStats.overload_drops`` (and in ``dropped``), shown in the
summary, every status event (JSON lines, recording) and the recording's ``session.json``
(``"session"``); the recording still holds every frame received, dropped or not, so a
replay of it (``replay_session``) shows what an unloaded machine would have found.
Measured with ``python3 benchmarks/live.py --overload 30`` (the suit at 30 x 120 Hz over a
pty): cue latency p99 60 ms, ~23 % of the frames dropped, no detector restart; with
``--max-lag 0`` (never drop) p99 1.28 s.
A source that hands over frames as fast as they are read (``Source.as_fast_as_read``: a
replay at ``speed=0``) is read only as fast as it is processed (``rtseg.live.intake``,
backpressure): every frame is processed, in order, as offline.  With L = 0 nothing is
dropped: the loop falls behind until the ring overwrites its oldest frames (see
``rtseg.core.ringbuffer``); it notices by absolute index, counts the lost frames as dropped
(``LiveStats.overruns``) and treats them as a gap (detectors restart).
``LiveStats.lag_s`` (age of the frame being processed) and ``backlog`` (frames waiting)
measure how far behind the loop is; a lag above ``buffer.lag_warn_seconds`` is logged
(rate-limited) and reported in the summary.  Cut times stay on the source clock under
overload too: a boundary frame the ring no longer holds is placed from the revealing
frame's session time (``SessionClock.time_of``).

Gaps
----
No cut is placed across a gap the detectors did not see: see ``rtseg.live.pipeline``.

Frame indices
-------------
``CutEvent.frame`` is the 0-based index of the boundary frame among all frames received
this session (= the row of the recorded session).  ``CutEvent.time`` is that frame's
time in session seconds (``rtseg.live.clock``: the source's own clock where frames carry
one, else the receive clock, counted from the session start), the clock of every time the
session reports (behaviour decisions, dropouts, status, the recording's log lines).
Processing latency (frame arrival -> datagram sent) is measured for every frame that
revealed a cut (``LiveStats.cut_latency_ms``) and, for benchmarking, the arrival ->
end-of-processing time of every frame (``LiveStats.frame_latency_ms``).

One cut per change on the wire
------------------------------
Every detector in ``detectors.methods`` runs on every frame, but by default only the
*primary* one's cuts (``detectors.primary``, default the first of ``methods``) are sent to
the OSC targets (``/rtseg/cut`` and templates), so one behaviour change fires one cue.
``output.cut_methods = "all"`` (or a list of methods) sends other streams too.  Every cut of
every detector still goes to the JSON-lines targets and the session recording, with
``CutEvent.wire`` saying whether it was sent (``wire_methods``).

Input counters
--------------
Input the source had to refuse (corrupt messages, CRC failures, bad messages, bad values,
unknown names: ``rtseg.core.events.INPUT_COUNTERS``) is read from ``source.stats`` (plus the
pipeline's own ``bad_values``) into every ``StatusEvent`` (``/rtseg/input`` over OSC, the
JSON-lines log, the recording) and the ``SessionSummary``.  These are counts of refused
input, not of lost frames (``dropped``).

Shutdown
--------
SIGINT / SIGTERM (when ``run()`` is called from the main thread) only set a stop flag; the
loop then reads nothing further, processes the frames already received (``_drain``), closes
the source, publishers and recorder, sends a final status with alive=0 and returns a
``SessionSummary``.  Nothing the source delivers can crash
the loop: malformed frames are counted (``LiveStats.bad_frames``) and logged.
"""

from __future__ import annotations

import logging
import re
import signal
import threading
import time
from typing import Any, Callable, Iterable

import numpy as np

from rtseg.live.clock import SessionClock
from rtseg.live.emitter import Event, SessionEvents
from rtseg.live.loop import run_sessions
from rtseg.live.health import SessionHealth
from rtseg.live.intake import HAND_BACK_DROPS, SessionInput
from rtseg.live.process import SessionProcessing
from rtseg.live.quiet import SessionQuiet
from rtseg.live.outputs import build_publishers, log_publishers, wire_methods
from rtseg.live.pipeline import (DEFAULT_FRAME_RATE, Pipeline, PipelineCut, PipelineStats,
                                 detector_params, make_detectors)
from rtseg.live.replay import replay_frames, replay_session
from rtseg.live.rate_check import DeclaredRateCheck, switch_rate
from rtseg.core.ringbuffer import RingBuffer
from rtseg.live.config import SessionConfig, load_session_config
from rtseg.live.stats import FloatRing, LiveStats, SessionSummary
from rtseg.live.shutdown import SessionShutdown

log = logging.getLogger("rtseg.live.session")

#: longest a session goes without a step while other sessions wake the loop, s
STEP_EVERY_S = 0.05


__all__ = ["DEFAULT_FRAME_RATE", "FloatRing", "LiveSession", "LiveStats", "Pipeline",
           "PipelineCut", "PipelineStats", "SessionSummary", "build_publishers",
           "detector_params", "make_detectors", "replay_frames", "replay_session",
           "wire_methods", "with_suit"]


def check_name(name: str) -> str:
    """``name`` if it can name a source (1 to 64 of ``[A-Za-z0-9_-]``), else ValueError."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", name):
        raise ValueError(f"source name {name!r}: use 1 to 64 letters, digits, '_' or '-'")
    return name


def with_suit(url: str, suit: str) -> str:
    """``url`` with ``suit=<suit>`` added for the sources that take a suit profile
    (serial://, osc://) when the URL does not name one itself."""
    from urllib.parse import parse_qs, urlsplit
    parts = urlsplit(url)
    if parts.scheme.lower() not in ("serial", "osc") or not suit:
        return url
    query = parse_qs(parts.query, keep_blank_values=True)
    if "suit" in query or (parts.scheme.lower() == "osc"
                           and query.get("format", ["vmc"])[-1].lower() not in ("vmc", "")):
        return url      # a suit is named, or an OSC format without suits (vrchat)
    return url + ("&" if parts.query else "?") + f"suit={suit}"


class LiveSession(SessionInput, SessionProcessing, SessionQuiet, SessionEvents, SessionHealth,
                  SessionShutdown):
    """One live segmentation session.

    source: a URL for ``rtseg.drivers.open_source`` or an opened ``Source``.
    config: a ``SessionConfig`` (default: ``config/live.toml``).
    publishers: object with ``publish_cut(ev) -> ev``, ``publish_status(ev)``,
        ``publish_dropout(ev)`` and ``close()`` (default: ``build_publishers(config)``, a
        ``rtseg.publishers.PublisherSet``).  ``publish_cut`` gets the cuts that go on the
        wire (``wire_methods``); the others go to a ``PublisherSet``'s JSON-lines targets,
        or to a custom object's ``publish_log_cut(ev)`` if it has one, and always to the
        recorder and the listeners.  recorder: object with ``record_frame(frame)``,
        ``record_cut(ev)``, ``record_event(ev)``, ``close()`` (default: a
        ``rtseg.recording.SessionRecorder`` when ``recording.dir`` is set).
    listeners: callables given every event after it is published (the CLI prints them).
    duration: stop after this many seconds (None: until the source ends or a signal).
    name: the source's name when one process runs several sessions
        (``rtseg.live.loop.run_sessions``): every event carries it (``source``) and the
        standard OSC addresses get it (``/rtseg/<name>/cut``); letters, digits, ``_``, ``-``.
    monitor: object with ``attach(session)`` (once the pipeline exists), ``tick(session)``
        (after each processing step, on the processing thread; must not block) and
        ``__call__(event)`` (a listener), e.g. ``rtseg.monitor.MonitorFeed``; its failures
        are counted (``LiveStats.monitor_errors``) and logged, never raised.
    """

    def __init__(self, source: Any, config: SessionConfig | None = None, *,
                 publishers: Any = None, recorder: Any = None,
                 listeners: Iterable[Callable[[Event], None]] = (),
                 duration: float | None = None, handle_signals: bool = True,
                 monitor: Any = None,
                 on_start: Callable[[str], None] | None = None, name: str = "") -> None:
        self.config = config if config is not None else load_session_config()
        #: the source's name, carried by every event (``source``) when one process runs
        #: several sessions; "" for a session on its own
        self.name = check_name(name) if name else ""
        #: called once the source is open, with the line naming the joints the features use
        self.on_start = on_start
        #: every parameter of each configured detector (refused here, before the source
        #: opens, when bad); the recording keeps them
        self.detector_params = detector_params(self.config)
        wire_methods(self.config)
        self._source_arg = source
        self.source: Any = None
        self.publishers = publishers
        self.recorder = recorder
        self.listeners = list(listeners)
        self.monitor = monitor
        if monitor is not None:
            self.listeners.append(monitor)
        self.duration = duration
        self.handle_signals = handle_signals
        self.stats = LiveStats()
        self.pipeline: Pipeline | None = None
        self.ring: RingBuffer | None = None
        self.session_start = 0.0
        self._stop = threading.Event()
        self._eof = threading.Event()
        self._reader_error: BaseException | None = None
        self._first_recv: float | None = None
        #: session seconds of every reported time (set up by ``run``)
        self.clock = SessionClock(time.monotonic(), DEFAULT_FRAME_RATE)
        self._rec_lock = threading.Lock()
        self._event_no = 0
        self._segment: dict[str, int] = {}
        self.primary = ""
        self.wire: frozenset[str] = frozenset()
        self._log_pubs: Any = None
        self.stop_reason = "running"
        self._rate_check: DeclaredRateCheck | None = None
        self._measured_rate: float | None = None    # set by the reader: switch to it
        self._warn_at: dict[str, float] = {}
        self._loop: Any = None                  # the rtseg.live.loop.SessionLoop running it
        self._reader_thread: threading.Thread | None = None
        self._polled = False                    # the loop reads the source (no thread)
        self._woken = False                     # the source's thread wakes the loop

    # ---------------------------------------------------------------- control
    def stop(self, reason: str = "stopped") -> None:
        """Ask the loop to end (from any thread; signal handlers use ``_on_signal``)."""
        if not self._stop.is_set():
            self.stop_reason = reason
        self._stop.set()
        if self._loop is not None:
            self._loop.waker.wake()

    def _on_signal(self, signum: int, _frame: Any) -> None:
        """SIGINT/SIGTERM handler.  Runs in the main thread between two bytecodes, possibly
        while that thread holds the ring buffer's lock: it must not take that lock (no
        ``ring.notify()``), so it only sets the flag; the loop wakes within 50 ms anyway."""
        if not self._stop.is_set():
            self.stop_reason = signal.Signals(signum).name
        self._stop.set()

    def _warn(self, key: str, msg: str, *args: Any, every: float = 5.0) -> None:
        now = time.monotonic()
        if now - self._warn_at.get(key, -1e9) >= every:
            self._warn_at[key] = now
            log.warning(msg, *args)

    # ---------------------------------------------------------------- setup
    def _open(self) -> None:
        if isinstance(self._source_arg, str):
            from rtseg.drivers import SourceError, open_source
            self._source_arg = with_suit(self._source_arg, self.config["source.suit"])
            try:
                self.source = open_source(self._source_arg)
            except SourceError as exc:      # several sources: say whose URL it is
                if self.name and not str(exc).startswith(f"{self.name}: "):
                    raise SourceError(f"{self.name}: {exc}") from exc
                raise
        else:
            self.source = self._source_arg
        src = self.source
        names = list(src.joint_names)
        parents = list(getattr(src, "parents", [-1] * len(names)))
        space = getattr(src, "space", "global")
        rate = getattr(src, "frame_rate", None)
        if not rate:
            log.warning("source has no nominal frame rate; assuming %.0f Hz until its clock "
                        "says otherwise (add rate= to the URL)", DEFAULT_FRAME_RATE)
        self.frame_rate = float(rate or DEFAULT_FRAME_RATE)
        self._rate_check = DeclaredRateCheck(self.frame_rate, assumed=not rate)
        self.pipeline = Pipeline(names, parents, space, self.frame_rate, self.config,
                                 rest=lambda: getattr(src, "rest_pose", None),
                                 standard=lambda: getattr(src, "t_pose_without_geometry", False))
        lines = []
        if hasattr(self.pipeline.features, "summary"):
            lines.append(self.pipeline.features.summary())
        if self.config["detectors.params"]:       # not the shipped defaults: say which
            from rtseg.config import params_path
            lines.append(f"detector parameters: {params_path(self.config['detectors.params'])}")
        for line in lines:
            log.info("%s", line)
            if self.on_start is not None:
                self.on_start(line)
        self.primary, self.wire = wire_methods(self.config, self.pipeline.detectors)
        J = len(names)
        self.ring = RingBuffer(int(self.config["buffer.capacity"]), J * 4, valid_width=J)
        if self.publishers is None:
            self.publishers = build_publishers(self.config)
        self._log_pubs = log_publishers(self.publishers)
        if self.pipeline.identity is not None and hasattr(self.publishers,
                                                          "templates_on_behaviour"):
            self.publishers.templates_on_behaviour()   # {label} = the behaviour (identity)
        if self.recorder is None and self.config["recording.dir"]:
            from rtseg.recording import SessionRecorder
            url = (self._source_arg if isinstance(self._source_arg, str)
                   else getattr(src, "url", type(src).__name__))
            meta = {"source": url, "config": self.config.origin,
                    "methods": list(self.pipeline.detectors), "primary": self.primary,
                    "wire_methods": sorted(self.wire),
                    "detector_params": self.detector_params}
            calibration = getattr(src, "calibration", None)     # serial:// calibration=FILE
            if hasattr(calibration, "as_dict"):
                meta["calibration"] = calibration.as_dict()     # the frames are calibrated
            try:
                self.recorder = SessionRecorder(
                    self.config["recording.dir"], names, parents, space=space,
                    frame_rate=self.frame_rate, start_monotonic=self.session_start, meta=meta)
            except OSError as exc:
                raise OSError(exc.errno, f"cannot record the session in "
                              f"{self.config['recording.dir']} ({exc.strerror or exc})") from None

    # ---------------------------------------------------------------- run
    def run(self) -> SessionSummary:
        """Run until the duration elapses, the source ends, or stop()/a signal; then shut
        everything down and return the summary.  The session runs on the calling thread
        (``rtseg.live.loop.run_sessions``, which also runs several sessions at once)."""
        return run_sessions([self], handle_signals=self.handle_signals)[0]

    def _begin(self, loop: Any) -> None:
        """Open the source and everything the session needs (``loop``: the
        ``rtseg.live.loop.SessionLoop`` that will run it)."""
        self._loop = loop
        # the time origin precedes the source's first frame (CutEvent.time >= 0)
        self.session_start = time.monotonic()
        self._open()
        J = len(self.pipeline.joint_names)
        rec_start = getattr(self.recorder, "start_monotonic", None)
        if isinstance(rec_start, float):
            self.session_start = rec_start
        self.clock = SessionClock(self.session_start, self.frame_rate,
                                  capacity=int(self.config["buffer.capacity"]),
                                  silence_s=float(self.config["gaps.dropout_seconds"]))
        if self.recorder is not None and hasattr(self.recorder, "clock"):
            self.recorder.clock = self.session_time     # its log lines' times
        self._last_valid = np.zeros(J)                  # session seconds
        self._joint_lost = np.zeros(J, dtype=bool)
        self._n_lost = 0
        self._dropout_s = float(self.config["gaps.dropout_seconds"])
        self._source_lost = False
        self._last_recv: float | None = None
        self._last_index = 0
        self._status_t = time.monotonic()
        self._status_frames = 0
        self._last_rate = 0.0
        self._interval = float(self.config["status.interval"])
        self._next_status = self._status_t + self._interval
        self._lag_warn = float(self.config["buffer.lag_warn_seconds"])
        self._max_lag = float(self.config["buffer.max_lag_seconds"])
        if getattr(self.source, "as_fast_as_read", False) is True:
            self._max_lag = 0.0          # a replay at speed 0: no frame is ever late
        self._thin = int(self.config["gaps.max_frames"])
        self._pending_lost = 0
        self._frame_cost = 0.0
        self._max_batch = int(self.config["buffer.max_batch"])
        self._begin_quiet()
        self._deadline: float | None = None      # set when the input starts
        self._cursor = self.ring.cursor(0)
        self._got: list[Any] = []
        self._last_step = 0.0

    def _wait_s(self, now: float) -> float:
        """How long the loop may sleep for this session: 0 while frames wait in the ring,
        else until its next status or deadline."""
        if self._cursor.backlog > 0 or self._stop.is_set():
            return 0.0
        wait = self._next_status - now
        if self._deadline is not None:
            wait = min(wait, self._deadline - now)
        return wait

    def _due(self, now: float) -> bool:
        """Whether the loop's wake-up concerns this session: frames wait, its status or
        deadline is due, it must stop, or ``STEP_EVERY_S`` passed since its last step
        (silence, recorder and monitor are looked after that often)."""
        return (self._cursor.backlog > 0 or now >= self._next_status
                or now - self._last_step >= STEP_EVERY_S or self._stop.is_set()
                or self._eof.is_set() or self._reader_error is not None
                or (self._deadline is not None and now >= self._deadline))

    def _step(self, now: float) -> None:
        """One wake-up of the session: frames too old dropped, the next window processed,
        silence, recorder, monitor and status looked after, stop conditions checked."""
        self._last_step = now
        cursor = self._cursor
        if self._max_lag > 0:
            # frames over the maximum lag: dropped at once, oldest first
            skipped = cursor.drop_older(now - self._max_lag)
            if skipped:
                self.stats.overload_drops += skipped
                self._pending_lost += skipped
        if self._measured_rate is not None:    # the source's clock disagreed
            rate, self._measured_rate = self._measured_rate, None
            try:
                switch_rate(self, rate, cursor.position)
            except Exception as exc:  # a rate the detectors refuse must not end the session
                log.error("could not switch to %g Hz (%s); the session keeps %g Hz",
                          rate, exc, self.frame_rate)
        w = cursor.read(self._max_batch)
        if len(w) or w.lost:
            self._process_window(w, now, self._loop.turn_s if self._loop is not None else None)
        self.stats.backlog = cursor.backlog
        self.stats.max_backlog = max(self.stats.max_backlog, self.stats.backlog)
        if self._polled and self.stats.overload_drops >= HAND_BACK_DROPS:
            self._hand_back()
        now = time.monotonic()
        if len(w) and self.stats.lag_s > self._lag_warn:
            self.stats.lag_warnings += 1
            self._warn("lag", "falling behind the source: frames wait %.0f ms "
                       "(%d frames queued)", self.stats.lag_s * 1000, cursor.backlog)
        if not len(w):
            self._check_silence(now)
            if self.recorder is not None and hasattr(self.recorder, "poll"):
                with self._rec_lock:
                    self.recorder.poll()
        if self.monitor is not None:
            self._monitor_call(self.monitor.tick)
        if now >= self._next_status:
            self._emit(self._status(now))
            self._next_status = max(self._next_status + self._interval,
                                    now + self._interval / 2)
        if self._deadline is not None and now >= self._deadline:
            self.stop("duration reached")
        elif self._eof.is_set() and cursor.backlog == 0:
            self.stop("end of source")
        elif self._reader_error is not None:
            self.stop(f"reader failed: {self._reader_error}")

    def _monitor_call(self, method: Callable[[Any], None]) -> None:
        try:
            method(self)
        except Exception as exc:  # the monitor must never end the session
            self.stats.monitor_errors += 1
            self._warn("monitor", "live monitor failed (%s: %s)", type(exc).__name__, exc)
