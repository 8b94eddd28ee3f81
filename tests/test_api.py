"""The Python API (host_tools.api) and the command line around it: `hdrg fit` writes the model of
`api.fit`, the refusals live in the API, the fit's defaults are one policy object, the error
boundary tells a user's error (one line, exit 2) from a bug (traceback, exit 1), `hdrg --version`
and `--help` import no command module, every command that writes takes -o/--out/--output and every
command's help ends with examples that parse."""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from host_tools.cli import COMMANDS, build_parser, main, user_error
from host_tools.golden import runlog
from host_tools.golden.model import BiasModel

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def cycle(tmp_path_factory):
    """A 4-h mode-reversal chamber cycle (both signs of dT/dt: the whole default pipeline runs)."""
    from host_tools import api
    path = tmp_path_factory.mktemp("api") / "cycle.csv"
    api.simulate("paper-mr-cycle-4dpm", seed=3, duration_s=14400, output=path)
    return path


def test_api_offers_the_workflow():
    from host_tools import api
    for name in ("simulate", "fit", "compensate", "quantize", "export", "diagnose", "metrics", "fit_policy"):
        assert callable(getattr(api, name)), name
        assert getattr(api, name).__doc__, name


def test_hdrg_fit_writes_the_model_of_api_fit(cycle, tmp_path, capsys):
    from host_tools import api
    assert main(["fit", str(cycle), "-o", str(tmp_path / "m.json")]) == 0
    capsys.readouterr()
    model = api.fit([cycle])
    assert BiasModel.from_json(tmp_path / "m.json").to_dict() == model.to_dict()
    # a RunLog is a run as well as its path; output= writes the same model
    again = api.fit([runlog.read(cycle)], tmp_path / "api.json")
    assert again.to_dict() == model.to_dict()
    assert BiasModel.from_json(tmp_path / "api.json").to_dict() == model.to_dict()


def test_api_fit_refuses_what_hdrg_fit_refuses(tmp_path):
    from host_tools import api
    from host_tools.errors import HdrgError
    from host_tools.fitting.fit import UnidentifiableError
    api.simulate("paper-ftr-cycle-4dpm", seed=1, duration_s=3000, output=tmp_path / "ftr.csv")
    tiny = tmp_path / "tiny.csv"
    tiny.write_text("".join((tmp_path / "ftr.csv").read_text().splitlines(keepends=True)[:40]))
    with pytest.raises(api.FitRefused, match="valid samples for"):
        api.fit([tiny], terms="k0,k1,k2,k3", rate_estimator="diff")
    with pytest.warns(api.FitWarning, match="do not identify"):
        assert api.fit([tiny], terms="k0,k1,k2,k3", rate_estimator="diff", force=True).terms == (0, 1, 2, 3)
    fewer = tmp_path / "fewer.csv"
    fewer.write_text("".join(tiny.read_text().splitlines(keepends=True)[:24]))
    with pytest.raises((api.FitRefused, UnidentifiableError)) as refused:    # forced or not: no error bars
        api.fit([fewer], terms="all", rate_estimator="diff", force=True)
    assert isinstance(refused.value, HdrgError)
    with pytest.raises(ValueError, match="same file|input"):
        api.fit([tiny], tiny)      # never over an input


def test_several_runs_say_so_in_the_model_not_in_a_warning_each_time(tmp_path):
    from host_tools import api
    a = api.simulate("paper-ftr-cycle-4dpm", seed=1, duration_s=3000)
    b = api.simulate("paper-ftr-cycle-4dpm", seed=2, duration_s=3000)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        model = api.fit([a, b], terms="k0,k1", rate_estimator="diff")
    assert model.fit["several_runs"] == api.SEVERAL_RUNS_NOTE
    assert not any(issubclass(w.category, api.FitWarning) and "training runs:" in str(w.message) for w in seen)


def test_the_fit_policy_gathers_the_defaults_the_help_shows():
    from host_tools.fitting import fit_lag, fit_rate
    from host_tools.fitting.fit import MIN_SAMPLES_PER_TERM
    from host_tools.fitting.fit_pipeline import GUARD_MARGIN, fit_policy
    from host_tools.golden import compensate, reversal
    p = fit_policy()
    assert p.rate_selection_mr == compensate.DEFAULT_RATE_SELECTION_MR and p.lag_block == compensate.DEFAULT_LAG_BLOCK
    assert p.rate_preferred == fit_rate.RATE_PREFERRED and dict(p.lag_margin) == fit_lag.LAG_MARGIN
    assert p.guard_margin == GUARD_MARGIN and p.min_samples_per_term == MIN_SAMPLES_PER_TERM
    assert p.max_stale_s == reversal.DEFAULT_MAX_STALE_S and p.cv_blocks == 8
    parser = build_parser("fit")
    fit_parser = parser._subparsers._group_actions[0].choices["fit"]
    text = fit_parser.format_help()
    assert f"fewer than {p.min_samples_per_term} valid samples" in text and f"(default {p.cv_blocks})" in text
    assert fit_parser.get_default("cv_blocks") == p.cv_blocks


def test_api_chain_compensate_metrics_quantize_export(cycle, tmp_path):
    from host_tools import api
    model = api.fit([cycle], tmp_path / "m.json")
    out = api.compensate(cycle, tmp_path / "m.json", output=tmp_path / "c.csv")
    assert {"bias_dph", "valid", "flags"} <= set(out.columns) and (tmp_path / "c.csv").exists()
    assert api.metrics([out])[0]["per_tau"]
    q = api.quantize(model, tmp_path / "table.json")
    paths = api.export(tmp_path / "table.json", tmp_path / "out")
    assert set(paths) == {"c", "json", "mem"} and all(Path(p).exists() for p in paths.values())
    assert json.loads((tmp_path / "table.json").read_text()) and q.table.to_words()


def test_api_namespace_is_its_all():
    from host_tools import api
    public = {name for name in vars(api) if not name.startswith("_")}
    assert public == set(api.__all__), public ^ set(api.__all__)
    for name in ("os", "warnings", "dataclass", "field", "np", "annotations"):
        assert not hasattr(api, name), name
    for name in api.__all__:
        assert getattr(api, name).__doc__ or isinstance(getattr(api, name), str), name


def test_term_labels_name_the_terms_as_hdrg_fit_prints_them(cycle):
    from host_tools import api
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        outcome = api.fit_with_result([cycle], terms="k0,k1,k2,k3", rate_estimator="diff")
    assert outcome.model.terms == (0, 1, 2, 3)
    assert api.term_labels(outcome.model) == outcome.term_labels == ("k0", "k1", "k2", "k3")


def test_compensate_takes_columns_and_returns_arrays(cycle, tmp_path):
    """A path, a RunLog and a mapping of columns give the same result: the compensated rate, the
    bias [deg/h], valid (bool) and flags, as documented; the docstring names no column that does
    not exist."""
    import numpy as np
    from host_tools import api
    model = api.fit([cycle], tmp_path / "m.json")
    log = runlog.read(cycle)
    columns = {name: np.asarray(log[name]) for name in ("t_s", "freq_hz", "temp_c", "rate_dph", "mode")}
    dps = dict(columns, rate_dps=columns["rate_dph"] / 3600.0)
    del dps["rate_dph"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        outs = [api.compensate(run, tmp_path / "m.json") for run in (cycle, log, columns, dps)]
    ref = outs[0]
    assert isinstance(ref, api.CompensatedRun) and isinstance(ref, runlog.RunLog)
    assert ref.valid.dtype == bool and ref.valid.any() and np.issubdtype(ref.flags.dtype, np.integer)
    assert np.array_equal(ref.valid, np.asarray(ref["valid"]) == 1)
    assert np.all(np.isfinite(ref.rate_dph[ref.valid])) and np.all(np.isfinite(ref.bias_dph[ref.valid]))
    assert ref.term_labels == api.term_labels(model)
    arrays = ref.to_dict()
    assert set(arrays) == {"t_s", "rate_dph", "bias_dph", "valid", "flags"}
    for out in outs[1:]:
        assert np.array_equal(out.valid, ref.valid) and np.array_equal(out.flags, ref.flags)
        assert np.allclose(out.rate_dph[out.valid], ref.rate_dph[ref.valid], rtol=0, atol=1e-9)
    doc = api.compensate.__doc__ + api.CompensatedRun.__doc__
    assert "comp_rate_dph" not in doc
    for key in ("rate_dph", "bias_dph", "valid", "flags"):
        assert f"``{key}``" in doc and key in ref.columns
    assert api.metrics([columns])[0]["per_tau"] and api.metrics([ref])[0]["per_tau"]
    with pytest.raises(TypeError, match="mapping of columns"):
        api.compensate([1, 2, 3], model)


def test_compensate_takes_a_dataframe(cycle, tmp_path):
    import numpy as np
    pd = pytest.importorskip("pandas")
    from host_tools import api
    model = api.fit([cycle])
    log = runlog.read(cycle)
    frame = pd.DataFrame({name: log[name] for name in ("t_s", "freq_hz", "temp_c", "rate_dph", "mode")})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a, b = api.compensate(frame, model), api.compensate(log, model)
    assert np.array_equal(a.valid, b.valid) and np.allclose(a.rate_dph[a.valid], b.rate_dph[b.valid], rtol=0, atol=1e-9)
    assert list(pd.DataFrame(a.to_dict()).columns) == ["t_s", "rate_dph", "bias_dph", "valid", "flags"]


# -- the error boundary ------------------------------------------------------------------------------

def _hdrg(*args, code=None, cwd=None):
    prog = (code or "") + "\nimport sys\nfrom host_tools.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    return subprocess.run([sys.executable, "-c", prog, *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, timeout=300)


def test_a_bug_keeps_its_traceback_and_a_bad_file_is_one_line(tmp_path, cycle):
    bug = "import host_tools.api as a\ndef broken(*x, **k):\n    raise KeyError('k9')\na.fit_with_result = broken"
    r = _hdrg("fit", cycle, "-o", tmp_path / "m.json", code=bug)
    assert r.returncode == 1 and "Traceback" in r.stderr and "KeyError: 'k9'" in r.stderr
    bad = tmp_path / "bad.csv"
    bad.write_text("this is not a run log\n1,2,3\n")
    r = _hdrg("fit", bad, "-o", tmp_path / "m.json")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("hdrg fit: error: "), r.stderr
    assert "Traceback" not in r.stderr


def test_user_error_tells_our_checks_from_library_errors():
    from host_tools.errors import HdrgError, UserError
    from host_tools.golden.runlog import RunLogError
    assert issubclass(RunLogError, HdrgError) and issubclass(RunLogError, ValueError)
    assert user_error(UserError("x")) and user_error(FileNotFoundError(2, "No such file", "a.csv"))
    from host_tools.cli.options import positive_seconds
    with pytest.raises(ValueError) as ours:
        positive_seconds("-1", "--duration", 10)
    assert user_error(ours.value)
    with pytest.raises(ValueError) as lib:
        int("x")
    assert not user_error(lib.value)
    for exc in (KeyError("a"), TypeError("b"), IndexError("c"), AttributeError("d")):
        assert not user_error(exc)


# -- start-up, options, examples ----------------------------------------------------------------------

@pytest.mark.parametrize("flag", ["--version", "--help"])
def test_version_and_help_import_no_command_module(flag):
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "host_tools.cli", flag], capture_output=True,
                       text=True, cwd=ROOT, timeout=60)
    assert r.returncode == 0 and "hdrg" in r.stdout
    imported = {line.split("|")[-1].strip() for line in r.stderr.splitlines() if line.startswith("import time:")}
    heavy = {m for m in imported if m.split(".")[0] in ("numpy", "scipy", "numba", "matplotlib")}
    commands = {m for m in imported if m.startswith("host_tools.cli.")}
    assert not heavy and not commands, (heavy, commands)


def test_commands_in_workflow_order():
    order = ["simulate", "capture", "fit", "compensate", "report", "metrics", "diagnose", "quantize", "export",
             "upload", "device", "vectors", "cost", "lot", "paper", "bench", "demo"]
    assert [c for c in COMMANDS if c in order] == [c for c in order if c in COMMANDS]


def _subparser(name):
    return build_parser(name)._subparsers._group_actions[0].choices[name]


def _options(parser) -> set:
    return {s for a in parser._actions for s in a.option_strings}


WRITERS = ("simulate", "fit", "compensate", "quantize", "export", "capture", "diagnose", "metrics", "cost", "paper",
           "lot")


@pytest.mark.parametrize("name", [c for c in WRITERS if c in COMMANDS])
def test_every_command_that_writes_takes_o_out_output(name):
    assert {"-o", "--out", "--output"} <= _options(_subparser(name))


def test_the_subcommands_that_write_take_o_out_output_too():
    sub = _subparser("vectors")._subparsers._group_actions[0].choices["generate"]
    assert {"-o", "--out", "--output"} <= _options(sub)
    for bench in _subparser("bench")._subparsers._group_actions[0].choices.values():
        assert {"-o", "--out", "--output"} <= _options(bench)


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_help_ends_with_examples_that_parse(name):
    parser = build_parser(name)
    epilog = _subparser(name).epilog or ""
    lines = [line.strip() for line in epilog.splitlines() if line.strip().startswith(f"hdrg {name}")]
    assert lines, f"hdrg {name} --help shows no example"
    for line in lines:
        args = parser.parse_args(shlex.split(line)[1:])
        assert args.command == name


def test_the_model_and_the_table_are_given_alike(cycle, tmp_path, capsys):
    from host_tools import api
    api.fit([cycle], tmp_path / "m.json")
    assert main(["quantize", str(tmp_path / "m.json"), "-o", str(tmp_path / "a.json")]) == 0
    assert main(["quantize", "--model", str(tmp_path / "m.json"), "--out", str(tmp_path / "b.json")]) == 0
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    assert main(["export", "--table", str(tmp_path / "a.json"), "--output", str(tmp_path / "x")]) == 0
    assert (tmp_path / "x" / "hdrg_table.h").exists()
    capsys.readouterr()
    assert main(["quantize", "-o", str(tmp_path / "c.json")]) == 2
    assert "--model" in capsys.readouterr().err


def test_api_fit_says_what_hdrg_fit_says(tmp_path):
    """api.fit's warnings are the lines `hdrg fit` prints: no several-runs note, the coverage of
    the runs together (two full cycles draw none), one line per fact."""
    from host_tools import api
    a = api.simulate("mr-one-cycle-4dpm", seed=2, output=str(tmp_path / "a.csv"))
    b = api.simulate("mr-one-cycle-2dpm", seed=3, output=str(tmp_path / "b.csv"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        api.fit([a, b])
    said = [str(w.message) for w in caught if issubclass(w.category, api.FitWarning)]
    assert not any("training runs:" in s or "cover" in s for s in said), said
    assert all("\n" not in s for s in said)


def test_api_compensate_repeats_an_uncalibrated_start_up(tmp_path):
    """api.compensate, like `hdrg compensate`, warns once when a log from power-on meets a model
    whose start-up is not calibrated (one training run), and not on a log that starts later."""
    from host_tools import api
    from host_tools.golden.flags import CompensationWarning
    model = api.fit(api.simulate("paper-mr-cycle-4dpm", seed=1, duration_s=3600))
    assert model.fit["start_up"]["calibrated"] is False
    run = api.simulate("paper-mr-cycle-4dpm", seed=2, duration_s=1800)
    for log, want in ((run, 1), (run.select(slice(400, None)), 0)):
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            api.compensate(log, model)
        said = [w for w in seen if issubclass(w.category, CompensationWarning) and "start-up" in str(w.message)]
        assert len(said) == want, [str(w.message) for w in seen]
