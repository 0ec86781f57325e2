"""Axis (Perception Neuron) rest geometry from a stream with displacement
(rtseg.drivers.axis.pose.rest_pose): each joint's position channels are its offset from
its parent, so over a real UDP socket the simulator's frames give the posture of the take
sent; without displacement, or with zero offsets, there is none."""

from __future__ import annotations

import numpy as np

import rtseg.drivers.axis.codec as A
from rtseg.drivers.axis.pose import rest_pose
from rtseg.drivers.axis.source import AxisBinarySource
from rtseg.simulators.axis_sender import AxisSender

from posture_round_trip import posture_back


def test_the_posture_of_the_take_sent_comes_back_over_udp():
    read, sent, rest, diff = posture_back(
        AxisBinarySource("127.0.0.1", 0, queue_size=4096),
        lambda take, port: AxisSender(take, "binary", "127.0.0.1", port, speed=4.0))
    assert read == sent and rest is not None and diff < 0.05


def test_no_geometry_without_offsets():
    v = np.zeros((len(A.JOINTS), 6))
    v[0, :3] = (10.0, 95.0, -30.0)                      # the Hips' travel only
    assert rest_pose(v.ravel(), with_ref=False) is None
    v[1, :3] = (-9.0, 0.0, 0.0)                          # RightUpLeg from the Hips, cm
    v[2, :3] = (0.0, -42.0, 0.0)
    pos = rest_pose(np.concatenate([np.zeros(6), v.ravel()]), with_ref=True).positions
    np.testing.assert_allclose(pos[0], 0.0)
    np.testing.assert_allclose(pos[2], [-0.09, -0.42, 0.0])
    v[3, 4] = np.nan
    assert rest_pose(v.ravel(), with_ref=False) is None
