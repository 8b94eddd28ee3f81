"""Run-log I/O: the CSV run-log format (shared/formats/run-log.md, version 1) and a lossless NPZ form.

A run log is one power-on of one gyroscope, sampled at a nominally fixed rate.  In memory it is a
:class:`RunLog`: named float64 columns (``mode`` is int64), the ``# key: value`` metadata lines in
order, the file it came from, and the notes of every repair the reader made.

Columns (units): ``t_s`` [s since power-on], ``rate_dph`` [deg/h, raw loop output; ``rate_dps``
in a file is converted on read], ``mode`` [0 FTR, 1 mode 1, 2 mode 2, 3 exchange; default 0],
``freq_hz`` [Hz, drive-mode frequency], ``temp_c`` [degC], ``aux_*`` [any]; the columns hdrg writes
(``bias_dph``, ``valid``, ``flags`` of a compensated log; hdrg capture's ``comp_*``, ``status``,
``state``, ``seq``) are kept as they are.  Any other column in a CSV file is kept too, with a
warning that names it (no tool uses it), and one that differs from a missing format column only in
case, spaces, '_' or '-' (``Mode``, ``Freq Hz``) is an error.

Bad input (each case is tested in tests/test_runlog.py):

* errors (:class:`RunLogError`, message ``FILE:LINE: problem``): empty file, no header, no data
  rows, missing required column, duplicated column name, a row with too many or too few cells
  (except the last line, below), text in a numeric cell, an empty cell, NaN or inf (except in a
  compensated log's ``rate_dph`` / ``bias_dph`` where ``valid`` is 0: empty in CSV, read as NaN,
  BLANK_WHERE_INVALID), a blank line inside the data,
  non-increasing, duplicated or negative ``t_s``, a ``mode`` code that is not 0, 1, 2 or 3, a ``freq_hz``
  that is not positive, metadata that contradicts the data (``reversal: on`` without a ``mode``
  column or with every sample in mode 0, ``reversal: off`` with modes 1/2/3, a
  ``sample_rate_hz`` more than 2 % away from 1 / the median ``t_s`` step, ``exchange_s`` > 0 with
  mode 1 going straight to mode 2 (no mode 3 between), ``mode`` 1 where capture's ``state`` is
  mode 2 or the reverse) - these last checks are made by the readers (:func:`check_metadata`), not
  for logs built in memory;
* warnings (:class:`RunLogWarning`, and the same text in ``RunLog.notes``) with a documented
  repair:

  - **truncated last line** (a last line without its line end, which may be cut inside its last
    number, or with fewer cells than the header): the partial line is discarded, never read as a
    shorter number; the warning names its line number and text and the count of rows kept.
  - **gaps in time** (a step longer than 1.5x the nominal step, the median step): every sample is
    kept; the log is split into contiguous *segments* at the gaps (``RunLog.segments``, start
    indices), so that causal estimators restart at each segment instead of differencing across a
    gap. The warning gives the count, the nominal step and the largest gap with its line.
  - **unfinished capture** (metadata ``capture: in progress``, written by `hdrg capture` until it
    closes the file): the rows are kept; the warning says the capture was interrupted.
  - **first dwell in mode 2** after power-on (the sequencer runs mode 1 first): modes 1 and 2 are
    probably swapped; the rows are kept.

Both readers make the same column checks (runlog_csv.check_columns), conversion (``rate_dps``),
repairs and warnings (:func:`_finish`); a computed column (:meth:`RunLog.with_columns`) with NaN/inf
where the log's own values are finite is refused naming the computation, not a line of the log.

Only regular files are read (a FIFO, a device, a directory: RunLogError before opening).  The CSV
reader streams the file in blocks (host_tools.golden.runlog_csv): its memory is about the final
arrays, its numbers exact (the double nearest each decimal).  The NPZ reader checks every member,
field and type before use.  Writers (:func:`write`, CSV and NPZ) are atomic (host_tools.atomic):
the file appears complete or not at all; the CSV writer escapes control characters in metadata.  The format, with the project's extensions (compensated columns ``bias_dph``,
``valid``, ``flags``, the metadata keys hdrg writes), is docs/RUN_LOG.md.
"""
from __future__ import annotations

import io
import json
import math
import os
import re
import warnings
import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from host_tools.atomic import atomic_open
from host_tools.golden.runlog_csv import (BLANK_WHERE_INVALID, FORMAT_COLUMNS, HDRG_COLUMNS, INT_COLUMNS,  # noqa: F401
                                          RunLogError, RunLogWarning, check_columns, is_compensated_output,
                                          meta_line, open_regular, read_table)

FORMAT_VERSION = 1
MODES = (0, 1, 2, 3)
MODE_FTR, MODE_1, MODE_2, MODE_EXCHANGE = MODES
GAP_FACTOR = 1.5
PROXY_COLUMNS = {"freq": "freq_hz", "temp": "temp_c"}
FS_META_TOLERANCE = 0.02          # metadata sample_rate_hz vs 1 / median t_s step
CAPTURE_KEY, CAPTURE_OPEN, CAPTURE_DONE = "capture", "in progress", "complete"
WRITE_ROWS = 1 << 16              # rows formatted at a time by write_csv (bounds its memory)


@dataclass
class RunLog:
    """One run log in memory.

    ``columns`` maps column name -> 1-D array (float64; ``mode`` int64), all of one length, in file
    order.  ``metadata`` keeps the ``# key: value`` lines in order (free-form ``#`` lines are kept
    under the key ``"#<n>"`` with their text as value).  ``first_data_line`` is the file line of
    row 0 (so row i is line ``first_data_line + i``).  ``segments`` holds the start index of each
    gap-free segment (``segments[0] == 0``).
    """

    columns: dict
    metadata: dict = field(default_factory=dict)
    source: str = "<memory>"
    notes: list = field(default_factory=list)
    first_data_line: int | None = None
    segments: np.ndarray = None

    def __post_init__(self):
        cols = {}
        for name, values in self.columns.items():
            arr = np.asarray(values)
            cols[name] = arr.astype(np.int64) if name in INT_COLUMNS else arr.astype(np.float64)
        if "mode" not in cols and "t_s" in cols:
            cols["mode"] = np.zeros(len(cols["t_s"]), np.int64)
            self._mode_given = False
        self.columns = cols
        _validate(self)
        if self.segments is None:
            self.segments = _find_segments(self, report=False)

    # -- accessors -------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.columns["t_s"])

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    @property
    def t_s(self) -> np.ndarray:
        return self.columns["t_s"]

    @property
    def rate_dph(self) -> np.ndarray:
        return self.columns["rate_dph"]

    @property
    def mode(self) -> np.ndarray:
        return self.columns["mode"]

    @property
    def has_mode_column(self) -> bool:
        """False when the file had no ``mode`` column (the reader filled in 0)."""
        return getattr(self, "_mode_given", True)

    @property
    def reversal(self) -> bool:
        """True when the log uses mode reversal (any sample in mode 1, 2 or 3)."""
        return bool(np.any(self.mode != MODE_FTR))

    @property
    def aux_columns(self) -> list:
        return [c for c in self.columns if c.startswith("aux_")]

    @property
    def nominal_step_s(self) -> float:
        """Nominal sample step [s]: the median time step."""
        if len(self) < 2:
            return float("nan")
        return float(np.median(np.diff(self.t_s)))

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate [Hz]: ``# sample_rate_hz`` metadata if it starts with a number, else 1/median step."""
        m = re.match(r"\s*([0-9.eE+-]+)", self.metadata.get("sample_rate_hz", ""))
        if m:
            try:
                value = float(m.group(1))
                if value > 0 and math.isfinite(value):
                    return value
            except ValueError:
                pass
        return 1.0 / self.nominal_step_s

    def proxy(self, kind: str | None = None) -> tuple[str, np.ndarray]:
        """The temperature proxy: ``kind`` 'freq' (``freq_hz``) or 'temp' (``temp_c``); None picks
        ``freq_hz`` when present (self-sensing), else ``temp_c``.  Returns (column name, values)."""
        if kind is None:
            kind = "freq" if "freq_hz" in self.columns else "temp"
        if kind not in PROXY_COLUMNS:
            raise ValueError(f"proxy must be 'freq' or 'temp', not {kind!r}")
        name = PROXY_COLUMNS[kind]
        if name not in self.columns:
            raise RunLogError(self.source, None, f"proxy '{kind}' needs column '{name}', which the log lacks")
        return name, self.columns[name]

    def line_of(self, row: int) -> int | None:
        """File line number of data row ``row`` (None for a log built in memory)."""
        return None if self.first_data_line is None else self.first_data_line + int(row)

    def select(self, rows) -> "RunLog":
        """A new RunLog with the given rows (boolean mask or index array); metadata copied."""
        cols = {k: v[rows] for k, v in self.columns.items()}
        return RunLog(cols, dict(self.metadata), self.source, list(self.notes))

    def with_columns(self, **new) -> "RunLog":
        """A copy with columns added or replaced (arrays of the same length).  A new column with
        NaN/inf where the log's own columns are finite is refused naming the computation (for a
        compensated log the bias model), never the file's line."""
        cols = dict(self.columns)
        cols.update(new)
        _check_computed(self, new, cols)
        return RunLog(cols, dict(self.metadata), self.source, list(self.notes),
                      self.first_data_line, self.segments)

    @classmethod
    def from_arrays(cls, *args, metadata: dict | None = None, source: str = "<memory>", **columns) -> "RunLog":
        """A RunLog built in memory (validated by :func:`_validate`, not by the readers' metadata checks).

        Columns (1-D, one length; units): ``t_s`` [s since power-on, increasing, required],
        ``rate_dph`` [deg/h, raw loop output, required], ``freq_hz`` [Hz] and/or ``temp_c`` [degC]
        (at least one: the temperature proxy), ``mode`` [0 FTR, 1, 2, 3 exchange; default 0],
        ``aux_*`` [any], and the columns hdrg writes (``bias_dph`` [deg/h], ``valid``, ``flags``).

        The columns are given as keywords (``from_arrays(t_s=t, rate_dph=r, temp_c=T)``) or as one
        mapping, positionally (``from_arrays({"t_s": t, ...})``, recognised by its ``t_s``; keywords
        may add columns to it).  ``metadata`` (key -> text) and ``source`` (a name
        for messages) are keywords, or the positional arguments after the mapping, in that order:
        ``from_arrays(metadata, source, **columns)`` and ``from_arrays(columns, metadata, source)``."""
        rest, given = list(args), {}
        if rest and isinstance(rest[0], Mapping) and "t_s" in rest[0]:
            given = dict(rest.pop(0))
        if len(rest) > 2:
            raise TypeError(f"from_arrays: at most a column mapping, metadata and source positionally, "
                            f"got {len(args)} arguments")
        if rest:
            if metadata is not None:
                raise TypeError("from_arrays: metadata given twice (positionally and as a keyword)")
            metadata = rest.pop(0)
        if rest:
            source = rest.pop(0)
        twice = sorted(set(given) & set(columns))
        if twice:
            raise TypeError(f"from_arrays: column(s) {', '.join(twice)} given twice (in the mapping and as keywords)")
        given.update(columns)
        return cls(given, dict(metadata or {}), source)


def _check_computed(log: RunLog, new: dict, cols: dict) -> None:
    """Refuse (RunLogError without a file line) a column of ``new`` with NaN/inf at a sample where
    it must hold a number (NaN is allowed only in a compensated log's BLANK_WHERE_INVALID column
    where ``valid`` is 0) while the log's own columns are finite there: the value was computed
    (by a bias model, an estimator), so the message names the computation, not the log's line."""
    blank_ok = _is_compensated_output(cols)
    for name, values in new.items():
        arr = np.asarray(values)
        if arr.dtype.kind != "f" or arr.ndim != 1 or len(arr) != len(log):
            continue
        bad = ~np.isfinite(arr)
        if blank_ok and name in BLANK_WHERE_INVALID:
            bad &= ~(np.isnan(arr) & (np.asarray(cols["valid"]) == 0))
        if not bad.any():
            continue
        row = int(np.argmax(bad))
        inputs = [k for k, a in log.columns.items() if a.dtype.kind == "f"
                  and not (k in BLANK_WHERE_INVALID and _is_compensated_output(log.columns))]
        if not all(np.isfinite(log.columns[k][row]) for k in inputs):
            continue                             # a non-finite input: _validate names it
        model = log.metadata.get("compensation_model")
        line = log.line_of(row)
        at = f"row {row}" + (f" (line {line} of the log)" if line is not None else "")
        who = (f"the bias model {model}" if model else
               "the bias model" if "bias_dph" in cols else "the computation that made it")
        raise RunLogError(log.source, None, f"{at}: the computed column '{name}' is {float(arr[row])!r} "
                                            f"({int(bad.sum())} sample(s)) while the log's inputs there are finite: "
                                            f"the fault is in {who} (e.g. coefficients too large), not in the log")


# -- validation shared by the readers and the in-memory constructor ------------------------------

_is_compensated_output = is_compensated_output


def _validate(log: RunLog) -> None:
    src, cols = log.source, log.columns

    def where(row):
        return log.line_of(row) if log.first_data_line is not None else None

    def rowtxt(row):
        return "" if log.first_data_line is not None else f"row {row}: "

    for req in ("t_s",):
        if req not in cols:
            raise RunLogError(src, log.first_data_line and log.first_data_line - 1, f"missing required column '{req}'")
    if "rate_dph" not in cols:
        raise RunLogError(src, log.first_data_line and log.first_data_line - 1,
                          "missing required column 'rate_dph' (or 'rate_dps')")
    if "freq_hz" not in cols and "temp_c" not in cols:
        raise RunLogError(src, log.first_data_line and log.first_data_line - 1,
                          "missing temperature proxy: one of the columns 'freq_hz', 'temp_c' is required")
    n = len(cols["t_s"])
    for name, arr in cols.items():
        if arr.ndim != 1 or len(arr) != n:
            raise RunLogError(src, None, f"column '{name}' has {len(arr)} values, 't_s' has {n}")
    if n == 0:
        raise RunLogError(src, log.first_data_line, "no data rows")
    blank_ok = _is_compensated_output(cols)
    for name, arr in cols.items():
        if arr.dtype.kind == "f":
            bad = ~np.isfinite(arr)
            if blank_ok and name in BLANK_WHERE_INVALID:
                bad &= ~(np.isnan(arr) & (cols["valid"] == 0))   # no number where not valid
                if bad.any():
                    row = int(np.argmax(bad))
                    what = "empty (NaN)" if np.isnan(arr[row]) else str(arr[row])
                    raise RunLogError(src, where(row), f"{rowtxt(row)}column '{name}' is {what} at a valid sample "
                                                       f"(valid 1); only a sample with valid 0 may have no number")
            if bad.any():
                row = int(np.argmax(bad))
                raise RunLogError(src, where(row), f"{rowtxt(row)}column '{name}' is {arr[row]} (NaN/inf is not a value)")
    t = cols["t_s"]
    if t[0] < 0:                        # t_s increases: only the first can be the first negative one
        raise RunLogError(src, where(0), f"{rowtxt(0)}t_s {float(t[0])!r} is negative: t_s is the time since "
                                         f"power-on (shared/formats/run-log.md), never before it")
    if n > 1:
        d = np.diff(t)
        if np.any(d <= 0):
            row = int(np.argmax(d <= 0)) + 1
            kind = "duplicated" if d[row - 1] == 0 else "not increasing"
            raise RunLogError(src, where(row), f"{rowtxt(row)}t_s {kind}: {float(t[row])!r} after {float(t[row - 1])!r}")
    mode = cols["mode"]
    bad = ~np.isin(mode, MODES)
    if bad.any():
        row = int(np.argmax(bad))
        raise RunLogError(src, where(row), f"{rowtxt(row)}unknown mode code {mode[row]} (known: 0 FTR, 1, 2, 3 exchange)")


def _metadata_flag(value) -> bool | None:
    v = str(value).strip().lower()
    return True if v in ("on", "yes", "true", "1") else False if v in ("off", "no", "false", "0") else None


def check_metadata(log: RunLog, header_line: int | None = None) -> None:
    """Refuse a non-positive ``freq_hz`` and metadata or columns that contradict the data
    (RunLogError; see the module doc: ``reversal``, ``sample_rate_hz``, ``exchange_s``, ``state``)
    and warn on an unfinished capture and a first dwell in mode 2.  Called by the readers (files), not for
    logs built in memory (tests and tools may use synthetic columns there)."""
    src = log.source
    if "freq_hz" in log.columns:
        bad = log.columns["freq_hz"] <= 0
        if bad.any():
            row = int(np.argmax(bad))
            line = log.line_of(row)
            raise RunLogError(src, line, f"{'' if line is not None else f'row {row}: '}freq_hz "
                                         f"{float(log.columns['freq_hz'][row])!r} is not a frequency "
                                         f"(the drive-mode frequency must be > 0 Hz)")
    rev = _metadata_flag(log.metadata.get("reversal", ""))
    if rev is True and not log.reversal:
        why = ("there is no 'mode' column" if not log.has_mode_column else "every sample is mode 0 (FTR)")
        raise RunLogError(src, header_line, f"metadata 'reversal: {log.metadata['reversal']}' but {why}: a "
                                            f"renamed or missing mode column would be fitted as FTR; fix the "
                                            f"column name or the metadata")
    if rev is False and log.reversal:
        row = int(np.argmax(log.mode != MODE_FTR))
        raise RunLogError(src, log.line_of(row), f"metadata 'reversal: {log.metadata['reversal']}' but row {row} "
                                                 f"has mode {log.mode[row]}: fix the metadata or the mode column")
    m = re.match(r"\s*([0-9.eE+-]+)", log.metadata.get("sample_rate_hz", ""))
    if m and len(log) >= 2:
        try:
            meta = float(m.group(1))
        except ValueError:
            meta = float("nan")
        data = 1.0 / log.nominal_step_s
        if not (meta > 0 and math.isfinite(meta)) or abs(meta / data - 1.0) > FS_META_TOLERANCE:
            raise RunLogError(src, None, f"metadata 'sample_rate_hz: {log.metadata['sample_rate_hz']}' does not "
                                         f"match t_s (median step {log.nominal_step_s:.6g} s = {data:.6g} Hz); "
                                         f"fix or remove the metadata line")
    _check_exchanges(log)
    _check_state_column(log)
    _check_first_mode(log)
    if str(log.metadata.get(CAPTURE_KEY, "")).strip().lower() == CAPTURE_OPEN:
        msg = (f"{src}: unfinished capture (metadata '{CAPTURE_KEY}: {CAPTURE_OPEN}'): the recording was "
               f"interrupted or is still running; the {len(log)} rows written so far are used")
        _repaired(log, msg, stacklevel=4)


def _metadata_number(value) -> float | None:
    """The number a metadata value starts with (``30``, ``30 s``), or None."""
    m = re.match(r"\s*([0-9.eE+-]+)", str(value))
    try:
        x = float(m.group(1)) if m else float("nan")
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def _where(log: RunLog, row: int) -> tuple:
    """(file line or None, the text naming the row in a message: '' when the line is named)."""
    line = log.line_of(row)
    return line, "" if line is not None else f"row {row}: "


def _check_exchanges(log: RunLog) -> None:
    """Refuse a mode-reversal log whose metadata declares exchanges (``exchange_s`` > 0, at least two
    sample steps) while its mode column goes from mode 1 straight to mode 2 (or back) between two
    samples with no gap between them: the exchange samples (output invalid) would be read as
    mode-1/2 data."""
    ex = _metadata_number(log.metadata.get("exchange_s", ""))
    if not log.reversal or ex is None or ex <= 0 or len(log) < 3 or ex < 2.0 * log.nominal_step_s:
        return
    m = log.mode
    straight = np.isin(m[1:], (MODE_1, MODE_2)) & np.isin(m[:-1], (MODE_1, MODE_2)) & (m[1:] != m[:-1])
    straight &= np.diff(log.t_s) <= GAP_FACTOR * log.nominal_step_s
    if not straight.any():
        return
    row = int(np.argmax(straight)) + 1
    line, rowtxt = _where(log, row)
    none = " and no sample has mode 3" if not np.any(m == MODE_EXCHANGE) else ""
    raise RunLogError(log.source, line, f"{rowtxt}metadata 'exchange_s: {log.metadata['exchange_s']}' declares "
                                        f"{ex:g} s of mode exchange (mode 3) between the modes, but the mode column "
                                        f"goes from mode {m[row - 1]} straight to mode {m[row]} here "
                                        f"({int(straight.sum())} such switch(es){none}): the exchange samples, whose "
                                        f"output is invalid, would be used as mode-1/2 data; write mode 3 during "
                                        f"the exchanges, or fix the metadata")


def _check_state_column(log: RunLog) -> None:
    """Refuse a log with hdrg capture's ``state`` column (the device's sequencer state 0..5,
    firmware_ref.formats.STATE_MODE) whose ``mode`` says 1 where the state is mode 2 or the reverse
    (modes 1 and 2 swapped).  A ``state`` column of other values is not checked."""
    if "state" not in log.columns or not log.has_mode_column:
        return
    from firmware_ref.formats import STATE_MODE, STATE_NAMES
    state = log.columns["state"]
    if not np.all(np.isin(state, np.arange(len(STATE_MODE)))):
        return
    expect = np.asarray(STATE_MODE)[state.astype(np.int64)]
    bad = np.isin(expect, (MODE_1, MODE_2)) & np.isin(log.mode, (MODE_1, MODE_2)) & (expect != log.mode)
    if bad.any():
        row = int(np.argmax(bad))
        line, rowtxt = _where(log, row)
        raise RunLogError(log.source, line, f"{rowtxt}mode {log.mode[row]} but state {int(state[row])} "
                                            f"({STATE_NAMES[int(state[row])]}) is mode {expect[row]} "
                                            f"({int(bad.sum())} samples disagree): the mode column contradicts the "
                                            f"device's sequencer state (modes 1 and 2 swapped?); fix the mode column")


def _check_first_mode(log: RunLog) -> None:
    """Warn when a mode-reversal log recorded from its power-on (first ``t_s`` within 1 s or two
    steps of 0, first sample mode 3) starts its first dwell in mode 2: the sequencer runs power-on,
    exchange, mode 1 first (firmware_ref/FORMATS.md), so modes 1 and 2 are probably swapped."""
    if (not log.reversal or len(log) < 3 or log.mode[0] != MODE_EXCHANGE
            or log.t_s[0] > max(1.0, 2.0 * log.nominal_step_s)):
        return
    dwell = np.flatnonzero(np.isin(log.mode, (MODE_1, MODE_2)))
    if len(dwell) == 0 or log.mode[dwell[0]] != MODE_2:
        return
    row = int(dwell[0])
    line = log.line_of(row)
    msg = (f"{log.source}{f':{line}' if line is not None else ''}: the first dwell after power-on is mode 2 "
           f"(row {row}, t_s {float(log.t_s[row])!r}); the sequencer runs mode 1 first (power-on, exchange, mode 1, "
           f"exchange, mode 2), so modes 1 and 2 are probably swapped: that flips the sign of the combined "
           f"output (true rate and non-reversing bias); fix the mode column if so")
    _repaired(log, msg, stacklevel=5)


def _repaired(log: RunLog, msg: str, stacklevel: int) -> None:
    """Say what the reader repaired or suspects about ``log``: in its notes (which the tools print and
    the reports keep) and as a RunLogWarning at ``stacklevel`` (counted from here)."""
    log.notes.append(msg)
    warnings.warn(msg, RunLogWarning, stacklevel=stacklevel)


def _find_segments(log: RunLog, report: bool) -> np.ndarray:
    t = log.t_s
    if len(t) < 3:
        return np.zeros(1, np.int64)
    d = np.diff(t)
    step = float(np.median(d))
    gaps = np.flatnonzero(d > GAP_FACTOR * step)
    if report and len(gaps):
        big = int(gaps[np.argmax(d[gaps])])
        line = log.line_of(big + 1)
        where = f"line {line}" if line is not None else f"row {big + 1}"
        msg = (f"{log.source}: {len(gaps)} gap(s) in time (nominal step {step:.6g} s); largest "
               f"{d[big]:.6g} s before {where}. Repair: all samples kept; the log is split into "
               f"{len(gaps) + 1} segments at the gaps (RunLog.segments) and causal estimators restart "
               f"at each segment")
        _repaired(log, msg, stacklevel=4)
    return np.concatenate([[0], gaps + 1]).astype(np.int64)


# -- CSV -----------------------------------------------------------------------------------------

def read_csv(path) -> RunLog:
    """Read a CSV run log (docs/RUN_LOG.md).  Raises :class:`RunLogError`; warns
    :class:`RunLogWarning` on repairs.  Only a regular file is read (a FIFO, a device, a directory
    is refused before it is opened for reading); the memory used is the final arrays (8 bytes per
    cell) plus one block of ``runlog_csv.CHUNK_BYTES`` (host_tools.golden.runlog_csv)."""
    source = os.fspath(path)
    with open_regular(source) as fh:
        table = read_table(fh, os.fstat(fh.fileno()).st_size, source)
    return _from_table(table, source)


def parse_csv_text(text: str, source: str = "<text>") -> RunLog:
    """Parse run-log CSV text (see :func:`read_csv`)."""
    data = text.encode("utf-8", "surrogateescape")
    return _from_table(read_table(io.BytesIO(data), len(data), source), source)


def _from_table(table, source: str) -> RunLog:
    """The RunLog of what runlog_csv.read_table read (see :func:`_finish`)."""
    return _finish(table.columns, table.metadata, source, table.notes, table.first_data_line, table.header_line)


def _finish(columns: dict, metadata: dict, source: str, notes: list, first_data_line: int | None = None,
            header_line: int | None = None) -> RunLog:
    """The RunLog of the columns a reader read (CSV or NPZ, after runlog_csv.check_columns):
    ``rate_dps`` converted to ``rate_dph``, ``mode`` defaulted to 0, types made float64 (int64
    for INT_COLUMNS), validated (:func:`_validate`, :func:`check_metadata`), segmented at gaps
    with the gap warning.  The same steps for both formats, so that they accept, warn about and
    refuse the same logs."""
    columns = {k: (np.asarray(v).astype(np.int64, copy=False) if k in INT_COLUMNS
                   else np.asarray(v).astype(np.float64, copy=False)) for k, v in columns.items()}
    if "rate_dps" in columns and "rate_dph" not in columns:
        columns["rate_dph"] = columns.pop("rate_dps") * 3600.0
        notes.append(f"{source}: 'rate_dps' converted to 'rate_dph' (x 3600)")
    log = RunLog.__new__(RunLog)
    log.columns = columns
    if "mode" not in columns and "t_s" in columns:
        columns["mode"] = np.zeros(len(columns["t_s"]), np.int64)
        log._mode_given = False
    log.metadata, log.source, log.notes, log.first_data_line = metadata, source, notes, first_data_line
    _validate(log)
    check_metadata(log, header_line)
    log.segments = _find_segments(log, report=True)
    return log


def _fmt_column(name: str, arr: np.ndarray) -> list:
    """The cells of one column: an integer in decimal, a float in its shortest round-trip form
    (``repr``), NaN (only where a compensated log is not valid) as an empty cell."""
    if arr.dtype.kind in "iu":
        return list(map(str, arr.tolist()))
    if np.isnan(arr).any():
        return [repr(x) if x == x else "" for x in arr.tolist()]
    return list(map(repr, arr.tolist()))


_BAD_NAME = re.compile(r"[,\x00-\x1f\x7f-\x9f\u2028\u2029]|^#|^\s|\s$|^$")


def write_csv(log: RunLog, path, extra_metadata: dict | None = None) -> None:
    """Write ``log`` as a CSV run log: the metadata lines (``extra_metadata`` after the log's own;
    control characters in a key or value escaped, ``:`` in a key written ``_``:
    runlog_csv.meta_line), the header, one row per sample, values in shortest round-trip form (CSV
    -> CSV is lossless).  ``WRITE_ROWS`` rows are formatted at a time, so the memory used is bounded.
    A column name the header cannot hold (a comma, a control character) is refused."""
    meta = dict(log.metadata)
    meta.update(extra_metadata or {})
    names = list(log.columns)
    bad = next((n for n in names if not isinstance(n, str) or _BAD_NAME.search(n)), None)
    if bad is not None:
        raise RunLogError(os.fspath(path), None, f"column name {bad!r} cannot be written to a CSV header")
    arrays = [log.columns[n] for n in names]
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("".join(meta_line(k, v) for k, v in meta.items()) + ",".join(names) + "\n")
        for lo in range(0, len(log), WRITE_ROWS):
            cells = [_fmt_column(n, a[lo:lo + WRITE_ROWS]) for n, a in zip(names, arrays)]
            fh.write("\n".join(map(",".join, zip(*cells))) + "\n")


# -- NPZ (lossless binary) ---------------------------------------------------------------------

def write_npz(log: RunLog, path) -> None:
    """Lossless binary form (numpy ``.npz``, members stored): ``header``, a JSON text (``format``
    ``hdrg-runlog``, ``version``, ``columns``: the names in order, ``metadata``: key -> text,
    ``notes``: texts), and ``col_<i>``, column i bit-exact (float64; int64 for INT_COLUMNS)."""
    header = json.dumps({"format": "hdrg-runlog", "version": FORMAT_VERSION, "columns": list(log.columns),
                         "metadata": {str(k): str(v) for k, v in log.metadata.items()},
                         "notes": [str(n) for n in log.notes]})
    arrays = {f"col_{i}": v for i, v in enumerate(log.columns.values())}
    with atomic_open(path, "wb") as fh:
        np.savez(fh, header=np.array(header), **arrays)


# what a hostile .npz can raise inside zipfile / numpy.lib.format (each becomes a RunLogError)
_NPZ_ERRORS = (zipfile.BadZipFile, zipfile.LargeZipFile, zlib.error, OSError, EOFError, ValueError, KeyError,
               NotImplementedError, RuntimeError, OverflowError, TypeError, SyntaxError)


def _npz_member(zf, info, source: str) -> np.ndarray:
    """The array of one .npy member, after its header (version, dtype, shape) is checked against
    the member's size: a declared shape never allocates more than the member holds."""
    with zf.open(info) as f:
        version = np.lib.format.read_magic(f)
        if version not in ((1, 0), (2, 0)):
            raise RunLogError(source, None, f"member {info.filename!r}: .npy version {version} (hdrg writes 1.0)")
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, _, dtype = read_header(f)
        if dtype.hasobject or dtype.kind not in "biufU" or dtype.fields is not None:
            raise RunLogError(source, None, f"member {info.filename!r}: dtype {dtype} is not numbers or text")
        if math.prod(shape) * dtype.itemsize > info.file_size or min(shape, default=0) < 0:
            raise RunLogError(source, None, f"member {info.filename!r}: shape {shape} does not fit its "
                                            f"{info.file_size} bytes")
    with zf.open(info) as f:
        return np.lib.format.read_array(f, allow_pickle=False)


def _npz_header(doc, source: str) -> tuple[list, dict, list]:
    """(columns, metadata, notes) of an NPZ header, every field's type checked."""
    def bad(problem):
        return RunLogError(source, None, problem)
    if not isinstance(doc, dict) or doc.get("format") != "hdrg-runlog":
        raise bad("not an hdrg run-log NPZ (header 'format' missing)")
    version = doc.get("version")
    if type(version) is not int or not 1 <= version <= FORMAT_VERSION:
        raise bad(f"header field 'version': {version!r} is not a run-log version this hdrg reads "
                  f"(1..{FORMAT_VERSION})")
    names = doc.get("columns")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise bad(f"header field 'columns': must be a non-empty list of column names, not {type(names).__name__}")
    named = next((n for n in names if _BAD_NAME.search(n)), None)
    if named is not None:
        raise bad(f"header field 'columns': {named!r} is not a column name (empty, a comma or a control character)")
    if len(set(names)) != len(names):
        raise bad(f"header field 'columns': a name appears twice in {names}")
    metadata, notes = doc.get("metadata", {}), doc.get("notes", [])
    if not isinstance(metadata, dict) or not all(isinstance(v, str) for v in metadata.values()):
        raise bad("header field 'metadata': must be an object of key: text")
    if not isinstance(notes, list) or not all(isinstance(n, str) for n in notes):
        raise bad("header field 'notes': must be a list of texts")
    return names, metadata, notes


def read_npz(path) -> RunLog:
    """Read an NPZ run log (:func:`write_npz`).  Every structure and type is checked before use:
    a regular file, a zip whose members are .npy arrays (stored or deflated) of sizes they can hold,
    ``header`` one JSON text (bounded, no repeated key) with the fields of :func:`write_npz`,
    ``col_<i>`` 1-D numbers, an integer column (``mode``, ``flags``, ``valid``) integers; then the
    checks of the CSV reader (NaN/inf, t_s, modes, metadata).  Raises :class:`RunLogError`."""
    from host_tools.jsonread import InputFileError, parse_json
    source = os.fspath(path)
    fh = open_regular(source)             # a missing file: the OSError of open(), as for a CSV
    try:
        with fh, zipfile.ZipFile(fh) as zf:
            infos = {info.filename: info for info in zf.infolist()}
            for info in infos.values():
                if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED) or (
                        info.compress_type == zipfile.ZIP_DEFLATED and info.file_size > 1100 * info.compress_size):
                    raise RunLogError(source, None, f"member {info.filename!r}: compression {info.compress_type} "
                                                    f"or size {info.file_size} not of an hdrg NPZ")
            if "header.npy" not in infos:
                raise RunLogError(source, None, "not an hdrg run-log NPZ (no 'header' member)")
            text = _npz_member(zf, infos["header.npy"], source)
            if text.dtype.kind != "U" or text.shape != ():
                raise RunLogError(source, None, f"member 'header': must be one JSON text, not {text.dtype} {text.shape}")
            try:
                names, metadata, notes = _npz_header(parse_json(str(text), source, "NPZ header"), source)
            except InputFileError as exc:
                raise RunLogError(source, None, str(exc).removeprefix(f"{source}: ")) from None
            check_columns(names, source, None, notes, 5)
            cols = {}
            for i, name in enumerate(names):
                if f"col_{i}.npy" not in infos:
                    raise RunLogError(source, None, f"column '{name}': member 'col_{i}' missing")
                arr = _npz_member(zf, infos[f"col_{i}.npy"], source)
                if arr.ndim != 1 or arr.dtype.kind not in "biuf":
                    raise RunLogError(source, None, f"column '{name}': must be 1-D numbers, not {arr.dtype} {arr.shape}")
                if name in INT_COLUMNS and arr.dtype.kind in "uf":
                    bad = ~(np.abs(arr) < 2.0 ** 63) | (arr != np.round(arr))
                    if bad.any():
                        row = int(np.argmax(bad))
                        raise RunLogError(source, None, f"row {row}: {name} {arr[row].item()!r} is not an integer")
                cols[name] = arr
    except RunLogError:
        raise
    except _NPZ_ERRORS as exc:
        raise RunLogError(source, None, f"unreadable NPZ run log: {exc}") from None
    return _finish(cols, metadata, source, notes)


def read(path) -> RunLog:
    """Read a run log by extension: ``.npz`` binary, anything else CSV."""
    return read_npz(path) if os.fspath(path).lower().endswith(".npz") else read_csv(path)


def write(log: RunLog, path, extra_metadata: dict | None = None) -> None:
    """Write a run log by extension: ``.npz`` binary, anything else CSV."""
    if os.fspath(path).lower().endswith(".npz"):
        if extra_metadata:
            log = RunLog(dict(log.columns), {**log.metadata, **extra_metadata}, log.source, list(log.notes))
        write_npz(log, path)
    else:
        write_csv(log, path, extra_metadata)
