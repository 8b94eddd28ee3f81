"""The full-pipeline RTL (vectors/hdl/hdrg_top.v) under Icarus and Verilator through the check-impl
protocol: tb_top.v answers TABLE / S / EVAL requests on stdin like the C driver, so
``hdrg vectors check-impl --cmd "vvp -n tb_top.vvp"`` (or the Verilator binary) runs the committed
vector sets on the RTL (docs/COST.md, "The whole pipeline in RTL").

``check_top`` builds the testbench (``iverilog -g2001`` or ``verilator --binary``), runs
check-impl set by set and reads the testbench's cycle file (``+cycles=``: clock cycles from
``start`` to ``done`` of every sample request; worst case and mean per set).  Within one process
a check is run once per (simulator, sets, defines, content of the RTL, testbench and vector files;
``once``, which cost_fpga's evaluator-alone simulations use too):
`hdrg cost --target ice40` and `--target xc7` check the same RTL, so a test run that measures
both (tests/test_cost.py, tests/test_rtl.py) simulates it once.
"""
from __future__ import annotations

import copy
import hashlib
from pathlib import Path

from host_tools import vectors as V
from host_tools.bench.cost_tools import CostError, run_tool, need
from host_tools.vectors.runner import check_impl

HDL = V.DEFAULT_DIR / "hdl"
TB_TOP = HDL / "tb_top.v"
CORE = ("hdrg_top.v", "hdrg_alu.v", "hdrg_div.v", "hdrg_eval_tm.v")
AUX = "hdrg_aux.v"                     # the aux generators (branch aux-rtl); used when hdrg_top instantiates it
SETS = ("evaluator", "sequencer", "e2e", "aux")
BREAK = "HDRG_BREAK_ROUNDING"


def top_sources() -> list:
    """The RTL files of hdrg_top (hdrg_aux.v when the top instantiates it)."""
    files = [HDL / f for f in CORE]
    if "hdrg_aux " in (HDL / "hdrg_top.v").read_text():
        files.append(HDL / AUX)
    return files


def build_top(sim: str, work: Path, defines=()) -> list:
    """Build tb_top + hdrg_top with ``sim`` ("icarus" or "verilator"); returns the command line
    (argv) that speaks the protocol."""
    work.mkdir(parents=True, exist_ok=True)
    tag = sim + "".join("_" + d for d in defines)
    src = [TB_TOP, *top_sources()]
    if sim == "icarus":
        exe = work / f"tb_top_{tag}.vvp"
        run_tool([need("iverilog"), "-g2001", "-Wall", f"-I{HDL}", *(f"-D{d}" for d in defines), "-o", exe, *src],
                 what="iverilog")
        return [need("vvp"), "-n", str(exe)]
    if sim == "verilator":
        obj = work / f"vl_top_{tag}"
        run_tool([need("verilator"), "--binary", "-j", "0", "-Wno-fatal", "-Wno-lint", "-Wno-style", "-O2", "--top-module", "tb_top",
              f"-I{HDL}", *(f"-D{d}" for d in defines), "-Mdir", obj, *src], what="verilator", timeout=1800)
        return [str(obj / "Vtb_top")]
    raise CostError(f"unknown simulator {sim!r} (icarus, verilator)")


def cycles_file(path: Path) -> dict:
    """The testbench's +cycles file: samples, worst and mean clock cycles per sample request."""
    words = path.read_text().split() if path.is_file() else []
    if len(words) != 6 or words[0::2] != ["samples", "max", "sum"]:
        raise CostError(f"{path}: no cycle count from the testbench")
    n, mx, total = int(words[1]), int(words[3]), int(words[5])
    return {"samples": n, "cycles_max": mx, "cycles_mean": round(total / n, 1) if n else None}


def check_set(argv: list, name: str, cyc: Path, timeout: float = 1800, first_rows=None) -> dict:
    """check-impl of one vector set through a testbench (``argv``, which gets ``+cycles=cyc``):
    ``{"vectors", "mismatches", "first", "samples", "cycles_max", "cycles_mean"}`` (cycles: sample
    requests only; ``first_rows``: the first vectors of every case)."""
    cyc.unlink(missing_ok=True)
    rep = check_impl([*argv, f"+cycles={cyc}"], names=[name], timeout=timeout, log=lambda s: None,
                     first_rows=first_rows)
    r = rep["sets"][name]
    return {"vectors": r["rows"], "mismatches": r["mismatches"], "first": r["first"], **cycles_file(cyc)}


def once(key: tuple, compute, reused=lambda: None):
    """``compute()``, run once per process for ``key`` and the content of the RTL and vectors
    (fingerprint()); a deep copy of the result (callers may change it). ``reused()`` is called when
    an earlier result is returned."""
    key = (*key, fingerprint())
    if key in _CHECKED:
        reused()
    else:
        _CHECKED[key] = compute()
    return copy.deepcopy(_CHECKED[key])


def check_top(sim: str, work: Path, sets=SETS, defines=(), log=print) -> dict:
    """check-impl of hdrg_top under ``sim`` on each of ``sets``: ``{set: {"vectors", "mismatches",
    "first", "samples", "cycles_max", "cycles_mean"}}`` (cycles: sample requests only); once per
    process (once())."""
    tag = f"{sim}{' ' + ' '.join(defines) if defines else ''}"
    return once(("check_top", sim, tuple(sets), tuple(defines)), lambda: _check_top(sim, work, sets, defines, log),
                lambda: log(f"  {tag}: the same RTL and vectors were checked in this process: reusing that result"))


def _check_top(sim: str, work: Path, sets, defines, log) -> dict:
    argv = build_top(sim, work, defines)
    out = {}
    for name in sets:
        out[name] = check_set(argv, name, work / f"cycles_{sim}_{name}{''.join('_' + d for d in defines)}.txt")
        log(f"  {sim}{' ' + ' '.join(defines) if defines else ''} {name}: {out[name]['vectors']} vectors, "
            f"{out[name]['mismatches']} mismatches, max {out[name]['cycles_max']} cycles/sample")
    return out


_CHECKED: dict = {}     # once()'s results in this process, by (key..., fingerprint())


def fingerprint() -> str:
    """SHA-256 of every HDL source, testbench and include and of the vector files (their manifest)."""
    h = hashlib.sha256()
    for f in sorted(HDL.glob("*.v")) + sorted(HDL.glob("*.vh")) + [V.DEFAULT_DIR / "manifest.json"]:
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()
