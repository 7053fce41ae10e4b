"""`bench sweep report DIR`: plots and a markdown summary of a sweep's ``results.parquet``.

Written into DIR (and nowhere else):

* ``errors.png``: distributions of the estimation and tracking errors, one box per group (the
  flux observer where the sweep sets one; else the variant labels, else the controller);
* ``trips.png``: trip probability against each mismatch the sweep varies, with 95 % Wilson
  intervals, one line per group;
* ``heatmap.png``: trip probability and median flux-angle error over the first two varied inputs;
* ``report.md``: counts, per-group quantiles and trip probabilities, the errors, the pictures.

Grid values are used as they are; continuous (random / Latin-hypercube) inputs are binned into
`BINS` quantile bins.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from bench.errors import BadInput
from bench.workflows.sweep import table
from bench.core.plotstyle import pyplot
from bench.workflows.sweep.tasks import TASKS

BINS = 6
Z95 = 1.959964  # two-sided 95 % normal quantile
METRICS = (  # column, label, unit scale
    ("est_flux_angle_rms_deg", "flux-angle error RMS [deg]", 1.0),
    ("est_flux_mag_rms_rel", "flux-magnitude error RMS [% of |i_m|]", 100.0),
    ("est_speed_rms", "speed-estimate error RMS [rad/s, electrical]", 1.0),
    ("speed_error_settled_rms", "settled speed-tracking error RMS [rad/s, electrical]", 1.0),
    ("load_dip_max", "load-step speed dip [rad/s, electrical]", 1.0),
)


def _horizontal() -> dict[str, Any]:
    import matplotlib

    major, minor = (int(x) for x in matplotlib.__version__.split(".")[:2])
    return {"orientation": "horizontal"} if (major, minor) >= (3, 10) else {"vert": False}


_HORIZONTAL = _horizontal()


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float, float]:
    """Trip probability k/n with its Wilson score interval (lo, p, hi); NaNs for n = 0."""
    if n == 0:
        return math.nan, math.nan, math.nan
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    # at k = 0 (k = n) the bound is exactly 0 (1); c - h would leave a rounding residue like 2e-19
    return (0.0 if k == 0 else max(0.0, c - h)), p, (1.0 if k == n else min(1.0, c + h))


def _group_key(rows: list[dict[str, Any]]) -> tuple[str, list[str]]:
    """The column(s) the report groups by, and each row's group name."""
    labels = sorted(k for k in rows[0] if k.startswith("label."))
    if "params.observer" in rows[0]:
        cols = ["params.observer", *labels]
    elif labels:
        cols = labels
    else:
        cols = ["controller"]
    return " / ".join(c.split(".", 1)[-1] for c in cols), [" / ".join(str(r.get(c)) for c in cols) for r in rows]


def _varied(rows: list[dict[str, Any]]) -> list[str]:
    """Numeric input columns (plant.*, params.*, task.*) that take more than one value."""
    out = []
    for c in rows[0]:
        if not c.startswith(("plant.", "params.", "task.")):
            continue
        vals = [r.get(c) for r in rows]
        if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals) and len(set(vals)) > 1:
            out.append(c)
    return out


def _bins(x: np.ndarray) -> tuple[np.ndarray, list[float]]:
    """Bin index per value and the bin centres: unique values of a grid, else quantile bins."""
    u = np.unique(x)
    if u.size <= BINS * 2:
        return np.searchsorted(u, x), [float(v) for v in u]
    edges = np.quantile(x, np.linspace(0, 1, BINS + 1))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, BINS - 1)
    return idx, [float(x[idx == i].mean()) if np.any(idx == i) else math.nan for i in range(BINS)]


def _num(rows: list[dict[str, Any]], col: str) -> np.ndarray:
    return np.array([r.get(col) if isinstance(r.get(col), (int, float)) else math.nan for r in rows], dtype=float)


def _q(x: np.ndarray, q: float) -> float:
    x = x[np.isfinite(x)]
    return float(np.quantile(x, q)) if x.size else math.nan


def _fmt(x: float, nd: int = 3) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:.{nd}g}"


def report(out: Path) -> list[Path]:
    """Write the plots and ``report.md`` into ``out``; returns the files written."""
    path = out / table.RESULTS
    if not path.is_file():
        raise BadInput("DIR", f"{out} holds no {table.RESULTS} (run bench sweep SPEC --out {out} first)")
    rows = table.read(path)
    if not rows:
        raise BadInput("DIR", f"{path} has no rows")
    if rows[0].get("task"):
        return _task_report(out, rows)
    plt = pyplot()
    gname, groups = _group_key(rows)
    names = list(dict.fromkeys(groups))
    garr = np.array(groups, dtype=object)
    status = np.array([r["status"] for r in rows], dtype=object)
    varied = _varied(rows)
    written: list[Path] = []
    figures = (
        (out / "errors.png", _errors_figure(plt, rows, gname, names, garr, status)),
        (out / "trips.png", _trips_figure(plt, rows, gname, names, garr, status, varied) if varied else None),
        (out / "heatmap.png", _heatmap_figure(plt, rows, status, varied) if len(varied) >= 2 else None),
    )
    for png, fig in figures:
        if fig is not None:
            fig.tight_layout()
            fig.savefig(png, dpi=110)
            plt.close(fig)
            written.append(png)
    md = out / "report.md"
    md.write_text(_markdown(rows, gname, groups, names, varied, [p.name for p in written]), encoding="utf-8")
    return [*written, md]


def _errors_figure(plt: Any, rows: list[dict[str, Any]], gname: str, names: list[str], garr: np.ndarray,
                   status: np.ndarray) -> Any:  # fmt: skip
    """The error distributions per group, of the cases that ran and did not trip (None: no error was logged)."""
    mets = [(c, lab, s) for c, lab, s in METRICS if np.isfinite(_num(rows, c)).any()]
    if not mets:
        return None
    fig, axes = plt.subplots(1, len(mets), figsize=(min(3.2 * len(mets) + 1, 16), 4.2 + 0.1 * len(names)),
                             squeeze=False)  # fmt: skip
    for ax, (c, lab, s) in zip(axes[0], mets):
        x = _num(rows, c) * s
        data = [x[(garr == g) & (status == "ok") & np.isfinite(x)] for g in names]
        ax.boxplot([d if d.size else [math.nan] for d in data], **_HORIZONTAL)
        ax.set_yticks(range(1, len(names) + 1), names if ax is axes[0][0] else [""] * len(names), fontsize=8)
        ax.set_xlabel(lab, fontsize=8)
        if np.nanmin(x) > 0 and np.nanmax(x) / max(np.nanmin(x), 1e-12) > 100:
            ax.set_xscale("log")
        ax.grid(alpha=0.3)
    fig.suptitle(f"{rows[0].get('controller')}: error distributions per {gname} (cases that did not trip)")
    return fig


def _trips_figure(plt: Any, rows: list[dict[str, Any]], gname: str, names: list[str], garr: np.ndarray,
                  status: np.ndarray, varied: list[str]) -> Any:  # fmt: skip
    """The trip probability (Wilson 95 % intervals) against each varied input, a line per group."""
    ran, tripped = status != "error", status == "tripped"
    fig, axes = plt.subplots(1, len(varied), figsize=(min(4.2 * len(varied) + 1, 16), 4.0), squeeze=False)
    for ax, c in zip(axes[0], varied):
        x = _num(rows, c)
        idx, centres = _bins(x)
        for g in names:
            sel = (garr == g) & ran
            lo, p, hi = np.array([wilson(int(np.sum(tripped & sel & (idx == i))), int(np.sum(sel & (idx == i))))
                                  for i in range(len(centres))]).T  # fmt: skip
            line = ax.plot(centres, p, "o-", label=g, ms=4)[0]
            ax.fill_between(centres, lo, hi, color=line.get_color(), alpha=0.15)
        ax.set_xlabel(c)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("trip probability (95 % CI)")
    axes[0][-1].legend(fontsize=7, title=gname, title_fontsize=7)
    fig.suptitle("trip probability against each varied input")
    return fig


def _heatmap_figure(plt: Any, rows: list[dict[str, Any]], status: np.ndarray, varied: list[str]) -> Any:
    """The trip probability and the median flux-angle error over the first two varied inputs (all groups)."""
    ran, tripped = status != "error", status == "tripped"
    cx, cy = varied[:2]
    ix, xs = _bins(_num(rows, cx))
    iy, ys = _bins(_num(rows, cy))
    ang = _num(rows, "est_flux_angle_rms_deg")
    P = np.full((len(ys), len(xs)), np.nan)
    E = np.full_like(P, np.nan)
    for i in range(len(ys)):
        for j in range(len(xs)):
            sel = (iy == i) & (ix == j) & ran
            if sel.any():
                P[i, j] = tripped[sel].mean()
                E[i, j] = _q(ang[sel & ~tripped], 0.5)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    # fixed colour scales from 0: a probability is in [0, 1] (no trips at all is white, not an autoscaled
    # -0.1..0.1 whose middle is red), an error starts at none
    e_max = float(np.nanmax(E)) if np.isfinite(E).any() else 1.0
    for ax, Z, lab, cmap, top in ((axes[0], P, "trip probability", "Reds", 1.0),
                                  (axes[1], E, "median flux-angle error RMS [deg]", "viridis",
                                   max(e_max, 1e-9))):  # fmt: skip
        im = ax.imshow(Z, origin="lower", aspect="auto", cmap=cmap, vmin=0.0, vmax=top)
        if Z is P and P.size <= 100:  # the numbers, readable where every cell has the same colour
            for (i, j), v in np.ndenumerate(P):
                if np.isfinite(v):
                    ax.text(j, i, f"{v:.2f}", ha="center", va="center", fontsize=7,
                            color="white" if v > 0.6 else "black")  # fmt: skip
        ax.set_xticks(range(len(xs)), [f"{v:.3g}" for v in xs], fontsize=8)
        ax.set_yticks(range(len(ys)), [f"{v:.3g}" for v in ys], fontsize=8)
        ax.set_xlabel(cx)
        ax.set_ylabel(cy)
        fig.colorbar(im, ax=ax, label=lab)
    fig.suptitle(f"over {cx} and {cy} (all groups)")
    return fig


def _task_report(out: Path, rows: list[dict[str, Any]]) -> list[Path]:
    """A computation sweep (`bench.workflows.sweep.tasks`): the task's own plot and a table of every case."""
    task = TASKS[rows[0]["task"]]
    written = task.plot(rows, out) if task.plot else []
    rows = sorted(rows, key=lambda r: r["index"])
    cols = [c for c in rows[0] if c.startswith("label.")] + _varied(rows)
    outs = [c for c in dict.fromkeys(k for r in rows for k in r) if c.startswith("out.")
            and all(isinstance(r.get(c), (int, float, type(None))) for r in rows)]  # fmt: skip
    status = [r["status"] for r in rows]
    lines = [f"# Sweep report: {len(rows)} cases of task `{task.name}`", "", f"{task.summary}.", "",
             f"ok {status.count('ok')}, error {status.count('error')}; wall time per case "
             f"p50 {_fmt(_q(_num(rows, 'case_wall_time'), .5))} s.", "",
             "| " + " | ".join([*cols, *outs, "status", "wall [s]"]) + " |",
             "|" + "---|" * (len(cols) + len(outs) + 2)]  # fmt: skip
    for r in rows:
        cells = [str(r.get(c)) if not isinstance(r.get(c), float) else _fmt(r[c], 4) for c in (*cols, *outs)]
        lines.append("| " + " | ".join([*cells, r["status"], _fmt(r["case_wall_time"], 3)]) + " |")
    errs = [r for r in rows if r["status"] == "error"]
    if errs:
        lines += ["", f"## Cases that raised ({len(errs)})", ""]
        lines += [f"- `{r['case_id']}`: {r.get('error')}" for r in errs[:20]]
    lines += ["", *[f"![{p.name}]({p.name})" for p in written]]
    md = out / "report.md"
    md.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return [*written, md]


def _markdown(rows: list[dict[str, Any]], gname: str, groups: list[str], names: list[str], varied: list[str],
              pictures: list[str]) -> str:  # fmt: skip
    status = [r["status"] for r in rows]
    lines = [f"# Sweep report: {len(rows)} cases", "",
             f"ok {status.count('ok')}, tripped {status.count('tripped')}, error {status.count('error')}; "
             f"controller {rows[0].get('controller')}, scenarios {', '.join(sorted({r['scenario'] for r in rows}))}. "
             "Errors are over the cases that did not trip; trip probabilities with 95 % Wilson intervals over the "
             "cases that ran.", "",
             f"| {gname} | cases | trip probability [95 % CI] | flux angle RMS p50 / p90 / max [deg] "
             "| flux magnitude RMS p50 / p90 [%] | speed estimate RMS p50 / p90 [rad/s] "
             "| speed tracking RMS p50 [rad/s] | load dip p50 [rad/s] |",
             "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for g in names:
        sel = [r for r, gg in zip(rows, groups) if gg == g and r["status"] != "error"]
        ok = [r for r in sel if r["status"] == "ok"]
        k = sum(r["status"] == "tripped" for r in sel)
        lo, p, hi = wilson(k, len(sel))
        a, m = _num(ok, "est_flux_angle_rms_deg"), 100 * _num(ok, "est_flux_mag_rms_rel")
        w, t, d = _num(ok, "est_speed_rms"), _num(ok, "speed_error_settled_rms"), _num(ok, "load_dip_max")
        lines.append(f"| {g} | {len(sel)} | {_fmt(p, 2)} [{_fmt(lo, 2)}, {_fmt(hi, 2)}] "
                     f"| {_fmt(_q(a, .5))} / {_fmt(_q(a, .9))} / {_fmt(_q(a, 1))} | {_fmt(_q(m, .5))} / {_fmt(_q(m, .9))} "
                     f"| {_fmt(_q(w, .5))} / {_fmt(_q(w, .9))} | {_fmt(_q(t, .5))} | {_fmt(_q(d, .5))} |")  # fmt: skip
    lines.append("")
    causes: dict[str, int] = {}
    for r in rows:
        if r["status"] == "tripped":
            c = str(r.get("trip_cause")).split(":")[0]
            causes[c] = causes.get(c, 0) + 1
    if causes:
        lines += ["Trip causes: " + ", ".join(f"{c} ({n})" for c, n in sorted(causes.items(), key=lambda x: -x[1])), ""]
    if varied:
        lines += [f"Varied inputs: {', '.join(f'`{c}`' for c in varied)}.", ""]
    errs = [r for r in rows if r["status"] == "error"]
    if errs:
        lines += [f"## Cases that raised ({len(errs)})", ""]
        lines += [f"- `{r['case_id']}` ({r['scenario']}, seed {r['seed']}): {r.get('error')}" for r in errs[:20]]
        lines.append("")
    lines += [f"![{p}]({p})" for p in pictures]
    return "\n".join(lines) + "\n"
