"""Writing identified parameters into a rig file's ``[motor]`` table (`bench identify --write`).

``[motor]`` is the nominal model the controllers use (`bench.params.MotorParams`); the identified
L_s, L_r, L_m, R_s, R_r (the thesis' form, L_s = L_r) replace it there. ``[mock.motor]``, the mock
plant's hidden true machine, is never touched. The file is edited with tomlkit, so comments and
layout stay; the old file is copied to ``<file>.<UTC stamp>.bak`` first; the new text is parsed
back as a rig file before it replaces the old one (written to a temporary file, then renamed).

With the table of the inverter's voltage error (`bench.inverter_error`, derived from the test's DC levels)
``[inverter_error]`` is written too (replaced if there is one).

Refused (`BadInput`, nothing written) when any value's 95 % interval is wider than
`MAX_REL_CI` of the value: such a fit says more about the test than about the motor.
"""

from __future__ import annotations

import os
import shutil
import time
import tomllib
from pathlib import Path
from typing import Any

import tomlkit

from bench.errors import BadInput

MAX_REL_CI = 0.05  # widest 95 % half-width, relative, that is written
NAMES = ("L_s", "L_r", "L_m", "R_s", "R_r")
MECHANICS = ("J", "B_visc", "m_coulomb")  # written too where a rotating test measured them
CHECKED = NAMES + ("J",)  # the interval check; friction is a few % of a small torque: written as measured


def check_writable(path: Path, field: str) -> None:
    """Refuse (one line) before any test runs: a rig file that cannot be written with its backup beside it,
    or one of the rig files shipped with imbench (`bench.config.RIGS_DIR`: they are the source tree's)."""
    from bench.config import RIGS_DIR

    if path.resolve().parent == RIGS_DIR.resolve():
        raise BadInput(field, f"{path} is a rig file shipped with imbench; copy it and give the copy "
                       f"(cp {path} runs/lab.toml)")  # fmt: skip
    if not (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK)):
        raise BadInput(field, f"cannot write {path} (and its backup next to it)")


def write_motor(path: str | Path, thesis: dict[str, dict[str, Any]],
                inverter_error: dict[str, list[float]] | None = None) -> dict[str, Any]:
    """Write ``thesis`` (the ``thesis_L_s_eq_L_r`` block of an identification) into ``path``'s [motor], and
    ``inverter_error`` (``{"current": [...], "error": [...]}``) as [inverter_error] where given; returns what
    was written and where the backup is."""
    for n in (n for n in CHECKED if n in thesis):
        v = thesis[n]["value"]
        half = (thesis[n]["ci95"][1] - thesis[n]["ci95"][0]) / 2.0
        if not half <= MAX_REL_CI * abs(v):
            raise BadInput("--write", f"not written: {n} = {v:.4g} has a 95 % interval of +-{half / abs(v):.1%}, wider "
                           f"than {MAX_REL_CI:.0%}; repeat the test (larger currents, more periods)")  # fmt: skip
    p = Path(path)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    new = motor_text(p.read_text(encoding="utf-8"), thesis, stamp, str(p), inverter_error)
    backup = p.with_name(f"{p.name}.{stamp}.bak")
    shutil.copy2(p, backup)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    tmp.write_text(new, encoding="utf-8")
    os.replace(tmp, p)
    return {"rig_file": str(p), "backup": str(backup),
            "motor": {n: float(f"{thesis[n]['value']:.5g}") for n in NAMES + MECHANICS if n in thesis},
            "inverter_error": inverter_error}


def motor_text(text: str, thesis: dict[str, dict[str, Any]], stamp: str, where: str = "rig file",
               inverter_error: dict[str, list[float]] | None = None) -> str:
    """The rig file ``text`` with ``thesis``'s L_s, L_r, L_m, R_s, R_r (and J, B_visc, m_coulomb where given) in
    [motor] (5 significant digits), each
    commented with ``stamp`` and the value it replaced; parsed back as a rig file (`BadInput` if it does not load)."""
    from bench.config import parse

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
            inv.comment(f"identified by bench identify {stamp} UTC: voltage error per phase (bench.inverter_error)")
            doc["inverter_error"] = inv
        inv["current"] = tomlkit.array([float(x) for x in inverter_error["current"]])
        inv["current"].comment("[A]")
        inv["error"] = tomlkit.array([float(x) for x in inverter_error["error"]])
        inv["error"].comment(f"[V] at +current, odd; identified by bench identify {stamp} UTC")
    new = tomlkit.dumps(doc)
    parse(tomllib.loads(new), where)  # never write a file that does not load back
    return new
