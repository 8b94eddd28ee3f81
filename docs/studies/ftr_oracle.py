"""What no FTR model can remove on the foreign family: the held-out power-on's damping change.

For every device of an accuracy record (docs/studies/accuracy_set*.json), the FTR held-out run
(2 degC/min, power-on 1, noise seed 1) is compensated by the ORACLE: the device's exact bias as it
was at the training power-on (the same run simulated with power-on 0: same temperatures, noise,
self-heating and effects; only the power-on's damping change differs).  What is left is the noise
plus the change of the damping term between the two power-ons, which an FTR model fitted on power-on
0 cannot know.  A second, kinder oracle knows the device's mean damping scale (1, the centre of the
power-on draws) instead of the training power-on's: what is left is the held-out power-on's own
draw d_scale(1) x B_D.  Held-out std at 1 s / floor, the floor as `hdrg bench accuracy` takes it (the same run without
thermal terms); the std over every sample of the run (the bench's over the model's valid ones:
all but the rate estimator's warm-up).

    python docs/studies/ftr_oracle.py docs/studies/accuracy_set0.json docs/studies/accuracy_set1.json docs/studies/accuracy_set2.json > docs/studies/ftr_oracle.txt
"""
import json
import sys

import numpy as np

from host_tools.bench.accuracy import floor_of
from host_tools.simulation.sim_foreign import damping_bias, foreign_device, simulate_foreign


def oracle_ratios(seed: int, holdout_rate: float = 2.0) -> tuple:
    """(as trained, mean scale): held-out std / floor of the two oracles (module doc)."""
    dev = foreign_device(seed)
    hold = simulate_foreign(dev, holdout_rate, False, 1, 1)
    as_trained = simulate_foreign(dev, holdout_rate, False, 0, 1)     # the training power-on's damping
    floor = simulate_foreign(dev, holdout_rate, False, 1, 1, thermal=False)
    out = floor.rate_dph + (hold.rate_dph - as_trained.rate_dph)    # noise + the power-on change
    mean_scale = floor.rate_dph + dev.damping_change(1)[0] * damping_bias(dev, holdout_rate)
    f = floor_of(floor)
    return float(np.std(out)) / f, float(np.std(mean_scale)) / f


def main(paths):
    for path in paths:
        recs = json.load(open(path))["records"]
        both = np.array([oracle_ratios(r["seed"]) for r in recs])
        ratios, kind = both[:, 0], both[:, 1]
        actual = np.array([r["ratio"]["ftr/default"] for r in recs])
        print(f"{path}: {len(recs)} devices; FTR held-out std / floor, median / p90: oracle (the training "
              f"power-on's exact bias) {np.median(ratios):.2f} / {np.percentile(ratios, 90):.2f}, "
              f"{int(np.sum(ratios > 1.3))} devices above 1.3; oracle knowing the mean scale {np.median(kind):.2f} / "
              f"{np.percentile(kind, 90):.2f}, {int(np.sum(kind > 1.3))} above 1.3; ftr/default {np.nanmedian(actual):.2f} / "
              f"{np.nanpercentile(actual, 90):.2f}")
        print(json.dumps({"source": path, "seeds": [r["seed"] for r in recs],
                          "oracle_ratio": [round(x, 4) for x in ratios],
                          "mean_scale_ratio": [round(x, 4) for x in kind]}))


if __name__ == "__main__":
    main(sys.argv[1:])
