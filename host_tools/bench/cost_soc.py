"""`hdrg cost --target ice40`: the whole pipeline on the iCE40 UP5K as the C twin on a RISC-V core
(vectors/hdl/hdrg_soc.v; docs/COST.md "iCE40 UP5K: the C twin on a RISC-V core").

* **Firmware**: firmware_ref/c/hdrg_fw.c (unchanged) and firmware_ref/c/rv32 (reset, link script,
  the mailbox loop) cross-compiled by Debian's riscv64-unknown-elf-gcc for RV32IMC at -Os; the ROM
  image (``rom.hex``: one 32-bit word per line, zero-filled to the ROM of the link script).
* **Bit-exact**: check-impl of every pipeline vector set through tb_soc under Verilator (``--binary``)
  and, because Icarus simulates the core at tens of thousands of clocks per second (every vector
  would take hours), under Icarus on the first ICARUS_FIRST vectors of every case of ICARUS_SETS
  (every table of the set loaded).  A firmware built with ``-DHDRG_BREAK_ROUNDING`` must fail (the same
  simulation binary with ``+rom=``; the first BROKEN_FIRST vectors of every e2e case).  Cycles per
  sample: from the testbench (``start`` to ``done``).
* **Synthesis and place-and-route**: ``synth_ice40 -dsp`` of the pin-light ``hdrg_soc_pnr`` with
  the ROM image, ``nextpnr-ice40 --up5k --package sg48 --freq 24`` (Fmax).

The core is PicoRV32 from the pythondata-cpu-picorv32 package (ISC licence; in the project's test
extra).  Nothing is copied from a table: every figure comes from the build and the run of the call.
"""
from __future__ import annotations

import os
import re
import struct
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from host_tools import vectors as V
from host_tools.bench import cost_fpga, cost_rtl
from host_tools.bench.cost_tools import CostError, need, run_tool, tool_version

ROOT = Path(__file__).resolve().parent.parent.parent
C_DIR = ROOT / "firmware_ref" / "c"
RV_DIR = C_DIR / "rv32"
HDL = V.DEFAULT_DIR / "hdl"
SOC = (HDL / "hdrg_soc.v", HDL / "hdrg_soc_ram.v")
TB_SOC = HDL / "tb_soc.v"
PNR_TOP = HDL / "hdrg_soc_pnr.v"
RV_GCC = "riscv64-unknown-elf-gcc"          # Debian: gcc-riscv64-unknown-elf
RV_FLAGS = ("-march=rv32imc", "-mabi=ilp32", "-Os", "-std=c99", "-Wall", "-Wextra", "-Werror", "-ffreestanding",
            "-nostdlib", "-ffunction-sections", "-fdata-sections", "-Wl,--gc-sections")
SETS = ("evaluator", "sequencer", "e2e", "aux", "validity")
# Icarus: the e2e set (the default 17-term mode-reversal tables at every drive frequency), its first
# ICARUS_FIRST vectors per case (about 1 min: a table load alone, with its CRC, is about 3 s of Icarus)
ICARUS_SETS = ("e2e",)
ICARUS_FIRST = 8
BROKEN_SET, BROKEN_FIRST = "e2e", 40        # a broken firmware must fail the first 40 vectors of every e2e case
OUTPUT_CLOCK_MHZ = cost_fpga.FMAX_GOAL_MHZ  # the clock the highest output rate is stated at


def picorv32() -> Path:
    """picorv32.v of the pythondata-cpu-picorv32 package; CostError naming the package when absent."""
    try:
        import pythondata_cpu_picorv32 as pkg
    except ImportError:
        raise CostError("the RISC-V core is not installed: pip install pythondata-cpu-picorv32 (in the project's "
                        "test extra: pip install -e '.[test]')") from None
    path = Path(pkg.data_location) / "picorv32.v"
    if not path.is_file():
        raise CostError(f"{path}: picorv32.v missing from the pythondata-cpu-picorv32 package")
    return path


def rom_words() -> int:
    """The ROM's size in 32-bit words, from the link script (the one place it is set)."""
    m = re.search(r"ROM \(rx\)\s*:\s*ORIGIN = 0x0+, LENGTH = (\d+)K", (RV_DIR / "link.ld").read_text())
    if not m:
        raise CostError(f"{RV_DIR / 'link.ld'}: no 'ROM (rx) : ORIGIN = 0x0, LENGTH = <n>K' line")
    return int(m.group(1)) * 256


def firmware(work: Path, defines=()) -> dict:
    """Build the SoC firmware (RV32IMC, -Os): ``{"elf", "hex", "rom_bytes", "functions"}``
    (rom_bytes: the image's .text, code and constants; functions: name -> bytes of each symbol of the
    image, functions and constant tables alike, from nm)."""
    work.mkdir(parents=True, exist_ok=True)
    tag = "".join("_" + d for d in defines)
    elf, binf, hexf = work / f"soc{tag}.elf", work / f"soc{tag}.bin", work / f"rom{tag}.hex"
    run_tool([need(RV_GCC), *RV_FLAGS, *(f"-D{d}" for d in defines), "-T", RV_DIR / "link.ld", f"-I{C_DIR}",
              RV_DIR / "start.S", RV_DIR / "hdrg_soc_main.c", C_DIR / "hdrg_fw.c", "-lgcc", "-o", elf],
             what=RV_GCC)
    run_tool([need("riscv64-unknown-elf-objcopy"), "-O", "binary", "-j", ".text", elf, binf], what="objcopy")
    image = binf.read_bytes()
    image += b"\0" * (-len(image) % 4)
    words = list(struct.unpack(f"<{len(image) // 4}I", image))
    n = rom_words()
    if len(words) > n:
        raise CostError(f"the firmware image is {len(image)} B, the ROM {4 * n} B (link.ld)")
    hexf.write_text("".join(f"{w:08x}\n" for w in words + [0] * (n - len(words))))
    funcs = {}
    for line in run_tool([need("riscv64-unknown-elf-nm"), "-S", "--size-sort", elf], what="nm").splitlines():
        parts = line.split()
        if len(parts) == 4 and parts[2] in "tT":
            funcs[parts[3]] = int(parts[1], 16)
    return {"elf": elf, "hex": hexf, "rom_bytes": len(image), "functions": funcs}


def build_tb(sim: str, work: Path) -> list:
    """tb_soc + hdrg_soc + PicoRV32 under ``sim`` ("icarus" or "verilator"); returns the argv that
    speaks the protocol (add ``+rom=FILE``)."""
    work.mkdir(parents=True, exist_ok=True)
    src = [TB_SOC, *SOC, picorv32()]
    if sim == "icarus":
        exe = work / "tb_soc.vvp"
        run_tool([need("iverilog"), "-g2005", f"-I{HDL}", "-Ptb_soc.ROM_WORDS=%d" % rom_words(), "-o", exe, *src],
                 what="iverilog")
        return [need("vvp"), "-n", str(exe)]
    if sim == "verilator":
        obj = work / "vl_soc"
        run_tool([need("verilator"), "--binary", "-j", "0", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2",
                  "-MAKEFLAGS", "OPT_FAST=-O2",     # the model's C++ at -O2 (Verilator's default -Os is slower)
                  "--top-module", "tb_soc", f"-I{HDL}", f"-GROM_WORDS={rom_words()}", "-Mdir", obj, *src],
                 what="verilator", timeout=1800)
        return [str(obj / "Vtb_soc")]
    raise CostError(f"unknown simulator {sim!r} (icarus, verilator)")


def check(argv: list, rom: Path, work: Path, sets=SETS, first_rows=None, tag: str = "", log=print) -> dict:
    """check-impl of the SoC (``argv`` of build_tb, firmware image ``rom``) on each of ``sets``
    (``first_rows``: the first vectors of every case), one simulator process per set, as many at
    once as the machine has cores: ``{set: {"vectors", "mismatches", "first", "samples",
    "cycles_max", "cycles_mean"}}``."""
    def one(name):
        return cost_rtl.check_set([*argv, f"+rom={rom}"], name, work / f"cycles_soc_{tag}_{name}.txt", timeout=7200,
                                  first_rows=first_rows)

    rows = {n: s["rows"] for n, s in V.read_manifest(V.DEFAULT_DIR)["sets"].items()}
    order = sorted(sets, key=lambda n: -rows.get(n, 0))         # the largest sets first
    with ThreadPoolExecutor(max_workers=max(1, min(len(sets), os.cpu_count() or 1))) as pool:
        done = dict(zip(order, pool.map(one, order)))
    out = {n: done[n] for n in sets}
    for name, x in out.items():
        log(f"  soc {tag} {name}: {x['vectors']} vectors, {x['mismatches']} mismatches, "
            f"max {x['cycles_max']} / mean {x['cycles_mean']} cycles per sample")
    return out


def synth_pnr(work: Path, rom: Path, seed: int = 1) -> dict:
    """synth_ice40 -dsp of hdrg_soc_pnr with the ROM image, then nextpnr-ice40 --up5k: cells,
    resources, Fmax (cost_fpga.nextpnr_up5k)."""
    js, stat = work / "pnr_soc.json", work / "stat_ice40_soc.txt"
    files = " ".join(str(f) for f in (PNR_TOP, *SOC, picorv32()))
    cmd = (f'read_verilog -DHDRG_SOC_ROM="{rom}" {files}; chparam -set ROM_WORDS {rom_words()} hdrg_soc; '
           f"synth_ice40 -dsp -top hdrg_soc_pnr -json {js}; tee -o {stat} stat")
    run_tool([need("yosys"), "-q", "-p", cmd], what="yosys", timeout=3600)
    cells = cost_fpga.yosys_cells(stat.read_text())
    return {"cells": cells, **cost_fpga.resources("ice40", cells), "pnr": cost_fpga.nextpnr_up5k(js, work, "soc", seed)}


def _strip(per_set: dict) -> dict:
    return {n: {k: v for k, v in x.items() if k != "first"} for n, x in per_set.items()}


def measure_soc(work: Path, log=print) -> dict:
    """Every figure of `hdrg cost --target ice40` (see the module doc)."""
    work.mkdir(parents=True, exist_ok=True)
    picorv32()                                  # the core's package first: it names what to install
    tools = {"riscv64-unknown-elf-gcc": tool_version(RV_GCC), "yosys": tool_version("yosys", "-V"),
             "iverilog": tool_version("iverilog", "-V"), "verilator": tool_version("verilator"),
             "nextpnr-ice40": tool_version("nextpnr-ice40"), "picorv32": _core_version()}
    fw = firmware(work)
    broken_fw = firmware(work, (cost_rtl.BREAK,))
    log(f"  firmware: {fw['rom_bytes']} B of {4 * rom_words()} B ROM (RV32IMC -Os)")
    vl = build_tb("verilator", work)
    every = check(vl, fw["hex"], work, tag="verilator", log=log)
    broken = check(vl, broken_fw["hex"], work, sets=(BROKEN_SET,), first_rows=BROKEN_FIRST, tag="broken", log=log)
    ic = check(build_tb("icarus", work), fw["hex"], work, sets=ICARUS_SETS, first_rows=ICARUS_FIRST, tag="icarus",
               log=log)
    syn = synth_pnr(work, fw["hex"])
    p = syn.pop("pnr")
    log(f"  yosys + nextpnr hdrg_soc_pnr: {syn['luts']} LUT4, {syn['dsps']} SB_MAC16, {syn['brams']} EBR, "
        f"{syn['sprams']} SPRAM; {p}")
    worst = max(x["cycles_max"] for x in every.values())
    res = {"target": "ice40",
           "design": "vectors/hdl/hdrg_soc.v (the whole pipeline: the C twin on PicoRV32 RV32IMC, "
                     "firmware_ref/c/rv32; ROM in EBR, RAM in SPRAM)",
           "scope": "whole pipeline", "tools": tools, "device": "iCE40 UP5K (sg48)",
           "firmware": {"rom_bytes": fw["rom_bytes"], "rom_capacity_bytes": 4 * rom_words(),
                        "functions": fw["functions"]},
           "bit_exact": (all(x["mismatches"] == 0 and x["vectors"] > 0 for r in (every, ic) for x in r.values())),
           "vectors": sum(x["vectors"] for x in every.values()),
           "verilator": _strip(every), "icarus": _strip(ic), "icarus_first_rows": ICARUS_FIRST,
           "icarus_vectors": sum(x["vectors"] for x in ic.values()),
           "first_mismatch": next((x["first"] for r in (every, ic) for x in r.values() if x["first"]), None),
           "broken_build_caught": broken[BROKEN_SET]["mismatches"] > 0,
           "broken_build_mismatches": broken[BROKEN_SET]["mismatches"],
           "broken_build_vectors": broken[BROKEN_SET]["vectors"], "broken_build_set": BROKEN_SET,
           "broken_build_first_rows": BROKEN_FIRST,
           "cycles_per_sample": worst,
           "cycles_per_sample_mean": {n: x["cycles_mean"] for n, x in every.items() if x["samples"]},
           "output_rate_hz_at_24mhz": int(OUTPUT_CLOCK_MHZ * 1e6 // worst),
           **syn, "fmax_mhz": p["fmax_mhz"], "pnr": p,
           "goals": {"luts": [syn["luts"], cost_fpga.UP5K["luts"]], "dsps": [syn["dsps"], cost_fpga.UP5K["dsps"]],
                     "brams": [syn["brams"], cost_fpga.UP5K["brams"]],
                     "sprams": [syn["sprams"], cost_fpga.UP5K["sprams"]],
                     "fmax_mhz": [p["fmax_mhz"], cost_fpga.FMAX_GOAL_MHZ]}}
    res["evaluator_alone"] = cost_fpga.measure_evaluator("ice40", work, log)
    return res


def _core_version() -> str:
    import pythondata_cpu_picorv32 as pkg
    return f"picorv32 {pkg.data_git_describe} (pythondata-cpu-picorv32 {pkg.version_str})"


def summary_lines(r: dict) -> list:
    """The SoC lines of `hdrg cost --target ice40`'s summary."""
    return [f"  firmware {r['firmware']['rom_bytes']} B of {r['firmware']['rom_capacity_bytes']} B ROM; "
            f"{r['sprams']} SPRAM; highest output rate at {OUTPUT_CLOCK_MHZ:g} MHz {r['output_rate_hz_at_24mhz']} Hz",
            "  per set (Verilator, every vector: mismatches, max / mean cycles per sample): "
            + "; ".join(f"{n} {x['vectors']} vectors {x['mismatches']}"
                        + (f", {x['cycles_max']}/{x['cycles_mean']}" if x["samples"] else "")
                        for n, x in r["verilator"].items()),
            f"  Icarus, the first {r['icarus_first_rows']} vectors of every case of {', '.join(r['icarus'])}: "
            f"{r['icarus_vectors']} vectors, "
            f"{sum(x['mismatches'] for x in r['icarus'].values())} mismatches",
            f"  broken firmware caught: {r['broken_build_caught']} ({r['broken_build_mismatches']} of "
            f"{r['broken_build_vectors']} {BROKEN_SET} vectors differ)"]
