"""Device emulators speaking the real rig's wire protocols, backed by the mock plant.

`RigEmulator` (mock_hw.emulators.rig) plays the VLT-style drive (CAN + Modbus TCP), the DC-load
drive (CAN) and the measurement front-end (serial stream); `Fault` schedules fault injection.
`start_emulator` is what ``bench run`` (autostart) and ``bench emulate`` use.
"""

from __future__ import annotations

from bench.config import RigConfig
from bench.errors import BadInput
from mock_hw.emulators.faults import KINDS, Fault, parse_faults
from mock_hw.emulators.rig import RigEmulator

__all__ = ["KINDS", "Fault", "RigEmulator", "emulator_running", "parse_faults", "start_emulator"]


def emulator_running(cfg: RigConfig) -> bool:
    """True if a `bench emulate` answers: its Modbus TCP port (or, without one, the serial
    ``socket://`` port) accepts a connection on 127.0.0.1."""
    import socket

    from mock_hw.emulators.links import LOOPBACK, parse_socket_url

    hw = cfg.hw
    if hw["modbus"]["transport"] == "tcp":
        addr = (LOOPBACK, hw["modbus"]["port"])
    else:
        try:
            addr = parse_socket_url(hw["serial"]["port"])
        except ValueError:
            return False
    if addr[1] == 0:
        return False
    try:
        with socket.create_connection(addr, timeout=0.2):
            return True
    except OSError:
        return False


def start_emulator(cfg: RigConfig, seed: int = 0, faults: list[Fault] | None = None,
                   realtime: bool = False) -> RigEmulator:  # fmt: skip
    """Start the emulators of a driver rig in this process (a background thread).

    Faults come from ``[[emulator.faults]]`` plus ``faults``. Bad settings raise `BadInput`.
    ``realtime``: the serving thread takes a real-time priority where allowed (`bench emulate`).
    """
    plan = parse_faults(cfg.hw["emulator"].get("faults", []), cfg.T_s) + list(faults or [])
    try:
        emu = RigEmulator(cfg, seed=seed, faults=plan)
    except OSError as exc:
        raise BadInput("emulator", "cannot serve the rig file's transports (can.channel, serial.port, modbus.port): "
                       f"{exc}; is another `bench emulate` running?") from None  # fmt: skip
    except ValueError as exc:
        msg = str(exc)
        field = msg.split(" ")[0] if msg.startswith("mock") else "serial.port"
        raise BadInput(field, msg) from None
    return emu.start(realtime=realtime)
