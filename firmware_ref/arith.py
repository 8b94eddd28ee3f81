"""Fixed-point primitives of the firmware reference, on plain Python integers (the readable spec).

Every function takes and returns Python ``int`` and checks its preconditions, so a violated
range shows up as an ``AssertionError`` in the reference instead of a silent wrap.  The numba
kernel (firmware_ref/kernel.py) and the C99 twin implement exactly the same operations on int64;
FORMATS.md gives them in pseudo-code.

Rounding is **round half up** (towards +infinity at ties), done by add-then-arithmetic-shift:
``rshift_round(x, s) = (x + 2**(s-1)) >> s`` (ARM SMMULR rounds the same way; apytypes calls it
``QuantizationMode.TIES_POS``).  Division rounds the same way: ``div_round(a, b) = floor((2a + b)
/ (2b))`` for ``b > 0``.  Saturation is symmetric for signed words (``[-(2**(w-1) - 1), 2**(w-1)
- 1]``), so negating a saturated word never overflows.
"""
from __future__ import annotations

INT64_MAX = (1 << 63) - 1
INT64_MIN = -(1 << 63)


def check_int64(x: int, what: str = "value") -> int:
    """Return x; AssertionError if it is outside int64 (the reference's overflow detector)."""
    assert INT64_MIN <= x <= INT64_MAX, f"{what} = {x} overflows int64"
    return x


def rshift_round(x: int, s: int) -> int:
    """Round-half-up arithmetic right shift: ``floor(x / 2**s + 1/2)``; ``s = 0`` returns x.
    Precondition: ``0 <= s <= 62`` and ``x + 2**(s-1)`` fits int64."""
    assert 0 <= s <= 62, f"shift {s} out of 0..62"
    if s == 0:
        return check_int64(x, "rshift_round input")
    return check_int64(x + (1 << (s - 1)), "rshift_round sum") >> s


def mul_rshift_round(a: int, b: int, s: int) -> int:
    """``rshift_round(a * b, s)``: the product (exact, must fit int64) rounded half up."""
    return rshift_round(check_int64(a * b, "product"), s)


def clamp(x: int, lo: int, hi: int) -> tuple[int, bool]:
    """``(min(max(x, lo), hi), clamped)``: clamped is True when x was outside [lo, hi]."""
    if x > hi:
        return hi, True
    if x < lo:
        return lo, True
    return x, False


def sat_signed(x: int, width: int) -> tuple[int, bool]:
    """Symmetric saturation to a signed ``width``-bit word: [-(2**(w-1) - 1), 2**(w-1) - 1]."""
    m = (1 << (width - 1)) - 1
    return clamp(x, -m, m)


def sat_unsigned(x: int, width: int) -> tuple[int, bool]:
    """Saturation to an unsigned ``width``-bit word: [0, 2**w - 1]."""
    return clamp(x, 0, (1 << width) - 1)


def floor_div(a: int, b: int) -> int:
    """``floor(a / b)`` for ``b > 0`` (C99: ``q = a / b; if (a % b != 0 && a < 0) q -= 1;``)."""
    assert b > 0, "divisor must be > 0"
    return a // b


def div_round(a: int, b: int) -> int:
    """Round-half-up quotient ``floor(a / b + 1/2) = floor((2a + b) / (2b))``, ``b > 0``."""
    assert b > 0, "divisor must be > 0"
    return floor_div(check_int64(2 * a + b, "div_round numerator"), check_int64(2 * b, "div_round divisor"))


def div_round_scaled(a: int, b: int, k: int) -> int:
    """Round-half-up ``a * 2**k / b`` for ``b > 0`` without forming ``a * 2**k``:
    ``q = floor(a / b)``, ``r = a - q b`` (0 <= r < b), result ``q * 2**k + div_round(r * 2**k, b)``.
    Exact (the identity ``floor((2a 2^k + b) / 2b) = q 2^k + floor((2 r 2^k + b) / 2b)`` holds for
    integers); needs ``|q| * 2**k`` and ``2 * b * 2**k`` to fit int64."""
    assert b > 0 and 0 <= k <= 62
    q = floor_div(a, b)
    r = a - q * b
    return check_int64(check_int64(q << k, "quotient scaled") + div_round(check_int64(r << k, "remainder scaled"), b),
                       "div_round_scaled")


def mul_rshift_round_wide(a: int, d: int, s: int) -> int:
    """``RHUW(a, d, s) = rshift_round(a * d, s)`` for a product wider than int64: ``|a| < 2^31``,
    ``|d| <= 2^62``, ``31 <= s <= 62`` (the filter / decay update of the aux generators, Q1.60 state
    times a 31-bit coefficient).  Exact; on int64 machines (numba, C) it is computed from the split
    ``d = dh 2^31 + dl`` (0 <= dl < 2^31) as ``(a dh + ((a dl + 2^(s-1)) >> 31)) >> (s - 31)``, which
    equals it by ``floor(floor(x / 2^31) / 2^(s-31)) = floor(x / 2^s)``; every intermediate there is
    below 2^63."""
    assert -(1 << 31) < a < 1 << 31 and abs(d) <= 1 << 62 and 31 <= s <= 62, (a, d, s)
    return check_int64((a * d + (1 << (s - 1))) >> s, "mul_rshift_round_wide result")
