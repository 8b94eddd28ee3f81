"""Recomputing the pipeline sets (``sequencer``, ``e2e``, ``aux``) from their input words: the
numba kernel's outputs, cross-checked with the per-sample Python reference; the case builder.
"""
from __future__ import annotations

import numpy as np

from firmware_ref import arith, formats as F
from host_tools.vectors.spec import (AUX_INPUTS, AUX_IN_FIELDS, IN_FIELDS, O_NAMES, PY_CHECK, ROW_FIELDS,
                                     SEQ_INPUTS, VectorsError)
from host_tools.vectors.files import VectorSet
from host_tools.vectors.evaluator import horner_rows


def window_sums(table, m, r, restart, b=None, warm=None):
    """The combiner's window sum and count after each sample (acc LSB 2^-10 deg/h, cnt): the part
    of firmware_ref.sequencer.Combiner that the numba kernel does not output.  ``m`` the mode of
    each sample (logged or the timer's); for an order-1 table ``b`` (B of each sample, LSB 2^-21)
    and ``warm`` (rate estimator in warm-up): the sums are of r = symsat32(RHU(c 2^11 - B, 11))
    over the used (warm) samples."""
    n = len(m)
    acc_o = np.zeros(n, np.int64)
    cnt_o = np.zeros(n, np.int64)
    if table.combiner == 0:
        return acc_o, cnt_o
    order1 = table.order == 1
    b = np.zeros(n, np.int64) if b is None else np.asarray(b, np.int64)
    warm = np.zeros(n, bool) if warm is None else np.asarray(warm, bool)
    cur = acc = cnt = pos = 0
    for i, (mi, ri, rs) in enumerate(zip(m.tolist(), r.tolist(), restart.tolist())):
        if rs:
            cur = acc = cnt = pos = 0
        if mi != cur:
            cur = mi if mi in (1, 2) else 0
            acc = cnt = pos = 0
        if cur:
            if pos >= table.settle_n:
                c = ri if cur == 1 else -ri
                if order1:
                    c = arith.sat_signed(arith.rshift_round((c << 11) - int(b[i]), 11), 32)[0]
                if cnt < F.COUNT_MAX and not (order1 and warm[i]):
                    acc += c
                    cnt += 1
            else:
                pos += 1
        acc_o[i] = acc
        cnt_o[i] = cnt
    return acc_o, cnt_o


# -- pipeline (sequencer, e2e) ---------------------------------------------------------------------------

def compute_pipeline(vs: VectorSet, rows: bool, check_python: int = PY_CHECK) -> None:
    """Fill the 16 output fields (and with ``rows`` the evaluator intermediates) of every case from
    the input columns (MODE -1: self-timed): numba kernel + window_sums; the first
    ``check_python`` samples of each case against firmware_ref.compensate.run_reference."""
    from firmware_ref.compensate import run_reference
    from firmware_ref.kernel import run_words

    c = vs.columns
    n = len(c["F"])
    has_aux = "K" in c                                   # the aux set: K and A0..A3 inputs
    res = {name: np.zeros(n, np.int64) for name in O_NAMES + (tuple(k for k, _ in ROW_FIELDS) if rows else ())}
    for case in vs.cases:
        lo, hi = case["rows"]
        t = vs.tables[case["table"]]
        mode = c["MODE"][lo:hi]
        timed = bool(mode.size and mode[0] == -1)
        if timed != bool(np.all(mode == -1)) or not np.all((mode >= -1) & (mode <= 3)):
            raise VectorsError(f"{vs.name} case {case['name']}: MODE must be all -1 (self-timed) or all 0..3")
        p = (c["F"] if t.proxy_kind == 0 else c["T"])[lo:hi]
        r, rs, z = c["R"][lo:hi], c["RESTART"][lo:hi], c["Z"][lo:hi]
        kw = {}
        if has_aux:
            kw = {"f": c["F"][lo:hi], "t": c["T"][lo:hi], "k": c["K"][lo:hi],
                  "aux": np.stack([c[f"A{j}"][lo:hi] for j in range(F.AUX_MAX_CHANNELS)], axis=1)}
        k = run_words(t, p, r, None if timed else mode, rs, z, self_timed=timed, detail=True, **kw)
        state = k["state"]
        m = np.asarray(F.STATE_MODE, np.int64)[state] if timed else mode
        acc, cnt = window_sums(t, m, r, rs, k["b"], (k["flags"] & F.FLAG_WARMUP) != 0)
        o = {"state": state, "vs": np.asarray(F.STATE_VS, np.int64)[state],
             "mode": m, "sign": np.asarray(F.STATE_SIGN, np.int64)[state], "u": k["u"], "v": k["v"],
             "z": k["z"], "s": k["s"], "acc": acc, "cnt": cnt, "y": k["y"], "b": k["b"],
             "out": k["out"], "bias": k["bias"], "valid": k["valid"], "flags": k["flags"]}
        if rows:
            hr = horner_rows(t, k["u"], k["v"], z, np.where(m == 2, 2, 1))
            if not np.array_equal(hr["b"], k["b"]):
                raise VectorsError(f"{vs.name} case {case['name']}: Horner rows disagree with the kernel's B")
            o.update((name, hr[name]) for name, _ in ROW_FIELDS)
        m_py = min(check_python, hi - lo)
        if m_py:
            ref = run_reference(t, p[:m_py], r[:m_py], None if timed else mode[:m_py], rs[:m_py], z[:m_py],
                                self_timed=timed, **{key: val[:m_py] for key, val in kw.items()})
            for name in ("state", "vs", "sign", "u", "v", "z", "s", "acc", "cnt", "y", "b", "out", "bias", "valid",
                         "flags"):
                if not np.array_equal(np.asarray(ref[name], np.int64), np.asarray(o[name][:m_py], np.int64)):
                    i = int(np.argmax(np.asarray(ref[name], np.int64) != o[name][:m_py]))
                    raise VectorsError(f"{vs.name} case {case['name']} sample {i}: {name}: numba kernel "
                                       f"{o[name][i]} != Python reference {ref[name][i]}")
        for name in res:
            res[name][lo:hi] = o[name]
    cols = {k: c[k] for k in (AUX_INPUTS if has_aux else SEQ_INPUTS)}
    cols.update(res)
    vs.columns = cols


class _Cases:
    """Collects the cases of a pipeline set: input columns, tables, descriptions."""

    def __init__(self):
        self.cases, self.tables, self.parts = [], [], []

    def add(self, name, desc, table, s, self_timed=False, t_words=None):
        """A case: stream ``s`` (p, r, mode, restart, z; for the aux set also f, t, aux, k)."""
        n = len(s["p"])
        rec = {"F": np.zeros(n, np.int64), "T": np.zeros(n, np.int64),
               "R": np.asarray(s["r"], np.int64),
               "MODE": np.full(n, -1, np.int64) if self_timed else np.asarray(s["mode"], np.int64),
               "RESTART": np.zeros(n, np.int64) if s.get("restart") is None else np.asarray(s["restart"], np.int64),
               "Z": np.zeros(n, np.int64) if s.get("z") is None else np.asarray(s["z"], np.int64)}
        rec["F" if table.proxy_kind == 0 else "T"] = np.asarray(s["p"], np.int64)
        if t_words is not None:                        # the other word from the log (e2e)
            rec["T" if table.proxy_kind == 0 else "F"] = np.asarray(t_words, np.int64)
        if s.get("k") is not None:                     # the aux set: every channel word, K, A0..A3
            rec["F"], rec["T"] = np.asarray(s["f"], np.int64), np.asarray(s["t"], np.int64)
            rec["F" if table.proxy_kind == 0 else "T"] = np.asarray(s["p"], np.int64)
            rec["K"] = np.asarray(s["k"], np.int64)
            a = np.asarray(s["aux"], np.int64).reshape(n, -1)
            for j in range(F.AUX_MAX_CHANNELS):
                rec[f"A{j}"] = a[:, j] if j < a.shape[1] else np.zeros(n, np.int64)
        rec["RESTART"][0] = 1
        try:
            ti = next(i for i, t in enumerate(self.tables) if t == table)
        except StopIteration:
            ti = len(self.tables)
            self.tables.append(table)
        self.cases.append({"name": name, "description": desc, "table": ti, "self_timed": bool(self_timed)})
        self.parts.append(rec)

    def columns(self) -> dict:
        start = 0
        for c, p in zip(self.cases, self.parts):
            c["rows"] = [start, start + len(p["R"])]
            start += len(p["R"])
        cols = {"case": np.concatenate([np.full(len(p["R"]), c, np.int64) for c, p in enumerate(self.parts)]),
                "i": np.concatenate([np.arange(len(p["R"]), dtype=np.int64) for p in self.parts])}
        for name, _ in (AUX_IN_FIELDS if "K" in self.parts[0] else IN_FIELDS):
            cols[name] = np.concatenate([p[name] for p in self.parts])
        return cols
