"""The ``validity`` set's case generator: the input-invalid bit (FORMATS.md "The input-invalid
bit") through the whole pipeline.  The columns are the ``aux`` set's (F T R MODE RESTART Z K A0..A3);
RESTART carries the bit as its bit 1 (``RESTART = restart + 2 invalid``, the protocol's S request).
The cases of aux_gen 0 tables send K = 0, 1, 2, ... and A0..A3 = 0 (read by no generator).

Cases: a flagged sample in the middle of a mode-1 window and of a mode-2 window, at a window's
first and last sample, in the settling part, in an exchange, a burst of flagged samples, two
tainted windows in a row (the other mode pairs with an older clean window until the staleness
limit), flagged samples at a restart and just before one; combine_first pair and trend,
regress_first pair, trend and none; the rate estimators diff, diffn, lsq and iir (the estimator
restarts at a flagged sample and the one after it); an FTR table; a self-timed table; a random
stream with 3 % flagged samples; aux generator tables (aux_gen 1) whose input filters hold their
state over a flagged sample (the proxy lagged, the T word, an aux word, an unfiltered input), an
aux rate term that re-warms with the estimator (diff, iir), a decay, flagged samples at
power-on and at restarts (the filters re-initialize at the next clean sample).
"""
from __future__ import annotations

import numpy as np

from firmware_ref import formats as F
from host_tools.vectors.spec import AUX_FIELDS, AUX_INPUTS
from host_tools.vectors.files import VectorSet
from host_tools.vectors.evaluator import qtable
from host_tools.vectors.pipeline import Cases, compute_pipeline
from host_tools.vectors.sequencer import _ramp

# a log-driven schedule: exchange 3, windows of 12 (settle 2 in the tables below)
_MODES = ([3] * 3 + [1] * 12 + [3] * 3 + [2] * 12) * 6 + [3] * 3 + [1] * 12


def _stream(table, rng, invalid_rows, modes=_MODES, restarts=()) -> dict:
    """The _ramp stream of ``table`` on ``modes`` with the invalid bit at ``invalid_rows`` and
    restarts at ``restarts`` (RESTART = restart + 2 invalid)."""
    s = _ramp(table, len(modes), rng)
    s["mode"] = np.array(modes, np.int64)
    rs = np.zeros(len(modes), np.int64)
    rs[list(restarts)] = 1
    rs[list(invalid_rows)] += 2
    s["restart"] = rs
    return s


# rows of _MODES: window k of mode 1 starts at 3 + 30 k, of mode 2 at 18 + 30 k (12 samples each)
_EDGES = [3 + 30 * 1, 14 + 30 * 1, 18 + 30 * 2 + 1, 29 + 30 * 2, 16 + 30 * 3, 3 + 30 * 4 + 6, 18 + 30 * 4 + 5,
          18 + 30 * 5 + 7]
_BURST = list(range(3 + 30 * 2 + 4, 3 + 30 * 2 + 9))


def _no_aux(table, s) -> dict:
    """``s`` with the aux set's columns for an aux_gen 0 table: F and T (the proxy word in its own
    channel, 0 in the other), K = 0, 1, 2, ... and no aux word."""
    n = len(s["p"])
    zero = np.zeros(n, np.int64)
    p = np.asarray(s["p"], np.int64)
    s["f"], s["t"] = (p, zero) if table.proxy_kind == 0 else (zero, p)
    s["k"] = np.arange(n, dtype=np.int64)
    s["aux"] = np.zeros((n, 0), np.int64)
    return s


# the aux cases (240 samples; the channel words step every 40: +1.2 spans, a ramp, -1.2 spans, a
# random walk, ...): flagged rows at power-on, in the ramp, before a restart, a flagged restart (70)
# followed by a flagged sample, a burst in the walk, a flagged restart alone (140), a sample before
# a restart (214); the channel words of a flagged sample are glitched (5 spans off the term's
# centre, clipped to the word)
_AUX_N = 240
_AUX_INVALID = [0, 1, 50, 51, 69, 70, 71, 125, 126, 127, 128, 129, 140, 214, 230]
_AUX_RESTARTS = [70, 140, 215]


def _aux_cases(cs, rng) -> None:
    """The aux_gen 1 cases (module doc)."""
    from host_tools.vectors.aux import _aux_steps, quantize_aux
    from host_tools.vectors.builders import make_model, with_aux

    lag = [{"gen": "input", "column": "freq_hz", "ref": 6227.5, "span": 2.0, "tau_s": 37.0, "power": 2,
            "weight": 0.2},
           {"gen": "input", "column": "temp_c", "ref": 25.0, "span": 40.0, "tau_s": 5.0, "weight": 0.15},
           {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.05, "tau_s": 12.0, "sign": True,
            "weight": 0.15},
           {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0, "weight": 0.1},
           {"gen": "decay_on", "tau_s": 50.0, "weight": 0.2}]
    for name, est, order, terms in (
            ("aux_filters_diff", "diff", "combine_first",
             lag + [{"gen": "rate", "column": "freq_hz", "estimator": "diff", "span": 0.01, "sign": True,
                     "weight": 0.2}]),
            ("aux_rate_iir", "iir", "regress_first",
             lag[:1] + [{"gen": "rate", "column": "freq_hz", "estimator": "iir", "shift": 3, "span": 0.003,
                         "weight": 0.5, "sign": True}])):
        model = make_model(estimator=est, shift=3, rate_span=0.003, settle_s=2.0, max_stale_s=40.0, order=order)
        t = quantize_aux(with_aux(model, terms))
        s = _aux_steps(t, _AUX_N, rng, step_every=40)
        chans = {0: s["f"], 1: s["t"], **{2 + c: s["aux"][:, c] for c in range(s["aux"].shape[1])}}
        sgn = np.where(np.arange(len(_AUX_INVALID)) % 2 == 0, 5.0, -5.0)
        for tm in t.aux().terms:
            if tm.kind == 0:                           # an input term: glitch its channel
                lo, hi = (0, F.UINT32_MAX) if tm.src == 0 else (-F.INT32_SYM, F.INT32_SYM)
                span = (2.0 ** 30) * 2.0 ** tm.c[3] / tm.c[1]
                chans[tm.src][_AUX_INVALID] = np.clip(np.round(tm.c[0] + sgn * span), lo, hi).astype(np.int64)
        s["p"] = chans[t.proxy_kind]
        rs = np.zeros(_AUX_N, np.int64)
        rs[_AUX_RESTARTS] = 1
        rs[_AUX_INVALID] += 2
        s["restart"] = rs
        cs.add(name, f"{order}, {est}, aux_gen 1 ({len(terms)} terms: input filters on F, T, A0, an unfiltered "
               f"input, decay_on, a rate term): flagged samples at power-on, in windows, a burst, at restarts; "
               f"the filters hold their state, the rate term re-warms", t, s)


def validity_set(rng) -> VectorSet:
    from host_tools.vectors.builders import random_stream

    base = Cases()

    class _Cases:                      # the aux set's columns for every case
        @staticmethod
        def add(name, desc, table, s, self_timed=False):
            base.add(name, desc, table, _no_aux(table, s), self_timed)

    cs = _Cases()
    for comb, order in (("pair", "combine_first"), ("trend", "combine_first"), ("pair", "regress_first"),
                        ("trend", "regress_first"), ("none", "regress_first")):
        t = qtable("diff", comb, order=order, settle_s=2.0, max_stale_s=40.0)
        cs.add(f"{order}_{comb}_edges", f"{order} {comb}, diff: flagged samples in a mode-1 and a mode-2 window "
               "(middle, first, last, settling), in an exchange, in consecutive windows", t,
               _stream(t, rng, _EDGES, _MODES[:180]))
        cs.add(f"{order}_{comb}_burst", f"{order} {comb}, diff: a burst of 5 flagged samples in a mode-1 window", t,
               _stream(t, rng, _BURST, _MODES[:120]))
    for est, n in (("diffn", 4), ("lsq", 5), ("iir", 2)):
        t = qtable(est, "pair", n=n, shift=3, settle_s=2.0, max_stale_s=40.0)
        cs.add(f"rate_{est}", f"combine_first pair, {est}: the estimator restarts at a flagged sample and the one "
               "after it (warm-up again)", t, _stream(t, rng, _EDGES + _BURST, _MODES[:180]))
    t = qtable("diff", "pair", settle_s=2.0, max_stale_s=80.0)
    cs.add("older_window", "pair, max_stale 80: a tainted mode-1 window; mode 2 pairs with the older clean one "
           "until it is too old", t, _stream(t, rng, [3 + 30 * 2 + 5, 3 + 30 * 3 + 5]))
    cs.add("restart_edges", "pair: flagged samples at a restart, just before one and right after one", t,
           _stream(t, rng, [63, 64, 100, 101, 150], restarts=(0, 64, 101, 149)))
    t = qtable("diff", None)
    s = _ramp(t, 60, rng)
    s["restart"] = np.zeros(60, np.int64)
    s["restart"][[5, 6, 20, 40]] = 2
    s["restart"][40] += 1
    cs.add("ftr", "FTR table: flagged samples not valid, the estimator re-warms", t, s)
    t = qtable("diffn", "trend", n=3, settle_s=1.0, power_on_s=3.0, exchange_s=2.0, dwell_s=6.0, max_stale_s=30.0)
    s = _ramp(t, 150, rng)
    s["restart"] = np.zeros(150, np.int64)
    s["restart"][[9, 30, 31, 77, 120]] = 2
    cs.add("self_timed", "self-timed trend, diffn n=3: flagged samples in windows and exchanges", t, s, True)
    t = qtable("lsq", "pair", n=4, order="regress_first", settle_s=1.0, max_stale_s=30.0)
    s = random_stream(rng, t, 200)
    s["restart"] = np.asarray(s["restart"], np.int64) + 2 * (rng.random(200) < 0.03)
    cs.add("random", "regress_first pair, lsq n=4: random_stream with 3 % flagged samples", t, s)
    _aux_cases(base, rng)
    vs = VectorSet("validity", "the input-invalid bit through the whole pipeline: the aux set's columns, "
                   "RESTART = restart + 2 x the input-invalid bit", base.columns(), AUX_INPUTS, AUX_FIELDS,
                   base.cases, base.tables)
    compute_pipeline(vs, rows=False)
    return vs
