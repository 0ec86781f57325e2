"""Named behaviour libraries (rtseg.library.behaviours, rtseg learn, rtseg live --behaviours): the
learn -> file -> load round trip, one-line refusal of another profile / version / garbage,
null rejection on synthetic performances (a behaviour the library never saw comes out
``unknown``), and the names on a real UDP socket from a live session."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtseg.library.file import save as save_library, to_dict as library_dict
from rtseg.evaluation.identity import run_identity
from rtseg.library.behaviours import UNKNOWN, Library, LibraryError
from rtseg.library.builder import LibraryBuilder
from rtseg.library.file import load
from rtseg.library.calibration import separating_rule, separating_threshold
from rtseg.library.examples import label_runs, take_rows
from rtseg.live.session import LiveSession
from rtseg.evaluation.online import live_config
from rtseg.live.config import from_dict
from rtseg.simulators.synth.motion import synthesize

from osc_collector import OscCollector
from take_source import TakeSource
from synth_identity import SYNTH_DETECTOR, SYNTH_THRESHOLD

LEARN = "walk:8,punch:8,squat:8,wave:8"
#: seeds 0 and 4 teach; other seeds (tempo, amplitude, style vary) are named
PERFORMANCE = "walk:6,kick:6,punch:6,jump:6,squat:6"


def _config():
    cfg, _ = live_config()
    cfg["identity.enabled"] = True
    cfg["identity.threshold"] = SYNTH_THRESHOLD
    cfg["detectors.contrast"] = dict(SYNTH_DETECTOR)
    return cfg


def _library(script=LEARN, seeds=(0, 4), metric="model"):
    """A library of every behaviour of ``script`` performed with each of ``seeds`` (each
    seed a performer of its own: tempo, amplitude and style vary)."""
    b = None
    for seed in seeds:
        res = synthesize(script, seed=seed)
        X, idx, profile = take_rows(res.take, _config())
        b = b or LibraryBuilder(profile, X.shape[1], res.take.frame_rate)
        for a, e, name in label_runs(res.frame_names()):
            i, j = np.searchsorted(idx, a), np.searchsorted(idx, e)
            assert b.add(X[i:j], name, f"synth{seed}", info={"person": f"synth{seed}"}) > 0
    return b.build(metric=metric)


@pytest.fixture(scope="module")
def library():
    return _library()


def test_saved_into_a_missing_folder(tmp_path, library):
    """``rtseg learn sets/new/lib.json`` makes the folder, and leaves no temporary file."""
    path = save_library(library, tmp_path / "sets" / "new" / "lib.json")
    assert path.parent.is_dir() and [p.name for p in path.parent.iterdir()] == ["lib.json"]
    assert load(path, library.profile, library.dims).names == library.names


def test_round_trip_through_the_file(tmp_path, library):
    path = save_library(library, tmp_path / "lib.json")
    doc = json.loads(path.read_text())
    assert doc["format"] == "rtseg-behaviour-library" and doc["version"] == 4
    assert doc["metric"] == "model" and len(doc["window_stats"]["n"]) == len(library.names)
    assert doc["profile"] == library.profile and doc["dims"] == library.dims
    back = load(path, library.profile, library.dims)
    assert back.names == library.names and back.behaviour_names == ["punch", "squat",
                                                                    "walk", "wave"]
    assert np.allclose(back.descriptors, library.descriptors, atol=1e-5)
    assert back.threshold == pytest.approx(library.threshold)
    assert back.ratio == pytest.approx(library.ratio) and 0 < back.ratio <= 1
    assert (back.window_s, back.step_s, back.edge_s, back.min_s) == (2.0, 0.5, 0.5, 1.0)
    assert back.examples == library.examples and back.starts == library.starts
    assert back.metric == "model" and back.k_nearest == library.k_nearest == 1
    # the window statistics read back exactly (rtseg.library.distance.stats_to_json): their
    # models' null directions, so the distances, are those of the library learned
    for w, v in zip(back.window_stats, library.window_stats):
        assert w.n == v.n and np.array_equal(w.mean, v.mean)
        assert np.array_equal(w.scatter, v.scatter)
    assert np.array_equal(back.bank.pairwise(), library.bank.pairwise())
    res = synthesize("walk:4", seed=5)
    X, _, _ = take_rows(res.take, _config())
    a, b = library.name(X[120:360]), back.name(X[120:360])
    assert a.name == b.name == "walk" and a.distance == pytest.approx(b.distance, abs=1e-4)


def test_refusals_are_one_clear_line(tmp_path, library):
    path = save_library(library, tmp_path / "lib.json")
    with pytest.raises(LibraryError, match="learned for feature profile 'canonical'.*'cmu14'"):
        load(path, "cmu14", 56)
    doc = json.loads(path.read_text())
    doc["version"] = 99
    (tmp_path / "v99.json").write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match="version 99"):
        load(tmp_path / "v99.json")
    (tmp_path / "garbage.json").write_bytes(b"\x00\x01not json")
    with pytest.raises(LibraryError, match="not a JSON behaviour library"):
        load(tmp_path / "garbage.json")
    doc["version"] = 2
    stats = doc["window_stats"]
    doc["window_stats"] = {k: v[:-1] for k, v in stats.items()}
    (tmp_path / "few_stats.json").write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match="malformed.*window statistics"):
        load(tmp_path / "few_stats.json")
    doc["window_stats"] = stats
    doc["descriptors"] = doc["descriptors"][:-1]
    (tmp_path / "short.json").write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match="malformed"):
        load(tmp_path / "short.json")
    for bad in ("v99.json", "garbage.json", "short.json"):
        p = subprocess.run([sys.executable, "-m", "rtseg.cli", "live", "sim://synth",
                            "--behaviours", str(tmp_path / bad), "--duration", "1"],
                           capture_output=True, text=True, timeout=60)
        assert p.returncode == 2
        assert len(p.stderr.strip().splitlines()) == 1 and "behaviour library" in p.stderr


@pytest.mark.parametrize("key, value, message", [
    ("names", lambda v: [7, *v[1:]], r"names\[0\] must be a string, got 7"),
    ("dims", lambda v: str(v), r'dims must be a whole number, got "48"'),
    ("dims", lambda v: float(v), r"dims must be a whole number, got 48.0"),
    ("frame_rate", lambda v: "120", r'frame_rate must be a number, got "120"'),
    ("frame_rate", lambda v: -120.0, r"frame_rate -120.0 not a positive number"),
    ("sources", lambda v: [True, *v[1:]], r"sources\[0\] must be a whole number, got true"),
    ("scale", lambda v: ["1.0", *v[1:]], r'scale\[0\] must be a number, got "1.0"'),
    ("descriptors", lambda v: [v[0][:-1] + ["x"], *v[1:]],
     r'descriptors\[0\] must be a list of numbers, got \['),
    ("threshold", lambda v: "high", r'threshold must be a number or null, got "high"'),
    ("profile", lambda v: 3, r"profile must be a string, got 3"),
])
def test_a_field_of_the_wrong_type_is_one_clear_line(tmp_path, library, key, value,
                                                      message):
    """A library edited by hand with an int among its names, dims as a string or a frame
    rate that is not a positive number is refused with one line naming the field."""
    doc = json.loads(save_library(library, tmp_path / "lib.json").read_text())
    assert doc["dims"] == 48 and doc["frame_rate"] == 120.0 and doc["window_s"] == 2.0
    doc[key] = value(doc[key])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match=message) as ei:
        load(bad)
    assert str(ei.value).startswith(f"behaviour library {bad}: ")
    assert "\n" not in str(ei.value)


@pytest.mark.parametrize("rate", [120, 60])
def test_a_whole_number_frame_rate_loads_as_a_number(tmp_path, library, caplog, rate):
    """``frame_rate: 120`` (a JSON int where the file writes 120.0) is a number like any
    other: loaded as a float without a word; libraries mix frame rates, so 60 in a library
    learned at 120 Hz loads too."""
    doc = json.loads(save_library(library, tmp_path / "lib.json").read_text())
    doc["frame_rate"] = rate
    path = tmp_path / "int_rate.json"
    path.write_text(json.dumps(doc))
    assert '"frame_rate": %d,' % rate in path.read_text()
    with caplog.at_level("WARNING"):
        back = load(path)
    assert back.frame_rate == float(rate) and isinstance(back.frame_rate, float)
    assert back.names == library.names and not caplog.records


def test_learn_command_and_its_errors(tmp_path):
    from rtseg.drivers.readers import write_take
    res = synthesize("walk:5,punch:5", seed=0)
    take = tmp_path / "t.npz"
    write_take(take, res.take)
    cut = res.segments[0].stop
    lib = tmp_path / "lib.json"
    run = lambda *a: subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", str(lib), *a],
                                    capture_output=True, text=True, timeout=120)
    p = run("--take", str(take), "--label", "walk", "--frames", f"0:{cut}",
            "--take", str(take), "--label", "punch", "--frames", f"{cut}:{res.take.n_frames}")
    assert p.returncode == 0, p.stderr
    assert "2 behaviours, 2 examples" in p.stdout
    assert load(lib).behaviour_names == ["punch", "walk"]
    p = run("--take", str(take), "--label", "walk", "--frames", "50:10")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1
    p = run("--label", "walk")
    assert p.returncode == 2 and "--label must follow a --take" in p.stderr
    lib.write_text('{"format": "something else"}')
    p = run("--take", str(take), "--label", "walk")
    assert p.returncode == 2 and "not a behaviour library" in p.stderr


def test_learn_windows_every_step_and_an_extended_library_keeps_its_own(tmp_path):
    """``--step`` sets how often example windows start (default 0.5 s): consecutive
    windows of one example start 1 s (120 frames) apart with --step 1, 0.5 s apart by
    default; extending keeps the file's step, another one is refused."""
    from rtseg.drivers.readers import write_take
    res = synthesize("walk:5,punch:5", seed=0)
    take = tmp_path / "t.npz"
    write_take(take, res.take)
    cut = res.segments[0].stop
    run = lambda lib, *a: subprocess.run([sys.executable, "-m", "rtseg.cli", "learn",
                                          str(lib), *a], capture_output=True, text=True,
                                         timeout=120)
    walk = ("--take", str(take), "--label", "walk", "--frames", f"0:{cut}")
    punch = ("--take", str(take), "--label", "punch", "--frames", f"{cut}:{res.take.n_frames}")
    fr = res.take.frame_rate

    def spacing(lib, name):
        st = [s for s, n in zip(lib.starts, lib.names) if n == name]
        return set(np.diff(st) / fr), len(st)

    p = run(tmp_path / "one.json", *walk, "--step", "1")
    assert p.returncode == 0, p.stderr
    one = load(tmp_path / "one.json")
    assert one.step_s == 1.0 and spacing(one, "walk")[0] == {1.0}
    p = run(tmp_path / "half.json", *walk)
    assert p.returncode == 0, p.stderr
    half = load(tmp_path / "half.json")
    assert half.step_s == 0.5 and spacing(half, "walk")[0] == {0.5}
    n1, n05 = spacing(one, "walk")[1], spacing(half, "walk")[1]
    assert n05 in (2 * n1 - 1, 2 * n1)
    p = run(tmp_path / "one.json", *punch)                 # extended: its own step
    assert p.returncode == 0, p.stderr
    ext = load(tmp_path / "one.json")
    assert ext.step_s == 1.0 and ext.behaviour_names == ["punch", "walk"]
    assert spacing(ext, "punch")[0] == {1.0} and spacing(ext, "walk") == spacing(one, "walk")
    p = run(tmp_path / "one.json", *punch, "--step", "0.5")
    assert p.returncode == 2 and "windows every 1 s" in p.stderr
    p = run(tmp_path / "bad.json", *walk, "--step", "0")
    assert p.returncode == 2 and "--step" in p.stderr


def _points_library(rows, names, k):
    """A 1-joint library (4 feature dims, 6 descriptor dims) whose windows are ``rows``
    (first descriptor coordinate; the rest 0), unit scale, no rejection."""
    D = np.zeros((len(rows), 6))
    D[:, 0] = rows
    return Library("test", 4, 120.0, D, list(names), list(range(len(rows))),
                   [{"name": n, "source": str(i), "frames": [0, 1]} for i, n in enumerate(names)],
                   scale=np.ones(6), k_nearest=k)


def test_a_name_is_as_near_as_its_k_nearest_windows():
    """One stray 'jump' window next to the query, three 'walk' windows a little farther:
    the nearest window says jump, the mean of the 3 nearest per name says walk."""
    lib = _points_library([0.1, 3.0, 3.2, 0.4, 0.45, 0.5], ["jump"] * 3 + ["walk"] * 3, 3)
    q = np.zeros(6)
    per = lib.name_distances(lib.distances(q))
    scale = np.sqrt(1 / 3)                 # only the spread group (1 of 3) differs
    assert per["walk"] == pytest.approx(0.45 * scale)
    assert per["jump"] == pytest.approx((0.1 + 3.0 + 3.2) / 3 * scale)
    assert lib.name_descriptor(q).name == "walk"
    lib.k_nearest = 1
    assert lib.name_descriptor(q).name == "jump"
    lib.k_nearest = 10                     # more than a name has: all of its windows
    assert lib.name_distances(lib.distances(q))["walk"] == pytest.approx(0.45 * scale)
    d = lib.distances(q)
    d[:3] = np.inf                         # windows another person's calibration skips
    assert set(lib.name_distances(d)) == {"walk"}


def test_k_nearest_in_the_file(tmp_path, library):
    """Model libraries name by the nearest window; descriptor libraries by the 3 nearest;
    a version-1 file (before the model distance) reads as a descriptor library, and one
    without ``k_nearest`` (before k-NN) as 1-NN, the rules their thresholds were set for."""
    assert library.k_nearest == 1
    desc = _library(metric="descriptor")
    assert desc.metric == "descriptor" and desc.k_nearest == 3 and not json.loads(
        save_library(desc, tmp_path / "d.json").read_text()).get("window_stats")
    doc = json.loads(save_library(desc, tmp_path / "lib.json").read_text())
    assert doc["k_nearest"] == 3 and load(tmp_path / "lib.json").k_nearest == 3
    doc["version"] = 1
    del doc["metric"]
    (tmp_path / "v1.json").write_text(json.dumps(doc))
    v1 = load(tmp_path / "v1.json")
    assert v1.metric == "descriptor" and v1.k_nearest == 3
    res = synthesize("walk:4", seed=5)
    X, _, _ = take_rows(res.take, _config())
    assert v1.name(X[120:360]).name == desc.name(X[120:360]).name == "walk"
    with pytest.raises(LibraryError, match="learn it again with --new"):
        v1.merged(library)              # a model library cannot grow from descriptor windows
    del doc["k_nearest"]                   # a file from before k-NN: its rule was 1-NN
    (tmp_path / "old.json").write_text(json.dumps(doc))
    assert load(tmp_path / "old.json").k_nearest == 1
    doc["k_nearest"] = 0
    (tmp_path / "zero.json").write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match="k_nearest 0"):
        load(tmp_path / "zero.json")


def _rotate_left(X, seed):
    """Rows X (frames, 4J) with each joint's quaternion (x, y, z, w) left-multiplied by a
    fixed random rotation: a rest-pose / axis offset on the parent side."""
    rng = np.random.default_rng(seed)
    n, d = X.shape
    Q = X.reshape(n, d // 4, 4)
    R = rng.normal(size=(d // 4, 4))
    R /= np.linalg.norm(R, axis=1, keepdims=True)
    rx, ry, rz, rw = R.T
    x, y, z, w = np.moveaxis(Q, -1, 0)
    out = np.stack([rw * x + rx * w + ry * z - rz * y, rw * y - rx * z + ry * w + rz * x,
                    rw * z + rx * y - ry * x + rz * w, rw * w - rx * x - ry * y - rz * z], -1)
    return out.reshape(n, d)


def test_angular_velocity_units_and_rest_pose_offsets():
    from rtseg.library.distance import angular_velocity
    fr, omega = 120.0, 2.0                        # one joint turning about z at 2 rad/s
    t = np.arange(60) / fr
    X = np.stack([0 * t, 0 * t, np.sin(omega * t / 2), np.cos(omega * t / 2)], axis=1)
    w = angular_velocity(X, fr)
    assert w.shape == (60 - 4, 3)
    assert np.allclose(w[:, 2], omega, rtol=1e-3) and np.allclose(w[:, :2], 0, atol=1e-9)
    res = synthesize("walk:4", seed=5)
    Y, _, _ = take_rows(res.take, _config())
    assert np.allclose(angular_velocity(_rotate_left(Y, 1), fr), angular_velocity(Y, fr),
                       atol=1e-9)
    with pytest.raises(ValueError, match="4J features"):
        angular_velocity(Y[:1], fr)


def test_a_performer_with_other_rest_pose_offsets_is_named_alike(library):
    """The same walk with every joint offset by a fixed rotation (another rig's rest pose):
    the model distance names it as before, at the same distance."""
    res = synthesize("walk:4", seed=5)
    X, _, _ = take_rows(res.take, _config())
    a = library.name(X[120:360])
    b = library.name(_rotate_left(X, 2)[120:360])
    assert a.name == b.name == "walk" and b.distance == pytest.approx(a.distance, rel=1e-6)


def test_model_bank_is_the_trackers_window_distance(library):
    """The vectorised distances of a query to every library window are the identity
    tracker's D (rtseg.identity.tracker.IdentityTracker.distance) pair by pair."""
    from rtseg.detectors.window_models import fit
    from rtseg.identity.tracker import IdentityTracker
    from rtseg.library.distance import window_stats
    res = synthesize("punch:4", seed=3)
    X, _, _ = take_rows(res.take, _config())
    q = fit(window_stats(X[100:400], 120.0))
    got = library.bank.distances(q)
    tr = IdentityTracker(120.0)
    want = np.array([tr.distance(q, m) for m in library.bank.models])
    assert got.shape == (len(library.names),)
    assert np.allclose(got, want, rtol=1e-9, atol=1e-9)
    M = library.bank.pairwise()
    assert np.allclose(M, M.T) and np.all(np.diag(M) == 0)


def test_separating_rule_uses_the_ratio_when_distances_overlap():
    """Known cases: d1 0.5-0.9 with a far second name; unknown cases: d1 0.5-0.9 too,
    but two other names about as near - only the ratio tells them apart."""
    same = [0.5, 0.6, 0.7, 0.8, 0.9]
    same_other = [2.0] * 5
    o1 = [0.55, 0.65, 0.75, 0.85, 0.95]
    o2 = [v * 1.05 for v in o1]
    t, r = separating_rule(same, same_other, o1, o2)
    assert t >= 0.9 and 0.45 < r < 0.95


def test_separating_threshold():
    assert separating_threshold([0.2, 0.3, 0.4], [1.0, 1.2]) == pytest.approx(0.7)
    # one name, no unknown cases: 1.3 x the median, one far same-name pair does not loosen it
    assert separating_threshold([0.2, 0.3, 0.4, 3.0], []) == pytest.approx(1.3 * 0.35)
    t = separating_threshold([0.2, 0.9], [0.5, 1.5])
    assert 0.2 < t < 1.5
    # the model distance's own factor (re-derived the same way)
    assert separating_threshold([0.2, 0.3, 0.4, 3.0], [], 1.45) == pytest.approx(1.45 * 0.35)


def test_a_still_or_tiny_window_is_unknown_not_an_error(library):
    """No motion at all (a frozen stream) or the 2-row minimum: degenerate models, the
    answer is ``unknown``, not an exception or a name."""
    still = np.tile([0.0, 0.0, 0.0, 1.0], (300, library.dims // 4))
    for W in (still, still[:2]):
        assert library.name(W).name == UNKNOWN


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_unseen_behaviours_come_out_unknown(library, seed):
    """walk, punch, squat are in the library (learned on seed 0), kick and jump are not."""
    res = synthesize(PERFORMANCE, seed=seed)
    run = run_identity(res.take, _config(), library)
    assert len(run.cut_frames) == 4, "the synthetic changes should all be cut"
    names = [m.name for m in run.tracker.history if not m.correction]
    assert names == ["walk", UNKNOWN, "punch", UNKNOWN, "squat"]
    ids = [m.behaviour for m in run.tracker.history if not m.correction]
    assert all(i >= 1 for i in ids)    # unknown segments keep their unsupervised id


def test_hiding_a_name_turns_its_segments_unknown():
    """A library without punch names the punch of a performance ``unknown`` and the
    behaviours it holds by their names (cut at the true changes: the library's naming
    alone, wherever a detector would cut)."""
    from rtseg.evaluation.names_lopo import truth_cut_run
    lib = _library("walk:8,squat:8,wave:8")       # no punch
    res = synthesize("walk:6,punch:6,squat:6", seed=2)
    run = truth_cut_run(res.take, np.asarray(res.frame_names()), _config(), lib)
    names = [m.name for m in run.tracker.history if not m.correction]
    assert names == ["walk", UNKNOWN, "squat"]


def test_live_session_sends_names_over_udp(tmp_path, library):
    path = save_library(library, tmp_path / "lib.json")
    res = synthesize(PERFORMANCE, seed=1)
    rx = OscCollector(linger=0.5)
    port = rx.port
    rec = tmp_path / "session"
    cfg = from_dict({"identity": {"enabled": True, "threshold": SYNTH_THRESHOLD,
                                  "behaviours": str(path)},
                     "output": {"osc": [f"127.0.0.1:{port}"],
                                "templates": ["/cue/{label}/start"]},
                     "recording": {"dir": str(rec)}, "status": {"interval": 60.0}})
    session = LiveSession(TakeSource(res.take), cfg, handle_signals=False)
    try:
        session.run()
    finally:
        rx.close()
    assert not rx.malformed
    msgs = [(a, args) for a, _, args in rx.messages]
    beh = [p for a, p in msgs if a == "/rtseg/behaviour"]
    assert [p[3] for p in beh] == ["walk", UNKNOWN, "punch", UNKNOWN, "squat"]
    assert all(int(p[2]) >= 1 for p in beh)       # the ids stay the unsupervised ones
    cues = [a for a, _ in msgs if a.startswith("/cue/")]
    assert cues == ["/cue/walk/start", "/cue/unknown/start", "/cue/punch/start",
                    "/cue/unknown/start", "/cue/squat/start"]
    # the recording carries the names, and replaying it offline gives them again
    from rtseg.evaluation.identity import replay_session_identities
    from rtseg.recording.reader import read_session_behaviours
    recorded = [(b.segment, b.name) for b in read_session_behaviours(rec)]
    assert [n for _, n in recorded] == [p[3] for p in beh]
    offline = replay_session_identities(str(rec), cfg).history
    assert [(m.segment, m.name) for m in offline] == recorded


def test_live_refuses_a_library_of_another_profile(tmp_path, library):
    """sim://synth is a 'unity' skeleton: a cmu14 library is refused at start, one line."""
    doc = library_dict(library)
    doc["profile"] = "cmu14"
    doc["dims"] = 56
    doc["descriptors"] = [r + [0.0] * 12 for r in doc["descriptors"]]
    doc["scale"] = doc["scale"] + [1.0] * 12
    doc["window_stats"]["mean"] = [m + [0.0] * 6 for m in doc["window_stats"]["mean"]]
    doc["window_stats"]["scatter"] = [[0.0] * (42 * 43 // 2)] * len(doc["names"])
    (tmp_path / "cmu.json").write_text(json.dumps(doc))
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "live", "sim://synth",
                        "--behaviours", str(tmp_path / "cmu.json"), "--duration", "2",
                        "--no-osc", "--quiet"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "feature profile 'cmu14'" in p.stderr


# ------------------------------------------------------------------ real data (optional)
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.mark.skipif(not (DATA / "cmu_single" / "index.tsv").is_file(),
                    reason="needs ../shared/data/cmu_single")
def test_learn_from_a_folder_and_refuse_another_skeleton(tmp_path):
    """BVH and ASF/AMC takes of cmu_single map to the same canonical joints: one library of
    every person; a stream of another feature profile (the tsseg4d channels) is refused."""
    lib = tmp_path / "all.json"
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", str(lib), "--from",
                        str(DATA / "cmu_single")], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    got = load(lib)
    assert got.profile == "canonical" and got.dims == 48
    assert {"golf_swing", "jump", "kick", "walk", "dance"} <= set(got.behaviour_names)
    assert {e["person"] for e in got.examples} == {"02", "05", "06", "08", "10", "16", "64"}
    # a stream of the four tsseg4d channels is refused at start with one line, exit 2
    csv = DATA / "tsseg4d" / "86_01.csv"
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "live", f"file://{csv}",
                        "--behaviours", str(lib), "--duration", "5", "--no-osc", "--quiet"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 2
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
    assert "learned for feature profile 'canonical' (48 dims)" in p.stderr and "'tsseg4d'" in p.stderr


@pytest.mark.skipif(not (DATA / "labels" / "mocap6" / "13_29.txt").is_file(),
                    reason="needs ../shared/data (mocap6 takes)")
def test_library_leave_one_take_out_report():
    from rtseg.evaluation.report import library_loto
    from rtseg.labels.takes import find_labelled_takes
    takes = find_labelled_takes(DATA, ("cmu",))
    doc = library_loto(takes, _config())
    assert doc["takes"] == ["13_29", "13_31", "14_14"]
    assert doc["known_segments"] >= 15
    # each exercise also left out of its take's library once: every segment counted again
    assert doc["unknown_segments"] == doc["known_segments"]
    assert 0 <= doc["accuracy"] <= 1 and 0 <= doc["unknown_rate"] <= 1
    # left-out behaviours sent as unknown: 11 of 18 with the shipped detector.  Measured by `rtseg evaluate
    # ../shared/data --online --identity --json` (library.unknown_correct)
    assert doc["unknown_correct"] >= 0.6
    assert doc["accuracy"] + doc["unknown_rate"] <= 1.0 + 1e-9
    # the name goes out after the labelled change (its cut comes after the change), and
    # within a few seconds of it; only segments starting near a change are counted
    dd = doc["decision_delay_s"]
    assert 0 < dd["decisions"] <= doc["known_segments"]
    assert 0.5 < dd["after_transition_median"] <= dd["after_transition_p90"] < 5.0


def test_library_decision_delay_counts_only_segments_near_a_change():
    """library_eval.Tally: the delay median is over the known segments that have one (a
    boundary within 1 s of a truth change); the others and not-known segments are left out."""
    from rtseg.evaluation.library import Named, Tally
    t = Tally()
    t.add([Named("a", 1, 100, "walk", "walk", 1.0, True, 1.5),
           Named("a", 2, 900, "jump", "jump", 1.0, True, 2.5),
           Named("a", 3, 2000, "walk", "unknown", 1.0, True, None),
           Named("a", 4, 3000, "kick", "unknown", 1.0, False, 9.0)])
    dd = t.summary()["decision_delay_s"]
    assert dd["decisions"] == 2
    assert dd["after_transition_median"] == 2.0


def test_without_a_second_example_the_threshold_is_the_default():
    """Windows of one example lie nearer each other than a new performance does, so they
    are no known case: a library where no behaviour has a second example is not
    calibrated and takes the metric's default threshold (ratio 1); a second performer
    calibrates it."""
    from rtseg.library.calibration import DEFAULT_THRESHOLD
    one = _library("walk:8,punch:8", seeds=(0,))
    assert one.calibration["calibrated"] is False and one.calibration["same"] == 0
    assert one.threshold == DEFAULT_THRESHOLD["model"] and one.ratio == 1.0
    walk = _library("walk:8", seeds=(0,))             # one name, one example
    assert walk.calibration["calibrated"] is False and walk.threshold == DEFAULT_THRESHOLD["model"]
    two = _library("walk:8,punch:8", seeds=(0, 4))
    assert two.calibration["calibrated"] is True and two.calibration["same"] > 0
    assert two.threshold != DEFAULT_THRESHOLD["model"]


def test_learn_says_when_every_example_is_of_one_person(tmp_path):
    """Takes of one person (the name before the take's first ``_``) calibrate the library
    on that person's other takes: ``rtseg learn`` says a new performer may be rejected
    more often; a second person's takes make the note go away."""
    from rtseg.drivers.readers import write_take
    args = []
    for seed, name in ((0, "walk"), (1, "walk"), (2, "punch"), (3, "punch")):
        take = tmp_path / f"ann_{seed}.npz"
        write_take(take, synthesize(f"{name}:8", seed=seed).take)
        args += ["--take", str(take), "--label", name]
    run = lambda lib, *a: subprocess.run([sys.executable, "-m", "rtseg.cli", "learn",
                                          str(tmp_path / lib), *a],
                                         capture_output=True, text=True, timeout=120)
    p = run("one.json", *args)
    assert p.returncode == 0, p.stderr
    assert "every example is of one person (ann)" in p.stderr
    assert load(tmp_path / "one.json").calibration["calibrated"] is True
    take = tmp_path / "bob_4.npz"
    write_take(take, synthesize("walk:8", seed=4).take)
    p = run("two.json", *args, "--take", str(take), "--label", "walk")
    assert p.returncode == 0, p.stderr
    assert "one person" not in p.stderr


def test_learn_says_when_the_threshold_is_the_default(tmp_path):
    from rtseg.drivers.readers import write_take
    res = synthesize("walk:6,punch:6", seed=0)
    take = tmp_path / "t.npz"
    write_take(take, res.take)
    lib = tmp_path / "lib.json"
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", str(lib), "--take", str(take),
                        "--label", "walk", "--frames", f"0:{res.segments[0].stop}"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "(default)" in p.stdout and "no behaviour has a second example" in p.stderr
    assert load(lib).calibration["calibrated"] is False


@pytest.mark.skipif(not (DATA / "labels" / "mocap6" / "13_29.txt").is_file(),
                    reason="needs ../shared/data (mocap6 takes)")
def test_a_one_example_library_of_real_exercises_still_rejects_the_others():
    """A few seconds of one exercise from 13_31 (what `rtseg learn --take --frames` makes)
    name 13_29's segments: the other exercises' segments must come out unknown.  With the
    windows of the one example calibrating each other (before), every segment got the
    name (benchmarks/library_loto.py fewshot: 0 of 196)."""
    import dataclasses
    from rtseg.labels.truth import truth_labels
    from rtseg.labels.takes import find_labelled_takes
    from rtseg.evaluation.library import name_take
    from rtseg.library.examples import learn
    from rtseg.labels.truth import MOCAP6_NAMES
    from rtseg.library.sources import examples_from_dir
    cfg, _ = live_config()                 # the shipped detector and identity settings
    cfg["identity.enabled"] = True
    ex = [e for e in examples_from_dir(DATA, cfg, takes=["13_31"]) if e.name == "ArmCircle"]
    a, b = ex[0].frames
    m = (a + b) // 2
    lib, _ = learn([dataclasses.replace(ex[0], frames=(m - 240, m + 240))])   # 4 s
    assert lib.behaviour_names == ["ArmCircle"] and not lib.calibration["calibrated"]
    lt = next(t for t in find_labelled_takes(DATA, ("cmu",)) if t.name == "13_29")
    take = lt.load()
    truth = np.array([MOCAP6_NAMES.get(str(v), str(v)) for v in truth_labels(lt, take.n_frames)])
    rows = name_take(take, truth, lib, cfg, "13_29")
    others = [r for r in rows if r.truth != "ArmCircle"]
    assert len(others) >= 4
    assert all(r.name == UNKNOWN for r in others), [(r.truth, r.name, r.distance) for r in others]
    assert [r.name for r in rows if r.truth == "ArmCircle"] == ["ArmCircle"]


def test_an_old_library_that_never_rejects_is_loaded_with_a_warning(tmp_path, library, caplog):
    """A file learned before 2026-12-02 from one example per behaviour could hold no
    threshold (every segment named): it still loads, with a warning that says what to do;
    a threshold the user gave is not warned about, and a file is warned about once."""
    import logging
    path = save_library(library, tmp_path / "lib.json")
    doc = json.loads(path.read_text())
    doc["threshold"] = None
    doc["calibration"] = {"same": 0, "other": 0}
    path.write_text(json.dumps(doc))
    with caplog.at_level(logging.WARNING, logger="rtseg.library.file"):
        lib = load(path)
    assert lib.threshold == float("inf")
    assert "no rejection threshold" in caplog.text and "--new" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtseg.library.file"):
        load(path)                      # once per file: rtseg live checks it, then loads it
    assert "no rejection threshold" not in caplog.text
    doc["calibration"]["threshold_given"] = True
    given = tmp_path / "given.json"
    given.write_text(json.dumps(doc))
    with caplog.at_level(logging.WARNING, logger="rtseg.library.file"):
        load(given)
    assert "no rejection threshold" not in caplog.text


def test_learn_show_lists_what_a_library_holds(tmp_path):
    """``rtseg learn LIB --show`` reads LIB only: its rule (and where it comes from) and
    every example with its source and take frames; with --take it is refused."""
    from rtseg.drivers.readers import write_take
    takes = []
    for seed in (0, 4):
        res = synthesize("walk:5,punch:5", seed=seed)
        takes.append((tmp_path / f"perf{seed}.npz", res.segments[0].stop, res.take.n_frames))
        write_take(takes[-1][0], res.take)
    lib = tmp_path / "lib.json"
    args = []
    for path, cut, n in takes:
        args += ["--take", str(path), "--label", "walk", "--frames", f"0:{cut}",
                 "--take", str(path), "--label", "punch", "--frames", f"{cut}:{n}"]
    run = lambda *a: subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", str(lib), *a],
                                    capture_output=True, text=True, timeout=120)
    assert run(*args).returncode == 0
    before = lib.read_bytes()
    p = run("--show")
    assert p.returncode == 0, p.stderr
    assert "2 behaviours, 4 examples" in p.stdout and "(calibrated)" in p.stdout
    assert "walk: 2 example(s)" in p.stdout and "punch: 2 example(s)" in p.stdout
    assert f"perf4 frames {takes[1][1]}:{takes[1][2]}" in p.stdout
    assert lib.read_bytes() == before                   # --show learns and writes nothing
    p = run("--show", "--take", str(takes[0][0]), "--label", "walk")
    assert p.returncode == 2 and "--show only reads LIB" in p.stderr


def test_learn_from_segments_of_a_recorded_session(tmp_path):
    """``--take SESSION_DIR --segment K``: the frames of segment K as the live session
    numbered it (its recorded cuts), so a rehearsal recording labels itself by segment."""
    from rtseg.recording.reader import read_session_cuts
    res = synthesize("walk:6,punch:6,walk:6", seed=1)
    rec = tmp_path / "rehearsal"
    cfg = from_dict({"output": {"osc": []}, "recording": {"dir": str(rec)},
                     "detectors": {"contrast": dict(SYNTH_DETECTOR)},
                     "status": {"interval": 60.0}})
    LiveSession(TakeSource(res.take), cfg, handle_signals=False).run()
    cuts = sorted(c.frame for c in read_session_cuts(rec))
    assert len(cuts) == 2, cuts
    lib = tmp_path / "lib.json"
    run = lambda *a: subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", str(lib), *a],
                                    capture_output=True, text=True, timeout=120)
    p = run("--take", str(rec), "--segment", "0", "--label", "walk",
            "--take", str(rec), "--segment", "1", "--label", "punch",
            "--take", str(rec), "--segment", "2", "--label", "walk")
    assert p.returncode == 0, p.stderr
    got = load(lib)
    assert [(e["name"], e["frames"]) for e in got.examples] == [
        ("walk", [0, cuts[0]]), ("punch", [cuts[0], cuts[1]]),
        ("walk", [cuts[1], res.take.n_frames])]
    assert got.calibration["calibrated"]            # two walks: a second example
    p = run("--take", str(rec), "--segment", "3", "--label", "walk")
    assert p.returncode == 2 and "no segment 3" in p.stderr and "0..2" in p.stderr
    p = run("--take", str(rec), "--segment", "1", "--frames", "0:100", "--label", "walk")
    assert p.returncode == 2 and "not both" in p.stderr
    p = run("--take", str(rec), "--segment", "one", "--label", "walk")
    assert p.returncode == 2 and "a segment number" in p.stderr
    take = tmp_path / "take.npz"
    from rtseg.drivers.readers import write_take
    write_take(take, res.take)
    p = run("--take", str(take), "--segment", "1", "--label", "walk")
    assert p.returncode == 2 and "needs a session recording" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
    p = run("--show")                   # LIB was never written by the refused runs above
    assert p.returncode == 0 and "3 examples" in p.stdout
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", str(tmp_path / "no.json"),
                        "--show"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "cannot read" in p.stderr


def test_learn_says_which_behaviours_the_library_may_confuse(tmp_path):
    """Each name's nearest other name is kept in the file's calibration and shown by
    ``rtseg learn``; two names for one motion (``walk`` and ``stroll``, the same walks
    under two labels) are flagged, a distinct one (``punch``) is not; a name of one person's
    example only (``squat``) is said to lack a second example from another person."""
    from rtseg.commands.learn import describe
    from rtseg.library.file import load
    b = None
    for seed in (0, 4):
        res = synthesize("walk:8,punch:8", seed=seed)
        X, idx, profile = take_rows(res.take, _config())
        b = b or LibraryBuilder(profile, X.shape[1], res.take.frame_rate)
        (a, e, _), (c, f, _) = label_runs(res.frame_names())
        i, j = np.searchsorted(idx, [a, e])
        who = {"person": f"synth{seed}"}
        b.add(X[i:j], "walk", f"synth{seed}", info=who)
        b.add(X[i:j], "stroll", f"synth{seed}", info=who)      # the same frames
        b.add(X[np.searchsorted(idx, c):np.searchsorted(idx, f)], "punch", f"synth{seed}",
              info=who)
        if seed == 0:                    # one person's example only: no known case
            sq = synthesize("squat:8", seed=seed)
            Xs, _, _ = take_rows(sq.take, _config())
            b.add(Xs, "squat", "synth0 squat", info=who)
    lib = load(save_library(b.build(), tmp_path / "lib.json"))       # kept through the file
    near = lib.calibration["nearest_other"]
    assert near["walk"]["name"] == "stroll" and near["stroll"]["name"] == "walk"
    assert near["walk"]["distance"] <= near["walk"]["same"]
    assert near["walk"]["nearer_other"] >= 0.25 and near["punch"]["nearer_other"] == 0
    assert near["punch"]["distance"] > near["punch"]["same"]
    lines = {ln.split(":")[0].strip(): ln for ln in describe(lib, tmp_path / "lib.json")[1:]}
    assert "may be confused" in lines["walk"] and "may be confused" in lines["stroll"]
    assert "nearest other name" in lines["punch"] and "confused" not in lines["punch"]
    assert near["squat"]["same"] is None
    assert "no second example from another person" in lines["squat"]
    assert "no second example" not in lines["punch"]
    # examples that name no person: a second example is another take's
    b2 = LibraryBuilder(profile, X.shape[1], res.take.frame_rate)
    for seed in (0, 4):
        r = synthesize("walk:8,punch:8", seed=seed)
        Xr, ir, _ = take_rows(r.take, _config())
        (a, e, _), (c, f, _) = label_runs(r.frame_names())
        b2.add(Xr[np.searchsorted(ir, a):np.searchsorted(ir, e)], "walk", f"take{seed}")
        if seed == 0:
            b2.add(Xr[np.searchsorted(ir, c):np.searchsorted(ir, f)], "punch", "take0")
    lines2 = {ln.split(":")[0].strip(): ln for ln in describe(b2.build(), tmp_path / "b2.json")[1:]}
    assert "(no second example: " in lines2["punch"] and "no second" not in lines2["walk"]
    # a file written before the report was kept: worked out when shown, the file's rule kept
    lib.calibration.pop("nearest_other")
    lib.threshold = 9.0
    again = describe(lib, tmp_path / "lib.json")
    assert "may be confused" in again[1 + sorted(lines).index("walk")]
    assert lib.threshold == 9.0 and "nearest_other" not in lib.calibration


def test_library_benchmark_refuses_bad_folders_in_one_line(tmp_path):
    """benchmarks/library_loto.py: a folder that is not there, or one without two mocap6
    takes (and --by-person without two people), or --params without its file, is one line
    on stderr and exit 2."""
    bench = str(Path(__file__).resolve().parents[1] / "benchmarks" / "library_loto.py")
    run = lambda *a: subprocess.run([sys.executable, bench, *a], capture_output=True,
                                    text=True, timeout=120)
    for args, says in ((["mocap6", str(tmp_path / "missing")], "does not exist"),
                       (["fewshot", str(tmp_path / "missing")], "does not exist"),
                       (["mocap6", "--by-person", str(tmp_path)], "needs two"),
                       (["mocap6", "--params"], "--params: a detector parameter file")):
        p = run(*args)
        assert p.returncode == 2, p.stderr
        assert len(p.stderr.strip().splitlines()) == 1 and says in p.stderr, p.stderr
    if not (DATA / "labels" / "mocap6" / "13_31.txt").is_file():
        return
    one = tmp_path / "one_person"                # subject 13's two takes only
    (one / "cmu").mkdir(parents=True)
    (one / "labels" / "mocap6").mkdir(parents=True)
    for f in ("cmu/13.asf", "cmu/13_29.amc", "cmu/13_31.amc", "labels/mocap6/13_29.txt",
              "labels/mocap6/13_31.txt"):
        os.symlink(DATA / f, one / f)
    p = run("mocap6", "--by-person", str(one))
    assert p.returncode == 2, p.stderr
    assert len(p.stderr.strip().splitlines()) == 1 and "two people" in p.stderr, p.stderr


def test_learn_prefers_named_examples_and_refuses_numbered_names():
    """A folder whose four-channel takes carry only state ids (tsseg4d) beside named takes:
    the named profile is learned; a library that would name behaviours by numbers is refused."""
    from rtseg.library.examples import Example, learn
    rng = np.random.default_rng(4)

    def ex(name: str, profile: str, dims: int, k: int) -> Example:
        X = rng.normal(size=(720, dims)) * 0.05 + k
        return Example(name, f"t{k}", f"p{k}", X, np.arange(720), (0, 720), profile, 120.0)

    named = [ex("walk", "canonical", 8, 0), ex("squat", "canonical", 8, 1)]
    ids = [ex(str(i), "tsseg4d", 4, 2 + i) for i in range(4)]
    lib, notes = learn(named + ids)
    assert lib.profile == "canonical" and sorted(lib.behaviour_names) == ["squat", "walk"]
    assert sum("left out" in n for n in notes) == 4
    with pytest.raises(ValueError, match="named by a number"):
        learn(ids)


def _people_library(takes):
    """A library from (person, seed, script) takes of the synthesiser, each take one example
    per behaviour of that person; the script's two behaviours are named walk and punch (a
    person whose script is "run:8,wave:8" walks and punches in a style of their own)."""
    b = None
    for k, (person, seed, script) in enumerate(takes):
        res = synthesize(script, seed=seed)
        X, idx, profile = take_rows(res.take, _config())
        b = b or LibraryBuilder(profile, X.shape[1], res.take.frame_rate)
        for (a, e, _), name in zip(label_runs(res.frame_names()), ("walk", "punch")):
            i, j = np.searchsorted(idx, a), np.searchsorted(idx, e)
            assert b.add(X[i:j], name, f"{person}{k}", info={"person": person}) > 0
    return b.build()


def test_the_library_says_how_much_farther_another_person_lies(tmp_path):
    """``calibration.people``: the median nearest same-name window of another example of
    the same person against another person's.  A person whose walk and punch look unlike
    the other's (run and wave) lies much farther from them than from their own other takes;
    two people of one style do not; one person: no figure.  ``rtseg learn --show`` prints
    it."""
    from rtseg.commands.learn import describe
    ann = [("ann", 0, "walk:8,punch:8"), ("ann", 4, "walk:8,punch:8")]
    styled = _people_library(ann + [("bob", 1, "run:8,wave:8"), ("bob", 5, "run:8,wave:8")])
    mixed = _people_library(ann + [("bob", 1, "walk:8,punch:8"), ("bob", 5, "walk:8,punch:8")])
    one = _people_library(ann)
    a, m = styled.calibration["people"], mixed.calibration["people"]
    assert a["windows"] > 0 and m["windows"] > 0
    assert a["ratio"] == pytest.approx(a["other_person"] / a["same_person"], rel=1e-2)
    assert a["ratio"] > 2.0 * m["ratio"]
    assert 0.5 < m["ratio"] < 2.0
    assert one.calibration["people"] is None
    save_library(styled, tmp_path / "styled.json")
    back = load(tmp_path / "styled.json")
    assert back.calibration["people"] == a
    lines = describe(back, tmp_path / "styled.json")
    line = next(x for x in lines if "another person's examples lie" in x)
    assert f"{a['ratio']:.2f} x" in line and "styles differ" in line
    assert not any("another person's examples" in x for x in describe(one, tmp_path / "o.json"))
    assert not any("styles differ" in x for x in describe(mixed, tmp_path / "m.json"))


def test_one_person_calibration_and_the_thresholds_scale():
    """``one_person_calibration``: calibrated on one person's examples only (not several
    people, not a given threshold).  ``decide(d, scale=s)`` judges by s x threshold."""
    ann = [("ann", 0, "walk:8,punch:8"), ("ann", 4, "walk:8,punch:8")]
    one = _people_library(ann)
    two = _people_library(ann + [("bob", 1, "walk:8,punch:8")])
    assert one.calibration["calibrated"] and one.one_person_calibration
    assert not two.one_person_calibration
    one.calibration["threshold_given"] = True
    assert not one.one_person_calibration
    names = np.asarray(one.names)
    t = one.threshold
    # the other name where the decision's margin term is nil: the threshold alone decides
    from rtseg.library.calibration import MARGIN_LEVEL, MARGIN_WEIGHT
    other = 1.5 * t / (one.ratio * math.exp(MARGIN_LEVEL / MARGIN_WEIGHT))
    d = np.where(names == "walk", 1.5 * t, other)
    assert one.decide(d).name == UNKNOWN and one.decide(d).nearest == "walk"
    assert one.decide(d, scale=2.0).name == "walk"
    assert one.decide(d, scale=1.4).name == UNKNOWN
