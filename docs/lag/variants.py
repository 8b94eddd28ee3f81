# Measurement script of docs/ACCURACY.md "Rate and lag selection" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/variants.py SET START END OUT.jsonl VARIANT [VARIANT ...]
"""Per foreign device of set SET: fit_default (`hdrg fit RUN`) under module-constant variants
(VARIANTS below), held-out std / floor as in `hdrg bench accuracy`, FTR and MR; fit time."""
import json, sys, time
import numpy as np
import host_tools.golden.compensate as C
from host_tools.fitting import fit_lag as FL, fit as F, fit_pipeline as FP
from host_tools.bench.accuracy import heldout_ratio, set_devices, SEED_STRIDE

VARIANTS = {
    "base": {},                                   # the defaults as committed
    "nosensor": {(FL, "LAG_SENSOR"): False},
    "old": {(FL, "LAG_SENSOR"): False, (FL, "LAG_REFIT_TOP"): 1, (FL, "LAG_SCREEN_GATE"): {"ftr": 0.2, "mr": 0.2},
            (FL, "LAG_MARGIN"): {"ftr": 0.2, "mr": 0.2}},   # the rule before (bcf758a)
    "sensor_oldrule": {(FL, "LAG_REFIT_TOP"): 1, (FL, "LAG_SCREEN_GATE"): {"ftr": 0.2, "mr": 0.2},
                       (FL, "LAG_MARGIN"): {"ftr": 0.2, "mr": 0.2}},
    "top1": {(FL, "LAG_REFIT_TOP"): 1},
    "pairs_mr": {(FL, "LAG_PAIRS_MR"): True},
    "top3": {(FL, "LAG_REFIT_TOP"): 3},
    "common": {"samples": "common"},
    "common_nosensor": {"samples": "common", (FL, "LAG_SENSOR"): False},
    "ftrauto": {(C, "DEFAULT_RATE_SELECTION_FTR"): "auto"},
    "ftrauto_nosensor": {(C, "DEFAULT_RATE_SELECTION_FTR"): "auto", (FL, "LAG_SENSOR"): False},
    "m10": {(FL, "LAG_MARGIN"): {"ftr": 0.1, "mr": 0.1}},
    "m30": {(FL, "LAG_MARGIN"): {"ftr": 0.3, "mr": 0.3}},
    "sensor_only0": {(FL, "SENSOR_TAUS_S"): (0.0,)},
}
S, a, b, outp, names = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5:]
VARIANTS["rate_phases"] = {"rate_cv": "phases"}   # rate auto scored by leave-one-phase-out CV
VARIANTS["rate_phases_sensor_off"] = {"rate_cv": "phases", (FL, "LAG_SENSOR"): False}
_orig_auto = F.fit_auto_rate
_orig_blocks = F.block_groups
_stash = {}


def phase_groups(p, k=120, min_len=300):
    """Monotone phases of the proxy p (sign of p[i] - p[i-k]), phases shorter than min_len merged
    into the one before; numbered in time order."""
    d = np.sign(p[k:] - p[:-k])
    d = np.concatenate([np.full(k, d[0] if len(d) else 0.0), d])
    for i in range(1, len(d)):
        if d[i] == 0:
            d[i] = d[i - 1]
    g = np.cumsum(np.concatenate([[0], d[1:] != d[:-1]])).astype(np.int64)
    ids, counts = np.unique(g, return_counts=True)
    out = g.copy()
    cur = 0
    for gid, c in zip(ids, counts):
        if gid > 0 and c < min_len:
            out[g == gid] = cur
        else:
            cur = gid
            out[g == gid] = gid
    return np.unique(out, return_inverse=True)[1].astype(np.int64)


def auto_phases(logs, terms=None, **kw):
    """fit_auto_rate whose CV groups are the proxy's monotone phases; the chosen candidate is then
    refitted with the usual time blocks (so the lag block compares like with like)."""
    orig_prepare = C.prepare

    def prep(log, cfg):
        pr = orig_prepare(log, cfg)
        _stash["p"] = pr.p
        return pr
    C.prepare = prep
    F.block_groups = lambda n, nb: phase_groups(_stash["p"]) if len(_stash.get("p", ())) == n else _orig_blocks(n, nb)
    try:
        m, r = _orig_auto(logs, terms, **kw)
    finally:
        C.prepare = orig_prepare
        F.block_groups = _orig_blocks
    sel = m.fit["rate_selection"]
    m2, r2 = F.fit_logs(logs, m.config, terms, cv_blocks=kw.get("cv_blocks", 8), blocks=True,
                        drop_unidentifiable=kw.get("drop_unidentifiable", True))
    m2.fit["rate_selection"] = sel
    return m2, r2


def run(tr, ho, fl, var):
    saved = {}
    for k, v in var.items():
        if isinstance(k, tuple):
            saved[k] = getattr(*k)
            setattr(k[0], k[1], v)
    samples = var.get("samples", "own")
    if var.get("rate_cv") == "phases":
        FP.fit_auto_rate = auto_phases
    else:
        FP.fit_auto_rate = lambda *a_, **kw: _orig_auto(*a_, samples=samples, **kw)
    try:
        t = time.time()
        m, _ = FP.fit_default([tr])
        dt = time.time() - t
        return {"r": heldout_ratio(m, ho, fl), "t": dt, "lag": m.fit.get("lag_block", {}).get("chosen"),
                "rate": m.config.rate.estimator + str(m.config.rate.shift if m.config.rate.estimator == "iir" else m.config.rate.n)}
    finally:
        for k, v in saved.items():
            setattr(k[0], k[1], v)


fo = open(outp, "w")
for rec, cases in set_devices(S * SEED_STRIDE + i for i in range(a, b)):
    for key, tr, ho, fl in cases:
        rec[key] = {n: run(tr, ho, fl, VARIANTS[n]) for n in names}
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
