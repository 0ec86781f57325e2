"""``rtseg learn LIB --check`` (rtseg.library.self_check): each person of a library named by a
library of its other people - the sub-libraries are the ones learning those examples
alone would build, behaviours only one person performs and each shared behaviour left
out count as missing, a one-person sub-library names through simulated sessions (the
performer's scale), and a library of one person is refused in one line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rtseg.evaluation.online import live_config
from rtseg.library.examples import learn, synthetic_examples
from rtseg.library.file import save
from rtseg.library.self_check import (SESSION_ORDERS, CheckError, _named, check, check_lines,
                                      subset, window_people)

SHARED = ["walk", "punch", "squat"]


def learn_cli(*args) -> subprocess.CompletedProcess:
    """``rtseg learn ARGS...`` in a subprocess."""
    return subprocess.run([sys.executable, "-m", "rtseg.cli", "learn", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def cfg():
    return live_config()[0]


def performer(examples, person):
    """``examples`` as performed by ``person`` (two synthetic seeds standing for two takes of
    one performer, so that a library of theirs alone can be calibrated)."""
    return [type(e)(**{**vars(e), "person": person}) for e in examples]


@pytest.fixture(scope="module")
def examples(cfg):
    """Two performers, two takes each of walk, punch and squat; ann also kicks."""
    return (performer(synthetic_examples(SHARED, [0, 1], cfg), "ann")
            + performer(synthetic_examples(SHARED, [4, 5], cfg), "bob")
            + performer(synthetic_examples(["kick"], [0], cfg), "ann"))


@pytest.fixture(scope="module")
def library(examples):
    lib, notes = learn(examples)
    assert not notes and lib.names_by_posture
    return lib


def test_each_person_named_by_the_others(library):
    """Known: each person's examples of the three shared behaviours (two takes each);
    missing: the kick only ann performs, and each shared behaviour left out in turn."""
    for posture in (True, False):
        r = check(library, posture)
        assert r.people == ["ann", "bob"] and r.posture is posture
        s0, s4 = (r.by_person[p].summary() for p in r.people)
        assert s0["known"]["examples"] == 6 and s4["known"]["examples"] == 6
        assert s0["left_out"]["examples"] == 7 and s4["left_out"]["examples"] == 6
        for s in (s0, s4):
            k = s["known"]
            assert k["named_right"] + k["unknown"] + k["wrong"] == pytest.approx(1.0, abs=2e-3)
            # the synthetic behaviours are far apart: the other performer's examples name them
            assert k["named_right"] >= 2 / 3
        pooled = r.as_dict()["pooled"]
        assert pooled["known"]["examples"] == 12 and pooled["left_out"]["examples"] == 13
        # per behaviour: two takes of each shared one by each person; the kick only ann's
        per = r.as_dict()["by_behaviour"]
        assert sorted(per) == ["kick", "punch", "squat", "walk"]
        assert [per[b]["known"]["examples"] for b in SHARED] == [4, 4, 4]
        assert [per[b]["left_out"]["examples"] for b in SHARED] == [4, 4, 4]
        assert per["kick"]["known"]["examples"] == 0 and per["kick"]["left_out"]["examples"] == 1
        assert sum(v["known"]["examples"] for v in per.values()) == 12
        # a missing example is `unknown` or named something else: the shares add up
        for v in list(per.values()) + [s0, s4]:
            u = v["left_out"]
            assert u["unknown"] + sum(u["named_as"].values()) == pytest.approx(1.0, abs=5e-3)
            assert all(n in library.names for n in u["named_as"])


def test_wrong_labels_in_the_others_examples_come_out_wrong(cfg, examples):
    """bob's walk and punch labelled the other way round: ann's walks are nearest to
    bob's walking, labelled punch - the check counts them wrong, not right."""
    swapped = []
    for e in examples:
        if e.person == "bob" and e.name in ("walk", "punch"):
            e = type(e)(**{**vars(e), "name": "punch" if e.name == "walk" else "walk"})
        swapped.append(e)
    lib, _ = learn(swapped)
    s0 = check(lib, True).by_person["ann"].summary()["known"]
    assert s0["wrong"] >= 1 / 3 and s0["named_right"] <= 2 / 3


def test_subset_is_the_library_of_those_examples_alone(examples, library):
    """The sub-library of ann's examples: the windows, threshold and posture rule that
    learning ann's examples alone gives."""
    keep = np.array([e.get("person") == "ann" for e in library.examples])
    sub = subset(library, keep)
    alone, _ = learn([e for e in examples if e.person == "ann"])
    assert sub.names == alone.names and len(sub.window_stats) == len(alone.window_stats)
    assert sub.threshold == pytest.approx(alone.threshold)
    assert sub.ratio == pytest.approx(alone.ratio)
    assert sub.posture_rule["threshold"] == pytest.approx(alone.posture_rule["threshold"])
    assert set(window_people(sub)) == {"ann"} and sub.one_person_calibration


def test_one_person_libraries_name_through_simulated_sessions(cfg, examples, library):
    """A one-person sub-library gives each example a name per simulated session order (the
    performer's scale builds up from the examples before it); a sub-library of two people
    one name."""
    who = window_people(library)
    keep = np.array([e.get("person") != "ann" for e in library.examples])
    mine = np.flatnonzero(who == "ann")
    got = _named(library, keep, subset(library, keep), mine[:3], mine, True)[0]
    assert [len(g) for g in got] == [SESSION_ORDERS] * 3
    three, _ = learn(examples + performer(synthetic_examples(SHARED, [7, 8], cfg), "cy"))
    who3 = window_people(three)
    keep3 = np.array([e.get("person") != "ann" for e in three.examples])
    mine3 = np.flatnonzero(who3 == "ann")
    assert [len(g) for g in _named(three, keep3, subset(three, keep3), mine3[:3], mine3,
                                   True)[0]] == [1, 1, 1]


def test_a_library_of_one_person_is_refused(examples):
    lib, _ = learn([e for e in examples if e.person == "bob"])
    with pytest.raises(CheckError, match="at least two people"):
        check(lib)


def test_check_lines(library):
    lines = check_lines(library, [check(library, True), check(library, False)])
    assert lines[0].startswith("a new performer, sessions with posture")
    assert "named right 1.00" in lines[1] or "named right 0." in lines[1]
    assert any(line.startswith("    ann: ") for line in lines)
    assert any(line.startswith("    kick: performed by one person only") for line in lines)
    assert any(line.startswith("    walk: 1.00 / 0.00 / 0.00 of 4") for line in lines)
    assert any("sessions without posture" in line for line in lines)


def test_learn_check_command(tmp_path, examples, library):
    lib = tmp_path / "lib.json"
    save(library, lib)
    one = tmp_path / "one.json"
    save(learn([e for e in examples if e.person == "ann"])[0], one)
    p = learn_cli(lib, "--check")
    assert p.returncode == 0, p.stderr
    assert "behaviours the library holds: named right" in p.stdout
    assert "sessions without posture" in p.stdout
    p = learn_cli(lib, "--check", "--json")
    assert p.returncode == 0, p.stderr
    doc = json.loads(p.stdout)
    assert [c["posture"] for c in doc["checks"]] == [True, False]
    assert doc["checks"][0]["pooled"]["known"]["examples"] == 12
    for args, says in (((one, "--check"), "at least two people"),
                       ((lib, "--json"), "--json goes with --check"),
                       ((lib, "--show", "--json"), "--json goes with --check"),
                       ((lib, "--check", "--new"), "--check only reads LIB"),
                       ((lib, "--check", "--show"), "--show only reads LIB")):
        p = learn_cli(*args)
        assert p.returncode == 2 and says in p.stderr, (args, p.stderr)
        assert len(p.stderr.strip().splitlines()) == 1


def test_both_distances_at_once_are_the_two_checks(library):
    """``checks`` makes each sub-library once for both distances: the same figures as
    the two checks apart."""
    from rtseg.library.self_check import checks
    both = checks(library, (True, False))
    assert [r.as_dict() for r in both] == [check(library, True).as_dict(),
                                           check(library, False).as_dict()]


def test_a_library_whose_people_share_no_behaviour_says_so(examples):
    """ann's kick and bob's walk only: nobody else performs either, so there is no known
    case - the lines say so, and both examples are counted missing."""
    kick = [e for e in examples if (e.person, e.name) == ("ann", "kick")]
    walk = [e for e in examples if (e.person, e.name) == ("bob", "walk")]
    lib, _ = learn(kick[:1] + walk[:1])
    r = check(lib)
    assert r.pooled.summary()["known"]["examples"] == 0
    assert r.pooled.summary()["left_out"]["examples"] == 2
    assert any("no behaviour is performed by two of its people" in line
               for line in check_lines(lib, [r]))


def test_learning_a_library_of_several_people_points_to_the_check(tmp_path):
    """``rtseg learn LIB --from DIR`` of two people's takes ends with a note naming the
    check; the check then runs on the file it wrote."""
    from source_folders import make_source
    src = make_source(tmp_path / "synth", ["p1", "p2"], ["walk", "squat"], rate=30.0,
                      seconds=6.0)
    lib = tmp_path / "lib.json"
    p = learn_cli(lib, "--from", src)
    assert p.returncode == 0, p.stderr
    assert f"rtseg learn {lib} --check" in p.stderr
    p = learn_cli(lib, "--check", "--json")
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["checks"][0]["people"] == ["p1", "p2"]


def test_a_descriptor_library_is_refused(examples):
    """A library of the version-1 descriptor distance has no window models to compare by:
    one line, learn it again."""
    lib, _ = learn(examples, metric="descriptor")
    with pytest.raises(CheckError, match="model distance: learn it again with --new"):
        check(lib)


@pytest.mark.parametrize("three_people", [False, True])
def test_the_operators_scale_curve(cfg, examples, library, three_people):
    """Pooled figures at other factors of the threshold: at 1 the check's own; a smaller
    factor sends at least as many examples `unknown`, a larger one at most as many; at a
    factor no distance reaches, nothing is `unknown`.  Both through one-person
    sub-libraries (the performer's scale on top) and through libraries of two people."""
    from rtseg.library.self_check import checks
    lib = library
    if three_people:
        lib, _ = learn(examples + performer(synthetic_examples(SHARED, [7, 8], cfg), "cy"))
    for r in checks(lib, (True, False), (0.25, 1.0, 4.0, 1e9)):
        pooled = r.pooled.summary()
        assert r.curve[1.0].summary() == pooled
        at = {f: t.summary() for f, t in r.curve.items()}
        unknown = [at[f]["known"]["unknown"] for f in (0.25, 1.0, 4.0, 1e9)]
        missing = [at[f]["left_out"]["unknown"] for f in (0.25, 1.0, 4.0, 1e9)]
        assert unknown == sorted(unknown, reverse=True) and unknown[-1] == 0.0
        assert missing == sorted(missing, reverse=True) and missing[-1] == 0.0
        assert missing[0] > 0.0         # a quarter of the threshold refuses a missing one
        assert all(at[f]["known"]["examples"] == pooled["known"]["examples"] for f in at)
        # the per-person and per-behaviour figures stay the check's at 1
        assert r.as_dict()["by_behaviour"] == check(lib, r.posture).as_dict()["by_behaviour"]


def test_learn_check_threshold_scales_command(tmp_path, library):
    lib = tmp_path / "lib.json"
    save(library, lib)
    p = learn_cli(lib, "--check", "--threshold-scales", "0.5,2")
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    at = [i for i, line in enumerate(lines) if line.startswith("  at the operator's scale")]
    assert len(at) == 2                       # with posture and without
    assert [lines[at[0] + k].split(":")[0].strip() for k in (1, 2, 3)] == ["0.5", "1", "2"]
    p = learn_cli(lib, "--check", "--threshold-scales", "0.5,2", "--json")
    doc = json.loads(p.stdout)
    assert [c["scale"] for c in doc["checks"][0]["threshold_scales"]] == [0.5, 1.0, 2.0]
    for args, says in (((lib, "--threshold-scales", "2"), "--threshold-scales goes with --check"),
                       ((lib, "--check", "--threshold-scales", "0,2"), "positive numbers"),
                       ((lib, "--check", "--threshold-scales", "x"), "positive numbers")):
        p = learn_cli(*args)
        assert p.returncode == 2 and says in p.stderr, (args, p.stderr)


def test_a_factor_given_twice_is_checked_once(library):
    """``--threshold-scales 2,2,0.5``: each factor's figures are its own (a repeated factor
    once), the same as ``2,0.5``."""
    from rtseg.library.self_check import checks
    twice = checks(library, (True,), (2.0, 2.0, 0.5))[0]
    once = checks(library, (True,), (2.0, 0.5))[0]
    assert list(twice.curve) == [2.0, 0.5]
    assert {f: t.summary() for f, t in twice.curve.items()} == \
        {f: t.summary() for f, t in once.curve.items()}
    assert twice.curve[0.5].summary() != twice.curve[2.0].summary()
