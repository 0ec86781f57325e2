"""Session recording: round trip, buffering, torn/corrupt records, a SIGKILL mid-session."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from rtseg.core.events import CutEvent, DropoutEvent, StatusEvent
from rtseg.core.frame import Frame
from rtseg.recording import (FRAMES_FILE, RecorderLogHandler, SessionRecorder, is_session_dir,
                             read_session, read_session_cuts, record_dtype)

NAMES = ["Hips", "Spine", "Head", "LeftHand", "RightHand", "LeftFoot", "RightFoot", "Chest",
         "Neck"]                       # 9 joints: valid bits span two bytes
PARENTS = [-1, 0, 7, 7, 7, 0, 0, 1, 7]


def random_frames(n: int, seed: int = 0, t0: float = 1000.0, dt: float = 0.01):
    rng = np.random.default_rng(seed)
    J = len(NAMES)
    frames = []
    for i in range(n):
        q = rng.normal(size=(J, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        valid = rng.random(J) > 0.2
        frames.append(Frame(
            recv_time=t0 + i * dt + rng.uniform(0, 0.002), quats=q, valid=valid,
            source_time=None if i % 7 == 3 else i * dt,
            seq=None if i % 5 == 4 else i,
            root_position=None if i < 2 else rng.normal(size=3)))
    return frames


def record(path, frames, **kw):
    rec = SessionRecorder(path, NAMES, PARENTS, space="global", frame_rate=kw.pop("frame_rate", 100.0),
                          meta={"source": "sim://test", "n": np.int64(3)},
                          start_monotonic=kw.pop("start_monotonic", 999.0), **kw)
    for f in frames:
        rec.record_frame(f)
    return rec


def test_round_trip_exact(tmp_path):
    frames = random_frames(250)
    d = tmp_path / "s1"
    rec = record(d, frames)
    rec.record_cut(CutEvent(event=1, segment=1, frame=120, time=0.2, method="pca",
                            confidence=np.float32(0.5), latency_ms=15.0))
    rec.record_event(StatusEvent(1, 99.0, 2, 1, stale_names=("Head",), time=1.0))
    rec.record_event(DropoutEvent("Head", True, time=1.1))
    before = time.monotonic()
    rec.record_log("calibrated", level="info")
    after = time.monotonic()
    rec.close()

    assert is_session_dir(d)
    tk = read_session(d)
    assert tk.n_frames == 250 and tk.joint_names == NAMES and tk.parents == PARENTS
    assert tk.space == "global" and tk.frame_rate == 100.0
    assert np.array_equal(tk.quats, np.stack([f.quats for f in frames]))
    assert np.array_equal(tk.valid, np.stack([f.valid for f in frames]))
    m = tk.meta
    assert np.array_equal(m["recv_time"], [f.recv_time for f in frames])
    assert np.allclose(m["session_time"], m["recv_time"] - 999.0)
    assert np.array_equal(m["seq"], [-1 if f.seq is None else f.seq for f in frames])
    st = np.array([np.nan if f.source_time is None else f.source_time for f in frames])
    assert np.array_equal(np.isnan(m["source_time"]), np.isnan(st))
    assert np.array_equal(m["source_time"][~np.isnan(st)], st[~np.isnan(st)])
    # root: first two frames had none -> filled with the first known value
    assert np.array_equal(tk.root_position[2:], np.stack([f.root_position for f in frames[2:]]))
    assert np.array_equal(tk.root_position[0], frames[2].root_position)
    assert m["closed_cleanly"] and m["torn_records"] == 0 and m["corrupt_bytes"] == 0
    assert m["session_meta"] == {"source": "sim://test", "n": 3}
    assert [c.frame for c in m["cuts"]] == [120] and m["cuts"][0].confidence == 0.5
    assert [e["type"] for e in m["events"]] == ["status", "dropout", "log"]
    assert m["events"][0]["stale_names"] == ["Head"]
    # a log line without a time gets the session clock: monotonic - start_monotonic (999.0
    # here, so negative on a machine up for less than 999 s - CI's fresh VMs)
    assert m["events"][2]["message"] == "calibrated"
    assert before - 999.0 <= m["events"][2]["time"] <= after - 999.0
    assert read_session_cuts(d)[0].latency_ms == 15.0
    header = json.loads((d / "session.json").read_text())
    assert header["closed"] and header["frames"] == 250 and header["version"] == 1


def test_float32_quats_and_estimated_rate(tmp_path):
    frames = random_frames(100, dt=1 / 60)
    rec = record(tmp_path / "s", frames, quat_dtype="<f4", frame_rate=None)
    rec.close()
    tk = read_session(tmp_path / "s")
    assert tk.quats.dtype == np.float64
    assert np.allclose(tk.quats, np.stack([f.quats for f in frames]), atol=1e-7)
    assert tk.meta["frame_rate_source"] == "estimated"
    assert tk.frame_rate == pytest.approx(60.0, rel=0.1)


def test_frames_are_buffered_not_written_per_frame(tmp_path):
    frames = random_frames(25)
    rec = SessionRecorder(tmp_path / "s", NAMES, PARENTS, flush_interval_s=60, max_buffer_frames=10)
    size = record_dtype(len(NAMES)).itemsize
    path = tmp_path / "s" / FRAMES_FILE
    for f in frames[:9]:
        rec.record_frame(f)
    assert path.stat().st_size == 0
    rec.record_frame(frames[9])
    assert path.stat().st_size == 10 * size
    for f in frames[10:15]:
        rec.record_frame(f)
    rec.poll()                                  # interval not yet passed
    assert path.stat().st_size == 10 * size
    rec.flush_interval_s = 0.01
    time.sleep(0.02)
    rec.poll()
    assert path.stat().st_size == 15 * size
    rec.close()
    assert rec.stats.flushes == 2


def test_torn_final_record_is_ignored_and_counted(tmp_path):
    d = tmp_path / "s"
    record(d, random_frames(30)).close()
    path = d / FRAMES_FILE
    data = path.read_bytes()
    size = record_dtype(len(NAMES)).itemsize
    with open(path, "ab") as fh:
        fh.write(data[:size // 2])              # a record cut short by a kill
    tk = read_session(d)
    assert tk.n_frames == 30 and tk.meta["torn_records"] == 1
    with open(path, "ab") as fh:
        fh.write(b"\0" * (2 * size))            # zero-filled blocks after a power loss
    tk = read_session(d)
    assert tk.n_frames == 30 and tk.meta["torn_records"] >= 1
    assert np.array_equal(tk.meta["seq"][:4], [0, 1, 2, 3])


def test_corrupt_middle_record_is_skipped_and_rest_kept(tmp_path):
    d = tmp_path / "s"
    frames = random_frames(40)
    record(d, frames).close()
    path = d / FRAMES_FILE
    size = record_dtype(len(NAMES)).itemsize
    data = bytearray(path.read_bytes())
    data[10 * size + 50] ^= 0xFF                # damage record 10
    path.write_bytes(bytes(data))
    tk = read_session(d)
    assert tk.n_frames == 39
    assert tk.meta["corrupt_bytes"] == size and tk.meta["torn_records"] == 0
    expect = [f.recv_time for i, f in enumerate(frames) if i != 10]
    assert np.array_equal(tk.meta["recv_time"], expect)


def test_torn_last_jsonl_line(tmp_path):
    d = tmp_path / "s"
    rec = record(d, random_frames(5))
    rec.record_cut(CutEvent(event=1, segment=1, frame=3, time=0.03, method="ppca"))
    rec.close()
    with open(d / "cuts.jsonl", "a") as fh:
        fh.write('{"type": "cut", "event": 2, "seg')
    cuts = read_session_cuts(d)
    assert [(c.event, c.label) for c in cuts] == [(1, "ppca")]
    assert read_session(d).meta["torn_lines"] == 1


def test_unclosed_session_is_read_with_one_warning_saying_what_was_lost(tmp_path, caplog):
    """A recording whose process was killed (``closed: false``, a record cut short at the
    end) reads, and says so once: frames read, the session time they reach, what is lost;
    a cleanly closed one reads without it (``rtseg segment`` printed nothing before)."""
    d = tmp_path / "killed"
    rec = record(d, random_frames(40))
    rec.flush()                                  # what a kill leaves: flushed, never closed
    size = record_dtype(len(NAMES)).itemsize
    with open(d / FRAMES_FILE, "ab") as fh:
        fh.write(b"RTSF" + b"\1" * (size // 3))  # a record cut short by the kill
    with caplog.at_level(logging.WARNING, logger="rtseg.recording"):
        tk = read_session(d)
    assert tk.n_frames == 40 and not tk.meta["closed_cleanly"]
    notes = [r.getMessage() for r in caplog.records if "not closed cleanly" in r.getMessage()]
    assert len(notes) == 1, caplog.text
    t_end = tk.meta["session_time"][-1]
    assert (f"{d} was not closed cleanly" in notes[0] and "40 frames read" in notes[0]
            and f"t={t_end:.2f} s" in notes[0] and "up to 0.5 s of frames" in notes[0]
            and "1 record(s) cut short" in notes[0]), notes[0]
    rec.close()
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtseg.recording"):
        assert read_session(d).meta["closed_cleanly"]
    assert "not closed" not in caplog.text


def test_bad_frames_are_counted_not_raised(tmp_path):
    rec = SessionRecorder(tmp_path / "s", NAMES, PARENTS)
    good = random_frames(1)[0]
    rec.record_frame(Frame(recv_time=1.0, quats=np.zeros((3, 4)), valid=np.ones(3, bool)))
    rec.record_frame(Frame(recv_time=None, quats=good.quats, valid=good.valid))
    rec.record_frame(good)
    rec.close()
    rec.record_frame(good)                      # after close: counted as lost
    assert rec.stats.bad_frames == 2 and rec.stats.lost_frames == 1
    assert read_session(tmp_path / "s").n_frames == 1


def test_write_error_ends_the_recording_and_keeps_file_readable(tmp_path, monkeypatch):
    rec = SessionRecorder(tmp_path / "s", NAMES, PARENTS, max_buffer_frames=5, flush_interval_s=60)
    frames = random_frames(15)
    for f in frames[:5]:
        rec.record_frame(f)
    real_write = os.write

    def full_disk(fd, data):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "write", full_disk)
    for f in frames[5:10]:
        rec.record_frame(f)
    monkeypatch.setattr(os, "write", real_write)
    for f in frames[10:]:
        rec.record_frame(f)
    rec.close()
    # the first failure ends the recording: a shorter session, never one with a hole
    assert rec.stats.write_errors == 1 and rec.stats.lost_frames == 10
    assert rec.failure == {"path": str(tmp_path / "s" / FRAMES_FILE),
                           "error": "No space left on device", "at_frame": 5}
    tk = read_session(tmp_path / "s")
    assert list(tk.meta["seq"]) == [0, 1, 2, 3, -1]


def test_never_overwrites_a_recording(tmp_path):
    d = tmp_path / "s"
    SessionRecorder(d, NAMES, PARENTS).close()
    with pytest.raises(FileExistsError, match=str(d)):
        SessionRecorder(d, NAMES, PARENTS)
    with pytest.raises(ValueError, match="parents"):
        SessionRecorder(tmp_path / "t", NAMES, PARENTS[:-1])


def test_read_errors_name_the_file(tmp_path):
    with pytest.raises(ValueError, match="not a recorded session"):
        read_session(tmp_path)
    d = tmp_path / "s"
    SessionRecorder(d, NAMES, PARENTS).close()
    h = json.loads((d / "session.json").read_text())
    h["version"] = 99
    (d / "session.json").write_text(json.dumps(h))
    with pytest.raises(ValueError, match=r"session.json: unsupported session format version 99"):
        read_session(d)


def test_empty_session_reads(tmp_path):
    SessionRecorder(tmp_path / "s", NAMES, PARENTS, frame_rate=None).close()
    tk = read_session(tmp_path / "s")
    assert tk.n_frames == 0 and tk.quats.shape == (0, len(NAMES), 4)
    assert tk.meta["frame_rate_source"] == "default"


def test_log_handler_writes_log_lines(tmp_path):
    rec = SessionRecorder(tmp_path / "s", NAMES, PARENTS)
    handler = RecorderLogHandler(rec)
    logger = logging.getLogger("rtseg.test_recording")
    logger.addHandler(handler)
    try:
        logger.warning("sensor %s lost", "Head")
        logger.info("not recorded (below WARNING)")
    finally:
        logger.removeHandler(handler)
    rec.close()
    ev = read_session(tmp_path / "s").meta["events"]
    assert [(e["type"], e["level"], e["message"]) for e in ev] == [("log", "warning", "sensor Head lost")]


CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    from rtseg.core.frame import Frame
    from rtseg.recording import SessionRecorder
    J = 17
    rec = SessionRecorder(sys.argv[1], [f"j{i}" for i in range(J)], [-1] + [0] * (J - 1),
                          frame_rate=200.0, flush_interval_s=0.2)
    valid = np.ones(J, bool)
    i = 0
    while True:
        a = i * 0.001
        q = np.tile([0.0, np.sin(a), 0.0, np.cos(a)], (J, 1))
        valid[i % J] = (i % 3) != 0
        rec.record_frame(Frame(recv_time=time.monotonic(), quats=q, valid=valid.copy(),
                               source_time=i / 200.0, seq=i))
        if i == 50:
            print("ready", flush=True)
        i += 1
        time.sleep(0.005)
""")


def test_sigkill_mid_session_loses_at_most_the_flush_interval(tmp_path):
    d = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(d)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.8)
        t_kill = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        proc.wait(5)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    tk = read_session(d)
    n = tk.n_frames
    assert n > 50
    seq = tk.meta["seq"]
    assert np.array_equal(seq, np.arange(n))                     # nothing lost before the tail
    recv = tk.meta["recv_time"]
    assert recv[-1] < t_kill and recv[-1] >= t_kill - 1.0        # at most ~1 s lost
    a = seq * 0.001
    assert np.allclose(tk.quats[:, 5], np.stack([0 * a, np.sin(a), 0 * a, np.cos(a)], axis=1))
    assert not tk.meta["closed_cleanly"] and tk.frame_rate == 200.0
    valid = np.ones(17, bool)                                    # the child's valid flags
    expect = []
    for i in range(n):
        valid[i % 17] = (i % 3) != 0
        expect.append(valid.copy())
    assert np.array_equal(tk.valid, np.array(expect))


def test_rest_geometry_of_another_shape_is_refused_in_one_line(tmp_path):
    """``note_rest`` takes (joints, 3) finite rest locations; anything else is one
    ValueError naming the shape, and the header keeps no geometry."""
    rec = SessionRecorder(tmp_path / "s", NAMES, PARENTS, space="global", frame_rate=100.0)
    try:
        for bad in (np.zeros((len(NAMES) + 1, 3)), np.full((len(NAMES), 3), np.nan)):
            with pytest.raises(ValueError, match="rest geometry of shape"):
                rec.note_rest(bad)
        assert "rest_positions" not in rec.header["meta"]
    finally:
        rec.close()
