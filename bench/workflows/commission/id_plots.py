"""The identification's figures: the standstill test's DC line and impedance (`bench.workflows.commission.identify`),
the rotating test's magnetising curve and mechanics (`bench.workflows.commission.rotating_fit`), each a PNG beside the
run's log."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from bench.workflows.commission import fits
from bench.workflows.commission.circuit import InverseGamma, impedance
from bench.core.plotstyle import pyplot, save


def plot_dc(res: dict[str, Any], png: Path) -> Path:
    """The standstill DC test: each level's measured and reference voltage against the current, the line fitted
    over the levels it used (R_s, the intercepts, the knee's tail)."""
    plt = pyplot()

    lv = res["dc"]["levels"]
    i = np.array([x["i"] for x in lv])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for kind, mk in (("measured", "o"), ("reference", "s")):
        ax1.plot(i, [x[f"u_{kind}"] for x in lv], mk, mfc="none", label=f"{kind} voltage")
    R, d = res["dc"]["R_s"]["value"], res["dc"].get("knee_tail_VA2") or 0.0
    lo = res["dc"].get("fit_from_A") or 0.0
    used = np.array([x["in_slope_fit"] for x in lv])
    ax1.plot(i[used], [x[f"u_{res['voltages']}"] for x, u in zip(lv, used) if u], ".", c="k", label="in the fit")
    for sgn, c in ((1, res["dc"]["intercept_pos_V"]), (-1, res["dc"]["intercept_neg_V"])):
        ii = sgn * np.linspace(max(lo, 1e-3), np.abs(i).max(), 40)
        ax1.plot(ii, R * ii + c + d * np.sign(ii) / ii**2, "k-", lw=0.8)  # the fit over the levels it used
    tail = f", knee tail {d:.3g} V A^2" if d else ""
    ax1.set_title(f"DC test ({res['voltages']} voltages): R_s = {R:.4f} ohm{tail}", fontsize=9)
    ax1.set_xlabel("i_alpha [A]")
    ax1.set_ylabel("u_alpha [V]")
    ax1.legend(fontsize=8)
    ax2.plot(i, [x["e_inv_from_slope"] for x in lv], "s", mfc="none", label="u_ref - R_s i")
    if "e_inv_measured" in lv[0]:
        ax2.plot(i, [x["e_inv_measured"] for x in lv], "o", mfc="none", label="u_ref - u_measured")
    ax2.axhline(0, c="k", lw=0.5)
    ax2.set_title("inverter voltage error (alpha axis)", fontsize=9)
    ax2.set_xlabel("i_alpha [A]")
    ax2.set_ylabel("[V]")
    ax2.legend(fontsize=8)
    return save(fig, png)


def plot_impedance(res: dict[str, Any], png: Path) -> Path:
    """The standstill AC test: the measured impedance per multisine line against the fitted model's."""
    plt = pyplot()

    lines = res["ac"]["lines"]
    f = np.array([x["f_Hz"] for x in lines])
    Z = np.array([complex(x["Z_re"], x["Z_im"]) for x in lines])
    Zf = np.array([complex(x["Z_fit_re"], x["Z_fit_im"]) for x in lines])
    g = res["inverse_gamma"]
    p = InverseGamma(*(g[n]["value"] for n in fits.NAMES))
    ff = np.geomspace(f.min() / 2, f.max() * 2, 200)
    Zc = impedance(p, 2 * np.pi * ff)
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    ax1.loglog(f, np.abs(Z), "o", mfc="none", label=f"measured ({res['voltages']} voltages)")
    ax1.loglog(f, np.abs(Zf), "x", label="fit, as sampled")
    ax1.loglog(ff, np.abs(Zc), "k-", lw=0.8, label="fit, continuous Z(jw)")
    ax1.set_ylabel("|Z| [ohm]")
    ax1.legend(fontsize=8)
    ax1.set_title(f"standstill impedance: R_s {p.R_s:.3f} ohm, L'_s {1e3 * p.L_sigma:.2f} mH, R'_r {p.R_R:.3f} ohm, "
                  f"L'_m {1e3 * p.L_M:.1f} mH", fontsize=9)  # fmt: skip
    ax2.semilogx(f, np.degrees(np.angle(Z)), "o", mfc="none")
    ax2.semilogx(f, np.degrees(np.angle(Zf)), "x")
    ax2.semilogx(ff, np.degrees(np.angle(Zc)), "k-", lw=0.8)
    ax2.set_ylabel("phase [deg]")
    ax2.set_xlabel("frequency [Hz]")
    return save(fig, png)


def plot_magnetising(res: dict[str, Any], png: Path) -> Path:
    plt = pyplot()

    lv = res["magnetising_curve"]["levels"]
    psi = np.array([x["psi_m"] for x in lv])
    i_mu = np.array([x["i_mu"] for x in lv])
    Lm = np.array([x["L_m"]["value"] for x in lv])
    err = np.array([(x["L_m"]["ci95"][1] - x["L_m"]["ci95"][0]) / 2 for x in lv])
    c = res["magnetising_curve"]["curve"]
    cg, cl = np.array(c["psi_m"]), np.array(c["L_m"])
    r = res["L_m_rated"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot(i_mu, psi, "o", mfc="none", label="measured (no load)")
    ax1.plot(cg / cl, cg, "k-", lw=0.8, label="local quadratic fit")
    ax1.set_xlabel("i_mu [A]")
    ax1.set_ylabel("|psi_m| [Wb]")
    ax1.set_title("magnetising curve", fontsize=9)
    ax1.legend(fontsize=8)
    ax2.errorbar(psi, Lm, yerr=err, fmt="o", mfc="none", capsize=3, label="measured, 95 %")
    ax2.plot(cg, cl, "k-", lw=0.8, label="local quadratic fit")
    ax2.errorbar([r["psi_rated_Wb"]], [r["value"]], yerr=[(r["ci95"][1] - r["ci95"][0]) / 2], fmt="s", c="C3",
                 capsize=3, label=f"rated: L_m = {r['value']:.4f} H")  # fmt: skip
    ax2.set_xlabel("|psi_m| [Wb]")
    ax2.set_ylabel("L_m (secant, L_s = L_r) [H]")
    ax2.set_title("mutual inductance over the main flux", fontsize=9)
    ax2.legend(fontsize=8)
    return save(fig, png)


def plot_mechanics(res: dict[str, Any], png: Path) -> Path:
    plt = pyplot()

    s = res["_series"]
    m = res["mechanics"]
    fig, (ax1, ax2, ax3) = plt.subplots(3, 1, figsize=(9, 8))
    ax1.plot(s["t"], s["w_ref"], "k--", lw=0.8, label="reference")
    ax1.plot(s["t"], s["w_mech"], lw=0.8, label="encoder")
    ax1.set_ylabel("omega_mech [rad/s]")
    ax1.legend(fontsize=8)
    ax1.set_title(f"J = {m['J']['value']:.5f} kg m^2, B = {m['B_visc']['value']:.2e} N m s/rad, "
                  f"T_c = {m['m_coulomb']['value']:.4f} N m", fontsize=9)  # fmt: skip
    ax2.plot(s["t"], s["m_e"], lw=0.8, label="m_e (4.6), current model, 30 ms mean")
    ax2.plot(s["t"], s["m_fit"], lw=0.8, label="J dw/dt + B w + T_c sgn w (fit; 30 ms Savitzky-Golay)")
    ax2.set_ylabel("torque [N m]")
    ax2.set_xlabel("t [s]")
    ax2.legend(fontsize=8)
    h = m["holds"]
    w = np.array([x["omega_mech"] for x in h])
    ax3.plot(w, [x["m_e"] for x in h], "o", mfc="none", label="speed holds: mean m_e")
    ww = np.linspace(w.min(), w.max(), 200)
    ax3.plot(ww, m["B_visc"]["value"] * ww + m["m_coulomb"]["value"] * np.sign(ww), "k-", lw=0.8, label="fit")
    ax3.set_xlabel("omega_mech [rad/s]")
    ax3.set_ylabel("friction torque [N m]")
    ax3.legend(fontsize=8)
    return save(fig, png)
