"""Every design constructs and verifies whatever the BLAS kernel, the set-up or the motor (synthesis.design_grid).

The construction's inertia test (B.18) used to decide on eigenvalues within round-off of zero, so which designs
constructed depended on the OpenBLAS kernel that numpy picked for the CPU. These tests run the designs in fresh
processes under several kernels (OPENBLAS_CORETYPE) and over a grid of set-ups and random motors.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from synthesis.design_grid import FLUX_OMEGAS, _off_grid, cases, current_case, flux_case, random_motors
from synthesis.models.motor import MotorData

ROOT = Path(__file__).resolve().parents[1]
#: the kernels of the issue that found the defect; "" = the one OpenBLAS picks for this CPU
KERNELS = ("", "Haswell", "SkylakeX", "Prescott")
#: the thesis' reading's gap by rate [Hz]: the LMIs' own optimum, certified by synthesis.lmi_dual (docs/results/
#: synthesis.md 4.0, 4.0.1), the bisection stops within 0.5 % of it: 3 kHz, above 150 rad/s in [1.01, 1.041] x the
#: bound; 600 Hz, from 150 rad/s up in [1.117, 1.194] x the bound (infeasible at 0.99 γ_a = 1.183x at 250, 400)
THESIS_READING_GAP = {3000.0: 1.045, 600.0: 1.20}


def _in_kernel(kernel: str, code: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE",)}
    if kernel:
        env["OPENBLAS_CORETYPE"] = kernel
    return subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip


def _kernel_runs(code: str) -> dict[str, dict]:
    procs = {k: _in_kernel(k, code) for k in KERNELS}
    out = {}
    for k, p in procs.items():
        so, se = p.communicate(timeout=600)
        assert p.returncode == 0, se[-2000:]
        out[k] = json.loads(so.strip().splitlines()[-1])
    return out


def _check_flux(rec: dict, variant: str = "full") -> None:
    assert rec["constructed"] and rec["verified"] and rec["verified_off_grid"], rec
    assert rec["max_frozen_hinf_over_gamma"] <= 1.0 + 1e-3, rec
    if variant == "full":
        assert rec["gap"] <= 1.01 and rec["backoff"] == pytest.approx(1.1), rec
    else:
        assert rec["gap"] <= THESIS_READING_GAP[rec["rate_hz"]] and rec["backoff"] <= 1.5, rec


def test_flux_observer_constructs_under_every_blas_kernel():
    """200 rad/s, full reading, 3 kHz: the design that failed on a fresh install (B.18: in_-(W) = 4 < c_Z = 5)."""
    code = ("import json, warnings; warnings.simplefilter('ignore')\n"
            "from synthesis.design_grid import flux_case\nfrom synthesis.environment import blas_info\n"
            "r = flux_case(200.0); r['blas'] = blas_info(); print(json.dumps(r, default=float))")  # fmt: skip
    runs = _kernel_runs(code)
    kernels = {k: {b["kernel"] for b in r["blas"]} for k, r in runs.items()}
    assert len(set().union(*kernels.values())) >= 3, kernels  # the runs really used different kernels
    for k, r in runs.items():
        _check_flux(r)
    gaps = [r["gap"] for r in runs.values()]
    assert max(gaps) - min(gaps) < 2e-3, gaps


def test_a_stalled_rebalancing_reaches_the_bound_under_every_blas_kernel():
    """Random motor 3 of seed 0, 400 rad/s, 3 kHz: the re-balancing stalls at 20-23x the bound under every kernel;
    which continuation path over ω_r,max escaped it depended on the kernel (20.3x under Haswell, 1.002x under
    SkylakeX). `bisect_gamma`'s escape reaches the bound under each."""
    code = ("import json, warnings; warnings.simplefilter('ignore')\n"
            "from synthesis.design_grid import random_motors\nfrom synthesis.environment import blas_info\n"
            "from synthesis.models.flux_observer import flux_gamma_a, flux_lower_bound\n"
            "from synthesis.models.motor import flux_observer_plant_discrete\n"
            "m = random_motors(20, 0)[3]\n"
            "lb = flux_lower_bound(flux_observer_plant_discrete(400.0, 1e-4, 1e-4, 1 / 3000, m)).value\n"
            "b = flux_gamma_a(400.0, Ts=1 / 3000, motor=m, lower_bound=lb)\n"
            "print(json.dumps({'gap': b.gamma_a / lb, 'first': b.iterations[0] / lb, 'blas': blas_info()}))"
            )  # fmt: skip
    runs = _kernel_runs(code)
    assert len({b["kernel"] for r in runs.values() for b in r["blas"]}) >= 3, runs
    for k, r in runs.items():
        assert r["first"] > 10.0, (k, r)  # the hard case: the first bisection is far above the bound
        assert 1.0 <= r["gap"] <= 1.01, (k, r)


@pytest.mark.slow
def test_thesis_reading_and_current_controller_under_every_blas_kernel():
    code = ("import json, warnings; warnings.simplefilter('ignore')\n"
            "from synthesis.design_grid import flux_case, current_case\n"
            "print(json.dumps([flux_case(200.0, 'partial'), flux_case(400.0, 'partial'), current_case(3000.0)],"
            " default=float))")  # fmt: skip
    procs = {k: _in_kernel(k, code) for k in KERNELS}
    for k, p in procs.items():
        so, se = p.communicate(timeout=1800)
        assert p.returncode == 0, se[-2000:]
        f200, f400, cur = json.loads(so.strip().splitlines()[-1])
        _check_flux(f200, "partial")
        _check_flux(f400, "partial")
        assert cur["verified"] and cur["verified_off_grid"], (k, cur)


def test_random_motors_are_within_the_stated_spread():
    base = MotorData()
    ms = random_motors(200, seed=3)
    for name, ref in (("R_s", base.R_s), ("R_r", base.R_r), ("L_m", base.L_m)):
        r = np.array([getattr(m, name) for m in ms]) / ref
        assert r.min() >= 0.6 and r.max() <= 1.4 and r.max() - r.min() > 0.7, name
    lsig = np.array([m.L_s - m.L_m for m in ms]) / (base.L_s - base.L_m)
    assert lsig.min() >= 0.6 - 1e-9 and lsig.max() <= 1.4 + 1e-9
    assert all(m.L_s == m.L_r for m in ms)  # the assumption of 3.6
    assert random_motors(3, seed=3)[2] == ms[2]  # reproducible


def test_a_random_motor_flux_observer_constructs_and_verifies():
    """The fast part of the grid (the kernel test above is the other): one random motor at the rigs' 400 rad/s."""
    _check_flux(flux_case(400.0, "full", 3000.0, random_motors(1, seed=7)[0]))


@pytest.mark.slow
def test_the_flux_observers_range_at_600_hz():
    _check_flux(flux_case(FLUX_OMEGAS[0], "full", 600.0))
    _check_flux(flux_case(FLUX_OMEGAS[-1], "full", 600.0))


@pytest.mark.slow
def test_thesis_reading_at_100_rad_s_and_600_hz_verifies_and_a_perturbed_gain_does_not():
    """The cell whose common-𝒳 analysis LMI found no certificate until the verification balanced the closed
    loop's state scaling (the observer's gains from the plant's states are ~9e4): it verifies on and off the
    grid, the LMI's γ is not below the frozen norms it bounds, and the same observer with its gain B_c1 off by
    2e-5 (relative) loses the level in the time-varying loop and in the analysis LMI."""
    from synthesis.lmi import ParameterSet
    from synthesis.models.flux_observer import design_flux_observer
    from synthesis.verify import verify
    from tests.test_verify import _perturb

    d = design_flux_observer(100.0, Ts=1.0 / 600.0, variant="partial")  # raises unless verified
    rep = d.verification
    assert rep.passed and rep.lmi_gamma >= rep.max_frozen_hinf * (1 - 1e-6), rep
    off = verify(d.plant, d.controller, d.gamma, _off_grid(41), raise_on_fail=False, lmi_points=None)
    assert off.passed, off
    bad = verify(d.plant, _perturb(d.controller, "B_c1", 1 + 2e-5), d.gamma, ParameterSet.interval(1).grid(41),
                 raise_on_fail=False)  # fmt: skip
    assert not bad.passed and not bad.checks["tv_gain<=gamma"] and not bad.checks["analysis_lmi<=gamma"], bad
    assert bad.lmi_gamma >= bad.max_frozen_hinf * (1 - 1e-6), bad


@pytest.mark.slow
def test_a_random_motor_current_controller_constructs_and_verifies():
    rec = current_case(600.0, random_motors(1, seed=5)[0])
    assert rec["constructed"] and rec["verified"] and rec["verified_off_grid"], rec
    assert rec["max_frozen_hinf_over_gamma"] <= 1.0 + 1e-3


@pytest.mark.slow
def test_the_whole_grid_constructs_and_verifies():
    """Flux observer 9 speeds x 2 readings x 2 rates, current controller at 3 rates, both for 20 random motors."""
    failed = []
    for label, fn, args in cases("all", n_motors=20):
        rec = fn(*args)
        try:
            if rec["design"] == "flux_observer":
                _check_flux(rec, rec["variant"])
            else:
                assert rec["constructed"] and rec["verified"] and rec["verified_off_grid"]
        except AssertionError:
            failed.append((label, rec.get("error") or {k: rec.get(k) for k in ("gap", "backoff", "verified")}))
    assert not failed, failed
