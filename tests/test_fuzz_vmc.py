"""Property tests of the OSC parser and VMC assembler: random and mutated datagrams.

Only ``OscParseError`` may escape ``parse_packet``; nothing may escape
``VmcAssembler.feed``/``flush``; the assembler recovers once valid frames follow.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pythonosc.osc_message import OscMessage as PyOscMessage
from scipy.spatial.transform import Rotation

from rtseg.drivers.osc.vmc.codec import (
    OscParseError, VmcAssembler, encode_bundle, encode_frame, encode_message, pack_bundles,
    parse_message, parse_packet,
)
from rtseg.drivers.osc.vrchat import VrchatAssembler
from rtseg.core.frame import Frame

BONES = ["Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand",
         "RightUpperArm", "RightLowerArm", "RightHand", "LeftUpperLeg", "LeftLowerLeg",
         "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot"]
Q = Rotation.random(3 * len(BONES), random_state=7).as_quat().reshape(3, len(BONES), 4)
SEED_DGRAMS = [d for i in range(2) for d in encode_frame(
    Q[i], BONES, time=float(i), root_position=(0, 1, i), max_datagram=400)]
# recovery frames: times no mutation can have produced by accident is not required; the
# change rules close whatever junk left open as soon as these arrive
CLEAN = [encode_frame(Q[i], BONES, time=1000.0 + i, root_position=(5, 5, i)) for i in range(3)]

FUZZ = settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def check_packet(data: bytes) -> None:
    try:
        msgs = parse_packet(data)
    except OscParseError:
        return
    for m in msgs:
        assert m.address.startswith("/") and isinstance(m.args, tuple)


def check_assembler(chunks: list[bytes]) -> None:
    asm = VmcAssembler(BONES)
    now = 0.0
    for c in chunks:
        for f in asm.feed(c, now):
            assert isinstance(f, Frame) and f.quats.shape == (len(BONES), 4)
            assert np.all(np.isfinite(f.quats))
            assert np.allclose(np.linalg.norm(f.quats, axis=1), 1.0)
        now += 0.001
    asm.flush(now + 1.0)
    # recovery: clean frames after the junk decode exactly
    out = []
    for k, frame in enumerate(CLEAN):
        for d in frame:
            out += asm.feed(d, now + 2 + k)
    out += asm.flush(now + 100.0, force=True)
    last = out[-2:]
    # junk may have left T anywhere: the clean frames keep their spacing, and the reported
    # clock never goes back (a step back in T starts a new clock segment)
    assert last[1].source_time - last[0].source_time == pytest.approx(1.0, abs=1e-6)
    times = [f.source_time for f in out if f.source_time is not None]
    assert times == sorted(times)
    if asm.stats.clock_restarts == 0:
        assert [f.source_time for f in last] == [1001.0, 1002.0]
    for f, q in zip(last, Q[1:]):
        assert f.valid.all()
        d = np.minimum(np.abs(f.quats - q).max(-1), np.abs(f.quats + q).max(-1))
        assert d.max() < 1e-6


@FUZZ
@given(st.binary(max_size=600))
def test_random_bytes(data):
    check_packet(data)
    check_packet(b"#bundle\x00" + data)
    check_packet(b"/VMC/Ext/Bone/Pos\x00\x00\x00" + data)
    check_assembler([data, b"#bundle\x00" + bytes(8) + data])
    vr = VrchatAssembler()
    for chunk in (data, b"/tracking/trackers/1/rotation\x00\x00\x00" + data):
        for f in vr.feed(chunk, 0.0):
            assert np.all(np.isfinite(f.quats))
    vr.flush(1.0)


mutation = st.one_of(
    st.tuples(st.just("flip"), st.integers(0, 2000), st.integers(1, 255)),
    st.tuples(st.just("cut"), st.integers(0, 2000), st.just(0)),
    st.tuples(st.just("insert4"), st.integers(0, 500), st.integers(0, 2 ** 32 - 1)),
    st.tuples(st.just("delete4"), st.integers(0, 500), st.just(0)),
    st.tuples(st.just("size"), st.integers(0, 40), st.integers(-2 ** 31, 2 ** 31 - 1)),
    st.tuples(st.just("float"), st.integers(0, 400), st.sampled_from(
        [float("nan"), float("inf"), -0.0, 2.0, 1e30, 1e-30])),
)


def mutate(data: bytes, ops) -> bytes:
    b = bytearray(data)
    for kind, pos, val in ops:
        if not b:
            break
        if kind == "flip":
            b[pos % len(b)] ^= val
        elif kind == "cut":
            del b[pos % (len(b) + 1):]
        elif kind == "insert4":
            p = (pos * 4) % (len(b) + 1)
            b[p:p] = struct.pack(">I", val)
        elif kind == "delete4":
            p = (pos * 4) % len(b)
            del b[p:p + 4]
        elif kind == "size":       # damage a bundle element size (or any aligned word)
            p = (16 + pos * 4) % max(len(b) - 3, 1)
            b[p:p + 4] = struct.pack(">i", val)
        elif kind == "float":
            p = (pos * 4) % max(len(b) - 3, 1)
            b[p:p + 4] = struct.pack(">f", val)
    return bytes(b)


@FUZZ
@given(st.lists(st.tuples(st.integers(0, len(SEED_DGRAMS) - 1),
                          st.lists(mutation, min_size=1, max_size=4)), min_size=1, max_size=6))
def test_mutated_vmc_datagrams(items):
    chunks = [mutate(SEED_DGRAMS[i], ops) for i, ops in items]
    for c in chunks:
        check_packet(c)
    check_assembler(chunks)


# --------------------------------------------------------------------------- round trip

f32 = st.floats(width=32, allow_nan=False)
arg = st.one_of(
    st.tuples(st.just("i"), st.integers(-2 ** 31, 2 ** 31 - 1)),
    st.tuples(st.just("f"), f32),
    st.tuples(st.just("d"), st.floats(allow_nan=False)),
    st.tuples(st.just("s"), st.text(st.characters(blacklist_characters="\x00",
                                                  blacklist_categories=("Cs",)), max_size=12)),
    st.tuples(st.just("b"), st.binary(max_size=12)),
    st.tuples(st.just("h"), st.integers(-2 ** 63, 2 ** 63 - 1)),
    st.tuples(st.sampled_from("TFN"), st.none()),
)
address = st.lists(st.text("abcXYZ09_", min_size=1, max_size=6), min_size=1, max_size=4).map(
    lambda parts: "/" + "/".join(parts))


@FUZZ
@given(address, st.lists(arg, max_size=8))
def test_encode_parse_round_trip_agrees_with_python_osc(addr, args):
    tags = "".join(t for t, _ in args)
    values = [v for _, v in args]
    dgram = encode_message(addr, tags, values)
    mine = parse_message(dgram)
    expect = [{"T": True, "F": False, "N": None}.get(t, v) for t, v in args]
    assert mine.address == addr and mine.tags == tags
    for got, want in zip(mine.args, expect):
        if isinstance(want, float):
            assert got == want or (math.isinf(want) and got == want)
        else:
            assert got == want
    ref = PyOscMessage(dgram)
    assert list(ref.params) == list(mine.args)


# --------------------------------------------------------------------------- structured streams

any_f32 = st.floats(width=32)
vmc_msg = st.one_of(
    st.tuples(st.just("bone"), st.sampled_from(BONES + ["hips", "Tail", ""]),
              st.lists(any_f32, min_size=7, max_size=7)),
    st.tuples(st.just("root"), st.just("root"), st.lists(any_f32, min_size=7, max_size=7)),
    st.tuples(st.just("t"), st.just(""), st.lists(any_f32, min_size=1, max_size=1)),
)


def _encode(kind: str, name: str, vals: list[float]) -> bytes:
    if kind == "t":
        return encode_message("/VMC/Ext/T", "f", vals)
    addr = "/VMC/Ext/Bone/Pos" if kind == "bone" else "/VMC/Ext/Root/Pos"
    return encode_message(addr, "sfffffff", [name] + vals)


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.lists(vmc_msg, min_size=1, max_size=6),
                          st.floats(0.0, 0.05)), min_size=1, max_size=12),
       st.sampled_from(["last", "first"]))
def test_structured_streams_with_extreme_values(stream, order):
    asm = VmcAssembler(BONES, time_order=order)
    now, seqs = 0.0, []
    for msgs, dt in stream:
        now += dt
        for f in asm.feed(encode_bundle([_encode(*m) for m in msgs]), now):
            seqs.append(f.seq)
            assert np.all(np.isfinite(f.quats))
            assert f.source_time is None or math.isfinite(f.source_time)
    seqs += [f.seq for f in asm.flush(now + 1.0)]
    assert seqs == sorted(set(seqs))


# --------------------------------------------------------------------------- fast path equivalence

frame_spec = st.fixed_dictionaries({
    "drop_bone": st.one_of(st.none(), st.integers(0, len(BONES) - 1)),
    "bad": st.sampled_from([None, None, None, "nan", "norm", "root_nan", "t_nan"]),
    "extra": st.lists(st.sampled_from(["blend", "thumb", "ok"]), max_size=3),
    "root": st.booleans(),
    "t_step": st.sampled_from([1, 1, 1, 2, 5, 0]),
    "small": st.booleans(),
})


def _frame_datagrams(k: int, t: float, spec: dict, q: np.ndarray) -> list[bytes]:
    msgs = []
    if spec["root"]:
        rp = (float("nan"), 0, 0) if spec["bad"] == "root_nan" else (0.1, 1.0, 0.01 * k)
        msgs.append(encode_message("/VMC/Ext/Root/Pos", "sfffffff", ["root", *rp, 0, 0, 0, 1]))
    for j, b in enumerate(BONES):
        if j == spec["drop_bone"]:
            continue
        x, y, z, w = q[j]
        if spec["bad"] == "nan" and j == 3:
            x = float("nan")
        if spec["bad"] == "norm" and j == 5:
            w = 3.0
        msgs.append(encode_message("/VMC/Ext/Bone/Pos", "sfffffff", [b, 0, 0.9, 0, -x, -y, z, w]))
    for e in spec["extra"]:
        if e == "blend":
            msgs.append(encode_message("/VMC/Ext/Blend/Val", "sf", ["A", 0.25 * k]))
        elif e == "thumb":
            msgs.append(encode_message("/VMC/Ext/Bone/Pos", "sfffffff",
                                       ["LeftThumbProximal", 0, 0, 0, 0, 0, 0, 1]))
        else:
            msgs.append(encode_message("/VMC/Ext/OK", "iiii", [1, 3, 0, k % 2]))
    msgs.append(encode_message("/VMC/Ext/T", "f", [float("nan") if spec["bad"] == "t_nan" else t]))
    return pack_bundles(msgs, 500 if spec["small"] else 1472)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frame_spec, min_size=1, max_size=10), st.integers(0, 2))
def test_whole_frame_fast_path_equals_general_path(specs, seed):
    q = Rotation.random(len(specs) * len(BONES), random_state=seed).as_quat().reshape(
        len(specs), len(BONES), 4)
    stream, t = [], 0.0
    for k, spec in enumerate(specs):
        t += spec["t_step"] / 60.0
        for i, d in enumerate(_frame_datagrams(k, t, spec, q[k])):
            stream.append((d, k / 60.0 + i * 1e-5))
    results = []
    for fast in (True, False):
        asm = VmcAssembler(BONES, fast=fast)
        out = [f for d, now in stream for f in asm.feed(d, now)] + asm.flush(100.0)
        results.append((out, asm.stats.as_dict(), asm.ok_state))
    (fo, fs, fok), (so, ss, sok) = results
    assert fs == ss and fok == sok and len(fo) == len(so)
    for a, b in zip(fo, so):
        assert (a.seq, a.source_time, a.recv_time) == (b.seq, b.source_time, b.recv_time)
        assert np.array_equal(a.valid, b.valid) and np.array_equal(a.quats, b.quats)
        assert (a.root_position is None) == (b.root_position is None)
        if a.root_position is not None:
            assert np.array_equal(a.root_position, b.root_position)
