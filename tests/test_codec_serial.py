"""rtseg serial wire format: COBS, CRC, frame layout, streaming decoders (no device)."""

from __future__ import annotations

import struct
from binascii import crc_hqx

import numpy as np
import pytest

from rtseg.drivers.serial import codec
from rtseg.drivers.serial.codec import (
    SerialFrameDecoder, TextLineDecoder, cobs_decode, cobs_encode, encode_frame)

IDS17 = list(range(17))


def random_quats(rng: np.random.Generator, *shape: int) -> np.ndarray:
    q = rng.normal(size=shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def wire_frames(n: int, seed: int = 0, ids=IDS17, seq0: int = 0, t0: int = 0):
    rng = np.random.default_rng(seed)
    q = random_quats(rng, n, len(ids))
    data = [encode_frame(seq0 + i, t0 + 8333 * i, ids, q[i]) for i in range(n)]
    return q, data


def test_crc_check_value():
    assert codec.crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize("raw, enc", [
    # Vectors from the COBS paper / Wikipedia "Consistent Overhead Byte Stuffing".
    (b"\x00", b"\x01\x01"),
    (b"\x00\x00", b"\x01\x01\x01"),
    (b"\x00\x11\x00", b"\x01\x02\x11\x01"),
    (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
    (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
    (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255))),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01"),
    (bytes(range(3, 256)) + b"\x00\x01", b"\xfe" + bytes(range(3, 256)) + b"\x02\x01"),
])
def test_cobs_reference_vectors(raw, enc):
    assert cobs_encode(raw) == enc
    assert bytes(cobs_decode(enc)) == raw


def test_cobs_round_trip_and_invalid():
    rng = np.random.default_rng(1)
    for n in (1, 10, 253, 254, 255, 508, 700):
        for density in (0.0, 0.05, 0.5):
            d = rng.integers(1, 256, n).astype(np.uint8)
            d[rng.random(n) < density] = 0
            raw = d.tobytes()
            enc = cobs_encode(raw)
            assert b"\x00" not in enc
            assert bytes(cobs_decode(enc)) == raw
    assert cobs_decode(b"\x05\x11\x22") is None  # code points past the end
    assert cobs_decode(b"") is None


def test_frame_layout_matches_spec():
    q = np.array([[0.0, 0.0, 0.0, 1.0], [0.5, -0.5, 0.5, 0.5]])
    wire = encode_frame(0x1234, 0xDEADBEEF, [3, 200], q, status=[0x07, 0x01])
    assert wire[0] == 0 and wire[-1] == 0 and b"\x00" not in wire[1:-1]
    dec = bytes(cobs_decode(wire[1:-1]))
    body, crc = dec[:-2], dec[-2:]
    assert int.from_bytes(crc, "little") == crc_hqx(body, 0xFFFF)
    assert len(body) == 9 + 2 * 10
    assert struct.unpack_from("<BBHIB", body) == (1, 1, 0x1234, 0xDEADBEEF, 2)
    # sensor records: id, status, w x y z in Q14
    assert struct.unpack_from("<BBhhhh", body, 9) == (3, 0x07, 16384, 0, 0, 0)
    assert struct.unpack_from("<BBhhhh", body, 19) == (200, 0x01, 8192, 8192, -8192, 8192)


def test_status_bits():
    assert codec.status_bits(True, 3, False) == 0x07 == codec.STATUS_DEFAULT
    assert codec.status_bits(False, 2, True) == 0x0C
    assert codec.calibration_level(0x0C) == 2
    with pytest.raises(ValueError):
        codec.status_bits(True, 4)


def test_round_trip_within_q14_resolution_and_wraps():
    q, data = wire_frames(50, seq0=65530, t0=2**32 - 100_000)
    dec = SerialFrameDecoder(known_ids=IDS17)
    out = dec.feed(b"".join(data))
    assert len(out) == 50
    assert dec.stats.frames == 50 and dec.stats.corrupt == 0
    for i, f in enumerate(out):
        assert f.msg_type == codec.MSG_FRAME
        assert f.seq == (65530 + i) & 0xFFFF
        assert f.time_us == (2**32 - 100_000 + 8333 * i) & 0xFFFFFFFF
        assert list(f.ids) == IDS17 and f.valid.all()
        np.testing.assert_allclose(f.quats, q[i], atol=codec.Q14_RESOLUTION)
        np.testing.assert_allclose(np.linalg.norm(f.quats, axis=1), 1.0, atol=1e-12)


def test_long_frame_uses_ff_blocks():
    ids = list(range(40))  # 409-byte body: COBS 0xFF blocks when a 254-byte run has no zero
    rng = np.random.default_rng(3)
    q = random_quats(rng, 40)
    q[np.abs(q) < 0.05] = 0.3  # avoid zero bytes from small values
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    body = codec.frame_body(7, 1, ids, q, status=0x07)
    wire = codec.pack_message(body)
    (f,) = SerialFrameDecoder().feed(wire)
    np.testing.assert_allclose(f.quats, q, atol=codec.Q14_RESOLUTION)
    assert list(f.ids) == ids


def test_resync_after_boot_text_truncation_and_split_feeds():
    q, data = wire_frames(6)
    boot = b"ets Jun  8 2016 00:22:57\r\nrst:0x1 (POWERON_RESET),boot:0x13\r\nload:0x3fff0018\r\n"
    stream = boot + data[0] + data[1][:40] + data[2] + b"\x00\x00\x00" + data[3] + data[4][:-1] \
        + boot + data[5]
    # frame 1 is cut short, frame 4 lost its trailing delimiter so the boot text joins it
    expected = [0, 2, 3, 5]
    for step in (1, 7, 64, len(stream)):
        dec = SerialFrameDecoder(known_ids=IDS17)
        got = []
        for a in range(0, len(stream), step):
            got += dec.feed(stream[a:a + step])
        assert [f.seq for f in got] == expected, step
        for f in got:
            np.testing.assert_allclose(f.quats, q[f.seq], atol=codec.Q14_RESOLUTION)
        assert dec.stats.corrupt == 2  # truncated 1, merged 4+boot
        assert dec.stats.skipped_bytes == len(boot)  # before the first delimiter


def test_each_kind_of_damage_is_counted():
    q = random_quats(np.random.default_rng(2), 2)
    good = codec.frame_body(1, 10, [0, 1], q)
    dec = SerialFrameDecoder()
    dec.feed(b"\x00")
    # bad CRC
    bad_crc = bytearray(codec.pack_message(good))
    dec_body = bytearray(cobs_decode(bytes(bad_crc[1:-1])))
    dec_body[-1] ^= 0x55
    assert dec.feed(b"\x00" + cobs_encode(bytes(dec_body)) + b"\x00") == []
    assert dec.stats.bad_crc == 1
    # bad version (valid CRC)
    assert dec.feed(codec.pack_message(b"\x02" + good[1:])) == []
    assert dec.stats.bad_version == 1
    # length does not match n (valid CRC)
    assert dec.feed(codec.pack_message(good[:-1])) == []
    assert dec.feed(codec.pack_message(b"\x01\x01\x00")) == []
    assert dec.stats.bad_length == 2
    # not COBS: a code byte pointing past the end
    assert dec.feed(b"\x00\x30\x01\x02\x00") == []
    assert dec.stats.bad_cobs == 1
    assert dec.stats.corrupt == 5
    # unknown message type with a valid CRC is not corrupt, just refused: only its number
    # is passed on (it counts in the sequence), with no sensors
    (unknown,) = dec.feed(codec.pack_message(b"\x01\x09" + good[2:]))
    assert (unknown.msg_type, unknown.seq, len(unknown.ids)) == (9, 1, 0)
    assert dec.stats.bad_messages == 1 and dec.stats.corrupt == 5
    # overlong run without any delimiter: discarded, decoder resynchronises
    assert dec.feed(b"\x01" * (codec.MAX_WIRE_BYTES + 10)) == []
    assert dec.stats.corrupt == 6 and dec.pending_bytes == 0
    out = dec.feed(b"\x00" + codec.pack_message(good))
    assert [f.seq for f in out] == [1]


def test_bad_values_and_unknown_ids():
    rec = struct.Struct("<BBhhhh")
    header = struct.pack("<BBHIB", 1, 1, 5, 0, 6)
    body = header + b"".join([
        rec.pack(0, 0x07, 16384, 0, 0, 0),            # good
        rec.pack(1, 0x07, 16384, 16384, 16384, 16384),  # norm 2: bad value
        rec.pack(2, 0x07, 0, 0, 0, 0),                # zero while claiming valid: bad value
        rec.pack(3, 0x06, 0, 0, 0, 0),                # not valid, says so: fine, not counted
        rec.pack(4, 0x0F, 16384, 0, 0, 0),            # error bit: not valid, not counted
        rec.pack(99, 0x07, 0, 16384, 0, 0),           # unknown id, valid value
    ])
    dec = SerialFrameDecoder(known_ids=range(17))
    (f,) = dec.feed(b"\x00" + codec.pack_message(body))
    assert list(f.valid) == [True, False, False, False, False, True]
    assert dec.stats.bad_values == 2
    assert dec.stats.unknown_ids == 1
    np.testing.assert_allclose(f.quats[5], [1.0, 0.0, 0.0, 0.0])  # x=1 in scalar-last
    # Q14 rounding and a slightly off norm are tolerated and renormalised
    s = int(round(16384 * 1.02))
    (g,) = dec.feed(codec.pack_message(header[:-1] + b"\x01" + rec.pack(0, 0x07, s, 0, 0, 0)))
    assert g.valid[0] and np.allclose(g.quats[0], [0, 0, 0, 1])
    s = int(round(16384 * 1.05))
    (h,) = dec.feed(codec.pack_message(header[:-1] + b"\x01" + rec.pack(0, 0x07, s, 0, 0, 0)))
    assert not h.valid[0] and dec.stats.bad_values == 3


def test_status_and_info_messages():
    dec = SerialFrameDecoder(known_ids=IDS17)
    q, data = wire_frames(1, seq0=3)
    stream = (codec.encode_info(1, 0, {"fw": "1.2", "board": "esp32"})
              + codec.encode_status(2, 5, [0, 1, 50], [0x07, 0x08, 0x01]) + data[0])
    info, status, frame = dec.feed(b"\x00" + stream)
    assert info.msg_type == codec.MSG_INFO and info.info == {"fw": "1.2", "board": "esp32"}
    assert status.msg_type == codec.MSG_STATUS and list(status.ids) == [0, 1, 50]
    assert list(status.status) == [0x07, 0x08, 0x01] and not status.valid.any()
    assert frame.seq == 3
    assert dec.stats.unknown_ids == 1 and dec.stats.messages == 3 and dec.stats.frames == 1


def test_encoder_refuses_bad_input():
    with pytest.raises(ValueError):
        encode_frame(0, 0, [0], np.array([[np.nan, 0, 0, 1]]))
    with pytest.raises(ValueError):
        encode_frame(0, 0, [0, 1], np.array([[0, 0, 0, 1.0]]))
    with pytest.raises(ValueError):
        encode_frame(0, 0, [256], np.array([[0, 0, 0, 1.0]]))


# --------------------------------------------------------------------------- text


def test_text_round_trip_and_grouping_by_repeated_id():
    rng = np.random.default_rng(4)
    q = random_quats(rng, 3, 4)
    stream = b"".join(codec.encode_text_frame([0, 1, 2, 3], q[i]) for i in range(3))
    dec = TextLineDecoder()  # no known ids: frames close when an id repeats
    out = dec.feed(stream)
    assert len(out) == 2  # the third frame is still open
    out += dec.flush()
    assert len(out) == 3
    for i, f in enumerate(out):
        assert f.seq is None and f.time_us is None and f.valid.all()
        np.testing.assert_allclose(f.quats, q[i], atol=2e-6)


def test_text_grouping_rules():
    line = b"%d,1,0,0,0\n"
    dec = TextLineDecoder(known_ids=[0, 1, 2])
    # rule 3: all known ids seen closes at once
    assert len(dec.feed(line % 0 + line % 2 + line % 1)) == 1
    # rule 2: blank line and '#' line close a partial frame
    (a,) = dec.feed(line % 0 + b"\r\n")
    (b,) = dec.feed(line % 1 + line % 2 + b"# frame end\n")
    assert list(a.ids) == [0] and list(b.ids) == [1, 2]
    # rule 1: repeated id
    (c,) = dec.feed(line % 1 + line % 1)
    assert list(c.ids) == [1] and dec.has_partial
    assert dec.stats.frames == 4


def test_text_bad_lines_are_counted_not_raised():
    dec = TextLineDecoder(known_ids=[0, 1])
    stream = (b"Booting sketch v1.2...\r\n"            # garbage
              b"0,1,0,0\n"                             # too few fields
              b"1,1,0,0,zero\n"                        # unparseable number
              b"0,nan,0,0,0\n"                         # NaN: bad value
              b"1,2,0,0,0,7\n"                         # norm 2: bad value
              b"0,0.7071,0.7071,0,0,7\n"               # fine (x = 0.7071 scalar-last)
              b"1,1,0,0,0,6\n"                         # status says invalid: fine
              b"7,1,0,0,0\n"                           # unknown id
              b"300,1,0,0,0\n"                         # id out of range
              + b"x" * 400 + b"\n")                    # overlong garbage
    out = dec.feed(stream) + dec.flush()
    assert dec.stats.garbage_lines == 2
    assert dec.stats.bad_messages == 3
    assert dec.stats.bad_values == 2
    assert dec.stats.unknown_ids == 1
    assert [list(f.valid) for f in out] == [[False, False], [True, False], [True]]
    np.testing.assert_allclose(out[1].quats[0], [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-4)


def test_decoder_for():
    assert isinstance(codec.decoder_for("rtseg"), SerialFrameDecoder)
    assert isinstance(codec.decoder_for("text"), TextLineDecoder)
    with pytest.raises(ValueError, match="unknown serial format"):
        codec.decoder_for("json")


# --------------------------------------------------------------------------- C reference

C_MAIN = r"""
#include <stdio.h>
#include "rtseg_serial.h"
int main(void) {
    static uint8_t ids[255], st[255], out[RTSEG_MAX_WIRE(255)];
    static int16_t q[255][4];
    uint32_t r = 12345u;
    const int sizes[] = {0, 1, 17, 25, 40, 255, 255, 60};
    printf("%04x\n", rtseg_crc16((const uint8_t *)"123456789", 9));
    for (int f = 0; f < 8; f++) {
        int n = sizes[f];
        uint16_t seq = (uint16_t)(65530 + f);
        uint32_t t = 4294967000u + 100000u * (uint32_t)f;
        printf("%u %u %d", seq, t, n);
        for (int k = 0; k < n; k++) {
            ids[k] = (uint8_t)(f == 7 ? k + 1 : k);
            st[k] = (uint8_t)(f == 7 ? 7 : k % 16);
            for (int c = 0; c < 4; c++) {
                r = r * 1103515245u + 12345u;
                int v = (int)((r >> 8) % 32769u) - 16384;
                if (f == 7) v = 257 + (int)((r >> 8) % 200u);  /* no zero bytes at all */
                q[k][c] = (int16_t)v;
                printf(" %d", v);
            }
            printf(" %u %u", ids[k], st[k]);
        }
        size_t len = rtseg_encode_frame(seq, t, (uint8_t)n, ids, st, q, out);
        printf(" ");
        for (size_t i = 0; i < len; i++) printf("%02x", out[i]);
        printf("\n");
    }
    return 0;
}
"""


def test_c_reference_encoder_matches(tmp_path):
    """docs/firmware/rtseg_serial.h, compiled, produces exactly the Python encoder's bytes."""
    import shutil
    import subprocess
    from pathlib import Path
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler")
    header_dir = Path(__file__).resolve().parent.parent / "docs" / "firmware"
    (tmp_path / "main.c").write_text(C_MAIN)
    exe = tmp_path / "enc"
    subprocess.run([cc, "-std=c99", "-Wall", "-Werror", "-O1", f"-I{header_dir}",
                    str(tmp_path / "main.c"), "-o", str(exe)], check=True, capture_output=True)
    lines = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split("\n")
    assert lines[0] == "29b1"
    dec = SerialFrameDecoder()
    dec.feed(b"\x00")
    n_ff = 0
    for line in lines[1:9]:
        tok = line.split()
        seq, t, n = int(tok[0]), int(tok[1]), int(tok[2])
        rec = np.array(tok[3:3 + 6 * n], dtype=np.int64).reshape(n, 6)
        wire = bytes.fromhex(tok[3 + 6 * n])
        wxyz = rec[:, :4] / 16384.0
        py = encode_frame(seq, t, rec[:, 4], wxyz[:, [1, 2, 3, 0]], status=rec[:, 5])
        assert wire == py
        p = 1
        while p < len(wire) - 1:  # walk the COBS code bytes
            n_ff += wire[p] == 0xFF  # a full 254-byte block
            p += wire[p]
        (f,) = dec.feed(wire)
        assert (f.seq, f.time_us, list(f.ids)) == (seq, t & 0xFFFFFFFF, list(rec[:, 4]))
    assert dec.stats.corrupt == 0
    assert n_ff >= 1  # the zero-free 60-sensor frame exercised 0xFF blocks


def test_complete_frames_take_the_short_path_with_the_same_values():
    """A frame of exactly the suit's sensors, in order, all valid, is flagged ``complete``
    (the serial source then uses it without a lookup); its values are those the checked
    path gives.  One damaged record, another order or a missing sensor is not complete."""
    q, data = wire_frames(6)
    dec = SerialFrameDecoder(known_ids=IDS17)
    fast = dec.feed(b"".join(data))
    assert [f.complete for f in fast] == [True] * 6
    plain = SerialFrameDecoder(known_ids=None).feed(b"".join(data))   # no suit: checked path
    assert not any(f.complete for f in plain)
    for a, b, want in zip(fast, plain, q):
        np.testing.assert_allclose(a.quats, b.quats, rtol=0, atol=1e-15)
        assert a.valid.all() and b.valid.all()
        np.testing.assert_allclose(a.quats, want, atol=codec.Q14_RESOLUTION)
    # one frame alone per feed (the live case) is complete too
    dec1 = SerialFrameDecoder(known_ids=IDS17)
    assert all(dec1.feed(d)[0].complete for d in data[1:4])
    # sensors in another order, one sensor missing, one not valid, a non-unit value
    base = q[0]
    cases = {
        "reversed": (IDS17[::-1], base[::-1], None),
        "missing": (IDS17[:-1], base[:-1], None),
        "invalid": (IDS17, base, [codec.STATUS_DEFAULT] * 16 + [0x06]),
        "norm": (IDS17, np.vstack([base[:16], base[16:] * 1.2]), None),
    }
    for name, (ids, qq, status) in cases.items():
        dec = SerialFrameDecoder(known_ids=IDS17)
        (f,) = dec.feed(b"\x00" + codec.encode_frame(1, 0, ids, qq, status))
        assert not f.complete, name
        assert list(f.ids) == list(ids), name
        assert f.valid.sum() == len(ids) - (name in ("invalid", "norm")), name
