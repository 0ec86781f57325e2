"""Noitom Axis Neuron / Axis Studio BVH broadcast: a real Axis BVH's motion (ISC fixture)
through both encodings, codec round trip, layouts, split datagrams, avatars, bad input and
fuzzing, and end to end over real sockets on 127.0.0.1 (UDP binary, TCP text)."""

from __future__ import annotations

import random
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rtseg.core import quat as Q
from rtseg.drivers import open_source
from rtseg.drivers.axis import codec as A
from rtseg.drivers.axis import text as AT
from rtseg.drivers.axis.source import AxisFrames, _BinaryAdapter
from rtseg.drivers.readers.bvh import read_bvh
from rtseg.core.profiles import resolve_joints, suit_profile
from rtseg.live.config import from_dict
from rtseg.simulators.axis_sender import AxisSender
from rtseg.simulators.synth.motion import synthesize
from vendor_helpers import (Counter, assert_refused, assert_same_cuts, free_port,
                            overwrite_bytes, random_bytes, read_all, run_live, send_and_read,
                            serial_reference, simulate_into)

FIXTURE = Path(__file__).parent / "fixtures" / "axis" / "test.bvh"


def fixture_motion() -> list[str]:
    """The MOTION lines of axis-streamer's test.bvh, as written by Axis Neuron."""
    text = FIXTURE.read_text()
    lines = text.split("Frame Time:", 1)[1].splitlines()[1:]
    return [ln for ln in lines if ln.strip()]


def same_rotation(a: np.ndarray, b: np.ndarray, atol: float = 1e-6) -> bool:
    return bool((np.abs(np.abs(np.sum(a * b, -1)) - 1) <= atol).all())


# --------------------------------------------------------------------------- the real BVH

def test_skeleton_is_the_one_axis_neuron_exports():
    take = read_bvh(FIXTURE)
    assert tuple(take.joint_names) == A.JOINTS and tuple(take.parents) == A.PARENTS
    assert len(A.JOINTS) == 59
    # 6 channels per joint, rotations Y X Z: the layout with displacement, order YXZ
    assert all(ch == ["px", "py", "pz", "Y", "X", "Z"] for ch in take.meta["channels"].values())


def test_fixture_motion_decodes_to_the_files_values_in_both_encodings():
    """Each MOTION line of the real Axis BVH streamed as Axis does: text (the line itself
    between index/name and ``||``) and binary (1480 bytes = 64 + 354 x 4, the single-packet
    size BvhStream.js notes).  Values come back exactly (float32 for binary), rotations
    equal those of the BVH reader (YXZ), the root position in metres."""
    take = read_bvh(FIXTURE)
    for k, line in enumerate(fixture_motion()):
        values = np.array(line.split(), dtype=np.float64)
        assert values.size == 354
        f = AT.decode_text(f"0 Avatar00 {line} ||".encode())
        assert (f.avatar_index, f.avatar_name, f.with_disp, f.with_ref) == (0, "Avatar00", True, False)
        assert np.array_equal(f.values, values)
        q, valid, pos = A.to_pose(f)
        assert valid.all() and same_rotation(q, take.quats[k], 1e-12)
        assert np.allclose(pos, take.root_position[k] / 100.0)
        data = A.encode_binary(values, frame_index=k)
        assert len(data) == 1480
        fb = A.decode_binary(data)
        assert np.array_equal(fb.values, values.astype(np.float32))
        assert fb.frame_index == k and fb.version == (1, 1, 0, 0)
        qb, validb, posb = A.to_pose(fb)
        assert validb.all() and same_rotation(qb, take.quats[k], 1e-6)
    # the first frame's documented values (test.bvh line 352)
    f0 = AT.decode_text(b"0 Avatar00 " + fixture_motion()[0].encode())
    assert f0.values[:6].tolist() == [-8.964398, 108.673515, 16.348038, -10.676419, -5.120858,
                                      -1.091372]


def test_header_layout_matches_the_documented_offsets():
    v = np.arange(354, dtype=np.float32)
    d = A.encode_binary(v, avatar_index=3, avatar_name="Dancer", frame_index=0x01020304)
    assert d[0:2] == b"\xff\xdd"                 # token 0xDDFF little-endian
    assert d[2:6] == b"\x00\x00\x01\x01"         # version 1.1.0.0: build, rev, minor, major
    assert d[6:8] == b"\x62\x01"                 # 354 values
    assert d[8] == 1 and d[9] == 0               # with displacement, without reference
    assert struct.unpack_from("<I", d, 10)[0] == 3
    assert d[14:46] == b"Dancer" + b"\0" * 26
    assert struct.unpack_from("<I", d, 46)[0] == 0x01020304
    assert d[62:64] == b"\xff\xee"               # token 0xEEFF
    assert np.array_equal(np.frombuffer(d, "<f4", offset=64), v)


@pytest.mark.parametrize("disp,ref,count", [(True, False, 354), (True, True, 360),
                                            (False, False, 180), (False, True, 186)])
def test_layouts(disp, ref, count):
    assert A.value_count(disp, ref) == count and A.layout(count) == (disp, ref)
    rng = np.random.default_rng(count)
    angles = rng.uniform(-170, 170, (59, 3))
    root = np.array([1.0, 95.0, -30.0])
    if disp:
        v = np.zeros((59, 6))
        v[:, 3:] = angles
        v[0, :3] = root
        v = v.ravel()
    else:
        v = np.concatenate([root, angles.ravel()])
    if ref:
        v = np.concatenate([rng.normal(size=6), v])
    f = A.decode_binary(A.encode_binary(v, with_disp=disp, with_ref=ref))
    q, valid, pos = A.to_pose(f)
    assert valid.all()
    assert same_rotation(q, Q.from_euler("YXZ", angles.astype(np.float32)), 1e-9)
    assert np.allclose(pos, root / 100.0)
    ft = AT.decode_text(AT.encode_text(v))
    assert (ft.with_disp, ft.with_ref) == (disp, ref)
    assert np.array_equal(ft.values.astype(np.float32), v.astype(np.float32))


def test_global_space_is_forward_kinematics():
    q = A.euler_to_quat("YXZ", np.random.default_rng(1).uniform(-120, 120, (59, 3)))
    assert np.allclose(A.global_pose(q), Q.global_from_local(q, list(A.PARENTS)), atol=1e-15)
    v = np.zeros((59, 6))
    v[:, 3:] = np.random.default_rng(2).uniform(-90, 90, (59, 3))
    f = A.decode_binary(A.encode_binary(v.ravel()))
    loc = AxisFrames(Counter()).frame(f, 0.0)
    glo = AxisFrames(Counter(), space="global").frame(f, 0.0)
    assert np.allclose(glo.quats, Q.global_from_local(loc.quats, list(A.PARENTS)))
    src = open_source("axis://:0?space=global")
    try:
        assert src.space == "global"
    finally:
        src.close()


def test_euler_orders_match_the_bvh_convention():
    x = np.random.default_rng(0).uniform(-180, 180, (500, 3))
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        assert same_rotation(A.euler_to_quat(order, x), Q.from_euler(order, x), 1e-12)
        back = A.euler_to_quat(order, A.quat_to_euler(order, A.euler_to_quat(order, x)))
        assert same_rotation(back, A.euler_to_quat(order, x), 1e-12)


# --------------------------------------------------------------------------- simulator

def test_simulator_round_trip_is_exact_to_float32_and_keeps_the_suit_pose():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=4).take
    for fmt in ("binary", "text"):
        s = AxisSender(take, fmt)
        for k in (0, 77, 200):
            part = s.encode(k, k, k / 60)[0]
            f = A.decode_binary(part) if fmt == "binary" else AT.decode_text(part)
            assert np.array_equal(f.values.astype(np.float32), s.values[k])
            q, valid, pos = A.to_pose(f)
            assert valid.all()
            g = Q.global_from_local(q, list(A.PARENTS))
            # every suit segment arrives as the global orientation the retargeting gave it
            for b, joint in A.SUIT_SEGMENTS.items():
                kk = s.suit.bones.index(b)
                assert same_rotation(g[A.JOINTS.index(joint)], s.quats[k, kk], 1e-5), (b, joint)
            assert np.allclose(pos, s.root[k], atol=1e-5)


def test_split_datagrams_are_joined_and_a_lost_part_is_counted():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=5).take
    s = AxisSender(take, "binary", split=1024)
    count = Counter()
    adapter = _BinaryAdapter(AxisFrames(count))
    parts = s.encode(3, 3, 0.05)
    assert [len(p) for p in parts] == [1024, 456]
    assert adapter.feed(parts[0], 0.0) == []
    (frame,) = adapter.feed(parts[1], 0.001)
    assert frame.seq == 3 and frame.valid.all()
    # a first part whose continuation never comes: counted when the next header arrives
    whole = AxisSender(take, "binary").encode(4, 4, 0.07)[0]
    assert adapter.feed(parts[0], 0.01) == []
    (frame,) = adapter.feed(whole, 0.02)
    assert frame.seq == 4 and count.counts == {"corrupt": 1}
    # a continuation without its header
    assert adapter.feed(parts[1], 0.03) == []
    assert count.counts == {"corrupt": 2}
    # ... or when the continuation is late past the timeout (0.1 s)
    assert adapter.feed(parts[0], 0.04) == []
    assert adapter.flush(0.1) == [] and count.counts == {"corrupt": 2}
    adapter.flush(0.2)
    assert count.counts == {"corrupt": 3}


def test_avatars_are_told_apart():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=6).take
    s = AxisSender(take, "binary", avatars=[(0, "Avatar00", 0), (1, "Avatar01", 40)])
    parts = s.encode(5, 5, 0.0)
    for sel, want in ((None, 5), ("1", 45), ("Avatar01", 45), ("Avatar00", 5)):
        frames = AxisFrames(Counter(), avatar=sel)
        out = [frames.frame(A.decode_binary(p), 0.0) for p in parts]
        got = [f for f in out if f is not None]
        assert len(got) == 1 and frames.other_avatars == 1
        q, _, _ = A.to_pose(A.decode_binary(A.encode_binary(s.values[want])))
        assert np.array_equal(got[0].quats, q)


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("mutate,kind", [
    (lambda d: d[:40], "corrupt"),
    (lambda d: b"\x00\x00" + d[2:], "corrupt"),
    (lambda d: d[:62] + b"\x00\x00" + d[64:], "corrupt"),
    (lambda d: d[:-4], "corrupt"),
    (lambda d: d[:8] + b"\x00" + d[9:], "bad_messages"),      # 354 values without displacement
    (lambda d: d[:8] + b"\x07" + d[9:], "bad_messages"),
])
def test_bad_binary_frames_raise_a_counted_kind(mutate, kind):
    d = A.encode_binary(np.zeros(354))
    with pytest.raises(A.AxisError) as exc:
        A.decode_binary(mutate(d))
    assert exc.value.kind == kind


@pytest.mark.parametrize("text,kind", [
    (b"", "corrupt"), (b"0 Avatar00", "corrupt"), (b"x Avatar00 1 2 3", "corrupt"),
    (b"0 Avatar00 " + b"1 " * 100, "bad_messages"), (b"\xff\xfe 0 a 1", "corrupt"),
    (b"0 Avatar00 " + b"1 " * 179 + b"abc", "corrupt"),
])
def test_bad_text_frames_raise_a_counted_kind(text, kind):
    with pytest.raises(A.AxisError) as exc:
        AT.decode_text(text)
    assert exc.value.kind == kind


def test_non_finite_angles_make_joints_invalid():
    v = np.zeros((59, 6))
    v[12, 4] = np.nan                          # Head
    v[0, 1] = np.inf                           # root position
    count = Counter()
    frames = AxisFrames(count)
    f = frames.frame(A.decode_binary(A.encode_binary(v.ravel())), 0.0)
    assert [A.JOINTS[j] for j in np.flatnonzero(~f.valid)] == ["Head"]
    assert f.root_position is None and count.counts == {"bad_values": 1}
    # in world space a joint's orientation chains its ancestors': a bad RightArm makes the
    # whole right arm (and hand) invalid, counted once
    v[12, 4] = 0.0
    v[14, 3] = np.nan                          # RightArm
    count = Counter()
    g = AxisFrames(count, space="global").frame(A.decode_binary(A.encode_binary(v.ravel())), 0)
    bad = [A.JOINTS[j] for j in np.flatnonzero(~g.valid)]
    assert bad[:3] == ["RightArm", "RightForeArm", "RightHand"] and len(bad) == 22
    assert count.counts == {"bad_values": 1}


def test_text_splitter_bounds_its_buffer():
    sp = AT.TextSplitter(max_frame=100)
    assert sp.feed(b"0 a 1 2 ||0 b 3") == [b"0 a 1 2 "]
    assert sp.feed(b" 4 ||") == [b"0 b 3 4 "]
    sp.feed(b"x" * 500)
    assert sp.overflows == 1 and sp.feed(b"||") == []


def test_fuzzed_inputs_never_escape():
    """10^4 fuzzed binary datagrams and 10^4 fuzzed text chunks: only AxisError from the
    codec, and what the sources run (datagram joiner + decoder, splitter + decoder) never
    raises."""
    rng = random.Random(2)
    take = synthesize("idle:2", frame_rate=60.0, seed=7).take
    sb, st = AxisSender(take, "binary"), AxisSender(take, "text", displacement=False)
    bins = [sb.encode(k, k, 0)[0] for k in range(5)]
    texts = [st.encode(k, k, 0)[0] for k in range(5)]
    count = Counter()
    adapter = _BinaryAdapter(AxisFrames(count))
    ok = bad = 0

    def mutate(src: bytes) -> bytes:
        r = rng.random()
        if r < 0.45:
            return overwrite_bytes(rng, src, 6)
        if r < 0.65:
            return src[:rng.randrange(len(src))]
        if r < 0.75:
            return src[rng.randrange(len(src)):]
        if r < 0.85:
            return src + src[:rng.randrange(len(src))]
        return random_bytes(rng, 80)

    for k in range(10_000):
        d = mutate(rng.choice(bins))
        try:
            A.decode_binary(d)
            ok += 1
        except A.AxisError:
            bad += 1
        adapter.feed(d, k * 1e-3)
        adapter.flush(k * 1e-3)
    frames = AxisFrames(count)
    splitter = AT.TextSplitter()
    for _ in range(10_000):
        d = mutate(rng.choice(texts))
        for chunk in [d, *splitter.feed(d)]:
            try:
                frames.frame(AT.decode_text(chunk), 0.0)
                ok += 1
            except A.AxisError:
                bad += 1
    assert ok > 1000 and bad > 1000


# --------------------------------------------------------------------------- fast paths

def test_text_numbers_parse_to_exactly_what_float_gives():
    """codec_axis_text's integer fast path (digits / 10^d) against float(), bit for bit
    (including -0.0), on numpy's shortest float32 forms, printf forms, and random strings
    of digits, points and minus signs (which must be refused exactly when float() refuses
    them)."""
    from rtseg.drivers.axis.text import parse_decimals
    rng = random.Random(7)
    nrng = np.random.default_rng(7)
    for _ in range(300):
        v = (nrng.standard_normal(40) * 10.0 ** nrng.integers(-8, 8, 40)).astype(np.float32)
        toks = [str(x) for x in v] + [f"{x:.{rng.randint(0, 9)}f}" for x in v[:20]]
        toks += ["-0.0", "-0.000", "0.0", "-.5", "1.", "007.50", "-1e-05", "nan"]
        rng.shuffle(toks)
        got = parse_decimals(" ".join(toks).encode())
        ref = np.array([float(t) for t in toks])
        assert got.view(np.int64).tolist() == ref.view(np.int64).tolist()
    refused = 0
    for _ in range(5000):
        toks = ["".join(rng.choice("0123456789.-") for _ in range(rng.randint(1, 20)))
                for _ in range(rng.randint(1, 5))]
        try:
            ref = np.array([float(t) for t in toks])
        except ValueError:
            ref = None
        try:
            got = parse_decimals(" ".join(toks).encode())
        except A.AxisError as e:
            assert ref is None and e.kind == "corrupt", toks
            refused += 1
            continue
        assert ref is not None and got.view(np.int64).tolist() == ref.view(np.int64).tolist()
    assert refused > 1000


def _random_number_token(rng: random.Random) -> str:
    """A token float() reads, in the forms a BVH writer or a fuzzer could produce: numpy's
    shortest float32 and float64 forms, printf forms, long mantissas, exponents (subnormal,
    overflowing), integers (beyond 2^53 and 2^64), signed zeros."""
    k = rng.random()
    if k < 0.2:
        x = struct.unpack("<d", struct.pack("<Q", rng.getrandbits(64)))[0]
        return repr(x) if np.isfinite(x) else "1.5"
    if k < 0.4:
        return str(np.float32(rng.uniform(-1000, 1000)))
    if k < 0.55:
        return f"{rng.uniform(-200, 200):.{rng.randint(0, 9)}f}"
    if k < 0.97:
        digits = "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 28)))
        tok = (digits.lstrip("0") or "0") if rng.random() < 0.97 else digits
        if rng.random() < 0.7:
            tok += "." + "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 25)))
        if rng.random() < 0.3:
            tok += rng.choice("eE") + rng.choice(["", "+", "-"]) + str(rng.randint(0, 340))
        return rng.choice(["", "-"]) + tok
    return rng.choice(["-0", "0", "-0.0", "0.0", "-0e5", "-0.000", "1e-400", "-1e-400",
                       "1e400", "18446744073709551615", "18446744073709551616",
                       "-9223372036854775809", "9007199254740993", "4.9e-324", "1.", ".5",
                       "-.5", "+1", "007.5", "nan", "inf", "-Infinity", "1_0"])


def test_json_number_path_is_bit_exact_to_float():
    """The orjson path (_json_rows, what decode_texts uses) against float(), bit for bit,
    -0.0 included, on every token form of _random_number_token; rows where some token is
    not a JSON number (or could be the integer -0) are refused as a whole (None) and then
    read exactly by parse_decimals' other paths."""
    from rtseg.drivers.axis import text as T
    if T._json_loads is None:
        pytest.skip("orjson is not installed (a dependency of rtseg)")
    rng = random.Random(11)
    parsed = refused = 0
    for _ in range(3000):
        rows_tok = [[_random_number_token(rng) for _ in range(rng.randint(1, 30))]
                    for _ in range(rng.randint(1, 3))]
        bodies = [" ".join(r).encode() for r in rows_tok]
        ref = [np.array([float(t) for t in r]) for r in rows_tok]
        rows = [b.translate(T._TO_JSON, T._NOT_JSON) for b in bodies]
        json = [k for k, (r, b) in enumerate(zip(rows, bodies)) if len(r) == len(b)]
        got = T._json_rows([rows[k] for k in json]) if json else None
        if got is None:                           # (letters, '_': decode_texts' exact path)
            refused += 1
        else:
            parsed += 1
            assert [g.view(np.int64).tolist() for g in got] == \
                [ref[k].view(np.int64).tolist() for k in json], rows_tok
        for b, r in zip(bodies, ref):              # whichever path parse_decimals takes
            assert T.parse_decimals(b).view(np.int64).tolist() == r.view(np.int64).tolist()
    assert parsed > 1000 and refused > 300
    assert T._json_rows([b"-0"]) is None and T._json_rows([b"1,-0"]) is None
    zeros = T._json_rows([b"-0.0,-0e1"])[0]
    assert (zeros == 0).all() and np.signbit(zeros).all()
    assert T._json_rows([b"1,,2"]) is None and T._json_rows([b"1e999"]) is None


def test_text_frames_with_non_json_tokens_keep_float_values_and_counters():
    """A frame whose numbers orjson refuses (printf's '1.', exponents beyond range, 'nan')
    decodes through the exact path: float()'s values, non-finite ones counted as bad
    values, and the other frames of the read unaffected."""
    from rtseg.drivers.axis.text import decode_texts
    rng = np.random.default_rng(5)
    good = [AT.encode_text(rng.uniform(-90, 90, 354))[:-3] for _ in range(2)]
    toks = good[0].split()
    odd = b" ".join(toks[:5] + [b"7."] + toks[6:])                 # not JSON, float() reads it
    huge = b" ".join(toks[:5] + [b"1e999"] + toks[6:])             # inf: a bad value
    got = decode_texts([good[0], odd, huge, good[1]])
    for chunk, f in zip([good[0], odd, huge, good[1]], got):
        ref = np.array([float(t) for t in chunk.split()[2:]])
        assert f.values.view(np.int64).tolist() == ref.view(np.int64).tolist()
    assert got[0].finite and got[3].finite and got[1].finite is got[2].finite is None
    count = Counter()
    frames = AxisFrames(count, space="global").many(got, 0.0)
    assert len(frames) == 4 and count.counts == {"bad_values": 1}
    assert frames[2].valid.sum() < 59 and frames[3].valid.all()


def test_text_splitter_cuts_any_read_boundaries_like_one_split():
    """Random streams of frames, '|', '||', '|||' and spaces, cut into random reads: the
    splitter gives exactly the non-blank pieces of ``stream.split(b"||")`` (the last one
    when the stream ends with '||'), whatever the read sizes."""
    rng = random.Random(3)
    for _ in range(2000):
        stream = b"".join(rng.choice([b"0 a 1.5 ", b"|", b"||", b"|||", b" ", b"2 b 3"])
                          for _ in range(rng.randint(0, 30))) + b"||"
        sp = AT.TextSplitter()
        got, at = [], 0
        while at < len(stream):
            n = rng.randint(1, 12)
            got += sp.feed(stream[at:at + n])
            at += n
        assert got == [f for f in stream.split(b"||")[:-1] if f.strip()], stream
    sp = AT.TextSplitter(max_frame=10)
    assert sp.feed(b"0 a 1.5 |") == [] and sp.feed(b"| 0 b") == [b"0 a 1.5 "]
    assert sp.feed(b"x" * 11) == [] and sp.overflows == 1 and sp.feed(b"||") == []


def _closed_form_quat(order: str, angles: np.ndarray) -> np.ndarray:
    """The closed form of euler_to_quat term by term (the code before its matrix form)."""
    a, b, c = ("XYZ".index(x) for x in order)
    half = angles * (np.pi / 360.0)
    s, co = np.sin(half), np.cos(half)
    sa, sb, sc, ca, cb, cc = s[..., 0], s[..., 1], s[..., 2], co[..., 0], co[..., 1], co[..., 2]
    cacb, sasb, sacb, casb = ca * cb, sa * sb, sa * cb, ca * sb
    e = 1.0 if (a, b, c) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    out = np.empty(half.shape[:-1] + (4,))
    out[..., 3] = cacb * cc - e * sasb * sc
    out[..., a] = sacb * cc + e * casb * sc
    out[..., b] = casb * cc - e * sacb * sc
    out[..., c] = cacb * sc + e * sasb * cc
    return out


_L_INDEX = np.array([[3, 2, 1, 0], [2, 3, 0, 1], [1, 0, 3, 2], [0, 1, 2, 3]])
_L_SIGN = np.array([[1.0, -1.0, 1.0, 1.0], [1.0, 1.0, -1.0, 1.0], [-1.0, 1.0, 1.0, 1.0],
                    [-1.0, -1.0, -1.0, 1.0]])


def _matrix_jump_global(local: np.ndarray) -> np.ndarray:
    """global_pose as it was before the quaternion form: pointer jumping on the local
    rotations' 4x4 left-product matrices (one batched 4x4 matrix product per round)."""
    J = local.shape[-2]
    m = np.empty(local.shape[:-2] + (J + 1, 4, 4))
    m[..., :J, :, :] = local[..., _L_INDEX] * _L_SIGN
    m[..., J, :, :] = np.eye(4)
    anc = np.array([J if p < 0 else p for p in A.PARENTS] + [J])
    for _ in range(4):                                   # 2^4 > 13 links
        m = m.take(anc, axis=-3) @ m
        anc = anc[anc]
    return m[..., :-1, :, 3]


@pytest.fixture(params=["kernel", "numpy"])
def pose_backend(request, monkeypatch):
    """Each pose path of codec_axis: the compiled kernel and the numpy one."""
    from rtseg.drivers.axis import kernel as axis_kernel
    if request.param == "kernel" and not axis_kernel.AVAILABLE:
        pytest.skip("the C kernel is not built (no compiler at install): numpy path only")
    monkeypatch.setattr(axis_kernel, "ENABLED", request.param == "kernel")
    return request.param


def test_global_pose_matches_the_matrix_form_to_float32(pose_backend):
    """The quaternion pointer jumping (global_pose, poses(space='global')) against the 4x4
    matrix form it replaced: within 1e-12 in float64 and the same float32 values (what
    the decoder + simulator round trips are exact to), for random angles of every order
    and the real Axis BVH; a frame alone gives the same bits as within a batch."""
    rng = np.random.default_rng(21)
    take = np.array([[float(t) for t in ln.split()] for ln in fixture_motion()])
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        x = rng.uniform(-180, 180, (300, 59, 3)) * 10.0 ** rng.integers(-5, 2, (300, 59, 1))
        q = A.euler_to_quat(order, x)
        want, got = _matrix_jump_global(q), A.global_pose(q)
        assert np.abs(got - want).max() < 1e-12
        assert np.array_equal(got.astype(np.float32), want.astype(np.float32))
        for i in (0, 17, 299):
            assert A.global_pose(q[i]).tobytes() == got[i].tobytes()
        g, _, _ = A.poses(take, *A.layout(take.shape[1]), order, 0.01, "global")
        want = _matrix_jump_global(A.to_poses(take, *A.layout(take.shape[1]), order)[0])
        assert np.abs(g - want).max() < 1e-12
        assert np.array_equal(g.astype(np.float32), want.astype(np.float32))


def test_euler_and_global_pose_are_bit_identical_to_the_term_by_term_forms(pose_backend):
    """euler_to_quat (8 half-angle products times a +-1 table) equals the closed form term
    by term, bit for bit; poses(space='global') (FK matrices built from the Euler terms)
    equals global_pose(euler_to_quat(...)) bit for bit, for one frame and a batch, and its
    local quaternions are euler_to_quat's."""
    rng = np.random.default_rng(9)
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        x = rng.uniform(-180, 180, (4, 59, 3)) * 10.0 ** rng.integers(-5, 2, (4, 59, 1))
        q = A.euler_to_quat(order, x)
        assert q.view(np.int64).tolist() == _closed_form_quat(order, x).view(np.int64).tolist()
        v = np.zeros((4, 59, 6))
        v[..., :3] = rng.uniform(-50, 50, (4, 59, 3))
        v[..., 3:] = x
        v = v.reshape(4, 354)
        g, loc, root = A.poses(v, True, False, order, 0.01, "global")
        assert np.array_equal(loc, q) and np.array_equal(root, v[:, :3] * 0.01)
        assert g.view(np.int64).tolist() == A.global_pose(q).view(np.int64).tolist()
        g1, loc1, _ = A.poses(v[1], True, False, order, 0.01, "global")
        assert np.array_equal(g1, g[1]) and np.array_equal(loc1, q[1])
        with_ref = np.concatenate([rng.uniform(-9, 9, (4, 6)), v], axis=1)   # 360 values
        no_disp = np.concatenate([v[:, :3], x.reshape(4, 177)], axis=1)       # 180 values
        for vals, disp, ref in ((with_ref, True, True), (no_disp, False, False)):
            g2, l2, r2 = A.poses(vals, disp, ref, order, 0.01, "global")
            assert np.array_equal(l2, q) and np.array_equal(g2, g) and np.array_equal(r2, root)
            g3, l3, r3 = A.poses(vals[2], disp, ref, order, 0.01, "global")     # one frame
            assert np.array_equal(l3, q[2]) and np.array_equal(g3, g[2])
            assert np.array_equal(r3, root[2])


def test_frames_of_one_read_decode_and_convert_as_one_by_one(pose_backend):
    """decode_texts (one number pass for the frames of a TCP read) and AxisFrames.many
    (one Euler / forward-kinematics pass) give each frame's values, errors and Frame as
    decode_text + AxisFrames.frame do, in order, other avatars skipped."""
    from rtseg.drivers.axis.text import decode_texts
    rng = np.random.default_rng(3)
    chunks = [f"0 Avatar00 {ln}".encode() for ln in fixture_motion()]      # 2 real frames
    chunks += [AT.encode_text(rng.uniform(-180, 180, 354))[:-3] for _ in range(4)]
    chunks.insert(2, b"0 Avatar00 1.0 2.0")                       # no layout: bad_messages
    chunks.insert(4, chunks[1].replace(b" 0", b" x", 1))           # not a number: corrupt
    chunks.insert(5, chunks[0].replace(b"Avatar00", b"Avatar01").replace(b"0 ", b"1 ", 1))
    chunks.append(b"0 Avatar00 " + b" ".join(f"{x:.2e}".encode() for x in range(354)))
    one = []
    for c in chunks:
        try:
            one.append(AT.decode_text(c))
        except A.AxisError as e:
            one.append(e)
    many = decode_texts(chunks)
    assert [type(x) for x in many] == [type(x) for x in one]
    for a, b in zip(many, one):
        if isinstance(a, A.AxisError):
            assert (a.kind, str(a)) == (b.kind, str(b))
        else:
            assert a.values.tobytes() == b.values.tobytes() and a.avatar_name == b.avatar_name
    for space in ("local", "global"):
        c1, c2 = Counter(), Counter()
        f1, f2 = AxisFrames(c1, space=space), AxisFrames(c2, space=space)
        ref = [f1.frame(x, 0.5) if not isinstance(x, A.AxisError) else f1.error(x, 0.5)
               for x in one]
        ref = [f for f in ref if f is not None]
        got = f2.many(many, 0.5)
        assert len(got) == len(ref) == 7 and f2.other_avatars == f1.other_avatars == 1
        assert c2.counts == c1.counts == {"bad_messages": 1, "corrupt": 1}
        for g, r in zip(got, ref):
            assert np.allclose(g.quats, r.quats, atol=1e-15, rtol=0) and g.seq == r.seq
            assert np.array_equal(g.root_position, r.root_position) and g.valid.all()


# --------------------------------------------------------------------------- sockets

def test_url_defaults_options_and_errors():
    src = open_source("axis://:0?rate=90&avatar=Avatar01&order=zxy")
    try:
        assert src.host == "127.0.0.1" and src.port > 0 and src.space == "global"
        assert src.joint_names == list(A.JOINTS) and src.frame_rate == 90.0
    finally:
        src.close()
    src = open_source("axis://:0?space=local")
    try:
        assert src.space == "local"
    finally:
        src.close()
    assert_refused([("axis://:0?format=csv", "not supported"),
                    ("axis://:0?order=XXY", "permutation"),
                    ("axis://:0?unit=ft", "unit="),
                    ("axis://:0?space=world", "local or global"),
                    ("axis://:0?backoff=1", "unknown option"),
                    ("axis://127.0.0.1:0?format=text", "give its port"),
                    ("axis://:0?allow=x", "axis:// allow=")])


def test_binary_datagrams_fed_together_give_the_frames_fed_one_by_one():
    """_BinaryAdapter.feed_many (what the source runs on the datagrams pending in its
    socket) against feed one datagram at a time: the same Frames bit for bit (quats,
    valid, seq, source_time, root) and the same counters, through split frames, a lost
    continuation, another avatar, a bad layout, a frame index jump and non-finite angles."""
    rng = np.random.default_rng(4)
    v = np.zeros((8, 59, 6))
    v[..., 3:] = rng.uniform(-170, 170, (8, 59, 3))
    v[..., 0, :3] = rng.uniform(-50, 150, (8, 3))
    v = v.reshape(8, 354)
    v[5, 40] = np.nan
    d = [A.encode_binary(v[k], frame_index=k if k < 6 else k + 3) for k in range(8)]
    datagrams = [d[0], d[1][:1024], d[1][1024:], d[2][:1024], d[3],
                 A.encode_binary(v[4], avatar_index=1, avatar_name="Other", frame_index=4),
                 A.encode_binary(v[4][:300], frame_index=4), d[4], d[5], d[6], d[7]]
    for space in ("local", "global"):
        c1, c2 = Counter(), Counter()
        one, many = _BinaryAdapter(AxisFrames(c1, space=space)), _BinaryAdapter(
            AxisFrames(c2, space=space))
        ref = [f for k, g in enumerate(datagrams) for f in one.feed(g, 0.5)]
        got = many.feed_many(datagrams, 0.5)
        assert len(got) == len(ref) == 7 and c1.counts == c2.counts
        assert c1.counts == {"corrupt": 1, "bad_messages": 1, "bad_values": 1, "gaps": 2,
                             "dropped": 4}                  # index 2, then 6, 7, 8
        for g, r in zip(got, ref):
            assert g.quats.tobytes() == r.quats.tobytes() and np.array_equal(g.valid, r.valid)
            assert (g.seq, g.source_time) == (r.seq, r.source_time)
            assert np.array_equal(g.root_position, r.root_position)


def test_a_repeated_or_late_binary_frame_is_dropped_and_counted():
    """UDP repeats and reorders datagrams: a frame whose index repeats the last one or lies
    a few behind it is dropped and counted in bad_messages - delivered, its seq would go
    back, which the live loop takes for a restarted stream - one by one and in a batch."""
    rng = np.random.default_rng(5)
    v = rng.uniform(-90, 90, (8, 354))
    d = [A.encode_binary(v[k], frame_index=k) for k in range(8)]
    datagrams = d[:6] + [d[5], d[3]] + d[6:]          # 5 repeated, 3 late
    for feed in ("one", "many"):
        c = Counter()
        adapter = _BinaryAdapter(AxisFrames(c))
        got = ([f for g in datagrams for f in adapter.feed(g, 0.5)] if feed == "one"
               else adapter.feed_many(datagrams, 0.5))
        assert [f.seq for f in got] == list(range(8)), feed
        assert c.counts == {"bad_messages": 2}, feed


def test_binary_source_takes_pending_datagrams_as_one_batch():
    """Datagrams sent faster than the reader decodes them wait in the socket buffer; the
    source takes them together (batches of more than one datagram), and every frame still
    arrives in order with the values of frame-by-frame decoding.  The first datagram's
    decoding is held 0.2 s (a reader that fell behind), so that the rest are waiting
    however fast the machine is."""
    rng = np.random.default_rng(6)
    n = 60
    v = np.zeros((n, 59, 6))
    v[..., 3:] = rng.uniform(-170, 170, (n, 59, 3))
    v = v.reshape(n, 354)
    src = open_source("axis://127.0.0.1:0?queue=1024")
    sizes: list[int] = []
    feed, feed_many = src._asm.feed, src._asm.feed_many

    def one(data, now):
        sizes.append(1)
        if len(sizes) == 1:
            time.sleep(0.2)          # the sender's 59 other datagrams arrive meanwhile
        return feed(data, now)

    def many(batch, now):
        sizes.append(len(batch))
        return feed_many(batch, now)

    src._asm.feed, src._asm.feed_many = one, many
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            for k in range(n):
                s.sendto(A.encode_binary(v[k], frame_index=k), ("127.0.0.1", src.port))
        frames = read_all(src)
    finally:
        src.close()
    assert [f.seq for f in frames] == list(range(n)) and sum(sizes) == n
    assert max(sizes) > 1 and src.stats.dropped == src.stats.corrupt == 0
    ref = _BinaryAdapter(AxisFrames(Counter(), space="global"))
    for k, f in enumerate(frames):
        want = ref.feed(A.encode_binary(v[k], frame_index=k), 0.0)[0]
        assert f.quats.tobytes() == want.quats.tobytes()


def test_binary_over_udp_split_datagrams_and_avatar_choice():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=8).take
    src = open_source("axis://127.0.0.1:0?avatar=Avatar01&queue=4096&rate=60&space=local")
    sender = AxisSender(take, "binary", "127.0.0.1", src.port, speed=8.0, split=1024,
                        avatars=[(0, "Avatar00", 0), (1, "Avatar01", 30)])
    frames = send_and_read(src, sender)
    n = take.n_frames
    assert len(frames) == n and src.other_avatars == n
    assert [f.seq for f in frames] == list(range(n))
    assert np.allclose([f.source_time for f in frames], np.arange(n) / 60.0)
    assert all(f.valid.all() for f in frames)
    want = [A.to_pose(A.decode_binary(A.encode_binary(sender.values[(k + 30) % n])))[0]
            for k in range(n)]
    assert np.array_equal(np.array([f.quats for f in frames]), np.array(want))
    assert src.stats.corrupt == src.stats.dropped == 0


def test_allow_list_refuses_other_senders_before_decoding():
    src = open_source("axis://127.0.0.1:0?allow=10.1.2.3")
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        out.sendto(A.encode_binary(np.zeros(354)), ("127.0.0.1", src.port))
        assert src.read(timeout=0.4) is None
        assert src.stats.refused_senders == 1 and src.stats.corrupt == 0
    finally:
        out.close()
        src.close()


def test_text_over_tcp_connects_late_and_reconnects_after_the_server_drops():
    """rtseg is the client: started before Axis's server is up it retries with backoff;
    when the server drops the connection it reconnects (counted) and frames resume."""
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=9).take
    port = free_port(socket.SOCK_STREAM)
    src = open_source(f"axis://127.0.0.1:{port}?format=text&rate=60&backoff=0.05&queue=4096")
    sender = AxisSender(take, "text", "127.0.0.1", port, speed=4.0, loop=True)
    try:
        time.sleep(0.3)                         # nothing listening yet: refused, retried
        assert not src.connected.is_set()
        sender.start()
        assert src.connected.wait(5)
        first = [src.read(timeout=2) for _ in range(20)]
        assert all(f is not None and f.valid.all() for f in first)
        assert sender.disconnect() == 1
        deadline = time.monotonic() + 5
        while src.stats.reconnects < 1 and time.monotonic() < deadline:
            src.read(timeout=0.05)
        assert src.stats.reconnects == 1
        after = [src.read(timeout=2) for _ in range(20)]
        assert all(f is not None and f.valid.all() for f in after)
        assert src.stats.corrupt <= 1          # at most the frame cut by the drop
    finally:
        sender.stop()
        src.close()


def test_text_frame_cut_by_a_closed_connection_counts_as_dropped():
    """Axis Neuron's server writes 10 text frames and half of the 11th, then closes; after
    rtseg reconnects it writes 10 more.  The half frame is a frame lost: 1 in ``dropped``
    (text frames carry no number that would show it), none counted corrupt."""
    from rtseg.drivers.axis.text import encode_text
    frames = [encode_text(np.zeros(354, np.float32) + k) for k in range(21)]
    with socket.socket() as srv:
        srv.bind(("127.0.0.1", 0))
        srv.listen(2)
        srv.settimeout(5)
        src = open_source(f"axis://127.0.0.1:{srv.getsockname()[1]}?format=text&backoff=0.01")
        try:
            c, _ = srv.accept()
            c.sendall(b"".join(frames[:10]) + frames[10][:1000])
            time.sleep(0.2)
            c.close()
            c, _ = srv.accept()
            with c:
                c.sendall(b"".join(frames[11:]))
                got = [f for f in iter(lambda: src.read(timeout=0.5), None)]
            assert len(got) == 20
            st = src.stats
            assert (st.dropped, st.corrupt, st.reconnects) == (1, 0, 1)
        finally:
            src.close()


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_simulator_through_live_session_gives_valid_joints_and_cuts(fmt):
    """A synthetic take with 3 behaviour changes, sent x4 (UDP binary, or TCP text from the
    simulator's server) into a LiveSession: every mapped joint valid in every frame, the
    take's clock (binary), and at least one cut."""
    rate, speed = 120.0, 4.0
    take = synthesize("idle:3,walk:4,punch:4,squat:4", frame_rate=rate, seed=3).take
    sender = None
    if fmt == "text":
        sender = AxisSender(take, "text", "127.0.0.1", 0, speed=speed, wait_client=10)
        sender.start()
        src = open_source(f"axis://127.0.0.1:{sender.port}?format=text&rate={rate:g}&queue=4096")
    else:
        # a 4 MB socket buffer (up to the system's rmem_max): seconds of these datagrams, so
        # a reader starved by a loaded machine loses none (the default holds ~0.3 s)
        src = open_source(f"axis://127.0.0.1:0?rate={rate:g}&queue=4096&rcvbuf=4194304")
        sender = AxisSender(take, "binary", "127.0.0.1", src.port, speed=speed)
    # text: the axis skeleton profile (whole spine); binary: the default (unity, aliases)
    cfg = from_dict({"features": {"profile": "axis"}} if fmt == "text" else {})
    frames, cuts, summary = run_live(src, sender, take, rate, speed, cfg,
                                     start=fmt == "binary", slack=15)
    assert len(frames) == take.n_frames == summary.frames_received
    mapped = resolve_joints("axis" if fmt == "text" else "unity", src.joint_names)
    assert all(f.valid[mapped].all() for f in frames)
    if fmt == "binary":
        assert np.allclose([f.source_time for f in frames], np.arange(take.n_frames) / rate)
    assert [f.seq for f in frames] == list(range(take.n_frames))
    assert src.stats.corrupt == src.stats.dropped == 0
    assert len(cuts) >= 1, "no cut on a take with 3 behaviour changes"


def test_rtseg_simulate_axis_command_reaches_the_source():
    out, port, frames = simulate_into("axis://127.0.0.1:0?queue=10000", "axis", "60")
    assert f'rtseg live "axis://127.0.0.1:{port}?format=binary&rate=60"' in out
    assert "rigid with their parent: RightShoulder, LeftShoulder" in out
    assert len(frames) == 240 and all(f.valid.all() for f in frames)


def test_suit_profile_places_every_segment_on_an_axis_joint():
    suit = suit_profile("axis")
    assert set(suit.bones) == set(A.SUIT_SEGMENTS)
    for k, b in enumerate(suit.bones):
        p = suit.parents[k]
        if p >= 0:   # the suit's hierarchy is the Axis one, restricted to its segments
            j, pj = A.JOINTS.index(A.SUIT_SEGMENTS[b]), A.JOINTS.index(A.SUIT_SEGMENTS[suit.bones[p]])
            while j >= 0 and j != pj:
                j = A.PARENTS[j]
            assert j == pj, b
    assert len(resolve_joints("unity", list(A.JOINTS))) == 12
    assert [A.JOINTS[j] for j in resolve_joints("axis", list(A.JOINTS))][:4] == [
        "Spine", "Spine1", "Spine2", "Spine3"]


def test_the_real_axis_bvh_replays_through_the_simulators():
    """The fixture as a take: the ``axis`` skeleton map is detected (Chest = Spine3) and the
    Axis simulator re-sends every suit segment with the global orientation the BVH gives it."""
    take = read_bvh(FIXTURE)
    s = AxisSender(take, "binary")
    assert s.retargeted.family == "axis"
    g_take = Q.global_from_local(take.quats, list(take.parents))
    for k in range(take.n_frames):
        q, valid, pos = A.to_pose(A.decode_binary(s.encode(k, k, 0.0)[0]))
        g = Q.global_from_local(q, list(A.PARENTS))
        for b, joint in A.SUIT_SEGMENTS.items():
            j = A.JOINTS.index(joint)
            assert same_rotation(g[j], g_take[k, j], 1e-5), joint
        assert np.allclose(pos, take.root_position[k] / 100.0, atol=1e-6)


def test_real_take_cuts_match_the_serial_suit(data_dir):
    """86_01 (CMU, 38 s) through the Axis binary codec, as the axis:// source delivers it
    (59 joints; the default space=global, or space=local without the calibration step),
    gives the cuts the 17-sensor serial suit gives through its codec, within 0.25 s
    (offline pipeline, the live loop's own).  (With space=local and the default
    calibration.mode = auto, the first of 86_01's six cuts moves from frame 530 to 450:
    why global is the default.)"""
    from rtseg.live.replay import replay_frames

    take, serial, ref = serial_reference(data_dir)
    rate = take.frame_rate
    sender = AxisSender(take, "binary")                # encode only: never started
    runs = {}
    for space in ("local", "global"):
        adapter = _BinaryAdapter(AxisFrames(Counter(), rate=rate, space=space))
        frames = [(f.quats, f.valid, f.seq, i / rate, f.source_time)
                  for i in range(take.n_frames)
                  for d in sender.encode(i, i, i / rate) for f in adapter.feed(d, i / rate)]
        assert len(serial) == len(frames) == take.n_frames
        assert all(v.all() for _, v, *_ in frames)
        runs[space] = frames
    # space=global (world orientations, no calibration under calibration.mode = auto), and
    # the default local space with calibration.mode = "none" (Axis's rotations are already
    # relative to its T-pose)
    for space, cfg in (("global", None), ("local", from_dict({"calibration": {"mode": "none"}}))):
        got = replay_frames(runs[space], list(A.JOINTS), list(A.PARENTS), space, rate, cfg)
        assert_same_cuts(got, ref, rate, space)


def test_rtseg_simulate_axis_take_replays_the_real_bvh():
    """``rtseg simulate axis --take test.bvh``: the skeleton map is detected as axis and the
    file's two frames arrive with the file's Hips rotation and root position."""
    take = read_bvh(FIXTURE)
    src = open_source("axis://127.0.0.1:0?queue=100&rate=125")
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "rtseg.cli", "simulate", "axis", "--take", str(FIXTURE),
             "--port", str(src.port)], capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, proc.stderr
        assert "skeleton map axis: Hips<-Hips" in proc.stdout and "Chest<-Spine3" in proc.stdout
        frames = read_all(src)
    finally:
        src.close()
    assert len(frames) == 2
    for k, f in enumerate(frames):
        assert f.valid.all() and f.source_time == k / 125
        assert same_rotation(f.quats[0], take.quats[k, 0], 1e-6)
        assert np.allclose(f.root_position, take.root_position[k] / 100.0, atol=1e-6)


@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_faulted_axis_stream_keeps_the_live_loop_up(fmt):
    """--faults on the Axis simulator: binary frames dropped and bunched reach the live
    loop with the frames not sent counted from the frame index (gaps, dropped); text: an
    unplug window closes the TCP connection, the source reconnects (counted) and every
    frame sent while connected arrives."""
    rate, speed = 60.0, 4.0
    take = synthesize("idle:3,walk:3", frame_rate=rate, seed=8).take
    if fmt == "text":
        sender = AxisSender(take, "text", "127.0.0.1", 0, speed=speed, wait_client=10,
                            faults="unplug=2:0.5,jitter=0.01,seed=2")
        sender.start()
        src = open_source(f"axis://127.0.0.1:{sender.port}?format=text&rate=60&backoff=0.02"
                          "&queue=4096")
    else:
        src = open_source("axis://127.0.0.1:0?rate=60&queue=4096&rcvbuf=4194304")
        sender = AxisSender(take, "binary", "127.0.0.1", src.port, speed=speed,
                            faults="drop=0.05,jitter=0.02,unplug=2:0.5,seed=2")
    frames, _, summary = run_live(src, sender, take, rate, speed, start=fmt == "binary")
    log = sender.sent_log
    unplugged = sum(1 for s in log if s.fault == "unplugged")
    assert unplugged >= 2 * 0.5 * rate - 1 and summary.frames_received == len(frames)
    if fmt == "binary":
        sent = [s.slot for s in log if not s.fault]
        assert [f.seq for f in frames] == sent
        assert src.stats.dropped == sent[-1] + 1 - len(sent) and src.stats.gaps >= 3
    else:
        assert src.stats.reconnects >= 1
        assert take.n_frames - unplugged - 2 * rate / speed <= len(frames) <= take.n_frames


def test_kernel_and_numpy_paths_agree(monkeypatch):
    """The compiled kernel's local quaternions are numpy's bit for bit (zeros, -0.0, angles
    past +-180 included), its global ones within 1e-15 of the pointer jumping's with the
    same float32 values, for every Euler order, one frame and a batch; bad shapes and
    parents are refused with ValueError."""
    from rtseg.drivers.axis import kernel as axis_kernel
    if not axis_kernel.AVAILABLE:
        pytest.skip("the C kernel is not built (no compiler at install)")
    rng = np.random.default_rng(5)
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        x = rng.uniform(-180, 180, (50, 59, 3)) * 10.0 ** rng.integers(-5, 2, (50, 59, 1))
        m = rng.random(x.shape)
        x[m < 0.2] = 0.0
        x[(m >= 0.2) & (m < 0.3)] = -0.0
        x[(m >= 0.3) & (m < 0.4)] = rng.choice([180.0, -360.0, 540.0])
        v = np.zeros((50, 59, 6))
        v[..., 3:] = x
        v = v.reshape(50, 354)
        out = {}
        for en in (True, False):
            monkeypatch.setattr(axis_kernel, "ENABLED", en)   # undone after the test
            out[en] = (A.poses(v, True, False, order, 0.01, "global"),
                       A.poses(v[7], True, False, order, 0.01, "global"),
                       A.global_pose(A.euler_to_quat(order, x)))
        (gk, lk, _), (g1k, l1k, _), gqk = out[True]
        (gn, ln, _), _, _ = out[False]
        assert lk.tobytes() == ln.tobytes() and l1k.tobytes() == ln[7].tobytes()
        assert g1k.tobytes() == gk[7].tobytes() and gqk.tobytes() == gk.tobytes()
        assert np.abs(gk - gn).max() < 1e-15
        assert np.array_equal(gk.astype(np.float32), gn.astype(np.float32))
    with pytest.raises(ValueError):
        axis_kernel.fk(np.zeros((3, 4)), A.PARENTS)
    with pytest.raises(ValueError):
        axis_kernel.fk(np.zeros((2, 4)), (-1, 2))
