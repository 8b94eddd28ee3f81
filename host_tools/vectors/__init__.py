"""`hdrg vectors`: deterministic test vectors of the fixed-point pipeline (firmware_ref/FORMATS.md),
to prove a firmware or RTL implementation against: generate, verify, check an external program.

Sets (each a CSV with a header, a ``$readmemh`` file and, where tables are used, a table file):

* ``primitives``: RHU, MULRHU, FLOORDIV, DIVROUND, DIVRS, CLAMP, SAT at ties, extremes and sign
  edges (firmware_ref.arith is the reference);
* ``evaluator``: the Horner evaluator (FORMATS.md step 5) on random integer tables, one-hot
  tables (one mantissa at +-(2^31 - 1)), tables at the accumulator bound and at the exponent
  extremes, realistic quantized tables; u, v at and inside +-2^30, z beyond +-2^30 (clamped);
* ``sequencer``: the whole pipeline with every output field, self-timed (power-on, the paper's
  30/120 s cycles, zero-length exchanges, one-sample dwells, settling >= dwell, long runs) and
  log-driven (corner streams of host_tools.vectors.builders, staleness limit edges, trend slope and
  output-word saturation, long windows, random models and streams);
* ``e2e``: simulated chamber runs (host_tools.simulation.sim, fixed seeds, short) with models fitted by
  host_tools.fitting.fit.fit_logs on host_tools.golden.compensate.fit_config_from_logs and quantized, through
  the whole pipeline with every intermediate: the input words (proxy F or T, rate R), u, v, z,
  the rate sum, the window sum, the Horner rows, the k7 term, the accumulator t, B, y, the
  output words, valid, flags;
* ``aux``: tables with aux generators (aux_gen 1, FORMATS.md "Aux generators"): every kind alone
  (z = its g), signs, powers, short and long filters, decays with restarts and exchange resets,
  ramps, oscillators at large and negative K, weight-sum clamps, coefficient extremes, random
  multi-term tables, and a simulated run with a fitted aux model; the inputs add K and the aux
  words A0..A3 (an ``S`` line of 11 fields), the outputs are the 16 ``O`` fields (z is the
  generated z).

Everything in the vector files is an integer (the CSV op names of ``primitives`` aside); seeds are
fixed; the manifest has no timestamps.  Outputs come from the numba kernel
(firmware_ref.kernel); every sample of every case is checked against the per-sample Python
reference (firmware_ref.compensate.run_reference, firmware_ref.evaluator), whose trace gives the
intermediates the kernel does not output (acc/cnt, the Horner rows, the k7 term, t): no second
evaluator or combiner here.

The fitted models of ``e2e`` are rounded to 7 significant digits (configuration and
coefficients) before quantization, so that an ulp of difference in the float simulator or the
fitter between machines does not flip a mantissa (byte-identical regeneration).

``manifest.json``: format and generator versions, the SHA-256 fingerprint of the algorithm sources
(``SOURCE_GLOBS``), the configuration (seeds, sizes, models), every coefficient table (words and
fields), each set's columns, ``$readmemh`` record layout and cases, and the SHA-256 of every file.
``generate`` refuses to overwrite vectors whose content changed unless GENERATOR_VERSION or
FORMAT_VERSION was bumped (or ``--force``).

``check-impl`` drives an external program through the line protocol of firmware_ref/c/README.md
(also in vectors/README.md): ``TABLE``, ``S``, ``EVAL`` and the primitive requests.

Layout (CMSIS-DSP style: generators, pattern files and the runner apart): ``spec`` (record spec,
versions), ``files`` (file formats + manifest), one case generator per set (``primitives``,
``evaluator``, ``sequencer``, ``e2e``, ``aux``; model/stream builders in ``builders``),
``pipeline`` (recomputing the pipeline sets through the kernel and the reference), ``build``
(generate/verify), ``runner`` (``check-impl``); the command is host_tools.cli.vectors.  The names below are re-exported here.
"""
from host_tools.vectors.spec import (AUX_FIELDS, AUX_IN_FIELDS, AUX_INPUTS, DEFAULT_DIR, E2E_FIELDS, EVAL_EXTRA,  # noqa: F401
                                     EVAL_FIELDS, EVAL_INPUTS, FORMAT_VERSION, GENERATOR_VERSION, IN_FIELDS,
                                     O_FIELDS, O_NAMES, PRIM_ARITY, PRIM_FIELDS, PRIM_FLAGGED, PRIM_INPUTS,
                                     PRIM_OPS, PY_CHECK, ROOT, ROW_FIELDS, SEED, SEQ_FIELDS, SEQ_INPUTS, SETS,
                                     SOURCE_GLOBS, STALE_MESSAGE, VectorsError)
from host_tools.vectors.files import (VectorSet, dump_manifest, make_manifest, parse_csv,  # noqa: F401
                                      read_manifest, render_all, render_csv, render_mem, source_fingerprint)
from host_tools.vectors.build import build_sets, generate, load_set, staleness, verify  # noqa: F401
from host_tools.vectors.runner import check_impl  # noqa: F401
