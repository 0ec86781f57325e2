#!/usr/bin/env python3
"""Live F1 under input faults: random frame loss, corrupt bytes and malformed datagrams.

    python3 benchmarks/faults.py            # readable table (about 10 minutes)
    python3 benchmarks/faults.py --json     # {"takes": {take: {"serial": {cond: row}, ...}},
                                            #  "pass": bool, "bars": {...}}
    python3 benchmarks/faults.py --takes synth --transports serial --conditions clean,loss5

What runs
---------
Each take is played through the real chain, accelerated (``--speed``, default 4: the
sender's clock, sequence numbers and ``/VMC/Ext/T`` stay those of 120 Hz):

- **serial**: ``rtseg.simulators.serial_device.SerialSuit`` (17 sensors, rtseg's binary
  format, on a real pty) read by ``LiveSession("serial://<pty>?rate=120")``;
- **vmc**: ``rtseg.simulators.vmc_sender.VmcSender`` (VMC bundles over real UDP to
  127.0.0.1) read by ``LiveSession("osc://127.0.0.1:<port>?format=vmc&rate=120")``.

Takes: ``synth``, the synthesised nine-behaviour performance (``simulators/synth``, 62 s,
8 changes, exact truth), and ``cmu86_01``, ``../shared/data/cmu/86_01.amc`` with its
labels (skipped with the reason when the data folder lacks it).

Conditions (the sender's ``rtseg.simulators.faults``): ``clean``; ``loss1`` / ``loss5`` /
``loss10``: each frame not sent with probability 1 / 5 / 10 % (``drop=``); ``corrupt0.01``
/ ``corrupt0.1`` / ``corrupt1``: each byte XOR-ed with probability 0.01 / 0.1 / 1 %
(``corrupt=``; over VMC all datagrams of a frame are one fault message); ``junk`` (VMC
only): the clean stream with malformed datagrams sent from the sender's own socket, each
kind 30 per second of the take's clock (so 120 per take second at any speed): random bytes
(8-1500 bytes), truncated copies of the bundle just sent, that bundle with its bone
messages' type tags changed to ``,siiiiiii``, and 64 KB bundles of bone messages with
unknown names.

Scored: the cuts of the default live detector (``detectors.primary``, as ``rtseg live``
sends them), each mapped back to the take frame it was received as (serial: sequence
number; VMC: ``/VMC/Ext/T``), against the truth at +/- 0.5 s (``rtseg.evaluation.scoring.tally``,
what ``rtseg evaluate --online`` reports as F1).  Every row gives ``f1`` beside the
take's clean ``f1_clean`` and their ratio, the cuts, the detector restarts and bridged gaps,
the frames sent / received, and ``overload_lost``: frames the sender delivered intact that
the session did not process (the reader or loop too slow: pty overflow, UDP buffer, ring
overrun).  A row with ``overload_lost > 0`` measures the machine, not the faults: lower
``--speed``.

``pass``: on every take, over serial F1(loss5) >= 0.95 x clean and F1(corrupt0.1) >= 0.95
x clean, over VMC F1(loss5) >= 0.95 x clean and F1(junk) >= 0.95 x clean.
"""

from __future__ import annotations

import argparse
import json
import logging
import socket
import struct
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from rtseg.evaluation.scoring import pooled_tally, tally  # noqa: E402
from rtseg.live.session import LiveSession  # noqa: E402
from rtseg.live.config import from_dict  # noqa: E402

RATE = 120.0
DATA = REPO.parent / "shared" / "data"
CONDITIONS = {"clean": "", "loss1": "drop=0.01", "loss5": "drop=0.05", "loss10": "drop=0.10",
              "corrupt0.01": "corrupt=0.0001", "corrupt0.1": "corrupt=0.001",
              "corrupt1": "corrupt=0.01", "junk": ""}
TRANSPORTS = ("serial", "vmc")
BARS = {"serial": ("loss5", "corrupt0.1"), "vmc": ("loss5", "junk")}
JUNK_PER_S = 30.0            # each kind, per second of the take's clock


@dataclass
class Bench:
    name: str
    take: Any
    transitions: list


def load_takes(names: list[str], log: Callable[[str], None]) -> tuple[list[Bench], dict]:
    """The takes asked for; {name: reason} for those skipped."""
    out, skipped = [], {}
    for name in names:
        if name == "synth":
            from rtseg.simulators.synth.motion import synthesize
            r = synthesize(frame_rate=RATE, seed=0)
            out.append(Bench("synth", r.take, r.transitions))
        elif name == "cmu86_01":
            motion = DATA / "cmu" / "86_01.amc"
            if not motion.is_file():
                skipped[name] = f"{motion} not found"
                log(f"faults: {name} skipped: {skipped[name]}")
                continue
            from rtseg.labels.takes import find_labelled_takes
            lt = [t for t in find_labelled_takes(DATA, groups=("cmu",)) if t.name == "86_01"]
            if not lt:
                skipped[name] = f"no labels for 86_01 under {DATA / 'labels'}"
                log(f"faults: {name} skipped: {skipped[name]}")
                continue
            out.append(Bench(name, lt[0].load(), lt[0].transitions))
        else:
            raise ValueError(f"unknown take {name!r}; known: synth, cmu86_01")
    return out, skipped


# ============================================================================ sessions
class _Probe:
    """Wraps ``Pipeline.process``: per session frame its seq / source time, and the
    primary detector's cuts (boundary and detected session indices)."""

    def __init__(self, session: LiveSession, keep_quats: bool = False) -> None:
        pipe = session.pipeline
        self.quats: list[np.ndarray] | None = [] if keep_quats else None
        cfg = session.config
        self.primary = cfg["detectors.primary"] or next(iter(pipe.detectors))
        self.seq: list[int | None] = []
        self.src: list[float | None] = []
        self.cuts: list[tuple[int, int]] = []
        inner = pipe.process

        def process(index, quats, valid, seq=None, recv_time=None, lost=0, source_time=None,
                    **kw):
            self.seq.append(seq)
            self.src.append(source_time)
            if self.quats is not None:
                self.quats.append(np.array(quats, dtype=np.float64))
            out = inner(index, quats, valid, seq, recv_time, lost, source_time, **kw)
            for c in out:
                if c.cut.method == self.primary:
                    self.cuts.append((c.boundary, c.detected))
            return out

        pipe.process = process


def _config():
    return from_dict({"output": {"osc": []}, "status": {"interval": 1.0}}, origin="faults")


def _run_session(url: str, start_sender: Callable[[], None],
                 sender_done: Callable[[], bool], timeout: float,
                 keep_quats: bool = False) -> tuple[LiveSession, _Probe, Any]:
    """Run a session on ``url``, start the sender once it is open, stop when the sender is
    done and the session has processed everything it received (0.7 s without progress)."""
    box: dict = {}

    class ProbeSession(LiveSession):
        def _open(self) -> None:
            super()._open()
            box["probe"] = _Probe(self, keep_quats)
            box["opened"] = True

    session = ProbeSession(url, _config(), handle_signals=False)

    def body() -> None:
        try:
            box["summary"] = session.run()
        except BaseException as exc:   # noqa: BLE001 - reported
            box["error"] = exc

    th = threading.Thread(target=body, name="faults-session", daemon=True)
    th.start()
    t0 = time.monotonic()
    while "opened" not in box and th.is_alive() and time.monotonic() - t0 < 30:
        time.sleep(0.02)
    if "opened" not in box:
        session.stop("not opened")
        th.join(10)
        raise RuntimeError(f"session on {url} did not open: {box.get('error')}")
    start_sender()
    while not sender_done() and time.monotonic() - t0 < timeout:
        time.sleep(0.1)
    last, still = -1, 0.0
    while still < 0.7 and time.monotonic() - t0 < timeout + 30:
        n = session.stats.frames_processed
        still = still + 0.1 if n == last else 0.0
        last = n
        time.sleep(0.1)
    session.stop("faults done")
    th.join(30)
    if "error" in box:
        raise RuntimeError(f"session crashed: {box['error']!r}")
    return session, box["probe"], box.get("summary")


def run_serial(b: Bench, faults: str, speed: float) -> dict:
    from rtseg.simulators.serial_device import SerialSuit
    suit = SerialSuit(b.take, rate=RATE, speed=speed, faults=faults or None)
    path = suit.start(send=False)
    try:
        session, probe, _ = _run_session(f"serial://{path}?rate={RATE:g}", suit.begin,
                                         lambda: suit.wait_done(0), b.take.n_frames / RATE / speed + 60)
    finally:
        suit.stop()
    # a frame's seq is its message index less the numbers taken by the info messages the
    # source received after its first message (rtseg.drivers.serial.stream: frames number
    # frames; the first message starts the numbering whatever its type)
    by_frame_seq, others, seen = {}, 0, False
    for m in suit.sent_log:
        if m.frame < 0:
            others += m.fate == "intact" and seen
        else:
            by_frame_seq[m.index - others] = m
        seen = seen or m.fate == "intact"
    # unwrap the u16 sequence numbers
    frames, received = [], set()
    prev, base = None, 0
    for s in probe.seq:
        if s is None:
            frames.append(-1)
            continue
        if prev is not None and s < prev and prev - s > 32768:
            base += 65536
        prev = s
        m = by_frame_seq.get(base + s)
        frames.append(m.frame if m is not None else -1)
        if m is not None:
            received.add(m.index)
    intact = [m.index for m in suit.sent_log if m.frame >= 0 and m.fate == "intact"]
    overflow = sum(1 for m in suit.sent_log if m.fate == "overflow")
    lost = sum(1 for i in intact if i not in received) + overflow + session.stats.overruns
    sent = sum(1 for m in suit.sent_log if m.frame >= 0)
    return _row(b, session, probe, np.array(frames), sent, lost)


_BONE_TAG = b",sfffffff"


def _junk(rng: np.random.Generator, last: bytes, k: int) -> bytes:
    """Malformed datagram of kind ``k`` (0 random bytes, 1 truncated copy of ``last``,
    2 ``last`` with bone type tags changed, 3 a 64 KB bundle of unknown bone names)."""
    if k == 0:
        return rng.integers(0, 256, int(rng.integers(8, 1501)), dtype=np.uint8).tobytes()
    if k == 1:
        return last[:int(rng.integers(1, max(2, len(last))))]
    if k == 2:
        return last.replace(_BONE_TAG, b",siiiiiii")
    from rtseg.drivers.osc.vmc.encode import encode_pose_message
    msgs = []
    size = 16
    i = 0
    while size < 65000 - 80:
        m = encode_pose_message("/VMC/Ext/Bone/Pos", f"NoSuchBone{i}", (0, 0, 0), (0, 0, 0, 1))
        msgs.append(struct.pack(">i", len(m)) + m)
        size += len(m) + 4
        i += 1
    return b"#bundle\x00" + struct.pack(">Q", 1) + b"".join(msgs)


def run_vmc(b: Bench, faults: str, speed: float, junk: bool) -> dict:
    from rtseg.simulators.vmc_sender import VmcSender
    probe_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe_sock.bind(("127.0.0.1", 0))
    port = probe_sock.getsockname()[1]
    probe_sock.close()
    period = 1.0 / RATE
    big = _junk(np.random.default_rng(0), b"", 3)
    counts = [0, 0, 0, 0]

    class JunkSender(VmcSender):
        """Sends the take; with ``junk``, malformed datagrams from the same socket, each
        kind due every 1/30 s of the take's clock."""
        rng = np.random.default_rng(1)

        def _send(self, dgrams: list[bytes]) -> None:
            super()._send(dgrams)
            if not junk or not dgrams:
                return
            slot = len(self.sent_log)
            due = int((slot + 1) * period * JUNK_PER_S)
            while counts[0] < due:
                bad = [_junk(self.rng, dgrams[0], k) if k < 3 else big for k in range(4)]
                for k, d in enumerate(bad):
                    try:
                        self._sock.sendto(d, self._addr)
                    except OSError:
                        pass
                    counts[k] += 1

    sender = JunkSender(b.take, "127.0.0.1", port, rate=RATE, speed=speed,
                        faults=faults or None)
    try:
        session, probe, _ = _run_session(
            f"osc://127.0.0.1:{port}?format=vmc&rate={RATE:g}", sender.start,
            lambda: sender.done.is_set(), b.take.n_frames / RATE / speed + 60, keep_quats=True)
    finally:
        sender.stop()
    frames = match_frames(probe.quats, session.pipeline.joint_names, sender)
    received = set(frames.tolist())
    frames = fill_unmatched(frames)
    log_ = sender.sent_log
    intact = [f.index for f in log_ if not f.dropped and not f.corrupted]
    lost = sum(1 for i in intact if i not in received) + session.stats.overruns
    row = _row(b, session, probe, frames, len(log_), lost)
    if junk:
        row["junk_sent"] = dict(zip(("random", "truncated", "wrong_types", "bundle_64k"), counts))
    return row


def match_frames(received: list[np.ndarray], joint_names: list[str], sender: Any,
                 window: int = 64, max_dist: float = 1e-6) -> np.ndarray:
    """The take frame each received VMC frame is, found by content (its ``/VMC/Ext/T``
    cannot tell once a corrupt T has started a new clock segment): the sent frame among
    the next ``window`` after the last match (the window widens by two frames for every
    received frame that matched none, so a run of damaged frames does not lose the place)
    whose bone rotations are nearest (median of 1 - |dot| over the bones, so one damaged
    bone does not hide the frame; float32 on the wire leaves about 1e-8, neighbouring
    frames at 120 Hz differ by far more than ``max_dist``), -1 when none is within it."""
    names = [n.lower() for n in joint_names]
    cols = [names.index(b.lower()) for b in sender.bone_names]
    sent = sender._quats                      # (frames, bones, 4), rtseg frame
    out = np.full(len(received), -1, dtype=np.int64)
    p = misses = 0
    for i, q in enumerate(received):
        cand = sent[p:p + window + 2 * misses]
        if not len(cand):
            break
        d = np.median(1.0 - np.abs(np.einsum("fbk,bk->fb", cand, q[cols])), axis=1)
        k = int(np.argmin(d))
        if d[k] <= max_dist:
            out[i] = p + k
            p = p + k + 1
            misses = 0
        else:
            misses += 1
    return out


def fill_unmatched(frames: np.ndarray) -> np.ndarray:
    """``frames`` with each -1 (a received frame matched to no sent one: a damaged bone)
    placed between its matched neighbours, in proportion to its position among the
    received frames between them (after the last match: one frame per frame received)."""
    out = frames.astype(np.float64)
    ok = np.flatnonzero(frames >= 0)
    if not len(ok):
        return frames
    bad = np.flatnonzero(frames < 0)
    out[bad] = np.interp(bad, ok, frames[ok].astype(np.float64))
    after = bad[bad > ok[-1]]
    out[after] = frames[ok[-1]] + (after - ok[-1])
    before = bad[bad < ok[0]]
    out[before] = np.maximum(0, frames[ok[0]] - (ok[0] - before))
    return np.round(out).astype(np.int64)


def _row(b: Bench, session: LiveSession, probe: _Probe, frames: np.ndarray, sent: int,
         lost: int) -> dict:
    """Score the primary detector's cuts (session indices -> take frames)."""
    n = len(frames)
    cuts = []
    for bo, de in probe.cuts:
        fb = frames[min(bo, n - 1)] if n else -1
        fd = frames[min(de, n - 1)] if n else -1
        if fb >= 0:
            cuts.append((int(fb), int(max(fd, fb))))
    t = pooled_tally([tally(cuts, b.transitions, RATE, 0.5)])
    ps = session.pipeline.stats
    src = session.source.stats.as_dict() if session.source is not None else {}
    return {"f1": t["f1"], "strict_f1": t["strict_f1"], "cuts": t["cuts"],
            "transitions": t["transitions"], "frames_sent": sent,
            "frames_received": session.stats.frames_received, "overload_lost": lost,
            "restarts": ps.restarts, "bridged_gaps": ps.bridged_gaps,
            "filled_frames": ps.filled_frames, "gap_frames": ps.gap_frames,
            "source": {k: v for k, v in src.items() if v}}


# ============================================================================ main
def measure(takes: list[Bench], transports: list[str], conditions: list[str], speed: float,
            log: Callable[[str], None]) -> dict:
    out: dict = {}
    for b in takes:
        out[b.name] = {}
        for tr in transports:
            rows: dict = {}
            for cond in conditions:
                if cond == "junk" and tr != "vmc":
                    continue
                t0 = time.monotonic()
                spec = CONDITIONS[cond]
                if spec:
                    spec += ",seed=3"
                row = (run_serial(b, spec, speed) if tr == "serial"
                       else run_vmc(b, spec, speed, cond == "junk"))
                row["wall_s"] = round(time.monotonic() - t0, 1)
                rows[cond] = row
                log(f"  {b.name:9} {tr:6} {cond:12} F1 {row['f1']:.3f}  cuts {row['cuts']:3}  "
                    f"restarts {row['restarts']:4}  bridged {row['bridged_gaps']:5}  "
                    f"received {row['frames_received']}/{row['frames_sent']}  "
                    f"overload lost {row['overload_lost']}  ({row['wall_s']} s)")
            clean = rows.get("clean", {}).get("f1")
            for row in rows.values():
                row["f1_clean"] = clean
                row["ratio"] = (row["f1"] / clean) if clean else None
            out[b.name][tr] = rows
    return out


def verdict(results: dict) -> tuple[bool | None, dict]:
    """(pass, {take/transport/condition: ratio >= 0.95}): False when a bar failed, None
    when none was run (or a clean F1 was 0), else True."""
    bars: dict[str, bool] = {}
    for take, trs in results.items():
        for tr, conds in BARS.items():
            for c in conds:
                row = trs.get(tr, {}).get(c)
                if row is not None and row["ratio"] is not None:
                    bars[f"{take}/{tr}/{c}"] = row["ratio"] >= 0.95
    if not bars:
        return None, bars
    return all(bars.values()), bars


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--json", action="store_true", help="print only the JSON result")
    p.add_argument("--speed", type=float, default=4.0,
                   help="senders run this many times faster than 120 Hz (default 4)")
    p.add_argument("--takes", default="synth,cmu86_01", help="comma list: synth, cmu86_01")
    p.add_argument("--transports", default="serial,vmc", help="comma list: serial, vmc")
    p.add_argument("--conditions", default=",".join(CONDITIONS),
                   help=f"comma list of {', '.join(CONDITIONS)} (clean is always run)")
    p.add_argument("--seconds", type=float, default=0.0,
                   help="play only the first SECONDS of each take (0 = all; for smoke tests)")
    args = p.parse_args(argv)
    transports = [t for t in args.transports.split(",") if t]
    conditions = [c for c in args.conditions.split(",") if c]
    for t in transports:
        if t not in TRANSPORTS:
            p.error(f"unknown transport {t!r}; known: {', '.join(TRANSPORTS)}")
    for c in conditions:
        if c not in CONDITIONS:
            p.error(f"unknown condition {c!r}; known: {', '.join(CONDITIONS)}")
    if "clean" not in conditions:
        conditions.insert(0, "clean")
    if not args.speed > 0:
        p.error("--speed must be > 0")
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")

    def log(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    try:
        takes, skipped = load_takes([t for t in args.takes.split(",") if t], log)
    except ValueError as exc:
        p.error(str(exc))
    if args.seconds > 0:
        n = int(args.seconds * RATE)
        for b in takes:
            b.take = b.take.slice(0, n) if hasattr(b.take, "slice") else b.take
            b.transitions = [t for t in b.transitions if t.hi < n]
    results = measure(takes, transports, conditions, args.speed, log)
    ok, bars = verdict(results)
    doc = {"speed": args.speed, "tolerance_s": 0.5, "takes": results, "skipped": skipped,
           "bars": bars, "pass": ok}
    if args.json:
        print(json.dumps(doc, indent=2))
    else:
        for take, trs in results.items():
            for tr, rows in trs.items():
                print(f"{take} over {tr}: clean F1 {rows['clean']['f1']:.3f}")
                for c, r in rows.items():
                    if c != "clean":
                        print(f"  {c:12} F1 {r['f1']:.3f} ({r['ratio'] if r['ratio'] is None else round(r['ratio'], 3)} x clean), "
                              f"{r['restarts']} restarts, {r['bridged_gaps']} gaps bridged, "
                              f"overload lost {r['overload_lost']}")
        for k, why in skipped.items():
            print(f"{k}: skipped ({why})")
        print("PASS" if ok else ("FAIL" if ok is False else "no bar run"))
    return 0 if ok is not False else 1


if __name__ == "__main__":
    sys.exit(main())
