"""Publishers through real sockets on 127.0.0.1: python-osc and liblo's oscdump as receivers,
a SLIP-decoding TCP server, down targets, templates, JSON lines, target specs."""

from __future__ import annotations

import io
import json
import math
import queue
import shutil
import socket
import struct
import subprocess
import threading
import time

import numpy as np
import pytest
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from osc_collector import OscCollector
from rtseg.core.events import CutEvent, DropoutEvent, StatusEvent, event_from_dict
from rtseg.publishers import (JsonlPublisher, OscTcpPublisher, OscUdpPublisher, Publisher,
                              PublisherSet, parse_target, sanitize_label)
from rtseg.publishers.osc.message import encode_message, slip_encode
from rtseg.publishers.templates import AddressTemplate

HOST = "127.0.0.1"


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    s = socket.socket(socket.AF_INET, kind)
    s.bind((HOST, 0))
    port = s.getsockname()[1]
    s.close()
    return port


def make_cut(**kw) -> CutEvent:
    base = dict(event=3, segment=4, frame=412, time=3.5, method="pca", label="walk",
                confidence=0.75, latency_ms=12.5, detector_delay_ms=100.0)
    base.update(kw)
    return CutEvent(**base)


@pytest.fixture
def receiver():
    r = OscCollector(linger=0.0)
    yield r
    r.close()


# -- encoder -------------------------------------------------------------------------------

def test_encoder_matches_python_osc_builder():
    b = OscMessageBuilder("/rtseg/cut")
    for tag, v in (("i", 7), ("f", 0.25), ("s", "walk"), ("i", -3), ("s", "")):
        b.add_arg(v, tag)
    assert encode_message("/rtseg/cut", "ifsis", [7, 0.25, "walk", -3, ""]) == b.build().dgram


def test_encoder_coerces_numpy_and_clamps():
    pkt = encode_message("/x", "iiff", [np.int64(2 ** 40), np.int32(-(2 ** 31) - 0), np.float32(0.5),
                                          1e300])
    msg = OscMessage(pkt)
    assert pkt[4:12] == b",iiff\0\0\0"
    assert msg.params[:3] == [2 ** 31 - 1, -(2 ** 31), 0.5]
    assert math.isinf(msg.params[3])
    with pytest.raises(ValueError, match="type tag"):
        encode_message("/x", "d", [1.0])
    with pytest.raises(ValueError, match="arguments"):
        encode_message("/x", "ii", [1])


# -- UDP -------------------------------------------------------------------------------------

def test_udp_cut_exact_args_and_types(receiver):
    ev = make_cut(event=np.int64(3), segment=np.int32(4), time=np.float32(3.5),
                  confidence=np.float64(0.75), label="High Kick!")
    with OscUdpPublisher(HOST, receiver.port) as pub:
        pub.publish_cut(ev)
        (a1, args1), (a2, args2) = receiver.take(2)
    assert a1 == "/rtseg/cut"
    assert args1 == [3, 4, 3.5, 0.75, 12.5, 100.0, "High Kick!"]
    assert [type(x) for x in args1] == [int, int, float, float, float, float, str]
    assert a2 == "/rtseg/cut/High_Kick"
    assert args2 == [4, 0.75] and [type(x) for x in args2] == [int, float]
    assert pub.stats.sent == 2 and pub.stats.dropped == 0


def test_udp_latency_stamped_from_boundary_recv_time(receiver):
    ev = make_cut(latency_ms=None, boundary_recv_time=time.monotonic() - 0.25)
    with OscUdpPublisher(HOST, receiver.port) as pub:
        pub.publish_cut(ev)
        (_, args), _ = receiver.take(2)
    assert 250.0 <= args[4] < 5000.0


def test_udp_status_and_dropout(receiver):
    with OscUdpPublisher(HOST, receiver.port) as pub:
        pub.publish_status(StatusEvent(alive=1, frame_rate=np.float32(99.5), dropped=np.int64(3),
                                       stale_joints=2, corrupt=7, crc_failures=5,
                                       bad_messages=np.int64(4), bad_values=2, unknown_names=1))
        pub.publish_dropout(DropoutEvent("LeftHand", lost=True))
        pub.publish_dropout(DropoutEvent("LeftHand", lost=False))
        got = receiver.take(4)
    assert got == [("/rtseg/status", [1, 99.5, 3, 2]), ("/rtseg/input", [7, 5, 4, 2, 1]),
                   ("/rtseg/dropout", ["LeftHand", 1]), ("/rtseg/dropout", ["LeftHand", 0])]


def test_udp_big_int_goes_as_int32_on_the_wire():
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind((HOST, 0))
    rx.settimeout(2)
    try:
        with OscUdpPublisher(HOST, rx.getsockname()[1]) as pub:
            pub.publish_cut(make_cut(event=2 ** 40, segment=np.uint64(5)))
            dgram = rx.recv(2048)
    finally:
        rx.close()
    assert dgram[12:24] == b",iiffffs\0\0\0\0"
    assert struct.unpack(">ii", dgram[24:32]) == (2 ** 31 - 1, 5)


def _start_oscdump(url: str) -> tuple[subprocess.Popen, queue.Queue]:
    proc = subprocess.Popen(["oscdump", "-L", url], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    lines: queue.Queue = queue.Queue()

    def pump():
        for line in proc.stdout:
            lines.put(line.rstrip("\n"))
    threading.Thread(target=pump, daemon=True).start()
    return proc, lines


def _stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(2)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(2)


def _lines_until(lines: queue.Queue, needle: str, timeout: float = 3.0) -> list[str]:
    out = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            out.append(lines.get(timeout=0.05))
        except queue.Empty:
            continue
        if needle in out[-1]:
            return out
    raise AssertionError(f"{needle!r} not received; got {out}")


@pytest.mark.skipif(shutil.which("oscdump") is None, reason="liblo-tools (oscdump) not installed")
def test_oscdump_receives_udp_cut_with_typetags():
    port = free_port()
    proc, lines = _start_oscdump(str(port))
    try:
        with OscUdpPublisher(HOST, port) as pub:
            # oscdump needs a moment to bind: probe with status messages until one arrives.
            deadline = time.monotonic() + 5
            seen = []
            while time.monotonic() < deadline:
                pub.publish_status(StatusEvent(1, 60.0, 0, 0))
                try:
                    seen.append(lines.get(timeout=0.1))
                    break
                except queue.Empty:
                    pass
            assert seen and "/rtseg/status ifii 1 60.000000 0 0" in seen[0], seen
            pub.publish_cut(make_cut(label="jump"))
            got = _lines_until(lines, "/rtseg/cut/")
    finally:
        _stop(proc)
    cut = [line for line in got if " /rtseg/cut " in line][0]
    assert cut.split(" ", 1)[1] == '/rtseg/cut iiffffs 3 4 3.500000 0.750000 12.500000 100.000000 "jump"'
    assert got[-1].split(" ", 1)[1] == "/rtseg/cut/jump if 4 0.750000"


def test_down_udp_target_counts_drops_and_never_raises():
    port = free_port()          # nothing listens there: each datagram draws ICMP unreachable
    with OscUdpPublisher(HOST, port) as pub:
        for i in range(20):
            pub.publish_cut(make_cut(event=i))
            time.sleep(0.002)
        assert pub.stats.refused > 0
        assert pub.stats.dropped >= pub.stats.refused
    # publishing after close is counted, not raised
    pub.publish_status(StatusEvent())
    assert pub.stats.dropped > pub.stats.refused


def test_udp_target_coming_back_receives_again():
    port = free_port()
    with OscUdpPublisher(HOST, port) as pub:
        for _ in range(5):
            pub.publish_status(StatusEvent())
            time.sleep(0.002)
        rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        rx.bind((HOST, port))
        rx.settimeout(2)
        try:
            pub.publish_dropout(DropoutEvent("Head", True))   # may first hit a pending refusal
            msg = OscMessage(rx.recv(2048))
        finally:
            rx.close()
    assert msg.address == "/rtseg/dropout" and msg.params == ["Head", 1]


# -- templates -------------------------------------------------------------------------------

def test_template_only_target_fires_qlab_style_cue(receiver):
    pub = parse_target(f"udp:{HOST}:{receiver.port},standard=off,template=/cue/{{label}}/start")
    try:
        pub.publish_cut(make_cut(label="walk fast"))
        pub.publish_status(StatusEvent())            # standard=off: not sent
        pub.publish_cut(make_cut(label="jump", segment=5))
        got = receiver.take(2)
    finally:
        pub.close()
    assert got == [("/cue/walk_fast/start", []), ("/cue/jump/start", [])]
    assert receiver.untaken == 0


def test_template_with_arguments_and_fields(receiver):
    pub = parse_target(f"{HOST}:{receiver.port}",
                       templates=["/show/{method}/seg{segment:03d} segment confidence label 1 0.5"])
    try:
        pub.publish_cut(make_cut(segment=7, label="punch"))
        got = receiver.take(3)
    finally:
        pub.close()
    assert [g[0] for g in got] == ["/rtseg/cut", "/rtseg/cut/punch", "/show/pca/seg007"]
    assert got[2][1] == [7, 0.75, "punch", 1, 0.5]
    assert [type(x) for x in got[2][1]] == [int, float, str, int, float]


@pytest.mark.parametrize("bad, why", [
    ("cue/{label}", "must start with '/'"),
    ("/cue/{name}/start", "unknown field"),
    ("/cue/{label}/start loudness", "unknown argument"),
    ("/cue/{segment:q}", "Unknown format code"),
    ("", "empty"),
])
def test_bad_templates_are_refused_with_the_template_named(bad, why):
    with pytest.raises(ValueError, match=why):
        AddressTemplate(bad)


@pytest.mark.parametrize("label, expected", [
    ("walk", "walk"), ("High Kick!", "High_Kick"), ("jump/land", "jump_land"),
    ("a  b", "a_b"), ("", "unlabelled"), ("***", "unlabelled"), ("crouch-2_x", "crouch-2_x"),
    ("sauté", "saut"),
])
def test_label_sanitising(label, expected):
    assert sanitize_label(label) == expected


# -- TCP -------------------------------------------------------------------------------------

def slip_frames(data: bytes) -> list[bytes]:
    """Independent SLIP decoder for the tests (RFC 1055, END=0xC0, ESC=0xDB)."""
    frames = []
    for chunk in data.split(b"\xc0"):
        if chunk:
            frames.append(chunk.replace(b"\xdb\xdc", b"\xc0").replace(b"\xdb\xdd", b"\xdb"))
    return frames


class SlipServer:
    """TCP server on 127.0.0.1 collecting every byte of each accepted connection."""

    def __init__(self, port: int = 0, close_first: bool = False) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((HOST, port))
        self.sock.listen(4)
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.data = bytearray()
        self.connections = 0
        self.close_first = close_first
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run)
        self.thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except socket.timeout:
                continue
            self.connections += 1
            if self.close_first and self.connections == 1:
                conn.close()
                continue
            conn.settimeout(0.05)
            with conn:
                while not self._stop.is_set():
                    try:
                        b = conn.recv(65536)
                    except socket.timeout:
                        continue
                    if not b:
                        break
                    self.data += b

    def messages(self, n: int, timeout: float = 3.0) -> list[OscMessage]:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            frames = slip_frames(bytes(self.data))
            if len(frames) >= n:
                return [OscMessage(f) for f in frames]
            time.sleep(0.01)
        raise AssertionError(f"expected {n} SLIP frames, got {slip_frames(bytes(self.data))}")

    def close(self) -> None:
        self._stop.set()
        self.thread.join(2)
        self.sock.close()


def test_tcp_slip_frames_with_escaped_bytes():
    srv = SlipServer()
    pub = OscTcpPublisher(HOST, srv.port)
    try:
        # 192 = 0x000000C0 and 219 = 0x000000DB and -2.0 = 0xC0000000 need SLIP escapes.
        pub.publish_cut(make_cut(event=192, segment=219, time=-2.0))
        pub.publish_status(StatusEvent(1, 100.0, 0, 1))
        msgs = srv.messages(3)
    finally:
        pub.close()
        srv.close()
    assert (msgs[0].address, msgs[0].params) == (
        "/rtseg/cut", [192, 219, -2.0, 0.75, 12.5, 100.0, "walk"])
    assert (msgs[1].address, msgs[1].params) == ("/rtseg/cut/walk", [219, 0.75])
    assert (msgs[2].address, msgs[2].params) == ("/rtseg/status", [1, 100.0, 0, 1])
    assert not pub._thread.is_alive()


@pytest.mark.skipif(shutil.which("oscdump") is None, reason="liblo-tools (oscdump) not installed")
def test_oscdump_receives_tcp_slip():
    port = free_port(socket.SOCK_STREAM)
    proc, lines = _start_oscdump(f"osc.tcp://:{port}")
    pub = OscTcpPublisher(HOST, port, backoff_s=(0.02, 0.1))
    try:
        pub.publish_cut(make_cut(event=192, segment=219, label="kick"))
        got = _lines_until(lines, "/rtseg/cut/kick", timeout=5)
    finally:
        pub.close()
        _stop(proc)
    assert any(line.endswith('/rtseg/cut iiffffs 192 219 3.500000 0.750000 12.500000 100.000000 "kick"')
               for line in got), got


def test_down_tcp_target_queues_drops_oldest_then_delivers_newest():
    port = free_port(socket.SOCK_STREAM)
    pub = OscTcpPublisher(HOST, port, queue_size=3, max_age_s=30, backoff_s=(0.02, 0.05))
    srv = None
    try:
        for i in range(10):
            pub.publish_status(StatusEvent(alive=1, frame_rate=60.0, dropped=i, stale_joints=0))
        assert pub.stats.dropped == 7 and pub.queued() == 3 and not pub.connected
        srv = SlipServer(port)
        msgs = srv.messages(3)
        assert [m.params[2] for m in msgs] == [7, 8, 9]
        # the sender counts a message once its bytes are written: the receiver may parse
        # the last one before that count is taken
        deadline = time.monotonic() + 2.0
        while pub.stats.sent < 3 and time.monotonic() < deadline:
            time.sleep(0.005)
        assert pub.stats.reconnects == 1 and pub.stats.sent == 3
    finally:
        pub.close()
        if srv:
            srv.close()
    assert not pub._thread.is_alive()


def test_tcp_connection_that_meets_itself_is_not_a_receiver(monkeypatch):
    """With no receiver on a local port, a reconnect may be given that port as its own
    source port and connect to itself (TCP simultaneous open): not a connection, nothing
    sent into it."""
    import rtseg.publishers.osc.tcp as tcp

    def self_connect(address, timeout=None):
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.bind((HOST, 0))
        s.connect((HOST, s.getsockname()[1]))
        return s

    monkeypatch.setattr(tcp.socket, "create_connection", self_connect)
    port = free_port(socket.SOCK_STREAM)
    pub = OscTcpPublisher(HOST, port, queue_size=3, max_age_s=30, backoff_s=(0.02, 0.05))
    try:
        pub.publish_status(StatusEvent(alive=1, frame_rate=60.0, dropped=0, stale_joints=0))
        time.sleep(0.2)
        assert not pub.connected and pub.stats.sent == 0 and pub.queued() == 1
    finally:
        pub.close()


def test_tcp_expired_messages_are_dropped_not_sent_late():
    port = free_port(socket.SOCK_STREAM)
    pub = OscTcpPublisher(HOST, port, max_age_s=0.05, backoff_s=(0.02, 0.05))
    srv = None
    try:
        pub.publish_cut(make_cut(event=1))
        time.sleep(0.15)
        srv = SlipServer(port)
        pub.publish_status(StatusEvent(1, 50.0, 0, 0))
        msgs = srv.messages(1)
        time.sleep(0.1)
        assert [m.address for m in srv.messages(1)] == ["/rtseg/status"]
        assert pub.stats.dropped == 2        # the two messages of the late cut
        assert len(msgs) == 1
    finally:
        pub.close()
        if srv:
            srv.close()


def test_tcp_reconnects_after_the_receiver_closes():
    srv = SlipServer(close_first=True)
    pub = OscTcpPublisher(HOST, srv.port, backoff_s=(0.02, 0.05))
    try:
        deadline = time.monotonic() + 3
        while srv.connections < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        while not pub.connected and time.monotonic() < deadline:
            time.sleep(0.01)
        pub.publish_dropout(DropoutEvent("Hips", True))
        msgs = srv.messages(1)
    finally:
        pub.close()
        srv.close()
    assert msgs[-1].params == ["Hips", 1]
    assert pub.stats.reconnects >= 2


def test_tcp_close_drops_and_counts_unsent():
    port = free_port(socket.SOCK_STREAM)
    pub = OscTcpPublisher(HOST, port, linger_s=0.05, backoff_s=(0.02, 0.05))
    pub.publish_status(StatusEvent())
    pub.close()
    assert not pub._thread.is_alive()
    assert pub.stats.dropped == 1 and pub.stats.sent == 0
    pub.publish_status(StatusEvent())        # after close: counted, not raised
    assert pub.stats.dropped == 2


# -- JSON lines ------------------------------------------------------------------------------

def test_jsonl_file_one_object_per_event(tmp_path):
    path = tmp_path / "events.jsonl"
    pub = JsonlPublisher(str(path))
    pub.publish_cut(make_cut(confidence=np.float32(0.5), score=float("nan")))
    assert path.read_text().count("\n") == 1           # flushed per line
    pub.publish_status(StatusEvent(1, 99.0, 4, 1, stale_names=("LeftHand",)))
    pub.publish_dropout(DropoutEvent("LeftHand", True, time=1.25))
    pub.close()
    objs = [json.loads(line) for line in path.read_text().splitlines()]
    assert [o["type"] for o in objs] == ["cut", "status", "dropout"]
    assert objs[0]["confidence"] == 0.5 and objs[0]["score"] is None and objs[0]["label"] == "walk"
    assert objs[1]["stale_names"] == ["LeftHand"] and objs[1]["dropped"] == 4
    assert objs[2] == {**objs[2], "name": "LeftHand", "lost": True, "time": 1.25}
    back = event_from_dict(objs[0])
    assert isinstance(back, CutEvent) and back.frame == 412 and math.isnan(back.score)


def test_jsonl_file_in_a_missing_folder(tmp_path):
    """The folder is made (as ``--record`` and ``segment --out`` do); a file standing where
    the folder should be is a clear error naming the target."""
    path = tmp_path / "a" / "b" / "events.jsonl"
    pub = JsonlPublisher(str(path))
    pub.publish_dropout(DropoutEvent("Head", True))
    pub.close()
    assert json.loads(path.read_text())["name"] == "Head"
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValueError, match=r"jsonl:.*f/events.jsonl: cannot open"):
        JsonlPublisher(str(tmp_path / "f" / "events.jsonl"))


def test_jsonl_stdout(capsys):
    pub = parse_target("-")
    pub.publish_dropout(DropoutEvent("Head", False))
    pub.close()
    obj = json.loads(capsys.readouterr().out)
    assert obj["type"] == "dropout" and obj["lost"] is False


def test_jsonl_write_error_is_counted(monkeypatch):
    broken = io.StringIO()
    broken.close()
    monkeypatch.setattr("sys.stdout", broken)
    pub = JsonlPublisher("-")
    pub.publish_status(StatusEvent())
    assert pub.stats.errors == 1 and pub.stats.dropped == 1


# -- target specs and fan-out ----------------------------------------------------------------

@pytest.mark.parametrize("spec, cls, host, port", [
    ("udp:127.0.0.1:9123", OscUdpPublisher, "127.0.0.1", 9123),
    ("127.0.0.1:9124", OscUdpPublisher, "127.0.0.1", 9124),
    ("9125", OscUdpPublisher, "127.0.0.1", 9125),
    ("osc.udp://127.0.0.1:9126/", OscUdpPublisher, "127.0.0.1", 9126),
    ("tcp:127.0.0.1:53000,queue=10,max_age=1.5", OscTcpPublisher, "127.0.0.1", 53000),
])
def test_parse_target_osc(spec, cls, host, port):
    pub = parse_target(spec)
    try:
        assert type(pub) is cls and (pub.host, pub.port) == (host, port)
    finally:
        pub.close()


def test_parse_target_jsonl(tmp_path):
    p = parse_target(f"jsonl:{tmp_path / 'x.jsonl'}")
    p.close()
    assert isinstance(p, JsonlPublisher) and p.path.endswith("x.jsonl")
    assert isinstance(parse_target("jsonl:-"), JsonlPublisher)


@pytest.mark.parametrize("spec, why", [
    ("udp:127.0.0.1", "HOST:PORT"),
    ("udp:127.0.0.1:70000", "not in 1..65535"),
    ("ftp:127.0.0.1:21", "unknown scheme"),
    ("udp:127.0.0.1:9123,foo=1", "unknown option 'foo'"),
    ("udp:127.0.0.1:9123,queue=5", "unknown option 'queue'"),
    ("tcp:127.0.0.1:9123,queue=x", "bad queue"),
    ("udp:127.0.0.1:9123,standard=off", "nothing to send"),
    ("udp:127.0.0.1:9123,template=/a/{x}", "unknown field"),
    ("jsonl:", "needs a path"),
    ("", "empty"),
])
def test_parse_target_errors_name_the_target(spec, why):
    with pytest.raises(ValueError, match=why) as ei:
        parse_target(spec)
    assert repr(spec) in str(ei.value)


def test_jsonl_target_refuses_templates():
    with pytest.raises(ValueError, match="OSC targets only"):
        parse_target("-", templates=["/a"])


class Exploding(Publisher):
    target = "boom"

    def publish_cut(self, ev):
        raise RuntimeError("boom")

    publish_status = publish_dropout = publish_cut


def test_publisher_set_isolates_failures(receiver, tmp_path):
    path = tmp_path / "out.jsonl"
    pubs = PublisherSet([Exploding(), OscUdpPublisher(HOST, receiver.port), JsonlPublisher(str(path))])
    with pubs:
        sent = pubs.publish_cut(make_cut(latency_ms=None, boundary_recv_time=time.monotonic()))
        pubs.publish_status(StatusEvent())
        got = receiver.take(3)
    assert sent.latency_ms is not None and sent.latency_ms >= 0
    assert [g[0] for g in got] == ["/rtseg/cut", "/rtseg/cut/walk", "/rtseg/status"]
    assert got[0][1][4] == pytest.approx(sent.latency_ms, abs=1e-3)   # one stamp for all
    st = pubs.stats()
    assert st["boom"]["failures"] == 2
    assert st[f"udp:{HOST}:{receiver.port}"]["sent"] == 3
    lines = path.read_text().splitlines()
    assert json.loads(lines[0])["latency_ms"] == pytest.approx(sent.latency_ms)


def test_publisher_set_from_specs_closes_made_publishers_on_error():
    with pytest.raises(ValueError, match="bad-one"):
        PublisherSet.from_specs(["tcp:127.0.0.1:9", "bad-one"])
    assert not any(t.name == "rtseg-osc-tcp" for t in threading.enumerate())


def test_publisher_set_adds_templates_to_osc_targets_only(tmp_path):
    pubs = PublisherSet.from_specs(["udp:127.0.0.1:9123", f"jsonl:{tmp_path / 'a'}"],
                                   templates=["/cue/{label}/start"])
    try:
        assert [t.spec for t in pubs.publishers[0].templates] == ["/cue/{label}/start"]
        assert len(pubs) == 2
    finally:
        pubs.close()


def test_slip_encode_escapes():
    assert slip_encode(b"a\xc0b\xdbc") == b"\xc0a\xdb\xdcb\xdb\xddc\xc0"
    assert slip_frames(slip_encode(b"\xc0\xdb\xdb\xc0")) == [b"\xc0\xdb\xdb\xc0"]


def test_slip_decoder_and_message_decoder_on_chunked_stream():
    from rtseg.publishers.osc.message import SlipDecoder, decode_message
    pkts = [encode_message("/rtseg/cut", "iiffffs", [192, 219, -2.0, 0.5, 1.0, 2.0, "kick"]),
            encode_message("/rtseg/dropout", "si", ["Head", 1])]
    stream = b"".join(slip_encode(p) for p in pkts)
    dec, got = SlipDecoder(), []
    for i in range(0, len(stream), 3):           # arbitrary chunk boundaries
        got += dec.feed(stream[i:i + 3])
    assert got == pkts and dec.errors == 0
    assert decode_message(got[0]) == ("/rtseg/cut", "iiffffs", [192, 219, -2.0, 0.5, 1.0, 2.0, "kick"])
    assert decode_message(got[1]) == ("/rtseg/dropout", "si", ["Head", 1])
    with pytest.raises(ValueError):
        decode_message(got[0][:-6])


def test_a_target_with_its_own_templates_does_not_also_fire_the_session_ones():
    """--template goes to the OSC targets without a template= of their own: a QLab target
    given its own cue address fires each cue once, not once per template list."""
    from rtseg.publishers import parse_target
    own = parse_target("udp:127.0.0.1:53000,standard=off,template=/cue/{label}/start segment",
                       ["/cue/{label}/start"])
    plain = parse_target("udp:127.0.0.1:53001", ["/cue/{label}/start"])
    try:
        assert [t.spec for t in own.templates] == ["/cue/{label}/start segment"]
        assert [t.spec for t in plain.templates] == ["/cue/{label}/start"]
    finally:
        own.close()
        plain.close()


@pytest.mark.parametrize("source, address", [("", "/cue/walk/start"),
                                             ("alice", "/cue/alice/walk/start")])
def test_an_empty_source_field_drops_out_of_the_address(source, address):
    """{source} of a session on its own is "": the address must not get '//' (an OSC 1.1
    path wildcard), so the empty part and its slash drop out."""
    ev = make_cut(label="walk", source=source)
    assert AddressTemplate("/cue/{source}/{label}/start").render(ev)[0] == address


def test_one_jsonl_destination_given_twice_is_written_once(tmp_path, caplog):
    import logging
    from rtseg.live.config import from_dict
    from rtseg.live.outputs import build_publishers
    path = tmp_path / "events.jsonl"
    cfg = from_dict({"output": {"osc": [], "jsonl": str(path),
                                "targets": [f"jsonl:{path}", "-", "jsonl:-"]}})
    with caplog.at_level(logging.WARNING, logger="rtseg"):
        pubs = build_publishers(cfg)
    try:
        assert len(pubs) == 2                     # the file once, standard output once
        assert sum("written once" in r.getMessage() for r in caplog.records) == 2
    finally:
        pubs.close()
