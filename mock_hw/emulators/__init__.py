"""Device emulators speaking the real rig's wire protocols, backed by the mock plant.

`RigEmulator` (mock_hw.emulators.rig) plays the VLT-style drive (CAN + Modbus TCP), the DC-load
drive (CAN) and the measurement front-end (serial stream); `Fault` schedules fault injection.
`start_emulator` is what ``bench run`` (autostart) and ``bench emulate`` use.

Session token: `bench emulate` serves a random 64-bit token in four holding registers
(`TOKEN_REGISTER`, Modbus TCP) and writes it into a file only its user can read (`token_file`,
~/.cache/imbench/emulate-PORT.token).
``bench run`` with ``emulator.autostart = "auto"`` attaches to an emulator only if it answers with
the token of that file: an emulator of another user (or any other program) on the rig file's ports
is refused with one line instead of driven.
"""

from __future__ import annotations

import os
from pathlib import Path

from bench.config import RigConfig
from bench.errors import BadInput
from mock_hw.emulators.faults import KINDS, Fault, parse_faults
from mock_hw.emulators.rig import TOKEN_REGISTER, RigEmulator

__all__ = ["KINDS", "TOKEN_REGISTER", "Fault", "RigEmulator", "emulator_running", "parse_faults", "publish_token",
           "start_emulator", "token_file", "withdraw_token"]  # fmt: skip


def _probe_port(cfg: RigConfig) -> int:
    """The port that tells whether a `bench emulate` runs: Modbus TCP, or else the serial socket (0: none)."""
    from mock_hw.emulators.links import parse_socket_url

    hw = cfg.hw
    if hw["modbus"]["transport"] == "tcp":
        return int(hw["modbus"]["port"])
    try:
        return parse_socket_url(hw["serial"]["port"])[1]
    except ValueError:
        return 0


def token_file(port: int) -> Path:
    """Where `bench emulate` on ``port`` keeps its session token: ~/.cache/imbench, readable by the
    user only (the home folder, not $XDG_RUNTIME_DIR: a run from an ssh session or cron must find the
    token of an emulator started in a desktop terminal)."""
    return Path.home() / ".cache" / "imbench" / f"emulate-{port}.token"


def publish_token(emu: RigEmulator) -> Path:
    """Write the emulator's token where this user's runs look for it (mode 0600, folder 0700)."""
    path = token_file(_probe_port(emu.host_config()))
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(emu.token.hex() + "\n")
    return path


def withdraw_token(emu: RigEmulator) -> None:
    """Remove the token file, if it is still this emulator's."""
    path = token_file(_probe_port(emu.host_config()))
    try:
        if path.read_text().strip() == emu.token.hex():
            path.unlink()
    except OSError:
        pass


def _served_token(cfg: RigConfig) -> str | None:
    """The token the emulator on the rig's Modbus TCP port serves (None: it does not answer for it)."""
    from bench.drivers.modbus import ModbusFailure, ModbusLink

    link = ModbusLink({**cfg.hw["modbus"], "timeout": min(cfg.hw["modbus"]["timeout"], 1.0)})
    try:
        link.connect()
        words = link.read(TOKEN_REGISTER, 4)
        return b"".join(w.to_bytes(2, "big") for w in words).hex()
    except (ModbusFailure, OSError, ValueError, BadInput):
        return None
    finally:
        link.close()


def emulator_running(cfg: RigConfig) -> bool:
    """True if this user's `bench emulate` answers on the rig's ports (127.0.0.1), False if nothing
    does; `BadInput` (one line) if something else answers there: another user's emulator or program.

    The Modbus TCP port (or, without one, the serial ``socket://`` port) is probed; an emulator is
    this user's when it serves the session token of `token_file` (Modbus TCP) - or, on a rig
    without Modbus TCP, when that file exists."""
    import socket

    from mock_hw.emulators.links import LOOPBACK

    port = _probe_port(cfg)
    if port == 0:
        return False
    try:
        with socket.create_connection((LOOPBACK, port), timeout=0.2):
            pass
    except OSError:
        return False
    path = token_file(port)
    try:
        want = path.read_text().strip()
    except OSError:
        want = None
    what = f"something answers on {LOOPBACK}:{port} (the rig file's ports)"
    fix = "stop it, or give the rig file ports of your own"
    if want is None:
        raise BadInput("emulator.autostart", f"{what}, but no `bench emulate` of yours: it left no session token "
                       f"in {path}; {fix}")  # fmt: skip
    if cfg.hw["modbus"]["transport"] == "tcp" and _served_token(cfg) != want:
        raise BadInput("emulator.autostart", f"{what}, but not the `bench emulate` whose session token is in {path} "
                       f"(another user's emulator, or one started since); {fix}")  # fmt: skip
    return True


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
