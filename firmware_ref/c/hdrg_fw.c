/*
 * hdrg_fw.c - C99 twin of the fixed-point compensation pipeline.  See hdrg_fw.h and
 * firmware_ref/FORMATS.md ("The exact integer algorithm (per sample)"); the comments name the
 * Python reference function each part copies.
 *
 * Portability notes (C99 6.5.7, 6.3.1.3, 6.5p5):
 *
 *  - Right shift of a negative value is implementation-defined, so it is never written.
 *    ASR(x, s) = floor(x / 2^s) is written
 *        x < 0 ? ~(~x >> s) : x >> s
 *    For x >= 0 it is the shift of a non-negative value.  For x < 0, ~x = -x - 1 >= 0 (int32_t
 *    and int64_t are two's complement by definition, C99 7.18.1.1), its shift is defined, and
 *    ~(~x >> s) = -floor((-x - 1) / 2^s) - 1 = -ceil(-x / 2^s) = floor(x / 2^s).  GCC and Clang
 *    recognize the idiom and emit one arithmetic shift (ASR on Cortex-M, SAR on x86-64; a 64-bit
 *    variable shift is the usual 9-instruction sequence on Cortex-M), so portability costs nothing.
 *  - Left shift of a negative value is undefined, so x << k is written x * ((int64_t)1 << k).
 *  - Signed overflow is undefined: every product and sum below is bounded by FORMATS.md
 *    ("Every signal"); the bounds rest on table checks that hdrg_table_parse() enforces (gains,
 *    shifts, s_bits vs g_v, exponents, and the Horner interval bound |acc| <= 2^31 - 1).
 *  - Division: no C / or % on 64-bit operands (on a 32-bit core that calls a 64-bit library
 *    division): hdrg_udiv64() divides with 32-bit divisions (UDIV on Cortex-M3/M4/M7) and
 *    hdrg_floor_div() etc. are built on it (see there).
 *  - Cortex-M: the per-sample products are written as (int64_t)a * b of two 32-bit operands
 *    (one SMULL/SMLAL) wherever the bounds allow it; each such primitive states its contract.
 *
 * -DHDRG_BREAK_ROUNDING builds a deliberately wrong twin (RHU truncates instead of rounding
 * half up) so that the tests can show that the comparison catches it.
 */
#include "hdrg_fw.h"

#define I64(x) ((int64_t)(x))
/* a function kept out of line (GCC, Clang): rare or optional work (window commits, the aux
 * generators) does not enter the register allocation of the per-sample path */
#if defined(__GNUC__)
#define HDRG_COLD __attribute__((noinline))
#else
#define HDRG_COLD
#endif
/* kept out of line in a size-optimized build (GCC, Clang -Os: __OPTIMIZE_SIZE__), inlined by the
 * compiler's choice otherwise: helpers called from several sites of the optional aux generators */
#if defined(__GNUC__) && defined(__OPTIMIZE_SIZE__)
#define HDRG_OUTLINE_OS static __attribute__((noinline))
#else
#define HDRG_OUTLINE_OS static inline
#endif
#define P2(k) ((int64_t)1 << (k))
/* a condition that is rarely true on the per-sample path (restarts, window changes, invalid inputs,
 * clamps, saturations, the aux generators): GCC and Clang lay its code out of the fall-through path, so
 * that the common case runs without taken branches */
#if defined(__GNUC__)
#define RARE(c) __builtin_expect(!!(c), 0)
#else
#define RARE(c) (c)
#endif
/* x unchanged, but opaque to the compiler's value-range tracking (GCC, Clang): an int32 known to be
 * non-negative would otherwise be zero-extended, and its 64-bit product with a signed word becomes
 * three multiplies instead of one SMULL/SMLAL */
#if defined(__GNUC__)
#define HDRG_OPAQUE(x) __asm__("" : "+r"(x))
#else
#define HDRG_OPAQUE(x) ((void)0)
#endif
/* the stages of the per-sample path, inlined into both entry points (GCC, Clang; not in a
 * -fno-inline build, which the per-stage code bytes of `hdrg cost` use) */
#if defined(__GNUC__) && !defined(__NO_INLINE__)
#define HDRG_INLINE inline __attribute__((always_inline))
#else
#define HDRG_INLINE inline
#endif

/* the table fields a configuration-specialized build fixes at compile time (hdrg_fw.h): the
 * per-sample path reads them through these, so that a fixed field is a constant */
#ifdef HDRG_FIX_PROXY
#define PROXY_KIND(t) ((void)(t), (uint32_t)HDRG_FIX_PROXY)
#else
#define PROXY_KIND(t) ((t)->proxy_kind)
#endif
#ifdef HDRG_FIX_EST
#define RATE_EST(t) ((void)(t), (uint32_t)HDRG_FIX_EST)
#else
#define RATE_EST(t) ((t)->rate_est)
#endif
#ifdef HDRG_FIX_COMB
#define COMBINER(t) ((void)(t), (uint32_t)HDRG_FIX_COMB)
#else
#define COMBINER(t) ((t)->combiner)
#endif
#ifdef HDRG_FIX_ORDER
#define ORDER(t) ((void)(t), (uint32_t)HDRG_FIX_ORDER)
#else
#define ORDER(t) ((t)->order)
#endif
/* the effective window n: rate_n (diffn, lsq) or 1 (diff, iir: a constant when the estimator is fixed) */
#if defined(HDRG_FIX_EST) && (HDRG_FIX_EST == 0 || HDRG_FIX_EST == 3)
#define WIN_N(st) ((void)(st), 1u)
#else
#define WIN_N(st) ((st)->n)
#endif

/* ---------------------------------------------------------------- primitives (arith.py) -- */

/* floor(x / 2^s), 0 <= s <= 63: the arithmetic shift, written without shifting a negative value
 * (see the top of this file). */
static inline int64_t asr64(int64_t x, unsigned s)
{
    return x < 0 ? ~(~x >> s) : x >> s;
}

/* floor(x / 2^s), 0 <= s <= 31, on a 32-bit word (one ASR). */
static inline int32_t asr32(int32_t x, unsigned s)
{
    return x < 0 ? ~(~x >> s) : x >> s;
}

/* RHU(x, s) = floor(x / 2^s + 1/2), 1 <= s <= 62, x + 2^(s-1) in int64 (arith.rshift_round).
 * Written as ASR(ASR(x, s - 1) + 1, 1): with y = floor(x / 2^(s-1)), floor((y + 1) / 2) =
 * floor((x + 2^(s-1)) / 2^s) (nested floors); y + 1 <= (x + 2^(s-1)) / 2^(s-1) fits int64.  One
 * variable 64-bit shift instead of a variable 2^(s-1) and a shift. */
static inline int64_t rhu64(int64_t x, unsigned s)
{
#ifdef HDRG_BREAK_ROUNDING
    return asr64(x, s);                             /* truncation: deliberately wrong */
#else
    return asr64(asr64(x, s - 1u) + 1, 1u);
#endif
}

/* RHU(x, s) of a bounded value, |x| <= 2^62, 1 <= s <= 62: floor((x + 2^(s-1)) / 2^s), the sum fits
 * int64 (with a constant s: one 64-bit add and a constant shift).  The per-sample sites below state
 * their bounds. */
static inline int64_t rhu64b(int64_t x, unsigned s)
{
#ifdef HDRG_BREAK_ROUNDING
    return asr64(x, s);
#else
    return asr64(x + P2(s - 1u), s);
#endif
}

/* RHU(x, s) of a 32-bit word, 0 <= s <= 31 (any int32 x): with y = floor(x / 2^(s-1)),
 * floor((x + 2^(s-1)) / 2^s) = floor((y + 1) / 2) (nested floors) = y - floor(y / 2) (the ceiling
 * of y / 2): one ASR and one subtract of an ASR-shifted operand.  No intermediate leaves int32
 * (x + 2^(s-1) could). */
static inline int32_t rhu32(int32_t x, unsigned s)
{
    if (s == 0u) {
        return x;
    }
#ifdef HDRG_BREAK_ROUNDING
    return asr32(x, s);
#else
    {
        int32_t y = asr32(x, s - 1u);
        return y - asr32(y, 1u);
    }
#endif
}

/* RHU(a w, 30) for |a| <= 2^31 - 1 and |w| <= 2^30 (a Horner accumulator times a Q1.30 word):
 * one 32 x 32 -> 64 product (SMULL; with the rounding constant GCC emits SMLAL) and the
 * two-register shift by 30 (LSRS + ORR); |a w + 2^29| < 2^61 and |result| <= |a| (|a w / 2^30|
 * <= |a|, rounded to an integer), so the result fits int32.  The caller's sum with the next
 * coefficient stays within the Horner interval bound 2^31 - 1 (hdrg_table_parse). */
static inline int32_t mulq30(int32_t a, int32_t w)
{
#ifdef HDRG_BREAK_ROUNDING
    return (int32_t)asr64((int64_t)a * w, HDRG_Q);
#else
    return (int32_t)asr64((int64_t)a * w + ((int64_t)1 << (HDRG_Q - 1)), HDRG_Q);
#endif
}

int64_t hdrg_asr(int64_t x, unsigned s)
{
    return asr64(x, s);
}

int64_t hdrg_rhu(int64_t x, unsigned s)
{
    return s == 0u ? x : rhu64(x, s);
}

int64_t hdrg_mul_rhu(int64_t a, int64_t b, unsigned s)
{
    return hdrg_rhu(a * b, s);
}

/* the number of leading zero bits of x != 0 (CLZ on Cortex-M3/M4/M7 with GCC or Clang) */
static inline unsigned nlz32(uint32_t x)
{
#if defined(__GNUC__)
    return (unsigned)__builtin_clz(x);
#else
    unsigned n = 0;
    while (!(x & 0x80000000u)) {
        x <<= 1;
        n++;
    }
    return n;
#endif
}

/* 32 / 16-bit digit division (Hacker's Delight, 2nd ed., fig. 9-3 "divlu"): the 64-bit value
 * u1 2^32 + u0 divided by v, u1 < v (so the quotient fits 32 bits); *r gets the remainder.  Only
 * 32-bit divisions (UDIV) and products: the divisor is normalized (top bit set) and the quotient
 * is formed from two 16-bit digits, each estimated from the top words and corrected at most twice. */
static uint32_t divlu(uint32_t u1, uint32_t u0, uint32_t v, uint32_t *r)
{
    const uint32_t b = 65536u;
    uint32_t un1, un0, vn1, vn0, q1, q0, un32, un21, un10, rhat;
    unsigned s = nlz32(v);                          /* normalize: the top bit of v set */
    v <<= s;
    vn1 = v >> 16;
    vn0 = v & 0xFFFFu;
    un32 = s == 0u ? u1 : (u1 << s) | (u0 >> (32u - s));
    un10 = u0 << s;
    un1 = un10 >> 16;
    un0 = un10 & 0xFFFFu;
    q1 = un32 / vn1;
    rhat = un32 - q1 * vn1;
    while (q1 >= b || q1 * vn0 > b * rhat + un1) {
        q1--;
        rhat += vn1;
        if (rhat >= b) {
            break;
        }
    }
    un21 = un32 * b + un1 - q1 * v;                 /* modulo 2^32: the true value is < v */
    q0 = un21 / vn1;
    rhat = un21 - q0 * vn1;
    while (q0 >= b || q0 * vn0 > b * rhat + un0) {
        q0--;
        rhat += vn1;
        if (rhat >= b) {
            break;
        }
    }
    *r = (un21 * b + un0 - q0 * v) >> s;
    return q1 * b + q0;
}

uint64_t hdrg_udiv64(uint64_t n, uint64_t d, uint64_t *rem)
{
    uint32_t dh = (uint32_t)(d >> 32), dl = (uint32_t)d, r, qh, ql;
    uint64_t q;
    if (dh == 0u) {                                 /* d < 2^32: two 64 / 32 digit steps */
        uint32_t nh = (uint32_t)(n >> 32);
        qh = nh / dl;
        ql = divlu(nh - qh * dl, (uint32_t)n, dl, &r);
        *rem = r;
        return ((uint64_t)qh << 32) | ql;
    }
    /* d >= 2^32, so q < 2^32: Hacker's Delight fig. 9-5 (divDu): normalize d to its top 32 bits,
     * divide n / 2 by them (the estimate is q or q + 1 after the shift), then correct once. */
    {
        unsigned s = nlz32(dh);                     /* 0..31 */
        uint64_t dn = d << s;
        /* n / 2 < 2^63 and dn / 2^32 >= 2^31: the quotient of divlu fits 32 bits */
        ql = divlu((uint32_t)(n >> 33), (uint32_t)(n >> 1), (uint32_t)(dn >> 32), &r);
        q = ((uint64_t)ql << s) >> 31;
        if (q != 0u) {
            q--;
        }
        if (n - q * d >= d) {
            q++;
        }
        *rem = n - q * d;
        return q;
    }
}

/* floor(a / b), b > 0: for a < 0, floor(a / b) = -floor((-a - 1) / b) - 1 (-a - 1 = ~a >= 0,
 * defined for every int64 a), remainder b - 1 - r'. */
static inline int64_t floor_divmod(int64_t a, int64_t b, int64_t *rem)
{
    uint64_t r;
    if (a >= 0) {
        int64_t q = (int64_t)hdrg_udiv64((uint64_t)a, (uint64_t)b, &r);
        *rem = (int64_t)r;
        return q;
    }
    {
        int64_t q = (int64_t)hdrg_udiv64((uint64_t)~a, (uint64_t)b, &r);
        *rem = b - 1 - (int64_t)r;
        return -q - 1;
    }
}

int64_t hdrg_floor_div(int64_t a, int64_t b)
{
    int64_t r;
    return floor_divmod(a, b, &r);
}

/* floor((2a + b) / 2b), b > 0, 2a + b and 2b in int64 (arith.div_round): a + (a + b) = 2a + b
 * without an intermediate 2a (which can leave int64 when 2a + b does not, for a < 0) */
static inline int64_t div_round(int64_t a, int64_t b)
{
    int64_t r;
    return floor_divmod(a + (a + b), 2 * b, &r);
}

int64_t hdrg_div_round(int64_t a, int64_t b)
{
    return div_round(a, b);
}

int64_t hdrg_div_round_scaled(int64_t a, int64_t b, unsigned k)
{
    int64_t r, q = floor_divmod(a, b, &r);          /* 0 <= r < b */
    return q * P2(k) + div_round(r * P2(k), b);
}

int64_t hdrg_clamp(int64_t x, int64_t lo, int64_t hi, int *clamped)
{
    int c = 0;
    if (x > hi) {
        x = hi;
        c = 1;
    } else if (x < lo) {
        x = lo;
        c = 1;
    }
    if (clamped != NULL) {
        *clamped = c;
    }
    return x;
}

int64_t hdrg_sat_signed(int64_t x, unsigned width, int *clamped)
{
    int64_t m = P2(width - 1u) - 1;
    return hdrg_clamp(x, -m, m, clamped);
}

int64_t hdrg_rhuw(int64_t a, int64_t d, unsigned s)
{
    /* d = dh 2^31 + dl with 0 <= dl < 2^31: |a dh| <= 2^62, 0 <= a dl + 2^(s-1) < 2^63 for a >= 0
     * (|a dl| < 2^62 in general), and floor(floor(x / 2^31) / 2^(s-31)) = floor(x / 2^s) */
    int64_t dh = hdrg_asr(d, 31u);
    int64_t dl = d - dh * P2(31);
#ifdef HDRG_BREAK_ROUNDING
    return hdrg_asr(a * dh + hdrg_asr(a * dl, 31u), s - 31u);
#else
    return hdrg_asr(a * dh + hdrg_asr(a * dl + P2(s - 1u), 31u), s - 31u);
#endif
}

/* hdrg_rhu for the aux generators and their sine: at -Os their several rounding shifts share one
 * copy of the 64-bit shift (less per-sample code; the generators are optional work) */
HDRG_OUTLINE_OS int64_t rhu_out(int64_t x, unsigned s)
{
    return hdrg_rhu(x, s);
}

/* sin(pi/2 x) = x (S0 + S1 x^2 + ... + S5 x^10), Q.30 (formats.SIN_POLY) */
static const int64_t SIN_POLY[6] = {1686629713, -693598663, 85569264, -5026852, 172032, -3670};

int32_t hdrg_sin_q30(uint64_t phase)
{
    unsigned quad = (unsigned)(phase >> 62);
    int64_t r = (int64_t)((phase >> 32) & 0x3FFFFFFFu) + (int64_t)((phase >> 31) & 1u);
    int64_t x = (quad & 1u) ? HDRG_ONE - r : r;      /* 0 .. 2^30 */
    int64_t x2 = rhu_out(x * x, HDRG_Q);
    int64_t p = SIN_POLY[5];
    int i;
    for (i = 4; i >= 0; i--) {
        p = rhu_out(p * x2, HDRG_Q) + SIN_POLY[i];  /* |p| < 2^31 */
    }
    p = rhu_out(p * x, HDRG_Q);
    if (p > HDRG_ONE) {
        p = HDRG_ONE;
    }
    return (int32_t)(quad >= 2u ? -p : p);
}

uint32_t hdrg_crc32_words(const uint32_t *words, size_t n)
{
    uint32_t crc = 0xFFFFFFFFu;
    size_t i;
    unsigned byte, bit;
    for (i = 0; i < n; i++) {
        for (byte = 0; byte < 4u; byte++) {
            crc ^= (words[i] >> (8u * byte)) & 0xFFu;
            for (bit = 0; bit < 8u; bit++) {
                crc = (crc & 1u) ? (crc >> 1) ^ 0xEDB88320u : crc >> 1;
            }
        }
    }
    return crc ^ 0xFFFFFFFFu;
}

/* ---------------------------------------------------------------- table (table.py) ------- */

static const char *const WORD_NAMES[HDRG_N_FIXED + 1u] = {
    "magic", "version", "length", "proxy_kind", "p_ref", "g_u", "u_off", "sh_u", "rate_est",
    "rate_n", "rate_shift", "rate_warmup", "s_bits", "g_v", "sh_v", "fs_q16", "combiner",
    "settle_n", "max_stale_n", "power_on_n", "exchange_n", "dwell_n", "e_0", "e_1", "e_2", "e_3",
    "e_7", "e_acc", "m_0", "m_1", "m_2", "m_3", "m_4", "m_5", "m_6", "m_7", "m_8", "m_9", "m_10",
    "m_11", "m_12", "m_13", "m_14", "m_15", "m_16", "aux_gen", "aux_nparams", "order", "n_banks",
    "e2_0", "e2_1", "e2_2", "e2_3", "e2_7", "e2_acc", "m2_0", "m2_1", "m2_2", "m2_3", "m2_4", "m2_5",
    "m2_6", "m2_7", "m2_8", "m2_9", "m2_10", "m2_11", "m2_12", "m2_13", "m2_14", "m2_15", "m2_16", "crc32"
};

const char *hdrg_word_name(unsigned index)
{
    if (index < HDRG_N_FIXED) {
        return WORD_NAMES[index];
    }
    return index == HDRG_N_FIXED ? "crc32/aux_param" : index < HDRG_TABLE_WORDS_MAX ? "aux_param" : "?";
}

const char *hdrg_error_name(int err)
{
    switch (err) {
    case HDRG_OK: return "OK";
    case HDRG_ERR_LENGTH: return "LENGTH";
    case HDRG_ERR_MAGIC: return "MAGIC";
    case HDRG_ERR_VERSION: return "VERSION";
    case HDRG_ERR_CRC: return "CRC";
    case HDRG_ERR_FIELD: return "FIELD";
    case HDRG_ERR_HORNER: return "HORNER";
    case HDRG_ERR_INPUT: return "INPUT";
    default: return "UNKNOWN";
    }
}

/* two's complement uint32 -> int32 value, without the implementation-defined cast */
static int64_t s32(uint32_t w)
{
    return w >= 0x80000000u ? I64(w) - P2(32) : I64(w);
}

/* POLY_INDEX (firmware_ref/terms.py): c[i][j] = m[POLY[i][j]], the term u^i v^j */
static const uint8_t POLY[4][4] = {{0, 4, 5, 6}, {1, 8, 9, 10}, {2, 11, 12, 13}, {3, 14, 15, 16}};
#define K_AUX 7

static int64_t abs64(int64_t x)
{
    return x < 0 ? -x : x;
}

#define NEED(cond, word) do { if (!(cond)) { *bad = (word); return HDRG_ERR_FIELD; } } while (0)

static int check_fields(const hdrg_table_t *t, unsigned *bad)
{
    unsigned g;
    /* Table.validate, in its order */
    NEED(t->proxy_kind <= 1u, HDRG_W_PROXY_KIND);
    if (t->proxy_kind == 1u) {
        NEED(abs64(t->p_ref) <= HDRG_INT32_SYM, HDRG_W_P_REF);
    }
    NEED(t->g_u > 0, HDRG_W_G_U);
    NEED(t->g_v > 0, HDRG_W_G_V);
    NEED(abs64(t->u_off) <= t->g_u / 2 + 1, HDRG_W_U_OFF);
    NEED(t->sh_u <= 62u, HDRG_W_SH_U);
    NEED(t->sh_v <= 62u, HDRG_W_SH_V);
    NEED(t->rate_est <= 3u, HDRG_W_RATE_EST);
    NEED(t->rate_n >= 1u && t->rate_n <= HDRG_N_HIST_MAX, HDRG_W_RATE_N);
    NEED(t->rate_est != 2u || t->rate_n >= 2u, HDRG_W_RATE_N);
    NEED(t->rate_shift <= 24u, HDRG_W_RATE_SHIFT);
    NEED(t->rate_warmup >= 1u && t->rate_warmup <= HDRG_TIMER_MAX, HDRG_W_RATE_WARMUP);
    NEED(t->s_bits >= 1u && t->s_bits <= (unsigned)HDRG_S_BITS_MAX, HDRG_W_S_BITS);
    NEED(t->g_v < P2(62u - t->s_bits), HDRG_W_G_V);
    NEED(t->fs_q16 > 0u, HDRG_W_FS_Q16);
    NEED(t->combiner <= 3u, HDRG_W_COMBINER);
    NEED(t->order <= 1u, HDRG_W_ORDER);
    NEED(t->n_banks == 1u + t->order, HDRG_W_N_BANKS);
    NEED(t->combiner != 3u || t->order == 1u, HDRG_W_COMBINER);
    NEED(t->combiner != 0u || t->order == 0u, HDRG_W_COMBINER);
    NEED(t->settle_n <= HDRG_TIMER_MAX, HDRG_W_SETTLE_N);
    NEED(t->max_stale_n <= HDRG_TIMER_MAX, HDRG_W_MAX_STALE_N);
    NEED(t->power_on_n <= HDRG_TIMER_MAX, HDRG_W_POWER_ON_N);
    NEED(t->exchange_n <= HDRG_TIMER_MAX, HDRG_W_EXCHANGE_N);
    NEED(t->max_stale_n < HDRG_COUNT_MAX, HDRG_W_MAX_STALE_N);
    NEED(t->dwell_n >= 1u && t->dwell_n <= HDRG_TIMER_MAX, HDRG_W_DWELL_N);
    for (g = 0; g < 5u; g++) {
        uint32_t e = g < 4u ? t->e_row[g] : t->e_7;
        unsigned w = g < 4u ? HDRG_W_E_0 + g : HDRG_W_E_7;
        NEED(e <= (unsigned)HDRG_EXP_MAX, w);
        NEED(e >= t->e_acc && e - t->e_acc <= (unsigned)HDRG_ALIGN_MAX, w);
    }
    NEED(t->e_acc <= (unsigned)HDRG_EXP_MAX, HDRG_W_E_ACC);
    for (g = 0; g < HDRG_N_TERMS; g++) {
        NEED(t->mant[g] != INT32_MIN, HDRG_W_M_0 + g);
    }
    if (t->n_banks == 1u) {                         /* bank 2 words all 0 */
        for (g = 0; g < 4u; g++) {
            NEED(t->e_row2[g] == 0u, HDRG_W_E2_0 + g);
        }
        NEED(t->e_7_2 == 0u, HDRG_W_E2_7);
        NEED(t->e_acc2 == 0u, HDRG_W_E2_ACC);
        for (g = 0; g < HDRG_N_TERMS; g++) {
            NEED(t->mant2[g] == 0, HDRG_W_M2_0 + g);
        }
    } else {
        for (g = 0; g < 5u; g++) {
            uint32_t e = g < 4u ? t->e_row2[g] : t->e_7_2;
            unsigned w = g < 4u ? HDRG_W_E2_0 + g : HDRG_W_E2_7;
            NEED(e <= (unsigned)HDRG_EXP_MAX, w);
            NEED(e >= t->e_acc2 && e - t->e_acc2 <= (unsigned)HDRG_ALIGN_MAX, w);
        }
        NEED(t->e_acc2 <= (unsigned)HDRG_EXP_MAX, HDRG_W_E2_ACC);
        for (g = 0; g < HDRG_N_TERMS; g++) {
            NEED(t->mant2[g] != INT32_MIN, HDRG_W_M2_0 + g);
        }
    }
    NEED(t->aux_gen <= (HDRG_AUX_GEN ? 1u : 0u), HDRG_W_AUX_GEN);    /* -DHDRG_AUX_GEN=0: aux_gen 0 only */
    NEED(t->aux_gen == 1u || t->aux_nparams == 0u, HDRG_W_AUX_NPARAMS);
    /* a configuration-specialized build refuses the tables of another configuration */
#ifdef HDRG_FIX_PROXY
    NEED(t->proxy_kind == (uint32_t)HDRG_FIX_PROXY, HDRG_W_PROXY_KIND);
#endif
#ifdef HDRG_FIX_EST
    NEED(t->rate_est == (uint32_t)HDRG_FIX_EST, HDRG_W_RATE_EST);
#endif
#ifdef HDRG_FIX_COMB
    NEED(t->combiner == (uint32_t)HDRG_FIX_COMB, HDRG_W_COMBINER);
#endif
#ifdef HDRG_FIX_ORDER
    NEED(t->order == (uint32_t)HDRG_FIX_ORDER, HDRG_W_ORDER);
#endif
    return HDRG_OK;
}

/* table.decode_aux + table.check_aux: the aux_gen 1 parameters p[0 .. aux_nparams-1] (words 47..)
 * decoded into t->aux_*; a field outside its range gives HDRG_ERR_FIELD with its word index. */
static int parse_aux(hdrg_table_t *t, const uint32_t *p, unsigned *bad)
{
    const unsigned base = t->n_fixed;
    uint32_t nt, nc, c, j, i;
    int64_t wsum = 0;
    if (t->aux_gen == 0u) {
        return HDRG_OK;
    }
    NEED(t->aux_nparams >= 2u, HDRG_W_AUX_NPARAMS);
    nt = p[0];
    nc = p[1];
    NEED(nt >= 1u && nt <= HDRG_AUX_MAX_TERMS, base);
    NEED(nc <= HDRG_AUX_MAX_CH, base + 1u);
    NEED(t->aux_nparams == 2u + nc + nt * HDRG_AUX_TERM_WORDS, HDRG_W_AUX_NPARAMS);
    t->aux_nterms = nt;
    t->aux_nch = nc;
    for (c = 0; c < nc; c++) {
        NEED(p[2u + c] <= HDRG_AUX_FRAC_MAX, base + 2u + c);
        t->aux_frac[c] = p[2u + c];
    }
    for (j = 0; j < nt; j++) {
        unsigned off = 2u + nc + j * HDRG_AUX_TERM_WORDS, w0 = base + off, used;
        const uint32_t *wd = p + off;
        hdrg_aux_term_t *a = &t->aux_term[j];
        a->kind = wd[0];
        a->sign = wd[1];
        a->src = wd[2];
        a->power = wd[3];
        a->w = s32(wd[4]);
        for (i = 0; i < 6u; i++) {
            a->c[i] = s32(wd[5u + i]);
        }
        NEED(a->kind <= HDRG_AUX_OSC, w0);
        NEED(a->sign <= 1u, w0 + 1u);
        NEED(abs64(a->w) <= HDRG_ONE, w0 + 4u);
        wsum += abs64(a->w);
        if (a->kind == HDRG_AUX_INPUT) {
            NEED(a->src < 2u + nc, w0 + 2u);
            NEED(a->power >= 1u && a->power <= HDRG_AUX_POWER_MAX, w0 + 3u);
            if (a->src == 0u) {
                a->c[0] = I64(wd[5]);                   /* an F word: uint32 */
            } else {
                NEED(abs64(a->c[0]) <= HDRG_INT32_SYM, w0 + 5u);
            }
            NEED(a->c[1] > 0, w0 + 6u);
            NEED(abs64(a->c[2]) <= a->c[1] / 2 + 1, w0 + 7u);
            NEED(a->c[3] >= 0 && a->c[3] <= 62, w0 + 8u);
            if (a->c[5] == 0) {
                NEED(a->c[4] == 0, w0 + 9u);
            } else {
                NEED(a->c[5] >= (int64_t)HDRG_AUX_SB_MIN && a->c[5] <= (int64_t)HDRG_AUX_SB_MAX, w0 + 10u);
                NEED(a->c[4] > 0, w0 + 9u);
            }
            used = 6u;
        } else {
            NEED(a->power == 1u, w0 + 3u);
            NEED(a->src == (a->kind == HDRG_AUX_RATE ? t->proxy_kind : 0u), w0 + 2u);
            used = 0u;
        }
        if (a->kind == HDRG_AUX_RATE) {
            NEED(a->c[0] >= 1 && a->c[0] <= HDRG_S_BITS_MAX, w0 + 5u);
            NEED(a->c[1] > 0 && a->c[1] < P2(62u - (unsigned)a->c[0]), w0 + 6u);
            NEED(a->c[2] >= 0 && a->c[2] <= 62, w0 + 7u);
            used = 3u;
        } else if (a->kind == HDRG_AUX_DECAY_ON || a->kind == HDRG_AUX_DECAY_EXCHANGE) {
            NEED(a->c[0] > 0, w0 + 5u);
            NEED(a->c[1] >= (int64_t)HDRG_AUX_SB_MIN && a->c[1] <= (int64_t)HDRG_AUX_SB_MAX, w0 + 6u);
            used = 2u;
        } else if (a->kind == HDRG_AUX_RAMP) {
            NEED(a->c[0] > 0, w0 + 5u);
            NEED(a->c[1] > 0, w0 + 6u);
            NEED(a->c[2] >= 0 && a->c[2] <= 62, w0 + 7u);
            /* g <= 2^30 at k = N - 1 ((N - 1) G < 2^62), else w g could overflow int64 */
            NEED(hdrg_rhu((a->c[0] - 1) * a->c[1], (unsigned)a->c[2]) <= HDRG_ONE, w0 + 6u);
            used = 3u;
        } else if (a->kind == HDRG_AUX_OSC) {
            NEED(a->c[1] >= 0, w0 + 6u);                /* W < 2^63 */
            a->c[0] = I64(wd[5]) + a->c[1] * P2(32);
            a->c[1] = 0;
            NEED(a->c[0] >= 1, w0 + 5u);
            NEED(a->c[2] == 0 || a->c[2] == 1, w0 + 7u);
            used = 3u;
        }
        for (i = used; i < 6u; i++) {
            NEED(a->c[i] == 0, w0 + 5u + i);
        }
    }
    NEED(wsum <= HDRG_ONE + I64(nt), base + 2u + nc + (nt - 1u) * HDRG_AUX_TERM_WORDS + 4u);
    return HDRG_OK;
}

/* The quantizer's interval bound (host_tools/quantize._coef_part): every row's |mantissa| sum
 * <= 2^31 - 1 and the aligned row bounds plus the k7 bound sum to <= 2^31 - 1.  With |u|, |v|,
 * |z| <= 2^30 (|RHU(x w, 30)| <= |x|) every Horner accumulator then stays within 2^31 - 1 and
 * every product below 2^61: this is what makes the evaluator free of overflow. */
static int check_horner_bank(const uint32_t *e_row, uint32_t e_7, uint32_t e_acc, const int32_t *mant,
                             unsigned w_e0, unsigned w_eacc, unsigned *bad)
{
    int64_t total = 0;
    unsigned i, j;
    for (i = 0; i < 4u; i++) {
        int64_t a = 0;
        for (j = 0; j < 4u; j++) {
            a += abs64(mant[POLY[i][j]]);
        }
        if (a > HDRG_ACC_LIMIT) {
            *bad = w_e0 + i;
            return HDRG_ERR_HORNER;
        }
        total += hdrg_rhu(a, e_row[i] - e_acc);
    }
    total += hdrg_rhu(abs64(mant[K_AUX]) * HDRG_ONE, HDRG_Q + e_7 - e_acc);
    if (total > HDRG_ACC_LIMIT) {
        *bad = w_eacc;
        return HDRG_ERR_HORNER;
    }
    return HDRG_OK;
}

/* both banks (each with its own exponents) */
static int check_horner(const hdrg_table_t *t, unsigned *bad)
{
    int err = check_horner_bank(t->e_row, t->e_7, t->e_acc, t->mant, HDRG_W_E_0, HDRG_W_E_ACC, bad);
    if (err == HDRG_OK && t->n_banks == 2u) {
        err = check_horner_bank(t->e_row2, t->e_7_2, t->e_acc2, t->mant2, HDRG_W_E2_0, HDRG_W_E2_ACC, bad);
    }
    return err;
}

/* the rounding constant of the folded Horner addends (0 in the deliberately broken build) */
#ifdef HDRG_BREAK_ROUNDING
#define HALF(s) 0
#else
#define HALF(s) P2((s) - 1u)
#endif
#define HALF_Q HALF(HDRG_Q)

/* hdrg_bank_t of one bank of checked fields (see hdrg_fw.h) */
static void derive_bank(hdrg_bank_t *k, const int32_t *m, const uint32_t *e_row, uint32_t e_7, uint32_t e_acc)
{
    unsigned i, j;
    for (i = 0; i < 4u; i++) {
        for (j = 0; j < 3u; j++) {
            k->row[i].add[j] = I64(m[POLY[i][2u - j]]) * P2(HDRG_Q) + HALF_Q;
        }
        k->row[i].top = m[POLY[i][3]];
        k->row[i].align = e_row[i] - e_acc;
    }
    k->m7 = m[K_AUX];
    k->k7_shift = (unsigned)HDRG_Q + e_7 - e_acc;
    k->k7_half = P2(k->k7_shift - 1u);
    k->e_acc = e_acc;
    k->y_sh = (int32_t)e_acc - HDRG_Y_FRAC;
}

int hdrg_table_parse(hdrg_table_t *t, const uint32_t *words, size_t n_words, unsigned *bad_word)
{
    unsigned dummy = 0, i;
    unsigned *bad = bad_word != NULL ? bad_word : &dummy;
    unsigned n_fixed;
    int err;
    *bad = 0;
    if (n_words < HDRG_N_FIXED_V1 + 1u) {
        *bad = HDRG_W_LENGTH;
        return HDRG_ERR_LENGTH;
    }
    if (words[HDRG_W_MAGIC] != HDRG_MAGIC) {
        *bad = HDRG_W_MAGIC;
        return HDRG_ERR_MAGIC;
    }
    if (words[HDRG_W_VERSION] < 1u || words[HDRG_W_VERSION] > HDRG_LAYOUT_VERSION) {
        *bad = HDRG_W_VERSION;
        return HDRG_ERR_VERSION;
    }
    n_fixed = words[HDRG_W_VERSION] == 1u ? HDRG_N_FIXED_V1 : HDRG_N_FIXED;
    if (n_words < n_fixed + 1u) {
        *bad = HDRG_W_LENGTH;
        return HDRG_ERR_LENGTH;
    }
    if (words[HDRG_W_LENGTH] != n_words) {
        *bad = HDRG_W_LENGTH;
        return HDRG_ERR_LENGTH;
    }
    if (hdrg_crc32_words(words, n_words - 1u) != words[n_words - 1u]) {
        *bad = (unsigned)(n_words - 1u);
        return HDRG_ERR_CRC;
    }
    t->proxy_kind = words[HDRG_W_PROXY_KIND];
    t->p_ref = t->proxy_kind == 0u ? I64(words[HDRG_W_P_REF]) : s32(words[HDRG_W_P_REF]);
    t->g_u = (int32_t)s32(words[HDRG_W_G_U]);
    t->u_off = (int32_t)s32(words[HDRG_W_U_OFF]);
    t->sh_u = words[HDRG_W_SH_U];
    t->rate_est = words[HDRG_W_RATE_EST];
    t->rate_n = words[HDRG_W_RATE_N];
    t->rate_shift = words[HDRG_W_RATE_SHIFT];
    t->rate_warmup = words[HDRG_W_RATE_WARMUP];
    if (words[HDRG_W_VERSION] < HDRG_IIR_GEAR_VERSION && t->rate_est == 3u) {
        *bad = HDRG_W_VERSION;                      /* an iir table of the blanked start-up */
        return HDRG_ERR_VERSION;
    }
    t->s_bits = words[HDRG_W_S_BITS];
    t->g_v = (int32_t)s32(words[HDRG_W_G_V]);
    t->sh_v = words[HDRG_W_SH_V];
    t->fs_q16 = words[HDRG_W_FS_Q16];
    t->combiner = words[HDRG_W_COMBINER];
    t->settle_n = words[HDRG_W_SETTLE_N];
    t->max_stale_n = words[HDRG_W_MAX_STALE_N];
    t->power_on_n = words[HDRG_W_POWER_ON_N];
    t->exchange_n = words[HDRG_W_EXCHANGE_N];
    t->dwell_n = words[HDRG_W_DWELL_N];
    for (i = 0; i < 4u; i++) {
        t->e_row[i] = words[HDRG_W_E_0 + i];
    }
    t->e_7 = words[HDRG_W_E_7];
    t->e_acc = words[HDRG_W_E_ACC];
    for (i = 0; i < HDRG_N_TERMS; i++) {
        uint32_t w = words[HDRG_W_M_0 + i];
        t->mant[i] = (int32_t)s32(w);              /* INT32_MIN is refused by check_fields */
    }
    t->aux_gen = words[HDRG_W_AUX_GEN];
    t->aux_nparams = words[HDRG_W_AUX_NPARAMS];
    t->n_fixed = n_fixed;
    if (n_fixed == HDRG_N_FIXED) {
        t->order = words[HDRG_W_ORDER];
        t->n_banks = words[HDRG_W_N_BANKS];
        for (i = 0; i < 4u; i++) {
            t->e_row2[i] = words[HDRG_W_E2_0 + i];
        }
        t->e_7_2 = words[HDRG_W_E2_7];
        t->e_acc2 = words[HDRG_W_E2_ACC];
        for (i = 0; i < HDRG_N_TERMS; i++) {
            t->mant2[i] = (int32_t)s32(words[HDRG_W_M2_0 + i]);  /* INT32_MIN is refused by check_fields */
        }
    } else {                                        /* version 1: combine_first, one bank */
        t->order = 0;
        t->n_banks = 1;
        for (i = 0; i < 4u; i++) {
            t->e_row2[i] = 0;
        }
        t->e_7_2 = 0;
        t->e_acc2 = 0;
        for (i = 0; i < HDRG_N_TERMS; i++) {
            t->mant2[i] = 0;
        }
    }
    if (I64(n_fixed) + I64(t->aux_nparams) + 1 != I64(n_words)) {
        *bad = HDRG_W_AUX_NPARAMS;
        return HDRG_ERR_LENGTH;
    }
    if (words[HDRG_W_VERSION] < HDRG_FREQ_WORD_VERSION && t->proxy_kind == 0u) {
        *bad = HDRG_W_VERSION;                      /* P_REF in the old 2^-18 Hz F word */
        return HDRG_ERR_VERSION;
    }
    t->n_words = (uint32_t)n_words;
    t->crc = words[n_words - 1u];
    err = check_fields(t, bad);
    if (err == HDRG_OK) {
        err = parse_aux(t, words + n_fixed, bad);
    }
    if (err == HDRG_OK && words[HDRG_W_VERSION] < HDRG_FREQ_WORD_VERSION) {
        for (i = 0; i < t->aux_nterms; i++) {       /* an aux input term's REF in the old F word */
            if (t->aux_term[i].kind == HDRG_AUX_INPUT && t->aux_term[i].src == 0u) {
                *bad = HDRG_W_VERSION;
                err = HDRG_ERR_VERSION;
            }
        }
    }
    if (err == HDRG_OK) {
        err = check_horner(t, bad);
    }
    if (err != HDRG_OK) {
        return err;
    }
    t->s_lim = P2(t->s_bits) - 1;
    t->k_sat = t->rate_est == 3u && (1u << t->rate_shift) > t->rate_warmup ? 1u << t->rate_shift : t->rate_warmup;
    t->p_ref_ob = t->proxy_kind == 0u ? words[HDRG_W_P_REF] : words[HDRG_W_P_REF] ^ 0x80000000u;
    t->u_add = I64(t->u_off) + (t->sh_u == 0u ? 0 : HALF(t->sh_u));
    t->v_half = t->sh_v == 0u ? 0 : HALF(t->sh_v);
    derive_bank(&t->bank[0], t->mant, t->e_row, t->e_7, t->e_acc);
    if (t->n_banks == 2u) {
        derive_bank(&t->bank[1], t->mant2, t->e_row2, t->e_7_2, t->e_acc2);
    } else {
        t->bank[1] = t->bank[0];
    }
    return HDRG_OK;
}

/* ---------------------------------------------------------------- pipeline --------------- */

static const uint8_t STATE_MODE[6] = {3, 3, 1, 3, 2, 0};
static const uint8_t STATE_VS[6] = {
    HDRG_VS_DRV_X, HDRG_VS_DRV_X, HDRG_VS_DRV_X | HDRG_VS_SNS_Y, HDRG_VS_DRV_Y,
    HDRG_VS_DRV_Y | HDRG_VS_SNS_X | HDRG_VS_NEG, HDRG_VS_DRV_X | HDRG_VS_SNS_Y
};
static const int8_t STATE_SIGN[6] = {0, 0, 1, 0, -1, 1};

int hdrg_init(hdrg_state_t *st, const uint32_t *words, size_t n_words, unsigned *bad_word)
{
    int err = hdrg_table_parse(&st->t, words, n_words, bad_word);
    if (err == HDRG_OK) {
        hdrg_reset(st);
    }
    return err;
}

static void rate_reset(hdrg_state_t *st)
{
    st->head = 0;
    st->k = 0;
    st->iy = 0;
}

static void comb_restart(hdrg_state_t *st)
{
    st->cur = 0;
    st->acc = 0;
    st->cnt = 0;
    st->pos = 0;
    st->ncommit[1] = 0;
    st->ncommit[2] = 0;
    st->slope[1] = 0;
    st->slope[2] = 0;
    st->taint = 0;
}

void hdrg_reset(hdrg_state_t *st)
{
    unsigned o;
    st->n = (st->t.rate_est == 1u || st->t.rate_est == 2u) ? st->t.rate_n : 1u;
    st->t_state = HDRG_ST_POWER_ON;
    st->t_cnt = 0;
    for (o = 0; o <= HDRG_N_HIST_MAX; o++) {
        st->hist[o] = 0;
    }
    rate_reset(st);
    st->prev_invalid = 0;
    comb_restart(st);
    st->last_window = 0;
    for (o = 0; o < 3u; o++) {
        st->ncommit[o] = 0;
        st->w[o] = 0;
        st->slope[o] = 0;
        st->span[o] = 0;
        st->age[o] = 0;
    }
    st->y_hold = 0;
    st->out_hold = 0;
    st->bias_hold = 0;
    for (o = 0; o < HDRG_AUX_MAX_TERMS; o++) {
        st->aux_y[o] = 0;
        st->aux_ex[o] = 0;
    }
    st->aux_pend = 0;
    st->kc = 0;
    st->fresh = 1;
}

/* the value of a stored proxy word */
static int64_t pword(const hdrg_state_t *st, uint32_t w)
{
    return PROXY_KIND(&st->t) == 0u ? I64(w) : s32(w);
}

/* the proxy word m samples back (0 <= m <= n) */
static int64_t hist_back(const hdrg_state_t *st, uint32_t m)
{
    uint32_t i = st->head >= m ? st->head - m : st->head + WIN_N(st) + 1u - m;
    return pword(st, st->hist[i]);
}

/* sequencer.state_length, next_state */
static int64_t state_length(const hdrg_table_t *t, unsigned s)
{
    switch (s) {
    case HDRG_ST_POWER_ON: return I64(t->power_on_n);
    case HDRG_ST_EXCH_TO_1: case HDRG_ST_EXCH_TO_2: return I64(t->exchange_n);
    case HDRG_ST_MODE_1: case HDRG_ST_MODE_2: return I64(t->dwell_n);
    default: return -1;
    }
}

static uint8_t next_state(const hdrg_table_t *t, unsigned s)
{
    if (s == HDRG_ST_POWER_ON) {
        return COMBINER(t) == 0u ? HDRG_ST_FTR : HDRG_ST_EXCH_TO_1;
    }
    if (s == HDRG_ST_MODE_2) {
        return HDRG_ST_EXCH_TO_1;
    }
    return (uint8_t)(s + 1u);
}

/* sequencer.Timer.step */
static uint8_t timer_step(hdrg_state_t *st)
{
    unsigned pass;
    for (pass = 0; pass < 3u; pass++) {
        if (st->t_state == HDRG_ST_FTR || I64(st->t_cnt) < state_length(&st->t, st->t_state)) {
            break;
        }
        st->t_state = next_state(&st->t, st->t_state);
        st->t_cnt = 0;
    }
    if (st->t_state != HDRG_ST_FTR) {
        st->t_cnt += 1u;                /* <= length <= 2^31 - 1 */
    }
    return st->t_state;
}

/* clamp of an int64 to [-2^30, 2^30] (u, v, z); sets flag in *flags if it was outside */
static inline int32_t clamp_one(int64_t x, unsigned *flags, unsigned flag)
{
    if (x > HDRG_ONE) {
        *flags |= flag;
        return (int32_t)HDRG_ONE;
    }
    if (x < -HDRG_ONE) {
        *flags |= flag;
        return -(int32_t)HDRG_ONE;
    }
    return (int32_t)x;
}

/* the same of an int32 (the Z word): 32-bit compares */
static inline int32_t clamp32_one(int32_t x, unsigned *flags, unsigned flag)
{
    if (x > (int32_t)HDRG_ONE) {
        *flags |= flag;
        return (int32_t)HDRG_ONE;
    }
    if (x < -(int32_t)HDRG_ONE) {
        *flags |= flag;
        return -(int32_t)HDRG_ONE;
    }
    return x;
}

/* proxy.proxy_u: dP = clamp(P - P_REF, +-(2^31 - 1)) is an int32, so RHU(dP G_U + U_OFF, SH_U) =
 * ASR(dP G_U + u_add, SH_U) with u_add = U_OFF + 2^(SH_U - 1) (hdrg_table_t) is one SMLAL and one
 * variable 64-bit shift (0 < G_U < 2^31, |U_OFF| <= 2^30, SH_U <= 62: |.| < 2^62 + 2^61); then
 * the clamp to +-2^30 */
static HDRG_INLINE int32_t proxy_u(const hdrg_table_t *t, uint32_t pw, unsigned *flags)
{
    /* dP on 32-bit words: P and P_REF in offset binary (a T word's sign bit flipped: the uint32s are
     * ordered as the values, and their difference is P - P_REF), so |P - P_REF| < 2^32 is a - r or
     * r - a, clamped to 2^31 - 1 before the conversion to int32 */
    uint32_t a = pw ^ (PROXY_KIND(t) == 0u ? 0u : 0x80000000u), r = t->p_ref_ob;
    uint32_t d = a >= r ? a - r : r - a;
    int32_t m = d > (uint32_t)HDRG_INT32_SYM ? HDRG_INT32_SYM : (int32_t)d;
    int32_t dp = a >= r ? m : -m;
    HDRG_OPAQUE(dp);                                /* one SMLAL below */
    return clamp_one(asr64(t->u_add + I64(dp) * t->g_u, t->sh_u), flags, HDRG_FLAG_PROXY_CLAMPED);
}

/* rate.RateState.step: pushes p; returns v, sets *s (the sum before its clamp) and the flags
 * HDRG_FLAG_WARMUP, HDRG_FLAG_RATE_CLAMPED in *flags */
static HDRG_INLINE int32_t rate_step(hdrg_state_t *st, uint32_t pw, int restart, int64_t *s_out, unsigned *flags)
{
    const hdrg_table_t *t = &st->t;
    uint32_t k = st->k, n = WIN_N(st), j, prev = 0;
    int64_t p, s = 0, sc;
    if (RARE(restart)) {
        rate_reset(st);
        k = 0;
    }
    if (n == 1u) {                                  /* diff, iir, a window of 1: the ring is hist[0] */
        prev = st->hist[0];                         /* the previous word (read only when k >= 1) */
        st->hist[0] = pw;
    } else {
        if (!restart) {
            st->head = st->head == n ? 0u : st->head + 1u;
        }
        st->hist[st->head] = pw;
    }
    p = pword(st, pw);
    if (RATE_EST(t) <= 1u) {                        /* diff, diffn: |S| < 2^32 */
        if (k >= n) {
            s = p - (n == 1u ? pword(st, prev) : hist_back(st, n));
        }
    } else if (RATE_EST(t) == 2u) {                 /* lsq: |S| < n^2 2^32 <= 2^56 */
        if (k >= n - 1u) {
            uint32_t idx = st->head >= n - 1u ? st->head - (n - 1u) : st->head + 2u;  /* mod n + 1 */
            for (j = 0; j < n; j++) {
                s += (2 * I64(j) - I64(n - 1u)) * (pword(st, st->hist[idx]) - p);
                idx = idx == n ? 0u : idx + 1u;
            }
        }
    } else {                                        /* iir: |y| < 2^56; n = 1 */
        if (k >= 1u) {                              /* the gear e = min(shift, floor(log2 k)); 0 at k = 1 */
            unsigned e = k >= (1u << t->rate_shift) ? t->rate_shift : 31u - nlz32(k);
            st->iy += hdrg_rhu((p - pword(st, prev)) * P2(HDRG_IIR_FRAC) - st->iy, e);
        }
        s = st->iy;
    }
    *s_out = s;
    st->k = k < t->k_sat ? k + 1u : k;              /* saturates at k_sat */
    if (k < t->rate_warmup) {
        *flags |= HDRG_FLAG_WARMUP;
        return 0;
    }
    sc = s;                                         /* clamp to +-s_lim = +-(2^SB - 1) */
    if (RARE(s > t->s_lim)) {
        sc = t->s_lim;
        *flags |= HDRG_FLAG_RATE_CLAMPED;
    } else if (RARE(s < -t->s_lim)) {
        sc = -t->s_lim;
        *flags |= HDRG_FLAG_RATE_CLAMPED;
    }
    /* RHU(sc g_v, sh_v) = ASR(sc g_v + 2^(sh_v - 1), sh_v): |sc g_v| < 2^SB 2^(62 - SB) = 2^62 */
    return clamp_one(asr64(sc * t->g_v + t->v_half, t->sh_v), flags, HDRG_FLAG_RATE_CLAMPED);
}

/* the window commit of sequencer.Combiner.step (once per window): mean, slope; returns the
 * slope's clamp flag.  A function of its own (not inlined: HDRG_COLD) so that the divisions
 * stay out of the per-sample register allocation. */
static HDRG_COLD int comb_commit(hdrg_state_t *st, unsigned cur)
{
    int c = 0;
    int64_t mean = hdrg_div_round_scaled(st->acc, I64(st->cnt), HDRG_MEAN_EXTRA);
    int64_t sp = I64(st->cnt) - 1;
    if (st->ncommit[cur] >= 1u) {
        int64_t dc2 = 2 * (I64(st->age[cur]) - 1) - sp + I64(st->span[cur]);
        st->slope[cur] = hdrg_clamp(hdrg_div_round_scaled(mean - st->w[cur], dc2, HDRG_SLOPE_EXTRA),
                                    -HDRG_SLOPE_MAX, HDRG_SLOPE_MAX, &c);
    }
    st->w[cur] = mean;
    st->span[cur] = (uint32_t)sp;
    st->age[cur] = 1u;
    st->ncommit[cur] = st->ncommit[cur] >= 1u ? 2u : 1u;
    return c;
}

/* sequencer.Combiner.step: returns cvalid, sets st->y_hold, HDRG_FLAG_SAT in *flags; b (the sample's B) and warm
 * are read by order 1 (the residual r = c - B) only; inv: the input-invalid bit (never used; taints the window,
 * which is then not committed) */
static HDRG_INLINE int comb_step(hdrg_state_t *st, unsigned mode, int32_t r, int restart, int64_t b, int warm,
                     int inv, unsigned *flags)
{
    const hdrg_table_t *t = &st->t;
    unsigned cur, o;
    int cvalid = 0;
    if (COMBINER(t) == 0u) {
        st->y_hold = I64(r) * P2(HDRG_Y_FRAC - 10);  /* R << 11 */
        return 1;
    }
    if (RARE(restart)) {
        comb_restart(st);
    }
    {                                               /* both ages, saturating (one LDRD / STRD) */
        uint32_t a1 = st->age[1], a2 = st->age[2];
        a1 += a1 < HDRG_COUNT_MAX ? 1u : 0u;
        a2 += a2 < HDRG_COUNT_MAX ? 1u : 0u;
        st->age[1] = a1;
        st->age[2] = a2;
    }
    cur = st->cur;
    if (RARE(mode != cur)) {
        if (cur != 0u && st->cnt >= 1u && !st->taint) {   /* commit the closing window (a clean one) */
            if (comb_commit(st, cur)) {
                *flags |= HDRG_FLAG_SAT;
            }
        }
        cur = (mode == 1u || mode == 2u) ? mode : 0u;
        st->cur = (uint8_t)cur;
        if (cur != 0u) {
            st->last_window = (uint8_t)cur;
        }
        st->acc = 0;
        st->cnt = 0;
        st->pos = 0;
        st->taint = 0;
    }
    if (cur != 0u) {
        int64_t c = cur == 1u ? I64(r) : -I64(r);
        if (inv) {
            st->taint = 1;
        }
        if (st->pos >= t->settle_n) {
            if (inv) {
                return 0;                           /* not used */
            }
            if (ORDER(t) == 1u) {
                int cs = 0;
                if (warm) {
                    return 0;                       /* not used */
                }
                /* r = symsat32(RHU(c 2^11 - B, 11)): |c 2^11| < 2^42, |B| < 2^52 */
                c = hdrg_sat_signed(rhu64b(c * P2(HDRG_OUT_SHIFT) - b, HDRG_OUT_SHIFT), 32u, &cs);
                if (cs) {
                    *flags |= HDRG_FLAG_SAT;
                }
                if (COMBINER(t) == 3u) {            /* none: out = r */
                    if (st->cnt < HDRG_COUNT_MAX) {
                        st->acc += c;
                        st->cnt += 1u;
                    } else {
                        *flags |= HDRG_FLAG_SAT;
                    }
                    st->y_hold = c * P2(HDRG_OUT_SHIFT);
                    return 1;
                }
            }
            if (st->cnt < HDRG_COUNT_MAX) {
                st->acc += c;                       /* |acc| <= 2^31 cnt < 2^62 */
                st->cnt += 1u;
            } else {
                *flags |= HDRG_FLAG_SAT;
            }
            o = 3u - cur;
            if (st->ncommit[o] >= 1u && st->age[o] <= t->max_stale_n) {
                int64_t other = st->w[o];
                if (COMBINER(t) == 2u) {
                    int dc = 0;
                    int64_t d = hdrg_clamp(2 * I64(st->age[o]) + I64(st->span[o]), 0, HDRG_D_MAX, &dc);
                    if (dc) {
                        *flags |= HDRG_FLAG_SAT;
                    }
                    other += rhu64b(st->slope[o] * d, HDRG_SLOPE_EXTRA);  /* < 2^40 2^22 */
                }
                st->y_hold = c * P2(HDRG_MEAN_EXTRA) + other;
                cvalid = 1;
            }
        } else {
            st->pos += 1u;
        }
    }
    return cvalid;
}

/* floor((a w + add) / 2^30) for |a| <= 2^31 - 1, |w| <= 2^30 and add = c 2^30 + 2^29 with a
 * coefficient c (hdrg_bank_t): RHU(a w, 30) + c in one SMLAL and the two-register shift by 30.
 * |a w + add| < 2^62; the result is the next Horner accumulator, |.| <= 2^31 - 1 by the Horner
 * interval bound (check_horner), so the conversion to int32 is exact. */
static inline int32_t horner_step(int32_t a, int32_t w, int64_t add)
{
    return (int32_t)asr64(add + (int64_t)a * w, HDRG_Q);
}

/* the row u^i of a bank: c[i][3] through three Horner steps in v, aligned to 2^-E (RHU by
 * e_i - E); written out four times by the caller (no loop) */
static inline int32_t horner_row(const hdrg_bank_t *k, unsigned i, int32_t v)
{
    const hdrg_row_t *w = &k->row[i];
    const int64_t *c = w->add;
    int32_t p = w->top;
    p = horner_step(p, v, c[0]);
    p = horner_step(p, v, c[1]);
    p = horner_step(p, v, c[2]);
    return rhu32(p, w->align);
}

/* clamp of an int32 to [-2^30, 2^30] (*clamped may be NULL) */
static inline int32_t clamp_q30(int32_t x, int *clamped)
{
    int c = x > (int32_t)HDRG_ONE || x < -(int32_t)HDRG_ONE;
    if (clamped != NULL) {
        *clamped = c;
    }
    return x > (int32_t)HDRG_ONE ? (int32_t)HDRG_ONE : x < -(int32_t)HDRG_ONE ? -(int32_t)HDRG_ONE : x;
}

/* evaluator.evaluate (bank 2: the m2_k, e2_g words), on 32-bit words (hdrg_bank_t).  Contract
 * (the table checks of hdrg_table_parse): every Horner accumulator p, q, t satisfies |.| <=
 * 2^31 - 1 (the quantizer's interval bound, check_horner), |u|, |v| <= 2^30 (precondition;
 * clamped in the pipeline), z is clamped here, e_i - E in 0..31 and e_7 - E in 0..31
 * (check_fields).  Each inner Horner step is one SMLAL (horner_step), each outer one mulq30 plus
 * a 32-bit add, each row alignment RHU(q, e_i - E) a 32-bit rhu32; only the k7 z product
 * (shift 30..61) and the result B (|B| < 2^52) are 64-bit.  evaluate_k: one bank (a pointer: every
 * load of the bank at a short offset from one register), z clamped already; out of line (the step
 * calls it directly). */
static HDRG_COLD int64_t evaluate_k(const hdrg_bank_t *k, int32_t u, int32_t v, int32_t zz)
{
    int32_t acc;
    /* the rows from u^3 down, each folded in as soon as it is formed (two live row values) */
    acc = horner_row(k, 3u, v);
    acc = mulq30(acc, u) + horner_row(k, 2u, v);
    acc = mulq30(acc, u) + horner_row(k, 1u, v);
    acc = mulq30(acc, u) + horner_row(k, 0u, v);
    /* RHU(m_7 z, s), s = 30 + e_7 - E: |m_7 z| < 2^61 (one SMLAL onto 2^(s-1)), |.| <= |m_7|.
     * The shift of the table's constant s without a variable 64-bit shift: for s >= 32,
     * floor(x / 2^s) = floor(floor(x / 2^32) / 2^(s - 32)) (the high word, one 32-bit ASR);
     * s = 30 and 31 are constant two-register shifts. */
    {
#ifdef HDRG_BREAK_ROUNDING
        int64_t x7 = (int64_t)k->m7 * zz;
#else
        int64_t x7 = k->k7_half + (int64_t)k->m7 * zz;
#endif
        unsigned s7 = k->k7_shift;
        if (s7 >= 32u) {
            acc += asr32((int32_t)asr64(x7, 32u), s7 - 32u);    /* |x7 / 2^32| < 2^29 */
        } else if (s7 == 30u) {
            acc += (int32_t)asr64(x7, 30u);
        } else {
            acc += (int32_t)asr64(x7, 31u);
        }
    }
    {
        int32_t ys = k->y_sh;                                   /* E - 21 */
        unsigned l;
        if (ys >= 0) {
            return rhu32(acc, (unsigned)ys);
        }
        /* acc 2^l, l = 21 - E in 1..21 (|acc| < 2^31: below 2^52): the high word
         * floor(acc / 2^(32 - l)), the low word acc 2^l mod 2^32 (no variable 64-bit shift) */
        l = (unsigned)-ys;
        return (int64_t)asr32(acc, 32u - l) * P2(32) + I64((uint32_t)acc << l);
    }
}

int64_t hdrg_evaluate_bank(const hdrg_table_t *t, unsigned bank, int32_t u, int32_t v, int32_t z, int *z_clamped)
{
    return evaluate_k(&t->bank[bank == 2u ? 1 : 0], u, v, clamp_q30(z, z_clamped));
}

int64_t hdrg_evaluate(const hdrg_table_t *t, int32_t u, int32_t v, int32_t z, int *z_clamped)
{
    return hdrg_evaluate_bank(t, 1u, u, v, z, z_clamped);
}

#if HDRG_AUX_GEN
/* hdrg_clamp for the aux generators (as rhu_out) */
HDRG_OUTLINE_OS int64_t clamp_out(int64_t x, int64_t lo, int64_t hi, int *clamped)
{
    return hdrg_clamp(x, lo, hi, clamped);
}

/* aux.normalize: q = clamp(RHU(clamp(x - REF) G + OFF, SH), +-2^30) */
static int64_t aux_norm(int64_t x, const int64_t *c)
{
    int64_t dx = clamp_out(x - c[0], -I64(HDRG_INT32_SYM), HDRG_INT32_SYM, NULL);
    return clamp_out(rhu_out(dx * c[1] + c[2], (unsigned)c[3]), -HDRG_ONE, HDRG_ONE, NULL);
}

/* aux.AuxStage.step: the raw sum RHU(acc, 30) (the caller clamps it); inv: the input-invalid
 * bit (an input filter holds its state; a restart on an invalid sample waits in aux_pend for the
 * next valid one) */
static HDRG_COLD int64_t aux_step(hdrg_state_t *st, const hdrg_input_t *in, const hdrg_aux_input_t *ax, int64_t k,
                        unsigned mode, int restart, int64_t s, int warm, int inv)
{
    const hdrg_table_t *t = &st->t;
    int64_t acc = 0, kk = k < 0 ? 0 : k, sm = mode <= 1u ? 1 : (mode == 2u ? -1 : 0);
    const int64_t one60 = P2(60);
    unsigned j, i;
    int irs = restart || st->aux_pend;              /* the input filters' restart */
    st->aux_pend = (uint8_t)(inv && irs);
    for (j = 0; j < t->aux_nterms; j++) {
        const hdrg_aux_term_t *a = &t->aux_term[j];
        const int64_t *c = a->c;
        int64_t g = 0, y = 0, x, *ys = &st->aux_y[j];
        /* the Q1.60 filter / decay state (one code path for the three kinds that have one):
         * set it to setv, or move it toward target: ys += RHUW(coef, target - ys, sh) */
        int filt = 0, set = restart;
        int64_t setv = 0, target = 0, coef = c[0];
        unsigned sh = (unsigned)c[1];
        switch (a->kind) {
        case HDRG_AUX_INPUT:
            x = a->src == 0u ? I64(in->f) : a->src == 1u ? I64(in->t) : (ax != NULL ? I64(ax->a[a->src - 2u]) : 0);
            g = y = aux_norm(x, c);
            if (c[5] != 0 && inv) {                 /* held over an invalid sample (0 at a restart) */
                if (irs) {
                    *ys = 0;
                }
                g = y = rhu_out(*ys, HDRG_Q);
            } else if (c[5] != 0) {
                filt = 1;
                set = irs;
                setv = target = y * HDRG_ONE;
                coef = c[4];
                sh = (unsigned)c[5];
            }
            break;
        case HDRG_AUX_RATE:
            if (!warm) {
                int64_t lim = P2((unsigned)c[0]) - 1;
                g = rhu_out(clamp_out(s, -lim, lim, NULL) * c[1], (unsigned)c[2]);
                g = clamp_out(g, -HDRG_ONE, HDRG_ONE, NULL);
            }
            break;
        case HDRG_AUX_ONE:
            g = HDRG_ONE;
            break;
        case HDRG_AUX_DECAY_ON:
            filt = 1;
            setv = one60;
            break;
        case HDRG_AUX_DECAY_EXCHANGE:               /* restart: 0 (a step toward 0 from 0 is 0) */
            filt = 1;
            if (restart) {
                st->aux_ex[j] = 0;
            }
            if (mode == 3u) {
                set = 1;
                st->aux_ex[j] = 1;
            } else if (st->aux_ex[j]) {
                set = 1;
                setv = one60;
                st->aux_ex[j] = 0;
            }
            break;
        case HDRG_AUX_RAMP:
            g = kk >= c[0] ? HDRG_ONE : rhu_out(kk * c[1], (unsigned)c[2]);   /* kk < N < 2^31 */
            break;
        default:                                    /* osc: the phase K W mod 2^64 (unsigned) */
            g = hdrg_sin_q30((uint64_t)kk * (uint64_t)c[0] + (c[2] != 0 ? UINT64_C(0x4000000000000000) : 0u));
            break;
        }
        if (filt) {
            *ys = set ? setv : *ys + hdrg_rhuw(coef, target - *ys, sh);
            g = y = rhu_out(*ys, HDRG_Q);
        }
        if (a->kind == HDRG_AUX_INPUT) {
            for (i = 1; i < a->power; i++) {
                g = rhu_out(g * y, HDRG_Q);
            }
        }
        if (a->sign) {
            g = sm * g;
        }
        acc += a->w * g;                            /* |.| <= 6 2^60 */
    }
    return rhu_out(acc, HDRG_Q);
}

#endif /* HDRG_AUX_GEN */

/* compensate.Pipeline.step: one sample.  o (hdrg_step_aux) gets every intermediate, r
 * (hdrg_step_out) the outputs only; the two public functions inline this body with one of them
 * NULL, so that the lean one has neither the stores nor the live registers of the intermediates
 * (SET below: a store only when full, a constant of each caller). */
#define SET(field, value) do { if (full) { o->field = (value); } } while (0)

static HDRG_INLINE int step_core(hdrg_state_t *st, const hdrg_input_t *in, const hdrg_aux_input_t *ax,
                                 int full, hdrg_sample_t *o, hdrg_out_t *r)
{
    const hdrg_table_t *t = &st->t;
    int restart = in->restart != 0;
    int inv = in->invalid != 0;
    int cvalid, valid, warm, rrestart;
    unsigned state, mode, flags = 0;                /* flags are set where they arise */
    uint32_t pw;
    int64_t b, s;
    int32_t u, v, z;
    if (in->mode < -1 || in->mode > 3) {
        return HDRG_ERR_INPUT;
    }
    if (ax != NULL && ax->k_given && (ax->k > HDRG_K_LIMIT || ax->k < -HDRG_K_LIMIT)) {
        return HDRG_ERR_INPUT;
    }
    /* 1. sequencer state: self-timed or logged */
    if (in->mode < 0) {
        if (restart) {
            st->t_state = HDRG_ST_POWER_ON;
            st->t_cnt = 0;
        }
        state = timer_step(st);
        mode = STATE_MODE[state];
    } else {
        mode = (unsigned)in->mode;
        state = mode == 0u ? HDRG_ST_FTR : mode == 1u ? HDRG_ST_MODE_1 : mode == 2u ? HDRG_ST_MODE_2
              : st->last_window == 1u ? HDRG_ST_EXCH_TO_2 : HDRG_ST_EXCH_TO_1;
    }
    SET(state, (uint8_t)state);
    SET(vs, STATE_VS[state]);
    SET(mode, (uint8_t)mode);
    SET(sign, STATE_SIGN[state]);
    /* 2. proxy, 3. rate (the outputs are stored as they arise: fewer live registers) */
    pw = PROXY_KIND(t) == 0u ? in->f : (uint32_t)in->t;   /* bit pattern, decoded by pword */
    u = proxy_u(t, pw, &flags);
    SET(u, u);
    rrestart = restart || inv || st->prev_invalid;  /* the estimator restarts at an invalid sample and the next */
    st->prev_invalid = (uint8_t)inv;
    v = rate_step(st, pw, rrestart, &s, &flags);
    SET(v, v);
    SET(s, s);
    warm = (flags & HDRG_FLAG_WARMUP) != 0u;
    /* 4b. aux: the generators (aux_gen 1; the sample counter kc is read by them only, so it is
     * kept for aux_gen 1 tables only) or the Z word */
#if HDRG_AUX_GEN
    if (RARE(t->aux_gen == 1u)) {
        int64_t k = (ax != NULL && ax->k_given) ? ax->k : st->kc;
        st->kc = k < HDRG_K_LIMIT ? k + 1 : HDRG_K_LIMIT;
        z = clamp_one(aux_step(st, in, ax, k, mode, restart || st->fresh, s, warm, inv), &flags,
                      HDRG_FLAG_AUX_CLAMPED);
        st->fresh = 0;
    } else
#endif
    {
        z = clamp32_one(in->z, &flags, HDRG_FLAG_AUX_CLAMPED);
    }
    SET(z, z);
    /* 5. evaluator: bank 2 on mode-2 samples of a two-bank table */
    b = evaluate_k(mode == 2u ? &t->bank[1] : &t->bank[0], u, v, z);   /* z is clamped */
    SET(b, b);
    /* 5b. combiner (order 1 reads B) */
    cvalid = comb_step(st, mode, in->r, restart, b, warm, inv, &flags);
    /* 6. compensate */
    valid = cvalid && !warm && mode != 3u && !inv;
    if (RARE(inv)) {
        flags |= HDRG_FLAG_INPUT_SAT;
    }
    if (valid) {
        int s1 = 0, s2 = 0;
        /* |y| < 2^47, |B| < 2^52; order 1: B is in y already */
        st->out_hold = (int32_t)hdrg_sat_signed(rhu64b(ORDER(t) == 0u ? st->y_hold - b : st->y_hold,
                                                         HDRG_OUT_SHIFT), 32u, &s1);
        st->bias_hold = (int32_t)hdrg_sat_signed(rhu64b(b, HDRG_OUT_SHIFT), 32u, &s2);
        if (RARE(s1 || s2)) {
            flags |= HDRG_FLAG_SAT;
        }
    }
    if (mode == 3u) {
        flags |= HDRG_FLAG_EXCHANGE;
    } else if (!cvalid) {
        flags |= HDRG_FLAG_STALE;
    }
    SET(acc, st->acc);
    SET(cnt, st->cnt);
    SET(y, st->y_hold);
    SET(out, st->out_hold);
    SET(bias, st->bias_hold);
    SET(valid, (uint8_t)valid);
    SET(flags, (uint8_t)flags);
    if (!full) {
        r->out = st->out_hold;
        r->bias = st->bias_hold;
        r->valid = (uint8_t)valid;
        r->flags = (uint8_t)flags;
    }
    return HDRG_OK;
}

int hdrg_step(hdrg_state_t *st, const hdrg_input_t *in, hdrg_sample_t *out)
{
    return hdrg_step_aux(st, in, NULL, out);
}

int hdrg_step_aux(hdrg_state_t *st, const hdrg_input_t *in, const hdrg_aux_input_t *ax, hdrg_sample_t *out)
{
    return step_core(st, in, ax, 1, out, NULL);
}

int hdrg_step_out(hdrg_state_t *st, const hdrg_input_t *in, const hdrg_aux_input_t *ax, hdrg_out_t *r)
{
    return step_core(st, in, ax, 0, NULL, r);
}
