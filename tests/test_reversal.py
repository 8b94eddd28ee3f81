"""Mode-reversal combination (host_tools.golden.reversal): exact semantics on hand-built logs."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from host_tools.golden.reversal import combine, ReversalConfig
from host_tools.golden.runlog import RunLog


def mr_log(n_periods=4, exch=3, dwell=12, omega=0.0, b_e=lambda i: 0.0 * i, b_d=lambda i: 0.0 * i, t_gap_at=None):
    """Synthetic MR log at 1 Hz: exchange, mode 1, exchange, mode 2, ... with exact raw output
    rate = s*(omega + b_e) + b_d (run-log sign convention); exchange samples are garbage (1e6)."""
    mode = np.concatenate([[3] * exch + [1] * dwell + [3] * exch + [2] * dwell] * n_periods)
    i = np.arange(len(mode), dtype=float)
    s = np.where(mode == 2, -1.0, 1.0)
    rate = s * (omega + b_e(i)) + b_d(i)
    rate[mode == 3] = 1e6
    t = i.copy()
    if t_gap_at is not None:
        t[t_gap_at:] += 1000.0
    return RunLog.from_arrays(t_s=t, rate_dph=rate, mode=mode, freq_hz=np.full(len(t), 6000.0)), mode


def test_pair_cancels_constant_damping_term():
    log, mode = mr_log(omega=9.7, b_e=lambda i: 3.0 + 0 * i, b_d=lambda i: 40.0 + 0 * i)
    c = combine(log, "pair")
    # first valid sample: first mode-2 sample after a complete mode-1 window
    first_valid = int(np.argmax(c.valid))
    assert mode[first_valid] == 2 and np.all(mode[first_valid - 3:first_valid] == 3)
    assert np.all(mode[:first_valid][mode[:first_valid] != 3] == 1)
    np.testing.assert_allclose(c.out_dph[c.valid], 12.7, rtol=0, atol=1e-12)
    assert not c.valid[mode == 3].any()


def test_pair_matches_hand_computation_and_holds_when_invalid():
    rng = np.random.default_rng(1)
    log, mode = mr_log(n_periods=3)
    rate = rng.normal(size=len(mode))
    log = log.with_columns(rate_dph=rate)
    c = combine(log, "pair")
    s = np.where(mode == 2, -1.0, 1.0)
    cc = s * rate
    # recompute by hand
    windows = []  # (mode, start, stop)
    start = 0
    for i in range(1, len(mode) + 1):
        if i == len(mode) or mode[i] != mode[start]:
            if mode[start] in (1, 2):
                windows.append((mode[start], start, i))
            start = i
    expect = np.zeros(len(mode))
    valid = np.zeros(len(mode), bool)
    hold = 0.0
    for i in range(len(mode)):
        if mode[i] in (1, 2):
            prev = [w for w in windows if w[0] != mode[i] and w[2] <= i]
            if prev:
                m, a, b = prev[-1]
                hold = 0.5 * (cc[i] + cc[a:b].mean())
                valid[i] = True
        expect[i] = hold
    np.testing.assert_array_equal(c.valid, valid)
    np.testing.assert_allclose(c.out_dph, expect, rtol=1e-13, atol=1e-13)


def test_trend_cancels_linear_drift_pair_does_not():
    log, mode = mr_log(n_periods=6, b_d=lambda i: 0.5 * i, b_e=lambda i: 2.0 + 0 * i)
    p = combine(log, "pair")
    t = combine(log, "trend")
    # trend is exact once the other mode has two windows
    m2_windows_done = np.flatnonzero(np.diff((mode == 2).astype(int)) == -1)
    start = m2_windows_done[1] + 1
    sel = t.valid & (np.arange(len(mode)) > start)
    np.testing.assert_allclose(t.out_dph[sel], 2.0, atol=1e-9)
    assert np.max(np.abs(p.out_dph[sel] - 2.0)) > 1.0


def test_settle_excludes_first_samples():
    rng = np.random.default_rng(2)
    log, mode = mr_log(n_periods=3)
    rate = rng.normal(size=len(mode))
    # poison the first 2 samples of every window
    starts = np.flatnonzero(np.diff(np.r_[0, mode]) != 0)
    poisoned = [k for s0 in starts if mode[s0] in (1, 2) for k in (s0, s0 + 1)]
    r2 = rate.copy()
    r2[poisoned] = 1e9
    a = combine(log.with_columns(rate_dph=rate), "pair", settle_s=2)
    b = combine(log.with_columns(rate_dph=r2), "pair", settle_s=2)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(a.out_dph[a.valid], b.out_dph[b.valid])
    assert not a.valid[poisoned].any()


def test_stale_estimate_invalidates():
    log, mode = mr_log(n_periods=3, dwell=12, exch=3)
    # other window ends at most exch+dwell samples before a sample: with max_stale 5 s the late part of each window is invalid
    c = combine(log, "pair", max_stale_s=5)
    full = combine(log, "pair")
    assert c.valid.sum() < full.valid.sum()
    assert c.valid.sum() > 0


def test_segment_gap_resets_state():
    log, mode = mr_log(n_periods=4, t_gap_at=30 * 2)  # gap at the start of the 3rd period
    assert len(log.segments) == 2
    c = combine(log, "pair")
    # after the gap: invalid until a new complete mode-1 window (same as at power-on)
    after = np.arange(len(mode)) >= 60
    first_valid_after = 60 + int(np.argmax(c.valid[after]))
    assert first_valid_after == 60 + 3 + 12 + 3


def test_ftr_passthrough_and_mixed_modes_error():
    t = np.arange(10.0)
    log = RunLog.from_arrays(t_s=t, rate_dph=t * 2, freq_hz=t + 6000)
    c = combine(log)
    assert c.valid.all() and np.array_equal(c.out_dph, t * 2)
    bad = RunLog.from_arrays(t_s=t, rate_dph=t, freq_hz=t, mode=[3, 1, 1, 0, 2, 2, 3, 1, 1, 1])
    with pytest.raises(ValueError, match="mode 0"):
        combine(bad)


def test_config_validation():
    with pytest.raises(ValueError, match="combiner"):
        ReversalConfig("average")
    assert ReversalConfig.from_dict(ReversalConfig("trend", 200, 1).to_dict()) == ReversalConfig("trend", 200, 1)


@settings(max_examples=30, deadline=None)
@given(cut=st.integers(min_value=1, max_value=119), combiner=st.sampled_from(["pair", "trend"]), seed=st.integers(0, 1000))
def test_causal(cut, combiner, seed):
    """Changing samples after `cut` never changes outputs before it."""
    log, mode = mr_log(n_periods=4)
    rng = np.random.default_rng(seed)
    rate = rng.normal(size=len(mode))
    r2 = rate.copy()
    r2[cut:] = rng.normal(size=len(mode) - cut) * 100
    a = combine(log.with_columns(rate_dph=rate), combiner)
    b = combine(log.with_columns(rate_dph=r2), combiner)
    np.testing.assert_array_equal(a.out_dph[:cut], b.out_dph[:cut])
    np.testing.assert_array_equal(a.valid, b.valid)
