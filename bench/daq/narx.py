"""The NARX excitation experiment of thesis 6.4.2 and its data set: definition and reading.

Collection (`bench.workflows.narx.collect`) is an ordinary bench session (`bench.runtime.session.run`: HAL, supervisor,
timed loop, MCAP log) with

* the ``excitation`` controller plugin (loose speed PI, P flux control, 0.8 A dither on both current
  references, 100 Hz logged filters; `bench.controllers.excitation`), and
* a scenario built from the seed (`excitation_scenario`): speed-reference steps of random length
  and level in [-250, 250] rad/s, i_mR-reference steps of random length and level in [0.8, 2.8] A,
  and the speed-dependent load m_L = 8(1 - 2/(1 + e^{0.01 omega_r})) of 6.4.1 (computed by the PC
  from the measured speed, as on the rig; the model never sees it),

so it runs unchanged against any rig file. The log carries a ``narx`` metadata record with every
setting needed to regenerate it (`NarxExperiment.as_dict`) and the data-set definition.

Reading (`read_signals`): the filtered /ctrl signals, decimated from the loop rate to 600 Hz, from the
end of the magnetising lead-in on: omega_r, i_mR_hat, i_sd_ref, i_sq_ref, and i_tau = i_sq_ref * i_mR_hat
(6.4.2). Scaling to the thesis' normalised signals lives with the model (`synthesis.narx.Scaling`).
"""

from __future__ import annotations

import bisect
import hashlib
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bench.core import load_profiles as lp
from bench.errors import BadInput
from bench.core.scenarios import Scenario
from bench.daq.reader import LogReader

FORMAT = "imbench.narx_dataset"
FORMAT_VERSION = "1.0"
LEAD_IN = 0.5  # [s] speed reference 0 while the flux builds; data start after it


@dataclass(frozen=True)
class NarxExperiment:
    """Settings of one excitation run (6.4.2). Everything random follows from ``seed``."""

    seed: int = 0
    samples: int = 22000  # data-set samples at ``sample_hz`` (thesis: 22000 per set)
    sample_hz: float = 600.0  # data-set rate after decimation (thesis: 600 Hz)
    omega_max: float = 250.0  # [rad/s] speed-reference levels uniform in [-omega_max, omega_max]
    omega_hold: tuple[float, float] = (0.3, 1.5)  # [s] speed-step lengths, uniform
    i_mR_range: tuple[float, float] = (0.8, 2.8)  # [A] i_mR-reference levels, uniform
    i_mR_hold: tuple[float, float] = (0.5, 3.0)  # [s] i_mR-step lengths, uniform
    load_max: float = 8.0  # [N m] m_L = load_max (1 - 2/(1 + e^{load_k omega_r}))
    load_k: float = 0.01  # [s/rad]
    lead_in: float = LEAD_IN  # [s]
    controller: dict[str, Any] = field(default_factory=dict)  # excitation-controller parameters (seed added)

    def validate(self) -> None:
        if not 1 <= self.samples <= 10_000_000:
            raise BadInput("--samples", f"must be an integer in [1, 10000000], got {self.samples}")
        if not (math.isfinite(self.sample_hz) and self.sample_hz > 0):
            raise BadInput("sample_hz", f"must be > 0 Hz, got {self.sample_hz}")
        if not 0 < self.omega_max <= 1000:
            raise BadInput("omega_max", f"must be in (0, 1000] rad/s, got {self.omega_max}")
        lo, hi = self.i_mR_range
        if not 0 < lo <= hi:
            raise BadInput("i_mR_range", f"must satisfy 0 < low <= high [A], got {self.i_mR_range}")
        for name, (a, b) in (("omega_hold", self.omega_hold), ("i_mR_hold", self.i_mR_hold)):
            if not 0 < a <= b:
                raise BadInput(name, f"must satisfy 0 < min <= max [s], got {(a, b)}")

    @property
    def duration(self) -> float:
        """Loop time of the run [s]: lead-in plus the data set (and one spare sample)."""
        return self.lead_in + (self.samples + 1) / self.sample_hz

    def controller_params(self) -> dict[str, Any]:
        return {"seed": self.seed, **self.controller}

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["controller"] = self.controller_params()
        return d


def _random_steps(rng: np.random.Generator, t0: float, t_end: float, hold: tuple[float, float],
                  low: float, high: float) -> tuple[list[float], list[float]]:  # fmt: skip
    """Step times from t0 with uniform random lengths in ``hold``, levels uniform in [low, high]."""
    times, levels = [], []
    t = t0
    while t < t_end:
        times.append(t)
        levels.append(float(rng.uniform(low, high)))
        t += float(rng.uniform(*hold))
    return times, levels


def _hold(times: list[float], levels: list[float], before: float) -> Callable[[float], float]:
    def f(t: float) -> float:
        i = bisect.bisect_right(times, t) - 1
        return before if i < 0 else levels[i]

    return f


def excitation_scenario(exp: NarxExperiment) -> Any:
    """The reference and load profiles of one excitation run (a `bench.core.scenarios.Scenario`)."""
    exp.validate()
    ss = np.random.SeedSequence([exp.seed, 6042])  # 6.4.2
    rng_w, rng_i = (np.random.default_rng(s) for s in ss.spawn(2))
    end = exp.duration
    w_times, w_levels = _random_steps(rng_w, exp.lead_in, end, exp.omega_hold, -exp.omega_max, exp.omega_max)
    i_times, i_levels = _random_steps(rng_i, 0.0, end, exp.i_mR_hold, *exp.i_mR_range)
    return Scenario(
        name=f"narx-seed{exp.seed}",
        description=(f"NARX excitation (6.4.2), seed {exp.seed}: random speed steps in +-{exp.omega_max:g} rad/s, "
                     f"i_mR steps in [{exp.i_mR_range[0]:g}, {exp.i_mR_range[1]:g}] A, load 6.4.1"),
        duration=end,
        speed_ref=_hold(w_times, w_levels, 0.0),
        load=lp.speed_dependent_641(exp.load_max, exp.load_k),
        i_mR_ref=_hold(i_times, i_levels, i_levels[0]),
    )  # fmt: skip


def dataset_definition(exp: NarxExperiment, rate_hz: float) -> dict[str, Any]:
    """How `read_signals` turns the log into the data set; stored in the log's ``narx`` record."""
    decim = rate_hz / exp.sample_hz
    if abs(decim - round(decim)) > 1e-9 or round(decim) < 1:
        raise BadInput("rig.rate_hz", f"must be an integer multiple of the data-set rate {exp.sample_hz:g} Hz, got {rate_hz:g}")
    return {
        "format": FORMAT, "format_version": FORMAT_VERSION, "topic": "/ctrl",
        "signals": {"omega_r": "omega_f", "i_mR": "i_mr_f", "i_sd_ref": "i_sd_ref_f", "i_sq_ref": "i_sq_ref_f"},
        "derived": {"i_tau": "i_sq_ref * i_mR (6.4.2)"},
        "loop_rate_hz": rate_hz, "sample_hz": exp.sample_hz, "decimation": int(round(decim)),
        "first_tick": int(round(exp.lead_in * rate_hz)), "samples": exp.samples,
        "filters": "first-order low-pass at log_filter_hz, at the loop rate, before decimation",
        "scaling": "deviation from a known operating point divided by the training set's standard "
                   "deviations (6.4.2); operating point and sigmas are stored with the model (synthesis.narx.Scaling)",
    }  # fmt: skip


@dataclass
class NarxSignals:
    """One data set in physical units at the data-set rate (6.4.2)."""

    t: np.ndarray  # [s] loop time of each sample
    omega_r: np.ndarray  # [rad/s] electrical, encoder, filtered
    i_mR: np.ndarray  # [A] i_mR estimate of the current-model observer, filtered
    i_sd_ref: np.ndarray  # [A] filtered
    i_sq_ref: np.ndarray  # [A] filtered
    i_tau: np.ndarray  # [A^2] i_sq_ref * i_mR
    sample_hz: float
    source: dict[str, Any]  # path, sha256, seed, experiment and data-set definition
    omega_true: np.ndarray | None = None  # mock rig only: true speed through the same filter (evidence, never trained on)

    def __len__(self) -> int:
        return self.t.size


def file_sha256(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_signals(path: str | Path) -> NarxSignals:
    """The data set of a log written by `collect` (raises `BadInput` for other logs)."""
    from scipy.signal import lfilter


    path = Path(path)
    if not path.is_file():
        raise BadInput(str(path), "no such file (a log written by `bench collect narx`)")
    try:
        r = LogReader(path)
    except Exception as exc:  # not MCAP at all
        raise BadInput(str(path), f"not an MCAP log: {type(exc).__name__}") from None
    meta = r.metadata()
    narx = meta.get("narx")
    if not narx or narx.get("dataset", {}).get("format") != FORMAT:
        raise BadInput(str(path), "not a NARX data-set log (no 'narx' metadata record; write one with `bench collect narx`)")
    d, exp = narx["dataset"], narx["experiment"]
    if str(d.get("format_version", "")).split(".")[0] != FORMAT_VERSION.split(".")[0]:
        raise BadInput(str(path), f"data-set format {d.get('format_version')} not supported ({FORMAT_VERSION})")
    ctrl, rig = r.read(d["topic"]), r.read("/rig")
    if bool(np.any(rig["tripped"])):
        raise BadInput(str(path), "the run tripped; the log is not a complete data set")
    idx = d["first_tick"] + d["decimation"] * np.arange(d["samples"])
    if idx[-1] >= ctrl["log_time"].size:
        raise BadInput(str(path), f"log holds {ctrl['log_time'].size} ticks, the data set needs {idx[-1] + 1}")
    sig = {name: np.ascontiguousarray(ctrl[col][idx], dtype=float) for name, col in d["signals"].items()}
    omega_true = None
    if "/truth" in r.topics():  # evidence for the noise floor: the true speed through the same filter
        a = 1.0 - math.exp(-2.0 * math.pi * exp["controller"].get("log_filter_hz", 100.0) / d["loop_rate_hz"])
        w = r.read("/truth")["omega_r"]
        omega_true = lfilter([a], [1.0, a - 1.0], w)[idx]
    source = {"path": str(path), "sha256": file_sha256(path), "seed": exp["seed"], "experiment": exp, "dataset": d,
              "code_version": meta.get("run", {}).get("code_version"),
              "rig": meta.get("rig", {}).get("rig", {}).get("name")}  # fmt: skip
    return NarxSignals(t=rig["t"][idx], omega_r=sig["omega_r"], i_mR=sig["i_mR"], i_sd_ref=sig["i_sd_ref"],
                       i_sq_ref=sig["i_sq_ref"], i_tau=sig["i_sq_ref"] * sig["i_mR"], sample_hz=float(d["sample_hz"]),
                       source=source, omega_true=omega_true)  # fmt: skip
