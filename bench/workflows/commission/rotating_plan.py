"""The rotating identification's plan and parameters: its limits, the segments it runs, the drive's model.

The rotating test (`bench.workflows.commission.rotating`: the controller that runs it) and its fit
(`bench.workflows.commission.rotating_fit`, which reads a log back) both follow the plan made here from the test's
parameters (`SCHEMA`), so neither imports the other's run or fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from bench.workflows.commission.circuit import InverseGamma, thesis_params
from bench.controllers.schema import Param
from bench.params import MotorParams

SPEED_PLAN_MAX = 0.7  # the plan's speed may be at most this x omega_max ...
SPEED_TRIP = 0.8  # ... and the test trips above this x omega_max
I_MARGIN = (1.25, 0.3)  # trip above 1.25 x the test's current limit + 0.3 A
U_HEADROOM = 0.8  # the plan may need at most this fraction of the inverter's linear range
SAT_TIME = 0.01  # [s] the current loop at its voltage limit this long: trip
TRACK_TIME = 0.3  # [s] speed error above the tolerance this long: trip
END_HOLD, DEMAG = 0.2, 0.15  # [s] at 0 speed with flux, then the flux ramped down
MIN_PERIODS = 3  # electrical periods a flux level's analysis window must hold
FLUX_REACH = 1.1  # levels_from = "flux": the levels must reach at least this x the rated flux
SCAN_START, SCAN_SETTLE = 0.25, 0.3  # the scan starts at this x the a-priori i_mR,n and holds it this long [s]
SCAN_CAP = 0.9  # ... and rises at most to this x the test's current limit
PSI_TAU = 0.01  # [s] low-pass of the main-flux estimate
# a flux level settles this many rotor time constants L'_m/R'_r of the drive's model: the drive's flux loop (4.4)
# acts on its current model's estimate, the machine's flux follows with its own T_r (longer where it is unsaturated,
# 1.3-2 x the model's on the fleet's saturating motors); 0.35 s (1.1 T_r) left the 0.3 s motors 1-2 % short of their
# level, L_m of the level up to 1 % off
SETTLE_T_R = 8.0


class RotatingViolation(RuntimeError):
    """The rotating test saw something it must not continue with (one line)."""


@dataclass(frozen=True)
class Segment:
    kind: str  # "magnetise", "ramp", "scan", "level", "hold", "end"
    t0: float  # [s]
    t1: float
    a0: float  # analysis window [a0, t1) (levels, holds)
    w0: float  # speed reference at t0 and t1 [rad/s electrical] (linear in between)
    w1: float
    flux: float  # the level: x the rated magnetising current, or (levels_from = flux) x the rated flux


@dataclass(frozen=True)
class Plan:
    segments: tuple[Segment, ...]
    i_mR_n: float  # rated magnetising current of the model [A]
    duration: float

    @classmethod
    def from_params(cls, p: dict[str, Any], i_mR_n: float) -> "Plan":
        segs: list[Segment] = []
        t = 0.0

        def add(kind: str, dur: float, w0: float, w1: float, flux: float, settle: float = 0.0) -> None:
            nonlocal t
            segs.append(Segment(kind, t, t + dur, t + settle, w0, w1, flux))
            t += dur

        def ramp(w0: float, w1: float) -> None:
            add("ramp", abs(w1 - w0) / p["accel"], w0, w1, 1.0)

        w = p["omega_test"]
        add("magnetise", p["magnetise"], 0.0, 0.0, 1.0)
        ramp(0.0, w)
        if p.get("levels_from", "current") == "flux":
            add("scan", p["scan_time"], w, w, SCAN_START, SCAN_SETTLE)
        n = p["flux_levels"]
        levels = [p["flux_lo"] + (p["flux_hi"] - p["flux_lo"]) * k / (n - 1) for k in range(n)] + [1.0]
        for f in levels:
            add("level", p["level_settle"] + p["level_average"], w, w, f, p["level_settle"])
        prev = w
        for k in range(p["holds"], 0, -1):
            for sgn in (1.0, -1.0):
                ws = sgn * w * k / p["holds"]
                if ws != prev:
                    ramp(prev, ws)
                add("hold", p["hold_settle"] + p["hold_average"], ws, ws, 1.0, p["hold_settle"])
                prev = ws
        ramp(prev, 0.0)
        add("end", END_HOLD + DEMAG, 0.0, 0.0, 1.0)
        return cls(tuple(segs), i_mR_n, t)

    def at(self, t: float) -> tuple[int, float, float]:
        """(segment index or -1 after the end, speed reference [rad/s], i_mR reference [A]) at loop time t."""
        for j, s in enumerate(self.segments):
            if t < s.t1:
                x = (t - s.t0) / (s.t1 - s.t0)
                flux = s.flux
                if s.kind == "end":  # hold, then the flux ramped to 0 over DEMAG
                    flux *= min(1.0, max(0.0, (s.t1 - t) / DEMAG))
                return j, s.w0 + (s.w1 - s.w0) * x, flux * self.i_mR_n
        return -1, 0.0, 0.0

    @property
    def omega_peak(self) -> float:
        return max(max(abs(s.w0), abs(s.w1)) for s in self.segments)

    @property
    def flux_peak(self) -> float:
        return max(s.flux for s in self.segments)

    def windows(self, kind: str) -> list[tuple[int, Segment]]:
        return [(j, s) for j, s in enumerate(self.segments) if s.kind == kind]


STAGES = {"magnetise": 1, "ramp": 2, "level": 3, "hold": 4, "end": 5, "scan": 6}


def model_of(p: dict[str, Any], nominal: MotorParams) -> InverseGamma:
    """The drive's model: the ``model_*`` parameters where given (> 0), else the nominal [motor]."""
    g = InverseGamma.of(nominal.L_s, nominal.L_r, nominal.L_m, nominal.R_s, nominal.R_r)
    return InverseGamma(*(p[f"model_{n}"] or getattr(g, n) for n in ("R_s", "L_sigma", "R_R", "L_M")))


def motor_of(g: InverseGamma, nominal: MotorParams) -> MotorParams:
    """A MotorParams (L_s = L_r form) with the inverse-Γ quantities of ``g``; Z_p, J, friction of ``nominal``."""
    th = thesis_params(g)
    return nominal.with_(**{n: th[n] for n in ("L_s", "L_r", "L_m", "R_s", "R_r")})


def at_flux(g: InverseGamma, L_M: float) -> InverseGamma:
    """The model ``g`` with the magnetising inductance L'_m = ``L_M`` measured at a flux level, R'_r referred at it:
    R'_r = R_r L'_m/(L'_s + L'_m), R_r of the T form under L_s = L_r (3.6) fixed (the referral ratio (L_m/L_r)²
    changes with saturation, R_r does not). The drive's model of the mechanics and the fit's current model."""
    return InverseGamma(g.R_s, g.L_sigma, thesis_params(g)["R_r"] * L_M / (g.L_sigma + L_M), L_M)


def rated_i_mR(p: dict[str, Any], g: InverseGamma) -> float:
    """i_mR,n: ``i_mR_rated`` where given, else psi_rated / L_m with L_m of the model under L_s = L_r
    (psi_r = L_m i_mR, (3.40))."""
    return p.get("i_mR_rated") or p["psi_rated"] / thesis_params(g)["L_m"]


#: the rotating test's parameters (`RotatingIdController`'s schema)
SCHEMA: dict[str, Param] = {
    "omega_test": Param(150.0, "speed of the no-load test and the fastest hold (electrical)", "rad/s", gt=0,
                        le=5000),  # fmt: skip
    "psi_rated": Param(0.88, "rated main flux (magnitude of psi_m), where L_m is reported (bench identify and "
                       "commission: the plate's, bench.core.nameplate.rated_flux); psi_rated / L_m (model) seeds the "
                       "flux scan", "Wb", gt=0, le=10),  # fmt: skip
    "i_mR_rated": Param(0.0, "a-priori rated magnetising current: the flux scan's seed, or the levels' unit "
                        "(levels_from = current); 0: psi_rated / L_m of the model (bench identify and commission: "
                        "the plate's rated i_sd)", "A", ge=0, le=200),  # fmt: skip
    "levels_from": Param("flux", "flux: the levels' i_mR found by a flux scan, the levels x psi_rated; current: "
                         "the levels x psi_rated / L_m of the model", choices=("flux", "current")),  # fmt: skip
    "flux_lo": Param(0.5, "lowest flux level, x the rated flux (levels_from = current: x the rated magnetising "
                     "current)", gt=0, le=3),  # fmt: skip
    "flux_hi": Param(1.2, "highest flux level, as flux_lo (levels_from = flux: at least 1.1)", gt=0, le=3),
    "scan_time": Param(2.0, "the flux scan: settling at the low level, the rise and the fall (levels_from = "
                       "flux)", "s", ge=0.5, le=20),  # fmt: skip
    "scan_rate": Param(2.5, "the scan's rise and fall, x the a-priori rated magnetising current per second", "1/s",
                       gt=0.1, le=100),  # fmt: skip
    "flux_levels": Param(6, "flux levels from flux_lo to flux_hi (then 1.0 again)", ge=3, le=30),
    "level_settle": Param(0.35, "settling time per flux level", "s", ge=0.05, le=10),
    "level_average": Param(0.25, "analysis window per flux level", "s", ge=0.02, le=10),
    "holds": Param(3, "speed holds per direction (k/holds x omega_test, k = holds..1)", ge=2, le=10),
    "hold_settle": Param(0.3, "settling time per speed hold", "s", ge=0.05, le=10),
    "hold_average": Param(0.4, "analysis window per speed hold", "s", ge=0.02, le=10),
    "accel": Param(600.0, "speed-ramp rate (electrical)", "rad/s^2", gt=1, le=1e5),
    "magnetise": Param(0.4, "magnetising time at standstill", "s", ge=0.05, le=10),
    "speed_bw": Param(100.0, "speed-PI crossover (K_p = bw J / Z_p, T_i = 4 / bw; J of [motor])", "rad/s",
                      gt=1, le=1000),  # fmt: skip
    "i_max": Param(0.0, "current limit of the test (0: the rig's I_max)", "A", ge=0, le=200),
    "track_tol": Param(0.25, "speed error that trips after 0.3 s, x omega_test (at least 20 rad/s)", gt=0,
                       le=10),  # fmt: skip
    "model_R_s": Param(0.0, "model R_s (0: the rig's [motor])", "ohm", ge=0, le=1000),
    "model_L_sigma": Param(0.0, "model L'_s, the inverse-Gamma leakage (0: the rig's [motor])", "H", ge=0, le=10),
    "model_R_R": Param(0.0, "model R'_r (0: the rig's [motor])", "ohm", ge=0, le=1000),
    "model_L_M": Param(0.0, "model L'_m (0: the rig's [motor])", "H", ge=0, le=10),
    "u_filter_fc": Param(1000.0, "natural frequency of the voltage channel's 2nd-order filter (fit)", "Hz",
                         gt=0, le=1e6),  # fmt: skip
    "u_filter_zeta": Param(1.0 / math.sqrt(2.0), "damping of the voltage channel's filter (fit)", gt=0, le=10),
}
