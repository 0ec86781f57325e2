"""``--faults dropout=SENSOR:...`` naming a sensor or bone the simulator does not have is
refused when the simulator is built (one line, exit 2 through the CLI) - it used to be
accepted and silence nothing, so the run looked fault-free - and a dropout that works is
counted in the serial simulator's summary."""

from __future__ import annotations

import os
import re
import threading
import time

import pytest

from rtseg.cli import main
from rtseg.simulators.faults import Dropout, FaultConfig, FaultInjector
from rtseg.simulators.synth.motion import synthesize

BONES = ("Hips, Spine, Chest, Neck, Head, LeftUpperArm, LeftLowerArm, LeftHand, "
         "RightUpperArm, RightLowerArm, RightHand, LeftUpperLeg, LeftLowerLeg, LeftFoot, "
         "RightUpperLeg, RightLowerLeg, RightFoot")


@pytest.fixture(scope="module")
def take():
    return synthesize("idle:2", seed=0).take


# ----------------------------------------------------------------------------- the CLI

@pytest.mark.parametrize("device, target, line", [
    ("serial", "99", "fault dropout=99:1:2: no sensor 99 in suit default17; "
                     f"valid: ids 0..16 or names {BONES}"),
    ("serial", "Nope", "fault dropout=Nope:1:2: no sensor 'Nope' in suit default17; "
                       f"valid: ids 0..16 or names {BONES}"),
    ("vmc", "99", "fault dropout=99:1:2: no bone 99 in the bones sent for suit default17; "
                  f"valid: indices 0..16 or names {BONES}"),
    ("vmc", "Nope", "fault dropout=Nope:1:2: no bone 'Nope' in the bones sent for suit "
                    f"default17; valid: indices 0..16 or names {BONES}"),
], ids=["serial-id", "serial-name", "vmc-index", "vmc-name"])
def test_unknown_dropout_target_is_refused_in_one_line(device, target, line, tmp_path, capsys):
    where = (["--link", str(tmp_path / "tty_d")] if device == "serial"
             else ["--port", "19991"])
    t0 = time.monotonic()
    rc = main(["simulate", device, "--synth", "idle:2", *where,
               "--faults", f"dropout={target}:1:2", "--duration", "5"])
    out, err = capsys.readouterr()
    assert rc == 2, (out, err)
    assert err == f"rtseg simulate: error: {line}\n"
    assert "Traceback" not in out + err and "sent " not in out
    assert time.monotonic() - t0 < 4.5            # refused at once, not after --duration
    assert not (tmp_path / "tty_d").exists()      # no device was made


def test_unknown_target_among_valid_ones_is_named(tmp_path, capsys):
    """Several dropouts: the one that does not exist is the one named; names are matched
    case-insensitively, as the devices do."""
    rc = main(["simulate", "serial", "--synth", "idle:2", "--link", str(tmp_path / "d"),
               "--faults", "dropout=lefthand:1:1,dropout=5:1:1,dropout=17:0:1:3,seed=2",
               "--duration", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.splitlines()) == 1
    assert "fault dropout=17:0:1:3: no sensor 17 in suit default17" in err


def test_vmc_bone_index_counts_the_bones_sent(take):
    """VMC targets are bone names or indices among the bones sent (``bone_names``)."""
    from rtseg.simulators.vmc_sender import VmcSender
    sender = VmcSender(take, "127.0.0.1", 9, faults="dropout=16:0:1,dropout=righthand:0:1")
    assert sender._silent_bones(0.5) == {16, sender.bone_names.index("RightHand")}
    with pytest.raises(ValueError, match=r"no bone 17 in the bones sent"):
        VmcSender(take, "127.0.0.1", 9, faults="dropout=17:0:1")
    with pytest.raises(ValueError, match=r"no bone 'LeftWing' in the bones sent"):
        VmcSender(take, "127.0.0.1", 9, faults=FaultConfig.parse("dropout=LeftWing:0:1"))


def test_serial_suit_refuses_unknown_targets_of_a_shared_injector(take, tmp_path):
    from rtseg.simulators.serial_device import SerialSuit
    with pytest.raises(ValueError, match=r"^fault dropout=Tail:0:1: no sensor 'Tail' in suit"):
        SerialSuit(take, faults=FaultInjector("dropout=Tail:0:1"), link=tmp_path / "d")
    assert not (tmp_path / "d").exists()


def test_check_dropout_targets_lists_sparse_ids():
    from rtseg.simulators.faults import check_dropout_targets
    cfg = FaultConfig(dropouts=[Dropout(3, 0.0, 1.0)])
    with pytest.raises(ValueError) as ei:
        check_dropout_targets(cfg, [1, 4, 9], ["A", "B", "C"], where="suit x")
    assert str(ei.value) == ("fault dropout=3:0:1: no sensor 3 in suit x; "
                             "valid: ids 1, 4, 9 or names A, B, C")
    check_dropout_targets(cfg, [3], [])                        # known: no error
    check_dropout_targets(FaultConfig(), [], [])               # no dropout: nothing to check
    check_dropout_targets(None, [], [])


# ----------------------------------------------------------------------------- a dropout that works

def test_serial_dropout_silences_the_sensor_and_records_it(take, tmp_path):
    from rtseg.simulators.serial_device import SerialSuit
    suit = SerialSuit(take, faults="dropout=LeftHand:0.2:0.5,dropout=3:1:0.25",
                      link=tmp_path / "d")
    hand = suit.suit.bones.index("LeftHand")
    lh = int(suit.sensor_ids[hand])
    _, ids, silenced = suit._encode(0, 0, 60)               # 0.5 s: LeftHand out
    assert silenced == (lh,) and lh not in ids and len(ids) == 16
    _, ids, silenced = suit._encode(0, 0, 130)              # 1.08 s: sensor 3 out
    assert silenced == (3,) and 3 not in ids and lh in ids
    _, ids, silenced = suit._encode(0, 0, 100)              # 0.83 s: none
    assert silenced == () and len(ids) == 17


def _read_port(link, stop: threading.Event) -> None:
    """A reader that opens the pty (so the suit starts) and drains it until the end."""
    import serial
    deadline = time.monotonic() + 20.0
    while not os.path.lexists(link) and time.monotonic() < deadline and not stop.is_set():
        time.sleep(0.01)
    try:
        port = serial.Serial(str(link), timeout=0.05)
    except (OSError, serial.SerialException):
        return
    try:
        while not stop.is_set():
            try:
                port.read(4096)
            except (OSError, serial.SerialException):
                return
    finally:
        port.close()


def _simulate_serial_read(link, faults: str) -> int:
    """``rtseg simulate serial`` of 2 s of idle with ``faults``, its pty read meanwhile by
    ``_read_port``; the exit status."""
    stop = threading.Event()
    reader = threading.Thread(target=_read_port, args=(link, stop), daemon=True)
    reader.start()
    try:
        return main(["simulate", "serial", "--synth", "idle:2", "--link", str(link),
                     "--speed", "4", "--linger", "0", "--faults", faults])
    finally:
        stop.set()
        reader.join(5.0)


@pytest.mark.parametrize("target", ["LeftHand", "7"])
def test_serial_summary_counts_the_frames_with_a_dropout(target, tmp_path, capsys):
    rc = _simulate_serial_read(tmp_path / "tty_d", f"dropout={target}:0.2:0.5")
    out, err = capsys.readouterr()
    assert rc == 0, err
    d = Dropout(target, 0.2, 0.5)
    expected = sum(d.active(k / 120.0) for k in range(240))   # frames 24..83
    assert 59 <= expected <= 61
    m = re.search(r"^sent 240 frame messages in [\d.]+ s \(([^)]*)\); (\d+) with a sensor "
                  r"dropout; \d+ device-info messages", out, re.M)
    assert m, out
    assert int(m[2]) == expected


def test_serial_summary_without_dropouts_says_nothing_of_them(tmp_path, capsys):
    rc = _simulate_serial_read(tmp_path / "tty_d", "seed=1")
    out = capsys.readouterr().out
    assert rc == 0
    assert re.search(r"^sent 240 frame messages in [\d.]+ s \(240 intact\); \d+ device-info",
                     out, re.M), out
    assert "dropout" not in out
