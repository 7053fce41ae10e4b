"""Sensors of the mock rig (mock_hw.sensors): LEM currents, filtered voltages, encoder."""

from __future__ import annotations

import cmath
import math
import random
import statistics

import pytest

from bench.hal import Command, space_vector
from bench.params import T_S_DEFAULT
from mock_hw.plant import EncoderConfig, MockConfig, MotorConfig, VoltagesConfig, make_mock_rig
from mock_hw.sensors import CurrentSensors, Encoder, VoltageSensors, gauss3

DT = T_S_DEFAULT
TWO_PI = 2.0 * math.pi


# --- noise -------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 12345])
def test_gauss3_is_exactly_random_gauss(seed):
    a, b = random.Random(seed), random.Random(seed)
    for k in range(500):
        assert gauss3(a) == (b.gauss(), b.gauss(), b.gauss())
        if k % 7 == 0:  # interleaved direct calls keep the streams aligned
            assert a.gauss() == b.gauss()


def test_noise_is_seeded_and_has_the_configured_std():
    def readings(seed: int) -> list[tuple[float, float, float]]:
        cs = CurrentSensors(noise_std=0.02, rng=random.Random(seed))
        out = []
        for _ in range(6000):
            cs.sample(0j)
            out.append(cs.read())
        return out

    r1, r2, r3 = readings(7), readings(7), readings(8)
    assert r1 == r2
    assert r1 != r3
    sd_si = 0.02 / 0.5  # 20 mV at 0.5 V/A = 40 mA
    for ch in range(3):
        xs = [r[ch] for r in r1]
        assert statistics.pstdev(xs) == pytest.approx(sd_si, rel=0.05)
        assert abs(statistics.fmean(xs)) < 5 * sd_si / math.sqrt(len(xs))  # unbiased rounding


# --- current channels --------------------------------------------------------------------------
def test_current_scaling_quantisation_and_phase_relation():
    cs = CurrentSensors(noise_std=0.0)
    lsb_a = cs.adc.lsb / (cs.burden / cs.turns_ratio)  # amperes per code
    assert lsb_a == pytest.approx(40.0 / 4096)  # +-10 V / (0.5 V/A), 12 bits
    for i_s in (0j, 1.234 - 0.5j, -3.3 + 4.1j, 7.0 + 0j):
        cs.sample(i_s)
        ia, ib, ic = cs.read()
        raw = cs.read_raw()
        assert all(isinstance(c, int) for c in raw)
        # codes -> amperes on the nominal scale
        assert (ia, ib, ic) == pytest.approx(tuple(c * lsb_a for c in raw), abs=1e-12)
        true = (i_s.real, -0.5 * i_s.real + 0.5 * math.sqrt(3) * i_s.imag,
                -0.5 * i_s.real - 0.5 * math.sqrt(3) * i_s.imag)  # fmt: skip
        for got, want in zip((ia, ib, ic), true):
            assert abs(got - want) <= 0.5 * lsb_a + 1e-12  # rounding to nearest code
        assert abs(space_vector(ia, ib, ic) - i_s) <= lsb_a


def test_current_adc_clips_at_full_scale():
    cs = CurrentSensors(noise_std=0.0)
    cs.sample(30.0 + 0j)  # phase a = 30 A, b = c = -15 A; range is +-20 A
    raw = cs.read_raw()
    assert raw[0] == 2047 and raw[1] == raw[2] == round(-15.0 * 0.5 / (20.0 / 4096))
    assert cs.read()[0] == pytest.approx(2047 * 40.0 / 4096)
    cs.sample(-50.0 + 0j)
    assert cs.read_raw()[0] == -2048
    assert cs.read()[0] == pytest.approx(-20.0)


def test_uncalibrated_offset_shows_and_calibration_removes_it():
    off = (0.05, -0.02, 0.0)  # volts at the ADC = 0.1 A, -0.04 A, 0 A
    cs = CurrentSensors(noise_std=0.0, offset=off)
    cs.sample(0j)
    lsb_a = 40.0 / 4096
    for got, o in zip(cs.read(), off):
        assert got == pytest.approx(o / 0.5, abs=0.5 * lsb_a)
    assert abs(cs.read()[0] - 0.1) < 0.5 * lsb_a and cs.read()[0] > 0.09
    cs.set_offset_cal(off)
    cs.sample(0j)
    assert all(abs(x) <= 0.5 * lsb_a for x in cs.read())
    cs2 = CurrentSensors(noise_std=0.0, offset=off, offset_cal=off)
    cs2.sample(2.0 + 0j)
    assert cs2.read()[0] == pytest.approx(2.0, abs=0.5 * lsb_a)


def test_gain_error_scales_the_reading():
    cs = CurrentSensors(noise_std=0.0, gain_error=(0.02, 0.0, -0.03), adc_bits=16)
    cs.sample(10.0 + 0j)  # a = 10, b = c = -5
    a, b, c = cs.read()
    assert a == pytest.approx(10.2, abs=1e-3)
    assert b == pytest.approx(-5.0, abs=1e-3)
    assert c == pytest.approx(-4.85, abs=1e-3)


# --- voltage channels --------------------------------------------------------------------------
def _filter_gain(f_sig: float, zeta: float) -> float:
    vs = VoltageSensors(1e-6, zeta=zeta, noise_std=0.0)
    w = TWO_PI * f_sig
    n = 20000  # 20 ms: many filter time constants
    for k in range(n):
        vs.advance(cmath.exp(1j * w * (k + 0.5) * 1e-6))
    return abs(vs.y)


def test_voltage_filter_is_minus_3db_at_1khz():
    g = _filter_gain(1000.0, 1.0 / math.sqrt(2.0))
    assert 20 * math.log10(g) == pytest.approx(-3.01, abs=0.02)
    assert _filter_gain(100.0, 1.0 / math.sqrt(2.0)) == pytest.approx(1.0, abs=1e-3)  # passband
    assert _filter_gain(10e3, 1.0 / math.sqrt(2.0)) == pytest.approx(0.01, rel=0.02)  # -40 dB/dec
    # critically damped alternative: |H| = 1/(2 zeta) = 0.5 at f_c
    assert _filter_gain(1000.0, 1.0) == pytest.approx(0.5, abs=1e-3)


def test_voltage_filter_discretisation_is_exact_at_3khz():
    vs = VoltageSensors(DT, noise_std=0.0)
    z, w0 = vs.zeta, TWO_PI * vs.f_c
    wd = w0 * math.sqrt(1 - z * z)
    for k in range(1, 30):
        vs.advance(100.0 + 0j)
        t = k * DT
        step = 1 - math.exp(-z * w0 * t) * (math.cos(wd * t) + z / math.sqrt(1 - z * z) * math.sin(wd * t))
        assert vs.y.real == pytest.approx(100.0 * step, abs=1e-9)


def test_voltage_channel_end_to_end_in_steady_dc():
    cfg = MockConfig(voltages=VoltagesConfig(noise_std=0.0))
    rig = make_mock_rig(cfg)
    with rig:
        u = 40.0 - 25.0j  # DC vector: the filter passes it unchanged
        for k in range(60):
            m = rig.read(k * DT)
            rig.write(Command(u_s_ref=u, enable=True))
        lsb_v = 20.0 / 4096 / (1.0 / 40.0)
        assert abs(m.u_s - u) < lsb_v
        assert all(isinstance(c, int) for c in m.raw_u)
        assert m.u_s == pytest.approx(complex(*rig.truth.sample()[10:12]), abs=lsb_v)


# --- encoder -----------------------------------------------------------------------------------
def test_encoder_counts_per_rev_and_wrap():
    enc = Encoder()
    assert enc.counts_per_rev == 4096 and enc.modulus == 65536
    q = TWO_PI / 4096
    enc.sample(TWO_PI + 0.5 * q)  # floor at the line, not round
    assert enc.read()[0] == 4096
    enc.sample(1000.5 * q)
    assert enc.read()[0] == 1000
    enc.sample(-0.5 * q)
    assert enc.read()[0] == 65535  # wraps downwards
    enc.sample(16 * TWO_PI + 5.5 * q)  # 65536 + 5
    assert enc.read()[0] == 5
    small = Encoder(lines=1024, modulus=10000)
    small.sample(3 * TWO_PI + 0.5 * q)
    assert small.read()[0] == 12288 % 10000


def test_encoder_index_latch_both_directions():
    enc = Encoder(index_angle=1.0)
    q = TWO_PI / 4096
    assert enc.read()[1] == -1
    th = 0.0
    for _ in range(2000):  # forward to 1.0 + 2 pi + a bit
        th += 0.004
        enc.sample(th)
        if th < 1.0:
            assert enc.read()[1] == -1
    mark0 = math.floor(1.0 / q)
    mark1 = math.floor((1.0 + TWO_PI) / q)
    assert th > 1.0 + TWO_PI and enc.read()[1] == mark1
    for _ in range(1000):  # back below the mark at 1 + 2 pi: it latches the same mark
        th -= 0.004
        enc.sample(th)
    assert 1.0 < th < 1.0 + TWO_PI and enc.read()[1] == mark1
    for _ in range(800):
        th -= 0.004
        enc.sample(th)
    assert th < 1.0 and enc.read()[1] == mark0


def test_encoder_speed_resolution_at_3khz():
    """One-sample count difference at 3 kHz: steps of 2 pi/4096*3000 = 4.6 rad/s (A.5)."""
    w_mech = 100.0
    cfg = MockConfig(motor=MotorConfig(hold_speed=True, omega_r0=2 * w_mech))
    rig = make_mock_rig(cfg)
    with rig:
        prev = rig.read(0.0).enc_count
        speeds = []
        for k in range(1, 3001):
            c = rig.read(k * DT).enc_count
            speeds.append(((c - prev) % 65536) * TWO_PI / 4096 / DT)  # wrap-aware difference
            prev = c
    levels = sorted(set(round(s, 9) for s in speeds))
    q = TWO_PI / 4096 * 3000
    assert q == pytest.approx(4.6, abs=0.01)
    assert len(levels) == 2 and levels[1] - levels[0] == pytest.approx(q)
    assert levels[0] < w_mech < levels[1]
    assert statistics.fmean(speeds) == pytest.approx(w_mech, abs=q / 3000 * 2)  # averaging helps
    assert rig.read(1.0 + 2 * DT).enc_index >= 0  # 15 revolutions passed the index


def test_encoder_stuck_and_jump_faults():
    enc = Encoder()
    q = TWO_PI / 4096
    enc.sample(100.5 * q)
    enc.inject_stuck(True)
    enc.sample(300.5 * q)
    assert enc.read()[0] == 100
    enc.inject_stuck(False)
    enc.sample(310.5 * q)
    assert enc.read()[0] == 110  # the 200 counts while stuck are lost
    enc.inject_jump(-50)
    assert enc.read()[0] == 60
    enc.sample(311.5 * q)
    assert enc.read()[0] == 61
    enc.reset()
    assert enc.read() == (0, -1)


def test_encoder_config_in_plant():
    rig = make_mock_rig(MockConfig(encoder=EncoderConfig(lines=500, modulus=4096)))
    assert rig.encoder.counts_per_rev == 2000 and rig.encoder.modulus == 4096
