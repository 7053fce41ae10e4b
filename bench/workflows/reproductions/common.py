"""Shared helpers of the observer reproductions: lockstep closed-loop runs kept in memory, and
estimation-error statistics against the mock rig's ground truth.

`simulate` runs the standard `TimedLoop` (lockstep) on a fresh mock rig, optionally with a true
machine that differs from the controller's nominal model (parameter mismatch), and returns every
logged field as a numpy array keyed ``"<topic>/<field>"`` (``"/truth/omega_r"``, ``"/ctrl/omega_est"``).
Nothing is written to disk.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from bench.core.config import load as load_rig
from bench.controllers.base import Controller, ControllerContext
from bench.daq import Topic
from bench.daq.memory import MemoryLog
from bench.runtime.loop import TimedLoop, log_topics
from bench.params import MotorParams
from bench.core.plotstyle import pyplot  # noqa: F401 (the reproductions take it from here)
from bench.core.scenarios import T_MAGNETISE, Scenario
from bench.runtime.compose import make_controller, mock_rig
from bench.core.supervisor import Supervisor
from bench.runtime.metrics import estimation_errors
from bench.operate.operator import Operator
from bench.operate.requests import ParamSpace, scheduled


@dataclass
class SimResult:
    data: dict[str, np.ndarray]
    trip_cause: str | None
    trip_t: float | None
    wall_time: float

    def __getitem__(self, key: str) -> np.ndarray:
        return self.data[key]


def simulate(scn: Scenario, params: dict[str, Any] | None = None, *, params_true: MotorParams | None = None,
             duration: float | None = None, seed: int = 0, rig: str = "mock",
             make: Callable[[ControllerContext], Controller] | None = None,
             mock: dict[str, dict[str, Any]] | None = None) -> SimResult:  # fmt: skip
    """One lockstep run of controller ``foc`` with ``params`` through ``scn``, kept in memory.

    ``params_true`` replaces the mock plant's true machine (the controller keeps the rig file's
    nominal model). ``make`` builds another controller from the context instead of ``foc``.
    ``mock`` changes tables of the rig file's ``[mock]`` settings, e.g. a voltage-sensor offset
    ``{"voltages": {"offset": [0.025, 0.0, 0.0]}}`` or a held shaft ``{"motor": {"hold_speed": True}}``.
    """
    cfg = load_rig(rig)
    r = mock_rig(cfg, seed, mock=mock, params_true=params_true)
    if make is None:
        ctrl = make_controller(cfg, r, "foc", params or {})
    else:
        ctrl = make(ControllerContext(T_s=cfg.T_s, motor=cfg.motor, I_max=cfg.limits.I_max,
                                      counts_per_rev=r.encoder.counts_per_rev, enc_modulus=r.encoder.modulus,
                                      omega_max=cfg.limits.omega_max))  # fmt: skip
    sup = Supervisor(cfg.limits, r.encoder.counts_per_rev, r.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
    record = MemoryLog([Topic(*t) for t in log_topics(r, ctrl)])
    operator = None
    if scn.switches:  # the scenario's scheduled part switches (bench.operate.operator), as bench run applies them

        space = ParamSpace.of(ctrl, cfg.limits, r.load.torque_limit)
        ctrl.prepare_switching()
        operator = Operator(ctrl, space, scheduled(scn.switches, space, cfg.T_s), record.event, sup.request_trip,
                            busy=lambda: sup.cause)  # fmt: skip
    r.configure()
    r.activate()
    try:
        res = TimedLoop(r, ctrl, scn, sup, T_s=cfg.T_s, duration=scn.duration if duration is None else duration,
                        log=record, operator=operator).run()  # fmt: skip
    finally:
        r.deactivate()
    return SimResult(record.columns(), res.trip_cause, res.trip_t, res.wall_time)


def save_figure(fig, out_dir: Path, name: str, title: str) -> None:  # noqa: ANN001
    """Title, tight layout, ``out_dir/name.png`` at 110 dpi, close."""
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out_dir / f"{name}.png", dpi=110)
    pyplot().close(fig)


def wrap(a: np.ndarray) -> np.ndarray:
    """Angles to (-pi, pi]."""
    return np.angle(np.exp(1j * a))


def errors(res: SimResult, t_from: float = T_MAGNETISE + 0.1) -> dict[str, float]:
    """Estimation errors against ground truth, over loop times >= t_from (and before any trip).

    Flux magnitude error: |i_m_hat| - |i_m| in A and relative to the mean true |i_m|; flux angle
    error: angle(i_m_hat) - angle(i_m) in degrees; speed error: omega_est - omega_r (the estimator's
    output if one runs, else the controller's speed feedback) in rad/s.
    """
    d = res.data
    ctrl = {k.removeprefix("/ctrl/"): v for k, v in d.items() if k.startswith("/ctrl/")}
    truth = {k.removeprefix("/truth/"): v for k, v in d.items() if k.startswith("/truth/")}
    out = estimation_errors(d["/rig/t"], ctrl, truth, d["/rig/omega_r_ref"], t_from, res.trip_t)
    out["tripped"] = res.trip_cause is not None
    return out
