"""VMC faults at the edges over real UDP sockets on 127.0.0.1: truncated bundles are dropped
whole, never used in part."""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest

from rtseg.drivers import open_source
from rtseg.drivers.codec_vmc import VmcAssembler, bundle_structure_error, encode_frame

from tests.test_vmc_live import SUIT, make_take, read_all, same_rotation


@pytest.fixture
def source():
    src = open_source("osc://127.0.0.1:0?format=vmc&suit=default17&quiet=0.02&queue=4096")
    try:
        yield src
    finally:
        src.close()


def _frame_datagrams(take, i: int) -> list[bytes]:
    return encode_frame(take.quats[i], SUIT, time=i / 60.0,
                        root_position=take.root_position[i], max_datagram=60000)


def test_truncated_bundles_are_dropped_whole_over_udp(source):
    take = make_take(60, seed=5)
    addr = ("127.0.0.1", source.port)
    rng = np.random.default_rng(1)
    n_bad = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        for i in range(len(take.quats)):
            dgrams = _frame_datagrams(take, i)
            assert len(dgrams) == 1, "one whole frame per datagram in this test"
            whole = dgrams[0]
            if i % 3 == 1:
                # a truncated copy of the next frame's bundle: elements before the cut parse
                cut = 4 * int(rng.integers(8, len(whole) // 4 - 1))
                bad = _frame_datagrams(take, min(i + 1, len(take.quats) - 1))[0][:cut]
                assert bundle_structure_error(bad, 0, len(bad), 0) is not None
                out.sendto(bad, addr)
                n_bad += 1
            out.sendto(whole, addr)
            time.sleep(0.002)
        frames = read_all(source)
    assert len(frames) == len(take.quats)          # no phantom frame from a partial bundle
    for i, f in enumerate(frames):
        assert f.source_time == pytest.approx(i / 60.0, abs=1e-5)
        assert bool(f.valid.all())
        assert same_rotation(f.quats, take.quats[i], atol=1e-6)
    assert source.stats.corrupt == n_bad
    assert source.stats.dropped == 0


def test_truncated_nested_bundle_is_dropped_whole():
    take = make_take(3, seed=2)
    asm = VmcAssembler(SUIT)
    whole = _frame_datagrams(take, 0)[0]
    # a nested bundle whose inner element is cut short while the outer sizes still add up
    inner = whole[:len(whole) - 8]
    outer = b"#bundle\x00" + struct.pack(">Q", 1) + struct.pack(">i", len(inner)) + inner
    assert bundle_structure_error(outer, 0, len(outer), 0) is not None
    assert asm.feed(outer, 0.0) == [] and not asm.pending
    assert asm.stats.corrupt == 1
