"""Errors at start: one clear line on stderr, exit status 2, never a traceback.
Every case runs the real CLI in-process (``rtseg.cli.main``); sessions that do start read
``sim://synth`` for a fraction of a second.  A property-based test throws random values at
every ``rtseg live`` option and configuration key."""

from __future__ import annotations

import json
import logging
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from rtseg.cli import main
from rtseg.live.config import SCHEMA


def run(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def assert_one_line_error(rc: int, err: str, *fragments: str) -> str:
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err[:2000]
    assert len(lines[0]) < 500, lines[0][:600]
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


def live(capsys, *argv: str) -> tuple[int, str, str]:
    return run(capsys, "live", *argv, "--no-osc", "--quiet")


def write_config(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "live.toml"
    p.write_text(text)
    return p


# ------------------------------------------------------------------------ sources

@pytest.mark.parametrize("bad", ["a b=sim://synth", "x.y=sim://synth"])
def test_a_source_name_that_is_not_one_is_named_as_such(capsys, bad):
    rc, _, err = live(capsys, bad, "--duration", "1")
    assert_one_line_error(rc, err, f"source {bad!r}: a source name (NAME=URL) is letters")


def test_a_bad_url_of_one_of_several_sources_names_that_source(capsys):
    # two sim:// sources, one bad: the line said only "sim:// option rate='abc'"
    rc, _, err = live(capsys, "a=sim://synth?stop=0.2&speed=0", "b=sim://synth?rate=abc",
                      "--duration", "1")
    assert_one_line_error(rc, err, "rtseg live: b: sim:// option rate='abc'")


def test_serial_baud_too_large(capsys):
    rc, _, err = live(capsys, "serial:///dev/ptmx?baud=12345678901234567890", "--duration", "1")
    assert_one_line_error(rc, err, "baud=12345678901234567890", "out of range")


@pytest.mark.parametrize("opt", ["stale=nan", "rate=inf", "queue=0", "backoff=-1", "baud=x"])
def test_serial_bad_numeric_options(capsys, opt):
    rc, _, err = live(capsys, f"serial:///dev/ptmx?{opt}", "--duration", "1")
    assert_one_line_error(rc, err, opt.split("=")[0])


def test_serial_device_that_is_not_a_serial_port(capsys):
    rc, _, err = live(capsys, "serial:///dev/null", "--duration", "1")
    line = assert_one_line_error(rc, err, "/dev/null", "not a serial port")
    assert "wait=1" not in line      # waiting would not help


def test_vrchat_url_gets_no_suit_option(capsys):
    rc, _, err = live(capsys, "osc://127.0.0.1:0?format=vrchat", "--duration", "0.3")
    assert rc == 0, err
    assert "unknown option" not in err


# ------------------------------------------------------------------------ configuration

@pytest.mark.parametrize("text, fragments", [
    ("[buffer]\ncapacity = 10000000000\n", ("buffer.capacity", "10000000000")),
    ("[status]\ninterval = nan\n", ("status.interval", "finite")),
    ("[status]\ninterval = inf\n", ("status.interval", "finite")),
    ('[features]\nprofile = "nope"\n', ("features.profile", "unknown skeleton profile 'nope'",
                                        "cmu14")),
    ("[gaps]\nmax_frames = 99999999999999\n", ("gaps.max_frames",)),
    ("[buffer\n", ("invalid TOML",)),
])
def test_bad_configuration_values(capsys, tmp_path, text, fragments):
    cfg = write_config(tmp_path, text)
    rc, _, err = live(capsys, "sim://synth", "--config", cfg, "--duration", "1")
    line = assert_one_line_error(rc, err, *fragments)
    assert '"unknown' not in line        # not a KeyError repr


def test_library_in_config_without_enabled_turns_identity_on(capsys, tmp_path):
    """``[identity] behaviours = "LIB"`` is ``--behaviours LIB`` (docs/identity.md): it
    turned nothing on without ``enabled = true``, so a library that was not there was
    ignored and the session ran without names (exit 0).  Now it is read, and a missing one
    is one line, exit 2; ``enabled = false`` written beside it still keeps identity off."""
    from rtseg.live.config import load_session_config
    cfg = write_config(tmp_path, '[identity]\nbehaviours = "nope.json"\n')
    assert load_session_config(cfg)["identity.enabled"]
    rc, _, err = live(capsys, "sim://synth", "--config", cfg, "--duration", "0.3")
    assert_one_line_error(rc, err, "nope.json", "cannot read")
    cfg.write_text('[identity]\nenabled = false\nbehaviours = "nope.json"\n')
    assert not load_session_config(cfg)["identity.enabled"]
    cfg.write_text('[identity]\nthreshold = 4.5\n')
    assert not load_session_config(cfg)["identity.enabled"]


def test_files_saved_with_a_byte_order_mark_are_read(capsys, tmp_path):
    """A configuration or parameter file saved as "UTF-8 with BOM" (Windows Notepad) was
    "invalid TOML: Invalid statement (at line 1, column 1)"; the mark is now skipped, and
    a real error in such a file still names its key."""
    from rtseg.live.config import load_session_config
    from rtseg.detectors.segmentation import load_params
    bom = b"\xef\xbb\xbf"
    cfg = tmp_path / "live.toml"
    cfg.write_bytes(bom + b"[status]\ninterval = 2.5\n")
    assert load_session_config(cfg)["status.interval"] == 2.5
    par = tmp_path / "det.toml"
    par.write_bytes(bom + b"[contrast]\nthreshold = 3.0\n")
    assert load_params(par, "contrast") == {"threshold": 3.0}
    cfg.write_bytes(bom + b"[status]\ninterval = \"x\"\n")
    rc, _, err = live(capsys, "sim://synth", "--config", cfg, "--duration", "0.3")
    assert_one_line_error(rc, err, "status.interval", "expected float")


def test_config_that_is_a_folder(capsys, tmp_path):
    rc, _, err = live(capsys, "sim://synth", "--config", tmp_path, "--duration", "1")
    assert_one_line_error(rc, err, f"{tmp_path} is a folder")
    assert ".toml" not in err


@pytest.mark.parametrize("template", ["/x/{segment:999999999999d}", "/x/{segment:99999999d}",
                                      "/x/{segment:.99999999f}", "/x/{segment:{event}d}"])
def test_template_width_is_bounded(capsys, template):
    rc, _, err = live(capsys, "sim://synth", "--template", template, "--duration", "1")
    assert_one_line_error(rc, err, "--template", template)


def test_template_of_reasonable_width_runs(capsys):
    rc, _, err = run(capsys, "live", "sim://synth", "--template", "/x/{segment:064d}",
                     "--osc", "127.0.0.1:9", "--quiet", "--duration", "0.2")
    assert rc == 0, err


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "soon"])
def test_duration_must_be_positive_and_finite(capsys, value):
    rc, _, err = live(capsys, "sim://synth", f"--duration={value}")
    assert_one_line_error(rc, err, "--duration")


# ------------------------------------------------------------------------ recording

def test_record_folder_that_cannot_be_created(capsys):
    rc, _, err = live(capsys, "sim://synth", "--record", "/proc/nope", "--duration", "1")
    assert_one_line_error(rc, err, "cannot record the session in /proc/nope")
    assert "_status_t" not in err


def test_record_folder_not_empty(capsys, tmp_path):
    (tmp_path / "old.txt").write_text("x")
    rc, _, err = live(capsys, "sim://synth", "--record", tmp_path, "--duration", "1")
    assert_one_line_error(rc, err, str(tmp_path), "not empty")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.txt"]


def test_recording_dir_from_config_that_fails_after_setup(capsys, tmp_path, caplog):
    """recording.dir in the file bypasses --record's check: the session's own setup fails
    after the publishers are built; the shutdown must not trip over the missing loop state
    (the old "'LiveSession' object has no attribute '_status_t'")."""
    cfg = write_config(tmp_path, '[recording]\ndir = "/proc/nope/rec"\n')
    with caplog.at_level(logging.WARNING):
        rc, _, err = live(capsys, "sim://synth", "--config", cfg, "--duration", "1")
    assert_one_line_error(rc, err, "/proc/nope")
    assert not [r for r in caplog.records if "_status_t" in r.getMessage()]


# ------------------------------------------------------------------------ takes

def test_segment_missing_take_is_file_not_found(capsys, tmp_path):
    rc, out, err = run(capsys, "segment", tmp_path / "nonexist.amc")
    assert out == ""
    line = assert_one_line_error(rc, err, "nonexist.amc", "file not found")
    assert "skeleton" not in line


@pytest.mark.parametrize("content, fragment", [
    (b"", "empty file"),
    (bytes(np.random.default_rng(3).integers(0, 256, 300, dtype=np.uint8)), "not a readable .npz"),
    (b"PK\x03\x04" + b"\x00" * 40, "not a readable .npz"),
])
def test_segment_bad_npz_names_the_file(capsys, tmp_path, content, fragment):
    p = tmp_path / "take.npz"
    p.write_bytes(content)
    rc, _, err = run(capsys, "segment", p)
    line = assert_one_line_error(rc, err, str(p), fragment)
    assert "allow_pickle" not in line


BVH_TAKE = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
"""


def test_bvh_with_utf8_bom_is_read(capsys, tmp_path):
    from rtseg.drivers.readers import read_take
    n = 40
    rows = [f"0 0 0 {10 * math.sin(i / 5):.3f} 0 0 {i % 7} 0 0" for i in range(n)]
    text = BVH_TAKE + f"Frames: {n}\nFrame Time: 0.0083333\n" + "\n".join(rows) + "\n"
    plain = tmp_path / "plain.bvh"
    plain.write_text(text, encoding="utf-8")
    bom = tmp_path / "bom.bvh"
    bom.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    a, b = read_take(plain), read_take(bom)
    assert b.joint_names == a.joint_names == ["Hips", "Spine"]
    np.testing.assert_array_equal(a.quats, b.quats)
    # two joints are no humanoid rig: a named profile selects them
    rc, out, err = run(capsys, "segment", bom, "--method", "pca", "--format", "json",
                       "--profile", "all")
    assert rc == 0, err
    assert json.loads(out)["n_frames"] == n


# ------------------------------------------------------------------------ property-based
#
# Random values for every `rtseg live` option and every configuration key.  Values that
# would reach the network or the file system outside the test folder are kept safe: hosts
# are loopback (or unparsable), paths are relative (the test runs in a temporary folder),
# the source is sim://synth or a URL that cannot open anything; a valid --duration is short.

_text = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12)
_safe_rel = _text.filter(lambda s: not s.startswith(("/", "~")) and ".." not in s)
_port = st.one_of(st.integers(-5, 70000).map(str), _text)
_host = st.sampled_from(["127.0.0.1", "", "[::1]", "127.0.0.1.5", "::1"])
_target = st.one_of(st.builds(lambda h, p: f"{h}:{p}", _host, _port), _text)
_spec = st.one_of(_target.map(lambda t: "udp:" + t), _target.map(lambda t: "tcp:" + t),
                  _safe_rel.map(lambda p: "jsonl:" + p),
                  st.builds(lambda p, o: f"udp:127.0.0.1:{p},{o}", _port, _text), _text)
_template = st.one_of(
    _text, st.builds(lambda f, s: f"/cue/{{{f}:{s}}}", st.sampled_from(
        ["segment", "event", "label", "method", "frame"]), _text),
    st.builds(lambda w: f"/x/{{segment:{w}d}}", st.integers(0, 10 ** 15)))
_scalar = st.one_of(st.integers(-(2 ** 63), 2 ** 63 - 1), st.integers(-10, 10),
                    st.floats(allow_nan=True, allow_infinity=True), st.booleans(), _text)
_value = st.one_of(_scalar, st.lists(_text, max_size=3), st.lists(_scalar, max_size=2),
                   st.dictionaries(_text, _scalar, max_size=2))
_url = st.sampled_from(["nope://x", "sim://nope", "serial://", "osc://127.0.0.1:0?format=x",
                        "osc://127.0.0.1:0?queue=0", "osc://127.0.0.1:0?quiet=nan",
                        "osc://127.0.0.1:99999", "file://missing.amc", ""])


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if v != v else ("inf" if v == math.inf else "-inf" if v == -math.inf
                                     else repr(v))
    if isinstance(v, str):
        return json.dumps(v)                     # a TOML basic string
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"


def _key_value(section: str, key: str):
    """A random value for a configuration key, kept safe for the keys that open things."""
    if (section, key) == ("source", "url"):
        return _url
    if (section, key) in (("recording", "dir"), ("output", "jsonl"), ("detectors", "params")):
        return st.one_of(_safe_rel, _value)
    if (section, key) in (("output", "osc"), ("output", "osc_tcp")):
        return st.one_of(st.lists(_target, max_size=2), _value)
    if (section, key) == ("output", "targets"):
        return st.one_of(st.lists(_spec, max_size=2), _value)
    if (section, key) == ("output", "templates"):
        return st.one_of(st.lists(_template, max_size=2), _value)
    return _value


_KEYS = [(s, k) for s, keys in SCHEMA.items() for k in keys]


@st.composite
def _config_text(draw) -> str:
    chosen = draw(st.lists(st.sampled_from(_KEYS), max_size=3, unique=True))
    tables: dict[str, list[str]] = {}
    for section, key in chosen:
        tables.setdefault(section, []).append(f"{key} = {_toml_value(draw(_key_value(section, key)))}")
    if draw(st.booleans()):                               # an unknown key or section
        tables.setdefault(draw(st.sampled_from([*SCHEMA, "nope"])), []).append(
            f"{draw(st.sampled_from(['x', 'capacity2']))} = 1")
    return "".join(f"[{s}]\n" + "\n".join(lines) + "\n" for s, lines in tables.items())


_OPTIONS = {
    "--osc": _target, "--osc-tcp": _target, "--template": _template, "--target": _spec,
    "--jsonl": st.one_of(_safe_rel, st.just("-")), "--record": _safe_rel,
    "--methods": st.one_of(_text, st.sampled_from(["pca", "ppca", "pca,ppca", ",", "gmm"])),
    "--duration": st.one_of(st.floats(0.05, 0.25).map(repr), _text,
                            st.sampled_from(["0", "-1", "nan", "inf", "-inf", "1e400"])),
}


@st.composite
def _argv(draw) -> list[str]:
    argv = ["live"]
    if draw(st.integers(0, 3)):
        argv.append("sim://synth")
    else:
        argv.append(draw(_url))
    for opt in draw(st.lists(st.sampled_from(sorted(_OPTIONS)), max_size=3)):
        argv.append(f"{opt}={draw(_OPTIONS[opt])}")
    if draw(st.booleans()):
        argv.append("--no-osc")
    if not any(a.startswith("--duration=") for a in argv):
        argv.append("--duration=0.15")
    return argv + ["--quiet"]


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(argv=_argv(), config=_config_text())
def test_random_options_and_config_give_a_clean_run_or_one_line(capsys, tmp_path, argv,
                                                                 config):
    os.chdir(tmp_path)      # relative paths (recordings, logs) land in the test folder
    cfg = tmp_path / "random.toml"
    cfg.write_text(config, encoding="utf-8", errors="surrogatepass")
    rc, _, err = run(capsys, *argv, "--config", cfg)
    event(f"exit status {rc}")
    if rc == 0:
        assert "Traceback" not in err, err
        return
    assert_one_line_error(rc, err)


@pytest.fixture(autouse=True)
def _keep_cwd_and_logging():
    """Restore the working folder, and drop the handler ``main()``'s logging.basicConfig
    attached to this test's captured stderr (closed once the test ends)."""
    cwd = os.getcwd()
    root = logging.getLogger()
    before = list(root.handlers)
    yield
    os.chdir(cwd)
    for h in list(root.handlers):
        if h not in before:
            root.removeHandler(h)


@pytest.fixture(scope="module")
def synth_take(tmp_path_factory) -> Path:
    from rtseg.drivers.readers.npz_take import write_npz
    from rtseg.simulators.synth.motion import synthesize
    p = tmp_path_factory.mktemp("take") / "synth.npz"
    write_npz(p, synthesize("idle:2,walk:2", seed=2).take)
    return p


_param_keys = st.sampled_from(["k_sigma", "window", "variant", "min_contrast", "tau", "nope",
                               "k", "threshold"])


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(method=st.sampled_from(["pca", "ppca", "gmm"]),
       fmt=st.sampled_from(["table", "json", "csv"]),
       profile=st.one_of(st.none(), _text, st.sampled_from(["cmu14", "unity", "all"])),
       params=st.one_of(st.none(), st.dictionaries(
           st.sampled_from(["pca", "ppca", "gmm", "x"]),
           st.dictionaries(_param_keys, _scalar, max_size=2), max_size=2)),
       skeleton=st.one_of(st.none(), _safe_rel))
def test_random_segment_options_give_a_clean_run_or_one_line(capsys, tmp_path, synth_take,
                                                             method, fmt, profile, params,
                                                             skeleton):
    os.chdir(tmp_path)
    argv = ["segment", str(synth_take), "--method", method, "--format", fmt]
    if profile is not None:
        argv += ["--profile", profile]
    if skeleton is not None:
        argv += ["--skeleton", skeleton]
    if params is not None:
        p = tmp_path / "params.toml"
        p.write_text("".join(f"[{m}]\n" + "".join(f"{k} = {_toml_value(v)}\n"
                                                   for k, v in table.items())
                             for m, table in params.items()), encoding="utf-8",
                     errors="surrogatepass")
        argv += ["--params", str(p)]
    rc, _, err = run(capsys, *argv)
    event(f"exit status {rc}")
    if rc == 0:
        assert "Traceback" not in err, err
        return
    assert_one_line_error(rc, err)


def test_evaluate_on_a_cmu_folder_points_at_its_parent(capsys, tmp_path):
    """The cmu takes' labels live beside the folder (../labels): evaluating cmu/ alone finds
    none, and the one line says which folder to give."""
    (tmp_path / "cmu").mkdir()
    (tmp_path / "labels").mkdir()
    rc, _, err = run(capsys, "evaluate", tmp_path / "cmu")
    line = assert_one_line_error(rc, err, "no labelled takes found in")
    assert f"give the folder that holds both, {tmp_path}" in line and "'any'" not in line


def test_files_named_in_a_config_file_are_found_beside_it(capsys, tmp_path, monkeypatch):
    """[detectors] params and [identity] behaviours given as relative paths in a
    configuration file are read beside it, whatever the current folder (else from the
    current folder, as before)."""
    from rtseg.live.config import load_session_config
    conf = tmp_path / "conf"
    conf.mkdir()
    (conf / "det.toml").write_text("[contrast]\nthreshold = 1.75\n")
    (conf / "live.toml").write_text('[detectors]\nparams = "det.toml"\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    cfg = load_session_config(conf / "live.toml")
    assert cfg["detectors.params"] == str(conf / "det.toml")
    rc, _, err = live(capsys, "sim://synth", "--config", conf / "live.toml", "--duration", "0.3")
    assert rc == 0, err
    # a file that is not beside it is looked for from the current folder, and named
    (conf / "live.toml").write_text('[detectors]\nparams = "nope.toml"\n')
    rc, _, err = live(capsys, "sim://synth", "--config", conf / "live.toml", "--duration", "0.3")
    assert_one_line_error(rc, err, "detectors.params", "nope.toml")


@pytest.mark.parametrize("argv, fragment", [
    (("--no-osc", "--osc", "127.0.0.1:19998"), "--no-osc and --osc"),
    (("--no-osc", "--template", "/cue/{label}"), "--template: no OSC target"),
])
def test_output_flags_that_contradict_each_other(capsys, argv, fragment):
    rc, _, err = run(capsys, "live", "sim://synth", "--duration", "0.3", "--quiet", *argv)
    assert_one_line_error(rc, err, fragment)


def test_a_folder_of_recorded_sessions_points_at_them(capsys, tmp_path):
    """A session of two named sources records each in DIR/<name>: reading DIR says so."""
    rec = tmp_path / "rec"
    rc, _, err = live(capsys, "a=sim://synth", "b=sim://synth", "--record", rec,
                      "--duration", "0.3")
    assert rc == 0, err
    rc, _, err = run(capsys, "live", f"file://{rec}", "--no-osc", "--quiet")
    line = assert_one_line_error(rc, err, "not a recorded session")
    assert "it holds the sessions of a, b (in rec/<name>): give one" in line
