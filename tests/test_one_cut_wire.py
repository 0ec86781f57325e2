"""One cut per behaviour change on the wire.

Two real online detectors (the paper's PCA and PPCA passes) run on a synthesised
performance with two behaviour changes; both find each change.  The session's OSC output
goes over a real UDP socket on 127.0.0.1 to a receiver here.  By default only the primary
detector's cuts are sent (``/rtseg/cut``, ``/rtseg/cut/<label>`` and every template), so
one change gives one cue; ``output.cut_methods = "all"`` sends both streams.  Every cut of
both detectors is in the JSON-lines log and the recording, marked ``wire`` true/false.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from osc_collector import OscCollector

from rtseg.config import ConfigError
from rtseg.live.session import LiveSession, wire_methods
from rtseg.recording import read_session_cuts, read_session_header
from rtseg.live.config import from_dict

SCRIPT = "idle:4,walk:5,punch:5"          # changes at frames 480 and 1080 (120 Hz)
CHANGES = (480, 1080)
SOURCE = f"sim://synth?script={SCRIPT}&seed=3&speed=0&space=global"
TEMPLATE = "/cue/{label}/go segment"


def run_session(tmp_path: Path, **output) -> tuple[LiveSession, OscCollector, list[dict]]:
    tmp_path.mkdir(parents=True, exist_ok=True)
    rx = OscCollector()
    log = tmp_path / "events.jsonl"
    rec = tmp_path / "rec"
    cfg = from_dict({"detectors": {"methods": ["pca", "ppca"], **output.pop("detectors", {})},
                     "output": {"osc": [f"127.0.0.1:{rx.port}"], "templates": [TEMPLATE],
                                "jsonl": str(log), **output},
                     "recording": {"dir": str(rec)}}, origin="test")
    try:
        session = LiveSession(SOURCE, cfg, handle_signals=False)
        session.run()
    finally:
        rx.close()
    assert not rx.malformed, "a datagram was not one well-formed OSC message"
    lines = [json.loads(ln) for ln in log.read_text().splitlines()]
    cuts = [d for d in lines if d["type"] == "cut"]
    # the recording's cut log is the JSON-lines log's cuts, wire flags included
    assert [(c.method, c.frame, c.wire) for c in read_session_cuts(rec)] == \
        [(c["method"], c["frame"], c["wire"]) for c in cuts]
    meta = read_session_header(rec)["meta"]         # the recording says what went out
    assert meta["primary"] == session.primary and set(meta["wire_methods"]) == session.wire
    return session, rx, cuts


def per_change(cuts: list[dict], method: str) -> list[int]:
    """Number of ``method`` cuts nearest to each true change."""
    n = [0] * len(CHANGES)
    for c in cuts:
        if c["method"] == method:
            n[min(range(len(CHANGES)), key=lambda i: abs(CHANGES[i] - c["frame"]))] += 1
    return n


def test_default_sends_one_cut_per_change(tmp_path):
    session, rx, cuts = run_session(tmp_path)
    assert session.primary == "pca" and session.wire == {"pca"}
    # both detectors found both changes: without the selection a change would fire twice
    assert per_change(cuts, "pca") == [1, 1] and per_change(cuts, "ppca") == [1, 1], cuts
    wire = rx.args("/rtseg/cut")
    assert len(wire) == 2 and [a[6] for a in wire] == ["pca", "pca"]
    assert [a[0] for a in wire] == [1, 2]                 # wire event numbers consecutive
    assert [a[1] for a in wire] == [1, 2]                 # segments of the primary stream
    assert len(rx.args("/rtseg/cut/pca")) == 2 and not rx.args("/rtseg/cut/ppca")
    assert [a for a in rx.args("/cue/pca/go")] == [[1], [2]] and not rx.args("/cue/ppca/go")
    # nothing lost: every cut is logged, the ones kept off the wire say so
    assert [(c["method"], c["wire"]) for c in cuts if c["wire"]] == [("pca", True)] * 2
    off = [c for c in cuts if not c["wire"]]
    assert [c["method"] for c in off] == ["ppca", "ppca"] and all(c["event"] == 0 for c in off)
    # the wire's boundary times are the logged pca cuts' times
    assert [a[2] for a in wire] == pytest.approx([c["time"] for c in cuts if c["wire"]], abs=1e-4)
    assert 0.0 <= min(a[3] for a in wire) and max(a[3] for a in wire) <= 1.0


def test_all_sends_every_detector(tmp_path):
    session, rx, cuts = run_session(tmp_path, cut_methods="all")
    assert session.wire == {"pca", "ppca"}
    wire = rx.args("/rtseg/cut")
    assert len(wire) == len(cuts) == 4 and all(c["wire"] for c in cuts)
    assert sorted(a[6] for a in wire) == ["pca", "pca", "ppca", "ppca"]
    assert [a[0] for a in wire] == [1, 2, 3, 4]
    assert len(rx.args("/cue/pca/go")) == 2 and len(rx.args("/cue/ppca/go")) == 2


def test_primary_and_list_select_the_stream(tmp_path):
    session, rx, cuts = run_session(tmp_path / "a", detectors={"primary": "ppca"})
    assert [a[6] for a in rx.args("/rtseg/cut")] == ["ppca", "ppca"]
    assert sorted(c["method"] for c in cuts) == ["pca", "pca", "ppca", "ppca"]
    session, rx, cuts = run_session(tmp_path / "b", cut_methods=["ppca"])
    assert session.primary == "pca" and session.wire == {"ppca"}
    assert [a[6] for a in rx.args("/rtseg/cut")] == ["ppca", "ppca"]


@pytest.mark.parametrize("raw,key", [
    ({"detectors": {"methods": ["pca"], "primary": "ppca"}}, "detectors.primary"),
    ({"detectors": {"methods": ["pca"]}, "output": {"cut_methods": ["ppca"]}},
     "output.cut_methods"),
    ({"output": {"cut_methods": "some"}}, "output.cut_methods"),
    ({"output": {"cut_methods": []}}, "output.cut_methods"),
])
def test_bad_selection_refused_at_start(raw, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        cfg = from_dict(raw, origin="test")
        LiveSession("sim://synth", cfg, handle_signals=False)


def test_wire_methods_defaults():
    cfg = from_dict({}, origin="test")
    primary, wire = wire_methods(cfg, ["b", "a"])
    assert primary == "b" and wire == {"b"}
