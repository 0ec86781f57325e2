"""A VMC sender's rest geometry from the bone positions it sends (rtseg.drivers.osc.vmc.rest):
chained along Unity's humanoid hierarchy, the bones the profile leaves out counted; over a
real UDP socket it gives the posture of the take sent, and a live pipeline with a posture
library names by posture once the first frames have come, and never when the sender sends
no positions."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.core.posture import Posture, take_posture
from rtseg.drivers.osc.source import OscVmcSource
from rtseg.drivers.osc.vmc.codec import VmcAssembler, encode_frame
from rtseg.drivers.osc.vmc.rest import CAPTURE_FRAMES, CAPTURE_LIMIT
from rtseg.simulators.vmc_sender import VmcSender

from test_library_posture import FR, swing, library
from test_vmc_live import PARENTS, SUIT, read_all
from vendor_helpers import free_port, run_while_sending

#: local positions (rtseg frame, metres) of a small avatar with shoulders and an upper chest
AVATAR = {
    "Hips": (0.0, 0.9, 0.0), "Spine": (0.0, 0.1, 0.0), "Chest": (0.0, 0.12, 0.0),
    "UpperChest": (0.0, 0.1, 0.0), "Neck": (0.0, 0.12, 0.0), "Head": (0.0, 0.1, 0.0),
    "LeftShoulder": (0.05, 0.08, 0.0), "RightShoulder": (-0.05, 0.08, 0.0),
    "LeftUpperArm": (0.1, 0.0, 0.0), "RightUpperArm": (-0.1, 0.0, 0.0),
    "LeftLowerArm": (0.27, 0.0, 0.0), "RightLowerArm": (-0.27, 0.0, 0.0),
    "LeftHand": (0.25, 0.0, 0.0), "RightHand": (-0.25, 0.0, 0.0),
    "LeftUpperLeg": (0.09, -0.05, 0.0), "RightUpperLeg": (-0.09, -0.05, 0.0),
    "LeftLowerLeg": (0.0, -0.42, 0.0), "RightLowerLeg": (0.0, -0.42, 0.0),
    "LeftFoot": (0.0, -0.4, 0.0), "RightFoot": (0.0, -0.4, 0.0),
}


def avatar_frames(names, positions, frames: int) -> list[list[bytes]]:
    quats = np.tile([0.0, 0.0, 0.0, 1.0], (len(names), 1))
    return [encode_frame(quats, names, time=k / 60.0, bone_positions=positions)
            for k in range(frames)]


def fed(asm: VmcAssembler, frames: list[list[bytes]]) -> None:
    for k, dgrams in enumerate(frames):
        for d in dgrams:
            asm.feed(d, k / 60.0)
    asm.flush(1e9, force=True)


def test_rest_geometry_chains_the_bones_the_profile_leaves_out():
    """The sender sends UpperChest and shoulders, which default17 does not hold: an upper
    arm's rest location still counts them (its local position is from its shoulder)."""
    names = list(AVATAR)
    pos = np.array([AVATAR[n] for n in names])
    asm = VmcAssembler(SUIT, parents=PARENTS)
    fed(asm, avatar_frames(names, pos, CAPTURE_FRAMES + 2))
    rest = asm.offsets.rest_pose()
    assert rest is not None
    at = {n: rest.positions[SUIT.index(n)] for n in SUIT}
    np.testing.assert_allclose(at["Hips"], 0.0)             # the hips' travel is left out
    np.testing.assert_allclose(at["LeftUpperArm"], [0.15, 0.4, 0.0], atol=1e-6)
    np.testing.assert_allclose(at["Head"], [0.0, 0.54, 0.0], atol=1e-6)
    np.testing.assert_allclose(at["RightFoot"], [-0.09, -0.87, 0.0], atol=1e-6)
    assert asm.stats.unknown_names > 0                     # still counted as not in the profile


def test_no_rest_geometry_before_the_first_frames_nor_from_zero_positions():
    names = list(AVATAR)
    pos = np.array([AVATAR[n] for n in names])
    asm = VmcAssembler(SUIT, parents=PARENTS)
    fed(asm, avatar_frames(names, pos, 2))
    assert asm.offsets.rest_pose() is None                 # still capturing
    hips_only = np.zeros_like(pos)                          # the hips' travel alone
    hips_only[names.index("Hips")] = (0.2, 0.9, -1.0)
    for sent in (None, hips_only):
        zero = VmcAssembler(SUIT, parents=PARENTS)
        fed(zero, avatar_frames(names, sent, CAPTURE_FRAMES + 2))
        assert not zero.offsets.capturing                 # decided: no geometry
        assert zero.offsets.rest_pose() is None


def test_a_profile_bone_never_sent_ends_the_capture_all_the_same():
    """No Neck from this sender: capture ends after CAPTURE_LIMIT frames and the head hangs
    at the upper chest (the bones it does send keep their places)."""
    names = [n for n in AVATAR if n != "Neck"]
    pos = np.array([AVATAR[n] for n in names])
    asm = VmcAssembler(SUIT, parents=PARENTS)
    fed(asm, avatar_frames(names, pos, CAPTURE_LIMIT - 1))
    assert asm.offsets.capturing and asm.offsets.rest_pose() is None
    fed(asm, avatar_frames(names, pos, 2))
    rest = asm.offsets.rest_pose()
    assert rest is not None
    np.testing.assert_allclose(rest.positions[SUIT.index("Head")], [0.0, 0.42, 0.0], atol=1e-6)
    np.testing.assert_allclose(rest.positions[SUIT.index("LeftUpperArm")], [0.15, 0.4, 0.0],
                               atol=1e-6)


@pytest.fixture
def received():
    """A swing take (a rig with shoulders and a spine of its own names) sent by the VMC
    simulator, read back by an ``osc://`` VMC source on 127.0.0.1."""
    take = swing(80.0, 3, seconds=4.0)
    src = OscVmcSource("127.0.0.1", 0, queue_size=4096)
    try:
        with VmcSender(take, "127.0.0.1", src.port, speed=4.0) as snd:
            snd.wait(10.0)
        frames = read_all(src)
        yield take, src, frames
    finally:
        src.close()


def test_the_posture_of_the_take_sent_comes_back_over_udp(received):
    take, src, frames = received
    assert len(frames) == take.n_frames
    rest = src.rest_pose
    assert rest is not None
    rows = Posture(src.joint_names, src.parents, rest, "local").transform(
        np.stack([f.quats for f in frames]))
    ref = take_posture(take)[[f.seq for f in frames]]
    # float32 on the wire; the suit has no shoulder joint, so a shoulder's own turn is lost
    assert np.abs(rows - ref).max() < 0.05


def test_a_live_pipeline_names_by_posture_once_the_sender_geometry_is_known(received):
    from rtseg.evaluation.online import live_config
    from rtseg.live.pipeline import Pipeline
    take, src, frames = received
    cfg, _ = live_config()
    cfg["identity.enabled"] = True
    seen = {}
    for label, rest in (("vmc", lambda: src.rest_pose), ("none", lambda: None)):
        pipe = Pipeline(src.joint_names, src.parents, "local", FR, cfg, rest=rest)
        pipe.identity.library = library()
        for i, f in enumerate(frames):
            pipe.process(i, f.quats, f.valid, f.seq, i / FR, 0, i / FR)
        st = pipe.identity.stats
        assert st.decisions >= 1
        seen[label] = (bool(pipe.identity.namer._has_pose.any()),
                       st.posture_namings == st.decisions)
    assert seen == {"vmc": (True, True), "none": (False, False)}


def test_a_recorded_vmc_session_keeps_the_sender_geometry_for_its_replays(tmp_path):
    """A live session over UDP records the sender's rest geometry (session.json meta); the
    recording read back as a take has it, so a replay names by posture as the live session
    did."""
    from rtseg.core.posture import RestPose
    from rtseg.drivers.readers import read_take
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    take = swing(80.0, 3, seconds=3.0)
    port = free_port()
    rec = tmp_path / "rec"
    cfg = from_dict({"output": {"osc": []}, "recording": {"dir": str(rec)}}, origin="test")
    session = LiveSession(f"osc://127.0.0.1:{port}?format=vmc&rate=120", cfg,
                          handle_signals=False, duration=take.n_frames / 120.0 / 4.0 + 1.5)
    sender = VmcSender(take, "127.0.0.1", port, speed=4.0)
    run_while_sending(session, sender)
    live_rest = session.source.rest_pose
    assert live_rest is not None
    replay = read_take(rec)
    rest = RestPose.find(replay)
    assert rest is not None
    np.testing.assert_allclose(rest.positions, live_rest.positions)
    rows = Posture(replay.joint_names, replay.parents, rest, replay.space).transform(replay.quats)
    assert np.isfinite(rows).all() and rows.shape == (replay.n_frames, 42)
