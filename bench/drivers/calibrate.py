"""ADC offset calibration (`bench calibrate`): standstill, inverter disabled, average, write back.

With the inverter disabled (coasting, zero reference) and the shaft still, the true phase
currents and the filtered voltages are zero, so the mean ADC code of each channel is its offset.
The offsets are stored in the rig file's ``[frontend]`` table as volts at the ADC input
(``offset_i``, ``offset_u``), which the front-end driver subtracts from then on; the rest of the
file, comments included, is kept (bench.config.write_offsets).

Refused (BadInput, nothing written) if the shaft moves during the measurement, if the inverter
reports itself enabled, or if samples were missing or corrupt.
"""

from __future__ import annotations

from typing import Any

from bench.config import load as load_rig
from bench.config import write_offsets
from bench.errors import BadInput
from bench.hal import SAFE_COMMAND as _SAFE
from bench.hal import ST_MEAS_CRC, ST_MEAS_LOST, ST_MEAS_STALE


def calibrate(rig_name: str, samples: int = 3000, write: bool = True, seed: int = 0) -> dict[str, Any]:
    from bench.session import build_rig

    cfg = load_rig(rig_name)
    if cfg.driver != "drivers" or cfg.path is None:
        raise BadInput("rig.driver",
                       f"bench calibrate needs a driver rig file (driver = \"drivers\"), got {cfg.driver!r}")
    rig = build_rig(cfg, seed)
    fe = rig.drivers["frontend"]  # type: ignore[attr-defined]
    sums_i, sums_u = [0, 0, 0], [0, 0, 0]
    counts: set[int] = set()
    bad = 0
    rig.configure()
    rig.activate()  # activate leaves the safe state: reference 0, inverter disabled, load 0
    try:
        for k in range(samples):
            m = rig.read(k * cfg.T_s)
            rig.write(_SAFE)
            if m.inv_enabled:
                raise BadInput("calibrate", "the inverter reports itself enabled; calibration needs it disabled")
            if m.status & (ST_MEAS_STALE | ST_MEAS_CRC | ST_MEAS_LOST):
                bad += 1
                continue
            counts.add(m.enc_count)
            for j in range(3):
                sums_i[j] += m.raw_i[j]
                sums_u[j] += m.raw_u[j]
    finally:
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
    if write:
        write_offsets(cfg.path, off_i, off_u)  # type: ignore[arg-type]
    return {"rig": cfg.path, "samples": good, "offset_i": off_i, "offset_u": off_u, "written": write,
            "unit": "V at the ADC input"}  # fmt: skip

