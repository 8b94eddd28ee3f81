# Measurement script of docs/ACCURACY.md "Rate preference" (not part of the package).
# Usage: PYTHONPATH=. python docs/lag/rate_prefer_window.py SET START END OUT.jsonl
"""MR default fit with the rate rule before (least CV) and after (prefer iir 9) per device; held-out
std / floor over the valid samples ("r") and over the valid samples at t >= 1100 s ("rw": after every
candidate's warm-up, so no rule gains by skipping the power-on transient)."""
import json, sys, numpy as np
from host_tools.fitting import fit as F, fit_pipeline as FP
from host_tools.golden.compensate import compensate
from host_tools.bench.accuracy import device_runs
from host_tools.simulation.sim_foreign import foreign_device
S,a,b,outp = sys.argv[1:5]
fo=open(outp,"w")
for i in range(int(a), int(b)):
    seed=int(S)*100000+i; tr, ho, fl = device_runs(foreign_device(seed), True)
    t=np.asarray(ho.columns["t_s"]); rec={"seed":seed}
    for name, pref in (("before", None), ("after", "default")):
        F.RATE_PREFERRED = None if pref is None else ("iir", 8, 9)
        m,_=FP.fit_default([tr]); out=compensate(ho,m); v=out["valid"]>0; w=v&(t>=1100)
        rec[name]={"r":float(np.std(out.rate_dph[v])/fl),"rw":float(np.std(out.rate_dph[w])/fl),"rate":m.fit["rate_selection"]["chosen"],"valid_frac":float(v.mean())}
    fo.write(json.dumps(rec)+"\n"); fo.flush()
