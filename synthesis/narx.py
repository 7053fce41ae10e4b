"""NARX identification of the speed dynamics (thesis 2.5, 6.4.2): scaling, ARX, MLP trained by LM.

Signals (6.4.2), all sampled at 600 Hz: the speed omega_r, the magnetising-current estimate i_mR_hat,
and the current references i_sd,ref and i_tau = i_sq,ref * i_mR_hat (i_tau pre-compensates the torque
nonlinearity (4.6)). `Scaling` turns them into the thesis' normalised signals (deviation from a known
operating point, divided by the training set's standard deviations):

    w~ = (omega_r - omega_r0)/s_w,  i~ = (i_mR - i_mR0)/s_i,  d~ = (i_sd,ref - i_sd,ref0)/s_d,
    tau~ = (i_tau - i_sq,ref0 i_mR0)/s_tau.

The model predicts w~_{k+1} from the regressor (`Orders`: n, n_i, n_u; thesis 4, 1, 2)

    z_{k+1} = [w~_k .. w~_{k-n+1}, i~_k .. i~_{k-n_i+1}, d~_k .. d~_{k-n_u+1}, tau~_k .. tau~_{k-n_u+1}]

(the thesis writes z_k with indices k-1 ... for the target at k; the same thing).

* ARX: w^_{k+1} = M_l z_{k+1}, M_l = M_o M_i^+ (least squares, `fit_arx`).
* MLP (2.21): w^_{k+1} = Theta_2 tanh(Theta_1 z_{k+1} + Theta_b), one hidden tanh layer (`NarxMLP`, torch),
  initialised from the ARX model with Theta_b = 0 and Theta_2 Theta_1 = M_l, Theta_2 large and Theta_1 small
  (`init_from_arx`), trained by Levenberg-Marquardt (`train_lm`: scipy's MINPACK ``least_squares(method='lm')``
  with the Jacobian from torch).
* Cost (6.4.2): J = 1/(s-n) sum eps^2 on the scaled speed; reported also in rad/s (`metrics`).

`NarxModel` bundles orders, scaling and both models and is saved as plain files (`save_model`: npz + JSON
with provenance; no pickle). `synthesis.mlp_lft` turns its MLP into a quasi-LPV LFT (6.3).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from synthesis.artifacts import write_artifact, read_artifact

__all__ = [
    "SIGNALS", "Scaling", "Dataset", "Orders", "MLPWeights", "NarxModel", "regressors",
    "fit_arx", "init_from_arx", "train_lm", "torch_jacobian", "NarxMLP", "TrainSettings", "TrainInfo", "metrics", "residual_autocorrelation", "free_run",
    "identify", "order_search", "save_model", "load_model", "MODEL_FORMAT", "MODEL_VERSION",
]  # fmt: skip

SIGNALS = ("omega_r", "i_mR", "i_sd_ref", "i_tau")  # model signals, in regressor order
MODEL_FORMAT = "imbench.narx_model"
MODEL_VERSION = "1.0"


# --------------------------------------------------------------------------------------------------
# scaling and data sets
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scaling:
    """Operating point and standard deviations of 6.4.2. ``scale``/``unscale`` work on numpy arrays or floats."""

    omega_r0: float  # [rad/s]
    i_mR0: float  # [A]
    i_sd_ref0: float  # [A]
    i_sq_ref0: float  # [A]
    sigma_omega: float  # [rad/s]
    sigma_i: float  # [A]
    sigma_d: float  # [A]
    sigma_tau: float  # [A^2]
    sigma_q: float = float("nan")  # [A] std of i_sq,ref (6.4.2 lists it; i_tau replaces i_sq,ref as input)

    @property
    def i_tau0(self) -> float:
        """Operating point of i_tau: i_sq,ref0 * i_mR0 (6.4.2)."""
        return self.i_sq_ref0 * self.i_mR0

    def offset(self, name: str) -> float:
        return {"omega_r": self.omega_r0, "i_mR": self.i_mR0, "i_sd_ref": self.i_sd_ref0, "i_tau": self.i_tau0,
                "i_sq_ref": self.i_sq_ref0}[name]  # fmt: skip

    def sigma(self, name: str) -> float:
        return {"omega_r": self.sigma_omega, "i_mR": self.sigma_i, "i_sd_ref": self.sigma_d, "i_tau": self.sigma_tau,
                "i_sq_ref": self.sigma_q}[name]  # fmt: skip

    def scale(self, name: str, x: Any) -> Any:
        """Physical -> normalised (6.4.2)."""
        return (x - self.offset(name)) / self.sigma(name)

    def unscale(self, name: str, x: Any) -> Any:
        """Normalised -> physical."""
        return x * self.sigma(name) + self.offset(name)

    @classmethod
    def fit(cls, signals: Any, operating_point: dict[str, float] | None = None) -> "Scaling":
        """Standard deviations of ``signals`` (a `bench.daq.narx.NarxSignals` or anything with the same
        arrays) around the known operating point (default: standstill at i_mR0 = i_sd,ref0 = 1.8 A, the
        middle of the excitation's [0.8, 2.8] A, i_sq,ref0 = 0 - an equilibrium of the drive).
        """
        op = {"omega_r0": 0.0, "i_mR0": 1.8, "i_sd_ref0": 1.8, "i_sq_ref0": 0.0, **(operating_point or {})}
        s = {k: float(np.std(getattr(signals, a)))
             for k, a in (("sigma_omega", "omega_r"), ("sigma_i", "i_mR"), ("sigma_d", "i_sd_ref"),
                          ("sigma_tau", "i_tau"), ("sigma_q", "i_sq_ref"))}  # fmt: skip
        for k, v in s.items():
            if not v > 0:
                raise ValueError(f"{k} = {v}: the data set does not excite this signal")
        return cls(**{k: float(v) for k, v in op.items()}, **s)

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, float]) -> "Scaling":
        return cls(**{k: float(v) for k, v in d.items()})


@dataclass
class Dataset:
    """A scaled data set: one array per signal in `SIGNALS`, equal lengths, plus where it came from."""

    w: np.ndarray  # scaled omega_r
    i: np.ndarray  # scaled i_mR
    d: np.ndarray  # scaled i_sd,ref
    tau: np.ndarray  # scaled i_tau
    scaling: Scaling
    sample_hz: float = 600.0
    source: dict[str, Any] = field(default_factory=dict)
    w_true: np.ndarray | None = None  # scaled true speed (mock rig only; evidence, never trained on)

    def __len__(self) -> int:
        return self.w.size

    @classmethod
    def from_signals(cls, signals: Any, scaling: Scaling | None = None) -> "Dataset":
        """Scale ``signals`` (`bench.daq.narx.NarxSignals`); without ``scaling`` fit it to these signals."""
        sc = Scaling.fit(signals) if scaling is None else scaling
        wt = None if getattr(signals, "omega_true", None) is None else sc.scale("omega_r", signals.omega_true)
        return cls(sc.scale("omega_r", signals.omega_r), sc.scale("i_mR", signals.i_mR),
                   sc.scale("i_sd_ref", signals.i_sd_ref), sc.scale("i_tau", signals.i_tau), sc,
                   float(getattr(signals, "sample_hz", 600.0)), dict(getattr(signals, "source", {})), wt)  # fmt: skip


@dataclass(frozen=True)
class Orders:
    """NARX orders (6.4.2): n past speeds, n_i past i_mR, n_u past values of each current input."""

    n: int = 4
    n_i: int = 1
    n_u: int = 2

    def __post_init__(self) -> None:
        if self.n < 1 or self.n_i < 0 or self.n_u < 1:
            raise ValueError(f"orders need n >= 1, n_i >= 0, n_u >= 1, got {self}")

    @property
    def lag(self) -> int:
        """Samples needed before the first prediction."""
        return max(self.n, self.n_i, self.n_u)

    @property
    def dim(self) -> int:
        return self.n + self.n_i + 2 * self.n_u

    def labels(self) -> list[str]:
        """Regressor entries, e.g. ``w[k]``, ``w[k-1]``, ... for the prediction of w[k+1]."""
        def lab(s: str, m: int) -> list[str]:
            return [f"{s}[k]" if j == 0 else f"{s}[k-{j}]" for j in range(m)]

        return lab("w", self.n) + lab("i", self.n_i) + lab("d", self.n_u) + lab("tau", self.n_u)


def regressors(ds: Dataset, orders: Orders) -> tuple[np.ndarray, np.ndarray]:
    """Z (rows z_{k+1}, `Orders`), target y = w~_{k+1}, for k+1 = lag ... len-1 (s - lag rows)."""
    N, L = len(ds), orders.lag
    cols = []
    for sig, m in ((ds.w, orders.n), (ds.i, orders.n_i), (ds.d, orders.n_u), (ds.tau, orders.n_u)):
        for j in range(m):
            cols.append(sig[L - 1 - j : N - 1 - j])
    return np.column_stack(cols), ds.w[L:].copy()


# --------------------------------------------------------------------------------------------------
# ARX and MLP
# --------------------------------------------------------------------------------------------------
def fit_arx(Z: np.ndarray, y: np.ndarray) -> np.ndarray:
    """M_l = M_o M_i^+ (6.4.2), with M_i = Z^T and M_o = y^T: the least-squares linear predictor (1 x dim)."""
    sol, *_ = np.linalg.lstsq(Z, y, rcond=None)  # = y^T pinv(Z^T), computed without forming the pseudo-inverse
    return sol.reshape(1, -1)


@dataclass(frozen=True)
class MLPWeights:
    """One hidden layer (2.21): out = Theta2 tanh(Theta1 z + Theta_b). Theta1 (l x dim), Theta_b (l), Theta2 (1 x l)."""

    Theta1: np.ndarray
    Theta_b: np.ndarray
    Theta2: np.ndarray

    @property
    def neurons(self) -> int:
        return self.Theta1.shape[0]

    def predict(self, Z: np.ndarray) -> np.ndarray:
        """Row-wise prediction for Z (N x dim) -> (N,); a single z (dim,) -> float array ()."""
        return np.tanh(Z @ self.Theta1.T + self.Theta_b) @ self.Theta2[0]

    def vector(self) -> np.ndarray:
        """Flat parameter vector [Theta1 row-major, Theta_b, Theta2]."""
        return np.concatenate([self.Theta1.ravel(), self.Theta_b, self.Theta2.ravel()])

    @classmethod
    def from_vector(cls, theta: np.ndarray, dim: int, neurons: int) -> "MLPWeights":
        l, m = neurons, dim
        theta = np.asarray(theta, float)
        return cls(theta[: l * m].reshape(l, m).copy(), theta[l * m : l * m + l].copy(), theta[l * m + l :].reshape(1, l).copy())


def init_from_arx(M_l: np.ndarray, neurons: int, *, scale: float = 1e-3, spread: float = 1.0,
                  seed: int = 0) -> MLPWeights:  # fmt: skip
    """Initial MLP close to the ARX model (6.4.2): Theta_b = 0 and Theta2 Theta1 = M_l exactly, Theta1 small.

    Theta1 = scale (M_l + D_j) row by row, with random rows D_j (relative size ``spread``) of zero mean
    over the neurons, and Theta2 = 1/(l scale) for each neuron: so Theta2 Theta1 = M_l, the neurons are
    all different (identical ones would stay identical under any gradient method), and with Theta1
    small every tanh works in its linear range, M_m(z) = M_l z + O(scale^2).
    """
    M_l = np.asarray(M_l, float).reshape(1, -1)
    rng = np.random.default_rng(seed)
    D = rng.standard_normal((neurons, M_l.shape[1])) * spread * np.sqrt(np.mean(M_l**2))
    D -= D.mean(axis=0) if neurons > 1 else D
    Theta1 = scale * (M_l + D)
    Theta2 = np.full((1, neurons), 1.0 / (neurons * scale))
    return MLPWeights(Theta1, np.zeros(neurons), Theta2)


def _torch():
    import torch

    return torch


def NarxMLP(dim: int, neurons: int):  # noqa: N802 - a torch module factory, named like the class it returns
    """The MLP (2.21) as a float64 torch module: Linear(dim, l) (Theta1, Theta_b) -> tanh -> Linear(l, 1, no bias) (Theta2)."""
    torch = _torch()

    class _NarxMLP(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.hidden = torch.nn.Linear(dim, neurons, dtype=torch.float64)
            self.out = torch.nn.Linear(neurons, 1, bias=False, dtype=torch.float64)

        def forward(self, z):  # noqa: ANN001, ANN202
            return self.out(torch.tanh(self.hidden(z))).squeeze(-1)

    return _NarxMLP()


@dataclass
class TrainInfo:
    """What `train_lm` did."""

    J_initial: float
    J_final: float
    nfev: int
    njev: int
    status: int
    message: str
    wall_time: float
    history: list[float] = field(default_factory=list)  # J at every residual evaluation

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def torch_jacobian(w: MLPWeights, Z: np.ndarray) -> np.ndarray:
    """d M_m(z_k) / d theta for every row z_k of Z (N x P, theta = `MLPWeights.vector`), by torch autograd.

    One reverse pass: every sample gets its own copy of the parameters (an N x P leaf tensor), so the
    gradient of the summed outputs with respect to copy k is row k of the Jacobian (the per-sample-gradient
    recipe; ``torch.func.jacfwd`` gives the same numbers at about ten times the cost here).
    """
    torch = _torch()
    N, dim, l = Z.shape[0], w.Theta1.shape[1], w.neurons
    T = torch.tensor(w.vector()).expand(N, -1).clone().requires_grad_(True)
    W1, b, W2 = torch.split(T, (l * dim, l, l), dim=1)
    Zt = torch.tensor(Z, dtype=torch.float64)  # aligned copy (see train_lm)
    out = (torch.tanh(torch.einsum("nld,nd->nl", W1.reshape(N, l, dim), Zt) + b) * W2).sum(dim=1)  # (2.21)
    out.sum().backward()
    return T.grad.numpy()


def train_lm(w0: MLPWeights, Z: np.ndarray, y: np.ndarray, *, max_nfev: int = 3000, ftol: float = 1e-10,
             xtol: float = 1e-10, gtol: float = 1e-10, jac: str = "torch",
             progress: Callable[[int, float], None] | None = None) -> tuple[MLPWeights, TrainInfo]:  # fmt: skip
    """Levenberg-Marquardt training of the MLP on (Z, y): scipy's MINPACK LM (``least_squares(method='lm')``).

    The residual eps = M_m(z) - y is computed by the torch module `NarxMLP`, the Jacobian by torch
    autograd (`torch_jacobian`); ``jac="2-point"`` uses scipy's finite differences instead, for
    cross-checks. ``progress(nfev, J)`` is called at every residual evaluation.
    """
    torch = _torch()
    from torch.func import functional_call

    dim, l = w0.Theta1.shape[1], w0.neurons
    model = NarxMLP(dim, l)
    # torch.tensor copies into torch's 64-byte aligned memory: MKL's GEMM results depend on operand alignment
    # (1e-15 differences, which the long LM path amplifies), so aligned copies keep the training reproducible
    Zt = torch.tensor(Z, dtype=torch.float64)
    yt = torch.tensor(y, dtype=torch.float64)

    def fun(theta: np.ndarray) -> np.ndarray:
        w = MLPWeights.from_vector(theta, dim, l)
        params = {"hidden.weight": torch.tensor(w.Theta1), "hidden.bias": torch.tensor(w.Theta_b),
                  "out.weight": torch.tensor(w.Theta2)}  # fmt: skip
        with torch.no_grad():
            r = (functional_call(model, params, (Zt,)) - yt).numpy()
        history.append(float(np.mean(r**2)))
        if progress is not None:
            progress(len(history), history[-1])
        return r

    def jac_fn(theta: np.ndarray) -> np.ndarray:
        return torch_jacobian(MLPWeights.from_vector(theta, dim, l), Z)

    history: list[float] = []
    t0 = time.perf_counter()
    J0 = float(np.mean((w0.predict(Z) - y) ** 2))
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the tensors are small: thread hand-offs cost more than they gain (10x on 2 shared cores)
    try:
        res = least_squares(fun, w0.vector(), jac=jac_fn if jac == "torch" else jac, method="lm", x_scale="jac",
                            ftol=ftol, xtol=xtol, gtol=gtol, max_nfev=max_nfev)  # fmt: skip
    finally:
        torch.set_num_threads(threads)
    w = MLPWeights.from_vector(res.x, dim, l)
    info = TrainInfo(J0, float(np.mean(res.fun**2)), int(res.nfev), int(res.njev or 0), int(res.status),
                     str(res.message), time.perf_counter() - t0, history)  # fmt: skip
    return w, info


# --------------------------------------------------------------------------------------------------
# the model, validation
# --------------------------------------------------------------------------------------------------
@dataclass
class NarxModel:
    """Orders, scaling, the MLP and the ARX model it was initialised from; ``dt`` = 1/sample rate."""

    orders: Orders
    scaling: Scaling
    mlp: MLPWeights
    M_l: np.ndarray  # ARX gain (1 x dim)
    dt: float
    meta: dict[str, Any] = field(default_factory=dict)

    def predict(self, Z: np.ndarray, which: str = "mlp") -> np.ndarray:
        """One-step predictions of the scaled speed for regressor rows Z."""
        return self.mlp.predict(Z) if which == "mlp" else Z @ self.M_l[0]


def metrics(model: NarxModel, ds: Dataset) -> dict[str, dict[str, float]]:
    """Prediction-error performance of both models on ``ds`` (6.4.2).

    J = 1/(s-n) sum eps^2 on the scaled speed. The thesis tabulates "sigma_w J"; since J is a mean
    square, we report sigma_w J as printed, sigma_w sqrt(J) (the RMS one-step error in rad/s) and
    sigma_w^2 J (the mean square in (rad/s)^2) so the comparison does not hinge on the reading.
    """
    Z, y = regressors(ds, model.orders)
    s = model.scaling.sigma_omega
    out = {}
    for which in ("mlp", "arx"):
        e = y - model.predict(Z, which)
        J = float(np.mean(e**2))
        out[which] = {"J": J, "sigma_w_J": s * J, "rms_rad_s": s * float(np.sqrt(J)), "ms_rad2_s2": s * s * J}
    return out


def residual_autocorrelation(e: np.ndarray, max_lag: int = 50) -> tuple[np.ndarray, np.ndarray, float]:
    """Scaled autocorrelation r(tau)/r(0) of ``e`` for tau = -max_lag..max_lag (Fig. 6.9), and the 95 %
    band +-1.96/sqrt(N) of white noise."""
    e = np.asarray(e, float) - np.mean(e)
    N = e.size
    full = np.correlate(e, e, mode="full")[N - 1 - max_lag : N + max_lag] / (e @ e)
    return np.arange(-max_lag, max_lag + 1), full, 1.96 / np.sqrt(N)


def free_run(model: NarxModel, ds: Dataset, which: str = "mlp", start: int = 0, length: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop simulation (Figs 6.10, 6.11): the model's own past speeds replace the measured ones.

    Starts from the measured speeds at ``start`` (the first ``lag`` samples); the inputs i~, d~, tau~
    are the measured ones. Returns (simulated, measured) scaled speeds for samples start+lag ...
    """
    o = model.orders
    Z, y = regressors(ds, o)
    end = Z.shape[0] if length is None else min(Z.shape[0], start + length)
    hist = list(ds.w[start + o.lag - o.n : start + o.lag][::-1])  # w[k], w[k-1], ... before the first prediction
    sim = np.empty(end - start)
    M = model.M_l[0]
    z = np.empty(o.dim)
    for m, k in enumerate(range(start, end)):
        z[:] = Z[k]
        z[: o.n] = hist
        p = float(M @ z) if which == "arx" else float(model.mlp.predict(z))
        sim[m] = p
        hist = [p] + hist[:-1]
    return sim, y[start:end]


# --------------------------------------------------------------------------------------------------
# identification and order search
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TrainSettings:
    neurons: int = 4
    init_scale: float = 1e-3
    init_spread: float = 1.0
    init_seed: int = 0
    max_nfev: int = 3000


def identify(train: Dataset, orders: Orders = Orders(), settings: TrainSettings = TrainSettings(),
             progress: Callable[[int, float], None] | None = None) -> tuple[NarxModel, TrainInfo]:  # fmt: skip
    """ARX by least squares, then the MLP initialised from it and trained by LM (6.4.2)."""
    Z, y = regressors(train, orders)
    M_l = fit_arx(Z, y)
    w0 = init_from_arx(M_l, settings.neurons, scale=settings.init_scale, spread=settings.init_spread,
                       seed=settings.init_seed)  # fmt: skip
    w, info = train_lm(w0, Z, y, max_nfev=settings.max_nfev, progress=progress)
    model = NarxModel(orders, train.scaling, w, M_l, 1.0 / train.sample_hz,
                      {"settings": asdict(settings), "training": {k: v for k, v in info.as_dict().items() if k != "history"}})  # fmt: skip
    return model, info


def order_search(train: Dataset, val: Dataset, *, neurons: tuple[int, ...] = (2, 4, 8), n: tuple[int, ...] = (2, 4, 6),
                 n_i: tuple[int, ...] = (1,), n_u: tuple[int, ...] = (1, 2), settings: TrainSettings = TrainSettings(),
                 progress: Callable[[dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:  # fmt: skip
    """Train one MLP per (neurons, n, n_i, n_u) and tabulate sigma_w sqrt(J) on both sets."""
    rows = []
    for l in neurons:
        for nn in n:
            for ni in n_i:
                for nu in n_u:
                    o = Orders(nn, ni, nu)
                    m, info = identify(train, o, replace(settings, neurons=l))
                    mt, mv = metrics(m, train), metrics(m, val)
                    row = {"neurons": l, "n": nn, "n_i": ni, "n_u": nu, "parameters": l * (o.dim + 2),
                           "mlp_train_rms": mt["mlp"]["rms_rad_s"], "mlp_val_rms": mv["mlp"]["rms_rad_s"],
                           "arx_train_rms": mt["arx"]["rms_rad_s"], "arx_val_rms": mv["arx"]["rms_rad_s"],
                           "nfev": info.nfev, "wall_time": info.wall_time}  # fmt: skip
                    rows.append(row)
                    if progress is not None:
                        progress(row)
    return rows


# --------------------------------------------------------------------------------------------------
# artifacts: NAME.npz + NAME.json, no pickle
# --------------------------------------------------------------------------------------------------
def save_model(path: str | Path, model: NarxModel, meta: dict[str, Any] | None = None) -> tuple[Path, Path]:
    """Write PATH.npz (Theta1, Theta_b, Theta2, M_l) and PATH.json (format, orders, scaling, dt, provenance)."""
    doc = {
        "model": "w~[k+1] = Theta2 tanh(Theta1 z[k+1] + Theta_b) (MLP, 2.21); ARX: w~[k+1] = M_l z[k+1]",
        "regressor": model.orders.labels(),
        "signals": {"w": "omega_r [rad/s]", "i": "i_mR_hat [A]", "d": "i_sd_ref [A]", "tau": "i_sq_ref*i_mR_hat [A^2]"},
        "orders": asdict(model.orders),
        "neurons": model.mlp.neurons,
        "scaling": model.scaling.to_dict(),
        "dt": model.dt,
        "meta": {**model.meta, **(meta or {})},
    }
    arrays = {"Theta1": model.mlp.Theta1, "Theta_b": model.mlp.Theta_b, "Theta2": model.mlp.Theta2, "M_l": model.M_l}
    return write_artifact(path, MODEL_FORMAT, MODEL_VERSION, arrays, doc)


def load_model(path: str | Path) -> NarxModel:
    """Read an artifact written by `save_model` (checks format, major version and the npz checksum)."""
    z, doc = read_artifact(path, MODEL_FORMAT, MODEL_VERSION)
    mlp = MLPWeights(z["Theta1"], z["Theta_b"], z["Theta2"])
    return NarxModel(Orders(**doc["orders"]), Scaling.from_dict(doc["scaling"]), mlp, z["M_l"], float(doc["dt"]),
                     dict(doc.get("meta", {})))  # fmt: skip
