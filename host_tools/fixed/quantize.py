"""Quantize a float bias model into the fixed-point coefficient table: `hdrg quantize`.

``quantize(model, exchange_s=30, dwell_s=120, power_on_s=0) -> Quantized`` maps a
:class:`host_tools.golden.model.BiasModel` to a :class:`firmware_ref.table.Table` (formats in
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

* **aux generators** (AuxConfig 'sum', table aux_gen 1, FORMATS.md "Aux generators"): at most 16
  terms and 4 aux_* columns; each aux column gets the largest AF_c in 0..48 with
  ``(|ref| + 2 span) 2^AF_c <= 2^31 - 1`` (:func:`aux_channel_fracs`); input terms are normalized
  like the proxy on their word (F, T or A_c); filter / decay coefficients ``b = 1 - a = B 2^-SB``
  with 31 significant bits (``1/16 <= fs tau <= 2^31`` samples); ramps ``G = RHU(2^(30+SH) / N)``
  (N < 2^31); oscillators ``W = RHU(2^64 / (P fs))`` (more than 2 samples per period); a rate
  term must be the model's own estimator on the proxy column (its own span); weights
  ``RHU(w 2^30)``.  Refused, with the reason: too many terms or columns, a column without an
  input word, a time constant, ramp or period out of range, a rate term of another estimator or
  column, a span below one word LSB.  The k7 mantissa and exponent are quantized as before.

* **two banks** (a ``regress_first`` mode-reversal model, docs/REGRESS_THEN_REVERSE.md; table order 1): bank 1
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
``sum j |c_ij|``, |k7| times the z generators' error (analytic per generator, ``aux_part``;
the oscillator's at the horizon K < 2^31), the combiner (window-mean and slope roundings, for
trend at the table's timing) and the final output rounding 2^-11 deg/h.  Two banks: the B
bound is the larger of the banks'; order 1 adds the residual word's rounding 2^-11 deg/h to the
error of every r (none: OUT = r, no further rounding; pair: (r + W_r)/2 then the output
rounding; trend: the legacy slope terms on W_r).  ``measured`` gives max
|B_fixed - B_golden| on the 3^3 corners of (u, v, z) and on a random grid; for an aux model the
report's ``aux`` adds the channels, each term's bound and ``measured_z``, max |z_fixed - z_golden|
on a synthetic run (:func:`measure_aux`).

Modules: this one (``quantize``, :class:`Quantized`, ``read_table``), host_tools.fixed.quantize_parts
(the parts: proxy, rate, timing, coefficients, aux generators) and host_tools.fixed.quantize_bound (the
bound and its measurement).

table.json (:meth:`Quantized.to_dict`): format, version, the table fields, the layout words and
CRC-32, the float model, the quantized coefficients, formats, timing, bound, measured, warnings.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from firmware_ref import formats as F
from firmware_ref.table import Table, TableError
from firmware_ref.terms import N_TERMS
from host_tools.fixed.quantize_bound import error_bound, measure, measure_aux
from host_tools.fixed.quantize_parts import (QuantizeError, aux_part, coef_part, proxy_part, rate_part, timing_part,
                                       group_exponent, rhu)

FORMAT = "hdrg-fixed-table"
VERSION = 1


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


def quantized_coef(t: Table, bank: int = 1) -> np.ndarray:
    """The coefficients of ``bank`` the table represents, deg/h."""
    b = t.bank(bank)
    return np.array([b.mant[k] * 2.0 ** -group_exponent(b, k) for k in range(N_TERMS)])


# -- the parts ----------------------------------------------------------------------------------------


# -- the aux generators (aux_gen 1) ----------------------------------------------------------------------


# -- the bound -------------------------------------------------------------------------------------------


def quantize(model, exchange_s: float = 30.0, dwell_s: float = 120.0, power_on_s: float = 0.0,
             max_error_dph: float | None = None, n_random: int = 20000) -> Quantized:
    """The fixed-point table of ``model`` (see the module doc); QuantizeError if it cannot be
    represented."""
    cfg = model.config
    fs = cfg.rate.fs
    where = f"{model.source}: cannot quantize"
    try:
        pp = proxy_part(cfg.proxy)
        rp = rate_part(cfg.rate, pp["_lsb"])
        rev = cfg.reversal
        two = rev is not None and rev.order == "regress_first"
        cp = coef_part(model.coef)
        if two:
            try:
                cp2 = coef_part(model.coef_mode2)
            except QuantizeError as exc:
                raise QuantizeError(f"bank 2 (mode 2): {exc}") from None
        fs_q16 = rhu(Fraction(fs) * (1 << 16))
        if not 0 < fs_q16 <= F.UINT32_MAX:
            raise QuantizeError(f"sample rate {fs} Hz outside the fs_q16 word (2^-16 .. 65536 Hz)")
        comb = 0 if rev is None else {"pair": 1, "trend": 2, "none": 3}[rev.combiner]
        settle_n = 0 if rev is None else timing_part(rev.settle_s, fs, "settle_s")
        stale_n = 0 if rev is None else timing_part(rev.max_stale_s, fs, "max_stale_s")
        timing = {"power_on_n": timing_part(power_on_s, fs, "power_on_s"),
                  "exchange_n": timing_part(exchange_s, fs, "exchange_s"),
                  "dwell_n": timing_part(dwell_s, fs, "dwell_s", 1)}
        out_range = F.INT32_SYM * 2.0 ** -F.OUT_FRAC
        for name, coef in (("", model.coef),) + ((("bank 2 (mode 2): ", model.coef_mode2),) if two else ()):
            total = float(sum(abs(Fraction(float(c))) for c in coef))
            if total > out_range:
                raise QuantizeError(f"{name}the bias bound sum |k| = {total:.6g} deg/h exceeds the output word "
                                    f"range +-{out_range:.6g} deg/h")
        ap = aux_part(cfg, pp)
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


MAX_TABLE_BYTES = 4 << 20        # a table.json is ~20 kB, a .bin/.memh under 1 kB; larger is refused unread


def read_table(path) -> Table:
    """A table from table.json (checks CRC and that its fields agree with its words), a binary
    ``.bin`` or a ``.memh``/``.hex`` memory file.  TableError (naming the file) for a file that is
    not a regular file, is over 4 MiB, is not UTF-8 or JSON, repeats a key, nests too deep,
    holds a field of the wrong type, or a ``timing`` field that disagrees with the words
    (:func:`check_timing`)."""
    return read_table_json(path)[0]


def read_table_json(path) -> tuple:
    """``(table, dict)``: the table of ``path`` (see :func:`read_table`) and, for a table.json,
    its checked dict (else None)."""
    from host_tools.jsonread import InputFileError, check_regular, parse_json, read_text

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    try:
        if ext == ".bin":
            check_regular(path, "table")
            with open(path, "rb") as fh:
                data = fh.read(MAX_TABLE_BYTES + 1)
            if len(data) > MAX_TABLE_BYTES:
                raise TableError(f"{path}: more than the {MAX_TABLE_BYTES}-byte limit of a table")
            return Table.from_bytes(data, path), None
        text = read_text(path, "table", MAX_TABLE_BYTES)
        if ext in (".memh", ".hex", ".mem"):
            return Table.from_memh(text, path), None
        d = parse_json(text, path, "table.json", max_depth=32)
    except InputFileError as exc:
        raise TableError(str(exc)) from None
    if not isinstance(d, dict) or d.get("format") != FORMAT:
        raise TableError(f"{path}: not an hdrg table (format {d.get('format') if isinstance(d, dict) else None!r}, "
                         f"expected {FORMAT!r})")
    if d.get("version") != VERSION or isinstance(d.get("version"), bool):
        raise TableError(f"{path}: unsupported table.json version {d.get('version')!r}")
    words = d.get("words")
    if not isinstance(words, list) or not all(isinstance(w, str) and re.fullmatch(r"(0[xX])?[0-9a-fA-F]{1,8}", w)
                                              for w in words):
        raise TableError(f"{path}: field 'words' missing or not a list of hex words (strings of 1 to 8 hex digits)")
    table = Table.from_words([int(w, 16) for w in words], path)
    fields_ = d.get("fields", {})
    if not isinstance(fields_, dict):
        raise TableError(f"{path}: field 'fields' must be an object (field name -> value), not "
                         f"{type(fields_).__name__}")
    vals = table.field_values()
    bad = [k for k, v in fields_.items() if vals.get(k) != v or isinstance(v, bool)]
    if bad:
        raise TableError(f"{path}: fields {', '.join(bad)} disagree with the words (edited by hand?)")
    check_timing(path, d.get("timing"), vals)
    for key in ("coef_dph", "coef_mode2_dph", "coef_quantized_dph", "coef_quantized_mode2_dph"):
        v = d.get(key)
        if v is not None and not (isinstance(v, list) and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                                              for c in v)):
            raise TableError(f"{path}: field '{key}' must be a list of numbers or null, not {type(v).__name__}")
    src = d.get("model_source")
    if src is not None and not isinstance(src, str):
        raise TableError(f"{path}: field 'model_source' must be a string or null, not {type(src).__name__}")
    return table, d


TIMING_WORDS = ("settle_n", "max_stale_n", "power_on_n", "exchange_n", "dwell_n")
TIMING_SECONDS = {"power_on_s": "power_on_n", "exchange_s": "exchange_n", "dwell_s": "dwell_n"}


def check_timing(path, timing, vals: dict) -> None:
    """TableError naming the field unless a table.json's ``timing`` (None: absent) agrees with the
    table's words ``vals`` (field name -> value): ``fs_hz`` gives the word ``fs_q16``, each ``*_n`` is
    its word, each time [s] rounds to its word's samples at ``fs_hz``; no other key.  An export copies
    ``timing``: it must not contradict the words it sits beside."""
    if timing is None:
        return
    if not isinstance(timing, dict):
        raise TableError(f"{path}: field 'timing' must be an object, not {type(timing).__name__}")
    known = ("fs_hz",) + TIMING_WORDS + tuple(TIMING_SECONDS)
    for key, v in timing.items():
        if key not in known:
            raise TableError(f"{path}: field 'timing.{key}': unknown (known: {', '.join(known)})")
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
            raise TableError(f"{path}: field 'timing.{key}': must be a finite number >= 0, not {v!r}")
    fs = timing.get("fs_hz", vals["fs_q16"] / 65536)
    if "fs_hz" in timing and (fs <= 0 or rhu(Fraction(fs) * (1 << 16)) != vals["fs_q16"]):
        raise TableError(f"{path}: field 'timing.fs_hz': {fs:g} Hz disagrees with the word fs_q16 "
                         f"{vals['fs_q16']} ({vals['fs_q16'] / 65536:g} Hz) (edited by hand?)")
    for key in TIMING_WORDS:
        if key in timing and timing[key] != vals[key]:
            raise TableError(f"{path}: field 'timing.{key}': {timing[key]!r} disagrees with the word {key} "
                             f"{vals[key]} (edited by hand?)")
    for key, word in TIMING_SECONDS.items():
        if key in timing and round(timing[key] * fs) != vals[word]:
            raise TableError(f"{path}: field 'timing.{key}': {timing[key]:g} s is {round(timing[key] * fs)} "
                             f"samples at {fs:g} Hz, the word {word} says {vals[word]} (edited by hand?)")
