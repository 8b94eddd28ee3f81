"""The lag-state block of the default fit: a thermal node that lags the proxy
differently from what one proxy u and its rate v can represent, modelled as a low-order polynomial
of the proxy, or of the temperature sensor, through first-order filters, carried to the firmware
as the k7 auxiliary regressor.

Regressors (host_tools.golden.regressors, generator ``input`` on the model's proxy column with the model's
proxy normalization, so ``q = u``): ``g_{tau,k} = lag(u, tau)^k``, k = 1..order, the first-order
low-pass of u with time constant tau [s] restarted at every segment start (exactly the firmware's
aux kind ``input`` with filter SB and power k, firmware_ref/aux.py).  **Sensor blocks** (LAG_SENSOR,
when the proxy is the resonator frequency and the logs have ``temp_c``): the same on the
temperature sensor, ``lag(T, tau)^k`` with T = (temp_c - ref) / span normalized over the training
range (:func:`sensor_source`), tau in SENSOR_TAUS_S (0 = the sensor itself).  The sensor sits on
another thermal node than the resonator: a second observation of the temperature field.

Choice (:func:`add_lag_block`), on the training runs only:

1. **Screen** every candidate of :func:`candidates` (one tau with order 2 or 3, of the proxy or the
   sensor; for FTR also two taus with order 3 each) by cross-validated squared error of the
   least-squares fit of the base model's polynomial terms + the candidate's lag columns, per
   coefficient bank (regress_first: mode 1 / mode 2), over the same groups as
   host_tools.fitting.fit.fit_logs (time blocks of one run, or runs).  All candidates share one
   pass of Gram matrices per (bank, group) (X'X of [poly | every lag power | y]), accumulated
   over blocks of at most SCREEN_CHUNK samples: memory flat in the number of samples; a
   candidate's fold solve is on the sub-Gram of its columns (training = total - fold).
2. **Pack** each of the LAG_REFIT_TOP candidates of least screen rms into ONE k7 sum: per bank b
   the lag coefficients a_b (deg/h) of the full training fit; FTR: ``z = sum_k a_k g_k / T``;
   regress_first: ``z = sum_k (P_k g_k + Q_k s g_k) / T`` with P = (a_1 + a_2) / 2, Q = (a_1 -
   a_2) / 2 (``sign`` terms: s = +1 on mode 1, -1 on mode 2, so z is a_b . g / T on bank b), T =
   sum |weights| (so sum |w| = 1 and |z| <= 1; zero weights are left out), and refit the model with
   host_tools.fitting.fit.fit_logs (same terms, so 'auto' may keep or drop k7; each bank fits its
   own k7 ~ T).
   Only candidates whose screen rms beats the base screen by LAG_SCREEN_GATE are refitted (FTR
   0.2; mode reversal: no gate; the screen fits the base's terms without re-selecting them and can
   rank a candidate whose refit is far better below the base).
3. **Keep** the refit of least cross-validated rms only when it beats the base model by
   LAG_MARGIN (relative; FTR 0.2, mode reversal 0.1); else the base model is returned unchanged.
   (Before: one refit, screen gate and margin 0.2 for both; docs/ACCURACY.md "Rate and lag
   selection".)  The model's fit
   info holds ``lag_block``: {"chosen": label or None, "base_cv_rms", "cv_rms", "candidates":
   [{label, screen_cv_rms, refit_cv_rms if refitted}]} (model.json).

Size: at most 6 terms in the k7 sum (one tau for mode reversal, 3 powers x (P, Q); at most two taus
of order 3 for FTR), of the chip's AUX_MAX_TERMS (16, firmware_ref.formats): the rest is room for
the power-on term and the closed loop's own generators (host_tools.fitting.diagnose).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numba as nb
import numpy as np

from firmware_ref.formats import AUX_MAX_TERMS
from firmware_ref.terms import K_AUX
from host_tools.golden.regressors import AuxConfig, normalize_term, normalized_input, regressor_matrix

LAG_TAUS_S = (60.0, 120.0, 240.0, 480.0, 960.0, 1920.0)   # screened time constants [s]
LAG_ORDERS = (2, 3)           # polynomial orders of a single-tau block
# per kind of log ("ftr", "mr"); chosen on foreign devices of set 1 and, for FTR, the measured logs
# (docs/ACCURACY.md "Rate and lag selection"):
LAG_MARGIN = {"ftr": 0.2, "mr": 0.1}          # required relative reduction of the refit's cross-validated rms
LAG_SCREEN_GATE = {"ftr": 0.2, "mr": None}    # a refitted candidate's screen rms must beat the base screen by this (None: no gate)
MAX_TAU_FRACTION = 0.5        # tau <= this x the longest training run (as host_tools.fitting.effects)
LAG_PAIRS_FTR = True          # FTR: also two-tau blocks (order 3 each)
LAG_PAIRS_MR = False          # mode reversal: also two-tau blocks of orders (1, 1), (2, 1), (1, 2) (6 terms at most)
LAG_REFIT_TOP = 2             # refit this many candidates of least screen CV rms; keep the best refit
LAG_SENSOR = True             # also blocks of the temperature sensor (temp_c) when the proxy is the frequency
SENSOR_TAUS_S = (0.0,) + LAG_TAUS_S   # sensor time constants [s] (0: the sensor itself, no filter)
SENSOR_COLUMN = "temp_c"
SENSOR_MARGIN = 0.1           # sensor normalization: training range widened by this x its width on each side
_RIDGE = 1e-10                # relative diagonal load of the scaled screen solves (collinear lags)
SCREEN_CHUNK = 1 << 16        # samples per block of the screen's Gram accumulation (memory ~ this x 60 x 8 B)


def lag_term(config, tau_s: float, power: int, weight: float = 1.0, sign: bool = False, sensor=None) -> dict:
    """Generator term lag(u, tau_s)^power of the model's proxy (host_tools.golden.regressors 'input');
    with ``sensor`` = (column, ref, span): of that column normalized as (x - ref) / span instead."""
    p = config.proxy
    column, ref, span = (p.column, p.ref, p.span) if sensor is None else sensor
    return {"gen": "input", "column": column, "ref": float(ref), "span": float(span),
            "tau_s": float(tau_s), "power": int(power), "weight": float(weight), "sign": bool(sign),
            "effect": "thermal_lag"}


def sensor_source(logs, config):
    """(column, ref, span) of the temperature sensor for sensor blocks, or None: LAG_SENSOR off, the
    proxy is the sensor itself, a log lacks the column, has a non-finite value in it, or it does
    not vary.  ref/span: the training
    range widened by SENSOR_MARGIN on each side (degC)."""
    if not LAG_SENSOR or config.proxy.column == SENSOR_COLUMN:
        return None
    if not all(SENSOR_COLUMN in log.columns for log in logs):
        return None
    x = np.concatenate([np.asarray(log.columns[SENSOR_COLUMN], np.float64) for log in logs])
    if not x.size or not np.isfinite(x).all() or not x.max() > x.min():
        return None
    lo, hi = float(x.min()), float(x.max())
    w = SENSOR_MARGIN * (hi - lo)
    return (SENSOR_COLUMN, 0.5 * (lo + hi), 0.5 * (hi - lo) + w)


def candidates(duration_s: float, reversal: bool, taus=LAG_TAUS_S, orders=LAG_ORDERS, pairs=None,
               sensor_taus=()) -> list:
    """Candidate blocks: tuples of elements (tau_s, order) (the proxy) or (tau_s, order, 'sensor');
    taus longer than MAX_TAU_FRACTION x the run dropped.  ``sensor_taus``: taus of sensor blocks
    (empty: none)."""
    keep = lambda ts: [t for t in ts if t <= MAX_TAU_FRACTION * duration_s]   # noqa: E731
    src = [(t,) for t in keep(taus)] + [(t, "sensor") for t in keep(sensor_taus)]
    el = lambda s, k: (s[0], k) + s[1:]   # noqa: E731
    out = [(el(s, k),) for s in src for k in orders]
    if not reversal and (LAG_PAIRS_FTR if pairs is None else pairs):
        out += [(el(s1, 3), el(s2, 3)) for i, s1 in enumerate(src) for s2 in src[i + 1:]]
    if reversal and (LAG_PAIRS_MR if pairs is None else pairs):
        out += [(el(s1, k1), el(s2, k2)) for i, s1 in enumerate(src) for s2 in src[i + 1:]
                for k1, k2 in ((1, 1), (2, 1), (1, 2))]
    return out


def _key(el):
    """(source, tau) of a candidate element: source '' (the proxy) or 'sensor'."""
    return (el[2] if len(el) > 2 else "", el[0])


def _label(cand) -> str:
    return " + ".join(f"lag({'T' if len(e) > 2 else 'u'}, {e[0]:g} s)^1..{e[1]}" for e in cand)


def _groups(pr, n_logs, cv_blocks, log_index):
    from host_tools.fitting.fit import block_groups
    if n_logs == 1:
        return block_groups(len(pr.y), cv_blocks)
    return np.full(len(pr.y), log_index, np.int64)


@nb.njit(cache=True, nogil=True)
def _lag_powers(q, seg, b, state, out):
    """The first-order lag y of the normalized input q (host_tools.golden.regressors.lowpass, the
    same operations: y = q at segment starts (``seg`` True), else y += b (q - y), b = 1 - a; b < 0:
    no filter, y = q) and its powers: out[i] = (y, y^2, y^3).  ``state``: y before q[0] (the
    filter carried over from the previous block of samples).  Returns y at the last sample."""
    for i in range(q.shape[0]):
        if b < 0.0 or seg[i]:
            state = q[i]
        else:
            state = state + b * (q[i] - state)
        y2 = state * state
        out[i, 0] = state
        out[i, 1] = y2
        out[i, 2] = y2 * state
    return state


def _screen_grams(logs, config, poly, keys, cv_blocks, sensor=None, chunk=SCREEN_CHUNK):
    """Per bank: {group: Gram of [poly columns | lag(x, tau)^1..3 for (source, tau) in keys | y]}
    over the samples the fit uses (x: the proxy, or for source 'sensor' the ``sensor`` column).
    Accumulated over blocks of at most ``chunk`` samples of one group (a group of fewer samples
    is one block), each block's rows built and multiplied out at once: memory ~ chunk x columns
    x 8 bytes, flat in the number of samples (the lag filters carry their state across blocks)."""
    from host_tools.golden.compensate import prepare
    two = config.reversal is not None and config.reversal.order == "regress_first"
    fs = float(config.rate.fs)
    banks = ({}, {}) if two else ({},)
    npoly = len(poly)
    width = npoly + 3 * len(keys) + 1
    for i, log in enumerate(logs):
        pr = prepare(log, config)
        n = len(pr.y)
        lags = []                   # per key: (input column, ref, span, b (-1: no filter))
        for src, t in keys:
            term = normalize_term(lag_term(config, t, 1, sensor=sensor if src else None))
            if term["column"] not in log:
                raise ValueError(f"{log.source}: the lag block needs column '{term['column']}', which the log lacks")
            b = 1.0 - math.exp(-1.0 / (fs * term["tau_s"])) if term["tau_s"] != 0 else -1.0
            lags.append((np.asarray(log[term["column"]], np.float64), term["ref"], term["span"], b))
        seg = np.zeros(n, np.bool_)
        if n:
            seg[0] = True
            seg[np.asarray(log.segments, np.int64)] = True
        state = [0.0] * len(keys)
        g = _groups(pr, len(logs), cv_blocks, i)
        masks = [pr.used & (pr.mode == 1), pr.used & (pr.mode == 2)] if two else [pr.used]
        bounds = np.concatenate([[0], np.flatnonzero(np.diff(g)) + 1, [n]]) if n else np.zeros(1, np.int64)
        for s0, e0 in zip(bounds[:-1], bounds[1:]):      # the contiguous runs of one group
            key = (i, int(g[s0]))
            for s in range(s0, e0, chunk):
                e = min(e0, s + chunk)
                A = np.empty((e - s, width))
                A[:, :npoly] = regressor_matrix(pr.u[s:e], pr.v[s:e])[:, list(poly)]
                for j, (x, ref, span, b) in enumerate(lags):
                    c = npoly + 3 * j
                    state[j] = _lag_powers(normalized_input(x[s:e], ref, span), seg[s:e], b, state[j], A[:, c:c + 3])
                A[:, -1] = pr.y[s:e]
                for bank, m in zip(banks, masks):
                    sel = m[s:e]
                    if sel.any():
                        Am = A[sel]
                        bank[key] = bank.get(key, 0) + Am.T @ Am
    return banks


def _solve(G, idx):
    """Least-squares coefficients of the columns ``idx`` from Gram G (last column = y), scaled,
    with a tiny ridge against exact collinearity.  G: one Gram matrix (p x p), or a stack of them
    (F x p x p: one solve each, coefficients F x len(idx))."""
    idx = np.asarray(idx)
    Gs = G[..., idx[:, None], idx[None, :]]
    b = G[..., idx, -1]
    d = np.sqrt(np.maximum(np.diagonal(Gs, axis1=-2, axis2=-1), 1e-300))
    S = Gs / (d[..., :, None] * d[..., None, :])
    S[..., np.arange(len(idx)), np.arange(len(idx))] += _RIDGE
    return np.linalg.solve(S, (b / d)[..., None])[..., 0] / d


def _sse(G, idx, c):
    return float(G[-1, -1] - 2.0 * c @ G[idx, -1] + c @ G[np.ix_(idx, idx)] @ c)


def _cv_sse(banks, idx, trains) -> float:
    """Held-out squared error summed over the groups (each fitted on the other groups) and banks;
    ``trains``: per bank, the stack of the groups' training Gram matrices (total - group)."""
    sse = 0.0
    for bank, train in zip(banks, trains):
        for Gf, c in zip(bank.values(), _solve(train, idx)):
            sse += max(_sse(Gf, idx, c), 0.0)
    return sse


def screen(logs, model, *, cv_blocks=8, taus=LAG_TAUS_S, orders=LAG_ORDERS, sensor_taus=None) -> dict:
    """Step 1 of the module doc for the base ``model`` of ``logs``: {"base": screen cv rms of the
    base polynomial terms, "rows": [{"block", "screen_cv_rms", "cand"}], "coefs": f(cand) -> the
    per-bank lag coefficients of the full training fit, "sensor": the sensor source or None}.
    ``sensor_taus`` None: SENSOR_TAUS_S when :func:`sensor_source` has a sensor.  No candidate
    (runs too short): rows []."""
    cfg = model.config
    poly = (0,) + tuple(sorted(k for k in model.terms if k not in (0, K_AUX)))
    duration = max(float(log.t_s[-1] - log.t_s[0]) for log in logs)
    sensor = sensor_source(logs, cfg)
    sensor_taus = (SENSOR_TAUS_S if sensor_taus is None else sensor_taus) if sensor else ()
    cands = candidates(duration, cfg.reversal is not None, taus, orders, sensor_taus=sensor_taus)
    if not cands:
        return {"base": None, "rows": [], "coefs": None, "sensor": sensor}
    keys = sorted({_key(e) for c in cands for e in c})
    banks = _screen_grams(logs, cfg, poly, keys, cv_blocks, sensor)
    npoly = len(poly)

    def idx_of(cand):
        idx = list(range(npoly))
        for e in cand:
            j = npoly + 3 * keys.index(_key(e))
            idx += list(range(j, j + e[1]))
        return idx

    totals = [sum(bank.values()) for bank in banks]
    trains = [np.stack([total - Gf for Gf in bank.values()]) for bank, total in zip(banks, totals)]
    nsamp = sum(G[0, 0] for bank in banks for G in bank.values())   # column 0 is k0 = 1: the sample count
    rms = lambda idx: float(np.sqrt(_cv_sse(banks, idx, trains) / nsamp))   # noqa: E731
    rows = [{"block": _label(c), "screen_cv_rms": rms(idx_of(c)), "cand": c} for c in cands]
    return {"base": rms(list(range(npoly))), "rows": rows, "sensor": sensor,
            "coefs": lambda c: [_solve(total, idx_of(c))[npoly:] for total in totals]}


def lag_config(config, cand, coefs, sensor=None):
    """The model config with the block ``cand`` packed into one k7 sum (module doc, step 2), or
    None when it does not fit the firmware (more than AUX_MAX_TERMS non-zero terms).  ``sensor``:
    the (column, ref, span) of sensor elements (:func:`sensor_source`)."""
    powers = [(e, p) for e in cand for p in range(1, e[1] + 1)]
    if len(coefs) == 2:
        P, Q = (coefs[0] + coefs[1]) / 2.0, (coefs[0] - coefs[1]) / 2.0
        raw = [(e, p, w, False) for (e, p), w in zip(powers, P)] + [(e, p, w, True) for (e, p), w in zip(powers, Q)]
    else:
        raw = [(e, p, w, False) for (e, p), w in zip(powers, coefs[0])]
    raw = [r for r in raw if r[2] != 0.0]
    total = sum(abs(r[2]) for r in raw)
    if not (raw and total > 0 and len(raw) <= AUX_MAX_TERMS):
        return None
    if any(len(e) > 2 for e in cand) and sensor is None:
        raise ValueError("a sensor block needs the sensor source (column, ref, span)")
    return replace(config, aux=AuxConfig("sum", {"fs": config.rate.fs, "terms": [
        lag_term(config, e[0], p, w / total, s, sensor if len(e) > 2 else None) for e, p, w, s in raw]}))


def add_lag_block(logs, model, res, terms=None, *, cv_blocks=8, taus=LAG_TAUS_S, orders=LAG_ORDERS,
                  margin=None, drop_unidentifiable=True, significance=None, min_gain=0.02, sensor_taus=None,
                  top=None, screen_gate=None):
    """The base ``model`` (and its FitResult ``res``, with a cross-validated rms) of ``logs``,
    extended by the lag-state block when it lowers the cross-validated rms by ``margin`` (None:
    LAG_MARGIN of the kind, 'ftr' or 'mr'; module doc): the ``top`` (None: LAG_REFIT_TOP) candidates
    of least screen CV rms are refitted (terms as given), the refit of least CV rms is kept when it
    beats the base by the margin.  ``screen_gate`` (None: LAG_SCREEN_GATE of the kind; 'off': no
    gate) also requires a refitted candidate's screen rms to beat the base screen by that fraction.  Returns (model, FitResult).
    A model that already has an aux regressor is returned as is."""
    from host_tools.fitting.fit import fit_logs

    logs = list(logs)
    kind = "ftr" if model.config.reversal is None else "mr"
    margin = LAG_MARGIN[kind] if margin is None else margin
    top = LAG_REFIT_TOP if top is None else top
    screen_gate = LAG_SCREEN_GATE[kind] if screen_gate is None else (None if screen_gate == "off" else screen_gate)
    if model.config.aux.generator != "none":
        return model, res
    sc = screen(logs, model, cv_blocks=cv_blocks, taus=taus, orders=orders, sensor_taus=sensor_taus)
    base_cv = (res.cv or {}).get("cv_rms")
    info = {"method": "lag-state block of the proxy (or the sensor), chosen by cross-validated rms "
                      "(host_tools.fitting.fit_lag)", "margin": margin, "refit_top": top, "screen_gate": screen_gate,
            "screen_base_cv_rms": sc["base"], "base_cv_rms": base_cv, "chosen": None,
            "candidates": [{k: v for k, v in r.items() if k != "cand"} for r in sc["rows"]]}
    model.fit["lag_block"] = info
    if not sc["rows"] or base_cv is None:
        return model, res
    ranked = sorted(range(len(sc["rows"])), key=lambda i: sc["rows"][i]["screen_cv_rms"])[:top]
    if screen_gate is not None:
        ranked = [i for i in ranked if sc["rows"][i]["screen_cv_rms"] < (1.0 - screen_gate) * sc["base"]]
    best = None
    for i in ranked:
        row = sc["rows"][i]
        cfg2 = lag_config(model.config, row["cand"], sc["coefs"](row["cand"]), sc["sensor"])
        if cfg2 is None:
            info["candidates"][i]["error"] = "more terms than the firmware's k7 sum holds"
            continue
        try:
            model2, res2 = fit_logs(logs, cfg2, terms, cv_blocks=cv_blocks, blocks=True,
                                    drop_unidentifiable=drop_unidentifiable, significance=significance,
                                    min_gain=min_gain)
        except ValueError as exc:
            info["candidates"][i]["error"] = str(exc)
            continue
        info["candidates"][i]["refit_cv_rms"] = res2.cv["cv_rms"]
        if best is None or res2.cv["cv_rms"] < best[0]:
            best = (res2.cv["cv_rms"], row["block"], model2, res2)
    if best is None:
        return model, res
    info["cv_rms"] = best[0]
    if not best[0] < (1.0 - margin) * base_cv:
        return model, res
    _, info["chosen"], model2, res2 = best
    if "rate_selection" in model.fit:
        model2.fit["rate_selection"] = model.fit["rate_selection"]
    model2.fit["lag_block"] = info
    return model2, res2
