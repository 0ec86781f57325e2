"""A serial suit read in the wrong format is never silent.

A suit printing text lines (``id,w,x,y,z[,status]``) on a URL without ``format=`` is
detected and read as text; with an explicit ``format=rtseg`` it never switches, and the
bytes that form no frame are counted (``corrupt``, ``skipped_bytes``: the session's
``bad input`` and ``/rtseg/input``) and named in a rate-limited warning with the hint
``add format=text``.  Binary input after a boot log is read as before.

Real parts: a simulated suit (rtseg.simulators.serial_device) or raw bytes on a real
pseudo-terminal opened by pyserial, and ``rtseg live`` in a subprocess."""

from __future__ import annotations

import json
import logging
import os
import select
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rtseg.core.profiles import suit_profile
from rtseg.core.quat import global_from_local
from rtseg.drivers import open_source
from rtseg.drivers.serial import codec, stream
from rtseg.drivers.serial.text import looks_like_text
from rtseg.simulators.serial_device import SerialSuit
from rtseg.simulators.synth.motion import synthesize

from test_serial_live import collect, make_take, raw_pty, rig  # noqa: F401  (fixtures)

REPO = Path(__file__).resolve().parents[1]
SUIT = suit_profile("default17")
J = len(SUIT.bones)
LOGGER = "rtseg.drivers.serial"
DETECTED = "text lines detected; reading format=text"
TEXT_HINT = "bytes of text lines (id,w,x,y,z) and no rtseg binary frame"


def wait_for(cond, timeout: float = 5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def messages(caplog, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.name == LOGGER and text in r.getMessage()]


# --------------------------------------------------------------------------- the detector


def test_looks_like_text_tells_text_lines_from_binary_and_boot_logs():
    ids = np.array(SUIT.sensor_ids)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
    text = codec.encode_text_frame(ids, q) * 3
    assert looks_like_text(text)
    # a boot banner before the records is tolerated; a boot log alone is not text
    boot = (b"rst:0x1 (POWERON_RESET),boot:0x13 (SPI_FAST_FLASH_BOOT)\r\n"
            b"I (31) boot: ESP-IDF v4.4\r\n")
    assert looks_like_text(b"x\n" + boot + text)
    assert not looks_like_text(boot * 40)
    # binary frames (and any text with a zero byte in it) are never text
    wire = b"".join(codec.encode_frame(k, k * 8333, ids, q) for k in range(10))
    assert not looks_like_text(wire)
    assert not looks_like_text(text[:500] + b"\x00" + text[500:])
    # spaces around fields and \r\n endings, as the text decoder accepts them
    assert looks_like_text(b"\n" + b" 3 , 0.5, 0.5 ,0.5,0.5\r\n" * 10)


# --------------------------------------------------------------------------- through a pty


def test_text_suit_on_a_url_without_format_gives_every_frame(rig, caplog):
    """QA's case: a text suit read with the URL's default format.  The source detects the
    text lines, says so once, and gives every frame, as ``format=text`` would."""
    caplog.set_level(logging.INFO, logger=LOGGER)
    take = make_take(240)
    suit, src = rig(take, rate=400.0, fmt="text")
    assert src.fmt == "rtseg"                    # binary until text lines arrive
    suit.begin()
    frames = collect(src, lambda fr, idle: suit.wait_done(0) and len(fr) >= 240)
    frames += collect(src, lambda fr, idle: idle, timeout=0.5)   # nothing more comes
    assert src.fmt == "text"
    assert len(frames) == 240
    expect = global_from_local(take.quats, take.parents)
    np.testing.assert_allclose(np.stack([f.quats for f in frames]), expect, atol=2e-6)
    assert all(f.seq is None and f.valid.all() for f in frames)
    st = src.stats
    assert (st.corrupt, st.bad_messages, st.bad_values, st.dropped) == (0, 0, 0, 0)
    assert len(messages(caplog, DETECTED)) == 1
    assert not messages(caplog, "no rtseg binary frame")


def test_text_detected_by_the_polled_reading_too(rig, caplog):
    """The live loop reads the port by polls (``take_over``): the same detection."""
    caplog.set_level(logging.WARNING, logger=LOGGER)
    take = make_take(120)
    suit, src = rig(take, rate=400.0, fmt="text")
    assert src.take_over() is True
    suit.begin()
    frames: list = []
    end = time.monotonic() + 10
    while time.monotonic() < end and not (suit.wait_done(0) and len(frames) >= 120):
        p = select.poll()
        for fd in src.poll_fds():
            p.register(fd, select.POLLIN)
        p.poll(20)
        src.poll(time.monotonic())
        src.take(frames)
    assert src.fmt == "text" and len(frames) == 120
    assert len(messages(caplog, DETECTED)) == 1 and src.stats.corrupt == 0


def test_explicit_rtseg_never_switches_and_counts_and_names_the_text(rig, caplog):
    """``format=rtseg`` with a text suit: no frame, never text; the bytes are counted in
    ``corrupt`` (one per run too long for a message) and ``skipped_bytes``, and one
    warning (rate limited) says the suit sends text lines and how to read them."""
    caplog.set_level(logging.INFO, logger=LOGGER)
    take = make_take(240)
    suit, src = rig(take, "format=rtseg", rate=400.0, fmt="text")
    suit.begin()
    assert suit.wait_done(5.0)
    assert all(m.fate == "intact" for m in suit.sent_log)
    sent = sum(len(codec.encode_text_frame(np.array(m.sensor_ids), suit.quats[m.frame],
                                           suit.status)) for m in suit.sent_log)
    assert sent > 150_000
    # every byte but those still waiting for a delimiter (at most a message's worth)
    assert wait_for(lambda: src.skipped_bytes >= sent - codec.MAX_WIRE_BYTES)
    frames = collect(src, lambda fr, idle: idle, timeout=0.5)
    assert frames == [] and src.fmt == "rtseg"
    assert src.skipped_bytes <= sent
    # one corrupt per discarded run: longer than a message, at most a message and a read
    skipped = src.skipped_bytes
    assert skipped // (2 * codec.MAX_WIRE_BYTES + 8192) <= src.stats.corrupt
    assert src.stats.corrupt <= skipped // (codec.MAX_WIRE_BYTES + 1)
    assert not messages(caplog, DETECTED)
    warned = messages(caplog, TEXT_HINT)
    assert len(warned) == 1, warned               # rate limited: once per 5 s
    assert "add format=text to the URL" in warned[0]


def test_garbage_without_delimiters_is_counted_and_named(raw_pty, caplog):
    """Bytes that are neither frames nor text lines (a wrong baud rate) on a URL without
    ``format=``: no switch to text, counted, and the warning says no delimiter came."""
    caplog.set_level(logging.WARNING, logger=LOGGER)
    master, path = raw_pty
    src = open_source(f"serial://{path}")
    try:
        rng = np.random.default_rng(5)
        junk = rng.integers(1, 256, 12_000, dtype=np.uint8).tobytes()   # no zero byte
        for a in range(0, len(junk), 1000):
            os.write(master, junk[a:a + 1000])
        assert wait_for(lambda: src.skipped_bytes >= 2 * codec.MAX_WIRE_BYTES)
        assert wait_for(lambda: messages(caplog, "without a frame delimiter (0x00)"))
        assert src.fmt == "rtseg" and src.stats.frames_ok == 0
        assert 2 <= src.stats.corrupt <= src.skipped_bytes // (codec.MAX_WIRE_BYTES + 1)
        warned = messages(caplog, "without a frame delimiter (0x00)")
        assert len(warned) == 1 and "format=text" in warned[0]
        assert not messages(caplog, DETECTED) and not messages(caplog, TEXT_HINT)
    finally:
        src.close()


@pytest.mark.parametrize("boot_lines", [2, 40])
def test_binary_after_a_boot_log_is_read_as_before(raw_pty, caplog, boot_lines):
    """A board printing a boot log (short, or longer than a message can be) and then rtseg
    frames, on a URL without ``format=``: every frame, no switch, no warning; a boot log
    too long for a message counts one corrupt run but, once a frame arrives, no dropped
    frame."""
    caplog.set_level(logging.WARNING, logger=LOGGER)
    master, path = raw_pty
    src = open_source(f"serial://{path}?stale=5")
    try:
        line = b"I (31) boot: ESP-IDF v4.4 2nd stage bootloader, compile time 12:00:00\r\n"
        boot = line * boot_lines
        assert (len(boot) > codec.MAX_WIRE_BYTES) == (boot_lines > 2)
        ids = np.array(SUIT.sensor_ids)
        q = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
        wire = b"".join(codec.encode_frame(k, k * 8333, ids, q) for k in range(30))
        for data in (boot, wire):
            for a in range(0, len(data), 1024):
                os.write(master, data[a:a + 1024])
            time.sleep(0.05)
        frames = collect(src, lambda fr, idle: len(fr) >= 30, timeout=5.0)
        assert [f.seq for f in frames] == list(range(30))
        assert src.fmt == "rtseg"
        long_boot = len(boot) > codec.MAX_WIRE_BYTES
        assert src.stats.corrupt == (1 if long_boot else 0)
        assert src.stats.dropped == 0 and src.stats.gaps == 0
        assert src.skipped_bytes == len(boot)
        assert not messages(caplog, DETECTED) and not messages(caplog, "no rtseg binary")
        assert not messages(caplog, "no intact rtseg")
    finally:
        src.close()


def test_text_after_binary_frames_does_not_switch(raw_pty, caplog):
    """Once an intact binary frame has arrived the format is settled: text lines after it
    are garbage of a binary link (counted and named), not a reason to switch."""
    caplog.set_level(logging.WARNING, logger=LOGGER)
    master, path = raw_pty
    src = open_source(f"serial://{path}")
    try:
        ids = np.array(SUIT.sensor_ids)
        q = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
        os.write(master, codec.encode_frame(0, 0, ids, q))
        assert len(collect(src, lambda fr, idle: len(fr) >= 1, timeout=3.0)) == 1
        text = codec.encode_text_frame(ids, q) * 12
        for a in range(0, len(text), 1024):
            os.write(master, text[a:a + 1024])
        assert wait_for(lambda: messages(caplog, TEXT_HINT))
        assert src.fmt == "rtseg" and src.stats.corrupt >= 1
        assert not messages(caplog, DETECTED)
    finally:
        src.close()


def test_rate_limited_warning_is_not_repeated_within_its_interval():
    """The stream warns at most once per 5 s however many bytes keep coming."""
    counts: dict[str, int] = {}
    s = stream.SuitStream(SUIT, "rtseg", 120.0, 0.25,
                          lambda k, n=1: counts.__setitem__(k, counts.get(k, 0) + n),
                          lambda f: None, "test")
    records = []
    handler = logging.Handler()
    handler.emit = records.append
    lg = logging.getLogger(LOGGER)
    lg.addHandler(handler)
    try:
        text = codec.encode_text_frame(np.array(SUIT.sensor_ids),
                                       np.tile([0.0, 0.0, 0.0, 1.0], (J, 1)))
        for k in range(200):                      # ~137 KB: 33 warning thresholds
            s.consume(text, 1.0 + k / 120)
    finally:
        lg.removeHandler(handler)
    hints = [r for r in records if TEXT_HINT in r.getMessage()]
    assert len(hints) == 1
    total = 200 * len(text)
    assert total > 30 * stream.NO_FRAME_WARN_BYTES
    assert s.fmt == "rtseg" and total - codec.MAX_WIRE_BYTES <= s.skipped_bytes <= total
    # fed one frame's text at a time: each run discarded is longer than a message, by
    # less than one feed
    skipped = s.skipped_bytes
    assert skipped // (codec.MAX_WIRE_BYTES + len(text)) <= counts["corrupt"]
    assert counts["corrupt"] <= skipped // (codec.MAX_WIRE_BYTES + 1)


# --------------------------------------------------------------------------- rtseg live


def run_live(url: str, tmp_path: Path, duration: float = 3.0) -> tuple[str, list[dict]]:
    """``rtseg live URL`` for ``duration`` s against a looping text suit; its stderr and
    the JSON lines it wrote."""
    take = synthesize("idle:2,walk:2", frame_rate=120.0, seed=1).take
    suit = SerialSuit(take, rate=120.0, fmt="text", loop=True)
    jsonl = tmp_path / "events.jsonl"
    try:
        path = suit.start()
        proc = subprocess.run(
            [sys.executable, "-m", "rtseg.cli", "live", url.format(path=path), "--no-osc",
             "--duration", f"{duration:g}", "--jsonl", str(jsonl)],
            capture_output=True, text=True, timeout=60, cwd=REPO)
    finally:
        suit.stop()
    assert proc.returncode == 0, proc.stderr
    events = [json.loads(ln) for ln in jsonl.read_text().splitlines() if ln.strip()]
    return proc.stderr, events


def summary_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith("session ended")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.slow
def test_rtseg_live_reads_a_text_suit_without_format(tmp_path):
    err, _ = run_live("serial://{path}", tmp_path)
    line = summary_line(err)
    received = int(line.split(" frames received")[0].rsplit(" ", 1)[1])
    assert received > 200, line                  # ~3 s at 120 Hz
    assert "bad input: 0 corrupt" in line
    assert err.count(DETECTED) == 1


@pytest.mark.slow
def test_rtseg_live_with_format_rtseg_reports_the_text_as_bad_input(tmp_path):
    err, events = run_live("serial://{path}?format=rtseg", tmp_path)
    line = summary_line(err)
    assert " 0 frames received" in line
    corrupt = int(line.split("bad input: ")[1].split(" corrupt")[0])
    assert corrupt > 0, line                     # no longer "0 corrupt": the QA bug
    assert TEXT_HINT in err and "add format=text to the URL" in err
    assert DETECTED not in err
    status = [e for e in events if e.get("type") == "status"]
    assert status and status[-1]["corrupt"] == corrupt   # what /rtseg/input carries
