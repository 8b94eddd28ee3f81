"""Calibrate a production lot: ``hdrg lot MANIFEST -o OUT [--spec SPEC.json] [--workers N | --scheduler ADDRESS]``.

Per device: the default fit of its training run(s) (what ``hdrg fit RUN...`` does), the check on
its held-out run(s), quantization and export of its coefficient table, and pass/fail against a
spec; then one report over the lot.  A lot is resumable and gives the same bytes whatever the
engine or the number of workers.

**Manifest** (CSV, UTF-8 with or without a BOM, a header line; blank lines and lines starting with ``#`` are skipped;
paths relative to the manifest's directory)::

    device,train,holdout,power_on_s
    A0001,A0001/train.csv,A0001/holdout.csv,
    A0002,A0002/train_4cpm.csv;A0002/train_2cpm.csv,A0002/holdout.csv,12.5

* ``device`` (required): the device id, 1 to 64 characters of letters, digits, ``_``, ``.``,
  ``-``, starting with a letter or a digit (it names the device's folder and is written into its
  tables).  Any other id is refused.
* ``train`` (required): the training run log(s) (CSV or .npz), several separated by ``;``
  (fitted together, each run's offset removed: ``hdrg fit``).
* ``holdout`` (optional): the held-out run log(s), ``;``-separated; empty: no held-out check.
* ``power_on_s`` (optional): the ``t_s`` [s] at which the device was powered on in each held-out
  run (one value per held-out run, or one for all; empty: the run's first sample); the held-out
  figures count from there.

A directory instead of a CSV: its ``manifest.csv`` when present; else every sub-directory is a
device (its name the id) holding ``train*.csv|npz`` and optionally ``holdout*.csv|npz`` (no
power-on marks; the lot's output folder, when it is inside, is not a device).  A bad manifest
(not a regular file, not UTF-8, unknown or missing column, bad id, a mark that is not a number)
is an error naming the file, the line and the field, before any device is processed.  A row that
fails alone (stage ``manifest``, before any work, its reason naming the other row): a device id
given again (also in another case; the first row is calibrated, the later one is a failed row of
the report), a run log that is an earlier device's run (the same path or the same bytes), a
held-out run that is the device's own training run.

**Per device** (host_tools.lot.device): read the runs; refuse training runs shorter than
``min_train_s``; fit (``host_tools.fitting.fit_pipeline.fit_default``, with hdrg fit's refusals);
compensate each held-out run (float golden model) and measure from power-on: the stability (std
of the ``stability_tau_s`` means of the valid output), the valid share, and the coverage (share
of non-exchange samples inside the model's proxy range, and inside its rate range: the inputs
the device meets that its training covered); quantize (``hdrg quantize``, the sequencer timing of
the spec) and export ``table.h`` (symbol ``HDRG_TABLE``, with ``HDRG_TABLE_DEVICE_ID``),
``table.json`` (with ``device_id``) and ``table.memh`` (a ``//`` comment line), each naming the
device and the table's CRC-32.  A device that fails (an unreadable, corrupt or too short log, a
fit or quantization refused, a figure outside the spec) is reported with its stage and reason and
exports no table (its model.json is kept when it exists); it never stops the lot.

**Spec** (``--spec`` JSON object; every key optional, null disables a check): the keys, their
defaults and units are :data:`host_tools.lot.inputs.DEFAULT_SPEC` and ``SPEC_DOC`` (printed by
``hdrg lot --help``).  The spec file is read like every JSON input (host_tools.jsonread): a
special file, non-UTF-8 bytes, a repeated key, deep nesting or an unusable number is refused.

**Outputs** in OUT: ``devices/<id>/`` with ``model.json`` (once fitted), ``result.json``
(figures, status, reasons, warnings), ``done.json`` (the done-marker, written last) and, for a
device that passes, ``table.h``, ``table.json``, ``table.memh``.  A device that fails keeps its
tables (when it has them) in ``devices/<id>/withheld/``: never to be shipped, they are there so
that a later spec under which it passes releases them without a refit; ``lot.md`` and ``lot.csv`` (one row per device: pass/fail, the stage
and reason, the figures), ``lot.json`` (the spec, the summary, every result, the worst devices),
``lot_histograms.png`` (the figures over the lot, the spec limits dashed).  Rows are sorted by
device id; nothing in them depends on time, host or worker.  A progress counter goes to stderr.
Exit code 0 when every device passes, 1 when some fail (the report is written), 2 on an error.

**Resume**: every file is written atomically (host_tools.atomic) and a device's ``done.json``
last, holding the sha256 of what its computation depends on (the bytes of its run logs, its
manifest row, the spec keys that change the figures, the toolchain version), the spec limits it
was judged against, and the sha256 of its output files.  Run the same command again after a
kill or a Ctrl-C: devices whose marker matches are reused, not refitted; a spec that changes only
limits (host_tools.lot.device.JUDGED_KEYS) judges the finished devices again from their
result.json (host_tools.lot.device.judge), rewrites it and moves their tables between the folder
and ``withheld/``; a device whose inputs or the other spec keys changed is redone.  The
temporary files of the atomic writer that a killed run left in OUT are removed.  The lot files (lot.*) describe a complete run only: a run with devices to
calibrate removes them first and writes them at its end.  One ``hdrg lot`` at a time per OUT (a
lock file).

**Engines** (host_tools.lot.parallel, which ``hdrg bench loop`` and ``hdrg bench accuracy`` use
too): ``--workers N`` local processes (default: all cores; 1 runs in the command's own process);
``--scheduler ADDRESS`` a Dask distributed cluster (``dask scheduler``; start workers with ``dask
worker ADDRESS --nthreads 1``: a worker process calibrates one device at a time).  Every device
is calibrated with one BLAS/OpenMP thread (a device is many small solves: a multi-threaded BLAS
only oversubscribes the cores), so N workers use N cores.
The workers read the run logs at the manifest's paths (a shared file system) and return the
outputs, which this command writes.  A worker process that dies (killed, out of memory) fails
only the device it was calibrating, without a done-marker (the next run tries it again): local
processes stop the broken pool's other processes (SIGTERM, then SIGKILL) and rerun its devices
each alone; Dask retries a task on another worker before it gives up (``KilledWorker``), and
each device's future is released once its outputs are written (a lost worker never recomputes
a finished device; the cluster's memory does not grow with the lot).  With ``--workers 1`` the command itself dies, and the
next run resumes.

**A simulated lot**: ``hdrg simulate --lot N -o DIR [--seed S] [--duration S] [--reversal on|off]``
writes N foreign devices (seeds S .. S+N-1, ids ``foreign-SEED``), each a training run at
``--chamber-rate`` (4 degC/min) and a held-out run at ``--holdout-rate`` (2 degC/min, the next
power-on and noise seed), and ``DIR/manifest.csv``; then ``hdrg lot DIR -o OUT``.

Python: ``host_tools.lot.run_lot(manifest, out, spec=None, workers=None, scheduler=None)``;
``host_tools.lot.simulated.write_lot`` makes a simulated lot (``hdrg simulate --lot N -o DIR``).
"""
from __future__ import annotations

from host_tools.lot.engine import LotStopped, run_lot
from host_tools.lot.inputs import DEFAULT_SPEC, load_spec, read_manifest

__all__ = ["DEFAULT_SPEC", "LotStopped", "load_spec", "read_manifest", "run_lot"]
