"""Figs 4.8-4.12: speed estimation while the FOC runs on the measured (encoder) speed (Sec. 4.4.3).

* ``fig4.8`` - speed 10 -> 12 -> 10 rad/s at 2 N m and at 9 N m load. Four estimators run
  alongside (passively) and are compared with the true speed: the rotor-equation estimator (4.19) on
  the Jansen-Lorenz flux with weighting mostly on the current model (A), balanced - the thesis'
  K_1 = 32(1+0.1j), K_2 = 2(1+0.1j) (B), mostly on the voltage model (C), and Kubota's observer
  with poles at 1.2x the model poles (D). In A-C the JL observer's rotation term uses the
  estimate itself, as in the thesis (a current-model flux driven by the true speed would make
  (4.19) return that speed).
* ``fig4.8-offset`` - the same with the estimators fed the *measured* voltage carrying a DC offset
  (0.5 V on phase a). The reference voltage of ``fig4.8`` has no offset, so there C cannot show the
  thesis' fluctuations at omega_mR; they come from "an almost constant offset in the integrated
  voltage", which the JL loop removes only with its slow pole (s^2 + K_1 (L_r/L_m) s + K_2 L_r/L_m:
  -0.066 rad/s for C, -0.063 and -33 rad/s for B), and which appears in the flux frame at omega_mR.
* ``fig4.9``/``fig4.10`` - speed-reference steps with Kubota's estimate alongside, and its error.
* ``fig4.11``/``fig4.12`` - slow sweep -15 -> 15 -> -15 rad/s with the load stepping 3 <-> 7 N m.

Differences from the thesis: its Fig. 4.8 moves the speed instantaneously (a simulation); here the
speed follows the reference through the FOC speed loop (about 30 ms to settle), and the estimators
see the mock rig's sensor noise and quantisation. Step levels and sweep rates the thesis does not
give are chosen in `bench.core.scenarios` (``fig4.9``, ``fig4.11``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bench.core import load_profiles as lp
from bench.core import scenarios
from bench.controllers.base import Controller, ControllerContext
from bench.controllers.foc import FocController
from bench.controllers.observers import JansenLorenzObserver, KubotaObserver
from bench.controllers.speed_estimators import RotorEquationSpeed
from bench.hal import Measurement
from bench.core.plotstyle import speed_label
from bench.workflows.reproduce import register
from bench.workflows.reproductions.common import SimResult, pyplot, save_figure, simulate
from bench.core.scenarios import T_MAGNETISE, Scenario

# JL weightings of Fig. 4.8: K_1 = k1 (1 + 0.1j), K_2 = k2 (1 + 0.1j)
JL_WEIGHTINGS = {"A": (320.0, 20.0), "B": (32.0, 2.0), "C": (3.2, 0.2)}
KUBOTA_48 = {"pole_ratio": 1.2, "lambda_c": 1000.0}
ROTOR_EQ_TAU = 0.01  # [s] low-pass of the rotor-equation estimate


class PassiveEstimators(Controller):
    """A `FocController` (encoder speed) plus speed estimators that only watch, for Fig. 4.8.

    Each tick the estimators get the stator current and the voltage the FOC's observer got.
    Chains: ``"A"``-``"C"``: JL flux observer -> rotor-equation speed (4.19) -> back into the JL
    rotation term; ``"D"``: Kubota's observer. Logged as ``omega_<chain>`` and ``i_m_<chain>_re/im``.

    The estimators start at loop time ``t_start`` from the steady state the FOC is in, as in the
    thesis' simulation: flux = the FOC's current-model flux (encoder speed, exact parameters),
    speed = the encoder speed. Before that they are idle (and log 0).
    """

    name = "foc_passive"
    summary = "FOC with passive speed estimators (Fig. 4.8)"

    def __init__(self, ctx: ControllerContext, foc_params: dict[str, Any] | None = None,
                 t_start: float = 0.0) -> None:  # fmt: skip
        super().__init__(ctx)
        self.t_start = t_start
        self.foc = FocController(ctx, **(foc_params or {}))
        m, T = ctx.motor, ctx.T_s
        self.chains: dict[str, tuple[Any, Any]] = {}
        for key, (k1, k2) in JL_WEIGHTINGS.items():
            jl = JansenLorenzObserver(m, T, K1_re=k1, K1_im=0.1 * k1, K2_re=k2, K2_im=0.1 * k2)
            self.chains[key] = (jl, RotorEquationSpeed(m, T, tau=ROTOR_EQ_TAU))
        self.chains["D"] = (KubotaObserver(m, T, **KUBOTA_48), None)
        self.fields = self.foc.fields + tuple(
            f for k in self.chains for f in (f"omega_{k}", f"i_m_{k}_re", f"i_m_{k}_im"))
        self.reset()

    def reset(self) -> None:
        self.foc.reset()
        self.started = False
        for obs, est in self.chains.values():
            obs.reset()
            if est is not None:
                est.reset()

    def _start(self, i_s: complex) -> None:
        m = self.ctx.motor
        i_m, w = self.foc.i_m_hat, self.foc.encoder.omega_r
        for obs, est in self.chains.values():
            if est is None:  # Kubota
                obs.i_s_hat, obs.i_m, obs.omega_i, obs.omega_hat = i_s, i_m, w, w
                obs._i_s_prev = i_s
            else:  # JL: psi_rc = L_m i_m, psi_s = L'_s i_s + L'_m i_m, g = 0 (steady state, e = 0)
                obs.psi_rc, obs.psi_s, obs.g, obs.i_m = m.L_m * i_m, m.Ls_p * i_s + m.Lm_p * i_m, 0j, i_m
                obs._i_s_prev = i_s
                est.omega_hat = est.omega_r = w
                est._prev = i_m
        self.started = True

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        u = self.foc.step(meas, omega_ref, i_mR_ref)
        i_s, u_s = meas.i_s, self.foc.u_s_obs
        if not self.started:
            if meas.t + 1e-9 < self.t_start:
                return u
            self._start(i_s)
            return u
        for obs, est in self.chains.values():
            if est is None:
                obs.update(i_s, u_s, 0.0)
            else:
                est.update(i_s, u_s, obs.update(i_s, u_s, est.omega_hat))
        return u

    def internals(self) -> tuple[float, ...]:
        out = list(self.foc.internals())
        for obs, est in self.chains.values():
            w = obs.omega_hat if est is None else est.omega_r
            out += [w, obs.i_m.real, obs.i_m.imag]
        return tuple(out)


def _fig48_scenario(load: float) -> Scenario:
    t0 = T_MAGNETISE
    return Scenario(
        f"fig4.8-{load:g}Nm", f"Fig. 4.8: speed 10 -> 12 -> 10 rad/s at {load:g} N m",
        t0 + 2.0, lambda t: 0.0 if t < t0 else 12.0 if t0 + 1.0 <= t < t0 + 1.5 else 10.0,
        lp.gated(lp.constant(load), t0),
    )  # fmt: skip


def _win(res: SimResult, t_from: float) -> np.ndarray:
    return res["/rig/t"] >= t_from


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2)))


#: voltage-sensor offset of ``fig4.8-offset``: 12.5 mV at the ADC of phase a = 0.5 V on u_a (divider 1/40,
#: 2.5 ADC codes), a DC offset of 1/3 V in the stator-fixed u_s the estimators integrate
U_OFFSET_ADC = (0.0125, 0.0, 0.0)


@register("fig4.8", "speed 10 -> 12 -> 10 rad/s at 2 and 9 N m: rotor-equation estimator on JL flux A/B/C, Kubota 1.2x (D)")
def fig4_8(out_dir: Path) -> dict[str, Any]:
    return _fig48(out_dir, "fig4.8", {}, None,
                  "Fig. 4.8: speed estimation at low and high load (FOC on the encoder; estimators passive)")  # fmt: skip


@register("fig4.8-offset", "fig4.8 with the measured voltage and a 0.5 V offset on u_a: the voltage model's weakness (C)")
def fig4_8_offset(out_dir: Path) -> dict[str, Any]:
    out = _fig48(out_dir, "fig4.8-offset", {"voltage_source": "measured"}, {"voltages": {"offset": list(U_OFFSET_ADC)}},
                 "Fig. 4.8 with a DC offset in the measured voltage (0.5 V on $u_a$ = 1/3 V in $u_s$; estimators "
                 "get the measured voltage)")  # fmt: skip
    out["voltage_offset_adc_V"] = U_OFFSET_ADC
    out["voltage_offset_u_s_V"] = 2.0 / 3.0 * U_OFFSET_ADC[0] * 40.0
    return out


def _fig48(out_dir: Path, name: str, foc_params: dict[str, Any], mock: dict[str, Any] | None,
           title: str) -> dict[str, Any]:  # fmt: skip
    plt = pyplot()
    loads = (2.0, 9.0)
    t_from = T_MAGNETISE + 0.5
    runs = {ld: simulate(_fig48_scenario(ld), make=lambda ctx: PassiveEstimators(ctx, foc_params, t_start=t_from),
                         mock=mock) for ld in loads}  # fmt: skip
    labels = {"A": "rotor eq., JL mostly current model", "B": "rotor eq., JL balanced (thesis K)",
              "C": "rotor eq., JL mostly voltage model", "D": "Kubota, poles 1.2x"}  # fmt: skip
    fig, axs = plt.subplots(4, 2, figsize=(10, 10), sharex=True)
    out: dict[str, Any] = {"foc_params": foc_params, "mock": mock,
                           "jl_weightings_k1_k2_times_1+0.1j": JL_WEIGHTINGS, "kubota": KUBOTA_48,
                           "rotor_eq_tau": ROTOR_EQ_TAU, "start": "estimators start at t = 0.9 s from the steady state at 10 rad/s",
                           "results": {}}  # fmt: skip
    for col, ld in enumerate(loads):
        r = runs[ld]
        t = r["/rig/t"]
        w_true = r["/truth/omega_r"]
        ok = _win(r, t_from)
        for row, key in enumerate(labels):
            ax = axs[row, col]
            w = r[f"/ctrl/omega_{key.lower()}"]
            ax.plot(t[ok], w_true[ok], color="tab:gray", lw=1.5, label="true")
            ax.plot(t[ok], w[ok], "k", lw=0.8, label="estimate")
            ax.set_ylim(6, 16)
            ax.grid(alpha=0.3)
            if col == 0:
                ax.set_ylabel(speed_label(f"{key}\n"))
            if row == 0:
                ax.set_title(f"load {ld:g} N m")
            ax.text(0.01, 0.95, labels[key], transform=ax.transAxes, fontsize=8, va="top")
            e = (w - w_true)[ok]
            # response to the 10 -> 12 step: time until the estimate is within 0.5 rad/s of the truth
            t_step = T_MAGNETISE + 1.0
            after = (t >= t_step) & (t < t_step + 0.5)
            bad = np.flatnonzero(np.abs((w - w_true)[after]) > 0.5)
            settle = float(t[after][bad[-1]] - t_step) if bad.size else 0.0
            out["results"][f"{key} {ld:g}Nm"] = {
                "speed_error_rms": _rms(e), "speed_error_max": float(np.max(np.abs(e))),
                "speed_error_mean": float(np.mean(e)), "settle_to_0.5rad_s_after_step_s": settle,
                "ripple_std_at_10rad_s": float(np.std((w - w_true)[(t >= t_from + 0.1) & (t < T_MAGNETISE + 1.0)])),
            }  # fmt: skip
        axs[-1, col].set_xlabel("t [s]")
    axs[0, 0].legend(fontsize=8, loc="lower right")
    save_figure(fig, out_dir, name, title)
    return out


# --- Figs 4.9-4.12: FOC on the encoder, Kubota alongside ---------------------------------------
ALONGSIDE = {"speed_estimator": "kubota", "kubota_pole_ratio": 1.2, "kubota_lambda_c": 1000.0}
_cache: dict[str, SimResult] = {}


def _alongside(scn_name: str) -> SimResult:
    if scn_name not in _cache:
        _cache[scn_name] = simulate(scenarios.get(scn_name), ALONGSIDE)
    return _cache[scn_name]


def _speed_fig(out_dir: Path, name: str, scn_name: str, error: bool, title: str) -> dict[str, Any]:
    plt = pyplot()
    r = _alongside(scn_name)
    t, w, w_est, w_ref = r["/rig/t"], r["/truth/omega_r"], r["/ctrl/omega_est"], r["/rig/omega_r_ref"]
    m_l = r["/rig/m_l_ref"]
    ok = t >= T_MAGNETISE
    fig, ax = plt.subplots(figsize=(10, 4.5))
    if error:
        ax.plot(t[ok], (w_est - w)[ok], "k", lw=0.7)
        ax.set_ylabel(speed_label(r"$\hat\omega_r - \omega_r$"))
    else:
        ax.plot(t[ok], w_ref[ok], color="tab:gray", lw=0.8, ls=":", label="reference")
        ax.plot(t[ok], w[ok], "k", lw=1, label="true speed")
        ax.plot(t[ok], w_est[ok], "tab:red", lw=0.8, ls="--", label="Kubota estimate")
        ax.set_ylabel(speed_label())
        ax.legend(fontsize=8)
        if np.any(m_l != 0):
            ax2 = ax.twinx()
            ax2.plot(t[ok], m_l[ok], color="tab:blue", lw=0.6, alpha=0.5)
            ax2.set_ylabel("load [N m]", color="tab:blue")
    ax.set_xlabel("t [s]")
    ax.grid(alpha=0.3)
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(out_dir / f"{name}.png", dpi=110)
    plt.close(fig)
    e = (w_est - w)[ok]
    out: dict[str, Any] = {"scenario": scn_name, "foc_params": ALONGSIDE,
                           "speed_error_rms": _rms(e), "speed_error_max": float(np.max(np.abs(e))),
                           "tracking_error_rms_true_speed": _rms((w_ref - w)[ok])}  # fmt: skip
    return out


def _per_level(r: SimResult) -> dict[str, float]:
    """Peak |estimate error| in the 0.5 s after each reference step, by the level stepped to."""
    t, w, w_est, w_ref = r["/rig/t"], r["/truth/omega_r"], r["/ctrl/omega_est"], r["/rig/omega_r_ref"]
    steps = np.flatnonzero(np.diff(w_ref) != 0) + 1
    out = {}
    for i in steps:
        win = (t >= t[i]) & (t < t[i] + 0.5)
        out[f"{w_ref[i - 1]:g}->{w_ref[i]:g}"] = float(np.max(np.abs((w_est - w)[win])))
    return out


@register("fig4.9", "FOC with measured speed, speed-reference steps, Kubota's estimate alongside")
def fig4_9(out_dir: Path) -> dict[str, Any]:
    out = _speed_fig(out_dir, "fig4.9", "fig4.9", False,
                     "Fig. 4.9: FOC on the encoder, steps of 25 rad/s, Kubota's estimate (poles 1.2x, $\\lambda_c$ = 1000)")
    out["peak_error_after_step"] = _per_level(_alongside("fig4.9"))
    return out


@register("fig4.10", "speed-estimation error of Kubota's method during the steps of fig4.9")
def fig4_10(out_dir: Path) -> dict[str, Any]:
    out = _speed_fig(out_dir, "fig4.10", "fig4.9", True, "Fig. 4.10: Kubota speed-estimation error during the steps of Fig. 4.9")
    out["peak_error_after_step"] = _per_level(_alongside("fig4.9"))
    return out


def _sweep_stats(r: SimResult) -> dict[str, Any]:
    t, w, w_est = r["/rig/t"], r["/truth/omega_r"], r["/ctrl/omega_est"]
    m_l = r["/rig/m_l_ref"]
    ok = t >= T_MAGNETISE + 1.0
    e = w_est - w
    # regenerating (load drives the shaft: omega < 0 with a positive load) vs motoring, and near zero
    regen = ok & (w < -1.0) & (m_l > 0)
    motor = ok & (w > 1.0) & (m_l > 0)
    zero = ok & (np.abs(w) <= 1.0)
    return {"rms_motoring": _rms(e[motor]), "rms_regenerating": _rms(e[regen]), "rms_near_zero": _rms(e[zero]),
            "max_motoring": float(np.max(np.abs(e[motor]))), "max_regenerating": float(np.max(np.abs(e[regen])))}  # fmt: skip


@register("fig4.11", "slow sweep -15 -> 15 -> -15 rad/s, load 3 <-> 7 N m every 2 s, Kubota's estimate alongside")
def fig4_11(out_dir: Path) -> dict[str, Any]:
    out = _speed_fig(out_dir, "fig4.11", "fig4.11", False,
                     "Fig. 4.11: speed sweep with load steps 3 <-> 7 N m, Kubota's estimate (dashed)")
    out.update(_sweep_stats(_alongside("fig4.11")))
    return out


@register("fig4.12", "speed-estimation error of Kubota's method during the sweep of fig4.11")
def fig4_12(out_dir: Path) -> dict[str, Any]:
    out = _speed_fig(out_dir, "fig4.12", "fig4.11", True, "Fig. 4.12: Kubota speed-estimation error during the sweep of Fig. 4.11")
    out.update(_sweep_stats(_alongside("fig4.11")))
    return out
