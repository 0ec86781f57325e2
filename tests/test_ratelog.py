"""The rate-limited log shared by the drivers and the publishers (rtseg.core.ratelog)."""

from __future__ import annotations

import logging

from rtseg.core.ratelog import RateLimitedLog


def _log(caplog, interval: float) -> RateLimitedLog:
    logger = logging.getLogger("rtseg.test.ratelog")
    caplog.set_level(logging.INFO, logger=logger.name)
    return RateLimitedLog(logger, interval=interval)


def test_repeats_within_the_interval_are_counted_and_said_with_the_next_message(caplog,
                                                                                monkeypatch):
    clock = [100.0]
    monkeypatch.setattr("rtseg.core.ratelog.time.monotonic", lambda: clock[0])
    rl = _log(caplog, interval=5.0)
    for k in range(4):                        # 100.0 .. 100.3 s: one logged, three left out
        rl("gap", "serial %s: %d messages missing", "/dev/x", k + 1)
        clock[0] += 0.1
    rl("other", "another kind is not held back")
    clock[0] = 105.5                          # past the interval: logged, with the count
    rl("gap", "serial %s: %d messages missing", "/dev/x", 9)
    msgs = [r.getMessage() for r in caplog.records]
    assert msgs == ["serial /dev/x: 1 messages missing",
                    "another kind is not held back",
                    "serial /dev/x: 9 messages missing (3 similar suppressed in the last 5 s)"]
    assert all(r.levelno == logging.WARNING for r in caplog.records)


def test_a_formatted_message_with_a_percent_sign_is_logged_as_text(caplog, monkeypatch):
    clock = [0.0]
    monkeypatch.setattr("rtseg.core.ratelog.time.monotonic", lambda: clock[0])
    rl = _log(caplog, interval=1.0)
    rl("send", "target 100% busy: OSError('%s')", level=logging.ERROR)
    rl("send", "target 100% busy: OSError('%s')", level=logging.ERROR)
    clock[0] = 2.0
    rl("send", "target 100% busy: OSError('%s')", level=logging.ERROR)
    msgs = [r.getMessage() for r in caplog.records]
    assert msgs == ["target 100% busy: OSError('%s')",
                    "target 100% busy: OSError('%s') (1 similar suppressed in the last 1 s)"]
    assert [r.levelno for r in caplog.records] == [logging.ERROR, logging.ERROR]
