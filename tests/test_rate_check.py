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


def _vmc_session_cuts(take, declared: float | None, caplog) -> tuple[list, object, list[str]]:
    """The primary detector's cuts of a live session on a VMC sender playing ``take`` at 4x
    (its /VMC/Ext/T keeps the take's rate) over real UDP, read with ``rate=declared`` (no
    rate= when None); the rate warnings."""
    import time as _time

    from rtseg.drivers import open_source
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    from rtseg.publishers import PublisherSet
    from rtseg.simulators.vmc_sender import VmcSender
    rate = "" if declared is None else f"&rate={declared:g}"
    src = open_source(f"osc://127.0.0.1:0?format=vmc{rate}&queue=4096")
    cuts: list = []
    sess = LiveSession(src, from_dict({"buffer": {"max_lag_seconds": 0.0}}),
                       publishers=PublisherSet(), handle_signals=False,
                       listeners=[lambda ev: cuts.append(ev) if getattr(ev, "wire", False)
                                  else None])
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtseg"):
        sender = VmcSender(take, port=src.port, rate=take.frame_rate, speed=4.0)
        box: dict = {}
        t = threading.Thread(target=lambda: box.setdefault("s", sess.run()), daemon=True)
        t.start()
        _time.sleep(0.3)
        with sender:
            sender.done.wait(60)
            _time.sleep(1.0)
        sess.stop()
        t.join(20)
    said = [r.getMessage() for r in caplog.records
            if "declared rate=" in r.getMessage() or "declares no frame rate" in r.getMessage()]
    return cuts, sess, said


def test_a_sender_faster_than_declared_is_segmented_at_its_own_rate(caplog):
    """A VMC sender at 120 Hz read as rate=60: one warning, and the session runs at the
    rate the sender's clock shows - the same cuts as a session told rate=120 (before, the
    detectors' windows were half their length in seconds and cut more often)."""
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize("idle:4,walk:5,punch:5,squat:5", frame_rate=120.0, seed=0).take
    wrong, sess, said = _vmc_session_cuts(take, 60.0, caplog)
    assert len(said) == 1 and "uses 120 Hz from now on" in said[0], said
    assert sess.frame_rate == 120.0 and sess.pipeline.frame_rate == 120.0
    right, sess2, said2 = _vmc_session_cuts(take, 120.0, caplog)
    assert not said2 and sess2.frame_rate == 120.0
    assert len(right) >= 2
    assert [c.frame for c in wrong] == pytest.approx([c.frame for c in right], abs=3)
    # times on the sender's clock, from each session's first frame
    t0, t0_2 = sess.clock.time_of(0), sess2.clock.time_of(0)
    assert [c.time - t0 for c in wrong] == pytest.approx([c.time - t0_2 for c in right],
                                                         abs=0.03)
    assert all(c.detector_delay_ms == pytest.approx(d.detector_delay_ms, abs=30)
               for c, d in zip(wrong, right))


def test_a_sender_without_a_declared_rate_is_segmented_at_its_clock_rate(caplog):
    """A VMC sender at 60 Hz read without rate= (the session assumes 120 Hz): one warning
    saying no rate was declared, and the session runs at the 60 Hz the sender's clock shows
    - the same cuts as a session told rate=60."""
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize("idle:4,walk:5,punch:5,squat:5", frame_rate=60.0, seed=0).take
    none, sess, said = _vmc_session_cuts(take, None, caplog)
    assert len(said) == 1 and "declares no frame rate" in said[0], said
    assert "uses 60 Hz from now on" in said[0] and "add rate=60" in said[0]
    assert sess.frame_rate == 60.0 and sess.pipeline.frame_rate == 60.0
    # the pipeline built at the new rate still knows where the rig's geometry comes from
    # (the sender's bone positions), so names by posture go on
    rest = sess.pipeline.posture.rest
    assert callable(rest) and rest() is not None
    right, sess2, said2 = _vmc_session_cuts(take, 60.0, caplog)
    assert not said2 and sess2.frame_rate == 60.0
    assert len(right) >= 2
    assert [c.frame for c in none] == pytest.approx([c.frame for c in right], abs=2)


def test_damaged_timestamps_do_not_move_the_measured_rate():
    """A clock with a few wild values (a corrupting link): the median period still says
    120 Hz; a clock that says an implausible rate is not believed (no switch)."""
    chk = DeclaredRateCheck(120.0, assumed=True)
    times = [i / 120.0 for i in range(600)]
    for k in (30, 31, 200, 333):
        times[k] += 57.0 if k % 2 else -3.0               # jumps either way
    said = [m for m in (chk.feed(i / 120.0, t, i) for i, t in enumerate(times)) if m]
    assert not said and chk.measured_hz == pytest.approx(120.0)
    slow = DeclaredRateCheck(120.0, assumed=True)
    said = [m for m in (slow.feed(i / 120.0, i * 1.25, i) for i in range(600)) if m]
    assert len(said) == 1 and "not believed" in said[0] and not slow.mismatch


def test_a_switch_the_detectors_refuse_is_logged_and_the_session_goes_on(caplog, monkeypatch):
    """Whatever the clock says, the live loop is never ended by the rate switch: a rate
    the detectors cannot run at is an error line and the session keeps its rate."""
    import rtseg.live.session as session_mod
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    from rtseg.publishers import PublisherSet

    def refuse(session, rate, upto):
        raise ValueError("min_before must be at least two steps")
    monkeypatch.setattr(session_mod, "switch_rate", refuse)
    sess = LiveSession("sim://synth", from_dict({}), publishers=PublisherSet(),
                       handle_signals=False, duration=1.0)
    sess._measured_rate = 0.8
    with caplog.at_level(logging.ERROR, logger="rtseg"):
        summary = sess.run()
    assert summary.stop_reason == "duration reached" and summary.frames_processed > 0
    assert any("could not switch to 0.8 Hz" in r.getMessage() for r in caplog.records)
    assert sess.frame_rate == 120.0
