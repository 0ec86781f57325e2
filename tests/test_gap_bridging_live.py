"""A stream losing 5 % of its frames at random, through a real pty (serial suit) and real
UDP (VMC sender): the short gaps are bridged and the detectors never restart."""

from __future__ import annotations

from rtseg.live.session import LiveSession
from rtseg.live.config import from_dict
from rtseg.simulators.serial_device import SerialSuit
from rtseg.simulators.synth.motion import synthesize
from rtseg.simulators.vmc_sender import VmcSender

from vendor_helpers import free_port, run_while_sending

SPEED = 4.0


def _take():
    return synthesize("idle:3,walk:3", frame_rate=120.0, seed=1).take


def _config():
    return from_dict({"output": {"osc": []}}, origin="test")


def _check(session: LiveSession, sent: int) -> None:
    st = session.pipeline.stats
    assert 0.85 * sent < session.stats.frames_received < 0.99 * sent
    assert st.restarts == 0
    # every gap after calibration is filled (one before it is not: nothing is fed yet)
    assert st.bridged_gaps >= 10 and 0.9 * st.gap_frames <= st.filled_frames <= st.gap_frames
    assert st.fed == session.stats.frames_processed - st.calibration_frames


def test_serial_5_percent_loss_does_not_restart_the_detectors():
    take = _take()
    suit = SerialSuit(take, rate=120.0, speed=SPEED, faults="drop=0.05,seed=4")
    path = suit.start()
    try:
        session = LiveSession(f"serial://{path}?rate=120", _config(), handle_signals=False,
                              duration=take.n_frames / 120.0 / SPEED + 1.5)
        session.run()
    finally:
        suit.stop()
    dropped = sum(1 for m in suit.sent_log if m.fate == "dropped")
    assert dropped > 0.03 * take.n_frames
    _check(session, take.n_frames)


def test_vmc_5_percent_loss_does_not_restart_the_detectors():
    take = _take()
    port = free_port()
    session = LiveSession(f"osc://127.0.0.1:{port}?format=vmc&rate=120", _config(),
                          handle_signals=False, duration=take.n_frames / 120.0 / SPEED + 2.0)
    sender = VmcSender(take, "127.0.0.1", port, rate=120.0, speed=SPEED,
                       faults="drop=0.05,seed=4")
    run_while_sending(session, sender)
    assert sum(1 for f in sender.sent_log if f.dropped) > 0.03 * take.n_frames
    _check(session, take.n_frames)
