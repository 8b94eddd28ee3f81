"""The bound on |fixed - golden| of a quantized table (deg/h; what it adds up: host_tools.fixed.quantize's
module doc, "The bound") and its measurement: max |B_fixed - B_golden| on the corners and a
random grid of (u, v, z), and max |z_fixed - z_golden| of the aux generators on a synthetic run.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from firmware_ref import formats as F
from firmware_ref.table import Table
from firmware_ref.terms import K_AUX, N_TERMS, TERM_POWERS
from host_tools.fixed.quantize_parts import (aux_part, norm_error, proxy_part, rate_error, rate_part, aux_channel_fracs,
                                       group_exponent)

def error_bound(table: Table, model, parts: dict | None = None) -> dict:
    """Bound on |fixed - golden| in deg/h (see the module doc): ``bias_B`` (B at 2^-21; two banks:
    the larger, ``banks`` each), ``bias_word`` (the BIAS output word), ``combiner`` (y), ``out``
    (the OUT word)."""
    if table.n_banks == 1:
        return _error_bound_bank(table, model, parts, table.bank(1), model.coef)
    banks = [_error_bound_bank(table, model, parts, table.bank(b), c)
             for b, c in ((1, model.coef), (2, model.coef_mode2))]
    worst = max(banks, key=lambda d: d["out"])
    return {**worst, "bias_B": max(d["bias_B"] for d in banks), "bias_word": max(d["bias_word"] for d in banks),
            "out": max(d["out"] for d in banks), "banks": [d["parts"] for d in banks]}


def _error_bound_bank(table: Table, model, parts, bank, coef_f) -> dict:
    cfg = model.config
    coef = [Fraction(float(x)) for x in coef_f]
    t = bank
    E = t.e_acc
    # coefficient quantization
    eps_coef = sum(abs(coef[k] - Fraction(t.mant[k], 1 << group_exponent(bank, k))) for k in range(N_TERMS))
    # evaluator roundings
    rnd = Fraction(0)
    for i in range(4):
        rnd += Fraction(3, 2) / (1 << t.e_row[i])
        if t.e_row[i] > E:
            rnd += Fraction(1, 2) / (1 << E)
    rnd += Fraction(3, 2) / (1 << E)
    if F.Q + t.e_7 - E > 0:
        rnd += Fraction(1, 2) / (1 << E)
    if E > F.Y_FRAC:
        rnd += Fraction(1, 2) / (1 << F.Y_FRAC)
    # input-map errors
    if parts is None:
        parts = {**proxy_part(cfg.proxy), **rate_part(cfg.rate, proxy_part(cfg.proxy)["_lsb"])}
    tb = table
    du = norm_error(cfg.proxy.ref, {"lsb": parts["_lsb"], "span_lsb": parts["_span_lsb"], "g": tb.g_u,
                                     "sh": tb.sh_u, "off": tb.u_off, "ref": tb.p_ref})
    dv = rate_error(cfg.rate, parts["_s_span"], tb.g_v, tb.sh_v)
    lip_u = sum(TERM_POWERS[k][0] * abs(coef[k]) for k in range(N_TERMS) if k != K_AUX)
    lip_v = sum(TERM_POWERS[k][1] * abs(coef[k]) for k in range(N_TERMS) if k != K_AUX)
    float_eps = sum(abs(c) for c in coef) * Fraction(1, 1 << 48)   # golden float64 roundings
    dz = Fraction(0)
    if tb.aux_gen == 1:
        dz = Fraction(parts["_aux"]["z_error"]) if "_aux" in parts else Fraction(aux_part(cfg, parts)["_z_error"])
    bias_b = eps_coef + rnd + lip_u * du + lip_v * dv + abs(coef[K_AUX]) * dz + float_eps
    half_out = Fraction(1, 1 << (F.OUT_FRAC + 1))
    # combiner
    if tb.order == 1:
        # residual path: every r carries the B error and its own rounding (half an r LSB)
        e_r = bias_b + half_out
        w_err = e_r + Fraction(1, 1 << (F.W_FRAC + 1))          # W_r: mean of the r errors + its rounding
        if tb.combiner == 3:
            out = e_r                                            # OUT = r exactly
        elif tb.combiner == 1:
            out = (e_r + w_err) / 2 + half_out
        else:
            d_max = min(2 * tb.max_stale_n + tb.dwell_n, F.D_MAX)
            dc2_min = max(2, 4 * (tb.exchange_n + tb.dwell_n) - 2 * tb.dwell_n)
            ratio = Fraction(d_max, dc2_min)
            out = (e_r + w_err + 2 * w_err * ratio + Fraction(d_max, 1 << (F.SLOPE_FRAC + 1))
                   + Fraction(1, 1 << (F.W_FRAC + 1))) / 2 + half_out
        comb = out - bias_b - half_out
    elif tb.combiner == 0:
        comb = Fraction(0)
    else:
        w_err = Fraction(1, 1 << (F.W_FRAC + 1))
        comb = w_err / 2
        if tb.combiner == 2:
            d_max = min(2 * tb.max_stale_n + tb.dwell_n, F.D_MAX)
            dc2_min = max(2, 4 * (tb.exchange_n + tb.dwell_n) - 2 * tb.dwell_n)
            ratio = Fraction(d_max, dc2_min)
            comb = (w_err + 2 * w_err * ratio + Fraction(d_max, 1 << (F.SLOPE_FRAC + 1)) + w_err) / 2
    return {"bias_B": float(bias_b), "bias_word": float(bias_b + half_out), "combiner": float(comb),
            "out": float(bias_b + comb + half_out),
            "parts": {"coef_quantization": float(eps_coef), "evaluator_rounding": float(rnd),
                      "u_error": float(du), "v_error": float(dv), "lipschitz_u_dph": float(lip_u),
                      "lipschitz_v_dph": float(lip_v), "z_error": float(dz), "k7_dph": float(abs(coef[K_AUX])),
                      "output_rounding": float(half_out)},
            "note": "deg/h; golden fed with the dequantized input words; trend combiner at the table's timing"}


def measure(table: Table, model, n_random: int = 20000, seed: int = 0) -> dict:
    """max |B_fixed - B_golden| (deg/h) on the 27 corners of (u, v, z) in {-1, 0, 1}^3 and on a
    random grid (u, v, z uniform in [-1, 1], plus the k7 axis only if k7 != 0)."""
    from firmware_ref.kernel import evaluate_words

    g = np.array([-F.ONE, 0, F.ONE], np.int64)
    uu, vv, zz = (a.ravel() for a in np.meshgrid(g, g, g, indexing="ij"))
    rng = np.random.default_rng(seed)
    ur, vr, zr = (rng.integers(-F.ONE, F.ONE + 1, n_random) for _ in range(3))
    out = {}
    for name, (u, v, z) in (("corners", (uu, vv, zz)), ("random", (ur, vr, zr))):
        worst = 0.0
        for bank in range(1, table.n_banks + 1):
            b = evaluate_words(table, u, v, z, bank=bank) * 2.0 ** -F.Y_FRAC
            mode = np.full(len(u), bank, np.int64) if table.n_banks == 2 else None
            gold = model.evaluate(u * 2.0 ** -F.Q, v * 2.0 ** -F.Q, z * 2.0 ** -F.Q, mode=mode)
            worst = max(worst, float(np.max(np.abs(b - gold))))
        out[name] = worst
    out["n_random"] = int(n_random)
    return out


def measure_aux(table: Table, model, n: int = 3000, seed: int = 0) -> dict:
    """max |z_fixed - z_golden| on a synthetic run of ``n`` samples (units of z): every channel the
    terms read sweeps 1.2 x its range (clamps included) with noise, the modes of a 30/120-sample
    reversal cycle (FTR models: mode 0), one time gap (a restart); the golden
    (host_tools.golden.regressors.aux_regressor) is fed the dequantized words, the fixed z comes from the
    kernel."""
    import warnings as _warnings

    from firmware_ref import inputs
    from firmware_ref.aux import aux_columns
    from firmware_ref.kernel import run_words
    from host_tools.golden.regressors import aux_regressor, power_on_counter
    from host_tools.golden.runlog import RunLog

    cfg = model.config
    aux = cfg.aux
    fs = aux.params["fs"]
    rng = np.random.default_rng(seed)
    i = np.arange(n)
    t_s = i / fs
    t_s[n // 2:] += 50.0 / fs                                   # a gap: the recursive generators restart
    if cfg.reversal is not None:
        cycle = np.array([3] * 30 + [1] * 120 + [3] * 30 + [2] * 120)
        mode = np.resize(cycle, n)
    else:
        mode = np.zeros(n, np.int64)
    ranges = {cfg.proxy.column: (cfg.proxy.ref, cfg.proxy.span)}
    for tm in aux.terms:
        if tm["gen"] == "input":
            ranges.setdefault(tm["column"], (tm["ref"], tm["span"]))
    ranges.setdefault("freq_hz" if cfg.proxy.column == "temp_c" else "temp_c",
                      (6000.0, 1.0) if cfg.proxy.column == "temp_c" else (20.0, 1.0))
    vals = {col: ref + 1.2 * span * np.sin(2 * np.pi * i / max(n / 3.0, 1.0) + k)
            + 1e-3 * span * rng.standard_normal(n) for k, (col, (ref, span)) in enumerate(ranges.items())}
    cols = aux_columns(aux)
    fracs = aux_channel_fracs(aux)
    f_w, _ = inputs.freq_words(vals["freq_hz"])
    t_w, _ = inputs.temp_words(vals["temp_c"])
    a_w = np.zeros((n, len(cols)), np.int64)
    deq = {"freq_hz": inputs.from_words(f_w, F.FREQ_FRAC), "temp_c": inputs.from_words(t_w, F.TEMP_FRAC)}
    for c, (col, fr) in enumerate(zip(cols, fracs)):
        a_w[:, c], _ = inputs.aux_channel_words(vals[col], fr, col)
        deq[col] = inputs.from_words(a_w[:, c], fr)
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore")
        log = RunLog.from_arrays(t_s=t_s, rate_dph=np.zeros(n), mode=mode, **deq)
    p = f_w if table.proxy_kind == 0 else t_w
    restart = np.zeros(n, np.uint8)
    restart[np.asarray(log.segments, np.int64)] = 1
    res = run_words(table, p, np.zeros(n, np.int64), mode, restart, f=f_w, t=t_w, aux=a_w,
                    k=power_on_counter(log.t_s, fs), detail=True)
    err = np.abs(res["z"] * 2.0 ** -F.Q - aux_regressor(log, aux))
    return {"z_max": float(np.max(err)), "n": int(n)}
