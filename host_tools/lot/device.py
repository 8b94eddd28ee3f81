"""One device of a lot: read, check, fit, held-out check, quantize, export, judge (host_tools.lot).

:func:`calibrate` ``(job) -> {"result": dict, "files": {name: bytes}}`` runs in a worker (a
process of the pool, or a Dask worker) and writes nothing: the lot's driver writes the files
(host_tools.lot.engine) and decides which of them to ship.  ``files`` holds every file the device
produced (model.json, table.h, table.json, table.memh, result.json), for a failed device too.
A problem of the device's data (unreadable or corrupt log, a drive frequency the table cannot
hold, a fit or quantization refused, a held-out run outside the model's range) makes the device
fail with its stage and reason; it never raises.  Warnings raised while a device is processed are
kept in its result, never printed.

The stages, in order (:data:`STAGES`): ``read`` the run logs; ``check`` the training runs'
drive frequency against the table's frequency word (a device outside it is refused before its
fit), their duration (spec ``min_train_s``) and repaired logs (spec ``allow_repaired_logs``);
``fit``; ``heldout``: each held-out run compensated and measured; ``quantize`` and ``export`` the
table; ``spec``: the figures against the spec's limits.  A failure stops only what depends on
it: a device whose quantization is refused still has its fit, held-out and residual figures,
and its result lists every spec limit those figures break.

``result.json`` keeps, besides the figures:

* ``failures``: what stopped a stage, ``[{"stage", "reason"}]`` (independent of the spec's
  limits: an unreadable log, the drive frequency, a refused fit or quantization, ...);
* ``reasons``: every reason the device fails, ``"STAGE: text"``, in stage order: the failures
  and the spec violations of its figures (:func:`judge`); ``stage``: the first of them (``done``
  for a device that passes); ``status``: ``pass`` or ``fail``;
* ``drive_freq_hz``: the median ``freq_hz`` of the training run(s) [Hz] (None when they have no
  ``freq_hz``); ``proxy``: the model's proxy kind (``freq`` or ``temp``; before a fit, the one
  the fit would use);
* ``repaired_logs``: the run logs the reader repaired (a truncated last line, gaps in time, an
  unfinished capture), ``log_repairs``: {run: [repair kinds]}.

:func:`judge` re-judges a finished device from these figures alone (no refit), for another spec
that differs only in the keys of :data:`JUDGED_KEYS`.

The fit is :func:`host_tools.fitting.fit_pipeline.fit_default` (what ``hdrg fit RUN...`` does),
with the refusals of ``hdrg fit`` (no degrees of freedom, fewer than MIN_SAMPLES_PER_TERM valid
samples per coefficient); the held-out figures come from host_tools.golden.compensate and
host_tools.fitting.metrics; the table from host_tools.fixed.quantize and host_tools.fixed.export.
"""
from __future__ import annotations

import json
import math
import threading
import warnings

import numpy as np

from firmware_ref import formats as F
from firmware_ref.vocabulary import FLAG_PROXY_CLAMPED, FLAG_RATE_CLAMPED

# name of each output file in a device's folder -> what it is
OUTPUTS = {"model.json": "the bias model (hdrg fit's model.json)",
           "table.h": "C99 header of the coefficient table (hdrg export --format c)",
           "table.json": "table.json with the float originals and the quantizer's report (hdrg export --format json)",
           "table.memh": "$readmemh words (hdrg export --format mem)",
           "result.json": "the device's figures, pass/fail and reasons"}
TABLE_SYMBOL = "hdrg_table"     # C symbol of every device's table (the firmware loads the same name)
STAGES = ("read", "check", "fit", "heldout", "quantize", "export", "spec")
# the spec keys :func:`judge` reads: a spec that differs from the calibration's only in these
# keys is judged from result.json without a refit (the others change the figures themselves)
JUDGED_KEYS = ("heldout_stability_max_dph", "residual_rms_max_dph", "coverage_min", "valid_share_min",
               "fixed_error_max_dph", "min_train_s", "require_heldout", "allow_repaired_logs")
# the run-log reader's repairs (host_tools.golden.runlog, module doc): text of its note -> kind
REPAIRS = (("truncated last line", "truncated last line"), ("gap(s) in time", "gaps in time"),
           ("unfinished capture", "unfinished capture"))

# Devices run one at a time per process: the warning capture (warnings.catch_warnings) is
# process-wide, so a Dask worker with several threads must not interleave two devices.
_LOCK = threading.Lock()


class DeviceFailure(Exception):
    """A device cannot go on: ``stage`` (one of STAGES) and the reason (the message)."""

    def __init__(self, stage: str, reason: str):
        super().__init__(reason)
        self.stage = stage


def num(x):
    """A JSON-safe float (None for None, NaN, inf)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _read(runs, names):
    from host_tools.golden import runlog

    logs = []
    for run in runs:
        try:
            log = runlog.read(run.path)
        except FileNotFoundError:
            raise DeviceFailure("read", f"{run.name}: no such file") from None
        except MemoryError:
            raise
        except Exception as exc:       # whatever the reader meets in a damaged file is the file's problem
            raise DeviceFailure("read", f"{run.name}: {_message(exc, names)}") from None
        log.source = run.name
        logs.append(log)
    return logs


def _message(exc: BaseException, names: dict) -> str:
    """The error text with the runs' paths replaced by their manifest names."""
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.strerror and exc.filename:
        text = f"{exc.filename}: {exc.strerror}"
    for path, name in names.items():
        text = text.replace(path, name)
    return text


def _duration_s(log) -> float:
    t = np.asarray(log.t_s, np.float64)
    if len(t) < 2:
        return 0.0
    return float(t[-1] - t[0] + np.median(np.diff(t)))


def _fit(logs):
    from host_tools.fitting.fit import MIN_SAMPLES_PER_TERM
    from host_tools.fitting.fit_pipeline import fit_default
    from host_tools.golden.checks import check_fit_inputs

    try:
        check_fit_inputs(logs, None)
        model, res = fit_default(logs)
    except (ValueError, LookupError, ArithmeticError, np.linalg.LinAlgError) as exc:
        raise DeviceFailure("fit", str(exc)) from None
    if res.dof <= 0 or not np.all(np.isfinite(res.stderr)):
        raise DeviceFailure("fit", f"{res.n} valid samples for {len(res.terms)} coefficients: no degrees of "
                                   f"freedom left (record a longer training run)")
    if res.n < MIN_SAMPLES_PER_TERM * len(res.terms):
        raise DeviceFailure("fit", f"{res.n} valid samples for {len(res.terms)} coefficients, fewer than "
                                   f"{MIN_SAMPLES_PER_TERM} per coefficient (record a longer training run)")
    model.source = "model.json"
    return model, res


def heldout_figures(log, model, mark, tau_s: float) -> dict:
    """The figures of one held-out run: compensated with ``model`` (float golden model), counted
    from the power-on mark ``mark`` [s] (None: the first sample): the stability (std of the
    ``tau_s`` means), the valid share, and the shares of non-exchange samples inside the model's
    proxy and rate ranges (not clamped)."""
    from host_tools.fitting.metrics import at_tau, bias_metrics, output_of
    from host_tools.golden.compensate import compensate
    from host_tools.golden.flags import problems
    from host_tools.golden.runlog import MODE_EXCHANGE

    try:
        out = compensate(log, model)
    except (ValueError, LookupError, ArithmeticError) as exc:
        raise DeviceFailure("heldout", f"{log.source}: {exc}") from None
    t = np.asarray(out.t_s, np.float64)
    on = t >= (t[0] if mark is None else mark)
    if not on.any():
        raise DeviceFailure("heldout", f"{log.source}: power-on mark {mark:g} s is after the run's last sample "
                                       f"({t[-1]:g} s)")
    _, out_dph, valid, _ = output_of(out)
    row = at_tau(bias_metrics(out_dph, t, valid & on, (tau_s,)), tau_s)
    flags = np.asarray(out["flags"], np.int64)
    meet = on & (np.asarray(out.mode) != MODE_EXCHANGE)
    n_meet = max(int(np.count_nonzero(meet)), 1)
    return {"run": log.source, "samples": int(np.count_nonzero(on)),
            "power_on_s": num(t[0] if mark is None else mark),
            "stability_dph": num(row["stability_dph"]), "stability_note": row["reason"],
            "valid_share": float(np.count_nonzero(valid & on) / np.count_nonzero(on)),
            "proxy_coverage": float(1.0 - np.count_nonzero(meet & ((flags & FLAG_PROXY_CLAMPED) != 0)) / n_meet),
            "rate_coverage": float(1.0 - np.count_nonzero(meet & ((flags & FLAG_RATE_CLAMPED) != 0)) / n_meet),
            "problems": problems(out)}


def _worst(rows, key, pick):
    vals = [r[key] for r in rows if r[key] is not None]
    return pick(vals) if vals else None


def _fmt_s(seconds: float) -> str:
    """A duration [s] as whole seconds, with h:mm:ss from one hour on."""
    sec = int(round(seconds))
    if sec < 3600:
        return f"{sec} s"
    return f"{sec} s ({sec // 3600}:{sec % 3600 // 60:02d}:{sec % 60:02d})"


def spec_violations(r: dict, spec: dict) -> list:
    """The spec limits (keys :data:`JUDGED_KEYS`) that the figures of result ``r`` break, as
    ``[(stage, text)]`` (empty: none).  A figure that is missing (its stage failed, and that
    failure is the device's reason) is not judged."""
    why = []
    lim = spec.get("min_train_s")
    if lim is not None and r.get("train_s") is not None and r["train_s"] < lim:
        why.append(("check", f"too short: the training run(s) cover {_fmt_s(r['train_s'])}, the spec needs "
                             f">= {_fmt_s(lim)} (min_train_s)"))
    repaired = r.get("repaired_logs") or []
    if repaired and not spec.get("allow_repaired_logs", False):
        kinds = r.get("log_repairs") or {}
        names = ", ".join(f"{n} ({', '.join(kinds[n])})" if kinds.get(n) else n for n in repaired)
        why.append(("check", f"repaired run log(s): {names}; the reader kept what it could read "
                             f"(allow_repaired_logs: false)"))
    tau = r.get("stability_tau_s") or spec.get("stability_tau_s")
    rows = r.get("heldout") or []
    if not r.get("holdout_runs") and not rows:
        if spec.get("require_heldout"):
            why.append(("spec", "no held-out run (the spec requires one: require_heldout)"))
    elif rows:
        lim = spec.get("heldout_stability_max_dph")
        stab = r.get("heldout_stability_dph")
        if lim is not None:
            if stab is None:
                notes = "; ".join(h["stability_note"] for h in rows if h.get("stability_note"))
                why.append(("spec", f"held-out stability ({tau:g}-s means) not measurable: {notes or 'no value'}"))
            elif stab > lim:
                why.append(("spec", f"held-out stability {stab:.4g} deg/h ({tau:g}-s means) > {lim:g} deg/h "
                                    f"(heldout_stability_max_dph)"))
        lim = spec.get("valid_share_min")
        if lim is not None and r.get("valid_share") is not None and r["valid_share"] < lim:
            why.append(("spec", f"valid share from power-on {r['valid_share']:.1%} < {lim:.1%} (valid_share_min)"))
        lim = spec.get("coverage_min")
        for what in ("proxy", "rate"):
            cov = r.get(f"{what}_coverage")
            if lim is not None and cov is not None and cov < lim:
                why.append(("spec", f"{what} coverage {cov:.1%} of the held-out samples inside the model's {what} "
                                    f"range < {lim:.1%} (coverage_min): the device meets inputs outside its "
                                    f"training range"))
    lim = spec.get("residual_rms_max_dph")
    if lim is not None and r.get("residual_rms_dph") is not None and r["residual_rms_dph"] > lim:
        why.append(("spec", f"training residual rms {r['residual_rms_dph']:.4g} deg/h > {lim:g} deg/h "
                            f"(residual_rms_max_dph)"))
    lim = spec.get("fixed_error_max_dph")
    if lim is not None and r.get("fixed_bound_dph") is not None and r["fixed_bound_dph"] > lim:
        why.append(("spec", f"|fixed - golden| bound {r['fixed_bound_dph']:.3g} deg/h > {lim:g} deg/h "
                            f"(fixed_error_max_dph)"))
    return why


def _stage_rank(stage: str) -> int:
    """Order of the stages in a device's reasons: a broken pipeline (``memory``, ``internal``,
    ``worker``: not a stage of STAGES) first, then STAGES in order."""
    return STAGES.index(stage) + 1 if stage in STAGES else 0


def failures_of(result: dict) -> list:
    """The failures of ``result`` that do not depend on the spec's limits, ``[{"stage", "reason"}]``;
    for a result.json written before ``failures`` existed: its reasons unless its stage is
    ``spec`` (those are judged again)."""
    if "failures" in result:
        return list(result["failures"] or [])
    stage = result.get("stage")
    if stage in (None, "done", "spec"):
        return []
    return [{"stage": stage, "reason": text} for text in result.get("reasons") or []]


def judge(result: dict, spec: dict) -> tuple:
    """Judge a finished device from its result.json figures alone (no refit): its ``failures``
    (which no spec changes) and the limits of ``spec`` (keys :data:`JUDGED_KEYS`) its figures
    break.  Returns ``(status, stage, reasons)``: ``"pass"``, ``"done"``, ``[]``, or ``"fail"``,
    the first failing stage and every reason as ``"STAGE: text"`` in stage order."""
    found = [(f["stage"], f["reason"]) for f in failures_of(result)] + spec_violations(result, spec)
    if not found:
        return "pass", "done", []
    found.sort(key=lambda sr: _stage_rank(sr[0]))      # stable: the order within a stage is kept
    return "fail", found[0][0], [f"{stage}: {text}" for stage, text in found]


def _export(device_id: str, model, spec: dict) -> tuple:
    from host_tools.fixed.export import c_header, json_dict
    from host_tools.fixed.quantize import QuantizeError, quantize
    from firmware_ref.table import TableError

    try:
        q = quantize(model, exchange_s=spec["exchange_s"], dwell_s=spec["dwell_s"], power_on_s=spec["power_on_s"])
    except (QuantizeError, TableError, ValueError) as exc:
        raise DeviceFailure("quantize", str(exc)) from None
    t = q.table
    crc = f"0x{t.crc:08x}"
    stamp = f"device {device_id}, table CRC-32 {crc}"
    head = c_header(t, TABLE_SYMBOL, q.to_dict())
    anchor = "#include <stdint.h>\n"
    if anchor not in head:      # pragma: no cover - the exporter's layout changed
        raise RuntimeError("the C header has no '#include <stdint.h>' line to put the device id after")
    sym = TABLE_SYMBOL.upper()
    head = (f"/* hdrg lot: {stamp}. */\n"
            + head.replace(anchor, f"{anchor}\n#define {sym}_DEVICE_ID \"{device_id}\"\n", 1))
    info = {**q.to_dict(), "device_id": device_id}
    table_json = json_dict(t, info)
    table_json["exported_by"] = "hdrg lot"
    files = {"table.h": head.encode("utf-8"),
             "table.json": _json_bytes(table_json),
             "table.memh": (f"// hdrg lot: {stamp}\n" + t.to_memh()).encode("utf-8")}
    b, m = q.report["bound_dph"], q.report["measured_dph"]
    figures = {"crc32": crc, "table_words": len(t.to_words()), "fixed_bound_dph": num(b["out"]),
               "fixed_measured_dph": num(max(m["corners"], m["random"])), "quantize_warnings": list(q.report["warnings"])}
    return files, figures


def _json_bytes(d: dict) -> bytes:
    return (json.dumps(d, indent=2, allow_nan=False) + "\n").encode("utf-8")


def freq_word_max_hz() -> float:
    """The largest drive frequency [Hz] the table's frequency word holds: uint32 with
    ``formats.FREQ_FRAC`` fractional bits, (2^32 - 1) 2^-FREQ_FRAC (just under 2^(32 - FREQ_FRAC))."""
    return F.UINT32_MAX * 2.0 ** -F.FREQ_FRAC


def _drive(train: list) -> tuple:
    """(median ``freq_hz`` of the training runs [Hz] or None, the proxy kind the fit will use:
    'freq' when every training run has ``freq_hz``, else 'temp')."""
    have = [np.asarray(log.columns["freq_hz"], np.float64) for log in train if "freq_hz" in log.columns]
    median = float(np.median(np.concatenate(have))) if have else None
    return median, ("freq" if len(have) == len(train) else "temp")


def _check_freq(train: list) -> str | None:
    """Why the table cannot hold the training runs' drive frequency (None: it can)."""
    top = freq_word_max_hz()
    for log in train:
        f = np.asarray(log.columns["freq_hz"], np.float64)
        if f.size and float(f.max()) > top:
            return (f"{log.source}: drive frequency {float(np.median(f)):.0f} Hz (median; max {float(f.max()):.0f} Hz) "
                    f"is outside the table's drive-frequency word, 0 .. {2.0 ** (32 - F.FREQ_FRAC):g} Hz (uint32, "
                    f"FREQ_FRAC = {F.FREQ_FRAC} fractional bits): the table cannot hold this device's proxy; "
                    f"not fitted")
    return None


def _repairs(logs: list) -> dict:
    """{run name: [repair kinds]} of the logs whose reader notes report a repair (REPAIRS)."""
    out = {}
    for log in logs:
        kinds = [kind for needle, kind in REPAIRS if any(needle in note for note in log.notes)]
        if kinds:
            out[log.source] = kinds
    return out


def _process(job: dict, result: dict, files: dict) -> None:
    """Run the stages of one device into ``result`` and ``files``; a stage that fails appends to
    ``result["failures"]`` and stops only the stages that need its output."""
    dev, spec = job["device"], job["spec"]
    names = {r.path: r.name for r in dev.train + dev.holdout}
    failures = result["failures"]

    def fail(exc: DeviceFailure) -> None:
        failures.append({"stage": exc.stage, "reason": _message(exc, names)})

    train, holdout = [], []
    for run in dev.train:
        try:
            train += _read([run], names)
        except DeviceFailure as exc:
            fail(exc)
    for run, mark in zip(dev.holdout, dev.power_on_s):
        try:
            holdout += [(log, mark) for log in _read([run], names)]
        except DeviceFailure as exc:
            fail(exc)
    log_repairs = _repairs(train + [log for log, _ in holdout])
    result["log_repairs"] = log_repairs
    result["repaired_logs"] = [r.name for r in dev.train + dev.holdout if r.name in log_repairs]
    if len(train) < len(dev.train):
        return                                      # nothing to fit without every training run
    result["train_s"] = sum(_duration_s(log) for log in train)
    result["train_samples"] = sum(len(log) for log in train)
    result["drive_freq_hz"], result["proxy"] = _drive(train)
    if result["proxy"] == "freq":
        why = _check_freq(train)
        if why:
            fail(DeviceFailure("check", why))
            return
    model, res = _fit(train)
    files["model.json"] = _json_bytes(model.to_dict())
    result.update({"proxy": model.config.proxy.kind, "terms": ",".join(f"k{k}" for k in res.terms),
                   "residual_rms_dph": num(res.rms), "cv_rms_dph": num(res.cv["cv_rms"]) if res.cv else None,
                   "fit_samples": int(res.n)})
    rows = []
    for log, mark in holdout:
        try:
            rows.append(heldout_figures(log, model, mark, spec["stability_tau_s"]))
        except DeviceFailure as exc:
            fail(exc)
    result["heldout"] = rows
    result["heldout_stability_dph"] = _worst(rows, "stability_dph", max) if all(
        r["stability_dph"] is not None for r in rows) else None
    for key in ("valid_share", "proxy_coverage", "rate_coverage"):
        result[key] = _worst(rows, key, min)
    try:
        tables, figures = _export(dev.id, model, spec)
    except DeviceFailure as exc:
        fail(exc)
        return
    files.update(tables)
    result.update(figures)


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def calibrate(job: dict) -> dict:
    """The outputs of one device (module doc): ``{"result": dict, "files": {name: bytes}}``, every
    file produced (a failed device's too; the driver decides what to ship).  ``job``: {"device":
    Device, "spec": dict, "input_hash": str}.  ``result["retry"]`` is True when the failure may
    not repeat (out of memory): the driver then writes no done-marker, so the next run tries the
    device again."""
    dev, spec = job["device"], job["spec"]
    result = {"device": dev.id, "status": "fail", "stage": None, "reasons": [], "failures": [],
              "input_hash": job["input_hash"], "train": [r.name for r in dev.train],
              "holdout_runs": [r.name for r in dev.holdout], "repaired_logs": [], "log_repairs": {},
              "train_s": None, "train_samples": None, "drive_freq_hz": None, "proxy": None, "terms": None,
              "residual_rms_dph": None, "cv_rms_dph": None, "fit_samples": None,
              "stability_tau_s": spec["stability_tau_s"], "heldout": [], "heldout_stability_dph": None,
              "valid_share": None, "proxy_coverage": None, "rate_coverage": None, "crc32": None,
              "table_words": None, "fixed_bound_dph": None, "fixed_measured_dph": None, "quantize_warnings": [],
              "warnings": [], "retry": False}
    files = {}
    names = {r.path: r.name for r in dev.train + dev.holdout}
    with _LOCK, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            _process(job, result, files)
        except DeviceFailure as exc:
            result["failures"].append({"stage": exc.stage, "reason": _message(exc, names)})
        except MemoryError:
            result["failures"].append({"stage": "memory",
                                       "reason": "out of memory (no done-marker: the next run tries again)"})
            result["retry"] = True
        except Exception as exc:        # a device never stops the lot: an unexpected error is its reason
            result["failures"].append({"stage": "internal", "reason": "unexpected " + _message(
                RuntimeError(_error_text(exc)), names)})
        msgs = []
        for w in caught:
            text = _message(Warning(str(w.message)), names)
            if text not in msgs:
                msgs.append(text)
        result["warnings"] = msgs
    result["status"], result["stage"], result["reasons"] = judge(result, spec)
    files["result.json"] = _json_bytes(result)
    return {"result": result, "files": files}
