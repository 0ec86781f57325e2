"""Recording onto a real small filesystem (a 2 MB tmpfs) that fills up mid-session or is
full at the start: the failure is loud and exact, what was written is a valid session."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import uuid

import pytest

from rtseg.core.events import CutEvent
from rtseg.recording import SessionRecorder, read_session, read_session_cuts

from tests.test_recording import NAMES, PARENTS, random_frames


@pytest.fixture
def small_fs(tmp_path):
    """A 2 MB tmpfs mounted under tmp_path (needs root and mount)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a 2 MB tmpfs needs root")
    mnt = tmp_path / f"fs-{uuid.uuid4().hex[:6]}"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_disk_filling_mid_session_is_loud_exact_and_leaves_a_valid_session(small_fs, caplog):
    d = small_fs / "rec1"
    frames = random_frames(12000, seed=2)          # ~4.3 MB of records: more than fits
    rec = SessionRecorder(d, NAMES, PARENTS, space="global", frame_rate=100.0,
                          max_buffer_frames=100)
    cuts_sent = 0
    with caplog.at_level(logging.WARNING, logger="rtseg"):
        for i, f in enumerate(frames):
            rec.record_frame(f)
            if i % 1000 == 500:
                rec.record_cut(CutEvent(event=cuts_sent + 1, segment=cuts_sent + 1, frame=i,
                                        time=i * 0.01, method="pca"))
                cuts_sent += 1
        rec.close()
    fail = rec.failure
    assert fail is not None and fail["path"].endswith("frames.bin")
    assert "No space left on device" in fail["error"]
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert len(errors) == 1 and str(d / "frames.bin") in errors[0].getMessage()
    assert f"failed at frame {fail['at_frame']}" in errors[0].getMessage()
    # what was written is a valid, closed, shorter session; the counts add up exactly
    assert not list(d.glob("*.tmp"))
    header = json.loads((d / "session.json").read_text())
    assert header["closed"] is True and header["recording_failed"] == fail
    take = read_session(d)
    assert take.n_frames == fail["at_frame"] == header["frames"] < len(frames)
    assert header["stats"]["lost_frames"] == len(frames) - take.n_frames
    cuts = read_session_cuts(d)
    assert len(cuts) == header["cuts"] and header["stats"]["lost_cuts"] == cuts_sent - len(cuts)
    assert all(c.frame < take.n_frames for c in cuts)


def test_disk_full_at_start_names_the_path(small_fs):
    with open(small_fs / "filler", "wb") as fh:
        try:
            while True:
                fh.write(b"\0" * 65536)
        except OSError:
            pass
    d = small_fs / "rec2"
    with pytest.raises(OSError) as err:
        SessionRecorder(d, NAMES, PARENTS, space="global")
    assert str(d) in str(err.value) and "No space left on device" in str(err.value)
    assert not list(d.glob("*.tmp"))


def test_live_session_says_its_recording_failed_in_summary_status_and_osc(small_fs, tmp_path):
    """A live session recording onto the 2 MB tmpfs: the summary, every status after the
    failure (JSON lines, the console line, ``/rtseg/recording`` over real UDP) and the
    closed session.json give the same frame and the same counts of what it holds."""
    from osc_collector import OscCollector

    from rtseg.commands.live import Console
    from rtseg.core.events import StatusEvent
    from rtseg.live.config import from_dict
    from rtseg.live.session import LiveSession
    script = "idle:3," + ",".join(["walk:8", "punch:8"] * 4)       # 67 s, 8 changes
    rec = small_fs / "live"
    log = tmp_path / "events.jsonl"
    with OscCollector(linger=0.3) as rx:
        cfg = from_dict({"output": {"osc": [f"127.0.0.1:{rx.port}"], "jsonl": str(log)},
                         "recording": {"dir": str(rec)}, "status": {"interval": 0.25}},
                        origin="test")
        session = LiveSession(f"sim://synth?script={script}&seed=1&speed=15", cfg,
                              handle_signals=False)
        summary = session.run()
    fail = summary.recording_failure
    assert fail is not None and "No space left on device" in fail["error"]
    at, held, cuts = fail["at_frame"], summary.recording_frames, summary.recording_cuts
    assert 0 < at == held < summary.frames_received
    text = summary.text()
    assert (f"FAILED at frame {at} (writing {fail['path']}: {fail['error']}); it holds "
            f"{held} frames and {cuts} cuts") in text
    # what the folder holds is what every report says
    assert read_session(rec).n_frames == held and len(read_session_cuts(rec)) == cuts
    header = json.loads((rec / "session.json").read_text())
    assert header["closed"] and header["frames"] == held and header["cuts"] == cuts
    assert not list(rec.glob("*.tmp"))
    # status in JSON lines: -1 until the failure, then the frame and the counts
    status = [json.loads(ln) for ln in log.read_text().splitlines()]
    status = [d for d in status if d["type"] == "status"]
    failed = [d for d in status if d["recording_failed_at"] >= 0]
    assert failed and status[0]["recording_failed_at"] == -1
    assert {d["recording_failed_at"] for d in failed} == {at}
    assert failed[-1]["recording_frames"] == held and failed[-1]["recording_cuts"] == cuts
    # over OSC: /rtseg/recording right after each such /rtseg/status
    osc = rx.args("/rtseg/recording")
    assert len(osc) == len(failed) and osc[-1] == [at, held, cuts]
    order = [a for a, _, _ in rx.messages if a in ("/rtseg/status", "/rtseg/recording")]
    assert all(order[i - 1] == "/rtseg/status" for i, a in enumerate(order)
               if a == "/rtseg/recording")
    # the console status line says it
    out = _Tty()
    Console(out=out, err=out).show_status(StatusEvent(
        **{k: v for k, v in failed[-1].items() if k not in ("type", "stale_names")}))
    assert (f"RECORDING FAILED at frame {at} (it holds {held} frames, {cuts} cuts)"
            in out.getvalue())


class _Tty:
    """A text stream that says it is a terminal (the console rewrites its status line)."""

    def __init__(self) -> None:
        self.parts: list[str] = []

    def write(self, s: str) -> int:
        self.parts.append(s)
        return len(s)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return True

    def getvalue(self) -> str:
        return "".join(self.parts)
