"""`hdrg cost`: the cycle model, the call-graph stack analysis and the Yosys report parser on
small inputs, a missing tool named with its Debian package, and every target's JSON from a real
build and run (slow; each skips with a reason when its tools are absent: CI installs them)."""
import json
import shutil
import textwrap

import pytest

from host_tools import cli
from host_tools.bench import cost, cost_fpga, cost_m4_model, cost_soc

pytestmark = pytest.mark.target      # the target toolchains: `pytest -m target` (.ci/run)

ARM = shutil.which("arm-none-eabi-gcc") and shutil.which("qemu-system-arm") and cost.NEWLIB_SPECS.is_file()
FPGA = all(shutil.which(t) for t in ("yosys", "iverilog", "vvp", "verilator"))


def test_missing_tool_names_the_debian_package(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(cost.CostError, match=r"qemu-system-arm not found: install the Debian package qemu-system-arm"):
        cost.need("qemu-system-arm")
    with pytest.raises(cost.CostError, match="gcc-arm-none-eabi"):
        cost.need("arm-none-eabi-gcc")
    with pytest.raises(cost.CostError, match="install the Debian package gcc-riscv64-unknown-elf"):
        cost.need(cost_soc.RV_GCC)


def test_missing_core_package_names_it(monkeypatch, tmp_path):
    """Without the pythondata-cpu-picorv32 package the iCE40 target says what to install, before it
    builds anything."""
    import builtins
    real = builtins.__import__

    def no_core(name, *a, **k):
        if name == "pythondata_cpu_picorv32":
            raise ImportError(name)
        return real(name, *a, **k)
    monkeypatch.setattr(builtins, "__import__", no_core)
    with pytest.raises(cost.CostError, match="pip install pythondata-cpu-picorv32"):
        cost.measure("ice40", tmp_path, log=lambda s: None)
    assert not any(tmp_path.iterdir())


def test_m4_cycle_model_counts_branches_loads_and_pops():
    dis = {0x10: ("ldr", "r0, [r1, #0]", 2), 0x12: ("ldr", "r2, [r1, #4]", 2), 0x14: ("adds", "r0, r0, r2", 2),
           0x16: ("cmp", "r0, #0", 2), 0x18: ("bne.n", "20 <x>", 2), 0x1a: ("nop", "", 2),
           0x20: ("umull", "r0, r1, r2, r3", 4), 0x24: ("pop", "{r4, r5, pc}", 2)}
    # not taken: ldr 2, ldr pipelined 1, adds 1, cmp 1, bne 1, nop 1, ... ; taken: bne 1 + P
    straight = [0x10, 0x12, 0x14, 0x16, 0x18, 0x1a]
    taken = [0x10, 0x12, 0x14, 0x16, 0x18, 0x20, 0x24]
    assert cost_m4_model.cycles_m4(straight, dis, P=2, div=7) == 2 + 1 + 1 + 1 + 1 + 1
    assert cost_m4_model.cycles_m4(taken, dis, P=2, div=7) == 2 + 1 + 1 + 1 + 3 + 1 + (1 + 3 + 2)
    assert cost_m4_model.cycles_m4(taken, dis, P=1, div=7) < cost.cycles_m4(taken, dis, P=3, div=7)
    mix, events = cost_m4_model.instruction_mix(taken + [0x12], {**dis, 0x12: ("ldr", "r2, [pc, #8]", 2)})
    assert mix == {"alu": 2, "multiply": 1, "divide": 0, "load/store": 3, "load/store multiple": 1,
                   "branch taken": 1, "branch not taken": 0}
    assert events == 4         # the taken bne, the pop into pc and the literal-pool load (twice)
    _, events = cost_m4_model.instruction_mix([0x10], {0x10: ("ldr.w", "pc, [sp], #4", 4)})
    assert events == 1         # a return through a load into pc refetches too (cycles_m4 charges it + P)


def test_worst_stack_path_from_gcc_call_graph(tmp_path):
    ci = tmp_path / "x.ci"
    ci.write_text(textwrap.dedent('''\
        graph: { title: "x.c"
        node: { title: "step" label: "step\\nx.c:1:1\\n40 bytes (static)" }
        node: { title: "x.c:eval" label: "eval\\nx.c:2:1\\n24 bytes (static)" }
        node: { title: "rhu" label: "rhu\\nx.c:3:1\\n8 bytes (static)" }
        node: { title: "__aeabi_ldivmod" label: "__aeabi_ldivmod\\n<built-in>" shape : ellipse }
        edge: { sourcename: "step" targetname: "x.c:eval" label: "x.c:1:2" }
        edge: { sourcename: "step" targetname: "rhu" }
        edge: { sourcename: "x.c:eval" targetname: "rhu" }
        edge: { sourcename: "rhu" targetname: "__aeabi_ldivmod" }
        }
        '''))
    stack, edges, dynamic = cost.call_graph(ci)
    assert stack == {"step": 40, "eval": 24, "rhu": 8, "__aeabi_ldivmod": None} and dynamic == []
    assert cost.worst_stack(stack, edges, "step") == (72, ["step", "eval", "rhu", "__aeabi_ldivmod?"])
    assert cost.reachable(edges, "eval") == {"eval", "rhu", "__aeabi_ldivmod"}


def test_stage_runs_charge_called_primitives_to_the_caller():
    where = {1: "proxy", 2: None, 3: "rate", 4: None, 5: "evaluator"}
    runs = cost._stage_runs([1, 2, 3, 4, 4, 5, 2], where)
    assert runs == [("proxy", [1, 2]), ("rate", [3, 4, 4]), ("evaluator", [5, 2])]


def test_yosys_stat_parser_sums_families():
    stat = "   Number of cells:  9\n     LUT2  3\n     LUT6  2\n     FDRE  4\n     DSP48E1  1\n\nother\n"
    cells = cost_fpga.yosys_cells(stat)
    assert cells == {"LUT2": 3, "LUT6": 2, "FDRE": 4, "DSP48E1": 1}
    r = cost_fpga.resources("xc7", cells)
    assert (r["luts"], r["ffs"], r["dsps"], r["brams"]) == (5, 4, 1, 0)


def _cost_json(target, tmp_path):
    out = tmp_path / f"{target}.json"
    rc = cli.main(["cost", "--target", target, "--json", str(out)])
    r = json.loads(out.read_text())
    assert rc == 0 and r["target"] == target and r["bit_exact"] is True
    for key in ("cycles_per_sample", "tools"):
        assert key in r
    return r


@pytest.mark.slow
@pytest.mark.parametrize("target", ["cortex-m4", "cortex-m7"])
@pytest.mark.skipif(not ARM, reason="gcc-arm-none-eabi, libnewlib-arm-none-eabi or qemu-system-arm not installed")
def test_mcu_cost_json(target, tmp_path):
    r = _cost_json(target, tmp_path)
    assert r["broken_build_caught"] is True
    assert r["-O2"]["vectors"] == r["-Os"]["vectors"] > 40000
    e2e = r["-O2"]["per_sample"]["e2e"]
    from host_tools import vectors as V
    cases = V.read_manifest(V.DEFAULT_DIR)["sets"]["e2e"]["cases"]
    assert e2e["samples"] == sum(min(cost.TRACE_SAMPLES, c["rows"][1] - c["rows"][0]) for c in cases)
    assert 100 < e2e["instructions"]["min"] <= r["instructions_per_sample"] <= e2e["instructions"]["max"] < 10000
    c = e2e["cycles_m4_model"]
    assert c["low"]["mean"] <= r["cycles_per_sample"] == c["nominal"]["mean"] <= c["high"]["mean"]
    assert r["cycles_per_sample"] >= r["instructions_per_sample"]        # >= 1 cycle per instruction
    assert 0 < r["code_bytes"] < r["code_bytes_O2"] and set(cost.STAGES["evaluator"]) & set(r["-O2"]["step_functions"])
    assert r["-O2"]["library"]["text"] > r["-Os"]["library"]["text"] > r["code_bytes"] // 2
    assert 0 < r["stack_bytes"] < 2048 and r["-O2"]["stack_step_path"][0] == cost.STEP
    st = r["per_stage"]["aux-sim"]["instructions_mean"]
    assert {"evaluator", "aux", "rate", "proxy", "step"} <= set(st) and st["aux"] > 0
    e2e_st = r["per_stage"]["e2e"]
    assert e2e_st["instructions_mean"].get("aux", 0) == 0     # Z word: no generators
    assert abs(sum(e2e_st["instructions_mean"].values()) - r["instructions_per_sample"]) < 1
    assert not any(k.startswith("other") for k in e2e_st["instructions_mean"])
    # the per-sample path has no 64-bit library division; without the aux generators it is smaller,
    # bit-exact on every other set, and refuses the aux set's tables
    assert not any(f.startswith("__") and "div" in f for f in r["-Os"]["step_functions"])
    na = r["-Os-no-aux-gen"]
    assert na["bit_exact"] is True and na["aux_tables_refused"] is True and "aux" not in na["sets"]
    assert 0 < r["code_bytes_no_aux_gen"] < r["code_bytes"]
    # the firmware entry point, generic and specialized: checked, traced, smaller
    lean, spec = r["builds"]["lean"], r["builds"]["specialized"]
    assert lean["vectors"] == r["-O2"]["vectors"] and lean["-O2"]["check"]["tables_refused"] == 0
    assert spec["defines"] == list(cost.SPECIAL_DEFINES) and spec["e2e_cases"] and len(spec["e2e_cases"]) < len(cases)
    assert spec["-O2"]["check"]["tables_refused"] > 0 and spec["-O2"]["check"]["refusals_missed"] == 0
    for b in (lean, spec):
        assert b["bit_exact"] is True and b["broken_build_caught"] is True and b["entry"] == cost.LEAN_STEP
        assert 100 < b["instructions_per_sample"] <= b["cycles_per_sample"]
        assert not any(k.startswith("other") for k in b["per_sample"]["per_stage_instructions"])
        ps = b["per_sample"]
        assert abs(sum(ps["mix"].values()) - b["instructions_per_sample"]) < 1 and ps["mix"]["multiply"] > 0
        fl = [ps["cycles_flash_no_cache"][str(w)] for w in cost_m4_model.FLASH_WAIT_STATES]
        assert b["cycles_per_sample"] < fl[0] < fl[1] < fl[2] and ps["flash_events"] > 0
        assert cost.LEAN_STEP in b["-Os"]["step_functions"] and cost.STEP not in b["-Os"]["step_functions"]
    generic_case = e2e["per_case"][spec["e2e_cases"][0]]
    assert spec["instructions_per_sample"] < generic_case["instructions"]
    assert spec["code_bytes"] < lean["code_bytes"] <= r["code_bytes"]


@pytest.mark.slow
@pytest.mark.skipif(not FPGA or not shutil.which("nextpnr-ice40"),
                    reason="yosys, iverilog, verilator or nextpnr-ice40 not installed")
def test_xc7_cost_json(tmp_path):
    """The dedicated RTL (hdrg_top): every vector under both simulators, cycles, 7-series cells."""
    r = _cost_json("xc7", tmp_path)
    from host_tools import vectors as V
    sets = V.read_manifest(V.DEFAULT_DIR)["sets"]
    assert r["scope"] == "whole pipeline" and r["broken_build_caught"] is True
    for sim in ("icarus", "verilator"):                 # every pipeline set, every vector, both simulators
        assert {n: (x["vectors"], x["mismatches"]) for n, x in r[sim].items()} == {
            n: (sets[n]["rows"], 0) for n in ("evaluator", "sequencer", "e2e", "aux")}
    cyc = {n: x["cycles_max"] for n, x in r["icarus"].items()}
    assert 126 < max(c for n, c in cyc.items() if n != "aux") <= cost_fpga.CYCLES_GOAL   # the evaluator alone: 126
    assert r["cycles_per_sample"] == max(cyc.values()) <= cost_fpga.CYCLES_AUX_WORST     # 16-term aux tables
    assert 1000 < r["luts"] and 1000 < r["ffs"] and 1 <= r["dsps"] and r["fmax_mhz"] is None
    e = r["evaluator_alone"]
    assert e["bit_exact"] is True and e["broken_build_caught"] is True and e["cycles_per_sample"] == 126
    assert e["luts"] < r["luts"] and e["dsps"] <= r["dsps"]


@pytest.mark.slow
@pytest.mark.skipif(not FPGA or not shutil.which("nextpnr-ice40") or not shutil.which(cost_soc.RV_GCC),
                    reason="yosys, iverilog, verilator, nextpnr-ice40 or gcc-riscv64-unknown-elf not installed")
def test_ice40_cost_json(tmp_path):
    """The SoC (the C twin on PicoRV32) on the UP5K: every vector under Verilator, the first of every
    e2e case under Icarus, a broken firmware caught, placed and routed within the UP5K, the cycles and the
    output rate stated."""
    r = _cost_json("ice40", tmp_path)
    from host_tools import vectors as V
    sets = V.read_manifest(V.DEFAULT_DIR)["sets"]
    assert r["scope"] == "whole pipeline" and r["bit_exact"] is True and r["first_mismatch"] is None
    assert {n: (x["vectors"], x["mismatches"]) for n, x in r["verilator"].items()} == {
        n: (sets[n]["rows"], 0) for n in cost_soc.SETS}
    per_case = {n: sum(min(cost_soc.ICARUS_FIRST, c["rows"][1] - c["rows"][0]) for c in sets[n]["cases"])
                for n in cost_soc.ICARUS_SETS}
    assert {n: (x["vectors"], x["mismatches"]) for n, x in r["icarus"].items()} == {n: (per_case[n], 0) for n in per_case}
    assert r["broken_build_caught"] is True and r["broken_build_mismatches"] > r["broken_build_vectors"] // 2
    assert r["firmware"]["rom_bytes"] <= r["firmware"]["rom_capacity_bytes"] and "hdrg_step_aux" in r["firmware"]["functions"]
    cyc = {n: x["cycles_max"] for n, x in r["verilator"].items() if x["samples"]}
    assert r["cycles_per_sample"] == max(cyc.values()) and r["output_rate_hz_at_24mhz"] == 24_000_000 // max(cyc.values())
    assert r["pnr"]["fits"] is True and r["pnr"]["utilisation"]["ICESTORM_DSP"][0] == r["dsps"]
    for k in ("luts", "dsps", "brams", "sprams"):
        assert 0 < r[k] <= cost_fpga.UP5K[k], k
    assert r["fmax_mhz"] >= cost_fpga.FMAX_GOAL_MHZ
    e = r["evaluator_alone"]
    assert e["luts"] <= 5280 and e["dsps"] <= 8 and e["fmax_mhz"] >= cost_fpga.FMAX_GOAL_MHZ


@pytest.mark.skipif(not shutil.which("gcc"), reason="gcc not installed")
def test_check_cases_of_host_specialized_build(tmp_path):
    """check_cases on the host build of the specialized lean driver: its configuration's vectors match,
    every other table is refused; the -DHDRG_BREAK_ROUNDING build of it mismatches."""
    from test_c_twin import build
    defines = ("HDRG_DRIVER_LEAN", *cost.SPECIAL_DEFINES)
    good = cost.check_cases([str(build(tmp_path, "spec", defines=defines))], cost.SPECIAL, cost.LEAN_FIELDS, log=None)
    assert good["mismatches"] == 0 and good["refusals_missed"] == 0 and good["first"] is None
    assert good["sets"]["e2e"]["vectors"] > 0 and good["tables_refused"] > 10 and good["sets"]["primitives"]["vectors"] > 0
    bad = cost.check_cases([str(build(tmp_path, "broken", defines=(*defines, "HDRG_BREAK_ROUNDING")))], cost.SPECIAL,
                           cost.LEAN_FIELDS, log=None)
    assert bad["mismatches"] > 0 and bad["vectors"] == good["vectors"]


@pytest.mark.skipif(not shutil.which("gcc"), reason="gcc not installed")
def test_host_cost_json(tmp_path):
    r = _cost_json("host", tmp_path)
    assert r["vectors"] > 40000 and r["ns_per_sample"] > 0 and r["code_bytes"] > 1000
