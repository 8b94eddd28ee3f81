"""Where the iCE40 LUT4s of the dedicated RTL go: Yosys `synth_ice40 -dsp -noflatten` of hdrg_top
(N_HIST 64; `hdrg cost --target xc7` measures it, the UP5K build is the SoC of
`hdrg cost --target ice40`), the cells of each module.  A flattened synthesis optimizes across
module boundaries, so its total is a little lower.

    python docs/studies/ice40_modules.py > docs/studies/ice40_modules.txt
"""
import re
import subprocess
import tempfile
from pathlib import Path

from host_tools.bench.cost_fpga import CELLS, TOP_N_HIST, resources
from host_tools.bench.cost_rtl import top_sources


def module_cells(stat: str) -> dict:
    """module -> {cell: count} of every '=== module ===' block of a Yosys `stat` (the hierarchy's
    total under 'design hierarchy')."""
    out = {}
    for m in re.finditer(r"^=== (.+?) ===\n(.*?)(?=^=== |\Z)", stat, re.S | re.M):
        name = re.sub(r"^\$paramod\\(\w+)\\.*$", r"\1", m.group(1).strip())
        name = "the whole design, not flattened" if name == "design hierarchy" else name
        out[name] = {c: int(n) for c, n in re.findall(r"^\s+(SB_\w+|\$\w+)\s+(\d+)$", m.group(2), re.M)}
    return out


def main():
    with tempfile.TemporaryDirectory() as d:
        stat = Path(d) / "stat.txt"
        cmd = (f"read_verilog {' '.join(str(p) for p in top_sources())}; chparam -set N_HIST {TOP_N_HIST} hdrg_top; "
               f"synth_ice40 -dsp -noflatten -top hdrg_top; tee -o {stat} stat")
        subprocess.run(["yosys", "-q", "-p", cmd], check=True)
        mods = module_cells(stat.read_text())
    keys = list(CELLS["ice40"])
    print("| module | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for name, cells in mods.items():
        r = resources("ice40", cells)
        print(f"| {name} | " + " | ".join(f"{r[k]:,}" for k in keys) + " |")


if __name__ == "__main__":
    main()
