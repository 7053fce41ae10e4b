"""Compiled plant step (numba): the mock plant's periods and sensor sampling in one call (issue 13).

`advance` runs `mock_hw.plant.MockPlant.acquire` of the plain-Python engine: per period the inverter's voltage
limit and voltage error (dead time, on-state drop, soft knee), the DC load's lag, the winding temperatures and R(T)
(`mock_hw.thermal`), the motor's RK4 step of (3.41)+(3.37) (or the coast (4.15); or the saturated flux-state model,
`mock_hw.motor.SaturatedInductionMotor`) and the voltage filter; then the LEM currents, the filtered voltages (ADC
with Gaussian noise) and the encoder.

The parts' kernels are written once, in the part's module, as plain Python that numba compiles, and both engines
call them: the voltage error (`mock_hw.inverter.voltage_error`), the lag (`mock_hw.load.lag_step`), the thermal
step and the copper losses (`mock_hw.thermal`), the linear motor's RK4 steps (`mock_hw.motor.rk4`, `rk4_coast`), the
saturated motor's step with its main-flux Newton iteration (`mock_hw.motor.sat_step`), the voltage filter
(`mock_hw.sensors.filter_step`) and the encoder (`mock_hw.sensors.encoder_sample`). They are written on complex
numbers, and numba's complex arithmetic is CPython 3.11's (a float operand is ``complex(x, 0.0)``, so ``a * z`` is
the full complex product). The ADC conversion (`mock_hw.sensors.adc_read`) takes its standard normal draws as
arguments: the Python engine draws them from `random.Random`, this module from its own copy of that generator
(below). The trajectories agree to the last bit (tests/test_compiled_plant.py).

State: one contiguous float64 buffer; its tail is viewed as int64 (counters, flags and the two
Mersenne-Twister states), so a tick passes a single array to the compiled code. The Python objects
of the plant stay: commands (inverter references, enable, faults, load torque) are their plain
attributes, read once per `acquire`; state attributes (``motor.i_s``, ``load.m_L``, ...) are
properties on the buffer (the `*View` classes here), so tests, tools and resets see and set the
state as before.

Noise: the sensors' `random.Random` streams are Mersenne Twister MT19937 with CPython's
``random()`` = (a*2^26 + b)/2^53 (a, b: 27 and 26 bits of two outputs) and Box-Muller `gauss`
with ``gauss_next``. MT19937 is written out here (not numba's own generator) to reproduce
CPython's streams bit for bit: the state is loaded from ``rng.getstate()`` and written back with
``rng.setstate()`` whenever Python code asks for ``adc.rng``.
"""

from __future__ import annotations

import math
import random
from dataclasses import replace

import numpy as np
from numba import njit, types

from bench.cpython_arith import cmul as _cmul, cquot as _cquot, entry, fmul as _fmul  # noqa: F401 (entry: plant.py)
from bench.jit_cache import compile_fixed, drop_stale
from bench.params import MotorParams
from mock_hw.inverter import SQRT3, voltage_error
from mock_hw.load import DcLoadDrive, lag_coefficients, lag_step
from mock_hw.motor import InductionMotor, SaturatedInductionMotor, Saturation, rk4, rk4_coast, sat_step
from mock_hw.sensors import Encoder, VoltageSensors, _Adc, adc_read, encoder_sample, filter_step
from mock_hw.thermal import ALPHA_AL, ALPHA_CU, ThermalModel, copper_loss, resistance, thermal_step

TWO_PI = 2.0 * math.pi  # as in mock_hw.sensors
_H = 0.5 * SQRT3

# --- buffer layout ------------------------------------------------------------------------------
# float slots
(IS_RE, IS_IM, IM_RE, IM_IM, W, TH, US_RE, US_IM, MOT_ML,  # motor state (and inputs of the last step)
 ML, LOAD_E, LOAD_MEAN,  # DC load: output torque, lag coefficients for h = dt
 Y_RE, Y_IM, DY_RE, DY_IM, P00, P01, P10, P11, G0, G1,  # voltage filter state and ZOH matrices
 A11, A12, A12W, B1, A21, KT, ZPJ, ZPI, BV, MC, WEI, LMP, LM, ZP, DT,  # motor coefficients, dt
 DEAD, FPWM, VON_A, VON_B, VON_C, IKNEE, ENC_SCALE, ENC_IANG,  # inverter voltage error, encoder
 R_S, R_R, RRP_C, LS_P, L_R, LMR,  # the motor's resistances and what its coefficients need of them
 T_S, T_R, T_AMB, TP00, TP01, TP10, TP11, TG00, TG01, TG10, TG11, TR_S20, TR_R20, TR_S, TR_R,  # thermal
 PS_RE, PS_IM, PR_RE, PR_IM, PM_RE, PM_IM, SAT_X, GS, GR, L0I, PSI_INV, SAT_A, LM0, PSI_SAT,  # saturated motor
 ) = range(80)  # fmt: skip
ADC_I = 80  # currents' ADC: 13 constants of `_Adc._c`, noise_std, gauss_next value
ADC_U = ADC_I + 15  # voltages' ADC
NF = ADC_U + 15  # float slots
ADC_NOISE, ADC_GNEXT = 13, 14
# int slots (offsets into the int64 view of buf[NF:])
(COAST, HOLD, SUBSTEPS, ENC_RAW, ENC_REV, ENC_OFF, ENC_STUCK, ENC_CNT, ENC_IDX, ENC_CPR, ENC_MOD,
 GN_I, GN_U, THERMAL, SAT) = range(15)  # fmt: skip  (GN_*: 1 if the stream holds a gauss_next; THERMAL, SAT: on)
MT_I = 16  # currents' MT19937: 624 words, then the index
MT_U = MT_I + 625
NI = MT_U + 625
N_BUF = NF + NI


def new_buffer() -> np.ndarray:
    """A zeroed state buffer (float64, C-contiguous)."""
    return np.zeros(N_BUF)


def int_view(buf: np.ndarray) -> np.ndarray:
    return buf[NF:].view(np.int64)


# --- MT19937 and gauss, as CPython's _randommodule.c and random.gauss ------------------------------
@njit
def _genrand(iv, base):
    mt_n, mt_m = 624, 397
    idx = iv[base + mt_n]
    if idx >= mt_n:
        for kk in range(mt_n - mt_m):
            y = (iv[base + kk] & 0x80000000) | (iv[base + kk + 1] & 0x7FFFFFFF)
            iv[base + kk] = iv[base + kk + mt_m] ^ (y >> 1) ^ (0x9908B0DF if y & 1 else 0)
        for kk in range(mt_n - mt_m, mt_n - 1):
            y = (iv[base + kk] & 0x80000000) | (iv[base + kk + 1] & 0x7FFFFFFF)
            iv[base + kk] = iv[base + kk + mt_m - mt_n] ^ (y >> 1) ^ (0x9908B0DF if y & 1 else 0)
        y = (iv[base + mt_n - 1] & 0x80000000) | (iv[base] & 0x7FFFFFFF)
        iv[base + mt_n - 1] = iv[base + mt_m - 1] ^ (y >> 1) ^ (0x9908B0DF if y & 1 else 0)
        idx = 0
    y = iv[base + idx]
    iv[base + mt_n] = idx + 1
    y ^= y >> 11
    y ^= (y << 7) & 0x9D2C5680
    y ^= (y << 15) & 0xEFC60000
    y ^= y >> 18
    return y


@njit
def _random(iv, base):
    a = _genrand(iv, base) >> 5
    b = _genrand(iv, base) >> 6
    return (a * 67108864.0 + b) * (1.0 / 9007199254740992.0)


@njit
def _gauss3(x, iv, adc, gn, mt):
    # mock_hw.sensors.gauss3 (CPython's Box-Muller gauss with gauss_next), same draw order
    x2pi = _random(iv, mt) * TWO_PI
    g2rad = math.sqrt(-2.0 * math.log(1.0 - _random(iv, mt)))
    if iv[gn] == 0:
        n1, n2 = math.cos(x2pi) * g2rad, math.sin(x2pi) * g2rad
        x2pi = _random(iv, mt) * TWO_PI
        g2rad = math.sqrt(-2.0 * math.log(1.0 - _random(iv, mt)))
        x[adc + ADC_GNEXT] = math.sin(x2pi) * g2rad
        iv[gn] = 1
        return n1, n2, math.cos(x2pi) * g2rad
    iv[gn] = 0
    return x[adc + ADC_GNEXT], math.cos(x2pi) * g2rad, math.sin(x2pi) * g2rad


@njit
def _convert(x, iv, adc, gn, mt, a, b, c):
    # _Adc.convert (mock_hw.sensors.adc_read) with this Mersenne Twister's draws
    s = x[adc + ADC_NOISE]
    na = nb = nc = 0.0
    if s > 0.0:
        na, nb, nc = _gauss3(x, iv, adc, gn, mt)
    ca, cb, cc, ya, yb, yc = _adc_read(a, b, c, na, nb, nc, s, x[adc], x[adc + 1], x[adc + 2], x[adc + 3], x[adc + 4],
                                       x[adc + 5], x[adc + 6], int(x[adc + 7]), int(x[adc + 8]), x[adc + 9],
                                       x[adc + 10], x[adc + 11], x[adc + 12])  # fmt: skip
    return (ya, yb, yc), (ca, cb, cc)


# the parts' kernels, written once in their modules
_voltage_error = njit(voltage_error)
_lag_step = njit(lag_step)
_thermal_step = njit(thermal_step)
_copper_loss = njit(copper_loss)
_resistance = njit(resistance)
_rk4_kernel = njit(rk4)
_rk4_coast_kernel = njit(rk4_coast)
_filter_step = njit(filter_step)
_sat_step_kernel = njit(sat_step)
_encoder_sample = njit(encoder_sample)
_adc_read = njit(adc_read)


# --- one period ------------------------------------------------------------------------------------
@njit
def _latch(x, ur, ui, on, u_dc):
    # Inverter.latch after the pipeline: SVPWM limit |u| <= u_dc/sqrt(3), then the voltage error
    if not on:
        return 0.0, 0.0
    lim = u_dc / SQRT3
    mag = math.hypot(ur, ui)  # abs(complex) is hypot in CPython
    if mag > lim:
        ur, ui = _cmul(ur, ui, lim / mag, 0.0)
    va, vb, vc = x[VON_A], x[VON_B], x[VON_C]
    if x[DEAD] > 0.0 or va != 0.0 or vb != 0.0 or vc != 0.0:  # Inverter.voltage_error, i_s at the period start
        er, ei = _voltage_error(x[DEAD] * x[FPWM] * u_dc, va, vb, vc, x[IKNEE], x[IS_RE], x[IS_IM])
        ur, ui = ur + er, ui + ei
    return ur, ui


@njit
def _rk4(x, hold, ur, ui, m_L, h):
    # InductionMotor._rk4: classic RK4 of (3.41)+(3.37), u and m_L held (mock_hw.motor.rk4)
    i_s, i_m, x[W], x[TH] = _rk4_kernel(complex(x[IS_RE], x[IS_IM]), complex(x[IM_RE], x[IM_IM]), x[W], x[TH],
                                        complex(ur, ui), m_L, h, hold, x[A11], x[A12], x[A12W], x[A21], x[B1], x[KT],
                                        x[ZPJ], x[ZPI], x[BV], x[MC], x[WEI])  # fmt: skip
    x[IS_RE], x[IS_IM], x[IM_RE], x[IM_IM] = i_s.real, i_s.imag, i_m.real, i_m.imag


@njit
def _rk4_coast(x, hold, m_L, h):
    # InductionMotor._rk4_coast: i_s = 0, (4.15), m_e = 0 (mock_hw.motor.rk4_coast)
    i_m, x[W], x[TH] = _rk4_coast_kernel(complex(x[IM_RE], x[IM_IM]), x[W], x[TH], m_L, h, hold, x[A21], x[ZPJ],
                                         x[ZPI], x[BV], x[MC], x[WEI])  # fmt: skip
    x[IM_RE], x[IM_IM] = i_m.real, i_m.imag


@njit
def _thermal(x, sat):
    # ThermalModel.advance with InductionMotor.winding_losses at the period start
    sr, si = x[IS_RE], x[IS_IM]
    if sat:  # SaturatedInductionMotor.i_rs = (psi_r - psi_m)/L_rs
        rr, ri = _fmul(x[GR], x[PR_RE] - x[PM_RE], x[PR_IM] - x[PM_IM])
    else:  # i_rs = (i_m - i_s) L_m/L_r (3.39)
        rr, ri = _fmul(x[LMR], x[IM_RE] - sr, x[IM_IM] - si)
    p_s, p_r = _copper_loss(x[R_S], sr, si), _copper_loss(x[R_R], rr, ri)
    x[T_S], x[T_R] = _thermal_step(x[T_AMB], x[T_S], x[T_R], x[TP00], x[TP01], x[TP10], x[TP11], x[TG00], x[TG01],
                                   x[TG10], x[TG11], p_s, p_r)  # fmt: skip
    x[TR_S] = _resistance(x[TR_S20], ALPHA_CU, x[T_S])
    x[TR_R] = _resistance(x[TR_R20], ALPHA_AL, x[T_R])


@njit
def _set_resistances(x, r_s, r_r):
    # InductionMotor.set_resistances: the coefficients of (3.41) that depend on R_s, R_r
    x[R_S], x[R_R] = r_s, r_r
    rrp = x[RRP_C] * r_r  # R'_r = (L_m/L_r)^2 R_r
    x[A11] = -(r_s + rrp) / x[LS_P]
    x[A12] = rrp / x[LS_P]
    x[A21] = r_r / x[L_R]


# --- the saturated motor (mock_hw.motor.SaturatedInductionMotor): its kernel, mock_hw.motor.sat_step ----------
@njit
def _sat_step(x, iv, coast, hold, ur, ui, m_L, h):
    ps, pr, pm, i_s, i_m, x[W], x[TH], u_s, x[SAT_X] = _sat_step_kernel(
        complex(x[PS_RE], x[PS_IM]), complex(x[PR_RE], x[PR_IM]), x[W], x[TH], complex(ur, ui), m_L, h, iv[SUBSTEPS],
        coast, hold, x[SAT_X], x[LM], x[GS], x[GR], x[R_S], x[R_R], x[ZP], x[ZPI], x[ZPJ], x[BV], x[MC], x[WEI],
        x[L0I], x[PSI_INV], x[SAT_A])  # fmt: skip
    x[PS_RE], x[PS_IM], x[PR_RE], x[PR_IM], x[PM_RE], x[PM_IM] = ps.real, ps.imag, pr.real, pr.imag, pm.real, pm.imag
    x[IS_RE], x[IS_IM], x[IM_RE], x[IM_IM] = i_s.real, i_s.imag, i_m.real, i_m.imag
    x[US_RE], x[US_IM] = u_s.real, u_s.imag


@njit
def _period(x, iv, ur, ui, on, u_dc, m_L_ref):
    ur, ui = _latch(x, ur, ui, on, u_dc)  # 1. inverter (one-sample pipeline done by the caller)
    # 2. DcLoadDrive.advance: exact lag, mean torque over the period
    x[ML], m_L = _lag_step(m_L_ref, x[ML], x[LOAD_E], x[LOAD_MEAN])
    thermal = iv[THERMAL] != 0
    if thermal:  # 3. the winding temperatures with the losses at the period start
        _thermal(x, iv[SAT] != 0)
    # 3. InductionMotor.step with substeps
    h = x[DT]
    n = iv[SUBSTEPS]
    hs = h / n
    hold = iv[HOLD] != 0
    if iv[SAT]:
        iv[COAST] = 0 if on else 1
        _sat_step(x, iv, not on, hold, ur, ui, m_L, h)
    elif not on:
        iv[COAST] = 1
        m0r, m0i = x[IM_RE], x[IM_IM]
        for _ in range(n):
            _rk4_coast(x, hold, m_L, hs)
        x[IS_RE], x[IS_IM] = 0.0, 0.0
        # back-EMF L'_m (i_m - i_m0)/h: float * complex, then complex / float (_Py_c_quot)
        t, u = _fmul(x[LMP], x[IM_RE] - m0r, x[IM_IM] - m0i)
        x[US_RE], x[US_IM] = _cquot(t, u, h, 0.0)
    else:
        iv[COAST] = 0
        for _ in range(n):
            _rk4(x, hold, ur, ui, m_L, hs)
        x[US_RE], x[US_IM] = ur, ui
    x[MOT_ML] = m_L
    if thermal:  # R(T) from the end of the period on
        _set_resistances(x, x[TR_S], x[TR_R])
    # 4. VoltageSensors.advance: exact ZOH of the filter with u_s held
    y, dy = _filter_step(complex(x[Y_RE], x[Y_IM]), complex(x[DY_RE], x[DY_IM]), complex(x[US_RE], x[US_IM]),
                         x[P00], x[P01], x[P10], x[P11], x[G0], x[G1])  # fmt: skip
    x[Y_RE], x[Y_IM], x[DY_RE], x[DY_IM] = y.real, y.imag, dy.real, dy.imag
    return ur, ui


@njit
def _encoder(x, iv):
    # Encoder.sample (mock_hw.sensors.encoder_sample)
    iv[ENC_RAW], iv[ENC_REV], iv[ENC_OFF], iv[ENC_CNT], iv[ENC_IDX] = _encoder_sample(
        x[TH], x[ENC_SCALE], x[ENC_IANG], iv[ENC_CPR], iv[ENC_MOD], iv[ENC_RAW], iv[ENC_REV], iv[ENC_OFF],
        iv[ENC_STUCK] != 0, iv[ENC_CNT], iv[ENC_IDX])  # fmt: skip
    return iv[ENC_CNT], iv[ENC_IDX]


_F3 = types.UniTuple(types.float64, 3)
_I3 = types.UniTuple(types.int64, 3)
_SIG = types.Tuple((_F3, _I3, _F3, _I3, types.UniTuple(types.int64, 2), types.complex128))(
    types.float64[::1], types.int64, types.complex128, types.boolean, types.complex128, types.boolean,
    types.float64, types.float64)  # fmt: skip


@njit(cache=True)  # (compiled for _SIG only, below: bench.jit_cache.compile_fixed)
def advance(buf, m, u1, on1, u2, on2, u_dc, m_L_ref):
    """Integrate m >= 0 periods (the first with (u1, on1), the others with (u2, on2): the inverter's
    pipeline outputs), then sample the sensors. Returns (current values, codes, voltage values, codes,
    encoder (count, index), voltage applied over the last period)."""
    x = buf[:NF]
    iv = buf[NF:].view(np.int64)
    ur, ui = 0.0, 0.0
    for j in range(m):
        if j == 0:
            ur, ui = _period(x, iv, u1.real, u1.imag, on1, u_dc, m_L_ref)
        else:
            ur, ui = _period(x, iv, u2.real, u2.imag, on2, u_dc, m_L_ref)
    # CurrentSensors.sample: phase currents of i_s, inverse of (3.17) with (3.1)
    re, h = x[IS_RE], _H * x[IS_IM]
    vi, ci = _convert(x, iv, ADC_I, GN_I, MT_I, re, -0.5 * re + h, -0.5 * re - h)
    # VoltageSensors.sample: filtered phase voltages
    re, h = x[Y_RE], _H * x[Y_IM]
    vu, cu = _convert(x, iv, ADC_U, GN_U, MT_U, re, -0.5 * re + h, -0.5 * re - h)
    return vi, ci, vu, cu, _encoder(x, iv), complex(ur, ui)


_INTEGRATE_SIG = types.complex128(types.float64[::1], types.complex128, types.boolean, types.float64, types.float64)


@njit(cache=True)  # (compiled for _INTEGRATE_SIG only, below)
def integrate(buf, u, on, u_dc, m_L_ref):
    """Integrate one period with (u, on), no sampling (a period the real-time loop skipped: the plant
    takes the drive's ride-through reference period by period). Returns the voltage applied over it."""
    ur, ui = _period(buf[:NF], buf[NF:].view(np.int64), u.real, u.imag, on, u_dc, m_L_ref)
    return complex(ur, ui)


_TRUTH_SIG = types.UniTuple(types.float64, 13)(types.float64[::1])  # (the thermal fields: ThermalView)
_TRUTH_SAT_SIG = types.UniTuple(types.float64, 15)(types.float64[::1])


@njit(cache=True)  # (compiled for _TRUTH_SIG only, below)
def truth(buf):
    """MockPlant.sample of the state in buf (TRUTH_FIELDS)."""
    x = buf[:NF]
    sr, si, mr, mi, ur, ui, lm = x[IS_RE], x[IS_IM], x[IM_RE], x[IM_IM], x[US_RE], x[US_IM], x[LM]
    return (sr, si, mr, mi, lm * mr, lm * mi, x[W], x[ZP] * x[TH], x[KT] * (si * mr - sr * mi), x[ML], ur, ui,
            1.5 * (ur * sr + ui * si))  # fmt: skip


@njit(cache=True)  # (compiled for _TRUTH_SAT_SIG only, below)
def truth_sat(buf):
    """MockPlant.sample of the saturated motor in buf (TRUTH_FIELDS + SATURATION_TRUTH)."""
    x = buf[:NF]
    iv = buf[NF:].view(np.int64)
    sr, si, mr, mi, ur, ui, lm = x[IS_RE], x[IS_IM], x[IM_RE], x[IM_IM], x[US_RE], x[US_IM], x[LM]
    prr, pri, pmr, pmi = x[PR_RE], x[PR_IM], x[PM_RE], x[PM_IM]
    if iv[COAST]:
        m_e = 0.0
    else:  # SaturatedInductionMotor.m_e = 3/2 Z_p Im{psi_r i_rs^*}
        irr, iri = _fmul(x[GR], prr - pmr, pri - pmi)
        m_e = 1.5 * x[ZP] * (pri * irr - prr * iri)
    psi = math.hypot(pmr, pmi)
    l_m = x[LM0] / (1.0 + math.pow(psi / x[PSI_SAT], x[SAT_A]))  # Saturation.L_m_of
    return (sr, si, mr, mi, lm * mr, lm * mi, x[W], x[ZP] * x[TH], m_e, x[ML], ur, ui, 1.5 * (ur * sr + ui * si),
            psi, l_m)  # fmt: skip


drop_stale(globals())  # (bench.jit_cache: numba's cache knows only this file's date)
compile_fixed(advance, _SIG)
compile_fixed(integrate, _INTEGRATE_SIG)
compile_fixed(truth, _TRUTH_SIG)
compile_fixed(truth_sat, _TRUTH_SAT_SIG)


# --- the plant's objects as views on the buffer ------------------------------------------------------
def _fslot(i: int) -> property:
    return property(lambda s: s._buf.item(i), lambda s, v: s._buf.__setitem__(i, v))


def _cslot(i: int) -> property:
    def get(s) -> complex:
        b = s._buf
        return complex(b.item(i), b.item(i + 1))

    def set_(s, v: complex) -> None:
        v = complex(v)
        s._buf[i] = v.real
        s._buf[i + 1] = v.imag

    return property(get, set_)


def _islot(i: int, kind: type = int) -> property:
    return property(lambda s: kind(s._iv.item(i)), lambda s, v: s._iv.__setitem__(i, int(v)))


class MotorView(InductionMotor):
    """`InductionMotor` whose state is in the plant buffer (the compiled engine integrates it)."""

    i_s, i_m, u_s = _cslot(IS_RE), _cslot(IM_RE), _cslot(US_RE)
    omega_r, theta_mech, m_L = _fslot(W), _fslot(TH), _fslot(MOT_ML)
    coast = _islot(COAST, bool)

    def __init__(self, buf: np.ndarray, params: MotorParams, **kw: object) -> None:
        self._buf, self._iv = buf, int_view(buf)
        super().__init__(params, **kw)  # type: ignore[arg-type]
        self._constants()

    def _constants(self) -> None:
        b, params = self._buf, self.params
        b[KT], b[ZPJ], b[ZPI] = self._k_t, self._zp_j, self._zp_inv
        b[BV], b[MC], b[WEI] = self._b_visc, self._m_c, self._w_eps_inv
        b[LMP], b[LM], b[ZP] = params.Lm_p, params.L_m, params.Z_p
        lmr = params.L_m / params.L_r
        b[RRP_C], b[LS_P], b[L_R], b[LMR] = lmr**2, params.Ls_p, params.L_r, lmr  # as ReferredQuantities.Rr_p
        self._iv[HOLD], self._iv[SUBSTEPS] = int(bool(self.hold_speed)), self.substeps

    def _set_coeffs(self) -> None:
        super()._set_coeffs()
        b = self._buf
        b[A11], b[A12], b[A12W], b[B1], b[A21] = self._a11, self._a12, self._a12w, self._b1, self._a21

    @property  # type: ignore[override]
    def params(self) -> MotorParams:
        """The machine, with the resistances the compiled thermal model last set."""
        p, b = self._params, self._buf
        if p.R_s != b.item(R_S) or p.R_r != b.item(R_R):
            p = self._params = replace(p, R_s=b.item(R_S), R_r=b.item(R_R))
        return p

    @params.setter
    def params(self, p: MotorParams) -> None:
        self._params = p
        self._buf[R_S], self._buf[R_R] = p.R_s, p.R_r


class SaturatedMotorView(MotorView, SaturatedInductionMotor):
    """`SaturatedInductionMotor` whose flux state is in the plant buffer."""

    _ps, _pr, _pm, _x = _cslot(PS_RE), _cslot(PR_RE), _cslot(PM_RE), _fslot(SAT_X)

    def __init__(self, buf: np.ndarray, params: MotorParams, saturation: Saturation, **kw: object) -> None:
        self._buf, self._iv = buf, int_view(buf)
        SaturatedInductionMotor.__init__(self, params, saturation, **kw)
        self._constants()
        sat = saturation
        buf[GS], buf[GR], buf[L0I], buf[PSI_INV], buf[SAT_A] = (self._gs, self._gr, 1.0 / sat.L_m0,
                                                               1.0 / sat.psi_sat, sat.exponent)  # fmt: skip
        buf[LM0], buf[PSI_SAT] = sat.L_m0, sat.psi_sat
        self._iv[SAT] = 1


class ThermalView(ThermalModel):
    """`ThermalModel` whose temperatures and resistances are in the plant buffer."""

    T_s, T_r, R_s, R_r = _fslot(T_S), _fslot(T_R), _fslot(TR_S), _fslot(TR_R)

    def __init__(self, buf: np.ndarray, dt: float, R_s20: float, R_r20: float, **kw: float) -> None:
        self._buf = buf
        super().__init__(R_s20, R_r20, **kw)
        self._coefficients(dt)
        buf[T_AMB], buf[TR_S20], buf[TR_R20] = self.T_amb, self.R_s20, self.R_r20
        buf[TP00], buf[TP01], buf[TP10], buf[TP11] = self._p00, self._p01, self._p10, self._p11
        buf[TG00], buf[TG01], buf[TG10], buf[TG11] = self._g00, self._g01, self._g10, self._g11
        int_view(buf)[THERMAL] = 1


class LoadView(DcLoadDrive):
    """`DcLoadDrive` whose output torque is in the plant buffer (the reference stays an attribute)."""

    m_L = _fslot(ML)

    def __init__(self, buf: np.ndarray, dt: float, **kw: float) -> None:
        self._buf = buf
        super().__init__(**kw)
        buf[LOAD_E], buf[LOAD_MEAN] = lag_coefficients(self.tau, dt)  # DcLoadDrive.advance's for h = dt


class AdcView(_Adc):
    """`_Adc` whose constants, noise state and Mersenne Twister are in the plant buffer.

    ``raw`` and ``value`` stay plain attributes (the plant sets them). Reading ``rng`` writes the
    compiled stream back into the `random.Random` and marks it lent: the plant reloads it before
    its next step, so Python code may draw from it in between.
    """

    def __init__(self, buf: np.ndarray, base: int, gn: int, mt: int, lent: list[bool], **kw: object) -> None:
        self._buf, self._iv, self._base, self._gn, self._mt, self._lent = buf, int_view(buf), base, gn, mt, lent
        super().__init__(**kw)  # type: ignore[arg-type]

    @classmethod
    def like(cls, adc: _Adc, buf: np.ndarray, base: int, gn: int, mt: int, lent: list[bool]) -> "AdcView":
        return cls(buf, base, gn, mt, lent, gain=adc.gain, adc_bits=adc.adc_bits, adc_range=adc.adc_range,
                   gain_error=adc.gain_error, offset=adc.offset, offset_cal=adc.offset_cal,
                   noise_std=adc.noise_std, rng=adc.rng)  # fmt: skip

    def _pack(self) -> None:
        super()._pack()
        self._buf[self._base:self._base + 13] = self._c

    @property
    def noise_std(self) -> float:
        return self._buf.item(self._base + ADC_NOISE)

    @noise_std.setter
    def noise_std(self, v: float) -> None:
        self._buf[self._base + ADC_NOISE] = v

    @property
    def rng(self) -> random.Random:
        r = self._rng
        iv, mt = self._iv, self._mt
        gn = self._buf.item(self._base + ADC_GNEXT) if iv[self._gn] else None
        r.setstate((3, tuple(iv[mt:mt + 625].tolist()), gn))
        self._is_lent = self._lent[0] = True
        return r

    @rng.setter
    def rng(self, r: random.Random) -> None:
        self._rng = r
        self.load_rng()

    def load_rng(self) -> None:
        """Copy the `random.Random`'s state into the buffer."""
        self._is_lent = False
        version, state, gn = self._rng.getstate()
        if version != 3 or len(state) != 625:
            raise RuntimeError(f"unexpected random.Random state version {version}")
        self._iv[self._mt:self._mt + 625] = state
        self._iv[self._gn] = gn is not None
        self._buf[self._base + ADC_GNEXT] = 0.0 if gn is None else gn


class VoltageView(VoltageSensors):
    """`VoltageSensors` whose filter state is in the plant buffer."""

    y, dy = _cslot(Y_RE), _cslot(DY_RE)

    def __init__(self, buf: np.ndarray, dt: float, **kw: object) -> None:
        self._buf = buf
        super().__init__(dt, **kw)  # type: ignore[arg-type]
        (buf[P00], buf[P01], buf[P10], buf[P11]), (buf[G0], buf[G1]) = self._phi, self._gam


class EncoderView(Encoder):
    """`Encoder` whose counter state is in the plant buffer; `read` returns the last sample."""

    _raw, _rev, _offset = _islot(ENC_RAW), _islot(ENC_REV), _islot(ENC_OFF)
    _stuck = _islot(ENC_STUCK, bool)

    def __init__(self, buf: np.ndarray, **kw: object) -> None:
        self._buf, self._iv = buf, int_view(buf)
        super().__init__(**kw)  # type: ignore[arg-type]
        buf[ENC_SCALE], buf[ENC_IANG] = self._scale, self.index_angle
        self._iv[ENC_CPR], self._iv[ENC_MOD] = self.counts_per_rev, self.modulus

    @property
    def _value(self) -> tuple[int, int]:
        return self._val

    @_value.setter
    def _value(self, v: tuple[int, int]) -> None:
        self._val = v
        self._iv[ENC_CNT], self._iv[ENC_IDX] = v

    def read(self) -> tuple[int, int]:
        return self._val
