"""A take replayed at ``speed=0`` ("as fast as read") waits for the processing instead of
outrunning it (backpressure, ``rtseg.live.intake``): every frame is processed, none is
overwritten in the ring or dropped as late, and the cuts are the offline ones of the same
take (``rtseg segment --method contrast``), however slow the processing.

Before, the reader thread read the take ~50 times faster than the loop processed it: the
ring was lapped (frames "overwritten before use", a detector restart, a source-clock jump)
and the cuts depended on the machine's load."""

from __future__ import annotations

import json
import re

import pytest

from rtseg.cli import main
from rtseg.drivers.readers import write_take
from rtseg.live.config import from_dict
from rtseg.live.intake import BACKPRESSURE_FRAMES
from rtseg.live.session import LiveSession
from rtseg.simulators.synth.motion import synthesize

SCRIPT = "idle:3,walk:5,punch:5,squat:5,wave:4"
CMU_86_01 = [452, 1143, 1933, 2494, 3271, 4052]     # rtseg segment --method contrast


@pytest.fixture(scope="module")
def take_file(tmp_path_factory):
    """A synthetic take written as .npz: (path, frames)."""
    result = synthesize(SCRIPT, seed=3)
    path = tmp_path_factory.mktemp("speed0") / "take.npz"
    write_take(path, result.take)
    return path, result.take.n_frames


def offline_cuts(capsys, path) -> list[int]:
    """The cut frames of ``rtseg segment PATH --method contrast``."""
    capsys.readouterr()
    assert main(["segment", str(path), "--method", "contrast", "--format", "json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    return [c["frame"] for c in doc["methods"]["contrast"]["cuts"]]


@pytest.mark.parametrize("max_lag", [0.0, 0.1])
def test_speed0_replay_processes_every_frame_and_cuts_as_offline(take_file, busy_core,
                                                                 capsys, max_lag):
    path, n = take_file
    expected = offline_cuts(capsys, path)
    assert len(expected) >= 3
    # a small ring and a slow pipeline (busy_core: 0.5 ms more a frame): without
    # backpressure the reader laps these 64 frames at once.  The shipped calibration pose
    # (a local-space take measured from its first 0.25 s), as rtseg segment uses it too
    cfg = from_dict({"output": {"osc": []}, "detectors": {"methods": ["contrast"]},
                     "buffer": {"capacity": 64, "max_lag_seconds": max_lag}}, origin="test")
    cuts = []
    session = LiveSession(f"file://{path}?speed=0", cfg, handle_signals=False,
                          listeners=[lambda ev: cuts.append(ev)
                                     if type(ev).__name__ == "CutEvent" else None])
    summary = session.run()
    st = session.stats
    assert session.stop_reason == "end of source"
    assert summary.frames_received == n and summary.frames_processed == n
    assert st.overruns == 0 and st.overload_drops == 0 and summary.dropped == 0
    assert session.pipeline.stats.restarts == 0 and session.pipeline.stats.gap_frames == 0
    assert session.clock.segments == 0            # the source clock was followed throughout
    assert st.max_backlog <= min(BACKPRESSURE_FRAMES, 64 // 2)
    assert [c.frame for c in cuts if c.method == "contrast"] == expected
    # session seconds on the take's clock: each cut's time is its frame's (plus the
    # first frame's arrival)
    t0 = cuts[0].time - expected[0] / 120.0
    for c in cuts:
        assert c.time == pytest.approx(t0 + c.frame / 120.0, abs=1e-6)


def test_speed0_replay_stops_while_the_reader_waits(take_file, busy_core):
    """A session stopped (duration) while its reader waits for room ends promptly."""
    path, n = take_file
    cfg = from_dict({"output": {"osc": []}, "detectors": {"methods": ["contrast"]},
                     "buffer": {"capacity": 64}}, origin="test")
    session = LiveSession(f"file://{path}?speed=0", cfg, handle_signals=False,
                          duration=0.3)
    summary = session.run()
    assert session.stop_reason == "duration reached"
    assert 0 < summary.frames_processed < n
    assert summary.frames_received - summary.frames_processed <= 64 // 2
    assert summary.dropped == 0
    assert session._reader_thread is not None and not session._reader_thread.is_alive()


def _cli_cut_frames(out: str) -> list[int]:
    return [int(m) for m in re.findall(r"^cut #\d+\s+contrast\b.*?\bframe (\d+)", out, re.M)]


@pytest.mark.realdata
@pytest.mark.parametrize("extra", [["--max-lag", "0"], []])
def test_86_01_at_speed0_cuts_as_offline(data_dir, capsys, extra):
    take = data_dir / "cmu" / "86_01.amc"
    expected = offline_cuts(capsys, take)
    assert expected == CMU_86_01
    rc = main(["live", f"file://{take}?speed=0", "--no-osc", *extra])
    out, err = capsys.readouterr()
    assert rc == 0, err
    assert _cli_cut_frames(out) == expected, (out, err)
    assert "overwritten" not in err and "source clock jumped" not in err
    assert "4579 frames received" in err and "4579 processed, 0 dropped" in err, err
