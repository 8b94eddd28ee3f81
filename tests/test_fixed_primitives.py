"""Fixed-point primitives and input words vs independent oracles: exact Fractions and apytypes
(QuantizationMode.TIES_POS is our round-half-up, OverflowMode.SAT the saturation), with
hypothesis strategies aimed at rounding ties and saturation edges."""
import math
from fractions import Fraction

import numpy as np
import pytest
from apytypes import APyFixed, OverflowMode, QuantizationMode
from hypothesis import example, given, settings
from hypothesis import strategies as st

from firmware_ref import arith
from firmware_ref import formats as F
from firmware_ref import inputs

I64 = st.integers(-(1 << 62), (1 << 62) - 1)


def apy_rhu(x: int, s: int) -> int:
    """RHU(x, s) by apytypes: x 2^-s as a 64-bit fixed-point number cast to 0 fractional bits."""
    a = APyFixed(x & ((1 << 64) - 1), bits=64, int_bits=64 - s)
    r = a.cast(int_bits=66 - s, frac_bits=0, quantization=QuantizationMode.TIES_POS,
               overflow=OverflowMode.SAT)
    return int(r.to_fraction())


def apy_word(y: float, width: int, signed: bool) -> int:
    """Float y (already scaled by 2^frac, exactly) -> word by apytypes: the exact float as a
    fixed-point value, cast to 0 fractional bits with TIES_POS and SAT, then the symmetric limit
    of our signed words."""
    fr = Fraction(y)
    k = fr.denominator.bit_length() - 1          # the denominator of a float is a power of two
    num = fr.numerator
    bits = max(num.bit_length() + 2, 8)
    a = APyFixed(num & ((1 << bits) - 1), bits=bits, int_bits=bits - k)
    r = a.cast(int_bits=width if signed else width + 1, frac_bits=0, quantization=QuantizationMode.TIES_POS,
               overflow=OverflowMode.SAT)
    w = int(r.to_fraction())
    if signed:
        return max(w, -((1 << (width - 1)) - 1))
    return min(max(w, 0), (1 << width) - 1)


@st.composite
def shift_case(draw):
    s = draw(st.integers(0, 40))
    kind = draw(st.sampled_from(["any", "tie", "near_tie"]))
    if kind == "any" or s == 0:
        x = draw(st.integers(-(1 << 61), (1 << 61)))
    else:
        k = draw(st.integers(-(1 << (60 - s)), 1 << (60 - s)))
        x = k * (1 << s) + (1 << (s - 1)) + (draw(st.integers(-1, 1)) if kind == "near_tie" else 0)
    return x, s


@settings(max_examples=400, deadline=None)
@given(shift_case())
@example((-3, 1)).via("tie below zero goes up: -1.5 -> -1")
@example((3, 1)).via("tie above zero goes up: 1.5 -> 2")
def test_rshift_round_vs_fraction_and_apytypes(case):
    x, s = case
    got = arith.rshift_round(x, s)
    assert got == math.floor(Fraction(x, 1 << s) + Fraction(1, 2))
    assert got == apy_rhu(x, s)


def test_rshift_round_ties_go_up():
    assert [arith.rshift_round(x, 1) for x in (-3, -1, 1, 3)] == [-1, 0, 1, 2]
    assert arith.rshift_round(-(1 << 40) - (1 << 9), 10) == -(1 << 30)  # -2^30 - 0.5 -> -2^30
    with pytest.raises(AssertionError):
        arith.rshift_round((1 << 63) - 1, 2)  # the rounding add would overflow int64


@settings(max_examples=300, deadline=None)
@given(st.integers(-(1 << 31), 1 << 31), st.integers(-(1 << 30), 1 << 30))
@example(-(1 << 31), 1 << 30)
@example(1 << 31, -(1 << 30))
@example(3, 1 << 29)  # 1.5 -> 2
@example(-3, 1 << 29)  # -1.5 -> -1
def test_q30_product_vs_apytypes(a, w):
    """The Horner step RHU(a * w, 30): apytypes multiplies exactly, then casts with TIES_POS."""
    got = arith.mul_rshift_round(a, w, F.Q)
    pa = APyFixed(a & ((1 << 40) - 1), bits=40, int_bits=40)
    pw = APyFixed(w & ((1 << 40) - 1), bits=40, int_bits=10)  # w 2^-30
    ref = (pa * pw).cast(int_bits=50, frac_bits=0, quantization=QuantizationMode.TIES_POS,
                         overflow=OverflowMode.SAT)
    assert got == int(ref.to_fraction())
    assert abs(got) <= abs(a)  # the fact the interval analysis uses


@settings(max_examples=400, deadline=None)
@given(st.integers(-(1 << 62), (1 << 62)), st.integers(1, (1 << 31) - 1), st.integers(0, 16))
@example(-5, 2, 0)  # -2.5 -> -2
@example(5, 2, 0)   # 2.5 -> 3
@example(-1, 2, 1)  # -1 exactly
@example(-(1 << 62), (1 << 31) - 1, 10)
def test_div_round_scaled_exact(a, b, k):
    if abs(a) > b * (1 << 31):  # the range the combiner uses: |a / b| <= 2^31 (mean), 2^42 (slope)
        a = a % (b << 31)
    got = arith.div_round_scaled(a, b, k)
    assert got == math.floor(Fraction(a * (1 << k), b) + Fraction(1, 2))
    assert arith.div_round(a, b) == math.floor(Fraction(a, b) + Fraction(1, 2))


@given(st.integers(-(1 << 40), 1 << 40), st.integers(2, 40))
def test_saturation_edges(x, width):
    lim = (1 << (width - 1)) - 1
    w, sat = arith.sat_signed(x, width)
    assert w == min(max(x, -lim), lim) and sat == (abs(x) > lim)
    # apytypes saturates two's-complement (down to -2^(w-1)); ours is symmetric
    a = APyFixed(x & ((1 << 48) - 1), bits=48, int_bits=48)
    ref = int(a.cast(int_bits=width, frac_bits=0, overflow=OverflowMode.SAT).to_fraction())
    assert w == max(ref, -lim)
    for edge in (lim, lim + 1, -lim, -lim - 1):
        assert arith.sat_signed(edge, width) == (min(max(edge, -lim), lim), abs(edge) > lim)
    u, usat = arith.sat_unsigned(x, width)
    assert u == min(max(x, 0), (1 << width) - 1) and usat == (not 0 <= x < (1 << width))


# -- input words ----------------------------------------------------------------------------------

WORDS = [("freq", F.FREQ_FRAC, 32, False), ("temp", F.TEMP_FRAC, 32, True), ("rate", F.RATE_FRAC, 32, True),
         ("aux", F.Q, 32, True)]


@st.composite
def word_value(draw, frac, width, signed):
    """Floats at ties (k + 1/2) 2^-frac, next to them, at the saturation edges, or anywhere."""
    kind = draw(st.sampled_from(["tie", "edge", "any"]))
    top = (1 << (width - 1)) if signed else (1 << width)
    if kind == "tie":
        k = draw(st.integers(-top if signed else 0, top - 1))
        x = (k + 0.5) * 2.0 ** -frac
        nudge = draw(st.sampled_from([0, 1, -1]))
        return float(np.nextafter(x, np.inf * nudge)) if nudge else x
    if kind == "edge":
        e = draw(st.sampled_from([top - 1, top, -(top - 1), -top, 0])) if signed else draw(st.sampled_from([top - 1, top, 0, -1]))
        x = (e + draw(st.sampled_from([-0.5, 0.0, 0.5, 0.25]))) * 2.0 ** -frac
        return x
    return draw(st.floats(-2.0 ** (width - frac + 1), 2.0 ** (width - frac + 1), allow_nan=False))


@pytest.mark.parametrize("name,frac,width,signed", WORDS)
def test_word_conversion_vs_apytypes(name, frac, width, signed):
    @settings(max_examples=150, deadline=None)
    @given(word_value(frac, width, signed))
    def check(x):
        w, sat = inputs.word_of(x, frac, signed, width)
        exact = math.floor(Fraction(x) * (1 << frac) + Fraction(1, 2))
        lo, hi = (-((1 << (width - 1)) - 1), (1 << (width - 1)) - 1) if signed else (0, (1 << width) - 1)
        assert w == min(max(exact, lo), hi) and sat == (not lo <= exact <= hi)
        assert w == apy_word(x * 2.0 ** frac, width, signed)  # x 2^frac is exact
        vec, vsat = inputs.to_words(np.array([x]), frac, signed, width)
        assert int(vec[0]) == w and bool(vsat[0]) == sat
    check()


def test_vector_words_specials():
    top = F.FREQ_RANGE_HZ
    w, sat = inputs.freq_words([6227.386, -1.0, 1e30, np.inf, top, top - 0.75 * 2.0 ** -F.FREQ_FRAC])
    assert w.tolist()[1:] == [0, F.UINT32_MAX, F.UINT32_MAX, F.UINT32_MAX, F.UINT32_MAX]
    assert sat.tolist() == [False, True, True, True, True, False]
    w, sat = inputs.rate_words([-np.inf, -(2.0 ** 21), 0.49999999999999994 * 2 ** -10, -0.5 * 2 ** -10])
    assert w.tolist() == [-F.INT32_SYM, -F.INT32_SYM, 0, 0] and sat.tolist() == [True, True, False, False]
    with pytest.raises(ValueError, match="NaN"):
        inputs.rate_words([1.0, np.nan])
    assert inputs.from_words([1 << F.FREQ_FRAC], F.FREQ_FRAC)[0] == 1.0
