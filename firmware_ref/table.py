"""The coefficient table: one versioned binary layout of 32-bit little-endian words, shared by the
C header, table.json, ``$readmemh`` memory files and the serial upload.

Layout (version 4; ``LAYOUT`` below, rendered into FORMATS.md)::

    word 0   magic 0x47524448 ("HDRG" as little-endian bytes)
    word 1   version (4)
    word 2   length: number of words including the CRC
    3..46    config words and bank 1's exponents and 17 coefficient mantissas (as version 1)
    47..71   order (0 combine_first, 1 regress_first), n_banks (1, 2), bank 2's exponents
             e2_0..e2_3, e2_7, e2_acc and mantissas m2_0..m2_16 (all 0 when n_banks = 1)
    72..     aux generator parameters (aux_nparams int32 words; aux_gen 1: AUX_HEADER, one AF_c per
             aux channel, AUX_TERM_WORDS per term, :func:`decode_aux`)
    last     CRC-32 (IEEE, zlib.crc32) of all preceding words as little-endian bytes

Banks (regress, then reverse; docs/REGRESS_THEN_REVERSE.md): a ``regress_first`` table (order 1) has two
coefficient banks, each with its own exponents (the quantizer sizes each bank on its own), and
the evaluator uses bank 2 on mode-2 samples, bank 1 on every other sample.  order 1 needs
n_banks 2 and a mode-reversal combiner (1 pair, 2 trend, 3 none); combiner 3 (none) needs
order 1; an FTR or combine_first table has order 0 and one bank.

Version 1 (47 fixed words, no order/bank-2 words) is still **read**, as order 0 (combine_first)
with one bank: its words mean exactly what they meant (``from_words``; the C twin does the same).
Version 2 has the same words; an iir rate estimator in it started after a 2^(shift+1)-sample
warm-up, so a version-2 table with the iir is refused (quantize the model again), any other is
read as it is.  Version 3: the iir starts at power-on (FORMATS.md).  Version 4: the same words, with
the drive-frequency word F at LSB 2^-15 Hz (0 .. 131072 Hz; 2^-18 Hz before), so a table of
version 3 or older whose proxy is the drive frequency, or one of whose aux input terms reads F,
holds its F centres in the old LSB and is refused (quantize the model again); any other is read as
it is.  Every writer writes version 4.

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
from firmware_ref import vocabulary as VOC
from firmware_ref.terms import K_AUX, N_TERMS, POLY_INDEX, TERM_NAMES

# coefficient groups sharing one exponent: the Horner rows u^0..u^3 (c_i0..c_i3), then k7
COEF_GROUPS = tuple(tuple(POLY_INDEX[i][j] for j in range(4)) for i in range(4)) + ((K_AUX,),)
# smallest rate warm-up that makes the estimator's history complete (the reference and the
# numba kernel agree only from there): diff 1, diffn n, lsq n - 1, iir 1 (its state starts at k = 1)
def min_rate_warmup(rate_est: int, rate_n: int) -> int:
    return (1, rate_n, rate_n - 1, 1)[rate_est]


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
VERSION = 4
VERSIONS_READ = (1, 2, 3, 4)
# the first layout version whose iir starts with the gear (firmware_ref.rate); an older table with
# the iir estimator was quantized for the blanked start-up and is refused
IIR_GEAR_VERSION = 3
# the first layout version of the 2^-15 Hz drive-frequency word (formats.FREQ_FRAC); an older table
# that reads F (proxy or aux input term) was quantized for 2^-18 Hz and is refused
FREQ_WORD_VERSION = 4
ORDER_COMBINE_FIRST, ORDER_REGRESS_FIRST = 0, 1

# (field, type, meaning) of words 0..46
LAYOUT = (
    ("magic", "uint32", "0x47524448 ('HDRG')"),
    ("version", "uint32", "layout version (4; 3, 2 and 1 (order 0, one bank) are read unless iir or reading F)"),
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
    ("combiner", "uint32", "0 ftr (no reversal), 1 pair, 2 trend, 3 none (order 1 only)"),
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
    ("aux_gen", "uint32", "aux generator: 0 none (z = the Z word, 0 on the host), 1 sum of generator terms"),
    ("aux_nparams", "uint32", "number of aux parameter words after word 71 (aux_gen 1: 2 + n_chan + 11 n_terms)"),
)
N_FIXED_V1 = len(LAYOUT)         # 47: the fixed part of a version-1 table
LAYOUT = LAYOUT + (
    ("order", "uint32", "0 combine_first (combine, then subtract B), 1 regress_first (window sums of r = c - B)"),
    ("n_banks", "uint32", "coefficient banks: 1, or 2 (order 1: bank 2 on mode-2 samples)"),
    ("e2_0", "uint32", "bank 2: exponent of row u^0 (0 when n_banks = 1)"),
    ("e2_1", "uint32", "bank 2: exponent of row u^1"),
    ("e2_2", "uint32", "bank 2: exponent of row u^2"),
    ("e2_3", "uint32", "bank 2: exponent of row u^3"),
    ("e2_7", "uint32", "bank 2: exponent of k7"),
    ("e2_acc", "uint32", "bank 2: exponent E of the outer accumulator"),
) + tuple((f"m2_{k}", "int32", f"bank 2: mantissa of k{k} (0 when n_banks = 1)") for k in range(N_TERMS))
FIELD_INDEX = {name: i for i, (name, _, _) in enumerate(LAYOUT)}
N_FIXED = len(LAYOUT)            # 72
SIGNED = {name for name, typ, _ in LAYOUT if typ == "int32"}

# -- aux parameters of aux_gen 1 ('sum'): header, AF_c per aux channel, AUX_TERM_WORDS per term -------
AUX_HEADER = (
    ("n_terms", "uint32", f"number of terms, 1..{F.AUX_MAX_TERMS}"),
    ("n_chan", "uint32", f"number of aux input words A_c, 0..{F.AUX_MAX_CHANNELS}"),
)
AUX_TERM_LAYOUT = (
    ("kind", "uint32", "0 input, 1 rate, 2 one, 3 decay_on, 4 decay_exchange, 5 ramp, 6 osc"),
    ("sign", "uint32", "1: times the mode sign s (+1 modes 0/1, -1 mode 2, 0 mode 3), else 0"),
    ("src", "uint32", "input: source channel 0 F, 1 T, 2 + c A_c; rate: the proxy's (0 freq, 1 temp); else 0"),
    ("power", "uint32", f"input: 1..{F.AUX_POWER_MAX}; else 1"),
    ("weight", "int32", "w_j, Q1.30, |w_j| <= 2^30"),
    ("c0", "int32", "coefficient 0 (by kind, below)"),
    ("c1", "int32", "coefficient 1"),
    ("c2", "int32", "coefficient 2"),
    ("c3", "int32", "coefficient 3"),
    ("c4", "int32", "coefficient 4"),
    ("c5", "int32", "coefficient 5"),
)
AUX_COEF = {    # kind -> meaning of c0.. (unused words are 0)
    "input": ("REF: centre in source-word LSB (F: uint32 pattern)", "G > 0", "OFF, |OFF| <= G/2 + 1",
              "SH 0..62", "B: filter b = B 2^-SB (0: no filter)", "SB 31..62 (0: no filter)"),
    "rate": ("SB: clamp |S| <= 2^SB - 1, 1..55", "G_V > 0, < 2^(62-SB)", "SH_V 0..62"),
    "one": (),
    "decay_on": ("B: b = 1 - a = B 2^-SB", "SB 31..62"),
    "decay_exchange": ("B: b = 1 - a = B 2^-SB", "SB 31..62"),
    "ramp": ("N >= 1", "G > 0: k / N = RHU(k G, SH); RHU((N - 1) G, SH) <= 2^30", "SH 0..62"),
    "osc": ("W low word (uint32)", "W high word, 0..2^31-1 (W >= 1)", "part: 0 sin, 1 cos"),
}
KIND_INPUT, KIND_RATE, KIND_ONE, KIND_DECAY_ON, KIND_DECAY_EXCHANGE, KIND_RAMP, KIND_OSC = range(7)


@dataclass(frozen=True)
class AuxTerm:
    """One decoded aux term: kind (0..6, formats.AUX_KINDS), sign (0/1), src (channel code), power,
    weight (Q1.30) and the decoded coefficients ``c`` (6 ints): as stored, except input's REF of
    an F source (uint32 value) and osc's c0 = W = low + 2^32 high (c1 then 0)."""

    kind: int
    sign: int
    src: int
    power: int
    weight: int
    c: tuple

    @property
    def name(self) -> str:
        return VOC.AUX_KINDS[self.kind] if 0 <= self.kind < len(VOC.AUX_KINDS) else f"kind {self.kind}"


@dataclass(frozen=True)
class AuxTable:
    """The decoded aux parameters of aux_gen 1: ``fracs`` (AF_c of each aux channel) and ``terms``."""

    fracs: tuple
    terms: tuple

    @property
    def n_chan(self) -> int:
        return len(self.fracs)


def _s32(w: int) -> int:
    w &= 0xFFFFFFFF
    return w - (1 << 32) if w >= 1 << 31 else w


def decode_aux(params) -> AuxTable:
    """Decode aux_gen 1 parameter words (signed ints) into an AuxTable; TableError if the counts do
    not add up (the field ranges are checked by :func:`check_aux`)."""
    p = [int(x) for x in params]
    if len(p) < 2:
        raise TableError(f"aux generator 1 (sum): needs at least 2 parameter words, has {len(p)}")
    nt, nc = p[0], p[1]
    if not 1 <= nt <= F.AUX_MAX_TERMS:
        raise TableError(f"aux n_terms {nt} not in 1..{F.AUX_MAX_TERMS}")
    if not 0 <= nc <= F.AUX_MAX_CHANNELS:
        raise TableError(f"aux n_chan {nc} not in 0..{F.AUX_MAX_CHANNELS}")
    want = 2 + nc + nt * F.AUX_TERM_WORDS
    if len(p) != want:
        raise TableError(f"aux params: {len(p)} words, n_terms {nt} and n_chan {nc} need {want}")
    terms = []
    for j in range(nt):
        w = p[2 + nc + j * F.AUX_TERM_WORDS: 2 + nc + (j + 1) * F.AUX_TERM_WORDS]
        kind, c = w[0], list(w[5:])
        if kind == KIND_INPUT and w[2] == F.CH_F:
            c[0] &= 0xFFFFFFFF
        if kind == KIND_OSC:
            c[0], c[1] = (c[0] & 0xFFFFFFFF) + (c[1] << 32), 0
        terms.append(AuxTerm(kind, w[1], w[2], w[3], w[4], tuple(c)))
    return AuxTable(tuple(p[2:2 + nc]), tuple(terms))


def encode_aux(fracs, terms) -> tuple:
    """The aux_gen 1 parameter words (signed ints) of channel fracs and AuxTerms (inverse of
    :func:`decode_aux`)."""
    out = [len(terms), len(fracs)] + [int(f) for f in fracs]
    for t in terms:
        c = list(t.c)
        if t.kind == KIND_OSC:
            c[0], c[1] = t.c[0] & 0xFFFFFFFF, t.c[0] >> 32
        out += [t.kind, t.sign, t.src, t.power, t.weight] + [_s32(x) for x in c]
    return tuple(out)


def check_aux(aux: AuxTable, proxy_kind: int) -> None:
    """Raise TableError naming the term and the field unless every aux field is in its legal range
    (the firmware relies on these for the absence of overflow)."""
    def need(cond, text):
        if not cond:
            raise TableError(f"coefficient table: {text}")

    for c, f in enumerate(aux.fracs):
        need(0 <= f <= F.AUX_FRAC_MAX, f"aux channel {c}: AF {f} not in 0..{F.AUX_FRAC_MAX}")
    lim31 = (1 << 31) - 1
    wsum = 0
    for j, t in enumerate(aux.terms):
        where = f"aux term {j} ({t.name})"
        need(0 <= t.kind < len(VOC.AUX_KINDS), f"{where}: kind {t.kind} not in 0..{len(VOC.AUX_KINDS) - 1}")
        need(t.sign in (0, 1), f"{where}: sign {t.sign} not 0 or 1")
        need(abs(t.weight) <= F.ONE, f"{where}: weight {t.weight} outside [-2^30, 2^30]")
        wsum += abs(t.weight)
        c = t.c
        used = len(AUX_COEF[VOC.AUX_KINDS[t.kind]])
        if t.kind == KIND_INPUT:
            need(0 <= t.src < F.CH_A0 + aux.n_chan,
                 f"{where}: src {t.src} not a channel (0 F, 1 T, 2..{1 + aux.n_chan} A)")
            need(1 <= t.power <= F.AUX_POWER_MAX, f"{where}: power {t.power} not in 1..{F.AUX_POWER_MAX}")
            if t.src == F.CH_F:
                need(0 <= c[0] <= F.UINT32_MAX, f"{where}: REF {c[0]} outside uint32")
            else:
                need(abs(c[0]) <= F.INT32_SYM, f"{where}: REF {c[0]} outside int32")
            need(0 < c[1] <= lim31, f"{where}: G {c[1]} not in 1..2^31-1")
            need(abs(c[2]) <= c[1] // 2 + 1, f"{where}: OFF {c[2]} exceeds G / 2")
            need(0 <= c[3] <= 62, f"{where}: SH {c[3]} not in 0..62")
            if c[5] == 0:
                need(c[4] == 0, f"{where}: filter B {c[4]} with SB 0 (no filter) must be 0")
            else:
                need(F.AUX_SB_MIN <= c[5] <= F.AUX_SB_MAX, f"{where}: filter SB {c[5]} not 0 or "
                                                           f"{F.AUX_SB_MIN}..{F.AUX_SB_MAX}")
                need(0 < c[4] <= lim31, f"{where}: filter B {c[4]} not in 1..2^31-1")
        else:
            need(t.power == 1, f"{where}: power {t.power} must be 1")
            if t.kind == KIND_RATE:
                need(t.src == proxy_kind, f"{where}: src {t.src} must be the proxy's channel {proxy_kind} "
                                          f"(the rate term reuses the model's rate sum S)")
            else:
                need(t.src == 0, f"{where}: src {t.src} must be 0")
        if t.kind == KIND_RATE:
            need(1 <= c[0] <= F.S_BITS_MAX, f"{where}: SB {c[0]} not in 1..{F.S_BITS_MAX}")
            need(0 < c[1] <= lim31 and c[1] < (1 << (62 - max(1, min(c[0], F.S_BITS_MAX)))),
                 f"{where}: G_V {c[1]} not in 1..min(2^31, 2^(62-SB))-1")
            need(0 <= c[2] <= 62, f"{where}: SH_V {c[2]} not in 0..62")
        elif t.kind in (KIND_DECAY_ON, KIND_DECAY_EXCHANGE):
            need(0 < c[0] <= lim31, f"{where}: B {c[0]} not in 1..2^31-1")
            need(F.AUX_SB_MIN <= c[1] <= F.AUX_SB_MAX, f"{where}: SB {c[1]} not in {F.AUX_SB_MIN}..{F.AUX_SB_MAX}")
        elif t.kind == KIND_RAMP:
            need(0 < c[0] <= lim31, f"{where}: N {c[0]} not in 1..2^31-1")
            need(0 < c[1] <= lim31, f"{where}: G {c[1]} not in 1..2^31-1")
            need(0 <= c[2] <= 62, f"{where}: SH {c[2]} not in 0..62")
            top = (c[0] - 1) * c[1]                  # g at k = N - 1, the ramp's largest value
            top = top if c[2] == 0 else (top + (1 << (c[2] - 1))) >> c[2]
            need(top <= F.ONE, f"{where}: RHU((N - 1) G, SH) = {top} exceeds 2^30: g would leave Q1.30 "
                               f"(and w g overflow int64 on the chip)")
        elif t.kind == KIND_OSC:
            need(1 <= c[0] < 1 << 63, f"{where}: phase step W {c[0]} not in 1..2^63-1")
            need(c[2] in (0, 1), f"{where}: part {c[2]} not 0 (sin) or 1 (cos)")
        if t.kind != KIND_INPUT:
            need(all(x == 0 for x in c[used:]), f"{where}: unused coefficient words must be 0")
    need(wsum <= F.ONE + len(aux.terms), f"aux weights: sum |w_j| = {wsum} exceeds 2^30 + n_terms")


@dataclass(frozen=True)
class Bank:
    """One coefficient bank: row exponents e_0..e_3, e_7, E and the 17 mantissas (k order)."""

    e_row: tuple
    e_7: int
    e_acc: int
    mant: tuple


def _old_freq_word(source: str, version: int, why: str) -> str:
    return (f"{source}: a version-{version} table was quantized for the old drive-frequency word (LSB 2^-18 Hz, "
            f"0 .. 16384 Hz) and {why}; this firmware reads F at 2^-{F.FREQ_FRAC} Hz (0 .. "
            f"{F.FREQ_RANGE_HZ:.0f} Hz, table version {FREQ_WORD_VERSION}): quantize the model again (hdrg quantize)")


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
    order: int = 0          # 0 combine_first (and FTR), 1 regress_first
    n_banks: int = 1
    e_row2: tuple = (0, 0, 0, 0)    # bank 2 (all 0 when n_banks = 1)
    e_7_2: int = 0
    e_acc2: int = 0
    mant2: tuple = (0,) * N_TERMS

    def __post_init__(self):
        self.e_row = tuple(int(e) for e in self.e_row)
        self.mant = tuple(int(m) for m in self.mant)
        self.e_row2 = tuple(int(e) for e in self.e_row2)
        self.mant2 = tuple(int(m) for m in self.mant2)
        self.aux_params = tuple(int(p) for p in self.aux_params)
        self.validate()

    def bank(self, b: int) -> "Bank":
        """The coefficients of bank ``b`` (1 or 2) as a :class:`Bank` (what the evaluator reads)."""
        if b == 2:
            return Bank(self.e_row2, self.e_7_2, self.e_acc2, self.mant2)
        return Bank(self.e_row, self.e_7, self.e_acc, self.mant)

    def bank_of_mode(self, mode: int) -> int:
        """The bank the evaluator uses for a sample of run-log ``mode``: 2 for mode 2 of a
        two-bank table, else 1."""
        return 2 if (self.n_banks == 2 and mode == 2) else 1

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
        need(0 <= self.rate_est < len(VOC.ESTIMATORS), f"rate_est {self.rate_est} unknown")
        need(1 <= self.rate_n <= F.N_HIST_MAX, f"rate_n {self.rate_n} not in 1..{F.N_HIST_MAX}")
        need(self.rate_est != 2 or self.rate_n >= 2, "lsq needs rate_n >= 2")
        need(0 <= self.rate_shift <= 24, f"rate_shift {self.rate_shift} not in 0..24")
        need(1 <= self.rate_warmup <= F.TIMER_MAX, f"rate_warmup {self.rate_warmup} out of range")
        need(1 <= self.s_bits <= F.S_BITS_MAX, f"s_bits {self.s_bits} not in 1..{F.S_BITS_MAX}")
        need(self.g_v < (1 << (62 - self.s_bits)), f"g_v {self.g_v} too large for s_bits {self.s_bits} "
                                                   f"(|S| G_V must stay below 2^62)")
        need(0 < self.fs_q16 <= F.UINT32_MAX, f"fs_q16 {self.fs_q16} out of range")
        need(self.combiner in (0, 1, 2, 3), f"combiner {self.combiner} not 0 (ftr), 1 (pair), 2 (trend), 3 (none)")
        need(self.order in (0, 1), f"order {self.order} not 0 (combine_first) or 1 (regress_first)")
        need(self.n_banks in (1, 2), f"n_banks {self.n_banks} not 1 or 2")
        need(self.n_banks == 1 + self.order, f"n_banks {self.n_banks} with order {self.order}: combine_first "
                                             f"(0) has one bank, regress_first (1) two")
        need(self.combiner != 3 or self.order == 1, "combiner 3 (none) needs order 1 (regress_first)")
        need(self.combiner != 0 or self.order == 0, "combiner 0 (ftr) needs order 0 (no mode reversal)")
        for name in ("settle_n", "max_stale_n", "power_on_n", "exchange_n"):
            need(0 <= getattr(self, name) <= F.TIMER_MAX, f"{name} {getattr(self, name)} not in 0..2^31-1")
        need(self.max_stale_n < F.COUNT_MAX, "max_stale_n must be below the age saturation 2^31-1")
        need(1 <= self.dwell_n <= F.TIMER_MAX, f"dwell_n {self.dwell_n} not in 1..2^31-1")
        need(len(self.e_row) == 4 and len(self.e_row2) == 4, "needs 4 row exponents per bank")
        need(len(self.mant) == N_TERMS and len(self.mant2) == N_TERMS, f"needs {N_TERMS} mantissas per bank")
        if self.n_banks == 1:
            need(not any(self.e_row2) and self.e_7_2 == 0 and self.e_acc2 == 0 and not any(self.mant2),
                 "bank 2 words (e2_*, m2_*) must be 0 in a one-bank table")
        for b in range(1, self.n_banks + 1):
            bk, pre = self.bank(b), ("" if b == 1 else "bank 2: ")
            for g, e in enumerate(bk.e_row + (bk.e_7,)):
                need(F.EXP_MIN <= e <= F.EXP_MAX, f"{pre}exponent {e} of group {g} not in {F.EXP_MIN}..{F.EXP_MAX}")
                need(0 <= e - bk.e_acc <= F.ALIGN_MAX, f"{pre}exponent {e} of group {g} minus E {bk.e_acc} "
                                                        f"not in 0..{F.ALIGN_MAX}")
            need(F.EXP_MIN <= bk.e_acc <= F.EXP_MAX, f"{pre}E {bk.e_acc} not in {F.EXP_MIN}..{F.EXP_MAX}")
            for k, m in enumerate(bk.mant):
                need(abs(m) <= F.INT32_SYM, f"{pre}mantissa m{'' if b == 1 else '2'}_{k} {m} outside int32")
        need(self.aux_gen in (0, 1), f"aux_gen {self.aux_gen} not 0 (none) or 1 (sum)")
        if self.aux_gen == 0:
            need(not self.aux_params, "aux generator 0 (none) takes no parameters")
        else:
            check_aux(decode_aux(self.aux_params), self.proxy_kind)
        # (every check above passed: exponents, mantissas and the estimator are in range)
        for b in range(1, self.n_banks + 1):
            bk, pre = self.bank(b), ("" if b == 1 else "bank 2: ")
            rows, bounds = horner_bounds(bk.e_row, bk.e_7, bk.e_acc, bk.mant)
            for g, r in enumerate(rows):
                need(r <= F.ACC_LIMIT, f"{pre}Horner row u^{g}: sum of |mantissas| {r} exceeds 2^31 - 1 "
                                       f"(evaluator would overflow)")
            need(sum(bounds) <= F.ACC_LIMIT, f"{pre}Horner accumulator bound {sum(bounds)} exceeds 2^31 - 1 "
                                             f"(evaluator would overflow)")
        w = min_rate_warmup(self.rate_est, self.rate_n)
        need(self.rate_warmup >= w, f"rate_warmup {self.rate_warmup} below {w}, the history length "
                                    f"of {VOC.ESTIMATORS[self.rate_est]} n={self.rate_n}")

    # -- words -----------------------------------------------------------------------------------
    def field_values(self) -> dict:
        """name -> value of every LAYOUT field (magic, version, length included)."""
        vals = {"magic": MAGIC, "version": VERSION, "length": N_FIXED + len(self.aux_params) + 1}
        for f in fields(self):
            if f.name in ("e_row", "mant", "aux_params", "e_row2", "mant2", "e_7_2", "e_acc2"):
                continue
            vals[f.name] = getattr(self, f.name)
        for i, e in enumerate(self.e_row):
            vals[f"e_{i}"] = e
        for k, m in enumerate(self.mant):
            vals[f"m_{k}"] = m
        for i, e in enumerate(self.e_row2):
            vals[f"e2_{i}"] = e
        vals["e2_7"], vals["e2_acc"] = self.e_7_2, self.e_acc2
        for k, m in enumerate(self.mant2):
            vals[f"m2_{k}"] = m
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
        """Decode and check (magic, version, length, CRC, field ranges).  A version-1 table (47
        fixed words) is read as order 0 (combine_first) with one bank."""
        words = [int(w) for w in words]
        if any(not 0 <= w <= F.UINT32_MAX for w in words):
            raise TableError(f"{source}: a word is outside uint32")
        if len(words) < N_FIXED_V1 + 1:
            raise TableError(f"{source}: {len(words)} words, a table has at least {N_FIXED_V1 + 1}")
        if words[0] != MAGIC:
            raise TableError(f"{source}: bad magic 0x{words[0]:08x} (expected 0x{MAGIC:08x}, 'HDRG')")
        if words[1] not in VERSIONS_READ:
            raise TableError(f"{source}: unsupported table version {words[1]} (this reads {VERSIONS_READ})")
        n_fixed = N_FIXED if words[1] >= 2 else N_FIXED_V1
        if len(words) < n_fixed + 1:
            raise TableError(f"{source}: {len(words)} words, a version-{words[1]} table has at least {n_fixed + 1}")
        if words[2] != len(words):
            raise TableError(f"{source}: length word says {words[2]} words, found {len(words)}")
        crc = crc32_words(words[:-1])
        if crc != words[-1]:
            raise TableError(f"{source}: CRC-32 mismatch (stored 0x{words[-1]:08x}, computed 0x{crc:08x})")
        vals = {}
        for i, (name, typ, _) in enumerate(LAYOUT[:n_fixed]):
            w = words[i]
            vals[name] = w - (1 << 32) if (typ == "int32" and w >= 1 << 31) else w
        if vals["proxy_kind"] == 0:
            vals["p_ref"] &= 0xFFFFFFFF
        if words[1] < IIR_GEAR_VERSION and vals["rate_est"] == 3:
            raise TableError(f"{source}: a version-{words[1]} table with the iir rate estimator was quantized for "
                             f"its old start-up (no output for 2^(shift+1) samples); the iir now starts at "
                             f"power-on (version {IIR_GEAR_VERSION}): quantize the model again (hdrg quantize)")
        npar = vals["aux_nparams"]
        if n_fixed + npar + 1 != len(words):
            raise TableError(f"{source}: aux_nparams {npar} does not match the length {len(words)}")
        if words[1] < FREQ_WORD_VERSION and vals["proxy_kind"] == 0:
            raise TableError(_old_freq_word(source, words[1], "its proxy is the drive frequency"))
        params = [w - (1 << 32) if w >= 1 << 31 else w for w in words[n_fixed:n_fixed + npar]]
        kw = {f.name: vals[f.name] for f in fields(cls) if f.name in vals}
        if n_fixed == N_FIXED:
            kw.update(e_row2=tuple(vals[f"e2_{i}"] for i in range(4)), e_7_2=vals["e2_7"], e_acc2=vals["e2_acc"],
                      mant2=tuple(vals[f"m2_{k}"] for k in range(N_TERMS)))
        try:
            table = cls(e_row=tuple(vals[f"e_{i}"] for i in range(4)),
                        mant=tuple(vals[f"m_{k}"] for k in range(N_TERMS)), aux_params=tuple(params), **kw)
        except TableError as exc:
            raise TableError(f"{source}: {exc}") from None
        if words[1] < FREQ_WORD_VERSION and table.aux_gen == 1 and any(
                t.kind == KIND_INPUT and t.src == F.CH_F for t in decode_aux(table.aux_params).terms):
            raise TableError(_old_freq_word(source, words[1], "an aux input term reads the drive frequency F"))
        return table

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

    def aux(self) -> AuxTable | None:
        """The decoded aux parameters (aux_gen 1), or None (aux_gen 0)."""
        return decode_aux(self.aux_params) if self.aux_gen == 1 else None

    def aux_array(self) -> np.ndarray:
        """int64[n_terms, 11] for the kernel: kind, sign, src, power, weight, c0..c5 (decoded as
        AuxTerm.c); shape (0, 11) for aux_gen 0."""
        aux = self.aux()
        rows = [] if aux is None else [[t.kind, t.sign, t.src, t.power, t.weight, *t.c] for t in aux.terms]
        return np.array(rows, np.int64).reshape(len(rows), F.AUX_TERM_WORDS)

    def param_names(self) -> list:
        """Names of the aux parameter words (for messages and the C header's comments)."""
        if self.aux_gen != 1 or len(self.aux_params) < 2:
            return [f"aux_param_{i}" for i in range(len(self.aux_params))]
        nc = max(0, self.aux_params[1])
        names = ["aux_n_terms", "aux_n_chan"] + [f"aux_af_{c}" for c in range(nc)]
        while len(names) < len(self.aux_params):
            j, i = divmod(len(names) - 2 - nc, F.AUX_TERM_WORDS)
            names.append(f"aux_t{j}_{AUX_TERM_LAYOUT[i][0]}")
        return names[:len(self.aux_params)]

    @property
    def crc(self) -> int:
        return self.to_words()[-1]


def crc32_words(words) -> int:
    """zlib.crc32 (IEEE 802.3) of the words as little-endian uint32 bytes."""
    return zlib.crc32(struct.pack(f"<{len(words)}I", *[w & 0xFFFFFFFF for w in words])) & 0xFFFFFFFF
