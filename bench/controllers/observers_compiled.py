"""Compiled flux observers and speed estimators (numba), equal to their Python references to the last bit.

The batch engine and the compiled FOC tick (`bench.controllers.foc_compiled`, which holds the current model)
run the other parts of `bench.controllers.observers` and `bench.controllers.speed_estimators` here:

=====================  ========  ==================================================================
part                   kind      reference
=====================  ========  ==================================================================
voltage model          1         `VoltageModelObserver.update` (4.16)(4.17)
Jansen-Lorenz          2         `JansenLorenzObserver.update` (4.3.1)
Kubota                 3         `KubotaObserver.update` (4.20)(4.21), its ``omega_hat``
LPV                    4         `LPVObserver.update` (5.63)(5.64), any artifact it loads
Kubota speed           EST 1     `KubotaSpeed.update`, with its own observer or ``shared``
rotor-equation speed   EST 2     `RotorEquationSpeed.update` (4.19)
=====================  ========  ==================================================================

Each part lives in a float64 slice ``x`` and an int64 slice ``iv`` (`layout` gives their lengths, `pack` fills
them from the Python object, `unpack` writes the state back): constants (gains, matrices, T_s) and state,
a complex value as two slots (re, im), an optional value (``None``) as a flag in ``iv``. Every observer keeps
its latest estimate i_m in ``x[0:2]``; every estimator keeps ``omega_hat`` in ``xe[0]`` and ``omega_r`` (the
filtered estimate, ``internals()``' ``omega_est``) in ``xe[1]``.

The kernels take scalars (complex as (re, im) pairs) and allocate nothing:

* ``update(kind, x, iv, i_s_re, i_s_im, u_s_re, u_s_im, omega_r) -> (i_m_re, i_m_im)``
* ``est_update(kind, xe, ive, xo, ivo, i_s_re, i_s_im, u_s_re, u_s_im, i_m_re, i_m_im) -> omega_r``:
  ``xo``/``ivo`` are the FOC's flux-observer slices. A `KubotaSpeed` with ``shared`` (the FOC's
  `KubotaObserver`) reads the observer's ``omega_hat`` from there and does not step it; one with its own
  observer carries it in its own slices (from ``xe[EST_OBS_F]``, ``ive[EST_OBS_I]``) and steps it there.
* ``set_R_r(kind, x, iv, R_r)``, ``est_set_R_r(kind, xe, ive, R_r)``: the R_r hand-over (`rr_adapt`).
* ``est_omega_hat(xe)``, ``est_omega_r(xe)``: the estimator's two speeds.

``reset`` and ``take_over`` stay Python: `unpack`, call the method, `pack` again (the unpacked object continues
as the kernel would, tests/test_compiled_observers.py). The LPV layout does not depend on the artifact (the
runtime pads every design to order 2, as `LPVObserver` does).

Every part is written once, in its module (`bench.controllers.observers.voltage_model_step`, `jl_step`,
`kubota_step`, `lpv_observer_step`, `bench.controllers.speed_estimators.rotor_equation_speed`: plain Python on
complex numbers that numba compiles with CPython 3.11's arithmetic); this module compiles them and keeps their state
in the slices. The helpers they call for CPython's errors and special values (`bench.controllers.kernel_math`) are
registered for numba here. None uses numpy per tick.

numba's on-disk cache (``cache=True``) checks only the file of the function it caches: `bench.core.jit_cache` flushes
the cached kernels of every compiled module when any of their sources changed.
``python -m bench.perf.observers_compiled`` times the kernels against the Python updates.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numba.extending import register_jitable

from bench.controllers.observers import (JansenLorenzObserver, KubotaObserver, LPVObserver, VoltageModelObserver,
                                         CurrentModelObserver)
from bench.controllers.kernel_math import (abs_checked, atan2, ccosh, cexp as cexp_, crect, csinh, csqrt,
                                           csquare, finite, hyperbolic, square)
from bench.controllers.observers import jl_step, kubota_step, lpv_observer_step, voltage_model_step
from bench.controllers.speed_estimators import KubotaSpeed, RotorEquationSpeed, rotor_equation_speed
from bench.core.jit_cache import drop_stale
from bench.core.slots import slots

KIND_CURRENT_MODEL = 0  # in bench.controllers.foc_compiled
KIND_VOLTAGE_MODEL = 1
KIND_JL = 2
KIND_KUBOTA = 3
KIND_LPV = 4
EST_NONE = 0
EST_KUBOTA = 1
EST_ROTOR_EQUATION = 2

# --- slots ------------------------------------------------------------------------------------------------
# float slots by name and kind (`bench.core.slots`; "c": re, im; "cN": N complex numbers, a tuple or a row-major matrix)
IM = 0  # every observer: i_m (re, im)
# voltage model
SV = slots("VoltageModelSlots", IM="c", PSI="c", PREV="c", CPSI="f", CIS="f", DECAY="f", TS="f", RS="f")
V_NF, V_NI = SV.size, 1
V_HAS_PREV = 0
# Jansen-Lorenz
SJ = slots("JansenLorenzSlots", IM="c", PSI="c", G="c", RC="c", PREV="c", W1="c", W2="c", B="f", TS="f", LM="f", RS="f",
           LR="f", CIS="f", LRLM="f", INVLM="f", K1="c", F="c4", G0="c4", L="c4")  # fmt: skip
J_NF, J_NI = SJ.size, 2
J_HAS_PREV, J_HAS_W = 0, 1
# Kubota
SK = slots("KubotaSlots", IM="c", ISH="c", EIS="c", PREV="c", WI="f", WHAT="f", K="f", LAM="f", LAMP="f", B1="f",
           TS="f", RR="f", LR="f", LM2="f", DEN="f", RS="f", LR2="f")  # fmt: skip
K_NF, K_NI = SK.size, 2
K_HAS_PREV, K_ADAPT = 0, 1
# LPV
SL = slots("LPVObserverSlots", IM="c", X1="c", X2="c", UPREV="c", DELTA="f", INVW="f", NUM="c3", DEN="c3", C1="c5",
           C2="c4", A="c4", B1="c4", B2="c2")  # fmt: skip
L_NF, L_NI = SL.size, 3
L_HAS_UPREV, L_CLIPPED, L_EXTRAP = 0, 1, 2
# estimators: omega_hat, omega_r, alpha first
EST_OMEGA_HAT, EST_OMEGA_R, EST_ALPHA = 0, 1, 2
EK_SHARED = 0  # KubotaSpeed: int flag; its own observer (not shared) follows at EST_OBS_F / EST_OBS_I
EST_OBS_F, EST_OBS_I = 3, 1
SR = slots("RotorEquationSlots", OMEGA_HAT="f", OMEGA_R="f", ALPHA="f", PREV="c", RAW="f", INVTR="f", INVT="f", MIN="f",
           LR="f")  # fmt: skip
R_NF, R_NI = SR.size, 0



# --- the observers ----------------------------------------------------------------------------------------
# kernels written once in bench.controllers.observers and speed_estimators, compiled here; the helpers they call
# registered here (bench.controllers.foc_compiled imports this module first), so that the controllers' modules do not
# import numba
for _helper in (abs_checked, atan2, square, csquare, finite, cexp_, csqrt, hyperbolic, ccosh, csinh, crect):
    register_jitable(_helper)
_voltage_model_step = njit(voltage_model_step)
_jl_step = njit(jl_step)
_lpv_observer_step = njit(lpv_observer_step)
_kubota_step = njit(kubota_step)
_rotor_equation_speed = njit(rotor_equation_speed)


@njit(cache=True)
def _voltage_model(x, iv, sr, si, ur, ui):
    # VoltageModelObserver.update (bench.controllers.observers.voltage_model_step)
    prev = complex(sr, si) if iv[V_HAS_PREV] == 0 else complex(x[SV.PREV], x[SV.PREV + 1])
    x[SV.PREV], x[SV.PREV + 1] = sr, si
    iv[V_HAS_PREV] = 1
    psi, i_m = _voltage_model_step(complex(x[SV.PSI], x[SV.PSI + 1]), prev, complex(sr, si), complex(ur, ui), x[SV.RS],
                                   x[SV.DECAY], x[SV.TS], x[SV.CPSI], x[SV.CIS])  # fmt: skip
    x[SV.PSI], x[SV.PSI + 1], x[IM], x[IM + 1] = psi.real, psi.imag, i_m.real, i_m.imag
    return i_m.real, i_m.imag


@njit(cache=True)
def _c4(x, i):  # the 2x2 complex matrix at x[i:i + 8], row-major
    return (complex(x[i], x[i + 1]), complex(x[i + 2], x[i + 3]), complex(x[i + 4], x[i + 5]),
            complex(x[i + 6], x[i + 7]))  # fmt: skip


@njit(cache=True)
def _jl(x, iv, sr, si, ur, ui, w):
    # JansenLorenzObserver.update (bench.controllers.observers.jl_step)
    prev = complex(sr, si) if iv[J_HAS_PREV] == 0 else complex(x[SJ.PREV], x[SJ.PREV + 1])
    x[SJ.PREV], x[SJ.PREV + 1] = sr, si
    iv[J_HAS_PREV] = 1
    psi, g, rc, w1, e0, i_m = _jl_step(
        complex(x[SJ.PSI], x[SJ.PSI + 1]), complex(x[SJ.G], x[SJ.G + 1]), complex(x[SJ.RC], x[SJ.RC + 1]), prev,
        complex(x[SJ.W1], x[SJ.W1 + 1]), complex(x[SJ.W2], x[SJ.W2 + 1]), iv[J_HAS_W] != 0, complex(sr, si),
        complex(ur, ui), w, x[SJ.B], x[SJ.TS], x[SJ.LM], x[SJ.RS], x[SJ.CIS], complex(x[SJ.K1], x[SJ.K1 + 1]),
        _c4(x, SJ.F), _c4(x, SJ.G0), _c4(x, SJ.L), x[SJ.LRLM], x[SJ.INVLM])  # fmt: skip
    iv[J_HAS_W] = 1
    x[SJ.PSI], x[SJ.PSI + 1], x[SJ.G], x[SJ.G + 1] = psi.real, psi.imag, g.real, g.imag
    x[SJ.RC], x[SJ.RC + 1] = rc.real, rc.imag
    x[SJ.W1], x[SJ.W1 + 1], x[SJ.W2], x[SJ.W2 + 1] = w1.real, w1.imag, e0.real, e0.imag
    x[IM], x[IM + 1] = i_m.real, i_m.imag
    return i_m.real, i_m.imag


@njit(cache=True)
def _kubota(x, iv, sr, si, ur, ui, omega_r):
    # KubotaObserver.update (observers.kubota_step)
    i_s = complex(sr, si)
    prev = _c(x, SK.PREV) if iv[K_HAS_PREV] else i_s
    x[SK.PREV], x[SK.PREV + 1] = sr, si
    iv[K_HAS_PREV] = 1
    ish, i_m, e, x[SK.WI], x[SK.WHAT] = _kubota_step(
        i_s, complex(ur, ui), omega_r, prev, _c(x, SK.ISH), _c(x, IM), x[SK.WI], x[SK.WHAT], iv[K_ADAPT] != 0,
        x[SK.K], x[SK.LAM], x[SK.LAMP], x[SK.B1], x[SK.TS], x[SK.RR], x[SK.LR], x[SK.RS], x[SK.LM2], x[SK.DEN],
        x[SK.LR2])  # fmt: skip
    x[SK.ISH], x[SK.ISH + 1], x[IM], x[IM + 1], x[SK.EIS], x[SK.EIS + 1] = ish.real, ish.imag, i_m.real, i_m.imag, \
        e.real, e.imag
    return i_m.real, i_m.imag


@njit(cache=True)
def _c(x, i):  # the complex value at x[i:i + 2]
    return complex(x[i], x[i + 1])


@njit(cache=True)
def _lpv(x, iv, sr, si, ur, ui, omega_r):
    # LPVObserver.update (observers.lpv_observer_step)
    u_s = complex(ur, ui)
    u_prev = _c(x, SL.UPREV) if iv[L_HAS_UPREV] else u_s
    n, e, c, f = SL.NUM, SL.DEN, SL.C1, SL.C2
    i_m, x1, x2, x[SL.DELTA], clipped = _lpv_observer_step(
        complex(sr, si), u_s, omega_r, u_prev, iv[L_EXTRAP] != 0, x[SL.INVW], _c(x, SL.X1), _c(x, SL.X2),
        (_c(x, n), _c(x, n + 2), _c(x, n + 4)), (_c(x, e), _c(x, e + 2), _c(x, e + 4)),
        (_c(x, c), _c(x, c + 2), _c(x, c + 4), _c(x, c + 6), _c(x, c + 8)), _c4(x, f), _c4(x, SL.A), _c4(x, SL.B1),
        (_c(x, SL.B2), _c(x, SL.B2 + 2)))  # fmt: skip
    if iv[L_EXTRAP]:
        x[SL.UPREV], x[SL.UPREV + 1] = ur, ui
        iv[L_HAS_UPREV] = 1
    if clipped:
        iv[L_CLIPPED] += 1
    x[IM], x[IM + 1] = i_m.real, i_m.imag
    x[SL.X1], x[SL.X1 + 1], x[SL.X2], x[SL.X2 + 1] = x1.real, x1.imag, x2.real, x2.imag
    return i_m.real, i_m.imag


@njit(cache=True)
def update(kind, x, iv, i_s_re, i_s_im, u_s_re, u_s_im, omega_r):
    """FluxObserver.update(i_s, u_s, omega_r) of the part ``kind`` in (x, iv); returns i_m_hat (re, im)."""
    if kind == KIND_VOLTAGE_MODEL:
        return _voltage_model(x, iv, i_s_re, i_s_im, u_s_re, u_s_im)
    if kind == KIND_JL:
        return _jl(x, iv, i_s_re, i_s_im, u_s_re, u_s_im, omega_r)
    if kind == KIND_KUBOTA:
        return _kubota(x, iv, i_s_re, i_s_im, u_s_re, u_s_im, omega_r)
    if kind == KIND_LPV:
        return _lpv(x, iv, i_s_re, i_s_im, u_s_re, u_s_im, omega_r)
    raise ValueError("observers_compiled.update: unknown observer kind")


@njit(cache=True)
def _kubota_set_R_r(x, R_r):
    x[SK.RR] = R_r  # motor.with_(R_r=R_r): sc_matrix reads it every tick


@njit(cache=True)
def set_R_r(kind, x, iv, R_r):
    """FluxObserver.set_R_r(R_r): the parts with R_r at run time take it (JL's current model, Kubota's A_sc)."""
    if kind == KIND_JL:
        x[SJ.B] = R_r / x[SJ.LR]
    elif kind == KIND_KUBOTA:
        _kubota_set_R_r(x, R_r)


# --- the speed estimators -------------------------------------------------------------------------------------
@njit(cache=True)
def _rotor_equation(x, sr, si, mr, mi):
    # RotorEquationSpeed.update (bench.controllers.speed_estimators.rotor_equation_speed)
    prev = complex(x[SR.PREV], x[SR.PREV + 1])
    x[SR.PREV], x[SR.PREV + 1] = mr, mi
    ok, raw = _rotor_equation_speed(prev, complex(sr, si), complex(mr, mi), x[SR.MIN], x[SR.INVT], x[SR.INVTR])
    if not ok:
        return x[EST_OMEGA_R]
    x[SR.RAW] = raw
    x[EST_OMEGA_R] += x[EST_ALPHA] * (raw - x[EST_OMEGA_R])
    x[EST_OMEGA_HAT] = x[EST_OMEGA_R]
    return x[EST_OMEGA_R]


@njit(cache=True)
def est_update(kind, xe, ive, xo, ivo, i_s_re, i_s_im, u_s_re, u_s_im, i_m_re, i_m_im):
    """SpeedEstimator.update(i_s, u_s, i_m_hat) of the estimator ``kind`` in (xe, ive); returns omega_r (filtered).

    (xo, ivo): the FOC's flux observer. A shared KubotaSpeed reads its omega_hat there (the FOC stepped it this
    tick); a KubotaSpeed with its own observer steps that one (in xe, ive) with omega_r = 0.0."""
    if kind == EST_KUBOTA:
        if ive[EK_SHARED]:
            w = xo[SK.WHAT]
        else:
            xk, ik = xe[EST_OBS_F:], ive[EST_OBS_I:]
            _kubota(xk, ik, i_s_re, i_s_im, u_s_re, u_s_im, 0.0)
            w = xk[SK.WHAT]
        xe[EST_OMEGA_HAT] = w
        xe[EST_OMEGA_R] += xe[EST_ALPHA] * (w - xe[EST_OMEGA_R])
        return xe[EST_OMEGA_R]
    if kind == EST_ROTOR_EQUATION:
        return _rotor_equation(xe, i_s_re, i_s_im, i_m_re, i_m_im)
    raise ValueError("observers_compiled.est_update: unknown estimator kind")


@njit(cache=True)
def est_set_R_r(kind, xe, ive, R_r):
    """SpeedEstimator.set_R_r(R_r) (a shared Kubota observer gets it as the flux observer, not here)."""
    if kind == EST_KUBOTA:
        if not ive[EK_SHARED]:
            _kubota_set_R_r(xe[EST_OBS_F:], R_r)
    elif kind == EST_ROTOR_EQUATION:
        xe[SR.INVTR] = R_r / xe[SR.LR]


@njit(cache=True)
def est_omega_hat(xe):
    """The estimate the flux observer's rotation term uses next tick (sensorless mode)."""
    return xe[EST_OMEGA_HAT]


@njit(cache=True)
def est_omega_r(xe):
    """The filtered estimate (internals()' omega_est)."""
    return xe[EST_OMEGA_R]


# --- Python side: kinds, layouts, pack and unpack ---------------------------------------------------------------
def kind_of(obj: Any) -> int:
    """The kind constant of a flux observer (KIND_*) or speed estimator (EST_*; None: EST_NONE)."""
    if obj is None:
        return EST_NONE
    for cls, kind in ((CurrentModelObserver, KIND_CURRENT_MODEL), (VoltageModelObserver, KIND_VOLTAGE_MODEL),
                      (JansenLorenzObserver, KIND_JL), (KubotaObserver, KIND_KUBOTA), (LPVObserver, KIND_LPV),
                      (KubotaSpeed, EST_KUBOTA), (RotorEquationSpeed, EST_ROTOR_EQUATION)):  # fmt: skip
        if isinstance(obj, cls):
            return kind
    raise ValueError(f"observers_compiled: no kernel for {type(obj).__name__}")


def layout(obj: Any) -> tuple[int, int]:
    """(float64 slots, int64 slots) the part needs."""
    if obj is None:
        return 0, 0
    if isinstance(obj, KubotaSpeed):
        return (EST_OBS_F, EST_OBS_I) if obj.shared else (EST_OBS_F + K_NF, EST_OBS_I + K_NI)
    if isinstance(obj, CurrentModelObserver):
        raise ValueError("observers_compiled: the current model is bench.controllers.foc_compiled's")
    for cls, size in ((VoltageModelObserver, (V_NF, V_NI)), (JansenLorenzObserver, (J_NF, J_NI)),
                      (KubotaObserver, (K_NF, K_NI)), (LPVObserver, (L_NF, L_NI)), (RotorEquationSpeed, (R_NF, R_NI))):
        if isinstance(obj, cls):
            return size
    raise ValueError(f"observers_compiled: no kernel for {type(obj).__name__}")


def _put(x: np.ndarray, i: int, *values: complex) -> None:
    for n, v in enumerate(values):
        v = complex(v)
        x[i + 2 * n], x[i + 2 * n + 1] = v.real, v.imag


def _get(x: np.ndarray, i: int) -> complex:
    return complex(x.item(i), x.item(i + 1))


def _put_opt(x: np.ndarray, i: int, iv: np.ndarray, flag: int, v: complex | None) -> None:
    iv[flag] = v is not None
    _put(x, i, 0j if v is None else v)


def _get_opt(x: np.ndarray, i: int, iv: np.ndarray, flag: int) -> complex | None:
    return _get(x, i) if iv.item(flag) else None


def pack(obj: Any, x: np.ndarray, iv: np.ndarray) -> None:
    """Write the part (constants and current state) into the float64 slice ``x`` and the int64 slice ``iv``."""
    nf, ni = layout(obj)
    if len(x) < nf or len(iv) < ni:
        raise ValueError(f"observers_compiled.pack: {type(obj).__name__} needs {nf} float and {ni} int slots")
    if isinstance(obj, VoltageModelObserver):
        _put(x, IM, obj.i_m, obj.psi_s)
        _put_opt(x, SV.PREV, iv, V_HAS_PREV, obj._i_s_prev)
        x[SV.CPSI], x[SV.CIS], x[SV.DECAY] = obj._c_psi, obj._c_is, obj._decay
        x[SV.TS], x[SV.RS] = obj.T_s, obj.motor.R_s
    elif isinstance(obj, JansenLorenzObserver):
        _put(x, IM, obj.i_m, obj.psi_s, obj.g, obj.psi_rc)
        _put_opt(x, SJ.PREV, iv, J_HAS_PREV, obj._i_s_prev)
        iv[J_HAS_W] = obj._w_prev is not None
        _put(x, SJ.W1, *(obj._w_prev or (0j, 0j)))
        m = obj.motor
        x[SJ.B], x[SJ.TS], x[SJ.LM], x[SJ.RS], x[SJ.LR] = obj._b, obj.T_s, m.L_m, m.R_s, m.L_r
        x[SJ.CIS], x[SJ.LRLM], x[SJ.INVLM] = obj._c_is, obj._lr_lm, obj._inv_Lm
        _put(x, SJ.K1, obj.K1)
        _put(x, SJ.F, *obj._F)
        _put(x, SJ.G0, *obj._G)
        _put(x, SJ.L, *obj._L)
    elif isinstance(obj, KubotaObserver):
        _pack_kubota(obj, x, iv)
    elif isinstance(obj, LPVObserver):
        _put(x, IM, obj.i_m, obj.x1, obj.x2)
        _put_opt(x, SL.UPREV, iv, L_HAS_UPREV, obj._u_prev)
        iv[L_CLIPPED], iv[L_EXTRAP] = obj.clipped, obj._extrap
        x[SL.DELTA], x[SL.INVW] = obj.delta, obj._inv_wmax
        _put(x, SL.NUM, *obj._num)
        _put(x, SL.DEN, *obj._den)
        _put(x, SL.C1, *obj._C1)
        _put(x, SL.C2, *obj._C2)
        _put(x, SL.A, *obj._A)
        _put(x, SL.B1, *obj._B1)
        _put(x, SL.B2, *obj._B2)
    elif isinstance(obj, KubotaSpeed):
        x[EST_OMEGA_HAT], x[EST_OMEGA_R], x[EST_ALPHA] = obj.omega_hat, obj.omega_r, obj._alpha
        iv[EK_SHARED] = obj.shared
        if not obj.shared:
            _pack_kubota(obj.obs, x[EST_OBS_F:], iv[EST_OBS_I:])
    elif isinstance(obj, RotorEquationSpeed):
        x[EST_OMEGA_HAT], x[EST_OMEGA_R], x[EST_ALPHA] = obj.omega_hat, obj.omega_r, obj._alpha
        _put(x, SR.PREV, obj._prev)
        x[SR.RAW], x[SR.INVTR], x[SR.INVT] = obj.omega_raw, obj._inv_Tr, obj._inv_T
        x[SR.MIN], x[SR.LR] = obj._min, obj.motor.L_r
    else:
        layout(obj)  # raises


def _pack_kubota(obj: KubotaObserver, x: np.ndarray, iv: np.ndarray) -> None:
    _put(x, IM, obj.i_m, obj.i_s_hat, obj.e_is)
    _put_opt(x, SK.PREV, iv, K_HAS_PREV, obj._i_s_prev)
    iv[K_ADAPT] = obj._adapt
    x[SK.WI], x[SK.WHAT], x[SK.K], x[SK.LAM], x[SK.LAMP] = obj.omega_i, obj.omega_hat, obj._k, obj._lam, obj._lam_p
    m = obj.motor
    x[SK.B1], x[SK.TS], x[SK.RR], x[SK.LR], x[SK.RS] = obj._b1, obj.T_s, m.R_r, m.L_r, m.R_s
    # sc_matrix's motor-only terms, by its own expressions
    x[SK.LM2], x[SK.DEN], x[SK.LR2] = m.L_m**2, m.L_r * (m.L_m**2 - m.L_s * m.L_r), m.L_r**2


def unpack(obj: Any, x: np.ndarray, iv: np.ndarray) -> None:
    """Write the kernel's state (and the R_r it was handed) back into the Python object."""
    if isinstance(obj, VoltageModelObserver):
        obj.i_m, obj.psi_s = _get(x, IM), _get(x, SV.PSI)
        obj._i_s_prev = _get_opt(x, SV.PREV, iv, V_HAS_PREV)
    elif isinstance(obj, JansenLorenzObserver):
        obj.i_m, obj.psi_s, obj.g, obj.psi_rc = _get(x, IM), _get(x, SJ.PSI), _get(x, SJ.G), _get(x, SJ.RC)
        obj._i_s_prev = _get_opt(x, SJ.PREV, iv, J_HAS_PREV)
        obj._w_prev = (_get(x, SJ.W1), _get(x, SJ.W2)) if iv.item(J_HAS_W) else None
        obj._b = x.item(SJ.B)
    elif isinstance(obj, KubotaObserver):
        _unpack_kubota(obj, x, iv)
    elif isinstance(obj, LPVObserver):
        obj.i_m, obj.x1, obj.x2 = _get(x, IM), _get(x, SL.X1), _get(x, SL.X2)
        obj._u_prev = _get_opt(x, SL.UPREV, iv, L_HAS_UPREV)
        obj.clipped, obj.delta = iv.item(L_CLIPPED), x.item(SL.DELTA)
    elif isinstance(obj, KubotaSpeed):
        obj.omega_hat, obj.omega_r = x.item(EST_OMEGA_HAT), x.item(EST_OMEGA_R)
        if not obj.shared:
            _unpack_kubota(obj.obs, x[EST_OBS_F:], iv[EST_OBS_I:])
    elif isinstance(obj, RotorEquationSpeed):
        obj.omega_hat, obj.omega_r = x.item(EST_OMEGA_HAT), x.item(EST_OMEGA_R)
        obj._prev, obj.omega_raw, obj._inv_Tr = _get(x, SR.PREV), x.item(SR.RAW), x.item(SR.INVTR)
    else:
        layout(obj)  # raises


def _unpack_kubota(obj: KubotaObserver, x: np.ndarray, iv: np.ndarray) -> None:
    obj.i_m, obj.i_s_hat, obj.e_is = _get(x, IM), _get(x, SK.ISH), _get(x, SK.EIS)
    obj._i_s_prev = _get_opt(x, SK.PREV, iv, K_HAS_PREV)
    obj.omega_i, obj.omega_hat = x.item(SK.WI), x.item(SK.WHAT)
    R_r = x.item(SK.RR)
    if np.float64(R_r).tobytes() != np.float64(obj.motor.R_r).tobytes():
        obj.set_R_r(R_r)


drop_stale(globals())  # (bench.core.jit_cache: numba's cache knows only this file's date)
