"""The parameters of a host_tools.simulation.sim run: the base physics (:class:`SimParams`), one dataclass
of parameters per effect and the registry ``EFFECTS`` (name -> :class:`EffectSpec`: class, on by
default, flips, help), and :class:`SimConfig` (everything a run depends on besides the seed).
The physics they parameterize: host_tools.simulation.sim's module doc; units are in the field names.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from host_tools.simulation.sim_profiles import Profile

# ---------------------------------------------------------------------------------------------
# parameters
# ---------------------------------------------------------------------------------------------

@dataclass
class SimParams:
    """Physics that is always present (no on/off): thermal nodes, drive-frequency law, reversal timing.

    Defaults: a packaged HDRG in a fixture in the chamber; 6227.386 Hz at 20 degC, -20.9 ppm/degC.
    """

    device: str = "hdrg-sim"
    t_ref_c: float = 20.0            # reference temperature of every polynomial [degC]
    tau_pkg_s: float = 900.0         # chamber -> package (fixture) lag [s]
    tau_res_s: float = 600.0         # package -> resonator lag [s]
    tau_el_s: float = 300.0          # package -> electronics lag [s]
    tau_board_s: float = 240.0       # chamber -> board temperature sensor lag [s]
    f0_hz: float = 6227.386          # drive frequency at t_ref_c [Hz]
    k_w_per_c: float = -20.9e-6      # linear temperature coefficient of the frequency [1/degC]
    c2_per_c2: float = -1.0e-8       # curvature [1/degC^2]
    vdd_nominal_v: float = 5.0       # supply voltage [V]
    reversal: bool = False           # mode reversal on: modes 3/1/3/2...; off: mode 0 (FTR)
    exchange_s: float = 30.0         # duration of a mode exchange [s]
    dwell_s: float = 120.0           # duration of a mode-1 or mode-2 window [s]

    def validate(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "device":
                continue
            if f.name == "reversal":
                if not isinstance(v, (bool, np.bool_)):
                    raise ValueError(f"parameter reversal must be true or false, not {v!r}")
                continue
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"parameter {f.name} must be a finite number, not {v!r}")
        for name in ("tau_pkg_s", "tau_res_s", "tau_el_s", "tau_board_s", "f0_hz", "vdd_nominal_v", "dwell_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"parameter {name} must be > 0, not {getattr(self, name)}")
        if not self.exchange_s >= 0:
            raise ValueError(f"parameter exchange_s must be >= 0, not {self.exchange_s}")
        if not isinstance(self.device, str) or not self.device.strip() or "\n" in self.device:
            raise ValueError(f"parameter device must be a one-line non-empty name, not {self.device!r}")


# -- effect parameter dataclasses ----------------------------------------------------------------

@dataclass
class SelfHeating:
    """Self-heating after power-on: each node rises by ``*_rise_c`` with time constant ``*_tau_s``."""
    res_rise_c: float = 0.4
    res_tau_s: float = 600.0
    el_rise_c: float = 1.0
    el_tau_s: float = 300.0
    board_rise_c: float = 0.3
    board_tau_s: float = 400.0


@dataclass
class DampingAsym:
    """B_D [deg/h] = c1 x + c2 x^2 + c3 x^3 + g1 r + g2 x r; x = T_res - t_ref [degC], r = dT_res/dt
    [degC/min].  Does not flip in mode 2."""
    c1_dph_per_c: float = 1.2
    c2_dph_per_c2: float = -0.004
    c3_dph_per_c3: float = 0.0001
    g1_dph_per_cpm: float = -6.0
    g2_dph_per_c_cpm: float = 0.0


@dataclass
class DampingWander:
    """Non-repeatable part of B_D [deg/h]: the damping-axis angle theta_tau wanders (heat flow in
    the structure, paper 3.1), a Gauss-Markov process of standard deviation sigma_dph and
    correlation time tau_s, different at every power-on (seed).  Does not flip in mode 2, so mode
    reversal cancels it while no temperature model can: the reason mode reversal exists."""
    sigma_dph: float = 0.6
    tau_s: float = 7200.0


@dataclass
class Electronics:
    """B_E [deg/h] = e1 y + e2 y^2, y = T_el - t_ref [degC].  Flips in mode 2."""
    e1_dph_per_c: float = 0.18
    e2_dph_per_c2: float = 0.001


@dataclass
class TurnOn:
    """Turn-on transient (parasitic charge settling) amp_dph * exp(-t / tau_s).  Flips in mode 2."""
    amp_dph: float = -2.0
    tau_s: float = 400.0


@dataclass
class EarthRate:
    """Earth rate on a vertical sensitive axis: 15.041 deg/h * sin(latitude_deg) (a true rate)."""
    latitude_deg: float = 28.2


@dataclass
class Arw:
    """Angle random walk N [deg/sqrt(h)]: white rate noise of 1-sample std 60 N sqrt(fs) deg/h."""
    arw_deg_per_sqrt_h: float = 0.003


@dataclass
class BiasInstability:
    """Flicker rate noise, one-sided PSD B^2/(pi f); Allan floor 0.664 B [deg/h]."""
    bi_dph: float = 0.05


@dataclass
class Rrw:
    """Rate random walk K [deg/h/sqrt(h)]: Allan deviation K sqrt(tau / 3 h)."""
    rrw_dph_per_sqrt_h: float = 0.05


@dataclass
class FreqNoise:
    """White measurement noise of the drive frequency [Hz, 1 sigma per sample]."""
    sigma_hz: float = 1.0e-4


@dataclass
class PllQuant:
    """Drive-PLL quantization: frequency rounded to lsb_hz (default: 48-bit NCO at 100 MHz)."""
    lsb_hz: float = 100e6 / 2 ** 48


@dataclass
class TempSensor:
    """Board temperature sensor: white noise sigma_c [degC] and resolution lsb_c [degC] (0: none)."""
    sigma_c: float = 0.02
    lsb_c: float = 0.01


@dataclass
class VddWander:
    """Supply-voltage wander in ``aux_vdd``: Gauss-Markov (sigma_v, tau_s), steps (times [s],
    sizes [V]) and white noise noise_v [V]."""
    sigma_v: float = 0.003
    tau_s: float = 1800.0
    noise_v: float = 0.0003
    step_times_s: tuple = ()
    step_sizes_v: tuple = ()


@dataclass
class ExchangeGlitch:
    """Garbage output in mode 3: +-amp_dph exp(-(t - start)/tau_s) (sign alternates per exchange)
    plus white noise noise_dph."""
    amp_dph: float = 400.0
    tau_s: float = 8.0
    noise_dph: float = 30.0


@dataclass
class ThermalLag:
    """(a) bias coef_dph_per_c * (T_hidden - t_ref), T_hidden = lag(T_ch, tau_s): a node no proxy sees."""
    coef_dph_per_c: float = 0.1
    tau_s: float = 1800.0
    flips: bool = True


@dataclass
class ExchangeTransient:
    """(c) amp_dph * exp(-(t - t_end)/tau_s) in the mode-1/2 window after each exchange ends at t_end.
    flips=True: a settling of the electronics (survives the combiner, adds amp/2-ish after it);
    flips=False: a settling of the mechanics (the combiner mostly cancels it)."""
    amp_dph: float = 1.0
    tau_s: float = 15.0
    flips: bool = True


@dataclass
class ImperfectReversal:
    """(d) term coef_dph_per_c * x * w_m in the raw output (x = T_res - t_ref), w = w1 in modes 0/1 and
    w2 in mode 2, not multiplied by s.  Default (0, 1): a temperature-proportional bias only in mode 2,
    i.e. the mode-2 damping asymmetry is not the exact mirror of mode 1; after the pair combiner
    about coef * x * (w1 - w2) / 2 survives."""
    coef_dph_per_c: float = 0.05
    w1: float = 0.0
    w2: float = 1.0


@dataclass
class ProxyHighOrder:
    """(e) amp_dph * (x / scale_c)^power, x = T_res - t_ref: beyond the cubic of the model."""
    amp_dph: float = 2.0
    power: int = 4
    scale_c: float = 40.0
    flips: bool = True


@dataclass
class BoardTemp:
    """(f) coef_dph_per_c * (T_board - t_ref): bias driven by the board node (logged as temp_c)."""
    coef_dph_per_c: float = 0.1
    flips: bool = True


@dataclass
class AuxVdd:
    """(g) coef_dph_per_v * (vdd - vdd_nominal): bias driven by the supply logged as aux_vdd."""
    coef_dph_per_v: float = 50.0
    flips: bool = True


@dataclass
class Aging:
    """(h) slow drift rate_dph_per_h * t / 3600 [deg/h]."""
    rate_dph_per_h: float = 0.05
    flips: bool = True


@dataclass
class Periodic:
    """(i) amp_dph * sin(2 pi t / period_s + phase_rad)."""
    amp_dph: float = 0.5
    period_s: float = 600.0
    phase_rad: float = 0.0
    flips: bool = True


@dataclass(frozen=True)
class EffectSpec:
    cls: type
    stream: int          # random-stream id (0: deterministic effect)
    default_on: bool
    help: str


# name -> spec; the order is the order of the metadata list
EFFECTS: dict = {
    "self_heating": EffectSpec(SelfHeating, 0, True, "self-heating of resonator/electronics/board after power-on"),
    "damping_asym": EffectSpec(DampingAsym, 0, True,
                               "B_D: damping-asymmetry bias in T_res and dT_res/dt (does not flip)"),
    "damping_wander": EffectSpec(DampingWander, 8, True,
                                 "non-repeatable wander of B_D (damping axis), Gauss-Markov (does not flip)"),
    "electronics": EffectSpec(Electronics, 0, True, "B_E: electronics bias in T_el (flips)"),
    "turn_on": EffectSpec(TurnOn, 0, True, "(b) turn-on transient after power-on (flips)"),
    "earth_rate": EffectSpec(EarthRate, 0, True, "Earth rate, vertical axis (true rate, flips)"),
    "arw": EffectSpec(Arw, 1, True, "angle random walk (white rate noise)"),
    "bias_instability": EffectSpec(BiasInstability, 2, True, "flicker rate noise (bias instability)"),
    "rrw": EffectSpec(Rrw, 3, True, "rate random walk"),
    "freq_noise": EffectSpec(FreqNoise, 4, True, "white noise on the drive frequency"),
    "pll_quant": EffectSpec(PllQuant, 0, True, "quantization of the drive frequency (NCO step)"),
    "temp_sensor": EffectSpec(TempSensor, 5, True, "noise and resolution of the board sensor temp_c"),
    "vdd_wander": EffectSpec(VddWander, 6, True, "wander/steps/noise of the supply aux_vdd"),
    "exchange_glitch": EffectSpec(ExchangeGlitch, 7, True, "garbage loop output during mode exchange"),
    "thermal_lag": EffectSpec(ThermalLag, 0, False, "(a) bias from a hidden lagged temperature node"),
    "exchange_transient": EffectSpec(ExchangeTransient, 0, False, "(c) decay after each mode exchange"),
    "imperfect_reversal": EffectSpec(ImperfectReversal, 0, False, "(d) temperature term not mirrored in mode 2"),
    "proxy_high_order": EffectSpec(ProxyHighOrder, 0, False, "(e) higher-order (x^4, x^5) proxy term"),
    "board_temp": EffectSpec(BoardTemp, 0, False, "(f) bias driven by the board temperature temp_c"),
    "aux_vdd": EffectSpec(AuxVdd, 0, False, "(g) bias driven by the supply voltage aux_vdd"),
    "aging": EffectSpec(Aging, 0, False, "(h) slow drift in time"),
    "periodic": EffectSpec(Periodic, 0, False, "(i) periodic bias component"),
}
DEFAULT_EFFECTS = tuple(n for n, s in EFFECTS.items() if s.default_on)
MISSING_EFFECTS = ("thermal_lag", "turn_on", "exchange_transient", "imperfect_reversal", "proxy_high_order",
                   "board_temp", "aux_vdd", "aging", "periodic")


def effect_params(name: str, **values):
    """The parameter dataclass of effect ``name`` with ``values`` replacing defaults (validated)."""
    spec = param_spec(name)
    known = {f.name: f for f in fields(spec.cls)}
    for key in values:
        if key not in known:
            raise ValueError(f"effect {name!r} has no parameter {key!r}; its parameters: {', '.join(known)}")
    obj = spec.cls(**values)
    _validate_effect(name, obj)
    return obj


def param_spec(name: str) -> EffectSpec:
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r}; known effects: {', '.join(EFFECTS)}")
    return EFFECTS[name]


def _validate_effect(name: str, p) -> None:
    for f in fields(p):
        v = getattr(p, f.name)
        what = f"effect {name} parameter {f.name}"
        if f.name == "flips":
            if not isinstance(v, (bool, np.bool_)):
                raise ValueError(f"{what} must be true or false, not {v!r}")
            continue
        if f.name in ("step_times_s", "step_sizes_v"):
            arr = np.asarray(v, float).ravel()
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{what} must be finite numbers, not {v!r}")
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not math.isfinite(v):
            raise ValueError(f"{what} must be a finite number, not {v!r}")
        if (f.name.startswith("tau") or f.name.endswith("_tau_s") or f.name in ("period_s", "scale_c")) and not v > 0:
            raise ValueError(f"{what} must be > 0, not {v}")
        if (f.name.startswith("sigma") or f.name.startswith("noise") or f.name.startswith("lsb")
                or f.name in ("arw_deg_per_sqrt_h", "bi_dph", "rrw_dph_per_sqrt_h")) and v < 0:
            raise ValueError(f"{what} must be >= 0, not {v}")
    if name == "proxy_high_order" and (int(p.power) != p.power or p.power < 1):
        raise ValueError(f"effect proxy_high_order parameter power must be an integer >= 1, not {p.power}")
    if name == "vdd_wander" and len(np.ravel(p.step_times_s)) != len(np.ravel(p.step_sizes_v)):
        raise ValueError("effect vdd_wander: step_times_s and step_sizes_v must have the same length")


@dataclass
class SimConfig:
    """Everything a run depends on besides the seed."""
    scenario: str
    profile: Profile
    params: SimParams
    effects: dict                 # name -> parameter dataclass (the effects that are ON)
    undeclared: frozenset
    duration_s: float
    sample_rate_hz: float

    @property
    def declared(self) -> list:
        return [n for n in EFFECTS if n in self.effects and n not in self.undeclared]
