"""Thesis-style PNG plots of a run log (speed with reference and load, currents, flux).

Figures 5.7/5.8 of the thesis show speed against time with the load torque; the load gets a panel
of its own here (fast load steps drawn over the speed hid it), then the rotor-flux-frame currents
and the magnetising current, with the ground truth where the mock rig logged it. The title comes
from the log's metadata, so `bench plot` of any log says what ran.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench.daq.reader import LogReader  # noqa: E402
from bench.plotstyle import DPI, speed_label  # noqa: E402


def style_axes(ax, ylabel: str) -> None:  # noqa: ANN001
    """The run plots' look: grid, label, a legend beside the axes (never over the data)."""
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.4, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, frameon=False)


def describe_run(meta: dict) -> str:
    """Title from the log's metadata: scenario, controller with the parts that ran (and their artifacts),
    the parameters that differ from the plugin's defaults, rig, seed."""
    from bench.controllers import changed_params

    run, rig = meta.get("run", {}), meta.get("rig", {})
    p = run.get("controller_params") or {}
    changed = changed_params(str(run.get("controller", "")), p)
    shown = {"observer", "current_controller", "speed_controller", "speed_source", "speed_estimator"}
    parts = []
    if run.get("controller") == "foc" or "observer" in p:

        def part(label: str, key: str, default: str, artifact: str) -> str:
            text = f"{label} {p.get(key, default)}"
            if p.get(key) == "lpv" and artifact in changed:  # which design: the shipped one or the user's
                shown.add(artifact)
                text += f" [{changed[artifact]}]"
            return text

        parts.append(part("observer", "observer", "?", "lpv_artifact"))
        parts.append(part("current", "current_controller", "pi", "lpv_current_artifact"))
        parts.append(part("speed", "speed_controller", "pi", "lpv_speed_artifact"))
        if p.get("speed_source") == "estimate":
            parts.append(f"sensorless ({p.get('speed_estimator', '?')})")
    ctrl = f"{run.get('controller', '?')}" + (f" ({', '.join(parts)})" if parts else "")
    name = (rig.get("rig") or {}).get("name", rig.get("name", "?")) if isinstance(rig, dict) else "?"
    first = run.get("description") or run.get("scenario") or ""
    rest = [f"{k}={v}" for k, v in changed.items() if k not in shown]
    extra = f"\nparameters: {', '.join(rest)}" if rest else ""
    return f"{first}\ncontroller {ctrl}; rig {name}; seed {run.get('seed', '?')}{extra}"


def plot_run(log_path: str | Path, png_path: str | Path, title: str | None = None) -> Path:
    """Write a 4-panel PNG of the run in ``log_path`` (speed, load, currents, flux); returns the PNG path.

    ``title``: default from the log's metadata (`describe_run`). A trip is marked in every panel.
    """
    r = LogReader(log_path)
    present = [tp for tp in ("/ctrl", "/truth") if tp in r.topics()]
    meas, *rest = r.read_ticks("/rig", *present)
    ref = cmd = meas
    ctrl = rest[present.index("/ctrl")] if "/ctrl" in present else {}
    truth = rest[present.index("/truth")] if "/truth" in present else {}
    meta = r.metadata()
    p = (meta.get("run") or {}).get("controller_params") or {}
    sensorless = p.get("speed_source") == "estimate"
    t = meas["t"]
    fig, axes = plt.subplots(4, 1, figsize=(11, 10), sharex=True, constrained_layout=True,
                             gridspec_kw={"height_ratios": [3, 1.2, 2.2, 1.6]})  # fmt: skip

    ax = axes[0]
    ax.plot(t, ref["omega_r_ref"], "k--", lw=1.0, label=r"$\omega_{r,ref}$")
    if "omega_hat" in ctrl:
        src = f"estimate, {p.get('speed_estimator', '?')}" if sensorless else "encoder"
        ax.plot(t, ctrl["omega_hat"], color="tab:blue", lw=0.8, label=rf"$\hat\omega_r$ ({src})")
    if "omega_r" in truth:
        ax.plot(t, truth["omega_r"], color="tab:red", lw=1.0, label=r"$\omega_r$ (true)")
    style_axes(ax, speed_label())

    ax = axes[1]
    ax.plot(t, cmd["m_l_ref"], color="tab:gray", lw=0.8, label=r"$m_{L,ref}$")
    if "m_l" in truth:
        ax.plot(t, truth["m_l"], color="tab:green", lw=0.8, label=r"$m_L$ (true)")
    style_axes(ax, "load torque [N m]")

    ax = axes[2]
    for key, style, label in (("i_sd_ref", "--", r"$i_{sd,ref}$"), ("i_sd", "-", r"$i_{sd}$"),
                              ("i_sq_ref", "--", r"$i_{sq,ref}$"), ("i_sq", "-", r"$i_{sq}$")):  # fmt: skip
        if key in ctrl:
            ax.plot(t, ctrl[key], style, lw=0.8, label=label)
    style_axes(ax, "current [A]")

    ax = axes[3]
    ax.plot(t, ref["i_mr_ref"], "k--", lw=1.0, label=r"$i_{mR,ref}$")
    if "i_mr_hat" in ctrl:
        ax.plot(t, ctrl["i_mr_hat"], color="tab:blue", lw=0.8, label=r"$\hat i_{mR}$")
    if "i_m_re" in truth:
        ax.plot(t, np.hypot(truth["i_m_re"], truth["i_m_im"]), color="tab:red", lw=0.8, label=r"$|i_m|$ (true)")
    style_axes(ax, "magnetising current [A]")
    ax.set_xlabel("time [s]")

    tripped = np.flatnonzero(meas["tripped"].astype(bool))
    if tripped.size:
        cause = (meta.get("shutdown") or {}).get("cause") or "trip"
        for i, a in enumerate(axes):
            a.axvline(t[tripped[0]], color="tab:red", lw=1.0, ls=":", label=None)
        axes[0].set_title(f"tripped at t = {t[tripped[0]]:.4f} s: {cause}", fontsize=9, color="tab:red", loc="left")
    fig.suptitle(title if title is not None else describe_run(meta), fontsize=10)
    png_path = Path(png_path)
    fig.savefig(png_path, dpi=DPI)
    plt.close(fig)
    return png_path
