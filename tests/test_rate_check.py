"""A declared rate= that disagrees with what arrives: one warning, over real UDP."""

from __future__ import annotations

import logging
import threading

import pytest

from rtseg.live.rate_check import DeclaredRateCheck


def test_check_warns_once_when_off_and_not_when_right():
    off = DeclaredRateCheck(60.0)
    msgs = [off.feed(i / 120.0, i / 120.0, i) for i in range(600)]
    said = [m for m in msgs if m]
    assert len(said) == 1 and "rate=60 Hz" in said[0] and "120.0 Hz" in said[0]
    ok = DeclaredRateCheck(120.0)
    assert not any(ok.feed(i / 120.0, i / 120.0, i) for i in range(600))
    assert ok.measured_hz == pytest.approx(120.0)


def test_lost_frames_do_not_lower_the_measured_rate():
    chk = DeclaredRateCheck(120.0)
    kept = [i for i in range(600) if i % 10 != 3]          # 10 % lost, seq shows the gaps
    assert not any(chk.feed(i / 120.0, i / 120.0, i) for i in kept)


def test_vmc_at_120_hz_into_rate_60_warns_over_udp(caplog):
    from rtseg.drivers import open_source
    from rtseg.live.session import LiveSession
    from rtseg.publishers import PublisherSet
    from rtseg.simulators.vmc_sender import VmcSender
    from rtseg.live.config import from_dict
    from tests.test_vmc_live import make_take
    take = make_take(400, seed=1)                  # 400 frames, sent at 120 Hz: 3.3 s
    src = open_source("osc://127.0.0.1:0?format=vmc&rate=60&queue=4096")
    sess = LiveSession(src, from_dict({"calibration": {"mode": "none"}}),
                       publishers=PublisherSet(), handle_signals=False)
    with caplog.at_level(logging.WARNING, logger="rtseg"):
        sender = VmcSender(take, port=src.port, rate=120.0)
        t = threading.Timer(4.5, sess.stop)
        t.start()
        with sender:
            summary = sess.run()
        t.cancel()
    warned = [r for r in caplog.records if "declared rate=60 Hz" in r.getMessage()]
    assert len(warned) == 1 and summary.frames_received > 240
