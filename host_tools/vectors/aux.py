"""The ``aux`` set's case generator: tables with aux generators (aux_gen 1), every kind alone,
random multi-term tables, tables of up to formats.AUX_MAX_TERMS (16) terms (the longest table: 255
words) and simulated runs with fitted aux models (3 and 16 terms).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from firmware_ref import formats as F
from firmware_ref.table import Table
from host_tools.vectors.spec import AUX_FIELDS, AUX_INPUTS
from host_tools.vectors.files import VectorSet
from host_tools.vectors.pipeline import Cases, compute_pipeline
from host_tools.vectors.e2e import jsonable_value, round_sig


# -- aux generators ----------------------------------------------------------------------------------------

def _aux_table(base, terms, fracs=()) -> Table:
    """``base`` (aux_gen 0) with aux_gen 1 terms (firmware_ref.table.AuxTerm) and channel fracs."""
    from firmware_ref.table import encode_aux

    return dataclasses.replace(base, aux_gen=1, aux_params=encode_aux(tuple(fracs), tuple(terms)))


def _one_kind(base_model, term, fs=1.0):
    """The quantized table of ``base_model`` with a single generator term of weight 1 (z = g)."""
    from host_tools.vectors.builders import with_aux

    return quantize_aux(with_aux(base_model, [{**term, "weight": 1.0}]))


def _aux_steps(table, n, rng, step_every=175, reversal=True) -> dict:
    """A stream whose channel words, for each input term, cycle every ``step_every`` samples through
    +1.2 spans (a step: filters settle, clamps), a ramp from -1.1 to +1.1 spans, -1.2 spans, and a
    random walk (aux_stream); modes of a short reversal cycle, K = i."""
    from host_tools.vectors.builders import aux_stream

    s = aux_stream(rng, table, n, reversal=reversal, extreme=0.0, k_jumps=False)
    info = table.aux()
    i = np.arange(n)
    phase = (i // step_every) % 4
    level = np.select([phase == 0, phase == 1, phase == 2],
                      [1.2, -1.1 + 2.2 * (i % step_every) / step_every, -1.2], np.nan)
    chans = {0: s["f"], 1: s["t"]}
    for c in range(info.n_chan):
        chans[2 + c] = s["aux"][:, c]
    for tm in info.terms:
        if tm.kind == 0:
            span = (2.0 ** 30) * 2.0 ** tm.c[3] / tm.c[1]
            lo, hi = (0, F.UINT32_MAX) if tm.src == 0 else (-F.INT32_SYM, F.INT32_SYM)
            set_ = ~np.isnan(level)
            chans[tm.src][set_] = np.clip(np.round(tm.c[0] + level[set_] * span), lo, hi).astype(np.int64)
    s["p"] = chans[table.proxy_kind]
    if reversal:
        s["mode"] = np.resize(np.array([3] * 4 + [1] * 12 + [3] * 4 + [2] * 12), n)
    return s


def aux_set(rng) -> VectorSet:
    from firmware_ref.table import AuxTerm
    from host_tools.vectors.builders import aux_stream, make_model, random_aux_model, with_aux

    cs = Cases()
    base_model = make_model(coef=[3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1,
                                  6e1, -5e1], settle_s=2.0, max_stale_s=25.0)
    temp_model = make_model("temp", ref=20.0, span=30.0, estimator="lsq", n=5, rate_span=0.5, combiner="trend",
                            settle_s=1.0, max_stale_s=25.0)
    # every kind alone, weight 1: z = g
    singles = [
        ("input_proxy", base_model, {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0},
         "the proxy itself (z = u)"),
        ("input_proxy_u5_sign", base_model, {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0,
                                             "power": 5, "sign": True}, "s u^5"),
        ("input_lag_freq", base_model, {"gen": "input", "column": "freq_hz", "ref": 6227.5, "span": 2.0, "tau_s": 37.0,
                                        "power": 2}, "the proxy lagged by 37 samples, squared"),
        ("input_temp_long_lag", base_model, {"gen": "input", "column": "temp_c", "ref": 25.0, "span": 40.0,
                                             "tau_s": 16384.0}, "temperature word (not the proxy) through a "
                                                                  "2^14-sample filter: no dead band"),
        ("input_temp_short_lag", base_model, {"gen": "input", "column": "temp_c", "ref": -5.0, "span": 0.5,
                                              "tau_s": 0.0625}, "the shortest legal filter (1/16 sample)"),
        ("input_aux_word", base_model, {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.05, "tau_s": 5.0,
                                        "power": 3, "sign": True}, "aux word A0 (AF from the range), s y^3"),
        ("input_freq_of_temp_model", temp_model, {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0},
         "temp proxy table reading the F word"),
        ("rate_sign", base_model, {"gen": "rate", "column": "freq_hz", "estimator": "diff", "span": 0.01,
                                   "sign": True}, "s v with its own span"),
        ("rate_lsq", temp_model, {"gen": "rate", "column": "temp_c", "estimator": "lsq", "n": 5, "span": 0.05},
         "the lsq rate sum with another span"),
        ("one_sign", base_model, {"gen": "one", "sign": True}, "s"),
        ("decay_on_short", base_model, {"gen": "decay_on", "tau_s": 4.0}, "decay since power-on / restarts, 4 samples"),
        ("decay_on_long", base_model, {"gen": "decay_on", "tau_s": 3.0e6}, "3 10^6 samples"),
        ("decay_exchange", base_model, {"gen": "decay_exchange", "tau_s": 6.0}, "decay since the last exchange"),
        ("decay_exchange_sign", base_model, {"gen": "decay_exchange", "tau_s": 2.5, "sign": True}, "s times it"),
        ("ramp", base_model, {"gen": "ramp", "n_samples": 300}, "k / 300, 1 from K = 300 on"),
        ("osc_sin", base_model, {"gen": "osc", "period_s": 7.3, "part": "sin"}, "sin, 7.3-sample period"),
        ("osc_cos", base_model, {"gen": "osc", "period_s": 86400.0, "part": "cos"}, "cos, 1-day period"),
    ]
    for name, model, term, desc in singles:
        t = _one_kind(model, term)
        s = _aux_steps(t, 700, rng, reversal=True)
        s["restart"][[350, 351, 520]] = 1
        cs.add(f"single_{name}", f"one term, weight 1 (z = g): {desc}; channel words cycle through +1.2 spans, a "
               f"ramp, -1.2 spans and a random walk (175 samples each), restarts at 350, 351, 520", t, s)
    # K: gaps, negative start, near 2^62 (osc wrap, ramp)
    t = _one_kind(base_model, {"gen": "osc", "period_s": 3.1, "part": "sin"})
    t2 = _aux_table(t, (AuxTerm(6, 0, 0, 1, 1 << 29, (1, 0, 1, 0, 0, 0)),
                        AuxTerm(6, 0, 0, 1, -(1 << 29), ((1 << 63) - 1, 0, 0, 0, 0, 0))))
    for name, tab in (("osc_k_edges", t), ("osc_w_extremes", t2)):
        s = aux_stream(rng, tab, 400, extreme=0.0, k_jumps=True)
        s["k"][:40] = np.arange(-20, 20)
        s["k"][40:80] = F.K_LIMIT - 40 + np.arange(40)
        s["k"][80:90] = -F.K_LIMIT
        cs.add(name, "oscillators at K = -20..19, 2^62 - 40 .. 2^62 - 1, -2^62 and random gaps "
               + ("(period 3.1 samples)" if tab is t else "(W = 1 cos, W = 2^63 - 1 sin)"), tab, s)
    t = _one_kind(base_model, {"gen": "ramp", "n_samples": 2 ** 31 - 1})
    s = aux_stream(rng, t, 200, extreme=0.0, k_jumps=True)
    s["k"][:50] = np.r_[np.arange(-5, 20), (1 << 31) - 14 + np.arange(25)]
    cs.add("ramp_longest", "ramp N = 2^31 - 1 around K = 0 and K = N", t, s)
    # weight-sum clamp (flag 32) and coefficient extremes (hand-made tables)
    base = _one_kind(base_model, {"gen": "one"})
    clamp_t = _aux_table(base, (AuxTerm(2, 0, 0, 1, (1 << 29) + 1, (0,) * 6),
                                AuxTerm(2, 1, 0, 1, (1 << 29) + 1, (0,) * 6)))
    cs.add("weight_sum_clamp", "two 'one' terms of weight 2^29 + 1 (sum |w| = 2^30 + 2): z = 2^30 + 2 is "
           "clamped (flag 32) in modes 0/1", clamp_t, aux_stream(rng, clamp_t, 150, extreme=0.0))
    lim = F.INT32_SYM
    ext_terms = (AuxTerm(0, 0, 2, 5, 1 << 28, (-lim, lim, lim // 2, 62, lim, 31)),
                 AuxTerm(0, 1, 0, 1, -(1 << 28), (F.UINT32_MAX, 1, 0, 0, 1, 62)),
                 AuxTerm(3, 0, 0, 1, 1 << 27, (lim, 31, 0, 0, 0, 0)),
                 AuxTerm(4, 1, 0, 1, -(1 << 27), (1, 62, 0, 0, 0, 0)),
                 AuxTerm(5, 0, 0, 1, 1 << 27, (1, lim, 0, 0, 0, 0)),
                 AuxTerm(0, 0, 5, 4, (1 << 27) + 1, (0, 1 << 30, 0, 1, 1 << 30, 40)))
    ext = _aux_table(base, ext_terms, fracs=(0, 48, 17, 30))
    s = aux_stream(rng, ext, 600, extreme=0.05)
    cs.add("coefficient_extremes", "hand-made: REF -(2^31 - 1) with G 2^31 - 1, SH 62, B 2^31 - 1 at SB 31, "
           "power 5; REF 2^32 - 1 with G 1, B 1 at SB 62; decays at B = 2^31 - 1 / SB 31 and B = 1 / SB 62; "
           "ramp N = 1; A3 power 4; AF 0, 48, 17, 30", ext, s)
    # the four aux words at very different scales (AF from 48 down to a few bits)
    words = [{"gen": "input", "column": col, "ref": ref, "span": span, "tau_s": tau, "weight": 0.25}
             for col, ref, span, tau in (("aux_a", 2.0e-7, 5.0e-8, 0.0), ("aux_b", 3.3, 0.05, 12.0),
                                         ("aux_c", -150.0, 40.0, 0.0), ("aux_d", 2.5e5, 1.0e4, 300.0))]
    t = quantize_aux(with_aux(base_model, words))
    cs.add("aux_words", f"four input terms on A0..A3 (AF {', '.join(map(str, t.aux().fracs))}), two filtered", t,
           _aux_steps(t, 700, rng))
    # random multi-term tables
    for j in range(6):
        reversal = j != 4
        est = ("diff", "diffn", "lsq", "iir", "diff", "lsq")[j]
        model = random_aux_model(rng, reversal=reversal, estimator=est, n_terms=[6, 6, 4, 3, 5, 6][j])
        t = quantize_aux(model)
        timed = j == 5
        cs.add(f"random_{j}", f"host_tools.vectors.builders.random_aux_model ({est}, {len(t.aux().terms)} terms) and "
               f"aux_stream{', self-timed' if timed else ''}", t, aux_stream(rng, t, 500, reversal=reversal), timed)
    # as many generator terms as the firmware holds (formats.AUX_MAX_TERMS = 16): random tables of 7, 10
    # and 13 terms and a random one of 16 (every kind: the first 7 terms take each kind once), a hand-made
    # table of 16 terms with every kind on all four aux words (the longest table: 255 words, the last aux
    # word at address 253), a fitted 16-term model on a simulated run
    for nt, est in ((7, "diffn"), (10, "iir"), (13, "lsq"), (F.AUX_MAX_TERMS, "diff")):
        t = quantize_aux(random_aux_model(rng, reversal=True, estimator=est, n_terms=nt))
        cs.add(f"random_{nt}_terms", f"host_tools.vectors.builders.random_aux_model ({est}, {len(t.aux().terms)} terms "
               f"of every kind, {t.aux().n_chan} aux words) and aux_stream", t, aux_stream(rng, t, 300))
    t = quantize_aux(with_aux(base_model, MAX_TERMS_EVERY_KIND))
    s = _aux_steps(t, 400, rng)
    s["restart"][[200, 201, 330]] = 1
    cs.add("max_terms_every_kind", f"hand-made: {len(t.aux().terms)} terms (AUX_MAX_TERMS) of every kind on F, T and "
           f"all four aux words, {len(t.to_words())} words (the longest table): inputs with and without filters, "
           f"powers 1..5, signs, a lag block of the proxy, rate, one, both decays, ramp, sin and cos; channel words "
           f"step and ramp as the single-kind cases, restarts at 200, 201, 330", t, s)
    log = aux_sim_log()
    case16, cfg16 = aux_sim16_case(log)
    cs.add(*case16)
    # a simulated run with a fitted aux model (the last case: hdrg cost's aux workload)
    case, cfg = aux_sim_case(log)
    cfg = {**cfg, "sim_aux_16": cfg16}
    cs.add(*case)
    vs = VectorSet("aux", "tables with aux generators (aux_gen 1): inputs F T R MODE RESTART Z K A0 A1 A2 A3 (MODE "
                   "-1: self-timed), outputs the 16 fields of the protocol's O line (z: the generated z)",
                   cs.columns(), AUX_INPUTS, AUX_FIELDS, cs.cases, cs.tables)
    vs.config = cfg
    compute_pipeline(vs, rows=False)
    return vs


def quantize_aux(model) -> Table:
    from host_tools.fixed.quantize import quantize

    return quantize(model, exchange_s=3.0, dwell_s=7.0, n_random=10).table


AUX_SIM = ("paper-mr-cycle-4dpm", 13, 2400.0, {"turn_on": {"amp_dph": 3.0, "tau_s": 300.0}})
AUX_SIM16_N = 1200          # samples of the 16-term simulated case (the first 20 minutes: the turn-on)

# the hand-made table of AUX_MAX_TERMS terms of every kind (case max_terms_every_kind; base_model's proxy
# is freq_hz at 6227 +- 3 Hz, its rate the diff): four aux words, F and T, sum |w| = 0.96
MAX_TERMS_EVERY_KIND = (
    {"gen": "input", "column": "aux_a", "ref": 2.0e-7, "span": 5.0e-8, "weight": 0.08},
    {"gen": "input", "column": "aux_b", "ref": 3.3, "span": 0.05, "tau_s": 12.0, "power": 3, "sign": True,
     "weight": -0.06},
    {"gen": "input", "column": "aux_c", "ref": -150.0, "span": 40.0, "power": 5, "weight": 0.05},
    {"gen": "input", "column": "aux_d", "ref": 2.5e5, "span": 1.0e4, "tau_s": 300.0, "power": 2, "weight": -0.07},
    {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0, "tau_s": 60.0, "weight": 0.07},
    {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0, "tau_s": 240.0, "weight": -0.06},
    {"gen": "input", "column": "freq_hz", "ref": 6227.5, "span": 2.0, "tau_s": 960.0, "power": 2, "weight": 0.05},
    {"gen": "input", "column": "temp_c", "ref": 25.0, "span": 40.0, "tau_s": 16384.0, "weight": 0.06},
    {"gen": "input", "column": "temp_c", "ref": -5.0, "span": 0.5, "tau_s": 0.0625, "sign": True, "weight": -0.05},
    {"gen": "rate", "column": "freq_hz", "estimator": "diff", "span": 0.01, "sign": True, "weight": 0.06},
    {"gen": "one", "sign": True, "weight": -0.04},
    {"gen": "decay_on", "tau_s": 4.0, "weight": 0.08},
    {"gen": "decay_exchange", "tau_s": 6.0, "sign": True, "weight": -0.07},
    {"gen": "ramp", "n_samples": 300, "weight": 0.06},
    {"gen": "osc", "period_s": 7.3, "part": "sin", "weight": 0.05},
    {"gen": "osc", "period_s": 86400.0, "part": "cos", "weight": -0.05},
)


def aux_sim_log():
    """The simulated run of AUX_SIM (host_tools.simulation.sim, warnings silenced)."""
    import warnings as _warnings

    from host_tools.simulation.sim import simulate

    scenario, seed, duration, undeclared = AUX_SIM
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore")
        return simulate(scenario, seed=seed, duration_s=duration, undeclared=undeclared)


def _fitted_sim_case(log, terms, name: str, what: str, n: int | None = None) -> tuple:
    """(the arguments of Cases.add, configuration): the model of ``log`` (fit_config_from_logs, combine_first
    pair, rounded to 7 significant digits) with the aux ``terms`` (a function of the config and the
    temperature range), fitted on the whole log, quantized; the case is its first ``n`` samples (all)."""
    from host_tools.fixed.fixed_point import log_words
    from host_tools.golden import compensate as hc
    from host_tools.fitting.fit import fit_logs
    from host_tools.golden.model import BiasModel, ModelConfig
    from host_tools.golden.proxy import ProxyConfig
    from host_tools.golden.rate import RateConfig
    from host_tools.golden.regressors import AuxConfig
    from host_tools.golden.reversal import ReversalConfig

    scenario, seed, duration, undeclared = AUX_SIM
    cfg0 = hc.fit_config_from_logs([log], reversal=ReversalConfig("pair", order="combine_first"))
    tr = (float(np.min(log["temp_c"])), float(np.max(log["temp_c"])))
    terms = terms(cfg0, tr)
    cfg = ModelConfig(ProxyConfig(cfg0.proxy.kind, round_sig(cfg0.proxy.ref), round_sig(cfg0.proxy.span)),
                      RateConfig(cfg0.rate.estimator, cfg0.rate.n, cfg0.rate.shift, round_sig(cfg0.rate.span),
                                 cfg0.rate.fs), cfg0.reversal, AuxConfig.from_terms(terms, cfg0.rate.fs))
    fitted, _ = fit_logs([log], cfg, tuple(range(17)))
    coef = np.array([round_sig(c) for c in fitted.coef], np.float64)
    model = BiasModel(cfg, fitted.terms, coef, source="<vectors aux sim>")
    table = quantize_aux(model)
    w = log_words(log, cfg)
    n = len(log) if n is None else n
    s = {"p": w["p"][:n], "r": w["r"][:n], "mode": w["mode"][:n], "restart": w["restart"][:n], "z": w["z"][:n],
         "f": w["f"][:n], "t": w["t"][:n], "aux": np.zeros((n, 0), np.int64), "k": w["k"][:n]}
    desc = (f"host_tools.simulation.sim.simulate({scenario!r}, seed={seed}, duration_s={duration:g}, undeclared={undeclared}); "
            f"{what}, fitted, quantized; log-driven" + ("" if n == len(log) else f", the first {n} samples"))
    config = {"scenario": scenario, "seed": seed, "duration_s": repr(duration), "undeclared": undeclared,
              "model": {"config": cfg.to_dict(), "terms": list(model.terms), "coef": list(model.coef)}}
    if n != len(log):
        config["samples"] = n
    return (name, desc, table, s), jsonable_value(config)


def aux_sim_case(log=None) -> tuple:
    """(the arguments of Cases.add, configuration) of the simulated aux run: host_tools.simulation.sim with an
    undeclared turn-on transient, a model with a decay_on, a lagged-proxy and a board-temperature
    term (fixed generator parameters), fitted, rounded to 7 significant digits, quantized."""
    def terms(cfg0, tr):
        return [{"gen": "decay_on", "tau_s": 300.0, "weight": 0.5},
                {"gen": "input", "column": cfg0.proxy.column, "ref": round_sig(cfg0.proxy.ref),
                 "span": round_sig(cfg0.proxy.span), "tau_s": 900.0, "weight": -0.25},
                {"gen": "input", "column": "temp_c", "ref": round_sig(0.5 * (tr[0] + tr[1])),
                 "span": round_sig(0.6 * (tr[1] - tr[0])), "tau_s": 60.0, "weight": 0.25, "sign": True}]

    return _fitted_sim_case(aux_sim_log() if log is None else log, terms, "sim_aux",
                            "aux decay_on + lagged proxy + s x lagged board temperature")


def aux_sim16_case(log=None) -> tuple:
    """As :func:`aux_sim_case` with AUX_MAX_TERMS (16) generator terms on the same run, the first
    AUX_SIM16_N samples: the fitter's lag-state block (the proxy through six filters, 60 .. 1920 s) and
    the closed loop's effects beside it (decays since power-on and since an exchange, two board-temperature
    lags, one with s, the squared temperature, u^4, s, a rate term, a ramp, a slow oscillator)."""
    def terms(cfg0, tr):
        px = {"column": cfg0.proxy.column, "ref": round_sig(cfg0.proxy.ref), "span": round_sig(cfg0.proxy.span)}
        tc = {"column": "temp_c", "ref": round_sig(0.5 * (tr[0] + tr[1])), "span": round_sig(0.6 * (tr[1] - tr[0]))}
        r = cfg0.rate
        lag = [{"gen": "input", **px, "tau_s": tau, "weight": w}
               for tau, w in ((60.0, 0.08), (120.0, -0.07), (240.0, 0.07), (480.0, -0.06), (960.0, 0.06),
                              (1920.0, -0.05))]
        return lag + [{"gen": "decay_on", "tau_s": 300.0, "weight": 0.1},
                      {"gen": "decay_exchange", "tau_s": 8.0, "sign": True, "weight": -0.05},
                      {"gen": "input", **tc, "tau_s": 60.0, "sign": True, "weight": 0.06},
                      {"gen": "input", **tc, "tau_s": 600.0, "weight": -0.05},
                      {"gen": "input", **tc, "tau_s": 120.0, "power": 2, "weight": 0.04},
                      {"gen": "input", **px, "power": 4, "weight": -0.04},
                      {"gen": "one", "sign": True, "weight": 0.03},
                      {"gen": "rate", "column": cfg0.proxy.column, "estimator": r.estimator, "n": r.n,
                       "shift": r.shift, "span": round_sig(4.0 * r.span), "weight": 0.05},
                      {"gen": "ramp", "n_samples": 900, "weight": -0.04},
                      {"gen": "osc", "period_s": 1800.0, "part": "sin", "weight": 0.03}]

    return _fitted_sim_case(aux_sim_log() if log is None else log, terms, "sim_aux_16",
                            f"{F.AUX_MAX_TERMS} aux terms: a lag block of the proxy (6 filters, 60 .. 1920 s), "
                            f"decay_on, s x decay_exchange, board-temperature lags (s x 60 s, 600 s, squared 120 s), "
                            f"u^4, s, a rate term, a ramp, a 1800 s sine", AUX_SIM16_N)
