"""The motor's plate (bench.core.nameplate): the rated point against the closed-form steady state (3.54)-(3.56), the
plate-only rated flux against the circuit it must invert, the checks of [nameplate] against [motor] and [limits] as
real `bench commission` subprocesses (exit 2, one line naming the field, before anything runs, the rig file
untouched), the thesis rigs unchanged to the bit, and a 4 kW motor getting defaults scaled to it."""

from __future__ import annotations

import cmath
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.core import nameplate, scenarios
from bench.core.config import RIGS_DIR, load as load_rig, parse
from bench.errors import BadInput
from bench.params import MotorParams

ROOT = Path(__file__).resolve().parents[1]
THESIS_MOTOR = MotorParams()  # (3.57)
#: a 4 kW, 4-pole motor (the mock's truth below) and a plate that fits it
MOTOR_4KW = MotorParams(L_s=0.176, L_r=0.176, L_m=0.170, R_s=1.5, R_r=1.2, J=0.030)
RIG_4KW = """\
# a 4 kW motor with its plate; [motor] is what bench commission would find (no saturation in [mock.motor] here)
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

[nameplate]
P_rated = 4000.0
U_rated = 400.0
I_rated = 8.3
f_rated = 50.0
n_rated = 1440.0
cos_phi = 0.83

[motor]
L_s = 0.176
L_r = 0.176
L_m = 0.170
R_s = 1.5
R_r = 1.2
J = 0.030

[mock.inverter]
u_dc = 650.0

[mock.currents]
burden = 250.0

[mock.load]
torque_limit = 40.0

[mock.motor]
L_s = 0.176
L_r = 0.176
L_m = 0.170
R_s = 1.5
R_r = 1.2
J = 0.030
"""


def _rig_4kw(tmp: Path) -> Path:
    p = tmp / "rig4kw.toml"
    p.write_text(RIG_4KW)
    return p


# --- the rated point and the rated flux -----------------------------------------------------------------------
def test_the_thesis_plate() -> None:
    """App. A.1: 1420 rpm at 50 Hz is Z_p = 2 at 5.3 % slip, 297.4 rad/s electrical, 10.09 N m at 1.5 kW."""
    p = nameplate.THESIS
    assert p.Z_p == 2 and p.slip == pytest.approx(1 - 2840 / 3000) and p.omega_r == pytest.approx(297.40, abs=0.01)
    assert p.T_rated == pytest.approx(10.09, abs=0.01) and p.u_peak == pytest.approx(310.27, abs=0.01)


def test_operating_point_is_the_thesis_steady_state() -> None:
    """The inverse-Gamma circuit against (3.54)-(3.56) written out in the T parameters, at the plate's point."""
    m, p = THESIS_MOTOR, nameplate.THESIS
    w_mR, w_r = p.omega_s, p.omega_r
    den = (m.R_s * m.R_r + 1j * (w_mR - w_r) * m.R_s * m.L_r + 1j * w_mR * m.L_s * m.R_r
           + w_mR * (w_mR - w_r) * (m.L_m**2 - m.L_r * m.L_s))  # fmt: skip
    i_s = (m.R_r + 1j * (w_mR - w_r) * m.L_r) * p.u_peak / den  # (3.54)
    i_m = m.R_r * p.u_peak / den  # (3.55)
    m_e = 1.5 * m.Z_p * m.L_m**2 / m.R_r * abs(i_m) ** 2 * (w_mR - w_r)  # (3.56)
    op = nameplate.operating_point(m, p)
    assert op.I_rms * math.sqrt(2) == pytest.approx(abs(i_s), rel=1e-12)
    assert op.i_mR == pytest.approx(abs(i_m), rel=1e-12) and op.psi_r == pytest.approx(m.L_m * abs(i_m), rel=1e-12)
    assert op.m_e == pytest.approx(m_e, rel=1e-12) and op.cos_phi == pytest.approx(math.cos(cmath.phase(p.u_peak / i_s)))
    # the numbers mock_hw.motor.Saturation states for the rated point of (3.57): 5.3 A peak, |psi_m| 0.885 Wb
    assert abs(i_s) == pytest.approx(5.3, abs=0.01) and op.psi_m == pytest.approx(0.885, abs=0.001)
    # against the plate: +4 % current, +18 % power (cold resistances; no iron or friction loss in the model)
    assert op.I_rms / p.I_rated - 1 == pytest.approx(0.042, abs=0.001)
    assert op.P_mech / p.P_rated - 1 == pytest.approx(0.179, abs=0.001)


@pytest.mark.parametrize("motor, U, f, n", [(THESIS_MOTOR, 380.0, 50.0, 1420.0), (MOTOR_4KW, 400.0, 50.0, 1440.0),
                                            (MOTOR_4KW.with_(Z_p=1), 230.0, 60.0, 3480.0)])  # fmt: skip
def test_rated_flux_inverts_the_circuit(motor: MotorParams, U: float, f: float, n: float) -> None:
    """A plate made from the circuit (its current, power factor and torque at the plate's point): the plate-only
    solve gives back the circuit's psi_R and i_mR (exactly: the same steady state), and |psi_m| within 0.2 % (L_s_sigma
    = L'_s / 2); from the torque instead of cos phi the same."""
    probe = nameplate.Nameplate(1.0, U, 1.0, f, n)
    op = nameplate.operating_point(motor, probe)
    L_sig, L_M = motor.L_s - motor.L_m**2 / motor.L_r, motor.L_m**2 / motor.L_r
    for cos_phi, P in ((op.cos_phi, 1.0), (None, op.m_e * 2 * math.pi * n / 60)):  # torque: m_e = P / omega_mech
        plate = nameplate.Nameplate(P, U, op.I_rms, f, n, cos_phi)
        rf = nameplate.rated_flux(plate, motor.R_s, L_sig)
        assert rf.psi_R == pytest.approx(L_M * op.i_mR, rel=1e-9) and rf.i_sd == pytest.approx(op.i_mR, rel=1e-9)
        assert rf.cos_phi == pytest.approx(op.cos_phi, rel=1e-9) and rf.m_e == pytest.approx(op.m_e, rel=1e-9)
        assert rf.psi_m == pytest.approx(op.psi_m, rel=2e-3)


def test_plate_of_a_machine_fits_it() -> None:
    plate = nameplate.plate_of(MOTOR_4KW, 400.0, 50.0, 1440.0, 4000.0)
    assert plate.I_rated == 8.31 and plate.P_rated == 4000.0 and plate.Z_p == 2
    from bench.core.supervisor import Limits

    nameplate.check(plate, MOTOR_4KW, Limits(I_max=17.0, I_trip=26.0, I_trip_phase=26.0, u_dc_max=800.0), True)
    with pytest.raises(BadInput, match="nameplate.I_rated: .* draws 3.29 A, not 8.31 A"):  # the same plate, (3.57)
        nameplate.check(plate, THESIS_MOTOR, Limits(I_max=17.0, I_trip=26.0, I_trip_phase=26.0, u_dc_max=800.0), True)


# --- [nameplate] against [motor] and [limits]: bad input -------------------------------------------------------
def _with(text: str, **plate: object) -> str:
    """rigs/mock.toml's text with the plate's fields replaced (None: removed) or added."""
    lines = text.splitlines()
    start = lines.index(next(x for x in lines if x.startswith("[nameplate]")))
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
    table = {x.split("=")[0].strip(): x.split("=", 1)[1].split("#")[0].strip() for x in lines[start + 1:end] if "=" in x}
    for k, v in plate.items():
        if v is None:
            table.pop(k, None)
        else:
            table[k] = v if isinstance(v, str) else repr(v)
    return "\n".join(lines[:start + 1] + [f"{k} = {v}" for k, v in table.items()] + [""] + lines[end:]) + "\n"


MOCK = (RIGS_DIR / "mock.toml").read_text()
BAD = [  # (the rig file's text, the field the one line names, words it says)
    (_with(MOCK, P_rated=-1500.0), "nameplate.P_rated", "must be a number in [1, 1e+07] W"),
    (_with(MOCK, I_rated="nan"), "nameplate.I_rated", "must be a number in [0.01, 100000] A"),
    (_with(MOCK, U_rated='"380 V"'), "nameplate.U_rated", "must be a number in [1, 100000] V"),
    (_with(MOCK, f_rated=3e306), "nameplate.f_rated", "must be a number in [0.1, 2000] Hz"),  # (found by the fuzzer)
    (_with(MOCK, voltage=380.0), "nameplate.voltage", "unknown field"),
    (_with(MOCK, n_rated=None), "nameplate.n_rated", "missing"),
    (_with(MOCK, cos_phi=1.2), "nameplate.cos_phi", "must be a number in [0.01, 1]"),
    (_with(MOCK, n_rated=1500.0), "nameplate.n_rated", "a slip of 0.0%"),  # a synchronous speed
    (_with(MOCK, n_rated=3100.0), "nameplate.n_rated", "below the synchronous speed of one pole pair"),
    (_with(MOCK, n_rated=960.0), "nameplate.n_rated", "Z_p = 3 pole pairs"),  # [motor] Z_p = 2
    (_with(MOCK, I_rated=11.0), "nameplate.I_rated", "limits.I_trip = 15 A"),  # 15.6 A amplitude
    (_with(MOCK, U_rated=690.0), "nameplate.U_rated", "the rated flux needs 563 V"),  # the inverter: 400 V
    (_with(MOCK, P_rated=4000.0), "nameplate.P_rated", "develops 1769 W, not 4000 W within 40%"),
    (_with(MOCK, I_rated=2.5), "nameplate.I_rated", "draws 3.75 A, not 2.5 A within 25%"),
    (_with(MOCK, cos_phi=0.6), "nameplate.cos_phi", "power factor of 0.84, not 0.6"),
]


@pytest.mark.parametrize("text, field, words", BAD, ids=[b[1] + ":" + b[2][:24] for b in BAD])
def test_bad_nameplate_refused_in_one_line(tmp_path: Path, text: str, field: str, words: str) -> None:
    with pytest.raises(BadInput) as exc:  # in process: every case
        import tomllib

        parse(tomllib.loads(text), "lab.toml")
    assert exc.value.field == field and words in exc.value.problem, str(exc.value)


@pytest.mark.parametrize("case", [0, 9, 10, 11])
def test_bad_nameplate_as_bench_commission(tmp_path: Path, case: int) -> None:
    """As a real subprocess: exit 2, one line naming the field, no report folder, the rig file byte for byte."""
    text, field, words = BAD[case]
    rig = tmp_path / "lab.toml"
    rig.write_text(text)
    before = rig.read_bytes()
    p = subprocess.run([sys.executable, "-m", "bench", "commission", "--rig", str(rig), "--out", str(tmp_path / "r")],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)  # fmt: skip
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith(f"bench: error: {field}"), p.stderr
    assert words in lines[0] and "Traceback" not in p.stderr
    assert rig.read_bytes() == before and sorted(f.name for f in tmp_path.iterdir()) == ["lab.toml"]


def test_commission_needs_a_nameplate(tmp_path: Path) -> None:
    """A rig without [nameplate] runs everything else as before (here: loads, and its scenarios are the thesis
    ones), but bench commission refuses it in one line before anything runs."""
    text = MOCK[:MOCK.index("[nameplate]")] + MOCK[MOCK.index("[mock]"):]
    rig = tmp_path / "lab.toml"
    rig.write_text(text)
    cfg = load_rig(str(rig))
    assert cfg.nameplate is None and nameplate.scaled(cfg.motor, cfg.nameplate) is None
    before = rig.read_bytes()
    p = subprocess.run([sys.executable, "-m", "bench", "commission", "--rig", str(rig), "--out", str(tmp_path / "r")],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)  # fmt: skip
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("bench: error: nameplate:"), p.stderr
    assert "P_rated, U_rated, I_rated, f_rated, n_rated" in lines[0]
    assert rig.read_bytes() == before and sorted(f.name for f in tmp_path.iterdir()) == ["lab.toml"]


# --- the thesis rigs: nothing changes ------------------------------------------------------------------------
@pytest.mark.parametrize("rig", sorted(f.stem for f in RIGS_DIR.glob("*.toml")))
def test_shipped_rigs_carry_the_thesis_plate(rig: str) -> None:
    cfg = load_rig(rig)
    assert cfg.nameplate == nameplate.THESIS and nameplate.scaled(cfg.motor, cfg.nameplate) is None


def _columns(log: Path) -> dict[str, np.ndarray]:
    from bench.daq import LogReader

    r = LogReader(log)
    tps = sorted(r.topics())
    wall = ("log_time", "compute_us", "latency_us", "overrun")  # wall-clock timing: differs between any two runs
    return {f"{tp}/{k}": v for tp, c in zip(tps, r.read_ticks(*tps)) for k, v in c.items() if k not in wall}


@pytest.mark.parametrize("scenario", ["fig5.7", "load-step"])
def test_a_thesis_rig_runs_bit_for_bit_as_without_a_plate(tmp_path: Path, scenario: str) -> None:
    """rigs/mock.toml with its thesis plate and the same file without [nameplate] (the bench before plates): the
    same columns to the bit, over the first 0.9 s of a lockstep run (load steps included)."""
    from bench.runtime.session import RunOptions, run

    plain = tmp_path / "plain.toml"
    plain.write_text(MOCK[:MOCK.index("[nameplate]")] + MOCK[MOCK.index("[mock]"):])
    cols = []
    for rig in (str(RIGS_DIR / "mock.toml"), str(plain)):
        summary, code = run(RunOptions(rig=rig, scenario=scenario, duration=0.9, out_dir=tmp_path / Path(rig).stem,
                                       realtime=False))  # fmt: skip
        assert code == 0
        cols.append(_columns(Path(summary["log"])))
    a, b = cols
    assert a.keys() == b.keys() and len(a) > 40
    for k in a:
        assert a[k].tobytes() == b[k].tobytes(), k
    assert float(np.max(a["/rig/m_l_ref"])) == 3.0 and float(np.max(a["/rig/i_mr_ref"])) == 2.5


def test_thesis_defaults_are_the_constants() -> None:
    """What the plate would derive on the thesis motor, beside the constants the thesis rigs keep."""
    from bench.workflows.commission.check import check_scenario, rated_speed
    from bench.workflows.commission.identify import check_inputs

    cfg = load_rig("mock")
    assert check_scenario(200.0).i_mR_ref == scenarios.I_MR_REF == 2.5  # (the rated point's i_mR: 2.59 A)
    assert nameplate.operating_point(cfg.motor, nameplate.THESIS).i_mR == pytest.approx(2.59, abs=0.01)
    params, _ = check_inputs("mock", "measured", None, False, None)
    assert params == {"voltages": "measured"}  # the standstill test's own defaults: 4 A, 2 A bias, ...
    assert rated_speed(cfg) == pytest.approx(0.85 * 400 / math.sqrt(3) / (0.352 * 2.5))


# --- another motor: the defaults scaled to it ------------------------------------------------------------------
def test_a_4kw_motor_gets_scaled_defaults(tmp_path: Path) -> None:
    """The limits from the plate, the speed PI from J, the test currents from the rated current, the check's and
    the scenarios' i_mR, speeds and loads from the rated point; a short lockstep run logs them."""
    from bench.workflows.commission.check import check_scenario, rated_speed
    from bench.workflows.commission.identify import check_inputs
    from bench.workflows.commission.rotating import RotatingIdController, plate_params
    from bench.workflows.commission.circuit import InverseGamma
    from bench.runtime.session import RunOptions, run

    rig = _rig_4kw(tmp_path)
    cfg = load_rig(str(rig))
    plate = cfg.nameplate
    k = nameplate.scaled(cfg.motor, cfg.nameplate)
    op = nameplate.operating_point(MOTOR_4KW, plate)
    assert k is not None and k.i_mR == op.i_mR == pytest.approx(5.60, abs=0.01)
    assert cfg.limits.I_max == pytest.approx(1.5 * math.sqrt(2) * 8.3) and cfg.limits.I_trip == pytest.approx(
        2.25 * math.sqrt(2) * 8.3) and cfg.limits.U_max == pytest.approx(1.15 * math.sqrt(2 / 3) * 400)  # fmt: skip
    assert k.speed_Kp == pytest.approx(100 * 0.030 / 2) and k.speed_Ti == pytest.approx(0.04)
    assert k.speed == pytest.approx(1440 / 1420) and k.torque == pytest.approx(4000 / 1440 / (1500 / 1420))
    params, _ = check_inputs(str(rig), "measured", {"ac_periods": 1}, False, None)
    # the DC current with the rated current (4 A x 8.3/3.6), the multisine's bias and swing with the rated point's
    # magnetising current (2 A and 1 A x |i_m|/2.6 A), the settling times with the rotor time constant L_r/R_r
    # (1.5 x 0.147 s over the defaults' 0.2 s)
    i_m = op.psi_m / MOTOR_4KW.L_m
    assert params["dc_current"] == 9.22 and params["ac_periods"] == 1  # a given one as it is
    assert params["ac_bias"] == pytest.approx(2.0 * i_m / 2.6, rel=2e-3) and 3.0 < i_m < 6.0
    assert params["ac_amplitude"] == params["sat_bias"] == pytest.approx(1.0 * i_m / 2.6, rel=2e-3)
    T_r = 0.176 / 1.2
    assert params["dc_settle"] == pytest.approx(1.5 * T_r / 0.2, rel=2e-3) and params["ac_settle"] == pytest.approx(
        2.0 * 1.5 * T_r / 0.2, rel=2e-3)  # fmt: skip
    scn = check_scenario(rated_speed(cfg), scenarios.Scaling(k.speed, k.torque, k.i_mR))
    assert scn.i_mR_ref == k.i_mR and scn.speed_ref(1.0) == pytest.approx(10 * k.speed)
    assert scn.load(0.4 + 0.5, 10.0) == pytest.approx(3 * k.torque)  # (0 for the first 1/3 s)
    assert rated_speed(cfg) == pytest.approx(0.85 * 500 / math.sqrt(3) / (0.176 * k.i_mR))
    # the rotating test: the plate's rated flux and the scan's seed (no L_m in either), its speeds scaled
    g = InverseGamma.of(0.176, 0.176, 0.170, 1.5, 1.2)
    rp = plate_params(cfg, {}, g)
    rf = nameplate.rated_flux(plate, 1.5, g.L_sigma)
    assert rp["psi_rated"] == rf.psi_m == pytest.approx(0.955, abs=0.002) and rp["i_mR_rated"] == rf.i_sd
    assert rp["omega_test"] == pytest.approx(150 * k.speed) and plate_params(cfg, {"psi_rated": 0.9}, g)["psi_rated"] == 0.9
    assert set(rp) <= set(RotatingIdController.schema)
    # a session: the scaled fig5.7 and the derived gains
    summary, code = run(RunOptions(rig=str(rig), scenario="fig5.7", duration=1.0, out_dir=tmp_path / "runs",
                                   realtime=False))  # fmt: skip
    assert code == 0, summary.get("trip_cause")
    from bench.daq import LogReader

    r = LogReader(Path(summary["log"]))
    meas, = r.read_ticks("/rig")
    assert float(np.max(meas["i_mr_ref"])) == pytest.approx(k.i_mR) and float(np.max(meas["m_l_ref"])) == pytest.approx(
        3 * k.torque) and float(np.max(meas["omega_r_ref"])) == pytest.approx(10 * k.speed)  # fmt: skip
    ctrl = r.metadata()["run"]["controller_params"]
    assert ctrl["speed_Kp"] == pytest.approx(1.5) and ctrl["speed_Ti"] == pytest.approx(0.04)
    assert "scaled to the rig's motor" in r.metadata()["run"]["description"]


def test_scenario_arguments_given_are_absolute(tmp_path: Path) -> None:
    cfg = load_rig(str(_rig_4kw(tmp_path)))
    from bench.runtime.session import scenario_scaling

    k = scenario_scaling(cfg)
    assert scenarios.scaled_arguments("load-step", {"speed": 80.0}, k) == {"speed": 80.0, "load": 3.0 * k.torque}
    scn = scenarios.get("load-step", {"speed": 80.0}, None, k)
    assert scn.speed_ref(1.0) == 80.0 and scn.load(1.0, 80.0) == pytest.approx(3.0 * k.torque)
    assert scn.i_mR_ref == pytest.approx(k.i_mR)
    hold = scenarios.get("hold", None, None, k)  # 297 rad/s, 10 N m on the thesis motor
    assert hold.speed_ref(5.0) == pytest.approx(297 * k.speed) and hold.load(5.0, 300.0) == pytest.approx(10 * k.torque)
