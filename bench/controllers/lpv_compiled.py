"""The LPV current and speed controllers compiled (numba) on a region of the FOC's buffer.

The parts' kernels are written once, in their modules: `bench.controllers.lpv_current.current_update`,
`bench.controllers.lpv_speed.speed_update` and the law's `bench.controllers.lpv_law.evaluate_into`, `step22`,
`solve_into` (thesis (5.36), (5.57), 6.2.2, 6.4.3). The Python engine calls them on the law's lists of Python numbers;
this module compiles them on views of a float64 slice ``x`` and an int64 slice ``iv`` (complex matrices as complex128
views), so the two give the same bits (tests/test_compiled_lpv.py, the golden logs).

Interface (the FOC buffer and the batch kernel hold a part as two slices):

- `layout(obj)` -> (float64 slots, int64 slots) the part needs (its matrices' sizes);
- `pack(obj, x, iv)` writes the constants (matrices, motor numbers, limits) and the state into them,
  `unpack(obj, x, iv)` writes the kernel's state back into the Python object (its next Python ``update``
  then gives the same bits as the kernel's);
- ``current_update(x, iv, i_ref_re, i_ref_im, i_sr_re, i_sr_im, omega_mR, i_mR, u_max) -> (u_re, u_im)``,
  leaving ``saturated`` (0.0 / 1.0), ``delta1``, ``delta2`` and ``clipped`` (0.0 / 1.0) in the slots
  `CU.SAT`, `CU.DELTA1`, `CU.DELTA2`, `CU.CLIPPED`;
- ``speed_update(x, iv, omega_ref, omega, i_mR, i_sd_ref) -> i_sq_ref``, leaving ``m_e_ref`` in `SP.ME`,
  ``saturated`` in `SP.SAT` and the row of ``internals()`` (4 values) in ``x[SP.ROW:SP.ROW + N_SPEED_ROW]``.

The divisor (the part runs at its artifact's rate) stays with the caller (``obj.divisor(T_base)``). Only the per-tick
``update`` is compiled: ``take_over`` (numpy least squares) and ``reset`` run in Python on an unpacked object, which
is then packed again. Its cost against the Python ``update``: `bench.perf.lpv_compiled`. numba's on-disk cache checks
this file only: `bench.core.jit_cache` flushes its entries when a module whose functions or constants it compiles
changed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit
from numba.extending import register_jitable

from bench.controllers import lpv_current as cur, lpv_law as law_, lpv_speed as spd
from bench.controllers import observers_compiled  # noqa: F401 (registers bench.controllers.kernel_math for numba)
from bench.controllers.lpv_current import LPVCurrentController, current_update as current_kernel
from bench.controllers.lpv_law import N_OF, OF, commit, evaluate_into
from bench.controllers.lpv_speed import LPVSpeedController, speed_update as speed_kernel
from bench.core.jit_cache import drop_stale
from bench.core.slots import slots

SPEED_LPV = 1  # the kind of speed part (foc_compiled's PI: 0)
CURRENT_LPV = 1  # the kind of current part (foc_compiled's PI: 0)

for _kernel in (law_.clip, law_.dot, law_.commit, law_.solve_into, law_.delta_c_into, law_.evaluate_into,
                law_.step22, cur.scheduling, cur.current_update, spd.shift, spd.schedule_into, spd.speed_update):
    register_jitable(_kernel)

# --- a ScheduledLaw's block ---------------------------------------------------------------------------------------
# int slots from the block's int base: complex (0 / 1), the law's dims, then its `lpv_law.OF` offsets into the part's
# x: the entries' in entries of the law (x viewed as complex for a complex law), the reals' (LAM, D) in floats
LW = slots("ScheduledLawInts", CPLX="i", DIMS="i7", O=f"i{N_OF}")
N_LAW_I = type(LW).size

# --- the current part ---------------------------------------------------------------------------------------------
CU = slots("LPVCurrentSlots", D1MAX="f", D2MAX="f",  # the design box (delta1_max [rad/s], delta2_max)
           SAT="f", CLIPPED="f", DELTA1="f", DELTA2="f")  # logged: saturated, clipped (0.0 / 1.0), delta1, delta2
NF_CURRENT = type(CU).size  # the law's stores follow
CI = slots("LPVCurrentInts", PATH="i",  # 0 lpv_law.step22, 1 the generic lpv_law.evaluate_into
           LAW=f"i{N_LAW_I}")  # the law's int block

# --- the speed part -----------------------------------------------------------------------------------------------
N_SPEED_ROW = 4
SP = slots("LPVSpeedSlots", W0="f", SW="f", I0="f", SI="f", D0="f", SD="f", T0="f", ST="f",  # scaling (6.4.2)
           IMAX="f", KT="f", TWO="f",  # I_max, the torque constant, 2.0 (kernel_math.square's exponent at run time)
           TAU_PREV="f", ME="f", ISD_LPV="f", SAT="f",  # state: tau~_{k-1}, m_e_ref, i_sd_lpv, saturated (0.0 / 1.0)
           ROW=f"f{N_SPEED_ROW}")  # internals(): delta_1, delta_2, i_sd_lpv, active  # fmt: skip
NF_SPEED = type(SP).size  # then the part's store (histories, scheduling map) and the law's stores
SPI = slots("LPVSpeedInts", ACTIVE="i", ITER="i",  # active (0 / 1), iterations
            N="i", NIH="i", NDH="i", NX="i", NCU="i",  # LPVSpeedController._hdims
            SO="i8",  # the starts (floats) of the part's store's blocks (lpv_speed.schedule_into)
            LAW=f"i{N_LAW_I}")  # the law's int block  # fmt: skip


@njit
def _complex_entries(x):  # the slots as complex numbers (a complex entry's float offset is even)
    return x[:len(x) // 2 * 2].view(np.complex128)


@njit
def _dims(iv, lb):
    p = lb + LW.DIMS
    return iv[p], iv[p + 1], iv[p + 2], iv[p + 3], iv[p + 4], iv[p + 5], iv[p + 6]


def _stepper(entries: Any, zero: Any) -> Any:
    @njit
    def step(x, iv, lb):
        e, o, dims = entries(x), iv[lb + LW.O:lb + LW.O + N_OF], _dims(iv, lb)
        evaluate_into(e, x, o, dims, zero)
        commit(e, o, dims[0])

    return step


@njit
def _real_entries(x):
    return x


_complex_step, _real_step = _stepper(_complex_entries, 0j), _stepper(_real_entries, 0.0)


@njit(cache=True)
def law_step(x, iv, lb):
    """`ScheduledLaw.step` on a law's block (y and Δ in their blocks): u to its block, the state advanced (tests)."""
    if iv[lb + LW.CPLX]:
        _complex_step(x, iv, lb)
    else:
        _real_step(x, iv, lb)


# --- the parts' updates -------------------------------------------------------------------------------------------
@njit(cache=True)
def current_update(x, iv, i_ref_re, i_ref_im, i_sr_re, i_sr_im, omega_mR, i_mR, u_max):
    """LPVCurrentController.update: (u_re, u_im); saturated, clipped, delta1, delta2 left in their slots."""
    lb = CI.LAW
    u, sat, clipped, d1, d2 = current_kernel(_complex_entries(x), x, iv[lb + LW.O:lb + LW.O + N_OF], _dims(iv, lb),
                                             iv[CI.PATH] == 0, x[CU.D1MAX], x[CU.D2MAX], complex(i_ref_re, i_ref_im),
                                             complex(i_sr_re, i_sr_im), omega_mR, i_mR, u_max)  # fmt: skip
    x[CU.SAT], x[CU.CLIPPED] = 1.0 if sat else 0.0, 1.0 if clipped else 0.0
    x[CU.DELTA1], x[CU.DELTA2] = d1, d2
    return u.real, u.imag


@njit(cache=True)
def speed_update(x, iv, omega_ref, omega, i_mR, i_sd_ref):
    """LPVSpeedController.update: i_sq_ref [A]; m_e_ref, saturated and the internals row left in their slots."""
    lb = SPI.LAW
    o, dims = iv[lb + LW.O:lb + LW.O + N_OF], _dims(iv, lb)
    scaling = (x[SP.W0], x[SP.SW], x[SP.I0], x[SP.SI], x[SP.D0], x[SP.SD], x[SP.T0], x[SP.ST], x[SP.IMAX], x[SP.KT],
               x[SP.TWO])  # fmt: skip
    state = (iv[SPI.ACTIVE] != 0, x[SP.TAU_PREV], x[SP.ME], x[SP.ISD_LPV], x[SP.SAT] != 0.0)
    hdims = (iv[SPI.N], iv[SPI.NIH], iv[SPI.NDH], iv[SPI.ITER], iv[SPI.NX], iv[SPI.NCU])
    i_sq, state = speed_kernel(x, x, o, dims, 0.0, x, iv[SPI.SO:SPI.SO + 8], hdims, scaling, state, omega_ref, omega,
                               i_mR, i_sd_ref)  # fmt: skip
    active, x[SP.TAU_PREV], x[SP.ME], x[SP.ISD_LPV], sat = state
    iv[SPI.ACTIVE], x[SP.SAT] = 1 if active else 0, 1.0 if sat else 0.0
    m, pd = dims[5], o[OF.D]
    x[SP.ROW] = x[pd] if m else 0.0  # internals()
    x[SP.ROW + 1] = x[pd + 1] if m > 1 else 0.0
    x[SP.ROW + 2] = x[SP.ISD_LPV]
    x[SP.ROW + 3] = 1.0 if active else 0.0
    return i_sq


# --- layout, pack, unpack -----------------------------------------------------------------------------------------
def _law_of(obj: Any) -> Any:
    """The part's `ScheduledLaw` (complex for the current part, real for the speed part)."""
    if isinstance(obj, LPVCurrentController):
        if not obj.law.generic.complex:
            raise ValueError("the LPV current law is complex")
        return obj.law.generic
    if isinstance(obj, LPVSpeedController):
        if obj.law.complex:
            raise ValueError("the LPV speed law is real (a complex one has no real torque output)")
        return obj.law
    raise TypeError(f"not an LPV part: {type(obj).__name__}")


def _law_block(law: Any, f0: int) -> tuple[list[int], int]:
    """The law's int block (`LW`) with its stores from float f0 (the reals, then the entries from an even slot for a
    complex law), and the end of its floats."""
    es = 2 if law.complex else 1
    rb = f0
    eb = rb + len(law.r)
    eb += eb % es
    o = [eb // es + v for v in law.o[:OF.LAM]] + [rb + v for v in law.o[OF.LAM:]]
    return [int(law.complex), *law.dims, *o], eb + es * len(law.e)


def _put_law(law: Any, x: np.ndarray, block: list[int]) -> None:
    """The law's stores into x at the block's offsets."""
    rb, eb = block[LW.O + OF.LAM], block[LW.O + OF.AC] * (2 if law.complex else 1)
    x[rb:rb + len(law.r)] = law.r
    _put(x, eb, law.e, law.complex)


def _get_law(law: Any, x: np.ndarray, block: Any) -> None:
    """The law's stores from x."""
    rb, eb = int(block[LW.O + OF.LAM]), int(block[LW.O + OF.AC]) * (2 if law.complex else 1)
    law.r[:] = _get(x, rb, len(law.r), False)
    law.e[:] = _get(x, eb, len(law.e), law.complex)


def _plan(obj: Any) -> tuple[Any, list[int], list[int], int, int]:
    """(the law, the part's int slots before the law's block, the law's block, n_float, n_int)."""
    law = _law_of(obj)
    if isinstance(obj, LPVCurrentController):
        block, nf = _law_block(law, NF_CURRENT)
        return law, [0 if obj.law.step22 else 1], block, nf, CI.LAW + N_LAW_I
    n, nih, ndh, iterations, nx, ncu = obj._hdims
    head = [0, iterations, n, nih, ndh, nx, ncu, *(NF_SPEED + v for v in obj._so)]
    block, nf = _law_block(law, NF_SPEED + len(obj._s))
    return law, head, block, nf, SPI.LAW + N_LAW_I


def layout(obj: Any) -> tuple[int, int]:
    """(float64 slots, int64 slots) the part (an `LPVCurrentController` or `LPVSpeedController`) needs."""
    *_, nf, ni = _plan(obj)
    return nf, ni


def _put(x: np.ndarray, p: int, values: Any, cplx: bool) -> None:
    a = np.asarray(values, dtype=complex if cplx else float).ravel()
    if cplx:
        x[p:p + 2 * a.size:2], x[p + 1:p + 2 * a.size:2] = a.real, a.imag
    else:
        x[p:p + a.size] = a


def _get(x: np.ndarray, p: int, n: int, cplx: bool) -> list[Any]:
    if cplx:
        return [complex(x.item(p + 2 * k), x.item(p + 2 * k + 1)) for k in range(n)]
    return [x.item(p + k) for k in range(n)]


def pack(obj: Any, x: np.ndarray, iv: np.ndarray) -> None:
    """The part's constants and state into ``x`` (float64, `layout`'s first size) and ``iv`` (int64)."""
    law, head, block, nf, ni = _plan(obj)
    if len(x) < nf or len(iv) < ni:
        raise ValueError(f"the part needs {nf} float and {ni} int slots, got {len(x)} and {len(iv)}")
    x[:nf] = 0.0
    iv[:ni] = 0
    iv[:len(head)] = head
    iv[len(head):ni] = block
    _put_law(law, x, block)
    if isinstance(obj, LPVCurrentController):
        x[CU.D1MAX], x[CU.D2MAX] = obj.law.delta1_max, obj.law.delta2_max
        x[CU.SAT], x[CU.CLIPPED] = float(obj.saturated), float(obj.clipped)
        x[CU.DELTA1], x[CU.DELTA2] = obj.delta1, obj.delta2
        return
    o = obj
    iv[SPI.ACTIVE] = int(o.active)
    x[SP.W0:SP.TWO + 1] = o._scaling
    x[SP.TAU_PREV], x[SP.ME], x[SP.ISD_LPV], x[SP.SAT] = o._tau_prev, o.m_e_ref, o.i_sd_lpv, float(o.saturated)
    x[NF_SPEED:NF_SPEED + len(o._s)] = o._s
    x[SP.ROW:SP.ROW + N_SPEED_ROW] = o.internals()


def unpack(obj: Any, x: np.ndarray, iv: np.ndarray) -> None:
    """The kernel's state from ``x``/``iv`` back into the part (plain Python floats, complex and bools)."""
    law = _law_of(obj)
    if isinstance(obj, LPVCurrentController):
        _get_law(law, x, iv[CI.LAW:])
        obj.saturated, obj.clipped = x.item(CU.SAT) != 0.0, x.item(CU.CLIPPED) != 0.0
        obj.delta1, obj.delta2 = x.item(CU.DELTA1), x.item(CU.DELTA2)
        return
    _get_law(law, x, iv[SPI.LAW:])
    obj.active = bool(iv[SPI.ACTIVE])
    obj._s[:] = _get(x, NF_SPEED, len(obj._s), False)
    obj._tau_prev, obj.m_e_ref, obj.i_sd_lpv = x.item(SP.TAU_PREV), x.item(SP.ME), x.item(SP.ISD_LPV)
    obj.saturated = x.item(SP.SAT) != 0.0


drop_stale(globals())  # (bench.core.jit_cache: numba's cache knows only this file's date)
