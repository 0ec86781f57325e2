"""``rtseg plot`` given a folder that is not one take: one line saying what the folder is
and what to give instead, before any label lookup (no "no labels found" first)."""

from __future__ import annotations

import logging

import pytest

from rtseg.cli import main

pytest.importorskip("matplotlib")


def plot(capsys, caplog, *argv) -> tuple[int, list[str], list[str]]:
    """``rtseg plot ARGV``: (exit status, stderr lines, messages logged)."""
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="rtseg"):
        rc = main(["plot", *map(str, argv)])
    return rc, capsys.readouterr().err.strip().splitlines(), caplog.messages


def test_a_folder_of_recorded_sessions_is_named_and_one_of_them_suggested(capsys, caplog,
                                                                          tmp_path):
    rec = tmp_path / "rec"
    rc = main(["live", "a=sim://synth", "b=sim://synth", "--record", str(rec),
               "--duration", "0.3", "--no-osc", "--quiet"])
    assert rc == 0, capsys.readouterr().err
    capsys.readouterr()
    rc, err, logged = plot(capsys, caplog, rec, "-o", tmp_path / "x.png")
    assert rc == 2 and len(err) == 1, err
    assert err[0] == (f"rtseg plot: error: {rec} is a folder of recorded sessions (a, b: "
                      f"rtseg live --record with several sources), not one take: give one "
                      f"of them, e.g. rtseg plot {rec / 'a'}")
    assert not logged, logged                  # no "no labels found" before it
    assert not (tmp_path / "x.png").exists()


def test_a_folder_without_a_session_and_a_missing_take_fail_in_one_line(capsys, caplog,
                                                                        tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    rc, err, logged = plot(capsys, caplog, empty)
    assert rc == 2 and len(err) == 1 and not logged, (err, logged)
    assert err[0].startswith(f"rtseg plot: error: {empty} is a folder but not a recorded "
                             f"session (no session.json in it): give a take file (.amc, ")
    rc, err, logged = plot(capsys, caplog, tmp_path / "missing.amc")
    assert rc == 2 and len(err) == 1 and not logged, (err, logged)
    assert "missing.amc: file not found" in err[0]
