#!/usr/bin/env python3
"""Decode throughput of the live input codecs for a 17-sensor suit (frames per second).

    python3 benchmarks/decode.py                   # readable report
    python3 benchmarks/decode.py --json            # {"serial": {"frames_per_s": N},
                                                   #  "vmc": {"frames_per_s": N}, ...}
    python3 benchmarks/decode.py --frames 5000 --repeat 7
    python3 benchmarks/decode.py --cpu-time        # process CPU time instead of wall clock
    python3 benchmarks/decode.py --only axis       # only the rows named axis...
    git worktree add /tmp/before <commit>          # the code before a change, timed by
    python3 benchmarks/decode.py --tree /tmp/before   # these loops (PYTHONPATH alone is not
                                                   # enough: see _use_tree)

Bytes are encoded **before** timing (encoding is not counted); the timed loop is decoding
only, on one core, median of ``--repeat`` runs:

- ``serial``: ``rtseg.drivers.serial.codec.SerialFrameDecoder`` fed the binary wire
  stream (COBS + CRC, Q14) in 4096-byte chunks, as a serial read loop would deliver it.
  ``serial_one_frame``: the same frames fed one frame per call (a live suit's reads at
  its rate each hold one frame: numpy's per-call cost is then the cost).
- ``vmc``: ``rtseg.drivers.osc.vmc.codec.VmcAssembler`` fed one UDP datagram at a time
  (17 Bone/Pos + Root/Pos + T + OK per frame, bundles of at most 1472 bytes: one datagram),
  frames closed and converted to rtseg's frame exactly as the live OSC source does (the
  whole-frame fast path applies).
- ``vmc_general_path``: the same with the whole-frame fast path off (message by message).
- ``vmc_55_bones``: every HumanBodyBones name sent, as VirtualMotionCapture does (38 are
  outside the suit and ignored), 3 datagrams per frame (message-by-message path).
- ``python_osc_parse`` (for comparison): python-osc's ``OscPacket`` parsing the same VMC
  datagrams, without any frame assembly.

- ``mvn``: ``rtseg.drivers.mvn.assembler.MvnAssembler`` fed Xsens MVN type-02 datagrams (23
  segments, one 760-byte datagram per frame); ``mvn_3_datagrams``: the same frames split
  over 3 datagrams each (reassembly by sample counter).
- ``mocopi``: ``rtseg.drivers.mocopi.assembler.MocopiAssembler`` fed mocopi ``fram`` datagrams
  (27 bones, one datagram per frame).

- ``rokoko``: ``rtseg.drivers.rokoko.source.RokokoAssembler`` fed Rokoko Studio Custom
  JSON v3 payloads (one actor, 21 bones; JSON parsed with orjson, a core dependency - the
  row says which parser ran, the json module only where orjson is missing);
  ``rokoko_lz4``: the same payloads LZ4-compressed; ``rokoko_json_module``: plain payloads
  parsed with the standard json module (the fallback, for comparison).
- ``mvn_tcp``: the ``mvn`` frames as MVN's TCP stream (messages back to back) in 4096-byte
  reads, cut by ``rtseg.drivers.mvn.codec.MxtpStream`` and assembled.
- ``axis_binary``: Axis BVH binary datagrams (64-byte header + 354 float32, 1480 bytes)
  through the axis source's datagram joiner, decoder and Euler -> quaternion conversion
  (``space=local``); ``axis_binary_global``: the same with ``space=global`` (the sources'
  default: forward kinematics per frame); ``axis_binary_global_burst``: the same fed 16
  datagrams at a time to ``_BinaryAdapter.feed_many`` (what the binary source decodes at
  once when datagrams wait in its socket: the catch-up rate); ``axis_text``: the same frames as the TCP text
  stream (``||``-separated, 354 numbers, ~2.5 KB a frame here: zero bone offsets), fed in
  4096-byte reads through ``axis_source.TextStream`` (the numbers of the frames a read
  completes are parsed by one orjson call and the frames converted together; a read
  completes 1 or 2 frames);
  ``axis_text_global`` the same in global space; ``axis_text_64k`` in 65536-byte reads
  (what the source reads when it has fallen behind: the catch-up rate) and
  ``axis_text_global_64k`` the same in global space (the sources' default).

Targets: >= 20 000 frames/s for VMC, MVN, mocopi, Rokoko and Axis (a suit sends 60-240).

Where an Axis text frame's time goes, step by step: ``benchmarks/axis_steps.py``.  Hostile
input for every decoder: ``benchmarks/fuzz_decoders.py``.  The objects fed here are the
sources' own per-read pipelines (``benchmarks/codec_feeds.py``, shared with the fuzzer).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time

import numpy as np


def _use_tree(argv: list[str]) -> str | None:
    """``--tree DIR`` on the command line: import rtseg (rtseg, rtseg.drivers,
    rtseg.simulators, rtseg.defaults) from the source tree DIR - e.g. a ``git worktree`` of
    an older commit - instead of the installed package.  ``PYTHONPATH=DIR`` alone is not
    enough: the editable install maps ``rtseg.drivers`` to this checkout's ``drivers/``
    whatever comes first on the path.  Returns DIR (or None)."""
    if "--tree" not in argv or argv.index("--tree") + 1 >= len(argv):
        return None
    import importlib.util
    import types
    from pathlib import Path
    root = Path(argv[argv.index("--tree") + 1]).resolve()
    sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in
                        (getattr(f, "__module__", "") + getattr(f, "__name__", "")).lower()]
    for name, sub in (("rtseg", "rtseg"), ("rtseg.drivers", "drivers"),
                      ("rtseg.simulators", "simulators"), ("rtseg.defaults", "config")):
        path, init = root / sub, root / sub / "__init__.py"
        if init.exists():
            spec = importlib.util.spec_from_file_location(
                name, init, submodule_search_locations=[str(path)])
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
        else:
            module = types.ModuleType(name)
            module.__path__ = [str(path)]
            sys.modules[name] = module
    return str(root)


TREE = _use_tree(sys.argv) if __name__ == "__main__" else None

from rtseg.drivers.osc.vmc.codec import (HUMAN_BODY_BONES, VmcAssembler,  # noqa: E402
                                      encode_frame as vmc_encode)
# the default17 suit's bones, in sensor order
from rtseg.simulators.synth.skeleton import JOINT_NAMES as BONES  # noqa: E402

from codec_feeds import (AxisTextFeed, MvnTcpFeed, axis_binary_feed, axis_values,  # noqa: E402
                         numpy_axis_path, rokoko_feed, rokoko_payloads, vendor_motion)

SERIAL_CHUNK = 4096
#: timer of the timed loops: wall clock, or this process's CPU time with --cpu-time
_clock = time.perf_counter


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
    rates = _time_feed(lambda: VmcAssembler(BONES, fast=fast), dgrams, n, repeat, "VMC")
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
        t0 = _clock()
        for d in dgrams:
            for m in OscPacket(d).messages:
                m.message.params
        rates.append(n / (_clock() - t0))
    return {"frames_per_s": round(statistics.median(rates))}


def _time_feed(make, dgrams: list[bytes], n: int, repeat: int, what: str) -> list[float]:
    rates = []
    for _ in range(repeat):
        asm = make()
        got = 0
        t0 = _clock()
        for k, d in enumerate(dgrams):
            got += len(asm.feed(d, k * 1e-3))
        dt = _clock() - t0
        got += len(asm.flush(1e9, force=True))
        if got != n:
            raise RuntimeError(f"{what} decoded {got} of {n} frames")
        rates.append(n / dt)
    return rates


def bench_mvn(n: int, repeat: int, parts: int = 1) -> dict:
    from rtseg.drivers.mvn.assembler import MvnAssembler
    from rtseg.drivers.mvn.codec import HEADER_SIZE, ITEM_SIZE, encode_datagrams
    q = vendor_motion(n, 23)
    ids = list(range(1, 24))
    per = -(-23 // parts)
    dgrams = [d for i in range(n) for d in encode_datagrams(
        i, i * 8, ids, q[i], np.zeros((23, 3)), max_datagram=HEADER_SIZE + per * ITEM_SIZE)]
    rates = _time_feed(lambda: MvnAssembler(ids), dgrams, n, repeat, "MVN")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "datagrams_per_frame": len(dgrams) / n, "bytes_per_frame": sum(map(len, dgrams)) / n}


def bench_mocopi(n: int, repeat: int) -> dict:
    from rtseg.drivers.mocopi.assembler import MocopiAssembler
    from rtseg.drivers.mocopi.codec import encode_frame
    q = vendor_motion(n, 27)
    dgrams = [encode_frame(i, q[i], time=i * 20, uttm=1.7e9 + i / 50) for i in range(n)]
    rates = _time_feed(MocopiAssembler, dgrams, n, repeat, "mocopi")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "datagrams_per_frame": 1.0, "bytes_per_frame": sum(map(len, dgrams)) / n}


def bench_rokoko(n: int, repeat: int, compress: bool = False, json_module: bool = False) -> dict:
    from rtseg.drivers.rokoko import codec as codec_rokoko
    dgrams = rokoko_payloads(n, compress)
    saved = codec_rokoko._loads
    if json_module:
        codec_rokoko._loads = json.loads
    try:
        rates = _time_feed(rokoko_feed, dgrams, n, repeat, "Rokoko")
    finally:
        codec_rokoko._loads = saved
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "datagrams_per_frame": 1.0, "bytes_per_frame": sum(map(len, dgrams)) / n,
            "json_parser": "json" if json_module else codec_rokoko.JSON_PARSER}


def bench_mvn_tcp(n: int, repeat: int) -> dict:
    """MVN over TCP: the type-02 messages back to back, in 4096-byte reads, cut by
    MxtpStream and fed to the assembler (what MvnTcpSource runs per read)."""
    from rtseg.drivers.mvn.codec import encode_datagrams
    q = vendor_motion(n, 23)
    ids = list(range(1, 24))
    stream = b"".join(d for i in range(n) for d in encode_datagrams(i, i * 8, ids, q[i],
                                                                     np.zeros((23, 3))))
    reads = [stream[k:k + SERIAL_CHUNK] for k in range(0, len(stream), SERIAL_CHUNK)]
    rates = _time_feed(lambda: MvnTcpFeed(ids), reads, n, repeat, "MVN TCP")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "bytes_per_frame": len(stream) / n}


def bench_axis(n: int, repeat: int, text: bool = False, space: str = "local",
               chunk: int = SERIAL_CHUNK) -> dict:
    """``chunk``: bytes per TCP read of the text stream (4096; 65536 is what the source
    asks for, and gets when it has fallen behind)."""
    from rtseg.drivers.axis.codec import encode_binary
    from rtseg.drivers.axis.text import encode_text
    v = axis_values(n)
    if text:
        stream = b"".join(encode_text(v[i]) for i in range(n))
        dgrams = [stream[k:k + chunk] for k in range(0, len(stream), chunk)]
        dgrams.append(b"||")          # the stream's last frame ends at the next separator
        make = lambda: AxisTextFeed(space)  # noqa: E731
    else:
        dgrams = [encode_binary(v[i], frame_index=i) for i in range(n)]
        stream = b"".join(dgrams)
        make = lambda: axis_binary_feed(space)  # noqa: E731
    rates = _time_feed(make, dgrams, n, repeat, "Axis")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "bytes_per_frame": len(stream) / n}


def bench_axis_burst(n: int, repeat: int, burst: int = 16, space: str = "global") -> dict:
    """Axis binary datagrams ``burst`` at a time through ``_BinaryAdapter.feed_many``: what
    the binary source decodes when datagrams wait in its socket (a reader catching up)."""
    from rtseg.drivers.axis.codec import encode_binary
    v = axis_values(n)
    dgrams = [encode_binary(v[i], frame_index=i) for i in range(n)]
    groups = [dgrams[k:k + burst] for k in range(0, n, burst)]
    rates = []
    for _ in range(repeat):
        asm = axis_binary_feed(space)
        if not hasattr(asm, "feed_many"):       # code before feed_many: one at a time
            asm.feed_many = lambda g, now, a=asm: [f for d in g for f in a.feed(d, now)]
        got = 0
        t0 = _clock()
        for k, g in enumerate(groups):
            got += len(asm.feed_many(g, k * 1e-3))
        dt = _clock() - t0
        if got != n:
            raise RuntimeError(f"Axis burst decoded {got} of {n} frames")
        rates.append(n / dt)
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "bytes_per_frame": len(dgrams[0]), "burst": burst}


def bench_serial(q: np.ndarray, repeat: int, one_frame: bool = False) -> dict | None:
    try:
        from rtseg.drivers.serial.codec import SerialFrameDecoder, encode_frame as ser_encode
    except ImportError as exc:
        print(f"serial decoder not available: {exc}", file=sys.stderr)
        return None
    n = q.shape[0]
    ids = list(range(17))
    stream = b"".join(ser_encode(i, i * 8333, ids, q[i]) for i in range(n))
    if one_frame:         # what a live read delivers at the suit's rate: one frame a read
        chunks = [ser_encode(i, i * 8333, ids, q[i]) for i in range(n)]
    else:
        chunks = [stream[k:k + SERIAL_CHUNK] for k in range(0, len(stream), SERIAL_CHUNK)]
    rates = []
    for _ in range(repeat):
        dec = SerialFrameDecoder(known_ids=ids)
        got = 0
        t0 = _clock()
        for c in chunks:
            got += len(dec.feed(c))
        dt = _clock() - t0
        if got != n:
            raise RuntimeError(f"serial decoded {got} of {n} frames")
        rates.append(n / dt)
    return {"frames_per_s": round(statistics.median(rates)),
            "runs": [round(r) for r in rates],
            "bytes_per_frame": len(stream) / n,
            "chunk_bytes": None if one_frame else SERIAL_CHUNK}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--frames", type=int, default=5000, help="frames per run (default 5000)")
    p.add_argument("--repeat", type=int, default=5, help="runs; the median is reported (default 5)")
    p.add_argument("--cpu-time", action="store_true", help="time with this process's CPU "
                   "time (time.process_time) instead of the wall clock: steadier on a "
                   "machine shared with other jobs (frames per CPU-second)")
    p.add_argument("--only", metavar="PREFIXES", help="time only the rows whose "
                   "name starts with one of these comma-separated prefixes (e.g. --only axis)")
    p.add_argument("--tree", metavar="DIR", help="import rtseg from the source tree DIR (a git "
                   "worktree of another commit: the code before a change) instead of the "
                   "installed package; command line only")
    p.add_argument("--no-kernel", action="store_true", help="Axis poses through the "
                   "numpy path even where the compiled kernel (rtseg.drivers.axis._axis_kernel) "
                   "is built, to compare the two in one tree (RTSEG_NO_KERNEL=1)")
    args = p.parse_args(argv)
    if args.no_kernel:
        numpy_axis_path()
    if args.cpu_time:
        global _clock
        _clock = time.process_time
    if args.frames < 10 or args.repeat < 1:
        p.error("--frames must be >= 10 and --repeat >= 1")
    q = vendor_motion(args.frames, 17)
    n, rep = args.frames, args.repeat
    rows = {
        "serial": lambda: bench_serial(q, rep) or {"frames_per_s": None},
        "serial_one_frame": lambda: bench_serial(q, rep, one_frame=True),
        "vmc": lambda: bench_vmc(q, rep),
        "vmc_general_path": lambda: bench_vmc(q, rep, fast=False),
        "vmc_55_bones": lambda: bench_vmc(q, rep, full=True),
        "mvn": lambda: bench_mvn(n, rep),
        "mvn_3_datagrams": lambda: bench_mvn(n, rep, parts=3),
        "mvn_tcp": lambda: bench_mvn_tcp(n, rep),
        "mocopi": lambda: bench_mocopi(n, rep),
        "rokoko": lambda: bench_rokoko(n, rep),
        "rokoko_lz4": lambda: bench_rokoko(n, rep, compress=True),
        "rokoko_json_module": lambda: bench_rokoko(n, rep, json_module=True),
        "axis_binary": lambda: bench_axis(n, rep),
        "axis_binary_global": lambda: bench_axis(n, rep, space="global"),
        "axis_binary_global_burst": lambda: bench_axis_burst(n, rep),
        "axis_text": lambda: bench_axis(n, rep, text=True),
        "axis_text_global": lambda: bench_axis(n, rep, text=True, space="global"),
        "axis_text_64k": lambda: bench_axis(n, rep, text=True, chunk=65536),
        "axis_text_global_64k": lambda: bench_axis(n, rep, text=True, space="global",
                                                   chunk=65536),
        "python_osc_parse": lambda: bench_python_osc(q[: max(10, n // 5)],
                                                     max(1, min(rep, 3))),
    }
    only = tuple(x for x in (args.only or "").split(",") if x)
    result: dict = {}
    for key, run in rows.items():
        if not only or key.startswith(only):
            r = run()
            if r is not None:
                result[key] = r
    result["config"] = {"frames": args.frames, "repeat": args.repeat, "sensors": 17,
                        "clock": "process_time" if args.cpu_time else "perf_counter",
                        "python": platform.python_version(), "machine": platform.machine(),
                        "tree": TREE or "installed",
                        "codec_axis": sys.modules["rtseg.drivers.axis.codec"].__file__
                        if "rtseg.drivers.axis.codec" in sys.modules else None}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"decode throughput, 17-sensor suit, {args.frames} frames, median of {args.repeat} runs"
          + (" (frames per CPU-second)" if args.cpu_time else "")
          + (f", code from {TREE}" if TREE else ""))
    serial = result.get("serial")
    if serial is not None and serial["frames_per_s"] is not None:
        print(f"  serial (COBS+CRC, {serial['bytes_per_frame']:.0f} B/frame, "
              f"{SERIAL_CHUNK} B reads): {serial['frames_per_s']:>9,} frames/s")
    one = result.get("serial_one_frame")
    if one is not None:
        print(f"  serial, one frame per read:          {one['frames_per_s']:>9,} frames/s")
    if "vmc" in result:
        v = result["vmc"]
        print(f"  VMC (OSC/UDP, {v['datagrams_per_frame']:.1f} datagrams, "
              f"{v['bytes_per_frame']:.0f} B/frame):    {v['frames_per_s']:>9,} frames/s")
    if "vmc_general_path" in result:
        print(f"  VMC, message-by-message path only:           "
              f"{result['vmc_general_path']['frames_per_s']:>9,} frames/s")
    if "vmc_55_bones" in result:
        f = result["vmc_55_bones"]
        print(f"  VMC, 55 bones ({f['datagrams_per_frame']:.0f} datagrams, "
              f"{f['bytes_per_frame']:.0f} B/frame):       {f['frames_per_s']:>9,} frames/s")
    parser = result.get("rokoko", {}).get("json_parser", "")
    for key, label in (("mvn", "Xsens MVN, 23 segments"), ("mvn_3_datagrams", "Xsens MVN, 3 datagrams/frame"),
                       ("mvn_tcp", "Xsens MVN over TCP, 4 KiB reads"),
                       ("mocopi", "Sony mocopi, 27 bones"),
                       ("rokoko", f"Rokoko JSON v3 ({parser})"),
                       ("rokoko_lz4", f"Rokoko JSON v3 LZ4 ({parser})"),
                       ("rokoko_json_module", "Rokoko JSON v3 (json module fallback)"),
                       ("axis_binary", "Axis BVH binary, 59 joints"),
                       ("axis_binary_global", "Axis BVH binary, space=global"),
                       ("axis_binary_global_burst", "Axis binary, global, 16 pending"),
                       ("axis_text", "Axis BVH text (TCP)"),
                       ("axis_text_global", "Axis BVH text, space=global"),
                       ("axis_text_64k", "Axis BVH text, 64 KiB reads"),
                       ("axis_text_global_64k", "Axis BVH text, global, 64 KiB reads")):
        if key not in result:
            continue
        r = result[key]
        print(f"  {label} ({r['bytes_per_frame']:.0f} B/frame): ".ljust(47)
              + f"{r['frames_per_s']:>9,} frames/s")
    if "python_osc_parse" in result:
        print(f"  python-osc parse only (comparison):          "
              f"{result['python_osc_parse']['frames_per_s']:>9,} frames/s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
