"""What a newcomer reads off a run: the R_r estimate's panel, titles that fit, the commissioning check's
criteria drawn with their limits, units in the report, `bench identify`'s table on a terminal, run-folder
hashes that tell artifacts apart, times in summary.json without float noise."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _short_run(tmp_path: Path, name: str, rig: str, params: dict, duration: float = 1.2) -> Path:
    from bench.core.scenarios import get as get_scenario
    from bench.runtime.session import RunOptions, run

    summary, code = run(RunOptions(rig=rig, scenario=get_scenario("warmup"), duration=duration, params=params,
                                   log=tmp_path / f"{name}.mcap", progress=False))  # fmt: skip
    assert code == 0, summary
    return Path(summary["log"])


@pytest.mark.parametrize("rig, source", [("mock-warm-fast", "thermal model"), ("mock-hot-rotor", "[mock.motor]")])
def test_run_plot_has_the_rr_estimate_against_the_truth(tmp_path: Path, rig: str, source: str) -> None:
    from bench.daq.plots import run_figure

    fig = run_figure(_short_run(tmp_path, "rr", rig, {"rr_adapt": "mras"}))
    assert len(fig.axes) == 5 and "rotor resistance" in fig.axes[4].get_ylabel()
    labels = [ln.get_label() for ln in fig.axes[4].lines]
    assert any("estimate" in lb for lb in labels) and any(source in lb for lb in labels), labels
    if source == "[mock.motor]":  # the hot rotor's constant true R_r: 1.5 x 3.3 Ohm
        true = next(ln for ln in fig.axes[4].lines if source in ln.get_label())
        assert np.allclose(true.get_ydata(), 4.95)
    plain = run_figure(_short_run(tmp_path, "plain", rig, {}))
    assert len(plain.axes) == 4  # no estimate, no panel


def test_long_scenario_titles_fit_the_figure(tmp_path: Path) -> None:
    from bench.daq.plots import fit_title, run_figure
    from bench.core.scenarios import get as get_scenario

    log = _short_run(tmp_path, "t", "mock", {}, duration=0.2)
    for name in ("hold", "warmup"):
        title = f"{get_scenario(name).description}\ncontroller foc (observer current_model, current pi, speed pi)"
        fig = run_figure(log, title)
        fig.canvas.draw()
        box = fig._suptitle.get_window_extent()
        assert box.x0 >= 0 and box.x1 <= fig.bbox.width, (name, box)
    assert fit_title("short", 11) == "short" and fit_title("a\nb", 11) == "a\nb"


def _check_columns(flux_angle_deg: float) -> dict[str, np.ndarray]:
    from bench.workflows.commission.check import HOLD_TIME, LOW_TIME, RAMP_TIME, check_scenario
    from bench.core.scenarios import T_MAGNETISE

    scn = check_scenario(200.0)
    t = np.arange(0.0, T_MAGNETISE + LOW_TIME + RAMP_TIME + HOLD_TIME, 1 / 3000)
    ref = np.array([scn.speed_ref(x) for x in t])
    im = 2.5 * np.exp(1j * 10.0 * t)
    im_hat = im * np.exp(1j * math.radians(flux_angle_deg))
    return {"/rig/t": t, "/rig/omega_r_ref": ref, "/ctrl/omega_hat": ref + 0.1, "/rig/m_l_ref": 0 * t,
            "/truth/i_m_re": im.real, "/truth/i_m_im": im.imag, "/ctrl/i_m_hat_re": im_hat.real,
            "/ctrl/i_m_hat_im": im_hat.imag, "/truth/omega_r": ref}  # fmt: skip


def test_no_go_plot_draws_every_criterion_with_its_limit_and_marks_the_failed_one() -> None:
    from bench.workflows.commission.check import GO, check_figure, check_metrics

    m = check_metrics(_check_columns(12.0), 200.0, None, judge="truth")
    assert not m["go"] and not m["criteria"]["flux angle vs truth (p95)"]["pass"]
    fig = check_figure(_check_columns(12.0), m)
    titles = {ax.get_title(loc="left"): ax for ax in fig.axes if ax.get_title(loc="left")}
    for name, c in m["criteria"].items():  # each judged criterion has its panel, its verdict in the title
        ax = next(a for tt, a in titles.items() if tt.startswith(name + ":"))
        assert ("FAIL" in ax.get_title(loc="left")) == (not c["pass"])
        if c["limit"] != "none":
            assert "limit" in ax.get_title(loc="left")
    angle = next(a for tt, a in titles.items() if tt.startswith("flux angle"))
    ys = {round(float(ln.get_ydata()[0]), 6) for ln in angle.lines if len(ln.get_ydata()) == 2}
    assert GO.flux_angle_p95_deg in ys and -GO.flux_angle_p95_deg in ys  # the limit drawn
    assert angle.spines["left"].get_edgecolor()[:3] != (0.0, 0.0, 0.0)  # the failed panel framed in red
    assert "failed: flux angle" in fig._suptitle.get_text()


def test_report_identified_motor_table_has_units(tmp_path: Path) -> None:
    from bench.workflows.commission.commission import write_report

    motor = {"R_s": {"value": 5.0, "ci95": [4.9, 5.1]}, "L_m": {"value": 0.34, "ci95": [0.33, 0.35]},
             "J": {"value": 0.0125, "ci95": [0.012, 0.013]}}  # fmt: skip
    text = write_report({"verdict": "NO-GO", "rig": "x.toml", "started": "now",
                         "stages": {"identify": {"motor": motor, "rig_time_s": 1.0}}}, tmp_path).read_text()  # fmt: skip
    assert "| | value | 95 % interval | unit |" in text
    assert "| R_s | 5 | [4.9, 5.1] | Ohm |" in text and "| L_m |" in text and "| H |" in text and "kg m^2" in text


def test_identify_prints_a_table_on_a_terminal_and_json_when_asked(tmp_path: Path, run_in_pty) -> None:  # noqa: ANN001
    code, text = run_in_pty([sys.executable, "-m", "bench", "identify", "--out", str(tmp_path)])
    assert code == 0, text
    assert "95 % interval" in text and "Ohm" in text and '"inverse_gamma"' not in text, text
    table = text[text.index("identified motor"):].splitlines()  # after the progress bar
    print("\n".join(table))
    assert len(table) < 15 and not any(line.lstrip().startswith("{") for line in table)
    (js,) = tmp_path.glob("*/identify.json")
    assert any(str(js) in line for line in table)
    res = json.loads(js.read_text())
    assert "R_r" in res["motor"] and f"{res['motor']['R_r']['value']:.5g}" in text
    # --json: the JSON on a terminal too (a re-estimate from the log, no new test)
    code, text = run_in_pty([sys.executable, "-m", "bench", "identify", "--json", "--from-log",
                             str(js.parent / "run.mcap"), "--out", str(tmp_path / "re")])  # fmt: skip
    assert code == 0, text
    body = text[text.index("{"): text.rindex("}") + 1]
    assert "R_r" in json.loads(body)["thesis_L_s_eq_L_r"]


def test_run_folder_hash_tells_artifacts_of_one_name_apart(tmp_path: Path) -> None:
    from bench.runtime.session import run_name

    def name(art: Path) -> str:
        return run_name("commission", "foc", {"observer": "lpv", "lpv_artifact": str(art / "flux_observer"),
                                              "voltage_source": "measured", "current_controller": "lpv",
                                              "lpv_current_artifact": str(art / "current_controller")}, 0)  # fmt: skip

    names = []
    for i, folder in enumerate(("a", "b")):
        (tmp_path / folder).mkdir()
        for f in ("flux_observer", "current_controller"):
            (tmp_path / folder / f"{f}.npz").write_bytes(bytes([i]) * 100)
        names.append(name(tmp_path / folder))
    assert "params-" in names[0] and names[0] != names[1]
    assert name(tmp_path / "a") == names[0]  # the same artifact: the same name
    (tmp_path / "a" / "flux_observer.npz").write_bytes(b"rebuilt")
    assert name(tmp_path / "a") != names[0]  # rebuilt in place: another


def test_summary_times_are_rounded_to_a_microsecond(tmp_path: Path) -> None:
    p = subprocess.run([sys.executable, "-m", "bench", "run", "--duration", "0.2", "--no-progress", "--out",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=120)  # fmt: skip
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["duration"] == 0.2  # 600 ticks of 1/3000 s: 0.19999999999999998 unrounded
    (summary,) = tmp_path.glob("*/summary.json")
    assert '"duration": 0.2,' in summary.read_text()
