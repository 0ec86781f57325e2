"""VRChat-style OSC trackers (osc://...?format=vrchat) over real UDP on 127.0.0.1."""

from __future__ import annotations

import time

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient
from scipy.spatial.transform import Rotation

from rtseg.drivers import open_source
from rtseg.drivers.osc.vrchat import JOINT_NAMES, VrchatAssembler, unity_euler_to_quat


def _axis(axis: int, deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    m = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


@pytest.mark.parametrize("euler", [(0, 90, 0), (30, 0, 0), (0, 0, 45), (10, -70, 125), (-80, 200, 33)])
def test_unity_euler_matches_explicit_matrices(euler):
    x, y, z = euler
    unity = _axis(1, y) @ _axis(0, x) @ _axis(2, z)     # Quaternion.Euler: Z, then X, then Y
    mirror = np.diag([1.0, 1.0, -1.0])                   # Unity (left-handed) -> ours
    ours = Rotation.from_quat(unity_euler_to_quat(np.array(euler, float))).as_matrix()
    assert np.allclose(ours, mirror @ unity @ mirror, atol=1e-12)


def _bundle(frame: dict[str, tuple[tuple, tuple]]) -> bytes:
    b = OscBundleBuilder(IMMEDIATELY)
    for tracker, (pos, rot) in frame.items():
        for kind, vals in (("position", pos), ("rotation", rot)):
            m = OscMessageBuilder(f"/tracking/trackers/{tracker}/{kind}")
            for v in vals:
                m.add_arg(float(v))
            b.add_content(m.build())
    return b.build().dgram


def read_all(src, idle: float = 0.3) -> list:
    out = []
    while (f := src.read(timeout=idle)) is not None:
        out.append(f)
    return out


def test_trackers_over_udp_from_python_osc():
    src = open_source("osc://127.0.0.1:0?format=vrchat&root=1&quiet=0.05")
    client = None
    try:
        assert src.joint_names == JOINT_NAMES and src.space == "global"
        client = SimpleUDPClient("127.0.0.1", src.port)
        frames_sent = []
        for k in range(4):
            frame = {"head": ((0, 1.6, 0.1 * k), (0, 10 * k, 0)),
                     "1": ((0.0, 1.0, 0.1 * k), (5, 0, 0))}
            if k != 2:                                   # tracker 2 drops out in frame 2
                frame["2"] = ((0.2, 0.1, 0.1 * k), (0, 0, 20))
            frames_sent.append(frame)
            client._sock.sendto(_bundle(frame), ("127.0.0.1", src.port))
            time.sleep(0.01)
        client.send_message("/tracking/trackers/3/rotation", ["x", 1.0, 2.0])   # bad type
        client.send_message("/tracking/trackers/9/rotation", [1.0, 2.0, 3.0])   # not a tracker
        client.send_message("/avatar/parameters/Foo", 1)                         # other address
        frames = read_all(src)
    finally:
        if client is not None:
            client._sock.close()
        src.close()
    assert len(frames) == 4
    for k, (f, sent) in enumerate(zip(frames, frames_sent)):
        assert f.valid.tolist() == [True, True, k != 2] + [False] * 6
        assert np.allclose(f.quats[0], unity_euler_to_quat(np.array([0.0, 10 * k, 0.0])), atol=1e-6)
        assert f.root_position == pytest.approx([0.0, 1.0, -0.1 * k], abs=1e-6)
    head_yaw = [np.degrees(Rotation.from_quat(f.quats[0]).as_rotvec()[1]) for f in frames]
    assert np.allclose(head_yaw, [0, -10, -20, -30], atol=1e-4)   # left-handed yaw flips sign
    assert np.allclose(frames[2].quats[2], frames[1].quats[2])     # dropout holds the last value
    assert src.stats.bad_messages == 1 and src.stats.corrupt == 0


def test_assembler_never_raises_on_garbage():
    asm = VrchatAssembler()
    for junk in [b"", b"abc", b"/tracking/trackers/1/rotation\x00\x00\x00,fff\x00\x00\x00\x00",
                 b"#bundle\x00" + bytes(8) + b"\x00\x00\x00\x08/a\x00\x00,\x00\x00\x00"]:
        assert asm.feed(junk, 0.0) == []
    assert asm.stats.corrupt == 3 and asm.flush(1.0) == []
