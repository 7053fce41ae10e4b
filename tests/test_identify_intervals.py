"""The standstill fit's 95 % intervals (bench.workflows.commission.fits) on synthetic multisine records through the
sampled circuit: the per-line noise estimate is the sensors' noise, and with noise alone the intervals hold the truth
about 95 % of the time. A periodic quadratic main flux (what the multisine's swing does on a saturating magnetising
branch) is found, at the non-excited harmonics and as lack of fit; it widens the intervals so that they still hold
the truth, and `fits.swing_bias` predicts the error it causes. A fixed R_s known to ±σ passes its error on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.workflows.commission import fits
from bench.workflows.commission.circuit import InverseGamma, observed_impedance
from bench.workflows.commission.signals import Multisine

T = 1.0 / 3000.0
TRUE = InverseGamma(R_s=5.0, L_sigma=0.0215, R_R=3.1, L_M=0.33)  # (3.57) in inverse-Gamma form, about
FILT = (1000.0, 1.0 / math.sqrt(2.0))
MS = Multisine.design(1.0, 100.0, 10, 1.0)  # the standstill test's default multisine (odd harmonics)
EVERY = Multisine.design(1.0, 100.0, 10, 1.0, "all")  # the same on every harmonic (older tests' grid)
BIAS, PERIODS = 2.0, 2
SD_I, SD_U = 4e-3, 0.08  # the mock's sensor noise in A and V (2 mV at the ADCs)
START = InverseGamma(5.0, 0.02, 3.0, 0.3)


def record(seed: int, k2: float = 0.0, ms: Multisine = MS,
           k3: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Time, current and voltage of PERIODS periods in periodic steady state: the circuit as sampled (measured
    voltages through the filter), plus the EMF d/dt (k2 (i_mu - BIAS)² + k3 (i_mu - BIAS)³) of a main flux with a
    quadratic and a cubic term (i_mu: the magnetising current, the stator current through the rotor's low pass
    R'_r/(R'_r + s L'_m)), plus noise."""
    n = PERIODS * int(round(1.0 / (ms.f0 * T)))
    t = np.arange(n) * T
    x = ms.amplitude * sum(np.sin(2 * np.pi * ms.f0 * h * t + ph) for h, ph in zip(ms.harmonics, ms.phases))
    X = np.fft.rfft(x)
    w = 2 * np.pi * ms.f0 * np.arange(X.size) / PERIODS
    x_mu = np.fft.irfft(X * TRUE.R_R / (TRUE.R_R + 1j * w * TRUE.L_M), n)
    D = np.fft.rfft(k2 * x_mu**2 + k3 * x_mu**3)
    U = np.zeros_like(X)
    U[1:] = X[1:] * observed_impedance(TRUE, w[1:], T, FILT) + 1j * w[1:] * D[1:]
    u = np.fft.irfft(U, n) + TRUE.R_s * BIAS
    rng = np.random.default_rng(seed)
    return t, BIAS + x + SD_I * rng.standard_normal(n), u + SD_U * rng.standard_normal(n)


def fit(seed: int, k2: float = 0.0, errors: bool = True, rs_sd: float = 0.0, ms: Multisine = MS,
        k3: float = 0.0) -> fits.ImpedanceFit:  # fmt: skip
    t, i, u = record(seed, k2, ms, k3)
    Z = fits.lockin(t, u, ms.freqs)[0] / fits.lockin(t, i, ms.freqs)[0]
    rec = fits.periods(t, i, u, ms.f0, ms.harmonics, 0.0, PERIODS, T) if errors else None
    return fits.impedance(2 * np.pi * ms.freqs, Z, T, FILT, START, fixed={"R_s": TRUE.R_s}, fixed_sd=rs_sd,
                          record=rec)  # fmt: skip


def test_noise_estimate_is_the_noise() -> None:
    """Per line, the noise of Z = U/I the periods show is the sensors' (white, independent):
    E|δZ/Z|² = 4/N (σ_u²/|U|² + σ_i²/|I|²) over N samples; 12 seeds, 120 degrees of freedom per line (the
    estimate's relative standard deviation is about 0.13: ±0.5 is about 4 of them)."""
    rows = [fit(s) for s in range(12)]
    est = np.mean([f.errors.noise_var for f in rows], axis=0)
    t, i, u = record(0)
    n = t.size
    I, U = fits.lockin(t, i, MS.freqs)[0], fits.lockin(t, u, MS.freqs)[0]
    expect = 4.0 / n * (SD_U**2 / np.abs(U) ** 2 + SD_I**2 / np.abs(I) ** 2)
    ratio = est / expect
    assert abs(ratio.mean() - 1.0) < 0.15 and np.all(np.abs(ratio - 1.0) < 0.5), ratio
    assert sum(f.errors.lof_statistic > f.errors.lof_limit for f in rows) <= 3  # 5 % expected: 0.6 of 12
    assert all(f.errors.model.max() < 3.0 * math.sqrt(f.errors.noise_var.max()) for f in rows)


@pytest.mark.slow
def test_noise_only_intervals_cover() -> None:
    """40 noise seeds: each interval holds the truth in >= 36 (95 % expects 38)."""
    rows = [fit(s) for s in range(40)]
    for n in ("L_sigma", "R_R", "L_M"):
        inside = sum(abs(getattr(f.params, n) - getattr(TRUE, n)) <= f.ci95[n] for f in rows)
        assert inside >= 36, (n, inside)


K2 = -0.1  # ψ = ... + k2 x²: slope dL/di = 2 k2 = -0.2 H/A against L'_m 0.33 H, 1 A peak


def test_distortion_found_and_covered() -> None:
    """A quadratic main flux as on a saturating machine (the incremental L'_m changing by 60 % over the multisine's
    peak), on a multisine of every harmonic: L'_m comes out 3 % low; the distortion is found at the non-excited
    harmonics and as lack of fit, the interval holds the truth, and `fits.swing_bias` with the true slope predicts
    the error from the circuit."""
    k2 = K2
    for s in range(2):
        plain, wide = fit(s, k2, errors=False, ms=EVERY), fit(s, k2, ms=EVERY)
        e = wide.errors
        assert e.lof_statistic > e.lof_limit and np.all(e.distortion[:4] > 3 * np.sqrt(e.noise_var[:4]))
        err = wide.params.L_M - TRUE.L_M
        assert -0.04 < err / TRUE.L_M < -0.02
        assert abs(err) <= wide.ci95["L_M"] and wide.ci95["L_M"] > 2 * plain.ci95["L_M"]
        t, i, u = record(s, k2, EVERY)
        rec = fits.periods(t, i, u, EVERY.f0, EVERY.harmonics, 0.0, PERIODS, T)
        pred = fits.swing_bias(wide, rec, 2 * k2, 2 * np.pi * EVERY.freqs, T, FILT)[wide.free.index("L_M")]
        assert 0.6 < pred / err < 1.1


def test_an_odd_multisine_is_not_biased_by_the_quadratic_flux() -> None:
    """The same quadratic main flux on the default, odd multisine: its square lies on the even harmonics, between
    the lines, so L'_m keeps its accuracy (within 0.3 %, against 3 % on every harmonic), the even distortion is
    not counted at the lines (what is left is noise), the fit shows no lack of fit, the interval holds the truth and
    `fits.swing_bias` predicts no bias."""
    for s in range(2):
        f = fit(s, K2)
        e = f.errors
        err = f.params.L_M - TRUE.L_M
        assert abs(err) / TRUE.L_M < 0.003 and abs(err) <= f.ci95["L_M"]
        assert e.lof_statistic < e.lof_limit  # (the F-test's 5 % false alarms may flag a line's distortion:)
        assert np.all(e.distortion < 3.0 * np.sqrt(e.noise_var)), e.distortion / np.sqrt(e.noise_var)
        t, i, u = record(s, K2)
        per = fits.periods(t, i, u, MS.f0, MS.harmonics, 0.0, PERIODS, T)
        U = per.U[:, 1::2]  # harmonic 2, 4, ...: the square is there, far above the noise
        assert np.abs(U.mean(axis=0)).max() > 10 * np.median(np.abs(U.std(axis=0)))
        pred = fits.swing_bias(f, per, 2 * K2, 2 * np.pi * MS.freqs, T, FILT)[f.free.index("L_M")]
        assert abs(pred) / TRUE.L_M < 1e-6


def test_the_cubic_flux_biases_an_odd_multisine_as_swing_bias_predicts() -> None:
    """A cubic main flux k3 x³ (the incremental L'_m changing by 3 k3 x² over the swing) falls on the odd
    lines too: L'_m comes out high by the swing's mean incremental inductance, about 1.5 %, and `fits.swing_bias`
    with the true curvature d²L/di² = 6 k3 predicts it within 15 %; with that bias in the interval, the interval
    holds the truth."""
    k3 = 0.2
    for s in range(2):
        f = fit(s, k3=k3)
        err = f.params.L_M - TRUE.L_M
        assert 0.01 < err / TRUE.L_M < 0.03
        t, i, u = record(s, 0.0, MS, k3)
        per = fits.periods(t, i, u, MS.f0, MS.harmonics, 0.0, PERIODS, T)
        swing = fits.swing_bias(f, per, 0.0, 2 * np.pi * MS.freqs, T, FILT, curvature=6 * k3)
        assert 0.85 < swing[f.free.index("L_M")] / err < 1.15
        assert abs(err) <= fits.with_swing(f, np.array([swing, 0.0 * swing])).ci95["L_M"]


def test_fixed_R_s_error_passes_on() -> None:
    """R_s held at a value known to ±0.5 %: L'_m's interval grows by about |dL'_m/dR_s| σ, and a fit with R_s held
    0.5 % off lands that far away."""
    a, b = fit(0), fit(0, rs_sd=0.01 * TRUE.R_s / 1.96)
    d = b.held_D[b.free.index("L_M"), 0]
    assert b.ci95["L_M"] > a.ci95["L_M"]
    t, i, u = record(0)
    Z = fits.lockin(t, u, MS.freqs)[0] / fits.lockin(t, i, MS.freqs)[0]
    off = fits.impedance(2 * np.pi * MS.freqs, Z, T, FILT, START, fixed={"R_s": TRUE.R_s * 1.005})
    assert off.params.L_M - a.params.L_M == pytest.approx(d * 0.005 * TRUE.R_s, rel=0.05)


def test_the_error_curve_passes_on_as_monte_carlo_says() -> None:
    """Without a voltage measurement the voltages are the references less the DC test's error curve, whose tail
    terms are fitted with R_s and correlated with it (`fits.dc_line`). Their error passes on to every interval
    (`fits.Curve`): drawn 150 times from the DC fit's covariance, the scatter of the R_s-free fit's R_s and of the
    R_s-held fit's R'_r and L'_m (R_s held at the drawn DC value) is what the propagated variance says."""
    rng = np.random.default_rng(1)
    i_l = np.array([-7.0, -6.0, -5.0, -4.0, -3.0, -2.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
    u_l = TRUE.R_s * i_l + np.sign(i_l) * (1.5 - 0.8 / i_l**2 - 0.3 / i_l**4) + 0.01 * rng.standard_normal(i_l.size)
    dc = fits.dc_line(i_l, u_l, tail=2)
    assert dc.cov.shape == (3, 3) and abs(dc.cov[0, 1]) > 0.3 * math.sqrt(dc.cov[0, 0] * dc.cov[1, 1])  # correlated
    t, i, u = record(0)
    w = 2 * np.pi * MS.freqs
    I = fits.lockin(t, i, MS.freqs)[0]
    X = dc.tail_regressors(i)
    curve = fits.Curve(np.column_stack([-fits.lockin(t, x, MS.freqs)[0] / I for x in X.T]), dc.cov)

    def fitted(delta: np.ndarray, with_curve: bool = False) -> tuple[fits.ImpedanceFit, fits.ImpedanceFit]:
        Z = fits.lockin(t, u - X @ delta[1:], MS.freqs)[0] / I  # the curve's tail off by delta[1:]
        c = curve if with_curve else None
        held = fits.impedance(w, Z, T, FILT, START, fixed={"R_s": TRUE.R_s + delta[0]}, curve=c)
        return held, fits.impedance(w, Z, T, FILT, START, curve=c)

    held0, free0 = fitted(np.zeros(3), with_curve=True)
    draws = [fitted(d) for d in rng.multivariate_normal(np.zeros(3), dc.cov, 150)]
    for f0, k, name in ((free0, 1, "R_s"), (held0, 0, "R_R"), (held0, 0, "L_M")):
        g = np.eye(len(f0.free))[f0.free.index(name)]
        predicted = math.sqrt(g @ f0.held_D @ f0.held_C @ f0.held_D.T @ g)
        scatter = np.std([getattr(d[k].params, name) for d in draws])
        assert scatter == pytest.approx(predicted, rel=0.15), name
    assert free0.held_C.shape == (2, 2) and held0.held_C.shape == (3, 3)


def test_one_period_counts_everything_as_model_error() -> None:
    t, i, u = record(0)
    n = t.size // PERIODS
    rec = fits.periods(t[:n], i[:n], u[:n], MS.f0, MS.harmonics, 0.0, 1, T)
    assert rec.I.shape[0] == 1
    Z = fits.lockin(t[:n], u[:n], MS.freqs)[0] / fits.lockin(t[:n], i[:n], MS.freqs)[0]
    f = fits.impedance(2 * np.pi * MS.freqs, Z, T, FILT, START, fixed={"R_s": TRUE.R_s}, record=rec)
    assert f.errors.noise_var is None and np.all(f.errors.model > 0)
    g = fits.impedance(2 * np.pi * MS.freqs, Z, T, FILT, START, fixed={"R_s": TRUE.R_s})
    assert all(f.ci95[n] > g.ci95[n] for n in f.free)
