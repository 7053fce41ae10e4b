"""`bench collect narx` and `bench train narx`: collect the 6.4.2 data sets (`collect`, a bench session), identify
the NARX speed model (6.4.2), validate it, transform it to an LFT (6.3).

`train` reads the training and validation logs of `bench collect narx` (`bench.daq.narx`), fits the ARX
model and the LM-trained MLP (`synthesis.narx`), writes the model artifact (MODEL.npz + MODEL.json, with
provenance: data files and their SHA-256, seeds, settings, date) and a validation report (`report`):

* ``validation.json`` - sigma_w J for MLP and ARX on both sets next to the thesis' values, the noise floor
  (mock rig: measured minus true speed, both through the logging filter), residual whiteness, free-run
  errors, the sector table (6.4.3) and the residual-gain uncertainty for a speed-noise bound (6.3.3, 7.2);
* thesis-style figures ``fig6.6.png`` (a section of the training set), ``fig6.7.png``/``fig6.8.png``
  (prediction errors), ``fig6.9.png`` (residual autocorrelation), ``fig6.10.png``/``fig6.11.png``
  (free-run simulation) and ``sectors.png`` (sector bounds of each neuron, cf. Fig. 6.4).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from bench.daq.narx import NarxExperiment, dataset_definition, excitation_scenario, read_signals
from bench.errors import BadInput
from bench.core.plotstyle import pyplot, speed_label
from bench.core.progress import Say, Steps
from synthesis.narx import (
    Dataset, Scaling, Orders, TrainSettings, identify, order_search, save_model, free_run, metrics, regressors,
    residual_autocorrelation,
)
from synthesis.mlp_lft import gain_uncertainty, mlp_to_lft
from bench.core.config import load as load_rig
from bench.runtime.session import RunOptions, run

THESIS = {
    "sigma_w_J": {"mlp": {"train": 1.04, "val": 1.02}, "arx": {"train": 1.71, "val": 1.82}},
    "sector_widths": [0.0114, 0.0092, 0.0062, 0.0035],
    "gain_uncertainty_0.5rad_s": [0.031, 0.025],
}
def _say(progress: Say | None) -> Say:
    return progress if progress is not None else (lambda s: None)


def load_dataset(path: str | Path, scaling: Any = None) -> Any:
    """MCAP log of `bench collect narx` -> scaled data set (`synthesis.narx.Dataset`, 6.4.2); the scaling
    (`synthesis.narx.Scaling`) fitted here unless given."""
    return Dataset.from_signals(read_signals(path), scaling)


def load_sets(train: Path, val: Path, operating_point: dict[str, float] | None = None) -> tuple[Any, Any]:
    """Scaled training and validation sets; the scaling comes from the training set (6.4.2)."""
    def read(path: Path, option: str) -> Any:
        try:
            return read_signals(path)
        except BadInput as exc:
            raise BadInput(option, f"{exc.field}: {exc.problem}") from None

    tr_sig, va_sig = read(train, "--train"), read(val, "--val")
    if va_sig.sample_hz != tr_sig.sample_hz:
        raise BadInput("--val", f"sample rate {va_sig.sample_hz} Hz differs from the training set's {tr_sig.sample_hz} Hz")
    sc = Scaling.fit(tr_sig, operating_point)
    return Dataset.from_signals(tr_sig, sc), Dataset.from_signals(va_sig, sc)


def _provenance(ds: Any) -> dict[str, Any]:
    p = ds.source
    return {"path": p["path"], "sha256": p["sha256"], "seed": p["seed"], "rig": p.get("rig"),
            "code_version": p.get("code_version"), "experiment": p["experiment"]}  # fmt: skip


def train(train_log: Path, val_log: Path, out: Path, *, neurons: int = 4, n: int = 4, n_i: int = 1,
          n_u: int = 2, max_nfev: int = 3000, init_scale: float = 1e-3, init_spread: float = 1.0, init_seed: int = 0,
          noise_rad_s: float = 0.5, search: bool = False, report_dir: Path | None = None,
          progress: Say | None = None, show_bar: bool = True) -> dict[str, Any]:  # fmt: skip
    """Identify, validate, transform; write MODEL.npz/.json and the report. Returns the summary."""

    say = _say(progress)
    if not 1 <= neurons <= 64:
        raise BadInput("--neurons", f"must be in [1, 64], got {neurons}")
    for name, v, lo in (("--n", n, 1), ("--n-i", n_i, 0), ("--n-u", n_u, 1)):
        if not lo <= v <= 20:
            raise BadInput(name, f"must be an integer in [{lo}, 20], got {v}")
    if not 1 <= max_nfev <= 1_000_000:
        raise BadInput("--max-nfev", f"must be in [1, 1000000], got {max_nfev}")
    if not 0 < init_scale <= 10:
        raise BadInput("--init-scale", f"must be in (0, 10], got {init_scale}")
    if not 0 <= init_spread <= 100:
        raise BadInput("--init-spread", f"must be in [0, 100], got {init_spread}")
    t0 = time.perf_counter()
    tr, va = load_sets(train_log, val_log)  # before any output: bad files end in one error line
    say(f"read {len(tr)} training and {len(va)} validation samples")
    orders = Orders(n, n_i, n_u)
    settings = TrainSettings(neurons=neurons, init_scale=init_scale, init_spread=init_spread, init_seed=init_seed,
                             max_nfev=max_nfev)  # fmt: skip
    timings: dict[str, float] = {"read": time.perf_counter() - t0}
    rows = None
    if search:
        say("order/neuron search (one LM training per row)")
        t = time.perf_counter()
        rows = order_search(tr, va, settings=settings, progress=lambda r: say(
            f"  l={r['neurons']} n={r['n']} n_i={r['n_i']} n_u={r['n_u']}: MLP rms {r['mlp_train_rms']:.4f} / "
            f"{r['mlp_val_rms']:.4f} rad/s, ARX {r['arx_train_rms']:.4f} / {r['arx_val_rms']:.4f} ({r['nfev']} evals)"))  # fmt: skip
        timings["search"] = time.perf_counter() - t
    s_w = tr.scaling.sigma_omega
    say(f"ARX least squares, then LM training of the {neurons}-neuron MLP (n={n}, n_i={n_i}, n_u={n_u}, "
        f"at most {max_nfev} evaluations)")  # fmt: skip
    t = time.perf_counter()
    best = [np.inf]
    with Steps(max_nfev, "LM evaluations", tty=None if show_bar else False) as step:

        def lm_progress(k: int, J: float) -> None:
            best[0] = min(best[0], J)
            step(k)

        model, info = identify(tr, orders, settings, progress=lm_progress)
    timings["train"] = time.perf_counter() - t
    why = (f"the evaluation budget (--max-nfev {max_nfev}) is used up; the model is the best found"
           if info.nfev >= max_nfev else f"converged: {info.message}")  # scipy says "maximum ... exceeded"
    say(f"  LM stopped after {info.nfev} evaluations, {info.wall_time:.1f} s: {why}; best rms one-step error "
        f"{s_w * np.sqrt(best[0]):.4f} rad/s")  # fmt: skip
    say("MLP -> quasi-LPV LFT (6.3): equilibrium, active ranges, sector bounds, residual-gain uncertainty")
    t = time.perf_counter()
    lft = mlp_to_lft(model, [tr])
    unc = gain_uncertainty(lft, noise_rad_s)
    timings["lft"] = time.perf_counter() - t
    meta = {"provenance": {"train": _provenance(tr), "val": _provenance(va)}, "lft": lft.summary(),
            "gain_uncertainty": {"noise_rad_s": noise_rad_s, "bound": unc.tolist()}}  # fmt: skip
    npz, js = save_model(out, model, meta)
    say("validation report")
    t = time.perf_counter()
    rep = report(model, tr, va, report_dir or Path(str(out) + "_report"), lft=lft, gain_unc=unc,
                 noise_rad_s=noise_rad_s, search=rows, history=info.history)  # fmt: skip
    timings["report"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    summary = {"model": {"npz": str(npz), "json": str(js)}, "orders": asdict(orders), "neurons": neurons,
               "training": {k: v for k, v in info.as_dict().items() if k != "history"}, "timings_s": timings,
               **{k: rep[k] for k in ("performance", "sector_table", "gain_uncertainty", "figures", "report")}}  # fmt: skip
    Path(rep["report"]).write_text(json.dumps({**rep["_doc"], "timings_s": timings}, indent=2, default=float))
    return summary


# --------------------------------------------------------------------------------------------------
# the validation report
# --------------------------------------------------------------------------------------------------
def report(model: Any, tr: Any, va: Any, out_dir: Path, *, lft: Any = None, gain_unc: np.ndarray | None = None,
           noise_rad_s: float = 0.5, search: list[dict[str, Any]] | None = None,
           history: list[float] | None = None) -> dict[str, Any]:  # fmt: skip
    """Write validation.json and the figures (Figs. 6.6-6.11, the sectors of the MLP's LFT, the training's
    convergence) into ``out_dir``; returns the numbers."""
    plt = pyplot()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    sets = {"train": tr, "val": va}
    perf = {name: metrics(model, ds) for name, ds in sets.items()}
    doc: dict[str, Any] = {"thesis": THESIS, "scaling": model.scaling.to_dict(), "orders": asdict(model.orders),
                           "neurons": model.mlp.neurons, "performance": perf}  # fmt: skip
    doc["noise_floor"] = floor = _noise_floor(model, sets)
    figs = {"fig6.6": _fig_training_set(model, tr, plt, out_dir)}
    figs.update(_figs_prediction_error(model, sets, perf, plt, out_dir))
    figs["fig6.9"], doc["autocorrelation"] = _fig_autocorrelation(model, va, plt, out_dir)
    fr, free_figs = _figs_free_run(model, sets, plt, out_dir)
    figs.update(free_figs)
    doc["free_run"] = fr
    if lft is not None:
        doc["sector_table"] = [{"j": j + 1, "neuron": int(lft.neurons[j]) + 1, "k_min": float(lft.k_min[j]),
                                "k_max": float(lft.k_max[j]), "width": float(lft.widths[j]),
                                "theta_b": float(lft.theta_b[j]), "xi_min": float(lft.xi_min[j]),
                                "xi_max": float(lft.xi_max[j])} for j in range(lft.widths.size)]  # fmt: skip
        doc["lft"] = lft.summary()
        figs["sectors"] = _save(_sector_figure(lft, plt), out_dir / "sectors.png")
    if history:
        figs["lm"], doc["lm_history_rms_rad_s"] = _fig_training(model, history, perf, floor, plt, out_dir)
    if gain_unc is not None:
        doc["gain_uncertainty"] = {"noise_rad_s": noise_rad_s, "bound": [float(v) for v in gain_unc]}
    if search is not None:
        doc["order_search"] = search
    doc["figures"] = {k: str(v) for k, v in figs.items()}
    path = out_dir / "validation.json"
    path.write_text(json.dumps(doc, indent=2, default=float))
    return {"performance": perf, "sector_table": doc.get("sector_table"), "gain_uncertainty": doc.get("gain_uncertainty"),
            "figures": doc["figures"], "report": str(path), "_doc": doc}  # fmt: skip


def _noise_floor(model: Any, sets: dict[str, Any]) -> dict[str, Any]:
    """The noise floor (mock rig): the measured speed against the true speed, and each model's one-step prediction
    against the true next speed, through the same filter [rad/s rms]."""
    s_w = model.scaling.sigma_omega
    floor = {}
    for name, ds in sets.items():
        if ds.w_true is not None:
            Z, y = regressors(ds, model.orders)
            y_true = ds.w_true[model.orders.lag :]
            floor[name] = {
                "meas_minus_true_rms_rad_s": s_w * float(np.std(ds.w - ds.w_true)),
                "mlp_vs_true_next_speed_rms_rad_s": s_w * float(np.sqrt(np.mean((model.predict(Z) - y_true) ** 2))),
                "arx_vs_true_next_speed_rms_rad_s": s_w * float(np.sqrt(np.mean((model.predict(Z, "arx") - y_true) ** 2))),
            }  # fmt: skip
    return floor


def _fig_training_set(model: Any, tr: Any, plt: Any, out_dir: Path) -> Path:
    """Fig. 6.6: a section of the training set, physical units."""
    sc = model.scaling
    k = slice(0, min(6000, len(tr)))
    tt = np.arange(len(tr))[k] / tr.sample_hz
    fig, ax = plt.subplots(4, 1, figsize=(9, 8), sharex=True, constrained_layout=True)
    for a, (sig, name, unit) in zip(ax, ((tr.w, "omega_r", r"$\omega_r$ [rad/s]"), (tr.i, "i_mR", r"$\hat i_{mR}$ [A]"),
                                         (tr.d, "i_sd_ref", r"$i_{sd,ref}$ [A]"), (tr.tau, "i_tau", None))):  # fmt: skip
        if name == "i_tau":  # the thesis plots i_sq,ref
            i_sq = sc.unscale("i_tau", tr.tau[k]) / sc.unscale("i_mR", tr.i[k])
            a.plot(tt, i_sq, lw=0.6)
            a.set_ylabel(r"$i_{sq,ref}$ [A]")
        else:
            a.plot(tt, sc.unscale(name, sig[k]), lw=0.6)
            a.set_ylabel(unit)
        a.grid(alpha=0.3)
    ax[-1].set_xlabel("time [s]")
    fig.suptitle(f"Fig. 6.6: {k.stop} samples of the training set (600 Hz)")
    return _save(fig, out_dir / "fig6.6.png")


def _figs_prediction_error(model: Any, sets: dict[str, Any], perf: dict[str, Any], plt: Any, out_dir: Path
                           ) -> dict[str, Path]:  # fmt: skip
    """Figs. 6.7, 6.8: the one-step prediction errors over 500 samples of each set."""
    s_w = model.scaling.sigma_omega
    figs = {}
    for fname, (name, ds) in zip(("fig6.7", "fig6.8"), sets.items()):
        Z, y = regressors(ds, model.orders)
        n = min(500, y.size)
        fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True, sharey=True, constrained_layout=True)
        for a, which in zip(ax, ("mlp", "arx")):
            e = s_w * (y[:n] - model.predict(Z[:n], which))
            a.plot(np.arange(n), e, lw=0.7)
            a.set_ylabel(speed_label(f"{which.upper()} error"))
            a.grid(alpha=0.3)
            a.set_title(f"{which.upper()}: rms over the whole set {perf[name][which]['rms_rad_s']:.3f} rad/s", fontsize=9)
        ax[-1].set_xlabel("sample")
        fig.suptitle(f"Fig. {fname[3:]}: one-step prediction error, 500 samples of the {'training' if name == 'train' else 'validation'} set")
        figs[fname] = _save(fig, out_dir / f"{fname}.png")
    return figs


def _fig_autocorrelation(model: Any, va: Any, plt: Any, out_dir: Path) -> tuple[Path, dict[str, Any]]:
    """Fig. 6.9: the autocorrelation of the prediction error on the validation set, and its numbers."""
    Z, y = regressors(va, model.orders)
    fig, ax = plt.subplots(2, 1, figsize=(9, 5), sharex=True, sharey=True, constrained_layout=True)
    acf = {}
    for a, which in zip(ax, ("mlp", "arx")):
        lags, r, band = residual_autocorrelation(y - model.predict(Z, which), 50)
        a.vlines(lags, 0, r, lw=1.0)
        a.axhspan(-band, band, color="tab:gray", alpha=0.25, label="95 % band of white noise")
        a.set_ylabel(f"{which.upper()}")
        a.set_ylim(-0.3, 1.05)
        a.grid(alpha=0.3)
        a.legend(fontsize=8, loc="upper right")
        outside = np.abs(r[lags != 0]) > band
        acf[which] = {"lag1": float(r[lags == 1][0]), "max_abs_nonzero_lag": float(np.max(np.abs(r[lags != 0]))),
                      "fraction_outside_band": float(np.mean(outside)), "band": band}  # fmt: skip
    ax[-1].set_xlabel("lag [samples]")
    fig.suptitle("Fig. 6.9: scaled autocorrelation of the prediction error, validation set")
    return _save(fig, out_dir / "fig6.9.png"), acf


def _figs_free_run(model: Any, sets: dict[str, Any], plt: Any, out_dir: Path
                   ) -> tuple[dict[str, Any], dict[str, Path]]:  # fmt: skip
    """Figs. 6.10, 6.11: the free-run simulation over 6000 samples of each set; the rms over each whole set."""
    s_w, sc = model.scaling.sigma_omega, model.scaling
    fr, figs = {}, {}
    for fname, (name, ds) in zip(("fig6.10", "fig6.11"), sets.items()):
        sim_m, meas = free_run(model, ds, "mlp", 0, 6000)
        sim_a, _ = free_run(model, ds, "arx", 0, 6000)
        full_m, full_y = free_run(model, ds, "mlp")
        full_a, _ = free_run(model, ds, "arx")
        fr[name] = {"mlp_rms_rad_s": s_w * float(np.sqrt(np.mean((full_m - full_y) ** 2))),
                    "arx_rms_rad_s": s_w * float(np.sqrt(np.mean((full_a - full_y) ** 2))),
                    "samples": int(full_y.size)}  # fmt: skip
        t = np.arange(meas.size) / ds.sample_hz
        w = lambda v: sc.unscale("omega_r", v)  # noqa: E731
        fig, ax = plt.subplots(3, 1, figsize=(9, 8), sharex=True, constrained_layout=True)
        for a, sim, lab in ((ax[0], sim_m, "MLP"), (ax[1], sim_a, "ARX")):
            a.plot(t, w(meas), ":", color="k", lw=0.9, label="measured")
            a.plot(t, w(sim), lw=0.8, label=f"{lab} simulation")
            a.set_ylabel(speed_label(r"$\omega_r$"))
            a.legend(fontsize=8, loc="upper right")
            a.grid(alpha=0.3)
        ax[2].plot(t, s_w * (sim_m - meas), lw=0.7)
        ax[2].set_ylabel(speed_label("MLP sim. error"))
        ax[2].set_xlabel("time [s]")
        ax[2].grid(alpha=0.3)
        fig.suptitle(f"Fig. {fname[3:]}: open-loop simulation, {meas.size} samples of the "
                     f"{'training' if name == 'train' else 'validation'} set "
                     f"(rms over the set: MLP {fr[name]['mlp_rms_rad_s']:.1f}, ARX {fr[name]['arx_rms_rad_s']:.1f} rad/s)")  # fmt: skip
        figs[fname] = _save(fig, out_dir / f"{fname}.png")
    return fr, figs


def _fig_training(model: Any, history: list[float], perf: dict[str, Any], floor: dict[str, Any], plt: Any,
                  out_dir: Path) -> tuple[Path, dict[str, float]]:  # fmt: skip
    """The Levenberg-Marquardt training's best rms one-step error against its residual evaluations, with the ARX
    model's and the noise floor; the figure and the error at a few evaluation counts."""
    h = model.scaling.sigma_omega * np.sqrt(np.minimum.accumulate(np.asarray(history)))
    arx = perf["train"]["arx"]["rms_rad_s"]
    fig, a = plt.subplots(figsize=(7, 3.6), constrained_layout=True)
    a.semilogx(np.arange(1, h.size + 1), h, lw=1.2, label="MLP (best so far)")
    a.axhline(arx, color="k", ls="--", lw=0.9, label="ARX")
    if "train" in floor:
        a.axhline(floor["train"]["meas_minus_true_rms_rad_s"], color="tab:red", ls=":", lw=0.9,
                  label="measured - true speed (noise)")
    a.set_xlabel("LM residual evaluations")
    a.set_ylabel(speed_label("rms one-step error"))
    a.set_title("Levenberg-Marquardt training from the ARX initialisation (training set)", fontsize=10)
    a.grid(alpha=0.3, which="both")
    a.legend(fontsize=8)
    at = {str(k): float(h[k - 1]) for k in (1, 10, 100, 300, 1000, 2000, 3000, 5000, 10000) if k <= h.size}
    return _save(fig, out_dir / "lm-convergence.png"), at


def _sector_figure(lft: Any, plt: Any) -> Any:
    """Each residual gain's sigma'(xi) over its active range with the sector lines (cf. Fig. 6.4)."""
    m = lft.widths.size
    fig, ax = plt.subplots(1, m, figsize=(3.2 * m, 3.4), constrained_layout=True, squeeze=False)
    for j, a in enumerate(ax[0]):
        xi = np.linspace(lft.xi_min[j], lft.xi_max[j], 801)
        col = np.zeros((xi.size, m))
        col[:, j] = xi
        c = 0.5 * (lft.k_min[j] + lft.k_max[j])
        # sigma'(xi) - c xi shows the nonlinearity; the sector lines become +-(k_max - k_min)/2 xi
        a.plot(xi, lft.sigma_prime(col)[:, j] - c * xi, lw=1.2, label=r"$\sigma'_j(\xi)-c_j\xi$")
        for k, st in ((lft.k_min[j], "--"), (lft.k_max[j], ":")):
            a.plot(xi, (k - c) * xi, st, color="k", lw=0.9)
        a.set_title(f"gain {j + 1} (neuron {lft.neurons[j] + 1}): width {lft.widths[j]:.2e}\n"
                    f"bias {lft.theta_b[j]:+.3g}", fontsize=9)  # fmt: skip
        a.set_xlabel(r"$\xi_j$")
        a.set_ylabel(r"$\sigma'_j(\xi_j) - c_j \xi_j$ (scaled units)")
        a.xaxis.set_major_locator(plt.MaxNLocator(4))
        a.grid(alpha=0.3)
    ax[0][0].legend(fontsize=8)
    fig.suptitle(r"Sector bounds on the active ranges (dashed $k_{min}$, dotted $k_{max}$; centre slope removed)")
    return fig


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------------------
# collection: the 6.4.2 experiment as a bench session
# --------------------------------------------------------------------------------------------------
def collect(exp: NarxExperiment, out: Path, *, rig: str = "mock", realtime: bool | None = None,
            allow_soft_realtime: bool = False, force: bool = False,
            progress: bool = True, live: dict[str, Any] | None = None) -> tuple[dict[str, Any], int]:  # fmt: skip
    """Run the excitation experiment ``exp`` on ``rig`` and log it to ``out`` (MCAP); returns (summary, exit code).
    ``live``: RunOptions' live_port/live_host/live_rate (bench.daq.live), to watch the collection."""

    exp.validate()
    cfg = load_rig(rig)
    definition = dataset_definition(exp, cfg.rate_hz)
    scn = excitation_scenario(exp)
    opts = RunOptions(rig=rig, controller="excitation", scenario=scn, duration=exp.duration, realtime=realtime,
                      allow_soft_realtime=allow_soft_realtime, force=force, seed=exp.seed, label="bench collect narx",
                      params=exp.controller_params(), log=Path(out), progress=progress,
                      metadata={"narx": {"experiment": exp.as_dict(), "dataset": definition}}, **(live or {}))  # fmt: skip
    summary, code = run(opts)
    summary["narx"] = {"experiment": exp.as_dict(), "dataset": definition}
    return summary, code


# --------------------------------------------------------------------------------------------------
# the whole identification chain: reproduction and benchmark
# --------------------------------------------------------------------------------------------------
def collect_sets(work_dir: Path, *, samples: int = 22000, seeds: tuple[int, int] = (1, 2), rig: str = "mock",
                 sample_hz: float = 600.0, progress: Say | None = None) -> tuple[list[Path], dict[str, Any]]:  # fmt: skip
    """Training (seeds[0]) and validation (seeds[1]) logs of the 6.4.2 experiment under ``work_dir``;
    returns the two log paths and the collection wall times."""

    say = _say(progress)
    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    logs, coll = [], {}
    for role, seed in zip(("train", "val"), seeds):
        log = work_dir / f"narx-{role}-seed{seed}.mcap"
        say(f"collecting the {role} set: seed {seed}, {samples} samples at {sample_hz:g} Hz")
        t = time.perf_counter()
        s, code = collect(NarxExperiment(seed=seed, samples=samples, sample_hz=sample_hz), log, rig=rig, progress=False)
        if code != 0:
            raise RuntimeError(f"collection of the {role} set stopped: {s.get('trip_cause')}")
        coll[role] = {"wall_s": time.perf_counter() - t, "loop_wall_s": s["wall_time"], "simulated_s": s["duration"],
                      "ticks": s["ticks"], "log": str(log), "log_bytes": log.stat().st_size}  # fmt: skip
        logs.append(log)
    return logs, coll


def collect_and_train(work_dir: Path, *, samples: int = 22000, seeds: tuple[int, int] = (1, 2), max_nfev: int = 3000,
                      rig: str = "mock", progress: Say | None = None) -> dict[str, Any]:  # fmt: skip
    """Training (seeds[0]) and validation (seeds[1]) sets, then `train`; everything under ``work_dir``.
    Returns the training summary plus the collection wall times."""
    logs, coll = collect_sets(work_dir, samples=samples, seeds=seeds, rig=rig, progress=progress)
    summary = train(logs[0], logs[1], Path(work_dir) / "model", max_nfev=max_nfev, report_dir=Path(work_dir) / "report",
                    progress=progress)  # fmt: skip
    summary["collect"] = coll
    return summary


def benchmark(samples: int = 22000, max_nfev: int = 3000, work_dir: Path | None = None) -> dict[str, Any]:
    """Wall time of collect (both sets) and train: JSON for docs/RESULTS.md."""
    import os
    import platform
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        s = collect_and_train(Path(work_dir or tmp), samples=samples, max_nfev=max_nfev)
        total = time.perf_counter() - t
    tr = s["training"]
    return {"benchmark": "narx", "samples": samples, "max_nfev": max_nfev, "total_s": total,
            "collect": {k: {kk: v[kk] for kk in ("wall_s", "loop_wall_s", "simulated_s", "ticks", "log_bytes")}
                        for k, v in s["collect"].items()},
            "train": s["timings_s"], "lm": {"nfev": tr["nfev"], "njev": tr["njev"], "status": tr["status"],
                                            "ms_per_evaluation": 1e3 * tr["wall_time"] / max(tr["nfev"], 1)},
            "performance_rms_rad_s": {m: {k: s["performance"][k][m]["rms_rad_s"] for k in ("train", "val")}
                                      for m in ("mlp", "arx")},
            "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "load_avg": os.getloadavg()}}  # fmt: skip
