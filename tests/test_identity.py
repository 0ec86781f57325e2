"""Behaviour identity (rtseg.identity.tracker): exact ids on synthetic performances with recurring
behaviours, one decision per segment within the bound, counted corrections, the OSC
messages over a real UDP socket, a live session's JSON lines and recording, and the
``rtseg evaluate --online --identity`` JSON."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rtseg.core.events import BehaviourEvent, CutEvent, event_from_dict
from rtseg.identity.tracker import IdentityTracker
from rtseg.evaluation.identity import replay_session_identities, run_identity
from rtseg.live.session import LiveSession
from rtseg.evaluation.online import live_config
from rtseg.publishers import PublisherSet, parse_target
from rtseg.recording import read_session_behaviours
from rtseg.live.config import from_dict
from rtseg.simulators.synth.motion import synthesize

from osc_collector import OscCollector
from synth_identity import SYNTH_DETECTOR, SYNTH_THRESHOLD
from take_source import TakeSource

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SCRIPT = "walk:6,punch:6,walk:6,punch:6,squat:6"


def _config(**identity):
    """The live configuration with identity on, ``identity`` keys set, and the detector
    settings of the synthetic tests (``SYNTH_DETECTOR``)."""
    cfg, _ = live_config()
    cfg["identity.enabled"] = True
    cfg["detectors.contrast"] = dict(SYNTH_DETECTOR)
    for k, v in identity.items():
        cfg[f"identity.{k}"] = v
    return cfg


def _segment_names(res, tracker, cuts):
    """Majority true behaviour of each live segment (0 = before the first cut)."""
    names = np.array(res.frame_names())
    bounds = [0, *cuts, len(names)]
    out = []
    for a, e in zip(bounds[:-1], bounds[1:]):
        v, c = np.unique(names[a:e], return_counts=True)
        out.append(str(v[c.argmax()]))
    return out


@pytest.mark.parametrize("seed", [0, 1, 3])
def test_recurring_behaviours_get_exact_identities(seed):
    res = synthesize(SCRIPT, seed=seed)
    run = run_identity(res.take, _config(threshold=SYNTH_THRESHOLD))
    tr = run.tracker
    assert len(run.cut_frames) == 4, "the synthetic changes should all be cut"
    truth = _segment_names(res, tr, run.cut_frames)
    assert truth == ["walk", "punch", "walk", "punch", "squat"]
    ids = {m.segment: m.behaviour for m in tr.history}
    got = [ids[s] for s in range(5)]
    assert got == [1, 2, 1, 2, 3], f"walk, punch, walk, punch, squat got ids {got}"
    assert tr.stats.corrections == 0
    # per-frame labels follow the segments
    lab = tr.frame_labels(res.take.n_frames)
    assert lab[0] == 1 and lab[run.cut_frames[1]] == 1 and lab[-1] == 3


def test_a_new_behaviour_is_not_forced_onto_an_old_one():
    res = synthesize("walk:6,squat:6,punch:6", seed=0)
    run = run_identity(res.take, _config(threshold=SYNTH_THRESHOLD))
    assert [m.behaviour for m in run.tracker.history] == [1, 2, 3]
    assert all(m.new for m in run.tracker.history)


def test_decision_sent_once_within_the_bound():
    res = synthesize(SCRIPT, seed=2)
    cfg = _config(threshold=SYNTH_THRESHOLD, decide_after_s=1.5)
    from rtseg.live.pipeline import Pipeline
    take = res.take
    fr = take.frame_rate
    pipe = Pipeline(take.joint_names, take.parents, take.space, fr, cfg)
    tr = pipe.identity
    detected = {}
    decided_at = {}
    for i in range(take.n_frames):
        for c in pipe.process(i, take.quats[i], np.ones(take.n_joints, bool), i, i / fr, 0, i / fr):
            detected[c.boundary] = c.detected
        for m in tr.drain():
            assert not m.correction
            assert m.segment not in decided_at, "a decision is sent once"
            assert m.decided_frame == i, "a message is drained at the frame that made it"
            decided_at[m.segment] = (m.boundary, i)
    assert sorted(decided_at) == list(range(len(detected) + 1))
    need = int(math.ceil(1.5 * fr))
    for seg, (b, i) in decided_at.items():
        # at least decide_after_s of the segment, from its boundary rounded to the nearest
        # block start, is summed
        assert i - b + 1 >= need - tr.block // 2, (seg, b, i)
        due = max(b + need, detected.get(b, b))
        assert i <= due + tr.block, f"segment {seg} decided at {i}, due at {due}"


@pytest.mark.parametrize("seed", [2, 5])
def test_quiet_frames_hide_no_cut_and_no_behaviour_message(seed):
    """Pipeline.quiet_frames with identity on: none of the next that many frames reveals
    a cut or makes an identity message (the live loop reads them late, in one batch);
    about one frame in a block of each may, so most frames are still quiet."""
    res = synthesize(SCRIPT, seed=seed)
    from rtseg.live.pipeline import Pipeline
    take = res.take
    fr = take.frame_rate
    pipe = Pipeline(take.joint_names, take.parents, take.space, fr,
                    _config(threshold=SYNTH_THRESHOLD, decide_after_s=1.5))
    quiet, out = [], []
    ok = np.ones(take.n_joints, bool)
    for i in range(take.n_frames):
        quiet.append(pipe.quiet_frames())
        cuts = pipe.process(i, take.quats[i], ok, i, i / fr, 0, i / fr)
        messages = pipe.identity.drain()
        if cuts or messages:
            out.append(i)
    assert len(out) >= 4
    for i, q in enumerate(quiet):
        assert not any(i <= o < i + q for o in out), (i, q, out)
    assert np.mean(np.array(quiet) > 0) > 0.7


def _blob(rng, n, basis, scale):
    z = rng.standard_normal((n, basis.shape[1])) * scale
    return z @ basis.T + 0.01 * rng.standard_normal((n, basis.shape[0]))


def test_a_correction_is_sent_once_and_counted():
    """Segment 1 starts like behaviour A for 2 s (decided: A), then is B for 10 s: at the
    next cut the whole segment overturns the decision once."""
    rng = np.random.default_rng(5)
    d = 6
    A = np.linalg.qr(rng.standard_normal((d, d)))[0]
    a_basis, b_basis = A[:, :3], A[:, 3:]
    fr = 100.0
    tr = IdentityTracker(fr, "x", decide_after_s=1.5, max_window_s=2.0, threshold=4.0)
    X = np.concatenate([_blob(rng, 800, a_basis, 1.0),          # segment 0: A
                        _blob(rng, 200, a_basis, 1.0),          # segment 1 begins like A
                        _blob(rng, 1000, b_basis, 1.0),         # ... and is B
                        _blob(rng, 600, a_basis, 1.0)])         # segment 2: A again
    cuts = {1000: 800, 2200: 2000}     # detected frame -> boundary (cut arrives 2 s late)
    for i, x in enumerate(X):
        tr.step(i, x, [])
        if i in cuts:
            tr.on_cut(cuts[i], i, "x")
    dec = [(m.segment, m.behaviour, m.correction, m.previous) for m in tr.history]
    assert dec[0] == (0, 1, False, 0)
    assert dec[1] == (1, 1, False, 0), "the first 2 s of segment 1 look like A"
    assert (1, 2, True, 1) in dec, "the whole segment is a new behaviour: corrected to 2"
    assert tr.stats.corrections == 1
    assert sum(1 for m in tr.history if m.segment == 1 and m.correction) == 1
    assert dec[-1][:3] == (2, 1, False), "A comes back as id 1"
    lab = tr.frame_labels(len(X))
    labc = tr.frame_labels(len(X), corrected=True)
    assert lab[1500] == 1 and labc[1500] == 2


def test_an_identity_failure_never_costs_a_cut():
    """A tracker that raises is counted and logged; the frame's cuts still come out."""
    from rtseg.live.pipeline import Pipeline
    res = synthesize("walk:6,punch:6", seed=0)
    take = res.take
    cfg = _config(threshold=SYNTH_THRESHOLD)
    pipe = Pipeline(take.joint_names, take.parents, take.space, take.frame_rate, cfg)

    class Broken:
        def step(self, index, x, cuts):
            raise RuntimeError("boom")
    pipe.identity = Broken()
    cuts = []
    for i in range(take.n_frames):
        cuts += pipe.process(i, take.quats[i], np.ones(take.n_joints, bool), i)
    assert len(cuts) == 1
    assert pipe.stats.identity_errors == pipe.stats.fed


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="threshold"):
        IdentityTracker(120.0, threshold=0)
    with pytest.raises(ValueError, match="decide_after_s"):
        IdentityTracker(120.0, decide_after_s=0)
    from rtseg.config import ConfigError
    with pytest.raises(ConfigError, match="name_after_s"):
        from_dict({"identity": {"name_after_s": 0.0}})
    with pytest.raises(Exception, match="identity.threshold"):
        from_dict({"identity": {"threshold": 0.5}})


# ------------------------------------------------------------------------ on the wire
def test_behaviour_messages_over_udp_with_templates():
    rx = OscCollector()
    port = rx.port
    pub = parse_target(f"udp:127.0.0.1:{port},template=/cue/{{label}}/start")
    pubs = PublisherSet([pub])
    try:
        cut = CutEvent(event=1, segment=1, frame=700, time=5.8, method="contrast")
        pubs.publish_cut(cut)
        before = rx.take(3)          # identity off: /rtseg/cut, /rtseg/cut/<label>, cue
        assert [a for a, _ in before] == ["/rtseg/cut", "/rtseg/cut/contrast",
                                          "/cue/contrast/start"]
        pubs.templates_on_behaviour()
        pubs.publish_cut(cut)
        dec = BehaviourEvent(event=1, segment=1, behaviour="2", name="2", confidence=0.75,
                             frame=700, decided_frame=990, time=8.2)
        pubs.publish_behaviour(dec)
        cor = BehaviourEvent(event=2, segment=1, behaviour="1", name="1", confidence=0.5,
                             frame=700, decided_frame=1500, time=12.5, correction=True,
                             previous="2")
        pubs.publish_behaviour(cor)
        got = rx.take(6)
    finally:
        pubs.close()
        rx.close()               # waits for stragglers: nothing more may have come
    assert rx.untaken == 0 and not rx.malformed
    addrs = [a for a, _ in got]
    # identity on: the cut no longer fires the template; the behaviour messages do
    assert addrs == ["/rtseg/cut", "/rtseg/cut/contrast", "/rtseg/behaviour", "/cue/2/start",
                     "/rtseg/behaviour/correct", "/cue/1/start"]
    assert got[2][1] == [1, 1, "2", "2", pytest.approx(0.75)]
    assert got[4][1] == [2, 1, "1", "1", pytest.approx(0.5), "2"]


def test_behaviour_event_json_round_trip():
    ev = BehaviourEvent(event=3, segment=2, behaviour="1", name="1", confidence=0.4,
                        frame=10, decided_frame=300, time=2.5, correction=True, previous="4")
    d = json.loads(json.dumps(ev.to_dict()))
    assert d["type"] == "behaviour"
    back = event_from_dict(d)
    assert isinstance(back, BehaviourEvent) and back.previous == "4" and back.correction


def test_live_session_sends_records_and_logs_identities(tmp_path):
    res = synthesize(SCRIPT, seed=0)
    rx = OscCollector(linger=0.5)
    port = rx.port
    rec = tmp_path / "session"
    log = tmp_path / "events.jsonl"
    cfg = from_dict({"identity": {"enabled": True, "threshold": SYNTH_THRESHOLD},
                     "output": {"osc": [f"127.0.0.1:{port}"], "jsonl": str(log),
                                "templates": ["/cue/{label}/start"]},
                     "recording": {"dir": str(rec)}, "status": {"interval": 60.0}})
    session = LiveSession(TakeSource(res.take), cfg, handle_signals=False)
    try:
        summary = session.run()
    finally:
        rx.close()
    assert not rx.malformed
    msgs = [(a, args) for a, _, args in rx.messages]
    assert summary.frames_processed == res.take.n_frames and summary.overruns == 0
    beh = [p for a, p in msgs if a == "/rtseg/behaviour"]
    assert [p[2] for p in beh] == ["1", "2", "1", "2", "3"]
    assert [p[1] for p in beh] == [0, 1, 2, 3, 4]
    assert [p[0] for p in beh] == [1, 2, 3, 4, 5]
    # the session summary counts them: five decisions, three ids, no library
    assert summary.identity["decisions"] == 5 and summary.identity["new_behaviours"] == 3
    assert summary.identity["named"] == summary.identity["names_unknown"] == 0
    assert "5 behaviour decisions (3 ids, " in summary.text()
    cues = [a for a, _ in msgs if a.startswith("/cue/")]
    assert cues == ["/cue/1/start", "/cue/2/start", "/cue/1/start", "/cue/2/start",
                    "/cue/3/start"]
    # every cut precedes the behaviour message of the segment it starts
    order = [a for a, _ in msgs if a in ("/rtseg/cut", "/rtseg/behaviour")]
    assert order[:2] == ["/rtseg/behaviour", "/rtseg/cut"]
    lines = [json.loads(line) for line in log.read_text().splitlines()]
    assert [d["behaviour"] for d in lines if d["type"] == "behaviour"] == ["1", "2", "1", "2", "3"]
    recorded = read_session_behaviours(rec)
    assert [(b.segment, b.behaviour) for b in recorded] == [(s, p[2]) for p in beh
                                                            for s in [p[1]]]
    # the recording replayed offline gives the same identities (deterministic pipeline)
    offline = replay_session_identities(str(rec), cfg).history
    assert [(m.segment, m.behaviour) for m in offline] == [(b.segment, int(b.behaviour))
                                                           for b in recorded]


# ------------------------------------------------------------------------ evaluate
@pytest.mark.skipif(not (DATA / "cmu" / "86_01.amc").is_file(),
                    reason="needs ../shared/data (CMU 86_01 with labels)")
def test_evaluate_identity_json(tmp_path):
    data = tmp_path / "data"
    (data / "cmu").mkdir(parents=True)
    (data / "labels").mkdir()
    for f in ("cmu/86.asf", "cmu/86_01.amc", "labels/cmu86_transitions.txt"):
        os.symlink(DATA / f, data / f)
    out = subprocess.run([sys.executable, "-m", "rtseg.cli", "evaluate", str(data), "--online",
                          "--identity", "--json", "--no-progress", "--group", "cmu"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    ident = doc["identity"]
    assert set(ident["pooled"]) == {"ari", "nmi", "decision_delay_s"}
    # pooled decision delay: one take, so its decisions' median is the take's
    d = ident["pooled"]["decision_delay_s"]
    assert d["after_transition_median"] == ident["takes"]["86_01"]["decision_delay_s"][
        "after_transition_median"]
    assert d["decisions"] >= 5 and 0 < d["after_transition_median"] <= d["after_transition_p90"]
    assert list(ident["takes"]) == ["86_01"]
    t = ident["takes"]["86_01"]
    assert t["true_behaviours"] == 4             # walk, jump, punch, leg_kick
    assert -1 <= t["ari"] <= 1 and 0 <= t["nmi"] <= 1
    assert t["ari"] == pytest.approx(ident["pooled"]["ari"])   # one take: pooled = the take
    assert t["segments"] >= 6
    assert doc["live_default"] == "contrast"


class _LengthLibrary:
    """Stands in for a behaviour library: names a window ``name`` once it holds at least
    ``rows`` rows, else ``unknown`` (as a real library rejects windows too short to say)."""

    def __init__(self, dims: int, rows: int, name: str = "walk") -> None:
        self.dims, self.rows, self.label = dims, rows, name
        self.calls: list[int] = []

    def name(self, W, frame_rate=None):
        from rtseg.library.behaviours import UNKNOWN, Naming
        self.calls.append(len(W))
        nm = self.label if len(W) >= self.rows else UNKNOWN
        return Naming(nm, self.label, 1.0, 0.5)


def _segment1_after_a_late_cut(tr, d: int, rng, boundary: int = 1200) -> list:
    """Random rows of ``d`` dims into tracker ``tr`` for ``boundary`` + 400 frames, a cut
    at ``boundary`` revealed 0.5 s (60 frames) late; the messages of segment 1."""
    for i in range(boundary + 400):
        tr.update(i, rng.normal(size=d))
        if i == boundary + 60:
            tr.on_cut(boundary, i)
    return [m for m in tr.history if m.segment == 1]


@pytest.mark.parametrize("rows, decided_after, name, waits", [
    (60, 180, "walk", 0),       # named at the first attempt: 1.5 s of the segment
    (150, 240, "walk", 2),      # unknown at 1.5 s, named at 2.0 s: the decision waited
    (10_000, 240, "unknown", 2),    # unknown either way: decided at name_after_s, unknown
])
def test_a_library_decision_waits_only_for_segments_it_cannot_name_yet(rows, decided_after,
                                                                        name, waits):
    """With a library the segment is decided at decide_after_s (1.5 s) when the library
    names it then; a segment it would call ``unknown`` waits for name_after_s (2.0 s) and
    is decided then whatever the answer (named window: boundary + 0.5 s on)."""
    fr, d = 120.0, 8
    lib = _LengthLibrary(d, rows)
    tr = IdentityTracker(fr, library=lib, decide_after_s=1.5, name_after_s=2.0)
    boundary = 1200
    seg1 = _segment1_after_a_late_cut(tr, d, np.random.default_rng(0), boundary)
    assert len(seg1) == 1
    assert seg1[0].decided_frame - boundary == decided_after - 1
    assert seg1[0].name == name
    # segment 0 (120 named rows at its first attempt) waits as segment 1 does
    assert tr.stats.name_waits == waits


class _StrictnessLibrary:
    """Stands in for a behaviour library: names every window ``walk`` when its threshold's
    factor (``scale``) is at least ``need``, else ``unknown`` - a segment that lies at
    ``need`` x the threshold."""

    def __init__(self, dims: int, need: float) -> None:
        self.dims, self.need = dims, need
        self.scales: list[float] = []

    def name(self, W, frame_rate=None, scale: float = 1.0):
        from rtseg.library.behaviours import UNKNOWN, Naming
        self.scales.append(scale)
        nm = "walk" if scale >= self.need else UNKNOWN
        return Naming(nm, "walk", self.need, 0.5)


@pytest.mark.parametrize("need, decided_after, name, first_names", [
    (0.5, 180, "walk", 1),      # within 0.8 x the threshold: named at the first look, 1.5 s
    (0.9, 300, "walk", 0),      # named by the threshold only: decided at 2.5 s, as without
    (2.0, 300, "unknown", 0),   # beyond it: decided at 2.5 s, unknown
])
def test_a_first_look_decides_a_segment_named_well_within_the_threshold(need, decided_after,
                                                                         name, first_names):
    """``first_name_after_s`` 1.5 s with ``first_name_scale`` 0.8: a segment the library
    names within 0.8 x its threshold 1.5 s in is decided then (id and name); any other
    waits for ``decide_after_s`` (2.5 s) and the library's own threshold."""
    fr, d = 120.0, 8
    lib = _StrictnessLibrary(d, need)
    tr = IdentityTracker(fr, library=lib, decide_after_s=2.5, name_after_s=2.5,
                         first_name_after_s=1.5, first_name_scale=0.8)
    rng = np.random.default_rng(0)
    boundary = 1200
    seg1 = _segment1_after_a_late_cut(tr, d, rng, boundary)
    assert len(seg1) == 1 and seg1[0].name == name
    assert seg1[0].decided_frame - boundary == decided_after - 1
    assert set(lib.scales) <= {0.8, 1.0} and 0.8 in lib.scales
    # segment 0 and segment 1 alike
    assert tr.stats.first_look_names == 2 * first_names
    assert tr.stats.first_look_waits == 2 * (1 - first_names)
    # without a library there is no first look: the id is decided at decide_after_s
    plain = IdentityTracker(fr, decide_after_s=2.5, first_name_after_s=1.5)
    seg1 = _segment1_after_a_late_cut(plain, d, rng, boundary)
    assert seg1[0].decided_frame - boundary == 300 - 1


def test_the_first_look_and_the_library_threshold_are_read_from_the_configuration():
    """``[identity] first_name_after_s``, ``first_name_scale`` and ``library_threshold``
    reach the tracker; the ids' threshold is ``library_threshold`` only with a library
    (0: ``threshold``); bad values are refused with one line naming the key."""
    from rtseg.config import ConfigError
    from rtseg.identity.tracker import tracker_options
    opts = tracker_options(_config())
    assert (opts["first_name_after_s"], opts["first_name_scale"], opts["library_threshold"]) \
        == (0.0, 1.0, None)
    opts = tracker_options(_config(first_name_after_s=1.5, first_name_scale=0.9,
                                   library_threshold=4.0, threshold=5.0))
    with_lib = IdentityTracker(120.0, "contrast", library=_StrictnessLibrary(4, 1.0), **opts)
    assert with_lib.threshold == 4.0 and with_lib.first_name_scale == 0.9
    assert IdentityTracker(120.0, "contrast", **opts).threshold == 5.0
    for key, bad in (("first_name_scale", 1.5), ("first_name_scale", 0.0),
                     ("first_name_after_s", -1.0), ("library_threshold", -2.0)):
        with pytest.raises(ConfigError, match=key):
            from_dict({"identity": {key: bad}}, origin="test")
    with pytest.raises(ValueError, match="first_name_scale"):
        IdentityTracker(120.0, first_name_after_s=1.5, first_name_scale=2.0)


class _OneNameLibrary(_LengthLibrary):
    """A stand-in library that names every window ``walk``, whatever it holds."""

    def __init__(self, dims: int) -> None:
        super().__init__(dims, 0)


@pytest.mark.parametrize("exclusive, names, contested", [
    (True, ["walk", "unknown", "walk"], 1),
    (False, ["walk", "walk", "walk"], 0),
])
def test_a_name_held_by_another_behaviour_id_is_sent_as_unknown(exclusive, names, contested):
    """Behaviours A, B, A: the library calls all three ``walk``; the tracker gives B its own
    id, so with exclusive names B's ``walk`` conflicts with A's and goes out ``unknown``,
    while A's return (A's id again) keeps the name."""
    tr, sent = _a_b_a(lambda d, A: _OneNameLibrary(d), exclusive_names=exclusive)
    assert [b for b, _ in sent] == [1, 2, 1]
    assert [n for _, n in sent] == names
    assert tr.stats.names_contested == contested


def _a_b_a(library, **options):
    """Behaviours A, B, A (8 s each, 100 Hz, cut 1 s late) named by ``library(d, A)`` (A:
    the directions' basis, A's in its first three columns): the tracker and the first
    decisions sent, (id, name)."""
    rng = np.random.default_rng(5)
    d, fr = 6, 100.0
    A = np.linalg.qr(rng.standard_normal((d, d)))[0]
    X = np.concatenate([_blob(rng, 800, A[:, :3], 1.0), _blob(rng, 800, A[:, 3:], 1.0),
                        _blob(rng, 800, A[:, :3], 1.0)])
    tr = IdentityTracker(fr, "x", decide_after_s=1.5, threshold=4.0, library=library(d, A),
                         **options)
    cuts = {900: 800, 1700: 1600}
    for i, x in enumerate(X):
        tr.update(i, x)
        if i in cuts:
            tr.on_cut(cuts[i], i, "x")
    return tr, [(m.behaviour, m.name) for m in tr.history if not m.correction]


class _TwoDistanceLibrary(_LengthLibrary):
    """Names every window ``walk``, at distance 1.0 when its energy lies mostly in the
    directions ``basis`` spans, else at ``other``."""

    def __init__(self, dims: int, basis: np.ndarray, other: float) -> None:
        super().__init__(dims, 0)
        self.basis, self.other = basis, other

    def name(self, W, frame_rate=None):
        from rtseg.library.behaviours import Naming
        W = np.asarray(W)
        inside = np.sum((W @ self.basis) ** 2) / np.sum(W ** 2)
        return Naming("walk", "walk", 1.0 if inside > 0.5 else self.other, 0.5)


@pytest.mark.parametrize("other, names, claimed", [
    (0.5, ["walk", "walk", "walk"], 1),      # B is twice as near to walk as A: it may hold it
    (0.95, ["walk", "unknown", "walk"], 0),  # nearer, but not by CLAIM_MARGIN: refused
])
def test_a_segment_clearly_nearer_to_a_held_name_than_its_holders_gets_it(other, names, claimed):
    """Behaviours A, B, A with exclusive names: B's id may share A's ``walk`` only when B
    lies clearly nearer to it (distance below CLAIM_MARGIN x A's)."""
    from rtseg.identity.names import CLAIM_MARGIN
    assert 0.5 < CLAIM_MARGIN < 0.95
    tr, sent = _a_b_a(lambda d, A: _TwoDistanceLibrary(d, A[:, :3], other))
    assert [b for b, _ in sent] == [1, 2, 1]
    assert [n for _, n in sent] == names
    assert tr.stats.names_claimed == claimed
    assert tr.stats.names_contested == 1 - claimed


def test_exclusive_names_is_read_from_the_configuration():
    """``[identity] exclusive_names`` reaches the tracker the live pipeline builds."""
    from rtseg.identity.tracker import tracker_from_config
    assert tracker_from_config(_config(), 120.0, "contrast").exclusive_names is True
    assert tracker_from_config(_config(exclusive_names=False), 120.0, "contrast").exclusive_names is False


def test_the_claim_margin_is_read_from_the_configuration_and_checked():
    """``[identity] claim_margin`` reaches the names the tracker grants; a value outside
    0-1 is refused with one line naming the key."""
    from rtseg.config import ConfigError
    from rtseg.identity.tracker import tracker_from_config
    from rtseg.live.config import from_dict
    tr, sent = _a_b_a(lambda d, A: _TwoDistanceLibrary(d, A[:, :3], 0.5),
                      **{"claim_margin": 0.0})
    assert [n for _, n in sent] == ["walk", "unknown", "walk"]       # 0: never claimed
    tr = tracker_from_config(_config(claim_margin=0.3), 120.0, "contrast")
    assert tr._holders.claim_margin == 0.3
    with pytest.raises(ConfigError, match="claim_margin"):
        from_dict({"identity": {"claim_margin": 1.5}}, origin="test")


def test_the_name_threshold_scale_is_read_from_the_configuration_and_checked():
    """``[identity] name_threshold_scale`` reaches the tracker's namer; 0 or a negative
    factor is refused with one line naming the key."""
    from rtseg.config import ConfigError
    from rtseg.identity.tracker import IdentityTracker, tracker_options
    from rtseg.live.config import from_dict
    assert tracker_options(_config())["name_threshold_scale"] == 1.0
    opts = tracker_options(_config(name_threshold_scale=1.5))
    tr = IdentityTracker(120.0, "contrast", library=_TwoDistanceLibrary(4, np.zeros((1, 3)), 0.5),
                         **opts)
    assert tr.namer.threshold_scale == 1.5
    for bad in (0.0, -1.0, 11.0):
        with pytest.raises(ConfigError, match="name_threshold_scale"):
            from_dict({"identity": {"name_threshold_scale": bad}}, origin="test")
    with pytest.raises(ValueError, match="name_threshold_scale"):
        IdentityTracker(120.0, "contrast", name_threshold_scale=0.0)


def test_a_correction_to_the_id_that_holds_the_name_gives_the_name_back():
    """Segment 1 starts with one of A's three directions turned a right angle (its own id;
    the library's ``walk`` is held by A's id, so it goes out ``unknown``), then is A for
    15 s: the correction to A's id carries ``walk`` again, counted in ``names_restored``."""
    rng = np.random.default_rng(5)
    d, fr = 6, 100.0
    A = np.linalg.qr(rng.standard_normal((d, d)))[0]
    T = A.copy()
    T[:, 2] = A[:, 3]

    def blob(n, basis):
        return (rng.standard_normal((n, 3)) @ basis.T
                + 0.1 * rng.standard_normal((n, d)))
    X = np.concatenate([blob(800, A[:, :3]),           # segment 0: A
                        blob(160, T[:, :3]),           # segment 1 begins turned
                        blob(1500, A[:, :3]),          # ... and is A
                        blob(600, A[:, 3:])])          # segment 2: another behaviour
    tr = IdentityTracker(fr, "x", decide_after_s=1.5, threshold=4.0,
                         library=_OneNameLibrary(d))
    cuts = {900: 800, 2560: 2460}
    for i, x in enumerate(X):
        tr.update(i, x)
        if i in cuts:
            tr.on_cut(cuts[i], i, "x")
    seg1 = [(m.behaviour, m.name, m.correction) for m in tr.history if m.segment == 1]
    assert seg1 == [(2, "unknown", False), (1, "walk", True)]
    seg2 = [m for m in tr.history if m.segment == 2]
    assert seg2[0].name == "unknown" and seg2[0].behaviour not in (1, 2)   # contested too
    assert tr.stats.names_contested == 2 and tr.stats.names_restored == 1
