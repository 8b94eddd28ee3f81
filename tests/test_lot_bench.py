"""Benchmark of `hdrg lot` (host_tools.lot): throughput with 1 and 2 local workers, in one run.

Run: python -m pytest -m benchmark tests/test_lot_bench.py -s
A lot of N_DEVICES simulated foreign devices (mode reversal, the whole chamber profile for
training at 4 degC/min, a held-out run at 2 degC/min: `hdrg simulate --lot`) is calibrated from
scratch REPEATS times with 1 worker (in process) and with 2 worker processes, alternately, after a
warm-up device (numba's compiled kernels and matplotlib loaded; the pool's processes are forked
from this process and start warm too).  The best repeat of each is kept (the machine may be
running other work).

The throughput is the rate of the device phase (run_lot's "seconds"["devices"]: devices per
minute while the engine calibrates), what a lot of thousands of devices runs at; the lot's fixed
costs (the input hashes, the report: "inputs", "report", serial, once per lot) are recorded
apart, and so is the whole command's speed-up on this small lot, which they lower.  Recorded in
benchmark.extra_info and printed: seconds of both (device phase and whole command), devices per
minute, per minute per core, the speed-ups, the extrapolation to 10,000 devices on 2 cores, the
CPU seconds per device of both (this process and its workers: their ratio shows the cost of the
processes themselves, whatever else runs), the load average, and the share of the cores that
OTHER processes used during the repeats (from /proc/stat less this process tree's CPU time).

Every repeat's tables must be the same bytes.  The 2-worker run must not cost more CPU per device
than 1 worker (+15 %); the device-phase speed-up is asserted (>= MIN_SPEEDUP) only when other
processes used less than 5 % of the cores, since it needs 2 otherwise idle cores.
"""
import os
import resource
import time

import pytest

from host_tools.lot import run_lot
from host_tools.lot.simulated import write_lot

N_DEVICES = 32
REPEATS = 3
MIN_SPEEDUP = 1.7


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process and of its finished children."""
    return sum(getattr(resource.getrusage(who), f) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
               for f in ("ru_utime", "ru_stime"))


def _machine_busy_s() -> float:
    """CPU seconds the whole machine has been busy (all cores; /proc/stat), NaN when unknown."""
    try:
        with open("/proc/stat", "r", encoding="ascii") as fh:
            f = [int(x) for x in fh.readline().split()[1:]]
    except (OSError, ValueError):
        return float("nan")
    idle = f[3] + (f[4] if len(f) > 4 else 0)
    return (sum(f[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def _tables(out):
    return {name: (out / name).read_bytes() for name in ("lot.csv", "lot.md", "lot.json")}


@pytest.mark.benchmark
def test_lot_throughput_1_vs_2_workers(benchmark, tmp_path):
    lot = tmp_path / "lot"
    write_lot(lot, N_DEVICES, seed=0)
    warm = tmp_path / "warm"
    write_lot(warm, 1, seed=N_DEVICES)
    run_lot(warm / "manifest.csv", tmp_path / "warm_out", workers=1, progress=False)

    runs = {1: [], 2: []}
    outs = iter(range(1000))
    load0 = os.getloadavg()

    def one_repeat():
        for workers in (1, 2):
            out = tmp_path / f"out{workers}_{next(outs)}"
            c0, t0 = _cpu_s(), time.perf_counter()
            res = run_lot(lot / "manifest.csv", out, workers=workers, progress=False)
            runs[workers].append({"s": time.perf_counter() - t0, "cpu_s": _cpu_s() - c0, "phases": res["seconds"],
                                  "res": res, "tables": _tables(out)})

    b0, c0, t0 = _machine_busy_s(), _cpu_s(), time.perf_counter()
    benchmark.pedantic(one_repeat, rounds=REPEATS, iterations=1)
    wall, ours = time.perf_counter() - t0, _cpu_s() - c0
    others = max(0.0, (_machine_busy_s() - b0 - ours) / (wall * (os.cpu_count() or 1)))
    load1 = os.getloadavg()

    ref = runs[1][0]
    for r in runs[1] + runs[2]:
        assert len(r["res"]["computed"]) == N_DEVICES and r["tables"] == ref["tables"]
    best = {w: min(runs[w], key=lambda r: r["s"]) for w in runs}
    dev = {w: min(r["phases"]["devices"] for r in runs[w]) for w in runs}
    cpu = {w: min(r["cpu_s"] for r in runs[w]) / N_DEVICES for w in runs}
    t1, t2 = best[1]["s"], best[2]["s"]
    info = {"devices": N_DEVICES, "repeats": REPEATS, "seconds_1_worker": t1, "seconds_2_workers": t2,
            "devices_per_min_1_worker": 60.0 * N_DEVICES / t1, "devices_per_min_2_workers": 60.0 * N_DEVICES / t2,
            "devices_per_min_per_core_2_workers": 30.0 * N_DEVICES / t2, "speedup_2_vs_1": t1 / t2,
            "device_phase_s_1_worker": dev[1], "device_phase_s_2_workers": dev[2],
            "device_phase_speedup_2_vs_1": dev[1] / dev[2],
            "report_s": min(r["phases"]["report"] for r in runs[1] + runs[2]),
            "inputs_s": min(r["phases"]["inputs"] for r in runs[1] + runs[2]),
            "devices_per_min_device_phase_1_worker": 60.0 * N_DEVICES / dev[1],
            "devices_per_min_device_phase_2_workers": 60.0 * N_DEVICES / dev[2],
            "hours_for_10000_devices_2_cores": 10000 * dev[2] / N_DEVICES / 3600.0,
            "cpu_s_per_device_1_worker": cpu[1], "cpu_s_per_device_2_workers": cpu[2],
            "loadavg_1min_before": load0[0], "loadavg_1min_after": load1[0],
            "other_processes_cpu_share": others, "passed": ref["res"]["passed"],
            "all_repeats_s": {w: [round(r["s"], 3) for r in runs[w]] for w in runs}}
    benchmark.extra_info.update(info)
    print("\nlot throughput: " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                                           for k, v in info.items()))
    assert cpu[2] <= 1.15 * cpu[1], "2 workers spend more CPU per device than 1: oversubscription or repeated warm-up"
    if others < 0.05:
        assert dev[1] / dev[2] >= MIN_SPEEDUP, \
            f"device-phase speed-up {dev[1] / dev[2]:.2f} < {MIN_SPEEDUP} on an otherwise idle machine"
