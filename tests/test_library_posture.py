"""Behaviour libraries with posture (rtseg.library.posture_distance): two behaviours whose
joints turn alike but where the body differs (an arm swung low or high) are told apart when
the session has posture, and not by rotations alone; the file keeps it; a session without
posture is named by the rotations' own rule."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rtseg.core import quat as Q
from rtseg.core.features import take_features
from rtseg.core.posture import RestPose, take_posture
from rtseg.library.behaviours import UNKNOWN
from rtseg.library.builder import LibraryBuilder
from rtseg.library.file import load, save
from rtseg.library.behaviours import LibraryError

from test_posture import _RIG, rig_take

FR = 60.0
NAMES = [n for n, _, _ in _RIG]


def swing(level_deg: float, person: int, seconds: float = 8.0) -> "object":
    """The left arm swung forward and back (±25° about the vertical axis of the arm's own
    frame) at shoulder level raised by ``level_deg``; every joint wobbles a little.  The
    arm's angular velocity does not depend on the level: only where the arm is does."""
    rng = np.random.default_rng(person)             # the same wobble at either level
    n = int(seconds * FR)
    t = np.arange(n) / FR
    f = 0.8 + 0.15 * person
    q = np.tile(Q.IDENTITY, (n, len(_RIG), 1)).astype(float)
    for j in range(len(_RIG)):                         # slow wobble everywhere
        ang = np.cumsum(rng.standard_normal((n, 3)), axis=0) * 0.002
        ang -= ang.mean(axis=0)
        q[:, j] = Q.from_euler("xyz", np.degrees(ang))
    arm = NAMES.index("LeftArm")
    raise_q = Q.from_euler("z", np.full((n, 1), level_deg))          # raise the arm (about z)
    swing_q = Q.from_euler("y", ((25.0 + 3 * person) * np.sin(2 * np.pi * f * t))[:, None])
    q[:, arm] = Q.multiply(Q.multiply(raise_q, swing_q), q[:, arm])
    return rig_take(q)


def add(builder: LibraryBuilder, take, name: str, person: int, posture: bool = True) -> None:
    X = take_features(take)
    P = take_posture(take) if posture else None
    builder.add(X, name, f"p{person}_{name}", frame_rate=FR,
                info={"person": f"p{person}"}, posture=P)


def library(posture: bool = True):
    b = LibraryBuilder("canonical", 48, FR)
    for person in (0, 1, 2):
        add(b, swing(0.0, person), "low", person, posture)
        add(b, swing(80.0, person), "high", person, posture)
    return b.build()


@pytest.fixture(scope="module")
def lib():
    return library()


def names_of(lib, take, posture: bool) -> list[str]:
    X, P = take_features(take), take_posture(take)
    out = []
    for s in range(60, len(X) - 150, 60):              # 2.5 s windows every second
        nm = lib.name(X[s:s + 150], FR, P[s:s + 150] if posture else None)
        out.append(nm.name)
    return out


def test_posture_tells_apart_what_the_rotations_cannot(lib):
    assert lib.has_posture and lib.names_by_posture
    assert lib.calibration["posture"]["threshold"] == pytest.approx(lib.posture_rule["threshold"], abs=1e-3)
    low, high = swing(0.0, 3), swing(80.0, 3)          # a fourth person
    for take, name in ((low, "low"), (high, "high")):
        with_posture = names_of(lib, take, True)
        assert with_posture.count(name) >= 0.8 * len(with_posture), with_posture
    # by rotations alone both levels are the same motion: the same answers for either
    assert names_of(lib, low, False) == names_of(lib, high, False)


def test_the_file_keeps_the_posture_and_its_rule(tmp_path, lib):
    path = save(lib, tmp_path / "lib.json")
    doc = json.loads(path.read_text())
    assert doc["version"] == 4 and len(doc["posture"]) == len(doc["names"])
    back = load(path)
    assert back.names_by_posture
    np.testing.assert_allclose(back.posture, lib.posture, atol=1e-5)
    assert back.posture_rule["threshold"] == pytest.approx(lib.posture_rule["threshold"], rel=1e-6)
    new = swing(80.0, 3)
    assert names_of(back, new, True) == names_of(lib, new, True)


def test_a_file_without_posture_names_by_rotations(tmp_path, lib):
    doc = json.loads(save(lib, tmp_path / "lib.json").read_text())
    del doc["posture"], doc["posture_rule"]
    doc["version"] = 2
    (tmp_path / "v2.json").write_text(json.dumps(doc))
    old = load(tmp_path / "v2.json")
    assert not old.has_posture and not old.names_by_posture
    new = swing(0.0, 3)
    assert names_of(old, new, True) == names_of(lib, new, False)


def test_a_malformed_posture_is_one_clear_error(tmp_path, lib):
    doc = json.loads(save(lib, tmp_path / "lib.json").read_text())
    doc["posture"] = doc["posture"][:-1]
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(LibraryError, match="posture descriptors or rule"):
        load(tmp_path / "bad.json")


def test_examples_without_posture_give_a_library_without_it():
    b = LibraryBuilder("canonical", 48, FR)
    for person in (0, 1):
        add(b, swing(0.0, person), "low", person)
        add(b, swing(80.0, person), "high", person, posture=person == 0)
    lib = b.build()
    assert not lib.has_posture and not lib.names_by_posture
    assert lib.name(take_features(swing(0.0, 3))[:150], FR, take_posture(swing(0.0, 3))[:150]).name in ("low", "high", UNKNOWN)


def test_the_live_pipeline_names_by_posture_when_the_rig_is_known(lib):
    from rtseg.evaluation.online import live_config
    from rtseg.live.pipeline import Pipeline
    take = swing(80.0, 3, seconds=6.0)
    cfg, _ = live_config()
    cfg["identity.enabled"] = True
    seen = {}
    for rest in (RestPose.of_take(take), None):
        pipe = Pipeline(take.joint_names, take.parents, "local", FR, cfg, rest=rest)
        pipe.identity.library = lib
        for i, q in enumerate(take.quats):
            pipe.process(i, q, np.ones(len(q), dtype=bool), i, i / FR, 0, i / FR)
        namer = pipe.identity.namer
        seen[rest is not None] = bool(namer._has_pose.any())
    assert seen == {True: True, False: False}


def test_a_rig_geometry_that_gives_no_posture_is_logged_once_and_the_session_names_on(lib, caplog):
    """Rest geometry that does not fit the source's rig (here, of another joint count):
    one warning, and the segments are named by the pose features alone."""
    from rtseg.evaluation.online import live_config
    from rtseg.live.pipeline import Pipeline
    take = swing(80.0, 3, seconds=6.0)
    cfg, _ = live_config()
    cfg["identity.enabled"] = True
    bad = RestPose(RestPose.of_take(take).positions[:-1])
    pipe = Pipeline(take.joint_names, take.parents, "local", FR, cfg, rest=bad)
    pipe.identity.library = lib
    with caplog.at_level("WARNING", logger="rtseg.live.posture_switch"):
        for i, q in enumerate(take.quats):
            pipe.process(i, q, np.ones(len(q), dtype=bool), i, i / FR, 0, i / FR)
    warned = [r for r in caplog.records if "no posture for behaviour names" in r.getMessage()]
    assert len(warned) == 1
    assert pipe.stats.identity_errors == 0 and not pipe.identity.namer._has_pose.any()
    assert pipe.identity.stats.decisions >= 1
