"""The Python API of hdrg: one plain function per step of the workflow, each what the command of the
same name does (the commands parse their options, call these and print).

    from host_tools import api
    api.simulate("mr-one-cycle-4dpm", seed=2, output="run1.csv")    # one chamber cycle (cools, heats), 4 degC/min
    api.simulate("mr-one-cycle-2dpm", seed=3, output="run2.csv")    # the same at 2 degC/min
    model = api.fit(["run1.csv", "run2.csv"], output="model.json") # = `hdrg fit run1.csv run2.csv -o model.json`
    print(api.term_labels(model))                              # ('k0', 'k1', ...): the names `hdrg fit` prints
    out = api.compensate("held_out.csv", model)                # a CompensatedRun
    out.rate_dph, out.valid, out.flags                         # compensated rate [deg/h], bool, flag bits
    print(api.metrics([out])[0]["per_tau"])
    q = api.quantize(model, output="table.json")               # the fixed-point table
    api.export(q.table, "out/", info=q.to_dict())              # C header, table.json, $readmemh

Units and formats: times in seconds, rates in deg/h, the proxy in its own unit (Hz for ``freq``,
degC for ``temp``).  A run log is a path (CSV or ``.npz``, docs/RUN_LOG.md), a
:class:`host_tools.golden.runlog.RunLog`, a mapping of column name -> array (``t_s`` [s],
``rate_dph`` [deg/h] or ``rate_dps`` [deg/s], ``freq_hz`` [Hz] and/or ``temp_c`` [degC], ``mode``
1/2/3 for mode reversal, 0 or left out without it, ``aux_<name>``: the columns of docs/RUN_LOG.md)
or a pandas DataFrame of those columns; a model a path to model.json (``hdrg fit``) or a
:class:`host_tools.golden.model.BiasModel` (``model.terms``: the term indices k, 0..16;
:func:`term_labels`: their names 'k0'..'k16'); a table a path (table.json, ``.bin``, ``.memh``)
or a :class:`firmware_ref.table.Table`.  Outputs (``output=``) are written atomically and never
over an input.  Errors the caller can fix raise host_tools.errors.HdrgError subclasses (also
ValueError); warnings go through :mod:`warnings` (category :class:`FitWarning` for the fit).

The defaults of the fit are :func:`fit_policy` (host_tools.fitting.fit_pipeline.FitPolicy).
"""
import os as _os
import warnings as _warnings
from collections.abc import Mapping as _Mapping
from dataclasses import dataclass as _dataclass
from dataclasses import field as _field

import numpy as _np

from host_tools.fitting.fit_pipeline import SEVERAL_RUNS_NOTE, FitPolicy, FitRefused, fit_policy
from host_tools.fitting.fit_pipeline import check_fit_result as _check_fit_result
from host_tools.golden.runlog import RunLog as _RunLog

__all__ = ["simulate", "fit", "fit_with_result", "compensate", "quantize", "export", "diagnose", "metrics",
           "term_labels", "fit_policy", "FitPolicy", "FitOutcome", "CompensatedRun", "FitRefused", "FitWarning",
           "SEVERAL_RUNS_NOTE"]


class FitWarning(UserWarning):
    """What a fit says about its result (terms the data do not identify, several runs, clamped inputs)."""


def _is_path(x) -> bool:
    return isinstance(x, (str, _os.PathLike))


def _from_columns(columns, source: str = "<columns>"):
    """A RunLog from a mapping of column name -> array, or from a pandas DataFrame."""
    if isinstance(columns, _Mapping):
        cols = dict(columns)
    elif hasattr(columns, "columns") and hasattr(columns, "to_numpy"):      # a pandas DataFrame
        cols = {c: columns[c].to_numpy() for c in columns.columns}
    else:
        raise TypeError(f"a run log is a path, a RunLog, a mapping of columns or a pandas DataFrame, "
                        f"not {type(columns).__name__}")
    cols = {str(name): _np.asarray(values) for name, values in cols.items()}
    if "rate_dps" in cols and "rate_dph" not in cols:
        cols["rate_dph"] = cols.pop("rate_dps") * 3600.0
    return _RunLog(cols, {}, source)


def _read_run(run):
    """A RunLog from a path, a RunLog, a mapping of columns or a pandas DataFrame."""
    from host_tools.golden import runlog
    if _is_path(run):
        return runlog.read(run)
    return run if isinstance(run, _RunLog) else _from_columns(run)


def _read_model(model):
    from host_tools.golden.model import BiasModel
    return BiasModel.from_json(model) if _is_path(model) else model


def _paths(*items) -> list:
    out = []
    for item in items:
        seq = item if isinstance(item, (list, tuple)) else [item]
        out.extend(p for p in seq if _is_path(p))
    return out


def term_labels(model) -> tuple:
    """The names of the terms of ``model`` (path or BiasModel), as `hdrg fit` prints them: 'k0',
    'k1', ... in the order of ``model.terms``.  The regressor of each (1, u, u^2, ..., v, z, u*v, ...)
    is firmware_ref.terms.TERM_NAMES[k] (model.json's ``term_names``)."""
    return tuple(f"k{k}" for k in _read_model(model).terms)


# -- simulate --------------------------------------------------------------------------------------------

def simulate(scenario: str = "paper-mr-cycle-4dpm", *, seed: int = 0, duration_s: float | None = None,
             sample_rate_hz: float = 1.0, output=None, **overrides):
    """A simulated run log (host_tools.simulation.sim.simulate): ``scenario`` one of
    ``hdrg simulate --list``, ``seed`` the random seed, ``duration_s`` [s] (None: the scenario's),
    ``sample_rate_hz`` [Hz]; ``overrides``: the simulator's parameters (``reversal``,
    ``exchange_s``, ``dwell_s``, ...: host_tools.simulation.sim.build_config).  ``output``: also
    write it (``.csv`` or ``.npz``).  Returns the RunLog."""
    from host_tools.golden import runlog
    from host_tools.simulation.sim import simulate as _simulate
    log = _simulate(scenario, seed=seed, duration_s=duration_s, sample_rate_hz=sample_rate_hz, **overrides)
    if output is not None:
        runlog.write(log, output)
    return log


# -- fit -------------------------------------------------------------------------------------------------

@_dataclass
class FitOutcome:
    """What :func:`fit_with_result` returns: the model, the fitter's FitResult of the model kept
    (``terms``, ``coef``, ``stderr``, ``n``, ``rms`` [deg/h], ``cond``, ``cv``, ``dropped``, ...),
    the training RunLogs and the warnings (sentences) about the result; ``term_labels``: the
    model's terms as 'k0', 'k1', ..."""
    model: object
    result: object
    logs: list
    warnings: list = _field(default_factory=list)

    @property
    def term_labels(self) -> tuple:
        return term_labels(self.model)


def fit_with_result(runs, output=None, *, terms=None, proxy=None, rate_estimator=None, rate_n=None,
                    rate_shift=None, order=None, combiner=None, settle_s=None, proxy_range=None, rate_range=None,
                    drop_unidentifiable: bool = False, cv_blocks: int | None = None, force: bool = False) -> FitOutcome:
    """:func:`fit`, returning a :class:`FitOutcome` and issuing no warning (the caller shows
    ``outcome.warnings``)."""
    from host_tools.atomic import refuse_overwrite
    from host_tools.fitting.fit import fit_logs
    from host_tools.fitting.fit_pipeline import fit_default, fit_without_run_offsets
    from host_tools.fitting.fit_rate import fit_auto_rate
    from host_tools.golden.checks import check_fit_inputs, coverage_advice
    from host_tools.golden.compensate import checked as _checked
    from host_tools.golden.compensate import fit_config_from_logs
    from host_tools.golden.flags import problems

    runs = list(runs) if isinstance(runs, (list, tuple)) else [runs]
    if output is not None:
        refuse_overwrite(output, _paths(runs))
    cv_blocks = fit_policy().cv_blocks if cv_blocks is None else cv_blocks
    logs = [_read_run(r) for r in runs]
    check_fit_inputs(logs, proxy)
    reversal = ({"combiner": combiner, "settle_s": settle_s, "order": order}
                if any(log.reversal for log in logs) else None)
    kw = dict(proxy_kind=proxy, proxy_range=proxy_range, rate_range=rate_range, reversal=reversal)
    if rate_estimator is None and rate_n is None and rate_shift is None:
        # the defaults (fit_policy()): rate auto for mode-reversal logs, the lag-state block of the
        # proxy or the sensor when cross-validation supports it, the guard against the cubic
        model, res = fit_default(logs, terms, drop_unidentifiable=drop_unidentifiable, cv_blocks=cv_blocks, **kw)
    else:
        if rate_estimator == "auto":
            def one(lg):
                return fit_auto_rate(lg, terms, cv_blocks=cv_blocks, **kw)
        else:
            cfg = fit_config_from_logs(logs, rate_estimator=rate_estimator, n=rate_n, shift=rate_shift, **kw)

            def one(lg):
                return fit_logs(lg, cfg, terms, drop_unidentifiable=drop_unidentifiable, cv_blocks=cv_blocks)
        model, res = fit_without_run_offsets(logs, one)     # several runs: per-run offsets removed
    _check_fit_result(res, force)
    if len(logs) > 1:
        model.fit["several_runs"] = SEVERAL_RUNS_NOTE
    said = []
    weak = model.fit.get("insignificant", [])
    if weak:
        said.append(f"the data do not identify {['k%d' % k for k in weak]} (|coef| < 2 standard errors); "
                    f"they fit noise: consider --terms auto")
    said.extend(coverage_advice(logs, model.config.proxy.kind))     # the runs together, not each alone
    for log in logs:   # e.g. proxy_range / rate_range narrower than the data: the fit saw clamped inputs
        said.extend(f"training run {log.source}: {m}" for m in problems(_checked(log, model)))
    if tuple(res.terms) == (0,) and terms in (None, "auto"):
        said.append("term selection kept only the offset k0: no temperature term held out in the "
                    "cross-validation; the model does not compensate temperature (see the warnings above, or fix the "
                    "terms with --terms)")
    said.extend(_fit_floor_and_start_up(model))
    if output is not None:
        model.to_json(output)
    return FitOutcome(model, res, logs, said)


def _fit_floor_and_start_up(model) -> list:
    """One line each: the model loses to no compensation held out (model.fit["floor"]); the
    start-up is not calibrated (model.fit["start_up"])."""
    out = []
    floor = model.fit.get("floor") or {}
    if floor.get("worse"):
        out.append(f"held out ({floor['method'].split(' (')[0]}), the model is worse than no temperature "
                   f"compensation ({'; '.join(floor['worse'])}): check it on a held-out run before shipping it")
    start = model.fit.get("start_up") or {}
    if start.get("calibrated") is False:
        out.append(f"start-up not calibrated: {start['why']}; {start['record']}")
    return out


def fit(runs, output=None, *, terms=None, proxy=None, rate_estimator=None, rate_n=None, rate_shift=None,
        order=None, combiner=None, settle_s=None, proxy_range=None, rate_range=None,
        drop_unidentifiable: bool = False, cv_blocks: int | None = None, force: bool = False):
    """Fit the bias model to training runs, as `hdrg fit` does; returns the BiasModel (and writes
    it to ``output``, model.json, when given).

    ``runs``: run logs (paths or RunLogs; one or a list).  With no rate option the defaults
    (:func:`fit_policy`, host_tools.fitting.fit_pipeline.fit_default): the rate estimator chosen by
    cross-validation on mode-reversal logs, terms 'auto', the lag-state block when it holds out, the
    guard against the flight stack's cubic; several runs: one offset per run removed.

    * ``terms``: 'auto' (default), 'all' (the paper's 16), 'k0,k1,...' or groups 'const,temp,rate,cross';
    * ``proxy``: 'freq' (drive frequency [Hz], default when logged) or 'temp' (temp_c [degC]);
    * ``rate_estimator`` ('diff', 'diffn', 'lsq', 'iir' or 'auto'), ``rate_n`` [samples],
      ``rate_shift`` (iir coefficient 2^-shift): a fixed proxy-rate estimator instead of the default;
    * ``order`` ('regress_first' | 'combine_first'), ``combiner`` ('pair' | 'trend' | 'none'),
      ``settle_s`` [s]: mode-reversal logs only;
    * ``proxy_range`` ('LO,HI' or a pair, proxy units), ``rate_range`` (largest |d proxy/dt|
      [proxy units/s]): the declared ranges (default: the training range + 10 %, the data's);
    * ``drop_unidentifiable``: drop the terms the data cannot identify instead of refusing;
    * ``cv_blocks``: time blocks of the cross-validation on one run (default ``fit_policy().cv_blocks``);
    * ``force``: fit even with fewer than ``fit_policy().min_samples_per_term`` valid samples per coefficient.

    Refusals: host_tools.fitting.fit.UnidentifiableError (collinear terms), :class:`FitRefused`
    (no degrees of freedom, too few samples per coefficient), RunLogError, ValueError of the checks
    of the inputs (a compensated log, a run given twice).  Warnings: :class:`FitWarning`."""
    out = fit_with_result(runs, output, terms=terms, proxy=proxy, rate_estimator=rate_estimator, rate_n=rate_n,
                          rate_shift=rate_shift, order=order, combiner=combiner, settle_s=settle_s,
                          proxy_range=proxy_range, rate_range=rate_range, drop_unidentifiable=drop_unidentifiable,
                          cv_blocks=cv_blocks, force=force)
    for w in out.warnings:
        _warnings.warn(w, FitWarning, stacklevel=2)
    return out.model


# -- compensate, metrics, diagnose ----------------------------------------------------------------------

@_dataclass(eq=False)
class CompensatedRun(_RunLog):
    """What :func:`compensate` returns: the compensated run log (a RunLog: ``out["name"]``,
    ``out.columns``, ``len(out)``, ``api.metrics([out])``, host_tools.golden.runlog.write) with the
    input's other columns and metadata (``compensated: yes``), and

    * ``t_s`` [s]: the input's times;
    * ``rate_dph`` [deg/h]: the compensated rate (column ``rate_dph``; NaN where not valid);
    * ``bias_dph`` [deg/h]: the bias the model removed (column ``bias_dph``; NaN where not valid);
    * ``valid``: bool array, True where the output is valid (column ``valid``, 1/0);
    * ``flags``: int array of flag bits (column ``flags``; docs/RUN_LOG.md, "Compensated run logs");
    * ``term_labels``: the model's terms, 'k0', 'k1', ...

    ``to_dict()``: these five arrays by name (``pandas.DataFrame(out.to_dict())`` for a table)."""
    term_labels: tuple = ()

    @property
    def bias_dph(self):
        return self.columns["bias_dph"]

    @property
    def valid(self):
        return self.columns["valid"] > 0

    @property
    def flags(self):
        return self.columns["flags"]

    def to_dict(self) -> dict:
        """{"t_s" [s], "rate_dph" [deg/h], "bias_dph" [deg/h], "valid" (bool), "flags" (int)}."""
        return {"t_s": self.t_s, "rate_dph": self.rate_dph, "bias_dph": self.bias_dph, "valid": self.valid,
                "flags": self.flags}


def _start_up_note(model, t_s) -> str | None:
    """The warning for a log that starts at power-on (first ``t_s`` 0) compensated by a model whose
    fit did not calibrate the start-up (model.json fit.start_up, hdrg fit), else None."""
    start = model.fit.get("start_up") or {}
    if start.get("calibrated") is not False or len(t_s) == 0 or float(t_s[0]) != 0.0:
        return None
    return (f"this log starts at power-on and the model's start-up is not calibrated: {start.get('why', '')} "
            f"(model.json fit.start_up)")


def compensate(run, model, *, impl: str = "float", table=None, output=None, strict: bool = False) -> CompensatedRun:
    """Apply ``model`` (path or BiasModel) to ``run`` (a path, a RunLog, a mapping of column name ->
    array or a pandas DataFrame: ``t_s`` [s], ``rate_dph`` [deg/h], ``freq_hz`` [Hz] and/or
    ``temp_c`` [degC], ``mode``; the columns the model was fitted on), as `hdrg compensate`:
    ``impl`` 'float' (the float64 golden model) or 'fixed' (the bit-accurate fixed-point reference;
    ``table`` a table path or Table instead of quantizing the model on the fly).

    Returns a :class:`CompensatedRun`: ``out.rate_dph`` the compensated rate [deg/h],
    ``out.bias_dph`` the bias removed [deg/h], ``out.valid`` (bool), ``out.flags`` (flag bits),
    ``out.term_labels``; the same as columns ``rate_dph``, ``bias_dph``, ``valid`` (1/0), ``flags``
    of the compensated log (docs/RUN_LOG.md, "Compensated run logs").  ``output``: also write it
    (CSV or ``.npz``).  Extrapolation and saturation warn (CompensationWarning), or raise with
    ``strict``; a log from power-on under a model whose start-up is not calibrated warns too."""
    from host_tools.atomic import refuse_overwrite
    from host_tools.golden import flags
    from host_tools.golden import runlog
    from host_tools.golden.compensate import check_impl
    from host_tools.golden.compensate import compensate as _compensate
    from host_tools.jsonread import check_regular

    check_impl(impl)
    if output is not None:
        refuse_overwrite(output, _paths(run, model, table))
    for item, what in ((run, "run log"), (model, "model"), (table, "table")):
        if _is_path(item):
            check_regular(item, what)       # /dev/zero, a FIFO: refused before anything reads them
    model = _read_model(model)
    if table is not None:
        if impl != "fixed":
            raise ValueError("a table needs impl 'fixed' (--impl fixed)")
        if _is_path(table):
            from host_tools.fixed.quantize import read_table
            table = read_table(table)
    out = _compensate(_read_run(run), model, impl=impl, table=table)
    flags.report(out, strict=strict)
    mode_given = out.has_mode_column
    out = CompensatedRun(out.columns, out.metadata, out.source, out.notes, out.first_data_line, out.segments,
                         term_labels(model))
    if not mode_given:
        out._mode_given = False
    if output is not None:
        if not _os.fspath(output).lower().endswith(".npz"):
            from host_tools.link.capture import meta_text
            # a metadata value with a newline (an NPZ's, a file name's) must not end its '# key: value' line
            out.metadata = {meta_text(k, key=True): meta_text(v) for k, v in out.metadata.items()}
        runlog.write(out, output)
    note = _start_up_note(model, out.t_s)      # after the output: a failed write is the one message
    if note:
        _warnings.warn(note, flags.CompensationWarning, stacklevel=2)
    return out


def metrics(runs, *, taus=None, combiner=None) -> list:
    """The paper's figures of merit of run logs (raw or compensated; paths, RunLogs or columns), as `hdrg
    metrics`: per run a dict (bias stability and instability per averaging time ``taus`` [s],
    default 1, 10, 100; rms [deg/h]; ...: host_tools.fitting.metrics.run_metrics).  ``combiner``:
    the mode-reversal combiner of raw mode-reversal logs (default: the fit's)."""
    from host_tools.fitting.metrics import DEFAULT_TAUS, load, run_metrics
    runs = list(runs) if isinstance(runs, (list, tuple)) else [runs]
    taus = DEFAULT_TAUS if taus is None else tuple(taus)
    return [run_metrics(load(r) if _is_path(r) else _read_run(r), taus=taus, combiner=combiner) for r in runs]


def diagnose(runs, holdout=(), out_dir=None, **options) -> tuple:
    """Trace the residual of the default model (:func:`fit`'s options ``proxy``, ``rate_estimator``,
    ``rate_n``, ``rate_shift``, ``terms``, ``combiner``, ``order``, ``settle_s``, ``proxy_range``,
    ``rate_range``) on the training ``runs`` to a missing effect and add it (host_tools.fitting.diagnose),
    as `hdrg diagnose`; the held-out runs ``holdout`` confirm each step.  ``options`` also: ``max_iter``,
    ``max_tries``, ``n_surrogates``, ``g_min``, ``cv_blocks``, ``cv_folds``, ``seed``, ``plots``,
    ``progress`` (a callable told what is done).  ``out_dir``: write diagnose.md, diagnose.json,
    model.json (and figures) there.  Returns (report dict, final BiasModel)."""
    from host_tools.fitting.diagnose import diagnose as _diagnose
    from host_tools.golden.checks import check_fit_inputs
    runs = list(runs) if isinstance(runs, (list, tuple)) else [runs]
    train = [_read_run(r) for r in runs]
    hold = [_read_run(r) for r in holdout]
    check_fit_inputs(train + hold, options.get("proxy"))
    return _diagnose(train, hold, out_dir=out_dir, **options)


# -- quantize, export -----------------------------------------------------------------------------------

def quantize(model, output=None, *, exchange_s: float = 30.0, dwell_s: float = 120.0, power_on_s: float = 0.0,
             max_error_dph: float | None = None):
    """The fixed-point coefficient table of ``model`` (path or BiasModel), as `hdrg quantize`:
    ``exchange_s``, ``dwell_s``, ``power_on_s`` [s] the sequencer's mode-exchange, mode-1/2 window
    and power-on times; ``max_error_dph``: refuse (QuantizeError) if the bound on |fixed - golden|
    exceeds it [deg/h].  Returns the Quantized result (``.table``: the Table; ``.report``: the
    bound and the measured error; ``.to_json``); ``output``: also write table.json."""
    from host_tools.atomic import refuse_overwrite
    from host_tools.fixed.quantize import quantize as _quantize
    if output is not None:
        refuse_overwrite(output, _paths(model))
    q = _quantize(_read_model(model), exchange_s=exchange_s, dwell_s=dwell_s, power_on_s=power_on_s,
                  max_error_dph=max_error_dph)
    if output is not None:
        q.to_json(output)
    return q


def export(table, out_dir, formats=None, name: str | None = None, info: dict | None = None) -> dict:
    """Write a coefficient table (path: table.json, .bin, .memh; or a Table) into the directory
    ``out_dir``, as `hdrg export`: ``formats`` any of 'c' (C99 header), 'json' (table.json with the
    float originals, from ``info`` or the table.json read), 'mem' ($readmemh words) (default: all);
    ``name`` the file base name and C symbol.  Returns {format: path written}."""
    from host_tools.atomic import refuse_overwrite
    from host_tools.fixed.export import DEFAULT_NAME, EXTENSIONS, FORMATS, check_name, load
    from host_tools.fixed.export import export as _export
    from host_tools.errors import UserError
    formats = FORMATS if formats is None else tuple(formats)
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise UserError(f"export formats {unknown}: not one of {list(FORMATS)}")
    name = DEFAULT_NAME if name is None else name
    check_name(name)
    if _is_path(table):
        refuse_overwrite([_os.path.join(out_dir, name + EXTENSIONS[f]) for f in formats], table)
        table, read_info = load(table)
        info = read_info if info is None else info
    return _export(table, out_dir, formats, name, info)
