"""The generated documentation of the fixed point, from the code it documents:

* the tables of firmware_ref/FORMATS.md (blocks between ``<!-- BEGIN name -->`` and
  ``<!-- END name -->``) from firmware_ref.formats, table and vocabulary;
* the vocabulary block of the C header firmware_ref/c/hdrg_fw.h (between
  ``/* BEGIN vocabulary`` and ``/* END vocabulary */``) from firmware_ref.vocabulary: one
  ``HDRG_<GROUP>_<NAME>`` constant per code, the status flag bits with their meanings.

``python -m firmware_ref.docgen --update`` rewrites both; tests/test_fixed_formats.py fails when
either is out of date.  Apart from formats and table so that neither imports the other.
"""
from __future__ import annotations

import sys
from pathlib import Path

from firmware_ref import formats as F
from firmware_ref import table as tbl
from firmware_ref import vocabulary as VOC

C_HEADER = Path(__file__).parent / "c" / "hdrg_fw.h"
C_BEGIN = "/* BEGIN vocabulary (generated from firmware_ref/vocabulary.py: python -m firmware_ref.docgen --update) */"
C_END = "/* END vocabulary */"
# C constant groups: (prefix, names); the value of each constant is the index of its name
C_CODE_GROUPS = (("HDRG_PROXY_", VOC.PROXY_KINDS), ("HDRG_EST_", VOC.ESTIMATORS), ("HDRG_COMB_", VOC.COMBINERS),
                 ("HDRG_ORDER_", VOC.ORDERS), ("HDRG_AUXGEN_", VOC.AUX_GENERATORS))


def _c_name(name: str) -> str:
    return name.upper().replace("EXCHANGE_TO_", "EXCH_TO_")


def render_c_vocabulary() -> str:
    """The C header's vocabulary block (without the BEGIN/END lines)."""
    out = []
    for prefix, names in C_CODE_GROUPS:
        out += [f"#define {prefix}{_c_name(n)} {k}u" for k, n in enumerate(names)]
    enums = (("hdrg_aux_kind", "HDRG_AUX_", VOC.AUX_KINDS), ("hdrg_seq_state", "HDRG_ST_", VOC.STATE_NAMES))
    for tag, prefix, names in enums:
        out.append(f"enum {tag} {{")
        out += [f"    {prefix}{_c_name(n)} = {k}{',' if k < len(names) - 1 else ''}" for k, n in enumerate(names)]
        out.append("};")
    out.append("/* status flags (uint8) */")
    const = {getattr(VOC, n): n for n in dir(VOC) if n.startswith("FLAG_")}    # bit -> FLAG_... name
    for bit, (_, text) in VOC.FLAGS.items():
        out.append(f"#define HDRG_{const[bit]} {bit}u".ljust(40) + f"/* {text} */")
    return "\n".join(out)


def splice_c(text: str) -> str:
    """``text`` (the header) with its vocabulary block rendered again."""
    i, j = text.find(C_BEGIN), text.find(C_END)
    if i < 0 or j < i:
        raise ValueError(f"{C_HEADER}: the vocabulary block markers are missing")
    return text[:i + len(C_BEGIN)] + "\n" + render_c_vocabulary() + "\n" + text[j:]


def _md_table(header, rows) -> str:
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(str(x) for x in row) + " |" for row in rows]
    return "\n".join(out)


def render_blocks() -> dict:
    """name -> markdown text of every generated block of FORMATS.md."""
    blocks = {}
    blocks["constants"] = _md_table(
        ("constant", "value", "meaning"),
        [(name, getattr(F, name), doc) for name, doc in (
            ("FREQ_FRAC", "fractional bits of the drive-frequency word"),
            ("TEMP_FRAC", "fractional bits of the temperature word"),
            ("RATE_FRAC", "fractional bits of the raw rate word"),
            ("Q", "fractional bits of u, v, z (Q1.30)"),
            ("DP_CLAMP", "|P - P_REF| clamp"),
            ("SPAN_LSB_MAX", "largest proxy span (word LSB)"),
            ("IIR_FRAC", "extra fractional bits of the iir state"),
            ("N_HIST_MAX", "longest diffn/lsq window n"),
            ("S_BITS_MAX", "largest rate-sum clamp exponent SB"),
            ("MIN_GAIN_BITS", "fewest significant bits of G_U, G_V"),
            ("W_FRAC", "fractional bits of the window mean W"),
            ("Y_FRAC", "fractional bits of y and B"),
            ("SLOPE_FRAC", "fractional bits of the trend slope (per half-sample)"),
            ("SLOPE_MAX", "trend slope clamp"),
            ("D_MAX", "trend distance clamp (half-samples)"),
            ("COUNT_MAX", "saturation of cnt, pos, age, span"),
            ("TIMER_MAX", "largest sequencer timing field"),
            ("ACC_LIMIT", "bound of every Horner accumulator"),
            ("EXP_MIN", "smallest coefficient exponent"),
            ("EXP_MAX", "largest coefficient exponent"),
            ("ALIGN_MAX", "largest alignment shift e_g - E"),
            ("OUT_FRAC", "fractional bits of the output words"),
            ("OUT_SHIFT", "the final rounding shift (Y_FRAC - OUT_FRAC)"),
            ("AUX_MAX_TERMS", "most terms of the aux sum"),
            ("AUX_MAX_CHANNELS", "most aux input words A_c"),
            ("AUX_TERM_WORDS", "table words per aux term"),
            ("AUX_FRAC_MAX", "largest fractional bits AF_c of an aux word"),
            ("AUX_STATE_FRAC", "fractional bits of the filter / decay state"),
            ("AUX_SB_MIN", "smallest filter / decay coefficient shift"),
            ("AUX_SB_MAX", "largest filter / decay coefficient shift"),
            ("AUX_TAU_N_MIN", "shortest time constant fs tau (samples)"),
            ("AUX_TAU_N_MAX", "longest time constant fs tau (samples)"),
            ("K_LIMIT", "largest |K| input"),
            ("SIN_POLY", "osc: sin(pi/2 x) = x sum S_i x^(2i), Q.30"),
            ("SIN_ERR_LSB", "osc: largest error of the integer sine (LSB 2^-30)"),
        )])
    blocks["signals"] = _md_table(("signal", "type", "frac bits", "LSB", "range", "rounding", "overflow", "stage"),
                                  [(s.name, s.ctype, s.frac, s.lsb, s.range, s.rounding, s.overflow, s.stage)
                                   for s in F.SIGNALS])
    blocks["flags"] = _md_table(("bit", "name", "meaning"),
                                [(bit, name, text) for bit, (name, text) in VOC.FLAGS.items()])
    blocks["states"] = _md_table(
        ("id", "state", "mode", "sign", "VS bits", "switches"),
        [(i, VOC.STATE_NAMES[i], F.STATE_MODE[i], F.STATE_SIGN[i], f"0x{F.STATE_VS[i]:02x}",
          " ".join(name for bit, (name, _) in F.VS_BITS.items() if F.STATE_VS[i] & bit) or "-")
         for i in range(len(VOC.STATE_NAMES))])
    blocks["vs_bits"] = _md_table(("bit", "name", "meaning"),
                                  [(f"0x{bit:02x}", name, text) for bit, (name, text) in F.VS_BITS.items()])
    d = F.derivation()
    fig = F.NoiseFigures()
    blocks["derivation"] = _md_table(("quantity", "value"), [
        ("stated drive-frequency noise sigma_f (sim FreqNoise default)", f"{fig.sigma_f_hz:.3g} Hz per sample"),
        ("PLL step (sim PllQuant default)", f"{d['pll_lsb_hz']:.3g} Hz"),
        ("df/dt at 1 degC/min (6227.386 Hz x 20.9 ppm/degC / 60)", f"{d['df_dt_hz_per_s'] * 1e3:.4f} mHz/s"),
        (f"per sample at 1 Hz, in word LSB (2^-{F.FREQ_FRAC} Hz)", f"{d['df_per_sample_lsb']:.1f} LSB"),
        ("rate-term resolution of one LSB per sample at 1 Hz", f"{d['rate_resolution_c_per_min']:.2e} degC/min"),
        ("largest LSB adding <= 1 % to sigma_f: sigma_f sqrt(12((1.01)^2-1))", f"{d['q_f_max_hz']:.3g} Hz (>= {d['f_frac_min']} fractional bits)"),
        (f"noise added by 2^-{F.FREQ_FRAC} Hz to sigma_f (and to the diff noise)", f"{100 * d['f_noise_increase']:.2e} %"),
        (f"smallest frequency noise for which 2^-{F.FREQ_FRAC} Hz adds <= 1 %", f"{d['f_sigma_min_hz']:.3g} Hz per sample"),
        ("frequency word range", f"0 .. {d['f_range_hz']:.0f} Hz"),
        (f"rate-term resolution at {F.FREQ_SUPPORTED_HZ[0]:.0f} Hz / {F.FREQ_SUPPORTED_HZ[1]:.0f} Hz drive (one LSB per sample at 1 Hz)",
         f"{d['rate_resolution_lo_c_per_min']:.3g} / {d['rate_resolution_hi_c_per_min']:.3g} degC/min"),
        ("stated ARW 0.003 deg/sqrt(h): 1-sample sigma at 1 Hz", f"{d['sigma_rate_dph']:.3g} deg/h"),
        ("largest rate LSB adding <= 1 %", f"{d['q_r_max_dph']:.3g} deg/h"),
        ("noise added by 2^-10 deg/h", f"{100 * d['r_noise_increase']:.2e} %"),
        ("rate word range", f"+-{d['r_range_dps']:.1f} deg/s"),
        ("stated board-sensor noise 0.02 degC: largest LSB adding <= 1 %", f"{d['q_t_max_c']:.3g} degC"),
        ("noise added by 2^-16 degC", f"{100 * d['t_noise_increase']:.2e} %"),
        ("final output rounding (half an output LSB)", f"{d['out_rounding_dph']:.3g} deg/h"),
    ])
    rows = []
    for est, n, comb in F.OP_CONFIGS:
        k = F.op_counts(est, n, comb)
        rows.append((f"{est}" + (f" n={n}" if est in ("diffn", "lsq") else ""),
                     comb, k["mul"], k["add"], k["shift"], k["cmp"], k["mem"], k["div_per_window"]))
    for est, n, comb in F.OP_CONFIGS_RTR:
        k = F.op_counts(est, n, comb, "regress_first")
        rows.append((f"{est}" + (f" n={n}" if est in ("diffn", "lsq") else ""),
                     f"{comb} (regress_first)", k["mul"], k["add"], k["shift"], k["cmp"], k["mem"],
                     k["div_per_window"]))
    blocks["ops"] = _md_table(("rate estimator", "combiner", "mul", "add", "shift", "cmp", "mem words",
                               "div per window"), rows)
    blocks["layout"] = _md_table(("word", "field", "type", "meaning"),
                                 [(i, name, typ, text) for i, (name, typ, text) in enumerate(tbl.LAYOUT)]
                                 + [("...", "aux params", "int32", "aux_nparams words (aux_gen 1: below)"),
                                    ("last", "crc32", "uint32", "zlib.crc32 of all preceding words, little-endian bytes")])
    blocks["aux_layout"] = _md_table(
        ("aux param", "field", "type", "meaning"),
        [(i, name, typ, text) for i, (name, typ, text) in enumerate(tbl.AUX_HEADER)]
        + [("2 .. 1+n_chan", "af_c", "uint32", f"fractional bits AF_c of aux word A_c (0..{F.AUX_FRAC_MAX})")]
        + [(f"+{i}", name, typ, text) for i, (name, typ, text) in enumerate(tbl.AUX_TERM_LAYOUT)])
    blocks["aux_coef"] = _md_table(
        ("kind", "id") + tuple(f"c{i}" for i in range(6)),
        [(kind, k) + tuple(tbl.AUX_COEF[kind][i] if i < len(tbl.AUX_COEF[kind]) else "0" for i in range(6))
         for k, kind in enumerate(VOC.AUX_KINDS)])
    rows = []
    for kind, filt, pw in F.AUX_OP_ROWS:
        k = F.aux_op_counts(kind, filt, pw)
        label = {"sum": "stage (once)"}.get(kind, kind) + (" tau > 0" if filt else "") + (f" power {pw}" if pw > 1 else "")
        rows.append((label, k["mul"], k["add"], k["shift"], k["cmp"], k["mem"]))
    blocks["aux_ops"] = _md_table(("aux term", "mul", "add", "shift", "cmp", "mem words"), rows)
    return blocks


def splice(text: str, blocks: dict) -> str:
    """Replace every ``<!-- BEGIN name -->...<!-- END name -->`` block of ``text``."""
    for name, body in blocks.items():
        begin, end = f"<!-- BEGIN {name} -->", f"<!-- END {name} -->"
        i, j = text.find(begin), text.find(end)
        if i < 0 or j < i:
            raise ValueError(f"generated block {name!r} markers missing")
        text = text[:i + len(begin)] + "\n" + body + "\n" + text[j:]
    return text


def formats_md_path() -> Path:
    return Path(__file__).with_name("FORMATS.md")


if __name__ == "__main__":  # python -m firmware_ref.docgen [--update]
    path = formats_md_path()
    new = splice(path.read_text(encoding="utf-8"), render_blocks())
    new_h = splice_c(C_HEADER.read_text(encoding="utf-8"))
    if "--update" in sys.argv[1:]:
        path.write_text(new, encoding="utf-8")
        C_HEADER.write_text(new_h, encoding="utf-8")
        print(f"{path}, {C_HEADER}: generated blocks updated")
    else:
        print(new)
        print(new_h)
