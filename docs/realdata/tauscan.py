"""tau scan (held-out rms1, deg/h) of cubicLag[tau] and cubicT+(T-L)[tau] over all splits. Usage: python tauscan.py"""
import csv
SPL = ["C->H", "H->C", "c1h->c2", "hc2->c1", "blk5"]
for ax in "xy":
    d = {(r["model"], r["split"]): r for r in csv.DictReader(open(f"tofu_{ax}.tsv"), delimiter="\t")}
    for fam in ("cubicLag", "cubicT+(T-L)", "lagpoly"):
        print(f"axis {ax} {fam}: tau | " + " ".join(f"{s:>8s}" for s in SPL) + " |  max   (cubicT: " +
              " ".join(f"{float(d[('cubicT', s)]['rms1']):.1f}" for s in SPL) + ")")
        for tau in (3, 10, 20, 30, 50, 70, 100, 150, 200, 300, 500, 700, 1000, 2000):
            v = [float(d[(f"{fam}[{tau}]", s)]["rms1"]) for s in SPL]
            print(f"   {tau:5d} | " + " ".join(f"{x:8.1f}" for x in v) + f" | {max(v):6.1f}")
