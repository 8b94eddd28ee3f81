"""The vectors' record spec: format/generator versions, paths, the sets, the CSV columns and
``$readmemh`` record layouts of each set (fields and widths, MSB first), the errors.
"""
from __future__ import annotations

from pathlib import Path


FORMAT_VERSION = 4          # file layout (columns, record layout, manifest keys); 2: the aux set (K, A0..A3);
                            # 3: table layout v2 (73+ words), the evaluator's bank column;
                            # 4: RESTART bit 1 = the input-invalid bit, the validity set (the aux set's columns)
GENERATOR_VERSION = 7       # the cases and their values; bump when a vector changes; 2: RHUW, SIN, aux;
                            # 3: regress_first (two banks, residual combiner pair/trend/none)
                            # 4: table layout v3 (the iir's start-up gear, warm-up 1), the iir_gear_log case
                            # 5: the input-invalid bit (the validity set; its aux_gen 1 cases)
                            # 6: table layout v4 (F word LSB 2^-15 Hz), the drive-frequency cases
                            # 7: AUX_MAX_TERMS 16: aux tables of 7..16 terms (random_<n>_terms,
                            #    max_terms_every_kind: 255 words, sim_aux_16)
STALE_MESSAGE = ("vectors are stale: regenerate with `hdrg vectors generate -o vectors/` and bump "
                 "GENERATOR_VERSION/FORMAT_VERSION")
ROOT = Path(__file__).resolve().parents[2]
DEFAULT_DIR = ROOT / "vectors"
SOURCE_GLOBS = ("firmware_ref/*.py", "firmware_ref/c/*.c", "firmware_ref/c/*.h",
                "host_tools/fixed/fixed_point.py", "host_tools/vectors/builders.py",
                "host_tools/golden/input_check.py")   # what the vectors compute with
SETS = ("primitives", "evaluator", "sequencer", "e2e", "aux", "validity")
PY_CHECK = 300              # the manifest's py_check_samples_per_case: at least this many samples per case are
                            # checked against the Python reference (since the package split: every sample)
SEED = 20240611             # the one seed; every set derives its generators from it

# -- columns ------------------------------------------------------------------------------------------
PRIM_OPS = ("RHU", "MULRHU", "FLOORDIV", "DIVROUND", "DIVRS", "CLAMP", "SAT", "RHUW", "SIN")
PRIM_ARITY = {"RHU": 2, "MULRHU": 3, "FLOORDIV": 2, "DIVROUND": 2, "DIVRS": 3, "CLAMP": 3, "SAT": 2, "RHUW": 3,
              "SIN": 1}
PRIM_FLAGGED = ("CLAMP", "SAT")          # answer "R value clamped"
# (name, bits in the $readmemh record); the CSV has these columns plus the extra ones
PRIM_FIELDS = (("op", 8), ("a", 64), ("b", 64), ("c", 64), ("result", 64), ("flag", 8))
PRIM_INPUTS = ("op", "a", "b", "c")
EVAL_FIELDS = (("case", 16), ("u", 32), ("v", 32), ("z", 32), ("bank", 8), ("b", 64), ("zclamped", 8))
EVAL_EXTRA = ("row0", "row1", "row2", "row3", "zterm", "t")          # CSV only
EVAL_INPUTS = ("case", "u", "v", "z", "bank")
IN_FIELDS = (("F", 32), ("T", 32), ("R", 32), ("MODE", 8), ("RESTART", 8), ("Z", 32))
O_FIELDS = (("state", 8), ("vs", 8), ("mode", 8), ("sign", 8), ("u", 32), ("v", 32), ("z", 32), ("s", 64),
            ("acc", 64), ("cnt", 32), ("y", 64), ("b", 64), ("out", 32), ("bias", 32), ("valid", 8), ("flags", 8))
O_NAMES = tuple(n for n, _ in O_FIELDS)           # the 16 fields of an `O` line, in order
ROW_FIELDS = (("row0", 32), ("row1", 32), ("row2", 32), ("row3", 32), ("zterm", 32), ("t", 32))
SEQ_FIELDS = (("case", 16),) + IN_FIELDS + O_FIELDS
E2E_FIELDS = SEQ_FIELDS + ROW_FIELDS
SEQ_INPUTS = ("case", "i") + tuple(n for n, _ in IN_FIELDS)
AUX_IN_FIELDS = IN_FIELDS + (("K", 64), ("A0", 32), ("A1", 32), ("A2", 32), ("A3", 32))
AUX_FIELDS = (("case", 16),) + AUX_IN_FIELDS + O_FIELDS
AUX_INPUTS = ("case", "i") + tuple(n for n, _ in AUX_IN_FIELDS)


class VectorsError(ValueError):
    """Vectors that cannot be used: a missing or corrupt file, an unsupported format."""
