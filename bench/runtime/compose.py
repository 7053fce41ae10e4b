"""The composition root: builds a rig (the mock plant, the drivers on their devices, or the drivers on emulators
started here) and the controller for it. Every run takes its rig and controller from here: sessions
(`bench.runtime.session`), the batch engine (`bench.batch.engine`), the reproductions' lockstep runs and the benchmarks.
The controllers themselves never import `mock_hw`; the mock plant, python-can, pyserial and pymodbus are loaded only for
a rig that needs them.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Any

from bench import controllers

from bench.core import nameplate
from bench.core.config import RIGS_DIR, RigConfig
from bench.controllers.base import Controller, ControllerContext
from bench.drivers.riglock import RigLock
from bench.errors import BadInput
from bench.hal import Rig
from bench.params import MotorParams


def mock_rig(cfg: RigConfig, seed: int, *, mock: dict[str, Any] | None = None,
             params_true: MotorParams | None = None) -> Rig:  # fmt: skip
    """The mock plant of ``cfg``: its ``[mock]`` tables, each updated by ``mock``'s (a table merges, a value replaces:
    ``{"engine": "compiled"}``, ``{"motor": {"hold_speed": True}}``), the drive's ride-through and trips from its
    limits, and ``params_true`` in place of the true machine. The one place that builds a mock rig (sessions, the
    batch engine, the reproductions' lockstep runs); BadInput names a bad ``[mock]`` field."""
    from mock_hw.plant import MockConfig, drive_settings, make_mock_rig

    tables = dict(cfg.mock)
    for key, value in (mock or {}).items():
        tables[key] = {**tables.get(key, {}), **value} if isinstance(value, dict) else value
    try:
        mock_cfg = MockConfig.from_dict(tables)
    except ValueError as exc:
        msg = str(exc)
        field_name, _, problem = msg.partition(" ")
        raise BadInput(field_name if field_name.startswith("mock") else "mock", problem or msg) from None
    return make_mock_rig(mock_cfg, dt=cfg.T_s, seed=seed, params_true=params_true, **drive_settings(cfg.limits))


def build_rig(cfg: RigConfig, seed: int, realtime: bool = True) -> Rig:
    """The rig of ``cfg``: the mock plant, or the drivers (on their devices, a `bench emulate`, or emulators started
    here). ``realtime``: the run's clock, told to a `bench emulate` (its control-word watchdog follows it)."""
    if cfg.driver == "mock":
        return mock_rig(cfg, seed)
    if cfg.driver == "drivers":
        from bench.drivers.rig import build_driver_rig  # python-can, pyserial, pymodbus: only for a rig of devices
        from mock_hw.emulators import emulator_running

        # one session per rig: the devices' locks first, before anything is sent on any link (the probe
        # of `bench emulate` below writes a challenge); a held one is refused naming its holder
        lock = RigLock(cfg.hw, cfg.name)
        lock.acquire()
        try:
            mode = cfg.hw["emulator"]["autostart"]
            if mode == "never" or (mode == "auto" and emulator_running(cfg, realtime)):  # devices or `bench emulate`
                return build_driver_rig(cfg, lock=lock)
            # in-process emulators on the rig file's transports, the run's seed for the plant noise
            from mock_hw.emulators import start_emulator

            emu = start_emulator(cfg, seed=seed)
            rig = build_driver_rig(emu.host_config(), on_close=[emu.close], lock=lock)  # + the ports it bound
        except BaseException:
            lock.release()
            raise
        rig.truth = emu.truth_view(rig.drivers["frontend"])  # logged only, never seen by controllers
        rig.emulator = emu  # type: ignore[attr-defined]
        return rig
    raise BadInput("rig.driver", f"unsupported driver {cfg.driver!r}")


def motor_defaults(cfg: RigConfig, name: str, params: dict[str, Any]) -> dict[str, Any]:
    """``params`` with the speed-PI gains derived from ``cfg``'s motor (`bench.core.nameplate.Scaled.foc_params`) where
    the controller ``name`` has them and they are not given; on the thesis motor ``params`` as they are."""
    k = nameplate.scaled(cfg.motor, cfg.nameplate)
    cls = controllers.available().get(name)
    if k is None or cls is None:
        return params
    return {**{n: v for n, v in k.foc_params().items() if n in cls.schema}, **params}


def make_controller(cfg: RigConfig, rig: Rig, name: str, params: dict[str, Any]) -> Controller:
    params = motor_defaults(cfg, name, params)
    ctx = ControllerContext(T_s=cfg.T_s, motor=cfg.motor, I_max=cfg.limits.I_max,
                            counts_per_rev=rig.encoder.counts_per_rev, enc_modulus=rig.encoder.modulus,
                            omega_max=cfg.limits.omega_max, inverter_error=cfg.inverter_error)  # fmt: skip
    try:
        return controllers.create(name, ctx, params)
    except BadInput as exc:  # an artifact for other motor data says "make one with `bench synth ... --rig RIG`":
        if "--rig RIG" not in exc.problem:  # name this rig in that command
            raise

        packaged = cfg.path is not None and Path(cfg.path).resolve() == (RIGS_DIR / f"{cfg.name}.toml").resolve()
        rig = cfg.name if packaged or cfg.path is None else shlex.quote(str(cfg.path))
        raise BadInput(exc.field, exc.problem.replace("--rig RIG", f"--rig {rig}")) from None
