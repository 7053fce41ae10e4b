"""Thesis experiments as reference and load profiles.

Every scenario starts with a magnetising lead-in of ``T_MAGNETISE`` seconds (speed reference 0,
no load) so the rotor flux is built before the experiment proper, as one does on a rig. Times in
the profiles are loop times (lead-in included).

On a rig whose motor is not the thesis motor (a ``[nameplate]`` other than App. A.1's, `bench.core.nameplate.scaled`)
every scenario is scaled to it (`Scaling`, `scale`): speeds by the rated speed, loads by the rated torque and the
i_mR reference by the rated point's i_mR, each relative to the thesis motor's; a parameterised scenario's arguments
given on the command line are taken as they are, its defaults are scaled. On the thesis motor nothing changes.

A parameterised scenario's arguments, given or default, are held inside the rig's set-point margins before a
run starts (`check_arguments`, `bench.core.setpoints`), and so is every scenario's own profile over the run: its
speed reference, its load (at any speed up to the over-speed trip) and its flux reference (`check_profile`).
Outside, the run is refused in one line naming the scenario, the value, the bound and what to give instead.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import inspect
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from bench.core import load_profiles as lp
from bench.errors import BadInput, allowed
from bench.core.setpoints import I_MR, LOAD, SPEED, Margins, number

T_MAGNETISE = 0.4  # [s]
I_MR_REF = 2.5  # [A] default magnetising-current reference (thesis uses 1.0-2.8 A in 6.4)


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    duration: float  # default run length [s], lead-in included
    speed_ref: Callable[[float], float]  # omega_r_ref(t) [rad/s, electrical]
    load: lp.LoadProfile  # m_L_ref(t, omega_r_measured) [N m]
    i_mR_ref: float | Callable[[float], float] = I_MR_REF  # [A], constant or a function of loop time
    # parts switched while running: (t [s], part, choice), e.g. (5.0, "speed_controller", "lpv")
    # (bench.operate.operator)
    switches: tuple[tuple[float, str, str], ...] = ()


@dataclass(frozen=True)
class Scaling:
    """A motor relative to the thesis motor (`bench.core.nameplate.Scaled`): speeds and loads are multiplied by
    ``speed`` and ``torque``, the i_mR reference is ``i_mR`` [A] where the thesis scenario has `I_MR_REF`."""

    speed: float
    torque: float
    i_mR: float

    def describe(self) -> str:
        return f"scaled to the rig's motor: speeds x {self.speed:.3g}, loads x {self.torque:.3g}, i_mR {self.i_mR:.3g} A"


def scale(scn: Scenario, k: Scaling, profiles: bool = True) -> Scenario:
    """``scn`` for another motor (`Scaling`); ``profiles`` False: only the i_mR reference (a parameterised scenario
    built from scaled arguments). A speed-dependent load is evaluated at the thesis motor's equivalent speed."""
    r = k.i_mR / I_MR_REF
    i_ref = scn.i_mR_ref
    i_mR = (lambda t, f=i_ref: r * f(t)) if callable(i_ref) else r * i_ref
    if not profiles:
        return dataclasses.replace(scn, i_mR_ref=i_mR, description=f"{scn.description} ({k.describe()})")
    speed, load = scn.speed_ref, scn.load
    return dataclasses.replace(scn, speed_ref=lambda t: k.speed * speed(t),
                               load=lambda t, omega: k.torque * load(t, omega / k.speed), i_mR_ref=i_mR,
                               description=f"{scn.description} ({k.describe()})")  # fmt: skip


def _speed_steps(times: list[float], values: list[float]) -> Callable[[float], float]:
    return lp.steps(times, values)  # called as f(t)


def _fig5_7() -> Scenario:
    t0 = T_MAGNETISE
    return Scenario(
        "fig5.7",
        "Fig. 5.7: omega_ref = 10 rad/s, load switching 0 <-> 3 N m every 1/3 s",
        t0 + 2.0,
        _speed_steps([t0], [10.0]),
        lp.square(t0, 1.0 / 3.0, 0.0, 3.0),
    )


def _fig5_8() -> Scenario:
    t0, dwell = T_MAGNETISE, 0.6
    up = [-150.0 + 15.0 * i for i in range(21)]  # -150 ... 150
    levels = up + up[-2::-1]  # ... and back to -150
    times = [t0 + dwell * i for i in range(len(levels))]
    return Scenario(
        "fig5.8",
        "Fig. 5.8: steps of 15 rad/s every 0.6 s, -150 -> 150 -> -150; load 0 <-> 3 sign(omega) N m every 0.1 s",
        t0 + dwell * len(levels),
        _speed_steps(times, levels),
        lp.sign_dependent(lp.square(t0, 0.1, 0.0, 3.0)),
    )


def _demo() -> Scenario:
    t0 = T_MAGNETISE
    return Scenario(
        "demo",
        "speed 0 -> 100 -> -100 -> 0 rad/s with 4 sign(omega) N m load steps (default of `bench run`)",
        t0 + 2.8,
        _speed_steps([t0, t0 + 1.2, t0 + 2.4], [100.0, -100.0, 0.0]),
        lp.sign_dependent(lp.steps([t0 + 0.6, t0 + 1.2, t0 + 1.8, t0 + 2.4], [4.0, 0.0, 4.0, 0.0])),
    )


def _load641() -> Scenario:
    t0 = T_MAGNETISE
    return Scenario(
        "load6.4.1",
        "speed steps +-200 rad/s against the speed-dependent load 8(1-2/(1+e^{0.01 omega})) of 6.4.1",
        t0 + 3.0,
        _speed_steps([t0, t0 + 1.0, t0 + 2.0], [200.0, -200.0, 50.0]),
        lp.speed_dependent_641(),
    )


def _ramps(times: list[float], values: list[float]) -> Callable[[float], float]:
    """Piecewise linear through (times[i], values[i]); 0 before the first point, last value after."""

    def f(t: float) -> float:
        if t < times[0]:
            return 0.0
        i = bisect.bisect_right(times, t) - 1
        if i >= len(times) - 1:
            return values[-1]
        a = (t - times[i]) / (times[i + 1] - times[i])
        return values[i] + a * (values[i + 1] - values[i])

    return f


def _fig4_9() -> Scenario:
    t0, dwell = T_MAGNETISE, 0.5
    up = [25.0 * i for i in range(1, 7)]  # 25 ... 150
    levels = up + up[-2::-1] + [0.0]
    times = [t0 + dwell * i for i in range(len(levels))]
    return Scenario(
        "fig4.9",
        "Figs 4.9/4.10: speed steps of 25 rad/s every 0.5 s, 0 -> 150 -> 0, no load",
        t0 + dwell * len(levels),
        _speed_steps(times, levels),
        lp.constant(0.0),
    )


def _fig4_11() -> Scenario:
    t0, hold, ramp = T_MAGNETISE, 1.0, 10.0
    return Scenario(
        "fig4.11",
        "Figs 4.11/4.12: slow sweep -15 -> 15 -> -15 rad/s (10 s each way, after 1 s at -15); "
        "load stepping 3 <-> 7 N m every 2 s",
        t0 + hold + 2 * ramp,
        _ramps([t0, t0 + hold, t0 + hold + ramp, t0 + hold + 2 * ramp], [-15.0, -15.0, 15.0, -15.0]),
        lp.square(t0, 2.0, 3.0, 7.0),
    )


def _fig5_11() -> Scenario:
    t0, hold, ramp = T_MAGNETISE, 1.0, 10.0
    return Scenario(
        "fig5.11",
        "Fig. 5.11: slow sweep -10 -> 10 -> -10 rad/s (10 s each way, after 1 s at -10); "
        "load 6 sign(omega) N m going up, 0 coming down",
        t0 + hold + 2 * ramp,
        _ramps([t0, t0 + hold, t0 + hold + ramp, t0 + hold + 2 * ramp], [-10.0, -10.0, 10.0, -10.0]),
        lp.gated(lp.sign_dependent(lp.constant(6.0)), t0, t0 + hold + ramp),
    )


def _relay0() -> Scenario:
    return Scenario(
        "relay0",
        "relay-feedback tuning around omega_r = 0: reference 0, no load (use with controller relay_tune)",
        T_MAGNETISE + 2.0,
        lambda t: 0.0,
        lp.constant(0.0),
    )


def _fig6_14() -> Scenario:
    t0, dwell = T_MAGNETISE, 0.5
    levels = [-250.0 + 25.0 * i for i in range(19)] + [-250.0]  # -250 ... 200 in 25 rad/s steps, back in one
    times = [t0 + dwell * i for i in range(len(levels))]
    return Scenario(
        "fig6.14",
        "Figs 6.14/6.15/7.1: steps of 25 rad/s every 0.5 s, -250 -> 200, then one step to -250; load of 6.4.1",
        t0 + dwell * (len(levels) - 1) + 1.5,
        _speed_steps(times, levels),
        lp.speed_dependent_641(),
        2.8,
    )


def _warmup() -> Scenario:
    t0 = T_MAGNETISE
    return Scenario(
        "warmup",
        "a loaded run that warms the rotor, then part load: 100 rad/s (0.5 s ramp), 7 N m from 1 s, 3 N m from 14 s "
        "to 20 s (rigs/mock-warm-fast.toml: R_r up to +46 %; on-line R_r estimate: -p rr_adapt=mras)",
        20.0,
        _ramps([t0, t0 + 0.5], [0.0, 100.0]),
        lp.steps([1.0, 14.0], [7.0, 3.0]),
    )


def hold(speed: float = 297.0, load: float = 10.0) -> Scenario:
    """A parameterised scenario: the rated point, held (to switch parts at): ``speed`` [rad/s, electrical] (297:
    1420 rpm, App. A) after a 0.5 s ramp, the load ``load`` [N m] (the rated 10) from 1 s to the end at 6 s."""
    t0 = T_MAGNETISE
    rated = " (the rated point: 1420 rpm, App. A; 10 N m)" if (speed, load) == (297.0, 10.0) else ""
    return Scenario(
        "hold",
        f"a point held{rated}, to switch parts at: {speed:g} rad/s after a 0.5 s ramp, {load:g} N m from 1 s to 6 s "
        "(e.g. bench run --scenario hold --switch 3:speed_controller=lpv --switch 4.5:speed_controller=pi)",
        6.0,
        _ramps([t0, t0 + 0.5], [0.0, float(speed)]),
        lp.steps([1.0], [float(load)]),
    )


AB_PERIOD = 0.5 * 19 + 1.0  # [s] one sequence of Fig. 6.14's steps: 19 levels of 0.5 s, the step back, 1 s


def _fig6_14_ab() -> Scenario:
    t0, dwell = T_MAGNETISE, 0.5
    levels = [-250.0 + 25.0 * i for i in range(19)] + [-250.0]  # -250 ... 200 in 25 rad/s steps, back in one
    times = [t0 + seq * AB_PERIOD + dwell * i for seq in (0, 1) for i in range(len(levels))]
    t_switch = t0 + AB_PERIOD - 0.5  # in the hold at -250 rad/s after the first sequence's step back
    return Scenario(
        "fig6.14-ab",
        "Fig. 6.14's steps and load twice in one run: the PI speed controller for the first sequence, the LPV one "
        f"(6.4.3) switched in bumpless at {t_switch:g} s for the second",
        t0 + 2 * AB_PERIOD,
        _speed_steps(times, levels * 2),
        lp.speed_dependent_641(),
        2.8,
        switches=((t_switch, "speed_controller", "lpv"),),
    )


def load_step(speed: float = 50.0, load: float = 3.0) -> Scenario:
    """A parameterised scenario: a constant speed reference ``speed`` [rad/s, electrical] from the lead-in's end, a
    load step 0 -> ``load`` [N m] 0.3 s later, 1 s in all (0.6 s after the lead-in). Short cases for studies over
    many operating points (`bench.workflows.reproductions.sensitivity`); the batch engine takes both per case
    (`bench.batch.engine.Run`'s ``scenario_args``). ``load-step`` on its own is the defaults."""
    t0 = T_MAGNETISE
    return Scenario(
        "load-step",
        f"constant speed {speed:g} rad/s, load step 0 -> {load:g} N m at {t0 + 0.3:g} s",
        t0 + 0.6,
        _speed_steps([t0], [float(speed)]),
        lp.steps([t0 + 0.3], [float(load)]),
    )


SCENARIOS: dict[str, Callable[..., Scenario]] = {  # a parameterised one takes float keywords
    "demo": _demo,
    "fig5.7": _fig5_7,
    "fig5.8": _fig5_8,
    "load6.4.1": _load641,
    "fig4.9": _fig4_9,
    "fig4.11": _fig4_11,
    "fig5.11": _fig5_11,
    "relay0": _relay0,
    "fig6.14": _fig6_14,
    "warmup": _warmup,
    "hold": hold,
    "fig6.14-ab": _fig6_14_ab,
    "load-step": load_step,
}


# what each argument of a parameterised scenario sets, for the set-point margins (`bench.core.setpoints`)
ARGUMENT_QUANTITIES = {"speed": SPEED, "load": LOAD}


def arguments(name: str) -> dict[str, float]:
    """The arguments a parameterised scenario takes, with their defaults (``{}``: a scenario without any)."""
    if name not in SCENARIOS:
        raise BadInput("scenario", f"unknown scenario {name!r}; allowed: {allowed(SCENARIOS)}")
    return {a: float(p.default) for a, p in inspect.signature(SCENARIOS[name]).parameters.items()}


def check_argument(name: str, key: str, value: Any, margins: Margins | None = None, got: str | None = None) -> float:
    """One argument of scenario ``name``: BadInput naming ``scenario.KEY`` for an unknown argument, a value that is
    not a finite number or is subnormal, and with a rig's ``margins`` a value outside them (a speed, a load torque:
    `ARGUMENT_QUANTITIES`); ``got``: how the message shows the value."""
    takes = arguments(name)
    field = f"scenario.{key}"
    if key not in takes:
        raise BadInput(field, f"unknown argument: {name!r} " + (f"takes {allowed(takes)}" if takes else
                                                                 "takes no arguments"))  # fmt: skip
    return number(field, value) if margins is None else margins.check(field, ARGUMENT_QUANTITIES[key], value, got)


def check_arguments(name: str, args: Mapping[str, Any] | None, margins: Margins | None = None) -> dict[str, float]:
    """``args`` of scenario ``name``, each checked (`check_argument`), with the defaults filled in; with a rig's
    ``margins`` the defaults are checked as well."""
    takes = arguments(name)
    args = dict(args or {})
    given = {k: check_argument(name, k, v, margins) for k, v in args.items()}
    out = {}
    for k, default in takes.items():
        hint = "" if margins is None else f" inside (--scenario-arg {k}={margins.bound(ARGUMENT_QUANTITIES[k]):g})"
        out[k] = given[k] if k in given else check_argument(name, k, default, margins,
                                                            f"{default:g}, the default of {name!r}: give {k} a value"
                                                            f"{hint}")  # fmt: skip
    return out


def get(name: str, args: Mapping[str, Any] | None = None, margins: Margins | None = None,
        scaling: Scaling | None = None) -> Scenario:
    """The scenario ``name``; a parameterised one (`arguments`) with ``args`` (its defaults where left out), checked
    (`check_arguments`: with a rig's ``margins``, inside them); with ``scaling`` for another motor (`scale`: the
    defaults of the arguments scaled, the given ones as they are)."""
    checked = check_arguments(name, scaled_arguments(name, args, scaling), margins)  # (names an unknown scenario)
    scn = SCENARIOS[name](**checked)
    return scn if scaling is None else scale(scn, scaling, profiles=not checked)


def scaled_arguments(name: str, args: Mapping[str, Any] | None, scaling: Scaling | None) -> dict[str, Any]:
    """``args`` with, where ``scaling`` is given, the scenario's other arguments at their defaults scaled (a speed
    by ``scaling.speed``, a load by ``scaling.torque``)."""
    if scaling is None:
        return dict(args or {})
    factor = {SPEED: scaling.speed, LOAD: scaling.torque}
    return {**{k: v * factor[ARGUMENT_QUANTITIES[k]] for k, v in arguments(name).items()}, **dict(args or {})}


# A scenario's own profile against the margins (`check_profile`): sampled every `PEAK_STEP` over the run (every
# profile here holds each value for 0.1 s or more and ends its ramps on a sample), at most `PEAK_TAIL` past the
# scenario's own duration (a longer run: its profiles hold their last value or repeat within 2 s, Fig. 4.11's load)
PEAK_STEP = 1e-3  # [s]
PEAK_TAIL = 5.0  # [s]
_FIX = {SPEED: "speed", LOAD: "load"}  # the argument that sets a quantity (`ARGUMENT_QUANTITIES`, reversed)


@dataclass(frozen=True)
class Peak:
    """The largest magnitude of one set-point of a profile, and the first time it is commanded [s]."""

    value: float
    t: float


def peaks(scn: Scenario, omega_max: float, duration: float | None = None) -> dict[str, Peak]:
    """The largest |speed reference| [rad/s], |load torque| [N m] (at the speeds -omega_max, -1, 0, 1, omega_max and
    the reference: a load may follow the measured speed up to the over-speed trip ``omega_max``) and |flux reference|
    [A] of ``scn`` over a run of ``duration`` (default: its own), keyed `SPEED`, `LOAD`, `I_MR`."""
    end = min(scn.duration if duration is None else duration, scn.duration + PEAK_TAIL)
    best = {SPEED: Peak(0.0, 0.0), LOAD: Peak(0.0, 0.0), I_MR: Peak(0.0, 0.0)}
    flux = scn.i_mR_ref if callable(scn.i_mR_ref) else None
    if flux is None:
        best[I_MR] = Peak(abs(float(scn.i_mR_ref)), 0.0)
    speeds = (-omega_max, -1.0, 0.0, 1.0, omega_max)
    for k in range(int(end / PEAK_STEP + 1e-9) + 1):
        t = k * PEAK_STEP
        w = float(scn.speed_ref(t))
        got = [(SPEED, abs(w)), (LOAD, max(abs(float(scn.load(t, x))) for x in (*speeds, w)))]
        if flux is not None:
            got.append((I_MR, abs(float(flux(t)))))
        for q, v in got:
            if not v <= best[q].value:  # (a NaN is kept: it is refused below)
                best[q] = Peak(v, t)
    return best


def check_profile(scn: Scenario, margins: Margins, duration: float | None = None,
                  advice: Mapping[str, tuple[str, str]] | None = None) -> None:  # fmt: skip
    """`BadInput` (field ``scenario``, one line) unless the set-points ``scn`` commands over a run of ``duration``
    (default: its own) stay inside the rig's ``margins`` (`peaks`): naming the scenario, the value and when, the
    bound, and what to give instead. ``advice``: per quantity (`SPEED`, `LOAD`, `I_MR`) the field to name and what
    to give instead, for a caller whose user sets the profile otherwise (`bench.workflows.commission.commission`)."""
    got = peaks(scn, margins.omega_max, duration)
    for q, what in ((SPEED, "a speed reference"), (LOAD, "a load torque"), (I_MR, "a flux reference i_mR")):
        p = got[q]
        if math.isfinite(p.value) and p.value <= margins.bound(q):
            continue
        field, fix = ("scenario", _fix(scn.name, q, margins)) if advice is None else advice[q]
        raise BadInput(field, f"{scn.name!r} commands {what} of {p.value:g} {_unit(q)} at t = {p.t:g} s, outside "
                       f"{margins.allowed(q)[len('a number in '):]}; {fix}")  # fmt: skip


def check_named(name: str, args: Mapping[str, float], margins: Margins, duration: float | None = None) -> None:
    """`check_profile` of the thesis scenario ``name`` with its (checked) ``args``, remembered: a sweep or a batch
    asks for the same few many times."""
    _check_named(name, tuple(sorted(args.items())), margins, duration)


@functools.lru_cache(maxsize=256)
def _check_named(name: str, args: tuple[tuple[str, float], ...], margins: Margins, duration: float | None) -> None:
    check_profile(get(name, dict(args)), margins, duration)


def _unit(quantity: str) -> str:
    return {SPEED: "rad/s", LOAD: "N m", I_MR: "A"}[quantity]


def _fix(name: str, quantity: str, margins: Margins) -> str:
    """What to run instead, for a profile whose ``quantity`` leaves the margins."""
    b = f"{margins.bound(quantity):g}"
    arg = _FIX.get(quantity)
    if arg is not None and name in SCENARIOS and arg in arguments(name):
        return f"give a smaller one: --scenario-arg {arg}={b}"
    if arg is None:
        return "a rig file whose limits.I_max allows it"
    takes = [n for n in SCENARIOS if arg in arguments(n)]
    return (f"a shorter --duration, a rig file whose limits allow it, or a scenario that takes its {arg} "
            f"(--scenario {takes[0]} --scenario-arg {arg}={b}; also {', '.join(takes[1:])})")
