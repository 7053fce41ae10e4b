"""Sensing of the mock rig: LEM current transducers (A.3), filtered voltage bridge (A.4), encoder (A.5).

Each sensor is sampled by the plant once per tick (``sample``) and then read through its HAL port
(``read``/``read_raw``), which only returns the cached sample, so reading is cheap and repeatable.

ADC (both analog chains): bipolar, ``adc_bits`` bits over +-``adc_range`` volts, signed integer
codes in [-2^(bits-1), 2^(bits-1) - 1], rounding to nearest, clipping at the ends. The defaults
(12 bits, +-10 V) are those of a DT28xx-class card; the thesis names the DT2829 but not its range.
Conversion back to SI uses the *nominal* scaling and the *calibrated* offset, so gain errors and
uncalibrated offsets show up in the measurement as they would on the rig.
"""

from __future__ import annotations

import functools
import math
import random

from numba.extending import register_jitable

SQRT3 = math.sqrt(3.0)
_H = 0.5 * SQRT3
TWO_PI = 2.0 * math.pi
_sqrt, _log, _cos, _sin = math.sqrt, math.log, math.cos, math.sin


def _triple(x: float | tuple[float, float, float] | list[float], name: str) -> tuple[float, float, float]:
    if isinstance(x, (int, float)):
        return (float(x),) * 3
    t = tuple(float(v) for v in x)
    if len(t) != 3:
        raise ValueError(f"{name} needs 3 per-phase values, got {len(t)}")
    return t  # type: ignore[return-value]


def gauss3(rng: random.Random) -> tuple[float, float, float]:
    """Three standard normals, exactly what three calls of ``rng.gauss(0.0, 1.0)`` return.

    This inlines CPython's `random.Random.gauss` (Box-Muller on ``rng.random()``, the spare value
    kept in ``rng.gauss_next``) and so shares its state and its sequence, at about a third of the
    cost of three method calls. tests/test_sensors.py checks the equality.
    """
    rnd = rng.random
    z = rng.gauss_next
    x2pi = rnd() * TWO_PI
    g2rad = _sqrt(-2.0 * _log(1.0 - rnd()))
    if z is None:
        n1, n2 = _cos(x2pi) * g2rad, _sin(x2pi) * g2rad
        x2pi = rnd() * TWO_PI
        g2rad = _sqrt(-2.0 * _log(1.0 - rnd()))
        rng.gauss_next = _sin(x2pi) * g2rad
        return n1, n2, _cos(x2pi) * g2rad
    rng.gauss_next = None
    return z, _cos(x2pi) * g2rad, _sin(x2pi) * g2rad


class _Adc:
    """Per-channel analog front end + ADC: v -> v (1+g) + offset + noise -> code -> SI value."""

    def __init__(
        self,
        gain: float,
        *,
        adc_bits: int,
        adc_range: float,
        gain_error: float | tuple[float, float, float],
        offset: float | tuple[float, float, float],
        offset_cal: float | tuple[float, float, float],
        noise_std: float,
        rng: random.Random,
    ) -> None:
        if int(adc_bits) != adc_bits or not 2 <= adc_bits <= 32:
            raise ValueError(f"adc_bits must be an integer in 2..32, got {adc_bits!r}")
        if not adc_range > 0 or not gain > 0 or not noise_std >= 0:
            raise ValueError("adc_range and the sensor gain must be > 0, noise_std >= 0")
        self.gain = float(gain)  # nominal volts at the ADC per SI unit
        self.adc_bits = int(adc_bits)
        self.adc_range = float(adc_range)
        self.lsb = 2.0 * adc_range / (1 << adc_bits)  # [V per code]
        self.code_min = -(1 << (adc_bits - 1))
        self.code_max = (1 << (adc_bits - 1)) - 1
        g = _triple(gain_error, "gain_error")
        self.gain_error = g
        self.offset = _triple(offset, "offset")
        self.noise_std = float(noise_std)
        self.rng = rng
        self._k = tuple(self.gain * (1.0 + gi) for gi in g)  # true volts per SI unit, per channel
        self.set_offset_cal(offset_cal)
        self.raw: tuple[int, int, int] = (0, 0, 0)
        self.value: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def set_offset_cal(self, offset_cal: float | tuple[float, float, float]) -> None:
        """Set the calibrated offsets [V at the ADC input] removed by the conversion to SI."""
        self.offset_cal = _triple(offset_cal, "offset_cal")
        self._pack()

    def _pack(self) -> None:
        # constants of `convert` in one tuple: one attribute lookup per sample
        k, off, oc, ginv = self._k, self.offset, self.offset_cal, 1.0 / self.gain
        self._c = (k[0], k[1], k[2], off[0], off[1], off[2], 1.0 / self.lsb, self.code_min,
                   self.code_max, self.lsb * ginv, oc[0] * ginv, oc[1] * ginv, oc[2] * ginv)  # fmt: skip

    def convert(self, a: float, b: float, c: float) -> None:
        """Sample the three channels' true values (SI) and store codes and SI readings."""
        noise = gauss3(self.rng) if self.noise_std > 0.0 else (0.0, 0.0, 0.0)
        ca, cb, cc, ya, yb, yc = adc_read(a, b, c, *noise, self.noise_std, *self._c)
        self.raw = (ca, cb, cc)
        self.value = (ya, yb, yc)

    def full_scale(self) -> float:
        """Largest measurable magnitude in SI units (nominal scaling)."""
        return self.adc_range / self.gain


class _AdcChannels:
    """Three channels behind one `_Adc`: the read-out shared by the current and voltage sensing."""

    adc: _Adc

    def set_offset_cal(self, offset_cal: float | tuple[float, float, float]) -> None:
        """Calibrated offsets [V at the ADC], e.g. the mean of the codes at zero times the LSB."""
        self.adc.set_offset_cal(offset_cal)

    def read(self) -> tuple[float, float, float]:
        return self.adc.value

    def read_raw(self) -> tuple[int, int, int]:
        return self.adc.raw


class CurrentSensors(_AdcChannels):
    """Three LEM closed-loop transducers (A.3): i -> i/turns -> burden resistor -> ADC (`PhaseSensorPort`).

    Defaults: turns ratio 1:1000 and a 500 Ohm burden give 0.5 V/A, so +-10 V spans +-20 A (the
    motor's rated peak is 5.1 A; starting transients reach about 3x that) with a 9.8 mA LSB at
    12 bits. Noise 2 mV rms at the ADC input = 4 mA rms.
    """

    def __init__(
        self,
        *,
        turns_ratio: float = 1000.0,
        burden: float = 500.0,
        adc_bits: int = 12,
        adc_range: float = 10.0,
        gain_error: float | tuple[float, float, float] = 0.0,
        offset: float | tuple[float, float, float] = 0.0,
        offset_cal: float | tuple[float, float, float] = 0.0,
        noise_std: float = 2e-3,
        rng: random.Random | None = None,
    ) -> None:
        if not turns_ratio > 0 or not burden > 0:
            raise ValueError("turns_ratio and burden must be > 0")
        self.turns_ratio = float(turns_ratio)
        self.burden = float(burden)
        self.adc = _Adc(burden / turns_ratio, adc_bits=adc_bits, adc_range=adc_range,
                        gain_error=gain_error, offset=offset, offset_cal=offset_cal,
                        noise_std=noise_std, rng=rng or random.Random(0))  # fmt: skip

    def sample(self, i_s: complex) -> None:
        """Sample the phase currents of the (zero-sequence-free) stator current vector i_s [A]."""
        re, h = i_s.real, _H * i_s.imag
        self.adc.convert(re, -0.5 * re + h, -0.5 * re - h)  # inverse of (3.17) with (3.1)



class VoltageSensors(_AdcChannels):
    """Star resistor bridge + 2nd-order 1 kHz low-pass + ADC (A.4) (`PhaseSensorPort`).

    The bridge's neutral is isolated like the stator's, so it measures phase-to-neutral voltages
    without zero sequence; the (identical) three filters therefore act on the space vector. The
    filter is H(s) = w0^2/(s^2 + 2 zeta w0 s + w0^2) with w0 = 2 pi f_c. The default
    zeta = 1/sqrt(2) (Butterworth) puts the -3 dB point at exactly f_c = 1 kHz, which is how we read
    the thesis' "cut-off frequency of 1 kHz"; zeta = 1 (critically damped) is possible too.
    Its input is the inverter's applied voltage, held over each period, so the zero-order-hold
    discretisation used here is exact.

    Defaults: divider 1/40 (+-400 V -> +-10 V; the linear-range peak is 560/sqrt(3) = 323 V),
    12-bit ADC (LSB 0.195 V), noise 2 mV rms at the ADC input = 80 mV at the motor.
    """

    def __init__(
        self,
        dt: float,
        *,
        divider_ratio: float = 1.0 / 40.0,
        f_c: float = 1000.0,
        zeta: float = 1.0 / math.sqrt(2.0),
        adc_bits: int = 12,
        adc_range: float = 10.0,
        gain_error: float | tuple[float, float, float] = 0.0,
        offset: float | tuple[float, float, float] = 0.0,
        offset_cal: float | tuple[float, float, float] = 0.0,
        noise_std: float = 2e-3,
        rng: random.Random | None = None,
    ) -> None:
        if not dt > 0 or not divider_ratio > 0 or not f_c > 0 or not zeta > 0:
            raise ValueError("dt, divider_ratio, f_c and zeta must be > 0")
        self.divider_ratio = float(divider_ratio)
        self.f_c = float(f_c)
        self.zeta = float(zeta)
        self.dt = float(dt)
        self.adc = _Adc(divider_ratio, adc_bits=adc_bits, adc_range=adc_range,
                        gain_error=gain_error, offset=offset, offset_cal=offset_cal,
                        noise_std=noise_std, rng=rng or random.Random(0))  # fmt: skip
        self._phi, self._gam = _zoh_second_order(2.0 * math.pi * f_c, zeta, dt)
        self.reset()

    def reset(self) -> None:
        self.y = 0j  # filter output (space vector) [V]
        self.dy = 0j  # its derivative [V/s]

    def advance(self, u_s: complex) -> None:
        """Run the filter over one period dt with u_s [V] held (exact ZOH discretisation)."""
        (p00, p01, p10, p11), (g0, g1) = self._phi, self._gam
        self.y, self.dy = filter_step(self.y, self.dy, u_s, p00, p01, p10, p11, g0, g1)

    def sample(self) -> None:
        """Sample the filtered phase voltages into the ADC."""
        y = self.y
        re, h = y.real, _H * y.imag
        self.adc.convert(re, -0.5 * re + h, -0.5 * re - h)

    def magnitude(self, f: float) -> float:
        """|H(j 2 pi f)| of the continuous filter."""
        w0, w = 2.0 * math.pi * self.f_c, 2.0 * math.pi * f
        return abs(w0**2 / complex(w0**2 - w**2, 2.0 * self.zeta * w0 * w))



@functools.lru_cache(maxsize=64)  # a pure function of three floats; scipy's expm is most of a plant's build time
def _zoh_second_order(w0: float, zeta: float, dt: float) -> tuple[tuple[float, ...], tuple[float, float]]:
    """Exact ZOH discretisation of x' = [[0,1],[-w0^2,-2 zeta w0]] x + [0, w0^2] u, y = x_0."""
    import numpy as np
    from scipy.linalg import expm

    m = np.zeros((3, 3))
    m[0, 1] = 1.0
    m[1, 0], m[1, 1], m[1, 2] = -w0 * w0, -2.0 * zeta * w0, w0 * w0
    e = expm(m * dt)
    phi = (float(e[0, 0]), float(e[0, 1]), float(e[1, 0]), float(e[1, 1]))
    return phi, (float(e[0, 2]), float(e[1, 2]))


class Encoder:
    """Incremental encoder with x4 quadrature decoding and an index channel (A.5) (`EncoderPort`).

    count = floor(theta_mech counts_per_rev/2 pi) mod modulus (the counter is zero at the
    power-up angle theta_mech = 0). The index mark lies at mechanical angle ``index_angle``; on each
    crossing (either direction) the counter value at the mark is latched; -1 before the first.

    Fault hooks: `inject_stuck` freezes the counter (lost counts stay lost when released) and
    `inject_jump` adds a permanent step of counts (e.g. noise on the A/B lines).
    """

    def __init__(self, *, lines: int = 1024, modulus: int = 1 << 16, index_angle: float = 0.0) -> None:
        if int(lines) != lines or lines < 1 or int(modulus) != modulus or modulus < 4 * lines:
            raise ValueError("lines must be a positive integer and modulus an integer >= 4*lines")
        self.lines = int(lines)
        self.counts_per_rev = 4 * self.lines
        self.modulus = int(modulus)
        self.index_angle = float(index_angle)
        self._scale = self.counts_per_rev / TWO_PI
        self.reset()

    def reset(self, theta_mech: float = 0.0) -> None:
        self._raw = math.floor(theta_mech * self._scale)  # unwrapped ideal count
        self._rev = math.floor((theta_mech - self.index_angle) / TWO_PI)
        self._offset = 0  # lost/added counts (stuck, jump)
        self._stuck = False
        self._value = (self._raw % self.modulus, -1)

    def inject_stuck(self, stuck: bool = True) -> None:
        """Freeze (True) or release (False) the counter."""
        self._stuck = stuck

    def inject_jump(self, counts: int) -> None:
        """Add ``counts`` to the counter from now on."""
        self._offset += int(counts)
        self._value = ((self._raw + self._offset) % self.modulus, self._value[1])

    def sample(self, theta_mech: float) -> None:
        """Update counter and index latch for the shaft angle theta_mech [rad]."""
        self._raw, self._rev, self._offset, count, index = encoder_sample(
            theta_mech, self._scale, self.index_angle, self.counts_per_rev, self.modulus, self._raw, self._rev,
            self._offset, self._stuck, *self._value)  # fmt: skip
        self._value = (count, index)

    def read(self) -> tuple[int, int]:
        return self._value


def filter_step(y: complex, dy: complex, u_s: complex, p00: float, p01: float, p10: float, p11: float, g0: float,
                g1: float) -> tuple[complex, complex]:  # fmt: skip
    """The voltage filter's state (y, dy/dt) after one period with u_s [V] held: [y, dy] <- Phi [y, dy] + Gamma u_s
    (`VoltageSensors`' exact ZOH). Plain Python on complex numbers that numba compiles: the compiled plant
    (mock_hw.compiled) calls this one."""
    return p00 * y + p01 * dy + g0 * u_s, p10 * y + p11 * dy + g1 * u_s


def encoder_sample(theta: float, scale: float, index_angle: float, counts_per_rev: int, modulus: int, raw0: int,
                   rev0: int, offset: int, stuck: bool, count: int, index: int
                   ) -> tuple[int, int, int, int, int]:  # fmt: skip
    """`Encoder.sample` at the shaft angle theta [rad] from the previous unwrapped count raw0, revolution rev0 (of
    the index mark), offset (lost or added counts), counter and index latch: (raw, rev, offset, count, index).
    Stuck: the counter does not move and the counts are lost. Plain Python that numba compiles: the compiled plant
    (mock_hw.compiled) calls this one."""
    raw = math.floor(theta * scale)
    rev = math.floor((theta - index_angle) / TWO_PI)
    if stuck:
        return raw, rev, offset - (raw - raw0), count, index
    if rev != rev0:  # passed the index mark at index_angle + 2 pi n
        n = rev if rev > rev0 else rev0
        index = (math.floor((index_angle / TWO_PI + n) * counts_per_rev) + offset) % modulus
    return raw, rev, offset, (raw + offset) % modulus, index


@register_jitable  # called from Python as it is, and compiled into adc_read's kernel
def _code(v: float, inv_lsb: float, lo: int, hi: int) -> int:
    c = math.floor(v * inv_lsb + 0.5)  # round to nearest code, then clip
    return hi if c > hi else (lo if c < lo else c)


def adc_read(a: float, b: float, c: float, na: float, nb: float, nc: float, noise_std: float, ka: float, kb: float,
             kc: float, oa: float, ob: float, oc: float, inv_lsb: float, lo: int, hi: int, q: float, za: float,
             zb: float, zc: float) -> tuple[int, int, int, float, float, float]:  # fmt: skip
    """`_Adc.convert` of three channels' true values a, b, c (SI) with the standard normal draws na, nb, nc: volts
    at the ADC v (1 + gain error) + offset + noise, the codes (rounded, clipped to lo..hi) and the readings in SI with
    the nominal gain and the calibrated offset (q = lsb/gain, z = offset_cal/gain): (codes, readings). The
    constants are `_Adc._c`'s. Plain Python that numba compiles: the compiled plant (mock_hw.compiled) calls this
    one with its own Mersenne Twister's draws."""
    va, vb, vc = a * ka + oa, b * kb + ob, c * kc + oc
    if noise_std > 0.0:
        va += na * noise_std
        vb += nb * noise_std
        vc += nc * noise_std
    ca, cb, cc = _code(va, inv_lsb, lo, hi), _code(vb, inv_lsb, lo, hi), _code(vc, inv_lsb, lo, hi)
    return ca, cb, cc, ca * q - za, cb * q - zb, cc * q - zc
