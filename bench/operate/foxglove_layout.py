"""The Foxglove layout shipped with imbench (docs/foxglove/imbench.json), built with foxglove-sdk's
layout classes: the plots of run.png, the Parameters panel, the operator services, /status and the
event topics. One layout serves a live run (`bench run --live`) and a recorded log, since both have
the same topics and fields. `bench layout > imbench.json` writes it; import it in Foxglove with
*Layouts -> Import from file*.
"""

from __future__ import annotations

import json

import foxglove.layouts as fl

# the series of each plot: (topic.field, label); the same signals as bench.daq.plots.plot_run
PLOTS: dict[str, list[tuple[str, str]]] = {
    "speed [rad/s, el.]": [("/rig.omega_r_ref", "omega_r ref"), ("/ctrl.omega_hat", "omega_r estimate"),
                           ("/truth.omega_r", "omega_r true (mock)")],
    "load [N m]": [("/rig.m_l_ref", "m_L command"), ("/truth.m_l", "m_L true (mock)")],
    "currents, field frame [A]": [("/ctrl.i_sd", "i_sd"), ("/ctrl.i_sd_ref", "i_sd ref"), ("/ctrl.i_sq", "i_sq"),
                                  ("/ctrl.i_sq_ref", "i_sq ref")],
    "flux [A]": [("/rig.i_mr_ref", "i_mR ref"), ("/ctrl.i_mr_hat", "i_mR estimate")],
    "phase currents [A]": [("/rig.i_a", "i_a"), ("/rig.i_b", "i_b"), ("/rig.i_c", "i_c")],
}  # fmt: skip
SERVICES = (("/stop", "{}", "Stop (ramp to zero)", "#1f77b4"), ("/estop", "{}", "E-STOP", "#d62728"),
            ("/mark", '{"note": "..."}', "Mark", "#7f7f7f"))  # fmt: skip


def layout() -> fl.Layout:
    def plot(title: str, series: list[tuple[str, str]]) -> fl.PlotPanel:
        return fl.PlotPanel(title=title, config=fl.PlotConfig(paths=[
            fl.PlotSeries(value=path, label=label, enabled=True, timestamp_method="receiveTime")
            for path, label in series]))  # fmt: skip

    plots = fl.SplitContainer(direction="column", items=[fl.SplitItem(content=plot(t, s)) for t, s in PLOTS.items()])
    services = fl.SplitContainer(direction="row", items=[fl.SplitItem(content=fl.ServiceCallPanel(
        title=name, config=fl.ServiceCallConfig(service_name=name, request_payload=payload, button_text=text,
                                                button_color=color))) for name, payload, text, color in SERVICES])  # fmt: skip
    side = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=3, content=fl.ParametersPanel(title="tunable parameters")),
        fl.SplitItem(proportion=1, content=services),
        fl.SplitItem(proportion=2, content=fl.TabContainer(tabs=[
            fl.TabItem(title=topic, content=fl.RawMessagesPanel(title=topic, config=fl.RawMessagesConfig(
                topic_path=topic, expansion="all"))) for topic in ("/status", "/params", "/events")])),
    ])  # fmt: skip
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=3, content=plots),
                                                                       fl.SplitItem(proportion=1, content=side)]))


def layout_json() -> str:
    """The layout as the shipped file holds it (indented, newline at the end)."""
    return json.dumps(json.loads(layout().to_json()), indent=2) + "\n"


def paths() -> list[str]:
    """Every topic.field the plots use."""
    return [p for series in PLOTS.values() for p, _ in series]


__all__ = ["PLOTS", "layout", "layout_json", "paths"]
