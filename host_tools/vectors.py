"""`hdrg vectors`: deterministic test vectors of the fixed-point pipeline (firmware_ref/FORMATS.md),
to prove a firmware or RTL implementation against: generate, verify, check an external program.

Sets (each a CSV with a header, a ``$readmemh`` file and, where tables are used, a table file):

* ``primitives``: RHU, MULRHU, FLOORDIV, DIVROUND, DIVRS, CLAMP, SAT at ties, extremes and sign
  edges (firmware_ref.arith is the reference);
* ``evaluator``: the Horner evaluator (FORMATS.md step 5) on random integer tables, one-hot
  tables (one mantissa at +-(2^31 - 1)), tables at the accumulator bound and at the exponent
  extremes, realistic quantized tables; u, v at and inside +-2^30, z beyond +-2^30 (clamped);
* ``sequencer``: the whole pipeline with every output field, self-timed (power-on, the paper's
  30/120 s cycles, zero-length exchanges, one-sample dwells, settling >= dwell, long runs) and
  log-driven (corner streams of firmware_ref.vectors, staleness limit edges, trend slope and
  output-word saturation, long windows, random models and streams);
* ``e2e``: simulated chamber runs (host_tools.sim, fixed seeds, short) with models fitted by
  host_tools.fit.fit_logs on host_tools.compensate.fit_config_from_logs and quantized, through
  the whole pipeline with every intermediate: the input words (proxy F or T, rate R), u, v, z,
  the rate sum, the window sum, the Horner rows, the k7 term, the accumulator t, B, y, the
  output words, valid, flags;
* ``aux``: tables with aux generators (aux_gen 1, FORMATS.md "Aux generators"): every kind alone
  (z = its g), signs, powers, short and long filters, decays with restarts and exchange resets,
  ramps, oscillators at large and negative K, weight-sum clamps, coefficient extremes, random
  multi-term tables, and a simulated run with a fitted aux model; the inputs add K and the aux
  words A0..A3 (an ``S`` line of 11 fields), the outputs are the 16 ``O`` fields (z is the
  generated z).

Everything in the vector files is an integer (the CSV op names of ``primitives`` aside); seeds are
fixed; the manifest has no timestamps.  Outputs come from the numba kernel
(firmware_ref.kernel); every case is cross-checked on its first ``PY_CHECK`` samples with the
per-sample Python reference (firmware_ref.compensate.run_reference, firmware_ref.evaluator),
which also gives acc/cnt, vs and sign semantics.

The fitted models of ``e2e`` are rounded to 7 significant digits (configuration and
coefficients) before quantization, so that an ulp of difference in the float simulator or the
fitter between machines does not flip a mantissa (byte-identical regeneration).

``manifest.json``: format and generator versions, the SHA-256 fingerprint of the algorithm sources
(``SOURCE_GLOBS``), the configuration (seeds, sizes, models), every coefficient table (words and
fields), each set's columns, ``$readmemh`` record layout and cases, and the SHA-256 of every file.
``generate`` refuses to overwrite vectors whose content changed unless GENERATOR_VERSION or
FORMAT_VERSION was bumped (or ``--force``).

``check-impl`` drives an external program through the line protocol of firmware_ref/c/README.md
(also in vectors/README.md): ``TABLE``, ``S``, ``EVAL`` and the primitive requests.
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np

from firmware_ref import arith
from firmware_ref import formats as F
from firmware_ref.table import Table, TableError, horner_bounds
from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX

FORMAT_VERSION = 3          # file layout (columns, record layout, manifest keys); 2: the aux set (K, A0..A3);
                            # 3: table layout v2 (73+ words), the evaluator's bank column
GENERATOR_VERSION = 3       # the cases and their values; bump when a vector changes; 2: RHUW, SIN, aux;
                            # 3: regress_first (two banks, residual combiner pair/trend/none)
STALE_MESSAGE = ("vectors are stale: regenerate with `hdrg vectors generate -o vectors/` and bump "
                 "GENERATOR_VERSION/FORMAT_VERSION")
ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DIR = ROOT / "vectors"
SOURCE_GLOBS = ("firmware_ref/*.py", "firmware_ref/c/*.c", "firmware_ref/c/*.h")
SETS = ("primitives", "evaluator", "sequencer", "e2e", "aux")
PY_CHECK = 300              # samples per case cross-checked with the Python reference
SEED = 20240611             # the one seed; every set derives its generators from it

# -- columns ------------------------------------------------------------------------------------------
PRIM_OPS = ("RHU", "MULRHU", "FLOORDIV", "DIVROUND", "DIVRS", "CLAMP", "SAT", "RHUW", "SIN")
PRIM_ARITY = {"RHU": 2, "MULRHU": 3, "FLOORDIV": 2, "DIVROUND": 2, "DIVRS": 3, "CLAMP": 3, "SAT": 2, "RHUW": 3,
              "SIN": 1}
PRIM_FLAGGED = ("CLAMP", "SAT")          # answer "R value clamped"
# (name, bits in the $readmemh record); the CSV has these columns plus the extra ones
PRIM_FIELDS = (("op", 8), ("a", 64), ("b", 64), ("c", 64), ("result", 64), ("flag", 8))
PRIM_INPUTS = ("op", "a", "b", "c")
EVAL_FIELDS = (("case", 16), ("u", 32), ("v", 32), ("z", 32), ("bank", 8), ("b", 64), ("zclamped", 8))
EVAL_EXTRA = ("row0", "row1", "row2", "row3", "zterm", "t")          # CSV only
EVAL_INPUTS = ("case", "u", "v", "z", "bank")
IN_FIELDS = (("F", 32), ("T", 32), ("R", 32), ("MODE", 8), ("RESTART", 8), ("Z", 32))
O_FIELDS = (("state", 8), ("vs", 8), ("mode", 8), ("sign", 8), ("u", 32), ("v", 32), ("z", 32), ("s", 64),
            ("acc", 64), ("cnt", 32), ("y", 64), ("b", 64), ("out", 32), ("bias", 32), ("valid", 8), ("flags", 8))
O_NAMES = tuple(n for n, _ in O_FIELDS)           # the 16 fields of an `O` line, in order
ROW_FIELDS = (("row0", 32), ("row1", 32), ("row2", 32), ("row3", 32), ("zterm", 32), ("t", 32))
SEQ_FIELDS = (("case", 16),) + IN_FIELDS + O_FIELDS
E2E_FIELDS = SEQ_FIELDS + ROW_FIELDS
SEQ_INPUTS = ("case", "i") + tuple(n for n, _ in IN_FIELDS)
AUX_IN_FIELDS = IN_FIELDS + (("K", 64), ("A0", 32), ("A1", 32), ("A2", 32), ("A3", 32))
AUX_FIELDS = (("case", 16),) + AUX_IN_FIELDS + O_FIELDS
AUX_INPUTS = ("case", "i") + tuple(n for n, _ in AUX_IN_FIELDS)


class VectorsError(ValueError):
    """Vectors that cannot be used: a missing or corrupt file, an unsupported format."""


# -- helpers ------------------------------------------------------------------------------------------

def _rhu(x, s: int):
    """RHU on int64 numpy arrays (or ints): s a Python int >= 0."""
    return x if s == 0 else (x + (1 << (s - 1))) >> s


def horner_rows(table, u, v, z, bank=None) -> dict:
    """The evaluator's intermediates on int64 arrays (u, v in [-2^30, 2^30], z any int32):
    ``row0..row3`` = a[i], the Horner row of u^i aligned to the accumulator (LSB 2^-E deg/h),
    ``zterm`` = RHU(m_7 z, 30 + e_7 - E), ``t`` the accumulator after k7 z, ``b`` = B (LSB 2^-21
    deg/h), ``zclamped``.  Exactly FORMATS.md step 5 (the formats bound every product below 2^62).
    ``bank``: int array (1, 2) of the bank of each sample (None: bank 1)."""
    if bank is not None and table.n_banks == 2:
        bank = np.asarray(bank, np.int64)
        one, two = horner_rows(table, u, v, z), horner_rows(table.bank(2), u, v, z)
        return {k: np.where(bank == 2, two[k], one[k]) for k in one}
    u = np.asarray(u, np.int64)
    v = np.asarray(v, np.int64)
    z = np.asarray(z, np.int64)
    table = table.bank(1) if hasattr(table, "bank") else table
    m, E = table.mant, table.e_acc
    out = {}
    for i in range(4):
        c = [m[POLY_INDEX[i][j]] for j in range(4)]
        p = np.full(u.shape, c[3], np.int64)
        p = _rhu(p * v, F.Q) + c[2]
        p = _rhu(p * v, F.Q) + c[1]
        q = _rhu(p * v, F.Q) + c[0]
        out[f"row{i}"] = _rhu(q, table.e_row[i] - E)
    t = out["row3"]
    for i in (2, 1, 0):
        t = _rhu(t * u, F.Q) + out[f"row{i}"]
    zc = np.clip(z, -F.ONE, F.ONE)
    out["zterm"] = _rhu(np.int64(m[K_AUX]) * zc, F.Q + table.e_7 - E)
    out["t"] = t + out["zterm"]
    out["b"] = _rhu(out["t"], E - F.Y_FRAC) if E >= F.Y_FRAC else out["t"] << (F.Y_FRAC - E)
    out["zclamped"] = (zc != z).astype(np.int64)
    return out


def window_sums(table, m, r, restart, b=None, warm=None):
    """The combiner's window sum and count after each sample (acc LSB 2^-10 deg/h, cnt): the part
    of firmware_ref.sequencer.Combiner that the numba kernel does not output.  ``m`` the mode of
    each sample (logged or the timer's); for an order-1 table ``b`` (B of each sample, LSB 2^-21)
    and ``warm`` (rate estimator in warm-up): the sums are of r = symsat32(RHU(c 2^11 - B, 11))
    over the used (warm) samples."""
    n = len(m)
    acc_o = np.zeros(n, np.int64)
    cnt_o = np.zeros(n, np.int64)
    if table.combiner == 0:
        return acc_o, cnt_o
    order1 = table.order == 1
    b = np.zeros(n, np.int64) if b is None else np.asarray(b, np.int64)
    warm = np.zeros(n, bool) if warm is None else np.asarray(warm, bool)
    cur = acc = cnt = pos = 0
    for i, (mi, ri, rs) in enumerate(zip(m.tolist(), r.tolist(), restart.tolist())):
        if rs:
            cur = acc = cnt = pos = 0
        if mi != cur:
            cur = mi if mi in (1, 2) else 0
            acc = cnt = pos = 0
        if cur:
            if pos >= table.settle_n:
                c = ri if cur == 1 else -ri
                if order1:
                    c = arith.sat_signed(arith.rshift_round((c << 11) - int(b[i]), 11), 32)[0]
                if cnt < F.COUNT_MAX and not (order1 and warm[i]):
                    acc += c
                    cnt += 1
            else:
                pos += 1
        acc_o[i] = acc
        cnt_o[i] = cnt
    return acc_o, cnt_o


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def source_fingerprint(root: Path = ROOT) -> dict:
    """SHA-256 of every algorithm source (SOURCE_GLOBS, CRLF normalized to LF) and of their
    concatenated digests: ``{"sha256": ..., "files": {path: sha256}}``."""
    files = {}
    for pattern in SOURCE_GLOBS:
        for path in sorted(root.glob(pattern)):
            files[path.relative_to(root).as_posix()] = _sha256(path.read_bytes().replace(b"\r\n", b"\n"))
    files = dict(sorted(files.items()))
    total = _sha256("".join(f"{k} {v}\n" for k, v in files.items()).encode())
    return {"sha256": total, "files": files}


# -- a set in memory --------------------------------------------------------------------------------

@dataclasses.dataclass
class VectorSet:
    """One set: ordered int64 columns, the record layout of its .mem file, its cases and tables."""

    name: str
    description: str
    columns: dict                       # name -> int64 array, CSV column order
    inputs: tuple                       # the input columns
    mem_fields: tuple                   # ((name, bits), ...), MSB first
    cases: list = dataclasses.field(default_factory=list)   # dicts: name, rows, table, self_timed, ...
    tables: list = dataclasses.field(default_factory=list)  # Table objects

    def __len__(self):
        return len(next(iter(self.columns.values())))

    def files(self) -> dict:
        """file name -> bytes."""
        out = {f"{self.name}.csv": render_csv(self), f"{self.name}.mem": render_mem(self.columns, self.mem_fields)}
        if self.tables:
            out[f"{self.name}.tables.mem"] = "".join(t.to_memh() for t in self.tables).encode()
        return out


def render_csv(vs: VectorSet) -> bytes:
    cols = []
    for name, arr in vs.columns.items():
        if name == "op":
            cols.append([PRIM_OPS[k] for k in arr.tolist()])
        else:
            cols.append([str(x) for x in arr.tolist()])
    lines = [",".join(vs.columns)] + [",".join(row) for row in zip(*cols)]
    return ("\n".join(lines) + "\n").encode()


def render_mem(columns: dict, fields: tuple) -> bytes:
    """One line per record: the fields' two's complement words concatenated, MSB first, in hex."""
    fmt = "".join(f"%0{bits // 4}x" for _, bits in fields) + "\n"
    masked = [(columns[name].astype(np.uint64) & np.uint64((1 << bits) - 1)).tolist() for name, bits in fields]
    return "".join(fmt % row for row in zip(*masked)).encode()


def parse_csv(data: bytes, source: str) -> dict:
    """CSV bytes -> name -> int64 array (op names back to codes)."""
    lines = data.decode().splitlines()
    if not lines:
        raise VectorsError(f"{source}: empty file")
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:]]
    for k, row in enumerate(rows):
        if len(row) != len(header):
            raise VectorsError(f"{source}:{k + 2}: {len(row)} fields, the header has {len(header)}")
    cols = {}
    for c, name in enumerate(header):
        vals = [row[c] for row in rows]
        try:
            if name == "op":
                cols[name] = np.array([PRIM_OPS.index(x) for x in vals], np.int64)
            else:
                cols[name] = np.array([int(x) for x in vals], np.int64)
        except ValueError:
            raise VectorsError(f"{source}: column {name!r}: a value is not an integer"
                               f"{' or an op name' if name == 'op' else ''}") from None
    return cols


# -- primitives -------------------------------------------------------------------------------------

def _prim_eval(op: str, a: int, b: int, c: int):
    """(result, flag) by firmware_ref.arith; AssertionError if a precondition is violated."""
    if op == "RHU":
        return arith.rshift_round(a, b), 0
    if op == "MULRHU":
        return arith.mul_rshift_round(a, b, c), 0
    if op == "FLOORDIV":
        return arith.floor_div(a, b), 0
    if op == "DIVROUND":
        return arith.div_round(a, b), 0
    if op == "DIVRS":
        return arith.div_round_scaled(a, b, c), 0
    if op == "CLAMP":
        assert b <= c
        v, f = arith.clamp(a, b, c)
        return v, int(f)
    if op == "RHUW":
        return arith.mul_rshift_round_wide(a, b, c), 0
    if op == "SIN":
        from firmware_ref.aux import sin_q30
        return sin_q30(a & 0xFFFFFFFFFFFFFFFF), 0
    assert 1 <= b <= 63
    v, f = arith.sat_signed(a, b)
    return v, int(f)


def _prim_cases(rng) -> list:
    """(op, a, b, c) tuples: ties, extremes, sign edges and random values; only those that meet
    the preconditions of firmware_ref.arith (the C driver answers ERR RANGE otherwise)."""
    MAX, MIN = arith.INT64_MAX, arith.INT64_MIN

    def rnd(lo=MIN, hi=MAX):
        return int(rng.integers(lo, hi, dtype=np.int64, endpoint=True))

    cases = []
    for s in (0, 1, 2, 3, 7, 10, 11, 16, 24, 29, 30, 31, 32, 36, 40, 52, 60, 61, 62):
        h = 1 << (s - 1) if s else 0
        xs = [0, 1, -1, 2, -2, h, -h, h + 1, -h - 1, h - 1, -h + 1, 3 * h, -3 * h, MAX - h, MIN, MIN + 1, MAX]
        for _ in range(6):
            k = rnd(-(1 << max(0, 62 - s)), 1 << max(0, 62 - s))
            xs += [k * (1 << s) + h, k * (1 << s) - h, k * (1 << s)]     # ties and exact multiples
        xs += [rnd() for _ in range(4)] + [rnd(-(1 << 40), 1 << 40)]
        cases += [("RHU", x, s, 0) for x in xs]
    for s in (1, 2, 11, 16, 29, 30, 31, 45, 60, 61, 62):
        h = 1 << (s - 1)
        for a, b in ((1, h), (-1, h), (3, h), (-3, h), (h, 1), (h, -1), (F.INT32_SYM, F.ONE), (-F.INT32_SYM, F.ONE),
                     (F.INT32_SYM, -F.ONE), (-F.INT32_SYM, -F.ONE), (F.ONE, F.ONE), (-F.ONE, F.ONE),
                     (-(1 << 31), F.ONE), ((1 << 31) - 1, (1 << 31) - 1), (MAX, 1), (MIN + h, 1), (1 << 40, 1 << 21),
                     (-(1 << 40), 1 << 21), (0, MAX), (MAX, -1)):
            cases.append(("MULRHU", a, b, s))
        for _ in range(8):
            cases.append(("MULRHU", rnd(-(1 << 32), 1 << 32), rnd(-(1 << 30), 1 << 30), s))
            k = rnd(-1000, 1000)
            cases.append(("MULRHU", 2 * k + 1, h, s))                         # ties: odd * 2^(s-1)
    for a, b in ((0, 1), (1, 1), (-1, 1), (7, 2), (-7, 2), (-8, 2), (MAX, 1), (MIN, 1), (MIN, 2), (MAX, MAX),
                 (MIN, MAX), (-1, MAX), (MAX - 1, MAX), (5, 3), (-5, 3), (-6, 3)):
        cases.append(("FLOORDIV", a, b, 0))
    for _ in range(40):
        cases.append(("FLOORDIV", rnd(), rnd(1, MAX), 0))
        cases.append(("FLOORDIV", rnd(-1000, 1000), rnd(1, 20), 0))
    for a, b in ((0, 1), (1, 2), (-1, 2), (3, 2), (-3, 2), (5, 10), (-5, 10), (4, 10), (-4, 10), (6, 10), (-6, 10),
                 (1, 3), (-1, 3), (2, 3), (-2, 3), (MAX // 2 - 1, 1), (MIN // 2, 1), (MAX // 4, MAX // 2 - 1)):
        cases.append(("DIVROUND", a, b, 0))
    for _ in range(40):
        b = rnd(1, 1 << 40)
        k = rnd(-(1 << 20), 1 << 20)
        cases.append(("DIVROUND", k * 2 * b + b, 2 * b, 0))                  # ties (k + 1/2)
        cases.append(("DIVROUND", rnd(MIN // 4, MAX // 4), rnd(1, MAX // 4), 0))
    for k in (0, 1, 10, 16, 20, 30, 40):
        for a, b in ((1, 2), (-1, 2), (3, 2), (-3, 2), (1, 3), (-1, 3), (0, 5), (1 << 30, 3), (-(1 << 30), 3),
                     (F.INT32_SYM, 1), (-F.INT32_SYM, 7), ((1 << 62) - 1, 1 << 41), (-(1 << 62), (1 << 41) + 1),
                     (MAX, MAX), (MIN, MAX), (MIN + 1, 1 << 62)):
            cases.append(("DIVRS", a, b, k))
        for _ in range(10):
            cases.append(("DIVRS", rnd(-(1 << 50), 1 << 50), rnd(1, 1 << 30), k))
    for x, lo, hi in ((0, 0, 0), (1, 0, 0), (-1, 0, 0), (5, -3, 4), (4, -3, 4), (-3, -3, 4), (-4, -3, 4),
                      (MAX, -F.ONE, F.ONE), (MIN, -F.ONE, F.ONE), (F.ONE + 1, -F.ONE, F.ONE),
                      (-F.ONE - 1, -F.ONE, F.ONE), (F.ONE, -F.ONE, F.ONE), (-F.ONE, -F.ONE, F.ONE),
                      (MIN, MIN, MAX), (MAX, MIN, MAX)):
        cases.append(("CLAMP", x, lo, hi))
    for _ in range(30):
        lo, hi = sorted((rnd(-(1 << 40), 1 << 40), rnd(-(1 << 40), 1 << 40)))
        cases.append(("CLAMP", rnd(-(1 << 41), 1 << 41), lo, hi))
    for w in (1, 2, 8, 16, 31, 32, 33, 48, 62, 63):
        lim = (1 << (w - 1)) - 1
        for x in (0, 1, -1, lim, -lim, lim + 1, -lim - 1, -lim - 2, MAX, MIN, MIN + 1):
            cases.append(("SAT", x, w, 0))
        for _ in range(3):
            cases.append(("SAT", rnd(), w, 0))
    lim31, lim62 = (1 << 31) - 1, 1 << 62
    for s in (31, 32, 40, 52, 61, 62):
        h = 1 << (s - 1)
        for a, d in ((lim31, lim62), (-lim31, lim62), (lim31, -lim62), (-lim31, -lim62), (1, h), (-1, h), (1, -h),
                     (3, h), (-3, h), (lim31, 0), (0, lim62), (1 << 30, 1 << 60), (-(1 << 30), 1 << 60),
                     (1 << 30, -(1 << 60)), (lim31, (1 << 31) - 1), (lim31, -(1 << 31)), (2, h - 1), (-2, h + 1)):
            cases.append(("RHUW", a, d, s))
        for _ in range(10):
            cases.append(("RHUW", rnd(-lim31, lim31), rnd(-lim62, lim62), s))
            k = rnd(-(1 << 20), 1 << 20)
            cases.append(("RHUW", 2 * k + 1, h, s))                           # ties: odd * 2^(s-1)
    quarter = 1 << 62
    for ph in (0, 1, quarter - 1, quarter, quarter + 1, 2 * quarter, 3 * quarter, -1, MIN, MAX, MIN + 1,
               (1 << 31) - 1, 1 << 31, (1 << 31) + 1, quarter - (1 << 31), quarter + (1 << 31), -(1 << 31),
               3 * quarter - (1 << 31) - 1):
        cases.append(("SIN", ph, 0, 0))
    for _ in range(120):
        cases.append(("SIN", rnd(), 0, 0))
    out = []
    for op, a, b, c in cases:
        if not (MIN <= a <= MAX and MIN <= b <= MAX and MIN <= c <= MAX):
            continue
        try:
            _prim_eval(op, a, b, c)
        except AssertionError:
            continue
        out.append((op, a, b, c))
    return out


def primitives_set(rng) -> VectorSet:
    cases = _prim_cases(rng)
    cols = {"op": np.array([PRIM_OPS.index(c[0]) for c in cases], np.int64),
            "a": np.array([c[1] for c in cases], np.int64),
            "b": np.array([c[2] for c in cases], np.int64),
            "c": np.array([c[3] for c in cases], np.int64)}
    vs = VectorSet("primitives", "fixed-point primitives (firmware_ref.arith): RHU(a, s=b), MULRHU(a, b, s=c), "
                   "FLOORDIV(a, b), DIVROUND(a, b), DIVRS(a, b, k=c), CLAMP(x=a, lo=b, hi=c), SAT(x=a, width=b), "
                   "RHUW(a, d=b, s=c) = RHU(a d, s) wider than int64, SIN(phase=a: the uint64 phase as int64 bits, "
                   "firmware_ref.aux.sin_q30); flag = clamped (CLAMP, SAT), else 0", cols, PRIM_INPUTS, PRIM_FIELDS,
                   cases=[{"name": op, "description": f"{op} requests"} for op in PRIM_OPS])
    compute_primitives(vs)
    return vs


def compute_primitives(vs: VectorSet) -> None:
    res, flag = [], []
    for op, a, b, c in zip(vs.columns["op"].tolist(), vs.columns["a"].tolist(), vs.columns["b"].tolist(),
                           vs.columns["c"].tolist()):
        try:
            r, f = _prim_eval(PRIM_OPS[op], a, b, c)
        except AssertionError as exc:
            raise VectorsError(f"primitives: {PRIM_OPS[op]} {a} {b} {c} violates a precondition ({exc})") from None
        res.append(r)
        flag.append(f)
    vs.columns["result"] = np.array(res, np.int64)
    vs.columns["flag"] = np.array(flag, np.int64)


# -- tables -----------------------------------------------------------------------------------------

def _qtable(est="diff", combiner="pair", n=5, shift=2, settle_s=2.0, max_stale_s=25.0, coef=None, kind=None,
            order="combine_first", coef2=None, **timing) -> Table:
    """A quantized table of firmware_ref.vectors.make_model (as tests/test_c_twin.py's table_of);
    ``order`` "regress_first": two banks (``coef2``: make_model's default)."""
    from firmware_ref.vectors import make_model
    from host_tools.quantize import quantize

    if coef is None:
        coef = [3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1, 6e1, -5e1]
    temp = (kind or ("temp" if est == "lsq" else "freq")) == "temp"
    model = make_model("temp" if temp else "freq", ref=20.0 if temp else 6227.0, span=30.0 if temp else 3.0,
                       estimator=est, n=n, shift=shift, rate_span=0.5 if temp else 0.003, combiner=combiner,
                       settle_s=settle_s, max_stale_s=max_stale_s, coef=coef, order=order, coef2=coef2)
    return quantize(model, n_random=10, **timing).table


def _fit_bounds(e_row, e_7, e_acc, mant) -> list:
    """Halve the mantissas (towards zero) until the Horner interval bounds hold."""
    mant = list(mant)
    while True:
        rows, bounds = horner_bounds(e_row, e_7, e_acc, mant)
        if max(rows) <= F.ACC_LIMIT and sum(bounds) <= F.ACC_LIMIT:
            return mant
        mant = [m >> 1 if m >= 0 else -((-m) >> 1) for m in mant]


def _two_banks(t1: Table, t2: Table) -> Table:
    """An order-1 two-bank table: t1 with bank 2 = bank 1 of t2 (combiner pair)."""
    from firmware_ref.vectors import two_bank_table

    return two_bank_table(t1 if t1.combiner else dataclasses.replace(t1, combiner=1), t2, None)


def _random_eval_table(rng, base: Table) -> Table:
    E = int(rng.integers(0, F.EXP_MAX + 1))
    e = [E + int(rng.integers(0, min(F.ALIGN_MAX, F.EXP_MAX - E) + 1)) for _ in range(5)]
    mant = []
    for _ in range(N_TERMS):
        bits = int(rng.integers(0, 32))
        m = int(rng.integers(0, 1 << bits)) if bits and rng.random() > 0.1 else 0
        mant.append(m if rng.random() < 0.5 else -m)
    mant = _fit_bounds(e[:4], e[4], E, mant)
    return dataclasses.replace(base, e_row=tuple(e[:4]), e_7=e[4], e_acc=E, mant=tuple(mant))


# -- evaluator --------------------------------------------------------------------------------------

def evaluator_set(rng) -> VectorSet:
    from firmware_ref.vectors import random_model
    from host_tools.quantize import quantize

    base = _qtable()
    tables, cases, parts = [], [], []
    edge = np.array([F.ONE, -F.ONE, F.ONE - 1, -F.ONE + 1, 0, 1, -1], np.int64)
    zedge = np.array([0, F.ONE, -F.ONE, F.ONE + 1, -F.ONE - 1, F.INT32_SYM, -F.INT32_SYM - 1, 12345], np.int64)

    def add(name, desc, table, u, v, z, bank=None):
        cases.append({"name": name, "description": desc, "table": len(tables)})
        tables.append(table)
        u = np.asarray(u, np.int64)
        bank = np.ones(len(u), np.int64) if bank is None else np.asarray(bank, np.int64)
        parts.append((u, np.asarray(v, np.int64), np.asarray(z, np.int64), bank))

    def random_points(n):
        u = rng.integers(-F.ONE, F.ONE, n, endpoint=True)
        v = rng.integers(-F.ONE, F.ONE, n, endpoint=True)
        z = rng.integers(-F.ONE - (F.ONE >> 2), F.ONE + (F.ONE >> 2), n, endpoint=True)
        pick = rng.random(n) < 0.1
        u[pick] = rng.choice(edge, int(pick.sum()))
        pick = rng.random(n) < 0.1
        v[pick] = rng.choice(edge, int(pick.sum()))
        pick = rng.random(n) < 0.05
        z[pick] = rng.choice(zedge, int(pick.sum()))
        return u, v, z

    grid_u, grid_v, grid_z = (a.ravel() for a in np.meshgrid(edge, edge, zedge, indexing="ij"))
    for k in range(N_TERMS):                       # one-hot: one mantissa at +-(2^31 - 1)
        for sign, (E, shift) in ((1, (21, 0)), (-1, (30, 22))):
            mant = [0] * N_TERMS
            mant[k] = sign * F.INT32_SYM
            e = [E + shift] * 5
            if k == K_AUX:
                e[4] = E + min(shift, F.EXP_MAX - E)
            t = dataclasses.replace(base, e_row=tuple(e[:4]), e_7=e[4], e_acc=E, mant=tuple(mant))
            u, v, z = random_points(12)
            add(f"onehot_k{k}_{'pos' if sign > 0 else 'neg'}",
                f"only m_{k} = {sign * F.INT32_SYM}, E = {E}, shift {shift}",
                t, np.r_[grid_u[::7], u], np.r_[grid_v[::7], v], np.r_[grid_z[::7], z])
    # tables at the accumulator bound: every row sum 2^31 - 5 aligned by 2 (2^29 - 1 each) + k7 bound 1
    row = [F.INT32_SYM - 4 - 3 * (1 << 29), 1 << 29, 1 << 29, 1 << 29]
    mant = [0] * N_TERMS
    for i in range(4):
        for j in range(4):
            mant[POLY_INDEX[i][j]] = row[j] * (1 if (i + j) % 2 == 0 else -1)
    mant[K_AUX] = F.INT32_SYM
    bound = dataclasses.replace(base, e_row=(23, 23, 23, 23), e_7=52, e_acc=21, mant=tuple(mant))
    extremes = {
        "acc_bound": ("every row's |mantissa| sum at 2^31 - 5, aligned bounds summing to 2^31 - 3", bound),
        "acc_bound_same_sign": ("as acc_bound with all mantissas positive",
                                dataclasses.replace(bound, mant=tuple(abs(m) for m in bound.mant))),
        "acc_bound_neg": ("as acc_bound_same_sign negated",
                          dataclasses.replace(bound, mant=tuple(-abs(m) for m in bound.mant))),
        "e_acc_0": ("E = 0 (B = t << 21, |B| up to 2^52), row exponents 0, 7, 19, 31, k7 at 31",
                    dataclasses.replace(base, e_row=(0, 7, 19, 31), e_7=31, e_acc=0,
                                        mant=tuple(_fit_bounds((0, 7, 19, 31), 31, 0, [F.INT32_SYM // 5 * (-1) ** k
                                                                                       for k in range(N_TERMS)])))),
        "e_acc_52": ("every exponent 52: B = RHU(t, 31), ties at 2^30",
                     dataclasses.replace(base, e_row=(52,) * 4, e_7=52, e_acc=52,
                                         mant=tuple(_fit_bounds((52,) * 4, 52, 52, [(1 << 30) + k * 12345 - 99999
                                                                                   for k in range(N_TERMS)])))),
        "k7_extreme": ("only m_7 = 2^31 - 1, e_7 = E = 30: RHU(m_7 z, 30) with z clamped",
                       dataclasses.replace(base, e_row=(30,) * 4, e_7=30, e_acc=30,
                                           mant=tuple(F.INT32_SYM if k == K_AUX else 0 for k in range(N_TERMS)))),
    }
    for name, (desc, t) in extremes.items():
        add(name, desc + "; u, v, z on the edge grid", t, grid_u, grid_v, grid_z)
    for k in range(24):
        u, v, z = random_points(160)
        add(f"random_{k}", "random legal integer table (exponents, mantissas), random points", _random_eval_table(rng, base),
            u, v, z)
    for k in range(8):
        t = quantize(random_model(rng), exchange_s=3.0, dwell_s=7.0, n_random=10).table
        u, v, z = random_points(100)
        add(f"quantized_{k}", "firmware_ref.vectors.random_model quantized by host_tools.quantize", t, u, v, z)
    # two banks (regress_first, order 1): the bank input selects the coefficients and exponents
    two = [("two_bank_extremes", "bank 1 = e_acc_0 (E = 0, B = t << 21), bank 2 = e_acc_52 (B = RHU(t, 31))",
            _two_banks(extremes["e_acc_0"][1], extremes["e_acc_52"][1])),
           ("two_bank_bound_signs", "bank 1 = acc_bound_same_sign, bank 2 = acc_bound_neg: B of opposite sign",
            _two_banks(extremes["acc_bound_same_sign"][1], extremes["acc_bound_neg"][1]))]
    for name, desc, t in two:
        bank = np.resize(np.array([1, 2], np.int64), len(grid_u))
        add(name, desc + "; u, v, z on the edge grid, banks alternating", t, grid_u, grid_v, grid_z, bank)
        add(name + "_swapped", desc + "; banks in the other order", t, grid_u, grid_v, grid_z, 3 - bank)
    for k in range(6):
        t = quantize(random_model(rng, order="regress_first"), exchange_s=3.0, dwell_s=7.0, n_random=10).table
        u, v, z = random_points(120)
        add(f"quantized_two_bank_{k}", "firmware_ref.vectors.random_model(order='regress_first') quantized: two "
            "banks with their own exponents, random bank per point", t, u, v, z, rng.integers(1, 3, 120))
    case_col = np.concatenate([np.full(len(p[0]), c, np.int64) for c, p in enumerate(parts)])
    cols = {"case": case_col, "u": np.concatenate([p[0] for p in parts]), "v": np.concatenate([p[1] for p in parts]),
            "z": np.concatenate([p[2] for p in parts]), "bank": np.concatenate([p[3] for p in parts])}
    start = 0
    for c, p in zip(cases, parts):
        c["rows"] = [start, start + len(p[0])]
        start += len(p[0])
    vs = VectorSet("evaluator", "the Horner evaluator alone (FORMATS.md step 5): B (LSB 2^-21 deg/h) and "
                   "zclamped at (u, v, z) with coefficient bank `bank` (1, or 2 of a two-bank table) for table "
                   "`case`; row0..row3 = the Horner rows a[i] aligned to 2^-E, "
                   "zterm = RHU(m_7 z, 30 + e_7 - E), t = the accumulator after k7 z (LSB 2^-E)",
                   cols, EVAL_INPUTS, EVAL_FIELDS, cases, tables)
    compute_evaluator(vs, check_python=True)
    return vs


def compute_evaluator(vs: VectorSet, check_python: bool = False) -> None:
    """Fill b, zclamped and the intermediates from case/u/v/z: numba kernel (B) and horner_rows
    (which must agree), optionally every row also by the Python evaluator."""
    from firmware_ref.evaluator import evaluate
    from firmware_ref.kernel import evaluate_words

    c = vs.columns
    if np.any(np.abs(c["u"]) > F.ONE) or np.any(np.abs(c["v"]) > F.ONE):
        raise VectorsError("evaluator: u and v must be in [-2^30, 2^30]")
    n = len(c["u"])
    res = {name: np.zeros(n, np.int64) for name in EVAL_EXTRA + ("b", "zclamped")}
    for case in vs.cases:
        lo, hi = case["rows"]
        t = vs.tables[case["table"]]
        u, v, z, bank = c["u"][lo:hi], c["v"][lo:hi], c["z"][lo:hi], c["bank"][lo:hi]
        if not np.all((bank == 1) | ((bank == 2) & (t.n_banks == 2))):
            raise VectorsError(f"evaluator case {case['name']}: bank must be 1, or 2 with a two-bank table")
        rows = horner_rows(t, u, v, z, bank)
        kb = evaluate_words(t, u, v, z)
        if t.n_banks == 2:
            kb = np.where(bank == 2, evaluate_words(t, u, v, z, bank=2), kb)
        if not np.array_equal(kb, rows["b"]):
            i = int(np.argmax(kb != rows["b"]))
            raise VectorsError(f"evaluator case {case['name']}: numba B {kb[i]} != Horner rows B {rows['b'][i]} "
                               f"at u={u[i]} v={v[i]} z={z[i]}")
        if check_python:
            for i in range(hi - lo):
                b, zc = evaluate(int(u[i]), int(v[i]), int(z[i]), t, bank=int(bank[i]))
                if b != rows["b"][i] or int(zc) != rows["zclamped"][i]:
                    raise VectorsError(f"evaluator case {case['name']}: Python reference B {b} != {rows['b'][i]} "
                                       f"at u={u[i]} v={v[i]} z={z[i]}")
        for name in res:
            res[name][lo:hi] = rows[name]
    cols = {k: c[k] for k in EVAL_INPUTS}
    cols.update((k, res[k]) for k in EVAL_EXTRA + ("b", "zclamped"))
    vs.columns = cols


# -- pipeline (sequencer, e2e) ---------------------------------------------------------------------------

def compute_pipeline(vs: VectorSet, rows: bool, check_python: int = PY_CHECK) -> None:
    """Fill the 16 output fields (and with ``rows`` the evaluator intermediates) of every case from
    the input columns (MODE -1: self-timed): numba kernel + window_sums; the first
    ``check_python`` samples of each case against firmware_ref.compensate.run_reference."""
    from firmware_ref.compensate import run_reference
    from firmware_ref.kernel import run_words

    c = vs.columns
    n = len(c["F"])
    has_aux = "K" in c                                   # the aux set: K and A0..A3 inputs
    res = {name: np.zeros(n, np.int64) for name in O_NAMES + (tuple(k for k, _ in ROW_FIELDS) if rows else ())}
    for case in vs.cases:
        lo, hi = case["rows"]
        t = vs.tables[case["table"]]
        mode = c["MODE"][lo:hi]
        timed = bool(mode.size and mode[0] == -1)
        if timed != bool(np.all(mode == -1)) or not np.all((mode >= -1) & (mode <= 3)):
            raise VectorsError(f"{vs.name} case {case['name']}: MODE must be all -1 (self-timed) or all 0..3")
        p = (c["F"] if t.proxy_kind == 0 else c["T"])[lo:hi]
        r, rs, z = c["R"][lo:hi], c["RESTART"][lo:hi], c["Z"][lo:hi]
        kw = {}
        if has_aux:
            kw = {"f": c["F"][lo:hi], "t": c["T"][lo:hi], "k": c["K"][lo:hi],
                  "aux": np.stack([c[f"A{j}"][lo:hi] for j in range(F.AUX_MAX_CHANNELS)], axis=1)}
        k = run_words(t, p, r, None if timed else mode, rs, z, self_timed=timed, detail=True, **kw)
        state = k["state"]
        m = np.asarray(F.STATE_MODE, np.int64)[state] if timed else mode
        acc, cnt = window_sums(t, m, r, rs, k["b"], (k["flags"] & F.FLAG_WARMUP) != 0)
        o = {"state": state, "vs": np.asarray(F.STATE_VS, np.int64)[state],
             "mode": m, "sign": np.asarray(F.STATE_SIGN, np.int64)[state], "u": k["u"], "v": k["v"],
             "z": k["z"], "s": k["s"], "acc": acc, "cnt": cnt, "y": k["y"], "b": k["b"],
             "out": k["out"], "bias": k["bias"], "valid": k["valid"], "flags": k["flags"]}
        if rows:
            hr = horner_rows(t, k["u"], k["v"], z, np.where(m == 2, 2, 1))
            if not np.array_equal(hr["b"], k["b"]):
                raise VectorsError(f"{vs.name} case {case['name']}: Horner rows disagree with the kernel's B")
            o.update((name, hr[name]) for name, _ in ROW_FIELDS)
        m_py = min(check_python, hi - lo)
        if m_py:
            ref = run_reference(t, p[:m_py], r[:m_py], None if timed else mode[:m_py], rs[:m_py], z[:m_py],
                                self_timed=timed, **{key: val[:m_py] for key, val in kw.items()})
            for name in ("state", "vs", "sign", "u", "v", "z", "s", "acc", "cnt", "y", "b", "out", "bias", "valid",
                         "flags"):
                if not np.array_equal(np.asarray(ref[name], np.int64), np.asarray(o[name][:m_py], np.int64)):
                    i = int(np.argmax(np.asarray(ref[name], np.int64) != o[name][:m_py]))
                    raise VectorsError(f"{vs.name} case {case['name']} sample {i}: {name}: numba kernel "
                                       f"{o[name][i]} != Python reference {ref[name][i]}")
        for name in res:
            res[name][lo:hi] = o[name]
    cols = {k: c[k] for k in (AUX_INPUTS if has_aux else SEQ_INPUTS)}
    cols.update(res)
    vs.columns = cols


class _Cases:
    """Collects the cases of a pipeline set: input columns, tables, descriptions."""

    def __init__(self):
        self.cases, self.tables, self.parts = [], [], []

    def add(self, name, desc, table, s, self_timed=False, t_words=None):
        """A case: stream ``s`` (p, r, mode, restart, z; for the aux set also f, t, aux, k)."""
        n = len(s["p"])
        rec = {"F": np.zeros(n, np.int64), "T": np.zeros(n, np.int64),
               "R": np.asarray(s["r"], np.int64),
               "MODE": np.full(n, -1, np.int64) if self_timed else np.asarray(s["mode"], np.int64),
               "RESTART": np.zeros(n, np.int64) if s.get("restart") is None else np.asarray(s["restart"], np.int64),
               "Z": np.zeros(n, np.int64) if s.get("z") is None else np.asarray(s["z"], np.int64)}
        rec["F" if table.proxy_kind == 0 else "T"] = np.asarray(s["p"], np.int64)
        if t_words is not None:                        # the other word from the log (e2e)
            rec["T" if table.proxy_kind == 0 else "F"] = np.asarray(t_words, np.int64)
        if s.get("k") is not None:                     # the aux set: every channel word, K, A0..A3
            rec["F"], rec["T"] = np.asarray(s["f"], np.int64), np.asarray(s["t"], np.int64)
            rec["F" if table.proxy_kind == 0 else "T"] = np.asarray(s["p"], np.int64)
            rec["K"] = np.asarray(s["k"], np.int64)
            a = np.asarray(s["aux"], np.int64).reshape(n, -1)
            for j in range(F.AUX_MAX_CHANNELS):
                rec[f"A{j}"] = a[:, j] if j < a.shape[1] else np.zeros(n, np.int64)
        rec["RESTART"][0] = 1
        try:
            ti = next(i for i, t in enumerate(self.tables) if t == table)
        except StopIteration:
            ti = len(self.tables)
            self.tables.append(table)
        self.cases.append({"name": name, "description": desc, "table": ti, "self_timed": bool(self_timed)})
        self.parts.append(rec)

    def columns(self) -> dict:
        start = 0
        for c, p in zip(self.cases, self.parts):
            c["rows"] = [start, start + len(p["R"])]
            start += len(p["R"])
        cols = {"case": np.concatenate([np.full(len(p["R"]), c, np.int64) for c, p in enumerate(self.parts)]),
                "i": np.concatenate([np.arange(len(p["R"]), dtype=np.int64) for p in self.parts])}
        for name, _ in (AUX_IN_FIELDS if "K" in self.parts[0] else IN_FIELDS):
            cols[name] = np.concatenate([p[name] for p in self.parts])
        return cols


def _ramp(table, n, rng, rate_lsb=600.0) -> dict:
    """A proxy ramp through the range with noise, rate words of a slow bias plus noise."""
    lo, hi = (0, F.UINT32_MAX) if table.proxy_kind == 0 else (-F.INT32_SYM, F.INT32_SYM)
    span = max(2, (F.ONE << table.sh_u) // table.g_u)
    x = np.linspace(-1.2, 1.2, n) * span + rng.normal(0, span * 1e-3, n)
    p = np.clip(table.p_ref + np.round(x).astype(np.int64), lo, hi)
    r = np.round(5000 * np.sin(np.arange(n) / 37.0) + rng.normal(0, rate_lsb, n)).astype(np.int64)
    return {"p": p, "r": r, "mode": np.zeros(n, np.int64), "restart": None, "z": None}


def sequencer_set(rng) -> VectorSet:
    from firmware_ref.vectors import corner_stream, random_model, random_stream
    from host_tools.quantize import quantize

    cs = _Cases()
    t = _qtable("diff", "pair", power_on_s=7.0, exchange_s=3.0, dwell_s=9.0)
    cs.add("power_on_timed", "self-timed from power-on (7), exchange 3, dwell 9, settle 2, pair", t,
           _ramp(t, 160, rng), True)
    t = _qtable("diffn", "trend", n=8, settle_s=5.0, max_stale_s=300.0)
    cs.add("paper_cycles_timed", "self-timed at the paper's timing (exchange 30, dwell 120, no power-on), "
           "trend, settle 5, 2.5 cycles", t, _ramp(t, 780, rng), True)
    t = _qtable("diff", None, power_on_s=5.0)
    cs.add("ftr_timed", "self-timed FTR table: power-on (5) then FTR forever", t, _ramp(t, 60, rng), True)
    t = _qtable("iir", "pair", shift=3, exchange_s=0.0, dwell_s=4.0)
    cs.add("no_exchange_timed", "self-timed, exchange_n = 0, power_on_n = 0: modes 1/2 alternate directly", t,
           _ramp(t, 100, rng), True)
    t = _qtable("diff", "trend", settle_s=0.0, power_on_s=2.0, exchange_s=1.0, dwell_s=1.0)
    cs.add("dwell1_timed", "self-timed, one-sample windows (dwell 1, exchange 1), trend", t, _ramp(t, 80, rng), True)
    t = _qtable("diff", "pair", settle_s=5.0, exchange_s=2.0, dwell_s=5.0)
    cs.add("settle_eq_dwell_timed", "self-timed, settle_n = dwell_n = 5: never valid (stale)", t, _ramp(t, 60, rng),
           True)
    # staleness limit edge: max_stale 10, the other window's age runs through 10 and 11
    t = _qtable("diff", "pair", settle_s=0.0, max_stale_s=10.0)
    modes = [1] * 5 + [2] * 15 + [3] * 3 + [1] * 12 + [3] * 8 + [2] * 6 + [3] * 9 + [1] * 4 + [2] * 3
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    cs.add("stale_edge_log", "log-driven, max_stale_n = 10: ages 1..15 of the other window (valid up to 10)", t, s)
    # trend slope clamp and output saturation: extreme rate words in short windows
    t = _qtable("diff", "trend", settle_s=0.0, max_stale_s=50.0)
    modes = [1, 1, 2, 2, 1, 1, 2, 2, 1, 1, 2, 2, 2, 3, 1, 1, 1, 2, 2, 2, 1]
    r = [F.INT32_SYM, F.INT32_SYM, 0, 0, -F.INT32_SYM, -F.INT32_SYM, F.INT32_SYM, F.INT32_SYM, F.INT32_SYM,
         F.INT32_SYM, -F.INT32_SYM, -F.INT32_SYM, 5, 0, -F.INT32_SYM, 3, 1, F.INT32_SYM, -1, 0, 7]
    s = {"p": np.full(len(modes), t.p_ref, np.int64), "r": np.array(r), "mode": np.array(modes)}
    cs.add("slope_clamp_log", "log-driven trend with +-(2^31 - 1) rate words in 2-sample windows: slope clamp, "
           "OUT saturation (flag 128)", t, s)
    # BIAS / OUT saturation: E = 0, B = m_0 << 21
    big = dataclasses.replace(_qtable("diff", None), e_row=(0, 0, 0, 0), e_7=0, e_acc=0,
                              mant=tuple(F.INT32_SYM if k == 0 else 0 for k in range(N_TERMS)))
    s = _ramp(big, 40, rng)
    s["r"][::3] = -F.INT32_SYM
    cs.add("bias_saturation_log", "FTR, B = (2^31 - 1) deg/h: BIAS and OUT saturate (flag 128)", big, s)
    neg = dataclasses.replace(big, mant=tuple(-m for m in big.mant))
    s = _ramp(neg, 20, rng)
    s["r"][::2] = F.INT32_SYM
    cs.add("bias_saturation_neg_log", "FTR, B = -(2^31 - 1) deg/h", neg, s)
    # long windows with extreme rates: |acc| up to 700 (2^31 - 1)
    t = _qtable("lsq", "trend", n=16, settle_s=3.0, max_stale_s=2000.0)
    modes = [3] * 5 + [1] * 700 + [3] * 4 + [2] * 700 + [3] * 2 + [1] * 60
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    s["r"] = np.where(np.arange(len(modes)) % 5 == 0, F.INT32_SYM, F.INT32_SYM - 1 - np.arange(len(modes)))
    s["restart"] = np.zeros(len(modes), np.int64)
    s["restart"][1000] = 1
    cs.add("long_windows_log", "log-driven, 700-sample windows of near-full-scale rate words (|acc| ~ 2^40.5), "
           "lsq n=16, restart inside a window", t, s)
    # long self-timed run: many short cycles
    t = _qtable("iir", "trend", shift=4, settle_s=1.0, max_stale_s=12.0, power_on_s=3.0, exchange_s=2.0,
                dwell_s=5.0)
    s = random_stream(rng, t, 2500)
    s["restart"][:] = 0
    s["restart"][[0, 1234]] = 1
    cs.add("long_timed", "self-timed, 2500 samples of exchange 2 / dwell 5 cycles (~180 windows), iir, trend, "
           "one restart", t, s, True)
    # corner streams of firmware_ref.vectors
    for est, comb in (("diff", "pair"), ("diffn", "trend"), ("lsq", None), ("iir", "trend"), ("lsq", "pair"),
                      ("iir", None)):
        t = _qtable(est, comb)
        cs.add(f"corner_{est}_{comb or 'ftr'}", "firmware_ref.vectors.corner_stream (log-driven)", t,
               corner_stream(t, reversal=comb is not None))
    t = _qtable("diffn", "pair", n=8, exchange_s=2.0, dwell_s=5.0)
    cs.add("corner_diffn_pair_timed", "firmware_ref.vectors.corner_stream words, self-timed", t,
           corner_stream(t), True)
    # regress, then reverse (order 1): two banks (bank 2 on mode-2 samples), the residual combiner
    for comb in ("pair", "trend", "none"):
        t = _qtable("diff", comb, order="regress_first", power_on_s=2.0, exchange_s=3.0, dwell_s=9.0)
        cs.add(f"rtr_{comb}_timed", f"regress_first {comb}: self-timed, power-on 2, exchange 3, dwell 9, settle 2; "
               "windows sum r = c - B of the mode's bank", t, _ramp(t, 200, rng), True)
    t = _qtable("diff", "pair", order="regress_first", settle_s=0.0, max_stale_s=10.0)
    modes = [1] * 5 + [2] * 15 + [3] * 3 + [1] * 12 + [3] * 8 + [2] * 6 + [3] * 9 + [1] * 4 + [2] * 3
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    cs.add("rtr_stale_edge_log", "regress_first pair, log-driven, max_stale_n = 10: ages 1..15 of the other window",
           t, s)
    big2 = np.array([2.0 ** 21 * 0.9] + [0.0] * (N_TERMS - 1))
    t = _qtable("diff", "trend", order="regress_first", settle_s=0.0, max_stale_s=50.0,
                coef=[1.0] + [0.0] * (N_TERMS - 1), coef2=big2)
    modes = [1, 1, 2, 2, 1, 1, 2, 2, 1, 1, 2, 2, 2, 3, 1, 1, 1, 2, 2, 2, 1]
    r = [F.INT32_SYM, F.INT32_SYM, 0, 0, -F.INT32_SYM, -F.INT32_SYM, F.INT32_SYM, F.INT32_SYM, F.INT32_SYM,
         F.INT32_SYM, -F.INT32_SYM, -F.INT32_SYM, 5, 0, -F.INT32_SYM, 3, 1, F.INT32_SYM, -1, 0, 7]
    s = {"p": np.full(len(modes), t.p_ref, np.int64), "r": np.array(r), "mode": np.array(modes)}
    cs.add("rtr_residual_saturation_log", "regress_first trend, bank 2 B = 0.9 2^21 deg/h, +-(2^31 - 1) rate "
           "words: the residual word r saturates (flag 128), slope clamp", t, s)
    t = _qtable("lsq", "pair", n=16, order="regress_first", settle_s=0.0, max_stale_s=200.0)
    modes = [1] * 30 + [2] * 30 + [1] * 30 + [2] * 30
    s = _ramp(t, len(modes), rng)
    s["mode"] = np.array(modes)
    s["restart"] = np.zeros(len(modes), np.int64)
    s["restart"][[0, 70]] = 1
    cs.add("rtr_warmup_log", "regress_first pair, lsq n=16: rate warm-up samples (after power-on and a restart "
           "inside a window) are not used (no sum, not valid)", t, s)
    for est, comb in (("diffn", "pair"), ("iir", "none"), ("lsq", "trend")):
        t = _qtable(est, comb, order="regress_first")
        cs.add(f"rtr_corner_{est}_{comb}", "regress_first: firmware_ref.vectors.corner_stream (log-driven)", t,
               corner_stream(t))
    for k in range(3):
        est = ("diff", "diffn", "iir")[k]
        t = quantize(random_model(rng, estimator=est, order="regress_first"), exchange_s=3.0, dwell_s=7.0,
                     n_random=10).table
        cs.add(f"rtr_random_{k}", f"firmware_ref.vectors.random_model(order='regress_first', {est}, combiner "
               f"{F.COMBINERS[t.combiner]}) and random_stream{', self-timed' if k == 1 else ''}", t,
               random_stream(rng, t, 500), k == 1)
    # random models and streams
    for k in range(4):
        reversal = k != 3
        est = ("diff", "diffn", "lsq", "iir")[k]
        t = quantize(random_model(rng, reversal=reversal, estimator=est), exchange_s=3.0, dwell_s=7.0,
                     n_random=10).table
        timed = k == 1
        cs.add(f"random_{k}", f"firmware_ref.vectors.random_model ({est}) and random_stream"
               f"{', self-timed' if timed else ''}", t, random_stream(rng, t, 500, reversal=reversal), timed)
    vs = VectorSet("sequencer", "the whole pipeline (sequencer, combiner, proxy, rate, evaluator, outputs): inputs "
                   "F T R MODE RESTART Z (MODE -1: self-timed), outputs the 16 fields of the protocol's O line",
                   cs.columns(), SEQ_INPUTS, SEQ_FIELDS, cs.cases, cs.tables)
    compute_pipeline(vs, rows=False)
    return vs


# -- end to end --------------------------------------------------------------------------------------

E2E_RUNS = (
    # name, scenario, seed, duration [s], description, reversal (order, combiner) or None
    ("ftr", "paper-ftr-cycle-4dpm", 11, 2400.0, "FTR, -20..20 degC cycles at 4 degC/min", None),
    ("mode_reversal", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal 30/120 s, cycles at 4 degC/min, "
     "combine_first pair (legacy)", ("combine_first", "pair")),
    ("regress_first_pair", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal, regress_first pair (two banks)",
     ("regress_first", "pair")),
    ("regress_first_none", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal, regress_first none (two banks)",
     ("regress_first", "none")),
    ("regress_first_trend", "paper-mr-cycle-4dpm", 12, 2400.0, "mode reversal, regress_first trend (two banks)",
     ("regress_first", "trend")),
)


def _round_sig(x: float, digits: int = 7) -> float:
    return float(f"{float(x):.{digits}g}")


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return repr(float(x))
    if isinstance(x, np.integer):
        return int(x)
    return x


def e2e_model(log, reversal=None):
    """The model of a run: fit_config_from_logs (rounded to 7 significant digits; ``reversal`` an
    (order, combiner) pair for a mode-reversal log), fit_logs with it, coefficients (both banks)
    rounded to 7 significant digits; returns (model, table)."""
    from host_tools import compensate as hc
    from host_tools.fit import fit_logs
    from host_tools.model import BiasModel, ModelConfig
    from host_tools.proxy import ProxyConfig
    from host_tools.quantize import quantize
    from host_tools.rate import RateConfig

    from host_tools.reversal import ReversalConfig

    rev = None if reversal is None else ReversalConfig(reversal[1], order=reversal[0])
    cfg0 = hc.fit_config_from_logs([log], reversal=rev)
    cfg = ModelConfig(ProxyConfig(cfg0.proxy.kind, _round_sig(cfg0.proxy.ref), _round_sig(cfg0.proxy.span)),
                      RateConfig(cfg0.rate.estimator, cfg0.rate.n, cfg0.rate.shift, _round_sig(cfg0.rate.span),
                                 cfg0.rate.fs), cfg0.reversal, cfg0.aux)
    fitted, _ = fit_logs([log], cfg)
    coef = np.array([_round_sig(c) for c in fitted.coef], np.float64)
    coef2 = None if fitted.coef_mode2 is None else np.array([_round_sig(c) for c in fitted.coef_mode2], np.float64)
    model = BiasModel(cfg, fitted.terms, coef, source=f"<vectors e2e {log.source}>", coef_mode2=coef2)
    return model, quantize(model, n_random=10).table


def e2e_set() -> tuple:
    """(VectorSet, configuration dict)."""
    from firmware_ref import inputs
    from firmware_ref.compensate import log_words
    from host_tools.sim import simulate

    cs = _Cases()
    config = {}
    for name, scenario, seed, duration, desc, reversal in E2E_RUNS:
        log = simulate(scenario, seed=seed, duration_s=duration)
        model, table = e2e_model(log, reversal)
        w = log_words(log, model.config)
        other = (inputs.temp_words(log["temp_c"]) if table.proxy_kind == 0 else inputs.freq_words(log["freq_hz"]))[0]
        cs.add(name, f"{desc}: host_tools.sim.simulate({scenario!r}, seed={seed}, duration_s={duration:g}), "
               f"fitted, quantized; log-driven", table, w, t_words=other)
        config[name] = {"scenario": scenario, "seed": seed, "duration_s": repr(duration),
                        "model": {"config": model.config.to_dict(), "terms": list(model.terms),
                                  "coef": list(model.coef),
                                  **({"coef_mode2": list(model.coef_mode2)} if model.coef_mode2 is not None
                                     else {})},
                        "input_saturated_samples": int(np.count_nonzero(w["input_sat"]))}
    vs = VectorSet("e2e", "simulated chamber runs through the whole pipeline with every intermediate: the "
                   "sequencer set's columns plus the evaluator's Horner rows (row0..row3, zterm, t at 2^-E)",
                   cs.columns(), SEQ_INPUTS, E2E_FIELDS, cs.cases, cs.tables)
    compute_pipeline(vs, rows=True)
    return vs, _jsonable(config)


# -- aux generators ----------------------------------------------------------------------------------------

def _aux_table(base, terms, fracs=()) -> Table:
    """``base`` (aux_gen 0) with aux_gen 1 terms (firmware_ref.table.AuxTerm) and channel fracs."""
    from firmware_ref.table import encode_aux

    return dataclasses.replace(base, aux_gen=1, aux_params=encode_aux(tuple(fracs), tuple(terms)))


def _one_kind(base_model, term, fs=1.0):
    """The quantized table of ``base_model`` with a single generator term of weight 1 (z = g)."""
    from firmware_ref.vectors import with_aux

    return quantize_aux(with_aux(base_model, [{**term, "weight": 1.0}]))


def _aux_steps(table, n, rng, step_every=175, reversal=True) -> dict:
    """A stream whose channel words, for each input term, cycle every ``step_every`` samples through
    +1.2 spans (a step: filters settle, clamps), a ramp from -1.1 to +1.1 spans, -1.2 spans, and a
    random walk (aux_stream); modes of a short reversal cycle, K = i."""
    from firmware_ref.vectors import aux_stream

    s = aux_stream(rng, table, n, reversal=reversal, extreme=0.0, k_jumps=False)
    info = table.aux()
    i = np.arange(n)
    phase = (i // step_every) % 4
    level = np.select([phase == 0, phase == 1, phase == 2],
                      [1.2, -1.1 + 2.2 * (i % step_every) / step_every, -1.2], np.nan)
    chans = {0: s["f"], 1: s["t"]}
    for c in range(info.n_chan):
        chans[2 + c] = s["aux"][:, c]
    for tm in info.terms:
        if tm.kind == 0:
            span = (2.0 ** 30) * 2.0 ** tm.c[3] / tm.c[1]
            lo, hi = (0, F.UINT32_MAX) if tm.src == 0 else (-F.INT32_SYM, F.INT32_SYM)
            set_ = ~np.isnan(level)
            chans[tm.src][set_] = np.clip(np.round(tm.c[0] + level[set_] * span), lo, hi).astype(np.int64)
    s["p"] = chans[table.proxy_kind]
    if reversal:
        s["mode"] = np.resize(np.array([3] * 4 + [1] * 12 + [3] * 4 + [2] * 12), n)
    return s


def aux_set(rng) -> VectorSet:
    from firmware_ref.table import AuxTerm
    from firmware_ref.vectors import aux_stream, make_model, random_aux_model, with_aux

    cs = _Cases()
    base_model = make_model(coef=[3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1,
                                  6e1, -5e1], settle_s=2.0, max_stale_s=25.0)
    temp_model = make_model("temp", ref=20.0, span=30.0, estimator="lsq", n=5, rate_span=0.5, combiner="trend",
                            settle_s=1.0, max_stale_s=25.0)
    # every kind alone, weight 1: z = g
    singles = [
        ("input_proxy", base_model, {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0},
         "the proxy itself (z = u)"),
        ("input_proxy_u5_sign", base_model, {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0,
                                             "power": 5, "sign": True}, "s u^5"),
        ("input_lag_freq", base_model, {"gen": "input", "column": "freq_hz", "ref": 6227.5, "span": 2.0, "tau_s": 37.0,
                                        "power": 2}, "the proxy lagged by 37 samples, squared"),
        ("input_temp_long_lag", base_model, {"gen": "input", "column": "temp_c", "ref": 25.0, "span": 40.0,
                                             "tau_s": 16384.0}, "temperature word (not the proxy) through a "
                                                                  "2^14-sample filter: no dead band"),
        ("input_temp_short_lag", base_model, {"gen": "input", "column": "temp_c", "ref": -5.0, "span": 0.5,
                                              "tau_s": 0.0625}, "the shortest legal filter (1/16 sample)"),
        ("input_aux_word", base_model, {"gen": "input", "column": "aux_vdd", "ref": 3.3, "span": 0.05, "tau_s": 5.0,
                                        "power": 3, "sign": True}, "aux word A0 (AF from the range), s y^3"),
        ("input_freq_of_temp_model", temp_model, {"gen": "input", "column": "freq_hz", "ref": 6227.0, "span": 3.0},
         "temp proxy table reading the F word"),
        ("rate_sign", base_model, {"gen": "rate", "column": "freq_hz", "estimator": "diff", "span": 0.01,
                                   "sign": True}, "s v with its own span"),
        ("rate_lsq", temp_model, {"gen": "rate", "column": "temp_c", "estimator": "lsq", "n": 5, "span": 0.05},
         "the lsq rate sum with another span"),
        ("one_sign", base_model, {"gen": "one", "sign": True}, "s"),
        ("decay_on_short", base_model, {"gen": "decay_on", "tau_s": 4.0}, "decay since power-on / restarts, 4 samples"),
        ("decay_on_long", base_model, {"gen": "decay_on", "tau_s": 3.0e6}, "3 10^6 samples"),
        ("decay_exchange", base_model, {"gen": "decay_exchange", "tau_s": 6.0}, "decay since the last exchange"),
        ("decay_exchange_sign", base_model, {"gen": "decay_exchange", "tau_s": 2.5, "sign": True}, "s times it"),
        ("ramp", base_model, {"gen": "ramp", "n_samples": 300}, "k / 300, 1 from K = 300 on"),
        ("osc_sin", base_model, {"gen": "osc", "period_s": 7.3, "part": "sin"}, "sin, 7.3-sample period"),
        ("osc_cos", base_model, {"gen": "osc", "period_s": 86400.0, "part": "cos"}, "cos, 1-day period"),
    ]
    for name, model, term, desc in singles:
        t = _one_kind(model, term)
        s = _aux_steps(t, 700, rng, reversal=True)
        s["restart"][[350, 351, 520]] = 1
        cs.add(f"single_{name}", f"one term, weight 1 (z = g): {desc}; channel words cycle through +1.2 spans, a "
               f"ramp, -1.2 spans and a random walk (175 samples each), restarts at 350, 351, 520", t, s)
    # K: gaps, negative start, near 2^62 (osc wrap, ramp)
    t = _one_kind(base_model, {"gen": "osc", "period_s": 3.1, "part": "sin"})
    t2 = _aux_table(t, (AuxTerm(6, 0, 0, 1, 1 << 29, (1, 0, 1, 0, 0, 0)),
                        AuxTerm(6, 0, 0, 1, -(1 << 29), ((1 << 63) - 1, 0, 0, 0, 0, 0))))
    for name, tab in (("osc_k_edges", t), ("osc_w_extremes", t2)):
        s = aux_stream(rng, tab, 400, extreme=0.0, k_jumps=True)
        s["k"][:40] = np.arange(-20, 20)
        s["k"][40:80] = F.K_LIMIT - 40 + np.arange(40)
        s["k"][80:90] = -F.K_LIMIT
        cs.add(name, "oscillators at K = -20..19, 2^62 - 40 .. 2^62 - 1, -2^62 and random gaps "
               + ("(period 3.1 samples)" if tab is t else "(W = 1 cos, W = 2^63 - 1 sin)"), tab, s)
    t = _one_kind(base_model, {"gen": "ramp", "n_samples": 2 ** 31 - 1})
    s = aux_stream(rng, t, 200, extreme=0.0, k_jumps=True)
    s["k"][:50] = np.r_[np.arange(-5, 20), (1 << 31) - 14 + np.arange(25)]
    cs.add("ramp_longest", "ramp N = 2^31 - 1 around K = 0 and K = N", t, s)
    # weight-sum clamp (flag 32) and coefficient extremes (hand-made tables)
    base = _one_kind(base_model, {"gen": "one"})
    clamp_t = _aux_table(base, (AuxTerm(2, 0, 0, 1, (1 << 29) + 1, (0,) * 6),
                                AuxTerm(2, 1, 0, 1, (1 << 29) + 1, (0,) * 6)))
    cs.add("weight_sum_clamp", "two 'one' terms of weight 2^29 + 1 (sum |w| = 2^30 + 2): z = 2^30 + 2 is "
           "clamped (flag 32) in modes 0/1", clamp_t, aux_stream(rng, clamp_t, 150, extreme=0.0))
    lim = F.INT32_SYM
    ext_terms = (AuxTerm(0, 0, 2, 5, 1 << 28, (-lim, lim, lim // 2, 62, lim, 31)),
                 AuxTerm(0, 1, 0, 1, -(1 << 28), (F.UINT32_MAX, 1, 0, 0, 1, 62)),
                 AuxTerm(3, 0, 0, 1, 1 << 27, (lim, 31, 0, 0, 0, 0)),
                 AuxTerm(4, 1, 0, 1, -(1 << 27), (1, 62, 0, 0, 0, 0)),
                 AuxTerm(5, 0, 0, 1, 1 << 27, (1, lim, 0, 0, 0, 0)),
                 AuxTerm(0, 0, 5, 4, (1 << 27) + 1, (0, 1 << 30, 0, 1, 1 << 30, 40)))
    ext = _aux_table(base, ext_terms, fracs=(0, 48, 17, 30))
    s = aux_stream(rng, ext, 600, extreme=0.05)
    cs.add("coefficient_extremes", "hand-made: REF -(2^31 - 1) with G 2^31 - 1, SH 62, B 2^31 - 1 at SB 31, "
           "power 5; REF 2^32 - 1 with G 1, B 1 at SB 62; decays at B = 2^31 - 1 / SB 31 and B = 1 / SB 62; "
           "ramp N = 1; A3 power 4; AF 0, 48, 17, 30", ext, s)
    # the four aux words at very different scales (AF from 48 down to a few bits)
    words = [{"gen": "input", "column": col, "ref": ref, "span": span, "tau_s": tau, "weight": 0.25}
             for col, ref, span, tau in (("aux_a", 2.0e-7, 5.0e-8, 0.0), ("aux_b", 3.3, 0.05, 12.0),
                                         ("aux_c", -150.0, 40.0, 0.0), ("aux_d", 2.5e5, 1.0e4, 300.0))]
    t = quantize_aux(with_aux(base_model, words))
    cs.add("aux_words", f"four input terms on A0..A3 (AF {', '.join(map(str, t.aux().fracs))}), two filtered", t,
           _aux_steps(t, 700, rng))
    # random multi-term tables
    for j in range(6):
        reversal = j != 4
        est = ("diff", "diffn", "lsq", "iir", "diff", "lsq")[j]
        model = random_aux_model(rng, reversal=reversal, estimator=est, n_terms=[6, 6, 4, 3, 5, 6][j])
        t = quantize_aux(model)
        timed = j == 5
        cs.add(f"random_{j}", f"firmware_ref.vectors.random_aux_model ({est}, {len(t.aux().terms)} terms) and "
               f"aux_stream{', self-timed' if timed else ''}", t, aux_stream(rng, t, 500, reversal=reversal), timed)
    # a simulated run with a fitted aux model
    case, cfg = aux_sim_case()
    cs.add(*case)
    vs = VectorSet("aux", "tables with aux generators (aux_gen 1): inputs F T R MODE RESTART Z K A0 A1 A2 A3 (MODE "
                   "-1: self-timed), outputs the 16 fields of the protocol's O line (z: the generated z)",
                   cs.columns(), AUX_INPUTS, AUX_FIELDS, cs.cases, cs.tables)
    vs.config = cfg
    compute_pipeline(vs, rows=False)
    return vs


def quantize_aux(model) -> Table:
    from host_tools.quantize import quantize

    return quantize(model, exchange_s=3.0, dwell_s=7.0, n_random=10).table


AUX_SIM = ("paper-mr-cycle-4dpm", 13, 2400.0, {"turn_on": {"amp_dph": 3.0, "tau_s": 300.0}})


def aux_sim_case() -> tuple:
    """(the arguments of _Cases.add, configuration) of the simulated aux run: host_tools.sim with an
    undeclared turn-on transient, a model with a decay_on, a lagged-proxy and a board-temperature
    term (fixed generator parameters), fitted, rounded to 7 significant digits, quantized."""
    import warnings as _warnings

    from firmware_ref.compensate import log_words
    from host_tools import compensate as hc
    from host_tools.fit import fit_logs
    from host_tools.model import BiasModel, ModelConfig
    from host_tools.proxy import ProxyConfig
    from host_tools.rate import RateConfig
    from host_tools.regressors import AuxConfig
    from host_tools.sim import simulate

    scenario, seed, duration, undeclared = AUX_SIM
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore")
        log = simulate(scenario, seed=seed, duration_s=duration, undeclared=undeclared)
    from host_tools.reversal import ReversalConfig

    cfg0 = hc.fit_config_from_logs([log], reversal=ReversalConfig("pair", order="combine_first"))
    tr = (float(np.min(log["temp_c"])), float(np.max(log["temp_c"])))
    terms = [{"gen": "decay_on", "tau_s": 300.0, "weight": 0.5},
             {"gen": "input", "column": cfg0.proxy.column, "ref": _round_sig(cfg0.proxy.ref),
              "span": _round_sig(cfg0.proxy.span), "tau_s": 900.0, "weight": -0.25},
             {"gen": "input", "column": "temp_c", "ref": _round_sig(0.5 * (tr[0] + tr[1])),
              "span": _round_sig(0.6 * (tr[1] - tr[0])), "tau_s": 60.0, "weight": 0.25, "sign": True}]
    cfg = ModelConfig(ProxyConfig(cfg0.proxy.kind, _round_sig(cfg0.proxy.ref), _round_sig(cfg0.proxy.span)),
                      RateConfig(cfg0.rate.estimator, cfg0.rate.n, cfg0.rate.shift, _round_sig(cfg0.rate.span),
                                 cfg0.rate.fs), cfg0.reversal, AuxConfig.from_terms(terms, cfg0.rate.fs))
    fitted, _ = fit_logs([log], cfg, tuple(range(17)))
    coef = np.array([_round_sig(c) for c in fitted.coef], np.float64)
    model = BiasModel(cfg, fitted.terms, coef, source="<vectors aux sim>")
    table = quantize_aux(model)
    w = log_words(log, cfg)
    s = {"p": w["p"], "r": w["r"], "mode": w["mode"], "restart": w["restart"], "z": w["z"], "f": w["f"],
         "t": w["t"], "aux": np.zeros((len(log), 0), np.int64), "k": w["k"]}
    desc = (f"host_tools.sim.simulate({scenario!r}, seed={seed}, duration_s={duration:g}, undeclared={undeclared}); "
            f"aux decay_on + lagged proxy + s x lagged board temperature, fitted, quantized; log-driven")
    config = {"scenario": scenario, "seed": seed, "duration_s": repr(duration), "undeclared": undeclared,
              "model": {"config": cfg.to_dict(), "terms": list(model.terms), "coef": list(model.coef)}}
    return ("sim_aux", desc, table, s), _jsonable(config)


# -- generate -----------------------------------------------------------------------------------------

def build_sets(names=SETS) -> tuple:
    """(list of VectorSet, configuration) for the named sets (deterministic)."""
    unknown = [n for n in names if n not in SETS]
    if unknown:
        raise ValueError(f"unknown vector set(s) {', '.join(unknown)}; sets: {', '.join(SETS)}")
    seeds = {name: SEED + k for k, name in enumerate(SETS)}
    out, config = [], {"seeds": seeds, "py_check_samples_per_case": PY_CHECK}
    for name in SETS:
        if name not in names:
            continue
        rng = np.random.default_rng(seeds[name])
        if name == "primitives":
            out.append(primitives_set(rng))
        elif name == "evaluator":
            out.append(evaluator_set(rng))
        elif name == "sequencer":
            out.append(sequencer_set(rng))
        elif name == "e2e":
            vs, cfg = e2e_set()
            config["e2e"] = cfg
            out.append(vs)
        else:
            vs = aux_set(rng)
            config["aux"] = vs.config
            out.append(vs)
    return out, config


def _table_entry(t: Table) -> dict:
    words = t.to_words()
    return {"crc32": f"{words[-1]:08x}", "words": [f"{w:08x}" for w in words], "fields": t.field_values()}


def _offsets(tables) -> list:
    """First word of each table in <set>.tables.mem (the tables are concatenated)."""
    out, at = [], 0
    for t in tables:
        out.append(at)
        at += len(t.to_words())
    return out


def make_manifest(sets, config, files: dict) -> dict:
    fp = source_fingerprint()
    return {
        "format": "hdrg-vectors",
        "format_version": FORMAT_VERSION,
        "generator": "hdrg vectors (host_tools/vectors.py)",
        "generator_version": GENERATOR_VERSION,
        "sources_sha256": fp["sha256"],
        "sources": fp["files"],
        "configuration": config,
        "protocol": "firmware_ref/c/README.md 'Driver protocol' (copied in vectors/README.md)",
        "sets": {vs.name: {
            "description": vs.description,
            "rows": len(vs),
            "csv": f"{vs.name}.csv",
            "columns": list(vs.columns),
            "inputs": list(vs.inputs),
            "mem": f"{vs.name}.mem",
            "mem_record": [{"name": n, "bits": b} for n, b in vs.mem_fields],
            "mem_record_bits": sum(b for _, b in vs.mem_fields),
            "tables_mem": f"{vs.name}.tables.mem" if vs.tables else None,
            # words per table when every table of the set has the same length (aux_gen 0: 48), else None
            # (the aux set: each table's length is its word 2 and the length of its manifest entry)
            "table_words": (len(vs.tables[0].to_words())
                            if vs.tables and len({len(t.to_words()) for t in vs.tables}) == 1 else None),
            "table_offsets": _offsets(vs.tables),
            "op_codes": list(PRIM_OPS) if vs.name == "primitives" else None,
            "cases": vs.cases,
            "tables": [_table_entry(t) for t in vs.tables],
        } for vs in sets},
        "files": {name: {"sha256": _sha256(data), "bytes": len(data)} for name, data in sorted(files.items())},
    }


def dump_manifest(manifest: dict) -> bytes:
    return (json.dumps(manifest, indent=1, sort_keys=True) + "\n").encode()


def render_all(sets, config) -> dict:
    """file name -> bytes, manifest.json included."""
    files = {}
    for vs in sets:
        files.update(vs.files())
    files["manifest.json"] = dump_manifest(make_manifest(sets, config, files))
    return files


def read_manifest(directory) -> dict:
    path = Path(directory) / "manifest.json"
    if not path.is_file():
        raise VectorsError(f"{path}: no manifest (generate the vectors with `hdrg vectors generate -o DIR`)")
    try:
        m = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise VectorsError(f"{path}: not JSON ({exc})") from None
    if m.get("format") != "hdrg-vectors":
        raise VectorsError(f"{path}: format {m.get('format')!r} is not 'hdrg-vectors'")
    if m.get("format_version") != FORMAT_VERSION:
        raise VectorsError(f"{path}: format_version {m.get('format_version')} is not supported (this reads "
                           f"{FORMAT_VERSION})")
    return m


def generate(directory, names=SETS, force: bool = False) -> dict:
    """Write the vectors into ``directory``; returns the manifest.  Refuses (VectorsError) to change
    an existing vector file without a version bump unless ``force``; files of the old manifest
    that the new one does not list are removed."""
    directory = Path(directory)
    sets, config = build_sets(names)
    files = render_all(sets, config)
    new = json.loads(files["manifest.json"])
    old = None
    if (directory / "manifest.json").is_file():
        try:
            old = read_manifest(directory)
        except VectorsError:
            old = None
    if old is not None and not force and (old.get("generator_version"), old.get("format_version")) == \
            (GENERATOR_VERSION, FORMAT_VERSION):
        changed = sorted(name for name, meta in new["files"].items()
                         if name in old.get("files", {}) and old["files"][name]["sha256"] != meta["sha256"])
        if changed:
            raise VectorsError(f"{directory}: the vectors changed ({', '.join(changed)}) but GENERATOR_VERSION "
                               f"{GENERATOR_VERSION} and FORMAT_VERSION {FORMAT_VERSION} are those of the existing "
                               f"manifest: bump GENERATOR_VERSION (host_tools/vectors.py) or pass --force")
    directory.mkdir(parents=True, exist_ok=True)
    if old is not None:
        for name in old.get("files", {}):
            if name not in new["files"] and (directory / name).is_file() and "/" not in name:
                (directory / name).unlink()
    for name, data in files.items():
        (directory / name).write_bytes(data)
    return new


# -- verify -------------------------------------------------------------------------------------------

def _set_order(manifest: dict, names=None) -> list:
    """The manifest's sets in SETS order (then any others), restricted to ``names``; ValueError
    for a name the manifest lacks."""
    have = manifest["sets"]
    if names:
        missing = [n for n in names if n not in have]
        if missing:
            raise ValueError(f"set(s) {', '.join(missing)} not in the vectors (sets: {', '.join(have)})")
    order = [n for n in SETS if n in have] + sorted(n for n in have if n not in SETS)
    return [n for n in order if not names or n in names]


def _load_set(directory: Path, name: str, meta: dict) -> VectorSet:
    """A set from its files: columns of the CSV, tables of the .tables.mem (checked against the
    manifest's words)."""
    cols = parse_csv((directory / meta["csv"]).read_bytes(), str(directory / meta["csv"]))
    if list(cols) != meta["columns"]:
        raise VectorsError(f"{directory / meta['csv']}: columns {list(cols)} differ from the manifest's")
    tables = []
    if meta.get("tables_mem"):
        text = (directory / meta["tables_mem"]).read_text().split()
        sizes = [len(entry["words"]) for entry in meta["tables"]]
        if len(text) != sum(sizes):
            raise VectorsError(f"{directory / meta['tables_mem']}: {len(text)} words, expected "
                               f"{sum(sizes)} ({len(sizes)} tables)")
        at = 0
        for k, entry in enumerate(meta["tables"]):
            words = [int(w, 16) for w in text[at:at + sizes[k]]]
            at += sizes[k]
            if [f"{w:08x}" for w in words] != entry["words"]:
                raise VectorsError(f"{directory / meta['tables_mem']}: table {k} differs from the manifest's")
            try:
                tables.append(Table.from_words(words, f"{meta['tables_mem']} table {k}"))
            except TableError as exc:
                raise VectorsError(str(exc)) from None
    inputs = tuple(meta["inputs"])
    mem_fields = tuple((f["name"], f["bits"]) for f in meta["mem_record"])
    return VectorSet(name, meta["description"], cols, inputs, mem_fields, meta["cases"], tables)


def _first_diff(name: str, meta: dict, got: dict, want: dict) -> str:
    """Text of the first row where the recomputed columns differ from the file's."""
    n = len(next(iter(want.values())))
    bad = np.zeros(n, bool)
    for col in want:
        if col in got and len(got[col]) == n:
            bad |= got[col] != want[col]
    if not bad.any():
        return f"set {name}: the files differ from the re-rendered values (format, not values)"
    i = int(np.argmax(bad))
    return _describe_row(name, meta, want, i) + "\n  " + "; ".join(
        f"{col}: file {want[col][i]}, recomputed {got[col][i]}" for col in want if got[col][i] != want[col][i])


def _describe_row(name: str, meta: dict, cols: dict, i: int) -> str:
    ins = " ".join(f"{k}={PRIM_OPS[cols[k][i]] if k == 'op' else cols[k][i]}" for k in meta["inputs"]
                   if k not in ("case", "i"))
    case = ""
    if "case" in cols:
        c = meta["cases"][int(cols["case"][i])]
        case = f" (case {c['name']}"
        case += f", sample {cols['i'][i]})" if "i" in cols else ")"
    return f"set {name}, row {i}{case}: inputs {ins}"


def verify(directory, names=None, log=print) -> list:
    """Check the SHA-256 of every file, then recompute every set from its inputs and diff; returns
    the list of problems (empty: the vectors are correct).  Prints progress with ``log``."""
    directory = Path(directory)
    manifest = read_manifest(directory)
    problems = []
    for fname, meta in manifest["files"].items():
        path = directory / fname
        if not path.is_file():
            problems.append(f"{path}: missing")
            continue
        data = path.read_bytes()
        if _sha256(data) != meta["sha256"] or len(data) != meta["bytes"]:
            problems.append(f"{path}: SHA-256 {_sha256(data)[:16]}... differs from the manifest's "
                            f"{meta['sha256'][:16]}... (file changed)")
    fp = source_fingerprint()
    if fp["sha256"] != manifest.get("sources_sha256"):
        changed = sorted(k for k in set(fp["files"]) | set(manifest.get("sources", {}))
                         if fp["files"].get(k) != manifest.get("sources", {}).get(k))
        log(f"note: the algorithm sources differ from those the vectors were generated from "
            f"({', '.join(changed)}); the recomputation below decides")
    for name in _set_order(manifest, names):
        meta = manifest["sets"][name]
        try:
            vs = _load_set(directory, name, meta)
        except (VectorsError, OSError) as exc:
            problems.append(str(exc))
            continue
        want = dict(vs.columns)
        try:
            if name == "primitives":
                compute_primitives(vs)
            elif name == "evaluator":
                compute_evaluator(vs)
            else:
                compute_pipeline(vs, rows=name == "e2e", check_python=50)
        except VectorsError as exc:
            problems.append(str(exc))
            continue
        same = list(vs.columns) == list(want) and all(np.array_equal(vs.columns[c], want[c]) for c in want)
        files = vs.files()
        disk = {f: (directory / f).read_bytes() for f in files}
        if not same or any(files[f] != disk[f] for f in files):
            problems.append(_first_diff(name, meta, vs.columns, want))
            log(f"{name}: {len(want[next(iter(want))])} rows: MISMATCH")
        else:
            log(f"{name}: {len(vs)} rows, {len(vs.cases)} cases: recomputed, identical")
    return problems


def staleness(directory=DEFAULT_DIR, regenerated: dict | None = None) -> list:
    """Problems that make committed vectors stale: the algorithm sources changed since they were
    generated, or a regeneration (file name -> bytes, default: generate now) differs from them."""
    directory = Path(directory)
    manifest = read_manifest(directory)
    problems = []
    fp = source_fingerprint()
    if fp["sha256"] != manifest.get("sources_sha256"):
        changed = sorted(k for k in set(fp["files"]) | set(manifest.get("sources", {}))
                         if fp["files"].get(k) != manifest.get("sources", {}).get(k))
        problems.append(f"algorithm sources changed since generation: {', '.join(changed)}")
    if regenerated is None:
        regenerated = render_all(*build_sets())
    for fname, data in regenerated.items():
        path = directory / fname
        if not path.is_file():
            problems.append(f"{fname}: not in {directory}")
        elif path.read_bytes() != data:
            problems.append(f"{fname}: regenerated bytes differ from {path}")
    return problems


# -- check-impl ---------------------------------------------------------------------------------------

def _requests(vs: VectorSet, fields) -> list:
    """(request line, expected response tokens, row index or None, compared token positions)."""
    c = vs.columns
    reqs = []
    if vs.name == "primitives":
        for i in range(len(vs)):
            op = PRIM_OPS[c["op"][i]]
            args = [c["a"][i], c["b"][i], c["c"][i]][:PRIM_ARITY[op]]
            exp = ["R", str(c["result"][i])] + ([str(c["flag"][i])] if op in PRIM_FLAGGED else [])
            reqs.append((f"{op} " + " ".join(map(str, args)), exp, i, None))
        return reqs
    pos = None if fields is None else [0] + [1 + O_NAMES.index(f) for f in fields]
    for case in vs.cases:
        t = vs.tables[case["table"]]
        words = t.to_words()
        reqs.append(("TABLE " + " ".join(f"{w:08x}" for w in words), ["T", str(len(words)), f"{words[-1]:08x}"],
                     None, None))
        lo, hi = case["rows"]
        if vs.name == "evaluator":
            for i in range(lo, hi):
                bank = f" {c['bank'][i]}" if c["bank"][i] != 1 else ""
                reqs.append((f"EVAL {c['u'][i]} {c['v'][i]} {c['z'][i]}{bank}", ["E", str(c["b"][i]),
                                                                                 str(c["zclamped"][i])], i, None))
        else:
            fin = AUX_IN_FIELDS if "K" in c else IN_FIELDS
            arr = np.stack([c[n] for n, _ in fin] + [c[n] for n in O_NAMES], axis=1)[lo:hi].tolist()
            w = len(fin)
            for k, row in enumerate(arr):
                reqs.append(("S " + " ".join(map(str, row[:w])), ["O"] + [str(x) for x in row[w:]], lo + k, pos))
    return reqs


def check_impl(cmd, directory=DEFAULT_DIR, names=None, fields=None, timeout: float = 600.0, log=print) -> dict:
    """Drive the program ``cmd`` (a command line, split like a POSIX shell; one process per set)
    through the protocol with every set's requests and compare its answers with the vectors.
    ``fields``: compare only these O fields of the pipeline sets (default all 16).  Returns
    ``{"sets": {name: {"requests", "rows", "mismatches", "first"}}, "mismatches": total,
    "first": text of the first mismatch or None}``."""
    directory = Path(directory)
    argv = shlex.split(cmd) if isinstance(cmd, str) else list(cmd)
    if not argv:
        raise ValueError("--cmd is empty")
    if fields is not None:
        bad = [f for f in fields if f not in O_NAMES]
        if bad:
            raise ValueError(f"--fields: unknown field(s) {', '.join(bad)}; fields: {', '.join(O_NAMES)}")
    manifest = read_manifest(directory)
    corrupt = [f for f, meta in manifest["files"].items()
               if not (directory / f).is_file() or _sha256((directory / f).read_bytes()) != meta["sha256"]]
    if corrupt:
        raise VectorsError(f"{directory}: files missing or changed since generation ({', '.join(corrupt)}); "
                           f"run `hdrg vectors verify`")
    report = {"sets": {}, "mismatches": 0, "first": None}
    for name in _set_order(manifest, names):
        meta = manifest["sets"][name]
        vs = _load_set(directory, name, meta)
        reqs = _requests(vs, fields)
        data = "".join(r[0] + "\n" for r in reqs) + "QUIT\n"
        try:
            pr = subprocess.run(argv, input=data.encode(), capture_output=True, timeout=timeout)
        except FileNotFoundError:
            raise ValueError(f"--cmd: program {argv[0]!r} not found") from None
        except subprocess.TimeoutExpired:
            raise ValueError(f"--cmd: {argv[0]} did not finish set {name} within {timeout:g} s") from None
        got = pr.stdout.decode(errors="replace").splitlines()
        nbad, first = 0, None
        for k, (line, exp, row, pos) in enumerate(reqs):
            ans = got[k].split() if k < len(got) else None
            if ans is not None and (ans == exp if pos is None else
                                    len(ans) == len(exp) and all(ans[p] == exp[p] for p in pos)):
                continue
            nbad += 1
            if first is None:
                where = (_describe_row(name, meta, vs.columns, row) if row is not None
                         else f"set {name}, table request {k}")
                if ans is None:
                    gtxt = (f"(no answer: the program exited with status {pr.returncode}; stderr: "
                            f"{pr.stderr.decode(errors='replace').strip()[-300:]!r})")
                else:
                    gtxt = got[k]
                first = f"{where}\n  request:  {line[:200]}\n  expected: {' '.join(exp)}\n  got:      {gtxt}"
                if ans is not None and exp[0] == "O" and len(ans) == len(exp):
                    diff = [f"{O_NAMES[p - 1]} {exp[p]} != {ans[p]}" for p in range(1, len(exp))
                            if ans[p] != exp[p] and (pos is None or p in pos)]
                    first += "\n  fields:   " + ", ".join(diff)
        rows = sum(1 for r in reqs if r[2] is not None)
        report["sets"][name] = {"requests": len(reqs), "rows": rows, "mismatches": nbad, "first": first}
        report["mismatches"] += nbad
        if report["first"] is None and first is not None:
            report["first"] = first
        log(f"{name}: {len(reqs)} requests ({rows} vectors), {nbad} mismatches"
            + (f" (exit status {pr.returncode})" if pr.returncode not in (0,) else ""))
    return report


# -- CLI ----------------------------------------------------------------------------------------------

def configure_cli(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    g = sub.add_parser("generate", help="generate the vectors into a directory")
    g.add_argument("-o", "--output", default="vectors", help="output directory (default: vectors/)")
    g.add_argument("--force", action="store_true", help="overwrite changed vectors without a version bump")
    v = sub.add_parser("verify", help="check the SHA-256s and recompute every vector from its inputs")
    v.add_argument("directory", nargs="?", default="vectors", help="vectors directory (default: vectors/)")
    v.add_argument("--sets", default=None, help="comma list of sets (default all)")
    c = sub.add_parser("check-impl", help="drive an external implementation through the stdin/stdout protocol "
                                          "(vectors/README.md) and compare")
    c.add_argument("--cmd", required=True, help="the program and its arguments, e.g. './hdrg_fw'")
    c.add_argument("directory", nargs="?", default="vectors", help="vectors directory (default: vectors/)")
    c.add_argument("--sets", default=None, help="comma list of sets (default all)")
    c.add_argument("--fields", default=None, help=f"compare only these O fields of the pipeline sets "
                                                  f"(default all: {','.join(O_NAMES)})")
    c.add_argument("--timeout", type=float, default=600.0, help="seconds per set (default 600)")


def _names(text):
    return None if text is None else [s.strip() for s in text.split(",") if s.strip()]


def run_cli(args) -> int:
    if args.action == "generate":
        m = generate(args.output, force=args.force)
        total = sum(f["bytes"] for f in m["files"].values())
        for name, s in m["sets"].items():
            print(f"{name}: {s['rows']} rows, {len(s['cases'])} cases")
        print(f"wrote {len(m['files']) + 1} files ({total / 1e6:.2f} MB) to {args.output} "
              f"(format {FORMAT_VERSION}, generator {GENERATOR_VERSION})")
        return 0
    if args.action == "verify":
        problems = verify(args.directory, _names(args.sets))
        for p in problems:
            print(f"MISMATCH: {p}")
        print("vectors OK" if not problems else f"{len(problems)} problem(s)")
        return 0 if not problems else 1
    rep = check_impl(args.cmd, args.directory, _names(args.sets), _names(args.fields), args.timeout)
    total = sum(s["rows"] for s in rep["sets"].values())
    if rep["mismatches"]:
        print(f"FAIL: {rep['mismatches']} mismatching answers ({total} vectors); first mismatch:\n{rep['first']}")
        return 1
    print(f"PASS: {total} vectors in {len(rep['sets'])} sets, no mismatch")
    return 0


if __name__ == "__main__":                 # python -m host_tools.vectors ACTION ... (same as hdrg vectors)
    _parser = argparse.ArgumentParser(prog="hdrg vectors", description=__doc__.split("\n\n")[0])
    configure_cli(_parser)
    try:
        sys.exit(run_cli(_parser.parse_args()))
    except ValueError as _exc:
        print(f"hdrg vectors: error: {_exc}", file=sys.stderr)
        sys.exit(2)
