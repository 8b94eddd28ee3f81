"""Is a turn-on named on a CLEAN foreign run a false discovery?  The power-on self-heating.

    PYTHONPATH=. python docs/loop/self_heating.py NPLAN SEED SECOND_TRAIN OUT.jsonl [I ...]
    PYTHONPATH=. python docs/loop/self_heating.py --table OUT.jsonl... --bench BENCH.json...

Every foreign device heats one thermal node after power-on (sim_foreign: ``rise_c`` 0.5..3 degC,
``tau_s``), part of the family's clean physics.  When that node is not the one the proxy and the
bias share, the 17 terms of the proxy cannot follow it and the compensated output carries a
decay with the self-heating's time constant: an effect the model lacks, in a run that carries no
undeclared effect.  For the clean runs of ``loop.plan(NPLAN, SEED)`` (or runs I ...) with the
benchmark's training runs (SECOND_TRAIN: 0 = one run, else the second run's degC/min) this
records, with the held-out metric of the loop:

* ``base``: the base model's held-out error (as the bench's ``base``);
* ``base_no_sh``: the same with the device's self-heating removed (rise 0; same noise), and
  ``sh_ratio = base / base_no_sh`` (the self-heating's ``effect_ratio``);
* ``sh_fit``: the base terms plus the loop's own turn_on candidate at the device's TRUE
  self-heating time constant, fitted on the training runs, and ``sh_fit_ratio = base / sh_fit``
  (the ``oracle_fit_ratio`` of the self-heating).

``--table`` joins these with the bench records of the same plan: the clean runs whose verdict is
"effect found", the turn-on steps among them and their time constants against the device's.
docs/LOOP.md, "Self-heating: the clean runs' own turn-on" gives the result.
"""
import copy
import json
import sys
import warnings

from host_tools.bench import loop
from host_tools.fitting.diagnose import _score, error_stats
from host_tools.fitting.diagnose_scan import _poly_terms, refit_with
from host_tools.fitting.effects import _term
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign


def one(spec, second_train):
    dev = foreign_device(spec["device"])
    quiet = copy.deepcopy(dev)
    quiet.self_heating["rise_c"] = 0.0
    rev = spec["reversal"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        train = loop._training_runs(dev, rev, None, second_train or None)
        hold = simulate_foreign(dev, 2.0, rev, 1, 1)
        base = loop._base_model(train)
        err = _score(error_stats([hold], base))[0]
        qtrain = loop._training_runs(quiet, rev, None, second_train or None)
        qhold = simulate_foreign(quiet, 2.0, rev, 1, 1)
        err_q = loop._base_error(qtrain, qhold)
        tau = dev.self_heating["tau_s"]
        fit, _ = refit_with(train, base.config, _poly_terms(base), [_term("decay_on", "turn_on", tau_s=tau)])
        err_f = _score(error_stats([hold], fit))[0]
    return {"i": spec["i"], "device": spec["device"], "reversal": rev, "second_train": second_train,
            "self_heating": dict(dev.self_heating), "resonator_node": dev.resonator_node,
            "common_node": dev.common_node, "damping_node": dev.damping_node,
            "base": err, "base_no_sh": err_q, "sh_ratio": err / err_q, "sh_fit": err_f, "sh_fit_ratio": err / err_f}


def measure(nplan, seed, second_train, out, only=()):
    specs = [s for s in loop.plan(nplan, seed) if s["effect"] is None and (not only or s["i"] in only)]
    with open(out, "a") as fh:
        for s in specs:
            rec = one(s, second_train)
            fh.write(json.dumps(rec) + "\n")
            fh.flush()
            print(rec["i"], f"sh_ratio {rec['sh_ratio']:.2f} sh_fit_ratio {rec['sh_fit_ratio']:.2f}", flush=True)


def table(outs, benches):
    recs = {}
    for f in outs:
        for line in open(f):
            r = json.loads(line)
            recs[(r["device"], r["second_train"])] = r
    for bf in benches:
        bench = json.load(open(bf))
        for b in bench["records"]:
            if b["effect"] is not None:
                continue
            two = 3.0 if "two_rates" in bf else 0
            r = recs.get((b["device"], two))
            if r is None:
                continue
            turn = [s for s in b["steps"] if s["effect"] == "turn_on" and s["confirmed"] and s["material"]]
            print(f"{bf.split('/')[-1]} run {b['i']} {'MR ' if b['reversal'] else 'FTR'} verdict {b['verdict']:28s} "
                  f"sh node n{r['self_heating']['node']} (res n{r['resonator_node']}, common n{r['common_node']}, "
                  f"damping n{r['damping_node']}) tau {r['self_heating']['tau_s']:.0f} s rise {r['self_heating']['rise_c']:.1f} C | "
                  f"base {b['base']:.3f} vs {r['base']:.3f}, sh_ratio {r['sh_ratio']:.2f}, sh_fit_ratio {r['sh_fit_ratio']:.2f} | "
                  f"turn_on found: {[round(s['params']['tau_s']) for s in turn]}")


if __name__ == "__main__":
    if sys.argv[1] == "--table":
        k = sys.argv.index("--bench")
        table(sys.argv[2:k], sys.argv[k + 1:])
    else:
        measure(int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4], [int(a) for a in sys.argv[5:]])
