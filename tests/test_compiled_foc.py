"""The compiled FOC tick (bench.controllers.foc_compiled) against the Python reference: same logs to the last bit."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bench.core.config import load as load_rig
from bench.controllers.base import ControllerContext
from bench.controllers.foc import FocController
from bench.daq import LogWriter, Topic
from bench.errors import BadInput
from bench.hal import Measurement
from bench.runtime.loop import TIMING_FIELDS
from bench.operate.requests import OFF
from bench.params import T_S_DEFAULT, MotorParams
from bench.runtime.session import RunOptions, run

pytest.importorskip("numba")
from bench.controllers import foc_compiled  # noqa: E402

DT = T_S_DEFAULT


def session(ctrl_engine: str, scenario: str, seed: int, duration: float, plant: str = "compiled",
            params: dict | None = None, replay: Path | None = None, rig: str = "mock", switches: tuple = (),
            fault: str | None = None, **limits: float) -> tuple[dict, dict, int]:  # fmt: skip
    """(summary, every topic's fields, compiled ticks run) of one in-memory session on the mock rig (``fault``:
    injected, `bench.runtime.fault_injection`)."""
    calls = [0]
    kernel = foc_compiled._STEP

    def counted(*args: object) -> complex:
        calls[0] += 1
        return kernel(*args)

    foc_compiled._STEP = counted  # the controller takes its kernel from here when it is built
    try:
        cfg = load_rig(rig)
        cfg = replace(cfg, mock={**cfg.mock, "engine": plant}, limits=replace(cfg.limits, **limits))
        summary, code = run(RunOptions(rig=cfg, scenario=scenario, seed=seed, duration=duration, progress=False,
                                       params={**(params or {}), "engine": ctrl_engine}, replay_params=replay,
                                       switches=switches, log_enabled=False, inject_fault=fault))  # fmt: skip
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
            # bit for bit (a float's bits: NaN where the other has NaN, -0.0 where -0.0); on a mismatch say where
            bits = (lambda a: a.view(np.uint64)) if x.dtype == np.float64 else (lambda a: a)  # noqa: E731
            assert np.array_equal(bits(x), bits(y)), (topic, f, int(np.argmax(bits(x) != bits(y))),
                                                      float(np.nanmax(np.abs(x - y))) if x.dtype.kind == "f" else 0)


@pytest.mark.parametrize("scenario,seed,duration,params,limits", [
    ("demo", 0, 2.0, {}, {}),
    ("fig5.7", 1, 0.8, {}, {}),
    ("load6.4.1", 3, 0.6, {}, {}),
    ("demo", 2, 1.0, {"speed_divisor": 2, "flux_divisor": 3, "current_divisor": 2}, {}),
    ("fig5.7", 4, 0.8, {"voltage_source": "measured", "delay_comp": 0.0, "u_margin": 0.8}, {}),
    ("demo", 5, 0.6, {"speed_filter_tau": 0.0, "speed_Kp": 1.5}, {"fault": "over-speed"}),  # an over-speed trip
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
    from bench.operate.requests import ParamSpace, session_params
    from bench.core.supervisor import Limits

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


SENSORLESS = {"speed_source": "estimate", "speed_estimator": "kubota", "kubota_pole_ratio": 1.1,
              "kubota_lambda_c": 1000.0}  # the robustness atlas' sensorless mode


@pytest.mark.parametrize("params", [
    {**SENSORLESS, "observer": "kubota"},  # Kubota's speed on the flux observer it shares
    {**SENSORLESS, "observer": "lpv"},  # ... with its own Kubota observer beside the LPV one
    {"speed_controller": "lpv", "lpv_speed_artifact": "robust", "current_controller": "lpv"},
    {"observer": "jl", "rr_adapt": "mras"},  # the R_r estimate handed to a tail part from inside the tick
    pytest.param({"observer": "voltage_model", "speed_estimator": "rotor_equation"}, marks=pytest.mark.slow),
    pytest.param({"observer": "kubota", "kubota_adapt": 0.0}, marks=pytest.mark.slow),
    pytest.param({"speed_controller": "lpv"}, marks=pytest.mark.slow),
    pytest.param({"current_controller": "lpv", "lpv_current_rate": 3000.0}, marks=pytest.mark.slow),
])  # fmt: skip
def test_every_part_logs_the_same_with_both_engines(params):
    """The parts the tick runs in tail regions (other observers, speed estimators, LPV laws): every logged value,
    their own internals (omega_est, the LPV speed part's scheduling) included, the same to the last bit."""
    a = session("python", "load6.4.1", 3, 0.7, params=params)
    b = session("compiled", "load6.4.1", 3, 0.7, params=params)
    assert_same_logs(a, b)


def test_switches_and_a_reset_of_the_estimate_with_tail_parts_act_alike(tmp_path):
    """A compiled run with the LPV observer and both LPV laws: a live R_r reset (the hand-over unpacks the tail
    parts around its Python code), then switches (the compiled engine hands every part's state to Python,
    `foc_compiled.detach`); the Python run's log to the bit."""
    params = {"observer": "lpv", "speed_controller": "lpv", "current_controller": "lpv", "rr_adapt": "mras"}
    log = _schedule_log(tmp_path / "sched.mcap", [
        {"tick": 600, "name": "rr_init", "old": 1.0, "new": 1.3},
        {"tick": 1200, "name": "observer", "old": "lpv", "new": "jl"},
        {"tick": 1500, "name": "speed_controller", "old": "lpv", "new": "pi"},
    ])  # fmt: skip
    a = session("python", "load6.4.1", 5, 0.7, params=params, replay=log)
    b = session("compiled", "load6.4.1", 5, 0.7, params=params, replay=log)
    assert a[0]["operator"]["applied"] == b[0]["operator"]["applied"] == 3
    assert b[2] == 1200  # the kernel until the first switch (tick 1200), Python from there
    assert_same_logs(a, b)
    assert not np.array_equal(a[1]["/ctrl"]["rr_hat"], session("python", "load6.4.1", 5, 0.7, params=params)[1]
                              ["/ctrl"]["rr_hat"])  # (the changes acted)


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
            c.omega, c.u_s_obs, c.i_sr, c._inv_Tr, c._advance, c._u_scale, c._div, c._use_measured_u) + (
            () if c.fw is None else (c.fw.factor, c.fw.u_fw, c.fw.k, c.fw.lo, c.fw.T))  # fmt: skip


@pytest.mark.parametrize("params", [{}, {"voltage_source": "measured", "speed_divisor": 3, "current_divisor": 2,
                                         "speed_filter_tau": 0.0},
                                    {"field_weakening": "on", "current_divisor": 2, "flux_divisor": 3}])  # fmt: skip
def test_steps_state_retune_and_reset_act_alike(params):
    """Tick by tick: the output, internals() and every state attribute (values and types), through skipped ticks,
    a counter wrap, voltage saturation (with field weakening: the factor lowered and raised again), live parameter
    changes, state set from outside and a reset."""
    ctrls = [FocController(_ctx(), engine=e, **params) for e in ("python", "compiled")]
    assert ctrls[0]._kernel is None and ctrls[1]._kernel is not None
    assert type(ctrls[1]).__name__ == "FocController" and isinstance(ctrls[1], FocController)
    assert _state(ctrls[0]) == _state(ctrls[1])
    changes = {300: ("speed_Kp", 2.0), 400: ("current_wc", 300.0), 500: ("flux_Km", 1.5), 600: ("delay_comp", 3.0),
               700: ("speed_Ti", 0.01)}  # fmt: skip
    fw = ctrls[0].fw is not None
    if fw:
        assert type(ctrls[1].fw).__name__ == "FieldWeakening" and ctrls[1].fields[-1] == "fw"
        changes.update({250: ("fw_gain", 400.0), 650: ("fw_u", 0.8), 900: ("fw_min", 0.9), 1200: ("fw_u", 0.99)})
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
                if fw:
                    c.fw.factor = 0.75
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
    if fw:  # the factor went down at the limit to its floors (0.5, then 0.9) and up again, more than once
        f = np.array([r[1][-1] for r in a if r[0] not in ("set", "reset")])
        assert np.any(f == 0.5) and np.any(f == 0.9) and np.sum(np.diff(f) > 0) >= 5 and np.sum(np.diff(f) < 0) > 50
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert repr(x) == repr(y), (i, x, y)  # repr: the same values (to the bit) of the same types


def test_unsupported_configuration_is_refused_or_falls_back():
    from bench.core.inverter_error import InverterError

    ctx = replace(_ctx(), inverter_error=InverterError((0.5, 2.0), (3.0, 4.0)))
    with pytest.raises(BadInput) as ei:
        FocController(ctx, engine="compiled")  # (inverter_comp = auto: the observers get the compensated reference)
    assert ei.value.field == "controller.foc.engine" and "[inverter_error]" in str(ei.value), str(ei.value)
    assert "\n" not in str(ei.value)
    auto = FocController(ctx, engine="auto")
    assert auto._kernel is None and type(auto) is FocController  # python, unchanged
    assert FocController(ctx, engine="compiled", inverter_comp="off")._kernel is not None
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
    from bench.workflows.sweep import cases as sweep_cases
    from bench.workflows.sweep import spec

    base = sweep_cases.expand(spec.parse({}))
    for engine in ("python", "compiled", "auto"):
        cs = sweep_cases.expand(spec.parse({"params": {"engine": engine}}))
        assert [c.case_id for c in cs] == [c.case_id for c in base]
    other = sweep_cases.expand(spec.parse({"params": {"speed_Kp": 0.7}}))
    assert other[0].case_id != base[0].case_id


def test_a_sweep_case_runs_the_compiled_controller(monkeypatch):
    from bench.workflows.sweep import cases as sweep_cases
    from bench.workflows.sweep import spec

    import bench.runtime.session as session_mod

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


def test_the_arithmetic_the_kernels_compile_is_cpythons():
    """The arithmetic numba compiles into the kernels (a float operand of complex arithmetic as complex(x, 0.0), Smith's
    division) and the helpers of bench.controllers.kernel_math compiled, against CPython itself, special values
    included (a whole session exercises only a few thousand values of each: ``x * x`` in place of ``x ** 2`` differs
    in about 1 of 1000 squares)."""
    from numba import njit

    from bench.controllers import kernel_math as km, observers_compiled  # noqa: F401 (registers kernel_math)

    fmul, cmul = njit(lambda a, w: a * w), njit(lambda z, w: z * w)
    cquot, rquot = njit(lambda z, w: z / w), njit(lambda z, c: z / c)
    atan2, absc = njit(lambda a, b: km.atan2(a, b)), njit(lambda z: km.abs_checked(z))
    square = njit(lambda x, two: km.square(x, two))
    rng = np.random.default_rng(3)
    special = [0.0, -0.0, 1.0, -1.0, 0.5, 3.0, 1e-310, -1e-310, 1e300, -1e300, math.inf, -math.inf, math.nan]
    drawn = [float(v) for v in rng.normal(0.0, 5.0, 20000)] + [float(v) for v in rng.uniform(-1e3, 1e3, 2000)]
    pairs = [(a, b) for a in special for b in special] + [(float(a), float(b)) for a, b in rng.normal(0, 3, (3000, 2))]
    diff = [x for x in special + drawn if _outcome(square, x, 2.0) != _outcome(lambda v: v**2, x)]
    assert not diff and sum(x * x != x**2 for x in drawn) > 5  # (these values would catch x * x)
    for (a, b), (c, d) in zip(pairs, pairs[::-1]):
        z, w = complex(a, b), complex(c, d)
        assert _outcome(fmul, a, w) == _outcome(lambda: a * w), (a, w)
        assert _outcome(cmul, z, w) == _outcome(lambda: z * w), (z, w)
        assert _outcome(cquot, z, w) == _outcome(lambda: z / w), (z, w)
        assert _outcome(rquot, z, c) == _outcome(lambda: z / c), (z, c)
        assert _outcome(atan2, a, b) == _outcome(math.atan2, a, b), (a, b)
        assert _outcome(km.atan2, a, b) == _outcome(math.atan2, a, b), (a, b)
        if math.isfinite(a):  # the kernels' abs sees finite values
            assert _outcome(absc, z) == _outcome(abs, z), z
    assert _outcome(absc, complex(1.5e308, 1.5e308)) == "OverflowError" == _outcome(abs, complex(1.5e308, 1.5e308))


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


# --- the on-line R_r estimate (rr_adapt = mras) in the kernel ------------------------------------------------------
_RR_ATTRS = ("T", "_inv_T", "Ls_p", "Lm_p", "_bow", "_alpha", "_settle", "_restart", "b_nom", "b_lo", "b_hi", "gain",
             "w_min", "iq_min", "init", "imr_min", "b", "R_r", "_i_prev", "_t_prev", "i_m", "gate", "q_ref", "q_adj",
             "_e_f", "_q_f", "_r2_f", "_open", "_warm")  # fmt: skip


def _rr_state(c: FocController) -> tuple:
    return tuple(getattr(c.rr, a) for a in _RR_ATTRS)


@pytest.mark.parametrize("params", [{}, {"voltage_source": "measured", "speed_divisor": 2, "current_divisor": 2}])
def test_r_r_estimate_steps_state_retune_and_reset_act_alike(params):
    """Both engines fed the same measurements of a loaded mock rig whose R_r steps +20 %, tick by tick: the output,
    internals() (rr_hat, rr_gate) and every state attribute of the controller and its RrMRAS (values and types),
    through the gate opening and closing, the estimate moving, skipped ticks, non-finite voltages (measured),
    live changes of every rr_* tunable (rr_init resets the estimate), state set from outside and a reset."""
    from bench.hal import Command
    from mock_hw.plant import MockConfig, make_mock_rig

    ctx = ControllerContext(T_s=DT, motor=MotorParams(), I_max=10.0, counts_per_rev=4096, enc_modulus=1 << 16)
    p = {"rr_adapt": "mras", "rr_gain": 20.0, **params}
    ctrls = [FocController(ctx, engine=e, **p) for e in ("python", "compiled")]
    assert ctrls[0]._kernel is None and ctrls[1]._kernel is not None
    assert type(ctrls[1].rr).__name__ == "RrMRAS" and ctrls[1].fields[-2:] == ("rr_hat", "rr_gate")
    assert _state(ctrls[0]) == _state(ctrls[1]) and repr(_rr_state(ctrls[0])) == repr(_rr_state(ctrls[1]))
    changes = {3300: ("rr_init", 1.3), 3900: ("rr_w_min", 150.0), 4300: ("rr_w_min", 20.0), 4600: ("rr_iq_min", 9.0),
               4800: ("rr_iq_min", 0.8), 5000: ("rr_gain", 5.0), 5600: ("rr_init", 0.7)}  # fmt: skip
    rig = make_mock_rig(MockConfig.from_dict({}), dt=DT)
    rows: list[list] = [[], []]
    t, k = 0.0, 0
    with rig:
        while k < 7000:
            t += DT * (3 if k % 1111 == 700 else 1)  # skipped ticks: the estimator crosses the gap, unused
            if k == 1500:
                rig.truth.motor.set_resistances(rig.truth.motor.params.R_s, 1.2 * MotorParams().R_r)
            meas = rig.read(t)
            if k in (2500, 2501, 4100):
                meas = replace(meas, u_a=math.nan if k != 4100 else math.inf)  # a torn voltage sample
            w_ref = 0.0 if t < 0.1 else min(100.0, 200.0 * (t - 0.1))
            for c, out in zip(ctrls, rows):
                if k in changes:
                    c.set_param(*changes[k])
                if k == 6000:
                    c.rr.b = 1.1 * c.rr.b  # state set from outside: the internals row follows
                    c.rr.gate = 3
                    out.append(("set", c.internals()))
                if k == 6400:
                    c.reset()
                    out.append(("reset", c.internals(), _state(c), _rr_state(c)))
                u = c.step(meas, w_ref, 2.5)
                out.append((u, c.internals(), _state(c), _rr_state(c)))
            rig.write(Command(u, True, 0.0 if t < 0.4 else 5.0))
            k += 1
    a, b = rows
    assert len(a) == len(b)
    for i, (x, y) in enumerate(zip(a, b)):
        assert repr(x) == repr(y), (i, x, y)  # repr: the same values (to the bit) of the same types
    # what the run went through (else the comparison proves little)
    ticks = [r for r in a if r[0] not in ("set", "reset")]
    gate = np.array([r[1][-1] for r in ticks])
    rr_hat = np.array([r[1][-2] for r in ticks])
    R_r = MotorParams().R_r
    assert np.sum(gate == 0) > 1500 and np.sum(gate > 0) > 1500, "open and closed"
    assert np.sum(np.diff(gate == 0) != 0) >= 4, "opens and closes more than once"
    assert {1, 2, 16} <= {int(g) & m for g in gate for m in (1, 2, 16)}, "closed by frequency, load, bad input"
    assert rr_hat[3299] > 1.1 * R_r, "adapted towards the stepped R_r"
    assert rr_hat[3300] == pytest.approx(1.3 * R_r, rel=0.01), "rr_init reset it"
    assert len(np.unique(rr_hat[3300:3900])) > 100, "and it moved again"
    assert rr_hat[5599] != rr_hat[5600] == pytest.approx(0.7 * R_r, rel=0.01)
    assert rr_hat[6400] == pytest.approx(0.7 * R_r, rel=1e-12) and gate[6400] == 16, "reset: to rr_init, no i_prev"


def test_a_warming_rotor_session_logs_the_same_with_both_engines(tmp_path):
    """Scenario warmup on rigs/mock-warm-fast.toml (the true R_r rises as the rotor warms) with rr_adapt = mras, and
    live changes of the estimator's tunables (rr_init resets the estimate, rr_w_min closes and opens the gate):
    every logged field of every topic the same to the bit."""
    log = _schedule_log(tmp_path / "sched.mcap", [
        {"tick": 6000, "name": "rr_init", "old": 1.0, "new": 1.25},
        {"tick": 7500, "name": "rr_w_min", "old": 20.0, "new": 250.0},
        {"tick": 8400, "name": "rr_w_min", "old": 250.0, "new": 20.0},
        {"tick": 9000, "name": "rr_gain", "old": 3.0, "new": 8.0},
        {"tick": 9600, "name": "rr_iq_min", "old": 0.8, "new": 0.5},
    ])  # fmt: skip
    p = {"rr_adapt": "mras"}
    a = session("python", "warmup", 9, 3.5, params=p, replay=log, rig="mock-warm-fast")
    b = session("compiled", "warmup", 9, 3.5, params=p, replay=log, rig="mock-warm-fast")
    assert a[0]["operator"]["applied"] == b[0]["operator"]["applied"] == 5
    assert_same_logs(a, b)
    ctrl, truth = a[1]["/ctrl"], a[1]["/truth"]
    gate, rr_hat = ctrl["rr_gate"], ctrl["rr_hat"]
    assert truth["r_r"][-1] > 1.05 * truth["r_r"][0], "the rotor warmed"
    assert np.sum(gate == 0) > 3000 and np.all(gate[7510:8400] == 1) and np.all(gate[8500:] == 0), "open, shut, open"
    assert len(np.unique(rr_hat[3000:6000])) > 1000 and rr_hat[6000] == pytest.approx(1.25 * 3.3, rel=0.01)



@pytest.mark.parametrize("current", ["pi", "lpv"])
def test_the_rated_point_on_a_hot_rotor_through_the_voltage_limit_logs_the_same(current):
    """Scenario hold (297 rad/s, 10 N m from 1 s) on rigs/mock-hot-rotor.toml (R_r 1.5 x nominal) with rr_adapt = mras:
    the stale estimate over-excites the motor at the load step, the current loop (the PI or the quasi-LPV part in a
    tail region) reaches its voltage limit, the estimate's gate closes (bit 4), the field weakening lowers the flux
    and lets go again: every logged field the same to the bit."""
    p = {"rr_adapt": "mras", "current_controller": current}
    a = session("python", "hold", 11, 1.6, params=p, rig="mock-hot-rotor")
    b = session("compiled", "hold", 11, 1.6, params=p, rig="mock-hot-rotor")
    assert_same_logs(a, b)
    ctrl = a[1]["/ctrl"]
    assert np.sum(ctrl["u_sat"]) > 20 and np.sum((ctrl["rr_gate"].astype(int) & 4) != 0) > 20, "at the limit, gated"
    assert np.min(ctrl["fw"]) < 0.95 and ctrl["fw"][-1] > np.min(ctrl["fw"]), "weakened, and on the way back"


def test_a_switch_hands_the_estimate_from_the_compiled_to_the_python_engine_exactly():
    """The compiled engine with the estimate runs to the first switch of a part (foc_compiled.detach): the
    estimator's state moves to the Python objects exactly, and the run logs as the Python engine's."""
    p = {"rr_adapt": "mras"}
    sw = ((2.2, "observer", "jl"), (2.6, "current_controller", "lpv"))
    a = session("python", "warmup", 10, 3.0, params=p, rig="mock-warm-fast", switches=sw)
    b = session("compiled", "warmup", 10, 3.0, params=p, rig="mock-warm-fast", switches=sw)
    assert a[0]["operator"]["applied"] == b[0]["operator"]["applied"] == 2 and b[0]["switches"][0]["to"] == "jl"
    assert abs(b[2] - 2.2 / DT) <= 1, b[2]  # the kernel ran up to the first switch
    assert_same_logs(a, b)
    gate = a[1]["/ctrl"]["rr_gate"]
    assert np.all(gate[int(2.0 / DT):] == 0), "the estimate adapts across the switches"


def test_the_r_r_estimator_alone_on_many_random_ticks():
    """The compiled RrMRAS.update (rr_adapt.mras_update, compiled by foc_compiled) against the Python one on 30000
    ticks of random inputs around an
    operating point (gate mostly open, so the estimate moves on most ticks; now and then a skipped tick, a saturated
    tick, a non-finite input): the return value and every state attribute after each tick, to the bit. Many more
    values than a session, so a rounding difference (x * x for x ** 2, another operation order) shows here."""
    from bench.controllers import rr_adapt
    from bench.controllers.rr_adapt import RrMRAS

    m = MotorParams()
    py = RrMRAS(m, DT, 50.0, 20.0, 0.8, 1.0)
    c = FocController(_ctx(), engine="compiled", rr_adapt="mras", rr_gain=50.0)
    assert foc_compiled._mras_update.py_func is rr_adapt.mras_update  # the very function the Python engine runs
    xr = c.rr.s
    assert np.shares_memory(xr, c._buf)  # the estimator views its region of the kernel's buffer
    c.rr.reset()
    assert repr(_rr_state(c)) == repr(tuple(getattr(py, a) for a in _RR_ATTRS))
    rng = np.random.default_rng(11)
    t, n_true, n_sq = 0.0, 0, 0
    for k in range(30000):
        t += DT * (4 if k % 2999 == 1000 else 1)
        th = 80.0 * t
        rot = complex(math.cos(th), math.sin(th))
        i_s = (2.5 + 3j + complex(*rng.normal(0.0, 0.3, 2))) * rot
        u_s = (30.0 + 150j + complex(*rng.normal(0.0, 5.0, 2))) * rot  # R_r_hat ~0.6-0.8 x nominal
        w, w_mR = 75.0 + rng.normal(0.0, 1.0), 80.0 + rng.normal(0.0, 10.0)
        i_sq, i_mR, sat = 3.0 + rng.normal(0.0, 0.5), 2.5 + rng.normal(0.0, 0.2), bool(rng.random() < 0.001)
        if k % 4001 == 2000:
            u_s = complex(math.nan, 1.0)
        elif k % 4001 == 3000:
            i_mR = 0.0
        r = (i_sq / i_mR) if i_mR > 0 else 0.0
        n_sq += r * r != r**2  # ticks at which x * x for x ** 2 would differ
        args = (t, i_s, u_s, w, w_mR, i_sq, i_mR, sat)
        ra = py.update(*args)
        rb = foc_compiled._mras_update(xr, *args)
        n_true += ra
        sa, sb = tuple(getattr(py, a) for a in _RR_ATTRS), _rr_state(c)
        assert ra == rb and repr(sa) == repr(sb), (k, [(n, u, v) for n, u, v in zip(_RR_ATTRS, sa, sb) if u != v])
    assert n_true > 20000 and py.b_lo < py.b < py.b_hi and n_sq > 3, (n_true, py.b / py.b_nom, n_sq)


def test_perf_of_the_adaptation_in_both_engines():
    """`bench perf observers`' rr_adapt_engines (short): the four ticks measured on a stretch where the estimate
    adapts, the compiled ones the cheaper (by far: ~1 us against ~5 us with the estimate)."""
    from bench.perf.observers import rr_adapt_engines

    out = rr_adapt_engines(duration=1.8, repeats=1, skip=1.5)
    assert out["ticks"] == 900 and out["gate_open_fraction"] > 0.9, out
    assert 0 < out["compiled_mras_us"] < out["python_mras_us"] and out["compiled_off_us"] < out["python_off_us"], out
    assert out["adaptation_python_us"] == out["python_mras_us"] - out["python_off_us"]
