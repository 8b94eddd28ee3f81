"""The fixed-point pipeline as one numba batch kernel over int64 arrays (cache=True).

Bit for bit the same algorithm as the Python-integer reference (firmware_ref.proxy, .rate,
.sequencer, .aux, .evaluator, .compensate) and the pseudo-code of FORMATS.md: every intermediate is an
int64 whose range the formats prove (no overflow checks here; the reference asserts them).

Batch organization (the per-sample results are unchanged by it): the samples are processed in
blocks of CHUNK; per block (1) the rate sums, read straight from the word array (the firmware's
ring of the last n + 1 words holds the same words within a segment), (2) pass A, the sequential
state of the timer (the mode of every sample), (2b) the aux generators of an aux_gen 1 table
(sequential: filter / decay states, the sample counter; firmware_ref.aux), (3) pass B, the
stateless u, v, z and B of the sample's bank (branch-free for one bank so LLVM vectorizes it:
products whose operands the formats bound to int32 are written as 32 x 32 -> 64 multiplies,
vpmuldq), (3b) pass A2, the sequential combiner (order 1 reads B: the residual r = c - B) and the
hold of y, (3c) the output words and flags, (4) pass C, the hold: invalid samples take the last
valid output words.

:func:`run_words` is the entry point: table + input words -> output words, valid, flags (and,
with ``detail``, u, v, B, y, state per sample).
"""
from __future__ import annotations

import numba
import numpy as np

from firmware_ref import formats as F
from firmware_ref.table import FIELD_INDEX as FI
from firmware_ref.terms import POLY_INDEX

_POLY = np.array(POLY_INDEX, np.int64)
_STATE_MODE = np.array(F.STATE_MODE, np.int64)

# field indices (compile-time constants for numba)
I_PREF, I_GU, I_UOFF, I_SHU = FI["p_ref"], FI["g_u"], FI["u_off"], FI["sh_u"]
I_EST, I_N, I_SHIFT, I_WARM = FI["rate_est"], FI["rate_n"], FI["rate_shift"], FI["rate_warmup"]
I_SB, I_GV, I_SHV = FI["s_bits"], FI["g_v"], FI["sh_v"]
I_COMB, I_SETTLE, I_STALE = FI["combiner"], FI["settle_n"], FI["max_stale_n"]
I_PON, I_EXCH, I_DWELL = FI["power_on_n"], FI["exchange_n"], FI["dwell_n"]
I_E0, I_E7, I_EACC, I_M0 = FI["e_0"], FI["e_7"], FI["e_acc"], FI["m_0"]
I2_E0, I2_E7, I2_EACC, I2_M0 = FI["e2_0"], FI["e2_7"], FI["e2_acc"], FI["m2_0"]
I_ORDER, I_NBANKS = FI["order"], FI["n_banks"]

_ONE = F.ONE
_Q = F.Q
_SIN = np.array(F.SIN_POLY, np.int64)
_KLIM = np.int64(F.K_LIMIT)


@numba.njit(cache=True, inline="always")
def _rshr(x, s):
    """Round-half-up arithmetic right shift (s >= 0)."""
    if s == 0:
        return x
    return (x + (np.int64(1) << (s - 1))) >> s


@numba.njit(cache=True, inline="always")
def _div_round_scaled(a, b, k):
    """RHU(a * 2^k / b), b > 0, via quotient and remainder (no a * 2^k)."""
    q = a // b
    r = a - q * b
    return q * (np.int64(1) << k) + (2 * (r << k) + b) // (2 * b)


@numba.njit(cache=True, inline="always")
def _mul32(a, b):
    """a * b for operands known to fit int32 (the formats prove it): a 32x32 -> 64 product,
    which LLVM vectorizes (vpmuldq)."""
    return np.int64(np.int32(a)) * np.int64(np.int32(b))


@numba.njit(cache=True, inline="always")
def _rhu_wide(a, d, s):
    """RHU(a * d, s) for |a| < 2^31, |d| <= 2^62, 31 <= s <= 62 (arith.mul_rshift_round_wide):
    d = dh 2^31 + dl, 0 <= dl < 2^31."""
    dh = d >> 31
    dl = d - dh * (np.int64(1) << 31)
    return (a * dh + ((a * dl + (np.int64(1) << (s - 1))) >> 31)) >> (s - 31)


@numba.njit(cache=True)
def _sin_q30(ph):
    """firmware_ref.aux.sin_q30 of the uint64 phase held as int64 bits."""
    one = np.int64(_ONE)
    h = np.int64(1) << 29
    quad = (ph >> 62) & 3
    r = ((ph >> 32) & (one - 1)) + ((ph >> 31) & 1)
    x = one - r if quad & 1 else r
    x2 = (x * x + h) >> 30
    p = _SIN[5]
    for i in range(4, -1, -1):
        p = ((p * x2 + h) >> 30) + _SIN[i]
    sv = min((p * x + h) >> 30, one)
    return -sv if quad >= 2 else sv


@numba.njit(cache=True)
def _aux_pass(terms, ch, kin, has_k, kc, c0, m_blk, restart, a_m, a_sraw, a_w, ystate, exst, zgen, bad):
    """The aux_gen 1 generators (firmware_ref.aux) over one block: the raw sum RHU(acc, 30) of
    every sample into zgen (pass B clamps it and sets flag 32); returns the internal counter.
    exst[nt] is the stage's PEND bit (a restart on an input-invalid sample)."""
    one = np.int64(_ONE)
    h = np.int64(1) << 29
    s_one = np.int64(1) << 60
    nt = terms.shape[0]
    for jb in range(m_blk):
        i = c0 + jb
        kk = kin[i] if has_k else kc
        kc = min(kk + 1, _KLIM)
        if kk < 0:
            kk = np.int64(0)
        ars = restart[i] != 0 or i == 0
        inv = bad[i] != 0
        irs = ars or exst[nt] != 0                     # the input filters' restart (PEND included)
        exst[nt] = 1 if (inv and irs) else 0
        m = a_m[jb]
        sm = np.int64(1) if m <= 1 else (np.int64(-1) if m == 2 else np.int64(0))
        acc = np.int64(0)
        for j in range(nt):
            kind = terms[j, 0]
            g = np.int64(0)
            if kind == 0:                                  # input
                dx = min(max(ch[terms[j, 2], i] - terms[j, 5], -2147483647), 2147483647)
                sh = terms[j, 8]
                q = dx * terms[j, 6] + terms[j, 7]
                if sh > 0:
                    q = (q + (np.int64(1) << (sh - 1))) >> sh
                q = min(max(q, -one), one)
                if terms[j, 10] == 0:
                    y = q
                else:
                    if inv:                                # held over an input-invalid sample
                        if irs:
                            ystate[j] = 0
                    elif irs:
                        ystate[j] = q << 30
                    else:
                        ystate[j] += _rhu_wide(terms[j, 9], (q << 30) - ystate[j], terms[j, 10])
                    y = (ystate[j] + h) >> 30
                g = y
                for _ in range(terms[j, 3] - 1):
                    g = (g * y + h) >> 30
            elif kind == 1:                                # rate
                if (a_w[jb] & 4) == 0:
                    lim = (np.int64(1) << terms[j, 5]) - 1
                    sc = min(max(a_sraw[jb], -lim), lim)
                    sh = terms[j, 7]
                    g = sc * terms[j, 6]
                    if sh > 0:
                        g = (g + (np.int64(1) << (sh - 1))) >> sh
                    g = min(max(g, -one), one)
            elif kind == 2:                                # one
                g = one
            elif kind == 3:                                # decay_on
                if ars:
                    ystate[j] = s_one
                else:
                    ystate[j] += _rhu_wide(terms[j, 5], -ystate[j], terms[j, 6])
                g = (ystate[j] + h) >> 30
            elif kind == 4:                                # decay_exchange
                if ars:
                    ystate[j] = 0
                    exst[j] = 0
                if m == 3:
                    ystate[j] = 0
                    exst[j] = 1
                elif exst[j] != 0:
                    ystate[j] = s_one
                    exst[j] = 0
                else:
                    ystate[j] += _rhu_wide(terms[j, 5], -ystate[j], terms[j, 6])
                g = (ystate[j] + h) >> 30
            elif kind == 5:                                # ramp
                if kk >= terms[j, 5]:
                    g = one
                else:
                    sh = terms[j, 7]
                    g = kk * terms[j, 6]
                    if sh > 0:
                        g = (g + (np.int64(1) << (sh - 1))) >> sh
            else:                                          # osc: the phase wraps mod 2^64
                g = _sin_q30(kk * terms[j, 5] + terms[j, 7] * (np.int64(1) << 62))
            if terms[j, 1] != 0:
                g = sm * g
            acc += terms[j, 4] * g
        zgen[jb] = (acc + h) >> 30
    return kc


@numba.njit(cache=True)
def _eval_consts(cfg, bank2=False):
    """The evaluator's constants of bank 1 (or bank 2) from the table, as one int64 tuple: c[i][j]
    (16, row-major), row alignment shifts s_i and their rounding halves h_i, m_7, its shift and
    half, the final B shift, its half and whether it is a left shift (E < 21)."""
    ie0, ie7, ieacc, im0 = (I2_E0, I2_E7, I2_EACC, I2_M0) if bank2 else (I_E0, I_E7, I_EACC, I_M0)
    e_acc = cfg[ieacc]
    c = np.empty(16, np.int64)
    for i in range(4):
        for j in range(4):
            c[4 * i + j] = cfg[im0 + _POLY[i, j]]
    s0 = cfg[ie0] - e_acc
    s1 = cfg[ie0 + 1] - e_acc
    s2 = cfg[ie0 + 2] - e_acc
    s3 = cfg[ie0 + 3] - e_acc
    sh7 = _Q + cfg[ie7] - e_acc
    left = 1 if e_acc < F.Y_FRAC else 0
    b_sh = F.Y_FRAC - e_acc if left else e_acc - F.Y_FRAC
    hb = 0 if left else (np.int64(1) << b_sh) >> 1
    one = np.int64(1)
    return (c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], c[11], c[12], c[13], c[14], c[15],
            s0, s1, s2, s3, (one << s0) >> 1, (one << s1) >> 1, (one << s2) >> 1, (one << s3) >> 1,
            cfg[im0 + 7], sh7, (one << sh7) >> 1, np.int64(b_sh), np.int64(hb), np.int64(left))


@numba.njit(cache=True, inline="always")
def _bias(co, uu, vv, zz):
    """B (int64, LSB 2^-21 deg/h) by the Horner scheme of firmware_ref.evaluator; u, v, z are
    Q1.30 words already clamped to [-2^30, 2^30].  Branch-free, so the block loop vectorizes."""
    hq = np.int64(1) << 29
    q3 = ((_mul32(((_mul32(((_mul32(co[15], vv) + hq) >> 30) + co[14], vv) + hq) >> 30) + co[13], vv) + hq) >> 30) + co[12]
    q2 = ((_mul32(((_mul32(((_mul32(co[11], vv) + hq) >> 30) + co[10], vv) + hq) >> 30) + co[9], vv) + hq) >> 30) + co[8]
    q1 = ((_mul32(((_mul32(((_mul32(co[7], vv) + hq) >> 30) + co[6], vv) + hq) >> 30) + co[5], vv) + hq) >> 30) + co[4]
    q0 = ((_mul32(((_mul32(((_mul32(co[3], vv) + hq) >> 30) + co[2], vv) + hq) >> 30) + co[1], vv) + hq) >> 30) + co[0]
    t = ((_mul32((q3 + co[23]) >> co[19], uu) + hq) >> 30) + ((q2 + co[22]) >> co[18])
    t = ((_mul32(t, uu) + hq) >> 30) + ((q1 + co[21]) >> co[17])
    t = ((_mul32(t, uu) + hq) >> 30) + ((q0 + co[20]) >> co[16])
    t += (_mul32(co[24], zz) + co[26]) >> co[25]
    if co[29]:
        return t << co[27]
    return (t + co[28]) >> co[27]


@numba.njit(cache=True)
def _eval_kernel(cfg, u, v, z, out, bank2):
    co = _eval_consts(cfg, bank2)
    one = np.int64(_ONE)
    for i in range(u.shape[0]):
        out[i] = _bias(co, u[i], v[i], min(max(z[i], -one), one))


CHUNK = 1024  # samples per block


@numba.njit(cache=True)
def _pass_b(co, co2, two, pb, p_ref, g_u, u_off, sh_u, a_s, g_v, sh_v, zb, a_m, a_b, a_fb):
    """Stateless part of a block, branch-free so LLVM vectorizes it (one-bank tables): u, v (from
    the clamped rate sum), z, B (bank 2 on mode-2 samples of a two-bank table, ``two``) and their
    flags (1 u clamped | 2 v clamped | 32 z clamped)."""
    if two:
        _uvzb_two(co, co2, pb, p_ref, g_u, u_off, sh_u, a_s, g_v, sh_v, zb, a_m, a_b, a_fb)
    else:
        _uvzb_one(co, pb, p_ref, g_u, u_off, sh_u, a_s, g_v, sh_v, zb, a_b, a_fb)


@numba.njit(cache=True, inline="always")
def _uvz(pb, p_ref, g_u, u_off, h_u, sh_u, s, g_v, h_v, sh_v, zz):
    """Clamped u, v, z and their flags (1 u, 2 v, 32 z) of one sample."""
    one = np.int64(_ONE)
    lim32 = np.int64(2147483647)
    dp = min(max(np.int64(pb) - p_ref, -lim32), lim32)
    uu = (_mul32(dp, g_u) + u_off + h_u) >> sh_u
    f = np.uint8((uu > one) | (uu < -one))
    uu = min(max(uu, -one), one)
    vv = (s * g_v + h_v) >> sh_v
    f |= np.uint8((vv > one) | (vv < -one)) << 1
    vv = min(max(vv, -one), one)
    f |= np.uint8((zz > one) | (zz < -one)) << 5
    zz = min(max(zz, -one), one)
    return uu, vv, zz, f


@numba.njit(cache=True)
def _uvzb_one(co, pb, p_ref, g_u, u_off, sh_u, a_s, g_v, sh_v, zb, a_b, a_fb):
    h_u = (np.int64(1) << sh_u) >> 1
    h_v = (np.int64(1) << sh_v) >> 1
    for jb in range(a_s.shape[0]):
        uu, vv, zz, f = _uvz(pb[jb], p_ref, g_u, u_off, h_u, sh_u, a_s[jb], g_v, h_v, sh_v, zb[jb])
        a_b[jb] = _bias(co, uu, vv, zz)
        a_fb[jb] = f


@numba.njit(cache=True)
def _uvzb_two(co, co2, pb, p_ref, g_u, u_off, sh_u, a_s, g_v, sh_v, zb, a_m, a_b, a_fb):
    h_u = (np.int64(1) << sh_u) >> 1
    h_v = (np.int64(1) << sh_v) >> 1
    for jb in range(a_s.shape[0]):
        uu, vv, zz, f = _uvz(pb[jb], p_ref, g_u, u_off, h_u, sh_u, a_s[jb], g_v, h_v, sh_v, zb[jb])
        if a_m[jb] == 2:
            a_b[jb] = _bias(co2, uu, vv, zz)
        else:
            a_b[jb] = _bias(co, uu, vv, zz)
        a_fb[jb] = f


@numba.njit(cache=True)
def _pass_out(order, a_y, a_b, a_fb, a_f, a_ok, out, bias, flags):
    """The OUT/BIAS words (candidates: pass C replaces them by the held values on invalid samples)
    and the flags (pass A's | pass B's | 128 OUT or BIAS saturated on a valid sample).  OUT =
    RHU(y - B, 11) (order 0) or RHU(y, 11) (order 1: y holds r = c - B already)."""
    lim32 = np.int64(2147483647)
    keep_b = np.int64(1) if order == 0 else np.int64(0)
    for jb in range(a_y.shape[0]):
        b = a_b[jb]
        ow = (a_y[jb] - keep_b * b + 1024) >> 11
        bw = (b + 1024) >> 11
        sat = (ow > lim32) | (ow < -lim32) | (bw > lim32) | (bw < -lim32)
        out[jb] = np.int32(min(max(ow, -lim32), lim32))
        bias[jb] = np.int32(min(max(bw, -lim32), lim32))
        flags[jb] = a_fb[jb] | a_f[jb] | (np.uint8(sat & (a_ok[jb] != 0)) << 7)


@numba.njit(cache=True)
def _kernel(cfg, p, r, mode_in, restart, z, has_z, self_timed, detail,
            out, bias, valid, flags, u_o, v_o, b_o, y_o, st_o, s_o, terms, ch, kin, has_k, z_o, bad):
    n = p.shape[0]
    one = np.int64(_ONE)
    nt = terms.shape[0]
    # -- table fields
    p_ref = cfg[I_PREF]
    g_u = cfg[I_GU]
    u_off = cfg[I_UOFF]
    sh_u = cfg[I_SHU]
    est = cfg[I_EST]
    nn = cfg[I_N]
    if est == 0 or est == 3:
        nn = 1
    rshift = cfg[I_SHIFT]
    warm_n = cfg[I_WARM]
    s_lim = (np.int64(1) << cfg[I_SB]) - 1
    g_v = cfg[I_GV]
    sh_v = cfg[I_SHV]
    comb = cfg[I_COMB]
    settle_n = cfg[I_SETTLE]
    max_stale = cfg[I_STALE]
    lens = np.empty(6, np.int64)
    lens[0] = cfg[I_PON]
    lens[1] = cfg[I_EXCH]
    lens[2] = cfg[I_DWELL]
    lens[3] = cfg[I_EXCH]
    lens[4] = cfg[I_DWELL]
    lens[5] = -1
    co = _eval_consts(cfg, False)
    two = cfg[I_NBANKS] == 2
    co2 = _eval_consts(cfg, two)
    order = cfg[I_ORDER]
    # -- state (per-mode combiner state in scalars: index 1 and 2)
    seg = 0
    iy = np.int64(0)
    t_state = 0
    t_cnt = 0
    cur = 0
    acc = np.int64(0)
    cnt = np.int64(0)
    nc1 = 0
    nc2 = 0
    w1 = np.int64(0)
    w2 = np.int64(0)
    sp1 = np.int64(0)
    sp2 = np.int64(0)
    e1 = np.int64(0)
    e2 = np.int64(0)
    sl1 = np.int64(0)
    sl2 = np.int64(0)
    sgn = np.int64(1)
    have_o = False
    other0 = np.int64(0)
    sl_o = np.int64(0)
    e_o = np.int64(0)
    sp_o = np.int64(0)
    used_from = np.int64(0)
    y_hold = np.int64(0)
    out_hold = np.int32(0)
    bias_hold = np.int32(0)
    last_window = 0
    taint = False                      # the open window held an input-invalid sample
    # -- block scratch
    a_s = np.empty(CHUNK, np.int64)    # clamped rate sum (0 in warm-up)
    a_w = np.empty(CHUNK, np.uint8)    # flags 4 warm-up, 2 rate sum clamped
    a_k = np.empty(CHUNK, np.int64)    # samples since the segment start
    a_y = np.empty(CHUNK, np.int64)    # combined output y (held)
    a_f = np.empty(CHUNK, np.uint8)    # pass-A flags
    a_m = np.empty(CHUNK, np.int64)    # mode of each sample (logged or the timer's)
    a_sraw = np.empty(CHUNK, np.int64)  # rate sum before its clamp (aux rate terms)
    zgen = np.empty(CHUNK, np.int64)   # generated z before its clamp (aux_gen 1)
    a_b = np.empty(CHUNK, np.int64)    # B of the sample's bank
    a_fb = np.empty(CHUNK, np.uint8)   # pass-B flags (1, 2, 32)
    ystate = np.zeros(max(nt, 1), np.int64)
    exst = np.zeros(nt + 1, np.int64)  # exchange flags; [nt]: the PEND bit
    kc = np.int64(0)
    zero_z = np.zeros(CHUNK, np.int64)
    for c0 in range(0, n, CHUNK):
        m_blk = min(CHUNK, n - c0)
        # ---------------- rate estimator sums, read straight from the word array (the firmware
        # keeps the last n + 1 words in a ring; within a segment both read the same words)
        for jb in range(m_blk):                      # restarts: segment, invalid sample and the one after
            i = c0 + jb
            if restart[i] != 0 or bad[i] != 0 or (i > 0 and bad[i - 1] != 0):
                seg = i
            a_k[jb] = c0 + jb - seg                  # samples since the segment start
        if est <= 1:
            for jb in range(m_blk):
                i = c0 + jb
                a_s[jb] = np.int64(p[i]) - p[i - nn] if a_k[jb] >= nn else np.int64(0)
        elif est == 2:
            for jb in range(m_blk):
                i = c0 + jb
                s = np.int64(0)
                if a_k[jb] >= nn - 1:
                    pi = np.int64(p[i])
                    for jj in range(nn):
                        s += (2 * jj - (nn - 1)) * (np.int64(p[i - nn + 1 + jj]) - pi)
                a_s[jb] = s
        else:
            for jb in range(m_blk):
                i = c0 + jb
                kk = a_k[jb]
                if kk == 0:
                    iy = np.int64(0)
                else:
                    e = rshift                       # the gear min(shift, floor(log2 k)); 0 at k = 1
                    if kk < (np.int64(1) << rshift):
                        e = 0
                        while (kk >> (e + 1)) != 0:
                            e += 1
                    iy += _rshr(((np.int64(p[i]) - p[i - 1]) << 24) - iy, e)
                a_s[jb] = iy
        if detail:
            for jb in range(m_blk):
                s_o[c0 + jb] = a_s[jb]
        if nt > 0:
            for jb in range(m_blk):
                a_sraw[jb] = a_s[jb]
        for jb in range(m_blk):
            sv = a_s[jb]
            w = np.uint8(a_k[jb] < warm_n)
            c = np.uint8((sv > s_lim) | (sv < -s_lim)) & (w ^ 1)
            a_w[jb] = (w << 2) | (c << 1)            # the warm-up (4) and rate-clamp (2) flags
            a_s[jb] = 0 if w else min(max(sv, -s_lim), s_lim)
        # ---------------- pass A1: the sequencer state of every sample (timer or logged mode)
        for jb in range(m_blk):
            i = c0 + jb
            if self_timed:
                if restart[i] != 0:
                    t_state = 0
                    t_cnt = 0
                for _ in range(3):
                    if t_state == 5 or t_cnt < lens[t_state]:
                        break
                    if t_state == 0:
                        t_state = 5 if comb == 0 else 1
                    elif t_state == 4:
                        t_state = 1
                    else:
                        t_state += 1
                    t_cnt = 0
                if t_state != 5:
                    t_cnt += 1
                m = _STATE_MODE[t_state]
            else:
                m = np.int64(mode_in[i])
            if detail:
                if self_timed:
                    st_o[i] = t_state
                elif m == 0:
                    st_o[i] = 5
                elif m == 1:
                    st_o[i] = 2
                elif m == 2:
                    st_o[i] = 4
                elif last_window == 1:
                    st_o[i] = 3
                else:
                    st_o[i] = 1
            if comb != 0 and (m == 1 or m == 2):
                last_window = m                      # the combiner's last window (state of mode 3)
            a_m[jb] = m
        # ---------------- aux generators (aux_gen 1): sequential, z before its clamp
        if nt > 0:
            kc = _aux_pass(terms, ch, kin, has_k, kc, c0, m_blk, restart, a_m, a_sraw, a_w, ystate, exst, zgen,
                           bad)
            zb = zgen[:m_blk]
        else:
            zb = z[c0:c0 + m_blk] if has_z else zero_z[:m_blk]
        # ---------------- pass B: stateless, vectorized: u, v, z, B of the sample's bank
        _pass_b(co, co2, two, p[c0:c0 + m_blk], p_ref, g_u, u_off, sh_u, a_s[:m_blk], g_v, sh_v, zb, a_m[:m_blk],
                a_b[:m_blk], a_fb[:m_blk])
        # ---------------- pass A2: sequential combiner (order 1: on the residual r = c - B)
        for jb in range(m_blk):
            i = c0 + jb
            rs = restart[i] != 0
            m = a_m[jb]
            fl = a_w[jb]
            warm = (fl & 4) != 0
            inv = bad[i] != 0
            if inv:
                fl |= 64
            cvalid = False
            if comb == 0:
                y_hold = np.int64(r[i]) << 11
                cvalid = True
            else:
                # ages as differences of sample indices (int64: no wrap in a batch), saturated
                # like the reference's counters: age_o = min(i - end_o, 2^31 - 1)
                if rs or m != cur:
                    if rs:
                        cur = 0
                        cnt = np.int64(0)
                        nc1 = 0
                        nc2 = 0
                        sl1 = np.int64(0)
                        sl2 = np.int64(0)
                    if cur != 0 and cnt >= 1 and not taint:
                        mean = _div_round_scaled(acc, cnt, 10)
                        sp = cnt - 1
                        if cur == 1:
                            if nc1 >= 1:
                                sl1 = _div_round_scaled(mean - w1, 2 * (min(i - e1, 2147483647) - 1) - sp + sp1, 16)
                                if sl1 > 1099511627775 or sl1 < -1099511627775:
                                    sl1 = min(max(sl1, -1099511627775), 1099511627775)
                                    fl |= 128
                            w1 = mean
                            sp1 = sp
                            e1 = i - 1
                            nc1 = min(nc1 + 1, 2)
                        else:
                            if nc2 >= 1:
                                sl2 = _div_round_scaled(mean - w2, 2 * (min(i - e2, 2147483647) - 1) - sp + sp2, 16)
                                if sl2 > 1099511627775 or sl2 < -1099511627775:
                                    sl2 = min(max(sl2, -1099511627775), 1099511627775)
                                    fl |= 128
                            w2 = mean
                            sp2 = sp
                            e2 = i - 1
                            nc2 = min(nc2 + 1, 2)
                    if m == 1 or m == 2:
                        cur = m
                        # this window's constants: sign, the other mode's state
                        sgn = np.int64(1) if m == 1 else np.int64(-1)
                        if m == 1:
                            have_o, other0, sl_o, e_o, sp_o = nc2 >= 1, w2, sl2, e2, sp2
                        else:
                            have_o, other0, sl_o, e_o, sp_o = nc1 >= 1, w1, sl1, e1, sp1
                        used_from = i + settle_n
                    else:
                        cur = 0
                    acc = np.int64(0)
                    cnt = np.int64(0)
                    taint = False
                taint = taint or (cur != 0 and inv)
                if cur != 0 and i >= used_from and not inv and not (order == 1 and warm):
                    c = sgn * r[i]
                    if order == 1:
                        c = ((c << 11) - a_b[jb] + 1024) >> 11        # r = c - B, LSB 2^-10 deg/h
                        if c > 2147483647 or c < -2147483647:
                            c = min(max(c, np.int64(-2147483647)), np.int64(2147483647))
                            fl |= 128
                    if cnt < 2147483647:
                        acc += c
                        cnt += 1
                    else:
                        fl |= 128
                    if comb == 3:
                        y_hold = c << 11
                        cvalid = True
                    else:
                        ag_o = min(i - e_o, 2147483647)
                        if have_o and ag_o <= max_stale:
                            other = other0
                            if comb == 2:
                                d = 2 * ag_o + sp_o
                                if d > 4194303:
                                    d = np.int64(4194303)
                                    fl |= 128
                                other += _rshr(sl_o * d, 16)
                            y_hold = (c << 10) + other
                            cvalid = True
            if m == 3:
                fl |= 8
            elif not cvalid:
                fl |= 16
            a_y[jb] = y_hold
            a_f[jb] = fl
            valid[i] = 1 if (cvalid and not warm and m != 3 and not inv) else 0
        # ---------------- output words and flags
        _pass_out(order, a_y[:m_blk], a_b[:m_blk], a_fb[:m_blk], a_f[:m_blk], valid[c0:c0 + m_blk],
                  out[c0:c0 + m_blk], bias[c0:c0 + m_blk], flags[c0:c0 + m_blk])
        if detail:
            h_u = (np.int64(1) << sh_u) >> 1
            h_v = (np.int64(1) << sh_v) >> 1
            for jb in range(m_blk):
                i = c0 + jb
                dp = min(max(np.int64(p[i]) - p_ref, -2147483647), 2147483647)
                uu = min(max((dp * g_u + u_off + h_u) >> sh_u, -one), one)
                vv = min(max((a_s[jb] * g_v + h_v) >> sh_v, -one), one)
                u_o[i] = uu
                v_o[i] = vv
                z_o[i] = min(max(zb[jb], -one), one)
                b_o[i] = a_b[jb]
                y_o[i] = a_y[jb]
        # ---------------- pass C: invalid samples hold the last valid output words
        for jb in range(m_blk):
            i = c0 + jb
            if valid[i]:
                out_hold = out[i]
                bias_hold = bias[i]
            else:
                out[i] = out_hold
                bias[i] = bias_hold


def run_words(table, p, r, mode=None, restart=None, z=None, self_timed: bool = False,
              detail: bool = False, f=None, t=None, aux=None, k=None, invalid=None) -> dict:
    """Run the kernel.  ``p`` proxy words, ``r`` rate words (int64[n]); ``mode`` 0..3 (int8[n]
    preferred; ignored and optional when ``self_timed``); ``restart`` bool/int[n] (default: only sample 0 restarts,
    which is the power-on state anyway); ``z`` Q1.30 words (default 0; aux_gen 0 only).  An aux_gen 1
    table reads the channel words of its input terms: ``f`` (F words; default ``p`` for a freq
    table), ``t`` (T words; default ``p`` for a temp table), ``aux`` (int64[n, n_chan], A_c words)
    and the counter ``k`` (int64[n], K since power-on, |K| <= 2^62; default 0, 1, 2, ...).  Returns
    a dict of arrays: ``out``, ``bias`` (int32 words, LSB 2^-10 deg/h), ``valid`` (uint8), ``flags``
    (uint8) and with ``detail`` also ``u``, ``v``, ``z`` (Q1.30, z clamped), ``b``, ``y`` (LSB
    2^-21 deg/h), ``state`` and ``s`` (the rate estimator's sum before its clamp).  ``invalid``:
    the input-invalid bits (bool/int[n], default none; FORMATS.md "The input-invalid bit")."""
    from firmware_ref.aux import channel_rows

    p = np.ascontiguousarray(p, np.int64)
    n = p.shape[0]
    r = np.ascontiguousarray(r, np.int64)
    if r.shape != (n,):
        raise ValueError(f"rate words: shape {r.shape}, expected ({n},)")
    if mode is None:
        if not self_timed:
            raise ValueError("mode is required unless self_timed")
        mode = np.zeros(n, np.int8)
    mode = np.asarray(mode)
    if mode.dtype != np.int8:
        if mode.size and (mode.min() < 0 or mode.max() > 3):
            raise ValueError("mode values must be 0..3")
        mode = mode.astype(np.int8)
    mode = np.ascontiguousarray(mode)
    restart = np.zeros(n, np.uint8) if restart is None else np.ascontiguousarray(restart, np.uint8)
    bad = np.zeros(n, np.uint8) if invalid is None else np.ascontiguousarray(invalid, np.uint8)
    has_z = z is not None
    z = np.zeros(1, np.int64) if z is None else np.ascontiguousarray(z, np.int64)
    for name, arr in (("mode", mode), ("restart", restart), ("invalid", bad)) + ((("z", z),) if has_z else ()):
        if arr.shape != (n,):
            raise ValueError(f"{name}: shape {arr.shape}, expected ({n},)")
    terms = table.aux_array()
    if terms.shape[0]:
        ch = np.ascontiguousarray(np.stack(channel_rows(table, n, p, f, t, aux)))
    else:
        ch = np.zeros((1, 1), np.int64)
    has_k = k is not None
    kin = np.ascontiguousarray(k, np.int64) if has_k else np.zeros(1, np.int64)
    if has_k:
        if kin.shape != (n,):
            raise ValueError(f"k: shape {kin.shape}, expected ({n},)")
        if n and int(np.max(np.abs(kin))) > F.K_LIMIT:
            raise ValueError("k: the sample counter must be within +-2^62")
    res = {"out": np.empty(n, np.int32), "bias": np.empty(n, np.int32), "valid": np.empty(n, np.uint8),
           "flags": np.empty(n, np.uint8)}
    m = n if detail else 1
    names = ("u", "v", "z", "b", "y", "state", "s")
    for name in names:
        res[name] = np.zeros(m, np.int64)
    _kernel(table.config_array(), p, r, mode, restart, z, has_z, bool(self_timed), bool(detail), res["out"], res["bias"],
            res["valid"], res["flags"], res["u"], res["v"], res["b"], res["y"], res["state"], res["s"],
            terms, ch, kin, has_k, res["z"], bad)
    if not detail:
        for name in names:
            del res[name]
    return res


def evaluate_words(table, u, v, z=None, bank: int = 1) -> np.ndarray:
    """B (int64, LSB 2^-21 deg/h) of coefficient ``bank`` (1, 2) at Q1.30 words u, v (|.| <=
    2^30) and z (clamped), by the kernel's evaluator."""
    u = np.ascontiguousarray(u, np.int64)
    v = np.ascontiguousarray(v, np.int64)
    z = np.zeros_like(u) if z is None else np.ascontiguousarray(z, np.int64)
    if not (u.shape == v.shape == z.shape) or u.ndim != 1:
        raise ValueError("u, v, z must be 1-D arrays of one length")
    if np.any(np.abs(u) > F.ONE) or np.any(np.abs(v) > F.ONE):
        raise ValueError("u and v must be in [-2^30, 2^30] (the pipeline clamps them)")
    out = np.empty(u.shape[0], np.int64)
    if bank not in (1, 2) or (bank == 2 and table.n_banks != 2):
        raise ValueError(f"bank {bank}: the table has {table.n_banks} bank(s)")
    _eval_kernel(table.config_array(), u, v, z, out, bank == 2)
    return out
