"""The induction motor at standstill as a circuit: impedance, its sampled-data form, and parameter sets.

**The inverse-Γ circuit is the thesis' referred model.** (4.2)-(4.3) with the rotor flux angle held
(ω_mR = 0) and the shaft at rest (ω_r = 0), i.e. slip 1, read in the Laplace domain

    (R_s + s L'_s) i_s + s L'_m i_m = u_s,       R'_r (i_m - i_s) + s L'_m i_m = 0

so i_m = R'_r / (R'_r + s L'_m) i_s and the stator sees

    Z(s) = u_s / i_s = R_s + s L'_s + s L'_m R'_r / (R'_r + s L'_m)                       (*)

with L'_s = σ L_s (leakage), L'_m = L_m²/L_r and R'_r = (L_m/L_r)² R_r, the definitions under (4.3).
This is the inverse-Γ equivalent circuit: R_s and the leakage L'_s in series with the magnetising
inductance L'_m in parallel with the rotor resistance R'_r. The same follows from (3.34)-(3.35)
at ω_r = 0 by eliminating i_rs: Z = R_s + s L_s - s² L_m² / (R_r + s L_r). Four numbers fix (*);
the T circuit has five (L_s, L_r, L_m, R_s, R_r), so terminal measurements cannot separate them
(thesis 3.6, "an infinite number of motor parameters all yielding the same behaviour"). With the
thesis' assumption L_s = L_r the T parameters follow uniquely (`thesis_params`).

At standstill a current along one stator axis (the α axis here) and its flux stay collinear, so
the torque of (3.41), 3 Z_p L_m²/(2 L_r) Im{i_s i_m*}, is zero: the test does not turn the shaft.

**Sampled data.** The bench measures at t_k and its inverter applies a reference one sample later,
held over a period (zero-order hold, `mock_hw.inverter`). The exact relation between the voltage
held over [t_k, t_k+1) and the currents sampled at t_k is the ZOH discretisation Y_d(z) of the
admittance 1/Z(s); the filtered voltage channel (thesis A.4: second order, 1 kHz) sees the same held
voltage through its own ZOH discretisation H_d(z). So the lock-in ratios the test measures are

    reference voltages (shifted by the inverter delay):  v / i  = 1 / Y_d(e^{jωT})
    measured voltages:                                   y / i  = H_d(e^{jωT}) / Y_d(e^{jωT})

and the fit compares these, not (*), with the data: no delay or filter phase is approximated
(at 100 Hz and 3 kHz the one-sample delay alone is 12°, the ZOH another 6°, the filter 8°).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.linalg import expm


@dataclass(frozen=True)
class InverseGamma:
    """The unique standstill parameter set (*): R_s [Ω], L_sigma = L'_s [H], R_R = R'_r [Ω], L_M = L'_m [H]."""

    R_s: float
    L_sigma: float
    R_R: float
    L_M: float

    @classmethod
    def of(cls, L_s: float, L_r: float, L_m: float, R_s: float, R_r: float) -> "InverseGamma":
        """From T-circuit parameters (the definitions under (4.3))."""
        return cls(R_s, L_s - L_m**2 / L_r, (L_m / L_r) ** 2 * R_r, L_m**2 / L_r)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def thesis_params(p: InverseGamma) -> dict[str, float]:
    """T-circuit parameters under the thesis' assumption L_s = L_r (3.6, (3.57)).

    L_s = L'_s + L'_m (because L'_m = (1 - σ) L_s), L_m = sqrt(L'_m L_r), R_r = R'_r (L_r/L_m)².
    """
    L_s = p.L_sigma + p.L_M
    L_m = math.sqrt(p.L_M * L_s)
    return {"L_s": L_s, "L_r": L_s, "L_m": L_m, "R_s": p.R_s, "R_r": p.R_R * (L_s / L_m) ** 2}


def impedance(p: InverseGamma, w: np.ndarray) -> np.ndarray:
    """Z(jω) of (*) [Ω] at angular frequencies ``w`` [rad/s]."""
    s = 1j * np.asarray(w, dtype=float)
    return p.R_s + s * p.L_sigma + s * p.L_M * p.R_R / (p.R_R + s * p.L_M)


def _freq_response(A: np.ndarray, B: np.ndarray, C: np.ndarray, T: float, w: np.ndarray) -> np.ndarray:
    """C (zI - Φ)^-1 Γ at z = e^{jωT} for the ZOH discretisation (Φ, Γ) of (A, B), single input/output."""
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1))  # expm of [[A, B], [0, 0]] T gives Φ and Γ together
    M[:n, :n], M[:n, n] = A * T, B * T
    E = expm(M)
    Phi, Gam = E[:n, :n], E[:n, n]
    z = np.exp(1j * np.asarray(w, dtype=float) * T)
    zf = z.reshape(-1)
    rhs = np.broadcast_to(Gam.astype(complex), (zf.size, n))[..., None]
    x = np.linalg.solve(zf[:, None, None] * np.eye(n) - Phi, rhs)[..., 0]  # one 2x2 solve per frequency, batched
    return (x @ C).reshape(z.shape)


def admittance_zoh(p: InverseGamma, w: np.ndarray, T: float) -> np.ndarray:
    """Y_d(e^{jωT}): held voltage over [t_k, t_k+1) -> sampled current, of the circuit (*).

    States i_s and i_m (= ψ'_R / L'_m): L'_s di_s/dt = u - (R_s + R'_r) i_s + R'_r i_m,
    L'_m di_m/dt = R'_r (i_s - i_m), from (4.2)-(4.3) at ω_mR = ω_r = 0.
    """
    A = np.array([[-(p.R_s + p.R_R) / p.L_sigma, p.R_R / p.L_sigma], [p.R_R / p.L_M, -p.R_R / p.L_M]])
    return _freq_response(A, np.array([1.0 / p.L_sigma, 0.0]), np.array([1.0, 0.0]), T, w)


def filter_zoh(f_c: float, zeta: float, w: np.ndarray, T: float) -> np.ndarray:
    """H_d(e^{jωT}) of the voltage channel's filter w0²/(s² + 2ζ w0 s + w0²), w0 = 2π f_c, driven by a held
    voltage."""
    w0 = 2.0 * math.pi * f_c
    A = np.array([[0.0, 1.0], [-w0 * w0, -2.0 * zeta * w0]])
    return _freq_response(A, np.array([0.0, w0 * w0]), np.array([1.0, 0.0]), T, w)


def observed_impedance(p: InverseGamma, w: np.ndarray, T: float, filt: tuple[float, float] | None) -> np.ndarray:
    """What the lock-in measures: 1/Y_d (reference voltages, delay removed) or H_d/Y_d (``filt`` = (f_c, ζ))."""
    Z = 1.0 / admittance_zoh(p, w, T)
    return Z if filt is None else Z * filter_zoh(filt[0], filt[1], w, T)
