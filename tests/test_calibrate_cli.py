"""``rtseg calibrate`` as a technician runs it: what it refuses (one line on stderr, exit
status 2, before the performer has calibrated for nothing), Ctrl-C (130, no traceback),
the ``rtseg live`` command it prints (pasted into a shell it reads the calibration, whatever
the file's name)."""

from __future__ import annotations

import shlex

import pytest

from rtseg.cli import main


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
