"""The quasi-LPV stator current controller of thesis Sec. 6.2 as a FOC part (runtime of the artifact).

`LPVCurrentLaw` runs a synthesised controller (an artifact of `bench synth current-controller`, i.e.
`synthesis.models.current_controller`) sample by sample, in the scheduled-signal form of 5.4.4:

    z̃_c = C_c2 x_c + D_c21 y,   w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c,
    u = C_c1 x_c + D_c11 y + D_c12 w_c,   x_c ← A_c x_c + B_c1 y + B_c2 w_c,

with the scheduling function (5.36) Δ_c(Δ) = N_− V_−^* (S^*PS − V_− N_− V_−^*)^{-1} V_+, S = [Δ; I],
[V_− V_+] = S^* U. Δ = diag(δ_1, δ_2) is real and diagonal, so S^*PS and V are evaluated entry by
entry, and the two small inversions (S^*PS − V_− N_− V_−^* and I − D_c22 Δ_c, both 2 x 2 for the
shipped artifacts) are closed-form (`bench.controllers.lpv_law.step22`; other sizes go through the generic
`bench.controllers.lpv_law.evaluate_into`). `current_update` is the controller's sample, written once: the Python
engine calls it on Python complex numbers, `bench.controllers.lpv_compiled` compiles it.

`LPVCurrentController` is the drop-in for `bench.controllers.foc.CurrentPI` (same ``update`` and
``reset``): y = ī_s,cc − ī_ref (6.2.2), δ_1 = ω_cc = the FOC's frame speed ω_mR (6.13),
δ_2 = i_sq/î_mR, output ū_s,cc limited to |u| ≤ u_max.

The δ_2 singularity at start-up (î_mR → 0, 6.2.1): δ_2 is computed as i_sq/max(î_mR, I_MR_FLOOR),
the same floor the FOC uses in ω_mR (4.5)/(6.13), so δ_2 = T_r (ω_cc − ω_r) stays exactly the slip
term of the frame the FOC really turns; then both δ are clipped to the design box
(|δ_1| ≤ 800 rad/s, |δ_2| ≤ 10). Clipping keeps Δ inside the set the controller was verified on,
so the scheduling stays finite and well-posed; while it clips (only when |i_sq| > 10·max(î_mR, 0.1 A),
i.e. asking for torque before the flux is there) the scheduled model is off by the clipped part and
the γ guarantee does not hold - the thesis' "performance may be degraded during start-up". In the
bench scenarios the magnetising lead-in keeps i_sq_ref ≈ 0 until î_mR has built up
(tests/test_lpv_current.py runs a start-up from zero flux).

Artifacts: `ARTIFACTS` maps the shipped rates (600 Hz, the thesis', and 3 kHz) to package data in
``bench/controllers/artifacts``; another artifact can be given by path.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bench.controllers.foc import I_MR_FLOOR
from bench.controllers.kernel_math import abs_checked
from bench.controllers.lpv_law import OF, ScheduledLaw, clip, commit, evaluate_into, step22
from bench.errors import BadInput
from bench.params import MotorParams
from synthesis.artifacts import ArtifactError, load_controller, motor_mismatch

DATA_DIR = Path(__file__).resolve().parent / "artifacts"
ARTIFACTS: dict[float, str] = {600.0: "current_controller_600Hz", 3000.0: "current_controller_3000Hz"}


def artifact_path(rate_hz: float, path: str = "") -> Path:
    """The artifact for a shipped rate, or `path` (without or with .json) if given."""
    if path:
        p = Path(path)
        return p.with_suffix("") if p.suffix in (".json", ".npz") else p
    if rate_hz not in ARTIFACTS:
        raise BadInput("controller.foc.lpv_current_rate",
                       f"shipped artifacts exist for {', '.join(f'{r:g}' for r in ARTIFACTS)} Hz, got {rate_hz:g} "
                       "(or give lpv_current_artifact = PATH)")  # fmt: skip
    return DATA_DIR / ARTIFACTS[rate_hz]


def scheduling(omega_mR: float, i_sq: float, i_mR: float, d1max: float, d2max: float
               ) -> tuple[float, float, float, float]:  # fmt: skip
    """(δ_1, δ_2) normalised, then clipped to the design box (6.17): δ_1 = ω_cc, δ_2 = i_sq/î_mR with î_mR floored
    (start-up)."""
    d1 = omega_mR / d1max
    d2 = i_sq / ((I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR) * d2max)
    return d1, d2, clip(d1, -1.0, 1.0), clip(d2, -1.0, 1.0)


def current_update(e: Any, r: Any, o: Any, dims: tuple, step22_path: bool, d1max: float, d2max: float,
                   i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float, u_max: float
                   ) -> tuple[complex, bool, bool, float, float]:  # fmt: skip
    """One sample of the LPV current controller (the kernel of `LPVCurrentController.update`) on its law's stores
    (`bench.controllers.lpv_law`): (u, saturated, clipped, delta1, delta2), the law's state advanced.
    ``step22_path``: the law is m_c = k_c = 2 (`step22`)."""
    d1, d2, c1, c2 = scheduling(omega_mR, i_sr.imag, i_mR, d1max, d2max)
    y = i_sr - i_ref  # y = ī_s − ī_ref (6.2.2)
    if step22_path:
        u = step22(e, r, o, dims[0], y, c1, c2)
    else:
        e[o[OF.Y]], r[o[OF.D]], r[o[OF.D] + 1] = y, c1, c2
        evaluate_into(e, r, o, dims, 0j)
        commit(e, o, dims[0])
        u = e[o[OF.U]]
    mag = abs_checked(u)
    saturated = mag > u_max
    if saturated:
        if mag == 0.0:  # (u_max < 0) CPython's message, which numba's is not
            raise ZeroDivisionError("float division by zero")
        u = u * (u_max / mag)
    return u, saturated, c1 != d1 or c2 != d2, c1 * d1max, c2 * d2max


class LPVCurrentLaw:
    """The LPV controller (5.57) + scheduling (5.36) of one artifact (a complex `ScheduledLaw`), one sample per
    `step` (5.4.4). Input y and output u are complex scalars; Δ = diag(d1, d2) in normalised units (|d| ≤ 1).
    """

    def __init__(self, path: str | Path) -> None:
        try:
            ctrl, doc = load_controller(path)
        except (ArtifactError, OSError, KeyError, ValueError) as e:
            raise BadInput("controller.foc.lpv_current_artifact",
                           f"a readable current-controller artifact (npz + JSON) is needed: {e}") from None  # fmt: skip
        K, S = ctrl.K, ctrl.scheduling
        if (K.n_y, K.n_u, S.n_wu, S.n_zu) != (1, 1, 2, 2):
            raise BadInput("controller.foc.lpv_current_artifact",
                           f"not a current-controller artifact (n_y={K.n_y}, n_u={K.n_u}, Δ {S.n_wu}x{S.n_zu})")  # fmt: skip
        self.doc = doc
        self.dt = float(K.dt)
        spec = doc.get("meta", {}).get("spec", {})
        self.delta1_max = float(spec.get("delta1_max", 800.0))
        self.delta2_max = float(spec.get("delta2_max", 10.0))
        try:
            self.generic = ScheduledLaw(ctrl, complex_entries=True)
        except ValueError as e:
            raise BadInput("controller.foc.lpv_current_artifact", str(e)) from None
        self.n_c, self.m_c, self.k_c = K.n_c, K.n_wc, K.n_zc
        #: the shipped shape (m_c = k_c = 2, four multipliers) runs the written-out `step22`
        self.step22 = (self.m_c, self.k_c, len(S.lam)) == (2, 2, 4)
        self.reset()

    def reset(self) -> None:
        self.generic.reset()

    @property
    def x(self) -> list[complex]:
        return self.generic.x

    @x.setter
    def x(self, value: list[complex]) -> None:
        self.generic.x = value

    def delta_c(self, d1: float, d2: float) -> list[list[complex]]:
        """Δ_c(Δ) of (5.36) for Δ = diag(d1, d2) (normalised)."""
        return self.generic.delta_c((d1, d2))

    def take_over(self, y: complex, d1: float, d2: float, u: complex) -> None:
        """The state whose output is ``u`` at ``y`` and Δ = diag(d1, d2), held (`ScheduledLaw.take_over`)."""
        self.generic.take_over([y], (d1, d2), [u], [0])

    def step(self, y: complex, d1: float, d2: float) -> complex:
        """u_k for y_k and Δ_k = diag(d1, d2); advances the controller state."""
        g = self.generic
        if self.step22:
            return step22(g.e, g.r, g.o, g.n_c, y, d1, d2)
        return g.step((y,), (d1, d2))[0]


class LPVCurrentController:
    """Drop-in for `CurrentPI`: the quasi-LPV current loop of 6.2 in rotor-flux coordinates.

    ``update(i_ref, i_sr, omega_mR, i_mR, u_max)`` returns ū_s,cc [V] with |u| ≤ u_max. The law
    runs at the artifact's rate; the FOC calls it every ``divisor`` base ticks.
    """

    def __init__(self, path: str | Path, motor: MotorParams) -> None:
        self.law = LPVCurrentLaw(path)
        diff = motor_mismatch(self.law.doc.get("meta", {}), motor)
        if diff:
            raise BadInput("controller.foc.lpv_current_artifact",
                           f"the artifact was designed for other motor data ({', '.join(diff)} differ from the rig's "
                           "nominal model); make one with `bench synth current-controller --rig RIG --out PATH`, then "
                           "-p lpv_current_artifact=PATH")  # fmt: skip
        self.T_r = motor.T_r
        self.reset()

    @property
    def dt(self) -> float:
        return self.law.dt

    def divisor(self, T_base: float) -> int:
        """Base ticks per controller sample; the artifact's period must be a multiple of T_base."""
        k = round(self.law.dt / T_base)
        if k < 1 or abs(k * T_base - self.law.dt) > 1e-9 * self.law.dt:
            raise BadInput("controller.foc.lpv_current_rate",
                           f"the artifact runs at {1 / self.law.dt:g} Hz, not an integer divisor of the loop's "
                           f"{1 / T_base:g} Hz")  # fmt: skip
        return k

    def reset(self) -> None:
        self.law.reset()
        self.saturated = False
        self.delta1 = self.delta2 = 0.0
        self.clipped = False

    def _deltas(self, i_sr: complex, omega_mR: float, i_mR: float) -> tuple[float, float]:
        """(δ_1, δ_2) normalised and clipped to the design box (as `current_update`)."""
        return scheduling(omega_mR, i_sr.imag, i_mR, self.law.delta1_max, self.law.delta2_max)[2:]

    def take_over(self, u_sr: complex, i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float) -> None:
        """Bumpless start: the law's state set so that at the last tick's inputs its output is the outgoing
        part's u_sr, nearest to the frozen law's steady state (`ScheduledLaw.take_over`)."""
        self.law.take_over(i_sr - i_ref, *self._deltas(i_sr, omega_mR, i_mR), u_sr)
        self.saturated = False

    def update(self, i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float, u_max: float) -> complex:
        law, g = self.law, self.law.generic
        u, self.saturated, self.clipped, self.delta1, self.delta2 = current_update(
            g.e, g.r, g.o, g.dims, law.step22, law.delta1_max, law.delta2_max, i_ref, i_sr, omega_mR, i_mR,
            u_max)
        return u
