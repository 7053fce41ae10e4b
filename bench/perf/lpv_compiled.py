"""Per-update cost of the compiled LPV parts (JSON): ``python -m bench.perf.lpv_compiled [updates]``.

Wall time per update, one process, same inputs, of the Python ``update`` (`LPVCurrentController`,
`LPVSpeedController`) and of its kernel (`bench.controllers.lpv_compiled`) called from a numba loop, as the
batch engine calls it (no dispatcher per call), for the shipped current artifacts (600 Hz, 3 kHz) and speed
designs (nominal, robust). The outputs of the two are checked to be the same bits.
"""

from __future__ import annotations

import json
import platform
import sys
import time

import numpy as np
from numba import njit

from bench.controllers import lpv_compiled as lc
from bench.controllers.lpv_current import LPVCurrentController, artifact_path as current_artifact
from bench.controllers.lpv_speed import LPVSpeedController, artifact_path as speed_artifact
from bench.core.jit_cache import drop_stale
from bench.params import MotorParams


@njit(cache=True)
def _current_loop(x, iv, inp, out):
    for k in range(inp.shape[0]):
        r = inp[k]
        out[k, 0], out[k, 1] = lc.current_update(x, iv, r[0], r[1], r[2], r[3], r[4], r[5], r[6])


@njit(cache=True)
def _speed_loop(x, iv, inp, out):
    for k in range(inp.shape[0]):
        r = inp[k]
        out[k, 0] = lc.speed_update(x, iv, r[0], r[1], r[2], r[3])


drop_stale(globals())  # (the loops compile the kernels in: numba's cache knows only this file's date)


def _inputs(kind: str, n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    k = np.arange(n)
    if kind == "current":  # i_ref, i_sr (near it), omega_mR, i_mR, u_max
        i_sq = 3.0 * np.sign(np.sin(0.01 * k))
        return np.column_stack([np.full(n, 1.8), i_sq, 1.8 + 0.2 * rng.standard_normal(n),
                                i_sq + 0.3 * rng.standard_normal(n), 300.0 * np.sin(0.002 * k), np.full(n, 1.8),
                                280.0 + 40.0 * np.sin(0.05 * k)])  # fmt: skip
    ref = 200.0 * np.sign(np.sin(0.003 * k))  # omega_ref, omega, i_mR, i_sd_ref
    return np.column_stack([ref, ref * (1.0 - np.exp(-(k % 1047) / 100.0)) + rng.standard_normal(n),
                            np.full(n, 1.8), np.full(n, 1.8)])  # fmt: skip


def measure(obj: object, kind: str, n: int) -> dict[str, float]:
    inp = _inputs(kind, n)
    rows = [tuple(float(v) for v in r) for r in inp]
    nf, ni = lc.layout(obj)
    x, iv = np.zeros(nf), np.zeros(ni, dtype=np.int64)
    lc.pack(obj, x, iv)
    out = np.zeros((n, 2))
    loop = _current_loop if kind == "current" else _speed_loop
    loop(x.copy(), iv.copy(), inp[:2].copy(), out[:2].copy())  # compile (or load), off the clock
    t0 = time.perf_counter()
    loop(x, iv, inp, out)
    t_kernel = time.perf_counter() - t0
    ref = np.zeros((n, 2))
    upd = obj.update
    t0 = time.perf_counter()
    if kind == "current":
        for k, r in enumerate(rows):
            u = upd(complex(r[0], r[1]), complex(r[2], r[3]), r[4], r[5], r[6])
            ref[k] = u.real, u.imag
    else:
        for k, r in enumerate(rows):
            ref[k, 0] = upd(*r)
    t_python = time.perf_counter() - t0
    return {"python_ns": 1e9 * t_python / n, "kernel_ns": 1e9 * t_kernel / n, "speedup": t_python / t_kernel,
            "same_bits": bool(np.array_equal(ref.view(np.int64), out.view(np.int64)))}


def run(n: int = 20000) -> dict[str, object]:
    m = MotorParams()
    parts = {f"current_{r:g}Hz": (LPVCurrentController(current_artifact(r), m), "current") for r in (600.0, 3000.0)}
    parts |= {f"speed_{d}": (LPVSpeedController(speed_artifact(d), m, 10.0), "speed") for d in ("nominal", "robust")}
    return {"updates": n, "python": platform.python_version(), "machine": platform.machine(),
            "parts": {name: measure(obj, kind, n) for name, (obj, kind) in parts.items()}}


if __name__ == "__main__":
    res = run(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)
    print(json.dumps(res, indent=1))
    sys.exit(0 if all(p["same_bits"] for p in res["parts"].values()) else 1)
