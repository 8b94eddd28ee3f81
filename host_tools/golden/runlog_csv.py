"""The CSV layer of the run-log reader (host_tools.golden.runlog): a file's bytes to metadata, header
and named numeric columns, with every check and repair of docs/RUN_LOG.md; and the escaping of the
writer's metadata lines.  The error and warning classes and the column vocabulary live here so that
this layer needs nothing from runlog; runlog re-exports them.

Reading (:func:`read_table`) is bounded and streaming:

* only a regular file is read (:func:`open_regular`: a FIFO, a device such as /dev/zero, a socket
  or a directory is refused before it is opened for reading, so nothing blocks or fills memory);
* the metadata and header lines are read one by one (at most ``HEAD_LINE_MAX`` bytes each);
* the end of the file is examined first (trailing blank lines; a last line without its line end,
  or with fewer cells than the header, is the truncated last line: discarded with a warning);
* the data rows are counted, then parsed in blocks of ``CHUNK_BYTES`` bytes straight into one
  float64 array (one row per column), so the memory used is the final arrays plus one block.

The numbers of a block are parsed by a numba kernel (:func:`_parse_rows`): plain decimal numbers
``[+-]digits[.digits][e[+-]digits]`` with optional spaces or tabs around them, converted exactly
(Clinger's fast path, else the Eisel-Lemire algorithm with a 128-bit table of powers of five: the
double nearest the decimal, as Python's ``float()``), and an empty cell as NaN where the column may
be empty.  A cell it does not take (``nan``, ``inf``, more than 19 significant digits, a subnormal)
is converted by ``float()`` if it is still a number; anything else (a blank line, a wrong cell
count, text, bytes that are not ASCII) sends the block to the per-line validator
(:func:`_parse_block_slowly`, numpy's loadtxt and the exact error ``FILE:LINE: problem``).
"""
from __future__ import annotations

import os
import re
import stat
import warnings
from dataclasses import dataclass, field

import numba
import numpy as np

from host_tools.errors import HdrgError

INT_COLUMNS = ("mode", "flags", "valid")   # integer columns (flags, valid: compensated logs, docs/RUN_LOG.md)
# a compensated log (it has the columns 'valid' and 'bias_dph') carries no number in these columns
# where valid is 0: NaN in memory and NPZ, an empty cell in CSV (docs/RUN_LOG.md)
BLANK_WHERE_INVALID = ("rate_dph", "bias_dph")
FORMAT_COLUMNS = ("t_s", "rate_dph", "rate_dps", "mode", "freq_hz", "temp_c")   # shared/formats/run-log.md
# columns hdrg itself writes (docs/RUN_LOG.md): a compensated log, and hdrg capture's device outputs
HDRG_COLUMNS = ("bias_dph", "valid", "flags", "comp_rate_dph", "comp_bias_dph", "comp_valid", "status", "state", "seq")
CHUNK_BYTES = 4 << 20          # data bytes parsed per block
HEAD_LINE_MAX = 1 << 20        # longest metadata or header line [bytes]
MAX_HARD = 4096                # cells per block the kernel leaves to float() before the block goes slow
_WS = b" \t\r\n\x0b\x0c"


class RunLogError(HdrgError, ValueError):
    """A run log that cannot be read: names the file, the line (1-based, physical) and the problem."""

    def __init__(self, source: str, line: int | None, problem: str):
        self.source, self.line, self.problem = source, line, problem
        where = f"{source}:{line}" if line is not None else source
        super().__init__(f"{where}: {problem}")


class RunLogWarning(UserWarning):
    """A repair the reader made (truncated last line dropped, gaps found); the text says which."""


def is_compensated_output(columns) -> bool:
    """The columns are `hdrg compensate`'s output (``valid`` and ``bias_dph``): BLANK_WHERE_INVALID
    may be NaN (CSV: empty) where valid is 0."""
    return "valid" in columns and "bias_dph" in columns


# -- the writer's metadata lines ----------------------------------------------------------------

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def meta_escape(value, key: bool = False) -> str:
    """``value`` as text for one ``# key: value`` line: control characters (newlines included) are
    written as Python escapes (``\\n``, ``\\x1b``), so no value can end its line early and forge a
    metadata line or a row; in a key, ``:`` (the key/value separator) becomes ``_``.  Text without
    control characters (and a key without ``:``) is returned unchanged."""
    text = _CONTROL.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), str(value))
    return text.replace(":", "_").strip() if key else text


def meta_line(key, value) -> str:
    """One metadata line (with its newline): ``# key: value``, or ``# value`` for a free-form
    comment (a key starting with ``#``); both escaped by :func:`meta_escape`."""
    key = str(key)
    if key.startswith("#"):
        return f"# {meta_escape(value)}\n"
    return f"# {meta_escape(key, key=True)}: {meta_escape(value)}\n"


# -- special files --------------------------------------------------------------------------------

def _kind(mode: int) -> str | None:
    if stat.S_ISREG(mode):
        return None
    return ("a directory" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode) else "a device"
            if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")


def open_regular(source: str):
    """The binary file object of the regular file ``source``; RunLogError for a directory, a FIFO, a
    device or a socket (checked with os.stat before opening, and again on the opened descriptor,
    which is opened without blocking).  A missing file raises the OSError of open()."""
    try:
        kind = _kind(os.stat(source).st_mode)
    except OSError:
        kind = None                          # missing or unreadable: open() says why
    if kind is None:
        fd = os.open(source, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        kind = _kind(os.fstat(fd).st_mode)
        if kind is None:
            return os.fdopen(fd, "rb")
        os.close(fd)
    raise RunLogError(source, None, f"is {kind}, not a regular file (a run log must be a file)")


# -- the number kernel ----------------------------------------------------------------------------

_U = np.uint64
_TEN, _TWO53, _M32, _S32, _ONE = _U(10), _U(1 << 53), _U(0xFFFFFFFF), _U(32), _U(1)
_ALL, _MASK9 = _U(0xFFFFFFFFFFFFFFFF), _U(0x1FF)


def _pow5_table() -> tuple[np.ndarray, np.ndarray]:
    """High and low 64-bit words of the 128-bit normalized approximations of 5**q, q = -342..308
    (the Eisel-Lemire table; truncated for q >= 0, rounded up for q < 0)."""
    hi, lo = np.empty(651, np.uint64), np.empty(651, np.uint64)
    for q in range(-342, 309):
        if q < 0:
            p5 = 5 ** -q
            z = (p5 - 1).bit_length()                 # smallest z with 2**z >= 5**-q
            c = 2 ** (z + 127 if q >= -27 else 2 * z + 128) // p5 + 1
            c >>= max(0, c.bit_length() - 128)
        else:
            c = 5 ** q
            c = c << (128 - c.bit_length()) if c.bit_length() < 128 else c >> (c.bit_length() - 128)
        hi[q + 342], lo[q + 342] = c >> 64, c & ((1 << 64) - 1)
    return hi, lo


_T_HI, _T_LO = _pow5_table()
_P10 = np.array([10.0 ** k for k in range(23)])      # exact doubles


@numba.njit(cache=True)
def _mul128(a, b):
    """(high, low) 64-bit words of the 128-bit product of two uint64."""
    a_lo, a_hi, b_lo, b_hi = a & _M32, a >> _S32, b & _M32, b >> _S32
    p0, p1, p2, p3 = a_lo * b_lo, a_lo * b_hi, a_hi * b_lo, a_hi * b_hi
    mid = (p0 >> _S32) + (p1 & _M32) + (p2 & _M32)
    return p3 + (p1 >> _S32) + (p2 >> _S32) + (mid >> _S32), (p0 & _M32) | (mid << _S32)


@numba.njit(cache=True)
def _eisel_lemire(w, q, t_hi, t_lo):
    """The bits (as int64) of the double nearest ``w * 10**q`` (0 < w < 2**64, -342 <= q <= 308),
    or -1 when the algorithm cannot decide or the result is subnormal or infinite."""
    lz = 0
    for s in (32, 16, 8, 4, 2, 1):
        if w >> _U(64 - s) == _U(0):
            lz += s
            w = w << _U(s)
    hi, lo = _mul128(w, t_hi[q + 342])
    if hi & _MASK9 == _MASK9:
        hi2, _ = _mul128(w, t_lo[q + 342])
        new_lo = lo + hi2
        if new_lo < lo:
            hi += _ONE
        lo = new_lo
    if lo == _ALL and (q < -27 or q > 55):
        return -1
    upper = np.int64(hi >> _U(63))
    shift = _U(upper + 9)
    mant = hi >> shift
    power2 = ((217706 * q) >> 16) + 63 + upper - lz + 1023
    if power2 <= 0:
        return -1
    if lo <= _ONE and -4 <= q <= 23 and mant & _U(3) == _ONE and (mant << shift) == hi:
        mant &= ~_ONE                         # exactly halfway: round to even
    mant += mant & _ONE
    mant >>= _ONE
    if mant >= _U(2 << 52):
        mant = _U(1 << 52)
        power2 += 1
    mant &= ~_U(1 << 52)
    if power2 >= 0x7FF:
        return -1
    return np.int64(mant | (_U(power2) << _U(52)))


@numba.njit(cache=True, inline="always")   # inlined: as a call per cell, 1e6 rows read in 0.38-0.42 s, not 0.36 s
def _digits(buf, i, n, w, nd, ndig, exp, wide, frac):
    """The run of decimal digits at ``buf[i:]`` (up to ``n``) added to a number being parsed: ``w``
    the significand of its first 19 significant digits (``nd`` of them so far; a further one sets
    ``wide``), ``ndig`` all digits read; ``frac``: digits after the decimal point, each kept one
    and each leading zero lowering the decimal exponent ``exp``.  Returns (i, w, nd, ndig, exp, wide)."""
    while i < n and 48 <= buf[i] <= 57:
        d = _U(buf[i] - 48)
        ndig += 1
        if nd > 0 or d != _U(0):
            if nd < 19:
                w = w * _TEN + d
                nd += 1
                if frac:
                    exp -= 1
            else:
                wide = True
        elif frac:
            exp -= 1
        i += 1
    return i, w, nd, ndig, exp, wide


@numba.njit(cache=True)
def _parse_rows(buf, out, row0, blank_ok, hard, t_hi, t_lo, p10):
    """Parse the complete lines of ``buf`` (uint8, every line ends with ``\\n``) into ``out[:, row0:]``
    (``out``: one float64 row per column).  Returns (0, n) on success, ``hard[:n]`` holding (row,
    column, start, end) of the cells left to float() (NaN meanwhile); (1, 0) when a line is not
    plain numbers (the caller parses the block slowly)."""
    ncol, n = out.shape[0], buf.shape[0]
    bits = np.empty(1, np.int64)
    as_float = bits.view(np.float64)
    nhard, row, i = 0, row0, 0
    while i < n:
        for col in range(ncol):
            start = i
            while i < n and (buf[i] == 32 or buf[i] == 9):
                i += 1
            neg = signed = dot = False
            if i < n and (buf[i] == 43 or buf[i] == 45):
                neg, signed = buf[i] == 45, True
                i += 1
            w, nd, ndig, exp, wide, bad = _U(0), 0, 0, 0, False, False
            i, w, nd, ndig, exp, wide = _digits(buf, i, n, w, nd, ndig, exp, wide, False)
            if i < n and buf[i] == 46:
                dot = True
                i, w, nd, ndig, exp, wide = _digits(buf, i + 1, n, w, nd, ndig, exp, wide, True)
            if ndig > 0 and i < n and (buf[i] == 101 or buf[i] == 69):
                i += 1
                eneg = False
                if i < n and (buf[i] == 43 or buf[i] == 45):
                    eneg = buf[i] == 45
                    i += 1
                ne, ev = 0, 0
                while i < n and 48 <= buf[i] <= 57:
                    if ev < 100000:
                        ev = ev * 10 + (buf[i] - 48)
                    ne += 1
                    i += 1
                bad = ne == 0
                exp += -ev if eneg else ev
            while i < n and (buf[i] == 32 or buf[i] == 9):
                i += 1
            if col == ncol - 1 and i + 1 < n and buf[i] == 13 and buf[i + 1] == 10:
                i += 1                                        # CRLF line end
            delim = 44 if col < ncol - 1 else 10
            if i < n and buf[i] == delim and ndig == 0 and not signed and not dot:
                if not blank_ok[col]:
                    return 1, 0
                out[col, row] = np.nan                        # an empty cell where the column may be empty
                i += 1
                continue
            hard_cell = bad or ndig == 0 or i >= n or buf[i] != delim or wide or (w != _U(0) and (exp < -342 or exp > 308))
            v = 0.0
            if not hard_cell and w != _U(0):
                if w <= _TWO53 and -22 <= exp <= 22:
                    v = np.float64(w) * p10[exp] if exp >= 0 else np.float64(w) / p10[-exp]
                else:
                    b = _eisel_lemire(w, exp, t_hi, t_lo)
                    if b < 0:
                        hard_cell = True
                    else:
                        bits[0] = b
                        v = as_float[0]
            if hard_cell:
                j = start
                while j < n and buf[j] != 44 and buf[j] != 10:
                    if buf[j] >= 128:
                        return 1, 0
                    j += 1
                if j >= n or buf[j] != delim or nhard == hard.shape[0]:
                    return 1, 0
                hard[nhard, 0], hard[nhard, 1], hard[nhard, 2], hard[nhard, 3] = row, col, start, j
                nhard += 1
                out[col, row] = np.nan
                i = j + 1
                continue
            out[col, row] = -v if neg else v
            i += 1
        row += 1
    return 0, nhard


_NUMBER = re.compile(rb"[ \t]*[+-]?(?:nan|inf|infinity|(?:\d+\.?\d*|\.\d+)(?:e[+-]?\d+)?)[ \t]*", re.I)


# -- reading --------------------------------------------------------------------------------------

@dataclass
class CsvTable:
    """What :func:`read_table` read: ``columns`` name -> 1-D array (float64; INT_COLUMNS int64), in
    file order; ``metadata`` the ``# key: value`` lines; the header's and the first data row's file
    lines (1-based); ``notes`` the warnings given."""

    columns: dict
    metadata: dict
    header_line: int
    first_data_line: int
    notes: list = field(default_factory=list)


def _warn(msg: str, notes: list, depth: int = 5) -> None:
    """Warn ``msg`` (RunLogWarning) and note it; ``depth``: the frames up to runlog.read's caller."""
    notes.append(msg)
    warnings.warn(msg, RunLogWarning, stacklevel=depth)


def _decode(raw: bytes, source: str, offset: int) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RunLogError(source, None, f"not a text file (UTF-8 decoding failed at byte {offset + exc.start})") \
            from None


def _parse_metadata_line(text: str, index: int, metadata: dict, lines: dict, source: str) -> None:
    """Add the metadata line ``text`` (file line ``index``) to ``metadata``; ``lines``: key -> the line
    that set it.  A key repeated with another value is refused with both lines (one would be lost);
    a repeat with the same value is kept once."""
    body = text[1:].strip()
    if ":" in body:
        key, value = (x.strip() for x in body.split(":", 1))
        if key in metadata and metadata[key] != value:
            raise RunLogError(source, index, f"metadata key '{key}' repeated with another value: line "
                                             f"{lines[key]} says {metadata[key]!r}, line {index} says {value!r} "
                                             f"(one would be ignored); keep one")
        metadata[key] = value
        lines.setdefault(key, index)
    elif body:
        metadata[f"#{index}"] = body


def _squash(name: str) -> str:
    return re.sub(r"[\s_\-]", "", name.lower())


def unknown_columns(names) -> list:
    """The header columns that are neither in the format, nor ``aux_*``, nor one hdrg writes."""
    return [c for c in names if c not in FORMAT_COLUMNS and c not in HDRG_COLUMNS and not c.startswith("aux_")]


def check_columns(names, source: str, line: int | None, notes: list, depth: int = 6,
                  header_text: str | None = None) -> None:
    """The column checks of every run-log reader (CSV header, NPZ ``columns``): refuse an empty or
    repeated name, both ``rate_dph`` and ``rate_dps`` (one would be ignored), a missing required
    column, and a column that is not a format column but equals one the log lacks once case,
    spaces, '_' and '-' are ignored (``Mode``, ``Freq Hz``: names are matched exactly, so the log
    would be read without it; ``rate_dph`` and ``rate_dps`` stand for each other); warn
    (RunLogWarning, noted in ``notes``) about a column not in the format.
    ``line``: the header's file line (None for an NPZ); ``depth``: the warning's stack level."""
    where = f"{source}:{line}" if line is not None else source
    if any(not c for c in names):
        raise RunLogError(source, line, f"empty column name in header {header_text or ','.join(names)!r}")
    seen = set()
    for c in names:
        if c in seen:
            raise RunLogError(source, line, f"column '{c}' appears twice in the header")
        seen.add(c)
    if "rate_dph" in seen and "rate_dps" in seen:
        raise RunLogError(source, line, "columns 'rate_dph' and 'rate_dps' are both present: the log has two rate "
                                        "columns and one of them would be ignored; keep one")
    present = {_squash(c) for c in names if c in FORMAT_COLUMNS}
    if "ratedph" in present or "ratedps" in present:
        present |= {"ratedph", "ratedps"}
    for c in unknown_columns(names):
        near = next((k for k in FORMAT_COLUMNS if _squash(k) == _squash(c) and _squash(k) not in present), None)
        if near is not None:
            raise RunLogError(source, line, f"column '{c}' is not '{near}' (column names are matched "
                                            f"exactly, shared/formats/run-log.md): as it stands the log would "
                                            f"be read without '{near}'; rename the column")
    for req, alt in (("t_s", None), ("rate_dph", "rate_dps")):
        if req not in names and (alt is None or alt not in names):
            need = f"'{req}'" + (f" (or '{alt}')" if alt else "")
            raise RunLogError(source, line, f"missing required column {need}; header has {list(names)}")
    if "freq_hz" not in names and "temp_c" not in names:
        raise RunLogError(source, line, f"missing temperature proxy: one of the columns 'freq_hz', "
                                        f"'temp_c' is required; header has {list(names)}")
    unknown = unknown_columns(names)
    if unknown:
        _warn(f"{where}: column(s) {', '.join(repr(c) for c in unknown)} not in the run-log format "
              f"(t_s, rate_dph or rate_dps, mode, freq_hz, temp_c, aux_*): kept in the log but used by no tool; "
              f"rename a logged channel to aux_<name> to offer it to the fit and the loop", notes, depth)


def _read_head(fh, source: str):
    """Metadata lines up to the header row: (metadata, header names, header text, header line)."""
    metadata, lines, lineno, content = {}, {}, 0, False
    while True:
        offset = fh.tell()
        raw = fh.readline(HEAD_LINE_MAX + 1)
        if not raw:
            if not content:
                raise RunLogError(source, 1, "empty file (no header, no data)")
            raise RunLogError(source, lineno, "no header row (only metadata lines)")
        lineno += 1
        if len(raw) > HEAD_LINE_MAX:
            raise RunLogError(source, lineno, f"line longer than {HEAD_LINE_MAX} bytes before the header: not a run log")
        if lineno == 1 and raw.startswith(b"\xef\xbb\xbf"):        # a leading BOM (Excel) is not data
            raw, offset = raw[3:], offset + 3
        text = _decode(raw, source, offset).rstrip("\r\n")
        if text.startswith("#"):
            _parse_metadata_line(text, lineno, metadata, lines, source)
            content = True
        elif text.strip():
            return metadata, [c.strip() for c in text.split(",")], text, lineno
        else:
            content = content or bool(text)


def _read_at(fh, lo: int, hi: int) -> bytes:
    fh.seek(lo)
    return fh.read(hi - lo)


def _tail(fh, start: int, end: int):
    """The last data line: (its start, the end of its text, the end of its line end or None when it
    has none); None when [start, end) holds only blank lines."""
    p, step = end, 1 << 16
    while p > start:                                # skip trailing blank lines
        lo = max(start, p - step)
        kept = _read_at(fh, lo, p).rstrip(_WS)
        if kept:
            p = lo + len(kept)
            break
        p = lo
    if p <= start:
        return None
    line_start, hi = start, p
    while hi > start:                               # the line's start: after the previous newline
        lo = max(start, hi - step)
        k = _read_at(fh, lo, hi).rfind(b"\n")
        if k >= 0:
            line_start = lo + k + 1
            break
        hi = lo
    line_end, q = None, p
    while q < end:                                  # its line end: a newline in the blank tail
        block = _read_at(fh, q, min(end, q + step))
        k = block.find(b"\n")
        if k >= 0:
            line_end = q + k + 1
            break
        q += len(block)
    return line_start, p, line_end


def _blocks(fh, start: int, end: int, source: str):
    """(offset, memoryview) blocks of whole lines of [start, end) (which ends with a newline), about
    CHUNK_BYTES each (a longer line makes a longer block)."""
    fh.seek(start)
    pos, carry = start, b""
    while pos < end:
        got = fh.read(min(CHUNK_BYTES, end - pos))
        if not got:
            raise RunLogError(source, None, "the file became shorter while it was read")
        pos += len(got)
        data = carry + got if carry else got
        cut = data.rfind(b"\n") + 1 if pos < end else len(data)
        if cut:
            yield pos - len(data), memoryview(data)[:cut]
        carry = data[cut:]


def _count_lines(fh, start: int, end: int) -> int:
    fh.seek(start)
    count, pos = 0, start
    while pos < end:
        got = fh.read(min(CHUNK_BYTES, end - pos))
        if not got:
            break
        count, pos = count + got.count(b"\n"), pos + len(got)
    return count


def _locate_bad_row(lines, names, source, first_line, blank=()):
    ncol = len(names)
    for r, line in enumerate(lines):
        lineno = first_line + r
        if not line.strip():
            raise RunLogError(source, lineno, "blank line inside the data")
        if line.startswith("#"):
            raise RunLogError(source, lineno, "metadata/comment line inside the data")
        if "\r" in line:
            raise RunLogError(source, lineno, "a carriage return (CR) inside the line (line ends are LF or CR LF)")
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
                if not _NUMBER_TEXT.fullmatch(cell):     # float() also takes '1_000', other digits
                    raise ValueError(cell)
            except ValueError:
                raise RunLogError(source, lineno, f"column '{names[k]}': {cell.strip()!r} is not a number") from None
    raise RunLogError(source, None, "could not parse the data rows")


_NUMBER_TEXT = re.compile(_NUMBER.pattern.decode("ascii"), re.I | re.ASCII)


def _float_or_blank(cell: str) -> float:
    """A cell of a BLANK_WHERE_INVALID column of a compensated log: empty -> NaN."""
    return float(cell) if cell.strip() else np.nan


def _parse_block_slowly(raw: bytes, offset: int, first_line: int, names, blank, source: str) -> np.ndarray:
    """The rows of one block (rows x columns) by the per-line validator and numpy's loadtxt: the
    exact error (``FILE:LINE: problem``) of the first bad line, or the values."""
    lines = [line[:-1] if line.endswith("\r") else line for line in _decode(raw, source, offset).split("\n")[:-1]]
    for r, line in enumerate(lines):
        if not line.strip():                      # loadtxt would skip it silently
            raise RunLogError(source, first_line + r, "blank line inside the data")
    try:
        table = np.loadtxt(lines, delimiter=",", dtype=np.float64, ndmin=2, comments=None,
                           converters={k: _float_or_blank for k in blank} or None)
        if table.shape != (len(lines), len(names)):
            raise ValueError("row or column count")
    except ValueError:
        _locate_bad_row(lines, names, source, first_line, blank)
        raise  # _locate_bad_row always raises; kept for safety
    return table


def _line_text(fh, start: int, end: int, row: int, source: str) -> str:
    """The text of data line ``row`` (0-based) of [start, end)."""
    seen = 0
    for _, raw in _blocks(fh, start, end, source):
        text = bytes(raw).decode("utf-8", "replace").split("\n")
        if seen + len(text) - 1 > row:
            return text[row - seen].rstrip("\r")
        seen += len(text) - 1
    return ""


def read_table(fh, size: int, source: str) -> CsvTable:
    """Read the CSV run log in the binary file ``fh`` up to byte ``size`` (see the module doc)."""
    notes = []
    metadata, names, header_text, header_line = _read_head(fh, source)
    check_columns(names, source, header_line, notes, 6, header_text)
    first_line, start, ncol = header_line + 1, fh.tell(), len(names)
    tail = _tail(fh, start, size) if start < size else None
    if tail is None:
        raise RunLogError(source, first_line, "no data rows after the header")
    line_start, text_end, line_end = tail
    end = line_end
    cells = _read_at(fh, line_start, text_end).split(b",")
    if line_end is None or len(cells) < ncol:        # the truncated last line
        kept = _count_lines(fh, start, line_start)
        last = _read_at(fh, line_start, min(text_end, line_start + 200)).decode("utf-8", "replace")
        why = "no line end: cut inside a cell or a number" if line_end is None else "too few cells"
        _warn(f"{source}:{first_line + kept}: truncated last line {last!r} ({why}; {len(cells)} of {ncol} cells); "
              f"repair: the partial line is discarded, the {kept} complete {'row is' if kept == 1 else 'rows are'} kept", notes)
        if not kept:
            raise RunLogError(source, first_line, "no complete data rows after the header")
        end = line_start
    blank = [k for k, name in enumerate(names) if name in BLANK_WHERE_INVALID] if is_compensated_output(names) else []
    blank_ok = np.array([k in blank for k in range(ncol)])
    hard = np.empty((MAX_HARD, 4), np.int64)
    blocks, nrows = [], 0
    for offset, raw in _blocks(fh, start, end, source):        # each block: (columns, rows)
        block = np.empty((ncol, raw.obj.count(b"\n", 0, len(raw))))
        status, nhard = _parse_rows(np.frombuffer(raw, np.uint8), block, 0, blank_ok, hard, _T_HI, _T_LO, _P10)
        for r, k, a, b in hard[:nhard if status == 0 else 0]:
            cell = bytes(raw[a:b])
            if not _NUMBER.fullmatch(cell[:-1] if cell.endswith(b"\r") and k == ncol - 1 else cell):
                status = 1
                break
            block[k, r] = float(cell)
        if status:
            block = _parse_block_slowly(bytes(raw), offset, first_line + nrows, names, blank, source).T
        blocks.append(block)
        nrows += block.shape[1]
    out = np.empty((ncol, nrows))                 # one row per column; the blocks released as they are copied
    row = 0
    while blocks:
        block = blocks.pop(0)
        out[:, row:row + block.shape[1]] = block
        row += block.shape[1]
        del block
    columns = {}
    for k, name in enumerate(names):
        col = out[k]
        if name in INT_COLUMNS:
            bad = ~(np.abs(col) < 2.0 ** 63)
            bad |= col != np.round(col)
            if bad.any():
                r = int(np.argmax(bad))
                cell = _line_text(fh, start, end, r, source).split(",")[k]
                raise RunLogError(source, first_line + r, f"{name} {cell!r} is not an integer")
            as_int = col.view(np.int64)
            as_int[...] = col                             # in place: no second array
            col = as_int
        columns[name] = col
    return CsvTable(columns, metadata, header_line, first_line, notes)
