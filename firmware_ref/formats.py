"""Every fixed-point signal of the firmware reference: the one module that the code and the docs
(firmware_ref/FORMATS.md) share.

The constants below are used by the Python reference, the numba kernel, the quantizer and the
table layout; firmware_ref.docgen renders the tables of FORMATS.md from them (the generated
blocks between ``<!-- BEGIN name -->`` and ``<!-- END name -->``; ``python -m
firmware_ref.docgen --update`` rewrites them, tests/test_fixed_formats.py checks they agree).

Conventions: ``Qm.f`` is a signed word with f fractional bits; "LSB" is the value of one unit;
**RHU** is round-half-up by add-then-arithmetic-shift, ``(x + 2**(s-1)) >> s`` (apytypes
``QuantizationMode.TIES_POS``; ARM SMMULR rounds the same way); **sym-sat** is symmetric
saturation ``[-(2**(w-1) - 1), 2**(w-1) - 1]`` (so negation never overflows).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

# the stage vocabulary (names and codes) is declared once, in firmware_ref.vocabulary; re-exported here
from firmware_ref.vocabulary import (AUX_GENERATORS, AUX_KINDS, COMBINERS, ESTIMATORS, FLAG_AUX_CLAMPED,  # noqa: F401
                                     FLAG_EXCHANGE, FLAG_INPUT_SAT, FLAG_PROXY_CLAMPED, FLAG_RATE_CLAMPED,
                                     FLAG_SAT, FLAG_STALE, FLAG_WARMUP, FLAGS, ORDERS, PROXY_KINDS, STAGES,
                                     STATE_NAMES)

# -- input words ---------------------------------------------------------------------------------
FREQ_FRAC = 15            # drive-frequency word: uint32, LSB 2^-15 Hz, 0 .. 131072 Hz (FORMATS.md)
FREQ_RANGE_HZ = float(1 << (32 - FREQ_FRAC))   # 131072 Hz: one past the largest word value
FREQ_SUPPORTED_HZ = (1.0e3, 1.0e5)            # drive frequencies the derivation is checked over
TEMP_FRAC = 16            # temperature word: int32, LSB 2^-16 degC
RATE_FRAC = 10            # raw rate word: int32, LSB 2^-10 deg/h (+-2^21 deg/h = +-582.5 deg/s)
Q = 30                    # u, v, z: int32 Q1.30, 1.0 = 2^30
ONE = 1 << Q
WORD_BITS = 32
INT32_SYM = (1 << 31) - 1          # symmetric int32 saturation limit
UINT32_MAX = (1 << 32) - 1

# -- proxy / rate -----------------------------------------------------------------------------------
DP_CLAMP = (1 << 31) - 1  # |P - P_ref| clamped to int32 before the gain product (u saturates anyway)
SPAN_LSB_MAX = 1 << 30     # largest proxy span in word LSB (a clamped dP still clamps u)
GAIN_BITS = 31            # gains are positive int32 (< 2^31)
IIR_FRAC = 24             # iir state: 24 fractional bits below the proxy LSB (>= MAX_SHIFT)
N_HIST_MAX = 4096         # longest diffn/lsq window: the history buffer holds n + 1 words
S_BITS_MAX = 55           # rate sum clamp |S| <= 2^SB - 1 with SB <= 55 (gain keeps >= 7 bits)
MIN_GAIN_BITS = 16        # quantizer refuses a proxy or rate gain with fewer significant bits

# -- sequencer / combiner ----------------------------------------------------------------------------
MEAN_EXTRA = 10           # window mean W: 10 more fractional bits than the rate word
W_FRAC = RATE_FRAC + MEAN_EXTRA      # 20: W LSB 2^-20 deg/h
Y_FRAC = W_FRAC + 1                  # 21: combined output y LSB 2^-21 deg/h (y = c + W_o [+ T] in W units)
SLOPE_EXTRA = 16                     # trend slope: 16 more fractional bits than W
SLOPE_FRAC = W_FRAC + SLOPE_EXTRA    # 36: LSB 2^-36 deg/h per half-sample
SLOPE_MAX = (1 << 40) - 1            # |slope| <= 2^40 - 1 (16 deg/h per half-sample)
D_MAX = (1 << 22) - 1                # trend distance (half-samples) clamp: |slope * d| < 2^62
COUNT_MAX = (1 << 31) - 1            # window count, sample ages: saturating uint32 at 2^31 - 1
TIMER_MAX = (1 << 31) - 1            # sequencer timing fields (samples) at most 2^31 - 1

# -- evaluator / output --------------------------------------------------------------------------------
ACC_LIMIT = (1 << 31) - 1  # every Horner accumulator |.| <= 2^31 - 1 (quantizer interval analysis)
EXP_MIN, EXP_MAX = 0, 52   # legal coefficient exponents: c = m * 2^-e
ALIGN_MAX = 31             # e_group - E in 0..31 (row and aux alignment shifts)
OUT_FRAC = 10              # compensated output and bias words: int32, LSB 2^-10 deg/h
OUT_SHIFT = Y_FRAC - OUT_FRAC        # 11: the one final rounding

# -- status flags (uint8; bits 1..16 are host_tools.golden.compensate's): firmware_ref.vocabulary ---------------

# -- sequencer states and virtual-switch control bits (paper Fig. 3c) -------------------------------------
ST_POWER_ON, ST_EXCH_TO_1, ST_MODE_1, ST_EXCH_TO_2, ST_MODE_2, ST_FTR = range(6)
STATE_MODE = (3, 3, 1, 3, 2, 0)      # run-log mode of each state
VS_DRV_X = 1      # AGC (drive) loop closed on the x electrodes: x is the drive axis
VS_DRV_Y = 2      # AGC loop closed on y
VS_SNS_Y = 4      # FTR (sense) loop closed on y: y senses, output valid for integration
VS_SNS_X = 8      # FTR loop closed on x
VS_NEG = 16       # rate sign negative (mode 2: the loop output is negated before combination)
VS_BITS = {
    VS_DRV_X: ("DRV_X", "AGC drive loop closed on x (drive electrodes x)"),
    VS_DRV_Y: ("DRV_Y", "AGC drive loop closed on y"),
    VS_SNS_Y: ("SNS_Y", "FTR rebalance loop closed on y (y is the sense axis)"),
    VS_SNS_X: ("SNS_X", "FTR rebalance loop closed on x"),
    VS_NEG: ("NEG", "output sign -1 (mode 2)"),
}
STATE_VS = (
    VS_DRV_X,                       # power-on: drive starts on x, sense loop open
    VS_DRV_X,                       # exchange to mode 1: drive re-established on x, sense open
    VS_DRV_X | VS_SNS_Y,            # mode 1: x drives, y senses
    VS_DRV_Y,                       # exchange to mode 2: drive moved to y, sense open
    VS_DRV_Y | VS_SNS_X | VS_NEG,   # mode 2: y drives, x senses, sign -1
    VS_DRV_X | VS_SNS_Y,            # FTR: as mode 1, forever
)
STATE_SIGN = (0, 0, 1, 0, -1, 1)
MODE_SIGN = (1, 1, -1, 0)           # rate sign per run-log mode 0..3

# COMBINERS, ORDERS, ESTIMATORS, PROXY_KINDS, AUX_GENERATORS (table codes): firmware_ref.vocabulary

# -- the aux regressor z: generators of aux_gen 1 'sum' (host_tools.golden.regressors module doc) -------------
# AUX_KINDS (term kind 0..6): firmware_ref.vocabulary
AUX_MAX_TERMS = 16        # terms of the sum: the fitter's lag-state block (6) and the closed loop's own
                          # effects beside it; a table has at most 72 + 2 + 4 + 16 x 11 + 1 = 255 words
AUX_MAX_CHANNELS = 4      # aux input words A0..A3 (run-log aux_* columns)
AUX_TERM_WORDS = 11       # table words per term
AUX_FRAC_MAX = 48         # aux word A_c: int32, LSB 2^-AF_c of its column's unit, AF_c in 0..48 (table)
CH_F, CH_T, CH_A0 = 0, 1, 2          # source channel codes: F word, T word, A_c = 2 + c
AUX_STATE_FRAC = 60       # filter / decay state: int64 Q1.60 (30 bits below z)
AUX_SB_MIN, AUX_SB_MAX = 31, 62      # filter / decay coefficient b = B 2^-SB, B < 2^31 (normalized >= 2^30)
AUX_TAU_N_MIN = 1.0 / 16.0           # shortest time constant fs tau [samples] (B must fit at SB = 31)
AUX_TAU_N_MAX = float(1 << 31)       # longest: B keeps 31 significant bits up to about 2^31 samples
AUX_POWER_MAX = 5         # input power 1..5
K_LIMIT = 1 << 62         # |K| (sample counter since power-on) accepted as an input
OSC_PHASE_BITS = 64       # osc phase: uint64 turns x 2^64; step W = RHU(2^64 / (P fs)), 1 <= W < 2^63
# sin(pi/2 x) = x (S_0 + S_1 x^2 + ... + S_5 x^10) for x in [0, 1], coefficients Q.30 (minimax fit,
# then rounded); the integer evaluation (FORMATS.md) is within SIN_ERR_LSB LSB of sin (largest error
# 3.07 LSB over all 2^30 + 1 arguments, computed once; tests/test_fixed_aux.py checks a dense sample)
SIN_POLY = (1686629713, -693598663, 85569264, -5026852, 172032, -3670)
SIN_ERR_LSB = 4


@dataclass(frozen=True)
class Fmt:
    """One signal: name, C type, fractional bits (text), LSB (text), range, rounding, overflow rule."""

    name: str
    ctype: str
    frac: str
    lsb: str
    range: str
    rounding: str
    overflow: str
    stage: str


def _p2(e: int) -> str:
    return f"2^{e}"


SIGNALS = (
    # inputs
    Fmt("F (drive frequency word)", "uint32", str(FREQ_FRAC), f"2^-{FREQ_FRAC} Hz = {2.0 ** -FREQ_FRAC:.4g} Hz",
        f"0 .. {FREQ_RANGE_HZ:.0f} Hz", "RHU from float", "sat [0, 2^32-1], FLAG_INPUT_SAT", "inputs"),
    Fmt("T (temperature word)", "int32", str(TEMP_FRAC), f"2^-{TEMP_FRAC} degC = {2.0 ** -TEMP_FRAC:.4g} degC",
        "+-32768 degC", "RHU from float", "sym-sat, FLAG_INPUT_SAT", "inputs"),
    Fmt("R (raw rate word)", "int32", str(RATE_FRAC), f"2^-{RATE_FRAC} deg/h = {2.0 ** -RATE_FRAC:.4g} deg/h",
        "+-2^21 deg/h = +-582.5 deg/s", "RHU from float", "sym-sat, FLAG_INPUT_SAT", "inputs"),
    Fmt("mode, restart", "uint8", "-", "-", "mode 0..3; restart 0/1", "-", "mode outside 0..3: host error", "inputs"),
    Fmt("Z (external aux word; aux_gen 0 only)", "int32", str(Q), "2^-30 (Q1.30)", "[-1, 1]", "RHU from float",
        "clamp [-2^30, 2^30], FLAG_AUX_CLAMPED", "inputs"),
    Fmt("A_c (aux channel word, c = 0..3)", "int32", "AF_c (table, 0..48)", "2^-AF_c of the aux_* column's unit",
        "+-2^(31-AF_c) units", "RHU from float", "sym-sat, FLAG_INPUT_SAT", "inputs"),
    Fmt("K (sample counter since power-on)", "int64", "0", "1 sample", "|K| <= 2^62 (default: internal count)",
        "rint(t_s fs) on the host", "refused beyond (host error / ERR RANGE)", "inputs"),
    # proxy
    Fmt("P_REF (proxy centre)", "same as P", "as P", "as P", "as P", "RHU from ref", "quantizer refuses", "table"),
    Fmt("dP = P - P_REF", "int64 -> int32", "as P", "as P", "|dP| <= 2^31 - 1", "exact", "clamp +-(2^31 - 1) (u clamps anyway)", "proxy"),
    Fmt("G_U, SH_U (proxy gain)", "int32 > 0, uint8", "-", "u = RHU(dP G_U, SH_U)", "2^30 <= G_U < 2^31 when SH_U > 0",
        "RHU from 2^(30+SH_U) LSB/span", "quantizer refuses span < LSB or > 2^30 LSB", "table"),
    Fmt("u", "int32", str(Q), "2^-30", "[-2^30, 2^30]", "RHU (1 shift)", "clamp, FLAG_PROXY_CLAMPED", "proxy"),
    # rate
    Fmt("history", "n+1 proxy words", "as P", "as P", "as P", "-", "-", "rate"),
    Fmt("S (estimator sum)", "int64", f"as P (iir: +{IIR_FRAC})", "P LSB (iir: 2^-24 P LSB)", "|S| < 2^57",
        "exact (iir: RHU per update)", "clamp +-(2^SB - 1), then v clamps", "rate"),
    Fmt("y (iir state)", "int64", f"P + {IIR_FRAC}", "2^-24 P LSB", "|y| < 2^56",
        "RHU (y += RHU(d 2^24 - y, e), gear e = min(shift, floor(log2 k)))",
        "cannot overflow (|d| < 2^32; y stays a convex combination of the d 2^24)", "rate"),
    Fmt("G_V, SH_V (rate gain)", "int32 > 0, uint8", "-", "v = RHU(S G_V, SH_V)", "G_V < 2^min(31, 62-SB)",
        "RHU from 2^(30+SH_V) / S_span", "quantizer refuses (see quantize)", "table"),
    Fmt("v", "int32", str(Q), "2^-30", "[-2^30, 2^30]", "RHU (1 shift)", "clamp, FLAG_RATE_CLAMPED", "rate"),
    Fmt("k (samples since restart)", "uint32", "0", "1 sample", "0 .. K_SAT", "-",
        "saturates at K_SAT = max(W, 2^shift) (iir), W (others)", "rate"),
    # aux generators (aux_gen 1)
    Fmt("REF, G, OFF, SH (input term)", "int32, int32 > 0, int32, uint8", "-", "q = RHU(dX G + OFF, SH)",
        "as P_REF, G_U, U_OFF, SH_U", "RHU from ref, 2^(30+SH) LSB/span", "quantizer refuses", "table"),
    Fmt("q (normalized input)", "int32", str(Q), "2^-30", "[-2^30, 2^30]", "RHU (1 shift)", "clamp (no flag)", "aux"),
    Fmt("B, SB (filter / decay coefficient)", "int32 > 0, uint8", "-", "b = B 2^-SB = 1 - a",
        f"2^30 <= B < 2^31, SB in {AUX_SB_MIN}..{AUX_SB_MAX}", "RHU from the exact 1 - a",
        "quantizer refuses fs tau outside 1/16 .. 2^31 samples", "table"),
    Fmt("Y (filter / decay state)", "int64", str(AUX_STATE_FRAC), "2^-60", "[-2^60, 2^60]",
        "RHU per update: Y += RHUW(B, X - Y, SB)", "cannot overflow (Y stays between Y and X)", "aux"),
    Fmt("y, g (generator output)", "int32", str(Q), "2^-30", "[-2^30, 2^30]", "RHU (Y >> 30, powers, ramp, sine)",
        "cannot overflow (clamped where a rounding could pass 2^30)", "aux"),
    Fmt("N, G, SH (ramp)", "int32 > 0, int32 > 0, uint8", "-", "g = RHU(k G, SH) for k < N", "N < 2^31",
        "RHU from 2^(30+SH) / N", "quantizer refuses N >= 2^31", "table"),
    Fmt("W (osc phase step)", "uint64 (2 words)", "64", "2^-64 turn per sample", "1 .. 2^63 - 1",
        "RHU from 2^64 / (P fs)", "quantizer refuses P fs <= 2 samples", "table"),
    Fmt("phase = K W mod 2^64", "uint64", "64", "2^-64 turn", "[0, 2^64)", "exact (modular)", "wraps (a full turn)",
        "aux"),
    Fmt("w_j (term weights)", "int32", str(Q), "2^-30", "sum |w_j| <= 2^30 + n_terms", "RHU from float",
        "quantizer refuses |w| > 1", "table"),
    Fmt("acc_z = sum w_j g_j", "int64", str(2 * Q), "2^-60", "|.| <= (2^30 + n_terms) 2^30 < 2^61", "exact",
        "cannot overflow (the weight-sum check)", "aux"),
    Fmt("z (generated)", "int32", str(Q), "2^-30", "[-2^30, 2^30]", "RHU(acc_z, 30)", "clamp, FLAG_AUX_CLAMPED",
        "aux"),
    # sequencer
    Fmt("c = s R (rate-corrected)", "int32", str(RATE_FRAC), f"2^-{RATE_FRAC} deg/h", "sym int32", "exact",
        "cannot overflow (R sym-sat)", "sequencer"),
    Fmt("x = r = c - B (residual word; order 1, regress_first)", "int32", str(RATE_FRAC),
        f"2^-{RATE_FRAC} deg/h", "sym int32", "RHU(c 2^11 - B, 11) (B of the sample's bank)", "sym-sat, FLAG_SAT",
        "sequencer"),
    Fmt("acc (window sum of c; order 1: of r)", "int64", str(RATE_FRAC), f"2^-{RATE_FRAC} deg/h", "|acc| < 2^62", "exact",
        "cnt saturates: later samples not added, FLAG_SAT", "sequencer"),
    Fmt("cnt, pos, age[o], span[o]", "uint32", "0", "1 sample", "0 .. 2^31-1", "-", "saturate at 2^31-1", "sequencer"),
    Fmt("W[o] (window mean)", "int64", str(W_FRAC), f"2^-{W_FRAC} deg/h", "|W| < 2^41", "RHU division, once per window",
        "cannot overflow", "sequencer"),
    Fmt("slope[o] (trend)", "int64", str(SLOPE_FRAC), f"2^-{SLOPE_FRAC} deg/h per half-sample", "|.| <= 2^40-1",
        "RHU division, once per window", "clamp, FLAG_SAT", "sequencer"),
    Fmt("d (trend distance)", "uint32", "1", "half a sample", "0 .. 2^22-1", "exact", "clamp, FLAG_SAT", "sequencer"),
    Fmt("T (trend term)", "int64", str(W_FRAC), f"2^-{W_FRAC} deg/h", "|T| < 2^46", "RHU (1 shift)", "cannot overflow",
        "sequencer"),
    Fmt("y (combined output)", "int64", str(Y_FRAC), f"2^-{Y_FRAC} deg/h", "|y| < 2^47",
        "exact (c 2^10 + W + T; order 1: r in place of c; none: r 2^11)", "cannot overflow", "sequencer"),
    Fmt("order, n_banks (table)", "uint32", "-", "-", "order 0 / 1 banks; 1 / 2 banks", "-", "table refused otherwise",
        "table"),
    # evaluator
    Fmt("m_k, m2_k (coefficient mantissas, bank 1, 2)", "int32", "e_g (per group and bank)", "2^-e_g deg/h",
        "sum_j |m_gj| <= 2^31-1",
        "RHU from float", "quantizer refuses", "table"),
    Fmt("e_0..e_3, e_7, E; e2_* (exponents, per bank)", "uint8", "-", "-", f"{EXP_MIN}..{EXP_MAX}; e_g - E in 0..{ALIGN_MAX}", "-",
        "quantizer refuses", "table"),
    Fmt("p, q_i (inner Horner)", "int64", "e_i", "2^-e_i deg/h", "|.| <= 2^31-1 (proved)", "RHU per product",
        "cannot overflow", "evaluator"),
    Fmt("t (outer Horner + k7 z)", "int64", "E", "2^-E deg/h", "|.| <= 2^31-1 (proved)", "RHU per product/alignment",
        "cannot overflow", "evaluator"),
    Fmt("B (bias)", "int64", str(Y_FRAC), f"2^-{Y_FRAC} deg/h", "|B| < 2^52", "RHU (E > 21) or exact",
        "cannot overflow", "evaluator"),
    # output
    Fmt("OUT (compensated rate word)", "int32", str(OUT_FRAC), f"2^-{OUT_FRAC} deg/h", "+-2^21 deg/h",
        f"RHU (y - B) >> {OUT_SHIFT} (order 0), RHU y >> {OUT_SHIFT} (order 1)", "sym-sat, FLAG_SAT", "compensate"),
    Fmt("BIAS (bias word)", "int32", str(OUT_FRAC), f"2^-{OUT_FRAC} deg/h", "+-2^21 deg/h", f"RHU B >> {OUT_SHIFT}",
        "sym-sat, FLAG_SAT", "compensate"),
    Fmt("flags", "uint8", "-", "-", "bits below", "-", "-", "compensate"),
)


# -- the input-format derivation -------------------------------------------------------------------

@dataclass(frozen=True)
class NoiseFigures:
    """The stated figures the input formats are derived against (host_tools.simulation.sim defaults when this
    was written): drive frequency f0 [Hz], its temperature coefficient [1/degC], white frequency
    noise [Hz, 1 sigma per sample], PLL step [Hz]; ARW [deg/sqrt(h)]; board-sensor noise [degC];
    sample rate [Hz]; the rate the rate term must resolve [degC/min]; allowed noise increase."""

    f0_hz: float = 6227.386
    k_per_c: float = -20.9e-6
    sigma_f_hz: float = 1.0e-4
    pll_lsb_hz: float = 100e6 / 2 ** 48
    arw_deg_sqrt_h: float = 0.003
    sigma_t_c: float = 0.02
    fs_hz: float = 1.0
    rate_c_per_min: float = 1.0
    max_noise_increase: float = 0.01


def max_lsb_for_noise(sigma: float, increase: float = 0.01) -> float:
    """Largest quantization step q whose uniform noise q/sqrt(12), added in quadrature, raises a
    white noise floor sigma by at most ``increase`` (relative): q = sigma sqrt(12 ((1+i)^2 - 1))."""
    return sigma * math.sqrt(12.0 * ((1.0 + increase) ** 2 - 1.0))


def noise_increase(sigma: float, lsb: float) -> float:
    """Relative increase of a white noise floor sigma by adding quantization noise lsb/sqrt(12)."""
    return math.sqrt(1.0 + (lsb / math.sqrt(12.0) / sigma) ** 2) - 1.0


def derivation(fig: NoiseFigures = NoiseFigures()) -> dict:
    """The numbers of the input-format derivation (see FORMATS.md)."""
    lsb_f = 2.0 ** -FREQ_FRAC
    lsb_t = 2.0 ** -TEMP_FRAC
    lsb_r = 2.0 ** -RATE_FRAC
    df_dt = abs(fig.f0_hz * fig.k_per_c) * fig.rate_c_per_min / 60.0           # Hz/s at the stated rate
    q_f = max_lsb_for_noise(fig.sigma_f_hz, fig.max_noise_increase)
    sigma_rate = 60.0 * fig.arw_deg_sqrt_h * math.sqrt(fig.fs_hz)                # deg/h per sample
    return {
        "df_dt_hz_per_s": df_dt,
        "df_per_sample_hz": df_dt / fig.fs_hz,
        "df_per_sample_lsb": df_dt / fig.fs_hz / lsb_f,
        "rate_resolution_c_per_min": lsb_f * fig.fs_hz / (df_dt / fig.rate_c_per_min),
        "q_f_max_hz": q_f,
        "f_frac_min": math.ceil(-math.log2(q_f)),
        "f_noise_increase": noise_increase(fig.sigma_f_hz, lsb_f),
        "f_noise_increase_diff": noise_increase(fig.sigma_f_hz * math.sqrt(2), lsb_f * math.sqrt(2)),
        "f_range_hz": (1 << 32) * lsb_f,
        # the same LSB over every supported drive frequency: the rule is on the frequency noise in Hz,
        # so it holds wherever that noise is at least f_sigma_min_hz; the rate term's resolution
        # (one LSB per sample at 1 degC/min) is coarsest at the lowest frequency
        "f_sigma_min_hz": lsb_f / math.sqrt(12.0 * ((1.0 + fig.max_noise_increase) ** 2 - 1.0)),
        "rate_resolution_lo_c_per_min": lsb_f * fig.fs_hz / (FREQ_SUPPORTED_HZ[0] * abs(fig.k_per_c) / 60.0),
        "rate_resolution_hi_c_per_min": lsb_f * fig.fs_hz / (FREQ_SUPPORTED_HZ[1] * abs(fig.k_per_c) / 60.0),
        "pll_lsb_hz": fig.pll_lsb_hz,
        "sigma_rate_dph": sigma_rate,
        "q_r_max_dph": max_lsb_for_noise(sigma_rate, fig.max_noise_increase),
        "r_noise_increase": noise_increase(sigma_rate, lsb_r),
        "r_range_dps": (1 << 31) * lsb_r / 3600.0,
        "q_t_max_c": max_lsb_for_noise(fig.sigma_t_c, fig.max_noise_increase),
        "t_noise_increase": noise_increase(fig.sigma_t_c, lsb_t),
        "out_rounding_dph": 0.5 * 2.0 ** -OUT_FRAC,
    }


# -- operation counts per sample ----------------------------------------------------------------------

def op_counts(estimator: str = "diff", n: int = 1, combiner: str = "pair", order: str = "combine_first") -> dict:
    """Operations per sample of one configuration, counted by construction from the algorithm of
    FORMATS.md (steady state, valid sample; the once-per-window divisions are listed apart).
    ``combiner`` "ftr", "pair", "trend" or "none" (regress_first only); ``order`` "combine_first"
    or "regress_first" (bank select, the residual word r = c - B).
    ``mul``: 32x32->64 (or 64x32) multiplies; ``add``: adds/subtracts/negations; ``shift``;
    ``cmp``: compares/branches (clamps are 2); ``mem``: 32-bit words read or written from the state
    and the table (registers not counted); ``div_per_window``: 64/32 divisions per window commit."""
    c = {"mul": 0, "add": 0, "shift": 0, "cmp": 0, "mem": 0, "div_per_window": 0}

    def add(**kw):
        for key, val in kw.items():
            c[key] += val

    # proxy: dP, clamp, product, RHU, clamp; table: P_REF, G_U, SH_U
    add(add=1, cmp=2, mul=1, shift=1, mem=3)
    add(add=1, cmp=2)
    # rate estimator
    if estimator in ("diff", "diffn"):
        add(add=1, mem=3)                               # S = P - P[i-n]; history write + read, index
    elif estimator == "lsq":
        add(add=2 * n, mul=n, mem=n + 2)                # n differences, n weight products, n sums
    elif estimator == "iir":
        add(add=3, shift=2, mem=4)                      # d, d<<24 - y, RHU add, y += ...; y (2 words), P[i-1]
        add(cmp=1)                                      # the gear: k >= 2^shift (past the start-up)
    else:
        raise ValueError(f"unknown estimator {estimator!r}")
    add(cmp=1, add=1, mem=1)                            # warm-up counter compare + increment
    add(cmp=2, mul=1, add=1, shift=1, mem=3)            # clamp S, product, RHU; table G_V, SH_V, SB
    add(cmp=2)                                          # clamp v
    if order not in ORDERS:
        raise ValueError(f"unknown order {order!r}")
    regress = order == "regress_first"
    if (combiner == "none" and not regress) or (combiner == "ftr" and regress):
        raise ValueError(f"combiner {combiner!r} is not legal with order {order!r}")
    # sequencer / combiner
    if regress:
        add(cmp=2)                                      # bank select (mode == 2), warm-up gate
        add(shift=2, add=2, cmp=2)                      # x = symsat32(RHU(c 2^11 - B, 11))
    if combiner == "ftr":
        add(shift=1)                                    # y = R << 11
    elif combiner == "none":
        add(cmp=2, add=1, mem=2)                        # mode change, settle; sign
        add(add=2, mem=3)                               # acc += x (2 words), cnt++
        add(add=2, mem=2)                               # age[1], age[2] increments
        add(shift=1)                                    # y = x << 11
    elif combiner not in ("pair", "trend"):
        raise ValueError(f"unknown combiner {combiner!r}")
    else:
        add(cmp=3, add=1, mem=2)                        # mode change, settle, staleness; sign
        add(add=2, mem=3)                               # acc += c (2 words), cnt++
        add(add=2, mem=2)                               # age[1], age[2] increments
        add(shift=1, add=1, mem=2)                      # y = (c << 10) + W[o]
        c["div_per_window"] += 1
        if combiner == "trend":
            add(shift=1, add=1, cmp=1, mem=3)           # d = 2 age + span, clamp; slope (2 words)
            add(mul=1, add=2, shift=1)                  # T = RHU(slope d), other += T
            c["div_per_window"] += 1
    # evaluator: 15 Horner multiply-adds + k7 z, each product rounded (add + shift)
    add(mul=16, add=16 + 16, shift=16, mem=17 + 6)      # 17 mantissas + 6 exponents
    add(add=4, shift=4)                                 # row alignments (RHU)
    add(add=1, shift=1, cmp=2)                          # B = RHU(t, E - 21); z clamp
    # compensate: y - B (combine_first only), two RHU, two saturations, hold (2 words)
    add(add=3 - (1 if regress else 0), shift=2, cmp=5, mem=2)
    return c


def aux_op_counts(kind: str, filtered: bool = False, power: int = 1) -> dict:
    """Operations per sample that one aux term of ``kind`` adds (aux_gen 1; counted by construction
    from FORMATS.md "Aux generators", steady state; ``filtered``: input with tau_s > 0; ``power``:
    input power), same keys as :func:`op_counts` (no divisions).  The fixed cost of the stage
    (K, RHU of the sum, z clamp) is :func:`aux_op_counts` ('sum')."""
    c = {"mul": 0, "add": 0, "shift": 0, "cmp": 0, "mem": 0}

    def add(**kw):
        for key, val in kw.items():
            c[key] += val

    if kind == "sum":
        add(add=1, shift=1, cmp=2, mem=2)                     # RHU(acc_z, 30), clamp; K (2 words)
        return c
    add(cmp=2, mul=1, add=1, mem=5)                           # dispatch, sign; w_j g (acc_z +=); 5 term words
    wide = {"mul": 2, "add": 5, "shift": 3}                   # RHUW(B, D, SB): split, 2 products, RHU, shifts
    if kind == "input":
        add(add=3, cmp=4, mul=1, shift=1, mem=5)              # dX, clamp, dX G + OFF, RHU, clamp; word, REF, G, OFF, SH
        if filtered:
            add(**wide)
            add(cmp=1, add=2, shift=2, mem=6)                 # restart?, D = q 2^30 - Y, Y +=, y = RHU(Y, 30); B, SB, Y
        add(mul=power - 1, add=power - 1, shift=power - 1, mem=1)
    elif kind == "rate":
        add(cmp=5, mul=1, add=1, shift=1, mem=3)              # warm-up, clamp S, product, RHU, clamp v
    elif kind == "one":
        pass
    elif kind in ("decay_on", "decay_exchange"):
        add(**wide)
        add(cmp=1, add=2, shift=1, mem=6)                     # restart?, D = -Y, Y +=, g = RHU(Y, 30); B, SB, Y
        if kind == "decay_exchange":
            add(cmp=2, mem=2)                                 # mode 3?, ex? (ex read/write)
    elif kind == "ramp":
        add(cmp=3, mul=1, add=1, shift=1, mem=3)              # max(K, 0), K >= N, product, RHU; N, G, SH
    elif kind == "osc":
        add(mul=7, add=15, shift=10, cmp=3, mem=3)            # K W (+2^62), quadrant, RHU of r, x^2, 5 Horner, x p
    else:
        raise ValueError(f"unknown aux term kind {kind!r}")
    return c


AUX_OP_ROWS = (("sum", False, 1), ("input", False, 1), ("input", True, 1), ("input", False, 5), ("rate", False, 1),
               ("one", False, 1), ("decay_on", False, 1), ("decay_exchange", False, 1), ("ramp", False, 1),
               ("osc", False, 1))


OP_CONFIGS = (("diff", 1, "ftr"), ("diff", 1, "pair"), ("diff", 1, "trend"), ("diffn", 8, "pair"),
              ("lsq", 8, "pair"), ("lsq", 32, "trend"), ("iir", 4, "pair"))
# (estimator, n, combiner, order) rows of the regress_first op-count table
OP_CONFIGS_RTR = (("diff", 1, "none"), ("diff", 1, "pair"), ("diff", 1, "trend"), ("lsq", 8, "pair"))
