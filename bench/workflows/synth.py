"""`bench synth ...`: design an LPV controller with `synthesis/`, verify it, save it as an artifact.

Each design writes ``OUT.npz`` + ``OUT.json`` (`synthesis.artifacts`: plain files, no pickle) that the
runtime plugins load. The JSON carries the model parameters, γ_a and γ, the solver settings, the
independent verification report, timings and the creation date. A construction that fails
verification raises (`synthesis.verify.VerificationError`), so no artifact is written for it.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from bench.errors import BadInput, DesignFailed
from synthesis.environment import environment
from synthesis.lmi import DEFAULT_SOLVER_OPTS
from bench.core.config import load as load_rig
from synthesis.artifacts import MOTOR_KEYS, save_controller, _jsonable, ArtifactError
from synthesis.models.motor import MotorData
from synthesis.models.current_controller import CurrentSpec, design_current_controller, summary as current_summary
from synthesis.models.flux_observer import VARIANTS, design_flux_observer, summary
from synthesis.construct import ConstructionError
from synthesis.verify import VerificationError
from synthesis.narx import load_model
from bench.controllers.excitation import ExcitationController
from synthesis.mlp_lft import gain_uncertainty, lft_from_model
from synthesis.models.speed_controller import (
    THESIS, SpeedSpec, design_robust_speed_controller, design_speed_controller, runtime_data, sampled_report,
)

Progress = Callable[[str], None]


def _solver_settings() -> dict[str, Any]:
    import clarabel
    import cvxpy


    return {"solver": "CLARABEL", "options": dict(DEFAULT_SOLVER_OPTS), "cvxpy": cvxpy.__version__,
            "clarabel": clarabel.__version__, "environment": environment()}  # fmt: skip


def motor_data(rig: str) -> Any:
    """The rig file's nominal electrical motor data as `synthesis.models.motor.MotorData`."""

    m = load_rig(rig).motor
    return MotorData(**{k: getattr(m, k) for k in MOTOR_KEYS})


def flux_observer(omega_r_max: float, rate_hz: float, out: Path, *, rig: str = "mock", backoff: float = 1.1,
                  discretisation: str = "full", progress: Progress | None = None) -> dict[str, Any]:  # fmt: skip
    """The LPV flux observer of thesis 5.6.2 for |ω_r| ≤ omega_r_max at rate_hz, for the nominal motor
    of ``rig``; returns the summary. ``discretisation``: "full" (the whole plant through D_bl, default)
    or "thesis" (5.6.1 as printed: only (5.79) through D_bl)."""


    t0 = time.perf_counter()
    try:
        d = design_flux_observer(omega_r_max, Ts=1.0 / rate_hz, backoff=backoff, motor=motor_data(rig),
                                 progress=progress, variant=VARIANTS[discretisation])  # fmt: skip
    except (ConstructionError, VerificationError) as e:
        raise DesignFailed(f"flux observer for |omega_r| <= {omega_r_max:g} rad/s at {rate_hz:g} Hz: {e}") from None
    info = summary(d)
    info["discretisation"] = discretisation
    meta = {"design": "flux_observer", "thesis": "5.6.2", "motor": asdict(d.motor), "rig": rig, "rate_hz": rate_hz,
            "scheduling": "Delta = omega_r / omega_r_max", "inputs": ["i_s_ab", "u_s_ab"], "outputs": ["i_m_ab"],
            "solver": _solver_settings(), **info}  # fmt: skip
    npz, js = save_controller(out, d.controller, meta)
    info.update(npz=str(npz), json=str(js), wall_time=time.perf_counter() - t0)
    return info


def current_controller(rate_hz: float, out: Path, *, discretisation: str = "causal", rig: str = "mock",
                       backoff: float = 1.1, input_delay: float = 0.0, prewarp: float | None = None,
                       rescale: str = "diagonal", centring: str = "scaled", objective: str = "trace",
                       progress: Progress | None = None) -> dict[str, Any]:  # fmt: skip
    """The quasi-LPV stator current controller of thesis 6.2.2 at rate_hz; returns the summary.

    ``discretisation``: "causal" (y and z_p from the sampled state, the runtime's default) or "full"
    (D_bl ⋆ M of the whole plant, which puts u_k into y_k; see synthesis.models.current_controller).
    ``input_delay``, ``prewarp``: the hold-aware design models of issue 12 (`CurrentSpec`; off = the thesis').
    ``rescale``: the γ bisection's re-balancing, "diagonal" (the shipped artifacts) or "full" (from the lower
    bound: the LMIs' optimum, issue 12; see `design_current_controller`); ``centring``: "scaled" (the shipped
    artifacts) or "balanced" (a design continuous in its model; `design_current_controller`); ``objective``: what
    the centring minimises, "trace" (the shipped artifacts) or "dual".
    """
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        # optimal_inaccurate solves are re-checked in numpy (synthesis.lmi); count them, don't print them
        warnings.simplefilter("always", UserWarning)
        try:
            spec = CurrentSpec(rate_hz=rate_hz, discretisation=discretisation, motor=motor_data(rig),
                               input_delay=input_delay, prewarp=prewarp)  # fmt: skip
        except ValueError as e:
            raise BadInput("--input-delay/--prewarp", str(e)) from None
        if rescale not in ("full", "diagonal"):
            raise BadInput("--rescale", f"allowed: full, diagonal; got {rescale!r}")
        if centring not in ("scaled", "balanced"):
            raise BadInput("--centring", f"allowed: scaled, balanced; got {centring!r}")
        if objective not in ("trace", "dual"):
            raise BadInput("--objective", f"allowed: trace, dual; got {objective!r}")
        try:
            d = design_current_controller(spec, backoff=backoff, progress=progress, rescale=rescale, centring=centring,
                                          objective=objective)  # fmt: skip
        except (ConstructionError, VerificationError) as e:
            raise DesignFailed(f"current controller at {rate_hz:g} Hz: {e}") from None
    info = current_summary(d)
    info["solver_warnings"] = len(caught)
    meta = {"design": "current_controller", "thesis": "6.2.2", "rig": rig, "rate_hz": rate_hz,
            "scheduling": "Delta = diag(omega_cc / delta1_max, (i_sq / i_mR_hat) / delta2_max)",
            "inputs": ["i_s_cc - i_s_cc_ref"], "outputs": ["u_s_cc"], "solver": _solver_settings(),
            **info}  # fmt: skip
    npz, js = save_controller(out, d.controller, meta)
    info.update(npz=str(npz), json=str(js), wall_time=time.perf_counter() - t0)
    return _jsonable(info)  # the full re-balancing's similarity T is complex (lmi_settings)


def _model(path: Path) -> Any:
    try:
        return load_model(path)
    except (ArtifactError, OSError, KeyError, ValueError) as e:
        raise BadInput("--model", f"a NARX model artifact of `bench train narx` (npz + JSON) is needed: {e}") from None


def log_filter_hz(model: Any) -> float:
    """The first-order filter the model's data went through (the excitation's ``log_filter_hz``, 6.4.2)."""
    exp = model.meta.get("provenance", {}).get("train", {}).get("experiment", {})
    return float(exp.get("controller", {}).get("log_filter_hz", ExcitationController.defaults["log_filter_hz"]))


def speed_controller(model_path: Path, out: Path, *, rig: str = "mock", n_gains: int = 2, filter_reading: str = "dc",
                     robust: bool = False, e_bar: str = "model", noise_rad_s: float = 0.5,
                     progress: Progress | None = None) -> dict[str, Any]:  # fmt: skip
    """The LPV speed controller of thesis 6.4.3 for the NARX model at ``model_path`` (Fig. 6.13 set-up, gamma
    bisection, construction, verification), or with ``robust`` the robust one of 7.2 for the scheduling-error
    bound ``e_bar``: "model" (`synthesis.mlp_lft.gain_uncertainty` of the kept gains for ``noise_rad_s``),
    "thesis" (3.1 %, 2.5 %) or comma-separated fractions. Writes OUT.npz/.json; returns the summary."""
    import hashlib

    import numpy as np


    say = progress or (lambda s: None)
    if not 0 <= n_gains <= 16:
        raise BadInput("--gains", f"must be an integer in [0, 16], got {n_gains}")
    if filter_reading not in ("dc", "pole"):
        raise BadInput("--filter", f"allowed: dc, pole; got {filter_reading!r}")
    model = _model(model_path)
    t0 = time.perf_counter()
    try:
        lft = lft_from_model(model)
    except ValueError as e:
        raise BadInput("--model", str(e)) from None
    if n_gains > lft.widths.size:
        raise BadInput("--gains", f"the model has {lft.widths.size} residual gains, got {n_gains}")
    spec = SpeedSpec(filter_reading=filter_reading, noise_rad_s=noise_rad_s, n_gains=n_gains, motor=motor_data(rig))
    eb_given = None
    if robust and e_bar != "model":
        if e_bar == "thesis":
            eb_given = np.asarray(THESIS["robust"]["e_bar"][:n_gains], float)
        else:
            try:
                eb_given = np.array([float(v) for v in e_bar.split(",")])
            except ValueError:
                raise BadInput("--e-bar", f"model, thesis or comma-separated fractions; got {e_bar!r}") from None
        if eb_given.size != n_gains or np.any(eb_given < 0) or np.any(eb_given >= 1):
            raise BadInput("--e-bar", f"{n_gains} fractions in [0, 1) are needed, got {eb_given.tolist()}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        try:
            d = design_speed_controller(lft, spec, progress=say)
        except (ConstructionError, VerificationError) as e:
            raise BadInput("--model", f"no verified speed controller for this model ({e}): its sector bounds allow "
                           "none; train another candidate (bench train narx --init-spread 0.3 or 0.1) or let "
                           "`bench pipeline narx-speed` train several and pick one") from None  # fmt: skip
        info: dict[str, Any] = {"nominal": d.summary()}
        ctrl, gamma = d.controller, d.gamma
        if robust:
            eb = gain_uncertainty(d.lft, noise_rad_s) if e_bar == "model" else eb_given
            try:
                r = design_robust_speed_controller(d.plant, eb, progress=say)
            except (ConstructionError, VerificationError) as e:
                raise BadInput("--e-bar", f"no verified robust controller for e_bar = {eb.tolist()}: {e}") from None
            info["robust_design"] = r.summary()
            if r.controller is None:
                raise BadInput("--e-bar", f"no robust design for e_bar = {eb.tolist()}: {r.design.reason}")
            ctrl, gamma = r.controller, r.gamma
    info["solver_warnings"] = len(caught)
    npz_model = Path(str(model_path.with_suffix("") if model_path.suffix in (".json", ".npz") else model_path) + ".npz")
    meta = {"design": "speed_controller", "thesis": "7.2" if robust else "6.4.3", "robust": robust, "rig": rig,
            "motor": spec.motor.as_dict(), "rate_hz": 1.0 / model.dt, "gamma": gamma,
            "model": {"path": str(model_path), "sha256": hashlib.sha256(npz_model.read_bytes()).hexdigest(),
                      "provenance": model.meta.get("provenance", {})},
            "runtime": runtime_data(d.lft, spec, log_filter_hz(model)),
            "scheduling": "Delta = diag((sigma'_j(xi_j)/xi_j - c_j)/h_j), xi = C_u x + E_u u (6.28)",
            "inputs": ["w~ - w~_ref (scaled speed error)"], "outputs": ["i_sd_ref~", "i_tau~"],
            "solver": _solver_settings(), **info}  # fmt: skip
    meta["sampled_data"] = sampled_report(ctrl, d.lft, spec, gamma)  # issue 12: the model is the sampled model
    npz, js = save_controller(out, ctrl, meta)
    info.update(npz=str(npz), json=str(js), wall_time=time.perf_counter() - t0, gamma=gamma, robust=robust)
    info["integral_action"] = False
    info["note"] = STEADY_OFFSET_NOTE.format(out=out)
    return info


# what a user of a synthesised speed controller meets first (bench synth speed-controller prints it; the
# numbers: docs/results/speed-controllers.md and the README's chain, measured on the demo scenario)
STEADY_OFFSET_NOTE = ("no integral action (the Fig. 6.13 set-up weights the speed error through a low-pass of finite "
                      "DC gain): the speed keeps a steady offset under load, about 2.4 rad/s at 4 N m with the shipped "
                      "design and about 10 rad/s with the README's identification chain; measure yours with `bench run "
                      "-p speed_controller=lpv -p lpv_speed_artifact={out}` (the demo scenario's 4 N m at +-100 rad/s)")
