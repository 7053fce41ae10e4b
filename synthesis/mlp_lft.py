"""MLP state-space model -> quasi-LPV model in LFT form (thesis 6.3.1-6.3.3), for the NARX model of 6.4.

Starting point: the NARX MLP of `synthesis.narx`, w~_{k+1} = Theta2 tanh(Theta1 z_{k+1} + Theta_b). Steps:

1. **Equilibrium shift** (6.3.1, Remark 6.5). For a chosen input equilibrium u° (default: the scaled
   operating point, u° = 0) the speed equilibrium w° solves w° = Theta2 tanh(Theta1 z° + Theta_b). With
   x = x~ - x°, u = u~ - u° and the new bias theta_b = Theta1 z° + Theta_b the model is
   w_{k+1} = Theta2 sigma'(xi), xi = Theta1 (z - z°), sigma'_j(xi) = tanh(xi + theta_b,j) - tanh(theta_b,j).
2. **Active input ranges** xi_j in [xi_min, xi_max] from the data (the training set, and any other given).
3. **Sector bounds** (6.21)-(6.23): k_min/k_max of sigma'_j(xi)/xi over the range, exact by the tangent
   search of 6.3.2 (`tangent_point`, the point where a line through the origin touches sigma'); the
   thesis' polynomial fit (`xi_b_thesis`) is the cross-check.
4. **Centring** (6.24)-(6.28): K_min = diag(k_min - eps), K_max = diag(k_max + eps),
   A = 1/2 Theta_o (K_min + K_max) Theta_x, B = 1/2 Theta_o (K_min + K_max) Theta_u,
   B_u = 1/2 Theta_o (K_max - K_min), Omega(xi) = 2 (K_max - K_min)^{-1} (sigma'(xi) - 1/2 (K_min + K_max) xi),
   so each residual gain Omega_j(xi)/xi lies in (-1, 1).
5. **Uncertainty on the residual gains** (6.3.3, used in 7.2): a bound on the speed-measurement noise
   bounds the error of xi, and a numerical search bounds the resulting error of Omega_j(xi)/xi.

The result, `MLPLFT`, holds a discrete `synthesis.lft.LFTPlant` (dt = 1/600 s) with

    state  x = [w_k .. w_{k-n+1}, i_{k-1} .. i_{k-n_i+1}, d_{k-1} .. d_{k-n_u+1}, tau_{k-1} .. tau_{k-n_u+1}] - x°
    input  u = [i_k, d_k, tau_k] - u°           (scaled i_mR_hat, i_sd,ref, i_tau; `synthesis.narx.Scaling`)
    output y = w_k - w°                          (scaled speed)
    parameter channel  z_u = xi (one per neuron), w_u = Omega(xi) = Delta z_u,
                       Delta = diag(Omega_j(xi_j)/xi_j), |Delta_jj| < 1

and no performance channel: the synthesis set-up (Fig. 6.13: observer, filters, noise, penalties) is
built around it by the controller design.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from scipy.optimize import brentq

from synthesis.lft import LFTPlant
from synthesis.narx import Dataset, NarxModel, Orders, Scaling, regressors

__all__ = [
    "secant", "secant_scalar", "tangent_point", "xi_b_thesis", "sector_bounds", "equilibrium", "MLPLFT", "mlp_to_lft",
    "active_ranges", "lft_from_model", "gain_uncertainty",
]  # fmt: skip


# --------------------------------------------------------------------------------------------------
# sector bounds of a shifted tanh neuron (6.3.2)
# --------------------------------------------------------------------------------------------------
def secant(b: float, xi: np.ndarray | float) -> np.ndarray:
    """sigma'(xi)/xi for sigma'(xi) = tanh(xi + b) - tanh(b); the limit 1 - tanh(b)^2 at xi = 0."""
    xi = np.asarray(xi, float)
    small = np.abs(xi) < 1e-6
    safe = np.where(small, 1.0, xi)
    # tanh(x+b) - tanh(b) = tanh(x) (1 - tanh(b)^2) / (1 + tanh(x) tanh(b)): no cancellation for small x
    tb, tx = math.tanh(b), np.tanh(safe)
    s = tx * (1.0 - tb * tb) / (1.0 + tx * tb) / safe
    d1 = 1.0 - tb * tb  # Taylor series at 0: d1 + d2 xi + d3 xi^2
    d2 = -tb * d1
    d3 = d1 * (3.0 * tb * tb - 1.0) / 3.0
    return np.where(small, d1 + d2 * xi + d3 * xi * xi, s)


def secant_scalar(b: float, xi: float) -> float:
    """`secant` for one float, in plain Python (per-tick scheduling of the LPV speed controller)."""
    tb = math.tanh(b)
    d1 = 1.0 - tb * tb
    if abs(xi) < 1e-6:
        return d1 - tb * d1 * xi + d1 * (3.0 * tb * tb - 1.0) / 3.0 * xi * xi
    tx = math.tanh(xi)
    return tx * d1 / (1.0 + tx * tb) / xi


def _tangency(b: float, xi: float) -> float:
    """h(xi) = xi sigma'_xi'(xi) - sigma'(xi) = xi^2 d/dxi (sigma'(xi)/xi): zero where the line through
    the origin touches sigma' (the secant slope is stationary)."""
    s = math.tanh(xi + b)
    return xi * (1.0 - s * s) - (s - math.tanh(b))


def tangent_point(b: float) -> float:
    """xi_b: where the secant slope sigma'(xi)/xi of tanh(xi + b) - tanh(b) is largest (6.3.2).

    For b > 0 it is the unique root of `_tangency` on (-inf, -b) (h < 0 on [-b, 0), h -> 1 + tanh b > 0
    as xi -> -inf); tanh is odd, so xi_b(-b) = -xi_b(b); for b = 0 the largest slope is at xi = 0.
    """
    if b == 0.0:
        return 0.0
    if b < 0.0:
        return -tangent_point(-b)
    lo = -b - 1.0
    while _tangency(b, lo) <= 0.0:
        lo = -b + 2.0 * (lo + b)
    return brentq(lambda x: _tangency(b, x), lo, -b, xtol=1e-14, rtol=1e-15, maxiter=200)


def xi_b_thesis(b: float) -> float:
    """The thesis' fit xi_b = -0.00379 b^3 + 0.07274 b^2 - 1.5146 b (b > 0), odd extension for b < 0."""
    a = abs(b)
    v = -0.00379 * a**3 + 0.07274 * a**2 - 1.5146 * a
    return v if b > 0 else -v


def sector_bounds(b: float, xi_min: float, xi_max: float) -> tuple[float, float]:
    """Exact (k_min, k_max) of (6.21)(6.22) for sigma'(xi) = tanh(xi + b) - tanh(b) on [xi_min, xi_max] \\ {0}.

    The secant slope g(xi) = sigma'(xi)/xi (continuous at 0) is, for b > 0, increasing on (-inf, xi_b)
    and decreasing on (xi_b, inf) (mirrored for b < 0; for b = 0 even with its maximum at 0). So its
    extremes on an interval are among the two end points and xi_b.
    """
    if not xi_min <= xi_max:
        raise ValueError(f"need xi_min <= xi_max, got [{xi_min}, {xi_max}]")
    pts = [xi_min, xi_max]
    xb = tangent_point(b)
    if xi_min < xb < xi_max:
        pts.append(xb)
    g = secant(b, np.array(pts))
    return float(g.min()), float(g.max())


# --------------------------------------------------------------------------------------------------
# the transformation
# --------------------------------------------------------------------------------------------------
def _selectors(o: Orders) -> tuple[np.ndarray, np.ndarray, int]:
    """P_x, P_u with z_{k+1} = P_x x_k + P_u u_k for the state and input of the module docstring."""
    nx = o.n + (o.n_i - 1 if o.n_i > 0 else 0) + 2 * (o.n_u - 1)
    Px, Pu = np.zeros((o.dim, nx)), np.zeros((o.dim, 3))
    Px[: o.n, : o.n] = np.eye(o.n)  # w_k .. w_{k-n+1}
    row, col = o.n, o.n
    for inp, m in ((0, o.n_i), (1, o.n_u), (2, o.n_u)):
        if m == 0:
            continue
        Pu[row, inp] = 1.0  # the current sample comes from the input
        for j in range(1, m):  # the older ones from the delay states
            Px[row + j, col + j - 1] = 1.0
        row += m
        col += m - 1
    return Px, Pu, nx


def equilibrium(model: NarxModel, u0: Sequence[float] = (0.0, 0.0, 0.0)) -> float:
    """Scaled speed w° with w° = Theta2 tanh(Theta1 z° + Theta_b) for constant scaled inputs u° = (i, d, tau)."""
    o, mlp = model.orders, model.mlp
    i0, d0, t0 = (float(v) for v in u0)
    zu = np.concatenate([np.full(o.n_i, i0), np.full(o.n_u, d0), np.full(o.n_u, t0)])

    def f(w: float) -> float:
        z = np.concatenate([np.full(o.n, w), zu])
        return float(mlp.predict(z)) - w

    # the ARX part makes f(w) ~ (a - 1) w with sum of AR coefficients a < 1 for a stable model: bracket outward
    lo, hi = -1.0, 1.0
    for _ in range(60):
        if f(lo) * f(hi) <= 0.0:
            return brentq(f, lo, hi, xtol=1e-15, rtol=1e-15)
        lo, hi = 2.0 * lo, 2.0 * hi
    raise ValueError("no speed equilibrium found for these inputs")


@dataclass
class MLPLFT:
    """The quasi-LPV LFT of an MLP NARX model (see the module docstring for states and channels).

    ``plant`` is the `LFTPlant`; the other fields describe the residual gains and how to evaluate them.
    All signals are scaled (`scaling`) and shifted by the equilibrium (``x0``, ``u0``, ``w0``).
    """

    plant: LFTPlant
    orders: Orders
    scaling: Scaling
    Theta_xi: np.ndarray  # (l x dim) xi = Theta_xi (z - z°) = C_u x + E_u u
    theta_b: np.ndarray  # (l,) shifted biases, sigma'_j(xi) = tanh(xi + theta_b,j) - tanh(theta_b,j)
    Theta_o: np.ndarray  # (1 x l) output weights
    k_min: np.ndarray  # (l,) sector bounds (6.21), before eps
    k_max: np.ndarray  # (6.22)
    eps: float  # widening of (6.24)
    xi_min: np.ndarray  # (l,) active input ranges
    xi_max: np.ndarray
    w0: float  # scaled speed equilibrium
    u0: np.ndarray  # (3,) scaled input equilibrium (i, d, tau)
    x0: np.ndarray  # (n_x,) state equilibrium
    neurons: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # MLP neuron index of each residual gain

    # -- the residual gains -----------------------------------------------------------------------
    @property
    def widths(self) -> np.ndarray:
        """k_max - k_min per residual gain (the thesis' sector-width table, 6.4.3)."""
        return self.k_max - self.k_min

    @property
    def _c(self) -> np.ndarray:  # 1/2 (K_min + K_max)
        return 0.5 * (self.k_min + self.k_max)

    @property
    def _h(self) -> np.ndarray:  # 1/2 (K_max - K_min), eps included
        return 0.5 * (self.k_max - self.k_min) + self.eps

    def sigma_prime(self, xi: np.ndarray) -> np.ndarray:
        """sigma'(xi) (rows of xi are points, columns neurons)."""
        return np.tanh(xi + self.theta_b) - np.tanh(self.theta_b)

    def Omega(self, xi: np.ndarray) -> np.ndarray:
        """The normalised residual function (6.28)."""
        return (self.sigma_prime(xi) - self._c * xi) / self._h

    def gain(self, j: int, xi: np.ndarray) -> np.ndarray:
        """Omega_j(xi)/xi of residual gain j, in (-1, 1) on the active range (continuous at xi = 0)."""
        return (secant(float(self.theta_b[j]), xi) - self._c[j]) / self._h[j]

    def gains(self, xi: np.ndarray) -> np.ndarray:
        """All residual gains for neuron inputs xi (..., l): the diagonal(s) of Delta."""
        xi = np.asarray(xi, float)
        return np.stack([self.gain(j, xi[..., j]) for j in range(self.theta_b.size)], axis=-1)

    def xi(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Neuron inputs for shifted state(s) and input(s): C_u x + E_u u."""
        return x @ self.plant.C_u.T + u @ self.plant.E_u.T

    def Delta(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The scheduling matrix diag(Omega_j(xi_j)/xi_j) at one (x, u)."""
        return np.diag(self.gains(self.xi(np.asarray(x, float), np.asarray(u, float))))

    def step(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, float]:
        """One step of the LFT closed with its own Delta: (x_{k+1}, y_k). Equals the MLP exactly."""
        P = self.plant.at(self.Delta(x, u)).to_state_space()
        x, u = np.asarray(x, float), np.asarray(u, float)
        return P.A @ x + P.B @ u, float((P.C @ x + P.D @ u)[0])

    # -- conversions ------------------------------------------------------------------------------
    def state_from_history(self, w: Sequence[float], i: Sequence[float], d: Sequence[float],
                           tau: Sequence[float]) -> np.ndarray:  # fmt: skip
        """Shifted state from scaled histories, newest first: w = (w_k, w_{k-1}, ...), i/d/tau = (i_{k-1}, ...)."""
        o = self.orders
        x = np.concatenate([np.asarray(w[: o.n], float), np.asarray(i[: max(o.n_i - 1, 0)], float),
                            np.asarray(d[: o.n_u - 1], float), np.asarray(tau[: o.n_u - 1], float)])  # fmt: skip
        return x - self.x0

    def keep(self, which: Sequence[int]) -> "MLPLFT":
        """The LFT with only the residual gains ``which`` (indices into this LFT's gains); the others are
        replaced by their sector centre, i.e. Delta_jj = 0 (how 6.4.3 'disregards' the narrowest gains)."""
        idx = np.asarray(list(which), int)
        p = self.plant
        plant = LFTPlant.from_blocks(p.A, B_u=p.B_u[:, idx], B=p.B, C_u=p.C_u[idx], E_u=p.E_u[idx], C=p.C,
                                     F_3=p.F_3, dt=p.dt)  # fmt: skip
        sel = {k: getattr(self, k)[idx] for k in ("k_min", "k_max", "xi_min", "xi_max", "theta_b", "neurons")}
        return replace(self, plant=plant, Theta_xi=self.Theta_xi[idx], Theta_o=self.Theta_o[:, idx], **sel)

    def widest(self, m: int) -> "MLPLFT":
        """`keep` the m residual gains with the largest sector widths (6.4.3 keeps two of four)."""
        return self.keep(np.argsort(-self.widths, kind="stable")[:m])

    def summary(self) -> dict[str, Any]:
        """The numbers of the transformation; ``ranges_by_neuron`` (MLP order) rebuilds it (`lft_from_model`)."""
        by = np.argsort(self.neurons)
        return {"ranges_by_neuron": {"xi_min": self.xi_min[by].tolist(), "xi_max": self.xi_max[by].tolist()},
                "neurons": self.neurons.tolist(), "k_min": self.k_min.tolist(), "k_max": self.k_max.tolist(),
                "widths": self.widths.tolist(), "eps": self.eps, "xi_min": self.xi_min.tolist(),
                "xi_max": self.xi_max.tolist(), "theta_b": self.theta_b.tolist(), "w0": self.w0,
                "u0": self.u0.tolist(), "n_x": self.plant.n_x, "dt": self.plant.dt}  # fmt: skip


def _equilibrium_point(model: NarxModel, u0: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(w°, x°, z°) for the input equilibrium u°."""
    o = model.orders
    Px, Pu, _ = _selectors(o)
    w0 = equilibrium(model, u0)
    x0 = np.concatenate([np.full(o.n, w0), np.full(max(o.n_i - 1, 0), u0[0]), np.full(o.n_u - 1, u0[1]),
                         np.full(o.n_u - 1, u0[2])])  # fmt: skip
    return w0, x0, Px @ x0 + Pu @ u0


def active_ranges(model: NarxModel, data: Sequence[Dataset], u0: Sequence[float] = (0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """[xi_min, xi_max] of every MLP neuron (in the MLP's order) over the data sets, 0 included (6.3.1)."""
    u0 = np.asarray(u0, float)
    _, _, z0 = _equilibrium_point(model, u0)
    l = model.mlp.neurons
    lo, hi = np.zeros(l), np.zeros(l)
    for ds in data:
        Z, _ = regressors(ds, model.orders)
        xi = (Z - z0) @ model.mlp.Theta1.T
        lo, hi = np.minimum(lo, xi.min(axis=0)), np.maximum(hi, xi.max(axis=0))
    return lo, hi


def mlp_to_lft(model: NarxModel, data: Sequence[Dataset] = (), *, ranges: tuple[Sequence[float], Sequence[float]] | None = None,
               eps: float = 1e-8, u0: Sequence[float] = (0.0, 0.0, 0.0)) -> MLPLFT:  # fmt: skip
    """Transform the MLP of ``model`` into the quasi-LPV LFT (6.3.1-6.3.2).

    The active ranges come from ``data`` (`active_ranges`) or are given as ``ranges`` = (xi_min, xi_max)
    per MLP neuron (e.g. stored with the model: `lft_from_model`). Residual gains are ordered by
    decreasing sector width (as the thesis tabulates them); ``neurons`` maps them back to the MLP's neurons.
    """
    o, mlp = model.orders, model.mlp
    u0 = np.asarray(u0, float)
    w0, x0, z0 = _equilibrium_point(model, u0)
    Px, Pu, nx = _selectors(o)
    T1, T2 = mlp.Theta1, mlp.Theta2
    theta_b = T1 @ z0 + mlp.Theta_b  # new bias (6.3.1)
    if ranges is None:
        if not data:
            raise ValueError("mlp_to_lft needs data sets or ranges for the active input ranges")
        lo, hi = active_ranges(model, data, u0)
    else:
        lo, hi = np.minimum(np.asarray(ranges[0], float), 0.0), np.maximum(np.asarray(ranges[1], float), 0.0)
    kk = np.array([sector_bounds(b, a, c) for b, a, c in zip(theta_b, lo, hi)])
    k_min, k_max = kk[:, 0], kk[:, 1]
    order = np.argsort(-(k_max - k_min), kind="stable")
    T1, T2, theta_b, lo, hi, k_min, k_max = T1[order], T2[:, order], theta_b[order], lo[order], hi[order], k_min[order], k_max[order]
    Kc = np.diag(0.5 * (k_min + k_max))  # (6.25)-(6.27), eps only widens K_max - K_min
    Kh = np.diag(0.5 * (k_max - k_min) + eps)
    Cx, Eu = T1 @ Px, T1 @ Pu  # xi = Theta_x x + Theta_u u
    A = np.zeros((nx, nx))
    B = np.zeros((nx, 3))
    A[0] = (T2 @ Kc @ Cx)[0]  # (6.25)
    B[0] = (T2 @ Kc @ Eu)[0]  # (6.26)
    B_u = np.zeros((nx, mlp.neurons))
    B_u[0] = (T2 @ Kh)[0]  # (6.27)
    # shift registers: speeds and delayed inputs
    for j in range(1, o.n):
        A[j, j - 1] = 1.0
    col = o.n
    for inp, m in ((0, o.n_i), (1, o.n_u), (2, o.n_u)):
        if m <= 1:
            continue
        B[col, inp] = 1.0
        for j in range(1, m - 1):
            A[col + j, col + j - 1] = 1.0
        col += m - 1
    C = np.zeros((1, nx))
    C[0, 0] = 1.0
    plant = LFTPlant.from_blocks(A, B_u=B_u, B=B, C_u=Cx, E_u=Eu, C=C, F_3=np.zeros((1, 3)), dt=model.dt)
    return MLPLFT(plant, o, model.scaling, T1, theta_b, T2, k_min, k_max, eps, lo, hi, w0, u0, x0, order)


def gain_uncertainty(lft: MLPLFT, noise_rad_s: float, *, n_xi: int = 4001, n_eta: int = 41) -> np.ndarray:
    """Bound on the error of each residual gain Omega_j(xi)/xi when the speed is measured with an error of
    at most ``noise_rad_s`` [rad/s] (6.3.3).

    Every speed tap of the regressor may be off by noise/sigma_w (scaled), so xi_j by at most
    eta_j = noise/sigma_w * sum_i |Theta_xi[j, speed taps i]|. The bound is
    sup |g_j(xi + eta) - g_j(xi)| over xi in the active range and |eta| <= eta_j, found on a dense grid
    (``n_xi`` x ``n_eta`` points, end points included). Returned as fractions of the unit sector.
    """
    o = lft.orders
    eta_max = noise_rad_s / lft.scaling.sigma_omega * np.abs(lft.Theta_xi[:, : o.n]).sum(axis=1)
    out = np.zeros(lft.Theta_xi.shape[0])
    for j in range(out.size):
        xi = np.linspace(lft.xi_min[j], lft.xi_max[j], n_xi)
        g0 = lft.gain(j, xi)
        eta = np.linspace(-eta_max[j], eta_max[j], n_eta)
        out[j] = max(float(np.max(np.abs(lft.gain(j, xi + e) - g0))) for e in eta)
    return out


def lft_from_model(model: NarxModel, *, eps: float | None = None) -> MLPLFT:
    """The LFT of a model artifact written by ``bench train narx``, rebuilt from the active ranges and the
    equilibrium input stored in its JSON (``meta["lft"]``) - no data sets needed (e.g. at run time)."""
    meta = model.meta.get("lft")
    if not meta or "ranges_by_neuron" not in meta:
        raise ValueError("the model artifact holds no LFT ranges (train it with `bench train narx`)")
    r = meta["ranges_by_neuron"]
    return mlp_to_lft(model, ranges=(r["xi_min"], r["xi_max"]), eps=meta["eps"] if eps is None else eps,
                      u0=meta.get("u0", (0.0, 0.0, 0.0)))  # fmt: skip
