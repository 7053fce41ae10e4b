"""Excitation controller for NARX data collection (thesis 6.4.2), built from the FOC's parts.

The experiment runs in "partial closed loop": a *loosely tuned* PI speed controller (Sec. 4.2.1,
`SpeedPI`) gives i_sq,ref, a P magnetising-current controller (Sec. 4.2.2, `FluxP`) gives i_sd,ref,
and small pseudo-random signals are added to both current references [Billings et al., 1992] so
the data show the open-loop behaviour and not only the closed loop's. Everything else - encoder
speed, the current-model flux observer (4.15) that 6.4.1 prescribes, the current PI with
decoupling (4.13)(4.14) - is the `FocController`, unchanged: this plugin composes one and wraps its
speed and flux controllers with `Dithered`.

The logged signals the data set is made of go through first-order low-pass filters (thesis: 100 Hz)
at the 3 kHz base rate; the data set reader decimates them to 600 Hz (`bench.daq.narx`):

    omega_f     encoder speed (per-tick count difference, unfiltered before this filter) [rad/s]
    i_mR_f      |i_m_hat| of the current-model observer [A]
    i_sd_ref_f  i_sd,ref including the dither [A]
    i_sq_ref_f  i_sq,ref including the dither [A]

The dither is a random level, uniform in [-a, a] (a = ``dither_amplitude``, thesis 0.8 A), held
for ``dither_hold`` base ticks (default 5: a new value every 600 Hz sample); d and q draw from two
streams seeded by ``seed``, so a run is reproducible.
"""

from __future__ import annotations

import math
import random
from dataclasses import replace
from typing import Any

from bench.controllers.base import Controller, ControllerContext
from bench.controllers.foc import FocController
from bench.controllers.schema import Param
from bench.errors import BadInput
from bench.hal import Measurement


class Dithered:
    """A reference generator (``SpeedPI`` or ``FluxP``) whose output gets a held random level added.

    ``update(*args)`` returns ``inner.update(*args) + d`` where d is redrawn uniformly in
    [-amplitude, amplitude] every ``hold`` calls; other attributes are the inner controller's.
    """

    def __init__(self, inner: Any, amplitude: float, hold: int, seed: int) -> None:
        self.inner, self.amplitude, self.hold, self.seed = inner, amplitude, hold, seed
        self.reset()

    def reset(self) -> None:
        if hasattr(self.inner, "reset"):
            self.inner.reset()
        self._rng = random.Random(self.seed)
        self._n = 0
        self.d = 0.0

    def update(self, *args: float) -> float:
        if self._n % self.hold == 0:
            self.d = self.amplitude * (2.0 * self._rng.random() - 1.0)
        self._n += 1
        return self.inner.update(*args) + self.d

    def __getattr__(self, name: str) -> Any:  # m_e_ref, K_m, ... of the wrapped controller
        if name == "inner":
            raise AttributeError(name)
        return getattr(self.inner, name)


class ExcitationController(Controller):
    name = "excitation"
    summary = "NARX data collection (6.4.2): loose speed PI + flux P, dithered current refs, 100 Hz logged filters"
    schema: dict[str, Param] = {
        # the FOC's own declarations, fixed for the experiment (a data set is not re-tuned half-way)
        **{k: replace(FocController.schema[k], tunable=False)
           for k in ("speed_filter_tau", "flux_Km", "current_wc", "u_margin", "delay_comp")},
        # loose speed PI: crossover Z_p K_p / J = 16 rad/s (6.4.2)
        "speed_Kp": replace(FocController.schema["speed_Kp"], default=0.1, tunable=False),
        "speed_Ti": replace(FocController.schema["speed_Ti"], default=0.25, tunable=False),
        "dither_amplitude": Param(0.8, "dither on both current references (6.4.2)", "A", ge=0, le=10),
        "dither_hold": Param(5, "base ticks between dither draws", ge=1, le=100_000),
        "seed": Param(0, "seed of the dither", ge=0, le=2**63 - 1),
        "log_filter_hz": Param(100.0, "first-order filters of the logged data-set signals (6.4.2)", "Hz", gt=0,
                               lt=1500),
    }  # fmt: skip
    _FOC_KEYS = ("speed_Kp", "speed_Ti", "speed_filter_tau", "flux_Km", "current_wc", "u_margin", "delay_comp")

    def __init__(self, ctx: ControllerContext, **params: Any) -> None:
        super().__init__(ctx, **params)
        p = self.p
        f_max = 0.5 / ctx.T_s
        if not 0 < p["log_filter_hz"] < f_max:
            raise BadInput("controller.excitation.log_filter_hz", f"must be in (0, {f_max:g}) Hz, got {p['log_filter_hz']}")
        # the flux observer is the current model (4.15), as 6.4.1 prescribes
        self.foc = FocController(ctx, observer="current_model", **{k: p[k] for k in self._FOC_KEYS})
        a, hold, seed = p["dither_amplitude"], p["dither_hold"], p["seed"]
        self.foc.speed = Dithered(self.foc.speed, a, hold, seed * 2 + 1)  # i_sq,ref dither
        self.foc.flux = Dithered(self.foc.flux, a, hold, seed * 2 + 2)  # i_sd,ref dither
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * p["log_filter_hz"] * ctx.T_s)
        self.fields = self.foc.fields + ("omega_f", "i_mR_f", "i_sd_ref_f", "i_sq_ref_f", "dither_d", "dither_q")
        self.reset()

    def reset(self) -> None:
        self.foc.reset()
        self.foc.flux.reset()
        self._f = [0.0, 0.0, 0.0, 0.0]

    @property
    def omega_u(self) -> float:
        """The wrapped FOC's field frequency (bench.hal.Command.omega_u: the drive's stall ride-through)."""
        return self.foc.omega_u

    def step(self, meas: Measurement, omega_ref: float, i_mR_ref: float) -> complex:
        foc = self.foc
        u = foc.step(meas, omega_ref, i_mR_ref)
        a, f = self._alpha, self._f
        f[0] += a * (foc.encoder.omega_raw - f[0])
        f[1] += a * (foc.i_mR_hat - f[1])
        f[2] += a * (foc.i_sd_ref - f[2])
        f[3] += a * (foc.i_sq_ref - f[3])
        return u

    def internals(self) -> tuple[float, ...]:
        f = self._f
        return self.foc.internals() + (f[0], f[1], f[2], f[3], self.foc.flux.d, self.foc.speed.d)
