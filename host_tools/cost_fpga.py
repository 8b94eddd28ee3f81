"""`hdrg cost --target ice40|xc7`: the RTL (vectors/hdl) checked bit for bit under Icarus and
Verilator, synthesized by Yosys (``synth_ice40 -dsp``, ``synth_xilinx``) and placed and routed by
nextpnr-ice40 for an UP5K (Fmax); docs/COST.md, FPGA sections.

Split out of host_tools/cost.py (which keeps the MCU/host targets, the shared tool helpers and the
CLI); every figure comes from the build and the run of the call.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

from host_tools import vectors as V
from host_tools.cost import CostError, _run, need, tool_version

# -- FPGA: the time-multiplexed evaluator ------------------------------------------------------------

HDL = V.DEFAULT_DIR / "hdl"
TM_SOURCES = (HDL / "tb_eval_tm.v", HDL / "hdrg_eval_tm.v")
TM_TOP, TM_PNR_TOP = "hdrg_eval_tm", "hdrg_eval_tm_pnr"
FMAX_GOAL_MHZ = 24.0
# Yosys cell -> resource, per family
CELLS = {"ice40": {"luts": ("SB_LUT4",), "ffs": ("SB_DFF",), "dsps": ("SB_MAC16",), "brams": ("SB_RAM40_4K",),
                   "carries": ("SB_CARRY",)},
         "xc7": {"luts": ("LUT1", "LUT2", "LUT3", "LUT4", "LUT5", "LUT6"), "ffs": ("FD",), "dsps": ("DSP48E1",),
                 "brams": ("RAMB18E1", "RAMB36E1"), "lutrams": ("RAM32M", "RAM64M", "RAM32X1D", "RAM64X1D"),
                 "carries": ("CARRY4",)}}


def _evaluator_meta():
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"]["evaluator"]
    return meta, len(meta["tables"])


def _tb_result(out: str, what: str) -> dict:
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


def _offsets_file(meta: dict, work: Path, name: str, per_case: bool) -> tuple:
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
    off, n_tab, n_words = _offsets_file(meta, work, "evaluator", per_case=False)
    params = {"REC": rec, "P_CASE": pos["case"], "P_U": pos["u"], "P_V": pos["v"], "P_Z": pos["z"], "P_B": pos["b"],
              "P_ZC": pos["zclamped"], "HAS_BANK": int("bank" in pos), "P_BANK": pos.get("bank", 0)}
    plus = [f"+vectors={V.DEFAULT_DIR / meta['mem']}", f"+tables={V.DEFAULT_DIR / meta['tables_mem']}",
            f"+offsets={off}", f"+n_vec={meta['rows']}", f"+n_tab={n_tab}", f"+n_words={n_words}"]
    return params, plus


def rtl_check_icarus(work: Path, defines=()) -> dict:
    """The time-multiplexed evaluator's testbench under Icarus on the evaluator vectors."""
    params, plus = _eval_tb_args(work)
    exe = work / ("tb_eval_tm" + "".join("_" + d for d in defines))
    _run([need("iverilog"), "-g2001", "-Wall", *(f"-D{d}" for d in defines),
          *(f"-Ptb_eval_tm.{k}={v}" for k, v in params.items()), "-o", exe, *TM_SOURCES], what="iverilog")
    out = _run([need("vvp"), "-n", exe, *plus], what="vvp", timeout=900)
    return _tb_result(out, "icarus")


def rtl_check_verilator(work: Path) -> dict:
    """The same testbench compiled by Verilator 5 (--binary)."""
    params, plus = _eval_tb_args(work)
    obj = work / "verilator"
    _run([need("verilator"), "--binary", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2", "--top-module", "tb_eval_tm",
          *(f"-G{k}={v}" for k, v in params.items()), "-Mdir", obj, *TM_SOURCES], what="verilator", timeout=900)
    out = _run([obj / "Vtb_eval_tm", *plus], what="verilator run", timeout=900)
    return _tb_result(out, "verilator")


FRONT_SOURCES = (HDL / "tb_front.v", HDL / "hdrg_front.v")


def front_params(set_name: str, work: Path) -> tuple:
    """(testbench parameters, plusargs) of tb_front for a pipeline vector set: the LSB position of
    each field in the set's $readmemh record and a file of each case's table start word."""
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"][set_name]
    rec, pos = record_positions(meta)
    off_file, n_cases, n_words = _offsets_file(meta, work, set_name, per_case=True)
    params = {"REC": rec, "P_CASE": pos["case"], "P_F": pos["F"], "P_T": pos["T"], "P_RESTART": pos["RESTART"],
              "P_U": pos["u"], "P_V": pos["v"], "P_S": pos["s"], "P_FLAGS": pos["flags"]}
    plus = [f"+vectors={V.DEFAULT_DIR / meta['mem']}", f"+tables={V.DEFAULT_DIR / meta['tables_mem']}",
            f"+offsets={off_file}", f"+n_vec={meta['rows']}", f"+n_words={n_words}", f"+n_tab={n_cases}"]
    return params, plus


def rtl_front_check(set_name: str, work: Path, simulator: str = "icarus", defines=()) -> dict:
    """hdrg_front (proxy + rate) on a pipeline vector set under Icarus or Verilator."""
    work.mkdir(parents=True, exist_ok=True)
    params, plus = front_params(set_name, work)
    tag = f"{set_name}_{simulator}" + "".join("_" + d for d in defines)
    if simulator == "icarus":
        exe = work / f"tb_front_{tag}"
        _run([need("iverilog"), "-g2001", "-Wall", *(f"-D{d}" for d in defines),
              *(f"-Ptb_front.{k}={v}" for k, v in params.items()), "-o", exe, *FRONT_SOURCES], what="iverilog")
        out = _run([need("vvp"), "-n", exe, *plus], what="vvp", timeout=1800)
    else:
        obj = work / f"vl_front_{tag}"
        _run([need("verilator"), "--binary", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2", "--top-module", "tb_front",
              *(f"-D{d}" for d in defines), *(f"-G{k}={v}" for k, v in params.items()), "-Mdir", obj,
              *FRONT_SOURCES], what="verilator", timeout=900)
        out = _run([obj / "Vtb_front", *plus], what="verilator run", timeout=1800)
    return _tb_result(out, f"{simulator} front {set_name}")


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


def synth(family: str, work: Path) -> dict:
    """Yosys synthesis of the evaluator alone (synth_ice40 -dsp / synth_xilinx): cells and resources."""
    cmd = (f"read_verilog {HDL / 'hdrg_eval_tm.v'}; "
           + ("synth_ice40 -dsp" if family == "ice40" else "synth_xilinx") + f" -top {TM_TOP}; tee -o {work / 'stat.txt'} stat")
    _run([need("yosys"), "-q", "-p", cmd], what="yosys", timeout=900)
    cells = yosys_cells((work / "stat.txt").read_text())
    return {"cells": cells, **resources(family, cells)}


FRONT_N_HIST = 64                       # ring depth synthesized for the proxy + rate RTL (a parameter)


def synth_front(family: str, work: Path) -> dict:
    """Yosys synthesis of hdrg_front (proxy + rate; N_HIST = FRONT_N_HIST): cells and resources."""
    cmd = (f"read_verilog {HDL / 'hdrg_front.v'}; chparam -set N_HIST {FRONT_N_HIST} hdrg_front; "
           + ("synth_ice40 -dsp" if family == "ice40" else "synth_xilinx") + f" -top hdrg_front; "
           f"tee -o {work / 'stat_front.txt'} stat")
    _run([need("yosys"), "-q", "-p", cmd], what="yosys", timeout=900)
    cells = yosys_cells((work / "stat_front.txt").read_text())
    return {"n_hist": FRONT_N_HIST, "cells": cells, **resources(family, cells)}


def pnr_ice40(work: Path, seed: int = 1) -> dict:
    """nextpnr-ice40 --up5k of the pin-light wrapper: Fmax of the clock, utilisation."""
    js = work / "pnr.json"
    _run([need("yosys"), "-q", "-p", f"read_verilog {HDL / 'hdrg_eval_tm.v'} {HDL / 'hdrg_eval_tm_pnr.v'}; "
                                     f"synth_ice40 -dsp -top {TM_PNR_TOP} -json {js}"], what="yosys", timeout=900)
    pr = subprocess.run([need("nextpnr-ice40"), "--up5k", "--package", "sg48", "--json", str(js),
                         "--pcf-allow-unconstrained", "--freq", str(FMAX_GOAL_MHZ), "--seed", str(seed)],
                        capture_output=True, text=True, timeout=1200)
    log = pr.stdout + pr.stderr
    fm = re.findall(r"Max frequency for clock '(clk[^']*)': ([\d.]+) MHz", log)
    if not fm:
        raise CostError(f"nextpnr-ice40 reported no Fmax (status {pr.returncode}):\n{log[-1500:]}")
    util = {m.group(1): (int(m.group(2)), int(m.group(3)))
            for m in re.finditer(r"(ICESTORM_LC|ICESTORM_DSP|ICESTORM_RAM|SB_IO):\s+(\d+)/\s*(\d+)", log)}
    return {"fmax_mhz": float(fm[-1][1]), "utilisation": util, "seed": seed}


def measure_fpga(target: str, work: Path, log=print) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    family = "ice40" if target == "ice40" else "xc7"
    tools = {"yosys": tool_version("yosys", "-V"), "iverilog": tool_version("iverilog", "-V"),
             "verilator": tool_version("verilator")}
    ic = rtl_check_icarus(work)
    log(f"  icarus: {ic}")
    vl = rtl_check_verilator(work)
    log(f"  verilator: {vl}")
    broken = rtl_check_icarus(work, ("HDRG_BREAK_ROUNDING",))
    syn = synth(family, work)
    log(f"  yosys: {syn}")
    front = {"icarus": {n: rtl_front_check(n, work) for n in ("sequencer", "e2e", "aux")}}
    front.update(synth_front(family, work))
    front["bit_exact"] = all(r["mismatches"] == 0 and r["vectors"] > 0 for r in front["icarus"].values())
    front["cycles_per_sample_max"] = max(r["cycles"] for r in front["icarus"].values())
    log(f"  proxy + rate RTL: {front}")
    res = {"target": target, "design": "vectors/hdl/hdrg_eval_tm.v (time-multiplexed evaluator: one 32x32 multiplier)",
           "scope": "evaluator only (the rest of the pipeline is not in RTL yet: docs/COST.md)",
           "tools": tools, "bit_exact": ic["mismatches"] == 0 and vl["mismatches"] == 0 and ic["vectors"] > 0,
           "vectors": ic["vectors"], "icarus": ic, "verilator": vl, "broken_build_caught": broken["mismatches"] > 0,
           "cycles_per_sample": ic["cycles"], **{k: v for k, v in syn.items()},
           "front_end": {"design": "vectors/hdl/hdrg_front.v (proxy + rate, not time-multiplexed yet)", **front}}
    if family == "ice40":
        tools["nextpnr-ice40"] = tool_version("nextpnr-ice40")
        p = pnr_ice40(work)
        log(f"  nextpnr: {p}")
        res.update({"fmax_mhz": p["fmax_mhz"], "pnr": p, "device": "iCE40 UP5K (sg48)",
                    "samples_per_s_at_fmax": round(p["fmax_mhz"] * 1e6 / ic["cycles"])})
    else:
        res.update({"fmax_mhz": None, "device": "Xilinx 7-series (Yosys synth_xilinx; no place-and-route in Debian)"})
    return res
