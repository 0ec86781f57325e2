"""Xsens MVN rest geometry from the world positions and orientations each frame carries
(``RestPose.from_world``): over a real UDP socket the simulator's frames give the posture of
the take sent; a stream that places only the pelvis has none."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.core.posture import PostureError, RestPose
from rtseg.drivers.mvn.source import MvnSource
from rtseg.simulators.mvn_sender import MvnSender

from posture_round_trip import posture_back
from test_library_posture import swing
from test_vmc_live import read_all


def test_a_rigid_chain_gives_back_its_offsets_in_any_pose():
    parents = [-1, 0, 1, 1]
    off = np.array([[0.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.2, 0.1, 0.0], [-0.2, 0.1, 0.3]])
    G = Rotation.random(4, random_state=3).as_quat()
    R = Rotation.from_quat(G).as_matrix()
    P = np.zeros((4, 3))
    P[0] = (4.0, 1.0, -2.0)
    for j, p in enumerate(parents):
        if p >= 0:
            P[j] = P[p] + R[p] @ off[j]
    rest = RestPose.from_world(P, G, parents)
    expect = np.array([off[0], off[1], off[1] + off[2], off[1] + off[3]])
    np.testing.assert_allclose(rest.positions, expect, atol=1e-12)


def test_the_posture_of_the_take_sent_comes_back_over_udp():
    read, sent, rest, diff = posture_back(
        MvnSource("127.0.0.1", 0, queue_size=4096),
        lambda take, port: MvnSender(take, "127.0.0.1", port, speed=4.0))
    assert read == sent and rest is not None and diff < 0.05


def test_a_stream_that_places_only_the_pelvis_has_no_geometry():
    take = swing(80.0, 3, seconds=1.0)
    src = MvnSource("127.0.0.1", 0, queue_size=4096)
    try:
        snd = MvnSender(take, "127.0.0.1", src.port, speed=4.0)
        snd._pos[:, 1:] = 0.0                        # what MVN senders without positions do
        with snd:
            snd.wait(10.0)
        assert read_all(src) and src.rest_pose is None
    finally:
        src.close()


def test_non_finite_world_values_are_one_posture_error():
    P = np.zeros((3, 3))
    P[2, 1] = np.nan
    with pytest.raises(PostureError, match="finite"):
        RestPose.from_world(P, np.tile([0.0, 0.0, 0.0, 1.0], (3, 1)), [-1, 0, 1])
