#!/usr/bin/env python3
"""Decode throughput of the live input codecs for a 17-sensor suit (frames per second).

    python3 benchmarks/decode.py                   # readable report
    python3 benchmarks/decode.py --json            # {"serial": {"frames_per_s": N},
                                                   #  "vmc": {"frames_per_s": N}, ...}
    python3 benchmarks/decode.py --frames 5000 --repeat 7
    python3 benchmarks/decode.py --cpu-time        # process CPU time instead of wall clock
    python3 benchmarks/decode.py --only axis       # only the rows named axis...
    python3 benchmarks/decode.py --axis-steps      # an Axis text frame's time, step by step
    git worktree add /tmp/before <commit>          # the code before a change, timed by
    python3 benchmarks/decode.py --tree /tmp/before   # these loops (PYTHONPATH alone is not
                                                   # enough: see _use_tree)

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

- ``mvn``: ``rtseg.drivers.codec_mvn.MvnAssembler`` fed Xsens MVN type-02 datagrams (23
  segments, one 760-byte datagram per frame); ``mvn_3_datagrams``: the same frames split
  over 3 datagrams each (reassembly by sample counter).
- ``mocopi``: ``rtseg.drivers.codec_mocopi.MocopiAssembler`` fed mocopi ``fram`` datagrams
  (27 bones, one datagram per frame).

- ``rokoko``: ``rtseg.drivers.rokoko_source.RokokoAssembler`` fed Rokoko Studio Custom
  JSON v3 payloads (one actor, 21 bones; JSON parsed with orjson, a core dependency - the
  row says which parser ran, the json module only where orjson is missing);
  ``rokoko_lz4``: the same payloads LZ4-compressed; ``rokoko_json_module``: plain payloads
  parsed with the standard json module (the fallback, for comparison).
- ``mvn_tcp``: the ``mvn`` frames as MVN's TCP stream (messages back to back) in 4096-byte
  reads, cut by ``codec_mvn.MxtpStream`` and assembled.
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

    python3 benchmarks/decode.py --fuzz [--fuzz-inputs 100000]

feeds, per format (mvn, mvn_tcp: stream reads, mocopi, rokoko, axis binary, axis text), that many mutated datagrams (bit flips, truncation,
rewritten header/length fields, appended bytes, random bytes; seeded) to the assembler
and reports how many raised (must be 0), frames produced, counters, and inputs/s.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation


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

from rtseg.drivers.codec_vmc import (HUMAN_BODY_BONES, VmcAssembler,  # noqa: E402
                                      encode_frame as vmc_encode)

BONES = ["Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "LeftLowerArm", "LeftHand",
         "RightUpperArm", "RightLowerArm", "RightHand", "LeftUpperLeg", "LeftLowerLeg",
         "LeftFoot", "RightUpperLeg", "RightLowerLeg", "RightFoot"]
SERIAL_CHUNK = 4096
#: timer of the timed loops: wall clock, or this process's CPU time with --cpu-time
_clock = time.perf_counter


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


def vendor_motion(n: int, joints: int, seed: int = 0) -> np.ndarray:
    """(n, joints, 4) smooth unit quaternions (scalar-last)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None, None] / 120.0
    rv = 0.7 * np.sin(2 * np.pi * (0.3 + rng.random((1, joints, 3))) * t
                      + 6 * rng.random((1, joints, 3)))
    return Rotation.from_rotvec(rv.reshape(-1, 3)).as_quat().reshape(n, joints, 4)


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
    from rtseg.drivers.codec_mvn import HEADER_SIZE, ITEM_SIZE, MvnAssembler, encode_datagrams
    q = vendor_motion(n, 23)
    ids = list(range(1, 24))
    per = -(-23 // parts)
    dgrams = [d for i in range(n) for d in encode_datagrams(
        i, i * 8, ids, q[i], np.zeros((23, 3)), max_datagram=HEADER_SIZE + per * ITEM_SIZE)]
    rates = _time_feed(lambda: MvnAssembler(ids), dgrams, n, repeat, "MVN")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "datagrams_per_frame": len(dgrams) / n, "bytes_per_frame": sum(map(len, dgrams)) / n}


def bench_mocopi(n: int, repeat: int) -> dict:
    from rtseg.drivers.codec_mocopi import MocopiAssembler, encode_frame
    q = vendor_motion(n, 27)
    dgrams = [encode_frame(i, q[i], time=i * 20, uttm=1.7e9 + i / 50) for i in range(n)]
    rates = _time_feed(MocopiAssembler, dgrams, n, repeat, "mocopi")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "datagrams_per_frame": 1.0, "bytes_per_frame": sum(map(len, dgrams)) / n}


def mutate(seeds: list[bytes], n: int, seed: int, magic: bytes = b""):
    """``n`` mutated datagrams from ``seeds`` (generator; seeded, reproducible)."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        d = bytearray(seeds[rng.integers(len(seeds))])
        op = rng.integers(6)
        if op == 0:
            for _ in range(rng.integers(1, 8)):
                d[rng.integers(len(d))] ^= 1 << int(rng.integers(8))
        elif op == 1:
            d = d[:rng.integers(len(d) + 1)]
        elif op == 2:
            a = int(rng.integers(0, min(len(d), 64)))
            d[a:a + 4] = rng.bytes(4)
        elif op == 3:
            d = d + rng.bytes(rng.integers(1, 64))
        elif op == 4:
            d = bytearray(magic + rng.bytes(rng.integers(0, 300)))
        else:
            d = bytearray(rng.bytes(rng.integers(0, 300)))
        yield bytes(d)


def fuzz(fmt: str, n: int, seed: int = 1) -> dict:
    """Feed ``n`` mutated datagrams (TCP reads for mvn_tcp, axis_text) of ``fmt``; count
    escaped exceptions."""
    import struct
    if fmt == "mvn":
        from rtseg.drivers.codec_mvn import (HEADER_SIZE, ITEM_SIZE, MvnAssembler,
                                             encode_datagrams, encode_message)
        q = vendor_motion(4, 23)
        ids = list(range(1, 24))
        seeds = [d for i in range(4) for d in encode_datagrams(
            i, i, ids, q[i], max_datagram=HEADER_SIZE + 8 * ITEM_SIZE)]
        seeds += [encode_message("12", b"\x00\x00\x00\x0aname:fuzz\n"),
                  encode_message("13", struct.pack(">II", 1, 2) + b"L5" + bytes(12)),
                  encode_message("24", bytes(12)), encode_message("25", b"01:02:03.004")]
        asm, magic = MvnAssembler(ids, quiet=0.0), b"MXTP"
    elif fmt == "mvn_tcp":
        from rtseg.drivers.codec_mvn import HEADER_SIZE, ITEM_SIZE, encode_datagrams
        q = vendor_motion(4, 23)
        ids = list(range(1, 24))
        stream = b"".join(d for i in range(4) for d in encode_datagrams(
            i, i, ids, q[i], max_datagram=HEADER_SIZE + 8 * ITEM_SIZE))
        seeds = [stream[k:k + 700] for k in range(0, len(stream), 700)]   # TCP reads
        asm, magic = _MvnTcp(ids), b"MXTP"
    elif fmt == "rokoko":
        from rtseg.drivers.codec_rokoko import LZ4_MAGIC
        seeds = _rokoko_payloads(3, False) + _rokoko_payloads(2, True)
        asm, magic = _rokoko_assembler(), LZ4_MAGIC
    elif fmt == "axis":
        from rtseg.drivers.codec_axis import encode_binary
        v = _axis_values(3)
        d = encode_binary(v[0])
        seeds = [encode_binary(v[1], frame_index=1), d[:1024], d[1024:],
                 encode_binary(v[2][:180], with_disp=False)]
        asm, magic = _axis_binary_assembler(), b"\xff\xdd"
    elif fmt == "axis_text":
        from rtseg.drivers.codec_axis import encode_text
        v = _axis_values(3)
        seeds = [encode_text(v[0]), encode_text(v[1][:180], 1, "Avatar01"), b" ||", b"||"]
        asm, magic = _AxisText(), b"0 Avatar00 "
    else:
        from rtseg.drivers.codec_mocopi import MocopiAssembler, encode_frame, encode_skeleton
        from rtseg.drivers.codec_mocopi import BONE_PARENTS
        q = vendor_motion(3, 27)
        seeds = [encode_frame(i, q[i], uttm=1.0 + i) for i in range(3)]
        seeds.append(encode_skeleton(list(BONE_PARENTS), np.tile([0, 0, 0, 1, 0, 0, 0], (27, 1))))
        asm, magic = MocopiAssembler(), b""
    escaped = frames = 0
    t0 = time.perf_counter()
    for k, d in enumerate(mutate(seeds, n, seed, magic)):
        try:
            frames += len(asm.feed(d, k * 1e-3)) + len(asm.flush(k * 1e-3))
        except Exception as exc:  # noqa: BLE001 - counting is the point
            escaped += 1
            if escaped <= 3:
                print(f"{fmt}: input {k} raised {exc!r}", file=sys.stderr)
    dt = time.perf_counter() - t0
    st = asm.stats
    return {"inputs": n, "escaped": escaped, "frames": frames, "corrupt": st.corrupt,
            "bad_values": st.bad_values, "bad_messages": st.bad_messages,
            "dropped": st.dropped, "inputs_per_s": round(n / dt)}


class _MvnTcp:
    """What MvnTcpSource runs per TCP read: MxtpStream -> MvnAssembler (its ``corrupt``
    also counts the stream's resynchronisations)."""

    def __init__(self, ids: list[int]) -> None:
        from rtseg.drivers.codec_mvn import MxtpStream
        from rtseg.drivers.codec_mvn_assembler import MvnAssembler
        self.cut, self.asm = MxtpStream(), MvnAssembler(ids, quiet=0.0)
        self.stats = self.asm.stats

    def feed(self, data: bytes, now: float) -> list:
        before = self.cut.resyncs
        out = [f for m in self.cut.feed(data) for f in self.asm.feed(m, now)]
        self.stats.corrupt += self.cut.resyncs - before
        return out

    def flush(self, now: float, force: bool = False) -> list:
        return self.asm.flush(now, force)


class _CountingStats:
    """A SourceStats and the ``count(field, n, message)`` callable the Rokoko/Axis
    assemblers take."""

    def __init__(self) -> None:
        from rtseg.drivers.base import SourceStats
        self.stats = SourceStats()

    def __call__(self, field: str, n: int = 1, message=None) -> None:
        setattr(self.stats, field, getattr(self.stats, field) + n)


class _AxisText:
    """What the axis text source runs on each TCP read (``axis_source.TextStream``: split
    on ``||``, decode the frames of the read together, convert)."""

    def __init__(self, space: str = "local") -> None:
        from rtseg.drivers.axis_source import AxisFrames, TextStream
        self.count = _CountingStats()
        self.stats = self.count.stats
        self.stream = TextStream(AxisFrames(self.count, space=space))

    def feed(self, data: bytes, now: float) -> list:
        return self.stream.feed(data, now)

    def flush(self, now: float, force: bool = False) -> list:
        return []


def _rokoko_assembler():
    from rtseg.drivers.rokoko_source import RokokoAssembler
    count = _CountingStats()
    asm = RokokoAssembler(None, count)
    asm.stats = count.stats
    return asm


def _axis_binary_assembler(space: str = "local"):
    from rtseg.drivers.axis_source import AxisFrames, _BinaryAdapter
    count = _CountingStats()
    asm = _BinaryAdapter(AxisFrames(count, space=space))
    asm.stats = count.stats
    return asm


def _rokoko_payloads(n: int, compress: bool) -> list[bytes]:
    from rtseg.drivers.codec_rokoko import encode_packet
    q = vendor_motion(n, 21)
    return [encode_packet([("Actor1", q[i], None, np.array([0.0, 0.95, 0.01 * i]))], i / 60,
                          compress=compress) for i in range(n)]


def _axis_values(n: int) -> np.ndarray:
    from rtseg.drivers.codec_axis import JOINTS, quat_to_euler
    v = np.zeros((n, len(JOINTS), 6))
    v[:, :, 3:] = quat_to_euler("YXZ", vendor_motion(n, len(JOINTS)))
    v[:, 0, :3] = (0.0, 95.0, 0.0)
    return v.reshape(n, -1)


def bench_rokoko(n: int, repeat: int, compress: bool = False, json_module: bool = False) -> dict:
    from rtseg.drivers import codec_rokoko
    dgrams = _rokoko_payloads(n, compress)
    saved = codec_rokoko._loads
    if json_module:
        codec_rokoko._loads = json.loads
    try:
        rates = _time_feed(_rokoko_assembler, dgrams, n, repeat, "Rokoko")
    finally:
        codec_rokoko._loads = saved
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "datagrams_per_frame": 1.0, "bytes_per_frame": sum(map(len, dgrams)) / n,
            "json_parser": "json" if json_module else codec_rokoko.JSON_PARSER}


def bench_mvn_tcp(n: int, repeat: int) -> dict:
    """MVN over TCP: the type-02 messages back to back, in 4096-byte reads, cut by
    MxtpStream and fed to the assembler (what MvnTcpSource runs per read)."""
    from rtseg.drivers.codec_mvn import MxtpStream, encode_datagrams
    from rtseg.drivers.codec_mvn_assembler import MvnAssembler
    q = vendor_motion(n, 23)
    ids = list(range(1, 24))
    stream = b"".join(d for i in range(n) for d in encode_datagrams(i, i * 8, ids, q[i],
                                                                     np.zeros((23, 3))))
    reads = [stream[k:k + SERIAL_CHUNK] for k in range(0, len(stream), SERIAL_CHUNK)]

    class _Tcp:
        def __init__(self) -> None:
            self.cut, self.asm = MxtpStream(), MvnAssembler(ids)

        def feed(self, data: bytes, now: float) -> list:
            return [f for m in self.cut.feed(data) for f in self.asm.feed(m, now)]

        def flush(self, now: float, force: bool = False) -> list:
            return self.asm.flush(now, force)

    rates = _time_feed(_Tcp, reads, n, repeat, "MVN TCP")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "bytes_per_frame": len(stream) / n}


def bench_axis(n: int, repeat: int, text: bool = False, space: str = "local",
               chunk: int = SERIAL_CHUNK) -> dict:
    """``chunk``: bytes per TCP read of the text stream (4096; 65536 is what the source
    asks for, and gets when it has fallen behind)."""
    from rtseg.drivers.codec_axis import encode_binary
    from rtseg.drivers.codec_axis_text import encode_text
    v = _axis_values(n)
    if text:
        stream = b"".join(encode_text(v[i]) for i in range(n))
        dgrams = [stream[k:k + chunk] for k in range(0, len(stream), chunk)]
        dgrams.append(b"||")          # the stream's last frame ends at the next separator
        make = lambda: _AxisText(space)  # noqa: E731
    else:
        dgrams = [encode_binary(v[i], frame_index=i) for i in range(n)]
        stream = b"".join(dgrams)
        make = lambda: _axis_binary_assembler(space)  # noqa: E731
    rates = _time_feed(make, dgrams, n, repeat, "Axis")
    return {"frames_per_s": round(statistics.median(rates)), "runs": [round(r) for r in rates],
            "bytes_per_frame": len(stream) / n}


def bench_axis_steps(n: int, repeat: int) -> dict:
    """Where an Axis text frame's time goes: the text source's pipeline (``TextStream``)
    taken apart into its steps, each timed with ``_clock`` around it, for 4 KiB and
    64 KiB reads in local and global space; the minimum over ``repeat`` passes of each
    step, in microseconds per frame.  The steps call the same functions as the pipeline
    (the frames' values are checked against ``TextStream``'s bit for bit)."""
    from rtseg.drivers import axis_pose as P
    from rtseg.drivers import codec_axis as A
    from rtseg.drivers import codec_axis_text as T
    from rtseg.drivers.axis_source import AxisFrames, TextStream
    from rtseg.frame import Frame
    v = _axis_values(n)
    stream = b"".join(T.encode_text(v[i]) for i in range(n))
    out: dict = {}
    for chunk in (SERIAL_CHUNK, 65536):
        reads = [stream[k:k + chunk] for k in range(0, len(stream), chunk)] + [b"||"]
        for space in ("local", "global"):
            best: dict[str, float] = {}
            for _ in range(repeat):
                acc = dict.fromkeys(("split", "fields_check", "orjson", "array",
                                     "axisframe_stack", "euler", "fk", "frame"), 0.0)
                split, conv = T.TextSplitter(), AxisFrames(lambda *a: None, space=space)
                frames = []
                for d in reads:
                    t0 = _clock()
                    chunks = split.feed(d)
                    t1 = _clock()
                    acc["split"] += t1 - t0
                    if not chunks:
                        continue
                    heads, rows = [], []
                    for c in chunks:
                        index, name, body = T._fields(c)
                        heads.append((index, name))
                        rows.append(body.translate(T._TO_JSON, T._NOT_JSON))
                    t2 = _clock()
                    lists = T._json_lists(rows)
                    t3 = _clock()
                    arrays = [T._array(x) for x in lists]
                    t4 = _clock()
                    fs = [A.AxisFrame(i, nm, x, *A.layout(x.size), finite=True)
                          for (i, nm), x in zip(heads, arrays)]
                    vals = arrays[0] if len(fs) == 1 else np.array(arrays)
                    t5 = _clock()
                    kernel = P.axis_kernel
                    if kernel.ENABLED:
                        # the compiled kernel: half-angle cosines and sines in numpy
                        # ("euler"), products and forward kinematics in C ("fk"; the
                        # local quaternions come out of the same call)
                        if vals.ndim == 1:
                            half = vals.take(P._angle_index(True, False, 59)[:, :-1])
                            np.multiply(half, P._HALF_RAD, out=half)
                        else:
                            half = P._half_angles(P._channels(vals, True, False, 59)[1])
                        u = P._cos_sin(half)
                        root = vals[..., :3]
                        t6 = _clock()
                        loc, q = kernel.euler_fk(u, 59, P._order_axes("YXZ"), P.PARENTS)
                        q = (loc if space == "local" else q).reshape(vals.shape[:-1] + (59, 4))
                        t7 = _clock()
                    else:
                        if space == "local" or vals.ndim == 2:
                            root, angles = P._channels(vals, True, False, 59)
                            tt = P._euler_terms(angles, identity_row=space == "global")
                        else:
                            half = vals.take(P._angle_index(True, False, 59))
                            np.multiply(half, P._HALF_RAD, out=half)
                            half[:, -1] = 0.0
                            tt = P._half_terms(half)
                            root = vals[:3]
                        T_, T4 = P._euler_tables("YXZ")
                        if space == "local":
                            q = (tt.T @ T_).reshape(angles.shape[:-1] + (4,))
                            t6 = t7 = _clock()
                        else:                            # quaternion pointer jumping
                            q = (tt.T @ T4).reshape(vals.shape[:-1] + (60, 16))
                            t6 = _clock()
                            q = P._fk(q)
                            t7 = _clock()
                    pos = root * 0.01
                    qs, ps = ([q], [pos]) if vals.ndim == 1 else (list(q), list(pos))
                    frames += [Frame(0.0, qs[k], P._ALL_VALID.copy(), None, conv._seq(f, 0.0),
                                     ps[k]) for k, f in enumerate(fs)]
                    t8 = _clock()
                    for key, dt in (("fields_check", t2 - t1), ("orjson", t3 - t2),
                                    ("array", t4 - t3), ("axisframe_stack", t5 - t4),
                                    ("euler", t6 - t5), ("fk", t7 - t6), ("frame", t8 - t7)):
                        acc[key] += dt
                for key, dt in acc.items():
                    best[key] = min(best.get(key, dt), dt)
            ref = TextStream(AxisFrames(lambda *a: None, space=space))
            want = [f for d in reads for f in ref.feed(d, 0.0)]
            if [f.quats.tobytes() for f in want] != [f.quats.tobytes() for f in frames]:
                raise RuntimeError("Axis steps: frames differ from TextStream's")
            row = {k: round(x / n * 1e6, 2) for k, x in best.items()}
            row["total"] = round(sum(best.values()) / n * 1e6, 2)
            out[f"{'4k' if chunk == SERIAL_CHUNK else '64k'}_{space}"] = row
    return out


def bench_axis_burst(n: int, repeat: int, burst: int = 16, space: str = "global") -> dict:
    """Axis binary datagrams ``burst`` at a time through ``_BinaryAdapter.feed_many``: what
    the binary source decodes when datagrams wait in its socket (a reader catching up)."""
    from rtseg.drivers.codec_axis import encode_binary
    v = _axis_values(n)
    dgrams = [encode_binary(v[i], frame_index=i) for i in range(n)]
    groups = [dgrams[k:k + burst] for k in range(0, n, burst)]
    rates = []
    for _ in range(repeat):
        asm = _axis_binary_assembler(space)
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
        t0 = _clock()
        for c in chunks:
            got += len(dec.feed(c))
        dt = _clock() - t0
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
    p.add_argument("--fuzz", action="store_true", help="fuzz the MVN, mocopi, Rokoko and Axis decoders "
                   "instead of timing (exit 1 if any input raised)")
    p.add_argument("--fuzz-inputs", type=int, default=100_000, help="inputs per format")
    p.add_argument("--cpu-time", action="store_true", help="time with this process's CPU "
                   "time (time.process_time) instead of the wall clock: steadier on a "
                   "machine shared with other jobs (frames per CPU-second)")
    p.add_argument("--only", metavar="PREFIXES", help="time (or fuzz) only the rows (formats) whose "
                   "name starts with one of these comma-separated prefixes (e.g. --only axis)")
    p.add_argument("--tree", metavar="DIR", help="import rtseg from the source tree DIR (a git "
                   "worktree of another commit: the code before a change) instead of the "
                   "installed package; command line only")
    p.add_argument("--no-kernel", action="store_true", help="Axis poses through the "
                   "numpy path even where the compiled kernel (rtseg.drivers._axis_kernel) "
                   "is built, to compare the two in one tree (RTSEG_NO_KERNEL=1)")
    p.add_argument("--axis-steps", action="store_true", help="instead of the rows: where an "
                   "Axis text frame's time goes, step by step (microseconds per frame)")
    args = p.parse_args(argv)
    if args.no_kernel:
        os.environ["RTSEG_NO_KERNEL"] = "1"
        if "rtseg.drivers.axis_kernel" in sys.modules:
            sys.modules["rtseg.drivers.axis_kernel"].ENABLED = False
    if args.cpu_time:
        global _clock
        _clock = time.process_time
    if args.axis_steps:
        steps = bench_axis_steps(max(10, args.frames), args.repeat)
        if args.json:
            print(json.dumps(steps))
        else:
            for key, row in steps.items():
                print(f"axis text {key}: " + ", ".join(f"{k} {x}" for k, x in row.items())
                      + " us/frame")
        return 0
    if args.fuzz:
        only = tuple(x for x in (args.only or "").split(",") if x)
        out = {fmt: fuzz(fmt, args.fuzz_inputs)
               for fmt in ("mvn", "mvn_tcp", "mocopi", "rokoko", "axis", "axis_text")
               if not only or fmt.startswith(only)}
        if args.json:
            print(json.dumps(out))
        else:
            for fmt, r in out.items():
                print(f"fuzz {fmt}: {r['inputs']:,} inputs, {r['escaped']} escaped, "
                      f"{r['frames']:,} frames, corrupt {r['corrupt']:,}, bad values "
                      f"{r['bad_values']:,}, bad messages {r['bad_messages']:,}, dropped "
                      f"{r['dropped']:,}; {r['inputs_per_s']:,} inputs/s")
        return 1 if any(r["escaped"] for r in out.values()) else 0
    if args.frames < 10 or args.repeat < 1:
        p.error("--frames must be >= 10 and --repeat >= 1")
    q = motion(args.frames)
    n, rep = args.frames, args.repeat
    rows = {
        "serial": lambda: bench_serial(q, rep) or {"frames_per_s": None},
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
                        "codec_axis": sys.modules["rtseg.drivers.codec_axis"].__file__
                        if "rtseg.drivers.codec_axis" in sys.modules else None}
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
