"""What the foreign family's own power-on self-heating costs the loop's starting model, on the clean
mode-reversal controls of a loop-benchmark seed (docs/LOOP.md, "Self-heating").

Per clean mode-reversal run of `hdrg bench loop --runs N --seed S` (the same devices and runs): the
held-out error of the starting model (`hdrg fit` defaults, trained on the 4 degC/min run, held out on
the 2 degC/min run of another power-on) with the family's physics as drawn, and with the
self-heating removed from the device (rise 0, training and held-out runs alike).  base /
no_self_heating is what the clean physics' self-heating costs; the loop benchmark's own record gives
what the loop found on those runs.  The held-out error is the loop's: the std of 100-s means of the
compensated held-out output (1-s where 100 s is undefined), deg/h.

    python docs/studies/self_heating_cost.py docs/studies/loop_seed0_previous_defaults.json > docs/studies/self_heating_cost_seed0.jsonl
"""
import copy
import json
import sys
import warnings

from host_tools.fitting.diagnose import base_model, base_options
from host_tools.fitting.diagnose_confirm import error_stats
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign


def base_error(train, hold) -> float:
    """Held-out error of the loop's starting model fitted on ``train``."""
    model = base_model([train], base_options(reversal=train.reversal))[0]
    stats = error_stats([hold], model)
    return stats["std100_dph"] if stats["std100_dph"] is not None else stats["std_dph"]


def cost(device_seed: int) -> dict:
    dev = foreign_device(device_seed)
    cold = copy.deepcopy(dev)
    cold.self_heating.update(rise_c=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base = base_error(simulate_foreign(dev, 4.0, True, 0, 0), simulate_foreign(dev, 2.0, True, 1, 1))
        no_sh = base_error(simulate_foreign(cold, 4.0, True, 0, 0), simulate_foreign(cold, 2.0, True, 1, 1))
    return {"device": device_seed, "self_heating": dev.self_heating, "base": base, "no_self_heating": no_sh,
            "ratio": base / no_sh}


def main(path):
    with open(path) as fh:
        records = json.load(fh)["records"]
    for rec in records:
        if rec["effect"] is None and rec["reversal"]:
            row = cost(rec["device"])
            row.update(i=rec["i"], verdict=rec["verdict"], final=rec["final"])
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
