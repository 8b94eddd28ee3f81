# Measurement script of docs/ACCURACY.md "Averaging the rate candidates" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/ensemble.py SET START END OUT.jsonl
"""Per foreign device of set SET: every rate candidate of fit_auto_rate (terms auto, then the
lag-state block), each compensating the held-out run; records per candidate the CV rms and the
held-out ratio, and, on the samples valid under every candidate, the ratio of the MEAN of the
candidates' outputs (model averaging), of the medoid (the candidate whose held-out output is
closest, in std, to the others'), and the std of each pair's difference (their disagreement)."""
import json, sys, time
import numpy as np
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import fit_logs, _rate_label, RATE_CANDIDATES
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.golden.compensate import fit_config_from_logs, compensate
from host_tools.bench.accuracy import set_devices, SEED_STRIDE

S, a, b, outp = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
fo = open(outp, "w")
for rec, cases in set_devices(S * SEED_STRIDE + i for i in range(a, b)):
    for key, tr, ho, fl in cases:
        t = time.time()
        outs, rows = [], []
        for est, n, sh in RATE_CANDIDATES:
            e = {"est": _rate_label(est, n, sh)}
            try:
                cfg = fit_config_from_logs([tr], rate_estimator=est, n=n, shift=sh)
                m, r = fit_logs([tr], cfg, None, blocks=True, drop_unidentifiable=True)
                m2, r2 = FL.add_lag_block([tr], m, r)
                e["cv"] = r2.cv["cv_rms"]
                o = compensate(ho, m2)
                v = o["valid"] > 0
                e["r"] = float(np.std(o.rate_dph[v]) / fl)
                outs.append((np.asarray(o.rate_dph, float), v))
            except ValueError as exc:
                e["err"] = str(exc)[:200]
            rows.append(e)
        md, _ = fit_default([tr])
        od = compensate(ho, md)
        vd = od["valid"] > 0
        rec[key + "_default"] = float(np.std(od.rate_dph[vd]) / fl)
        rec[key + "_default_est"] = md.fit.get("rate_selection", {}).get("chosen")
        if len(outs) == len(RATE_CANDIDATES):
            common = np.logical_and.reduce([v for _, v in outs])
            X = np.array([o[common] for o, _ in outs])
            rec[key + "_mean"] = float(np.std(X.mean(0)) / fl)
            D = np.array([[np.std(X[i] - X[j]) / fl for j in range(len(X))] for i in range(len(X))])
            rec[key + "_disagree"] = D.tolist()
            k = int(np.argmin(D.sum(1)))
            rec[key + "_medoid"] = rows[k]["est"]
            rec[key + "_medoid_r"] = float(np.std(X[k]) / fl)
            rec[key + "_common_r"] = [float(np.std(x) / fl) for x in X]
            rec[key + "_default_common"] = float(np.std(od.rate_dph[common]) / fl)
        rec[key] = rows
        rec[key + "_t"] = time.time() - t
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
