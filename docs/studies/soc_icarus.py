"""The iCE40 SoC (vectors/hdl/hdrg_soc.v: the C twin on PicoRV32) under Icarus on whole vector sets:
what `hdrg cost --target ice40` runs on every vector under Verilator only (Icarus simulates the core
at tens of thousands of clocks per second, so the cost flow runs it on a subset).  Builds the
firmware and the Icarus testbench as the cost flow does, runs check-impl on each set with every
vector, and prints the vectors, mismatches, the clock cycles from the testbench (sample requests)
and the wall time, from which Icarus's speed on this design follows.

    python docs/studies/soc_icarus.py --sets e2e > docs/studies/soc_icarus_e2e.txt    (about 45 min)
"""
import argparse
import tempfile
import time
from pathlib import Path

from host_tools.bench import cost_rtl, cost_soc
from host_tools.bench.cost_tools import tool_version


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", default="e2e", help="comma list of vector sets (default e2e)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        fw = cost_soc.firmware(work)
        argv = cost_soc.build_tb("icarus", work)
        print(f"iCE40 SoC under {tool_version('iverilog', '-V')}; firmware {fw['rom_bytes']} B (RV32IMC -Os)")
        for name in args.sets.split(","):
            t0 = time.monotonic()
            c = cost_rtl.check_set([*argv, f"+rom={fw['hex']}"], name, work / f"cycles_{name}.txt", timeout=86400)
            wall = time.monotonic() - t0
            total = c["samples"] * (c["cycles_mean"] or 0)
            print(f"{name}: {c['vectors']} vectors, {c['mismatches']} mismatches"
                  + (f" (first: {c['first']})" if c["first"] else "")
                  + f"; {c['samples']} sample requests, worst {c['cycles_max']} / mean {c['cycles_mean']} clock cycles; "
                  f"wall {wall / 60:.1f} min: about {total / wall / 1e3:.0f} k sample clocks per second")


if __name__ == "__main__":
    main()
