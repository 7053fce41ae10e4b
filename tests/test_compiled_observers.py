"""The compiled flux observers and speed estimators (bench.controllers.observers_compiled) against their Python
references: the same outputs and the same state, to the bit (float64 bit patterns: signed zeros count)."""

from __future__ import annotations

import cmath
import copy
import math
import struct
from dataclasses import replace
from typing import Any, Callable

import numpy as np
import pytest

from bench.controllers.observers import (CurrentModelObserver, JansenLorenzObserver, KubotaObserver, LPVObserver,
                                         VoltageModelObserver)
from bench.controllers.speed_estimators import KubotaSpeed, RotorEquationSpeed
from bench.params import T_S_DEFAULT, MotorParams

pytest.importorskip("numba")
from bench.controllers import observers_compiled as oc  # noqa: E402

M, T = MotorParams(), T_S_DEFAULT
N = 10000  # ticks of the synthetic inputs (then the closed-loop stretch)


def bits(v: Any) -> Any:
    """A value's exact identity: type and float64 bit patterns (signed zeros and NaN payloads count)."""
    if v is None:
        return None
    if isinstance(v, float):
        return struct.unpack("<q", struct.pack("<d", v))[0]
    if isinstance(v, complex):
        return "c", bits(v.real), bits(v.imag)
    if isinstance(v, (tuple, list)):
        return tuple(bits(e) for e in v)
    if isinstance(v, (bool, int)):
        return type(v).__name__, int(v)
    if isinstance(v, MotorParams):
        return tuple(bits(getattr(v, f)) for f in ("L_s", "L_r", "L_m", "R_s", "R_r"))
    raise TypeError(type(v))


STATE = {
    VoltageModelObserver: ("i_m", "psi_s", "_i_s_prev"),
    JansenLorenzObserver: ("i_m", "psi_s", "g", "psi_rc", "_i_s_prev", "_w_prev", "_b"),
    KubotaObserver: ("i_m", "i_s_hat", "e_is", "_i_s_prev", "omega_i", "omega_hat", "motor"),
    LPVObserver: ("i_m", "x1", "x2", "_u_prev", "delta", "clipped"),
    KubotaSpeed: ("omega_hat", "omega_r"),
    RotorEquationSpeed: ("omega_hat", "omega_r", "_prev", "omega_raw", "_inv_Tr"),
}


def state(obj: Any) -> Any:
    s = {name: bits(getattr(obj, name)) for name in STATE[type(obj)]}
    if isinstance(obj, KubotaSpeed) and not obj.shared:
        s["obs"] = state(obj.obs)
    return s


# --- inputs --------------------------------------------------------------------------------------------------
def synthetic(n: int, seed: int) -> list[tuple[complex, complex, float, complex]]:
    """(i_s, u_s, omega_r, i_m) per tick: zeros first, then stretches of rotating currents and voltages (|i_s| up to
    10 A, |u_s| up to 300 V, speeds up to +-300 rad/s, with noise) changing by steps, some of white noise, a
    stretch of flux below the rotor-equation estimator's threshold and one of exact (signed) zeros."""
    rng = np.random.default_rng(seed)
    nz = complex(-0.0, -0.0)
    out: list[tuple[complex, complex, float, complex]] = [(nz, nz, -0.0, nz)] * 20
    out += [(complex(0.0, -0.0), complex(-0.0, 0.0), -0.0, complex(-0.0, 0.0))] * 20 + [(0j, 0j, 0.0, 0j)] * 100
    th = 0.0
    while len(out) < n:
        length = int(rng.integers(200, 1500))
        kind = rng.integers(0, 5)
        amp_i, amp_u, amp_m = rng.uniform(0.0, 10.0), rng.uniform(0.0, 300.0), rng.uniform(0.0, 4.0)
        w_e, w_r = rng.uniform(-320.0, 320.0), rng.uniform(-300.0, 300.0)
        ph_i, ph_u = rng.uniform(-math.pi, math.pi, 2)
        for _ in range(length):
            th += w_e * T
            if kind == 0:  # white noise of the full size
                i_s = complex(*rng.uniform(-7.0, 7.0, 2))
                u_s = complex(*rng.uniform(-210.0, 210.0, 2))
                w = float(rng.uniform(-300.0, 300.0))
                i_m = complex(*rng.uniform(-3.0, 3.0, 2))
            else:
                i_s = amp_i * cmath.exp(1j * (th + ph_i)) + complex(*rng.normal(0.0, 0.05, 2))
                u_s = amp_u * cmath.exp(1j * (th + ph_u)) + complex(*rng.normal(0.0, 2.0, 2))
                w = w_r + float(rng.normal(0.0, 1.0))
                i_m = (0.1 if kind == 1 else amp_m) * cmath.exp(1j * th) + complex(*rng.normal(0.0, 0.01, 2))
            out.append((i_s, u_s, w, i_m))
    return out[:n]


@pytest.fixture(scope="module")
def closed_loop() -> list[tuple[complex, complex, float, complex]]:
    """The inputs the FOC's current-model observer got in a real closed-loop session (scenario demo, mock rig):
    (i_s, u_s, omega_r) and its estimate i_m."""
    from bench.core.config import load as load_rig
    from bench.runtime.session import RunOptions, run

    rec: list[tuple[complex, complex, float, complex]] = []
    orig = CurrentModelObserver.update

    def spy(self, i_s, u_s, omega_r):  # noqa: ANN001, ANN202
        i_m = orig(self, i_s, u_s, omega_r)
        rec.append((i_s, u_s, omega_r, i_m))
        return i_m

    CurrentModelObserver.update = spy
    try:
        cfg = load_rig("mock")
        cfg = replace(cfg, mock={**cfg.mock, "engine": "compiled"})
        run(RunOptions(rig=cfg, scenario="demo", seed=0, duration=0.6, progress=False, params={"engine": "python"},
                       log_enabled=False))  # fmt: skip
    finally:
        CurrentModelObserver.update = orig
    assert len(rec) > 1500 and max(abs(r[0]) for r in rec) > 2.0 and max(abs(r[2]) for r in rec) > 10.0
    return rec


# --- the parts as systems of one tick ------------------------------------------------------------------------
class Sys:
    """A part (or the FOC's shared Kubota pair) with its Python step and its kernel step on packed slices."""

    def __init__(self, make: Callable[[], Any]) -> None:
        self.make = make

    def pack(self, obj: Any) -> Any: ...
    def py(self, obj: Any, inp: tuple) -> tuple: ...
    def kern(self, arrays: Any, inp: tuple) -> tuple: ...
    def unpack(self, obj: Any, arrays: Any) -> None: ...
    def state(self, obj: Any) -> Any: ...
    def set_R_r(self, obj: Any, arrays: Any, R_r: float) -> None: ...


def _slices(obj: Any) -> tuple[np.ndarray, np.ndarray]:
    nf, ni = oc.layout(obj)
    # the part in the middle of larger arrays (as in the FOC's buffer), NaN around it: nothing else is read
    x, iv = np.full(nf + 6, np.nan), np.full(ni + 6, -7, dtype=np.int64)
    oc.pack(obj, x[3:3 + nf], iv[3:3 + ni])
    return x, iv


class OnePart(Sys):
    """One part alone, packed in the middle of larger arrays."""

    def pack(self, obj):
        x, iv = _slices(obj)
        return oc.kind_of(obj), x, iv

    def unpack(self, obj, a):
        oc.unpack(obj, a[1][3:], a[2][3:])

    def state(self, obj):
        return state(obj)


class Observer(OnePart):
    """A flux observer (Kubota's with its omega_hat)."""

    def py(self, obj, inp):
        i_s, u_s, w, _ = inp
        i_m = obj.update(i_s, u_s, w)
        return (i_m, obj.omega_hat) if isinstance(obj, KubotaObserver) else (i_m,)

    def kern(self, a, inp):
        kind, x, iv = a
        i_s, u_s, w, _ = inp
        xo, io = x[3:], iv[3:]
        i_m = complex(*oc.update(kind, xo, io, i_s.real, i_s.imag, u_s.real, u_s.imag, w))
        assert bits(i_m) == bits(complex(xo[0], xo[1]))  # the estimate stays in x[0:2]
        return (i_m, float(xo[oc.SK.WHAT])) if kind == oc.KIND_KUBOTA else (i_m,)

    def set_R_r(self, obj, a, R_r):
        obj.set_R_r(R_r)
        oc.set_R_r(a[0], a[1][3:], a[2][3:], R_r)


class Estimator(OnePart):
    """A speed estimator fed the recorded estimate i_m (its own Kubota observer, or none)."""

    def py(self, obj, inp):
        i_s, u_s, _, i_m = inp
        w = obj.update(i_s, u_s, i_m)
        return w, obj.omega_hat, obj.omega_r

    def kern(self, a, inp):
        kind, x, iv = a
        i_s, u_s, _, i_m = inp
        xe, ie = x[3:], iv[3:]
        nowhere = np.full(1, np.nan), np.zeros(1, np.int64)  # no flux observer to read
        w = oc.est_update(kind, xe, ie, *nowhere, i_s.real, i_s.imag, u_s.real, u_s.imag, i_m.real, i_m.imag)
        return w, oc.est_omega_hat(xe), oc.est_omega_r(xe)

    def set_R_r(self, obj, a, R_r):
        obj.set_R_r(R_r)
        oc.est_set_R_r(a[0], a[1][3:], a[2][3:], R_r)


class SharedKubota(Sys):
    """The FOC's sensorless Kubota pair: the flux observer turned by the estimator's omega_hat of the previous
    tick, then the estimator reading the observer without stepping it (FocController.step)."""

    def pack(self, pair):
        obs, est = pair
        return _slices(obs), _slices(est)

    def py(self, pair, inp):
        obs, est = pair
        i_s, u_s, _, _ = inp
        i_m = obs.update(i_s, u_s, est.omega_hat)
        w = est.update(i_s, u_s, i_m)
        return i_m, w, est.omega_hat, est.omega_r

    def kern(self, a, inp):
        (x, iv), (xe, ie) = a
        xo, io, xe, ie = x[3:], iv[3:], xe[3:], ie[3:]
        i_s, u_s, _, _ = inp
        i_m = complex(*oc.update(oc.KIND_KUBOTA, xo, io, i_s.real, i_s.imag, u_s.real, u_s.imag, oc.est_omega_hat(xe)))
        w = oc.est_update(oc.EST_KUBOTA, xe, ie, xo, io, i_s.real, i_s.imag, u_s.real, u_s.imag, i_m.real, i_m.imag)
        return i_m, w, oc.est_omega_hat(xe), oc.est_omega_r(xe)

    def unpack(self, pair, a):
        (x, iv), (xe, ie) = a
        oc.unpack(pair[0], x[3:], iv[3:])
        oc.unpack(pair[1], xe[3:], ie[3:])

    def state(self, pair):
        return state(pair[0]), state(pair[1])

    def set_R_r(self, pair, a, R_r):  # FocController._use_R_r: the observer, then the estimator (a no-op: shared)
        (x, iv), (xe, ie) = a
        pair[0].set_R_r(R_r)
        pair[1].set_R_r(R_r)
        oc.set_R_r(oc.KIND_KUBOTA, x[3:], iv[3:], R_r)
        oc.est_set_R_r(oc.EST_KUBOTA, xe[3:], ie[3:], R_r)


def _shared_pair() -> tuple[KubotaObserver, KubotaSpeed]:
    obs = KubotaObserver(M, T, lambda_p=0.5)
    return obs, KubotaSpeed(M, T, shared=obs, tau=0.005)


CASES: dict[str, Sys] = {
    "voltage_model": Observer(lambda: VoltageModelObserver(M, T)),
    "voltage_model_tau": Observer(lambda: VoltageModelObserver(M, T, tau=0.05)),
    "jl": Observer(lambda: JansenLorenzObserver(M, T)),
    "jl_gains": Observer(lambda: JansenLorenzObserver(M, T, K1_re=200.0, K1_im=-40.0, K2_re=50.0, K2_im=7.0)),
    "kubota": Observer(lambda: KubotaObserver(M, T)),
    "kubota_pi_omega0": Observer(lambda: KubotaObserver(M, T, lambda_p=2.0, omega0=50.0, pole_ratio=1.6)),
    "kubota_no_gain": Observer(lambda: KubotaObserver(M, T, pole_ratio=1.0)),  # G = 0
    "kubota_luenberger": Observer(lambda: KubotaObserver(M, T, adapt=0.0)),
    "lpv": Observer(lambda: LPVObserver(M, T)),
    "lpv_held_u": Observer(lambda: LPVObserver(M, T, u_extrapolate=0.0)),
    "kubota_speed_own": Estimator(lambda: KubotaSpeed(M, T, tau=0.01, observer_params={"lambda_c": 3000.0})),
    "kubota_speed_shared": SharedKubota(_shared_pair),
    "rotor_equation": Estimator(lambda: RotorEquationSpeed(M, T)),
    "rotor_equation_unfiltered": Estimator(lambda: RotorEquationSpeed(M, T, tau=0.0, i_mR_min=0.5)),
}


@pytest.mark.parametrize("name", list(CASES))
def test_kernel_equals_python_to_the_bit(name, closed_loop):
    """Every output of every tick, and the state unpacked every 1000 ticks, through an R_r change, the synthetic
    inputs and then a closed-loop stretch; then unpack and continue in Python == continue in the kernel."""
    s = CASES[name]
    ref, twin = s.make(), s.make()
    template = copy.deepcopy(twin)
    a = s.pack(twin)
    inputs = synthetic(N, seed=len(name)) + closed_loop
    changed = 0
    for k, inp in enumerate(inputs):
        if k == N // 2:  # an on-line R_r estimate handed over (rr_adapt): JL, Kubota, the rotor equation use it
            s.set_R_r(ref, a, 1.37 * M.R_r)
        p, c = s.py(ref, inp), s.kern(a, inp)
        assert bits(p) == bits(c), (name, k, p, c)
        if k % 1000 == 999 or k == len(inputs) - 1:
            clone = copy.deepcopy(template)
            s.unpack(clone, a)
            assert s.state(clone) == s.state(ref), (name, k)
            changed += s.state(clone) != s.state(template)
    assert changed, "the state moved"
    # hand the running part back to Python: it continues as the kernel does
    py = copy.deepcopy(template)
    s.unpack(py, a)
    for inp in synthetic(2000, seed=99):
        assert bits(s.py(py, inp)) == bits(s.kern(a, inp)), name
    s.unpack(template, a)
    assert s.state(template) == s.state(py)


def test_outputs_are_not_trivial(closed_loop):
    """The comparisons above see estimates of real size (not all zeros or NaN) and speeds that adapt."""
    inputs = synthetic(N, seed=1) + closed_loop
    for s in (CASES["kubota"], CASES["lpv"], CASES["jl"], CASES["voltage_model_tau"]):
        obj = s.make()
        out = [s.py(obj, inp)[0] for inp in inputs]
        mags = np.abs(np.array(out))
        assert np.all(np.isfinite(mags)) and mags.max() > 0.5
    est = CASES["rotor_equation"].make()
    w = [CASES["rotor_equation"].py(est, inp)[0] for inp in inputs]
    assert np.all(np.isfinite(w)) and np.ptp(w) > 100.0


def test_pack_then_unpack_is_the_identity_and_sizes_are_checked():
    for s in CASES.values():
        obj = s.make()
        for inp in synthetic(300, seed=5):
            s.py(obj, inp)
        fresh = copy.deepcopy(obj)
        s.unpack(fresh, s.pack(obj))
        assert s.state(fresh) == s.state(obj)
    with pytest.raises(ValueError, match="needs 21 float and 2 int"):
        oc.pack(KubotaObserver(M, T), np.zeros(20), np.zeros(2, np.int64))
    with pytest.raises(ValueError, match="current model"):
        oc.layout(CurrentModelObserver(M, T))
    assert oc.kind_of(CurrentModelObserver(M, T)) == oc.KIND_CURRENT_MODEL == 0
    assert oc.kind_of(None) == oc.EST_NONE and oc.layout(None) == (0, 0)
    assert oc.layout(KubotaSpeed(M, T, shared=KubotaObserver(M, T))) == (oc.EST_OBS_F, oc.EST_OBS_I)
    with pytest.raises(ValueError, match="unknown observer kind"):
        oc.update(0, np.zeros(4), np.zeros(1, np.int64), 0.0, 0.0, 0.0, 0.0, 0.0)


def test_shared_kubota_does_not_step_the_observer_twice():
    obs, est = _shared_pair()
    xo, io = np.zeros(oc.K_NF), np.zeros(oc.K_NI, np.int64)
    xe, ie = np.zeros(oc.EST_OBS_F), np.zeros(oc.EST_OBS_I, np.int64)
    oc.pack(obs, xo, io)
    oc.pack(est, xe, ie)
    oc.update(oc.KIND_KUBOTA, xo, io, 3.0, 1.0, 100.0, 20.0, 0.0)
    before = xo.tobytes(), io.tobytes()
    w = oc.est_update(oc.EST_KUBOTA, xe, ie, xo, io, 3.0, 1.0, 100.0, 20.0, 0.0, 0.0)
    assert (xo.tobytes(), io.tobytes()) == before and xe[oc.EST_OMEGA_HAT] == xo[oc.SK.WHAT] != 0.0 and w != 0.0


def _outcome(f: Callable, *args: Any) -> Any:
    try:
        r = f(*args)
    except (ArithmeticError, ValueError) as exc:
        return type(exc).__name__
    return bits(complex(*r) if isinstance(r, tuple) else r)


def test_the_cmath_helpers_are_cpythons():
    """bench.controllers.kernel_math's cexp, csqrt, ccosh, csinh and csquare, compiled (as the observers' kernels
    call them) and plain, against CPython's cmath.exp, sqrt, cosh, sinh and z ** 2 for finite arguments (signed
    zeros, subnormals, overflow: the same bits or the same exception); a non-finite argument gives NaN + NaN j
    (without the sign bit) in both."""
    from numba import njit

    from bench.controllers import kernel_math as km

    rng = np.random.default_rng(4)
    special = [0.0, -0.0, 1.0, -1.0, 0.5, 3.0, 1e-310, -1e-310, 5e-324, 1e-170, 1e300, -1e300, 1.7e308, 710.0,
               -710.0, 709.0, 720.0]  # fmt: skip
    pairs = [(a, b) for a in special for b in special]
    pairs += [(float(a), float(b)) for a, b in rng.normal(0, 3, (4000, 2))]
    pairs += [(float(a), float(b)) for a, b in rng.normal(0, 3, (2000, 2)) * 10.0 ** rng.integers(-8, 8, (2000, 2))]
    helpers = ((km.cexp, cmath.exp), (km.csqrt, cmath.sqrt), (km.ccosh, cmath.cosh), (km.csinh, cmath.sinh),
               (km.csquare, lambda v: v**2))  # fmt: skip
    compiled = [njit(lambda z, f=f: f(z)) for f, _ in helpers]  # (registered by observers_compiled)
    raised = 0
    for a, b in pairs:
        z = complex(a, b)
        for (plain, ref), comp in zip(helpers, compiled):
            want = _outcome(ref, z)
            raised += want == "OverflowError"
            assert _outcome(comp, z) == _outcome(plain, z) == want, (plain.__name__, z)
    assert raised > 50
    nan = bits(complex(math.nan, math.nan))
    for z in (complex(math.nan, 1.0), complex(-math.nan, -math.nan), complex(math.inf, 0.0), complex(1.0, -math.inf)):
        for (plain, _), comp in zip(helpers[:4], compiled):
            assert _outcome(comp, z) == _outcome(plain, z) == nan, (plain.__name__, z)


def _signed_zeros(obj: Any) -> None:
    """Every state value set to negative zero (as a hand-over could leave it): the kernels' signed zeros."""
    nz = complex(-0.0, -0.0)
    if isinstance(obj, tuple):  # the shared pair
        parts = obj
    elif isinstance(obj, KubotaSpeed):
        parts = (obj, obj.obs)
    else:
        parts = (obj,)
    for part in parts:
        for name in STATE[type(part)]:
            v = getattr(part, name)
            if name in ("motor", "_b", "_inv_Tr", "clipped"):
                continue
            setattr(part, name, (nz, nz) if name == "_w_prev" else nz if isinstance(v, complex) or v is None
                    else -0.0)  # fmt: skip


@pytest.mark.parametrize("name", list(CASES))
def test_signed_zeros_are_cpythons(name):
    s = CASES[name]
    ref, twin = s.make(), s.make()
    _signed_zeros(ref)
    _signed_zeros(twin)
    a = s.pack(twin)
    nz = complex(-0.0, -0.0)
    inputs = ([(nz, nz, -0.0, nz)] * 5 + [(complex(0.0, -0.0), complex(-0.0, 0.0), 0.0, complex(-0.0, 0.0))] * 5
              + [(nz, complex(-0.0, 1e-3), -0.0, nz)] * 5 + synthetic(200, seed=7)[140:])  # fmt: skip
    for k, inp in enumerate(inputs):
        p, c = s.py(ref, inp), s.kern(a, inp)
        assert bits(p) == bits(c), (name, k, p, c)
        seen = copy.deepcopy(ref)  # the state after every tick (a signed zero seldom reaches the output)
        s.unpack(seen, a)
        assert s.state(seen) == s.state(ref), (name, k)


# --- replayed from real closed-loop runs of the FOC (each part in the loop, R_r handed over by the MRAS) ------------
def _record(rig: str, scenario: str, duration: float, params: dict) -> tuple[Any, Any, list, Any]:
    """Run a Python-engine session; return the FOC's (observer, estimator) as they were before its first tick, the
    calls it made on them in order (("obs" | "est", args, result) and ("obs_R" | "est_R", R_r)), and the pair after."""
    from bench.core.config import load as load_rig
    from bench.controllers.foc import FocController
    from bench.runtime.session import RunOptions, run

    events: list = []
    seen: dict[str, Any] = {}
    spied = [(c, "update") for c in (VoltageModelObserver, JansenLorenzObserver, KubotaObserver, LPVObserver,
                                     CurrentModelObserver, KubotaSpeed, RotorEquationSpeed)]  # fmt: skip
    spied += [(c, "set_R_r") for c in (JansenLorenzObserver, KubotaObserver, CurrentModelObserver, KubotaSpeed,
                                       RotorEquationSpeed)]  # fmt: skip
    spied += [(FocController, "step")]
    origs = {(c, n): c.__dict__[n] for c, n in spied}

    def spy(cls: type, name: str) -> Callable:
        orig = origs[(cls, name)]

        def f(self, *args):  # noqa: ANN001, ANN202
            if cls is FocController:
                if "pair" not in seen:  # before the first tick: the state the replay starts from
                    seen["ctrl"], seen["pair"] = self, copy.deepcopy((self.observer, self.estimator))
                return orig(self, *args)
            ctrl = seen.get("ctrl")
            role = None
            if ctrl is not None:
                role = "obs" if self is ctrl.observer else "est" if self is ctrl.estimator else None
            r = orig(self, *args)
            if role is not None:  # (not the calls a KubotaSpeed makes on its own observer)
                events.append((role, args, r) if name == "update" else (role + "_R", args[0]))
            return r

        return f

    for c, n in spied:
        setattr(c, n, spy(c, n))
    try:
        cfg = load_rig(rig)
        cfg = replace(cfg, mock={**cfg.mock, "engine": "compiled"})
        summary, _ = run(RunOptions(rig=cfg, scenario=scenario, seed=0, duration=duration, progress=False,
                                    params={"engine": "python", **params}, log_enabled=False))  # fmt: skip
    finally:
        for (c, n), orig in origs.items():
            setattr(c, n, orig)
    assert not summary.get("trip_cause"), summary.get("trip_cause")
    ctrl = seen["ctrl"]
    return seen["pair"][0], seen["pair"][1], events, (ctrl.observer, ctrl.estimator)


@pytest.mark.parametrize("rig,scenario,duration,params", [
    ("mock", "demo", 0.6, {"observer": "jl"}),
    ("mock", "demo", 0.6, {"observer": "lpv"}),
    ("mock", "demo", 0.6, {"observer": "voltage_model", "speed_estimator": "rotor_equation"}),
    ("mock", "demo", 0.6, {"observer": "kubota", "speed_estimator": "kubota", "speed_source": "estimate"}),
    ("mock", "demo", 0.6, {"speed_estimator": "kubota", "kubota_lambda_c": 2000.0, "kubota_tau": 0.01}),
    ("rigs/mock-warm-fast.toml", "warmup", 1.2, {"observer": "kubota", "speed_estimator": "kubota",
                                                 "rr_adapt": "mras"}),
    ("rigs/mock-warm-fast.toml", "warmup", 1.2, {"observer": "jl", "speed_estimator": "rotor_equation",
                                                 "rr_adapt": "mras"}),
    ("rigs/mock-warm-fast.toml", "warmup", 1.2, {"speed_estimator": "kubota", "rr_adapt": "mras"}),
])  # fmt: skip
def test_replayed_closed_loop_runs_are_bit_identical(rig, scenario, duration, params):
    """The calls a Python FOC made on its observer and estimator in a real session, replayed on a copy of them (it
    reproduces the run's own results) and on the kernels: the same results, and at the end the same state as the
    FOC's own objects."""
    obs0, est0, events, (obs_end, est_end) = _record(rig, scenario, duration, params)
    obs, est = copy.deepcopy((obs0, est0))
    obs_k = None if isinstance(obs0, CurrentModelObserver) else obs0  # the current model is foc_compiled's
    xo, io = _slices(obs_k) if obs_k is not None else (np.full(4, np.nan), np.zeros(4, np.int64))
    xe, ie = _slices(est0) if est0 is not None else (None, None)
    ko, ke = oc.kind_of(obs0), oc.kind_of(est0)
    n = {"obs": 0, "est": 0, "obs_R": 0, "est_R": 0}
    for ev in events:
        n[ev[0]] += 1
        if ev[0] == "obs":
            (i_s, u_s, w), r = ev[1], ev[2]
            assert bits(obs.update(i_s, u_s, w)) == bits(r)  # the replay is the run
            if obs_k is not None:
                c = complex(*oc.update(ko, xo[3:], io[3:], i_s.real, i_s.imag, u_s.real, u_s.imag, w))
                assert bits(c) == bits(r)
        elif ev[0] == "est":
            (i_s, u_s, i_m), r = ev[1], ev[2]
            assert bits(est.update(i_s, u_s, i_m)) == bits(r)
            c = oc.est_update(ke, xe[3:], ie[3:], xo[3:], io[3:], i_s.real, i_s.imag, u_s.real, u_s.imag, i_m.real,
                              i_m.imag)  # fmt: skip
            assert bits(c) == bits(r)
        elif ev[0] == "obs_R":
            obs.set_R_r(ev[1])
            if obs_k is not None:
                oc.set_R_r(ko, xo[3:], io[3:], ev[1])
        else:
            est.set_R_r(ev[1])
            oc.est_set_R_r(ke, xe[3:], ie[3:], ev[1])
    assert n["obs"] > 1500 and (est0 is None or n["est"] == n["obs"])
    if "rr_adapt" in params:
        assert n["obs_R"] > 100, "the R_r estimate was handed over"
    if obs_k is not None:
        oc.unpack(obs, xo[3:], io[3:])
        assert state(obs) == state(obs_end)
    if est0 is not None:
        oc.unpack(est, xe[3:], ie[3:])
        assert state(est) == state(est_end)


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("bad", [(complex(math.nan, 1.0), 10j, 5.0, 1 + 1j), (1 + 1j, complex(math.inf, 0.0), 5.0, 1j),
                                 (1 + 1j, 1j, math.nan, complex(math.nan, 0.0))])  # fmt: skip
def test_a_non_finite_input_acts_alike(name, bad):
    """A NaN current, an infinite voltage, a NaN speed (a broken sensor) once, amid ordinary ticks: the same bits
    (NaN included) or the same exception, tick by tick."""
    s = CASES[name]
    ref, twin = s.make(), s.make()
    a = s.pack(twin)
    inputs = synthetic(200, seed=3)[150:]
    for k, inp in enumerate(inputs[:20] + [bad] + inputs[20:]):
        outcome = []
        for f, arg in ((s.py, ref), (s.kern, a)):
            try:
                outcome.append(bits(f(arg, inp)))
            except (ArithmeticError, ValueError) as exc:
                outcome.append(type(exc).__name__)
        assert outcome[0] == outcome[1], (name, k, outcome)


def test_called_from_numba_on_slices_of_one_buffer():
    """As the compiled FOC tick would: observer and estimator slices of one float64 buffer whose tail is viewed as
    int64, the kernels called from an njit function (sensorless shared Kubota), equal to the Python pair."""
    from numba import njit

    obs, est = _shared_pair()
    (nfo, nio), (nfe, nie) = oc.layout(obs), oc.layout(est)
    NF = 5 + nfo + nfe
    buf = np.zeros(NF + nio + nie)
    iv = buf[NF:].view(np.int64)
    oc.pack(obs, buf[5:5 + nfo], iv[:nio])
    oc.pack(est, buf[5 + nfo:NF], iv[nio:])

    @njit
    def tick(buf, i_s_re, i_s_im, u_s_re, u_s_im):  # noqa: ANN001, ANN202
        x = buf[:NF]
        iv = buf[NF:].view(np.int64)
        xo, io = x[5:5 + nfo], iv[:nio]
        xe, ie = x[5 + nfo:], iv[nio:]
        mr, mi = oc.update(oc.KIND_KUBOTA, xo, io, i_s_re, i_s_im, u_s_re, u_s_im, oc.est_omega_hat(xe))
        w = oc.est_update(oc.EST_KUBOTA, xe, ie, xo, io, i_s_re, i_s_im, u_s_re, u_s_im, mr, mi)
        return mr, mi, w, oc.est_omega_r(xe)

    for i_s, u_s, _, _ in synthetic(3000, seed=11):
        i_m = obs.update(i_s, u_s, est.omega_hat)
        w = est.update(i_s, u_s, i_m)
        mr, mi, wk, wr = tick(buf, i_s.real, i_s.imag, u_s.real, u_s.imag)
        assert bits((i_m, w, est.omega_r)) == bits((complex(mr, mi), wk, wr))
    assert abs(est.omega_hat) > 1.0  # the speed estimate moved
