"""Pose features and skeleton/suit profiles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.core import quat as Q
from rtseg.config import ConfigError
from rtseg.drivers.readers import read_take
from rtseg.core.features import PoseFeatures, constant_dims, left_matrices, take_features
from rtseg.core.rig import RigError
from rtseg.core.profiles import choose_profile, resolve_joints, skeleton_profile, suit_profile
from rtseg.core.take import Take

S = math.sqrt(0.5)
CMU14 = ["lowerback", "upperback", "thorax", "lowerneck", "upperneck", "head", "rhumerus",
         "rradius", "lhumerus", "lradius", "rfemur", "rtibia", "lfemur", "ltibia"]


def _rand_quats(shape: tuple[int, ...], seed: int) -> np.ndarray:
    n = int(np.prod(shape))
    return Rotation.random(n, random_state=seed).as_quat().reshape(*shape, 4)


def _smooth_local(frames: int, joints: int, seed: int) -> np.ndarray:
    """Smooth random local motion: slerp-like rotation vectors along a random walk."""
    rng = np.random.default_rng(seed)
    rv = np.cumsum(rng.normal(scale=0.05, size=(frames, joints, 3)), axis=0)
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat().reshape(frames, joints, 4)


@pytest.fixture(scope="module")
def suit():
    return suit_profile("default17")


# ---------------------------------------------------------------------------------------
# Profiles

def test_skeleton_profiles_and_choice(suit):
    assert skeleton_profile("cmu14") == CMU14
    assert len(skeleton_profile("unity")) == 12
    assert skeleton_profile("tsseg4d") == ["lhumerus", "rhumerus", "lfemur", "rfemur"]
    # a skeleton with its hierarchy maps to the canonical joints; bare channels do not
    assert choose_profile(list(suit.bones), list(suit.parents)) == "canonical"
    assert choose_profile(["root"] + [n.upper() for n in CMU14]) != "canonical"   # no hierarchy
    assert choose_profile(["lhumerus", "rhumerus", "lfemur", "rfemur"]) == "tsseg4d"
    with pytest.raises(RigError, match="cannot map the skeleton"):
        choose_profile(["a", "b"], [-1, 0])
    with pytest.raises(KeyError, match="unknown skeleton profile 'nope'"):
        skeleton_profile("nope")
    with pytest.raises(KeyError, match="no fixed joint list"):
        skeleton_profile("all")


def test_unity_aliases_and_case(suit):
    names = [("UpperChest" if b == "Chest" else b).lower() for b in suit.bones]
    idx = resolve_joints("unity", names)
    assert names[idx[1]] == "upperchest"
    # Canonical name wins over the alias when both exist.
    both = list(suit.bones) + ["UpperChest"]
    assert both[resolve_joints("unity", both)[1]] == "Chest"


def test_suit_profile_default17(suit, tmp_path):
    assert suit.sensor_ids == tuple(range(17)) and suit.frame_rate == 120.0
    assert suit.bones[0] == "Hips" and suit.parents[0] == -1
    assert suit.bones[suit.parents[suit.bones.index("LeftLowerArm")]] == "LeftUpperArm"
    assert all(p < k for k, p in enumerate(suit.parents))
    assert suit.index_of_sensor(14) == 14
    with pytest.raises(KeyError, match="unknown suit 'x'"):
        suit_profile("x")
    bad = tmp_path / "suits.toml"
    bad.write_text('[suits.s]\nframe_rate = 60\nsensors = [{id = 0, bone = "A", parent = "B"}]\n')
    with pytest.raises(ConfigError, match=r"suits\.s\.sensors\[0\]\.parent 'B' is not a bone"):
        suit_profile("s", bad)
    bad.write_text('[suits.s]\nframe_rate = 60\nsensors = [{id = 0, bone = "A"}, {id = 0, bone = "B"}]\n')
    with pytest.raises(ConfigError, match=r"sensors\[1\]\.id 0 used twice"):
        suit_profile("s", bad)


# ---------------------------------------------------------------------------------------
# Hand-checked features

def test_global_to_local_hand_checked():
    # parent: 90° about z; child global: Rz(90)·Rx(90) -> parent-relative Rx(90).
    qz = np.array([0, 0, S, S])
    qx = np.array([S, 0, 0, S])
    g = np.array([[qz, Q.multiply(qz, qx)]])
    pf = PoseFeatures(["p", "c"], [-1, 0], "global", "all")
    np.testing.assert_allclose(pf.transform(g), [[0, 0, S, S, S, 0, 0, S]], atol=1e-12)
    np.testing.assert_allclose(pf.step(g[0]), [0, 0, S, S, S, 0, 0, S], atol=1e-12)
    assert pf.dim == 8 and pf.joints == ["p", "c"]


def test_left_matrices_are_hamilton_products():
    a, b = _rand_quats((6,), 1), _rand_quats((6,), 2)
    np.testing.assert_allclose((left_matrices(a) @ b[:, :, None])[:, :, 0], Q.multiply(a, b), atol=1e-15)
    np.testing.assert_allclose((left_matrices(a, conjugate=True) @ b[:, :, None])[:, :, 0],
                               Q.multiply(Q.conjugate(a), b), atol=1e-15)


def test_full_hierarchy_used_before_selection(suit):
    """Spine's parent Hips is not in the unity profile, yet Spine is relative to Hips."""
    local = _smooth_local(30, 17, 3)
    g = Q.global_from_local(local, list(suit.parents))
    pf = PoseFeatures(suit.bones, suit.parents, "global", "unity")
    assert pf.profile == "unity" and "Hips" not in pf.joints
    X = pf.transform(g)
    ref = PoseFeatures(suit.bones, suit.parents, "local", "unity").transform(local)
    np.testing.assert_allclose(X, ref, atol=1e-12)
    spine = pf.joints.index("Spine")
    np.testing.assert_allclose(np.abs(X[:, 4 * spine:4 * spine + 4]), np.abs(local[:, 1]), atol=1e-12)


def test_sign_continuity_and_first_frame_w_positive(suit):
    local = _smooth_local(200, 17, 4)
    rng = np.random.default_rng(5)
    flipped = local * rng.choice([-1.0, 1.0], size=local.shape[:2])[..., None]
    pf = PoseFeatures(suit.bones, suit.parents, "local", "all")
    X = pf.transform(flipped).reshape(200, 17, 4)
    assert np.all(X[0, :, 3] >= 0)
    assert np.all(np.sum(X[1:] * X[:-1], axis=-1) >= 0)
    # Same rotations, only signs changed.
    np.testing.assert_allclose(np.abs(np.sum(X * local, axis=-1)), 1.0, atol=1e-12)
    # The continuous features are the unflipped motion up to one sign per joint.
    ref = pf.transform(local).reshape(200, 17, 4)
    np.testing.assert_allclose(X, ref, atol=1e-12)


@pytest.mark.parametrize("space", ["global", "local"])
@pytest.mark.parametrize("profile", ["unity", "all"])
def test_step_equals_transform(suit, space, profile):
    q = _smooth_local(150, 17, 6)
    if space == "global":
        q = Q.global_from_local(q, list(suit.parents))
    q = q * np.random.default_rng(7).choice([-1.0, 1.0], size=q.shape[:2])[..., None]
    pf = PoseFeatures(suit.bones, suit.parents, space, profile)
    T = pf.transform(q)
    S1 = np.array([pf.step(f) for f in q])
    np.testing.assert_allclose(S1, T, atol=1e-12)
    pf.reset()
    S2 = np.array([pf.step(f) for f in q])
    np.testing.assert_allclose(S2, T, atol=1e-12)
    # Rows returned by step are copies: mutating one does not disturb continuity.
    pf.reset()
    first = pf.step(q[0])
    first[:] = 0
    np.testing.assert_allclose(pf.step(q[1]), T[1], atol=1e-12)
    # Non-contiguous / list input is accepted.
    pf.reset()
    np.testing.assert_allclose(pf.step(q[0].tolist()), T[0], atol=1e-12)


def test_calibration_maps_rest_to_identity_and_removes_rig_offsets(suit):
    """VMC-like rig: local rotations = rest ⊗ anatomical.  Calibrating on the rest pose
    gives features of the anatomical motion."""
    anat = _smooth_local(80, 17, 8)
    anat[0] = Q.IDENTITY  # frame 0: performer in the rest pose
    rest = _rand_quats((17,), 9)
    rig = Q.multiply(rest[None], anat)
    pf = PoseFeatures(suit.bones, suit.parents, "local")
    pf.calibrate(rig[0])
    assert pf.calibrated
    T = pf.transform(rig)
    np.testing.assert_allclose(T[0].reshape(-1, 4), np.tile(Q.IDENTITY, (12, 1)), atol=1e-12)
    ref = PoseFeatures(suit.bones, suit.parents, "local").transform(anat)
    np.testing.assert_allclose(T, ref, atol=1e-12)
    np.testing.assert_allclose(np.array([pf.step(f) for f in rig]), T, atol=1e-12)
    # Constructor argument is the same as calibrate(); clear_calibration undoes it.
    pf2 = PoseFeatures(suit.bones, suit.parents, "local", calibration=rig[0])
    np.testing.assert_allclose(pf2.transform(rig), T, atol=1e-12)
    pf2.clear_calibration()
    np.testing.assert_allclose(np.abs(pf2.transform(rig)[:, :4]), np.abs(rig[:, 1]), atol=1e-12)


def test_missing_joint_names_joint_and_profile():
    with pytest.raises(KeyError, match=r"joint 'rtibia' of skeleton profile 'cmu14' is missing"):
        PoseFeatures([n for n in CMU14 if n != "rtibia"], [-1] * 13, "local", "cmu14")
    with pytest.raises(KeyError, match=r"'Chest' \(or UpperChest, Spine1, Spine2\) of skeleton profile 'unity'"):
        PoseFeatures(["Spine"], [-1], "local", "unity")


def test_bad_inputs():
    with pytest.raises(ValueError, match="space must be"):
        PoseFeatures(["a"], [-1], "world")
    with pytest.raises(ValueError, match="invalid parent index 3"):
        PoseFeatures(["a", "b"], [-1, 3], "local")
    pf = PoseFeatures(["a", "b"], [-1, 0], "local", "all")
    with pytest.raises(ValueError, match=r"frame must be \(2, 4\)"):
        pf.step(np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"quats must be \(frames, 2, 4\)"):
        pf.transform(np.zeros((5, 3, 4)))
    assert pf.transform(np.zeros((0, 2, 4))).shape == (0, 8)


def test_constant_dims():
    X = np.column_stack([np.zeros(10), np.linspace(0, 1, 10), np.full(10, 3.0), np.r_[np.zeros(9), 1e-12]])
    np.testing.assert_array_equal(constant_dims(X), [True, False, True, True])
    np.testing.assert_array_equal(constant_dims(X, tol=0.0), [True, False, True, False])
    with pytest.raises(ValueError):
        constant_dims(np.zeros(3))


def test_axis_frames_make_one_dof_components_exactly_zero():
    """A 1-dof x rotation inside an axis frame rotated 20° about z: parent-relative it mixes
    x and y; in its axis frame (the AMC dof rotation) y and z are exactly zero."""
    angles = np.linspace(0, 90, 25)
    C = Rotation.from_euler("z", 20, degrees=True).as_quat()
    M = Rotation.from_euler("x", angles[:, None], degrees=True).as_quat()
    L = Q.multiply(Q.multiply(C, M), Q.conjugate(C))
    take = Take(["j"], [-1], 120.0, L[:, None, :], meta={"axis_quats": C[None]})
    assert not constant_dims(PoseFeatures(["j"], [-1], "local", "all").transform(take.quats))[1]
    X = take_features(take, "all")
    np.testing.assert_allclose(X, M, atol=1e-12)
    np.testing.assert_array_equal(constant_dims(X), [False, True, True, False])


# ---------------------------------------------------------------------------------------
# Real data

@pytest.mark.realdata
def test_real_86_01_features(data_dir):
    take = read_take(data_dir / "cmu" / "86_01.amc")
    X = take_features(take, "cmu14")
    assert X.shape == (4579, 56) and X.dtype == np.float64
    pf = PoseFeatures.for_take(take, "cmu14")
    assert pf.profile == "cmu14" and pf.joints == CMU14
    # Features are the AMC dof rotations M = Rz·Ry·Rx (frame 1 lfemur: -29.1974 1.82053 -23.3363).
    j = CMU14.index("lfemur")
    np.testing.assert_allclose(X[0, 4 * j:4 * j + 4], Rotation.from_euler(
        "xyz", [-29.1974, 1.82053, -23.3363], degrees=True).as_quat(), atol=1e-12)
    # 1-dof bones (radius, tibia): y and z zero up to rounding; nothing else constant.
    labels = np.array([f"{n}.{c}" for n in CMU14 for c in "xyzw"])
    assert np.abs(X[:, constant_dims(X)]).max() < 1e-12
    assert sorted(labels[constant_dims(X)]) == sorted(
        f"{n}.{c}" for n in ("rradius", "lradius", "rtibia", "ltibia") for c in "yz")
    assert np.linalg.matrix_rank(np.cov(X[:, ~constant_dims(X)].T)) == 48
    # Global orientations (what an IMU suit reports) give the same features.
    g = Q.global_from_local(take.quats, take.parents)
    pg = PoseFeatures(take.joint_names, take.parents, "global", "cmu14",
                      axis_quats=take.meta["axis_quats"])
    np.testing.assert_allclose(pg.transform(g), X, atol=1e-12)
    np.testing.assert_allclose(np.array([pg.step(f) for f in g[:300]]), X[:300], atol=1e-12)
    # Without axis frames: a fixed orthogonal map per joint, so pairwise distances agree.
    Xc = PoseFeatures(take.joint_names, take.parents, "local", "cmu14").transform(take.quats)
    d = np.linalg.norm(X[::200, None] - X[None, ::200], axis=-1)
    dc = np.linalg.norm(Xc[::200, None] - Xc[None, ::200], axis=-1)
    np.testing.assert_allclose(d, dc, atol=1e-9)


@pytest.mark.realdata
def test_tsseg4d_features(data_dir):
    csv = data_dir / "tsseg4d" / "86_01.csv"
    if not csv.is_file():
        pytest.skip(f"{csv} absent")
    take = read_take(csv)
    X = take_features(take)
    assert X.shape == (take.n_frames, 16)
    assert PoseFeatures.for_take(take).profile == "tsseg4d"
    np.testing.assert_array_equal(constant_dims(X), np.tile([False, True, True, False], 4))
