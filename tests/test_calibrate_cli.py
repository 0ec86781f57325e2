"""``rtseg calibrate`` as a technician runs it: Ctrl-C (130, no traceback)."""

from __future__ import annotations

import pytest


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
