"""The robustness atlas' numbers (bench.workflows.reproductions.atlas) on a synthetic table with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.workflows.reproductions import atlas
from bench.workflows.sweep.report import wilson


def _rows() -> list[dict]:
    rng = np.random.default_rng(0)
    rows = []
    for g, trip_every in (("PI", 0), ("LPV current", 4)):  # LPV current: every 4th case trips
        for i in range(200):
            rr = 0.5 + i / 199
            tripped = trip_every and i % trip_every == 0
            rows.append({"index": len(rows), "label.controller": g, "status": "tripped" if tripped else "ok",
                         "trip_cause": "over-current: |i_s| 12 A > 10 A" if tripped else None,
                         "plant.R_r": rr, "plant.R_s": rng.uniform(0.8, 1.2), "plant.L_m": rng.uniform(0.85, 1.15),
                         "plant.J": rng.uniform(0.7, 1.3), "speed_error_settled_rms": float(i),  # 0..199
                         "speed_error_rms": 40.0 + rr, "i_mR_error_rms": abs(rr - 1.0),
                         "est_flux_angle_rms_deg": 10 * abs(rr - 1.0), "case_wall_time": 0.5})  # fmt: skip
    rows.append({**rows[0], "index": len(rows), "status": "error"})  # a case that raised: not counted as ran
    return rows


def test_summary_counts_trips_with_wilson_intervals_and_quantiles_over_cases_that_did_not_trip():
    s = {x["group"]: x for x in atlas.summarise("controllers", _rows())}
    pi, lpv = s["PI"], s["LPV current"]
    assert (pi["cases"], pi["ran"], pi["trips"], pi["trip_probability"]) == (201, 200, 0, 0.0)
    assert pi["trip_ci95"] == [0.0, pytest.approx(wilson(0, 200)[2])]
    assert (lpv["trips"], lpv["trip_probability"]) == (50, 0.25) and lpv["trip_causes"] == {"over-current": 50}
    assert pi["speed_error_settled_rms"]["p50"] == pytest.approx(99.5)  # median of 0..199
    assert pi["speed_error_settled_rms"]["max"] == 199.0
    kept = [i for i in range(200) if i % 4]  # the tripped cases' errors are left out
    assert lpv["speed_error_settled_rms"]["p90"] == pytest.approx(np.quantile(kept, 0.9))


def test_markdown_row_and_figure(tmp_path):
    rows = _rows()
    md = atlas.markdown("controllers", atlas.summarise("controllers", rows))
    lo, _, hi = wilson(50, 200)
    assert f"| LPV current | 200 | 50 | 0.25 [{lo:.2g}, {hi:.2g}] |" in md
    assert "LPV current: over-current (50)" in md
    for name in atlas.SPECS:  # every row of both tables has the header's number of cells (no stray "|")
        lines = [x for x in atlas.markdown(name, []).splitlines() if x.startswith("|")]
        assert len({x.count("|") for x in lines}) == 1, lines
    atlas.plot("controllers", rows, tmp_path / "a.png")
    assert (tmp_path / "a.png").stat().st_size > 20_000


def test_the_atlas_specs_are_the_documented_ones():
    from bench.workflows.sweep.spec import load

    for name, path in atlas.SPECS.items():
        sp = load(path)
        assert sp.kind == "lhs" and sp.samples == 1000
        assert sp.ranges == {"plant.R_r": (0.5, 1.5), "plant.R_s": (0.8, 1.2), "plant.L_m": (0.85, 1.15),
                             "plant.J": (0.7, 1.3)}  # fmt: skip


def test_paired_comparison_and_sign_test():
    assert atlas.sign_test(0, 10) == pytest.approx(2 / 1024) and atlas.sign_test(5, 10) == 1.0
    assert atlas.sign_test(8, 10) == pytest.approx(2 * (1 + 10 + 45) / 1024)
    rows = []
    for obs, off in (("lpv", 0.0), ("jl", 1.0)):  # jl one degree worse at every point, lpv's tracking 0.5 worse
        for i in range(30):
            rows.append({"label.mode": "encoder", "params.observer": obs, "status": "ok", "plant.R_r": 0.5 + i / 29,
                         "plant.R_s": 1.0, "plant.L_m": 1.0, "plant.J": 1.0, "est_flux_angle_rms_deg": i + off,
                         "est_flux_mag_rms_rel": 0.01 * i, "speed_error_settled_rms": 2.0 - off / 2})  # fmt: skip
    rows[0]["status"] = "tripped"  # left out of the pairs
    by = {p["metric"]: p for p in atlas.paired(rows)}
    ang, mag, trk = (by[c] for c in atlas.PAIRED)
    assert (ang["points"], ang["ref_better_share"], ang["median_difference"]) == (29, 1.0, -1.0)
    assert ang["sign_test_p"] == pytest.approx(2 / 2**29) and math.isnan(mag["ref_better_share"])
    assert (trk["ref_better_share"], trk["median_difference"]) == (0.0, 0.5)
    md = atlas.paired_markdown(atlas.paired(rows))
    assert "| encoder | jl | 100 % / -1 / " in md
