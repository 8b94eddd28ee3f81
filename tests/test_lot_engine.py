"""`hdrg lot` (host_tools.lot) under hostile conditions: a pool worker killed mid-lot, Ctrl-C, a
Dask worker lost, repeated and shared rows in the manifest, a spec that changes only its limits
(judged again, no refit; a failed device's tables withheld), temporary files of a killed run,
special files and malformed manifests and specs, an output folder inside the lot, the footprint
of a failed device, and the --help text."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from host_tools.lot import read_manifest, run_lot
from host_tools.lot.engine import MARKER
from host_tools.lot.inputs import manifest_conflicts, run_digests
from host_tools.lot.simulated import write_lot

SPEC = {"min_train_s": 300, "heldout_stability_max_dph": None, "residual_rms_max_dph": None}
N = 10
ENV = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}


@pytest.fixture(scope="module")
def lot(tmp_path_factory):
    """N simulated devices (10-min runs, seconds to calibrate) and a spec."""
    d = tmp_path_factory.mktemp("lot_in")
    write_lot(d, N, seed=0, reversal=False, duration_s=600)
    (d / "spec.json").write_text(json.dumps(SPEC))
    return d


@pytest.fixture(scope="module")
def reference(lot, tmp_path_factory):
    """The lot run in this process, undisturbed: (OUT, summary)."""
    out = tmp_path_factory.mktemp("lot_ref")
    return out, run_lot(lot / "manifest.csv", out, spec=lot / "spec.json", workers=1, progress=False)


def _device_files(out: Path) -> dict:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted((out / "devices").rglob("*")) if p.is_file()}


def _children(pid: int) -> list:
    """The pids of the child processes of ``pid``."""
    try:
        import psutil
        return [c.pid for c in psutil.Process(pid).children()]
    except ImportError:
        kids = []
        for task in Path(f"/proc/{pid}/task").iterdir():
            kids += [int(k) for k in (task / "children").read_text().split()]
        return kids


def _lot_command(lot: Path, out: Path, *extra, **kw) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "host_tools.cli", "lot", str(lot / "manifest.csv"), "-o", str(out), "--spec",
           str(lot / "spec.json"), "--no-progress", *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV, **kw)


def _wait_first_marker(proc, out: Path, limit_s: float = 60.0) -> None:
    end = time.monotonic() + limit_s
    while not list((out / "devices").glob(f"*/{MARKER}")):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < end, "no device finished"
        time.sleep(0.01)


def test_a_killed_pool_worker_does_not_hang_the_command(lot, reference, tmp_path):
    """SIGKILL one pool process (the OOM killer) while the lot runs: the command ends, the devices
    in flight are calibrated again, the tables are those of an undisturbed run."""
    out = tmp_path / "out"
    proc = _lot_command(lot, out, "--workers", "2")
    try:
        _wait_first_marker(proc, out)
        me = Path(f"/proc/{proc.pid}/cmdline").read_bytes()
        kids = [k for k in _children(proc.pid) if Path(f"/proc/{k}/cmdline").read_bytes() == me]     # forked workers
        assert kids, "no pool process"
        os.kill(kids[0], signal.SIGKILL)
        t0 = time.monotonic()
        stdout, stderr = proc.communicate(timeout=60)
        ended_s = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            for pid in _children(proc.pid):
                os.kill(pid, signal.SIGKILL)
            proc.kill()
            proc.communicate()
    print(f"the command ended {ended_s:.2f} s after the kill")
    assert proc.returncode in (0, 1), stderr.decode()
    assert b"Traceback" not in stderr, stderr.decode()
    assert _device_files(out) == _device_files(reference[0])
    assert (out / "lot.csv").read_bytes() == (reference[0] / "lot.csv").read_bytes()


def test_ctrl_c_stops_a_busy_lot_without_worker_tracebacks(lot, reference, tmp_path):
    out = tmp_path / "out"
    proc = _lot_command(lot, out, "--workers", "2", start_new_session=True)
    try:
        _wait_first_marker(proc, out)
        os.killpg(proc.pid, signal.SIGINT)      # Ctrl-C: the terminal signals the whole group
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    text = stderr.decode()
    assert proc.returncode == 130, text
    assert "Traceback" not in text and "hdrg lot: interrupted" in text, text
    # the same command resumes: the devices finished before the stop are reused, the rest calibrated
    # (a temporary file the stop left behind is removed), the tables those of an undisturbed run
    res = run_lot(lot / "manifest.csv", out, spec=lot / "spec.json", workers=1, progress=False)
    assert res["reused"] and sorted(res["reused"] + res["computed"]) == reference[1]["computed"]
    assert _device_files(out) == _device_files(reference[0])


# -- Dask: futures released as results arrive ---------------------------------------------------------

CALLS: list = []


def _slow_double(job):
    CALLS.append(job)
    time.sleep(0.02)
    return 2 * job


def test_dask_releases_collected_results_and_never_recomputes_them():
    """run_jobs on a Dask cluster: once a result is collected the cluster holds it no more, and a
    worker lost afterwards makes the scheduler recompute none of the collected jobs."""
    import distributed

    from host_tools.lot.parallel import run_jobs

    CALLS.clear()
    n = 20
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        sched = cluster.scheduler
        got, collected_before_loss = [], None
        run = run_jobs(_slow_double, list(range(n)), scheduler=cluster.scheduler_address)
        try:
            for job, res in run:
                assert res == 2 * job
                got.append(job)
                if len(got) == n // 2:
                    end = time.monotonic() + 10
                    while len(sched.tasks) > n - len(got) and time.monotonic() < end:
                        time.sleep(0.02)
                    assert len(sched.tasks) <= n - len(got), len(sched.tasks)     # the collected ones are gone
                    collected_before_loss = list(got)
                    cluster.sync(list(cluster.workers.values())[0].close)       # a worker lost
        finally:
            run.close()
    assert sorted(got) == list(range(n))
    assert all(CALLS.count(j) == 1 for j in collected_before_loss), sorted(CALLS)


def test_a_bad_scheduler_address_is_one_line(capsys, lot, tmp_path, monkeypatch):
    """--scheduler garbage, and an address where no scheduler answers: one line, exit 2."""
    from host_tools import cli
    from host_tools.lot import parallel

    args = ["lot", str(lot / "manifest.csv"), "-o", str(tmp_path / "o"), "--no-progress", "--scheduler"]
    assert cli.main(args + ["garbage"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error: --scheduler 'garbage': not a Dask scheduler address" in err, err
    monkeypatch.setattr(parallel, "CONNECT_TIMEOUT_S", 1.0)
    assert cli.main(args + ["tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error: --scheduler tcp://127.0.0.1:1: cannot reach the Dask scheduler" in err, err


# -- the manifest's rows that fail alone --------------------------------------------------------------

def test_conflicting_rows_fail_alone_naming_the_other(lot, tmp_path):
    """A repeated id (also in another case), a run shared with another device (the same path, or a
    copy), a held-out run that is the training run (path or bytes): that row fails with a reason
    naming the other; the rest of the lot is calibrated."""
    f = lambda i, role="train": f"{lot}/foreign-{i}/{role}.csv"     # noqa: E731
    shutil.copyfile(f(3), tmp_path / "copy3.csv")
    shutil.copyfile(f(4), tmp_path / "copy4.csv")
    rows = [f"A0,{f(0)},{f(0, 'holdout')}",                 # line 2
            f"A0,{f(1)},",                                  # line 3: the id again
            f"a0,{f(2)},",                                  # line 4: in another case
            f"B3,{f(3)},",                                  # line 5
            f"C3,{tmp_path / 'copy3.csv'},",                # line 6: B3's run, copied
            f"D5,{f(5)},{f(5)}",                            # line 7: holds out its training run
            f"E4,{f(4)},{tmp_path / 'copy4.csv'}",          # line 8: ... as a copy
            f"F6,{f(6)},{f(0, 'holdout')}"]                 # line 9: A0's held-out run
    m = tmp_path / "m.csv"
    m.write_text("device,train,holdout\n" + "\n".join(rows) + "\n")
    devices = read_manifest(m)
    why = {f"{devices[i].id}@{devices[i].where.rsplit(':', 1)[1]}": v for i, v in
           manifest_conflicts(devices, run_digests(devices)).items()}
    assert sorted(why) == ["A0@3", "C3@6", "D5@7", "E4@8", "F6@9", "a0@4"]
    assert why["A0@3"][0] == "repeat" and f"{m}:2" in why["A0@3"][1] and f"{m}:3" in why["A0@3"][1]
    assert "differ only in case" in why["a0@4"][1] and f"{m}:2" in why["a0@4"][1]
    assert why["C3@6"] == ("runs", f"training run {tmp_path / 'copy3.csv'} is the same bytes as the training run "
                                   f"{f(3)} of device 'B3' ({m}:5): a run belongs to one device")
    assert "is the training run" in why["D5@7"][1] and "the same file" in why["D5@7"][1]
    assert "is the training run" in why["E4@8"][1] and "the same bytes" in why["E4@8"][1]
    assert "held-out run" in why["F6@9"][1] and "'A0'" in why["F6@9"][1]

    out = tmp_path / "out"
    (out / "devices" / "C3").mkdir(parents=True)        # tables of an earlier run must not stay shippable
    (out / "devices" / "C3" / "table.h").write_text("old")
    res = run_lot(m, out, spec=lot / "spec.json", workers=1, progress=False)
    assert res["computed"] == ["A0", "B3"] and len(res["refused"]) == 6
    rows = [r.split(",") for r in (out / "lot.csv").read_text().splitlines()[1:]]
    assert sorted((r[0], r[1], r[2]) for r in rows) == [
        ("A0", "fail", "manifest"), ("A0", "pass", "done"), ("B3", "pass", "done"), ("C3", "fail", "manifest"),
        ("D5", "fail", "manifest"), ("E4", "fail", "manifest"), ("F6", "fail", "manifest"), ("a0", "fail", "manifest")]
    a0 = json.loads((out / "devices" / "A0" / "result.json").read_text())
    assert a0["train"] == [f(0)]        # the first row's device
    assert sorted(p.name for p in (out / "devices" / "C3").iterdir()) == ["result.json"]
    assert not (out / "devices" / "a0").exists() or os.path.samefile(out / "devices" / "a0", out / "devices" / "A0")


# -- a changed spec: judged again, no refit ---------------------------------------------------------------

def test_a_spec_that_changes_only_limits_rejudges_without_refitting(lot, reference, tmp_path, monkeypatch):
    """Tighten a limit: every fitted device fails, its tables go to withheld/ (not shippable), and
    the files are those of a fresh run under that spec; loosen it again: they are released.  No
    device is calibrated again."""
    from host_tools.lot import engine

    out = tmp_path / "out"
    shutil.copytree(reference[0], out)
    tight = tmp_path / "tight.json"
    tight.write_text(json.dumps({**SPEC, "residual_rms_max_dph": 1e-9}))
    fresh = tmp_path / "fresh"
    run_lot(lot / "manifest.csv", fresh, spec=tight, workers=1, progress=False)

    calls = []
    real = engine.calibrate
    monkeypatch.setattr(engine, "calibrate", lambda job: calls.append(job["device"].id) or real(job))
    res = run_lot(lot / "manifest.csv", out, spec=tight, workers=1, progress=False)
    assert calls == [] and res["computed"] == [] and res["passed"] == 0
    passed_before = sorted(r.split(",")[0] for r in (reference[0] / "lot.csv").read_text().splitlines()[1:]
                           if r.split(",")[1] == "pass")
    assert passed_before and set(passed_before) <= set(res["rejudged"])
    for dev in passed_before:
        folder = out / "devices" / dev
        assert not (folder / "table.h").exists() and (folder / "withheld" / "table.h").exists()
        result = json.loads((folder / "result.json").read_text())
        assert result["status"] == "fail" and any("residual_rms_max_dph" in r for r in result["reasons"])
    assert _device_files(out) == _device_files(fresh)
    for name in ("lot.csv", "lot.json", "lot.md"):
        assert (out / name).read_bytes() == (fresh / name).read_bytes()

    res = run_lot(lot / "manifest.csv", out, spec=lot / "spec.json", workers=1, progress=False)
    assert calls == [] and res["computed"] == []
    assert _device_files(out) == _device_files(reference[0])
    res = run_lot(lot / "manifest.csv", out, spec=lot / "spec.json", workers=1, progress=False)
    assert res["rejudged"] == [] and len(res["reused"]) == N


# -- temporary files, special files, malformed inputs --------------------------------------------------------

def test_temporary_files_of_a_killed_run_are_removed(lot, reference, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(reference[0], out)
    dev = out / "devices" / "foreign-0"
    ours = [out / ".lot.csv.k2j4_x9a.tmp.csv", dev / ".table.h.abcdefgh.tmp.h", dev / ".done.json.0a1b2c3d.tmp.json",
            dev / ".model.json.zzzzzzzz.tmp.json"]
    theirs = [out / "notes.tmp", dev / ".table.h.abc.tmp.h", dev / ".x.abcdefgh.tmp.csv", lot.parent / ".y.abcdefgh.tmp"]
    for p in ours + theirs:
        p.write_text("partial")
    res = run_lot(lot / "manifest.csv", out, spec=lot / "spec.json", workers=1, progress=False)
    assert sorted(res["removed_tmp"]) == sorted(map(str, ours))
    assert not any(p.exists() for p in ours) and all(p.exists() for p in theirs)
    assert len(res["reused"]) == N


def test_special_files_as_runs_fail_the_device_without_blocking(lot, tmp_path):
    """train=/dev/zero and a FIFO as a run: those devices fail at read, naming the file; the lot
    does not block (a subprocess with a time limit)."""
    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    m = tmp_path / "m.csv"
    m.write_text(f"device,train\nZ,/dev/zero\nF,{fifo}\nG,{lot}/foreign-0/train.csv\n")
    code = (f"import json; from host_tools.lot import run_lot; r = run_lot({str(m)!r}, {str(tmp_path / 'out')!r}, "
            f"spec={str(lot / 'spec.json')!r}, workers=1, progress=False); print(json.dumps(r['computed']))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60, env=ENV)
    assert done.returncode == 0, done.stderr.decode()
    results = {r["device"]: r for r in json.loads((tmp_path / "out" / "lot.json").read_text())["devices"]}
    assert results["G"]["status"] == "pass"
    assert results["Z"]["stage"] == "read" and "/dev/zero" in results["Z"]["reasons"][0] \
        and "not a regular file" in results["Z"]["reasons"][0]
    assert results["F"]["stage"] == "read" and "FIFO" in results["F"]["reasons"][0]


def _deep(n: int) -> str:
    return '{"coverage_min": ' + "[" * n + "]" * n + "}"


@pytest.mark.parametrize("what, content, needle", [
    ("spec", '{"coverage_min": 0.5, "coverage_min": 0.9}', "duplicated key 'coverage_min'"),
    ("spec", '{"dwell_s": ' + "9" * 5000 + "}", "not a usable spec"),
    ("spec", '{"dwell_s": ' + "9" * 4000 + "}", "field 'dwell_s': must be a finite number"),
    ("spec", _deep(100_000), "nested too deep"),
    ("spec", b'{"dwell_s": 1.0, "x": "\xff"}', "not a text file (UTF-8 decoding failed at byte 23)"),
    ("spec", "FIFO", "is a FIFO, not a regular file"),
    ("manifest", b"device,train\nA1,caf\xe9.csv\n", ":2: the manifest is not UTF-8 text (byte 0xe9"),
    ("manifest", "FIFO", "is a FIFO, not a regular file"),
], ids=["spec-duplicated-key", "spec-5000-digits", "spec-4000-digits", "spec-100000-deep", "spec-not-utf8",
        "spec-fifo", "manifest-not-utf8", "manifest-fifo"])
def test_hostile_specs_and_manifests_are_one_line_errors(lot, tmp_path, capsys, what, content, needle):
    from host_tools import cli

    path = tmp_path / f"{what}.x"
    if content == "FIFO":
        os.mkfifo(path)
    else:
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    manifest = path if what == "manifest" else lot / "manifest.csv"
    spec = path if what == "spec" else lot / "spec.json"
    t0 = time.monotonic()
    rc = cli.main(["lot", str(manifest), "-o", str(tmp_path / "out"), "--spec", str(spec), "--workers", "1",
                   "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and err.startswith(f"hdrg lot: error: {path}"), err
    assert needle in err and "Traceback" not in err, err
    assert len(err) < 400 and time.monotonic() - t0 < 10


def test_a_manifest_with_a_bom_is_read(lot, tmp_path):
    m = tmp_path / "m.csv"
    m.write_bytes(b"\xef\xbb\xbf" + f"device,train\nA1,{lot}/foreign-0/train.csv\n".encode())
    (dev,) = read_manifest(m)
    assert dev.id == "A1" and dev.where == f"{m}:2"


def test_an_output_folder_inside_a_directory_lot_is_not_a_device(lot, tmp_path):
    """`hdrg lot DIR -o DIR/out` (the directory convention): the output folder is no device, on
    the first run or on resume; nor is another lot's output folder in DIR."""
    d = tmp_path / "lot"
    for i in (0, 1):
        (d / f"dev{i}").mkdir(parents=True)
        shutil.copyfile(lot / f"foreign-{i}" / "train.csv", d / f"dev{i}" / "train.csv")
    first = run_lot(d, d / "out", spec=lot / "spec.json", workers=1, progress=False)
    assert first["computed"] == ["dev0", "dev1"]
    again = run_lot(d, d / "out", spec=lot / "spec.json", workers=1, progress=False)
    assert again["reused"] == ["dev0", "dev1"] and again["computed"] == []
    other = run_lot(d, d / "out2", spec=lot / "spec.json", workers=1, progress=False)     # d/out is in d
    assert other["computed"] == ["dev0", "dev1"] and other["devices"] == 2


def test_a_failed_device_leaves_a_small_folder(tmp_path):
    """A device that fails before its fit: result.json and done.json only (no model, no
    withheld/), at most 3 file-system blocks with the folder (measured: st_blocks)."""
    runs = tmp_path / "runs"
    runs.mkdir()
    rows = []
    for i in range(20):
        (runs / f"r{i}.csv").write_text(f"t_s,rate_dph\n0,{i}\n")
        rows.append(f"D{i:03d},{runs / f'r{i}.csv'}")
    (tmp_path / "m.csv").write_text("device,train\n" + "\n".join(rows) + "\n")
    res = run_lot(tmp_path / "m.csv", tmp_path / "out", workers=1, progress=False)
    assert res["failed"] == 20
    sizes = []
    for folder in sorted((tmp_path / "out" / "devices").iterdir()):
        assert sorted(p.name for p in folder.iterdir()) == [MARKER, "result.json"]
        sizes.append(sum(p.stat().st_blocks * 512 for p in [folder, *folder.iterdir()]))
        assert (folder / "result.json").stat().st_size < 4096
    block = os.statvfs(tmp_path).f_bsize
    print(f"a failed device's folder: {max(sizes)} bytes on disk (block {block} bytes)")
    assert max(sizes) <= 3 * max(block, 4096)


def test_the_help_lists_columns_spec_keys_and_outputs(capsys):
    from host_tools import cli
    from host_tools.lot.device import OUTPUTS
    from host_tools.lot.inputs import COLUMNS, DEFAULT_SPEC, SPEC_DOC
    from host_tools.lot.report import FILES

    with pytest.raises(SystemExit):
        cli.main(["lot", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for col in COLUMNS:
        assert f" {col} " in text
    assert set(SPEC_DOC) == set(DEFAULT_SPEC)
    for key, val in DEFAULT_SPEC.items():
        assert f" {key} {json.dumps(val)} [{SPEC_DOC[key][0]}]" in text, key
    for name in list(OUTPUTS) + list(FILES):
        assert name in text
    assert "withheld/" in text
