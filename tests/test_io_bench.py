"""Run-log CSV speed and memory against pandas, on the same 1,000,000-row content in the same run:
``python -m pytest -m benchmark tests/test_io_bench.py -q -s`` prints the times, the ratios
hdrg / pandas and the reader's peak memory (tracemalloc) over the final arrays.

The content: t_s, freq_hz, rate_dph, mode, temp_c, aux_vdd, floats in their shortest round-trip
form (about 84 MB).  The targets: read and write within 2x of pandas.read_csv /
DataFrame.to_csv; the reader's peak at most 3x its final arrays.  The asserted bounds are looser
(a loaded machine), to catch a regression, not to measure.
"""
from __future__ import annotations

import time
import tracemalloc
import warnings

import numpy as np
import pytest

from host_tools.golden import runlog

pd = pytest.importorskip("pandas")
pytestmark = pytest.mark.benchmark
N_ROWS = 1_000_000


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    """(the log, its CSV path) with N_ROWS rows."""
    rng = np.random.default_rng(1)
    n = N_ROWS
    log = runlog.RunLog.from_arrays({"device": "bench", "sample_rate_hz": "1"}, t_s=np.arange(n) * 1.0,
                                    freq_hz=6227.0 + rng.standard_normal(n), rate_dph=rng.standard_normal(n) * 100,
                                    mode=rng.integers(0, 4, n), temp_c=20 + rng.standard_normal(n),
                                    aux_vdd=5 + rng.standard_normal(n) * 1e-3)
    path = tmp_path_factory.mktemp("bench") / "big.csv"
    runlog.write(log, path)
    return log, path


def _best(fn, rounds=3) -> float:
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def _read(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return runlog.read(path)


def test_read_speed_and_memory_against_pandas(benchmark, big):
    log, path = big
    back = _read(path)                                        # compiled / cached before timing
    assert all(np.array_equal(back[k], log[k]) for k in log.columns)
    ours = benchmark.pedantic(_read, args=(path,), rounds=3, iterations=1)
    assert len(ours) == N_ROWS
    t_ours = benchmark.stats.stats.min
    t_pandas = _best(lambda: pd.read_csv(path, comment="#"))
    tracemalloc.start()
    try:
        kept = _read(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    final = sum(v.nbytes for v in kept.columns.values())
    ratio = t_ours / t_pandas
    benchmark.extra_info.update(read_s=t_ours, pandas_read_s=t_pandas, ratio=ratio, peak_over_final=peak / final)
    print(f"\nread {N_ROWS} rows: hdrg {t_ours:.3f} s, pandas.read_csv {t_pandas:.3f} s, ratio {ratio:.2f}; "
          f"peak memory {peak / 1e6:.0f} MB = {peak / final:.2f} x the final arrays ({final / 1e6:.0f} MB)")
    assert ratio < 4.0 and peak <= 3 * final


def test_write_speed_against_pandas(benchmark, big, tmp_path):
    log, path = big
    out = tmp_path / "out.csv"
    benchmark.pedantic(runlog.write, args=(log, out), rounds=2, iterations=1)
    assert out.read_bytes() == path.read_bytes()
    t_ours = benchmark.stats.stats.min
    frame = pd.DataFrame({k: v for k, v in log.columns.items()})
    t_pandas = _best(lambda: frame.to_csv(tmp_path / "pd.csv", index=False), rounds=2)
    tracemalloc.start()
    try:
        runlog.write(log, out)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    ratio = t_ours / t_pandas
    benchmark.extra_info.update(write_s=t_ours, pandas_write_s=t_pandas, ratio=ratio, peak_mb=peak / 1e6)
    print(f"\nwrite {N_ROWS} rows: hdrg {t_ours:.3f} s ({t_ours / N_ROWS / 6 * 1e9:.0f} ns per value), "
          f"DataFrame.to_csv {t_pandas:.3f} s, ratio {ratio:.2f}; peak memory {peak / 1e6:.0f} MB")
    assert ratio < 3.0
