/* hdrg_soc_main.c - the firmware of hdrg_soc (vectors/hdl/hdrg_soc.v): the C twin (hdrg_fw.c,
 * unchanged) behind a word mailbox in the RAM that the host writes and reads through the SoC's
 * word port (docs/COST.md "iCE40 UP5K: the C twin on a RISC-V core").
 *
 * Mailbox (uint32 words at the start of the RAM, host word address = index):
 *   0..255   IN_TABLE  the table words (TABLE: n words, the count in IN_ARG[0])
 *   256..271 IN_ARG    a command's inputs:
 *            sample:  F, T, R, MODE (-1..3), RESTART (bit 0 restart, bit 1 input-invalid), Z,
 *                     K low, K high, K given (0/1), A0..A3
 *            eval:    U, V, Z, BANK (1 or 2)
 *   272..303 OUT       a command's results (word 0: the return code, HDRG_OK = 0):
 *            table:   rc, bad word, CRC word
 *            sample:  rc, state, vs, mode, sign, u, v, z, s (low, high), acc (low, high), cnt,
 *                     y (low, high), b (low, high), out, bias, valid, flags
 *            eval:    rc, B (low, high), z clamped
 * Return code SOC_NOTABLE: a sample or eval before a table was loaded (or after a refused one).
 * Command register (MMIO 0x20000, read): 0 none, 1 table, 2 sample, 3 eval (set by the host's
 * load / start / eval_start pulse); writing it (any value) reports the command done.  The mailbox is
 * plain memory that the host writes while the core polls the command register: a compiler barrier
 * after the poll and before the done keeps every mailbox access in between. */
#include <stdint.h>
#include "hdrg_fw.h"

#define MB_TABLE 0u
#define MB_ARG 256u
#define MB_OUT 272u
#define MB_WORDS 304u
#define SOC_CMD (*(volatile uint32_t *)0x20000u)
#define SOC_NOTABLE 255u
#define BARRIER() __asm__ volatile("" ::: "memory")

enum { CMD_NONE = 0, CMD_TABLE = 1, CMD_SAMPLE = 2, CMD_EVAL = 3 };

__attribute__((section(".mbox"), used)) uint32_t mbox[MB_WORDS];

static hdrg_state_t g_st;
static int g_have_table;

/* a freestanding build: GCC may call memcpy and memset for structure copies and clears */
void *memcpy(void *dst, const void *src, unsigned long n);
void *memset(void *dst, int c, unsigned long n);

void *memcpy(void *dst, const void *src, unsigned long n)
{
    unsigned char *d = dst;
    const unsigned char *s = src;
    while (n--) {
        *d++ = *s++;
    }
    return dst;
}

void *memset(void *dst, int c, unsigned long n)
{
    unsigned char *d = dst;
    while (n--) {
        *d++ = (unsigned char)c;
    }
    return dst;
}

static int64_t word64(uint32_t lo, uint32_t hi)
{
    return (int64_t)(((uint64_t)hi << 32) | lo);
}

static void put64(unsigned i, int64_t x)
{
    mbox[MB_OUT + i] = (uint32_t)(uint64_t)x;
    mbox[MB_OUT + i + 1u] = (uint32_t)((uint64_t)x >> 32);
}

static void cmd_table(void)
{
    unsigned bad = 0;
    uint32_t n = mbox[MB_ARG];
    int e = n > MB_ARG ? HDRG_ERR_LENGTH : hdrg_init(&g_st, &mbox[MB_TABLE], (size_t)n, &bad);
    g_have_table = e == HDRG_OK;
    mbox[MB_OUT] = (uint32_t)e;
    mbox[MB_OUT + 1u] = bad;
    mbox[MB_OUT + 2u] = g_st.t.crc;
}

static void cmd_sample(void)
{
    hdrg_input_t in;
    hdrg_aux_input_t ax;
    hdrg_sample_t o;
    const uint32_t *a = &mbox[MB_ARG];
    unsigned c;
    int e;
    if (!g_have_table) {
        mbox[MB_OUT] = SOC_NOTABLE;
        return;
    }
    in.f = a[0];
    in.t = (int32_t)a[1];
    in.r = (int32_t)a[2];
    in.mode = (int8_t)(int32_t)a[3];
    in.restart = (uint8_t)(a[4] & 1u);
    in.invalid = (uint8_t)((a[4] >> 1) & 1u);
    in.z = (int32_t)a[5];
    ax.k = word64(a[6], a[7]);
    ax.k_given = (uint8_t)(a[8] != 0u);
    for (c = 0; c < HDRG_AUX_MAX_CH; c++) {
        ax.a[c] = (int32_t)a[9u + c];
    }
    e = hdrg_step_aux(&g_st, &in, &ax, &o);
    mbox[MB_OUT] = (uint32_t)e;
    mbox[MB_OUT + 1u] = o.state;
    mbox[MB_OUT + 2u] = o.vs;
    mbox[MB_OUT + 3u] = o.mode;
    mbox[MB_OUT + 4u] = (uint32_t)(int32_t)o.sign;
    mbox[MB_OUT + 5u] = (uint32_t)o.u;
    mbox[MB_OUT + 6u] = (uint32_t)o.v;
    mbox[MB_OUT + 7u] = (uint32_t)o.z;
    put64(8u, o.s);
    put64(10u, o.acc);
    mbox[MB_OUT + 12u] = o.cnt;
    put64(13u, o.y);
    put64(15u, o.b);
    mbox[MB_OUT + 17u] = (uint32_t)o.out;
    mbox[MB_OUT + 18u] = (uint32_t)o.bias;
    mbox[MB_OUT + 19u] = o.valid;
    mbox[MB_OUT + 20u] = o.flags;
}

static void cmd_eval(void)
{
    const uint32_t *a = &mbox[MB_ARG];
    int zc = 0;
    int64_t b;
    if (!g_have_table) {
        mbox[MB_OUT] = SOC_NOTABLE;
        return;
    }
    b = hdrg_evaluate_bank(&g_st.t, a[3], (int32_t)a[0], (int32_t)a[1], (int32_t)a[2], &zc);
    mbox[MB_OUT] = HDRG_OK;
    put64(1u, b);
    mbox[MB_OUT + 3u] = (uint32_t)zc;
}

int main(void)
{
    SOC_CMD = CMD_NONE;                             /* the first done: booted */
    for (;;) {
        uint32_t c = SOC_CMD;
        BARRIER();
        if (c == CMD_TABLE) {
            cmd_table();
        } else if (c == CMD_SAMPLE) {
            cmd_sample();
        } else if (c == CMD_EVAL) {
            cmd_eval();
        } else {
            continue;
        }
        BARRIER();
        SOC_CMD = c;                                /* done */
    }
}
