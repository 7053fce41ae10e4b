"""The LPV speed controller of thesis 6.4.3 (and the robust one of 7.2) as a FOC part (runtime of the artifact).

`LPVSpeedController` is a drop-in for `bench.controllers.foc.SpeedPI` (same ``update``/``reset``; the FOC
calls it every ``divisor`` base ticks, 5 at 3 kHz for the 600 Hz design): ``update(omega_ref, omega,
i_mR, i_sd_ref)`` returns i_sq,ref. One sample, in the model's scaled signals (`synthesis.narx.Scaling`,
6.4.2):

1. w~ = (omega - omega_r0)/s_w (omega: the encoder speed through the FOC's first-order filter, set to the
   model's 100 Hz data filter, `speed_filter_tau`), w~_ref likewise, i~ = (i_mR_hat - i_mR0)/s_i, d~ from
   the i_sd,ref the traditional P controller of i_mR (4.2.2) has just set: the LPV controller's own
   i_sd,ref output is replaced by it, as the thesis does (it is logged, and stays ~0 by the design's penalty).
2. Scheduling: the NARX LFT's state x = [w~_k .. w~_{k-3}, d~_{k-1}, tau~_{k-1}] - x° from the measured
   histories and its input u = [i~_k, d~_k, tau~] - u°. tau~_k is not known yet (z_u,k depends on u_k,
   the algebraic loop of 6.4.3), so tau~_{k-1} is used, as the thesis does; with ``iterations`` > 0 the
   scheduling is re-evaluated with the new tau~_k that many times before the sample is committed.
   xi = C_u x + E_u u; delta_j = (sigma'_j(xi_j)/xi_j - c_j)/h_j (6.28), clipped to [-1, 1] (outside the
   active ranges the sector, and the guarantee, do not hold).
3. The controller (5.57)+(5.36) with y = w~ - w~_ref (`bench.controllers.lpv_law.ScheduledLaw`, Python
   floats), output [d~_lpv, tau~]; i_tau = s_tau tau~ + i_sq,ref0 i_mR0, i_sq,ref = i_tau / i_mR_hat (the
   inverse of the model's i_tau = i_sq,ref i_mR_hat), limited to |i_sq,ref| <= sqrt(I_max^2 - i_sd,ref^2)
   as the PI is (4.8). The tau~ actually applied (after the limit) enters the histories.

Start-up: the model only knows i_mR in the data's range (references 0.8-2.8 A). Until i_mR_hat first reaches
`START_I_MR` the controller outputs i_sq,ref = 0 and its state stays at zero (the histories are kept), so it
starts on built-up flux; the scenarios' magnetising lead-in holds the speed reference at 0 meanwhile.

Artifacts (`bench synth speed-controller`, `synthesis.models.speed_controller`): the controller npz + JSON,
whose ``meta.runtime`` holds the scaling, equilibrium and scheduling map. `SHIPPED` names the package-data
designs (nominal 6.4.3 and robust 7.2 at 600 Hz, nominal at 3 kHz); another one is given by path.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from bench.controllers.foc import I_MR_FLOOR
from bench.controllers.kernel_math import square
from bench.controllers.lpv_law import OF, ScheduledLaw, clip, commit, evaluate_into
from bench.errors import BadInput
from bench.params import MotorParams
from synthesis.artifacts import ArtifactError, load_controller, motor_mismatch

DATA_DIR = Path(__file__).resolve().parent / "artifacts"
SHIPPED: dict[str, str] = {"nominal": "speed_controller_600Hz", "robust": "speed_controller_robust_600Hz",
                           "nominal_3000Hz": "speed_controller_3000Hz"}
START_I_MR = 0.5  # [A] i_mR_hat the LPV speed controller waits for (start-up)
FIELD = "controller.foc.lpv_speed_artifact"


def artifact_path(name: str = "nominal") -> Path:
    """A shipped design by name (`SHIPPED`), or a path (without or with .json/.npz)."""
    if name in SHIPPED:
        return DATA_DIR / SHIPPED[name]
    if not name:
        raise BadInput(FIELD, f"a shipped design ({', '.join(SHIPPED)}) or an artifact path")
    p = Path(name)
    return p.with_suffix("") if p.suffix in (".json", ".npz") else p


def shift(h: Any, p: int, n: int, v: float) -> None:
    """h[p:p + n] = [v] + h[p:p + n - 1] (a history, newest first)."""
    for k in range(n - 1, 0, -1):
        h[p + k] = h[p + k - 1]
    if n:
        h[p] = v


def schedule_into(r: Any, pd: int, m: int, s: Any, so: Any, nx: int, ncu: int, i: float, d: float, tau: float
                  ) -> None:  # fmt: skip
    """delta_j of (6.28) at the histories and the inputs (i~, d~, tau~), clipped to [-1, 1], into r[pd:pd + m]. The
    speed part's store ``s`` holds, from the starts ``so``: the histories, x°, u°, C_u (m x ``ncu``) and E_u (m x 3)
    row-major, tanh(θ_b), c and h of the NARX LFT's scheduling map; x - x° has ``nx`` entries."""
    ph, px0, pu0, pCu, pEu, ptb, pc, phh = so
    nk = nx if nx < ncu else ncu
    u_0, u_1, u_2 = i - s[pu0], d - s[pu0 + 1], tau - s[pu0 + 2]
    for j in range(m):
        acc = 0.0
        for k in range(nk):
            acc = acc + s[pCu + j * ncu + k] * (s[ph + k] - s[px0 + k])
        xi = acc + s[pEu + 3 * j] * u_0 + s[pEu + 3 * j + 1] * u_1 + s[pEu + 3 * j + 2] * u_2
        # sigma'(xi)/xi of tanh(xi + b) - tanh(b) (synthesis.mlp_lft.secant_scalar, inlined)
        b = s[ptb + j]
        d1 = 1.0 - b * b
        if abs(xi) < 1e-6:
            g = d1 - b * d1 * xi + d1 * (3.0 * b * b - 1.0) / 3.0 * xi * xi
        else:
            tx = math.tanh(xi)
            g = tx * d1 / (1.0 + tx * b) / xi
        r[pd + j] = clip((g - s[pc + j]) / s[phh + j], -1.0, 1.0)


def speed_update(e: Any, r: Any, o: Any, dims: tuple, zero: Any, s: Any, so: Any, hdims: tuple, scaling: tuple,
                 state: tuple, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> tuple[float, tuple]:
    """One sample of the LPV speed controller (the kernel of `LPVSpeedController.update`, see the module docstring):
    (i_sq_ref, the next ``state``); the law's state and Δ (its stores ``e``, ``r``, `bench.controllers.lpv_law`) and
    the histories (in ``s``, `schedule_into`) advanced. ``state`` = (active, tau~_{k-1}, m_e_ref, i_sd_lpv, saturated);
    ``hdims`` = (n, n_i − 1, n_u − 1, iterations, n_x, n of C_u's rows); ``scaling`` = (ω_r0, σ_ω, i_mR0, σ_i,
    i_sd,ref0, σ_d, i_τ0, σ_τ, I_max, k_torque, 2.0): the exponent of the squares given at run time
    (`bench.controllers.kernel_math.square`)."""
    w0, sw, i0, si, d0, sd, t0, st, I_max, k_torque, two = scaling
    n, nih, ndh, iterations, nx, ncu = hdims
    active, tau_prev, m_e_ref, i_sd_lpv, saturated = state
    ph, pu0, pu, pd, m = so[0], so[2], o[OF.U], o[OF.D], dims[5]
    w = (omega - w0) / sw
    i = (i_mR - i0) / si
    d = (i_sd_ref - d0) / sd
    shift(s, ph, n, w)
    if not active and i_mR >= START_I_MR:
        active = True
        for k in range(dims[0]):  # the law's reset
            e[o[OF.X] + k] = zero
    floor = I_MR_FLOOR if I_MR_FLOOR > i_mR else i_mR
    i_sq = 0.0
    if active:
        e[o[OF.Y]] = w - (omega_ref - w0) / sw  # e = w~ - w~_ref (Fig. 6.13)
        schedule_into(r, pd, m, s, so, nx, ncu, i, d, tau_prev)  # u_{k-1} for u_k (6.4.3)
        evaluate_into(e, r, o, dims, zero)
        for _ in range(iterations):
            schedule_into(r, pd, m, s, so, nx, ncu, i, d, e[pu + 1] + s[pu0 + 2])
            evaluate_into(e, r, o, dims, zero)
        commit(e, o, dims[0])
        i_sd_lpv = (e[pu] + s[pu0 + 1]) * sd + d0
        i_tau = (e[pu + 1] + s[pu0 + 2]) * st + t0
        i_sq = i_tau / floor
        q = square(I_max, two) - square(i_sd_ref, two)
        lim = math.sqrt(0.0 if 0.0 > q else q)  # as (4.8)
        saturated = abs(i_sq) > lim
        i_sq = clip(i_sq, -lim, lim)
    tau = (i_sq * i_mR - t0) / st  # the i_tau applied, scaled
    shift(s, ph + n, nih, i)
    if ndh:
        shift(s, ph + n + nih, ndh, d)
        shift(s, ph + n + nih + ndh, ndh, tau)
    return i_sq, (active, tau, k_torque * floor * i_sq, i_sd_lpv, saturated)


class LPVSpeedController:
    """Drop-in for `SpeedPI`: the scheduled LPV speed law of one artifact (see the module docstring)."""

    fields = ("lpv_delta1", "lpv_delta2", "lpv_i_sd_ref", "lpv_active")

    def __init__(self, path: str | Path, motor: MotorParams, I_max: float, *, iterations: int = 0) -> None:
        try:
            ctrl, doc = load_controller(path)
        except (ArtifactError, OSError, KeyError, ValueError) as e:
            raise BadInput(FIELD, f"a readable speed-controller artifact (npz + JSON) is needed: {e}") from None
        meta = doc.get("meta", {})
        rt = meta.get("runtime")
        K, S = ctrl.K, ctrl.scheduling
        if meta.get("design") != "speed_controller" or rt is None or (K.n_y, K.n_u) != (1, 2) or S.n_wu != S.n_zu:
            raise BadInput(FIELD, f"{path} is not a speed-controller artifact (`bench synth speed-controller`)")
        diff = motor_mismatch(meta, motor)
        if diff:
            raise BadInput(FIELD, f"the artifact was designed for other motor data ({', '.join(diff)} differ from "
                                  "the rig's nominal model); make one with `bench synth speed-controller --model MODEL --rig RIG "
                                  "--out PATH` (MODEL: `bench train narx` on this rig's data), then "
                                  "-p lpv_speed_artifact=PATH")  # fmt: skip
        if not isinstance(iterations, int) or not 0 <= iterations <= 10:
            raise BadInput("controller.foc.lpv_speed_iterations", f"must be an integer in [0, 10], got {iterations!r}")
        self.doc, self.iterations = doc, iterations
        self.law = ScheduledLaw(ctrl)
        self.dt = float(K.dt)
        self.I_max, self.k_torque = I_max, motor.torque_constant
        sc = rt["scaling"]
        self._w0, self._sw = sc["omega_r0"], sc["sigma_omega"]
        self._i0, self._si = sc["i_mR0"], sc["sigma_i"]
        self._d0, self._sd = sc["i_sd_ref0"], sc["sigma_d"]
        self._t0, self._st = sc["i_sq_ref0"] * sc["i_mR0"], sc["sigma_tau"]
        o = rt["orders"]
        self._n, self._ni, self._nu = o["n"], o["n_i"], o["n_u"]
        self._x0 = [float(v) for v in rt["x0"]]
        self._u0 = [float(v) for v in rt["u0"]]
        self._Cu = [[float(v) for v in r] for r in rt["C_u"]]
        self._Eu = [[float(v) for v in r] for r in rt["E_u"]]
        self._tb = [math.tanh(float(b)) for b in rt["theta_b"]]
        self._c = [float(v) for v in rt["c"]]
        self._h = [float(v) for v in rt["h"]]
        if len(self._Cu) != self.law.m:
            raise BadInput(FIELD, "scheduling map and controller disagree on the number of residual gains")
        m = self.law.m
        if self._n < 1 or len(self._u0) < 3 or any(len(e) < 3 for e in self._Eu) or \
                any(len(v) != m for v in (self._Eu, self._tb, self._c, self._h)) or \
                len({len(r) for r in self._Cu}) > 1:  # fmt: skip
            raise BadInput(FIELD, "the scheduling map's sizes disagree (a speed history, three inputs, m rows each)")
        self._orders()
        self._scaling = (self._w0, self._sw, self._i0, self._si, self._d0, self._sd, self._t0, self._st, I_max,
                         self.k_torque, 2.0)  # fmt: skip
        #: the model's data were the encoder speed through this first-order filter (6.4.2: 100 Hz)
        self.speed_filter_tau = 1.0 / (2.0 * math.pi * float(rt["log_filter_hz"]))
        self.reset()

    def divisor(self, T_base: float) -> int:
        """Base ticks per controller sample; the artifact's period must be a multiple of T_base."""
        k = round(self.dt / T_base)
        if k < 1 or abs(k * T_base - self.dt) > 1e-9 * self.dt:
            raise BadInput(FIELD, f"the artifact runs at {1 / self.dt:g} Hz, not an integer divisor of the loop's "
                                  f"{1 / T_base:g} Hz")  # fmt: skip
        return k

    def _orders(self) -> None:
        """The histories' lengths (n, n_i − 1, n_u − 1), the iterations, the entries of x - x° in (6.28) and of C_u's
        rows, from the model's orders; the store of the histories and the scheduling map (`schedule_into`)."""
        nih, ndh = max(self._ni - 1, 0), max(self._nu - 1, 0)
        nx = min(self._n + nih + 2 * ndh, len(self._x0))
        self._hdims = (self._n, nih, ndh, self.iterations, nx, len(self._Cu[0]) if self.law.m else 0)
        blocks = ([0.0] * (self._n + nih + 2 * ndh), self._x0[:nx], self._u0[:3], [v for r in self._Cu for v in r],
                  [v for r in self._Eu for v in r[:3]], self._tb, self._c, self._h)  # fmt: skip
        self._so = tuple(sum(len(b) for b in blocks[:k]) for k in range(len(blocks)))
        self._s = [v for b in blocks for v in b]

    @property
    def _hist(self) -> list[float]:
        """The scaled histories w~ (n), i~ (n_i − 1), d~ and tau~ (n_u − 1 each), newest first (a copy)."""
        return self._s[:self._so[1]]

    @_hist.setter
    def _hist(self, value: list[float]) -> None:
        if len(value) != self._so[1]:
            raise ValueError(f"the histories have {self._so[1]} entries, got {len(value)}")
        self._s[:self._so[1]] = value

    def reset(self) -> None:
        self.law.reset()
        self.active = False
        n, nih, ndh = self._hdims[:3]
        u0 = self._u0
        self._hist = [self._x0[0]] * n + [u0[0]] * nih + [u0[1]] * ndh + [u0[2]] * ndh  # at the equilibrium
        self._tau_prev = u0[2]
        self.law.d = [0.0] * self.law.m
        self.m_e_ref = 0.0
        self.i_sd_lpv = 0.0
        self.saturated = False

    @property
    def delta(self) -> list[float]:
        """The scheduling's Δ of the last sample (6.28)."""
        return self.law.d

    def take_over(self, i_sq: float, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> None:
        """Bumpless start (a switch from another speed part): the histories as in steady state at the last
        tick's values, and the law's state set so that its torque output equals the outgoing part's
        (`ScheduledLaw.take_over`); ``omega`` is the encoder speed through the filter in force until now."""
        w = (omega - self._w0) / self._sw
        i = (i_mR - self._i0) / self._si
        d = (i_sd_ref - self._d0) / self._sd
        tau = (i_sq * i_mR - self._t0) / self._st
        self.reset()
        n, nih, ndh = self._hdims[:3]
        self._hist = [w] * n + [i] * nih + [d] * ndh + [tau] * ndh
        self._tau_prev = tau
        self.m_e_ref = self.k_torque * max(i_mR, I_MR_FLOOR) * i_sq
        if i_mR >= START_I_MR:  # else it starts as at start-up, when the flux is there
            self.active = True
            g = self.law
            schedule_into(g.r, g.o[OF.D], g.m, self._s, self._so, *self._hdims[4:], i, d, tau)
            y = (w - (omega_ref - self._w0) / self._sw,)
            g.take_over(y, g.d, [tau - self._u0[2]], [1])

    def update(self, omega_ref: float, omega: float, i_mR: float, i_sd_ref: float) -> float:
        """Return i_sq,ref [A] (see the module docstring)."""
        g = self.law
        i_sq, state = speed_update(g.e, g.r, g.o, g.dims, g.zero, self._s, self._so, self._hdims, self._scaling,
                                   (self.active, self._tau_prev, self.m_e_ref, self.i_sd_lpv, self.saturated),
                                   omega_ref, omega, i_mR, i_sd_ref)  # fmt: skip
        self.active, self._tau_prev, self.m_e_ref, self.i_sd_lpv, self.saturated = state
        return i_sq

    def internals(self) -> tuple[float, ...]:
        d = self.delta
        return (d[0] if d else 0.0, d[1] if len(d) > 1 else 0.0, self.i_sd_lpv, float(self.active))

    def info(self) -> dict[str, Any]:
        meta = self.doc.get("meta", {})
        return {"gamma": self.doc.get("gamma"), "rate_hz": 1.0 / self.dt, "robust": meta.get("robust", False)}
