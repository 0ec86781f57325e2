#!/usr/bin/env python3
"""Live-session benchmark: latency, CPU use per suit (1, 4, 8 suits in one process), cost
per frame by stage, detector delay, highest sustained input rate.

    python3 benchmarks/live.py            # readable report (about 4 minutes)
    python3 benchmarks/live.py --json     # {"latency_ms": {"p50", "p99", "max"},
                                          #  "cut_latency_ms": [ms of each cut],
                                          #  "cpu_fraction", "cpu_fraction_runs",
                                          #  "suits": {"1": {...}, "4": ...,
                                          #  "8": ...}, "stages_us": {...}, "wakeup": {...},
                                          #  "detector_delay_ms": {method: ms},
                                          #  "max_rate_fps", "core_max_rate_fps"}
    python3 benchmarks/live.py --monitor  # only the CPU cost of the live monitor (rtseg.monitor)
                                          # with one page open in headless Chromium
    python3 benchmarks/live.py --vmc      # only a VMC performer over UDP: CPU and latency,
                                          # quiet frames batched and not

Everything goes through the real chain (``benchmarks/live_chain.py``): the synthetic
17-sensor suit (``rtseg.simulators.serial_device``, default synthesised performance) runs in
a **separate process** on a real pty, rtseg's binary serial format; this process runs
``LiveSession("serial://<pty>")`` (serial driver, ring buffer, pose features, the configured
live detectors: by default ``contrast``) and sends cuts and status over OSC/UDP to a socket
on 127.0.0.1.

1. **Latency and CPU at 120 Hz** (``--seconds``, default 30 s): processing latency of
   every frame = its arrival (``Frame.recv_time``, stamped by the serial driver when its
   bytes were read) to the end of its processing, which includes sending the OSC datagram
   when the frame reveals a cut (p50/p99; target p99 < 5 ms; the detector's own delay is
   not included).  The latency of the frames that actually sent a cut is reported too.
   CPU fraction = process CPU time (all threads of this process; the simulated suit is
   another process) / wall time (target < 0.10 of one core).  ``--repeat N`` runs this
   step N times and reports the median run (``cpu_fraction_runs`` lists every run's CPU):
   on a shared virtual machine one run's share of a core drifts by a fifth.
1b. **Several suits in one process** (``--suits``, default 1, 4, 8; ``--seconds`` each):
   that many simulated 17-sensor suits at 120 Hz, each on its own pty, served by one
   other process (``benchmarks/live_chain.py --serve-suits``: the suits' threads, phases
   spread over a frame period); this process runs one session per suit, all on one thread
   (``rtseg.live.loop.run_sessions``).  Reported per count: CPU of this process as a
   fraction of one core, in all and per suit; frame latency p50/p99/max over every
   suit's frames; frames received and dropped.
1c. **Cost per frame by stage** (``--stage-seconds``, one suit at 120 Hz, identity on so
   that its cost shows): thread CPU time (``time.thread_time``) in microseconds per
   frame of ``decode`` (the serial driver's ``poll``: read and decode), ``receive``
   (recording check, ring buffer append), ``features`` (``PoseFeatures.step``),
   ``detector`` (every detector's ``update``), ``identity`` (the tracker's ``step``),
   ``pipeline`` (the rest of ``Pipeline.process``: gaps, sanitising, index bookkeeping),
   ``publish`` (every ``publish_*`` call), ``ahead`` (the detectors' work ahead between
   frames, ``Pipeline.ahead``), ``loop`` (the rest: waiting, the ring cursor,
   dropouts, status, counters) and ``total`` (the thread's CPU time over the frames).
   The timers add about 1 µs a call.
1d. **The machine's cost of a wake-up** (with 1c; ``benchmarks/wakeup.py``): CPU of an empty
   wake-up at 120 Hz (the floor under any suit's cost) and one frame's serial decode in a
   tight loop against once per wake-up (how much cold caches multiply a frame's work).
2. **Detector delay** per method: median of ``detected_at - frame`` over the cuts of the
   default synthesised performance (8 behaviour changes, 62 s) replayed through the same
   pipeline, in ms at 120 Hz.  Cuts of the live run in step 1 are included.
3. **Highest sustained input rate**: the suit is played at rising rates (500, 1000, 2000,
   3000, 4000, 6000, 8000, 10000, 12000, 16000 frames/s, ``--step-seconds`` each).  A rate is sustained when the
   session receives at least 97 % of the frames the suit sends in that time, loses none
   (no sequence gaps, no ring-buffer overruns, no queue overflow) and the p99 frame latency
   stays under 50 ms.  Reported: the highest sustained rate (target >= 2000).

``--monitor`` runs only step 1, twice: without the live monitor, then with it serving
(``rtseg.monitor``: feed and server thread in this process) and one page open in headless
Chromium (another process, not counted).  Reported: both CPU fractions and their difference,
the monitor's cost (target <= 0.01 of a core).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from rtseg.live.session import LiveSession, replay_frames  # noqa: E402
from live_chain import (Suit, config, pcts, quiet_counts, run_session,  # noqa: E402
                        run_suits, sink)

RATES = (500, 1000, 2000, 3000, 4000, 6000, 8000, 10000, 12000, 16000)


def _pcts_text(p: dict[str, float | None]) -> str:
    """``live_chain.pcts`` in words ("-" for none)."""
    return ", ".join(f"{k} " + ("-" if p[k] is None else f"{p[k]:.3f} ms")
                     for k in ("p50", "p99", "max"))


def latency_and_cpu(seconds: float, port: int, monitor: bool = False,
                    batch_quiet: bool = True, kind: str = "serial") -> dict:
    session, summary, cpu, fps = run_session(120.0, seconds, port, monitor=monitor,
                                             batch_quiet=batch_quiet, kind=kind,
                                             warmup=2.0 if kind == "vmc" else 1.0)
    lat = np.fromiter(session.stats.open_latency_ms, float)
    every = np.fromiter(session.stats.frame_latency_ms, float)
    cut_lat = np.fromiter(session.stats.cut_latency_ms, float)
    return {
        "frames": len(every), "open_frames": len(lat), "rate": fps,
        "latency_ms": pcts(lat), "every_frame": pcts(every),
        "quiet": quiet_counts(session),
        "cut_latency": [round(float(x), 3) for x in cut_lat],
        "cpu_fraction": cpu, "dropped": summary.dropped, "cuts": summary.cuts,
    }


def detector_delays(extra: dict[str, list[float]]) -> dict[str, float]:
    from rtseg.core.quat import global_from_local
    from rtseg.simulators.synth.motion import synthesize
    take = synthesize(frame_rate=120.0).take
    g = global_from_local(take.quats, take.parents)
    ok = np.ones(take.n_joints, bool)
    frames = ((g[i], ok, i, i / 120.0) for i in range(take.n_frames))
    cuts = replay_frames(frames, take.joint_names, take.parents, "global", 120.0, config(9))
    out: dict[str, list[float]] = {m: list(v) for m, v in extra.items()}
    for c in cuts:
        out.setdefault(c.cut.method, []).append((c.detected - c.boundary) / 120.0 * 1000.0)
    return {m: float(np.median(v)) for m, v in out.items() if v}


def max_rate(step_seconds: float, port: int, log, kind: str = "serial") -> tuple[int, list[dict]]:
    best = 0
    rows = []
    for rate in RATES:
        session, summary, cpu, fps = run_session(float(rate), step_seconds, port, kind=kind)
        src = summary.source_stats
        lat = np.fromiter(session.stats.frame_latency_ms, float)
        lost = src.get("dropped", 0) + summary.overruns
        p99 = float(np.percentile(lat, 99)) if lat.size else float("inf")
        ok = fps >= 0.97 * rate and lost == 0 and p99 < 50.0
        rows.append({"rate": rate, "received_fps": fps, "lost": lost,
                     "p99_ms": p99, "cpu_fraction": cpu, "sustained": ok})
        log(f"  {rate:5d} fps: received {fps:7.0f}/s, lost {lost}, "
            f"p99 latency {p99:7.2f} ms, CPU {cpu:4.2f} -> "
            f"{'sustained' if ok else 'falls behind'}")
        if not ok:
            break
        best = rate
    return best, rows


def overload(factor: float, seconds: float, port: int, log, max_lag: float | None = None
             ) -> dict:
    """The 17-sensor suit sent ``factor`` times faster than its 120 Hz (device clock and
    sequence numbers keep the take's 120 Hz) for ``seconds`` after a 1 s warm-up.
    Reported: cue latency (arrival of the frame that revealed a cut -> its OSC datagram
    sent) p50/p99 over the cuts, the same for every processed frame, overload drops, the
    largest lag, and whether every cut time is on the source clock (the take's seconds,
    running over twice as fast as the wall clock here; never the wall clock) and in
    order."""
    suit = Suit(120.0, speed=factor)
    try:
        cfg = config(port)
        if max_lag is not None:
            from rtseg.live.config import apply_overrides
            apply_overrides(cfg, {"buffer.max_lag_seconds": max_lag}, origin="benchmark")
        session = LiveSession(f"serial://{suit.path}?rate=120", cfg, handle_signals=False,
                              duration=seconds + 1.0)
        cuts: list = []
        session.listeners.append(lambda ev: cuts.append(ev) if hasattr(ev, "detected_frame")
                                 else None)
        marks: dict[str, float] = {}

        def start_measuring() -> None:
            session.stats.frame_latency_ms.clear()
            session.stats.cut_latency_ms.clear()
            marks.update(wall=time.monotonic(), frames=session.stats.frames_received,
                         drops=session.stats.overload_drops, cuts=len(cuts))

        timer = threading.Timer(1.0, start_measuring)
        timer.start()
        summary = session.run()
        timer.cancel()
        wall = time.monotonic() - marks["wall"]
    finally:
        suit.close()
    measured = cuts[int(marks["cuts"]):]
    cue = np.fromiter((c.processing_ms for c in measured if c.wire and c.processing_ms
                       is not None), float)
    lat = np.fromiter(session.stats.frame_latency_ms, float)
    # the cut's time against the session clock of its revealing frame on the device clock:
    # the take's seconds run about `factor` times faster than the wall clock (less when a
    # busy machine slows the simulated suit down); the wall clock would give the same
    src_t = [c.time + (c.detected_frame - c.frame) / 120.0 for c in cuts]
    wall_t = [c.detected_recv_time - session.session_start for c in cuts]
    on_source = all(s > 2.0 * w for s, w in zip(src_t[1:], wall_t[1:])) and all(
        b >= a for a, b in zip([c.time for c in cuts], [c.time for c in cuts][1:]))

    def pct(a: np.ndarray, p: float) -> float | None:
        return round(float(np.percentile(a, p)), 3) if a.size else None

    out = {"overload": factor, "input_fps": round((summary.frames_received - marks["frames"])
                                                    / wall, 1),
           "seconds": round(wall, 1), "max_lag_setting_ms": summary.max_lag_setting_ms,
           "cue_latency_ms": {"p50": pct(cue, 50), "p99": pct(cue, 99), "cuts": int(cue.size)},
           "frame_latency_ms": {"p50": pct(lat, 50), "p99": pct(lat, 99)},
           "overload_drops": session.stats.overload_drops - int(marks["drops"]),
           "dropped": summary.dropped, "overruns": summary.overruns,
           "max_lag_ms": round(summary.max_lag_ms, 1), "cuts": summary.cuts,
           "restarts": summary.pipeline.get("restarts", 0),
           "cut_times_on_source_clock": bool(on_source),
           "cut_times_s": [round(c.time, 2) for c in cuts[:12]]}
    log(f"   {out['input_fps']:.0f} frames/s in, {out['overload_drops']} dropped for "
        f"overload, cue latency p50 {out['cue_latency_ms']['p50']} ms p99 "
        f"{out['cue_latency_ms']['p99']} ms over {out['cue_latency_ms']['cuts']} cuts, "
        f"frame latency p99 {out['frame_latency_ms']['p99']} ms, max lag "
        f"{out['max_lag_ms']} ms, cut times on the source clock: {on_source}")
    return out


def monitor_cost(seconds: float, port: int, log, as_json: bool) -> int:
    """CPU of the session (this process: loop, reader, OSC and the monitor's server
    thread) at 120 Hz without the monitor and with it serving one Chromium page."""
    log(f"17-sensor suit at 120 Hz over a pty, {seconds:g} s: without the monitor ...")
    off = latency_and_cpu(seconds, port)
    log(f"   CPU {off['cpu_fraction'] * 100:.2f} % of one core, latency of every frame "
        f"{_pcts_text(off['every_frame'])}, {off['dropped']} dropped")
    log("   with the monitor and one page open in headless Chromium ...")
    on = latency_and_cpu(seconds, port, monitor=True)
    log(f"   CPU {on['cpu_fraction'] * 100:.2f} % of one core, latency of every frame "
        f"{_pcts_text(on['every_frame'])}, {on['dropped']} dropped")
    extra = on["cpu_fraction"] - off["cpu_fraction"]
    log(f"   the monitor costs {extra:+.4f} of a core (target <= 0.01)")
    result = {"cpu_fraction": {"without": round(off["cpu_fraction"], 4),
                               "with_monitor": round(on["cpu_fraction"], 4),
                               "monitor": round(extra, 4)},
              "latency_ms_p99": {"without": off["every_frame"]["p99"],
                                 "with_monitor": on["every_frame"]["p99"]}}
    print(json.dumps(result) if as_json else json.dumps(result, indent=2))
    return 0


def vmc_cost(seconds: float, port: int, log, as_json: bool) -> int:
    """``--vmc``: one VMC performer at 120 Hz (``rtseg simulate vmc`` in another process,
    UDP on 127.0.0.1, 17 bones, /VMC/Ext/T sent) into one session on ``osc://``, with the
    quiet frames batched and without: CPU of this process, latencies, quiet counts."""
    out = {}
    for name, batched in (("batched", True), ("unbatched", False)):
        log(f"VMC performer at 120 Hz over UDP, {seconds:g} s, quiet frames "
            f"{'batched' if batched else 'read as they arrive'} ...")
        r = latency_and_cpu(seconds, port, batch_quiet=batched, kind="vmc")
        log(f"   CPU {r['cpu_fraction'] * 100:.2f} % of one core; {r['frames']} frames, "
            f"{r['dropped']} dropped; frames that could send {_pcts_text(r['latency_ms'])}; "
            f"every frame {_pcts_text(r['every_frame'])}; {r['quiet']['frames']} quiet "
            f"frames in {r['quiet']['batches']} batches")
        out[name] = {"cpu_fraction": round(r["cpu_fraction"], 4), "frames": r["frames"],
                     "dropped": r["dropped"], "latency_ms": r["latency_ms"],
                     "every_frame_latency_ms": r["every_frame"], "quiet": r["quiet"]}
    out["ratio"] = round(out["batched"]["cpu_fraction"]
                         / max(out["unbatched"]["cpu_fraction"], 1e-9), 3)
    log(f"   batched / unbatched CPU {out['ratio']:.2f}")
    print(json.dumps(out) if as_json else json.dumps(out, indent=2))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--json", action="store_true", help="print only the JSON result")
    p.add_argument("--seconds", type=float, default=30.0, help="length of the 120 Hz run")
    p.add_argument("--repeat", type=int, default=1, metavar="N",
                   help="run step 1 (one suit at 120 Hz) N times: its CPU and latency are "
                        "the median run's, every run's CPU is listed (the machine's share "
                        "of a core drifts between runs)")
    p.add_argument("--step-seconds", type=float, default=4.0, help="length of each rate step")
    p.add_argument("--skip-core", action="store_true",
                   help="skip the rate steps of the session core without the serial driver")
    p.add_argument("--overload", type=float, metavar="X",
                   help="only the overload run: the suit sent X times faster than its 120 Hz "
                        "for --seconds; cue latency p50/p99, overload drops, cut times")
    p.add_argument("--max-lag", type=float, metavar="S",
                   help="with --overload: buffer.max_lag_seconds (default the config's)")
    p.add_argument("--suits", default="1,4,8",
                   help="suit counts run in one process, comma separated ('' skips)")
    p.add_argument("--stage-seconds", type=float, default=15.0,
                   help="length of the run measuring the cost per frame by stage (0 skips)")
    p.add_argument("--skip-rates", action="store_true",
                   help="skip the highest sustained input rate steps")
    p.add_argument("--vmc", action="store_true",
                   help="only a VMC performer over UDP into one session, quiet frames "
                        "batched and not: CPU and latency of each")
    p.add_argument("--monitor", action="store_true",
                   help="only the CPU cost of the live monitor: step 1 without it, then with "
                        "the monitor served and one page open in headless Chromium")
    args = p.parse_args(argv)
    if args.repeat < 1:
        p.error(f"--repeat must be at least 1, got {args.repeat}")
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")

    def log(msg: str) -> None:
        print(msg, file=sys.stderr if args.json else sys.stdout, flush=True)

    t0 = time.monotonic()
    s = sink()
    port = s.getsockname()[1]
    if args.overload:
        try:
            log(f"17-sensor suit at {args.overload:g} x 120 Hz over a pty for "
                f"{args.seconds:g} s ...")
            res = overload(args.overload, args.seconds, port, log, args.max_lag)
        finally:
            s.close()
        print(json.dumps(res) if args.json else json.dumps(res, indent=2))
        return 0
    if args.monitor:
        try:
            return monitor_cost(args.seconds, port, log, args.json)
        finally:
            s.close()
    if args.vmc:
        try:
            return vmc_cost(args.seconds, port, log, args.json)
        finally:
            s.close()
    try:
        log(f"1. 17-sensor suit at 120 Hz over a pty for {args.seconds:g} s"
            + (f", {args.repeat} runs" if args.repeat > 1 else "") + " ...")
        runs = [latency_and_cpu(args.seconds, port) for _ in range(args.repeat)]
        # the run whose CPU is the median (the lower middle one for an even count)
        lc = sorted(runs, key=lambda r: r["cpu_fraction"])[(len(runs) - 1) // 2]
        if len(runs) > 1:
            log("   CPU of each run: " + ", ".join(f"{r['cpu_fraction']:.4f}" for r in runs)
                + "; the median run's figures follow")
        log(f"   {lc['frames']} frames measured ({lc['rate']:.1f}/s, after 1 s warm-up), "
            f"{lc['dropped']} dropped, {lc['cuts']} cuts")
        ev, qt = lc["every_frame"], lc["quiet"]
        log(f"   processing latency of the {lc['open_frames']} frames that could send "
            f"(arrival -> processed/sent): {_pcts_text(lc['latency_ms'])}")
        log(f"   every frame, the quiet ones read in batches too: {_pcts_text(ev)}; "
            f"{qt['frames']} quiet frames in {qt['batches']} batches, {qt['late_open']} "
            f"frames that could send read late")
        log(f"   latency of the frames that sent a cut: {lc['cut_latency']} ms")
        log(f"   CPU: {lc['cpu_fraction'] * 100:.1f} % of one core")
        log("   the same without quiet-frame batching (buffer.batch_quiet = false) ...")
        unb = latency_and_cpu(args.seconds, port, batch_quiet=False)
        log(f"   CPU: {unb['cpu_fraction'] * 100:.1f} % of one core "
            f"(batched / unbatched {lc['cpu_fraction'] / unb['cpu_fraction']:.2f}); latency "
            f"of the frames that could send {_pcts_text(unb['latency_ms'])}; every frame "
            f"{_pcts_text(unb['every_frame'])}")
        suits: dict[str, dict] = {}
        for n in [int(x) for x in args.suits.split(",") if x.strip()]:
            log(f"1b. {n} suit(s) at 120 Hz in one process, one thread, {args.seconds:g} s ...")
            r = run_suits(n, args.seconds, port)
            suits[str(n)] = r
            log(f"   CPU {r['cpu_fraction']:.4f} of one core in all, "
                f"{r['cpu_fraction_per_suit']:.4f} per suit; {r['fps_per_suit']:.1f} frames/s "
                f"per suit; latency of the frames that could send "
                f"{_pcts_text(r['latency_ms'])}; every frame {_pcts_text(r['every_frame_latency_ms'])}; "
                f"{r['dropped']} dropped, {r['quiet']['late_open']} read late")
        stages = wake = None
        if args.stage_seconds > 0:
            log(f"1c. cost per frame by stage (one suit, identity on, {args.stage_seconds:g} s) ...")
            stages = run_suits(1, args.stage_seconds, port, stages=True)["stages_us"]
            log("   µs per frame: " + ", ".join(f"{k} {v:.1f}" for k, v in stages.items()))
            log("1d. the machine's cost of a wake-up (benchmarks/wakeup.py, 8 s) ...")
            from wakeup import measure as wakeup_cost
            wake = wakeup_cost(8.0, 120.0)
            log(f"   empty wake-up {wake['empty_wakeup_us']} µs ({100 * wake['empty_cpu_fraction']:.2f} "
                f"% of a core at 120 Hz); one frame's serial decode {wake['decode_tight_us']} µs "
                f"in a tight loop, {wake['decode_woken_us']} µs woken (x{wake['woken_over_tight']})")
        log("2. detector delay (default synthesised performance, 8 changes, replayed) ...")
        delays = detector_delays({})
        log("   " + ", ".join(f"{m} {v:.0f} ms" for m, v in delays.items()))
        best = core = None
        if not args.skip_rates:
            log(f"3. highest sustained input rate, whole chain through the pty "
                f"({args.step_seconds:g} s per step) ...")
            best, _rows = max_rate(args.step_seconds, port, log)
            log(f"   highest sustained: {best} frames/s")
        if not args.skip_core and not args.skip_rates:
            log("   the session core alone (in-process paced source, no serial driver):")
            core, _ = max_rate(args.step_seconds, port, log, kind="core")
            log(f"   highest sustained by the core: {core} frames/s")
    finally:
        s.close()
    result = {"latency_ms": lc["latency_ms"],
              "every_frame_latency_ms": lc["every_frame"], "quiet": lc["quiet"],
              "cut_latency_ms": lc["cut_latency"],
              "unbatched": {"cpu_fraction": round(unb["cpu_fraction"], 4),
                            "latency_ms": unb["latency_ms"],
                            "cut_latency_ms": unb["cut_latency"],
                            "every_frame_latency_ms": unb["every_frame"]},
              "detector_delay_ms": {m: round(v, 1) for m, v in delays.items()},
              "cpu_fraction": round(lc["cpu_fraction"], 4),
              "cpu_fraction_runs": [round(r["cpu_fraction"], 4) for r in runs], "suits": suits,
              "stages_us": stages, "wakeup": wake, "max_rate_fps": best,
              "core_max_rate_fps": core}
    log(f"total benchmark time {time.monotonic() - t0:.0f} s")
    if args.json:
        print(json.dumps(result))
    else:
        print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
