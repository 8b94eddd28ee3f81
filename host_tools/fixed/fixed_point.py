"""The host side of the fixed-point path (``hdrg compensate --impl fixed``): run log -> input
words (:func:`log_words`), model -> table (host_tools.fixed.quantize), the words through the firmware
reference (firmware_ref.kernel / firmware_ref.compensate.run_reference) and back to deg/h
(:func:`compensate_log`); the words back to a float log (:func:`dequantized_log`, the reference
input of the |fixed - golden| bound).

These need both the golden model (run logs, models, the quantizer) and the bit-accurate reference,
so they live here: firmware_ref depends on nothing in host_tools (docs/ARCHITECTURE.md).
The input stage: the per-sample input-invalid bit (the pipeline's input; host_tools.golden.
input_check.input_flags on ``rate_dph`` and the proxy column, with the F word's range) is made
here; bit 64 of a saturated aux channel word (which does not set the bit) is added here too.
"""
from __future__ import annotations

import numpy as np

from firmware_ref import formats as F
from firmware_ref import inputs
from firmware_ref.aux import aux_columns
from firmware_ref.compensate import run_reference
from host_tools.golden import runlog as rl
from host_tools.golden.checks import check_sample_rate
from host_tools.fixed.quantize import quantize
from host_tools.fixed.quantize_parts import aux_channel_fracs
from host_tools.golden.input_check import FREQ_RAIL, RANGE_KEYS, input_flags, model_columns
from host_tools.golden.regressors import power_on_counter


def log_words(log, config) -> dict:
    """Input words of a run log under a ModelConfig: ``p`` (proxy), ``r`` (rate), ``mode``,
    ``restart``, ``z`` (0: the external Z word is not used by the host), ``invalid`` (uint8[n]: the
    input-invalid bit, host_tools.golden.input_check.input_flags with ``word_range`` on
    input_check.model_columns: the rate, proxy or an aux-read F / T word outside what the sensor can report or its word can hold), ``input_sat`` (bool[n]:
    an aux channel word the pipeline reads was saturated), and for an aux 'sum' generator the channel
    words it reads: ``f`` (F), ``t`` (T), ``aux`` (int64[n, n_chan]: the aux_* columns of
    firmware_ref.aux.aux_columns as A_c words with the quantizer's AF_c) and ``k`` (the counter
    K = rint(t_s fs), fs of the aux params, as the golden); else those are None."""
    pname, pcol = log.proxy(config.proxy.kind)
    p, _ = inputs.proxy_words(pcol, config.proxy.kind)
    r, _ = inputs.rate_words(log.rate_dph)
    bad, _ = input_flags(log, model_columns(log, config), word_range=True)
    n = len(log)
    restart = np.zeros(n, np.uint8)
    restart[np.asarray(log.segments, np.int64)] = 1
    if n:
        restart[0] = 1
    out = {"p": p, "r": r, "mode": np.asarray(log.mode, np.int64), "restart": restart, "z": np.zeros(n, np.int64),
           "f": None, "t": None, "aux": None, "k": None, "invalid": bad.astype(np.uint8)}
    sat = np.zeros(n, bool)
    if config.aux.generator != "none":
        where = f"{log.source}: the aux generator"
        used = {tm["column"] for tm in config.aux.terms if tm["gen"] == "input"}
        for col in sorted(used):
            if col not in log:
                raise ValueError(f"{where} needs column '{col}', which the log lacks "
                                 f"(columns: {', '.join(log.columns)})")
        if "freq_hz" in log:
            out["f"], fsat = inputs.freq_words(log["freq_hz"])
            sat |= fsat if "freq_hz" in used and pname != "freq_hz" else False
        if "temp_c" in log:
            out["t"], tsat = inputs.temp_words(log["temp_c"])
            sat |= tsat if "temp_c" in used and pname != "temp_c" else False
        cols = aux_columns(config.aux)
        fracs = aux_channel_fracs(config.aux)
        a = np.zeros((n, len(cols)), np.int64)
        for c, (col, frac) in enumerate(zip(cols, fracs)):
            a[:, c], asat = inputs.aux_channel_words(log[col], frac, col)
            sat |= asat
        out["aux"] = a
        k = power_on_counter(log.t_s, config.aux.params["fs"])
        if n and int(np.max(np.abs(k))) > F.K_LIMIT:
            raise ValueError(f"{where}: the sample counter rint(t_s fs) exceeds 2^62")
        out["k"] = k
    out["input_sat"] = sat
    return out


def check_table_matches(table, model) -> None:
    """Refuse a table whose data flow differs from the model's (a table of another model)."""
    expect = quantize(model).table
    diffs = [name for name in ("proxy_kind", "p_ref", "g_u", "u_off", "sh_u", "rate_est", "rate_n", "rate_shift",
                               "rate_warmup", "g_v", "sh_v", "combiner", "settle_n", "max_stale_n", "mant",
                               "e_row", "e_7", "e_acc", "aux_gen", "aux_params", "order", "n_banks", "mant2",
                               "e_row2", "e_7_2", "e_acc2")
             if getattr(table, name) != getattr(expect, name)]
    if diffs:
        raise ValueError(f"--table: the table does not match the model {model.source} "
                         f"(fields differ: {', '.join(diffs)}); quantize this model again")


def compensate_log(log, model, table=None, impl: str = "numba", return_flags: bool = False):
    """``hdrg compensate --impl fixed``: the compensated run log computed in fixed point.

    ``table``: a firmware_ref.table.Table (checked against the model) or None (the model is
    quantized on the fly by host_tools.fixed.quantize).  The log is converted to words
    (firmware_ref.inputs), run through the kernel (``impl='numba'``) or the Python reference
    (``'python'``) - an aux 'sum' generator runs in fixed point from the log's channels (F, T,
    aux_* words and K, :func:`log_words`), 'none' gives z = 0 - and the output words are written
    back in deg/h: ``rate_dph`` (OUT),
    ``bias_dph`` (BIAS), ``valid`` 1.0/0.0, the same columns as the float path; the metadata adds
    ``compensation_table_crc``.  Model/log mismatches are refused as in the float path.  With
    ``return_flags`` returns ``(log, flags)``, flags uint8[n] (formats.FLAGS bits)."""
    if str(log.metadata.get("compensated", "")).strip().lower() == "yes" or "bias_dph" in log:
        raise ValueError(f"{log.source}: the log is already compensated (metadata 'compensated: yes' "
                         f"or a 'bias_dph' column)")
    cfg = model.config
    check_sample_rate(log, cfg.rate.fs)
    if cfg.reversal is None and log.reversal:
        raise ValueError(f"{log.source}: the model is for force-to-rebalance (no mode reversal) "
                         f"but the log uses mode reversal (modes 1/2/3)")
    if cfg.reversal is not None and not log.reversal:
        raise ValueError(f"{log.source}: the model is for mode reversal "
                         f"(combiner {cfg.reversal.combiner!r}) but the log is FTR (all mode 0)")
    if cfg.reversal is not None and np.any(np.asarray(log.mode) == rl.MODE_FTR):
        row = int(np.argmax(np.asarray(log.mode) == rl.MODE_FTR))
        raise ValueError(f"{log.source}: row {row}: mode 0 (FTR) sample in a mode-reversal log")
    if table is None:
        table = quantize(model).table
    else:
        check_table_matches(table, model)
    w = log_words(log, cfg)
    chans = {name: w[name] for name in ("f", "t", "aux", "k", "invalid")}
    if impl == "numba":
        from firmware_ref.kernel import run_words
        res = run_words(table, w["p"], w["r"], w["mode"], w["restart"], w["z"], **chans)
    elif impl == "python":
        res = run_reference(table, w["p"], w["r"], w["mode"], w["restart"], w["z"], **chans)
    else:
        raise ValueError(f"impl must be 'numba' or 'python', not {impl!r}")
    valid = res["valid"].astype(bool)
    flags = res["flags"] | np.where(w["input_sat"], F.FLAG_INPUT_SAT, 0).astype(np.uint8)
    out = log.with_columns(rate_dph=inputs.out_dph(res["out"]), bias_dph=inputs.out_dph(res["bias"]),
                           valid=valid.astype(np.float64))
    nvalid = int(np.count_nonzero(valid))
    out.metadata.update({
        "compensated": "yes",
        "compensation_model": model.source,
        "compensation_impl": "fixed",
        "compensation_terms": ",".join(f"k{k}" for k in model.terms),
        "compensation_valid": f"{nvalid} of {len(log)} samples",
        "compensation_table_crc": f"0x{table.crc:08x}",
    })
    nsat = int(np.count_nonzero(flags & (F.FLAG_SAT | F.FLAG_INPUT_SAT)))
    if nsat:
        out.metadata["compensation_saturated"] = f"{nsat} samples"
    return (out, flags) if return_flags else out


def dequantized_log(log, model):
    """The reference input of the |fixed - golden| bound: ``log`` with every column the fixed path
    reads (proxy, rate, and the channels of an aux generator) replaced by the value of its input
    word, so that input quantization, accounted for separately (FORMATS.md), is not counted."""
    cfg = model.config
    w = log_words(log, cfg)
    out = log.with_columns()
    if cfg.proxy.column == "freq_hz" and not str(out.metadata.get(RANGE_KEYS["freq_hz"], "")).strip():
        # the F word's range: the golden flags its rail exactly where the fixed path (word_range) does
        out.metadata[RANGE_KEYS["freq_hz"]] = f"0..{FREQ_RAIL * 2.0 ** -F.FREQ_FRAC!r}"
    cols = {cfg.proxy.column: inputs.from_words(w["p"], inputs.proxy_frac(cfg.proxy.kind)),
            "rate_dph": inputs.from_words(w["r"], F.RATE_FRAC)}
    if w["f"] is not None:
        cols["freq_hz"] = inputs.from_words(w["f"], F.FREQ_FRAC)
    if w["t"] is not None:
        cols["temp_c"] = inputs.from_words(w["t"], F.TEMP_FRAC)
    for c, (col, fr) in enumerate(zip(aux_columns(cfg.aux), aux_channel_fracs(cfg.aux))):
        cols[col] = inputs.from_words(w["aux"][:, c], fr)
    return out.with_columns(**cols)
