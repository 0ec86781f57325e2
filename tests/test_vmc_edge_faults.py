"""VMC faults at the edges over real UDP sockets on 127.0.0.1: truncated bundles are dropped
whole, never used in part."""

from __future__ import annotations

import socket
import struct
import time

import numpy as np
import pytest

from rtseg.drivers import open_source
from rtseg.drivers.osc.vmc.codec import VmcAssembler, bundle_structure_error, encode_frame

from tests.test_vmc_live import SUIT, make_take, read_all, same_rotation
from tests.test_vmc_live import source  # noqa: F401  (the fixture: a VMC source on port 0)


def _frame_datagrams(take, i: int) -> list[bytes]:
    return encode_frame(take.quats[i], SUIT, time=i / 60.0,
                        root_position=take.root_position[i], max_datagram=60000)


def test_truncated_bundles_are_dropped_whole_over_udp(source):
    take = make_take(60, seed=5)
    addr = ("127.0.0.1", source.port)
    rng = np.random.default_rng(1)
    n_bad = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        for i in range(len(take.quats)):
            dgrams = _frame_datagrams(take, i)
            assert len(dgrams) == 1, "one whole frame per datagram in this test"
            whole = dgrams[0]
            if i % 3 == 1:
                # a truncated copy of the next frame's bundle: elements before the cut parse
                cut = 4 * int(rng.integers(8, len(whole) // 4 - 1))
                bad = _frame_datagrams(take, min(i + 1, len(take.quats) - 1))[0][:cut]
                assert bundle_structure_error(bad, 0, len(bad), 0) is not None
                out.sendto(bad, addr)
                n_bad += 1
            out.sendto(whole, addr)
            time.sleep(0.002)
        frames = read_all(source)
    assert len(frames) == len(take.quats)          # no phantom frame from a partial bundle
    for i, f in enumerate(frames):
        assert f.source_time == pytest.approx(i / 60.0, abs=1e-5)
        assert bool(f.valid.all())
        assert same_rotation(f.quats, take.quats[i], atol=1e-6)
    assert source.stats.corrupt == n_bad
    assert source.stats.dropped == 0


def _element_cuts(bundle: bytes) -> list[int]:
    """Offsets at which the bundle's elements end (a cut there still parses)."""
    pos, out = 16, []
    while pos < len(bundle):
        pos += 4 + struct.unpack_from(">i", bundle, pos)[0]
        out.append(pos)
    return out


def test_copy_cut_at_an_element_boundary_is_dropped_over_udp(source):
    """A copy of the bundle just sent, cut where an element ends, parses as a bundle: it is
    recognised as a truncated copy, counted in ``corrupt``, and the frames around it are
    exactly those sent (no phantom frame, no frame closed early)."""
    take = make_take(60, seed=6)
    addr = ("127.0.0.1", source.port)
    n_bad = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        for i in range(len(take.quats)):
            whole = _frame_datagrams(take, i)[0]
            out.sendto(whole, addr)
            if i % 2 == 1:
                cut = _element_cuts(whole)[1 + i % 5]
                bad = whole[:cut]
                assert bundle_structure_error(bad, 0, len(bad), 0) is None
                out.sendto(bad, addr)
                n_bad += 1
            time.sleep(0.002)
        frames = read_all(source)
    assert len(frames) == len(take.quats)
    for i, f in enumerate(frames):
        assert f.source_time == pytest.approx(i / 60.0, abs=1e-5)
        assert bool(f.valid.all())
        assert same_rotation(f.quats, take.quats[i], atol=1e-6)
    assert source.stats.corrupt == n_bad and source.stats.dropped == 0


def test_truncated_nested_bundle_is_dropped_whole():
    take = make_take(3, seed=2)
    asm = VmcAssembler(SUIT)
    whole = _frame_datagrams(take, 0)[0]
    # a nested bundle whose inner element is cut short while the outer sizes still add up
    inner = whole[:len(whole) - 8]
    outer = b"#bundle\x00" + struct.pack(">Q", 1) + struct.pack(">i", len(inner)) + inner
    assert bundle_structure_error(outer, 0, len(outer), 0) is not None
    assert asm.feed(outer, 0.0) == [] and not asm.pending
    assert asm.stats.corrupt == 1


def _send_run(out: socket.socket, addr, take, t0: float = 0.0, pause: float = 0.002) -> None:
    for i in range(len(take.quats)):
        out.sendto(encode_frame(take.quats[i], SUIT, time=t0 + i / 60.0,
                                root_position=take.root_position[i], max_datagram=60000)[0],
                   addr)
        time.sleep(pause)


def test_second_sender_is_refused_counted_and_named(source, caplog):
    a, b = make_take(40, seed=1), make_take(40, seed=9)
    addr = ("127.0.0.1", source.port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s1, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s2:
        s1.bind(("127.0.0.1", 0))
        s2.bind(("127.0.0.1", 0))
        for i in range(40):       # two senders interleaved on one port, T far apart
            s1.sendto(encode_frame(a.quats[i], SUIT, time=i / 60.0, max_datagram=60000)[0], addr)
            s2.sendto(encode_frame(b.quats[i], SUIT, time=500 + i / 60.0,
                                   max_datagram=60000)[0], addr)
            time.sleep(0.002)
        frames = read_all(source)
        second = s2.getsockname()
    assert len(frames) == 40
    for i, f in enumerate(frames):
        assert f.source_time == pytest.approx(i / 60.0, abs=1e-5)
        assert same_rotation(f.quats, a.quats[i], atol=1e-6)
    assert source.stats.other_senders == 40
    assert source.stats.dropped == 0 and source.stats.clock_restarts == 0
    named = [r for r in caplog.records if f"{second[0]}:{second[1]}" in r.getMessage()]
    assert len(named) == 1 and "other_senders" in named[0].getMessage()


def test_senders_newest_follows_the_new_sender():
    src = open_source("osc://127.0.0.1:0?format=vmc&quiet=0.02&queue=4096&senders=newest")
    try:
        a, b = make_take(20, seed=1), make_take(20, seed=9)
        addr = ("127.0.0.1", src.port)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s1, \
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s2:
            _send_run(s1, addr, a)
            _send_run(s2, addr, b, t0=0.5)
            s1.sendto(encode_frame(a.quats[0], SUIT, time=0.0, max_datagram=60000)[0], addr)
            frames = read_all(src)
        assert len(frames) == 41       # a, then b; a's late datagram takes over again
        assert same_rotation(frames[25].quats, b.quats[5], atol=1e-6)
        assert src.stats.other_senders == 0
    finally:
        src.close()


def test_bad_senders_option_is_refused():
    from rtseg.drivers import SourceError
    with pytest.raises(SourceError, match="senders="):
        open_source("osc://127.0.0.1:0?format=vmc&senders=all")


def test_restarted_sender_continues_the_clock(source, caplog):
    """A sender restarted (new socket, T from 0 again) after the handover silence: reported
    times go on increasing, one warning, counted."""
    from rtseg.drivers.osc.source import SENDER_HANDOVER
    take = make_take(30, seed=4)
    addr = ("127.0.0.1", source.port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s1:
        _send_run(s1, addr, take)
    time.sleep(SENDER_HANDOVER + 0.1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s2:
        _send_run(s2, addr, take)
    frames = read_all(source)
    assert len(frames) == 60
    times = [f.source_time for f in frames]
    assert all(b > a for a, b in zip(times, times[1:])), times
    assert times[30] == pytest.approx(times[29] + 1 / 60.0, abs=1e-3)
    assert times[59] - times[30] == pytest.approx(29 / 60.0, abs=1e-5)
    assert source.stats.clock_restarts == 1 and source.stats.other_senders == 0
    warned = [r for r in caplog.records if "went back" in r.getMessage()]
    assert len(warned) == 1


def test_clock_jump_ahead_starts_a_new_segment():
    take = make_take(4, seed=3)
    asm = VmcAssembler(SUIT)
    out = []
    for i, t in enumerate([1.0, 1.0 + 1 / 60, 1.0 + 2 / 60, 9000.0]):
        out += asm.feed(encode_frame(take.quats[i], SUIT, time=t, max_datagram=60000)[0],
                        i * 0.01)
    out += asm.flush(1.0, force=True)
    times = [f.source_time for f in out]
    assert len(times) == 4 and times[3] == pytest.approx(1.0 + 3 / 60, abs=1e-4)
    assert asm.stats.clock_restarts == 1 and asm.stats.dropped == 0


def _feed_times(times, recv_step=0.005, silence_before=None):
    """Frames of T ``times`` fed to one assembler, ``recv_step`` s apart on the receive
    clock (plus ``silence_before`` = (index, seconds)); the frames out and the assembler."""
    take = make_take(len(times), seed=5)
    asm = VmcAssembler(SUIT)
    out, now = [], 0.0
    for i, t in enumerate(times):
        if silence_before and i == silence_before[0]:
            now += silence_before[1]
        out += asm.feed(encode_frame(take.quats[i], SUIT, time=t, max_datagram=60000)[0], now)
        now += recv_step
    out += asm.flush(now + 1.0, force=True)
    return out, asm


def test_a_late_or_repeated_frame_is_dropped_and_the_clock_goes_on():
    """UDP reorders and repeats datagrams: a frame whose T lies behind the last one's (up to
    LATE_WINDOW) and that arrives promptly is dropped and counted in bad_messages.  It is no
    clock restart and makes no gap: the frames after it go on from the newest T."""
    p = 1 / 60
    ts = [1.0 + k * p for k in range(20)]
    late = ts[:15] + [ts[5]] + ts[15:]                 # frame 5 again, 10 frames late
    out, asm = _feed_times(late)
    assert [f.source_time for f in out] == pytest.approx(ts, abs=1e-6)
    assert [f.seq for f in out] == list(range(20))
    st = asm.stats
    assert (st.bad_messages, st.clock_restarts, st.gaps, st.dropped) == (1, 0, 0, 0)
    swapped = ts[:10] + [ts[11], ts[10]] + ts[12:]     # two frames swapped on the way
    out, asm = _feed_times(swapped)
    assert [f.source_time for f in out] == pytest.approx(ts[:10] + ts[11:], abs=1e-6)
    assert [f.seq for f in out] == list(range(10)) + list(range(11, 20))   # 10's slot lost
    st = asm.stats
    assert (st.bad_messages, st.clock_restarts, st.gaps, st.dropped) == (1, 0, 1, 1)


def test_a_damaged_time_ahead_costs_one_frame_and_one_clock_restart():
    """A T damaged a little ahead (still a time): the frames after it lie behind it.  The
    first is dropped as late; the next goes on from that one, not from the damaged frame,
    so the damaged T was the odd one: a clock restart there, and the rest is delivered
    (reported times still increasing) - not every frame up to the damaged time dropped."""
    p = 1 / 60
    ts = [1.0 + k * p for k in range(30)]
    out, asm = _feed_times(ts[:10] + [ts[10] + 0.5] + ts[11:])
    times = [f.source_time for f in out]
    assert len(out) == 29 and all(b > a for a, b in zip(times, times[1:]))
    assert asm.stats.bad_messages == 1 and asm.stats.clock_restarts == 1


def test_late_and_reordered_frames_over_udp_cost_the_live_loop_no_restart(source):
    """Over real UDP: one frame sent again 15 frames late, and two frames swapped.  The
    source drops the two late ones (bad_messages), counts the swapped pair's lost slot
    once, restarts no clock, and the frames' seq never goes back - so the live loop's gap
    accounting (``rtseg.live.input_gaps``) sees one missing frame and no restart."""
    from rtseg.live.input_gaps import InputGaps
    take = make_take(60, seed=6)
    order = list(range(30)) + [15] + list(range(30, 40)) + [41, 40] + list(range(42, 60))
    addr = ("127.0.0.1", source.port)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        for i in order:
            out.sendto(encode_frame(take.quats[i], SUIT, time=1.0 + i / 60.0,
                                    max_datagram=60000)[0], addr)
            time.sleep(0.002)
    frames = read_all(source)
    assert len(frames) == 59
    st = source.stats
    assert (st.bad_messages, st.clock_restarts, st.gaps, st.dropped) == (2, 0, 1, 1)
    gaps = InputGaps(max_gap_frames=12)
    missing = [gaps.step(f.seq, f.recv_time, f.source_time)[0] for f in frames]
    assert sum(missing) == 1 and max(missing) == 1          # the swapped pair's slot


def test_a_step_back_after_a_silence_or_beyond_the_late_window_restarts_the_clock():
    """T going back after LATE_SILENCE without frames, or by more than LATE_WINDOW, is the
    sender's clock restarting: every frame is delivered, the reported times go on."""
    from rtseg.drivers.osc.vmc.frames import LATE_SILENCE, LATE_WINDOW
    p = 1 / 60
    run = [0.5 + k * p for k in range(10)]
    again = [k * p for k in range(10)]                 # back by 0.5 s < LATE_WINDOW
    out, asm = _feed_times(run + again, silence_before=(10, LATE_SILENCE + 0.05))
    times = [f.source_time for f in out]
    assert len(out) == 20 and all(b > a for a, b in zip(times, times[1:]))
    assert asm.stats.clock_restarts == 1 and asm.stats.bad_messages == 0
    far = [k * p for k in range(10)]
    out, asm = _feed_times([LATE_WINDOW + 1.0 + t for t in far] + far)   # no silence
    assert len(out) == 20 and asm.stats.clock_restarts == 1 and asm.stats.bad_messages == 0


def _rmem_max() -> int | None:
    try:
        with open("/proc/sys/net/core/rmem_max") as fh:
            return int(fh.read())
    except (OSError, ValueError):
        return None


def _junk_bundle_64k() -> tuple[bytes, int]:
    """A 64 KB bundle of bone messages with unknown names (junk a broken sender emits),
    and how many messages it holds."""
    from rtseg.drivers.osc.vmc.encode import encode_pose_message
    parts, size, i = [], 16, 0
    while size < 64000:
        m = encode_pose_message("/VMC/Ext/Bone/Pos", f"NoSuchBone{i}", (0, 0, 0), (0, 0, 0, 1))
        parts.append(struct.pack(">i", len(m)) + m)
        size += len(m) + 4
        i += 1
    return b"#bundle\x00" + struct.pack(">Q", 1) + b"".join(parts), len(parts)


@pytest.mark.skipif((_rmem_max() or 0) < (2 << 20),
                    reason="net.core.rmem_max below 2 MiB: the kernel cannot grant the "
                           "receive buffer this test relies on")
def test_oversized_junk_while_the_reader_waits_costs_no_valid_frame():
    """30 junk bundles of 64 KB arrive, among 80 valid frames, while the reader thread is
    held (as a busy machine holds it): the socket's default receive buffer keeps every
    valid frame.  With the OS default (~200 KB, three such bundles) most are lost."""
    import threading
    src = open_source("osc://127.0.0.1:0?format=vmc&suit=default17&queue=4096")
    try:
        assert src.rcvbuf >= 4 << 20
        take = make_take(81, seed=2)
        held, release = threading.Event(), threading.Event()
        feed = src.assembler.feed

        def held_feed(data, now):
            if not held.is_set():
                held.set()
                release.wait(10)
            return feed(data, now)

        src.assembler.feed = held_feed
        junk, per_bundle = _junk_bundle_64k()
        n_junk = 0
        addr = ("127.0.0.1", src.port)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            for d in _frame_datagrams(take, 0):
                out.sendto(d, addr)
            assert held.wait(5)
            for i in range(1, len(take.quats)):
                if i % 8 in (1, 4, 6):
                    out.sendto(junk, addr)
                    n_junk += 1
                for d in _frame_datagrams(take, i):
                    out.sendto(d, addr)
            release.set()
            frames = read_all(src)
        assert len(frames) == len(take.quats)
        for i, f in enumerate(frames):
            assert f.source_time == pytest.approx(i / 60.0, abs=1e-5)
            assert same_rotation(f.quats, take.quats[i], atol=1e-6)
        assert n_junk == 30 and src.stats.dropped == 0
        assert src.stats.unknown_names == n_junk * per_bundle
    finally:
        src.close()


def test_a_damaged_time_is_refused_not_taken_for_a_clock():
    """A /VMC/Ext/T whose bytes were damaged into 2.4e24 s: a bad value (counted), the
    frame keeps the sender's clock - not a clock restart that lost every millisecond."""
    take = make_take(6, seed=6)
    asm = VmcAssembler(SUIT)
    out = []
    for i, t in enumerate([1.0, 1.0 + 1 / 60, 2.4e24, 1.0 + 3 / 60, 1.0 + 4 / 60, 1.0 + 5 / 60]):
        out += asm.feed(encode_frame(take.quats[i], SUIT, time=t, max_datagram=60000)[0],
                        i * 0.01)
    out += asm.flush(1.0, force=True)
    times = [f.source_time for f in out]
    assert asm.stats.clock_restarts == 0 and asm.stats.bad_values == 1
    assert times[3:] == pytest.approx([1.0 + 3 / 60, 1.0 + 4 / 60, 1.0 + 5 / 60], abs=1e-6)
    assert all(b > a for a, b in zip(times, times[1:]) if a is not None and b is not None)
