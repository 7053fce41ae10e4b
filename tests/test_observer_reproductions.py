"""The closed-loop observer reproductions (Figs 5.7-5.11), the ground-truth error table and the observer benchmark."""

from __future__ import annotations

import json

import pytest

from bench.workflows import reproduce
from bench.workflows.reproductions import observer_errors as oe


def test_figures_5_7_to_5_11_are_registered():
    names = reproduce.available()
    for n in ("fig5.7", "fig5.8", "fig5.9", "fig5.10", "fig5.11"):
        assert n in names


def _cases() -> dict:
    return {(c.scenario, c.params["observer"], c.labels["mode"], c.labels["plant"]): c for c in oe.cases()}


def test_the_sweep_file_holds_the_case_parameters_and_mismatched_plants():
    from bench.workflows.reproductions.closed_loop import SENSORLESS

    by = _cases()
    assert len(by) == 5 * 4 * 2 * 3
    enc = by[("fig5.7", "kubota", "encoder", "nominal")].params
    assert enc["kubota_adapt"] == 0.0 and enc["speed_source"] == "encoder" and enc["speed_estimator"] == "none"
    sl = by[("fig5.7", "lpv", "sensorless", "nominal")].params
    assert {k: sl[k] for k in SENSORLESS} == SENSORLESS and sl["kubota_adapt"] == 1.0
    assert sl["kubota_pole_ratio"] == 1.1 and sl["kubota_lambda_c"] == 1000.0
    assert "motor" not in by[("fig5.7", "jl", "encoder", "nominal")].rig.get("mock", {})
    assert by[("fig5.7", "jl", "encoder", "R_r +50 %")].rig["mock"]["motor"] == {"R_r": pytest.approx(1.5 * 3.3)}
    assert by[("fig5.7", "jl", "encoder", "R_s +20 %")].rig["mock"]["motor"] == {"R_s": pytest.approx(6.0)}


def test_rotor_resistance_mismatch_hits_the_current_model_not_the_voltage_model():
    """Sec. 4.3: the current model needs R_r, the voltage model does not. With the plant's R_r 50 % high the
    current model's flux angle is off by degrees, the voltage model's stays at its nominal level."""
    from bench.workflows.sweep.cases import run_case

    by = _cases()
    cm_hot = oe.table_row(run_case(by[("fig5.7", "current_model", "encoder", "R_r +50 %")]))
    cm_nom = oe.table_row(run_case(by[("fig5.7", "current_model", "encoder", "nominal")]))
    vm_hot = oe.table_row(run_case(by[("fig5.7", "voltage_model", "encoder", "R_r +50 %")]))
    assert not (cm_hot["tripped"] or cm_nom["tripped"] or vm_hot["tripped"])
    assert cm_nom["flux_angle_rms_deg"] < 0.2 and cm_hot["flux_angle_rms_deg"] > 2.0
    assert cm_hot["flux_mag_rms_rel"] > 0.02
    assert vm_hot["flux_angle_rms_deg"] < 0.2


def test_markdown_and_splice(tmp_path):
    row = {"scenario": "fig5.7", "observer": "lpv", "mode": "encoder", "plant": "nominal", "flux_mag_rms_A": 0.0012,
           "flux_mag_max_A": 0.004, "flux_angle_rms_deg": 0.02, "flux_angle_max_deg": 0.1, "speed_rms": 0.33,
           "speed_max": 1.4, "trip_cause": None, "trip_t": None}  # fmt: skip
    tripped = {**row, "mode": "sensorless", "flux_angle_rms_deg": float("nan"), "trip_cause": "over-speed", "trip_t": 3.5}
    md = oe.markdown([row, tripped])
    assert "| fig5.7 | lpv | nominal | 1.2 / 4 | 0.02 / 0.1 | 0.33 / 1.4 | no |" in md
    assert "– / 0.1" in md and "**3.50 s**: over-speed" in md
    f = tmp_path / "R.md"
    f.write_text(f"head\n{oe.BEGIN}\nold\n{oe.END}\ntail\n")
    oe.splice(f, "NEW")
    assert f.read_text() == f"head\n{oe.BEGIN}\nNEW\n{oe.END}\ntail\n"
    f.write_text("no markers")
    with pytest.raises(SystemExit, match="markers not found"):
        oe.splice(f, "NEW")


def test_observer_benchmark_per_call_json():
    from bench.perf.observers import per_call

    out = per_call(n_calls=300, repeats=1)
    json.dumps(out)
    assert set(out["observers_ns"]) >= {"current_model", "voltage_model", "jl", "kubota", "lpv"}
    assert set(out["speed_estimators_ns"]) == {"rotor_equation", "kubota"}
    assert all(v > out["call_overhead_ns"] for v in out["observers_ns"].values())


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fig5.7", "fig5.9"])
def test_reproductions_write_png_and_json(tmp_path, name):
    out, written = reproduce.reproduce(name, tmp_path)
    assert tmp_path / f"{name}.png" in written
    assert (tmp_path / f"{name}.png").stat().st_size > 10_000
    assert json.loads((tmp_path / f"{name}.json").read_text())["runs"]
    assert all(not r["tripped"] for r in out["runs"].values())
