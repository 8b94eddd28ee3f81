"""Tests of the numeric core of the fitter (host_tools/fitting/fit.py)."""
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from firmware_ref.terms import K_AUX, N_TERMS, PAPER_TERMS
from host_tools.fitting import fit as F

ALL = tuple(range(N_TERMS))


def cycles(n, rng, rates=(0.25, 0.5, 1.0), seg=(1500, 6000), noise=0.05):
    """u: a temperature-cycle-like path over [-1, 1] (triangle segments at several rates, reflected
    at the ends); v: its normalized rate (piecewise constant) plus noise, clipped to [-1, 1]."""
    u = np.empty(n)
    v = np.empty(n)
    x, i = rng.uniform(-1, 1), 0
    step = 4.0 / seg[1]
    while i < n:
        length = int(rng.integers(*seg))
        rate = rng.choice(rates) * rng.choice((-1.0, 1.0))
        for j in range(i, min(n, i + length)):
            x += rate * step
            if x > 1:
                x, rate = 2 - x, -rate
            elif x < -1:
                x, rate = -2 - x, -rate
            u[j], v[j] = x, rate
        i += length
    v = np.clip(v + noise * rng.standard_normal(n), -1, 1)
    return u, v


def aux(n, rng):
    """A generic auxiliary channel: slow random walk plus white noise (e.g. a supply voltage)."""
    walk = np.cumsum(rng.standard_normal(n)) / np.sqrt(n)
    return 2.0 + walk + 0.2 * rng.standard_normal(n)


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(7)
    n = 40000
    u, v = cycles(n, rng)
    z = aux(n, rng)
    coef = rng.uniform(-3, 3, N_TERMS)
    y = F.design_matrix(u, v, z) @ coef
    return u, v, z, y, coef, rng


def test_recovers_all_17_terms_noiseless(data):
    u, v, z, y, coef, _ = data
    res = F.fit(u, v, z, y, terms=ALL)
    assert res.terms == ALL and res.dropped == ()
    np.testing.assert_allclose(res.coef, coef, rtol=1e-9, atol=1e-9 * np.abs(coef).max())
    assert res.n == len(u) and res.dof == len(u) - N_TERMS
    assert res.rms < 1e-6 * np.sqrt(np.mean(y ** 2))
    assert np.isfinite(res.cond) and res.cond > 1
    # the default term set is the paper's 16 plus k7 when z is given
    assert F.fit(u, v, z, y).terms == ALL
    assert F.fit(u, v, None, y - coef[K_AUX] * z).terms == PAPER_TERMS


@pytest.mark.parametrize("terms", [ALL, (0, 1, 2, 4, 8, 12), (3, 7, 16)])
def test_equals_lstsq_on_noisy_data(data, terms):
    u, v, z, y, _, rng = data
    yn = y + 0.7 * rng.standard_normal(len(y))
    res = F.fit(u, v, z, yn, terms=terms)
    X = F.design_matrix(u, v, z, terms)
    c, *_ = np.linalg.lstsq(X, yn, rcond=None)
    np.testing.assert_allclose(res.coef[list(terms)], c, rtol=0, atol=1e-10 * np.abs(c).max())
    others = [k for k in ALL if k not in terms]
    assert np.all(res.coef[others] == 0) and np.all(res.stderr[others] == 0)
    r = yn - X @ c
    assert res.rms == pytest.approx(np.sqrt(np.mean(r ** 2)), rel=1e-9)
    cov = (r @ r) / (len(r) - len(terms)) * np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(res.stderr[list(terms)], np.sqrt(np.diag(cov)), rtol=1e-7)
    assert res.cond == pytest.approx(np.linalg.cond(X / np.linalg.norm(X, axis=0)), rel=1e-7)


def test_weights_equal_scaled_lstsq(data):
    u, v, z, y, _, rng = data
    yn = y + rng.standard_normal(len(y))
    w = rng.uniform(0.2, 3.0, len(y))
    res = F.fit(u, v, z, yn, w, terms=ALL)
    sw = np.sqrt(w)
    X = F.design_matrix(u, v, z)
    c, *_ = np.linalg.lstsq(X * sw[:, None], yn * sw, rcond=None)
    np.testing.assert_allclose(res.coef, c, rtol=0, atol=1e-10 * np.abs(c).max())
    assert res.sum_w == pytest.approx(w.sum(), rel=1e-12)
    assert res.rms == pytest.approx(np.sqrt(np.sum(w * (yn - X @ c) ** 2) / w.sum()), rel=1e-9)


def test_chunked_accumulation_equals_one_shot(data):
    u, v, z, y, _, rng = data
    one = F.Accumulator().add(u, v, z, y)
    chunked = F.Accumulator()
    cuts = np.sort(rng.choice(np.arange(1, len(u)), 40, replace=False))
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(u)]):
        chunked.add(u[a:b], v[a:b], z[a:b], y[a:b])
    for name in ("M", "Y", "Z", "S"):
        np.testing.assert_allclose(getattr(chunked, name), getattr(one, name), rtol=1e-12, atol=1e-12 * len(u))
    np.testing.assert_allclose(F.solve(chunked, ALL).coef, F.solve(one, ALL).coef, rtol=1e-10, atol=1e-10)


def test_merge_of_runs_equals_concatenation():
    rng = np.random.default_rng(3)
    runs = []
    coef = rng.uniform(-2, 2, N_TERMS)
    for _ in range(3):
        n = int(rng.integers(5000, 9000))
        u, v = cycles(n, rng)
        z = aux(n, rng)
        y = F.design_matrix(u, v, z) @ coef + 0.3 * rng.standard_normal(n)
        runs.append((u, v, z, y))
    accs = [F.Accumulator().add(*r) for r in runs]
    cat = [np.concatenate(x) for x in zip(*runs)]
    whole = F.Accumulator().add(*cat)
    for merged in (accs[0] + accs[1] + accs[2], sum(accs), accs[0].merge(accs[1]).merge(accs[2])):
        assert merged.n == whole.n
        np.testing.assert_allclose(merged.M, whole.M, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(F.solve(merged).coef, F.solve(whole).coef, rtol=1e-10, atol=1e-10)
    # per-group accumulation in one pass, and subtraction (train = total - fold)
    groups = np.concatenate([np.full(len(r[0]), k) for k, r in enumerate(runs)])
    per = F.accumulate_groups(*cat, groups=groups)
    assert list(per) == [0, 1, 2]
    for k in range(3):
        np.testing.assert_allclose(per[k].M, accs[k].M, rtol=1e-12, atol=1e-9)
    rest = whole - accs[1]
    np.testing.assert_allclose(rest.M, (accs[0] + accs[2]).M, rtol=1e-9, atol=1e-8)
    assert rest.n == accs[0].n + accs[2].n
    # the accumulator state survives JSON
    back = F.Accumulator.from_dict(json.loads(json.dumps(whole.to_dict(), allow_nan=False)))
    for name in ("M", "Y", "Z", "S"):
        np.testing.assert_array_equal(getattr(back, name), getattr(whole, name))


def test_masked_samples_change_nothing(data):
    u, v, z, y, _, rng = data
    n = len(u)
    keep = rng.uniform(size=n) > 0.3
    ref = F.Accumulator().add(u[keep], v[keep], z[keep], y[keep])
    g = [x.copy() for x in (u, v, z, y)]
    for x in g:  # garbage where masked: huge values, and NaN
        x[~keep] = rng.uniform(-1e6, 1e6, (~keep).sum())
        x[np.flatnonzero(~keep)[::7]] = np.nan
    for w in (keep, keep.astype(float), keep.astype(np.int8)):
        acc = F.Accumulator().add(*g, w)
        for name in ("M", "Y", "Z", "S"):
            np.testing.assert_array_equal(getattr(acc, name), getattr(ref, name))
    assert acc.n == keep.sum()
    res = F.fit(*g, keep, terms=ALL)
    np.testing.assert_array_equal(res.coef, F.solve(ref, ALL).coef)


def test_bad_samples_are_refused_by_name(data):
    u, v, z, y, _, _ = data
    acc = F.Accumulator().add(u[:100], v[:100], z[:100], y[:100])
    before = acc.S.copy()
    yb = y[:200].copy()
    yb[150] = np.nan
    with pytest.raises(ValueError, match=r"'y' is nan at sample 150"):
        acc.add(u[:200], v[:200], z[:200], yb)
    np.testing.assert_array_equal(acc.S, before)  # unchanged after the error
    w = np.ones(200)
    w[20] = -1
    with pytest.raises(ValueError, match=r"'w' is -1.0 at sample 20"):
        acc.add(u[:200], v[:200], z[:200], y[:200], w)
    with pytest.raises(ValueError, match=r"'v' has 199 samples"):
        acc.add(u[:200], v[:199], z[:200], y[:200])
    with pytest.raises(ValueError, match="no samples"):
        F.fit(u[:10], v[:10], None, y[:10], np.zeros(10))
    with pytest.raises(ValueError, match="unknown term"):
        F.fit(u, v, z, y, terms=(0, 17))


def test_single_ramp_at_constant_rate_is_refused():
    n = 3000
    u = np.linspace(-1, 1, n)
    v = np.full(n, 0.5)
    coef = np.zeros(N_TERMS)
    coef[[0, 1, 2, 3, 4, 8, 12]] = [1.0, 2.0, -1.0, 0.5, 3.0, 0.7, -0.4]
    y = F.design_matrix(u, v) @ coef
    with pytest.raises(F.UnidentifiableError) as err:
        F.fit(u, v, None, y)
    msg = str(err.value)
    assert "k4 (v) is collinear with k0 (1)" in msg
    assert "k8 (u*v) is collinear with k1 (u)" in msg
    assert "k12 (u^2*v^2) is collinear with k2 (u^2)" in msg
    rate_terms = (4, 5, 6, 8, 9, 10, 11, 12, 13, 14, 15, 16)
    assert set(err.value.collinear) == set(rate_terms)
    assert isinstance(err.value, ValueError)
    res = F.fit(u, v, None, y, drop_unidentifiable=True)
    assert res.terms == (0, 1, 2, 3) and res.dropped == rate_terms
    assert np.all(res.coef[list(rate_terms)] == 0)
    # the kept terms absorb the collinear ones: the fitted curve still reproduces y
    assert np.abs(res.predict(u, v) - y).max() < 1e-9 * np.abs(y).max()
    assert res.collinear[4] == (0,)
    assert json.dumps(res.to_dict(), allow_nan=False)
    # k7 without z is refused by name
    with pytest.raises(F.UnidentifiableError, match=r"k7 \(z\) is zero"):
        F.fit(u, v, None, y, terms=(0, 1, 7))


def sparse_problem(seed, runs=5, n=16000, true=(0, 1, 2, 4, 8)):
    """Runs at different rates with AR(1) noise (correlation time 100 samples)."""
    rng = np.random.default_rng(seed)
    coef = np.zeros(N_TERMS)
    coef[list(true)] = [1.0, 2.0, -1.5, 0.8, 1.2][:len(true)]
    out = []
    for r in range(runs):
        u, v = cycles(n, rng, rates=(0.3 + 0.7 * r / (runs - 1),), seg=(4000, 8000))
        z = aux(n, rng)
        phi = 0.99
        e = lfilter([1.0], [1.0, -phi], rng.standard_normal(n)) * 0.3 * np.sqrt(1 - phi ** 2)
        out.append((u, v, z, F.design_matrix(u, v, z) @ coef + e, np.full(n, r)))
    return [np.concatenate(x) for x in zip(*out)]


@pytest.mark.parametrize("seed", [0, 1])
def test_auto_selects_the_true_support(seed):
    u, v, z, y, g = sparse_problem(seed)
    by_runs = F.fit(u, v, z, y, terms="auto", groups=g)
    assert by_runs.terms == (0, 1, 2, 4, 8)
    assert by_runs.cv["groups"] == 5 and by_runs.requested == ALL
    path = by_runs.cv["path"]
    assert path[by_runs.cv["selected_step"]]["terms"] == [0, 1, 2, 4, 8]
    # CV error falls along the selected path, and the result is JSON
    rms = [p["cv_rms"] for p in path[:by_runs.cv["selected_step"] + 1] if "added" in p]
    assert all(a > b for a, b in zip(rms, rms[1:]))
    assert json.dumps(by_runs.to_dict(), allow_nan=False)
    # one run without groups: contiguous time blocks
    by_blocks = F.fit(u, v, z, y, terms="auto", cv_blocks=8)
    assert by_blocks.terms == (0, 1, 2, 4, 8) and by_blocks.cv["groups"] == 8


def test_auto_needs_groups(data):
    u, v, z, y, _, _ = data
    with pytest.raises(ValueError, match="at least 2 groups"):
        F.fit_accumulators(F.Accumulator().add(u, v, z, y), "auto")
    # a fixed term set with groups reports its cross-validated RMS
    res = F.fit(u, v, z, y, terms=(0, 1), groups=F.block_groups(len(u), 4))
    assert res.cv["method"] == "fixed" and res.cv["cv_rms"] >= res.rms


def test_predict_matches_design(data):
    u, v, z, _, coef, _ = data
    np.testing.assert_allclose(F.predict(coef, u, v, z), F.design_matrix(u, v, z) @ coef, rtol=1e-12, atol=1e-11)


SMALL = np.random.default_rng(11)
_U, _V = cycles(3000, SMALL, seg=(300, 900))
_Z = aux(3000, SMALL)
_Y = F.design_matrix(_U, _V, _Z) @ SMALL.uniform(-2, 2, N_TERMS) + 0.1 * SMALL.standard_normal(3000)
_REF = F.solve(F.Accumulator().add(_U, _V, _Z, _Y), ALL).coef


@settings(max_examples=30, deadline=None)
@given(cuts=st.lists(st.integers(1, 2999), max_size=12, unique=True), order=st.randoms(use_true_random=False))
def test_fit_is_invariant_to_chunking_and_chunk_order(cuts, order):
    bounds = list(zip([0] + sorted(cuts), sorted(cuts) + [3000]))
    order.shuffle(bounds)
    acc = F.Accumulator()
    for a, b in bounds:
        acc.add(_U[a:b], _V[a:b], _Z[a:b], _Y[a:b])
    assert acc.n == 3000
    np.testing.assert_allclose(F.solve(acc, ALL).coef, _REF, rtol=1e-9, atol=1e-9 * np.abs(_REF).max())


@pytest.mark.benchmark
@pytest.mark.parametrize("how", ["diff", "auto"])
def test_bench_fit_time_rate_auto_vs_fixed(benchmark, how):
    """Fit time of one foreign mode-reversal training run (4 degC/min, whole chamber profile; the
    accuracy benchmark's training run) with terms auto: the fixed default rate estimator (diff)
    against rate estimator 'auto' (every RATE_CANDIDATE fitted).  Run:
    python -m pytest tests/test_fit.py -m benchmark -k rate_auto"""
    from host_tools.golden.compensate import fit_config_from_logs
    from host_tools.fitting.fit import fit_logs
    from host_tools.fitting.fit_rate import fit_auto_rate
    from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

    log = simulate_foreign(foreign_device(3), 4.0, True, 0, 0)
    rev = {"combiner": "pair", "order": "regress_first"}

    def run():
        if how == "auto":
            return fit_auto_rate([log], "auto", reversal=rev)[0]
        return fit_logs([log], fit_config_from_logs([log], rate_estimator="diff", reversal=rev), "auto")[0]

    model = benchmark.pedantic(run, rounds=3, iterations=1, warmup_rounds=1)
    assert model.coef_mode2 is not None and np.all(np.isfinite(model.coef))
    benchmark.extra_info.update({"samples": len(log), "rate": model.config.rate.estimator})


def test_rate_auto_keeps_the_preferred_candidate_unless_another_beats_it_by_the_margin():
    """fit_auto_rate's rule: the preferred candidate (RATE_PREFERRED, iir shift 9, by default) unless
    the least-CV candidate's CV rms is below (1 - margin) x the preferred one's.  The preferred one
    here is the worse of two in CV; a margin on either side of their ratio flips the choice, and the
    rule is written in model.json."""
    from host_tools.fitting.fit_rate import RATE_CANDIDATES, RATE_PREFER_MARGIN, RATE_PREFERRED, fit_auto_rate
    from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

    assert RATE_PREFERRED in RATE_CANDIDATES and 0.0 < RATE_PREFER_MARGIN < 1.0
    log = simulate_foreign(foreign_device(3), 4.0, True, 0, 0, 3000.0)
    cands = (RATE_CANDIDATES[0], RATE_CANDIDATES[-1])          # diff, iir 9
    terms = (0, 1, 4, 5)
    sel = fit_auto_rate([log], terms, candidates=cands, prefer=None)[0].fit["rate_selection"]
    cv = {r["estimator"]: r["cv_rms"] for r in sel["candidates"]}
    (best, cv_best), (worse, cv_worse) = sorted(cv.items(), key=lambda kv: kv[1])
    assert sel["chosen"] == best and cv_best < cv_worse
    worse_c = cands[["diff", "iir shift=9"].index(worse)]
    ratio = cv_best / cv_worse
    for margin, want in ((0.5 * (1.0 - ratio), best), (1.0 - 0.5 * ratio, worse)):
        model, res = fit_auto_rate([log], terms, candidates=cands, prefer=worse_c, prefer_margin=margin)
        got = model.fit["rate_selection"]
        assert got["chosen"] == want and got["preferred"] == worse and got["prefer_margin"] == margin
        assert res.cv["cv_rms"] == pytest.approx(cv[want], rel=1e-12)
        assert got["chosen"].split()[0] == model.config.rate.estimator
    # the default prefers iir shift 9
    got = fit_auto_rate([log], terms, candidates=cands)[0].fit["rate_selection"]
    want = "diff" if cv["diff"] < (1.0 - RATE_PREFER_MARGIN) * cv["iir shift=9"] else "iir shift=9"
    assert got["preferred"] == "iir shift=9" and got["chosen"] == want


def test_rate_auto_on_common_samples_scores_every_candidate_on_the_same_samples():
    """fit_auto_rate(samples='common'): each candidate's reported CV rms is its fit on the samples
    used by every candidate (fit_logs masks), the least one is chosen and then refitted on all its
    own samples; 'own' (the default) scores each on its own samples.  Bad options are refused."""
    from host_tools.golden.compensate import fit_config_from_logs, prepare
    from host_tools.fitting.fit import fit_logs
    from host_tools.fitting.fit_rate import RATE_CANDIDATES, fit_auto_rate
    from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign

    log = simulate_foreign(foreign_device(3), 4.0, True, 0, 0, 3000.0)
    cands = (RATE_CANDIDATES[0], ("diffn", 600, 4))            # diff (warm-up 1), diffn 600 (600)
    terms = (0, 1, 4, 5)
    cfgs = [fit_config_from_logs([log], rate_estimator=e, n=n, shift=s) for e, n, s in cands]
    used = [prepare(log, c).used for c in cfgs]
    common = used[0] & used[1]
    assert common.sum() < used[0].sum()                        # the long warm-up removes samples
    own = [fit_logs([log], c, terms, blocks=True)[1] for c in cfgs]
    com = [fit_logs([log], c, terms, blocks=True, masks=[common])[1] for c in cfgs]
    assert com[0].n == common.sum() == com[1].n and own[0].n == used[0].sum()
    for samples, want in (("own", own), ("common", com)):
        model, res = fit_auto_rate([log], terms, candidates=cands, samples=samples, prefer=None)
        sel = model.fit["rate_selection"]
        assert [r["cv_rms"] for r in sel["candidates"]] == pytest.approx([r.cv["cv_rms"] for r in want], rel=1e-12)
        k = int(np.argmin([r.cv["cv_rms"] for r in want]))
        assert sel["chosen"] == ("diff", "diffn n=600")[k] and sel["samples"] == samples
        assert res.n == used[k].sum()                          # the chosen one on all its own samples
        assert res.cv["cv_rms"] == pytest.approx(own[k].cv["cv_rms"], rel=1e-12)
    with pytest.raises(ValueError, match="samples"):
        fit_auto_rate([log], terms, candidates=cands, samples="all")
    with pytest.raises(ValueError, match="prefer_margin"):
        fit_auto_rate([log], terms, candidates=cands, prefer_margin=1.0)
    with pytest.raises(ValueError, match="mask"):
        fit_logs([log], cfgs[0], terms, masks=[common[:-1]])
