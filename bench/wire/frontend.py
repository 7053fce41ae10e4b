"""The measurement front-end's serial stream: LEM x3, voltage bridge x3 and the encoder counter, one frame per
sample; the codec of `bench.drivers.frontend.FrontEnd` and of the emulated front-end.

Wire format (docs/protocols.md), one frame per sample, little-endian, 28 bytes::

    offset  size  field
    0       2     sync word A5 5A
    2       2     seq        uint16, +1 per sample (the tick number modulo 2^16)
    4       2     status     uint16: bit0 encoder error, bit1 ADC clipped, bit2 index seen
    6       6     raw_i      3 x int16 ADC codes, LEM currents a, b, c
    12      6     raw_u      3 x int16 ADC codes, voltage bridge a, b, c
    18      4     enc_count  uint32 counter value (wraps at the rig's modulus)
    22      4     enc_index  int32 count latched at the last index pulse, -1 if none
    26      2     crc        CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over bytes 2..25

The frame format is ours, so it is hand-packed with `struct`; the CRC is the standard
CRC-16/CCITT-FALSE computed by the C implementation in the standard library (`binascii.crc_hqx`),
not a hand-written one: it is maintained, fast (~0.1 us per frame) and what most MCU CRC units do.

`FrameParser` turns a byte stream into frames: it hunts for the sync word, checks the CRC and on a
bad frame skips one byte and hunts again, so it resynchronises after any corruption, and never
raises on any input (tests/test_fuzz_frames.py feeds it 1e5 random and mutated frames).
"""

from __future__ import annotations

import binascii
import struct

SYNC = b"\xa5\x5a"
_BODY = struct.Struct("<HH3h3hIi")  # seq, status, raw_i, raw_u, enc_count, enc_index
FRAME_SIZE = 2 + _BODY.size + 2  # 28
FS_ENC_ERROR, FS_ADC_CLIP, FS_INDEX = 1, 2, 4  # frame status bits

Frame = tuple[int, int, tuple[int, int, int], tuple[int, int, int], int, int]  # seq, status, raw_i, raw_u, count, index


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (check value 0x29B1 for b"123456789")."""
    return binascii.crc_hqx(data, 0xFFFF)


def encode_frame(seq: int, status: int, raw_i: tuple[int, int, int], raw_u: tuple[int, int, int],
                 enc_count: int, enc_index: int) -> bytes:  # fmt: skip
    """One frame (used by the emulator and the tests)."""
    body = _BODY.pack(seq & 0xFFFF, status & 0xFFFF, *raw_i, *raw_u, enc_count & 0xFFFFFFFF, enc_index)
    return SYNC + body + struct.pack("<H", crc16(body))


def decode_frame(buf: bytes) -> Frame | None:
    """Decode exactly one frame; None if it is not a valid one (length, sync word or CRC)."""
    if len(buf) != FRAME_SIZE or buf[:2] != SYNC:
        return None
    body = buf[2:-2]
    if crc16(body) != (buf[-2] | (buf[-1] << 8)):
        return None
    seq, st, i0, i1, i2, u0, u1, u2, cnt, idx = _BODY.unpack(body)
    return seq, st, (i0, i1, i2), (u0, u1, u2), cnt, idx


class FrameParser:
    """Byte stream -> frames, with resynchronisation. Counts CRC/framing errors in ``crc_errors``."""

    MAX_BUFFER = 64 * FRAME_SIZE  # a stream that never syncs cannot grow the buffer without bound

    def __init__(self) -> None:
        self.buf = bytearray()
        self.crc_errors = 0
        self.frames = 0

    def feed(self, data: bytes) -> list[Frame]:
        buf = self.buf
        buf += data
        out: list[Frame] = []
        while True:
            j = buf.find(SYNC)
            if j < 0:
                # keep a trailing A5 that may start the next sync word
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                del buf[: len(buf) - keep]
                break
            if j:
                del buf[:j]
            if len(buf) < FRAME_SIZE:
                break
            frame = decode_frame(bytes(buf[:FRAME_SIZE]))
            if frame is None:
                self.crc_errors += 1
                del buf[:1]  # hunt for the next sync word inside this frame
                continue
            del buf[:FRAME_SIZE]
            out.append(frame)
            self.frames += 1
        if len(buf) > self.MAX_BUFFER:
            del buf[: len(buf) - FRAME_SIZE]
        return out
