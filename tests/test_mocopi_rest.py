"""A mocopi sender's rest geometry from the bone translations it sends
(rtseg.drivers.mocopi.rest): over a real UDP socket the simulator's skeleton and frames give
the posture of the take sent; without a skeleton the frames' translations do; a skeleton
whose rest rotations are not the identity, or zero offsets, give none."""

from __future__ import annotations

import numpy as np

from rtseg.drivers.mocopi.codec import BONE_NAMES, BONE_PARENTS, MocopiFrame, MocopiSkeleton
from rtseg.drivers.mocopi.rest import rest_pose
from rtseg.drivers.mocopi.source import MocopiSource
from rtseg.simulators.mocopi_sender import MocopiSender

from posture_round_trip import posture_back

IDS = list(range(len(BONE_NAMES)))


def test_the_posture_of_the_take_sent_comes_back_over_udp():
    read, sent, rest, diff = posture_back(
        MocopiSource("127.0.0.1", 0, queue_size=4096),
        lambda take, port: MocopiSender(take, "127.0.0.1", port, speed=4.0))
    assert read == sent and rest is not None and diff < 0.05


def _tran(offsets: np.ndarray, w: float = 1.0) -> np.ndarray:
    t = np.zeros((len(offsets), 7), dtype=np.float32)
    t[:, 3] = w
    t[:, 4:] = offsets
    return t


def test_frames_alone_give_the_geometry_and_odd_skeletons_give_none():
    rng = np.random.default_rng(0)
    off = rng.normal(0.0, 0.1, (len(IDS), 3))
    off[0] = (3.0, 0.9, -2.0)                        # the root's travel: left out
    frame = MocopiFrame(0, 0, None, None, np.array(IDS), _tran(off))
    rest = rest_pose(IDS, None, frame)
    expect = np.zeros((len(IDS), 3))
    for b, p in enumerate(BONE_PARENTS):
        if p >= 0:
            expect[b] = expect[p] + off[b].astype(np.float32)
    np.testing.assert_allclose(rest.positions, expect, atol=1e-6)
    turned = MocopiSkeleton(np.array(IDS), np.array(BONE_PARENTS), _tran(off, w=0.9))
    assert rest_pose(IDS, turned, frame) is None      # rest rotations not the identity
    assert rest_pose(IDS, None, MocopiFrame(0, 0, None, None, np.array(IDS),
                                            _tran(np.zeros_like(off)))) is None
    assert rest_pose(IDS, None, None) is None
