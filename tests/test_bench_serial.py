"""Benchmarks of the serial link: sustained SAMPLE frames/s from the virtual device to the host
over a real pseudo-terminal (device at speed 0 with back-pressure; host decoding, CRC checks and
sequence accounting included; setup excluded), and the decoder alone on an in-memory stream.

Run: python -m pytest tests/test_bench_serial.py -m benchmark
Recorded in benchmark.extra_info: frames, seconds, frames_per_s (and bytes_per_s for the link).
"""
import time

import pytest

from host_tools.link import device as D
from host_tools import link as SL

N_FRAMES = 50_000


@pytest.mark.benchmark
@pytest.mark.parametrize("batch", [16, 64, 256])
def test_bench_link_frames_per_s(benchmark, batch):
    state = {}

    def setup():
        dev, name, _ = D.make_device("static", duration_s=float(N_FRAMES), speed=0.0, batch=batch)
        state["dev"], state["port"] = dev, SL.open_port(name)
        return (), {}

    def transfer():
        dev, port = state["dev"], state["port"]
        link = SL.HostLink(port)
        got = 0
        dev.start()
        t0 = time.perf_counter()
        deadline = time.monotonic() + 120
        try:
            while got < N_FRAMES and time.monotonic() < deadline:
                got += sum(1 for fr in link.poll() if fr.type == SL.T_SAMPLE)
            dt = time.perf_counter() - t0
        finally:
            assert dev.unplug(5.0)
            port.close()
        state["res"] = {"frames": got, "seconds": dt, "frames_per_s": got / dt,
                        "bytes_per_s": got * (SL.OVERHEAD + SL.SAMPLE.size) / dt,
                        "crc_errors": link.decoder.stats.crc_errors, "seq_gaps": link.stats.seq_gaps}

    benchmark.pedantic(transfer, setup=setup, rounds=3, iterations=1)
    res = state["res"]
    benchmark.extra_info.update(res)
    print(f"\nbatch {batch}: {res['frames_per_s']:.0f} frames/s ({res['bytes_per_s'] / 1e6:.2f} MB/s)")
    assert res["frames"] == N_FRAMES and res["crc_errors"] == 0 and res["seq_gaps"] == 0


@pytest.mark.benchmark
def test_bench_decoder_frames_per_s(benchmark):
    res = benchmark.pedantic(D.decode_benchmark, args=(100_000,), rounds=3, iterations=1)
    benchmark.extra_info.update(res)
    print(f"\ndecoder: {res['frames_per_s']:.0f} frames/s")
    assert res["frames"] == 100_000
