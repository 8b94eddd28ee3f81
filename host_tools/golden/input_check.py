"""Input validity of a run log: which samples are outside what the sensor can report, and which
proxy columns are stuck.  The host input stage of both implementations (the float golden model
host_tools.golden.compensate and the fixed-point path host_tools.fixed.fixed_point) and the fit
read the same per-sample mask from :func:`input_flags`.

**Input-invalid samples** (a per-sample bit: the firmware's input, what a sensor front end's
over-range flag gives; firmware_ref/FORMATS.md "The input-invalid bit").  The test is on the
input words (firmware_ref.inputs: round half up, saturation), so that a log and its dequantized
copy (host_tools.fixed.fixed_point.dequantized_log) flag the same samples:

* ``rate_dph``: ``|R| >= R_FS`` with ``R`` the raw rate word (LSB 2^-10 deg/h) and ``R_FS`` the
  word of the declared full scale (metadata ``rate_full_scale_dph: X`` in deg/h, or
  ``rate_full_scale_dps: X`` in deg/s), at most 2^31 - 1.  A loop output at its rail is a clipped
  reading, so a sample AT the full scale is flagged.  Default: the word's own rail, 2^31 - 1 LSB
  = 2^21 - 2^-10 deg/h (582.5 deg/s): any value the word cannot hold.
* ``freq_hz`` (drive frequency): the F word (LSB 2^-15 Hz) outside ``[word(LO), word(HI)]`` of the
  declared plausible range (metadata ``freq_range_hz: LO..HI`` in Hz), or 0 (below 2^-16 Hz).
  Default: any positive frequency (the reader refuses <= 0) - the float model serves drive
  frequencies beyond the word's 131072 Hz (such a device is refused at quantize, not here).  With ``word_range`` (the fixed-point path, whose F
  word cannot hold more, and the dequantized log that the golden reference is fed in the
  |fixed - golden| comparison, host_tools.fixed.fixed_point.dequantized_log) the word's upper rail
  2^32 - 1 is flagged too: the default range is then the word's, 0 .. 131072 Hz.
* ``temp_c``: the T word (LSB 2^-16 degC) outside ``[word(LO), word(HI)]`` of ``temp_range_c:
  LO..HI`` (degC), or at a rail (+-(2^31 - 1)).  Default: the word's range +-32768 degC.

A deterministic range test and nothing else (no outlier test against neighbours): a chip can do it
with two compares per word, it never flags a sample of a clean log whose values lie inside the
declared range (false-alarm rate 0 by construction on every clean log measured, see
:data:`FALSE_ALARMS`), and a log that declares its sensor's full scale gets every clipped reading.
A glitch inside the full scale is not an input error this test can see.

**Stuck proxy** (a host check, reported, not a per-sample bit): a run of at least
``STUCK_N`` = 256 consecutive *identical* values of ``freq_hz`` or ``temp_c``.  Why 256: a drive
PLL reports its NCO frequency; where the NCO step (3.55e-7 Hz in the simulator) is far below the
frequency's noise (1e-4 Hz per sample) two identical consecutive readings are rare (longest run 2
in 62400 simulated paper samples), but a coarse frequency counter (the foreign family's 6.6e-4 Hz
step, at a steady temperature) repeats a value for up to 56 samples, and a temperature register
for up to 30 (:data:`FALSE_ALARMS`).  256 is 4.6 x the longest clean run measured: a run that long
is a frozen register, a stalled PLL or a logger repeating its last value.  Samples of a stuck run are not
made invalid (a frozen value is plausible per sample); the run is named in a warning and `hdrg
compensate --strict` refuses.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from firmware_ref import formats as F
from firmware_ref import inputs

RATE_FS_KEYS = ("rate_full_scale_dph", "rate_full_scale_dps")   # metadata: the rate full scale
RANGE_KEYS = {"freq_hz": "freq_range_hz", "temp_c": "temp_range_c"}  # metadata: the plausible range LO..HI
CHECKED = ("rate_dph", "freq_hz", "temp_c")                        # the columns the test reads


def model_columns(log, config) -> tuple:
    """The checked columns a model reads from ``log`` (``config``: its ModelConfig): ``rate_dph``,
    its proxy column, and freq_hz / temp_c where its k7 generators read them: one mask for the
    float path, the fixed point's input-invalid bit and the fit's view of a compensation."""
    cols = ["rate_dph", log.proxy(config.proxy.kind)[0]]
    for term in config.aux.terms:
        col = term.get("column")
        if col in CHECKED and col in log and col not in cols:
            cols.append(col)
    return tuple(cols)
STUCK_N = 256              # this many identical consecutive proxy values or more: stuck
INPUT_KEY = "input_invalid"    # metadata of a compensated log: 'N samples; column K (first row R: ...), ...'
STUCK_KEY = "input_stuck"      # metadata of a compensated log: 'column rows A..B (N samples), ...'
RATE_RAIL = (1 << 31) - 1      # largest |R| word
FREQ_RAIL = F.UINT32_MAX       # largest F word
TEMP_RAIL = (1 << 31) - 1      # largest |T| word
# The false-alarm rate measured on clean logs (python -m host_tools.golden.input_check LOG ...):
# flagged samples / samples and the longest run of identical proxy values.
FALSE_ALARMS = {
    "simulated: paper-mr-cycle-4dpm seeds 1, 2, paper-ftr-cycle-4dpm seed 3 (3 x 31200 samples)":
        "0 flagged; longest identical run: freq_hz 2, temp_c 7",
    "simulated: foreign family devices 0..7 (hdrg simulate --family random --seed D --chamber-rate 4 "
    "--reversal on --power-on 0 --noise-seed 1; 100114 samples)":
        "0 flagged; longest identical run: freq_hz 56 (device 5: a 6.6e-4 Hz counter step), temp_c 30",
    "measured: tests/data/psim-tvac-lsm6dsm (x, y; 2 x 6250 samples)": "0 flagged; longest temp_c run 4",
    "measured: tests/data/tofupilot-imu-thermal (x, y; 2 x 8400 samples)": "0 flagged; longest temp_c run 2",
}


@dataclass
class InputReport:
    """What :func:`input_flags` found in a log of ``n`` samples: per checked column the number of
    flagged samples (``counts``), the first flagged row and its value (``first``), the limit
    applied (``limits``, text), and the stuck runs ``stuck``: (column, first row, last row)."""

    source: str
    n: int
    counts: dict = field(default_factory=dict)
    first: dict = field(default_factory=dict)
    limits: dict = field(default_factory=dict)
    stuck: list = field(default_factory=list)
    flagged: int = 0
    first_row: int = -1

    def invalid_text(self) -> str:
        """'N samples; rate_dph 1, first row 1200: 1e+09 (|x| >= ...); freq_hz ...' or ''."""
        if not self.flagged:
            return ""
        parts = [f"{c} {k}, first row {self.first[c][0]}: {self.first[c][1]:g} ({self.limits[c]})"
                 for c, k in self.counts.items() if k]
        return f"{self.flagged} samples; " + "; ".join(parts)

    def stuck_text(self) -> str:
        """'freq_hz rows 100..400 (301 samples), ...' or ''."""
        return ", ".join(f"{c} rows {a}..{b} ({b - a + 1} samples)" for c, a, b in self.stuck)

    def messages(self) -> list:
        """The warnings this report deserves (one sentence each), [] for a clean log."""
        msgs = []
        if self.flagged:
            msgs.append(invalid_message(self.invalid_text(), self.n))
        if self.stuck:
            msgs.append(stuck_message(self.stuck_text()))
        return msgs


def invalid_message(text: str, n: int) -> str:
    """The warning of :attr:`InputReport.invalid_text` ``text`` for a log of ``n`` samples."""
    k = int(text.split(" ", 1)[0])
    return (f"input: {k} of {n} samples outside what the sensor can report: {text.split('; ', 1)[1]}; they and "
            f"every output computed from them (their window's pairings, the rate estimator's re-warm) are not "
            f"valid, and a fit leaves them out")


def stuck_message(text: str) -> str:
    """The warning of :attr:`InputReport.stuck_text` ``text``."""
    return (f"stuck proxy: {text} hold one value for {STUCK_N} or more consecutive samples (a frozen register "
            f"or a stalled drive PLL; the proxy's noise makes that implausible): the compensation there "
            f"uses a proxy that does not follow the temperature")


def _number(text: str, key: str, source: str) -> float:
    try:
        value = float(str(text).strip().split()[0])
    except (ValueError, IndexError):
        raise ValueError(f"{source}: metadata '{key}: {text}' is not a number") from None
    if not math.isfinite(value) or not value > 0:
        raise ValueError(f"{source}: metadata '{key}: {text}' must be a finite number > 0")
    return value


def _range(text: str, key: str, source: str) -> tuple:
    m = re.match(r"\s*([-+0-9.eE]+)\s*(?:\.\.|,)\s*([-+0-9.eE]+)\s*$", str(text))
    try:
        lo, hi = (float(m.group(1)), float(m.group(2))) if m else (math.nan, math.nan)
    except ValueError:
        lo = hi = math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise ValueError(f"{source}: metadata '{key}: {text}' is not a range LO..HI with LO < HI")
    return lo, hi


def declared_limits(log, word_range: bool = False) -> dict:
    """The limits in force for ``log`` (metadata or defaults, see the module doc): {'rate_dph':
    R_FS word, 'freq_hz': (lo word, hi word), 'temp_c': (lo word, hi word)} with a text each under
    '<column>_text'; ``word_range``: the frequency's upper rail is flagged (module doc)."""
    md, src = log.metadata, log.source
    out = {}
    rfs = RATE_RAIL
    text = f"|x| >= {RATE_RAIL * 2.0 ** -F.RATE_FRAC:.10g} deg/h (the rate word's rail)"
    for key in RATE_FS_KEYS:
        if str(md.get(key, "")).strip():
            fs = _number(md[key], key, src) * (3600.0 if key.endswith("_dps") else 1.0)
            rfs = min(inputs.word_of(fs, F.RATE_FRAC)[0], RATE_RAIL)
            text = f"|x| >= the full scale {rfs * 2.0 ** -F.RATE_FRAC:.10g} deg/h (metadata {key})"
            break
    out["rate_dph"], out["rate_dph_text"] = rfs, text
    for col, frac, signed, rail, unit in (("freq_hz", F.FREQ_FRAC, False, FREQ_RAIL, "Hz"),
                                          ("temp_c", F.TEMP_FRAC, True, TEMP_RAIL, "degC")):
        key = RANGE_KEYS[col]
        lo_w, hi_w = (-rail if signed else 0), rail
        text = f"outside the {col} word's range"
        if col == "freq_hz" and not word_range:
            hi_w, text = rail + 1, "not positive"
        if str(md.get(key, "")).strip():
            lo, hi = _range(md[key], key, src)
            lo_w = max(inputs.word_of(lo, frac, signed)[0], lo_w)
            hi_w = min(inputs.word_of(hi, frac, signed)[0], hi_w)
            text = f"outside {lo:g}..{hi:g} {unit} (metadata {key})"
        out[col], out[col + "_text"] = (lo_w, hi_w), text
    return out


def _words(col: str, x):
    if col == "rate_dph":
        return inputs.rate_words(x)[0]
    if col == "freq_hz":
        return inputs.freq_words(x)[0]
    return inputs.temp_words(x)[0]


def column_flags(log, col: str, limits: dict | None = None, word_range: bool = False) -> np.ndarray:
    """bool[n]: the samples of column ``col`` (one of CHECKED) outside what the sensor can report
    (``limits``: :func:`declared_limits`; ``word_range`` as there)."""
    lim = declared_limits(log, word_range) if limits is None else limits
    if col == "freq_hz" and not word_range:
        # the float path serves any positive frequency: compare in Hz (the word saturates at 131072 Hz)
        x = np.asarray(log[col], np.float64)
        lo, hi = (_range(log.metadata[RANGE_KEYS[col]], RANGE_KEYS[col], log.source)
                  if str(log.metadata.get(RANGE_KEYS[col], "")).strip() else (0.0, np.inf))
        with np.errstate(invalid="ignore"):
            return ~np.isfinite(x) | (x <= 0) | (x < lo) | (x > hi)
    w = _words(col, np.asarray(log[col], np.float64))
    if col == "rate_dph":
        return np.abs(w) >= lim["rate_dph"]
    lo, hi = lim[col]
    if col == "freq_hz":
        return (w < lo) | (w > hi) | (w <= 0) | ((w >= FREQ_RAIL) & (hi <= FREQ_RAIL))
    return (w < lo) | (w > hi) | (w <= -TEMP_RAIL) | (w >= TEMP_RAIL)


def stuck_runs(x, min_n: int = STUCK_N) -> list:
    """(first row, last row) of every run of at least ``min_n`` identical consecutive values of ``x``."""
    x = np.asarray(x)
    n = len(x)
    if n < min_n:
        return []
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    starts = np.concatenate(([0], change))
    ends = np.concatenate((change, [n])) - 1
    keep = ends - starts + 1 >= min_n
    return [(int(a), int(b)) for a, b in zip(starts[keep], ends[keep])]


def longest_run(x) -> int:
    """The longest run of identical consecutive values of ``x`` (0 for an empty array)."""
    x = np.asarray(x)
    if not len(x):
        return 0
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    bounds = np.concatenate(([0], change, [len(x)]))
    return int(np.max(np.diff(bounds)))


def input_flags(log, columns=None, word_range: bool = False) -> tuple:
    """``(mask, report)``: ``mask`` bool[n], True where one of ``columns`` (default: every column
    of CHECKED the log has; the fixed and float compensation pass ``rate_dph`` and the model's
    proxy column) is outside what the sensor can report (module doc; ``word_range``: the
    fixed-point path's F word range, :func:`declared_limits`); ``report`` an
    :class:`InputReport` (counts, first rows, limits, and the stuck runs of the proxy columns
    among ``columns``)."""
    cols = [c for c in (CHECKED if columns is None else columns) if c in log]
    n = len(log)
    lim = declared_limits(log, word_range)
    mask = np.zeros(n, bool)
    rep = InputReport(log.source, n)
    for col in cols:
        bad = column_flags(log, col, lim, word_range)
        k = int(np.count_nonzero(bad))
        rep.counts[col] = k
        rep.limits[col] = lim[col + "_text"]
        if k:
            row = int(np.argmax(bad))
            rep.first[col] = (row, float(np.asarray(log[col])[row]))
        mask |= bad
        if col in RANGE_KEYS:
            rep.stuck.extend((col, a, b) for a, b in stuck_runs(np.asarray(log[col])))
    rep.flagged = int(np.count_nonzero(mask))
    rep.first_row = int(np.argmax(mask)) if rep.flagged else -1
    return mask, rep


class InputWarning(UserWarning):
    """Input-invalid samples or a stuck proxy in a run log (the text gives the counts and rows)."""


def warn_inputs(logs) -> list:
    """For the fit path: per log of ``logs`` the mask of :func:`fit_mask`, warning
    (InputWarning, once per log) how many samples the fit leaves out and any stuck proxy."""
    import warnings

    from host_tools.errors import UserError

    masks = [fit_mask(log, warn=lambda text: warnings.warn(text, InputWarning, stacklevel=3)) for log in logs]
    for log, m in zip(logs, masks):
        if len(m) and not m.any():
            _, rep = input_flags(log)
            raise UserError(f"{log.source}: every sample is outside what the sensor can report "
                            f"({rep.invalid_text()}): nothing to fit; check the log or its declared ranges")
    return masks


def fit_mask(log, warn=None) -> np.ndarray:
    """bool[n], True for the samples a fit may use as far as the inputs go (not input-invalid,
    :func:`input_flags`); ``warn`` (a callable taking one text, e.g. warnings.warn) is told the
    count excluded and any stuck proxy, once per log."""
    mask, rep = input_flags(log)
    if warn is not None:
        if rep.flagged:
            warn(f"{log.source}: {rep.flagged} of {rep.n} samples excluded from the fit: input outside what the "
                 f"sensor can report: {rep.invalid_text().split('; ', 1)[1]}")
        if rep.stuck:
            warn(f"{log.source}: {stuck_message(rep.stuck_text())}")
    return ~mask


def rate_restarts(segments, bad) -> np.ndarray:
    """The restarts of the rate estimator: the segment starts, every input-invalid sample and the
    sample after it (int64, sorted): the estimator re-warms after a flagged sample, which thus
    never enters its memory (the fixed point: firmware_ref.rate, the same rule)."""
    bad = np.asarray(bad, bool)
    idx = np.flatnonzero(bad)
    after = idx + 1
    after = after[after < len(bad)]
    return np.unique(np.concatenate((np.asarray(segments, np.int64), idx, after))).astype(np.int64)


def main(argv=None) -> int:
    """``python -m host_tools.golden.input_check LOG ...``: per log the flagged samples and the
    longest run of identical proxy values (the false-alarm measurement of the module doc)."""
    import sys

    from host_tools.golden import runlog as rl

    for path in (sys.argv[1:] if argv is None else argv):
        log = rl.read(path)
        mask, rep = input_flags(log)
        runs = ", ".join(f"{c} {longest_run(log[c])}" for c in RANGE_KEYS if c in log)
        print(f"{path}: {len(log)} samples, {rep.flagged} flagged "
              f"({100.0 * rep.flagged / max(len(log), 1):.4f} %); longest identical run: {runs}; "
              f"stuck: {rep.stuck_text() or 'none'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
