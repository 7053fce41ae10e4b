"""The mock plant behind the HAL: motor + inverter + sensors + DC load, stepped by the loop's clock.

`MockPlant` is one `bench.hal.Device` (it owns the simulation) and the rig's `GroundTruth`.
`make_mock_rig` wires it into a `bench.hal.Rig` whose ports are the plant's inverter, sensors and
load. Controllers see only those ports; tests and logs may read ``rig.truth``.

Time: the plant lives on the grid t_k = k dt. ``acquire(t)`` rounds t to the nearest grid point and
integrates up to it, one period at a time (several if ticks were skipped). Each period
[t_k, t_{k+1}):

1. the inverter latches its reference (one-sample delay, ZOH, voltage limit, voltage error (dead
   time, on-state drop) with the current at t_k; a period without a new reference, a tick the loop
   skipped, gets the drive's ride-through substitute; the drive's own over-current check; `mock_hw.inverter`);
2. the DC load's lag advances and hands its mean torque over the period to the motor;
3. (``[mock.thermal]`` on) the winding temperatures advance with the copper losses at t_k
   (`mock_hw.thermal`);
4. the motor integrates (3.41)+(3.37) with the held voltage (RK4, `mock_hw.motor`; with
   ``[mock.motor] saturation`` the flux-state model `mock_hw.motor.SaturatedInductionMotor`); then
   it takes the resistances of the new temperatures (thermal on);
5. the voltage sensors' 1 kHz filter integrates the terminal voltage exactly.

Then the sensors are sampled at t: LEM currents, filtered voltages, encoder.

Engines (``[mock] engine``): "python" runs the periods in the plain-Python objects above (the
reference); "compiled" runs them, and the sampling, in one numba call (`mock_hw.compiled`), equal to
the reference to the last bit, with the same objects as views on its state; "auto" is "compiled" when
numba imports, else "python". Every configuration is supported by both, the non-ideal models
(voltage error, saturation, thermal state) included. The default here is "python": the
compiled engine costs about 0.8 s more at start (numba's import and cached code; about 6.5 s once to
compile into an empty cache) and pays off from about 25 s of simulated time, so sweeps (`bench.workflows.sweep`, many
cases per process) use "auto", and `bench run` does for a real-time run and from 25 s of simulated time
(`bench.runtime.session.default_engines`), the reference for shorter lockstep runs.
"""

from __future__ import annotations

import importlib.util
import math
import random
from dataclasses import dataclass, field, fields, replace
from typing import Any

from bench.errors import BadInput, allowed, finite_number
from bench.hal import Measurement, Rig
from bench.params import T_S_DEFAULT, MotorParams
from mock_hw.inverter import DRIVE_LIMIT_MARGIN, DRIVE_TRIP_MARGIN, Inverter
from mock_hw.load import DcLoadDrive
from mock_hw.motor import OMEGA_EPS_DEFAULT, PSI_M_RATED, InductionMotor, Saturation, SaturatedInductionMotor
from mock_hw.sensors import CurrentSensors, Encoder, VoltageSensors
from mock_hw.thermal import ThermalModel

Triple = tuple[float, float, float]
_ZERO3: Triple = (0.0, 0.0, 0.0)


# --- configuration ------------------------------------------------------------------------------
class MockConfigError(BadInput):
    """A bad mock setting. One line: "<dotted field> <what is allowed>, got <value>"."""

    def __str__(self) -> str:
        return f"{self.field} {self.problem}"


@dataclass(frozen=True)
class MotorConfig:
    """The true machine. In a rig file the MotorParams fields sit flat next to the others."""

    params: MotorParams = field(default_factory=MotorParams)
    omega_eps: float = OMEGA_EPS_DEFAULT  # Coulomb-friction regularisation [rad/s mech]
    omega_r0: float = 0.0  # initial electrical speed [rad/s]
    hold_speed: bool = False  # shaft held at omega_r0 by an ideal speed source
    # main-flux saturation (mock_hw.motor.Saturation): L_m(psi) = L_m0/(1 + (psi/psi_sat)^sat_exp),
    # L_m(psi_rated) = L_m of the params
    saturation: bool = False
    psi_rated: float = PSI_M_RATED  # [Wb]
    psi_sat: float = 1.1  # [Wb]
    sat_exp: float = 7.0


@dataclass(frozen=True)
class InverterConfig:
    u_dc: float = 560.0  # DC link [V]; limits |u_s| to u_dc/sqrt(3)
    delay: int = 1  # computation/transport delay [samples], 0 or 1
    dead_time: float = 0.0  # [s]; 0 = compensated by the drive
    f_pwm: float = 15e3  # switching frequency [Hz] (A.2)
    v_on: Triple = _ZERO3  # switches' on-state drop [V], per phase
    i_knee: float = 0.0  # soft sign of the voltage error [A]: i/sqrt(i^2 + i_knee^2); 0 = hard sign


@dataclass(frozen=True)
class CurrentsConfig:
    turns_ratio: float = 1000.0  # LEM 1:N
    burden: float = 500.0  # [Ohm] -> 0.5 V/A
    adc_bits: int = 12
    adc_range: float = 10.0  # +- [V]
    gain_error: Triple = _ZERO3  # relative, per phase
    offset: Triple = _ZERO3  # [V at the ADC], per phase
    offset_cal: Triple = _ZERO3  # calibrated offset removed on conversion [V at the ADC]
    noise_std: float = 2e-3  # [V rms at the ADC]


@dataclass(frozen=True)
class VoltagesConfig:
    divider_ratio: float = 1.0 / 40.0  # bridge output/input
    f_c: float = 1000.0  # filter natural frequency [Hz]
    zeta: float = 1.0 / math.sqrt(2.0)  # filter damping (Butterworth: -3 dB at f_c)
    adc_bits: int = 12
    adc_range: float = 10.0
    gain_error: Triple = _ZERO3
    offset: Triple = _ZERO3
    offset_cal: Triple = _ZERO3
    noise_std: float = 2e-3


@dataclass(frozen=True)
class EncoderConfig:
    lines: int = 1024  # (A.5); x4 decoding -> 4096 counts/rev
    modulus: int = 1 << 16  # counter wraps here
    index_angle: float = 0.0  # mechanical angle of the index mark [rad]


@dataclass(frozen=True)
class LoadConfig:
    tau: float = 2e-3  # current-loop lag of the DC drive [s]
    torque_limit: float = 15.0  # [N m]


@dataclass(frozen=True)
class ThermalConfig:
    """Winding temperatures and R(T) (`mock_hw.thermal`); off by default."""

    enabled: bool = False
    T_amb: float = 20.0  # ambient [degC]
    R_th_s: float = 0.35  # stator to ambient [K/W]
    tau_s: float = 1200.0  # stator node time constant R_th_s C_s [s]
    R_th_r: float = 0.8  # rotor to ambient [K/W]
    tau_r: float = 900.0  # rotor node time constant [s]
    G_sr: float = 0.0  # stator-rotor coupling [W/K]
    time_scale: float = 1.0  # thermal time compression: time constants / time_scale
    rise_s0: float = 0.0  # initial temperature above ambient [K]
    rise_r0: float = 0.0


@dataclass(frozen=True)
class MockConfig:
    """Everything that defines the mock rig. Build it from a rig file's ``[mock]`` table with
    `from_dict`; every field has a default."""

    motor: MotorConfig = field(default_factory=MotorConfig)
    inverter: InverterConfig = field(default_factory=InverterConfig)
    currents: CurrentsConfig = field(default_factory=CurrentsConfig)
    voltages: VoltagesConfig = field(default_factory=VoltagesConfig)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)
    load: LoadConfig = field(default_factory=LoadConfig)
    thermal: ThermalConfig = field(default_factory=ThermalConfig)
    substeps: int = 1  # RK4 steps per sample period
    seed: int = 0  # rig seed, combined with the run seed of make_mock_rig
    engine: str = "python"  # "compiled" (numba, mock_hw.compiled) | "python" (reference) | "auto"

    @classmethod
    def from_dict(cls, d: dict[str, Any], prefix: str = "mock") -> "MockConfig":
        """Validate a (TOML-style) dict.

        Raises `MockConfigError` (a `bench.errors.BadInput`, hence a ValueError) whose message is
        one line naming the dotted field and what is allowed, e.g.
        ``mock.currents.adc_bits must be an integer in 8..24, got 40``; unknown keys list the
        allowed ones.
        """
        return _from_dict(cls, d, prefix)

    def as_dict(self) -> dict[str, Any]:
        """Plain dict that `from_dict` accepts (motor parameters flattened)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "motor":
                sec = dict(v.params.as_dict())
                sec.update({g.name: getattr(v, g.name) for g in fields(v) if g.name != "params"})
                out["motor"] = sec
            elif hasattr(v, "__dataclass_fields__"):
                sec = {}
                for g in fields(v):
                    x = getattr(v, g.name)
                    sec[g.name] = list(x) if isinstance(x, tuple) else x
                out[f.name] = sec
            else:
                out[f.name] = v
        return out


# Validation rules: (kind, lo, hi). kind: "num" (number in [lo, hi]), "int" (integer in [lo, hi]),
# "bool", "triple" (3 numbers in [lo, hi], or one number). A quantity that must be positive has a
# sane lower end, not 0: a denormal such as 5e-324 passes "> 0" and is zero to every equation.
_INF = math.inf
_M = MotorParams.RANGES  # the machine's ranges: one place for the nominal and the true machine
_RULES: dict[str, dict[str, tuple[str, float, float]]] = {
    "motor": {
        "L_s": ("num", *_M["L_s"]), "L_r": ("num", *_M["L_r"]), "L_m": ("num", *_M["L_m"]),
        "R_s": ("num", *_M["R_s"]), "R_r": ("num", *_M["R_r"]), "Z_p": ("int", 1, 16),
        "J": ("num", *_M["J"]), "B_visc": ("num", 0, 100), "m_coulomb": ("num", 0, 1000),
        "omega_eps": ("num", 1e-4, 1000), "omega_r0": ("num", -5000, 5000), "hold_speed": ("bool", 0, 0),
        "saturation": ("bool", 0, 0), "psi_rated": ("num", 0.01, 10), "psi_sat": ("num", 0.01, 10),
        "sat_exp": ("num", 1, 30),
    },
    "inverter": {
        "u_dc": ("num", 1, 2000), "delay": ("int", 0, 1), "dead_time": ("num", 0, 2e-5),
        "f_pwm": ("num", 100, 200e3), "v_on": ("triple", 0, 10), "i_knee": ("num", 0, 100),
    },
    "thermal": {
        "enabled": ("bool", 0, 0), "T_amb": ("num", -40, 100), "R_th_s": ("num", 1e-3, 100),
        "tau_s": ("num", 1e-3, 1e6), "R_th_r": ("num", 1e-3, 100), "tau_r": ("num", 1e-3, 1e6),
        "G_sr": ("num", 0, 1000), "time_scale": ("num", 1, 1e5), "rise_s0": ("num", 0, 300),
        "rise_r0": ("num", 0, 300),
    },
    "currents": {
        "turns_ratio": ("num", 1e-3, 1e6), "burden": ("num", 1e-3, 1e6), "adc_bits": ("int", 8, 24),
        "adc_range": ("num", 1e-3, 1000), "gain_error": ("triple", -0.5, 0.5),
        "offset": ("triple", -100, 100), "offset_cal": ("triple", -100, 100),
        "noise_std": ("num", 0, 10),
    },
    "voltages": {
        "divider_ratio": ("num", 1e-6, 1), "f_c": ("num", 1, 1e6), "zeta": ("num", 0.05, 10),
        "adc_bits": ("int", 8, 24), "adc_range": ("num", 1e-3, 1000), "gain_error": ("triple", -0.5, 0.5),
        "offset": ("triple", -100, 100), "offset_cal": ("triple", -100, 100),
        "noise_std": ("num", 0, 10),
    },
    "encoder": {"lines": ("int", 1, 1 << 20), "modulus": ("int", 4, 1 << 62), "index_angle": ("num", -1000, 1000)},
    "load": {"tau": ("num", 1e-5, 10), "torque_limit": ("num", 1e-3, 1e4)},
    "": {"substeps": ("int", 1, 1000), "seed": ("int", 0, (1 << 63) - 1), "engine": ("engine", 0, 0)},
}  # fmt: skip
ENGINES = ("auto", "compiled", "python")
_NO_NUMBA = "'compiled' needs numba (pip install numba); use 'auto' or 'python', "
_SECTIONS = {"motor": MotorConfig, "inverter": InverterConfig, "currents": CurrentsConfig,
             "voltages": VoltagesConfig, "encoder": EncoderConfig, "load": LoadConfig,
             "thermal": ThermalConfig}  # fmt: skip


def resolve_engine(engine: str) -> str:
    """The engine that runs: "auto" is "compiled" when numba (and so `mock_hw.compiled`) imports. A compiled module
    that numba cannot load or compile here (no writable cache folder, `bench.core.jit_cache`) makes "auto" run Python,
    with a note for the run's warnings."""
    if engine == "python":
        return "python"
    if engine not in ENGINES:
        raise MockConfigError("mock.engine", f"must be one of {', '.join(map(repr, ENGINES))}, got {engine!r}")
    try:
        import mock_hw.compiled  # noqa: F401  (compiles, or loads the cached machine code)
    except ImportError:
        if engine == "compiled":
            raise MockConfigError("mock.engine", _NO_NUMBA + "got 'compiled'") from None
        return "python"
    except Exception as exc:  # noqa: BLE001 - numba's cache or compiler failed: the reference engine still runs
        why = " ".join(f"{type(exc).__name__}: {exc}".split())
        if engine == "compiled":
            why = f"'compiled' cannot load here ({why}); use 'auto' or 'python'"
            raise MockConfigError("mock.engine", why) from None
        from bench.core.jit_cache import note

        note(f"plant: the Python engine ran, the compiled one failed to load ({why})")
        return "python"
    return "compiled"


_is_num = finite_number


def _rng_text(lo: float, hi: float) -> str:
    if lo == -_INF and hi == _INF:
        return ""
    if hi == _INF:
        return f" >= {lo:g}"
    if lo == -_INF:
        return f" <= {hi:g}"
    return f" in [{lo:g}, {hi:g}]"


def _check(name: str, v: Any, rule: tuple[str, float, float]) -> Any:
    kind, lo, hi = rule
    if kind == "engine":
        if v not in ENGINES:
            raise MockConfigError(name, f"must be one of {', '.join(map(repr, ENGINES))}, got {v!r}")
        if v == "compiled" and importlib.util.find_spec("numba") is None:
            raise MockConfigError(name, _NO_NUMBA + f"got {v!r}")
        return v
    if kind == "bool":
        if not isinstance(v, bool):
            raise MockConfigError(name, f"must be true or false, got {v!r}")
        return v
    if kind == "int":
        if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
            raise MockConfigError(name, f"must be an integer in {lo:g}..{hi:g}, got {v!r}")
        return v
    if kind == "num":
        if not _is_num(v) or not lo <= v <= hi:
            raise MockConfigError(name, f"must be a finite number{_rng_text(lo, hi)}, got {v!r}")
        return float(v)
    # triple
    vals = [v, v, v] if _is_num(v) else v
    if (not isinstance(vals, (list, tuple)) or len(vals) != 3
            or not all(_is_num(x) and lo <= x <= hi for x in vals)):  # fmt: skip
        raise MockConfigError(name, f"must be one number or a list of 3 (phases a, b, c){_rng_text(lo, hi)}, got {v!r}")
    return tuple(float(x) for x in vals)


def _from_dict(cls: type[MockConfig], d: dict[str, Any], prefix: str) -> MockConfig:
    if not isinstance(d, dict):
        raise MockConfigError(prefix, f"must be a table, got {type(d).__name__}")
    top_allowed = [*_SECTIONS, *_RULES[""]]
    kw: dict[str, Any] = {}
    for key, val in d.items():
        name = f"{prefix}.{key}"
        if key in _RULES[""]:
            kw[key] = _check(name, val, _RULES[""][key])
            continue
        if key not in _SECTIONS:
            raise MockConfigError(name, f"unknown key; allowed: {allowed(top_allowed)}")
        if not isinstance(val, dict):
            raise MockConfigError(name, f"must be a table of {allowed(_RULES[key])}, got {val!r}")
        rules = _RULES[key]
        sec: dict[str, Any] = {}
        for k, v in val.items():
            if k not in rules:
                raise MockConfigError(f"{name}.{k}", f"unknown key; allowed: {allowed(rules)}")
            sec[k] = _check(f"{name}.{k}", v, rules[k])
        kw[key] = _build_section(key, sec, name)
    return cls(**kw)


def _build_section(key: str, sec: dict[str, Any], name: str) -> Any:
    if key == "motor":
        pnames = {f.name for f in fields(MotorParams)}
        params = replace(MotorParams(), **{k: v for k, v in sec.items() if k in pnames})
        if params.L_m**2 >= params.L_s * params.L_r:
            raise MockConfigError(f"{name}.L_m", f"must satisfy L_m^2 < L_s*L_r (positive leakage), got {params.L_m!r}")
        rest = {k: v for k, v in sec.items() if k not in pnames}
        cfg = MotorConfig(params=params, **rest)
        if cfg.saturation and not (params.L_m < params.L_s and params.L_m < params.L_r):
            raise MockConfigError(f"{name}.saturation", "needs L_m < L_s and L_m < L_r (positive leakages), "
                                  f"got L_m={params.L_m!r}, L_s={params.L_s!r}, L_r={params.L_r!r}")  # fmt: skip
        return cfg
    if key == "encoder":
        cfg = EncoderConfig(**sec)
        if cfg.modulus < 4 * cfg.lines:
            raise MockConfigError(f"{name}.modulus", f"must be >= 4*lines = {4 * cfg.lines}, got {cfg.modulus}")
        return cfg
    return _SECTIONS[key](**sec)


# --- the plant --------------------------------------------------------------------------------
TRUTH_FIELDS: tuple[str, ...] = (
    "i_s_re", "i_s_im", "i_m_re", "i_m_im", "psi_r_re", "psi_r_im", "omega_r", "theta_r",
    "m_e", "m_L", "u_s_re", "u_s_im", "p_in",
)  # fmt: skip
SATURATION_TRUTH = ("psi_m", "l_m")  # |psi_m| [Wb], its secant L_m [H] (with [mock.motor] saturation)
THERMAL_TRUTH = ("temp_s", "temp_r", "r_s", "r_r")  # winding temperatures [degC], R_s, R_r [Ohm] ([mock.thermal])


class MockPlant:
    """The simulated rig (a `Device`) and its ground truth (a `GroundTruth`).

    Truth at the last sample time t: stator/magnetising current and rotor flux (stator-fixed),
    electrical speed and angle theta_r = Z_p theta_mech, torques m_e and m_L (load drive output),
    the terminal voltage u_s applied over the period ending at t (the input, or the back-EMF while
    coasting) and p_in = (3/2) Re{u_s i_s^*} with i_s at t. With saturation on, `SATURATION_TRUTH`
    follows; with the thermal state on, `THERMAL_TRUTH` (then the log's /truth has those fields too;
    with both off it is exactly `TRUTH_FIELDS`, as before these models existed).
    """

    fields = TRUTH_FIELDS

    def __init__(
        self,
        config: MockConfig | None = None,
        dt: float = T_S_DEFAULT,
        seed: int = 0,
        params_true: MotorParams | None = None,
        *,
        ride_through: float | None = None,
        i_trip: float = math.inf,
        i_limit: float = math.inf,
    ) -> None:
        cfg = config if config is not None else MockConfig()
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        self.config = cfg
        self.dt = float(dt)
        self._inv_dt = 1.0 / self.dt
        self.seed = seed
        params = params_true if params_true is not None else cfg.motor.params
        self.engine = resolve_engine(cfg.engine)
        cm: Any = None
        buf: Any = None
        if self.engine == "compiled":
            from mock_hw import compiled as cm

            buf = cm.new_buffer()
        mc = cfg.motor
        mkw = dict(substeps=cfg.substeps, omega_eps=mc.omega_eps, omega_r0=mc.omega_r0, hold_speed=mc.hold_speed)
        if mc.saturation:
            sat = Saturation(params.L_m, mc.psi_rated, mc.psi_sat, mc.sat_exp)
            self.motor = (cm.SaturatedMotorView(buf, params, sat, **mkw) if cm
                          else SaturatedInductionMotor(params, sat, **mkw))  # fmt: skip
        else:
            self.motor = cm.MotorView(buf, params, **mkw) if cm else InductionMotor(params, **mkw)
        tc = cfg.thermal
        self.thermal: ThermalModel | None = None
        if tc.enabled:
            tkw = dict(T_amb=tc.T_amb, R_th_s=tc.R_th_s, tau_s=tc.tau_s, R_th_r=tc.R_th_r, tau_r=tc.tau_r, G_sr=tc.G_sr,
                       time_scale=tc.time_scale, rise_s0=tc.rise_s0, rise_r0=tc.rise_r0)  # fmt: skip
            self.thermal = (cm.ThermalView(buf, self.dt, params.R_s, params.R_r, **tkw) if cm
                            else ThermalModel(params.R_s, params.R_r, **tkw))  # fmt: skip
        extra = (SATURATION_TRUTH if mc.saturation else ()) + (THERMAL_TRUTH if tc.enabled else ())
        if extra:
            self.fields = TRUTH_FIELDS + extra
        ic = cfg.inverter
        self.inverter = Inverter(ic.u_dc, delay=ic.delay, dead_time=ic.dead_time, f_pwm=ic.f_pwm, v_on=ic.v_on,
                                 i_knee=ic.i_knee, T_s=self.dt, ride_through=ride_through, i_trip=i_trip,
                                 i_limit=i_limit)  # fmt: skip
        cc, vc = cfg.currents, cfg.voltages
        self.currents = CurrentSensors(
            turns_ratio=cc.turns_ratio, burden=cc.burden, adc_bits=cc.adc_bits, adc_range=cc.adc_range,
            gain_error=cc.gain_error, offset=cc.offset, offset_cal=cc.offset_cal, noise_std=cc.noise_std,
            rng=self._rng("currents"))  # fmt: skip
        vkw = dict(divider_ratio=vc.divider_ratio, f_c=vc.f_c, zeta=vc.zeta, adc_bits=vc.adc_bits,
                   adc_range=vc.adc_range, gain_error=vc.gain_error, offset=vc.offset, offset_cal=vc.offset_cal,
                   noise_std=vc.noise_std, rng=self._rng("voltages"))  # fmt: skip
        self.voltages = cm.VoltageView(buf, self.dt, **vkw) if cm else VoltageSensors(self.dt, **vkw)
        ec = cfg.encoder
        ekw = dict(lines=ec.lines, modulus=ec.modulus, index_angle=ec.index_angle)
        self.encoder = cm.EncoderView(buf, **ekw) if cm else Encoder(**ekw)
        lkw = dict(tau=cfg.load.tau, torque_limit=cfg.load.torque_limit)
        self.load = cm.LoadView(buf, self.dt, **lkw) if cm else DcLoadDrive(**lkw)
        self._buf = buf  # compiled engine: the state buffer; None: the Python engine
        if cm:
            self._lent = [False]  # set when Python code takes an ADC's random.Random (cm.AdcView.rng)
            self.currents.adc = cm.AdcView.like(self.currents.adc, buf, cm.PF.ADC_I, cm.PI.GN_I, cm.PI.MT_I, self._lent)
            self.voltages.adc = cm.AdcView.like(self.voltages.adc, buf, cm.PF.ADC_U, cm.PI.GN_U, cm.PI.MT_U, self._lent)
            buf[cm.PF.DT], buf[cm.PF.DEAD], buf[cm.PF.FPWM] = self.dt, ic.dead_time, ic.f_pwm
            buf[cm.PF.VON_A], buf[cm.PF.VON_B], buf[cm.PF.VON_C] = self.inverter.v_on
            buf[cm.PF.IKNEE] = self.inverter.i_knee
            self._advance = cm.entry(cm.advance)
            self._integrate = cm.entry(cm.integrate)
            self._cm = cm
            self._truth = cm.entry(cm.truth_sat if mc.saturation else cm.truth)
        self.active = False
        self.configure()

    def _rng(self, name: str) -> random.Random:
        # one stream per sensor: switching noise on in one does not shift the others
        return random.Random(f"imbench-mock:{self.config.seed}:{self.seed}:{name}")

    # --- Device ---------------------------------------------------------------------------
    def configure(self) -> None:
        """Reset the simulation to t = 0 (motor at rest or at omega_r0, de-energised)."""
        mc = self.config.motor
        self.motor.reset(omega_r=mc.omega_r0)
        self.motor.coast = True
        if self.thermal is not None:
            self.thermal.reset()
            self.motor.set_resistances(self.thermal.R_s, self.thermal.R_r)
        self.inverter.reset()
        self.voltages.reset()
        self.load.reset()
        self.encoder.reset(self.motor.theta_mech)
        self.currents.adc.rng = self._rng("currents")
        self.voltages.adc.rng = self._rng("voltages")
        self.k = 0
        self.t = 0.0
        self._sample_sensors()

    def activate(self) -> None:
        self.active = True

    def deactivate(self) -> None:
        # The Rig has already commanded the safe state; the simulation keeps running (coasting).
        self.active = False

    def acquire(self, t: float) -> None:
        """Integrate up to the grid point nearest t, then sample the sensors there."""
        n = math.floor(t * self._inv_dt + 0.5)
        k = self.k
        if self._buf is not None:  # compiled engine
            if self._lent[0]:
                self._reload_rngs()
            if n > k:
                inv, buf, u_dc, m_L_ref = self.inverter, self._buf, self.inverter.u_dc, self.load.m_L_ref
                check = inv.i_trip < math.inf
                cm = self._cm
                while True:  # the drive's period start (Inverter.pipeline) in Python, the period in the kernel
                    u, on = inv.pipeline(complex(buf.item(cm.PF.IS_RE), buf.item(cm.PF.IS_IM)) if check else 0j)
                    k += 1
                    if k == n:
                        break
                    inv.u_applied = self._integrate(buf, u, on, u_dc, m_L_ref)  # a period the loop skipped
                (self.currents.adc.value, self.currents.adc.raw, self.voltages.adc.value, self.voltages.adc.raw,
                 self.encoder._val, inv.u_applied) = self._advance(buf, 1, u, on, u, on, u_dc, m_L_ref)  # fmt: skip
                self.k = n
                self.t = n * self.dt
            else:
                self._sample_sensors()
            return
        if n > k:
            motor, inv, load, volt, dt, th = self.motor, self.inverter, self.load, self.voltages, self.dt, self.thermal
            while k < n:
                u = inv.latch(motor.i_s)  # period start: one-sample delay, ZOH, limit, voltage error
                motor.coast = not inv.on
                if th is None:
                    motor.step(u, load.advance(dt), dt)
                else:  # losses at t_k held over the period; R(T) from its end on
                    th.advance(*motor.winding_losses(), dt)
                    motor.step(u, load.advance(dt), dt)
                    motor.set_resistances(th.R_s, th.R_r)
                volt.advance(motor.u_s)
                k += 1
            self.k = k
            self.t = k * dt
        self._sample_sensors()

    def measure(self, t: float) -> Measurement:
        """`acquire` and the rig's `Measurement` of this plant's ports, in one call (`bench.hal.Rig.read`
        assembles the same from the ports; the mock plant reports no link status bits)."""
        self.acquire(t)
        cur, volt = self.currents.adc, self.voltages.adc
        (i_a, i_b, i_c), (u_a, u_b, u_c), (count, index) = cur.value, volt.value, self.encoder.read()
        st = self.inverter.status()
        return Measurement(t, i_a, i_b, i_c, u_a, u_b, u_c, count, index, st.u_dc, st.enabled, st.fault, cur.raw,
                           volt.raw, 0, st.fault_name)  # fmt: skip

    def _sample_sensors(self) -> None:
        if self._buf is not None:
            if self._lent[0]:
                self._reload_rngs()
            (self.currents.adc.value, self.currents.adc.raw, self.voltages.adc.value, self.voltages.adc.raw,
             self.encoder._val, _) = self._advance(self._buf, 0, 0j, False, 0j, False, self.inverter.u_dc, 0.0)
            return
        m = self.motor
        self.currents.sample(m.i_s)
        self.voltages.sample()
        self.encoder.sample(m.theta_mech)

    def _reload_rngs(self) -> None:
        for adc in (self.currents.adc, self.voltages.adc):
            if adc._is_lent:
                adc.load_rng()
        self._lent[0] = False

    def step(self, n: int = 1) -> None:
        """Advance n periods (convenience for tests; the loop uses `acquire`)."""
        self.acquire((self.k + n) * self.dt)

    # --- GroundTruth ----------------------------------------------------------------------
    def sample(self) -> tuple[float, ...]:
        if self._buf is not None:
            th = self.thermal
            if th is None:
                return self._truth(self._buf)
            return self._truth(self._buf) + (th.T_s, th.T_r, th.R_s, th.R_r)
        m = self.motor
        i_s, i_m, u = m.i_s, m.i_m, m.u_s
        L_m = m.params.L_m
        out = (i_s.real, i_s.imag, i_m.real, i_m.imag, L_m * i_m.real, L_m * i_m.imag, m.omega_r,
               m.params.Z_p * m.theta_mech, m.m_e, self.load.m_L, u.real, u.imag,
               1.5 * (u.real * i_s.real + u.imag * i_s.imag))  # fmt: skip
        if self.fields is TRUTH_FIELDS:
            return out
        if isinstance(m, SaturatedInductionMotor):
            out += (abs(m.psi_m), m.L_m_now)
        th = self.thermal
        if th is not None:
            out += (th.T_s, th.T_r, th.R_s, th.R_r)
        return out

    def truth(self) -> dict[str, float]:
        """The ground truth as a dict (for tests and tools; not per tick)."""
        return dict(zip(self.fields, self.sample()))


def drive_settings(limits: Any) -> dict[str, float]:
    """The drive's ride-through budget, over-current trip and current limit for a rig's `bench.core.supervisor.Limits`:
    the budget as the rig file says, the trip `DRIVE_TRIP_MARGIN` above the PC's phase trip, the current limit
    while riding through `DRIVE_LIMIT_MARGIN` below it."""
    return {"ride_through": limits.ride_through, "i_trip": limits.I_trip_phase * DRIVE_TRIP_MARGIN,
            "i_limit": limits.I_trip_phase * DRIVE_LIMIT_MARGIN}


def make_mock_rig(
    config: MockConfig | None = None,
    dt: float = T_S_DEFAULT,
    seed: int = 0,
    params_true: MotorParams | None = None,
    *,
    ride_through: float | None = None,
    i_trip: float = math.inf,
    i_limit: float = math.inf,
) -> Rig:
    """A `bench.hal.Rig` named "mock" on a fresh `MockPlant` (also ``rig.truth``).

    ``seed`` is the run seed; with ``config.seed`` it selects the noise streams. ``params_true``
    overrides ``config.motor.params`` (e.g. a hot rotor while the controller keeps the nominal one).
    ``ride_through`` [s], ``i_trip`` and ``i_limit`` [A] are the drive's stall budget, its own over-current trip
    and its current limit while riding through (`mock_hw.inverter.Inverter`; a session sets them from the rig's
    limits, `drive_settings`).
    """
    plant = MockPlant(config, dt=dt, seed=seed, params_true=params_true, ride_through=ride_through, i_trip=i_trip,
                      i_limit=i_limit)
    return Rig(name="mock", inverter=plant.inverter, currents=plant.currents, voltages=plant.voltages,
               encoder=plant.encoder, load=plant.load, devices=[plant], truth=plant, measure=plant.measure)  # fmt: skip
