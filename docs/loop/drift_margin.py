"""Choose diagnose_scan.DRIFT_MARGIN: how much better than the structure a drift in time must be.

    PYTHONPATH=. python docs/loop/drift_margin.py NPLAN SEED OUT.json     # measure (2 processes)
    PYTHONPATH=. python docs/loop/drift_margin.py --choose OUT.json BENCH.json

For the clean, aging and thermal_lag runs of the loop benchmark's plan(NPLAN, SEED) it runs the
loop's first structure scan (aging scored beside the structure) and records, from the full ranking,
the CV gain of the best structural candidate g_s and of the best aging candidate g_a, and
ratio = (1 - g_s) / (1 - g_a): how many times less residual variance the drift leaves.  The gains do
not depend on the margin.  ``--choose`` reads the effect_ratio of each run from a bench record of the
same plan (BENCH.json) and, over the margins between consecutive ratios, counts: clean runs the
drift would take (false), aging runs with effect_ratio >= 2 it would miss, and thermal_lag runs with
effect_ratio >= 2 it would rename aging.  docs/LOOP.md "A drift beside the structure" gives the rule
and the choice (calibration seed 1: docs/loop/drift_margin_seed1.json, bench150_seed1.json).
"""
import json
import sys
import warnings
from multiprocessing import Pool


def one(args):
    nplan, seed, i = args
    import host_tools.fitting.diagnose_scan as ds
    from host_tools.bench import loop
    from host_tools.fitting.diagnose import diagnose
    from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign
    ds.TOP_RANKING = 10 ** 6          # the whole ranking
    spec = loop.plan(nplan, seed)[i]
    dev, eff, rev, st = foreign_device(spec["device"]), spec["effect"], spec["reversal"], spec["strength"] or 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = simulate_foreign(dev, 4.0, rev, 0, 0, effect=eff, strength=st)
        ho = simulate_foreign(dev, 2.0, rev, 1, 1, effect=eff, strength=st)
        rep, _ = diagnose([tr], [ho], plots=False, max_iter=1)
    it = rep["iterations"][0] if rep["iterations"] else None
    rk = it["ranking"] if it else []
    gs = max((r["gain"] for r in rk if r["family"] != "aging"), default=0.0)
    ga = max((r["gain"] for r in rk if r["family"] == "aging"), default=0.0)
    return {**spec, "g_struct": gs, "g_aging": ga, "ratio": (1 - gs) / max(1 - ga, 1e-9)}


def choose(recs, bench):
    er = {r["i"]: r["effect_ratio"] for r in bench["records"]}
    clean = [r["ratio"] for r in recs if r["effect"] is None]
    aging = [r["ratio"] for r in recs if r["effect"] == "aging" and (er[r["i"]] or 0) >= 2]
    lag = [r["ratio"] for r in recs if r["effect"] == "thermal_lag" and (er[r["i"]] or 0) >= 2]
    print(f"clean ({len(clean)}): max ratio {max(clean):.2f}")
    print(f"aging, effect_ratio >= 2 ({len(aging)}): " + " ".join(f"{x:.2f}" for x in sorted(aging)))
    print(f"thermal_lag, effect_ratio >= 2 ({len(lag)}): " + " ".join(f"{x:.2f}" for x in sorted(lag)))
    cuts = sorted(x for x in set([1.0] + clean + aging + lag) if x >= 1.0)
    print("margin in        clean taken  aging missed  thermal_lag renamed")
    for lo, hi in zip(cuts, cuts[1:] + [float("inf")]):
        m = lo + 1e-9      # a drift wins when ratio >= margin
        print(f"({lo:5.2f}, {hi:5.2f}]  {sum(x >= m for x in clean):11d}  {sum(x < m for x in aging):12d}  "
              f"{sum(x >= m for x in lag):19d}")


if __name__ == "__main__":
    if sys.argv[1] == "--choose":
        choose(json.load(open(sys.argv[2])), json.load(open(sys.argv[3])))
        sys.exit(0)
    from host_tools.bench import loop
    nplan, seed, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    idx = [s["i"] for s in loop.plan(nplan, seed) if s["effect"] in (None, "aging", "thermal_lag")]
    with Pool(2) as p:
        recs = p.map(one, [(nplan, seed, i) for i in idx], chunksize=1)
    with open(out, "w") as f:
        json.dump(recs, f, indent=0)
