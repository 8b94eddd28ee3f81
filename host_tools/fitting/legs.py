"""What training runs can identify: their chamber legs (the sign of dT/dt) and, per term group,
whether the runs identify it, and leg-respecting cross-validation.

A temperature chamber run is a sequence of *legs*: stretches where the temperature proxy rises,
falls or holds.  Whether a rising proxy means heating or cooling is the proxy's sign convention
(:data:`HEATING_SIGN`): the drive frequency falls as the temperature rises (-20.9 ppm/degC), so a
rising frequency proxy is a cooling leg; a rising temperature sensor is a heating leg.  The rate
terms of the 17-term model (every term
with a power of the normalized rate v: k4..k6, k8..k16) and the lag-state block describe how the
bias depends on dT/dt; fitted on legs of one sign they are applied to the other sign by
extrapolation, so the fit only offers them when the training runs hold legs of both signs.

Leg detection (:func:`find_legs`), per run: the proxy's slope [proxy units/s] is the
least-squares slope of the proxy over a centred time window of ``LEG_WINDOW_S`` (works on
bursty logs with gaps; a window spanning less than a quarter of its length gives no slope).
Samples whose |slope| is below ``HOLD_FRACTION`` x the run's 95th percentile of |slope| are
*holds*; a stretch of one sign shorter than ``MIN_LEG_S`` (or a hold) joins the leg before it
(the first such stretch of a run joins the leg after it).  Every sample of a run belongs to one
leg; a leg's sign is that of its proxy change from its first to its last sample.

Term groups (:func:`identifiability`): ``proxy`` (k1..k3: the proxy range the training runs
cover against the range the model will meet), ``rate`` (k4..k6, k8..k16 and the lag block:
both signs of dT/dt, each on at least ``MIN_SIGN_SHARE`` of the samples; with fewer than
``CV_LEGS_PER_SIGN`` legs of a sign, a leg held out by the cross-validation leaves no leg of its
sign to train on, so the rate terms are fitted on one sign and scored on the other in that
fold; with one leg of each sign that is every fold: ``rate_cv_extrapolated`` is then True and
the fit asks more of them, see host_tools.fitting.fit_pipeline.fit_default),
``rate_curvature``
(the powers v^2, v^3: more than one chamber rate, the 75th/25th percentile of |slope| on the
moving samples >= ``MIN_RATE_RATIO``; reported only).  Each group not identified comes with
the chamber run that would identify it.
"""
from __future__ import annotations

import math

import numpy as np

LEG_WINDOW_S = 600.0     # centred window of the slope that decides a leg's sign [s]
HOLD_FRACTION = 0.1      # |slope| below this x the run's 95th percentile of |slope|: a hold
MIN_LEG_S = 300.0        # shorter stretches of one sign join the leg before them [s]
MIN_SIGN_SHARE = 0.15    # each sign of dT/dt on at least this share of the samples identifies the rate terms
CV_LEGS_PER_SIGN = 2     # fewer legs of a sign: a leg held out leaves none of its sign (see "extrapolated")
MIN_RATE_RATIO = 1.5     # p75 / p25 of |dT/dt| on the moving samples: more than one chamber rate
MIN_PROXY_SHARE = 0.5    # training proxy range below this share of the model's range: warned

HEATING_SIGN = {"freq": -1, "temp": 1}   # sign of the proxy's change when the device heats

RATE_TERMS = (4, 5, 6, 8, 9, 10, 11, 12, 13, 14, 15, 16)   # every term with a power of v
PROXY_TERMS = (0, 1, 2, 3)                                 # k0 and the cubic in u


def window_slope(t_s, p, window_s: float = LEG_WINDOW_S) -> np.ndarray:
    """Least-squares slope of p [proxy units] against t_s [s] over the samples within
    +-window_s/2 of each sample, float64[n] [proxy units/s]; NaN where the window's samples span
    less than window_s/4 (start and end of a short run, or an isolated burst)."""
    t = np.asarray(t_s, np.float64)
    p = np.asarray(p, np.float64)
    n = len(t)
    if n < 2:
        return np.full(n, np.nan)
    tc = t - t[0]
    c = [np.concatenate([[0.0], np.cumsum(x)]) for x in (np.ones(n), tc, p, tc * tc, tc * p)]
    lo = np.searchsorted(tc, tc - window_s / 2, side="left")
    hi = np.searchsorted(tc, tc + window_s / 2, side="right")
    s0, s1, sp, s11, s1p = (x[hi] - x[lo] for x in c)
    den = s0 * s11 - s1 * s1
    span = tc[hi - 1] - tc[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (s0 * s1p - s1 * sp) / den
    out[(span < window_s / 4) | ~(den > 0)] = np.nan
    return out


def find_legs(t_s, p, window_s: float = LEG_WINDOW_S, min_leg_s: float = MIN_LEG_S, slope=None) -> list:
    """Legs of one run: a list of (start, stop, sign) sample index ranges [start, stop) covering
    every sample in order, sign +1 (proxy rising), -1 (falling) or 0 (no change).  ``slope``: the
    run's :func:`window_slope` when the caller has it already."""
    t = np.asarray(t_s, np.float64)
    p = np.asarray(p, np.float64)
    n = len(t)
    if n == 0:
        return []
    slope = window_slope(t, p, window_s) if slope is None else slope
    finite = np.isfinite(slope)
    if not finite.any():
        return [(0, n, _sign(p[-1] - p[0]))]
    scale = float(np.percentile(np.abs(slope[finite]), 95))
    sign = np.where(finite & (np.abs(slope) > HOLD_FRACTION * scale), np.sign(slope), 0).astype(int)
    # stretches of equal sign
    edges = np.flatnonzero(np.diff(sign)) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [n]])
    legs = []
    for a, b in zip(starts, stops):
        s = int(sign[a])
        short = t[b - 1] - t[a] < min_leg_s
        if legs and (s == 0 or short or s == legs[-1][2]):
            legs[-1][1] = b                      # join the leg before
        elif not legs and (s == 0 or short):
            legs.append([a, b, 0])               # provisional: takes the sign of what follows
        else:
            if legs and legs[-1][2] == 0:
                legs[-1][1], legs[-1][2] = b, s  # the run's first stretch joins this leg
            else:
                legs.append([a, b, s])
    return [(int(a), int(b), _sign(p[b - 1] - p[a]) if s == 0 else s) for a, b, s in legs]


def _sign(x) -> int:
    return int(np.sign(x)) if np.isfinite(x) else 0


def proxy_kind_of(logs, kind: str | None = None) -> str:
    """The proxy kind ('freq' or 'temp') ``logs`` use for ``kind`` None (freq_hz when logged)."""
    if kind is not None:
        return kind
    return "freq" if logs and all("freq_hz" in log for log in logs) else "temp"


def temperature_change(proxy_sign: int, kind: str) -> str:
    """'heating', 'cooling' or 'hold' for a leg whose proxy changes with ``proxy_sign`` (+1, -1, 0)."""
    if proxy_sign == 0:
        return "hold"
    return "heating" if proxy_sign == HEATING_SIGN[kind] else "cooling"


def leg_ids(logs, proxy_kind: str | None = None) -> list:
    """Per log, int64[n]: the leg index of each sample, numbered over all logs in order
    (log 0's legs first); and the list of (log index, start, stop, sign) of every leg."""
    ids, table = [], []
    for i, log in enumerate(logs):
        _, p = log.proxy(proxy_kind)
        lid = np.zeros(len(log), np.int64)
        for a, b, s in find_legs(log.t_s, p):
            lid[a:b] = len(table)
            table.append((i, a, b, s))
        ids.append(lid)
    return ids, table


def identifiability(logs, config=None) -> dict:
    """Per term group, whether ``logs`` (training RunLogs) identify it, and what run would.

    ``config``: the ModelConfig the model will use (its proxy range is the range the model will
    meet), or None (the logs' own proxy).  Returns {"legs": [{"run", "sign" (of the proxy's
    change), "temperature" ('heating', 'cooling', 'hold'), "t0_s", "t1_s", "proxy": [first,
    last]}], "legs_per_sign" (rising / falling / hold proxy), "legs_per_temperature" (heating /
    cooling / hold), "proxy" (the kind), "proxy_rises_when" ('cooling' for the drive frequency),
    "groups": {"proxy" | "rate" | "rate_curvature": {"identified": bool, "why": str, "record":
    str (empty when identified or when another group's record comes first)}},
    "rate_terms_identified": bool}.  Legs are named by the sign of the temperature change
    (:data:`HEATING_SIGN`), not by the proxy's."""
    kind = None if config is None else config.proxy.kind
    resolved = proxy_kind_of(logs, kind)
    heat = HEATING_SIGN[resolved]
    n_sign = {1: 0, -1: 0, 0: 0}
    n_legs = {1: 0, -1: 0, 0: 0}
    slopes, lo, hi = [], math.inf, -math.inf
    legs = []
    for log in logs:
        _, p = log.proxy(kind)
        slope = window_slope(log.t_s, p)
        for a, b, s in find_legs(log.t_s, p, slope=slope):
            n_sign[s] += b - a
            n_legs[s] += 1
            legs.append({"run": log.source, "sign": {1: "rising", -1: "falling", 0: "hold"}[s],
                         "temperature": temperature_change(s, resolved),
                         "t0_s": float(log.t_s[a]), "t1_s": float(log.t_s[b - 1]),
                         "proxy": [float(p[a]), float(p[b - 1])]})
        lo, hi = min(lo, float(np.min(p))), max(hi, float(np.max(p)))
        sl = np.abs(slope[np.isfinite(slope)])
        if sl.size:
            slopes.append(sl[sl > HOLD_FRACTION * np.percentile(sl, 95)])
    total = sum(n_sign.values()) or 1
    share_up, share_down = n_sign[1] / total, n_sign[-1] / total
    rate_ok = share_up >= MIN_SIGN_SHARE and share_down >= MIN_SIGN_SHARE   # so a leg of each sign
    share = {"heating": n_sign[heat] / total, "cooling": n_sign[-heat] / total}
    seen = (f"{n_legs[heat]} heating leg(s) on {100 * share['heating']:.0f} % and {n_legs[-heat]} cooling leg(s) "
            f"on {100 * share['cooling']:.0f} % of the samples")
    if rate_ok:
        rate = {"identified": True, "record": "", "why": f"both signs of dT/dt: {seen}"}
    else:
        short = [name for name in ("heating", "cooling") if share[name] < MIN_SIGN_SHARE]
        rate = {"identified": False,
                "why": f"{seen} (needs >= {100 * MIN_SIGN_SHARE:.0f} % of the samples "
                       f"of each sign): the rate terms and the lag block are left out",
                "record": f"{' and '.join(short)} legs over the same temperature range (e.g. two full chamber cycles)"}
    moving = np.concatenate(slopes) if slopes else np.zeros(0)
    if moving.size >= 10 and np.percentile(moving, 25) > 0:
        ratio = float(np.percentile(moving, 75) / np.percentile(moving, 25))
    else:
        ratio = 1.0
    curv_ok = rate_ok and ratio >= MIN_RATE_RATIO
    if not rate_ok:
        curvature = {"identified": False, "record": "", "why": "needs the rate terms first"}
    else:
        curvature = {"identified": curv_ok, "record": "" if curv_ok else "a second run at another chamber rate (e.g. half or twice the rate)",
                     "why": f"|dT/dt| p75/p25 = {ratio:.2f} on the moving samples (more than one chamber rate: >= {MIN_RATE_RATIO:g})"}
    proxy = {"identified": True, "record": "", "why": f"training proxy range [{lo:.6g}, {hi:.6g}]"}
    if config is not None:
        share = (hi - lo) / (2.0 * config.proxy.span) if config.proxy.span > 0 else 1.0
        proxy["why"] += f", {100 * share:.0f} % of the model's range"
        if share < MIN_PROXY_SHARE:
            proxy.update(identified=False, record="a run over the whole temperature range the gyro will meet")
    # one leg of each sign: every leave-one-leg-out fold trains on one sign and scores the other
    extrapolated = rate_ok and max(n_legs[1], n_legs[-1]) < CV_LEGS_PER_SIGN
    if rate_ok and min(n_legs[1], n_legs[-1]) < CV_LEGS_PER_SIGN:
        rate["why"] += ("; the cross-validation scores them on a sign they were not fitted on when it holds out the "
                        "single leg of a sign" + (" (every fold)" if extrapolated else ""))
        rate["record"] = "another full chamber cycle (two legs of each sign let the cross-validation check the rate terms)"
    return {"legs": legs, "rate_cv_extrapolated": extrapolated, "legs_per_sign": {"rising": n_legs[1], "falling": n_legs[-1], "hold": n_legs[0]},
            "legs_per_temperature": {"heating": n_legs[heat], "cooling": n_legs[-heat], "hold": n_legs[0]},
            "proxy": resolved, "proxy_rises_when": temperature_change(1, resolved),
            "groups": {"proxy": proxy, "rate": rate, "rate_curvature": curvature},
            "rate_terms_identified": rate_ok}


def block_ids(logs, n_blocks: int) -> tuple:
    """As :func:`leg_ids`, with each log cut into ``n_blocks`` contiguous time blocks instead of
    its legs (sign 0): the folds of a cross-validation on a single leg."""
    ids, table = [], []
    for i, log in enumerate(logs):
        n = len(log)
        edges = np.linspace(0, n, min(n_blocks, n) + 1).astype(int)
        lid = np.zeros(n, np.int64)
        for a, b in zip(edges[:-1], edges[1:]):
            if b > a:
                lid[a:b] = len(table)
                table.append((i, int(a), int(b), 0))
        ids.append(lid)
    return ids, table


def leg_cv(logs, candidates, proxy_kind: str | None = None, folds=None) -> dict | None:
    """Leave-one-leg-out cross-validation of fixed term sets, all scored on the same samples.

    ``candidates``: {label: (ModelConfig, terms)}.  The folds are the legs of the training runs
    (:func:`leg_ids` of ``proxy_kind``); fold f trains on every other leg and is scored on its
    samples that every candidate uses and whose proxy lies inside the other legs' proxy range
    (a held-out leg beyond that range would score the polynomials' extrapolation, which the chip
    never does beyond its clamp and which rejects every term when legs cover different ranges;
    such samples are counted, not scored).  The held-out leg's mean residual is scored too: a
    rate effect (hysteresis between heating and cooling) is mostly a per-leg offset.  Returns None with fewer than 2 legs holding scored samples; else
    {"folds", "scored" (samples), "out_of_range" (samples), "cv_rms": {label: deg/h}, "cv_std":
    {label: deg/h, each held-out leg's (and bank's) own mean residual left out: its std}}.
    ``folds``: other folds in the form of :func:`leg_ids` (e.g. :func:`block_ids`)."""
    from host_tools.fitting.fit import Accumulator, heldout_errors
    from host_tools.golden.compensate import prepare

    ids, table = leg_ids(logs, proxy_kind) if folds is None else folds
    if len(table) < 2:
        return None
    preps, done = {}, []
    for label, (cfg, _) in candidates.items():     # candidates sharing one config share its preparation
        same = [lb for lb, c in done if c is cfg]
        preps[label] = preps[same[0]] if same else [prepare(log, cfg) for log in logs]
        done.append((label, cfg))
    used = [np.logical_and.reduce([preps[lb][i].used for lb in candidates]) for i in range(len(logs))]
    p = [np.asarray(log.proxy(proxy_kind)[1], np.float64) for log in logs]
    rng = []
    for i, a, b, _ in table:
        m = used[i][a:b]
        rng.append((float(np.min(p[i][a:b][m])), float(np.max(p[i][a:b][m]))) if m.any() else None)
    live = [f for f, r in enumerate(rng) if r is not None]
    if len(live) < 2:
        return None
    scored_masks = {}
    n_out = 0
    for f in live:
        i, a, b, _ = table[f]
        lo = min(rng[g][0] for g in live if g != f)
        hi = max(rng[g][1] for g in live if g != f)
        inside = np.zeros(len(p[i]), bool)
        inside[a:b] = used[i][a:b] & (p[i][a:b] >= lo) & (p[i][a:b] <= hi)
        n_out += int(np.count_nonzero(used[i][a:b])) - int(np.count_nonzero(inside))
        scored_masks[f] = inside
    out = {"folds": len(live), "scored": int(sum(np.count_nonzero(m) for m in scored_masks.values())),
           "out_of_range": n_out, "cv_rms": {}, "cv_std": {}}
    for label, (cfg, terms) in candidates.items():
        two = cfg.reversal is not None and cfg.reversal.order == "regress_first"
        banks = (1, 2) if two else (None,)
        leg_acc, test_acc = {}, {}
        for f in live:
            i, a, b, _ = table[f]
            pr = preps[label][i]
            leg = np.zeros(len(pr.y), bool)
            leg[a:b] = used[i][a:b]
            for bk in banks:
                sel = leg if bk is None else leg & (pr.mode == bk)
                leg_acc[f, bk] = Accumulator().add(pr.u, pr.v, pr.z, pr.y, sel)
                tsel = scored_masks[f] if bk is None else scored_masks[f] & (pr.mode == bk)
                test_acc[f, bk] = Accumulator().add(pr.u, pr.v, pr.z, pr.y, tsel)
        total = {bk: sum(leg_acc[f, bk] for f in live) for bk in banks}
        sse = free = sw = 0.0
        for f in live:
            for bk in banks:
                e, e_free = heldout_errors(total[bk] - leg_acc[f, bk], test_acc[f, bk], terms)
                sse, free, sw = sse + e, free + e_free, sw + test_acc[f, bk].sum_w
        out["cv_rms"][label] = math.sqrt(sse / sw) if sw > 0 else math.nan
        out["cv_std"][label] = math.sqrt(free / sw) if sw > 0 else math.nan
    return out
