"""Rokoko Studio Live (Custom JSON v3): codec round trip, LZ4, actors, bad input and fuzzing,
and end to end over real UDP sockets on 127.0.0.1 (simulator -> rokoko:// -> LiveSession).

No real v3 capture is public: payloads come from the simulator, which follows the schema
Rokoko's own receiver reads (Rokoko/rokoko-studio-live-blender core/live_data_manager.py)."""

from __future__ import annotations

import json
import random
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rtseg.drivers import open_source
from rtseg.drivers.rokoko import codec as C
from rtseg.drivers.rokoko.codec import (BODY_BONES, BODY_PARENTS, LZ4_MAGIC, RokokoError,
                                        decode_packet, encode_packet, unity_to_rh)
from rtseg.drivers.rokoko.source import RokokoAssembler
from rtseg.core.profiles import resolve_joints, suit_profile
from rtseg.simulators.rokoko_sender import RokokoSender
from rtseg.simulators.synth.motion import synthesize
from vendor_helpers import (Counter, assert_refused, assert_same_cuts, free_port,
                            overwrite_bytes, random_bytes, read_all, run_live, send_and_read,
                            serial_reference, simulate_into)

lz4 = pytest.importorskip("lz4.frame", reason="the lz4 package (rtseg[rokoko]) is needed "
                          "for LZ4 payloads")
J = len(BODY_BONES)


def random_pose(seed: int = 0) -> np.ndarray:
    """(21, 4) random unit quaternions rounded to float32, rtseg frame."""
    q = Rotation.random(J, random_state=seed).as_quat()
    return q.astype(np.float32).astype(np.float64)


# --------------------------------------------------------------------------- codec

@pytest.mark.parametrize("compress", [False, True])
def test_round_trip_is_exact_to_float32(compress):
    for seed in range(20):
        q = random_pose(seed)
        hip = np.array([0.25, 0.97, -1.5], dtype=np.float32).astype(np.float64)
        data = encode_packet([("Actor1", q, None, hip)], timestamp=seed / 60, fps=60,
                             compress=compress)
        assert (data[:4] == LZ4_MAGIC) == compress
        pkt = decode_packet(data)
        assert pkt.version == 3 and pkt.fps == 60 and pkt.compressed == compress
        assert pkt.timestamp == seed / 60
        a = pkt.actor(None)
        assert a.name == "Actor1" and a.valid.all() and a.bad == 0
        assert np.array_equal(a.quats.astype(np.float32), q.astype(np.float32))
        assert np.array_equal(a.hip_position.astype(np.float32), hip.astype(np.float32))


def test_wire_is_unity_left_handed_and_follows_the_schema():
    """On the wire: Unity's left-handed frame (z mirrored), rotation {x,y,z,w}, the keys
    Rokoko's receiver reads (version, fps, scene.timestamp, scene.actors[].name/meta/
    dimensions/body.<bone>.position/rotation)."""
    q = random_pose(3)
    doc = json.loads(encode_packet([("Bob", q, None, np.array([0.1, 1.0, 2.0]))], 1.5, 100))
    assert doc["version"] == 3 and doc["fps"] == 100 and doc["scene"]["timestamp"] == 1.5
    actor = doc["scene"]["actors"][0]
    assert actor["name"] == "Bob" and actor["meta"]["hasBody"] is True
    assert actor["dimensions"]["hipHeight"] > 0
    assert list(actor["body"]) == list(BODY_BONES)
    wire = np.array([[actor["body"][b]["rotation"][k] for k in "xyzw"] for b in BODY_BONES])
    assert np.array_equal(wire.astype(np.float32), (q * [-1, -1, 1, 1]).astype(np.float32))
    assert actor["body"]["hip"]["position"] == pytest.approx({"x": 0.1, "y": 1.0, "z": -2.0})
    # (x, y, z, w) -> (-x, -y, z, w) is the mirror z -> -z: M' = S M S, S = diag(1, 1, -1)
    S = np.diag([1.0, 1.0, -1.0])
    M = Rotation.from_quat(q).as_matrix()
    assert np.allclose(Rotation.from_quat(unity_to_rh(q)).as_matrix(), S @ M @ S)
    assert np.array_equal(unity_to_rh(unity_to_rh(q)), q)


def test_hierarchy_is_rokokos():
    par = {b: (BODY_BONES[p] if p >= 0 else None) for b, p in zip(BODY_BONES, BODY_PARENTS)}
    assert par["hip"] is None and par["leftUpperArm"] == "leftShoulder"
    assert par["leftShoulder"] == "chest" and par["rightToe"] == "rightFoot"
    assert all(p < k for k, p in enumerate(BODY_PARENTS))


def test_several_actors_and_selection():
    qa, qb = random_pose(1), random_pose(2)
    data = encode_packet([("Alice", qa, None, None), ("Bob", qb, None, None)], 0.0)
    pkt = decode_packet(data)
    assert [a.name for a in pkt.actors] == ["Alice", "Bob"]
    assert np.array_equal(pkt.actor("Bob").quats.astype(np.float32), qb.astype(np.float32))
    assert pkt.actor(None).name == "Alice" and pkt.actor("Carol") is None
    only = decode_packet(data, only="Bob")          # what a source following Bob decodes
    assert [a.name for a in only.actors] == ["Bob"] and only.names == ["Alice", "Bob"]
    assert np.array_equal(only.actor("Bob").quats, pkt.actor("Bob").quats)
    assert [a.name for a in decode_packet(data, only=None).actors] == ["Alice"]
    assert decode_packet(data, only="Carol").actors == []
    count = Counter()
    asm = RokokoAssembler("Bob", count)
    f = asm.feed(data, 1.0)[0]
    assert np.array_equal(f.quats.astype(np.float32), qb.astype(np.float32))
    assert asm.feed(encode_packet([("Alice", qa, None, None)], 0.1), 1.1) == []
    assert count.counts == {"unknown_names": 1}


def test_missing_and_bad_bones_are_invalid_not_fatal():
    q = random_pose(4)
    valid = np.ones(J, dtype=bool)
    valid[BODY_BONES.index("leftHand")] = False
    doc = json.loads(encode_packet([("A", q, valid, None)], 0.0))
    body = doc["scene"]["actors"][0]["body"]
    body["head"]["rotation"]["w"] = float("nan")
    body["neck"]["rotation"] = {"x": 0, "y": 0, "z": 0, "w": 2.0}       # not unit
    body["chest"]["rotation"]["x"] = "0.1"                              # wrong type
    body["spine"]["rotation"] = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.99}  # renormalised
    a = decode_packet(json.dumps(doc).encode()).actors[0]
    bad = {"leftHand", "head", "neck", "chest"}
    assert [b for b, v in zip(BODY_BONES, a.valid) if not v] == [b for b in BODY_BONES if b in bad]
    assert a.bad == 3                          # nan, non-unit, mistyped (absent: not bad)
    assert np.allclose(a.quats[BODY_BONES.index("spine")], [0, 0, 0, 1])
    count = Counter()
    asm = RokokoAssembler(None, count)
    prev = asm.feed(encode_packet([("A", q, None, None)], 0.0), 0.0)[0]
    f = asm.feed(json.dumps(doc).encode(), 0.1)[0]
    assert count.counts == {"bad_values": 3}
    k = BODY_BONES.index("leftHand")            # invalid: the last good value is repeated
    assert not f.valid[k] and np.array_equal(f.quats[k], prev.quats[k])


@pytest.mark.parametrize("data,kind", [
    (b"", "corrupt"), (b"\xff\xfe{", "corrupt"), (b"{not json", "corrupt"),
    (b"[1,2]", "bad_messages"), (b'{"version":2,"scene":{"actors":[]}}', "bad_messages"),
    (b'{"version":3,"trackers":[],"scene":{"actors":[]}}', "bad_messages"),
    (b'{"version":3,"scene":{"actors":{}}}', "bad_messages"),
    (b'{"version":3,"scene":{"actors":[{"name":"a"}]}}', "bad_messages"),
    (b'{"version":3,"scene":{"actors":[7]}}', "bad_messages"),
    (LZ4_MAGIC + b"\x00" * 20, "corrupt"),
])
def test_bad_payloads_raise_a_counted_kind(data, kind):
    with pytest.raises(RokokoError) as exc:
        decode_packet(data)
    assert exc.value.kind == kind


def test_lz4_truncated_and_oversized_payloads_are_corrupt():
    good = encode_packet([("A", random_pose(5), None, None)], 0.0, compress=True)
    with pytest.raises(RokokoError, match="truncated|bad LZ4"):
        decode_packet(good[:-9])
    bomb = lz4.compress(b" " * (C.MAX_JSON_BYTES + 10) + b"{}")
    assert len(bomb) < 65000
    with pytest.raises(RokokoError, match="inflates past"):
        decode_packet(bomb)


def test_both_json_parsers_agree(monkeypatch):
    data = encode_packet([("A", random_pose(6), None, np.array([1.0, 2.0, 3.0]))], 2.0)
    a = decode_packet(data)
    monkeypatch.setattr(C, "_loads", json.loads)
    b = decode_packet(data)
    assert np.array_equal(a.actors[0].quats, b.actors[0].quats)
    assert np.array_equal(a.actors[0].hip_position, b.actors[0].hip_position)


def test_orjson_is_the_parser_and_the_json_fallback_is_logged_once(monkeypatch, caplog):
    """orjson is a core dependency: installed rtseg parses with it.  Where it is missing
    (simulated here) every Rokoko source still works and one warning says so per process,
    not one per source."""
    import tomllib
    from pathlib import Path
    from rtseg.drivers.rokoko import source as S
    assert C.JSON_PARSER == "orjson"
    project = tomllib.loads((Path(__file__).parent.parent / "pyproject.toml").read_text())
    assert any(r.startswith("orjson") for r in project["project"]["dependencies"])
    monkeypatch.setattr(S, "JSON_PARSER", "json")
    monkeypatch.setattr(S, "_told_parser", False)
    monkeypatch.setattr(C, "_loads", json.loads)
    caplog.set_level("WARNING", logger="rtseg.drivers.rokoko")
    sources = [open_source("rokoko://127.0.0.1:0") for _ in range(2)]
    try:
        data = encode_packet([("A", random_pose(3), None, None)], 1.0)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(data, ("127.0.0.1", sources[0].port))
        frame = sources[0].read(timeout=2.0)
        assert frame is not None and np.array_equal(frame.quats, decode_packet(data).actors[0].quats)
    finally:
        for src in sources:
            src.close()
    told = [r for r in caplog.records if "orjson" in r.getMessage()]
    assert len(told) == 1 and "json module" in told[0].getMessage()


def _mutations(rng: random.Random, base: list[bytes], doc: dict):
    """Fuzzed payloads: byte flips / truncations / splices of valid JSON and LZ4 payloads,
    random bytes, and structurally valid JSON with values swapped for other JSON types."""
    junk = [None, True, "x", [], {}, -1e308, 1e400, 3, [1, 2], {"x": 1}]
    while True:
        r = rng.random()
        src = rng.choice(base)
        if r < 0.35:
            yield overwrite_bytes(rng, src, 8)
        elif r < 0.5:
            yield src[:rng.randrange(len(src))]
        elif r < 0.6:
            yield random_bytes(rng, 64)
        elif r < 0.7:
            yield LZ4_MAGIC + random_bytes(rng, 64)
        else:
            d = json.loads(json.dumps(doc))
            node, path = d, []
            while isinstance(node, (dict, list)) and node and rng.random() < 0.85:
                key = rng.choice(list(node)) if isinstance(node, dict) else rng.randrange(len(node))
                path.append((node, key))
                node = node[key]
            if path:
                parent, key = path[-1]
                if rng.random() < 0.2 and isinstance(parent, dict):
                    del parent[key]
                else:
                    parent[key] = rng.choice(junk)
            text = json.dumps(d)
            yield lz4.compress(text.encode()) if rng.random() < 0.2 else text.encode()


def test_fuzzed_payloads_never_escape():
    """10^4 fuzzed payloads: only RokokoError from the codec, and the assembler (what the
    source runs) never raises, counting each payload at most once."""
    rng = random.Random(1)
    q = random_pose(7)
    plain = encode_packet([("A", q, None, np.zeros(3)), ("B", q, None, None)], 1.0)
    base = [plain, encode_packet([("A", q, None, None)], 1.0, compress=True)]
    doc = json.loads(plain)
    count = Counter()
    asm = RokokoAssembler(None, count)
    gen = _mutations(rng, base, doc)
    frames = errors = 0
    for _ in range(10_000):
        data = next(gen)
        try:
            decode_packet(data)
        except RokokoError:
            pass
        try:
            decode_packet(data, only=None)              # what the assembler decodes
        except RokokoError:
            errors += 1
        frames += len(asm.feed(data, 0.0))
    assert errors > 1000 and frames > 1000          # both kinds were exercised
    assert sum(count.counts.get(k, 0) for k in ("corrupt", "bad_messages")) == errors


# --------------------------------------------------------------------------- sockets

def udp_out() -> socket.socket:
    return socket.socket(socket.AF_INET, socket.SOCK_DGRAM)


def test_url_defaults_options_and_errors():
    src = open_source("rokoko://:0?actor=Bob&rate=100")
    try:
        assert src.host == "127.0.0.1" and src.port > 0
        assert src.joint_names == list(BODY_BONES) and src.parents == list(BODY_PARENTS)
        assert src.space == "global" and src.frame_rate == 100.0
        assert src.assembler.actor == "Bob"
    finally:
        src.close()
    assert_refused([("rokoko://:0?bogus=1", "unknown option"),
                    ("rokoko://:0?rate=0", "out of range"),
                    ("rokoko://:0?allow=nonsense", "rokoko:// allow="),
                    ("rokoko://:99999", "out of range")])


def test_sender_to_source_round_trip_with_lz4_and_actor_choice():
    take = synthesize("idle:2,walk:2", frame_rate=60.0, seed=2).take
    src = open_source("rokoko://127.0.0.1:0?actor=Second&queue=4096&rate=60")
    offset = 50
    sender = RokokoSender(take, "127.0.0.1", src.port, compress=True, speed=8.0,
                          actors=[("First", 0), ("Second", offset)])
    frames = send_and_read(src, sender)
    n = take.n_frames
    assert len(frames) == n
    assert [f.seq for f in frames] == list(range(n))
    assert np.allclose([f.source_time for f in frames], np.arange(n) / 60.0)
    got = np.array([f.quats for f in frames]).astype(np.float32)
    want = sender.body[(np.arange(n) + offset) % n]
    assert np.array_equal(got, want)
    assert all(f.valid.all() for f in frames)
    assert np.allclose([f.root_position for f in frames], sender.root[(np.arange(n) + offset) % n],
                       atol=1e-6)
    assert src.stats.corrupt == src.stats.bad_messages == src.stats.dropped == 0


def test_junk_datagrams_are_counted_and_the_source_goes_on():
    src = open_source("rokoko://127.0.0.1:0")
    out = udp_out()
    try:
        good = encode_packet([("A", random_pose(8), None, None)], 0.0)
        for d in (b"junk", b'{"version": 2}', good, LZ4_MAGIC + b"xx", good):
            out.sendto(d, ("127.0.0.1", src.port))
        frames = read_all(src)
    finally:
        out.close()
        src.close()
    assert len(frames) == 2
    assert src.stats.corrupt == 2 and src.stats.bad_messages == 1


def test_allow_list_refuses_other_senders_before_decoding():
    src = open_source("rokoko://127.0.0.1:0?allow=10.9.8.7")
    out = udp_out()
    try:
        out.sendto(encode_packet([("A", random_pose(9), None, None)], 0.0),
                   ("127.0.0.1", src.port))
        assert src.read(timeout=0.4) is None
        assert src.stats.refused_senders == 1 and src.stats.corrupt == 0
    finally:
        out.close()
        src.close()


def test_simulator_through_live_session_gives_valid_joints_and_cuts():
    """A synthetic take with 3 behaviour changes, sent x4 as Rokoko JSON over 127.0.0.1 into
    a LiveSession: every mapped joint valid in every frame, the take's clock, and at least
    one cut."""
    rate, speed = 120.0, 4.0
    take = synthesize("idle:3,walk:4,punch:4,squat:4", frame_rate=rate, seed=3).take
    src = open_source(f"rokoko://127.0.0.1:0?rate={rate:g}&queue=4096")
    sender = RokokoSender(take, "127.0.0.1", src.port, speed=speed)
    frames, cuts, summary = run_live(src, sender, take, rate, speed)
    assert len(frames) == take.n_frames == summary.frames_received
    mapped = resolve_joints("unity", src.joint_names)
    assert all(f.valid[mapped].all() for f in frames)
    assert np.allclose([f.source_time for f in frames], np.arange(take.n_frames) / rate)
    assert src.stats.corrupt == src.stats.dropped == 0
    assert len(cuts) >= 1, "no cut on a take with 3 behaviour changes"


def test_rtseg_simulate_rokoko_command_reaches_the_source():
    out, port, frames = simulate_into("rokoko://127.0.0.1:0?queue=10000&actor=B", "rokoko",
                                      "60", "--actor", "A,B", "--lz4")
    assert f'rtseg live "rokoko://127.0.0.1:{port}?rate=60"' in out
    assert "rigid with their parent: LeftShoulder, RightShoulder, LeftToes, RightToes" in out
    assert len(frames) == 240 and all(f.valid.all() for f in frames)


def test_suit_profile_names_rokokos_bones():
    suit = suit_profile("rokoko")
    assert [C.SUIT_BONES[b] for b in BODY_BONES] == list(suit.bones)
    assert [suit.parents[k] for k in range(J)] == list(BODY_PARENTS)
    # the pose-feature joints resolve on Rokoko's names (unity profile aliases)
    assert len(resolve_joints("unity", list(BODY_BONES))) == 12
    # the rokoko skeleton profile picks the same bones as the unity profile's aliases
    assert resolve_joints("rokoko", list(BODY_BONES)) == resolve_joints("unity", list(BODY_BONES))


def test_rtseg_live_rokoko_url_prints_cuts():
    """``rtseg live rokoko://127.0.0.1:PORT`` (a separate process) fed by the simulator:
    the session prints cuts and ends after --duration."""
    rate, speed = 120.0, 4.0
    take = synthesize("idle:3,walk:4,punch:4", frame_rate=rate, seed=5).take
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "rtseg.cli", "live", f"rokoko://127.0.0.1:{port}?rate={rate:g}",
         "--no-osc", "--quiet", "--duration", "7"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sender = RokokoSender(take, "127.0.0.1", port, speed=speed)
    try:
        time.sleep(2.0)                         # the process imports and binds the port
        with sender:
            sender.wait(10)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
    assert proc.returncode == 0, err
    assert any(ln.startswith("cut #") for ln in out.splitlines()), out + err


def test_a_take_with_rokoko_names_replays_unchanged():
    """A take named like Rokoko's bones (a session recorded from rokoko://) is placed by the
    ``rokoko`` skeleton map: the bodies sent are the take's global orientations."""
    from rtseg.core import quat as Q
    from rtseg.core.take import Take
    rng = np.random.default_rng(3)
    n = 30
    local = Rotation.from_rotvec(rng.normal(scale=0.5, size=(n * J, 3))).as_quat().reshape(n, J, 4)
    take = Take(list(BODY_BONES), list(BODY_PARENTS), 60.0, local,
                root_position=rng.normal(size=(n, 3)), length_unit="m")
    s = RokokoSender(take)
    assert s.retargeted.family == "rokoko" and s.describe().count("<-") == J
    g = Q.global_from_local(local, list(BODY_PARENTS))
    for k in range(n):
        a = decode_packet(s.payload(k, k / 60)).actors[0]
        assert a.valid.all()
        assert (np.abs(np.abs(np.sum(a.quats * g[k], -1)) - 1) < 1e-6).all()


def test_real_take_cuts_match_the_serial_suit(data_dir):
    """86_01 (CMU, 38 s) through the Rokoko codec gives the cuts the 17-sensor serial suit
    gives through its codec, within 0.25 s (offline pipeline, the live loop's own)."""
    from rtseg.live.replay import replay_frames

    take, serial, ref = serial_reference(data_dir)
    rate = take.frame_rate
    sender = RokokoSender(take)                         # encode only: never started
    asm = RokokoAssembler(None, Counter())
    rok = [(f.quats, f.valid, f.seq, i / rate, f.source_time) for i in range(take.n_frames)
           for f in asm.feed(sender.payload(i, i / rate), i / rate)]
    assert len(serial) == len(rok) == take.n_frames
    assert all(v.all() for _, v, *_ in rok)
    got = replay_frames(rok, list(BODY_BONES), list(BODY_PARENTS), "global", rate)
    assert_same_cuts(got, ref, rate)


def test_rtseg_simulate_rokoko_with_faults():
    """``--faults``: dropped payloads never arrive, corrupted ones are refused and counted
    (JSON damage), the rest arrive; the summary says what the faults did."""
    out, port, frames = simulate_into("rokoko://127.0.0.1:0?queue=10000&rcvbuf=4194304",
                                      "rokoko", "60", "--faults", "drop=0.1,corrupt=0.0002,seed=4")
    dropped = int(out.split(" dropped by faults")[0].rsplit("; ", 1)[1])
    corrupted = int(out.split(" corrupted by faults")[0].rsplit("; ", 1)[1])
    assert dropped > 5 and corrupted > 5
    assert 240 - dropped - corrupted <= len(frames) <= 240 - dropped
