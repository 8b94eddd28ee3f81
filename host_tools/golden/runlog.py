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
  non-increasing or duplicated ``t_s``, a ``mode`` code that is not 0, 1, 2 or 3, a ``freq_hz``
  that is not positive, metadata that contradicts the data (``reversal: on`` without a ``mode``
  column or with every sample in mode 0, ``reversal: off`` with modes 1/2/3, a
  ``sample_rate_hz`` more than 2 % away from 1 / the median ``t_s`` step) - these last checks are
  made by the readers (:func:`check_metadata`), not for logs built in memory;
* warnings (:class:`RunLogWarning`, and the same text in ``RunLog.notes``) with a documented
  repair:

  - **truncated last line** (fewer cells than the header, or a cell that does not parse, on the
    final line of a file that does not end with a newline): the partial line is discarded; the
    warning names its line number and text.
  - **gaps in time** (a step longer than 1.5x the nominal step, the median step): every sample is
    kept; the log is split into contiguous *segments* at the gaps (``RunLog.segments``, start
    indices), so that causal estimators restart at each segment instead of differencing across a
    gap. The warning gives the count, the nominal step and the largest gap with its line.
  - **unfinished capture** (metadata ``capture: in progress``, written by `hdrg capture` until it
    closes the file): the rows are kept; the warning says the capture was interrupted.

Writers (:func:`write`, CSV and NPZ) are atomic (host_tools.atomic): the file appears complete
or not at all.  The format, with the project's extensions (compensated columns ``bias_dph``,
``valid``, ``flags``, the metadata keys hdrg writes), is docs/RUN_LOG.md.
"""
from __future__ import annotations

import io
import json
import math
import os
import re
import warnings
from dataclasses import dataclass, field

import numpy as np

from host_tools.atomic import atomic_open
from host_tools.errors import HdrgError

FORMAT_VERSION = 1
MODES = (0, 1, 2, 3)
MODE_FTR, MODE_1, MODE_2, MODE_EXCHANGE = MODES
GAP_FACTOR = 1.5
PROXY_COLUMNS = {"freq": "freq_hz", "temp": "temp_c"}
INT_COLUMNS = ("mode", "flags", "valid")   # integer columns (flags, valid: compensated logs, docs/RUN_LOG.md)
# a compensated log (it has the columns 'valid' and 'bias_dph') carries no number in these columns
# where valid is 0: NaN in memory and NPZ, an empty cell in CSV (docs/RUN_LOG.md)
BLANK_WHERE_INVALID = ("rate_dph", "bias_dph")
FS_META_TOLERANCE = 0.02          # metadata sample_rate_hz vs 1 / median t_s step
FORMAT_COLUMNS = ("t_s", "rate_dph", "rate_dps", "mode", "freq_hz", "temp_c")   # shared/formats/run-log.md
# columns hdrg itself writes (docs/RUN_LOG.md): a compensated log, and hdrg capture's device outputs
HDRG_COLUMNS = ("bias_dph", "valid", "flags", "comp_rate_dph", "comp_bias_dph", "comp_valid", "status", "state", "seq")
CAPTURE_KEY, CAPTURE_OPEN, CAPTURE_DONE = "capture", "in progress", "complete"


class RunLogError(HdrgError, ValueError):
    """A run log that cannot be read: names the file, the line (1-based, physical) and the problem."""

    def __init__(self, source: str, line: int | None, problem: str):
        self.source, self.line, self.problem = source, line, problem
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {problem}")


class RunLogWarning(UserWarning):
    """A repair the reader made (truncated last line dropped, gaps found); the text says which."""


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
        """A copy with columns added or replaced (arrays of the same length)."""
        cols = dict(self.columns)
        cols.update(new)
        return RunLog(cols, dict(self.metadata), self.source, list(self.notes),
                      self.first_data_line, self.segments)

    @classmethod
    def from_arrays(cls, metadata: dict | None = None, source: str = "<memory>", **columns) -> "RunLog":
        return cls(dict(columns), dict(metadata or {}), source)


# -- validation shared by the readers and the in-memory constructor ------------------------------

def _is_compensated_output(columns) -> bool:
    """The columns are `hdrg compensate`'s output (``valid`` and ``bias_dph``): BLANK_WHERE_INVALID
    may be NaN (CSV: empty) where valid is 0."""
    return "valid" in columns and "bias_dph" in columns


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
    """Refuse a non-positive ``freq_hz`` and metadata that contradicts the data (RunLogError; see
    the module doc) and warn on an unfinished capture.  Called by the readers (files), not for
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
    if m and len(log) > 2:
        try:
            meta = float(m.group(1))
        except ValueError:
            meta = float("nan")
        data = 1.0 / log.nominal_step_s
        if not (meta > 0 and math.isfinite(meta)) or abs(meta / data - 1.0) > FS_META_TOLERANCE:
            raise RunLogError(src, None, f"metadata 'sample_rate_hz: {log.metadata['sample_rate_hz']}' does not "
                                         f"match t_s (median step {log.nominal_step_s:.6g} s = {data:.6g} Hz); "
                                         f"fix or remove the metadata line")
    if str(log.metadata.get(CAPTURE_KEY, "")).strip().lower() == CAPTURE_OPEN:
        msg = (f"{src}: unfinished capture (metadata '{CAPTURE_KEY}: {CAPTURE_OPEN}'): the recording was "
               f"interrupted or is still running; the {len(log)} rows written so far are used")
        log.notes.append(msg)
        warnings.warn(msg, RunLogWarning, stacklevel=3)


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
        msg = (f"{log.source}: {len(gaps)} gap(s) in time (nominal step {step:.6g} s); largest "
               f"{d[big]:.6g} s before line {line}. Repair: all samples kept; the log is split into "
               f"{len(gaps) + 1} segments at the gaps (RunLog.segments) and causal estimators restart "
               f"at each segment")
        log.notes.append(msg)
        warnings.warn(msg, RunLogWarning, stacklevel=3)
    return np.concatenate([[0], gaps + 1]).astype(np.int64)


# -- CSV -----------------------------------------------------------------------------------------

def _parse_metadata_line(text: str, index: int, metadata: dict) -> None:
    body = text[1:].strip()
    if ":" in body:
        key, value = body.split(":", 1)
        metadata[key.strip()] = value.strip()
    elif body:
        metadata[f"#{index}"] = body


def read_csv(path) -> RunLog:
    """Read a CSV run log.  Raises :class:`RunLogError`; warns :class:`RunLogWarning` on repairs."""
    source = os.fspath(path)
    try:
        with open(source, "r", encoding="utf-8-sig", newline="") as fh:   # -sig: a leading BOM (Excel) is not data
            text = fh.read()
    except UnicodeDecodeError as exc:
        raise RunLogError(source, None, f"not a text file (UTF-8 decoding failed at byte {exc.start})") from None
    return parse_csv_text(text, source)


def _squash(name: str) -> str:
    return re.sub(r"[\s_\-]", "", name.lower())


def _unknown_columns(names) -> list:
    """The header columns that are neither in the format, nor ``aux_*``, nor one hdrg writes."""
    return [c for c in names if c not in FORMAT_COLUMNS and c not in HDRG_COLUMNS and not c.startswith("aux_")]


def _check_near_miss_columns(names, source: str, header_line: int) -> None:
    """Refuse a header column that is not a format column but equals one the header lacks once case,
    spaces, '_' and '-' are ignored (``Mode`` or ``MODE`` for ``mode``, ``Freq Hz`` for ``freq_hz``):
    names are matched exactly, so the log would be read without it (a mode-reversal log as FTR, a
    frequency proxy replaced by temp_c).  ``rate_dph`` and ``rate_dps`` stand for each other."""
    present = {_squash(c) for c in names if c in FORMAT_COLUMNS}
    if "ratedph" in present or "ratedps" in present:
        present |= {"ratedph", "ratedps"}
    for c in _unknown_columns(names):
        near = next((k for k in FORMAT_COLUMNS if _squash(k) == _squash(c) and _squash(k) not in present), None)
        if near is not None:
            raise RunLogError(source, header_line, f"column '{c}' is not '{near}' (column names are matched "
                                                   f"exactly, shared/formats/run-log.md): as it stands the log would "
                                                   f"be read without '{near}'; rename the column")


def _warn_unknown_columns(names, source: str, header_line: int, notes: list) -> None:
    """Warn about (and note) every header column that is neither in the format, nor ``aux_*``, nor one
    hdrg writes: it is kept in the log and used by no tool."""
    unknown = _unknown_columns(names)
    if unknown:
        names_text = ", ".join(f"'{c}'" for c in unknown)
        msg = (f"{source}:{header_line}: column(s) {names_text} not in the run-log format (t_s, rate_dph or "
               f"rate_dps, mode, freq_hz, temp_c, aux_*): kept in the log but used by no tool; rename a logged "
               f"channel to aux_<name> to offer it to the fit and the loop")
        notes.append(msg)
        warnings.warn(msg, RunLogWarning, stacklevel=5)


def parse_csv_text(text: str, source: str = "<text>") -> RunLog:
    """Parse run-log CSV text (see :func:`read_csv`)."""
    if not text.strip():
        raise RunLogError(source, 1, "empty file (no header, no data)")
    ends_with_newline = text.endswith("\n") or text.endswith("\r")
    lines = text.splitlines()
    metadata, notes = {}, []
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        if lines[i].startswith("#"):
            _parse_metadata_line(lines[i], i + 1, metadata)
        i += 1
    if i >= len(lines):
        raise RunLogError(source, len(lines), "no header row (only metadata lines)")
    header_line = i + 1
    names = [c.strip() for c in lines[i].split(",")]
    if any(not c for c in names):
        raise RunLogError(source, header_line, f"empty column name in header {lines[i]!r}")
    seen = set()
    for c in names:
        if c in seen:
            raise RunLogError(source, header_line, f"column '{c}' appears twice in the header")
        seen.add(c)
    _check_near_miss_columns(names, source, header_line)
    for req, alt in (("t_s", None), ("rate_dph", "rate_dps")):
        if req not in names and (alt is None or alt not in names):
            need = f"'{req}'" + (f" (or '{alt}')" if alt else "")
            raise RunLogError(source, header_line, f"missing required column {need}; header has {names}")
    if "freq_hz" not in names and "temp_c" not in names:
        raise RunLogError(source, header_line,
                          f"missing temperature proxy: one of the columns 'freq_hz', 'temp_c' is required; header has {names}")
    _warn_unknown_columns(names, source, header_line, notes)
    data = lines[i + 1:]
    while data and not data[-1].strip():  # trailing blank lines are harmless
        data.pop()
    first_data_line = header_line + 1
    if not data:
        raise RunLogError(source, first_data_line, "no data rows after the header")

    ncol = len(names)
    # the compensated output's rate_dph / bias_dph: an empty cell (a sample with valid 0) is NaN
    blank_cols = [k for k, name in enumerate(names) if name in BLANK_WHERE_INVALID] if _is_compensated_output(names) else []

    def check_last():
        # a truncated final line: fewer cells, or a cell that does not parse, and no final newline
        last = data[-1]
        cells = last.split(",")
        broken = len(cells) < ncol
        if not broken and len(cells) == ncol:
            try:
                [_float_or_blank(c) if k in blank_cols else float(c) for k, c in enumerate(cells)]
            except ValueError:
                broken = not ends_with_newline
        if broken and (not ends_with_newline or len(cells) < ncol):
            line = first_data_line + len(data) - 1
            msg = (f"{source}:{line}: truncated last line {last!r} ({len(cells)} of {ncol} cells); "
                   f"repair: the partial line is discarded, the {len(data) - 1} complete rows are kept")
            notes.append(msg)
            warnings.warn(msg, RunLogWarning, stacklevel=4)
            data.pop()

    check_last()
    if not data:
        raise RunLogError(source, first_data_line, "no complete data rows after the header")
    blank = next((r for r, line in enumerate(data) if not line.strip()), None)
    if blank is not None:  # np.loadtxt would skip it silently
        raise RunLogError(source, first_data_line + blank, "blank line inside the data")
    try:
        table = np.loadtxt(io.StringIO("\n".join(data)), delimiter=",", dtype=np.float64, ndmin=2,
                           comments=None, converters={k: _float_or_blank for k in blank_cols} or None)
        if table.shape[1] != ncol:
            raise ValueError("column count")
    except ValueError:
        _locate_bad_row(data, names, source, first_data_line, blank_cols)
        raise  # _locate_bad_row always raises; kept for safety
    columns = {}
    for k, name in enumerate(names):
        col = table[:, k]
        if name in INT_COLUMNS:
            bad = (col != np.round(col)) | ~np.isfinite(col)
            if bad.any():
                row = int(np.argmax(bad))
                raise RunLogError(source, first_data_line + row, f"{name} {data[row].split(',')[k]!r} is not an integer")
            col = col.astype(np.int64)
        columns[name] = col
    if "rate_dps" in columns and "rate_dph" not in columns:
        columns["rate_dph"] = columns.pop("rate_dps") * 3600.0
        notes.append(f"{source}: 'rate_dps' converted to 'rate_dph' (x 3600)")
    log = RunLog.__new__(RunLog)
    log.columns = {k: v for k, v in columns.items()}
    if "mode" not in log.columns:
        log.columns["mode"] = np.zeros(len(table), np.int64)
        log._mode_given = False
    log.metadata, log.source, log.notes, log.first_data_line = metadata, source, notes, first_data_line
    _validate(log)
    check_metadata(log, header_line)
    log.segments = _find_segments(log, report=True)
    return log


def _float_or_blank(cell: str) -> float:
    """A cell of a BLANK_WHERE_INVALID column of a compensated log: empty -> NaN."""
    return float(cell) if cell.strip() else math.nan


def _locate_bad_row(data, names, source, first_data_line, blank=()):
    ncol = len(names)
    for r, line in enumerate(data):
        lineno = first_data_line + r
        if not line.strip():
            raise RunLogError(source, lineno, "blank line inside the data")
        if line.startswith("#"):
            raise RunLogError(source, lineno, "metadata/comment line inside the data")
        cells = line.split(",")
        if len(cells) != ncol:
            raise RunLogError(source, lineno, f"{len(cells)} cells, the header has {ncol}: {line!r}")
        for k, cell in enumerate(cells):
            if not cell.strip():
                if k in blank:
                    continue
                raise RunLogError(source, lineno, f"column '{names[k]}': empty cell (a number is required; only "
                                                  f"a compensated log's rate_dph / bias_dph may be empty, where "
                                                  f"valid is 0)")
            try:
                float(cell)
            except ValueError:
                raise RunLogError(source, lineno, f"column '{names[k]}': {cell.strip()!r} is not a number") from None
    raise RunLogError(source, None, "could not parse the data rows")


def _fmt_column(name: str, arr: np.ndarray) -> list:
    if arr.dtype.kind in "iu":
        return [str(int(x)) for x in arr.tolist()]
    # shortest repr that round-trips exactly; NaN (only where a compensated log is not valid) is empty
    return [repr(x) if x == x else "" for x in arr.tolist()]


def write_csv(log: RunLog, path, extra_metadata: dict | None = None) -> None:
    """Write ``log`` as CSV run log (values in shortest round-trip form, so CSV -> CSV is lossless).
    ``extra_metadata`` lines are added after the log's own."""
    meta = dict(log.metadata)
    meta.update(extra_metadata or {})
    names = list(log.columns)
    formatted = [_fmt_column(n, log.columns[n]) for n in names]
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        for key, value in meta.items():
            fh.write(f"# {value}\n" if key.startswith("#") else f"# {key}: {value}\n")
        fh.write(",".join(names) + "\n")
        fh.writelines(",".join(row) + "\n" for row in zip(*formatted))


# -- NPZ (lossless binary) ---------------------------------------------------------------------

def write_npz(log: RunLog, path) -> None:
    """Lossless binary form: every column bit-exact, metadata and notes as JSON."""
    header = json.dumps({"format": "hdrg-runlog", "version": FORMAT_VERSION, "columns": list(log.columns),
                         "metadata": log.metadata, "notes": log.notes})
    arrays = {f"col_{i}": v for i, v in enumerate(log.columns.values())}
    with atomic_open(path, "wb") as fh:
        np.savez(fh, header=np.array(header), **arrays)


def read_npz(path) -> RunLog:
    source = os.fspath(path)
    try:
        with np.load(source, allow_pickle=False) as z:
            header = json.loads(str(z["header"]))
            if header.get("format") != "hdrg-runlog":
                raise RunLogError(source, None, "not an hdrg run-log NPZ (header 'format' missing)")
            cols = {name: z[f"col_{i}"] for i, name in enumerate(header["columns"])}
    except (OSError, ValueError, KeyError) as exc:
        if isinstance(exc, RunLogError):
            raise
        raise RunLogError(source, None, f"unreadable NPZ run log: {exc}") from None
    log = RunLog(cols, header.get("metadata", {}), source, header.get("notes", []))
    check_metadata(log)
    return log


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
