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

Progress = Callable[[str], None]


def _solver_settings() -> dict[str, Any]:
    from synthesis.lmi import DEFAULT_SOLVER_OPTS

    import clarabel
    import cvxpy

    return {"solver": "CLARABEL", "options": dict(DEFAULT_SOLVER_OPTS), "cvxpy": cvxpy.__version__,
            "clarabel": clarabel.__version__}  # fmt: skip


def motor_data(rig: str) -> Any:
    """The rig file's nominal electrical motor data as `synthesis.models.motor.MotorData`."""
    from bench.config import load as load_rig
    from synthesis.artifacts import MOTOR_KEYS
    from synthesis.models.motor import MotorData

    m = load_rig(rig).motor
    return MotorData(**{k: getattr(m, k) for k in MOTOR_KEYS})


def flux_observer(omega_r_max: float, rate_hz: float, out: Path, *, rig: str = "mock", backoff: float = 1.1,
                  progress: Progress | None = None) -> dict[str, Any]:  # fmt: skip
    """The LPV flux observer of thesis 5.6.2 for |ω_r| ≤ omega_r_max at rate_hz, for the nominal motor
    of ``rig``; returns the summary."""
    from synthesis.artifacts import save_controller
    from synthesis.models.flux_observer import design_flux_observer, summary

    t0 = time.perf_counter()
    d = design_flux_observer(omega_r_max, Ts=1.0 / rate_hz, backoff=backoff, motor=motor_data(rig), progress=progress)
    info = summary(d)
    meta = {"design": "flux_observer", "thesis": "5.6.2", "motor": asdict(d.motor), "rig": rig, "rate_hz": rate_hz,
            "scheduling": "Delta = omega_r / omega_r_max", "inputs": ["i_s_ab", "u_s_ab"], "outputs": ["i_m_ab"],
            "solver": _solver_settings(), **info}  # fmt: skip
    npz, js = save_controller(out, d.controller, meta)
    info.update(npz=str(npz), json=str(js), wall_time=time.perf_counter() - t0)
    return info


def current_controller(rate_hz: float, out: Path, *, discretisation: str = "causal", rig: str = "mock",
                       backoff: float = 1.1, progress: Progress | None = None) -> dict[str, Any]:  # fmt: skip
    """The quasi-LPV stator current controller of thesis 6.2.2 at rate_hz; returns the summary.

    ``discretisation``: "causal" (y and z_p from the sampled state, the runtime's default) or "full"
    (D_bl ⋆ M of the whole plant, which puts u_k into y_k; see synthesis.models.current_controller).
    """
    from synthesis.artifacts import save_controller
    from synthesis.models.current_controller import CurrentSpec, design_current_controller, summary

    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        # optimal_inaccurate solves are re-checked in numpy (synthesis.lmi); count them, don't print them
        warnings.simplefilter("always", UserWarning)
        spec = CurrentSpec(rate_hz=rate_hz, discretisation=discretisation, motor=motor_data(rig))
        d = design_current_controller(spec, backoff=backoff, progress=progress)
    info = summary(d)
    info["solver_warnings"] = len(caught)
    meta = {"design": "current_controller", "thesis": "6.2.2", "rig": rig, "rate_hz": rate_hz,
            "scheduling": "Delta = diag(omega_cc / delta1_max, (i_sq / i_mR_hat) / delta2_max)",
            "inputs": ["i_s_cc - i_s_cc_ref"], "outputs": ["u_s_cc"], "solver": _solver_settings(),
            **info}  # fmt: skip
    npz, js = save_controller(out, d.controller, meta)
    info.update(npz=str(npz), json=str(js), wall_time=time.perf_counter() - t0)
    return info
