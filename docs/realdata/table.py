"""Markdown tables from tofu_<ax>.tsv: held-out rms(1 s) [std at 1 s / std of 100-s means] per split. Usage: python table.py"""
import csv
MODELS = ["raw(mean)", "cubicT", "p16[d1]", "p16[ls30]", "p16[iir100]", "cubicT+v[d1]", "cubicT+v[ls30]",
          "cubicLag[10]", "cubicLag[20]", "cubicT+(T-L)[200]", "cubicT+(T-L)[300]", "lagpoly[100]", "cubicT+branch(s,sT)",
          "cubicT+acc_y", "cubicT+acc_xyz", "cubicT+lag(acc_y,200)", "cubicT+acc_xyz+(T-L)[200]", "cubicT+t", "cubicT+exp(-t/300)"]
SPL = ["C->H", "H->C", "c1h->c2", "hc2->c1", "blk5"]
for ax in "xy":
    rows = list(csv.DictReader(open(f"tofu_{ax}.tsv"), delimiter="\t"))
    d = {(r["model"], r["split"]): r for r in rows}
    print(f"\n**Axis {ax}** — held-out rms of 1-s means (incl. the mean offset) [std of 1-s means / std of 100-s means], deg/h\n")
    print("| model | " + " | ".join(SPL) + " |"); print("|---|" + "---|" * len(SPL))
    for m in MODELS:
        cells = []
        for s in SPL:
            r = d[(m, s)]; f = lambda k: float(r[k])
            cells.append(f"{f('rms1'):.1f} [{f('s1'):.1f}/{f('s100'):.1f}]" if f('rms1') < 1000 else f"{f('rms1'):.0e}")
        print(f"| {m} | " + " | ".join(cells) + " |")
