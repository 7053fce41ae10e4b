"""The quasi-LPV stator current controller of thesis Sec. 6.2 as a FOC part (runtime of the artifact).

`LPVCurrentLaw` runs a synthesised controller (an artifact of `bench synth current-controller`, i.e.
`synthesis.models.current_controller`) sample by sample, in the scheduled-signal form of 5.4.4:

    z̃_c = C_c2 x_c + D_c21 y,   w_c = Δ_c (I − D_c22 Δ_c)^{-1} z̃_c,
    u = C_c1 x_c + D_c11 y + D_c12 w_c,   x_c ← A_c x_c + B_c1 y + B_c2 w_c,

with the scheduling function (5.36) Δ_c(Δ) = N_− V_−^* (S^*PS − V_− N_− V_−^*)^{-1} V_+, S = [Δ; I],
[V_− V_+] = S^* U. Δ = diag(δ_1, δ_2) is real and diagonal, so S^*PS and V are evaluated entry by
entry, and the two small inversions (S^*PS − V_− N_− V_−^* and I − D_c22 Δ_c, both 2 x 2 for the
shipped artifacts) are closed-form (`_step22`; other sizes go through the generic
`bench.controllers.lpv_law.ScheduledLaw`). Everything per tick is Python complex/float arithmetic: no numpy.

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

from bench.controllers.foc import I_MR_FLOOR
from bench.controllers.lpv_law import ScheduledLaw
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


def _rows(M) -> list[list[complex]]:  # noqa: ANN001
    return [[complex(v) for v in row] for row in M]


class LPVCurrentLaw:
    """The LPV controller (5.57) + scheduling (5.36) of one artifact, one sample per `step` (5.4.4).

    Input y and output u are complex scalars; Δ = diag(d1, d2) in normalised units (|d| ≤ 1).
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
        meta = doc.get("meta", {})
        spec = meta.get("spec", {})
        self.delta1_max = float(spec.get("delta1_max", 800.0))
        self.delta2_max = float(spec.get("delta2_max", 10.0))
        self.n_c, self.m_c, self.k_c = K.n_c, K.n_wc, K.n_zc
        if self.m_c != S.m_c or self.k_c != S.k_c:
            raise BadInput("controller.foc.lpv_current_artifact", "scheduling and controller sizes disagree")
        self._Ac, self._Bc1, self._Bc2 = _rows(K.A_c), [complex(v) for v in K.B_c1[:, 0]], _rows(K.B_c2)
        self._Cc1, self._Dc11, self._Dc12 = [complex(v) for v in K.C_c1[0]], complex(K.D_c11[0, 0]), [complex(v) for v in K.D_c12[0]]
        self._Cc2, self._Dc21, self._Dc22 = _rows(K.C_c2), [complex(v) for v in K.D_c21[:, 0]], _rows(K.D_c22)
        P = S.P
        self._Q = _rows(P[:2, :2])
        self._S = _rows(P[:2, 2:])
        self._R = _rows(P[2:, 2:])
        self._Uw = _rows(S.U[:2])
        self._Uz = _rows(S.U[2:])
        self._lam = [float(v) for v in S.lam]
        self._generic = ScheduledLaw(ctrl)  # any m_c, k_c
        self.reset()

    def reset(self) -> None:
        self.x = [0j] * self.n_c

    def delta_c(self, d1: float, d2: float) -> list[list[complex]]:
        """Δ_c(Δ) of (5.36) for Δ = diag(d1, d2) (normalised)."""
        return self._generic.delta_c((d1, d2))

    def take_over(self, y: complex, d1: float, d2: float, u: complex) -> None:
        """The state whose output is ``u`` at ``y`` and Δ = diag(d1, d2), held (`ScheduledLaw.take_over`)."""
        g = self._generic
        g.take_over([y], (d1, d2), [u], [0])
        self.x = list(g.x)

    def step(self, y: complex, d1: float, d2: float) -> complex:
        """u_k for y_k and Δ_k = diag(d1, d2); advances the controller state."""
        if self.m_c == 2 and self.k_c == 2:
            return self._step22(y, d1, d2)
        return self._step_generic(y, d1, d2)

    def _step22(self, y: complex, d1: float, d2: float) -> complex:
        """`step` written out for m_c = k_c = 2 (both shipped artifacts): about half the cost."""
        (q00, q01), (q10, q11) = self._Q
        (s00, s01), (s10, s11) = self._S
        (r00, r01), (r10, r11) = self._R
        w0, w1 = self._Uw
        z0, z1 = self._Uz
        l0, l1, l2, l3 = self._lam
        # V = S^* U = Δ U_w + U_z (rows i = 0, 1; columns: two of N_−, two of N_+)
        a0, a1, a2, a3 = d1 * w0[0] + z0[0], d1 * w0[1] + z0[1], d1 * w0[2] + z0[2], d1 * w0[3] + z0[3]
        b0, b1, b2, b3 = d2 * w1[0] + z1[0], d2 * w1[1] + z1[1], d2 * w1[2] + z1[2], d2 * w1[3] + z1[3]
        # M = S^*PS − V_− N_− V_−^*
        m00 = d1 * d1 * q00 + d1 * (s00 + s00.conjugate()) + r00 - l0 * a0 * a0.conjugate() - l1 * a1 * a1.conjugate()
        m01 = d1 * d2 * q01 + d1 * s01 + d2 * s10.conjugate() + r01 - l0 * a0 * b0.conjugate() - l1 * a1 * b1.conjugate()
        m10 = d2 * d1 * q10 + d2 * s10 + d1 * s01.conjugate() + r10 - l0 * b0 * a0.conjugate() - l1 * b1 * a1.conjugate()
        m11 = d2 * d2 * q11 + d2 * (s11 + s11.conjugate()) + r11 - l0 * b0 * b0.conjugate() - l1 * b1 * b1.conjugate()
        det = m00 * m11 - m01 * m10
        # M^{-1} V_+
        p0 = (m11 * a2 - m01 * b2) / det
        p1 = (m11 * a3 - m01 * b3) / det
        t0 = (m00 * b2 - m10 * a2) / det
        t1 = (m00 * b3 - m10 * a3) / det
        # Δ_c = N_− V_−^* M^{-1} V_+
        c00 = l0 * (a0.conjugate() * p0 + b0.conjugate() * t0)
        c01 = l0 * (a0.conjugate() * p1 + b0.conjugate() * t1)
        c10 = l1 * (a1.conjugate() * p0 + b1.conjugate() * t0)
        c11 = l1 * (a1.conjugate() * p1 + b1.conjugate() * t1)
        x = self.x
        Cc2, Dc21 = self._Cc2, self._Dc21
        zt0 = sum(c * xi for c, xi in zip(Cc2[0], x)) + Dc21[0] * y
        zt1 = sum(c * xi for c, xi in zip(Cc2[1], x)) + Dc21[1] * y
        (e00, e01), (e10, e11) = self._Dc22
        # L = I − D_c22 Δ_c, v = L^{-1} z̃, w_c = Δ_c v
        g00 = 1.0 - (e00 * c00 + e01 * c10)
        g01 = -(e00 * c01 + e01 * c11)
        g10 = -(e10 * c00 + e11 * c10)
        g11 = 1.0 - (e10 * c01 + e11 * c11)
        dg = g00 * g11 - g01 * g10
        v0 = (g11 * zt0 - g01 * zt1) / dg
        v1 = (g00 * zt1 - g10 * zt0) / dg
        wc0 = c00 * v0 + c01 * v1
        wc1 = c10 * v0 + c11 * v1
        Dc12 = self._Dc12
        u = sum(c * xi for c, xi in zip(self._Cc1, x)) + self._Dc11 * y + Dc12[0] * wc0 + Dc12[1] * wc1
        self.x = [sum(a * xi for a, xi in zip(row, x)) + b1 * y + b2[0] * wc0 + b2[1] * wc1
                  for row, b1, b2 in zip(self._Ac, self._Bc1, self._Bc2)]  # fmt: skip
        return u

    def _step_generic(self, y: complex, d1: float, d2: float) -> complex:
        g = self._generic
        g.x = self.x
        u = g.step((y,), (d1, d2))[0]
        self.x = g.x
        return u


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
        """(δ_1, δ_2) normalised and clipped to the design box."""
        law = self.law
        d1 = omega_mR / law.delta1_max  # δ_1 = ω_cc (6.17)
        d2 = i_sr.imag / (max(i_mR, I_MR_FLOOR) * law.delta2_max)  # δ_2 = i_sq/î_mR, floored (start-up)
        c1 = min(max(d1, -1.0), 1.0)
        c2 = min(max(d2, -1.0), 1.0)
        self.clipped = c1 != d1 or c2 != d2
        return c1, c2

    def take_over(self, u_sr: complex, i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float) -> None:
        """Bumpless start: the law's state set so that at the last tick's inputs its output is the outgoing
        part's u_sr, nearest to the frozen law's steady state (`ScheduledLaw.take_over`)."""
        self.law.take_over(i_sr - i_ref, *self._deltas(i_sr, omega_mR, i_mR), u_sr)
        self.saturated = False

    def update(self, i_ref: complex, i_sr: complex, omega_mR: float, i_mR: float, u_max: float) -> complex:
        law = self.law
        c1, c2 = self._deltas(i_sr, omega_mR, i_mR)
        self.delta1, self.delta2 = c1 * law.delta1_max, c2 * law.delta2_max
        u = law.step(i_sr - i_ref, c1, c2)  # y = ī_s − ī_ref (6.2.2)
        mag = abs(u)
        self.saturated = mag > u_max
        if self.saturated:
            u *= u_max / mag
        return u
