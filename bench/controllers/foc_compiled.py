"""Compiled FOC tick (numba): `FocController.step` in one call, equal to the Python engine to the last bit.

``engine = "compiled"`` (or ``"auto"``) of `bench.controllers.foc.FocController` runs its tick here for the
configuration the kernels cover: the current-model observer (4.15), the speed PI with the current-limited
torque bound (4.7)(4.8), the flux P, the complex current PI with decoupling (4.13)(4.14), omega_mR (4.5),
encoder speed, any divisors, reference or measured observer voltage, any gains, delay compensation, voltage margin
and speed filter, the voltage-feedback field weakening and the on-line R_r estimate (``rr_adapt = "mras"``,
`bench.controllers.rr_adapt`, and the hand-over `FocController._use_R_r`).

The parts' kernels are written once, in their modules, as plain Python that this module compiles (``njit``): the
encoder speed, the current model, the flux P, the speed PI, the current PI, the field weakening and the R_r
estimate (docs/architecture.md, "Kernels written once"). What is written here is the tick that calls them in
`FocController.step`'s order, on the same complex numbers (numba's complex arithmetic is CPython 3.11's; the row's
angle is `bench.controllers.kernel_math.atan2`), so the logs agree bit for bit (tests/test_compiled_foc.py,
tests/test_controller_kernels.py).

State: one contiguous float64 buffer, its slots declared by name and kind (`SF`, `bench.core.slots`); a part of it is
viewed as int64 (`SI`: the encoder count, flags, the tick counter, the divisors). The controller and its parts
stay the same Python objects, with their state and gains as properties on the buffer (`attach`), so ``retune``,
``reset`` and anything reading or setting ``ctrl.speed.x``, ``ctrl.i_sd_ref``, ``ctrl.encoder.omega_raw``,
``ctrl.rr.b``, ... act as with the Python engine.
The R_r estimator keeps its numbers in an array declared by name (`bench.core.slots`); here that array is the region
``RR_AT:RR_END`` of the buffer, which the estimator views.
The kernel also leaves the row of ``internals()`` in the buffer (setting a logged value from Python refreshes
it), so reading it is one slice: 14 values, one more with the field weakening (``fw``; int slot ``SI.FW_ON``), two
more with the R_r estimate (``rr_hat``, ``rr_gate``; the int slot ``SI.R_ON`` says whether the estimator runs).

The other parts run in kernels of their own: the other flux observers and the speed estimators
(`observers_compiled`) and the LPV current and speed parts (`lpv_compiled`), each in a tail region of the buffer
(its kind, start and size in the int slots); the tick dispatches on the kinds (0: this module's current model, no
estimator, PI loops) and the row grows by the estimator's two speeds and the LPV speed part's four values as
``internals()`` does. Those parts are not views: `FocController` unpacks them into their Python objects around its
own Python code on them (``reset``, the R_r hand-over, a switch) and packs them again (`unpack_tails`,
`pack_tails`). `pack` gives the batch engine the buffer of a Python-engine controller.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, types
from numba.extending import register_jitable

from bench.controllers import lpv_compiled as lc, observers_compiled as oc
from bench.controllers.foc import (I_MR_FLOOR, CurrentPI, SpeedPI, current_pi, decoupling, field_frame,
                                   field_weakening, flux_p, speed_pi, stator_voltage)
from bench.controllers.kernel_math import atan2
from bench.controllers.rr_adapt import S as RS, gates, mras_update, own_model
from bench.core.encoder import encoder_speed_step
from bench.core.jit_cache import compile_fixed, drop_stale, entry
from bench.hal import SQRT3_INV
from bench.core.slots import slots
from bench.controllers.observers import CurrentModelObserver, current_model_step

# the parts written once in their modules (their helpers registered here, so that the controllers' modules do not
# import numba: bench.controllers.kernel_math)
register_jitable(decoupling)  # (bench.controllers.kernel_math's helpers: by observers_compiled)
register_jitable(own_model)
register_jitable(gates)
_current_model_step = njit(current_model_step)  # the current model (4.15)
_encoder_speed_step = njit(encoder_speed_step)
_flux_p = njit(flux_p)
_speed_pi = njit(speed_pi)
_field_weakening = njit(field_weakening)
_current_pi = njit(current_pi)
_field_frame = njit(field_frame)  # the field frame and the output's turn back to the stator frame
_stator_voltage = njit(stator_voltage)
_mras_update = njit(mras_update)  # the R_r estimate (bench.controllers.rr_adapt.RrMRAS)

# --- buffer layout ------------------------------------------------------------------------------
# float slots, by name and kind (`bench.core.slots`: "c" is a complex value, re then im)
SF = slots(
    "FocFloats",
    # EncoderSpeed
    E_KW="f", E_KTH="f", E_TS="f", E_TAU="f", E_ALPHA="f", E_LATE="f", E_PREV_T="f", E_WR="f", E_WRAW="f", E_TH="f",
    O_B="f", O_TS="f", O_IM="c", O_PREV="c",  # CurrentModelObserver
    S_K="f", S_IMAX="f", S_KP="f", S_KI="f", S_X="f", S_ME="f",  # SpeedPI
    F_KM="f", F_IMAX="f",  # FluxP
    C_KP="f", C_KI="f", C_X="c", C_SAT="f", C_LS="f", C_LM="f", C_RR="f",  # CurrentPI (saturated: 0.0 / 1.0)
    ISD_REF="f", ISQ_REF="f", U_SR="c", U_S_REF="c", U_H0="c", U_H1="c",  # FocController
    I_M="c", I_MR="f", W_MR="f", ROT="c", OMEGA="f", U_OBS="c", I_SR="c", INV_TR="f", ADVANCE="f", U_SCALE="f",
    TWO="f",  # 2.0, the exponent of x ** 2 given at run time (bench.controllers.kernel_math.square)
    R_RR2="f",  # (L_m/L_r)**2 of FocController._use_R_r: the current PI's R'_r = R_r (L_m/L_r)^2
    FW_F="f", FW_U="f", FW_K="f", FW_LO="f",  # FieldWeakening: factor, u_fw, k, lo
    # the internals() row: FocController.fields, 14 values; + 2 with a speed estimator (omega_enc, omega_est),
    # + 4 with the LPV speed part (its scheduling), + 1 with field weakening (fw), + 2 with rr_adapt (rr_hat, rr_gate)
    ROW="f",
)  # fmt: skip
N_ROW = 14  # the row of the PI loops, the current model and the encoder speed; the buffer has room for N_ROW_MAX
N_ROW_MAX = N_ROW + 2 + 4 + 1 + 2
NF = SF.ROW + N_ROW_MAX  # float slots
# int slots (offsets into the int64 view of buf[NF:])
SI = slots(
    "FocInts",
    # EncoderSpeed (_prev, _prev_t: flag 0 = None)
    E_MOD="i", E_HALF="i", E_PREV="i", E_HAS_PREV="i", E_D="i", E_HAS_T="i",
    O_HAS_PREV="i",  # CurrentModelObserver._i_s_prev is not None
    K="i", DIV_W="i", DIV_F="i", DIV_C="i", MEAS_U="i",  # FocController: tick counter, divisors, measured voltage
    R_ON="i",  # FocController.rr is not None
    FW_ON="i",  # FocController.fw is not None
    ORIENTED="i",  # FocController._oriented
    # the parts in tail regions of the buffer (`pack_parts`: the batch engine): their kinds (0: the current model, no
    # estimator, the PI loops, which live in the slots above) and each region's start, float and int slot counts
    OBS_KIND="i", EST_KIND="i", SENSORLESS="i", SPD_KIND="i", CUR_KIND="i",
    OBS_AT="i", OBS_NF="i", OBS_NI="i", EST_AT="i", EST_NF="i", EST_NI="i", SPD_AT="i", SPD_NF="i", SPD_NI="i",
    CUR_AT="i", CUR_NF="i", CUR_NI="i",
)  # fmt: skip
N_BUF = NF + SI.size  # the buffer without the R_r estimator's array and the tail regions
RR_AT, RR_END = N_BUF, N_BUF + RS.size  # the R_r estimator's array (bench.controllers.rr_adapt.S): RrMRAS views it
TAILS_AT = RR_END


# --- the tick ----------------------------------------------------------------------------------------
@njit
def _encoder(x, iv, count, t):
    # EncoderSpeed.update(count, t) (bench.core.encoder.encoder_speed_step)
    iv[SI.E_D], x[SF.E_TH], x[SF.E_WRAW], x[SF.E_WR] = _encoder_speed_step(
        count, iv[SI.E_PREV], iv[SI.E_HAS_PREV] != 0, iv[SI.E_MOD], iv[SI.E_HALF], x[SF.E_TH], x[SF.E_WR],
        x[SF.E_KTH], x[SF.E_KW], x[SF.E_ALPHA], x[SF.E_TS], x[SF.E_LATE], x[SF.E_TAU], True, t, x[SF.E_PREV_T],
        iv[SI.E_HAS_T] != 0)  # fmt: skip
    iv[SI.E_PREV], iv[SI.E_HAS_PREV] = count, 1
    x[SF.E_PREV_T], iv[SI.E_HAS_T] = t, 1
    return x[SF.E_WR]


@njit
def _observer(x, iv, sr, si, w):
    # CurrentModelObserver.update(i_s, u_s, omega_r): the current model (4.15) (observers.current_model_step)
    if iv[SI.O_HAS_PREV] == 0:
        pr, pi = sr, si
    else:
        pr, pi = x[SF.O_PREV], x[SF.O_PREV + 1]
    x[SF.O_PREV], x[SF.O_PREV + 1] = sr, si
    iv[SI.O_HAS_PREV] = 1
    i_m = _current_model_step(complex(x[SF.O_IM], x[SF.O_IM + 1]), complex(pr, pi), complex(sr, si), w, x[SF.O_B],
                              x[SF.O_TS])  # fmt: skip
    x[SF.O_IM], x[SF.O_IM + 1] = i_m.real, i_m.imag
    return i_m.real, i_m.imag


@njit
def _flux(x, i_mR_ref, i_mR):
    # FluxP.update (bench.controllers.foc.flux_p)
    return _flux_p(x[SF.F_KM], x[SF.F_IMAX], i_mR_ref, i_mR)


@njit
def _speed(x, omega_ref, omega, i_mR, i_sd_ref):
    # SpeedPI.update (bench.controllers.foc.speed_pi)
    i_sq, x[SF.S_X], x[SF.S_ME] = _speed_pi(omega_ref, omega, i_mR, i_sd_ref, x[SF.S_X], x[SF.S_KP], x[SF.S_KI],
                                            x[SF.S_K], x[SF.S_IMAX], x[SF.TWO])  # fmt: skip
    return i_sq


@njit
def _current(x, i_sd_ref, i_sq_ref, i_sd, i_sq, omega_mR, i_mR, u_max):
    # CurrentPI.update (bench.controllers.foc.current_pi)
    u, xi, sat = _current_pi(complex(i_sd_ref, i_sq_ref), complex(i_sd, i_sq), omega_mR, i_mR, u_max,
                             complex(x[SF.C_X], x[SF.C_X + 1]), x[SF.C_KP], x[SF.C_KI], x[SF.C_LS], x[SF.C_LM],
                             x[SF.C_RR])  # fmt: skip
    x[SF.C_X], x[SF.C_X + 1] = xi.real, xi.imag
    x[SF.C_SAT] = 1.0 if sat else 0.0
    return u.real, u.imag


@njit
def _fw(x, saturated, u_max):
    # FieldWeakening.update(saturated, u_sr, u_max) (bench.controllers.foc.field_weakening)
    x[SF.FW_F] = _field_weakening(x[SF.FW_F], saturated, complex(x[SF.U_SR], x[SF.U_SR + 1]), u_max, x[SF.FW_K],
                                  x[SF.FW_U], x[SF.FW_LO])  # fmt: skip


@njit
def _region(buf, iv, at):
    # a tail region's (float slots, int slots): at = SI.OBS_AT, EST_AT, SPD_AT or CUR_AT (empty when not in use)
    a, nf = iv[at], iv[at + 1]
    return buf[a:a + nf], buf[a + nf:a + nf + iv[at + 2]].view(np.int64)


@njit
def _row(buf, x, iv):
    # FocController.internals()
    r = SF.ROW
    est = iv[SI.EST_KIND] != 0
    x[r] = x[SF.OMEGA] if est else x[SF.E_WR]  # self.omega with a speed estimator, else encoder.omega_r
    x[r + 1], x[r + 2], x[r + 3] = x[SF.I_M], x[SF.I_M + 1], x[SF.I_MR]
    x[r + 4] = atan2(x[SF.I_M + 1], x[SF.I_M])
    x[r + 5], x[r + 6], x[r + 7] = x[SF.W_MR], x[SF.I_SR], x[SF.I_SR + 1]
    x[r + 8], x[r + 9] = x[SF.ISD_REF], x[SF.ISQ_REF]
    xw, _ = _region(buf, iv, SI.SPD_AT)
    x[r + 10] = x[SF.S_ME] if iv[SI.SPD_KIND] == 0 else xw[lc.SP.ME]  # speed.m_e_ref
    x[r + 11], x[r + 12] = x[SF.U_SR], x[SF.U_SR + 1]
    if iv[SI.CUR_KIND] == 0:
        x[r + 13] = x[SF.C_SAT]
    else:
        xc, _ = _region(buf, iv, SI.CUR_AT)
        x[r + 13] = xc[lc.CU.SAT]  # float(current.saturated)
    r += N_ROW
    if est:
        xe, _ = _region(buf, iv, SI.EST_AT)
        x[r], x[r + 1] = x[SF.E_WR], oc.est_omega_r(xe)  # encoder.omega_r, estimator.omega_r
        r += 2
    if iv[SI.SPD_KIND] != 0:  # the LPV speed part's internals()
        for j in range(lc.N_SPEED_ROW):
            x[r + j] = xw[lc.SP.ROW + j]
        r += lc.N_SPEED_ROW
    if iv[SI.FW_ON]:
        x[r] = x[SF.FW_F]  # fw.factor
        r += 1
    if iv[SI.R_ON]:
        xr = buf[RR_AT:RR_END]
        x[r], x[r + 1] = xr[RS.b] * xr[RS.L_r], xr[RS.gate]  # rr.R_r, float(rr.gate)


_F = types.float64
_SIG = types.complex128(types.float64[::1], _F, _F, _F, _F, _F, _F, _F, types.int64, _F, _F, _F)


@njit(cache=True)  # (compiled for _SIG only, below: bench.core.jit_cache.compile_fixed)
def step(buf, t, i_a, i_b, i_c, u_a, u_b, u_c, enc_count, u_dc, omega_ref, i_mR_ref):
    """FocController.step for one measurement (its scalar fields); returns u_s_ref, leaves the internals row."""
    x = buf[:NF]
    iv = buf[NF:N_BUF].view(np.int64)
    k = iv[SI.K]
    iv[SI.K] = k + 1
    omega = _encoder(x, iv, enc_count, t)
    sr, si = (2.0 * i_a - i_b - i_c) / 3.0, (i_b - i_c) * SQRT3_INV  # meas.i_s (bench.hal.space_vector)
    if iv[SI.MEAS_U]:
        ur, ui = (2.0 * u_a - u_b - u_c) / 3.0, (u_b - u_c) * SQRT3_INV  # meas.u_s
    else:
        ur, ui = x[SF.U_H1], x[SF.U_H1 + 1]
    x[SF.U_OBS], x[SF.U_OBS + 1] = ur, ui
    obs_kind, est_kind = iv[SI.OBS_KIND], iv[SI.EST_KIND]
    xo, ivo = _region(buf, iv, SI.OBS_AT)
    xe, ive = _region(buf, iv, SI.EST_AT)
    if iv[SI.SENSORLESS]:  # the observer's rotation term uses the estimate of the previous tick
        w_obs = oc.est_omega_hat(xe)
    else:  # the unfiltered per-sample speed: the rotation term integrates to the encoder angle exactly
        w_obs = x[SF.E_WRAW]
    if obs_kind == 0:
        mr, mi = _observer(x, iv, sr, si, w_obs)
    else:
        mr, mi = oc.update(obs_kind, xo, ivo, sr, si, ur, ui, w_obs)
    if est_kind != 0:
        w_est = oc.est_update(est_kind, xe, ive, xo, ivo, sr, si, ur, ui, mr, mi)
        if iv[SI.SENSORLESS]:
            omega = w_est
    x[SF.OMEGA] = omega
    i_mR, oriented, rot = _field_frame(complex(mr, mi), i_mR_ref, iv[SI.ORIENTED] != 0,
                                       complex(x[SF.ROT], x[SF.ROT + 1]))  # fmt: skip
    iv[SI.ORIENTED] = oriented
    x[SF.ROT], x[SF.ROT + 1] = rot.real, rot.imag
    i_sr = complex(sr, si) * rot
    isr, isi = i_sr.real, i_sr.imag
    x[SF.I_M], x[SF.I_M + 1], x[SF.I_MR], x[SF.I_SR], x[SF.I_SR + 1] = mr, mi, i_mR, isr, isi
    w_mR = omega + x[SF.INV_TR] * isi / (I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR)  # (4.5)
    x[SF.W_MR] = w_mR
    if iv[SI.CUR_KIND] == 0:
        sat = x[SF.C_SAT] != 0.0  # current.saturated (of its last update)
    else:
        xc, _ = _region(buf, iv, SI.CUR_AT)
        sat = xc[lc.CU.SAT] != 0.0
    if iv[SI.R_ON]:  # the R_r estimate from this period; the parts use it from the next tick on
        xr = buf[RR_AT:RR_END]
        if _mras_update(xr, t, complex(sr, si), complex(ur, ui), x[SF.E_WRAW], w_mR, isi, i_mR, sat):
            # FocController._use_R_r: the observer (set_R_r), the slip (4.5), the decoupling R'_r (4.13)
            R_r = xr[RS.b] * xr[RS.L_r]  # rr.R_r
            if obs_kind == 0:
                x[SF.O_B] = R_r / xr[RS.L_r]
            else:
                oc.set_R_r(obs_kind, xo, ivo, R_r)
            if est_kind != 0:
                oc.est_set_R_r(est_kind, xe, ive, R_r)
            x[SF.INV_TR] = xr[RS.b]
            if iv[SI.CUR_KIND] == 0:
                x[SF.C_RR] = x[SF.R_RR2] * R_r
    if k % iv[SI.DIV_F] == 0:
        x[SF.ISD_REF] = _flux(x, i_mR_ref * x[SF.FW_F] if iv[SI.FW_ON] else i_mR_ref, i_mR)
    if k % iv[SI.DIV_W] == 0:
        if iv[SI.SPD_KIND] == 0:
            x[SF.ISQ_REF] = _speed(x, omega_ref, omega, i_mR, x[SF.ISD_REF])
        else:
            xw, ivw = _region(buf, iv, SI.SPD_AT)
            x[SF.ISQ_REF] = lc.speed_update(xw, ivw, omega_ref, omega, i_mR, x[SF.ISD_REF])
    if k % iv[SI.DIV_C] == 0:
        u_max = u_dc * x[SF.U_SCALE]
        if iv[SI.CUR_KIND] == 0:
            x[SF.U_SR], x[SF.U_SR + 1] = _current(x, x[SF.ISD_REF], x[SF.ISQ_REF], isr, isi, w_mR, i_mR, u_max)
        else:
            xc, ivc = _region(buf, iv, SI.CUR_AT)
            x[SF.U_SR], x[SF.U_SR + 1] = lc.current_update(xc, ivc, x[SF.ISD_REF], x[SF.ISQ_REF], isr, isi, w_mR, i_mR,
                                                           u_max)  # fmt: skip
    if iv[SI.FW_ON]:  # (a slower current loop: its output and flag held between its updates)
        if iv[SI.CUR_KIND] == 0:
            sat = x[SF.C_SAT] != 0.0
        else:
            xc, _ = _region(buf, iv, SI.CUR_AT)
            sat = xc[lc.CU.SAT] != 0.0
        _fw(x, sat, u_dc * x[SF.U_SCALE])
    u = _stator_voltage(complex(x[SF.U_SR], x[SF.U_SR + 1]), rot, w_mR, x[SF.ADVANCE])
    ur, ui = u.real, u.imag
    x[SF.U_S_REF], x[SF.U_S_REF + 1] = ur, ui
    x[SF.U_H1], x[SF.U_H1 + 1] = x[SF.U_H0], x[SF.U_H0 + 1]
    x[SF.U_H0], x[SF.U_H0 + 1] = ur, ui
    _row(buf, x, iv)
    return complex(ur, ui)


_FILL_SIG = types.void(types.float64[::1])


@njit(cache=True)  # (compiled for _FILL_SIG only, below)
def fill_row(buf):
    """Recompute the internals row from the state (after Python code set a logged value)."""
    _row(buf, buf[:NF], buf[NF:N_BUF].view(np.int64))


drop_stale(globals())  # (bench.core.jit_cache: numba's cache knows only this file's date)
compile_fixed(step, _SIG)
compile_fixed(fill_row, _FILL_SIG)
_STEP = entry(step)
_FILL = entry(fill_row)


# --- the controller's objects as views on the buffer ---------------------------------------------------
def _f(i: int, row: bool = False) -> property:
    if row:
        def set_(s: Any, v: float) -> None:
            s._buf[i] = v
            _FILL(s._buf)
    else:
        def set_(s: Any, v: float) -> None:
            s._buf[i] = v
    return property(lambda s: s._buf.item(i), set_)


def _c(i: int, row: bool = False) -> property:
    def get(s: Any) -> complex:
        b = s._buf
        return complex(b.item(i), b.item(i + 1))

    def set_(s: Any, v: complex) -> None:
        v = complex(v)
        s._buf[i] = v.real
        s._buf[i + 1] = v.imag
        if row:
            _FILL(s._buf)

    return property(get, set_)


def _i(i: int, kind: type = int, row: bool = False) -> property:
    def set_(s: Any, v: int) -> None:
        s._iv[i] = int(v)
        if row:
            _FILL(s._buf)

    return property(lambda s: kind(s._iv.item(i)), set_)


def _opt(flag: int, value: property) -> property:
    """An optional value (None: flag 0) held in ``value``'s slot."""
    def get(s: Any) -> Any:
        return value.fget(s) if s._iv.item(flag) else None

    def set_(s: Any, v: Any) -> None:
        s._iv[flag] = v is not None
        value.fset(s, 0 if v is None else v)

    return property(get, set_)


def _sat() -> property:
    def set_(s: Any, v: bool) -> None:
        s._buf[SF.C_SAT] = 1.0 if v else 0.0
        _FILL(s._buf)

    return property(lambda s: s._buf.item(SF.C_SAT) != 0.0, set_)


def _hist() -> property:  # FocController._u_hist: the references of the last two ticks
    def get(s: Any) -> tuple[complex, complex]:
        b = s._buf
        return complex(b.item(SF.U_H0), b.item(SF.U_H0 + 1)), complex(b.item(SF.U_H1), b.item(SF.U_H1 + 1))

    def set_(s: Any, v: tuple[complex, complex]) -> None:
        a, b = complex(v[0]), complex(v[1])
        s._buf[SF.U_H0:SF.U_H1 + 2] = (a.real, a.imag, b.real, b.imag)

    return property(get, set_)


def _divs() -> property:  # FocController._div: (speed, flux, current) divisors
    return property(lambda s: tuple(s._iv[SI.DIV_W:SI.DIV_C + 1].tolist()),
                    lambda s, v: s._iv.__setitem__(slice(SI.DIV_W, SI.DIV_C + 1), tuple(int(d) for d in v)))


_VIEWS: dict[str, dict[str, property]] = {
    "encoder": {
        "modulus": _i(SI.E_MOD), "half": _i(SI.E_HALF), "k_omega": _f(SF.E_KW), "k_theta": _f(SF.E_KTH),
        "T_s": _f(SF.E_TS), "tau": _f(SF.E_TAU), "alpha": _f(SF.E_ALPHA), "_late": _f(SF.E_LATE),
        "_prev": _opt(SI.E_HAS_PREV, _i(SI.E_PREV)),
        "d": _i(SI.E_D), "_prev_t": _opt(SI.E_HAS_T, _f(SF.E_PREV_T)), "omega_r": _f(SF.E_WR, row=True),
        "omega_raw": _f(SF.E_WRAW), "theta_r": _f(SF.E_TH),
    },
    "observer": {"_b": _f(SF.O_B), "T_s": _f(SF.O_TS), "i_m": _c(SF.O_IM),
                 "_i_s_prev": _opt(SI.O_HAS_PREV, _c(SF.O_PREV))},
    "speed": {"k": _f(SF.S_K), "I_max": _f(SF.S_IMAX), "K_p": _f(SF.S_KP), "k_i": _f(SF.S_KI), "x": _f(SF.S_X),
              "m_e_ref": _f(SF.S_ME, row=True)},
    "flux": {"K_m": _f(SF.F_KM), "I_max": _f(SF.F_IMAX)},
    "fw": {"factor": _f(SF.FW_F, row=True), "u_fw": _f(SF.FW_U), "k": _f(SF.FW_K), "lo": _f(SF.FW_LO)},
    "current": {"K_p": _f(SF.C_KP), "k_i": _f(SF.C_KI), "Ls_p": _f(SF.C_LS), "Lm_p": _f(SF.C_LM), "Rr_p": _f(SF.C_RR),
                "x": _c(SF.C_X), "saturated": _sat()},
    "": {  # the FocController itself
        "k": _i(SI.K), "i_sd_ref": _f(SF.ISD_REF, row=True), "i_sq_ref": _f(SF.ISQ_REF, row=True),
        "u_sr": _c(SF.U_SR, row=True), "u_s_ref": _c(SF.U_S_REF), "_u_hist": _hist(), "i_m_hat": _c(SF.I_M, row=True),
        "i_mR_hat": _f(SF.I_MR, row=True), "omega_mR": _f(SF.W_MR, row=True), "_rot": _c(SF.ROT),
        "_oriented": _i(SI.ORIENTED, bool), "omega": _f(SF.OMEGA),
        "u_s_obs": _c(SF.U_OBS),
        "i_sr": _c(SF.I_SR, row=True), "_inv_Tr": _f(SF.INV_TR), "_advance": _f(SF.ADVANCE), "_u_scale": _f(SF.U_SCALE),
        "_div": _divs(), "_use_measured_u": _i(SI.MEAS_U, bool),
    },
}  # fmt: skip
_CLASSES: dict[tuple[str, type], type] = {}


def _view_class(part: str, cls: type) -> type:
    """``cls`` with its state attributes as properties on the buffer (one subclass per class, same name)."""
    key = (part, cls)
    if key not in _CLASSES:
        _CLASSES[key] = type(cls.__name__, (cls,), {"__module__": cls.__module__, "__qualname__": cls.__qualname__,
                                                     "__doc__": cls.__doc__, **_VIEWS[part]})  # fmt: skip
    return _CLASSES[key]


def _to_view(obj: Any, part: str, buf: np.ndarray) -> None:
    """Turn ``obj`` into a view on ``buf``: its attributes that the kernel uses move into the buffer."""
    state = dict(vars(obj))
    vars(obj).clear()
    obj.__class__ = _view_class(part, type(obj))
    obj._buf, obj._iv = buf, buf[NF:N_BUF].view(np.int64)
    for k, v in state.items():
        setattr(obj, k, v)


def _regions(ctrl: Any) -> list[tuple[int, int, Any, Any]]:
    """(slot of the region, kind, part, kernel module) of each part of ``ctrl`` this module does not hold itself;
    ValueError names a part no kernel covers."""

    out = []
    if not isinstance(ctrl.observer, CurrentModelObserver):
        out.append((SI.OBS_AT, oc.kind_of(ctrl.observer), ctrl.observer, oc))
    if ctrl.estimator is not None:
        out.append((SI.EST_AT, oc.kind_of(ctrl.estimator), ctrl.estimator, oc))
    for at, kind, part, pi in ((SI.SPD_AT, lc.SPEED_LPV, ctrl.speed, SpeedPI),
                               (SI.CUR_AT, lc.CURRENT_LPV, ctrl.current, CurrentPI)):  # fmt: skip
        if not isinstance(part, pi):
            try:
                lc.layout(part)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"no kernel for this {type(part).__name__}: {exc}") from None
            out.append((at, kind, part, lc))
    return out


def uncovered(ctrl: Any) -> str | None:
    """Why the kernels cannot run ``ctrl`` (a `FocController` on the Python engine), or None."""
    if ctrl._inv is not None:
        return "runs without the rig's [inverter_error] compensation"
    try:
        _regions(ctrl)
    except ValueError as exc:
        return f"has {exc}"
    return None


def attach(ctrl: Any) -> None:
    """Run ``ctrl`` (a `FocController` the kernels cover, `uncovered`) on the kernel: the encoder, flux, FOC, R_r
    estimate and the PI parts and current model as views on the buffer; the other parts packed into its tail
    regions (`pack_tails`, `unpack_tails`: their Python objects hold their state only between `unpack_tails` and
    `pack_tails`, which `FocController` does around its own Python code on them, e.g. ``reset``)."""
    regions = _regions(ctrl)
    sizes = [mod.layout(obj) for _, _, obj, mod in regions]
    buf = np.zeros(TAILS_AT + sum(nf + ni for nf, ni in sizes))
    iv = buf[NF:N_BUF].view(np.int64)
    a = TAILS_AT
    tails = []
    for (at, kind, obj, mod), (nf, ni) in zip(regions, sizes):
        iv[_KIND_OF[at]] = kind
        iv[at], iv[at + 1], iv[at + 2] = a, nf, ni
        tails.append((obj, mod, buf[a:a + nf], buf[a + nf:a + nf + ni].view(np.int64)))
        a += nf + ni
    ctrl._tails = tails
    pack_tails(ctrl)
    in_tails = [obj for obj, *_ in tails]
    _attach(ctrl, buf, views=[p for p in ("observer", "speed", "current")
                              if all(getattr(ctrl, p) is not o for o in in_tails)])  # fmt: skip
    iv[SI.SENSORLESS] = ctrl._sensorless


def pack_tails(ctrl: Any) -> None:
    """The tail parts' Python state into the buffer."""
    for obj, mod, x, iv in ctrl._tails:
        mod.pack(obj, x, iv)


def unpack_tails(ctrl: Any) -> None:
    """The tail parts' state from the buffer into their Python objects (exactly: the same floats)."""
    for obj, mod, x, iv in ctrl._tails:
        mod.unpack(obj, x, iv)


def pack(ctrl: Any) -> np.ndarray:
    """The state buffer of ``ctrl`` (a `FocController` on the Python engine) for the batch engine, with every part the
    kernels cover (`attach`); ``ctrl`` itself is not changed (a copy is attached). ValueError: not covered."""
    import copy

    why = "it takes a controller on the Python engine" if ctrl._kernel is not None else uncovered(ctrl)
    if why:
        raise ValueError(why)
    c = copy.deepcopy(ctrl)
    attach(c)
    return c._buf


_KIND_OF = {SI.OBS_AT: SI.OBS_KIND, SI.EST_AT: SI.EST_KIND, SI.SPD_AT: SI.SPD_KIND, SI.CUR_AT: SI.CUR_KIND}


def _attach(ctrl: Any, buf: np.ndarray, views: tuple[str, ...] | list[str] = ("observer", "speed", "current")) -> None:
    """``ctrl`` on ``buf``: the encoder, flux, FOC and the parts ``views`` as views; the row's length."""
    buf[SF.TWO] = 2.0
    for part in ("encoder", "flux", *views):
        _to_view(getattr(ctrl, part), part, buf)
    _to_view(ctrl, "", buf)
    n_row = N_ROW + (2 if ctrl.estimator is not None else 0) + (lc.N_SPEED_ROW if ctrl._speed_logs else 0)
    if ctrl.fw is not None:  # FieldWeakening
        _to_view(ctrl.fw, "fw", buf)
        ctrl._iv[SI.FW_ON] = 1
        n_row += 1
    rr = ctrl.rr
    if rr is not None:  # RrMRAS: its array is a region of the buffer from now on
        rr.view(buf[RR_AT:RR_END], logged=lambda: _FILL(buf))
        m = ctrl.ctx.motor  # (rr.motor and observer.motor: the same object, one L_r for R_r = b L_r and set_R_r)
        buf[SF.R_RR2] = (m.L_m / m.L_r) ** 2  # FocController._use_R_r: Rr_p = (L_m/L_r)**2 * R_r
        ctrl._iv[SI.R_ON] = 1
        n_row += 2
    ctrl._row = slice(SF.ROW, SF.ROW + n_row)
    ctrl._w_slot = SF.W_MR  # omega_mR, the field's frequency the drive turns a reference at through a stall
    ctrl._kernel = _STEP


def detach(ctrl: Any) -> None:
    """Back to the Python engine (a part switched while running): every view's values move from the buffer
    into plain attributes, exactly (the same floats), and the objects get their own classes back; the tail parts'
    state into their objects."""
    unpack_tails(ctrl)
    ctrl._tails = []
    if ctrl.rr is not None:
        ctrl.rr.view(None)  # an array of its own again
    for part in _VIEWS:
        obj = ctrl if part == "" else getattr(ctrl, part, None)
        if obj is None or "_buf" not in vars(obj):
            continue
        values = {name: getattr(obj, name) for name in _VIEWS[part]}
        obj.__class__ = type(obj).__mro__[1]
        del obj._buf, obj._iv
        for name, v in values.items():
            setattr(obj, name, v)
    ctrl._kernel = None
