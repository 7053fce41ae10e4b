"""Writing identified parameters into a rig file's ``[motor]`` table (`bench identify --write`).

``[motor]`` is the nominal model the controllers use (`bench.params.MotorParams`); the identified
L_s, L_r, L_m, R_s, R_r (the thesis' form, L_s = L_r) replace it there. ``[mock.motor]``, the mock
plant's hidden true machine, is never touched. The file is edited with tomlkit, so comments and
layout stay; the new text is parsed back as a rig file before anything is written.

With the table of the inverter's voltage error (`bench.core.inverter_error`, derived from the test's DC levels)
``[inverter_error]`` is written too (replaced if there is one).

Refused (`BadInput`, nothing written) when any value's 95 % interval is wider than
`MAX_REL_CI` of the value: such a fit says more about the test than about the motor.

The file is replaced as every rig file a command changes is (`bench.core.rigfile_write.replace_file`: read
once at the start, refused if it changed since, locked, written beside it and renamed over it, a backup,
signals deferred around the commit point, written through a symbolic link).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import tomlkit

from bench.errors import BadInput
from bench.core.rigfile_write import Snapshot, replace_file, utc_stamp
from bench.core.config import parse

MAX_REL_CI = 0.05  # widest 95 % half-width, relative, that is written
NAMES = ("L_s", "L_r", "L_m", "R_s", "R_r")
MECHANICS = ("J", "B_visc", "m_coulomb")  # written too where a rotating test measured them
CHECKED = NAMES + ("J",)  # the interval check; friction is a few % of a small torque: written as measured


def write_motor(path: str | Path, thesis: dict[str, dict[str, Any]],
                inverter_error: dict[str, list[float]] | None = None,
                read: Snapshot | None = None) -> dict[str, Any]:  # fmt: skip
    """Write ``thesis`` (the ``thesis_L_s_eq_L_r`` block of an identification) into ``path``'s [motor], and
    ``inverter_error`` (``{"current": [...], "error": [...]}``) as [inverter_error] where given (`replace_file`);
    ``read``: the file as the run read it when it started (default: now). Returns what was written and where
    the backup is."""
    wide = wide_intervals(thesis)
    if wide:
        raise BadInput("--write", f"not written: {wide[0]}; repeat the test (larger currents, more periods)")
    snap = read if read is not None else Snapshot.read(path)
    stamp = utc_stamp()
    new = motor_text(snap.text, thesis, stamp, str(snap.path), inverter_error)
    out = replace_file(snap, new, stamp)
    return {**out, "motor": {n: float(f"{thesis[n]['value']:.5g}") for n in NAMES + MECHANICS if n in thesis},
            "inverter_error": inverter_error}


def wide_interval(name: str, x: dict[str, Any]) -> str | None:
    """One line if ``x``'s ({"value", "ci95"}) 95 % interval is wider than `MAX_REL_CI` of its value (such a value
    is not written), else None."""
    v, (lo, hi) = x["value"], x["ci95"]
    half = (hi - lo) / 2.0
    if half <= MAX_REL_CI * abs(v):
        return None
    rel = f"+-{half:.3g}"
    if v:  # relative, with the digits that show it above the limit
        r = half / abs(v)
        rel = f"+-{r:.{2 if round(r, 4) > MAX_REL_CI else 3}%}"
    return f"{name} = {v:.4g} has a 95 % interval of {rel} ({lo:.4g} to {hi:.4g}), wider than {MAX_REL_CI:.0%}"


def wide_intervals(motor: dict[str, dict[str, Any]]) -> list[str]:
    """`wide_interval` of each value of ``motor`` (the [motor] form) that `write_motor` checks (`CHECKED`)."""
    return [w for w in (wide_interval(n, motor[n]) for n in CHECKED if n in motor) if w]


def motor_text(text: str, thesis: dict[str, dict[str, Any]], stamp: str, where: str = "rig file",
               inverter_error: dict[str, list[float]] | None = None) -> str:
    """The rig file ``text`` with ``thesis``'s L_s, L_r, L_m, R_s, R_r (and J, B_visc, m_coulomb where given) in
    [motor] (5 significant digits), each
    commented with ``stamp`` and the value it replaced; parsed back as a rig file (`BadInput` if it does not load)."""
    doc = tomlkit.parse(text)
    motor = doc.get("motor")
    if motor is None:
        motor = tomlkit.table()
        doc["motor"] = motor
    for n in (n for n in NAMES + MECHANICS if n in thesis):
        old = motor.get(n)
        motor[n] = float(f"{thesis[n]['value']:.5g}")
        was = f", was {old}" if old is not None else ""
        how = "rotating test" if n in MECHANICS else "L_s = L_r assumed"
        motor[n].comment(f"identified by bench identify {stamp} UTC ({how}){was}")
    if inverter_error is not None:
        inv = doc.get("inverter_error")
        if inv is None:
            inv = tomlkit.table()
            inv.comment(f"identified by bench identify {stamp} UTC: voltage error per phase "
                        "(bench.core.inverter_error)")
            doc["inverter_error"] = inv
        inv["current"] = tomlkit.array([float(x) for x in inverter_error["current"]])
        inv["current"].comment("[A]")
        inv["error"] = tomlkit.array([float(x) for x in inverter_error["error"]])
        inv["error"].comment(f"[V] at +current, odd; identified by bench identify {stamp} UTC")
    new = tomlkit.dumps(doc)
    parse(tomllib.loads(new), where)  # never write a file that does not load back
    return new
