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
from host_tools.bench.accuracy import heldout_ratio, set_devices, SEED_STRIDE

S, a, b, outp = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]




fo = open(outp, "w")
for rec, cases in set_devices(S * SEED_STRIDE + i for i in range(a, b)):
    for key, tr, ho, fl in cases:
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
                e["cv_own"] = r.cv["cv_rms"]; e["r_own"] = heldout_ratio(m, ho, fl); e["n_own"] = int(r.n)
                m2, r2 = FL.add_lag_block([tr], m, r)
                e["r_own_lag"] = heldout_ratio(m2, ho, fl); e["lag_own"] = m2.fit["lag_block"]["chosen"]
                mc, rc = fit_logs([tr], cfg, None, blocks=True, drop_unidentifiable=True, masks=[common])
                e["cv_com"] = rc.cv["cv_rms"]; e["r_com"] = heldout_ratio(mc, ho, fl); e["n_com"] = int(rc.n)
                mc2, _ = FL.add_lag_block([tr], mc, rc)
                e["r_com_lag"] = heldout_ratio(mc2, ho, fl); e["lag_com"] = mc2.fit["lag_block"]["chosen"]
            except ValueError as exc:
                e["err"] = str(exc)[:200]
            e["t"] = time.time() - t
            rows.append(e)
        rec[key] = rows
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
