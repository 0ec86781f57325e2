"""Live loop logic with small fakes: gaps restart the detectors (no cut across a gap),
calibration, bad input counted not fatal, dropouts, ring overruns, config validation."""

from __future__ import annotations

import time

import numpy as np
import pytest

from rtseg.config import ConfigError
from rtseg.detectors.base import Cut, OnlineDetector
from rtseg.drivers.base import Source
from rtseg.core.events import CutEvent, DropoutEvent, StatusEvent
from rtseg.core.frame import Frame
from rtseg.live.session import LiveSession, Pipeline
from rtseg.core.quat import from_euler
from rtseg.live.config import from_dict, load_session_config
from rtseg.simulators.synth.motion import JOINT_NAMES, PARENTS

J = len(JOINT_NAMES)
ARM = JOINT_NAMES.index("LeftUpperArm")
RAISED = from_euler("X", np.array([90.0]))


class StepDetector(OnlineDetector):
    """Cuts where the features jump: 3 consecutive frames far from the segment's first
    frame -> Cut(frame = first of them, detected_at = third).  Frames counted from restart."""
    name = "step"
    frame_origin = "restart"

    def __init__(self, delay: float = 0.0) -> None:
        self.delay = delay
        self.restart()
        self.restarts = 0

    def restart(self) -> None:
        self.i = -1
        self.ref = None
        self.run = 0
        self.restarts = getattr(self, "restarts", -1) + 1

    def update(self, x):
        if self.delay:
            time.sleep(self.delay)
        self.i += 1
        if self.ref is None:
            self.ref = x.copy()
            return None
        if np.linalg.norm(x - self.ref) > 0.5:
            self.run += 1
            if self.run == 3:
                self.ref = x.copy()
                self.run = 0
                return Cut(self.i - 2, self.name, 0.9, self.i, 1.0)
        else:
            self.run = 0
        return None


def frames(n: int, change_at: int, *, seq_jump_at: int | None = None, jump: int = 10,
           invalid: range = range(0)) -> list[tuple[np.ndarray, np.ndarray, int, float]]:
    """n frames: identity pose, left upper arm raised from frame ``change_at`` on."""
    out = []
    seq = 0
    for i in range(n):
        q = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
        if i >= change_at:
            q[ARM] = RAISED
        v = np.ones(J, dtype=bool)
        if i in invalid:
            v[ARM] = False
        if seq_jump_at is not None and i == seq_jump_at:
            seq += jump
        out.append((q, v, seq, i / 120.0))
        seq += 1
    return out


def pipeline(cfg: dict | None = None, space: str = "global", det: OnlineDetector | None = None
             ) -> Pipeline:
    config = from_dict(cfg or {"calibration": {"mode": "none"}})
    return Pipeline(JOINT_NAMES, PARENTS, space, 120.0, config,
                    detectors={"step": det or StepDetector()})


def run(pipe: Pipeline, fr) -> list:
    cuts = []
    for i, (q, v, seq, t) in enumerate(fr):
        cuts.extend(pipe.process(i, q, v, seq, t))
    return cuts


def test_cut_found_without_gap():
    cuts = run(pipeline(), frames(400, 200))
    assert [(c.boundary, c.detected) for c in cuts] == [(200, 202)]
    assert cuts[0].cut.method == "step"


def test_sequence_gap_restarts_and_no_cut_across_it():
    """A gap longer than gaps.bridge_seconds (0.1 s = 12 frames at 120 Hz) restarts."""
    pipe = pipeline()
    cuts = run(pipe, frames(400, 200, seq_jump_at=200, jump=13))
    assert cuts == []
    assert pipe.stats.restarts == 1 and pipe.stats.gap_frames == 13
    assert pipe.stats.bridged_gaps == 0 and pipe.stats.filled_frames == 0


def test_short_gap_is_bridged_with_filled_frames():
    """12 missing frames (0.1 s): the detector is fed 12 interpolated frames and goes on;
    the change inside the gap is cut at the first received frame after it."""
    det = StepDetector()
    pipe = pipeline(det=det)
    cuts = run(pipe, frames(400, 200, seq_jump_at=200, jump=12))
    assert [(c.boundary, c.detected) for c in cuts] == [(200, 200)]
    assert pipe.stats.restarts == 0 and det.restarts == 0
    assert pipe.stats.bridged_gaps == 1 and pipe.stats.filled_frames == 12
    assert det.i + 1 == 400 + 12                     # every received frame + the filled ones
    # a gap before the change: the cut keeps its session index
    pipe = pipeline()
    cuts = run(pipe, frames(400, 200, seq_jump_at=100, jump=5))
    assert [(c.boundary, c.detected) for c in cuts] == [(200, 202)]
    assert pipe.stats.bridged_gaps == 1 and pipe.stats.filled_frames == 5
    # bridge_seconds = 0: only max_frames (3) missing frames are bridged
    pipe = pipeline({"calibration": {"mode": "none"}, "gaps": {"bridge_seconds": 0.0}})
    assert run(pipe, frames(400, 200, seq_jump_at=200, jump=4)) == []
    assert pipe.stats.restarts == 1


def test_cuts_keep_their_session_index_over_many_bridged_gaps():
    """Every 4th frame lost for 20 000 frames (5 000 filled rows, past the point where old
    ones are forgotten) and the arm toggling every 1 000 frames: each cut is at the
    session index of the toggle frame."""
    fr = []
    for t in range(20_000):
        if t % 4 == 3:
            continue
        q = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
        if (t // 1000) % 2:
            q[ARM] = RAISED
        fr.append((q, np.ones(J, dtype=bool), t & 0xFFFF, t / 120.0))
    pipe = pipeline()
    cuts = run(pipe, fr)
    assert [c.boundary for c in cuts] == [750 * k for k in range(1, 20)]
    assert pipe.stats.restarts == 0 and pipe.stats.filled_frames == 4999
    assert len(pipe._filled) < 4096 + 10


def test_filled_frames_interpolate_between_the_poses():
    """The filled rotations lie between the last fed pose and the received one (nlerp)."""
    class Tap(StepDetector):
        def update(self, x):
            rows.append(np.array(x))
            return None
    rows: list = []
    pipe = pipeline(det=Tap())
    fr = frames(40, 20, seq_jump_at=20, jump=3)
    run(pipe, fr)
    assert len(rows) == 43
    before, after = rows[19], rows[23]
    d = [np.linalg.norm(rows[k] - before) for k in range(19, 24)]
    assert d[0] == 0 and all(a < b for a, b in zip(d, d[1:])), d
    assert np.allclose(rows[23], after)


def test_frames_dropped_by_the_loop_are_a_gap_and_cuts_name_the_frames_fed():
    """The live loop drops frames under overload and says how many (``lost``): the cut's
    boundary and detected frame are the session indices of the frames the detector was
    fed there, and the sequence gap those frames leave is not counted twice."""
    fr = frames(400, 203)
    fed = [k for k in range(400) if k % 4 < 2]         # frames k % 4 in (2, 3) dropped
    after = [k for k in fed if k >= 203]               # the arm is raised from 203 on
    for origin in ("restart", "creation"):
        det = StepDetector()
        det.frame_origin = origin
        pipe = pipeline(det=det)
        cuts, prev = [], -1
        for k in fed:
            q, v, seq, t = fr[k]
            cuts.extend(pipe.process(k, q, v, seq, t, lost=k - prev - 1))
            prev = k
        # the dropped pairs are bridged with filled rows (each mapped to the next frame fed):
        # the step shows in the fill of 203, so the detector's third row since the change
        # is frame 205
        assert [(c.boundary, c.detected) for c in cuts] == [(after[0], after[1])], origin
        assert pipe.stats.restarts == 0
        assert pipe.stats.gap_frames == 400 - len(fed) - (400 - 1 - fed[-1])
    # more than gaps.bridge_seconds dropped at once is a gap that restarts the detectors
    pipe = pipeline()
    for i, (q, v, seq, t) in enumerate(fr[:100]):
        pipe.process(i, q, v, seq, t)
    q, v, seq, t = fr[120]
    pipe.process(120, q, v, seq, t, lost=20)
    assert pipe.stats.restarts == 1 and pipe.stats.gap_frames == 20


def test_silence_restarts():
    fr = frames(400, 200)
    fr = [(q, v, None, t + (1.0 if i >= 200 else 0.0)) for i, (q, v, s, t) in enumerate(fr)]
    pipe = pipeline()
    assert run(pipe, fr) == [] and pipe.stats.restarts == 1


def test_u16_sequence_wrap_is_not_a_gap():
    fr = frames(300, 1000)
    fr = [(q, v, (65500 + s) % 65536, t) for q, v, s, t in fr]
    pipe = pipeline()
    run(pipe, fr)
    assert pipe.stats.restarts == 0 and pipe.stats.gap_frames == 0


def test_invalid_required_joints_restart_only_past_the_limit():
    pipe = pipeline()
    cuts = run(pipe, frames(400, 200, invalid=range(195, 215)))
    assert cuts == [] and pipe.stats.restarts == 1
    assert pipe.stats.skipped_invalid == 20 - 12      # 0.1 s = 12 frames bridged
    # 12 invalid frames: bridged, no restart
    pipe = pipeline()
    cuts = run(pipe, frames(400, 200, invalid=range(190, 202)))
    assert [c.boundary for c in cuts] == [202] and pipe.stats.restarts == 0
    # two invalid frames: fed with the last good value, no restart, cut where the arm moves
    pipe = pipeline()
    cuts = run(pipe, frames(400, 200, invalid=range(200, 202)))
    assert [c.boundary for c in cuts] == [202] and pipe.stats.restarts == 0
    # a joint outside required_joints may be invalid for long
    pipe = pipeline({"calibration": {"mode": "none"}, "gaps": {"required_joints": ["Head"]}})
    cuts = run(pipe, frames(400, 200, invalid=range(100, 150)))
    assert [c.boundary for c in cuts] == [200] and pipe.stats.restarts == 0


def test_non_finite_values_are_replaced_and_counted():
    fr = frames(300, 1000)
    fr[50][0][3] = np.nan
    fr[51][0][4] = 0.0
    pipe = pipeline()
    assert run(pipe, fr) == []
    assert pipe.stats.bad_values == 2 and pipe.stats.restarts == 0


def test_cut_boundary_before_restart_is_discarded():
    class Late(StepDetector):
        frame_origin = "creation"

        def update(self, x):
            self.i += 1
            self.n = getattr(self, "n", -1) + 1
            if self.n == 150:                     # refers to a frame before the restart
                return Cut(90, "late", 0.5, 150)
            return None

    det = Late()
    pipe = pipeline(det=det)
    cuts = run(pipe, frames(200, 1000, seq_jump_at=100, jump=20))
    assert cuts == [] and pipe.stats.discarded_cuts == 1


def test_calibration_pose_averaged_for_local_input():
    seen = []

    class Rec(StepDetector):
        def update(self, x):
            seen.append(x.copy())
            return super().update(x)

    pipe = pipeline({"calibration": {"mode": "auto", "frames": 5}}, space="local", det=Rec())
    rig = from_euler("XYZ", np.array([20.0, -10.0, 5.0]))
    fr = []
    for i in range(50):
        q = np.tile(rig, (J, 1))
        fr.append((q, np.ones(J, bool), i, i / 120))
    run(pipe, fr)
    assert pipe.stats.calibration_frames == 5 and pipe.stats.fed == 45
    ident = np.tile([0.0, 0.0, 0.0, 1.0], len(seen[0]) // 4)
    np.testing.assert_allclose(seen[0], ident, atol=1e-9)
    # global input in auto mode is not calibrated
    pipe = pipeline({"calibration": {"mode": "auto"}})
    run(pipe, fr)
    assert pipe.stats.calibration_frames == 0 and pipe.stats.fed == 50


# ------------------------------------------------------------------------ live session
class FakeSource(Source):
    """Replays frames; ``bad`` indices yield malformed frames, ``errors`` indices raise."""
    space = "global"
    frame_rate = 120.0

    def __init__(self, fr, bad=(), errors=(), pace: float = 0.0, invalid_tail: bool = False):
        super().__init__()
        self.joint_names = list(JOINT_NAMES)
        self.parents = list(PARENTS)
        self.fr = fr
        self.i = 0
        self.bad = set(bad)
        self.errors = set(errors)
        self.pace = pace
        self.closed = False

    def read(self, timeout=None):
        if self.i >= len(self.fr):
            raise EOFError
        i = self.i
        self.i += 1
        if i in self.errors:
            self.errors.discard(i)
            self.i -= 1
            raise OSError("device hiccup")
        if self.pace:
            time.sleep(self.pace)
        q, v, seq, _ = self.fr[i]
        if i in self.bad:
            return Frame(time.monotonic(), q[:5], v, None, seq)
        self.stats.frames_ok += 1
        return Frame(time.monotonic(), q, v, None, seq)

    def close(self):
        self.closed = True


class FakePublishers:
    def __init__(self):
        self.events = []
        self.closed = False

    def publish_cut(self, ev):
        ev = ev.stamped()
        self.events.append(ev)
        return ev

    def publish_status(self, ev):
        self.events.append(ev)

    def publish_dropout(self, ev):
        self.events.append(ev)

    def close(self):
        self.closed = True


class FakeRecorder:
    def __init__(self):
        self.frames = []
        self.events = []
        self.closed = False

    def record_frame(self, f):
        self.frames.append(f)

    def record_cut(self, ev):
        self.events.append(ev)

    def record_event(self, ev):
        self.events.append(ev)

    def close(self):
        self.closed = True


def session(src, cfg=None, det=None, **kw):
    config = from_dict(cfg or {"calibration": {"mode": "none"}, "status": {"interval": 0.05}})
    s = LiveSession(src, config, publishers=FakePublishers(), recorder=FakeRecorder(),
                    handle_signals=False, **kw)
    import rtseg.live.pipeline as pipe_mod
    orig = pipe_mod.make_detectors
    pipe_mod.make_detectors = lambda c, r: {"step": det or StepDetector()}
    try:
        summary = s.run()
    finally:
        pipe_mod.make_detectors = orig
    return s, summary


def test_session_publishes_records_and_survives_bad_input():
    src = FakeSource(frames(600, 300), bad={100}, errors={200}, pace=0.0005)
    s, summary = session(src)
    pubs, rec = s.publishers, s.recorder
    cuts = [e for e in pubs.events if isinstance(e, CutEvent)]
    # frame 100 was malformed and never entered the session: indices after it shift by one
    assert [(c.frame, c.detected_frame, c.method, c.segment, c.event) for c in cuts] == \
        [(299, 301, "step", 1, 1)]
    assert cuts[0].latency_ms is not None and cuts[0].latency_ms >= 0
    # processing latency: arrival of the revealing frame -> send; latency adds the
    # detector's delay (boundary frame arrival -> revealing frame arrival)
    assert 0 <= cuts[0].processing_ms <= cuts[0].latency_ms
    assert cuts[0].detected_recv_time >= cuts[0].boundary_recv_time
    assert cuts[0].detector_delay_ms == pytest.approx(2 / 120 * 1000)
    assert 0 <= cuts[0].time < summary.duration_s
    assert summary.frames_received == 599 and summary.frames_processed == 599
    assert s.stats.bad_frames == 1 and s.stats.source_errors == 1
    assert len(rec.frames) == 599
    assert [type(e) for e in rec.events].count(CutEvent) == 1
    status = [e for e in pubs.events if isinstance(e, StatusEvent)]
    assert status and status[-1].alive == 0 and all(e.alive == 1 for e in status[:-1])
    assert summary.stop_reason == "end of source"
    assert src.closed and pubs.closed and rec.closed
    assert summary.cuts == 1 and summary.dropped == 1


def test_session_reports_joint_dropout_and_restore():
    invalid = range(100, 250)
    src = FakeSource(frames(400, 10_000, invalid=invalid), pace=0.002)
    cfg = {"calibration": {"mode": "none"}, "status": {"interval": 0.05},
           "gaps": {"dropout_seconds": 0.1, "required_joints": ["Head"]}}
    s, summary = session(src, cfg)
    drops = [e for e in s.publishers.events if isinstance(e, DropoutEvent)]
    assert [(d.name, d.lost) for d in drops] == [("LeftUpperArm", True), ("LeftUpperArm", False)]
    status = [e for e in s.publishers.events if isinstance(e, StatusEvent)]
    assert any(e.stale_joints == 1 and e.stale_names == ("LeftUpperArm",) for e in status)
    assert all(e.lag_ms >= 0 and e.backlog >= 0 for e in status)


def test_session_counts_ring_overruns_as_dropped_and_restarts():
    src = FakeSource(frames(400, 10_000), pace=0.0003)
    cfg = {"calibration": {"mode": "none"},
           "buffer": {"capacity": 16, "max_batch": 4, "max_lag_seconds": 0}}
    det = StepDetector(delay=0.003)
    s, summary = session(src, cfg, det=det)
    assert summary.frames_received == 400
    assert s.stats.overruns > 0
    assert summary.frames_processed + s.stats.overruns == 400
    assert s.pipeline.stats.restarts >= 1 and det.restarts >= 1
    assert summary.dropped >= s.stats.overruns
    assert len(s.recorder.frames) == 400      # recording holds everything received


def test_session_duration_and_stop():
    src = FakeSource(frames(100_000, 10**9), pace=0.001)
    s, summary = session(src, duration=0.3)
    assert summary.stop_reason == "duration reached"
    assert 0.25 < summary.duration_s < 2.0


def test_frames_received_while_the_session_stops_are_processed():
    """A frame the reader thread receives after the loop's last step (the session asked
    to stop meanwhile) is still processed and recorded: none is received and lost."""
    holder: dict = {}

    class Stopping(FakeSource):
        def read(self, timeout=None):
            if self.i == 150:
                holder["s"].stop("asked")
                time.sleep(0.1)            # the loop's last step passes meanwhile
            return super().read(timeout)

    src = Stopping(frames(300, 10**9), pace=0.0005)
    config = from_dict({"calibration": {"mode": "none"}, "status": {"interval": 0.05}})
    s = LiveSession(src, config, publishers=FakePublishers(), recorder=FakeRecorder(),
                    handle_signals=False)
    holder["s"] = s
    import rtseg.live.pipeline as pipe_mod
    orig = pipe_mod.make_detectors
    pipe_mod.make_detectors = lambda c, r: {"step": StepDetector()}
    try:
        summary = s.run()
    finally:
        pipe_mod.make_detectors = orig
    assert summary.stop_reason == "asked"
    assert summary.frames_received == 151          # the one read while stopping too
    assert summary.frames_processed == summary.frames_received
    assert len(s.recorder.frames) == summary.frames_received


def test_session_freezes_the_heap_while_it_runs_and_thaws_it_after():
    """The loop keeps the objects alive at its start out of the collector (no full
    collection stalls the reader) and hands them back when it ends, so a process that
    runs many sessions still collects cycles that were alive when one started."""
    import gc
    gc.unfreeze()
    seen: list[int] = []

    class Watching(FakeSource):
        def read(self, timeout=None):
            seen.append(gc.get_freeze_count())
            return super().read(timeout)

    s, summary = session(Watching(frames(300, 10**9)))
    assert summary.frames_received == 300
    assert seen and min(seen) > 0              # frozen while frames were read
    assert gc.get_freeze_count() == 0          # thawed after


# ------------------------------------------------------------------------ configuration
def test_config_errors_name_the_key(tmp_path):
    p = tmp_path / "live.toml"
    cases = {
        '[output]\nosc = ["localhost"]\n': "output.osc[0]",
        '[gaps]\nmax_frame = 3\n': "gaps.max_frame",
        '[status]\ninterval = "1"\n': "status.interval",
        '[calibration]\nmode = "sometimes"\n': "calibration.mode",
        '[detectors]\nmethods = ["pca", "hmm"]\n': "detectors.methods",
        '[output]\ntemplates = ["cue/{label}"]\n': "output.templates[0]",
        '[nonsense]\nx = 1\n': "[nonsense]",
        '[buffer]\ncapacity = 4\n': "buffer.capacity",
    }
    for text, key in cases.items():
        p.write_text(text)
        with pytest.raises(ConfigError, match=key.replace("[", r"\[").replace("]", r"\]")) as ei:
            load_session_config(p)
        assert "live.toml" in str(ei.value)
    with pytest.raises(ConfigError, match="output.osc"):
        load_session_config(overrides={"output.osc": ["127.0.0.1:99999"]})
    cfg = load_session_config(overrides={"output.osc": ["127.0.0.1:9000"], "status.interval": 2})
    assert cfg["output.osc"] == ["127.0.0.1:9000"] and cfg["status.interval"] == 2.0


def test_unknown_required_joint_refused():
    with pytest.raises(ConfigError, match="gaps.required_joints"):
        pipeline({"gaps": {"required_joints": ["Tail"]}})


def test_bad_full_target_refused_at_start():
    from rtseg.live.session import build_publishers
    with pytest.raises(ConfigError, match=r"output.targets\[0\]"):
        build_publishers(from_dict({"output": {"targets": ["udp:127.0.0.1:9123,colour=red"]}}))


def test_real_detectors_place_no_cut_across_a_gap():
    """Synthesised idle -> walk; the frames around the change (and 1 s either side) never
    arrive (sequence gap).  With the real online PCA/PPCA detectors: without the gap the
    change is found; with it the detectors restart and no cut lands in or right after it."""
    from rtseg.core.quat import global_from_local
    from rtseg.simulators.synth.motion import synthesize

    r = synthesize("idle:6,walk:6", frame_rate=120.0, seed=1)
    take = r.take
    g = global_from_local(take.quats, take.parents)
    mid = r.transitions[0].mid
    ok = np.ones(take.n_joints, bool)
    cfg = from_dict({})
    full = [(g[i], ok, i, i / 120.0) for i in range(take.n_frames)]
    lo, hi = mid - 120, mid + 120
    gapped = [f for i, f in enumerate(full) if not lo <= i < hi]

    def cuts_of(fr):
        pipe = Pipeline(take.joint_names, take.parents, "global", 120.0, cfg)
        out = []
        for i, (q, v, seq, t) in enumerate(fr):
            out.extend(pipe.process(i, q, v, seq, t))
        return out, pipe

    base, _ = cuts_of(full)
    assert any(abs(c.boundary - mid) <= 60 for c in base), [c.boundary for c in base]
    cuts, pipe = cuts_of(gapped)
    assert pipe.stats.restarts == 1 and pipe.stats.gap_frames == hi - lo
    # session index lo is the first frame after the gap; PCA needs 2.5 s and PPCA ~1.3 s
    # of a new segment before they can cut, so nothing within 1 s after the gap
    assert not [c for c in cuts if lo - 120 <= c.boundary < lo + 120], \
        [(c.cut.method, c.boundary, c.detected) for c in cuts]
    assert all(c.boundary >= lo or c.detected < lo for c in cuts)


def test_suit_from_config_added_to_device_urls():
    from rtseg.live.session import with_suit
    assert with_suit("serial:///dev/ttyUSB0", "suitX") == "serial:///dev/ttyUSB0?suit=suitX"
    assert with_suit("osc://0.0.0.0:39539?format=vmc", "s") == "osc://0.0.0.0:39539?format=vmc&suit=s"
    assert with_suit("serial:///dev/x?suit=a", "b") == "serial:///dev/x?suit=a"
    assert with_suit("sim://synth", "b") == "sim://synth"


def test_bad_detector_settings_refused_before_the_source_opens(tmp_path):
    class Unopenable:
        def __getattr__(self, name):
            raise AssertionError("source touched")

    with pytest.raises(ConfigError, match=r"detectors\.pca: .*foo"):
        LiveSession(Unopenable(), from_dict({"detectors": {"pca": {"foo": 1}}}))
    with pytest.raises(ConfigError, match=r"detectors\.params: .*nonexistent"):
        LiveSession(Unopenable(), from_dict({"detectors": {"params": str(tmp_path / "nonexistent.toml")}}))
    with pytest.raises(ConfigError, match=r"detectors\.ppca: .*window_s"):
        LiveSession(Unopenable(), from_dict({"detectors": {"ppca": {"window_s": -1.0}}}))


def test_json_parameter_file_in_the_live_configuration(tmp_path):
    """``[detectors] params`` given the JSON file ``rtseg segment --params`` reads: it was
    parsed as TOML ("invalid TOML: Invalid statement"); now JSON is read as JSON, and its
    values are checked as a TOML file's are."""
    from rtseg.live.detector_setup import detector_params
    p = tmp_path / "det.json"
    p.write_text('{"contrast": {"threshold": 3.5}}')
    got = detector_params(from_dict({"detectors": {"params": str(p)}}))
    assert got["contrast"]["threshold"] == 3.5
    p.write_text('{"contrast": {"threshold": "high"}}')
    with pytest.raises(ConfigError, match=r"detectors\.params: .*det\.json.*threshold"):
        detector_params(from_dict({"detectors": {"params": str(p)}}))
    p.write_text('{"contrast": ')
    with pytest.raises(ConfigError, match=r"det\.json: invalid JSON"):
        detector_params(from_dict({"detectors": {"params": str(p)}}))


def test_joint_the_features_do_not_use_may_be_missing_for_ever():
    """A VMC rig without hands: LeftHand never valid.  The features (unity profile) do not
    use it, so calibration completes and the detectors are fed without restarts."""
    hand = JOINT_NAMES.index("LeftHand")
    fr = frames(400, 200)
    for q, v, _, _ in fr:
        v[hand] = False
    pipe = pipeline({"calibration": {"mode": "auto", "frames": 5}}, space="local")
    cuts = run(pipe, fr)
    assert hand not in pipe.required and ARM in pipe.required
    assert pipe.calibrated and pipe.stats.restarts == 0 and pipe.stats.fed == 395
    assert [c.boundary for c in cuts] == [200]


def test_source_clock_reveals_lost_frames_without_sequence_numbers():
    """VMC-like input: seq counts assembled frames (no gap visible), the sender's clock
    jumps by 20 frame periods where frames were lost -> restart (beyond the 12 frames
    bridged at the nominal 120 Hz), no cut across it.  The period is learned from the clock
    (here 1/60 s, whatever the nominal rate)."""
    fr = frames(400, 200)
    dt = 1 / 60
    fr_t = []
    for i, (q, v, _, t) in enumerate(fr):
        st = i * dt + (20 * dt if i >= 200 else 0.0)
        fr_t.append((q, v, i, i * dt, st))
    pipe = pipeline()
    cuts = []
    for i, (q, v, seq, t, st) in enumerate(fr_t):
        cuts.extend(pipe.process(i, q, v, seq, t, 0, st))
    assert cuts == [] and pipe.stats.restarts == 1 and pipe.stats.gap_frames == 20
    # jittery clock, no loss: no restart
    rng = np.random.default_rng(0)
    pipe = pipeline()
    cuts = []
    for i, (q, v, seq, t, _) in enumerate(fr_t):
        st = i * dt + rng.uniform(-0.3, 0.3) * dt
        cuts.extend(pipe.process(i, q, v, seq, t, 0, st))
    assert [c.boundary for c in cuts] == [200] and pipe.stats.restarts == 0


def test_source_that_slows_down_is_not_one_long_gap():
    fr = frames(600, 10_000)
    pipe = pipeline()
    st = 0.0
    for i, (q, v, seq, t) in enumerate(fr):
        st += 1 / 60 if i < 100 else 1 / 10          # 60 Hz, then 10 Hz for good
        pipe.process(i, q, v, i, st, 0, st)
    assert pipe.stats.restarts <= 8 and pipe.stats.fed > 500


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as hst  # noqa: E402
from hypothesis.extra.numpy import arrays  # noqa: E402

_weird = hst.floats(allow_nan=True, allow_infinity=True, width=64)


@settings(max_examples=40, deadline=None)
@given(hst.lists(hst.tuples(arrays(np.float64, (J, 4), elements=_weird),
                            arrays(bool, (J,)),
                            hst.one_of(hst.none(), hst.integers(-2**40, 2**40)),
                            hst.one_of(hst.none(), _weird),
                            hst.one_of(hst.none(), _weird)), min_size=1, max_size=25))
def test_pipeline_survives_garbage(frames_):
    """Whatever a buggy source delivers (NaN, inf, zero quaternions, wild sequence numbers
    and clocks), the pipeline neither raises nor feeds a non-finite feature."""
    seen = []

    class Check(StepDetector):
        def update(self, x):
            assert np.all(np.isfinite(x))
            seen.append(1)
            return super().update(x)

    pipe = pipeline(det=Check())
    for i, (q, v, seq, t, st) in enumerate(frames_):
        pipe.process(i, q, v, seq, t, 0, st)
        np.testing.assert_allclose(np.linalg.norm(pipe._last_good, axis=1), 1.0, rtol=1e-9)
    assert pipe.stats.frames == len(frames_)
    assert pipe.stats.fed + pipe.stats.filled_frames == len(seen)


def test_a_cut_goes_out_before_the_identity_step_of_its_frame():
    """The live loop sends a frame's cuts, then runs the behaviour identity's step of that
    frame (its window fits), then sends its behaviour messages: a cue does not wait for
    the identity, and the messages keep their order."""
    from rtseg.identity.tracker import IdentityTracker
    from rtseg.core.events import BehaviourEvent
    seen = []                              # (cuts the step got, cut events published by then)
    orig = IdentityTracker.step

    def step(self, index, x, cuts):
        if cuts:
            seen.append((len(cuts), sum(isinstance(e, CutEvent) for e in pubs.events)))
        return orig(self, index, x, cuts)

    class Pubs(FakePublishers):
        def publish_behaviour(self, ev):
            self.events.append(ev)

    pubs = Pubs()
    config = from_dict({"calibration": {"mode": "none"}, "status": {"interval": 0.05},
                        "identity": {"enabled": True}})
    src = FakeSource(frames(900, 300), pace=0.0002)
    s = LiveSession(src, config, publishers=pubs, recorder=FakeRecorder(),
                    handle_signals=False)
    import rtseg.live.pipeline as pipe_mod
    orig_make = pipe_mod.make_detectors
    pipe_mod.make_detectors = lambda c, r: {"step": StepDetector()}
    IdentityTracker.step = step
    try:
        s.run()
    finally:
        pipe_mod.make_detectors = orig_make
        IdentityTracker.step = orig
    assert seen == [(1, 1)]                # the cut was out when the identity saw it
    events = [e for e in pubs.events if isinstance(e, (CutEvent, BehaviourEvent))]
    cut_at = [i for i, e in enumerate(events) if isinstance(e, CutEvent)]
    after = [e.segment for e in events[cut_at[0] + 1:]]
    assert len(cut_at) == 1 and 1 in after   # the new segment's decision follows its cut
    assert all(e.segment == 0 for e in events[:cut_at[0]])


def test_work_ahead_that_fails_is_counted_and_the_session_goes_on(caplog):
    """A detector whose work ahead raises never ends the session: the failures are
    counted in the pipeline's stats and logged, and its cuts still go out."""
    class FailingAhead(StepDetector):
        quiet_frames = 1                   # every next frame quiet: the loop works ahead

        def ahead(self):
            raise RuntimeError("ahead broke")

    src = FakeSource(frames(600, 300), pace=0.0005)
    with caplog.at_level("WARNING", logger="rtseg.live.session"):
        s, summary = session(src, det=FailingAhead())
    cuts = [e for e in s.publishers.events if isinstance(e, CutEvent)]
    assert [c.frame for c in cuts] == [300] and summary.stop_reason == "end of source"
    assert summary.frames_processed == 600
    assert s.pipeline.stats.ahead_errors > 10
    assert "work ahead failed (RuntimeError: ahead broke" in caplog.text


def test_the_last_status_states_the_input_rate_of_a_whole_span():
    """The status sent as the session ends comes moments after the one before it: too short
    a span to count frames over. It repeats the last rate instead of dividing a frame or two
    by a few milliseconds (which said 2 648 Hz for a 120 Hz suit)."""
    src = FakeSource(frames(100_000, 10**9), pace=1.0 / 200.0)       # about 200 Hz
    s, summary = session(src, {"calibration": {"mode": "none"}, "status": {"interval": 0.25}},
                         duration=1.6)
    status = [e for e in s.publishers.events if isinstance(e, StatusEvent)]
    assert len(status) >= 4 and status[-1].alive == 0
    whole = [e.frame_rate for e in status[1:-1]]
    assert status[-1].frame_rate == pytest.approx(whole[-1])
    assert all(50.0 < r < 400.0 for r in whole + [status[-1].frame_rate])


def test_every_frame_received_is_accounted_for_in_the_summary():
    """Received = processed + dropped by the session + arrived as it stopped (after its last
    processing: recorded, not processed), and the summary says so when some did."""
    from rtseg.live.stats import SessionSummary
    src = FakeSource(frames(100_000, 10**9), pace=1.0 / 500.0)
    s, summary = session(src, duration=0.5)
    assert summary.frames_received == (summary.frames_processed + summary.overruns
                                       + summary.overload_drops + summary.unprocessed)
    assert len(s.recorder.frames) == summary.frames_received
    fields = {f: getattr(summary, f) for f in SessionSummary.__dataclass_fields__}
    text = SessionSummary(**{**fields, "unprocessed": 2}).text()
    assert "2 arrived as it stopped (recorded, not processed)" in text
    assert "arrived as it stopped" not in SessionSummary(**{**fields, "unprocessed": 0}).text()
    # a source's damaged frame counters (rtseg.drivers.vendor_seq) are said beside bad input
    damaged = SessionSummary(**{**fields, "source_stats": {"counter_jumps": 3}}).text()
    assert "unknown names (3 damaged frame counters), " in damaged
