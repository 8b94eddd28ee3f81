"""The stage vocabulary, declared once: stage names, the codes of the rate estimators, combiners,
orders, proxy kinds, aux generators and aux term kinds, the sequencer states, the status flag bits
with their names and meanings.

At the bottom of the dependency graph (imports nothing): the golden model (host_tools.golden.proxy, rate,
reversal, compensate, flags), the fixed point (firmware_ref.formats, table), the CLI ``choices``
and the generated docs (FORMATS.md and the constants block of firmware_ref/c/hdrg_fw.h, both
rendered by firmware_ref.docgen) read these names.

A code is the index of a name in its tuple: the table field (FORMATS.md "Coefficient table
layout") and the C constant ``HDRG_<GROUP>_<NAME>`` hold that integer.
"""

# Stages of the per-sample pipeline, in data-flow order (the ``stage`` column of FORMATS.md).
STAGES = ("inputs", "proxy", "rate", "aux", "table", "evaluator", "sequencer", "compensate")

PROXY_KINDS = ("freq", "temp")                     # table proxy_kind: 0 F word, 1 T word
ESTIMATORS = ("diff", "diffn", "lsq", "iir")       # table rate_est 0..3
COMBINERS = ("ftr", "pair", "trend", "none")       # table combiner 0..3 (0: no mode reversal; 3: order 1 only)
REVERSAL_COMBINERS = COMBINERS[1:]                 # the golden's mode-reversal combiners (host_tools.golden.reversal)
ORDERS = ("combine_first", "regress_first")        # table order 0, 1
AUX_GENERATORS = ("none", "sum")                   # table aux_gen 0 (z = the external Z word), 1
AUX_KINDS = ("input", "rate", "one", "decay_on", "decay_exchange", "ramp", "osc")   # aux term kind 0..6
STATE_NAMES = ("power_on", "exchange_to_1", "mode_1", "exchange_to_2", "mode_2", "ftr")   # sequencer state 0..5

# -- status flags: uint8, one bit each ------------------------------------------------------------
FLAG_PROXY_CLAMPED = 1
FLAG_RATE_CLAMPED = 2
FLAG_WARMUP = 4
FLAG_EXCHANGE = 8
FLAG_STALE = 16
FLAG_AUX_CLAMPED = 32      # z outside [-2^30, 2^30] was clamped
FLAG_INPUT_SAT = 64        # the input-invalid bit (an input outside what the sensor can report), or a saturated aux word
FLAG_SAT = 128             # a saturation inside the pipeline (window count, trend slope/distance, output words)
FLAGS = {
    FLAG_PROXY_CLAMPED: ("proxy_clamped", "u outside [-1, 1] was clamped (golden: same rule, |u_raw| > 1)"),
    FLAG_RATE_CLAMPED: ("rate_clamped", "v outside [-1, 1] was clamped"),
    FLAG_WARMUP: ("warmup", "rate estimator in warm-up (v = 0)"),
    FLAG_EXCHANGE: ("exchange", "mode 3 (exchange or power-on)"),
    FLAG_STALE: ("stale", "mode 1/2 sample without a valid combination (settling, no window, too old)"),
    FLAG_AUX_CLAMPED: ("aux_clamped", "z word outside [-2^30, 2^30] was clamped"),
    FLAG_INPUT_SAT: ("input_saturated", "input-invalid: the sample's invalid bit (an input outside the declared "
                                        "full scale or its word's range; host input stage), or an aux word saturated"),
    FLAG_SAT: ("saturated", "saturation in the pipeline: window count, trend slope/distance, output word"),
}
# The flags of the float golden model (host_tools.golden.compensate): bits 1..16, same meanings.
GOLDEN_FLAG_NAMES = {bit: FLAGS[bit][0] for bit in (FLAG_PROXY_CLAMPED, FLAG_RATE_CLAMPED, FLAG_WARMUP,
                                                    FLAG_EXCHANGE, FLAG_STALE)}
