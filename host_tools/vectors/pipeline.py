"""Recomputing the pipeline sets (``sequencer``, ``e2e``, ``aux``) from their input words: the
numba kernel's outputs, checked sample by sample against the per-sample Python reference, whose
trace gives the intermediates the kernel does not output; the case builder.
"""
from __future__ import annotations

import numpy as np

from firmware_ref import formats as F
from host_tools.vectors.spec import (AUX_INPUTS, AUX_IN_FIELDS, IN_FIELDS, O_NAMES, ROW_FIELDS, SEQ_INPUTS,
                                     VectorsError)
from host_tools.vectors.files import VectorSet
from host_tools.vectors.evaluator import reference_rows


# -- pipeline (sequencer, e2e) ---------------------------------------------------------------------------

def compute_pipeline(vs: VectorSet, rows: bool) -> None:
    """Fill the 16 output fields (and with ``rows`` the evaluator intermediates) of every case from
    the input columns (MODE -1: self-timed): the numba kernel and the per-sample Python reference
    (firmware_ref.compensate.run_reference) must agree on every field of every sample; the window
    sum and count (acc, cnt) are the reference's, the Horner rows its evaluator's trace
    (host_tools.vectors.evaluator.reference_rows)."""
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
        r, ctl, z = c["R"][lo:hi], c["RESTART"][lo:hi], c["Z"][lo:hi]
        if not np.all((ctl >= 0) & (ctl <= 3)):
            raise VectorsError(f"{vs.name} case {case['name']}: RESTART must be 0..3 (bit 0 restart, bit 1 invalid)")
        rs, bad = ctl & 1, (ctl >> 1) & 1                # RESTART: bit 0 restart, bit 1 the input-invalid bit
        kw = {"invalid": bad}
        if has_aux:
            kw = {"invalid": bad, "f": c["F"][lo:hi], "t": c["T"][lo:hi], "k": c["K"][lo:hi],
                  "aux": np.stack([c[f"A{j}"][lo:hi] for j in range(F.AUX_MAX_CHANNELS)], axis=1)}
        k = run_words(t, p, r, None if timed else mode, rs, z, self_timed=timed, detail=True, **kw)
        state = k["state"]
        m = np.asarray(F.STATE_MODE, np.int64)[state] if timed else mode
        ref = run_reference(t, p, r, None if timed else mode, rs, z, self_timed=timed, **kw)
        o = {"state": state, "vs": np.asarray(F.STATE_VS, np.int64)[state],
             "mode": m, "sign": np.asarray(F.STATE_SIGN, np.int64)[state], "u": k["u"], "v": k["v"],
             "z": k["z"], "s": k["s"], "acc": ref["acc"], "cnt": ref["cnt"], "y": k["y"], "b": k["b"],
             "out": k["out"], "bias": k["bias"], "valid": k["valid"], "flags": k["flags"]}
        for name in ("state", "vs", "sign", "u", "v", "z", "s", "y", "b", "out", "bias", "valid", "flags"):
            if not np.array_equal(np.asarray(ref[name], np.int64), np.asarray(o[name], np.int64)):
                i = int(np.argmax(np.asarray(ref[name], np.int64) != o[name]))
                raise VectorsError(f"{vs.name} case {case['name']} sample {i}: {name}: numba kernel "
                                   f"{o[name][i]} != Python reference {ref[name][i]}")
        if rows:
            hr = reference_rows(t, k["u"], k["v"], z, np.where(m == 2, 2, 1))
            if not np.array_equal(hr["b"], k["b"]):
                raise VectorsError(f"{vs.name} case {case['name']}: the evaluator trace disagrees with the kernel's B")
            o.update((name, hr[name]) for name, _ in ROW_FIELDS)
        for name in res:
            res[name][lo:hi] = o[name]
    cols = {k: c[k] for k in (AUX_INPUTS if has_aux else SEQ_INPUTS)}
    cols.update(res)
    vs.columns = cols


class Cases:
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
        rec["RESTART"][0] |= 1                         # bit 1 (the input-invalid bit) kept
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
