/*
 * hdrg_fw_main.c - stdin/stdout driver of the C twin (protocol: firmware_ref/c/README.md).
 *
 * Build:  gcc -std=c99 -O2 -Wall -Wextra -Werror -o hdrg_fw hdrg_fw.c hdrg_fw_main.c
 * -DHDRG_DRIVER_LEAN: S requests run the firmware entry point hdrg_step_out (the O line's
 * intermediates are 0; see req_sample).
 * Optional: -DHDRG_TABLE_HEADER='"hdrg_table.h"' (a header of `hdrg export --format c`) enables
 * the request `TABLE BUILTIN`, which loads the table compiled in from that header.
 *
 * Exit status: 0 when every request succeeded, 1 when some request was answered with ERR,
 * 2 on a fatal error (unreadable/truncated binary block, out of memory, write failure).
 */
#include <errno.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "hdrg_fw.h"

#ifdef HDRG_TABLE_HEADER
#include HDRG_TABLE_HEADER
#endif

#define LINE_MAX_CHARS 8192
#define P31 ((int64_t)1 << 31)
#define P62 ((int64_t)1 << 62)
#define MAX_TOKENS 300
#define REC_IN 6        /* binary input record: F T R MODE RESTART Z, int64 little-endian */
#define REC_IN_AUX 11   /* ... with K A0 A1 A2 A3 (BIN N 11, BENCH N REPEATS 11) */
#define REC_OUT 16      /* binary output record: the 16 fields of an O line, int64 little-endian */

static hdrg_state_t g_st;
static int g_have_table = 0;
static int g_run_kind = 0;      /* 0 none yet, 1 logged modes, 2 self-timed (-1) */
static int g_any_error = 0;

static void fatal(const char *msg)
{
    fprintf(stderr, "hdrg_fw: fatal: %s\n", msg);
    exit(2);
}

static void err(const char *code, const char *detail)
{
    printf("ERR %s %s\n", code, detail);
    g_any_error = 1;
}

/* ------------------------------------------------------------------ number parsing -------- */

static int parse_i64(const char *s, int64_t *out)
{
    char *end;
    long long v;
    if (*s == '\0') {
        return 0;
    }
    errno = 0;
    v = strtoll(s, &end, 10);
    if (errno != 0 || *end != '\0') {
        return 0;
    }
    *out = (int64_t)v;
    return 1;
}

static int parse_hex32(const char *s, uint32_t *out)
{
    char *end;
    unsigned long long v;
    const char *p = s;
    if (p[0] == '0' && (p[1] == 'x' || p[1] == 'X')) {
        p += 2;
    }
    if (!((*p >= '0' && *p <= '9') || (*p >= 'a' && *p <= 'f') || (*p >= 'A' && *p <= 'F'))) {
        return 0;
    }
    errno = 0;
    v = strtoull(p, &end, 16);
    if (errno != 0 || *end != '\0' || v > 0xFFFFFFFFull) {
        return 0;
    }
    *out = (uint32_t)v;
    return 1;
}

/* checked int64 arithmetic for the primitive requests (preconditions of firmware_ref/arith.py) */
static int mul_ok(int64_t a, int64_t b, int64_t *r)
{
    if (a > 0) {
        if (b > 0 ? a > INT64_MAX / b : b < INT64_MIN / a) {
            return 0;
        }
    } else if (a < 0) {
        if (b > 0 ? a < INT64_MIN / b : (b != 0 && b < INT64_MAX / a)) {
            return 0;
        }
    }
    *r = a * b;
    return 1;
}

static int add_ok(int64_t a, int64_t b, int64_t *r)
{
    if ((b > 0 && a > INT64_MAX - b) || (b < 0 && a < INT64_MIN - b)) {
        return 0;
    }
    *r = a + b;
    return 1;
}

static int rhu_ok(int64_t x, int64_t s)
{
    int64_t t;
    return s >= 0 && s <= 62 && (s == 0 || add_ok(x, (int64_t)1 << (s - 1), &t));
}

static int divrs_ok(int64_t a, int64_t b, int64_t k)
{
    int64_t q, r, qs, rs, num, b2, res;
    if (b <= 0 || k < 0 || k > 62) {
        return 0;
    }
    q = a / b;
    r = a % b;                  /* as hdrg_div_round_scaled: no q * b product */
    if (r < 0) {
        q -= 1;
        r += b;
    }
    return mul_ok(q, (int64_t)1 << k, &qs) && mul_ok(r, (int64_t)1 << k, &rs)
        && add_ok(rs, b, &num) && add_ok(rs, num, &num) && mul_ok(b, 2, &b2)
        && add_ok(qs, hdrg_floor_div(num, b2), &res);
}

/* ------------------------------------------------------------------ requests ------------- */

static int need_args(int ntok, int want, const char *usage)
{
    if (ntok != want) {
        err("SYNTAX", usage);
        return 0;
    }
    return 1;
}

static int parse_args(char **tok, int n, int64_t *vals, const char *usage)
{
    int i;
    for (i = 0; i < n; i++) {
        if (!parse_i64(tok[i], &vals[i])) {
            err("SYNTAX", usage);
            return 0;
        }
    }
    return 1;
}

/* The name of word `bad` of a refused table: "crc32" for the last word, the aux parameters of an
 * aux_gen 1 table by the names of Python's Table.param_names (aux_n_terms, aux_n_chan, aux_af_<c>,
 * aux_t<j>_<field>), any other by hdrg_word_name. */
static void word_name(const uint32_t *words, size_t n, unsigned bad, char *out)
{
    static const char *const TERM_FIELDS[HDRG_AUX_TERM_WORDS] = {
        "kind", "sign", "src", "power", "weight", "c0", "c1", "c2", "c3", "c4", "c5"};
    unsigned nf = (n > 1u && words[1] >= 2u) ? HDRG_N_FIXED : HDRG_N_FIXED_V1, rel, nc;
    if (n > 0 && bad == n - 1u) {
        strcpy(out, "crc32");
        return;
    }
    if (bad < nf || bad >= n) {
        strcpy(out, hdrg_word_name(bad));
        return;
    }
    rel = bad - nf;
    nc = n > nf + 1u ? words[nf + 1u] : 0u;
    if (rel == 0u) {
        strcpy(out, "aux_n_terms");
    } else if (rel == 1u) {
        strcpy(out, "aux_n_chan");
    } else if (nc > HDRG_AUX_MAX_CH) {
        strcpy(out, "aux_param");
    } else if (rel < 2u + nc) {
        sprintf(out, "aux_af_%u", rel - 2u);
    } else {
        rel -= 2u + nc;
        sprintf(out, "aux_t%u_%s", rel / HDRG_AUX_TERM_WORDS, TERM_FIELDS[rel % HDRG_AUX_TERM_WORDS]);
    }
}

static void load_table(const uint32_t *words, size_t n)
{
    unsigned bad = 0;
    int e;
    char name[48], detail[96];
    g_have_table = 0;
    g_run_kind = 0;
    e = hdrg_init(&g_st, words, n, &bad);
    if (e != HDRG_OK) {
        word_name(words, n, bad, name);
        sprintf(detail, "word %u %s", bad, name);
        err(hdrg_error_name(e), detail);
        return;
    }
    g_have_table = 1;
    printf("T %u %08" PRIx32 "\n", (unsigned)n, g_st.t.crc);
}

static void req_table(char **tok, int ntok)
{
    uint32_t words[MAX_TOKENS];
    int i;
    if (ntok == 2 && strcmp(tok[1], "BUILTIN") == 0) {
#ifdef HDRG_TABLE_HEADER
        load_table(HDRG_TABLE, HDRG_TABLE_WORDS);
#else
        g_have_table = 0;
        err("SYNTAX", "TABLE BUILTIN needs a build with -DHDRG_TABLE_HEADER");
#endif
        return;
    }
    for (i = 1; i < ntok; i++) {
        if (!parse_hex32(tok[i], &words[i - 1])) {
            g_have_table = 0;
            err("SYNTAX", "TABLE <hex word> ... (32-bit hex words)");
            return;
        }
    }
    load_table(words, (size_t)(ntok - 1));
}

/* validate and convert one sample's inputs (na = 6 .. 11 values: F T R MODE RESTART Z, then
 * optionally K and the aux words A0..A3, missing ones 0; without K the internal counter counts);
 * returns an error text or NULL */
static const char *make_input(const int64_t *a, int na, hdrg_input_t *in, hdrg_aux_input_t *ax)
{
    int c;
    if (a[0] < 0 || a[0] > 4294967295LL) return "F outside uint32";
    if (a[1] < INT32_MIN || a[1] > INT32_MAX) return "T outside int32";
    if (a[2] < INT32_MIN || a[2] > INT32_MAX) return "R outside int32";
    if (a[3] < -1 || a[3] > 3) return "MODE not in -1..3";
    if (a[4] < 0 || a[4] > 3) return "RESTART not 0..3 (bit 0 restart, bit 1 input-invalid)";
    if (a[5] < INT32_MIN || a[5] > INT32_MAX) return "Z outside int32";
    if (na > 6 && (a[6] > HDRG_K_LIMIT || a[6] < -HDRG_K_LIMIT)) return "K outside +-2^62";
    for (c = 7; c < na; c++) {
        if (a[c] < INT32_MIN || a[c] > INT32_MAX) return "A (aux word) outside int32";
    }
    in->f = (uint32_t)a[0];
    in->t = (int32_t)a[1];
    in->r = (int32_t)a[2];
    in->mode = (int8_t)a[3];
    in->restart = (uint8_t)(a[4] & 1);
    in->invalid = (uint8_t)((a[4] >> 1) & 1);
    in->z = (int32_t)a[5];
    ax->k_given = (uint8_t)(na > 6);
    ax->k = na > 6 ? a[6] : 0;
    for (c = 0; c < (int)HDRG_AUX_MAX_CH; c++) {
        ax->a[c] = 7 + c < na ? (int32_t)a[7 + c] : 0;
    }
    return NULL;
}

static const char *check_run_kind(const hdrg_input_t *in)
{
    int kind = in->mode < 0 ? 2 : 1;
    if (g_run_kind != 0 && g_run_kind != kind) {
        return "MODE -1 (self-timed) and logged modes mixed in one run (send RESET or TABLE)";
    }
    g_run_kind = kind;
    return NULL;
}

static void sample_fields(const hdrg_sample_t *o, int64_t *f)
{
    f[0] = o->state;
    f[1] = o->vs;
    f[2] = o->mode;
    f[3] = o->sign;
    f[4] = o->u;
    f[5] = o->v;
    f[6] = o->z;
    f[7] = o->s;
    f[8] = o->acc;
    f[9] = o->cnt;
    f[10] = o->y;
    f[11] = o->b;
    f[12] = o->out;
    f[13] = o->bias;
    f[14] = o->valid;
    f[15] = o->flags;
}

static void req_sample(char **tok, int ntok)
{
    static const char usage[] = "S <F> <T> <R> <MODE> <RESTART> <Z> [<K> [<A0> [<A1> [<A2> [<A3>]]]]]";
    int64_t a[REC_IN_AUX], f[REC_OUT];
    hdrg_input_t in;
    hdrg_aux_input_t ax;
    hdrg_sample_t o;
    const char *e;
    int i;
    if (ntok < 1 + REC_IN || ntok > 1 + REC_IN_AUX) {
        err("SYNTAX", usage);
        return;
    }
    if (!parse_args(tok + 1, ntok - 1, a, usage)) {
        return;
    }
    if (!g_have_table) {
        err("NOTABLE", "send TABLE first");
        return;
    }
    e = make_input(a, ntok - 1, &in, &ax);
    if (e == NULL) {
        e = check_run_kind(&in);
    }
    if (e != NULL) {
        err("RANGE", e);
        return;
    }
#ifdef HDRG_DRIVER_LEAN
    {   /* the firmware entry point: out, bias, valid, flags; acc, cnt, y from the state; the
         * other fields (intermediates) are not computed by it and answered 0 (compare with
         * check-impl --fields out,bias,valid,flags,acc,cnt,y) */
        hdrg_out_t r;
        hdrg_step_out(&g_st, &in, &ax, &r);
        memset(&o, 0, sizeof o);
        o.acc = g_st.acc;
        o.cnt = g_st.cnt;
        o.y = g_st.y_hold;
        o.out = r.out;
        o.bias = r.bias;
        o.valid = r.valid;
        o.flags = r.flags;
    }
#else
    hdrg_step_aux(&g_st, &in, &ax, &o);
#endif
    sample_fields(&o, f);
    fputs("O", stdout);
    for (i = 0; i < REC_OUT; i++) {
        printf(" %" PRId64, f[i]);
    }
    fputs("\n", stdout);
}

static void req_eval(char **tok, int ntok)
{
    static const char usage[] = "EVAL <U> <V> <Z> [<BANK>]";
    int64_t a[4] = {0, 0, 0, 1}, b;
    int zc = 0;
    if (ntok == 5) {
        if (!parse_args(tok + 1, 4, a, usage)) {
            return;
        }
        if (a[3] != 1 && a[3] != 2) {
            err("RANGE", "BANK must be 1 or 2");
            return;
        }
    } else if (!need_args(ntok, 4, usage) || !parse_args(tok + 1, 3, a, usage)) {
        return;
    }
    if (!g_have_table) {
        err("NOTABLE", "send TABLE first");
        return;
    }
    if (a[0] < -HDRG_ONE || a[0] > HDRG_ONE || a[1] < -HDRG_ONE || a[1] > HDRG_ONE) {
        err("RANGE", "U and V must be in [-2^30, 2^30]");
        return;
    }
    if (a[2] < INT32_MIN || a[2] > INT32_MAX) {
        err("RANGE", "Z outside int32");
        return;
    }
    b = hdrg_evaluate_bank(&g_st.t, (unsigned)a[3], (int32_t)a[0], (int32_t)a[1], (int32_t)a[2], &zc);
    printf("E %" PRId64 " %d\n", b, zc);
}

static void req_prim(const char *name, char **tok, int ntok)
{
    int64_t a[3], r = 0, t;
    int c = 0;
    if (strcmp(name, "RHU") == 0) {
        if (!need_args(ntok, 3, "RHU <X> <S>") || !parse_args(tok + 1, 2, a, "RHU <X> <S>")) return;
        if (!rhu_ok(a[0], a[1])) {
            err("RANGE", "RHU needs 0 <= S <= 62 and X + 2^(S-1) within int64");
            return;
        }
        printf("R %" PRId64 "\n", hdrg_rhu(a[0], (unsigned)a[1]));
    } else if (strcmp(name, "MULRHU") == 0) {
        if (!need_args(ntok, 4, "MULRHU <A> <B> <S>") || !parse_args(tok + 1, 3, a, "MULRHU <A> <B> <S>")) return;
        if (!mul_ok(a[0], a[1], &t) || !rhu_ok(t, a[2])) {
            err("RANGE", "MULRHU needs A B within int64 and RHU's preconditions");
            return;
        }
        printf("R %" PRId64 "\n", hdrg_mul_rhu(a[0], a[1], (unsigned)a[2]));
    } else if (strcmp(name, "FLOORDIV") == 0) {
        if (!need_args(ntok, 3, "FLOORDIV <A> <B>") || !parse_args(tok + 1, 2, a, "FLOORDIV <A> <B>")) return;
        if (a[1] <= 0) {
            err("RANGE", "FLOORDIV needs B > 0");
            return;
        }
        printf("R %" PRId64 "\n", hdrg_floor_div(a[0], a[1]));
    } else if (strcmp(name, "DIVROUND") == 0) {
        if (!need_args(ntok, 3, "DIVROUND <A> <B>") || !parse_args(tok + 1, 2, a, "DIVROUND <A> <B>")) return;
        if (a[1] <= 0 || !add_ok(a[0], a[1], &t) || !add_ok(a[0], t, &t) || !mul_ok(a[1], 2, &t)) {
            err("RANGE", "DIVROUND needs B > 0 and 2A + B, 2B within int64");
            return;
        }
        printf("R %" PRId64 "\n", hdrg_div_round(a[0], a[1]));
    } else if (strcmp(name, "DIVRS") == 0) {
        if (!need_args(ntok, 4, "DIVRS <A> <B> <K>") || !parse_args(tok + 1, 3, a, "DIVRS <A> <B> <K>")) return;
        if (!divrs_ok(a[0], a[1], a[2])) {
            err("RANGE", "DIVRS needs B > 0, 0 <= K <= 62 and every intermediate within int64");
            return;
        }
        printf("R %" PRId64 "\n", hdrg_div_round_scaled(a[0], a[1], (unsigned)a[2]));
    } else if (strcmp(name, "CLAMP") == 0) {
        if (!need_args(ntok, 4, "CLAMP <X> <LO> <HI>") || !parse_args(tok + 1, 3, a, "CLAMP <X> <LO> <HI>")) return;
        if (a[1] > a[2]) {
            err("RANGE", "CLAMP needs LO <= HI");
            return;
        }
        r = hdrg_clamp(a[0], a[1], a[2], &c);
        printf("R %" PRId64 " %d\n", r, c);
    } else if (strcmp(name, "RHUW") == 0) {
        if (!need_args(ntok, 4, "RHUW <A> <D> <S>") || !parse_args(tok + 1, 3, a, "RHUW <A> <D> <S>")) return;
        if (a[0] <= -P31 || a[0] >= P31 || a[1] < -P62 || a[1] > P62 || a[2] < 31 || a[2] > 62) {
            err("RANGE", "RHUW needs |A| < 2^31, |D| <= 2^62 and 31 <= S <= 62");
            return;
        }
        printf("R %" PRId64 "\n", hdrg_rhuw(a[0], a[1], (unsigned)a[2]));
    } else if (strcmp(name, "SIN") == 0) {
        if (!need_args(ntok, 2, "SIN <PHASE>") || !parse_args(tok + 1, 1, a, "SIN <PHASE>")) return;
        /* the uint64 phase given as the int64 of its bits: (uint64_t)a is a mod 2^64 */
        printf("R %" PRId32 "\n", hdrg_sin_q30((uint64_t)a[0]));
    } else { /* SAT */
        if (!need_args(ntok, 3, "SAT <X> <WIDTH>") || !parse_args(tok + 1, 2, a, "SAT <X> <WIDTH>")) return;
        if (a[1] < 1 || a[1] > 63) {
            err("RANGE", "SAT needs 1 <= WIDTH <= 63");
            return;
        }
        r = hdrg_sat_signed(a[0], (unsigned)a[1], &c);
        printf("R %" PRId64 " %d\n", r, c);
    }
}

static void req_crc(char **tok, int ntok)
{
    uint32_t words[MAX_TOKENS];
    int i;
    for (i = 1; i < ntok; i++) {
        if (!parse_hex32(tok[i], &words[i - 1])) {
            err("SYNTAX", "CRC <hex word> ...");
            return;
        }
    }
    printf("R %08" PRIx32 "\n", hdrg_crc32_words(words, (size_t)(ntok - 1)));
}

/* ------------------------------------------------------------------ binary blocks -------- */

static void read_record(hdrg_input_t *in, hdrg_aux_input_t *ax, int width, long long index)
{
    unsigned char buf[8 * REC_IN_AUX];
    int64_t a[REC_IN_AUX];
    const char *e;
    int i, j;
    char msg[160];
    if (fread(buf, 1, (size_t)(8 * width), stdin) != (size_t)(8 * width)) {
        sprintf(msg, "binary block truncated at record %lld", index);
        fatal(msg);
    }
    for (i = 0; i < width; i++) {
        uint64_t u = 0;
        for (j = 7; j >= 0; j--) {
            u = (u << 8) | buf[8 * i + j];
        }
        /* two's complement uint64 -> int64 without the implementation-defined cast */
        a[i] = u >= UINT64_C(0x8000000000000000) ? -(int64_t)(UINT64_C(0xFFFFFFFFFFFFFFFF) - u) - 1 : (int64_t)u;
    }
    e = make_input(a, width, in, ax);
    if (e == NULL) {
        e = check_run_kind(in);
    }
    if (e != NULL) {
        sprintf(msg, "binary record %lld: %s", index, e);
        fatal(msg);
    }
}

static void write_record(const hdrg_sample_t *o)
{
    unsigned char buf[8 * REC_OUT];
    int64_t f[REC_OUT];
    int i, j;
    sample_fields(o, f);
    for (i = 0; i < REC_OUT; i++) {
        uint64_t u = (uint64_t)f[i];
        for (j = 0; j < 8; j++) {
            buf[8 * i + j] = (unsigned char)(u >> (8 * j));
        }
    }
    if (fwrite(buf, 1, sizeof buf, stdout) != sizeof buf) {
        fatal("write failed");
    }
}

/* the header of a binary block: want - 1 counts, then an optional record width (6 or 11);
 * any error is fatal (the block's bytes follow on stdin); returns the width */
static int parse_count(char **tok, int ntok, int want, int64_t *a)
{
    int i;
    int64_t width = REC_IN;
    if (ntok != want && ntok != want + 1) {
        fatal(want == 2 ? "usage: BIN <N> [<WIDTH>]" : "usage: BENCH <N> <REPEATS> [<WIDTH>]");
    }
    for (i = 0; i < want - 1; i++) {
        if (!parse_i64(tok[i + 1], &a[i]) || a[i] < 0) {
            fatal("binary block: the count is not a non-negative integer");
        }
    }
    if (ntok == want + 1 && (!parse_i64(tok[want], &width) || (width != REC_IN && width != REC_IN_AUX))) {
        fatal("binary block: the record width must be 6 or 11");
    }
    if (!g_have_table) {
        fatal("binary block without a table");
    }
    return (int)width;
}

static void req_bin(char **tok, int ntok)
{
    int64_t a[1], i;
    hdrg_input_t in;
    hdrg_aux_input_t ax;
    hdrg_sample_t o;
    int width = parse_count(tok, ntok, 2, a);
    printf("BIN %" PRId64 "\n", a[0]);
    for (i = 0; i < a[0]; i++) {
        read_record(&in, &ax, width, (long long)i);
        hdrg_step_aux(&g_st, &in, &ax, &o);
        write_record(&o);
    }
}

static void req_bench(char **tok, int ntok)
{
    int64_t a[2], i, rep;
    hdrg_input_t *ins;
    hdrg_aux_input_t *axs;
    hdrg_sample_t o;
    uint64_t best = UINT64_MAX, sum = 0;
    int width = parse_count(tok, ntok, 3, a);
    ins = (hdrg_input_t *)malloc((size_t)(a[0] > 0 ? a[0] : 1) * sizeof *ins);
    axs = (hdrg_aux_input_t *)malloc((size_t)(a[0] > 0 ? a[0] : 1) * sizeof *axs);
    if (ins == NULL || axs == NULL) {
        fatal("out of memory");
    }
    for (i = 0; i < a[0]; i++) {
        read_record(&ins[i], &axs[i], width, (long long)i);
    }
    for (rep = 0; rep < (a[1] > 0 ? a[1] : 1); rep++) {
        clock_t t0, t1;
        uint64_t ns;
        hdrg_reset(&g_st);
        sum = 0;
        t0 = clock();
        for (i = 0; i < a[0]; i++) {
            hdrg_step_aux(&g_st, &ins[i], &axs[i], &o);
            sum += ((uint64_t)(uint32_t)o.out ^ ((uint64_t)(uint32_t)o.bias << 32)) + o.flags;
        }
        t1 = clock();
        ns = (uint64_t)(t1 - t0) * UINT64_C(1000000000) / (uint64_t)CLOCKS_PER_SEC;
        if (ns < best) {
            best = ns;
        }
    }
    free(ins);
    free(axs);
    hdrg_reset(&g_st);
    g_run_kind = 0;
    printf("BENCH %" PRId64 " %" PRIu64 " %016" PRIx64 "\n", a[0], best, sum);
}

/* ------------------------------------------------------------------ main loop ------------ */

int main(void)
{
    static char line[LINE_MAX_CHARS];
    char *tok[MAX_TOKENS + 1];
    static char stdout_buf[1 << 16];
    setvbuf(stdout, stdout_buf, _IOFBF, sizeof stdout_buf);
    while (fgets(line, sizeof line, stdin) != NULL) {
        int ntok = 0;
        char *p, *hash;
        size_t len = strlen(line);
        if (len > 0 && line[len - 1] != '\n' && !feof(stdin)) {
            int ch;
            while ((ch = getchar()) != EOF && ch != '\n') {
            }
            err("SYNTAX", "line longer than 8191 characters");
            continue;
        }
        hash = strchr(line, '#');
        if (hash != NULL) {
            *hash = '\0';
        }
        for (p = strtok(line, " \t\r\n"); p != NULL; p = strtok(NULL, " \t\r\n")) {
            if (ntok == MAX_TOKENS) {
                break;
            }
            tok[ntok++] = p;
        }
        if (p != NULL) {
            err("SYNTAX", "more than 300 fields");
            continue;
        }
        if (ntok == 0) {
            continue;
        }
        if (strcmp(tok[0], "S") == 0) {
            req_sample(tok, ntok);
        } else if (strcmp(tok[0], "TABLE") == 0) {
            req_table(tok, ntok);
        } else if (strcmp(tok[0], "RESET") == 0) {
            if (!need_args(ntok, 1, "RESET")) continue;
            if (!g_have_table) {
                err("NOTABLE", "send TABLE first");
                continue;
            }
            hdrg_reset(&g_st);
            g_run_kind = 0;
            puts("OK");
        } else if (strcmp(tok[0], "EVAL") == 0) {
            req_eval(tok, ntok);
        } else if (strcmp(tok[0], "RHU") == 0 || strcmp(tok[0], "MULRHU") == 0
                   || strcmp(tok[0], "FLOORDIV") == 0 || strcmp(tok[0], "DIVROUND") == 0
                   || strcmp(tok[0], "DIVRS") == 0 || strcmp(tok[0], "CLAMP") == 0
                   || strcmp(tok[0], "SAT") == 0 || strcmp(tok[0], "RHUW") == 0 || strcmp(tok[0], "SIN") == 0) {
            req_prim(tok[0], tok, ntok);
        } else if (strcmp(tok[0], "CRC") == 0) {
            req_crc(tok, ntok);
        } else if (strcmp(tok[0], "BIN") == 0) {
            req_bin(tok, ntok);
        } else if (strcmp(tok[0], "BENCH") == 0) {
            req_bench(tok, ntok);
        } else if (strcmp(tok[0], "QUIT") == 0) {
            break;
        } else {
            err("SYNTAX", "unknown request");
        }
    }
    if (fflush(stdout) != 0) {
        fatal("write failed");
    }
    return g_any_error ? 1 : 0;
}
