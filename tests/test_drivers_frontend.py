"""Measurement front-end: frame format byte for byte, stream parser, the driver over socket:// and
a pty pair, scaling, sequence checks and reconnection."""

from __future__ import annotations

import time

import pytest

from bench.drivers.frontend import FrontEnd
from bench.wire.frontend import FRAME_SIZE, FrameParser, crc16, decode_frame, encode_frame
from bench.hal import ST_LINK_DOWN, ST_MEAS_CRC, ST_MEAS_DUP, ST_MEAS_LATE, ST_MEAS_LOST, ST_MEAS_STALE
from mock_hw.emulators.links import SerialEndpoint

T = 1.0 / 3000
FE = {"turns_ratio": 1000.0, "burden": 500.0, "adc_bits": 12, "adc_range": 10.0, "offset_i": (0.0, 0.0, 0.0),
      "offset_u": (0.0, 0.0, 0.0), "divider_ratio": 0.025, "lines": 1024, "modulus": 65536}  # fmt: skip


def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1  # the catalogued check value of CRC-16/CCITT-FALSE


def test_frame_layout_byte_for_byte():
    f = encode_frame(0x1234, 0x0004, (1, -1, 2047), (-2048, 0, 100), 0x00010203, -1)
    body = bytes.fromhex("3412 0400 0100 ffff ff07 00f8 0000 6400 03020100 ffffffff")
    assert f == b"\xa5\x5a" + body + crc16(body).to_bytes(2, "little")
    assert len(f) == FRAME_SIZE == 28
    assert decode_frame(f) == (0x1234, 4, (1, -1, 2047), (-2048, 0, 100), 0x10203, -1)
    bad = bytearray(f)
    bad[10] ^= 1
    assert decode_frame(bytes(bad)) is None


def test_parser_resynchronises_after_garbage_and_corruption():
    frames = [encode_frame(k, 0, (k, 0, 0), (0, 0, 0), k, -1) for k in range(5)]
    bad = bytearray(frames[2])
    bad[20] ^= 0xFF
    stream = b"\x00\xa5\x5a\xa5" + frames[0] + frames[1] + bytes(bad) + b"\xa5" + frames[3] + frames[4]
    p = FrameParser()
    got = []
    for i in range(0, len(stream), 7):  # arbitrary chunking
        got += p.feed(stream[i:i + 7])
    assert [f[0] for f in got] == [0, 1, 3, 4]
    assert p.crc_errors >= 1


class Link:
    """Device side of the serial link plus the driver on the host side."""

    def __init__(self, url: str = "socket://127.0.0.1:0", **fe) -> None:
        self.dev = SerialEndpoint(url)
        self.fe = FrontEnd({"port": self.dev.url, "baudrate": 2_000_000, "timeout": 0.02, "reconnect_interval": 0.01},
                           {**FE, **fe}, T)  # fmt: skip
        self.fe.configure()
        self.fe.activate()
        assert self.dev.wait_connected(2.0)

    def send(self, k: int, raw_i=(0, 0, 0), raw_u=(0, 0, 0), cnt: int = 0, idx: int = -1, status: int = 0) -> bytes:
        f = encode_frame(k, status, raw_i, raw_u, cnt, idx)
        self.dev.write(f)
        return f

    def close(self) -> None:
        self.fe.close()
        self.dev.close()


@pytest.fixture(params=["socket://127.0.0.1:0", "pty"])
def link(request):
    lk = Link(request.param)
    yield lk
    lk.close()


def test_scaling_and_ports(link):
    # 0.5 V/A (1000 turns, 500 Ohm); 12 bits over +-10 V: 4.8828 mV per code
    link.send(0, raw_i=(205, -205, 0), raw_u=(1000, -500, -500), cnt=4097, idx=12)
    link.fe.acquire(0.0)
    assert link.fe.status_bits == 0
    i = link.fe.currents.read()
    assert i[0] == pytest.approx(205 * 20.0 / 4096 * 2) and i[1] == pytest.approx(-i[0]) and i[2] == 0.0
    assert link.fe.voltages.read()[0] == pytest.approx(1000 * 20.0 / 4096 * 40)  # divider 1/40
    assert link.fe.currents.read_raw() == (205, -205, 0)
    assert link.fe.encoder.read() == (4097, 12) and link.fe.encoder.counts_per_rev == 4096


def test_offsets_are_removed():
    lk = Link(offset_i=(0.01, -0.02, 0.0))
    try:
        lk.send(0, raw_i=(2, -4, 0))
        lk.fe.acquire(0.0)
        assert lk.fe.currents.read()[0] == pytest.approx((2 * 20 / 4096 - 0.01) * 2)
        assert lk.fe.currents.read()[1] == pytest.approx((-4 * 20 / 4096 + 0.02) * 2)
    finally:
        lk.close()


def test_sequence_checks(link):
    fe = link.fe
    link.send(0, cnt=1)
    fe.acquire(0.0)
    assert fe.status_bits == 0
    fe.acquire(T)  # frame 1 never comes
    assert fe.status_bits == ST_MEAS_STALE and fe.encoder.read()[0] == 1  # last values kept
    link.send(1)  # ... comes late, with 2
    link.send(2, cnt=2)
    fe.acquire(2 * T)
    assert fe.status_bits == ST_MEAS_LATE and fe.encoder.read()[0] == 2
    link.send(2)  # a duplicate, then 3
    link.send(3, cnt=3)
    fe.acquire(3 * T)
    assert fe.status_bits == ST_MEAS_DUP
    link.send(6, cnt=6)  # 4 and 5 lost: 6 is taken
    fe.acquire(4 * T)
    assert fe.status_bits == ST_MEAS_LOST and fe.encoder.read()[0] == 6
    bad = bytearray(encode_frame(7, 0, (0, 0, 0), (0, 0, 0), 7, -1))
    bad[-1] ^= 0xFF
    link.dev.write(bytes(bad))
    link.send(7, cnt=7)
    fe.acquire(7 * T)
    assert fe.status_bits == ST_MEAS_CRC and fe.encoder.read()[0] == 7
    assert fe.stats["crc"] == 1 and fe.stats["late"] == 1 and fe.stats["dup"] == 1 and fe.stats["lost"] == 2


def test_waits_at_most_the_timeout():
    lk = Link()
    try:
        t0 = time.perf_counter()
        lk.fe.acquire(0.0)
        assert 0.015 < time.perf_counter() - t0 < 0.2
        assert lk.fe.status_bits & ST_MEAS_STALE
    finally:
        lk.close()


def test_reconnects_after_disconnect():
    lk = Link()
    try:
        lk.send(0)
        lk.fe.acquire(0.0)
        lk.dev.disconnect()
        k = 1
        lk.fe.acquire(k * T)
        assert lk.fe.status_bits & ST_LINK_DOWN and lk.fe.status_bits & ST_MEAS_STALE
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:  # the driver retries every reconnect_interval
            k += 1
            lk.send(k, cnt=k)
            lk.fe.acquire(k * T)
            if lk.fe.status_bits == 0:
                break
        assert lk.fe.status_bits == 0 and lk.fe.encoder.read()[0] == k
        assert lk.fe.stats["reconnects"] == 1 and lk.dev.connections == 2
    finally:
        lk.close()
