"""Random induction motors from 0.37 to 11 kW for the mock plant, each with a consistent nameplate.

A fleet motor is what a user would bring to the bench: a standard 4-pole, 400 V, 50 Hz cage motor with a
nameplate (``[nameplate]``: P_rated W, U_rated V line-to-line rms, I_rated A rms, f_rated Hz, n_rated rpm,
cos_phi), behind an inverter with its own voltage errors. The rig file's ``[motor]`` is what the user would
type in before any identification: an equivalent circuit estimated from the plate alone (`from_nameplate`: the
leakage from its law, the rest fitted to the plate); ``[mock.motor]`` is the hidden true machine the plant simulates.

**Scaling with power** (per unit of the rated phase impedance Z_b = U_ph/I_b; all laws anchored at (3.57),
the thesis motor: 1.5 kW, 3.6 A at 380 V, Z_b = 60.9 ohm; exponents from the trends of catalogue data of
standard IE3 4-pole motors, 0.37-11 kW):

* efficiency 1 - eta = 0.171 (P / 1 kW)^-0.287 and cos phi = 0.70 + 0.0442 ln(P / 0.37 kW) (IEC 60034-30-1's
  IE3 4-pole efficiencies, 77.3 % at 0.37 kW to 91.4 % at 11 kW; catalogue cos phi 0.70 to 0.85): only to set
  the impedance base, I_b = P / (3 U_ph eta cos phi); the plate's current and cos phi come from the circuit;
* R_s: 0.0821 pu (P / 1.5 kW)^-0.30 - copper losses fall from about 12 % to 4 % of the rating;
* R_r: 0.0542 pu (P / 1.5 kW)^-0.35 - the rotor's copper loss is the slip's share of the air-gap power, so
  R'_r in pu is about the rated slip, 8-9 % at 0.37 kW to 2.5-3 % at 11 kW (catalogue speeds 1370-1460 rpm);
* X_m = omega L_m: 1.76 pu (P / 1.5 kW)^0.15 - the magnetising current is 70 % of the rated current at
  0.37 kW and about 40 % at 11 kW (bigger machines, relatively smaller air gaps);
* the leakage per side X_ls = omega (L_s - L_m) = omega (L_r - L_m): 0.057 pu (P / 1.5 kW)^0.05 (about
  constant: the leakage's share of the voltage at rated current);
* inertia (motor and the bench's load machine, as the mock's default of 3 x the rotor's): 0.0125 kg m^2
  (P / 1.5 kW)^1.3 - catalogue rotor inertias of 4-pole motors (0.0008 kg m^2 at 0.37 kW, 0.05 at 11 kW);
  friction (the mock's 0.05 N m Coulomb, 1e-3 N m s/rad viscous at 1.5 kW) with the rated torque; the bench's DC
  load machine sized to the motor: its torque limit 1.5 x the rated torque (the thesis rig's 15 N m for 10.09 N m).

At 11 kW this gives R_s 0.51 ohm, R_r 0.31 ohm, L_m 85 mH, L_ls 2.3 mH; at 0.37 kW R_s 29 ohm, R_r 21 ohm,
L_m 1.06 H (typical data of such motors). Each true machine takes every one of R_s, R_r, X_m, X_ls times its
own factor, log-uniform within 1/`SPREAD` .. `SPREAD` (manufacturers and designs differ), and J likewise;
L_s = L_r (the thesis' assumption (3.6), so the thesis-form parameters are comparable with a truth).

**The nameplate is the true circuit's rated point**: P_rated is a standard rating (IEC 60072-1 series) drawn
uniformly; the slip where the true machine's shaft power ((3.56) at 400 V, 50 Hz, less the friction) equals
it is the rated slip: n_rated = 1500 (1 - s) rpm, I_rated and cos phi from (3.54) there, rounded as a plate
is (1 rpm, 3 digits, 2 digits). The rated main flux |psi_m| there (3.55) is where the saturation curve's
secant L_m equals the circuit's (`mock_hw.motor.Saturation`: psi_rated).

**Saturation**: the motors take turns linear, mild, linear, strong (half of them saturate). Mild is the shape
of rigs/mock-real.toml (psi_sat/psi_rated 1.25, exponent 7), drawn within psi_sat/psi_rated 1.18-1.32,
exponent 6-8; strong that of the strongly saturating test motor (0.95/0.88 = 1.08, exponent 5), drawn within
1.02-1.12, exponent 4.5-5.5.

**The inverter** (`mock_hw.inverter`'s voltage error): dead time uniform in 0-3 us (0-25 V at 560 V and 15
kHz), on-state drop 0.5-2 V with a +-10 % mismatch per phase, the soft knee i_knee 2-10 % of the rated
current (rigs/mock-real.toml: 0.2 A of 3.6 A). The sensors are the mock's (noise, 12-bit ADCs, the voltage
channel's 1 kHz filter), the current channel scaled to the motor: full scale 4 x the rated peak current (the
thesis rig: 20 A for 3.6 A); limits from the rated current as on the thesis rig (I_max 2, trips 3 x the rated
peak).

Seeded: motor k of seed s is the same whatever the fleet's size (`numpy.random.SeedSequence(s).spawn`).
Run as ``python3 -m bench.workflows.commission.fleet --motors 20 --seed 0 --out DIR``: the rig files, and fleet.json
with every motor's plate, the [motor] guess and the truth.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomlkit

from bench.workflows.commission.circuit import InverseGamma, thesis_params
from bench.core.nameplate import Nameplate
from bench.params import MotorParams
from mock_hw.motor import steady_state, Saturation
from bench.workflows.commission.identify import plate_defaults
from bench.core.config import parse

STANDARD_KW = (0.37, 0.55, 0.75, 1.1, 1.5, 2.2, 3.0, 4.0, 5.5, 7.5, 11.0)  # IEC 60072-1 ratings [kW]
U_RATED = 400.0  # [V] line-to-line rms
F_RATED = 50.0  # [Hz]
Z_P = 2  # 4 poles
LOAD_X = 1.5  # the DC load machine's torque limit over the rated torque (the thesis rig: 15 N m for 10.09 N m)
SPREAD = 1.25  # each true per-unit value within /1.25 .. x1.25 of its law
KINDS = ("linear", "mild", "linear", "strong")  # motor k is KINDS[k % 4]

# the laws (module docstring): per-unit value at 1.5 kW and the exponent of P / 1.5 kW
P_ANCHOR = 1.5e3  # [W] the thesis motor
LAWS = {"R_s": (5.0 / 60.9, -0.30), "R_r": (3.3 / 60.9, -0.35), "X_m": (2 * math.pi * 50 * 0.341 / 60.9, 0.15),
        "X_ls": (2 * math.pi * 50 * 0.011 / 60.9, 0.05), "J": (0.0125, 1.3)}  # fmt: skip


def efficiency(P: float) -> float:
    """IE3 4-pole 50 Hz efficiency trend (module docstring)."""
    return 1.0 - 0.171 * (P / 1e3) ** -0.287


def power_factor(P: float) -> float:
    """Catalogue cos phi trend of 4-pole motors (module docstring)."""
    return 0.70 + 0.0442 * math.log(P / 370.0)


def base_impedance(P: float, U: float = U_RATED) -> float:
    """Z_b = U_ph / I_b with the rated current of the efficiency and power-factor trends [ohm]."""
    u_ph = U / math.sqrt(3.0)
    return u_ph / (P / (3.0 * u_ph * efficiency(P) * power_factor(P)))


def law(name: str, P: float) -> float:
    """The per-unit law (J: in kg m^2) at shaft power P [W]."""
    x0, e = LAWS[name]
    return x0 * (P / P_ANCHOR) ** e


def circuit(P: float, f: dict[str, float] | None = None, U: float = U_RATED, f_e: float = F_RATED) -> MotorParams:
    """The T circuit (L_s = L_r) of the laws at P [W], each per-unit value times its factor in ``f`` (1 if not
    given); friction with the rated torque."""
    f = f or {}
    Zb, w = base_impedance(P, U), 2.0 * math.pi * f_e
    g = {n: law(n, P) * f.get(n, 1.0) for n in LAWS}
    L_m = g["X_m"] * Zb / w
    L_s = L_m + g["X_ls"] * Zb / w
    k_t = P / P_ANCHOR  # rated torque relative to the thesis motor's (same speed)
    return MotorParams(L_s=L_s, L_r=L_s, L_m=L_m, R_s=g["R_s"] * Zb, R_r=g["R_r"] * Zb, Z_p=Z_P, J=g["J"],
                       B_visc=1e-3 * k_t, m_coulomb=0.05 * k_t)  # fmt: skip


@dataclass(frozen=True)
class RatedPoint:
    slip: float
    I: float  # [A] rms
    cos_phi: float
    P_shaft: float  # [W]
    psi_m: float  # [Wb] |main flux| (amplitude-invariant vectors, 3.17)
    i_m: float  # [A] |magnetising current| psi_r / L_m


def operating_point(p: MotorParams, slip: float, U: float = U_RATED, f_e: float = F_RATED) -> RatedPoint:
    """The steady state (3.54)-(3.56) at ``slip`` on U [V] line-to-line rms and f_e [Hz]: current, power factor,
    shaft power (air-gap torque times speed less the friction) and the main flux."""
    w = 2.0 * math.pi * f_e
    u = math.sqrt(2.0 / 3.0) * U  # phase peak = space-vector amplitude (3.17)
    w_r = (1.0 - slip) * w
    i_s, i_m, m_e = steady_state(p, complex(u, 0.0), w, w_r)
    w_mech = w_r / p.Z_p
    fric = p.B_visc * w_mech + p.m_coulomb * math.tanh(w_mech / 0.01)
    i_rs = (i_m - i_s) * p.L_m / p.L_r  # (3.39)
    psi_m = abs(p.L_m * (i_s + i_rs))
    return RatedPoint(slip, abs(i_s) / math.sqrt(2.0), i_s.real / abs(i_s), (m_e - fric) * w_mech, psi_m, abs(i_m))


def rated_slip(p: MotorParams, P: float, U: float = U_RATED, f_e: float = F_RATED) -> float:
    """The slip where the shaft power is P [W] (below the breakdown slip)."""
    from scipy.optimize import brentq, minimize_scalar

    fn = lambda s: operating_point(p, s, U, f_e).P_shaft - P  # noqa: E731
    top = minimize_scalar(lambda s: -fn(s), bounds=(1e-4, 0.5), method="bounded").x  # breakdown
    if fn(top) <= 0:
        raise ValueError(f"the circuit cannot give {P:g} W (its breakdown power is {fn(top) + P:.4g} W)")
    return float(brentq(fn, 1e-5, top, xtol=1e-12))


def _sig(x: float, digits: int) -> float:
    return float(f"{x:.{digits - 1}e}")


def nameplate_of(p: MotorParams, P: float, U: float = U_RATED, f_e: float = F_RATED) -> tuple[Nameplate, RatedPoint]:
    """The plate of machine ``p`` rated P [W] (module docstring), and its rated point (unrounded)."""
    rp = operating_point(p, rated_slip(p, P, U, f_e), U, f_e)
    n = round(60.0 * f_e / p.Z_p * (1.0 - rp.slip))
    return Nameplate(P, U, _sig(rp.I, 3), f_e, float(n), round(rp.cos_phi, 2)), rp


def from_nameplate(plate: Nameplate) -> MotorParams:
    """The equivalent circuit a user estimates from the plate alone (the rig's ``[motor]`` before identification):
    the leakage from its law (the plate cannot tell it), then X_m, R_r and R_s so that the circuit at the plate's
    slip draws the plate's current at its cos phi and gives its shaft power (three equations, three unknowns;
    `operating_point`). The laws as they are if that has no solution."""
    from scipy.optimize import least_squares

    P, s = plate.P_rated, plate.slip

    def build(x: np.ndarray) -> MotorParams:
        return circuit(P, {"X_m": math.exp(x[0]), "R_r": math.exp(x[1]), "R_s": math.exp(x[2])}, plate.U_rated,
                       plate.f_rated)  # fmt: skip

    def res(x: np.ndarray) -> list[float]:
        op = operating_point(build(x), s, plate.U_rated, plate.f_rated)
        return [op.I / plate.I_rated - 1.0, op.P_shaft / P - 1.0, op.cos_phi / plate.cos_phi - 1.0]

    sol = least_squares(res, [0.0, 0.0, 0.0], xtol=1e-12, ftol=1e-12)
    ok = max(abs(r) for r in sol.fun) < 1e-6 and max(abs(v) for v in sol.x) < math.log(3.0)
    return build(sol.x) if ok else circuit(P, U=plate.U_rated, f_e=plate.f_rated)


@dataclass(frozen=True)
class FleetMotor:
    """One motor of the fleet: plate, the user's [motor] guess, the hidden truth, the plant's other settings."""

    label: str
    kind: str  # "linear", "mild", "strong"
    nameplate: Nameplate
    nominal: MotorParams  # [motor]: from the nameplate (`from_nameplate`)
    true: MotorParams  # [mock.motor]
    psi_rated: float  # [Wb] main flux at the rated point
    i_m_rated: float  # [A] magnetising current at the rated point (peak, space vector)
    saturation: dict[str, Any] | None  # psi_rated, psi_sat, sat_exp (None: linear)
    inverter: dict[str, Any]  # [mock.inverter]
    factors: dict[str, float] = field(default_factory=dict)  # the truth's per-unit factors

    @property
    def I_peak(self) -> float:
        return math.sqrt(2.0) * self.nameplate.I_rated

    def limits(self) -> dict[str, float]:
        """[limits] from the rated current (the thesis rig's ratios: I_max 2, trips 3 x the rated peak)."""
        ip = self.I_peak
        return {"I_max": _sig(2.0 * ip, 3), "I_trip": _sig(3.0 * ip, 3), "I_trip_phase": _sig(3.0 * ip, 3)}

    def currents(self) -> dict[str, float]:
        """[mock.currents]: the LEM's burden for a full scale of 4 x the rated peak on +-10 V (1:1000)."""
        return {"burden": _sig(1000.0 * 10.0 / (4.0 * self.I_peak), 3)}

    def load(self) -> dict[str, float]:
        """[mock.load]: the DC load machine's torque limit, 1.5 x the plate's rated torque (module docstring)."""
        return {"torque_limit": _sig(LOAD_X * self.nameplate.T_rated, 3)}

    def sat_curve(self) -> Any:
        """The true saturation curve (`mock_hw.motor.Saturation`), None if linear."""
        s = self.saturation
        return None if s is None else Saturation(self.true.L_m, s["psi_rated"], s["psi_sat"], s["sat_exp"])

    def truth_at(self, i_bias: float) -> dict[str, dict[str, float]]:
        """The parameters a standstill test at DC bias ``i_bias`` [A] (α axis) measures, in both forms: the true
        machine, with L_m the incremental dψ/di_mu at the bias on a saturating one (at standstill the rotor
        carries no DC current, so i_mu = i_bias sets the main flux; the leakages are constant in the plant)."""
        p = self.true
        sat = self.sat_curve()
        L_m = p.L_m if sat is None else sat.L_dyn(sat.solve(abs(i_bias), 0.0))
        L_ls = p.L_s - p.L_m
        g = InverseGamma.of(L_ls + L_m, L_ls + L_m, L_m, p.R_s, p.R_r)
        th = thesis_params(g)
        return {"inverse_gamma": g.as_dict(), "thesis": {n: th[n] for n in ("R_s", "R_r", "L_m", "L_s", "L_r")}}

    def standstill_params(self, voltages: str = "measured") -> dict[str, float]:
        """The standstill test's defaults on this motor's rig file, as `bench identify` takes them
        (`bench.workflows.commission.identify.plate_defaults`: scaled from the thesis motor's by the plate and
        [motor])."""
        return plate_defaults(self.guess(), self.nameplate, voltages)

    def guess(self) -> MotorParams:
        """The rig file's ``[motor]``: `nominal` to 4 digits (J to 3)."""
        m = self.nominal
        return MotorParams(**{n: _sig(getattr(m, n), 4) for n in ("L_s", "L_r", "L_m", "R_s", "R_r")}, Z_p=m.Z_p,
                           J=_sig(m.J, 3))  # fmt: skip

    def rig_doc(self, engine: str = "auto") -> tomlkit.TOMLDocument:
        """The rig file: [rig], [limits], [motor] (the plate's guess), [nameplate] (`bench.core.nameplate`), [mock] with
        the truth."""
        doc = tomlkit.document()
        doc.add(tomlkit.comment(f"A fleet motor (bench.workflows.commission.fleet): "
                                f"{self.nameplate.P_rated / 1e3:g} kW, {self.kind}; [motor] is the guess from the plate, [mock.motor] the hidden truth"))
        doc["rig"] = {"name": f"fleet-{self.label}", "driver": "mock", "rate_hz": 3000}
        doc["limits"] = {**self.limits(), "omega_max": 400.0, "u_dc_min": 400.0, "u_dc_max": 750.0,
                         "max_stall": 0.05, "ride_through": 0.05}  # the mock rigs' (rigs/mock.toml)
        g = self.guess()
        doc["motor"] = {"L_s": g.L_s, "L_r": g.L_r, "L_m": g.L_m, "R_s": g.R_s, "R_r": g.R_r, "Z_p": g.Z_p, "J": g.J}
        doc["nameplate"] = self.nameplate.as_dict()
        t = self.true
        motor: dict[str, Any] = {n: getattr(t, n) for n in ("L_s", "L_r", "L_m", "R_s", "R_r", "J", "B_visc",
                                                            "m_coulomb")}  # fmt: skip
        motor["Z_p"] = t.Z_p
        if self.saturation is not None:
            motor.update({"saturation": True, **self.saturation})
        doc["mock"] = {"engine": engine, "motor": motor, "inverter": self.inverter, "currents": self.currents(),
                       "load": self.load()}  # fmt: skip
        return doc

    def manifest(self) -> dict[str, Any]:
        """Everything about the motor as JSON (fleet.json)."""
        return {"label": self.label, "kind": self.kind, "nameplate": self.nameplate.as_dict(),
                "motor_guess": {n: getattr(self.nominal, n) for n in ("L_s", "L_r", "L_m", "R_s", "R_r", "J")},
                "truth": self.true.as_dict(), "truth_factors": self.factors, "psi_rated_Wb": self.psi_rated,
                "i_m_rated_A": self.i_m_rated, "saturation": self.saturation, "inverter": self.inverter,
                "limits": self.limits(), "currents": self.currents(), "load": self.load(),
                "standstill_params": {v: self.standstill_params(v) for v in ("measured", "reference")}}  # fmt: skip


def draw_motor(k: int, rng: np.random.Generator) -> FleetMotor:
    """Motor number ``k`` (0-based; its kind is KINDS[k % 4]) from its own generator (module docstring)."""
    kind = KINDS[k % len(KINDS)]
    P = 1e3 * float(rng.choice(STANDARD_KW))
    f = {n: float(SPREAD ** rng.uniform(-1.0, 1.0)) for n in LAWS}
    f = {n: float(f"{v:.4f}") for n, v in f.items()}
    c = circuit(P, f)
    true = c.with_(**{n: _sig(getattr(c, n), 6) for n in ("L_s", "L_r", "L_m", "R_s", "R_r", "J", "B_visc",
                                                            "m_coulomb")})  # fmt: skip
    true.validate()
    plate, rp = nameplate_of(true, P)
    inv_v = rng.uniform(0.5, 2.0)
    inverter = {"dead_time": _sig(rng.uniform(0.0, 3e-6), 3),
                "v_on": [_sig(inv_v * x, 3) for x in rng.uniform(0.9, 1.1, 3)],
                "i_knee": _sig(rng.uniform(0.02, 0.10) * plate.I_rated, 3)}  # fmt: skip
    sat = None
    if kind == "mild":
        sat = {"psi_sat": rng.uniform(1.18, 1.32), "sat_exp": rng.uniform(6.0, 8.0)}
    elif kind == "strong":
        sat = {"psi_sat": rng.uniform(1.02, 1.12), "sat_exp": rng.uniform(4.5, 5.5)}
    if sat is not None:
        sat = {"psi_rated": _sig(rp.psi_m, 4), "psi_sat": _sig(sat["psi_sat"] * rp.psi_m, 4),
               "sat_exp": round(sat["sat_exp"], 2)}  # fmt: skip
    m = FleetMotor(f"m{k:03d}", kind, plate, from_nameplate(plate), true, rp.psi_m, rp.i_m, sat, inverter, f)
    parse(m.rig_doc().unwrap())  # bench.core.config takes it: the plate against [motor], [limits]; the plant's [mock]
    return m


def draw_fleet(n: int, seed: int = 0) -> list[FleetMotor]:
    """``n`` motors; motor k depends on (seed, k) only."""
    return [draw_motor(k, np.random.default_rng(ss)) for k, ss in enumerate(np.random.SeedSequence(seed).spawn(n))]


def write_fleet(motors: list[FleetMotor], out: Path, engine: str = "auto") -> list[Path]:
    """Each motor's rig file ``<label>.toml`` and fleet.json; returns the rig files."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for m in motors:
        path = out / f"{m.label}.toml"
        path.write_text(tomlkit.dumps(m.rig_doc(engine)), encoding="utf-8")
        paths.append(path)
    (out / "fleet.json").write_text(json.dumps({"motors": [m.manifest() for m in motors]}, indent=1))
    return paths


def add_fleet_options(ap: Any, motors_help: str, motors: int = 20) -> None:
    """The fleet's ``--motors`` (default ``motors``) and ``--seed`` on an argparse parser (this module's and its
    studies')."""
    ap.add_argument("--motors", type=int, default=motors, help=f"{motors_help} (default {motors})")
    ap.add_argument("--seed", type=int, default=0, help="fleet seed (default 0)")


def fleet_options_refused(a: Any, most: int) -> bool:
    """Print the one-line refusal of bad ``--motors`` (1..``most``) or ``--seed`` (>= 0); True if refused."""
    why = (f"--motors must be in 1..{most}" if not 1 <= a.motors <= most else
           "--seed must be >= 0" if a.seed < 0 else None)  # fmt: skip
    if why:
        print(f"bench: error: {why}", file=sys.stderr)
    return why is not None


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python3 -m bench.workflows.commission.fleet",

                                 description=__doc__.splitlines()[0])
    add_fleet_options(ap, "how many motors")
    ap.add_argument("--out", type=Path, required=True, help="folder for the rig files and fleet.json")
    a = ap.parse_args(argv)
    if fleet_options_refused(a, 10000):
        return 2
    paths = write_fleet(draw_fleet(a.motors, a.seed), a.out)
    print(json.dumps({"rigs": [str(p) for p in paths], "manifest": str(Path(a.out) / "fleet.json")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
