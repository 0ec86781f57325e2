#!/usr/bin/env python3
"""Decode throughput of the live input codecs for a 17-sensor suit (frames per second).

    python3 benchmarks/decode.py                   # readable report
    python3 benchmarks/decode.py --json            # {"serial": {"frames_per_s": N},
                                                   #  "vmc": {"frames_per_s": N}, ...}
    python3 benchmarks/decode.py --frames 5000 --repeat 7

Bytes are encoded **before** timing (encoding is not counted); the timed loop is decoding
only, on one core, median of ``--repeat`` runs:

- ``serial``: ``rtseg.drivers.codec_serial.SerialFrameDecoder`` fed the binary wire
  stream (COBS + CRC, Q14) in 4096-byte chunks, as a serial read loop would deliver it.
- ``vmc``: ``rtseg.drivers.codec_vmc.VmcAssembler`` fed one UDP datagram at a time
  (17 Bone/Pos + Root/Pos + T + OK per frame, bundles of at most 1472 bytes: one datagram),
  frames closed and converted to rtseg's frame exactly as the live OSC source does (the
  whole-frame fast path applies).
- ``vmc_general_path``: the same with the whole-frame fast path off (message by message).
- ``vmc_55_bones``: every HumanBodyBones name sent, as VirtualMotionCapture does (38 are
  outside the suit and ignored), 3 datagrams per frame (message-by-message path).
- ``python_osc_parse`` (for comparison): python-osc's ``OscPacket`` parsing the same VMC
  datagrams, without any frame assembly.

Targets: >= 20 000 frames/s for VMC (a suit sends 60-120).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from rtseg.drivers.codec_vmc import HUMAN_BODY_BONES, VmcAssembler, encode_frame as vmc_encode

BONES = ["Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand",
         "RightUpperArm", "RightLowerArm", "RightHand", "LeftUpperLeg", "LeftLowerLeg",
         "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot"]
SERIAL_CHUNK = 4096


def motion(n: int, seed: int = 0) -> np.ndarray:
    """(n, 17, 4) smooth, sign-continuous unit quaternions (scalar-last)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None, None] / 120.0
    rv = 0.7 * np.sin(2 * np.pi * (0.3 + rng.random((1, 17, 3))) * t + 6 * rng.random((1, 17, 3)))
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat().reshape(n, 17, 4)


def bench_vmc(q: np.ndarray, repeat: int, fast: bool = True, full: bool = False) -> dict:
    """``full``: send all 55 HumanBodyBones (as VirtualMotionCapture does; the 38 outside the
    suit are ignored), several datagrams per frame."""
    n = q.shape[0]
    if full:
        names = list(HUMAN_BODY_BONES)
        cols = [BONES.index(b) if b in BONES else -1 for b in names]
        ident = np.array([0.0, 0.0, 0.0, 1.0])
        qq = np.stack([q[:, c] if c >= 0 else np.broadcast_to(ident, (n, 4)) for c in cols], 1)
    else:
        names, qq = BONES, q
    dgrams = [d for i in range(n) for d in vmc_encode(
        qq[i], names, time=i / 120.0, root_position=(0.0, 1.0, 0.01 * i))]
    rates = []
    for _ in range(repeat):
        asm = VmcAssembler(BONES, fast=fast)
        got = 0
        t0 = time.perf_counter()
        for k, d in enumerate(dgrams):
            got += len(asm.feed(d, k * 1e-3))
        dt = time.perf_counter() - t0
        got += len(asm.flush(1e9, force=True))
        if got != n:
            raise RuntimeError(f"VMC decoded {got} of {n} frames")
        rates.append(n / dt)
    return {"frames_per_s": round(statistics.median(rates)),
            "runs": [round(r) for r in rates],
            "datagrams_per_frame": len(dgrams) / n,
            "bytes_per_frame": sum(map(len, dgrams)) / n}


def bench_python_osc(q: np.ndarray, repeat: int) -> dict | None:
    try:
        from pythonosc.osc_packet import OscPacket
    except ImportError:  # pragma: no cover
        return None
    n = q.shape[0]
    dgrams = [d for i in range(n) for d in vmc_encode(q[i], BONES, time=i / 120.0,
                                                       root_position=(0.0, 1.0, 0.0))]
    rates = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for d in dgrams:
            for m in OscPacket(d).messages:
                m.message.params
        rates.append(n / (time.perf_counter() - t0))
    return {"frames_per_s": round(statistics.median(rates))}


def bench_serial(q: np.ndarray, repeat: int) -> dict | None:
    try:
        from rtseg.drivers.codec_serial import SerialFrameDecoder, encode_frame as ser_encode
    except ImportError as exc:
        print(f"serial decoder not available: {exc}", file=sys.stderr)
        return None
    n = q.shape[0]
    ids = list(range(17))
    stream = b"".join(ser_encode(i, i * 8333, ids, q[i]) for i in range(n))
    chunks = [stream[k:k + SERIAL_CHUNK] for k in range(0, len(stream), SERIAL_CHUNK)]
    rates = []
    for _ in range(repeat):
        dec = SerialFrameDecoder(known_ids=ids)
        got = 0
        t0 = time.perf_counter()
        for c in chunks:
            got += len(dec.feed(c))
        dt = time.perf_counter() - t0
        if got != n:
            raise RuntimeError(f"serial decoded {got} of {n} frames")
        rates.append(n / dt)
    return {"frames_per_s": round(statistics.median(rates)),
            "runs": [round(r) for r in rates],
            "bytes_per_frame": len(stream) / n, "chunk_bytes": SERIAL_CHUNK}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--frames", type=int, default=5000, help="frames per run (default 5000)")
    p.add_argument("--repeat", type=int, default=5, help="runs; the median is reported (default 5)")
    args = p.parse_args(argv)
    if args.frames < 10 or args.repeat < 1:
        p.error("--frames must be >= 10 and --repeat >= 1")
    q = motion(args.frames)
    result: dict = {}
    serial = bench_serial(q, args.repeat)
    result["serial"] = serial if serial is not None else {"frames_per_s": None}
    result["vmc"] = bench_vmc(q, args.repeat)
    result["vmc_general_path"] = bench_vmc(q, args.repeat, fast=False)
    result["vmc_55_bones"] = bench_vmc(q, args.repeat, full=True)
    pyosc = bench_python_osc(q[: max(10, args.frames // 5)], max(1, min(args.repeat, 3)))
    if pyosc is not None:
        result["python_osc_parse"] = pyosc
    result["config"] = {"frames": args.frames, "repeat": args.repeat, "sensors": 17,
                        "python": platform.python_version(), "machine": platform.machine()}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"decode throughput, 17-sensor suit, {args.frames} frames, median of {args.repeat} runs")
    if serial is not None:
        print(f"  serial (COBS+CRC, {serial['bytes_per_frame']:.0f} B/frame, "
              f"{SERIAL_CHUNK} B reads): {serial['frames_per_s']:>9,} frames/s")
    v = result["vmc"]
    print(f"  VMC (OSC/UDP, {v['datagrams_per_frame']:.1f} datagrams, {v['bytes_per_frame']:.0f} "
          f"B/frame):    {v['frames_per_s']:>9,} frames/s")
    g, f = result["vmc_general_path"], result["vmc_55_bones"]
    print(f"  VMC, message-by-message path only:           {g['frames_per_s']:>9,} frames/s")
    print(f"  VMC, 55 bones ({f['datagrams_per_frame']:.0f} datagrams, {f['bytes_per_frame']:.0f} B/frame):"
          f"       {f['frames_per_s']:>9,} frames/s")
    if pyosc is not None:
        print(f"  python-osc parse only (comparison):          {pyosc['frames_per_s']:>9,} frames/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
