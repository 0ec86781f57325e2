"""VMC over real UDP sockets on 127.0.0.1: sender -> osc:// source, raw datagrams, liblo."""

from __future__ import annotations

import random
import shutil
import socket
import subprocess
import time

import numpy as np
import pytest
from pythonosc.osc_message import OscMessage as PyOscMessage
from scipy.spatial.transform import Rotation

from rtseg.drivers import SourceError, open_source
from rtseg.drivers.osc.vmc.codec import (
    BONE_ADDRESS, ROOT_ADDRESS, encode_message, encode_pose_message, pack_bundles, parse_packet,
)
from rtseg.drivers.osc.source import OscVmcSource
from rtseg.simulators.vmc_sender import VmcSender
from rtseg.core.take import Take

SUIT = ["Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand",
        "RightUpperArm", "RightLowerArm", "RightHand", "LeftUpperLeg", "LeftLowerLeg",
        "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot"]
PARENTS = [-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15]


def make_take(n: int = 90, seed: int = 0, names=None) -> Take:
    """Smooth random local rotations (sign-continuous) and a moving root, 60 Hz."""
    names = names or SUIT
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None, None] / 60.0
    rotvec = 0.8 * np.sin(2 * np.pi * (0.5 + rng.random((1, len(names), 3))) * t
                          + rng.random((1, len(names), 3)) * 6)
    q = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat().reshape(n, len(names), 4)
    root = np.stack([np.sin(t[:, 0, 0]), 1.0 + 0.1 * t[:, 0, 0], 0.5 * t[:, 0, 0]], axis=1)
    parents = PARENTS if names is SUIT else [-1] * len(names)
    return Take(list(names), list(parents), 60.0, q, root_position=root, length_unit="m")


def same_rotation(a: np.ndarray, b: np.ndarray, atol: float = 3e-7) -> bool:
    d = np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1))
    return bool(d.max() <= atol)


def read_all(src, idle: float = 0.3, limit: float = 10.0) -> list:
    frames, t_end = [], time.monotonic() + limit
    while time.monotonic() < t_end:
        f = src.read(timeout=idle)
        if f is None:
            break
        frames.append(f)
    return frames


@pytest.fixture
def source():
    src = open_source("osc://127.0.0.1:0?format=vmc&suit=default17&quiet=0.02&queue=4096")
    try:
        yield src
    finally:
        src.close()


@pytest.fixture
def udp_out():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        yield s
    finally:
        s.close()


def test_source_properties_and_ephemeral_port(source):
    assert isinstance(source, OscVmcSource)
    assert source.port > 0 and source.space == "local"
    assert source.joint_names == SUIT and source.parents == PARENTS
    assert source.read(timeout=0.01) is None


def test_sender_to_source_round_trip_equals_the_take(source):
    take = make_take(120)
    with VmcSender(take, port=source.port, rate=600.0) as sender:
        assert sender.wait(10.0)
        frames = read_all(source)
    assert len(frames) == 120 and sender.send_errors == 0
    q = np.array([f.quats for f in frames])
    assert same_rotation(q, take.quats)
    assert np.allclose([f.root_position for f in frames], take.root_position, atol=1e-6)
    assert [f.seq for f in frames] == list(range(120))
    assert np.allclose([f.source_time for f in frames], np.arange(120) / 600.0, atol=1e-6)
    assert all(f.valid.all() for f in frames)
    recv = [f.recv_time for f in frames]
    assert recv == sorted(recv)
    assert source.stats.frames_ok == 120 and source.stats.dropped == 0
    assert source.stats.corrupt == source.stats.bad_messages == source.stats.bad_values == 0


def test_several_datagrams_per_frame(source):
    take = make_take(40, seed=1)
    with VmcSender(take, port=source.port, rate=400.0, max_datagram=256) as sender:
        assert sender.wait(10.0)
        frames = read_all(source)
    assert min(s.datagrams for s in sender.sent_log) >= 5
    assert len(frames) == 40
    assert same_rotation(np.array([f.quats for f in frames]), take.quats)


def test_reordered_datagrams_and_messages_within_frames(source, udp_out):
    take = make_take(30, seed=2)
    rng = random.Random(1)
    addr = ("127.0.0.1", source.port)
    for i in range(30):
        # the root leads the frame (as VMC senders send it); bones, T and OK come in any
        # order, spread over datagrams that arrive in any order
        root = encode_pose_message(ROOT_ADDRESS, "root", take.root_position[i], (0, 0, 0, 1))
        msgs = [encode_pose_message(BONE_ADDRESS, b, (0, 0, 0), take.quats[i, j])
                for j, b in enumerate(SUIT)]
        msgs += [encode_message("/VMC/Ext/T", "f", [i / 60.0]),
                 encode_message("/VMC/Ext/OK", "i", [1])]
        rng.shuffle(msgs)
        dgrams = pack_bundles([root] + msgs, 300)
        rest = dgrams[1:]
        rng.shuffle(rest)
        for d in [dgrams[0]] + rest:
            udp_out.sendto(d, addr)
        time.sleep(0.002)
    frames = read_all(source)
    assert len(frames) == 30
    assert same_rotation(np.array([f.quats for f in frames]), take.quats)
    assert np.allclose([f.root_position for f in frames], take.root_position, atol=1e-6)
    assert np.allclose([f.source_time for f in frames], np.arange(30) / 60.0, atol=1e-6)


def test_unknown_addresses_ignored_bad_types_counted(source, udp_out):
    addr = ("127.0.0.1", source.port)
    q = Rotation.from_euler("z", 40, degrees=True).as_quat()
    junk = [encode_message("/VMC/Ext/Blend/Val", "sf", ["Joy", 0.5]),
            encode_message("/VMC/Ext/Cam", "sffffffff", ["Camera"] + [0.0] * 8),
            encode_message("/tracking/trackers/1/position", "fff", [0, 1, 0]),
            encode_message(BONE_ADDRESS, "sfffsfff", ["Spine", 0, 0, 0, "x", 0, 0, 1]),
            encode_message(BONE_ADDRESS, "sff", ["Chest", 0, 0]),
            encode_message("/VMC/Ext/T", "i", [5]),   # int time: accepted as a number
            encode_message("/VMC/Ext/T", "b", [b"??"])]
    for j in junk:
        udp_out.sendto(j, addr)
    udp_out.sendto(encode_pose_message(BONE_ADDRESS, "LeftHand", (0, 0, 0), q), addr)
    frames = read_all(source)
    assert len(frames) == 1
    f = frames[0]
    assert f.valid.tolist() == [b == "LeftHand" for b in SUIT]
    assert np.allclose(f.quats[SUIT.index("LeftHand")], q, atol=1e-7)
    assert f.source_time == 5.0
    assert source.stats.bad_messages == 3 and source.stats.corrupt == 0


def test_sensor_dropout_and_dropped_frames_via_faults(source):
    take = make_take(120, seed=3)
    faults = "drop=0.1,dropout=LeftHand:0.05:0.05,seed=4"
    with VmcSender(take, port=source.port, rate=600.0, faults=faults) as sender:
        assert sender.wait(10.0)
        frames = read_all(source)
    sent = [s for s in sender.sent_log if not s.dropped]
    assert 0 < len(sent) < 120 and len(frames) == len(sent)
    hand = SUIT.index("LeftHand")
    for s, f in zip(sent, frames):
        assert f.source_time == pytest.approx(s.source_time, abs=1e-6)
        assert f.seq == s.slot                       # lost frames are sequence gaps
        assert f.valid[hand] == ("LeftHand" not in s.omitted)
        assert f.valid.sum() == len(SUIT) - len(s.omitted)
        if "LeftHand" not in s.omitted:
            assert same_rotation(f.quats[hand], take.quats[s.index, hand])
    assert any(s.omitted for s in sent)
    assert source.stats.dropped == 120 - len(sent) - (119 - sent[-1].slot)


def test_close_stops_thread_and_frees_port():
    src = OscVmcSource("127.0.0.1", 0)
    port = src.port
    thread = src._thread
    src.close()
    src.close()
    assert not thread.is_alive()
    again = OscVmcSource("127.0.0.1", port)   # port free again
    again.close()


def test_queue_overflow_drops_oldest_and_counts(udp_out):
    src = open_source("osc://127.0.0.1:0?queue=4&quiet=30")   # last frame stays open
    try:
        addr = ("127.0.0.1", src.port)
        for i in range(10):
            udp_out.sendto(encode_pose_message(BONE_ADDRESS, "Hips", (0, 0, 0), (0, 0, 0, 1)), addr)
            udp_out.sendto(encode_message("/VMC/Ext/T", "f", [float(i)]), addr)
        deadline = time.monotonic() + 5
        while src.stats.dropped < 5 and time.monotonic() < deadline:
            time.sleep(0.01)
        frames = read_all(src, idle=0.1)
        assert [f.source_time for f in frames] == [5.0, 6.0, 7.0, 8.0]
        assert src.stats.dropped == 5 and src.stats.frames_ok == 4
    finally:
        src.close()


@pytest.mark.parametrize("url, message", [
    ("osc://127.0.0.1:0?format=bvh", "not supported"),
    ("osc://127.0.0.1:0?format=vrchat&suit=default17", "unknown option"),
    ("osc://127.0.0.1:0?format=vrchat&root=knee", "root tracker"),
    ("osc://127.0.0.1:0?bogus=1", "unknown option"),
    ("osc://127.0.0.1:0?quiet=abc", "quiet"),
    ("osc://127.0.0.1:0?suit=nosuch", "nosuch"),
    ("osc://127.0.0.1:99999", "out of range"),
    ("osc://127.0.0.1:0?time_order=middle", "time_order"),
])
def test_bad_urls_give_clear_errors(url, message):
    with pytest.raises(SourceError, match=message):
        open_source(url)


def test_port_in_use_is_a_source_error(source):
    with pytest.raises(SourceError, match="cannot listen"):
        OscVmcSource("127.0.0.1", source.port)


# --------------------------------------------------------------------------- liblo

needs_oscsend = pytest.mark.skipif(shutil.which("oscsend") is None,
                                   reason="liblo-tools (oscsend) not installed")


def oscsend(port: int, address: str, types: str, *values) -> None:
    subprocess.run(["oscsend", "127.0.0.1", str(port), address, types, *map(str, values)],
                   check=True, timeout=10, capture_output=True)


@needs_oscsend
def test_parser_reads_liblo_encoding_like_python_osc(udp_out):
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(5.0)
        port = rx.getsockname()[1]
        oscsend(port, "/VMC/Ext/Bone/Pos", "sfffffff", "LeftUpperArm", 0.5, -1, 2, 0.1, 0.2, 0.3, 0.9)
        oscsend(port, "/all/types", "ihfdsSTFNm", 7, 2 ** 40, 1.5, 0.25, "text", "sym", "0x90304000")
        raw = [rx.recv(65536), rx.recv(65536)]
    finally:
        rx.close()
    for dgram in raw:
        (mine,) = parse_packet(dgram)
        ref = PyOscMessage(dgram)
        assert mine.address == ref.address
        if mine.address == BONE_ADDRESS:
            assert list(mine.args) == list(ref.params)
            assert mine.args[0] == "LeftUpperArm" and mine.args[1:4] == (0.5, -1.0, 2.0)
        else:
            assert mine.tags == "ihfdsSTFNm"
            assert mine.args[:9] == (7, 2 ** 40, 1.5, 0.25, "text", "sym", True, False, None)
            assert len(mine.args[9]) == 4


@needs_oscsend
def test_oscsend_skeleton_decoded():
    # every oscsend is a new process, so a new sender port: one stream from many senders
    src = open_source("osc://127.0.0.1:0?format=vmc&quiet=0.5&senders=merge")
    try:
        # Unity (left-handed) 30° about Y for Hips, 90° about X for LeftLowerArm
        s, c = np.sin(np.radians(15)), np.cos(np.radians(15))
        r = np.sqrt(0.5)
        oscsend(src.port, ROOT_ADDRESS, "sfffffff", "root", 1, 0, 2, 0, 0, 0, 1)
        oscsend(src.port, BONE_ADDRESS, "sfffffff", "Hips", 0, 0.9, 0, 0, s, 0, c)
        oscsend(src.port, BONE_ADDRESS, "sfffffff", "leftlowerarm", 0, 0, 0, r, 0, 0, r)
        oscsend(src.port, BONE_ADDRESS, "sfffffff", "NotABone", 0, 0, 0, 0, 0, 0, 1)
        oscsend(src.port, "/VMC/Ext/T", "f", 12.5)
        oscsend(src.port, "/VMC/Ext/OK", "iiii", 1, 3, 0, 1)
        # next frame: Hips again closes the first one; its T follows its bones
        oscsend(src.port, BONE_ADDRESS, "sfffffff", "Hips", 0, 0.9, 0, 0, 0, 0, 1)
        oscsend(src.port, "/VMC/Ext/T", "f", 12.6)
        f1 = src.read(timeout=5.0)
        f2 = src.read(timeout=5.0)
    finally:
        src.close()
    assert f1 is not None and f2 is not None
    assert f1.source_time == pytest.approx(12.5) and f2.source_time == pytest.approx(12.6)
    hips, arm = SUIT.index("Hips"), SUIT.index("LeftLowerArm")
    assert f1.valid.tolist() == [j in (hips, arm) for j in range(len(SUIT))]
    assert np.allclose(f1.quats[hips], [0, -s, 0, c], atol=1e-6)      # (-x, -y, z, w)
    assert np.allclose(f1.quats[arm], [-r, 0, 0, r], atol=1e-6)
    # root (1, 0, 2) -> (1, 0, -2) plus hips offset (0, 0.9, 0) under identity root rotation
    assert f1.root_position == pytest.approx([1.0, 0.9, -2.0], abs=1e-6)
    assert f2.valid.tolist() == [j == hips for j in range(len(SUIT))]
    assert np.allclose(f2.quats[hips], [0, 0, 0, 1]) and np.allclose(f2.quats[arm], f1.quats[arm])
    assert src.stats.unknown_names == 1 and src.ok_state == (1, 3, 0, 1)


def test_time_order_first_from_url(udp_out):
    """A T-first sender with a partial skeleton: T opens each frame."""
    src = open_source("osc://127.0.0.1:0?time_order=first&quiet=0.3")
    try:
        addr = ("127.0.0.1", src.port)
        for i in range(3):
            udp_out.sendto(encode_message("/VMC/Ext/T", "f", [10.0 + i]), addr)
            q = Rotation.from_euler("y", 10 * i, degrees=True).as_quat()
            udp_out.sendto(encode_pose_message(BONE_ADDRESS, "Head", (0, 0, 0), q), addr)
        frames = read_all(src, idle=0.6)
    finally:
        src.close()
    assert [f.source_time for f in frames] == [10.0, 11.0, 12.0]
    head = SUIT.index("Head")
    angles = [Rotation.from_quat(f.quats[head]).magnitude() for f in frames]
    assert np.allclose(np.degrees(angles), [0, 10, 20], atol=1e-4)


def test_sender_command_line_streams_a_synthesised_take(source):
    import sys
    proc = subprocess.run(
        [sys.executable, "-m", "rtseg.simulators.vmc_sender", "--port", str(source.port),
         "--script", "idle:1.5,walk:1.5", "--rate", "1000"],
        capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    frames = read_all(source)
    assert "sent 360 frames" in proc.stdout
    assert len(frames) == 360 and all(f.valid.all() for f in frames)


def test_close_wakes_a_blocked_reader():
    import threading
    src = OscVmcSource("127.0.0.1", 0)
    result = []
    t = threading.Thread(target=lambda: result.append(src.read(timeout=None)))
    t.start()
    time.sleep(0.05)
    src.close()
    t.join(timeout=5.0)
    assert not t.is_alive() and result == [None]


def test_looping_sender_keeps_time_increasing_until_stopped(source):
    take = make_take(20, seed=5)
    sender = VmcSender(take, port=source.port, rate=500.0, loop=True).start()
    try:
        deadline = time.monotonic() + 10
        while len(sender.sent_log) < 50 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        sender.stop()
    thread_gone = not sender._thread.is_alive()
    frames = read_all(source)
    assert thread_gone and len(sender.sent_log) >= 50
    n = len(sender.sent_log)
    assert [s.index for s in sender.sent_log] == [k % 20 for k in range(n)]
    times = [f.source_time for f in frames]
    assert len(frames) == n and times == sorted(times) and times[-1] == pytest.approx((n - 1) / 500.0)
    assert same_rotation(frames[25].quats, take.quats[5])


def test_decoder_exception_is_counted_and_the_loop_goes_on(udp_out, caplog):
    src = OscVmcSource("127.0.0.1", 0, quiet=0.05)
    try:
        real = src.assembler.feed
        calls = []

        def flaky(data, now):
            calls.append(len(data))
            if len(calls) == 1:
                raise RuntimeError("decoder bug")
            return real(data, now)

        src.assembler.feed = flaky
        msg = encode_pose_message(BONE_ADDRESS, "Hips", (0, 0, 0), (0, 0, 0, 1))
        udp_out.sendto(msg, ("127.0.0.1", src.port))
        udp_out.sendto(msg, ("127.0.0.1", src.port))
        frames = read_all(src)
    finally:
        src.close()
    assert len(calls) == 2 and len(frames) == 1 and src.stats.corrupt == 1
    assert "crashed the decoder" in caplog.text
