"""VLT5003-style inverter: set-points over CAN every tick, parameters and status over Modbus.

CAN (bench/wire/imbench.dbc, encoded with cantools):

* ``VLT_SETPOINT`` (host -> drive, every tick): u_alpha, u_beta [V, 0.02 V/bit], ENABLE, a 4-bit
  rolling COUNTER (+1 per frame), OMEGA_U [rad/s, 1 rad/s/bit]: the field's electrical frequency.
  The drive applies the last set-point it holds at the next SYNC (one-sample delay, as the thesis'
  VLT); for a SYNC without a new set-point it turns the last one by OMEGA_U T_s (stall ride-through,
  bench.hal.InverterPort) for up to the rig's ``limits.ride_through``, and coasts with a latched
  SETPOINT_TIMEOUT trip if no set-point came for its timeout; a counter that does not advance by one
  sets COUNTER_ERROR.
* ``VLT_STATUS`` (drive -> host, every ``status_divider`` SYNCs): DC link [0.1 V], ENABLED, TRIP,
  SETPOINT_TIMEOUT, COUNTER_ERROR, HEARTBEAT = the SYNC tick it answers, FAULT = which fault the
  drive latched (the DBC's value table: set-point watchdog, control-word timeout, over-current,
  ...); the supervisor's trip cause names it.

Modbus (Danfoss FC profile, bench.drivers.modbus): at ``configure`` the driver connects, reads the
status word and the DC link (refusing a drive that reports a trip); ``activate`` pulses a fault
reset and writes RUN (0x047C) - the drive then accepts bus set-points, and ENABLE gates its bridge;
``deactivate`` sends a disabled set-point, then STOP (0x043C). `reset_fault` clears a latched
drive trip. With ``[inverter] setpoints = "modbus"`` the set-points go to the reference registers
instead (slow: see the transport budget in bench.core.config).

Per tick: `set_voltage`/`disable` send a frame at once (``enable`` only arms the flag, the
following ``set_voltage`` carries it); right before each SYNC a keep-alive set-point goes out if
the tick sent none (the `Rig` does not call a disabled inverter every tick), so the drive sees one
set-point per tick either way. The reference amplitude is clipped to ``limits.U_max``.

`status` drains the status frames. When a status frame is due for this tick and has not arrived,
it waits up to ``can.status_wait``; if none came for ``can.heartbeat_timeout`` it sets ST_INV_STALE
(and the supervisor trips: "inverter heartbeat lost"). Until the first status frame the DC link
read over Modbus at configure stands in.
"""

from __future__ import annotations

import time
from typing import Any

import can
import cantools

from bench.drivers.canbus import CanLink
from bench.drivers.modbus import ModbusFailure, ModbusLink
from bench.hal import ST_INV_COMM, ST_INV_STALE, InverterStatus
from bench.wire.canbus import fault_names
from bench.wire.fc_profile import CTW_RESET, CTW_RUN, CTW_STOP, STW_TRIP, to_percent_word


OMEGA_U_MAX = 1023.0  # [rad/s] the range of VLT_SETPOINT.OMEGA_U (11 bits, 1 rad/s: 0.01 rad in a 20 ms stall)


class VltInverter:
    """Driver of the inverter (`InverterPort` and `Device`)."""

    def __init__(self, link: CanLink, modbus: ModbusLink | None, can_cfg: dict[str, Any], mb_cfg: dict[str, Any],
                 setpoints: str, U_max: float, u_dc_nominal: float, T_s: float) -> None:  # fmt: skip
        self.link = link
        self.modbus = modbus
        self.mb = mb_cfg
        self.setpoints = setpoints
        self.U_max = U_max
        self.u_dc_nominal = u_dc_nominal
        self.T_s = T_s
        self.msg_sp = link.message("VLT_SETPOINT")
        self.msg_st = link.message("VLT_STATUS")
        self.divider = can_cfg["status_divider"]
        self._fault_names = fault_names(self.msg_st)
        self.hb_ticks = max(1, int(round(can_cfg["heartbeat_timeout"] / T_s)))
        self.status_wait = can_cfg["status_wait"]
        self._ref = 0j
        self._omega = 0.0
        self._on = False
        self._counter = 0
        self._sent = False
        self._mb_on = False
        self.tick = 0
        self._status = InverterStatus(False, False, 0.0)
        self._status_tick: int | None = None  # tick of the last status frame
        self.status_bits = 0
        self.stats = {"setpoints": 0, "status_frames": 0, "status_waits": 0}

    # --- Device ---------------------------------------------------------------------------------
    def configure(self) -> None:
        self.link.subscribe(self.msg_st.frame_id, self._on_status)
        if self._before_sync not in self.link._pre_sync:
            self.link.add_pre_sync(self._before_sync)
        if self.modbus is not None:
            self.modbus.connect()
            stw = self.modbus.read(self.mb["status_word"])[0]
            u_dc = self.modbus.read(self.mb["dc_link"])[0] * 0.1
            self._status = InverterStatus(False, bool(stw & STW_TRIP), u_dc)

    def activate(self) -> None:
        self._status_tick = None
        self._counter = 0
        if self.modbus is not None:
            try:
                self.modbus.write(self.mb["control_word"], [CTW_STOP | CTW_RESET])
                self.modbus.write(self.mb["control_word"], [CTW_RUN])
            except ModbusFailure:
                self.status_bits |= ST_INV_COMM

    def deactivate(self) -> None:
        self._on = False
        self._ref = 0j
        self._send()
        if self.modbus is not None:
            try:
                self.modbus.write(self.mb["control_word"], [CTW_STOP])
            except ModbusFailure:
                pass

    def close(self) -> None:
        if self.modbus is not None:
            self.modbus.close()

    def acquire(self, t: float) -> None:
        self.tick = int(round(t / self.T_s))

    def _before_sync(self) -> None:
        if not self._sent:
            self._send()  # keep-alive: one set-point per tick, before the SYNC that applies it
        self._sent = False

    def reset_fault(self) -> None:
        """Clear a latched drive trip (FC-profile reset bit, rising edge)."""
        if self.modbus is None:
            raise ModbusFailure("no Modbus channel configured")
        self.modbus.write(self.mb["control_word"], [CTW_STOP])
        self.modbus.write(self.mb["control_word"], [CTW_STOP | CTW_RESET])
        self.modbus.write(self.mb["control_word"], [CTW_RUN])

    # --- InverterPort -------------------------------------------------------------------------
    def _send(self) -> None:
        ref = self._ref if self._on else 0j
        if self.setpoints == "modbus" and self.modbus is not None:
            try:
                self.modbus.write(self.mb["reference"], [to_percent_word(ref.real, self.U_max),
                                                          to_percent_word(ref.imag, self.U_max)])  # fmt: skip
                if self._on != self._mb_on:  # the control word only on a change of enable
                    self.modbus.write(self.mb["control_word"], [CTW_RUN if self._on else CTW_STOP])
                    self._mb_on = self._on
            except ModbusFailure:
                self.status_bits |= ST_INV_COMM
        else:
            data = self.msg_sp.encode({"U_ALPHA": ref.real, "U_BETA": ref.imag, "ENABLE": int(self._on),
                                       "COUNTER": self._counter, "OMEGA_U": self._omega if self._on else 0.0},
                                      strict=False)  # fmt: skip
            self.link.send(self.msg_sp.frame_id, data)
            self._counter = (self._counter + 1) & 0xF
        self.stats["setpoints"] += 1
        self._sent = True

    def set_voltage(self, u_s_ref: complex, omega_u: float = 0.0) -> None:
        mag = abs(u_s_ref)
        if mag > self.U_max:
            u_s_ref *= self.U_max / mag
        self._ref = u_s_ref
        self._omega = round(omega_u) if abs(omega_u) <= OMEGA_U_MAX else 0.0  # beyond the frame's range: hold
        self._send()

    def enable(self) -> None:
        self._on = True

    def disable(self) -> None:
        self._on = False
        self._send()

    def _on_status(self, msg: can.Message) -> None:
        try:
            s = self.msg_st.decode(msg.data, decode_choices=False)
        except (ValueError, KeyError, IndexError, cantools.database.DecodeError):
            self.stats["bad_frames"] = self.stats.get("bad_frames", 0) + 1
            return  # a malformed frame is ignored (and the heartbeat ages)
        fault = bool(s["TRIP"] or s["SETPOINT_TIMEOUT"])  # COUNTER_ERROR is a warning (counted)
        if s["COUNTER_ERROR"]:
            self.stats["counter_errors"] = self.stats.get("counter_errors", 0) + 1
        name = ""
        if fault:  # which fault (VLT_STATUS.FAULT); a drive without the code still says "set-point watchdog"
            code = int(s.get("FAULT", 0))
            name = self._fault_names.get(code, f"fault code {code}") if code else (
                "set-point watchdog" if s["SETPOINT_TIMEOUT"] else "")  # fmt: skip
        self._status = InverterStatus(bool(s["ENABLED"]), fault, float(s["U_DC"]), name)
        hb = int(s["HEARTBEAT"])
        self._status_tick = self.tick - ((self.tick - hb) & 0xFF)
        self.stats["status_frames"] += 1

    def status(self) -> InverterStatus:
        link = self.link
        link.poll()
        tick = self.tick
        due = tick - tick % self.divider
        if self._status_tick is None or self._status_tick < due:
            self.stats["status_waits"] += 1
            deadline = time.perf_counter() + self.status_wait
            while (self._status_tick is None or self._status_tick < due) and (
                    left := deadline - time.perf_counter()) > 0:  # fmt: skip
                link.wait(left)
        bits = self.status_bits & ~ST_INV_STALE
        last = self._status_tick
        if (last is None and tick >= self.hb_ticks) or (last is not None and tick - last > self.hb_ticks):
            bits |= ST_INV_STALE
        self.status_bits = bits
        return self._status
