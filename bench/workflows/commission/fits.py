"""Least-squares fits of the standstill identification, each with 95 % confidence intervals.

* `linear` - ordinary least squares, Student-t intervals from the residual variance.
* `dc_line` - R_s as the slope of the per-level mean voltage over the mean current, with one
  intercept per polarity: u = R_s i + c_+ [i > 0] + c_- [i < 0]. A constant inverter voltage error
  (dead time, on-state drop: ±4/3 (t_d f_pwm u_dc + v_on) for a current along a phase axis,
  `mock_hw.inverter`) sits in the intercepts and leaves the slope alone (moteus' method, with both
  polarities here). Without a voltage measurement a soft knee bends the error curve on toward its
  plateau over the low levels; ``tail`` fits that bend's leading terms as well.
* `lockin` - phasors of several sinusoids at once by least squares on a constant and a cos/sin pair
  per line (a lock-in amplifier in batch form); over whole common periods the regressors are
  orthogonal and this is the DFT at those lines.
* `impedance` - the inverse-Γ parameters from lock-in impedances: nonlinear least squares
  (scipy's trust-region reflective) on the relative complex error, parameters in logarithms so they
  stay positive; intervals from the Jacobian at the optimum (`ImpedanceFit.half_width`).
* `periods`, `line_errors` - what is wrong with each line's impedance besides the circuit, from the
  data: the equation error E = U - Z I of each period at every harmonic of the multisine's f0 (Z the
  fitted circuit), its noise (the scatter from one period to the next), the periodic distortion at the
  non-excited harmonics between the lines (of an odd multisine: the odd ones), and the lack of fit at the
  lines beyond their noise.
* `swing_bias` - the bias the multisine's own swing causes where the incremental L'_m depends on the
  current (the saturation check's two biases measure how much): the quadratic part of the main flux
  makes sums and differences of the lines, which on a grid of every harmonic fall on the lines too (on
  an odd multisine's they fall between them, and that bias comes out 0); the cubic part falls on the lines
  of either grid.

**The intervals** (`ImpedanceFit.half_width`, for any parameter or function of them) are the larger of
two error models: (a) every error random, of the size of the fit's residual (Gauss-Newton covariance
s²(JᵀJ)⁻¹, Student-t with the fit's degrees of freedom, every line weighted alike); and (b) the noise
as measured per line, random (the sandwich A Σ Aᵀ, A = (JᵀJ)⁻¹Jᵀ, Σ the lines' noise variances,
Student-t with Satterthwaite's degrees of freedom) plus the model error, which does not average out:
the larger of the swing's bias and the bias the lines' model errors d_k (distortion, lack of fit) can
cause when they add up coherently, Σ_k d_k |a_k| (their phases unknown; a_k line k's row of A for the
quantity). (a) alone weights the lines as if their relative noise were equal; the low lines, which
carry L'_m, are noisier, and periodic errors are bias, not noise. What a fit holds at values measured
elsewhere passes its error on in both, D C Dᵀ with D the fit's derivatives by those values and C their
covariance: R_s from the DC test (dθ/dR_s = −A ∂r/∂R_s), and without a voltage measurement the inverter's
error curve that the DC test fitted, which the voltages are corrected by (`Curve`; its tail's terms are
correlated with the DC R_s, so the two come with one covariance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from bench.workflows.commission.circuit import InverseGamma, observed_impedance, filter_zoh


@dataclass(frozen=True)
class LinearFit:
    coef: np.ndarray
    cov: np.ndarray
    ci95: np.ndarray  # half-widths
    residual_rms: float
    dof: int


def _t95(dof: int) -> float:
    from scipy import stats  # here, not at the top: every `bench` process loads the plugins (this module), few fit

    return float(stats.t.ppf(0.975, dof)) if dof > 0 else math.inf


def linear(X: np.ndarray, y: np.ndarray) -> LinearFit:
    """OLS y ≈ X coef; covariance s² (XᵀX)^-1 with s² = SSR / (n - p)."""
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    dof = X.shape[0] - X.shape[1]
    s2 = float(r @ r) / dof if dof > 0 else math.nan
    cov = s2 * np.linalg.pinv(X.T @ X)
    return LinearFit(coef, cov, _t95(dof) * np.sqrt(np.diag(cov)), float(np.sqrt(np.mean(r**2))), dof)


@dataclass(frozen=True)
class DcLine:
    R_s: float  # [Ω]
    R_s_ci: float  # 95 % half-width [Ω]
    c_pos: float  # intercept of the positive levels [V] (nan if none)
    c_neg: float  # intercept of the negative levels [V]
    residual_rms: float  # [V]
    dof: int
    tail: float = 0.0  # the knee's tail d [V A²]: + d sgn(i)/i² (0 unless fitted)
    tail_sd: float = 0.0  # its standard deviation
    tail4: float = 0.0  # the tail's second term e [V A⁴]: + e sgn(i)/i⁴ (0 unless fitted)
    cov: np.ndarray | None = field(default=None, compare=False)  # covariance of (R_s, the tail's terms fitted)

    def error(self, i: np.ndarray) -> np.ndarray:
        """The fitted inverter error curve [V] at the currents ``i`` [A]: the intercept of i's polarity and the tail."""
        i = np.asarray(i, dtype=float)
        a = np.maximum(np.abs(i), 1e-9)
        return np.where(i > 0, self.c_pos, self.c_neg) + np.sign(i) * (self.tail / a**2 + self.tail4 / a**4)

    def tail_regressors(self, i: np.ndarray) -> np.ndarray:
        """The error curve's derivatives by its tail's terms at the currents ``i`` (samples x terms): sgn(i)/i^2k."""
        a = np.maximum(np.abs(np.asarray(i, dtype=float)), 1e-9)
        n = 0 if self.cov is None else self.cov.shape[0] - 1
        return np.column_stack([np.sign(i) / a ** (2 * k) for k in range(1, n + 1)]).reshape(a.size, n)


def dc_line(i: np.ndarray, u: np.ndarray, tail: int = 0) -> DcLine:
    """R_s and the intercepts per polarity from per-level means (module docstring); ``tail``: the number of
    terms of the knee's tail, d sgn(i)/i² and e sgn(i)/i⁴, the series of any error curve that reaches its
    plateau like a soft knee (i/sqrt(i² + i_k²) = 1 - i_k²/(2 i²) + 3 i_k⁴/(8 i⁴) - ...). A current along phase
    a's axis puts -i/2 through phases b and c, whose knees reach further: their i⁻⁴ term is 16 times phase a's,
    and at the lowest levels above the knee it moves R_s by about 0.1-0.4 % where only d is fitted."""
    i, u = np.asarray(i, dtype=float), np.asarray(u, dtype=float)
    pos, neg = i > 0, i < 0
    cols = [i] + [m.astype(float) for m in (pos, neg) if m.any()]
    cols += [np.sign(i) / i ** (2 * k) for k in range(1, tail + 1)]
    f = linear(np.column_stack(cols), u)
    c = list(f.coef[1 : 1 + int(pos.any()) + int(neg.any())])
    c_pos = c.pop(0) if pos.any() else math.nan
    c_neg = c.pop(0) if neg.any() else math.nan
    k = len(f.coef) - tail  # the tail's terms come last
    d, d_sd = (float(f.coef[k]), float(math.sqrt(max(f.cov[k, k], 0.0)))) if tail else (0.0, 0.0)
    e = float(f.coef[k + 1]) if tail >= 2 else 0.0
    held = [0, *range(k, len(f.coef))]
    return DcLine(float(f.coef[0]), float(f.ci95[0]), float(c_pos), float(c_neg), f.residual_rms, f.dof, d, d_sd, e,
                  f.cov[np.ix_(held, held)])  # fmt: skip


def lockin(t: np.ndarray, x: np.ndarray, freqs: np.ndarray) -> tuple[np.ndarray, float]:
    """Phasors X_k with x ≈ c + Σ Re{X_k e^{j 2π f_k t}}, and the residual rms."""
    w = 2.0 * math.pi * np.asarray(freqs, dtype=float)
    ph = np.outer(t, w)
    X = np.column_stack([np.ones_like(t), np.cos(ph), np.sin(ph)])
    coef, *_ = np.linalg.lstsq(X, x, rcond=None)
    K = w.size
    a, b = coef[1 : 1 + K], coef[1 + K :]
    r = x - X @ coef
    return a - 1j * b, float(np.sqrt(np.mean(r**2)))


NEIGHBOURS = 4  # harmonics of f0 next to each line (log distance) that estimate its noise and distortion
DETECT = 0.95  # distortion and lack of fit count where an F-test at this level finds them above the noise


@dataclass(frozen=True)
class Periods:
    """A multisine's record split into its periods: the phasors (`lockin` convention) of the current ``I`` and
    the voltage ``U`` at every harmonic h f0, h = 1..H (column h - 1), one row per period; ``lines`` are the
    excited harmonics."""

    f0: float
    lines: tuple[int, ...]
    I: np.ndarray
    U: np.ndarray

    @property
    def harmonics(self) -> np.ndarray:
        return np.arange(1, self.I.shape[1] + 1)


def periods(t: np.ndarray, i: np.ndarray, u: np.ndarray, f0: float, lines: tuple[int, ...], t0: float, n: int,
            T: float) -> Periods:  # fmt: skip
    """`Periods` of ``n`` whole periods 1/f0 from ``t0``, harmonics up to 1.2 x the highest line plus
    2 `NEIGHBOURS`: per period an FFT where the period is sampled at every tick (T), else `lockin`."""
    H = int(math.ceil(1.2 * max(lines))) + 2 * NEIGHBOURS
    m = int(round(1.0 / (f0 * T)))
    Ip, Up = [], []
    for q in range(n):
        a = t0 + q / f0  # phasors relative to the period's start: the same phase reference in every period
        sel = (t >= a - 0.5 * T) & (t < a + 1.0 / f0 - 0.5 * T)
        if int(sel.sum()) == m and H < m // 2:  # whole period, no tick missing: the DFT at its bins h f0
            Ip.append(np.fft.rfft(i[sel])[1 : H + 1] * 2.0 / m)
            Up.append(np.fft.rfft(u[sel])[1 : H + 1] * 2.0 / m)
        else:
            w = f0 * np.arange(1, H + 1)
            Ip.append(lockin(t[sel] - a, i[sel], w)[0])
            Up.append(lockin(t[sel] - a, u[sel], w)[0])
    return Periods(f0, tuple(lines), np.array(Ip), np.array(Up))


@dataclass(frozen=True)
class LineErrors:
    """Per line of a multisine, relative to the line's impedance (|δZ/Z|): ``noise_var`` the variance of its
    noise (None with one period) with ``noise_dof`` degrees of freedom per line, and ``model`` the rms of what
    the circuit misses there (`line_errors`), with the two estimates it is the larger of (``distortion``,
    ``lack_of_fit``) and the lack-of-fit test's statistic and limit."""

    noise_var: np.ndarray | None
    noise_dof: int
    model: np.ndarray
    distortion: np.ndarray
    lack_of_fit: np.ndarray
    lof_statistic: float = math.nan
    lof_limit: float = math.nan


def line_errors(per: Periods, Z_model: np.ndarray, residual: np.ndarray, n_params: int,
                neighbours: int = NEIGHBOURS) -> LineErrors:  # fmt: skip
    """What is wrong with each line's impedance besides the circuit, from the equation error E = U - Z I of
    every period at every harmonic (``Z_model``: the fitted circuit there, as observed): a part of the voltage
    the circuit does not explain by the current; at a line, E/U is the relative error of its Z = U/I.

    * noise: the variance of the periods' mean from their scatter, over the line and its ``neighbours``
      nearest harmonics (log distance): 2 (P - 1)(n + 1) degrees of freedom per line;
    * distortion: the mean power of the periods' mean at the ``neighbours`` nearest non-excited harmonics, less
      the noise there, where an F-test at `DETECT` finds it above the noise: what the non-excited harmonics
      carry of a periodic distortion (on the lines' harmonic grid it falls on the lines too);
    * lack of fit: where the fit's relative residual at the lines (``residual``, complex, ``n_params`` fitted)
      is larger than their noise by an F-test at `DETECT` over all lines, each line's excess
      sqrt(|r|² - noise): a model error the residual shows (the part the parameters absorb it cannot show).

    ``model`` is the larger of the two per line. One period: no noise estimate; everything at the non-excited
    harmonics counts as distortion, and there is no lack-of-fit test."""
    from scipy import stats

    lines = list(per.lines)
    hs = per.harmonics
    P = per.I.shape[0]
    E = per.U - Z_model[None, :] * per.I
    Em, Um = E.mean(axis=0), per.U.mean(axis=0)
    s2 = (np.abs(E - Em) ** 2).sum(axis=0) / (P - 1) / P if P > 1 else None
    # an odd multisine (every line odd): its even-order distortion lies on the even harmonics and cannot reach a
    # line (a sum of an even number of odd harmonics is even); its odd-order part, which can, shows on the
    # non-excited odd ones: only those estimate the distortion at the lines
    odd = all(h % 2 for h in lines)
    non = [h for h in hs if h not in lines and (h % 2 or not odd)]

    def near(h: int, pool: list[int], n: int) -> np.ndarray:
        return np.array(sorted(pool, key=lambda q: (abs(math.log(q / h)), q))[:n]) - 1

    dof = 2 * (P - 1) * (neighbours + 1)
    f_dist = float(stats.f.ppf(DETECT, 2 * neighbours, dof)) if P > 1 else 0.0
    nv, dist = [], []
    for h in lines:
        U2 = abs(Um[h - 1]) ** 2
        nb = near(h, non, neighbours)
        tot = float(np.mean(np.abs(Em[nb]) ** 2))
        if s2 is None:
            dist.append(math.sqrt(tot / U2))
            continue
        nv.append(float(np.mean(s2[near(h, list(hs), neighbours + 1)])) / U2)
        nz = float(np.mean(s2[nb]))
        dist.append(math.sqrt((tot - nz) / U2) if tot > f_dist * nz else 0.0)
    K = len(lines)
    r2 = np.abs(np.asarray(residual)) ** 2
    lof = np.zeros(K)
    stat = limit = math.nan
    if s2 is not None:
        noise = np.array(nv)
        stat = float(np.sum(r2 / noise) * 2.0 / (2 * K - n_params))  # ~ F(2K - p, K dof) without a model error
        limit = float(stats.f.ppf(DETECT, 2 * K - n_params, K * dof))
        if stat > limit:
            lof = np.sqrt(np.maximum(r2 - noise, 0.0))
    d = np.array(dist)
    return LineErrors(np.array(nv) if s2 is not None else None, dof if s2 is not None else 0, np.maximum(d, lof), d,
                      lof, stat, limit)  # fmt: skip


@dataclass(frozen=True)
class ImpedanceFit:
    params: InverseGamma
    ci95: dict[str, float]  # half-widths of the free parameters (`half_width`)
    cov: dict[str, dict[str, float]]  # Gauss-Newton covariance of the free parameters
    free: tuple[str, ...]
    residual_rms: float  # rms of the relative complex error |Z_fit - Z| / |Z|
    dof: int
    Z_fit: np.ndarray
    sens: np.ndarray | None = None  # A = (JᵀJ)⁻¹Jᵀ: free parameters per residual (Re of each line, then Im)
    errors: LineErrors | None = None
    held_D: np.ndarray | None = None  # the free parameters' derivatives by the values held (free x held)
    held_C: np.ndarray | None = None  # those values' covariance (R_s fixed, the error curve's tail: `Curve`)
    swing: np.ndarray | None = None  # the free parameters' bias from the multisine's swing (`swing_bias`), by rows

    def half_width(self, grad: np.ndarray) -> float:
        """95 % half width of a function of the free parameters with gradient ``grad`` (module docstring): the
        larger of the residual's Student-t interval and, with `line_errors`, the noise's (Satterthwaite's
        degrees of freedom over the lines) plus the model error: the larger of its bound Σ_k d_k |a_k| and the
        swing's bias (`swing_bias`)."""
        g = np.asarray(grad, dtype=float)
        C = np.array([[self.cov[a][b] for b in self.free] for a in self.free])
        held = float(g @ self.held_D @ self.held_C @ self.held_D.T @ g) if self.held_D is not None else 0.0
        out = _t95(self.dof) * math.sqrt(max(float(g @ C @ g) + held, 0.0))
        e = self.errors
        if e is None or self.sens is None:
            return out
        a = g @ self.sens
        K = e.model.size
        row = np.hypot(a[:K], a[K:])
        bias = float(np.sum(e.model * row))
        if self.swing is not None:  # two estimates of one error: the larger
            bias = max(bias, float(np.abs(np.atleast_2d(self.swing) @ g).sum()))
        if e.noise_var is None:
            return out + bias
        parts = row**2 * e.noise_var / 2.0  # Re and Im of each line: half its variance each
        var = float(parts.sum())
        nu = var**2 / float(np.sum(parts**2) / e.noise_dof) if var > 0 else math.inf
        return max(out, _t95(int(min(nu, 1e6))) * math.sqrt(var + held) + bias)


NAMES = ("R_s", "L_sigma", "R_R", "L_M")


@dataclass(frozen=True)
class Curve:
    """The inverter's error curve as an input of an impedance fit (reference voltages, corrected by it): ``dZ``
    (lines x terms) each line's impedance by each term of the curve's tail (`DcLine.tail_regressors`), ``cov`` the
    DC fit's covariance of (R_s, those terms) (`DcLine.cov`)."""

    dZ: np.ndarray
    cov: np.ndarray


def impedance(w: np.ndarray, Z: np.ndarray, T: float, filt: tuple[float, float] | None, start: InverseGamma,
              fixed: dict[str, float] | None = None, *, fixed_sd: float = 0.0, curve: Curve | None = None,
              record: Periods | None = None) -> ImpedanceFit:  # fmt: skip
    """Fit (*) of `bench.workflows.commission.circuit` to lock-in impedances ``Z`` at ``w`` [rad/s].

    ``filt`` as in `observed_impedance`; ``fixed`` holds parameters kept at a value (e.g. R_s from the
    DC test), ``fixed_sd`` the standard deviation of a fixed R_s (its error passes on to the others);
    ``curve``: the error curve the voltages were corrected by (its error passes on too, with R_s's where R_s is
    fixed: ``curve.cov`` then replaces ``fixed_sd``); ``start`` is the initial guess (the rig's nominal model: the
    fit is local); ``record``: the multisine's periods (`periods`), for the lines' noise and model error
    (`line_errors`) in the intervals.
    """
    fixed = dict(fixed or {})
    free = tuple(n for n in NAMES if n not in fixed)
    w, Z = np.asarray(w, dtype=float), np.asarray(Z, dtype=complex)
    scale = np.abs(Z)

    def build(theta: np.ndarray, held: dict[str, float] = fixed) -> InverseGamma:
        vals = dict(held)
        vals.update({n: math.exp(v) for n, v in zip(free, theta)})
        return InverseGamma(**vals)

    def resid(theta: np.ndarray, held: dict[str, float] = fixed) -> np.ndarray:
        e = (observed_impedance(build(theta, held), w, T, filt) - Z) / scale
        return np.concatenate([e.real, e.imag])

    x0 = np.log([getattr(start, n) for n in free])
    from scipy import optimize

    sol = optimize.least_squares(resid, x0, method="trf", x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    p = build(sol.x)
    r = sol.fun
    dof = r.size - len(free)
    s2 = float(r @ r) / dof if dof > 0 else math.nan
    J = sol.jac * np.exp(sol.x)[None, :] ** -1  # d r / d p = d r / d theta / p
    JtJ_inv = np.linalg.pinv(J.T @ J)
    cov = s2 * JtJ_inv
    A = JtJ_inv @ J.T
    cols: list[np.ndarray] = []
    C = None
    if "R_s" in fixed and (fixed_sd > 0 or curve is not None):  # dθ/dR_s = -A ∂r/∂R_s (central difference)
        h = 1e-6 * fixed["R_s"]
        up, down = ({**fixed, "R_s": fixed["R_s"] + d} for d in (h, -h))
        dr = (resid(sol.x, up) - resid(sol.x, down)) / (2 * h)
        cols.append(-(A @ dr))
        C = np.array([[fixed_sd**2]])
    if curve is not None and curve.dZ.shape[1]:  # dθ/dc = A ∂Z/∂c / |Z| (r = (Z_fit - Z)/|Z|)
        cols += [A @ np.concatenate([(dz / scale).real, (dz / scale).imag]) for dz in curve.dZ.T]
        C = curve.cov if "R_s" in fixed else curve.cov[1:, 1:]
    covd = {a: {b: float(cov[i, j]) for j, b in enumerate(free)} for i, a in enumerate(free)}
    Zf = observed_impedance(p, w, T, filt)
    errors = None
    if record is not None:
        Z_all = observed_impedance(p, 2.0 * math.pi * record.f0 * record.harmonics, T, filt)
        errors = line_errors(record, Z_all, (Zf - Z) / scale, len(free))
    fit = ImpedanceFit(p, {}, covd, free, float(np.sqrt(np.mean(np.abs((Zf - Z) / scale) ** 2))), dof, Zf, A, errors,
                       np.column_stack(cols) if cols else None, C)  # fmt: skip
    ci = {n: fit.half_width(np.eye(len(free))[k]) for k, n in enumerate(free)}
    return replace(fit, ci95=ci)


def swing_bias(fit: ImpedanceFit, record: Periods, slope: float, w: np.ndarray, T: float,
               filt: tuple[float, float] | None, curvature: float = 0.0) -> np.ndarray:  # fmt: skip
    """The bias of ``fit``'s free parameters (same order) that the multisine's swing causes on a magnetising
    branch whose incremental inductance changes with the current by ``slope`` [H/A] (the saturation check's two
    biases: (L'_m(b_1) - L'_m(b_2)) / (b_1 - b_2)) and whose slope changes by ``curvature`` [H/A²].

    Where the incremental inductance depends on the current, the main flux about the bias is
    ψ(b + x) = ψ(b) + L'_m x + ½ slope x² + ⅙ curvature x³ + ...: the multisine's magnetising current x (the
    lines of the record's current through the rotor's low pass R'_r/(R'_r + s L'_m), (*) of
    `bench.workflows.commission.circuit`) adds the EMF s Q, Q the spectrum of the higher terms, seen at the terminals
    through the same low pass (the rotor resistance in parallel) and the voltage channel's filter. Their sums and
    differences of lines fall on the lines too (they are harmonics of one f0), where they are read as impedance and
    move the fit: on an odd multisine the square's fall between the lines, the cube's on them (to first order the
    mean incremental inductance over the swing, L'_m + ½ curvature ⟨x²⟩). The bias is the fit of the circuit's
    impedance plus that EMF over the current, less the fit of the circuit's alone."""
    p = fit.params
    lines = np.array(record.lines)
    I = record.I.mean(axis=0)[lines - 1]
    N = 8 * int(lines.max())  # samples of one period: the square's harmonics up to 2 x the highest line, no alias
    wl = np.asarray(w, dtype=float)
    lp = p.R_R / (p.R_R + 1j * wl * p.L_M)
    spec = np.zeros(N // 2 + 1, dtype=complex)
    spec[lines] = I * lp * (N / 2.0)  # the `lockin` phasors as an FFT of one period
    x = np.fft.irfft(spec, N)
    Q = np.fft.rfft(0.5 * slope * x * x + curvature / 6.0 * x**3)[lines] * (2.0 / N)
    D = 1j * wl * Q * lp
    if filt is not None:
        D = D * filter_zoh(filt[0], filt[1], wl, T)
    Z0 = observed_impedance(p, wl, T, filt)
    held = {n: getattr(p, n) for n in NAMES if n not in fit.free}
    f0 = impedance(wl, Z0, T, filt, p, held)
    f1 = impedance(wl, Z0 + D / I, T, filt, p, held)
    return np.array([getattr(f1.params, n) - getattr(f0.params, n) for n in fit.free])


def with_swing(fit: ImpedanceFit, swing: np.ndarray) -> ImpedanceFit:
    """``fit`` with the swing's bias (`swing_bias`) in its intervals: one vector, or one per row whose signs are
    unknown to each other (their magnitudes add)."""
    out = replace(fit, swing=np.asarray(swing, dtype=float))
    return replace(out, ci95={n: out.half_width(np.eye(len(fit.free))[k]) for k, n in enumerate(fit.free)})


def gradient(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """The Jacobian of f at x by central differences (relative step 1e-6)."""
    x = np.asarray(x, dtype=float)
    y0 = np.asarray(f(x), dtype=float)
    G = np.empty((y0.size, x.size))
    for k in range(x.size):
        h = 1e-6 * max(abs(x[k]), 1e-12)
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        G[:, k] = (np.asarray(f(xp)) - np.asarray(f(xm))) / (2 * h)
    return G
