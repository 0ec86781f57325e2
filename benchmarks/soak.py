#!/usr/bin/env python3
"""Soak test: a long live session through the real pty serial suit with faults, accelerated.

    python3 benchmarks/soak.py                  # cuts mode, 8 session hours at 120 Hz
    python3 benchmarks/soak.py --hours 1 --json
    python3 benchmarks/soak.py --mode hostile --hours 0.25 --json   # survival under 1 % corruption

Cuts mode (default)
-------------------
The suit loops a 10-minute synthesised performance (``soak_score.soak_script``: the
synthesiser's behaviours in random order, each 5-20 s, every one recurring; the loop's
junction is a change too) with realistic faults (``CUTS_FAULTS``: 0.01 % of bytes
corrupted, an unplug of 0.3 s every 20 session minutes, two sensors silent for 50 ms every
5 minutes).  Fault times are seconds of the take's 120 Hz clock (session seconds); the suit
sends ``--speed`` (default 10) times faster.  The session runs the default live detector
and behaviour identity (``identity.enabled``).  Added to the figures below:

- ``cuts``, ``transitions``: the primary detector's cuts and the true changes sent;
- ``f1_by_hour``: live F1 at +/- 0.5 s per session hour (cuts matched to the changes over
  the whole run, then true positives and misses counted in the hour of the change's mid,
  false cuts in the hour of the cut; ``soak_score.score_by_hour``);
- ``ari_by_hour``: adjusted Rand index per session hour between every frame's true
  behaviour and the behaviour id rtseg sent for the segment holding it;
- ``frames_accounted``: frames sent = frames received + destroyed by faults (corrupted,
  dropped) + lost at unplugs (sent while unplugged, written just before a pull or in the
  reconnect second after a replug), exactly; ``accounting`` gives the four numbers,
  ``overflow`` (frames that met a full pty: the serial reader did not drain it in time)
  and ``queue_drops`` (frames the serial source dropped from its full queue: the session's
  reader did not take them in time), the two losses of a busy machine, which are none of
  the four;
- ``overload_drops``: frames received that the loop dropped to stay within its maximum
  lag (``buffer.max_lag_seconds``): the machine did not keep up with ``--speed``;
- ``clean_offline``: F1 of the same performance through the same pipeline offline, with no
  fault, pty or loop (``soak_score.clean_f1``): the detector's own figure, which the
  per-hour F1 cannot beat.
Bar: the hostile mode's (below) plus ``frames_accounted``, live F1 of every hour >= 0.95
and the last hour within 0.02 of the first.

Hostile mode (``--mode hostile``)
---------------------------------
The synthesised default performance (62 s) loops on a simulated 17-sensor suit
(``rtseg.simulators.serial_device.SerialSuit``) in a **separate process** on a real pty,
rtseg's binary serial format, with faults (``--faults``, default ``corrupt=0.01`` of bytes,
an unplug of 6 s every 200 s, bursts: jitter of up to 2 ms (wall clock) per message so
frames arrive bunched, 0.1 % of frames dropped, and two sensors silent for 20 s every
400 s; fault times are seconds of the suit's device clock, the take's 120 Hz, so at the
default 20x an unplug of 0.3 s every 10 s of wall-clock time: 144 unplugs in 8 session
hours).  This
process runs ``LiveSession("serial://<pty>?rate=120")`` exactly as ``rtseg live`` does
(serial driver, ring buffer, pose features, every configured online detector, OSC to a
socket on 127.0.0.1; no recording).  The suit sends ``--speed`` (default 20) times faster
than 120 Hz, so 8 session hours take 24 minutes; the session's windows stay those of 120 Hz
(the URL's ``rate``).  "Hours" below are **session** hours: 432 000 frames each.

Measured (both modes)
---------------------
- ``frames``: frames the suit attempted to send (its ``sent_log``); ``frames_received``.
- ``crashes``: the session ended other than by the soak's stop, raised, or its reader
  thread failed (``stop_reason``), plus source read errors and frames the loop could not
  process.
- ``rss_growth_mb``: median resident set size of this process (``/proc/self/status``,
  sampled every second) over the last window minus that over the first window; a window is
  one session hour, or a quarter of the run when it is shorter than 4 hours.
- ``p99_first_hour_us`` / ``p99_last_hour_us``: 99th percentile of the time one frame
  spends in ``Pipeline.process`` (features + every detector), microseconds, in the first
  and last window (log-binned histograms, 0.1 % resolution, so memory stays fixed).
  Wall time includes whatever else the machine runs; ``p99_cpu_*`` is the same for the
  thread's CPU time (``time.thread_time_ns``), which tells the pipeline's own cost growing
  apart from neighbours' load.  The bar is on the wall figure.
- ``lost_frames``: frames the suit sent intact that the session did not process: the suit
  reports every message's fate (intact / corrupted / dropped / unplugged / overflow); the
  session's frames are matched by unwrapped sequence number up to the last one received,
  and ring-buffer overruns are added.  ``destroyed_by_faults`` = corrupted + dropped +
  unplugged frames, plus intact frames never read that were written in the last 0.1 s
  before a pull (in the pty when the cable went, as bytes in a USB adapter are) or in the
  1 s after a replug while the reader was still reconnecting (the port's input is flushed
  when it reopens) - ``lost_to_unplug`` - plus frames that met a full pty within 1 s after
  a replug
  (``overflow_after_replug``: the device is back but the reader is still in its reconnect
  back-off, 50-400 ms, which at 20x speed is up to 8 s of session frames; at 120 Hz the
  pty's 4 KB buffer covers it); any other ``overflow`` (pty full: the reader too slow)
  counts as lost.
- ``p99_by_window_us`` / ``p99_cpu_by_window_us``: the same p99 for every window, to tell a
  trend from a step; ``suit_cpu_s_by_window`` / ``suit_rss_mb_by_window``: CPU seconds the
  suit process (which shares the machine's cores) used in each window and its resident set
  size at the window's end (``/proc/<pid>``).
- ``overflow_at_s``: session seconds at which frames met a full pty (the first 100), and
  ``overflows_near_gc_pause``: how many came within 50 ms of a garbage-collector pause of
  >= 2 ms in the session process (``gc``: collections per generation, pauses >= 2 ms, the
  longest), to tell a stalled reader from a slow one.
Bar: 0 crashes, RSS growth < 5 MB, p99 last window within 10 % of the first,
lost_frames 0.  ``pass`` says whether all hold.
"""

from __future__ import annotations

import argparse
import bisect
import json
import logging
import math
import multiprocessing as mp
import os
import socket
import sys
import tempfile
import threading
import time
from array import array
from pathlib import Path


REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from rtseg.live.session import LiveSession  # noqa: E402
from rtseg.live.config import from_dict  # noqa: E402
from rtseg.live.detector_setup import detector_params  # noqa: E402

sys.path.insert(0, str(REPO / "benchmarks"))
from soak_meter import GcPauses, Meter  # noqa: E402
from soak_score import (CutProbe, ari_by_hour, clean_f1, score_by_hour, to_frames,  # noqa: E402
                        truth)

import numpy as np  # noqa: E402

RATE = 120.0
FRAMES_PER_HOUR = int(RATE * 3600)
DEFAULT_FAULTS = ("corrupt=0.01,drop=0.001,jitter=0.002,unplug=200:6,"
                  "dropout=5:200:20:400,dropout=11:300:20:400,seed=11")
CUTS_FAULTS = ("corrupt=0.0001,unplug=1200:0.3,dropout=5:300:0.05:300,"
               "dropout=11:450:0.05:300,seed=11")
FATES = ("intact", "corrupted", "dropped", "unplugged", "overflow", "info", "unknown")
IN_FLIGHT_S = 0.1            # intact frames written this soon before a pull may die in the pty
REPLUG_S = 1.0               # overflow this soon after a replug: the reader is reopening


# ============================================================================ suit process
def _suit_main(conn, send_rate: float, faults: str, link: str, n_frames: int,
               mode: str = "hostile", speed: float = 1.0) -> None:
    """Child process: serve the looping synthesised take on a pty until ``n_frames`` frames
    were attempted, then unplug for good (frames still in the pty are lost, but they come
    after the last one the session received and so are not counted, see below).

    Tallies message fates as it goes (the suit's ``sent_log`` is swapped out every 0.5 s,
    so memory stays flat); the last ~20 s are kept per message so that, at the end, fates
    can be counted up to the parent's last received message index."""
    logging.basicConfig(level=logging.ERROR)
    from collections import deque
    from rtseg.simulators.serial_device import SerialSuit
    from rtseg.simulators.synth.motion import synthesize
    if mode == "cuts":
        from soak_score import soak_script
        r = synthesize(soak_script(), frame_rate=RATE, seed=0)
        take = r.take
        info = (take.n_frames, [(t.lo, t.hi, t.mid, t.before, t.after) for t in r.transitions],
                [(g.name, g.start, g.stop) for g in r.segments])
        del r
    else:
        take = synthesize(frame_rate=RATE, seed=0).take
        info = None
    # the take's clock (device time, fault times: what the session's rate= declares) runs
    # at 120 Hz, sent ``speed`` times faster
    suit = SerialSuit(take, rate=RATE, speed=speed, faults=faults, link=link, loop=True)
    conn.send((suit.start(), info))
    totals: dict[str, int] = {}
    recent: deque[list] = deque()
    attempted = 0

    near_unplug: list[int] = []          # intact frames written just before a pull or
                                         # just after a replug (reader reconnecting)
    overflow_at: list[float] = []        # time.monotonic() of each frame that met a full
                                         # pty (the clock is the machine's, shared)

    info_idx: list[int] = []             # message indices of the suit's info messages
    codes = bytearray()                  # per message index: index in FATES
    sent_at = array("d")                 # per message index: send time (monotonic)
    pulls: list[float] = []              # suit.unplug_log split, in time order (it is
    replugs: list[float] = []            # appended as it happens), extended as it grows

    def after_replug(t: float) -> bool:
        k = bisect.bisect_right(replugs, t)
        return k > 0 and t - replugs[k - 1] < REPLUG_S

    def before_pull(t: float) -> bool:
        k = bisect.bisect_left(pulls, t)
        return k < len(pulls) and pulls[k] - t < IN_FLIGHT_S

    def tally(chunk: list, upto: int | None = None) -> None:
        # each message is looked up by bisection: a scan of every unplug so far made the
        # suit's CPU time grow through the run (2 880 unplugs in 8 session hours)
        for u, r in suit.unplug_log[len(pulls):]:
            pulls.append(u)
            replugs.append(r)
        for m in chunk:
            while len(codes) <= m.index:
                codes.append(FATES.index("unknown"))
                sent_at.append(math.nan)
            codes[m.index] = FATES.index("info" if m.frame < 0 else m.fate)
            sent_at[m.index] = m.send_time
            if m.frame < 0:
                info_idx.append(m.index)
                continue
            if upto is not None and m.index > upto:
                continue
            fate = m.fate
            if fate == "overflow" and after_replug(m.send_time):
                fate = "overflow_after_replug"
            elif fate == "overflow" and len(overflow_at) < 10_000:
                overflow_at.append(m.send_time)
            elif fate == "intact" and (before_pull(m.send_time) or after_replug(m.send_time)):
                near_unplug.append(m.index)
            totals[fate] = totals.get(fate, 0) + 1

    while attempted < n_frames and not conn.poll(0):
        time.sleep(0.05 if n_frames - attempted < send_rate else 0.5)
        chunk, suit.sent_log = suit.sent_log, []
        suit.injector.take_record()       # fates are in sent_log; keep the heap flat
        attempted += sum(1 for m in chunk if m.frame >= 0)
        recent.append(chunk)
        conn.send(("progress", attempted))
        while len(recent) > 400:
            tally(recent.popleft())
    suit.stop()
    chunk, suit.sent_log = suit.sent_log, []
    recent.append(chunk)
    conn.send(("stopped", attempted))
    upto = conn.recv()                    # the parent's last received message index
    first_kept = next((c[0].index for c in recent if c), None)
    for c in recent:
        tally(c, upto)
    conn.send(("done", totals, first_kept, near_unplug, overflow_at, info_idx))
    unseen = conn.recv()                  # intact frames the session never received
    conn.send(("why", _why_unseen(unseen, codes, sent_at, pulls, replugs)))
    conn.close()


def _why_unseen(unseen, codes: bytearray, sent_at, pulls: list[float],
                replugs: list[float]) -> dict[str, int]:
    """Where the intact frames the session never received were: next to a message that
    met a full pty or was corrupted, within 5 s after a replug, or elsewhere."""
    out: dict[str, int] = {}
    ovf, cor = FATES.index("overflow"), FATES.index("corrupted")
    for i in unseen:
        i = int(i)
        if i >= len(codes) or FATES[codes[i]] != "intact":
            continue
        near = {codes[j] for j in (i - 1, i + 1) if 0 <= j < len(codes)}
        t = sent_at[i]
        k = bisect.bisect_right(replugs, t)
        if ovf in near:
            why = "beside_overflow"
        elif cor in near:
            why = "beside_corrupted"
        elif k > 0 and t - replugs[k - 1] < 5.0:
            why = "within_5s_after_replug"
        else:
            why = "other"
        out[why] = out.get(why, 0) + 1
    return out


# ============================================================================ scoring
def _score_cuts(probe: CutProbe, truth_info, info_idx: list[int], result: dict,
                session: LiveSession) -> dict:
    """The cuts mode's figures (see the module docstring)."""
    n_loop, transitions, segments = truth_info
    sent = result["frames"]
    received = session.stats.frames_received
    fates = result["fates"]
    destroyed = fates.get("corrupted", 0) + fates.get("dropped", 0)
    at_unplugs = (fates.get("unplugged", 0) + fates.get("overflow_after_replug", 0)
                  + result["lost_to_unplug"])
    cut_msg = probe.cuts[:probe.n_cuts]
    cut_frames = to_frames(cut_msg[:, 0], info_idx) if probe.n_cuts else np.zeros(0, np.int64)
    ids = probe.ids[:probe.n_ids].copy()
    if probe.n_ids:
        ids[:, 1] = to_frames(ids[:, 1], info_idx)
    trans, starts, codes, _ = truth(n_loop, transitions, segments, sent)
    f1 = score_by_hour(cut_frames, trans, FRAMES_PER_HOUR, sent, RATE)
    ari = ari_by_hour(cut_frames, ids, starts, codes, n_loop, FRAMES_PER_HOUR, len(f1),
                      sent)
    return {"mode": "cuts", "cuts": int(probe.n_cuts), "transitions": len(trans),
            "f1_by_hour": f1, "ari_by_hour": ari, "identity_messages": int(probe.n_ids),
            "frames_accounted": sent == received + destroyed + at_unplugs,
            # where the frames went; "overflow" (the pty was full: the serial reader did
            # not drain it in time) and "queue_drops" (the source's frame queue was full:
            # the session's reader did not take them in time) are what a busy machine
            # adds, and what stops the account from closing
            "accounting": {"sent": sent, "received": received, "destroyed": destroyed,
                           "lost_at_unplugs": at_unplugs,
                           "overflow": fates.get("overflow", 0),
                           "queue_drops": int(getattr(session.source, "overflow_drops", 0))},
            # received but not processed: dropped by the loop to keep up (max lag)
            "overload_drops": session.stats.overload_drops,
            "bridged_gaps": session.pipeline.stats.bridged_gaps,
            "filled_frames": session.pipeline.stats.filled_frames,
            "unmapped_events": probe.late}


# ============================================================================ measuring
def soak(hours: float, speed: float, faults: str, log, mode: str = "hostile",
         clean: bool = True, params: str = "") -> dict:
    n_frames = int(round(hours * FRAMES_PER_HOUR))
    window_frames = max(1, min(FRAMES_PER_HOUR, n_frames // 4))
    n_windows = max(1, n_frames // window_frames)
    tmp = tempfile.mkdtemp(prefix=f"rtseg-soak-{os.getpid()}-")
    link = os.path.join(tmp, "suit")
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_suit_main, args=(child, RATE * speed, faults, link, n_frames,
                                                mode, speed), daemon=True)
    proc.start()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    stop_sink = threading.Event()

    def drain() -> None:
        sink.settimeout(0.2)
        while not stop_sink.is_set():
            try:
                sink.recv(65536)
            except OSError:
                pass

    drainer = threading.Thread(target=drain, daemon=True)
    drainer.start()
    meter = Meter(window_frames, n_windows,
                  n_seen=n_frames + n_frames // 50 + 100_000)   # + info messages
    crashes = 0
    summary = None
    result: dict = {}
    try:
        if not parent.poll(60):
            raise RuntimeError("the suit process did not start")
        path, truth_info = parent.recv()
        settings: dict = {"output": {"osc": [f"127.0.0.1:{sink.getsockname()[1]}"]},
                          "status": {"interval": 1.0}}
        if mode == "cuts":
            settings["identity"] = {"enabled": True}
        if params:
            settings["detectors"] = {"params": params}
        cfg = from_dict(settings, origin="soak")
        contrast_params = detector_params(cfg).get("contrast")
        probe = CutProbe() if mode == "cuts" else None

        class SoakSession(LiveSession):
            def _open(self) -> None:
                super()._open()
                meter.wrap(self.pipeline)
                meter.wrap_source(self.source)
                if probe is not None:
                    probe.wrap(self.pipeline, meter)

        session = SoakSession(f"serial://{path}?rate={RATE:g}", cfg, handle_signals=False)
        box: dict = {}

        def body() -> None:
            try:
                box["summary"] = session.run()
            except BaseException as exc:          # noqa: BLE001 - a crash is a result
                box["error"] = exc

        runner = threading.Thread(target=body, name="soak-session", daemon=True)
        gc_pauses = GcPauses()
        t_start = time.monotonic()
        runner.start()
        attempted = 0
        stopped = False
        next_report = t_start + 30
        while not stopped and runner.is_alive():
            while parent.poll(0):
                msg = parent.recv()
                attempted = msg[1]
                stopped = msg[0] == "stopped"
            meter.sample_rss()
            meter.sample_suit(proc.pid)
            now = time.monotonic()
            if now >= next_report:
                next_report = now + 30
                log(f"  {attempted / FRAMES_PER_HOUR:5.2f} session h sent, "
                    f"{meter.processed} frames processed, RSS {meter.rss_mb_samples[max(meter.n_rss - 1, 0)]:.1f} MB, "
                    f"{now - t_start:.0f} s")
            time.sleep(1.0)
        # the suit has stopped: let the session finish what it received
        last = -1
        while runner.is_alive() and meter.processed != last:
            last = meter.processed
            time.sleep(0.5)
        parent.send(meter.last_abs)
        while True:
            if not parent.poll(60):
                raise RuntimeError("the suit process did not report")
            msg = parent.recv()
            if msg[0] == "done":
                _, fates, first_kept, near_unplug, overflow_at, info_idx = msg
                break
        upto = min(meter.last_abs + 1, meter.got.size)
        unseen = np.flatnonzero(~meter.got[:upto])       # never received (not: dropped)
        parent.send(unseen)
        why_unseen = parent.recv()[1] if parent.poll(120) else {}
        wall = time.monotonic() - t_start
        session.stop("soak done")
        runner.join(30)
        if runner.is_alive() or "error" in box:
            crashes += 1
        summary = box.get("summary")
        if summary is not None and summary.stop_reason != "soak done":
            crashes += 1
        crashes += session.stats.source_errors + session.stats.bad_frames
        if session._reader_error is not None:
            crashes += 1
        if first_kept is not None and meter.last_abs < first_kept:
            raise RuntimeError("the session fell more than 20 s behind the suit; "
                               "lost frames cannot be counted")
        intact = fates.get("intact", 0)
        overruns = session.stats.overruns
        processed_matched = meter.processed
        # intact frames written just before a pull (they die with the pty) or just after a
        # replug, before the reader has reopened the port (its open discards them), never read
        in_flight = sum(1 for i in near_unplug if i < meter.got.size and not meter.got[i])
        lost = (max(0, intact - processed_matched - in_flight) + overruns
                + fates.get("overflow", 0))
        first, lastw = 0, n_windows - 1
        while lastw > 0 and not meter.has_window(lastw):
            lastw -= 1
        p_first, p_last = meter.p99_us(first), meter.p99_us(lastw)
        c_first, c_last = meter.p99_us(first, cpu=True), meter.p99_us(lastw, cpu=True)
        r_first, r_last = meter.rss_mb(first), meter.rss_mb(lastw)
        growth = (r_last - r_first) if r_first is not None and r_last is not None else None
        windows = range(lastw + 1)
        suit_cpu, suit_rss = meter.suit_by_window()
        sent = sum(fates.values())
        result = {
            "hours": hours, "speed": speed, "faults": faults,
            "params": params or None, "contrast_params": contrast_params,
            "frames": sent, "frames_received": session.stats.frames_received,
            "frames_processed": meter.processed, "wall_s": round(wall, 1),
            "crashes": crashes,
            "rss_first_mb": r_first, "rss_last_mb": r_last, "rss_growth_mb": growth,
            "window_hours": window_frames / FRAMES_PER_HOUR,
            "p99_first_hour_us": p_first, "p99_last_hour_us": p_last,
            "p99_change": (p_last / p_first - 1.0) if p_first and p_last else None,
            "p99_cpu_first_hour_us": c_first, "p99_cpu_last_hour_us": c_last,
            "p99_cpu_change": (c_last / c_first - 1.0) if c_first and c_last else None,
            "p99_by_window_us": [meter.p99_us(w) for w in windows],
            "p99_cpu_by_window_us": [meter.p99_us(w, cpu=True) for w in windows],
            "suit_cpu_s_by_window": suit_cpu[:lastw + 1],
            "suit_rss_mb_by_window": suit_rss[:lastw + 1],
            "lost_frames": lost,
            "destroyed_by_faults": sum(fates.get(k, 0) for k in (
                "corrupted", "dropped", "unplugged", "overflow_after_replug")) + in_flight,
            "fates": fates, "lost_to_unplug": in_flight, "overruns": overruns,
            # intact frames never received (those lost to unplugs included), by where
            "unseen_intact": why_unseen,
            "reconnects": session.source.stats.reconnects if session.source else None,
            "input": summary.input if summary is not None else None,
            "cuts": summary.cuts if summary is not None else None,
            "detector_restarts": session.pipeline.stats.restarts if session.pipeline else None,
            # where the overflows fell: session seconds after the start, and how many came
            # within 50 ms of a garbage-collector pause of >= 2 ms in this process
            "overflow_at_s": [round(t - t_start, 3) for t in overflow_at[:100]],
            "overflows_near_gc_pause": gc_pauses.near(overflow_at),
            "gc": {"collections": gc_pauses.counts,
                   "pauses_2ms": len(gc_pauses.pauses),
                   "max_pause_ms": round(max((ms for _, ms, _ in gc_pauses.pauses), default=0.0), 2),
                   "gen2_pauses_2ms": sum(1 for *_, g in gc_pauses.pauses if g == 2)},
        }
        gc_pauses.close()
        result["pass"] = bool(crashes == 0 and growth is not None and growth < 5.0
                              and result["p99_change"] is not None
                              and result["p99_change"] <= 0.10 and lost == 0)
        if probe is not None:
            result.update(_score_cuts(probe, truth_info, info_idx, result, session))
            if clean:
                result["clean_offline"] = clean_f1(RATE, params)
            f1s = [f for f in result["f1_by_hour"] if f is not None]
            result["pass"] = bool(result["pass"] and result["frames_accounted"] and f1s
                                  and min(f1s) >= 0.95 and abs(f1s[-1] - f1s[0]) <= 0.02)
    finally:
        stop_sink.set()
        drainer.join(2)
        sink.close()
        if proc.is_alive():
            try:
                parent.send(-1)
            except OSError:
                pass
            proc.join(10)
            if proc.is_alive():
                proc.terminate()
                proc.join(5)
        try:
            os.rmdir(tmp)
        except OSError:
            pass
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--hours", type=float, default=8.0,
                   help="session hours at 120 Hz (default 8 = 3.46 M frames)")
    p.add_argument("--speed", type=float, default=None,
                   help="the suit sends this many times faster than 120 Hz (default: cuts 10, "
                        "hostile 20)")
    p.add_argument("--mode", choices=("cuts", "hostile"), default="cuts",
                   help="cuts (default): a long performance with known changes and realistic "
                        "faults, scored per hour; hostile: survival under heavy faults")
    p.add_argument("--faults", default=None,
                   help=f"fault spec of rtseg.simulators.faults (default: cuts {CUTS_FAULTS}; "
                        f"hostile {DEFAULT_FAULTS})")
    p.add_argument("--no-clean", action="store_true",
                   help="cuts mode: skip clean_offline (the performance's F1 offline, about "
                        "15 s of CPU after the run)")
    p.add_argument("--params", default="", metavar="NAME|FILE",
                   help="detector parameters of the session (a file, or a shipped name such "
                        "as full; default config/detectors.toml)")
    p.add_argument("--json", action="store_true", help="print only the JSON result")
    args = p.parse_args(argv)
    if args.params:
        from rtseg.config import ConfigError
        from rtseg.detectors import load_params
        try:
            load_params(args.params)
        except (ConfigError, OSError, ValueError) as exc:
            p.error(f"--params: {exc}")
    if not (args.hours > 0 and math.isfinite(args.hours)):
        p.error("--hours must be a number > 0")
    if args.speed is None:
        args.speed = 10.0 if args.mode == "cuts" else 20.0
    if not (args.speed > 0 and math.isfinite(args.speed)):
        p.error("--speed must be a number > 0")
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    faults = args.faults if args.faults is not None else (
        CUTS_FAULTS if args.mode == "cuts" else DEFAULT_FAULTS)
    log(f"soak ({args.mode}): {args.hours:g} session hours ({int(args.hours * FRAMES_PER_HOUR)} frames) at "
        f"{args.speed:g}x 120 Hz, faults {faults}")
    r = soak(args.hours, args.speed, faults, log, args.mode, clean=not args.no_clean,
             params=args.params)
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        fmt = lambda v, f: "-" if v is None else format(v, f)   # noqa: E731
        print(f"frames sent {r['frames']}, received {r['frames_received']}, "
              f"destroyed by faults {r['destroyed_by_faults']}, lost {r['lost_frames']}")
        print(f"crashes {r['crashes']}; RSS {fmt(r['rss_first_mb'], '.1f')} -> "
              f"{fmt(r['rss_last_mb'], '.1f')} MB (growth {fmt(r['rss_growth_mb'], '.2f')} MB)")
        print(f"Pipeline.process p99: first window {fmt(r['p99_first_hour_us'], '.1f')} us, "
              f"last {fmt(r['p99_last_hour_us'], '.1f')} us "
              f"({fmt(r['p99_change'] and 100 * r['p99_change'], '+.1f')} %)")
        print(f"  thread CPU time p99: first {fmt(r['p99_cpu_first_hour_us'], '.1f')} us, "
              f"last {fmt(r['p99_cpu_last_hour_us'], '.1f')} us "
              f"({fmt(r['p99_cpu_change'] and 100 * r['p99_cpu_change'], '+.1f')} %)")
        print("  p99 by window (wall / thread CPU, us): " + ", ".join(
            f"{fmt(a, '.0f')}/{fmt(b, '.0f')}"
            for a, b in zip(r["p99_by_window_us"], r["p99_cpu_by_window_us"])))
        print("  suit process CPU s by window: " + ", ".join(
            fmt(c, '.1f') for c in r["suit_cpu_s_by_window"])
              + f"; its RSS at the end {fmt(r['suit_rss_mb_by_window'][-1], '.1f')} MB")
        if r.get("mode") == "cuts":
            print(f"cuts {r['cuts']} of {r['transitions']} changes; live F1 by hour "
                  + ", ".join(fmt(f, '.3f') for f in r["f1_by_hour"]) + "; ARI by hour "
                  + ", ".join(fmt(a, '.3f') for a in r["ari_by_hour"]))
            a = r["accounting"]
            print(f"frames accounted: {r['frames_accounted']} (sent {a['sent']} = received "
                  f"{a['received']} + destroyed {a['destroyed']} + lost at unplugs "
                  f"{a['lost_at_unplugs']}; overflow {a['overflow']}, source queue drops "
                  f"{a['queue_drops']}); "
                  f"overload drops {r['overload_drops']}")
            if "clean_offline" in r:
                c = r["clean_offline"]
                print(f"the same performance offline, no faults: F1 {c['f1']:.3f} "
                      f"(strict {c['strict_f1']:.3f}), {c['cuts']} cuts of "
                      f"{c['transitions']} changes")
        print(f"wall time {r['wall_s']} s; {'PASS' if r['pass'] else 'FAIL'}")
    return 0 if r["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
