# Measurement script of docs/ACCURACY.md "Rate preference" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/rate_prefer_sweep.py SET START END OUT.jsonl
"""Per foreign device of set SET (seeds SET*100000 + i), FTR and MR: for every rate candidate
(fit_auto_rate's five and two longer ones), the base fit (terms auto, lag off) with its CV rms, then
the lag-state block (fit_lag.add_lag_block) with its CV rms; held-out std / floor of both, as in
`hdrg bench accuracy`.  docs/lag/rate_prefer_analyze.py replays selection rules from these."""
import json, sys, time
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import fit_logs, _rate_label
from host_tools.golden.compensate import fit_config_from_logs
from host_tools.bench.accuracy import heldout_ratio, set_devices, SEED_STRIDE

S, a, b, outp = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
CANDS = (("diff", 8, 4), ("diffn", 16, 4), ("lsq", 32, 4), ("iir", 8, 7), ("iir", 8, 9), ("iir", 8, 10), ("lsq", 128, 4))




fo = open(outp, "w")
for rec, cases in set_devices(S * SEED_STRIDE + i for i in range(a, b)):
    for key, tr, ho, fl in cases:
        rows = []
        for est, n, sh in CANDS:
            e = {"est": _rate_label(est, n, sh)}
            t = time.time()
            try:
                cfg = fit_config_from_logs([tr], rate_estimator=est, n=n, shift=sh)
                m, r = fit_logs([tr], cfg, None, blocks=True, drop_unidentifiable=True)
                e["cv"] = r.cv["cv_rms"]; e["r"] = heldout_ratio(m, ho, fl)
                m2, r2 = FL.add_lag_block([tr], m, r)
                e["cv_lag"] = r2.cv["cv_rms"]; e["r_lag"] = heldout_ratio(m2, ho, fl); e["lag"] = m2.fit["lag_block"]["chosen"]
            except ValueError as exc:
                e["err"] = str(exc)[:200]
            e["t"] = time.time() - t
            rows.append(e)
        rec[key] = rows
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
