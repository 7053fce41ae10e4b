"""Golden runs: today's code gives the recorded digests of five lockstep runs bit for bit, on every engine
(tests/golden, docs/golden.md). A failure names the run, the engine, the column or value and where it first differs.

The runs are checked in a child process (`python3 -m tests.golden.record --check`), which starts with the golden
numerical kernels (`tests.golden.runs`: libm, BLAS, numpy's SIMD paths): they are chosen when the libraries load,
before any test could.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.golden import digest, runs

ROOT = Path(__file__).resolve().parents[1]
FAST = ("fig5.7", "hold-switches", "warmup-mras", "atlas")  # the logged runs from their in-memory record
SLOW = ("identify-mock-real",)  # ~20 s per engine: its session writes and reads back an MCAP log four times


def release_drift() -> list[str]:
    """The numerical libraries (and Python, libc) whose release differs from the recording's. A new release may
    change last bits with no change of ours, and CI installs the newest releases pyproject.toml allows: the digests
    are then compared on the recording's releases only, and the test says it skipped and why (re-record after
    checking the difference: docs/golden.md)."""
    import platform

    from synthesis.environment import environment

    rec = json.loads(runs.path("fig5.7").read_text())["environment"]
    now = environment()
    out = [f"{k} {rec['packages'].get(k)} -> {v}" for k, v in now["packages"].items() if rec["packages"].get(k) != v]
    if rec.get("python") != now["python"]:
        out.append(f"python {rec.get('python')} -> {now['python']}")
    libc = " ".join(platform.libc_ver())
    if rec.get("libc") != libc:
        out.append(f"libc {rec.get('libc')} -> {libc}")
    return out


@pytest.fixture(scope="module")
def checked(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., dict[str, list[str]]]:
    """``checked(*args)``: the differences per run of one ``record --check`` child with ``args`` (run once)."""
    drift = release_drift()
    if drift:
        pytest.skip("golden digests were recorded with other releases (" + "; ".join(drift) + "): compared on the "
                    "recording's releases only; re-record after checking (python3 -m tests.golden.record --check)")
    done: dict[tuple[str, ...], dict[str, list[str]]] = {}

    def check(*args: str) -> dict[str, list[str]]:
        if args not in done:
            out = tmp_path_factory.mktemp("golden") / "found.json"
            p = subprocess.run([sys.executable, "-m", "tests.golden.record", "--check", "--json", str(out), *args],
                               cwd=ROOT, capture_output=True, text=True, timeout=1800)  # fmt: skip
            assert out.exists(), f"the check did not finish (exit {p.returncode}):\n{p.stdout}\n{p.stderr[-4000:]}"
            done[args] = json.loads(out.read_text())
        return done[args]

    return check


@pytest.mark.parametrize("name", FAST)
def test_a_golden_run_gives_its_recorded_digest(name: str, checked: Callable[..., dict[str, list[str]]]) -> None:
    found = checked(*FAST)[name]
    assert not found, digest.report(name, found, 40)


@pytest.mark.slow
@pytest.mark.parametrize("name", SLOW)
def test_the_identification_gives_its_recorded_digest(name: str, checked: Callable[..., dict[str, list[str]]]) -> None:
    found = checked(*SLOW)[name]
    assert not found, digest.report(name, found, 40)


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in FAST if n != "atlas"])
def test_a_golden_run_written_as_an_mcap_log_gives_its_recorded_digest(name: str, checked) -> None:  # noqa: ANN001
    """The same runs as `bench run` writes them: the log writer's process, the MCAP file read back, the plot."""
    logged = tuple(n for n in FAST if n != "atlas")
    found = checked("--mcap", *logged)[name]
    assert not found, digest.report(name, found, 40)


def test_every_run_is_recorded_small_and_from_a_commit() -> None:
    """Each run has its digest, recorded on all its engines from a commit without other changes; all of them
    together are well under 1 MB."""
    sizes = {name: runs.path(name).stat().st_size for name in runs.RUNS}
    assert sum(sizes.values()) < 500_000, sizes
    assert set(FAST) | set(SLOW) == set(runs.RUNS)
    for name in runs.RUNS:
        rec = runs.recorded(name)
        assert rec["run"] == name and rec["engines"] == list(runs.RUNS[name].engines)
        assert len(rec["recorded_from"]["commit"]) == 40 and rec["recorded_from"]["uncommitted_changes"] is False
        assert rec["environment"]["blas"] and all(b["kernel"] for b in rec["environment"]["blas"])


def _one_ulp_later(x: float) -> float:
    return math.nextafter(x, math.inf)


def test_the_digest_finds_one_ulp_in_one_tick_and_says_where() -> None:
    """The comparison itself: one value one ulp off in the 2nd second of a column is reported with its block."""
    rng = np.random.default_rng(0)
    cols = {"/ctrl": {"t": np.arange(9000) / 3000.0, "i_sq": rng.normal(size=9000), "log_time": rng.normal(size=9000)}}
    schema = {"/ctrl": [("t", "float64"), ("i_sq", "float64"), ("log_time", "float64")]}
    rec = json.loads(json.dumps(digest.log(cols, schema, [], 1 / 3000.0)))
    cols["/ctrl"]["i_sq"][4567] = _one_ulp_later(cols["/ctrl"]["i_sq"][4567])
    cols["/ctrl"]["log_time"][0] += 1.0  # the wall clock: not compared
    now = json.loads(json.dumps(digest.log(cols, schema, [], 1 / 3000.0)))
    (msg,) = digest.diff(rec, now)
    assert msg.startswith("topics./ctrl.columns.i_sq: differs from the 1-s block 1 (t = 1..2 s) on"), msg
    assert digest.diff(rec, json.loads(json.dumps(rec))) == []


def test_the_digest_of_a_table_names_the_rows_and_columns_that_differ() -> None:
    rows = [{"case_id": f"c{i}", "index": i, "x": 0.1 * i, "status": "ok"} for i in range(30)]
    rec = digest.table(rows, 10)
    rows[20] = {**rows[20], "x": _one_ulp_later(rows[20]["x"])}
    rows[7] = {**rows[7], "status": "tripped"}
    msgs = digest.diff({"rows": rec}, {"rows": digest.table(rows, 10)})
    assert msgs[0] == "rows: 2 of 30 rows differ (rows [7, 20]) in 2 column(s): x, status", msgs
    assert msgs[1].startswith("rows row 20 (case_id=c20, index=20): recorded -> now: x 2.0 -> 2.0000000000000004")
    assert digest.same(0.0, 0.0) and not digest.same(0.0, -0.0) and not digest.same(1, 1.0)
    assert digest.same(math.nan, math.nan)
