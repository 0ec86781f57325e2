"""Retargeting a take onto a suit's sensors (rtseg.simulators.retarget): skeleton maps,
forward kinematics against an independent matrix computation, IMU noise and drift."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.core.profiles import suit_profile
from rtseg.simulators.retarget import (MAPS, ImuModel, RetargetError, forward_kinematics,
                                       resolve, retarget)
from rtseg.simulators.synth.motion import synthesize
from rtseg.core.take import Take

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
CMU_AMC = DATA / "cmu" / "86_01.amc"
CMU_BVH = DATA / "cmu_single" / "bvh" / "02_01.bvh"
SUIT = suit_profile("default17")

#: The CMU ASF bones and parents in the order the ASF reader gives them (86.asf).
CMU_ASF_NAMES = [
    "root", "lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes", "rhipjoint", "rfemur", "rtibia",
    "rfoot", "rtoes", "lowerback", "upperback", "thorax", "lowerneck", "upperneck", "head",
    "lclavicle", "lhumerus", "lradius", "lwrist", "lhand", "lfingers", "lthumb", "rclavicle",
    "rhumerus", "rradius", "rwrist", "rhand", "rfingers", "rthumb"]
CMU_PARENTS = [-1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14, 15, 13, 17, 18, 19, 20,
               21, 20, 13, 24, 25, 26, 27, 28, 27]
#: The CMU BVH ("cgspeed") joints, same hierarchy as the ASF.
CMU_BVH_NAMES = [
    "Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RHipJoint",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "LowerBack", "Spine", "Spine1",
    "Neck", "Neck1", "Head", "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand",
    "LeftFingerBase", "LeftHandIndex1", "LThumb", "RightShoulder", "RightArm", "RightForeArm",
    "RightHand", "RightFingerBase", "RightHandIndex1", "RThumb"]
#: A Mixamo rig (prefixed names), arms and legs only down to the feet and hands.
MIXAMO_NAMES = ["mixamorig:Hips", "mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2",
                "mixamorig:Neck", "mixamorig:Head", "mixamorig:HeadTop_End",
                "mixamorig:LeftShoulder", "mixamorig:LeftArm", "mixamorig:LeftForeArm",
                "mixamorig:LeftHand", "mixamorig:RightShoulder", "mixamorig:RightArm",
                "mixamorig:RightForeArm", "mixamorig:RightHand", "mixamorig:LeftUpLeg",
                "mixamorig:LeftLeg", "mixamorig:LeftFoot", "mixamorig:LeftToeBase",
                "mixamorig:RightUpLeg", "mixamorig:RightLeg", "mixamorig:RightFoot",
                "mixamorig:RightToeBase"]
MIXAMO_PARENTS = [-1, 0, 1, 2, 3, 4, 5, 3, 7, 8, 9, 3, 11, 12, 13, 0, 15, 16, 17, 0, 19, 20, 21]

#: The Daz / Poser rig of CMU's Daz-friendly BVH conversion (10_04), fingers left out
DAZ_NAMES = ["hip", "abdomen", "chest", "neck", "head", "lCollar", "lShldr", "lForeArm",
             "lHand", "rCollar", "rShldr", "rForeArm", "rHand", "lButtock", "lThigh",
             "lShin", "lFoot", "rButtock", "rThigh", "rShin", "rFoot"]
DAZ_PARENTS = [-1, 0, 1, 2, 3, 2, 5, 6, 7, 2, 9, 10, 11, 0, 13, 14, 15, 0, 17, 18, 19]

#: What each family must give each suit bone (the segment the sensor is strapped to).
EXPECTED = {
    "cmu-asf": ["root", "lowerback", "thorax", "lowerneck", "head", "lhumerus", "lradius",
                "lhand", "rhumerus", "rradius", "rhand", "lfemur", "ltibia", "lfoot", "rfemur",
                "rtibia", "rfoot"],
    "cmu-bvh": ["Hips", "LowerBack", "Spine1", "Neck", "Head", "LeftArm", "LeftForeArm",
                "LeftHand", "RightArm", "RightForeArm", "RightHand", "LeftUpLeg", "LeftLeg",
                "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot"],
    "mixamo": ["mixamorig:" + n for n in [
        "Hips", "Spine", "Spine2", "Neck", "Head", "LeftArm", "LeftForeArm", "LeftHand",
        "RightArm", "RightForeArm", "RightHand", "LeftUpLeg", "LeftLeg", "LeftFoot",
        "RightUpLeg", "RightLeg", "RightFoot"]],
    "daz": ["hip", "abdomen", "chest", "neck", "head", "lShldr", "lForeArm", "lHand",
            "rShldr", "rForeArm", "rHand", "lThigh", "lShin", "lFoot", "rThigh", "rShin",
            "rFoot"],
}


def random_take(names, parents, n=50, seed=0, rate=120.0) -> Take:
    rng = np.random.default_rng(seed)
    q = Rotation.random(n * len(names), random_state=rng.integers(1 << 31)).as_quat()
    return Take(list(names), list(parents), rate, q.reshape(n, len(names), 4), space="local")


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation angle between unit quaternions a and b, degrees."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    rel = Rotation.from_quat(a.reshape(-1, 4)).inv() * Rotation.from_quat(b.reshape(-1, 4))
    return np.degrees(rel.magnitude()).reshape(a.shape[:-1])


@pytest.mark.parametrize("family, names, parents", [
    ("cmu-asf", CMU_ASF_NAMES, CMU_PARENTS),
    ("cmu-bvh", CMU_BVH_NAMES, CMU_PARENTS),
    ("mixamo", MIXAMO_NAMES, MIXAMO_PARENTS),
    ("daz", DAZ_NAMES, DAZ_PARENTS),
])
def test_each_family_is_detected_and_places_every_sensor(family, names, parents):
    take = random_take(names, parents, n=5)
    res = resolve(take, SUIT)
    assert res.family == family and not res.missing
    assert [names[c] for c in res.columns] == EXPECTED[family]


def test_cmu_bvh_names_are_not_taken_as_unity_names():
    """cgspeed's Spine/Neck/Head/LeftHand are also HumanBodyBones names, but its Spine is
    the mid back: matching by name alone (the old bug) would put Chest nowhere."""
    res = resolve(random_take(CMU_BVH_NAMES, CMU_PARENTS, n=2), SUIT)
    assert res.family == "cmu-bvh"
    assert CMU_BVH_NAMES[res.columns[SUIT.bones.index("Spine")]] == "LowerBack"


def test_unity_takes_map_to_themselves():
    truth = synthesize("walk:1.5", seed=2)
    rt = retarget(truth.take, SUIT)
    assert rt.family == "unity" and rt.present.all() and rt.valid.all()
    assert [truth.take.joint_names[c] for c in rt.columns] == list(SUIT.bones)
    g = forward_kinematics(truth.take)
    assert angle_deg(rt.quats, g).max() < 1e-6
    # local() undoes the forward kinematics in the suit's hierarchy (= the synth's)
    assert angle_deg(rt.local(), truth.take.quats).max() < 1e-6


@pytest.mark.skipif(not CMU_AMC.exists(), reason=f"CMU data not found at {CMU_AMC}")
def test_real_cmu_asf_amc_take_places_every_sensor():
    from rtseg.drivers.readers import read_take
    take = read_take(CMU_AMC)
    rt = retarget(take, SUIT)
    assert rt.family == "cmu-asf" and rt.present.all() and rt.valid.all()
    assert rt.quats.shape == (take.n_frames, 17, 4)
    assert np.allclose(np.linalg.norm(rt.quats, axis=-1), 1.0)
    # sign-continuous over time, as a live stream must be
    assert (np.sum(rt.quats[1:] * rt.quats[:-1], axis=-1) >= 0).all()


@pytest.mark.skipif(not CMU_BVH.exists(), reason=f"CMU BVH data not found at {CMU_BVH}")
def test_real_cmu_bvh_take_places_every_sensor():
    from rtseg.drivers.readers import read_take
    take = read_take(CMU_BVH)
    res = resolve(take, SUIT)
    assert res.family == "cmu-bvh" and not res.missing
    assert [take.joint_names[c] for c in res.columns] == EXPECTED["cmu-bvh"]


DAZ_BVH = CMU_BVH.parent / "10_04.bvh"


@pytest.mark.skipif(not DAZ_BVH.exists(), reason=f"CMU Daz-style BVH not found at {DAZ_BVH}")
def test_real_daz_bvh_take_places_every_sensor():
    from rtseg.drivers.readers import read_take
    take = read_take(DAZ_BVH)
    rt = retarget(take, SUIT)
    assert rt.family == "daz" and rt.present.all() and rt.valid.all()
    assert [take.joint_names[c] for c in rt.columns] == EXPECTED["daz"]


def test_unmapped_bones_are_a_clear_error_naming_them():
    names = [n for n in CMU_ASF_NAMES if n not in ("lhand", "lwrist", "rfoot")]
    parents = [-1] + [0] * (len(names) - 1)
    with pytest.raises(RetargetError) as info:
        resolve(random_take(names, parents, n=2), SUIT)
    msg = str(info.value)
    assert "'cmu-asf'" in msg and "2 of suit 'default17'" in msg
    assert "LeftHand (looked for lhand or lwrist)" in msg
    assert "RightFoot (looked for rfoot)" in msg
    assert "RightHand" not in msg.split("joints in the take")[0]
    # lwrist stands in for a missing lhand
    names = [n for n in CMU_ASF_NAMES if n != "lhand"]
    res = resolve(random_take(names, [-1] + [0] * (len(names) - 1), n=2), SUIT)
    assert names[res.columns[SUIT.bones.index("LeftHand")]] == "lwrist"
    # a forced family that does not fit names every bone it lacks
    with pytest.raises(RetargetError, match=r"skeleton map 'mixamo'.*Hips \(looked for Hips\)"):
        resolve(random_take(CMU_ASF_NAMES, CMU_PARENTS, n=2), SUIT, family="mixamo")
    with pytest.raises(RetargetError, match="unknown skeleton map 'nope'"):
        resolve(random_take(CMU_ASF_NAMES, CMU_PARENTS, n=2), SUIT, family="nope")
    with pytest.raises(RetargetError, match="no known skeleton family.*joints in the take: a, b"):
        resolve(random_take(["a", "b"], [-1, 0], n=2), SUIT)


def test_joint_map_overrides_and_is_checked():
    names = [n for n in CMU_ASF_NAMES if n != "head"]
    take = random_take(names, [-1] + [0] * (len(names) - 1), n=2)
    res = resolve(take, SUIT, joint_map={"head": "upperneck"})      # bone names any case
    assert names[res.columns[SUIT.bones.index("Head")]] == "upperneck"
    with pytest.raises(RetargetError, match="'Skull' is not a bone of suit"):
        resolve(take, SUIT, joint_map={"Skull": "upperneck"})
    with pytest.raises(RetargetError, match="has no joint 'cranium'"):
        resolve(take, SUIT, joint_map={"Head": "cranium"})
    res = resolve(take, SUIT, allow_missing=True)
    assert res.missing == ("Head",) and res.columns[SUIT.bones.index("Head")] == -1


def _matrix_fk(take: Take) -> np.ndarray:
    """Independent forward kinematics with rotation matrices: R_j = R_parent @ L_j."""
    L = Rotation.from_quat(take.quats.reshape(-1, 4)).as_matrix().reshape(
        take.n_frames, take.n_joints, 3, 3)
    R = np.empty_like(L)
    for j, p in enumerate(take.parents):
        R[:, j] = L[:, j] if p < 0 else np.einsum("fab,fbc->fac", R[:, p], L[:, j])
    return R


def test_forward_kinematics_matches_an_independent_matrix_computation():
    take = random_take(CMU_ASF_NAMES, CMU_PARENTS, n=40, seed=3)
    rt = retarget(take, SUIT)
    R = _matrix_fk(take)
    got = Rotation.from_quat(rt.quats.reshape(-1, 4)).as_matrix().reshape(40, 17, 3, 3)
    np.testing.assert_allclose(got, R[:, list(rt.columns)], atol=1e-12)


def test_known_pose_arm_raised_and_body_turned():
    """Left shoulder (lhumerus) abducted 90 deg about world -Z, forearm and hand straight,
    whole body turned 90 deg about +Y: the left arm sensors read turn ⊗ raise, the other
    sensors read the turn alone."""
    n = len(CMU_ASF_NAMES)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (1, n, 1))
    turn = Rotation.from_euler("y", 90, degrees=True)
    raise_ = Rotation.from_euler("z", -90, degrees=True)
    q[0, 0] = turn.as_quat()
    q[0, CMU_ASF_NAMES.index("lhumerus")] = raise_.as_quat()
    rt = retarget(Take(CMU_ASF_NAMES, CMU_PARENTS, 120.0, q), SUIT)
    arm = {"LeftUpperArm", "LeftLowerArm", "LeftHand"}
    for k, bone in enumerate(SUIT.bones):
        want = (turn * raise_) if bone in arm else turn
        assert angle_deg(rt.quats[0, k], want.as_quat()) < 1e-9, bone
    # geometry by hand: the left arm's rest direction (+X in the CMU T-pose) is rotated
    # -90 deg about Z to -Y (down), then the body turn (+90 deg about Y) leaves -Y alone;
    # the hips' +X (to the subject's left) turns to -Z
    arm = Rotation.from_quat(rt.quats[0, SUIT.bones.index("LeftUpperArm")])
    np.testing.assert_allclose(arm.apply([1, 0, 0]), [0, -1, 0], atol=1e-12)
    hips = Rotation.from_quat(rt.quats[0, SUIT.bones.index("Hips")])
    np.testing.assert_allclose(hips.apply([1, 0, 0]), [0, 0, -1], atol=1e-12)


def test_take_validity_propagates_down_the_chain():
    take = random_take(CMU_ASF_NAMES, CMU_PARENTS, n=6)
    take.valid = np.ones((6, len(CMU_ASF_NAMES)), dtype=bool)
    take.valid[2, CMU_ASF_NAMES.index("lhumerus")] = False
    rt = retarget(take, SUIT)
    bad = {SUIT.bones[k] for k in np.flatnonzero(~rt.valid[2])}
    assert bad == {"LeftUpperArm", "LeftLowerArm", "LeftHand"}
    assert rt.valid[[0, 1, 3, 4, 5]].all()


def test_imu_noise_and_drift_are_seeded_and_reproducible():
    take = synthesize("walk:2", seed=1).take            # 240 frames at 120 Hz
    clean = retarget(take, SUIT).quats
    imu = ImuModel(noise_deg=0.5, drift_deg_per_min=30.0, seed=7)
    a = retarget(take, SUIT, imu=imu).quats
    b = retarget(take, SUIT, imu=ImuModel.parse("noise=0.5,drift=30,seed=7")).quats
    c = retarget(take, SUIT, imu=ImuModel(noise_deg=0.5, drift_deg_per_min=30.0, seed=8)).quats
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    err = angle_deg(a, clean)
    assert 0.2 < np.median(err[:12]) < 2.0            # ~0.5 deg per axis at the start
    # drift alone: rotation about world +Y growing linearly, at most 30 deg/min (= 1 deg
    # over the 2 s take), and different sensors drift differently
    d = retarget(take, SUIT, imu=ImuModel(drift_deg_per_min=30.0, seed=7)).quats
    rel = Rotation.from_quat(d.reshape(-1, 4)) * Rotation.from_quat(clean.reshape(-1, 4)).inv()
    rv = rel.as_rotvec().reshape(240, 17, 3)
    assert np.abs(rv[..., [0, 2]]).max() < 1e-9                        # about Y only
    yaw = np.degrees(rv[..., 1])
    t = np.arange(240) / 120.0
    rates = yaw[-1] / t[-1]                                             # deg per s
    np.testing.assert_allclose(yaw, t[:, None] * rates[None, :], atol=1e-9)
    assert np.abs(rates).max() <= 30.0 / 60.0 and np.ptp(rates) > 0.05
    # off by default
    assert np.array_equal(retarget(take, SUIT, imu=ImuModel()).quats, clean)


@pytest.mark.parametrize("spec, fragment", [
    ("noise=-1", "noise_deg must be a finite number >= 0"),
    ("drift=nan", "drift_deg_per_min must be a finite number >= 0"),
    ("wobble=2", "expected noise=DEG"),
    ("noise=abc", "noise needs a number"),
])
def test_imu_spec_errors(spec, fragment):
    with pytest.raises(ValueError, match=fragment):
        ImuModel.parse(spec)


def test_every_map_covers_every_default17_bone():
    low = {b.lower() for b in SUIT.bones}
    for m in MAPS.values():
        assert low <= {k.lower() for k in m.bones}, m.name


def test_a_rig_no_family_names_is_placed_by_its_canonical_joints():
    """Joint names no skeleton map knows (a prefix on every joint, as exporters write) are
    placed as the readers map any rig (rtseg.core.rig: names and topology): every default17
    bone gets the joint it has in the plain rig, and the suit's orientations are the same."""
    import sys
    sys.path.insert(0, str(Path(__file__).parent))
    from rig_variants import in_rig
    take = in_rig(synthesize("walk:2,squat:2", seed=2).take, "bandai")
    renamed = Take([f"Character1_{n}" for n in take.joint_names], take.parents,
                   take.frame_rate, take.quats, take.root_position, take.space, None,
                   take.length_unit, "prefixed")
    plain, pref = resolve(take, SUIT), resolve(renamed, SUIT)
    assert plain.family == "bandai" and pref.family == "topology" and not pref.missing
    assert pref.columns == plain.columns
    a, b = retarget(take, SUIT), retarget(renamed, SUIT)
    np.testing.assert_allclose(a.local(), b.local())
    # names that say nothing and a flat hierarchy: one error, nothing placed
    flat = Take([f"j{k:02d}" for k in range(len(take.joint_names))],
                [-1] + [0] * (len(take.joint_names) - 1), take.frame_rate, take.quats,
                None, "local", None, take.length_unit, "generic")
    with pytest.raises(RetargetError, match="no joint for any of suit 'default17''s bones"):
        resolve(flat, SUIT, allow_missing=True)
