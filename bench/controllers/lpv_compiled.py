"""Compiled LPV parts (numba): the LPV current and speed controllers' ``update``, equal to Python to the last bit.

`current_update` is `bench.controllers.lpv_current.LPVCurrentController.update` (the scheduling deltas (6.17),
`LPVCurrentLaw.step` - its unrolled ``_step22`` for m_c = k_c = 2, which both shipped artifacts (600 Hz and
3 kHz) take, else the generic `bench.controllers.lpv_law.ScheduledLaw` path with complex entries - and the
voltage limit); `speed_update` is `bench.controllers.lpv_speed.LPVSpeedController.update` (the scaled
histories, the scheduling (6.28), ``iterations`` re-evaluations, `ScheduledLaw.evaluate` (5.36)(5.57) with
`solve_small` op for op - the closed-form 2 x 2 inverse that the shipped designs use, Gaussian elimination
with partial pivoting otherwise - and the torque bound (4.8)). The Python classes stay the reference; every
operation is written as CPython 3.11 evaluates it (`bench.core.cpython_arith`: a float operand of complex
arithmetic is ``complex(x, 0.0)``; ``sum`` over a generator adds left to right from int 0, which for these
operands is the same as starting from 0.0 / 0j; ``x ** 2`` is ``pow``), so the outputs, the logged values
and the state agree bit for bit (tests/test_compiled_lpv.py). A real law (the speed designs) runs real
arithmetic, a complex one complex arithmetic: the two are not interchangeable to the bit.

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

The divisor (the part runs at its artifact's rate) stays with the caller (``obj.divisor(T_base)``). The
kernels allocate nothing: the scheduling's and the solver's intermediates have scratch slots in ``x``.
Only the per-tick ``update`` is compiled: ``take_over`` (numpy least squares) and ``reset`` run in Python on
an unpacked object, which is then packed again. Its cost against the Python ``update``: `bench.perf.lpv_compiled`,
recorded in docs/results/speed-controllers.md.

The reference is Python floats in, as the FOC passes them: numpy scalars (``np.float64``) would turn the
Python law's complex arithmetic into numpy's, whose division rounds differently. numba's on-disk cache checks
this file only: `bench.core.jit_cache` flushes its entries when `bench.core.cpython_arith` or a Python module whose
constants it takes (`I_MR_FLOOR`, `START_I_MR`) changed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from bench.controllers.foc import I_MR_FLOOR
from bench.controllers.lpv_current import LPVCurrentController
from bench.controllers.lpv_speed import START_I_MR, LPVSpeedController
from bench.core.cpython_arith import abs_, cmul, cquot, fmul, fsq
from bench.core.jit_cache import drop_stale
from bench.core.slots import slots

SPEED_LPV = 1  # the kind of speed part (foc_compiled's PI: 0)
CURRENT_LPV = 1  # the kind of current part (foc_compiled's PI: 0)

# --- a ScheduledLaw's block ---------------------------------------------------------------------------------------
# int slots from the block's int base: sizes, then float offsets (into the part's x) of the matrices (row-major; a
# complex entry takes two slots re, im, a real one one), the state, and the scratch of one evaluation
LW = slots("ScheduledLawInts", CPLX="i", NC="i", NY="i", NU="i", MC="i", KC="i", M="i", NK="i",
           AC="i", BC1="i", BC2="i", CC1="i", DC11="i", DC12="i", CC2="i", DC21="i", DC22="i", Q="i", S="i", R="i",
           UW="i", UZ="i",
           LAM="i",  # the N's diagonal, real (one slot each)
           X="i",  # the state x_c
           Y="i", D="i",  # inputs: y (entries), Δ's diagonal (real)
           U="i", XN="i",  # outputs of `_evaluate`: u and the next state
           # scratch: V, M, M^{-1} V_+, Δ_c, z̃, L, v, w_c, the elimination
           V="i", MM="i", XS="i", DC="i", ZT="i", L="i", VV="i", WC="i", A="i")  # fmt: skip
N_LAW_I = type(LW).size
_MATS = ("_Ac", "_Bc1", "_Bc2", "_Cc1", "_Dc11", "_Dc12", "_Cc2", "_Dc21", "_Dc22", "_Q", "_S", "_R", "_Uw", "_Uz")

# --- the current part ---------------------------------------------------------------------------------------------
CU = slots("LPVCurrentSlots", D1MAX="f", D2MAX="f",  # the design box (delta1_max [rad/s], delta2_max)
           SAT="f", CLIPPED="f", DELTA1="f", DELTA2="f")  # logged: saturated, clipped (0.0 / 1.0), delta1, delta2
NF_CURRENT = type(CU).size  # the law's block follows
CI = slots("LPVCurrentInts", PATH="i",  # 0 LPVCurrentLaw._step22, 1 its generic path (ScheduledLaw, complex)
           LAW=f"i{N_LAW_I}")  # the law's int block

# --- the speed part -----------------------------------------------------------------------------------------------
N_SPEED_ROW = 4
SP = slots("LPVSpeedSlots", W0="f", SW="f", I0="f", SI="f", D0="f", SD="f", T0="f", ST="f",  # scaling (6.4.2)
           IMAX="f", KT="f", TWO="f",  # I_max, the torque constant, 2.0 (the exponent of x ** 2, given at run time)
           TAU_PREV="f", ME="f", ISD_LPV="f", SAT="f",  # state: tau~_{k-1}, m_e_ref, i_sd_lpv, saturated (0.0 / 1.0)
           ROW=f"f{N_SPEED_ROW}")  # internals(): delta_1, delta_2, i_sd_lpv, active  # fmt: skip
NF_SPEED = type(SP).size  # then the scheduling map, the histories and the law's block
SPI = slots("LPVSpeedInts", ACTIVE="i", ITER="i",  # active (0 / 1), iterations
            N="i", NIH="i", NDH="i", NX="i", NCU="i",  # len(_w), len(_ih), len(_dh) = len(_th), len(x) in _schedule,
            # len(C_u[j]); then float offsets
            HIST="i", X0="i", U0="i", CU="i", EU="i", TB="i", C="i", H="i",
            LAW=f"i{N_LAW_I}")  # the law's int block  # fmt: skip


# --- ScheduledLaw: arithmetic on (re, im) pairs, real or complex ---------------------------------------------------
def _law_kernels(c: bool) -> tuple[Any, Any, Any]:
    """(evaluate, solve, dot) for a real (``c`` false) or complex law: ``c`` is a constant of the compiled code."""
    es = 2 if c else 1  # slots per entry

    @njit
    def _ld(x, p):
        if c:
            return x[p], x[p + 1]
        return x[p], 0.0

    @njit
    def _st(x, p, re, im):
        x[p] = re
        if c:
            x[p + 1] = im

    @njit
    def _mul(ar, ai, br, bi):  # entry * entry
        if c:
            return cmul(ar, ai, br, bi)
        return ar * br, 0.0

    @njit
    def _fmul(f, re, im):  # float * entry
        if c:
            return fmul(f, re, im)
        return f * re, 0.0

    @njit
    def _div(ar, ai, br, bi):  # entry / entry
        if c:
            return cquot(ar, ai, br, bi)
        if br == 0.0:
            raise ZeroDivisionError("float division by zero")
        return ar / br, 0.0

    @njit
    def _abs(re, im):
        if c:
            return abs_(re, im)
        return abs(re)

    @njit
    def _dot(x, pa, pb, n):  # sum(a * b for a, b in zip(row, vec))
        sr, si = 0.0, 0.0
        for k in range(n):
            ar, ai = _ld(x, pa + es * k)
            br, bi = _ld(x, pb + es * k)
            tr, ti = _mul(ar, ai, br, bi)
            sr += tr
            si += ti
        return sr, si


    @njit
    def _solve(x, n, nb, pM, pB, bs, pX, pA):
        # solve_small(M, B): M (n x n) at pM, B (n x nb, rows bs entries apart) at pB, X (n x nb) to pX; scratch pA
        if n == 2:  # _inv2, closed form
            ar, ai = _ld(x, pM)
            br, bi = _ld(x, pM + es)
            cr, ci = _ld(x, pM + 2 * es)
            dr, di = _ld(x, pM + 3 * es)
            t1r, t1i = _mul(ar, ai, dr, di)
            t2r, t2i = _mul(br, bi, cr, ci)
            er, ei = t1r - t2r, t1i - t2i  # det
            i00r, i00i = _div(dr, di, er, ei)
            i01r, i01i = _div(-br, -bi, er, ei)
            i10r, i10i = _div(-cr, -ci, er, ei)
            i11r, i11i = _div(ar, ai, er, ei)
            for j in range(nb):
                xr, xi = _ld(x, pB + es * j)
                yr, yi = _ld(x, pB + es * (bs + j))
                pr, pi = _mul(i00r, i00i, xr, xi)
                qr, qi = _mul(i01r, i01i, yr, yi)
                _st(x, pX + es * j, pr + qr, pi + qi)
                pr, pi = _mul(i10r, i10i, xr, xi)
                qr, qi = _mul(i11r, i11i, yr, yi)
                _st(x, pX + es * (nb + j), pr + qr, pi + qi)
            return
        w = n + nb  # Gaussian elimination with partial pivoting on A = [M B]
        for i in range(n):
            for j in range(n):
                vr, vi = _ld(x, pM + es * (i * n + j))
                _st(x, pA + es * (i * w + j), vr, vi)
            for j in range(nb):
                vr, vi = _ld(x, pB + es * (i * bs + j))
                _st(x, pA + es * (i * w + n + j), vr, vi)
        for col in range(n):
            p = col  # max(range(col, n), key=abs(A[r][col])): the first of the largest
            vr, vi = _ld(x, pA + es * (col * w + col))
            best = _abs(vr, vi)
            for r in range(col + 1, n):
                vr, vi = _ld(x, pA + es * (r * w + col))
                v = _abs(vr, vi)
                if v > best:
                    p, best = r, v
            if p != col:
                for j in range(es * w):
                    a, b = pA + es * col * w + j, pA + es * p * w + j
                    x[a], x[b] = x[b], x[a]
            pr, pi = _ld(x, pA + es * (col * w + col))
            for r in range(col + 1, n):
                vr, vi = _ld(x, pA + es * (r * w + col))
                fr, fi = _div(vr, vi, pr, pi)
                if fr != 0.0 or fi != 0.0:  # `if f:` (NaN is true; a real f has fi = 0.0)
                    for j in range(col, w):
                        ar, ai = _ld(x, pA + es * (col * w + j))
                        tr, ti = _mul(fr, fi, ar, ai)
                        ar, ai = _ld(x, pA + es * (r * w + j))
                        _st(x, pA + es * (r * w + j), ar - tr, ai - ti)
        for r in range(n - 1, -1, -1):
            for j in range(nb):
                sr, si = 0.0, 0.0
                for k in range(r + 1, n):
                    ar, ai = _ld(x, pA + es * (r * w + k))
                    br, bi = _ld(x, pX + es * (k * nb + j))
                    tr, ti = _mul(ar, ai, br, bi)
                    sr += tr
                    si += ti
                ar, ai = _ld(x, pA + es * (r * w + n + j))
                dr, di = _ld(x, pA + es * (r * w + r))
                qr, qi = _div(ar - sr, ai - si, dr, di)
                _st(x, pX + es * (r * nb + j), qr, qi)

    @njit
    def _delta_c(x, iv, lb):
        # ScheduledLaw.delta_c: Δ_c(Δ) of (5.36) for Δ = diag(D), to LW.DC (m_c x (nk - m_c))
        m, mc, nk = iv[lb + LW.M], iv[lb + LW.MC], iv[lb + LW.NK]
        nb = nk - mc
        oD, oLam, oV, oMM, oDC = iv[lb + LW.D], iv[lb + LW.LAM], iv[lb + LW.V], iv[lb + LW.MM], iv[lb + LW.DC]
        oQ, oS, oR, oUw, oUz = iv[lb + LW.Q], iv[lb + LW.S], iv[lb + LW.R], iv[lb + LW.UW], iv[lb + LW.UZ]
        for i in range(m):  # V = S^* U
            di = x[oD + i]
            for k in range(nk):
                q = es * (i * nk + k)
                wr, wi = _ld(x, oUw + q)
                zr, zi = _ld(x, oUz + q)
                tr, ti = _fmul(di, wr, wi)
                _st(x, oV + q, tr + zr, ti + zi)
        for i in range(m):  # M = S^*PS − V_− N_− V_−^*
            di = x[oD + i]
            for j in range(m):
                dj = x[oD + j]
                ar, ai = _ld(x, oQ + es * (i * m + j))
                ar, ai = _fmul(di * dj, ar, ai)
                br, bi = _ld(x, oS + es * (i * m + j))
                br, bi = _fmul(di, br, bi)
                ar, ai = ar + br, ai + bi
                br, bi = _ld(x, oS + es * (j * m + i))
                br, bi = _fmul(dj, br, -bi)
                ar, ai = ar + br, ai + bi
                br, bi = _ld(x, oR + es * (i * m + j))
                ar, ai = ar + br, ai + bi
                sr, si = 0.0, 0.0
                for k in range(mc):
                    vr, vi = _ld(x, oV + es * (i * nk + k))
                    tr, ti = _mul(vr, vi, x[oLam + k], 0.0)
                    vr, vi = _ld(x, oV + es * (j * nk + k))
                    tr, ti = _mul(tr, ti, vr, -vi)
                    sr += tr
                    si += ti
                _st(x, oMM + es * (i * m + j), ar - sr, ai - si)
        oXS = iv[lb + LW.XS]
        _solve(x, m, nb, oMM, oV + es * mc, nk, oXS, iv[lb + LW.A])  # M^{-1} V_+
        for r in range(mc):
            lr = x[oLam + r]
            for k in range(nb):
                sr, si = 0.0, 0.0
                for i in range(m):
                    vr, vi = _ld(x, oV + es * (i * nk + r))
                    br, bi = _ld(x, oXS + es * (i * nb + k))
                    tr, ti = _mul(vr, -vi, br, bi)
                    sr += tr
                    si += ti
                tr, ti = _fmul(lr, sr, si)
                _st(x, oDC + es * (r * nb + k), tr, ti)

    @njit
    def _evaluate(x, iv, lb):
        # ScheduledLaw.evaluate(y = LW.Y, d = LW.D): u to LW.U and the next state to LW.XN; the state LW.X unchanged
        nc, ny, nu, mc, kc = iv[lb + LW.NC], iv[lb + LW.NY], iv[lb + LW.NU], iv[lb + LW.MC], iv[lb + LW.KC]
        oX, oY, oWC = iv[lb + LW.X], iv[lb + LW.Y], iv[lb + LW.WC]
        if mc:
            _delta_c(x, iv, lb)
            nb = iv[lb + LW.NK] - mc
            oDC, oZT, oL, oVV = iv[lb + LW.DC], iv[lb + LW.ZT], iv[lb + LW.L], iv[lb + LW.VV]
            oCc2, oDc21, oDc22 = iv[lb + LW.CC2], iv[lb + LW.DC21], iv[lb + LW.DC22]
            for i in range(kc):
                ar, ai = _dot(x, oCc2 + es * i * nc, oX, nc)
                br, bi = _dot(x, oDc21 + es * i * ny, oY, ny)
                _st(x, oZT + es * i, ar + br, ai + bi)
            for i in range(kc):  # L = I − D_c22 Δ_c
                for j in range(kc):
                    sr, si = 0.0, 0.0
                    for r in range(mc):
                        ar, ai = _ld(x, oDc22 + es * (i * mc + r))
                        br, bi = _ld(x, oDC + es * (r * nb + j))
                        tr, ti = _mul(ar, ai, br, bi)
                        sr += tr
                        si += ti
                    e = 1.0 if i == j else 0.0
                    _st(x, oL + es * (i * kc + j), e - sr, 0.0 - si)
            _solve(x, kc, 1, oL, oZT, 1, oVV, iv[lb + LW.A])  # v = L^{-1} z̃
            for r in range(mc):  # w_c = Δ_c v
                ar, ai = _dot(x, oDC + es * r * nb, oVV, kc)
                _st(x, oWC + es * r, ar, ai)
        oU, oXN = iv[lb + LW.U], iv[lb + LW.XN]
        oCc1, oDc11, oDc12 = iv[lb + LW.CC1], iv[lb + LW.DC11], iv[lb + LW.DC12]
        for i in range(nu):
            ar, ai = _dot(x, oCc1 + es * i * nc, oX, nc)
            br, bi = _dot(x, oDc11 + es * i * ny, oY, ny)
            cr, ci = _dot(x, oDc12 + es * i * mc, oWC, mc)
            _st(x, oU + es * i, ar + br + cr, ai + bi + ci)
        oAc, oBc1, oBc2 = iv[lb + LW.AC], iv[lb + LW.BC1], iv[lb + LW.BC2]
        for i in range(nc):
            ar, ai = _dot(x, oAc + es * i * nc, oX, nc)
            br, bi = _dot(x, oBc1 + es * i * ny, oY, ny)
            cr, ci = _dot(x, oBc2 + es * i * mc, oWC, mc)
            _st(x, oXN + es * i, ar + br + cr, ai + bi + ci)

    return _evaluate, _solve, _dot


_evaluate_r, _solve_r, _ = _law_kernels(False)
_evaluate_c, _solve_c, _cdot = _law_kernels(True)


@njit
def _commit(x, iv, lb):
    # self.x = xn
    n = iv[lb + LW.NC] * (2 if iv[lb + LW.CPLX] else 1)
    oX, oXN = iv[lb + LW.X], iv[lb + LW.XN]
    for k in range(n):
        x[oX + k] = x[oXN + k]


@njit(cache=True)
def law_step(x, iv, lb):
    """ScheduledLaw.step(y = LW.Y, d = LW.D): u to LW.U, the state advanced (for tests of the generic law)."""
    if iv[lb + LW.CPLX]:
        _evaluate_c(x, iv, lb)
    else:
        _evaluate_r(x, iv, lb)
    _commit(x, iv, lb)


@njit(cache=True)
def solve_small(x, iv, c, n, nb, pM, pB, pX, pA):
    """bench.controllers.lpv_law.solve_small on slots (for tests): M n x n at pM, B n x nb at pB, X to pX."""
    if c:
        _solve_c(x, n, nb, pM, pB, nb, pX, pA)
    else:
        _solve_r(x, n, nb, pM, pB, nb, pX, pA)


# --- LPVCurrentLaw._step22 ----------------------------------------------------------------------------------------
@njit
def _cl(x, p):
    return x[p], x[p + 1]


@njit
def _diag(d, qr, qi, sr, si, rr, ri):  # d * d * q + d * (s + s.conjugate()) + r, as Python evaluates it
    mr, mi = fmul(d * d, qr, qi)
    tr, ti = fmul(d, sr + sr, si + -si)
    return mr + tr + rr, mi + ti + ri


@njit
def _cross(dx, dy, qr, qi, sxr, sxi, syr, syi, rr, ri):  # dx * dy * q + dx * sx + dy * sy.conjugate() + r
    mr, mi = fmul(dx * dy, qr, qi)
    tr, ti = fmul(dx, sxr, sxi)
    mr, mi = mr + tr, mi + ti
    tr, ti = fmul(dy, syr, -syi)
    return mr + tr + rr, mi + ti + ri


@njit
def _minus_lxy(mr, mi, l, xr, xi, yr, yi):  # m - l * x * y.conjugate(), as Python evaluates it
    tr, ti = fmul(l, xr, xi)
    tr, ti = cmul(tr, ti, yr, -yi)
    return mr - tr, mi - ti


@njit
def _mul_add(ar, ai, br, bi, cr, ci, dr, di):  # a * b + c * d
    tr, ti = cmul(ar, ai, br, bi)
    ur, ui = cmul(cr, ci, dr, di)
    return tr + ur, ti + ui


@njit
def _mul_sub(ar, ai, br, bi, cr, ci, dr, di):  # a * b - c * d
    tr, ti = cmul(ar, ai, br, bi)
    ur, ui = cmul(cr, ci, dr, di)
    return tr - ur, ti - ui


@njit
def _step22(x, iv, lb, yr, yi, d1, d2):
    oQ, oS, oR = iv[lb + LW.Q], iv[lb + LW.S], iv[lb + LW.R]
    oUw, oUz, oLam = iv[lb + LW.UW], iv[lb + LW.UZ], iv[lb + LW.LAM]
    q00r, q00i = _cl(x, oQ)
    q01r, q01i = _cl(x, oQ + 2)
    q10r, q10i = _cl(x, oQ + 4)
    q11r, q11i = _cl(x, oQ + 6)
    s00r, s00i = _cl(x, oS)
    s01r, s01i = _cl(x, oS + 2)
    s10r, s10i = _cl(x, oS + 4)
    s11r, s11i = _cl(x, oS + 6)
    r00r, r00i = _cl(x, oR)
    r01r, r01i = _cl(x, oR + 2)
    r10r, r10i = _cl(x, oR + 4)
    r11r, r11i = _cl(x, oR + 6)
    l0, l1 = x[oLam], x[oLam + 1]
    # V = Δ U_w + U_z: a = row 0 (d1), b = row 1 (d2)
    tr, ti = fmul(d1, x[oUw], x[oUw + 1])
    a0r, a0i = tr + x[oUz], ti + x[oUz + 1]
    tr, ti = fmul(d1, x[oUw + 2], x[oUw + 3])
    a1r, a1i = tr + x[oUz + 2], ti + x[oUz + 3]
    tr, ti = fmul(d1, x[oUw + 4], x[oUw + 5])
    a2r, a2i = tr + x[oUz + 4], ti + x[oUz + 5]
    tr, ti = fmul(d1, x[oUw + 6], x[oUw + 7])
    a3r, a3i = tr + x[oUz + 6], ti + x[oUz + 7]
    tr, ti = fmul(d2, x[oUw + 8], x[oUw + 9])
    b0r, b0i = tr + x[oUz + 8], ti + x[oUz + 9]
    tr, ti = fmul(d2, x[oUw + 10], x[oUw + 11])
    b1r, b1i = tr + x[oUz + 10], ti + x[oUz + 11]
    tr, ti = fmul(d2, x[oUw + 12], x[oUw + 13])
    b2r, b2i = tr + x[oUz + 12], ti + x[oUz + 13]
    tr, ti = fmul(d2, x[oUw + 14], x[oUw + 15])
    b3r, b3i = tr + x[oUz + 14], ti + x[oUz + 15]
    # m00 = d1 * d1 * q00 + d1 * (s00 + s00.conjugate()) + r00 - l0 * a0 * a0.conjugate() - l1 * a1 * a1.conjugate()
    mr, mi = _diag(d1, q00r, q00i, s00r, s00i, r00r, r00i)
    mr, mi = _minus_lxy(mr, mi, l0, a0r, a0i, a0r, a0i)
    m00r, m00i = _minus_lxy(mr, mi, l1, a1r, a1i, a1r, a1i)
    # m01 = d1 * d2 * q01 + d1 * s01 + d2 * s10.conjugate() + r01 - l0 * a0 * b0.conjugate() - l1 * a1 * b1.conjugate()
    mr, mi = _cross(d1, d2, q01r, q01i, s01r, s01i, s10r, s10i, r01r, r01i)
    mr, mi = _minus_lxy(mr, mi, l0, a0r, a0i, b0r, b0i)
    m01r, m01i = _minus_lxy(mr, mi, l1, a1r, a1i, b1r, b1i)
    # m10 = d2 * d1 * q10 + d2 * s10 + d1 * s01.conjugate() + r10 - l0 * b0 * a0.conjugate() - l1 * b1 * a1.conjugate()
    mr, mi = _cross(d2, d1, q10r, q10i, s10r, s10i, s01r, s01i, r10r, r10i)
    mr, mi = _minus_lxy(mr, mi, l0, b0r, b0i, a0r, a0i)
    m10r, m10i = _minus_lxy(mr, mi, l1, b1r, b1i, a1r, a1i)
    # m11 = d2 * d2 * q11 + d2 * (s11 + s11.conjugate()) + r11 - l0 * b0 * b0.conjugate() - l1 * b1 * b1.conjugate()
    mr, mi = _diag(d2, q11r, q11i, s11r, s11i, r11r, r11i)
    mr, mi = _minus_lxy(mr, mi, l0, b0r, b0i, b0r, b0i)
    m11r, m11i = _minus_lxy(mr, mi, l1, b1r, b1i, b1r, b1i)
    # det = m00 * m11 - m01 * m10
    dtr, dti = _mul_sub(m00r, m00i, m11r, m11i, m01r, m01i, m10r, m10i)
    # M^{-1} V_+
    p0r, p0i = cquot(*_mul_sub(m11r, m11i, a2r, a2i, m01r, m01i, b2r, b2i), dtr, dti)
    p1r, p1i = cquot(*_mul_sub(m11r, m11i, a3r, a3i, m01r, m01i, b3r, b3i), dtr, dti)
    t0r, t0i = cquot(*_mul_sub(m00r, m00i, b2r, b2i, m10r, m10i, a2r, a2i), dtr, dti)
    t1r, t1i = cquot(*_mul_sub(m00r, m00i, b3r, b3i, m10r, m10i, a3r, a3i), dtr, dti)
    # Δ_c = N_− V_−^* M^{-1} V_+
    c00r, c00i = fmul(l0, *_mul_add(a0r, -a0i, p0r, p0i, b0r, -b0i, t0r, t0i))
    c01r, c01i = fmul(l0, *_mul_add(a0r, -a0i, p1r, p1i, b0r, -b0i, t1r, t1i))
    c10r, c10i = fmul(l1, *_mul_add(a1r, -a1i, p0r, p0i, b1r, -b1i, t0r, t0i))
    c11r, c11i = fmul(l1, *_mul_add(a1r, -a1i, p1r, p1i, b1r, -b1i, t1r, t1i))
    nc = iv[lb + LW.NC]
    oX, oCc2, oDc21, oDc22 = iv[lb + LW.X], iv[lb + LW.CC2], iv[lb + LW.DC21], iv[lb + LW.DC22]
    # z̃ = C_c2 x + D_c21 y
    sr, si = _cdot(x, oCc2, oX, nc)
    tr, ti = cmul(x[oDc21], x[oDc21 + 1], yr, yi)
    z0r, z0i = sr + tr, si + ti
    sr, si = _cdot(x, oCc2 + 2 * nc, oX, nc)
    tr, ti = cmul(x[oDc21 + 2], x[oDc21 + 3], yr, yi)
    z1r, z1i = sr + tr, si + ti
    e00r, e00i = _cl(x, oDc22)
    e01r, e01i = _cl(x, oDc22 + 2)
    e10r, e10i = _cl(x, oDc22 + 4)
    e11r, e11i = _cl(x, oDc22 + 6)
    # L = I − D_c22 Δ_c
    tr, ti = _mul_add(e00r, e00i, c00r, c00i, e01r, e01i, c10r, c10i)
    g00r, g00i = 1.0 - tr, 0.0 - ti
    tr, ti = _mul_add(e00r, e00i, c01r, c01i, e01r, e01i, c11r, c11i)
    g01r, g01i = -tr, -ti
    tr, ti = _mul_add(e10r, e10i, c00r, c00i, e11r, e11i, c10r, c10i)
    g10r, g10i = -tr, -ti
    tr, ti = _mul_add(e10r, e10i, c01r, c01i, e11r, e11i, c11r, c11i)
    g11r, g11i = 1.0 - tr, 0.0 - ti
    dgr, dgi = _mul_sub(g00r, g00i, g11r, g11i, g01r, g01i, g10r, g10i)
    # v = L^{-1} z̃, w_c = Δ_c v
    v0r, v0i = cquot(*_mul_sub(g11r, g11i, z0r, z0i, g01r, g01i, z1r, z1i), dgr, dgi)
    v1r, v1i = cquot(*_mul_sub(g00r, g00i, z1r, z1i, g10r, g10i, z0r, z0i), dgr, dgi)
    w0r, w0i = _mul_add(c00r, c00i, v0r, v0i, c01r, c01i, v1r, v1i)
    w1r, w1i = _mul_add(c10r, c10i, v0r, v0i, c11r, c11i, v1r, v1i)
    # u = C_c1 x + D_c11 y + D_c12[0] w_c0 + D_c12[1] w_c1
    oCc1, oDc11, oDc12 = iv[lb + LW.CC1], iv[lb + LW.DC11], iv[lb + LW.DC12]
    sr, si = _cdot(x, oCc1, oX, nc)
    tr, ti = cmul(x[oDc11], x[oDc11 + 1], yr, yi)
    sr, si = sr + tr, si + ti
    tr, ti = cmul(x[oDc12], x[oDc12 + 1], w0r, w0i)
    sr, si = sr + tr, si + ti
    tr, ti = cmul(x[oDc12 + 2], x[oDc12 + 3], w1r, w1i)
    u_r, u_i = sr + tr, si + ti
    # x <- A_c x + B_c1 y + B_c2 w_c (every row from the old x: through LW.XN)
    oAc, oBc1, oBc2, oXN = iv[lb + LW.AC], iv[lb + LW.BC1], iv[lb + LW.BC2], iv[lb + LW.XN]
    for i in range(nc):
        sr, si = _cdot(x, oAc + 2 * i * nc, oX, nc)
        tr, ti = cmul(x[oBc1 + 2 * i], x[oBc1 + 2 * i + 1], yr, yi)
        sr, si = sr + tr, si + ti
        p = oBc2 + 4 * i
        tr, ti = cmul(x[p], x[p + 1], w0r, w0i)
        sr, si = sr + tr, si + ti
        tr, ti = cmul(x[p + 2], x[p + 3], w1r, w1i)
        x[oXN + 2 * i], x[oXN + 2 * i + 1] = sr + tr, si + ti
    _commit(x, iv, lb)
    return u_r, u_i


# --- the parts' updates -----------------------------------------------------------------------------------------
@njit(cache=True)
def current_update(x, iv, i_ref_re, i_ref_im, i_sr_re, i_sr_im, omega_mR, i_mR, u_max):
    """LPVCurrentController.update: (u_re, u_im); saturated, clipped, delta1, delta2 left in their slots."""
    d1max, d2max = x[CU.D1MAX], x[CU.D2MAX]
    d1 = omega_mR / d1max  # δ_1 = ω_cc (6.17)
    d2 = i_sr_im / ((I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR) * d2max)  # δ_2 = i_sq/î_mR, floored
    c1 = -1.0 if -1.0 > d1 else d1
    c1 = 1.0 if 1.0 < c1 else c1
    c2 = -1.0 if -1.0 > d2 else d2
    c2 = 1.0 if 1.0 < c2 else c2
    x[CU.CLIPPED] = 1.0 if c1 != d1 or c2 != d2 else 0.0
    x[CU.DELTA1], x[CU.DELTA2] = c1 * d1max, c2 * d2max
    yr, yi = i_sr_re - i_ref_re, i_sr_im - i_ref_im  # y = ī_s − ī_ref (6.2.2)
    lb = CI.LAW
    if iv[CI.PATH] == 0:
        ur, ui = _step22(x, iv, lb, yr, yi, c1, c2)
    else:
        oY, oD = iv[lb + LW.Y], iv[lb + LW.D]
        x[oY], x[oY + 1], x[oD], x[oD + 1] = yr, yi, c1, c2
        _evaluate_c(x, iv, lb)  # (LPVCurrentLaw's state is complex)
        _commit(x, iv, lb)
        oU = iv[lb + LW.U]
        ur, ui = x[oU], x[oU + 1]
    mag = abs_(ur, ui)
    if mag > u_max:
        x[CU.SAT] = 1.0
        if mag == 0.0:  # u_max < 0: CPython's message
            raise ZeroDivisionError("float division by zero")
        return cmul(ur, ui, u_max / mag, 0.0)
    x[CU.SAT] = 0.0
    return ur, ui


@njit
def _schedule(x, iv, i, d, tau):
    # LPVSpeedController._schedule(i, d, tau) to the law's Δ slots
    oH, oX0, oU0, oCU, oEU = iv[SPI.HIST], iv[SPI.X0], iv[SPI.U0], iv[SPI.CU], iv[SPI.EU]
    oTB, oC, oHH, oD = iv[SPI.TB], iv[SPI.C], iv[SPI.H], iv[iv[SPI.LAW] + LW.D]
    nx, ncu = iv[SPI.NX], iv[SPI.NCU]
    nk = nx if nx < ncu else ncu
    u0, u1, u2 = i - x[oU0], d - x[oU0 + 1], tau - x[oU0 + 2]
    for j in range(iv[iv[SPI.LAW] + LW.M]):
        s = 0.0
        for k in range(nk):
            s += x[oCU + j * ncu + k] * (x[oH + k] - x[oX0 + k])
        e = oEU + 3 * j
        xi = s + x[e] * u0 + x[e + 1] * u1 + x[e + 2] * u2
        tb = x[oTB + j]
        d1 = 1.0 - tb * tb
        if abs(xi) < 1e-6:
            g = d1 - tb * d1 * xi + d1 * (3.0 * tb * tb - 1.0) / 3.0 * xi * xi
        else:
            tx = math.tanh(xi)
            g = tx * d1 / (1.0 + tx * tb) / xi
        v = (g - x[oC + j]) / x[oHH + j]
        v = -1.0 if -1.0 > v else v
        x[oD + j] = 1.0 if 1.0 < v else v


@njit
def _shift(x, p, n, v):  # h = [v] + h[:-1]
    for k in range(n - 1, 0, -1):
        x[p + k] = x[p + k - 1]
    if n:
        x[p] = v


@njit
def _speed_row(x, iv):
    lb = iv[SPI.LAW]
    m, oD = iv[lb + LW.M], iv[lb + LW.D]
    x[SP.ROW] = x[oD] if m else 0.0
    x[SP.ROW + 1] = x[oD + 1] if m > 1 else 0.0
    x[SP.ROW + 2] = x[SP.ISD_LPV]
    x[SP.ROW + 3] = float(iv[SPI.ACTIVE])


@njit(cache=True)
def speed_update(x, iv, omega_ref, omega, i_mR, i_sd_ref):
    """LPVSpeedController.update: i_sq_ref [A]; m_e_ref, saturated and the internals row left in their slots."""
    w0, sw = x[SP.W0], x[SP.SW]
    w = (omega - w0) / sw
    i = (i_mR - x[SP.I0]) / x[SP.SI]
    d = (i_sd_ref - x[SP.D0]) / x[SP.SD]
    oH, n, nih, ndh = iv[SPI.HIST], iv[SPI.N], iv[SPI.NIH], iv[SPI.NDH]
    _shift(x, oH, n, w)
    lb = iv[SPI.LAW]
    if iv[SPI.ACTIVE] == 0 and i_mR >= START_I_MR:
        iv[SPI.ACTIVE] = 1
        oX = iv[lb + LW.X]  # law.reset()
        for k in range(iv[lb + LW.NC] * (2 if iv[lb + LW.CPLX] else 1)):
            x[oX + k] = 0.0
    floor = I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR
    i_sq = 0.0
    oU0 = iv[SPI.U0]
    if iv[SPI.ACTIVE]:
        x[iv[lb + LW.Y]] = w - (omega_ref - w0) / sw  # e = w~ - w~_ref (Fig. 6.13)
        _schedule(x, iv, i, d, x[SP.TAU_PREV])  # u_{k-1} for u_k (6.4.3)
        _evaluate_r(x, iv, lb)
        oU = iv[lb + LW.U]
        for _ in range(iv[SPI.ITER]):
            _schedule(x, iv, i, d, x[oU + 1] + x[oU0 + 2])
            _evaluate_r(x, iv, lb)
        _commit(x, iv, lb)
        x[SP.ISD_LPV] = (x[oU] + x[oU0 + 1]) * x[SP.SD] + x[SP.D0]
        i_tau = (x[oU + 1] + x[oU0 + 2]) * x[SP.ST] + x[SP.T0]
        i_sq = i_tau / floor
        two = x[SP.TWO]
        r = fsq(x[SP.IMAX], two) - fsq(i_sd_ref, two)
        lim = math.sqrt(0.0 if 0.0 > r else r)  # as (4.8)
        x[SP.SAT] = 1.0 if abs(i_sq) > lim else 0.0
        i_sq = -lim if -lim > i_sq else i_sq
        i_sq = lim if lim < i_sq else i_sq
    tau = (i_sq * i_mR - x[SP.T0]) / x[SP.ST]  # the i_tau applied, scaled
    _shift(x, oH + n, nih, i)
    if ndh:
        _shift(x, oH + n + nih, ndh, d)
        _shift(x, oH + n + nih + ndh, ndh, tau)
    x[SP.TAU_PREV] = tau
    x[SP.ME] = x[SP.KT] * floor * i_sq
    _speed_row(x, iv)
    return i_sq


# --- layout, pack, unpack ---------------------------------------------------------------------------------------
def _law_source(obj: Any) -> tuple[Any, bool, bool]:
    """(the object holding the law's matrices and sizes, complex, the current law's _step22 path)."""
    if isinstance(obj, LPVCurrentController):
        law = obj.law
        if law.m_c == 2 and law.k_c == 2:
            if len(law._lam) != 4:
                raise ValueError("LPVCurrentLaw._step22 needs 4 scheduling multipliers")
            return law, True, True
        if not law._generic.complex:  # LPVCurrentLaw's state is complex: a real generic law would mix the two
            raise ValueError("the compiled LPV current law runs m_c = k_c = 2 or a complex generic law")
        return law._generic, True, False
    if isinstance(obj, LPVSpeedController):
        if obj.law.complex:
            raise ValueError("the LPV speed law is real (a complex one has no real torque output)")
        return obj.law, False, False
    raise TypeError(f"not an LPV part: {type(obj).__name__}")


def _law_arrays(src: Any, cplx: bool, step22: bool) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """The law's matrices as 2-D arrays (the same numbers as its lists) and its sizes."""
    if step22:  # LPVCurrentLaw's own lists (every entry complex)
        nc, ny, nu, mc, kc, m = src.n_c, 1, 1, src.m_c, src.k_c, 2
    else:
        nc, ny, nu, mc, kc, m = src.n_c, src.n_y, src.n_u, src.m_c, src.k_c, src.m
    nk = len(src._lam)
    shapes = {"_Ac": (nc, nc), "_Bc1": (nc, ny), "_Bc2": (nc, mc), "_Cc1": (nu, nc), "_Dc11": (nu, ny),
              "_Dc12": (nu, mc), "_Cc2": (kc, nc), "_Dc21": (kc, ny), "_Dc22": (kc, mc), "_Q": (m, m), "_S": (m, m),
              "_R": (m, m), "_Uw": (m, nk), "_Uz": (m, nk)}  # fmt: skip
    if mc and nk - mc != kc:
        raise ValueError(f"Δ_c is {mc} x {nk - mc}, D_c22 {kc} x {mc}")
    dtype = complex if cplx else float
    mats = {k: np.asarray(getattr(src, k), dtype=dtype).reshape(s) for k, s in shapes.items()}
    return mats, {"nc": nc, "ny": ny, "nu": nu, "mc": mc, "kc": kc, "m": m, "nk": nk}


def _law_layout(sz: dict[str, int], cplx: bool, f0: int) -> tuple[list[int], int]:
    """The law block's int header and its end in x (floats from f0)."""
    es = 2 if cplx else 1
    nc, ny, nu, mc, kc, m, nk = (sz[k] for k in ("nc", "ny", "nu", "mc", "kc", "m", "nk"))
    nb = nk - mc
    hdr = [int(cplx), nc, ny, nu, mc, kc, m, nk]
    p = f0
    sizes = [nc * nc, nc * ny, nc * mc, nu * nc, nu * ny, nu * mc, kc * nc, kc * ny, kc * mc, m * m, m * m, m * m,
             m * nk, m * nk]  # the matrices, in _MATS order
    for s in sizes:
        hdr.append(p)
        p += es * s
    hdr.append(p)  # lam
    p += nk
    for s, scale in ((nc, es), (ny, es), (m, 1), (nu, es), (nc, es), (m * nk, es), (m * m, es), (m * nb, es),
                     (mc * nb, es), (kc, es), (kc * kc, es), (kc, es), (mc, es),
                     (max(m * (m + nb), kc * (kc + 1)), es)):  # X, Y, D, U, XN, V, MM, XS, DC, ZT, L, VV, WC, A
        hdr.append(p)
        p += scale * s
    assert len(hdr) == N_LAW_I
    return hdr, p


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


def _speed_sizes(obj: LPVSpeedController) -> dict[str, int]:
    n, nih, ndh = obj._n, max(obj._ni - 1, 0), max(obj._nu - 1, 0)
    m = obj.law.m
    if n < 1 or len(obj._u0) < 3:
        raise ValueError("the speed law needs a speed history and three inputs")
    for name in ("_Cu", "_Eu", "_tb", "_c", "_h"):
        if len(getattr(obj, name)) != m:
            raise ValueError(f"the scheduling map's {name} has not {m} rows")
    ncu = len(obj._Cu[0]) if m else 0
    if any(len(r) != ncu for r in obj._Cu) or any(len(r) < 3 for r in obj._Eu):
        raise ValueError("the scheduling map's C_u / E_u rows differ in length")
    return {"n": n, "nih": nih, "ndh": ndh, "nx": min(n + nih + 2 * ndh, len(obj._x0)), "ncu": ncu, "m": m}


def _plan(obj: Any) -> tuple[Any, bool, bool, dict[str, np.ndarray], list[int], list[int], int, int]:
    """(law source, complex, step22, matrices, the part's int slots but the law's, the law's header, n_float, n_int)."""
    src, cplx, step22 = _law_source(obj)
    mats, sz = _law_arrays(src, cplx, step22)
    if isinstance(obj, LPVCurrentController):
        hdr, nf = _law_layout(sz, cplx, NF_CURRENT)
        return src, cplx, step22, mats, [0 if step22 else 1], hdr, nf, CI.LAW + N_LAW_I
    s = _speed_sizes(obj)
    p = NF_SPEED
    offs = []
    for size in (s["n"] + s["nih"] + 2 * s["ndh"], len(obj._x0), 3, s["m"] * s["ncu"], 3 * s["m"], s["m"], s["m"],
                 s["m"]):  # HIST, X0, U0, CU, EU, TB, C, H
        offs.append(p)
        p += size
    hdr, nf = _law_layout(sz, cplx, p)
    ints = [0, 0, s["n"], s["nih"], s["ndh"], s["nx"], s["ncu"], *offs, SPI.LAW + 1]
    assert len(ints) == SPI.LAW + 1
    return src, cplx, step22, mats, ints, hdr, nf, SPI.LAW + 1 + N_LAW_I


def layout(obj: Any) -> tuple[int, int]:
    """(float64 slots, int64 slots) the part (an `LPVCurrentController` or `LPVSpeedController`) needs."""
    *_, nf, ni = _plan(obj)
    return nf, ni


def pack(obj: Any, x: np.ndarray, iv: np.ndarray) -> None:
    """The part's constants and state into ``x`` (float64, `layout`'s first size) and ``iv`` (int64)."""
    src, cplx, step22, mats, ints, hdr, nf, ni = _plan(obj)
    if len(x) < nf or len(iv) < ni:
        raise ValueError(f"the part needs {nf} float and {ni} int slots, got {len(x)} and {len(iv)}")
    x[:nf] = 0.0
    iv[:ni] = 0
    lb = len(ints)
    iv[:lb] = ints
    iv[lb:lb + N_LAW_I] = hdr
    for name, off in zip(_MATS, hdr[LW.AC:LW.LAM]):
        _put(x, off, mats[name], cplx)
    x[hdr[LW.LAM]:hdr[LW.LAM] + len(src._lam)] = src._lam
    if isinstance(obj, LPVCurrentController):
        law = obj.law
        _put(x, hdr[LW.X], law.x, True)  # the state is LPVCurrentLaw's (the generic law's is set from it per step)
        x[CU.D1MAX], x[CU.D2MAX] = law.delta1_max, law.delta2_max
        x[CU.SAT], x[CU.CLIPPED] = float(obj.saturated), float(obj.clipped)
        x[CU.DELTA1], x[CU.DELTA2] = obj.delta1, obj.delta2
        return
    o = obj
    iv[SPI.ACTIVE], iv[SPI.ITER] = int(o.active), o.iterations
    x[SP.W0:SP.TWO + 1] = (o._w0, o._sw, o._i0, o._si, o._d0, o._sd, o._t0, o._st, o.I_max, o.k_torque, 2.0)
    x[SP.TAU_PREV], x[SP.ME], x[SP.ISD_LPV], x[SP.SAT] = o._tau_prev, o.m_e_ref, o.i_sd_lpv, float(o.saturated)
    hist = o._w + o._ih + o._dh + o._th
    if [len(o._w), len(o._ih), len(o._dh), len(o._th)] != [iv[SPI.N], iv[SPI.NIH], iv[SPI.NDH], iv[SPI.NDH]]:
        raise ValueError("the speed controller's histories do not have their lengths")
    x[iv[SPI.HIST]:iv[SPI.HIST] + len(hist)] = hist
    x[iv[SPI.X0]:iv[SPI.X0] + len(o._x0)] = o._x0
    x[iv[SPI.U0]:iv[SPI.U0] + 3] = o._u0[:3]
    ncu = iv[SPI.NCU]
    for j in range(o.law.m):
        x[iv[SPI.CU] + j * ncu:iv[SPI.CU] + (j + 1) * ncu] = o._Cu[j]
        x[iv[SPI.EU] + 3 * j:iv[SPI.EU] + 3 * j + 3] = o._Eu[j][:3]
    m = o.law.m
    x[iv[SPI.TB]:iv[SPI.TB] + m], x[iv[SPI.C]:iv[SPI.C] + m], x[iv[SPI.H]:iv[SPI.H] + m] = o._tb, o._c, o._h
    _put(x, hdr[LW.X], o.law.x, False)
    if len(o.delta) != m:
        raise ValueError("the speed controller's delta has not m entries")
    x[hdr[LW.D]:hdr[LW.D] + m] = o.delta
    x[SP.ROW:SP.ROW + N_SPEED_ROW] = o.internals()


def unpack(obj: Any, x: np.ndarray, iv: np.ndarray) -> None:
    """The kernel's state from ``x``/``iv`` back into the part (plain Python floats, complex and bools)."""
    lb = CI.LAW if isinstance(obj, LPVCurrentController) else int(iv[SPI.LAW])
    cplx, nc, oX = bool(iv[lb + LW.CPLX]), int(iv[lb + LW.NC]), int(iv[lb + LW.X])
    if isinstance(obj, LPVCurrentController):
        obj.law.x = _get(x, oX, nc, True)
        obj.saturated, obj.clipped = x.item(CU.SAT) != 0.0, x.item(CU.CLIPPED) != 0.0
        obj.delta1, obj.delta2 = x.item(CU.DELTA1), x.item(CU.DELTA2)
        return
    if not isinstance(obj, LPVSpeedController):
        raise TypeError(f"not an LPV part: {type(obj).__name__}")
    obj.law.x = _get(x, oX, nc, cplx)
    obj.active = bool(iv[SPI.ACTIVE])
    h, n, nih, ndh = int(iv[SPI.HIST]), int(iv[SPI.N]), int(iv[SPI.NIH]), int(iv[SPI.NDH])
    obj._w = _get(x, h, n, False)
    obj._ih = _get(x, h + n, nih, False)
    obj._dh = _get(x, h + n + nih, ndh, False)
    obj._th = _get(x, h + n + nih + ndh, ndh, False)
    obj._tau_prev, obj.m_e_ref, obj.i_sd_lpv = x.item(SP.TAU_PREV), x.item(SP.ME), x.item(SP.ISD_LPV)
    obj.saturated = x.item(SP.SAT) != 0.0
    obj.delta = _get(x, int(iv[lb + LW.D]), int(iv[lb + LW.M]), False)


drop_stale(globals())  # (bench.core.jit_cache: numba's cache knows only this file's date)
