"""Issue #10 (round 2 session 9): held-out ratio of `hdrg fit` defaults (terms auto over the 17) against fixed term sets
without the higher powers of the rate.  PYTHONPATH=. python docs/lag/term_sets.py SET START N OUT.jsonl (prints a JSON line per device)."""
import json
import sys
import warnings

warnings.simplefilter("ignore")
from host_tools.bench.accuracy import set_devices, heldout_ratio
from host_tools.fitting.fit_pipeline import fit_default
S, a, n, out = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
SETS = {"default": None, "linv": "0,1,2,3,4,8,11,14", "v2": "0,1,2,3,4,5,8,9,11,12,14,15"}
recs = []
for rec, cases in set_devices(range(S * 100000 + a, S * 100000 + a + n), reversals=(True, False)):
    for key, train, hold, floor in cases:
        for name, terms in SETS.items():
            try:
                m, _ = fit_default([train], terms)
                rec[f"{key}/{name}"] = heldout_ratio(m, hold, floor)
            except (ValueError, ArithmeticError) as exc:     # a fit that fails is recorded, not dropped
                rec[f"{key}/{name}"] = float("nan")
                rec[f"{key}/{name}/error"] = f"{type(exc).__name__}: {exc}"
    recs.append(rec)
    print(json.dumps(rec), flush=True)
with open(out, "w") as fh:
    fh.writelines(json.dumps(r) + "\n" for r in recs)
