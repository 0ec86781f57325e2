"""Posture rows (rtseg.core.posture): forward kinematics into the body frame, the same on
every rig and size, and a clear error without rest geometry."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rtseg.core import quat as Q
from rtseg.core.posture import DIM, POINTS, Posture, PostureError, RestPose, take_posture
from rtseg.core.take import Take

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"

# A cgspeed-style BVH rig, Y up, facing +Z, T-pose at rest (offsets in cm).
_RIG = [
    ("Hips", "", (0, 90, 0)),
    ("LeftUpLeg", "Hips", (10, 0, 0)), ("LeftLeg", "LeftUpLeg", (0, -40, 0)),
    ("LeftFoot", "LeftLeg", (0, -40, 0)),
    ("RightUpLeg", "Hips", (-10, 0, 0)), ("RightLeg", "RightUpLeg", (0, -40, 0)),
    ("RightFoot", "RightLeg", (0, -40, 0)),
    ("LowerBack", "Hips", (0, 10, 0)), ("Spine", "LowerBack", (0, 15, 0)),
    ("Spine1", "Spine", (0, 15, 0)), ("Neck", "Spine1", (0, 10, 0)), ("Head", "Neck", (0, 10, 0)),
    ("LeftShoulder", "Spine1", (5, 5, 0)), ("LeftArm", "LeftShoulder", (15, 0, 0)),
    ("LeftForeArm", "LeftArm", (30, 0, 0)), ("LeftHand", "LeftForeArm", (25, 0, 0)),
    ("RightShoulder", "Spine1", (-5, 5, 0)), ("RightArm", "RightShoulder", (-15, 0, 0)),
    ("RightForeArm", "RightArm", (-30, 0, 0)), ("RightHand", "RightForeArm", (-25, 0, 0)),
]


def rig_take(quats: np.ndarray, rig=_RIG, scale: float = 1.0) -> Take:
    names = [n for n, _, _ in rig]
    parents = [names.index(p) if p else -1 for _, p, _ in rig]
    offsets = np.array([o for _, _, o in rig], dtype=float) * scale
    F = len(quats)
    return Take(names, parents, 120.0, quats, np.tile(offsets[0], (F, 1)), "local",
                meta={"format": "bvh", "offsets": offsets}, source="rig")


def rest_quats(frames: int = 1, rig=_RIG) -> np.ndarray:
    return np.tile(Q.IDENTITY, (frames, len(rig), 1)).astype(float)


def about(axis: str, deg: float) -> np.ndarray:
    return Q.from_euler(axis, np.array([deg]))


def point(rows: np.ndarray, name: str) -> np.ndarray:
    k = POINTS.index(name)
    return rows[..., 3 * k:3 * k + 3]


def test_rest_pose_rows_are_the_rig_in_leg_lengths_about_the_pelvis():
    rows = take_posture(rig_take(rest_quats()))
    assert rows.shape == (1, DIM)
    leg = 80.0
    np.testing.assert_allclose(point(rows[0], "left_wrist"), np.array([75, 45, 0]) / leg, atol=1e-12)
    np.testing.assert_allclose(point(rows[0], "right_ankle"), np.array([-10, -80, 0]) / leg, atol=1e-12)
    np.testing.assert_allclose(point(rows[0], "head"), np.array([0, 60, 0]) / leg, atol=1e-12)


def test_a_bent_elbow_moves_the_wrist_and_nothing_else():
    q = rest_quats(2)
    names = [n for n, _, _ in _RIG]
    q[1, names.index("LeftForeArm")] = about("y", -90.0)      # forearm swings to the front
    rows = take_posture(rig_take(q))
    moved = np.flatnonzero(np.abs(rows[1] - rows[0]) > 1e-9)
    assert set(moved // 3) == {POINTS.index("left_wrist")}
    # the forearm (25 cm to the hand) now points forward
    np.testing.assert_allclose(point(rows[1], "left_wrist") - point(rows[1], "left_elbow"),
                               np.array([0, 0, 25]) / 80.0, atol=1e-12)


def test_heading_position_and_size_drop_out():
    rng = np.random.default_rng(1)
    q = Q.normalize(np.tile(Q.IDENTITY, (50, len(_RIG), 1)) + 0.3 * rng.standard_normal((50, len(_RIG), 4)))
    base = take_posture(rig_take(q))
    turned = q.copy()
    turned[:, 0] = Q.multiply(about("y", 73.0), q[:, 0])        # the whole body turned about up
    np.testing.assert_allclose(take_posture(rig_take(turned)), base, atol=1e-12)
    np.testing.assert_allclose(take_posture(rig_take(q, scale=0.01)), base, atol=1e-12)  # cm -> m
    # lying down is not standing: a body tipped about the heading axis differs
    tipped = q.copy()
    tipped[:, 0] = Q.multiply(about("x", 90.0), q[:, 0])
    assert np.abs(take_posture(rig_take(tipped)) - base).max() > 0.3


def test_an_extra_joint_at_the_same_place_changes_nothing():
    rig = list(_RIG)
    k = [n for n, _, _ in rig].index("LeftForeArm")
    rig[k] = ("LeftForeArm", "LeftArmRoll", (0, 0, 0))
    rig.insert(k, ("LeftArmRoll", "LeftArm", (30, 0, 0)))
    rng = np.random.default_rng(2)
    q = Q.normalize(np.tile(Q.IDENTITY, (20, len(_RIG), 1)) + 0.3 * rng.standard_normal((20, len(_RIG), 4)))
    q2 = np.insert(q, k, Q.IDENTITY, axis=1)
    np.testing.assert_allclose(take_posture(rig_take(q2, rig)), take_posture(rig_take(q)), atol=1e-12)


def test_global_orientations_give_the_same_rows_as_local_ones():
    rng = np.random.default_rng(3)
    q = Q.normalize(np.tile(Q.IDENTITY, (10, len(_RIG), 1)) + 0.3 * rng.standard_normal((10, len(_RIG), 4)))
    local = rig_take(q)
    g = Q.global_from_local(q, local.parents)
    glob = Posture(local.joint_names, local.parents, RestPose.of_take(local), "global")
    np.testing.assert_allclose(glob.transform(g), take_posture(local), atol=1e-12)
    np.testing.assert_allclose(glob.transform(g[4:5])[0], take_posture(local)[4], atol=1e-12)


def test_a_rig_with_a_joint_before_its_parent_is_refused_with_one_line():
    t = rig_take(rest_quats())
    order = [1, 0] + list(range(2, len(_RIG)))             # LeftUpLeg listed before Hips
    t.joint_names = [t.joint_names[k] for k in order]
    t.parents = [order.index(t.parents[k]) if t.parents[k] >= 0 else -1 for k in order]
    t.quats = t.quats[:, order]
    t.meta = {"format": "bvh", "offsets": t.meta["offsets"][order]}
    with pytest.raises(PostureError, match="comes before its parent"):
        take_posture(t)
    assert Posture.find(t) is None


def test_a_take_without_rest_geometry_says_so():
    t = rig_take(rest_quats())
    t.meta = {}
    with pytest.raises(PostureError, match="no rest geometry"):
        take_posture(t)
    assert RestPose.find(t) is None and Posture.find(t) is None


@pytest.mark.skipif(not (DATA / "cmu" / "86_01.amc").exists(),
                    reason="../shared/data/cmu (real CMU motion) is absent")
def test_a_real_walk_stands_upright_in_asf_and_bvh():
    from rtseg.drivers.readers import read_take
    takes = [read_take(DATA / "cmu" / "86_01.amc")]
    bvh = DATA / "cmu_single" / "bvh" / "02_01.bvh"
    if bvh.exists():
        takes.append(read_take(bvh).slice(2, 300))
    for t in takes:
        rows = take_posture(t)
        head, ankle = point(rows, "head"), point(rows, "left_ankle")
        assert np.median(head[:, 1]) > 0.5 and np.median(ankle[:, 1]) < -0.8, t.source
        assert np.median(point(rows, "left_hip")[:, 0]) > 0 > np.median(point(rows, "right_hip")[:, 0])
