"""VMC codec: OSC parser against python-osc, encoder, frame assembly rules (no sockets)."""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage as PyOscMessage
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.osc_packet import OscPacket
from scipy.spatial.transform import Rotation

from rtseg.drivers.osc.vmc.codec import (
    BONE_ADDRESS, ROOT_ADDRESS, OscParseError, VmcAssembler, encode_bundle, encode_frame,
    encode_message, encode_pose_message, pack_bundles, parse_message, parse_packet,
)

BONES = ["Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand",
         "RightUpperArm", "RightLowerArm", "RightHand", "LeftUpperLeg", "LeftLowerLeg",
         "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot"]


def rand_quats(n: int, j: int, seed: int) -> np.ndarray:
    q = Rotation.random(n * j, random_state=seed).as_quat().reshape(n, j, 4)
    return q


def same_rotation(a: np.ndarray, b: np.ndarray, atol: float = 2e-7) -> bool:
    """Equal up to the sign of each quaternion, at float32 resolution."""
    d = np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1))
    return bool(d.max() <= atol)


def build(address: str, *args) -> bytes:
    b = OscMessageBuilder(address)
    for a in args:
        b.add_arg(a)
    return b.build().dgram


def feed_all(asm: VmcAssembler, datagrams, now: float = 0.0) -> list:
    out = []
    for d in datagrams:
        out.extend(asm.feed(d, now))
    return out


# --------------------------------------------------------------------------- parser

def test_parser_matches_python_osc_on_every_type():
    b = OscMessageBuilder("/a/b")
    for value in [1, 2.5, "héllo", b"\x01\x02\x03", True, False, None, 2 ** 40, [1, [2.0, "x"]]]:
        b.add_arg(value)
    b.add_arg(1.0 / 3.0, "d")
    b.add_arg((0x90, 0x3C, 0x40, 0x00), "m")
    dgram = b.build().dgram
    ref = PyOscMessage(dgram)
    mine = parse_message(dgram)
    assert mine.address == ref.address == "/a/b"
    assert mine.tags == "ifsbTFNh[i[fs]]dm"
    params = list(ref.params)
    assert mine.args[-1] == bytes(params[-1]) and list(mine.args[:-1]) == params[:-1]


def test_parser_reads_time_tags_and_symbols():
    dgram = (b"/t\x00\x00,tSc\x00\x00\x00\x00" + struct.pack(">Q", (5 << 32) + 7)
             + b"sym\x00" + struct.pack(">i", ord("A")))
    m = parse_message(dgram)
    assert m.args == ((5 << 32) + 7, "sym", "A")


def test_parser_handles_nested_bundles_like_python_osc():
    inner = OscBundleBuilder(IMMEDIATELY)
    inner.add_content(OscMessageBuilder("/inner").build())
    m = OscMessageBuilder("/x")
    m.add_arg(7)
    outer = OscBundleBuilder(12345)
    outer.add_content(m.build())
    outer.add_content(inner.build())
    dgram = outer.build().dgram
    msgs = parse_packet(dgram)
    ref = [(m.message.address, list(m.message.params)) for m in OscPacket(dgram).messages]
    assert [(x.address, list(x.args)) for x in msgs] == ref
    assert msgs[0].timetag >> 32 == 12345 + 2208988800 and msgs[1].timetag == 1   # NTP epoch 1900


@pytest.mark.parametrize("bad", [
    b"", b"/ab", b"/abc", b"abcd\x00\x00\x00\x00", b"/a\x00\x00,f\x00\x00\x00\x00",
    b"/a\x00\x00,z\x00\x00", b"#bundle\x00" + b"\x00" * 8 + b"\x00\x00\x00\x09/a\x00\x00",
    b"/a\x00\x00,b\x00\x00\x00\x00\x00\x10", b"/a\x00\x00,[\x00\x00",
])
def test_parser_rejects_malformed_with_its_error(bad):
    with pytest.raises(OscParseError):
        parse_packet(bad)


def test_encoder_output_is_read_by_python_osc():
    msg = encode_message("/VMC/Ext/OK", "iii", [np.int64(1), 3, 0])
    assert PyOscMessage(msg).params == [1, 3, 0]
    m2 = encode_message("/t", "fsdb", [np.float32(0.5), "abc", 1.25, b"xyz"])
    assert PyOscMessage(m2).params == [0.5, "abc", 1.25, b"xyz"]
    bundle = encode_bundle([msg, m2])
    assert OscBundle.dgram_is_bundle(bundle)
    assert [c.address for c in OscBundle(bundle)] == ["/VMC/Ext/OK", "/t"]


# --------------------------------------------------------------------------- encoder

def test_encode_frame_converts_to_unity_and_fits_datagrams():
    q = rand_quats(1, len(BONES), 1)[0]
    dgrams = encode_frame(q, BONES, time=1.5, root_position=(0.1, 0.9, 2.0), max_datagram=400)
    assert len(dgrams) > 2 and all(len(d) <= 400 for d in dgrams)
    msgs = [m for d in dgrams for m in OscPacket(d).messages]
    by_addr: dict = {}
    for m in msgs:
        by_addr.setdefault(m.message.address, []).append(list(m.message.params))
    assert by_addr["/VMC/Ext/T"] == [[1.5]]
    root = by_addr[ROOT_ADDRESS][0]
    assert root[0] == "root" and root[1:4] == pytest.approx([0.1, 0.9, -2.0], abs=1e-6)
    bones = by_addr[BONE_ADDRESS]
    assert [b[0] for b in bones] == BONES
    got = np.array([b[4:8] for b in bones])
    expect = q * np.array([-1, -1, 1, 1])          # (x, y, z, w) -> (-x, -y, z, w)
    assert np.allclose(got, expect, atol=1e-7)
    # first message order as VMC performers send it: Root, bones, T, OK
    assert [m.message.address for m in msgs][0] == ROOT_ADDRESS
    assert [m.message.address for m in msgs][-2:] == ["/VMC/Ext/T", "/VMC/Ext/OK"]


def test_pack_bundles_refuses_message_larger_than_limit():
    big = encode_message("/x", "b", [b"\x00" * 200])
    with pytest.raises(ValueError, match="does not fit"):
        pack_bundles([big], max_datagram=128)


# --------------------------------------------------------------------------- assembler

def frames_of(n: int, seed: int = 0, **kw) -> tuple[np.ndarray, list[list[bytes]]]:
    q = rand_quats(n, len(BONES), seed)
    return q, [encode_frame(q[i], BONES, time=i / 60.0, root_position=(0.0, 1.0, 0.01 * i),
                            **kw) for i in range(n)]


def test_roundtrip_several_datagrams_per_frame():
    q, pkts = frames_of(20, max_datagram=300)
    assert all(len(p) >= 4 for p in pkts)
    asm = VmcAssembler(BONES)
    frames = feed_all(asm, [d for p in pkts for d in p])
    frames += asm.flush(0.0, force=True)
    assert len(frames) == 20
    assert same_rotation(np.array([f.quats for f in frames]), q)
    assert [f.seq for f in frames] == list(range(20))
    assert [f.source_time for f in frames] == pytest.approx([i / 60.0 for i in range(20)])
    assert all(f.valid.all() for f in frames)
    assert frames[7].root_position == pytest.approx([0.0, 1.0, 0.07], abs=1e-6)
    assert asm.stats.as_dict() == {k: 0 for k in asm.stats.as_dict()}


def test_complete_frame_closes_without_waiting_once_order_is_known():
    q, pkts = frames_of(3)
    asm = VmcAssembler(BONES)
    assert feed_all(asm, pkts[0]) == []          # sender's message order not known yet
    f01 = feed_all(asm, pkts[1])                 # root changed: frame 0 closed; 1 complete
    assert [f.seq for f in f01] == [0, 1]
    assert [f.source_time for f in f01] == pytest.approx([0.0, 1 / 60.0])
    f2 = feed_all(asm, pkts[2])
    assert len(f2) == 1 and f2[0].source_time == pytest.approx(2 / 60.0)
    assert not asm.pending


@pytest.mark.parametrize("order", ["vmc", "t_first", "shuffled"])
def test_message_order_within_frame_does_not_matter(order):
    n = 12
    q = rand_quats(n, len(BONES), 3)
    rng = random.Random(5)
    stream = []
    for i in range(n):
        root = encode_pose_message(ROOT_ADDRESS, "root", (0, 1, i), (0, 0, 0, 1))
        bones = [encode_pose_message(BONE_ADDRESS, b, (0, 0, 0), q[i, j]) for j, b in enumerate(BONES)]
        t = encode_message("/VMC/Ext/T", "f", [i * 0.5])
        ok = encode_message("/VMC/Ext/OK", "i", [1])
        if order == "vmc":           # VirtualMotionCapture: Root, Bones, OK, T
            msgs = [root, *bones, ok, t]
        elif order == "t_first":
            msgs = [t, root, *bones, ok]
        else:
            msgs = [root, *bones, ok, t]
            rng.shuffle(msgs)
        dgrams = pack_bundles(msgs, 256)
        if order == "shuffled":
            rng.shuffle(dgrams)
        stream += dgrams
    asm = VmcAssembler(BONES, time_order="first" if order == "t_first" else "last")
    frames = feed_all(asm, stream) + asm.flush(0.0, force=True)
    assert len(frames) == n
    assert same_rotation(np.array([f.quats for f in frames]), q)
    assert [f.source_time for f in frames] == [i * 0.5 for i in range(n)]
    assert [f.root_position[2] for f in frames] == [float(i) for i in range(n)]


def _bone(name: str, quat=(0.0, 0.0, 0.0, 1.0), pos=(0.0, 0.0, 0.0)) -> bytes:
    return encode_pose_message(BONE_ADDRESS, name, pos, quat)


def test_partial_frames_close_on_time_change_and_hold_last_values():
    asm = VmcAssembler(BONES, time_order="first")
    r = Rotation.from_euler("y", 30, degrees=True).as_quat()
    out = asm.feed(encode_bundle([encode_message("/VMC/Ext/T", "f", [1.0]), _bone("Hips", r),
                                  _bone("Spine", r)]), 0.0)
    assert out == [] and asm.pending
    out = asm.feed(encode_bundle([encode_message("/VMC/Ext/T", "f", [2.0]), _bone("hips")]), 0.01)
    assert len(out) == 1
    f = out[0]
    assert f.source_time == 1.0 and f.recv_time == 0.01
    assert f.valid.tolist() == [True, True] + [False] * 15
    assert np.allclose(f.quats[:2], r) and np.allclose(f.quats[2:], [0, 0, 0, 1])
    (g,) = asm.flush(0.5)      # quiet gap
    assert g.source_time == 2.0 and g.valid.tolist() == [True] + [False] * 16
    assert np.allclose(g.quats[0], [0, 0, 0, 1]) and np.allclose(g.quats[1], r)  # Spine held
    assert asm.flush(1.0) == []


def test_quiet_gap_needs_quiet_seconds():
    asm = VmcAssembler(BONES, quiet=0.05)
    asm.feed(_bone("Hips"), 10.0)
    assert asm.flush(10.03) == []
    assert len(asm.flush(10.05)) == 1


def test_root_change_and_repeated_bone_close_frames():
    asm = VmcAssembler(BONES)
    root0 = encode_pose_message(ROOT_ADDRESS, "root", (0, 0, 0), (0, 0, 0, 1))
    root1 = encode_pose_message(ROOT_ADDRESS, "root", (0, 0, 1), (0, 0, 0, 1))
    assert asm.feed(encode_bundle([root0, _bone("Hips")]), 0) == []
    assert len(asm.feed(encode_bundle([root1, _bone("Hips")]), 0)) == 1    # root changed
    assert len(asm.feed(_bone("Hips"), 0)) == 1                            # Hips again
    assert len(asm.feed(root1, 0)) == 0                                    # same root: no cut


def test_left_handed_conversion_and_root_position_includes_hips_offset():
    asm = VmcAssembler(BONES)
    # Unity: root at (1, 0, 2) turned 90° about Y (left-handed); hips 1 unit along local +X.
    s = math.sqrt(0.5)
    root = encode_message(ROOT_ADDRESS, "sfffffff", ["root", 1, 0, 2, 0, s, 0, s])
    hips = encode_message(BONE_ADDRESS, "sfffffff", ["Hips", 1, 0, 0, 0.1, 0.2, 0.3, math.sqrt(0.86)])
    asm.feed(encode_bundle([root, hips]), 0)
    (f,) = asm.flush(1.0)
    assert np.allclose(f.quats[0], [-0.1, -0.2, 0.3, math.sqrt(0.86)], atol=1e-7)
    # our frame: root (1, 0, -2), rotation (0, -s, 0, s) = -90° about Y maps +X to +Z
    assert f.root_position == pytest.approx([1.0, 0.0, -1.0], abs=1e-6)
    assert asm.root_rotation == pytest.approx((0, -s, 0, s), abs=1e-7)


def test_unknown_addresses_and_surplus_arguments_are_ignored():
    asm = VmcAssembler(BONES)
    msgs = [build("/VMC/Ext/Blend/Val", "A", 0.5), build("/VMC/Ext/Blend/Apply"),
            build("/other", 1, 2, 3),
            encode_message(ROOT_ADDRESS, "sffffffffffffff", ["root"] + [0, 1, 0, 0, 0, 0, 1] + [1] * 7),
            encode_message(BONE_ADDRESS, "sfffffffi", ["Spine", 0, 0, 0, 0, 0, 0, 1, 99]),
            encode_message("/VMC/Ext/OK", "iiii", [1, 3, 0, 1])]
    asm.feed(encode_bundle(msgs), 0)
    (f,) = asm.flush(1.0)
    assert f.valid[BONES.index("Spine")] and f.valid.sum() == 1
    assert f.root_position == pytest.approx([0, 1, 0])
    assert asm.ok_state == (1, 3, 0, 1)
    assert asm.stats.as_dict() == {k: 0 for k in asm.stats.as_dict()}


def test_bad_arguments_names_and_values_are_counted_and_dropped():
    asm = VmcAssembler(BONES)
    msgs = [
        encode_message(BONE_ADDRESS, "siffffff", ["Hips", 1, 0, 0, 0, 0, 0, 1]),   # int position: accepted
        encode_message(BONE_ADDRESS, "ffffffff", [0] * 7 + [1]),                   # name not a string
        encode_message(BONE_ADDRESS, "sfff", ["Hips", 0, 0, 0]),                   # too few
        encode_message("/VMC/Ext/T", "s", ["now"]),                                # wrong type
        encode_message(BONE_ADDRESS, "sfffffff", ["Tail", 0, 0, 0, 0, 0, 0, 1]),   # unknown bone
        encode_message(BONE_ADDRESS, "sfffffff", ["Spine", 0, 0, 0, float("nan"), 0, 0, 1]),
        encode_message(BONE_ADDRESS, "sfffffff", ["Chest", 0, 0, 0, 0, 0, 0, 2]),  # not unit
        encode_message(BONE_ADDRESS, "sfffffff", ["Neck", 0, 0, 0, 0, 0, 0, 0]),   # zero
        encode_message(BONE_ADDRESS, "sfffffff", ["LEFTHAND", 0, 0, 0, 0, 0, 0, 1]),  # ok, any case
    ]
    asm.feed(encode_bundle(msgs), 0)
    (f,) = asm.flush(1.0)
    s = asm.stats
    # ints are numbers: ",siffffff" is accepted as a pose
    assert (s.bad_messages, s.unknown_names, s.bad_values) == (3, 1, 3)
    assert f.valid[BONES.index("Hips")] and f.valid[BONES.index("LeftHand")]
    assert f.valid.sum() == 2


def test_corrupt_datagrams_are_counted_not_raised():
    asm = VmcAssembler(BONES)
    good = encode_bundle([_bone("Hips")])
    for bad in [good[:-3], good[:20], b"#bundle\x00" + b"\x00" * 8 + struct.pack(">i", 400) + good[20:],
                b"\xff" * 16, b"/VMC/Ext/Bone/Pos\x00\x00\x00,sfffffff\x00\x00\x00Hips"]:
        assert asm.feed(bad, 0) == []
    assert asm.stats.corrupt == 5 and not asm.pending


def test_names_matched_case_insensitively_and_unknown_counted_per_message():
    asm = VmcAssembler(BONES)
    asm.feed(encode_bundle([_bone("hIpS"), _bone("LeftThumbProximal"), _bone("LeftThumbProximal")]), 0)
    (f,) = asm.flush(1.0)
    assert f.valid[0] and asm.stats.unknown_names == 2


def test_sign_continuity_per_bone():
    asm = VmcAssembler(BONES)
    q = Rotation.from_euler("x", 10, degrees=True).as_quat()
    asm.feed(_bone("Hips", q), 0)
    asm.feed(_bone("Hips", -q), 0)          # same rotation, flipped sign: closes frame 1
    (f1,) = asm.feed(_bone("Hips", q), 0)
    (f2,) = asm.flush(1.0)
    assert np.allclose(f1.quats[0], f2.quats[0])
    off = VmcAssembler(BONES, continuous=False)
    off.feed(_bone("Hips", q), 0)
    off.feed(_bone("Hips", -q), 0)
    (g,) = off.flush(1.0)
    assert np.allclose(g.quats[0], -q, atol=1e-7)


def _vmc_frame(i: int, q: np.ndarray, max_datagram: int = 1472) -> list[bytes]:
    """VirtualMotionCapture order: Root, Bones, OK, T; the last datagram holds only OK + T."""
    root = encode_pose_message(ROOT_ADDRESS, "root", (0, 1, 0.1 * i), (0, 0, 0, 1))
    bones = [encode_pose_message(BONE_ADDRESS, b, (0, 0, 0), q[j]) for j, b in enumerate(BONES)]
    tail = [encode_message("/VMC/Ext/OK", "i", [1]), encode_message("/VMC/Ext/T", "f", [i * 0.25])]
    return pack_bundles([root, *bones], max_datagram) + [encode_bundle(tail)]


@pytest.mark.parametrize("lost", ["all_bones", "first_datagram"])
def test_lost_datagrams_do_not_shift_or_merge_later_frames(lost):
    """A frame whose bone datagrams are lost leaves an orphan T (or a frame without root);
    the frames after it must still get their own T, root and bones."""
    n = 10
    q = rand_quats(n, len(BONES), 9)
    asm = VmcAssembler(BONES)
    frames = []
    for i in range(n):
        dgrams = _vmc_frame(i, q[i], max_datagram=600)
        if i == 4:
            dgrams = dgrams[-1:] if lost == "all_bones" else dgrams[1:]
        for k, d in enumerate(dgrams):
            frames += asm.feed(d, i / 60.0 + k * 1e-5)     # bursts 1/60 s apart
    frames += asm.flush(1.0)
    by_t = {round(f.source_time / 0.25): f for f in frames}
    assert len(by_t) == len(frames)                        # every T used once
    for i in range(n):
        if i == 4:
            continue
        f = by_t[i]
        assert f.valid.all() and same_rotation(f.quats, q[i])
        assert f.root_position[2] == pytest.approx(0.1 * i, abs=1e-6)
    if lost == "first_datagram":
        part = by_t[4]
        assert 0 < part.valid.sum() < len(BONES)
        assert same_rotation(part.quats[part.valid], q[4][part.valid])
    else:
        assert 4 not in by_t


def test_time_jumps_become_sequence_gaps():
    asm = VmcAssembler(BONES)
    q = rand_quats(1, len(BONES), 2)[0]
    sent = [0, 1, 2, 3, 6, 7, 8, 12, 13]          # frames 4, 5, 9, 10, 11 lost
    frames = []
    for k in sent:
        frames += feed_all(asm, encode_frame(q, BONES, time=k / 90.0, root_position=(0, 1, k)),
                           now=k / 90.0)
    frames += asm.flush(10.0)
    assert [f.seq for f in frames] == sent
    assert asm.stats.gaps == 2 and asm.stats.dropped == 5
    assert asm.frame_period == pytest.approx(1 / 90.0, rel=1e-4)


def test_jittery_sender_clock_is_not_a_gap():
    asm = VmcAssembler(BONES)
    rng = np.random.default_rng(0)
    t = np.cumsum(1 / 60.0 * (1 + rng.uniform(-0.3, 0.3, 200)))
    frames = []
    for k, tk in enumerate(t):
        frames += feed_all(asm, [encode_bundle([_bone("Hips"), encode_message("/VMC/Ext/T", "f", [tk])])],
                           now=float(tk))
    assert [f.seq for f in frames] == list(range(len(frames))) and asm.stats.gaps == 0


def test_whole_frame_fast_path_is_used_and_agrees():
    q, pkts = frames_of(30)
    q[10, 3] = [0.0, 0.0, 0.0, 2.0]                 # a bad value: general path counts it
    pkts[10] = encode_frame(q[10], BONES, time=10 / 60.0, root_position=(0.0, 1.0, 0.1))
    out = {}
    for fast in (True, False):
        asm = VmcAssembler(BONES, fast=fast)
        frames = feed_all(asm, [d for p in pkts for d in p]) + asm.flush(0.0, force=True)
        out[fast] = (frames, asm.stats.as_dict(), asm.fast_frames)
    (ff, fs, hits), (sf, ss, none) = out[True], out[False]
    assert hits >= 25 and none == 0
    assert fs == ss and fs["bad_values"] == 1
    assert [f.seq for f in ff] == [f.seq for f in sf] == list(range(30))
    assert all(np.array_equal(a.quats, b.quats) and np.array_equal(a.valid, b.valid)
               for a, b in zip(ff, sf))
    assert not ff[10].valid[3] and np.array_equal(ff[10].quats[3], ff[9].quats[3])
