# Measurement scripts of docs/REGRESS_THEN_REVERSE.md (not part of the package).
"""Sweep: per foreign device, per (kind, estimator, terms): training CV rms (8 time blocks) and
held-out ratio (std at 1 s / floor), train 4 degC/min p0 n0, hold out 2 degC/min p1 n1.
usage: sweep.py START END OUT KINDS ESTS TERMSETS"""
import dataclasses, json, sys, warnings
import numpy as np
from host_tools.bench.accuracy import ESTIMATORS, floor_of, _std
from host_tools.golden.compensate import compensate, fit_config_from_logs
from host_tools.fitting.fit import fit_logs
from host_tools.golden.model import ModelConfig, BiasModel
from host_tools.golden.reversal import ReversalConfig
from host_tools.simulation.sim_foreign import damping_bias, foreign_device, simulate_foreign

start, end, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
kinds = sys.argv[4].split(",")
ests = sys.argv[5].split(",")
termsets = sys.argv[6].split(";")
recs = []
warnings.simplefilter("ignore")
for seed in range(start, end):
    dev = foreign_device(seed)
    sc0, _ = dev.damping_change(0); sc1, _ = dev.damping_change(1)
    rec = {"seed": seed, "dchange": float(abs(sc1 - sc0) * np.std(damping_bias(dev, 2.0, None))), "r": {}}
    for rev in (False, True):
        ks = [k for k in kinds if (k != "ftr") == rev]
        if not ks:
            continue
        train = simulate_foreign(dev, 4.0, rev, 0, 0, None)
        hold = simulate_foreign(dev, 2.0, rev, 1, 1, None)
        floor = floor_of(simulate_foreign(dev, 2.0, rev, 1, 1, None, thermal=False))
        for k in ks:
            if k == "ftr":
                rc, variants = None, {"ftr": None}
            elif k == "rf":
                rc = ReversalConfig("pair", order="regress_first")
                variants = {f"rf-{c}": ReversalConfig(c, order="regress_first") for c in ("none", "pair", "trend")}
            else:
                o, c = k.split("-")
                rc = ReversalConfig(c, order="combine_first")
                variants = {k: rc}
            for e in ests:
                est, n, sh = ESTIMATORS[e]
                for ts in termsets:
                    try:
                        cfg = fit_config_from_logs([train], rate_estimator=est, n=n, shift=sh, reversal=rc)
                        model, res = fit_logs([train], cfg, ts, cv_blocks=8, drop_unidentifiable=True, blocks=True)
                        cv = res.cv["cv_rms"] if res.cv else float("nan")
                    except Exception as exc:
                        for name in variants:
                            rec["r"][f"{name}/{e}/{ts}"] = {"err": str(exc)[:200]}
                        continue
                    for name, vrc in variants.items():
                        m = model if vrc is None or vrc == rc else BiasModel(
                            dataclasses.replace(model.config, reversal=vrc), model.terms, model.coef,
                            coef_mode2=model.coef_mode2)
                        try:
                            outl = compensate(hold, m)
                            v = outl["valid"] > 0
                            rec["r"][f"{name}/{e}/{ts}"] = {"ratio": _std(outl.rate_dph[v]) / floor, "cv": cv,
                                                            "rms": res.rms, "nterms": len(res.terms)}
                        except Exception as exc:
                            rec["r"][f"{name}/{e}/{ts}"] = {"err": str(exc)[:200]}
    recs.append(rec)
    print(seed, file=sys.stderr, flush=True)
json.dump(recs, open(out, "w"))
