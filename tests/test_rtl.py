"""The RTL (vectors/hdl): the whole pipeline hdrg_top behind the check-impl protocol (tb_top.v) and
the time-multiplexed evaluator alone (hdrg_eval_tm.v through tb_eval_tm.v): bit-exact under Icarus
(the first cases of every pipeline set and the whole validity set in the default run; every vector
under @slow) and under
Verilator (@slow), cycles per sample within the goal, lint-clean under Verilator -Wall, and a
deliberately broken build (-DHDRG_BREAK_ROUNDING) caught."""
import re
import shutil
import subprocess

import pytest

from host_tools.bench import cost_fpga, cost_rtl, cost_soc
from host_tools import vectors as V
from host_tools.vectors.build import load_set
from host_tools.vectors.runner import requests

pytestmark = pytest.mark.target      # the target toolchains: `pytest -m target` (.ci/run)

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


def test_once_computes_each_check_once_and_returns_copies():
    """cost_rtl.once, the process memo of the RTL checks (hdrg_top's and the evaluator's alone)."""
    calls, reused = [], []
    key = ("test_once", id(calls))

    def compute():
        calls.append(1)
        return {"x": [1]}
    first = cost_rtl.once(key, compute, lambda: reused.append(1))
    first["x"].append(2)                              # the caller's copy only
    again = cost_rtl.once(key, compute, lambda: reused.append(1))
    assert calls == [1] and reused == [1] and again == {"x": [1]}


# -- the whole pipeline (vectors/hdl/hdrg_top.v) ------------------------------------------------------

def _subset(cases_per_set=1, rows_per_case=120):
    """Request lines and expected answers: the first cases of every pipeline set (table loads,
    samples, EVAL requests), at most rows_per_case samples each."""
    manifest = V.read_manifest(V.DEFAULT_DIR)
    lines, expected = [], []
    for name in ("evaluator", "sequencer", "e2e", "aux"):
        vs = load_set(V.DEFAULT_DIR, name, manifest["sets"][name])
        n_case, n_rows = -1, 0
        for line, exp, _row, _pos in requests(vs, None):
            if line.startswith("TABLE"):
                n_case, n_rows = n_case + 1, 0
            elif n_rows >= rows_per_case:
                continue
            else:
                n_rows += 1
            if n_case >= cases_per_set:
                break
            lines.append(line)
            expected.append(" ".join(exp))
    return "".join(x + "\n" for x in lines) + "QUIT\n", expected


def _run_subset(tmp_path, sim, defines=()):
    argv = cost_rtl.build_top(sim, tmp_path, defines)
    data, expected = _subset()
    cyc = tmp_path / "cycles.txt"
    pr = subprocess.run([*argv, f"+cycles={cyc}"], input=data, capture_output=True, text=True, timeout=600)
    got = pr.stdout.splitlines()[:len(expected)]
    bad = [k for k, e in enumerate(expected) if k >= len(got) or got[k] != e]
    return expected, got, bad, cost_rtl.cycles_file(cyc)


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_top_bit_exact_icarus_subset(tmp_path):
    expected, got, bad, cyc = _run_subset(tmp_path, "icarus")
    assert len(expected) > 300 and sum(e.startswith("O ") for e in expected) > 300
    assert not bad, f"{len(bad)} mismatches; first: expected {expected[bad[0]]!r}, got {got[bad[0]] if bad[0] < len(got) else None!r}"
    assert 126 < cyc["cycles_max"] <= CYCLES_GOAL and cyc["samples"] > 300     # the evaluator alone takes 126


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_top_validity_set_icarus(tmp_path):
    """The input-invalid bit (FORMATS.md "The input-invalid bit") in hdrg_top: every vector of the
    validity set (RESTART bit 1; aux_gen 1 cases whose input filters hold over a flagged sample)."""
    manifest = V.read_manifest(V.DEFAULT_DIR)
    r = cost_rtl.check_top("icarus", tmp_path, sets=("validity",), log=lambda s: None)["validity"]
    assert r["vectors"] == manifest["sets"]["validity"]["rows"] > 3000 and r["mismatches"] == 0, r["first"]
    assert r["cycles_max"] <= CYCLES_GOAL


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_broken_top_is_caught(tmp_path):
    expected, _, bad, _ = _run_subset(tmp_path, "icarus", (cost_rtl.BREAK,))
    assert len(bad) > len(expected) // 10


@pytest.mark.skipif(not VERILATOR, reason="Verilator not installed (Debian package verilator)")
def test_top_lint_clean():
    files = [str(f) for f in cost_rtl.top_sources()]
    pr = subprocess.run([VERILATOR, "--lint-only", "-Wall", "-GN_HIST=4096", "--top-module", "hdrg_top", *files],
                        capture_output=True, text=True)
    assert pr.returncode == 0 and "%Warning" not in pr.stderr, pr.stderr


@pytest.mark.slow
@pytest.mark.parametrize("sim", ["icarus", "verilator"])
@pytest.mark.skipif(not (ICARUS and VERILATOR), reason="iverilog or verilator not installed")
def test_top_every_vector(sim, tmp_path):
    """check-impl of every pipeline set (evaluator, sequencer, e2e, aux, validity) on hdrg_top."""
    manifest = V.read_manifest(V.DEFAULT_DIR)
    r = cost_rtl.check_top(sim, tmp_path, sets=cost_rtl.SETS + ("validity",), log=lambda s: None)
    for name, x in r.items():
        assert x["vectors"] == manifest["sets"][name]["rows"] and x["mismatches"] == 0, (name, x["first"])
    # the goal on every set but aux, whose tables of up to AUX_MAX_TERMS (16) terms keep the aux generators
    # busy past the evaluator: bounded by the worst legal table (cost_fpga.CYCLES_AUX_WORST)
    assert max(x["cycles_max"] for n, x in r.items() if n != "aux") <= CYCLES_GOAL
    assert CYCLES_GOAL < r["aux"]["cycles_max"] <= cost_fpga.CYCLES_AUX_WORST, r["aux"]


@pytest.mark.skipif(not ICARUS, reason="Icarus Verilog not installed (Debian package iverilog)")
def test_a_window_longer_than_the_rings_depth_is_refused(tmp_path):
    """An RTL built with a short ring (N_HIST) reads and writes the ring out of range for a longer
    diffn/lsq window: table_fits goes low and the testbench refuses the table (ERR FIELD word 9
    rate_n), as the C twin refuses a window above 4096; a window that fits loads as before."""
    m = V.read_manifest(V.DEFAULT_DIR)
    tables = [t for st in m["sets"].values() for t in st.get("tables", []) if t["fields"].get("rate_est") in (1, 2)]
    short = next(t for t in tables if t["fields"]["rate_n"] <= 6)
    long_ = next(t for t in tables if t["fields"]["rate_n"] > 6)
    exe = tmp_path / "tb_top_n6.vvp"
    subprocess.run(["iverilog", "-g2001", f"-I{cost_rtl.HDL}", "-Ptb_top.N_HIST=6", "-o", str(exe), str(cost_rtl.TB_TOP),
                    *map(str, cost_rtl.top_sources())], check=True, capture_output=True, timeout=300)
    data = "".join("TABLE " + " ".join(t["words"]) + "\n" for t in (short, long_, short)) + "QUIT\n"
    out = subprocess.run(["vvp", "-n", str(exe)], input=data, capture_output=True, text=True, timeout=300).stdout.splitlines()
    assert out[0] == f"T {len(short['words'])} {short['words'][-1]}" and out[2] == out[0]
    assert out[1].startswith("ERR FIELD word 9 rate_n") and "N_HIST 6" in out[1]


# -- the SoC (vectors/hdl/hdrg_soc.v: the C twin on PicoRV32), the iCE40 UP5K build ----------------------

RV = shutil.which(cost_soc.RV_GCC)


@pytest.fixture(scope="module")
def soc(tmp_path_factory):
    """The SoC's firmware image and its Icarus testbench (argv)."""
    if not (ICARUS and RV):
        pytest.skip("iverilog or gcc-riscv64-unknown-elf (Debian packages) not installed")
    work = tmp_path_factory.mktemp("soc")
    return cost_soc.firmware(work), cost_soc.build_tb("icarus", work), work


def _soc_run(argv, rom, lines):
    return subprocess.run([*argv, f"+rom={rom}"], input="".join(x + "\n" for x in lines) + "QUIT\n",
                          capture_output=True, text=True, timeout=600).stdout.splitlines()


def test_soc_rom_is_the_link_scripts_and_holds_the_firmware(soc):
    """The ROM that hdrg_soc.v, tb_soc.v and the link script give is one size, and the image fits it."""
    fw, _, _ = soc
    words = cost_soc.rom_words()
    for f in (cost_soc.SOC[0], cost_soc.TB_SOC):
        assert re.search(r"parameter ROM_WORDS = (\d+)", f.read_text()).group(1) == str(words), f
    assert 8000 < fw["rom_bytes"] <= 4 * words and len(fw["hex"].read_text().split()) == words


def test_soc_checks_the_table_as_the_c_twin_does(soc):
    """The firmware's table load is the C twin's hdrg_init: a wrong CRC word is refused with its
    return code and word index (the dedicated RTL leaves that check to the host); a sample or an
    eval without a loaded table is refused as the C driver refuses it; the good table loads, and a
    sample after it answers the C driver's 16 fields."""
    fw, argv, _ = soc
    m = V.read_manifest(V.DEFAULT_DIR)
    vs = load_set(V.DEFAULT_DIR, "e2e", m["sets"]["e2e"])
    table, sample = requests(vs, None, first_rows=1)[:2]
    words = table[0].split()[1:]
    bad = "TABLE " + " ".join(words[:-1] + [f"{int(words[-1], 16) ^ 1:08x}"])
    out = _soc_run(argv, fw["hex"], [sample[0], bad, sample[0], "EVAL 0 0 0", table[0], sample[0]])
    assert out[0] == out[2] == out[3] == "ERR NOTABLE send TABLE first"  # no table yet, or a refused one
    assert out[1] == f"ERR TABLE 4 word {len(words) - 1}"          # HDRG_ERR_CRC at the CRC word
    assert out[4].split() == table[1] and out[5].split() == sample[1]


def test_soc_trap_ends_the_run_with_an_error(soc, tmp_path):
    """A ROM without a program (zero words: illegal instructions) traps the core; the testbench says
    so instead of waiting for ever."""
    _, argv, _ = soc
    rom = tmp_path / "zeros.hex"
    rom.write_text("00000000\n" * cost_soc.rom_words())
    assert _soc_run(argv, rom, ["EVAL 0 0 0"]) == ["ERR TRAP the core trapped"]


@pytest.mark.skipif(not VERILATOR, reason="Verilator not installed (Debian package verilator)")
def test_soc_lint_clean():
    """hdrg_soc, its RAM and the place-and-route wrapper are clean under verilator --lint-only -Wall
    (the core's own file, and the core's outputs the SoC does not use, excepted)."""
    files = [str(cost_soc.PNR_TOP), *map(str, cost_soc.SOC), str(cost_soc.picorv32())]
    pr = subprocess.run([VERILATOR, "--lint-only", "-Wall", "-Wno-fatal", "-Wno-PINMISSING", "--top-module",
                         "hdrg_soc_pnr", *files], capture_output=True, text=True)
    ours = [line for line in pr.stderr.splitlines() if line.startswith("%Warning") and "picorv32.v" not in line]
    assert pr.returncode == 0 and not ours, (ours, pr.stderr[-500:])
