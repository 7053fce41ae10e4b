"""The compiled FOC tick (bench.controllers.foc_compiled) against the Python reference: same logs to the last bit."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bench.config import load as load_rig
from bench.controllers.base import ControllerContext
from bench.controllers.foc import FocController
from bench.daq import LogWriter, Topic
from bench.errors import BadInput
from bench.hal import Measurement
from bench.loop import TIMING_FIELDS
from bench.operator import OFF
from bench.params import T_S_DEFAULT, MotorParams
from bench.session import RunOptions, run

pytest.importorskip("numba")
from bench.controllers import foc_compiled  # noqa: E402

DT = T_S_DEFAULT


def session(ctrl_engine: str, scenario: str, seed: int, duration: float, plant: str = "compiled",
            params: dict | None = None, replay: Path | None = None, **limits: float) -> tuple[dict, dict, int]:  # fmt: skip
    """(summary, every topic's fields, compiled ticks run) of one in-memory session on the mock rig."""
    calls = [0]
    kernel = foc_compiled._STEP

    def counted(*args: object) -> complex:
        calls[0] += 1
        return kernel(*args)

    foc_compiled._STEP = counted  # the controller takes its kernel from here when it is built
    try:
        cfg = load_rig("mock")
        cfg = replace(cfg, mock={**cfg.mock, "engine": plant}, limits=replace(cfg.limits, **limits))
        summary, code = run(RunOptions(rig=cfg, scenario=scenario, seed=seed, duration=duration, progress=False,
                                       params={**(params or {}), "engine": ctrl_engine}, replay_params=replay,
                                       log_enabled=False))  # fmt: skip
    finally:
        foc_compiled._STEP = kernel
    rec = summary.pop("record")
    return summary, {tp: rec.read(tp) for tp in rec.topics()}, calls[0]


def assert_same_logs(a: tuple[dict, dict, int], b: tuple[dict, dict, int]) -> None:
    (sp, lp, np_), (sc, lc, nc) = a, b
    assert np_ == 0 and 0.5 * sc["ticks"] < nc <= sc["ticks"], "only the compiled run calls the kernel, every tick"
    assert sp["ticks"] == sc["ticks"] and sp.get("trip_cause") == sc.get("trip_cause")
    assert set(lp) == set(lc) and {"/rig", "/ctrl", "/truth"} <= set(lp)
    assert set(lp["/ctrl"]) >= {f.lower() for f in FocController.fields}  # (logged in lower case)
    for topic in lp:
        assert set(lp[topic]) == set(lc[topic]), topic
        for f, x in lp[topic].items():
            if f in TIMING_FIELDS:
                continue
            y = lc[topic][f]
            # bit for bit; on a mismatch say where and how far off it is
            assert np.array_equal(x, y), (topic, f, int(np.argmax(x != y)), float(np.max(np.abs(x - y))))


@pytest.mark.parametrize("scenario,seed,duration,params,limits", [
    ("demo", 0, 2.0, {}, {}),
    ("fig5.7", 1, 0.8, {}, {}),
    ("load6.4.1", 3, 0.6, {}, {}),
    ("demo", 2, 1.0, {"speed_divisor": 2, "flux_divisor": 3, "current_divisor": 2}, {}),
    ("fig5.7", 4, 0.8, {"voltage_source": "measured", "delay_comp": 0.0, "u_margin": 0.8}, {}),
    ("demo", 5, 0.6, {"speed_filter_tau": 0.0, "speed_Kp": 1.5}, {"omega_max": 30.0}),  # an over-speed trip
])  # fmt: skip
def test_sessions_log_the_same_with_both_controller_engines(scenario, seed, duration, params, limits):
    a = session("python", scenario, seed, duration, params=params, **limits)
    b = session("compiled", scenario, seed, duration, params=params, **limits)
    assert_same_logs(a, b)
    if limits:
        assert b[0].get("trip_cause"), "the run was meant to trip"


def test_the_same_on_the_python_plant():
    assert_same_logs(session("python", "demo", 6, 1.0, plant="python"),
                     session("compiled", "demo", 6, 1.0, plant="python"))  # fmt: skip


def _schedule_log(path: Path, events: list[dict]) -> Path:
    """A log holding only a schedule of applied parameter changes (as a live run's log would; test_operator)."""
    from bench.operator import ParamSpace, session_params
    from bench.supervisor import Limits

    tun = {k: p for k, p in FocController.schema.items() if p.tunable}
    sp = ParamSpace(tun | session_params(Limits(), 15.0), {k: p.default for k, p in tun.items()},
                    [k for k in FocController.schema if k not in tun])  # fmt: skip
    w = LogWriter(path, [Topic("/rig", "imbench_msgs/msg/Dummy", [("t", "float64"), ("tick", "int64")])],
                  metadata={"run": {"rate_hz": 1.0 / DT}}, operator=sp.describe(), timing=False)  # fmt: skip
    for i, e in enumerate(events):
        w.event({"seq": i + 1, "t": e["tick"] * DT, "who": "test", "note": "", "status": "applied", "kind": "set",
                 "log_time": int(e["tick"] * DT * 1e9), **e})  # fmt: skip
    w.close()
    return path


def test_live_parameter_changes_act_alike(tmp_path):
    log = _schedule_log(tmp_path / "sched.mcap", [
        {"tick": 900, "name": "speed_Kp", "old": 0.6, "new": 1.4},
        {"tick": 1200, "name": "current_wc", "old": 1000.0, "new": 600.0},
        {"tick": 1500, "name": "flux_Km", "old": 4.0, "new": 2.5},
        {"tick": 1800, "name": "delay_comp", "old": 1.5, "new": 0.5},
        {"tick": 2100, "name": "speed_Ti", "old": 0.04, "new": 0.02},
        {"tick": 2400, "name": "omega_r_ref_override", "old": OFF, "new": -40.0},
    ])  # fmt: skip
    a = session("python", "demo", 8, 1.5, replay=log)
    b = session("compiled", "demo", 8, 1.5, replay=log)
    assert a[0]["operator"]["applied"] == b[0]["operator"]["applied"] == 6
    assert_same_logs(a, b)
    i_sq = a[1]["/ctrl"]["i_sq_ref"]
    assert not np.array_equal(i_sq, session("python", "demo", 8, 1.5)[1]["/ctrl"]["i_sq_ref"])  # the changes acted


# --- the controller object itself --------------------------------------------------------------------------
def _ctx() -> ControllerContext:
    return ControllerContext(T_s=DT, motor=MotorParams(), I_max=10.0, counts_per_rev=4096, enc_modulus=5000)


def _meas(k: int, t: float) -> Measurement:
    """A synthetic measurement: rotating currents and voltages, a counter that wraps, a low DC link now and then."""
    th = 40.0 * t
    i = [4.0 * math.cos(th - n * 2.0 * math.pi / 3.0) + 0.3 * math.sin(7.0 * k) for n in range(3)]
    u = [80.0 * math.cos(th + 0.3 - n * 2.0 * math.pi / 3.0) for n in range(3)]
    count = (4900 + 3 * k + (k * k) % 7) % 5000
    return Measurement(t, *i, *u, count, -1, 540.0 if k % 200 < 150 else 60.0, True, False, (0, 0, 0), (0, 0, 0))


def _state(c: FocController) -> tuple:
    e, o, s, f, cu = c.encoder, c.observer, c.speed, c.flux, c.current
    return (e.modulus, e.half, e.k_omega, e.k_theta, e.T_s, e.tau, e.alpha, e._late, e._prev, e.d, e._prev_t,
            e.omega_r, e.omega_raw, e.theta_r, o._b, o.T_s, o.i_m, o._i_s_prev, s.k, s.I_max, s.K_p, s.k_i, s.x,
            s.m_e_ref, f.K_m, f.I_max, cu.K_p, cu.k_i, cu.Ls_p, cu.Lm_p, cu.Rr_p, cu.x, cu.saturated, c.k,
            c.i_sd_ref, c.i_sq_ref, c.u_sr, c.u_s_ref, c._u_hist, c.i_m_hat, c.i_mR_hat, c.rho, c.omega_mR, c._rot,
            c.omega, c.u_s_obs, c.i_sr, c._inv_Tr, c._advance, c._u_scale, c._div, c._use_measured_u)  # fmt: skip


@pytest.mark.parametrize("params", [{}, {"voltage_source": "measured", "speed_divisor": 3, "current_divisor": 2,
                                         "speed_filter_tau": 0.0}])  # fmt: skip
def test_steps_state_retune_and_reset_act_alike(params):
    """Tick by tick: the output, internals() and every state attribute (values and types), through skipped ticks,
    a counter wrap, voltage saturation, live parameter changes, state set from outside and a reset."""
    ctrls = [FocController(_ctx(), engine=e, **params) for e in ("python", "compiled")]
    assert ctrls[0]._kernel is None and ctrls[1]._kernel is not None
    assert type(ctrls[1]).__name__ == "FocController" and isinstance(ctrls[1], FocController)
    assert _state(ctrls[0]) == _state(ctrls[1])
    changes = {300: ("speed_Kp", 2.0), 400: ("current_wc", 300.0), 500: ("flux_Km", 1.5), 600: ("delay_comp", 3.0),
               700: ("speed_Ti", 0.01)}  # fmt: skip
    n_sat = 0
    for c in ctrls:
        t, k = 0.0, 0
        rows = []
        while k < 1500:
            t += DT * (3 if k % 97 == 50 else 1)  # skipped ticks: the encoder divides by the elapsed time
            if k in changes:
                c.set_param(*changes[k])
            if k == 800:
                c.i_sd_ref = 1.25  # state set from outside: the internals row follows
                c.speed.x = 0.5
                rows.append(("set", c.internals()))
            if k == 1000:
                c.reset()
                rows.append(("reset", c.internals(), _state(c)))
            u = c.step(_meas(k, t), 30.0 * math.sin(3.0 * t), 2.0)
            rows.append((u, c.internals(), _state(c)))
            n_sat += c.current.saturated
            k += 1
        c.rows = rows
    assert n_sat > 10, "the test is meant to saturate the voltage now and then"
    a, b = ctrls[0].rows, ctrls[1].rows
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert repr(x) == repr(y), (i, x, y)  # repr: the same values (to the bit) of the same types


def test_unsupported_configuration_is_refused_or_falls_back():
    for params, words in (({"observer": "jl"}, "observer = 'current_model' only, got 'jl'"),
                          ({"speed_estimator": "rotor_equation"}, "speed_estimator = 'none' only, got 'rotor_equation'"),
                          ({"current_controller": "lpv"}, "current_controller = 'pi' only, got 'lpv'")):  # fmt: skip
        with pytest.raises(BadInput) as ei:
            FocController(_ctx(), engine="compiled", **params)
        assert ei.value.field == "controller.foc.engine" and words in str(ei.value), str(ei.value)
        assert "\n" not in str(ei.value)
    auto = FocController(_ctx(), engine="auto", observer="jl")
    assert auto._kernel is None and type(auto) is FocController  # python, unchanged
    assert FocController(_ctx(), engine="auto")._kernel is not None
    assert FocController(_ctx())._kernel is None  # the default is the reference
    with pytest.raises(BadInput, match="engine"):
        FocController(_ctx(), engine="fast")
    with pytest.raises(BadInput, match="cannot change while running"):
        FocController(_ctx(), engine="auto").set_param("engine", "python")


def test_relay_tune_has_no_engine():
    from bench.controllers.relay import RelayTuneController

    assert "engine" not in RelayTuneController.schema
    assert RelayTuneController(_ctx())._kernel is None


def test_the_sweep_case_id_does_not_depend_on_the_engine():
    from bench.sweep import cases as sweep_cases
    from bench.sweep import spec

    base = sweep_cases.expand(spec.parse({}))
    for engine in ("python", "compiled", "auto"):
        cs = sweep_cases.expand(spec.parse({"params": {"engine": engine}}))
        assert [c.case_id for c in cs] == [c.case_id for c in base]
    other = sweep_cases.expand(spec.parse({"params": {"speed_Kp": 0.7}}))
    assert other[0].case_id != base[0].case_id


def test_a_sweep_case_runs_the_compiled_controller(monkeypatch):
    from bench.sweep import cases as sweep_cases
    from bench.sweep import spec

    import bench.session as session_mod

    seen: list[dict] = []

    def spy(opts):  # noqa: ANN001, ANN202
        seen.append(dict(opts.params))
        raise RuntimeError("stop here")

    monkeypatch.setattr(session_mod, "run", spy)
    case = sweep_cases.expand(spec.parse({}))[0]
    with pytest.raises(RuntimeError):
        sweep_cases.run_session(case)
    assert seen[-1].get("engine") == "auto"
    case = sweep_cases.expand(spec.parse({"params": {"engine": "python"}}))[0]
    with pytest.raises(RuntimeError):
        sweep_cases.run_session(case)
    assert seen[-1].get("engine") == "python"


def test_the_controller_calls_the_kernel_without_the_dispatcher():
    from numba.core.dispatcher import Dispatcher

    c = FocController(_ctx(), engine="compiled")
    assert not isinstance(c._kernel, Dispatcher)
    twin = c._buf.copy()
    m = _meas(0, 0.0)
    args = (m.t, m.i_a, m.i_b, m.i_c, m.u_a, m.u_b, m.u_c, m.enc_count, m.u_dc, 10.0, 2.0)
    assert c._kernel(c._buf, *args) == foc_compiled.step(twin, *args) and c._buf.tobytes() == twin.tobytes()


def _outcome(f, *args: object) -> str:  # noqa: ANN001
    """repr of the result (the same bits, NaN aside, of the same types), or the exception's type."""
    try:
        r = f(*args)
    except (ArithmeticError, ValueError) as exc:
        return type(exc).__name__
    return repr(complex(*r) if isinstance(r, tuple) else r)


def test_the_arithmetic_helpers_are_cpythons():
    """bench.cpython_arith against CPython itself, special values included (a whole session exercises only a
    few thousand values of each: ``x * x`` in place of ``x ** 2`` differs in about 1 of 1000 squares)."""
    import cmath

    from bench import cpython_arith as ca

    rng = np.random.default_rng(3)
    special = [0.0, -0.0, 1.0, -1.0, 0.5, 3.0, 1e-310, -1e-310, 1e300, -1e300, math.inf, -math.inf, math.nan]
    drawn = [float(v) for v in rng.normal(0.0, 5.0, 20000)] + [float(v) for v in rng.uniform(-1e3, 1e3, 2000)]
    pairs = [(a, b) for a in special for b in special] + [(float(a), float(b)) for a, b in rng.normal(0, 3, (3000, 2))]
    diff = [x for x in special + drawn if _outcome(ca.fsq, x, 2.0) != _outcome(lambda v: v**2, x)]
    assert not diff and sum(x * x != x**2 for x in drawn) > 5  # (these values would catch x * x)
    for (a, b), (c, d) in zip(pairs, pairs[::-1]):
        z, w = complex(a, b), complex(c, d)
        assert _outcome(ca.fmul, a, c, d) == _outcome(lambda: a * w), (a, w)
        assert _outcome(ca.cmul, a, b, c, d) == _outcome(lambda: z * w), (z, w)
        assert _outcome(ca.cquot, a, b, c, d) == _outcome(lambda: z / w), (z, w)
        assert _outcome(ca.cquot, a, b, c, 0.0) == _outcome(lambda: z / c), (z, c)
        assert _outcome(ca.atan2_, a, b) == _outcome(math.atan2, a, b), (a, b)
        if math.isfinite(a):  # the kernel's abs, exp and rect see finite values (NaN: the angle only)
            assert _outcome(ca.abs_, a, b) == _outcome(abs, z), z
            assert _outcome(ca.crect, 1.0, b) == _outcome(cmath.rect, 1.0, b), b
            if math.isfinite(b):
                assert _outcome(ca.cexp, a, b) == _outcome(cmath.exp, z), z
    assert _outcome(ca.cexp, 710.0, 1.0) == "OverflowError" and _outcome(ca.crect, 1.0, math.inf) == "ValueError"
    assert _outcome(ca.abs_, 1.5e308, 1.5e308) == "OverflowError" == _outcome(abs, complex(1.5e308, 1.5e308))


def test_a_failing_tick_raises_what_python_raises():
    """A negative DC link with no current error: u_max / |u| divides by zero in both engines, with the same message
    (the loop trips on it, naming the exception)."""
    ctrls = [FocController(_ctx(), engine=e, delay_comp=0.0) for e in ("python", "compiled")]
    m = Measurement(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, -1, -10.0, True, False, (0, 0, 0), (0, 0, 0))
    out = []
    for c in ctrls:
        with pytest.raises(ZeroDivisionError) as ei:
            c.step(m, 0.0, 0.0)
        out.append(str(ei.value))
    assert out[0] == out[1] == "float division by zero"
