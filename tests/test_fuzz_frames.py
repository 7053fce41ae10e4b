"""Frame decoders under fuzzing: random and mutated frames never raise.

Serial front-end frames (decode_frame, FrameParser), CAN frames on both ends (the VLT driver's
status decoder; the emulator's set-point, load and SYNC handlers). The 1e5-frame runs are marked
slow (``pytest -m slow``); smaller always-run versions and hypothesis properties run every time.
"""

from __future__ import annotations

import itertools
import random

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.core.config import parse
from bench.drivers.canbus import CanLink
from bench.wire.frontend import FRAME_SIZE, FrameParser, decode_frame, encode_frame
from bench.drivers.vlt import VltInverter
from mock_hw.emulators import RigEmulator
from mock_hw.emulators.testing import emulated_data

T = 1.0 / 3000
_n = itertools.count()


def valid_frame(rng: random.Random) -> bytes:
    return encode_frame(rng.getrandbits(16), rng.getrandbits(16), tuple(rng.randint(-32768, 32767) for _ in range(3)),
                        tuple(rng.randint(-32768, 32767) for _ in range(3)), rng.getrandbits(32),
                        rng.randint(-(1 << 31), (1 << 31) - 1))  # fmt: skip


def mutate(rng: random.Random, f: bytes) -> bytes:
    b = bytearray(f)
    op = rng.randrange(5)
    if op == 0:  # flip bits
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
    elif op == 1:  # truncate
        del b[rng.randrange(len(b)):]
    elif op == 2:  # insert bytes
        i = rng.randrange(len(b) + 1)
        b[i:i] = rng.randbytes(rng.randint(1, 6))
    elif op == 3:  # random bytes, sync word kept
        b = bytearray(b"\xa5\x5a" + rng.randbytes(rng.randint(0, 40)))
    else:  # swap bytes
        i, j = rng.randrange(len(b)), rng.randrange(len(b))
        b[i], b[j] = b[j], b[i]
    return bytes(b)


def fuzz_serial(n: int, seed: int) -> tuple[int, int]:
    rng = random.Random(seed)
    parser = FrameParser()
    accepted = 0
    for k in range(n):
        f = valid_frame(rng)
        m = mutate(rng, f) if k % 4 else rng.randbytes(rng.randint(0, 2 * FRAME_SIZE))
        d = decode_frame(m)
        if d is not None:  # whatever decodes must re-encode to the same bytes (CRC-valid frame)
            assert encode_frame(*d) == m
        for fr in parser.feed(m):
            assert encode_frame(*fr)[:2] == b"\xa5\x5a"
            accepted += 1
        assert len(parser.buf) <= FrameParser.MAX_BUFFER + 64
    return accepted, parser.crc_errors


@pytest.mark.slow
def test_serial_decoder_survives_1e5_frames():
    accepted, errors = fuzz_serial(100_000, seed=1)
    assert errors > 10_000  # the fuzzer really hit the CRC path


def test_serial_decoder_survives_5e3_frames():
    accepted, errors = fuzz_serial(5_000, seed=2)
    assert errors > 500


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=200), st.integers(1, 64))
def test_parser_never_raises_on_any_stream(data, chunk):
    p = FrameParser()
    for i in range(0, len(data), chunk):
        for fr in p.feed(data[i:i + chunk]):
            assert len(encode_frame(*fr)) == FRAME_SIZE


_NOISE = st.binary(max_size=FRAME_SIZE).map(lambda b: b.replace(b"\xa5", b"\x00"))  # no sync byte in it


@settings(max_examples=200, deadline=None)
@given(st.lists(_NOISE, max_size=5), st.integers(0, 2**16 - 1), st.integers(1, 64))
def test_valid_frames_are_all_found_between_noise(noise, seed, chunk):
    rng = random.Random(seed)
    frames = [valid_frame(rng) for _ in range(len(noise) + 1)]
    stream = frames[0] + b"".join(nz + fr for nz, fr in zip(noise, frames[1:]))
    p = FrameParser()
    got = []
    for i in range(0, len(stream), chunk):
        got += p.feed(stream[i:i + chunk])
    assert got == [decode_frame(f) for f in frames]


def can_frames(n: int, seed: int, ids: list[int]):
    """n random frames for each id (random length 0..8, random bytes), interleaved."""
    rng = random.Random(seed)
    for _ in range(n):
        for i in ids:
            yield can.Message(arbitration_id=i, data=rng.randbytes(rng.randint(0, 8)), is_extended_id=False)


def fuzz_can(n: int, seed: int) -> dict:
    data = emulated_data("virtual")
    data["can"]["channel"] = f"fuzz-{next(_n)}"
    cfg = parse(data)
    emu = RigEmulator(cfg)
    link = CanLink(cfg.hw["can"], T)
    inv = VltInverter(link, None, cfg.hw["can"], cfg.hw["modbus"], "can", 400.0, 560.0, T)
    try:
        for k, msg in enumerate(can_frames(n, seed, [0x080, 0x100, 0x110, 0x180])):
            if msg.arbitration_id == 0x180:
                inv.tick = k
                inv._on_status(msg)
                st = inv._status
                assert st.u_dc >= 0.0 and isinstance(st.fault, bool)
            else:
                emu.handle(msg)
        return {"bad": emu.stats["bad_frames"] + inv.stats.get("bad_frames", 0), "syncs": emu.stats["syncs"]}
    finally:
        emu.close()
        link.close()


@pytest.mark.slow
def test_can_decoders_survive_1e5_frames_each():
    out = fuzz_can(100_000, seed=3)
    assert out["bad"] > 100_000 and out["syncs"] > 10_000


def test_can_decoders_survive_1500_frames_each():
    out = fuzz_can(1_500, seed=4)
    assert out["bad"] > 1_500 and out["syncs"] > 150
