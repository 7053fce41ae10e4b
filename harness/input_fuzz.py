"""Bad-input fuzzing: mutated rig files and command lines end in one line and exit code 2.

Every case is a mutation with a known verdict: a value no field can take (1e308, -1e308, inf, nan,
an integer of 400 digits, a value of another type; a denormal 5e-324 where the quantity must be
positive), an unknown table or field, an unknown name where a name is expected, an output path
that cannot name a file ('' or a 300-byte name), an address this machine does not have, devices
that do not answer; set-points just over the rig's margins (bench.core.setpoints) as scenario arguments and
in sweep files; scenarios whose own profile leaves a rig's margins (speed, load, flux reference: `bench run`
and sweeps) and faults injected where they may not be; `bench identify`/`bench commission` parameters that are
malformed, unknown, unused, non-finite or subnormal, ``-r`` without ``--rotating``, and a report folder that
cannot be made; `bench calibrate` with bad options, rig files it may not or cannot write, and devices that do
not answer. The harness counts, per case, one of

* ``clean``: refused with exactly one line ``bench: error: <field>: ...`` and exit code 2;
* ``traceback``: any other exception, an internal error (exit 3) or a traceback on stderr;
* ``hang``: no answer within 20 s;
* ``wrong_success``: the input was accepted (exit 0, or a rig file that loads);
* ``other``: refused, but not in one line with exit 2;
* ``left_files``: refused cleanly, but a file or folder was left behind (a refused run creates nothing).

``python3 -m harness.input_fuzz [--cases N] [--seed S]`` prints the counts as JSON (docs/RESULTS.md
section 7); tests/test_input_fuzz.py runs a small sample with hypothesis choosing the mutations.
Rig files are checked in-process through `bench.core.config.load` (fast); command lines through
`bench.cli.main` in-process (a refused run stops before any device or file is opened).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import random
import signal
import tempfile
import tomllib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import tomlkit

from bench.core.supervisor import LIMIT_RANGES
from bench.errors import BadInput
from bench.params import MotorParams
from bench.controllers import available
from mock_hw.emulators.testing import emulated_data
from bench.core.config import load

ROOT = Path(__file__).resolve().parents[1]
RIG_FILES = ("mock", "emulated", "lab-example", "mock-hot-rotor")
ABSURD_NUMBERS = (1e308, -1e308, math.inf, -math.inf, math.nan, 10**400)
DENORMAL = 5e-324  # > 0, yet zero to every equation: absurd where a quantity must be positive
OTHER_TYPES: tuple[Any, ...] = ("text", True, [1, 2, 3], {"x": 1})
LONG_NAME = "a" * 300  # no file system takes a name this long (NAME_MAX 255)


@dataclass
class Case:
    kind: str  # "rig" | "cli"
    what: str  # description
    payload: Any  # rig-file dict, or argv list
    files: dict[str, str] | None = None  # cli: files written into the working folder first
    links: dict[str, str] | None = None  # cli: symbolic links made there (name -> target)


def positive_field(path: tuple[str, ...]) -> bool:
    """A rig field that holds a positive physical quantity (a limit, a machine constant)."""
    return (path[0] == "limits" and path[-1] in LIMIT_RANGES) or (path[-2:-1] == ("motor",)
                                                                     and path[-1] in MotorParams.RANGES)


def _never_rig() -> str:
    """rigs/emulated.toml with real devices (autostart never) on ports nothing serves (1, 2, 3)."""
    data = tomllib.loads((ROOT / "rigs" / "emulated.toml").read_text())
    data["emulator"]["autostart"] = "never"
    data["can"]["channel"], data["serial"]["port"], data["modbus"]["port"] = "127.0.0.1:1", "socket://127.0.0.1:2", 3
    return tomlkit.dumps(data)


def _leaves(data: dict[str, Any], prefix: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], Any]]:
    out = []
    for k, v in data.items():
        if isinstance(v, dict):
            out += _leaves(v, (*prefix, k))
        elif not (isinstance(v, list) and v and isinstance(v[0], dict)):
            out.append(((*prefix, k), v))
    return out


def _set(data: dict[str, Any], path: tuple[str, ...], value: Any) -> dict[str, Any]:
    out = json.loads(json.dumps(data))  # deep copy of plain TOML data
    t = out
    for k in path[:-1]:
        t = t[k]
    t[path[-1]] = value
    return out


def absurd_for(value: Any) -> list[Any]:
    """Values no field holding ``value`` may accept."""
    if isinstance(value, bool):
        return [1e308, "text", [1, 2, 3]]
    if isinstance(value, (int, float)) or (isinstance(value, list) and value and isinstance(value[0], (int, float))):
        return [*ABSURD_NUMBERS, "text", {"x": 1}]
    if isinstance(value, str):
        return [1e308, True, [1, 2, 3], {"x": 1}]
    return [1e308]


def rig_cases(rng: random.Random, n: int) -> list[Case]:
    bases = {name: tomllib.loads((ROOT / "rigs" / f"{name}.toml").read_text()) for name in RIG_FILES}
    pool: list[Case] = []
    for name, data in bases.items():
        for path, value in _leaves(data):
            bads = absurd_for(value) + ([DENORMAL] if positive_field(path) else [])
            for bad in bads:
                shown = f"<{len(str(bad))} digits>" if isinstance(bad, int) and bad > 1e300 else repr(bad)
                pool.append(Case("rig", f"{name}: {'.'.join(path)} = {shown}", _set(data, path, bad)))
        for table in data:
            if isinstance(data[table], dict):
                pool.append(Case("rig", f"{name}: unknown field {table}.bogus", _set(data, (table, "bogus"), 1.0)))
        pool.append(Case("rig", f"{name}: unknown table", {**data, "bogus": {"x": 1}}))
        pool.append(Case("rig", f"{name}: no [rig] table", {k: v for k, v in data.items() if k != "rig"}))
    rng.shuffle(pool)
    return pool[:n]


def cli_cases(rng: random.Random, n: int) -> list[Case]:
    pool: list[Case] = []
    for ctrl, cls in available().items():
        for key, spec in cls.schema.items():
            for bad in absurd_for(spec.default):
                value = tomlkit.item(bad).as_string() if not isinstance(bad, dict) else "{x=1}"
                shown = value if len(value) < 30 else f"<{len(value)} digits>"
                pool.append(Case("cli", f"{ctrl} -p {key}={shown}", ["run", "--controller", ctrl, "-p", f"{key}={value}",
                                                                     "--no-progress"]))  # fmt: skip
        pool.append(Case("cli", f"{ctrl} -p bogus=1", ["run", "--controller", ctrl, "-p", "bogus=1", "--no-progress"]))
    for d in ("1e-9", "0", "-1", "inf", "nan", "1e308", "abc", ""):
        pool.append(Case("cli", f"--duration {d}", ["run", "--duration", d, "--no-progress"]))
    for opt, val in (("--seed", "x"), ("--seed", "1.5"), ("--scenario", "nope"), ("--controller", "nope"),
                     ("--rig", "nope"), ("--log-buffer", "0"), ("--log-buffer", "nan"), ("--bogus", "1"),
                     ("-p", "novalue"), ("-p", "a=1\nb=2"), ("-p", "=3")):  # fmt: skip
        pool.append(Case("cli", f"{opt} {val!r}", ["run", opt, val, "--no-progress"]))
    for scn, arg in (("load-step", "spede=1"), ("load-step", "speed=nan"), ("load-step", "speed="),
                     ("load-step", "load=1e999"), ("demo", "speed=1"),
                     *(("load-step", a) for a in OVER_MARGINS)):  # fmt: skip
        pool.append(Case("cli", f"--scenario {scn} --scenario-arg {arg}",
                         ["run", "--scenario", scn, "--scenario-arg", arg, "--no-progress"]))  # fmt: skip
    pool += sweep_margin_cases() + identify_cases() + profile_cases() + calibrate_cases()
    for opt in ("--log", "--summary", "--plot", "--can-log"):  # paths that cannot name a file
        for val in ("", f"{LONG_NAME}.x", f"sub/{LONG_NAME}/x.y"):
            pool.append(Case("cli", f"{opt} {val[:12]!r}...", ["run", opt, val, "--no-progress"]))
    pool.append(Case("cli", "--live-host 1.2.3.4 --live-port 0", ["run", "--live", "--live-host", "1.2.3.4",
                                                                  "--live-port", "0", "--no-progress"]))  # fmt: skip
    pool.append(Case("cli", "devices that do not answer", ["run", "--rig", "never.toml", "--allow-soft-realtime",
                                                           "--no-progress"], {"never.toml": _never_rig()}))  # fmt: skip
    smoke = (ROOT / "sweeps" / "smoke.toml").read_text().split("[design.axes]")[0]
    axis = ", ".join(str(1 + i / 10000) for i in range(1000))
    pool.append(Case("cli", "sweep of a million cases", ["sweep", "big.toml", "--out", "out", "--no-progress"],
                     {"big.toml": f'{smoke}[design.axes]\n"plant.R_r" = [{axis}]\n"plant.R_s" = [{axis}]\n'}))
    for val in ("nan", "inf", "-inf", "9" * 400):  # refused by the client: the protocol cannot carry them
        pool.append(Case("cli", f"set speed_Kp={val[:5]}", ["set", f"speed_Kp={val}", "--port", "1"]))
    for cmd in (["synth", "flux-observer", "--omega-max", "1e308"], ["synth", "current-controller", "--rate", "nan"],
                ["collect", "narx", "--out", "/dev/null/x.mcap", "--samples", "100"], ["perf", "loop", "--duration", "0"],
                ["tune", "speed", "--amplitude", "-1"], ["plot", "/nonexistent.mcap"], ["inspect", "/"],
                ["controllers", "nope"], ["reproduce", "nope"]):  # fmt: skip
        pool.append(Case("cli", " ".join(cmd), cmd))
    rng.shuffle(pool)
    return pool[:n]


# set-points just over the mock rig's margins (0.8 x 400 rad/s, 0.8 x 15 N m), absurd, and subnormal
OVER_MARGINS = ("speed=320.001", "speed=-320.001", "speed=400", "speed=-400", "speed=1e308", "speed=-1e9",
                "load=12.001", "load=-12.001", "load=20", "load=-20", "speed=1e-320", "load=-5e-324")  # fmt: skip


def sweep_margin_cases() -> list[Case]:
    """Sweep files whose scenario values, axes or ranges (or, on a slower rig, the arguments' defaults) leave the
    rig's set-point margins: refused before any case runs, the results folder never made."""
    head = '[sweep]\nscenarios = ["load-step"]\n'
    specs = {f"[scenario] {k} = {v}": f"{head}[scenario]\n{k} = {v}\n"
             for k, v in (("speed", "1e308"), ("speed", "-1e9"), ("speed", "400.0"), ("speed", "-400.0"),
                          ("load", "20.0"), ("load", "-20.0"), ("speed", "1e-320"))}  # fmt: skip
    for k, vals in (("speed", "[50.0, 400.0]"), ("speed", "[-1e9, 50.0]"), ("load", "[3.0, -20.0]")):
        specs[f"axis scenario.{k} = {vals}"] = f'{head}[design.axes]\n"scenario.{k}" = {vals}\n'
    for k, lohi in (("speed", "[0.0, 1e308]"), ("load", "[-20.0, 3.0]")):
        specs[f"range scenario.{k} = {lohi}"] = (f'{head}[design]\nkind = "lhs"\nsamples = 3\n[design.ranges]\n'
                                                 f'"scenario.{k}" = {lohi}\n')  # fmt: skip
    slow = (ROOT / "rigs" / "mock.toml").read_text().replace("omega_max = 400.0", "omega_max = 60.0")
    pool = [Case("cli", f"sweep {what}", ["sweep", "s.toml", "--out", "out", "--no-progress"], {"s.toml": text})
            for what, text in specs.items()]  # fmt: skip
    slow_spec = head.replace("[sweep]\n", '[sweep]\nrig = "slow.toml"\n')  # load-step's 50 rad/s > 0.8 x 60
    pool.append(Case("cli", "sweep load-step's default speed on a 60 rad/s rig",
                     ["sweep", "s.toml", "--out", "out", "--no-progress"], {"slow.toml": slow, "s.toml": slow_spec}))
    return pool


def _mock_rig(**changes: str) -> str:
    """rigs/mock.toml with ``[limits]`` values changed (``omega_max="300.0"``) and a ``[mock.load]`` torque limit
    (``torque_limit="5.0"``)."""
    text = (ROOT / "rigs" / "mock.toml").read_text()
    for key, value in changes.items():
        if key == "torque_limit":
            text += f"\n[mock.load]\ntorque_limit = {value}\n"
            continue
        old = next(line for line in text.splitlines() if line.startswith(f"{key} ="))
        text = text.replace(old, f"{key} = {value}", 1)
    return text


def profile_cases() -> list[Case]:
    """Scenarios whose own profile leaves the rig's margins (0.8 of omega_max, of the load's torque limit, of I_max),
    on `bench run` and in sweeps, and faults injected where they may not be: refused before anything runs."""
    rigs = {"r300.toml": _mock_rig(omega_max="300.0"),  # margin 240 rad/s: Fig. 6.14's 250
            "r240.toml": _mock_rig(omega_max="240.0"),  # 192: 6.4.1's 200
            "r180.toml": _mock_rig(omega_max="180.0"),  # 144: Fig. 5.8's 150
            "t5.toml": _mock_rig(torque_limit="5.0"),  # 4 N m: Fig. 4.11's 7, the warm-up's 7, hold's 10
            "i3.toml": _mock_rig(I_max="3.0")}  # 2.4 A: every scenario's flux reference (2.5, 2.8)
    pairs = [("r300.toml", "fig6.14"), ("r300.toml", "fig6.14-ab"), ("r240.toml", "load6.4.1"),
             ("r240.toml", "hold"), ("r180.toml", "fig5.8"), ("r180.toml", "fig4.9"), ("t5.toml", "fig4.11"),
             ("t5.toml", "warmup"), ("t5.toml", "hold"), ("t5.toml", "fig5.11"), ("i3.toml", "demo"),
             ("i3.toml", "fig6.14"), (str(ROOT / "rigs" / "lab-example.toml"), "hold")]  # fmt: skip
    pool = [Case("cli", f"run --rig {Path(rig).name} --scenario {scn}", ["run", "--rig", rig, "--scenario", scn,
                                                                         "--no-progress"], rigs)
            for rig, scn in pairs]  # fmt: skip
    for rig, scn, args in (("mock", "hold", ["speed=320.5"]), ("mock", "hold", ["load=12.5"]),
                           ("mock", "hold", ["speed=-1e308"]), ("t5.toml", "hold", ["load=4.5"]),
                           (str(ROOT / "rigs" / "lab-example.toml"), "hold", ["speed=281"]),
                           ("i3.toml", "load-step", ["speed=10"])):  # fmt: skip
        argv = ["run", "--rig", rig, "--scenario", scn, *(x for a in args for x in ("--scenario-arg", a)),
                "--no-progress"]  # fmt: skip
        pool.append(Case("cli", f"run --rig {Path(rig).name} --scenario {scn} {' '.join(args)}", argv, rigs))
    for rig, scn in (("r300.toml", "fig6.14"), ("t5.toml", "fig4.11"), ("i3.toml", "fig5.8")):
        spec = f'[sweep]\nrig = "{rig}"\nscenarios = ["fig5.7", "{scn}"]\nseeds = [1, 2]\n'
        pool.append(Case("cli", f"sweep {scn} on {rig}", ["sweep", "s.toml", "--out", "out", "--no-progress"],
                         {**rigs, "s.toml": spec}))  # fmt: skip
    for extra, what in ((["--rig", str(ROOT / "rigs" / "lab-example.toml")], "on a rig with real devices"),
                        (["--scenario", "relay0"], "with no speed to cross"),
                        ([], "unknown"), (["--rig", "r300.toml", "--scenario", "fig6.14"], "outside the margins")):
        fault = "bogus" if what == "unknown" else "over-speed"
        pool.append(Case("cli", f"--inject-fault {fault} {what}", ["run", *extra, "--inject-fault", fault,
                                                                   "--no-progress"], rigs))  # fmt: skip
    return pool


def calibrate_cases() -> list[Case]:
    """`bench calibrate` refused before it measures (bad options, rig files it may not or cannot write), or as soon
    as its devices do not answer: one line, exit 2, the rig file as it was and nothing beside it."""
    emu = tomlkit.dumps(emulated_data("virtual"))
    files = {"emu.toml": emu, "never.toml": _never_rig(), "mock.toml": (ROOT / "rigs" / "mock.toml").read_text(),
             "empty.toml": "", "notoml.toml": "[rig\n"}  # fmt: skip
    links = {"link.toml": str(ROOT / "rigs" / "emulated.toml")}
    pool = []
    for argv, what in (([], "no --rig"), (["--rig", "nope"], "an unknown rig"), (["--rig", ""], "an empty --rig"),
                       (["--rig", "mock"], "the mock rig"), (["--rig", "mock.toml"], "a mock rig file"),
                       (["--rig", "emulated"], "a shipped rig file"),
                       (["--rig", str(ROOT / "rigs" / "lab-example.toml")], "the shipped lab example"),
                       (["--rig", "/proc/self/x"], "/proc/self/x"), (["--rig", "/"], "a folder"),
                       (["--rig", "empty.toml"], "an empty file"), (["--rig", "notoml.toml"], "not TOML"),
                       (["--rig", "never.toml"], "devices that do not answer"),
                       (["--rig", "never.toml", "--dry-run"], "devices that do not answer, --dry-run"),
                       (["--rig", "link.toml"], "a link to a shipped rig file"),
                       *((["--rig", "emu.toml", "--samples", v], f"--samples {v[:12]}")
                         for v in ("0", "9", "-1", "abc", "nan", "1e3", "1000001", "9" * 400, "")),
                       (["--rig", "emu.toml", "--bogus"], "an unknown option"),
                       (["--rig", "emu.toml", "--dry-run", "--dry-run=1"], "a flag with a value")):  # fmt: skip
        pool.append(Case("cli", f"calibrate {what}", ["calibrate", *argv], files, links))
    return pool


def identify_cases() -> list[Case]:
    """`bench identify` and `bench commission` (mock rig, nothing written: --dry-run) refused before any test runs."""
    bad_p = ("dc_current=abc", "=", "==1", "=1=2", "dc_current=" + "9" * 400, "dc_current=nan", "dc_current=1e-320",
             "ac_bias=-5e-324", "lpv_speed_artifact=/etc/passwd", "bogus=1", "voltages=reference")  # fmt: skip
    bad_r = ("bogus=1", "lpv_speed_artifact=/etc/passwd", "omega_test=1e-320", "omega_test=300", "flux_lo=1.3",
             "model_R_s=3", "=1", "omega_test=inf")  # fmt: skip
    pool = []
    for cmd in (["identify", "--rig", "mock"], ["commission", "--rig", "mock", "--dry-run", "--out", "report"]):
        for p in bad_p:
            pool.append(Case("cli", f"{cmd[0]} -p {p[:30]}", [*cmd, "-p", p]))
        for r in bad_r:
            pool.append(Case("cli", f"{cmd[0]} --rotating -r {r}", [*cmd, "--rotating", "-r", r]))
        # (bench commission runs the rotating test on the mock by default: -r is refused once it is switched off)
        off = ["--standstill-only"] if cmd[0] == "commission" else []
        pool.append(Case("cli", f"{cmd[0]} -r without --rotating", [*cmd, *off, "-r", "omega_test=100"]))
    pool.append(Case("cli", "identify --from-log -r", ["identify", "--from-log", "x.mcap", "-r", "omega_test=100"]))
    pool.append(Case("cli", "commission --out /proc/self/x", ["commission", "--rig", "mock", "--dry-run", "--out",
                                                              "/proc/self/x"]))  # fmt: skip
    return pool


class _Hang(Exception):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise _Hang()


def run_case(case: Case, work: Path, timeout: int = 20) -> str:
    """Outcome of one case: clean | traceback | hang | wrong_success | other."""
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(timeout)
    try:
        if case.kind == "rig":
            f = work / "case.toml"
            f.write_text(tomlkit.dumps(case.payload))
            try:
                load(str(f))
            except BadInput as exc:
                return "clean" if "\n" not in str(exc) else "other"
            return "wrong_success"
        from bench.cli import main

        for name, text in (case.files or {}).items():
            (work / name).write_text(text)
        for name, target in (case.links or {}).items():
            (work / name).unlink(missing_ok=True)
            (work / name).symlink_to(target)
        before = {p for p in work.rglob("*")}
        err = io.StringIO()
        code: Any = 0
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), contextlib.chdir(work):
            try:
                main(list(case.payload))
            except SystemExit as exc:
                code = exc.code
        left = {p for p in work.rglob("*")} - before
        lines = err.getvalue().strip().splitlines()
        if code == 3 or "Traceback" in err.getvalue():
            return "traceback"
        if code == 0:
            return "wrong_success"
        if not (code == 2 and len(lines) == 1 and lines[0].startswith("bench: error:")):
            return "other"
        return "left_files" if left else "clean"
    except _Hang:
        return "hang"
    except Exception:  # noqa: BLE001 - escaped the one-line error path
        return "traceback"
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def run(n_rig: int, n_cli: int, seed: int = 0) -> dict[str, Any]:
    rng = random.Random(seed)
    cases = rig_cases(rng, n_rig) + cli_cases(rng, n_cli)
    counts: Counter[str] = Counter()
    bad: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            outcome = run_case(case, Path(tmp))
            counts[outcome] += 1
            if outcome != "clean":
                bad.append(f"{outcome}: {case.kind}: {case.what}")
    return {"tried": len(cases), **{k: counts.get(k, 0) for k in ("clean", "traceback", "hang", "wrong_success",
                                                                     "other", "left_files")}, "failures": bad}  # fmt: skip


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rig-cases", type=int, default=100000, help="rig-file mutations (at most all there are)")
    ap.add_argument("--cli-cases", type=int, default=100000, help="command lines (at most all there are)")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    print(json.dumps(run(a.rig_cases, a.cli_cases, a.seed), indent=2))


if __name__ == "__main__":
    main()
