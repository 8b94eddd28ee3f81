"""Which off-resonator bias makes the mode-reversal tail?

For the set-0 devices above 1.5 (held-out std / floor, `hdrg fit` defaults, mr/default), the same
device with (a) the common-mode bias moved to the resonator's node, (b) the damping bias moved
there, (c) both (the ablation row "bias on the resonator node").  Everything else as drawn.

    python docs/studies/tail_nodes.py 1 5 9 10 13 17 18 27 31 32 43 44 46 > docs/studies/tail_nodes.jsonl
"""
import copy
import json
import sys
import warnings

from host_tools.bench.accuracy import SEED_STRIDE, evaluate_device, select_options
from host_tools.simulation.sim_foreign import foreign_device


def common_on_resonator(d):
    d.common_node = d.resonator_node


def damping_on_resonator(d):
    d.damping_node = d.resonator_node


def both_on_resonator(d):
    d.common_node = d.damping_node = d.resonator_node


VARIANTS = {"as drawn": lambda d: None, "common on resonator": common_on_resonator, "damping on resonator": damping_on_resonator,
            "both on resonator": both_on_resonator}


def main(indices, set_seed=0):
    options = select_options(["mr/default"])
    for i in indices:
        row = {"device": set_seed * SEED_STRIDE + i}
        for label, change in VARIANTS.items():
            dev = copy.deepcopy(foreign_device(set_seed * SEED_STRIDE + i))
            nodes = (dev.resonator_node, dev.damping_node, dev.common_node)
            change(dev)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                row[label] = evaluate_device(dev, options)["ratio"]["mr/default"]
        row["nodes (resonator, damping, common)"] = nodes
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]])
