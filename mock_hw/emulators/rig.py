"""The emulated rig: the mock plant behind the real wire protocols (CAN, serial stream, Modbus TCP).

One `RigEmulator` plays every device of rigs/emulated.toml over the same bytes as the real rig:

* the VLT-style drive: CAN set-points in, status frames out (python-can + cantools, the same
  DBC as the driver), Danfoss FC-profile registers over Modbus TCP (pymodbus server, 127.0.0.1);
* the DC-load drive: CAN torque frames (or a Modbus analog-output register);
* the measurement front-end: 28-byte frames over a serial link (a ``socket://`` TCP server on
  127.0.0.1, or a pty pair).

Lockstep (docs/protocols.md): the emulator advances its plant only on SYNC. SYNC tick k comes
after the set-points and load command the host wrote in tick k-1, on the same bus, so the plant
integrates [t_{k-1}, t_k) with exactly the commands the in-process mock rig would have; then the
emulator sends the status frame (every ``status_divider`` ticks) and the sample frame k. The
host's loop time therefore drives the plant, and an emulated run is deterministic for a seed.
In real-time mode nothing changes: the host's wall-clock loop sends SYNC, the emulator follows.

Faults (mock_hw.emulators.faults) are scheduled in ticks and applied on the bytes (drop,
corrupt, delay, duplicate, stall, disconnect) or on the plant (encoder stuck/jump, drive trip,
lost heartbeat).
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
import threading
import time
from dataclasses import replace
from typing import Any

import can
import cantools

from bench.core.config import RigConfig
from bench.wire.canbus import fault_names, load_dbc, open_bus
from bench.wire.frontend import FS_ADC_CLIP, encode_frame
from bench.wire.fc_profile import (
    CTW_RESET, CTW_START, STW_BUS_CONTROL, STW_CONTROL_READY, STW_DRIVE_READY, STW_RUNNING, STW_TRIP,
    from_percent_word, to_percent_word,
)  # fmt: skip
from mock_hw.emulators.faults import Fault
from mock_hw.emulators.links import ModbusTcpEndpoint, SerialEndpoint, TcpCanServerBus, modbus_peer
from mock_hw.inverter import SETPOINT_WATCHDOG
from mock_hw.plant import MockConfig, MockPlant, drive_settings
from bench.core.rt_host import realtime_setup


EMU_PRIORITY = 40  # SCHED_FIFO priority of `bench emulate` (the loop takes 50)
CONTROL_WORD_TIMEOUT = "control-word timeout"  # fault names as in the DBC's VLT_STATUS.FAULT value table
# which emulator this is, proved without disclosing its secret (mock_hw.emulators.emulator_running): a
# client writes a 128-bit nonce into AUTH_WORDS holding registers at CHALLENGE_REGISTER and reads
# `auth_answer` (HMAC-SHA256 under the emulator's secret, 128 bits) from as many at ANSWER_REGISTER, per
# connection. Wire addresses, big-endian words; far from the FC profile's and the parameters' registers.
CHALLENGE_REGISTER = 59990
AUTH_WORDS = 8
ANSWER_REGISTER = CHALLENGE_REGISTER + AUTH_WORDS
# the host's clock, written by a host that asked a challenge (mock_hw.emulators.emulator_running):
# CLOCK_WALL (the default) or CLOCK_TICKS, a lockstep host whose time is its SYNC ticks
CLOCK_REGISTER = ANSWER_REGISTER + AUTH_WORDS
CLOCK_WALL, CLOCK_TICKS = 1, 2
_AUTH_END = CLOCK_REGISTER + 1


def auth_answer(secret: bytes, nonce: bytes) -> bytes:
    """The answer to a challenge: HMAC-SHA256(secret, nonce), its first 2 * AUTH_WORDS bytes."""
    return hmac.new(secret, nonce, hashlib.sha256).digest()[: 2 * AUTH_WORDS]


def _words(b: bytes) -> list[int]:
    return [int.from_bytes(b[i:i + 2], "big") for i in range(0, len(b), 2)]


def _realtime_thread() -> dict[str, Any]:
    return realtime_setup(cpu_index=0, priority=EMU_PRIORITY)


class RigEmulator:
    """All devices of a driver rig, emulated over their wire protocols and backed by `MockPlant`."""

    def __init__(self, cfg: RigConfig, seed: int = 0, faults: list[Fault] | None = None) -> None:
        if cfg.driver != "drivers":
            raise ValueError("the emulator needs a rig file with rig.driver = \"drivers\"")
        # first, so that close() works whatever the rest of __init__ got to (a port already taken)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        # which emulator this is: never served; `bench emulate` keeps it in a file only its user reads, and
        # answers challenges with it (auth_answer)
        self.secret = secrets.token_bytes(32)
        self._nonces: dict[object, bytearray] = {}  # Modbus connection -> the nonce it wrote
        self.host_clock = CLOCK_WALL  # which clock the controlling host runs on (CLOCK_REGISTER)
        self._mb_owner: object | None = None  # the Modbus connection that commands the drive (one at a time)
        self.bus: Any = None
        self.serial: SerialEndpoint | None = None
        self.modbus: ModbusTcpEndpoint | None = None
        hw = cfg.hw
        self.cfg = cfg
        self.T_s = cfg.T_s
        self.plant = MockPlant(MockConfig.from_dict(cfg.mock), dt=cfg.T_s, seed=seed, **drive_settings(cfg.limits))
        self.U_max = cfg.limits.U_max
        self.torque_limit = hw["load"]["torque_limit"]
        can_cfg = hw["can"]
        self.db = load_dbc(can_cfg)
        self.m_sp = self.db.get_message_by_name("VLT_SETPOINT")
        self.m_st = self.db.get_message_by_name("VLT_STATUS")
        self.m_load = self.db.get_message_by_name("LOAD_TORQUE")
        self.m_sync = self.db.get_message_by_name("SYNC")
        self.divider = can_cfg["status_divider"]
        # the drive's fault names -> codes of VLT_STATUS.FAULT (the DBC's value table: one list for both ends)
        self._fault_codes = {name: code for code, name in fault_names(self.m_st).items()}
        self.sp_timeout = max(1, int(round(can_cfg["heartbeat_timeout"] / cfg.T_s)))
        self.control_timeout = float(hw["emulator"]["control_timeout"])  # [s] wall clock, `bench emulate`
        self.faults: list[Fault] = list(faults or [])
        self.lock = threading.Lock()  # plant state: CAN thread vs Modbus server thread
        self.stats = {"syncs": 0, "frames": 0, "status_frames": 0, "setpoints": 0, "counter_errors": 0,
                      "dropped": 0, "corrupted": 0, "duplicated": 0, "delayed": 0, "sync_gaps": 0,
                      "bad_frames": 0, "refused_writes": 0}  # fmt: skip
        self._reset_state()
        mb = hw["modbus"]
        self.mb = mb
        try:
            if can_cfg["interface"] == "tcp":  # serve the loopback TCP CAN link (bench.drivers.tcpcan)
                self.bus = TcpCanServerBus(can_cfg["channel"], self.stats)
            else:
                self.bus = open_bus(can_cfg)
            self.serial = SerialEndpoint(hw["serial"]["port"])
            if mb["transport"] == "tcp":
                regs = [mb[k] for k in ("control_word", "status_word", "actual_value", "dc_link", "load_register")]
                regs += [mb["reference"], mb["reference"] + 1, *range(CHALLENGE_REGISTER, _AUTH_END)]
                self.modbus = ModbusTcpEndpoint(mb["port"], mb["unit"], regs, self._modbus_action, self._modbus_gone)
        except BaseException:
            self.close()  # what was opened: a port taken by someone else must not leak the others
            raise
        self._handlers = {self.m_sp.frame_id: self._on_setpoint, self.m_load.frame_id: self._on_load,
                          self.m_sync.frame_id: self._on_sync}  # fmt: skip

    def _reset_state(self) -> None:
        self.k: int | None = None  # last SYNC tick
        self.bus_run = False  # FC-profile control word: RUN
        self._ctw = 0
        self._last_sp: int | None = None  # tick of the last set-point frame
        self._last_sp_wall: float | None = None  # time.monotonic() of the last set-point (real-time watchdog)
        self._sp_counter: int | None = None
        self.sp_timeout_flag = False
        self.counter_error = False
        self._delayed: list[tuple[int, bytes]] = []  # (release tick, frame)
        self._stuck = False
        self._last_status: int | None = None
        self._first_frame = True
        self._truth: dict[int, tuple[float, ...]] = {}

    # --- host-side view ---------------------------------------------------------------------
    def host_config(self) -> RigConfig:
        """The rig config with the addresses this emulator actually bound (ephemeral ports)."""
        hw = {k: dict(v) for k, v in self.cfg.hw.items()}
        hw["serial"]["port"] = self.serial.url
        if self.modbus is not None:
            hw["modbus"]["port"] = self.modbus.port
        if isinstance(self.bus, TcpCanServerBus):
            hw["can"]["channel"] = self.bus.channel
        return replace(self.cfg, hw=hw)

    # --- lifecycle --------------------------------------------------------------------------
    def start(self, realtime: bool = False) -> "RigEmulator":
        self._stop.clear()
        self._thread = threading.Thread(target=self.serve, args=(realtime,), name="emu-can", daemon=True)
        self._thread.start()
        return self

    def serve(self, realtime: bool = False) -> None:
        """Process CAN frames until `stop` (blocking; `start` runs it in a thread).

        ``realtime`` (`bench emulate`, best effort): this thread takes SCHED_FIFO priority
        `EMU_PRIORITY`, below the loop's, on the first CPU (the loop pins itself to the last), so
        that on a busy machine the emulated devices answer like hardware would: at once.
        """
        if realtime:
            self.rt_setup = _realtime_thread()
        stop = self._stop
        poll = min(0.05, self.control_timeout / 4)
        while not stop.is_set():
            self.serve_once(poll, realtime)

    def serve_once(self, poll: float, realtime: bool) -> None:
        """One received frame handled; or, when the bus stayed quiet for ``poll`` seconds, the wall-clock watchdog
        (``realtime``) looks. Not after each frame: frames that queued while this process itself was descheduled
        (a busy machine) are no silence of the host, whatever frame heads the backlog."""
        msg = self.bus.recv(poll)
        if msg is not None:
            self.handle(msg)
        elif realtime:
            self._control_watchdog()

    def _control_watchdog(self) -> None:
        """The drive's control-word timeout on the wall clock (FC 8-03/8-04 "stop and trip").

        A real drive does not need SYNC to notice that its master went silent: once it has received
        set-points in RUN, ``control_timeout`` seconds without one coast the motor and latch a fault.
        Without this, a host killed with SIGKILL left the emulated drive running its last command.
        Only in real time (`bench emulate`), and paced to the run's clock: a host that said it runs in lockstep
        (``CLOCK_TICKS``) has no wall-clock deadlines (a slow one is no dead one), and its plant advances only on
        its SYNC, so the set-point watchdog, counted in SYNC ticks, is its watchdog.
        """
        last = self._last_sp_wall
        if last is None or not self.bus_run or self.sp_timeout_flag or self.host_clock == CLOCK_TICKS:
            return
        if time.monotonic() - last > self.control_timeout:
            with self.lock:
                self.sp_timeout_flag = True
                self.plant.inverter.disable()
                self.plant.inverter.inject_fault(CONTROL_WORD_TIMEOUT)
                self.stats["control_timeouts"] = self.stats.get("control_timeouts", 0) + 1

    def handle(self, msg: can.Message) -> None:
        """Process one received CAN frame; a malformed one is counted and ignored."""
        h = self._handlers.get(msg.arbitration_id)
        if h is not None:
            try:
                h(msg)
            except (ValueError, KeyError, IndexError, cantools.database.DecodeError):
                self.stats["bad_frames"] += 1

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def close(self) -> None:
        self.stop()
        if self.modbus is not None:
            self.modbus.close()
        if self.serial is not None:
            self.serial.close()
        if self.bus is not None:
            self.bus.shutdown()
            self.bus = None

    def __enter__(self) -> "RigEmulator":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def truth_view(self, frontend: Any) -> "EmulatorTruth":
        """The plant's ground truth at the samples the host's front-end driver takes."""
        return EmulatorTruth(self, frontend)

    def inject(self, fault: Fault) -> None:
        self.faults.append(fault)

    # --- CAN ----------------------------------------------------------------------------------
    def _on_setpoint(self, msg: can.Message) -> None:
        s = self.m_sp.decode(msg.data, decode_choices=False)
        c = int(s["COUNTER"])
        if self._sp_counter is not None and c != (self._sp_counter + 1) & 0xF:
            self.counter_error = True
            self.stats["counter_errors"] += 1
        self._sp_counter = c
        self._last_sp = self.k if self.k is not None else 0
        self._last_sp_wall = time.monotonic()
        self.stats["setpoints"] += 1
        inv = self.plant.inverter
        with self.lock:
            inv.set_voltage(complex(s["U_ALPHA"], s["U_BETA"]), float(s.get("OMEGA_U", 0.0)))
            if s["ENABLE"] and self.bus_run and not self.sp_timeout_flag:
                inv.enable()
            else:
                inv.disable()

    def _on_load(self, msg: can.Message) -> None:
        s = self.m_load.decode(msg.data, decode_choices=False)
        with self.lock:
            self.plant.load.set_torque(float(s["M_REF"]))

    def _on_sync(self, msg: can.Message) -> None:
        tick8 = msg.data[0] if msg.data else 0
        if self.k is None:
            k = tick8
        else:
            d = (tick8 - self.k) & 0xFF
            if d == 0:
                return  # repeated SYNC
            if d > 1:
                self.stats["sync_gaps"] += 1
            k = self.k + d
        self.k = k
        self.stats["syncs"] += 1
        self.step(k)

    def step(self, k: int) -> None:
        """Advance the plant to tick k and send what the devices send at that sample."""
        plant = self.plant
        active = [f for f in self.faults if f.active(k)] if self.faults else []
        kinds = {f.kind for f in active}
        with self.lock:
            self._plant_faults(k, kinds, active)
            # the drive's set-point watchdog (only once it runs on bus set-points)
            if (self.bus_run and self._last_sp is not None and k - self._last_sp > self.sp_timeout
                    and not self.sp_timeout_flag):  # fmt: skip
                self.sp_timeout_flag = True
                plant.inverter.inject_fault(SETPOINT_WATCHDOG)
            plant.acquire(k * self.T_s)
            truth = self._truth
            truth[k & 0xFFFF] = plant.sample()  # ground truth of this sample, for in-process logging
            if len(truth) > 16:
                del truth[next(iter(truth))]
            inv_st = plant.inverter.status()
            raw_i = plant.currents.read_raw()
            raw_u = plant.voltages.read_raw()
            cnt, idx = plant.encoder.read()
        last = self._last_status
        due = last is None or k // self.divider != last // self.divider  # also when the due tick was skipped
        if due and "heartbeat_lost" not in kinds:
            self._last_status = k
            sig = {"U_DC": inv_st.u_dc, "ENABLED": int(inv_st.enabled), "TRIP": int(inv_st.fault),
                   "SETPOINT_TIMEOUT": int(self.sp_timeout_flag), "COUNTER_ERROR": int(self.counter_error),
                   "HEARTBEAT": k & 0xFF}  # fmt: skip
            if self._fault_codes:  # which fault (a DBC without VLT_STATUS.FAULT: not sent)
                sig["FAULT"] = self._fault_codes.get(inv_st.fault_name, 255) if inv_st.fault else 0
            data = self.m_st.encode(sig)
            try:
                self.bus.send(can.Message(arbitration_id=self.m_st.frame_id, data=data, is_extended_id=False))
                self.stats["status_frames"] += 1
            except can.CanError:
                pass
        adc_i, adc_u = plant.currents.adc, plant.voltages.adc
        st = 0
        if any(c in (adc_i.code_min, adc_i.code_max) for c in raw_i) or any(
                c in (adc_u.code_min, adc_u.code_max) for c in raw_u):  # fmt: skip
            st |= FS_ADC_CLIP
        frame = encode_frame(k, st, raw_i, raw_u, cnt, idx)
        self._send_frame(k, frame, kinds, active)

    def _plant_faults(self, k: int, kinds: set[str], active: list[Fault]) -> None:
        plant = self.plant
        stuck = "encoder_stuck" in kinds
        if stuck != self._stuck:
            plant.encoder.inject_stuck(stuck)
            self._stuck = stuck
        for f in active:
            if f.kind == "encoder_jump" and k == f.at:
                plant.encoder.inject_jump(f.arg or 1000)
            elif f.kind == "inverter_fault" and k == f.at:
                plant.inverter.inject_fault("injected")

    def _send_frame(self, k: int, frame: bytes, kinds: set[str], active: list[Fault]) -> None:
        ser = self.serial
        if self._delayed:
            due = [f for t, f in self._delayed if t <= k]
            self._delayed = [(t, f) for t, f in self._delayed if t > k]
            for f in due:
                ser.write(f)
        if "disconnect" in kinds:
            if any(f.kind == "disconnect" and f.at == k for f in active):
                ser.disconnect()
            self.stats["dropped"] += 1
            return
        if "stall" in kinds or "drop" in kinds:
            self.stats["dropped"] += 1
            return
        if "corrupt" in kinds:
            b = bytearray(frame)
            b[6 + (k % 20)] ^= 0x5A
            frame = bytes(b)
            self.stats["corrupted"] += 1
        if "delay" in kinds:
            n = max(1, next(f.arg for f in active if f.kind == "delay"))
            self._delayed.append((k + n, frame))
            self.stats["delayed"] += 1
            return
        if "duplicate" in kinds:
            frame = frame + frame
            self.stats["duplicated"] += 1
        # the first frame of a session waits (up to 1 s) for the host's serial connection
        ser.write(frame, wait=1.0 if self._first_frame else 0.0)
        self._first_frame = False
        self.stats["frames"] += 1

    # --- Modbus (pymodbus SimDevice action) ------------------------------------------------------
    async def _modbus_action(self, fc: int, start: int, address: int, count: int, registers: list[int],
                             values: Any) -> Any:  # fmt: skip
        """Every Modbus access. The first connection that writes a device register commands the drive until it
        closes; another's writes meanwhile are refused (DEVICE_BUSY), so a second host cannot start, reset
        (restart the session) or give set-points - except a plain stop or coast of the control word, which
        anyone on the network may send, as to a real drive. Challenge registers are per connection."""
        from pymodbus.constants import ExcCodes

        mb = self.mb
        inv = self.plant.inverter
        peer = modbus_peer()
        with self.lock:
            if values:  # write
                device = [(address + i, int(v)) for i, v in enumerate(values)
                          if not CHALLENGE_REGISTER <= address + i < _AUTH_END]  # fmt: skip
                if device and peer is not None:
                    if self._mb_owner is not None and self._mb_owner is not peer:
                        stops = [a == mb["control_word"] and not v & (CTW_START | CTW_RESET) for a, v in device]
                        if not all(stops):
                            self.stats["refused_writes"] += 1
                            return ExcCodes.DEVICE_BUSY
                    else:
                        self._mb_owner = peer
                for i, v in enumerate(values):
                    j = address + i - CHALLENGE_REGISTER
                    if 0 <= j < AUTH_WORDS:
                        nonce = self._nonces.setdefault(peer, bytearray(2 * AUTH_WORDS))
                        nonce[2 * j:2 * j + 2] = (int(v) & 0xFFFF).to_bytes(2, "big")
                    elif address + i == CLOCK_REGISTER and peer in self._nonces and int(v) in (CLOCK_WALL, CLOCK_TICKS):
                        self.host_clock = int(v)  # from a host that asked a challenge
                for a, v in device:
                    self._write_register(a, v)
                return None
            st = inv.status()
            stw = STW_CONTROL_READY | STW_DRIVE_READY | STW_BUS_CONTROL
            if st.fault:
                stw |= STW_TRIP
            if st.enabled:
                stw |= STW_RUNNING
            live = {mb["status_word"]: stw, mb["dc_link"]: int(round(st.u_dc * 10)) & 0xFFFF,
                    mb["actual_value"]: to_percent_word(abs(inv.u_applied), self.U_max),
                    mb["control_word"]: self._ctw}  # fmt: skip
            nonce = self._nonces.get(peer)
            answer = _words(auth_answer(self.secret, bytes(nonce))) if nonce is not None else [0] * AUTH_WORDS
            for i in range(AUTH_WORDS):  # what another connection wrote or was answered is not shown
                live[CHALLENGE_REGISTER + i] = 0
                live[ANSWER_REGISTER + i] = answer[i]
            for a, v in live.items():
                if 0 <= a - start < len(registers):
                    registers[a - start] = v
        return None

    def _modbus_gone(self, peer: object) -> None:
        """A Modbus connection closed: its nonce goes, and the drive is free for the next host."""
        with self.lock:
            self._nonces.pop(peer, None)
            if self._mb_owner is peer:
                self._mb_owner = None

    def _write_register(self, a: int, v: int) -> None:
        mb, inv = self.mb, self.plant.inverter
        if a == mb["control_word"]:
            if v & CTW_RESET and not self._ctw & CTW_RESET:  # rising edge: fault reset
                # STOP + reset in one word is how a host starts its session (bench.drivers.vlt): the plant
                # restarts at rest, t = 0 - from any state, also after a host died while the drive ran
                if not self.bus_run or not v & CTW_START:
                    self.plant.configure()
                    delayed = self._delayed
                    self._reset_state()
                    self.stats["sessions"] = self.stats.get("sessions", 0) + 1
                    del delayed[:]
                inv.reset_fault()
                self.sp_timeout_flag = False
                self.counter_error = False
                self._last_sp = None
                self._last_sp_wall = None
            self.bus_run = bool(v & CTW_START)
            if not self.bus_run:
                inv.disable()
            elif self.cfg.hw["inverter"]["setpoints"] == "modbus" and not self.sp_timeout_flag:
                inv.enable()
            self._ctw = v
        elif a == mb["reference"]:
            self._last_sp_wall = time.monotonic()
            inv.set_voltage(complex(from_percent_word(v, self.U_max), inv._ref.imag))
        elif a == mb["reference"] + 1:
            inv.set_voltage(complex(inv._ref.real, from_percent_word(v, self.U_max)))
        elif a == mb["load_register"]:
            self.plant.load.set_torque(from_percent_word(v, self.torque_limit))


class EmulatorTruth:
    """`GroundTruth` of an in-process emulator, as it was at the sample the host last used.

    The emulator may already be computing the next sample (``can.sync_early``) while the loop logs
    this one, so the plant is not read directly: the emulator keeps a snapshot per sample, and this
    returns the one of the tick the front-end driver asked for (NaN if the emulator never made it).
    """

    def __init__(self, emu: RigEmulator, frontend: Any) -> None:
        self.emu, self.frontend = emu, frontend
        self.fields = emu.plant.fields
        self._nan = tuple(float("nan") for _ in self.fields)

    def sample(self) -> tuple[float, ...]:
        seq = self.frontend._prev_want  # this tick's sample, also when its frame was lost on the wire
        if seq is None:
            return self._nan
        truth = self.emu._truth
        snap = truth.get(seq)
        if snap is None:  # the emulator is behind (the host did not wait for a frame): wait a little
            end = time.perf_counter() + 0.02
            while snap is None and time.perf_counter() < end:
                time.sleep(1e-4)
                snap = truth.get(seq)
        return snap if snap is not None else self._nan


def wait_for_client(emu: RigEmulator, timeout: float = 5.0) -> bool:
    """Wait until the host has opened the serial link (tests)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if emu.serial.connected:
            return True
        time.sleep(0.005)
    return False
