"""The coefficient table: one versioned binary layout of 32-bit little-endian words, shared by the
C header, table.json, ``$readmemh`` memory files and the serial upload.

Layout (version 1; ``LAYOUT`` below, rendered into FORMATS.md)::

    word 0   magic 0x47524448 ("HDRG" as little-endian bytes)
    word 1   version (1)
    word 2   length: number of words including the CRC
    3..46    config words and the 17 coefficient mantissas (LAYOUT)
    47..     aux generator parameters (aux_nparams int32 words)
    last     CRC-32 (IEEE, zlib.crc32) of all preceding words as little-endian bytes

Signed fields are stored as two's complement.  :class:`Table` holds the decoded fields;
``to_words/from_words``, ``to_bytes/from_bytes``, ``to_memh``/``from_memh`` (one 8-digit hex word
per line), ``to_c_header`` convert; every reader checks magic, version, length and CRC and raises
:class:`TableError` naming the problem.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field, fields

import numpy as np

from firmware_ref import formats as F
from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX, TERM_NAMES

# coefficient groups sharing one exponent: the Horner rows u^0..u^3 (c_i0..c_i3), then k7
COEF_GROUPS = tuple(tuple(POLY_INDEX[i][j] for j in range(4)) for i in range(4)) + ((K_AUX,),)
# smallest rate warm-up that makes the estimator's history complete (the reference and the
# numba kernel agree only from there): diff 1, diffn n, lsq n - 1, iir 2
def min_rate_warmup(rate_est: int, rate_n: int) -> int:
    return (1, rate_n, rate_n - 1, 2)[rate_est]


def _rhu_shift(a: int, s: int) -> int:
    return a if s == 0 else (a + (1 << (s - 1))) >> s


def horner_bounds(e_row, e_7, e_acc, mant) -> list:
    """Interval bound of every evaluator accumulator for |u|, |v|, |z| <= 1 (Q1.30): the bound of
    each Horner row in accumulator units (a row's partial sums never exceed the sum of its |mantissas|,
    and RHU(p * v, 30) never exceeds |p|), and of k7 * z.  Their sum bounds the outer Horner
    accumulator; a table is legal only when every row sum and the total are <= 2^31 - 1."""
    rows = [sum(abs(mant[k]) for k in COEF_GROUPS[g]) for g in range(4)]
    bounds = [_rhu_shift(rows[g], e_row[g] - e_acc) for g in range(4)]
    bounds.append(_rhu_shift(abs(mant[K_AUX]) << F.Q, F.Q + e_7 - e_acc))
    return rows, bounds

MAGIC = 0x47524448
VERSION = 1

# (field, type, meaning) of words 0..46
LAYOUT = (
    ("magic", "uint32", "0x47524448 ('HDRG')"),
    ("version", "uint32", "layout version (1)"),
    ("length", "uint32", "words including the CRC"),
    ("proxy_kind", "uint32", "0 freq (P = F word, uint32), 1 temp (P = T word, int32)"),
    ("p_ref", "int32", "proxy centre P_REF in proxy-word LSB (freq: uint32 bit pattern)"),
    ("g_u", "int32", "proxy gain G_U > 0"),
    ("u_off", "int32", "proxy offset U_OFF = RHU((P_REF - ref/LSB) G_U): the centre's fraction"),
    ("sh_u", "uint32", "proxy shift SH_U: u = RHU(dP G_U + U_OFF, SH_U)"),
    ("rate_est", "uint32", "rate estimator: 0 diff, 1 diffn, 2 lsq, 3 iir"),
    ("rate_n", "uint32", "window n (diff: 1)"),
    ("rate_shift", "uint32", "iir shift (0..24)"),
    ("rate_warmup", "uint32", "warm-up W (samples)"),
    ("s_bits", "uint32", "rate-sum clamp |S| <= 2^SB - 1"),
    ("g_v", "int32", "rate gain G_V > 0"),
    ("sh_v", "uint32", "rate shift SH_V: v = RHU(S G_V, SH_V)"),
    ("fs_q16", "uint32", "nominal sample rate x 2^16 (informative; the gains hold fs)"),
    ("combiner", "uint32", "0 ftr (no reversal), 1 pair, 2 trend"),
    ("settle_n", "uint32", "settling samples per window"),
    ("max_stale_n", "uint32", "staleness limit (samples)"),
    ("power_on_n", "uint32", "sequencer: power-on samples (mode 3)"),
    ("exchange_n", "uint32", "sequencer: exchange samples (mode 3)"),
    ("dwell_n", "uint32", "sequencer: mode-1/2 window samples"),
    ("e_0", "uint32", "exponent of Horner row u^0 (k0, k4, k5, k6)"),
    ("e_1", "uint32", "exponent of row u^1 (k1, k8, k9, k10)"),
    ("e_2", "uint32", "exponent of row u^2 (k2, k11, k12, k13)"),
    ("e_3", "uint32", "exponent of row u^3 (k3, k14, k15, k16)"),
    ("e_7", "uint32", "exponent of k7 (aux)"),
    ("e_acc", "uint32", "exponent E of the outer accumulator"),
) + tuple((f"m_{k}", "int32", f"mantissa of k{k} ({TERM_NAMES[k]})") for k in range(N_TERMS)) + (
    ("aux_gen", "uint32", "aux generator: 0 none (z = 0)"),
    ("aux_nparams", "uint32", "number of aux parameter words that follow"),
)
FIELD_INDEX = {name: i for i, (name, _, _) in enumerate(LAYOUT)}
N_FIXED = len(LAYOUT)            # 47
SIGNED = {name for name, typ, _ in LAYOUT if typ == "int32"}


class TableError(ValueError):
    """A table that cannot be used (bad magic, version, length, CRC, or field value)."""


@dataclass
class Table:
    """The decoded fields of a coefficient table (all Python ints; see LAYOUT)."""

    proxy_kind: int
    p_ref: int
    g_u: int
    u_off: int
    sh_u: int
    rate_est: int
    rate_n: int
    rate_shift: int
    rate_warmup: int
    s_bits: int
    g_v: int
    sh_v: int
    fs_q16: int
    combiner: int
    settle_n: int
    max_stale_n: int
    power_on_n: int
    exchange_n: int
    dwell_n: int
    e_row: tuple            # e_0..e_3
    e_7: int
    e_acc: int
    mant: tuple             # 17 mantissas, k order
    aux_gen: int = 0
    aux_params: tuple = field(default_factory=tuple)

    def __post_init__(self):
        self.e_row = tuple(int(e) for e in self.e_row)
        self.mant = tuple(int(m) for m in self.mant)
        self.aux_params = tuple(int(p) for p in self.aux_params)
        self.validate()

    # -- checks --------------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise TableError unless every field is in its legal range (the firmware relies on it)."""
        def need(cond, text):
            if not cond:
                raise TableError(f"coefficient table: {text}")
        need(self.proxy_kind in (0, 1), f"proxy_kind {self.proxy_kind} not 0 (freq) or 1 (temp)")
        if self.proxy_kind == 0:
            need(0 <= self.p_ref <= F.UINT32_MAX, f"p_ref {self.p_ref} outside uint32")
        else:
            need(abs(self.p_ref) <= F.INT32_SYM, f"p_ref {self.p_ref} outside int32")
        for name in ("g_u", "g_v"):
            need(0 < getattr(self, name) < (1 << F.GAIN_BITS), f"{name} {getattr(self, name)} not in 1..2^31-1")
        need(abs(self.u_off) <= self.g_u // 2 + 1, f"u_off {self.u_off} exceeds G_U / 2")
        need(0 <= self.sh_u <= 62 and 0 <= self.sh_v <= 62, f"shifts sh_u {self.sh_u}, sh_v {self.sh_v} not in 0..62")
        need(0 <= self.rate_est < len(F.ESTIMATORS), f"rate_est {self.rate_est} unknown")
        need(1 <= self.rate_n <= F.N_HIST_MAX, f"rate_n {self.rate_n} not in 1..{F.N_HIST_MAX}")
        need(self.rate_est != 2 or self.rate_n >= 2, "lsq needs rate_n >= 2")
        need(0 <= self.rate_shift <= 24, f"rate_shift {self.rate_shift} not in 0..24")
        need(1 <= self.rate_warmup <= F.TIMER_MAX, f"rate_warmup {self.rate_warmup} out of range")
        need(1 <= self.s_bits <= F.S_BITS_MAX, f"s_bits {self.s_bits} not in 1..{F.S_BITS_MAX}")
        need(self.g_v < (1 << (62 - self.s_bits)), f"g_v {self.g_v} too large for s_bits {self.s_bits} "
                                                   f"(|S| G_V must stay below 2^62)")
        need(0 < self.fs_q16 <= F.UINT32_MAX, f"fs_q16 {self.fs_q16} out of range")
        need(self.combiner in (0, 1, 2), f"combiner {self.combiner} not 0 (ftr), 1 (pair), 2 (trend)")
        for name in ("settle_n", "max_stale_n", "power_on_n", "exchange_n"):
            need(0 <= getattr(self, name) <= F.TIMER_MAX, f"{name} {getattr(self, name)} not in 0..2^31-1")
        need(self.max_stale_n < F.COUNT_MAX, "max_stale_n must be below the age saturation 2^31-1")
        need(1 <= self.dwell_n <= F.TIMER_MAX, f"dwell_n {self.dwell_n} not in 1..2^31-1")
        need(len(self.e_row) == 4, "needs 4 row exponents")
        need(len(self.mant) == N_TERMS, f"needs {N_TERMS} mantissas")
        for g, e in enumerate(self.e_row + (self.e_7,)):
            need(F.EXP_MIN <= e <= F.EXP_MAX, f"exponent {e} of group {g} not in {F.EXP_MIN}..{F.EXP_MAX}")
            need(0 <= e - self.e_acc <= F.ALIGN_MAX, f"exponent {e} of group {g} minus E {self.e_acc} "
                                                      f"not in 0..{F.ALIGN_MAX}")
        need(F.EXP_MIN <= self.e_acc <= F.EXP_MAX, f"E {self.e_acc} not in {F.EXP_MIN}..{F.EXP_MAX}")
        for k, m in enumerate(self.mant):
            need(abs(m) <= F.INT32_SYM, f"mantissa m_{k} {m} outside int32")
        need(self.aux_gen == 0 and not self.aux_params, "aux generator must be 0 (none) with no parameters")
        # (every check above passed: exponents, mantissas and the estimator are in range)
        rows, bounds = horner_bounds(self.e_row, self.e_7, self.e_acc, self.mant)
        for g, r in enumerate(rows):
            need(r <= F.ACC_LIMIT, f"Horner row u^{g}: sum of |mantissas| {r} exceeds 2^31 - 1 (evaluator would overflow)")
        need(sum(bounds) <= F.ACC_LIMIT, f"Horner accumulator bound {sum(bounds)} exceeds 2^31 - 1 "
                                         f"(evaluator would overflow)")
        w = min_rate_warmup(self.rate_est, self.rate_n)
        need(self.rate_warmup >= w, f"rate_warmup {self.rate_warmup} below {w}, the history length "
                                    f"of {F.ESTIMATORS[self.rate_est]} n={self.rate_n}")

    # -- words -----------------------------------------------------------------------------------
    def field_values(self) -> dict:
        """name -> value of every LAYOUT field (magic, version, length included)."""
        vals = {"magic": MAGIC, "version": VERSION, "length": N_FIXED + len(self.aux_params) + 1}
        for f in fields(self):
            if f.name in ("e_row", "mant", "aux_params"):
                continue
            vals[f.name] = getattr(self, f.name)
        for i, e in enumerate(self.e_row):
            vals[f"e_{i}"] = e
        for k, m in enumerate(self.mant):
            vals[f"m_{k}"] = m
        vals["aux_nparams"] = len(self.aux_params)
        return vals

    def to_words(self) -> list:
        """The uint32 words, CRC last."""
        vals = self.field_values()
        words = [vals[name] & 0xFFFFFFFF for name, _, _ in LAYOUT] + [p & 0xFFFFFFFF for p in self.aux_params]
        return words + [crc32_words(words)]

    def to_bytes(self) -> bytes:
        return struct.pack(f"<{len(self.to_words())}I", *self.to_words())

    def to_memh(self) -> str:
        """``$readmemh`` text: one 8-digit hex word per line (address 0 first)."""
        return "".join(f"{w:08x}\n" for w in self.to_words())

    @classmethod
    def from_words(cls, words, source: str = "<words>") -> "Table":
        """Decode and check (magic, version, length, CRC, field ranges)."""
        words = [int(w) for w in words]
        if any(not 0 <= w <= F.UINT32_MAX for w in words):
            raise TableError(f"{source}: a word is outside uint32")
        if len(words) < N_FIXED + 1:
            raise TableError(f"{source}: {len(words)} words, a table has at least {N_FIXED + 1}")
        if words[0] != MAGIC:
            raise TableError(f"{source}: bad magic 0x{words[0]:08x} (expected 0x{MAGIC:08x}, 'HDRG')")
        if words[1] != VERSION:
            raise TableError(f"{source}: unsupported table version {words[1]} (this reads {VERSION})")
        if words[2] != len(words):
            raise TableError(f"{source}: length word says {words[2]} words, found {len(words)}")
        crc = crc32_words(words[:-1])
        if crc != words[-1]:
            raise TableError(f"{source}: CRC-32 mismatch (stored 0x{words[-1]:08x}, computed 0x{crc:08x})")
        vals = {}
        for i, (name, typ, _) in enumerate(LAYOUT):
            w = words[i]
            vals[name] = w - (1 << 32) if (typ == "int32" and w >= 1 << 31) else w
        if vals["proxy_kind"] == 0:
            vals["p_ref"] &= 0xFFFFFFFF
        npar = vals["aux_nparams"]
        if N_FIXED + npar + 1 != len(words):
            raise TableError(f"{source}: aux_nparams {npar} does not match the length {len(words)}")
        params = [w - (1 << 32) if w >= 1 << 31 else w for w in words[N_FIXED:N_FIXED + npar]]
        kw = {f.name: vals[f.name] for f in fields(cls) if f.name in vals}
        try:
            return cls(e_row=tuple(vals[f"e_{i}"] for i in range(4)),
                       mant=tuple(vals[f"m_{k}"] for k in range(N_TERMS)), aux_params=tuple(params), **kw)
        except TableError as exc:
            raise TableError(f"{source}: {exc}") from None

    @classmethod
    def from_bytes(cls, data: bytes, source: str = "<bytes>") -> "Table":
        if len(data) % 4:
            raise TableError(f"{source}: {len(data)} bytes is not a whole number of 32-bit words")
        return cls.from_words(struct.unpack(f"<{len(data) // 4}I", data), source)

    @classmethod
    def from_memh(cls, text: str, source: str = "<memh>") -> "Table":
        words = []
        for lineno, line in enumerate(text.splitlines(), 1):
            line = line.split("//")[0].strip()
            if not line:
                continue
            try:
                words.append(int(line, 16))
            except ValueError:
                raise TableError(f"{source}:{lineno}: not a hex word: {line!r}") from None
        return cls.from_words(words, source)

    # -- for the kernel --------------------------------------------------------------------------
    def config_array(self) -> np.ndarray:
        """int64[N_FIXED]: the decoded LAYOUT fields (signed), indexed by FIELD_INDEX."""
        vals = self.field_values()
        return np.array([vals[name] for name, _, _ in LAYOUT], np.int64)

    @property
    def crc(self) -> int:
        return self.to_words()[-1]


def crc32_words(words) -> int:
    """zlib.crc32 (IEEE 802.3) of the words as little-endian uint32 bytes."""
    return zlib.crc32(struct.pack(f"<{len(words)}I", *[w & 0xFFFFFFFF for w in words])) & 0xFFFFFFFF
