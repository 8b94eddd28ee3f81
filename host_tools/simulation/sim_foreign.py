"""A second, FOREIGN virtual gyroscope: randomized thermal physics written independently of the
pipeline and of host_tools.simulation.sim (from which it takes only the mode-sequence timing), so that a
benchmark can tell whether the pipeline's defaults hold on physics they were not tuned on.

A *device* is a seed: :func:`foreign_device` draws its structure with ``numpy.random.default_rng``.
A *run* is (device, chamber rate, reversal on/off, power-on index, noise seed):
:func:`simulate_foreign`.  Two runs of one device share its physics; they differ in the chamber
rate, the non-repeatable damping change of their power-on and the noise.  Units are in the names
(``_s`` s, ``_c`` degC, ``_hz`` Hz, ``_dph`` deg/h, ``_v`` V, ``_g`` standard gravity); the
sample rate is 1 Hz.

Physics of a device (ranges are the randomization, uniform unless said otherwise):

1. **Chamber air** ``T_ch``: trapezoid cycles starting soaked at ``high_c`` (18..25 degC): hold,
   ramp down to ``low_c`` (-25..-15), hold, ramp up, hold, ``n_cycles`` (2..3) times; holds 5..30
   min; the ramp rate is the run's (1..5 degC/min in the benchmark).
2. **Thermal nodes** (2..4): first-order lags, tau 60..1500 s (log-uniform); node 0 is fed by the
   chamber air, every later node by the air (parallel, p = 0.4) or by an earlier node (series).
   Exact discretization for an input linear between samples; every node starts soaked.
   *Self-heating*: after power-on one node gains ``rise_c * (1 - exp(-t/tau_s))`` (0.5..3 degC,
   tau 100..900 s), which its downstream nodes see through their lags.  One node is the
   resonator, one (another) carries the temperature sensor, one the damping-asymmetry bias (the
   resonator with p = 0.5), one the common-mode (electronics) bias.
3. **Drive frequency** ``freq_hz`` = ``f0 (1 + a1 x + a2 x^2 + a3 x^3)`` with x = T_res - 25 degC,
   f0 3..40 kHz (the paper's HDRG 6.2 kHz, disk and hemispherical resonators from a few kHz,
   ADXRS45x 15..18 kHz, MPU-6000/6050 24..36 kHz), a1 = -20.9 ppm/degC x (1 + N(0, 3 %)), a2 ~
   N(0, 0.02 ppm/degC^2), a3 ~ N(0, 2e-4 ppm/degC^3); plus white PLL noise (0.05..0.2 mHz) and quantization to the NCO step
   ``f_clk / 2**N`` (f_clk 10..50 MHz, N 35..40: 0.01..1.5 mHz).
4. **Temperature sensor** ``temp_c`` = gain x T_sensor_node + offset (gain 1 +- 1 %, offset +- 1
   degC), white noise 0.01..0.05 degC, quantized to 2**-4..2**-8 degC.  The sensor node is not the
   resonator's (a board or package sensor), except on a temperature-only device (below).
5. **Raw loop output** ``rate_dph`` with s = +1 (mode 0, 1), -1 (mode 2), 0 (mode 3)::

       rate = s * (Omega + B_E + flipping effects) + (1 + d_scale) * B_D + d_offset
              + non-flipping effects + settling tail + noise            (modes 0, 1, 2)
       rate = ringing + B_D + noise                                     (mode 3)

   - Omega: the true rate, the vertical Earth-rate component at a random latitude (a rate, not a
     bias: it stays in the noise-only run);
   - B_D (damping asymmetry, does NOT flip): cubic in y = T_dnode / 20 degC: c0 ~ N(0, 20), c1 =
     +-(10..40), c2 ~ N(0, 8), c3 ~ N(0, 6) deg/h;
   - B_E (common mode, flips): e1 y + e2 y^2 + e3 tanh((T_enode - Tk)/w) with y = T_enode / 20,
     e1 ~ N(0, 5), e2 ~ N(0, 3), e3 = +-(2..10) deg/h, Tk -15..15 degC, w 8..25 degC;
   - power-on damping change (non-repeatable, drawn per (device, power-on)): d_scale ~ N(0,
     sigma) with sigma 1..5 % per device, d_offset ~ U(-m, m) with m 0.5..3 deg/h per device;
   - mode exchange (mode 3): ringing ``A exp(-t'/tau) cos(2 pi f t')`` (A 50..300 deg/h, tau
     2..8 s, f 0.05..0.3 Hz; t' since the exchange started); settling tail in the first seconds
     of mode 1/2: ``+-A exp(-t''/tau)`` (A 0.5..3 deg/h, tau 2..6 s, sign + entering mode 1 and -
     entering mode 2, t'' since the exchange ended);
   - noise (does not flip): white (1-s std 0.1..0.5 deg/h), flicker (bias instability: a sum of
     Gauss-Markov processes, 2 per decade, tau 10..1e5 s, one-sided PSD ``B^2/(pi f)``, B
     0.01..0.08 deg/h), rate random walk K 0.02..0.2 deg/h/sqrt(h).
6. **Aux channels** (always logged): ``aux_vdd`` [V] supply: nominal 3.3 or 5 V + Gauss-Markov
   wander (5..20 mV, tau 300..3000 s) + 1 mV white noise; ``aux_acc_x/y/z`` [m/s^2] accelerometer:
   gravity in a frame tilting slowly (two Gauss-Markov tilt angles, 3..12 deg, tau 600..3000 s)
   plus 0.02 m/s^2 white noise.  The gyro responds to them only under the ``aux`` effect.

**Temperature-only devices** (``ForeignDevice.logs_freq`` False; about TEMP_ONLY_SHARE = 1 in 8
seeds, chosen by ``default_rng([seed, 4])`` so that every other draw of the seed is that of a
device that logs its drive frequency): the drive frequency is not logged, as on a gyroscope whose
interface gives a die temperature and no drive-frequency output.  Such a device's log holds
``t_s``, ``rate_dph``, ``mode``, ``temp_c`` and the aux columns, no ``freq_hz``; its temperature
sensor sits on the resonator's node (an on-die sensor: ``sensor_node`` = ``resonator_node``, the
sensor's gain, offset, noise and quantization as drawn in 4), so that ``temp_c`` tracks the
resonator and serves as the temperature proxy (``hdrg fit`` takes ``temp_c`` as the proxy when a log
has no ``freq_hz``).  The ``board_temp`` effect then follows the resonator's node, and
``proxy_high_order`` remains a function of the resonator temperature that ``temp_c`` measures.

Effects (``EFFECT_KINDS``; undeclared: a run's metadata never names them).  Each has device-drawn
parameters (``ForeignDevice.effects``) and a dimensionless ``strength`` that multiplies its bias
linearly (strength 1 = the nominal amplitude given here); all of them FLIP (like B_E, so mode
reversal does not cancel them) unless said otherwise:

====================  =================================================================  ========
kind                  bias at strength 1                                                 runs
====================  =================================================================  ========
thermal_lag           k (T_h - 0 degC), k = +-(0.05..0.15) deg/h/degC, T_h a hidden      FTR, MR
                      node lagging the resonator node by tau 1500..4000 s
turn_on               A exp(-t/tau), A = +-(1..3) deg/h, tau 200..900 s                  FTR, MR
exchange_transient    A exp(-t''/tau) after each exchange, A = +-(1..3) deg/h, tau 5..40  MR
                      s; does NOT flip (an axis-state transient)
imperfect_reversal    mode 2 only: eps B_D + delta added to the raw output, eps = +-     MR
                      (1..3) %, delta = +-(0.5..1.5) deg/h (non-flipping parts reverse
                      imperfectly)
proxy_high_order      A y^4, y = T_res / 20 degC, A = +-(2..4) deg/h                     FTR, MR
board_temp            k (T_sensor - 0 degC) + q (T_sensor/20)^2, k = +-(0.03..0.08)       FTR, MR
                      deg/h/degC, q ~ N(0, 0.5) deg/h (follows the temp_c sensor's node)
aux                   kv (vdd - nominal) + g . acc / 9.80665, kv = +-(30..80) deg/h/V,   FTR, MR
                      g = 1..4 deg/h/g per axis (random signs); columns aux_vdd, aux_acc_*
aging                 A (1 - exp(-t/tau)), A = +-(1..3) deg/h, tau 2..8 h                 FTR, MR
periodic              A sin(2 pi t / P + phi), A = 0.5..1.5 deg/h, P 400..3000 s          FTR, MR
                      (chamber compressor cycling: vibration-induced bias)
====================  =================================================================  ========

``thermal=False`` gives the noise-only floor run: the same temperatures, frequency, sensor, aux
columns, true rate and noise realization (same draws), with every bias term zeroed (B_D, B_E,
the power-on change, ringing, settling tail and the effects).

Determinism: device structure from ``default_rng([seed, 0])``, effect parameters from
``default_rng([seed, 1, k])``, the power-on change from ``default_rng([seed, 2, power_on])``, the
noise from ``default_rng([seed, 3, noise_seed])`` (fixed draw order, independent of thermal/effect,
the same whether or not ``freq_hz`` is logged), whether the drive frequency is logged from
``default_rng([seed, 4])``.

Version 2 (``foreign_version`` in the metadata): f0 3..40 kHz (version 1: 6..30 kHz, from the same
random number, so every other parameter of a seed is unchanged) and the temperature-only devices.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.signal import lfilter

from host_tools.golden.runlog import RunLog
from host_tools.simulation.sim_physics import mode_sequence

FOREIGN_VERSION = 2
TEMP_ONLY_SHARE = 0.125   # probability that a device logs no drive frequency (its temp_c is the proxy)
EXCHANGE_S = 30.0
DWELL_S = 120.0
T_REF_C = 0.0           # reference of the normalized temperatures y = (T - T_REF_C) / T_SCALE_C
T_SCALE_C = 20.0
F_REF_C = 25.0          # reference temperature of the drive-frequency polynomial
G0 = 9.80665
MAX_SAMPLES = 10_000_000
STARTUP_S = 2700.0       # a start-up at constant ambient: 45 min (the paper's Table 4)


@dataclass(frozen=True)
class EffectKind:
    """One undeclared effect: ``name`` (a family of host_tools.fitting.effects.FAMILIES), ``runs``
    ('ftr+mr' or 'mr': the run types it acts on), ``flips`` (follows the mode sign), ``columns``
    (the logged columns its bias follows; '' when it follows no logged column), ``units``."""

    name: str
    runs: str
    flips: bool
    columns: str
    units: str


EFFECTS = {
    "thermal_lag": EffectKind("thermal_lag", "ftr+mr", True, "", "deg/h per degC of a hidden lagged node"),
    "turn_on": EffectKind("turn_on", "ftr+mr", True, "", "deg/h at power-on"),
    "exchange_transient": EffectKind("exchange_transient", "mr", False, "", "deg/h at the end of an exchange"),
    "imperfect_reversal": EffectKind("imperfect_reversal", "mr", False, "mode", "fraction of B_D and deg/h in mode 2"),
    "proxy_high_order": EffectKind("proxy_high_order", "ftr+mr", True, "", "deg/h at |T_res| = 20 degC"),
    "board_temp": EffectKind("board_temp", "ftr+mr", True, "temp_c", "deg/h per degC of the sensor node"),
    "aux": EffectKind("aux", "ftr+mr", True, "aux_vdd,aux_acc_x,aux_acc_y,aux_acc_z", "deg/h per V and per g"),
    "aging": EffectKind("aging", "ftr+mr", True, "", "deg/h of final drift"),
    "periodic": EffectKind("periodic", "ftr+mr", True, "", "deg/h amplitude"),
}
EFFECT_KINDS = tuple(EFFECTS)


@dataclass
class ForeignDevice:
    """Everything a device's runs share (JSON-able; :meth:`describe` gives a short summary)."""

    seed: int
    nodes: list            # [{"tau_s", "parent"}]; parent -1 = chamber air, else an earlier node index
    resonator_node: int
    sensor_node: int
    damping_node: int
    common_node: int
    self_heating: dict     # node, rise_c, tau_s
    chamber: dict          # high_c, low_c, hold_s, n_cycles
    drive: dict            # f0_hz, a1_per_c, a2_per_c2, a3_per_c3, pll_noise_hz, nco_step_hz
    sensor: dict           # gain, offset_c, noise_c, lsb_c
    damping: dict          # c0..c3 [deg/h], change_sigma, change_offset_max_dph
    common: dict           # e1, e2, e3 [deg/h], tk_c, w_c
    omega_dph: float
    exchange: dict         # ring_amp_dph, ring_tau_s, ring_freq_hz, tail_amp_dph, tail_tau_s
    noise: dict            # white_dph, flicker_b_dph, rrw_k
    aux: dict              # vdd_nom_v, vdd_wander_v, vdd_tau_s, tilt_deg, tilt_tau_s
    effects: dict = field(default_factory=dict)   # kind -> parameters at strength 1
    logs_freq: bool = True  # False: a temperature-only device (no freq_hz; temp_c on the resonator's node)

    def to_dict(self) -> dict:
        return asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1, sort_keys=True)

    def describe(self) -> str:
        """One line: nodes, which node carries what, the main amplitudes."""
        nodes = " ".join(f"n{i}<{'air' if nd['parent'] < 0 else 'n%d' % nd['parent']}:{nd['tau_s']:.0f}s"
                         for i, nd in enumerate(self.nodes))
        return (f"foreign device {self.seed}: {nodes}; resonator n{self.resonator_node}, sensor "
                f"n{self.sensor_node}, damping n{self.damping_node}, common n{self.common_node}; "
                f"f0 {self.drive['f0_hz']:.0f} Hz{'' if self.logs_freq else ' (not logged: temp_c proxy)'}; "
                f"damping c1 {self.damping['c1']:+.1f} deg/h, common "
                f"tanh {self.common['e3']:+.1f} deg/h; white {self.noise['white_dph']:.2f} deg/h; "
                f"self-heating n{self.self_heating['node']} {self.self_heating['rise_c']:.1f} degC")

    def damping_change(self, power_on: int) -> tuple[float, float]:
        """(d_scale, d_offset_dph) of power-on ``power_on`` (non-repeatable, drawn per run)."""
        rng = np.random.default_rng([self.seed, 2, _check_int(power_on, "power_on")])
        return (float(rng.normal(0.0, self.damping["change_sigma"])),
                float(rng.uniform(-1.0, 1.0) * self.damping["change_offset_max_dph"]))


def _check_int(value, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{what} must be a non-negative integer, not {value!r}")
    return int(value)


def _pm(rng, lo, hi):
    """Uniform magnitude in [lo, hi] with a random sign."""
    return float(rng.uniform(lo, hi) * rng.choice((-1.0, 1.0)))


def foreign_device(seed: int) -> ForeignDevice:
    """Draw device ``seed`` (a non-negative integer) of the foreign family (module doc)."""
    seed = _check_int(seed, "seed")
    r = np.random.default_rng([seed, 0])
    n_nodes = int(r.integers(2, 5))
    nodes = []
    for j in range(n_nodes):
        parent = -1 if j == 0 or r.random() < 0.4 else int(r.integers(0, j))
        nodes.append({"tau_s": float(math.exp(r.uniform(math.log(60.0), math.log(1500.0)))), "parent": parent})
    res = int(r.integers(0, n_nodes))
    sensor = int(r.choice([j for j in range(n_nodes) if j != res]))
    damping = res if r.random() < 0.5 else int(r.integers(0, n_nodes))
    common = int(r.integers(0, n_nodes))
    logs_freq = bool(np.random.default_rng([seed, 4]).random() >= TEMP_ONLY_SHARE)
    if not logs_freq:
        sensor = res            # an on-die sensor: temp_c tracks the resonator (module doc)
    dev = ForeignDevice(
        seed=seed, nodes=nodes, resonator_node=res, sensor_node=sensor, damping_node=damping, common_node=common,
        self_heating={"node": int(r.integers(0, n_nodes)), "rise_c": float(r.uniform(0.5, 3.0)),
                      "tau_s": float(r.uniform(100.0, 900.0))},
        chamber={"high_c": float(r.uniform(18.0, 25.0)), "low_c": float(r.uniform(-25.0, -15.0)),
                 "hold_s": float(60.0 * r.uniform(5.0, 30.0)), "n_cycles": int(r.integers(2, 4))},
        drive={"f0_hz": float(r.uniform(3e3, 40e3)), "a1_per_c": -20.9e-6 * (1.0 + r.normal(0.0, 0.03)),
               "a2_per_c2": float(r.normal(0.0, 0.02e-6)), "a3_per_c3": float(r.normal(0.0, 2e-10)),
               "pll_noise_hz": float(r.uniform(0.05e-3, 0.2e-3)),
               "nco_step_hz": float(r.uniform(10e6, 50e6) / 2.0 ** int(r.integers(35, 41)))},
        sensor={"gain": float(1.0 + r.uniform(-0.01, 0.01)), "offset_c": float(r.uniform(-1.0, 1.0)),
                "noise_c": float(r.uniform(0.01, 0.05)), "lsb_c": float(2.0 ** -int(r.integers(4, 9)))},
        damping={"c0": float(r.normal(0.0, 20.0)), "c1": _pm(r, 10.0, 40.0), "c2": float(r.normal(0.0, 8.0)),
                 "c3": float(r.normal(0.0, 6.0)), "change_sigma": float(r.uniform(0.01, 0.05)),
                 "change_offset_max_dph": float(r.uniform(0.5, 3.0))},
        common={"e1": float(r.normal(0.0, 5.0)), "e2": float(r.normal(0.0, 3.0)), "e3": _pm(r, 2.0, 10.0),
                "tk_c": float(r.uniform(-15.0, 15.0)), "w_c": float(r.uniform(8.0, 25.0))},
        omega_dph=float(15.041067 * math.sin(math.radians(r.uniform(-60.0, 60.0)))),
        exchange={"ring_amp_dph": float(r.uniform(50.0, 300.0)), "ring_tau_s": float(r.uniform(2.0, 8.0)),
                  "ring_freq_hz": float(r.uniform(0.05, 0.3)), "tail_amp_dph": float(r.uniform(0.5, 3.0)),
                  "tail_tau_s": float(r.uniform(2.0, 6.0))},
        noise={"white_dph": float(r.uniform(0.1, 0.5)), "flicker_b_dph": float(r.uniform(0.01, 0.08)),
               "rrw_k": float(r.uniform(0.02, 0.2))},
        aux={"vdd_nom_v": float(r.choice((3.3, 5.0))), "vdd_wander_v": float(r.uniform(0.005, 0.02)),
             "vdd_tau_s": float(r.uniform(300.0, 3000.0)), "tilt_deg": float(r.uniform(3.0, 12.0)),
             "tilt_tau_s": float(r.uniform(600.0, 3000.0))},
        logs_freq=logs_freq,
    )
    for k, name in enumerate(EFFECT_KINDS):
        e = np.random.default_rng([seed, 1, k])
        dev.effects[name] = {
            "thermal_lag": lambda: {"k_dph_per_c": _pm(e, 0.05, 0.15), "tau_s": float(e.uniform(1500.0, 4000.0))},
            "turn_on": lambda: {"amp_dph": _pm(e, 1.0, 3.0), "tau_s": float(e.uniform(200.0, 900.0))},
            "exchange_transient": lambda: {"amp_dph": _pm(e, 1.0, 3.0), "tau_s": float(e.uniform(5.0, 40.0))},
            "imperfect_reversal": lambda: {"eps": _pm(e, 0.01, 0.03), "delta_dph": _pm(e, 0.5, 1.5)},
            "proxy_high_order": lambda: {"amp_dph": _pm(e, 2.0, 4.0)},
            "board_temp": lambda: {"k_dph_per_c": _pm(e, 0.03, 0.08), "q_dph": float(e.normal(0.0, 0.5))},
            "aux": lambda: {"kv_dph_per_v": _pm(e, 30.0, 80.0),
                            "g_dph_per_g": [_pm(e, 1.0, 4.0) for _ in range(3)]},
            "aging": lambda: {"amp_dph": _pm(e, 1.0, 3.0), "tau_s": float(3600.0 * e.uniform(2.0, 8.0))},
            "periodic": lambda: {"amp_dph": float(e.uniform(0.5, 1.5)), "period_s": float(e.uniform(400.0, 3000.0)),
                                 "phase_rad": float(e.uniform(0.0, 2.0 * math.pi))},
        }[name]()
    return dev


# -- building blocks ------------------------------------------------------------------------------

def chamber_profile(dev: ForeignDevice, rate_c_per_min: float, start_low: bool = False) -> np.ndarray:
    """Breakpoints (t_s, temp_c) of the device's trapezoid cycles at ``rate_c_per_min`` [degC/min],
    starting soaked at ``high_c`` (``start_low``: at ``low_c``, the cycles mirrored)."""
    if not (isinstance(rate_c_per_min, (int, float)) and math.isfinite(rate_c_per_min) and rate_c_per_min > 0):
        raise ValueError(f"chamber rate must be a positive number of degC/min, not {rate_c_per_min!r}")
    c = dev.chamber
    first, second = (c["low_c"], c["high_c"]) if start_low else (c["high_c"], c["low_c"])
    ramp = 60.0 * (c["high_c"] - c["low_c"]) / rate_c_per_min
    pts, t = [(0.0, first)], 0.0
    for _ in range(c["n_cycles"]):
        for temp in (first, second, second, first):
            t += c["hold_s"] if temp == pts[-1][1] else ramp
            pts.append((t, temp))
    t += c["hold_s"]
    pts.append((t, first))
    return np.array(pts)


def lag(u: np.ndarray, tau_s: float, dt_s: float = 1.0) -> np.ndarray:
    """First-order lag ``dy/dt = (u - y)/tau`` of samples ``u``, exact for u linear between
    samples, starting soaked (y[0] = u[0])."""
    a = math.exp(-dt_s / tau_s)
    g = tau_s / dt_s * (1.0 - a)
    b = np.array([1.0 - g, g - a])
    y, _ = lfilter(b, [1.0, -a], u, zi=np.array([u[0] * g]))   # steady state: y = u = u[0] from the start
    return y


def _gauss_markov(rng, n: int, sigma: float, tau_s: float) -> np.ndarray:
    """Stationary Gauss-Markov process (std ``sigma``, correlation time ``tau_s``), 1-s samples."""
    a = math.exp(-1.0 / tau_s)
    e = rng.standard_normal(n)
    e[1:] *= math.sqrt(1.0 - a * a)
    y, _ = lfilter([1.0], [1.0, -a], e[1:], zi=np.array([a * e[0]]))
    return sigma * np.concatenate(([e[0]], y))


FLICKER_TAUS_S = tuple(10.0 ** (k / 2.0) for k in range(2, 11))   # 10 s .. 1e5 s, 2 per decade


def _flicker(rng, n: int, b_dph: float) -> np.ndarray:
    """Flicker noise with one-sided PSD ~ b^2 / (pi f) between about 1/(2 pi 1e5 s) and 1/(2 pi 10 s):
    each Gauss-Markov component has variance b^2 ln(10) / (pi m), m = 2 per decade."""
    sigma = b_dph * math.sqrt(math.log(10.0) / (math.pi * 2.0))
    return sum(_gauss_markov(rng, n, sigma, tau) for tau in FLICKER_TAUS_S)


def node_temperatures(dev: ForeignDevice, t_s: np.ndarray, chamber_c: np.ndarray) -> list:
    """Temperature [degC] of every node (with self-heating after power-on)."""
    temps = []
    sh = dev.self_heating
    for j, nd in enumerate(dev.nodes):
        src = chamber_c if nd["parent"] < 0 else temps[nd["parent"]]
        y = lag(src, nd["tau_s"])
        if j == sh["node"]:
            y = y + sh["rise_c"] * (1.0 - np.exp(-t_s / sh["tau_s"]))
        temps.append(y)
    return temps


def damping_bias(dev: ForeignDevice, rate_c_per_min: float, duration_s: float | None = None) -> np.ndarray:
    """B_D [deg/h] of a run at ``rate_c_per_min`` at every 1-s sample, before the power-on change
    (the run multiplies it by 1 + d_scale and adds d_offset): e.g. to size the effect of a
    damping change, ``d_scale * std(B_D)``."""
    prof = chamber_profile(dev, rate_c_per_min)
    n = int(math.floor(prof[-1, 0] if duration_s is None else duration_s)) + 1
    t = np.arange(n, dtype=np.float64)
    temps = node_temperatures(dev, t, np.interp(t, prof[:, 0], prof[:, 1]))
    y = (temps[dev.damping_node] - T_REF_C) / T_SCALE_C
    c = dev.damping
    return c["c0"] + c["c1"] * y + c["c2"] * y ** 2 + c["c3"] * y ** 3


def _since_exchange_end(t_s: np.ndarray, mode: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(seconds since the last exchange ended, +1/-1 = the mode entered) at every sample; inf/0
    before the first exchange end; in mode 3 the time since the exchange started in the first array."""
    n = len(t_s)
    since = np.full(n, np.inf)
    entered = np.zeros(n)
    last_end, last_start, last_sign, prev = -np.inf, -np.inf, 0.0, -1
    for i in range(n):
        m = mode[i]
        if m == 3 and prev != 3:
            last_start = t_s[i]
        if m in (1, 2) and prev == 3:
            last_end, last_sign = t_s[i], (1.0 if m == 1 else -1.0)
        since[i] = t_s[i] - (last_start if m == 3 else last_end)
        entered[i] = last_sign
        prev = m
    return since, entered


# -- the run --------------------------------------------------------------------------------------

def _parse_effects(effect) -> tuple:
    if effect is None:
        return ()
    names = (effect,) if isinstance(effect, str) else tuple(effect)
    for name in names:
        if name not in EFFECTS:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(EFFECT_KINDS)}")
    return names


def simulate_foreign(device, rate_c_per_min: float, reversal: bool, power_on: int = 0, noise_seed: int = 0,
                     duration_s: float | None = None, thermal: bool = True, effect=None,
                     strength: float = 1.0, ambient_c: float | None = None, start_low: bool = False,
                     modes=None) -> RunLog:
    """One run of ``device`` (a ForeignDevice or a seed) at chamber rate ``rate_c_per_min``
    [degC/min], mode reversal on/off, power-on index ``power_on`` (selects the damping change),
    ``noise_seed``; ``duration_s`` None = the whole chamber profile; ``thermal=False`` zeroes every
    bias term (module doc); ``effect`` one name of EFFECT_KINDS or a sequence of them (undeclared),
    each at ``strength`` (>= 0, dimensionless).  An MR-only effect on an FTR run is an error.
    ``ambient_c`` [degC]: a power-on at constant ambient instead of the chamber profile (the
    chamber air held at ``ambient_c``, every node soaked at it; ``rate_c_per_min`` then only names
    the run; ``duration_s`` None = STARTUP_S): the start-up of the paper's Table 4.  ``start_low``:
    the chamber cycles start soaked at the low end (the power-on at the cold end of the range).
    The log has no ``freq_hz`` column when the device is temperature-only (``dev.logs_freq`` False;
    module doc).  ``modes``: an explicit mode schedule (int[n] of 1, 2, 3, e.g.
    host_tools.simulation.sim_physics.sparse_sequence) instead of the paper's; needs ``reversal``."""
    dev = device if isinstance(device, ForeignDevice) else foreign_device(device)
    power_on = _check_int(power_on, "power_on")
    noise_seed = _check_int(noise_seed, "noise_seed")
    effects = _parse_effects(effect)
    if not (isinstance(strength, (int, float)) and math.isfinite(strength) and strength >= 0):
        raise ValueError(f"strength must be a finite number >= 0, not {strength!r}")
    for name in effects:
        if EFFECTS[name].runs == "mr" and not reversal:
            raise ValueError(f"effect {name!r} acts on mode-reversal runs only (reversal is off)")
    prof = chamber_profile(dev, rate_c_per_min, bool(start_low))
    if ambient_c is not None:
        if not (isinstance(ambient_c, (int, float)) and math.isfinite(ambient_c) and -60.0 <= ambient_c <= 100.0):
            raise ValueError(f"ambient_c must be a temperature in -60..100 degC, not {ambient_c!r}")
        prof = np.array([(0.0, float(ambient_c)), (float(STARTUP_S), float(ambient_c))])
    if duration_s is None:
        duration_s = float(prof[-1, 0])
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s >= 2):
        raise ValueError(f"duration_s must be >= 2 s, not {duration_s!r}")
    n = int(math.floor(duration_s)) + 1
    if n > MAX_SAMPLES:
        raise ValueError(f"duration_s {duration_s} gives {n} samples, more than {MAX_SAMPLES}")
    t = np.arange(n, dtype=np.float64)
    mode = mode_sequence(t, bool(reversal), EXCHANGE_S, DWELL_S) if modes is None else _check_modes(modes, n, reversal)
    s = np.where(mode == 2, -1.0, np.where(mode == 3, 0.0, 1.0))

    # temperatures (profile holds its last value past its end)
    chamber = np.interp(t, prof[:, 0], prof[:, 1])
    temps = node_temperatures(dev, t, chamber)
    t_res = temps[dev.resonator_node]

    # noise: fixed draw order, independent of thermal/effect
    rng = np.random.default_rng([dev.seed, 3, noise_seed])
    nz = dev.noise
    white = nz["white_dph"] * rng.standard_normal(n)
    flick = _flicker(rng, n, nz["flicker_b_dph"])
    rrw = np.cumsum(rng.standard_normal(n)) * nz["rrw_k"] / 60.0   # K [deg/h/sqrt(h)] * sqrt(1 s / 1 h)
    pll = dev.drive["pll_noise_hz"] * rng.standard_normal(n)
    sens = dev.sensor["noise_c"] * rng.standard_normal(n)
    vdd_w = _gauss_markov(rng, n, dev.aux["vdd_wander_v"], dev.aux["vdd_tau_s"]) + 1e-3 * rng.standard_normal(n)
    tilt = [np.radians(_gauss_markov(rng, n, dev.aux["tilt_deg"], dev.aux["tilt_tau_s"])) for _ in range(2)]
    acc_noise = 0.02 * rng.standard_normal((3, n))

    # drive frequency (self-sensed proxy)
    d = dev.drive
    x = t_res - F_REF_C
    f = d["f0_hz"] * (1.0 + d["a1_per_c"] * x + d["a2_per_c2"] * x ** 2 + d["a3_per_c3"] * x ** 3) + pll
    freq = np.round(f / d["nco_step_hz"]) * d["nco_step_hz"]
    # temperature sensor
    t_sens = temps[dev.sensor_node]
    temp_c = dev.sensor["gain"] * t_sens + dev.sensor["offset_c"] + sens
    temp_c = np.round(temp_c / dev.sensor["lsb_c"]) * dev.sensor["lsb_c"]
    # aux channels
    vdd = dev.aux["vdd_nom_v"] + vdd_w
    ax, ay = tilt
    acc = np.vstack([G0 * np.sin(ay), -G0 * np.sin(ax) * np.cos(ay), -G0 * np.cos(ax) * np.cos(ay)]) + acc_noise

    flip = np.zeros(n)      # multiplied by s
    keep = np.zeros(n)      # not flipping (modes 0/1/2/3)
    if thermal:
        yd = (temps[dev.damping_node] - T_REF_C) / T_SCALE_C
        c = dev.damping
        b_d = c["c0"] + c["c1"] * yd + c["c2"] * yd ** 2 + c["c3"] * yd ** 3     # as damping_bias()
        d_scale, d_off = dev.damping_change(power_on)
        b_d = (1.0 + d_scale) * b_d + d_off
        te = temps[dev.common_node]
        ye = (te - T_REF_C) / T_SCALE_C
        e = dev.common
        b_e = e["e1"] * ye + e["e2"] * ye ** 2 + e["e3"] * np.tanh((te - e["tk_c"]) / e["w_c"])
        flip += b_e
        keep += b_d
        since, entered = _since_exchange_end(t, mode)
        ex = dev.exchange
        since_f = np.where(np.isfinite(since), since, 1e9)
        ring = ex["ring_amp_dph"] * np.exp(-since_f / ex["ring_tau_s"]) * np.cos(2 * np.pi * ex["ring_freq_hz"] * since_f)
        tail = entered * ex["tail_amp_dph"] * np.exp(-since_f / ex["tail_tau_s"])
        keep += np.where(mode == 3, ring, np.where(mode == 0, 0.0, tail))
        for name in effects:
            p = dev.effects[name]
            term = strength * _effect_term(name, p, dev, t, mode, temps, since, b_d, vdd, acc)
            if EFFECTS[name].flips:
                flip += term
            else:
                keep += term
    rate = s * (dev.omega_dph + flip) + keep + white + flick + rrw

    meta = {"device": f"foreign-{dev.seed}", "sample_rate_hz": "1", "reversal": "on" if reversal else "off"}
    if reversal:
        meta.update({"exchange_s": f"{EXCHANGE_S:g}", "dwell_s": f"{DWELL_S:g}"} if modes is None else {"schedule": "explicit"})
    meta.update({"family": "random", "foreign_version": str(FOREIGN_VERSION), "seed": str(dev.seed),
                 "profile": (f"trapezoid {rate_c_per_min:g} degC/min" + (", cold start" if start_low else "")
                             if ambient_c is None
                             else f"constant {ambient_c:g} degC from power-on"), "power_on": str(power_on),
                 "noise_seed": str(noise_seed), "thermal": "on" if thermal else "off"})
    where = (f"{rate_c_per_min:g}cpm" + (" cold" if start_low else "")) if ambient_c is None else f"ambient {ambient_c:g}C"
    src = (f"<foreign {dev.seed} {where} {'MR' if reversal else 'FTR'} p{power_on} "
           f"n{noise_seed}{'' if thermal else ' floor'}>")
    cols = {"t_s": t, "freq_hz": freq} if dev.logs_freq else {"t_s": t}
    return RunLog.from_arrays(metadata=meta, source=src, **cols, rate_dph=rate, mode=mode,
                              temp_c=temp_c, aux_vdd=vdd, aux_acc_x=acc[0], aux_acc_y=acc[1], aux_acc_z=acc[2])


def _check_modes(modes, n: int, reversal: bool) -> np.ndarray:
    """An explicit mode schedule: int64[n], values 1, 2, 3, on a mode-reversal run."""
    if not reversal:
        raise ValueError("modes: an explicit mode schedule needs reversal on")
    m = np.asarray(modes)
    if m.shape != (n,):
        raise ValueError(f"modes: {m.shape} values for a run of {n} samples")
    bad = ~np.isin(m, (1, 2, 3))
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"modes: sample {i} has mode {m[i].item()!r} (1, 2 or 3 on a mode-reversal run)")
    return m.astype(np.int64)


def _effect_term(name, p, dev, t, mode, temps, since, b_d, vdd, acc) -> np.ndarray:
    """Bias [deg/h] of effect ``name`` at strength 1 (module doc table)."""
    if name == "thermal_lag":
        return p["k_dph_per_c"] * (lag(temps[dev.resonator_node], p["tau_s"]) - T_REF_C)
    if name == "turn_on":
        return p["amp_dph"] * np.exp(-t / p["tau_s"])
    if name == "exchange_transient":
        out = p["amp_dph"] * np.exp(-np.where(np.isfinite(since), since, 1e9) / p["tau_s"])
        return np.where(mode == 3, 0.0, out)
    if name == "imperfect_reversal":
        return np.where(mode == 2, p["eps"] * b_d + p["delta_dph"], 0.0)
    if name == "proxy_high_order":
        return p["amp_dph"] * ((temps[dev.resonator_node] - T_REF_C) / T_SCALE_C) ** 4
    if name == "board_temp":
        ts = temps[dev.sensor_node] - T_REF_C
        return p["k_dph_per_c"] * ts + p["q_dph"] * (ts / T_SCALE_C) ** 2
    if name == "aux":
        g = np.asarray(p["g_dph_per_g"])
        return p["kv_dph_per_v"] * (vdd - dev.aux["vdd_nom_v"]) + (g[:, None] * acc).sum(axis=0) / G0
    if name == "aging":
        return p["amp_dph"] * (1.0 - np.exp(-t / p["tau_s"]))
    if name == "periodic":
        return p["amp_dph"] * np.sin(2 * np.pi * t / p["period_s"] + p["phase_rad"])
    raise ValueError(f"unknown effect {name!r}")


def format_effects() -> str:
    """The undeclared effect kinds of the random family (runs, flip, columns followed, units of
    strength 1) as the text `hdrg simulate --family random --list` prints."""
    lines = ["random family: a device is --seed; undeclared effects (--effect NAME, --strength X):"]
    lines += [f"  {k.name:19s} runs {k.runs:6s} {'flips' if k.flips else 'no flip'}; follows "
              f"{k.columns or '-'}; strength 1 = nominal ({k.units})" for k in EFFECTS.values()]
    return "\n".join(lines)
