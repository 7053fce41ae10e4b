"""Test signals of the standstill identification: the DC staircase and the multisine, as one plan.

`Plan` is built from the plugin's parameters alone, so the controller that plays it and the fit
that reads the log afterwards (`bench.workflows.commission.identify`) agree on every window without storing
anything but the parameters.

* **DC staircase**: ``dc_levels`` current levels per polarity up to ``dc_current``, played in
  ascending order, I (k - 1/2)/(n - 1/2) for k = -n..-1, 1..n: every step has the same size, the
  one through zero too, so each window holds the same residue of the rotor transient (time
  constant L'_m/R'_r, about 0.1 s for (3.57)), a constant the fit's intercepts absorb and that
  has no AC content; the first level, reached from zero, settles longer.
* **multisine**: lines at integer multiples n_k f_0 of ``ac_f_min`` (so every line completes a
  whole number of periods in 1/f_0), log-spaced up to ``ac_f_max``, on the odd harmonics only
  (``ac_grid = "odd"``, an *odd multisine*: a sum or difference of two odd harmonics is even, so the
  quadratic part of a saturating main flux, ψ(b + x) = ψ(b) + L'_m x + ½ (dL'_m/di) x², falls between the
  lines and leaves their impedance alone; on every harmonic, ``"all"``, 1 + 2 = 3, 2 + 3 = 5, … put it on
  the lines and the fit read it as impedance: L'_m 4-5 % low and R_r +0.4-0.9 % on saturating fleet
  motors, docs/results/identify-intervals.md; older logs, without the parameter, were ``"all"``), equal
  amplitudes, Schroeder
  phases φ_k = -π k (k-1) / K (low crest factor), scaled so the peak is ``ac_amplitude``. It rides
  on a DC bias ``ac_bias`` on the same axis, so the current never crosses zero: the inverter's
  voltage error stays on one branch of its curve (the knee at zero current is never visited) and
  the flux stays at one operating point. It fades in over `FADE` s inside the settling time.
* **saturation check** (``sat_bias`` > 0): the same multisine once more on a second DC bias
  ``sat_bias``, its amplitude scaled by sat_bias/ac_bias (the same relative swing of the flux),
  after a settling time ``sat_settle``, analysed over the same ``ac_periods``. At standstill the
  rotor carries no current at DC, so the bias sets the main flux (ψ_m = L_m i_bias) and the
  multisine measures the *incremental* inductance dψ/di there; on a linear machine it is the same
  at both biases, on a saturating one it falls as the bias grows (`bench.workflows.commission.identify`
  compares the two). Its segment has kind ``"sat"``.
* **warming check**: the same short DC pattern at the start and at the end of the test:
  +``dc_current`` (settling 2 ``check_settle``: it is reached from 0 A at the start, from the
  multisine's bias at the end), then -``dc_current`` (``check_settle``), ``check_average``
  averaging each. The statistic (u(+I) - u(-I)) / (i(+I) - i(-I)) is R_s plus a bias from the
  inverter's voltage error; the bias is the same at both ends (same levels), so the difference
  end - start is the change of R_s while the test ran (the windings warming). No rest at 0 A: a
  current held at zero makes the dead time's error chatter with the current's noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

FADE = 0.1  # [s] multisine fade-in
FIRST_EXTRA = 0.5  # [s] extra settling of the first DC level (reached from 0 A)
EPS = 1e-9  # [s] loop times are k T_s and segment bounds sums of floats: compare with this slack (as ticks)
END_TICKS = 0.002  # [s] after the last level: the slewed ramp back to 0 A and this, then the run ends
# (no dwell at 0 A: there the dead time's error chatters with the current's noise, a voltage vector
# that jumps by pi - which the supervisor's encoder-stuck check reads as a rotating field)


@dataclass(frozen=True)
class Segment:
    kind: str  # "dc" (staircase), "ac" (multisine), "sat" (multisine, second bias), "chk0" / "chk1" (warming check)
    t0: float  # [s] loop time the segment starts (its reference is set from here)
    t1: float  # [s] end
    a0: float  # [s] analysis window [a0, t1)
    level: float  # DC current or the multisine's bias [A]


@dataclass(frozen=True)
class Multisine:
    f0: float  # [Hz] frequency resolution; the common period is 1/f0
    harmonics: tuple[int, ...]  # line n_k at n_k f0
    amplitude: float  # [A] per line
    phases: tuple[float, ...]  # [rad]
    peak: float = 0.0  # [A] largest |value| over a period

    @property
    def freqs(self) -> np.ndarray:
        return self.f0 * np.asarray(self.harmonics, dtype=float)

    def __call__(self, tau: float) -> float:
        """The signal at time ``tau`` [s] since its start (no fade) [A]."""
        a, f0 = self.amplitude, 2.0 * math.pi * self.f0
        return a * sum(math.sin(f0 * n * tau + ph) for n, ph in zip(self.harmonics, self.phases))

    @classmethod
    def design(cls, f_min: float, f_max: float, lines: int, peak: float, grid: str = "odd") -> "Multisine":
        """``lines`` log-spaced harmonics of ``f_min`` up to ``f_max`` (fewer where two round to one), on the odd
        harmonics (``grid = "odd"``) or on every one (``"all"``; module docstring); Schroeder phases, scaled to
        ``peak``."""
        n_max = max(1, int(math.floor(f_max / f_min + 1e-9)))
        snap = (lambda x: 2 * int(round((x - 1.0) / 2.0)) + 1) if grid == "odd" else (lambda x: int(round(x)))
        top = n_max - 1 + n_max % 2 if grid == "odd" else n_max  # the highest line allowed on the grid
        ns = sorted({min(snap(x), top) for x in np.geomspace(1.0, n_max, lines)})
        K = len(ns)
        phases = tuple(-math.pi * k * (k - 1) / K for k in range(1, K + 1))
        tau = np.arange(0, 1.0 / f_min, 1.0 / (50.0 * f_min * n_max))
        w = 2.0 * math.pi * f_min * np.asarray(ns, dtype=float)
        worst = float(np.max(np.abs(np.sin(np.outer(tau, w) + np.asarray(phases)).sum(axis=1))))
        return cls(f_min, tuple(ns), peak / worst, phases, peak)


@dataclass(frozen=True)
class Plan:
    segments: tuple[Segment, ...]
    multisine: Multisine
    duration: float  # [s] the whole run
    sat_multisine: Multisine | None = None  # the multisine on the second bias (None: no saturation check)

    @classmethod
    def from_params(cls, p: dict[str, Any]) -> "Plan":
        n, I = p["dc_levels"], p["dc_current"]
        pos = [I * (k - 0.5) / (n - 0.5) for k in range(1, n + 1)]  # equal steps, across zero too
        levels = [-x for x in reversed(pos)] + pos
        segs: list[Segment] = []
        t = 0.0

        def add(kind: str, settle: float, average: float, level: float) -> None:
            nonlocal t
            segs.append(Segment(kind, t, t + settle + average, t + settle, level))
            t = segs[-1].t1

        def check(kind: str) -> None:  # the first level settles twice as long: its step differs at the two ends
            for lev, k in ((I, 2.0), (-I, 1.0)):
                add(kind, k * p["check_settle"], p["check_average"], lev)

        check("chk0")
        for j, lev in enumerate(levels):
            add("dc", p["dc_settle"] + (FIRST_EXTRA if j == 0 else 0.0), p["dc_average"], lev)
        ms = Multisine.design(p["ac_f_min"], p["ac_f_max"], p["ac_lines"], p["ac_amplitude"], p.get("ac_grid", "all"))
        add("ac", max(p["ac_settle"], FADE), p["ac_periods"] / p["ac_f_min"], p["ac_bias"])
        sat_bias = p.get("sat_bias", 0.0)  # absent in the logs of older tests: no saturation check
        sat_ms = None
        if sat_bias > 0 and p["ac_bias"] > 0:
            r = sat_bias / p["ac_bias"]
            sat_ms = replace(ms, amplitude=ms.amplitude * r, peak=ms.peak * r)
            add("sat", max(p.get("sat_settle", 1.0), FADE), p["ac_periods"] / p["ac_f_min"], sat_bias)
        check("chk1")
        return cls(tuple(segs), ms, segs[-1].t1 + abs(segs[-1].level) / p["slew"] + END_TICKS, sat_ms)

    def checks(self, kind: str) -> list[Segment]:
        """The warming check's two levels at the start (``"chk0"``) or the end (``"chk1"``)."""
        return [s for s in self.segments if s.kind == kind]

    @property
    def dc(self) -> list[Segment]:
        return [s for s in self.segments if s.kind == "dc"]

    @property
    def ac(self) -> Segment:
        return next(s for s in self.segments if s.kind == "ac")

    @property
    def sat(self) -> Segment | None:
        """The saturation check's multisine segment (None without one)."""
        return next((s for s in self.segments if s.kind == "sat"), None)

    @property
    def peak_current(self) -> float:
        """Largest current the plan asks for [A] (before the controller's slew limit)."""
        lv = max(abs(s.level) for s in self.segments if s.kind not in ("ac", "sat"))
        out = max(lv, abs(self.ac.level) + self.multisine.peak)
        if self.sat is not None and self.sat_multisine is not None:
            out = max(out, abs(self.sat.level) + self.sat_multisine.peak)
        return out

    def reference(self, t: float) -> tuple[int, float, float]:
        """(segment index or -1 after the last, DC target [A], multisine value [A]) at loop time t."""
        for j, s in enumerate(self.segments):
            if t < s.t1 - EPS:
                if s.kind in ("ac", "sat"):
                    tau = t - s.t0
                    ms = self.multisine if s.kind == "ac" else self.sat_multisine
                    return j, s.level, min(1.0, tau / FADE) * ms(tau)
                return j, s.level, 0.0
        return -1, 0.0, 0.0
