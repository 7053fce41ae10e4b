"""Thesis-style PNG plots of a run log (speed with reference and load, currents, flux).

Figures 5.7/5.8 of the thesis show speed against time with the load torque dashed; this adds the
rotor-flux-frame currents and the magnetising current, and the ground truth where the mock rig
logged it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench.daq.reader import LogReader  # noqa: E402


def plot_run(log_path: str | Path, png_path: str | Path, title: str | None = None) -> Path:
    """Write a 3-panel PNG of the run in ``log_path``; returns the PNG path."""
    r = LogReader(log_path)
    present = [tp for tp in ("/ctrl", "/truth") if tp in r.topics()]
    meas, *rest = r.read_ticks("/rig", *present)
    ref = cmd = meas
    ctrl = rest[present.index("/ctrl")] if "/ctrl" in present else {}
    truth = rest[present.index("/truth")] if "/truth" in present else {}
    t = meas["t"]
    fig, axes = plt.subplots(3, 1, figsize=(10, 8.5), sharex=True, constrained_layout=True)

    ax = axes[0]
    ax.plot(t, ref["omega_r_ref"], "k--", lw=1.0, label=r"$\omega_{r,ref}$")
    if "omega_hat" in ctrl:
        ax.plot(t, ctrl["omega_hat"], color="tab:blue", lw=0.8, label=r"$\hat\omega_r$ (encoder)")
    if "omega_r" in truth:
        ax.plot(t, truth["omega_r"], color="tab:red", lw=1.0, label=r"$\omega_r$ (true)")
    ax.set_ylabel("speed [rad/s, el.]")
    ax2 = ax.twinx()
    ax2.plot(t, cmd["m_l_ref"], color="tab:gray", ls=":", lw=1.0, label=r"$m_{L,ref}$")
    if "m_l" in truth:
        ax2.plot(t, truth["m_l"], color="tab:green", ls="--", lw=0.8, label=r"$m_L$ (true)")
    ax2.set_ylabel("load torque [N m]")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="upper left", fontsize=8, ncol=3)

    ax = axes[1]
    for key, style, label in (("i_sd_ref", "--", r"$i_{sd,ref}$"), ("i_sd", "-", r"$i_{sd}$"),
                              ("i_sq_ref", "--", r"$i_{sq,ref}$"), ("i_sq", "-", r"$i_{sq}$")):  # fmt: skip
        if key in ctrl:
            ax.plot(t, ctrl[key], style, lw=0.8, label=label)
    ax.set_ylabel("current [A]")
    ax.legend(loc="upper left", fontsize=8, ncol=4)

    ax = axes[2]
    ax.plot(t, ref["i_mr_ref"], "k--", lw=1.0, label=r"$i_{mR,ref}$")
    if "i_mr_hat" in ctrl:
        ax.plot(t, ctrl["i_mr_hat"], color="tab:blue", lw=0.8, label=r"$\hat i_{mR}$")
    if "i_m_re" in truth:
        ax.plot(t, np.hypot(truth["i_m_re"], truth["i_m_im"]), color="tab:red", lw=0.8, label=r"$|i_m|$ (true)")
    ax.set_ylabel("magnetising current [A]")
    ax.set_xlabel("time [s]")
    ax.legend(loc="lower right", fontsize=8, ncol=3)
    if title:
        fig.suptitle(title)
    png_path = Path(png_path)
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return png_path
