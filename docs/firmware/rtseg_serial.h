/*
 * rtseg serial wire format, version 1: reference encoder for microcontrollers (C99).
 *
 *   0x00 | COBS( body || crc16_le(body) ) | 0x00
 *
 * body (little-endian): u8 version=1, u8 type=1, u16 seq, u32 time_us, u8 n,
 *   then n x { u8 id, u8 status, i16 w, i16 x, i16 y, i16 z }   (Q14: 1.0 = 16384)
 * status bits: bit0 valid, bits1-2 calibration 0..3, bit3 error.
 * crc16: CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), check("123456789") = 0x29B1.
 *
 * Specification: rtseg/drivers/codec_serial.py and docs/protocols.md.  This file is
 * compiled and checked against the Python decoder by tests/test_codec_serial.py.
 * Usage (Arduino):
 *     static uint8_t wire[RTSEG_MAX_WIRE(17)];
 *     size_t len = rtseg_encode_frame(seq++, micros(), 17, ids, status, q14, wire);
 *     Serial.write(wire, len);
 */
#ifndef RTSEG_SERIAL_H
#define RTSEG_SERIAL_H

#include <stddef.h>
#include <stdint.h>

#define RTSEG_VERSION 1
#define RTSEG_MSG_FRAME 1
#define RTSEG_STATUS_VALID 0x01
#define RTSEG_STATUS_CAL(level) ((uint8_t)(((level) & 3) << 1))
#define RTSEG_STATUS_ERROR 0x08
#define RTSEG_BODY_LEN(n) (9 + 10 * (size_t)(n))
/* body + crc, plus one COBS byte per 254, plus the two delimiters */
#define RTSEG_MAX_WIRE(n) (RTSEG_BODY_LEN(n) + 2 + (RTSEG_BODY_LEN(n) + 2) / 254 + 1 + 2)

static uint16_t rtseg_crc16(const uint8_t *p, size_t n) {
    uint16_t crc = 0xFFFF;
    while (n--) {
        crc ^= (uint16_t)(*p++) << 8;
        for (int b = 0; b < 8; b++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* COBS-encode n bytes of src into dst (room for n + n/254 + 1 bytes); returns length.
 * The output contains no zero byte. */
static size_t rtseg_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst) {
    size_t code_at = 0, out = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (src[i] == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        } else {
            dst[out++] = src[i];
            if (++code == 0xFF && i + 1 < n) {  /* full block: no implied zero */
                dst[code_at] = code;
                code_at = out++;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    return out;
}

/* One orientation frame, ready to write.  q[k] = {w, x, y, z} in Q14 (scalar FIRST).
 * out needs RTSEG_MAX_WIRE(n) bytes.  Returns the number of bytes to send. */
static size_t rtseg_encode_frame(uint16_t seq, uint32_t time_us, uint8_t n,
                                 const uint8_t *ids, const uint8_t *status,
                                 const int16_t (*q)[4], uint8_t *out) {
    static uint8_t body[RTSEG_BODY_LEN(255) + 2];
    size_t m = 0;
    body[m++] = RTSEG_VERSION;
    body[m++] = RTSEG_MSG_FRAME;
    body[m++] = (uint8_t)(seq & 0xFF);
    body[m++] = (uint8_t)(seq >> 8);
    for (int b = 0; b < 4; b++) body[m++] = (uint8_t)(time_us >> (8 * b));
    body[m++] = n;
    for (uint8_t k = 0; k < n; k++) {
        body[m++] = ids[k];
        body[m++] = status[k];
        for (int c = 0; c < 4; c++) {
            uint16_t v = (uint16_t)q[k][c];
            body[m++] = (uint8_t)(v & 0xFF);
            body[m++] = (uint8_t)(v >> 8);
        }
    }
    uint16_t crc = rtseg_crc16(body, m);
    body[m++] = (uint8_t)(crc & 0xFF);   /* CRC little-endian, like every field */
    body[m++] = (uint8_t)(crc >> 8);
    out[0] = 0x00;
    size_t len = rtseg_cobs_encode(body, m, out + 1);
    out[1 + len] = 0x00;
    return len + 2;
}

#endif /* RTSEG_SERIAL_H */
