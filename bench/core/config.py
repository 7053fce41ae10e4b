"""Rig files (TOML): which rig, which driver serves each port, transports, scaling and limits.

A rig file has these tables (all optional except ``[rig]``)::

    [rig]      name, driver ("mock" | "drivers"), rate_hz, free_shaft (true: only the DC load machine is
               coupled, the shaft may turn in `bench commission`'s rotating test; default: true on the mock and
               emulated rigs, false on a real one)
    [limits]   I_max, I_trip, I_trip_phase, U_max, omega_max, u_dc_min, u_dc_max, stale_ticks,
               burst_count, burst_window, enc_stuck_time, enc_stuck_omega, max_stall, ride_through,
               enable_timeout   (bench.core.supervisor.Limits)
    [motor]    the nominal model controllers use: L_s, L_r, L_m, R_s, R_r, Z_p, J, B_visc, m_coulomb
    [nameplate]  the motor's plate: P_rated [W], U_rated [V line to line, rms], I_rated [A rms], f_rated [Hz],
               n_rated [rpm], cos_phi (optional); checked against [motor] and [limits], and the drive's defaults
               follow from it where it is not the thesis motor's (bench.core.nameplate)
    [inverter_error]  the inverter's voltage error per phase: current = [A...], error = [V...]
               (bench.core.inverter_error); absent: the controllers compensate nothing
    [mock]     settings of the mock plant (mock_hw.plant.MockConfig); [mock.motor] overrides the
               *true* machine, e.g. R_r = 4.95 for a hot rotor, and holds its saturation curve;
               [mock.inverter] the voltage error, [mock.thermal] the winding temperatures
               (docs/mock-plant.md). The emulators run this plant too.

``driver = "drivers"`` builds the rig from real drivers (bench/drivers) and needs these tables
(every field has the default shown in `SCHEMA`; docs/protocols.md describes the wire formats)::

    [ports]    which driver serves each HAL port: inverter = "vlt"; currents, voltages, encoder =
               "frontend"; load = "load_can" | "load_modbus"
    [can]      python-can transport (interface, channel, bitrate, max_bus_load), DBC file, frame map
               (sync_id, setpoint_id, status_id, load_id), status_divider, heartbeat_timeout
    [serial]   measurement front-end link: port (pyserial URL), baudrate, timeout, reconnect_interval
    [modbus]   transport ("tcp" | "rtu"), host, port, unit, serial_port, baudrate, timeout, rtt,
               register map (control_word, reference, status_word, actual_value, dc_link,
               load_register)
    [inverter] setpoints ("can" | "modbus")
    [frontend] scaling: turns_ratio, burden, adc_bits, adc_range, offset_i, offset_u (calibrated
               offsets, V at the ADC; `bench calibrate` writes them), divider_ratio, lines, modulus
    [load]     torque_limit [N m]
    [emulator] autostart (start the emulators in-process if nothing answers), seed

`bench run --rig NAME` looks for ``NAME`` as a path, then ``rigs/NAME.toml`` in the working
directory, then in the source tree. Every error names the offending field in one line, e.g.
``can.bitrate: must be an integer in 10000..1000000, got 2000000``.

Transport budget (`check_budget`): a rig whose loop rate the transports cannot carry is refused,
and the error says what they can carry. CAN: worst-case bit-stuffed frame lengths of the frames
sent per tick at ``bitrate * max_bus_load``. Serial: frame bytes x 10 bits at ``baudrate``. Modbus
RTU: request + response characters (11 bits each) + 2 x t3.5 silent intervals per transaction;
Modbus TCP: ``rtt`` per transaction. Only per-tick traffic counts (set-points, load command,
SYNC, status, samples); parameter traffic at start/stop does not.
"""

from __future__ import annotations

import math
import sys
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import tomlkit

from bench.core import nameplate
from bench.errors import BadInput, allowed, finite_number
from bench.core.inverter_error import InverterError, parse as parse_inverter_error
from bench.core.nameplate import Nameplate
from bench.params import MotorParams
from bench.core.supervisor import LIMIT_RANGES, Limits
from bench.core.rigfile_write import RIGS_DIR, Snapshot, replace_file

if TYPE_CHECKING:
    from bench.core.rigfile_write import Snapshot

DRIVERS = ("mock", "drivers")
_SECTIONS = ("rig", "limits", "motor", "nameplate", "inverter_error", "mock", "ports", "can", "serial", "modbus", "inverter", "frontend", "load",
             "emulator")  # fmt: skip
_INT_LIMITS = ("stale_ticks", "burst_count")
ELECTRICAL = ("L_s", "L_r", "L_m", "R_s", "R_r")  # [motor] fields that state the machine (checked against a plate)

_INF = math.inf
# (kind, default, lo, hi). kinds: int, num (finite, in [lo, hi]), bool, str, one of a tuple (choice),
# triple (one number or 3 numbers in [lo, hi]).
Rule = tuple[Any, Any, float, float]
SCHEMA: dict[str, dict[str, Rule]] = {
    "ports": {
        "inverter": (("vlt",), "vlt", 0, 0),
        "currents": (("frontend",), "frontend", 0, 0),
        "voltages": (("frontend",), "frontend", 0, 0),
        "encoder": (("frontend",), "frontend", 0, 0),
        "load": (("load_can", "load_modbus"), "load_can", 0, 0),
    },
    "can": {
        "interface": ("str", "virtual", 0, 0),  # any python-can interface: virtual, socketcan, pcan, ...
        "channel": ("str", "imbench", 0, 0),
        "bitrate": ("int", 1_000_000, 10_000, 1_000_000),
        "max_bus_load": ("num", 0.9, 0.05, 1.0),
        "dbc": ("str", "", 0, 0),  # "" = the packaged bench/wire/imbench.dbc
        "sync": ("bool", True, 0, 0),  # send a SYNC frame each tick (lockstep and sampled devices)
        "sync_early": ("bool", False, 0, 0),  # SYNC right after the last write (emulators only)
        "sync_id": ("int", 0x080, 0, 0x7FF),
        "setpoint_id": ("int", 0x100, 0, 0x7FF),
        "load_id": ("int", 0x110, 0, 0x7FF),
        "status_id": ("int", 0x180, 0, 0x7FF),
        "status_divider": ("int", 3, 1, 1000),  # the inverter sends its status every N SYNCs
        "heartbeat_timeout": ("num", 0.02, 1e-4, 10.0),  # [s] no status frame this long -> ST_INV_STALE; >= ride_through
        "status_wait": ("num", 0.005, 0.0, 1.0),  # [s] how long status() waits for a due status frame
    },
    "serial": {
        "port": ("str", "socket://127.0.0.1:27600", 0, 0),  # pyserial URL or device
        "baudrate": ("int", 2_000_000, 1200, 100_000_000),
        "timeout": ("num", 0.05, 1e-4, 10.0),  # [s] wait for the tick's frame before ST_MEAS_STALE
        "reconnect_interval": ("num", 0.2, 0.001, 60.0),  # [s] between reconnection attempts
    },
    "modbus": {
        "transport": (("tcp", "rtu"), "tcp", 0, 0),
        "host": ("str", "127.0.0.1", 0, 0),
        "port": ("int", 27502, 0, 65535),
        "unit": ("int", 1, 0, 247),
        "serial_port": ("str", "/dev/ttyUSB0", 0, 0),
        "baudrate": ("int", 115200, 1200, 4_000_000),
        "timeout": ("num", 0.5, 1e-3, 60.0),
        "rtt": ("num", 1e-3, 1e-5, 10.0),  # [s] assumed TCP transaction time (budget check)
        "control_word": ("int", 49999, 0, 65535),  # FC profile, wire addresses (register - 1)
        "reference": ("int", 50009, 0, 65535),  # u_alpha, u_beta at reference, reference + 1
        "status_word": ("int", 50199, 0, 65535),
        "actual_value": ("int", 50209, 0, 65535),
        "dc_link": ("int", 16299, 0, 65535),  # par. 16-30, 0.1 V
        "load_register": ("int", 0, 0, 65535),  # analog-output module channel (load_modbus)
    },
    "inverter": {
        "setpoints": (("can", "modbus"), "can", 0, 0),
    },
    "frontend": {
        "turns_ratio": ("num", 1000.0, 1e-3, 1e6),
        "burden": ("num", 500.0, 1e-3, 1e6),
        "adc_bits": ("int", 12, 8, 16),
        "adc_range": ("num", 10.0, 1e-3, 1e3),
        "offset_i": ("triple", 0.0, -100.0, 100.0),  # [V at the ADC]
        "offset_u": ("triple", 0.0, -100.0, 100.0),
        "divider_ratio": ("num", 1.0 / 40.0, 1e-6, 1.0),
        "lines": ("int", 1024, 1, 1 << 20),
        "modulus": ("int", 1 << 16, 4, 1 << 32),
    },
    "load": {
        "torque_limit": ("num", 15.0, 1e-3, 1e4),
    },
    "emulator": {
        # "auto": use a running `bench emulate` of this user if one answers on modbus.port (it must prove it
        # knows the secret of this user's token file; anything else there is refused), else start in-process;
        # "always": start in-process; "never": connect to whatever serves the transports
        "autostart": (("auto", "always", "never"), "auto", 0, 0),
        "seed": ("int", 0, 0, (1 << 63) - 1),  # plant noise seed for `bench emulate` (bench run uses --seed)
        "faults": ("list", [], 0, 0),  # [[emulator.faults]] tables: mock_hw.emulators.faults
        # the emulated drive's control-word timeout (FC par. 8-03, function 8-04 "stop and trip"): in
        # `bench emulate` (real time), no set-point for this long -> coast and report the fault
        "control_timeout": ("num", 0.1, 0.005, 60.0),
    },
}  # fmt: skip
DRIVER_SECTIONS = tuple(SCHEMA)


@dataclass(frozen=True)
class RigConfig:
    name: str
    driver: str
    rate_hz: float
    limits: Limits
    motor: MotorParams
    mock: dict[str, Any] = field(default_factory=dict)
    path: str | None = None
    hw: dict[str, dict[str, Any]] = field(default_factory=dict)  # validated driver tables, defaults filled
    inverter_error: InverterError | None = None  # [inverter_error]; None: none given
    nameplate: Nameplate | None = None  # [nameplate]; None: none given
    # [rig] free_shaft; None: not given (bench.workflows.commission.commission.shaft_may_turn)
    free_shaft: bool | None = None

    @property
    def T_s(self) -> float:
        return 1.0 / self.rate_hz

    def as_dict(self) -> dict[str, Any]:
        out = {"rig": {"name": self.name, "driver": self.driver, "rate_hz": self.rate_hz}
               | ({} if self.free_shaft is None else {"free_shaft": self.free_shaft}),
               "limits": self.limits.as_dict(), "motor": self.motor.as_dict(), "mock": self.mock,
               "path": self.path}  # fmt: skip
        out.update({k: dict(v) for k, v in self.hw.items()})
        if self.inverter_error is not None:
            out["inverter_error"] = self.inverter_error.as_dict()
        if self.nameplate is not None:
            out["nameplate"] = self.nameplate.as_dict()
        return out


def is_real_rig(cfg: RigConfig) -> bool:
    """Real devices behind real drivers (no emulator will be started for them)."""
    return cfg.driver == "drivers" and cfg.hw["emulator"]["autostart"] == "never"


def _numbers(section: str, table: Any, cls: type) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise BadInput(section, "must be a table")
    names = [f.name for f in fields(cls)]
    out: dict[str, Any] = {}
    for key, value in table.items():
        if key not in names:
            raise BadInput(f"{section}.{key}", f"unknown field; allowed: {allowed(names)}")
        if not finite_number(value):
            raise BadInput(f"{section}.{key}", f"must be a finite number, got {value!r}")
        out[key] = value
    return out


_is_num = finite_number


def _check(name: str, v: Any, rule: Rule) -> Any:
    kind, _, lo, hi = rule
    if isinstance(kind, tuple):
        if v not in kind:
            raise BadInput(name, f"must be one of {allowed(repr(k) for k in kind)}, got {v!r}")
        return v
    if kind == "bool":
        if not isinstance(v, bool):
            raise BadInput(name, f"must be true or false, got {v!r}")
        return v
    if kind == "list":
        if not isinstance(v, list):
            raise BadInput(name, f"must be an array of tables, got {v!r}")
        return v
    if kind == "str":
        if not isinstance(v, str):
            raise BadInput(name, f"must be a string, got {v!r}")
        if not v.strip() and rule[1]:  # a field whose default names something may not be emptied
            raise BadInput(name, f"must not be empty (default {rule[1]!r})")
        return v
    if kind == "int":
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise BadInput(name, f"must be an integer in {lo:g}..{hi:g}, got {v!r}")
        return v
    if kind == "num":
        if not _is_num(v) or not lo <= v <= hi:
            raise BadInput(name, f"must be a number in [{lo:g}, {hi:g}], got {v!r}")
        return float(v)
    vals = [v, v, v] if _is_num(v) else v  # triple
    if not isinstance(vals, list) or len(vals) != 3 or not all(_is_num(x) and lo <= x <= hi for x in vals):
        raise BadInput(name, f"must be one number or a list of 3 numbers (phases a, b, c), got {v!r}")
    return tuple(float(x) for x in vals)


def parse_hw(data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Validate the driver tables and fill in defaults."""
    out: dict[str, dict[str, Any]] = {}
    for section, rules in SCHEMA.items():
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise BadInput(section, "must be a table")
        sec = {k: _check(f"{section}.{k}", r[1], r) for k, r in rules.items()}
        for key, value in table.items():
            if key not in rules:
                raise BadInput(f"{section}.{key}", f"unknown field; allowed: {allowed(rules)}")
            sec[key] = _check(f"{section}.{key}", value, rules[key])
        out[section] = sec
    can = out["can"]
    if can["interface"] == "tcp":  # the loopback TCP CAN link: 127.0.0.1:PORT (bench.drivers.tcpcan)
        from bench.wire.tcpcan import parse_channel

        try:
            _, port = parse_channel(can["channel"])
        except Exception as exc:  # noqa: BLE001 - python-can's or int()'s complaint, one line
            raise BadInput("can.channel", f"the tcp interface needs 127.0.0.1:PORT: {exc}") from None
        if not 0 <= port <= 65535:
            raise BadInput("can.channel", f"port must be in 0..65535, got {port}")
    ids = {k: can[k] for k in ("sync_id", "setpoint_id", "load_id", "status_id")}
    seen: dict[int, str] = {}
    for key, value in ids.items():
        if value in seen:
            raise BadInput(f"can.{key}", f"frame id 0x{value:03X} is already used by can.{seen[value]}")
        seen[value] = key
    fe = out["frontend"]
    if fe["modulus"] < 4 * fe["lines"]:
        raise BadInput("frontend.modulus", f"must be >= 4*lines = {4 * fe['lines']}, got {fe['modulus']}")
    return out


def parse(data: dict[str, Any], path: str | None = None) -> RigConfig:
    """Validate a rig-file dictionary."""
    for key in data:
        if key not in _SECTIONS:
            raise BadInput(key, f"unknown table; allowed: {allowed(_SECTIONS)}")
    rig = data.get("rig")
    if not isinstance(rig, dict):
        raise BadInput("rig", "missing [rig] table with name, driver, rate_hz")
    for key in rig:
        if key not in ("name", "driver", "rate_hz", "free_shaft"):
            raise BadInput(f"rig.{key}", "unknown field; allowed: name, driver, rate_hz, free_shaft")
    free_shaft = rig.get("free_shaft")
    if free_shaft is not None and not isinstance(free_shaft, bool):
        raise BadInput("rig.free_shaft", f"must be true or false, got {free_shaft!r}")
    name = rig.get("name", "unnamed")
    if not isinstance(name, str) or not name.strip():
        raise BadInput("rig.name", f"must be a non-empty string, got {name!r}")
    driver = rig.get("driver", "mock")
    if driver not in DRIVERS:
        raise BadInput("rig.driver", f"unknown driver {driver!r}; allowed: {allowed(DRIVERS)}")
    rate = rig.get("rate_hz", 3000.0)
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (100.0 <= rate <= 50_000.0):
        raise BadInput("rig.rate_hz", f"must be a number in 100..50000, got {rate!r}")

    plate = nameplate.parse(data["nameplate"]) if "nameplate" in data else None
    lim_fields = _numbers("limits", data.get("limits", {}), Limits)
    for key in _INT_LIMITS:
        if key in lim_fields and lim_fields[key] != int(lim_fields[key]):
            raise BadInput(f"limits.{key}", f"must be an integer, got {lim_fields[key]}")
    if not nameplate.is_thesis(plate):  # current and voltage limits the file leaves out follow the plate
        lim_fields = {**nameplate.limit_defaults(plate), **lim_fields}  # type: ignore[arg-type]
    lim = Limits(**lim_fields)
    for key, value in lim.as_dict().items():
        lo, hi = LIMIT_RANGES[key]
        if not lo <= value <= hi:
            raise BadInput(f"limits.{key}", f"must be in [{lo:g}, {hi:g}], got {value}")
        if 0.0 < abs(value) < sys.float_info.min:  # a subnormal passes "in [0, hi]" and is zero to every check
            raise BadInput(f"limits.{key}", f"must be 0 or a normal number in [{lo:g}, {hi:g}], got {value}")
    if lim.I_max >= lim.I_trip:
        raise BadInput("limits.I_max", f"must be below limits.I_trip ({lim.I_trip}), got {lim.I_max}")
    if lim.u_dc_min >= lim.u_dc_max:
        raise BadInput("limits.u_dc_min", "must be below limits.u_dc_max")
    if lim.max_stall < lim.ride_through:  # the PC would trip on a stall the drive bridged
        raise BadInput("limits.max_stall", f"must be >= limits.ride_through ({lim.ride_through:g} s), "
                       f"got {lim.max_stall:g}")

    motor_fields = _numbers("motor", data.get("motor", {}), MotorParams)
    if plate is not None and "Z_p" not in motor_fields:  # the plate's pole pairs
        motor_fields["Z_p"] = plate.Z_p
    if "Z_p" in motor_fields and not (isinstance(motor_fields["Z_p"], int) and 1 <= motor_fields["Z_p"] <= 32):
        raise BadInput("motor.Z_p", f"must be an integer in 1..32, got {motor_fields['Z_p']}")
    motor = MotorParams(**motor_fields)
    try:
        motor.validate()
    except ValueError as exc:
        field_name, _, problem = str(exc).partition(" ")
        raise BadInput(field_name, problem) from None
    if plate is not None:  # against [motor] (where the file states the machine) and [limits]
        nameplate.check(plate, motor, lim, motor_given=any(k in motor_fields for k in ELECTRICAL))
    mock = data.get("mock", {})
    if not isinstance(mock, dict):
        raise BadInput("mock", "must be a table")
    from mock_hw.plant import MockConfig  # the plant's settings are checked with the file, not at run time

    MockConfig.from_dict(mock)
    hw: dict[str, dict[str, Any]] = {}
    if driver == "drivers":
        hw = parse_hw(data)
        if hw["can"]["heartbeat_timeout"] < lim.ride_through:  # the drive's set-point watchdog would cut it short
            raise BadInput("can.heartbeat_timeout", f"must be >= limits.ride_through ({lim.ride_through:g} s), "
                           f"got {hw['can']['heartbeat_timeout']:g}")
    else:
        for section in DRIVER_SECTIONS:
            if section in data:
                raise BadInput(section, f"only used with rig.driver = \"drivers\", not {driver!r}")
    inv = parse_inverter_error(data["inverter_error"]) if "inverter_error" in data else None
    cfg = RigConfig(str(name), driver, float(rate), lim, motor, mock, path, hw, inv, plate, free_shaft)
    if driver == "drivers":
        check_budget(cfg)
    return cfg


# --- transport budget --------------------------------------------------------------------------
FRAME_BYTES = 28  # measurement front-end frame (bench.drivers.frontend.FRAME_SIZE)
CAN_DLC = {"sync": 1, "setpoint": 6, "load": 3, "status": 5}  # data bytes per frame (imbench.dbc)


def can_frame_bits(dlc: int) -> int:
    """Worst-case length of a classic CAN data frame with an 11-bit id, incl. stuff bits and IFS."""
    return 47 + 8 * dlc + (33 + 8 * dlc) // 4


def modbus_rtu_transaction_s(request: int, response: int, baudrate: int) -> float:
    """RTU transaction time: characters at 11 bits, plus the 3.5-character silence on both frames
    (fixed 1.75 ms above 19200 baud, as the Modbus serial-line spec says)."""
    t_char = 11.0 / baudrate
    t35 = 1.75e-3 if baudrate > 19200 else 3.5 * t_char
    return (request + response) * t_char + 2.0 * t35


def budget(cfg: RigConfig) -> dict[str, dict[str, Any]]:
    """Per-tick load on each transport and the highest loop rate it carries [Hz]."""
    hw = cfg.hw
    out: dict[str, dict[str, Any]] = {}
    can = hw["can"]
    bits = 0
    frames = []
    if can["sync"]:
        bits += can_frame_bits(CAN_DLC["sync"])
        frames.append("SYNC")
    if hw["inverter"]["setpoints"] == "can":
        bits += can_frame_bits(CAN_DLC["setpoint"])
        frames.append("VLT_SETPOINT")
    if hw["ports"]["load"] == "load_can":
        bits += can_frame_bits(CAN_DLC["load"])
        frames.append("LOAD_TORQUE")
    bits_status = can_frame_bits(CAN_DLC["status"]) / can["status_divider"]
    bits += bits_status
    frames.append(f"VLT_STATUS/{can['status_divider']}")
    out["can"] = {"field": "can.bitrate", "bits_per_tick": bits, "frames": frames,
                  "max_rate_hz": can["bitrate"] * can["max_bus_load"] / bits,
                  "what": f"CAN at {can['bitrate']} bit/s, {can['max_bus_load']:.0%} bus load, "
                          f"{bits:.0f} bits/tick worst case ({' + '.join(frames)})"}  # fmt: skip
    ser = hw["serial"]
    out["serial"] = {"field": "serial.baudrate", "max_rate_hz": ser["baudrate"] / (10.0 * FRAME_BYTES),
                     "what": f"serial at {ser['baudrate']} baud, {FRAME_BYTES}-byte frames"}  # fmt: skip
    mb = hw["modbus"]
    per_tick: list[tuple[int, int, str]] = []  # (request bytes, response bytes) on RTU
    if hw["inverter"]["setpoints"] == "modbus":
        per_tick.append((13, 8, "set-point FC16 x2 registers"))
    if hw["ports"]["load"] == "load_modbus":
        per_tick.append((8, 8, "load torque FC06"))
    if per_tick:
        if mb["transport"] == "rtu":
            t = sum(modbus_rtu_transaction_s(a, b, mb["baudrate"]) for a, b, _ in per_tick)
            what = f"Modbus RTU at {mb['baudrate']} baud ({', '.join(n for *_, n in per_tick)}: {t * 1e3:.2f} ms/tick)"
            fld = "modbus.baudrate"
        else:
            t = mb["rtt"] * len(per_tick)
            what = f"Modbus TCP at {mb['rtt'] * 1e3:g} ms per transaction ({len(per_tick)}/tick)"
            fld = "modbus.rtt"
        out["modbus"] = {"field": fld, "max_rate_hz": 1.0 / t, "what": what}
    return out


def check_budget(cfg: RigConfig) -> None:
    """Refuse a loop rate a transport cannot carry; the error says what it can carry."""
    for info in budget(cfg).values():
        if cfg.rate_hz > info["max_rate_hz"]:
            raise BadInput("rig.rate_hz", f"{cfg.rate_hz:g} Hz is more than {info['what']} can carry: at most "
                           f"{math.floor(info['max_rate_hz'])} Hz (see {info['field']})")  # fmt: skip


# --- files -------------------------------------------------------------------------------------
def resolve(name_or_path: str) -> Path:
    p = Path(name_or_path)
    candidates = [p, Path("rigs") / f"{name_or_path}.toml", RIGS_DIR / f"{name_or_path}.toml"]
    for c in candidates:
        if c.is_file():
            return c
    known = sorted(f.stem for f in RIGS_DIR.glob("*.toml")) if RIGS_DIR.is_dir() else []
    raise BadInput("rig", f"no rig file {name_or_path!r}; give a path or one of: {allowed(known)}")


def read_toml(path: Path, kind: str) -> tuple[dict[str, Any], str]:
    """(table, text) of a TOML file; anything unreadable is `BadInput` naming the file (``kind``: "a rig
    file", "a sweep file", ... for the message)."""
    try:
        text = path.read_text(encoding="utf-8")
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise BadInput(str(path), f"not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise BadInput(str(path), f"not a text file in UTF-8 ({kind} is TOML)") from None
    except OSError as exc:
        raise BadInput(str(path), f"cannot read: {exc.strerror or exc}") from None


def load(name_or_path: str) -> RigConfig:
    path = resolve(name_or_path)
    return parse(read_toml(path, "a rig file")[0], str(path))


def write_offsets(path: str | Path, offset_i: tuple[float, float, float], offset_u: tuple[float, float, float],
                  read: Snapshot | None = None) -> dict[str, Any]:
    """Write calibrated ADC offsets into the ``[frontend]`` table of a rig file with tomlkit, which keeps
    the rest of the file (comments, layout, multi-line arrays) as it is; ``[frontend]`` is created if
    missing. The result is parsed back, then replaces the file as every rig file a command changes
    (`bench.core.rigfile_write.replace_file`: a backup, refused if the file changed since ``read``, the
    `bench.core.rigfile_write.Snapshot` the command took at its start; default: now). Returns what was written where."""
    snap = read if read is not None else Snapshot.read(path)
    doc = tomlkit.parse(snap.text)
    fe = doc.get("frontend")
    if fe is None:
        fe = tomlkit.table()
        doc["frontend"] = fe
    for key, values in (("offset_i", offset_i), ("offset_u", offset_u)):
        arr = tomlkit.array([float(f"{x:.6g}") for x in values])
        item = fe.get(key)
        fe[key] = arr
        if item is None or not getattr(item, "trivia", None) or not item.trivia.comment:
            fe[key].comment("calibrated by bench calibrate [V at the ADC]")
        else:
            fe[key].trivia.comment = item.trivia.comment  # keep the user's comment
    text = tomlkit.dumps(doc)
    parse(tomllib.loads(text), str(snap.path))  # never write a file we could not load back
    return replace_file(snap, text, field="--rig")
