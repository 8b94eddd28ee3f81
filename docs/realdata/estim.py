"""Q1: dT/dt estimator comparison, held-out rms1 per split for cubicT+v[est] and p16[est]. Usage: python estim.py"""
import csv
SPL = ["C->H", "H->C", "c1h->c2", "hc2->c1", "blk5"]
for ax in "xy":
    d = {(r["model"], r["split"]): r for r in csv.DictReader(open(f"tofu_{ax}.tsv"), delimiter="\t")}
    print(f"axis {ax}  (" + " ".join(SPL) + ")   cubicT: " + " ".join(f"{float(d[('cubicT', s)]['rms1']):.1f}" for s in SPL))
    for fam in ("cubicT+v", "p16"):
        for est in ("d1", "iir30", "iir100", "iir300", "iir1000", "ls10", "ls30", "ls100"):
            v = [float(d[(f"{fam}[{est}]", s)]["rms1"]) for s in SPL]
            print(f"  {fam:9s}[{est:7s}] " + " ".join(f"{x:8.1f}" for x in v) + f"   max {max(v):8.1f}")
