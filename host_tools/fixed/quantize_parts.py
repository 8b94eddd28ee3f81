"""The parts of a fixed-point coefficient table, each quantized from one piece of a float model
(the rules: host_tools.fixed.quantize's module doc, formats: firmware_ref/FORMATS.md): the proxy
normalization, the rate estimator's gain, the timing words, the coefficient groups with their
exponents, and the aux generators (aux_gen 1).  Each ``_*_part`` returns the table words of its
piece plus underscored entries (``_lsb``, ``_bounds``, ``_z_error``, ...) that the error bound
(host_tools.fixed.quantize_bound) reads; a piece that cannot be represented raises
:class:`QuantizeError` naming it and the reason.
"""
from __future__ import annotations

import math
from fractions import Fraction

from firmware_ref import formats as F
from firmware_ref.table import COEF_GROUPS, horner_bounds
from firmware_ref.terms import K_AUX, N_TERMS, TERM_POWERS
from host_tools.errors import HdrgError

GROUPS = COEF_GROUPS
GROUP_NAMES = ("row u^0", "row u^1", "row u^2", "row u^3", "k7 (aux)")

class QuantizeError(HdrgError, ValueError):
    """A model the fixed-point formats cannot represent (the message gives the reason)."""


def rhu(x: Fraction) -> int:
    """Round half up of an exact rational."""
    return math.floor(x + Fraction(1, 2))


def rhu_shift(a: int, s: int) -> int:
    return a if s == 0 else (a + (1 << (s - 1))) >> s


def group_exponent(t, k: int, bank: int = 1) -> int:
    """The exponent of coefficient k in ``bank`` (t: a Table or a table.Bank)."""
    b = t.bank(bank) if hasattr(t, "bank") else t
    return b.e_7 if k == K_AUX else b.e_row[TERM_POWERS[k][0]]


def _norm_part(ref: float, span: float, frac: int, unsigned: bool, what: str, unit: str, word: str) -> dict:
    """The word-level normalization q = RHU((X - REF) G + OFF, SH) of (x - ref) / span for a word
    with LSB 2^-frac (the proxy's, and the aux input terms'); QuantizeError names ``what``."""
    lsb = Fraction(1, 1 << frac)
    p_ref = rhu(Fraction(ref) / lsb)
    if (unsigned and not 0 <= p_ref <= F.UINT32_MAX) or (not unsigned and abs(p_ref) > F.INT32_SYM):
        raise QuantizeError(f"{what} ref {ref} {unit} is outside the {word}")
    span_lsb = Fraction(span) / lsb
    if span_lsb > F.SPAN_LSB_MAX:
        raise QuantizeError(f"{what} span {span} {unit} exceeds 2^30 word LSB ({float(lsb * F.SPAN_LSB_MAX):g} {unit})")
    sh, g = _gain(Fraction(1), span_lsb, (1 << F.GAIN_BITS) - 1)
    if sh is None:
        raise QuantizeError(f"{what} span {span} {unit} is below one word LSB ({float(lsb):g} {unit}): "
                            f"the gain 2^30 LSB/span does not fit int32")
    off = rhu((p_ref - Fraction(ref) / lsb) * g)
    return {"ref": p_ref, "g": g, "off": off, "sh": sh, "span_lsb": span_lsb, "lsb": lsb}


def norm_error(ref: float, n: dict) -> Fraction:
    """Bound on |q_fixed - (x - ref) / span| at dequantized inputs (gain and centre quantization,
    the rounding), in units of q."""
    lsb, span_lsb = n["lsb"], n["span_lsb"]
    g = Fraction(n["g"], 1 << (F.Q + n["sh"]))
    return (Fraction(1, 1 << (F.Q + 1)) + (span_lsb + 1) * abs(g - 1 / span_lsb)
            + abs((n["ref"] - Fraction(ref) / lsb) * g - Fraction(n["off"], 1 << (F.Q + n["sh"])))
            + abs(Fraction(ref) / lsb - n["ref"]) * abs(g - 1 / span_lsb))


def proxy_part(pc) -> dict:
    frac = F.FREQ_FRAC if pc.kind == "freq" else F.TEMP_FRAC
    word = f"drive-frequency word (0 .. {F.FREQ_RANGE_HZ:.0f} Hz)" if pc.kind == "freq" else "temperature word (+-32768 degC)"
    n = _norm_part(pc.ref, pc.span, frac, pc.kind == "freq", "proxy", pc.unit, word)
    return {"proxy_kind": 0 if pc.kind == "freq" else 1, "p_ref": n["ref"], "g_u": n["g"], "u_off": n["off"],
            "sh_u": n["sh"], "_span_lsb": n["span_lsb"], "_lsb": n["lsb"], "_norm": n}


def _gain(num: Fraction, den: Fraction, gmax: int):
    """Largest shift s in 0..62 with G = RHU(num 2^(30+s) / den) <= gmax; (s, G) or (None, None)."""
    best = (None, None)
    for s in range(0, 63):
        g = rhu(num * (1 << (F.Q + s)) / den)
        if g > gmax:
            break
        best = (s, g)
    return best


def rate_part(rc, lsb: Fraction) -> dict:
    est = F.ESTIMATORS.index(rc.estimator)
    n = rc.n if rc.estimator in ("diffn", "lsq") else 1
    if n > F.N_HIST_MAX:
        raise QuantizeError(f"rate n = {n} exceeds the firmware's history buffer ({F.N_HIST_MAX} samples)")
    s_span = Fraction(rc.divisor) * Fraction(rc.span) / (Fraction(rc.fs) * lsb)
    if rc.estimator == "iir":
        s_span *= 1 << F.IIR_FRAC
    if s_span < Fraction(1, 2):
        raise QuantizeError(f"rate span {rc.span} proxy units/s is below one word LSB per sample at "
                            f"fs = {rc.fs} Hz: the rate gain does not fit int32")
    sb = 1                               # smallest SB with 2^(SB-1) > S_span: 2^SB - 1 > S_span
    while (1 << (sb - 1)) <= s_span:
        sb += 1
    if sb > F.S_BITS_MAX:
        raise QuantizeError(f"rate span {rc.span} proxy units/s with the {rc.estimator} estimator "
                            f"(divisor {rc.divisor}) needs a rate-sum range of 2^{sb}, beyond 2^{F.S_BITS_MAX}")
    gmax = min((1 << F.GAIN_BITS) - 1, (1 << (62 - sb)) - 1)
    sh, g = _gain(Fraction(1), s_span, gmax)
    if sh is None or g < (1 << F.MIN_GAIN_BITS):
        raise QuantizeError(f"rate span {rc.span} proxy units/s: the rate gain has fewer than "
                            f"{F.MIN_GAIN_BITS} significant bits within the rate-sum range 2^{sb}")
    if rhu_shift(((1 << sb) - 1) * g, sh) <= F.ONE:  # a clamped S must still clamp v
        raise QuantizeError("internal: rate-sum clamp does not saturate v")  # pragma: no cover
    return {"rate_est": est, "rate_n": n, "rate_shift": rc.shift, "rate_warmup": rc.warmup, "s_bits": sb,
            "g_v": g, "sh_v": sh, "_s_span": s_span}


def timing_part(value_s: float, fs: float, name: str, minimum: int = 0) -> int:
    if not math.isfinite(value_s) or value_s < 0:
        raise QuantizeError(f"{name} = {value_s} s: must be a finite number of seconds >= 0")
    n = int(round(value_s * fs))
    if value_s > 0 and n == 0:
        raise QuantizeError(f"{name} = {value_s} s rounds to 0 samples at {fs} Hz (one sample is {1 / fs:g} s)")
    if not minimum <= n <= F.TIMER_MAX - 1:
        raise QuantizeError(f"{name} = {value_s} s at {fs} Hz gives {n} samples; needs {minimum}..{F.TIMER_MAX - 1}")
    return n


def coef_part(coef) -> dict:
    c = [Fraction(float(x)) for x in coef]
    e_max = []
    for g, ks in enumerate(GROUPS):
        found = None
        for e in range(F.EXP_MAX, F.EXP_MIN - 1, -1):
            if sum(abs(rhu(c[k] * (1 << e))) for k in ks) <= F.ACC_LIMIT:
                found = e
                break
        if found is None:
            tot = float(sum(abs(c[k]) for k in ks))
            raise QuantizeError(f"{GROUP_NAMES[g]}: the sum of |coefficients| {tot:.6g} deg/h exceeds "
                                f"2^31 - 1 deg/h at the coarsest legal exponent {F.EXP_MIN}")
        e_max.append(found)
    for E in range(min(e_max), F.EXP_MIN - 1, -1):
        e_g = [min(e, E + F.ALIGN_MAX) for e in e_max]
        mant = [0] * N_TERMS
        for g, ks in enumerate(GROUPS):
            for k in ks:
                mant[k] = rhu(c[k] * (1 << e_g[g]))
        _, bounds = horner_bounds(e_g[:4], e_g[4], E, mant)
        if sum(bounds) <= F.ACC_LIMIT:
            return {"e_row": tuple(e_g[:4]), "e_7": e_g[4], "e_acc": E, "mant": tuple(mant),
                    "_bounds": bounds}
    raise QuantizeError("the coefficients cannot be aligned to one accumulator below 2^31 "
                        "at any legal exponent (sum of |coefficients| too large)")


def rate_error(rc, s_span: Fraction, g_v: int, sh_v: int) -> Fraction:
    """Bound on |v_fixed - v_golden| (units of v): rounding, gain quantization, iir state rounding."""
    dv = Fraction(1, 1 << (F.Q + 1)) + (s_span + 1) * abs(Fraction(g_v, 1 << (F.Q + sh_v)) - 1 / s_span)
    if rc.estimator == "iir":
        dv += Fraction(1 << rc.shift, 2) / s_span
    return dv


# -- the aux generators (aux_gen 1) ----------------------------------------------------------------------

AUX_CHANNEL_WORDS = {"freq_hz": (F.CH_F, F.FREQ_FRAC, True, "Hz", f"drive-frequency word (0 .. {F.FREQ_RANGE_HZ:.0f} Hz)"),
                     "temp_c": (F.CH_T, F.TEMP_FRAC, False, "degC", "temperature word (+-32768 degC)")}
OSC_HORIZON = 1 << 31        # the osc error bound holds for K < 2^31 samples (the golden's float drift grows)
GOLDEN_OSC_STEP_EPS = Fraction(8, 1 << 53)   # golden rotation: float64 error per step (estimate)


def aux_channel_fracs(aux) -> list:
    """AF_c of every aux channel of an AuxConfig (firmware_ref.aux.aux_columns order): the largest
    in 0..AUX_FRAC_MAX with (max over its input terms of |ref| + 2 span) 2^AF <= 2^31 - 1, so a
    saturated word is at least 2 spans from the centre (q clamps as in the golden)."""
    from firmware_ref.aux import aux_columns

    out = []
    for col in aux_columns(aux):
        top = max(abs(Fraction(t["ref"])) + 2 * Fraction(t["span"]) for t in aux.terms
                  if t["gen"] == "input" and t["column"] == col)
        fr = None
        for f in range(F.AUX_FRAC_MAX, -1, -1):
            if top * (1 << f) <= F.INT32_SYM:
                fr = f
                break
        if fr is None:
            raise QuantizeError(f"aux column {col!r}: |ref| + 2 span = {float(top):.6g} exceeds the aux word "
                                f"range (2^31 - 1 units at AF = 0)")
        out.append(fr)
    return out


def _coef_shift(b: Fraction, what: str, n_samples: float) -> tuple:
    """(B, SB) of a filter / decay coefficient b = 1 - a: the largest SB in 31..62 with
    B = RHU(b 2^SB) <= 2^31 - 1, B >= 2^30 (31 significant bits)."""
    if not F.AUX_TAU_N_MIN <= n_samples <= F.AUX_TAU_N_MAX:
        raise QuantizeError(f"{what}: the time constant fs tau = {n_samples:.6g} samples is outside "
                            f"{F.AUX_TAU_N_MIN:g} .. 2^31 samples (the filter coefficient 1 - a = B 2^-SB "
                            f"needs 2^30 <= B < 2^31 with SB in {F.AUX_SB_MIN}..{F.AUX_SB_MAX})")
    best = None
    for sb in range(F.AUX_SB_MIN, F.AUX_SB_MAX + 1):
        bb = rhu(b * (1 << sb))
        if bb > F.INT32_SYM:
            break
        best = (bb, sb)
    if best is None or best[0] < (1 << 30):
        raise QuantizeError(f"{what}: the coefficient 1 - a = {float(b):.6g} cannot be held with 31 significant "
                            f"bits (fs tau = {n_samples:.6g} samples)")
    return best


def aux_part(cfg, pp: dict) -> dict:
    """aux_gen, aux_params (the table words) and the z-error bound ``_z_error`` (units of z) of the
    model's AuxConfig; QuantizeError names the term and the reason."""
    from firmware_ref.aux import aux_columns
    from firmware_ref.table import AuxTerm, encode_aux
    from host_tools.golden.rate import RateConfig

    aux = cfg.aux
    if aux.generator == "none":
        return {"aux_gen": 0, "aux_params": (), "_z_error": 0, "_info": None}
    terms = aux.terms
    fs = aux.params["fs"]
    if len(terms) > F.AUX_MAX_TERMS:
        raise QuantizeError(f"aux generator 'sum' has {len(terms)} terms; the firmware holds at most {F.AUX_MAX_TERMS}")
    cols = aux_columns(aux)
    if len(cols) > F.AUX_MAX_CHANNELS:
        raise QuantizeError(f"aux generator reads {len(cols)} aux_* columns ({', '.join(cols)}); the firmware has "
                            f"{F.AUX_MAX_CHANNELS} aux input words")
    fracs = aux_channel_fracs(aux)
    out, info = [], []
    half = Fraction(1, 1 << (F.Q + 1))
    z_err = half                                                  # RHU(acc, 30)
    for j, tm in enumerate(terms):
        gen = tm["gen"]
        where = f"aux term {j} ({gen})"
        c = [0] * 6
        src, power, err = 0, 1, Fraction(0)
        d = {"term": j, "gen": gen}
        if gen == "input":
            col = tm["column"]
            if col in AUX_CHANNEL_WORDS:
                src, frac, unsigned, unit, word = AUX_CHANNEL_WORDS[col]
            elif col.startswith("aux_"):
                src, frac, unsigned, unit, word = (F.CH_A0 + cols.index(col), fracs[cols.index(col)], False,
                                                   "units", f"aux word of {col} (LSB 2^-{fracs[cols.index(col)]})")
            else:
                raise QuantizeError(f"{where}: column {col!r} has no input word (the firmware reads freq_hz, "
                                    f"temp_c and aux_* columns)")
            n = _norm_part(tm["ref"], tm["span"], frac, unsigned, f"{where} {col}", unit, word)
            c[:4] = [n["ref"], n["g"], n["off"], n["sh"]]
            err = norm_error(tm["ref"], n)
            if tm["tau_s"] > 0:
                a = math.exp(-1.0 / (fs * tm["tau_s"]))
                b = Fraction(1.0 - a)                             # the golden's b (float)
                c[4], c[5] = _coef_shift(b, where, fs * tm["tau_s"])
                db = abs(Fraction(c[4], 1 << c[5]) - b) / b
                err += 2 * db + Fraction(1, 1 << 61) / b + half + Fraction(fs * tm["tau_s"]) * Fraction(1, 1 << 52)
            power = tm["power"]
            err = power * err + (power - 1) * half
            d.update(column=col, channel=src, frac=frac)
        elif gen == "rate":
            r = cfg.rate
            if tm["column"] != cfg.proxy.column:
                raise QuantizeError(f"{where}: a rate of column {tm['column']!r} has no fixed-point form (only the "
                                    f"proxy column {cfg.proxy.column!r}, whose rate sum the firmware has)")
            rt = RateConfig(tm["estimator"], tm["n"], tm["shift"], tm["span"], fs)
            same = (rt.estimator == r.estimator and rt.divisor == r.divisor and rt.warmup == r.warmup
                    and (r.estimator != "iir" or rt.shift == r.shift))
            if not same:
                raise QuantizeError(f"{where}: the estimator {rt.estimator} n={rt.n} shift={rt.shift} differs from "
                                    f"the model's ({r.estimator} n={r.n} shift={r.shift}): the firmware has one rate sum")
            rp = rate_part(rt, pp["_lsb"])
            c[:3] = [rp["s_bits"], rp["g_v"], rp["sh_v"]]
            src = pp["proxy_kind"]
            err = rate_error(rt, rp["_s_span"], rp["g_v"], rp["sh_v"])
        elif gen == "one":
            pass
        elif gen in ("decay_on", "decay_exchange"):
            a = math.exp(-1.0 / (fs * tm["tau_s"]))
            b = 1 - Fraction(a)                                   # the golden multiplies by a
            c[0], c[1] = _coef_shift(b, where, fs * tm["tau_s"])
            db = abs(Fraction(c[0], 1 << c[1]) - b) / b
            err = db + Fraction(1, 1 << 61) / b + half + Fraction(fs * tm["tau_s"]) * Fraction(1, 1 << 53)
        elif gen == "ramp":
            nn = tm["n_samples"]
            if nn > F.INT32_SYM:
                raise QuantizeError(f"{where}: n_samples {nn} exceeds 2^31 - 1")
            sh, g = _gain(Fraction(1), Fraction(nn), F.INT32_SYM)
            c[:3] = [nn, g, sh]
            err = nn * abs(Fraction(g, 1 << (F.Q + sh)) - Fraction(1, nn)) + half
        else:  # osc
            pfs = Fraction(tm["period_s"]) * Fraction(fs)
            w = rhu(Fraction(1 << 64) / pfs)
            if not 1 <= w < 1 << 63:
                raise QuantizeError(f"{where}: the period {tm['period_s']} s is {float(pfs):.6g} samples; the "
                                    f"oscillator needs more than 2 samples per period")
            c[0], c[2] = w, 1 if tm["part"] == "cos" else 0
            phase = abs(Fraction(w) - Fraction(1 << 64) / pfs) * OSC_HORIZON * 2 * Fraction(math.pi) / (1 << 64)
            err = Fraction(F.SIN_ERR_LSB, 1 << F.Q) + phase + OSC_HORIZON * GOLDEN_OSC_STEP_EPS
        wq = max(-F.ONE, min(F.ONE, rhu(Fraction(tm["weight"]) * F.ONE)))
        z_err += abs(Fraction(tm["weight"])) * err + abs(Fraction(tm["weight"]) - Fraction(wq, F.ONE))
        kind = F.AUX_KINDS.index(gen)
        out.append(AuxTerm(kind, int(tm["sign"]), src, power, wq, tuple(c)))
        d.update(weight_q30=wq, g_error=float(err))
        info.append(d)
    params = encode_aux(fracs, out)
    return {"aux_gen": 1, "aux_params": params, "_z_error": z_err,
            "_info": {"channels": [{"column": col, "word": f"A{c}", "frac": fr} for c, (col, fr) in
                                   enumerate(zip(cols, fracs))], "terms": info, "z_error": float(z_err),
                      "osc_horizon_samples": OSC_HORIZON}}
