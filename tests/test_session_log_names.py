"""Several live sessions in one process: every log record says which session it concerns
(``rtseg.core.session_log``), whether it is logged on the loop's thread or in a thread a
session started (a driver's reader thread), and ``rtseg live`` with several sources
prints the name on every such line; one source prints its lines as before."""

from __future__ import annotations

import logging
import subprocess
import sys
import threading

import pytest

from rtseg.core.session_log import SessionNames, in_session, start_thread
from rtseg.live.config import from_dict
from rtseg.live.loop import run_sessions
from rtseg.live.session import LiveSession
from vendor_helpers import NoPublish, free_port


class Captured(logging.Handler):
    """Records that reach it, each with its formatted line, through :class:`SessionNames`."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.addFilter(SessionNames())
        self.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        self.got: list[tuple[logging.LogRecord, str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.got.append((record, self.format(record)))


@pytest.fixture
def captured():
    """A :class:`Captured` handler on the ``rtseg`` logger for the test."""
    handler = Captured()
    logger = logging.getLogger("rtseg")
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)


def absent_socket_device() -> str:
    """A serial URL on a TCP port nothing listens on, kept trying (``wait=1``): a pyserial
    URL is read by the source's own reader thread (never polled), which logs "cannot open"
    as soon as it starts."""
    return f"serial://socket://127.0.0.1:{free_port()}?wait=1"


def test_a_warning_of_session_bs_driver_thread_names_b(captured):
    """Session b's serial driver warns from its own reader thread, while session a runs
    beside it on the loop: the record is b's (``record.session``, and its line starts with
    "b: "), never a's."""
    cfg = from_dict({})
    a = LiveSession("sim://synth", cfg, publishers=NoPublish(), duration=0.5,
                    handle_signals=False, name="a")
    b = LiveSession(absent_socket_device(), from_dict({}), publishers=NoPublish(),
                    duration=0.5, handle_signals=False, name="b")
    run_sessions([a, b], handle_signals=False)
    cannot = [(r, line) for r, line in captured.got if "cannot open" in r.getMessage()]
    assert cannot, [line for _, line in captured.got]
    for record, line in cannot:
        assert record.threadName.startswith("rtseg-serial"), record.threadName  # the driver's
        assert record.session == "b"
        assert line.startswith("rtseg.drivers.serial: b: serial socket://"), line
    assert not [line for _, line in captured.got if line.split(": ", 2)[1] == "a"
                and "serial" in line]


def test_warnings_on_the_loop_thread_name_their_session_over_udp(captured):
    """Two VMC sources polled by one loop thread, b's declared rate wrong: the rate
    warning is b's alone, and every record of the run names the session it was logged
    for."""
    from rtseg.drivers import open_source
    from rtseg.simulators.vmc_sender import VmcSender
    from test_vmc_live import make_take

    take = make_take(240)                        # 60 Hz, 4 s of the sender's clock
    srcs = {"a": open_source("osc://127.0.0.1:0?format=vmc&rate=60"),
            "b": open_source("osc://127.0.0.1:0?format=vmc&rate=120")}
    sessions = [LiveSession(src, from_dict({}), publishers=NoPublish(), duration=1.2,
                            handle_signals=False, name=name) for name, src in srcs.items()]
    senders = [VmcSender(take, port=src.port, rate=60.0, speed=10.0) for src in srcs.values()]
    timer = threading.Timer(0.3, lambda: [s.start() for s in senders])
    timer.start()
    try:
        run_sessions(sessions, handle_signals=False)
    finally:
        timer.cancel()
        for s in senders:
            s.stop()
    rate = [(r, line) for r, line in captured.got if "declared rate=" in r.getMessage()]
    assert [r.session for r, _ in rate] == ["b"], [line for _, line in captured.got]
    assert rate[0][1].startswith("rtseg.live.session: b: declared rate=120 Hz")
    live = [r for r, _ in captured.got if r.name.startswith(("rtseg.live", "rtseg.drivers"))]
    assert live and all(r.session in ("a", "b") for r in live)


def test_the_filter_prefixes_once_and_threads_keep_the_name():
    """A message already starting with the name is left alone; a bad format is left for
    the handler to report; scopes nest and restore; a thread started with
    ``start_thread`` keeps its starter's session, one started plainly has none."""
    names = SessionNames()

    def record(msg: str, *args: object) -> logging.LogRecord:
        return logging.LogRecord("rtseg.x", logging.WARNING, __file__, 1, msg, args, None)

    with in_session("b"):
        r = record("b: already named")
        names.filter(r)
        assert r.getMessage() == "b: already named"
        r = record("100%% of %s lost", "frames")
        names.filter(r)
        assert r.getMessage() == "b: 100% of frames lost"
        bad = record("%d frames", "many")
        assert names.filter(bad) and bad.msg == "%d frames"
        with in_session("a"):
            r = record("inner")
            names.filter(r)
            assert r.getMessage() == "a: inner" and r.session == "a"
        seen: dict[str, str] = {}

        def look(key: str) -> None:
            r = record("x")
            names.filter(r)
            seen[key] = r.session

        start_thread(lambda: look("start_thread"), name="t1").join(2)
        plain = threading.Thread(target=look, args=("plain",))
        plain.start()
        plain.join(2)
        r = record("after")
        names.filter(r)
        assert r.getMessage() == "b: after"
    assert seen == {"start_thread": "b", "plain": ""}
    r = record("outside")
    names.filter(r)
    assert r.getMessage() == "outside" and r.session == ""


def _live(*argv: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "rtseg.cli", "live", *argv, "--no-osc",
                             "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)


def test_rtseg_live_names_every_logged_line_of_several_sources_and_none_of_one():
    """``rtseg live a=... b=...``: the driver's warning line of b starts its message with
    "b: "; the same source alone (named or not) prints it as before, without a name."""
    many = _live("a=sim://synth", f"b={absent_socket_device()}", "--duration", "0.5")
    one = _live(f"b={absent_socket_device()}", "--duration", "0.5")
    err_many = many.communicate(timeout=60)[1]
    err_one = one.communicate(timeout=60)[1]
    assert many.returncode == 0 and one.returncode == 0, err_many + err_one
    lines = [line for line in err_many.splitlines() if "cannot open" in line]
    assert lines and all(" WARNING rtseg.drivers.serial: b: serial socket://" in line
                         for line in lines), err_many
    logged = [line for line in err_many.splitlines() if " WARNING " in line]
    assert all(line.split(": ", 2)[1] in ("a", "b") for line in logged), err_many
    lines = [line for line in err_one.splitlines() if "cannot open" in line]
    assert lines and all(" WARNING rtseg.drivers.serial: serial socket://" in line
                         for line in lines), err_one
