"""Benchmark of the C99 twin (run with `pytest -m benchmark tests/test_bench_c.py -s`): per-sample
cost of hdrg_step measured inside the driver (`BENCH N REPEATS`: the inputs are in memory, the
timed loop has no parsing or output; best of REPEATS by clock()), beside the numba fixed-point
kernel (firmware_ref.kernel.run_words) measured in the same run on the same 2 x 10^6 samples.  No
timed assertions: the numbers go to ``benchmark.extra_info`` and are printed.  The checksum of the
timed C pass must equal that of the kernel's words (a correctness check, not a timing one)."""
import subprocess
import time

import numpy as np
import pytest

from firmware_ref.kernel import run_words
from host_tools.vectors.builders import make_model
from host_tools.fixed.quantize import quantize
from host_tools.simulation.sim_physics import mode_sequence
from test_c_twin import CFLAGS, GCC, build, input_records, table_line

pytestmark = [pytest.mark.benchmark,
              pytest.mark.skipif(GCC is None, reason="gcc not found on PATH: the C twin cannot be built")]
N = 2_000_000
REPEATS = 5


def paper_stream(table, n=N, seed=0):
    """A paper-like stream: proxy random walk, rate words, the 30/120 s mode cycle at 1 Hz."""
    rng = np.random.default_rng(seed)
    p = table.p_ref + np.cumsum(rng.integers(-600, 601, n))
    mode = mode_sequence(np.arange(n, dtype=float), True, 30.0, 120.0)
    restart = np.zeros(n, np.uint8)
    restart[0] = 1
    return {"p": p.astype(np.int64), "r": rng.integers(-200_000, 200_000, n).astype(np.int64),
            "mode": np.asarray(mode, np.int64), "restart": restart, "z": None}


def checksum(out, bias, flags) -> int:
    """The driver's BENCH checksum: sum of ((uint32 OUT) xor ((uint32 BIAS) << 32)) + flags mod 2^64."""
    o = np.asarray(out, np.int64).astype(np.uint64) & np.uint64(0xFFFFFFFF)
    b = (np.asarray(bias, np.int64).astype(np.uint64) & np.uint64(0xFFFFFFFF)) << np.uint64(32)
    return int(np.sum((o ^ b) + np.asarray(flags, np.uint64), dtype=np.uint64))


def c_bench(exe, table, s, repeats=REPEATS):
    """(best ns for the whole stream, checksum) from the driver's BENCH request."""
    rec = input_records(table, s)
    data = f"{table_line(table)}\nBENCH {len(rec)} {repeats}\n".encode() + rec.astype("<i8").tobytes()
    pr = subprocess.run([str(exe)], input=data, capture_output=True)
    assert pr.returncode == 0, pr.stderr
    lines = pr.stdout.decode().splitlines()
    assert lines[0].startswith("T ") and lines[1].startswith(f"BENCH {len(rec)} ")
    _, _, ns, cs = lines[1].split()
    return int(ns), int(cs, 16)


@pytest.fixture(scope="module")
def exes(tmp_path_factory):
    d = tmp_path_factory.mktemp("bench_c")
    out = {"O2": build(d, "hdrg_fw_o2", CFLAGS)}
    try:
        out["O3 native"] = build(d, "hdrg_fw_o3", CFLAGS[:1] + ("-O3", "-march=native") + CFLAGS[2:])
    except AssertionError:  # pragma: no cover - a compiler without -march=native
        pass
    return out


@pytest.mark.parametrize("estimator,n,combiner", [("diff", 1, "pair"), ("lsq", 8, "trend")])
def test_bench_c_vs_numba(benchmark, exes, estimator, n, combiner):
    table = quantize(make_model(estimator=estimator, n=n, combiner=combiner), n_random=100).table
    s = paper_stream(table)
    run_words(table, s["p"][:1000], s["r"][:1000], s["mode"][:1000])          # compile / load the cache
    res = benchmark.pedantic(run_words, args=(table, s["p"], s["r"], s["mode"], s["restart"]), rounds=5,
                             iterations=1, warmup_rounds=1)
    ns_numba = 1e9 * benchmark.stats.stats.min / N
    expect = checksum(res["out"], res["bias"], res["flags"])
    info = {"samples": N, "ns_per_sample_numba": ns_numba}
    lines = [f"{estimator} n={n} {combiner}: numba fixed kernel {ns_numba:.2f} ns/sample"]
    for name, exe in exes.items():
        ns, cs = c_bench(exe, table, s)
        assert cs == expect, f"C ({name}) computed different words than the kernel"
        info[f"ns_per_sample_c_{name.replace(' ', '_')}"] = ns / N
        lines.append(f"C twin hdrg_step ({name}): {ns / N:.2f} ns/sample ({ns / N / ns_numba:.2f} x numba)")
    # end to end through the protocol (binary block: encoding + pipe + decoding included)
    rec = input_records(table, s)
    data = f"{table_line(table)}\nBIN {N}\n".encode() + rec.astype("<i8").tobytes()
    t0 = time.perf_counter()
    pr = subprocess.run([str(exes["O2"])], input=data, capture_output=True)
    wall = time.perf_counter() - t0
    assert pr.returncode == 0
    info["ns_per_sample_c_bin_protocol_end_to_end"] = 1e9 * wall / N
    lines.append(f"C driver, BIN block end to end (I/O included): {1e9 * wall / N:.1f} ns/sample")
    benchmark.extra_info.update(info)
    print("\n" + "\n".join(lines))
