"""`hdrg lot` (host_tools.lot): a small simulated lot with a corrupt, a too-short and an
out-of-range device; each fails alone with its reason; the tables are byte-identical whatever the
engine (in process, 2 processes, a Dask LocalCluster) and after an interrupted run is resumed,
which refits nothing finished."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from host_tools.golden import runlog
from host_tools.lot import LotStopped, load_spec, read_manifest, run_lot
from host_tools.lot.engine import MARKER
from host_tools.lot.simulated import write_lot
from host_tools.simulation.sim_foreign import simulate_foreign

SPEC = {"min_train_s": 600, "heldout_stability_max_dph": None, "residual_rms_max_dph": None,
        "coverage_min": 0.99, "valid_share_min": 0.5, "fixed_error_max_dph": 0.01}
GOOD = ("foreign-0", "foreign-1")       # drive frequency inside the table's word: they quantize and pass


@pytest.fixture(scope="module")
def lot(tmp_path_factory):
    """4 simulated FTR devices (20 min runs) plus 3 bad ones, a manifest and a spec."""
    d = tmp_path_factory.mktemp("lot_in")
    ids = write_lot(d, 4, seed=0, reversal=False, duration_s=1200)
    rows = [line for line in (d / "manifest.csv").read_text().splitlines()]
    # corrupt: a training log with text in a number cell
    (d / "bad-corrupt").mkdir()
    lines = (d / "foreign-0" / "train.csv").read_text().splitlines()
    k = len(lines) // 2
    cells = lines[k].split(",")
    cells[1] = "x1.5e"
    lines[k] = ",".join(cells)
    (d / "bad-corrupt" / "train.csv").write_text("\n".join(lines) + "\n")
    # too short: 2 minutes of training
    (d / "bad-short").mkdir()
    runlog.write(simulate_foreign(0, 4.0, False, 0, 0, 120), d / "bad-short" / "train.csv")
    # outside the model's range: trained on 20 min, held out on a run that goes much colder
    (d / "bad-range").mkdir()
    runlog.write(simulate_foreign(1, 4.0, False, 0, 5, 1200), d / "bad-range" / "train.csv")
    runlog.write(simulate_foreign(1, 4.0, False, 1, 1, 3000), d / "bad-range" / "holdout.csv")
    rows += ["bad-corrupt,bad-corrupt/train.csv,,",
             "bad-short,bad-short/train.csv,,",
             "bad-range,bad-range/train.csv,bad-range/holdout.csv,0"]
    (d / "manifest.csv").write_text("\n".join(rows) + "\n")
    (d / "spec.json").write_text(json.dumps(SPEC))
    assert ids == ["foreign-0", "foreign-1", "foreign-2", "foreign-3"]
    return d


def _copy_run(src: Path, dst: Path) -> None:
    """A copy of the run log ``src`` with other bytes (a metadata line added): a lot takes it for
    another run (a byte-identical copy is the same run: manifest_conflicts)."""
    dst.write_text("# copy: yes\n" + src.read_text())


def _files(out: Path) -> dict:
    """Every output of a lot, the histograms included (path relative to OUT -> bytes)."""
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and p.name != ".lot.lock"}


@pytest.fixture(scope="module")
def reference(lot, tmp_path_factory):
    """The lot run in this process (1 worker): (OUT, summary)."""
    out = tmp_path_factory.mktemp("lot_ref")
    res = run_lot(lot / "manifest.csv", out, spec=lot / "spec.json", workers=1, progress=False)
    return out, res


def test_each_bad_device_fails_alone_with_its_reason(reference):
    out, res = reference
    results = {r["device"]: r for r in json.loads((out / "lot.json").read_text())["devices"]}
    assert sorted(results) == sorted(["bad-corrupt", "bad-range", "bad-short"] + [f"foreign-{i}" for i in range(4)])
    assert res["computed"] == sorted(results) and res["reused"] == []
    for dev in GOOD:
        assert results[dev]["status"] == "pass", results[dev]["reasons"]
        assert results[dev]["stage"] == "done" and results[dev]["crc32"]
    bad = results["bad-corrupt"]
    assert (bad["status"], bad["stage"]) == ("fail", "read")
    assert "bad-corrupt/train.csv" in bad["reasons"][0] and "x1.5e" in bad["reasons"][0]
    bad = results["bad-short"]
    assert (bad["status"], bad["stage"]) == ("fail", "check")
    assert "too short" in bad["reasons"][0] and "121 s" in bad["reasons"][0]
    bad = results["bad-range"]
    assert (bad["status"], bad["stage"]) == ("fail", "spec")
    assert bad["proxy_coverage"] < 0.99
    assert any("proxy coverage" in r and "coverage_min" in r for r in bad["reasons"])
    # the table rows: sorted by device, the reason in the row
    rows = (out / "lot.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == sorted(results)
    assert "too short" in next(r for r in rows if r.startswith("bad-short,"))
    md = (out / "lot.md").read_text()
    assert "| bad-corrupt | fail |" in md and "x1.5e" in md and "## Worst devices" in md
    assert (out / "lot_histograms.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_passing_device_exports_its_tables_with_its_id_and_crc(reference):
    from host_tools.fixed.export import decode_c_header
    from host_tools.fixed.quantize import read_table

    out, _ = reference
    folder = out / "devices" / "foreign-0"
    result = json.loads((folder / "result.json").read_text())
    crc = result["crc32"]
    header = (folder / "table.h").read_text()
    assert '#define HDRG_TABLE_DEVICE_ID "foreign-0"' in header and f"CRC-32 {crc}" in header
    memh = (folder / "table.memh").read_text()
    assert memh.startswith(f"// hdrg lot: device foreign-0, table CRC-32 {crc}\n")
    tj = json.loads((folder / "table.json").read_text())
    assert tj["device_id"] == "foreign-0" and tj["crc32"] == crc
    words = read_table(folder / "table.json").to_words()
    assert read_table(folder / "table.memh").to_words() == words == decode_c_header(header)
    assert f"0x{words[-1]:08x}" == crc
    marker = json.loads((folder / MARKER).read_text())
    assert marker["input_hash"] == result["input_hash"] and "table.h" in marker["files"]
    # a failed device ships no table: its tables (when it has them) are in withheld/
    assert sorted(p.name for p in (out / "devices" / "bad-range").iterdir()) == [MARKER, "model.json", "result.json",
                                                                                "withheld"]
    assert sorted(p.name for p in (out / "devices" / "bad-range" / "withheld").iterdir()) == [
        "table.h", "table.json", "table.memh"]
    marker = json.loads((out / "devices" / "bad-range" / MARKER).read_text())
    assert "withheld/table.h" in marker["files"] and "table.h" not in marker["files"]
    assert sorted(p.name for p in (out / "devices" / "bad-corrupt").iterdir()) == [MARKER, "result.json"]


def test_two_workers_give_the_same_bytes(lot, reference, tmp_path):
    res = run_lot(lot / "manifest.csv", tmp_path, spec=lot / "spec.json", workers=2, progress=False)
    assert res["computed"] == reference[1]["computed"]
    assert _files(tmp_path) == _files(reference[0])


def test_an_interrupted_lot_resumes_without_refitting(lot, reference, tmp_path):
    with pytest.raises(LotStopped):
        run_lot(lot / "manifest.csv", tmp_path, spec=lot / "spec.json", workers=2, progress=False, stop_after=3)
    done = sorted(p.parent.name for p in (tmp_path / "devices").glob(f"*/{MARKER}"))
    assert len(done) >= 3 and not (tmp_path / "lot.csv").exists()
    stamps = {d: os.stat(tmp_path / "devices" / d / MARKER).st_mtime_ns for d in done}
    res = run_lot(lot / "manifest.csv", tmp_path, spec=lot / "spec.json", workers=2, progress=False)
    assert res["reused"] == done
    assert sorted(res["computed"] + res["reused"]) == reference[1]["computed"]
    assert {d: os.stat(tmp_path / "devices" / d / MARKER).st_mtime_ns for d in done} == stamps
    assert _files(tmp_path) == _files(reference[0])

    # a third run refits nothing; a changed input redoes that device only; so does a damaged output
    res = run_lot(lot / "manifest.csv", tmp_path, spec=lot / "spec.json", workers=1, progress=False)
    assert res["computed"] == [] and len(res["reused"]) == 7
    (tmp_path / "devices" / "foreign-1" / "table.h").write_text("damaged")
    res = run_lot(lot / "manifest.csv", tmp_path, spec=lot / "spec.json", workers=1, progress=False)
    assert res["computed"] == ["foreign-1"]
    assert _files(tmp_path) == _files(reference[0])
    changed = tmp_path / "in"
    shutil.copytree(lot, changed)
    os.replace(changed / "bad-short" / "train.csv", changed / "bad-short" / "old.csv")
    _copy_run(changed / "foreign-3" / "train.csv", changed / "bad-short" / "train.csv")
    res = run_lot(changed / "manifest.csv", tmp_path, spec=changed / "spec.json", workers=1, progress=False)
    assert res["computed"] == ["bad-short"]
    # a spec that changes a key of the computation redoes every device
    (changed / "spec2.json").write_text(json.dumps({**SPEC, "dwell_s": 60}))
    res = run_lot(changed / "manifest.csv", tmp_path, spec=changed / "spec2.json", workers=2, progress=False)
    assert len(res["computed"]) == 7
    results = {r["device"]: r for r in json.loads((tmp_path / "lot.json").read_text())["devices"]}
    assert results["bad-short"]["stage"] != "check" and results["bad-short"]["train"] == ["bad-short/train.csv"]


# `hdrg lot` in a child process whose device "zz-slow" never finishes (it waits for ever where
# it would read its runs), so that the kill lands while it is calibrated, whatever the machine's speed
_SLOW_LOT = """
import sys, time
from host_tools.cli import main
from host_tools.lot import engine
real = engine.calibrate
def calibrate(job):
    if job["device"].id == "zz-slow":
        time.sleep(3600)
    return real(job)
engine.calibrate = calibrate
sys.exit(main(sys.argv[1:]))
"""


def test_a_killed_command_resumes(lot, reference, tmp_path):
    """SIGKILL `hdrg lot` while it calibrates its last device; the second command refits none of
    the devices finished before the kill, and calibrates the last one."""
    inp = tmp_path / "in"
    shutil.copytree(lot, inp)
    (inp / "zz-slow").mkdir()
    _copy_run(lot / "foreign-0" / "train.csv", inp / "zz-slow" / "train.csv")
    with open(inp / "manifest.csv", "a") as fh:
        fh.write("zz-slow,zz-slow/train.csv,,\n")
    out = tmp_path / "out"
    cmd = [sys.executable, "-c", _SLOW_LOT, "lot", str(inp / "manifest.csv"), "-o", str(out),
           "--spec", str(inp / "spec.json"), "--workers", "1", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    others = reference[1]["computed"]
    try:
        while proc.poll() is None and not all((out / "devices" / d / MARKER).exists() for d in others):
            try:
                proc.wait(timeout=0.05)
            except subprocess.TimeoutExpired:
                pass
        assert proc.poll() is None, proc.stderr.read().decode()
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL and not (out / "lot.csv").exists()
    assert not (out / "devices" / "zz-slow" / MARKER).exists()
    stamps = {d: os.stat(out / "devices" / d / MARKER).st_mtime_ns for d in others}
    res = run_lot(inp / "manifest.csv", out, spec=inp / "spec.json", workers=2, progress=False)
    assert res["computed"] == ["zz-slow"] and res["reused"] == others
    assert {d: os.stat(out / "devices" / d / MARKER).st_mtime_ns for d in others} == stamps
    ref = _files(reference[0])
    got = _files(out)
    assert {k: v for k, v in got.items() if k.startswith("devices/") and "zz-slow" not in k} == \
        {k: v for k, v in ref.items() if k.startswith("devices/")}
    rows = got["lot.csv"].decode().splitlines()
    assert [r for r in rows if not r.startswith("zz-slow,")] == ref["lot.csv"].decode().splitlines()
    assert next(r for r in rows if r.startswith("zz-slow,")).split(",")[1] == "pass"


def test_the_commands(lot, tmp_path, capsys):
    from host_tools import cli

    assert cli.main(["simulate", "--lot", "2", "--seed", "5", "--reversal", "off", "--duration", "300",
                     "-o", str(tmp_path / "sim")]) == 0
    devices = read_manifest(tmp_path / "sim")
    assert [d.id for d in devices] == ["foreign-5", "foreign-6"]
    assert all(len(d.train) == 1 and len(d.holdout) == 1 and Path(d.holdout[0].path).is_file() for d in devices)
    assert runlog.read(devices[0].train[0].path).metadata["device"] == "foreign-5"
    # a lot with failing devices: the report is written, exit 1; progress on stderr
    capsys.readouterr()
    assert cli.main(["lot", str(lot / "manifest.csv"), "-o", str(tmp_path / "out"), "--spec",
                     str(lot / "spec.json"), "--workers", "1"]) == 1
    cap = capsys.readouterr()
    assert "7 devices, " in cap.out and "(failed at: check 1, read 1" in cap.out
    assert "hdrg lot: 7/7 devices" in cap.err
    assert cli.main(["lot", "--print-spec"]) == 0
    assert json.loads(capsys.readouterr().out) == load_spec()
    assert cli.main(["lot", str(lot / "nothing.csv"), "-o", str(tmp_path / "o2")]) == 2
    assert "nothing.csv" in capsys.readouterr().err


@pytest.mark.parametrize("text, needle", [
    ("device,train\nA 1,a.csv\n", "field 'device': 'A 1' is not a device id"),
    ("device,train\n../x,a.csv\n", "is not a device id"),
    ("device,train,extra\nA1,a.csv,1\n", "unknown column(s) extra"),
    ("device,holdout\nA1,a.csv\n", "missing column(s) train"),
    ("device,train\nA1,\n", "field 'train': empty"),
    ("device,train,holdout,power_on_s\nA1,a.csv,b.csv,soon\n", "field 'power_on_s': 'soon' is not a number"),
    ("device,train,holdout,power_on_s\nA1,a.csv,b.csv;c.csv,1;2;3\n", "3 marks for 2 held-out runs"),
    ("device,train,power_on_s\nA1,a.csv,5\n", "no held-out run"),
    ("device,train\nA1,a.csv,b.csv\n", "3 cells, the header has 2"),
    ("# only a comment\n", "empty manifest"),
])
def test_a_bad_manifest_is_refused_naming_line_and_field(tmp_path, text, needle):
    path = tmp_path / "manifest.csv"
    path.write_text(text)
    with pytest.raises(ValueError) as exc:
        read_manifest(path)
    assert needle in str(exc.value) and str(path) in str(exc.value)


def test_the_manifest_and_the_directory_convention(tmp_path):
    (tmp_path / "m.csv").write_text("# lot 7\ndevice,train,holdout,power_on_s\n\nB2,b/t.csv,b/h1.csv;b/h2.csv,12.5\n"
                                    "A1,/abs/t.csv;a/t2.npz,,\n")
    a, b = read_manifest(tmp_path / "m.csv")
    assert (a.id, b.id) == ("A1", "B2") and b.where.endswith("m.csv:4")
    assert [r.name for r in a.train] == ["/abs/t.csv", "a/t2.npz"] and a.holdout == ()
    assert b.train[0].path == str(tmp_path / "b" / "t.csv") and b.power_on_s == (12.5, 12.5)
    for dev, files in (("D1", ("train.csv", "holdout.csv", "notes.txt")), ("D0", ("train_b.npz", "train_a.csv"))):
        (tmp_path / "dirs" / dev).mkdir(parents=True)
        for f in files:
            (tmp_path / "dirs" / dev / f).write_text("")
    d0, d1 = read_manifest(tmp_path / "dirs")
    assert [r.name for r in d0.train] == ["D0/train_a.csv", "D0/train_b.npz"] and d0.holdout == ()
    assert [r.name for r in d1.holdout] == ["D1/holdout.csv"]
    (tmp_path / "dirs" / "E").mkdir()
    with pytest.raises(ValueError, match="no training run"):
        read_manifest(tmp_path / "dirs")


@pytest.mark.parametrize("spec, needle", [
    ({"coverage": 0.9}, "unknown spec key(s) coverage"),
    ({"coverage_min": 1.5}, "a share between 0 and 1"),
    ({"residual_rms_max_dph": "1"}, "must be a finite number >= 0"),
    ({"require_heldout": 1}, "must be true or false"),
    ({"dwell_s": None}, "may not be null"),
    ({"stability_tau_s": 0}, "must be > 0"),
])
def test_a_bad_spec_is_refused_naming_the_key(tmp_path, spec, needle):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(spec))
    with pytest.raises(ValueError) as exc:
        load_spec(path)
    assert needle in str(exc.value) and str(path) in str(exc.value)
    assert load_spec(None)["coverage_min"] == 0.99


def test_a_device_that_breaks_the_pipeline_fails_alone(lot, tmp_path, monkeypatch):
    """An unexpected error is the device's reason (marker written: it would repeat); running out
    of memory is too, without a marker, so the next run tries that device again."""
    from host_tools.lot import device

    (tmp_path / "m.csv").write_text(f"device,train,holdout\nA,{lot}/foreign-0/train.csv,{lot}/foreign-0/holdout.csv\n"
                                    f"B,{lot}/foreign-1/train.csv,\n")
    real = device._fit

    def broken(logs):
        if logs[0].source.endswith("foreign-0/train.csv"):
            raise MemoryError()
        raise TypeError("a bug")

    monkeypatch.setattr(device, "_fit", broken)
    res = run_lot(tmp_path / "m.csv", tmp_path / "out", spec=lot / "spec.json", workers=1, progress=False)
    results = {r["device"]: r for r in json.loads((tmp_path / "out" / "lot.json").read_text())["devices"]}
    assert (results["A"]["stage"], results["A"]["retry"]) == ("memory", True) and "out of memory" in results["A"]["reasons"][0]
    assert results["B"]["stage"] == "internal" and "TypeError: a bug" in results["B"]["reasons"][0]
    assert not (tmp_path / "out" / "devices" / "A" / MARKER).exists()
    assert (tmp_path / "out" / "devices" / "B" / MARKER).exists()
    monkeypatch.setattr(device, "_fit", real)
    res = run_lot(tmp_path / "m.csv", tmp_path / "out", spec=lot / "spec.json", workers=1, progress=False)
    assert res["computed"] == ["A"] and res["reused"] == ["B"] and res["passed"] == 1


@pytest.mark.skipif(__import__("multiprocessing").get_start_method() != "fork",
                    reason="the workers must inherit the patched function (fork)")
def test_a_device_that_kills_its_worker_process_fails_alone(lot, reference, tmp_path, monkeypatch):
    from host_tools.lot import device

    _copy_run(lot / "foreign-0" / "train.csv", tmp_path / "c.csv")      # A's run under another name and bytes
    rows = "".join(f"{d},{run}\n" for d, run in zip("ABC", (lot / "foreign-0" / "train.csv", lot / "foreign-1" /
                                                             "train.csv", tmp_path / "c.csv")))
    (tmp_path / "m.csv").write_text("device,train\n" + rows)
    real = device._fit

    def killer(logs):
        if os.environ.get("HDRG_LOT_TEST_KILL") == "1" and logs[0].source.endswith("foreign-1/train.csv"):
            os._exit(9)     # a worker process that dies (the OOM killer, a crash)
        return real(logs)

    monkeypatch.setattr(device, "_fit", killer)
    monkeypatch.setenv("HDRG_LOT_TEST_KILL", "1")
    res = run_lot(tmp_path / "m.csv", tmp_path / "out", spec=lot / "spec.json", workers=2, progress=False)
    results = {r["device"]: r for r in json.loads((tmp_path / "out" / "lot.json").read_text())["devices"]}
    assert res["computed"] == list("ABC")
    for d in "B":       # the device trained on foreign-1
        assert results[d]["stage"] == "worker" and "BrokenProcessPool" in results[d]["reasons"][0]
        assert not (tmp_path / "out" / "devices" / d / MARKER).exists()
    for d in "AC":
        assert results[d]["status"] == "pass" and (tmp_path / "out" / "devices" / d / MARKER).exists()
    monkeypatch.delenv("HDRG_LOT_TEST_KILL")
    res = run_lot(tmp_path / "m.csv", tmp_path / "out", spec=lot / "spec.json", workers=2, progress=False)
    assert res["computed"] == ["B"] and res["passed"] == 3


# last in the file: the in-process cluster leaves an idle thread behind, and the tests above fork
def test_a_dask_local_cluster_gives_the_same_bytes(lot, reference, tmp_path):
    import distributed
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        res = run_lot(lot / "manifest.csv", tmp_path, spec=lot / "spec.json", scheduler=cluster.scheduler_address,
                      progress=False)
    assert res["computed"] == reference[1]["computed"]
    assert _files(tmp_path) == _files(reference[0])


def _threads(_):
    from host_tools.lot.parallel import blas_threads
    return os.environ.get("OPENBLAS_NUM_THREADS"), os.environ.get("OMP_NUM_THREADS"), blas_threads()


def test_every_engine_runs_its_jobs_with_one_thread(monkeypatch):
    """host_tools.lot.parallel: the jobs see one BLAS thread and the thread variables at 1, in this
    process (restored after) and in the pool's processes; results come back in the items' order."""
    from host_tools.lot import parallel

    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    restore = parallel._limit_blas(2)       # conftest starts the tests with one BLAS thread
    try:
        before = parallel.blas_threads()
        assert before and set(before) == {2}
        for workers in (1, 2):
            got = parallel.map_ordered(_threads, range(3), workers=workers)
            assert all(a == b == "1" and counts and set(counts) == {1} for a, b, counts in got), (workers, got)
        assert parallel.blas_threads() == before and os.environ["OPENBLAS_NUM_THREADS"] == "2"
        assert "OMP_NUM_THREADS" not in os.environ
        with parallel.single_threaded(), parallel.single_threaded():      # re-entrant
            assert set(parallel.blas_threads()) == {1}
        assert parallel.blas_threads() == before
    finally:
        restore()
    assert parallel.map_ordered(abs, [-3, 2, -1], workers=2) == [3, 2, 1]
