"""ADC offset calibration (`bench calibrate`): standstill, inverter disabled, average, write back.

With the inverter disabled (coasting, zero reference) and the shaft still, the true phase
currents and the filtered voltages are zero, so the mean ADC code of each channel is its offset.
The offsets are stored in the rig file's ``[frontend]`` table as volts at the ADC input
(``offset_i``, ``offset_u``), which the front-end driver subtracts from then on; the rest of the
file, comments included, is kept (bench.core.config.write_offsets). The file is read when the command starts
and replaced as every rig file a command changes (`bench.core.rigfile_write`: refused if it changed meanwhile,
a backup beside it, a symbolic link written through, and a signal before the commit point leaves it byte for
byte: exit 128 + the signal).

Refused (BadInput, nothing written) before anything is measured: a shipped rig file, one that cannot be written;
after the measurement: if the shaft moved, if the inverter reports itself enabled, or if samples were missing
or corrupt.
"""

from __future__ import annotations

from typing import Any

from bench.core.config import load as load_rig
from bench.core.config import resolve, write_offsets
from bench.errors import BadInput
from bench.hal import SAFE_COMMAND as _SAFE
from bench.hal import ST_MEAS_CRC, ST_MEAS_LOST, ST_MEAS_STALE, RigState
from bench.core.rigfile_write import Snapshot, check_writable
from bench.core.shutdown import critical_section, pause_for_test
from bench.runtime.compose import build_rig


def calibrate(rig_name: str, samples: int = 3000, write: bool = True, seed: int = 0) -> dict[str, Any]:
    """Measure the offsets of ``samples`` ticks on the driver rig ``rig_name`` (a name or a file) and, with ``write``,
    put them into its rig file (module docstring). Returns the offsets and ``written`` (where, the backup; None
    without ``write``, or when the write was refused: ``not_written`` says why in one line)."""
    path = resolve(rig_name)
    cfg = load_rig(str(path))
    if cfg.driver != "drivers" or cfg.path is None:
        raise BadInput("rig.driver",
                       f"bench calibrate needs a driver rig file (driver = \"drivers\"), got {cfg.driver!r}")
    snap = None
    if write:  # before anything is measured (--dry-run: nothing to write)
        check_writable(path, "--rig")
        snap = Snapshot.read(path)  # what is replaced: refused at the end if it changed meanwhile
    rig = build_rig(cfg, seed)
    fe = rig.drivers["frontend"]  # type: ignore[attr-defined]
    sums_i, sums_u = [0, 0, 0], [0, 0, 0]
    counts: set[int] = set()
    bad = 0
    try:
        rig.configure()
        rig.activate()  # activate leaves the safe state: reference 0, inverter disabled, load 0
        for k in range(samples):
            m = rig.read(k * cfg.T_s)
            rig.write(_SAFE)
            if k == samples // 2:
                pause_for_test("calibrate-measuring")
            if m.inv_enabled:
                raise BadInput("calibrate", "the inverter reports itself enabled; calibration needs it disabled")
            if m.status & (ST_MEAS_STALE | ST_MEAS_CRC | ST_MEAS_LOST):
                bad += 1
                continue
            counts.add(m.enc_count)
            for j in range(3):
                sums_i[j] += m.raw_i[j]
                sums_u[j] += m.raw_u[j]
    finally:  # the safe command, the devices (and an in-process emulator) closed, the rig's lock released;
        with critical_section():  # a signal arriving meanwhile is raised once that is done
            if rig.state is RigState.UNCONFIGURED:
                rig.close()  # type: ignore[attr-defined]
            else:
                rig.deactivate()
    good = samples - bad
    if bad > samples // 100 or good == 0:
        raise BadInput("calibrate", f"{bad} of {samples} samples missing or corrupt; check the front-end link")
    if len(counts) > 2:  # one count of dither at an edge is allowed
        raise BadInput("calibrate", f"the shaft moved during calibration ({len(counts)} encoder counts seen); "
                       "it must be at standstill")  # fmt: skip
    lsb = fe.lsb
    off_i = tuple(s / good * lsb for s in sums_i)
    off_u = tuple(s / good * lsb for s in sums_u)
    out = {"rig": cfg.path, "samples": good, "offset_i": off_i, "offset_u": off_u, "written": None,
           "unit": "V at the ADC input"}  # fmt: skip
    if write:
        try:
            out["written"] = write_offsets(path, off_i, off_u, read=snap)
        except BadInput as exc:  # the measurement stands; only the write is refused (the file as it was)
            out["not_written"] = str(exc)
    return out

