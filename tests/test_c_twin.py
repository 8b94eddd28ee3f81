"""The C99 twin (firmware_ref/c) against the numba kernel and the per-sample Python reference, bit
for bit, through the driver's stdin/stdout protocol (firmware_ref/c/README.md): 10^6 random
samples and every corner stream, extreme tables, counter edges, the primitives and the evaluator
alone, table checks, the simulator's paper scenarios with fitted and quantized models; a build
under -fsanitize=undefined; and a deliberately broken build that the comparison must catch.

Helpers here (build, run_bin, run_text, ...) are imported by test_export.py and test_bench_c.py.
"""
import copy
import dataclasses
import shutil
import struct
import subprocess
import zlib
from pathlib import Path

import numpy as np
import pytest

import firmware_ref
from firmware_ref import arith
from firmware_ref import formats as F
from firmware_ref.compensate import run_reference
from host_tools.fixed.fixed_point import log_words
from firmware_ref.evaluator import evaluate
from firmware_ref.kernel import evaluate_words, run_words
from firmware_ref.table import FIELD_INDEX, LAYOUT, Table, TableError, crc32_words
from firmware_ref.terms import K_AUX
from host_tools.vectors.builders import (aux_stream, corner_stream, make_model, random_aux_model, random_model,
                                  random_stream, with_aux)
from host_tools.fixed.quantize import quantize

GCC = shutil.which("gcc")
pytestmark = pytest.mark.skipif(GCC is None, reason="gcc not found on PATH: the C twin cannot be built")

C_DIR = Path(firmware_ref.__file__).parent / "c"
SOURCES = (C_DIR / "hdrg_fw.c", C_DIR / "hdrg_fw_main.c")
CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic")
STRICT = CFLAGS + ("-Wconversion", "-Wsign-conversion", "-Wshadow", "-Wcast-qual", "-Wstrict-prototypes",
                   "-Wmissing-prototypes")
UBSAN = ("-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-fsanitize=undefined",
         "-fno-sanitize-recover=all")
FIELDS = ("state", "vs", "mode", "sign", "u", "v", "z", "s", "acc", "cnt", "y", "b", "out", "bias", "valid", "flags")
KERNEL_KEYS = ("out", "bias", "valid", "flags", "u", "v", "z", "b", "y", "s", "state")
REF_KEYS = KERNEL_KEYS + ("vs", "sign", "acc", "cnt")


# -- helpers ------------------------------------------------------------------------------------------

def build(outdir, name="hdrg_fw", flags=CFLAGS, defines=(), include=(), sources=SOURCES) -> Path:
    """Compile the driver (or ``sources``) into ``outdir/name``; AssertionError with gcc's output."""
    exe = Path(outdir) / name
    cmd = [GCC, *flags, *[f"-D{d}" for d in defines], *[f"-I{i}" for i in include], "-o", str(exe),
           *map(str, sources)]
    pr = subprocess.run(cmd, capture_output=True, text=True)
    assert pr.returncode == 0, f"{' '.join(cmd)}\n{pr.stderr}"
    return exe


def table_line(table) -> str:
    return "TABLE " + " ".join(f"{w:08x}" for w in table.to_words())


def input_records(table, s, self_timed=False) -> np.ndarray:
    """int64[n, 6]: F T R MODE RESTART Z (the proxy word in the column of the table's kind); a
    stream with aux channels (``k`` not None: host_tools.vectors.builders.aux_stream) gives int64[n, 11]
    with F and T from ``f``, ``t`` and K A0 A1 A2 A3 after Z."""
    n = len(s["p"])
    aux = s.get("k") is not None
    rec = np.zeros((n, 11 if aux else 6), np.int64)
    if aux:
        rec[:, 0], rec[:, 1] = s["f"], s["t"]
        rec[:, 6] = s["k"]
        a = np.asarray(s["aux"], np.int64).reshape(n, -1)
        rec[:, 7:7 + a.shape[1]] = a
    rec[:, 0 if table.proxy_kind == 0 else 1] = s["p"]
    rec[:, 2] = s["r"]
    rec[:, 3] = -1 if self_timed else s["mode"]
    rec[:, 4] = 0 if s.get("restart") is None else s["restart"]
    rec[:, 5] = 0 if s.get("z") is None else s["z"]
    return rec


def run_bin(exe, table, s, self_timed=False) -> dict:
    """The driver on a stream through a BIN block (record width 6, or 11 with the aux inputs);
    dict of int64 arrays named FIELDS."""
    rec = input_records(table, s, self_timed)
    n = len(rec)
    width = "" if rec.shape[1] == 6 else f" {rec.shape[1]}"
    data = f"{table_line(table)}\nBIN {n}{width}\n".encode() + rec.astype("<i8").tobytes()
    pr = subprocess.run([str(exe)], input=data, capture_output=True)
    assert pr.returncode == 0 and not pr.stderr, pr.stderr.decode(errors="replace")[-2000:]
    i = pr.stdout.index(b"\n")
    j = pr.stdout.index(b"\n", i + 1)
    assert pr.stdout[:i].decode().startswith("T "), pr.stdout[:i]
    assert pr.stdout[i + 1:j] == f"BIN {n}".encode()
    arr = np.frombuffer(pr.stdout[j + 1:], "<i8")
    assert arr.size == n * len(FIELDS)
    arr = arr.reshape(n, len(FIELDS))
    return {name: arr[:, c].astype(np.int64) for c, name in enumerate(FIELDS)}


def run_text(exe, lines, expect_rc=0):
    """The driver on text requests; returns the response lines (stderr must be empty)."""
    pr = subprocess.run([str(exe)], input="\n".join(lines) + "\n", capture_output=True, text=True)
    assert pr.returncode == expect_rc and not pr.stderr, (pr.returncode, pr.stderr[-2000:], pr.stdout[-500:])
    return pr.stdout.splitlines()


def run_samples_text(exe, table, s, self_timed=False) -> dict:
    """The driver on a stream through S lines; dict of int64 arrays named FIELDS."""
    rec = input_records(table, s, self_timed)
    lines = [table_line(table)] + ["S " + " ".join(map(str, row)) for row in rec.tolist()]
    out = run_text(exe, lines)
    assert out[0].startswith("T ") and all(line.startswith("O ") for line in out[1:]) and len(out) == len(rec) + 1
    arr = np.array([line.split()[1:] for line in out[1:]], np.int64)
    return {name: arr[:, c] for c, name in enumerate(FIELDS)}


def assert_same(ref, got, keys=KERNEL_KEYS, what=""):
    for key in keys:
        a = np.asarray(ref[key]).astype(np.int64)
        if not np.array_equal(a, got[key]):
            i = int(np.argmax(a != got[key]))
            raise AssertionError(f"{what}: {key} differs first at sample {i} of {len(a)}: reference {a[i]}, "
                                 f"C {got[key][i]}")


def _chans(s) -> dict:
    return {k: s[k] for k in ("f", "t", "aux", "k") if s.get(k) is not None}


def kernel(table, s, self_timed=False):
    return run_words(table, s["p"], s["r"], None if self_timed else s["mode"], s.get("restart"), s.get("z"),
                     self_timed=self_timed, detail=True, **_chans(s))


def reference(table, s, self_timed=False):
    return run_reference(table, s["p"], s["r"], None if self_timed else s["mode"], s.get("restart"), s.get("z"),
                         self_timed=self_timed, **_chans(s))


def table_of(est="diff", combiner="pair", n=5, shift=2, settle_s=2.0, max_stale_s=25.0, coef=None, **kw):
    if coef is None:
        coef = np.array([3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1, 6e1, -5e1])
    temp = est == "lsq"
    model = make_model("temp" if temp else "freq", ref=20.0 if temp else 6227.0, span=30.0 if temp else 3.0,
                       estimator=est, n=n, shift=shift, rate_span=0.5 if temp else 0.003, combiner=combiner,
                       settle_s=settle_s, max_stale_s=max_stale_s, coef=coef)
    return quantize(model, n_random=10, **kw).table


def with_fields(table, **changes) -> Table:
    return dataclasses.replace(table, **changes)


@pytest.fixture(scope="module")
def c_exe(tmp_path_factory):
    return build(tmp_path_factory.mktemp("c_twin"))


@pytest.fixture(scope="module")
def ubsan_exe(tmp_path_factory):
    d = tmp_path_factory.mktemp("c_twin_ubsan")
    probe = d / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    pr = subprocess.run([GCC, *UBSAN, "-o", str(d / "probe"), str(probe)], capture_output=True, text=True)
    if pr.returncode != 0:
        pytest.skip(f"gcc cannot build with -fsanitize=undefined here: {pr.stderr.strip()[:200]}")
    return build(d, "hdrg_fw_ubsan", UBSAN)


# -- build --------------------------------------------------------------------------------------------

def test_builds_clean_with_strict_warnings(tmp_path):
    """The library and driver compile without a warning under -Wconversion etc., and with a
    small history ring; the library alone needs nothing but stdint.h/stddef.h."""
    build(tmp_path, "strict", STRICT)
    build(tmp_path, "small_ring", STRICT, defines=("HDRG_N_HIST_MAX=16",))
    lib = (C_DIR / "hdrg_fw.c").read_text() + (C_DIR / "hdrg_fw.h").read_text()
    includes = sorted({line.split()[1] for line in lib.splitlines() if line.startswith("#include")})
    assert includes == ['"hdrg_fw.h"', "<stddef.h>", "<stdint.h>"]
    for banned in ("float", "double", "malloc", "free(", "<stdio.h>", "<stdlib.h>"):
        assert banned not in (C_DIR / "hdrg_fw.c").read_text(), banned


def test_small_ring_refuses_long_windows(tmp_path):
    exe = build(tmp_path, "small_ring", CFLAGS, defines=("HDRG_N_HIST_MAX=16",))
    ok = table_of("diffn", n=16)
    too_long = table_of("diffn", n=17)
    out = run_text(exe, [table_line(ok), table_line(too_long)], expect_rc=1)
    assert out[0].startswith("T ") and out[1] == "ERR FIELD word 9 rate_n"


# -- bit-exactness: random streams ------------------------------------------------------------------

RANDOM_CASES = [  # (seed, reversal, estimator, samples, self-timed)
    (0, True, "lsq", 1_000_000, False),
    (1, True, "diff", 200_000, False),
    (2, True, "diffn", 200_000, True),
    (3, True, "iir", 200_000, False),
    (4, False, "lsq", 200_000, False),
    (5, False, "iir", 200_000, True),
]


@pytest.mark.parametrize("seed,reversal,estimator,n,self_timed", RANDOM_CASES)
def test_random_streams_equal_numba(c_exe, seed, reversal, estimator, n, self_timed):
    rng = np.random.default_rng(500 + seed)
    table = quantize(random_model(rng, reversal=reversal, estimator=estimator), exchange_s=3.0, dwell_s=7.0,
                     power_on_s=2.0, n_random=10).table
    s = random_stream(rng, table, n, reversal=reversal)
    got = run_bin(c_exe, table, s, self_timed)
    assert_same(kernel(table, s, self_timed), got, what=f"seed {seed}")
    fl = got["flags"]
    for bit in (F.FLAG_PROXY_CLAMPED, F.FLAG_RATE_CLAMPED, F.FLAG_AUX_CLAMPED, F.FLAG_WARMUP):
        assert (fl & bit).any(), bit
    assert got["valid"].any() and (~got["valid"].astype(bool)).any()
    if reversal:
        assert (fl & F.FLAG_STALE).any() and (fl & F.FLAG_EXCHANGE).any()
        assert set(np.unique(got["state"]).tolist()) == ({0, 1, 2, 3, 4} if self_timed else {1, 2, 3, 4})


@pytest.mark.parametrize("seed,estimator,reversal", [(0, "diff", True), (1, "lsq", True), (2, "iir", False)])
def test_random_streams_equal_python_reference(c_exe, seed, estimator, reversal):
    """10^4 samples against the per-sample Python-integer reference, every column."""
    rng = np.random.default_rng(900 + seed)
    table = quantize(random_model(rng, reversal=reversal, estimator=estimator), exchange_s=3.0, dwell_s=7.0,
                     n_random=10).table
    s = random_stream(rng, table, 10_000, reversal=reversal)
    assert_same(reference(table, s), run_bin(c_exe, table, s), REF_KEYS, f"seed {seed}")


# -- corner streams, every estimator and combiner ---------------------------------------------------

@pytest.mark.parametrize("combiner", [None, "pair", "trend"])
@pytest.mark.parametrize("estimator", ["diff", "diffn", "lsq", "iir"])
def test_corner_streams(c_exe, combiner, estimator):
    """Text protocol (S lines): logged modes against the Python reference (every column) and the
    kernel; self-timed against the kernel."""
    table = table_of(estimator, combiner)
    s = corner_stream(table, reversal=combiner is not None)
    got = run_samples_text(c_exe, table, s)
    assert_same(reference(table, s), got, REF_KEYS, "corners")
    assert_same(kernel(table, s), got, what="corners, kernel")
    np.testing.assert_array_equal(got["mode"], s["mode"])
    np.testing.assert_array_equal(got["z"], np.clip(s["z"], -F.ONE, F.ONE))
    if combiner == "trend":
        assert (got["flags"] & F.FLAG_SAT).any()
    got = run_bin(c_exe, table, s, self_timed=True)
    assert_same(reference(table, s, self_timed=True), got, REF_KEYS, "corners, self-timed")
    assert_same(kernel(table, s, self_timed=True), got, what="corners, self-timed, kernel")


def extreme_tables():
    """Valid tables at the edges of every field (Table.validate and the Horner bound hold)."""
    base = table_of("diff", "trend")
    lim = F.INT32_SYM
    out = {}
    # E = 0 (B = t << 21), rows 1..3 and k7 aligned by the largest shift 31, row 0 at the bound
    m = [0] * 17
    for k in (1, 8, 9, 10):
        m[k] = lim // 4 if k != 10 else -(lim - 3 * (lim // 4))
    for k in (2, 11, 12, 13, 3, 14, 15, 16):
        m[k] = (-1) ** k * (lim // 4)
    m[K_AUX] = -lim
    m[0], m[4], m[5], m[6] = 1 << 30, -(1 << 29), 1 << 28, -(lim - 4 - (1 << 30) - (1 << 29) - (1 << 28))
    out["E0_max"] = with_fields(base, e_row=(0, 31, 31, 31), e_7=31, e_acc=0, mant=tuple(m))
    # E = 52 (B = RHU(t, 31)), every exponent equal: all |mantissas| sum to the bound
    m2 = [(-1) ** k * (lim // 17) for k in range(17)]
    out["E52"] = with_fields(base, e_row=(52, 52, 52, 52), e_7=52, e_acc=52, mant=tuple(m2))
    out["E21"] = with_fields(base, e_row=(21, 23, 30, 52), e_7=40, e_acc=21, mant=tuple(m2))
    # proxy gain edges: no shift (u = dP + u_off), the largest shift; temp/freq centres at the word edges
    out["g_u_1"] = with_fields(base, g_u=1, u_off=1, sh_u=0, p_ref=0)
    out["sh_u_62"] = with_fields(base, g_u=lim, u_off=-(lim // 2), sh_u=62, p_ref=F.UINT32_MAX)
    t_tab = table_of("lsq", "pair", n=3)
    out["temp_pref_max"] = with_fields(t_tab, p_ref=lim)
    out["temp_pref_min"] = with_fields(t_tab, p_ref=-lim)
    # rate-sum clamp edges
    out["s_bits_55"] = with_fields(base, s_bits=55, g_v=127, sh_v=0)
    out["s_bits_1"] = with_fields(base, s_bits=1, g_v=lim, sh_v=62)
    # iir shift 0 and 24; the shortest legal warm-up (2); a warm-up that never ends
    iir = table_of("iir", "pair", shift=0)
    out["iir_shift_0"] = with_fields(iir, rate_shift=0, rate_warmup=2)
    out["iir_shift_24"] = with_fields(iir, rate_shift=24)
    out["warmup_forever"] = with_fields(base, rate_warmup=F.TIMER_MAX)
    # timing: no settling and no staleness allowance; everything stale; exchange 0, dwell 1
    out["stale_0_settle_big"] = with_fields(base, max_stale_n=0, settle_n=F.TIMER_MAX)
    out["stale_max"] = with_fields(base, max_stale_n=F.COUNT_MAX - 1, settle_n=0, combiner=1)
    out["dwell_1_exchange_0"] = with_fields(base, dwell_n=1, exchange_n=0, power_on_n=F.TIMER_MAX)
    return out


@pytest.mark.parametrize("name", list(extreme_tables()))
def test_extreme_tables(c_exe, name):
    table = extreme_tables()[name]
    rng = np.random.default_rng(len(name))
    reversal = table.combiner != 0
    outs = []
    for s in (corner_stream(table, reversal), random_stream(rng, table, 1500, reversal=reversal)):
        got = run_bin(c_exe, table, s)
        assert_same(reference(table, s), got, REF_KEYS, name)
        assert_same(kernel(table, s), got, what=name + " (kernel)")
        outs.append(got)
        got = run_bin(c_exe, table, s, self_timed=True)
        assert_same(kernel(table, s, self_timed=True), got, what=name + " (self-timed)")
    flags = np.concatenate([o["flags"] for o in outs])
    out = np.concatenate([o["out"] for o in outs])
    if name == "E0_max":      # |B| up to 2^31 2^21 LSB: the output words saturate
        assert (flags & F.FLAG_SAT).any() and (np.abs(out) == F.INT32_SYM).any()
    if name == "warmup_forever":
        assert (flags & F.FLAG_WARMUP).all() and not out.any()
    if name == "stale_0_settle_big":
        assert not out.any()


def test_longest_lsq_window(c_exe):
    """lsq with n = N_HIST_MAX = 4096: the ring at its compile-time size (kernel only: the Python
    reference would take minutes)."""
    table = with_fields(table_of("lsq", "pair", n=3), rate_n=F.N_HIST_MAX, rate_warmup=F.N_HIST_MAX - 1)
    rng = np.random.default_rng(3)
    s = random_stream(rng, table, 20_000)
    s["restart"][:] = 0
    s["restart"][[0, 9000]] = 1
    got = run_bin(c_exe, table, s)
    assert_same(kernel(table, s), got, what="lsq n=4096")
    assert (got["s"] != 0).any()


# -- counter edges ------------------------------------------------------------------------------------

def test_settle_and_staleness_edges(c_exe):
    """Windows of settle_n - 1, settle_n, settle_n + 1 samples and gaps around max_stale_n: both
    sides of every comparison happen (against the reference, every column)."""
    table = with_fields(table_of("diff", "trend"), settle_n=3, max_stale_n=12)
    modes = []
    for w in (2, 3, 4, 5):
        for gap in (1, 5, 8, 9, 10, 11):
            modes += [1] * w + [3] * gap + [2] * w + [3] * gap
    modes = np.array(modes * 2, np.int64)
    n = len(modes)
    rng = np.random.default_rng(0)
    s = {"p": table.p_ref + np.cumsum(rng.integers(-300, 301, n)), "r": rng.integers(-5000, 5000, n),
         "mode": modes, "restart": np.r_[1, np.zeros(n - 1)].astype(np.uint8), "z": np.zeros(n, np.int64)}
    got = run_bin(c_exe, table, s)
    assert_same(reference(table, s), got, REF_KEYS, "edges")
    in_window = (s["mode"] == 1) | (s["mode"] == 2)
    assert (got["valid"][in_window] == 1).any() and (got["flags"][in_window] & F.FLAG_STALE).any()


def test_trend_distance_saturates_on_long_gaps(c_exe):
    """A mode-2 window more than 2^21 samples after the last mode-1 window: the trend distance
    d = 2 age + span clamps at D_MAX = 2^22 - 1 (flag 128); C == kernel over 2.2 * 10^6 samples."""
    table = with_fields(table_of("diff", "trend"), settle_n=0, max_stale_n=3_000_000)
    m = [1] * 6 + [3] * 2 + [2] * 6 + [3] * 2 + [1] * 6 + [3] * 2_150_000 + [2] * 40
    n = len(m)
    rng = np.random.default_rng(1)
    s = {"p": np.full(n, table.p_ref) + rng.integers(-3, 4, n), "r": rng.integers(-20000, 20000, n),
         "mode": np.array(m, np.int64), "restart": np.r_[1, np.zeros(n - 1)].astype(np.uint8), "z": None}
    got = run_bin(c_exe, table, s)
    assert_same(kernel(table, s), got, what="long gap")
    assert (got["flags"][-40:] & F.FLAG_SAT).all() and got["valid"][-20:].all()


# -- primitives, evaluator, tables --------------------------------------------------------------------

I64_MIN, I64_MAX = -(1 << 63), (1 << 63) - 1


def primitive_cases(rng):
    """(request, expected response) pairs; preconditions violated -> ERR RANGE (arith asserts)."""
    cases = []

    def expect(req, fn, fmt):
        try:
            val = fn()
        except AssertionError:
            cases.append((req, "ERR RANGE"))
            return
        cases.append((req, fmt(val)))

    one = lambda v: f"R {v}"                                   # noqa: E731
    two = lambda v: f"R {v[0]} {int(v[1])}"                    # noqa: E731
    for s in range(0, 63):
        ks = [0, 1, -1, 2, -2, 12345, -12345] + list(rng.integers(-(1 << (62 - s)), 1 << (62 - s), 6))
        for k in ks:
            for d in (-1, 0, 1):
                x = int(k) * (1 << s) + ((1 << (s - 1)) if s else 0) + d
                if I64_MIN <= x <= I64_MAX:
                    expect(f"RHU {x} {s}", lambda: arith.rshift_round(x, s), one)
        for x in (I64_MIN, I64_MAX, I64_MAX - (1 << max(s - 1, 0)), I64_MAX - (1 << max(s - 1, 0)) + 1):
            expect(f"RHU {x} {s}", lambda: arith.rshift_round(x, s), one)
    vals = [0, 1, -1, F.ONE, -F.ONE, F.INT32_SYM, -F.INT32_SYM, -(1 << 31), 3 << 28, (1 << 31) + 1]
    vals += [int(v) for v in rng.integers(-(1 << 40), 1 << 40, 6)]
    for a in vals:
        for b in vals:
            for s in (0, 1, 29, 30, 31, 61, 62):
                expect(f"MULRHU {a} {b} {s}", lambda: arith.mul_rshift_round(a, b, s), one)
    divs = [1, 2, 3, 7, 10, 1 << 20, F.INT32_SYM, (1 << 62) + 1, I64_MAX]
    nums = [0, 1, -1, 5, -5, 7, -7, I64_MIN, I64_MAX, -(1 << 62) - 1, (1 << 62) - 1]
    nums += [int(v) for v in rng.integers(-(1 << 62), 1 << 62, 8)]
    for a in nums:
        for b in divs:
            expect(f"FLOORDIV {a} {b}", lambda: arith.floor_div(a, b), one)
            expect(f"DIVROUND {a} {b}", lambda: arith.div_round(a, b), one)
            for k in (0, 1, 10, 16, 40, 62):
                expect(f"DIVRS {a} {b} {k}", lambda: arith.div_round_scaled(a, b, k), one)
    for b in (2, 4, 6, 10, 1 << 31):                          # exact ties of div_round
        for q in (-3, -1, 0, 2):
            a = q * b + b // 2
            expect(f"DIVROUND {a} {b}", lambda: arith.div_round(a, b), one)
            expect(f"DIVRS {a} {b} 0", lambda: arith.div_round_scaled(a, b, 0), one)
    for w in range(1, 64):
        lim = (1 << (w - 1)) - 1
        for x in (lim, lim + 1, -lim, -lim - 1, 0, I64_MIN, I64_MAX):
            expect(f"SAT {x} {w}", lambda: arith.sat_signed(x, w), two)
    for x in (-5, 0, 5, I64_MIN, I64_MAX):
        expect(f"CLAMP {x} -3 4", lambda: arith.clamp(x, -3, 4), two)
    from firmware_ref.aux import sin_q30
    lim31, lim62 = (1 << 31) - 1, 1 << 62
    for s in (30, 31, 32, 45, 61, 62, 63):
        for a in (lim31, -lim31, 1 << 31, 0, 3, -3, int(rng.integers(-lim31, lim31))):
            for d in (lim62, -lim62, lim62 + 1, (1 << (s - 1)) if s < 63 else 1, -(1 << 31), (1 << 31) - 1,
                      int(rng.integers(-lim62, lim62))):
                expect(f"RHUW {a} {d} {s}", lambda: arith.mul_rshift_round_wide(a, d, s), one)
    phases = [0, 1, -1, I64_MIN, I64_MAX, 1 << 62, -(1 << 62), 3 << 61]
    for ph in phases + [int(x) for x in rng.integers(I64_MIN, I64_MAX, 40)]:
        expect(f"SIN {ph}", lambda: sin_q30(ph & 0xFFFFFFFFFFFFFFFF), one)
    return cases


def test_primitives_equal_arith(c_exe):
    """RHU ties at every shift, products, floor/round divisions at ties and int64 edges,
    saturation edges at every width: the same values as firmware_ref.arith, and ERR RANGE exactly
    where arith's preconditions fail."""
    cases = primitive_cases(np.random.default_rng(0))
    out = run_text(c_exe, [req for req, _ in cases], expect_rc=1)
    assert len(out) == len(cases)
    bad = [(req, exp, got) for (req, exp), got in zip(cases, out) if not got.startswith(exp) or
           (not exp.startswith("ERR") and got != exp)]
    assert not bad, bad[:5]
    assert sum(exp == "ERR RANGE" for _, exp in cases) > 10
    assert sum(req.startswith("RHU ") for req, _ in cases) > 2000
    assert sum(req.startswith("RHUW") and exp == "ERR RANGE" for req, exp in cases) > 10


def test_evaluator_alone(c_exe):
    """EVAL on the corners of (u, v, z) (+-2^30, +-(2^30 - 1), +-1, 0, z beyond +-2^30) and random
    points, for small and large coefficient scales: == the kernel and the Python evaluator."""
    rng = np.random.default_rng(2)
    g = np.array([-F.ONE, -F.ONE + 1, -1, 0, 1, F.ONE - 1, F.ONE], np.int64)
    zg = np.r_[g, F.ONE + 1, -F.ONE - 1, F.INT32_SYM, -(1 << 31)]
    uu, vv, zz = (a.ravel() for a in np.meshgrid(g, g, zg, indexing="ij"))
    u = np.r_[uu, rng.integers(-F.ONE, F.ONE + 1, 1500)]
    v = np.r_[vv, rng.integers(-F.ONE, F.ONE + 1, 1500)]
    z = np.r_[zz, rng.integers(-(1 << 31), 1 << 31, 1500)]
    tables = [quantize(make_model(coef=rng.choice([-1, 1], 17) * sc * 10 ** rng.uniform(-4, 0, 17)),
                       n_random=10).table for sc in (1e-4, 1.0, 1e5)]
    tables.append(extreme_tables()["E0_max"])
    tables.append(extreme_tables()["E52"])
    for table in tables:
        lines = [table_line(table)] + [f"EVAL {a} {b} {c}" for a, b, c in zip(u, v, z)]
        out = run_text(c_exe, lines)
        got = np.array([line.split()[1:] for line in out[1:]], np.int64)
        np.testing.assert_array_equal(got[:, 0], evaluate_words(table, u, v, z))
        for i in range(0, len(u), 7):
            assert tuple(got[i]) == tuple(int(x) for x in evaluate(int(u[i]), int(v[i]), int(z[i]), table))
    out = run_text(c_exe, [table_line(tables[0]), f"EVAL {F.ONE + 1} 0 0"], expect_rc=1)
    assert out[1].startswith("ERR RANGE")


def recrc(words):
    return list(words[:-1]) + [crc32_words(words[:-1])]


def table_cases():
    """(name, words, C error code, word index): corrupted tables both implementations refuse."""
    base = table_of("diff", "pair")
    w = base.to_words()
    FI = FIELD_INDEX

    def field(name, value, extra=None):
        ww = list(w)
        ww[FI[name]] = value & 0xFFFFFFFF
        for k, v in (extra or {}).items():
            ww[FI[k]] = v & 0xFFFFFFFF
        return recrc(ww)

    cases = [
        ("magic", [w[0] ^ 1] + w[1:], "MAGIC", 0),
        ("version", recrc([w[0], 5] + w[2:]), "VERSION", 1),
        ("version_0", recrc([w[0], 0] + w[2:]), "VERSION", 1),
        # an iir table of layout version 2 was quantized for the blanked start-up: refused
        ("iir_v2", recrc([w[0], 2] + w[2:FI["rate_est"]] + [3] + w[FI["rate_est"] + 1:]), "VERSION", 1),
        # a frequency-proxy table of layout version 3 holds P_REF in the old 2^-18 Hz word: refused
        ("freq_word_v3", recrc([w[0], 3] + w[2:]), "VERSION", 1),
        ("short", w[:-2] + [w[-1]], "LENGTH", 2),
        ("length_word", recrc(w[:2] + [72] + w[3:]), "LENGTH", 2),
        ("crc", w[:-1] + [w[-1] ^ 0x80000000], "CRC", 72),
        ("aux_params", recrc(w[:2] + [74] + w[3:-1] + [5, 0]), "LENGTH", 46),
        ("aux_params_declared", recrc(w[:2] + [74] + w[3:FI["aux_nparams"]] + [1] + w[FI["order"]:-1] + [5, 0]),
         "FIELD", 46),
        ("v2_words_as_v1", recrc([w[0], 1] + w[2:]), "LENGTH", 46),
        ("proxy_kind", field("proxy_kind", 2), "FIELD", 3),
        ("temp_p_ref", field("p_ref", -(1 << 31), {"proxy_kind": 1}), "FIELD", 4),
        ("g_u_zero", field("g_u", 0), "FIELD", 5),
        ("g_u_negative", field("g_u", -5), "FIELD", 5),
        ("u_off", field("u_off", base.g_u // 2 + 2), "FIELD", 6),
        ("sh_u", field("sh_u", 63), "FIELD", 7),
        ("rate_est", field("rate_est", 4), "FIELD", 8),
        ("rate_n_zero", field("rate_n", 0), "FIELD", 9),
        ("rate_n_big", field("rate_n", F.N_HIST_MAX + 1), "FIELD", 9),
        ("lsq_n_1", field("rate_est", 2, {"rate_n": 1}), "FIELD", 9),
        ("rate_shift", field("rate_shift", 25), "FIELD", 10),
        ("rate_warmup", field("rate_warmup", 0), "FIELD", 11),
        ("s_bits_0", field("s_bits", 0), "FIELD", 12),
        ("s_bits_56", field("s_bits", 56), "FIELD", 12),
        ("g_v_vs_s_bits", field("s_bits", 40, {"g_v": 1 << 22}), "FIELD", 13),
        ("sh_v", field("sh_v", 70), "FIELD", 14),
        ("fs", field("fs_q16", 0), "FIELD", 15),
        ("combiner", field("combiner", 3), "FIELD", 16),
        ("settle", field("settle_n", 1 << 31), "FIELD", 17),
        ("stale", field("max_stale_n", F.COUNT_MAX), "FIELD", 18),
        ("dwell", field("dwell_n", 0), "FIELD", 21),
        ("e_0_big", field("e_0", 53), "FIELD", 22),
        ("e_1_below_E", field("e_1", base.e_acc - 1), "FIELD", 23),
        ("e_7_align", field("e_7", base.e_acc + 32), "FIELD", 26),
        ("mant_min", field("m_5", -(1 << 31)), "FIELD", FI["m_5"]),
        ("aux_gen", field("aux_gen", 2), "FIELD", 45),
        ("aux_gen_1_no_params", field("aux_gen", 1), "FIELD", 46),
        ("order", field("order", 2), "FIELD", 47),
        ("n_banks_order_0", field("n_banks", 2), "FIELD", 48),
        ("order_1_one_bank", field("order", 1), "FIELD", 48),
        ("bank2_in_one_bank", field("e2_0", 5), "FIELD", 49),
        ("m2_in_one_bank", field("m2_3", 1), "FIELD", FI["m2_3"]),
        ("ftr_two_banks", field("combiner", 0, {"order": 1, "n_banks": 2}), "FIELD", 16),
        ("bank2_e_big", field("e2_1", 53, {"order": 1, "n_banks": 2}), "FIELD", FI["e2_1"]),
        ("bank2_mant_min", field("m2_5", -(1 << 31), {"order": 1, "n_banks": 2, "e2_0": base.e_row[0],
                                 "e2_1": base.e_row[1], "e2_2": base.e_row[2], "e2_3": base.e_row[3],
                                 "e2_7": base.e_7, "e2_acc": base.e_acc}), "FIELD", FI["m2_5"]),
    ]
    return base, cases


def test_table_checks(c_exe):
    """Corrupted tables: Table.from_words (Python) raises TableError and the C parser refuses them
    with the right code and word; a valid table loads with its CRC (computed in C)."""
    base, cases = table_cases()
    lines = [table_line(base)]
    for name, words, _, _ in cases:
        with pytest.raises(TableError):
            Table.from_words(words, name)
        lines.append("TABLE " + " ".join(f"{x:08x}" for x in words))
    out = run_text(c_exe, lines, expect_rc=1)
    assert out[0] == f"T 73 {base.crc:08x}"
    for (name, _, code, word), got in zip(cases, out[1:]):
        assert got.startswith(f"ERR {code} word {word} "), (name, got)
    # a table refused leaves no table
    out = run_text(c_exe, [lines[1], "S 0 0 0 0 1 0"], expect_rc=1)
    assert out[1].startswith("ERR NOTABLE")


def test_horner_bound_is_checked_in_c(c_exe):
    """A CRC-valid table whose mantissas break the quantizer's interval bound: its evaluator could
    overflow int64, so the C parser refuses it (HORNER), and so does Python's Table.validate."""
    from firmware_ref.table import TableError, crc32_words
    base = table_of("diff", "pair")
    m = [F.INT32_SYM // 16] * 17
    with pytest.raises(TableError, match="Horner"):
        with_fields(base, e_row=(30,) * 4, e_7=30, e_acc=30, mant=tuple(m))   # Table() validates
    big = copy.copy(base)
    big.e_row, big.e_7, big.e_acc, big.mant = (30,) * 4, 30, 30, tuple(m)
    words = big.to_words()[:-1]
    words.append(crc32_words(words))                       # a valid CRC over the bad table
    with pytest.raises(TableError, match="Horner"):
        Table.from_words(words)
    out = run_text(c_exe, ["TABLE " + " ".join(f"{w:08x}" for w in words)], expect_rc=1)
    assert out[0].startswith("ERR HORNER")
    ok = with_fields(base, e_row=(30,) * 4, e_7=30, e_acc=30, mant=tuple([F.INT32_SYM // 17] * 17))
    assert run_text(c_exe, [table_line(ok)])[0].startswith("T 73 ")


def test_crc_equals_zlib(c_exe):
    rng = np.random.default_rng(4)
    lists = [[], [0], [0xFFFFFFFF], list(range(7))] + [list(rng.integers(0, 1 << 32, k)) for k in (1, 5, 48, 200)]
    out = run_text(c_exe, ["CRC " + " ".join(f"0x{int(x):08X}" for x in ws) for ws in lists])
    for ws, got in zip(lists, out):
        data = struct.pack(f"<{len(ws)}I", *[int(x) for x in ws])
        assert got == f"R {zlib.crc32(data) & 0xFFFFFFFF:08x}"


def test_protocol_errors(c_exe):
    table = table_of("diff", "pair")
    lines = ["S 0 0 0 0 1 0", "EVAL 0 0 0", "RESET", "BOGUS 1", table_line(table), "# a comment", "",
             f"S {table.p_ref} 0 5 1 1 0  # trailing comment", "S 1 2 3", "S x 0 0 1 0 0",
             f"S {1 << 32} 0 0 1 0 0", f"S 0 {1 << 31} 0 1 0 0", f"S 0 0 {-(1 << 31) - 1} 1 0 0",
             "S 0 0 0 4 0 0", "S 0 0 0 1 4 0", "S 0 0 0 -1 0 0", "RESET", "S 0 0 0 -1 0 0",
             "S 0 0 0 2 0 0", "TABLE BUILTIN", "TABLE 47524448 zz", f"RHU 1 {1 << 70}", "SAT 1 64",
             "RESET"]
    out = run_text(c_exe, lines, expect_rc=1)
    expect = ["ERR NOTABLE", "ERR NOTABLE", "ERR NOTABLE", "ERR SYNTAX", "T 73", "O ", "ERR SYNTAX",
              "ERR SYNTAX", "ERR RANGE F", "ERR RANGE T", "ERR RANGE R", "ERR RANGE MODE", "ERR RANGE RESTART",
              "ERR RANGE MODE -1", "OK", "O ", "ERR RANGE MODE -1", "ERR SYNTAX", "ERR SYNTAX", "ERR SYNTAX",
              "ERR RANGE", "ERR NOTABLE"]
    assert len(out) == len(expect)
    for got, exp in zip(out, expect):
        assert got.startswith(exp), (got, exp)
    assert run_text(c_exe, [table_line(table), "RESET", "QUIT", "BOGUS"]) == [f"T 73 {table.crc:08x}", "OK"]


def test_binary_block_errors_are_fatal(c_exe):
    table = table_of("diff", "pair")
    rec = np.zeros((3, 6), "<i8")
    rec[:, 3] = 7
    for data in (f"{table_line(table)}\nBIN 3\n".encode() + rec.tobytes(),
                 f"{table_line(table)}\nBIN 3\n".encode() + rec.tobytes()[:50],
                 b"BIN 1\n" + rec[:1].tobytes()):
        pr = subprocess.run([str(c_exe)], input=data, capture_output=True)
        assert pr.returncode == 2 and b"fatal" in pr.stderr


# -- the simulator's paper scenarios with fitted, quantized models ----------------------------------

@pytest.mark.parametrize("scenario,combiner,duration", [("paper-mr-cycle-4dpm", "pair", 20000.0),
                                                        ("paper-mr-cycle-4dpm", "trend", 20000.0),
                                                        ("paper-ftr-cycle-4dpm", None, 8000.0)])
def test_paper_scenarios(c_exe, scenario, combiner, duration):
    from host_tools.golden import compensate as hc
    from host_tools.fitting.fit import fit_logs
    from host_tools.golden.reversal import ReversalConfig
    from host_tools.simulation.sim import simulate

    log = simulate(scenario, seed=3, duration_s=duration)
    cfg = hc.fit_config_from_logs([log], reversal=None if combiner is None else ReversalConfig(combiner))
    model, _ = fit_logs([log], cfg)
    table = quantize(model, n_random=100).table
    w = log_words(log, cfg)
    got = run_bin(c_exe, table, w)
    assert_same(kernel(table, w), got, what=scenario)
    assert got["valid"].mean() > 0.5 and not (got["flags"] & F.FLAG_SAT).any()
    if combiner is not None:                # the internal sequencer on the same words
        assert_same(kernel(table, w, self_timed=True), run_bin(c_exe, table, w, self_timed=True),
                    what=scenario + " self-timed")


# -- undefined-behaviour sanitizer, broken build -------------------------------------------------------

def test_ubsan_build(ubsan_exe):
    """The -fsanitize=undefined -fno-sanitize-recover=all build (any UB aborts with a message on
    stderr, which run_bin/run_text refuse) on the corner streams of every configuration, the
    extreme tables, the primitives at the int64 edges and random streams: same words."""
    for est in ("diff", "diffn", "lsq", "iir"):
        for comb in (None, "pair", "trend"):
            table = table_of(est, comb)
            s = corner_stream(table, reversal=comb is not None)
            assert_same(kernel(table, s), run_bin(ubsan_exe, table, s), what=f"ubsan {est} {comb}")
    for name, table in extreme_tables().items():
        s = random_stream(np.random.default_rng(1), table, 1000, reversal=table.combiner != 0)
        assert_same(kernel(table, s), run_bin(ubsan_exe, table, s), what=f"ubsan {name}")
        s = corner_stream(table, reversal=table.combiner != 0)
        assert_same(kernel(table, s, True), run_bin(ubsan_exe, table, s, True), what=f"ubsan {name} timed")
    rng = np.random.default_rng(8)
    for est in ("lsq", "iir"):
        table = quantize(random_model(rng, estimator=est), exchange_s=3.0, dwell_s=7.0, n_random=10).table
        s = random_stream(rng, table, 20_000)
        assert_same(kernel(table, s), run_bin(ubsan_exe, table, s), what=f"ubsan random {est}")
    for seed in range(6):                     # aux generators of every kind, long K jumps, extremes
        table, s = aux_case(seed, 20_000)
        assert_same(kernel(table, s), run_bin(ubsan_exe, table, s), what=f"ubsan aux {seed}")
    table = aux_extreme_table()
    s = aux_stream(np.random.default_rng(3), table, 5000, extreme=0.05)
    assert_same(kernel(table, s), run_bin(ubsan_exe, table, s), what="ubsan aux extremes")
    from host_tools.vectors.builders import two_bank_table    # regress_first: residual saturation, both banks
    big = np.zeros(17)
    big[0] = 2.0 ** 21 * 0.9
    e = extreme_tables()
    for comb in (1, 2, 3):
        for t1, t2 in ((table_of("diffn", "pair"), table_of("diffn", "pair", coef=big)),
                       (e["E0_max"], e["E52"])):
            table = two_bank_table(t1 if t1.combiner else with_fields(t1, combiner=1), t2, comb)
            s = corner_stream(table)
            assert_same(kernel(table, s), run_bin(ubsan_exe, table, s), what=f"ubsan regress_first {comb}")
            assert_same(kernel(table, s, True), run_bin(ubsan_exe, table, s, True), what=f"ubsan rtr {comb} timed")
    cases = primitive_cases(np.random.default_rng(1))
    out = run_text(ubsan_exe, [req for req, _ in cases], expect_rc=1)
    assert all(got.startswith(exp) for (_, exp), got in zip(cases, out)) and len(out) == len(cases)


def test_ubsan_aborts_on_undefined_behaviour(ubsan_exe, tmp_path):
    """Control: the sanitizer flags do abort a program with a signed overflow (so a clean run of
    the twin means something)."""
    src = tmp_path / "overflow.c"
    src.write_text("int main(int argc, char **argv) {\n    long long x = 9223372036854775807LL;\n"
                   "    (void)argv;\n    return (int)((x + argc) & 1);\n}\n")
    exe = build(tmp_path, "overflow", UBSAN, sources=(src,))
    pr = subprocess.run([str(exe)], capture_output=True, text=True)
    assert pr.returncode != 0 and "runtime error" in pr.stderr


def test_broken_rounding_build_is_caught(tmp_path):
    """-DHDRG_BREAK_ROUNDING (RHU truncates): the comparison with the kernel fails."""
    broken = build(tmp_path, "hdrg_fw_broken", CFLAGS, defines=("HDRG_BREAK_ROUNDING",))
    rng = np.random.default_rng(0)
    table = quantize(random_model(rng, estimator="diff"), exchange_s=3.0, dwell_s=7.0, n_random=10).table
    s = random_stream(rng, table, 10_000)
    with pytest.raises(AssertionError, match="differs first"):
        assert_same(kernel(table, s), run_bin(broken, table, s), what="broken build")
    assert run_text(broken, ["RHU 3 1"]) == ["R 1"]          # 1.5 truncated (the correct build: 2)


# -- aux generators (aux_gen 1) -------------------------------------------------------------------------

AUX_CASE_TERMS = (3, 4, 5, 6, 9, 12, 16, 16)     # terms of aux_case(seed) by seed % 8 (AUX_MAX_TERMS 16)


def aux_case(seed, n, reversal=None):
    """A random aux model (3..16 terms: AUX_CASE_TERMS; from 7 terms on every kind) quantized, and an
    aux stream for it."""
    rng = np.random.default_rng(3000 + seed)
    reversal = seed % 3 != 2 if reversal is None else reversal
    est = ("diff", "diffn", "lsq", "iir")[seed % 4]
    model = random_aux_model(rng, reversal=reversal, estimator=est, n_terms=AUX_CASE_TERMS[seed % 8])
    table = quantize(model, exchange_s=3.0, dwell_s=7.0, power_on_s=2.0, n_random=10).table
    return table, aux_stream(rng, table, n, reversal=reversal)


def aux_extreme_table():
    """Hand-made: every coefficient at an edge (REF at the word limits, G 1 and 2^31 - 1, SH 62,
    B 1 / 2^31 - 1 at SB 62 / 31, ramp N = 1, osc W = 1 and 2^63 - 1, power 5, AF 0 and 48)."""
    from firmware_ref.table import AuxTerm, encode_aux
    lim = F.INT32_SYM
    terms = (AuxTerm(0, 0, 2, 5, 1 << 27, (-lim, lim, lim // 2, 62, lim, 31)),
             AuxTerm(0, 1, 0, 1, -(1 << 27), (F.UINT32_MAX, 1, 0, 0, 1, 62)),
             AuxTerm(3, 0, 0, 1, 1 << 27, (lim, 31, 0, 0, 0, 0)),
             AuxTerm(4, 1, 0, 1, -(1 << 27), (1, 62, 0, 0, 0, 0)),
             AuxTerm(6, 1, 0, 1, 1 << 27, (1, 0, 1, 0, 0, 0)),
             AuxTerm(6, 0, 0, 1, (1 << 27) + 5, ((1 << 63) - 1, 0, 0, 0, 0, 0)))
    return with_fields(table_of("diff", "trend"), aux_gen=1, aux_params=encode_aux((0, 48, 13), terms))


@pytest.mark.parametrize("seed", range(8))
def test_aux_random_streams_equal_numba(c_exe, seed):
    """Random aux tables (every kind, signs, powers, filters up to 10^6 samples, K gaps and values
    near 2^62) through BIN blocks of width 11, logged and self-timed: == the kernel, z included."""
    table, s = aux_case(seed, 100_000)
    got = run_bin(c_exe, table, s)
    assert_same(kernel(table, s), got, what=f"aux seed {seed}")
    assert len(np.unique(got["z"])) > 100
    if table.combiner:
        assert_same(kernel(table, s, True), run_bin(c_exe, table, s, True), what=f"aux seed {seed} self-timed")


@pytest.mark.parametrize("seed", range(3))
def test_aux_streams_equal_python_reference(c_exe, seed):
    table, s = aux_case(10 + seed, 5000)
    assert_same(reference(table, s), run_bin(c_exe, table, s), REF_KEYS + ("z",), f"aux seed {seed}")


def test_aux_extreme_table(c_exe):
    table = aux_extreme_table()
    rng = np.random.default_rng(4)
    for s in (aux_stream(rng, table, 3000, extreme=0.05), aux_stream(rng, table, 3000, extreme=0.5)):
        got = run_bin(c_exe, table, s)
        assert_same(reference(table, s), got, REF_KEYS + ("z",), "aux extremes")
        assert_same(kernel(table, s), got, what="aux extremes (kernel)")


def test_aux_text_protocol_and_internal_counter(c_exe):
    """S lines of 7..11 fields: K given (and the aux words) or, with 6 fields, the internal
    counter (0, 1, 2, ... since TABLE/RESET; restarts do not reset it) and aux words 0."""
    base = table_of("diff", "pair")
    model = make_model(coef=[3e3, -2e3, 1e3, -5e2, 7e2, -3e2, 1e2, 5e2, -4e2, 3e2, -2e2, 1e2, -9e1, 8e1, -7e1,
                             6e1, -5e1], settle_s=2.0, max_stale_s=25.0)
    table = quantize(with_aux(model, [{"gen": "ramp", "n_samples": 40, "weight": 0.4},
                                      {"gen": "osc", "period_s": 9.0, "part": "cos", "weight": 0.3},
                                      {"gen": "input", "column": "aux_x", "ref": 1.0, "span": 2.0, "weight": 0.3}]),
                     n_random=10).table
    assert table.e_row != base.e_row or table.aux_gen == 1
    rng = np.random.default_rng(6)
    s = aux_stream(rng, table, 300, k_jumps=False)
    got = run_samples_text(c_exe, table, s)                 # 11 fields, K = 0, 1, 2, ...
    assert_same(kernel(table, s), got, what="text, K given")
    s6 = {k: s[k] for k in ("p", "r", "mode", "restart", "z")}
    got6 = run_samples_text(c_exe, table, s6)               # 6 fields: the internal counter, A0 = 0
    ref6 = run_words(table, s["p"], s["r"], s["mode"], s["restart"], s["z"], detail=True, t=s["t"],
                     aux=np.zeros((300, 1), np.int64))
    assert_same(ref6, got6, what="text, internal counter")
    assert not np.array_equal(got6["z"], got["z"])         # the A0 word matters
    lines = [table_line(table), "S 0 0 0 1 1 0 5", "S 0 0 0 1 0 0 6 1 2 3 4", f"S 0 0 0 1 0 0 {(1 << 62) + 1}",
             "S 0 0 0 1 0 0 0 1 2 3 4 5", f"S 0 0 0 1 0 0 0 {1 << 31}"]
    out = run_text(c_exe, lines, expect_rc=1)
    assert out[0].startswith("T ") and out[1].startswith("O ") and out[2].startswith("O ")
    assert out[3].startswith("ERR RANGE K") and out[4].startswith("ERR SYNTAX") and out[5].startswith("ERR RANGE A")


def test_aux_table_checks(c_exe):
    """Every aux field out of range: Table (Python) raises TableError naming it, the C parser
    refuses it with FIELD and the word index; counts that do not add up: FIELD at aux_nparams."""
    from firmware_ref.table import N_FIXED
    table = aux_extreme_table()
    w = table.to_words()
    nc = table.aux().n_chan
    t0 = N_FIXED + 2 + nc                     # first word of term 0
    term = lambda j, i: t0 + 11 * j + i       # noqa: E731

    def put(changes, length=None):
        ww = list(w[:-1])
        for i, v in changes.items():
            ww[i] = v & 0xFFFFFFFF
        if length is not None:
            ww = ww[:length]
            ww[2] = len(ww) + 1
            ww[FIELD_INDEX["aux_nparams"]] = len(ww) - N_FIXED
        return ww + [crc32_words(ww)]

    cases = [
        ("n_terms_0", put({N_FIXED: 0}), N_FIXED),
        ("n_terms_17", put({N_FIXED: F.AUX_MAX_TERMS + 1}), N_FIXED),
        ("n_chan_5", put({N_FIXED + 1: 5}), N_FIXED + 1),
        ("count_mismatch", put({N_FIXED: 5}), FIELD_INDEX["aux_nparams"]),
        ("af_49", put({N_FIXED + 3: 49}), N_FIXED + 3),
        ("kind_7", put({term(2, 0): 7}), term(2, 0)),
        ("sign_2", put({term(0, 1): 2}), term(0, 1)),
        ("weight_big", put({term(0, 4): (1 << 30) + 1}), term(0, 4)),
        ("input_src", put({term(0, 2): 2 + nc}), term(0, 2)),
        ("input_power_0", put({term(0, 3): 0}), term(0, 3)),
        ("input_power_6", put({term(0, 3): 6}), term(0, 3)),
        ("input_ref_min", put({term(0, 5): -(1 << 31)}), term(0, 5)),
        ("input_g_0", put({term(0, 6): 0}), term(0, 6)),
        ("input_off", put({term(1, 7): 2}), term(1, 7)),
        ("input_sh", put({term(0, 8): 63}), term(0, 8)),
        ("input_sb_30", put({term(0, 10): 30}), term(0, 10)),
        ("input_b_0", put({term(0, 9): 0}), term(0, 9)),
        ("input_b_without_sb", put({term(0, 10): 0}), term(0, 9)),
        ("decay_power", put({term(2, 3): 2}), term(2, 3)),
        ("decay_src", put({term(2, 2): 1}), term(2, 2)),
        ("decay_b_0", put({term(2, 5): 0}), term(2, 5)),
        ("decay_sb_63", put({term(3, 6): 63}), term(3, 6)),
        ("decay_unused", put({term(3, 7): 1}), term(3, 7)),
        ("osc_w_0", put({term(4, 5): 0}), term(4, 5)),
        ("osc_w_hi_negative", put({term(5, 6): 0x80000000}), term(5, 6)),
        ("osc_part_2", put({term(4, 7): 2}), term(4, 7)),
        ("osc_unused", put({term(4, 8): 1}), term(4, 8)),
        ("rate_src", put({term(2, 0): 1, term(2, 5): 20, term(2, 6): 5, term(2, 2): 1}), term(2, 2)),
        ("rate_sb_0", put({term(2, 0): 1, term(2, 5): 0}), term(2, 5)),
        ("rate_g_big", put({term(2, 0): 1, term(2, 5): 40, term(2, 6): 1 << 22}), term(2, 6)),
        ("ramp_n_0", put({term(2, 0): 5, term(2, 5): 0, term(2, 6): 7}), term(2, 5)),
        ("ramp_sh", put({term(2, 0): 5, term(2, 5): 4, term(2, 6): 7, term(2, 7): 63}), term(2, 7)),
        # g = RHU((N - 1) G, SH) above 2^30 (here 2^40): w g would overflow int64
        ("ramp_above_one", put({term(2, 0): 5, term(2, 5): 1 << 20, term(2, 6): (1 << 30) - 1, term(2, 7): 9}),
         term(2, 6)),
        ("ramp_one_lsb_over", put({term(2, 0): 5, term(2, 5): 2, term(2, 6): (1 << 30) + 1, term(2, 7): 0}),
         term(2, 6)),
        ("one_coef", put({term(2, 0): 2, term(2, 6): 0}), term(2, 5)),
        ("weight_sum", put({term(j, 4): 1 << 29 for j in range(6)}), term(5, 4)),
    ]
    lines = [table_line(table)]
    for name, words, _ in cases:
        with pytest.raises(TableError):
            Table.from_words(words, name)
        lines.append("TABLE " + " ".join(f"{x:08x}" for x in words))
    out = run_text(c_exe, lines, expect_rc=1)
    assert out[0] == f"T {len(w)} {table.crc:08x}"
    names = [x[0] for x in LAYOUT] + table.param_names()       # the driver names the aux words as Python does
    for (name, _, word), got in zip(cases, out[1:]):
        assert got == f"ERR FIELD word {word} {names[word]}", (name, got)


def test_aux_max_terms_table_runs_and_one_more_is_refused(c_exe):
    """The longest table (AUX_MAX_TERMS = 16 terms of every kind on all four aux words: 255 words)
    loads (T 255), runs bit for bit as the kernel and the Python reference, and resets its sixteen
    states at RESET; a 17-term table with consistent words (266) is refused as FIELD at word 72,
    named aux_n_terms (HDRG_AUX_MAX_TERMS), as Python's Table refuses it naming n_terms."""
    from firmware_ref.table import N_FIXED, encode_aux
    from host_tools.vectors.aux import MAX_TERMS_EVERY_KIND, quantize_aux
    table = quantize_aux(with_aux(make_model(settle_s=2.0, max_stale_s=25.0), list(MAX_TERMS_EVERY_KIND)))
    aux = table.aux()
    assert len(aux.terms) == F.AUX_MAX_TERMS and aux.n_chan == F.AUX_MAX_CHANNELS and len(table.to_words()) == 255
    rng = np.random.default_rng(17)
    for s in (aux_stream(rng, table, 20_000), aux_stream(rng, table, 3000, extreme=0.2)):
        got = run_bin(c_exe, table, s)
        assert_same(kernel(table, s), got, what="16 terms")
        assert len(np.unique(got["z"])) > 100
    s = aux_stream(rng, table, 2000)
    assert_same(reference(table, s), run_bin(c_exe, table, s), REF_KEYS + ("z",), "16 terms (reference)")
    assert_same(kernel(table, s, True), run_bin(c_exe, table, s, True), what="16 terms self-timed")
    params = encode_aux(aux.fracs, aux.terms + (dataclasses.replace(aux.terms[-1], weight=0),))
    body = table.to_words()[:N_FIXED]
    body[FIELD_INDEX["aux_nparams"]], body[2] = len(params), N_FIXED + len(params) + 1
    body += [x & 0xFFFFFFFF for x in params]
    words = body + [crc32_words(body)]
    assert len(words) == 266
    with pytest.raises(TableError, match="aux n_terms 17 not in 1..16"):
        Table.from_words(words, "17 terms")
    out = run_text(c_exe, [table_line(table), "TABLE " + " ".join(f"{w:08x}" for w in words)], expect_rc=1)
    assert out == [f"T 255 {table.crc:08x}", f"ERR FIELD word {N_FIXED} aux_n_terms"], out


def test_bin_block_width_errors_are_fatal(c_exe):
    table = table_of("diff", "pair")
    rec = np.zeros((2, 11), "<i8")
    for head, body in (("BIN 2 7", rec.tobytes()), ("BIN 2 11", rec.tobytes()[:100]), ("BENCH 2 1 12", b"")):
        pr = subprocess.run([str(c_exe)], input=f"{table_line(table)}\n{head}\n".encode() + body, capture_output=True)
        assert pr.returncode == 2 and b"fatal" in pr.stderr, head


# -- regress, then reverse (layout v2: order 1, two banks, combiner 3 none) ---------------------------------

def rtr_table(rng, estimator, combiner, **kw):
    """A two-bank regress_first table: bank 2 quantized from a second random model."""
    from host_tools.vectors.builders import two_bank_table
    t1 = quantize(random_model(rng, reversal=True, estimator=estimator), n_random=10, **kw).table
    t2 = quantize(random_model(rng, reversal=True, estimator=estimator), n_random=10, **kw).table
    return two_bank_table(t1, t2, combiner)


@pytest.mark.parametrize("seed,estimator,combiner,self_timed", [
    (0, "diff", 1, False), (1, "lsq", 2, False), (2, "iir", 3, False), (3, "diffn", 1, True), (4, "diff", 3, True)])
def test_regress_first_streams_equal_numba_and_reference(c_exe, seed, estimator, combiner, self_timed):
    """Two-bank tables, every residual combiner, logged and self-timed, with restarts: C == numba
    on 10^5 samples and C == the Python reference (every column) on the first 5000."""
    rng = np.random.default_rng(1500 + seed)
    table = rtr_table(rng, estimator, combiner, exchange_s=3.0, dwell_s=7.0, power_on_s=2.0)
    s = random_stream(rng, table, 100_000, reversal=True)
    got = run_bin(c_exe, table, s, self_timed)
    assert_same(kernel(table, s, self_timed), got, what=f"regress_first seed {seed}")
    short = {k: (v[:5000] if isinstance(v, np.ndarray) else v) for k, v in s.items()}
    got_s = run_bin(c_exe, table, short, self_timed)
    assert_same(reference(table, short, self_timed), got_s, REF_KEYS, f"regress_first seed {seed}, reference")
    m2 = got["mode"] == 2
    assert m2.any() and (~m2).any() and got["valid"].any()


@pytest.mark.parametrize("combiner", [1, 2, 3])
def test_regress_first_corners_and_saturation(c_exe, combiner):
    """Corner streams on a two-bank table whose bank 2 has |B| near the output range: the residual
    word saturates (flag 128); text protocol against the reference and the kernel."""
    from host_tools.vectors.builders import two_bank_table
    big = np.zeros(17)
    big[0] = 2.0 ** 21 * 0.9
    table = two_bank_table(table_of("diffn", "pair"), table_of("diffn", "pair", coef=big), combiner)
    s = corner_stream(table, reversal=True)
    got = run_samples_text(c_exe, table, s)
    assert_same(reference(table, s), got, REF_KEYS, "regress_first corners")
    assert_same(kernel(table, s), got, what="regress_first corners, kernel")
    assert (got["flags"] & F.FLAG_SAT).any()


def test_evaluator_bank_select_and_version_1_table(c_exe):
    """EVAL U V Z BANK evaluates bank 2 (== the kernel's and Python's bank 2); a version-1 table is
    read by the C parser as order 0 with one bank and runs exactly like its version-2 words."""
    from firmware_ref.table import N_FIXED, N_FIXED_V1
    from host_tools.vectors.builders import two_bank_table
    rng = np.random.default_rng(3)
    table = two_bank_table(table_of("diff", "pair"), table_of("diff", "pair", coef=rng.normal(0, 100, 17)), 1)
    u, v, z = (rng.integers(-F.ONE, F.ONE + 1, 300) for _ in range(3))
    out = run_text(c_exe, [table_line(table)] + [f"EVAL {a} {b} {c} 2" for a, b, c in zip(u, v, z)]
                   + [f"EVAL {a} {b} {c} 1" for a, b, c in zip(u, v, z)] + ["EVAL 0 0 0 3"], expect_rc=1)
    got = np.array([line.split()[1] for line in out[1:-1]], np.int64)
    np.testing.assert_array_equal(got[:300], evaluate_words(table, u, v, z, bank=2))
    np.testing.assert_array_equal(got[300:], evaluate_words(table, u, v, z, bank=1))
    assert not np.array_equal(got[:300], got[300:])
    assert int(got[0]) == evaluate(int(u[0]), int(v[0]), int(z[0]), table, bank=2)[0]
    assert out[-1].startswith("ERR RANGE")
    one = table_of("lsq", "trend")              # a temperature proxy: a version-1 frequency table is refused
    w = one.to_words()
    v1 = [w[0], 1, N_FIXED_V1 + 1] + w[3:N_FIXED_V1]
    v1 = v1 + [crc32_words(v1)]
    assert Table.from_words(v1) == one
    s = random_stream(np.random.default_rng(4), one, 3000, reversal=True)
    rec = input_records(one, s)
    lines = ["TABLE " + " ".join(f"{x:08x}" for x in v1)] + ["S " + " ".join(map(str, r)) for r in rec.tolist()]
    out = run_text(c_exe, lines)
    assert out[0] == f"T {N_FIXED_V1 + 1} {v1[-1]:08x}" and N_FIXED == 72
    assert out[1:] == run_text(c_exe, [table_line(one)] + lines[1:])[1:]


# -- the input-invalid bit (FORMATS.md "The input-invalid bit"; RESTART bit 1 of the protocol) ---------------

@pytest.mark.parametrize("seed,estimator,reversal,order,self_timed", [
    (0, "diff", True, "combine_first", False), (1, "lsq", True, "regress_first", False),
    (2, "iir", True, "combine_first", True), (3, "diffn", False, "combine_first", False),
    (4, "iir", True, "regress_first", False)])
def test_invalid_bit_equals_numba_and_reference(c_exe, seed, estimator, reversal, order, self_timed):
    """Random streams with 3 % of the samples (and bursts) input-invalid: the C twin (BIN block,
    RESTART = restart + 2 invalid) equals the numba kernel and the Python reference, every column."""
    rng = np.random.default_rng(1300 + seed)
    kw = {"order": order} if order == "regress_first" else {"reversal": reversal}
    table = quantize(random_model(rng, estimator=estimator, **kw), exchange_s=3.0, dwell_s=7.0, power_on_s=2.0,
                     n_random=10).table
    s = random_stream(rng, table, 6000, reversal=reversal)
    inv = rng.random(6000) < 0.03
    inv[1000:1012] = True
    s["restart"] = np.asarray(s["restart"], np.int64)
    rec = input_records(table, s, self_timed)
    rec[:, 4] = s["restart"] + 2 * inv
    n = len(rec)
    data = f"{table_line(table)}\nBIN {n}\n".encode() + rec.astype("<i8").tobytes()
    pr = subprocess.run([str(c_exe)], input=data, capture_output=True)
    assert pr.returncode == 0 and not pr.stderr, pr.stderr.decode(errors="replace")[-2000:]
    j = pr.stdout.index(b"\n", pr.stdout.index(b"\n") + 1)
    arr = np.frombuffer(pr.stdout[j + 1:], "<i8").reshape(n, len(FIELDS))
    got = {name: arr[:, c].astype(np.int64) for c, name in enumerate(FIELDS)}
    mode = None if self_timed else s["mode"]
    k = run_words(table, s["p"], s["r"], mode, s["restart"], s.get("z"), self_timed=self_timed, detail=True,
                  invalid=inv)
    ref = run_reference(table, s["p"], s["r"], mode, s["restart"], s.get("z"), self_timed=self_timed, invalid=inv)
    assert_same(k, got, what=f"seed {seed} numba")
    assert_same(ref, got, REF_KEYS, f"seed {seed} reference")
    assert ((got["flags"] & F.FLAG_INPUT_SAT) != 0).tolist() == inv.tolist() and not got["valid"][inv].any()
