"""``rtseg learn LIB --from DIR`` on source folders laid out like ../shared/data/cmu_single,
hdm05 and bandai (rtseg.library.sources): every take whose rig maps to the canonical
skeleton, any frame rate; short clips of one person and behaviour joined; the same example
learned twice is a no-op.  The folders are written here from synthetic performers
(tests/source_folders.py); one test uses the real folders and skips when they are absent."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtseg.library.file import load
from rtseg.library.examples import Example, unique_examples
from rtseg.library.examples import motion_key

from source_folders import make_source

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
BEHAVIOURS = ["walk", "squat", "wave"]


def _learn(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", *args],
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def parent(tmp_path_factory) -> Path:
    """Two source folders: a cmu-bvh rig at 120 Hz (one 6 s take per person and
    behaviour) and the bandai rig at 30 Hz (each take cut into three 2 s clips)."""
    root = tmp_path_factory.mktemp("data")
    make_source(root / "single", ["a1", "a2"], BEHAVIOURS, rate=120.0, rig="cmu-bvh")
    make_source(root / "clips", ["b1", "b2"], BEHAVIOURS, rate=30.0, rig="bandai", clips=3,
                seed0=10)
    return root


def test_learn_from_a_parent_of_sources_of_two_rigs_and_frame_rates(parent, tmp_path):
    lib = tmp_path / "lib.json"
    p = _learn(str(lib), "--from", str(parent))
    assert p.returncode == 0, p.stderr
    got = load(lib)
    assert got.profile == "canonical" and got.behaviour_names == sorted(BEHAVIOURS)
    assert {e["person"] for e in got.examples} == {"a1", "a2", "b1", "b2"}
    by_rate = {}
    for e in got.examples:
        by_rate.setdefault(e["frame_rate"], []).append(e)
    assert sorted(by_rate) == [30.0, 120.0]
    # 120 Hz: one example per take (6 s); 30 Hz: the three 2 s clips (shorter than an
    # example once the rest at the ends is dropped) of a person and behaviour joined
    assert len(by_rate[120.0]) == 6 and all("+" not in e["source"] for e in by_rate[120.0])
    assert len(by_rate[30.0]) == 6
    assert all(e["source"].count("+") == 2 for e in by_rate[30.0]), by_rate[30.0]
    # windows are cut in seconds at each example's own rate: a joined 30 Hz example of
    # ~5.4 s gives as many windows as 120 Hz material of that length
    wins = np.bincount(got.sources, minlength=len(got.examples))
    k30 = [k for k, e in enumerate(got.examples) if e["frame_rate"] == 30.0]
    assert all(wins[k] >= 5 for k in k30)
    assert all(len(e["key"]) == 16 for e in got.examples)
    assert len({e["key"] for e in got.examples}) == 12

    # the same folder again: nothing added, the file untouched
    before = lib.read_bytes()
    p = _learn(str(lib), "--from", str(parent))
    assert p.returncode == 0, p.stderr
    assert "12 already in the library" in p.stderr
    assert lib.read_bytes() == before
    # with a take too short to give a window: noted, nothing new, still a success
    short = make_source(tmp_path / "short", ["s1"], ["walk"], seconds=1.6)
    p = _learn(str(lib), "--from", str(parent), "--take", str(short / "bvh" / "s1_001.bvh"),
               "--label", "walk")
    assert p.returncode == 0, p.stderr
    assert "s1_001" in p.stderr and "shorter than 2 s" in p.stderr
    assert "12 already in the library" in p.stderr and lib.read_bytes() == before
    # the short take alone: nothing could be learned, as for a new library: an error
    p = _learn(str(lib), "--take", str(short / "bvh" / "s1_001.bvh"), "--label", "walk")
    assert p.returncode == 2 and "no example long enough to learn from" in p.stderr
    assert lib.read_bytes() == before
    # one take of it given by hand (the same frames: rest at the ends dropped as --from
    # does) and a copy of the source folder under another name: the same motion
    copy = tmp_path / "copy"
    shutil.copytree(parent / "single", copy)
    p = _learn(str(lib), "--take", str(copy / "bvh" / "a1_001.bvh"), "--label", "walk",
               "--from", str(copy))
    assert p.returncode == 0, p.stderr
    assert "7 already in the library" in p.stderr and lib.read_bytes() == before
    # the same frames under another name: not added, said
    p = _learn(str(lib), "--take", str(copy / "bvh" / "a1_001.bvh"), "--label", "run")
    assert p.returncode == 0 and "already in the library as 'walk'" in p.stderr
    assert lib.read_bytes() == before
    # another range of a known take is another example
    p = _learn(str(lib), "--take", str(copy / "bvh" / "a1_001.bvh"), "--label", "walk",
               "--frames", "0:500")
    assert p.returncode == 0, p.stderr
    assert len(load(lib).examples) == 13


def test_example_keys_and_unique_examples():
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize("walk:3,squat:3", frame_rate=60.0, seed=2).take
    k = motion_key(take, 0, 120)
    assert k == motion_key(take, 0, 120) and len(k) == 16
    assert k != motion_key(take, 0, 121) and k != motion_key(take, 1, 121)

    def ex(name: str, key: str) -> Example:
        return Example(name, "t", "p", np.zeros((10, 8)), np.arange(10), (0, 10), "c", 60.0, key)

    new, rep = unique_examples([ex("walk", "k1"), ex("walk", "k1"), ex("squat", "k2"),
                                ex("x", ""), ex("x", "")], known={"k2": "squat"})
    assert [e.key for e in new] == ["k1", "", ""] and [e.key for e in rep] == ["k1", "k2"]


def test_a_spliced_folder_beside_the_sources_is_not_a_source(tmp_path):
    """A data folder may hold ``spliced/`` (benchmarks/splice.py's output, which
    ``rtseg evaluate`` reads): its ``index.tsv`` lists performances, not takes, and has no
    ``bvh/`` or ``amc/`` beside it, so it is no source folder; ``rtseg learn --from`` the
    parent learns the source (it said "spliced/index.tsv: missing column(s) take")."""
    from rtseg.library.sources import source_folders
    root = tmp_path / "data"
    make_source(root / "single", ["a1", "a2"], ["walk", "squat"], rate=30.0, seconds=4.0)
    (root / "spliced").mkdir()
    (root / "spliced" / "index.tsv").write_text(
        "performance\tkind\tformat\tframes\tsegment\tbehaviour\tsubject\tstart\n")
    assert source_folders(root) == [root / "single"]
    p = _learn(str(tmp_path / "lib.json"), "--from", str(root))
    assert p.returncode == 0, p.stderr
    assert {e["person"] for e in load(tmp_path / "lib.json").examples} == {"a1", "a2"}


def test_examples_of_spliced_performances_are_their_segments_people(tmp_path):
    """``rtseg learn --from DATA`` also learns the spliced performances in ``DATA/spliced/``:
    each example's person is the subject of its segment (it was the file name's prefix,
    "mixed" or "same"), so --person / --exclude-person keep a person's material out of the
    library there too."""
    from rtseg.evaluation.splice import generate
    root = tmp_path / "data"
    src = make_source(root / "single", ["p1", "p2"], BEHAVIOURS, rate=30.0, seconds=8.0)
    generate(src, root / "spliced", seed=0, n=1, kinds=("mixed",))
    lib = tmp_path / "lib.json"
    p = _learn(str(lib), "--from", str(root))
    assert p.returncode == 0, p.stderr
    spliced = [e for e in load(lib).examples if e["source"].startswith("mixed_000")]
    assert spliced and {e["person"] for e in spliced} == {"p1", "p2"}
    p = _learn(str(lib), "--new", "--from", str(root), "--exclude-person", "p2")
    assert p.returncode == 0, p.stderr
    assert {e["person"] for e in load(lib).examples} == {"p1"}
    p = _learn(str(lib), "--new", "--from", str(root), "--person", "p2")
    assert p.returncode == 0, p.stderr
    assert {e["person"] for e in load(lib).examples} == {"p2"}


def test_learn_from_a_folder_that_does_not_exist(tmp_path):
    p = _learn(str(tmp_path / "lib.json"), "--from", str(tmp_path / "nowhere"))
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1
    assert "no such folder" in p.stderr


@pytest.mark.skipif(not ((DATA / "hdm05" / "index.tsv").is_file()
                         and (DATA / "bandai" / "index.tsv").is_file()),
                    reason="needs ../shared/data/hdm05 and bandai")
def test_learn_from_real_hdm05_amc_and_bandai_bvh(tmp_path):
    """A parent folder holding part of hdm05 (ASF/AMC, 120 Hz, one unit per clip) and of
    bandai (BVH, 30 Hz): one canonical library of both; short clips joined."""
    root = tmp_path / "data"
    for src, keep in (("hdm05", ("bd", "bk")), ("bandai", ("bn1", "bn2"))):
        d = root / src
        d.mkdir(parents=True)
        sub = "amc" if src == "hdm05" else "bvh"
        (d / sub).symlink_to(DATA / src / sub)
        lines = (DATA / src / "index.tsv").read_text().splitlines()
        want = ("squat", "kick") if src == "hdm05" else ("walk", "wave_left_hand")
        rows = [r for r in lines[1:] if r.split("\t")[1] in keep and r.split("\t")[5] in want]
        (d / "index.tsv").write_text("\n".join(lines[:1] + rows) + "\n")
    lib = tmp_path / "lib.json"
    p = _learn(str(lib), "--from", str(root))
    assert p.returncode == 0, p.stderr
    got = load(lib)
    assert got.behaviour_names == ["kick", "squat", "walk", "wave_left_hand"]
    assert {e["person"] for e in got.examples} == {"bd", "bk", "bn1", "bn2"}
    assert {e["frame_rate"] for e in got.examples} == {30.0, 120.0}
    squats = [e for e in got.examples if e["name"] == "squat"]
    assert squats and all("+" in e["source"] for e in squats)    # one squat per clip: joined
    p = _learn(str(lib), "--from", str(root))
    assert f"{len(got.examples)} already in the library" in p.stderr


@pytest.mark.skipif(not (DATA / "bandai" / "index.tsv").is_file(),
                    reason="needs ../shared/data/bandai")
def test_a_lone_short_take_is_kept_when_one_window_fits(tmp_path):
    """bandai's bn2_044 (68 frames at 30 Hz, 2.27 s) and bn2_032 (65 frames) are the only
    short takes of their person and behaviour: nothing to join them with.  bn2_044 still
    gives one window (1 s after 0.5 s off each end of its fed rows) and is learned;
    bn2_032's fed rows are too short for one, and the note says so."""
    from rtseg.evaluation.online import live_config
    from rtseg.library.examples import learn
    from rtseg.library.sources import examples_from_source
    d = tmp_path / "bandai"
    d.mkdir()
    (d / "bvh").symlink_to(DATA / "bandai" / "bvh")
    lines = (DATA / "bandai" / "index.tsv").read_text().splitlines()
    rows = [r for r in lines[1:] if r.split("\t")[0] in ("bn2_044", "bn2_032", "bn2_001")]
    (d / "index.tsv").write_text("\n".join(lines[:1] + rows) + "\n")
    cfg, _ = live_config()
    ex = examples_from_source(d, cfg)
    assert sorted(e.take for e in ex) == ["bn2_001", "bn2_032", "bn2_044"]
    lib, notes = learn(ex)
    assert sorted(e["source"] for e in lib.examples) == ["bn2_001", "bn2_044"]
    assert sum(n == "raise_up_right_hand" for n in lib.names) == 1      # one window
    assert any(n.startswith("bn2_032 ") and "shorter than" in n for n in notes), notes


def test_learn_with_a_profile_leaves_out_the_rigs_that_cannot_give_it(tmp_path):
    """--profile cmu14 computes the examples' features with it: the takes of a rig with the
    CMU ASF joint names are learned, those of another rig are left out in one note line
    naming the joint they lack (not one error for the whole run)."""
    root = tmp_path / "data"
    make_source(root / "asf", ["c1", "c2"], ["walk", "squat"], rig="cmu-asf")
    make_source(root / "bvh", ["d1", "d2"], ["walk", "squat"], rig="cmu-bvh", seed0=5)
    lib = tmp_path / "lib.json"
    p = _learn(str(lib), "--from", str(root), "--profile", "cmu14")
    assert p.returncode == 0, p.stderr
    got = load(lib)
    assert got.profile == "cmu14" and got.dims == 56
    assert {e["person"] for e in got.examples} == {"c1", "c2"}
    left = [ln for ln in p.stderr.splitlines() if "left out" in ln]
    assert len(left) == 1 and left[0].startswith("rtseg learn: note: 4 takes left out (")
    assert "of skeleton profile 'cmu14' is missing" in left[0]
    # a profile no rig of the folder can give: nothing to learn, one line, exit 2
    p = _learn(str(tmp_path / "none.json"), "--from", str(root / "bvh"), "--profile", "cmu14")
    assert p.returncode == 2 and "no labelled examples" in p.stderr
