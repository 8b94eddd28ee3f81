# Measurement script of docs/ACCURACY.md (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/band_cv.py SET START END OUT.jsonl
"""Per foreign device of set SET, mode reversal: every rate candidate of fit_auto_rate (terms auto,
then the lag-state block), its in-run CV rms (time blocks, as fitted), a leave-one-RATE-BAND-out CV
rms (folds by the training proxy's smoothed |rate|: holds, transitions, ramps; the model's terms,
refitted per fold by least squares, per bank) and its held-out ratio, as in `hdrg bench accuracy`."""
import json, sys, time
import numpy as np
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import fit_logs, _rate_label, RATE_CANDIDATES
from host_tools.golden.compensate import fit_config_from_logs, prepare
from host_tools.golden.regressors import regressor_matrix
from host_tools.bench.accuracy import set_devices, SEED_STRIDE, heldout_ratio

EDGES = (0.25, 0.75)     # |rate| / its 95th percentile over the used samples


def band_ids(p, used, width=121):
    r = np.abs(np.convolve(np.gradient(np.asarray(p, float)), np.ones(width) / width, mode="same"))
    ref = np.percentile(r[used], 95)
    return np.digitize(r / ref, EDGES)


def band_cv(log, model):
    pr = prepare(log, model.config)
    X = regressor_matrix(pr.u, pr.v, pr.z)[:, list(model.terms)]
    bands = band_ids(pr.p, pr.used)
    banks = [pr.used & (pr.mode == 1), pr.used & (pr.mode == 2)] if model.coef_mode2 is not None else [pr.used]
    sse = np.zeros(3); cnt = np.zeros(3)
    for bank in banks:
        for b in range(3):
            tr, te = bank & (bands != b), bank & (bands == b)
            if te.sum() == 0 or tr.sum() < X.shape[1] * 4:
                continue
            c, *_ = np.linalg.lstsq(X[tr], pr.y[tr], rcond=None)
            e = pr.y[te] - X[te] @ c
            sse[b] += e @ e; cnt[b] += len(e)
    return float(np.sqrt(sse.sum() / cnt.sum())), (np.sqrt(sse / np.maximum(cnt, 1))).tolist(), cnt.tolist()


S, a, b, outp = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
fo = open(outp, "w")
for rec, cases in set_devices((S * SEED_STRIDE + i for i in range(a, b)), reversals=(True,)):
    for key, tr, ho, fl in cases:
        t = time.time(); rows = []
        for est, n, sh in RATE_CANDIDATES:
            e = {"est": _rate_label(est, n, sh)}
            try:
                cfg = fit_config_from_logs([tr], rate_estimator=est, n=n, shift=sh)
                m, r = fit_logs([tr], cfg, None, blocks=True, drop_unidentifiable=True)
                e["cv0"] = r.cv["cv_rms"]; e["r0"] = heldout_ratio(m, ho, fl)
                e["band0"], e["bands0"], e["cnt"] = band_cv(tr, m)
                m2, r2 = FL.add_lag_block([tr], m, r)
                e["cv"] = r2.cv["cv_rms"]; e["r"] = heldout_ratio(m2, ho, fl)
                e["lag"] = m2.fit["lag_block"]["chosen"] is not None
                e["band"], e["bands"], _ = band_cv(tr, m2)
            except ValueError as exc:
                e["err"] = str(exc)[:200]
            rows.append(e)
        rec[key] = rows; rec["t"] = time.time() - t
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
