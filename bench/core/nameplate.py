"""The motor's nameplate (a rig file's ``[nameplate]``), its checks against ``[motor]`` and ``[limits]``, and the
defaults of the drive, the tests and the scenarios derived from it.

Fields, as on the plate: ``P_rated`` [W] rated shaft power, ``U_rated`` [V] line-to-line rms, ``I_rated`` [A] rms,
``f_rated`` [Hz], ``n_rated`` [rpm], and optionally ``cos_phi``. Space vectors are amplitude-invariant (3.17), the
windings star-connected (App. A.1), so the rated phase-voltage amplitude is sqrt(2/3) U_rated and the rated
current amplitude sqrt(2) I_rated.

**The plate alone** gives the pole pairs Z_p = floor(60 f/n) (the synchronous speed 60 f/Z_p is the first one
above n), the slip s = 1 - Z_p n/(60 f), the rated electrical rotor speed ω_r = 2π f (1 - s) and the rated torque
T = P / (2π n/60).

**The rated point of ``[motor]``** (`operating_point`): the equivalent circuit in steady state at the plate's
voltage, frequency and slip, (3.54)-(3.56) in the inverse-Γ form of (4.2)-(4.3): the stator current, the
developed power m_e ω_r/Z_p, the rotor flux ψ_r and i_mR = |ψ_r|/L_m (3.40). The rig's ``[motor]`` must draw
the plate's current within `TOL_CURRENT` and develop its power within `TOL_POWER` there (`check`).

**The rated flux from the plate** (`rated_flux`): the steady state (4.9)-(4.10) in rotor-flux coordinates,
u_s = R_s i_s + jω_s (ψ_R + L'_s i_s), ψ_R = L'_m i_mR real, holds with |u_s| and |i_s| from the plate and one
more plate value: the power factor (cos φ: Re{u_s i_s*} = |u_s||i_s| cos φ) or, without it, the rated torque
(m_e = 3/2 Z_p ψ_R i_sq (4.6), so Re{u_s i_s*} = R_s |i_s|² + ω_s m_e/(3/2 Z_p)). Both give ψ_R i_sq and
ψ_R i_sd in closed form, and the main flux |ψ_m| = |ψ_R + L'_s i_s - L_sσ i_s| with the stator leakage
L_sσ = L'_s/2 (L_s = L_r: L_s - L_m = L'_s/(1 + L_m/L_s), 1-3 % off L'_s/2 for L_m/L_s = 0.94-0.99, which is
0.1 % of |ψ_m|). It needs R_s and the leakage L'_s, which do not saturate (a standstill test gives them), and
no L_m: the rotating test's flux levels come from it (`bench.workflows.commission.rotating`).

**Defaults** (`scaled`): on a rig whose plate is not the thesis motor's (`THESIS`), the FOC's i_mR reference
is the rated point's i_mR of ``[motor]``; the speed PI has the bandwidth `SPEED_BW` (K_p = ω_bw J/Z_p,
T_i = 4/ω_bw, the crossover of `bench.controllers.foc`); the identification's DC test currents are scaled by
I_rated / 3.6 A, its multisine's bias and swing by the rated point's magnetising current |ψ_m|/L_m over the thesis
motor's 2.6 A, and its settling times by 1.5 L'_m/R'_r of ``[motor]`` over the 0.2 s its defaults were chosen for
(never shorter than those; without a ``[motor]`` of this machine, from the plate alone), the scenarios' speeds by
the rated speed / 297.4 rad/s and their loads by the rated torque / 10.09 N m; unset ``[limits]`` current and
voltage limits follow the plate (`limit_defaults`). The over-speed limit is the rig's (``limits.omega_max``).
Where the plate is the thesis motor's, or a rig has none, everything keeps the thesis values the bench has always
used (`scaled` returns None): the derived ones differ a little (i_mR 2.59 A at the plate against the 2.5 A of
`bench.core.scenarios.I_MR_REF`). docs/commissioning.md, "Nameplate", lists every derived value with its formula.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

from bench.errors import BadInput, allowed, finite_number, subnormal

if TYPE_CHECKING:
    from bench.params import MotorParams
    from bench.core.supervisor import Limits

REQUIRED = ("P_rated", "U_rated", "I_rated", "f_rated", "n_rated")
FIELDS = {"P_rated": "W", "U_rated": "V", "I_rated": "A", "f_rated": "Hz", "n_rated": "rpm", "cos_phi": ""}
# what a plate of a motor a bench drives can say (any other value is a typo or an attack: refused in one line, and
# the derived quantities stay finite)
RANGES = {"P_rated": (1.0, 1e7), "U_rated": (1.0, 1e5), "I_rated": (0.01, 1e5), "f_rated": (0.1, 2000.0),
          "n_rated": (1.0, 240000.0), "cos_phi": (0.01, 1.0)}
MAX_SLIP = 0.2  # a rated slip above this is no induction motor's plate (1-10 % from large to small machines)
# [motor] against the plate, at the plate's voltage, frequency and slip: (3.57) are 20 degC resistances, and
# a rotor 40-100 K warmer at the rated point has a 15-40 % higher R_r, so the cold circuit develops more power
# at the rated slip ((3.57): +18 %, current +4 %); the model has no iron and friction losses either
TOL_CURRENT = 0.25
TOL_POWER = 0.40
TOL_COS_PHI = 0.10  # absolute: the circuit's power factor against the plate's (iron losses are not modelled)
U_MARGIN = 0.95  # the FOC's u_margin: the current loop uses this fraction of the linear range u_dc/sqrt(3)

# defaults derived on a non-thesis plate (docs/commissioning.md, Nameplate)
SPEED_BW = 100.0  # [rad/s] speed-PI crossover: K_p = SPEED_BW J / Z_p, T_i = 4 / SPEED_BW
SENSORLESS_BW = 40.0  # [rad/s] the same for the sensorless speed PI (the thesis retuned it slower, 5.6.3)
I_MAX_X = 1.5  # limits.I_max = 1.5 x the rated current amplitude (a drive's usual overload current)
I_TRIP_X = 2.25  # limits.I_trip, I_trip_phase = 2.25 x (the 10 A / 15 A ratio of the thesis rigs)
U_MAX_X = 1.15  # limits.U_max = 1.15 x the rated phase-voltage amplitude


@dataclass(frozen=True)
class Nameplate:
    """A motor's rating plate (SI as on the plate; module docstring)."""

    P_rated: float  # rated shaft power [W]
    U_rated: float  # rated voltage, line to line, rms [V]
    I_rated: float  # rated current, rms [A]
    f_rated: float  # rated frequency [Hz]
    n_rated: float  # rated speed [rpm]
    cos_phi: float | None = None  # rated power factor

    @property
    def Z_p(self) -> int:
        """Pole pairs: the synchronous speed 60 f/Z_p is the first one above the rated speed."""
        return int(60.0 * self.f_rated / self.n_rated)

    @property
    def slip(self) -> float:
        return 1.0 - self.Z_p * self.n_rated / (60.0 * self.f_rated)

    @property
    def omega_s(self) -> float:
        """Rated stator frequency [rad/s]."""
        return 2.0 * math.pi * self.f_rated

    @property
    def omega_r(self) -> float:
        """Rated rotor speed, electrical [rad/s]."""
        return self.Z_p * 2.0 * math.pi * self.n_rated / 60.0

    @property
    def T_rated(self) -> float:
        """Rated shaft torque P / ω_mech [N m]."""
        return self.P_rated / (2.0 * math.pi * self.n_rated / 60.0)

    @property
    def u_peak(self) -> float:
        """Rated phase-voltage amplitude sqrt(2/3) U_rated [V] (star, amplitude-invariant vectors)."""
        return math.sqrt(2.0 / 3.0) * self.U_rated

    @property
    def i_peak(self) -> float:
        """Rated current amplitude sqrt(2) I_rated [A]."""
        return math.sqrt(2.0) * self.I_rated

    def as_dict(self) -> dict[str, float]:
        return {k: v for k, v in asdict(self).items() if v is not None}


#: the thesis motor, App. A.1: 1.5 kW, 1420 rpm, 3.6 A at 380 V (50 Hz mains: Z_p = 2, slip 5.3 %, 10.09 N m)
THESIS = Nameplate(P_rated=1500.0, U_rated=380.0, I_rated=3.6, f_rated=50.0, n_rated=1420.0)
THESIS_I_M = 2.6  # [A] the thesis motor's magnetising current |ψ_m|/L_m at its plate (2.595 A for (3.57))
# [s] the rotor time constant the standstill test's settling times were chosen for: 5 and 10 time constants of the
# slowest rotor within +-40 % of (3.57); another motor's are scaled by 1.5 L'_m/R'_r of its [motor] over this (the
# 1.5 for a [motor] guessed from the plate; unscaled, a large motor's DC levels were read inside their transient:
# docs/results/fleet-commission.md)
SETTLE_T_R = 0.2
# i_sq/i_mR at the rated point, for a rotor time constant from the plate alone (ω_slip = i_sq/(τ_r i_mR), (4.5)): 1.8
# for (3.57), 1.1-2.6 over the fleet's circuits (bench.workflows.commission.fleet); the largest, so that the settling
# is long enough
SLIP_RATIO = 2.5


def parse(table: Any) -> Nameplate:
    """A ``[nameplate]`` table, checked on its own (BadInput naming the field): the known fields, the required ones,
    positive finite numbers, cos_phi in (0, 1], and a rated speed below a synchronous one with a plausible slip."""
    if not isinstance(table, dict):
        raise BadInput("nameplate", "must be a table")
    for key in table:
        if key not in FIELDS:
            raise BadInput(f"nameplate.{key}", f"unknown field; allowed: {allowed(FIELDS)}")
    for key in REQUIRED:
        if key not in table:
            raise BadInput(f"nameplate.{key}", f"missing: the plate's {', '.join(REQUIRED)} are all needed "
                           f"({FIELDS[key]})")  # fmt: skip
    vals: dict[str, float] = {}
    for key, v in table.items():
        lo, hi = RANGES[key]
        if not finite_number(v) or not lo <= v <= hi or subnormal(float(v)):
            unit = f" {FIELDS[key]}" if FIELDS[key] else ""
            raise BadInput(f"nameplate.{key}", f"must be a number in [{lo:g}, {hi:g}]{unit}, got {v!r}")
        vals[key] = float(v)
    plate = Nameplate(**vals)
    n_sync1 = 60.0 * plate.f_rated
    if plate.n_rated >= n_sync1:
        raise BadInput("nameplate.n_rated", f"must be below the synchronous speed of one pole pair at "
                       f"f_rated = {plate.f_rated:g} Hz ({n_sync1:g} rpm), got {plate.n_rated:g}")  # fmt: skip
    if not 1 <= plate.Z_p <= 32 or not 0.0 < plate.slip <= MAX_SLIP:
        zp = max(plate.Z_p, 1)
        raise BadInput("nameplate.n_rated", f"{plate.n_rated:g} rpm at {plate.f_rated:g} Hz is a slip of "
                       f"{plate.slip:.1%} below the synchronous {n_sync1 / zp:g} rpm (Z_p = {zp}); an induction "
                       f"motor's rated slip is in (0, {MAX_SLIP:.0%}]")  # fmt: skip
    return plate


@dataclass(frozen=True)
class OperatingPoint:
    """The steady state of a machine model at a voltage, frequency and slip (`operating_point`)."""

    I_rms: float  # stator current [A rms]
    P_mech: float  # developed mechanical power m_e ω_r / Z_p [W]
    m_e: float  # torque (3.56) [N m]
    cos_phi: float
    psi_r: float  # |ψ_r| [Wb]
    i_mR: float  # |ψ_r| / L_m (3.40) = i_sd in steady state [A]
    psi_m: float  # |ψ_m| = L_m |i_s + i_r| [Wb]


def operating_point(motor: MotorParams, plate: Nameplate, slip: float | None = None) -> OperatingPoint:
    """``motor``'s circuit in steady state at the plate's voltage and frequency and ``slip`` (default the plate's):
    (3.54)-(3.56) in the inverse-Γ form of (4.2)-(4.3) with d/dt = jω_s in stator coordinates, i.e.
    Z = R_s + jω_s L'_s + (jω_s L'_m ∥ R'_r/s)."""
    s = plate.slip if slip is None else slip
    w = plate.omega_s
    L_sig = motor.L_s - motor.L_m**2 / motor.L_r
    L_M = motor.L_m**2 / motor.L_r
    R_R = (motor.L_m / motor.L_r) ** 2 * motor.R_r
    Z_m = 1.0 / (1.0 / (1j * w * L_M) + s / R_R)
    Z = motor.R_s + 1j * w * L_sig + Z_m
    i_s = plate.u_peak / Z
    i_M = i_s * Z_m / (1j * w * L_M)  # the magnetising branch: psi_R = L'_m i_M, |i_M| = i_mR
    psi_R = L_M * abs(i_M)
    i_mR = abs(i_M)
    i_sq = math.sqrt(max(abs(i_s) ** 2 - i_mR**2, 0.0))
    m_e = 1.5 * motor.Z_p * L_M * i_mR * i_sq  # (4.6)
    psi_s = (plate.u_peak - motor.R_s * i_s) / (1j * w)
    psi_m = abs(psi_s - (motor.L_s - motor.L_m) * i_s)  # T circuit: psi_s = L_sσ i_s + psi_m
    return OperatingPoint(abs(i_s) / math.sqrt(2.0), m_e * w * (1.0 - s) / motor.Z_p, m_e,
                          math.cos(cmath.phase(Z)), psi_R * motor.L_r / motor.L_m, i_mR, psi_m)  # fmt: skip


@dataclass(frozen=True)
class RatedFlux:
    """The rated point from the plate with R_s and L'_s only (`rated_flux`)."""

    psi_m: float  # main flux |ψ_m| [Wb]
    psi_R: float  # inverse-Γ rotor flux ψ_R = L'_m i_mR [Wb]
    psi_s: float  # stator flux |ψ_s| [Wb]
    i_sd: float  # the current along ψ_R: i_mR at the rated point [A]
    i_sq: float  # [A]
    cos_phi: float  # the plate's, or the one the torque implies
    m_e: float  # the torque it implies [N m]


def rated_flux(plate: Nameplate, R_s: float, L_sigma: float, field: str = "nameplate") -> RatedFlux:
    """The rated point from the plate and R_s, L'_s (module docstring; BadInput naming ``field`` where the plate's
    power cannot be drawn at its voltage and current)."""
    U, I, w = plate.u_peak, plate.i_peak, plate.omega_s
    if plate.cos_phi is not None:
        re = U * I * plate.cos_phi
        a = (re - R_s * I * I) / w  # psi_R i_sq
    else:
        a = plate.T_rated / (1.5 * plate.Z_p)
        re = R_s * I * I + w * a
    if not (0.0 < a and re < U * I):
        raise BadInput(f"{field}.P_rated", f"{plate.P_rated:g} W cannot be had from {plate.U_rated:g} V and "
                       f"{plate.I_rated:g} A with R_s = {R_s:.4g} ohm: it needs a power factor of "
                       f"{re / (U * I):.2f}")  # fmt: skip
    b = math.sqrt(U * U * I * I - re * re) / w - L_sigma * I * I  # psi_R i_sd
    if not b > 0.0:
        raise BadInput(f"{field}.U_rated", f"{plate.U_rated:g} V at {plate.f_rated:g} Hz leaves no magnetising "
                       f"current beside the leakage L'_s = {L_sigma:.4g} H at {plate.I_rated:g} A")  # fmt: skip
    psi_R = math.hypot(a, b) / I
    i_s = complex(b, a) / psi_R
    psi_s = psi_R + L_sigma * i_s
    return RatedFlux(abs(psi_s - 0.5 * L_sigma * i_s), psi_R, abs(psi_s), i_s.real, i_s.imag, re / (U * I),
                     1.5 * plate.Z_p * a)  # fmt: skip


def check(plate: Nameplate, motor: MotorParams, limits: Limits, motor_given: bool) -> None:
    """The plate against the rig (BadInput naming the field; docs/commissioning.md, Nameplate): the pole pairs and,
    where ``[motor]`` states the machine (``motor_given``), its rated point (`operating_point`) within `TOL_CURRENT`,
    `TOL_POWER` and `TOL_COS_PHI`; the rated current below the trip currents; the rated voltage, i.e. the rated
    flux at the rated frequency, within what the inverter gives (``U_max`` and the linear range at ``u_dc_max``).
    The over-speed limit is the rig's choice (a rig may stay below the rated speed)."""
    if plate.Z_p != motor.Z_p:
        raise BadInput("nameplate.n_rated", f"{plate.n_rated:g} rpm at {plate.f_rated:g} Hz is Z_p = {plate.Z_p} "
                       f"pole pairs (synchronous {60 * plate.f_rated / plate.Z_p:g} rpm), but motor.Z_p = "
                       f"{motor.Z_p}")  # fmt: skip
    i_pk = plate.i_peak
    for name in ("I_trip", "I_trip_phase"):
        if i_pk >= getattr(limits, name):
            raise BadInput("nameplate.I_rated", f"{plate.I_rated:g} A rms is {i_pk:.3g} A amplitude, at or above "
                           f"limits.{name} = {getattr(limits, name):g} A: the rated current would trip")  # fmt: skip
    u_inv = min(limits.U_max, U_MARGIN * limits.u_dc_max / math.sqrt(3.0))
    if plate.u_peak > u_inv:
        raise BadInput("nameplate.U_rated", f"the rated flux needs {plate.u_peak:.0f} V ({plate.U_rated:g} V line "
                       f"to line) at {plate.f_rated:g} Hz, more than the inverter gives: {u_inv:.0f} V (limits.U_max "
                       f"= {limits.U_max:g} V, {U_MARGIN:g} x u_dc_max/sqrt(3) = "
                       f"{U_MARGIN * limits.u_dc_max / math.sqrt(3.0):.0f} V)")  # fmt: skip
    if not motor_given:
        return
    op = operating_point(motor, plate)
    where = f"the [motor] circuit at {plate.U_rated:g} V, {plate.f_rated:g} Hz, slip {plate.slip:.2%}"
    if abs(op.I_rms / plate.I_rated - 1.0) > TOL_CURRENT:
        raise BadInput("nameplate.I_rated", f"{where} draws {op.I_rms:.3g} A, not {plate.I_rated:g} A within "
                       f"{TOL_CURRENT:.0%}: the plate and [motor] are not the same machine")  # fmt: skip
    if abs(op.P_mech / plate.P_rated - 1.0) > TOL_POWER:
        raise BadInput("nameplate.P_rated", f"{where} develops {op.P_mech:.4g} W, not {plate.P_rated:g} W within "
                       f"{TOL_POWER:.0%}: the plate and [motor] are not the same machine")  # fmt: skip
    if plate.cos_phi is not None and abs(op.cos_phi - plate.cos_phi) > TOL_COS_PHI:
        raise BadInput("nameplate.cos_phi", f"{where} has a power factor of {op.cos_phi:.2f}, not {plate.cos_phi:g} "
                       f"within {TOL_COS_PHI:g}")  # fmt: skip


def limit_defaults(plate: Nameplate) -> dict[str, float]:
    """``[limits]`` values a rig with a (non-thesis) plate gets where its file sets none: I_max, the trip currents
    and U_max scaled to the rated current and voltage (`I_MAX_X`, `I_TRIP_X`, `U_MAX_X`)."""
    return {"I_max": I_MAX_X * plate.i_peak, "I_trip": I_TRIP_X * plate.i_peak,
            "I_trip_phase": I_TRIP_X * plate.i_peak, "U_max": U_MAX_X * plate.u_peak}  # fmt: skip


def plate_of(motor: MotorParams, U_rated: float, f_rated: float, n_rated: float,
             P_rated: float | None = None) -> Nameplate:  # fmt: skip
    """A plate consistent with ``motor`` (for test machines): at the voltage, frequency and speed given, the circuit's
    current and its developed power (rounded as a plate would be: 3 significant digits)."""
    probe = Nameplate(1.0, U_rated, 1.0, f_rated, n_rated)
    op = operating_point(motor, probe)
    sig = lambda x: float(f"{x:.3g}")  # noqa: E731
    return Nameplate(sig(P_rated if P_rated is not None else op.P_mech), U_rated, sig(op.I_rms), f_rated, n_rated)


# --- defaults scaled to the motor ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Scaled:
    """The drive's, the tests' and the scenarios' defaults for a rig's motor (module docstring)."""

    plate: Nameplate
    i_mR: float  # the FOC's i_mR reference [A]
    speed: float  # scenario speeds x this (rated speed / the thesis motor's)
    torque: float  # scenario loads x this (rated torque / the thesis motor's)
    current: float  # identification DC test currents x this (rated current / the thesis motor's)
    magnetising: float  # the multisine's bias and swing x this (rated |i_m| / the thesis motor's `THESIS_I_M`)
    settle: float  # the identification's settling times x this (1.5 T'_r / `SETTLE_T_R`, at least 1)
    speed_Kp: float  # [N m s/rad]
    speed_Ti: float  # [s]
    sensorless_speed_Kp: float
    sensorless_speed_Ti: float

    def foc_params(self) -> dict[str, float]:
        return {"speed_Kp": self.speed_Kp, "speed_Ti": self.speed_Ti, "sensorless_speed_Kp": self.sensorless_speed_Kp,
                "sensorless_speed_Ti": self.sensorless_speed_Ti}  # fmt: skip


def is_thesis(plate: Nameplate | None) -> bool:
    """No plate, or the thesis motor's: the bench's thesis values apply unchanged."""
    return plate is None or plate == THESIS


def scaled(m: MotorParams, plate: Nameplate | None) -> Scaled | None:
    """The defaults for a rig's motor ``m`` and its ``[nameplate]``, or None where the rig has no plate or the
    thesis motor's (then every default is the thesis value, as it always was)."""
    if is_thesis(plate):
        return None
    assert plate is not None
    op = operating_point(m, plate)
    k_i = plate.I_rated / THESIS.I_rated
    # the standstill test's biases and settling need this machine's circuit: [motor] where it is the plate's machine
    # (a rig file without one has (3.57)), else the plate alone: the magnetising current the same share of the rated
    # current as the thesis motor's, the rotor time constant from the rated slip by (4.5)
    if abs(op.I_rms / plate.I_rated - 1.0) <= TOL_CURRENT:
        k_m, T_r = op.psi_m / m.L_m / THESIS_I_M, m.Lm_p / m.Rr_p
    else:
        k_m, T_r = k_i, SLIP_RATIO / (plate.slip * plate.omega_s)
    return Scaled(plate, op.i_mR, plate.omega_r / THESIS.omega_r, plate.T_rated / THESIS.T_rated, k_i, k_m,
                  max(1.0, 1.5 * T_r / SETTLE_T_R), SPEED_BW * m.J / m.Z_p, 4.0 / SPEED_BW,
                  SENSORLESS_BW * m.J / m.Z_p, 4.0 / SENSORLESS_BW)  # fmt: skip
