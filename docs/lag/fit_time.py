# Measurement script of docs/ACCURACY.md "Rate and lag selection": fit time of fit_default per
# training run (foreign devices 100..105, 4 degC/min, FTR and MR), median over the devices.
# Usage: PYTHONPATH=<tree> python docs/lag/fit_time.py   (run the old and new tree at the same time)
import time
import numpy as np
from host_tools.fitting.fit_pipeline import fit_default
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

for rev in (False, True):
    ts = []
    for seed in range(100, 106):
        tr = simulate_foreign(foreign_device(seed), 4.0, rev, 0, 0, None)
        t = time.process_time()
        fit_default([tr])
        ts.append(time.process_time() - t)
    print("MR" if rev else "FTR", "fit_default CPU s per run: median %.2f, min %.2f, max %.2f" % (np.median(ts), min(ts), max(ts)), flush=True)
