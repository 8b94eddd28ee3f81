"""Export a coefficient table for firmware and FPGA: `hdrg export TABLE --format c|json|mem|all -o DIR`.

One versioned layout (firmware_ref/table.py, FORMATS.md "Coefficient table layout"): 32-bit
words, signed fields two's complement, CRC-32 (IEEE, zlib.crc32) of the preceding words' little-
endian bytes last.  Every export holds exactly these words:

* ``c``    ``NAME.h``: ``static const uint32_t NAME_UPPER[NAME_UPPER_WORDS]`` (one word per line,
  commented with its field, type, decoded value and, for the mantissas, the coefficient in deg/h,
  quantized and float original), ``#define``s of the magic, the layout version, the word count
  and the CRC-32; C99, includes only <stdint.h>.  The C twin loads it with
  ``hdrg_init(&st, NAME_UPPER, NAME_UPPER_WORDS, NULL)`` (firmware_ref/c/README.md).
* ``json`` ``NAME.json``: a table.json (format ``hdrg-fixed-table``, readable by
  ``host_tools.fixed.quantize.read_table`` and ``hdrg compensate --table``) with the words, CRC, decoded
  fields, the layout description and, when the source is a table.json, the float originals
  (model, ``coef_dph``) and the quantizer's report.
* ``mem``  ``NAME.memh``: ``$readmemh`` text, one 8-digit hex word per line, address 0 first.

Layout version 4 (version 3's words with the drive-frequency word at 2^-15 Hz; the iir starts at power-on): the words carry ``order``, ``n_banks`` and bank 2's
exponents and mantissas (words 47..71; the C header comments bank 2's coefficients in deg/h, the
JSON adds ``coef_quantized_mode2_dph``).  A version-1 TABLE (``.memh``/``.bin`` of an older
export) is read as combine_first with one bank and written as version 4; a version-1/2 table with
the iir rate estimator, and a version-1..3 table that reads the drive frequency (its centres in the
old 2^-18 Hz word), are refused (quantize its model again).

TABLE is a table.json (``hdrg quantize``), a binary ``.bin`` or a ``.memh``/``.hex``/``.mem``
file; it is checked (magic, version, length, CRC, field ranges, the JSON's field types) before
anything is written.  A table.json's float originals (its model, ``coef_dph``, the quantizer's
report) are kept only when quantizing that model again, at the table.json's sequencer timing,
reproduces the table's words exactly and ``coef_dph`` is the model's (:func:`check_originals`);
otherwise (words or CRC edited, model or coefficients edited, model unreadable) they are left
out: the header and the JSON carry a note instead, and :func:`load` warns.

Nothing from a file reaches the header as code: ``--name`` must be a C identifier (a letter, then
letters, digits, ``_``; at most 63 characters; not a name C or <stdint.h> reserves, e.g. one that
starts with ``_`` or upper-cases to ``UINT32_MAX``); free text (the model's file name, a table's
``model_source``) is quoted only inside one-line comments by :func:`comment_text` (printable
ASCII, escapes for anything else, no ``*/``, ``/*`` or ``??``), so the header defines the table's
array, its four macros and its include guard and nothing else.
"""
from __future__ import annotations

import json
import os
import re
import warnings
from pathlib import Path

from firmware_ref import formats as F
from firmware_ref.table import LAYOUT, MAGIC, N_FIXED, VERSION as LAYOUT_VERSION, Table
from firmware_ref.terms import K_AUX, TERM_NAMES, TERM_POWERS
from host_tools.fixed.quantize import FORMAT, VERSION, quantized_coef, read_table_json

FORMATS = ("c", "json", "mem")
EXTENSIONS = {"c": ".h", "json": ".json", "mem": ".memh"}
DEFAULT_NAME = "hdrg_table"


def load(path) -> tuple[Table, dict | None]:
    """``(table, table_json_dict)``: the checked table of ``path`` and, for a table.json, its
    dict (the float originals and the quantizer's report, when they reproduce the table:
    :func:`check_originals`, else a warning and a dict with a ``note`` instead of them), else None."""
    table, info = read_table_json(path)
    if info is None:
        return table, None
    checked = check_originals(table, info, os.fspath(path))
    if checked is not info:
        warnings.warn(checked["note"], stacklevel=2)
    return table, checked


ORIGINAL_KEYS = ("model", "model_source", "coef_dph", "coef_mode2_dph")


def check_originals(table: Table, info: dict, source: str = "table.json") -> dict:
    """``info`` (a table.json dict) when its float originals belong to ``table``: quantizing
    ``info["model"]`` with ``info["timing"]``'s exchange, dwell and power-on times [s] gives
    exactly the table's words, and ``coef_dph`` / ``coef_mode2_dph`` are that model's.  Otherwise
    a new dict without the originals and the quantizer's report (``model``, ``model_source``,
    ``coef_dph`` None) whose ``note`` says why.  A dict without originals is returned as it is."""
    if all(info.get(k) is None for k in ORIGINAL_KEYS):
        return info
    problem = _originals_problem(table, info)
    if problem is None:
        return info
    note = (f"{source}: the float originals (model, coef_dph, quantizer report) are left out: {problem} "
            f"(edited after quantization?)")
    return {"model": None, "model_source": None, "coef_dph": None, "note": note}


def _originals_problem(table: Table, info: dict) -> str | None:
    """Why ``info``'s float originals do not belong to ``table`` (see :func:`check_originals`), or None."""
    from host_tools.errors import HdrgError
    from host_tools.fixed.quantize import quantize
    from host_tools.golden.model import BiasModel

    if not isinstance(info.get("model"), dict):
        return "the table.json has no model to check them against"
    timing = info.get("timing")
    keys = ("exchange_s", "dwell_s", "power_on_s")
    if not (isinstance(timing, dict) and all(isinstance(timing.get(k), (int, float)) and
                                             not isinstance(timing.get(k), bool) for k in keys)):
        return "the table.json has no sequencer timing (timing.exchange_s, dwell_s, power_on_s)"
    try:
        model = BiasModel.from_dict(info["model"], "model of the table.json")
        words = quantize(model, *(float(timing[k]) for k in keys), n_random=16).table.to_words()
    except (HdrgError, ValueError, OverflowError) as exc:
        return f"its model does not quantize ({exc})"
    if words != table.to_words():
        diff = [i for i, (a, b) in enumerate(zip(words, table.to_words())) if a != b]
        where = f"word(s) {', '.join(map(str, diff[:8]))}" if diff and len(words) == len(table.to_words()) \
            else "the word count"
        return f"quantizing its model gives other words ({where} differ)"
    for key, coef in (("coef_dph", model.coef), ("coef_mode2_dph", model.coef_mode2)):
        value = info.get(key)
        if value is not None and (coef is None or [float(c) for c in value] != [float(c) for c in coef]):
            return f"'{key}' is not its model's"
    return None


def _group_exponent(table: Table, k: int, bank: int = 1) -> int:
    b = table.bank(bank)
    return b.e_7 if k == K_AUX else b.e_row[TERM_POWERS[k][0]]


# upper-cased names that <stdint.h> or the C implementation own (a clash would not compile, or
# would redefine a macro): the limits and constant macros, and every name beginning with '_'
_RESERVED = re.compile(r"_.*|U?INT\w*_(MAX|MIN|C)|(SIZE|PTRDIFF|SIG_ATOMIC|WCHAR|WINT)_(MAX|MIN)")
COMMENT_LIMIT = 200         # characters of free text (a file name) quoted in a comment


def check_name(name: str) -> str:
    """``name`` when it can be the header's symbol (see the module doc), else ValueError."""
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]{0,62}", name):
        raise ValueError(f"--name {name!r}: must be a C identifier of at most 63 characters (a letter, then "
                         f"letters, digits, '_')")
    if _RESERVED.fullmatch(name.upper()):
        raise ValueError(f"--name {name!r}: {name.upper()} is reserved by C or <stdint.h>; choose another name")
    return name


def comment_text(text, limit: int = COMMENT_LIMIT) -> str:
    """``text`` made safe inside a C block comment on one line: printable ASCII only (any other
    character, newlines included, as a Python escape ``\\n``, ``\\x1b``, ``\\u00e9``), no ``*/`` or
    ``/*`` (``* /``, ``/ *``: a comment cannot be closed or warned about), no ``??`` (a trigraph), at
    most ``limit`` characters (then ``...``)."""
    s = str(text).encode("unicode_escape").decode("ascii")
    s = "".join(c if " " <= c <= "~" else "?" for c in s)
    while "*/" in s or "/*" in s or "??" in s:
        s = s.replace("*/", "* /").replace("/*", "/ *").replace("??", "? ?")
    if len(s) > limit:
        s = s[:limit - 3].rstrip("\\") + "..."
    return s


def _coef_list(info: dict | None, key: str):
    """``info[key]`` (a table.json's float originals) as floats, or None when absent; ValueError
    naming the field when it is not a list of numbers."""
    value = (info or {}).get(key)
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                              for c in value):
        raise ValueError(f"table.json field {key!r}: must be a list of numbers (the float coefficients), not "
                         f"{type(value).__name__}")
    return [float(c) for c in value]


def c_header(table: Table, name: str = DEFAULT_NAME, info: dict | None = None) -> str:
    """The C99 header text (see the module doc); ``name`` gives the guard and the symbols
    (upper-cased), ``info`` a table.json dict for the float originals in the comments."""
    sym = check_name(name).upper()
    words = table.to_words()
    vals = table.field_values()
    coef = _coef_list(info, "coef_dph")
    coef2 = _coef_list(info, "coef_mode2_dph")
    src = (info or {}).get("model_source")
    src = None if src is None else comment_text(src)
    frac_p = F.FREQ_FRAC if table.proxy_kind == 0 else F.TEMP_FRAC
    aux_names = table.param_names()          # aux parameter words (FORMATS.md "Aux generators")
    lines = [
        f"/* hdrg coefficient table: layout version {LAYOUT_VERSION}, {len(words)} words, "
        f"CRC-32 0x{words[-1]:08x}.",
        " * Generated by `hdrg export`" + (f" from the model {src}" if src else "") + "; do not edit.",
        " *",
        *([f" * Note: {comment_text(info['note'], limit=1000)}", " *"] if (info or {}).get("note") else []),
        f" * Layout: firmware_ref/FORMATS.md \"Coefficient table layout (version {LAYOUT_VERSION})\": 32-bit words,",
        " * signed fields two's complement, the last word the CRC-32 (IEEE 802.3, zlib.crc32) of all",
        " * preceding words as little-endian bytes.",
        f" * Load (firmware_ref/c): hdrg_init(&st, {sym}, {sym}_WORDS, NULL).",
        " *",
        " * Formats: proxy word P "
        + (f"= F, uint32, LSB 2^-{F.FREQ_FRAC} Hz" if table.proxy_kind == 0
           else f"= T, int32, LSB 2^-{F.TEMP_FRAC} degC")
        + f"; rate word R int32, LSB 2^-{F.RATE_FRAC} deg/h;",
        f" * u, v, z int32 Q1.{F.Q}; u = RHU((P - p_ref) g_u + u_off, sh_u); v = RHU(S g_v, sh_v);",
        " * coefficient k = m_k 2^-e_g deg/h (g: Horner row u^i, or k7); Horner accumulator LSB",
        f" * 2^-e_acc deg/h; bias B and combined y LSB 2^-{F.Y_FRAC} deg/h; OUT, BIAS int32 LSB "
        f"2^-{F.OUT_FRAC} deg/h.",
        f" * Proxy word fractional bits here: {frac_p}.  RHU = round half up.",
        f" * Order {table.order} ({F.ORDERS[table.order]}), {table.n_banks} coefficient bank(s), combiner "
        f"{table.combiner} ({F.COMBINERS[table.combiner]})"
        + ("; bank 2 (m2_k 2^-e2_g) on mode-2 samples; the window sums take r = c - B." if table.n_banks == 2
           else "."),
        " */",
        f"#ifndef {sym}_H_INCLUDED",
        f"#define {sym}_H_INCLUDED",
        "",
        "#include <stdint.h>",
        "",
        f"#define {sym}_MAGIC 0x{MAGIC:08x}u",
        f"#define {sym}_LAYOUT_VERSION {LAYOUT_VERSION}u",
        f"#define {sym}_WORDS {len(words)}u",
        f"#define {sym}_CRC32 0x{words[-1]:08x}u",
        "",
        f"static const uint32_t {sym}[{sym}_WORDS] = {{",
    ]
    for i, w in enumerate(words):
        if i < N_FIXED:
            fname, typ, meaning = LAYOUT[i]
            v = vals[fname]
            text = f"{i:2d} {fname:<12s} {typ:<6s} {v}: {meaning}"
            bank = 2 if fname.startswith("m2_") else 1
            if fname.startswith(("m_", "m2_")) and (bank == 1 or table.n_banks == 2):
                k = int(fname.split("_")[1])
                e = _group_exponent(table, k, bank)
                text = (f"{i:2d} {fname:<12s} {typ:<6s} {v}: k{k} ({TERM_NAMES[k]}) = m 2^-{e} = "
                        f"{v * 2.0 ** -e:.9g} deg/h" + (" (bank 2)" if bank == 2 else ""))
                cf = coef if bank == 1 else coef2
                if cf is not None and k < len(cf):
                    text += f" (float {float(cf[k]):.9g})"
        elif i < len(words) - 1:
            text = f"{i:2d} {aux_names[i - N_FIXED]:<12s} int32  {w - (1 << 32) if w >= 1 << 31 else w}"
        else:
            text = f"{i:2d} crc32        uint32 CRC-32 of words 0..{i - 1}"
        text = comment_text(text, limit=1000)
        lines.append(f"    0x{w:08x}u, /* {text} */")
    lines += ["};", "", f"#endif /* {sym}_H_INCLUDED */", ""]
    return "\n".join(lines)


def decode_c_header(text: str, name: str = DEFAULT_NAME) -> list:
    """The words of a header written by :func:`c_header` (for round-trip checks)."""
    sym = name.upper()
    m = re.search(r"static const uint32_t " + re.escape(sym) + r"\[[^\]]*\]\s*=\s*\{(.*?)\};", text, re.S)
    if m is None:
        raise ValueError(f"no array {sym} in the header")
    body = re.sub(r"/\*.*?\*/", "", m.group(1), flags=re.S)
    return [int(x, 16) for x in re.findall(r"0x([0-9a-fA-F]{8})u", body)]


def json_dict(table: Table, info: dict | None = None) -> dict:
    """The table.json dict: ``info`` (a table.json dict, float originals) with the words, CRC and
    fields of ``table``, plus the layout; without ``info`` the minimal table.json."""
    words = table.to_words()
    d = dict(info) if info else {"model": None, "model_source": None, "coef_dph": None}
    d.update({
        "format": FORMAT,
        "version": VERSION,
        "layout_version": LAYOUT_VERSION,
        "fields": {k: int(v) for k, v in table.field_values().items()},
        "words": [f"0x{w:08x}" for w in words],
        "crc32": f"0x{words[-1]:08x}",
        "coef_quantized_dph": [float(c) for c in quantized_coef(table)],
        **({"coef_quantized_mode2_dph": [float(c) for c in quantized_coef(table, 2)]} if table.n_banks == 2 else {}),
        "layout": [{"word": i, "field": n, "type": t, "meaning": m} for i, (n, t, m) in enumerate(LAYOUT)]
        + [{"word": len(words) - 1, "field": "crc32", "type": "uint32",
            "meaning": "zlib.crc32 of all preceding words, little-endian bytes"}],
        "exported_by": "hdrg export",
    })
    return d


def export(table: Table, outdir, formats=FORMATS, name: str = DEFAULT_NAME, info: dict | None = None) -> dict:
    """Write the exports of ``table`` into ``outdir`` (created if missing); returns
    ``{format: Path}``.  ``formats``: any of 'c', 'json', 'mem'."""
    check_name(name)
    bad = [f for f in formats if f not in FORMATS]
    if bad:
        raise ValueError(f"unknown export format(s) {', '.join(bad)}; choose from {', '.join(FORMATS)}")
    from host_tools.atomic import atomic_open

    outdir = Path(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise NotADirectoryError(f"{outdir}: exists and is not a directory (-o names the directory to write into)")
    outdir.mkdir(parents=True, exist_ok=True)
    paths = {}
    for fmt in formats:
        path = outdir / (name + EXTENSIONS[fmt])
        with atomic_open(path, "w", encoding="utf-8") as fh:
            if fmt == "c":
                fh.write(c_header(table, name, info))
            elif fmt == "json":
                json.dump(json_dict(table, info), fh, indent=2)
                fh.write("\n")
            else:
                fh.write(table.to_memh())
        paths[fmt] = path
    return paths
