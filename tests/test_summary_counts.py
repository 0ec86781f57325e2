"""The session summary says what the outputs really did (real sockets on 127.0.0.1)."""

from __future__ import annotations

import socket
from dataclasses import asdict

from rtseg.live.stats import SessionSummary, source_losses_text, targets_text


def _summary(**kw) -> SessionSummary:
    base = dict(duration_s=1.0, frames_received=10, frames_processed=10, frame_rate=10.0,
                cuts=2, cuts_by_method={"pca": 2}, dropped=0, source_stats={}, pipeline={},
                overruns=0, bad_frames=0, max_lag_ms=0.0, cut_latency_ms_p50=None,
                cut_latency_ms_p99=None, recording=None, stop_reason="test", wire_cuts=2)
    base.update(kw)
    return SessionSummary(**base)


def test_no_osc_target_claims_no_sends():
    s = _summary(targets={"jsonl:-": {"sent": 4, "dropped": 0, "errors": 0}})
    assert "sent over OSC" not in s.text() and "no OSC target" in s.text()


def test_dead_tcp_target_is_reported_as_dropped():
    from rtseg.publishers import PublisherSet
    with socket.socket() as probe:      # a port with nobody listening
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    pubs = PublisherSet.from_specs([f"tcp:127.0.0.1:{port}"])
    from rtseg.core.events import CutEvent
    for i in range(3):
        pubs.publish_cut(CutEvent(event=i + 1, segment=i + 1, frame=10 * i, time=0.1 * i,
                                  method="pca"))
    pubs.close()
    s = _summary(targets=pubs.stats())
    text = targets_text(s.targets)
    (key, st), = s.targets.items()
    assert st["sent"] == 0 and st["dropped"] >= 3
    assert f"{key}: 0 messages sent, {st['dropped']} dropped" in text


def test_source_refusals_are_in_the_summary():
    text = _summary(source_stats={"other_senders": 40, "corrupt": 3, "clock_restarts": 1}).text()
    assert "40 from a second sender" in text and "1 source clock restarts" in text
    assert "3 corrupt" in source_losses_text({"corrupt": 3})


def test_gap_costs_are_in_the_summary():
    text = _summary(pipeline={"bridged_gaps": 4, "filled_frames": 9, "restarts": 2,
                              "discarded_cuts": 1}).text()
    assert "gaps: 4 bridged (9 frames filled), 2 detector restarts, 1 cuts discarded" in text
    assert "gaps:" not in _summary(pipeline={"restarts": 0}).text()


def test_the_cuts_the_relative_floor_held_back_are_counted():
    s = _summary(cuts_by_method={"contrast": 2}, floored={"contrast": 4})
    assert "contrast relative floor held back 4" in s.text()
    assert s.as_dict()["floored"] == {"contrast": 4}
    assert "relative floor" not in _summary(floored={"contrast": 0}).text()


def test_the_identity_summary_says_how_many_names_the_performers_scale_judged():
    """The session summary's identity part names the decisions whose threshold the
    performer's scale raised, and the largest factor; nothing when none was."""
    from rtseg.identity.messages import IdentityStats
    from rtseg.live.stats import identity_text
    counts = asdict(IdentityStats(decisions=6, new_behaviours=4, named=3, names_unknown=3))
    assert "performer's scale" not in identity_text(counts)
    counts.update(names_scaled=4, largest_scale=2.4)
    text = identity_text(counts)
    assert "3 named, 3 unknown" in text
    assert "4 with the performer's scale (the threshold up to x 2.40)" in text
    assert "name_threshold_scale" not in text
    counts.update(name_threshold_scale=1.5)
    assert "the library's threshold x 1.5 ([identity] name_threshold_scale)" in identity_text(counts)


def test_the_identity_summary_says_how_many_decisions_the_first_look_made():
    from rtseg.identity.messages import IdentityStats
    from rtseg.live.stats import identity_text
    counts = asdict(IdentityStats(decisions=6, new_behaviours=4, named=3, names_unknown=3))
    assert "first look" not in identity_text(counts)
    counts.update(first_look_names=2, first_look_waits=4)
    assert "2 decided at the first look ([identity] first_name_after_s)" in identity_text(counts)
