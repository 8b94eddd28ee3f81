"""The ``sequencer`` set's case generator: the whole pipeline, self-timed and log-driven.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from firmware_ref import formats as F
from firmware_ref.terms import N_TERMS
from host_tools.vectors.spec import SEQ_FIELDS, SEQ_INPUTS
from host_tools.vectors.files import VectorSet
from host_tools.vectors.evaluator import qtable
from host_tools.vectors.pipeline import Cases, compute_pipeline


def _ramp(table, n, rng, rate_lsb=600.0) -> dict:
    """A proxy ramp through the range with noise, rate words of a slow bias plus noise."""
    lo, hi = (0, F.UINT32_MAX) if table.proxy_kind == 0 else (-F.INT32_SYM, F.INT32_SYM)
    span = max(2, (F.ONE << table.sh_u) // table.g_u)
    x = np.linspace(-1.2, 1.2, n) * span + rng.normal(0, span * 1e-3, n)
    p = np.clip(table.p_ref + np.round(x).astype(np.int64), lo, hi)
    r = np.round(5000 * np.sin(np.arange(n) / 37.0) + rng.normal(0, rate_lsb, n)).astype(np.int64)
    return {"p": p, "r": r, "mode": np.zeros(n, np.int64), "restart": None, "z": None}


def _extreme_stream(t) -> dict:
    """21 log-driven samples at P_REF in 2-sample windows with +-(2^31 - 1) rate words: the trend
    slope clamp and the output (or residual) word saturations."""
    modes = [1, 1, 2, 2, 1, 1, 2, 2, 1, 1, 2, 2, 2, 3, 1, 1, 1, 2, 2, 2, 1]
    r = [F.INT32_SYM, F.INT32_SYM, 0, 0, -F.INT32_SYM, -F.INT32_SYM, F.INT32_SYM, F.INT32_SYM, F.INT32_SYM,
         F.INT32_SYM, -F.INT32_SYM, -F.INT32_SYM, 5, 0, -F.INT32_SYM, 3, 1, F.INT32_SYM, -1, 0, 7]
    return {"p": np.full(len(modes), t.p_ref, np.int64), "r": np.array(r), "mode": np.array(modes)}


# (drive frequency [Hz], rate estimator, combiner) of the drive-frequency cases
DRIVE_FREQ_CASES = ((3.0e3, "diff", "pair"), (24.0e3, "diffn", "trend"), (36.0e3, "iir", "pair"),
                    (65.0e3, "diff", None))
# (name, proxy centre [Hz], span [Hz]): the proxy range touching each end of the F word
WORD_END_CASES = (("word_low_end_log", 8.0, 4.0),
                  ("word_high_end_log", F.FREQ_RANGE_HZ - 12.0, 8.0))


def sequencer_set(rng) -> VectorSet:
    from host_tools.vectors.builders import corner_stream, random_model, random_stream
    from host_tools.fixed.quantize import quantize

    cs = Cases()
    t = qtable("diff", "pair", power_on_s=7.0, exchange_s=3.0, dwell_s=9.0)
    cs.add("power_on_timed", "self-timed from power-on (7), exchange 3, dwell 9, settle 2, pair", t,
           _ramp(t, 160, rng), True)
    t = qtable("diffn", "trend", n=8, settle_s=5.0, max_stale_s=300.0)
    cs.add("paper_cycles_timed", "self-timed at the paper's timing (exchange 30, dwell 120, no power-on), "
           "trend, settle 5, 2.5 cycles", t, _ramp(t, 780, rng), True)
    t = qtable("diff", None, power_on_s=5.0)
    cs.add("ftr_timed", "self-timed FTR table: power-on (5) then FTR forever", t, _ramp(t, 60, rng), True)
    t = qtable("iir", "pair", shift=3, exchange_s=0.0, dwell_s=4.0)
    cs.add("no_exchange_timed", "self-timed, exchange_n = 0, power_on_n = 0: modes 1/2 alternate directly", t,
           _ramp(t, 100, rng), True)
    t = qtable("diff", "trend", settle_s=0.0, power_on_s=2.0, exchange_s=1.0, dwell_s=1.0)
    cs.add("dwell1_timed", "self-timed, one-sample windows (dwell 1, exchange 1), trend", t, _ramp(t, 80, rng), True)
    t = qtable("diff", "pair", settle_s=5.0, exchange_s=2.0, dwell_s=5.0)
    cs.add("settle_eq_dwell_timed", "self-timed, settle_n = dwell_n = 5: never valid (stale)", t, _ramp(t, 60, rng),
           True)
    # staleness limit edge: max_stale 10, the other window's age runs through 10 and 11
    t = qtable("diff", "pair", settle_s=0.0, max_stale_s=10.0)
    modes = [1] * 5 + [2] * 15 + [3] * 3 + [1] * 12 + [3] * 8 + [2] * 6 + [3] * 9 + [1] * 4 + [2] * 3
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    cs.add("stale_edge_log", "log-driven, max_stale_n = 10: ages 1..15 of the other window (valid up to 10)", t, s)
    # trend slope clamp and output saturation: extreme rate words in short windows
    t = qtable("diff", "trend", settle_s=0.0, max_stale_s=50.0)
    s = _extreme_stream(t)
    cs.add("slope_clamp_log", "log-driven trend with +-(2^31 - 1) rate words in 2-sample windows: slope clamp, "
           "OUT saturation (flag 128)", t, s)
    # BIAS / OUT saturation: E = 0, B = m_0 << 21
    big = dataclasses.replace(qtable("diff", None), e_row=(0, 0, 0, 0), e_7=0, e_acc=0,
                              mant=tuple(F.INT32_SYM if k == 0 else 0 for k in range(N_TERMS)))
    s = _ramp(big, 40, rng)
    s["r"][::3] = -F.INT32_SYM
    cs.add("bias_saturation_log", "FTR, B = (2^31 - 1) deg/h: BIAS and OUT saturate (flag 128)", big, s)
    neg = dataclasses.replace(big, mant=tuple(-m for m in big.mant))
    s = _ramp(neg, 20, rng)
    s["r"][::2] = F.INT32_SYM
    cs.add("bias_saturation_neg_log", "FTR, B = -(2^31 - 1) deg/h", neg, s)
    # long windows with extreme rates: |acc| up to 700 (2^31 - 1)
    t = qtable("lsq", "trend", n=16, settle_s=3.0, max_stale_s=2000.0)
    modes = [3] * 5 + [1] * 700 + [3] * 4 + [2] * 700 + [3] * 2 + [1] * 60
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    s["r"] = np.where(np.arange(len(modes)) % 5 == 0, F.INT32_SYM, F.INT32_SYM - 1 - np.arange(len(modes)))
    s["restart"] = np.zeros(len(modes), np.int64)
    s["restart"][1000] = 1
    cs.add("long_windows_log", "log-driven, 700-sample windows of near-full-scale rate words (|acc| ~ 2^40.5), "
           "lsq n=16, restart inside a window", t, s)
    # long self-timed run: many short cycles
    t = qtable("iir", "trend", shift=4, settle_s=1.0, max_stale_s=12.0, power_on_s=3.0, exchange_s=2.0,
                dwell_s=5.0)
    s = random_stream(rng, t, 2500)
    s["restart"][:] = 0
    s["restart"][[0, 1234]] = 1
    cs.add("long_timed", "self-timed, 2500 samples of exchange 2 / dwell 5 cycles (~180 windows), iir, trend, "
           "one restart", t, s, True)
    # corner streams of host_tools.vectors.builders
    for est, comb in (("diff", "pair"), ("diffn", "trend"), ("lsq", None), ("iir", "trend"), ("lsq", "pair"),
                      ("iir", None)):
        t = qtable(est, comb)
        cs.add(f"corner_{est}_{comb or 'ftr'}", "host_tools.vectors.builders.corner_stream (log-driven)", t,
               corner_stream(t, reversal=comb is not None))
    t = qtable("diffn", "pair", n=8, exchange_s=2.0, dwell_s=5.0)
    cs.add("corner_diffn_pair_timed", "host_tools.vectors.builders.corner_stream words, self-timed", t,
           corner_stream(t), True)
    # regress, then reverse (order 1): two banks (bank 2 on mode-2 samples), the residual combiner
    for comb in ("pair", "trend", "none"):
        t = qtable("diff", comb, order="regress_first", power_on_s=2.0, exchange_s=3.0, dwell_s=9.0)
        cs.add(f"rtr_{comb}_timed", f"regress_first {comb}: self-timed, power-on 2, exchange 3, dwell 9, settle 2; "
               "windows sum r = c - B of the mode's bank", t, _ramp(t, 200, rng), True)
    t = qtable("diff", "pair", order="regress_first", settle_s=0.0, max_stale_s=10.0)
    modes = [1] * 5 + [2] * 15 + [3] * 3 + [1] * 12 + [3] * 8 + [2] * 6 + [3] * 9 + [1] * 4 + [2] * 3
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    cs.add("rtr_stale_edge_log", "regress_first pair, log-driven, max_stale_n = 10: ages 1..15 of the other window",
           t, s)
    big2 = np.array([2.0 ** 21 * 0.9] + [0.0] * (N_TERMS - 1))
    t = qtable("diff", "trend", order="regress_first", settle_s=0.0, max_stale_s=50.0,
                coef=[1.0] + [0.0] * (N_TERMS - 1), coef2=big2)
    s = _extreme_stream(t)
    cs.add("rtr_residual_saturation_log", "regress_first trend, bank 2 B = 0.9 2^21 deg/h, +-(2^31 - 1) rate "
           "words: the residual word r saturates (flag 128), slope clamp", t, s)
    t = qtable("lsq", "pair", n=16, order="regress_first", settle_s=0.0, max_stale_s=200.0)
    modes = [1] * 30 + [2] * 30 + [1] * 30 + [2] * 30
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    s["restart"] = np.zeros(len(modes), np.int64)
    s["restart"][[0, 70]] = 1
    cs.add("rtr_warmup_log", "regress_first pair, lsq n=16: rate warm-up samples (after power-on and a restart "
           "inside a window) are not used (no sum, not valid)", t, s)
    for est, comb in (("diffn", "pair"), ("iir", "none"), ("lsq", "trend")):
        t = qtable(est, comb, order="regress_first")
        cs.add(f"rtr_corner_{est}_{comb}", "regress_first: host_tools.vectors.builders.corner_stream (log-driven)", t,
               corner_stream(t))
    for k in range(3):
        est = ("diff", "diffn", "iir")[k]
        t = quantize(random_model(rng, estimator=est, order="regress_first"), exchange_s=3.0, dwell_s=7.0,
                     n_random=10).table
        cs.add(f"rtr_random_{k}", f"host_tools.vectors.builders.random_model(order='regress_first', {est}, combiner "
               f"{F.COMBINERS[t.combiner]}) and random_stream{', self-timed' if k == 1 else ''}", t,
               random_stream(rng, t, 500), k == 1)
    # random models and streams
    for k in range(4):
        reversal = k != 3
        est = ("diff", "diffn", "lsq", "iir")[k]
        t = quantize(random_model(rng, reversal=reversal, estimator=est), exchange_s=3.0, dwell_s=7.0,
                     n_random=10).table
        timed = k == 1
        cs.add(f"random_{k}", f"host_tools.vectors.builders.random_model ({est}) and random_stream"
               f"{', self-timed' if timed else ''}", t, random_stream(rng, t, 500, reversal=reversal), timed)
    # the iir's start-up gear (shift min(10, floor(log2 k))) through every step, k saturating at 2^10,
    # a restart after the saturation and a second segment whose gear reaches 10
    t = qtable("iir", "pair", shift=10, settle_s=1.0, max_stale_s=40.0)
    s = random_stream(rng, t, 3200)
    s["restart"][:] = 0
    s["restart"][[0, 2000]] = 1
    cs.add("iir_gear_log", "log-driven, iir shift 10: the start-up gear 0..10 (k = 1, 2, 4, .., 1024), k saturating "
           "at 2^10, a restart at 2000 and a second 1200-sample segment", t, s)
    # drive frequencies across the F word (uint32, LSB 2^-FREQ_FRAC Hz): the proxy centre at a
    # 3, 24, 36 and 65 kHz gyroscope (span and rate span of -20..20 degC and 4 degC/min at
    # -20.9 ppm/degC), and tables whose range touches each end of the word
    for f0, est, comb in DRIVE_FREQ_CASES:
        t = qtable(est, comb, ref=f0, span=f0 * 20.9e-6 * 20.0, rate_span=f0 * 20.9e-6 * 4.0 / 60.0)
        cs.add(f"drive_{f0 / 1e3:g}khz_log", f"log-driven, frequency proxy centred at {f0:g} Hz ({est}, "
               f"{comb or 'ftr'}): ramp through the range", t, _ramp(t, 300, rng))
        cs.add(f"drive_{f0 / 1e3:g}khz_random", f"frequency proxy centred at {f0:g} Hz ({est}, {comb or 'ftr'}): "
               "random_stream (word rails included)", t, random_stream(rng, t, 300, reversal=comb is not None))
    for name, ref, span in WORD_END_CASES:
        t = qtable("diff", "pair", ref=ref, span=span, rate_span=span * 1e-3)
        cs.add(name, f"frequency proxy centred at {ref:g} Hz, span {span:g} Hz: the range reaches the F word's "
               "end; corner_stream (log-driven)", t, corner_stream(t))
    vs = VectorSet("sequencer", "the whole pipeline (sequencer, combiner, proxy, rate, evaluator, outputs): inputs "
                   "F T R MODE RESTART Z (MODE -1: self-timed), outputs the 16 fields of the protocol's O line",
                   cs.columns(), SEQ_INPUTS, SEQ_FIELDS, cs.cases, cs.tables)
    compute_pipeline(vs, rows=False)
    return vs
