"""hdrg bench loop's runs (bench_loop.plan / run_one, seed 0, 120 runs, shard K/2), clean runs first:
the same records as `hdrg bench loop --shard K/2 --json`, in another order (so a partial run covers the clean runs)."""
import json, sys
from host_tools.bench import loop as bl
k = int(sys.argv[1]); out = sys.argv[2]
specs = [s for s in bl.plan(120, 0) if s["i"] % 2 == k]
specs = [s for s in specs if s["effect"] is None] + [s for s in specs if s["effect"] is not None]
recs = []
for sp in specs:
    recs.append(bl.run_one(sp))
    with open(out, "w") as fh:
        json.dump({"summary": bl.summarize(sorted(recs, key=lambda r: r["i"])), "records": recs}, fh, indent=1)
    r = recs[-1]
    print(len(recs), r["i"], r["effect"], r["verdict"], [(s["effect"], s["confirmed"]) for s in r["steps"]], r["seconds"], flush=True)
