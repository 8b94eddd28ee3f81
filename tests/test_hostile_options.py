"""Hostile model files, options and environments: absurd coefficients and non-finite or oversized
numbers in a model, NaN/inf/negative or zero-sample options of quantize and diagnose, float
originals that do not belong to an exported table, empty check-impl lists, an unsplittable --cmd,
a check-impl program whose child keeps stdout open, a closed stdout and NUMBA_NUM_THREADS=0.

Each case is a one-line error naming the cause, a warning, or the right result; never a traceback,
a silent wrong result or a hang.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest

from host_tools import cli
from host_tools.golden.model import COEF_LIMIT_DPH, BiasModel, ModelError
from host_tools.vectors.builders import make_model

ROOT = Path(__file__).resolve().parent.parent
VECTORS = ROOT / "vectors"


def hdrg(*argv) -> int:
    return cli.main([str(a) for a in argv])


def one_line_error(err: str, *needles: str) -> None:
    """``err`` is exactly one line, an error without a traceback, holding every needle."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "error:" in lines[0] and "Traceback" not in err, err
    for n in needles:
        assert n in lines[0], (n, err)


@pytest.fixture
def model_dict():
    return make_model().to_dict()


def write_text(path: Path, d: dict, replace=()) -> Path:
    text = json.dumps(d)
    for old, new in replace:
        assert old in text
        text = text.replace(old, new, 1)
    path.write_text(text)
    return path


# == 1. the model reader ================================================================================

@pytest.mark.parametrize("literal,shown", [("1e308", "1e+308"), ("-3e6", "-3e+06"), ("NaN", "nan"),
                                           ("Infinity", "inf"), ("9" * 400, "400-digit integer")])
def test_model_reader_refuses_absurd_coefficients(tmp_path, model_dict, literal, shown):
    path = write_text(tmp_path / "m.json", model_dict, [('"coef_dph": [1.5', f'"coef_dph": [{literal}')])
    with pytest.raises(ModelError) as exc:
        BiasModel.from_json(path)
    msg = str(exc.value)
    assert "field 'coef_dph'" in msg and "k0 (term 1)" in msg and shown in msg and "2097152" in msg


def test_model_reader_checks_bank_2_and_keeps_the_limit_itself(tmp_path):
    d = make_model(order="regress_first").to_dict()
    d["coef_mode2_dph"][4] = -2.5e6
    with pytest.raises(ModelError, match=r"coef_mode2_dph'.*k4 .*-2\.5e\+06"):
        BiasModel.from_dict(d)
    d["coef_mode2_dph"][4] = -COEF_LIMIT_DPH
    assert BiasModel.from_dict(d).coef_mode2[4] == -COEF_LIMIT_DPH


@pytest.mark.parametrize("old,new,field", [
    ('"max_stale_s": 300.0', '"max_stale_s": 1e999', "config.reversal.max_stale_s"),
    ('"max_stale_s": 300.0', '"max_stale_s": 1e300', "config.reversal.max_stale_s"),
    ('"settle_s": 0.0', '"settle_s": 1e10', "config.reversal.settle_s"),
    ('"ref": 6227.0', '"ref": 1' + "0" * 400, "config.proxy.ref"),
    ('"span": 3.0', '"span": NaN', "config.proxy.span"),
])
def test_model_reader_names_non_finite_and_oversized_config_fields(tmp_path, model_dict, capsys, old, new, field):
    path = write_text(tmp_path / "m.json", model_dict, [(old, new)])
    with pytest.raises(ModelError, match=f"field '{field}'"):
        BiasModel.from_json(path)
    assert hdrg("quantize", path, "-o", tmp_path / "t.json") == 2
    one_line_error(capsys.readouterr().err, field)
    assert not (tmp_path / "t.json").exists()


def test_compensate_strict_refuses_a_model_with_a_huge_coefficient(tmp_path, capsys):
    from host_tools import api
    run = tmp_path / "run.csv"
    api.simulate("paper-mr-cycle-4dpm", duration_s=400, output=run)
    coef = [1e308] + [0.0] * 16
    path = tmp_path / "m.json"
    make_model(coef=[1.0] + [0.0] * 16).to_json(path)
    d = json.loads(path.read_text())
    d["coef_dph"] = coef
    path.write_text(json.dumps(d))
    capsys.readouterr()
    assert hdrg("compensate", run, "--model", path, "-o", tmp_path / "out.csv", "--strict") == 2
    one_line_error(capsys.readouterr().err, "k0", "2097152")
    assert not (tmp_path / "out.csv").exists()


# == 2. options of quantize and diagnose ================================================================

@pytest.mark.parametrize("option,value,needle", [
    ("--max-error", "nan", "--max-error nan"), ("--max-error", "-1", "--max-error -1"),
    ("--max-error", "inf", "--max-error inf"), ("--exchange-s", "inf", "--exchange-s inf"),
    ("--exchange-s", "nan", "--exchange-s nan"), ("--power-on-s", "-2", "--power-on-s -2"),
    ("--dwell-s", "0", "--dwell-s 0"), ("--dwell-s", "0.4", "shorter than one sample at the model's sample rate 1 Hz"),
    ("--exchange-s", "0.4", "shorter than one sample at the model's sample rate 1 Hz"),
    ("--power-on-s", "0.2", "--power-on-s 0.2"), ("--exchange-s", "1e300", "2147483646 samples"),
])
def test_quantize_refuses_meaningless_numbers(tmp_path, capsys, option, value, needle):
    model = tmp_path / "m.json"
    make_model().to_json(model)
    assert hdrg("quantize", model, "-o", tmp_path / "t.json", option, value) == 2
    one_line_error(capsys.readouterr().err, option, needle)
    assert not (tmp_path / "t.json").exists()


def test_quantize_exchange_zero_is_no_blanking(tmp_path, capsys):
    model = tmp_path / "m.json"
    make_model().to_json(model)
    assert hdrg("quantize", model, "-o", tmp_path / "t.json", "--exchange-s", "0", "--dwell-s", "1") == 0
    timing = json.loads((tmp_path / "t.json").read_text())["timing"]
    assert timing["exchange_n"] == 0 and timing["dwell_n"] == 1


@pytest.mark.parametrize("option,value", [("--g-min", "nan"), ("--g-min", "inf"), ("--g-min", "-0.1"),
                                          ("--g-min", "1.5"), ("--seed", "-1"), ("--settle", "nan"),
                                          ("--settle", "inf"), ("--max-iter", "-1"), ("--cv-folds", "0")])
def test_diagnose_refuses_meaningless_numbers(tmp_path, capsys, option, value):
    assert hdrg("diagnose", tmp_path / "run.csv", "-o", tmp_path / "d", option, value) == 2
    one_line_error(capsys.readouterr().err, f"{option} {value}")
    assert not (tmp_path / "d").exists()


# == 3. float originals of an exported table ============================================================

@pytest.fixture
def table_json(tmp_path, capsys):
    model = tmp_path / "m.json"
    make_model().to_json(model)
    assert hdrg("quantize", model, "-o", tmp_path / "t.json") == 0
    capsys.readouterr()
    return tmp_path / "t.json"


def _edit_word(d: dict, field_name: str, delta: int) -> dict:
    from firmware_ref.table import LAYOUT
    words = [int(w, 16) for w in d["words"]]
    i = [n for n, (f, _, _) in enumerate(LAYOUT) if f == field_name][0]
    words[i] = (words[i] + delta) & 0xFFFFFFFF
    words[-1] = zlib.crc32(b"".join(w.to_bytes(4, "little") for w in words[:-1]))
    d = dict(d, words=[f"0x{w:08x}" for w in words], crc32=f"0x{words[-1]:08x}")
    d.pop("fields")
    return d


def test_export_keeps_the_originals_of_an_unedited_table(tmp_path, table_json, capsys):
    assert hdrg("export", table_json, "-o", tmp_path / "ok") == 0
    assert "warning" not in capsys.readouterr().err
    header = (tmp_path / "ok" / "hdrg_table.h").read_text()
    assert "(float 1.5)" in header and "Note:" not in header
    assert json.loads((tmp_path / "ok" / "hdrg_table.json").read_text())["model"] is not None


@pytest.mark.parametrize("edit", ["words", "coef"])
def test_export_leaves_out_originals_that_do_not_belong_to_the_table(tmp_path, table_json, capsys, edit):
    d = json.loads(table_json.read_text())
    if edit == "words":
        d = _edit_word(d, "m_0", 1000)
    else:
        d["coef_dph"][0] = 99.0
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(d))
    assert hdrg("export", edited, "-o", tmp_path / "x") == 0
    err = capsys.readouterr().err
    assert err.count("hdrg export: warning:") == 1 and "float originals" in err
    header = (tmp_path / "x" / "hdrg_table.h").read_text()
    assert "(float " not in header and " * Note: " in header and "m.json" not in header
    out = json.loads((tmp_path / "x" / "hdrg_table.json").read_text())
    assert out["model"] is None and out["coef_dph"] is None and "bound_dph" not in out and "float originals" in out["note"]
    # the export of the export keeps the note and has nothing more to warn about
    assert hdrg("export", tmp_path / "x" / "hdrg_table.json", "-o", tmp_path / "y") == 0
    assert "warning" not in capsys.readouterr().err
    assert " * Note: " in (tmp_path / "y" / "hdrg_table.h").read_text()


# == 4. check-impl ======================================================================================

def _check(*extra):
    return ["vectors", "check-impl", VECTORS, *extra]


@pytest.mark.parametrize("option,value", [("--fields", ""), ("--fields", " , "), ("--sets", "")])
def test_check_impl_refuses_an_empty_list(capsys, option, value):
    assert hdrg(*_check("--cmd", "true", option, value)) == 2
    one_line_error(capsys.readouterr().err, option, "names nothing")


def test_check_impl_refuses_unknown_fields_and_an_unsplittable_cmd(capsys):
    from host_tools.vectors.runner import check_impl
    from host_tools.vectors.spec import VectorsError
    assert hdrg(*_check("--cmd", "true", "--fields", "out,nope")) == 2
    one_line_error(capsys.readouterr().err, "unknown field(s) nope")
    assert hdrg(*_check("--cmd", "./impl 'unbalanced")) == 2
    one_line_error(capsys.readouterr().err, "--cmd", "No closing quotation")
    with pytest.raises(VectorsError, match="--fields is empty"):
        check_impl("true", VECTORS, ["primitives"], fields=[])


def test_check_impl_does_not_wait_for_a_child_that_keeps_stdout_open(tmp_path, capsys):
    pidfile = tmp_path / "pid"
    script = tmp_path / "impl.sh"
    script.write_text(f"#!/bin/sh\nsleep 30 &\necho $! > {pidfile}\ncat > /dev/null\necho X\n")
    script.chmod(0o755)
    t0 = time.monotonic()
    assert hdrg(*_check("--cmd", script, "--sets", "primitives")) == 1
    took = time.monotonic() - t0
    out = capsys.readouterr().out
    assert "FAIL" in out and "got:      X" in out
    assert took < 10, took
    pid = int(pidfile.read_text())
    for _ in range(50):             # the forked sleep was killed with the group (gone, or a zombie)
        if _gone(pid):
            break
        time.sleep(0.1)
    assert _gone(pid)


def _gone(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


# == 5. the environment =================================================================================

def _python_m(shell_prefix: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ, **(env_extra or {}))
    return subprocess.run(["sh", "-c", f"{shell_prefix} exec {sys.executable} -m host_tools.cli simulate --list"],
                          capture_output=True, text=True, timeout=120, env=env)


def test_closed_stdout_is_a_one_line_error():
    r = _python_m("exec >&-;")
    assert r.returncode == 2
    one_line_error(r.stderr, "standard output is closed")


def test_numba_num_threads_zero_is_a_one_line_error():
    r = _python_m("", {"NUMBA_NUM_THREADS": "0"})
    assert r.returncode == 2
    one_line_error(r.stderr, "NUMBA_NUM_THREADS=0")


def test_startup_problem(monkeypatch):
    from host_tools.cli import startup_problem
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    assert startup_problem() is None
    monkeypatch.setenv("NUMBA_NUM_THREADS", "-1")
    assert "NUMBA_NUM_THREADS=-1" in startup_problem()
    monkeypatch.setattr(sys, "stdout", None)
    assert "standard output is closed" in startup_problem()


def test_hdrg_entry_refuses_a_closed_stdout(monkeypatch):
    """The `hdrg` entry point (host_tools.cli.main) with stdout closed: exit 2, no traceback."""
    from host_tools import cli
    monkeypatch.setattr(sys, "stdout", None)
    assert cli.main(["simulate", "--list"]) == 2


@pytest.mark.parametrize("value", ["nan", "inf", "-1"])
def test_fit_settle_must_be_finite_seconds(tmp_path, capsys, value):
    """`hdrg fit --settle` refuses NaN, inf and negative seconds by name, in one line."""
    assert hdrg("fit", tmp_path / "run.csv", "-o", tmp_path / "m.json", "--settle", value) == 2
    one_line_error(capsys.readouterr().err, f"--settle {value}")
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("value", ["100", "nan", "inf"])
def test_demo_refuses_a_run_too_short_to_fit(tmp_path, capsys, value):
    """`hdrg demo --duration 100` names the real cause (the runs are shorter than two mode-reversal
    periods), not a missing mode-2 bank; NaN and inf are refused the same way."""
    assert hdrg("demo", "-o", tmp_path / "d", "--duration", value) == 2
    one_line_error(capsys.readouterr().err, f"--duration {value}", "at least 600 s")
    assert not (tmp_path / "d").exists()
