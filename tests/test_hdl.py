"""The Verilog-2001 evaluator (vectors/hdl/hdrg_evaluator.v) against the evaluator vectors, through
its $readmemh testbench (vectors/hdl/tb_evaluator.v) under Icarus Verilog: zero mismatches, and a
deliberately broken build (-DHDRG_BREAK_ROUNDING: RHU truncates) must fail."""
import re
import shutil
import subprocess

import pytest

from host_tools import vectors as V

IVERILOG = shutil.which("iverilog")
VVP = shutil.which("vvp")
pytestmark = pytest.mark.skipif(IVERILOG is None or VVP is None,
                                reason="Icarus Verilog (iverilog, vvp) not installed: the HDL testbench cannot run")
HDL = V.DEFAULT_DIR / "hdl"
SOURCES = (HDL / "tb_evaluator.v", HDL / "hdrg_evaluator.v")
# the record layout the testbench slices (case[191:176] u v z bank[79:72] b[71:8] zclamped[7:0])
TB_RECORD = [("case", 16), ("u", 32), ("v", 32), ("z", 32), ("bank", 8), ("b", 64), ("zclamped", 8)]


@pytest.fixture(scope="module")
def evaluator_meta():
    return V.read_manifest(V.DEFAULT_DIR)["sets"]["evaluator"]


def run_testbench(tmp_path, meta, defines=()):
    """Compile (iverilog -g2001 -Wall) and run; returns (vectors, mismatches, stdout)."""
    exe = tmp_path / "tb_evaluator"
    cmd = [IVERILOG, "-g2001", "-Wall", *[f"-D{d}" for d in defines], "-o", str(exe), *map(str, SOURCES)]
    pr = subprocess.run(cmd, capture_output=True, text=True)
    assert pr.returncode == 0 and not pr.stderr.strip() and not pr.stdout.strip(), pr.stderr + pr.stdout
    n_tab = len(meta["tables"])
    pr = subprocess.run([VVP, "-n", str(exe), f"+vectors={V.DEFAULT_DIR / meta['mem']}",
                         f"+tables={V.DEFAULT_DIR / meta['tables_mem']}", f"+n_vec={meta['rows']}",
                         f"+n_tab={n_tab}"], capture_output=True, text=True, timeout=300)
    assert pr.returncode == 0 and "WARNING" not in pr.stdout + pr.stderr and "ERROR" not in pr.stdout, \
        pr.stdout[-2000:] + pr.stderr[-2000:]
    m = re.search(r"^RESULT vectors=(\d+) mismatches=(\d+)$", pr.stdout, re.M)
    assert m, pr.stdout[-2000:]
    return int(m.group(1)), int(m.group(2)), pr.stdout


def test_record_layout_is_the_testbenchs(evaluator_meta):
    assert [(f["name"], f["bits"]) for f in evaluator_meta["mem_record"]] == TB_RECORD
    assert evaluator_meta["table_words"] == 73


def test_rtl_evaluator_matches_every_vector(tmp_path, evaluator_meta):
    n, bad, out = run_testbench(tmp_path, evaluator_meta)
    assert n == evaluator_meta["rows"] > 1000
    assert bad == 0, out[-3000:]


def test_broken_rtl_evaluator_is_caught(tmp_path, evaluator_meta):
    n, bad, out = run_testbench(tmp_path, evaluator_meta, defines=("HDRG_BREAK_ROUNDING",))
    assert n == evaluator_meta["rows"]
    assert bad > n // 10 and "MISMATCH vector" in out


def test_rtl_bank_select_is_checked(tmp_path, evaluator_meta):
    """The evaluator set has bank-2 vectors, and an RTL that ignores bank 2 fails on them."""
    banks = [c for c in evaluator_meta["cases"] if "two_bank" in c["name"]]
    assert len(banks) >= 6
    n, bad, out = run_testbench(tmp_path, evaluator_meta, defines=("HDRG_BREAK_BANK",))
    assert n == evaluator_meta["rows"] and bad > 100 and ", bank 2)" in out
