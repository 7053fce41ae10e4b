"""Peers of the batch engine, per simulated step: gym-electric-motor's squirrel-cage induction motor environment and
motulator's induction-machine drive, each in a fresh process (`bench perf batch` puts them beside its rows).

Neither is a dependency of imbench (the optional extra ``peers`` installs both). Each is timed on what it is made for,
on the thesis' machine where the peer takes parameters (3.57):

- gym-electric-motor ``Cont-SC-SCIM-v0`` (continuous speed control; its default step tau = 1e-4 s, scipy's ODE
  solver): ``env.step`` with a constant action, resets included when an episode ends. A step is one motor step.
- motulator: `motulator.drive.model.Drive` (the Gamma-model induction machine, a stiff mechanical system, a voltage
  source converter, zero-order hold) under its own `CurrentVectorControl` (encoder speed, T_s = 1/3000 s as the
  bench's loop) through `Simulation.simulate` (scipy's ``solve_ivp`` per sample): speed 10 rad/s from 0.1 s, 3 N m
  of load from 0.3 s. A step is one control sample.

``python -m bench.perf.peers NAME [STEPS]`` prints one JSON line: ``us_per_step`` (median of 3 repeats),
``steps_per_s``; or ``skipped`` with the reason (the package does not import).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import warnings
from typing import Any

PEERS = ("gym-electric-motor", "motulator")
# the thesis' machine (3.57), as the yardstick's
R_S, R_R, L_S, L_R, L_M, Z_P, J = 5.0, 3.3, 0.352, 0.352, 0.341, 2, 0.0125


def _gem(steps: int) -> dict[str, Any]:
    import gym_electric_motor as gem
    import numpy as np

    env = gem.make("Cont-SC-SCIM-v0")
    env.reset(seed=0)
    action = np.full(env.action_space.shape, 0.1)
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(steps):
            _obs, _r, term, trunc, _info = env.step(action)
            if term or trunc:
                env.reset()
        runs.append((time.perf_counter() - t0) / steps)
    ps = env.unwrapped.physical_system
    return {"what": "gym-electric-motor Cont-SC-SCIM-v0, env.step with a constant action", "version": gem.__version__
            if hasattr(gem, "__version__") else _version("gym-electric-motor"), "step_s": float(ps.tau),
            "solver": type(ps._ode_solver).__name__, "runs_us": [r * 1e6 for r in runs]}  # fmt: skip


def _motulator(steps: int) -> dict[str, Any]:
    import motulator.drive.control.im as control
    from motulator.drive import model
    from motulator.drive.utils import InductionMachineInvGammaPars, InductionMachinePars

    T_s = 1.0 / 3000.0
    # the thesis' T-model parameters in motulator's inverse-Gamma form
    par = InductionMachineInvGammaPars(n_p=Z_P, R_s=R_S, R_R=R_R * (L_M / L_R) ** 2, L_sgm=L_S - L_M**2 / L_R,
                                       L_M=L_M**2 / L_R)  # fmt: skip
    runs = []
    for _ in range(3):
        mdl = model.Drive(model.VoltageSourceConverter(u_dc=540.0),
                          model.InductionMachine(InductionMachinePars.from_inv_gamma_model_pars(par)),
                          model.StiffMechanicalSystem(J=J))  # fmt: skip
        ctrl = control.CurrentVectorControl(par, control.CurrentReferenceCfg(par, max_i_s=8.0), J=J, T_s=T_s,
                                            sensorless=False)  # fmt: skip
        ctrl.ref.w_m = lambda t: 10.0 * (t > 0.1)  # electrical rotor speed [rad/s]
        mdl.mechanics.tau_L = lambda t: 3.0 * (t > 0.3)
        t0 = time.perf_counter()
        model.Simulation(mdl, ctrl).simulate(t_stop=steps * T_s)
        runs.append((time.perf_counter() - t0) / steps)
    return {"what": "motulator InductionMachine + CurrentVectorControl, Simulation.simulate (solve_ivp per sample)",
            "version": _version("motulator"), "step_s": T_s, "solver": "scipy.integrate.solve_ivp (RK45)",
            "runs_us": [r * 1e6 for r in runs]}  # fmt: skip


def _version(dist: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(dist)
    except PackageNotFoundError:
        return None


def measure(name: str, steps: int = 1500) -> dict[str, Any]:
    """One peer's per-step cost in this process, or ``skipped`` with why."""
    fn = {"gym-electric-motor": _gem, "motulator": _motulator}[name]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = fn(steps)
    except ImportError as exc:
        return {"peer": name, "skipped": f"not installed ({exc.name or exc}): pip install 'imbench[peers]'"}
    us = sorted(out["runs_us"])[1]
    return {"peer": name, **out, "steps": steps, "us_per_step": us, "steps_per_s": 1e6 / us}


def run(name: str, steps: int = 1500, python: str | None = None) -> dict[str, Any]:
    """`measure` in a fresh process (``python``: another interpreter, e.g. a venv of its own for the peers)."""
    p = subprocess.run([python or sys.executable, "-m", "bench.perf.peers", name, str(steps)], capture_output=True,
                       text=True)  # fmt: skip
    if p.returncode != 0 or not p.stdout.strip():
        return {"peer": name, "skipped": f"failed: {(p.stderr.strip().splitlines() or ['?'])[-1]}"}
    return json.loads(p.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    print(json.dumps(measure(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 1500)))
