"""bench sweep: sweep files, cases as ordinary sessions on Dask, results.parquet, resume, errors, report."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from bench.errors import BadInput
from bench.workflows.sweep import cases as sweep_cases
from bench.workflows.sweep import plant, spec, table
from bench.workflows.sweep.engine import Cluster, run_sweep

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ROOT / "sweeps" / "smoke.toml"
METRICS = ("status", "trip_cause", "trip_time", "ticks", "sim_time", "exit_code", "speed_error_rms",
           "speed_error_settled_rms", "load_steps", "load_dip_max", "load_recovery_mean", "i_mR_error_rms",
           "est_flux_angle_rms_deg", "est_flux_mag_rms_A", "est_speed_rms")  # fmt: skip


def _same(a, b) -> bool:
    return (a is None and b is None) or a == b or (isinstance(a, float) and isinstance(b, float)
                                                   and math.isnan(a) and math.isnan(b))  # fmt: skip


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    """The smoke sweep, run once on the engine's own local cluster with 2 worker processes."""
    out = tmp_path_factory.mktemp("sweep") / "smoke"
    result = run_sweep(spec.load(SMOKE), out, workers=2, progress=False)
    return out, result, table.read(out / table.RESULTS)


@pytest.fixture(scope="module")
def threads():
    """An in-process Dask cluster (threads) for the tests that need no separate processes."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None) as lc:  # fmt: skip
        with Client(lc) as c:
            yield c


def test_smoke_sweep_on_two_local_workers(smoke):
    out, result, rows = smoke
    assert 8 <= result["cases"] <= 16 and result["ran"] == result["cases"] and result["skipped"] == 0
    assert result["workers"] == 2 and len({r["worker"] for r in rows}) == 2  # both processes ran cases
    assert result["ok"] + result["tripped"] == result["cases"] and result["error"] == 0
    assert [r["index"] for r in rows] == list(range(result["cases"]))
    assert len({r["case_id"] for r in rows}) == len(rows)
    ok = [r for r in rows if r["status"] == "ok"]
    assert ok and all(r["ticks"] == 3000 and r["sim_time"] == pytest.approx(1.0) for r in ok)
    # the physics shows: a hot rotor (R_r x 1.5) puts the current model's flux angle off by degrees
    cm = {(r["plant.R_r"], r["plant.R_s"]): r for r in rows if r["params.observer"] == "current_model"}
    assert cm[(1.0, 1.0)]["est_flux_angle_rms_deg"] < 0.2 < 2.0 < cm[(1.5, 1.0)]["est_flux_angle_rms_deg"]
    early = [r for r in rows if r["status"] == "tripped" and r["trip_time"] < 0.5]  # before the error window
    assert all(r["est_flux_angle_rms_deg"] is None and r["est_speed_rms"] is None for r in early)
    assert not list(out.glob("logs")) and not list(out.glob("*.mcap"))  # no per-tick log without --keep-logs
    assert sorted(p.name for p in out.iterdir()) == ["results.parquet", "spec.toml", "sweep.json"]


def test_smoke_rows_equal_bench_run_of_each_case(smoke, tmp_path):
    """Every row equals `bench run` of the same case (its rig file, seed and parameters) with a log.

    The sweep's cases take the compiled plant ("auto"); the single runs here the Python reference."""
    import tomlkit

    from bench.cli import cli

    _, _, rows = smoke
    by_id = {r["case_id"]: r for r in rows}
    for case in sweep_cases.expand(spec.load(SMOKE)):
        assert case.rig["mock"]["engine"] == "auto"
        rig = tmp_path / f"{case.case_id}.toml"
        rig.write_text(tomlkit.dumps({**case.rig, "mock": {**case.rig["mock"], "engine": "python"}}))
        log = tmp_path / f"{case.case_id}.mcap"
        code = cli.main(args=[*case.bench_run_args(str(rig)), "--log", str(log), "--no-progress"],
                        standalone_mode=False)  # fmt: skip
        text = log.with_name(log.stem + ".summary.json").read_text()
        summary = json.loads(text, parse_constant=lambda c: pytest.fail(f"summary.json has {c}: not standard JSON"))
        single = sweep_cases.summary_row(summary)
        row = by_id[case.case_id]
        assert code == row["exit_code"]
        for k in METRICS:
            assert _same(single.get(k), row.get(k)), (case.case_id, k, single.get(k), row.get(k))


def test_resume_skips_finished_cases_and_reruns_the_missing_ones(smoke, tmp_path, threads):
    src, _, rows = smoke
    out = tmp_path / "resumed"
    out.mkdir()
    kept = rows[:5]
    table.write(out / table.RESULTS, kept)
    result = run_sweep(spec.load(SMOKE), out, client=threads, progress=False)
    assert (result["skipped"], result["ran"]) == (5, len(rows) - 5)
    again = table.read(out / table.RESULTS)
    assert [r["case_id"] for r in again] == [r["case_id"] for r in rows]
    assert [r["worker"] for r in again[:5]] == [r["worker"] for r in kept]  # not run again
    for a, b in zip(again, rows):  # the re-run cases give the same numbers (same seed, same case)
        assert all(_same(a.get(k), b.get(k)) for k in METRICS), a["case_id"]
    result = run_sweep(spec.load(SMOKE), out, client=threads, progress=False)
    assert (result["skipped"], result["ran"]) == (len(rows), 0)


def test_resume_over_a_table_with_duplicated_rows_keeps_one_row_per_case(smoke, tmp_path, threads):
    _, _, rows = smoke
    out = tmp_path / "twice"
    out.mkdir()
    table.write(out / table.RESULTS, rows + rows)  # e.g. two runs that both wrote every case
    said: list[str] = []
    result = run_sweep(spec.load(SMOKE), out, client=threads, progress=False, say=said.append)
    assert (result["skipped"], result["ran"]) == (len(rows), 0)
    again = table.read(out / table.RESULTS)
    assert len(again) == len({r["case_id"] for r in again}) == len(rows)
    assert said == [f"sweep smoke: {len(rows)} cases, {len(rows)} done before, 0 to run"]


def test_a_million_cases_need_allow_large(tmp_path):
    big = tmp_path / "big.toml"
    axes = '"plant.R_r" = [%s]\n"plant.R_s" = [%s]\n' % (", ".join(f"{0.5 + i / 1000:.4f}" for i in range(1000)),
                                                         ", ".join(f"{0.8 + i / 2500:.4f}" for i in range(1000)))
    big.write_text(SMOKE.read_text().split("[design.axes]")[0] + "[design.axes]\n" + axes)
    assert spec.count(spec.load(big)) == 1_000_000
    p = _bench("sweep", str(big), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert p.returncode == 2 and p.stderr.strip().splitlines() == [
        f"bench: error: --allow-large: the sweep has 1000000 cases, more than {spec.LARGE_CASES}; pass --allow-large "
        "to run them all"], p.stderr  # fmt: skip
    assert not (tmp_path / "out").exists() and p.stdout == ""


def test_a_raising_case_is_recorded_and_the_sweep_goes_on(tmp_path, threads):
    sp = spec.parse({
        "sweep": {"scenarios": ["fig5.7"], "duration": 0.5},
        "design": {"variants": {"speed": [
            {"label": "pi"},
            {"label": "missing-artifact", "params": {"speed_controller": "lpv", "lpv_speed_artifact": str(tmp_path / "none")}},
        ]}},
    })  # fmt: skip
    result = run_sweep(sp, tmp_path / "out", client=threads, progress=False)
    assert (result["ok"], result["error"]) == (1, 1)
    rows = {r["label.speed"]: r for r in table.read(tmp_path / "out" / table.RESULTS)}
    assert rows["pi"]["status"] == "ok" and rows["pi"]["ticks"] == 1500
    bad = rows["missing-artifact"]
    assert bad["status"] == "error" and "BadInput" in bad["error"] and "lpv_speed_artifact" in bad["error"]
    assert bad["ticks"] is None
    # an errored case runs again on resume; the finished one does not
    again = run_sweep(sp, tmp_path / "out", client=threads, progress=False)
    assert (again["skipped"], again["ran"], again["error"]) == (1, 1, 1)


def test_keep_logs_writes_each_cases_log_and_rig_file(tmp_path, threads):
    from bench.daq import LogReader

    sp = spec.parse({"sweep": {"scenarios": ["fig5.7"], "duration": 0.5}, "plant": {"R_r": 1.2}})
    result = run_sweep(sp, tmp_path / "out", client=threads, keep_logs=True, progress=False)
    assert result["ok"] == 1
    (row,) = table.read(tmp_path / "out" / table.RESULTS)
    log = Path(row["log"])
    assert log.parent == tmp_path / "out" / "logs" and log.name == f"{row['case_id']}.mcap"
    assert LogReader(log).read("/rig")["t"].size == row["ticks"] == 1500
    import tomllib

    rig = tomllib.loads((log.parent / f"{row['case_id']}.rig.toml").read_text())
    assert rig["mock"]["motor"] == {"R_r": pytest.approx(1.2 * 3.3)} and rig["motor"]["R_r"] == 3.3


DIE_ONCE = '''
import os
from pathlib import Path
from bench.workflows.sweep.cases import run_case

def die_once(case, log_dir):
    marker = Path(os.environ["SWEEP_TEST_MARKER"]) / case.case_id
    if not marker.exists():
        marker.touch()
        os._exit(17)  # the worker process dies mid-case
    return run_case(case, log_dir)

def die_always(case, log_dir):
    os._exit(17)
'''


def test_a_worker_dying_mid_case_gets_one_retry(tmp_path, monkeypatch):
    (tmp_path / "dying_runner.py").write_text(DIE_ONCE)
    monkeypatch.syspath_prepend(str(tmp_path))  # the spawned workers get this sys.path
    monkeypatch.setenv("SWEEP_TEST_MARKER", str(tmp_path))
    import dying_runner

    sp = spec.parse({"sweep": {"scenarios": ["fig5.7"], "duration": 0.3}})
    with Cluster(1) as cl:  # the engine's own local cluster (one retry), started once for both sweeps
        result = run_sweep(sp, tmp_path / "once", client=cl.client, progress=False, runner=dying_runner.die_once)
        assert (result["ok"], result["error"]) == (1, 0)
        result = run_sweep(sp, tmp_path / "always", client=cl.client, progress=False,
                           runner=dying_runner.die_always)  # fmt: skip
    assert result["error"] == 1
    row = table.read(tmp_path / "always" / table.RESULTS)[0]
    assert "KilledWorker" in row["error"] and "died twice" in row["error"]


def test_report_writes_plots_and_markdown(smoke):
    from bench.workflows.sweep.report import report

    out, result, _ = smoke
    written = report(out)
    names = {p.name for p in written}
    assert names == {"errors.png", "trips.png", "heatmap.png", "report.md"}
    assert all((out / n).stat().st_size > 10_000 for n in names - {"report.md"})
    md = (out / "report.md").read_text()
    assert f"# Sweep report: {result['cases']} cases" in md
    for obs in ("current_model", "jl", "lpv"):
        assert f"| {obs} | 4 |" in md
    assert "`plant.R_r`" in md and "`plant.R_s`" in md


def _bench(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=120, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})  # fmt: skip


def test_a_typo_in_the_spec_exits_2_naming_the_field_and_writes_nothing(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(SMOKE.read_text().replace('"plant.R_s"', '"plant.R_z"'))
    p = _bench("sweep", str(bad), "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().splitlines() == [p.stderr.strip()]  # one line
    assert "design.axes.plant.R_z" in p.stderr and "unknown plant key" in p.stderr
    assert not (tmp_path / "out").exists() and p.stdout == ""


def test_an_unreachable_scheduler_exits_2_and_writes_nothing(tmp_path):
    p = _bench("sweep", str(SMOKE), "--out", str(tmp_path / "out"), "--scheduler", "tcp://127.0.0.1:9",
               "--connect-timeout", "1", cwd=tmp_path)  # fmt: skip
    assert p.returncode == 2, p.stderr
    assert "--scheduler: cannot reach tcp://127.0.0.1:9" in p.stderr
    assert not (tmp_path / "out").exists()
    # before the wait, the user is told how many cases and what it waits for (Dask takes seconds to start or give up)
    lines = p.stderr.splitlines()
    assert "sweep smoke: 12 cases" in lines[0]
    assert "sweep smoke: connecting to the Dask scheduler tcp://127.0.0.1:9 ..." in lines[1]


_TASK = {"sweep": {"task": "flux_observer_gamma"}}


@pytest.mark.parametrize("data, field", [
    ({"sweep": {"controler": "foc"}}, "sweep.controler"),
    ({"sweep": {"scenarios": ["fig9.9"]}}, "sweep.scenarios"),
    ({"sweep": {"seeds": [0, 0]}}, "sweep.seeds"),
    ({"sweep": {"duration": -1.0}}, "sweep.duration"),
    ({"params": {"speed_Kp": -1.0}}, "params.speed_Kp"),
    ({"params": {"speed_kp": 1.0}}, "params.speed_kp"),
    ({"plant": {"R_r": 100.0}}, "plant.R_r"),
    ({"design": {"kind": "sobol"}}, "design.kind"),
    ({"design": {"kind": "lhs", "samples": 4}}, "design.ranges"),
    ({"design": {"kind": "lhs", "samples": 4, "ranges": {"plant.R_r": [1.5, 0.5]}}}, "design.ranges.plant.R_r"),
    ({"design": {"kind": "random", "ranges": {"plant.R_r": [0.5, 1.5]}}}, "design.samples"),
    ({"design": {"axes": {"observer": ["jl"]}}}, "design.axes.observer"),
    ({"design": {"axes": {"params.observer": ["jl", "jll"]}}}, "design.axes.params.observer"),
    ({"design": {"variants": {"mode": [{"label": "a"}, {"label": "a"}]}}}, "design.variants.mode"),
    ({"design": {"variants": {"mode": [{"label": "a", "plant": {"J": 0}}]}}}, "design.variants.mode[0].plant.J"),
    ({"sweep": {"rig": "emulated"}}, "sweep.rig"),
    ({"plot": {}}, "plot"),
    # computation sweeps (bench.workflows.sweep.tasks)
    ({"sweep": {"task": "fig55"}}, "sweep.task"),
    ({**_TASK, "task": {"omega_r_max": 100.0, "omega": 1.0}}, "task.omega"),
    ({**_TASK, "task": {"omega_r_max": -5.0}}, "task.omega_r_max"),
    ({**_TASK, "task": {"omega_r_max": 100.0, "variant": "half"}}, "task.variant"),
    (_TASK, "task.omega_r_max"),  # required, given nowhere
    ({"sweep": {"task": "flux_observer_gamma", "scenarios": ["fig5.7"]}, "task": {"omega_r_max": 1e2}}, "sweep.scenarios"),
    ({**_TASK, "params": {"speed_Kp": 1.0}, "task": {"omega_r_max": 1e2}}, "params"),
    ({**_TASK, "design": {"axes": {"params.observer": ["jl"]}}}, "design.axes.params.observer"),
    ({**_TASK, "design": {"kind": "lhs", "samples": 3, "ranges": {"task.variant": [0, 1]}}}, "design.ranges.task.variant"),
    ({**_TASK, "design": {"variants": {"c": [{"label": "a", "params": {}}]}}}, "design.variants.c[0].params"),
    ({"task": {"omega_r_max": 100.0}}, "task"),  # [task] without a task sweep
    ({"sweep": {"task": "narx_candidate"}, "task": {"train_log": "/nonexistent.mcap"}}, "task.train_log"),
])  # fmt: skip
def test_bad_specs_name_the_field(data, field):
    with pytest.raises(BadInput) as exc:
        spec.parse(data)
    assert exc.value.field == field, str(exc.value)


def test_a_mismatch_the_rig_refuses_stops_before_anything_runs(tmp_path):
    rig = tmp_path / "small-counter.toml"
    rig.write_text((ROOT / "rigs" / "mock.toml").read_text() + "\n[mock.encoder]\nmodulus = 8192\n")
    sp = spec.parse({"sweep": {"rig": str(rig)}, "design": {"axes": {"plant.encoder_lines": [1024, 2048]}}})
    assert len(sweep_cases.expand(sp)) == 2
    sp = spec.parse({"sweep": {"rig": str(rig)}, "design": {"axes": {"plant.encoder_lines": [1024, 4096]}}})
    with pytest.raises(BadInput, match="the mock rig refuses it: mock.encoder.modulus must be >= 4"):
        sweep_cases.expand(sp)


def test_latin_hypercube_is_stratified_seeded_and_crossed_with_the_grid():
    data = {"sweep": {"seeds": [3]}, "design": {"kind": "lhs", "samples": 10, "seed": 7,
            "axes": {"params.observer": ["jl", "kubota"]},
            "ranges": {"plant.R_r": [0.5, 1.5], "plant.encoder_lines": [256, 4096]}}}  # fmt: skip
    cs = sweep_cases.expand(spec.parse(data))
    assert len(cs) == 20 and {c.seed for c in cs} == {3}
    rr = sorted(c.plant["R_r"] for c in cs if c.params["observer"] == "jl")
    assert all(0.5 + 0.1 * i <= r < 0.5 + 0.1 * (i + 1) for i, r in enumerate(rr))  # one point per stratum
    assert all(isinstance(c.plant["encoder_lines"], int) for c in cs)
    assert [c.case_id for c in sweep_cases.expand(spec.parse(data))] == [c.case_id for c in cs]
    data["design"]["seed"] = 8
    assert [c.plant for c in sweep_cases.expand(spec.parse(data))] != [c.plant for c in cs]


def test_plant_keys_map_onto_the_mock_rig():
    from bench.params import MotorParams

    m = MotorParams()
    mock = plant.apply({}, {"R_r": 1.5, "L_m": 1.1, "leakage": 2.0, "J": 0.7, "current_offset": 0.01,
                            "encoder_lines": 256, "dead_time": 2e-6})  # fmt: skip
    mo = mock["motor"]
    assert mo["R_r"] == 1.5 * m.R_r and "R_s" not in mo and mo["J"] == pytest.approx(0.7 * m.J)
    assert mo["L_m"] == pytest.approx(1.1 * m.L_m)
    assert mo["L_s"] - mo["L_m"] == pytest.approx(2.0 * (m.L_s - m.L_m))
    assert mock["currents"]["offset"] == [0.01, 0.0, 0.0]
    assert mock["encoder"]["lines"] == 256 and mock["inverter"]["dead_time"] == 2e-6
    assert plant.apply({"motor": {"R_r": 4.95}}, {"R_r": 2.0})["motor"]["R_r"] == 9.9  # on the rig's true machine
    assert plant.apply({}, {"R_r": 1.0}) == {}


def test_the_case_hash_follows_the_run_not_the_spelling():
    a = sweep_cases.expand(spec.parse({"params": {"observer": "current_model"}, "plant": {"R_r": 1.0}}))
    b = sweep_cases.expand(spec.parse({}))
    c = sweep_cases.expand(spec.parse({"plant": {"R_r": 1.01}}))
    assert a[0].case_id == b[0].case_id != c[0].case_id


@pytest.mark.parametrize("name, groups", [("atlas-observers", ("params.observer", "label.mode")),
                                          ("atlas-controllers", ("label.controller",))])  # fmt: skip
def test_the_atlas_specs_hold_at_least_1000_mismatch_cases_per_group(name, groups):
    cs = sweep_cases.expand(spec.load(ROOT / "sweeps" / f"{name}.toml"))
    count: dict = {}
    for c in cs:
        key = tuple(c.inputs()[g] for g in groups)
        count[key] = count.get(key, 0) + 1
    assert min(count.values()) >= 1000
    for key, lo, hi in (("R_r", 0.5, 1.5), ("R_s", 0.8, 1.2), ("L_m", 0.85, 1.15), ("J", 0.7, 1.3)):
        vals = [c.plant[key] for c in cs]
        assert lo <= min(vals) < lo + 0.01 and hi - 0.01 < max(vals) <= hi


def test_wilson_interval_matches_the_closed_form_and_its_end_points():
    from bench.workflows.sweep.report import wilson

    lo, p, hi = wilson(0, 1000)
    assert (lo, p) == (0.0, 0.0) and hi == pytest.approx(1.959964**2 / (1000 + 1.959964**2))  # z^2/(n+z^2) at k=0
    assert wilson(1000, 1000)[2] == 1.0 and wilson(1000, 1000)[0] == pytest.approx(1000 / (1000 + 1.959964**2))
    lo, p, hi = wilson(20, 100)  # textbook value: 0.2 -> [0.1333, 0.2888]
    assert p == 0.2 and lo == pytest.approx(0.1333, abs=1e-4) and hi == pytest.approx(0.2888, abs=1e-4)


def test_a_full_disk_never_costs_the_results_table(tmp_path, threads, monkeypatch):
    """Every table write fails half-way (ENOSPC): the earlier table stays whole, no temporary file is left,
    and the sweep's result carries every row (bench sweep prints them and exits 1)."""
    import errno

    import pyarrow.parquet as pq

    sp = spec.parse({"sweep": {"scenarios": ["fig5.7"], "duration": 0.3, "seeds": [1, 2, 3]}})
    out = tmp_path / "out"
    first = run_sweep(sp, out, client=threads, progress=False)
    assert first["ran"] == 3
    kept = (out / table.RESULTS).read_bytes()

    def full(tbl, where, **kw):  # writes part of the file, then the disk is full
        Path(where).write_bytes(b"PAR1 half a table")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pq, "write_table", full)
    sp2 = spec.parse({"sweep": {"scenarios": ["fig5.7"], "duration": 0.3, "seeds": [1, 2, 3, 4]}})
    result = run_sweep(sp2, out, client=threads, progress=False, flush_s=0.0)
    assert result["results"] is None and "No space left on device" in result["table_error"]
    assert (result["skipped"], result["ran"]) == (3, 1) and len(result["rows"]) == 4
    assert sorted(r["seed"] for r in result["rows"]) == [1, 2, 3, 4]
    assert (out / table.RESULTS).read_bytes() == kept  # the earlier table, whole
    assert sorted(p.name for p in out.iterdir() if p.is_file()) == ["results.parquet", "spec.toml", "sweep.json"]


def test_the_local_cluster_speaks_tls_and_refuses_clients_without_its_certificate():
    """Another local user must not reach the sweep's workers: the scheduler listens on tls:// with a
    certificate made for this cluster; a plain client, or one with a certificate of its own, is refused."""
    from distributed import Client
    from distributed.security import Security

    from bench.workflows.sweep.engine import Cluster

    with Cluster(1) as cl:
        addr = cl.cluster.scheduler_address
        assert addr.startswith("tls://127.0.0.1:")
        assert cl.client.submit(sum, [1, 2]).result() == 3  # the sweep's own client works
        with pytest.raises((OSError, TimeoutError)):  # TLS with a certificate of its own (another user's)
            Client(addr, timeout=3, security=Security.temporary()).close()
        with pytest.raises((OSError, TimeoutError)):  # plain TCP, as before: no handshake, no connection
            Client(addr.replace("tls://", "tcp://"), timeout=3).close()
