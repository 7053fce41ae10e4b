"""The fits of the rotating identification (`bench.workflows.commission.rotating`), from its MCAP log.

**No-load test, per flux level.** Over the level's window [a0, t1):

* the stator frequency ω_s: the slope of the unwrapped angle of the measured current vector;
* the fundamental phasors U, I of the measured voltage y (behind the 2nd-order filter of the voltage
  channel, thesis A.4) and of the current over the window's last whole electrical periods, by least
  squares beside an offset, the negative sequence and the inverter's 6k ± 1 harmonics (`HARMONICS`;
  a plain Σ y i* / Σ |i|² lets the dead time's 5th and 7th harmonics pull L'_m down by 1 % at low flux);
* Z = U / I / H(jω_s) / c: H = ω0²/(ω0² - ω_s² + 2jζω0ω_s) is the filter (1.9° at 24 Hz), c
  (`sampled_ratio`) what the sampling does: the inverter holds the voltage over a period and the held
  voltage's ripple near the sampling frequency aliases into the sampled current (-0.35 % on L'_m at
  24 Hz and 3 kHz without it); c is the ratio of the exact ZOH relations (as at standstill,
  `bench.workflows.commission.circuit`) to the continuous ones, on the model, at the measured ω_s and ω_r;
* Z_m = Z - R_s - jω_s L'_s, L'_m = -1/(ω_s Im{1/Z_m}) (the magnetising branch, exact at any slip), with the
  level's own L'_s: the T form's leakage l = L_s - L_m of the standstill model is held (the main flux saturates,
  the leakage does not), so L'_s = L_s - L_m²/L_s follows the level's L_m (`main_L`; holding the standstill L'_s
  instead put L_m 0.1-0.4 % high at the rated flux of the fleet's strongly saturating motors). Its 95 % interval
  from the scatter of the per-period values (Student t), a level still settling (the per-period values' slope
  times the rotor's time constant) and the standstill intervals of R_s and l where given (delta method);
* the thesis' form under L_s = L_r (3.6): L_m = (L'_m + sqrt(L'_m² + 4 L'_m l))/2, L_s = L_m + l; the main flux
  ψ_m = ψ_s - l i_s with ψ_s = (u_s - R_s i_s)/(jω_s) (the T circuit (3.34)-(3.35)), |ψ_m| averaged over the
  window, the magnetising current i_μ = |ψ_m| / L_m.

**L_m at the rated flux** ``psi_rated``: a locally weighted quadratic in |ψ_m| over every level, the last (the
mechanics', at 1.0) included (`local_fit`: a Gaussian kernel of 0.35 level spacings times 1/σ²); the plotted curve
is the same local fit along |ψ_m|. No curve shape is assumed. Its interval also holds the interpolation's error,
estimated by the step to a local quadratic and cubic of twice the bandwidth (`rated_L`). Outside the measured flux
range the value is extrapolated and a warning says so.

**Mechanics.** (3.37) with friction: J dω/dt = m_e - B ω - T_c sgn ω (mechanical ω; J, B per mechanical
rad). m_e = 3/2 Z_p L'_m Im{i_s i_m*} (4.6)/(3.41), with i_m from the machine's model run offline on the
logged currents, exact for sampled data (`sampled_current_model`: the ZOH discretisation of (3.41) at the
encoder's speed; the current model (4.15) on the samples, `current_model`, puts |i_m| 0.5 % high at 24 Hz
and 3 kHz, and J 0.2-0.5 % high), on the no-load level's inverse-Γ circuit at the test's flux (L'_m, L'_s and
R'_r = R_r (L_m/L_s)² of that level: the referral ratio changes with saturation, R_r does not). The torque
integrated is each sampling step's mean (`step_torque`: Simpson's rule with the exact state in the step's middle;
the held voltage's ripple makes the samples' torque differ from the mean, B -1.5 to -2.5 % with the samples). The
drive steers the field with the test's model from the end of the no-load test on
(`bench.workflows.commission.rotating.at_flux`), so the flux stays at the level where this linear current model holds.
Integrated over a window [t_a, t_b]:

    J (ω_b - ω_a) + B (θ_b - θ_a) + T_c ∫ sgn ω dt = ∫ m_e dt

with every term through the same smoothing, which keeps the equation exact (`mechanics_fit`): on the ramps a
Savitzky-Golay filter of 20 ms (ω the derivative of the smoothed encoder angle), at the holds a 0.2 s moving mean
that stays inside the hold (ω the angle's difference over it; the encoder's quantisation in a 20 ms speed made
J Δω as large as 5 % of the viscous torque). Friction from the speed holds (per hold,
mean m_e - J mean dω/dt = B ω + T_c sgn ω: a line with a step, both directions), J from the windows
from the middle of each hold to the middle of the next ramp and on to the middle of the next hold
(there m_e is mostly J dω/dt), each by least squares (`fits.linear`: Student-t intervals from the
residuals; J's interval includes the friction's), alternating until they agree. The intervals of J and the
friction also hold the torque model's own uncertainty: L'_m's interval at the level and the standstill R_r's,
through the fit's sensitivity to each, and the linear model's error under load on a saturating machine
(`with_torque_model_error`, `saturation_shift`). A joint fit of all
three on every window lets the ramps' torque errors (1 % of 4 N m) swamp the friction (0.05-0.15 N m).
The friction is held physical, B ≥ 0 and T_c ≥ 0 (`nonnegative`; a value held at 0 gets the interval of
`_bounded` and a warning).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from bench.workflows.commission import fits
from bench.workflows.commission.circuit import InverseGamma, thesis_params, filter_zoh
from bench.workflows.commission.rotating_plan import FLUX_REACH, SCHEMA, Plan, model_of, rated_i_mR
from bench.controllers.schema import defaults_of
from bench.errors import BadInput
from bench.params import MotorParams
from bench.daq import LogReader

BANDWIDTH = 0.7  # kernel width of the local fit along |psi_m|, x the levels' median spacing
SG_WINDOW = 0.02  # [s] Savitzky-Golay window of the mechanics
# [s] moving mean at the holds' ends: there J Δω is a small term, and the encoder's quantisation in the 20 ms
# window's speed (about 0.05 rad/s) made J Δω/Δt as large as 5 % of the viscous torque B ω (B -4 % with the plant's
# own torque)
HOLD_WINDOW = 0.2


def _val(v: float, ci: float) -> dict[str, Any]:
    return {"value": float(v), "ci95": [float(v - ci), float(v + ci)]}


def _t(dof: int) -> float:
    from scipy import stats

    return float(stats.t.ppf(0.975, dof)) if dof > 0 else math.inf


def filter_response(w: float, f_c: float, zeta: float) -> complex:
    """H(jω) of the voltage channel's filter ω0²/(s² + 2ζω0 s + ω0²)."""
    w0 = 2.0 * math.pi * f_c
    return w0 * w0 / (w0 * w0 - w * w + 2j * zeta * w0 * w)


def branch_L(Z: complex, w_s: float, R_s: float, L_sigma: float) -> float:
    """L'_m from the stator impedance at ω_s: -1/(ω_s Im{1/(Z - R_s - jω_s L'_s)})."""
    return -1.0 / (w_s * (1.0 / (Z - R_s - 1j * w_s * L_sigma)).imag)


def _zoh_response(A: np.ndarray, B: np.ndarray, C: np.ndarray, T: float, w: float) -> complex:
    """C (zI - Φ)^-1 Γ at z = e^{jωT} for the ZOH discretisation (Φ, Γ) of a complex (A, B)."""
    from scipy.linalg import expm

    n = A.shape[0]
    M = np.zeros((n + 1, n + 1), dtype=complex)
    M[:n, :n], M[:n, n] = A * T, B * T
    E = expm(M)
    return complex(C @ np.linalg.solve(np.exp(1j * w * T) * np.eye(n) - E[:n, :n], E[:n, n]))


def sampled_ratio(g: InverseGamma, w_s: float, w_r: float, T: float, f_c: float, zeta: float) -> complex:
    """(y/i as sampled) / (H(jω_s) Z(jω_s)): what the sampling does to the measured impedance at ω_s.

    The inverter holds each voltage over a period, the currents and the filtered voltages are sampled:
    y_k / i_k = H_d / Y_d, the ZOH discretisations of the voltage filter and of the machine's admittance
    (states i_s, i_m of (3.41) in the inverse-Γ form, at the speed w_r), as `bench.workflows.commission.circuit`
    does at standstill. The held voltage's ripple around the sampling frequency aliases into the sampled
    current: about -0.35 % on L'_m at 24 Hz, 3 kHz if ignored."""
    Ls, Lm, Rs, Rr = g.L_sigma, g.L_M, g.R_s, g.R_R
    A = np.array([[-(Rs + Rr) / Ls, (Rr - 1j * w_r * Lm) / Ls], [Rr / Lm, -Rr / Lm + 1j * w_r]])
    B, C = np.array([1.0 / Ls, 0.0]), np.array([1.0, 0.0])
    Y_d = _zoh_response(A, B, C, T, w_s)
    Z = 1.0 / complex(C @ np.linalg.solve(1j * w_s * np.eye(2) - A, B))
    H_d = complex(filter_zoh(f_c, zeta, np.array([w_s]), T)[0])
    return (H_d / Y_d) / (filter_response(w_s, f_c, zeta) * Z)


HARMONICS = (1, 0, -1, -5, 7, -11, 13)  # orders k of e^{jkω_s t} fitted beside the fundamental (k = 1)


def fundamental(t: np.ndarray, x: np.ndarray, w: float) -> complex:
    """The positive-sequence fundamental phasor X with x ≈ X e^{jω(t - t_0)} + the other `HARMONICS`
    (offset, unbalance, the inverter's 6k ± 1 voltage-error harmonics), by least squares."""
    E = np.exp(1j * np.outer(t - t[0], w * np.asarray(HARMONICS, dtype=float)))
    return complex(np.linalg.lstsq(E, x, rcond=None)[0][0])


def main_L(Z: complex, w_s: float, R_s: float, leak: float) -> tuple[float, float]:
    """(L_m, L'_m): the T form's L_m under L_s = L_r (3.6) and the branch's L'_m from the stator impedance at ω_s,
    with the T form's leakage l = L_s - L_m held (the main flux saturates, the leakage does not): the level's
    L'_s = L_s - L_m²/L_s follows its own L_m (`InverseGamma.of`), by fixed point (L'_s moves L'_m only slightly)."""
    L_m = 0.0
    for _ in range(50):
        L_M = branch_L(Z, w_s, R_s, InverseGamma.of(L_m + leak, L_m + leak, L_m, R_s, 1.0).L_sigma)
        L_m, old = 0.5 * (L_M + math.sqrt(L_M * L_M + 4.0 * L_M * leak)), L_m  # L'_m = L_m²/(L_m + l)
        if abs(L_m - old) <= 1e-13 * L_m:
            break
    return L_m, L_M


def leakage(g: InverseGamma, model_ci: dict[str, float]) -> tuple[float, float]:
    """The T form's leakage l = L_s - L_m under L_s = L_r (3.6) of the standstill model ``g`` and its 95 % half-width:
    l = L'_s + L'_m - sqrt(L'_m (L'_s + L'_m)), the half-widths of L'_s and L'_m (``model_ci``) through it."""
    th = thesis_params(g)
    dl = (1.0 - g.L_M / (2.0 * th["L_m"]), 1.0 - (2.0 * g.L_M + g.L_sigma) / (2.0 * th["L_m"]))
    return th["L_s"] - th["L_m"], math.hypot(dl[0] * model_ci.get("L_sigma", 0.0), dl[1] * model_ci.get("L_M", 0.0))


def level_fit(t: np.ndarray, i_s: np.ndarray, y: np.ndarray, T: float, filt: tuple[float, float], R_s: float,
              leak: float, R_r: float, w_r: float, ci_R_s: float = 0.0, ci_leak: float = 0.0) -> dict[str, Any]:
    """One flux level: ω_s, Z, L'_m (with interval), the T-form L_m and |ψ_m| (module docstring), the T form's
    leakage ``leak`` = L_s - L_m and R_r of the standstill model held (`main_L`). ``filt``: (f_c, ζ) of the voltage
    channel; R_r and the rotor speed ``w_r`` only enter the small sampling correction (`sampled_ratio`, applied in
    two fixed-point steps)."""
    w_s = float(np.polyfit(t, np.unwrap(np.angle(i_s)), 1)[0])
    periods = int(abs(w_s) * (t[-1] - t[0]) / (2.0 * math.pi))
    if periods < 2:
        raise BadInput("controller.rotating_id.level_average", f"holds {periods} electrical period(s) at "
                       f"{w_s:.0f} rad/s; it must hold at least 2 (raise level_average or omega_test)")  # fmt: skip
    h = filter_response(w_s, *filt)
    # whole periods from the window's end, and each period on its own (the interval)
    n_per = 2.0 * math.pi / abs(w_s) / T
    starts = [t.size - int(round((periods - q) * n_per)) for q in range(periods + 1)]
    U = fundamental(t[starts[0]:], y[starts[0]:], w_s)
    I = fundamental(t[starts[0]:], i_s[starts[0]:], w_s)
    Z_raw = U / I / h

    def model(L_m: float) -> InverseGamma:  # the level's inverse-Γ circuit
        return InverseGamma.of(L_m + leak, L_m + leak, L_m, R_s, R_r)

    c = 1.0 + 0j
    for _ in range(2):
        c = sampled_ratio(model(main_L(Z_raw / c, w_s, R_s, leak)[0]), w_s, w_r, T, *filt)
    Z = Z_raw / c
    L_m, Lm = main_L(Z, w_s, R_s, leak)
    g = model(L_m)
    parts = np.array([branch_L(fundamental(t[a:b], y[a:b], w_s) / fundamental(t[a:b], i_s[a:b], w_s) / (h * c),
                               w_s, R_s, g.L_sigma) for a, b in zip(starts[:-1], starts[1:])])  # fmt: skip
    ci_noise = _t(parts.size - 1) * float(np.std(parts, ddof=1) / math.sqrt(parts.size))
    # a level still settling: the flux follows its current with the rotor's time constant T_r = L'_m/R'_r, so the
    # window's mean is off the settled value by about the per-period values' slope times T_r (a model error)
    mid = np.array([(t[a] + t[b - 1]) / 2.0 for a, b in zip(starts[:-1], starts[1:])])
    drift = abs(float(np.polyfit(mid, parts, 1)[0])) * g.L_M / g.R_R if parts.size > 2 else 0.0
    # the standstill's 95 % half-widths through the same formula, added in quadrature
    dR = (main_L(Z, w_s, R_s + 1e-6, leak)[1] - Lm) / 1e-6
    dl = (main_L(Z, w_s, R_s, leak + 1e-9)[1] - Lm) / 1e-9
    ci = math.sqrt(ci_noise**2 + drift**2 + (dR * ci_R_s) ** 2 + (dl * ci_leak) ** 2)
    # the fundamentals of the continuous voltage and current: the held voltage's u_k = y_k / H_d, its fundamental
    # u_k sinc(wT/2) e^{-jwT/2}, and I_f = U_f / Z (the sampled current also holds the aliased ripple)

    x = w_s * T / 2.0
    U_f = U / complex(filter_zoh(*filt, np.array([w_s]), T)[0]) * (math.sin(x) / x) * complex(math.cos(x), -math.sin(x))
    I_f = U_f / Z
    # T circuit (3.34)-(3.35): psi_s = (u_s - R_s i_s)/(j w_s), psi_m = psi_s - l i_s
    psi_m = abs((U_f - R_s * I_f) / (1j * w_s) - leak * I_f)
    # L_m = (L'_m + sqrt(L'_m² + 4 L'_m l))/2: dL_m/dL'_m = (1 + (L'_m + 2 l)/sqrt(L'_m² + 4 L'_m l))/2
    ci_Lm = ci * 0.5 * (1.0 + (Lm + 2.0 * leak) / math.sqrt(Lm * Lm + 4.0 * Lm * leak))
    return {"omega_s": w_s, "Z_re": Z.real, "Z_im": Z.imag, "L_M": _val(Lm, ci), "L_m": _val(L_m, ci_Lm),
            "L_s": L_m + leak, "L_sigma": g.L_sigma, "R_R": g.R_R, "psi_m": psi_m, "i_mu": psi_m / L_m,
            "i_s": abs(I_f), "u_s": abs(U_f), "periods": periods, "settling_error_L_M": drift,
            "sampling_correction": [c.real, c.imag]}  # fmt: skip


def local_fit(x: np.ndarray, v: np.ndarray, sd: np.ndarray, x0: float, degree: int = 3,
              width: float = 1.0) -> tuple[float, float, float]:
    """(value at x0, 95 % half-width, reduced chi²) of a polynomial of ``degree`` in x - x0 fitted by least squares
    with the weights K((x - x0)/h) / sd², K a Gaussian kernel, h = ``width`` x `BANDWIDTH` x the median spacing of x
    (LOESS): the few nearest levels carry the fit, and the curve it traces along x0 is smooth. The interval: the
    sandwich covariance of the weighted estimate with the points' own variances sd², times the reduced chi² of the
    kernel-weighted residuals where that exceeds 1."""
    x, v, sd = (np.asarray(a, dtype=float) for a in (x, v, sd))
    h = width * BANDWIDTH * float(np.median(np.diff(np.sort(x))))
    K = np.exp(-0.5 * ((x - x0) / h) ** 2)
    sd = np.maximum(sd, 1e-12 * np.abs(v).max())
    X = np.vander(x - x0, degree + 1, increasing=True)
    W = K / sd**2
    G = np.linalg.pinv(X.T @ (W[:, None] * X)) @ (X.T * W)  # coef = G v
    coef = G @ v
    cov = (G * sd**2) @ G.T
    r = (v - X @ coef) / sd
    dof = float(K.sum()) - (degree + 1.0)
    chi2 = float(np.sum(K * r**2) / dof) if dof > 0 else 1.0
    return float(coef[0]), float(1.96 * math.sqrt(cov[0, 0] * max(1.0, chi2))), chi2


def rated_L(x: np.ndarray, v: np.ndarray, sd: np.ndarray, x0: float) -> tuple[float, float, float, float]:
    """(L_m at x0, 95 % half-width, reduced chi², the interpolation's error): a local quadratic at half the bandwidth
    (`local_fit`), its interval holding its error along the curve as well as the levels' own (in quadrature): the
    larger step from it to the local quadratic and cubic at the whole bandwidth. A steep knee bends the curve between
    levels 0.13 x psi_rated apart: there a quadratic at the whole bandwidth was 0.1-0.35 % low, a cubic up to 0.1 %
    low, and the step from the cubic to the narrow quadratic held only 75 % of the cubic's error on the fleet's mildly
    saturating motors (64 % coverage)."""
    value, ci, chi2 = local_fit(x, v, sd, x0, 2, 0.5)
    interp = max(abs(value - local_fit(x, v, sd, x0, q)[0]) for q in (2, 3))
    return value, math.hypot(ci, interp), chi2, interp


# --- mechanics ------------------------------------------------------------------------------------------
def current_model(t_k: float, i_s: np.ndarray, theta_r: np.ndarray, T_r: float) -> np.ndarray:
    """i_m of (4.15) in stator coordinates, integrated in rotor coordinates: T_r di_m^r/dt = i_s^r - i_m^r,
    i_s^r = i_s e^{-jθ_r} linear between samples (exact for that input), from i_m = 0."""
    from scipy.signal import lfilter

    x = i_s * np.exp(-1j * theta_r)
    a = math.exp(-t_k / T_r)
    # exact response to a first-order-hold input: x_{k+1} = a x_k + b0 u_{k+1} + b1 u_k
    b0 = 1.0 - (1.0 - a) * T_r / t_k
    b1 = (1.0 - a) * T_r / t_k - a
    i_mr = lfilter([b0, b1], [1.0, -a], x)
    return i_mr * np.exp(1j * theta_r)


def sampled_current_model(T: float, i_s: np.ndarray, w_r: np.ndarray, g: InverseGamma, grid: int = 65,
                          mid: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray, np.ndarray]:
    """i_m of (3.41) in stator coordinates from the *sampled* currents, exact for a voltage held over each period.

    The current model (4.15) driven by current samples (`current_model`) takes the current as linear between
    them; the held voltage's ripple makes it not, and the samples' fundamental differs from the flux's drive:
    its |i_m| comes out high by about 1.9 (ω_s T)² at zero slip (0.49 % at 24 Hz and 3 kHz on a 3 kW motor,
    exactly the ZOH relation of `sampled_ratio`), which put J 0.2-0.5 % high. Here the machine's ZOH
    discretisation x_{k+1} = A_d x_k + B_d u_k (x = (i_s, i_m), the inverse-Γ model at the speed w_r) gives,
    with u_k eliminated by its first row,

        i_m[k+1] = (A_d10 - ρ A_d00) i_s[k] + (A_d11 - ρ A_d01) i_m[k] + ρ i_s[k+1],   ρ = B_d1 / B_d0,

    from the currents alone. A_d and B_d follow the speed: computed on ``grid`` speeds over w_r's range [rad/s,
    electrical] and interpolated linearly. From i_m = 0, like `current_model`. ``mid``: also (i_s, i_m) in the
    middle of each step, x(T/2) = A_h x_k + B_h u_k with the same u_k (`step_torque`)."""
    Ls, Lm, Rs, Rr = g.L_sigma, g.L_M, g.R_s, g.R_R
    lo, hi = float(np.min(w_r)), float(np.max(w_r))
    ws = np.linspace(lo, hi, grid) if hi > lo else np.array([lo])
    coef = np.empty((ws.size, 9), dtype=complex)
    for j, w in enumerate(ws):
        A = np.array([[-(Rs + Rr) / Ls, (Rr - 1j * w * Lm) / Ls], [Rr / Lm, -Rr / Lm + 1j * w]])
        Ad, Bd, Ah, Bh = (*_zoh(A, 1.0 / Ls, T), *_zoh(A, 1.0 / Ls, T / 2.0))
        rho = Bd[1] / Bd[0]
        # u_k = (i_s[k+1] - A_d00 i_s[k] - A_d01 i_m[k]) / B_d0 into row q of x(T) and x(T/2)
        coef[j] = [Ad[1, 0] - rho * Ad[0, 0], Ad[1, 1] - rho * Ad[0, 1], rho,
                   *(x for q in (0, 1) for x in (Ah[q, 0] - Bh[q] / Bd[0] * Ad[0, 0],
                                                 Ah[q, 1] - Bh[q] / Bd[0] * Ad[0, 1], Bh[q] / Bd[0]))]  # fmt: skip
    w_mid = 0.5 * (w_r[:-1] + w_r[1:])  # the step k -> k+1 at its mean speed: at w_r[k] a ramp's speed lags by half a
    # step's change, a slip error that the rotor's long memory adds up (2 % on the flux over a ramp)
    c = [np.interp(w_mid, ws, coef[:, q].real) + 1j * np.interp(w_mid, ws, coef[:, q].imag) if ws.size > 1
         else np.full(w_mid.size, coef[0, q]) for q in range(9)]  # fmt: skip
    am, bm, rm = (x.tolist() for x in c[:3])
    si = i_s.tolist()
    out, x = [0j] * len(si), 0j
    for k in range(len(si) - 1):  # a first-order recursion with varying coefficients: no vectorised filter
        x = am[k] * si[k] + bm[k] * x + rm[k] * si[k + 1]
        out[k + 1] = x
    i_m = np.array(out, dtype=complex)
    if not mid:
        return i_m
    a, b, n = i_s[:-1], i_m[:-1], i_s[1:]
    return i_m, c[3] * a + c[4] * b + c[5] * n, c[6] * a + c[7] * b + c[8] * n


def _zoh(A: np.ndarray, b: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(A_d, B_d) of x' = A x + (b, 0) u with u held over h (the machine's (3.41), the voltage into the stator row)."""
    from scipy.linalg import expm

    M = expm(np.block([[A * h, np.array([[b * h], [0.0]])], [np.zeros((1, 3))]]))
    return M[:2, :2], M[:2, 2]


def step_torque(m: np.ndarray, m_mid: np.ndarray) -> np.ndarray:
    """The torque averaged over each step k -> k+1, by Simpson's rule from the samples ``m`` and the step's middle
    ``m_mid`` (the mechanics integrate the torque the machine makes between the samples, not at them: with the held
    voltage's ripple the samples' torque differs from its mean)."""
    return (m[:-1] + 4.0 * m_mid + m[1:]) / 6.0


def mechanics_fit(t: np.ndarray, theta: np.ndarray, m_e: np.ndarray, holds: list[tuple[float, float]],
                  edges: list[float], m_step: np.ndarray | None = None) -> dict[str, Any]:  # fmt: skip
    """Friction from the holds, J from the ramps (module docstring); the two alternate until they agree,
    as each takes the other's small term (a hold's speed still drifts a little, a ramp carries friction).

    Every term of J Δω + B Δθ + T_c Δ∫sgn ω = Δ∫m_e goes through the same Savitzky-Golay smoothing
    (ω is the derivative of the smoothed angle; the angle, ∫m_e and ∫sgn ω are smoothed alike), so the
    equation stays exact while the encoder's quantisation and the torque ripple of the inverter's dead
    time (about 1 N m at 6 ω_s on rigs/mock-real.toml) are averaged: a window edge that cuts a ripple
    period cuts it in the speed and in the torque integral the same way."""
    from scipy.signal import savgol_filter

    T = float(np.median(np.diff(t)))
    # ∫m_e from t[0]: the steps' mean torques (``m_step``, `step_torque`) where given, else the trapezoid
    cum_m = np.concatenate([[0.0], np.cumsum(m_step if m_step is not None else (m_e[:-1] + m_e[1:]) / 2) * T])
    sgn = np.sign(savgol_filter(theta, _sg_window(T), 3, deriv=1, delta=T))
    cum_s = np.concatenate([[0.0], np.cumsum(sgn[:-1] + sgn[1:]) * T / 2])

    def smoothed(window: float) -> tuple[np.ndarray, ...]:  # ω, θ, ∫sgn ω, ∫m_e through one smoothing
        sg = {"window_length": _sg_window(T, window), "polyorder": 3}
        return (savgol_filter(theta, deriv=1, delta=T, **sg), *(savgol_filter(x, **sg) for x in (theta, cum_s, cum_m)))

    def boxcar(window: float) -> tuple[np.ndarray, ...]:
        """The same through a moving mean of n samples: the mean of ω is the angle's difference over the window, the
        derivative of the mean angle, exactly (a long Savitzky-Golay derivative is not the smoothed speed where the
        speed bends, at a hold's end)."""
        from scipy.ndimage import uniform_filter1d

        n = _sg_window(T, window)
        h = n // 2
        w_mean = np.empty_like(theta)
        w_mean[h:-h - 1] = (theta[n:] - theta[:-n]) / (n * T)  # the mean of the n sample-to-sample speeds
        w_mean[:h], w_mean[-h - 1:] = w_mean[h], w_mean[-h - 2]
        return (w_mean, *(uniform_filter1d(x, n, mode="nearest") for x in (theta, cum_s, cum_m)))

    def rows(a: np.ndarray, b: np.ndarray, sm: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        return (*(x[b] - x[a] for x in sm), t[b] - t[a])

    def index(x: Any) -> np.ndarray:
        return np.clip(np.searchsorted(t, np.asarray(x, dtype=float)), 0, t.size - 1)

    # holds: mean torque, mean speed, mean acceleration over each window, through a longer moving mean that stays
    # inside it (its ends W/2 in from the hold's: the ramps' inertial torque stays out)
    W = min(HOLD_WINDOW, 0.5 * min(b - a for a, b in holds))
    h_dw, h_dth, h_ds, h_dm, h_T = rows(index([a + W / 2 for a, _ in holds]), index([b - W / 2 for _, b in holds]) - 1,
                                        boxcar(W))  # fmt: skip
    h_w, h_m, h_acc = h_dth / h_T, h_dm / h_T, h_dw / h_T
    dw, dth, ds, dm, _ = rows(index(edges[:-1]), index(edges[1:]), smoothed(SG_WINDOW))
    J = B = Tc = 0.0
    for _ in range(20):
        # hold: mean m_e - J dw/dt = B w + T_c mean sgn w;  ramp: J dw = int m_e - B dtheta - T_c int sgn w
        X_h, y_h = np.column_stack([h_w, h_ds / h_T]), h_m - J * h_acc
        fr = fits.linear(X_h, y_h)
        B, Tc = nonnegative(X_h, y_h, fr.coef)
        fj = fits.linear(dw[:, None], dm - B * dth - Tc * ds)
        J, J_old = float(fj.coef[0]), J
        if abs(J - J_old) <= 1e-9 * abs(J):
            break
    # the friction's uncertainty through J = sum dw (dm - B dth - T_c ds) / sum dw^2, added in quadrature
    # (the unconstrained fit's covariance: the friction's uncertainty is that, whether or not a value is held at 0)
    g = -np.array([dw @ dth, dw @ ds]) / (dw @ dw)
    ci_J = math.sqrt(fj.ci95[0] ** 2 + (_t(fr.dof) ** 2) * float(g @ fr.cov @ g))
    names = ("B_visc", "m_coulomb")
    if np.all(fr.coef >= 0.0):
        friction = {n: _val(v, ci) for n, v, ci in zip(names, (B, Tc), fr.ci95)}
    else:  # held physical (`nonnegative`); what the unconstrained fit said is kept beside
        friction = {n: _bounded(v, ci) for n, v, ci in zip(names, (B, Tc), fr.ci95)}
        friction["friction_unconstrained"] = {n: _val(v, ci) for n, v, ci in zip(names, fr.coef, fr.ci95)}
    return {"J": _val(J, ci_J), **friction,
            "friction_residual_rms_N_m": fr.residual_rms, "friction_dof": fr.dof,
            "J_residual_rel": float(fj.residual_rms / np.sqrt(np.mean(dm**2))), "J_windows": int(dw.size),
            "J_dof": fj.dof, "holds": [{"omega_mech": float(x), "m_e": float(y), "J_dw_dt": float(J * d)}
                                       for x, y, d in zip(h_w, h_m, h_acc)]}  # fmt: skip


H_REL = 1e-3  # relative step of the torque model's parameters for the sensitivities of the mechanics


def with_torque_model_error(mech: dict[str, Any], moved: dict[str, tuple[dict[str, Any], float]],
                            rel: dict[str, float]) -> dict[str, Any]:  # fmt: skip
    """``mech`` (`mechanics_fit`) with the torque model's uncertainty in the intervals of J and the friction. The
    fit's intervals hold for the model (4.6)/(4.15) as given; ``moved[n]`` = (the same fit with the model moved,
    the factor that turns its shift into a 95 % half-width). For L'_m and R'_r (m_e scales with L'_m, the current
    model's T_r = L'_m/R'_r shapes its transients) the move is a relative step `H_REL` and the factor rel_n / H_REL
    (``rel``: their relative 95 % half-widths; the delta method); for the saturation under load (`saturation_shift`)
    the move is the estimated error itself and the factor 1. Each value's half-width becomes
    sqrt(fit² + Σ_n (shift_n · factor_n)²) (independent errors). A friction value held at 0 keeps its lower end
    there (`_bounded`)."""
    out = dict(mech)
    added: dict[str, float] = {}
    for q in ("J", "B_visc", "m_coulomb"):
        v = mech[q]["value"]
        model = math.sqrt(sum(((m[q]["value"] - v) * k) ** 2 for m, k in moved.values()))
        half = math.hypot(mech[q]["ci95"][1] - v, model)  # (the upper end: a value held at 0 has a cut lower one)
        out[q] = _bounded(v, half) if q != "J" and "friction_unconstrained" in mech else _val(v, half)
        added[q] = model
    out["torque_model"] = {"rel_half_width": dict(rel), "half_width_added": added,
                           "shift": {n: {q: m[q]["value"] - mech[q]["value"] for q in ("J", "B_visc", "m_coulomb")}
                                     for n, (m, _) in moved.items()},
                           "note": "95 % half-widths from the torque model (L'_m, R'_r and the saturation under "
                                   "load), in quadrature with the fit's"}  # fmt: skip
    return out


def saturation_shift(levels: list[dict[str, Any]], i_s: np.ndarray, i_m: np.ndarray, L_sigma: float) -> np.ndarray:
    """The factor by which the torque (4.6) of the linear current model is off, per sample, to first order: the
    model holds L'_m at the level's value, but under load the main flux |ψ_m| = |L'_m i_m + (L'_s - l) i_s| (the
    T form's, l = L_s - L_m under L_s = L_r) rises with the torque current, through the rotor leakage, and on a
    saturating machine L'_m falls with it. The slope dL'_m/d|ψ_m| is the no-load levels' (`local_fit` at the
    mechanics' level, the last). 1 on a linear machine. On four of the fleet's saturating motors it moved J
    towards the truth by 0.85-2 times J's error (with `current_model`'s torque, before `sampled_current_model`;
    docs/results/fleet-commission.md), too coarse for a correction: it enters J's interval as a model error."""
    psi = np.array([lv["psi_m"] for lv in levels])
    L = np.array([lv["L_M"]["value"] for lv in levels])
    sd = np.array([(lv["L_M"]["ci95"][1] - lv["L_M"]["ci95"][0]) / 3.92 for lv in levels])
    jl = levels[-1]
    psi0, L0 = jl["psi_m"], jl["L_M"]["value"]
    h = 0.01 * psi0
    slope = (local_fit(psi, L, sd, psi0 + h)[0] - local_fit(psi, L, sd, psi0 - h)[0]) / (2 * h)
    th = thesis_params(InverseGamma(1.0, L_sigma, 1.0, L0))
    leak = L_sigma - (th["L_s"] - th["L_m"])  # psi_m = psi_R + (L'_s - l) i_s, psi_R = L'_m i_m (inverse Γ)
    return 1.0 + slope * (np.abs(L0 * i_m + leak * i_s) - psi0) / L0


def nonnegative(X: np.ndarray, y: np.ndarray, coef: np.ndarray) -> tuple[float, ...]:
    """The friction (B, T_c) held physical, B ≥ 0 and T_c ≥ 0: ``coef`` (the unconstrained least squares of
    y ≈ X coef) where both are ≥ 0, else the least squares under the bounds (NNLS; for two unknowns its active
    set holds the negative one at 0 and fits the other alone, or both at 0)."""
    if np.all(coef >= 0.0):
        return tuple(float(c) for c in coef)
    from scipy.optimize import nnls

    return tuple(float(c) for c in nnls(np.asarray(X, dtype=float), np.asarray(y, dtype=float))[0])


def _bounded(v: float, ci: float) -> dict[str, Any]:
    """The interval of a friction coefficient of a fit held at the bound 0 (`nonnegative`): the value (the
    constrained one, 0 for the one held there) ± the unconstrained fit's half-width, cut at 0. The
    unconstrained marginal interval is the 95 % one (it includes the other coefficient's uncertainty); for the
    value held at 0 this gives [0, half-width], which contains the unconstrained interval's part above 0 (so it
    holds any true value ≥ 0 that interval held) and keeps a width where the unconstrained fit lies far below 0."""
    return {"value": float(v), "ci95": [max(0.0, float(v - ci)), float(v + ci)]}


def _sg_window(T: float, window: float = SG_WINDOW) -> int:
    return 2 * int(window / (2 * T)) + 1  # odd: 61 samples at 3 kHz


def speed(t: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """dθ/dt [rad/s] of an encoder angle: a cubic Savitzky-Golay derivative over `SG_WINDOW`."""
    from scipy.signal import savgol_filter

    T = float(np.median(np.diff(t)))
    return savgol_filter(theta, _sg_window(T), 3, deriv=1, delta=T)


# --- the whole analysis -----------------------------------------------------------------------------------
def analyse_log(log: Path, model_ci: dict[str, float] | None = None, keep_series: bool = False) -> dict[str, Any]:
    """The rotating identification from a recorded run (its MCAP log). ``model_ci``: 95 % half-widths of the
    standstill R_s and L_sigma, and ``R_r_rel`` the relative one of its R_r (T form) (the intervals are
    conditional on them otherwise)."""

    r = LogReader(log)
    meta = r.metadata()
    run_meta, rig_meta = meta["run"], meta["rig"]
    if run_meta.get("controller") != "rotating_id":
        raise BadInput("log", f"{log} is a run of {run_meta.get('controller')!r}, not of rotating_id")
    p = {**defaults_of(SCHEMA), "levels_from": "current", **run_meta["controller_params"]}  # (older logs:
    # before the flux scan)
    nominal = MotorParams(**rig_meta["motor"])
    meas, ctrl = r.read_ticks("/rig", "/ctrl")
    return analyse(meas, ctrl, p, 1.0 / float(run_meta["rate_hz"]), nominal, model_ci or {}, keep_series) | {
        "rig": rig_meta["rig"]["name"], "log": str(log)}


def analyse(meas: dict[str, np.ndarray], ctrl: dict[str, np.ndarray], p: dict[str, Any], T_s: float,
            nominal: Any, model_ci: dict[str, float], keep_series: bool = False) -> dict[str, Any]:  # fmt: skip
    """The identification from a rotating run's /rig and /ctrl columns (module docstring); ``keep_series``
    adds the time series the mechanics plot needs (``_series``, not JSON)."""

    g = model_of(p, nominal)
    plan = Plan.from_params(p, rated_i_mR(p, g))
    t = meas["t"]
    i_s = (2.0 * meas["i_a"] - meas["i_b"] - meas["i_c"]) / 3.0 + 1j * (meas["i_b"] - meas["i_c"]) / math.sqrt(3.0)
    y = (2.0 * meas["u_a"] - meas["u_b"] - meas["u_c"]) / 3.0 + 1j * (meas["u_b"] - meas["u_c"]) / math.sqrt(3.0)
    theta = ctrl["theta_mech"]
    w_mech = speed(t, theta)
    warnings: list[str] = []
    # 1. no-load test, the T form's leakage l = L_s - L_m and R_r of the standstill model held (`main_L`)
    leak, ci_leak = leakage(g, model_ci)
    levels = _levels(t, i_s, y, theta, ctrl, p, plan, g, nominal, model_ci, leak, ci_leak, T_s)
    rated, curve = _rated_flux(levels, p, warnings)
    jl = levels[-1]  # the flux level of the mechanics
    # 2. mechanics at the last level's flux
    mech, m_e, first = _mechanics(t, i_s, theta, w_mech, plan, g, jl, levels, nominal.Z_p, model_ci, T_s, warnings)
    out: dict[str, Any] = {
        "warnings": warnings,
        "L_m_rated": rated,
        "magnetising_curve": {"levels": levels, "curve": curve},
        "L_M_at_test_flux": jl["L_M"] | {"psi_m": jl["psi_m"]},
        "mechanics": mech,
        "conditions": {
            "T_s": T_s, "duration_s": plan.duration, "omega_test": p["omega_test"], "i_mR_rated_model": plan.i_mR_n,
            "flux_levels": [s.flux for _, s in plan.windows("level")], "levels_from": p["levels_from"],
            "level_settle_s": p["level_settle"],
            "level_average_s": p["level_average"], "holds_omega": [s.w0 for _, s in plan.windows("hold")],
            "hold_average_s": p["hold_average"], "accel": p["accel"], "load_torque": 0.0,
            "model_inverse_gamma": g.as_dict(), "leakage_T": _val(leak, ci_leak),
            "omega_max_seen": float(np.max(np.abs(w_mech))) * nominal.Z_p,
            "i_s_max": float(np.max(np.abs(i_s))), "u_s_max": float(np.max(np.abs(y))),
            "voltage_filter": {"f_c": p["u_filter_fc"], "zeta": p["u_filter_zeta"]},
            "J_note": "J is all that turns with the shaft: motor rotor, coupling and the DC load machine's rotor",
        },
    }  # fmt: skip
    if keep_series:
        out["_series"] = _series(t, theta, w_mech, m_e, ctrl, mech, plan.segments[first].t0 - 0.1, nominal.Z_p, T_s)
    return out


def _levels(t: np.ndarray, i_s: np.ndarray, y: np.ndarray, theta: np.ndarray, ctrl: dict[str, np.ndarray],
            p: dict[str, Any], plan: Any, g: InverseGamma, nominal: Any, model_ci: dict[str, float], leak: float,
            ci_leak: float, T_s: float) -> list[dict[str, Any]]:  # fmt: skip
    """The no-load test: each flux level's fit (`level_fit`) over its window, with its reference and slip."""
    k = np.rint(t / T_s).astype(np.int64)
    R_r = thesis_params(g)["R_r"]
    flux_mode = p["levels_from"] == "flux"
    levels = []
    for j, s in plan.windows("level"):
        sel = (k >= int(round(s.a0 / T_s))) & (k < int(round(s.t1 / T_s)))
        wm = float((theta[sel][-1] - theta[sel][0]) / (t[sel][-1] - t[sel][0]))
        w_r = wm * nominal.Z_p
        lv = level_fit(t[sel], i_s[sel], y[sel], T_s, (p["u_filter_fc"], p["u_filter_zeta"]), g.R_s, leak, R_r, w_r,
                       model_ci.get("R_s", 0.0), ci_leak)  # fmt: skip
        i_ref = float(np.mean(ctrl["i_mr_ref_plan"][sel])) if flux_mode else s.flux * plan.i_mR_n
        lv.update({"segment": j, "flux_ref": s.flux, "i_mR_ref": i_ref, "omega_r": w_r,
                   "omega_slip": lv["omega_s"] - w_r})  # fmt: skip
        levels.append(lv)
    return levels


def _rated_flux(levels: list[dict[str, Any]], p: dict[str, Any], warnings: list[str]
                ) -> tuple[dict[str, Any], dict[str, list[float]]]:  # fmt: skip
    """L_m at the rated flux from every level (the last, 1.0 again, is a point of the curve as well; `rated_L`)
    and the curve along the flux; a rated flux outside the levels, or levels short of `FLUX_REACH`, warn."""

    psi = np.array([lv["psi_m"] for lv in levels])
    Lm = np.array([lv["L_m"]["value"] for lv in levels])
    sd = np.array([(lv["L_m"]["ci95"][1] - lv["L_m"]["ci95"][0]) / 3.92 for lv in levels])
    psi_r = p["psi_rated"]
    L_rated, ci_rated, chi2, interp = rated_L(psi, Lm, sd, psi_r)
    if not psi.min() <= psi_r <= psi.max():
        warnings.append(f"the rated flux {psi_r:g} Wb is outside the measured {psi.min():.3f}-{psi.max():.3f} Wb: "
                        "L_m there is extrapolated (widen flux_lo / flux_hi)")  # fmt: skip
    if p["levels_from"] == "flux" and psi.max() < FLUX_REACH * psi_r:
        warnings.append(f"the flux levels reach {psi.max():.3f} Wb, {psi.max() / psi_r:.2f} x the rated {psi_r:g} Wb, "
                        f"not {FLUX_REACH:g} x: the scan met the test's current limit (raise i_max, the rig's "
                        "I_max)")  # fmt: skip
    grid = np.linspace(psi.min(), psi.max(), 60)
    curve = [local_fit(psi, Lm, sd, x, 2, 0.5)[0] for x in grid]  # (the estimate of `rated_L` along the flux)
    rated = _val(L_rated, ci_rated) | {
        "psi_rated_Wb": psi_r, "fit_chi2_reduced": chi2, "interpolation_error": interp,
        "form": "T circuit under L_s = L_r (as (3.57)), secant at |psi_m| = psi_rated"}  # fmt: skip
    return rated, {"psi_m": grid.tolist(), "L_m": curve}


def _mechanics(t: np.ndarray, i_s: np.ndarray, theta: np.ndarray, w_mech: np.ndarray, plan: Any, g: InverseGamma,
               jl: dict[str, Any], levels: list[dict[str, Any]], Z_p: int, model_ci: dict[str, float], T_s: float,
               warnings: list[str]) -> tuple[dict[str, Any], np.ndarray, int]:  # fmt: skip
    """J and the friction at the flux level ``jl`` (`mechanics_fit` on the torque (4.6) of the level's circuit),
    their intervals with the torque model's error; returns them, the torque samples and the first hold's
    segment."""
    L_M, R_R, L_sig = jl["L_M"]["value"], jl["R_R"], jl["L_sigma"]  # the level's inverse-Γ circuit
    w_r = Z_p * w_mech

    def torque(L: float, R: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # (4.6): samples, i_m, steps
        i_m, s_mid, m_mid = sampled_current_model(T_s, i_s, w_r, InverseGamma(g.R_s, L_sig, R, L), mid=True)
        k_t = 1.5 * Z_p * L
        m = k_t * (i_s * i_m.conj()).imag
        return m, i_m, step_torque(m, k_t * (s_mid * m_mid.conj()).imag)

    m_e, i_m, m_step = torque(L_M, R_R)
    holds, edges = [], []
    segs = plan.segments
    first = next(j for j, s in enumerate(segs) if s.kind == "hold")
    for j, s in enumerate(segs):
        if s.kind == "hold":
            holds.append((s.a0, s.t1))
        elif s.kind == "ramp" and j > first:  # from the middle of the hold before to the one after
            before, after = segs[j - 1], segs[j + 1]
            edges.append(((before.a0 + before.t1) / 2, (s.t0 + s.t1) / 2, (after.a0 + after.t1) / 2))
    edges = sorted({e for tri in edges for e in tri})
    mech = mechanics_fit(t, theta, m_e, holds, edges, m_step)
    rel = {"L_M": (jl["L_M"]["ci95"][1] - jl["L_M"]["ci95"][0]) / 2.0 / L_M, "R_R": model_ci.get("R_r_rel", 0.0)}
    moved = {}
    for n, r in rel.items():
        m, _, ms = torque(L_M * (1 + H_REL * (n == "L_M")), R_R * (1 + H_REL * (n == "R_R")))
        moved[n] = (mechanics_fit(t, theta, m, holds, edges, ms), r / H_REL)
    sat = saturation_shift(levels, i_s, i_m, L_sig)
    moved["saturation"] = (mechanics_fit(t, theta, m_e * sat, holds, edges, m_step * 0.5 * (sat[:-1] + sat[1:])), 1.0)
    mech = with_torque_model_error(mech, moved, rel)
    for n, u in mech.get("friction_unconstrained", {}).items():
        if u["value"] < 0.0:
            warnings.append(f"the friction fit gave {n} = {u['value']:.3g} (95 % {u['ci95'][0]:.3g} to "
                            f"{u['ci95'][1]:.3g}), below 0: held at 0, interval {mech[n]['ci95'][0]:.3g} to "
                            f"{mech[n]['ci95'][1]:.3g}")  # fmt: skip
    mech["flux_level"] = {"i_mR_ref": jl["i_mR_ref"], "psi_m": jl["psi_m"], "L_M": L_M, "R_R": R_R,
                          "k_t_N_m_per_A": 1.5 * Z_p * L_M}  # fmt: skip
    return mech, m_e, first


def _series(t: np.ndarray, theta: np.ndarray, w_mech: np.ndarray, m_e: np.ndarray, ctrl: dict[str, np.ndarray],
            mech: dict[str, Any], t_from: float, Z_p: int, T_s: float) -> dict[str, np.ndarray]:  # fmt: skip
    """The mechanics plot's series from ``t_from``: the speed and its reference, the torque (4.6) and the fitted
    J dω/dt + B ω + T_c sgn ω through the same 30 ms smoothing."""
    from scipy.ndimage import uniform_filter1d
    from scipy.signal import savgol_filter

    sel = t >= t_from
    J, B, Tc = (mech[n]["value"] for n in ("J", "B_visc", "m_coulomb"))
    n_s = 2 * int(0.015 / T_s) + 1
    dw = savgol_filter(theta, n_s, 3, deriv=2, delta=T_s)
    m_fit = J * dw + B * w_mech + Tc * np.sign(w_mech)
    return {"t": t[sel], "w_mech": w_mech[sel], "w_ref": ctrl["omega_ref"][sel] / Z_p,
            "m_e": uniform_filter1d(m_e, n_s)[sel], "m_fit": m_fit[sel]}  # fmt: skip
