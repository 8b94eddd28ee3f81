# Measurement script of docs/LOOP.md "Generalization warning" (not part of the package).
# Usage: PYTHONPATH=. python docs/loop/generalization_gap.py SEED SHARD(0|1) OUT.jsonl
"""Per run of the loop bench plan (120 runs of SEED, runs i % 2 == SHARD): the loop's start model
(diagnose.base_model) fitted on the training run; its error (the loop's metric, deg/h) on the training
and on the held-out run."""
import sys, json, warnings
from host_tools.bench.loop import plan, _base_model
from host_tools.fitting.diagnose import error_stats, _score
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign
seed, shard = int(sys.argv[1]), int(sys.argv[2])
fo = open(sys.argv[3], "w")
for spec in plan(120, seed):
    if spec["i"] % 2 != shard: continue
    dev = foreign_device(spec["device"]); eff, rev, st = spec["effect"], spec["reversal"], spec["strength"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = simulate_foreign(dev, 4.0, rev, 0, 0, effect=eff, strength=st or 1.0)
        ho = simulate_foreign(dev, 2.0, rev, 1, 1, effect=eff, strength=st or 1.0)
        m = _base_model(tr)
        a = error_stats([tr], m); b = error_stats([ho], m)
    fo.write(json.dumps({**spec, "train": _score(a)[0], "hold": _score(b)[0]}) + "\n"); fo.flush()
