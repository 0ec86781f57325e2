"""Axis (Perception Neuron) rest geometry from a stream with displacement
(rtseg.drivers.axis.pose.rest_positions): each joint's position channels are its offset from
its parent, so over a real UDP socket the simulator's frames give the posture of the take
sent; without displacement, or with zero offsets, there is none."""

from __future__ import annotations

import numpy as np

import rtseg.drivers.axis.codec as A
from rtseg.core.posture import Posture, take_posture
from rtseg.drivers.axis.pose import rest_positions
from rtseg.drivers.axis.source import AxisBinarySource
from rtseg.simulators.axis_sender import AxisSender

from test_library_posture import swing
from test_vmc_live import read_all


def test_the_posture_of_the_take_sent_comes_back_over_udp():
    take = swing(80.0, 3, seconds=3.0)
    src = AxisBinarySource("127.0.0.1", 0, queue_size=4096)
    try:
        with AxisSender(take, "binary", "127.0.0.1", src.port, speed=4.0) as snd:
            snd.wait(10.0)
        frames = read_all(src)
        rest = src.rest_pose
    finally:
        src.close()
    assert len(frames) == take.n_frames and rest is not None
    rows = Posture(src.joint_names, src.parents, rest, src.space).transform(
        np.stack([f.quats for f in frames]))
    ref = take_posture(take)[[f.seq for f in frames]]
    assert np.abs(rows - ref).max() < 0.05


def test_no_geometry_without_offsets():
    v = np.zeros((len(A.JOINTS), 6))
    v[0, :3] = (10.0, 95.0, -30.0)                      # the Hips' travel only
    assert rest_positions(v.ravel(), with_ref=False) is None
    v[1, :3] = (-9.0, 0.0, 0.0)                          # RightUpLeg from the Hips, cm
    v[2, :3] = (0.0, -42.0, 0.0)
    pos = rest_positions(np.concatenate([np.zeros(6), v.ravel()]), with_ref=True)
    np.testing.assert_allclose(pos[0], 0.0)
    np.testing.assert_allclose(pos[2], [-0.09, -0.42, 0.0])
    v[3, 4] = np.nan
    assert rest_positions(v.ravel(), with_ref=False) is None
