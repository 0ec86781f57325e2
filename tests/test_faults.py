"""Fault configuration parsing and the deterministic, recording fault injector."""

from __future__ import annotations

import numpy as np
import pytest

from rtseg.simulators.faults import Dropout, FaultConfig, FaultInjector


def test_parse_cli_form():
    cfg = FaultConfig.parse(
        "corrupt=0.01,drop=0.02,jitter=0.002,dropout=5:2.0:1.0,dropout=LeftHand:1:0.5:4,"
        "unplug=10:0.5,seed=9")
    assert cfg.corrupt_byte_rate == 0.01 and cfg.drop_frame_rate == 0.02
    assert cfg.jitter_s == 0.002 and cfg.seed == 9
    assert cfg.dropouts == [Dropout(5, 2.0, 1.0), Dropout("LeftHand", 1.0, 0.5, 4.0)]
    assert cfg.unplug_every_s == 10 and cfg.unplug_for_s == 0.5
    assert FaultConfig.parse(cfg.to_spec()) == cfg
    assert not FaultConfig.parse("").enabled and cfg.enabled


@pytest.mark.parametrize("spec, match", [
    ("corrupt", "key=value"),
    ("corrupt=lots", "corrupt=lots"),
    ("corrupt=1.5", "0..1"),
    ("dropout=5:2", "SENSOR:START:DURATION"),
    ("explode=1", "unknown fault"),
    ("jitter=-1", "jitter"),
])
def test_parse_errors_name_the_item(spec, match):
    with pytest.raises(ValueError, match=match):
        FaultConfig.parse(spec)


def test_schedules():
    inj = FaultInjector("dropout=5:2.0:1.0,dropout=7:1:0.5:4,unplug=10:0.5")
    assert inj.silent_sensors(1.9) == set()
    assert inj.silent_sensors(2.5) == {5}
    assert inj.silent_sensors(5.2) == {7}  # periodic: 1, 5, 9, ...
    assert inj.silent_sensors(5.6) == set()
    assert not inj.unplugged(0.2) and not inj.unplugged(9.9)
    assert inj.unplugged(10.1) and not inj.unplugged(10.6) and inj.unplugged(20.4)


def test_injector_is_deterministic_and_records_exactly():
    data = bytes(range(1, 201))
    runs = []
    for _ in range(2):
        inj = FaultInjector("corrupt=0.01,drop=0.1,jitter=0.01,seed=4")
        outs = [inj.process(i, data) for i in range(300)]
        runs.append((outs, [inj.jitter() for _ in range(5)], inj.snapshot()))
    assert runs[0][0] == runs[1][0] and runs[0][1] == runs[1][1]
    outs, jit, rec = runs[0]
    assert all(0 <= j <= 0.01 for j in jit)
    assert sorted(rec.intact + rec.dropped + list(rec.corrupted)) == list(range(300))
    for i, out in enumerate(outs):
        if i in rec.dropped:
            assert out is None
        elif i in rec.intact:
            assert out == data
        else:
            diff = np.flatnonzero(np.frombuffer(out, np.uint8) != np.frombuffer(data, np.uint8))
            assert diff.tolist() == rec.corrupted[i]  # every recorded byte really changed
    assert 10 < len(rec.dropped) < 60 and len(rec.corrupted) > 100


def test_corruption_stream_independent_of_other_faults():
    """Adding jitter must not change which bytes get corrupted."""
    data = bytes(100)
    a = FaultInjector("corrupt=0.05,seed=1")
    b = FaultInjector("corrupt=0.05,jitter=0.1,seed=1")
    for i in range(50):
        b.jitter()
        assert a.process(i, data) == b.process(i, data)


def test_mark_lost_moves_the_record():
    inj = FaultInjector("seed=0")
    inj.process(0, b"abc")
    inj.mark_lost(0, "overflow")
    inj.mark_lost(1, "unplugged")
    rec = inj.snapshot()
    assert rec.intact == [] and rec.lost == {0: "overflow", 1: "unplugged"}


def test_take_record_hands_over_and_starts_empty():
    inj = FaultInjector("corrupt=0.2,drop=0.1,seed=3")
    for i in range(200):
        inj.process(i, bytes(4))
    whole = inj.snapshot()
    first = inj.take_record()
    assert (first.intact, first.corrupted, first.dropped) == (whole.intact, whole.corrupted, whole.dropped)
    assert first.intact and first.corrupted and first.dropped
    assert inj.record.intact == [] and inj.record.corrupted == {} and inj.record.dropped == []
    for i in range(200, 260):
        inj.process(i, bytes(4))
    later = inj.take_record()
    seen = set(later.intact) | set(later.corrupted) | set(later.dropped)
    assert seen == set(range(200, 260))
