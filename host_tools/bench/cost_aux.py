"""The aux generators in RTL (vectors/hdl/hdrg_aux.v): drive its testbench tb_aux.v with the aux
vector set under Icarus or Verilator, and synthesize the module alone for iCE40 / 7-series.

The testbench takes the record layout as parameters (the LSB position of each field in the set's
``$readmemh`` record, manifest "mem_record") and a file of each case's table start word; its inputs
per sample are the record's F, T, A0..A3, K, RESTART, Z and, from the pipeline's outputs in the
record, the sample's mode, the rate sum S and the warm-up flag (bit 4); it compares z and flag bit 32.
:func:`write_directed` writes any tables and streams in the same layout (expected values from
firmware_ref.compensate.run_reference); :func:`synth_aux` / :func:`pnr_aux` give the resources and
Fmax (hdrg_aux_pnr.v); ``op_cycles`` selects the module's OP_CYCLES (2 or 4).  docs/COST_AUX.md.
"""
from __future__ import annotations

from pathlib import Path

from host_tools import vectors as V
from host_tools.bench.cost_tools import CostError, run_tool, need
from host_tools.bench.cost_fpga import HDL, offsets_file, tb_result, record_positions, resources, yosys_cells

AUX_SOURCES = (HDL / "tb_aux.v", HDL / "hdrg_aux.v")
SET = "aux"


def aux_params(work: Path, n_vec: int | None = None) -> tuple:
    """(tb_aux parameters, plusargs) for the committed aux set (``n_vec``: only the first rows)."""
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"][SET]
    rec, pos = record_positions(meta)
    work.mkdir(parents=True, exist_ok=True)
    off_file, n_cases, n_words = offsets_file(meta, work, SET, per_case=True)
    params = {"REC": rec, "P_CASE": pos["case"], "P_F": pos["F"], "P_T": pos["T"], "P_RESTART": pos["RESTART"],
              "P_Z": pos["Z"], "P_K": pos["K"], "P_A0": pos["A0"], "P_A1": pos["A1"], "P_A2": pos["A2"],
              "P_A3": pos["A3"], "P_MODE": pos["mode"], "P_ZOUT": pos["z"], "P_S": pos["s"], "P_FLAGS": pos["flags"]}
    rows = meta["rows"] if n_vec is None else min(n_vec, meta["rows"])
    plus = [f"+vectors={V.DEFAULT_DIR / meta['mem']}", f"+tables={V.DEFAULT_DIR / meta['tables_mem']}",
            f"+offsets={off_file}", f"+n_vec={rows}", f"+n_words={n_words}", f"+n_tab={n_cases}"]
    return params, plus


def _cycles(out: str) -> dict:
    import re

    m = re.search(r"^CYCLES min=(\d+) max=(\d+)$", out, re.M)
    return {"cycles_min": int(m.group(1)), "cycles_max": int(m.group(2))} if m else {}


def rtl_aux_check(work: Path, simulator: str = "icarus", defines=(), n_vec: int | None = None,
                  files: tuple | None = None, op_cycles: int = 2) -> dict:
    """hdrg_aux (``op_cycles`` per operation: 2 or 4) on the aux set (or ``files``: the (parameters,
    plusargs) of :func:`write_directed`) under Icarus (``iverilog -g2001``) or Verilator
    (``--binary``): {vectors, mismatches, cycles (the most of one sample), cycles_min, cycles_max}."""
    params, plus = aux_params(work, n_vec) if files is None else files
    params = {**params, "OP_CYCLES": op_cycles}
    tag = simulator + f"_c{op_cycles}" + "".join("_" + d for d in defines)
    if simulator == "icarus":
        exe = work / f"tb_aux_{tag}"
        run_tool([need("iverilog"), "-g2001", "-Wall", *(f"-D{d}" for d in defines),
              *(f"-Ptb_aux.{k}={v}" for k, v in params.items()), "-o", exe, *AUX_SOURCES], what="iverilog")
        out = run_tool([need("vvp"), "-n", exe, *plus], what="vvp", timeout=1800)
    elif simulator == "verilator":
        obj = work / f"vl_aux_{tag}"
        run_tool([need("verilator"), "--binary", "-j", "0", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2", "--top-module", "tb_aux",
              *(f"-D{d}" for d in defines), *(f"-G{k}={v}" for k, v in params.items()), "-Mdir", obj,
              *AUX_SOURCES], what="verilator", timeout=900)
        out = run_tool([obj / "Vtb_aux", *plus], what="verilator run", timeout=1800)
    else:
        raise CostError(f"simulator {simulator!r}: icarus or verilator")
    return {**tb_result(out, f"{simulator} aux"), **_cycles(out)}


def lint_aux(op_cycles: int = 2) -> str:
    """``verilator --lint-only -Wall`` of hdrg_aux.v: its output (empty when clean); CostError if it fails."""
    return run_tool([need("verilator"), "--lint-only", "-Wall", f"-GOP_CYCLES={op_cycles}", HDL / "hdrg_aux.v"],
                what="verilator lint")


def synth_aux(family: str, work: Path, op_cycles: int = 2) -> dict:
    """Yosys synthesis of hdrg_aux alone (``synth_ice40 -dsp`` or ``synth_xilinx``): cells and resources."""
    work.mkdir(parents=True, exist_ok=True)
    stat = work / f"stat_aux_{family}_c{op_cycles}.txt"
    cmd = (f"read_verilog {HDL / 'hdrg_aux.v'}; chparam -set OP_CYCLES {op_cycles} hdrg_aux; "
           + ("synth_ice40 -dsp" if family == "ice40" else "synth_xilinx")
           + f" -top hdrg_aux; tee -o {stat} stat")
    run_tool([need("yosys"), "-q", "-p", cmd], what="yosys", timeout=1800)
    cells = yosys_cells(stat.read_text())
    return {"cells": cells, **resources(family, cells)}


# -- directed cases: any tables and streams, expected values from the Python reference ---------------------

def write_directed(work: Path, cases, name: str = "directed") -> tuple:
    """Write ``cases`` (a list of (firmware_ref Table, stream dict with int arrays ``f``, ``t``, ``r``,
    ``mode`` (0..3, logged), ``restart``, ``z``, ``k`` and ``aux`` (int64[n, n_chan]))) as
    ``$readmemh`` files in the aux set's record layout, with the expected z, flags, S and mode from
    firmware_ref.compensate.run_reference; returns (tb_aux parameters, plusargs) like :func:`aux_params`."""
    import numpy as np

    from firmware_ref.compensate import run_reference

    meta = V.read_manifest(V.DEFAULT_DIR)["sets"][SET]
    rec, pos = record_positions(meta)
    bits = {f["name"]: f["bits"] for f in meta["mem_record"]}
    work.mkdir(parents=True, exist_ok=True)
    lines, words, offsets = [], [], []
    for c, (table, s) in enumerate(cases):
        n = len(s["k"])
        p = s["f"] if table.proxy_kind == 0 else s["t"]
        out = run_reference(table, p, s["r"], s["mode"], s["restart"], s["z"], f=s["f"], t=s["t"], aux=s["aux"],
                            k=s["k"])
        offsets.append(len(words))
        words += [w & 0xFFFFFFFF for w in table.to_words()]
        aux = np.zeros((n, 4), np.int64)
        aux[:, :s["aux"].shape[1]] = s["aux"]
        cols = {"case": [c] * n, "F": s["f"], "T": s["t"], "R": s["r"], "MODE": s["mode"], "RESTART": s["restart"],
                "Z": s["z"], "K": s["k"], "A0": aux[:, 0], "A1": aux[:, 1], "A2": aux[:, 2], "A3": aux[:, 3],
                "mode": s["mode"], "z": out["z"], "s": out["s"], "flags": out["flags"]}
        for i in range(n):
            v = 0
            for field, col in cols.items():
                v |= (int(col[i]) & ((1 << bits[field]) - 1)) << pos[field]
            lines.append(f"{v:0{rec // 4}x}")
    vec, tab, off = (work / f"{name}.mem", work / f"{name}.tables.mem", work / f"{name}.offsets.mem")
    vec.write_text("\n".join(lines) + "\n")
    tab.write_text("".join(f"{w:08x}\n" for w in words))
    off.write_text("".join(f"{o:08x}\n" for o in offsets))
    params = {"REC": rec, "P_CASE": pos["case"], "P_F": pos["F"], "P_T": pos["T"], "P_RESTART": pos["RESTART"],
              "P_Z": pos["Z"], "P_K": pos["K"], "P_A0": pos["A0"], "P_A1": pos["A1"], "P_A2": pos["A2"],
              "P_A3": pos["A3"], "P_MODE": pos["mode"], "P_ZOUT": pos["z"], "P_S": pos["s"], "P_FLAGS": pos["flags"]}
    plus = [f"+vectors={vec}", f"+tables={tab}", f"+offsets={off}", f"+n_vec={len(lines)}", f"+n_words={len(words)}",
            f"+n_tab={len(cases)}"]
    return params, plus


def pnr_aux(work: Path, seed: int = 1, freq_mhz: float = 24.0, op_cycles: int = 2) -> dict:
    """nextpnr-ice40 --up5k of the pin-light wrapper hdrg_aux_pnr.v: Fmax of the clock, utilisation."""
    import re
    import subprocess

    work.mkdir(parents=True, exist_ok=True)
    js = work / f"aux_pnr_c{op_cycles}.json"
    run_tool([need("yosys"), "-q", "-p", f"read_verilog {HDL / 'hdrg_aux.v'} {HDL / 'hdrg_aux_pnr.v'}; "
                                     f"chparam -set OP_CYCLES {op_cycles} hdrg_aux_pnr; "
                                     f"synth_ice40 -dsp -top hdrg_aux_pnr -json {js}"], what="yosys", timeout=1800)
    pr = subprocess.run([need("nextpnr-ice40"), "--up5k", "--package", "sg48", "--json", str(js),
                         "--pcf-allow-unconstrained", "--freq", str(freq_mhz), "--seed", str(seed)],
                        capture_output=True, text=True, timeout=3600)
    log = pr.stdout + pr.stderr
    (work / f"aux_pnr_c{op_cycles}.log").write_text(log)                  # the critical path is in it
    fm = re.findall(r"Max frequency for clock '(clk[^']*)': ([\d.]+) MHz", log)
    if not fm:
        raise CostError(f"nextpnr-ice40 reported no Fmax (status {pr.returncode}):\n{log[-1500:]}")
    util = {m.group(1): (int(m.group(2)), int(m.group(3)))
            for m in re.finditer(r"(ICESTORM_LC|ICESTORM_DSP|ICESTORM_RAM|SB_IO):\s+(\d+)/\s*(\d+)", log)}
    return {"fmax_mhz": float(fm[-1][1]), "utilisation": util, "seed": seed}
