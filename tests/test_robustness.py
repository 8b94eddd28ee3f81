"""No silent wrong answers: one regression test per probe of a careless or hostile input.

Every case must give a clear error (``hdrg CMD: error: ...``, exit code 2, no traceback), a
warning with the count, or a correct result.  The CLI runs in-process (host_tools.cli.main) on
small simulated runs, except where a real process is needed (SIGPIPE).
"""
import os
import signal
import threading
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from firmware_ref import formats as F
from host_tools import cli
from host_tools.golden import flags as hflags, runlog
from host_tools.simulation import sim
from host_tools.golden.runlog import RunLogError, RunLogWarning

ROOT = Path(__file__).resolve().parents[1]


def hdrg(capsys, *argv):
    """Run `hdrg argv...` in-process: (exit code, stdout, stderr)."""
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return rc, out, err


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A narrow FTR run (-4..5 degC), a wide one (slow ramp from -40 degC), a model fitted on the
    narrow run, and a mode-reversal run."""
    d = tmp_path_factory.mktemp("robust")
    prof = d / "prof.csv"
    prof.write_text("t_s,temp_c\n0,-4\n1500,5\n3000,-4\n")
    paths = {"dir": d}
    assert cli.main(["simulate", "--scenario", "paper-ftr-cycle-4dpm", "--profile", str(prof), "--seed", "1",
                     "--duration", "3000", "-o", str(d / "narrow.csv")]) == 0
    runlog.write(sim.simulate("paper-slow-ramp", seed=2, duration_s=6000), d / "wide.csv")
    runlog.write(sim.simulate("paper-mr-cycle-4dpm", seed=3, duration_s=4000), d / "mr.csv")
    assert cli.main(["fit", str(d / "narrow.csv"), "-o", str(d / "model.json")]) == 0
    for name in ("narrow", "wide", "mr", "model"):
        paths[name] = d / (name + (".json" if name == "model" else ".csv"))
    return paths


# -- 1. extrapolation is reported -------------------------------------------------------------------------

@pytest.mark.parametrize("impl", ["float", "fixed"])
def test_extrapolation_flags_counts_warning_and_strict(runs, capsys, tmp_path, impl):
    out = tmp_path / "c.csv"
    rc, stdout, err = hdrg(capsys, "compensate", runs["wide"], "--model", runs["model"], "-o", out, "--impl", impl)
    assert rc == 0
    log = runlog.read(out)
    fl = log["flags"]
    assert fl.dtype == np.int64 and len(fl) == len(log)
    n_proxy = int(np.count_nonzero(fl & F.FLAG_PROXY_CLAMPED))
    assert n_proxy > 0.5 * len(log)                     # the wide run is mostly outside -4..5 degC
    assert f"proxy_clamped {n_proxy}" in stdout          # console summary
    assert f"proxy_clamped {n_proxy}" in log.metadata["compensation_flags"]
    assert "warning" in err and "extrapolation" in err and f"{n_proxy} of {len(log)}" in err
    if impl == "float":  # the flag bits are the golden proxy clamping
        from host_tools.golden.model import BiasModel
        m = BiasModel.from_json(runs["model"])
        _, u_clamped = m.config.proxy.normalize(runlog.read(runs["wide"])["freq_hz"])
        assert np.array_equal((fl & F.FLAG_PROXY_CLAMPED) != 0, u_clamped)
    # --strict: an error, nothing written
    out2 = tmp_path / "strict.csv"
    rc, _, err = hdrg(capsys, "compensate", runs["wide"], "--model", runs["model"], "-o", out2, "--impl", impl,
                      "--strict")
    assert rc == 2 and "error" in err and "extrapolation" in err and not out2.exists()


def test_inside_the_range_no_warning(runs, capsys, tmp_path):
    rc, stdout, err = hdrg(capsys, "compensate", runs["narrow"], "--model", runs["model"], "-o", tmp_path / "c.csv",
                           "--strict")
    # the one warning: the model (one training run) did not calibrate the start-up, and this log starts at power-on
    assert rc == 0 and [x for x in err.splitlines() if "warning" in x and "start-up" not in x] == [] and "flags:" in stdout


def test_startup_model_on_a_cycle_warns(tmp_path, capsys):
    """A model from a 25 degC start-up run applied to a -20..20 degC cycle: flagged, not silent."""
    runlog.write(sim.simulate("startup-ftr", seed=4, duration_s=1500), tmp_path / "s.csv")
    runlog.write(sim.simulate("paper-ftr-cycle-4dpm", seed=5, duration_s=3000), tmp_path / "cyc.csv")
    assert hdrg(capsys, "fit", tmp_path / "s.csv", "-o", tmp_path / "m.json", "--terms", "k0,k1")[0] == 0
    rc, _, err = hdrg(capsys, "compensate", tmp_path / "cyc.csv", "--model", tmp_path / "m.json",
                      "-o", tmp_path / "c.csv")
    assert rc == 0 and "extrapolation" in err and "proxy_clamped" in err


# -- 2. fixed-point saturation is not valid -----------------------------------------------------------------

def test_saturated_samples_are_not_valid(runs, capsys, tmp_path):
    log = runlog.read(runs["narrow"]).select(slice(0, 1000))
    rate = log.rate_dph.copy()
    rows = np.arange(500, 511)
    rate[rows] = 5e6                                      # beyond the +-2^21 deg/h input word
    bad = tmp_path / "sat.csv"
    runlog.write(log.with_columns(rate_dph=rate), bad)
    out = tmp_path / "c.csv"
    rc, stdout, err = hdrg(capsys, "compensate", bad, "--model", runs["model"], "-o", out, "--impl", "fixed")
    assert rc == 0
    c = runlog.read(out)
    assert np.all(c["flags"][rows] & F.FLAG_INPUT_SAT)
    assert np.all(c["valid"][rows] == 0)
    # no number: the saturated value (2,097,145 deg/h) never appears in the output
    assert np.all(np.abs(c.rate_dph[c["valid"] == 1]) < 1e4)
    assert np.isnan(c.rate_dph[rows]).all() and np.isnan(c["bias_dph"][rows]).all()
    assert "input_saturated 11" in stdout and "saturation: 11 of 1000" in err
    nvalid = int(np.count_nonzero(c["valid"]))
    assert f"{nvalid} valid" in stdout and nvalid <= 1000 - 11
    assert hdrg(capsys, "compensate", bad, "--model", runs["model"], "-o", tmp_path / "s.csv", "--impl", "fixed",
                "--strict")[0] == 2


def test_add_flags_holds_and_counts():
    log = runlog.RunLog.from_arrays(t_s=np.arange(6.0), rate_dph=[1.0, 2, 3, 4, 5, 6], temp_c=np.zeros(6),
                                    bias_dph=np.zeros(6), valid=np.ones(6))
    out = hflags.add_flags(log, [0, 1, F.FLAG_SAT, F.FLAG_INPUT_SAT, 0, F.FLAG_RATE_CLAMPED])
    assert out["valid"].tolist() == [1, 1, 0, 0, 1, 1]
    assert out.rate_dph.tolist() == [1, 2, 2, 2, 5, 6]
    assert out.metadata["compensation_flags"] == "proxy_clamped 1, rate_clamped 1, input_saturated 1, saturated 1"
    assert any("saturation: 2 of 6" in m for m in hflags.problems(out))
    assert any("extrapolation: 1 of 6" in m and "proxy_clamped" in m for m in hflags.problems(out))


# -- 3. -o equal to an input ------------------------------------------------------------------------------

def test_output_equal_to_input_is_refused(runs, capsys, tmp_path):
    src = tmp_path / "a.csv"
    src.write_bytes(runs["narrow"].read_bytes())
    model = tmp_path / "m.json"
    model.write_bytes(runs["model"].read_bytes())
    link = tmp_path / "link.csv"
    link.symlink_to(src)
    before = src.read_bytes(), model.read_bytes()
    for argv in (["compensate", src, "--model", model, "-o", src],
                 ["compensate", src, "--model", model, "-o", link],
                 ["compensate", src, "--model", model, "-o", model],
                 ["fit", src, "-o", src],
                 ["quantize", model, "-o", model],
                 ["metrics", src, "--json", link]):
        rc, _, err = hdrg(capsys, *argv)
        assert rc == 2 and "refusing to overwrite an input" in err, argv
    assert (src.read_bytes(), model.read_bytes()) == before


# -- 4. interrupted writes ----------------------------------------------------------------------------------

def test_interrupted_write_leaves_no_partial_file(runs, tmp_path, monkeypatch):
    log = runlog.read(runs["narrow"])
    dest = tmp_path / "out.csv"
    dest.write_text("old content\n")
    calls = {"n": 0}
    real = runlog._fmt_column

    def interrupt(name, arr):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(name, arr)

    monkeypatch.setattr(runlog, "_fmt_column", interrupt)
    with pytest.raises(KeyboardInterrupt):
        runlog.write(log, dest)
    assert dest.read_text() == "old content\n"               # untouched
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]  # no temporary file left
    monkeypatch.setattr(runlog, "_fmt_column", real)
    runlog.write(log, tmp_path / "new.npz")
    assert len(runlog.read(tmp_path / "new.npz")) == len(log)


def test_sigterm_during_compensate_leaves_no_output(runs, tmp_path):
    """A real process killed mid-command: the output is absent, never a truncated run log."""
    out = tmp_path / "c.csv"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "host_tools.cli", "compensate", str(runs["wide"]), "--model",
                          str(runs["model"]), "-o", str(out)], env=env, stderr=subprocess.PIPE)
    import time
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not any(tmp_path.iterdir()) and p.poll() is None:
        time.sleep(0.005)
    p.terminate()
    rc = p.wait(60)
    # finished; "terminated" (128 + SIGTERM, caught inside the command); or killed by the default
    # handler (-SIGTERM) after the command had restored it, i.e. after the output was complete
    assert rc in (0, 128 + signal.SIGTERM, -signal.SIGTERM)
    if rc == 128 + signal.SIGTERM:
        err = p.stderr.read().decode()
        assert "terminated" in err
        if out.exists():        # the stop came after the rename: complete, and the message says so
            assert f"written complete before the stop: {out}" in err and len(runlog.read(out)) == 6000
        else:
            assert "(no output written)" in err
    else:
        assert len(runlog.read(out)) == 6000                    # complete, never truncated
    assert [f.name for f in tmp_path.iterdir() if f.name != "c.csv"] == []   # no temporary file left


def test_a_stop_names_the_outputs_already_complete(tmp_path, monkeypatch, capsys):
    """SIGTERM / Ctrl-C inside a command: the message says which outputs were renamed into place
    (complete) before the stop, or that none was; the one being written is absent."""
    import types

    from host_tools import atomic
    monkeypatch.setattr(atomic, "COMPLETED", [])
    done, half = tmp_path / "done.csv", tmp_path / "half.csv"

    def run(args):
        with atomic.atomic_open(done, "w") as fh:
            fh.write("complete\n")
        with atomic.atomic_open(half, "w") as fh:
            fh.write("part")
            raise args.stop()

    for stop, rc, word in ((cli._Terminated, 128 + signal.SIGTERM, "terminated"), (KeyboardInterrupt, 130, "interrupted")):
        atomic.COMPLETED.clear()
        assert cli._run(types.SimpleNamespace(command="x", debug=False, stop=stop), types.SimpleNamespace(run=run)) == rc
        err = capsys.readouterr().err
        assert f"hdrg x: {word}; written complete before the stop: {done}" in err
        assert done.read_text() == "complete\n" and not half.exists()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["done.csv"]          # no temporary file
    atomic.COMPLETED.append(str(tmp_path / "earlier.csv"))     # written by an earlier command in this process
    none = types.SimpleNamespace(run=lambda args: (_ for _ in ()).throw(cli._Terminated()))
    assert cli._run(types.SimpleNamespace(command="x", debug=False), none) == 128 + signal.SIGTERM
    assert "hdrg x: terminated (no output written)" in capsys.readouterr().err


def test_unfinished_capture_is_marked_and_warned(tmp_path):
    from host_tools.link.capture import RunLogWriter

    path = tmp_path / "cap.csv"
    w = RunLogWriter(path, {"sample_rate_hz": "1"}, columns=("t_s", "rate_dph", "temp_c"), flush_every=2)
    for i in range(5):
        w.append(f"{i}.0,1.5,20.0\n")
    w.flush()
    with pytest.warns(RunLogWarning, match="unfinished capture"):
        log = runlog.read(path)
    assert len(log) == 5 and log.metadata["capture"] == "in progress"
    w.close()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        log = runlog.read(path)
    assert len(log) == 5 and log.metadata["capture"] == "complete"
    assert path.read_text().splitlines()[0].rstrip() == "# capture: complete"


# -- 5. OS errors: one line, exit code 2, no traceback ---------------------------------------------------

def test_os_errors_are_one_line(runs, capsys, tmp_path, monkeypatch):
    d = tmp_path / "adir"
    d.mkdir()
    afile = tmp_path / "afile"
    afile.write_text("x")
    cases = [["fit", d, "-o", tmp_path / "m.json"],
             ["compensate", d, "--model", runs["model"], "-o", tmp_path / "c.csv"],
             ["compensate", runs["narrow"], "--model", runs["model"], "-o", d],
             ["fit", runs["narrow"], "-o", d],
             ["report", runs["narrow"], "--model", runs["model"], "--out", afile, "--no-plots"],
             ["metrics", tmp_path / "missing.csv"],
             ["compensate", runs["narrow"], "--model", runs["model"], "-o", tmp_path / "no" / "c.csv"]]
    for argv in cases:
        rc, _, err = hdrg(capsys, *argv)
        assert rc == 2 and err.startswith(f"hdrg {argv[0]}: error: ") and err.count("\n") == 1, (argv, err)

    def denied(path):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(runlog, "read_csv", denied)
    rc, _, err = hdrg(capsys, "fit", runs["narrow"], "-o", tmp_path / "m.json")
    assert rc == 2 and err == f"hdrg fit: error: {runs['narrow']}: Permission denied\n"
    with pytest.raises(PermissionError):                  # --debug: the traceback
        cli.main(["--debug", "fit", str(runs["narrow"]), "-o", str(tmp_path / "m.json")])
    with pytest.raises(PermissionError):
        cli.main(["fit", str(runs["narrow"]), "-o", str(tmp_path / "m.json"), "--debug"])


def test_broken_pipe_is_quiet(runs):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "host_tools.cli", "metrics", str(runs["narrow"]), "--json"],
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                                      # `| head -0`
    err = p.stderr.read().decode()
    assert p.wait(120) == 141 and err == ""


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.startswith("hdrg ")


# -- 6. reinterpretations ----------------------------------------------------------------------------------

def _edit(src, dst, fn):
    dst.write_text(fn(Path(src).read_text()))
    return dst


def test_renamed_freq_column(runs, capsys, tmp_path):
    nf = _edit(runs["narrow"], tmp_path / "nf.csv", lambda s: s.replace("freq_hz", "freq_x", 1))
    rc, _, err = hdrg(capsys, "fit", nf, "-o", tmp_path / "m.json")
    assert rc == 0 and "warning" in err and "no 'freq_hz' column" in err and "temp_c" in err
    rc, _, err = hdrg(capsys, "fit", nf, runs["narrow"], "-o", tmp_path / "m2.json")
    assert rc == 2 and "no 'freq_hz' column" in err
    # a freq model on a log without freq_hz: an error, never temp_c
    rc, _, err = hdrg(capsys, "compensate", nf, "--model", runs["model"], "-o", tmp_path / "c.csv")
    assert rc == 2 and "freq_hz" in err


def test_renamed_mode_column_with_reversal_on(runs, tmp_path):
    bad = _edit(runs["mr"], tmp_path / "nm.csv", lambda s: s.replace(",mode,", ",mode_x,", 1))
    with pytest.raises(RunLogError, match="reversal: on.*no 'mode' column"):
        runlog.read(bad)


def test_sample_rate_metadata_against_t_s(runs, tmp_path):
    bad = _edit(runs["narrow"], tmp_path / "fs.csv", lambda s: s.replace("# sample_rate_hz: 1\n",
                                                                         "# sample_rate_hz: 10\n", 1))
    with pytest.raises(RunLogError, match="sample_rate_hz: 10.*1 Hz"):
        runlog.read(bad)


def test_compensated_log_fed_to_fit(runs, capsys, tmp_path):
    c = tmp_path / "c.csv"
    assert hdrg(capsys, "compensate", runs["narrow"], "--model", runs["model"], "-o", c)[0] == 0
    rc, _, err = hdrg(capsys, "fit", c, "-o", tmp_path / "m.json")
    assert rc == 2 and "compensated log" in err


def test_negative_frequency(runs, tmp_path):
    log = runlog.read(runs["narrow"])
    lines = Path(runs["narrow"]).read_text().splitlines(keepends=True)
    header = next(i for i, l in enumerate(lines) if not l.startswith("#"))
    k = lines[header].strip().split(",").index("freq_hz")
    cells = lines[header + 5].rstrip("\n").split(",")
    cells[k] = "-" + cells[k]
    lines[header + 5] = ",".join(cells) + "\n"
    bad = tmp_path / "neg.csv"
    bad.write_text("".join(lines))
    with pytest.raises(RunLogError, match=rf"neg.csv:{header + 6}: freq_hz .* must be > 0"):
        runlog.read(bad)
    assert len(log) == 3000


# -- 7. tiny data -----------------------------------------------------------------------------------------

def test_tiny_data(runs, capsys, tmp_path):
    tiny = tmp_path / "tiny.csv"
    tiny.write_text("".join(Path(runs["narrow"]).read_text().splitlines(keepends=True)[:21]))
    m = tmp_path / "m.json"
    for extra in (["--drop-unidentifiable"], ["--terms", "auto"]):
        rc, _, err = hdrg(capsys, "fit", tiny, "-o", m, *extra)
        assert rc == 2 and "valid samples for" in err and not m.exists(), (extra, err)
    rc, _, err = hdrg(capsys, "fit", tiny, "-o", m, "--terms", "all")  # the default is auto
    assert rc == 2 and "--drop-unidentifiable" in err and "drop_unidentifiable=True" not in err
    # forced with enough degrees of freedom: error bars are numbers, never nan
    rc, out, _ = hdrg(capsys, "fit", tiny, "-o", m, "--terms", "k0,k1", "--force")
    assert rc == 0 and "nan" not in out and "nan" not in m.read_text().lower()


# -- 8. device ----------------------------------------------------------------------------------------------

def test_capture_into_missing_directory(capsys, tmp_path):
    rc, _, err = hdrg(capsys, "capture", "--port", "loop://", "-o", tmp_path / "missing" / "c.csv", "--quiet")
    assert rc == 2 and "does not exist" in err and "port error" not in err


def test_table_mode_problem():
    from host_tools.link.device import identity_table
    from host_tools.link.codec import table_mode_problem

    ftr = identity_table(sim.simulate("static", seed=0, duration_s=600))
    mr = identity_table(sim.simulate("paper-mr-cycle-4dpm", seed=0, duration_s=1200))
    assert table_mode_problem(ftr, reversal=True) and "force-to-rebalance" in table_mode_problem(ftr, True)
    assert table_mode_problem(mr, reversal=False) and "mode reversal" in table_mode_problem(mr, False)
    assert table_mode_problem(ftr, False) is None and table_mode_problem(mr, True) is None


# -- 9. small but visible -----------------------------------------------------------------------------------

@pytest.mark.parametrize("cmd", ["fit", "capture", "upload", "demo", "compensate"])
def test_help_is_the_commands_own(cmd, capsys):
    with pytest.raises(SystemExit):
        cli.main([cmd, "--help"])
    out = " ".join(capsys.readouterr().out.split())
    helptext = cli.COMMANDS[cmd][1]
    assert helptext[1:] in out
    assert "Numeric core" not in out and "The serial link to" not in out


def test_demo_help_states_its_duration(capsys):
    with pytest.raises(SystemExit):
        cli.main(["demo", "--help"])
    out = capsys.readouterr().out
    out = " ".join(out.split())
    assert "a few seconds" not in out and "about 0.5 to 1.5 min" in out


def test_readme_cites_the_projects_format_document():
    readme = (ROOT / "README.md").read_text()
    assert "docs/RUN_LOG.md" in readme and (ROOT / "docs" / "RUN_LOG.md").exists()
    assert "shared/formats/run-log.md" not in readme
    assert "19,386" not in readme
    doc = (ROOT / "docs" / "RUN_LOG.md").read_text()
    for bit, (name, _) in F.FLAGS.items():
        assert f"| {bit} | `{name}` |" in doc
    assert "capture: in progress" in doc


def test_report_allan_reaches_long_taus_on_mode_reversal(runs, tmp_path):
    """The report's Allan figure of a mode-reversal run reaches 100 s: beyond the longest gap-free
    stretch (one dwell) the exchanges are bridged, and the curve says which taus are bridged."""
    from host_tools.fitting import report
    from host_tools.golden.compensate import fit_config_from_logs
    from host_tools.fitting.fit import fit_logs

    log = runlog.read(runs["mr"])
    model, _ = fit_logs([log], fit_config_from_logs([log], reversal={"combiner": "trend"}), "k0,k1")
    doc = report.report([log], model, tmp_path / "rep")
    curves = doc["allan"][os.path.basename(log.source)]
    for curve in curves.values():
        taus = curve["gapfree"]["tau_s"] + (curve["bridged"] or {"tau_s": []})["tau_s"]
        assert max(taus) >= 100.0
        assert max(curve["gapfree"]["tau_s"]) <= curve["longest_stretch_s"] / 2
    assert (tmp_path / "rep" / "allan.png").stat().st_size > 0


def test_atomic_writes_keep_symlinks_and_special_files(tmp_path):
    from host_tools.atomic import atomic_open

    target = tmp_path / "real.txt"
    target.write_text("old")
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    with atomic_open(link, "w") as fh:
        fh.write("new")
    assert link.is_symlink() and target.read_text() == "new"
    with atomic_open(os.devnull, "w") as fh:        # a character device: written in place, not replaced
        fh.write("x")
    assert not Path(os.devnull).is_file()
    with pytest.raises(IsADirectoryError):
        with atomic_open(tmp_path, "w"):
            pass


def _stop_inside_the_rename(tmp_path, monkeypatch, deliver):
    """atomic_open under a SIGTERM handler that raises cli._Terminated, with ``deliver()`` called
    between the rename and its record; returns (what COMPLETED held right after ``deliver``, out
    path) once the stop has surfaced as cli._Terminated; asserts the command's handler is back."""
    from host_tools import atomic
    monkeypatch.setattr(atomic, "COMPLETED", [])
    out = tmp_path / "o.txt"
    real_replace = os.replace
    seen = []

    def replace_then_deliver(src, dst):
        real_replace(src, dst)
        deliver()
        seen.append(list(atomic.COMPLETED))

    def handler(signum, frame):
        raise cli._Terminated()

    old = signal.signal(signal.SIGTERM, handler)
    try:
        monkeypatch.setattr(atomic.os, "replace", replace_then_deliver)
        with pytest.raises(cli._Terminated):
            with atomic.atomic_open(out, "w") as fh:
                fh.write("x\n")
        assert signal.getsignal(signal.SIGTERM) is handler        # the command's handler is back
    finally:
        signal.signal(signal.SIGTERM, old)
    return seen, out


def test_a_stop_during_the_rename_is_held_until_it_is_recorded(tmp_path, monkeypatch):
    """A SIGTERM that arrives while the destination is renamed into place is delivered only after
    the rename is recorded in atomic.COMPLETED (the window CI hit: the file complete, the message
    "(no output written)").  Directed at this thread, so that no other thread of the test process
    takes it (that case: the next test)."""
    from host_tools import atomic
    seen, out = _stop_inside_the_rename(
        tmp_path, monkeypatch, lambda: signal.pthread_kill(threading.get_ident(), signal.SIGTERM))
    assert seen == [[]]                                   # the signal was pending during the rename ...
    assert atomic.COMPLETED == [os.path.realpath(out)] and out.read_text() == "x\n"    # ... and came after the record


def test_a_stop_taken_by_another_thread_is_held_too(tmp_path, monkeypatch):
    """A SIGTERM sent to the process may be taken by another thread (numba's, a serial device's):
    its C-level handler makes the MAIN thread run the Python handler at its next instruction,
    whatever the main thread's mask.  Simulated by calling the installed handler inside the window:
    it must only record the stop, which is raised after the rename is recorded."""
    from host_tools import atomic
    seen, out = _stop_inside_the_rename(
        tmp_path, monkeypatch, lambda: signal.getsignal(signal.SIGTERM)(signal.SIGTERM, None))
    assert seen == [[]]
    assert atomic.COMPLETED == [os.path.realpath(out)] and out.read_text() == "x\n"
