"""The candidate-effect library of ``hdrg diagnose``: physically motivated regressor families that a
bias model may lack, each computed CAUSALLY from signals the run log has, with its parameters
scanned.

Every candidate is one or two *generator terms* of host_tools.golden.regressors (the k7 generators, module
doc there): the diagnosis scores exactly the column that the model will use as z if the candidate
wins.  Families (the names are the simulator's effect names, host_tools.simulation.sim_params.MISSING_EFFECTS):

===================  =======================================================  ======================
family               regressor (u: the model's normalized proxy, s: mode       scanned
                     sign)
===================  =======================================================  ======================
thermal_lag          lag(u, tau): the proxy through a first-order filter: a   tau_s in TAU_GRID_S
                     heat source that lags the proxy (bias vs proxy
                     hysteresis beyond what the rate terms model)
thermal_lag block    lag(u, tau), lag^2, lag^3 (3 columns, one k7 sum: a        tau_s
                     lagged node with its own polynomial; order=3)
turn_on              decay since power-on exp(-t/tau)                         tau_s in TAU_GRID_S
exchange_transient   decay since the end of the last mode exchange; or s      tau_s in
                     times it together with s (2 columns): a transient that   EXCHANGE_TAUS_S,
                     does not flip leaves s * (decay - its mean over the      sign
                     other window) after the combiner  (mode-reversal logs)
exchange_settling    decay since the end of the last mode exchange, ONE        tau_s <= SETTLING_
                     coefficient for both mode banks (regress_first: in the    TAU_FACTOR x the
                     target s * rate it is the same in both modes, i.e. the    settle window
                     raw output's transient follows the mode sign like the
                     rate): the readout still settling after the window
                     (structure of the mode-reversal pipeline, not an effect)
imperfect_reversal   s, s*u, s*v: terms that follow the mode sign             which
                     (mode-reversal logs)
proxy_high_order     u^4, u^5                                                 power
board_temp           the other temperature column (temp_c when the proxy is   tau_s in 0 + grid
                     freq_hz, and vice versa), normalized, and its lags
aux_<name>           every aux_* column, normalized, and its lags             tau_s in 0 + grid
aux                  every aux_* column at once (one coefficient each, no     columns
                     lag): supply and g sensitivity on every axis, which one
                     column at a time fits with a biased coefficient
aging                time since power-on, t / T; and decay since power-on     tau_s > MAX_TURN_ON_
                     exp(-t/tau), tau beyond a turn-on (the drift             FRACTION x run,
                     A (1 - exp(-t/tau)) up to the constant k0)               <= AGING_MAX_FRACTION
periodic             sin and cos (2 columns) at the periods of the strongest  period_s
                     lines of the residual spectrum
===================  =======================================================  ======================

Ranges: the proxy terms use the model's proxy normalization; another column is normalized to its
training range (min..max over the non-exchange samples of the training logs) widened by 10 % on
each side (so |g| <= 1 with a margin, as the proxy); a column that is constant over the training
data gives no candidate.  The aging ramp is normalized to 1.1 x the longest training run.

Time-constant grids are geometric with ratio 2; :func:`refine` proposes the neighbours at ratio
2^(1/4) (and 2^(1/2)) of a winner, so the final tau is within about 2^(1/8) = 1.09 of the best
point on a fine grid.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from host_tools.golden import runlog as rl
from host_tools.golden.regressors import generator_values

TAU_GRID_S = (15.0, 30.0, 60.0, 120.0, 240.0, 480.0, 960.0, 1920.0, 3840.0, 7680.0)
EXCHANGE_TAUS_S = (2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
RANGE_MARGIN = 0.1
RAMP_MARGIN = 0.1
MAX_TAU_FRACTION = 0.5     # thermal_lag / board_temp / aux lags: tau <= this x the longest training run
LAG_BLOCK_ORDER = 3          # thermal_lag block: lag(u, tau)^1..3, three columns
MAX_TURN_ON_FRACTION = 0.25  # turn_on: tau <= this x the longest training run (it must have decayed)
AGING_MAX_FRACTION = 4.0     # aging: decays with MAX_TURN_ON_FRACTION x run < tau <= this x run (grid ratio 2)
SETTLING_TAU_FACTOR = 2.0    # exchange_settling: tau <= this x the settle window (a longer window would remove it)
FAMILIES = ("thermal_lag", "turn_on", "exchange_transient", "exchange_settling", "imperfect_reversal",
            "proxy_high_order", "board_temp", "aux", "aging", "periodic")


@dataclass
class Candidate:
    """One candidate regressor: ``family`` (the effect name; aux columns 'aux_<name>'), ``params``
    (the scanned parameters, for the report: tau_s, power, which, sign, period_s, column),
    ``terms`` (generator term dicts of host_tools.golden.regressors, weight 1.0 each: 1 column, or 2 for
    periodic), ``scan`` (the name of the continuous parameter :func:`refine` may refine, or ''),
    ``extra`` (scan hints: ``shared`` -- one coefficient for both mode banks of a regress_first
    model; ``max_tau_s`` -- the largest tau refinement may reach; ``line`` -- a spectral line)."""

    family: str
    params: dict
    terms: tuple
    scan: str = ""
    extra: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        inner = ", ".join(f"{k}={_fmt(v)}" for k, v in self.params.items())
        return f"{self.family}({inner})" if inner else self.family

    def columns(self, log, fs: float) -> np.ndarray:
        """The candidate's regressor column(s), float64[len(log), len(terms)]."""
        return np.column_stack([generator_values(log, t, fs) for t in self.terms])


def _fmt(v):
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def effect_term(gen, effect, **params) -> dict:
    return {"gen": gen, "weight": 1.0, "effect": effect, **params}


def training_range(logs, column: str):
    """(ref, span) of ``column`` over the non-exchange samples of ``logs`` widened by RANGE_MARGIN on
    each side, or None if a log lacks it or it is constant / not finite."""
    vals = []
    for log in logs:
        if column not in log:
            return None
        keep = np.asarray(log.mode) != rl.MODE_EXCHANGE
        vals.append(np.asarray(log[column], np.float64)[keep])
    vals = np.concatenate(vals) if vals else np.zeros(0)
    if vals.size == 0 or not np.all(np.isfinite(vals)):
        return None
    lo, hi = float(vals.min()), float(vals.max())
    if not hi > lo:
        return None
    w = RANGE_MARGIN * (hi - lo)
    return 0.5 * (lo + hi), 0.5 * (hi - lo) + w


def _duration_s(logs) -> float:
    return max(float(log.t_s[-1] - log.t_s[0]) for log in logs)


def library(train_logs, config, *, tau_grid=TAU_GRID_S, exchange_taus=EXCHANGE_TAUS_S, periods=(),
            families=None) -> list:
    """The candidates for training logs ``train_logs`` and a ModelConfig ``config`` (its proxy,
    rate estimator, reversal and fs).  ``periods``: the periods [s] to try for 'periodic' (from
    the residual spectrum, see host_tools.fitting.diagnose).  ``families``: restrict to these family
    names (default all; 'aux' selects every aux_* column)."""
    logs = list(train_logs)
    fs = config.rate.fs
    pcol = config.proxy.column
    pref, pspan = config.proxy.ref, config.proxy.span
    reversal = config.reversal is not None
    dur = _duration_s(logs)
    want = set(FAMILIES if families is None else families)
    out = []
    lag_taus = [t for t in tau_grid if t <= MAX_TAU_FRACTION * dur]
    if "thermal_lag" in want:
        for tau in lag_taus:
            out.append(Candidate("thermal_lag", {"tau_s": tau},
                                 (effect_term("input", "thermal_lag", column=pcol, ref=pref, span=pspan, tau_s=tau),),
                                 "tau_s"))
    if "thermal_lag" in want:     # lag-state polynomial block: lag, lag^2, lag^3 (one k7 sum)
        for tau in lag_taus:
            out.append(Candidate("thermal_lag", {"tau_s": tau, "order": LAG_BLOCK_ORDER},
                                 tuple(effect_term("input", "thermal_lag", column=pcol, ref=pref, span=pspan, tau_s=tau,
                                             power=k) for k in range(1, LAG_BLOCK_ORDER + 1)), "tau_s"))
    if "turn_on" in want:
        for tau in (t for t in tau_grid if t <= MAX_TURN_ON_FRACTION * dur):
            out.append(Candidate("turn_on", {"tau_s": tau}, (effect_term("decay_on", "turn_on", tau_s=tau),), "tau_s"))
    if reversal and "exchange_transient" in want:
        for sign in (False, True):
            for tau in exchange_taus:
                terms = (effect_term("decay_exchange", "exchange_transient", tau_s=tau, sign=sign),)
                if sign:   # the combiner leaves s * (transient - its mean over the other window)
                    terms += (effect_term("one", "exchange_transient", sign=True),)
                out.append(Candidate("exchange_transient", {"tau_s": tau, "sign": sign}, terms, "tau_s"))
    settle = config.reversal.settle_s if reversal else 0.0
    if reversal and "exchange_settling" in want and config.reversal.order == "regress_first" and settle > 0:
        for tau in (t for t in exchange_taus if t <= SETTLING_TAU_FACTOR * settle):
            out.append(Candidate("exchange_settling", {"tau_s": tau},
                                 (effect_term("decay_exchange", "exchange_settling", tau_s=tau),), "tau_s",
                                 {"shared": True, "max_tau_s": SETTLING_TAU_FACTOR * settle}))
    if reversal and "imperfect_reversal" in want:
        r = config.rate
        for which, term in (("s", effect_term("one", "imperfect_reversal", sign=True)),
                            ("s*u", effect_term("input", "imperfect_reversal", column=pcol, ref=pref, span=pspan,
                                          sign=True)),
                            ("s*v", effect_term("rate", "imperfect_reversal", column=pcol, estimator=r.estimator,
                                          n=r.n, shift=r.shift, span=r.span, sign=True))):
            out.append(Candidate("imperfect_reversal", {"which": which}, (term,)))
    if "proxy_high_order" in want:
        for power in (4, 5):
            out.append(Candidate("proxy_high_order", {"power": power},
                                 (effect_term("input", "proxy_high_order", column=pcol, ref=pref, span=pspan,
                                        power=power),)))
    columns = []
    if "board_temp" in want:
        other = "temp_c" if pcol == "freq_hz" else "freq_hz"
        columns.append(("board_temp", other))
    for name in logs[0].aux_columns:
        if "aux" in want or name in want:
            columns.append((name, name))
    joint = []
    for family, col in columns:
        rng = training_range(logs, col)
        if rng is None:
            continue
        for tau in (0.0,) + tuple(lag_taus):
            out.append(Candidate(family, {"column": col, "tau_s": tau},
                                 (effect_term("input", family, column=col, ref=rng[0], span=rng[1], tau_s=tau),),
                                 "tau_s"))
        if family != "board_temp" and "aux" in want:
            joint.append(effect_term("input", "aux", column=col, ref=rng[0], span=rng[1], tau_s=0.0))
    if len(joint) >= 2:     # every aux column at once: a sensitivity to supply and to g on every axis
        out.append(Candidate("aux", {"columns": "+".join(t["column"] for t in joint), "tau_s": 0.0}, tuple(joint)))
    if "aging" in want:
        kmax = max(int(np.rint(log.t_s[-1] * fs)) for log in logs)
        n_samples = max(1, int(math.ceil((1.0 + RAMP_MARGIN) * max(kmax, 1))))
        out.append(Candidate("aging", {"n_samples": n_samples},
                             (effect_term("ramp", "aging", n_samples=n_samples),)))
        # a drift that has not settled in the run: exp(-t/tau) beyond every turn-on tau (a decay
        # that does not finish in the run is a drift, one that does is a turn-on transient)
        tau = float(tau_grid[0])
        while tau <= AGING_MAX_FRACTION * dur:
            if tau > MAX_TURN_ON_FRACTION * dur:
                out.append(Candidate("aging", {"tau_s": tau}, (effect_term("decay_on", "aging", tau_s=tau),), "tau_s",
                                     {"max_tau_s": AGING_MAX_FRACTION * dur, "min_tau_s": MAX_TURN_ON_FRACTION * dur}))
            tau *= 2.0
    if "periodic" in want:
        for period in periods:
            out.append(periodic(float(period)))
    return out


def periodic(period_s: float) -> Candidate:
    """The 'periodic' candidate at ``period_s``: a sin and a cos oscillator term."""
    return Candidate("periodic", {"period_s": float(period_s)},
                     (effect_term("osc", "periodic", period_s=float(period_s), part="sin"),
                      effect_term("osc", "periodic", period_s=float(period_s), part="cos")), "period_s")


def with_param(cand: Candidate, name: str, value: float) -> Candidate:
    """A copy of ``cand`` with the scanned parameter ``name`` (tau_s or period_s) set to ``value``."""
    terms = tuple({**t, name: float(value)} if name in t else dict(t) for t in cand.terms)
    return Candidate(cand.family, {**cand.params, name: float(value)}, terms, cand.scan, dict(cand.extra))


def refine(cand: Candidate, ratios=(2 ** -0.5, 2 ** -0.25, 2 ** 0.25, 2 ** 0.5), max_value=None) -> list:
    """Neighbours of ``cand`` on a finer grid of its scanned parameter (ratios applied to the
    current value; a tau of 0 is not refined).  [] when nothing is scanned."""
    if not cand.scan:
        return []
    value = cand.params[cand.scan]
    if not value > 0:
        return []
    out = []
    for r in ratios:
        v = value * r
        if (max_value is not None and v > max_value) or v <= cand.extra.get("min_tau_s", 0.0):
            continue
        out.append(with_param(cand, cand.scan, v))
    return out
