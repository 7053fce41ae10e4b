"""The commissioning check's criteria that need no truth: what a real rig measures decides GO.

A real rig has no ``/truth``. It measures the stator currents, the stator voltages (thesis A.4: a star
resistor bridge behind a 2nd-order 1 kHz filter), the encoder angle, and it knows the torque it commands
from the DC load machine. Over steady windows of the closed-loop check (the candidate's own designs
running, `bench.workflows.commission.check.check_windows`) these are set against the model under test (the
candidate rig file's ``[motor]``, used in its inverse-Γ form R_s, L'_s, R'_r, L'_m of 4.1):

**1. The voltage model and the current model agree** (thesis 4.3). In steady state at the stator
frequency ω_s and the slip ω_slip = ω_s − ω_r, both measured (the current vector's angle, the encoder),
the current model (4.15) gives i_m,C = I / (1 + j ω_slip T_r), T_r = L'_m/R'_r, and the voltage model
(4.16)-(4.17) i_m,V = (U − R_s I − jω_s L'_s I) / (jω_s L'_m). Their ratio

    r = i_m,V / i_m,C = Z_m Y_m,    Z_m = U/I − R_s − jω_s L'_s,    Y_m = 1/(jω_s L'_m) + ω_slip/(ω_s R'_r)

is the measured magnetising branch (Z_m, as in the rotating test, `rotating_fit.branch_L`) times the
model's branch admittance: 1 for the true machine at any speed and load. It is also the measured stator
voltage against the one the model predicts for the measured current, speed and slip (the steady state
(3.54)-(3.55): U_model = (R_s + jω_s L'_s + 1/Y_m) I). Without load the slip is nearly zero and
|r| = L'_m,true / L'_m: **the flux magnitude** judges L'_m. Under load arg r ≈ atan(ω_slip T_r,true) −
atan(ω_slip T_r): **the flux angle** judges the rotor time constant, i.e. R_r. The phasors U, I are those
of the rotating test (`rotating_fit.fundamental`: whole periods, beside the offset, the negative sequence
and the inverter's harmonics), U divided by the voltage channel's filter H(jω_s) and by the sampled-data
correction (`rotating_fit.sampled_ratio`, on the model).

**2. The torque against the DC load.** The current model's torque (4.6), m_e = 3/2 Z_p L'_m Im{i_s i_m*}
with i_m of the model run offline on the logged currents and the encoder's speed, exact for the held voltage
(`rotating_fit.sampled_current_model`), averaged over each sampling period (`rotating_fit.step_torque`: the
shaft feels the mean torque, not the samples'; in steady state this is the slip relation (3.56), m_e = 3 Z_p
L_m² |i_m|² ω_slip / (2 R_r) = 3/2 Z_p L'_m T_r |i_m|² ω_slip, at the measured slip, up to the sampling's
(ω_s T)² terms: the current model on the samples alone reads the torque about 1 % high at 35 Hz and 3 kHz),
less J dω/dt, stepped between the loaded and the unloaded
windows at the same speed, against the DC load's commanded step. Friction and iron losses are the same at
the same speed and cancel. It needs no voltage measurement, and it sees L'_m (the torque constant) and T_r
(the slip's share of the current, x/(1 + x²) with x = ω_slip T_r): an L_m 30 % low makes the model's torque
step 30-45 % small (L'_m and T_r both short).

**Limits** (`Accuracy`, docs/commissioning.md): each criterion's value for the true machine is 0 up to the
errors of what enters it. Every known error source is set to its bound, one at a time, and the value's
change taken (first order); the limit is the sum of those changes (worst case, no cancellation assumed)
plus the 95 % half-width of the value's own scatter (per electrical period, or per part of a window):

* the current and voltage channels' gains (`Accuracy.i_gain`, `u_gain`), the current channels' offset
  left after `bench calibrate` (`i_offset`), the voltage filter's natural frequency and damping
  (`filter_fc`, `filter_zeta`: thesis A.4 gives the filter as 2nd order at 1 kHz), the DC load's torque
  (`load_gain`);
* the model's own 95 % intervals (`model_intervals`: from the identification; none for a ``[motor]``
  taken as it is, ``--skip-identify``), each widened by the tolerance a model is accepted with
  (`Accuracy.model_tol`, 5 %: the widest interval an identified value may have to be written). A linear
  model is exact at one flux and one rotor temperature; the check runs at its own flux (a saturating machine
  identified at the rated flux is a few % off at the check's), and the rotor may be warmer than when it was
  identified. A model within 5 % in every parameter passes; one 30 % off in L_m or R_r does not.

**Steady or not.** Both flux criteria compare steady-state phasors. A window whose per-period values scatter
more than all the known errors together allow (the scatter's 95 % half-width above the rest of the limit) is
not in steady state: the drive oscillates there (a 10 Hz speed swing on a 4 kW motor told R_r 30 % high, the
flux angle swinging ±13° per period), and its value cannot be judged. That criterion fails and says why (`UNSTEADY`),
where adding the swing to the limit would pass it (measured margins: docs/results/fleet-commission.md).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

import numpy as np

from bench.workflows.commission.circuit import InverseGamma
from bench.workflows.commission.rigfile import MAX_REL_CI
from bench.workflows.commission.rotating_fit import (filter_response, fundamental, sampled_current_model, sampled_ratio,
                                                     speed, step_torque)
from bench.workflows.commission.rotating import RotatingIdController
from mock_hw.plant import MockConfig

#: the criteria's names, as the report, the figure and the verdict name them
FLUX_MAG = "flux magnitude: voltage vs current model"
FLUX_ANGLE = "flux angle: voltage vs current model"
TORQUE = "torque step vs the DC load"
NAMES = (FLUX_MAG, FLUX_ANGLE, TORQUE)
PARAMS = ("R_s", "L_sigma", "R_R", "L_M")  # the inverse-Γ parameters (InverseGamma's fields)
PARTS = 4  # a torque window is split into this many parts for the scatter of its mean
UNSTEADY = "not in steady state"  # a window whose per-period scatter exceeds the known errors (module docstring)


@dataclass(frozen=True)
class Accuracy:
    """What the rig's measurements are known to within: the error model the limits come from (bounds, not
    standard deviations). The defaults are those of the thesis' rig class (App. A) as a lab would state them;
    a rig with better (calibrated) sensors may give smaller ones."""

    i_gain: float = 0.01  # current channels' gain, relative (LEM closed-loop transducer 0.5 %, burden, ADC)
    u_gain: float = 0.01  # voltage channels' gain, relative (resistor bridge 0.1 % parts, filter DC gain, ADC)
    i_offset: float = 0.01  # [A] current offset left after `bench calibrate` (one code: 12 bit on +-10 V, 0.5 V/A)
    filter_fc: float = 0.05  # the voltage filter's natural frequency, relative (5 % capacitors)
    filter_zeta: float = 0.05  # ... and its damping, relative
    load_gain: float = 0.03  # the DC load's torque against its command, relative (torque constant)
    # how far each model parameter may be from the machine at the check's operating point and still be a good
    # model: the width an identified value may have to be written (rigfile.MAX_REL_CI); it covers what a linear
    # model cannot follow (the flux of the check against the flux the model was identified at, a warmer rotor)
    model_tol: float = MAX_REL_CI

    def as_dict(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


ACCURACY = Accuracy()


@dataclass(frozen=True)
class Window:
    """A steady stretch of the check [a, b) [s] at the commanded load ``load`` [N m]; ``rated`` marks the
    windows at the rated speed (the flux criteria need the speed: at 10 rad/s the voltage is mostly R_s i_s
    and a window holds a fraction of an electrical period)."""

    name: str
    a: float
    b: float
    load: float
    rated: bool


@dataclass(frozen=True)
class Bench:
    """What the analysis needs of the rig besides the log: the sample period, the pole pairs, the encoder,
    the voltage channel's filter (f_c [Hz], ζ)."""

    T_s: float
    Z_p: int
    counts_per_rev: int
    modulus: int
    filt: tuple[float, float]

    @classmethod
    def of(cls, cfg: Any) -> "Bench":
        """From a rig configuration (`bench.core.config.RigConfig`): the encoder of the mock plant or of the
        front-end, the filter of thesis A.4 (the rotating test's defaults)."""
        if cfg.driver == "mock":
            enc = MockConfig.from_dict(cfg.mock).encoder
            lines, modulus = enc.lines, enc.modulus
        else:
            lines, modulus = cfg.hw["frontend"]["lines"], cfg.hw["frontend"]["modulus"]
        d = RotatingIdController.defaults
        return cls(cfg.T_s, int(cfg.motor.Z_p), 4 * int(lines), int(modulus), (d["u_filter_fc"], d["u_filter_zeta"]))


def model_intervals(ident: dict[str, Any] | None) -> dict[str, float]:
    """The model's relative 95 % half-widths per inverse-Γ parameter, from an identification result
    (`bench.workflows.commission.identify.identify`): the standstill's R_s, L'_s, R'_r, and L'_m from the standstill or,
    with the rotating test, from its L_m at the rated flux (L_m = sqrt(L'_m (L'_s + L'_m)) at a fixed L'_s:
    dL'_m/L'_m = 2 dL_m/L_m / (1 + L'_m/L_s)). None (a ``[motor]`` taken as it is): all 0."""
    if not ident or "inverse_gamma" not in ident:
        return dict.fromkeys(PARAMS, 0.0)

    def rel(v: dict[str, Any]) -> float:
        return abs(v["ci95"][1] - v["ci95"][0]) / 2.0 / abs(v["value"])

    ig = ident["inverse_gamma"]
    out = {n: rel(ig[n]) for n in PARAMS}
    if "rotating" in ident and "L_m" in ident.get("motor", {}):
        m = ident["motor"]
        out["L_M"] = 2.0 * rel(m["L_m"]) / (1.0 + m["L_m"]["value"] ** 2 / m["L_s"]["value"] ** 2)
    return out


def signals(d: dict[str, np.ndarray], bench: Bench) -> dict[str, np.ndarray]:
    """The measured space vectors (3.17) and the encoder's electrical angle from a check's columns."""
    r = {k.removeprefix("/rig/"): v for k, v in d.items() if k.startswith("/rig/")}
    i_s = (2.0 * r["i_a"] - r["i_b"] - r["i_c"]) / 3.0 + 1j * (r["i_b"] - r["i_c"]) / math.sqrt(3.0)
    y = (2.0 * r["u_a"] - r["u_b"] - r["u_c"]) / 3.0 + 1j * (r["u_b"] - r["u_c"]) / math.sqrt(3.0)
    counts = np.asarray(r["enc_count"], dtype=float)
    step = np.diff(counts)  # the counter wraps at its modulus: unwrap
    step = (step + bench.modulus / 2.0) % bench.modulus - bench.modulus / 2.0
    counts = counts[0] + np.concatenate(([0.0], np.cumsum(step)))
    theta = bench.Z_p * 2.0 * math.pi * counts / bench.counts_per_rev  # electrical
    return {"t": np.asarray(r["t"], dtype=float), "i_s": i_s, "y": y, "theta": theta,
            "m_L_ref": np.asarray(r["m_l_ref"], dtype=float)}  # fmt: skip


def _t95(n: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, n - 1)) if n > 1 else math.inf


def _tol(name: str, rel_ci: dict[str, float], acc: Accuracy) -> float:
    """How far the model's parameter ``name`` may be off, relative: its 95 % interval plus `Accuracy.model_tol`."""
    return rel_ci.get(name, 0.0) + acc.model_tol


def _perturbed(g: InverseGamma, name: str, rel: float) -> InverseGamma:
    return replace(g, **{name: getattr(g, name) * (1.0 + rel)})


def flux_ratio(Z: complex, w_s: float, w_slip: float, g: InverseGamma) -> complex:
    """r = i_m,V / i_m,C of the module docstring: the measured magnetising branch Z − R_s − jω_s L'_s times the
    model's branch admittance 1/(jω_s L'_m) + ω_slip/(ω_s R'_r); 1 for the true machine."""
    return (Z - g.R_s - 1j * w_s * g.L_sigma) * (1.0 / (1j * w_s * g.L_M) + w_slip / (w_s * g.R_R))


def flux_window(sig: dict[str, np.ndarray], win: Window, g: InverseGamma, bench: Bench, rel_ci: dict[str, float],
                acc: Accuracy = ACCURACY) -> dict[str, Any]:  # fmt: skip
    """The two flux models' ratio r over one window (module docstring), with the limits of |r| − 1 and arg r.
    NaN (and the reason) where the window holds fewer than 2 electrical periods."""
    sel = (sig["t"] >= win.a) & (sig["t"] < win.b)
    t, i_s, y, th = sig["t"][sel], sig["i_s"][sel], sig["y"][sel], sig["theta"][sel]
    out: dict[str, Any] = {"window": win.name, "t": [win.a, win.b], "load_N_m": win.load}
    if t.size < 10:
        return out | {"magnitude_pct": math.nan, "angle_deg": math.nan, "why": "no samples (the check stopped)"}
    w_r = float(np.polyfit(t, th, 1)[0])
    w_s = float(np.polyfit(t, np.unwrap(np.angle(i_s)), 1)[0])
    periods = int(abs(w_s) * (t[-1] - t[0]) / (2.0 * math.pi))
    out.update({"omega_s": w_s, "omega_r": w_r, "omega_slip": w_s - w_r, "periods": periods})
    if periods < 2:
        return out | {"magnitude_pct": math.nan, "angle_deg": math.nan,
                      "why": f"{periods} electrical period(s) in the window: too slow to compare the fluxes"}  # fmt: skip
    n_per = 2.0 * math.pi / abs(w_s) / bench.T_s
    starts = [t.size - int(round((periods - q) * n_per)) for q in range(periods + 1)]
    ratio = fundamental(t[starts[0]:], y[starts[0]:], w_s) / fundamental(t[starts[0]:], i_s[starts[0]:], w_s)
    per = np.array([fundamental(t[a:b], y[a:b], w_s) / fundamental(t[a:b], i_s[a:b], w_s)
                    for a, b in zip(starts[:-1], starts[1:])])  # fmt: skip

    def r_of(model: InverseGamma, filt: tuple[float, float] = bench.filt, gain: float = 1.0,
             u_over_i: complex | np.ndarray = ratio) -> complex | np.ndarray:  # fmt: skip
        c = sampled_ratio(model, w_s, w_r, bench.T_s, *filt)
        Z = u_over_i * gain / (filter_response(w_s, *filt) * c)
        return flux_ratio(Z, w_s, w_s - w_r, model)

    def mag(r: complex | np.ndarray) -> Any:
        return 100.0 * (np.abs(r) - 1.0)

    def ang(r: complex | np.ndarray) -> Any:
        return np.degrees(np.angle(r))

    r0 = complex(r_of(g))
    f_c, zeta = bench.filt
    errors = {"gains (current, voltage)": r_of(g, gain=1.0 + acc.i_gain + acc.u_gain),
              "voltage filter f_c": r_of(g, filt=(f_c * (1.0 + acc.filter_fc), zeta)),
              "voltage filter damping": r_of(g, filt=(f_c, zeta * (1.0 + acc.filter_zeta)))}  # fmt: skip
    errors.update({f"model {n} ±{100.0 * _tol(n, rel_ci, acc):.2g} %": r_of(_perturbed(g, n, _tol(n, rel_ci, acc)))
                   for n in PARAMS})  # fmt: skip
    r_per = np.asarray(r_of(g, u_over_i=per))
    budget = {}
    for name, f in (("magnitude", mag), ("angle", ang)):
        parts = {k: abs(float(f(v)) - float(f(r0))) for k, v in errors.items()}
        parts["scatter (95 %)"] = _t95(r_per.size) * float(np.std(f(r_per), ddof=1)) / math.sqrt(r_per.size)
        budget[name] = parts
    t_per = [0.5 * (t[a] + t[b - 1]) for a, b in zip(starts[:-1], starts[1:])]
    for name, parts in budget.items():  # steady or not (module docstring)
        scatter, rest = parts["scatter (95 %)"], sum(v for k, v in parts.items() if k != "scatter (95 %)")
        if scatter > rest:
            out[f"{name}_unsteady"] = (f"{UNSTEADY} in '{win.name}': its per-period {name} scatters "
                                       f"+-{scatter:.3g} (95 %), more than the known errors' {rest:.3g}")  # fmt: skip
    return out | {"ratio": [r0.real, r0.imag], "magnitude_pct": float(mag(r0)), "angle_deg": float(ang(r0)),
                  "magnitude_limit_pct": sum(budget["magnitude"].values()),
                  "angle_limit_deg": sum(budget["angle"].values()), "budget": budget,
                  "per_period": {"t": t_per, "magnitude_pct": mag(r_per).tolist(), "angle_deg": ang(r_per).tolist()}}  # fmt: skip


def model_torque(sig: dict[str, np.ndarray], g: InverseGamma, bench: Bench) -> tuple[np.ndarray, np.ndarray]:
    """(m_e [N m] of (4.6) averaged over each sampling period k -> k+1, at index k, the last repeated; |i_m| [A]):
    the model ``g`` run offline on the measured currents and the encoder's speed, exact for the held voltage
    (`rotating_fit.sampled_current_model`, `step_torque`)."""
    i_s = sig["i_s"]
    i_m, s_mid, m_mid = sampled_current_model(bench.T_s, i_s, speed(sig["t"], sig["theta"]), g, mid=True)
    k_t = 1.5 * bench.Z_p * g.L_M
    m = step_torque(k_t * (i_s * i_m.conj()).imag, k_t * (s_mid * m_mid.conj()).imag)
    return np.append(m, m[-1]), np.abs(i_m)


def torque_step(sig: dict[str, np.ndarray], wins: list[Window], g: InverseGamma, bench: Bench, J: float,
                rel_ci: dict[str, float], acc: Accuracy = ACCURACY, label: str = "") -> dict[str, Any]:  # fmt: skip
    """The model's torque step between the loaded and the unloaded windows ``wins`` (all at one speed) against
    the DC load's commanded step (module docstring): (Δm_model / Δm_L − 1) in %, and its limit."""
    t = sig["t"]
    on = [w for w in wins if w.load != 0.0]
    off = [w for w in wins if w.load == 0.0]
    out: dict[str, Any] = {"windows": label, "loaded": len(on), "unloaded": len(off)}
    sels = {w.name: (t >= w.a) & (t < w.b) for w in wins}
    if not on or not off or any(int(s.sum()) < 2 * PARTS for s in sels.values()):
        return out | {"deviation_pct": math.nan, "why": "no samples (the check stopped)"}
    theta_m = sig["theta"] / bench.Z_p

    def step(m_e: np.ndarray) -> tuple[float, float]:
        """(the step of the mean of m_e - J dω/dt between loaded and unloaded parts, its 95 % half-width)."""
        vals: dict[bool, list[float]] = {True: [], False: []}
        for w in wins:
            s = sels[w.name]
            tt, th, m = t[s], theta_m[s], m_e[s]
            for part in np.array_split(np.arange(tt.size), PARTS):
                accel = 2.0 * float(np.polyfit(tt[part] - tt[part][0], th[part], 2)[0])  # mechanical rad/s^2
                vals[w.load != 0.0].append(float(np.mean(m[part])) - J * accel)
        a, b = np.array(vals[True]), np.array(vals[False])
        d = float(a.mean() - b.mean())
        se = math.sqrt(a.var(ddof=1) / a.size + b.var(ddof=1) / b.size)
        return d, _t95(min(a.size, b.size)) * se

    m0, i_m_abs = model_torque(sig, g, bench)
    dm, scatter = step(m0)
    dm_L = float(np.mean([w.load for w in on]) - np.mean([w.load for w in off]))
    dev = 100.0 * (dm / dm_L - 1.0)
    i_m_mean = float(np.mean(np.concatenate([i_m_abs[s] for s in sels.values()])))
    budget = {"current gain (m ~ i_s i_m)": 100.0 * ((1.0 + acc.i_gain) ** 2 - 1.0) * abs(dm / dm_L),
              "current offset": 100.0 * 2.0 * 1.5 * bench.Z_p * g.L_M * i_m_mean * acc.i_offset / abs(dm_L),
              "DC load torque": 100.0 * acc.load_gain * abs(dm / dm_L),
              "J (50 %)": 100.0 * abs(step(m0 * 0.0)[0]) * 0.5 / abs(dm_L)}  # fmt: skip
    for n in ("R_R", "L_M"):  # the current model's parameters (R_s and L'_s do not enter it)
        tol = _tol(n, rel_ci, acc)
        gp = _perturbed(g, n, tol)
        moved = step(model_torque(sig, gp, bench)[0])[0]
        budget[f"model {n} ±{100.0 * tol:.2g} %"] = 100.0 * abs(moved - dm) / abs(dm_L)
    budget["scatter (95 %)"] = 100.0 * scatter / abs(dm_L)
    no_load = float(np.mean(np.concatenate([m0[sels[w.name]] for w in off])))
    return out | {"model_step_N_m": dm, "load_step_N_m": dm_L, "deviation_pct": dev,
                  "limit_pct": sum(budget.values()), "budget": budget, "no_load_N_m": no_load,
                  "spans": [min(w.a for w in wins) - 0.3, max(w.b for w in wins)],
                  "window_spans": [[w.a, w.b] for w in wins]}  # fmt: skip


def criteria(d: dict[str, np.ndarray], windows: list[Window], model: Any, bench: Bench,
             rel_ci: dict[str, float] | None = None, acc: Accuracy = ACCURACY,
             voltages: bool = True) -> tuple[dict[str, dict[str, Any]], dict[str, Any]]:  # fmt: skip
    """The no-truth criteria of a check's columns ``d`` for the model ``model`` (`bench.params.MotorParams`):
    (criteria in `commission._crit`'s form, the details per window). ``voltages`` False: the rig measures no
    stator voltage, the flux criteria are not judged (the torque criterion needs none)."""
    rel_ci = rel_ci or dict.fromkeys(PARAMS, 0.0)
    g = InverseGamma.of(model.L_s, model.L_r, model.L_m, model.R_s, model.R_r)
    sig = signals(d, bench)
    crit: dict[str, dict[str, Any]] = {}
    details: dict[str, Any] = {"model_inverse_gamma": g.as_dict(), "model_intervals_rel": rel_ci,
                               "accuracy": acc.as_dict(), "voltages_measured": voltages, "bench": asdict(bench)}  # fmt: skip
    if voltages:
        flux = [flux_window(sig, w, g, bench, rel_ci, acc) for w in windows if w.rated]
        details["flux"] = flux
        crit[FLUX_MAG] = _worst([(abs(f["magnitude_pct"]), f.get("magnitude_limit_pct", math.nan), f["window"])
                                 for f in flux], "%", [f["magnitude_unsteady"] for f in flux
                                                       if "magnitude_unsteady" in f])  # fmt: skip
        loaded = [f for f in flux if f["load_N_m"] != 0.0]
        crit[FLUX_ANGLE] = _worst([(abs(f["angle_deg"]), f.get("angle_limit_deg", math.nan), f["window"])
                                   for f in loaded], "deg", [f["angle_unsteady"] for f in loaded
                                                             if "angle_unsteady" in f])  # fmt: skip
    torque = [torque_step(sig, [w for w in windows if w.rated == rated], g, bench, model.J, rel_ci, acc,
                          "rated speed" if rated else "low speed")
              for rated in (False, True) if any(w.rated == rated for w in windows)]  # fmt: skip
    details["torque"] = torque
    crit[TORQUE] = _worst([(abs(q["deviation_pct"]), q.get("limit_pct", math.nan), q["windows"]) for q in torque], "%")
    return crit, details


def _worst(rows: list[tuple[float, float, str]], unit: str, unsteady: list[str] | None = None) -> dict[str, Any]:
    """One criterion over several windows: passes when every window is within its own limit and steady
    (``unsteady``: why a window is not, `UNSTEADY`); shows the window nearest to (or furthest beyond) its limit.
    No window at all: NaN, which fails."""
    if not rows:
        return {"value": math.nan, "limit": math.nan, "unit": unit, "pass": False, "window": "none"}
    v, lim, name = max(rows, key=lambda r: r[0] / r[1] if r[1] > 0 and math.isfinite(r[0]) else math.inf)
    ok = all(a <= b for a, b, _ in rows) and not unsteady  # NaN fails
    return {"value": v, "limit": lim, "unit": unit, "pass": bool(ok), "window": name} | \
        ({"why": "; ".join(unsteady)} if unsteady else {})  # fmt: skip


def draw(ax: Any, name: str, d: dict[str, np.ndarray], m: dict[str, Any], limit_style: dict[str, Any],
         win_style: dict[str, Any]) -> None:  # fmt: skip
    """The panel of the no-truth criterion ``name`` in `check.check_figure`: the flux criteria per
    electrical period over their windows, each window's value (a red X beyond its limit) and its limit; the
    torque criterion as the model's torque (4.6) above its no-load level against the DC load's command."""
    det = m.get("rig") or {}
    if name in (FLUX_MAG, FLUX_ANGLE):
        key, lim_key, unit = (("magnitude_pct", "magnitude_limit_pct", "%") if name == FLUX_MAG
                              else ("angle_deg", "angle_limit_deg", "deg"))  # fmt: skip
        first = True
        for f in det.get("flux") or []:
            if name == FLUX_ANGLE and f["load_N_m"] == 0.0:
                continue
            a, b = f["t"]
            ax.axvspan(a, b, **win_style, label="judged window" if first else None)
            pp = f.get("per_period")
            if pp:
                ax.plot(pp["t"], pp[key], ".", color="k", ms=3, label="per electrical period" if first else None)
            v, lim = f[key], f.get(lim_key, math.nan)
            bad = not abs(v) <= lim
            ax.plot([0.5 * (a + b)], [v if math.isfinite(v) else 0.0], "X" if bad else "o", ms=8 if bad else 5,
                    color="tab:red" if bad else "tab:green", label="window's value" if first else None)  # fmt: skip
            if math.isfinite(lim):
                ax.hlines([lim, -lim], a, b, **limit_style, label="its limit" if first else None)
            ax.annotate(f"{f['load_N_m']:g} N m", (a, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -9),
                        textcoords="offset points", fontsize=7, color="0.35")  # fmt: skip
            first = False
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.margins(y=0.25)
        ax.set_ylabel(f"i_m,V / i_m,C\n{'|r| - 1 [%]' if name == FLUX_MAG else 'arg r [deg]'}")
        ax.legend(fontsize=7, loc="upper left")
        return
    if name != TORQUE or "bench" not in det:
        return
    from scipy.ndimage import uniform_filter1d

    bench = Bench(**{**det["bench"], "filt": tuple(det["bench"]["filt"])})
    g = InverseGamma(**det["model_inverse_gamma"])
    sig = signals(d, bench)
    t = sig["t"]
    m_e = uniform_filter1d(model_torque(sig, g, bench)[0], max(1, int(0.02 / bench.T_s)))  # 20 ms
    above = np.full(t.size, np.nan)
    for q in det.get("torque") or []:
        spans = q.get("spans")
        if not spans or not math.isfinite(q.get("no_load_N_m", math.nan)):
            continue
        sel = (t >= spans[0]) & (t < spans[1])
        above[sel] = m_e[sel] - q["no_load_N_m"]
        for k, (a, b) in enumerate(q["window_spans"]):
            ax.axvspan(a, b, **win_style, label="judged window" if k == 0 and q["windows"] == "low speed" else None)
        txt = f"{q['windows']}: step {q['model_step_N_m']:.3g} N m for {q['load_step_N_m']:.3g} N m"
        ax.annotate(txt, (spans[0], q["load_step_N_m"]), xytext=(2, 4), textcoords="offset points", fontsize=7)
    ax.plot(t, sig["m_L_ref"], color="tab:blue", ls="--", lw=0.9, label="DC load command")
    ax.plot(t, above, "k", lw=0.7, label="model torque (4.6) above its no-load level")
    ax.set_ylabel("torque\n[N m]")
    ax.legend(fontsize=7, loc="lower right")
