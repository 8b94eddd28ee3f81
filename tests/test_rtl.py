"""The time-multiplexed evaluator (vectors/hdl/hdrg_eval_tm.v) on the evaluator vectors through its
testbench (vectors/hdl/tb_eval_tm.v): bit-exact under Icarus and under Verilator, a constant number
of cycles per sample within the goal, lint-clean under Verilator -Wall, and a deliberately broken
build (-DHDRG_BREAK_ROUNDING) caught."""
import shutil
import subprocess

import pytest

from host_tools import cost_fpga

ICARUS = shutil.which("iverilog") and shutil.which("vvp")
VERILATOR = shutil.which("verilator")
CYCLES_GOAL = 200


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_tm_evaluator_bit_exact_icarus(tmp_path):
    meta, _ = cost_fpga._evaluator_meta()
    r = cost_fpga.rtl_check_icarus(tmp_path)
    assert r["vectors"] == meta["rows"] > 1000
    assert r["mismatches"] == 0
    assert 25 <= r["cycles"] <= CYCLES_GOAL           # at least one cycle per operation of the program


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_broken_tm_evaluator_is_caught(tmp_path):
    r = cost_fpga.rtl_check_icarus(tmp_path, ("HDRG_BREAK_ROUNDING",))
    assert r["mismatches"] > r["vectors"] // 10


@pytest.mark.skipif(not VERILATOR, reason="Verilator not installed (Debian package verilator)")
def test_tm_evaluator_lint_clean():
    pr = subprocess.run([VERILATOR, "--lint-only", "-Wall", "--top-module", "hdrg_eval_tm_pnr",
                         str(cost_fpga.HDL / "hdrg_eval_tm.v"), str(cost_fpga.HDL / "hdrg_eval_tm_pnr.v")],
                        capture_output=True, text=True)
    assert pr.returncode == 0 and "%Warning" not in pr.stderr, pr.stderr


@pytest.mark.slow
@pytest.mark.skipif(not VERILATOR, reason="Verilator not installed (Debian package verilator)")
def test_tm_evaluator_bit_exact_verilator(tmp_path):
    r = cost_fpga.rtl_check_verilator(tmp_path)
    assert r["mismatches"] == 0 and r["vectors"] > 1000 and 25 <= r["cycles"] <= CYCLES_GOAL


# -- proxy + rate (vectors/hdl/hdrg_front.v) on the pipeline sets ----------------------------------

@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
@pytest.mark.parametrize("set_name", ["sequencer", "e2e", "aux"])
def test_front_bit_exact_icarus(set_name, tmp_path):
    from host_tools import vectors as V
    rows = V.read_manifest(V.DEFAULT_DIR)["sets"][set_name]["rows"]
    r = cost_fpga.rtl_front_check(set_name, tmp_path)
    assert r["vectors"] == rows > 1000 and r["mismatches"] == 0
    assert r["cycles"] >= 4


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_broken_front_is_caught(tmp_path):
    r = cost_fpga.rtl_front_check("sequencer", tmp_path, defines=("HDRG_BREAK_ROUNDING",))
    assert r["mismatches"] > r["vectors"] // 10


@pytest.mark.slow
@pytest.mark.skipif(not VERILATOR, reason="Verilator not installed (Debian package verilator)")
@pytest.mark.parametrize("set_name", ["sequencer", "e2e"])
def test_front_bit_exact_verilator(set_name, tmp_path):
    r = cost_fpga.rtl_front_check(set_name, tmp_path, "verilator")
    assert r["vectors"] > 1000 and r["mismatches"] == 0
