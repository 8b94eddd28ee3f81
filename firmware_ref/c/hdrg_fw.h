/*
 * hdrg_fw.h - C99 twin of the fixed-point compensation pipeline (firmware_ref/FORMATS.md).
 *
 * Bit for bit the same as the Python-integer reference (firmware_ref/proxy.py, rate.py,
 * sequencer.py, evaluator.py, compensate.py) and the numba kernel (firmware_ref/kernel.py).
 * stdint.h and stddef.h only; no floating point, no malloc (all state is in hdrg_state_t),
 * no undefined behaviour and no implementation-defined behaviour:
 *   - arithmetic right shifts of negative values are never written: floor(x / 2^s) is
 *     x < 0 ? ~(~x >> s) : x >> s, one ASR with GCC/Clang (proof in hdrg_fw.c);
 *   - no 64-bit / or %: hdrg_udiv64() divides with 32-bit divisions (no library division on a
 *     32-bit core); the per-sample products are 32 x 32 -> 64 (SMULL/SMLAL) where the bounds allow;
 *   - left shifts of negative values are written as products with (int64_t)1 << k;
 *   - every signed intermediate stays inside int64 by the bounds of FORMATS.md, which the
 *     table checks of hdrg_table_parse() enforce (including the Horner interval bound);
 *   - uint32 -> int32 reinterpretation is done arithmetically, never by a cast.
 *
 * Usage:
 *     static hdrg_state_t st;                     (18.5 kB with HDRG_N_HIST_MAX = 4096)
 *     if (hdrg_init(&st, words, n_words) != HDRG_OK) ... refuse the table
 *     per sample: hdrg_step(&st, &in, &out);      (in: input words, out: outputs + intermediates)
 *     or hdrg_step_aux(&st, &in, &aux, &out) with the aux words A_c and the counter K (aux_gen 1)
 *
 * Units (FORMATS.md): F uint32 LSB 2^-15 Hz (0 .. 131072 Hz); T int32 LSB 2^-16 degC; R int32 LSB 2^-10 deg/h;
 * u, v, z int32 Q1.30; y, B int64 LSB 2^-21 deg/h; OUT, BIAS int32 LSB 2^-10 deg/h; A_c int32
 * LSB 2^-AF_c (table); K int64 samples since power-on.
 */
#ifndef HDRG_FW_H
#define HDRG_FW_H

#include <stddef.h>
#include <stdint.h>

/* Longest diffn/lsq window n the history ring can hold (compile-time; the ring holds n + 1
 * uint32 words, 4 (HDRG_N_HIST_MAX + 1) bytes).  A table with rate_n above it is refused
 * (HDRG_ERR_FIELD).  At most 4096 (formats.N_HIST_MAX: the lsq bound |S| < 2^57 needs it). */
#ifndef HDRG_N_HIST_MAX
#define HDRG_N_HIST_MAX 4096
#endif
#if HDRG_N_HIST_MAX < 2 || HDRG_N_HIST_MAX > 4096
#error "HDRG_N_HIST_MAX must be in 2..4096"
#endif

/* 1 (default): the aux generators of aux_gen 1 tables are compiled in; 0: a firmware without
 * them (aux_gen 1 tables are refused, HDRG_ERR_FIELD at word aux_gen; about 1.4 kB less code on
 * Cortex-M at -Os).  Everything else is the same, bit for bit. */
#ifndef HDRG_AUX_GEN
#define HDRG_AUX_GEN 1
#endif

/* A configuration-specialized build (the firmware engineer ships one configuration): each of
 * these, when defined, fixes a table field at compile time, so that its branches and the code of
 * the other choices fold away; the coefficients and every other field are still loaded at run
 * time.  A table with another value of a fixed field is refused (HDRG_ERR_FIELD at that word).
 *   -DHDRG_FIX_PROXY=k   proxy_kind (0 freq, 1 temp)
 *   -DHDRG_FIX_EST=k     rate_est (0 diff, 1 diffn, 2 lsq, 3 iir)
 *   -DHDRG_FIX_COMB=k    combiner (0 ftr, 1 pair, 2 trend, 3 none)
 *   -DHDRG_FIX_ORDER=k   order (0 combine_first, 1 regress_first; n_banks follows)
 * Fix the fields of the table you ship (the exported header lists them: rate_est, combiner, ...):
 * `hdrg fit` chooses the rate estimator per device (cross-validated, iir preferred) and may add
 * aux terms (a lag block), so a build fixed for one device's table may refuse another's.  The
 * build `hdrg cost` measures (regress_first pair, diff, freq proxy, no aux generators):
 * -DHDRG_FIX_PROXY=0 -DHDRG_FIX_EST=0 -DHDRG_FIX_COMB=1 -DHDRG_FIX_ORDER=1 -DHDRG_AUX_GEN=0.
 * Bit for bit the same answers for every table it accepts. */
#if defined(HDRG_FIX_PROXY) && (HDRG_FIX_PROXY < 0 || HDRG_FIX_PROXY > 1)
#error "HDRG_FIX_PROXY must be 0 or 1"
#endif
#if defined(HDRG_FIX_EST) && (HDRG_FIX_EST < 0 || HDRG_FIX_EST > 3)
#error "HDRG_FIX_EST must be in 0..3"
#endif
#if defined(HDRG_FIX_COMB) && (HDRG_FIX_COMB < 0 || HDRG_FIX_COMB > 3)
#error "HDRG_FIX_COMB must be in 0..3"
#endif
#if defined(HDRG_FIX_ORDER) && (HDRG_FIX_ORDER < 0 || HDRG_FIX_ORDER > 1)
#error "HDRG_FIX_ORDER must be 0 or 1"
#endif

/* ---- table layout (version 4; 3, 2 and 1 (order 0, one bank) are read unless iir or reading F) */
#define HDRG_MAGIC 0x47524448u          /* 'HDRG' as little-endian bytes */
#define HDRG_LAYOUT_VERSION 4u
#define HDRG_IIR_GEAR_VERSION 3u        /* the iir starts with the gear from this version on */
#define HDRG_FREQ_WORD_VERSION 4u       /* F at LSB 2^-15 Hz from this version on (2^-18 Hz before): an
                                           older table that reads F (proxy or aux input) is refused */
#define HDRG_N_FIXED 72u                /* words 0..71: header, config, bank 1, aux header, order,
                                           n_banks, bank 2 */
#define HDRG_N_FIXED_V1 47u             /* words 0..46 of a version-1 table */
#define HDRG_N_TERMS 17u
/* aux generators (aux_gen 1 'sum'): parameters n_terms, n_chan, AF_c per channel, 11 words per term */
#define HDRG_AUX_MAX_TERMS 16u         /* formats.AUX_MAX_TERMS: a table of more is refused (FIELD at n_terms) */
#define HDRG_AUX_MAX_CH 4u
#define HDRG_AUX_TERM_WORDS 11u
#define HDRG_AUX_FRAC_MAX 48u
#define HDRG_AUX_PARAMS_MAX (2u + HDRG_AUX_MAX_CH + HDRG_AUX_MAX_TERMS * HDRG_AUX_TERM_WORDS)   /* 182 */
/* the longest table: 255 words (word addresses 0..254, 1020 bytes: one serial TABLE frame) */
#define HDRG_TABLE_WORDS_MAX (HDRG_N_FIXED + HDRG_AUX_PARAMS_MAX + 1u)                     /* 255 */

enum hdrg_word {
    HDRG_W_MAGIC = 0, HDRG_W_VERSION, HDRG_W_LENGTH, HDRG_W_PROXY_KIND, HDRG_W_P_REF, HDRG_W_G_U,
    HDRG_W_U_OFF, HDRG_W_SH_U, HDRG_W_RATE_EST, HDRG_W_RATE_N, HDRG_W_RATE_SHIFT, HDRG_W_RATE_WARMUP,
    HDRG_W_S_BITS, HDRG_W_G_V, HDRG_W_SH_V, HDRG_W_FS_Q16, HDRG_W_COMBINER, HDRG_W_SETTLE_N,
    HDRG_W_MAX_STALE_N, HDRG_W_POWER_ON_N, HDRG_W_EXCHANGE_N, HDRG_W_DWELL_N, HDRG_W_E_0,
    HDRG_W_E_7 = HDRG_W_E_0 + 4, HDRG_W_E_ACC, HDRG_W_M_0,
    HDRG_W_AUX_GEN = HDRG_W_M_0 + 17, HDRG_W_AUX_NPARAMS,
    HDRG_W_ORDER, HDRG_W_N_BANKS, HDRG_W_E2_0, HDRG_W_E2_7 = HDRG_W_E2_0 + 4, HDRG_W_E2_ACC, HDRG_W_M2_0
};

/* ---- formats (firmware_ref/formats.py) ------------------------------------------------- */
#define HDRG_Q 30
#define HDRG_ONE ((int64_t)1 << HDRG_Q)
#define HDRG_INT32_SYM 2147483647
#define HDRG_IIR_FRAC 24
#define HDRG_S_BITS_MAX 55
#define HDRG_MEAN_EXTRA 10
#define HDRG_SLOPE_EXTRA 16
#define HDRG_SLOPE_MAX (((int64_t)1 << 40) - 1)
#define HDRG_D_MAX 4194303
#define HDRG_COUNT_MAX 2147483647u
#define HDRG_TIMER_MAX 2147483647u
#define HDRG_ACC_LIMIT 2147483647
#define HDRG_EXP_MAX 52
#define HDRG_ALIGN_MAX 31
#define HDRG_Y_FRAC 21
#define HDRG_OUT_SHIFT 11
#define HDRG_AUX_SB_MIN 31u
#define HDRG_AUX_SB_MAX 62u
#define HDRG_AUX_POWER_MAX 5u
#define HDRG_K_LIMIT ((int64_t)1 << 62)

/* ---- vocabulary: codes of the table fields, aux term kinds, sequencer states, status flags -- */
/* BEGIN vocabulary (generated from firmware_ref/vocabulary.py: python -m firmware_ref.docgen --update) */
#define HDRG_PROXY_FREQ 0u
#define HDRG_PROXY_TEMP 1u
#define HDRG_EST_DIFF 0u
#define HDRG_EST_DIFFN 1u
#define HDRG_EST_LSQ 2u
#define HDRG_EST_IIR 3u
#define HDRG_COMB_FTR 0u
#define HDRG_COMB_PAIR 1u
#define HDRG_COMB_TREND 2u
#define HDRG_COMB_NONE 3u
#define HDRG_ORDER_COMBINE_FIRST 0u
#define HDRG_ORDER_REGRESS_FIRST 1u
#define HDRG_AUXGEN_NONE 0u
#define HDRG_AUXGEN_SUM 1u
enum hdrg_aux_kind {
    HDRG_AUX_INPUT = 0,
    HDRG_AUX_RATE = 1,
    HDRG_AUX_ONE = 2,
    HDRG_AUX_DECAY_ON = 3,
    HDRG_AUX_DECAY_EXCHANGE = 4,
    HDRG_AUX_RAMP = 5,
    HDRG_AUX_OSC = 6
};
enum hdrg_seq_state {
    HDRG_ST_POWER_ON = 0,
    HDRG_ST_EXCH_TO_1 = 1,
    HDRG_ST_MODE_1 = 2,
    HDRG_ST_EXCH_TO_2 = 3,
    HDRG_ST_MODE_2 = 4,
    HDRG_ST_FTR = 5
};
/* status flags (uint8) */
#define HDRG_FLAG_PROXY_CLAMPED 1u      /* u outside [-1, 1] was clamped (golden: same rule, |u_raw| > 1) */
#define HDRG_FLAG_RATE_CLAMPED 2u       /* v outside [-1, 1] was clamped */
#define HDRG_FLAG_WARMUP 4u             /* rate estimator in warm-up (v = 0) */
#define HDRG_FLAG_EXCHANGE 8u           /* mode 3 (exchange or power-on) */
#define HDRG_FLAG_STALE 16u             /* mode 1/2 sample without a valid combination (settling, no window, too old) */
#define HDRG_FLAG_AUX_CLAMPED 32u       /* z word outside [-2^30, 2^30] was clamped */
#define HDRG_FLAG_INPUT_SAT 64u         /* input-invalid: the sample's invalid bit (an input outside the declared full scale or its word's range; host input stage), or an aux word saturated */
#define HDRG_FLAG_SAT 128u              /* saturation in the pipeline: window count, trend slope/distance, output word */
/* END vocabulary */

/* ---- virtual-switch bits ------------------------------------------------------------- */
#define HDRG_VS_DRV_X 0x01u
#define HDRG_VS_DRV_Y 0x02u
#define HDRG_VS_SNS_Y 0x04u
#define HDRG_VS_SNS_X 0x08u
#define HDRG_VS_NEG 0x10u

/* ---- errors ---------------------------------------------------------------------------- */
enum hdrg_error {
    HDRG_OK = 0,
    HDRG_ERR_LENGTH,    /* fewer than 73 (version 1: 48) words, or the length word disagrees with the count */
    HDRG_ERR_MAGIC,     /* word 0 is not 0x47524448 */
    HDRG_ERR_VERSION,   /* word 1 is not 1..4, an iir table of version 1 or 2 (blanked start-up), or a
                           table of version 1..3 that reads F (quantized for the 2^-18 Hz word) */
    HDRG_ERR_CRC,       /* the last word is not the CRC-32 of the others */
    HDRG_ERR_FIELD,     /* a field outside its legal range (which: *bad_word) */
    HDRG_ERR_HORNER,    /* the mantissas break the Horner interval bound (|acc| <= 2^31 - 1) */
    HDRG_ERR_INPUT      /* hdrg_step: mode not in -1..3; hdrg_step_aux: |K| > 2^62 */
};

/* One decoded aux term (FORMATS.md "Aux generators"; firmware_ref/table.py AuxTerm): c[] as
 * stored, except input's REF of an F source (the uint32 value) and osc's c[0] = W (64 bits). */
typedef struct hdrg_aux_term {
    uint32_t kind, sign, src, power;
    int64_t w;                  /* weight, Q1.30 */
    int64_t c[6];
} hdrg_aux_term_t;

/* One coefficient bank in the evaluator's order, derived from the table words by
 * hdrg_table_parse (nothing here is a new degree of freedom): row i = 0..3 (the u^i row) is
 * p = c[i][3], then three Horner steps p = RHU(p v, 30) + c[i][2], c[i][1], c[i][0], written as
 * floor((p v + add) / 2^30) with add = c[i][j] 2^30 + 2^29 (the rounding constant and the next
 * coefficient folded into one SMLAL addend: RHU(p v, 30) + c = floor((p v + 2^29 + c 2^30) / 2^30)). */
typedef struct hdrg_row {     /* one row, contiguous (one base register for all its loads) */
    int64_t add[3];             /* add[k] = c[i][2 - k] 2^30 + 2^29 */
    int32_t top;                /* c[i][3] */
    uint32_t align;             /* e_i - E (0..31) */
} hdrg_row_t;
typedef struct hdrg_bank {
    hdrg_row_t row[4];
    int64_t k7_half;            /* 2^(k7_shift - 1) */
    int32_t m7;                 /* k7 mantissa */
    uint32_t k7_shift;          /* 30 + e_7 - E (30..61) */
    uint32_t e_acc;             /* E */
    int32_t y_sh;               /* E - 21 (-21..31): >= 0 the RHU of the result, < 0 its left shift by 21 - E */
} hdrg_bank_t;

/* The decoded table fields (FORMATS.md "Coefficient table layout"); signed fields decoded from
 * two's complement, p_ref of a freq table kept as the uint32 value.  The fields after crc are
 * derived at parse time for the per-sample path. */
typedef struct hdrg_table {
    uint32_t proxy_kind;        /* 0 freq (P = F word), 1 temp (P = T word) */
    int64_t p_ref;
    int32_t g_u, u_off;         /* 0 < g_u < 2^31, |u_off| <= g_u / 2 + 1 */
    uint32_t sh_u;
    uint32_t rate_est;          /* 0 diff, 1 diffn, 2 lsq, 3 iir */
    uint32_t rate_n, rate_shift, rate_warmup, s_bits;
    int32_t g_v;                /* 0 < g_v < 2^min(31, 62 - s_bits) */
    uint32_t sh_v, fs_q16;
    uint32_t combiner;          /* 0 ftr, 1 pair, 2 trend, 3 none (order 1 only) */
    uint32_t settle_n, max_stale_n, power_on_n, exchange_n, dwell_n;
    uint32_t e_row[4], e_7, e_acc;
    int32_t mant[HDRG_N_TERMS];
    uint32_t aux_gen, aux_nparams;
    uint32_t order;             /* 0 combine_first (and FTR), 1 regress_first (residual combiner) */
    uint32_t n_banks;           /* 1, or 2 with order 1: bank 2 on mode-2 samples */
    uint32_t e_row2[4], e_7_2, e_acc2;          /* bank 2 (0 when n_banks = 1) */
    int32_t mant2[HDRG_N_TERMS];
    uint32_t n_fixed;           /* fixed words of the table read: 72 (versions 2, 3) or 47 (version 1) */
    uint32_t aux_nterms, aux_nch;               /* aux_gen 1 */
    uint32_t aux_frac[HDRG_AUX_MAX_CH];
    hdrg_aux_term_t aux_term[HDRG_AUX_MAX_TERMS];
    uint32_t n_words, crc;
    int64_t s_lim;              /* 2^s_bits - 1: the rate-sum clamp */
    uint32_t k_sat;             /* where k saturates: max(rate_warmup, 2^rate_shift) for iir, else rate_warmup */
    uint32_t p_ref_ob;          /* p_ref in offset binary: the word (freq), the word with bit 31 flipped (temp) */
    int64_t u_add;              /* u_off + 2^(sh_u - 1) (u_off if sh_u = 0): u = ASR(dP g_u + u_add, sh_u) */
    int64_t v_half;             /* 2^(sh_v - 1) (0 if sh_v = 0): v = ASR(S g_v + v_half, sh_v) */
    hdrg_bank_t bank[2];        /* bank 1, bank 2 (a copy of bank 1 for a one-bank table) */
} hdrg_table_t;

/* The input words of one sample. */
typedef struct hdrg_input {
    uint32_t f;         /* drive-frequency word F (used when proxy_kind = 0) */
    int32_t t;          /* temperature word T (used when proxy_kind = 1) */
    int32_t r;          /* raw rate word R */
    int32_t z;          /* aux word Z (Q1.30; clamped to [-2^30, 2^30], flag 32) */
    int8_t mode;        /* logged mode 0..3, or -1: the internal sequencer (timer) decides */
    uint8_t restart;    /* 1 at the start of a gap-free segment */
    uint8_t invalid;    /* 1: the input-invalid bit (the front end's over-range flag; FORMATS.md
                         * "The input-invalid bit"): the sample is not valid, the rate estimator
                         * restarts at it and at the next sample, its window is not committed,
                         * the aux input filters hold their state over it */
} hdrg_input_t;

/* The extra input words of one sample for an aux_gen 1 table (hdrg_step_aux): the aux words
 * A_c (int32, LSB 2^-AF_c of the aux_* column's unit) and the sample counter K since power-on
 * (|K| <= 2^62; k_given 0: the internal count, K = previous K + 1, 0 at power-on).  F and T come
 * from hdrg_input_t (both are read when a term uses them). */
typedef struct hdrg_aux_input {
    int32_t a[HDRG_AUX_MAX_CH];
    int64_t k;
    uint8_t k_given;
} hdrg_aux_input_t;

/* The outputs and every intermediate of one sample. */
typedef struct hdrg_sample {
    uint8_t state;      /* sequencer state (enum hdrg_seq_state) */
    uint8_t vs;         /* virtual-switch bits of the state */
    uint8_t mode;       /* run-log mode 0..3 */
    int8_t sign;        /* rate sign of the state: 1, -1, 0 (sense loop open) */
    int32_t u, v, z;    /* Q1.30 (clamped; z: the Z word (aux_gen 0) or the generated z) */
    int64_t s;          /* rate-estimator sum before its clamp (P LSB; iir: 2^-24 P LSB) */
    int64_t acc;        /* window sum after this sample (LSB 2^-10 deg/h; order 1: of r = c - B) */
    uint32_t cnt;       /* window count after this sample */
    int64_t y;          /* combined output (held), LSB 2^-21 deg/h */
    int64_t b;          /* bias B of the sample's bank, LSB 2^-21 deg/h */
    int32_t out, bias;  /* output words (held), LSB 2^-10 deg/h */
    uint8_t valid, flags;
} hdrg_sample_t;

/* The outputs of one sample for a firmware (hdrg_step_out): what the control loop reads. */
typedef struct hdrg_out {
    int32_t out, bias;  /* output words (held), LSB 2^-10 deg/h */
    uint8_t valid, flags;
} hdrg_out_t;

/* The whole firmware state: the table and every register of the pipeline. */
typedef struct hdrg_state {
    hdrg_table_t t;
    uint32_t n;                             /* effective window: rate_n (diffn, lsq) or 1 */
    /* timer */
    uint8_t t_state;
    uint32_t t_cnt;
    /* rate estimator */
    uint32_t head;                          /* index of the present word */
    uint32_t k;                             /* samples since restart, saturating at t.k_sat */
    int64_t iy;                             /* iir state, 2^-24 P LSB */
    uint8_t prev_invalid;                   /* the previous sample was input-invalid */
    /* combiner (index 1, 2: the modes) */
    uint8_t cur, last_window;
    uint8_t taint;                          /* the open window held an input-invalid sample */
    uint8_t ncommit[3];
    int64_t acc;
    uint32_t cnt, pos;
    int64_t w[3], slope[3];
    uint32_t span[3], age[3];
    /* held outputs */
    int64_t y_hold;
    int32_t out_hold, bias_hold;
    /* aux generators: filter / decay states (Q1.60), exchange flags, sample counter, power-on */
    int64_t aux_y[HDRG_AUX_MAX_TERMS];
    uint8_t aux_ex[HDRG_AUX_MAX_TERMS];
    uint8_t aux_pend;                       /* a restart on an input-invalid sample, for the input filters */
    int64_t kc;
    uint8_t fresh;
    /* the history ring last: every other register is then within an immediate load offset of the
     * state's address (Cortex-M: no second base register for the fields behind a 16 kB ring) */
    uint32_t hist[HDRG_N_HIST_MAX + 1];     /* ring of the last n + 1 proxy words (bit patterns) */
} hdrg_state_t;

/* ---- primitives (FORMATS.md "primitives"; preconditions as firmware_ref/arith.py) ------- */
/* RHU(x, s) = floor(x / 2^s + 1/2); 0 <= s <= 62 and x + 2^(s-1) must fit int64. */
int64_t hdrg_rhu(int64_t x, unsigned s);
/* floor(x / 2^s) for 0 <= s <= 63 (the arithmetic right shift, written portably). */
int64_t hdrg_asr(int64_t x, unsigned s);
/* RHU(a * b, s); the product must fit int64. */
int64_t hdrg_mul_rhu(int64_t a, int64_t b, unsigned s);
/* floor(n / d) and *rem = n - d floor(n / d) for d > 0, with 32-bit divisions only (no 64-bit
 * library division): the per-sample path's only divider (window means, trend slopes). */
uint64_t hdrg_udiv64(uint64_t n, uint64_t d, uint64_t *rem);
/* floor(a / b), b > 0. */
int64_t hdrg_floor_div(int64_t a, int64_t b);
/* floor((2a + b) / 2b), b > 0. */
int64_t hdrg_div_round(int64_t a, int64_t b);
/* RHU(a 2^k / b), b > 0, without forming a 2^k (see arith.div_round_scaled). */
int64_t hdrg_div_round_scaled(int64_t a, int64_t b, unsigned k);
/* min(max(x, lo), hi); *clamped = 1 if x was outside (clamped may be NULL). */
int64_t hdrg_clamp(int64_t x, int64_t lo, int64_t hi, int *clamped);
/* symmetric saturation to a signed width-bit word, 1 <= width <= 63 */
int64_t hdrg_sat_signed(int64_t x, unsigned width, int *clamped);
/* CRC-32 (IEEE 802.3, zlib.crc32) of n words as little-endian bytes. */
uint32_t hdrg_crc32_words(const uint32_t *words, size_t n);
/* RHUW(a, d, s) = RHU(a * d, s) for |a| < 2^31, |d| <= 2^62, 31 <= s <= 62 (a product wider than
 * int64, computed from d = dh 2^31 + dl; arith.mul_rshift_round_wide). */
int64_t hdrg_rhuw(int64_t a, int64_t d, unsigned s);
/* sin(2 pi phase / 2^64) in Q1.30 (firmware_ref/aux.py sin_q30), phase a uint64. */
int32_t hdrg_sin_q30(uint64_t phase);

/* ---- table, pipeline ------------------------------------------------------------------- */
/* Decode and check a table (magic, version, length, CRC, every field range and the Horner
 * interval bound).  Returns HDRG_OK or an error; *bad_word (may be NULL) gets the index of the
 * offending word (HDRG_ERR_FIELD) or 0. */
int hdrg_table_parse(hdrg_table_t *t, const uint32_t *words, size_t n_words, unsigned *bad_word);
/* Name of a layout word ("s_bits", "m_7", "crc32", ...), or "?" */
const char *hdrg_word_name(unsigned index);
/* Name of an error code */
const char *hdrg_error_name(int err);

/* Parse the table into st and reset (power-on).  On error st is left unusable. */
int hdrg_init(hdrg_state_t *st, const uint32_t *words, size_t n_words, unsigned *bad_word);
/* Power-on reset (everything, including the held outputs). */
void hdrg_reset(hdrg_state_t *st);
/* One sample.  Returns HDRG_OK, or HDRG_ERR_INPUT (mode outside -1..3; the state is unchanged).
 * Same as hdrg_step_aux(st, in, NULL, out): aux words 0, the internal sample counter. */
int hdrg_step(hdrg_state_t *st, const hdrg_input_t *in, hdrg_sample_t *out);
/* One sample with the aux generators' extra inputs (aux may be NULL); HDRG_ERR_INPUT also when
 * |K| > 2^62. */
int hdrg_step_aux(hdrg_state_t *st, const hdrg_input_t *in, const hdrg_aux_input_t *aux, hdrg_sample_t *out);
/* The firmware entry point: one sample, the same as hdrg_step_aux bit for bit (same state, same
 * out, bias, valid, flags), without the intermediates of hdrg_sample_t (fewer stores and live
 * registers).  aux may be NULL. */
int hdrg_step_out(hdrg_state_t *st, const hdrg_input_t *in, const hdrg_aux_input_t *aux, hdrg_out_t *r);
/* The bias B (LSB 2^-21 deg/h) at u, v in [-2^30, 2^30] (precondition) and any z (clamped;
 * *z_clamped may be NULL). */
int64_t hdrg_evaluate(const hdrg_table_t *t, int32_t u, int32_t v, int32_t z, int *z_clamped);
/* The same with coefficient bank 1 or 2 (bank 2 of a one-bank table: bank 1). */
int64_t hdrg_evaluate_bank(const hdrg_table_t *t, unsigned bank, int32_t u, int32_t v, int32_t z, int *z_clamped);

#endif /* HDRG_FW_H */
