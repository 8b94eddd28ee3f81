"""The physics of host_tools.simulation.sim: the thermal lags, the mode sequence, the noise processes and
:func:`run_physics` (every signal of a run and every effect's contribution, from a
:class:`~host_tools.simulation.sim_params.SimConfig` and a seed).  Signal chain and units: host_tools.simulation.sim's
module doc.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.signal import lfilter

from host_tools.simulation.sim_params import EFFECTS, SimConfig

EARTH_RATE_DPH = 15.041067  # sidereal Earth rate [deg/h]

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


def sparse_sequence(t_s: np.ndarray, exchange_s: float, window_s: float, period_s: float) -> np.ndarray:
    """Mode of every sample under sparse reversal: the gyroscope runs in mode 1 and makes an
    *excursion* (exchange (3) ``exchange_s``, mode 2 ``window_s``, exchange back) every
    ``period_s``.  From power-on: exchange, mode 1 ``window_s`` (the first excursion's reference),
    then the first excursion at ``exchange_s + window_s``, the next ones ``period_s`` apart
    [s].  A ``period_s`` shorter than one excursion plus its reference window is an error."""
    for what, v in (("exchange_s", exchange_s), ("window_s", window_s), ("period_s", period_s)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"sparse reversal: {what} must be > 0 s, not {v!r}")
    if period_s < 3 * exchange_s + 2 * window_s:
        raise ValueError(f"sparse reversal: period_s {period_s:g} s is shorter than an excursion and its "
                         f"reference window (3 x exchange_s + 2 x window_s = {3 * exchange_s + 2 * window_s:g} s)")
    t = np.asarray(t_s, float)
    mode = np.ones(len(t), np.int64)
    mode[t < exchange_s] = 3
    first = exchange_s + window_s
    ph = np.mod(t - first, period_s)
    on = t >= first
    mode[on & (ph < 2 * exchange_s + window_s)] = 3
    mode[on & (ph >= exchange_s) & (ph < exchange_s + window_s)] = 2
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
