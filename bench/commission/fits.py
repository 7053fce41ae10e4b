"""Least-squares fits of the standstill identification, each with 95 % confidence intervals.

* `linear` - ordinary least squares, Student-t intervals from the residual variance.
* `dc_line` - R_s as the slope of the per-level mean voltage over the mean current, with one
  intercept per polarity: u = R_s i + c_+ [i > 0] + c_- [i < 0]. A constant inverter voltage error
  (dead time, on-state drop: ±4/3 (t_d f_pwm u_dc + v_on) for a current along a phase axis,
  `mock_hw.inverter`) sits in the intercepts and leaves the slope alone (moteus' method, with both
  polarities here). Without a voltage measurement a soft knee bends the error curve on toward its
  plateau over the low levels; ``tail=True`` fits that bend's leading term as well.
* `lockin` - phasors of several sinusoids at once by least squares on a constant and a cos/sin pair
  per line (a lock-in amplifier in batch form); over whole common periods the regressors are
  orthogonal and this is the DFT at those lines.
* `impedance` - the inverse-Γ parameters from lock-in impedances: nonlinear least squares
  (scipy's trust-region reflective) on the relative complex error, parameters in logarithms so they
  stay positive; intervals from the Jacobian at the optimum (Gauss-Newton covariance, Student-t).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from bench.commission.circuit import InverseGamma, observed_impedance


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


def dc_line(i: np.ndarray, u: np.ndarray, tail: bool = False) -> DcLine:
    """R_s and the intercepts per polarity from per-level means (module docstring); ``tail``: with the
    knee's tail d sgn(i)/i², the leading term of any error curve that reaches its plateau like a soft
    knee (i/sqrt(i² + i_k²) = 1 - i_k²/(2 i²) + ...)."""
    i, u = np.asarray(i, dtype=float), np.asarray(u, dtype=float)
    pos, neg = i > 0, i < 0
    cols = [i] + [m.astype(float) for m in (pos, neg) if m.any()] + ([np.sign(i) / i**2] if tail else [])
    f = linear(np.column_stack(cols), u)
    c = list(f.coef[1 : 1 + int(pos.any()) + int(neg.any())])
    c_pos = c.pop(0) if pos.any() else math.nan
    c_neg = c.pop(0) if neg.any() else math.nan
    d, d_sd = (float(f.coef[-1]), float(math.sqrt(max(f.cov[-1, -1], 0.0)))) if tail else (0.0, 0.0)
    return DcLine(float(f.coef[0]), float(f.ci95[0]), float(c_pos), float(c_neg), f.residual_rms, f.dof, d, d_sd)


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


@dataclass(frozen=True)
class ImpedanceFit:
    params: InverseGamma
    ci95: dict[str, float]  # half-widths of the free parameters
    cov: dict[str, dict[str, float]]  # covariance of the free parameters
    free: tuple[str, ...]
    residual_rms: float  # rms of the relative complex error |Z_fit - Z| / |Z|
    dof: int
    Z_fit: np.ndarray


NAMES = ("R_s", "L_sigma", "R_R", "L_M")


def impedance(w: np.ndarray, Z: np.ndarray, T: float, filt: tuple[float, float] | None, start: InverseGamma,
              fixed: dict[str, float] | None = None) -> ImpedanceFit:  # fmt: skip
    """Fit (*) of `bench.commission.circuit` to lock-in impedances ``Z`` at ``w`` [rad/s].

    ``filt`` as in `observed_impedance`; ``fixed`` holds parameters kept at a value (e.g. R_s from the
    DC test); ``start`` is the initial guess (the rig's nominal model: the fit is local).
    """
    fixed = dict(fixed or {})
    free = tuple(n for n in NAMES if n not in fixed)
    w, Z = np.asarray(w, dtype=float), np.asarray(Z, dtype=complex)
    scale = np.abs(Z)

    def build(theta: np.ndarray) -> InverseGamma:
        vals = dict(fixed)
        vals.update({n: math.exp(v) for n, v in zip(free, theta)})
        return InverseGamma(**vals)

    def resid(theta: np.ndarray) -> np.ndarray:
        e = (observed_impedance(build(theta), w, T, filt) - Z) / scale
        return np.concatenate([e.real, e.imag])

    x0 = np.log([getattr(start, n) for n in free])
    from scipy import optimize

    sol = optimize.least_squares(resid, x0, method="trf", x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12)
    p = build(sol.x)
    r = sol.fun
    dof = r.size - len(free)
    s2 = float(r @ r) / dof if dof > 0 else math.nan
    J = sol.jac * np.exp(sol.x)[None, :] ** -1  # d r / d p = d r / d theta / p
    cov = s2 * np.linalg.pinv(J.T @ J)
    t = _t95(dof)
    ci = {n: float(t * math.sqrt(max(cov[k, k], 0.0))) for k, n in enumerate(free)}
    covd = {a: {b: float(cov[i, j]) for j, b in enumerate(free)} for i, a in enumerate(free)}
    Zf = observed_impedance(p, w, T, filt)
    return ImpedanceFit(p, ci, covd, free, float(np.sqrt(np.mean(np.abs((Zf - Z) / scale) ** 2))), dof, Zf)


def propagate(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Standard deviations of f(x) by the delta method (central differences)."""
    x = np.asarray(x, dtype=float)
    y0 = np.asarray(f(x), dtype=float)
    G = np.empty((y0.size, x.size))
    for k in range(x.size):
        h = 1e-6 * max(abs(x[k]), 1e-12)
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        G[:, k] = (np.asarray(f(xp)) - np.asarray(f(xm))) / (2 * h)
    return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", G, cov, G), 0.0))
