"""`bench reproduce fig5.5 | fig5.6`: the LPV flux observer design figures (thesis 5.6.2), from the synthesis
library's designs (`synthesis.models.flux_observer`, `synthesis.lower_bound`).

Each writes NAME.png into out_dir and returns the numbers (JSON-ready); the `bench reproduce` registry
(bench/workflows/reproduce.py) writes NAME.json from the returned dict. Fig. 5.5's grid runs on the sweep engine, which
is why this lives in the bench and not in the synthesis library (that imports nothing of the bench).

- ``fig5.5``: γ_a as a function of ω_r,max (10 ... 400 rad/s), Thm 5.15 with bisection, for both readings
  of 5.6.1, with the independent lower bound of each (issue 12) and the curve of the earlier numerics.
- ``fig5.6``: frequency responses at ω_r = 10 rad/s (positive frequencies 0.1 ... 1e4 rad/s) of the
  LPV observer (ω_r,max = 200, γ = 1.1 γ_a; and the design of the earlier numerics), the JL observer (K_1 = 32(1 +
  0.1j), K_2 = 2(1 + 0.1j)) and the current model (JL with K_1 = 10000, K_2 = 0): ī_s → î_m and ū_s → î_m.
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.core.config import read_toml
from bench.core.plotstyle import pyplot
from bench.workflows.reproduce import register
from bench.workflows.sweep import table
from bench.workflows.sweep.engine import run_sweep
from bench.workflows.sweep.spec import parse
from bench.workflows.sweep.tasks import THESIS_GAMMA, plot_fig5_5
from synthesis.models.flux_observer import JL_K1, JL_K2, design_flux_observer, jl_response, observer_response

__all__ = ["fig5_5", "fig5_6", "plot_fig5_5"]

SWEEP_FIG5_5 = Path(__file__).resolve().parents[3] / "sweeps" / "fig5.5.toml"


@register("fig5.5", "gamma_a of the LPV flux observer versus omega_r,max (10..400 rad/s), 3 kHz")
def fig5_5(out_dir: Path, omegas: tuple[float, ...] | None = None, *, workers: int | None = 2,
           scheduler: str | None = None, progress: bool = False, sweep_dir: Path | None = None) -> dict[str, Any]:  # fmt: skip
    """γ_a(ω_r,max) (Fig. 5.5) for both readings of 5.6.1 with the independent lower bound of each
    (`synthesis.lower_bound`), and γ_a with the earlier numerics (diagonal re-balancing).

    The grid is the sweep file ``sweeps/fig5.5.toml`` (task ``flux_observer_gamma``) on the sweep engine
    (`bench.workflows.sweep`: a local Dask cluster of ``workers``, or ``scheduler``); ``omegas`` replaces its
    ω_r,max axis. Its table lands in ``sweep_dir`` (default ``runs/sweeps/fig5.5``, where a re-run resumes;
    with ``omegas``, a temporary folder), not next to the figure, which may be docs/figures.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    data, text = read_toml(SWEEP_FIG5_5, "a sweep file")
    if omegas is not None:
        data["design"]["axes"]["task.omega_r_max"] = [float(w) for w in omegas]
        text = ""
    spec = parse(data, name="fig5.5", source=text)
    with tempfile.TemporaryDirectory(prefix="fig5.5-") as tmp:
        where = Path(sweep_dir) if sweep_dir else (Path(tmp) if omegas is not None else Path("runs/sweeps/fig5.5"))
        res = run_sweep(spec, where, workers=None if scheduler else workers, scheduler=scheduler,
                        progress=progress)  # fmt: skip
        rows = table.read(Path(res["results"]))
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise RuntimeError(f"fig5.5: {len(bad)} grid point(s) failed, e.g. {bad[0]['error']}")
    curves: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        curves.setdefault(r["label.curve"], []).append(
            dict(omega_r_max=r["task.omega_r_max"], **{k[4:]: r[k] for k in r if k.startswith("out.")}))
    for c in curves.values():
        c.sort(key=lambda r: r["omega_r_max"])
    plot_fig5_5(curves, out_dir / "fig5.5.png")
    full, thesis, before = (curves[k] for k in ("full", "thesis reading", "diagonal re-balancing"))
    return dict(
        figure="fig5.5",
        description="gamma_a(omega_r_max) and the independent lower bound (worst frozen-speed optimal LTI observer, "
                    "Riccati), sigma_i = sigma_u = 1e-4, 3 kHz, bilinear discretisation, both readings of 5.6.1",
        full=full,
        thesis_reading=thesis,
        full_numerics_diagonal_rebalancing=[{k: r[k] for k in ("omega_r_max", "gamma_a")} for r in before],
        thesis_gamma_a_at_200=THESIS_GAMMA / 1.1,
        sweep={k: res[k] for k in ("results", "workers", "wall_time_s", "ran", "skipped")},
        wall_time=time.perf_counter() - t0,
    )


@register("fig5.6", "Bode plots at omega_r = 10 rad/s: LPV observer vs JL vs current model")
def fig5_6(out_dir: Path, omega_r: float = 10.0) -> dict[str, Any]:
    """Frequency responses of the three observers at ω_r = 10 rad/s (Fig. 5.6)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    d = design_flux_observer(200.0)
    d_before = design_flux_observer(200.0, rescale="diagonal", check=False)  # γ_a ≈ 2.5x the optimum
    w = np.logspace(-1, 4, 400)
    lpv = observer_response(d, omega_r, w)
    lpv_before = observer_response(d_before, omega_r, w)
    jl = jl_response(omega_r, JL_K1, JL_K2, w)
    cm = jl_response(omega_r, 10000.0, 0.0, w)
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    titles = ("ī_s → î_m", "ū_s → î_m")
    for col in range(2):
        for (H, style, lab) in ((lpv, "-", "LPV observer, γ_a at the bound"),
                                (lpv_before, "-.", "LPV observer, γ_a 2.5x (diagonal re-balancing)"),
                                (jl, "--", "JL observer"), (cm, ":", "current model")):  # fmt: skip
            axes[0, col].semilogx(w, 20 * np.log10(np.abs(H[col]) + 1e-300), style, label=lab)
            axes[1, col].semilogx(w, np.degrees(np.angle(H[col])), style, label=lab)
        axes[0, col].set_title(titles[col])
        axes[0, col].set_ylabel("gain [dB]")
        axes[1, col].set_ylabel("phase [deg]")
        axes[1, col].set_xlabel("ω [rad/s]")
        for r in range(2):
            axes[r, col].axvline(math.pi / d.Ts, color="grey", lw=0.8)
            axes[r, col].grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"Fig. 5.6: observers at ω_r = {omega_r:g} rad/s (grey: Nyquist of the 3 kHz LPV observer)")
    fig.tight_layout()
    fig.savefig(out_dir / "fig5.6.png", dpi=120)
    plt.close(fig)
    pick = np.unique(np.searchsorted(w, [0.1, 1, 3, 10, 30, 100, 300, 1000, 3000, 9000]).clip(0, len(w) - 1))

    def table(H: tuple[np.ndarray, np.ndarray]) -> dict:
        return {name: [dict(w=float(w[k]), gain_db=float(20 * np.log10(abs(h[k]) + 1e-300)),
                            phase_deg=float(np.degrees(np.angle(h[k])))) for k in pick]
                for name, h in zip(("i_s_to_i_m", "u_s_to_i_m"), H)}  # fmt: skip

    ver = d.verification.as_dict() if d.verification else None
    return dict(
        figure="fig5.6",
        omega_r=omega_r,
        lpv=dict(gamma_a=d.gamma_a, gamma=d.gamma, gamma_lower_bound=d.lower_bound.value if d.lower_bound else None,
                 omega_r_max=200.0, n_c=d.controller.K.n_c, response=table(lpv), verification=ver),
        lpv_diagonal_rebalancing=dict(gamma_a=d_before.gamma_a, gamma=d_before.gamma, response=table(lpv_before)),  # fmt: skip
        jl=dict(K1=[JL_K1.real, JL_K1.imag], K2=[JL_K2.real, JL_K2.imag], response=table(jl)),
        current_model=dict(K1=10000.0, K2=0.0, response=table(cm)),
        wall_time=time.perf_counter() - t0,
    )
