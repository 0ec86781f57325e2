"""Suit calibration (rtseg.core.suit_calibration, rtseg calibrate, serial:// calibration=):
raw IMU orientations - each sensor turned on its segment, a Z-up or Y-up sensor world, any
heading - become segment rotations from a T-pose facing +Z, from a held T-pose and knee
bends; what cannot be calibrated is one line saying why; over a real pseudo-terminal a
session with the calibration names by posture."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rtseg.core import quat
from rtseg.core.suit_calibration import (CalibrationError, SuitCalibration, calibrate,
                                         still_stretch)
from rtseg.simulators.retarget import ImuModel
from rtseg.simulators.synth.motion import synthesize

RATE = 120.0


def degrees_apart(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 2 * np.degrees(np.arccos(np.clip(np.abs(np.sum(a * b, -1)), 0.0, 1.0)))


@pytest.fixture(scope="module")
def performer():
    """(take, global rotations): 1.5 s of an exact T-pose (every rotation the identity,
    facing +Z), then a synthetic performer squatting and walking."""
    take = synthesize("squat:6,walk:4", frame_rate=RATE, seed=1).take
    g = quat.global_from_local(take.quats, list(take.parents))
    still = np.tile(np.array([0.0, 0.0, 0.0, 1.0]), (int(1.5 * RATE), g.shape[1], 1))
    return take, np.concatenate([still, g])


@pytest.mark.parametrize("up, heading", [("z", 40.0), ("z", -100.0), ("y", 170.0), ("y", 0.0)])
def test_raw_orientations_come_back_as_rotations_from_the_t_pose(performer, up, heading):
    take, g = performer
    raw = ImuModel(mount_deg=180, up=up, heading_deg=heading, seed=3).apply(g, RATE)
    assert degrees_apart(raw, g).min() > 1.0          # the sensors' own frames, not the body's
    cal, report = calibrate(raw, take.joint_names, take.parents, RATE, up)
    assert report["t_pose_frames"] == [0, int(RATE)]
    assert abs((report["heading_deg"] - heading + 180) % 360 - 180) < 1.0
    assert np.percentile(degrees_apart(cal.apply(raw), g), 99) < 0.5


def test_a_calibration_is_saved_and_read_back(performer, tmp_path):
    take, g = performer
    raw = ImuModel(mount_deg=90, up="z", heading_deg=25.0, seed=4).apply(g, RATE)
    cal, _ = calibrate(raw, take.joint_names, take.parents, RATE, "z")
    path = tmp_path / "suit.json"
    cal.save(path)
    back = SuitCalibration.load(path)
    assert back.joint_names == cal.joint_names and back.up == "z"
    assert np.abs(back.apply(raw) - cal.apply(raw)).max() < 1e-6
    (tmp_path / "other.json").write_text(json.dumps({"format": "rtseg-behaviour-library"}))
    for bad, message in ((tmp_path / "missing.json", "cannot read"),
                         (tmp_path / "other.json", "not an rtseg suit calibration")):
        with pytest.raises(CalibrationError, match=message):
            SuitCalibration.load(bad)
    with pytest.raises(CalibrationError, match="calibrate it"):
        cal.check_joints(["Hips", "Spine"], "suit x")


def test_a_damaged_calibration_file_is_refused_not_applied(performer, tmp_path):
    """A heading of NaN made every frame NaN (a session of nothing but bad values); a zero
    reference quaternion was silently taken for the identity; an empty calibration= read
    the suit raw.  Each is now one line."""
    from rtseg.drivers import open_source
    from rtseg.drivers.base import SourceError
    take, g = performer
    raw = ImuModel(mount_deg=90, up="z", heading_deg=25.0, seed=4).apply(g, RATE)
    cal, _ = calibrate(raw, take.joint_names, take.parents, RATE, "z")
    doc = cal.as_dict()
    for key, value, says in (("heading_deg", "NaN", "heading_deg must be a finite"),
                             ("heading_deg", float("inf"), "heading_deg must be a finite"),
                             ("reference", [[0.0, 0.0, 0.0, 0.0]] + doc["reference"][1:],
                              "Hips is not a unit quaternion"),
                             ("reference", [[0.0, 0.0, 0.0, 2.0]] + doc["reference"][1:],
                              "Hips is not a unit quaternion")):
        path = tmp_path / "damaged.json"
        path.write_text(json.dumps(dict(doc, **{key: value})))
        with pytest.raises(CalibrationError, match=says):
            SuitCalibration.load(path)
        with pytest.raises(SourceError, match=says):
            open_source(f"serial:///dev/null?calibration={path}")
    with pytest.raises(SourceError, match="calibration= needs a file"):
        open_source("serial:///dev/null?calibration=")


def test_what_cannot_be_calibrated_says_why(performer):
    take, g = performer
    raw = ImuModel(mount_deg=180, up="z", heading_deg=-100.0, seed=3).apply(g, RATE)
    names, parents = take.joint_names, take.parents
    with pytest.raises(CalibrationError, match="hold the T-pose"):
        calibrate(raw[int(1.5 * RATE):], names, parents, RATE, "z")       # no T-pose
    with pytest.raises(CalibrationError, match="bend the knees"):
        calibrate(raw[:int(1.6 * RATE)], names, parents, RATE, "z")       # no knee bends
    with pytest.raises(CalibrationError, match="up axis is not the one given"):
        calibrate(raw, names, parents, RATE, "y")                         # Z-up sensors
    assert still_stretch(raw, RATE, hold_s=2.0) is None                   # held 1.5 s only


def test_rtseg_calibrate_over_a_pty_and_a_session_that_names_by_posture(tmp_path, capsys):
    """A simulated suit of raw sensors (mounted at random, Z up, heading 40) on a real
    pseudo-terminal: ``rtseg calibrate`` records the calibration from its T-pose and squat;
    read with ``calibration=`` its frames are the performer's rotations (parent-relative
    within a few degrees: the simulated T-pose is held about 3 degrees off the ideal one), and a live session with a
    behaviour library names by posture; a calibration of other sensors is refused."""
    from rtseg.cli import main
    from rtseg.drivers import open_source
    from rtseg.drivers.base import SourceError
    from rtseg.evaluation.online import live_config
    from rtseg.library.examples import learn, synthetic_examples
    from rtseg.library.file import save
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    from rtseg.simulators.serial_device import SerialSuit
    perf = synthesize("tpose:3,squat:5,walk:5,punch:5", frame_rate=RATE, seed=1).take
    imu = "mount=180,up=z,heading=40,seed=5"
    cal_path = tmp_path / "suit.json"
    suit = SerialSuit(perf, rate=RATE, speed=4.0, imu=imu)
    link = suit.start()
    try:
        rc = main(["calibrate", f"serial://{link}?rate=120", "--up", "z", "--out",
                   str(cal_path), "--seconds", "20"])
    finally:
        suit.stop()
    out = capsys.readouterr().out
    assert rc == 0 and "calibration=" in out and cal_path.exists()

    truth = quat.local_from_global(SerialSuit(perf, rate=RATE).quats, list(perf.parents))
    cfg0, _ = live_config()
    lib, _ = learn(synthetic_examples(["walk", "squat", "punch"], [3, 4], cfg0, seconds=6.0))
    lib_path = save(lib, tmp_path / "lib.json")
    suit = SerialSuit(perf, rate=RATE, speed=4.0, imu=imu)
    link = suit.start()
    try:
        cfg = from_dict({"output": {"osc": []}, "recording": {"dir": str(tmp_path / "rec")},
                         "identity": {"enabled": True, "behaviours": str(lib_path)}})
        session = LiveSession(f"serial://{link}?rate=120&calibration={cal_path}", cfg,
                              handle_signals=False, duration=perf.n_frames / RATE / 4.0 + 0.6)
        session.run()
    finally:
        suit.stop()
    assert session.pipeline.posture.origin == "source"      # the standard T-pose, facing +Z
    assert session.pipeline.identity.stats.posture_namings >= 1
    from rtseg.recording.reader import read_session
    rec = read_session(tmp_path / "rec")
    # the recording says its frames are calibrated, and with what
    assert rec.meta["session_meta"]["calibration"] == SuitCalibration.load(cal_path).as_dict()
    seq = np.asarray(rec.meta["seq"]) % len(truth)
    local = quat.local_from_global(rec.quats, list(perf.parents))
    err = degrees_apart(local[:, 1:], truth[seq][:, 1:])        # the root's heading aside
    assert np.median(err) < 6.0             # the T-pose held about 3 degrees off the ideal

    bad = SuitCalibration(("a", "b"), np.tile([0.0, 0.0, 0.0, 1.0], (2, 1)), "y", 0.0)
    bad.save(tmp_path / "bad.json")
    with pytest.raises(SourceError, match="calibrate it"):
        open_source(f"serial:///dev/null?calibration={tmp_path / 'bad.json'}")
