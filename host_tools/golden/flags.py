"""Status flags of a compensated run log: the ``flags`` column, its counts and the warnings.

The bits are those of the fixed-point pipeline (firmware_ref/formats.py ``FLAGS``; the golden
model host_tools.golden.compensate sets the same bits 1..16 and 64 with the same rules;
docs/RUN_LOG.md):

====  ===============  ======================================================================
bit   name             meaning
====  ===============  ======================================================================
1     proxy_clamped    u outside [-1, 1] was clamped: the proxy is outside the model's range
2     rate_clamped     v outside [-1, 1] was clamped: the proxy rate is outside the model's range
4     warmup           rate estimator in warm-up (not valid)
8     exchange         mode 3 (not valid)
16    stale            mode-reversal output not valid (settling, no window, too old)
32    aux_clamped      the k7 regressor z was clamped (fixed point)
64    input_saturated  input-invalid: an input outside what the sensor can report (both
                       implementations, host_tools.golden.input_check), or (fixed point) an
                       aux word saturated
128   saturated        a saturation inside the fixed-point pipeline (window count, trend, output)
====  ===============  ======================================================================

An aux input outside the range its k7 term was fitted on is clamped on its own, which bit 32 (the
sum z) does not see: a host check (host_tools.golden.regressors.aux_inputs_clamped) counts it into
the metadata ``aux_inputs_clamped`` (:func:`note_aux_inputs`), and :func:`problems` treats it as
extrapolation like the bits.

Clamping (1, 2, 32) keeps a sample valid but means the model is *extrapolated*: above
``WARN_FRACTION`` of the samples `hdrg compensate` warns (``--strict``: refuses).  A saturated
sample (64, 128) is never valid: its output is held like any invalid sample, and any saturation
is warned about (``--strict``: refused).  Input-invalid samples (metadata ``input_invalid``,
host_tools.golden.input_check: count, column, first row, limit) and a stuck proxy (metadata
``input_stuck``: column and rows) are warned about at any count (``--strict``: refused).
"""
from __future__ import annotations

import re
import warnings

import numpy as np

from firmware_ref import vocabulary as VOC
from host_tools.golden.input_check import INPUT_KEY, STUCK_KEY, invalid_message, stuck_message

FLAG_NAMES = {bit: name for bit, (name, _) in VOC.FLAGS.items()}
SATURATION = VOC.FLAG_SAT | VOC.FLAG_INPUT_SAT
EXTRAPOLATION = {VOC.FLAG_PROXY_CLAMPED: "the proxy is outside the model's proxy range",
                 VOC.FLAG_RATE_CLAMPED: "the proxy rate is outside the model's rate range",
                 VOC.FLAG_AUX_CLAMPED: "the k7 regressor is outside its range"}
WARN_FRACTION = 0.01   # warn when more than 1 % of the samples are clamped (extrapolation)
AUX_INPUTS_KEY = "aux_inputs_clamped"   # metadata: 'column count, ...' of aux inputs outside the model's range
POWER_ON_KEY = "power_on_term"   # metadata: why the model's time-since-power-on term may not fit this log
STALE_KEY = "stale_by_age"   # metadata: 'N samples; ...' not valid only because the other mode's window was too old


class CompensationWarning(UserWarning):
    """Extrapolation or saturation in a compensated run log (the text gives the counts)."""


def counts(flags) -> dict:
    """{flag name: number of samples with that bit}, every bit of FLAG_NAMES, in bit order."""
    flags = np.asarray(flags, np.int64)
    return {name: int(np.count_nonzero(flags & bit)) for bit, name in sorted(FLAG_NAMES.items())}


def format_counts(c: dict) -> str:
    """'proxy_clamped 12, saturated 3' (non-zero counts only) or 'none'."""
    return ", ".join(f"{k} {v}" for k, v in c.items() if v) or "none"


def _hold(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    idx = np.where(valid, np.arange(len(values)), -1)
    np.maximum.accumulate(idx, out=idx)
    return np.where(idx >= 0, values[np.maximum(idx, 0)], 0.0)


def add_flags(out, flags):
    """The compensated RunLog ``out`` with the ``flags`` column (int64), saturated samples made
    not valid (their ``rate_dph`` / ``bias_dph`` hold the last valid values), and the metadata
    ``compensation_flags`` (non-zero counts) and ``compensation_valid`` updated."""
    flags = np.asarray(flags, np.int64)
    valid = (np.asarray(out["valid"]) != 0) & ((flags & SATURATION) == 0)
    out = out.with_columns(rate_dph=_hold(out["rate_dph"], valid), bias_dph=_hold(out["bias_dph"], valid),
                           valid=valid.astype(np.float64), flags=flags)
    nvalid = int(np.count_nonzero(valid))
    out.metadata["compensation_valid"] = f"{nvalid} of {len(out)} samples"
    out.metadata["compensation_flags"] = format_counts(counts(flags))
    return out


def note_aux_inputs(out, clamped: dict):
    """Record ``clamped`` ({aux column: samples outside the model's range of it},
    host_tools.golden.regressors.aux_inputs_clamped) in the metadata of the compensated log ``out``
    (AUX_INPUTS_KEY), where :func:`problems` and the user find it."""
    if clamped:
        out.metadata[AUX_INPUTS_KEY] = ", ".join(f"{c} {k}" for c, k in clamped.items())
    return out


def _aux_inputs(out) -> dict:
    text = str(out.metadata.get(AUX_INPUTS_KEY, "") or "").strip()
    pairs = [p.rsplit(" ", 1) for p in text.split(", ")] if text else []
    return {c: int(k) for c, k in pairs}


def problems(out) -> list:
    """The warnings a compensated log deserves: input-invalid samples (INPUT_KEY, first) and a stuck
    proxy (STUCK_KEY; host_tools.golden.input_check), extrapolation above WARN_FRACTION (clamp flags,
    and aux inputs outside the model's range: :func:`note_aux_inputs`), samples lost to a window
    older than the model's max_stale_s above WARN_FRACTION (STALE_KEY, host_tools.golden.compensate.
    note_host_checks), any saturation (fixed point: flags 64 or 128; float: flag 128, or flag 64
    beyond the input-invalid samples); each a sentence with the count, the share and the source."""
    flags = np.asarray(out["flags"], np.int64)
    n = len(flags)
    msgs = []
    for col, k in _aux_inputs(out).items():
        if k > WARN_FRACTION * n:
            msgs.append(f"extrapolation: {k} of {n} samples ({100.0 * k / n:.1f} %) have aux input '{col}' outside "
                        f"the range the model's k7 term was fitted on (clamped to its edge; the aux_clamped flag "
                        f"does not see a single input); the model is applied outside its training data there")
    for bit, what in EXTRAPOLATION.items():
        k = int(np.count_nonzero(flags & bit))
        if k > WARN_FRACTION * n:
            msgs.append(f"extrapolation: {k} of {n} samples ({100.0 * k / n:.1f} %) {FLAG_NAMES[bit]} "
                        f"({what}); the model is applied outside its training data there")
    stale = str(out.metadata.get(STALE_KEY, "") or "").strip()
    m = re.match(r"(\d+)\s+samples?\b(?:\s*;\s*(.*))?$", stale)
    if stale and m is None:
        msgs.append(f"metadata '{STALE_KEY}: {stale}' is not 'N samples; ...': the samples lost to an old "
                    f"mode-reversal window are not known")
    elif m and int(m.group(1)) > WARN_FRACTION * n:
        k = int(m.group(1))
        msgs.append(f"stale: {k} of {n} samples ({100.0 * k / n:.1f} %) are not valid only because the other "
                    f"mode's window is older than the model's max_stale_s" + (f" ({m.group(2)})" if m.group(2) else "")
                    + ": the log's mode-reversal windows are longer than the training runs'; refit on runs with "
                    "this schedule")
    invalid = str(out.metadata.get(INPUT_KEY, "") or "").strip()
    k_in = 0
    if invalid:
        m = re.match(r"(\d+)\s+samples?\s*;\s*\S", invalid)
        if m is None:
            msgs.append(f"metadata '{INPUT_KEY}: {invalid}' is not 'N samples; ...': the input-invalid samples are "
                        f"not known")
        else:
            k_in = int(m.group(1))
            msgs.insert(0, invalid_message(invalid, n))
    stuck = str(out.metadata.get(STUCK_KEY, "") or "").strip()
    if stuck:
        msgs.append(stuck_message(stuck))
    power_on = str(out.metadata.get(POWER_ON_KEY, "") or "").strip()
    if power_on:
        msgs.append(f"power-on term: {power_on}")
    if str(out.metadata.get("compensation_impl", "")).strip() == "fixed":
        k = int(np.count_nonzero(flags & SATURATION))    # an input-invalid word is a saturated word there too
    else:
        k = int(np.count_nonzero(flags & VOC.FLAG_SAT)) + max(0, int(np.count_nonzero(flags & VOC.FLAG_INPUT_SAT)) - k_in)
    if k:
        msgs.append(f"saturation: {k} of {n} samples saturated in fixed point (flags input_saturated/saturated); "
                    f"they are marked not valid")
    return msgs


def report(out, strict: bool = False) -> None:
    """Warn (CompensationWarning) about every :func:`problems` entry; with ``strict`` raise
    ValueError instead (the `hdrg compensate --strict` contract)."""
    msgs = problems(out)
    if strict and msgs:
        raise ValueError(f"{out.source}: " + "; ".join(msgs) + " (--strict)")
    for m in msgs:
        warnings.warn(f"{out.source}: {m}", CompensationWarning, stacklevel=2)


def summary(out) -> str:
    """The console line: samples, valid, flag counts."""
    n = len(out)
    nvalid = int(np.count_nonzero(out["valid"]))
    return (f"{n} samples, {nvalid} valid ({100.0 * nvalid / n:.1f} %); flags: "
            f"{format_counts(counts(out['flags']))}")
