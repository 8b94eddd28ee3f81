"""The engine that runs independent jobs: in this process, a local process pool, or a Dask
distributed cluster (``hdrg lot``, ``hdrg bench loop``, ``hdrg bench accuracy``).

* :func:`run_jobs` ``(fn, jobs, workers=1, scheduler=None, crashed=None)`` yields ``(job,
  fn(job))`` pairs as they finish: one worker runs them in this process, in order; several, a
  ``concurrent.futures.ProcessPoolExecutor`` (at most 2 x ``workers`` jobs submitted at a time);
  ``scheduler``, the Dask distributed cluster at that address.
* :func:`map_ordered` ``(fn, items, ...)`` -> the list ``[fn(item) for item in items]``, in the
  items' order whatever the engine, for callers that want the serial result.

``fn`` must be a module-level function (or a ``functools.partial`` of one) and its jobs and
results picklable.  A job's result must depend on the job alone, never on the process that
computes it: that is what makes the outputs the same whatever the engine or the worker count.

**One thread per worker.**  Every job runs with its BLAS (OpenBLAS, MKL) and OpenMP thread pools
limited to one thread (:func:`single_threaded`): the jobs here are many small least-squares
problems, for which a multi-threaded BLAS spends its time waking and spinning threads: two pool
processes with a two-thread BLAS each oversubscribe two cores (measured on an idle 2-core
machine, `hdrg lot` of 100 simulated devices: 16.5 s with 1 worker, 16.7 s with 2 workers of two
BLAS threads, 9.4 s with 2 workers of one; on a loaded machine a device took 3-4 x longer with two
BLAS threads than with one; the same bytes out).  The pool processes also get ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS``,
``MKL_NUM_THREADS``, ``NUMBA_NUM_THREADS`` = 1 in their environment (libraries they load later,
processes they start).  The limit uses threadpoolctl when it is installed, else the thread
setters of the OpenBLAS libraries loaded in the process.  A Dask worker started by ``dask
worker`` has the same variables set by its nanny; start it with ``--nthreads 1``.

**Worker start.**  On Linux the pool forks this process, so a worker starts with what the
command has imported and compiled (numba's kernels): a command that warmed up before its pool
started pays no compile or import cost per worker; a cold one pays it once per worker, in
parallel.  The objects of this process are frozen (``gc.freeze``) while the pool runs, so that
the workers' garbage collections do not copy the pages they inherit.

**Crashes.**  A pool process that dies (killed, out of memory) breaks the pool: its other
processes are stopped (SIGTERM, then SIGKILL after STOP_WAIT_S; the workers take SIGTERM's
default action, not the command's handler they inherit), a new pool takes over, and the jobs
that were submitted to the broken one run again, each alone, so that the job that kills its
process is the only one lost: ``crashed(job, exc)`` gives its result (None: it raises
RuntimeError).  A process that died while it wrote its result would leave the pool waiting for
the rest of the message for ever: the engine checks the processes every POLL_S seconds while no
job finishes, and takes a pool with a dead process and no progress for broken.  Nothing waits
without a bound: a stop (Ctrl-C, an error) ends the pool the same way.  On Dask a task whose
worker dies is retried by the scheduler before it fails (``KilledWorker``); each Dask future is
released as soon as its result is collected, so that the cluster's memory does not grow with the
number of jobs and a worker lost later never recomputes a collected job.  An exception raised by
``fn`` in a pool process or a Dask task goes to ``crashed`` too when it is given, else it is
raised here as it is.  ``--scheduler`` must read as an address (:func:`check_scheduler`), and a
scheduler that does not answer within CONNECT_TIMEOUT_S seconds is an error.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import gc
import os
import threading

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
# thread setters/getters of the OpenBLAS builds numpy and scipy ship (plain, 64-bit ints, scipy's)
_OPENBLAS_API = (("openblas_set_num_threads", "openblas_get_num_threads"),
                 ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
                 ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
                 ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"))


def default_workers() -> int:
    """All the cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def check_workers(workers) -> int:
    """``workers`` (None: :func:`default_workers`) as an int >= 1, or ValueError."""
    workers = default_workers() if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"--workers must be >= 1, not {workers}")
    return workers


def _openblas_libs() -> list:
    """(set, get) ctypes functions of every OpenBLAS library loaded in this process."""
    found = []
    try:
        with open("/proc/self/maps", "r", encoding="utf-8", errors="replace") as fh:
            paths = {line.split(None, 5)[5].strip() for line in fh if "openblas" in line.lower() and
                     len(line.split(None, 5)) == 6}
    except OSError:         # pragma: no cover - not Linux
        return found
    for path in sorted(paths):
        if not os.path.exists(path):
            continue
        try:
            lib = ctypes.CDLL(path, mode=getattr(os, "RTLD_NOLOAD", 0))    # only the one already loaded
        except OSError:
            continue
        for set_name, get_name in _OPENBLAS_API:
            setter, getter = getattr(lib, set_name, None), getattr(lib, get_name, None)
            if setter is not None and getter is not None:
                getter.restype = ctypes.c_int
                found.append((setter, getter))
                break
    return found


def blas_threads() -> list:
    """The thread count of every BLAS/OpenMP pool loaded in this process (threadpoolctl's view
    when it is installed, else the OpenBLAS libraries')."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return [getter() for _, getter in _openblas_libs()]
    return [int(d["num_threads"]) for d in threadpool_info()]


def _limit_blas(n: int):
    """Limit the BLAS/OpenMP thread pools loaded in this process to ``n`` threads; returns a
    function that restores them."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        libs = _openblas_libs()
        before = [getter() for _, getter in libs]
        for setter, _ in libs:
            setter(n)
        return lambda: [setter(k) for (setter, _), k in zip(libs, before)]
    limit = threadpool_limits(limits=n)
    return limit.restore_original_limits


_LOCK = threading.Lock()
_DEPTH = [0, None, None]     # nesting depth, the BLAS restore function, the saved environment


@contextlib.contextmanager
def single_threaded():
    """Run the block with one BLAS/OpenMP thread (module doc) and the THREAD_VARIABLES at 1 (a
    library loaded inside the block starts single-threaded), then restore both; re-entrant, and
    shared by the threads of a process (the limits are per process)."""
    with _LOCK:
        if _DEPTH[0] == 0:
            _DEPTH[2] = {k: os.environ.get(k) for k in THREAD_VARIABLES}
            os.environ.update({k: "1" for k in THREAD_VARIABLES})
            _DEPTH[1] = _limit_blas(1)
        _DEPTH[0] += 1
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH[0] -= 1
            if _DEPTH[0] == 0:
                with contextlib.suppress(Exception):
                    _DEPTH[1]()
                for k, v in _DEPTH[2].items():
                    if v is None:
                        os.environ.pop(k, None)
                    else:
                        os.environ[k] = v


def run_call(fn, job):
    """``fn(job)`` with one thread (what every engine runs)."""
    with single_threaded():
        return fn(job)


def _worker_init() -> None:
    """In each pool process: one thread for good (module doc), and die with the command.  A
    killed command (SIGKILL) would otherwise leave its workers blocked on the task queue for ever
    (Linux: PR_SET_PDEATHSIG); Ctrl-C goes to the whole process group: the command stops the
    pool, the workers do not raise.  SIGTERM gets its default action back (a forked worker
    inherits the command's handler, which would unwind the worker into a queue nobody reads
    instead of ending it when the pool stops it)."""
    import signal

    os.environ.update({k: "1" for k in THREAD_VARIABLES})
    with contextlib.suppress(Exception):
        _limit_blas(1)
    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))     # 1 = PR_SET_PDEATHSIG
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _lost(job, exc, crashed):
    if crashed is None:
        raise RuntimeError(f"a worker process died while computing {job!r} ({type(exc).__name__}: {exc})") from exc
    return crashed(job, exc)


STOP_WAIT_S = 5.0       # how long stopped pool processes get to end before they are killed [s]
POLL_S = 1.0            # how often the pool's processes are checked while no job finishes [s]


def _terminate(ex, wait_s: float = STOP_WAIT_S) -> None:
    """Stop the processes of the pool ``ex`` now, without waiting for their jobs: SIGTERM, then
    SIGKILL for those still alive after ``wait_s`` seconds in all."""
    import time

    procs = list((getattr(ex, "_processes", None) or {}).values())
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.terminate()
    end = time.monotonic() + wait_s
    for proc in procs:
        with contextlib.suppress(Exception):
            proc.join(max(0.0, end - time.monotonic()))
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
    if all(not proc.is_alive() for proc in procs):
        # a process stopped while it wrote its result leaves half a message in the result pipe, and
        # the pool's manager thread waits for the rest for ever: this process holds the pipe's
        # last write end, closed here so that the thread reads the end of the pipe and stops
        with contextlib.suppress(Exception):
            ex._result_queue._writer.close()


def _a_process_died(ex) -> bool:
    """True when a process of the pool ``ex`` has ended (they live as long as the pool)."""
    with contextlib.suppress(Exception):
        return any(p.exitcode is not None for p in list((ex._processes or {}).values()))
    return False


def _shutdown(ex, wait_s: float = STOP_WAIT_S) -> None:
    """Shut the pool ``ex`` down, waiting at most ``wait_s`` seconds for its manager thread."""
    ex.shutdown(wait=False, cancel_futures=True)
    thread = getattr(ex, "_executor_manager_thread", None)
    if thread is not None:
        thread.join(wait_s)


def _run_pool(fn, jobs, workers: int, crashed):
    queue, alone = list(reversed(jobs)), []
    # the objects this process holds go to the collector's permanent generation while the pool
    # forks, so that a worker's collections do not write into (and copy) every page it inherits
    freeze = hasattr(gc, "freeze") and gc.get_freeze_count() == 0
    if freeze:
        gc.freeze()
    try:
        yield from _pool_passes(fn, queue, alone, workers, crashed)
    finally:
        if freeze:
            gc.unfreeze()


def _pool_passes(fn, queue, alone, workers, crashed):
    """Run ``queue`` (popped from the end) through pools of ``workers`` processes; after a pool
    breaks, the jobs it held run again each alone (``alone``) in a new pool: one that breaks a
    pool again is given to ``crashed``."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    while queue or alone:
        ex = ProcessPoolExecutor(max_workers=workers, initializer=_worker_init)
        running, lost, broken = {}, [], False
        try:
            while queue or alone or running:
                try:
                    if alone and not running:
                        job, solo = alone.pop(), True
                        running[ex.submit(fn, job)] = (job, True)
                    while queue and not alone and len(running) < 2 * workers:
                        job, solo = queue.pop(), False
                        running[ex.submit(fn, job)] = (job, False)
                except BrokenProcessPool:   # broke since the last wait: this job never started
                    (alone if solo else queue).append(job)
                    broken = True
                done = set()
                if running and not broken:
                    done = wait(running, timeout=POLL_S, return_when=FIRST_COMPLETED)[0]
                    if not done and _a_process_died(ex):
                        # the pool notices a dead process by itself, unless the process died while it
                        # wrote its result: then the pool waits for the rest of it for ever
                        done = wait(running, timeout=POLL_S, return_when=FIRST_COMPLETED)[0]
                        broken = not done
                for fut in done:
                    job, solo = running.pop(fut)
                    try:
                        result = fut.result()
                    except BrokenProcessPool as exc:
                        lost.append((job, solo, exc))
                        continue
                    except Exception as exc:
                        if crashed is None:
                            raise
                        result = crashed(job, exc)
                    yield job, result
                if lost or broken:
                    held = list(running.items())
                    running.clear()
                    for fut, (job, solo) in held:
                        if fut.done() and not fut.cancelled() and fut.exception() is None:
                            yield job, fut.result()     # finished just before the break
                        else:
                            lost.append((job, solo, BrokenProcessPool("the pool broke")))
                    broken = True
                    break
        except BaseException:       # the caller stopped (an error, Ctrl-C, close()): drop the running jobs
            _terminate(ex)
            raise
        finally:
            if broken:              # a broken pool: its other processes are stopped, not awaited
                _terminate(ex)
            _shutdown(ex)
        for job, solo, exc in lost:
            if solo:
                yield job, _lost(job, exc, crashed)
            else:
                alone.append(job)


CONNECT_TIMEOUT_S = 30.0     # how long to try to reach a Dask scheduler [s]
_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def check_scheduler(address: str) -> str:
    """``address`` when it reads as a Dask scheduler address (``[tcp|tls|inproc|ucx|ws|wss://]HOST:PORT``,
    PORT 1..65535; ``inproc://`` takes any name), else UserError naming it."""
    import re

    from host_tools.errors import UserError

    text = str(address).strip()
    m = re.fullmatch(r"(?:([a-z]+)://)?(.+)", text)
    scheme, rest = ((m.group(1) or "tcp"), m.group(2)) if m else ("", "")
    ok = False
    if scheme in _SCHEMES:
        if scheme == "inproc":
            ok = bool(rest)
        else:
            hp = re.fullmatch(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})", rest)
            ok = bool(hp) and 1 <= int(hp.group(2)) <= 65535
    if not ok:
        raise UserError(f"--scheduler {address!r}: not a Dask scheduler address (expected [tcp://]HOST:PORT, "
                        f"e.g. tcp://10.0.0.5:8786; schemes: {', '.join(_SCHEMES)})")
    return text


def _run_dask(fn, jobs, scheduler: str, crashed):
    """Submit every job to the cluster, yield the results as they complete and release each future
    as soon as its result is here: the cluster holds only the results not yet collected (its memory
    does not grow with the lot), and a worker lost later has nothing of the collected jobs to
    recompute."""
    try:
        from distributed import Client, as_completed
    except ImportError:     # pragma: no cover - a dependency of hdrg
        raise ValueError("--scheduler needs Dask distributed (pip install 'dask[distributed]')") from None
    from host_tools.errors import UserError

    scheduler = check_scheduler(scheduler)
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError) as exc:
        raise UserError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({type(exc).__name__}: "
                        f"{str(exc).splitlines()[0] if str(exc) else 'no answer'})") from None
    pending = {}        # key -> (future, job) of the jobs whose result is not collected yet
    try:
        futures = client.map(functools.partial(run_call, fn), jobs, pure=False)
        pending.update((f.key, (f, job)) for f, job in zip(futures, jobs))
        done = as_completed(futures)
        del futures
        for fut in done:
            _, job = pending.pop(fut.key)
            try:
                result = fut.result()
            except Exception as exc:    # a worker died (KilledWorker) or the task raised
                if crashed is None:
                    raise
                result = crashed(job, exc)
            fut.release()
            del fut
            yield job, result
    finally:
        with contextlib.suppress(Exception):
            client.cancel([f for f, _ in pending.values()])
        pending.clear()
        client.close()


def run_jobs(fn, jobs, workers: int = 1, scheduler: str | None = None, crashed=None):
    """``(job, fn(job))`` pairs as they finish (module doc): in this process for ``workers`` 1
    (in order), a local process pool for more, the Dask cluster at ``scheduler`` when given."""
    jobs = list(jobs)
    if scheduler:
        yield from _run_dask(fn, jobs, scheduler, crashed)
    elif workers <= 1:
        with single_threaded():
            for job in jobs:
                yield job, fn(job)
    else:
        yield from _run_pool(functools.partial(run_call, fn), jobs, min(workers, len(jobs)), crashed)


def map_ordered(fn, items, workers: int = 1, scheduler: str | None = None, on_result=None) -> list:
    """``[fn(item) for item in items]`` through :func:`run_jobs`, in the items' order;
    ``on_result(index, result, done)`` is called as each result arrives (``done``: how many so
    far), e.g. for progress."""
    items = list(items)
    out = [None] * len(items)
    run = run_jobs(_Indexed(fn), list(enumerate(items)), workers, scheduler)
    try:
        for n, ((i, _), result) in enumerate(run, 1):
            out[i] = result
            if on_result is not None:
                on_result(i, result, n)
    finally:
        run.close()
    return out


class _Indexed:
    """``fn`` applied to the item of an ``(index, item)`` job (picklable when ``fn`` is)."""

    def __init__(self, fn):
        self.fn = fn

    def __call__(self, job):
        return self.fn(job[1])
