# Measurement script of docs/ACCURACY.md "Rate and lag selection" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/select_sweep.py SET START END OUT.jsonl
"""Per foreign device: base default fit (lag off), then every lag candidate: per-group screen SSE
under several CV groupings, the forced refit's CV rms and held-out ratio."""
import json, sys, time
import numpy as np
import host_tools.golden.compensate as C
from host_tools.fitting import fit_lag as FL
from host_tools.fitting.fit import fit_logs
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.golden.compensate import prepare
from host_tools.bench.accuracy import heldout_ratio, set_devices, SEED_STRIDE

S, a, b, outp = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
C.DEFAULT_LAG_BLOCK = "off"


def phase_groups(pr, n):
    """Monotone phases of the proxy (sign of its slope over 120 s), numbered in time order."""
    p = pr.p
    k = 120
    d = np.sign(p[k:] - p[:-k])
    d = np.concatenate([np.full(k, d[0] if len(d) else 0), d])
    # forward-fill zeros
    for i in range(1, len(d)):
        if d[i] == 0:
            d[i] = d[i - 1]
    return np.cumsum(np.concatenate([[0], d[1:] != d[:-1]])).astype(np.int64)


def grams(tr, cfg, poly, keys, groups, sensor):
    two = cfg.reversal is not None
    pr = prepare(tr, cfg)
    from host_tools.golden.regressors import regressor_matrix, generator_values
    cols = [regressor_matrix(pr.u, pr.v)[:, list(poly)]]
    for src, t in keys:
        y1 = generator_values(tr, FL.lag_term(cfg, t, 1, sensor=sensor if src else None), cfg.rate.fs)
        cols.append(np.column_stack([y1, y1 * y1, y1 * y1 * y1]))
    A = np.column_stack(cols + [pr.y])
    g = groups(pr)
    masks = [pr.used & (pr.mode == 1), pr.used & (pr.mode == 2)] if two else [pr.used]
    banks = []
    for m in masks:
        bank = {}
        for key in np.unique(g[m]):
            Am = A[m & (g == key)]
            bank[int(key)] = Am.T @ Am
        banks.append(bank)
    return banks


def per_group_sse(banks, idx):
    keys = sorted(set().union(*[set(b) for b in banks]))
    out = np.zeros(len(keys))
    for bank in banks:
        total = sum(bank.values())
        for j, k in enumerate(keys):
            if k in bank:
                Gf = bank[k]
                out[j] += max(FL._sse(Gf, idx, FL._solve(total - Gf, idx)), 0.0)
    return out.tolist()


fo = open(outp, "w")
for rec, cases in set_devices(S * SEED_STRIDE + i for i in range(a, b)):
    for key, tr, ho, fl in cases:
        m, r = fit_default([tr])
        if r.cv is None:
            m, r = fit_logs([tr], m.config, None, blocks=True)
        d = {"base": heldout_ratio(m, ho, fl), "base_cv": r.cv["cv_rms"], "rate": m.fit.get("rate_selection", {}).get("chosen")}
        cfg = m.config
        poly = (0,) + tuple(sorted(k for k in m.terms if k not in (0, 7)))
        duration = float(tr.t_s[-1] - tr.t_s[0])
        sensor = FL.sensor_source([tr], cfg)
        cands = FL.candidates(duration, tr.reversal, sensor_taus=FL.SENSOR_TAUS_S if sensor else ())
        keys = sorted({FL._key(e) for c in cands for e in c})
        npoly = len(poly)

        def idx_of(c):
            idx = list(range(npoly))
            for e in c:
                j = npoly + 3 * keys.index(FL._key(e))
                idx += list(range(j, j + e[1]))
            return idx
        schemes = {f"b{nb}": (lambda nb: (lambda pr: FL._groups(pr, 1, nb, 0)))(nb) for nb in (4, 8, 16)}
        schemes["ph"] = lambda pr: phase_groups(pr, len(pr.y))
        d["screen_base"] = {}
        G = {}
        for sn, gf in schemes.items():
            G[sn] = grams(tr, cfg, poly, keys, gf, sensor)
            d["screen_base"][sn] = per_group_sse(G[sn], list(range(npoly)))
        full = [sum(bk.values()) for bk in G["b8"]]
        d["cands"] = []
        scr = {FL._label(c): {sn: per_group_sse(G[sn], idx_of(c)) for sn in schemes} for c in cands}
        refit = set()
        for sn in schemes:
            order = sorted(cands, key=lambda c: sum(scr[FL._label(c)][sn]))
            refit |= {FL._label(c) for c in order[:1]}
            if sn == "b8":
                refit |= {FL._label(c) for c in order[:4]}
        for c in cands:
            e = {"block": FL._label(c), "ntau": len(c), "sensor": any(len(x) > 2 for x in c)}
            e["screen"] = scr[e["block"]]
            if e["block"] not in refit:
                d["cands"].append(e)
                continue
            coefs = [FL._solve(F, idx_of(c))[npoly:] for F in full]
            cfg2 = FL.lag_config(cfg, c, coefs, sensor)
            if cfg2 is None:
                e["err"] = "too many terms"
            else:
                try:
                    m2, r2 = fit_logs([tr], cfg2, None, blocks=True, drop_unidentifiable=True)
                    e["cv"] = r2.cv["cv_rms"]; e["ratio"] = heldout_ratio(m2, ho, fl); e["k7"] = 7 in m2.terms
                except ValueError as exc:
                    e["err"] = str(exc)[:100]
            d["cands"].append(e)
        rec[key] = d
    fo.write(json.dumps(rec) + "\n"); fo.flush()
    print(rec["seed"], "done", flush=True)
