"""The batch engine: many lockstep sessions of the mock rig and the FOC in one compiled loop.

`simulate` runs N cases (a rig file, a seed, the FOC's parameters each) of one scenario and duration and
returns one session summary per case, the numbers `bench.runtime.session.run` gives for the same case without a
log (`bench.runtime.run_summary.summarize`: speed and magnetising-current errors, load steps, estimation errors; trip
cause and time, ticks). The cases advance in `bench.batch.kernel.run_all`, a numba loop parallel over
the cases, which calls the same compiled plant (`mock_hw.compiled.advance`) and FOC tick
(`bench.controllers.foc_compiled.step`) as the scalar engines, on each case's own state buffers built
here by the same constructors a session uses: every case is the scalar run of that case, to the bit in
its trajectory; of its summary, ticks, counts, trip tick and cause are the same bits, the error numbers
within 1e-12 relative or 1e-14 absolute, flux angles within 1e-13 deg (`rows_differ`: the session computes
them from the log with numpy: pairwise sums, its own complex abs, a SIMD arctan2; the loop with compensated
sums and C's hypot and atan2; tests/test_batch.py).

What it covers (`unsupported` says why a case is not): the mock rig (any `[mock]` setting: the compiled
plant covers them all), the FOC with every part the compiled kernels cover (`foc_compiled.pack`: every flux
observer and speed estimator, PI and LPV speed and current parts; not the on-line R_r estimate, whose metrics
the loop does not keep, nor the field weakening, whose voltage-limit report it does not keep, nor a rig's
[inverter_error] compensation), the supervisor's checks a mock rig can trip (over-current, over-speed,
encoder jump and stuck, DC link, NaN, inverter state, a non-finite command), the scenarios whose load
sees the speed only through its sign or is Sec. 6.4.1's, a constant magnetising reference; the parameterised
``load-step`` (constant speed, a load step) with each case's own speed and load. Everything
else runs on the scalar engine (`bench.runtime.session.run`).
"""

from __future__ import annotations

import functools
import importlib.util
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench.core.config import RigConfig
from bench.errors import BadInput
from bench.core import load_profiles as lp, scenarios, supervisor_checks as sc
from bench.batch import kernel as bk
from bench.core.scenarios import check_arguments, check_named, get, T_MAGNETISE
from bench.core.setpoints import Margins
from bench.core.supervisor import Supervisor
from bench.core.nameplate import is_thesis
from bench.runtime.loop import POST_TRIP_TIME
from bench.batch.kernel import LOAD_641, LOAD_TABLE, N_O, N_OI, run_all
from bench.controllers import foc_compiled as fc
from bench.runtime.run_summary import summary_time
from bench.runtime.compose import make_controller, mock_rig
from bench.runtime.fault_injection import inject

# scenarios whose load profile the kernel evaluates: a table by the sign of the measured speed, or 6.4.1's law
_SIGN_TABLE = ("demo", "fig5.7", "fig5.8", "fig4.9", "fig4.11", "fig5.11", "relay0", "warmup", "load-step")
# parameterised scenarios whose speed reference and load are linear in two of their arguments: the tables are built
# with both at 1, each case scales them by its own values (`Run.scenario_args`, the scenario's defaults where left out)
_SCALED = {"load-step": ("speed", "load")}
_LOAD_641 = ("load6.4.1", "fig6.14")
SCENARIOS = _SIGN_TABLE + _LOAD_641  # the scenarios the batch engine runs
_LOOP = threading.Lock()
_CHECK_OMEGAS = (-250.0, -3.1, -0.37, 0.0, 0.37, 3.1, 250.0)  # the load model is checked at these speeds


@dataclass(frozen=True)
class Run:
    """One case of a batch: the rig (mock), the run seed, the FOC's parameters; for a parameterised scenario
    (``load-step``: ``speed`` [rad/s, electrical], ``load`` [N m]) this case's arguments of it."""

    rig: RigConfig
    seed: int = 0
    params: dict[str, Any] = field(default_factory=dict)
    controller: str = "foc"
    scenario_args: dict[str, float] = field(default_factory=dict)
    # a fault injected on purpose (bench.runtime.fault_injection), as `bench run` injects it
    inject_fault: str | None = None


@dataclass
class _Scenario:
    name: str
    T: float
    n_ticks: int
    w_ref: np.ndarray
    last_change: np.ndarray
    ref_changed: np.ndarray
    load_kind: int
    load: tuple[np.ndarray, np.ndarray, np.ndarray]
    load_641: tuple[float, float]
    i_mR_ref: float


@functools.lru_cache(maxsize=8)  # shared by the batches of a worker: building the tables takes ~0.2 s per simulated s
def _scenario(name: str, duration: float | None, T: float) -> _Scenario:
    """The scenario's per-tick tables (reference, its changes, the load), or BadInput naming what the kernel lacks."""
    scn = scenarios.SCENARIOS[name](**dict.fromkeys(_SCALED[name], 1.0)) if name in _SCALED else scenarios.get(name)
    if name not in SCENARIOS:
        raise BadInput("scenario", f"the batch engine has no load model of {name!r}; it runs {', '.join(SCENARIOS)}")
    if callable(scn.i_mR_ref):
        raise BadInput("scenario", f"{name!r} has a time-varying magnetising reference: scalar engine only")
    if scn.switches:
        raise BadInput("scenario", f"{name!r} switches parts while running: scalar engine only")
    dur = scn.duration if duration is None else duration
    if not (math.isfinite(dur) and T <= dur <= 3600):
        raise BadInput("duration", f"must be in [{T:.3g}, 3600] s (at least one tick), got {dur}")
    n = int(round(dur / T))
    t = np.array([k * T for k in range(n)])
    w = np.array([scn.speed_ref(float(x)) for x in t], dtype=float)
    changes = np.flatnonzero(np.diff(w) != 0) + 1  # as bench.runtime.run_summary.summarize finds them in the log
    last = np.full(n, -np.inf)
    if changes.size:
        idx = np.searchsorted(t[changes], t, side="right") - 1
        ok = idx >= 0
        last[ok] = t[changes][idx[ok]]
    changed = np.zeros(n, dtype=np.bool_)
    changed[changes] = True
    tables = tuple(np.array([scn.load(float(x), s) for x in t], dtype=float) for s in (1.0, -1.0, 0.0))
    law = lp.speed_dependent_641()
    probe = t[:: max(1, n // 50)]
    for x in probe:  # the model must be the scenario's own load, at any speed
        for om in _CHECK_OMEGAS:
            want = scn.load(float(x), om)
            got = law(float(x), om) if name in _LOAD_641 else scn.load(float(x), math.copysign(1.0, om) if om else 0.0)
            if got != want:
                raise BadInput("scenario", f"the load of {name!r} is not the batch engine's model of it "
                               f"(t = {x:g} s, omega = {om:g} rad/s: {want!r} != {got!r})")  # fmt: skip
    return _Scenario(name, T, n, w, last, changed, LOAD_641 if name in _LOAD_641 else LOAD_TABLE,
                     tables, (8.0, 0.01), float(scn.i_mR_ref))  # fmt: skip


class _Case:
    """One case's state buffers and numbers, built by the constructors `bench.runtime.session.run` uses."""

    def __init__(self, run: Run, scn: _Scenario) -> None:
        cfg = run.rig
        if cfg.driver != "mock":
            raise BadInput("rig.driver", f"the batch engine runs the mock rig only, got {cfg.driver!r}")
        if run.controller != "foc":
            raise BadInput("controller", f"the batch engine runs the foc controller only, got {run.controller!r}")
        if cfg.T_s != scn.T:
            raise BadInput("rig.rate_hz", "every case of a batch needs the same loop rate")

        if not is_thesis(cfg.nameplate):  # its tables are the thesis motor's scenarios (bench.core.scenarios.scale)
            raise BadInput("nameplate", "a motor other than the thesis one has scaled scenarios: scalar engine only")
        # BadInput naming the argument: not a number, or outside the set-point margins of this case's rig; so is the
        # scenario's own profile over the run (bench.core.scenarios.check_profile)
        margins = Margins.of_rig(cfg)
        self.scenario_args = check_arguments(scn.name, run.scenario_args, margins)
        duration = scn.n_ticks * scn.T
        check_named(scn.name, self.scenario_args, margins, duration)
        self.fault: dict[str, Any] | None = None
        if run.inject_fault is not None:
            cfg, self.fault = inject(cfg, run.inject_fault, get(scn.name, self.scenario_args), duration,
                                     "inject_fault")  # fmt: skip
        # the compiled plant and FOC: the same runs as the Python ones, to the bit (their tests)
        rig = mock_rig(cfg, run.seed, mock={"engine": "compiled"})
        # the controller as a session builds it (on the Python engine), its state packed for the compiled tick with
        # every part the kernels cover (foc_compiled.pack: the same buffer the compiled engine runs on)
        ctrl = make_controller(cfg, rig, "foc", {**run.params, "engine": "python"})
        if ctrl.rr is not None:
            raise BadInput("controller.foc.rr_adapt", "the batch engine keeps no R_r-estimate metrics: scalar engine only")
        if ctrl.fw is not None:
            raise BadInput("controller.foc.field_weakening", "the batch engine keeps no voltage-limit report: scalar "
                           "engine only")
        try:
            xf = fc.pack(ctrl)
        except ValueError as exc:
            raise BadInput("controller", f"the batch engine has no compiled kernel for this configuration: {exc}") \
                from None
        sup = Supervisor(cfg.limits, rig.encoder.counts_per_rev, rig.encoder.modulus, cfg.motor.Z_p, cfg.T_s)
        rig.configure()
        rig.activate()
        plant = rig.truth
        if plant._lent[0]:
            plant._reload_rngs()
        inv = plant.inverter
        if inv._cmd_on or inv._next_on or inv._fault or plant.k != 0 or plant.load.m_L_ref != 0.0:
            raise RuntimeError("the mock rig is not in its safe start state")  # (the kernel starts from it)
        self.xp = plant._buf.copy()
        self.xf = xf
        self.xs = np.zeros(fc.N_BUF)
        fc._to_view(sup.speed, "encoder", self.xs)  # the supervisor's encoder speed, on foc_compiled's kernel
        lim = cfg.limits
        p = np.zeros(bk.N_P)
        p[bk.P.UDC], p[bk.P.INV_DT], p[bk.P.IMR_REF] = inv.u_dc, plant._inv_dt, scn.i_mR_ref
        p[bk.P.I_TRIP], p[bk.P.I_TRIP_PH], p[bk.P.OMEGA_MAX] = lim.I_trip, lim.I_trip_phase, lim.omega_max
        p[bk.P.UDC_MIN], p[bk.P.UDC_MAX] = lim.u_dc_min, lim.u_dc_max
        p[bk.P.STUCK_OMEGA], p[bk.P.STUCK_U] = lim.enc_stuck_omega, lim.enc_stuck_u
        p[bk.P.TORQUE_LIM] = plant.load.torque_limit
        p[bk.P.LOAD_MMAX], p[bk.P.LOAD_K] = scn.load_641
        p[bk.P.K_TORQUE] = cfg.motor.torque_constant  # the nominal k of (4.6), as the session scores the torque
        w_arg, load_arg = _SCALED.get(scn.name, (None, None))
        p[bk.P.W_SCALE] = self.scenario_args[w_arg] if w_arg else 1.0
        p[bk.P.LOAD_SCALE] = self.scenario_args[load_arg] if load_arg else 1.0
        q = np.zeros(bk.N_Q, dtype=np.int64)
        q[bk.Q.DELAY], q[bk.Q.JUMP_MAX] = inv.delay, sup.enc_jump_max
        q[bk.Q.STUCK_TICKS], q[bk.Q.ENABLE_TICKS] = sup._stuck_ticks, sup._enable_ticks
        self.p, self.q, self.limits = p, q, lim
        self.controller_params = {**ctrl.params(), "engine": "compiled"}  # (what the loop runs: the compiled tick)


# the results row of a case from the batch and from the scalar engine (`rows_differ`): exact in these columns, the
# other numbers within REL relative or ABS absolute; the flux-angle errors within ANGLE_ABS: they are differences of
# two angles of ~pi, which the session's numpy arctan2 (a SIMD library on AVX-512 CPUs, not correctly rounded) and the
# loop's C atan2 each round to within an ulp of pi (2.5e-14 deg); timing columns differ by nature
EXACT = {"status", "exit_code", "trip_cause", "trip_time", "ticks", "sim_time", "deadline_misses", "overruns",
         "load_steps", "warnings", "error"}  # fmt: skip
TIMING = {"wall_time", "realtime_factor", "compute_us_p50", "compute_us_p99", "compute_us_max", "case_wall_time",
          "worker"}  # fmt: skip
REL, ABS, ANGLE_ABS = 1e-12, 1e-14, 1e-13


def rows_differ(a: dict[str, Any], b: dict[str, Any]) -> str | None:
    """None if two results rows of one case agree as the batch engine promises, else the first column that does not
    (with both values)."""
    if set(a) != set(b):
        return f"columns: {sorted(set(a) ^ set(b))}"
    for k in sorted(set(a) - TIMING):
        x, y = a[k], b[k]
        if k in EXACT or not isinstance(x, float) or not isinstance(y, float):
            ok = x == y
        elif math.isnan(y):
            ok = math.isnan(x)
        else:
            ok = math.isclose(x, y, rel_tol=REL, abs_tol=ANGLE_ABS if k.startswith("est_flux_angle") else ABS)
        if not ok:
            return f"{k}: {x!r} != {y!r}"
    return None


def unsupported(run: Run, scenario: str, duration: float | None = None) -> str | None:
    """Why the batch engine cannot run this case (one line), or None if it can."""
    if importlib.util.find_spec("numba") is None:
        return "the batch engine needs numba (pip install numba)"
    try:
        _Case(run, _scenario(scenario, duration, run.rig.T_s))
    except BadInput as exc:
        return f"{exc.field} {exc.problem}"
    return None


def _stats(n: int, sq: float, s: float, mx: float) -> dict[str, float]:
    """bench.runtime.run_summary.stats from the sums: rms, max_abs, mean ({} without samples)."""
    if n == 0:
        return {}
    return {"rms": float(np.sqrt(sq / n)), "max_abs": float(mx), "mean": float(s / n)}


def _cause(code: int, o: np.ndarray, oi: np.ndarray, case: _Case) -> str | None:
    """The supervisor's cause text (`bench.core.supervisor_checks.cause`) from the kernel's code and numbers."""
    return sc.cause(code, case.limits, float(o[bk.O.TRIP_V1]), float(o[bk.O.TRIP_V2]), float(o[bk.O.TRIP_V3]),
                    int(oi[bk.OI.JUMP_D]), 1, int(case.q[bk.Q.JUMP_MAX]), bool(oi[bk.OI.ENABLE_CMD]))  # fmt: skip


def _summary(o: np.ndarray, oi: np.ndarray, case: _Case, scn: _Scenario, run: Run, wall: float) -> dict[str, Any]:
    """The session summary (`bench.runtime.session.run` without a log) of one case."""

    T = scn.T
    code = int(oi[bk.OI.TRIP])
    cause = _cause(code, o, oi, case)
    trip_t = int(oi[bk.OI.TRIP_K]) * T if code else None
    ticks = int(oi[bk.OI.TICKS])
    sim = ticks * T
    n_a, n_s, n_e, n_p = (int(oi[i]) for i in (bk.OI.N_ACTIVE, bk.OI.N_SETTLED, bk.OI.N_EST, bk.OI.N_PEAKS))
    peaks = n_p > 0
    nan = math.nan

    def rms(i: int) -> float:
        return float(np.sqrt(o[i] / n_e)) if n_e else nan

    def rel(x: float, ref: float) -> float:
        return x / ref if ref > 0 else nan

    mean_im = float(o[bk.O.IM_SUM] / n_e) if n_e else nan
    mean_m = float(o[bk.O.ME_SUM] / n_e) if n_e else nan
    p95 = {i: float(o[i]) for i in (bk.O.P95_MAG, bk.O.P95_ANG, bk.O.P95_M)}
    est = {  # bench.runtime.metrics.estimation_errors
        "flux_mag_rms_A": rms(bk.O.MAG_SQ), "flux_mag_max_A": float(o[bk.O.MAG_MAX]) if n_e else nan,
        "flux_mag_rms_rel": rel(rms(bk.O.MAG_SQ), mean_im),
        "flux_mag_p95_A": p95[bk.O.P95_MAG], "flux_mag_p95_rel": rel(p95[bk.O.P95_MAG], mean_im),
        "flux_angle_rms_deg": rms(bk.O.ANG_SQ), "flux_angle_max_deg": float(o[bk.O.ANG_MAX]) if n_e else nan,
        "flux_angle_p95_deg": p95[bk.O.P95_ANG],
        "speed_rms": rms(bk.O.W_SQ), "speed_max": float(o[bk.O.W_MAX]) if n_e else nan,
        "tracking_rms": rms(bk.O.TR_SQ), "tripped": trip_t is not None,
        "torque_rms_Nm": rms(bk.O.M_SQ), "torque_p95_Nm": p95[bk.O.P95_M],
        "torque_rms_rel": rel(rms(bk.O.M_SQ), mean_m), "torque_p95_rel": rel(p95[bk.O.P95_M], mean_m),
    }  # fmt: skip
    return {
        "scenario": scn.name, "scenario_args": case.scenario_args, "controller": run.controller,
        "controller_params": case.controller_params,
        "rig": run.rig.name, "seed": run.seed, "exit_code": 1 if cause else 0, "trip_cause": cause,
        "trip_time": summary_time(trip_t), "realtime": False, "ticks": ticks, "duration": summary_time(sim),
        "wall_time": wall,
        "realtime_factor": sim / wall if wall > 0 else math.inf, "deadline_misses": 0, "overruns": 0,
        "skipped_ticks": 0, "timing": {}, "engine": "batch",
        "speed_source": "truth",
        "speed_error": _stats(n_a, o[bk.O.E_SQ], o[bk.O.E_SUM], o[bk.O.E_MAX]),
        "speed_error_settled": _stats(n_s, o[bk.O.ES_SQ], o[bk.O.ES_SUM], o[bk.O.ES_MAX]),
        "load_steps": {"count": n_p, "peak_deviation_max": float(o[bk.O.PEAK_MAX]) if peaks else None,
                       "peak_deviation_mean": float(o[bk.O.PEAK_SUM] / n_p) if peaks else None,
                       "recovery_time_1rad_s_mean": float(o[bk.O.REC_SUM] / n_p) if peaks else None},
        "i_mR_error": _stats(n_s, o[bk.O.I_SQ], o[bk.O.I_SUM], o[bk.O.I_MAX]),
        "estimation_errors": {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in est.items()},
        "warnings": [],
    } | ({"fault_injection": case.fault} if case.fault is not None else {})  # fmt: skip


def simulate(runs: list[Run], scenario: str, duration: float | None = None,
             timing: dict[str, float] | None = None, states: dict[str, np.ndarray] | None = None,
             refused: dict[int, str] | None = None) -> list[dict[str, Any] | None]:  # fmt: skip
    """The session summary of every run (one scenario and duration, one loop rate), computed in one batch.

    Raises `BadInput` if a run is outside what the engine covers (`unsupported`); with ``refused`` (a dict) such
    runs are left out instead: their summary is None and ``refused[index]`` says why. ``wall_time`` of each
    summary is its share of the batch's wall time. ``timing`` (if given) gets ``build_s`` (the cases'
    objects and buffers), ``loop_s`` (the compiled loop) and ``loop_cpu_s`` (its CPU time, all threads) [s].
    ``states`` (if given) gets the cases' final state buffers, one row each: ``plant`` (`mock_hw.compiled`'s layout)
    and ``controller`` (`bench.controllers.foc_compiled`'s), of the runs not refused.
    """
    import numba


    if not runs:
        return []
    t_build = time.perf_counter()
    T = runs[0].rig.T_s
    scn = _scenario(scenario, duration, T)
    cases, kept = [], []
    for i, r in enumerate(runs):
        try:
            cases.append(_Case(r, scn))
            kept.append(i)
        except BadInput as exc:
            if refused is None:
                raise
            refused[i] = f"{exc.field} {exc.problem}"
    n = len(cases)
    out: list[dict[str, Any] | None] = [None] * len(runs)
    if not n:
        return out
    XP, XS = (np.ascontiguousarray(np.stack([getattr(c, a) for c in cases])) for a in ("xp", "xs"))
    XF = np.zeros((n, max(c.xf.size for c in cases)))  # the controllers' buffers: their tail regions differ in length
    for i, c in enumerate(cases):
        XF[i, :c.xf.size] = c.xf
    P, Q = np.stack([c.p for c in cases]), np.stack([c.q for c in cases])
    OUT, OUTI = np.zeros((n, N_O)), np.zeros((n, N_OI), dtype=np.int64)
    t0, c0 = time.perf_counter(), time.process_time()
    with _LOOP:  # one batch at a time per process (numba's threading layers need not take concurrent launches)
        chunk = numba.set_parallel_chunksize(1)  # cases handed out one at a time: one that trips early frees its thread
        try:
            run_all(XP, XF, XS, P, Q, scn.w_ref, scn.last_change, scn.ref_changed, scn.load_kind, *scn.load,
                    scn.n_ticks, int(round(POST_TRIP_TIME / T)), T, T_MAGNETISE, T_MAGNETISE + 0.1,
                    OUT, OUTI)  # fmt: skip
        finally:
            numba.set_parallel_chunksize(chunk)
    t1, c1 = time.perf_counter(), time.process_time()
    if timing is not None:
        timing.update(build_s=t0 - t_build, loop_s=t1 - t0, loop_cpu_s=c1 - c0)
    if states is not None:
        states.update(plant=XP, controller=XF)
    wall = (t1 - t0) / n
    for j, i in enumerate(kept):
        out[i] = _summary(OUT[j], OUTI[j], cases[j], scn, runs[i], wall)
    return out
