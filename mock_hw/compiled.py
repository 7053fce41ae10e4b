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

from bench.core.jit_cache import compile_fixed, drop_stale, entry  # noqa: F401 (entry: plant.py)
from bench.params import MotorParams
from bench.core.slots import slots
from mock_hw.inverter import SQRT3, voltage_error
from mock_hw.load import DcLoadDrive, lag_coefficients, lag_step
from mock_hw.motor import InductionMotor, SaturatedInductionMotor, Saturation, rk4, rk4_coast, sat_step
from mock_hw.sensors import Encoder, VoltageSensors, _Adc, adc_read, encoder_sample, filter_step
from mock_hw.thermal import ALPHA_AL, ALPHA_CU, ThermalModel, copper_loss, resistance, thermal_step

TWO_PI = 2.0 * math.pi  # as in mock_hw.sensors
_H = 0.5 * SQRT3

# --- buffer layout (`bench.core.slots`) ---------------------------------------------------------------
# float slots
PF = slots("PlantSlots",
           # motor state (and inputs of the last step)
           IS_RE="f", IS_IM="f", IM_RE="f", IM_IM="f", W="f", TH="f", US_RE="f", US_IM="f", MOT_ML="f",
           # DC load: output torque, lag coefficients for h = dt
           ML="f", LOAD_E="f", LOAD_MEAN="f",
           # voltage filter state and ZOH matrices
           Y_RE="f", Y_IM="f", DY_RE="f", DY_IM="f", P00="f", P01="f", P10="f", P11="f", G0="f", G1="f",
           # motor coefficients, dt
           A11="f", A12="f", A12W="f", B1="f", A21="f", KT="f", ZPJ="f", ZPI="f", BV="f", MC="f", WEI="f", LMP="f",
           LM="f", ZP="f", DT="f",
           # inverter voltage error, encoder
           DEAD="f", FPWM="f", VON_A="f", VON_B="f", VON_C="f", IKNEE="f", ENC_SCALE="f", ENC_IANG="f",
           # the motor's resistances and what its coefficients need of them
           R_S="f", R_R="f", RRP_C="f", LS_P="f", L_R="f", LMR="f",
           # thermal
           T_S="f", T_R="f", T_AMB="f", TP00="f", TP01="f", TP10="f", TP11="f", TG00="f", TG01="f", TG10="f",
           TG11="f", TR_S20="f", TR_R20="f", TR_S="f", TR_R="f",
           # saturated motor
           PS_RE="f", PS_IM="f", PR_RE="f", PR_IM="f", PM_RE="f", PM_IM="f", SAT_X="f", GS="f", GR="f", L0I="f",
           PSI_INV="f", SAT_A="f", LM0="f", PSI_SAT="f",
           # the currents' and the voltages' ADC: 13 constants of `_Adc._c`, noise_std, gauss_next value
           ADC_I="f15", ADC_U="f15")  # fmt: skip
NF = type(PF).size  # float slots
ADC_NOISE, ADC_GNEXT = 13, 14  # in an ADC's block
# int slots (offsets into the int64 view of buf[NF:]); GN_*: 1 if the stream holds a gauss_next; THERMAL, SAT: on
PI = slots("PlantInts", COAST="i", HOLD="i", SUBSTEPS="i", ENC_RAW="i", ENC_REV="i", ENC_OFF="i", ENC_STUCK="i",
           ENC_CNT="i", ENC_IDX="i", ENC_CPR="i", ENC_MOD="i", GN_I="i", GN_U="i", THERMAL="i", SAT="i",
           MT_I="i625", MT_U="i625")  # the currents' and the voltages' MT19937: 624 words, then the index  # fmt: skip
NI = type(PI).size
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
        u = complex(ur, ui) * (lim / mag)
        ur, ui = u.real, u.imag
    va, vb, vc = x[PF.VON_A], x[PF.VON_B], x[PF.VON_C]
    if x[PF.DEAD] > 0.0 or va != 0.0 or vb != 0.0 or vc != 0.0:  # Inverter.voltage_error, i_s at the period start
        er, ei = _voltage_error(x[PF.DEAD] * x[PF.FPWM] * u_dc, va, vb, vc, x[PF.IKNEE], x[PF.IS_RE], x[PF.IS_IM])
        ur, ui = ur + er, ui + ei
    return ur, ui


@njit
def _rk4(x, hold, ur, ui, m_L, h):
    # InductionMotor._rk4: classic RK4 of (3.41)+(3.37), u and m_L held (mock_hw.motor.rk4)
    i_s, i_m, x[PF.W], x[PF.TH] = _rk4_kernel(
        complex(x[PF.IS_RE], x[PF.IS_IM]), complex(x[PF.IM_RE], x[PF.IM_IM]), x[PF.W], x[PF.TH], complex(ur, ui), m_L,
        h, hold, x[PF.A11], x[PF.A12], x[PF.A12W], x[PF.A21], x[PF.B1], x[PF.KT], x[PF.ZPJ], x[PF.ZPI], x[PF.BV],
        x[PF.MC], x[PF.WEI])  # fmt: skip
    x[PF.IS_RE], x[PF.IS_IM], x[PF.IM_RE], x[PF.IM_IM] = i_s.real, i_s.imag, i_m.real, i_m.imag


@njit
def _rk4_coast(x, hold, m_L, h):
    # InductionMotor._rk4_coast: i_s = 0, (4.15), m_e = 0 (mock_hw.motor.rk4_coast)
    i_m, x[PF.W], x[PF.TH] = _rk4_coast_kernel(
        complex(x[PF.IM_RE], x[PF.IM_IM]), x[PF.W], x[PF.TH], m_L, h, hold, x[PF.A21], x[PF.ZPJ], x[PF.ZPI], x[PF.BV],
        x[PF.MC], x[PF.WEI])  # fmt: skip
    x[PF.IM_RE], x[PF.IM_IM] = i_m.real, i_m.imag


@njit
def _thermal(x, sat):
    # ThermalModel.advance with InductionMotor.winding_losses at the period start
    sr, si = x[PF.IS_RE], x[PF.IS_IM]
    if sat:  # SaturatedInductionMotor.i_rs = (psi_r - psi_m)/L_rs
        i_r = x[PF.GR] * complex(x[PF.PR_RE] - x[PF.PM_RE], x[PF.PR_IM] - x[PF.PM_IM])
    else:  # i_rs = (i_m - i_s) L_m/L_r (3.39)
        i_r = x[PF.LMR] * complex(x[PF.IM_RE] - sr, x[PF.IM_IM] - si)
    p_s, p_r = _copper_loss(x[PF.R_S], sr, si), _copper_loss(x[PF.R_R], i_r.real, i_r.imag)
    x[PF.T_S], x[PF.T_R] = _thermal_step(
        x[PF.T_AMB], x[PF.T_S], x[PF.T_R], x[PF.TP00], x[PF.TP01], x[PF.TP10], x[PF.TP11], x[PF.TG00], x[PF.TG01],
        x[PF.TG10], x[PF.TG11], p_s, p_r)  # fmt: skip
    x[PF.TR_S] = _resistance(x[PF.TR_S20], ALPHA_CU, x[PF.T_S])
    x[PF.TR_R] = _resistance(x[PF.TR_R20], ALPHA_AL, x[PF.T_R])


@njit
def _set_resistances(x, r_s, r_r):
    # InductionMotor.set_resistances: the coefficients of (3.41) that depend on R_s, R_r
    x[PF.R_S], x[PF.R_R] = r_s, r_r
    rrp = x[PF.RRP_C] * r_r  # R'_r = (L_m/L_r)^2 R_r
    x[PF.A11] = -(r_s + rrp) / x[PF.LS_P]
    x[PF.A12] = rrp / x[PF.LS_P]
    x[PF.A21] = r_r / x[PF.L_R]


# --- the saturated motor (mock_hw.motor.SaturatedInductionMotor): its kernel, mock_hw.motor.sat_step ----------
@njit
def _sat_step(x, iv, coast, hold, ur, ui, m_L, h):
    ps, pr, pm, i_s, i_m, x[PF.W], x[PF.TH], u_s, x[PF.SAT_X] = _sat_step_kernel(
        complex(x[PF.PS_RE], x[PF.PS_IM]), complex(x[PF.PR_RE], x[PF.PR_IM]), x[PF.W], x[PF.TH], complex(ur, ui), m_L,
        h, iv[PI.SUBSTEPS], coast, hold, x[PF.SAT_X], x[PF.LM], x[PF.GS], x[PF.GR], x[PF.R_S], x[PF.R_R], x[PF.ZP],
        x[PF.ZPI], x[PF.ZPJ], x[PF.BV], x[PF.MC], x[PF.WEI], x[PF.L0I], x[PF.PSI_INV], x[PF.SAT_A])  # fmt: skip
    x[PF.PS_RE], x[PF.PS_IM], x[PF.PR_RE], x[PF.PR_IM] = ps.real, ps.imag, pr.real, pr.imag
    x[PF.PM_RE], x[PF.PM_IM] = pm.real, pm.imag
    x[PF.IS_RE], x[PF.IS_IM], x[PF.IM_RE], x[PF.IM_IM] = i_s.real, i_s.imag, i_m.real, i_m.imag
    x[PF.US_RE], x[PF.US_IM] = u_s.real, u_s.imag


@njit
def _period(x, iv, ur, ui, on, u_dc, m_L_ref):
    ur, ui = _latch(x, ur, ui, on, u_dc)  # 1. inverter (one-sample pipeline done by the caller)
    # 2. DcLoadDrive.advance: exact lag, mean torque over the period
    x[PF.ML], m_L = _lag_step(m_L_ref, x[PF.ML], x[PF.LOAD_E], x[PF.LOAD_MEAN])
    thermal = iv[PI.THERMAL] != 0
    if thermal:  # 3. the winding temperatures with the losses at the period start
        _thermal(x, iv[PI.SAT] != 0)
    # 3. InductionMotor.step with substeps
    h = x[PF.DT]
    n = iv[PI.SUBSTEPS]
    hs = h / n
    hold = iv[PI.HOLD] != 0
    if iv[PI.SAT]:
        iv[PI.COAST] = 0 if on else 1
        _sat_step(x, iv, not on, hold, ur, ui, m_L, h)
    elif not on:
        iv[PI.COAST] = 1
        m0r, m0i = x[PF.IM_RE], x[PF.IM_IM]
        for _ in range(n):
            _rk4_coast(x, hold, m_L, hs)
        x[PF.IS_RE], x[PF.IS_IM] = 0.0, 0.0
        # back-EMF L'_m (i_m - i_m0)/h: float * complex, then complex / float (_Py_c_quot)
        u = x[PF.LMP] * complex(x[PF.IM_RE] - m0r, x[PF.IM_IM] - m0i) / h
        x[PF.US_RE], x[PF.US_IM] = u.real, u.imag
    else:
        iv[PI.COAST] = 0
        for _ in range(n):
            _rk4(x, hold, ur, ui, m_L, hs)
        x[PF.US_RE], x[PF.US_IM] = ur, ui
    x[PF.MOT_ML] = m_L
    if thermal:  # R(T) from the end of the period on
        _set_resistances(x, x[PF.TR_S], x[PF.TR_R])
    # 4. VoltageSensors.advance: exact ZOH of the filter with u_s held
    y, dy = _filter_step(complex(x[PF.Y_RE], x[PF.Y_IM]), complex(x[PF.DY_RE], x[PF.DY_IM]),
                         complex(x[PF.US_RE], x[PF.US_IM]), x[PF.P00], x[PF.P01], x[PF.P10], x[PF.P11], x[PF.G0],
                         x[PF.G1])  # fmt: skip
    x[PF.Y_RE], x[PF.Y_IM], x[PF.DY_RE], x[PF.DY_IM] = y.real, y.imag, dy.real, dy.imag
    return ur, ui


@njit
def _encoder(x, iv):
    # Encoder.sample (mock_hw.sensors.encoder_sample)
    iv[PI.ENC_RAW], iv[PI.ENC_REV], iv[PI.ENC_OFF], iv[PI.ENC_CNT], iv[PI.ENC_IDX] = _encoder_sample(
        x[PF.TH], x[PF.ENC_SCALE], x[PF.ENC_IANG], iv[PI.ENC_CPR], iv[PI.ENC_MOD], iv[PI.ENC_RAW], iv[PI.ENC_REV],
        iv[PI.ENC_OFF], iv[PI.ENC_STUCK] != 0, iv[PI.ENC_CNT], iv[PI.ENC_IDX])  # fmt: skip
    return iv[PI.ENC_CNT], iv[PI.ENC_IDX]


_F3 = types.UniTuple(types.float64, 3)
_I3 = types.UniTuple(types.int64, 3)
_SIG = types.Tuple((_F3, _I3, _F3, _I3, types.UniTuple(types.int64, 2), types.complex128))(
    types.float64[::1], types.int64, types.complex128, types.boolean, types.complex128, types.boolean,
    types.float64, types.float64)  # fmt: skip


@njit(cache=True)  # (compiled for _SIG only, below: bench.core.jit_cache.compile_fixed)
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
    re, h = x[PF.IS_RE], _H * x[PF.IS_IM]
    vi, ci = _convert(x, iv, PF.ADC_I, PI.GN_I, PI.MT_I, re, -0.5 * re + h, -0.5 * re - h)
    # VoltageSensors.sample: filtered phase voltages
    re, h = x[PF.Y_RE], _H * x[PF.Y_IM]
    vu, cu = _convert(x, iv, PF.ADC_U, PI.GN_U, PI.MT_U, re, -0.5 * re + h, -0.5 * re - h)
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
    sr, si, mr, mi, ur, ui, lm = x[PF.IS_RE], x[PF.IS_IM], x[PF.IM_RE], x[PF.IM_IM], x[PF.US_RE], x[PF.US_IM], x[PF.LM]
    return (sr, si, mr, mi, lm * mr, lm * mi, x[PF.W], x[PF.ZP] * x[PF.TH], x[PF.KT] * (si * mr - sr * mi), x[PF.ML],
            ur, ui, 1.5 * (ur * sr + ui * si))  # fmt: skip


@njit(cache=True)  # (compiled for _TRUTH_SAT_SIG only, below)
def truth_sat(buf):
    """MockPlant.sample of the saturated motor in buf (TRUTH_FIELDS + SATURATION_TRUTH)."""
    x = buf[:NF]
    iv = buf[NF:].view(np.int64)
    sr, si, mr, mi, ur, ui, lm = x[PF.IS_RE], x[PF.IS_IM], x[PF.IM_RE], x[PF.IM_IM], x[PF.US_RE], x[PF.US_IM], x[PF.LM]
    prr, pri, pmr, pmi = x[PF.PR_RE], x[PF.PR_IM], x[PF.PM_RE], x[PF.PM_IM]
    if iv[PI.COAST]:
        m_e = 0.0
    else:  # SaturatedInductionMotor.m_e = 3/2 Z_p Im{psi_r i_rs^*}
        i_r = x[PF.GR] * complex(prr - pmr, pri - pmi)
        irr, iri = i_r.real, i_r.imag
        m_e = 1.5 * x[PF.ZP] * (pri * irr - prr * iri)
    psi = math.hypot(pmr, pmi)
    l_m = x[PF.LM0] / (1.0 + math.pow(psi / x[PF.PSI_SAT], x[PF.SAT_A]))  # Saturation.L_m_of
    return (sr, si, mr, mi, lm * mr, lm * mi, x[PF.W], x[PF.ZP] * x[PF.TH], m_e, x[PF.ML], ur, ui,
            1.5 * (ur * sr + ui * si), psi, l_m)  # fmt: skip


drop_stale(globals())  # (bench.core.jit_cache: numba's cache knows only this file's date)
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

    i_s, i_m, u_s = _cslot(PF.IS_RE), _cslot(PF.IM_RE), _cslot(PF.US_RE)
    omega_r, theta_mech, m_L = _fslot(PF.W), _fslot(PF.TH), _fslot(PF.MOT_ML)
    coast = _islot(PI.COAST, bool)

    def __init__(self, buf: np.ndarray, params: MotorParams, **kw: object) -> None:
        self._buf, self._iv = buf, int_view(buf)
        super().__init__(params, **kw)  # type: ignore[arg-type]
        self._constants()

    def _constants(self) -> None:
        b, params = self._buf, self.params
        b[PF.KT], b[PF.ZPJ], b[PF.ZPI] = self._k_t, self._zp_j, self._zp_inv
        b[PF.BV], b[PF.MC], b[PF.WEI] = self._b_visc, self._m_c, self._w_eps_inv
        b[PF.LMP], b[PF.LM], b[PF.ZP] = params.Lm_p, params.L_m, params.Z_p
        lmr = params.L_m / params.L_r
        # RRP_C as ReferredQuantities.Rr_p
        b[PF.RRP_C], b[PF.LS_P], b[PF.L_R], b[PF.LMR] = lmr**2, params.Ls_p, params.L_r, lmr
        self._iv[PI.HOLD], self._iv[PI.SUBSTEPS] = int(bool(self.hold_speed)), self.substeps

    def _set_coeffs(self) -> None:
        super()._set_coeffs()
        b = self._buf
        b[PF.A11], b[PF.A12], b[PF.A12W], b[PF.B1], b[PF.A21] = self._a11, self._a12, self._a12w, self._b1, self._a21

    @property  # type: ignore[override]
    def params(self) -> MotorParams:
        """The machine, with the resistances the compiled thermal model last set."""
        p, b = self._params, self._buf
        if p.R_s != b.item(PF.R_S) or p.R_r != b.item(PF.R_R):
            p = self._params = replace(p, R_s=b.item(PF.R_S), R_r=b.item(PF.R_R))
        return p

    @params.setter
    def params(self, p: MotorParams) -> None:
        self._params = p
        self._buf[PF.R_S], self._buf[PF.R_R] = p.R_s, p.R_r


class SaturatedMotorView(MotorView, SaturatedInductionMotor):
    """`SaturatedInductionMotor` whose flux state is in the plant buffer."""

    _ps, _pr, _pm, _x = _cslot(PF.PS_RE), _cslot(PF.PR_RE), _cslot(PF.PM_RE), _fslot(PF.SAT_X)

    def __init__(self, buf: np.ndarray, params: MotorParams, saturation: Saturation, **kw: object) -> None:
        self._buf, self._iv = buf, int_view(buf)
        SaturatedInductionMotor.__init__(self, params, saturation, **kw)
        self._constants()
        sat = saturation
        buf[PF.GS], buf[PF.GR], buf[PF.L0I], buf[PF.PSI_INV], buf[PF.SAT_A] = (self._gs, self._gr, 1.0 / sat.L_m0,
                                                               1.0 / sat.psi_sat, sat.exponent)  # fmt: skip
        buf[PF.LM0], buf[PF.PSI_SAT] = sat.L_m0, sat.psi_sat
        self._iv[PI.SAT] = 1


class ThermalView(ThermalModel):
    """`ThermalModel` whose temperatures and resistances are in the plant buffer."""

    T_s, T_r, R_s, R_r = _fslot(PF.T_S), _fslot(PF.T_R), _fslot(PF.TR_S), _fslot(PF.TR_R)

    def __init__(self, buf: np.ndarray, dt: float, R_s20: float, R_r20: float, **kw: float) -> None:
        self._buf = buf
        super().__init__(R_s20, R_r20, **kw)
        self._coefficients(dt)
        buf[PF.T_AMB], buf[PF.TR_S20], buf[PF.TR_R20] = self.T_amb, self.R_s20, self.R_r20
        buf[PF.TP00], buf[PF.TP01], buf[PF.TP10], buf[PF.TP11] = self._p00, self._p01, self._p10, self._p11
        buf[PF.TG00], buf[PF.TG01], buf[PF.TG10], buf[PF.TG11] = self._g00, self._g01, self._g10, self._g11
        int_view(buf)[PI.THERMAL] = 1


class LoadView(DcLoadDrive):
    """`DcLoadDrive` whose output torque is in the plant buffer (the reference stays an attribute)."""

    m_L = _fslot(PF.ML)

    def __init__(self, buf: np.ndarray, dt: float, **kw: float) -> None:
        self._buf = buf
        super().__init__(**kw)
        buf[PF.LOAD_E], buf[PF.LOAD_MEAN] = lag_coefficients(self.tau, dt)  # DcLoadDrive.advance's for h = dt


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

    y, dy = _cslot(PF.Y_RE), _cslot(PF.DY_RE)

    def __init__(self, buf: np.ndarray, dt: float, **kw: object) -> None:
        self._buf = buf
        super().__init__(dt, **kw)  # type: ignore[arg-type]
        (buf[PF.P00], buf[PF.P01], buf[PF.P10], buf[PF.P11]), (buf[PF.G0], buf[PF.G1]) = self._phi, self._gam


class EncoderView(Encoder):
    """`Encoder` whose counter state is in the plant buffer; `read` returns the last sample."""

    _raw, _rev, _offset = _islot(PI.ENC_RAW), _islot(PI.ENC_REV), _islot(PI.ENC_OFF)
    _stuck = _islot(PI.ENC_STUCK, bool)

    def __init__(self, buf: np.ndarray, **kw: object) -> None:
        self._buf, self._iv = buf, int_view(buf)
        super().__init__(**kw)  # type: ignore[arg-type]
        buf[PF.ENC_SCALE], buf[PF.ENC_IANG] = self._scale, self.index_angle
        self._iv[PI.ENC_CPR], self._iv[PI.ENC_MOD] = self.counts_per_rev, self.modulus

    @property
    def _value(self) -> tuple[int, int]:
        return self._val

    @_value.setter
    def _value(self, v: tuple[int, int]) -> None:
        self._val = v
        self._iv[PI.ENC_CNT], self._iv[PI.ENC_IDX] = v

    def read(self) -> tuple[int, int]:
        return self._val
