"""The standard T-pose for sources that send no rig geometry (rtseg.core.standard_rig): its
posture lies near the rig's own; the facing probe tells a T-pose facing +Z from one turned
half a revolution by the knees, and gives up, saying why, on rotations that fit neither;
a live VMC session whose sender sends zero bone positions names by posture with it, over
real UDP, and records the geometry it used."""

from __future__ import annotations


import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.core.posture import Posture, RestPose, take_posture
from rtseg.core.standard_rig import MIN_BENT, FacingProbe, standard_rest
from rtseg.simulators.synth.motion import synthesize

from vendor_helpers import free_port, run_while_sending

HALF_TURN = Rotation.from_euler("y", 180, degrees=True)


@pytest.fixture(scope="module")
def take():
    """A synthetic performer (default17 bones, T-pose at identity, facing +Z) walking,
    squatting and punching."""
    return synthesize("walk:5,squat:5,punch:4", frame_rate=120.0, seed=1).take


def turned(quats: np.ndarray) -> np.ndarray:
    """The same motion on a rig whose T-pose faces the other way (VRM 0.x against 1.0)."""
    r = Rotation.from_quat(quats.reshape(-1, 4))
    return (HALF_TURN * r * HALF_TURN.inv()).as_quat().reshape(quats.shape)


def probe_over(take, quats: np.ndarray, every: int = 4, max_frames: int = 1800) -> FacingProbe:
    p = FacingProbe(take.joint_names, take.parents, take.space, max_frames=max_frames)
    for k in range(0, len(quats), every):
        p.observe(quats[k])
        if p.result is not None or p.failed is not None:
            break
    return p


def test_the_standard_pose_places_the_body_near_the_rig_own_geometry(take):
    rest = standard_rest(take.joint_names, take.parents)
    rows = Posture(take.joint_names, take.parents, rest, take.space).transform(take.quats)
    own = take_posture(take)
    # another body's proportions: within 0.15 leg lengths everywhere, 0.03 on average
    assert np.abs(rows - own).max() < 0.15
    assert np.abs(rows - own).mean() < 0.03
    # a half turn changes x and z only
    back = standard_rest(take.joint_names, take.parents, turned=True).positions
    np.testing.assert_allclose(back * [-1.0, 1.0, -1.0], rest.positions)


@pytest.mark.parametrize("half_turn", [False, True])
def test_the_probe_tells_the_facing_from_the_knees(take, half_turn):
    quats = turned(take.quats) if half_turn else take.quats
    p = probe_over(take, quats)
    assert p.failed is None and p.result is not None
    assert p.turned is half_turn and p.bent >= MIN_BENT
    # with the facing it chose, the posture is the one of the performer facing +Z
    rows = Posture(take.joint_names, take.parents, p.result, take.space).transform(quats)
    ref = Posture(take.joint_names, take.parents, standard_rest(take.joint_names, take.parents),
                  take.space).transform(take.quats)
    assert np.abs(rows - ref).max() < 1e-9
    # the other facing bends every knee backwards
    wrong = standard_rest(take.joint_names, take.parents, turned=not half_turn)
    bad = Posture(take.joint_names, take.parents, wrong, take.space).transform(quats)
    assert np.abs(bad - ref).max() > 0.5


def test_the_probe_gives_up_on_a_body_that_never_bends_a_knee(take):
    still = np.tile([0.0, 0.0, 0.0, 1.0], (400, len(take.joint_names), 1))
    p = probe_over(take, still, every=1, max_frames=300)
    assert p.result is None and p.failed == "0 bent knees in 300 frames"


def test_the_probe_gives_up_on_legs_that_never_hang_down(take):
    # the same motion with the hips turned a quarter about X: the body lies on its back, as
    # a rig whose rest pose is not upright would move
    q = take.quats.copy()
    lying = Rotation.from_euler("x", -90, degrees=True)
    q[:, 0] = (lying * Rotation.from_quat(q[:, 0])).as_quat()
    p = probe_over(take, q, max_frames=len(q) // 4)
    assert p.result is None
    assert p.failed is not None and p.failed.startswith("the ankles never lie lower than")


def test_a_live_vmc_sender_without_positions_names_by_the_standard_pose(tmp_path, caplog):
    """Over real UDP: a VMC sender that sends zero bone positions; the session's library
    names by posture; the facing probe decides on the stream, the names use posture from
    then on, and the recording keeps the geometry used."""
    import logging
    from rtseg.drivers.readers import read_take
    from rtseg.library.examples import learn, synthetic_examples
    from rtseg.library.file import save
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    from rtseg.simulators.vmc_sender import VmcSender
    from rtseg.evaluation.online import live_config
    cfg0, _ = live_config()
    lib, _ = learn(synthetic_examples(["walk", "squat", "punch"], [3, 4], cfg0, seconds=6.0))
    assert lib.names_by_posture
    path = save(lib, tmp_path / "lib.json")
    perf = synthesize("walk:6,squat:6,punch:6,walk:6", frame_rate=120.0, seed=1).take
    port = free_port()
    rec = tmp_path / "rec"
    cfg = from_dict({"output": {"osc": []}, "recording": {"dir": str(rec)},
                     "identity": {"enabled": True, "behaviours": str(path)}}, origin="test")
    speed = 4.0
    session = LiveSession(f"osc://127.0.0.1:{port}?format=vmc&rate=120", cfg,
                          handle_signals=False, duration=perf.n_frames / 120.0 / speed + 1.5)
    sender = VmcSender(perf, "127.0.0.1", port, speed=speed)
    sender.bone_positions = None                     # a sender without positions
    with caplog.at_level(logging.INFO, logger="rtseg.live.posture_switch"):
        run_while_sending(session, sender)
    assert session.source.rest_pose is None and session.source.t_pose_without_geometry
    sp = session.pipeline.posture
    assert sp.origin == "standard" and sp.posture is not None
    assert "the standard T-pose, facing +Z" in caplog.text
    st = session.pipeline.identity.stats
    assert 1 <= st.posture_namings <= st.decisions
    rest = RestPose.find(read_take(rec))
    assert rest is not None
    np.testing.assert_allclose(rest.positions, sp.geometry.positions)


def test_an_axis_stream_without_displacement_gets_the_standard_pose_by_its_knees(take):
    """Over real UDP: Axis binary frames without displacement carry no geometry; the
    source says so, and its (global) rotations are from a T-pose: the probe decides on
    them and the posture is the performer's by the standard pose."""
    from rtseg.drivers.axis.source import AxisBinarySource
    from rtseg.simulators.axis_sender import AxisSender
    from test_vmc_live import read_all
    src = AxisBinarySource("127.0.0.1", 0, queue_size=8192)
    try:
        assert not src.t_pose_without_geometry
        with AxisSender(take, "binary", "127.0.0.1", src.port, speed=8.0,
                        displacement=False) as snd:
            snd.wait(10.0)
        frames = read_all(src)
        assert src.rest_pose is None and src.t_pose_without_geometry
    finally:
        src.close()
    assert len(frames) == take.n_frames
    quats = np.stack([f.quats for f in frames])
    p = FacingProbe(src.joint_names, src.parents, src.space)
    for q in quats[::4]:
        p.observe(q)
    assert p.result is not None and p.turned is False
    rows = Posture(src.joint_names, src.parents, p.result, src.space).transform(quats)
    ref = Posture(take.joint_names, take.parents, standard_rest(take.joint_names, take.parents),
                  take.space).transform(take.quats)
    # Axis's rig has more spine and neck joints than the take and Euler angles on the
    # wire: within 0.03 leg lengths
    assert np.abs(rows - ref).max() < 0.03


#: the ASF people the standard pose's proportions are the mean of (module doc)
PEOPLE = {"hdm05/amc": ("bd_001", "bk_001", "dg_001"),
          "cmu_single/amc": ("10_01", "16_01", "64_01")}


def test_the_standard_proportions_are_the_mean_of_six_people(data_dir):
    """Heights and arm spans of T_POSE against the mean of the six ASF people's rest
    geometry (leg lengths about the hips' midpoint). The table is symmetric with straight
    legs, where the ASF rest pose spreads them, and its pelvis and spine are a humanoid
    avatar's, not the ASF root's."""
    from rtseg.core.rig import map_rig
    from rtseg.core.standard_rig import T_POSE
    from rtseg.drivers.readers import read_take
    found = {}
    for folder, takes in PEOPLE.items():
        for name in takes:
            path = data_dir / folder / f"{name}.amc"
            if not path.is_file():
                pytest.skip(f"{path} not found")
            t = read_take(path)
            R = RestPose.of_take(t).positions
            idx = map_rig(t.joint_names, t.parents).index
            loc = {c: R[idx[c]] for c in T_POSE if c in idx}
            for side in ("left", "right"):
                for limb, end in (("lower_arm", "hand"), ("lower_leg", "foot")):
                    loc[f"{side}_{end}"] = R[t.parents.index(idx[f"{side}_{limb}"])]
            mid = 0.5 * (loc["left_upper_leg"] + loc["right_upper_leg"])
            leg = (np.linalg.norm(loc["left_lower_leg"] - loc["left_upper_leg"])
                   + np.linalg.norm(loc["left_foot"] - loc["left_lower_leg"]))
            for c, v in loc.items():
                found.setdefault(c, []).append((v - mid) / leg)
    mean = {c: np.mean(v, axis=0) for c, v in found.items()}
    for c in T_POSE:
        if c in ("pelvis", "spine"):
            continue
        assert abs(T_POSE[c][1] - mean[c][1]) < 0.03, c                  # heights
    for side in ("left", "right"):
        for c in (f"{side}_upper_arm", f"{side}_lower_arm", f"{side}_hand", f"{side}_upper_leg"):
            assert abs(T_POSE[c][0] - mean[c][0]) < 0.02, c              # spans


def test_a_serial_suit_declared_tpose_names_by_the_standard_pose(tmp_path):
    """``serial://...?tpose=1`` (a suit whose firmware sends each segment's rotation from a
    T-pose, as the simulated suit does): over a real pseudo-terminal the session's facing
    probe decides and names use posture; without the option they never do."""
    from rtseg.drivers import open_source
    from rtseg.drivers.base import SourceError
    from rtseg.evaluation.online import live_config
    from rtseg.library.examples import learn, synthetic_examples
    from rtseg.library.file import save
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    from rtseg.simulators.serial_device import SerialSuit
    cfg0, _ = live_config()
    lib, _ = learn(synthetic_examples(["walk", "squat", "punch"], [3, 4], cfg0, seconds=6.0))
    path = save(lib, tmp_path / "lib.json")
    perf = synthesize("walk:5,squat:5,punch:5", frame_rate=120.0, seed=1).take
    origins = {}
    for opt in ("&tpose=1", ""):
        suit = SerialSuit(perf, rate=120.0, speed=4.0)
        link = suit.start()
        try:
            cfg = from_dict({"output": {"osc": []},
                             "identity": {"enabled": True, "behaviours": str(path)}})
            session = LiveSession(f"serial://{link}?rate=120{opt}", cfg, handle_signals=False,
                                  duration=perf.n_frames / 120.0 / 4.0 + 0.6)
            session.run()
        finally:
            suit.stop()
        st = session.pipeline.identity.stats
        origins[opt] = (session.pipeline.posture.origin, st.posture_namings >= 1)
    assert origins == {"&tpose=1": ("standard", True), "": (None, False)}
    with pytest.raises(SourceError, match="tpose"):
        open_source("serial:///dev/null?tpose=maybe")
