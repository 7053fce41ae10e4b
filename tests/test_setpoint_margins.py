"""Every speed and load set-point inside the same margins, whatever its source (bench.core.setpoints): scenario
arguments on the command line, a sweep's [scenario] values, axes and ranges, the arguments' defaults, the batch engine's
cases and the live overrides; refused before anything runs, in one line naming the field and the allowed range.
The shipped scenarios' own profiles against the shipped rigs' margins."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from bench.core import scenarios
from bench.core.config import RIGS_DIR
from bench.core.config import load as load_rig
from bench.errors import BadInput
from bench.operate.requests import ParamSpace, session_params
from bench.core.setpoints import LOAD, MARGIN, SPEED, Margins
from bench.workflows.sweep import spec as sweep_spec
from bench.workflows.sweep.cases import expand
from tests.test_identify_refusals import _bench, _refused

ROOT = Path(__file__).resolve().parents[1]
MOCK = Margins.of_rig(load_rig("mock"))  # 400 rad/s, 15 N m: 320 rad/s, 12 N m
SPEED_RANGE = "[-320, 320] rad/s (0.8 x the rig's limits.omega_max = 400)"
LOAD_RANGE = "[-12, 12] N m (0.8 x the rig's mock.load.torque_limit = 15)"


def _one_line(p: subprocess.CompletedProcess, field: str) -> str:
    return _refused(p, f"{field}: ")


@pytest.mark.parametrize("arg, field, allowed", [
    ("speed=1e308", "scenario.speed", SPEED_RANGE),  # ran the motor at 361 rad/s and logged 1e308
    ("speed=400", "scenario.speed", SPEED_RANGE),
    ("speed=-400", "scenario.speed", SPEED_RANGE),
    ("load=20", "scenario.load", LOAD_RANGE),
    ("load=-20", "scenario.load", LOAD_RANGE),
    ("speed=1e-320", "scenario.speed", "finite number (0 or at least 2.23e-308 in magnitude)"),
])  # fmt: skip
def test_scenario_arguments_outside_the_margins_are_refused_before_the_run(tmp_path, arg, field, allowed):
    p = _bench(tmp_path, "run", "--scenario", "load-step", "--scenario-arg", arg, "--duration", "4", "--lockstep",
               "--no-progress")  # fmt: skip
    assert allowed in _one_line(p, field)
    assert list(tmp_path.iterdir()) == []  # no runs/ folder, no run folder


def test_the_bounds_are_inclusive_and_the_rule_is_the_overrides():
    assert scenarios.check_arguments("load-step", {"speed": -320.0, "load": 12}, MOCK) == {"speed": -320.0,
                                                                                          "load": 12.0}  # fmt: skip
    for k, v in (("speed", 320.0000001), ("load", -12.000001)):
        with pytest.raises(BadInput, match=f"scenario.{k}: must be a number in"):
            scenarios.check_arguments("load-step", {k: v}, MOCK)
    # the live overrides: the same bounds, from the same rule, and a subnormal refused there too
    sess = session_params(load_rig("mock").limits, MOCK.torque_limit)
    assert (sess["omega_r_ref_override"].ge, sess["omega_r_ref_override"].le) == (-MOCK.omega, MOCK.omega) == (-320, 320)
    assert (sess["m_l_ref_override"].ge, sess["m_l_ref_override"].le) == (-MOCK.torque, MOCK.torque) == (-12, 12)
    assert 1.0 - MARGIN == 0.8
    space = ParamSpace(sess, {})
    for name in ("omega_r_ref_override", "m_l_ref_override", "i_mr_ref_override"):
        for bad in (1e-320, "1e-320", -5e-324):
            with pytest.raises(BadInput, match=name):
                space.check(name, bad)


@pytest.mark.parametrize("bad", [10**400, float("nan"), float("inf"), True, "80", None])
def test_scenario_arguments_must_be_finite_numbers(bad):
    with pytest.raises(BadInput, match="scenario.speed: must be a finite number"):
        scenarios.check_arguments("load-step", {"speed": bad}, MOCK)


def test_the_defaults_are_checked_against_the_rig(tmp_path):
    """load-step's defaults (50 rad/s, 3 N m) on a rig whose margin is 48 rad/s: refused, naming the argument and
    saying it is the default; given a value inside, it runs."""
    rig = tmp_path / "slow.toml"
    rig.write_text((RIGS_DIR / "mock.toml").read_text().replace("omega_max = 400.0", "omega_max = 60.0"))
    slow = Margins.of_rig(load_rig(str(rig)))
    with pytest.raises(BadInput, match=r"scenario.speed: must be a number in \[-48, 48\] rad/s .* got 50, the default"):
        scenarios.check_arguments("load-step", {}, slow)
    assert scenarios.check_arguments("load-step", {"speed": 40}, slow) == {"speed": 40.0, "load": 3.0}
    with pytest.raises(BadInput, match="scenario.speed") as exc:  # a sweep on that rig: before any case runs
        expand(sweep_spec.parse({"sweep": {"rig": str(rig), "scenarios": ["load-step"]}}))
    assert "the default of 'load-step'" in exc.value.problem
    assert len(expand(sweep_spec.parse({"sweep": {"rig": str(rig), "scenarios": ["load-step"]},
                                        "scenario": {"speed": 40.0}}))) == 1  # fmt: skip


_LS = {"sweep": {"scenarios": ["load-step"]}}


@pytest.mark.parametrize("data, field", [
    ({**_LS, "scenario": {"speed": 1e308}}, "scenario.speed"),
    ({**_LS, "scenario": {"speed": -1e9}}, "scenario.speed"),
    ({**_LS, "scenario": {"speed": 400.0}}, "scenario.speed"),
    ({**_LS, "scenario": {"load": -20.0}}, "scenario.load"),
    ({**_LS, "scenario": {"load": 1e-320}}, "scenario.load"),
    ({**_LS, "design": {"axes": {"scenario.speed": [100.0, -400.0]}}}, "design.axes.scenario.speed"),
    ({**_LS, "design": {"axes": {"scenario.load": [3.0, 20.0]}}}, "design.axes.scenario.load"),
    ({**_LS, "design": {"kind": "lhs", "samples": 3, "ranges": {"scenario.speed": [0.0, 1e308]}}},
     "design.ranges.scenario.speed"),
    ({**_LS, "design": {"kind": "random", "samples": 3, "ranges": {"scenario.load": [-20.0, 3.0]}}},
     "design.ranges.scenario.load"),
])  # fmt: skip
def test_sweep_scenario_values_axes_and_ranges_outside_the_margins(data, field):
    with pytest.raises(BadInput) as exc:
        sweep_spec.parse(data)
    assert exc.value.field == field and "must be" in exc.value.problem, str(exc.value)


def test_a_sweep_outside_the_margins_exits_2_before_any_case(tmp_path):
    (tmp_path / "s.toml").write_text('[sweep]\nscenarios = ["load-step"]\n[design.axes]\n"scenario.speed" = [50.0, 1e308]\n')
    p = _bench(tmp_path, "sweep", "s.toml", "--out", "out", "--no-progress")
    assert SPEED_RANGE in _one_line(p, 'design.axes.scenario.speed')
    assert sorted(f.name for f in tmp_path.iterdir()) == ["s.toml"]


def test_the_batch_engine_refuses_its_cases_outside_the_margins():
    from bench.batch.engine import Run, unsupported

    why = unsupported(Run(load_rig("mock"), scenario_args={"speed": 400.0}), "load-step")
    assert why is not None and "scenario.speed" in why and "[-320, 320]" in why
    assert unsupported(Run(load_rig("mock"), scenario_args={"speed": 320.0, "load": -12.0}), "load-step") is None


@pytest.mark.parametrize("name", ["mock", "mock-real", "mock-warm-fast", "lab-example"])
def test_the_margins_read_the_load_drive_the_run_builds(name):
    """The torque limit of the margins is the one the run's load drive clips at (`rig.load.torque_limit`, the
    overrides' bound): [mock.load] on a mock rig, [load] on a driver rig."""
    cfg = load_rig(name)
    if cfg.driver == "mock":
        from bench.runtime.compose import build_rig

        assert Margins.of_rig(cfg).torque_limit == build_rig(cfg, 0).load.torque_limit
    else:
        assert Margins.of_rig(cfg).torque_limit == cfg.hw["load"]["torque_limit"]


def _peaks(scn: scenarios.Scenario, omega_max: float) -> tuple[float, float, float]:
    """The test's own oracle: the largest |speed reference|, |load torque| and |flux reference| of a scenario, every
    0.5 ms of its run (every profile holds each value for 0.1 s or more), the load at speeds up to the over-speed
    trip."""
    ts = [k * 5e-4 for k in range(int(scn.duration * 2e3) + 1)]
    speeds = (-omega_max, -1.0, 0.0, 1.0, omega_max)
    flux = scn.i_mR_ref if callable(scn.i_mR_ref) else (lambda t: scn.i_mR_ref)
    return (max(abs(scn.speed_ref(t)) for t in ts),
            max(abs(scn.load(t, w)) for t in ts for w in (*speeds, scn.speed_ref(t))),
            max(abs(flux(t)) for t in ts))  # fmt: skip


# the shipped rigs that cannot run a shipped scenario inside the margins: the rated point (297 rad/s) is more than
# 0.8 x the lab rig's 350 rad/s over-speed limit (280 rad/s); refused before anything runs
OUTSIDE = {("lab-example", "hold")}


def _prepare(rig: str, name: str, **kw):
    from bench.runtime.session import RunOptions, prepare

    return prepare(RunOptions(rig=rig, scenario=name, allow_soft_realtime=True, progress=False, **kw))


def test_every_shipped_scenario_on_every_shipped_rig_is_inside_or_refused():
    """The product of the shipped rigs and scenarios: each pair either passes the run's checks (and the test's own
    peaks say it is inside) or is refused in one line naming the scenario, the value, the bound and what to give
    (and the peaks say it is outside); `OUTSIDE` pins which."""
    rigs = {p.stem: Margins.of_rig(load_rig(str(p))) for p in sorted(RIGS_DIR.glob("*.toml"))}
    assert {"mock", "emulated", "lab-example"} <= set(rigs)
    refused = set()
    for name in scenarios.SCENARIOS:
        scn = scenarios.get(name)
        peaks = {w_max: _peaks(scn, w_max) for w_max in {mg.omega_max for mg in rigs.values()}}
        for rig, mg in rigs.items():
            w, m, i = peaks[mg.omega_max]
            inside = w <= mg.omega and m <= mg.torque and i <= mg.i_mR
            try:
                _prepare(rig, name)
            except BadInput as exc:
                refused.add((rig, name))
                assert not inside, (rig, name, str(exc))
                line = str(exc)
                assert "\n" not in line and name in line and f"{w:g}" in line, line
                assert f"[{-mg.omega:g}, {mg.omega:g}] rad/s (0.8 x the rig's limits.omega_max" in line, line
                assert "--scenario-arg speed=" in line, line  # what to give instead
            else:
                assert inside, (rig, name, w, m, i)
    assert refused == OUTSIDE


def test_the_refusal_of_a_built_in_profile_from_the_command_line(tmp_path):
    """One line, exit 2, before anything runs: the built-in profile's peak, when, the bound and what to run instead;
    the parameterised ``hold`` is given a speed inside and runs that far."""
    p = _bench(tmp_path, "run", "--rig", str(RIGS_DIR / "lab-example.toml"), "--scenario", "hold")
    assert _one_line(p, "scenario.speed") == (
        "bench: error: scenario.speed: must be a number in [-280, 280] rad/s (0.8 x the rig's limits.omega_max = "
        "350), got 297, the default of 'hold': give speed a value inside (--scenario-arg speed=280)")
    assert list(tmp_path.iterdir()) == []
    rig = tmp_path / "r300.toml"  # Fig. 6.14's -250 rad/s on a rig whose margin is 240 rad/s
    rig.write_text((RIGS_DIR / "mock.toml").read_text().replace("omega_max = 400.0", "omega_max = 300.0"))
    p = _bench(tmp_path, "run", "--rig", str(rig), "--scenario", "fig6.14", "--lockstep")
    assert _one_line(p, "scenario") == (
        "bench: error: scenario: 'fig6.14' commands a speed reference of 250 rad/s at t = 0.4 s, outside [-240, 240] "
        "rad/s (0.8 x the rig's limits.omega_max = 300); a shorter --duration, a rig file whose limits allow it, or "
        "a scenario that takes its speed (--scenario hold --scenario-arg speed=240; also load-step)")
    assert sorted(f.name for f in tmp_path.iterdir()) == ["r300.toml"]  # no runs/ folder
    # inside: the same scenario cut before its first step, the parameterised hold at its bound
    plan = _prepare(str(rig), "fig6.14", duration=0.399)
    assert plan.scn.name == "fig6.14"
    assert _prepare("lab-example", "hold", scenario_args={"speed": 280.0}).scn.speed_ref(1.0) == 280.0


def test_a_scenario_object_a_load_and_a_flux_reference_are_bounded_too():
    from bench.core import load_profiles as lp
    from bench.core.scenarios import Scenario
    from bench.runtime.session import RunOptions, prepare

    def scn(speed=0.0, load=0.0, i_mR=2.5):
        return Scenario("mine", "a test's own", 1.0, lambda t: speed if t >= 0.5 else 0.0,
                        lp.steps([0.7], [load]), i_mR)  # fmt: skip

    prepare(RunOptions(scenario=scn(320.0, -12.0, 8.0), progress=False))  # at the bounds: inside
    for bad, what in ((scn(speed=-320.5), "a speed reference of 320.5 rad/s at t = 0.5 s"),
                      (scn(load=12.5), "a load torque of 12.5 N m at t = 0.7 s"),
                      (scn(i_mR=lambda t: 8.5 if t > 0.25 else 2.0), "a flux reference i_mR of 8.5 A at t = 0.251 s"),
                      (scn(i_mR=9.0), "a flux reference i_mR of 9 A at t = 0 s")):  # fmt: skip
        with pytest.raises(BadInput, match="^scenario: 'mine' commands ") as exc:
            prepare(RunOptions(scenario=bad, progress=False))
        assert what in str(exc.value), str(exc.value)
    with pytest.raises(BadInput, match=r"outside \[-8, 8\] A \(0.8 x the rig's limits.I_max = 10\)"):
        prepare(RunOptions(scenario=scn(i_mR=9.0), progress=False))
    # a run longer than the scenario: its profile goes on (here: holds), so it is checked past the end too
    with pytest.raises(BadInput, match="at t = 1.5 s"):
        prepare(RunOptions(scenario=Scenario("late", "", 1.0, lp.steps([1.5], [330.0]), lp.constant(0.0)),
                           duration=2.0, progress=False))  # fmt: skip
    prepare(RunOptions(scenario=Scenario("late", "", 1.0, lp.steps([1.5], [330.0]), lp.constant(0.0)),
                       duration=1.4, progress=False))  # fmt: skip


def test_sweeps_and_batches_check_the_built_in_profiles(tmp_path):
    rig = tmp_path / "r300.toml"
    rig.write_text((RIGS_DIR / "mock.toml").read_text().replace("omega_max = 400.0", "omega_max = 300.0"))
    with pytest.raises(BadInput, match="^scenario: 'fig6.14' commands a speed reference of 250 rad/s"):
        expand(sweep_spec.parse({"sweep": {"rig": str(rig), "scenarios": ["fig5.7", "fig6.14"]}}))
    assert len(expand(sweep_spec.parse({"sweep": {"rig": str(rig), "scenarios": ["fig5.7", "fig6.14"],
                                                  "duration": 0.39}}))) == 2  # fmt: skip
    from bench.batch.engine import Run, unsupported

    why = unsupported(Run(load_rig(str(rig))), "fig6.14")
    assert why is not None and why.startswith("scenario 'fig6.14' commands a speed reference of 250 rad/s"), why
    assert unsupported(Run(load_rig(str(rig))), "fig6.14", 0.39) is None


def test_the_over_speed_fault_is_injected_on_mock_and_emulated_rigs_only(tmp_path):
    """The trip lowered to half the largest speed reference of the run (the margins are the rig's own); a real rig
    is refused in one line, before anything runs; an unknown fault too."""
    plan = _prepare("emulated", "fig5.8", inject_fault="over-speed")
    assert plan.cfg.limits.omega_max == 75.0 and plan.fault["rig_omega_max"] == load_rig("emulated").limits.omega_max
    assert _prepare("mock", "fig4.9", inject_fault="over-speed", duration=1.0).cfg.limits.omega_max == 25.0  # 50 in 1 s
    assert _prepare("mock", "fig5.8").cfg.limits.omega_max == 400.0  # (nothing injected: the rig's)
    with pytest.raises(BadInput, match="commands no speed in the run"):
        _prepare("mock", "relay0", inject_fault="over-speed")
    p = _bench(tmp_path, "run", "--rig", str(RIGS_DIR / "lab-example.toml"), "--inject-fault", "over-speed")
    assert _one_line(p, "--inject-fault") == (
        "bench: error: --inject-fault: faults are injected on mock and emulated rigs only; rig 'lab' drives real "
        "devices (emulator.autostart = \"never\")")
    p = _bench(tmp_path, "run", "--inject-fault", "over-speed; rm -rf /")
    assert "unknown fault" in _one_line(p, "--inject-fault")
    assert list(tmp_path.iterdir()) == []


def test_every_scenario_argument_is_a_speed_or_a_load():
    for name in scenarios.SCENARIOS:
        assert set(scenarios.arguments(name)) <= set(scenarios.ARGUMENT_QUANTITIES), name
    assert set(scenarios.ARGUMENT_QUANTITIES.values()) == {SPEED, LOAD}
