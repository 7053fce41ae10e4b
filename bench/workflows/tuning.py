"""Relay-feedback tuning of the speed PI (thesis Sec. 4.2; Åström-Hägglund relay method, Ziegler-Nichols rules).

`tune_speed` runs the relay experiment (`bench.controllers.relay`, scenario ``relay0``) as an ordinary
bench session, so it works on the mock rig, the emulated rig and a real rig alike, then
`relay_analysis` reads the oscillation from the log:

* period T_u from the relay's switching instants, omega_u = 2 pi / T_u;
* the loop's frequency response at omega_u, G(j omega_u) = c_omega / c_m, from the first harmonics of
  the speed the relay saw (c_omega) and of the relay's torque reference (c_m) over whole periods.
  The path from torque reference to filtered encoder speed (current loop, mechanics, encoder,
  filter) is linear to first order, so this ratio measures it directly;
* the ultimate gain K_u = 1/|G(j omega_u)| and the phase of G there, which is -180 deg for an ideal
  relay without hysteresis and lies 15-30 deg above that with the hysteresis needed against
  encoder noise (the Åström-Hägglund reading of the relay experiment);
* Ziegler-Nichols PI (1942): K_p = 0.45 K_u, T_i = T_u / 1.2.

Why not the describing function 4d/(pi a) for K_u: it assumes the relay sees a sinusoid. With the
thesis' 1024-line encoder at 3 kHz the oscillation spans only a few counts, the relay switches on
quantisation noise as much as on the oscillation, and 4d/(pi a) came out up to 3x too high on the
mock rig, while c_omega/c_m stayed within 5 % of the speed loop's linear model (tests/test_tuning.py,
docs/RESULTS.md). The describing-function value is still reported (``K_u_df``) for comparison.

Units: d [N m], speed [rad/s electrical], so K_p comes in N m s/rad like the FOC's ``speed_Kp``.
"""

from __future__ import annotations

import json
import math
import shlex
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.errors import BadInput
from bench.core.plotstyle import speed_label
from bench.core.scenarios import T_MAGNETISE
from bench.controllers.relay import RelayTuneController
from bench.daq import LogReader
from bench.runtime.session import RunOptions, run

SETTLE = 0.5  # [s] after the magnetising lead-in before the oscillation is analysed
PHASE_WARN = 30.0  # [deg] identified point further than this from -180 deg: warn


@dataclass(frozen=True)
class RelayResult:
    d: float  # relay amplitude [N m]
    eps: float  # hysteresis [rad/s]
    T_u: float  # oscillation period [s]
    omega_u: float  # 2 pi / T_u [rad/s]
    G_re: float  # G(j omega_u), torque reference -> filtered speed [rad/s per N m]
    G_im: float
    K_u: float  # 1 / |G(j omega_u)| [N m s/rad]
    phase_deg: float  # angle of G(j omega_u) [deg]
    a: float  # first-harmonic speed amplitude [rad/s]
    K_u_df: float  # describing-function estimate 4 d / (pi a), for comparison only
    n_periods: int
    speed_Kp: float  # Ziegler-Nichols PI
    speed_Ti: float
    warnings: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _first_harmonic(t: np.ndarray, x: np.ndarray, w: float) -> complex:
    return complex(2.0 * np.mean((x - x.mean()) * np.exp(-1j * w * t)))


def relay_analysis(t: np.ndarray, omega: np.ndarray, m_e: np.ndarray, *, d: float, eps: float,
                   t_from: float = 0.0) -> RelayResult:  # fmt: skip
    """Ultimate gain and period from a relay experiment's log (see the module docstring).

    ``omega`` is the speed the relay switched on, ``m_e`` the relay's torque reference. Raises
    `BadInput` if fewer than three whole oscillation periods are found after ``t_from``.
    """
    sel = t >= t_from
    t, omega, m_e = t[sel], omega[sel], m_e[sel]
    rising = np.flatnonzero((m_e[1:] > 0) & (m_e[:-1] <= 0)) + 1  # relay switches to +d
    if rising.size < 4:
        raise BadInput("relay", f"only {max(rising.size - 1, 0)} whole oscillation periods after t = {t_from:.2f} s; "
                                "allowed: a longer run or a larger relay_amplitude")  # fmt: skip
    periods = np.diff(t[rising])
    T_u = float(np.mean(periods))
    w_u = 2.0 * math.pi / T_u
    i0, i1 = rising[0], rising[-1]  # whole periods only
    tt = t[i0:i1]
    c_w = _first_harmonic(tt, omega[i0:i1], w_u)
    c_m = _first_harmonic(tt, m_e[i0:i1], w_u)
    G = c_w / c_m
    K_u = 1.0 / abs(G)
    phase = math.degrees(math.atan2(G.imag, G.real))
    a = abs(c_w)
    warnings: list[str] = []
    if abs(abs(phase) - 180.0) > PHASE_WARN:
        warnings.append(f"the oscillation is at {phase:.0f} deg, more than {PHASE_WARN:g} deg from -180 deg: "
                        "lower relay_hysteresis")  # fmt: skip
    if np.std(periods) > 0.1 * T_u:
        warnings.append(f"periods vary by {np.std(periods) / T_u:.0%}: the oscillation is not steady")
    return RelayResult(d=d, eps=eps, T_u=T_u, omega_u=w_u, G_re=G.real, G_im=G.imag, K_u=K_u, phase_deg=phase, a=a,
                       K_u_df=4.0 * d / (math.pi * a), n_periods=int(periods.size), speed_Kp=0.45 * K_u,
                       speed_Ti=T_u / 1.2, warnings=tuple(warnings))  # fmt: skip


def tune_speed(rig: str = "mock", *, params: dict[str, Any] | None = None, duration: float | None = None,
               seed: int = 0, out_dir: Path = Path("runs"), progress: bool = False, realtime: bool | None = None,
               allow_soft_realtime: bool = False, live: dict[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    """Run the relay experiment on ``rig`` and return the analysis, the run summary and file paths.
    ``live``: RunOptions' live_port/live_host/live_rate (bench.daq.live), to watch the experiment.

    ``params`` are `RelayTuneController` parameters (``relay_amplitude``, ``relay_hysteresis`` and
    the FOC's). Writes the run folder of an ordinary session (log, summary, run plot) plus
    ``tune.json`` and ``tune.png`` (the oscillation that was analysed).
    """

    p = {**RelayTuneController.defaults, **(params or {})}
    summary, code = run(RunOptions(rig=rig, controller="relay_tune", scenario="relay0", duration=duration, seed=seed,
                                   params=params or {}, out_dir=out_dir, progress=progress, realtime=realtime,
                                   allow_soft_realtime=allow_soft_realtime, label="bench tune speed",
                                   **(live or {})))  # fmt: skip
    if code != 0:
        return {"tripped": summary["trip_cause"], "run": summary, "exit_code": code}
    log = Path(summary["log"])
    r = LogReader(log)
    rig_t, ctrl = r.read("/rig"), r.read("/ctrl")
    res = relay_analysis(rig_t["t"], ctrl["omega_hat"], ctrl["m_e_ref"], d=p["relay_amplitude"],
                         eps=p["relay_hysteresis"], t_from=T_MAGNETISE + SETTLE)  # fmt: skip
    folder = log.parent
    png = plot_relay(rig_t["t"], ctrl["omega_hat"], ctrl["m_e_ref"], res, folder / "tune.png")
    gains = {"speed_Kp": float(f"{res.speed_Kp:.4g}"), "speed_Ti": float(f"{res.speed_Ti:.4g}")}
    command = " ".join(["bench run", *(["--rig", shlex.quote(rig)] if rig != "mock" else []),
                        *(f"-p {k}={v:g}" for k, v in gains.items())])  # fmt: skip
    out = {"relay": res.as_dict(), "suggested_params": {"speed_Kp": res.speed_Kp, "speed_Ti": res.speed_Ti},
           "command": command, "rig": rig, "seed": seed, "log": str(log), "plot": str(png), "run_plot": summary["plot"]}  # fmt: skip
    (folder / "tune.json").write_text(json.dumps(out, indent=2))
    out["json"] = str(folder / "tune.json")
    return out


def plot_relay(t: np.ndarray, omega: np.ndarray, m_e: np.ndarray, res: RelayResult, png: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t0 = T_MAGNETISE + SETTLE
    win = (t >= t0) & (t <= t0 + 6 * res.T_u)
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5))
    ax1.plot(t[win], omega[win], lw=0.8, label=r"$\hat\omega_r$ (filtered encoder)")
    ax1.axhline(res.eps, ls=":", c="k", lw=0.8, label=r"$\pm\varepsilon$")
    ax1.axhline(-res.eps, ls=":", c="k", lw=0.8)
    ax1.set_ylabel(speed_label())
    ax1.legend(loc="upper right", fontsize=8)
    ax1.set_title(f"relay experiment: d = {res.d:g} N m, eps = {res.eps:g} rad/s -> T_u = {1e3 * res.T_u:.1f} ms, "
                  f"G(j omega_u) at {res.phase_deg:.0f} deg\nK_u = 1/|G| = {res.K_u:.3f} N m s/rad; "
                  f"ZN PI: K_p = {res.speed_Kp:.3f}, T_i = {1e3 * res.speed_Ti:.1f} ms", fontsize=9)  # fmt: skip
    ax2.plot(t[win], m_e[win], lw=0.8, c="C3")
    ax2.set_ylabel("relay torque ref. [N m]")
    ax2.set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png
