"""Detector parameter files chosen on the command line: ``--params FILE`` or a shipped one
by name (``fast``: config/fast.toml) for ``rtseg live``, the parameters a recording keeps,
and the warning when a recording is segmented with others.  The real CLI in-process on
``sim://synth``."""

from __future__ import annotations

import json
import logging

import pytest

from rtseg.cli import build_parser, main
from rtseg.commands.live import config_from_args
from rtseg.config import config_dir
from rtseg.detectors import load_params
from rtseg.live.detector_setup import detector_params


def run(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_a_missing_parameter_path_is_a_parameter_file_everywhere(capsys, tmp_path):
    missing = tmp_path / "nope.toml"
    for argv in (["live", "sim://synth?stop=1", "--no-osc", "--quiet"], ["segment", missing]):
        rc, _, err = run(capsys, *argv, "--params", missing)
        assert rc == 2 and f"parameter file not found: {missing}" in err, err


def test_params_names_a_missing_file_or_shipped_name(capsys):
    rc, _, err = run(capsys, "live", "sim://synth", "--params", "nosuch", "--duration", "1",
                     "--no-osc", "--quiet")
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err
    assert "parameter file not found: nosuch" in lines[0]
    assert "no shipped nosuch.toml" in lines[0]


def test_params_prompt_says_the_defaults_are_that_set(capsys):
    """``prompt`` was a shipped set until the defaults became it: one line saying so, for
    the live loop and offline; the replacing ``full`` is shipped."""
    for argv in (["live", "sim://synth", "--duration", "1", "--no-osc", "--quiet"],
                 ["segment", "sim://synth"]):
        rc, _, err = run(capsys, *argv, "--params", "prompt")
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and "Traceback" not in err, err
        assert "'prompt' is no longer shipped" in lines[0] and "'full'" in lines[0]
    full = load_params("full")["contrast"]
    assert full["confirm_reach_s"] == 0 and full["pre_after_s"] == 0


def test_params_fast_reaches_the_session_configuration():
    args = build_parser().parse_args(["live", "sim://synth", "--params", "fast"])
    p = detector_params(config_from_args(args))["contrast"]
    assert p == load_params("fast")["contrast"]
    assert p["pre_after_s"] == 1.5 and p != load_params()["contrast"]


def test_recording_keeps_its_parameters_and_segment_says_when_they_differ(capsys, tmp_path,
                                                                          caplog):
    rec = tmp_path / "rec"
    caplog.set_level(logging.INFO, logger="rtseg")
    rc, _, err = run(capsys, "live", "sim://synth?stop=10&speed=0", "--params", "fast",
                     "--no-osc", "--quiet", "--record", rec)
    assert rc == 0, err
    assert any("detector parameters:" in r.getMessage() and "fast.toml" in r.getMessage()
               for r in caplog.records)
    meta = json.loads((rec / "session.json").read_text())["meta"]
    assert meta["detector_params"]["contrast"] == load_params("fast")["contrast"]
    # segmented with the defaults: one warning naming what differs
    rc, out, err = run(capsys, "segment", rec, "--method", "contrast")
    assert rc == 0 and "contrast gate_threshold = 4.0 (now 3.5)" in err
    assert "contrast hold_s = 1.0 (now 2.0)" in err and "and 1 more" in err   # pre_level
    assert "ran its detectors with other parameters" in err
    assert f"give --params {rec} to cut as it did" in err
    # with the session's own, named or read from the recording itself: no warning, one result
    outs = []
    for given in ("fast", rec, rec / "session.json"):
        rc, out, err = run(capsys, "segment", rec, "--method", "contrast", "--params", given,
                           "--format", "json")
        assert rc == 0 and "other parameters" not in err, err
        outs.append(json.loads(out)["methods"]["contrast"]["cuts"])
    assert outs[0] and outs[0] == outs[1] == outs[2]
    assert load_params(rec)["contrast"] == load_params("fast")["contrast"]
    # a recording that does not keep them (an older rtseg's): one line saying so
    doc = json.loads((rec / "session.json").read_text())
    del doc["meta"]["detector_params"]
    old = tmp_path / "old"
    old.mkdir()
    (old / "session.json").write_text(json.dumps(doc))
    rc, _, err = run(capsys, "segment", rec, "--params", old)
    assert rc == 2 and len(err.strip().splitlines()) == 1
    assert "does not keep the parameters its detectors ran with" in err


def test_a_pre_look_no_shorter_than_the_full_look_is_refused(capsys, tmp_path):
    p = tmp_path / "p.toml"
    for text, says in (("confirm_reach_s = 1.0\npre_after_s = 2.0\n",
                        "pre_after_s (2.0) must be shorter than after_s (2.0)"),
                       ("confirm_reach_s = 0.0\npre_after_s = 1.5\n",
                        "pre_after_s (1.5) needs confirm_reach_s > 0")):
        p.write_text("[contrast]\n" + text)
        rc, _, err = run(capsys, "live", "sim://synth?stop=1", "--params", p, "--no-osc",
                         "--quiet")
        assert rc == 2 and len(err.strip().splitlines()) == 1, err
        assert says in err, err


def test_a_file_with_the_removed_early_look_on_is_refused_off_is_read(tmp_path):
    """Files written before the early look was removed: its keys with it off (every
    recording of the defaults) still load; with it on, one error naming what replaces it."""
    from rtseg.config import ConfigError
    p = tmp_path / "old.toml"
    p.write_text("[contrast]\nearly_after_s = 0.0\nearly_threshold = 1.5\nthreshold = 1.3\n")
    assert load_params(p)["contrast"]["threshold"] == 1.3
    assert "early_after_s" not in load_params(p)["contrast"]
    p.write_text("[contrast]\nearly_after_s = 1.5\n")
    with pytest.raises(ConfigError, match="early look was removed.*pre_after_s"):
        load_params(p)


def test_a_folder_named_fast_does_not_hide_the_shipped_file(capsys, tmp_path, monkeypatch):
    """A recording made with ``--record fast`` leaves a folder ``fast`` here (or beside a
    configuration file): ``--params fast`` / ``params = "fast"`` still name
    config/fast.toml (a folder is no parameter file); a file named ``fast`` still wins."""
    from rtseg.config import config_dir, find_config
    from rtseg.live.config import load_session_config
    monkeypatch.chdir(tmp_path)
    (tmp_path / "fast").mkdir()
    assert find_config("fast") == config_dir() / "fast.toml"
    assert load_params("fast")["contrast"]["pre_after_s"] == 1.5
    cfg_file = tmp_path / "show.toml"
    cfg_file.write_text('[detectors]\nparams = "fast"\n')
    cfg = load_session_config(cfg_file)
    assert detector_params(cfg)["contrast"]["pre_after_s"] == 1.5
    rc, _, err = run(capsys, "live", "sim://synth?stop=0.5&speed=0", "--params", "fast",
                     "--no-osc", "--quiet")
    assert rc == 0, err
    (tmp_path / "fast").rmdir()
    (tmp_path / "fast").write_text("[contrast]\nthreshold = 9.0\n")
    assert load_params("fast")["contrast"]["threshold"] == 9.0


@pytest.mark.parametrize("stop", [1.5, 0.3])
def test_live_console_shows_the_features_and_the_parameter_file(capsys, stop):
    """Both start lines reach the console before the first status line: the parameter file
    used to replace the features line (one banner kept, the last); a session that ends
    before its first status line (0.3 s) shows them at its end, before its summary."""
    rc, _, err = run(capsys, "live", f"sim://synth?stop={stop}", "--params", "fast", "--no-osc")
    assert rc == 0, err
    assert "rtseg live: features: " in err
    assert "rtseg live: detector parameters: " in err and "fast.toml" in err
    assert err.index("detector parameters") < err.index("session ended")


def test_empty_params_is_one_usage_error_everywhere(capsys, tmp_path):
    """``--params ""`` (an unset shell variable): segment used to fail with '[Errno 21] Is
    a directory', live and evaluate --online ran the defaults silently.  Now each refuses
    it in one line, exit 2."""
    take = tmp_path / "t.npz"
    for argv in (["segment", take], ["live", "sim://synth?stop=0.5&speed=0", "--no-osc"],
                 ["evaluate", tmp_path, "--online"]):
        rc, out, err = run(capsys, *argv, "--params", "")
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and "Traceback" not in err, (argv, err)
        assert "argument --params" in lines[0] and "'fast'" in lines[0]


def test_a_flat_file_in_live_says_to_use_a_method_table(capsys, tmp_path):
    """rtseg segment reads a flat parameter file; live and evaluate --online read one table
    per method and said 'unknown section [threshold]' of a flat one.  Now one line
    naming the key and the table to put it in, exit 2, for TOML and JSON."""
    (tmp_path / "flat.toml").write_text("threshold = 1.5\n")
    (tmp_path / "flat.json").write_text('{"threshold": 1.5}')
    for name in ("flat.toml", "flat.json"):
        for argv in (["live", "sim://synth?stop=0.5&speed=0", "--no-osc", "--quiet"],
                     ["evaluate", tmp_path, "--online"]):
            rc, _, err = run(capsys, *argv, "--params", tmp_path / name)
            lines = err.strip().splitlines()
            assert rc == 2 and len(lines) == 1 and "Traceback" not in err, (argv, err)
            assert "threshold = 1.5 is not in a method table" in lines[0]
            assert "[contrast]" in lines[0] and "unknown section" not in lines[0]
    take = tmp_path / "t.npz"
    from rtseg.drivers.readers import write_take
    from rtseg.simulators.synth.motion import synthesize
    write_take(take, synthesize("idle:4,walk:4", seed=1).take)
    rc, out, err = run(capsys, "segment", take, "--method", "contrast",
                       "--params", tmp_path / "flat.toml")
    assert rc == 0, err


def test_segment_of_several_recordings_says_which_ran_other_parameters(capsys, tmp_path):
    """The archive path (several takes, or --out) used to drop the warning one recording
    gets: its records now carry params_differ and one warning names the sessions."""
    for name, extra in (("fastrec", ["--params", "fast"]), ("plain", [])):
        rc, _, err = run(capsys, "live", "sim://synth?stop=1.5&speed=0", *extra,
                         "--no-osc", "--quiet", "--record", tmp_path / name)
        assert rc == 0, err
    out = tmp_path / "x.jsonl"
    rc, _, err = run(capsys, "segment", tmp_path / "fastrec", tmp_path / "plain",
                     "--method", "contrast", "--out", out, "--no-progress")
    assert rc == 0, err
    recs = {r["take"]: r for r in map(json.loads, out.read_text().splitlines())}
    assert "pre_level = 4.0 (now 6.0)" in recs["fastrec"]["params_differ"]
    assert "params_differ" not in recs["plain"]
    assert "1 recorded session(s) ran their detectors with other parameters: fastrec" in err
    # with fast: the session recorded with the defaults is the one named
    rc, stdout, err = run(capsys, "segment", tmp_path / "fastrec", tmp_path / "plain",
                          "--method", "contrast", "--params", "fast", "--no-progress")
    recs = {r["take"]: r for r in map(json.loads, stdout.splitlines())}
    assert rc == 0 and "1 recorded session(s)" in err and "parameters: plain;" in err
    assert "params_differ" not in recs["fastrec"] and "params_differ" in recs["plain"]


def test_lopo_checks_its_params_before_reading_the_data(tmp_path):
    """benchmarks/lopo.py --params read the file only after the data (minutes of splicing)
    and ended in a traceback; now a bad name is one line, exit 2, first."""
    import subprocess
    import sys
    from pathlib import Path
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "lopo.py"
    r = subprocess.run([sys.executable, str(script), str(tmp_path), "--params", "nosuch"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip() == ("lopo: parameter file not found: nosuch (no such file "
                                f"here, and no shipped nosuch.toml in {config_dir()})")


def test_replay_session_cuts_with_the_parameters_the_session_ran_with(capsys, tmp_path):
    """``rtseg.live.replay.replay_session`` of a recording made with ``--params fast``
    gives the cuts the session sent (boundary and detecting frame), not those of the
    full look (``--params full``, which detects later); a configuration given still wins."""
    from rtseg.evaluation.online import live_config
    from rtseg.live.replay import replay_session
    from rtseg.recording import read_session
    rec = tmp_path / "rec"
    rc, _, err = run(capsys, "live", "sim://synth?stop=30&speed=0", "--params", "fast",
                     "--no-osc", "--quiet", "--record", rec)
    assert rc == 0, err
    sent = [(c.frame, c.detected_frame) for c in read_session(rec).meta["cuts"]
            if c.wire and c.method == "contrast"]
    assert len(sent) >= 3
    assert [(c.boundary, c.detected) for c in replay_session(str(rec))] == sent
    full = [(c.boundary, c.detected)
            for c in replay_session(str(rec), live_config(None, None, "full")[0])]
    assert full != sent
