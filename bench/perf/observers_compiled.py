"""Per-update cost of the compiled flux observers and speed estimators against their Python ``update`` (JSON).

``python -m bench.perf.observers_compiled [n_calls]``: for each part of `bench.controllers.observers_compiled`,
ns per update of the kernel called from a numba loop (as the batch engine and the compiled FOC tick call it; the
loop's own cost included, some ns) and of the Python reference called from a Python loop, on the same realistic
inputs (`bench.perf.observers._inputs`), median of ``repeats`` runs, same process. CPU time of the thread, so a
busy machine slows the numbers but does not make them meaningless.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from typing import Any

import numpy as np
from numba import njit

from bench.controllers import observers_compiled as oc
from bench.controllers.observers import JansenLorenzObserver, KubotaObserver, LPVObserver, VoltageModelObserver
from bench.controllers.speed_estimators import KubotaSpeed, RotorEquationSpeed
from bench.params import T_S_DEFAULT, MotorParams
from bench.perf.observers import _inputs


@njit  # (no cache: numba would not see a change in observers_compiled)
def _loop_obs(kind, x, iv, inp):  # inp rows: i_s re, im, u_s re, im, omega_r
    acc = 0.0
    for k in range(inp.shape[0]):
        r, _ = oc.update(kind, x, iv, inp[k, 0], inp[k, 1], inp[k, 2], inp[k, 3], inp[k, 4])
        acc += r
    return acc


@njit  # (no cache: numba would not see a change in observers_compiled)
def _loop_est(kind, xe, ive, xo, ivo, inp):  # inp rows: i_s re, im, u_s re, im, i_m re, im
    acc = 0.0
    for k in range(inp.shape[0]):
        acc += oc.est_update(kind, xe, ive, xo, ivo, inp[k, 0], inp[k, 1], inp[k, 2], inp[k, 3], inp[k, 4], inp[k, 5])
    return acc


@njit  # (no cache: numba would not see a change in observers_compiled)
def _loop_shared(xo, ivo, xe, ive, inp):  # the FOC's sensorless Kubota pair: observer, then the shared estimator
    acc = 0.0
    for k in range(inp.shape[0]):
        mr, mi = oc.update(oc.KIND_KUBOTA, xo, ivo, inp[k, 0], inp[k, 1], inp[k, 2], inp[k, 3], oc.est_omega_hat(xe))
        acc += oc.est_update(oc.EST_KUBOTA, xe, ive, xo, ivo, inp[k, 0], inp[k, 1], inp[k, 2], inp[k, 3], mr, mi)
    return acc


def _time(fn: Any, n: int, repeats: int) -> float:
    runs = []
    for _ in range(repeats):
        t0 = time.thread_time_ns()
        fn()
        runs.append((time.thread_time_ns() - t0) / n)
    return statistics.median(runs)


def _packed(obj: Any) -> tuple[np.ndarray, np.ndarray]:
    nf, ni = oc.layout(obj)
    x, iv = np.zeros(max(nf, 1)), np.zeros(max(ni, 1), np.int64)
    oc.pack(obj, x, iv)
    return x, iv


def run(n_calls: int = 20000, repeats: int = 5, seed: int = 0) -> dict[str, Any]:
    m, T = MotorParams(), T_S_DEFAULT
    args = _inputs(n_calls, seed)
    est_args = [(i, u, i * 0.5) for i, u, _ in args]  # (i_s, u_s, i_m_hat), as bench.perf.observers
    arr = np.array([(i.real, i.imag, u.real, u.imag, w) for i, u, w in args])
    est_arr = np.array([(i.real, i.imag, u.real, u.imag, h.real, h.imag) for i, u, h in est_args])
    out: dict[str, Any] = {"n_calls": n_calls, "repeats": repeats, "unit": "ns per update"}
    res: dict[str, Any] = {}
    for name, make in (("voltage_model", lambda: VoltageModelObserver(m, T)),
                       ("jl", lambda: JansenLorenzObserver(m, T)), ("kubota", lambda: KubotaObserver(m, T)),
                       ("lpv", lambda: LPVObserver(m, T))):  # fmt: skip
        py, ker = make(), make()
        x, iv = _packed(ker)
        kind = oc.kind_of(ker)
        _loop_obs(kind, x.copy(), iv.copy(), arr[:10])  # compile (or load from the cache)
        res[name] = {"compiled": _time(lambda: _loop_obs(kind, x, iv, arr), n_calls, repeats),
                     "python": _time(lambda: [py.update(*a) for a in args], n_calls, repeats)}  # fmt: skip
    for name, make in (("kubota_speed_own", lambda: KubotaSpeed(m, T)),
                       ("rotor_equation", lambda: RotorEquationSpeed(m, T))):
        py, ker = make(), make()
        x, iv = _packed(ker)
        kind = oc.kind_of(ker)
        xo, ivo = np.zeros(1), np.zeros(1, np.int64)
        _loop_est(kind, x.copy(), iv.copy(), xo, ivo, est_arr[:10])
        res[name] = {"compiled": _time(lambda: _loop_est(kind, x, iv, xo, ivo, est_arr), n_calls, repeats),
                     "python": _time(lambda: [py.update(*a) for a in est_args], n_calls, repeats)}  # fmt: skip
    obs = KubotaObserver(m, T)
    est = KubotaSpeed(m, T, shared=obs)
    pobs = KubotaObserver(m, T)
    pest = KubotaSpeed(m, T, shared=pobs)
    (xo, ivo), (xe, ive) = _packed(obs), _packed(est)
    _loop_shared(xo.copy(), ivo.copy(), xe.copy(), ive.copy(), arr[:10])

    def py_shared() -> None:
        for i, u, _ in args:
            pest.update(i, u, pobs.update(i, u, pest.omega_hat))

    res["kubota_sensorless_pair"] = {"compiled": _time(lambda: _loop_shared(xo, ivo, xe, ive, arr), n_calls, repeats),
                                     "python": _time(py_shared, n_calls, repeats)}  # fmt: skip
    for r in res.values():
        r["speedup"] = round(r["python"] / r["compiled"], 1)
    out["parts"] = res
    return out


if __name__ == "__main__":
    print(json.dumps(run(int(sys.argv[1]) if len(sys.argv) > 1 else 20000), indent=2))
