"""A real take through the simulated serial suit on a real pty into the live loop: the cuts
it sends are the ones the same detector gives offline on the recorded frames, and they
score on 86_01 like ``rtseg evaluate --online`` does."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from rtseg.evaluation.scoring import score, widen
from rtseg.labels.takes import find_labelled_takes
from rtseg.live.session import LiveSession
from rtseg.evaluation.online import live_config, live_cuts
from rtseg.live.replay import replay_session
from rtseg.recording import read_session
from rtseg.live.config import from_dict
from rtseg.simulators.serial_device import SerialSuit

SPEED = 4.0   # 480 frames/s; at 8x the test failed once with load average 4.5


@pytest.mark.realdata
@pytest.mark.slow
def test_86_01_through_the_serial_suit_scores_like_evaluate_online(data_dir, tmp_path):
    [lt] = [t for t in find_labelled_takes(data_dir, ("cmu",)) if t.name == "86_01"]
    take = lt.load()
    rec = tmp_path / "session"
    suit = SerialSuit(take, rate=take.frame_rate, speed=SPEED)
    box: dict = {}
    try:
        path = suit.start()
        cfg = from_dict({"output": {"osc": []}, "recording": {"dir": str(rec)}}, origin="test")
        session = LiveSession(f"serial://{path}?rate={take.frame_rate:g}", cfg,
                              handle_signals=False)
        th = threading.Thread(target=lambda: box.setdefault("s", session.run()), daemon=True)
        th.start()
        assert suit.wait_done(take.n_frames / (take.frame_rate * SPEED) + 20)
        time.sleep(0.5)
        session.stop("test done")
        th.join(15)
        assert not th.is_alive()
    finally:
        suit.stop()
    assert session.primary == "contrast"
    tk = read_session(rec)
    assert tk.n_frames == take.n_frames, "every frame of the take was received and recorded"
    sent = [c for c in tk.meta["cuts"] if c.wire]
    offline = replay_session(str(rec))
    assert len(sent) == len(offline) >= 5
    for c, o in zip(sent, offline):
        assert abs(c.frame - o.boundary) <= 2
    # session frames -> take frames through the suit's device clock (the take's own)
    src = tk.meta["source_time"]
    assert np.allclose(np.diff(src), 1 / take.frame_rate, atol=2e-5)
    to_take = [int(round(src[c.frame] * take.frame_rate)) for c in sent]
    # cut times are on the take's clock although the frames arrived 4x faster
    t0 = float(tk.meta["recv_time"][0]) - float(tk.meta["header"]["start_monotonic"])
    for c in sent:
        assert c.time == pytest.approx(src[c.frame] + t0, abs=0.02), (c.time, src[c.frame])
    wide = widen(lt.transitions, int(round(0.5 * take.frame_rate)))
    f1_suit = score(to_take, wide).f1
    cfg_online, _ = live_config(methods=["contrast"])
    f1_online = score([c.boundary for c in live_cuts(take, cfg_online)["contrast"]], wide).f1
    assert abs(f1_suit - f1_online) <= 0.1, (f1_suit, f1_online, to_take)
    assert f1_suit >= 0.8
