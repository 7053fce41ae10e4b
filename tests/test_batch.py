"""The batch engine (bench.batch.engine): every case of a batch is the scalar session of that case.

The trajectory: every case's final plant and controller state equals the scalar loop's, bit for bit. The summary:
compared per case with `bench.runtime.session.run` (compiled plant and FOC, no log) through the sweep's results
row (`bench.workflows.sweep.cases.summary_row`): ticks, trip cause and time, counts to the bit; the error numbers,
which the session computes with numpy from the logged ticks and the batch from sums in its loop, within
1e-12 relative or 1e-14 absolute (numpy's pairwise sums and its vectorised complex abs differ from the
loop's compensated sums and C hypot by a few ulp of the operands).
"""

from __future__ import annotations

import math
import tomllib

import pytest

pytest.importorskip("numba")

from bench.batch.engine import SCENARIOS, Run, rows_differ, simulate, unsupported  # noqa: E402
from bench.core.config import RIGS_DIR, parse  # noqa: E402
from bench.runtime.session import RunOptions, run  # noqa: E402
from bench.workflows.sweep.cases import summary_row  # noqa: E402
from bench.workflows.sweep.plant import apply  # noqa: E402

BASE = tomllib.loads((RIGS_DIR / "mock.toml").read_text())
def rig(plant: dict | None = None, limits: dict | None = None, mock: dict | None = None, plate: bool = True):
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in BASE.items() if plate or k != "nameplate"}
    m = apply({**data.get("mock", {}), **(mock or {})}, plant or {})
    data["mock"] = m
    data["limits"] = {**data.get("limits", {}), **(limits or {})}
    return parse(data, None)


def scalar(r: Run, scenario: str, duration: float) -> dict:
    summary, _ = run(RunOptions(rig=r.rig, controller="foc", scenario=scenario, duration=duration, realtime=False,
                                seed=r.seed, params={**r.params, "engine": "compiled"}, progress=False,
                                log_enabled=False, inject_fault=r.inject_fault))  # fmt: skip
    return summary


def assert_same(batch: dict, ref: dict) -> None:
    assert_same_row(summary_row(batch), summary_row(ref))


def assert_same_row(a: dict, b: dict) -> None:
    """Two results rows: the same columns; exact where exact, else within the tolerances `rows_differ` states."""
    why = rows_differ(a, b)
    assert why is None, why


def test_batch_equals_scalar_per_case() -> None:
    """Four different cases (true machine, noise seed, gains, dead time, saturation) in one batch."""
    runs = [
        Run(rig(), seed=0),
        Run(rig({"R_r": 1.4, "J": 0.8}), seed=1, params={"speed_Kp": 0.5}),
        Run(rig({"R_s": 0.85, "L_m": 1.1, "dead_time": 3e-6}), seed=2),
        Run(rig(mock={"motor": {"saturation": True}}), seed=3, params={"current_wc": 1500.0}),
    ]
    out = simulate(runs, "fig5.7", 0.8)  # the first load step at 0.733 s
    assert [s["trip_cause"] for s in out] == [None] * 4
    assert out[0]["load_steps"]["count"] == 1
    for r, s in zip(runs, out):
        assert_same(s, scalar(r, "fig5.7", 0.8))
    # different cases, different numbers (the cases are not one case four times)
    assert len({s["speed_error"]["rms"] for s in out}) == 4


def test_batch_equals_scalar_with_the_plant_models_and_a_speed_dependent_load() -> None:
    """No inverter delay, the winding temperatures, sensor errors, a coarse encoder; the demo's load brakes by the
    sign of the measured speed, with reference changes around its load steps."""
    runs = [
        Run(rig(mock={"inverter": {"delay": 0}, "thermal": {"enabled": True, "time_scale": 1000.0, "rise_s0": 40.0}}),
            seed=5),
        Run(rig({"encoder_lines": 256, "current_offset": 0.02, "voltage_noise": 0.01},
                mock={"currents": {"gain_error": [0.01, -0.01, 0.0]}, "inverter": {"v_on": 1.5, "i_knee": 0.3}}),
            seed=6, params={"voltage_source": "measured"}),
    ]  # fmt: skip
    out = simulate(runs, "demo", 1.8)
    assert out[0]["load_steps"]["count"] >= 1
    for r, s in zip(runs, out):
        assert_same(s, scalar(r, "demo", 1.8))


def test_final_states_are_the_scalar_loops_to_the_bit() -> None:
    """The trajectory itself: after the run, every case's plant and controller state buffers (motor, filters, noise
    streams, encoder; observer, PI states) equal those of the scalar loop (`bench.runtime.loop.TimedLoop` on the
    session's objects) bit for bit, a tripped case's included."""
    import numpy as np

    from bench.runtime.fault_injection import inject
    from bench.runtime.loop import TimedLoop
    from bench.core.scenarios import get
    from bench.runtime.run_summary import summary_time
    from bench.runtime.compose import make_controller
    from bench.core.supervisor import Supervisor
    from mock_hw.plant import MockConfig, make_mock_rig

    runs = [Run(rig({"R_r": 1.3, "dead_time": 2e-6}), seed=7), Run(rig(), seed=8, inject_fault="over-speed")]
    states: dict = {}
    out = simulate(runs, "load6.4.1", 0.6, states=states)
    assert out[0]["trip_cause"] is None and out[1]["trip_cause"].startswith("over-speed")
    for i, r in enumerate(runs):
        cfg = r.rig if r.inject_fault is None else inject(r.rig, r.inject_fault, get("load6.4.1"), 0.6)[0]
        plant_rig = make_mock_rig(MockConfig.from_dict({**cfg.mock, "engine": "compiled"}), dt=cfg.T_s, seed=r.seed)
        ctrl = make_controller(cfg, plant_rig, "foc", {"engine": "compiled"})
        sup = Supervisor(cfg.limits, plant_rig.encoder.counts_per_rev, plant_rig.encoder.modulus, cfg.motor.Z_p,
                         cfg.T_s)  # fmt: skip
        plant_rig.configure()
        plant_rig.activate()
        res = TimedLoop(plant_rig, ctrl, get("load6.4.1"), sup, T_s=cfg.T_s, duration=0.6).run()
        assert res.ticks == out[i]["ticks"] and summary_time(res.trip_t) == out[i]["trip_time"]
        plant = plant_rig.truth
        plant._reload_rngs() if plant._lent[0] else None
        assert np.array_equal(states["plant"][i], plant._buf, equal_nan=True)
        assert np.array_equal(states["controller"][i], ctrl._buf, equal_nan=True)


SENSORLESS = {"speed_source": "estimate", "speed_estimator": "kubota", "kubota_pole_ratio": 1.1,
              "kubota_lambda_c": 1000.0}  # the atlas' sensorless mode
PARTS = [{"observer": "voltage_model"}, {"observer": "jl"}, {"observer": "kubota", "kubota_adapt": 0.0},
         {"observer": "lpv"}, SENSORLESS, {**SENSORLESS, "observer": "kubota"}, {**SENSORLESS, "observer": "lpv"},
         {"speed_estimator": "rotor_equation"},
         {"current_controller": "lpv"}, {"speed_controller": "lpv", "lpv_speed_artifact": "nominal"},
         {"speed_controller": "lpv", "lpv_speed_artifact": "robust", "current_controller": "lpv"}]  # fmt: skip


def state_of(ctrl, buf):  # noqa: ANN001, ANN201
    """``buf`` (a controller's buffer after a batch run) with its tail regions' state only: each region unpacked into
    a copy of ``ctrl``'s part and packed again (the LPV parts' scratch slots hold the last evaluation's intermediates,
    which are not state; `pack` leaves them zero)."""
    import copy

    import numpy as np

    from bench.controllers import foc_compiled as fc, lpv_compiled, observers_compiled

    c = copy.deepcopy(ctrl)
    iv = buf[fc.NF:fc.N_BUF].view(np.int64)
    for at, part, mod in ((fc.SI.OBS_AT, c.observer, observers_compiled),
                          (fc.SI.EST_AT, c.estimator, observers_compiled),
                          (fc.SI.SPD_AT, c.speed, lpv_compiled), (fc.SI.CUR_AT, c.current, lpv_compiled)):  # fmt: skip
        a, nf, ni = (int(v) for v in iv[at:at + 3])
        if nf + ni:
            mod.unpack(part, buf[a:a + nf], buf[a + nf:a + nf + ni].view(np.int64))
    out = buf.copy()
    out[fc.N_BUF:] = fc.pack(c)[fc.N_BUF:]
    return out


def test_every_part_it_covers_equals_the_python_session_to_the_bit() -> None:
    """The flux observers, speed estimators (shared and own Kubota observer), LPV current and speed parts in one batch
    (each case its own machine): every results row equals the Python-engine session's, and every case's final plant
    and controller state equals the scalar loop's bit for bit (the Python controller's state packed the same way,
    `foc_compiled.pack`)."""
    import numpy as np

    from bench.controllers import foc_compiled
    from bench.runtime.loop import TimedLoop
    from bench.core.scenarios import get
    from bench.runtime.compose import make_controller
    from bench.core.supervisor import Supervisor
    from mock_hw.plant import MockConfig, make_mock_rig

    runs = [Run(rig({"R_r": 0.7 + 0.06 * i, "L_m": 1.1 - 0.02 * i}), seed=30 + i, params=p) for i, p in enumerate(PARTS)]
    assert [unsupported(r, "load6.4.1") for r in runs] == [None] * len(runs)
    states: dict = {}
    out = simulate(runs, "load6.4.1", 0.9, states=states)
    for i, r in enumerate(runs):
        cfg = r.rig
        py = {**r.params, "engine": "python"}
        ref, _ = run(RunOptions(rig=cfg, controller="foc", scenario="load6.4.1", duration=0.9, realtime=False,
                                seed=r.seed, params=py, progress=False, log_enabled=False))  # fmt: skip
        assert_same(out[i], ref)
        plant_rig = make_mock_rig(MockConfig.from_dict({**cfg.mock, "engine": "compiled"}), dt=cfg.T_s, seed=r.seed)
        ctrl = make_controller(cfg, plant_rig, "foc", py)
        sup = Supervisor(cfg.limits, plant_rig.encoder.counts_per_rev, plant_rig.encoder.modulus, cfg.motor.Z_p,
                         cfg.T_s)  # fmt: skip
        plant_rig.configure()
        plant_rig.activate()
        TimedLoop(plant_rig, ctrl, get("load6.4.1"), sup, T_s=cfg.T_s, duration=0.9).run()
        want = foc_compiled.pack(ctrl)
        got = states["controller"][i]
        assert not got[want.size:].any()  # (the padding of a shorter buffer)
        assert np.array_equal(state_of(ctrl, got[:want.size]), want, equal_nan=True), r.params
    flux = [s["estimation_errors"]["flux_angle_rms_deg"] for s in out]
    assert len(set(flux)) == len(flux)  # all different runs
    assert "rr_adapt" in (unsupported(Run(rig(), params={"rr_adapt": "mras"}), "load6.4.1") or "")


@pytest.mark.parametrize("scenario", [s for s in SCENARIOS if s not in ("fig5.7", "demo", "load6.4.1")])
def test_every_scenario_it_runs_equals_scalar(scenario: str) -> None:
    """The other scenarios' references (steps, ramps) and loads (by the speed's sign, gated, 6.4.1's law, the
    magnetising reference of fig6.14), 0.9 s each."""
    runs = [Run(rig({"R_r": 1.2}), seed=11)]
    (out,) = simulate(runs, scenario, 0.9)
    assert_same(out, scalar(runs[0], scenario, 0.9))


def test_load_step_with_each_cases_speed_and_load_equals_scalar() -> None:
    """The parameterised ``load-step``: one batch, each case its own speed and load (a zero speed: no reference change;
    a braking load; the defaults), each equal to the scalar session of `bench.core.scenarios.load_step` with those
    values."""
    from bench.core.scenarios import load_step

    args = [{"speed": 80.0, "load": 4.5}, {"speed": 0.0, "load": 2.0}, {"speed": -35.0, "load": -3.0}, {}]
    runs = [Run(rig({"R_r": 0.8 + 0.2 * i}), seed=20 + i, scenario_args=a) for i, a in enumerate(args)]
    out = simulate(runs, "load-step", 0.9)
    for r, s in zip(runs, out):
        assert_same(s, scalar(r, load_step(**r.scenario_args), 0.9))
    assert [s["load_steps"]["count"] for s in out] == [1, 1, 1, 1]
    assert len({s["speed_error_settled"]["rms"] for s in out}) == 4
    bad = unsupported(Run(rig(), scenario_args={"spede": 1.0}), "load-step")
    assert bad is not None and "spede" in bad
    assert "finite" in (unsupported(Run(rig(), scenario_args={"load": math.inf}), "load-step") or "")
    assert "no arguments" in (unsupported(Run(rig(), scenario_args={"speed": 1.0}), "fig5.7") or "")


def test_tripping_cases_stop_alone() -> None:
    """An over-current and an over-speed trip inside a batch: each stops at its scalar run's tick (plus the
    post-trip ticks), the others run to the end."""
    runs = [
        Run(rig(), seed=0),
        # the magnetising current trips it (no plate: its 3.6 A would trip, and the rig file is refused)
        Run(rig(limits={"I_trip_phase": 2.0}, plate=False), seed=1),
        Run(rig(), seed=2, inject_fault="over-speed"),  # 200 rad/s asked, the trip lowered to 100 rad/s
        Run(rig({"R_r": 0.6}), seed=3),
        Run(rig(limits={"u_dc_min": 600.0}), seed=4),  # the mock's 560 V DC link: trips at the first tick
        # ~12 V magnetising at standstill: "encoder stuck" (in 0.1 s: a shaft at rest on a count's edge may toggle
        # the count, 0.13 s apart after the magnetising kick)
        Run(rig(limits={"enc_stuck_u": 5.0, "enc_stuck_time": 0.1}), seed=5),
        Run(rig(limits={"enc_stuck_omega": 0.1, "enc_stuck_u": 1000.0, "enc_stuck_time": 0.1}), seed=6),  # angle noise
    ]
    out = simulate(runs, "load6.4.1", 0.7)
    refs = [scalar(r, "load6.4.1", 0.7) for r in runs]
    assert out[1]["trip_cause"].startswith("over-current") and out[2]["trip_cause"].startswith("over-speed")
    assert out[4]["trip_cause"].startswith("DC link") and out[4]["trip_time"] == 0.0 and out[4]["speed_error"] == {}
    assert out[5]["trip_cause"].startswith("encoder stuck") and out[6]["trip_cause"].startswith("encoder stuck")
    assert out[1]["ticks"] < out[2]["ticks"] < out[0]["ticks"] == out[3]["ticks"] == round(0.7 * 3000)
    for s, ref in zip(out, refs):
        assert_same(s, ref)


def test_rows_differ_holds_to_its_tolerances() -> None:
    """The comparison the tests and `bench perf batch --atlas` use: exact columns exact, errors 1e-12 relative,
    flux angles 1e-13 deg absolute, timing ignored."""
    base = {"status": "ok", "trip_time": 0.5, "speed_error_rms": 1.0, "est_flux_angle_rms_deg": 0.02,
            "wall_time": 1.0}  # fmt: skip
    assert rows_differ(base, dict(base, wall_time=7.0)) is None
    assert rows_differ(base, dict(base, speed_error_rms=1.0 + 5e-13)) is None
    assert "speed_error_rms" in rows_differ(base, dict(base, speed_error_rms=1.0 + 5e-12))
    assert rows_differ(base, dict(base, est_flux_angle_rms_deg=0.02 + 5e-14)) is None
    assert "angle" in rows_differ(base, dict(base, est_flux_angle_rms_deg=0.02 + 3e-13))
    assert "trip_time" in rows_differ(base, dict(base, trip_time=math.nextafter(0.5, 1.0)))
    assert "columns" in rows_differ(base, {**base, "extra": 1})


def test_unsupported_says_why() -> None:
    assert unsupported(Run(rig()), "fig5.7") is None
    why = unsupported(Run(rig(), params={"rr_adapt": "mras"}), "fig5.7")
    assert why is not None and "rr_adapt" in why
    why = unsupported(Run(rig(), params={"speed_controller": "lpv", "speed_estimator": "kubota"}), "fig5.7")
    assert why is None  # (an LPV speed law on the encoder, Kubota's speed estimated and logged alongside)
    why = unsupported(Run(rig(), params={"observer": "lpv"}), "fig6.14-ab")
    assert why is not None and "fig6.14-ab" in why
    with pytest.raises(Exception, match="scenario"):
        simulate([Run(rig())], "no-such-scenario")


def test_sweep_runs_compatible_cases_in_batches_and_resumes(tmp_path) -> None:
    """`run_sweep(batch=N)`: the cases the batch engine covers in batch tasks, those with the R_r estimate (not
    covered) one task each; the rows equal the scalar sweep's; a resumed sweep runs only the missing cases."""
    from distributed import Client, LocalCluster

    from bench.workflows.sweep import table
    from bench.workflows.sweep.engine import run_sweep
    from bench.workflows.sweep.spec import parse as parse_spec

    axes = {"params.rr_adapt": ["off", "mras"], "plant.R_r": [1.0, 1.4]}
    sp = parse_spec({"sweep": {"name": "b", "scenarios": ["fig5.7"], "duration": 0.6, "seeds": [0, 1, 2, 3]},
                     "design": {"axes": axes}})
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None) as lc, Client(lc) as client:  # fmt: skip
        res = run_sweep(sp, tmp_path / "batch", client=client, progress=False, batch=2)
        run_sweep(sp, tmp_path / "scalar", client=client, progress=False)
        rows = {r["case_id"]: r for r in table.read(tmp_path / "batch" / table.RESULTS)}
        ref = {r["case_id"]: r for r in table.read(tmp_path / "scalar" / table.RESULTS)}
        assert res["ran"] == 16 and res["error"] == 0 and set(rows) == set(ref)
        batched = {k for k, r in rows.items() if r["compute_us_p50"] is None}  # no per-tick timing in a batch
        assert batched == {k for k, r in rows.items() if r["params.rr_adapt"] == "off"}
        shares = [rows[k]["case_wall_time"] for k in batched]  # each case's share of its batch's time
        assert sorted(shares.count(x) for x in shares) == [2] * 8  # 8 cases in batches of 2
        for k in rows:
            a = {c: v for c, v in rows[k].items() if c not in ("case_wall_time", "worker")}
            b = {c: v for c, v in ref[k].items() if c not in ("case_wall_time", "worker")}
            assert_same_row(a, b)
        # resume: drop two batched rows and one scalar one; only those run again
        gone = sorted(batched)[:2] + [next(k for k in rows if k not in batched)]
        table.write(tmp_path / "batch" / table.RESULTS, [r for k, r in rows.items() if k not in gone])
        again = run_sweep(sp, tmp_path / "batch", client=client, progress=False, batch=2)
        assert again["skipped"] == 13 and again["ran"] == 3 and again["error"] == 0
        after = {r["case_id"]: r for r in table.read(tmp_path / "batch" / table.RESULTS)}
        assert set(after) == set(rows)
        for k in set(rows) - set(gone):
            assert after[k]["case_wall_time"] == rows[k]["case_wall_time"]  # kept, not run again
        for k in gone:
            assert_same_row({c: v for c, v in after[k].items() if c not in ("case_wall_time", "worker")},
                            {c: v for c, v in ref[k].items() if c not in ("case_wall_time", "worker")})


def test_sweep_scenario_arguments_batch_equals_scalar() -> None:
    """A sweep over ``load-step``'s arguments (``[scenario]`` fixed, a ``"scenario.load"`` axis): the cases carry them
    (input columns ``scenario.*``, a ``bench run`` line with --scenario-arg), and the batched rows equal the scalar
    ones case by case; an argument the scenario does not take is refused naming the field."""
    from bench.errors import BadInput
    from bench.workflows.sweep.batching import group, run_group
    from bench.workflows.sweep.cases import expand, run_case
    from bench.workflows.sweep.spec import parse as parse_spec

    sp = parse_spec({"sweep": {"name": "s", "scenarios": ["load-step"], "duration": 0.8}, "scenario": {"speed": 70.0},
                     "design": {"axes": {"scenario.load": [1.0, 4.0, -2.5]}}})  # fmt: skip
    cases = expand(sp)
    assert [c.scenario_args for c in cases] == [{"speed": 70.0, "load": x} for x in (1.0, 4.0, -2.5)]
    assert len({c.case_id for c in cases}) == 3
    assert cases[1].inputs()["scenario.load"] == 4.0
    assert cases[1].bench_run_args("r.toml")[-4:] == ["--scenario-arg", "speed=70.0", "--scenario-arg", "load=4.0"]
    groups, singles = group(cases, 8, 1)
    assert singles == [] and sum(map(len, groups)) == 3  # every case batchable (one group per case here: 1 worker)
    rows = run_group(cases)
    assert [r["compute_us_p50"] for r in rows] == [None] * 3  # from the batch, not the scalar fallback
    for c, r in zip(cases, rows):
        ref = run_case(c)
        assert_same_row({k: v for k, v in r.items() if k not in ("case_wall_time", "worker")},
                        {k: v for k, v in ref.items() if k not in ("case_wall_time", "worker")})
    assert rows[0]["load_dip_max"] < rows[1]["load_dip_max"]  # the larger step dips further
    for bad, field in (({"scenario": {"sped": 1.0}}, "scenario.sped"),
                       ({"design": {"axes": {"scenario.load": [1.0, math.nan]}}}, "design.axes.scenario.load")):
        with pytest.raises(BadInput) as exc:
            parse_spec({"sweep": {"scenarios": ["load-step"]}, **bad})
        assert exc.value.field == field
    with pytest.raises(BadInput) as exc:
        parse_spec({"sweep": {"scenarios": ["fig5.7"]}, "scenario": {"speed": 1.0}})
    assert "no arguments" in exc.value.problem


def test_a_case_the_batch_turns_down_runs_alone_on_the_scalar_engine() -> None:
    """A group with a case the engine refuses only when building it (the R_r estimate): that case's row comes from
    the scalar engine, the others' from the batch, each equal to its scalar row; `simulate` names the reason."""
    from bench.workflows.sweep.batching import run_group
    from bench.workflows.sweep.cases import expand, run_case
    from bench.workflows.sweep.spec import parse as parse_spec

    sp = parse_spec({"sweep": {"name": "m", "scenarios": ["fig5.7"], "duration": 0.6},
                     "design": {"axes": {"params.rr_adapt": ["off", "mras"], "plant.R_r": [0.9, 1.2]}}})  # fmt: skip
    cases = expand(sp)
    rows = run_group(cases)  # (forced into one group: the sweep's grouping would leave the mras cases out)
    for c, r in zip(cases, rows):
        assert (r["compute_us_p50"] is None) == (c.params["rr_adapt"] == "off")  # batch, or the scalar engine
        ref = run_case(c)
        assert_same_row({k: v for k, v in r.items() if k not in ("case_wall_time", "worker")},
                        {k: v for k, v in ref.items() if k not in ("case_wall_time", "worker")})
    refused: dict[int, str] = {}
    out = simulate([Run(rig()), Run(rig(), params={"rr_adapt": "mras"})], "fig5.7", 0.05, refused=refused)
    assert out[1] is None and out[0]["ticks"] == 150 and list(refused) == [1] and "rr_adapt" in refused[1]


@pytest.mark.slow
def test_bench_sweep_batch_in_real_processes(tmp_path) -> None:
    """`bench sweep run SPEC --batch N` as a user runs it: its own local cluster (worker processes, TLS), exit 0,
    the batched cases' rows in the table next to the scalar ones."""
    import json
    import subprocess
    import sys

    from bench.workflows.sweep import table

    spec = tmp_path / "b.toml"
    spec.write_text('[sweep]\nname = "b"\nscenarios = ["fig5.7"]\nduration = 0.6\nseeds = [0, 1, 2]\n\n'
                    '[design.axes]\n"params.rr_adapt" = ["off", "mras"]\n')  # fmt: skip
    p = subprocess.run([sys.executable, "-m", "bench", "sweep", "run", str(spec), "--out", str(tmp_path / "out"),
                        "--workers", "1", "--batch", "8", "--no-progress"], capture_output=True, text=True,
                       timeout=600)  # fmt: skip
    assert p.returncode == 0, p.stderr
    res = json.loads(p.stdout)
    assert res["ran"] == 6 and res["error"] == 0
    rows = table.read(tmp_path / "out" / table.RESULTS)
    batched = {o: [r["compute_us_p50"] is None for r in rows if r["params.rr_adapt"] == o]
               for o in ("off", "mras")}  # fmt: skip
    assert batched == {"off": [True] * 3, "mras": [False] * 3}
    assert all(r["status"] == "ok" and r["ticks"] == 1800 for r in rows)
