"""``rtseg live SOURCE_URL``: segment a live stream and send each cut over OSC.

Cuts are printed on stdout as they happen (one line each); a one-line status (input frame
rate, drops, stale joints, lag, last cut) goes to stderr - rewritten in place with ``\\r``
when stderr is a terminal, otherwise printed as a plain line every few seconds.  Ctrl-C or
SIGTERM ends the session cleanly (source, publishers and recording closed, summary printed).
"""

from __future__ import annotations

import argparse
import re
import sys
import time
from typing import Any, Callable, TextIO

from rtseg.cli import error_text, params_file, positive_float
from rtseg.config import ConfigError
from rtseg.core.events import SENDER_COUNTERS, BehaviourEvent, CutEvent, DropoutEvent, StatusEvent
from rtseg.live.stats import source_losses_text
from rtseg.live.config import SessionConfig, load_session_config

#: seconds between plain status lines when stderr is not a terminal
PLAIN_STATUS_EVERY = 5.0


def add_session_arguments(p: argparse.ArgumentParser, osc_default_note: str = "") -> None:
    """Options shared by ``rtseg live`` and ``rtseg demo``."""
    p.add_argument("--osc", action="append", metavar="HOST:PORT",
                   help="OSC/UDP target for cut, status and dropout messages (repeatable; "
                        "replaces the config's output.osc; default 127.0.0.1:9123)"
                   + osc_default_note)
    p.add_argument("--osc-tcp", action="append", metavar="HOST:PORT",
                   help="OSC 1.1 over TCP (SLIP) target, e.g. QLab (repeatable)")
    p.add_argument("--no-osc", action="store_true", help="send no OSC over UDP")
    p.add_argument("--template", action="append", metavar="ADDR",
                   help="extra OSC address template sent on each cut to every OSC target, "
                        "e.g. '/cue/{label}/start' (repeatable)")
    p.add_argument("--target", action="append", metavar="SPEC",
                   help="full target spec, e.g. 'udp:127.0.0.1:53000,standard=off,"
                        "template=/cue/{label}/start' (repeatable)")
    p.add_argument("--jsonl", metavar="PATH|-", help="also write events as JSON lines ('-': stdout)")
    p.add_argument("--record", metavar="DIR", help="record the session (frames + events) to DIR")
    p.add_argument("--config", metavar="FILE", help="session configuration (default config/live.toml)")
    p.add_argument("--methods", metavar="LIST",
                   help="online detectors, comma separated: contrast (the default), pca, ppca")
    p.add_argument("--params", type=params_file, metavar="FILE",
                   help="detector parameters, TOML or JSON with one table per method "
                        "([contrast] ...; detectors.params): a file, or a shipped set: "
                        "'full' (each change waits for the contrast to fall: about 0.5 s "
                        "later; config/full.toml) or 'fast' (sooner; config/fast.toml)")
    p.add_argument("--duration", type=positive_float, metavar="S",
                   help="stop after S seconds (a number > 0)")
    p.add_argument("--max-lag", type=float, metavar="S",
                   help="longest a frame may wait before processing, s (default 0.1, "
                        "buffer.max_lag_seconds): under overload older frames are dropped, "
                        "oldest first, and counted; 0 = never drop")
    p.add_argument("--quiet", action="store_true", help="no status line on stderr")
    p.add_argument("--monitor", nargs="?", const="", default=None, metavar="[HOST:]PORT",
                   help="serve a live monitor page (detector statistic, cuts, behaviours, "
                        "input health) on HOST:PORT (default 127.0.0.1:8765; another host "
                        "than 127.0.0.1 lets that network watch); needs "
                        "pip install 'rtseg[monitor]'")


def config_from_args(args: argparse.Namespace) -> SessionConfig:
    """The session configuration: file (``--config``) then command-line overrides.
    Errors name the key or the flag."""
    over: dict[str, Any] = {}
    if args.osc:
        over["output.osc"] = list(args.osc)
    if getattr(args, "no_osc", False):
        if args.osc:
            raise ConfigError("--no-osc and --osc: give one of them")
        over["output.osc"] = []
    if args.osc_tcp:
        over["output.osc_tcp"] = list(args.osc_tcp)
    if args.template:
        over["output.templates"] = list(args.template)
    if args.target:
        over["output.targets"] = list(args.target)
    if args.jsonl:
        over["output.jsonl"] = args.jsonl
    if args.record:
        check_record_dir(args.record)
        over["recording.dir"] = args.record
    if getattr(args, "max_lag", None) is not None:
        over["buffer.max_lag_seconds"] = args.max_lag
    if getattr(args, "params", None):
        over["detectors.params"] = args.params
    if args.methods:
        over["detectors.methods"] = [m.strip() for m in args.methods.split(",") if m.strip()]
    cfg = load_session_config(args.config)
    if over:
        from rtseg.live.config import apply_overrides
        for key, value in over.items():
            try:
                apply_overrides(cfg, {key: value}, origin="command line")
            except ConfigError as exc:
                flag = FLAGS.get(key, key)
                raise ConfigError(str(exc).replace(f"command line: {key}", flag, 1)) from None
    if args.template and not (cfg["output.osc"] or cfg["output.osc_tcp"] or any(
            not str(t).startswith(("-", "jsonl:")) for t in cfg["output.targets"])):
        raise ConfigError("--template: no OSC target to send it to (--no-osc, and no --osc-tcp "
                          "or --target)")
    return cfg


def check_record_dir(path: str) -> None:
    """Refuse a ``--record`` folder that cannot hold a new recording (not empty, a file,
    or its parent missing / not writable) before anything is opened."""
    import os
    from pathlib import Path
    p = Path(path)
    if p.exists():
        if not p.is_dir():
            raise ConfigError(f"--record {path}: exists and is not a folder")
        if any(p.iterdir()):
            raise ConfigError(f"--record {path}: folder exists and is not empty "
                              "(give a new or empty folder)")
        if not os.access(p, os.W_OK | os.X_OK):
            raise ConfigError(f"--record {path}: folder is not writable")
        return
    parent = p.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"--record {path}: cannot create the folder ({parent} is not a "
                          "writable folder)")


#: configuration key -> the command-line flag that sets it (for error messages)
FLAGS = {"output.osc": "--osc", "output.osc_tcp": "--osc-tcp", "output.templates": "--template",
         "output.targets": "--target", "output.jsonl": "--jsonl", "recording.dir": "--record",
         "detectors.methods": "--methods", "detectors.params": "--params",
         "buffer.max_lag_seconds": "--max-lag"}


def format_cut(ev: CutEvent) -> str:
    """One cut line; ``t=`` is ``ev.time``, the boundary in session seconds (the time
    sent over OSC and written to JSON lines and the recording)."""
    proc = "-" if ev.processing_ms is None else f"{ev.processing_ms:.2f}"
    num = f"#{ev.event:<3d}" if ev.wire else "(log)"    # (log): not sent over OSC
    t = ev.time
    return (f"cut {num} {ev.method:<5s} segment {ev.segment:<3d} "
            f"frame {ev.frame:<7d} t={t:9.3f} s  confidence {ev.confidence:.2f}  "
            f"detector delay {ev.detector_delay_ms:4.0f} ms  processing {proc} ms")


def format_behaviour(ev: BehaviourEvent, first_segment: int | None) -> str:
    """One behaviour line (``rtseg.identity.tracker``): which behaviour segment ``ev.segment`` is.

    first_segment: the earliest segment of the session with this behaviour id, when that is
    an earlier one (the behaviour recurs), else None (a new behaviour).  ``decided t=`` is
    ``ev.time``, when the decision was made in session seconds."""
    name = f' "{ev.name}"' if ev.name and ev.name != ev.behaviour else ""
    if ev.correction:
        what = f"corrected from {ev.previous or '-'}"
    elif first_segment is None:
        what = "new behaviour"
    else:
        what = f"same as segment {first_segment}"
    t = ev.time
    return (f"behaviour {ev.behaviour:>3s}{name} segment {ev.segment:<3d} "
            f"from frame {ev.frame:<7d} decided t={t:9.3f} s  ({what})  "
            f"confidence {ev.confidence:.2f}")


class Console:
    """Prints cuts and behaviour decisions on ``out`` and the status line on ``err``
    (an event listener)."""

    def __init__(self, out: TextIO | None = None, err: TextIO | None = None,
                 print_cuts: bool = True, status: bool = True,
                 session_stats: Callable[[], Any] | None = None,
                 name: str = "") -> None:
        # the streams of the moment (not those bound when this module was imported)
        self.out = out if out is not None else sys.stdout
        self.err = err if err is not None else sys.stderr
        self.print_cuts = print_cuts
        self.status = status
        #: the source's name when several run: lines start with it, and the status is a
        #: plain line (several sessions would overwrite each other's line in place)
        self.name = name
        self.tty = bool(getattr(err, "isatty", lambda: False)()) and not name
        self.last_cut: CutEvent | None = None
        self.session_stats = session_stats
        self._line_shown = False
        self._last_plain = 0.0
        self._corrupt_at: tuple[float, int] | None = None   # (Unix s, corrupt count)
        self.first_segment: dict[str, int] = {}    # behaviour id -> earliest segment
        self.last_behaviour: BehaviourEvent | None = None
        #: lines printed before the first status line (the features the session uses, the
        #: detector parameter file)
        self.banners: list[str] = []

    @property
    def _tag(self) -> str:
        return f"{self.name}: " if self.name else ""

    def _clear(self) -> None:
        if self.tty and self._line_shown:
            self.err.write("\r\033[K")
            self.err.flush()
            self._line_shown = False

    def __call__(self, ev: Any) -> None:
        if isinstance(ev, CutEvent):
            self.last_cut = ev
            if self.print_cuts:
                self._clear()
                print(self._tag + format_cut(ev), file=self.out, flush=True)
        elif isinstance(ev, BehaviourEvent):
            self.last_behaviour = ev
            first = self.first_segment.setdefault(ev.behaviour, ev.segment)
            if self.print_cuts:
                self._clear()
                print(self._tag + format_behaviour(ev, first if first != ev.segment else None),
                      file=self.out, flush=True)
        elif isinstance(ev, DropoutEvent):
            self._clear()
            print(f"rtseg: {self._tag}dropout: {ev.name} {'lost' if ev.lost else 'restored'} "
                  f"at t={ev.time:.2f} s", file=self.err, flush=True)
        elif isinstance(ev, StatusEvent) and self.status and ev.alive:
            self._show_banners()      # the joints the features use, once the session runs
            self.show_status(ev)

    def show_status(self, ev: StatusEvent) -> None:
        lag = ""
        if self.session_stats is not None:
            st = self.session_stats()
            lag = f" | lag {st.lag_s * 1000:.0f} ms"
        last = "-"
        if self.last_cut is not None:
            c = self.last_cut
            last = f"{c.method} #{c.event} at {c.time:.2f} s"
            b = self.last_behaviour
            if b is not None and b.segment == c.segment:
                last += f" ({b.label})"
        # messages arriving damaged: their rate next to the frames' (0.0 fps of intact
        # frames while a suit sends 120 corrupt messages a second says so); both per
        # wall-clock second (the events' wall_time)
        damaged = ""
        wall = ev.wall_time
        prev, self._corrupt_at = self._corrupt_at, (wall, ev.corrupt)
        if prev is not None and ev.corrupt > prev[1] and wall > prev[0]:
            damaged = f" (+{(ev.corrupt - prev[1]) / (wall - prev[0]):.1f}/s corrupt)"
        line = (f"rtseg live: {self._tag}{ev.time:7.1f} s | {ev.frame_rate:6.1f} fps{damaged} | "
                f"{ev.dropped} dropped"
                + (f" ({ev.overload_drops} under overload)" if ev.overload_drops else "")
                + f" | {ev.stale_joints} stale{lag} | last cut: {last}")
        if any(ev.input_counts().values()):
            line += f" | {ev.input_text()}"
        refused = source_losses_text({k: getattr(ev, k) for k in SENDER_COUNTERS})
        if refused:
            line += " | " + refused[2:]
        if ev.recording_failed_at >= 0:
            line += (f" | RECORDING FAILED at frame {ev.recording_failed_at} (it holds "
                     f"{ev.recording_frames} frames, {ev.recording_cuts} cuts)")
        if self.tty:
            self.err.write("\r\033[K" + line)
            self.err.flush()
            self._line_shown = True
        else:
            now = time.monotonic()
            if now - self._last_plain >= PLAIN_STATUS_EVERY:
                self._last_plain = now
                print(line, file=self.err, flush=True)

    def _show_banners(self) -> None:
        """The start lines not shown yet (with the status line: not under --quiet)."""
        if self.banners and self.status:
            self._clear()
            for line in self.banners:
                print(f"rtseg live: {self._tag}{line}", file=self.err, flush=True)
        self.banners = []

    def finish(self) -> None:
        self._clear()
        self._show_banners()      # a session that ended before its first status line


def start_monitor(address: str | None, prog: str) -> tuple[Any, Any] | None:
    """The live monitor's feed and started server for ``--monitor`` (None: not asked);
    prints its address (and what a non-loopback binding exposes) on stderr.  Raises
    ConfigError when it cannot run (aiohttp missing, bad or busy address)."""
    if address is None:
        return None
    from rtseg.monitor import MonitorUnavailable, start_monitor as start
    try:
        feed, server = start(address or None)
    except (MonitorUnavailable, ValueError, OSError) as exc:
        raise ConfigError(f"--monitor: {exc}") from None
    from rtseg.monitor.server import exposure_note
    print(f"{prog}: live monitor at {server.url}", file=sys.stderr, flush=True)
    note = exposure_note(server.host, server.port)
    if note:
        print(f"{prog}: warning: {note}", file=sys.stderr, flush=True)
    return feed, server


def run_session(source: Any, cfg: SessionConfig, duration: float | None, quiet: bool,
                before_run: Callable[[], None] | None = None,
                monitor: tuple[Any, Any] | None = None,
                check: Callable[[Any], int] | None = None, name: str = "") -> int:
    """Run a live session with console output; returns the exit status (``check``, when
    given, judges the :class:`rtseg.live.stats.SessionSummary` after it is printed:
    its return value is the status).

    ``monitor``: ``(feed, server)`` of :func:`start_monitor`; the server is stopped when
    the session ends.  ``name``: the source's name (``NAME=URL``; "" for none).

    Every time printed (cuts, behaviour decisions, dropouts, status) is in session seconds,
    the times sent and recorded (``rtseg.live.clock``)."""
    from rtseg.live.session import LiveSession
    console = Console(print_cuts=cfg["output.jsonl"] != "-", status=not quiet)
    try:
        session = LiveSession(source, cfg, listeners=[console], duration=duration,
                              monitor=monitor[0] if monitor else None, name=name,
                              on_start=console.banners.append)
        console.session_stats = lambda: session.stats
        if before_run is not None:
            before_run()
        summary = session.run()
    finally:
        console.finish()
        if monitor is not None:
            monitor[1].stop()
    print(summary.text(), file=sys.stderr, flush=True)
    return check(summary) if check is not None else 0


def run_many(sources: list[tuple[str, str]], cfg: SessionConfig, duration: float | None,
             quiet: bool) -> int:
    """Several sources, one session each, on one thread (``rtseg.live.loop.run_sessions``):
    each with its own detectors and counters; its events carry its name (OSC addresses
    ``/rtseg/<name>/...``), its recording goes to ``recording.dir/<name>``.  Each
    summary is printed after its name, and so is every line it logs (its driver's
    warnings, its session's: ``rtseg.core.session_log``); the exit status is 0."""
    import copy
    from pathlib import Path
    from rtseg.core.session_log import session_names_shown
    from rtseg.live.loop import run_sessions
    from rtseg.live.session import LiveSession
    sessions, consoles = [], []
    try:
        for name, url in sources:
            c = copy.deepcopy(cfg)
            if cfg["recording.dir"]:
                c["recording.dir"] = str(Path(cfg["recording.dir"]) / name)
            console = Console(print_cuts=cfg["output.jsonl"] != "-", status=not quiet,
                              name=name)
            session = LiveSession(url, c, listeners=[console], duration=duration, name=name,
                                  on_start=console.banners.append)
            console.session_stats = lambda s=session: s.stats
            sessions.append(session)
            consoles.append(console)
        with session_names_shown():
            summaries = run_sessions(sessions)
    finally:
        for console in consoles:
            console.finish()
    for (name, _), summary in zip(sources, summaries):
        print(f"{name}: {summary.text()}", file=sys.stderr, flush=True)
    return 0


#: ``NAME=URL`` on the command line: a source named NAME
_NAMED = re.compile(r"([A-Za-z0-9_-]{1,64})=(.+)")


def source_list(given: list[str], cfg: SessionConfig) -> list[tuple[str, str]]:
    """``(name, url)`` of each source to run: the command line's (``URL`` or
    ``NAME=URL``), else the configuration's ``[[sources]]``, else its ``source.url``.
    With several, an unnamed one is ``suit<k>`` (k its 1-based position).  Names used
    twice raise ConfigError."""
    out: list[tuple[str, str]] = []
    if given:
        for item in given:
            m = _NAMED.fullmatch(item)
            if m is None and "=" in item.split("://", 1)[0]:
                raise ConfigError(f"source {item!r}: a source name (NAME=URL) is letters, "
                                  f"digits, _ and - (at most 64)")
            out.append((m.group(1), m.group(2)) if m and "://" not in m.group(1)
                       else ("", item))
    elif cfg.sources:
        out = [(e["name"], e["url"]) for e in cfg.sources]
    elif cfg["source.url"]:
        out = [("", cfg["source.url"])]
    if len(out) > 1:
        out = [(name or f"suit{k}", url) for k, (name, url) in enumerate(out, 1)]
    names = [n for n, _ in out]
    twice = sorted({n for n in names if n and names.count(n) > 1})
    if twice:
        raise ConfigError(f"source name {twice[0]!r} is given twice")
    return out


def use_library(cfg: Any, path: str, prog: str) -> bool:
    """Turn identity on with the behaviour library file ``path`` (``--behaviours``): its
    format and version are checked now, its feature profile at session start.  False, with
    one line on stderr, when it is refused."""
    from rtseg.library.behaviours import LibraryError
    from rtseg.library.file import load
    try:
        load(path)
    except LibraryError as exc:
        print(f"{prog}: {error_text(exc)}", file=sys.stderr)
        return False
    cfg["identity.enabled"] = True
    cfg["identity.behaviours"] = path
    return True


def run(args: argparse.Namespace) -> int:
    try:
        cfg = config_from_args(args)
    except ConfigError as exc:
        print(f"rtseg live: configuration error: {error_text(exc)}", file=sys.stderr)
        return 2
    if getattr(args, "behaviours", None) and not use_library(cfg, args.behaviours, "rtseg live"):
        return 2
    try:
        sources = source_list(args.source, cfg)
    except ConfigError as exc:
        print(f"rtseg live: {exc}", file=sys.stderr)
        return 2
    if not sources:
        print("rtseg live: no source: give SOURCE_URL or set source.url (or [[sources]]) in "
              "the configuration", file=sys.stderr)
        return 2
    if len(sources) > 1 and getattr(args, "monitor", None) is not None:
        print("rtseg live: --monitor shows one source; give one SOURCE_URL", file=sys.stderr)
        return 2
    from rtseg.drivers import SourceError
    try:
        if len(sources) > 1:
            return run_many(sources, cfg, args.duration, args.quiet)
        name, url = sources[0]
        monitor = start_monitor(getattr(args, "monitor", None), "rtseg live")
        return run_session(url, cfg, args.duration, args.quiet, monitor=monitor, name=name)
    except (ConfigError, SourceError) as exc:
        print(f"rtseg live: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:   # setup (recording folder, output file): the loop never raises
        print(f"rtseg live: error: {exc.strerror or exc}"
              + (f": {exc.filename}" if exc.filename else ""), file=sys.stderr)
        return 2


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "live", help="segment a live stream and send cuts over OSC",
        description="Segment a live motion stream into behaviours and send each cut over OSC "
                    "as it happens.  Sources: serial:///dev/ttyUSB0?baud=921600, "
                    "osc://:39539?format=vmc (loopback; write 0.0.0.0 and allow= to listen on the "
                    "network), file://take.amc?skeleton=86.asf, "
                    "sim://synth.")
    p.add_argument("source", nargs="*", metavar="SOURCE_URL",
                   help="where frames come from (default: [[sources]] or source.url of the "
                        "configuration); several run in one process, one session each, "
                        "named NAME=URL (default suit1, suit2, ...): their cuts and status go "
                        "out as /rtseg/NAME/cut, ...")
    add_session_arguments(p)
    p.add_argument("--behaviours", metavar="LIB",
                   help="behaviour library (rtseg learn) naming each segment; turns identity "
                        "on; a segment unlike every example is named 'unknown'")
    p.set_defaults(func=run)
