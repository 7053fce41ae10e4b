"""`bench commission` with the motor's plate: the rotating test by default wherever the shaft may turn
(``[rig] free_shaft``; ``--standstill-only`` makes the result provisional, and the report says so), every stage's
warnings in report.md and on stderr, the rotating test's flux levels found on the motor's own magnetising curve
(not from a standstill L_m), and a 4 kW saturating motor commissioned at its own rated flux."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.workflows.commission.commission import _rotating, shaft_may_turn, write_report
from bench.core.config import RIGS_DIR, load as load_rig
from bench.errors import BadInput

ROOT = Path(__file__).resolve().parents[1]
MOCK_REAL = (RIGS_DIR / "mock-real.toml").read_text()
#: a strongly saturating (3.57) machine (tests/test_identify_saturation.py): the standstill L_m is 64 % low
STRONG = MOCK_REAL.replace("psi_sat = 1.1 ", "psi_sat = 0.95 ").replace("sat_exp = 7.0", "sat_exp = 5.0")
#: the 4 kW motor behind the mock with mock-real's inverter and its saturation curve at its own rated flux
RIG_4KW = """\
[rig]
name = "mock-4kw"
driver = "mock"
rate_hz = 3000

[limits]                # I_max, I_trip, I_trip_phase, U_max: from the plate
omega_max = 400.0
u_dc_min = 500.0
u_dc_max = 800.0
max_stall = 0.05
ride_through = 0.05

[nameplate]             # a new motor: its plate, no [motor] yet
P_rated = 4000.0
U_rated = 400.0
I_rated = 8.3
f_rated = 50.0
n_rated = 1440.0
cos_phi = 0.83

[mock.inverter]
u_dc = 650.0
dead_time = 2e-6
v_on = 1.5
i_knee = 0.2

[mock.currents]
burden = 250.0          # 0.25 V/A: +-40 A over +-10 V

[mock.load]
torque_limit = 40.0

[mock.motor]
L_s = 0.176
L_r = 0.176
L_m = 0.170
R_s = 1.5
R_r = 1.2
J = 0.030
saturation = true
psi_rated = 0.95
psi_sat = 1.1
sat_exp = 7.0
"""


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *args], cwd=ROOT, capture_output=True, text=True, timeout=900)


# --- where the shaft may turn ----------------------------------------------------------------------------------
def test_a_plate_without_its_motor_scales_the_standstill_test_from_the_plate_alone(tmp_path: Path) -> None:
    """A plate and no [motor] (the rig's [motor] is then (3.57), not this machine): the DC current and the multisine
    scale with the rated current (4 A, 2 A, 1 A x 8.3/3.6), the settling times with the rotor time constant the rated
    slip gives by (4.5) for i_sq/i_mR = 2.5: 2.5/(0.04 x 100 pi) = 0.199 s, x 1.5 over the defaults' 0.2 s."""
    import math

    from bench.workflows.commission.identify import check_inputs

    rig = tmp_path / "lab.toml"
    rig.write_text(RIG_4KW)
    params, _ = check_inputs(str(rig), "measured", {}, False, None)
    assert params["dc_current"] == 9.22 and params["ac_bias"] == 4.61 and params["ac_amplitude"] == 2.31
    settle = 1.5 * 2.5 / (0.04 * 100.0 * math.pi) / 0.2
    assert params["dc_settle"] == pytest.approx(settle, rel=3e-3) and settle > 1.4
    assert params["ac_settle"] == pytest.approx(2.0 * settle, rel=3e-3)
    with_motor = RIG_4KW.replace("[nameplate]", "[motor]\nL_s = 0.176\nL_r = 0.176\nL_m = 0.170\nR_s = 1.5\n"
                                 "R_r = 1.2\nJ = 0.030\n\n[nameplate]", 1)  # fmt: skip
    rig.write_text(with_motor)
    params, _ = check_inputs(str(rig), "measured", {}, False, None)  # [motor] fits the plate: its own T_r, i_m
    assert params["dc_settle"] == pytest.approx(1.5 * 0.176 / 1.2 / 0.2, rel=3e-3) and params["ac_bias"] < 4.5


def test_where_the_shaft_may_turn(tmp_path: Path) -> None:
    """The mock and emulated rigs turn by default, a real one only where its file says free_shaft = true;
    --standstill-only (rotating False) and reference voltages make the result provisional."""
    mock, lab, emu = (load_rig(r) for r in ("mock", "lab-example", "emulated"))
    assert shaft_may_turn(mock) and shaft_may_turn(emu) and not shaft_may_turn(lab)
    assert _rotating(mock, None, "measured") == (True, None)
    assert _rotating(mock, False, "measured")[1].startswith("--standstill-only")
    assert "reference voltages" in _rotating(mock, None, "reference")[1]
    assert "free_shaft" in _rotating(lab, None, "measured")[1] and _rotating(lab, True, "measured") == (True, None)
    for value, turns in (("true", True), ("false", False)):
        p = tmp_path / f"lab-{value}.toml"
        p.write_text((RIGS_DIR / "lab-example.toml").read_text().replace('name = "lab"', f'name = "lab"\nfree_shaft = {value}'))
        cfg = load_rig(str(p))
        assert cfg.free_shaft is turns and shaft_may_turn(cfg) is turns
    with pytest.raises(BadInput, match=r"--rotating: the rig file says the shaft may not turn"):
        _rotating(cfg, True, "measured")
    bad = tmp_path / "bad.toml"
    bad.write_text((RIGS_DIR / "mock.toml").read_text().replace('name = "mock"', 'name = "mock"\nfree_shaft = "yes"'))
    with pytest.raises(BadInput, match=r"rig.free_shaft: must be true or false"):
        load_rig(str(bad))


def test_rotating_and_standstill_only_together_refused(tmp_path: Path) -> None:
    rig = tmp_path / "lab.toml"
    rig.write_text(MOCK_REAL)
    p = _bench("commission", "--rig", str(rig), "--out", str(tmp_path / "r"), "--rotating", "--standstill-only")
    assert p.returncode == 2 and p.stderr.strip().splitlines() == ["bench: error: --standstill-only: not with --rotating"]
    assert sorted(f.name for f in tmp_path.iterdir()) == ["lab.toml"]


def test_report_states_provisional_and_the_warnings(tmp_path: Path) -> None:
    rep = {"verdict": "GO (provisional: standstill test only)", "rig": "lab.toml", "started": "t", "stages": {},
           "provisional": "--standstill-only: the standstill test only",
           "warnings": ["identify: saturation: incremental L_m ...", "identify: rotating test: the rated flux 0.9 Wb "
                        "is outside the measured 0.4-0.8 Wb: L_m there is extrapolated (widen flux_lo / flux_hi)"]}
    text = write_report(rep, tmp_path).read_text()
    assert "**Provisional**: --standstill-only" in text and "## Warnings" in text
    assert all(f"* {w}" in text for w in rep["warnings"])


# --- a strongly saturating motor -------------------------------------------------------------------------------
def test_rotating_levels_reach_the_rated_flux_whatever_the_model_l_m(tmp_path: Path) -> None:
    """The strongly saturating (3.57) machine; the drive's model is what its standstill test gives (L'_m 64 % low,
    the incremental value). The flux scan places the levels on the machine's own curve: they span 0.5-1.2 x the
    rated flux (at least 1.1 x), and L_m at the rated flux is the plant's secant value. (With the levels from that
    L_m, levels_from = current, the first level alone is at 1.1 x the rated flux.) Shortened plan, about 9 s."""
    from bench.workflows.commission.circuit import InverseGamma
    from bench.workflows.commission.rotating import identify_rotating
    from mock_hw.motor import Saturation

    rig = tmp_path / "strong.toml"
    rig.write_text(STRONG)
    g = InverseGamma.of(0.352, 0.352, 0.341, 5.0, 3.3)
    g = InverseGamma(g.R_s, g.L_sigma, g.R_R, 0.36 * g.L_M)  # the standstill's incremental L'_m
    ss = {"inverse_gamma": {n: {"value": v, "ci95": [0.995 * v, 1.005 * v]} for n, v in g.as_dict().items()}}
    short = {"flux_levels": 4, "holds": 2, "level_settle": 0.3, "level_average": 0.2, "hold_average": 0.3}
    res = identify_rotating(str(rig), ss, params=short, out_dir=tmp_path)
    assert "tripped" not in res, res.get("tripped")
    psi_n = res["L_m_rated"]["psi_rated_Wb"]
    assert psi_n == 0.88  # the thesis plate's rated flux
    psi = [lv["psi_m"] for lv in res["magnetising_curve"]["levels"]]
    assert psi[0] < 0.6 * psi_n and max(psi) >= 1.1 * psi_n, [x / psi_n for x in psi]
    for lv in res["magnetising_curve"]["levels"]:  # each level within 10 % of its flux target
        assert lv["psi_m"] == pytest.approx(lv["flux_ref"] * psi_n, rel=0.10)
    truth = Saturation(0.341, 0.88, 0.95, 5.0).L_m_of(psi_n)
    assert res["L_m_rated"]["value"] == pytest.approx(truth, rel=0.01)
    assert not [w for w in res["warnings"] if "extrapolated" in w or "reach" in w], res["warnings"]
    assert res["conditions"]["levels_from"] == "flux"


@pytest.mark.slow  # about 40 s: the standstill test, then NO-GO before the designs
def test_strong_saturation_standstill_only_is_no_go_with_its_warning(tmp_path: Path) -> None:
    """--standstill-only on the strongly saturating motor: its incremental L_m (64 % low) does not fit the plate
    (the circuit draws far more than 3.6 A), so NO-GO before any design, the rig file untouched; the saturation
    check's warning is in report.md and on stderr, and the report says the result is provisional."""
    rig = tmp_path / "lab.toml"
    rig.write_text(STRONG)
    before = rig.read_bytes()
    out = tmp_path / "report"
    p = _bench("commission", "--rig", str(rig), "--out", str(out), "--standstill-only")
    assert p.returncode == 1, p.stderr
    res = json.loads(p.stdout)
    assert "does not fit the rig file: nameplate.I_rated" in res["verdict"] and res["provisional"]
    sat = [w for w in res["warnings"] if "saturation:" in w]
    assert len(sat) == 1 and sum(f"bench: warning: {sat[0]}" == x for x in p.stderr.splitlines()) == 1
    report = (out / "report.md").read_text()
    assert f"* {sat[0]}" in report and "**Provisional**" in report and "flux observer" not in res["stages"]
    assert rig.read_bytes() == before


@pytest.mark.slow  # 4-6 min on the 2-core machine
def test_4kw_saturating_motor_commissioned_at_its_rated_flux(tmp_path: Path) -> None:
    """A 4 kW motor with its plate and no [motor]: the standstill test (test currents scaled to 8.3 A), the rotating
    test at the plate's rated flux (0.955 Wb), the designs, and the check at the rated point's i_mR (5.6 A, not the
    thesis motor's 2.5 A), its loads and speeds scaled: GO, flux angle p95 within the limit; the saturation warning
    reaches report.md and stderr; [motor] written, loading back against the plate."""
    import tomllib

    rig = tmp_path / "lab.toml"
    rig.write_text(RIG_4KW)
    out = tmp_path / "report"
    p = _bench("commission", "--rig", str(rig), "--out", str(out))
    assert p.returncode == 0, p.stderr[-3000:]
    res = json.loads(p.stdout)
    assert res["go"] and res["provisional"] is None and res["verdict"] == "GO"
    rep = json.loads((out / "commission.json").read_text())
    cl = rep["stages"]["closed loop"]
    assert cl["i_mR_ref"] == pytest.approx(5.6, abs=0.15) and cl["load_step"] == pytest.approx(7.89, abs=0.01)
    assert cl["truth"]["flux_angle_p95_deg"] < 5.0 and cl["truth"]["flux_mag_p95_rel"] < 0.10
    ident = json.loads(Path(rep["stages"]["identify"]["json"]).read_text())
    assert ident["conditions"]["dc_levels_A"][-1] == pytest.approx(9.22)  # 4 A x 8.3 / 3.6
    assert ident["rotating"]["L_m_rated"]["psi_rated_Wb"] == pytest.approx(0.955, abs=0.003)
    motor = tomllib.loads(rig.read_text())["motor"]
    assert motor["L_m"] == pytest.approx(0.1683, rel=0.01) and motor["R_s"] == pytest.approx(1.5, rel=0.01)
    sat = [w for w in rep["warnings"] if "saturation:" in w]
    assert sat and f"* {sat[0]}" in (out / "report.md").read_text() and f"bench: warning: {sat[0]}" in p.stderr
    load_rig(str(rig))  # the written [motor] fits the plate


def test_a_wide_j_interval_stops_commissioning_before_the_designs(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The rotating test's J with a 95 % interval wider than `--write` accepts: NO-GO right after the
    identification (one line naming J, its interval and the limit), no design or check run, the rig file as it
    was. The rotating test's result is the rig's truth (3.57) with J's interval widened to +-8 %; the
    standstill test runs on the mock."""
    import bench.workflows.commission.identify as identify_mod
    from bench.workflows.commission.commission import commission
    from bench.workflows.commission.rigfile import MAX_REL_CI
    from bench.params import MotorParams

    true = MotorParams()
    J = true.J

    def fake(rig: str, standstill: dict, **kw: object) -> dict:
        val = {n: {"value": v, "ci95": [0.99 * v, 1.01 * v]} for n, v in (("B_visc", true.B_visc),
                                                                           ("m_coulomb", true.m_coulomb))}  # fmt: skip
        return {"L_m_rated": {"value": true.L_m, "ci95": [0.99 * true.L_m, 1.01 * true.L_m]},
                "mechanics": {"J": {"value": J, "ci95": [0.92 * J, 1.08 * J]}, **val}, "warnings": [], "plots": [],
                "rig_time_s": 1.0}  # fmt: skip

    monkeypatch.setattr(identify_mod, "identify_rotating", fake)  # where `identify` calls it
    rig = tmp_path / "lab.toml"
    rig.write_text((RIGS_DIR / "mock.toml").read_text())
    before = rig.read_bytes()
    rep, code = commission(str(rig), tmp_path / "report", rotating=True)
    assert code == 1
    line = rep["verdict"]
    assert line.startswith("NO-GO: the identification is refused: J = ") and "\n" not in line
    assert "+-8.00%" in line and f"wider than {MAX_REL_CI:.0%}" in line and f"{0.92 * J:.4g} to {1.08 * J:.4g}" in line
    assert set(rep["stages"]) == {"identify"}  # nothing after it ran
    assert rig.read_bytes() == before
