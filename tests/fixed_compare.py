"""The fixed-point output against the float golden model on the same input words, shared by
test_fixed_golden and test_fixed_aux."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from host_tools.golden import compensate as hc
from host_tools.fixed.fixed_point import compensate_log, dequantized_log
from host_tools.fixed.quantize import Quantized, quantize


@dataclass
class Comparison:
    fixed: object            # the fixed-point compensated log
    gold: object             # the golden compensated log of the dequantized input words
    flags: np.ndarray        # the fixed-point status flags
    q: Quantized             # the quantized model (its bound)
    err: np.ndarray          # fixed - golden output [deg/h]
    berr: np.ndarray         # fixed - golden bias [deg/h]
    valid: np.ndarray        # bool: valid samples

    @property
    def emax(self) -> float:
        return float(np.max(np.abs(self.err)))

    @property
    def bmax(self) -> float:
        return float(np.max(np.abs(self.berr)))


def fixed_vs_golden(log, model, table=None) -> Comparison:
    """Quantize ``model`` (or use ``table``), run ``log`` through the fixed-point path and the golden
    model on the dequantized words; asserts that both mark the same samples valid and that the
    fixed flags' golden bits (& 31) are the golden's."""
    q = quantize(model)
    fixed, flags = compensate_log(log, model, table=q.table if table is None else table, return_flags=True)
    deq = dequantized_log(log, model)
    gold = hc.compensate(deq, model)
    np.testing.assert_array_equal(fixed["valid"], gold["valid"])
    np.testing.assert_array_equal(flags & 31, hc.prepare(deq, model).flags)
    valid = gold["valid"] > 0   # the golden log has no number where not valid (NaN); the words hold theirs
    return Comparison(fixed, gold, flags, q, np.where(valid, fixed.rate_dph - gold.rate_dph, 0.0),
                      np.where(valid, fixed["bias_dph"] - gold["bias_dph"], 0.0), valid)
