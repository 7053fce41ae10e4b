"""Estimation errors against the mock rig's ground truth: flux magnitude and angle, torque, estimated speed,
and the on-line R_r estimate; the transients at parts switched while running (`switch_transients`); the time at
the current loop's voltage limit and what it did to the field weakening and the R_r estimate (`voltage_limit`,
`voltage_limit_warning`: no truth needed).

One definition, used by the session summary (``estimation_errors`` in summary.json and every sweep
row) and by the observer reproductions (`bench.workflows.reproductions.common.errors`). Ground truth exists
only on rigs that log ``/truth`` (the mock plant and the emulators).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from bench.operate.requests import switch_names

__all__ = ["estimation_errors", "switch_transients", "voltage_limit", "voltage_limit_warning"]

SWITCH_WINDOW_U = 0.01  # [s] after a switch in which the voltage-reference jump is taken (30 ticks at 3 kHz)
SWITCH_WINDOW_M = 0.05  # [s] after a switch in which the torque transient is taken
SWITCH_LATER = 0.5  # [s] after a switch: the incoming part's own steady behaviour, over SWITCH_LATER_SPAN
SWITCH_LATER_SPAN = 0.2  # [s]
AT_LIMIT_AT_END = 0.5  # [s] a run whose last this-many seconds were all at the voltage limit ended there (a warning)
GATE_VLIM = 4  # rr_gate's voltage-limit bit (bench.controllers.rr_adapt.GATE_VLIM; not imported: no controllers here)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def _max_abs(x: np.ndarray) -> float:
    return float(np.max(np.abs(x))) if x.size else math.nan


def _p95(x: np.ndarray) -> float:
    """95th percentile of |x| (NaN for no sample)."""
    return float(np.percentile(np.abs(x), 95)) if x.size else math.nan


def _rel(x: float, ref: float) -> float:
    return x / ref if ref > 0 else math.nan


def estimation_errors(t: np.ndarray, ctrl: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray],
                      omega_ref: np.ndarray, t_from: float, trip_t: float | None = None,
                      torque_constant: float | None = None,
                      R_r_true: float | None = None) -> dict[str, float | bool]:  # fmt: skip
    """Errors over loop times ``t >= t_from`` and before ``trip_t`` (if any).

    Flux magnitude: |i_m_hat| - |i_m| [A], also relative to the mean true |i_m|; flux angle:
    angle(i_m_hat) - angle(i_m) [deg], wrapped to (-180, 180]; speed: the estimator's output
    (``omega_est`` where a speed estimator runs, else the controller's ``omega_hat``) minus the true
    omega_r [rad/s]; tracking: omega_r_ref - omega_r [rad/s]. RMS, largest and 95th percentile of the
    magnitude (``_p95``). NaN where no sample is left.

    With ``torque_constant`` (k of (4.6), the controller's nominal 3/2 Z_p L'_m) and the controller's
    ``i_mR_hat`` and ``i_sq``: torque, the controller's own estimate k i_mR_hat i_sq (4.6) minus the true m_e
    [N m], also relative to the mean true |m_e|. Where the controller logs an R_r estimate (``rr_hat``):
    rr_hat / R_r - 1 against the truth's ``r_r`` (warming motor) or the constant ``R_r_true``, over the window,
    where it adapts (``rr_gate`` = 0) and at its end, and the fraction of the window it adapts.
    """
    ok = t >= t_from
    if trip_t is not None:
        ok &= t < trip_t
    im_true = truth["i_m_re"] + 1j * truth["i_m_im"]
    im_hat = ctrl["i_m_hat_re"] + 1j * ctrl["i_m_hat_im"]
    e_mag = (np.abs(im_hat) - np.abs(im_true))[ok]
    e_ang = np.degrees(np.angle(np.exp(1j * (np.angle(im_hat) - np.angle(im_true)))))[ok]
    w_est = ctrl["omega_est"] if "omega_est" in ctrl else ctrl["omega_hat"]
    e_w = (w_est - truth["omega_r"])[ok]
    e_track = (omega_ref - truth["omega_r"])[ok]
    mean_im = float(np.mean(np.abs(im_true)[ok])) if ok.any() else math.nan
    out: dict[str, float | bool] = {
        "flux_mag_rms_A": _rms(e_mag), "flux_mag_max_A": _max_abs(e_mag),
        "flux_mag_rms_rel": _rel(_rms(e_mag), mean_im),
        "flux_mag_p95_A": _p95(e_mag), "flux_mag_p95_rel": _rel(_p95(e_mag), mean_im),
        "flux_angle_rms_deg": _rms(e_ang), "flux_angle_max_deg": _max_abs(e_ang), "flux_angle_p95_deg": _p95(e_ang),
        "speed_rms": _rms(e_w), "speed_max": _max_abs(e_w),
        "tracking_rms": _rms(e_track), "tripped": trip_t is not None,
    }  # fmt: skip
    # (the log's field names are lower case: i_mR_hat is i_mr_hat there)
    if torque_constant is not None and "i_sq" in ctrl and "i_mr_hat" in ctrl and "m_e" in truth:
        e_m = (torque_constant * ctrl["i_mr_hat"] * ctrl["i_sq"] - truth["m_e"])[ok]  # (4.6) against the truth
        mean_m = float(np.mean(np.abs(truth["m_e"][ok]))) if ok.any() else math.nan
        out.update({"torque_rms_Nm": _rms(e_m), "torque_p95_Nm": _p95(e_m), "torque_rms_rel": _rel(_rms(e_m), mean_m),
                    "torque_p95_rel": _rel(_p95(e_m), mean_m)})  # fmt: skip
    rr_true = truth["r_r"] if "r_r" in truth else R_r_true
    if "rr_hat" in ctrl and rr_true is not None:
        e_rr = (ctrl["rr_hat"] / rr_true - 1.0)[ok]  # rr_true: an array (warming motor) or a constant
        adapting = (ctrl["rr_gate"] == 0)[ok] if "rr_gate" in ctrl else np.ones(e_rr.shape, bool)
        out.update({"rr_rms_rel": _rms(e_rr), "rr_p95_rel": _p95(e_rr), "rr_p95_rel_adapting": _p95(e_rr[adapting]),
                    "rr_final_rel": float(e_rr[-1]) if e_rr.size else math.nan,
                    "rr_adapting_frac": float(np.mean(adapting)) if adapting.size else math.nan})  # fmt: skip
    return out


def switch_transients(t: np.ndarray, u_s_ref: np.ndarray, omega_mR: np.ndarray, events: list[Mapping],
                      m_e: np.ndarray | None = None) -> list[dict[str, object]]:  # fmt: skip
    """What each applied part switch (a set of ``switchable`` parts on /params) did to the command and the torque.

    The voltage reference's step per tick is taken in the rotating field, |u_k - u_{k-1} e^{j omega_mR T}|
    (in steady state the reference turns, it does not jump); ``u_jump`` is its largest value in the
    `SWITCH_WINDOW_U` after the switch, ``u_step_before`` the same just before (the outgoing part's own), and
    ``u_step_later`` the largest over `SWITCH_LATER_SPAN` from `SWITCH_LATER` after (the incoming part's own
    steps, settled). With the true torque ``m_e``: ``torque_transient``, the largest |m_e - mean| in
    `SWITCH_WINDOW_M` after the switch, the mean over that window before it; ``torque_before`` the same of the
    window before, ``torque_later`` the largest |m_e - mean| over the later span. [V], [N m]."""
    switches = switch_names()

    T = float(t[1] - t[0]) if t.size > 1 else math.nan
    step = np.zeros(t.shape)
    step[1:] = np.abs(u_s_ref[1:] - u_s_ref[:-1] * np.exp(1j * omega_mR[:-1] * T))
    nu, nm, nl, ns = (int(round(w / T)) for w in (SWITCH_WINDOW_U, SWITCH_WINDOW_M, SWITCH_LATER, SWITCH_LATER_SPAN))
    out: list[dict[str, object]] = []
    for ev in events:
        if ev.get("kind", "set") != "set" or ev.get("name") not in switches or ev.get("status") != "applied":
            continue
        k = int(np.searchsorted(t, float(ev["t"]) - 0.5 * T))  # the first tick the incoming part computed
        if k < max(nu, nm) or k >= t.size:
            continue  # too near the run's ends to measure

        def peak(x: np.ndarray, a: int, n: int) -> float:  # up to the run's end (a trip); NaN if none is left
            return float(np.max(x[a:a + n])) if a < x.size else math.nan

        row: dict[str, object] = {"t": float(ev["t"]), "part": ev["name"], "from": str(ev.get("old_text", ev.get("old"))),
                                  "to": str(ev.get("new_text", ev.get("new"))), "u_jump": peak(step, k, nu),
                                  "u_step_before": peak(step, k - nu, nu),
                                  "u_step_later": peak(step, k + nl, ns) if k + nl + ns <= t.size else math.nan}  # fmt: skip
        if m_e is not None:
            base = float(np.mean(m_e[k - nm:k]))
            dev = np.abs(m_e - base)
            later = m_e[k + nl:k + nl + ns]
            row |= {"torque_transient": peak(dev, k, nm), "torque_before": peak(dev, k - nm, nm),
                    "torque_later": float(np.max(np.abs(later - np.mean(later)))) if later.size == ns else math.nan}  # fmt: skip
        out.append(row)
    return out


def voltage_limit(t: np.ndarray, ctrl: Mapping[str, np.ndarray], t_from: float, trip_t: float | None = None,
                  ) -> dict[str, float]:  # fmt: skip
    """The current loop at its voltage limit (``u_sat``, the FOC's flag), over loop times ``t >= t_from`` and before
    ``trip_t``: the share of the time, the longest stretch and the stretch the run ended in [s] (0: it ended off the
    limit); where logged, the field weakening's factor (``fw``: its least and its last value) and the time the R_r
    estimate was frozen by the limit (``rr_gate``'s voltage-limit bit) [s]."""
    ok = t >= t_from
    if trip_t is not None:
        ok &= t < trip_t
    sat = ctrl["u_sat"][ok] != 0.0
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    edges = np.flatnonzero(np.diff(np.concatenate(([0], sat.view(np.int8), [0]))))  # starts and ends of stretches
    lengths = edges[1::2] - edges[::2]
    out = {"at_limit_frac": float(np.mean(sat)) if sat.size else math.nan,
           "longest_s": round(float(lengths.max()) * dt, 6) if lengths.size else 0.0,
           "at_end_s": round(float(lengths[-1]) * dt, 6) if sat.size and sat[-1] else 0.0}  # fmt: skip
    if "fw" in ctrl:
        fw = ctrl["fw"][ok]
        out.update({"fw_min": float(np.min(fw)) if fw.size else math.nan,
                    "fw_end": float(fw[-1]) if fw.size else math.nan})  # fmt: skip
    if "rr_gate" in ctrl:
        frozen = (ctrl["rr_gate"][ok].astype(np.int64) & GATE_VLIM) != 0
        out["rr_frozen_by_limit_s"] = round(float(np.sum(frozen)) * dt, 6)
    return out


def voltage_limit_warning(vl: Mapping[str, float] | None, params: Mapping[str, object] | None) -> str | None:
    """One line for summary.json's warnings when the run ended at the voltage limit (its last `AT_LIMIT_AT_END`
    seconds, ``vl`` from `voltage_limit`), naming the limit and what keeps the drive there; ``params``: the FOC's."""
    if not vl or not vl.get("at_end_s", 0.0) >= AT_LIMIT_AT_END:
        return None
    p = params or {}
    msg = (f"the run ended at the current loop's voltage limit (u_margin = {p.get('u_margin', '?')} of the linear "
           f"range u_dc/sqrt(3)) for its last {vl['at_end_s']:.2f} s: ")  # fmt: skip
    if "fw_end" not in vl:
        msg += ("the reference needs more voltage than the inverter has, and field weakening is off "
                "(-p field_weakening=on)")  # fmt: skip
    elif vl["fw_end"] <= float(p.get("fw_min", 0.0)):  # type: ignore[arg-type]
        msg += (f"the field weakening is at its floor fw_min = {p.get('fw_min')} of the i_mR reference and still short "
                "of voltage (lower speed or load, or a higher DC link)")  # fmt: skip
    else:
        msg += f"the field weakening was still lowering the flux (factor {vl['fw_end']:.3f})"
    if "rr_frozen_by_limit_s" in vl:
        msg += "; the R_r estimate is frozen there (rr_gate 4)"
    return msg
