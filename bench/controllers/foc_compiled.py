"""Compiled FOC tick (numba): `FocController.step` in one call, equal to the Python reference to the last bit.

``engine = "compiled"`` (or ``"auto"``) of `bench.controllers.foc.FocController` runs its tick here for the
configuration the kernel covers: the current-model observer (4.15), the speed PI with the current-limited
torque bound (4.7)(4.8), the flux P, the complex current PI with decoupling (4.13)(4.14), omega_mR (4.5),
encoder speed (no speed estimator), any divisors, reference or measured observer voltage, any gains,
delay compensation, voltage margin and speed filter. `FocController` (and its parts `SpeedPI`, `FluxP`,
`CurrentPI`, `bench.encoder.EncoderSpeed`, `bench.controllers.observers.CurrentModelObserver`) stays the
reference; every operation of its tick is written here in the order CPython evaluates it, complex
arithmetic included (`bench.cpython_arith`: CPython 3.11 turns a float operand into ``complex(x, 0.0)``),
so the logs agree bit for bit (tests/test_compiled_foc.py).

State: one contiguous float64 buffer; its tail is viewed as int64 (the encoder count, flags, the tick
counter, the divisors). The controller and its parts stay the same Python objects, with their state and
gains as properties on the buffer (`attach`), so ``retune``, ``reset`` and anything reading or setting
``ctrl.speed.x``, ``ctrl.i_sd_ref``, ``ctrl.encoder.omega_raw``, ... act as with the Python engine. The
kernel also leaves the row of ``internals()`` in the buffer (setting a logged value from Python refreshes
it), so reading it is one slice.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit, types

from bench.controllers.foc import I_MR_FLOOR
from bench.cpython_arith import abs_, atan2_, cexp, cmul, cquot, crect, entry, fmul, fsq
from bench.hal import SQRT3_INV

# --- buffer layout ------------------------------------------------------------------------------
# float slots (a complex value takes two: re, im)
(E_KW, E_KTH, E_TS, E_TAU, E_ALPHA, E_LATE, E_PREV_T, E_WR, E_WRAW, E_TH,  # EncoderSpeed
 O_B, O_TS, O_IM, _O_IM_IM, O_PREV, _O_PREV_IM,  # CurrentModelObserver
 S_K, S_IMAX, S_KP, S_KI, S_X, S_ME,  # SpeedPI
 F_KM, F_IMAX,  # FluxP
 C_KP, C_KI, C_X, _C_X_IM, C_SAT, C_LS, C_LM, C_RR,  # CurrentPI (saturated: 0.0 / 1.0)
 ISD_REF, ISQ_REF, U_SR, _U_SR_IM, U_S_REF, _U_S_REF_IM, U_H0, _U_H0_IM, U_H1, _U_H1_IM,  # FocController
 I_M, _I_M_IM, I_MR, W_MR, ROT, _ROT_IM, OMEGA, U_OBS, _U_OBS_IM, I_SR, _I_SR_IM, INV_TR, ADVANCE, U_SCALE,
 TWO,  # 2.0, the exponent of x ** 2 given at run time (bench.cpython_arith.fsq)
 ROW,  # the internals() row: FocController.fields, 14 values
 ) = range(58)  # fmt: skip
N_ROW = 14
NF = ROW + N_ROW  # float slots
# int slots (offsets into the int64 view of buf[NF:])
(E_MOD, E_HALF, E_PREV, E_HAS_PREV, E_D, E_HAS_T,  # EncoderSpeed (_prev, _prev_t: flag 0 = None)
 O_HAS_PREV,  # CurrentModelObserver._i_s_prev is not None
 K, DIV_W, DIV_F, DIV_C, MEAS_U,  # FocController: tick counter, divisors, voltage_source = measured
 ) = range(12)  # fmt: skip
N_BUF = NF + 12


# --- the tick ----------------------------------------------------------------------------------------
@njit
def _encoder(x, iv, count, t):
    # EncoderSpeed.update(count, t)
    if iv[E_HAS_PREV] == 0:
        d = 0
    else:
        d = (count - iv[E_PREV]) % iv[E_MOD]  # Python's int %: numba's too
        if d >= iv[E_HALF]:
            d -= iv[E_MOD]
    iv[E_PREV] = count
    iv[E_HAS_PREV] = 1
    iv[E_D] = d
    x[E_TH] += d * x[E_KTH]
    alpha = x[E_ALPHA]
    dt = x[E_TS] if iv[E_HAS_T] == 0 else t - x[E_PREV_T]
    x[E_PREV_T] = t
    iv[E_HAS_T] = 1
    if dt > x[E_LATE]:  # skipped ticks
        x[E_WRAW] = d * x[E_KW] * x[E_TS] / dt
        tau = x[E_TAU]
        alpha = 1.0 - math.exp(-dt / tau) if tau > 0 else 1.0
        x[E_WR] += alpha * (x[E_WRAW] - x[E_WR])
        return x[E_WR]
    x[E_WRAW] = d * x[E_KW]
    x[E_WR] += alpha * (x[E_WRAW] - x[E_WR])
    return x[E_WR]


@njit
def _observer(x, iv, sr, si, w):
    # CurrentModelObserver.update(i_s, u_s, omega_r): the current model (4.15), exact for omega_r held
    if iv[O_HAS_PREV] == 0:
        pr, pi = sr, si
    else:
        pr, pi = x[O_PREV], x[O_PREV + 1]
    x[O_PREV], x[O_PREV + 1] = sr, si
    iv[O_HAS_PREV] = 1
    b = x[O_B]
    ar, ai = -b, w  # a = complex(-b, omega_r)
    zr, zi = cmul(ar, ai, x[O_TS], 0.0)  # a * T_s
    fr, fi = cexp(zr, zi)  # phi
    t1r, t1i = cmul(fr, fi, x[O_IM], x[O_IM + 1])  # phi * i_m
    qr, qi = cquot(fr - 1.0, fi - 0.0, ar, ai)  # (phi - 1.0) / a
    qr, qi = cmul(qr, qi, b, 0.0)  # * b
    qr, qi = cmul(qr, qi, 0.5, 0.0)  # * 0.5
    qr, qi = cmul(qr, qi, pr + sr, pi + si)  # * (prev + i_s)
    mr, mi = t1r + qr, t1i + qi
    x[O_IM], x[O_IM + 1] = mr, mi
    return mr, mi


@njit
def _flux(x, i_mR_ref, i_mR):
    # FluxP.update: P control of i_mR, reference premultiplied by (K_m+1)/K_m
    K_m = x[F_KM]
    i_sd = K_m * ((K_m + 1.0) / K_m * i_mR_ref - i_mR)
    lim = x[F_IMAX]
    i_sd = -lim if -lim > i_sd else i_sd
    return lim if lim < i_sd else i_sd


@njit
def _speed(x, omega_ref, omega, i_mR, i_sd_ref):
    # SpeedPI.update: torque bound (4.8), conditional integration, i_sq_ref (4.7)
    if I_MR_FLOOR > i_mR:
        i_mR = I_MR_FLOOR
    r = fsq(x[S_IMAX], x[TWO]) - fsq(i_sd_ref, x[TWO])
    m_max = x[S_K] * i_mR * math.sqrt(0.0 if 0.0 > r else r)  # (4.8)
    e = omega_ref - omega
    u = x[S_KP] * e + x[S_X]
    m = -m_max if -m_max > u else u
    if m > m_max:
        m = m_max
    if m == u or (u > m_max and e < 0.0) or (u < -m_max and e > 0.0):
        x[S_X] += x[S_KI] * e
    xi = x[S_X]
    xi = -m_max if -m_max > xi else xi
    x[S_X] = m_max if m_max < xi else xi
    x[S_ME] = m
    return m / (x[S_K] * i_mR)  # (4.7)


@njit
def _current(x, i_sd_ref, i_sq_ref, i_sd, i_sq, omega_mR, i_mR, u_max):
    # CurrentPI.update: complex PI with decoupling (4.13)(4.14), back-calculation at |u_sr| = u_max
    er, ei = i_sd_ref - i_sd, i_sq_ref - i_sq  # e = i_ref - i_sr
    ffr = -omega_mR * x[C_LS] * i_sq + x[C_RR] * (i_sd - i_mR)  # (4.13)
    ffi = omega_mR * x[C_LS] * i_sd + x[C_LM] * omega_mR * i_mR  # (4.14)
    kp = x[C_KP]
    a, b = fmul(kp, er, ei)
    ur, ui = a + x[C_X], b + x[C_X + 1]
    ur, ui = ur + ffr, ui + ffi
    mag = abs_(ur, ui)
    if mag > u_max:
        if mag == 0.0:  # u_max < 0: CPython's message, not numba's
            raise ZeroDivisionError("float division by zero")
        lr, li = cmul(ur, ui, u_max / mag, 0.0)
        qr, qi = cquot(lr - ur, li - ui, kp, 0.0)
        a, b = fmul(x[C_KI], er + qr, ei + qi)
        x[C_X], x[C_X + 1] = x[C_X] + a, x[C_X + 1] + b
        x[C_SAT] = 1.0
        return lr, li
    a, b = fmul(x[C_KI], er, ei)
    x[C_X], x[C_X + 1] = x[C_X] + a, x[C_X + 1] + b
    x[C_SAT] = 0.0
    return ur, ui


@njit
def _row(x):
    # FocController.internals() without a speed estimator
    r = ROW
    x[r] = x[E_WR]
    x[r + 1], x[r + 2], x[r + 3] = x[I_M], x[I_M + 1], x[I_MR]
    x[r + 4] = atan2_(x[I_M + 1], x[I_M])
    x[r + 5], x[r + 6], x[r + 7] = x[W_MR], x[I_SR], x[I_SR + 1]
    x[r + 8], x[r + 9], x[r + 10] = x[ISD_REF], x[ISQ_REF], x[S_ME]
    x[r + 11], x[r + 12], x[r + 13] = x[U_SR], x[U_SR + 1], x[C_SAT]


_F = types.float64
_SIG = types.complex128(types.float64[::1], _F, _F, _F, _F, _F, _F, _F, types.int64, _F, _F, _F)


@njit([_SIG], cache=True)
def step(buf, t, i_a, i_b, i_c, u_a, u_b, u_c, enc_count, u_dc, omega_ref, i_mR_ref):
    """FocController.step for one measurement (its scalar fields); returns u_s_ref, leaves the internals row."""
    x = buf[:NF]
    iv = buf[NF:].view(np.int64)
    k = iv[K]
    iv[K] = k + 1
    omega = _encoder(x, iv, enc_count, t)
    sr, si = (2.0 * i_a - i_b - i_c) / 3.0, (i_b - i_c) * SQRT3_INV  # meas.i_s (bench.hal.space_vector)
    if iv[MEAS_U]:
        ur, ui = (2.0 * u_a - u_b - u_c) / 3.0, (u_b - u_c) * SQRT3_INV  # meas.u_s
    else:
        ur, ui = x[U_H1], x[U_H1 + 1]
    x[U_OBS], x[U_OBS + 1] = ur, ui
    # the observer gets the unfiltered per-sample speed
    mr, mi = _observer(x, iv, sr, si, x[E_WRAW])
    x[OMEGA] = omega
    i_mR = abs_(mr, mi)
    if i_mR > I_MR_FLOOR:
        rr, ri = cquot(mr, -mi, i_mR, 0.0)  # e^{-j rho} = conj(i_m) / |i_m|
        x[ROT], x[ROT + 1] = rr, ri
    else:
        rr, ri = x[ROT], x[ROT + 1]
    isr, isi = cmul(sr, si, rr, ri)
    x[I_M], x[I_M + 1], x[I_MR], x[I_SR], x[I_SR + 1] = mr, mi, i_mR, isr, isi
    w_mR = omega + x[INV_TR] * isi / (I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR)  # (4.5)
    x[W_MR] = w_mR
    if k % iv[DIV_F] == 0:
        x[ISD_REF] = _flux(x, i_mR_ref, i_mR)
    if k % iv[DIV_W] == 0:
        x[ISQ_REF] = _speed(x, omega_ref, omega, i_mR, x[ISD_REF])
    if k % iv[DIV_C] == 0:
        u_max = u_dc * x[U_SCALE]
        x[U_SR], x[U_SR + 1] = _current(x, x[ISD_REF], x[ISQ_REF], isr, isi, w_mR, i_mR, u_max)
    adv = w_mR * x[ADVANCE]
    ar, ai = cmul(x[U_SR], x[U_SR + 1], rr, -ri)  # u_sr * rot.conjugate()
    cr, ci = crect(1.0, adv)
    ur, ui = cmul(ar, ai, cr, ci)  # * cmath.rect(1.0, adv)
    x[U_S_REF], x[U_S_REF + 1] = ur, ui
    x[U_H1], x[U_H1 + 1] = x[U_H0], x[U_H0 + 1]
    x[U_H0], x[U_H0 + 1] = ur, ui
    _row(x)
    return complex(ur, ui)


@njit(types.void(types.float64[::1]), cache=True)
def fill_row(buf):
    """Recompute the internals row from the state (after Python code set a logged value)."""
    _row(buf[:NF])


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


def _i(i: int, kind: type = int) -> property:
    return property(lambda s: kind(s._iv.item(i)), lambda s, v: s._iv.__setitem__(i, int(v)))


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
        s._buf[C_SAT] = 1.0 if v else 0.0
        _FILL(s._buf)

    return property(lambda s: s._buf.item(C_SAT) != 0.0, set_)


def _hist() -> property:  # FocController._u_hist: the references of the last two ticks
    def get(s: Any) -> tuple[complex, complex]:
        b = s._buf
        return complex(b.item(U_H0), b.item(U_H0 + 1)), complex(b.item(U_H1), b.item(U_H1 + 1))

    def set_(s: Any, v: tuple[complex, complex]) -> None:
        a, b = complex(v[0]), complex(v[1])
        s._buf[U_H0:U_H1 + 2] = (a.real, a.imag, b.real, b.imag)

    return property(get, set_)


def _divs() -> property:  # FocController._div: (speed, flux, current) divisors
    return property(lambda s: tuple(s._iv[DIV_W:DIV_C + 1].tolist()),
                    lambda s, v: s._iv.__setitem__(slice(DIV_W, DIV_C + 1), tuple(int(d) for d in v)))


_VIEWS: dict[str, dict[str, property]] = {
    "encoder": {
        "modulus": _i(E_MOD), "half": _i(E_HALF), "k_omega": _f(E_KW), "k_theta": _f(E_KTH), "T_s": _f(E_TS),
        "tau": _f(E_TAU), "alpha": _f(E_ALPHA), "_late": _f(E_LATE), "_prev": _opt(E_HAS_PREV, _i(E_PREV)),
        "d": _i(E_D), "_prev_t": _opt(E_HAS_T, _f(E_PREV_T)), "omega_r": _f(E_WR, row=True),
        "omega_raw": _f(E_WRAW), "theta_r": _f(E_TH),
    },
    "observer": {"_b": _f(O_B), "T_s": _f(O_TS), "i_m": _c(O_IM), "_i_s_prev": _opt(O_HAS_PREV, _c(O_PREV))},
    "speed": {"k": _f(S_K), "I_max": _f(S_IMAX), "K_p": _f(S_KP), "k_i": _f(S_KI), "x": _f(S_X),
              "m_e_ref": _f(S_ME, row=True)},
    "flux": {"K_m": _f(F_KM), "I_max": _f(F_IMAX)},
    "current": {"K_p": _f(C_KP), "k_i": _f(C_KI), "Ls_p": _f(C_LS), "Lm_p": _f(C_LM), "Rr_p": _f(C_RR), "x": _c(C_X),
                "saturated": _sat()},
    "": {  # the FocController itself
        "k": _i(K), "i_sd_ref": _f(ISD_REF, row=True), "i_sq_ref": _f(ISQ_REF, row=True), "u_sr": _c(U_SR, row=True),
        "u_s_ref": _c(U_S_REF), "_u_hist": _hist(), "i_m_hat": _c(I_M, row=True), "i_mR_hat": _f(I_MR, row=True),
        "omega_mR": _f(W_MR, row=True), "_rot": _c(ROT), "omega": _f(OMEGA), "u_s_obs": _c(U_OBS),
        "i_sr": _c(I_SR, row=True), "_inv_Tr": _f(INV_TR), "_advance": _f(ADVANCE), "_u_scale": _f(U_SCALE),
        "_div": _divs(), "_use_measured_u": _i(MEAS_U, bool),
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
    obj._buf, obj._iv = buf, buf[NF:].view(np.int64)
    for k, v in state.items():
        setattr(obj, k, v)


def attach(ctrl: Any) -> None:
    """Run ``ctrl`` (a `FocController` of a supported configuration, built but not yet reset) on the kernel."""
    buf = np.zeros(N_BUF)
    buf[TWO] = 2.0
    for part in ("encoder", "observer", "speed", "flux", "current"):
        _to_view(getattr(ctrl, part), part, buf)
    _to_view(ctrl, "", buf)
    ctrl._row = slice(ROW, ROW + N_ROW)
    ctrl._kernel = _STEP


def detach(ctrl: Any) -> None:
    """Back to the Python engine (a part switched while running): every view's values move from the buffer
    into plain attributes, exactly (the same floats), and the objects get their own classes back."""
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
