"""Quantize a float bias model into the fixed-point coefficient table: `hdrg quantize`.

``quantize(model, exchange_s=30, dwell_s=120, power_on_s=0) -> Quantized`` maps a
:class:`host_tools.model.BiasModel` to a :class:`firmware_ref.table.Table` (formats in
firmware_ref/FORMATS.md):

* **proxy**: ``P_REF = RHU(ref / LSB_P)``; ``G_U = RHU(2^(30 + SH_U) LSB_P / span)`` with the
  largest SH_U that keeps ``G_U < 2^31``; ``U_OFF = RHU((P_REF - ref / LSB_P) G_U)``.  Refused: a span below one word LSB or above 2^30 LSB,
  a centre outside the word.
* **rate**: ``S_span = D span / (fs LSB_P)`` (x 2^24 for iir) is the estimator sum at |v| = 1;
  the sum clamp ``SB = floor(log2 S_span) + 2`` (so ``2^SB - 1 > S_span``); ``G_V =
  RHU(2^(30 + SH_V) / S_span) < 2^min(31, 62 - SB)`` with the largest SH_V.  Refused: S_span < 1/2
  (the gain does not fit: a rate span below one LSB per sample), ``SB > 55`` or fewer than 16
  significant gain bits, n > 4096.
* **timing**: ``settle_n = round(settle_s fs)``, ``max_stale_n = round(max_stale_s fs)`` (the
  golden's expressions), sequencer power-on/exchange/dwell in samples.
* **coefficients** (interval analysis; u, v, z in [-1, 1]): each group g (Horner rows u^0..u^3
  and k7) gets the largest exponent ``e_g`` in 0..52 with ``sum_j |RHU(c_gj 2^e_g)| <= 2^31 - 1``
  (a rounded product ``RHU(x w, 30)`` with |w| <= 2^30 never exceeds |x|, so every inner partial
  sum is bounded by the sum of the row's |mantissas|); the accumulator exponent E is the largest
  in 0..min(e_g) such that, with ``e_g <- min(e_g, E + 31)``, the aligned row bounds
  ``RHU(A_g, e_g - E)`` plus the k7 bound ``RHU(|m_7| 2^30, 30 + e_7 - E)`` sum to at most
  ``2^31 - 1`` (the outer partial sums are bounded by that sum).  Hence no in-range input can
  overflow any intermediate.  Refused: a group whose |coefficient| sum exceeds 2^31 - 1 deg/h at
  exponent 0, a model whose |B| bound exceeds the output word (2^21 deg/h), or a bound on
  |fixed - golden| above ``max_error_dph`` when given.

* **aux generators** (AuxConfig 'sum', table aux_gen 1, FORMATS.md "Aux generators"): at most 6
  terms and 4 aux_* columns; each aux column gets the largest AF_c in 0..48 with
  ``(|ref| + 2 span) 2^AF_c <= 2^31 - 1`` (:func:`aux_channel_fracs`); input terms are normalized
  like the proxy on their word (F, T or A_c); filter / decay coefficients ``b = 1 - a = B 2^-SB``
  with 31 significant bits (``1/16 <= fs tau <= 2^31`` samples); ramps ``G = RHU(2^(30+SH) / N)``
  (N < 2^31); oscillators ``W = RHU(2^64 / (P fs))`` (more than 2 samples per period); a rate
  term must be the model's own estimator on the proxy column (its own span); weights
  ``RHU(w 2^30)``.  Refused, with the reason: too many terms or columns, a column without an
  input word, a time constant, ramp or period out of range, a rate term of another estimator or
  column, a span below one word LSB.  The k7 mantissa and exponent are quantized as before.

* **two banks** (a ``regress_first`` mode-reversal model, /work/spec-rtr.md; table order 1): bank 1
  (``coef``, mode 1 and every non-mode-2 sample) and bank 2 (``coef_mode2``) are quantized
  **each with its own exponents** (the rule above, per bank: a bank with small coefficients keeps
  its resolution whatever the other's size; the firmware reads the bank's exponents with its
  mantissas, so this costs nothing per sample).  Each bank has its own interval bound
  (``interval_bounds.banks``) and is refused on its own, naming it ("bank 2: row u^0: ...").
  Combiner codes: pair 1, trend 2, none 3.  The **residual path** (FORMATS.md, order 1): r =
  symsat32(RHU(c 2^11 - B, 11)) is an int32 word of the rate word's format, so the window sums,
  means, slopes and y keep the legacy bounds (|acc| < 2^62, |W| < 2^41, |y| < 2^47); refused: a
  bank whose |B| bound exceeds the output word (r and OUT would saturate on every sample).

The **bound** on |fixed - golden| (deg/h, golden fed with the dequantized input words) adds:
coefficient quantization (exact), the evaluator's roundings (1.5 LSB_e per row, 0.5 LSB_E per
alignment, 1.5 LSB_E outer, 0.5 LSB_E for k7, 0.5 LSB_21), the u and v errors (gain and centre
quantization, rounding, iir state rounding) times the Lipschitz constants ``sum i |c_ij|`` and
``sum j |c_ij|``, |k7| times the z generators' error (analytic per generator, ``_aux_part``;
the oscillator's at the horizon K < 2^31), the combiner (window-mean and slope roundings, for
trend at the table's timing) and the final output rounding 2^-11 deg/h.  Two banks: the B
bound is the larger of the banks'; order 1 adds the residual word's rounding 2^-11 deg/h to the
error of every r (none: OUT = r, no further rounding; pair: (r + W_r)/2 then the output
rounding; trend: the legacy slope terms on W_r).  ``measured`` gives max
|B_fixed - B_golden| on the 3^3 corners of (u, v, z) and on a random grid; for an aux model the
report's ``aux`` adds the channels, each term's bound and ``measured_z``, max |z_fixed - z_golden|
on a synthetic run (:func:`measure_aux`).

table.json (:meth:`Quantized.to_dict`): format, version, the table fields, the layout words and
CRC-32, the float model, the quantized coefficients, formats, timing, bound, measured, warnings.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from firmware_ref import formats as F
from firmware_ref.table import COEF_GROUPS, Table, TableError, horner_bounds
from firmware_ref.terms import K_AUX, N_TERMS, TERM_POWERS

FORMAT = "hdrg-fixed-table"
VERSION = 1
GROUPS = COEF_GROUPS
GROUP_NAMES = ("row u^0", "row u^1", "row u^2", "row u^3", "k7 (aux)")


class QuantizeError(ValueError):
    """A model the fixed-point formats cannot represent (the message gives the reason)."""


def rhu(x: Fraction) -> int:
    """Round half up of an exact rational."""
    return math.floor(x + Fraction(1, 2))


def rhu_shift(a: int, s: int) -> int:
    return a if s == 0 else (a + (1 << (s - 1))) >> s


@dataclass
class Quantized:
    """A quantized model: the table, the source model, and the report (bound, measured, ...)."""

    table: Table
    model: object
    report: dict = field(default_factory=dict)

    def coef_quantized(self, bank: int = 1) -> np.ndarray:
        """The coefficients of ``bank`` the table represents, deg/h: m_k 2^-e_g."""
        return quantized_coef(self.table, bank)

    def to_dict(self) -> dict:
        t = self.table
        words = t.to_words()
        return {
            "format": FORMAT,
            "version": VERSION,
            "layout_version": words[1],
            "fields": {k: int(v) for k, v in t.field_values().items()},
            "words": [f"0x{w:08x}" for w in words],
            "crc32": f"0x{words[-1]:08x}",
            "model": self.model.to_dict(),
            "model_source": self.model.source,
            "coef_dph": [float(c) for c in self.model.coef],
            "coef_quantized_dph": [float(c) for c in self.coef_quantized()],
            **({"coef_mode2_dph": [float(c) for c in self.model.coef_mode2],
                "coef_quantized_mode2_dph": [float(c) for c in self.coef_quantized(2)]}
               if t.n_banks == 2 else {}),
            "formats": formats_summary(t),
            **self.report,
        }

    def to_json(self, path) -> None:
        from host_tools.atomic import atomic_open
        with atomic_open(path, "w", encoding="utf-8") as fh:
            json.dump(self.to_dict(), fh, indent=2)
            fh.write("\n")


def formats_summary(t: Table) -> dict:
    frac_p = F.FREQ_FRAC if t.proxy_kind == 0 else F.TEMP_FRAC
    return {
        "proxy_word": {"kind": "freq" if t.proxy_kind == 0 else "temp",
                       "type": "uint32" if t.proxy_kind == 0 else "int32", "frac": frac_p},
        "rate_word": {"type": "int32", "frac": F.RATE_FRAC, "unit": "deg/h"},
        "u_v_z": {"type": "int32", "frac": F.Q},
        "coef_lsb_dph": [2.0 ** -group_exponent(t, k) for k in range(N_TERMS)],
        "accumulator_lsb_dph": 2.0 ** -t.e_acc,
        **({"coef_lsb_mode2_dph": [2.0 ** -group_exponent(t, k, 2) for k in range(N_TERMS)],
            "accumulator_lsb_mode2_dph": 2.0 ** -t.e_acc2,
            "residual_word": {"type": "int32", "frac": F.RATE_FRAC, "unit": "deg/h",
                              "rule": "symsat32(RHU(c 2^11 - B, 11))"}} if t.n_banks == 2 else {}),
        "order": F.ORDERS[t.order], "n_banks": t.n_banks,
        "window_mean_frac": F.W_FRAC, "y_frac": F.Y_FRAC, "slope_frac": F.SLOPE_FRAC,
        "output_word": {"type": "int32", "frac": F.OUT_FRAC, "unit": "deg/h"},
        "rounding": "round half up (add 2^(s-1), arithmetic shift)",
    }


def group_exponent(t, k: int, bank: int = 1) -> int:
    """The exponent of coefficient k in ``bank`` (t: a Table or a table.Bank)."""
    b = t.bank(bank) if hasattr(t, "bank") else t
    return b.e_7 if k == K_AUX else b.e_row[TERM_POWERS[k][0]]


def quantized_coef(t: Table, bank: int = 1) -> np.ndarray:
    """The coefficients of ``bank`` the table represents, deg/h."""
    b = t.bank(bank)
    return np.array([b.mant[k] * 2.0 ** -group_exponent(b, k) for k in range(N_TERMS)])


# -- the parts ----------------------------------------------------------------------------------------

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


def _norm_error(ref: float, n: dict) -> Fraction:
    """Bound on |q_fixed - (x - ref) / span| at dequantized inputs (gain and centre quantization,
    the rounding), in units of q."""
    lsb, span_lsb = n["lsb"], n["span_lsb"]
    g = Fraction(n["g"], 1 << (F.Q + n["sh"]))
    return (Fraction(1, 1 << (F.Q + 1)) + (span_lsb + 1) * abs(g - 1 / span_lsb)
            + abs((n["ref"] - Fraction(ref) / lsb) * g - Fraction(n["off"], 1 << (F.Q + n["sh"])))
            + abs(Fraction(ref) / lsb - n["ref"]) * abs(g - 1 / span_lsb))


def _proxy_part(pc) -> dict:
    frac = F.FREQ_FRAC if pc.kind == "freq" else F.TEMP_FRAC
    word = "drive-frequency word (0 .. 16384 Hz)" if pc.kind == "freq" else "temperature word (+-32768 degC)"
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


def _rate_part(rc, lsb: Fraction) -> dict:
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


def _timing(value_s: float, fs: float, name: str, minimum: int = 0) -> int:
    n = int(round(value_s * fs))
    if not minimum <= n <= F.TIMER_MAX - 1:
        raise QuantizeError(f"{name} = {value_s} s at {fs} Hz gives {n} samples; needs {minimum}..{F.TIMER_MAX - 1}")
    return n


def _coef_part(coef) -> dict:
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


def _rate_error(rc, s_span: Fraction, g_v: int, sh_v: int) -> Fraction:
    """Bound on |v_fixed - v_golden| (units of v): rounding, gain quantization, iir state rounding."""
    dv = Fraction(1, 1 << (F.Q + 1)) + (s_span + 1) * abs(Fraction(g_v, 1 << (F.Q + sh_v)) - 1 / s_span)
    if rc.estimator == "iir":
        dv += Fraction(1 << rc.shift, 2) / s_span
    return dv


# -- the aux generators (aux_gen 1) ----------------------------------------------------------------------

AUX_CHANNEL_WORDS = {"freq_hz": (F.CH_F, F.FREQ_FRAC, True, "Hz", "drive-frequency word (0 .. 16384 Hz)"),
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


def _aux_part(cfg, pp: dict) -> dict:
    """aux_gen, aux_params (the table words) and the z-error bound ``_z_error`` (units of z) of the
    model's AuxConfig; QuantizeError names the term and the reason."""
    from firmware_ref.aux import aux_columns
    from firmware_ref.table import AuxTerm, encode_aux
    from host_tools.rate import RateConfig

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
            err = _norm_error(tm["ref"], n)
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
            rp = _rate_part(rt, pp["_lsb"])
            c[:3] = [rp["s_bits"], rp["g_v"], rp["sh_v"]]
            src = pp["proxy_kind"]
            err = _rate_error(rt, rp["_s_span"], rp["g_v"], rp["sh_v"])
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


# -- the bound -------------------------------------------------------------------------------------------

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
        parts = {**_proxy_part(cfg.proxy), **_rate_part(cfg.rate, _proxy_part(cfg.proxy)["_lsb"])}
    tb = table
    du = _norm_error(cfg.proxy.ref, {"lsb": parts["_lsb"], "span_lsb": parts["_span_lsb"], "g": tb.g_u,
                                     "sh": tb.sh_u, "off": tb.u_off, "ref": tb.p_ref})
    dv = _rate_error(cfg.rate, parts["_s_span"], tb.g_v, tb.sh_v)
    lip_u = sum(TERM_POWERS[k][0] * abs(coef[k]) for k in range(N_TERMS) if k != K_AUX)
    lip_v = sum(TERM_POWERS[k][1] * abs(coef[k]) for k in range(N_TERMS) if k != K_AUX)
    float_eps = sum(abs(c) for c in coef) * Fraction(1, 1 << 48)   # golden float64 roundings
    dz = Fraction(0)
    if tb.aux_gen == 1:
        dz = Fraction(parts["_aux"]["z_error"]) if "_aux" in parts else Fraction(_aux_part(cfg, parts)["_z_error"])
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
    (host_tools.regressors.aux_regressor) is fed the dequantized words, the fixed z comes from the
    kernel."""
    import warnings as _warnings

    from firmware_ref import inputs
    from firmware_ref.aux import aux_columns
    from firmware_ref.kernel import run_words
    from host_tools.regressors import aux_regressor, power_on_counter
    from host_tools.runlog import RunLog

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


def quantize(model, exchange_s: float = 30.0, dwell_s: float = 120.0, power_on_s: float = 0.0,
             max_error_dph: float | None = None, n_random: int = 20000) -> Quantized:
    """The fixed-point table of ``model`` (see the module doc); QuantizeError if it cannot be
    represented."""
    cfg = model.config
    fs = cfg.rate.fs
    where = f"{model.source}: cannot quantize"
    try:
        pp = _proxy_part(cfg.proxy)
        rp = _rate_part(cfg.rate, pp["_lsb"])
        rev = cfg.reversal
        two = rev is not None and rev.order == "regress_first"
        cp = _coef_part(model.coef)
        if two:
            try:
                cp2 = _coef_part(model.coef_mode2)
            except QuantizeError as exc:
                raise QuantizeError(f"bank 2 (mode 2): {exc}") from None
        fs_q16 = rhu(Fraction(fs) * (1 << 16))
        if not 0 < fs_q16 <= F.UINT32_MAX:
            raise QuantizeError(f"sample rate {fs} Hz outside the fs_q16 word (2^-16 .. 65536 Hz)")
        comb = 0 if rev is None else {"pair": 1, "trend": 2, "none": 3}[rev.combiner]
        settle_n = 0 if rev is None else _timing(rev.settle_s, fs, "settle_s")
        stale_n = 0 if rev is None else _timing(rev.max_stale_s, fs, "max_stale_s")
        timing = {"power_on_n": _timing(power_on_s, fs, "power_on_s"),
                  "exchange_n": _timing(exchange_s, fs, "exchange_s"),
                  "dwell_n": _timing(dwell_s, fs, "dwell_s", 1)}
        out_range = F.INT32_SYM * 2.0 ** -F.OUT_FRAC
        for name, coef in (("", model.coef),) + ((("bank 2 (mode 2): ", model.coef_mode2),) if two else ()):
            total = float(sum(abs(Fraction(float(c))) for c in coef))
            if total > out_range:
                raise QuantizeError(f"{name}the bias bound sum |k| = {total:.6g} deg/h exceeds the output word "
                                    f"range +-{out_range:.6g} deg/h")
        ap = _aux_part(cfg, pp)
        table = Table(proxy_kind=pp["proxy_kind"], p_ref=pp["p_ref"], g_u=pp["g_u"], u_off=pp["u_off"],
                      sh_u=pp["sh_u"],
                      rate_est=rp["rate_est"], rate_n=rp["rate_n"], rate_shift=rp["rate_shift"],
                      rate_warmup=rp["rate_warmup"], s_bits=rp["s_bits"], g_v=rp["g_v"], sh_v=rp["sh_v"],
                      fs_q16=fs_q16, combiner=comb, settle_n=settle_n, max_stale_n=stale_n, **timing,
                      e_row=cp["e_row"], e_7=cp["e_7"], e_acc=cp["e_acc"], mant=cp["mant"],
                      aux_gen=ap["aux_gen"], aux_params=ap["aux_params"],
                      **({"order": 1, "n_banks": 2, "e_row2": cp2["e_row"], "e_7_2": cp2["e_7"],
                          "e_acc2": cp2["e_acc"], "mant2": cp2["mant"]} if two else {}))
    except (QuantizeError, TableError) as exc:
        raise QuantizeError(f"{where}: {exc}") from None
    warnings = []
    if comb == 2 and 2 * stale_n + timing["dwell_n"] > F.D_MAX:
        warnings.append(f"trend distance 2 max_stale_n + dwell_n = {2 * stale_n + timing['dwell_n']} half-samples "
                        f"exceeds D_MAX = {F.D_MAX}: it saturates (FLAG_SAT) on stale-limit samples")
    bound = error_bound(table, model, {**pp, **rp, "_aux": {"z_error": ap["_z_error"]}})
    if max_error_dph is not None and bound["out"] > max_error_dph:
        raise QuantizeError(f"{where}: the bound on |fixed - golden| {bound['out']:.3g} deg/h exceeds "
                            f"--max-error {max_error_dph:g} deg/h")
    report = {
        "timing": {"fs_hz": fs, "settle_n": settle_n, "max_stale_n": stale_n, **timing,
                   "exchange_s": exchange_s, "dwell_s": dwell_s, "power_on_s": power_on_s},
        "interval_bounds": {"group_bounds_at_E": cp["_bounds"], "sum": int(sum(cp["_bounds"])),
                            "limit": F.ACC_LIMIT,
                            **({"banks": [{"group_bounds_at_E": c["_bounds"], "sum": int(sum(c["_bounds"]))}
                                          for c in (cp, cp2)],
                                "residual": {"r": "int32 sym-sat (FLAG_SAT), LSB 2^-10 deg/h",
                                             "acc": "|acc| <= (2^31 - 1)^2 < 2^62", "W": "|W| < 2^41",
                                             "y": "|y| < 2^47"}} if two else {})},
        "bound_dph": bound,
        "measured_dph": measure(table, model, n_random),
        "warnings": warnings,
    }
    if ap["_info"] is not None:
        report["aux"] = {**ap["_info"], "measured_z": measure_aux(table, model)}
    return Quantized(table, model, report)


def read_table(path) -> Table:
    """A table from table.json (checks CRC and that its fields agree with its words), a binary
    ``.bin`` or a ``.memh``/``.hex`` memory file."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext == ".bin":
        with open(path, "rb") as fh:
            return Table.from_bytes(fh.read(), path)
    with open(path, "r", encoding="utf-8") as fh:
        text = fh.read()
    if ext in (".memh", ".hex", ".mem"):
        return Table.from_memh(text, path)
    try:
        d = json.loads(text)
    except json.JSONDecodeError as exc:
        raise TableError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise TableError(f"{path}: not an hdrg table (format {d.get('format') if isinstance(d, dict) else None!r}, "
                         f"expected {FORMAT!r})")
    if d.get("version") != VERSION:
        raise TableError(f"{path}: unsupported table.json version {d.get('version')!r}")
    try:
        words = [int(w, 16) for w in d["words"]]
    except (KeyError, TypeError, ValueError):
        raise TableError(f"{path}: field 'words' missing or not a list of hex words") from None
    table = Table.from_words(words, path)
    fields_ = d.get("fields", {})
    vals = table.field_values()
    bad = [k for k, v in fields_.items() if vals.get(k) != v]
    if bad:
        raise TableError(f"{path}: fields {', '.join(bad)} disagree with the words (edited by hand?)")
    return table
