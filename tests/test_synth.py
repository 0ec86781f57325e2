"""The procedural motion synthesiser: skeleton, scripts, exact transitions, realism checks."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.core import quat
from rtseg.config import load_toml
from rtseg.simulators.synth.motion import (BEHAVIOURS, DEFAULT_SCRIPT, FEATURE_JOINTS, JOINT_NAMES,
                                    PARENTS, ScriptError, joint_positions, local_quats, mirror,
                                    parse_script, synthesize)

RATE = 120.0


@pytest.fixture(scope="module")
def default_take():
    return synthesize(seed=0)


def test_skeleton_is_the_default17_suit():
    sensors = load_toml("suits")["suits"]["default17"]["sensors"]
    names = [s["bone"] for s in sorted(sensors, key=lambda s: s["id"])]
    assert JOINT_NAMES == names
    parents = [names.index(s["parent"]) if s["parent"] else -1
               for s in sorted(sensors, key=lambda s: s["id"])]
    assert PARENTS == parents
    assert set(FEATURE_JOINTS) <= set(names) and len(FEATURE_JOINTS) == 12


def test_parse_script_accepts_and_normalises():
    assert parse_script("idle:4, Walk:8.5s;jumping-jacks:2") == [
        ("idle", 4.0), ("walk", 8.5), ("jumping_jacks", 2.0)]
    names = [n for n, _ in parse_script(DEFAULT_SCRIPT)]
    assert 6 <= len(names) <= 10 and set(names) <= set(BEHAVIOURS)
    assert all(5 <= s <= 10 for _, s in parse_script(DEFAULT_SCRIPT))


@pytest.mark.parametrize("script, fragment", [
    ("", "empty"),
    ("idle:4,,walk:3", "item 2 is empty"),
    ("idle:4,walk", "item 2 'walk': expected behaviour:seconds"),
    ("idle:4,moonwalk:3", "unknown behaviour 'moonwalk'"),
    ("idle:abc", "expected behaviour:seconds"),
    ("idle:0.5", "at least"),
])
def test_parse_script_errors_name_the_item(script, fragment):
    with pytest.raises(ScriptError, match=fragment.replace("(", r"\(")):
        parse_script(script)


def test_same_seed_same_take_other_seed_other_take():
    a = synthesize("idle:2,walk:3,punch:3", seed=7)
    b = synthesize("idle:2,walk:3,punch:3", seed=7)
    c = synthesize("idle:2,walk:3,punch:3", seed=8)
    assert np.array_equal(a.take.quats, b.take.quats)
    assert np.array_equal(a.take.root_position, b.take.root_position)
    assert a.transitions == b.transitions
    assert not np.allclose(a.take.quats, c.take.quats, atol=1e-3)


def test_transitions_and_segments_follow_the_script(default_take):
    r = default_take
    items = parse_script(DEFAULT_SCRIPT)
    assert r.take.n_frames == round(sum(s for _, s in items) * RATE)
    assert len(r.transitions) == len(items) - 1
    bounds = np.round(np.cumsum([s for _, s in items]) * RATE).astype(int)[:-1]
    for k, t in enumerate(r.transitions):
        assert (t.before, t.after) == (items[k][0], items[k + 1][0])
        assert t.lo <= t.mid <= t.hi and t.mid == bounds[k]
        assert 0.4 * RATE - 1 <= t.width <= 0.8 * RATE + 1
        assert abs((t.lo + t.hi) / 2 - t.mid) <= 1
    # segments tile the take, switching at the transition mids
    assert r.segments[0].start == 0 and r.segments[-1].stop == r.take.n_frames
    for s, t, nxt in zip(r.segments, r.transitions, r.segments[1:]):
        assert s.stop == t.mid == nxt.start
    assert [s.name for s in r.segments] == [n for n, _ in items]
    labels = r.frame_labels()
    assert np.array_equal(np.flatnonzero(np.diff(labels)) + 1, [t.mid for t in r.transitions])
    assert np.array_equal(r.take.meta["frame_labels"], labels)


def _same_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per frame: every joint's rotation equal (q or -q)."""
    return np.all(np.abs(np.abs(np.sum(a * b, axis=-1)) - 1.0) < 1e-12, axis=-1)


def test_blend_span_is_exactly_the_transition_range():
    # Same seed: the first behaviour's instance, the blend spans, drift and noise are shared,
    # so frames before `lo` are identical whatever follows, and frames after `hi` are
    # identical whatever preceded.
    a = synthesize("walk:4,squat:4", seed=3)
    b = synthesize("walk:4,punch:4", seed=3)
    c = synthesize("idle:4,squat:4", seed=3)
    t = a.transitions[0]
    assert (t.lo, t.hi) == (b.transitions[0].lo, b.transitions[0].hi) == (c.transitions[0].lo, c.transitions[0].hi)
    ab = _same_rotation(a.take.quats, b.take.quats)
    assert ab[:t.lo].all() and not ab[t.lo:].any()
    ac = _same_rotation(a.take.quats, c.take.quats)
    assert ac[t.hi + 1:].all() and not ac[:t.hi + 1].any()


def test_quaternions_unit_and_continuous(default_take):
    q = default_take.take.quats
    assert q.shape == (default_take.take.n_frames, 17, 4)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-12)
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    assert (dots > 0).all()                       # sign-continuous
    step_deg = np.degrees(2 * np.arccos(np.clip(dots, -1, 1)))
    # fastest limb (a punch's elbow) below 1700 deg/s, as human joints are
    assert step_deg.max() < 1700.0 / RATE
    # transitions are as smooth as the behaviours: no jump at a blend
    in_blend = np.zeros(len(step_deg), bool)
    for t in default_take.transitions:
        in_blend[t.lo - 1:t.hi + 1] = True
    assert step_deg[in_blend].max() <= step_deg[~in_blend].max()


def test_take_metadata(default_take):
    tk = default_take.take
    assert tk.space == "local" and tk.frame_rate == RATE and tk.length_unit == "m"
    assert tk.joint_names == JOINT_NAMES and tk.parents == PARENTS
    assert tk.meta["synth_script"] and tk.meta["synth_seed"] == 0


def test_feet_stay_on_the_floor_and_gait_moves_forward():
    r = synthesize("idle:3,walk:6,jump:5", seed=2)
    tk = r.take
    glob = quat.global_from_local(tk.quats, tk.parents)
    pos = joint_positions(glob, tk.root_position)
    ankle = np.minimum(pos[:, JOINT_NAMES.index("LeftFoot"), 1],
                       pos[:, JOINT_NAMES.index("RightFoot"), 1])
    idle = slice(0, 300)
    walk = slice(r.segments[1].start + 60, r.segments[1].stop - 60)
    jump = slice(r.segments[2].start + 60, r.segments[2].stop)
    # standing: ankles ~7 cm above the floor (the sensor noise moves them a few mm)
    assert np.all(np.abs(ankle[idle] - 0.07) < 0.03)
    assert ankle[jump].max() > 0.25                # airborne while jumping
    speed = np.linalg.norm(np.diff(tk.root_position[walk][:, [0, 2]], axis=0), axis=1) * RATE
    assert 1.0 < speed.mean() < 1.7
    assert np.allclose(np.diff(tk.root_position[idle][:, [0, 2]], axis=0), 0.0)


def _stats(X: np.ndarray) -> np.ndarray:
    return np.concatenate([X.mean(axis=0), X.std(axis=0)])


def _features(take) -> np.ndarray:
    idx = [take.joint_index(n) for n in FEATURE_JOINTS]
    return take.quats[:, idx, :].reshape(take.n_frames, -1)


@pytest.mark.parametrize("seed", [0, 1])
def test_behaviours_are_stationary_and_distinct(seed):
    """Feature statistics (mean, std of the 12 joints' quaternions) of the two halves of one
    behaviour are much closer than those of any two different behaviours."""
    script = ",".join(f"{name}:20" for name in BEHAVIOURS)
    r = synthesize(script, seed=seed)
    X = _features(r.take)
    halves = {}
    for s in r.segments:
        a, b = s.start + 60, s.stop - 60        # clear of the blends
        m = (a + b) // 2
        halves[s.name] = (_stats(X[a:m]), _stats(X[m:b]))
    for name, (h1, h2) in halves.items():
        within = np.linalg.norm(h1 - h2)
        between = min(np.linalg.norm(x - y) for other, hs in halves.items() if other != name
                      for x in (h1, h2) for y in hs)
        assert within < 0.6 * between, (name, within, between)


def test_behaviours_use_different_joints():
    """The joints that move most differ between behaviours (legs for gait, one arm for
    waving, both arms for arm circles), as on real motion capture."""
    def motion(name):
        tk = synthesize(f"{name}:8", seed=1).take
        return {j: float(np.degrees(2 * np.arccos(np.clip(
            np.abs(np.sum(tk.quats[:, i] * tk.quats[:, i].mean(0), -1)
                   / np.linalg.norm(tk.quats[:, i].mean(0))), -1, 1))).std())
            for i, j in enumerate(tk.joint_names)}
    walk, wave, circles, squat = motion("walk"), motion("wave"), motion("arm_circles"), motion("squat")
    assert walk["LeftLowerLeg"] > 5 * walk["LeftLowerArm"]
    waving = max(wave["LeftLowerArm"], wave["RightLowerArm"])
    assert waving > 5 * max(wave["LeftUpperLeg"], wave["RightUpperLeg"])
    assert min(wave["LeftLowerArm"], wave["RightLowerArm"]) < 0.3 * waving   # one hand
    assert min(circles["LeftUpperArm"], circles["RightUpperArm"]) > 5 * circles["LeftLowerLeg"]
    assert squat["LeftLowerLeg"] > 5 and squat["RightLowerLeg"] > 5


def test_mirror_swaps_sides_and_is_an_involution():
    rng = np.random.default_rng(0)
    A = rng.normal(0, 30, (5, 17, 4))
    assert np.array_equal(mirror(mirror(A)), A)
    q, qm = local_quats(A), local_quats(mirror(A))
    li, ri = JOINT_NAMES.index("LeftLowerLeg"), JOINT_NAMES.index("RightLowerLeg")
    assert np.allclose(q[:, li], qm[:, ri])       # knee: same flexion on the other side
    # identity angles except the arms' T-pose offset are the identity rotation
    assert np.allclose(np.abs(local_quats(np.zeros((1, 17, 4)))[0, :, 3])[[0, 1, 11, 12]], 1.0)


def test_detectors_separate_synthetic_behaviours():
    """End to end with the real detectors: PPCA finds every transition of a short take."""
    from rtseg.detectors import segment_features
    from rtseg.evaluation.scoring import score
    from rtseg.core.features import take_features

    r = synthesize("walk:6,squat:6,punch:6,wave:6", seed=0)
    cuts = segment_features(take_features(r.take), "ppca", r.take.frame_rate)
    s = score(cuts, r.transitions)
    assert s.recall == 1.0, ([c.frame for c in cuts], r.transitions)
    assert s.precision >= 0.75
