import os, warnings
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np
from host_tools.golden.runlog import read_csv
import os
D = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "data") + "/"
def load_tofu(ax):
    r = read_csv(D + f"tofupilot-imu-thermal/tofupilot-imu-{ax}.csv")
    return {k: np.asarray(v, float) for k, v in r.columns.items()}
def load_psim(ax):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = read_csv(D + f"psim-tvac-lsm6dsm/psim-tvac-{ax}.csv")
    c = {k: np.asarray(v, float) for k, v in r.columns.items()}
    return c, np.asarray(r.segments)
