"""Faults injected on purpose, to test the trip paths (``bench run --inject-fault NAME``): mock and emulated rigs only.

Every set-point stays inside the rig's margins, the scenario's own profile included (`bench.core.setpoints`,
`bench.core.scenarios.check_profile`), so a run can no longer send the motor over speed by its references. A test of
the over-speed trip injects the fault instead, by name:

* ``over-speed``: the supervisor's over-speed trip (``limits.omega_max``) is lowered, for this run only, to half
  the largest speed reference the scenario commands in the run (`bench.core.scenarios.peaks`). The motor crosses it as
  it follows its reference, and the run trips through the one shutdown path (safe command, log, summary, exit 1)
  as on a real over-speed. The margins are the rig's own (checked before the fault is injected), so nothing is
  commanded that the rig file would not allow.

A fault is refused (one line, exit 2) on a rig with real devices (`bench.core.config.is_real_rig`): real hardware
is never a test object of this kind. The summary records what was injected (``fault_injection``), and the run
says so on stderr before it starts.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from bench.errors import BadInput, allowed
from bench.core.scenarios import peaks
from bench.core.setpoints import SPEED
from bench.core.config import is_real_rig

if TYPE_CHECKING:
    from bench.core.config import RigConfig
    from bench.core.scenarios import Scenario

FAULTS = {
    "over-speed": "the over-speed trip lowered to half the scenario's largest speed reference in the run",
}
OVER_SPEED_FRACTION = 0.5  # the trip, as a fraction of the largest speed reference


def check(cfg: RigConfig, fault: str, field: str = "--inject-fault") -> None:
    """`BadInput` for an unknown fault, or any fault on a rig with real devices."""
    if fault not in FAULTS:
        raise BadInput(field, f"unknown fault {fault!r}; allowed: {allowed(FAULTS)}")

    if is_real_rig(cfg):
        raise BadInput(field, f"faults are injected on mock and emulated rigs only; rig {cfg.name!r} drives real "
                       "devices (emulator.autostart = \"never\")")  # fmt: skip


def inject(cfg: RigConfig, fault: str, scn: Scenario, duration: float | None = None,
           field: str = "--inject-fault") -> tuple[RigConfig, dict[str, Any]]:  # fmt: skip
    """(the rig of the run with ``fault`` injected, what was injected) for ``scn`` run for ``duration`` (default: its
    own); `BadInput` as `check` says, or when the scenario gives the fault nothing to act on."""

    check(cfg, fault, field)
    lim = cfg.limits
    peak = peaks(scn, lim.omega_max, duration)[SPEED]
    if peak.value <= 0.0:
        raise BadInput(field, f"{fault}: scenario {scn.name!r} commands no speed in the run: nothing to cross")
    level = OVER_SPEED_FRACTION * peak.value
    record = {"fault": fault, "what": FAULTS[fault], "omega_max": level, "rig_omega_max": lim.omega_max,
              "peak_speed_ref": peak.value}  # fmt: skip
    return dataclasses.replace(cfg, limits=dataclasses.replace(lim, omega_max=level)), record


def describe(record: dict[str, Any]) -> str:
    """The line a run says on stderr before it starts."""
    return (f"fault injection: {record['fault']}: the over-speed trip lowered from {record['rig_omega_max']:g} to "
            f"{record['omega_max']:g} rad/s for this run (half its largest speed reference); it is meant to trip")
