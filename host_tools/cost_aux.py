"""The aux generators in RTL (vectors/hdl/hdrg_aux.v): drive its testbench tb_aux.v with the aux
vector set under Icarus or Verilator, and synthesize the module alone for iCE40 / 7-series.

The testbench takes the record layout as parameters (the LSB position of each field in the set's
``$readmemh`` record, manifest "mem_record") and a file of each case's table start word; its inputs
per sample are the record's F, T, A0..A3, K, RESTART, Z and, from the pipeline's outputs in the
record, the sample's mode, the rate sum S and the warm-up flag (bit 4); it compares z and flag bit 32.
"""
from __future__ import annotations

from pathlib import Path

from host_tools import vectors as V
from host_tools.cost import (CostError, HDL, _offsets_file, _run, _tb_result, need, record_positions, resources,
                             yosys_cells)

AUX_SOURCES = (HDL / "tb_aux.v", HDL / "hdrg_aux.v")
SET = "aux"


def aux_params(work: Path, n_vec: int | None = None) -> tuple:
    """(tb_aux parameters, plusargs) for the committed aux set (``n_vec``: only the first rows)."""
    meta = V.read_manifest(V.DEFAULT_DIR)["sets"][SET]
    rec, pos = record_positions(meta)
    work.mkdir(parents=True, exist_ok=True)
    off_file, n_cases, n_words = _offsets_file(meta, work, SET, per_case=True)
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


def rtl_aux_check(work: Path, simulator: str = "icarus", defines=(), n_vec: int | None = None) -> dict:
    """hdrg_aux on the aux set under Icarus (``iverilog -g2001``) or Verilator (``--binary``):
    {vectors, mismatches, cycles (the most of one sample), cycles_min, cycles_max}."""
    params, plus = aux_params(work, n_vec)
    tag = simulator + "".join("_" + d for d in defines)
    if simulator == "icarus":
        exe = work / f"tb_aux_{tag}"
        _run([need("iverilog"), "-g2001", "-Wall", *(f"-D{d}" for d in defines),
              *(f"-Ptb_aux.{k}={v}" for k, v in params.items()), "-o", exe, *AUX_SOURCES], what="iverilog")
        out = _run([need("vvp"), "-n", exe, *plus], what="vvp", timeout=1800)
    elif simulator == "verilator":
        obj = work / f"vl_aux_{tag}"
        _run([need("verilator"), "--binary", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2", "--top-module", "tb_aux",
              *(f"-D{d}" for d in defines), *(f"-G{k}={v}" for k, v in params.items()), "-Mdir", obj,
              *AUX_SOURCES], what="verilator", timeout=900)
        out = _run([obj / "Vtb_aux", *plus], what="verilator run", timeout=1800)
    else:
        raise CostError(f"simulator {simulator!r}: icarus or verilator")
    return {**_tb_result(out, f"{simulator} aux"), **_cycles(out)}


def lint_aux() -> str:
    """``verilator --lint-only -Wall`` of hdrg_aux.v: its output (empty when clean); CostError if it fails."""
    return _run([need("verilator"), "--lint-only", "-Wall", HDL / "hdrg_aux.v"], what="verilator lint")


def synth_aux(family: str, work: Path) -> dict:
    """Yosys synthesis of hdrg_aux alone (``synth_ice40 -dsp`` or ``synth_xilinx``): cells and resources."""
    work.mkdir(parents=True, exist_ok=True)
    stat = work / f"stat_aux_{family}.txt"
    cmd = (f"read_verilog {HDL / 'hdrg_aux.v'}; " + ("synth_ice40 -dsp" if family == "ice40" else "synth_xilinx")
           + f" -top hdrg_aux; tee -o {stat} stat")
    _run([need("yosys"), "-q", "-p", cmd], what="yosys", timeout=1800)
    cells = yosys_cells(stat.read_text())
    return {"cells": cells, **resources(family, cells)}
