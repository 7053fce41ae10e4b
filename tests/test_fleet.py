"""The random motor fleet (bench.workflows.commission.fleet): each plate is the true circuit's rated point, the [motor]
guess reproduces the plate, the per-unit laws scale as catalogue motors do and meet (3.57) at 1.5 kW, half the fleet
saturates, and a seed gives the same fleet (motor k independent of the fleet's size), in rig files the mock accepts."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from bench.workflows.commission import fleet
from bench.workflows.commission.fleet import (KINDS, STANDARD_KW, circuit, draw_fleet, operating_point, rated_slip,
                                             write_fleet)
from bench.params import MotorParams

ROOT = Path(__file__).resolve().parents[1]
# the plate rounds: n to 1 rpm (at 11 kW the slip is ~35 rpm: 1.5 % of it, and the power goes with the slip),
# I_rated to 3 digits (0.5 %), cos phi to 0.01 (0.005)
TOL_P, TOL_I, TOL_COS = 0.02, 0.02, 0.01


@pytest.fixture(scope="module")
def motors() -> list[fleet.FleetMotor]:
    return draw_fleet(16, seed=0)


def test_plate_is_the_true_circuits_rated_point(motors: list[fleet.FleetMotor]) -> None:
    """The true circuit at the plate's slip, 400 V and 50 Hz draws the plate's current at its cos phi and gives
    its shaft power; the [motor] guess from the plate alone does the same."""
    for m in motors:
        p = m.nameplate
        assert p.P_rated / 1e3 in STANDARD_KW and (p.U_rated, p.f_rated) == (400.0, 50.0)
        assert 1350 <= p.n_rated < 1500 and 0.6 < p.cos_phi < 0.95
        for params in (m.true, m.nominal):
            op = operating_point(params, p.slip, p.U_rated, p.f_rated)
            assert op.P_shaft == pytest.approx(p.P_rated, rel=TOL_P), m.label
            assert op.I == pytest.approx(p.I_rated, rel=TOL_I), m.label
            assert abs(op.cos_phi - p.cos_phi) <= TOL_COS, m.label
        assert m.psi_rated == pytest.approx(operating_point(m.true, p.slip).psi_m, rel=2e-3)  # exact vs rounded slip


def test_thesis_motor_anchors_the_laws() -> None:
    """At 1.5 kW and 380 V with the thesis plate's 3.6 A as the base, the laws give (3.57) back."""
    th = MotorParams()
    Zb = 380.0 / math.sqrt(3.0) / 3.6
    w = 2 * math.pi * 50.0
    assert fleet.law("R_s", 1.5e3) * Zb == pytest.approx(th.R_s, rel=2e-3)
    assert fleet.law("R_r", 1.5e3) * Zb == pytest.approx(th.R_r, rel=2e-3)
    assert fleet.law("X_m", 1.5e3) * Zb / w == pytest.approx(th.L_m, rel=2e-3)
    assert fleet.law("X_ls", 1.5e3) * Zb / w == pytest.approx(th.L_s - th.L_m, rel=2e-3)
    assert fleet.law("J", 1.5e3) == th.J


def test_scaling_with_power() -> None:
    """From 0.37 to 11 kW: resistances and inductances fall, the inertia, the rated current and speed rise, the slip
    and the magnetising share of the current fall, as catalogue motors do (module docstring of fleet)."""
    rows = []
    for P in STANDARD_KW:
        c = circuit(1e3 * P)
        s = rated_slip(c, 1e3 * P)
        op = operating_point(c, s)
        rows.append((c.R_s, c.R_r, c.L_m, c.L_s - c.L_m, -c.J, s, -op.I, op.i_m / (math.sqrt(2) * op.I)))
    for k, name in enumerate(("R_s", "R_r", "L_m", "L_ls", "-J", "slip", "-I", "i_m/I")):
        col = [r[k] for r in rows]
        assert all(a > b for a, b in zip(col, col[1:])), name
    small, big = rows[0], rows[-1]
    assert 0.06 < small[5] < 0.10 and 0.02 < big[5] < 0.035  # rated slip: catalogue 1370-1400 rpm and 1460 rpm
    assert small[7] > 0.55 and big[7] < 0.45  # magnetising current over the rated current


def test_half_saturate_and_the_plant_takes_every_rig(motors: list[fleet.FleetMotor], tmp_path: Path) -> None:
    from bench.core.config import load

    assert [m.kind for m in motors] == [KINDS[k % 4] for k in range(len(motors))]
    sat = [m for m in motors if m.saturation]
    assert len(sat) == len(motors) // 2 and {m.kind for m in sat} == {"mild", "strong"}
    for m in sat:
        s = m.saturation
        ratio = s["psi_sat"] / s["psi_rated"]
        assert (1.18 <= ratio <= 1.32) if m.kind == "mild" else (1.02 <= ratio <= 1.12)
        assert s["psi_rated"] == pytest.approx(m.psi_rated, rel=1e-3)
        curve = m.sat_curve()
        assert curve.L_m_of(s["psi_rated"]) == pytest.approx(m.true.L_m)  # secant = the circuit's L_m at rated flux
        lo, hi = m.truth_at(0.1)["thesis"]["L_m"], m.truth_at(m.i_m_rated)["thesis"]["L_m"]
        assert lo > m.true.L_m > hi  # incremental: above the secant at small flux, below it at the rated one
    for m in motors:
        assert (m.truth_at(1.0)["thesis"]["L_m"] == m.true.L_m) is (m.saturation is None)
        inv = m.inverter
        assert 0 <= inv["dead_time"] <= 3e-6 and all(0.45 <= v <= 2.2 for v in inv["v_on"])
    paths = write_fleet(motors[:4], tmp_path)
    for m, path in zip(motors[:4], paths):
        cfg = load(str(path))  # bench.core.config validates it, [mock] included
        assert cfg.motor.R_s == pytest.approx(m.nominal.R_s, rel=1e-3)
        assert cfg.mock["motor"]["R_s"] == m.true.R_s
        assert cfg.nameplate == m.nameplate  # the plate in the rig file, through bench.core.nameplate's checks


def test_plates_pass_the_rig_checks_with_either_circuit() -> None:
    """bench.core.config's plate checks (bench.core.nameplate: ranges, pole pairs, [motor]'s rated point, [limits]) take
    every plate of a large fleet, with the guess from the plate in [motor] and with the true machine there (the rig of
    the same designs for the true parameters)."""
    import tomlkit

    from bench.core.config import parse
    from bench.core.nameplate import RANGES, operating_point as plate_point

    for m in draw_fleet(60, seed=1):
        assert all(RANGES[k][0] <= v <= RANGES[k][1] for k, v in m.nameplate.as_dict().items()), m.label
        doc = m.rig_doc().unwrap()
        cfg = parse(doc)
        assert cfg.nameplate == m.nameplate and cfg.motor.Z_p == m.nameplate.Z_p
        doc["motor"] |= {n: getattr(m.true, n) for n in ("L_s", "L_r", "L_m", "R_s", "R_r", "J")}
        true_cfg = parse(tomlkit.parse(tomlkit.dumps(doc)).unwrap())
        op = plate_point(true_cfg.motor, m.nameplate)
        assert op.I_rms == pytest.approx(m.nameplate.I_rated, rel=0.02), m.label  # (3.54): the plate's current


def test_the_commissioning_check_fits_every_rig() -> None:
    """The commissioning check's set-points (Fig. 5.7's load step and the loaded hold scaled to the plate, the rated
    speed, the rated i_mR) stay inside each fleet rig's margins, the DC load machine's torque limit included (it is
    sized to the motor: 1.5 x the rated torque): `bench commission`'s own up-front check passes."""
    import tomlkit

    from bench.workflows.commission.check import check_setpoints
    from bench.core.config import parse

    for m in draw_fleet(40, seed=0):
        cfg = parse(tomlkit.parse(tomlkit.dumps(m.rig_doc())).unwrap())
        assert cfg.mock["load"]["torque_limit"] == pytest.approx(1.5 * m.nameplate.T_rated, rel=5e-3)
        check_setpoints(cfg)


def test_seeded_and_reproducible(tmp_path: Path) -> None:
    a, b = draw_fleet(6, seed=3), draw_fleet(6, seed=3)
    assert [m.manifest() for m in a] == [m.manifest() for m in b]
    assert [m.manifest() for m in draw_fleet(3, seed=3)] == [m.manifest() for m in a[:3]]  # k does not depend on n
    assert [m.manifest() for m in draw_fleet(6, seed=4)] != [m.manifest() for m in a]
    one, two = tmp_path / "one", tmp_path / "two"
    for out in (one, two):
        subprocess.run([sys.executable, "-m", "bench.workflows.commission.fleet",
                        "--motors", "3", "--seed", "3", "--out",
                        str(out)], check=True, capture_output=True, cwd=ROOT)  # fmt: skip
    for f in sorted(one.iterdir()):
        assert f.read_bytes() == (two / f.name).read_bytes(), f.name
    man = json.loads((one / "fleet.json").read_text())
    assert [m["label"] for m in man["motors"]] == ["m000", "m001", "m002"]


def test_bad_arguments() -> None:
    p = subprocess.run([sys.executable, "-m", "bench.workflows.commission.fleet", "--motors", "0", "--out", "/tmp/x"],
                       capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert p.returncode == 2 and p.stderr.strip().splitlines() == ["bench: error: --motors must be in 1..10000"]


def test_the_slowest_rotor_is_identified_from_its_own_defaults(tmp_path: Path) -> None:
    """m019 (7.5 kW, strongly saturating, τ_r = L_r/R_r = 0.32 s, the fleet's slowest rotor) with `bench identify`'s
    defaults: its DC levels settle 2.47 s (1.5 τ_r of [motor] over 0.2 s), so R_s comes out within 0.2 % and R_r
    within 0.5 %, each inside its 95 % interval. Settled the thesis motor's 1.0 s they were read inside the rotor's
    transient: R_s -0.74 %, R_r +1.19 %."""
    import tomlkit

    from bench.workflows.commission.identify import identify

    m = draw_fleet(20, 0)[19]
    rig = tmp_path / "m019.toml"
    rig.write_text(tomlkit.dumps(m.rig_doc()))
    res = identify(str(rig), out_dir=tmp_path / "id")
    assert res["conditions"]["dc_settle_s"] == pytest.approx(2.47, abs=0.01)
    R_s, R_r = res["dc"]["R_s"], res["thesis_L_s_eq_L_r"]["R_r"]
    assert abs(R_s["value"] / m.true.R_s - 1.0) < 0.002 and abs(R_r["value"] / m.true.R_r - 1.0) < 0.005, (R_s, R_r)
    assert R_s["ci95"][0] <= m.true.R_s <= R_s["ci95"][1] and R_r["ci95"][0] <= m.true.R_r <= R_r["ci95"][1]
