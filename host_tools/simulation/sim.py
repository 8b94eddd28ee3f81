"""The virtual gyroscope: a deterministic-for-a-seed simulator of run logs of a mode-matched disk
gyroscope (HDRG) in a temperature chamber (Chen et al. 2022), behind ``hdrg simulate``.

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
trend combiner of host_tools.golden.reversal + 17 terms ~0.27 deg/h (paper: 0.45).  The FTR run
self-compensates to ~0.2 deg/h (paper: 1.1), the start-up run 0.48 -> 0.04 deg/h (paper: 0.05-0.08).

Modules: this one (scenarios, the configuration, :func:`simulate`), host_tools.simulation.sim_profiles (the
chamber programs), host_tools.simulation.sim_params (SimParams, the effects' parameters and registry,
SimConfig) and host_tools.simulation.sim_physics (lags, mode sequence, noise, :func:`run_physics`).

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

from host_tools.golden.checks import shorter_than_a_sample, whole_samples
from host_tools.golden.runlog import RunLog
from host_tools.simulation.sim_params import DEFAULT_EFFECTS, EFFECTS, SimConfig, SimParams, param_spec, effect_params
from host_tools.simulation.sim_physics import run_physics
from host_tools.simulation.sim_profiles import Profile, constant_profile, cycle_profile, slow_ramp_profile

SIM_VERSION = 1
MAX_SAMPLES = 100_000_000


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
    "paper-mr-cycle-2dpm": Scenario(
        "mode reversal 30/120/30/120 s, -20..20 degC cycles at 2 degC/min, 2-h holds (a second chamber rate)",
        lambda: cycle_profile(2.0), reversal=True),
    "mr-one-cycle-4dpm": Scenario(
        "mode reversal, one -20..20 degC cycle at 4 degC/min, 1-h holds: a cooling and a heating leg, 2.3 h",
        lambda: cycle_profile(4.0, hold_s=3600.0, n_cycles=1), reversal=True),
    "mr-one-cycle-2dpm": Scenario(
        "mode reversal, one -20..20 degC cycle at 2 degC/min, 1-h holds: a cooling and a heating leg, 2.7 h",
        lambda: cycle_profile(2.0, hold_s=3600.0, n_cycles=1), reversal=True),
    "ftr-one-cycle-4dpm": Scenario(
        "FTR, one -20..20 degC cycle at 4 degC/min, 1-h holds: a cooling and a heating leg, 2.3 h",
        lambda: cycle_profile(4.0, hold_s=3600.0, n_cycles=1)),
    "ftr-one-cycle-2dpm": Scenario(
        "FTR, one -20..20 degC cycle at 2 degC/min, 1-h holds: a cooling and a heating leg, 2.7 h",
        lambda: cycle_profile(2.0, hold_s=3600.0, n_cycles=1)),
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
            param_spec(name)
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
    param_spec(name)
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
    if params.reversal:
        for name in ("exchange_s", "dwell_s"):
            value = getattr(params, name)
            if value != 0 and shorter_than_a_sample(value, sample_rate_hz):
                raise ValueError(f"{name} {value:g} s is shorter than one sample at {sample_rate_hz:g} Hz "
                                 f"({1 / sample_rate_hz:g} s)" + (" (or 0 for none)" if name == "exchange_s" else ""))
    n = int(round(duration_s * sample_rate_hz))
    if n < 2:
        raise ValueError(f"duration {duration_s} s at {sample_rate_hz} Hz gives {n} sample(s); need at least 2")
    if n > MAX_SAMPLES:
        raise ValueError(f"duration {duration_s} s at {sample_rate_hz} Hz gives {n} samples (limit {MAX_SAMPLES})")
    return SimConfig(scenario, profile, params, effects, frozenset(hidden), duration_s, sample_rate_hz)


def schedule_notes(cfg: SimConfig) -> list:
    """Notes on a mode-reversal schedule whose exchange or dwell is not a whole number of samples:
    the schedule runs in continuous time, so those phases last one sample more or less by turns."""
    fs, p = cfg.sample_rate_hz, cfg.params
    notes = []
    for name, phase in (("exchange_s", "exchange"), ("dwell_s", "mode-1/2 window")) if p.reversal else ():
        n = getattr(p, name) * fs
        if not whole_samples(getattr(p, name), fs):
            notes.append(f"{name} {getattr(p, name):g} s is {n:.6g} samples at {fs:g} Hz: the schedule runs in "
                         f"continuous time, so each {phase} lasts {math.floor(n)} or {math.ceil(n)} samples "
                         f"(a sequencer counts whole samples)")
    return notes


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
