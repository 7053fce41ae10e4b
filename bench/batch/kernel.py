"""The batch engine's compiled loop (numba): many lockstep sessions of the mock plant and the compiled FOC at once.

`run_all` runs N independent cases, each a whole lockstep session (`bench.runtime.loop.TimedLoop` without the
log), in one call: a ``prange`` over the cases (the cores share them), inside it the ticks of one case.
Per tick it does what the scalar session does, in the same order: the plant's `acquire` with the
inverter's one-sample pipeline (`mock_hw.plant.MockPlant.acquire`, compiled engine) and its sensors
(`mock_hw.compiled.advance`, the very same compiled function), the supervisor's checks
(`bench.core.supervisor_checks.measurement_checks`, the function `bench.core.supervisor.Supervisor` calls, compiled; its
encoder speed by `bench.controllers.foc_compiled`'s kernel), the FOC tick (`bench.controllers.foc_compiled.step`,
the same function), the load profile and `bench.hal.Rig.write`. A trip ends a case after
`bench.runtime.loop.POST_TRIP_TIME` of safe ticks, as in the loop; the other cases run on.

Instead of logging every tick, the loop keeps the reductions of `bench.runtime.run_summary.summarize` and
`bench.runtime.metrics.estimation_errors` (sums, maxima, counts, the load-step windows; for the 95th percentiles the
window's absolute estimation errors of the case being run, sorted at its end): `bench.batch.engine` turns them
into the session's summary. Sums are compensated (Neumaier), so they agree with numpy's pairwise sums of
the logged values to about 1e-15 relative; counts, trip tick and cause are the same bits; the flux
magnitude uses C's hypot where numpy's vectorised complex abs may differ by an ulp.

Buffers: the plant's (`mock_hw.compiled` layout) and the controller's (`foc_compiled` layout) of every
case, one row each of two 2-D arrays; the supervisor's encoder speed in a third (`foc_compiled` layout,
only its encoder slots used); per-case numbers in ``P`` (floats) and ``Q`` (ints); the scenario's
per-tick reference and load tables shared by all cases, each case's entries those times its own factors
(``P_W_SCALE``, ``P_LOAD_SCALE``; a zero entry stays the table's zero, a zero factor has no reference changes).
Results: ``OUT`` (floats) and ``OUTI`` (ints).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from bench.controllers import foc_compiled as fc
from bench.core import supervisor_checks as sc
from bench.core.jit_cache import drop_stale
from bench.core.slots import slots
from mock_hw import compiled as cm

# --- per-case inputs ----------------------------------------------------------------------------------
# P (float64): the case's numbers; W_SCALE, LOAD_SCALE: the case's factors on the shared reference and load tables
# (1: the tables as they are)
P = slots("CaseFloats", UDC="f", INV_DT="f", IMR_REF="f", I_TRIP="f", I_TRIP_PH="f", OMEGA_MAX="f", UDC_MIN="f",
          UDC_MAX="f", STUCK_OMEGA="f", STUCK_U="f", TORQUE_LIM="f", LOAD_MMAX="f", LOAD_K="f", K_TORQUE="f",
          W_SCALE="f", LOAD_SCALE="f")  # fmt: skip
N_P = type(P).size
# Q (int64)
Q = slots("CaseInts", DELAY="i", JUMP_MAX="i", STUCK_TICKS="i", ENABLE_TICKS="i")
N_Q = type(Q).size

# load kinds (the scenario's): a table of m_L_ref(t, omega) for omega > 0, < 0, == 0 (a profile that sees only the
# sign of the speed), or Sec. 6.4.1's m_max (1 - 2/(1 + e^{k omega}))
LOAD_TABLE, LOAD_641 = 0, 1

# --- results ------------------------------------------------------------------------------------------
# trip codes: bench.core.supervisor_checks' (bench.batch.engine names them with its `cause`)
TRIP_NONE, TRIP_NONFINITE = sc.TRIP_NONE, sc.TRIP_NONFINITE
# OUTI (int64)
OI = slots("ResultInts", TICKS="i", TRIP="i", TRIP_K="i", N_ACTIVE="i", N_SETTLED="i", N_EST="i", N_PEAKS="i",
           N_RECOV="i", ENABLE_CMD="i", JUMP_D="i")  # fmt: skip
N_OI = type(OI).size
# OUT (float64): a compensated sum takes two slots (sum, compensation: "f2")
O = slots("Results",
          TRIP_V1="f", TRIP_V2="f", TRIP_V3="f",  # the cause's numbers
          E_SQ="f2", E_SUM="f2", E_MAX="f",  # speed error over the active ticks
          ES_SQ="f2", ES_SUM="f2", ES_MAX="f",  # ... over the settled ticks
          I_SQ="f2", I_SUM="f2", I_MAX="f",  # magnetising-current error over the settled ticks
          MAG_SQ="f2", MAG_MAX="f", ANG_SQ="f2", ANG_MAX="f", W_SQ="f2", W_MAX="f",  # estimation errors
          TR_SQ="f2", IM_SUM="f2",  # tracking error, |i_m| (true)
          PEAK_MAX="f", PEAK_SUM="f2", REC_SUM="f2",  # load steps
          M_SQ="f2", ME_SUM="f2",  # torque estimate's error (4.6), |m_e| (true)
          # 95th percentiles of |error| (flux magnitude, angle, torque)
          P95_MAG="f", P95_ANG="f", P95_M="f")  # fmt: skip
N_O = type(O).size

RAD2DEG = 180.0 / math.pi  # numpy's degrees()

# the supervisor's per-tick checks, the scalar runs' own functions compiled
_measurement_checks = njit(sc.measurement_checks)
_limits = njit(sc.limits)


@njit
def _add(o, i, v):
    # Neumaier's compensated sum in o[i] (sum), o[i + 1] (compensation)
    s = o[i]
    t = s + v
    if abs(s) >= abs(v):
        o[i + 1] += (s - t) + v
    else:
        o[i + 1] += (v - t) + s
    o[i] = t


@njit
def _max(o, i, v):
    if v > o[i]:
        o[i] = v


@njit
def _p95(a, n):
    # np.percentile(a[:n], 95) (numpy's "linear" method, its _lerp; NaN without samples or with a NaN)
    if n == 0:
        return math.nan
    b = np.sort(a[:n])
    if math.isnan(b[n - 1]):
        return math.nan
    vi = (n - 1) * 0.95
    if vi >= n - 1:
        return b[n - 1]
    lo = int(math.floor(vi))
    g = vi - lo
    x0, x1 = b[lo], b[lo + 1]
    d = x1 - x0
    if g >= 0.5:
        return x1 - d * (1.0 - g)
    return x0 + d * g


@njit
def _close_window(o, oi, w_ok, w_n, w_peak, w_above, t_s):
    # one load step's window is complete (bench.runtime.run_summary.summarize): its peak and recovery time
    if w_ok and w_n > 0:
        oi[OI.N_PEAKS] += 1
        _max(o, O.PEAK_MAX, w_peak)
        _add(o, O.PEAK_SUM, w_peak)
        oi[OI.N_RECOV] += 1
        _add(o, O.REC_SUM, w_above - t_s if w_above >= t_s else 0.0)


@njit
def run_one(xp, xf, xs, p, q, w_ref, last_change, ref_changed, load_kind, load_pos, load_neg, load_zero,
            n_ticks, post_trip, T, t_mag, t_est, o, oi):  # fmt: skip
    """One case: the session's ticks until the end or POST_TRIP after a trip; reductions into o, oi."""
    iv_s = xs[fc.NF:fc.N_BUF].view(np.int64)
    # the logged speed estimate the estimation errors score (bench.runtime.metrics.estimation_errors): the estimator's
    # omega_est (the row's 16th value) where one runs, else omega_hat (the row's first: the encoder speed)
    w_est_at = fc.SF.ROW + fc.N_ROW + 1 if xf[fc.NF:fc.N_BUF].view(np.int64)[fc.SI.EST_KIND] != 0 else fc.SF.ROW
    saturated = xp[cm.NF:].view(np.int64)[cm.PI.SAT] != 0
    abs_err = np.empty((3, n_ticks))  # |flux magnitude|, |flux angle|, |torque| errors of the window: percentiles
    k_torque = p[P.K_TORQUE]
    u_dc, inv_dt, i_mR_ref = p[P.UDC], p[P.INV_DT], p[P.IMR_REF]
    delay = q[Q.DELAY] != 0
    w_scale, load_scale = p[P.W_SCALE], p[P.LOAD_SCALE]
    ref_moves = w_scale != 0.0  # a zero factor: a reference of 0 throughout, without changes
    for i in range(N_O):
        o[i] = 0.0
    for i in range(N_OI):
        oi[i] = 0
    o[O.E_MAX] = o[O.ES_MAX] = o[O.I_MAX] = -1.0
    o[O.MAG_MAX] = o[O.ANG_MAX] = o[O.W_MAX] = o[O.PEAK_MAX] = -1.0
    # the inverter (mock_hw.inverter.Inverter) and the rig (bench.hal.Rig): after configure + activate
    ref_r, ref_i, cmd_on, next_r, next_i, next_on, enabled = 0.0, 0.0, False, 0.0, 0.0, False, False
    m_L_ref = 0.0  # the load's clipped reference (DcLoadDrive.set_torque)
    kp = 0  # the plant's grid index
    # the supervisor (bench.core.supervisor.Supervisor): its checks' state (bench.core.supervisor_checks)
    tripped = False
    enable_cmd = False
    sx, siv = np.zeros(sc.N_F), np.zeros(sc.N_I, np.int64)
    slim = _limits(q[Q.JUMP_MAX], 2.0 * p[P.OMEGA_MAX] * T, q[Q.STUCK_TICKS], T, p[P.STUCK_OMEGA], p[P.STUCK_U],
                   p[P.I_TRIP_PH], p[P.I_TRIP], p[P.OMEGA_MAX], p[P.UDC_MIN], p[P.UDC_MAX],
                   q[Q.ENABLE_TICKS])  # fmt: skip
    # load-step windows (summarize), the last logged m_L_ref
    mL_prev = 0.0
    w_open, w_ok, w_n, w_peak, w_above, w_ts = False, False, 0, -1.0, -math.inf, 0.0
    stop_at = n_ticks
    k = 0
    while k < stop_at:
        t = k * T
        # --- rig.read(t): MockPlant.acquire (compiled engine) and the measurement
        n = math.floor(t * inv_dt + 0.5)
        if n > kp:
            on = cmd_on  # and not fault: the mock inverter has no fault here
            if delay:
                u1r, u1i, on1 = next_r, next_i, next_on
                next_r, next_i, next_on = ref_r, ref_i, cmd_on
            else:
                u1r, u1i, on1 = ref_r, ref_i, on
            vi, _ci, vu, _cu, enc, _ua = cm.advance(xp, n - kp, complex(u1r, u1i), on1, complex(ref_r, ref_i), on,
                                                    u_dc, m_L_ref)  # fmt: skip
            kp = n
        else:
            vi, _ci, vu, _cu, enc, _ua = cm.advance(xp, 0, 0j, False, 0j, False, u_dc, 0.0)
        i_a, i_b, i_c = vi
        u_a, u_b, u_c = vu
        count = enc[0]
        inv_enabled = next_on if delay else cmd_on
        was_tripped = tripped
        w = w_ref[k]
        if w != 0.0:
            w *= w_scale
        lc = last_change[k] if ref_moves else -math.inf
        # --- Supervisor.check_measurement (lockstep: one tick since the last, no status bits): its very checks
        if not tripped:
            omega = fc._encoder(xs, iv_s, count, t)
            trip = _measurement_checks(sx, siv, slim, iv_s[fc.SI.E_D], 1, i_a, i_b, i_c, u_a, u_b, u_c, omega, False,
                                       u_dc, inv_enabled, enable_cmd)  # fmt: skip
            if trip != TRIP_NONE:
                tripped = True
                oi[OI.TRIP], oi[OI.TRIP_K] = trip, k
                o[O.TRIP_V1], o[O.TRIP_V2], o[O.TRIP_V3] = sx[sc.V1], sx[sc.V2], sx[sc.V3]
                oi[OI.JUMP_D], oi[OI.ENABLE_CMD] = siv[sc.JUMP_D], siv[sc.ENABLE_CMD]
        # --- the controller, Supervisor.check_command, the load profile
        enable, cr, ci, m_cmd = False, 0.0, 0.0, 0.0
        if not tripped:
            u = fc.step(xf, t, i_a, i_b, i_c, u_a, u_b, u_c, count, u_dc, w, i_mR_ref)
            if not (math.isfinite(u.real) and math.isfinite(u.imag)):
                tripped = True
                oi[OI.TRIP], oi[OI.TRIP_K] = TRIP_NONFINITE, k
                o[O.TRIP_V1], o[O.TRIP_V2] = u.real, u.imag
            else:
                enable, cr, ci = True, u.real, u.imag
                om = xs[fc.SF.E_WR]  # Supervisor.omega_r
                if load_kind == LOAD_641:
                    m_cmd = p[P.LOAD_MMAX] * (1.0 - 2.0 / (1.0 + math.exp(max(min(p[P.LOAD_K] * om, 700.0), -700.0))))
                else:
                    m_cmd = load_pos[k] if om > 0 else (load_neg[k] if om < 0 else load_zero[k])
                    if m_cmd != 0.0:
                        m_cmd *= load_scale
        # --- rig.write(cmd)
        if enable:
            if not enabled:
                cmd_on = True
                enabled = True
            ref_r, ref_i = cr, ci
        elif enabled:
            ref_r, ref_i = 0.0, 0.0
            cmd_on = False
            next_on = False
            enabled = False
        lim = p[P.TORQUE_LIM]
        m_L_ref = lim if m_cmd > lim else (-lim if m_cmd < -lim else m_cmd)
        enable_cmd = enable
        if tripped and not was_tripped:
            stop_at = min(stop_at, k + 1 + post_trip)
        # --- the reductions of the log (summarize, estimation_errors) from this tick's row
        omega_true = xp[cm.PF.W]
        e = w - omega_true
        active = t >= t_mag and not tripped
        settled = active and (t - lc > 0.2)
        if active:
            oi[OI.N_ACTIVE] += 1
            _add(o, O.E_SQ, e**2)
            _add(o, O.E_SUM, e)
            _max(o, O.E_MAX, abs(e))
        im_r, im_i = xp[cm.PF.IM_RE], xp[cm.PF.IM_IM]
        if settled:
            oi[OI.N_SETTLED] += 1
            _add(o, O.ES_SQ, e**2)
            _add(o, O.ES_SUM, e)
            _max(o, O.ES_MAX, abs(e))
            di = i_mR_ref - math.hypot(im_r, im_i)
            _add(o, O.I_SQ, di**2)
            _add(o, O.I_SUM, di)
            _max(o, O.I_MAX, abs(di))
        if t >= t_est and not tripped:  # estimation_errors: t >= t_from and before the trip
            j = oi[OI.N_EST]
            oi[OI.N_EST] += 1
            hr, hi = xf[fc.SF.I_M], xf[fc.SF.I_M + 1]
            a_true = math.hypot(im_r, im_i)
            em = math.hypot(hr, hi) - a_true
            _add(o, O.MAG_SQ, em**2)
            _max(o, O.MAG_MAX, abs(em))
            abs_err[0, j] = abs(em)
            dang = math.atan2(hi, hr) - math.atan2(im_i, im_r)
            ea = math.atan2(math.sin(dang), math.cos(dang)) * RAD2DEG
            _add(o, O.ANG_SQ, ea**2)
            _max(o, O.ANG_MAX, abs(ea))
            abs_err[1, j] = abs(ea)
            ew = xf[w_est_at] - omega_true  # the speed estimate: omega_est with an estimator, else omega_hat
            _add(o, O.W_SQ, ew**2)
            _max(o, O.W_MAX, abs(ew))
            _add(o, O.TR_SQ, e**2)
            _add(o, O.IM_SUM, a_true)
            m_e = cm.truth_sat(xp)[8] if saturated else cm.truth(xp)[8]  # the true torque (MockPlant.sample)
            e_m = k_torque * xf[fc.SF.I_MR] * xf[fc.SF.I_SR + 1] - m_e  # (4.6): k i_mR_hat i_sq - m_e
            _add(o, O.M_SQ, e_m**2)
            _add(o, O.ME_SUM, abs(m_e))
            abs_err[2, j] = abs(e_m)
        # load steps: |diff(m_L_ref logged)| > 0.5; window [t_s, min(t_s + 0.2, next step)), active ticks,
        # left out when a reference change falls within (t_s - 0.2, window end)
        if k > 0 and abs(m_cmd - mL_prev) > 0.5:
            if w_open:
                _close_window(o, oi, w_ok, w_n, w_peak, w_above, w_ts)
            w_open, w_ts, w_n, w_peak, w_above = True, t, 0, -1.0, -math.inf
            w_ok = not (t < t_mag) and not (lc > t - 0.2)
        elif w_open and t < w_ts + 0.2 and ref_changed[k] and ref_moves:
            w_ok = False
        if w_open and t < w_ts + 0.2 and active:
            dev = abs(e)
            w_n += 1
            if dev > w_peak:
                w_peak = dev
            if dev > 1.0:
                w_above = t
        mL_prev = m_cmd
        k += 1
    if w_open:
        _close_window(o, oi, w_ok, w_n, w_peak, w_above, w_ts)
    n_est = oi[OI.N_EST]
    o[O.P95_MAG], o[O.P95_ANG], o[O.P95_M] = _p95(abs_err[0], n_est), _p95(abs_err[1], n_est), _p95(abs_err[2], n_est)
    oi[OI.TICKS] = k


@njit(parallel=True, cache=True)
def run_all(XP, XF, XS, P, Q, w_ref, last_change, ref_changed, load_kind, load_pos, load_neg, load_zero, n_ticks,
            post_trip, T, t_mag, t_est, OUT, OUTI):  # fmt: skip
    """Every case (rows of XP, XF, XS, P, Q), in parallel over the cases; results in OUT, OUTI. (`bench.batch.engine`
    calls it with numba's parallel chunk size 1: a case that trips early frees its thread for the next.)"""
    for c in prange(XP.shape[0]):
        run_one(XP[c], XF[c], XS[c], P[c], Q[c], w_ref, last_change, ref_changed, load_kind, load_pos, load_neg,
                load_zero, n_ticks, post_trip, T, t_mag, t_est, OUT[c], OUTI[c])  # fmt: skip


drop_stale(globals())  # (bench.core.jit_cache: numba's cache knows only this file's date)
