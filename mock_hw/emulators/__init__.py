"""Device emulators speaking the real rig's wire protocols, backed by the mock plant.

`RigEmulator` (mock_hw.emulators.rig) plays the VLT-style drive (CAN + Modbus TCP), the DC-load
drive (CAN) and the measurement front-end (serial stream); `Fault` schedules fault injection.
`start_emulator` is what ``bench run`` (autostart) and ``bench emulate`` use.

Which emulator (``bench run`` with ``emulator.autostart = "auto"``): `bench emulate` holds a random
secret that it never serves; it writes it, with its pid, into a file only its user can read
(`token_file`, in the runtime folder of bench.drivers.riglock). A run attaches only to an emulator that
proves it knows that secret: the run writes a random nonce into the challenge registers (Modbus TCP) and
checks the answer, HMAC-SHA256(secret, nonce), with `hmac.compare_digest`. Anything else on the rig
file's ports (another user's emulator, a program that replays what it read from ours) is refused with
one line; a file whose emulator is gone (``kill -9``) is removed where it is found.
"""

from __future__ import annotations

import hmac
import json
import os
import secrets
from pathlib import Path
from typing import Any

from bench.core.config import RigConfig
from bench.drivers.riglock import process_alive, process_start, runtime_dir
from bench.errors import BadInput
from mock_hw.emulators.faults import KINDS, Fault, parse_faults
from mock_hw.emulators.rig import (ANSWER_REGISTER, AUTH_WORDS, CHALLENGE_REGISTER, CLOCK_REGISTER, CLOCK_TICKS,
                                  CLOCK_WALL, RigEmulator, auth_answer)

__all__ = ["ANSWER_REGISTER", "CHALLENGE_REGISTER", "KINDS", "Fault", "RigEmulator", "emulator_running",
           "parse_faults", "publish_token", "remove_stale_tokens", "start_emulator", "token_file",
           "withdraw_token"]  # fmt: skip


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
    """Where `bench emulate` on ``port`` keeps its session secret and pid: the runtime folder (mode 0700,
    one fixed path per user, so a run from ssh or cron finds the emulator of a desktop terminal)."""
    return runtime_dir() / f"emulate-{port}.token"


def publish_token(emu: RigEmulator) -> Path:
    """Write the emulator's secret where this user's runs look for it (mode 0600; replaced in one rename)."""
    path = token_file(_probe_port(emu.host_config()))
    pid = os.getpid()
    tmp = path.with_name(f".{path.name}.{pid}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w") as f:
        json.dump({"pid": pid, "start": process_start(pid), "secret": emu.secret.hex()}, f)
        f.write("\n")
    os.replace(tmp, path)
    return path


def _read_token(path: Path) -> dict[str, Any] | None:
    """The token file's pid, start and secret (bytes); None if there is none or it is not one."""
    try:
        info = json.loads(path.read_text())
        return {"pid": int(info["pid"]), "start": info.get("start"), "secret": bytes.fromhex(info["secret"])}
    except (OSError, ValueError, KeyError, TypeError):
        return None


def withdraw_token(emu: RigEmulator) -> None:
    """Remove the token file, if it is still this emulator's."""
    path = token_file(_probe_port(emu.host_config()))
    info = _read_token(path)
    if info is not None and hmac.compare_digest(info["secret"], emu.secret):
        path.unlink(missing_ok=True)


def remove_stale_tokens() -> list[Path]:
    """Remove token files whose `bench emulate` is gone (killed: it could not withdraw them); the removed."""
    gone = []
    for path in runtime_dir().glob("emulate-*.token"):
        info = _read_token(path)
        if info is None or not process_alive(info["pid"], info["start"]):
            path.unlink(missing_ok=True)
            gone.append(path)
    return gone


def _proves_secret(cfg: RigConfig, secret: bytes, realtime: bool = True) -> bool:
    """True if the emulator on the rig's Modbus TCP port answers a fresh challenge under ``secret``; then it is told
    the run's clock (``realtime``: the wall clock; else the SYNC ticks of a lockstep run), which paces its
    control-word watchdog."""
    from bench.drivers.modbus import ModbusFailure, ModbusLink

    nonce = secrets.token_bytes(2 * AUTH_WORDS)
    link = ModbusLink({**cfg.hw["modbus"], "timeout": min(cfg.hw["modbus"]["timeout"], 1.0)})
    try:
        link.connect()
        link.write(CHALLENGE_REGISTER, [int.from_bytes(nonce[i:i + 2], "big") for i in range(0, len(nonce), 2)])
        words = link.read(ANSWER_REGISTER, AUTH_WORDS)
        got = b"".join((w & 0xFFFF).to_bytes(2, "big") for w in words)
        ok = hmac.compare_digest(got, auth_answer(secret, nonce))
        if ok:
            link.write(CLOCK_REGISTER, [CLOCK_WALL if realtime else CLOCK_TICKS])
    except (ModbusFailure, OSError, ValueError, BadInput):
        return False
    finally:
        link.close()
    return ok


def emulator_running(cfg: RigConfig, realtime: bool = True) -> bool:
    """True if this user's `bench emulate` answers on the rig's ports (127.0.0.1), False if nothing
    does; `BadInput` (one line) if something else answers there. ``realtime``: the run's clock, which the
    emulator's control-word watchdog follows (`_proves_secret`).

    The Modbus TCP port (or, without one, the serial ``socket://`` port) is probed. An emulator is this
    user's when the `token_file` of that port names a live `bench emulate` and, over Modbus TCP, the
    emulator answers a challenge under that file's secret (without Modbus TCP: the live pid only)."""
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
    info = _read_token(path)
    what = f"something answers on {LOOPBACK}:{port} (the rig file's ports)"
    fix = "stop it, or give the rig file ports of your own"
    if info is None:
        raise BadInput("emulator.autostart", f"{what}, but no `bench emulate` of yours: it left no session secret "
                       f"in {path}; {fix}")  # fmt: skip
    if not process_alive(info["pid"], info["start"]):
        path.unlink(missing_ok=True)
        raise BadInput("emulator.autostart", f"{what}, but the `bench emulate` of {path} (pid {info['pid']}) is gone "
                       f"(file removed): not yours; {fix}")  # fmt: skip
    if cfg.hw["modbus"]["transport"] == "tcp" and not _proves_secret(cfg, info["secret"], realtime):
        raise BadInput("emulator.autostart", f"{what}, but it does not prove it knows the session secret of {path} "
                       f"(another user's emulator, or a program posing as yours); {fix}")  # fmt: skip
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
