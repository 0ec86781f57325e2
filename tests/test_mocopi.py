"""Sony mocopi: third-party sample packets, codec round trip, bad input and fuzzing, and
end to end over real UDP sockets on 127.0.0.1."""

from __future__ import annotations

import socket
import struct
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.drivers import open_source
from rtseg.drivers.mocopi.codec import (
    BONE_NAMES, BONE_PARENTS, FTYP, encode_frame, encode_skeleton, field,
    iter_fields, parse_packet,
)
from rtseg.core import quat as Q
from rtseg.drivers.mocopi.assembler import MocopiAssembler
from rtseg.drivers.mocopi.source import ForwardKinematics, MocopiSource
from rtseg.core.profiles import suit_profile
from rtseg.simulators.mocopi_sender import MocopiSender
from rtseg.simulators.synth.motion import synthesize
from vendor_helpers import (append_junk, assert_same_cuts, assert_sane_frame, flip_bits,
                            assert_refused, run_live, serial_reference, simulate_into,
                            truncate)

FIXTURES = Path(__file__).parent / "fixtures" / "mocopi"
N = len(BONE_NAMES)


def sample(name: str) -> bytes:
    return (FIXTURES / name).read_bytes()


def random_pose(n: int, seed: int = 0) -> np.ndarray:
    q = Rotation.random(n * N, random_state=seed).as_quat().reshape(n, N, 4)
    return q.astype(np.float32).astype(np.float64)


# --------------------------------------------------------------------------- samples (MIT)

def test_sample_skeleton_packet_gives_the_documented_values():
    """t-34400/mocopi_protocol_supplement parser/sample/sample_skdf.bin: what its parser
    prints (head, sndf, 27 bndt with parents, rest pose)."""
    pkt = parse_packet(sample("sample_skdf.bin"))
    assert pkt.ftyp == b"sony motion format" and pkt.version == 1 and pkt.port == 12351
    sk = pkt.skeleton
    assert pkt.frame is None and sk is not None
    assert sk.bone_ids.tolist() == list(range(27))
    assert sk.parent_ids.tolist() == list(BONE_PARENTS)          # 65535 -> -1 for the root
    assert sk.tran[0].tolist() == pytest.approx([0, 0, 0, -1, 0, 0.9329289793968201, 0])
    assert sk.tran[1, 4:].tolist() == pytest.approx([0.0, 0.05078670009970665,
                                                     -0.01151379942893982])
    assert sk.tran[12, 4:].tolist() == pytest.approx([0.12954699993133545, 0.03249499946832657,
                                                      -0.032687198370695114])
    # every rest rotation is the sign-flipped identity (0, 0, 0, -1)
    assert np.array_equal(np.abs(sk.tran[:, :4]), np.tile([0, 0, 0, 1], (27, 1)))
    # the field tree: head 35, sndf 26, skdf 1736 > bons 1728 > 27 bndt of 56 bytes
    data = sample("sample_skdf.bin")
    top = [(t, b - a) for t, a, b in iter_fields(data, 0, len(data))]
    assert top == [(b"head", 35), (b"sndf", 26), (b"skdf", 1736)]


def test_sample_frame_packet_gives_the_documented_values():
    pkt = parse_packet(sample("sample_fram.bin"))
    fr = pkt.frame
    assert pkt.skeleton is None and fr is not None and pkt.port == 12351
    assert fr.fnum == 1 and fr.time == 0 and fr.tmcd is None
    when = datetime.fromtimestamp(fr.uttm, timezone.utc)
    assert when.replace(tzinfo=None) == datetime(2023, 12, 29, 0, 49, 58, 551346)
    assert fr.bone_ids.tolist() == list(range(27))
    assert fr.tran[0].tolist() == pytest.approx([0, 0, 0, -1, 0, 0.9329289793968201, 0])
    asm = MocopiAssembler()
    out = asm.feed(sample("sample_fram.bin"), 3.0)
    assert len(out) == 1
    f = out[0]
    assert f.valid.all() and f.seq == 1 and f.source_time == fr.uttm and f.recv_time == 3.0
    # sign-flipped identities are accepted: the same rotation, made continuous with the
    # identity each joint starts from
    assert np.array_equal(f.quats, np.tile([0.0, 0.0, 0.0, 1.0], (27, 1)) * np.sign(f.quats[:, 3:]))
    assert np.allclose(f.quats, [0, 0, 0, 1])
    assert f.root_position.tolist() == pytest.approx([0.0, 0.9329289793968201, 0.0])
    assert asm.stats.bad_values == asm.stats.corrupt == 0
    assert asm.feed(sample("sample_skdf.bin"), 3.1) == [] and asm.skeleton is not None


def test_encoder_reproduces_the_sample_layout():
    """Encoding the sample's own values gives the sample's fram and btrs bytes (the header
    ipad differs: the sample carries the sender's address)."""
    data = sample("sample_fram.bin")
    fr = parse_packet(data).frame
    mine = encode_frame(fr.fnum, fr.tran[:, :4], fr.tran[:, 4:], time=fr.time, uttm=fr.uttm)
    start = data.index(b"fram") - 4
    assert mine[mine.index(b"fram") - 4:] == data[start:]
    sk = parse_packet(sample("sample_skdf.bin")).skeleton
    mine = encode_skeleton(sk.parent_ids.tolist(), sk.tran)
    d2 = sample("sample_skdf.bin")
    assert mine[mine.index(b"skdf") - 4:] == d2[d2.index(b"skdf") - 4:]


# --------------------------------------------------------------------------- codec

def test_round_trip_is_exact_to_float32():
    q = random_pose(40, seed=1)
    pos = np.random.default_rng(2).normal(size=(40, N, 3)).astype(np.float32)
    asm = MocopiAssembler(continuous=False)
    for k in range(40):
        out = asm.feed(encode_frame(k, q[k], pos[k], time=k * 20, uttm=1e9 + k / 50), k)
        assert len(out) == 1
        f = out[0]
        assert np.array_equal(f.quats, q[k]) and f.valid.all() and f.seq == k
        assert f.source_time == 1e9 + k / 50
        assert np.array_equal(f.root_position, pos[k, 0].astype(np.float64))
    # default: signs made continuous; same rotations
    asm = MocopiAssembler()
    for k in range(40):
        g = asm.feed(encode_frame(k, q[k]), 0)[0].quats
        assert np.all(np.all(g == q[k], -1) | np.all(g == -q[k], -1))


def test_generic_path_equals_fast_path_and_optional_fields():
    """A frame with tmcd and btdt records in a non-standard layout (extra sub-field) goes
    through the field-by-field path and decodes to the same values."""
    q = random_pose(1, seed=3)[0]
    fast = parse_packet(encode_frame(5, q, uttm=12.5)).frame
    recs = b"".join(field(b"btdt", field(b"bnid", struct.pack("<H", i))
                          + field(b"xtra", b"\x01\x02\x03")
                          + field(b"tran", np.r_[q[i], 0, 0, 0].astype("<f4").tobytes()))
                    for i in range(N))
    body = (field(b"fnum", struct.pack("<I", 5)) + field(b"time", struct.pack("<I", 0))
            + field(b"uttm", struct.pack("<d", 12.5)) + field(b"tmcd", b"\x01\x02\x03\x04")
            + field(b"btrs", recs))
    head = field(b"head", field(b"ftyp", FTYP) + field(b"vrsn", b"\x01"))
    slow = parse_packet(head + field(b"fram", body)).frame
    assert slow.tmcd == b"\x01\x02\x03\x04" and slow.uttm == fast.uttm == 12.5
    assert np.array_equal(slow.tran, fast.tran) and np.array_equal(slow.bone_ids, fast.bone_ids)


def test_partial_and_bad_frames_are_counted():
    q = random_pose(2, seed=4)
    asm = MocopiAssembler(continuous=False)
    asm.feed(encode_frame(0, q[0]), 0)
    # only 20 bones sent: the rest keep their last value, invalid
    out = asm.feed(encode_frame(1, q[1][:20], bone_ids=range(20)), 0)[0]
    assert out.valid[:20].all() and not out.valid[20:].any()
    assert np.array_equal(out.quats[20:], q[0][20:])
    bad = q[1].copy()
    bad[4] = np.nan
    bad[7] = [0, 0, 0, 3.0]
    out = asm.feed(encode_frame(2, bad), 0)[0]
    assert asm.stats.bad_values == 2 and not out.valid[4] and not out.valid[7]
    assert np.isfinite(out.quats).all()
    good = encode_frame(3, q[0])
    for d in (good[:-3], good[:5], b"", good.replace(FTYP, b"sony motion formaX"),
              field(b"head", field(b"ftyp", FTYP))):
        assert asm.feed(d, 0) == []
    assert asm.stats.corrupt == 3 and asm.stats.bad_messages == 2


def fuzz_inputs(n: int, seed: int) -> list[bytes]:
    rng = np.random.default_rng(seed)
    q = random_pose(2, seed=seed)
    seeds = [sample("sample_fram.bin"), sample("sample_skdf.bin")]
    out = []
    for i in range(n):
        pick = rng.integers(len(seeds) + 2)
        # the frames numbered on (a repeated fnum is a repeated datagram, dropped whole)
        d = bytearray(encode_frame(i, q[pick], uttm=1.0 + i) if pick < 2
                      else seeds[pick - 2])
        op = rng.integers(5)
        if op == 0:
            flip_bits(rng, d)
        elif op == 1:
            d = truncate(rng, d)
        elif op == 2:                                    # a length field rewritten
            pos = [i - 4 for i in range(4, len(d) - 4) if d[i:i + 4].isalpha()]
            if pos:
                p = pos[rng.integers(len(pos))]
                d[p:p + 4] = struct.pack("<I", int(rng.integers(0, 1 << 32)))
        elif op == 3:
            d = append_junk(rng, d)
        else:
            d = bytearray(rng.bytes(rng.integers(0, 400)))
        out.append(bytes(d))
    return out


def test_a_repeated_or_late_frame_is_dropped_and_counted():
    """A frame whose fnum repeats the last one or lies a few behind it (repeated or
    reordered on the way) is dropped, 1 in bad_messages each; the frames' seq never goes
    back (the live loop would take that for a restarted stream), nothing counts as lost."""
    q = random_pose(6, seed=3)
    d = [encode_frame(k, q[k], uttm=1.0 + k) for k in range(6)]
    asm = MocopiAssembler()
    got = [f for k, g in enumerate(d[:4] + [d[3], d[1]] + d[4:]) for f in asm.feed(g, k * 0.02)]
    assert [f.seq for f in got] == list(range(6))
    st = asm.stats
    assert (st.bad_messages, st.dropped, st.gaps, st.counter_jumps) == (2, 0, 0, 0)


def test_fuzzed_datagrams_never_escape():
    asm = MocopiAssembler()
    frames = 0
    for k, d in enumerate(fuzz_inputs(10_000, seed=7)):
        for f in asm.feed(d, k * 1e-3):
            frames += 1
            assert_sane_frame(f, 27)
    assert frames > 200 and asm.stats.corrupt > 3000      # both paths were exercised


def test_forward_kinematics_matches_the_reference_chain():
    fk = ForwardKinematics(BONE_PARENTS)
    q = random_pose(3, seed=9)
    for k in range(3):
        assert np.allclose(fk(q[k]), Q.global_from_local(q[k][None], list(BONE_PARENTS))[0],
                           atol=1e-15)
    valid = np.ones(N, dtype=bool)
    valid[BONE_NAMES.index("torso_7")] = False
    v = fk.chain_valid(valid)
    below = {"torso_7", "neck_1", "neck_2", "head", "l_shoulder", "l_up_arm", "l_low_arm",
             "l_hand", "r_shoulder", "r_up_arm", "r_low_arm", "r_hand"}
    assert {BONE_NAMES[j] for j in np.flatnonzero(~v)} == below
    with pytest.raises(ValueError):
        ForwardKinematics([1, -1])


# --------------------------------------------------------------------------- sockets

def test_url_defaults_options_and_errors():
    src = open_source("mocopi://:0")
    try:
        assert isinstance(src, MocopiSource) and src.host == "127.0.0.1" and src.port > 0
        prof = suit_profile("mocopi")
        assert src.space == "global" and src.joint_names == list(prof.bones)
        assert src.bone_ids == list(range(27))
        # the suit's hierarchy is mocopi's own (BONE_PARENTS)
        assert src.parents == list(BONE_PARENTS)
    finally:
        src.close()
    local = open_source("mocopi://:0?space=local")
    try:
        assert local.space == "local" and isinstance(local.assembler, MocopiAssembler)
    finally:
        local.close()
    assert_refused((("mocopi://:0?character=1", "character"), ("mocopi://:99999", "range"),
                    ("mocopi://:0?space=world", "space"),
                    ("mocopi://:0?queue=0", "queue"), ("mocopi://:0?allow=", "allow")))


def test_sample_packets_over_udp_and_allow_list():
    src = open_source("mocopi://127.0.0.1:0?allow=127.0.0.1")
    other = open_source("mocopi://127.0.0.1:0?allow=192.0.2.1")
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for port in (src.port, other.port):
                s.sendto(sample("sample_skdf.bin"), ("127.0.0.1", port))
                s.sendto(sample("sample_fram.bin"), ("127.0.0.1", port))
                s.sendto(b"junk", ("127.0.0.1", port))
        f = src.read(timeout=2)
        assert f is not None and f.seq == 1 and f.valid.all()
        deadline = time.monotonic() + 2
        while (src.stats.corrupt < 1 or other.stats.refused_senders < 3) and \
                time.monotonic() < deadline:
            time.sleep(0.01)
        assert src.stats.corrupt == 1 and src.assembler.skeleton is not None
        assert other.stats.refused_senders == 3 and other.read(timeout=0.05) is None
    finally:
        src.close()
        other.close()


def test_simulator_through_live_session_gives_valid_joints_and_cuts():
    rate, speed = 120.0, 4.0
    take = synthesize("idle:3,walk:4,punch:4,squat:4", frame_rate=rate, seed=3).take
    src = open_source(f"mocopi://127.0.0.1:0?rate={rate:g}&queue=4096")
    sender = MocopiSender(take, "127.0.0.1", src.port, speed=speed, unix_start=1.7e9,
                          skeleton_every=120)
    frames, cuts, summary = run_live(src, sender, take, rate, speed)
    assert len(frames) == take.n_frames == summary.frames_received
    assert all(f.valid.all() for f in frames)
    assert [f.seq for f in frames] == list(range(take.n_frames))
    st = np.array([f.source_time for f in frames]) - 1.7e9
    assert np.allclose(st, np.arange(take.n_frames) / rate, atol=1e-6)   # the take's clock
    # the rotations that arrived are the ones the simulator sent, chained to global ones
    sent = Q.global_from_local(sender.local_quats, list(BONE_PARENTS))
    got = np.stack([f.quats for f in frames])
    d = np.minimum(np.abs(got - sent).max(-1), np.abs(got + sent).max(-1))
    assert d.max() < 1e-6
    assert src.stats.corrupt == src.stats.dropped == 0
    assert len(cuts) >= 1, "no cut on a take with 3 behaviour changes"


def test_rtseg_simulate_mocopi_command_reaches_the_source():
    out, port, frames = simulate_into("mocopi://127.0.0.1:0?queue=10000", "mocopi", "50")
    assert f'rtseg live "mocopi://127.0.0.1:{port}?rate=50"' in out
    assert "filled from their parents: torso_1, torso_3" in out
    assert len(frames) == 200 and all(f.valid.all() for f in frames)


def test_real_take_cuts_match_the_serial_suit(data_dir):
    """86_01 (CMU, 38 s) through the mocopi codec and the source's default global
    conversion gives the cuts the 17-sensor serial suit gives, within 0.25 s."""
    from rtseg.live.replay import replay_frames

    take, serial, ref = serial_reference(data_dir)
    rate = take.frame_rate
    sender = MocopiSender(take, "127.0.0.1", 9, unix_start=1.7e9)   # encode only
    asm = MocopiAssembler(sender.bone_ids)
    fk = ForwardKinematics(sender.suit.parents)
    moc = [(fk(f.quats), f.valid, f.seq, i / rate, f.source_time) for i in range(take.n_frames)
           for d in sender.encode(i, i, i / rate) for f in asm.feed(d, i / rate)]
    assert len(serial) == len(moc) == take.n_frames
    got = replay_frames(moc, list(sender.suit.bones), list(sender.suit.parents), "global", rate)
    assert_same_cuts(got, ref, rate)


def test_learned_layout_and_general_paths_agree():
    q = random_pose(30, seed=13)
    fast, slow = MocopiAssembler(), MocopiAssembler(fast=False)
    for k in range(30):
        d = encode_frame(k, q[k], np.full((N, 3), 0.5), uttm=100.0 + k, time=k)
        a, b = fast.feed(d, 0.0)[0], slow.feed(d, 0.0)[0]
        assert np.array_equal(a.quats, b.quats) and a.seq == b.seq == k
        assert a.source_time == b.source_time and np.array_equal(a.root_position, b.root_position)
    assert fast.fast_frames == 29 and slow.fast_frames == 0
    # a packet of another layout (no uttm) falls back and is learned in turn
    out = fast.feed(encode_frame(99, q[0]), 0.0)[0]
    assert out.seq == 99 and out.source_time is None and fast.fast_frames == 29


def test_slightly_off_unit_rotations_are_renormalised():
    q = random_pose(1, seed=15)[0]
    scaled = q.copy()
    scaled[9] *= 0.99
    f = MocopiAssembler(continuous=False).feed(encode_frame(0, scaled), 0)[0]
    assert f.valid.all() and np.allclose(np.linalg.norm(f.quats, axis=1), 1.0, atol=1e-12)
    assert np.allclose(f.quats[9], q[9], atol=1e-7)
    assert np.array_equal(np.delete(f.quats, 9, 0), np.delete(q, 9, 0))


def test_rtseg_simulate_mocopi_with_faults_counts_the_missing_frames():
    """``--faults drop=...``: the frames the simulator left out are the fnum gaps the
    source counts."""
    out, port, frames = simulate_into("mocopi://127.0.0.1:0?queue=10000&rcvbuf=4194304",
                                      "mocopi", "60", "--faults", "drop=0.1,seed=4")
    dropped = int(out.split(" dropped by faults")[0].rsplit("; ", 1)[1])
    seqs = [f.seq for f in frames]
    assert dropped > 5 and len(frames) == 240 - dropped
    assert seqs == sorted(seqs) and seqs[-1] + 1 - len(seqs) <= dropped
