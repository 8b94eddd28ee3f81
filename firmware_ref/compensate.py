"""Compensated output and status flags in fixed point: the whole per-sample pipeline.

Per sample (Python-integer reference :class:`Pipeline`; the numba kernel firmware_ref.kernel is
bit-identical)::

    state/mode  = sequencer timer (self-timed) or the logged mode
    u, uc       = proxy_u(P)                          (firmware_ref.proxy)
    v, vc, warm = rate.step(P, restart)               (firmware_ref.rate)
    z, zc       = aux_gen 0: clamp(Z, +-2^30); aux_gen 1: the generators (firmware_ref.aux) on
                  the channel words (F, T, A_c), K, mode, restart (or power-on), S, warm
    B           = evaluate(u, v, z, bank)             (firmware_ref.evaluator, every sample; bank 2
                                                       on mode-2 samples of a two-bank table)
    cvalid, y   = combiner.step(mode, R, restart, B, warm)   (firmware_ref.sequencer; y held;
                                                       order 1 accumulates r = c - B)
    valid       = cvalid and not warm and mode != 3
    if valid:   OUT = symsat32(RHU(y - B, 11)) (order 0) or symsat32(RHU(y, 11)) (order 1: B is
                in y already); BIAS = symsat32(RHU(B, 11))   (held otherwise; 0 before the first)
    flags       = 1 uc | 2 vc | 4 warm | 8 (mode == 3) | 16 (not cvalid and mode != 3)
                  | 32 zc | 128 (any saturation: window count, trend, residual r, OUT, BIAS)

OUT and BIAS are int32 words, LSB 2^-10 deg/h; the hold is not reset at restarts (as the golden
host_tools.compensate).  K is the sample counter since power-on (the golden's ``rint(t_s fs)``);
when not given, the pipeline counts itself: K = the previous sample's K + 1, 0 at power-on.  Bit 64 (an input value saturated when converted to a word) is added by
the host side (:func:`compensate_log`).

:func:`compensate_log` is ``hdrg compensate --impl fixed``: run log + model (+ optional table)
-> compensated run log with the same columns as the float path.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_ref import formats as F
from firmware_ref import inputs
from firmware_ref.arith import clamp, rshift_round, sat_signed
from firmware_ref.aux import AuxStage, aux_columns, channel_rows
from firmware_ref.evaluator import evaluate
from firmware_ref.proxy import proxy_u
from firmware_ref.rate import RateState
from firmware_ref.sequencer import Sequencer


@dataclass
class Sample:
    """One sample of the pipeline's outputs (words) and intermediates."""

    out: int
    bias: int
    valid: bool
    flags: int
    u: int
    v: int
    z: int
    b: int
    y: int
    s: int
    state: int
    vs: int
    sign: int
    acc: int
    cnt: int


class Pipeline:
    """The per-sample reference (see the module doc)."""

    def __init__(self, table, self_timed: bool = False):
        self.table = table
        self.rate = RateState(table)
        self.seq = Sequencer(table, self_timed)
        self.aux = AuxStage(table) if table.aux_gen == 1 else None
        self.kc = 0                  # the internal sample counter (K when not given)
        self.fresh = True            # power-on: the aux generators start as at a restart
        self.out_hold = 0
        self.bias_hold = 0

    def step(self, p: int, r: int, mode, restart: bool = False, z: int = 0, chan=(), k: int | None = None) -> Sample:
        """One sample: proxy word ``p``, rate word ``r``, logged ``mode`` (None: self-timed),
        ``restart``, external ``z`` (aux_gen 0), channel words ``chan`` by code (aux_gen 1) and
        the counter ``k`` (None: the internal count)."""
        t = self.table
        state, mode = self.seq.mode_step(mode, restart)
        u, uc = proxy_u(p, t)
        v, vc, warm, s = self.rate.step(p, restart)
        k = self.kc if k is None else int(k)
        self.kc = min(k + 1, F.K_LIMIT)
        if self.aux is not None:
            z, zc, _ = self.aux.step(chan, k, mode, restart or self.fresh, s, warm)
        else:
            z, zc = clamp(z, -F.ONE, F.ONE)
        self.fresh = False
        b, _ = evaluate(u, v, z, t, bank=t.bank_of_mode(mode))
        so = self.seq.combine_step(state, mode, r, restart, b, warm)
        valid = so.valid and not warm and mode != 3
        sat = so.sat
        if valid:
            o, s1 = sat_signed(rshift_round(so.y - (b if t.order == 0 else 0), F.OUT_SHIFT), 32)
            bw, s2 = sat_signed(rshift_round(b, F.OUT_SHIFT), 32)
            sat = sat or s1 or s2
            self.out_hold, self.bias_hold = o, bw
        flags = ((F.FLAG_PROXY_CLAMPED if uc else 0) | (F.FLAG_RATE_CLAMPED if vc else 0)
                 | (F.FLAG_WARMUP if warm else 0) | (F.FLAG_EXCHANGE if mode == 3 else 0)
                 | (F.FLAG_STALE if (not so.valid and mode != 3) else 0)
                 | (F.FLAG_AUX_CLAMPED if zc else 0) | (F.FLAG_SAT if sat else 0))
        return Sample(self.out_hold, self.bias_hold, valid, flags, u, v, z, b, so.y, s, so.state, so.vs, so.sign,
                      so.acc, so.cnt)


def run_reference(table, p, r, mode=None, restart=None, z=None, self_timed: bool = False, f=None, t=None,
                  aux=None, k=None) -> dict:
    """The Python reference over arrays; same arguments and the same dict as
    firmware_ref.kernel.run_words with ``detail=True`` (plus ``vs``, ``sign``, ``acc``, ``cnt``),
    as int64/uint8 arrays."""
    n = len(p)
    pipe = Pipeline(table, self_timed)
    rows = channel_rows(table, n, p, f, t, aux) if table.aux_gen == 1 else []
    chans = list(zip(*[row.tolist() for row in rows])) if rows else [()] * n
    kin = None if k is None else np.asarray(k, np.int64).tolist()
    cols = {name: [] for name in ("out", "bias", "valid", "flags", "u", "v", "z", "b", "y", "s", "state", "vs",
                                  "sign", "acc", "cnt")}
    for i in range(n):
        s = pipe.step(int(p[i]), int(r[i]), None if mode is None else int(mode[i]),
                      bool(i == 0 or (restart is not None and restart[i])), 0 if z is None else int(z[i]),
                      chans[i], None if kin is None else kin[i])
        for name in cols:
            cols[name].append(int(getattr(s, name)))
    out = {name: np.array(vals, np.int64) for name, vals in cols.items()}
    out["valid"] = out["valid"].astype(np.uint8)
    out["flags"] = out["flags"].astype(np.uint8)
    return out


# -- host side: run logs --------------------------------------------------------------------------

def log_words(log, config) -> dict:
    """Input words of a run log under a ModelConfig: ``p`` (proxy), ``r`` (rate), ``mode``,
    ``restart``, ``z`` (0: the external Z word is not used by the host), ``input_sat`` (bool[n]:
    some input value the pipeline reads was saturated), and for an aux 'sum' generator the channel
    words it reads: ``f`` (F), ``t`` (T), ``aux`` (int64[n, n_chan]: the aux_* columns of
    firmware_ref.aux.aux_columns as A_c words with the quantizer's AF_c) and ``k`` (the counter
    K = rint(t_s fs), fs of the aux params, as the golden); else those are None."""
    _, pcol = log.proxy(config.proxy.kind)
    p, psat = inputs.proxy_words(pcol, config.proxy.kind)
    r, rsat = inputs.rate_words(log.rate_dph)
    n = len(log)
    restart = np.zeros(n, np.uint8)
    restart[np.asarray(log.segments, np.int64)] = 1
    if n:
        restart[0] = 1
    out = {"p": p, "r": r, "mode": np.asarray(log.mode, np.int64), "restart": restart, "z": np.zeros(n, np.int64),
           "f": None, "t": None, "aux": None, "k": None}
    sat = psat | rsat
    if config.aux.generator != "none":
        from host_tools.quantize import aux_channel_fracs
        from host_tools.regressors import power_on_counter

        where = f"{log.source}: the aux generator"
        used = {tm["column"] for tm in config.aux.terms if tm["gen"] == "input"}
        for col in sorted(used):
            if col not in log:
                raise ValueError(f"{where} needs column '{col}', which the log lacks "
                                 f"(columns: {', '.join(log.columns)})")
        if "freq_hz" in log:
            out["f"], fsat = inputs.freq_words(log["freq_hz"])
            sat |= fsat if "freq_hz" in used else False
        if "temp_c" in log:
            out["t"], tsat = inputs.temp_words(log["temp_c"])
            sat |= tsat if "temp_c" in used else False
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
    from host_tools.quantize import quantize

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
    quantized on the fly by host_tools.quantize).  The log is converted to words
    (firmware_ref.inputs), run through the kernel (``impl='numba'``) or the Python reference
    (``'python'``) - an aux 'sum' generator runs in fixed point from the log's channels (F, T,
    aux_* words and K, :func:`log_words`), 'none' gives z = 0 - and the output words are written
    back in deg/h: ``rate_dph`` (OUT),
    ``bias_dph`` (BIAS), ``valid`` 1.0/0.0, the same columns as the float path; the metadata adds
    ``compensation_table_crc``.  Model/log mismatches are refused as in the float path.  With
    ``return_flags`` returns ``(log, flags)``, flags uint8[n] (formats.FLAGS bits)."""
    from host_tools import compensate as hc
    from host_tools import runlog as rl
    from host_tools.quantize import quantize

    if str(log.metadata.get("compensated", "")).strip().lower() == "yes" or "bias_dph" in log:
        raise ValueError(f"{log.source}: the log is already compensated (metadata 'compensated: yes' "
                         f"or a 'bias_dph' column)")
    cfg = model.config
    hc.check_sample_rate(log, cfg.rate.fs)
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
    chans = {name: w[name] for name in ("f", "t", "aux", "k")}
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
