"""The example runs of docs/GETTING_STARTED.md (section 3, read from the file) and of the README's
Python example (the same runs) identify the 17-term model: through host_tools.api, `hdrg fit`'s
defaults keep it over the cubic (rate terms and their curvature identified, a rate term and a cross
term among the terms kept), `--terms all` fits all 17 terms, and the model beats the cubic on the
held-out run."""
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from host_tools import api

ROOT = Path(__file__).resolve().parent.parent
SIMULATE = re.compile(r"^hdrg simulate --scenario (\S+) --seed (\d+) -o (\S+)", re.M)
RATE_TERMS = {4, 5, 6}
CROSS_TERMS = set(range(8, 17))


def getting_started_runs() -> dict:
    """{file name: (scenario, seed)} of the `hdrg simulate` lines of section 3."""
    text = (ROOT / "docs" / "GETTING_STARTED.md").read_text(encoding="utf-8")
    section = text[text.index("## 3. Step by step"):text.index("## 4.")]
    return {out: (scenario, int(seed)) for scenario, seed, out in SIMULATE.findall(section)}


@pytest.fixture(scope="module")
def runs():
    return {name: api.simulate(scenario, seed=seed) for name, (scenario, seed) in getting_started_runs().items()}


def test_getting_started_names_two_training_runs_at_two_rates_and_a_check_run():
    found = getting_started_runs()
    assert set(found) == {"train_4dpm.csv", "train_2dpm.csv", "check.csv"}
    assert found["train_4dpm.csv"][0] == "mr-one-cycle-4dpm" and found["train_2dpm.csv"][0] == "mr-one-cycle-2dpm"
    assert len({seed for _, seed in found.values()}) == 3          # three power-ons


def test_the_example_runs_keep_the_17_term_model(runs):
    train = [runs["train_4dpm.csv"], runs["train_2dpm.csv"]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        outcome = api.fit_with_result(train)
        every = api.fit(train, terms="all")
        cubic = api.fit(train, terms="k0,k1,k2,k3")
    model = outcome.model
    ident = model.fit["identifiability"]
    assert ident["groups"]["rate"]["identified"] and ident["groups"]["rate_curvature"]["identified"]
    assert model.fit["guard"]["chosen"] == "17-term model", model.fit["guard"]
    assert set(model.terms) & RATE_TERMS and set(model.terms) & CROSS_TERMS, outcome.term_labels
    assert every.terms == tuple(range(17)) and api.term_labels(every) == tuple(f"k{k}" for k in range(17))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        held = {name: api.compensate(runs["check.csv"], m) for name, m in
                (("default", model), ("all", every), ("cubic", cubic))}
    std = {name: float(np.std(out.rate_dph[out.valid])) for name, out in held.items()}
    assert std["default"] < 0.6 * std["cubic"] and std["all"] < 0.6 * std["cubic"], std


def test_one_sign_of_dt_or_one_run_alone_keeps_the_cubic(runs):
    one_sign = api.simulate("paper-mr-cycle-4dpm", seed=2, duration_s=10800)    # cools, then holds
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for train in ([one_sign], [runs["train_4dpm.csv"]]):
            assert api.fit(train).terms == (0, 1, 2, 3)
