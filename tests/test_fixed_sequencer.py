"""The fixed-point sequencer: timer states and virtual-switch bits (paper and another timing),
power-on, counter edges (long runs, saturation instead of wrap), and the integer combiner vs the
golden host_tools.golden.reversal.combine."""
import numpy as np
import pytest

from firmware_ref import formats as F
from firmware_ref.compensate import Pipeline
from firmware_ref.kernel import run_words
from firmware_ref.sequencer import Combiner, Sequencer, Timer
from host_tools.vectors.builders import make_model
from host_tools.golden import runlog as rl
from host_tools.fixed.quantize import quantize
from host_tools.golden.reversal import combine
from host_tools.simulation.sim_physics import mode_sequence

ZERO = np.zeros(17)


def table_of(combiner="pair", fs=1.0, exchange_s=30.0, dwell_s=120.0, power_on_s=0.0, settle_s=0.0,
             max_stale_s=300.0, coef=ZERO):
    model = make_model(combiner=combiner, fs=fs, settle_s=settle_s, max_stale_s=max_stale_s, coef=coef)
    return quantize(model, exchange_s=exchange_s, dwell_s=dwell_s, power_on_s=power_on_s, n_random=10).table


def timer_states(table, n, restart_at=()):
    seq = Sequencer(table, self_timed=True)
    out = [seq.step(None, 0, i == 0 or i in restart_at) for i in range(n)]
    return out


@pytest.mark.parametrize("fs,exchange_s,dwell_s", [(1.0, 30.0, 120.0), (4.0, 2.5, 7.25)])
def test_timer_matches_simulator_timing(fs, exchange_s, dwell_s):
    table = table_of(fs=fs, exchange_s=exchange_s, dwell_s=dwell_s)
    n = int(3.5 * 2 * (exchange_s + dwell_s) * fs)
    outs = timer_states(table, n)
    t = np.arange(n) / fs
    np.testing.assert_array_equal([o.mode for o in outs], mode_sequence(t, True, exchange_s, dwell_s))
    # the numba kernel's self-timed states are the same
    res = run_words(table, np.full(n, table.p_ref), np.zeros(n), None, None, None, self_timed=True, detail=True)
    np.testing.assert_array_equal(res["state"], [o.state for o in outs])
    for o in outs:
        assert o.vs == F.STATE_VS[o.state] and o.sign == F.STATE_SIGN[o.state]
        if o.mode == 1:
            assert o.vs == F.VS_DRV_X | F.VS_SNS_Y and o.sign == 1
        elif o.mode == 2:
            assert o.vs == F.VS_DRV_Y | F.VS_SNS_X | F.VS_NEG and o.sign == -1
        else:
            assert not o.vs & (F.VS_SNS_X | F.VS_SNS_Y) and o.sign == 0  # sense loop open
    # an exchange drives the axis of the window that follows it
    for a, b in zip(outs, outs[1:]):
        if a.mode == 3 and b.mode in (1, 2):
            assert a.vs & (F.VS_DRV_X | F.VS_DRV_Y) == b.vs & (F.VS_DRV_X | F.VS_DRV_Y)


def test_timer_power_on_zero_exchange_restart_and_ftr():
    table = table_of(exchange_s=0.0, dwell_s=4.0, power_on_s=3.0)
    states = [o.state for o in timer_states(table, 20, restart_at=(14,))]
    P, M1, M2 = F.ST_POWER_ON, F.ST_MODE_1, F.ST_MODE_2
    assert states == [P] * 3 + [M1] * 4 + [M2] * 4 + [M1] * 3 + [P] * 3 + [M1] * 3
    ftr = table_of(combiner=None, power_on_s=2.0)
    assert [o.state for o in timer_states(ftr, 6)] == [P, P] + [F.ST_FTR] * 4
    assert [o.vs for o in timer_states(ftr, 3)][-1] == F.VS_DRV_X | F.VS_SNS_Y


def test_timer_long_dwell_has_no_wrap():
    """dwell_n = 2^31 - 2 (the largest): the in-state counter ends exactly there."""
    table = table_of(fs=1.0, exchange_s=1.0, dwell_s=float(F.TIMER_MAX - 1))
    tm = Timer(table)
    assert [tm.step() for _ in range(2)] == [F.ST_EXCH_TO_1, F.ST_MODE_1]
    tm.cnt = F.TIMER_MAX - 3            # jump ahead (2^31 samples would take too long)
    assert [tm.step() for _ in range(3)] == [F.ST_MODE_1, F.ST_MODE_1, F.ST_EXCH_TO_2]
    assert tm.cnt == 1


def test_combiner_ages_and_counts_saturate():
    table = table_of(max_stale_s=float(F.COUNT_MAX - 2))
    comb = Combiner(table)
    for m in [1, 1, 2]:
        comb.step(m, 1024, m == 1 and comb.cur == 0)
    comb.age[1] = F.COUNT_MAX - 1        # as after ~2^31 samples of mode 2
    for _ in range(3):
        valid, y, sat = comb.step(2, 1024, False)
    assert comb.age[1] == F.COUNT_MAX and not valid and not sat  # saturated, now stale: no wrap
    comb.cnt = F.COUNT_MAX - 1
    assert comb.step(2, 1024, False)[2] is False and comb.cnt == F.COUNT_MAX
    assert comb.step(2, 1024, False)[2] is True and comb.cnt == F.COUNT_MAX  # count saturates, flagged


def test_trend_distance_clamps_on_a_long_run():
    """2.2e6 samples in one window: the trend distance d reaches D_MAX and saturates (flag 128);
    outputs follow the closed form W + RHU(slope min(d, D_MAX), 16)."""
    table = table_of(combiner="trend", max_stale_s=float(F.COUNT_MAX - 2), dwell_s=10.0)
    n = 2_200_000
    mode = np.r_[[1] * 3, [2] * 3, [1] * 3, [2] * (n - 9)].astype(np.int64)
    c1, c2 = 1000, 1300                       # mode-1 windows' rate words
    r = np.r_[[c1] * 3, [0] * 3, [c2] * 3, [-500] * (n - 9)].astype(np.int64)   # mode 2: c = +500
    res = run_words(table, np.full(n, table.p_ref), r, mode, None, None, detail=True)
    w1, w2 = c1 << 10, c2 << 10
    slope = ((w2 - w1) * 2 ** 16 * 2 + 12) // (2 * 12)          # dc2 = 12 half-samples
    for i in (9, 10, 1000, 2_097_000, 2_097_159, 2_097_160, n - 1):
        d = min(2 * (i - 8) + 2, F.D_MAX)
        y = (500 << 10) + w2 + ((slope * d + 2 ** 15) >> 16)
        assert res["y"][i] == y, i
        assert res["out"][i] == (y + 2 ** 10) >> 11
        assert bool(res["flags"][i] & F.FLAG_SAT) == (2 * (i - 8) + 2 > F.D_MAX), i


def mode_runs(rng, n, lengths=(1, 25)):
    mode = np.empty(n, np.int64)
    i, cur = 0, 3
    while i < n:
        cur = {3: rng.choice([1, 2]), 1: rng.choice([3, 2]), 2: rng.choice([3, 1])}[cur]
        run = int(rng.integers(*lengths))
        mode[i:i + run] = cur
        i += run
    return mode


@pytest.mark.parametrize("combiner", ["pair", "trend"])
@pytest.mark.parametrize("settle_s,max_stale_s", [(0.0, 300.0), (3.0, 20.0), (1.0, 6.0)])
def test_combiner_equals_golden(combiner, settle_s, max_stale_s):
    rng = np.random.default_rng(3)
    n = 3000
    mode = mode_runs(rng, n)
    t = np.arange(n, dtype=float)
    for gap in (700, 1900, 1901):
        t[gap:] += 10.0                   # time gaps: segments restart the state
    rwords = np.round(rng.standard_normal(n) * 2000 + 500 * np.sin(t / 300)).astype(np.int64)
    log = rl.RunLog.from_arrays(metadata={"sample_rate_hz": "1"}, t_s=t, rate_dph=rwords * 2.0 ** -10,
                                mode=mode, temp_c=20.0 + 0.0 * t)
    assert len(log.segments) == 4
    gold = combine(log, combiner=combiner, max_stale_s=max_stale_s, settle_s=settle_s, fs_hz=1.0)
    table = table_of(combiner=combiner, settle_s=settle_s, max_stale_s=max_stale_s)
    seq = Sequencer(table)
    starts = set(int(s) for s in log.segments)
    outs = [seq.step(int(mode[i]), int(rwords[i]), i in starts) for i in range(n)]
    valid = np.array([o.valid for o in outs])
    y = np.array([o.y for o in outs]) * 2.0 ** -F.Y_FRAC
    np.testing.assert_array_equal(valid, gold.valid)
    assert valid.sum() > 300
    tol = 2.0 ** -21 if combiner == "pair" else 1e-5
    assert np.max(np.abs(y - gold.out_dph)) <= tol
    np.testing.assert_array_equal([o.sign for o in outs], gold.sign)
    # window accumulators: the running sum of c over the used samples of the open window
    acc = np.array([o.acc for o in outs])
    cnt = np.array([o.cnt for o in outs])
    i = int(np.flatnonzero(cnt == 12)[0])
    sgn = 1 if mode[i] == 1 else -1
    assert acc[i] == sgn * rwords[i - 11:i + 1].sum()


def test_pipeline_power_on_state():
    table = table_of(settle_s=2.0)
    pipe = Pipeline(table, self_timed=True)
    s = [pipe.step(table.p_ref, 100, None, i == 0) for i in range(40)]
    assert s[0].state == F.ST_EXCH_TO_1 and not s[0].valid and s[0].flags & F.FLAG_EXCHANGE
    assert all(not x.valid for x in s) and s[0].out == 0 and s[0].bias == 0
    assert s[31].flags & F.FLAG_STALE and not s[31].flags & F.FLAG_EXCHANGE  # mode 1, no mode-2 window
