"""Thesis-style PNG plots of a run log (speed with reference and load, currents, flux).

Figures 5.7/5.8 of the thesis show speed against time with the load torque; the load gets a panel
of its own here (fast load steps drawn over the speed hid it), then the rotor-flux-frame currents
and the magnetising current, with the ground truth where the mock rig logged it; a run with the on-line
R_r estimate (``rr_adapt``) gets a fifth panel, the estimate against the true R_r. The title comes
from the log's metadata, so `bench plot` of any log says what ran; it is wrapped to the figure's width.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from bench.daq.reader import LogReader, internals_topic  # noqa: E402
from bench.core.plotstyle import DPI, speed_label  # noqa: E402
from bench.controllers import changed_params  # noqa: E402
from bench.operate.requests import switch_names  # noqa: E402


def fit_title(text: str, width_in: float, fontsize: float = 10.0) -> str:
    """``text`` with every line wrapped to fit a figure ``width_in`` inches wide at ``fontsize`` points
    (an average glyph of DejaVu Sans is about 0.6 em; a margin of a few characters either side)."""
    chars = max(int(width_in * 72.0 / (0.6 * fontsize)) - 6, 20)
    return "\n".join(textwrap.fill(line, chars, break_on_hyphens=False) or line for line in text.split("\n"))


def true_rr(meta: dict, truth: dict) -> tuple[np.ndarray | float | None, str]:
    """The simulated machine's R_r for the estimate's panel, and where it came from: /truth ``r_r`` (the
    mock's thermal model on), else the rig's ``[mock.motor] R_r`` (the true machine), else ``[motor] R_r``
    (the mock simulates the nominal machine). None on a real rig (no /truth)."""
    if "r_r" in truth:
        return truth["r_r"], "true, thermal model"
    if not truth:
        return None, ""
    rig = meta.get("rig") or {}
    hidden = ((rig.get("mock") or {}).get("motor") or {}).get("R_r")
    if hidden is not None:
        return float(hidden), "true, [mock.motor]"
    nominal = (rig.get("motor") or {}).get("R_r")
    return (float(nominal), "true, [motor]") if nominal is not None else (None, "")


def style_axes(ax, ylabel: str) -> None:  # noqa: ANN001
    """The run plots' look: grid, label, a legend beside the axes (never over the data)."""
    ax.set_ylabel(ylabel)
    ax.grid(True, lw=0.4, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, frameon=False)


def describe_run(meta: dict) -> str:
    """Title from the log's metadata: scenario, controller with the parts that ran (and their artifacts),
    the parameters that differ from the plugin's defaults, rig, seed."""
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


# what each kind of request looks like on the plots (parameter changes, overrides, operator actions)
MARK_STYLE = {"set": ("tab:purple", "-."), "switch": ("tab:green", "-"), "override": ("tab:orange", "-."), "mark": ("tab:olive", ":"),
              "stop": ("black", "--"), "estop": ("tab:red", "--")}  # fmt: skip
MAX_MARK_LABELS = 30  # more than this many requests: lines only (a long tuning session)


def event_marks(events: list[dict]) -> list[tuple[float, str, str]]:
    """(loop time, label, kind) of each applied request of /params and /events (`LogReader.events`): a
    parameter change ``speed_Kp 0.6 -> 0.8``, a part switched (``speed_controller pi -> lpv``), an override, a mark's note, a stop, an e-stop. Refused
    requests changed nothing and are left out."""
    out = []
    for e in events:
        if e.get("status") != "applied":
            continue
        kind = e.get("kind", "set")
        if kind == "set":
            name = str(e.get("name", "?"))
            kind = "override" if name.endswith("_override") else "switch" if name in switch_names() else "set"
            label = f"{name} {e.get('old_text', e.get('old'))} -> {e.get('new_text', e.get('new'))}"
        elif kind == "mark":
            note = str(e.get("note", ""))
            label = "mark: " + (note if len(note) <= 40 else note[:39] + "\u2026")
        else:
            label = {"stop": "operator stop", "estop": "operator E-STOP"}.get(kind, kind)
        # a client's text is drawn as text: no mathtext ($), one line
        out.append((float(e["t"]), " ".join(label.split()).replace("$", r"\$"), kind))
    return out


def _draw_marks(axes, marks: list[tuple[float, str, str]]) -> None:  # noqa: ANN001
    """A vertical line per request in every panel; its label along the line at the top of the first panel."""
    for t_ev, label, kind in marks:
        colour, style = MARK_STYLE.get(kind, ("tab:gray", ":"))
        for a in axes:
            a.axvline(t_ev, color=colour, lw=0.9, ls=style, alpha=0.8)
        if len(marks) <= MAX_MARK_LABELS:
            axes[0].annotate(label, xy=(t_ev, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -3),
                             textcoords="offset points", rotation=90, va="top", ha="left", fontsize=7,
                             color=colour, clip_on=True, bbox={"fc": "white", "ec": "none", "alpha": 0.75, "pad": 0.5})  # fmt: skip


def plot_run(log_path: str | Path, png_path: str | Path, title: str | None = None) -> Path:
    """Write a 4-panel PNG of the run in ``log_path`` (speed, load, currents, flux); returns the PNG path.

    ``title``: default from the log's metadata (`describe_run`). A trip is marked in every panel, and so is
    every applied parameter change, override and operator action of /params and /events (`event_marks`).
    """
    fig = run_figure(log_path, title)
    png_path = Path(png_path)
    fig.savefig(png_path, dpi=DPI)
    plt.close(fig)
    return png_path


def _current_panel(ax: Any, t: np.ndarray, ctrl: dict[str, np.ndarray], meas: dict[str, np.ndarray]) -> None:
    """The field-frame currents and their references; for a plugin without them, the measured |i_s|."""
    for key, style, label in (("i_sd_ref", "--", r"$i_{sd,ref}$"), ("i_sd", "-", r"$i_{sd}$"),
                              ("i_sq_ref", "--", r"$i_{sq,ref}$"), ("i_sq", "-", r"$i_{sq}$")):  # fmt: skip
        if key in ctrl:
            ax.plot(t, ctrl[key], style, lw=0.8, label=label)
    if not ax.lines and all(k in meas for k in ("i_a", "i_b", "i_c")):  # a plugin without FOC's fields
        # the measured stator current's space-vector length, amplitude-invariant: sqrt(2/3 (i_a^2+i_b^2+i_c^2))
        i_s = np.sqrt(2.0 / 3.0 * (meas["i_a"] ** 2 + meas["i_b"] ** 2 + meas["i_c"] ** 2))
        ax.plot(t, i_s, color="tab:blue", lw=0.8, label=r"$|i_s|$ (measured)")
    style_axes(ax, "current [A]")


def _rr_panel(ax: Any, t: np.ndarray, ctrl: dict[str, np.ndarray], truth: dict[str, np.ndarray],
              meta: dict[str, Any]) -> None:  # fmt: skip
    """The on-line R_r estimate against the rig file's nominal R_r and the truth (the mock's, or the log's)."""
    nominal = ((meta.get("rig") or {}).get("motor") or {}).get("R_r")
    if nominal is not None:
        ax.axhline(float(nominal), color="tab:gray", ls=":", lw=1.0, label=r"$R_r$ nominal ([motor])")
    ax.plot(t, ctrl["rr_hat"], color="tab:blue", lw=0.9, label=r"$\hat R_r$ (on-line estimate)")
    true, src = true_rr(meta, truth)
    if isinstance(true, np.ndarray):
        ax.plot(t, true, color="tab:red", lw=1.0, label=rf"$R_r$ ({src})")
    elif true is not None:
        ax.axhline(true, color="tab:red", lw=1.0, label=rf"$R_r$ ({src})")
    style_axes(ax, r"rotor resistance [$\Omega$]")


def run_figure(log_path: str | Path, title: str | None = None):  # noqa: ANN201 - a matplotlib Figure
    """The figure of `plot_run`, not yet saved (its axes: speed, load, current, magnetising current, and with
    the on-line R_r estimate in /ctrl, R_r)."""
    r = LogReader(log_path)
    ctrl_topic = internals_topic(r.topics())
    present = [tp for tp in (ctrl_topic, "/truth") if tp in r.topics()]
    meas, *rest = r.read_ticks("/rig", *present)
    ref = cmd = meas
    ctrl = rest[present.index(ctrl_topic)] if ctrl_topic in present else {}
    truth = rest[present.index("/truth")] if "/truth" in present else {}
    meta = r.metadata()
    p = (meta.get("run") or {}).get("controller_params") or {}
    sensorless = p.get("speed_source") == "estimate"
    t = meas["t"]
    rr = "rr_hat" in ctrl  # the on-line R_r estimate ran (rr_adapt)
    ratios = [3, 1.2, 2.2, 1.6] + [1.6] * rr
    fig, axes = plt.subplots(len(ratios), 1, figsize=(11, 10 + 1.8 * rr), sharex=True, constrained_layout=True,
                             gridspec_kw={"height_ratios": ratios})  # fmt: skip

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

    _current_panel(axes[2], t, ctrl, meas)

    ax = axes[3]
    ax.plot(t, ref["i_mr_ref"], "k--", lw=1.0, label=r"$i_{mR,ref}$")
    if "fw" in ctrl and np.any(ctrl["fw"] < 1.0):  # the field weakening lowered it at the voltage limit
        ax.plot(t, ref["i_mr_ref"] * ctrl["fw"], color="tab:purple", ls="--", lw=0.9,
                label=r"$i_{mR,ref}$ field-weakened")  # fmt: skip
    if "i_mr_hat" in ctrl:
        ax.plot(t, ctrl["i_mr_hat"], color="tab:blue", lw=0.8, label=r"$\hat i_{mR}$")
    if "i_m_re" in truth:
        ax.plot(t, np.hypot(truth["i_m_re"], truth["i_m_im"]), color="tab:red", lw=0.8, label=r"$|i_m|$ (true)")
    style_axes(ax, "magnetising current [A]")

    if rr:
        _rr_panel(axes[4], t, ctrl, truth, meta)
    axes[-1].set_xlabel("time [s]")

    try:
        marks = event_marks(r.events())
    except Exception:  # noqa: BLE001 - a torn /params or /events: the plot without the marks
        marks = []
    _draw_marks(axes, marks)

    tripped = np.flatnonzero(meas["tripped"].astype(bool))
    if tripped.size:
        cause = (meta.get("shutdown") or {}).get("cause") or "trip"
        for i, a in enumerate(axes):
            a.axvline(t[tripped[0]], color="tab:red", lw=1.0, ls=":", label=None)
        axes[0].set_title(f"tripped at t = {t[tripped[0]]:.4f} s: {cause}", fontsize=9, color="tab:red", loc="left")
    fig.suptitle(fit_title(title if title is not None else describe_run(meta), fig.get_figwidth()), fontsize=10)
    return fig
