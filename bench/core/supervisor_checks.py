"""The supervisor's per-tick checks, written once: plain Python that numba compiles as it is.

`bench.core.supervisor.Supervisor` (every scalar run, either engine) calls these functions directly, and the batch
engine (`bench.batch.kernel`) compiles the same functions into its loop with ``njit``; the causes' text for
both is `cause`. They use only float and complex arithmetic that numba evaluates as CPython does (``abs`` of a
complex is C's hypot, complex division is CPython's ``_Py_c_quot``, ``cmath.phase`` is C's atan2 for a finite
quotient), so the batch engine's trip ticks are the scalar runs' to the bit. The checks that need Python
(a requested trip, a loop stall, the drivers' status bits and bursts, the drive's own fault) stay in
`Supervisor` and enter here as ``outside`` at their place in the order.

State: ``x`` (floats) and ``iv`` (ints), lists in `Supervisor`, numpy arrays in the batch engine, their slots
named below (`new_state` makes them). The trip's numbers are left in ``x[V1..V3]`` and ``iv[JUMP_*]``.
"""

from __future__ import annotations

import cmath
import math
from typing import Any

from bench.hal import SQRT3_INV

# trip codes, in the order of precedence of `measurement_checks` (the batch engine's results hold them)
TRIP_NONE = 0
TRIP_PHASE = 1  # per-phase over-current
TRIP_ISV = 2  # space-vector over-current
TRIP_JUMP = 3  # encoder jump
TRIP_STUCK = 4  # encoder stuck
TRIP_SPEED = 5  # over-speed
TRIP_DCLINK = 6  # DC link outside its band
TRIP_NAN = 7  # NaN in the measurement
TRIP_ENABLE = 8  # the drive's reported state is not the command
TRIP_NONFINITE = 9  # the controller's output (`Supervisor.check_command`)
TRIP_OUTSIDE = 10  # a cause `Supervisor` names itself (the drive's fault, the drivers' status bits)

# float slots of the state
U_ANGLE = 0  # voltage-vector rotation accumulated while the count is still [rad]
U_SUM = 1  # sum of |u_s| while the count is still [V]
PREV_UA = 2  # the last measured phase voltages, for the stuck check's rotation
PREV_UB = 3
PREV_UC = 4
V1 = 5  # the trip's numbers (`cause`)
V2 = 6
V3 = 7
N_F = 8
# int slots
STILL = 0  # ticks the encoder count has not moved
HAVE_COUNT = 1  # the encoder has given its first count
HAS_PREV = 2  # PREV_UA.. hold a measurement
MISMATCH = 3  # ticks the drive's reported state has differed from the command
JUMP_D = 4  # an encoder jump's count step and ticks
JUMP_N = 5
ENABLE_CMD = 6  # the command at an inverter-state trip (1: enabled)
N_I = 7


def new_state() -> tuple[list[float], list[int]]:
    """A fresh state (the start of a run, `Supervisor.reset`)."""
    return [0.0] * N_F, [0] * N_I


def limits(jump_max: int, rot_step_max: float, stuck_ticks: int, T_s: float, stuck_omega: float, stuck_u: float,
           i_trip_phase: float, i_trip: float, omega_max: float, u_dc_min: float, u_dc_max: float,
           enable_ticks: int) -> tuple:  # fmt: skip
    """The numbers `measurement_checks` takes as ``lim``, in its order (made once per run)."""
    return (jump_max, rot_step_max, stuck_ticks, T_s, stuck_omega, stuck_u, i_trip_phase, i_trip, omega_max,
            u_dc_min, u_dc_max, enable_ticks)  # fmt: skip


def measurement_checks(x: Any, iv: Any, lim: tuple, d: int, n: int, i_a: float, i_b: float, i_c: float, u_a: float,
                       u_b: float, u_c: float, omega: float, outside: bool, u_dc: float, inv_enabled: bool,
                       enable_cmd: bool) -> int:  # fmt: skip
    """One measurement's checks, ``n`` ticks after the last, in their order of precedence (bench.core.supervisor's
    docstring); returns the first that trips (TRIP_NONE: none). ``lim``: `limits`; ``d``: the count step the
    encoder speed has just taken; ``omega``: that speed; ``outside``: a cause `Supervisor` names itself.

    * phase and space-vector over-current;
    * the encoder: a jump is a step no shaft below twice the over-speed limit makes (``jump_max`` counts per
      tick); stuck: no count for ``stuck_ticks`` while the measured voltage vector turns faster than
      ``stuck_omega`` on average (steps above ``rot_step_max`` per tick are no field the drive turns, but a
      vector that flips) or its mean amplitude exceeds ``stuck_u``;
    * over-speed; ``outside``; the DC link; NaN; the drive's reported state against the command for more than
      ``enable_ticks``."""
    # the encoder's checks first: they keep their state every tick (the order below decides which trips)
    enc = TRIP_NONE
    if iv[HAVE_COUNT] == 0:  # the first sample: no step yet (the voltage before it counts as 0)
        iv[HAVE_COUNT] = 1
    elif abs(d) > lim[0] * n:  # jump_max
        iv[JUMP_D], iv[JUMP_N] = d, n
        enc = TRIP_JUMP
    elif d != 0:  # the shaft moved: the common case costs no voltage vector
        x[PREV_UA], x[PREV_UB], x[PREV_UC], iv[HAS_PREV] = u_a, u_b, u_c, 1
        if iv[STILL] != 0:
            iv[STILL], x[U_ANGLE], x[U_SUM] = 0, 0.0, 0.0
    else:
        rot_step_max, stuck_ticks, T_s, stuck_omega, stuck_u = lim[1], lim[2], lim[3], lim[4], lim[5]
        u = complex((2.0 * u_a - u_b - u_c) / 3.0, (u_b - u_c) * SQRT3_INV)  # (3.17), as bench.hal.space_vector
        u_prev = 0j
        if iv[HAS_PREV] != 0:
            pa, pb, pc = x[PREV_UA], x[PREV_UB], x[PREV_UC]
            u_prev = complex((2.0 * pa - pb - pc) / 3.0, (pb - pc) * SQRT3_INV)
        x[PREV_UA], x[PREV_UB], x[PREV_UC], iv[HAS_PREV] = u_a, u_b, u_c, 1
        iv[STILL] += 1
        au = abs(u)
        x[U_SUM] += au
        if au > 5.0 and abs(u_prev) > 5.0:
            step = cmath.phase(u / u_prev)
            if abs(step) <= rot_step_max * n:
                x[U_ANGLE] += step
        still = iv[STILL]
        if still >= stuck_ticks:
            w = abs(x[U_ANGLE]) / (still * T_s)
            u_mean = x[U_SUM] / still
            if w > stuck_omega or u_mean > stuck_u:
                x[V1], x[V2], x[V3] = still * T_s, w, u_mean
                enc = TRIP_STUCK
    if inv_enabled != enable_cmd:
        iv[MISMATCH] += 1
    else:
        iv[MISMATCH] = 0
    i_trip_phase = lim[6]
    if abs(i_a) > i_trip_phase or abs(i_b) > i_trip_phase or abs(i_c) > i_trip_phase:
        x[V1] = max(abs(i_a), abs(i_b), abs(i_c))
        return TRIP_PHASE
    i_s = abs(complex((2.0 * i_a - i_b - i_c) / 3.0, (i_b - i_c) * SQRT3_INV))
    if i_s > lim[7]:
        x[V1] = i_s
        return TRIP_ISV
    if enc != TRIP_NONE:  # before over-speed: a jump also fakes a huge speed
        return enc
    if abs(omega) > lim[8]:
        x[V1] = abs(omega)
        return TRIP_SPEED
    if outside:
        return TRIP_OUTSIDE
    if not (lim[9] <= u_dc <= lim[10]):
        x[V1] = u_dc
        return TRIP_DCLINK
    if math.isnan(i_a + i_b + i_c + u_a + u_b + u_c):
        return TRIP_NAN
    if iv[MISMATCH] > lim[11]:
        x[V1] = iv[MISMATCH] * lim[3]  # T_s
        iv[ENABLE_CMD] = 1 if enable_cmd else 0
        return TRIP_ENABLE
    return TRIP_NONE


def cause(code: int, lim: Any, v1: float = 0.0, v2: float = 0.0, v3: float = 0.0, d: int = 0, n: int = 1,
          jump_max: int = 0, enable_cmd: bool = False) -> str | None:  # fmt: skip
    """The one-line cause of a trip code with its numbers (``lim``: the rig's `bench.core.supervisor.Limits`); None for
    TRIP_NONE. TRIP_OUTSIDE is not named here."""
    if code == TRIP_NONE:
        return None
    if code == TRIP_PHASE:
        return f"over-current: phase |i| = {v1:.2f} A > {lim.I_trip_phase:g} A"
    if code == TRIP_ISV:
        return f"over-current: |i_s| = {v1:.2f} A > {lim.I_trip:g} A"
    if code == TRIP_JUMP:
        return f"encoder jump: {d:+d} counts in {n} tick{'s' if n > 1 else ''} > {jump_max * n}"
    if code == TRIP_STUCK:
        return (f"encoder stuck: no count for {v1:.3f} s while the stator voltage rotates at {v2:.0f} rad/s, "
                f"mean |u_s| = {v3:.0f} V")  # fmt: skip
    if code == TRIP_SPEED:
        return f"over-speed: |omega_r| = {v1:.1f} rad/s > {lim.omega_max:g} rad/s"
    if code == TRIP_DCLINK:
        return f"DC link {v1:.1f} V outside [{lim.u_dc_min:g}, {lim.u_dc_max:g}] V"
    if code == TRIP_NAN:
        return "measurement is NaN"
    if code == TRIP_ENABLE:
        said, told = ("disabled", "enabled") if enable_cmd else ("enabled", "disabled")
        return (f"inverter state: commanded {told} but the drive reports {said} for {v1 * 1e3:.1f} ms "
                f"(> {lim.enable_timeout * 1e3:g} ms)")  # fmt: skip
    if code == TRIP_NONFINITE:
        return f"controller output not finite: {complex(v1, v2)!r}"
    raise ValueError(f"no text for trip code {code}")
