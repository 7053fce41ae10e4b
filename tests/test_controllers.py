"""FOC parts against closed-form behaviour, and the plugin registry."""

from __future__ import annotations

import cmath
import math

import pytest

from bench import controllers
from bench.controllers.base import ControllerContext
from bench.controllers.foc import CurrentPI, FluxP, FocController, SpeedPI
from bench.controllers.observers import CurrentModelObserver
from bench.core.encoder import EncoderSpeed
from bench.errors import BadInput
from bench.params import T_S_DEFAULT, MotorParams

M = MotorParams()
T = T_S_DEFAULT


def ctx(**kw) -> ControllerContext:
    base = dict(T_s=T, motor=M, I_max=10.0, counts_per_rev=4096, enc_modulus=2**16)
    base.update(kw)
    return ControllerContext(**base)


def test_current_model_steady_state_matches_3_54_3_55():
    """Fed the steady-state stator current, (4.15) converges to i_ms of (3.55).

    From (3.54)/(3.55): i_ms = R_r / (R_r + j (omega_mR - omega_r) L_r) * i_ss.
    """
    obs = CurrentModelObserver(M, T)
    for omega_mR, omega_r in ((50.0, 45.0), (10.0, 4.0), (-80.0, -70.0), (3.0, 10.0)):
        obs.reset()
        i_ss = 3.0 * cmath.exp(0.3j)
        n = int(1.5 / T)  # 14 rotor time constants
        for k in range(n + 1):
            i_m = obs.update(i_ss * cmath.exp(1j * omega_mR * k * T), 0j, omega_r)
        expected = M.R_r / (M.R_r + 1j * (omega_mR - omega_r) * M.L_r) * i_ss * cmath.exp(1j * omega_mR * n * T)
        assert abs(i_m - expected) < 1e-3 * abs(expected), (omega_mR, omega_r)


def test_encoder_speed_wraps_and_resolves_one_count():
    enc = EncoderSpeed(4096, 2**16, 2, T, tau=0.0)  # unfiltered
    enc.update(2**16 - 1)
    w = enc.update(0)  # one count forward across the wrap
    step = 2 * 2 * math.pi / (4096 * T)  # electrical rad/s per count per tick
    assert w == pytest.approx(step)
    assert step / 2 == pytest.approx(4.6, abs=0.05)  # App. A.5: ~4.6 rad/s mechanical
    assert enc.update(2**16 - 2) == pytest.approx(-2 * step)  # two counts back across the wrap


def test_speed_pi_respects_torque_limit_4_8_and_unwinds():
    k = M.torque_constant
    pi = SpeedPI(0.25, 0.1, k, 10.0, T)
    i_mR, i_sd = 2.5, 2.5
    m_max = k * i_mR * math.sqrt(10.0**2 - i_sd**2)
    for _ in range(3000):  # 1 s of large error
        i_sq = pi.update(200.0, 0.0, i_mR, i_sd)
    assert pi.m_e_ref == pytest.approx(m_max)
    assert i_sq == pytest.approx(math.sqrt(100 - i_sd**2))  # (4.7) then |i_s| = I_max
    assert pi.x <= m_max + 1e-12  # integrator clamped: no windup beyond the bound
    # once the error reverses, the output leaves the limit within a few ticks
    for n in range(1, 50):
        pi.update(0.0, 10.0, i_mR, i_sd)
        if pi.m_e_ref < m_max:
            break
    assert n < 10


def test_flux_p_zero_steady_state_error():
    """With the (K+1)/K premultiplication, i_mR = i_sd in steady state (4.4) gives zero error."""
    fp = FluxP(4.0, 10.0)
    i_mR = 0.0
    a = math.exp(-T / M.T_r)
    for _ in range(int(2.0 / T)):
        i_sd = fp.update(2.5, i_mR)
        i_mR = a * i_mR + (1 - a) * i_sd  # (4.4), ideal current loop
    assert i_mR == pytest.approx(2.5, rel=1e-6)


def test_current_pi_bandwidth_on_decoupled_plant():
    """On (R_s + L'_s s) i = u_c the PI (pole-zero cancellation) gives a first-order loop at w_cc."""
    wc = 1000.0
    pi = CurrentPI(M.Ls_p * wc, M.Ls_p / M.R_s, T, M.Ls_p, M.Lm_p, M.Rr_p)
    a = math.exp(-M.R_s / M.Ls_p * T)
    i = 0j
    ref = 1.0 + 0j
    t63 = None
    for k in range(1, 300):
        u = pi.update(ref, i, 0.0, 0.0, 1e6) - pi.Rr_p * i.real  # remove the R'_r feed-forward: i_mR = 0 here
        i = a * i + (1 - a) / M.R_s * u  # exact ZOH plant, no delay
        if t63 is None and i.real >= 0.632:
            t63 = k * T
    assert abs(i - ref) < 1e-3
    assert t63 == pytest.approx(1 / wc, rel=0.35)


def test_current_pi_anti_windup_limits_and_recovers():
    """An unreachable reference saturates the voltage; afterwards the loop recovers at once.

    Without anti-windup the integrator would charge for 0.1 s and the current would overshoot
    the new reference for a long time.
    """
    pi = CurrentPI(M.Ls_p * 1000.0, M.Ls_p / M.R_s, T, M.Ls_p, M.Lm_p, M.Rr_p)
    a = math.exp(-M.R_s / M.Ls_p * T)
    i, u_max = 0j, 100.0  # at most 20 A reachable through R_s = 5 Ohm
    for _ in range(300):
        u = pi.update(50.0 + 0j, i, 0.0, 0.0, u_max) - pi.Rr_p * i.real
        i = a * i + (1 - a) / M.R_s * u
    assert pi.saturated and abs(abs(u + pi.Rr_p * i.real) - u_max) < 1e-9
    lows = []
    for _ in range(60):  # 20 ms at the achievable reference 5 A
        u = pi.update(5.0 + 0j, i, 0.0, 0.0, u_max) - pi.Rr_p * i.real
        i = a * i + (1 - a) / M.R_s * u
        lows.append(i.real)
    assert abs(i - 5.0) < 0.05
    assert min(lows) > 4.0  # no large undershoot from a wound-up integrator


def test_registry_lists_foc_and_rejects_unknown():
    assert "foc" in controllers.available()
    c = controllers.create("foc", ctx())
    assert isinstance(c, FocController)
    with pytest.raises(BadInput, match="controller: unknown controller 'nope'; allowed: .*foc"):
        controllers.create("nope", ctx())
    # the registry is scanned once per process; a caller changing its copy does not change it
    table = controllers.available()
    table["nope"] = FocController
    del table["foc"]
    assert "nope" not in controllers.available() and controllers.available()["foc"] is FocController


@pytest.mark.parametrize(
    "params, field",
    [({"speed_Kp": "x"}, "controller.foc.speed_Kp"), ({"bogus": 1.0}, "controller.foc.bogus"),
     ({"observer": "magic"}, "controller.foc.observer"), ({"speed_divisor": 0}, "controller.foc.speed_divisor")],
)  # fmt: skip
def test_foc_bad_params_name_the_field(params, field):
    with pytest.raises(BadInput) as exc:
        controllers.create("foc", ctx(), params)
    assert str(exc.value).startswith(field)


def test_foc_multirate_divisor_holds_speed_output():
    """With speed_divisor = 5 (600 Hz) the i_sq reference changes only every 5th tick."""
    from bench.hal import Measurement

    c = FocController(ctx(), speed_divisor=5)
    seen = []
    for k in range(30):
        m = Measurement(k * T, 1.0, -0.5, -0.5, 0, 0, 0, 3 * k, -1, 560.0, True, False, (0, 0, 0), (0, 0, 0))
        c.step(m, 50.0, 1.0)  # i_sd_ref = 5 A < I_max leaves room for torque
        seen.append(c.i_sq_ref)
    changes = [k for k in range(1, 30) if seen[k] != seen[k - 1]]
    assert changes and all(k % 5 == 0 for k in changes)


def test_field_frame_waits_for_the_flux_estimate_from_zero_flux():
    """From zero flux the field frame stays on the a axis (along which i_sd builds the flux) while the estimate is
    below a tenth of its reference, even where it flips its sign above I_MR_FLOOR (an LPV observer under the first
    ticks' saturated voltage on a 7.5 kW motor: 0.1-0.5 A at i_mR_ref = 8 A, and the frame that followed it tripped
    over-current in 15 ms); above that it follows the estimate, and below I_MR_FLOOR (the flux gone) it waits again."""
    from bench.controllers.foc import FRAME_REL, I_MR_FLOOR
    from bench.hal import Measurement

    class Scripted:  # an observer whose estimate the test sets
        i_m = 0j

        def update(self, i_s: complex, u_s: complex, omega: float) -> complex:
            return self.i_m

    i_mR_ref = 8.0
    c = FocController(ctx())
    c.observer = obs = Scripted()
    frames = []
    script = [0.4, -0.4, 0.45j, -0.3, 0.5] + [1.5 * FRAME_REL * i_mR_ref * 1j] + [0.05, 0.3]
    for k, est in enumerate(script):
        obs.i_m = est
        m = Measurement(k * T, 1.0, -0.5, -0.5, 0, 0, 0, 0, -1, 560.0, True, False, (0, 0, 0), (0, 0, 0))
        c.step(m, 0.0, i_mR_ref)
        frames.append(c.i_sr)  # the measured current (1 A along a) in the field frame
    assert all(abs(f - 1.0) < 1e-12 for f in frames[:5])  # held: above I_MR_FLOOR, below FRAME_REL * i_mR_ref
    assert abs(frames[5] - (-1j)) < 1e-12  # followed: the estimate along +b turns the frame by 90 degrees
    assert 0.05 < I_MR_FLOOR < 0.3 < FRAME_REL * i_mR_ref
    assert abs(frames[6] - (-1j)) < 1e-12 and abs(frames[7] - (-1j)) < 1e-12  # flux gone: held where it was again
