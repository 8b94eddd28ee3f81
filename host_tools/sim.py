"""The virtual gyroscope: a deterministic-for-a-seed simulator of run logs of a mode-matched disk
gyroscope (HDRG) in a temperature chamber (Chen et al. 2022), and the ``hdrg simulate`` command.

Signal chain (every block but the chamber and the thermal lags is an *effect* that can be switched
off and has a dataclass of parameters; units are in the field names: ``_s`` seconds, ``_c`` degC,
``_hz`` Hz, ``_dph`` deg/h, ``_cpm`` degC/min, ``_v`` volt):

1. **Chamber** ``T_ch(t)`` [degC]: a piecewise-linear time/temperature table (:class:`Profile`).
2. **Thermal nodes**, first-order lags, each starting soaked at the chamber temperature at t = 0:
   package ``T_pkg = lag(T_ch, tau_pkg_s)``; resonator ``T_res = lag(T_pkg, tau_res_s)``;
   electronics ``T_el = lag(T_pkg, tau_el_s)``; board sensor ``T_board = lag(T_ch, tau_board_s)``.
   The recursion is the exact discretization of ``dy/dt = (u - y)/tau`` for an input linear
   between samples (first-order hold), so it is stable for any tau > 0 and exact for the chamber
   table whenever its breakpoints fall on samples.  Effect ``self_heating`` adds, after power-on
   at t = 0, ``rise_c * (1 - exp(-t / tau_s))`` to the resonator, the electronics and the board.
3. **Drive frequency** (the self-sensed proxy, ``freq_hz``):
   ``f = f0_hz * (1 + k_w_per_c * x + c2_per_c2 * x**2)``, ``x = T_res - t_ref_c``; effect
   ``freq_noise`` adds white noise, effect ``pll_quant`` rounds to the drive PLL's NCO step.
4. **Raw loop output** ``rate_dph`` [deg/h], with ``s = +1`` in modes 0/1, ``-1`` in mode 2 and 0
   in mode 3 (the sign convention of shared/formats/run-log.md)::

       rate = s * (Omega + B_E + B_turnon + flipping extras) + B_D + non-flipping extras + noise

   - ``damping_asym`` (B_D, eq. 1, does NOT flip): cubic in ``x`` plus the thermal-gradient term
     ``g1 * r + g2 * x * r`` with ``r = dT_res/dt`` [degC/min] (the gradient across a lagged
     resonator is ``tau_res * r``): the FTR hysteresis of Fig. 7.  Everything in B_D is a function
     of the resonator temperature and its rate, i.e. of the proxy ``u`` and its rate ``v``.
   - ``electronics`` (B_E, flips): quadratic in ``T_el - t_ref_c``.
   - ``turn_on`` (flips): ``amp_dph * exp(-t / tau_s)``, parasitic-charge settling after power-on.
   - ``earth_rate`` (a true rate, flips): ``15.041 deg/h * sin(latitude)``, vertical sensitive axis.
   - noise (does not flip; independent of the mode): ``arw`` (white rate noise, angle random walk
     ``N`` [deg/sqrt(h)]: 1-sample std ``60 * N * sqrt(fs)`` deg/h), ``bias_instability`` (flicker,
     one-sided PSD ``B**2 / (pi f)`` from a sum of Gauss-Markov processes, 2 per decade of
     correlation time from 1/fs to 1e7 s: Allan floor ``0.664 * B``), ``rrw`` (rate random
     walk ``K`` [deg/h/sqrt(h)]: Allan deviation ``K * sqrt(tau / 3 h)``).
   - ``exchange_glitch``: in mode 3 the loop output is garbage: a decaying transient
     ``+-amp_dph * exp(-(t - start)/tau_s)`` (sign alternates per exchange) plus white noise.
5. **Board sensor** ``temp_c`` = ``T_board`` (+ effect ``temp_sensor``: noise and quantization);
   **supply** ``aux_vdd`` = ``vdd_nominal_v`` (+ effect ``vdd_wander``: Gauss-Markov wander, steps,
   white noise).

"Missing-effect" families (off by default; for the closed-loop diagnosis tests): ``thermal_lag``
(a), ``turn_on`` (b), ``exchange_transient`` (c), ``imperfect_reversal`` (d), ``proxy_high_order``
(e), ``board_temp`` (f), ``aux_vdd`` (g), ``aging`` (h), ``periodic`` (i).  Bias families with a
``flips`` parameter add ``s * term`` to the raw output when ``flips`` is True (like a true rate and
B_E: mode reversal does NOT cancel it) and ``term`` when False (like B_D: mode reversal cancels it);
in mode 3 (s = 0) only the non-flipping terms and the noise are present.

Metadata of a simulated log: ``device``, ``sample_rate_hz``, ``reversal`` (on/off), ``exchange_s``
and ``dwell_s`` (only when reversal is on), ``scenario``, ``seed``, ``profile``, ``effects`` (comma
list, registry order, of the effects that are ON and declared).  Effects passed as ``undeclared``
act on the data but are not listed.

Calibration (defaults; judged like the paper on non-overlapping 100-s block means of the valid
output: std with ddof=1, and max-min; the mode-reversal output is the paper's pair combiner
``out = (c + W_other) / 2``).  Measured with seeds 0, 1, 2, 7 (spread < 0.5 %), see
tests/test_sim.py::test_calibration:

=====================================  ===============  ================  ===================
run                                    stability 1 sig  variation (p-p)   paper
=====================================  ===============  ================  ===================
paper-ftr-cycle-4dpm (100 s / 1 s)     27.9 / 27.9      67.6 / 68.5       27.8, 66 (Table 2)
paper-mr-cycle-4dpm, pair (100 s/1 s)  2.61 / 2.62      6.78 / 8.2        2.57, 6.12 (4.4)
paper-ftr-cycle-1dpm, -2dpm (100 s)    27.9, 28.0       66.5, 67.0        23.5/62.3, 28.4/66.2
paper-slow-ramp (100 s)                62               174               15.8, 129 (Table 1)
paper-startup-mr, pair (1 s)           0.44             2.1               0.29-0.52, 1.5-3.3
=====================================  ===============  ================  ===================

With the pair combiner the residual of the mode-reversal run is B_E (a function of the lagged
electronics temperature, i.e. of u and v) plus a first-order term of the temperature change
between the two modes' windows, ``+-(dB_D/dt) * (lag)/2`` with the sign of the mode (eq. 6): a
17-term fit in (u, v) leaves ~0.85 deg/h (100 s), adding ``z = s * v`` (k7) ~0.34 deg/h, and the
trend combiner of host_tools.reversal + 17 terms ~0.27 deg/h (paper: 0.45).  The FTR run
self-compensates to ~0.2 deg/h (paper: 1.1), the start-up run 0.48 -> 0.04 deg/h (paper: 0.05-0.08).

Determinism: every random effect draws from its own streams ``numpy.random.default_rng([seed,
stream_id, sub])``, so a seed gives bit-identical arrays, switching one effect off leaves every other
effect's samples unchanged (differencing two runs isolates one contribution), and everything is
causal: a longer run of the same seed and settings starts with the same samples.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field, fields

import numpy as np
from scipy.signal import lfilter

from host_tools.runlog import RunLog

SIM_VERSION = 1
EARTH_RATE_DPH = 15.041067  # sidereal Earth rate [deg/h]
MAX_SAMPLES = 100_000_000


# ---------------------------------------------------------------------------------------------
# chamber profiles
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Profile:
    """A chamber temperature program: breakpoints ``t_s`` [s, strictly increasing, first >= 0] and
    ``temp_c`` [degC], linear in between; before the first breakpoint the first temperature, after
    the last one the last temperature holds."""

    t_s: tuple
    temp_c: tuple
    name: str = "table"

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        y = np.asarray(self.temp_c, float)
        where = f"chamber profile '{self.name}'"
        if t.ndim != 1 or y.ndim != 1 or len(t) != len(y):
            raise ValueError(f"{where}: t_s and temp_c must be 1-D of equal length ({t.shape} vs {y.shape})")
        if len(t) < 1:
            raise ValueError(f"{where}: needs at least one breakpoint")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
            raise ValueError(f"{where}: NaN/inf in the table")
        if t[0] < 0:
            raise ValueError(f"{where}: first time {t[0]} s is negative")
        if np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0)) + 1
            raise ValueError(f"{where}: t_s not strictly increasing at row {k} ({t[k - 1]} then {t[k]})")
        if np.any(y < -273.15):
            raise ValueError(f"{where}: temperature below absolute zero")
        object.__setattr__(self, "t_s", tuple(float(v) for v in t))
        object.__setattr__(self, "temp_c", tuple(float(v) for v in y))

    @property
    def end_s(self) -> float:
        return self.t_s[-1]

    def __call__(self, t) -> np.ndarray:
        """Chamber temperature [degC] at times ``t`` [s]."""
        return np.interp(np.asarray(t, float), self.t_s, self.temp_c)

    @classmethod
    def from_table(cls, table, name: str = "table") -> "Profile":
        """From rows ``(t_s, temp_c)`` (a list of pairs or an (n, 2) array)."""
        arr = np.asarray(table, float)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"chamber profile '{name}': need rows (t_s, temp_c), got shape {arr.shape}")
        return cls(tuple(arr[:, 0]), tuple(arr[:, 1]), name)

    @classmethod
    def from_csv(cls, path) -> "Profile":
        """From a 2-column CSV ``t_s,temp_c`` (an optional header row; ``#`` lines are comments)."""
        path = os.fspath(path)
        rows = []
        with open(path, encoding="utf-8") as fh:
            for lineno, line in enumerate(fh, 1):
                text = line.strip()
                if not text or text.startswith("#"):
                    continue
                cells = [c.strip() for c in text.split(",")]
                try:
                    vals = [float(c) for c in cells]
                except ValueError:
                    if not rows and lineno == _first_content_line(path):
                        continue  # header
                    raise ValueError(f"{path}:{lineno}: not two numbers t_s,temp_c: {text!r}") from None
                if len(vals) != 2:
                    raise ValueError(f"{path}:{lineno}: {len(vals)} cells, a profile row is t_s,temp_c")
                rows.append(vals)
        if not rows:
            raise ValueError(f"{path}: no profile rows (expected lines t_s,temp_c)")
        try:
            return cls.from_table(rows, name=os.path.basename(path))
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None


def _first_content_line(path) -> int:
    with open(path, encoding="utf-8") as fh:
        for lineno, line in enumerate(fh, 1):
            if line.strip() and not line.strip().startswith("#"):
                return lineno
    return 0


def cycle_profile(rate_c_per_min: float, low_c: float = -20.0, high_c: float = 20.0,
                  hold_s: float = 7200.0, n_cycles: int = 2, end_hold_s: float | None = None) -> Profile:
    """Temperature cycles (paper 4.3): from ``high_c`` (held ``end_hold_s``, default ``hold_s / 2``)
    ramp to ``low_c`` at ``rate_c_per_min``, hold ``hold_s``, ramp back, hold, ... ``n_cycles``
    times; the last hold at ``high_c`` lasts ``end_hold_s`` (so both extremes get equal time)."""
    if end_hold_s is None:
        end_hold_s = hold_s / 2.0
    if not rate_c_per_min > 0 or not hold_s >= 0 or not end_hold_s >= 0 or n_cycles < 1 or not high_c > low_c:
        raise ValueError(f"cycle profile: need rate > 0, holds >= 0, n_cycles >= 1, high > low "
                         f"(got {rate_c_per_min}, {hold_s}, {end_hold_s}, {n_cycles}, {low_c}..{high_c})")
    ramp = (high_c - low_c) / rate_c_per_min * 60.0
    t, y = [0.0], [high_c]
    for k in range(n_cycles):
        for target in (low_c, high_c):
            hold = end_hold_s if (k == 0 and target == low_c) else hold_s
            t += [t[-1] + hold, t[-1] + hold + ramp]
            y += [y[-1], target]
    t.append(t[-1] + end_hold_s)
    y.append(y[-1])
    return Profile(tuple(t), tuple(y), f"cycle {low_c:g}..{high_c:g} degC at {rate_c_per_min:g} degC/min, "
                                       f"holds {hold_s:g} s, {n_cycles} cycles")


def slow_ramp_profile(rate_c_per_min: float = 0.5, hold_s: float = 3600.0) -> Profile:
    """Paper 4.2 / Table 1: hold at -40 degC, ramp slowly to 60 degC, hold, ramp down to 25 degC,
    hold."""
    r = 60.0 / rate_c_per_min
    t = [0.0, hold_s, hold_s + 100 * r, 2 * hold_s + 100 * r, 2 * hold_s + 135 * r, 3 * hold_s + 135 * r]
    return Profile(tuple(t), (-40.0, -40.0, 60.0, 60.0, 25.0, 25.0),
                   f"slow ramp -40 -> 60 -> 25 degC at {rate_c_per_min:g} degC/min, holds {hold_s:g} s")


def constant_profile(temp_c: float = 20.0, duration_s: float = 3600.0) -> Profile:
    """Constant chamber temperature (static runs, power-on at ambient)."""
    return Profile((0.0, float(duration_s)), (float(temp_c), float(temp_c)), f"constant {temp_c:g} degC")


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
    spec = _spec(name)
    known = {f.name: f for f in fields(spec.cls)}
    for key in values:
        if key not in known:
            raise ValueError(f"effect {name!r} has no parameter {key!r}; its parameters: {', '.join(known)}")
    obj = spec.cls(**values)
    _validate_effect(name, obj)
    return obj


def _spec(name: str) -> EffectSpec:
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


# ---------------------------------------------------------------------------------------------
# scenarios
# ---------------------------------------------------------------------------------------------

@dataclass
class Scenario:
    description: str
    profile: object                       # a Profile, or a callable () -> Profile
    reversal: bool = False
    duration_s: float | None = None       # None: the profile's end
    off: tuple = ()                       # default effects switched off
    params: dict = field(default_factory=dict)


SCENARIOS: dict = {
    "paper-ftr-cycle-1dpm": Scenario(
        "FTR, -20..20 degC cycles at 1 degC/min, 2-h holds (paper 4.3, Tables 2/3)",
        lambda: cycle_profile(1.0)),
    "paper-ftr-cycle-2dpm": Scenario(
        "FTR, -20..20 degC cycles at 2 degC/min, 2-h holds (paper 4.3, Tables 2/3, benchmark data 1)",
        lambda: cycle_profile(2.0)),
    "paper-ftr-cycle-4dpm": Scenario(
        "FTR, -20..20 degC cycles at 4 degC/min, 2-h holds (paper 4.3/4.4: 27.8 deg/h, 66 deg/h)",
        lambda: cycle_profile(4.0)),
    "paper-slow-ramp": Scenario(
        "FTR, slow ramp -40 -> 60 degC at 0.5 degC/min, then 25 degC (paper 4.2, Table 1)",
        lambda: slow_ramp_profile()),
    "paper-mr-cycle-4dpm": Scenario(
        "mode reversal 30/120/30/120 s, -20..20 degC cycles at 4 degC/min (paper 4.4: 2.57, 6.12 deg/h)",
        lambda: cycle_profile(4.0), reversal=True),
    "paper-startup-mr": Scenario(
        "mode reversal, power-on at constant 25 degC ambient, 45 min: self-heating + turn-on (paper 4.4, Table 4)",
        lambda: constant_profile(25.0, 2700.0), reversal=True),
    "startup-ftr": Scenario(
        "FTR, power-on at constant 25 degC ambient, 45 min: self-heating + turn-on",
        lambda: constant_profile(25.0, 2700.0)),
    "static": Scenario(
        "FTR, constant 20 degC, warmed up (no self-heating/turn-on): for Allan deviation",
        lambda: constant_profile(20.0, 7200.0), off=("self_heating", "turn_on")),
}


def list_scenarios() -> dict:
    """name -> one-line description of every named scenario."""
    return {name: sc.description for name, sc in SCENARIOS.items()}


# ---------------------------------------------------------------------------------------------
# building the configuration
# ---------------------------------------------------------------------------------------------

def _as_profile(value) -> Profile:
    if isinstance(value, Profile):
        return value
    if isinstance(value, (str, os.PathLike)):
        return Profile.from_csv(value)
    if callable(value):
        return value()
    return Profile.from_table(value)


def _effect_items(value, what: str) -> dict:
    """Normalize an effect selection to {name: {param: value}}: a comma string 'a,b', 'NAME:p=v,...'
    strings, an iterable of names, or a dict name -> dict of parameters (or None)."""
    if value is None:
        return {}
    if isinstance(value, str):
        value = [v for v in value.split(",") if v.strip()] if ":" not in value else [value]
    if isinstance(value, dict):
        out = {}
        for name, params in value.items():
            _spec(name)
            if params is None:
                params = {}
            elif dataclasses.is_dataclass(params):
                params = dataclasses.asdict(params)
            elif not isinstance(params, dict):
                raise ValueError(f"{what}: parameters of effect {name!r} must be a dict, not {params!r}")
            out[name] = dict(params)
        return out
    out = {}
    for item in value:
        if not isinstance(item, str):
            raise ValueError(f"{what}: effect names must be strings, not {item!r}")
        name, params = parse_inject(item)
        out.setdefault(name, {}).update(params)
    return out


def parse_inject(text: str) -> tuple[str, dict]:
    """Parse ``NAME`` or ``NAME:param=value,param=value`` (values: numbers, true/false, or
    ``a;b;c`` lists of numbers).  Returns (name, {param: value})."""
    text = text.strip()
    name, _, rest = text.partition(":")
    name = name.strip()
    _spec(name)
    params = {}
    for item in [p for p in rest.split(",") if p.strip()]:
        key, eq, val = item.partition("=")
        key, val = key.strip(), val.strip()
        if not eq or not key or not val:
            raise ValueError(f"effect {name!r}: bad parameter {item.strip()!r} (expected param=value)")
        params[key] = _parse_value(name, key, val)
    return name, params


def _parse_value(effect: str, key: str, val: str):
    low = val.lower()
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    try:
        if ";" in val:
            return tuple(float(v) for v in val.split(";") if v.strip())
        num = float(val)
        return int(num) if key == "power" and num == int(num) else num
    except ValueError:
        raise ValueError(f"effect {effect!r} parameter {key!r}: {val!r} is not a number, "
                         f"true/false or a;b list") from None


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


def build_config(scenario: str = "static", duration_s=None, sample_rate_hz: float = 1.0, undeclared=(),
                 **overrides) -> SimConfig:
    """The configuration of :func:`simulate` (same arguments, without the seed).

    ``overrides`` (all optional):

    * any :class:`SimParams` field, e.g. ``tau_pkg_s=900``, ``reversal=True``, ``exchange_s=20``;
    * ``profile``: a :class:`Profile`, rows ``(t_s, temp_c)`` or a CSV path;
    * ``effects``: the exact set of ON, declared effects (names, comma string, or dict name -> params);
    * ``inject``: effects to switch on (declared) and/or re-parameterize: dict name -> params, or
      names / ``'NAME:p=v,...'`` strings;
    * ``off``: effects to switch off (names or comma string).

    ``undeclared``: effects switched on (with defaults or the given params: dict or ``'NAME:p=v'``)
    that act on the data but are not listed in the metadata.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r}; known: {', '.join(SCENARIOS)}")
    sc = SCENARIOS[scenario]
    overrides = dict(overrides)
    prof = overrides.pop("profile", None)
    profile = _as_profile(sc.profile if prof is None else prof)
    effects_sel = overrides.pop("effects", None)
    inject = _effect_items(overrides.pop("inject", None), "inject")
    off = _effect_items(overrides.pop("off", None), "off")
    hidden = _effect_items(undeclared, "undeclared")
    pvals = dict(sc.params)
    pvals["reversal"] = sc.reversal
    names = {f.name for f in fields(SimParams)}
    for key, val in overrides.items():
        if key not in names:
            raise ValueError(f"unknown simulate option {key!r}; options: profile, effects, inject, off, "
                             f"{', '.join(sorted(names))}")
        pvals[key] = val
    params = SimParams(**pvals)
    params.validate()

    if effects_sel is None:
        on = {n: {} for n in DEFAULT_EFFECTS if n not in sc.off}
    else:
        on = _effect_items(effects_sel, "effects")
    for name in off:
        on.pop(name, None)
    for src in (inject, hidden):
        for name, pv in src.items():
            on.setdefault(name, {}).update(pv)
    effects = {n: effect_params(n, **on[n]) for n in EFFECTS if n in on}

    if duration_s is None:
        duration_s = sc.duration_s if sc.duration_s is not None else profile.end_s
    try:
        duration_s = float(duration_s)
        sample_rate_hz = float(sample_rate_hz)
    except (TypeError, ValueError):
        raise ValueError(f"duration_s and sample_rate_hz must be numbers, "
                         f"not {duration_s!r}, {sample_rate_hz!r}") from None
    if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0):
        raise ValueError(f"sample_rate_hz must be > 0, not {sample_rate_hz}")
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be > 0, not {duration_s}")
    n = int(round(duration_s * sample_rate_hz))
    if n < 2:
        raise ValueError(f"duration {duration_s} s at {sample_rate_hz} Hz gives {n} sample(s); need at least 2")
    if n > MAX_SAMPLES:
        raise ValueError(f"duration {duration_s} s at {sample_rate_hz} Hz gives {n} samples (limit {MAX_SAMPLES})")
    return SimConfig(scenario, profile, params, effects, frozenset(hidden), duration_s, sample_rate_hz)


# ---------------------------------------------------------------------------------------------
# the physics
# ---------------------------------------------------------------------------------------------

def lag(u: np.ndarray, tau_s: float, dt_s: float, y0: float | None = None) -> np.ndarray:
    """First-order lag ``dy/dt = (u - y)/tau`` sampled every ``dt_s``: exact for an input linear
    between samples (first-order hold), unconditionally stable.  ``y0`` defaults to ``u[0]``
    (soaked)."""
    u = np.asarray(u, float)
    a = math.exp(-dt_s / tau_s)
    k = tau_s / dt_s * (1.0 - a)
    b = [1.0 - k, k - a]
    base = u[0]
    y = lfilter(b, [1.0, -a], u - base) + base
    if y0 is not None and y0 != base:
        y += (y0 - base) * a ** np.arange(len(u))
    return y


def mode_sequence(t_s: np.ndarray, reversal: bool, exchange_s: float, dwell_s: float) -> np.ndarray:
    """Mode of every sample: all 0 (FTR) without reversal; with reversal, from power-on:
    exchange (3) ``exchange_s``, mode 1 ``dwell_s``, exchange, mode 2 ``dwell_s``, repeat."""
    if not reversal:
        return np.zeros(len(t_s), np.int64)
    period = 2.0 * (exchange_s + dwell_s)
    ph = np.mod(t_s, period)
    mode = np.full(len(t_s), 2, np.int64)
    mode[ph < exchange_s + dwell_s + exchange_s] = 3
    mode[ph < exchange_s + dwell_s] = 1
    mode[ph < exchange_s] = 3
    return mode


def _rng(seed: int, name: str, sub: int = 0) -> np.random.Generator:
    """Random stream ``sub`` of effect ``name``: independent of every other effect and of the run
    length (a longer run of the same seed starts with the same samples)."""
    return np.random.default_rng([seed, EFFECTS[name].stream, sub])


FLICKER_PER_DECADE = 2          # Gauss-Markov processes per decade of correlation time
FLICKER_TAU_MAX_S = 1.0e7       # longest correlation time [s] (~4 months)


def _flicker(seed: int, n: int, fs: float, b_dph: float) -> np.ndarray:
    """Flicker rate noise [deg/h] with one-sided PSD ~ b^2/(pi f) (Allan floor 0.664 b): a sum of
    first-order Gauss-Markov processes with correlation times log-spaced (FLICKER_PER_DECADE per
    decade) from 1/fs to FLICKER_TAU_MAX_S s, each of variance b^2 ln(r)/pi (r the spacing
    ratio), started stationary.  Causal, so a run's prefix does not depend on its length."""
    r = 10.0 ** (1.0 / FLICKER_PER_DECADE)
    q = b_dph * math.sqrt(math.log(r) / math.pi)
    out = np.zeros(n)
    tau = 1.0 / fs
    k = 0
    while tau <= FLICKER_TAU_MAX_S:
        a = math.exp(-1.0 / (fs * tau))
        w = _rng(seed, "bias_instability", k).standard_normal(n)
        x0 = q * w[0]
        out[0] += x0
        if n > 1:
            out[1:] += lfilter([q * math.sqrt(1.0 - a * a)], [1.0, -a], w[1:], zi=[a * x0])[0]
        tau *= r
        k += 1
    return out


def _sign_of(mode: np.ndarray) -> np.ndarray:
    return np.where(mode == 2, -1.0, np.where(mode == 3, 0.0, 1.0))


def run_physics(cfg: SimConfig, seed: int) -> dict:
    """All signals of a run [SI-ish units] as a dict: ``t_s``, ``mode``, ``sign``, temperatures
    ``T_ch``, ``T_pkg``, ``T_res``, ``T_el``, ``T_board`` [degC], ``r_res_cpm`` [degC/min],
    ``freq_hz``, ``temp_c``, ``aux_vdd``, ``rate_dph``, and ``parts``: effect name -> its additive
    contribution to ``rate_dph`` [deg/h] (the truth for closed-loop tests)."""
    p, eff = cfg.params, cfg.effects
    fs = cfg.sample_rate_hz
    dt = 1.0 / fs
    n = int(round(cfg.duration_s * fs))
    t = np.arange(n) / fs
    mode = mode_sequence(t, p.reversal, p.exchange_s, p.dwell_s)
    s = _sign_of(mode)

    T_ch = cfg.profile(t)
    T_pkg = lag(T_ch, p.tau_pkg_s, dt)
    T_res_l = lag(T_pkg, p.tau_res_s, dt)
    T_el = lag(T_pkg, p.tau_el_s, dt)
    T_board = lag(T_ch, p.tau_board_s, dt)
    r_res = (T_pkg - T_res_l) / p.tau_res_s * 60.0       # dT_res/dt of the lag [degC/min]
    T_res = T_res_l
    if "self_heating" in eff:
        sh = eff["self_heating"]
        e_res = np.exp(-t / sh.res_tau_s)
        T_res = T_res_l + sh.res_rise_c * (1.0 - e_res)
        r_res = r_res + sh.res_rise_c / sh.res_tau_s * e_res * 60.0
        T_el = T_el + sh.el_rise_c * (1.0 - np.exp(-t / sh.el_tau_s))
        T_board = T_board + sh.board_rise_c * (1.0 - np.exp(-t / sh.board_tau_s))
    x = T_res - p.t_ref_c

    # drive frequency
    freq = p.f0_hz * (1.0 + p.k_w_per_c * x + p.c2_per_c2 * x * x)
    if "freq_noise" in eff:
        freq = freq + _rng(seed, "freq_noise").standard_normal(n) * eff["freq_noise"].sigma_hz
    if "pll_quant" in eff and eff["pll_quant"].lsb_hz > 0:
        lsb = eff["pll_quant"].lsb_hz
        freq = np.round(freq / lsb) * lsb

    # board sensor
    temp = T_board.copy()
    if "temp_sensor" in eff:
        ts = eff["temp_sensor"]
        temp = temp + _rng(seed, "temp_sensor").standard_normal(n) * ts.sigma_c
        if ts.lsb_c > 0:
            temp = np.round(np.round(temp / ts.lsb_c) * ts.lsb_c, 10)  # no 19.990000000000002

    # supply voltage
    vdd = np.full(n, p.vdd_nominal_v)
    if "vdd_wander" in eff:
        vw = eff["vdd_wander"]
        a = math.exp(-dt / vw.tau_s)
        w = _rng(seed, "vdd_wander", 0).standard_normal(n)
        wander = lfilter([math.sqrt(1.0 - a * a) * vw.sigma_v], [1.0, -a], w[1:], zi=[a * vw.sigma_v * w[0]])[0]
        vdd[0] += vw.sigma_v * w[0]
        vdd[1:] += wander
        vdd += _rng(seed, "vdd_wander", 1).standard_normal(n) * vw.noise_v
        for ts_, dv in zip(np.ravel(vw.step_times_s), np.ravel(vw.step_sizes_v)):
            vdd[t >= ts_] += dv

    parts = {}

    def add(name, term, flips):
        parts[name] = s * term if flips else term * np.ones(n)

    if "damping_asym" in eff:
        d = eff["damping_asym"]
        add("damping_asym", ((d.c3_dph_per_c3 * x + d.c2_dph_per_c2) * x + d.c1_dph_per_c) * x
            + (d.g1_dph_per_cpm + d.g2_dph_per_c_cpm * x) * r_res, False)
    if "damping_wander" in eff:
        dw = eff["damping_wander"]
        a = math.exp(-dt / dw.tau_s)
        w = _rng(seed, "damping_wander").standard_normal(n)
        x0 = dw.sigma_dph * w[0]
        gm = np.empty(n)
        gm[0] = x0
        if n > 1:
            gm[1:] = lfilter([dw.sigma_dph * math.sqrt(1.0 - a * a)], [1.0, -a], w[1:], zi=[a * x0])[0]
        add("damping_wander", gm, False)
    if "electronics" in eff:
        e = eff["electronics"]
        y = T_el - p.t_ref_c
        add("electronics", (e.e2_dph_per_c2 * y + e.e1_dph_per_c) * y, True)
    if "turn_on" in eff:
        add("turn_on", eff["turn_on"].amp_dph * np.exp(-t / eff["turn_on"].tau_s), True)
    if "earth_rate" in eff:
        add("earth_rate", np.full(n, EARTH_RATE_DPH * math.sin(math.radians(eff["earth_rate"].latitude_deg))), True)
    if "arw" in eff:
        sigma = 60.0 * eff["arw"].arw_deg_per_sqrt_h * math.sqrt(fs)
        parts["arw"] = _rng(seed, "arw").standard_normal(n) * sigma
    if "bias_instability" in eff:
        parts["bias_instability"] = _flicker(seed, n, fs, eff["bias_instability"].bi_dph)
    if "rrw" in eff:
        step = eff["rrw"].rrw_dph_per_sqrt_h / 60.0 * math.sqrt(dt)
        parts["rrw"] = np.cumsum(_rng(seed, "rrw").standard_normal(n)) * step
    if "thermal_lag" in eff:
        tl = eff["thermal_lag"]
        add("thermal_lag", tl.coef_dph_per_c * (lag(T_ch, tl.tau_s, dt) - p.t_ref_c), tl.flips)
    if "exchange_transient" in eff:
        et = eff["exchange_transient"]
        since = _time_since_exchange_end(t, mode)
        term = np.where(np.isfinite(since), et.amp_dph * np.exp(-np.nan_to_num(since, nan=0.0) / et.tau_s), 0.0)
        term[mode == 3] = 0.0
        add("exchange_transient", term, et.flips)
    if "imperfect_reversal" in eff:
        ir = eff["imperfect_reversal"]
        w = np.where(mode == 2, ir.w2, np.where(mode == 3, 0.0, ir.w1))
        parts["imperfect_reversal"] = ir.coef_dph_per_c * x * w
    if "proxy_high_order" in eff:
        ph = eff["proxy_high_order"]
        add("proxy_high_order", ph.amp_dph * (x / ph.scale_c) ** int(ph.power), ph.flips)
    if "board_temp" in eff:
        bt = eff["board_temp"]
        add("board_temp", bt.coef_dph_per_c * (T_board - p.t_ref_c), bt.flips)
    if "aux_vdd" in eff:
        av = eff["aux_vdd"]
        add("aux_vdd", av.coef_dph_per_v * (vdd - p.vdd_nominal_v), av.flips)
    if "aging" in eff:
        ag = eff["aging"]
        add("aging", ag.rate_dph_per_h * t / 3600.0, ag.flips)
    if "periodic" in eff:
        pe = eff["periodic"]
        add("periodic", pe.amp_dph * np.sin(2.0 * math.pi * t / pe.period_s + pe.phase_rad), pe.flips)
    if "exchange_glitch" in eff and np.any(mode == 3):
        eg = eff["exchange_glitch"]
        g = _rng(seed, "exchange_glitch")
        ex = mode == 3
        start = np.flatnonzero(ex & ~np.concatenate([[False], ex[:-1]]))
        idx = np.cumsum(np.isin(np.arange(n), start)) - 1          # index of the current exchange
        t_start = t[start][np.maximum(idx, 0)]
        sign = np.where(idx % 2 == 0, 1.0, -1.0)
        term = np.where(ex, sign * eg.amp_dph * np.exp(-(t - t_start) / eg.tau_s)
                        + g.standard_normal(n) * eg.noise_dph, 0.0)
        parts["exchange_glitch"] = term

    rate = np.zeros(n)
    for name in EFFECTS:            # fixed summation order: bit-identical results
        if name in parts:
            rate = rate + parts[name]
    return dict(t_s=t, mode=mode, sign=s, T_ch=T_ch, T_pkg=T_pkg, T_res=T_res, T_el=T_el, T_board=T_board,
                r_res_cpm=r_res, freq_hz=freq, temp_c=temp, aux_vdd=vdd, rate_dph=rate, parts=parts)


def _time_since_exchange_end(t, mode) -> np.ndarray:
    """Seconds since the end of the last exchange (the first sample of a mode-1/2 window after an
    exchange is at 0); NaN before the first exchange ends."""
    n = len(t)
    ex = mode == 3
    ends = np.flatnonzero(ex[:-1] & ~ex[1:]) + 1          # first sample after each exchange
    out = np.full(n, np.nan)
    if len(ends) == 0:
        return out
    k = np.searchsorted(ends, np.arange(n), side="right") - 1
    ok = k >= 0
    out[ok] = t[ok] - t[ends[k[ok]]]
    return out


# ---------------------------------------------------------------------------------------------
# public API
# ---------------------------------------------------------------------------------------------

def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, not {seed!r}")
    return int(seed)


def simulate(scenario: str = "static", seed: int = 0, duration_s: float | None = None,
             sample_rate_hz: float = 1.0, undeclared=(), return_truth: bool = False, **overrides):
    """Simulate one power-on of the virtual gyroscope: a :class:`RunLog` with the columns
    ``t_s, freq_hz, rate_dph, mode, temp_c, aux_vdd`` (see the module doc for the physics and
    :func:`build_config` for ``overrides``).  ``duration_s`` None: the scenario's.  With
    ``return_truth`` returns ``(log, truth)``, truth as :func:`run_physics` (temperatures and the
    contribution of every effect)."""
    seed = _check_seed(seed)
    cfg = build_config(scenario, duration_s, sample_rate_hz, undeclared, **overrides)
    sig = run_physics(cfg, seed)
    p = cfg.params
    meta = {"device": p.device, "sample_rate_hz": f"{cfg.sample_rate_hz:g}",
            "reversal": "on" if p.reversal else "off"}
    if p.reversal:
        meta["exchange_s"] = f"{p.exchange_s:g}"
        meta["dwell_s"] = f"{p.dwell_s:g}"
    meta.update({"scenario": cfg.scenario, "seed": str(seed), "profile": cfg.profile.name,
                 "simulator": f"hdrg.sim {SIM_VERSION}", "effects": ",".join(cfg.declared)})
    log = RunLog.from_arrays(metadata=meta, source=f"<simulate {cfg.scenario} seed {seed}>",
                             t_s=sig["t_s"], freq_hz=sig["freq_hz"], rate_dph=sig["rate_dph"],
                             mode=sig["mode"], temp_c=sig["temp_c"], aux_vdd=sig["aux_vdd"])
    return (log, sig) if return_truth else log


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------


def format_list() -> str:
    """The named scenarios and the effects (with their default parameters; * marks the effects on by
    default) as the text `hdrg simulate --list` prints."""
    lines = ["scenarios:"]
    lines += [f"  {name:22s} {desc}" for name, desc in list_scenarios().items()]
    lines.append("effects (* on by default; NAME:param=value for --inject/--undeclared):")
    for name, spec in EFFECTS.items():
        pars = ", ".join(f"{f.name}={f.default!r}" for f in fields(spec.cls))
        lines.append(f"  {'*' if spec.default_on else ' '} {name:19s} {spec.help}; {pars}")
    return "\n".join(lines)
