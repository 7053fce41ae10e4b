"""Figs 4.6 and 4.7: when Kubota's speed adaptation (4.21) runs away (thesis Sec. 4.4.2).

* ``fig4.6`` - the steady-state angle (4.28), angle(e_is) - angle(i_m_hat), over omega_mR for
  omega_r = 10 and omega_hat = 15 rad/s, and the sign of d omega_hat/dt = lambda_c Im{e_is^* i_m_hat}
  it implies: where the estimate moves away from the true speed the observer diverges.
* ``fig4.7`` - the observer (G = 0, lambda_c = 1000) fed the exact steady state of the motor at
  omega_r = 10, omega_mR = 4 rad/s (regenerating): the speed estimate runs away. The same
  observer at omega_mR = 14 rad/s (motoring) converges.

Both use the nominal motor (3.57) and the steady state (3.53)-(3.55).
"""

from __future__ import annotations

import cmath
import math
from pathlib import Path
from typing import Any

import numpy as np

from bench.controllers.observers import KubotaObserver, sc_matrix
from bench.params import T_S_DEFAULT, MotorParams
from bench.core.plotstyle import speed_label
from bench.workflows.reproduce import register


def steady_state_x(motor: MotorParams, omega_r: float, omega_mR: float) -> np.ndarray:
    """[i_s, i_m] per unit u_ss in the frame rotating at omega_mR: (-A_sc + j omega_mR)^-1 B_sc (3.53)."""
    a11, a12, a21, a22 = sc_matrix(motor, omega_r)
    A = np.array([[a11, a12], [a21, a22]])
    B = np.array([motor.L_r / (motor.L_s * motor.L_r - motor.L_m**2), 0.0])
    return np.linalg.solve(-A + 1j * omega_mR * np.eye(2), B)


def angle_4_28(motor: MotorParams, omega_r: float, omega_hat: float, omega_mR: float) -> tuple[float, float]:
    """(angle(e_is) - angle(i_m_hat) [rad] from (4.28), Im{e_is^* i_m_hat} per unit |u_ss|^2)."""
    x, xh = steady_state_x(motor, omega_r, omega_mR), steady_state_x(motor, omega_hat, omega_mR)
    e = x[0] - xh[0]
    ang = cmath.phase(e) - cmath.phase(xh[1])
    return math.remainder(ang, 2 * math.pi), float((np.conj(e) * xh[1]).imag)


def divergence_boundary(motor: MotorParams, omega_r: float) -> float:
    """Closed form of the sign change of Im{e_is^* i_m_hat} at omega_mR > 0 (found here, not in the
    thesis): omega_mR* = omega_r R_s/(R_s + R_r), independent of omega_hat. Between 0 and omega_mR*
    (the flux turning slower than this, same sign as omega_r) the estimate moves away."""
    return omega_r * motor.R_s / (motor.R_s + motor.R_r)


@register("fig4.6", "steady-state angle (4.28) vs omega_mR, omega_r = 10, omega_hat = 15: where Kubota diverges")
def fig4_6(out_dir: Path) -> dict[str, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = MotorParams()
    w_r, w_hat = 10.0, 15.0
    grid = np.linspace(-30.0, 40.0, 1401)
    vals = [angle_4_28(m, w_r, w_hat, w) for w in grid]
    ang = np.degrees([v[0] for v in vals])
    drive = np.array([v[1] for v in vals])
    away = drive > 0  # d omega_hat/dt > 0 while omega_hat > omega_r: the error grows
    # sign changes of the adaptation drive, located by bisection on the grid
    crossings = []
    for i in np.flatnonzero(np.diff(np.sign(drive)) != 0):
        lo, hi = grid[i], grid[i + 1]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if np.sign(angle_4_28(m, w_r, w_hat, mid)[1]) == np.sign(drive[i]):
                lo = mid
            else:
                hi = mid
        crossings.append(0.5 * (lo + hi))
    boundary = divergence_boundary(m, w_r)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(grid, ang, "k", lw=1.2, label=r"$\angle e_{is} - \angle\hat{i}_m$ (4.28)")
    ax.fill_between(grid, -180, 180, where=away, color="tab:red", alpha=0.15,
                    label=r"$\dot{\hat\omega}_r>0$: estimate runs away")  # fmt: skip
    ax.axvline(boundary, color="tab:red", ls="--", lw=1, label=rf"$\omega_r R_s/(R_s+R_r)$ = {boundary:.2f} rad/s")
    ax.axvline(5.0, color="tab:gray", ls=":", lw=1, label="thesis: diverges below 5 rad/s")
    ax.set_xlabel(r"$\omega_{mR}$ [rad/s]")
    ax.set_ylabel("angle [deg]")
    ax.set_ylim(-185, 185)
    ax.set_yticks(range(-180, 181, 90))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(r"Fig. 4.6: steady state, $\omega_r$ = 10, $\hat\omega_r$ = 15 rad/s, motor (3.57)")
    fig.tight_layout()
    fig.savefig(out_dir / "fig4.6.png", dpi=120)
    plt.close(fig)
    runaway = grid[away]
    return {
        "omega_r": w_r, "omega_hat": w_hat,
        "runaway_interval_omega_mR": [float(runaway.min()), float(runaway.max())] if runaway.size else None,
        "sign_changes_omega_mR": crossings,
        "closed_form_boundary": boundary,
        "thesis_boundary": 5.0,
        "angle_deg_at": {str(w): float(np.degrees(angle_4_28(m, w_r, w_hat, w)[0])) for w in (-10.0, 2.0, 4.0, 8.0, 20.0)},
    }  # fmt: skip


def run_steady(motor: MotorParams, omega_r: float, omega_mR: float, omega0: float, seconds: float,
               i_mR: float = 2.5, start: complex = 0.8 * cmath.exp(0.3j), pole_ratio: float = 1.0,
               lambda_c: float = 1000.0) -> dict[str, np.ndarray]:  # fmt: skip
    """Kubota's observer fed the exact steady state of (3.41); estimates returned in the flux frame.

    The true i_m = i_mR (real) in the flux frame; the initial current estimates are the true ones
    times ``start``, the initial speed estimate ``omega0``.
    """
    T = T_S_DEFAULT
    x = steady_state_x(motor, omega_r, omega_mR)
    u_ss = i_mR / x[1]
    i_ss, i_ms = complex(x[0] * u_ss), complex(x[1] * u_ss)
    obs = KubotaObserver(motor, T, pole_ratio=pole_ratio, lambda_c=lambda_c, omega0=omega0)
    back = cmath.exp(-1j * omega_mR * T)
    obs.i_s_hat, obs.i_m = i_ss * start * back, i_ms * start * back
    n = int(round(seconds / T))
    t = np.arange(n) * T
    i_s_f, i_m_f, w = np.empty(n, complex), np.empty(n, complex), np.empty(n)
    for k in range(n):
        rot = cmath.exp(1j * omega_mR * k * T)
        u = u_ss * cmath.exp(1j * omega_mR * (k - 0.5) * T)  # held over the period: its mid value
        obs.update(i_ss * rot, u, 0.0)
        i_s_f[k], i_m_f[k], w[k] = obs.i_s_hat / rot, obs.i_m / rot, obs.omega_hat
    return {"t": t, "i_s_hat": i_s_f, "i_m_hat": i_m_f, "omega_hat": w, "i_ss": i_ss, "i_ms": i_ms}


@register("fig4.7", "Kubota observer (G = 0, lambda_c = 1000) in steady state at omega_r = 10, omega_mR = 4: diverges")
def fig4_7(out_dir: Path) -> dict[str, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = MotorParams()
    seconds = 3.0
    cases = {"regenerating, omega_mR = 4 (thesis)": 4.0, "motoring, omega_mR = 14": 14.0}
    runs = {name: run_steady(m, 10.0, w, 11.0, seconds) for name, w in cases.items()}
    fig, axs = plt.subplots(2, 2, figsize=(10, 7))
    out: dict[str, Any] = {"omega_r": 10.0, "omega_hat_0": 11.0, "G": 0, "lambda_c": 1000.0, "cases": {}}
    for col, (name, r) in enumerate(runs.items()):
        ax = axs[0, col]
        for key, true, c in (("i_s_hat", r["i_ss"], "tab:blue"), ("i_m_hat", r["i_ms"], "tab:green")):
            z = r[key]
            ax.plot(z.real, z.imag, color=c, lw=1, label=key.replace("_hat", " estimate"))
            ax.plot(true.real, true.imag, "*", color=c, ms=12)
            ax.plot(z[0].real, z[0].imag, "s", color=c, mfc="none", ms=8)
        ax.set_aspect("equal", "datalim")
        ax.set_title(f"{name}\nflux frame: true * , initial estimate \u25a1", fontsize=9)
        ax.set_xlabel("d [A]")
        ax.set_ylabel("q [A]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax = axs[1, col]
        ax.plot(r["t"], r["omega_hat"], "k", lw=1, label=r"$\hat\omega_r$")
        ax.axhline(10.0, color="tab:red", ls="--", lw=1, label=r"$\omega_r$")
        ax.set_xlabel("t [s]")
        ax.set_ylabel(speed_label())
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        w = r["omega_hat"]
        e_s = np.abs(r["i_s_hat"] - r["i_ss"])
        k_min = int(np.argmin(e_s))
        out["cases"][name] = {
            "omega_mR": cases[name], "omega_hat_end": float(w[-1]), "omega_hat_min": float(w.min()),
            "omega_hat_max": float(w.max()), "i_s_error_start": float(e_s[0]), "i_s_error_min": float(e_s[k_min]),
            "t_i_s_error_min": float(r["t"][k_min]), "i_s_error_end": float(e_s[-1]),
            "i_m_error_end": float(abs(r["i_m_hat"][-1] - r["i_ms"])),
        }  # fmt: skip
    fig.suptitle("Fig. 4.7: Kubota's observer fed the steady state at $\\omega_r$ = 10 rad/s, G = 0, $\\lambda_c$ = 1000")
    fig.tight_layout()
    fig.savefig(out_dir / "fig4.7.png", dpi=120)
    plt.close(fig)
    return out
