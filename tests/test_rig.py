"""Any humanoid rig -> the canonical joints (rtseg.core.rig), and cuts that do not depend on the
rig or the frame rate the motion comes in."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from rtseg.core import quat as Q
from rtseg.drivers.readers import read_take, write_take
from rtseg.core.features import PoseFeatures
from rtseg.evaluation.online import live_config, live_cuts
from rtseg.core.profiles import suit_profile
from rtseg.core.resample import resample_take
from rtseg.core.rig import CANONICAL, RigError, map_rig
from rtseg.detectors.segmentation import segment_take
from rtseg.simulators.synth.motion import synthesize

from conftest import DATA_DIR
from rig_variants import RIGS, in_rig
from source_folders import write_bvh


def _tree(spec: list[tuple[str, str]]) -> tuple[list[str], list[int]]:
    names = [n for n, _ in spec]
    return names, [names.index(p) if p else -1 for _, p in spec]


def _humanoid(torso: list[tuple[str, str]], arm: list[str], leg: list[str], chest: str,
              pelvis: str, side: tuple[str, str]) -> tuple[list[str], list[int]]:
    spec = list(torso)
    for s in side:
        prev = chest
        for j in arm:
            spec.append((j.format(s=s), prev))
            prev = j.format(s=s)
        prev = pelvis
        for j in leg:
            spec.append((j.format(s=s), prev))
            prev = j.format(s=s)
    return _tree(spec)


def test_named_families_map_every_canonical_joint():
    # the other CMU BVH conversion: LeftShoulder is the upper arm there, LeftHip the thigh
    names, parents = _humanoid(
        [("Hips", ""), ("Chest", "Hips"), ("Chest2", "Chest"), ("Neck", "Chest2"), ("Head", "Neck")],
        ["{s}Collar", "{s}Shoulder", "{s}Elbow", "{s}Wrist"], ["{s}Hip", "{s}Knee", "{s}Ankle"],
        "Chest2", "Hips", ("Left", "Right"))
    rig = map_rig(names, parents)
    assert rig.family == "cmu-bvh-mb"
    assert rig.joints["left_upper_arm"] == "LeftShoulder" and rig.joints["left_lower_arm"] == "LeftElbow"
    assert rig.joints["right_upper_leg"] == "RightHip" and rig.joints["spine"] == "Chest"
    assert rig.optional["left_upper_arm"] == ("LeftCollar",)
    # VRM / VMC humanoid bones in lowerCamel case, with an UpperChest the arms hang from
    names, parents = _humanoid(
        [("hips", ""), ("spine", "hips"), ("chest", "spine"), ("upperChest", "chest"),
         ("neck", "upperChest"), ("head", "neck")],
        ["{s}Shoulder", "{s}UpperArm", "{s}LowerArm", "{s}Hand"],
        ["{s}UpperLeg", "{s}LowerLeg", "{s}Foot"], "upperChest", "hips", ("left", "right"))
    rig = map_rig(names, parents)
    assert rig.family == "unity" and rig.joints["chest"] == "upperChest"
    assert rig.optional["chest"] == ("chest",)          # composed into chest | spine
    # every suit of config/suits.toml maps by name
    for suit in ("default17", "xsens-mvn", "mocopi", "rokoko", "axis"):
        s = suit_profile(suit)
        assert set(map_rig(s.bones, s.parents).joints) == set(CANONICAL)


def test_unknown_rig_by_names_and_topology():
    """The Unreal mannequin's names are in no family: found by parts, sides and topology."""
    names, parents = _humanoid(
        [("root", ""), ("pelvis", "root"), ("spine_01", "pelvis"), ("spine_02", "spine_01"),
         ("spine_03", "spine_02"), ("neck_01", "spine_03"), ("head", "neck_01")],
        ["clavicle_{s}", "upperarm_{s}", "upperarm_twist_01_{s}", "lowerarm_{s}", "hand_{s}"],
        ["thigh_{s}", "calf_{s}", "foot_{s}", "ball_{s}"], "spine_03", "pelvis", ("l", "r"))
    rig = map_rig(names, parents)
    assert rig.family == "topology"
    assert rig.joints == {
        "pelvis": "pelvis", "spine": "spine_01", "chest": "spine_03", "neck": "neck_01",
        "head": "head", "left_upper_arm": "upperarm_l", "right_upper_arm": "upperarm_r",
        "left_lower_arm": "lowerarm_l", "right_lower_arm": "lowerarm_r",
        "left_upper_leg": "thigh_l", "right_upper_leg": "thigh_r",
        "left_lower_leg": "calf_l", "right_lower_leg": "calf_r"}
    # the forearm hangs from the twist helper: it is composed, not a joint of its own
    assert rig.optional["left_lower_arm"] == ("upperarm_twist_01_l",)
    assert rig.optional["chest"] == ("spine_02",)


def test_side_words_inside_names_and_arms_that_branch_at_the_neck():
    """3ds Max Biped and Character Creator put the side between separators ("Bip01 L Thigh",
    "CC_Base_R_Calf"); Biped hangs the clavicles from its neck link, the joint the head hangs
    from: that joint is then the neck and the one below it the chest."""
    for sep in (" ", "_"):
        b = lambda x: f"Bip01{sep}{x}".replace(" ", sep)   # noqa: E731
        torso = [(b("Pelvis"), ""), (b("Spine"), b("Pelvis")), (b("Spine1"), b("Spine")),
                 (b("Spine2"), b("Spine1")), (b("Neck"), b("Spine2")), (b("Head"), b("Neck"))]
        names, parents = _humanoid(
            torso, [b("{s} Clavicle"), b("{s} UpperArm"), b("{s} Forearm"), b("{s} Hand")],
            [b("{s} Thigh"), b("{s} Calf"), b("{s} Foot")], b("Neck"), b("Pelvis"), ("L", "R"))
        rig = map_rig(names, parents)
        assert rig.family == "topology"
        assert (rig.joints["chest"], rig.joints["neck"]) == (b("Spine2"), b("Neck"))
        assert rig.joints["right_lower_leg"] == b("R Calf")
        assert rig.joints["left_upper_arm"] == b("L UpperArm")
        assert rig.optional["left_upper_arm"] == (b("Neck"), b("L Clavicle"))
    names, parents = _humanoid(
        [("CC_Base_Hip", ""), ("CC_Base_Waist", "CC_Base_Hip"), ("CC_Base_Spine01", "CC_Base_Waist"),
         ("CC_Base_Spine02", "CC_Base_Spine01"), ("CC_Base_NeckTwist01", "CC_Base_Spine02"),
         ("CC_Base_Head", "CC_Base_NeckTwist01")],
        ["CC_Base_{s}_Clavicle", "CC_Base_{s}_Upperarm", "CC_Base_{s}_Forearm", "CC_Base_{s}_Hand"],
        ["CC_Base_{s}_Thigh", "CC_Base_{s}_Calf", "CC_Base_{s}_Foot"], "CC_Base_Spine02",
        "CC_Base_Hip", ("L", "R"))
    rig = map_rig(names, parents)
    assert rig.joints["left_lower_arm"] == "CC_Base_L_Forearm"
    assert rig.joints["right_upper_leg"] == "CC_Base_R_Thigh"


def test_a_biped_bvh_keeps_the_spaces_in_its_joint_names(performance, tmp_path):
    """A 3ds Max Biped BVH file ("JOINT Bip01 L Thigh": joint names with spaces) is read with
    its names whole and mapped by names and topology."""
    biped = in_rig(performance.take, "biped")
    take = read_take(write_bvh(tmp_path / "biped.bvh", biped))
    assert sorted(take.joint_names) == sorted(biped.joint_names)
    assert "Bip01 L Thigh" in take.joint_names and "Bip01 R Forearm" in take.joint_names
    rig = PoseFeatures.for_take(take).rig
    assert rig.family == "topology" and rig.joints["left_upper_leg"] == "Bip01 L Thigh"


def test_unmappable_rig_is_one_clear_line():
    names, parents = _tree([("Hips", ""), ("Spine", "Hips"), ("Head", "Spine"),
                            ("LeftArm", "Spine"), ("RightArm", "Spine")])
    with pytest.raises(RigError) as err:
        map_rig(names, parents, "robot.bvh")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("robot.bvh: cannot map the skeleton")
    assert "lower arm" in msg and "Hips, Spine, Head" in msg
    # the features refuse it too, rather than falling back to every joint
    with pytest.raises(RigError):
        PoseFeatures(names, parents, "local")


def test_local_and_global_inputs_give_the_same_canonical_features():
    t = in_rig(synthesize("walk:3,punch:3", seed=2).take, "cmu-bvh")
    local = PoseFeatures.for_take(t).transform(t.quats)
    g = Q.global_from_local(t.quats, t.parents)
    glob = PoseFeatures(t.joint_names, t.parents, "global").transform(g)
    np.testing.assert_allclose(glob, local, atol=1e-12)
    pf = PoseFeatures.for_take(t)
    np.testing.assert_allclose(np.array([pf.step(q) for q in t.quats[:50]]), local[:50], atol=1e-12)


@pytest.fixture(scope="module")
def performance():
    return synthesize(seed=3)


def _live_times(take) -> np.ndarray:
    cfg, default = live_config()
    return np.array([c.boundary / take.frame_rate for c in live_cuts(take, cfg)[default]])


def _close(a: np.ndarray, b: np.ndarray, tol: float) -> bool:
    return len(a) == len(b) and bool(np.all(np.abs(a - b) <= tol))


def test_four_rigs_cut_alike(performance, tmp_path):
    """The same motion in the ASF, cgspeed BVH, Mixamo and Bandai rigs, and in 3ds Max
    Biped's, which no family knows (written to a file and read back), gives the same live
    and offline cuts."""
    ref_live = _live_times(performance.take)
    ref_off = segment_take(performance.take, "contrast").cut_frames
    assert len(ref_live) >= 6
    for rig in (*RIGS, "biped"):
        path = write_take(tmp_path / f"{rig}.npz", in_rig(performance.take, rig))
        take = read_take(path)
        assert PoseFeatures.for_take(take).rig.family == (rig if rig in RIGS else "topology")
        got = _live_times(take)
        assert _close(got, ref_live, 0.25), (rig, got, ref_live)
        assert segment_take(take, "contrast").cut_frames == ref_off


@pytest.mark.parametrize("rate", [30.0, 60.0, 90.0])
def test_frame_rates_cut_alike(performance, rate):
    """Resampled to 30, 60 and 90 fps (and in the Bandai rig at 30 fps, as that data set
    comes), the live cuts lie within 0.25 s of the 120 fps ones."""
    ref = _live_times(performance.take)
    got = _live_times(resample_take(performance.take, rate))
    assert _close(got, ref, 0.25), (rate, got, ref)
    if rate == 30.0:
        bandai = _live_times(resample_take(in_rig(performance.take, "bandai"), rate))
        assert _close(bandai, ref, 0.25), (bandai, ref)


def test_resample_keeps_time_and_motion():
    take = synthesize("walk:3", seed=1).take
    r = resample_take(take, 30.0)
    assert r.frame_rate == 30.0 and r.n_frames == int((take.n_frames - 1) / 4) + 1
    # every 4th frame of the 120 fps take is an exact sample at 30 fps
    np.testing.assert_allclose(np.abs(np.sum(r.quats * take.quats[::4][:r.n_frames], axis=-1)),
                               1.0, atol=1e-12)
    with pytest.raises(ValueError, match="positive"):
        resample_take(take, 0)


@pytest.mark.realdata
def test_segment_json_reports_the_joints_used():
    bvh = DATA_DIR / "bandai" / "bvh" / "bn1_001.bvh"
    if not bvh.is_file():
        pytest.skip(f"{bvh} absent")
    p = subprocess.run([sys.executable, "-m", "rtseg.cli", "segment", str(bvh), "--method", "pca",
                        "--format", "json"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    feats = json.loads(p.stdout)["features"]
    assert feats["profile"] == "canonical" and feats["rig"] == "bandai"
    assert feats["joints"]["left_upper_arm"] == "UpperArm_L"
    assert feats["composed"]["left_upper_arm"] == ["Shoulder_L"]
