"""DC-load torque command (thesis App. A.6): over CAN (default) or a Modbus analog-output module.

Default: CAN, frame ``LOAD_TORQUE`` (bench/wire/imbench.dbc): M_REF [N m, 1 mN m/bit, signed
16 bit] and a 4-bit rolling counter, sent every tick in `set_torque`. Chosen over a Modbus AO
module because it shares the bus, the SYNC and the timing of the inverter set-points (a few
microseconds per tick, and a 3 kHz rate fits the CAN budget), while a Modbus transaction per tick
would limit the loop to a few hundred Hz on RTU (bench.core.config.budget). The DC drive applies the
torque reference it holds at each SYNC.

Alternative (``[ports] load = "load_modbus"``): one holding register of an analog-output module
(``modbus.load_register``), 0x4000 = ``load.torque_limit``, written with FC06 every tick.

Both clip the command to +-``load.torque_limit``. A failed send is counted (``send_errors``); the
DC drive's own command timeout is what makes the load safe if the link dies.
"""

from __future__ import annotations

from bench.drivers.canbus import CanLink
from bench.drivers.modbus import ModbusFailure, ModbusLink
from bench.wire.fc_profile import to_percent_word


class CanLoad:
    """`LoadPort` over CAN (also a `Device`, with nothing to do per tick)."""

    def __init__(self, link: CanLink, torque_limit: float) -> None:
        self.link = link
        self.torque_limit = torque_limit
        self.msg = link.message("LOAD_TORQUE")
        self._counter = 0
        self.m_L_ref = 0.0

    def set_torque(self, m_L_ref: float) -> None:
        lim = self.torque_limit
        m = lim if m_L_ref > lim else (-lim if m_L_ref < -lim else m_L_ref)
        self.m_L_ref = m
        self.link.send(self.msg.frame_id, self.msg.encode({"M_REF": m, "COUNTER": self._counter}, strict=False))
        self._counter = (self._counter + 1) & 0xF
        self.link.end_of_tick()  # the Rig writes the load last

    def configure(self) -> None: ...
    def activate(self) -> None: ...
    def deactivate(self) -> None: ...
    def acquire(self, t: float) -> None: ...


class ModbusLoad:
    """`LoadPort` on a Modbus analog-output module (also a `Device`)."""

    def __init__(self, modbus: ModbusLink, register: int, torque_limit: float, link: CanLink | None = None) -> None:
        self.modbus = modbus
        self.link = link
        self.register = register
        self.torque_limit = torque_limit
        self.m_L_ref = 0.0
        self.send_errors = 0

    def set_torque(self, m_L_ref: float) -> None:
        lim = self.torque_limit
        m = lim if m_L_ref > lim else (-lim if m_L_ref < -lim else m_L_ref)
        self.m_L_ref = m
        try:
            self.modbus.write(self.register, [to_percent_word(m, lim)])
        except ModbusFailure:
            self.send_errors += 1
        if self.link is not None:
            self.link.end_of_tick()

    def configure(self) -> None:
        if self.modbus.client is None:
            self.modbus.connect()

    def activate(self) -> None: ...
    def deactivate(self) -> None: ...
    def acquire(self, t: float) -> None: ...
