"""A simulated lot for `hdrg lot` (``hdrg simulate --lot N -o DIR``): N devices of the foreign
family (host_tools.simulation.sim_foreign: each seed its own randomized physics), each with a
training run and a held-out run at another chamber rate and power-on, and the manifest."""
from __future__ import annotations

import os

from host_tools.atomic import atomic_open
from host_tools.golden import runlog
from host_tools.simulation.sim_foreign import foreign_device, simulate_foreign


def write_lot(out_dir, n: int, seed: int = 0, chamber_rate: float = 4.0, holdout_rate: float | None = 2.0,
              reversal: bool = True, power_on: int = 0, noise_seed: int = 0, duration_s: float | None = None,
              effect=None, strength: float = 1.0, thermal: bool = True) -> list:
    """Simulate a lot of ``n`` foreign devices (seeds ``seed`` .. ``seed + n - 1``) into ``out_dir``:
    ``foreign-SEED/train.csv`` (chamber rate ``chamber_rate``, ``power_on``, ``noise_seed``),
    ``foreign-SEED/holdout.csv`` (``holdout_rate``, power-on and noise seed + 1; None: no held-out
    run) and ``manifest.csv`` (written last).  Returns the device ids."""
    if n < 1:
        raise ValueError(f"a lot needs at least 1 device (--lot), not {n}")
    os.makedirs(out_dir, exist_ok=True)
    rows = ["device,train,holdout,power_on_s"]
    ids = []
    for s in range(seed, seed + n):
        dev = foreign_device(s)
        dev_id = f"foreign-{s}"
        os.makedirs(os.path.join(out_dir, dev_id), exist_ok=True)
        runs = [("train", chamber_rate, power_on, noise_seed)]
        if holdout_rate is not None:
            runs.append(("holdout", holdout_rate, power_on + 1, noise_seed + 1))
        for role, cpm, pon, nseed in runs:
            log = simulate_foreign(dev, cpm, reversal, pon, nseed, duration_s, thermal, effect, strength)
            runlog.write(log, os.path.join(out_dir, dev_id, f"{role}.csv"))
        rows.append(f"{dev_id},{dev_id}/train.csv," + (f"{dev_id}/holdout.csv" if holdout_rate is not None else "") + ",")
        ids.append(dev_id)
    with atomic_open(os.path.join(out_dir, "manifest.csv"), "w", encoding="utf-8") as fh:
        fh.write("\n".join(rows) + "\n")
    return ids
