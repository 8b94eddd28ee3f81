"""What the foreign family's own power-on self-heating costs the loop's starting model, on the clean
mode-reversal controls of a loop-bench seed (round 2 session 13).

Per clean MR run of `hdrg bench loop --runs N --seed S` (the same devices and runs): the held-out
error of the starting model (`hdrg fit` defaults, trained on the 4 degC/min run, held out on the
2 degC/min run of another power-on) with the family's physics as drawn, and with the self-heating
removed from the device (rise 0, training and held-out runs alike).  base / no_self_heating is what
the clean physics' self-heating costs; the loop's own records give what it found on those runs.

    PYTHONPATH=. python docs/loop/self_heating_cost.py RECORDS.json > OUT.jsonl
"""
import copy
import json
import sys
import warnings

from host_tools.bench import loop as L
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign


def cost(device_seed: int) -> dict:
    dev = foreign_device(device_seed)
    cold = copy.deepcopy(dev)
    cold.self_heating.update(rise_c=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        base = L._base_error(simulate_foreign(dev, 4.0, True, 0, 0), simulate_foreign(dev, 2.0, True, 1, 1))
        no_sh = L._base_error(simulate_foreign(cold, 4.0, True, 0, 0), simulate_foreign(cold, 2.0, True, 1, 1))
    return {"device": device_seed, "self_heating": dev.self_heating, "base": base, "no_self_heating": no_sh,
            "ratio": base / no_sh}


def main(path):
    for rec in json.load(open(path))["records"]:
        if rec["effect"] is None and rec["reversal"]:
            row = cost(rec["device"])
            row.update(i=rec["i"], verdict=rec["verdict"], final=rec["final"])
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(sys.argv[1])
