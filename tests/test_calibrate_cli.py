"""``rtseg calibrate`` as a technician runs it: what it refuses (one line on stderr, exit
status 2, before the performer has calibrated for nothing), Ctrl-C (130, no traceback),
the ``rtseg live`` command it prints (pasted into a shell it reads the calibration, whatever
the file's name), and a suit whose clock runs at another rate than the one declared (over a
real pseudo-terminal)."""

from __future__ import annotations

import shlex

import pytest

from rtseg.cli import main

RAW = "mount=180,up=z,heading=40,seed=5"


def run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.parametrize("url", ["sim://synth", "osc://127.0.0.1:0?format=vmc",
                                 "file://nowhere.bvh"])
def test_a_source_that_is_no_serial_suit_is_refused_in_one_line(url, tmp_path, capsys):
    rc, out, err = run_cli(["calibrate", url, "--out", str(tmp_path / "suit.json")], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert "serial://" in lines[0] and "hold a T-pose" not in err
    assert not (tmp_path / "suit.json").exists()


def test_an_out_file_that_cannot_be_written_is_refused_before_the_suit_is_read(tmp_path, capsys):
    """The device does not exist either: the --out problem is said first, before anyone
    holds a T-pose and squats for a file that could not be written."""
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    for out, says in ((tmp_path / "missing" / "suit.json", "does not exist"),
                      (tmp_path / "afile" / "suit.json", "is not a folder"),
                      (tmp_path / "adir", "is a folder")):
        rc, _, err = run_cli(["calibrate", "serial:///dev/rtseg-no-such-tty", "--out",
                              str(out)], capsys)
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and "--out" in lines[0] and says in lines[0], err
    rc, _, err = run_cli(["calibrate", "serial:///dev/rtseg-no-such-tty", "--out",
                          str(tmp_path / "new.json")], capsys)
    assert rc == 2 and "cannot open serial device" in err
    assert not (tmp_path / "new.json").exists()          # the write check leaves nothing


def test_a_hold_longer_than_the_wait_is_refused(tmp_path, capsys):
    rc, _, err = run_cli(["calibrate", "serial:///dev/rtseg-no-such-tty", "--out",
                          str(tmp_path / "s.json"), "--hold", "5", "--seconds", "3"], capsys)
    assert rc == 2 and "--hold" in err and len(err.strip().splitlines()) == 1


def test_ctrl_c_while_the_commands_load_exits_130_without_a_traceback(monkeypatch):
    import rtseg.cli as cli

    def interrupted():
        raise KeyboardInterrupt
    monkeypatch.setattr(cli, "build_parser", interrupted)
    try:
        rc = cli.main(["calibrate", "--help"])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped rtseg.cli.main: the console shows a traceback")
    assert rc == 130


@pytest.mark.parametrize("out", ["suit.json", "my takes/suit cal.json", "a&b+c #1.json",
                                 "it's $HOME.json"])
def test_the_printed_live_command_reads_the_file_it_names(out):
    from rtseg.commands.calibrate import live_command
    from rtseg.drivers import parse_url
    for source in ("serial:///dev/ttyUSB0", "serial:///dev/ttyUSB0?format=text&baud=115200"):
        argv = shlex.split(live_command(source, out))
        assert argv[:2] == ["rtseg", "live"] and len(argv) == 3
        scheme, location, options = parse_url(argv[2])
        assert (scheme, location, options["calibration"]) == ("serial", "/dev/ttyUSB0", out)
    argv = shlex.split(live_command("serial:///dev/ttyUSB0", out, rate=59.9))
    assert parse_url(argv[2])[2]["rate"] == "60"
    argv = shlex.split(live_command("serial:///dev/ttyUSB0?rate=60", out, rate=59.9))
    assert argv[2].count("rate=") == 1


def test_a_60_hz_suit_read_without_rate_is_calibrated_and_the_command_works(tmp_path, capsys):
    """A 60 Hz suit read as the profile's 120 Hz: the 1 s hold was 120 frames, 2 s of a
    T-pose that drifts, and nothing was found.  The device's clock now times it; the
    printed command (a folder with a space, a '&' in the name) opens with the
    calibration and rate=60."""
    from rtseg.drivers import open_source
    from rtseg.simulators.serial_device import SerialSuit
    from rtseg.simulators.synth.motion import synthesize
    perf = synthesize("tpose:3,squat:4", frame_rate=60.0, seed=0).take
    (tmp_path / "my cal").mkdir()
    out = tmp_path / "my cal" / "suit&1.json"
    suit = SerialSuit(perf, rate=60.0, speed=4.0, imu=RAW)
    link = suit.start()
    try:
        rc, printed, err = run_cli(["calibrate", f"serial://{link}", "--up", "z", "--out",
                                    str(out), "--seconds", "6"], capsys)
    finally:
        suit.stop()
    assert rc == 0, err
    assert "60.0 Hz" in err and "T-pose held at 0.0-1.0 s" in err
    line = next(ln for ln in printed.splitlines() if "use it with:" in ln)
    argv = shlex.split(line.split("use it with:", 1)[1])
    src = open_source(argv[2] + "&wait=1")
    try:
        assert src.calibration is not None and src.frame_rate == 60.0
    finally:
        src.close()


def test_a_failed_capture_says_what_the_input_lost():
    """A capture that found no T-pose on a damaged link says so beside the advice: the
    frames left out for an invalid sensor and the link's losses, from the source's counts."""
    import numpy as np
    from types import SimpleNamespace
    from rtseg.core.frame import Frame
    from rtseg.drivers.base import SourceStats
    from rtseg.live.calibrate import capture
    from rtseg.simulators.synth.skeleton import JOINT_NAMES, PARENTS
    rng = np.random.default_rng(0)
    frames = []
    for i in range(240):                      # 2 s at 120 Hz: never still, the first second
        q = rng.normal(size=(len(JOINT_NAMES), 4))    # without a valid Hips
        valid = np.ones(len(JOINT_NAMES), bool)
        valid[0] = i >= 120
        frames.append(Frame(i / 120.0, q / np.linalg.norm(q, axis=1, keepdims=True), valid,
                            i / 120.0, i))
    stats = SourceStats(dropped=17, corrupt=5)
    t = iter(np.arange(0.0, 10.0, 0.004))
    source = SimpleNamespace(joint_names=JOINT_NAMES, parents=PARENTS, space="global",
                             frame_rate=120.0, stats=stats,
                             read=lambda timeout=None: frames.pop(0) if frames else None)
    got = capture(source, "y", seconds=1.5, clock=lambda: next(t))
    assert got.calibration is None
    assert "hold the T-pose still" in got.reason
    assert "120 of 240 frames had a sensor invalid for more than 0.25 s" in got.reason
    assert "17 frames lost, 5 damaged messages" in got.reason


def test_a_sensor_that_drops_out_briefly_does_not_spoil_the_t_pose():
    """A sensor invalid in every third frame (the source keeps its last good value) is taken
    at that value: the 1 s T-pose and the squat still calibrate; gone for good, it cannot."""
    import numpy as np
    from types import SimpleNamespace
    from rtseg.core import quat
    from rtseg.core.frame import Frame
    from rtseg.live.calibrate import capture
    from rtseg.simulators.retarget import ImuModel
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize("squat:6", frame_rate=120.0, seed=1).take
    g = quat.global_from_local(take.quats, list(take.parents))
    g = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (144, g.shape[1], 1)), g])   # 1.2 s
    raw = ImuModel(mount_deg=180, up="z", heading_deg=30.0, seed=2).apply(g, 120.0)

    def source(gone_after):
        frames, last = [], raw[0].copy()
        for i, q in enumerate(raw):
            valid = np.ones(len(q), bool)
            valid[3] = i % 3 != 0 and i < gone_after
            last[valid] = q[valid]
            frames.append(Frame(i / 120.0, last.copy(), valid, i / 120.0, i))
        return SimpleNamespace(joint_names=take.joint_names, parents=take.parents,
                               space="global", frame_rate=120.0, stats=None,
                               read=lambda timeout=None: frames.pop(0) if frames else None)

    def clock():
        t = iter(np.arange(0.0, 100.0, 0.001))
        return lambda: next(t)
    got = capture(source(len(raw)), "z", seconds=20.0, clock=clock())
    assert got.calibration is not None, got.reason
    assert got.report["t_pose_frames"][1] - got.report["t_pose_frames"][0] == 120
    lost = capture(source(60), "z", seconds=20.0, clock=clock())
    assert lost.calibration is None and "had a sensor invalid" in lost.reason
