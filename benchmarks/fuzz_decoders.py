#!/usr/bin/env python3
"""Fuzz the live input decoders: 10^6 hostile inputs per format, 0 escaped exceptions.

    python3 benchmarks/fuzz_decoders.py               # 1 000 000 inputs per format
    python3 benchmarks/fuzz_decoders.py --n 20000 --json
    python3 benchmarks/fuzz_decoders.py --formats vmc --seed 3

Formats and the decoder objects fed (one long-lived decoder per format, as a live source
keeps one, so state left by earlier junk is part of what is tested; a fresh one every
100 000 inputs):

- ``serial``: ``rtseg.drivers.serial.codec.SerialFrameDecoder`` (binary COBS/CRC frames, 17 sensors) fed
  byte chunks, and every 8th input also ``TextLineDecoder`` (text lines) then ``flush``;
- ``vmc``: ``rtseg.drivers.osc.vmc.codec.VmcAssembler`` (17 humanoid bones) fed one UDP datagram per input,
  ``flush`` every 64 inputs;
- ``vrchat``: ``rtseg.drivers.osc.vrchat.VrchatAssembler`` fed one datagram per input, ``flush`` every
  64 inputs.
- ``mvn``: ``rtseg.drivers.mvn.assembler.MvnAssembler`` (23 segments) fed Xsens MVN datagrams (type-02 frames
  split over 3 datagrams, types 12/13/24/25), ``flush`` every 64 inputs;
- ``mocopi``: ``rtseg.drivers.mocopi.assembler.MocopiAssembler`` (27 bones) fed mocopi ``fram``/``skdf``
  datagrams.
- ``mvn_tcp``: MVN over TCP, what ``MvnTcpSource`` runs per read (``MxtpStream`` then
  ``MvnAssembler``), fed 700-byte reads of a stream of type-02/12/13 messages;
- ``rokoko``: the Rokoko source's ``RokokoAssembler`` fed Custom JSON v3 payloads, plain
  and LZ4-compressed;
- ``axis``: the Axis binary source's joiner, decoder and converter (``_BinaryAdapter``)
  fed BVH binary datagrams (whole frames, a frame split over two datagrams, a frame
  without displacement);
- ``axis_text``: the Axis text source's ``TextStream`` fed reads of the ``||``-separated
  text stream.

The four last are the sources' per-read pipelines of ``benchmarks/codec_feeds.py``, the
objects ``benchmarks/decode.py`` times.

Each input is a valid seed (a real frame, info/status message, bundle, tracker message)
mutated by one to four of: bit flips, byte overwrites, random insertions (zeros likely,
the serial delimiter), deletions, truncation, duplicated/spliced pieces of another seed,
OSC type-tag and length-field rewrites, non-finite/huge float patches; or (1 in 8)
plain random bytes.  Seeded (``--seed``): the same command feeds the same inputs.

Reported per format: inputs, escaped exceptions (must be 0; the first few tracebacks are
printed), frames produced, frames violating the output contract (valid quaternion not unit
or not finite: must be 0), the decoder's counters, and inputs per second.  Exit status 1
if anything escaped or violated the contract.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import random
import struct
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Callable

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from rtseg.drivers.serial import codec as cs  # noqa: E402
from rtseg.drivers.osc.vmc import codec as cv  # noqa: E402
from rtseg.drivers.osc import vrchat as cvr  # noqa: E402
from rtseg.drivers.mocopi import codec as cmo  # noqa: E402
from rtseg.drivers.mvn import codec as cmv  # noqa: E402
from rtseg.drivers.mvn.assembler import MvnAssembler  # noqa: E402
from rtseg.drivers.mocopi.assembler import MocopiAssembler  # noqa: E402
from rtseg.drivers.base import SourceStats  # noqa: E402
from rtseg.simulators.synth.skeleton import JOINT_NAMES as BONES  # noqa: E402

sys.path.insert(0, str(REPO / "benchmarks"))
from codec_feeds import (AxisTextFeed, MvnTcpFeed, axis_binary_feed,  # noqa: E402
                         axis_values, rokoko_feed, rokoko_payloads)

FRESH_EVERY = 100_000
OSC_TAGS = b"ifsbhdtTFNI[]cmr"


def _quats(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    q = rng.normal(size=(n, k, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# ============================================================================ seeds
def serial_seeds(rng: np.random.Generator) -> list[bytes]:
    q = _quats(rng, 6, 17)
    out = [cs.encode_frame(100 + i, 8333 * i, list(range(17)), q[i]) for i in range(4)]
    out.append(cs.encode_frame(7, 1, [0, 3, 5], q[4, :3]))
    out.append(cs.encode_status(9, 2, list(range(17)), [cs.status_bits()] * 17))
    out.append(cs.encode_info(10, 3, {"fw": "1.2", "suit": "fuzz"}))
    out.append(b"".join(out[:3]))                      # several frames in one read
    return out


def serial_text_seeds(rng: np.random.Generator) -> list[bytes]:
    q = _quats(rng, 3, 17)
    return [cs.encode_text_frame(list(range(17)), q[i]) for i in range(3)] + [
        b"boot: ok\r\n", b"\r\n\r\n"]


def vmc_seeds(rng: np.random.Generator) -> list[bytes]:
    q = _quats(rng, 3, len(BONES))
    out: list[bytes] = []
    for i in range(3):
        out += cv.encode_frame(q[i], BONES, time=float(i), root_position=(0, 1, i),
                               max_datagram=1472 if i else 400)
    out.append(cv.encode_message("/VMC/Ext/Bone/Pos", "sfffffff", ["Hips", 0, 1, 0, 0, 0, 0, 1]))
    out.append(cv.encode_message("/VMC/Ext/OK", "i", [1]))
    out.append(cv.encode_message("/VMC/Ext/T", "f", [12.5]))
    return out


def vrchat_seeds(rng: np.random.Generator) -> list[bytes]:
    out: list[bytes] = []
    for t in cvr.TRACKERS:
        pos = cv.encode_message(f"/tracking/trackers/{t}/position", "fff",
                                [float(x) for x in rng.normal(size=3)])
        rot = cv.encode_message(f"/tracking/trackers/{t}/rotation", "fff",
                                [float(x) for x in rng.uniform(-180, 180, 3)])
        out += [pos, rot]
    out.append(cv.encode_bundle(out[:6]))
    return out


def mvn_seeds(rng: np.random.Generator) -> list[bytes]:
    q = _quats(rng, 3, 23)
    ids = list(range(1, 24))
    out = [d for i in range(3) for d in cmv.encode_datagrams(
        i, 17 * i, ids, q[i], max_datagram=cmv.HEADER_SIZE + 8 * cmv.ITEM_SIZE)]
    out += [cmv.encode_message("12", b"\x00\x00\x00\x0bname:fuzzed"),
            cmv.encode_message("13", struct.pack(">II", 1, 2) + b"L5" + bytes(12)),
            cmv.encode_message("24", bytes(12)), cmv.encode_message("25", b"01:02:03.004")]
    return out


def mocopi_seeds(rng: np.random.Generator) -> list[bytes]:
    q = _quats(rng, 3, 27)
    out = [cmo.encode_frame(i, q[i], uttm=1.7e9 + i) for i in range(3)]
    out.append(cmo.encode_skeleton(list(cmo.BONE_PARENTS), np.tile([0, 0, 0, 1, 0, 0, 0], (27, 1))))
    return out


def mvn_tcp_seeds(rng: np.random.Generator) -> list[bytes]:
    """TCP reads (700 bytes) of MVN messages back to back, as the stream arrives."""
    stream = b"".join(mvn_seeds(rng))
    return [stream[k:k + 700] for k in range(0, len(stream), 700)]


def rokoko_seeds(rng: np.random.Generator) -> list[bytes]:
    return rokoko_payloads(3, False) + rokoko_payloads(2, True)


def axis_seeds(rng: np.random.Generator) -> list[bytes]:
    from rtseg.drivers.axis.codec import encode_binary
    v = axis_values(3)
    d = encode_binary(v[0])
    return [encode_binary(v[1], frame_index=1), d[:1024], d[1024:],
            encode_binary(v[2][:180], with_disp=False)]


def axis_text_seeds(rng: np.random.Generator) -> list[bytes]:
    from rtseg.drivers.axis.text import encode_text
    v = axis_values(3)
    return [encode_text(v[0]), encode_text(v[1][:180], 1, "Avatar01"), b" ||", b"||"]


# ============================================================================ mutation
class Mutator:
    """Hostile variations of seed inputs (see the module docstring)."""

    def __init__(self, seeds: list[bytes], rnd: random.Random, osc: bool) -> None:
        self.seeds = seeds
        self.r = rnd
        self.osc = osc

    def __call__(self) -> bytes:
        r = self.r
        if r.random() < 0.125:
            return r.randbytes(r.choice((0, 1, 3, 4, 8, 16, 64, 200, 1500)))
        buf = bytearray(r.choice(self.seeds))
        for _ in range(r.randint(1, 4)):
            op = r.randrange(9 if self.osc else 7)
            n = len(buf)
            if op == 0 and n:                               # bit flips
                for _ in range(r.randint(1, 8)):
                    i = r.randrange(n)
                    buf[i] ^= 1 << r.randrange(8)
            elif op == 1 and n:                             # byte overwrite
                buf[r.randrange(n)] = r.randrange(256)
            elif op == 2:                                   # insertion (zeros likely)
                ins = bytes(r.randint(1, 4)) if r.random() < 0.5 else r.randbytes(r.randint(1, 16))
                i = r.randint(0, n)
                buf[i:i] = ins
            elif op == 3 and n:                             # deletion
                i = r.randrange(n)
                del buf[i:i + r.randint(1, 16)]
            elif op == 4 and n:                             # truncation
                del buf[r.randrange(n):]
            elif op == 5:                                   # splice with another seed
                other = r.choice(self.seeds)
                i, j = r.randint(0, n), r.randint(0, len(other))
                buf = buf[:i] + other[j:]
            elif op == 6 and n >= 4:                        # non-finite / huge float patch
                i = r.randrange(0, n - 3)
                buf[i:i + 4] = struct.pack(">f", r.choice((math.nan, math.inf, -math.inf,
                                                           3e38, -1e-45, 0.0)))
            elif op == 7:                                   # OSC type tags rewritten
                k = buf.find(b",")
                if k >= 0:
                    for _ in range(r.randint(1, 3)):
                        i = k + 1 + r.randrange(8)
                        if i < len(buf):
                            buf[i] = r.choice(OSC_TAGS)
            elif op == 8 and n >= 20:                       # bundle length / size field
                i = r.choice((16, r.randrange(0, n - 3)))
                buf[i:i + 4] = struct.pack(">i", r.choice((-1, 0, 3, 7, n, 1 << 30,
                                                           r.randrange(-100, 2000))))
        return bytes(buf)


# ============================================================================ checks
def frame_ok(f: Any) -> bool:
    """The output contract: every valid quaternion is finite and unit (frames of
    ``rtseg.core.frame.Frame`` or ``rtseg.drivers.serial.codec.DecodedFrame``)."""
    q = np.asarray(f.quats, dtype=np.float64)
    v = np.asarray(f.valid, dtype=bool)
    if q.size == 0 or not v.any():
        return True
    qv = q.reshape(-1, 4)[v.reshape(-1)]
    return bool(np.isfinite(qv).all() and np.allclose(np.einsum("ij,ij->i", qv, qv), 1.0,
                                                      atol=1e-6))


class Runner:
    """Feeds one format's inputs; counts escapes, frames, contract violations."""

    def __init__(self, name: str, make: Callable[[], Any],
                 step: Callable[[Any, bytes, int], list]) -> None:
        self.name, self.make, self.step = name, make, step
        self.escaped = 0
        self.frames = 0
        self.bad_frames = 0
        self.examples: list[str] = []

    def run(self, inputs: Callable[[], bytes], n: int) -> dict:
        dec = self.make()
        counters: dict[str, int] = {}
        t0 = time.perf_counter()
        for i in range(n):
            if i and i % FRESH_EVERY == 0:
                _add(counters, _stats(dec))
                dec = self.make()
            data = inputs()
            try:
                out = self.step(dec, data, i)
            except Exception:       # noqa: BLE001 - the point is to count them
                self.escaped += 1
                if len(self.examples) < 3:
                    self.examples.append(f"input {data!r}\n{traceback.format_exc()}")
                dec = self.make()
                continue
            for f in out:
                self.frames += 1
                if not frame_ok(f):
                    self.bad_frames += 1
                    if len(self.examples) < 3:
                        self.examples.append(f"contract violated by {data!r}: {f}")
        dt = time.perf_counter() - t0
        _add(counters, _stats(dec))
        return {"inputs": n, "escaped": self.escaped, "frames": self.frames,
                "contract_violations": self.bad_frames, "counters": counters,
                "inputs_per_s": n / dt if dt > 0 else None, "seconds": dt,
                "examples": self.examples}


def _stats(dec: Any) -> dict[str, int]:
    objs = dec if isinstance(dec, tuple) else (dec,)
    out: dict[str, int] = {}
    for o in objs:
        st = getattr(o, "stats", None)
        if st is not None:
            _add(out, {k: v for k, v in st.as_dict().items() if isinstance(v, int)})
    return out


def _add(acc: dict[str, int], d: dict[str, int]) -> None:
    for k, v in d.items():
        acc[k] = acc.get(k, 0) + v


def _serial_decoders() -> tuple[Any, Any]:
    ids = range(17)
    return cs.SerialFrameDecoder(known_ids=ids), cs.TextLineDecoder(known_ids=ids)


def _serial_step(dec, data, i):
    """Binary frames from every input; every 8th input also as text lines, then flushed."""
    binary, text = dec
    out = binary.feed(data)
    if i % 8 == 0:
        out += text.feed(data)
        out += text.flush()
    return out


def _feed_then_flush(dec, data, i):
    """Feed at 1 ms per input; every 64 inputs flush as if 1 s had passed (assemblers that
    close frames on time)."""
    now = i * 0.001
    out = dec.feed(data, now)
    if i % 64 == 63:
        out += dec.flush(now + 1.0)
    return out


#: format -> (seed inputs, whether they are OSC, a fresh decoder, its step)
FORMATS: dict[str, tuple[Callable, bool, Callable[[], Any], Callable]] = {
    "serial": (lambda rng: serial_seeds(rng) + serial_text_seeds(rng), False,
               _serial_decoders, _serial_step),
    "vmc": (vmc_seeds, True, lambda: cv.VmcAssembler(BONES, stats=SourceStats()),
            _feed_then_flush),
    "vrchat": (vrchat_seeds, True, lambda: cvr.VrchatAssembler(root="head", stats=SourceStats()),
               _feed_then_flush),
    "mvn": (mvn_seeds, False, lambda: MvnAssembler(list(range(1, 24)), stats=SourceStats()),
            _feed_then_flush),
    "mocopi": (mocopi_seeds, False, lambda: MocopiAssembler(stats=SourceStats()),
               lambda dec, data, i: dec.feed(data, i * 0.001)),
    "mvn_tcp": (mvn_tcp_seeds, False, lambda: MvnTcpFeed(list(range(1, 24))), _feed_then_flush),
    "rokoko": (rokoko_seeds, False, rokoko_feed, _feed_then_flush),
    "axis": (axis_seeds, False, axis_binary_feed, _feed_then_flush),
    "axis_text": (axis_text_seeds, False, AxisTextFeed, _feed_then_flush),
}


def fuzz_format(fmt: str, n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    rnd = random.Random(seed)
    seeds, osc, make, step = FORMATS[fmt]
    return Runner(fmt, make, step).run(Mutator(seeds(rng), rnd, osc=osc), n)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=1_000_000, help="inputs per format (default 10^6)")
    p.add_argument("--formats", default=",".join(FORMATS),
                   help=f"comma separated (default all: {', '.join(FORMATS)})")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--json", action="store_true", help="print only the JSON result")
    args = p.parse_args(argv)
    if args.n < 1:
        p.error("--n must be >= 1")
    fmts = [f.strip() for f in args.formats.split(",") if f.strip()]
    for f in fmts:
        if f not in FORMATS:
            p.error(f"unknown format {f!r} ({', '.join(FORMATS)})")
    logging.disable(logging.CRITICAL)      # the decoders warn on every kind of junk
    results = {}
    for f in fmts:
        r = fuzz_format(f, args.n, args.seed)
        results[f] = r
        if not args.json:
            c = ", ".join(f"{k} {v}" for k, v in sorted(r["counters"].items()) if v)
            print(f"{f:9s} {r['inputs']:,} inputs in {r['seconds']:.1f} s "
                  f"({r['inputs_per_s']:,.0f}/s): {r['escaped']} escaped, {r['frames']:,} frames, "
                  f"{r['contract_violations']} contract violations; counters: {c}", flush=True)
            for ex in r["examples"]:
                print(ex, file=sys.stderr)
    if args.json:
        print(json.dumps(results, indent=2))
    bad = any(r["escaped"] or r["contract_violations"] for r in results.values())
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
