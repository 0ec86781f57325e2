"""file:// and sim:// live sources and their shared absolute-schedule pacing."""

from __future__ import annotations

import threading
import time
from urllib.parse import quote

import numpy as np
import pytest

from rtseg.core import quat
from rtseg.drivers import SourceError, open_source
from rtseg.drivers.readers import write_take
from rtseg.drivers.replay.pacing import Pacer, ReplaySource
from rtseg.core.frame import Frame
from rtseg.simulators.synth.motion import synthesize
from rtseg.core.take import Take


@pytest.fixture(scope="module")
def synth():
    return synthesize("idle:2,walk:2", seed=5)


@pytest.fixture
def npz_path(tmp_path, synth):
    return write_take(tmp_path / "take.npz", synth.take)


def _drain(src) -> list[Frame]:
    frames = []
    while True:
        try:
            f = src.read(timeout=5.0)
        except EOFError:
            return frames
        assert f is not None, "a due frame did not arrive"
        frames.append(f)


# ------------------------------------------------------------------ pacing

class FakeClock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_pacer_schedule_is_absolute():
    clock = FakeClock()
    p = Pacer.nominal(10, 100.0, speed=2.0, clock=clock)
    assert p.due(0) == 100.0                      # t0 fixed by the first call
    clock.t = 150.0                               # however late we ask ...
    assert p.due(3) == pytest.approx(100.0 + 3 / 200.0)   # ... k is due at t0 + k/(rate*speed)
    assert p.due(13) == pytest.approx(100.0 + (10 / 100.0 + 3 / 100.0) / 2.0)  # second loop
    p.set_speed(4.0, 5)                            # re-based: item 5 due now
    assert p.due(5) == pytest.approx(150.0) and p.due(9) == pytest.approx(150.0 + 4 / 400.0)
    fast = Pacer.nominal(10, 100.0, speed=0.0, clock=clock)
    assert fast.due(0) == fast.due(9) == 150.0


def test_pacer_rejects_bad_arguments():
    with pytest.raises(ValueError, match="speed"):
        Pacer.nominal(3, 100.0, speed=-1.0)
    with pytest.raises(ValueError, match="non-decreasing"):
        Pacer(np.array([0.0, 0.2, 0.1]), 0.3)


def test_replay_yields_exactly_the_takes_frames(synth):
    tk = synth.take
    src = ReplaySource(tk, speed=0)
    assert (src.joint_names, src.parents, src.space, src.frame_rate) == \
        (tk.joint_names, tk.parents, "local", 120.0)
    frames = _drain(src)
    assert len(frames) == tk.n_frames
    assert np.array_equal(np.stack([f.quats for f in frames]), tk.quats)
    assert np.array_equal(np.stack([f.root_position for f in frames]), tk.root_position)
    assert [f.seq for f in frames] == list(range(tk.n_frames))
    assert np.allclose([f.source_time for f in frames], np.arange(tk.n_frames) / 120.0)
    assert all(f.valid.all() for f in frames)
    recv = np.array([f.recv_time for f in frames])
    assert (np.diff(recv) >= 0).all()
    assert src.stats.frames_ok == tk.n_frames
    with pytest.raises(EOFError):
        src.read(timeout=0)
    frames[0].quats[:] = 0                         # frames are copies, not views of the take
    assert np.allclose(np.linalg.norm(tk.quats[0], axis=-1), 1.0)


def test_replay_paces_in_real_time_scaled_by_speed(synth):
    tk = synth.take.slice(0, 120)                  # 1 s of motion at speed 5 -> 0.2 s
    src = ReplaySource(tk, speed=5.0)
    first = src.read(timeout=1.0)
    t0 = src.pacer.t0
    frames = [first] + _drain(src)
    assert len(frames) == 120
    due = t0 + np.arange(120) / (120.0 * 5.0)
    recv = np.array([f.recv_time for f in frames])
    assert (recv >= due - 1e-6).all()               # never early
    assert recv[-1] - t0 < (119 / 600.0) + 0.5     # and not dawdling (generous: shared CPU)


def test_schedule_does_not_drift_after_a_slow_read(synth):
    tk = synth.take.slice(0, 480)                   # 4 s at speed 4 -> 1 s
    src = ReplaySource(tk, speed=4.0)
    src.read(timeout=1.0)
    t0 = src.pacer.t0
    time.sleep(0.4)                                 # consumer stalls 0.4 s ...
    rest = _drain(src)
    recv = np.array([f.recv_time for f in rest])
    assert len(rest) == 479                         # nothing dropped
    # ... the overdue frames come at once, and the last one is still due at t0 + 479/480 s,
    # not 0.4 s later (a relative schedule would have drifted by the stall).
    expected_last = t0 + 479 / 480.0
    assert expected_last - 1e-6 <= recv[-1] < expected_last + 0.3


def test_read_timeout_returns_none_before_due(synth):
    src = ReplaySource(synth.take, speed=0.05)     # frames every 1/6 s
    assert src.read(timeout=1.0) is not None       # frame 0 at once
    assert src.read(timeout=0) is None
    t = time.monotonic()
    assert src.read(timeout=0.002) is None
    assert time.monotonic() - t >= 0.002
    f = src.read(timeout=1.0)
    assert f is not None and f.seq == 1


def test_close_wakes_a_blocked_read(synth):
    src = ReplaySource(synth.take, speed=0.001)    # next frame due in ~8 s
    src.read()
    result = {}

    def reader():
        t = time.monotonic()
        try:
            src.read()
        except EOFError as exc:
            result["eof"] = str(exc)
        result["waited"] = time.monotonic() - t

    th = threading.Thread(target=reader)
    th.start()
    time.sleep(0.05)
    src.close()
    th.join(timeout=2.0)
    assert not th.is_alive()
    assert "closed" in result["eof"] and result["waited"] < 1.0
    with pytest.raises(EOFError):
        src.read(timeout=0)


def test_loop_keeps_seq_increasing(synth):
    tk = synth.take.slice(0, 10)
    src = ReplaySource(tk, speed=0, loop=True)
    frames = [src.read() for _ in range(25)]
    assert [f.seq for f in frames] == list(range(25))
    assert np.array_equal(frames[13].quats, tk.quats[3])
    assert src.loops == 2 and src.position == 5 and not src.finished


def test_invalid_rows_hold_the_last_valid_value():
    q = quat.normalize(np.random.default_rng(0).normal(size=(4, 2, 4)))
    valid = np.array([[True, True], [True, False], [False, False], [True, True]])
    tk = Take(["a", "b"], [-1, 0], 10.0, q, valid=valid)
    frames = _drain(ReplaySource(tk, speed=0))
    assert np.array_equal(frames[1].valid, [True, False])
    assert np.array_equal(frames[1].quats[1], q[0, 1])   # b held from frame 0
    assert np.array_equal(frames[2].quats, np.stack([q[1, 0], q[0, 1]]))
    assert np.array_equal(frames[3].quats, q[3])


def test_start_stop_and_space_conversion(synth):
    tk = synth.take
    src = ReplaySource(tk, speed=0, start=1.0, stop=1.5, space="global")
    frames = _drain(src)
    assert [f.seq for f in frames] == list(range(120, 180))
    assert src.space == "global"
    g = quat.global_from_local(tk.quats[120:180], tk.parents)
    got = np.stack([f.quats for f in frames])
    assert np.allclose(np.abs(np.sum(got * g, axis=-1)), 1.0)
    with pytest.raises(SourceError, match="outside the take"):
        ReplaySource(tk, start=99.0)
    with pytest.raises(SourceError, match="after start"):
        ReplaySource(tk, start=1.0, stop=0.5)


# ------------------------------------------------------------------ file://

def test_file_source_replays_an_npz_take(npz_path, synth):
    src = open_source(f"file://{npz_path}?speed=0")
    assert src.path == npz_path
    assert (src.joint_names, src.parents, src.space, src.frame_rate) == \
        (synth.take.joint_names, synth.take.parents, "local", 120.0)
    frames = _drain(src)
    assert np.array_equal(np.stack([f.quats for f in frames]), synth.take.quats)
    assert [f.seq for f in frames] == list(range(synth.take.n_frames))


def test_file_source_relative_path_and_pacing(npz_path, monkeypatch):
    monkeypatch.chdir(npz_path.parent)
    with open_source("file://take.npz?speed=20&stop=0.5") as src:
        frames = _drain(src)
        t0 = src.pacer.t0
    assert len(frames) == 60
    assert all(f.recv_time >= t0 + f.seq / 2400.0 - 1e-6 for f in frames)


def test_file_source_reads_a_percent_encoded_path(tmp_path, synth):
    """A folder whose name has a '#' (``rtseg live --record "run #1"`` makes one) or a
    file URL copied from a file manager (``My%20Takes``): the path as written, else
    percent-decoded.  Before, no URL could name such a folder: '#' starts the URL's
    fragment and %23 was taken literally ("no such file or folder")."""
    d = tmp_path / "my takes #1 ü"
    d.mkdir()
    p = write_take(d / "take.npz", synth.take)
    src = open_source("file://" + quote(str(p)) + "?speed=0")
    assert src.path == p and len(_drain(src)) == synth.take.n_frames
    literal = tmp_path / "a%20b.npz"             # a name that holds a '%' is read as written
    write_take(literal, synth.take)
    assert open_source(f"file://{literal}?speed=0").path == literal
    with pytest.raises(SourceError, match="no such file"):
        open_source("file://" + quote(str(tmp_path / "none #2.npz")))


@pytest.mark.parametrize("url, fragment", [
    ("file://does-not-exist.npz", "no such file"),
    ("file://{p}?sped=2", "unknown option"),
    ("file://{p}?speed=-1", "speed"),
    ("file://{p}?speed=fast", "expected a number"),
    ("file://{p}?loop=maybe", "loop"),
    ("file://{p}?space=world", "space"),
    ("file://{p}?timing=recorded", "recorded receive times"),
    ("file://", "needs a path"),
])
def test_file_source_errors(url, fragment, npz_path):
    with pytest.raises(SourceError, match=fragment):
        open_source(url.format(p=npz_path))


def test_file_source_unreadable_take_names_the_file(tmp_path):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(SourceError, match="broken.npz"):
        open_source(f"file://{bad}")


def test_file_source_amc_with_skeleton_beside_the_take(data_dir, monkeypatch):
    monkeypatch.chdir(data_dir)
    src = open_source("file://cmu/86_01.amc?skeleton=86.asf&speed=0&stop=0.25")
    assert src.frame_rate == 120.0 and src.space == "local"
    assert "lfemur" in src.joint_names
    frames = _drain(src)
    assert len(frames) == 30 and frames[-1].seq == 29


def test_file_source_replays_a_recorded_session_with_its_timing(tmp_path, synth):
    from rtseg.recording import SessionRecorder

    tk = synth.take
    rec_times = 50.0 + np.cumsum(np.r_[0.0, np.full(29, 1 / 120.0)])
    rec_times[20:] += 0.1                           # a 0.1 s gap in the recording
    seqs = np.r_[np.arange(20), np.arange(32, 42)]  # ... with 12 frames lost
    d = tmp_path / "session"
    with SessionRecorder(d, tk.joint_names, tk.parents, "local", 120.0) as rec:
        for k in range(30):
            valid = np.ones(tk.n_joints, bool)
            rec.record_frame(Frame(recv_time=float(rec_times[k]), quats=tk.quats[k], valid=valid,
                                   source_time=seqs[k] / 120.0, seq=int(seqs[k])))
    src = open_source(f"file://{d}?speed=2")       # timing=recorded by default for sessions
    frames = _drain(src)
    assert [f.seq for f in frames] == list(seqs)
    assert np.allclose(np.stack([f.quats for f in frames]), tk.quats[:30])
    recv = np.array([f.recv_time for f in frames])
    # paced by the recorded receive times at speed 2, gap included (never early)
    assert np.all(recv >= src.pacer.t0 + (rec_times - rec_times[0]) / 2.0 - 1e-6)
    assert recv[20] - src.pacer.t0 >= (20 / 120.0 + 0.1) / 2.0 - 1e-6
    nominal = _drain(open_source(f"file://{d}?speed=0&timing=nominal"))
    assert [f.seq for f in nominal] == list(range(30))


# ------------------------------------------------------------------ sim://

def test_sim_source_is_the_synthesiser(synth):
    src = open_source("sim://synth?script=idle:2,walk:2&seed=5&speed=0")
    assert src.transitions == synth.transitions
    assert [s.name for s in src.segments] == ["idle", "walk"]
    frames = _drain(src)
    assert np.array_equal(np.stack([f.quats for f in frames]), synth.take.quats)
    assert (src.space, src.frame_rate, src.joint_names) == ("local", 120.0, synth.take.joint_names)


def test_sim_source_options():
    src = open_source("sim://synth?script=walk:2&rate=60&space=global&noise=0&speed=0&stop=1")
    assert src.frame_rate == 60.0 and src.space == "global"
    frames = _drain(src)
    assert len(frames) == 60
    ref = synthesize("walk:2", frame_rate=60.0, seed=0, noise_deg=0.0).take
    g = quat.global_from_local(ref.quats[:60], ref.parents)
    assert np.allclose(np.abs(np.sum(np.stack([f.quats for f in frames]) * g, -1)), 1.0)


def test_sim_source_paces(synth):
    src = open_source("sim://synth?script=idle:2,walk:2&seed=5&speed=8&stop=0.5")
    first = src.read(timeout=1.0)
    t0 = src.pacer.t0
    frames = [first] + _drain(src)
    assert len(frames) == 60
    assert all(f.recv_time >= t0 + f.seq / 960.0 - 1e-6 for f in frames)


@pytest.mark.parametrize("url, fragment", [
    ("sim://noise", "unknown generator"),
    ("sim://synth?script=idle:2,fly:3", "unknown behaviour 'fly'"),
    ("sim://synth?seed=-1", "seed"),
    ("sim://synth?rate=0", "rate"),
    ("sim://synth?rate=100000", r"rate=100000: out of range 1.0..1000.0"),  # was an OOM kill
    ("sim://synth?rate=0.5", "rate"),
    ("sim://synth?colour=red", "unknown option"),
])
def test_sim_source_errors(url, fragment):
    with pytest.raises(SourceError, match=fragment):
        open_source(url)


@pytest.mark.parametrize("query", ["start=1e308", "start=1e308&stop=1e308"])
def test_start_far_past_the_end_is_refused_in_one_line(query):
    # start * rate overflowed to infinity: OverflowError, an 'internal error' of rtseg live
    with pytest.raises(SourceError, match="outside the take"):
        open_source(f"sim://synth?script=walk:2&{query}")


def test_stop_far_past_the_end_is_the_end():
    src = open_source("sim://synth?script=walk:2&rate=30&speed=0&stop=1e308")
    assert src.n_frames == 60
