"""The supervisor's per-tick checks are one source: the plain function (every scalar run) and the same function
compiled by numba (the batch engine) give the same trip codes and state to the bit."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from bench.core import supervisor_checks as sc

compiled = njit(sc.measurement_checks)


def _run(check, x, iv, lim, rows) -> list[int]:  # noqa: ANN001
    return [check(x, iv, lim, *r) for r in rows]


def test_compiled_and_plain_agree_to_the_bit() -> None:
    """10,000 ticks of a shaft that mostly stands still under a turning, noisy voltage vector (the stuck check's
    complex arithmetic: |u|, u / u_prev, its phase), with jumps, over-currents, DC-link and state faults mixed in."""
    rng = np.random.default_rng(7)
    T_s = 1 / 3000
    lim = sc.limits(40, 2.0 * 314.0 * T_s, 300, T_s, 50.0, 150.0, 16.0, 15.0, 314.0, 400.0, 700.0, 30)
    rows = []
    theta = 0.0
    for k in range(10_000):
        theta += rng.normal(0.05, 0.2)
        amp = rng.choice([2.0, 20.0, 200.0])
        u = amp * np.cos(theta - np.array([0.0, 2.0 * math.pi / 3, 4.0 * math.pi / 3])) + rng.normal(0, 1e-3, 3)
        i = rng.normal(0.0, 6.0, 3)
        d = int(rng.choice([0, 0, 0, 1, -1, 3, 90]))
        rows.append((d, int(rng.choice([1, 1, 2])), *map(float, i), *map(float, u), float(rng.normal(0, 200)),
                     bool(rng.random() < 0.01), float(rng.normal(560, 80)), bool(rng.random() < 0.5),
                     bool(rng.random() < 0.5)))  # fmt: skip
    x, iv = sc.new_state()
    xa, iva = np.zeros(sc.N_F), np.zeros(sc.N_I, np.int64)
    plain = []
    got = []
    for r in rows:  # tick by tick, each side on its own state, compared after every tick
        plain.append(sc.measurement_checks(x, iv, lim, *r))
        got.append(compiled(xa, iva, lim, *r))
        assert xa.tolist() == x and iva.tolist() == iv
    assert got == plain
    codes = set(plain)
    # the checks the mixture reaches; the stuck check's complex arithmetic is in the state compared every tick
    assert x[sc.U_ANGLE] != 0.0 and x[sc.U_SUM] > 0.0
    assert {sc.TRIP_NONE, sc.TRIP_PHASE, sc.TRIP_ISV, sc.TRIP_JUMP, sc.TRIP_SPEED, sc.TRIP_DCLINK} <= codes


def test_a_still_shaft_under_a_turning_field_is_stuck() -> None:
    """A count that does not move while the voltage vector turns at 100 rad/s: stuck after stuck_ticks, with the
    numbers the cause names."""
    T_s = 1 / 3000
    lim = sc.limits(40, 2.0 * 314.0 * T_s, 300, T_s, 50.0, 1e9, 1e9, 1e9, 314.0, 0.0, 1e9, 30)
    x, iv = sc.new_state()
    codes = []
    for k in range(400):
        th = 100.0 * k * T_s
        u = [100.0 * math.cos(th - p) for p in (0.0, 2.0 * math.pi / 3, 4.0 * math.pi / 3)]
        codes.append(sc.measurement_checks(x, iv, lim, 0, 1, 0.0, 0.0, 0.0, *u, 0.0, False, 560.0, False, False))
        if codes[-1] != sc.TRIP_NONE:
            break
    assert codes[-1] == sc.TRIP_STUCK and len(codes) == 301  # the first sample has no step; then 300 still ticks
    assert abs(x[sc.V2] - 100.0) < 0.5 and abs(x[sc.V3] - 100.0) < 1e-6
    text = sc.cause(sc.TRIP_STUCK, None, x[sc.V1], x[sc.V2], x[sc.V3])
    assert text == "encoder stuck: no count for 0.100 s while the stator voltage rotates at 100 rad/s, mean |u_s| = 100 V"
