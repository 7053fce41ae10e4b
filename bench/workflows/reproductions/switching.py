"""``bench reproduce switching``: the jump each part switch makes, with and without the hand-over.

Every switchable pair of the FOC (`bench.controllers.foc.SWITCHABLE`) is switched there and back on two operating
points, as a scenario's schedule would: scenario ``hold`` (the rated point, 297 rad/s and 10 N m) and Fig. 5.7's
load cycle (10 rad/s, 0 <-> 3 N m every 1/3 s; switched 0.13 s into a plateau), each once with the hand-over
(``handover = bumpless``) and once without (``cold``: the incoming part from its reset state). The numbers are
`bench.runtime.metrics.switch_transients` from the summary: the voltage-reference jump (in the rotating field) and the
true torque transient, against the limits 2 % of the rated voltage (380 V: 310 V phase amplitude) and 5 % of the rated
torque (10 N m). Writes ``switching.png`` (bars, log scale) and the table as JSON.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from bench.core import scenarios
from bench.workflows.reproduce import register
from bench.workflows.reproductions.common import pyplot, save_figure
from bench.runtime.session import RunOptions, run

U_LIMIT = 0.02 * 380.0 * (2.0 / 3.0) ** 0.5  # [V] 2 % of the rated phase-voltage amplitude
M_LIMIT = 0.05 * 10.0  # [N m] 5 % of the rated torque
# (part, there, back, extra parameters): every part, every choice, from the defaults and back
PAIRS: tuple[tuple[str, str, str, dict[str, Any]], ...] = (
    ("speed_controller", "lpv", "pi", {}),
    ("current_controller", "lpv", "pi", {}),
    ("observer", "lpv", "current_model", {}),
    ("observer", "jl", "current_model", {}),
    ("observer", "kubota", "current_model", {}),
    ("observer", "voltage_model", "current_model", {}),
    ("speed_source", "estimate", "encoder", {"speed_estimator": "rotor_equation"}),
)
# (scenario, switch there, switch back, duration): the later span (0.5 s on) must stay inside the run
POINTS = {"hold": ("hold", 1.5, 2.3, 3.1), "fig5.7": ("fig5.7", 1.2, 1.9, 2.7)}


def measure(point: str, part: str, there: str, back: str, params: dict[str, Any], handover: str) -> list[dict]:
    """`switch_transients` of one run that switches ``part`` to ``there`` and back."""
    name, t1, t2, duration = POINTS[point]
    scn = dataclasses.replace(scenarios.get(name), switches=((t1, part, there), (t2, part, back)))
    summary, _ = run(RunOptions(scenario=scn, duration=duration, params={**params, "handover": handover},
                                log_enabled=False, progress=False))  # fmt: skip
    rows = summary.get("switches", [])
    for r in rows:
        r["trip_cause"] = summary.get("trip_cause")
    return rows


def table() -> list[dict[str, Any]]:
    out = []
    for point in POINTS:
        for part, there, back, params in PAIRS:
            for handover in ("bumpless", "cold"):
                for r in measure(point, part, there, back, params, handover):
                    out.append({"point": point, "handover": handover, **r})
    return out


@register("switching", "parts switched while running: voltage jump and torque transient of every pair, with and "
                       "without the hand-over, at the rated point and in Fig. 5.7's load cycle")
def switching(out_dir: Path) -> dict[str, Any]:
    rows = table()
    plt = pyplot()
    fig, axs = plt.subplots(2, 2, figsize=(14, 9), sharey="row")

    def label(r: dict) -> str:
        short = {"speed_controller": "speed", "current_controller": "current", "observer": "obs.",
                 "speed_source": "speed from", "current_model": "CM", "voltage_model": "VM"}  # fmt: skip
        return f"{short.get(r['part'], r['part'])} {short.get(r['from'], r['from'])} → {short.get(r['to'], r['to'])}"

    for r in rows:
        r["label"] = label(r)
    for j, point in enumerate(POINTS):
        sel = [r for r in rows if r["point"] == point]
        labels = list(dict.fromkeys(r["label"] for r in sel if r["handover"] == "bumpless"))
        x = np.arange(len(labels))
        for i, (key, limit, unit) in enumerate((("u_jump", U_LIMIT, "V"), ("torque_transient", M_LIMIT, "N m"))):
            ax = axs[i][j]
            for k, (handover, colour) in enumerate((("bumpless", "tab:green"), ("cold", "tab:red"))):
                v = [next((r[key] for r in sel if r["handover"] == handover and r["label"] == lab), np.nan)
                     for lab in labels]  # fmt: skip
                ax.bar(x + (k - 0.5) * 0.38, [np.nan if a is None else a for a in v], 0.38, color=colour,
                       label=f"{handover} hand-over")  # fmt: skip
            if point == "hold":  # (in the load cycle the later span holds load steps: no steady reference)
                own = [next((r["u_step_later" if key == "u_jump" else "torque_later"] for r in sel if
                             r["handover"] == "bumpless" and r["label"] == lab), np.nan) for lab in labels]  # fmt: skip
                ax.plot(x - 0.19, [np.nan if a is None else a for a in own], "k_", ms=14, mew=2,
                        label="the incoming part's own, settled")  # fmt: skip
            ax.axhline(limit, color="k", ls="--", lw=0.9, label=f"limit {limit:.3g} {unit}")
            ax.set_yscale("log")
            ax.set_xticks(x, labels, fontsize=7.5, rotation=55, ha="right")
            ax.grid(alpha=0.3, axis="y")
            if j == 0:
                ax.set_ylabel("voltage-reference jump [V]" if key == "u_jump" else "true torque transient [N m]")
            if i == 0:
                ax.set_title({"hold": "rated point (297 rad/s, 10 N m)", "fig5.7": "Fig. 5.7's load cycle"}[point],
                             fontsize=10)  # fmt: skip
    axs[0][0].legend(fontsize=7, loc="upper left")
    save_figure(fig, out_dir, "switching", "Parts switched while running: with and without the hand-over")
    return {"limits": {"u_jump_V": U_LIMIT, "torque_transient_Nm": M_LIMIT}, "rows": rows}
