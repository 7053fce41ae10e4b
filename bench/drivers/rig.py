"""The rig of real devices: `DriverRig` and `build_driver_rig`, which wires the drivers of this package from a
rig file (``rig.driver = "drivers"``). It imports python-can, cantools, pyserial and pymodbus, so a mock session
never loads it (`bench.runtime.compose.build_rig` imports it for a rig of devices only)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from bench.core.config import RigConfig
from bench.drivers.canbus import CanLink
from bench.drivers.frontend import FrontEnd
from bench.drivers.load import CanLoad, ModbusLoad
from bench.drivers.modbus import ModbusLink
from bench.drivers.riglock import RigLock
from bench.drivers.vlt import VltInverter
from bench.hal import Rig, RigState


class DriverRig(Rig):
    """A `Rig` whose devices hold connections; `deactivate` also closes them.

    ``lock``: the devices' locks, taken (if not yet) before any device is configured, released on close.
    """

    def __init__(self, *, closers: list[Callable[[], None]], lock: RigLock, **kw: Any) -> None:
        super().__init__(**kw)
        self._closers = closers
        self.lock = lock
        self.drivers: dict[str, Any] = {}

    def configure(self) -> None:
        self.lock.acquire()  # BadInput naming the holder if another session has one of the devices
        super().configure()

    def deactivate(self) -> None:
        try:
            super().deactivate()
        finally:
            self.close()

    def close(self) -> None:
        for c in self._closers:
            try:
                c()
            except Exception:  # noqa: BLE001 - closing must go on for the others
                pass
        self.lock.release()  # after the devices (and an in-process emulator) are closed
        self.state = RigState.UNCONFIGURED

    def stats(self) -> dict[str, Any]:
        """Driver counters (frames, stale, lost, CRC, status frames, ...) for the run summary."""
        return {name: dict(getattr(d, "stats", {})) for name, d in self.drivers.items()}


def build_driver_rig(cfg: RigConfig, *, trace_modbus: Callable[[bool, bytes], bytes] | None = None,
                     on_close: list[Callable[[], None]] | None = None, truth: Any = None,
                     lock: RigLock | None = None) -> DriverRig:  # fmt: skip
    """The rig of a ``driver = "drivers"`` rig file: CAN link, VLT inverter, load, front-end.

    ``truth``: an in-process emulator's plant, logged as /truth (never seen by controllers). ``lock``: locks
    the caller already holds (`bench.runtime.compose.build_rig`); the devices of ``cfg`` are added to it.
    """
    hw = cfg.hw
    link = CanLink(hw["can"], cfg.T_s)
    modbus = ModbusLink(hw["modbus"], trace_packet=trace_modbus)
    inv = VltInverter(link, modbus, hw["can"], hw["modbus"], hw["inverter"]["setpoints"], cfg.limits.U_max,
                      u_dc_nominal=float(cfg.mock.get("inverter", {}).get("u_dc", 560.0)), T_s=cfg.T_s)  # fmt: skip
    if hw["ports"]["load"] == "load_can":
        load: Any = CanLoad(link, hw["load"]["torque_limit"])
    else:
        load = ModbusLoad(modbus, hw["modbus"]["load_register"], hw["load"]["torque_limit"], link)
    fe = FrontEnd(hw["serial"], hw["frontend"], cfg.T_s)
    # order matters per tick: SYNC (after the inverter's keep-alive set-point), then the sample
    devices = [inv, load, link, fe]
    closers = [fe.close, inv.close, link.close, *(on_close or [])]
    if lock is None:
        lock = RigLock(cfg.hw, cfg.name)
    lock.add(cfg.hw)
    rig = DriverRig(name=cfg.name, inverter=inv, currents=fe.currents, voltages=fe.voltages, encoder=fe.encoder,
                    load=load, devices=devices, closers=closers, truth=truth, lock=lock)  # fmt: skip
    rig.drivers = {"can": link, "inverter": inv, "load": load, "frontend": fe}
    return rig
