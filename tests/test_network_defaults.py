"""Safe network defaults: the OSC sources listen on loopback unless an
address is written, ``allow=`` restricts senders (refused datagrams counted and logged once
per sender), and a UDP target with nothing listening is warned about once.  Real UDP
sockets, all on 127.0.0.0/8."""

from __future__ import annotations

import logging
import socket
import time

import numpy as np
import pytest

from rtseg.drivers import SourceError, open_source
from rtseg.drivers.osc.vmc.codec import encode_frame
from rtseg.drivers.osc.url import (DEFAULT_HOST, is_wide, parse_allow, parse_location,
                                   sender_allowed)
from rtseg.core.events import StatusEvent
from rtseg.publishers.osc.udp import OscUdpPublisher

BONES = ["Hips", "Spine", "Head"]


@pytest.mark.parametrize("url, port", [("osc://", 39539), ("osc://:0", 0),
                                       ("osc://?format=vrchat", 9000), ("osc://:0?format=vrchat", 0)])
def test_no_address_means_loopback(url, port):
    host, p = parse_location(url[len("osc://"):].split("?")[0],
                              9000 if "vrchat" in url else 39539)
    assert (host, p) == ("127.0.0.1", port)
    if port == 0:                      # really bound: on loopback only
        src = open_source(url)
        try:
            assert src._sock.getsockname()[0] == "127.0.0.1" == DEFAULT_HOST
        finally:
            src.close()


def test_wide_addresses_only_when_written():
    assert parse_location("0.0.0.0:39539", 39539) == ("0.0.0.0", 39539)
    assert parse_location("[::]:39539", 39539) == ("::", 39539)
    assert is_wide("0.0.0.0") and is_wide("::") and is_wide("192.168.1.4")
    assert not is_wide("127.0.0.1") and not is_wide("::1") and not is_wide("localhost")


def test_allow_parsing():
    nets = parse_allow("192.168.1.20, 10.0.0.0/24,::1")
    assert [str(n) for n in nets] == ["192.168.1.20/32", "10.0.0.0/24", "::1/128"]
    assert sender_allowed("10.0.0.77", nets) and sender_allowed("192.168.1.20", nets)
    assert not sender_allowed("192.168.1.21", nets) and not sender_allowed("10.0.1.1", nets)
    assert sender_allowed("::ffff:10.0.0.5", nets)           # IPv4-mapped
    assert sender_allowed("::1", nets) and not sender_allowed("::2", nets)
    assert sender_allowed("1.2.3.4", None)
    for bad in ("", ",", "10.0.0.0/33", "host.example", "1.2.3"):
        with pytest.raises(SourceError, match="allow="):
            parse_allow(bad)
    with pytest.raises(SourceError, match="allow="):
        open_source("osc://127.0.0.1:0?allow=nonsense")


def _sender(addr: str) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((addr, 0))
    return s


def _frames(src, n: int, timeout: float = 2.0) -> list:
    got, end = [], time.monotonic() + timeout
    while len(got) < n and time.monotonic() < end:
        f = src.read(timeout=0.05)
        if f is not None:
            got.append(f)
    return got


@pytest.mark.parametrize("fmt", ["vmc"])
def test_allow_drops_other_senders_counts_and_logs_once(caplog, fmt):
    src = open_source(f"osc://127.0.0.1:0?format={fmt}&allow=127.0.0.2&quiet=0.01")
    good, bad = _sender("127.0.0.2"), _sender("127.0.0.3")
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(src.joint_names), 1))
    try:
        with caplog.at_level(logging.WARNING, logger="rtseg.drivers.osc"):
            for k in range(5):
                for dgram in encode_frame(q, src.joint_names, time=k / 60):
                    bad.sendto(dgram, ("127.0.0.1", src.port))
                time.sleep(0.03)
            time.sleep(0.1)
            assert _frames(src, 1, timeout=0.3) == []          # nothing from 127.0.0.3
            n_bad = src.stats.refused_senders
            assert n_bad >= 5
            for k in range(5):
                for dgram in encode_frame(q, src.joint_names, time=k / 60):
                    good.sendto(dgram, ("127.0.0.1", src.port))
                time.sleep(0.03)
            got = _frames(src, 5)
        assert len(got) == 5
        assert src.stats.refused_senders == n_bad                # the allowed one not counted
        assert src.stats.as_dict()["refused_senders"] == n_bad   # in the stats dict
        refusals = [r for r in caplog.records if "refused" in r.getMessage()]
        assert len(refusals) == 1 and "127.0.0.3" in refusals[0].getMessage()
    finally:
        good.close()
        bad.close()
        src.close()


def test_vrchat_accepts_allow():
    src = open_source("osc://127.0.0.1:0?format=vrchat&allow=127.0.0.0/8")
    try:
        assert [str(n) for n in src.allow] == ["127.0.0.0/8"]
    finally:
        src.close()


def _free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def test_udp_target_without_receiver_is_warned_once_per_outage(caplog):
    port = _free_udp_port()
    pub = OscUdpPublisher("127.0.0.1", port)
    st = StatusEvent(alive=1, frame_rate=120.0, dropped=0, stale_joints=0, time=1.0)
    try:
        with caplog.at_level(logging.INFO, logger="rtseg.publishers"):
            for _ in range(30):
                pub.publish_status(st)
            warned = [r for r in caplog.records if "nothing listening" in r.getMessage()]
            assert len(warned) == 1
            assert pub.stats.refused >= 10
            rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)   # a receiver starts
            rx.bind(("127.0.0.1", port))
            for _ in range(5):
                pub.publish_status(st)
            rx.close()                                              # and goes away again
            for _ in range(5):
                pub.publish_status(st)
            assert any("listening again" in r.getMessage() for r in caplog.records)
            warned = [r for r in caplog.records if "nothing listening" in r.getMessage()]
            assert len(warned) == 2
    finally:
        pub.close()
