"""Xsens MVN: codec round trip, multi-datagram and multi-character frames, other message
types, bad input and fuzzing, and end to end over real UDP sockets on 127.0.0.1."""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.drivers import open_source
from rtseg.drivers.mvn.codec import (
    BODY_SEGMENTS, HEADER_SIZE, ITEM_SIZE, encode_datagrams,
    encode_message, from_mvn_pos, from_mvn_quat, parse_header, parse_meta, to_mvn_pos,
    to_mvn_quat,
)
from rtseg.drivers.mvn.assembler import MvnAssembler
from rtseg.drivers.mvn.source import MvnSource
from rtseg.core.profiles import resolve_joints, suit_profile
from rtseg.simulators.mvn_sender import MvnSender
from rtseg.simulators.synth.motion import synthesize
from vendor_helpers import (append_junk, assert_same_cuts, assert_sane_frame, flip_bits,
                            assert_refused, read_all, run_live, serial_reference,
                            simulate_into, truncate)

IDS = list(range(1, BODY_SEGMENTS + 1))


def random_pose(n: int, seed: int = 0) -> np.ndarray:
    """(n, 23, 4) random unit quaternions, rounded to float32 (what the wire carries)."""
    q = Rotation.random(n * len(IDS), random_state=seed).as_quat().reshape(n, len(IDS), 4)
    return q.astype(np.float32).astype(np.float64)


def same_up_to_sign(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.all(np.all(a == b, -1) | np.all(a == -b, -1)))


def feed_all(asm: MvnAssembler, dgrams, now: float = 0.0) -> list:
    out = []
    for d in dgrams:
        out += asm.feed(d, now)
    return out


# --------------------------------------------------------------------------- codec

def test_frame_conversion_is_a_rotation_and_inverts_exactly():
    q = random_pose(4)[:, 0]
    assert np.array_equal(from_mvn_quat(to_mvn_quat(q)), q)
    p = np.random.default_rng(0).normal(size=(5, 3))
    assert np.array_equal(from_mvn_pos(to_mvn_pos(p)), p)
    # MVN up (+Z) is rtseg up (+Y); the relabelling keeps handedness (det +1)
    assert np.array_equal(from_mvn_pos(np.array([0.0, 0.0, 1.0])), [0.0, 1.0, 0.0])
    assert np.isclose(np.linalg.det(from_mvn_pos(np.eye(3))), 1.0)
    # a 90 degree turn about MVN's up axis is one about rtseg's up axis
    w = np.cos(np.pi / 4)
    assert np.allclose(from_mvn_quat(np.array([w, 0, 0, w])), [0, w, 0, w])


def test_header_layout_matches_the_specification():
    d = encode_datagrams(70000, 123456, [1, 2], random_pose(1)[0, :2], character=3)[0]
    assert len(d) == HEADER_SIZE + 2 * ITEM_SIZE and d[:6] == b"MXTP02"
    assert struct.unpack(">I", d[6:10])[0] == 70000 and d[10] == 0x80 and d[11] == 2
    assert struct.unpack(">I", d[12:16])[0] == 123456 and d[16] == 3 and d[17] == 23
    assert struct.unpack(">H", d[22:24])[0] == 2 * ITEM_SIZE
    assert struct.unpack(">i", d[24:28])[0] == 1
    h = parse_header(d)
    assert (h.msg_type, h.sample, h.index, h.last, h.items, h.time_ms, h.character) == \
        ("02", 70000, 0, True, 2, 123456, 3)


def test_round_trip_is_exact_to_float32():
    q = random_pose(50, seed=1)
    pos = np.random.default_rng(2).normal(size=(50, len(IDS), 3)).astype(np.float32)
    asm = MvnAssembler(IDS, continuous=False)
    frames = []
    for k in range(50):
        frames += feed_all(asm, encode_datagrams(k, 10 * k, IDS, q[k], pos[k]), k * 0.01)
    assert len(frames) == 50
    for k, f in enumerate(frames):
        assert np.array_equal(f.quats, q[k]) and f.valid.all()
        assert f.seq == k and f.source_time == pytest.approx(k / 100.0)
        assert np.array_equal(f.root_position, pos[k, 0].astype(np.float64))
    # with sign continuity on (the default) the rotations are the same up to sign
    asm = MvnAssembler(IDS)
    got = [feed_all(asm, encode_datagrams(k, k, IDS, q[k]))[0].quats for k in range(50)]
    assert all(same_up_to_sign(g, q[k]) for k, g in enumerate(got))


def test_multi_datagram_frames_in_any_order():
    q = random_pose(3, seed=4)
    small = HEADER_SIZE + 5 * ITEM_SIZE                 # 5 segments per datagram: 5 parts
    parts = encode_datagrams(7, 70, IDS, q[0], max_datagram=small)
    assert len(parts) == 5 and [parse_header(p).last for p in parts] == [False] * 4 + [True]
    assert [parse_header(p).index for p in parts] == list(range(5))
    asm = MvnAssembler(IDS, continuous=False)
    out = feed_all(asm, parts[:-1])
    assert out == []                                   # not complete before the last part
    out = asm.feed(parts[-1], 0.0)
    assert len(out) == 1 and np.array_equal(out[0].quats, q[0]) and out[0].valid.all()
    # reordered: the last-flagged datagram first; complete when the rest are in
    parts = encode_datagrams(8, 80, IDS, q[1], max_datagram=small)
    order = [4, 2, 0, 3, 1]
    outs = [asm.feed(parts[i], 0.0) for i in order]
    assert [len(o) for o in outs] == [0, 0, 0, 0, 1]
    assert np.array_equal(outs[-1][0].quats, q[1]) and outs[-1][0].seq == 8


def test_lost_datagram_gives_a_frame_with_those_segments_invalid():
    q = random_pose(2, seed=5)
    small = HEADER_SIZE + 10 * ITEM_SIZE
    a = encode_datagrams(1, 0, IDS, q[0], max_datagram=small)        # 3 parts: 10, 10, 3
    b = encode_datagrams(2, 10, IDS, q[1], max_datagram=small)
    asm = MvnAssembler(IDS, continuous=False)
    assert feed_all(asm, [a[0], a[2]]) == []
    out = asm.feed(b[0], 1.0)                  # the next sample closes the open frame
    assert len(out) == 1 and asm.incomplete_frames == 1
    f = out[0]
    assert f.seq == 1 and f.valid.sum() == 13
    assert not f.valid[10:20].any() and f.valid[:10].all() and f.valid[20:].all()
    assert np.array_equal(f.quats[:10], q[0, :10])
    # a late datagram of sample 1 is counted and dropped, not decoded into frame 2
    assert asm.feed(a[1], 1.0) == [] and asm.stats.bad_messages == 1
    assert asm.stats.dropped == 0                 # nothing was lost: a repeat came late
    out = feed_all(asm, b[1:])
    assert len(out) == 1 and out[0].valid.all() and out[0].seq == 2
    # quiet flush emits an open frame on its own
    c = encode_datagrams(3, 20, IDS, q[0], max_datagram=small)
    assert asm.feed(c[0], 5.0) == [] and asm.flush(5.001) == []
    out = asm.flush(5.0 + 2 * asm.quiet)
    assert len(out) == 1 and out[0].valid.sum() == 10


def test_several_characters_are_told_apart():
    q = random_pose(6, seed=6)
    dg = []
    for k in range(3):
        dg += encode_datagrams(k, k, IDS, q[k], character=0)
        dg += encode_datagrams(k + 100, k, IDS, q[k + 3], character=1,
                               max_datagram=HEADER_SIZE + 8 * ITEM_SIZE)
    for char, rows in ((0, q[:3]), (1, q[3:])):
        asm = MvnAssembler(IDS, character=char, continuous=False)
        frames = feed_all(asm, dg)
        assert len(frames) == 3
        assert all(np.array_equal(f.quats, r) for f, r in zip(frames, rows))
        assert asm.other_characters == ({1: 9} if char == 0 else {0: 3})
        assert asm.characters_seen == {0, 1}


def test_meta_scaling_centre_of_mass_and_timecode_are_parsed_never_fatal():
    asm = MvnAssembler(IDS)
    meta = b"name:Dancer\nxmid:1234\ncolor:ff0000\n"
    assert asm.feed(encode_message("12", struct.pack(">I", len(meta)) + meta), 0) == []
    assert asm.meta == {"name": "Dancer", "xmid": "1234", "color": "ff0000"}
    assert parse_meta(b"name:Bare\n") == {"name": "Bare"}      # without the length prefix
    scale = struct.pack(">I", 2) + b"".join(
        struct.pack(">I", len(n)) + n + struct.pack(">3f", *xyz)
        for n, xyz in ((b"Pelvis", (0.0, 0.0, 1.0)), (b"L5", (0.5, 0.0, 1.25))))
    asm.feed(encode_message("13", scale), 0)
    assert asm.scaling == {"Pelvis": (0.0, 1.0, 0.0), "L5": (0.0, 1.25, 0.5)}
    asm.feed(encode_message("24", struct.pack(">3f", 0.25, 0.5, 1.0)), 0)
    assert asm.center_of_mass == (0.5, 1.0, 0.25)
    asm.feed(encode_message("25", b"12:34:56.789"), 0)
    assert asm.timecode == "12:34:56.789"
    for t in ("01", "03", "20", "21", "22", "23", "99"):
        assert asm.feed(encode_message(t, b"\x00" * 40), 0) == []
    assert set(asm.skipped_types) == {"01", "03", "20", "21", "22", "23", "99"}
    # truncated ones: counted, never raised
    asm.feed(encode_message("24", b"\x00\x01"), 0)
    asm.feed(encode_message("13", struct.pack(">I", 5) + b"\x00\x00\x00\x09Pel"), 0)
    assert asm.stats.bad_messages == 1 and asm.stats.corrupt == 0
    # pose frames still decode afterwards
    assert len(asm.feed(encode_datagrams(1, 1, IDS, random_pose(1)[0])[0], 0)) == 1


@pytest.mark.parametrize("data,counter", [
    (b"", "corrupt"), (b"MXTP02" + b"\x00" * 10, "corrupt"),
    (b"XXXX02" + b"\x00" * 18, "corrupt"), (b"MXTPab" + b"\x00" * 18, "corrupt"),
])
def test_bad_headers_are_counted(data, counter):
    asm = MvnAssembler(IDS)
    assert asm.feed(data, 0.0) == [] and getattr(asm.stats, counter) == 1


def test_payload_overruns_and_bad_values_are_counted():
    q = random_pose(1)[0]
    d = bytearray(encode_datagrams(1, 0, IDS, q)[0])
    asm = MvnAssembler(IDS)
    assert asm.feed(bytes(d[:-5]), 0) == [] and asm.stats.corrupt == 1     # truncated
    d2 = bytearray(d)
    d2[11] = 40                                           # claims 40 items
    assert asm.feed(bytes(d2), 0) == [] and asm.stats.corrupt == 2
    bad = q.copy()
    bad[3] = np.nan
    bad[5] = [0.0, 0.0, 0.0, 2.0]
    out = asm.feed(encode_datagrams(2, 0, IDS, bad)[0], 0)
    assert len(out) == 1 and asm.stats.bad_values == 2
    assert not out[0].valid[3] and not out[0].valid[5] and out[0].valid.sum() == 21
    assert np.isfinite(out[0].quats).all()


def fuzz_inputs(n: int, seed: int) -> list[bytes]:
    """Valid datagrams of every type, mutated (bit flips, truncation, splices, random
    header fields), plus random bytes."""
    rng = np.random.default_rng(seed)
    q = random_pose(4, seed=seed)
    base = [encode_datagrams(k, k, IDS, q[k], max_datagram=HEADER_SIZE + 7 * ITEM_SIZE)
            for k in range(4)]
    seeds = [d for frame in base for d in frame] + [
        encode_message("12", b"\x00\x00\x00\x0bname:Fuzzed"),
        encode_message("13", struct.pack(">I", 1) + struct.pack(">I", 2) + b"L5" + bytes(12)),
        encode_message("24", bytes(12)), encode_message("25", b"01:02:03.004")]
    out = []
    for _ in range(n):
        d = bytearray(seeds[rng.integers(len(seeds))])
        op = rng.integers(6)
        if op == 0:
            flip_bits(rng, d)
        elif op == 1:
            d = truncate(rng, d)
        elif op == 2:
            d[rng.integers(6, 24):rng.integers(6, 24) + 1] = rng.bytes(1)   # header fields
        elif op == 3:
            d = append_junk(rng, d)
        elif op == 4:
            d = bytearray(b"MXTP" + rng.bytes(rng.integers(0, 200)))
        else:
            d = bytearray(rng.bytes(rng.integers(0, 300)))
        out.append(bytes(d))
    return out


def test_fuzzed_datagrams_never_escape():
    asm = MvnAssembler(IDS, quiet=0.0)
    frames = 0
    inputs = fuzz_inputs(10_000, seed=11)
    for k, d in enumerate(inputs):
        for f in asm.feed(d, k * 1e-3) + asm.flush(k * 1e-3):
            frames += 1
            assert_sane_frame(f, 23)
    st = asm.stats
    assert frames > 100 and st.corrupt > 1000        # both paths were exercised


# --------------------------------------------------------------------------- sockets

def test_url_defaults_options_and_errors():
    src = open_source("mvn://:0")
    try:
        assert isinstance(src, MvnSource) and src.host == "127.0.0.1" and src.port > 0
        assert src.space == "global" and len(src.joint_names) == 23
        prof = suit_profile("xsens-mvn")
        assert src.joint_names == list(prof.bones) and src.parents == list(prof.parents)
        assert src.segment_ids == IDS
        # the pose features resolve on the MVN suit (unity profile)
        names = [src.joint_names[i] for i in resolve_joints("unity", src.joint_names)]
        assert "Chest" in names and "L3" not in names
    finally:
        src.close()
    assert_refused((("mvn://:0?character=300", "character"), ("mvn://:0?nope=1", "nope"),
                    ("mvn://:abc", "port"), ("mvn://:0?allow=notanip", "allow"),
                    ("mvn://:0?suit=nosuch", "nosuch")))


def test_allow_list_refuses_other_senders_before_decoding():
    src = open_source("mvn://127.0.0.1:0?allow=10.9.8.7")
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for d in encode_datagrams(1, 0, IDS, random_pose(1)[0]):
                s.sendto(d, ("127.0.0.1", src.port))
        deadline = time.monotonic() + 2
        while src.stats.refused_senders < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert src.stats.refused_senders == 1 and src.read(timeout=0.1) is None
    finally:
        src.close()


def test_two_characters_over_udp_into_one_source_each():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=1).take
    # 2 sources x 2 senders x 4 datagrams per frame: modest speed and a large receive
    # buffer so a loaded 2-core machine does not drop datagrams in the kernel
    a = open_source("mvn://127.0.0.1:0?character=0&queue=10000&rcvbuf=4194304")
    b = open_source("mvn://127.0.0.1:0?character=2&queue=10000&rcvbuf=4194304")
    senders = [MvnSender(take, "127.0.0.1", src.port, character=c, speed=3.0,
                         max_datagram=HEADER_SIZE + 6 * ITEM_SIZE)
               for src in (a, b) for c in (0, 2)]
    try:
        for s in senders:
            s.start()
        assert all(s.wait(10) for s in senders)
        time.sleep(0.2)
        for src in (a, b):
            frames = read_all(src, 0.2)
            assert len(frames) == take.n_frames
            assert [f.seq for f in frames] == list(range(take.n_frames))
            assert all(f.valid.all() for f in frames)
            assert src.assembler.other_characters == {2 if src is a else 0: 4 * take.n_frames + 1}
            assert src.assembler.meta == {"name": "rtseg"}
            assert src.assembler.incomplete_frames == 0
    finally:
        for s in senders:
            s.stop()
        a.close()
        b.close()


def test_simulator_through_live_session_gives_valid_joints_and_cuts(tmp_path):
    """A synthetic take with 3 behaviour changes, sent x4 as MVN over 127.0.0.1 into a
    LiveSession: every frame arrives with every segment valid, the source clock is the
    take's, and the detectors cut."""
    rate, speed = 120.0, 4.0
    take = synthesize("idle:3,walk:4,punch:4,squat:4", frame_rate=rate, seed=3).take
    src = open_source(f"mvn://127.0.0.1:0?rate={rate:g}&queue=4096")
    sender = MvnSender(take, "127.0.0.1", src.port, speed=speed)
    frames, cuts, summary = run_live(src, sender, take, rate, speed)
    assert len(frames) == take.n_frames == summary.frames_received
    assert all(f.valid.all() for f in frames)
    st = np.array([f.source_time for f in frames])
    assert np.allclose(st, np.round(np.arange(take.n_frames) / rate * 1000) / 1000)
    assert src.stats.corrupt == src.stats.dropped == 0
    assert len(cuts) >= 1, "no cut on a take with 3 behaviour changes"


def test_rtseg_simulate_mvn_command_reaches_the_source():
    out, port, frames = simulate_into("mvn://127.0.0.1:0?queue=10000&character=1", "mvn", "60",
                                      "--character", "1")
    assert f'rtseg live "mvn://127.0.0.1:{port}?rate=60&character=1"' in out
    assert "filled from their parents: L3, T12, RightShoulder" in out
    assert len(frames) == 240 and all(f.valid.all() for f in frames)


def test_real_take_cuts_match_the_serial_suit(data_dir):
    """86_01 (CMU, 38 s) through the MVN codec gives the cuts the 17-sensor serial suit
    gives through its codec, within 0.25 s: the suit changes the features only where the
    joints differ (offline pipeline, the live loop's own, no sockets)."""
    from rtseg.live.replay import replay_frames

    take, serial, ref = serial_reference(data_dir)
    rate = take.frame_rate
    sender = MvnSender(take, "127.0.0.1", 9)            # encode only: never started
    asm = MvnAssembler(sender.segment_ids)
    mvn = [(f.quats, f.valid, f.seq, i / rate, f.source_time) for i in range(take.n_frames)
           for d in sender.encode(i, i, i / rate) for f in asm.feed(d, i / rate)]
    assert len(serial) == len(mvn) == take.n_frames
    assert all(v.all() for _, v, *_ in mvn)
    got = replay_frames(mvn, list(sender.suit.bones), list(sender.suit.parents), "global", rate)
    assert_same_cuts(got, ref, rate)


def test_fast_and_general_paths_agree():
    """Segments in suit order take the vectorised path; the same frames with the items
    shuffled take the general one: identical frames (signs made continuous in both)."""
    q = random_pose(30, seed=12)
    pos = np.random.default_rng(3).normal(size=(30, 23, 3)).astype(np.float32)
    perm = np.random.default_rng(4).permutation(23)
    fast, slow = MvnAssembler(IDS), MvnAssembler(IDS)
    for k in range(30):
        a = fast.feed(encode_datagrams(k, k, IDS, q[k], pos[k])[0], 0.0)[0]
        b = slow.feed(encode_datagrams(k, k, [IDS[i] for i in perm], q[k][perm],
                                       pos[k][perm])[0], 0.0)[0]
        assert np.array_equal(a.quats, b.quats) and np.array_equal(a.valid, b.valid)
        assert np.array_equal(a.root_position, b.root_position)


def test_slightly_off_unit_quaternions_are_renormalised():
    q = random_pose(1, seed=14)[0]
    scaled = q.copy()
    scaled[2] *= 1.01                        # within the tolerance: accepted, renormalised
    f = MvnAssembler(IDS, continuous=False).feed(encode_datagrams(1, 0, IDS, scaled)[0], 0)[0]
    assert f.valid.all() and np.allclose(np.linalg.norm(f.quats, axis=1), 1.0, atol=1e-12)
    assert np.allclose(f.quats[2], q[2], atol=1e-7)
    assert np.array_equal(np.delete(f.quats, 2, 0), np.delete(q, 2, 0))   # others untouched


# --------------------------------------------------------------------------- TCP, faults

def test_tcp_stream_is_cut_into_messages_and_resynchronised_after_damage():
    """MxtpStream: the datagrams sent back to back come out whole whatever the read
    boundaries; bytes that do not start a header are skipped to the next "MXTP" and each
    such run counts once."""
    from rtseg.drivers.mvn.codec import MxtpStream
    q = random_pose(6, seed=4)
    msgs = [encode_message("12", b"name:tcp\n")]
    msgs += [d for i in range(6) for d in encode_datagrams(
        i, i * 8, IDS, q[i], max_datagram=HEADER_SIZE + 10 * ITEM_SIZE)]
    data = b"".join(msgs)
    rng = np.random.default_rng(0)
    for _ in range(20):
        cuts = np.sort(rng.choice(np.arange(1, len(data)), 12, replace=False))
        st = MxtpStream()
        got = [m for a, b in zip([0, *cuts], [*cuts, len(data)]) for m in st.feed(data[a:b])]
        assert got == msgs and st.resyncs == 0
    st = MxtpStream()
    damaged = b"xyzMX" + msgs[0] + b"\x00" * 7 + b"".join(msgs[1:4]) + b"MXTP9" + b"".join(msgs[4:])
    got = st.feed(damaged[:50]) + st.feed(damaged[50:])
    assert got == msgs and st.resyncs == 3 and st.skipped_bytes == 5 + 7 + 5
    bad = bytearray(msgs[2])
    bad[22:24] = (len(bad) - HEADER_SIZE + ITEM_SIZE).to_bytes(2, "big")   # size != items
    st = MxtpStream()
    assert st.feed(b"".join([msgs[1], bytes(bad), *msgs[3:]])) == [msgs[1], *msgs[3:]]
    assert st.resyncs == 1 and st.skipped_bytes == len(bad)


def test_simulator_over_tcp_gives_the_udp_frames_exactly():
    """mvn://...?transport=tcp listens, MvnSender(transport="tcp") connects and streams: every
    frame arrives, bit for bit what the same datagrams give through the assembler, with
    the meta message (sent on connect) parsed."""
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=2).take
    src = open_source("mvn://127.0.0.1:0?transport=tcp&queue=10000")
    sender = MvnSender(take, "127.0.0.1", src.port, transport="tcp", speed=6.0,
                       max_datagram=HEADER_SIZE + 10 * ITEM_SIZE)
    ref = MvnAssembler(list(sender.segment_ids))
    want = [f for i in range(take.n_frames)
            for f in feed_all(ref, sender.encode(i, i, i / 60.0))] + ref.flush(0, True)
    try:
        with sender:
            assert sender.wait(10)
        time.sleep(0.2)
        assert src.connections == 1 and not src.connected.is_set()   # the sender closed it
        frames = read_all(src)
        assert src.assembler.meta == {"name": "rtseg"}
    finally:
        src.close()
    assert len(frames) == len(want) == take.n_frames
    for f, w in zip(frames, want):
        assert f.seq == w.seq and f.quats.tobytes() == w.quats.tobytes()
        assert f.root_position.tobytes() == w.root_position.tobytes()
    assert src.stats.corrupt == src.stats.dropped == src.stats.reconnects == 0


def _lost_runs(log) -> tuple[set[int], int]:
    """(slots not sent, runs of them followed by a sent slot)."""
    lost = {s.slot for s in log if s.fault in ("dropped", "unplugged") or s.send_time is None}
    last = max(s.slot for s in log if s.slot not in lost)
    runs = sum(1 for k in lost if k - 1 not in lost and k < last)
    return {k for k in lost if k < last}, runs


@pytest.mark.parametrize("transport", ["udp", "tcp"])
def test_faulted_stream_keeps_the_live_loop_up_and_counts_the_lost_frames(transport):
    """Frames dropped by faults, bunched by jitter and lost in unplug windows (TCP: the
    connection is closed and made again): the live session runs to the end, every frame
    that was sent arrives, and the frames that were not are counted - as sequence gaps in
    the source's counters (gaps, dropped) and as lost frames in the session summary."""
    rate, speed = 60.0, 4.0
    take = synthesize("idle:3,walk:3", frame_rate=rate, seed=5).take
    src = open_source(f"mvn://127.0.0.1:0?transport={transport}&queue=10000"
                      + ("&rcvbuf=4194304" if transport == "udp" else ""))
    sender = MvnSender(take, "127.0.0.1", src.port, transport=transport, speed=speed,
                       faults="drop=0.05,jitter=0.02,unplug=2:0.5,seed=3")
    frames, _, summary = run_live(src, sender, take, rate, speed)
    lost, runs = _lost_runs(sender.sent_log)
    assert sum(1 for s in sender.sent_log if s.fault == "dropped") >= 5
    assert sum(1 for s in sender.sent_log if s.fault == "unplugged") >= 2 * 0.5 * rate - 1
    assert [f.seq for f in frames] == [k for k in range(take.n_frames) if k not in lost
                                       ][:len(frames)]
    assert len(frames) == summary.frames_received >= take.n_frames - len(lost) - 1
    assert src.stats.dropped == summary.source_stats["dropped"] == len(lost)
    assert src.stats.gaps == runs and summary.dropped >= len(lost)
    if transport == "tcp":
        assert src.stats.reconnects >= 2 and sender.connections >= 3


def test_corrupting_faults_are_counted_as_refused_input_and_never_stop_the_loop():
    rate, speed = 60.0, 4.0
    take = synthesize("idle:2,walk:2", frame_rate=rate, seed=6).take
    src = open_source("mvn://127.0.0.1:0?transport=tcp&queue=10000")
    sender = MvnSender(take, "127.0.0.1", src.port, transport="tcp", speed=speed,
                       faults="corrupt=0.002,seed=1")
    frames, _, summary = run_live(src, sender, take, rate, speed)
    damaged = sum(1 for s in sender.sent_log if s.fault == "corrupted")
    assert damaged > 50
    refused = summary.input
    assert refused["corrupt"] + refused["bad_values"] + refused["bad_messages"] > 0
    assert src.stats.corrupt >= 1                    # header damage: stream resynchronised
    assert take.n_frames - damaged - 5 <= len(frames) <= take.n_frames + 5


def test_rtseg_simulate_mvn_over_tcp_with_faults():
    out, port, frames = simulate_into("mvn://127.0.0.1:0?transport=tcp&queue=10000", "mvn",
                                      "60", "--transport", "tcp", "--faults", "drop=0.1,seed=2")
    assert f'rtseg live "mvn://127.0.0.1:{port}?rate=60&transport=tcp"' in out
    dropped = int(out.split(" dropped by faults")[0].rsplit("; ", 1)[1])
    assert dropped > 5 and len(frames) == 240 - dropped
    assert_refused([("mvn://127.0.0.1:0?transport=quic", "udp or tcp"),
                    ("mvn://127.0.0.1:0?transport=tcp&rcvbuf=1000", "unknown option")])
