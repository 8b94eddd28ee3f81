"""Benchmark of `hdrg lot` (host_tools.lot): throughput with 1 and 2 local workers, in one run.

Run: python -m pytest -m benchmark tests/test_lot_bench.py -s
A lot of N_DEVICES simulated foreign devices (mode reversal, the whole chamber profile for
training at 4 degC/min, a held-out run at 2 degC/min: `hdrg simulate --lot`) is calibrated from
scratch with 1 worker (in process) and with 2 worker processes, after a warm-up device (numba's
compiled kernels loaded).  Recorded in benchmark.extra_info and printed: seconds of both, devices
per minute, per minute per core, the 2-worker speed-up, the extrapolation to 10,000 devices, and
the CPU seconds per device of both runs (this process and its workers: their ratio shows the
cost of the processes themselves, whatever else the machine runs).  The outputs of both runs
must be the same bytes.  The wall-clock speed-up needs 2 otherwise idle cores.
"""
import resource
import time

import pytest

from host_tools.lot import run_lot
from host_tools.lot.simulated import write_lot

N_DEVICES = 8


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process and of its finished children."""
    return sum(getattr(resource.getrusage(who), f) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
               for f in ("ru_utime", "ru_stime"))


def _tables(out):
    return {name: (out / name).read_bytes() for name in ("lot.csv", "lot.md", "lot.json")}


@pytest.mark.benchmark
def test_lot_throughput_1_vs_2_workers(benchmark, tmp_path):
    lot = tmp_path / "lot"
    write_lot(lot, N_DEVICES, seed=0)
    warm = tmp_path / "warm"
    write_lot(warm, 1, seed=N_DEVICES)
    run_lot(warm / "manifest.csv", tmp_path / "warm_out", workers=1, progress=False)

    c0, t0 = _cpu_s(), time.perf_counter()
    one = run_lot(lot / "manifest.csv", tmp_path / "out1", workers=1, progress=False)
    t1, cpu1 = time.perf_counter() - t0, _cpu_s() - c0
    outs = iter(tmp_path / f"out2_{i}" for i in range(100))
    c0 = _cpu_s()
    two = benchmark.pedantic(lambda: run_lot(lot / "manifest.csv", next(outs), workers=2, progress=False),
                             rounds=1, iterations=1)
    t2, cpu2 = benchmark.stats.stats.min, _cpu_s() - c0
    assert len(one["computed"]) == len(two["computed"]) == N_DEVICES
    assert _tables(tmp_path / "out1") == _tables(tmp_path / "out2_0")
    info = {"devices": N_DEVICES, "seconds_1_worker": t1, "seconds_2_workers": t2,
            "devices_per_min_1_worker": 60.0 * N_DEVICES / t1, "devices_per_min_2_workers": 60.0 * N_DEVICES / t2,
            "devices_per_min_per_core_2_workers": 30.0 * N_DEVICES / t2, "speedup_2_vs_1": t1 / t2,
            "hours_for_10000_devices_2_cores": 10000 * t2 / N_DEVICES / 3600.0,
            "cpu_s_per_device_1_worker": cpu1 / N_DEVICES, "cpu_s_per_device_2_workers": cpu2 / N_DEVICES,
            "passed": two["passed"]}
    benchmark.extra_info.update(info)
    print("\nlot throughput: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                           for k, v in info.items()))
