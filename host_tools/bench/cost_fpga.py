"""`hdrg cost --target xc7`: the dedicated RTL (vectors/hdl/hdrg_top.v) checked bit for bit under
Icarus and Verilator and synthesized by Yosys (``synth_xilinx``); the evaluator alone for both FPGA
targets (``synth_ice40 -dsp`` and nextpnr-ice40 for an UP5K: Fmax); the shared Yosys and nextpnr
helpers of the iCE40 SoC (host_tools/bench/cost_soc.py); docs/COST.md, FPGA sections.

* The full pipeline ``hdrg_top`` (the first row): check-impl of every pipeline vector set through
  tb_top under Icarus and Verilator (host_tools/bench/cost_rtl.py), a ``-DHDRG_BREAK_ROUNDING`` build
  that must fail, cycles per sample (worst case over the vectors, from the testbench), Yosys cells
  of ``hdrg_top`` (ring depth TOP_N_HIST).
* The evaluator alone ``hdrg_eval_tm`` (the secondary row): tb_eval_tm on the evaluator set, its
  synthesis and place-and-route (hdrg_eval_tm_pnr).

Split out of host_tools/bench/cost.py (which keeps the MCU/host targets, the shared tool helpers and the
CLI); every figure comes from the build and the run of the call.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from firmware_ref.formats import AUX_MAX_TERMS
from host_tools.bench import cost_rtl
from host_tools import vectors as V
from host_tools.bench.cost_tools import CostError, run_tool, need, tool_version

# -- FPGA: the evaluator alone (tb_eval_tm) ------------------------------------------------------------

HDL = V.DEFAULT_DIR / "hdl"
UP5K = {"luts": 5280, "dsps": 8, "brams": 30, "sprams": 4}   # iCE40 UP5K: LUT4 (logic cells), SB_MAC16, SB_RAM40_4K, SB_SPRAM256KA
UP5K_LUT_AIM = 3000                     # LUT4: "a small share of the device"
CYCLES_GOAL = 200                       # the dedicated RTL (hdrg_top)
# A sample whose aux generators (hdrg_aux: one operation per 2 cycles) run longer than the evaluator takes
# their 2 + 2 (operations + 1) cycles plus the front end before them and the tail after them (at most
# CYCLES_AUX_FRAME; 28 measured on the aux set).  The goal holds for tables of up to about 84 operations
# (6 terms of any kind); a table of up to formats.AUX_MAX_TERMS (16) terms may take up to CYCLES_AUX_WORST
# (16 oscillators of 13 operations; docs/COST_AUX.md): the aux set's 16-term tables miss the goal.
CYCLES_AUX_FRAME = 40
CYCLES_AUX_WORST = CYCLES_AUX_FRAME + 2 + 2 * (AUX_MAX_TERMS * 13 + 1)
TOP_N_HIST = 64                         # ring depth synthesized for hdrg_top (longest diffn/lsq window; vectors: 16)
TM_SOURCES = (HDL / "tb_eval_tm.v", HDL / "hdrg_eval_tm.v")
TM_TOP, TM_PNR_TOP = "hdrg_eval_tm", "hdrg_eval_tm_pnr"
FMAX_GOAL_MHZ = 24.0
# Yosys cell -> resource, per family
CELLS = {"ice40": {"luts": ("SB_LUT4",), "ffs": ("SB_DFF",), "dsps": ("SB_MAC16",), "brams": ("SB_RAM40_4K",),
                   "sprams": ("SB_SPRAM256KA",), "carries": ("SB_CARRY",)},
         "xc7": {"luts": ("LUT1", "LUT2", "LUT3", "LUT4", "LUT5", "LUT6"), "ffs": ("FD",), "dsps": ("DSP48E1",),
                 "brams": ("RAMB18E1", "RAMB36E1"), "lutrams": ("RAM32M", "RAM64M", "RAM32X1D", "RAM64X1D"),
                 "carries": ("CARRY4",)}}


def _evaluator_meta():
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["evaluator"]
    return meta, len(meta["tables"])


def tb_result(out: str, what: str) -> dict:
    m = re.search(r"^RESULT vectors=(\d+) mismatches=(\d+) cycles=(-?\d+)$", out, re.M)
    if not m or "ERROR" in out:
        raise CostError(f"{what}: no RESULT line:\n{out[-1500:]}")
    return {"vectors": int(m.group(1)), "mismatches": int(m.group(2)), "cycles": int(m.group(3))}


def record_positions(meta: dict) -> tuple:
    """(record bits, {field: LSB position}) of a set's $readmemh record (manifest "mem_record", MSB first)."""
    rec = sum(f["bits"] for f in meta["mem_record"])
    pos, top = {}, rec
    for f in meta["mem_record"]:
        top -= f["bits"]
        pos[f["name"]] = top
    return rec, pos


def offsets_file(meta: dict, work: Path, name: str, per_case: bool) -> tuple:
    """A file of table start words (one per table, or per case: the case's table) and the number of
    table words."""
    n_words = len((V.DEFAULT_DIR / meta["tables_mem"]).read_text().split())
    offsets = meta.get("table_offsets") or [k * meta["table_words"] for k in range(len(meta["tables"]))]
    rows = [offsets[c["table"]] for c in meta["cases"]] if per_case else offsets
    path = work / f"{name}.offsets.mem"
    path.write_text("".join(f"{o:08x}\n" for o in rows))
    return path, len(rows), n_words


def _eval_tb_args(work: Path) -> tuple:
    """(parameters, plusargs) of tb_eval_tm for the committed evaluator set."""
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["evaluator"]
    rec, pos = record_positions(meta)
    work.mkdir(parents=True, exist_ok=True)
    off, n_tab, n_words = offsets_file(meta, work, "evaluator", per_case=False)
    params = {"REC": rec, "P_CASE": pos["case"], "P_U": pos["u"], "P_V": pos["v"], "P_Z": pos["z"], "P_B": pos["b"],
              "P_ZC": pos["zclamped"], "HAS_BANK": int("bank" in pos), "P_BANK": pos.get("bank", 0)}
    plus = [f"+vectors={V.DEFAULT_DIR / meta['mem']}", f"+tables={V.DEFAULT_DIR / meta['tables_mem']}",
            f"+offsets={off}", f"+n_vec={meta['rows']}", f"+n_tab={n_tab}", f"+n_words={n_words}"]
    return params, plus


def rtl_check_icarus(work: Path, defines=()) -> dict:
    """The time-multiplexed evaluator's testbench under Icarus on the evaluator vectors."""
    params, plus = _eval_tb_args(work)
    exe = work / ("tb_eval_tm" + "".join("_" + d for d in defines))
    run_tool([need("iverilog"), "-g2001", "-Wall", *(f"-D{d}" for d in defines),
          *(f"-Ptb_eval_tm.{k}={v}" for k, v in params.items()), "-o", exe, *TM_SOURCES], what="iverilog")
    out = run_tool([need("vvp"), "-n", exe, *plus], what="vvp", timeout=900)
    return tb_result(out, "icarus")


def rtl_check_verilator(work: Path) -> dict:
    """The same testbench compiled by Verilator 5 (--binary)."""
    params, plus = _eval_tb_args(work)
    obj = work / "verilator"
    run_tool([need("verilator"), "--binary", "-j", "0", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2", "--top-module", "tb_eval_tm",
          *(f"-G{k}={v}" for k, v in params.items()), "-Mdir", obj, *TM_SOURCES], what="verilator", timeout=900)
    out = run_tool([obj / "Vtb_eval_tm", *plus], what="verilator run", timeout=900)
    return tb_result(out, "verilator")


def yosys_cells(stat: str) -> dict:
    """Cell name -> count from the last 'Number of cells' block of a Yosys `stat`."""
    block = stat[stat.rindex("Number of cells"):]
    out = {}
    for line in block.splitlines()[1:]:
        m = re.match(r"\s+(\S+)\s+(\d+)$", line)
        if not m:
            break
        out[m.group(1)] = int(m.group(2))
    return out


def resources(family: str, cells: dict) -> dict:
    return {k: sum(n for c, n in cells.items() if c.startswith(prefixes)) for k, prefixes in CELLS[family].items()}


def _synth_cmd(family: str, sources, top: str, params: dict, out: str) -> str:
    return (f"read_verilog {' '.join(str(x) for x in sources)}; "
            + "".join(f"chparam -set {k} {v} {top}; " for k, v in params.items())
            + ("synth_ice40 -dsp" if family == "ice40" else "synth_xilinx") + f" -top {top}; " + out)


def synth(family: str, work: Path, full: bool = True) -> dict:
    """Yosys synthesis (synth_ice40 -dsp / synth_xilinx) of hdrg_top (``full``; N_HIST = TOP_N_HIST)
    or of the evaluator alone: cells and resources."""
    stat = work / f"stat_{family}_{'top' if full else 'eval'}.txt"
    if full:
        cmd = _synth_cmd(family, cost_rtl.top_sources(), "hdrg_top", {"N_HIST": TOP_N_HIST}, f"tee -o {stat} stat")
    else:
        cmd = _synth_cmd(family, [HDL / "hdrg_eval_tm.v"], TM_TOP, {}, f"tee -o {stat} stat")
    run_tool([need("yosys"), "-q", "-p", cmd], what="yosys", timeout=3600)
    cells = yosys_cells(stat.read_text())
    return {"cells": cells, **resources(family, cells)}


def pnr_evaluator(work: Path, seed: int = 1) -> dict:
    """nextpnr-ice40 --up5k --package sg48 of the evaluator alone's pin-light wrapper
    (hdrg_eval_tm_pnr): Fmax and utilisation (nextpnr_up5k)."""
    js = work / "pnr_eval.json"
    cmd = _synth_cmd("ice40", [HDL / "hdrg_eval_tm.v", HDL / "hdrg_eval_tm_pnr.v"], TM_PNR_TOP, {}, "")
    run_tool([need("yosys"), "-q", "-p", cmd.replace("synth_ice40 -dsp -top", f"synth_ice40 -dsp -json {js} -top")],
             what="yosys", timeout=3600)
    return nextpnr_up5k(js, work, "eval", seed)


def nextpnr_up5k(js: Path, work: Path, tag: str, seed: int = 1) -> dict:
    """nextpnr-ice40 --up5k --package sg48 --freq FMAX_GOAL_MHZ of a Yosys JSON netlist: Fmax and
    utilisation (the log: ``nextpnr_<tag>.log``); ``fits`` False (and no Fmax) when nextpnr cannot
    place it."""
    pr = subprocess.run([need("nextpnr-ice40"), "--up5k", "--package", "sg48", "--json", str(js),
                         "--pcf-allow-unconstrained", "--freq", str(FMAX_GOAL_MHZ), "--seed", str(seed)],
                        capture_output=True, text=True, timeout=3600)
    log = pr.stdout + pr.stderr
    (work / f"nextpnr_{tag}.log").write_text(log)
    util = {m.group(1): (int(m.group(2)), int(m.group(3)))
            for m in re.finditer(r"(ICESTORM_LC|ICESTORM_DSP|ICESTORM_RAM|ICESTORM_SPRAM|SB_IO):\s+(\d+)/\s*(\d+)", log)}
    fm = re.findall(r"Max frequency for clock '(clk[^']*)': ([\d.]+) MHz", log)
    if not fm:                          # no timing report: it did not place (the log says why)
        over = [k for k, (used, avail) in util.items() if used > avail]
        why = (f"does not fit the UP5K: {', '.join(f'{k} {util[k][0]}/{util[k][1]}' for k in over)}" if over
               else "nextpnr-ice40 failed (status %d): %s" % (pr.returncode, " | ".join(log.strip().splitlines()[-3:])))
        return {"fits": False, "fmax_mhz": None, "utilisation": util, "seed": seed, "error": why}
    return {"fits": True, "fmax_mhz": float(fm[-1][1]), "utilisation": util, "seed": seed}


def measure_evaluator(family: str, work: Path, log=print) -> dict:
    """The evaluator alone (the secondary row): tb_eval_tm under Icarus and Verilator, a broken
    build, synthesis, and (iCE40) place-and-route."""
    ic, vl, broken = cost_rtl.once(("evaluator",), lambda: (rtl_check_icarus(work), rtl_check_verilator(work),
                                                             rtl_check_icarus(work, ("HDRG_BREAK_ROUNDING",))))
    syn = synth(family, work, full=False)
    r = {"design": "vectors/hdl/hdrg_eval_tm.v (time-multiplexed evaluator)", "vectors": ic["vectors"],
         "bit_exact": ic["mismatches"] == 0 and vl["mismatches"] == 0 and ic["vectors"] > 0,
         "broken_build_caught": broken["mismatches"] > 0, "cycles_per_sample": ic["cycles"], **syn}
    if family == "ice40":
        p = pnr_evaluator(work)
        r.update({"fmax_mhz": p["fmax_mhz"], "pnr": p})
    log(f"  evaluator alone: {r}")
    return r


def measure_fpga(target: str, work: Path, log=print) -> dict:
    """Every figure of `hdrg cost --target xc7` (the dedicated RTL; see the module doc)."""
    if target != "xc7":
        raise CostError(f"the dedicated RTL is measured for xc7 (the iCE40 build is the SoC: cost_soc), not {target!r}")
    work.mkdir(parents=True, exist_ok=True)
    tools = {"yosys": tool_version("yosys", "-V"), "iverilog": tool_version("iverilog", "-V"),
             "verilator": tool_version("verilator")}
    ic = cost_rtl.check_top("icarus", work, log=log)
    vl = cost_rtl.check_top("verilator", work, log=log)
    broken = cost_rtl.check_top("icarus", work, sets=("sequencer",), defines=(cost_rtl.BREAK,), log=log)
    syn = synth("xc7", work)
    log(f"  yosys hdrg_top: {syn}")
    per_set = {n: {k: v for k, v in x.items() if k != "first"} for n, x in ic.items()}
    res = {"target": target,
           "design": "vectors/hdl/hdrg_top.v (the whole pipeline: sequencer, proxy, rate, aux generators, "
                     "evaluator, combiner/residual tracker, outputs; two shared 32x32 multipliers)",
           "scope": "whole pipeline", "n_hist": TOP_N_HIST, "tools": tools,
           "bit_exact": all(x["mismatches"] == 0 and x["vectors"] > 0 for r in (ic, vl) for x in r.values()),
           "vectors": sum(x["vectors"] for x in ic.values()), "icarus": per_set,
           "verilator": {n: {k: v for k, v in x.items() if k != "first"} for n, x in vl.items()},
           "first_mismatch": next((x["first"] for r in (ic, vl) for x in r.values() if x["first"]), None),
           "broken_build_caught": broken["sequencer"]["mismatches"] > 0,
           "broken_build_mismatches": broken["sequencer"]["mismatches"],
           "cycles_per_sample": max(x["cycles_max"] for x in ic.values()),
           "cycles_per_sample_mean": {n: x["cycles_mean"] for n, x in ic.items() if x["samples"]}, **syn,
           "fmax_mhz": None, "device": "Xilinx 7-series (Yosys synth_xilinx; no place-and-route in Debian)"}
    res["evaluator_alone"] = measure_evaluator("xc7", work, log)
    return res


def summary_lines(r: dict) -> list:
    """The FPGA-specific lines of `hdrg cost`'s summary."""
    lines = ["  per set (Icarus / Verilator mismatches, max / mean cycles per sample): "
             + "; ".join(f"{n} {x['vectors']} vectors {x['mismatches']}/{r['verilator'][n]['mismatches']}"
                         + (f", {x['cycles_max']}/{x['cycles_mean']}" if x["samples"] else "")
                         for n, x in r["icarus"].items())]
    if r.get("pnr") and not r["pnr"]["fits"]:
        lines.append(f"  nextpnr: {r['pnr']['error']}")
    return lines + [evaluator_line(r)]


def evaluator_line(r: dict) -> str:
    """The summary line of the evaluator alone (hdrg_eval_tm) of an FPGA record."""
    e = r["evaluator_alone"]
    return (f"  evaluator alone: bit_exact {e['bit_exact']} ({e['vectors']} vectors), {e['cycles_per_sample']} "
            f"cycles; luts {e['luts']}, ffs {e['ffs']}, dsps {e['dsps']}, brams {e['brams']}"
            + (f", fmax {e['fmax_mhz']} MHz" if e.get("fmax_mhz") else ""))
