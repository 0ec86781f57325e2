"""Cost on the caller's thread of publishing events and recording frames.

    python3 benchmarks/bench_output.py [--n 20000]

Measures, per call (median and 99th percentile of per-call times, microseconds):
- ``publish_cut`` over OSC/UDP to a listening socket on 127.0.0.1 (2 datagrams per cut),
  and to a port where nothing listens (refusals counted);
- ``publish_cut`` with one QLab-style template (3 datagrams);
- ``publish_cut`` over OSC/TCP (SLIP), i.e. the queue append; the connection thread sends;
- ``publish_cut`` as JSON lines to a file (write + flush per line);
- ``PublisherSet.publish_cut`` fanning out to UDP + JSON lines;
- ``SessionRecorder.record_frame`` for a 17-joint frame (flush every 0.5 s), and the
  flush itself.
"""

from __future__ import annotations

import argparse
import socket
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from rtseg.core.events import CutEvent
from rtseg.core.frame import Frame
from rtseg.publishers import (JsonlPublisher, OscTcpPublisher, OscUdpPublisher, PublisherSet)
from rtseg.recording import SessionRecorder


def timed(fn, n: int) -> tuple[float, float]:
    ts = np.empty(n)
    pc = time.perf_counter
    for i in range(n):
        t0 = pc()
        fn(i)
        ts[i] = pc() - t0
    return float(np.median(ts) * 1e6), float(np.percentile(ts, 99) * 1e6)


def cut(i: int) -> CutEvent:
    return CutEvent(event=i, segment=i, frame=10 * i, time=0.1 * i, method="pca",
                    label="walk", confidence=0.8, boundary_recv_time=time.monotonic() - 0.01,
                    detector_delay_ms=50.0)


def drain(sock: socket.socket, stop: threading.Event) -> None:
    sock.settimeout(0.05)
    while not stop.is_set():
        try:
            sock.recv(65536)
        except (socket.timeout, OSError):
            pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=20000)
    args = ap.parse_args()
    n = args.n
    rows = []

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    stop = threading.Event()
    th = threading.Thread(target=drain, args=(rx, stop))
    th.start()
    port = rx.getsockname()[1]
    with OscUdpPublisher("127.0.0.1", port) as p:
        rows.append(("udp publish_cut (listening)", *timed(lambda i: p.publish_cut(cut(i)), n)))
    with OscUdpPublisher("127.0.0.1", port, templates=["/cue/{label}/start"]) as p:
        rows.append(("udp publish_cut + 1 template", *timed(lambda i: p.publish_cut(cut(i)), n)))

    down = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    down.bind(("127.0.0.1", 0))
    down_port = down.getsockname()[1]
    down.close()
    with OscUdpPublisher("127.0.0.1", down_port) as p:
        rows.append(("udp publish_cut (target down)", *timed(lambda i: p.publish_cut(cut(i)), n)))
        print(f"  target down: refused={p.stats.refused} dropped={p.stats.dropped}")

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    p = OscTcpPublisher("127.0.0.1", srv.getsockname()[1], queue_size=n * 3)
    conn, _ = srv.accept()
    th2 = threading.Thread(target=drain, args=(conn, stop))
    th2.start()
    rows.append(("tcp publish_cut (enqueue)", *timed(lambda i: p.publish_cut(cut(i)), n)))
    p.close()

    with tempfile.TemporaryDirectory() as tmp:
        with JsonlPublisher(str(Path(tmp) / "e.jsonl")) as p:
            rows.append(("jsonl publish_cut (file)", *timed(lambda i: p.publish_cut(cut(i)), n)))
        with PublisherSet([OscUdpPublisher("127.0.0.1", port),
                           JsonlPublisher(str(Path(tmp) / "f.jsonl"))]) as ps:
            rows.append(("PublisherSet udp+jsonl", *timed(lambda i: ps.publish_cut(cut(i)), n)))

        J = 17
        rng = np.random.default_rng(0)
        q = rng.normal(size=(J, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        valid = np.ones(J, bool)
        rec = SessionRecorder(Path(tmp) / "s", [f"j{i}" for i in range(J)], [-1] * J,
                              frame_rate=100.0)
        frames = [Frame(recv_time=time.monotonic(), quats=q, valid=valid, source_time=i * 0.01,
                        seq=i) for i in range(n)]
        rows.append(("record_frame 17 joints", *timed(lambda i: rec.record_frame(frames[i]), n)))
        rec.flush_interval_s = 1e9
        for f in frames[:50]:
            rec.record_frame(f)
        t0 = time.perf_counter()
        rec.flush()
        rows.append(("flush of 50 frames (0.5 s at 100 Hz)", (time.perf_counter() - t0) * 1e6, float("nan")))
        rec.close()

    stop.set()
    th.join()
    th2.join()
    rx.close()
    conn.close()
    srv.close()
    print(f"{'operation':40s} {'median us':>10s} {'p99 us':>10s}   (n={n})")
    for name, med, p99 in rows:
        print(f"{name:40s} {med:10.1f} {p99:10.1f}")


if __name__ == "__main__":
    main()
