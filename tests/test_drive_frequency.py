"""Any drive frequency a vibratory gyroscope uses: the F word (uint32, LSB 2^-FREQ_FRAC Hz) holds
1 kHz .. 100 kHz and up to its end; a table fitted at each frequency meets the |fixed - golden|
bound and the 0.002 deg/h goal; a table of the old 2^-18 Hz layout is refused with what to do;
the committed vectors hold the drive-frequency cases."""
import json

import numpy as np
import pytest

from firmware_ref import formats as F
from firmware_ref import table as T
from firmware_ref.table import Table, TableError, crc32_words, encode_aux
from host_tools.fixed.quantize import QuantizeError, quantize
from host_tools.golden import compensate as comp
from host_tools.golden.reversal import ReversalConfig
from host_tools.fitting.fit import fit_logs
from host_tools.simulation.sim import simulate
from host_tools.vectors.builders import make_model
from host_tools.vectors.spec import DEFAULT_DIR
from fixed_compare import fixed_vs_golden

GOAL_DPH = 0.002


@pytest.mark.parametrize("f0_hz", [1.0e3, 3.0e3, 24.0e3, 36.0e3, 65.0e3, 1.0e5, 130.0e3])
def test_fixed_vs_golden_at_every_drive_frequency(f0_hz):
    """A mode-reversal chamber cycle simulated at drive frequency f0, fitted (regress_first pair,
    all 17 terms), quantized: |fixed - golden| on the same input words within the quantizer's bound
    and the goal, no input word saturated, and the fixed output as flat as the golden."""
    log = simulate("paper-mr-cycle-4dpm", seed=3, duration_s=3600.0, f0_hz=f0_hz)
    assert abs(float(np.median(log["freq_hz"])) / f0_hz - 1.0) < 2e-3
    cfg = comp.fit_config_from_logs([log], reversal=ReversalConfig("pair", order="regress_first"))
    model, _ = fit_logs([log], cfg, terms="all")
    c = fixed_vs_golden(log, model)
    assert c.q.table.proxy_kind == 0 and c.q.table.p_ref == round(model.config.proxy.ref * 2 ** F.FREQ_FRAC)
    assert c.emax < GOAL_DPH and c.emax <= c.q.report["bound_dph"]["out"]
    assert c.bmax <= c.q.report["bound_dph"]["bias_word"]
    assert not (c.flags & F.FLAG_INPUT_SAT).any()
    v = c.valid
    assert np.std(c.fixed.rate_dph[v]) == pytest.approx(np.std(c.gold.rate_dph[v]), rel=1e-3)


def test_word_range_and_refusal_beyond_it():
    """The word's range is 0 .. 2^(32 - FREQ_FRAC) Hz; a centre beyond it is refused by name."""
    assert F.FREQ_RANGE_HZ == 2.0 ** (32 - F.FREQ_FRAC) >= 1.3e5
    top = quantize(make_model(ref=F.FREQ_RANGE_HZ - 12.0, span=8.0, rate_span=0.008), n_random=10).table
    assert top.p_ref == round((F.FREQ_RANGE_HZ - 12.0) * 2 ** F.FREQ_FRAC) <= F.UINT32_MAX
    with pytest.raises(QuantizeError, match=r"outside the drive-frequency word \(0 \.\. 131072 Hz\)"):
        quantize(make_model(ref=F.FREQ_RANGE_HZ + 10.0, span=8.0, rate_span=0.008))


def _as_version(words, version):
    w = list(words)
    w[1] = version
    return w[:-1] + [crc32_words(w[:-1])]


def test_old_layout_tables_are_read_or_refused_with_what_to_do():
    """Version 1..3 tables: a frequency proxy, or an aux input term on F, held its centre in the
    old 2^-18 Hz word: refused with 'quantize the model again'; a temperature-proxy table is read."""
    freq = quantize(make_model(), n_random=10).table
    for v in (2, 3):
        with pytest.raises(TableError, match=r"2\^-18 Hz.*quantize the model again \(hdrg quantize\)"):
            Table.from_words(_as_version(freq.to_words(), v), "old.memh")
    temp = quantize(make_model(kind="temp", ref=20.0, span=40.0, rate_span=0.5), n_random=10).table
    assert Table.from_words(_as_version(temp.to_words(), 3), "old.memh") == temp
    # a temperature-proxy table whose aux input term reads F: refused at version 3, read at 4
    aux = temp.aux_params
    term = T.AuxTerm(T.KIND_INPUT, 0, F.CH_F, 1, F.ONE // 2, (round(6227.0 * 2 ** F.FREQ_FRAC), 1 << 30, 0, 17, 0, 0))
    with_f = T.Table(**{**{f: getattr(temp, f) for f in temp.__dataclass_fields__},
                        "aux_gen": 1, "aux_params": encode_aux((), [term])})
    assert aux == () and Table.from_words(with_f.to_words()) == with_f
    with pytest.raises(TableError, match="an aux input term reads the drive frequency"):
        Table.from_words(_as_version(with_f.to_words(), 3), "old.memh")


def test_vectors_hold_the_drive_frequency_cases():
    """The committed sequencer and e2e sets hold cases at 3, 24, 36 and 65 kHz and at each end of
    the word, and their tables' proxy centres are there."""
    from host_tools.vectors.sequencer import DRIVE_FREQ_CASES, WORD_END_CASES
    man = json.loads((DEFAULT_DIR / "manifest.json").read_text(encoding="utf-8"))
    text = json.dumps(man)
    for f0, _, _ in DRIVE_FREQ_CASES:
        assert f"drive_{f0 / 1e3:g}khz_log" in text and f"regress_first_pair_{f0 / 1e3:g}khz" in text
    for name, _, _ in WORD_END_CASES:
        assert name in text
    assert {f0 for f0, _, _ in DRIVE_FREQ_CASES} == {3.0e3, 24.0e3, 36.0e3, 65.0e3}
    lo, hi = WORD_END_CASES[0][1] - WORD_END_CASES[0][2], WORD_END_CASES[1][1] + WORD_END_CASES[1][2]
    assert lo <= 4.0 and hi >= F.FREQ_RANGE_HZ - 4.0
