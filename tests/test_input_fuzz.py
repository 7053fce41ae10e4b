"""Bad input of every kind: one line, exit code 2, no traceback, never a wrong success (issue 10).

The fixed pool (harness/input_fuzz.py: every field of every shipped rig file set to values no field
can take, unknown tables and fields, every controller parameter set absurdly, bad options of every
command) runs whole in the default suite; hypothesis adds random mutations, more of them under
``-m slow``.
"""

from __future__ import annotations

import json
import math
import random
import string
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness import input_fuzz
from bench.controllers.foc import FocController
from harness.input_fuzz import Case, run_case

ROOT = Path(__file__).resolve().parents[1]
RIGS = {name: tomllib.loads((ROOT / "rigs" / f"{name}.toml").read_text()) for name in input_fuzz.RIG_FILES}
LEAVES = [(name, path, value) for name, data in RIGS.items() for path, value in input_fuzz._leaves(data)]
NUMERIC_LEAVES = [leaf for leaf in LEAVES if isinstance(leaf[2], (int, float)) and not isinstance(leaf[2], bool)]
NUMERIC_PARAMS = sorted(k for k, p in FocController.schema.items() if p.kind in ("int", "float"))


@pytest.mark.slow  # 15 s: the whole pool (python3 -m harness.input_fuzz); the property tests below sample it
def test_the_whole_pool_is_refused_in_one_line():
    res = input_fuzz.run(100_000, 100_000, seed=0)
    assert res["tried"] > 1000
    assert res["clean"] == res["tried"], res["failures"][:20]


# absurd for every numeric rig field: not finite, or beyond any physical range the files allow (<= 1e6)
ABSURD = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf]),
                   st.floats(min_value=1e7, max_value=1e308), st.floats(min_value=-1e308, max_value=-1e7),
                   st.text(alphabet=string.ascii_letters, min_size=1, max_size=12))  # fmt: skip


def _rig_case(leaf_index: int, value: object) -> str:
    name, path, _ = NUMERIC_LEAVES[leaf_index]
    return run_case(Case("rig", f"{name}: {'.'.join(path)} = {value!r}", input_fuzz._set(RIGS[name], path, value)),
                    Path(_tmp()))  # fmt: skip


_TMP_ROOT: list[Path] = []  # this module's folder under pytest's basetemp (pytest keeps the last three runs)


@pytest.fixture(scope="module", autouse=True)
def _tmp_root(tmp_path_factory):
    _TMP_ROOT[:] = [tmp_path_factory.mktemp("fuzz")]
    yield
    _TMP_ROOT.clear()


def _tmp() -> str:
    """A fresh folder per case (hypothesis runs many cases in one test, so not tmp_path), under this module's
    pytest temporary folder: nothing is left in /tmp itself."""
    return tempfile.mkdtemp(dir=_TMP_ROOT[0])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, len(NUMERIC_LEAVES) - 1), ABSURD)
def test_random_absurd_rig_values_are_refused(leaf_index, value):
    assert _rig_case(leaf_index, value) == "clean", (NUMERIC_LEAVES[leaf_index][:2], value)


@pytest.mark.slow
@settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, len(NUMERIC_LEAVES) - 1), ABSURD)
def test_random_absurd_rig_values_are_refused_long(leaf_index, value):
    assert _rig_case(leaf_index, value) == "clean", (NUMERIC_LEAVES[leaf_index][:2], value)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(NUMERIC_PARAMS), st.text(alphabet=string.ascii_letters + "_-", min_size=1, max_size=10))
def test_random_text_for_a_numeric_parameter_is_refused(name, text):
    argv = ["run", "-p", f"{name}={text}", "--no-progress"]
    assert run_case(Case("cli", " ".join(argv), argv), Path(_tmp())) == "clean", argv


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(min_size=0, max_size=2000))
def test_random_bytes_as_a_rig_file_never_give_a_traceback(blob):
    f = Path(_tmp()) / "r.toml"
    f.write_bytes(blob)
    from bench.core.config import load
    from bench.errors import BadInput

    with pytest.raises(BadInput):  # random bytes are never a valid rig file ([rig] is required)
        load(str(f))


def test_bad_input_through_real_processes_is_one_line():
    rng = random.Random(3)
    cases = input_fuzz.cli_cases(rng, 8)
    for case in cases:
        p = subprocess.run([sys.executable, "-m", "bench", *case.payload], capture_output=True, text=True,
                           cwd=_tmp(), timeout=120)  # fmt: skip
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("bench: error:"), (case.what, p.stderr)
        assert "Traceback" not in p.stderr


def test_fuzz_counts_command_prints_json():
    p = subprocess.run([sys.executable, "-m", "harness.input_fuzz", "--rig-cases", "20", "--cli-cases", "10"],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)  # fmt: skip
    res = json.loads(p.stdout)
    assert res["tried"] == 30 and res["clean"] == 30


def _pool_cases(*prefixes: str) -> list[Case]:
    return [c for c in input_fuzz.cli_cases(random.Random(0), 100_000) if c.what.startswith(prefixes)]


@pytest.mark.parametrize("case", _pool_cases("--log ", "--summary '", "--live-host", "devices that do not answer",
                                             "set speed_Kp", "foc -p speed_Kp=<",
                                             "sweep of a million"), ids=lambda c: c.what)  # fmt: skip
def test_edge_inputs_through_real_processes_are_one_line_and_leave_nothing(case, tmp_path):
    """An output path that names no file, an address this machine lacks, devices that do not
    answer, nan or a 400-digit number for a parameter: exit 2, one line, and no folder left behind
    (the run folder and runs/ are made only for a run that starts)."""
    for name, text in (case.files or {}).items():
        (tmp_path / name).write_text(text)
    before = set(tmp_path.rglob("*"))
    p = subprocess.run([sys.executable, "-m", "bench", *case.payload], capture_output=True, text=True,
                       cwd=tmp_path, timeout=120)  # fmt: skip
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("bench: error:"), (case.what, p.stderr)
    assert set(tmp_path.rglob("*")) == before, (case.what, set(tmp_path.rglob("*")) - before)


def test_set_points_over_the_margins_and_bad_identify_input_are_refused_in_one_line(tmp_path):
    """The pool's set-points over the rig's margins (scenario arguments, sweep values, axes, ranges, a default) and
    bad `bench identify`/`bench commission` input: clean, in-process, in the default suite (the whole pool: slow)."""
    pool = _pool_cases("--scenario load-step --scenario-arg", "sweep [scenario]", "sweep axis", "sweep range",
                       "sweep load-step", "identify", "commission")  # fmt: skip
    assert len(pool) >= 60
    assert [c.what for c in pool if run_case(c, tmp_path) != "clean"] == []


def test_denormals_for_positive_quantities_are_refused():
    """5e-324 > 0, yet zero to every equation: every positive limit and machine constant refuses it."""
    pool = [c for c in input_fuzz.rig_cases(random.Random(0), 100_000) if c.what.endswith("= 5e-324")]
    names = {c.what.split(": ")[1].split(" =")[0] for c in pool}
    assert {"motor.R_s", "mock.motor.R_r", "limits.max_stall", "limits.u_dc_min"} <= names
    assert [c.what for c in pool if run_case(c, Path(_tmp())) != "clean"] == []


@pytest.mark.realtime
def test_bench_set_nan_against_a_live_run_is_refused_at_once(tmp_path):
    """The live server drops a message it cannot parse (NaN is not JSON), so `bench set speed_Kp=nan` used
    to wait 3 s and exit 1; the client refuses it first (exit 2, one line), and a valid set still works."""
    run = subprocess.Popen([sys.executable, "-m", "bench", "run", "--no-progress", "--log", str(tmp_path / "r.mcap"),
                            "--realtime", "--duration", "60", "--live", "--live-port", "0"], cwd=tmp_path,
                           stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        line = run.stderr.readline()
        assert line.startswith("bench: live: ws://127.0.0.1:"), line
        port = line.split("ws://127.0.0.1:")[1].split()[0]
        for value in ("nan", "inf", "9" * 400):
            p = subprocess.run([sys.executable, "-m", "bench", "set", f"speed_Kp={value}", "--port", port],
                               capture_output=True, text=True, timeout=60)  # fmt: skip
            assert p.returncode == 2 and p.stderr.strip().splitlines() == [p.stderr.strip()], p.stderr
            assert p.stderr.startswith("bench: error: speed_Kp: must be a finite number")  # not the 3 s timeout
        ok = subprocess.run([sys.executable, "-m", "bench", "set", "speed_Kp=0.5", "--port", port],
                            capture_output=True, text=True, timeout=60)  # fmt: skip
        assert ok.returncode == 0 and "speed_Kp: 0.6 -> 0.5" in ok.stdout, ok.stderr
    finally:
        run.terminate()
        run.communicate(timeout=60)


def test_profiles_outside_the_margins_and_bad_calibrate_input_are_refused_in_one_line(tmp_path):
    """The pool's scenarios whose own profile leaves a rig's margins (bench run, sweeps, an injected fault where it
    may not be) and bad `bench calibrate` input: clean, in-process; each profile refusal names the scenario's field
    (or the fault's), and a calibrate refusal leaves the rig files as they were."""
    import contextlib
    import io

    from bench.cli import main

    profiles, calibrate = input_fuzz.profile_cases(), input_fuzz.calibrate_cases()
    assert len(profiles) >= 25 and len(calibrate) >= 20
    assert [c.what for c in profiles + calibrate if run_case(c, tmp_path) != "clean"] == []
    for c in profiles:  # the refusal is the one meant: the scenario's profile or argument, or the fault
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), contextlib.chdir(tmp_path):
            with pytest.raises(SystemExit):
                main(list(c.payload))
        line = err.getvalue().strip()
        assert line.startswith(("bench: error: scenario: '", "bench: error: scenario.", "bench: error: --inject-fault:"))
        assert " outside [" in line or "must be a number in [" in line or "--inject-fault" in line, line
    for name, text in (calibrate[0].files or {}).items():
        assert (tmp_path / name).read_text() == text, name
