"""Counters that hide nothing, through real sockets and a real pty: senders refused by
``allow=`` are in the summary, every status line (JSON lines, the recording's
events.jsonl) and session.json; frames destroyed by damaged serial bytes count as dropped
and the console says damaged messages arrive; the summary's processing latency is over
every frame processed, not only the frames that revealed a cut."""

from __future__ import annotations

import io
import json
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from rtseg.commands.live import Console
from rtseg.drivers import open_source
from rtseg.drivers.osc.vmc.codec import encode_frame
from rtseg.core.events import StatusEvent
from rtseg.live.session import LiveSession
from rtseg.recording import read_session
from rtseg.live.config import from_dict
from rtseg.simulators.serial_device import SerialSuit
from rtseg.simulators.synth.motion import synthesize

from tests.test_vmc_live import SUIT, make_take


class Terminal(io.StringIO):
    """Captures what the console writes to a terminal (the status line rewritten)."""

    def isatty(self) -> bool:
        return True


def config(tmp_path: Path, **extra) -> object:
    return from_dict({"output": {"osc": [], "jsonl": str(tmp_path / "events.jsonl")},
                      "recording": {"dir": str(tmp_path / "rec")},
                      "status": {"interval": 0.2}, **extra}, origin="test")


def status_lines(tmp_path: Path) -> list[dict]:
    lines = [json.loads(ln) for ln in (tmp_path / "events.jsonl").read_text().splitlines()]
    return [d for d in lines if d["type"] == "status"]


def test_senders_refused_by_allow_are_counted_everywhere(tmp_path):
    src = open_source("osc://127.0.0.1:0?format=vmc&suit=default17&allow=127.0.0.2"
                      "&quiet=0.02&queue=4096")
    take = make_take(120, seed=3)
    session = LiveSession(src, config(tmp_path), handle_signals=False, duration=2.5)
    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("s", session.run()), daemon=True)
    t.start()
    addr = ("127.0.0.1", src.port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as good, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as bad:
        good.bind(("127.0.0.2", 0))
        bad.bind(("127.0.0.3", 0))
        time.sleep(0.3)
        for i in range(120):
            q = take.quats[i]
            good.sendto(encode_frame(q, SUIT, time=i / 60.0, max_datagram=60000)[0], addr)
            bad.sendto(encode_frame(q, SUIT, time=i / 60.0, max_datagram=60000)[0], addr)
            time.sleep(1 / 60.0)
    t.join(10)
    summary = box["s"]
    refused = src.stats.refused_senders
    assert refused == 120 and summary.frames_received >= 100
    assert f"{refused} refused by allow=" in summary.text()
    # every status line carries the count, rising to the total
    st = status_lines(tmp_path)
    counts = [d["refused_senders"] for d in st]
    assert counts == sorted(counts) and counts[-1] == refused and counts[0] < refused
    rec = read_session(tmp_path / "rec")
    rec_st = [e for e in rec.meta["events"] if e.get("type") == "status"]
    assert rec_st[-1]["refused_senders"] == refused
    header = json.loads((tmp_path / "rec" / "session.json").read_text())
    assert header["session"]["refused_senders"] == refused
    assert header["session"]["other_senders"] == 0
    # the console status line says so too
    out = io.StringIO()
    Console(out=out, err=out).show_status(StatusEvent(**{k: v for k, v in st[-1].items()
                                                         if k not in ("type", "stale_names")}))
    assert f"{refused} refused by allow=" in out.getvalue()


def test_frames_destroyed_by_damaged_bytes_are_dropped_not_hidden(tmp_path):
    """10 % of the bytes damaged: a 17-sensor frame (about 185 bytes) practically never
    arrives whole.  The status must not read '0 dropped': every destroyed frame counts."""
    take = synthesize(frame_rate=120.0).take
    suit = SerialSuit(take, rate=120.0, faults="corrupt=0.1,seed=4", loop=True)
    suit.start(send=False)
    try:
        session = LiveSession(f"serial://{suit.path}?rate=120", config(tmp_path),
                              handle_signals=False, duration=2.5)
        box: dict = {}
        t = threading.Thread(target=lambda: box.setdefault("s", session.run()), daemon=True)
        t.start()
        time.sleep(0.3)
        suit.begin()
        t.join(15)
    finally:
        suit.stop()
    summary = box["s"]
    sent = [m for m in suit.sent_log]
    damaged = [m for m in sent if m.fate == "corrupted"]
    assert len(damaged) >= 0.95 * len(sent) and len(sent) > 150
    # what arrived: (almost) no frame; what was destroyed: (about) every one sent
    assert summary.frames_received <= 0.05 * len(sent)
    assert summary.dropped >= 0.5 * len(damaged)
    assert summary.dropped <= 2 * len(sent)
    st = status_lines(tmp_path)
    alive = [d for d in st if d["alive"]]
    assert alive[-1]["dropped"] > 0 and alive[-1]["dropped"] >= alive[0]["dropped"]
    # the console line says damaged messages arrive next to the 0 fps of intact frames
    out = Terminal()
    con = Console(out=out, err=out)
    for d in alive[-2:]:
        con.show_status(StatusEvent(**{k: v for k, v in d.items()
                                       if k not in ("type", "stale_names")}))
    line = out.getvalue().split("\r\033[K")[-1]
    assert "/s corrupt)" in line and f"| {alive[-1]['dropped']} dropped" in line
    rate = float(line.split("(+")[1].split("/s corrupt")[0])
    assert 30 < rate < 400        # about 120 damaged messages a second


def test_summary_latency_is_over_every_frame_processed():
    cfg = from_dict({"output": {"osc": []}}, origin="test")
    session = LiveSession("sim://synth?script=idle:3,walk:3&seed=2&speed=4", cfg,
                          handle_signals=False)
    summary = session.run()
    lat = session.stats.frame_latency_ms.values()
    assert summary.latency_frames == summary.frames_processed == len(lat) == 720
    assert summary.latency_ms_p99 == pytest.approx(float(np.percentile(lat, 99)))
    assert summary.latency_ms_p50 == pytest.approx(float(np.percentile(lat, 50)))
    assert f"(p50/p99 over {summary.frames_processed} frames" in summary.text()
    cues = session.stats.cut_latency_ms.values()
    assert len(cues) == summary.cuts < summary.frames_processed
    # and over the frames that could send (the detector looks once per 15 frames)
    could = session.stats.open_latency_ms.values()
    assert 0 < summary.open_latency_frames == len(could) < summary.frames_processed / 5
    assert summary.open_latency_ms_p99 == pytest.approx(float(np.percentile(could, 99)))
    assert f"; {len(could)} that could send {summary.open_latency_ms_p50:.2f}/" in \
        summary.text()
