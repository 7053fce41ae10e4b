"""Figs 5.7-5.11: the LPV, JL and Kubota flux observers inside the FOC (thesis Sec. 5.6.3).

* ``fig5.7`` / ``fig5.8`` - encoder speed; the LPV observer (left) against the JL observer with the
  thesis' K_1 = 32(1+0.1j), K_2 = 2(1+0.1j) (right): omega_ref = 10 rad/s with the load switching
  0 <-> 3 N m every 1/3 s, and the stepwise sweep -150 -> 150 -> -150 rad/s with 0 <-> 3 sign(omega) N m
  every 0.1 s (scenarios ``fig5.7``, ``fig5.8``).
* ``fig5.9`` / ``fig5.10`` / ``fig5.11`` - sensorless: the speed is Kubota's estimate (poles at 1.1x
  the model poles, lambda_c = 1000) and the speed PI uses the FOC's sensorless set
  (``sensorless_speed_Kp``/``_Ti``). Columns LPV, JL, Kubota's own flux; top row the estimated speed,
  middle row the true speed (the thesis' "measured"). Scenarios ``fig5.7``, ``fig5.8``, ``fig5.11``.

The thesis could only compare closed-loop behaviour. The mock rig also knows the true flux, so every
figure has a bottom row the thesis could not draw: the flux-angle error of the estimate that orients
the controller, angle(i_m_hat) - angle(i_m). The JSON holds the `errors` statistics of each run.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bench.core import scenarios
from bench.core.plotstyle import speed_label
from bench.workflows.reproduce import register
from bench.workflows.reproductions.common import SimResult, errors, pyplot, save_figure, simulate, wrap
from bench.core.scenarios import T_MAGNETISE

#: the speed observer of 5.6.3: Kubota, observer poles 1.1x the model poles, lambda_c = 1000
KUBOTA_SPEED: dict[str, Any] = {"speed_estimator": "kubota", "kubota_pole_ratio": 1.1, "kubota_lambda_c": 1000.0}
SENSORLESS: dict[str, Any] = {"speed_source": "estimate", **KUBOTA_SPEED}
#: column title -> flux observer (JL with the FOC's defaults, the thesis' K_1, K_2)
ENCODER_COLUMNS = {"LPV observer": "lpv", "JL observer": "jl"}
SENSORLESS_COLUMNS = {"LPV observer": "lpv", "JL observer": "jl", "Kubota observer": "kubota"}

_cache: dict[tuple[str, str, bool], SimResult] = {}


def run(scn_name: str, observer: str, sensorless: bool) -> SimResult:
    """One lockstep run (nominal plant, seed 0), cached for the figures that share it."""
    key = (scn_name, observer, sensorless)
    if key not in _cache:
        params = {"observer": observer, **(SENSORLESS if sensorless else {})}
        _cache[key] = simulate(scenarios.get(scn_name), params)
    return _cache[key]


def _angle_error_deg(r: SimResult) -> np.ndarray:
    im_hat = r["/ctrl/i_m_hat_re"] + 1j * r["/ctrl/i_m_hat_im"]
    im = r["/truth/i_m_re"] + 1j * r["/truth/i_m_im"]
    return np.degrees(wrap(np.angle(im_hat) - np.angle(im)))


def _stats(r: SimResult, params: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {"foc_params": params, **errors(r)}
    out["trip_cause"], out["trip_t"] = r.trip_cause, r.trip_t
    return out


def _load_axis(ax, t: np.ndarray, m_l: np.ndarray, ok: np.ndarray, label: bool):  # noqa: ANN001, ANN202
    ax2 = ax.twinx()
    ax2.plot(t[ok], m_l[ok], color="tab:blue", lw=0.8, ls="--", alpha=0.7)
    lo, hi = float(np.min(m_l[ok])), float(np.max(m_l[ok]))
    span = max(hi - lo, 1.0)
    ax2.set_ylim(lo - 0.2 * span, lo + 3.0 * span)  # the load in the lower third, under the speed
    if label:
        ax2.set_ylabel("load $m_L$ [N m], dashed (all columns)", color="tab:blue")
        ax2.tick_params(axis="y", colors="tab:blue")
    else:  # every column runs the same load on the same scale: the last column's axis reads for all
        ax2.tick_params(right=False, labelright=False)
    return ax2


def _encoder_figure(out_dir: Path, name: str, scn_name: str, title: str, show_load: bool) -> dict[str, Any]:
    plt = pyplot()
    cols = ENCODER_COLUMNS
    fig, axs = plt.subplots(2, len(cols), figsize=(12, 6.5), sharex=True, height_ratios=[2.2, 1], squeeze=False)
    out: dict[str, Any] = {"scenario": scn_name, "speed": "encoder", "runs": {}}
    for j, (label, obs) in enumerate(cols.items()):
        r = run(scn_name, obs, False)
        t, ok = r["/rig/t"], r["/rig/t"] >= T_MAGNETISE - 0.05
        ax = axs[0, j]
        ax.plot(t[ok], r["/rig/omega_r_ref"][ok], color="tab:gray", lw=1.0, ls=":", label=r"reference $\omega_{r,ref}$")
        ax.plot(t[ok], r["/truth/omega_r"][ok], "k", lw=0.9, label=r"speed $\omega_r$")
        ax.set_title(label)
        ax.grid(alpha=0.3)
        if show_load:
            _load_axis(ax, t, r["/rig/m_l_ref"], ok, j == len(cols) - 1)
        axs[1, j].plot(t[ok], _angle_error_deg(r)[ok], "k", lw=0.7)
        axs[1, j].grid(alpha=0.3)
        axs[1, j].set_xlabel("t [s]")
        out["runs"][obs] = _stats(r, {"observer": obs})
    axs[0, 0].set_ylabel(speed_label())
    axs[0, 0].legend(fontsize=8, loc="upper left")
    axs[1, 0].set_ylabel("flux angle error [deg]\n(mock rig truth)")
    _share_y(axs[0])
    _share_y(axs[1])
    save_figure(fig, out_dir, name, title)
    return out


def _share_y(row) -> None:  # noqa: ANN001
    lo = min(a.get_ylim()[0] for a in row)
    hi = max(a.get_ylim()[1] for a in row)
    for a in row:
        a.set_ylim(lo, hi)


def _sensorless_figure(out_dir: Path, name: str, scn_name: str, title: str, show_load: bool) -> dict[str, Any]:
    plt = pyplot()
    cols = SENSORLESS_COLUMNS
    fig, axs = plt.subplots(3, len(cols), figsize=(14, 8.5), sharex=True, height_ratios=[2, 2, 1], squeeze=False)
    out: dict[str, Any] = {"scenario": scn_name, "speed": "sensorless: Kubota, poles 1.1x, lambda_c = 1000",
                           "speed_pi": "FOC sensorless_speed_Kp / sensorless_speed_Ti", "runs": {}}  # fmt: skip
    for j, (label, obs) in enumerate(cols.items()):
        r = run(scn_name, obs, True)
        t, ok = r["/rig/t"], r["/rig/t"] >= T_MAGNETISE - 0.05
        ref = r["/rig/omega_r_ref"]
        for i, (key, what) in enumerate((("/ctrl/omega_est", "estimated speed"), ("/truth/omega_r", "true speed"))):
            ax = axs[i, j]
            ax.plot(t[ok], ref[ok], color="tab:gray", lw=1.0, ls=":", label="reference")
            ax.plot(t[ok], r[key][ok], "k", lw=0.8, label=what)
            ax.grid(alpha=0.3)
            if show_load and i == 1:
                _load_axis(ax, t, r["/rig/m_l_ref"], ok, j == len(cols) - 1)
            if j == 0:
                ax.set_ylabel(speed_label(what))
        axs[0, j].set_title(label + (f"  (tripped at {r.trip_t:.2f} s)" if r.trip_cause else ""))
        axs[2, j].plot(t[ok], _angle_error_deg(r)[ok], "k", lw=0.7)
        axs[2, j].grid(alpha=0.3)
        axs[2, j].set_xlabel("t [s]")
        out["runs"][obs] = _stats(r, {"observer": obs, **SENSORLESS})
    axs[2, 0].set_ylabel("flux angle error [deg]\n(mock rig truth)")
    for i in range(3):
        _share_y(axs[i])
    _share_y([axs[0, 0], axs[0, 1], axs[0, 2], axs[1, 0], axs[1, 1], axs[1, 2]])
    axs[1, 0].legend(fontsize=8, loc="upper left")
    save_figure(fig, out_dir, name, title)
    return out


def _step_peaks(r: SimResult, window: float = 0.6) -> dict[str, float]:
    """Largest |estimate - true speed| in the window after each reference step: at the first (largest)
    step, and the worst over all steps."""
    t, w, ref = r["/rig/t"], r["/truth/omega_r"], r["/rig/omega_r_ref"]
    est = r.data.get("/ctrl/omega_est", r["/ctrl/omega_hat"])
    steps = np.flatnonzero(np.diff(ref) != 0) + 1
    out: dict[str, float] = {}
    for k, i in enumerate(steps):
        win = (t >= t[i]) & (t < t[i] + window)
        if r.trip_t is not None:
            win &= t < r.trip_t
        if not win.any():
            continue
        e_est = float(np.max(np.abs((est - w)[win])))
        if k == 0:
            out["first_step_estimate_error_peak"] = e_est
            out["first_step"] = f"{ref[i - 1]:g} -> {ref[i]:g} rad/s"
        out["estimate_error_peak_worst_step"] = max(out.get("estimate_error_peak_worst_step", 0.0), e_est)
    return out


@register("fig5.7", "encoder speed, omega_ref = 10 rad/s, load 0 <-> 3 N m every 1/3 s: LPV vs JL observer")
def fig5_7(out_dir: Path) -> dict[str, Any]:
    return _encoder_figure(out_dir, "fig5.7", "fig5.7", "Fig. 5.7: closed loop at $\\omega_{r,ref}$ = 10 rad/s, "
                           "load 0 <-> 3 N m every 1/3 s (encoder speed)", show_load=True)  # fmt: skip


@register("fig5.8", "encoder speed, steps of 15 rad/s -150 -> 150 -> -150, load 0 <-> 3 sign(omega) N m: LPV vs JL")
def fig5_8(out_dir: Path) -> dict[str, Any]:
    out = _encoder_figure(out_dir, "fig5.8", "fig5.8", "Fig. 5.8: stepwise sweep through the speed range, load "
                          "0 <-> 3 sign($\\omega_r$) N m every 0.1 s (encoder speed)", show_load=False)  # fmt: skip
    for obs in ENCODER_COLUMNS.values():
        out["runs"][obs].update(_step_peaks(run("fig5.8", obs, False)))
    return out


@register("fig5.9", "sensorless (Kubota speed 1.1x, lambda_c = 1000) at omega_ref = 10 rad/s: LPV, JL, Kubota flux")
def fig5_9(out_dir: Path) -> dict[str, Any]:
    return _sensorless_figure(out_dir, "fig5.9", "fig5.7", "Fig. 5.9: speed sensorless at $\\omega_{r,ref}$ = 10 rad/s, "
                              "load 0 <-> 3 N m every 1/3 s (Kubota speed, poles 1.1x, $\\lambda_c$ = 1000)",
                              show_load=True)  # fmt: skip


@register("fig5.10", "sensorless stepwise sweep -150 -> 150 -> -150 rad/s: LPV, JL, Kubota flux")
def fig5_10(out_dir: Path) -> dict[str, Any]:
    out = _sensorless_figure(out_dir, "fig5.10", "fig5.8", "Fig. 5.10: speed sensorless stepwise sweep "
                             "(Kubota speed, poles 1.1x, $\\lambda_c$ = 1000)", show_load=False)  # fmt: skip
    for obs in SENSORLESS_COLUMNS.values():
        out["runs"][obs].update(_step_peaks(run("fig5.8", obs, True)))
    return out


@register("fig5.11", "sensorless slow sweep -10 -> 10 -> -10 rad/s, load 6 sign(omega) N m up, 0 down")
def fig5_11(out_dir: Path) -> dict[str, Any]:
    out = _sensorless_figure(out_dir, "fig5.11", "fig5.11", "Fig. 5.11: speed sensorless slow sweep through zero, "
                             "load 6 sign($\\omega_r$) N m going up, 0 coming down", show_load=True)  # fmt: skip
    for obs in SENSORLESS_COLUMNS.values():
        r = run("fig5.11", obs, True)
        t, w, est = r["/rig/t"], r["/truth/omega_r"], r["/ctrl/omega_est"]
        near0 = (t >= T_MAGNETISE + 1.0) & (np.abs(w) < 2.0)
        out["runs"][obs]["estimate_error_rms_near_zero_speed"] = float(np.sqrt(np.mean((est - w)[near0] ** 2)))
    return out
