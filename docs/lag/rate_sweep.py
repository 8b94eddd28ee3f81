# Measurement script of docs/ACCURACY.md "Rate and lag selection" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/rate_sweep.py SET START END OUT.jsonl
"""Per foreign device of set SET (seeds SET*100000 + i): for FTR and MR and each rate candidate of
fit_auto_rate, the base fit (terms auto, lag off) scored by CV on its own samples and on the samples
valid for every candidate; held-out ratio of the base and of the base + lag block (auto)."""
import json, sys, time
import numpy as np
import host_tools.golden.compensate as C
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import fit_logs, RATE_CANDIDATES, _rate_label
from host_tools.golden.compensate import fit_config_from_logs, prepare
from host_tools.bench.accuracy import damping_change_dph, device_runs, heldout_valid, SEED_STRIDE
from host_tools.simulation.sim_foreign import foreign_device

S, a, b, outp = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]


def ratio(m, ho, fl):
    return float(np.std(heldout_valid(m, ho)) / fl)


fo = open(outp, "w")
for i in range(a, b):
    seed = S * SEED_STRIDE + i
    dev = foreign_device(seed)
    rec = {"seed": seed, "dc": damping_change_dph(dev)}
    for rev in (False, True):
        key = "mr" if rev else "ftr"
        tr, ho, fl = device_runs(dev, rev)
        cfgs = {}
        for est, n, sh in RATE_CANDIDATES:
            cfgs[_rate_label(est, n, sh)] = fit_config_from_logs([tr], rate_estimator=est, n=n, shift=sh)
        common = np.logical_and.reduce([prepare(tr, c).used for c in cfgs.values()])
        rows = []
        for lab, cfg in cfgs.items():
            e = {"est": lab}
            t = time.time()
            try:
                m, r = fit_logs([tr], cfg, None, blocks=True, drop_unidentifiable=True)
                e["cv_own"] = r.cv["cv_rms"]; e["r_own"] = ratio(m, ho, fl); e["n_own"] = int(r.n)
                m2, r2 = FL.add_lag_block([tr], m, r)
                e["r_own_lag"] = ratio(m2, ho, fl); e["lag_own"] = m2.fit["lag_block"]["chosen"]
                mc, rc = fit_logs([tr], cfg, None, blocks=True, drop_unidentifiable=True, masks=[common])
                e["cv_com"] = rc.cv["cv_rms"]; e["r_com"] = ratio(mc, ho, fl); e["n_com"] = int(rc.n)
                mc2, _ = FL.add_lag_block([tr], mc, rc)
                e["r_com_lag"] = ratio(mc2, ho, fl); e["lag_com"] = mc2.fit["lag_block"]["chosen"]
            except ValueError as exc:
                e["err"] = str(exc)[:200]
            e["t"] = time.time() - t
            rows.append(e)
        rec[key] = rows
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(seed, "done", flush=True)
