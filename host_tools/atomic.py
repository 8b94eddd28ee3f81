"""Atomic outputs: every file hdrg writes appears complete or not at all.

A writer writes to a temporary file in the destination's directory (``.NAME.XXXX.tmp``, same
file system, so the final :func:`os.replace` is atomic), flushes and fsyncs it, and renames it
over the destination only when the write succeeded.  An interrupted or failed write (Ctrl-C,
SIGTERM, a full disk, an exception) removes the temporary file and leaves any previous
destination untouched.  (A SIGKILL can leave a ``.*.tmp`` file behind; never the destination
half-written.)  A symlink destination keeps the link and replaces its target; an existing
non-regular file (a terminal, ``/dev/stdout``, a FIFO) is written in place.

* :func:`atomic_open` ``(path, mode="w", **open_kwargs)``: a context manager yielding the file
  object of the temporary file;
* :func:`atomic_path` ``(path)``: a context manager yielding the temporary path (same suffix as
  ``path``, for writers that take a path, e.g. matplotlib's savefig);
* :func:`refuse_overwrite` ``(outputs, inputs)``: ValueError when an output resolves to one of
  the inputs (``-o`` equal to an input would destroy it);
* :data:`COMPLETED`: the destinations renamed into place by this process, in order (the CLI names
  them when a command is interrupted after some outputs were already complete); the rename and
  its record happen with SIGINT / SIGTERM held, so a stop cannot fall between them.

The run-log capture (host_tools.link.capture) keeps its incremental fsync'ed file instead and
marks an unfinished capture in its metadata (docs/RUN_LOG.md).
"""
from __future__ import annotations

import contextlib
import errno
import os
import stat
import signal
import tempfile
import threading


def _special(path: str) -> bool:
    """True for an existing non-regular file (a terminal, /dev/stdout, a FIFO): written in place."""
    return os.path.exists(path) and not os.path.isfile(path) and not os.path.isdir(path)


class FifoWithoutReader(OSError):
    """An output path is a FIFO that no process reads: writing to it would wait forever."""


def fifo_writer(path: str):
    """For a FIFO: a write end opened without blocking (held while the caller writes, so its
    reader sees one stream), or FifoWithoutReader when no process reads it; None for any other
    path."""
    if not stat.S_ISFIFO(os.stat(path).st_mode):
        return None
    try:
        return os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError as exc:
        if exc.errno == errno.ENXIO:
            raise FifoWithoutReader(f"{path}: is a FIFO that no process is reading (writing would wait forever); "
                                    f"start the reader first or write to a file") from None
        raise


def _tmp_in_dir(path: str) -> tuple[int, str]:
    if os.path.isdir(path):
        raise IsADirectoryError(f"{path}: is a directory, not a file to write")
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise FileNotFoundError(f"{path}: the directory {directory} does not exist")
    base = os.path.basename(path)
    suffix = os.path.splitext(base)[1]
    return tempfile.mkstemp(prefix=f".{base}.", suffix=".tmp" + suffix, dir=directory)


COMPLETED: list = []


def _finish(tmp: str, path: str) -> None:
    try:
        mode = os.stat(path).st_mode & 0o7777 if os.path.exists(path) else 0o666 & ~_umask()
        os.chmod(tmp, mode)
    except OSError:  # pragma: no cover - permissions are a nicety
        pass
    with _stops_held():     # a stop between the rename and the record would hide a complete output
        os.replace(tmp, path)
        COMPLETED.append(os.fspath(path))


@contextlib.contextmanager
def _stops_held():
    """SIGINT and SIGTERM held for the duration and delivered on exit.  Two layers: on POSIX the
    signals are masked in this thread (``pthread_sigmask``); and in the main thread their Python
    handlers are replaced by one that only records them, because a signal sent to the PROCESS may
    be taken by another thread (numba's, a serial device's), whose C-level handler then makes the
    main thread run the Python handler at its next instruction, inside the window, whatever this
    thread's mask.  On exit the mask and the handlers are restored and every recorded signal is
    raised again (``signal.raise_signal``: its handler runs before this returns)."""
    held = (signal.SIGINT, signal.SIGTERM)
    caught = []
    old_handlers = {}
    if threading.current_thread() is threading.main_thread():
        for sig in held:
            if signal.getsignal(sig) is not None:       # None: a handler not set from Python, left alone
                old_handlers[sig] = signal.signal(sig, lambda signum, frame: caught.append(signum))
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, held) if hasattr(signal, "pthread_sigmask") else None
    try:
        yield
    finally:
        if old_mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)   # a pending signal is recorded here
        for sig, handler in old_handlers.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(caught):
            signal.raise_signal(sig)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; on success fsync it and rename it to ``path``."""
    path = os.path.realpath(os.fspath(path))    # a symlink: its target is replaced, the link kept
    if _special(path):
        probe = fifo_writer(path)
        try:
            yield path
        finally:
            if probe is not None:
                os.close(probe)
        return
    fd, tmp = _tmp_in_dir(path)
    os.close(fd)
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        _finish(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_open(path, mode: str = "w", **kwargs):
    """``open(path, mode, **kwargs)`` on a temporary file next to ``path``, renamed to ``path``
    after a successful write (flushed and fsync'ed first); removed on any exception."""
    if not any(c in mode for c in "wx"):
        raise ValueError(f"atomic_open writes a whole file: mode must be 'w' or 'wb', not {mode!r}")
    with atomic_path(path) as target:     # the same temporary file, fsync, rename and clean-up
        with open(target, mode.replace("x", "w"), **kwargs) as fh:
            yield fh


def same_file(a, b) -> bool:
    """True when paths ``a`` and ``b`` name the same file (samefile when both exist, else the
    resolved real paths)."""
    a, b = os.fspath(a), os.fspath(b)
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def refuse_overwrite(outputs, inputs) -> None:
    """ValueError when any output path resolves to one of the input paths (None entries are
    ignored); the message names both."""
    outs = [outputs] if isinstance(outputs, (str, os.PathLike)) else list(outputs)
    ins = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    for out in outs:
        if out is None:
            continue
        for src in ins:
            if src is not None and same_file(out, src):
                raise ValueError(f"output {os.fspath(out)} is the input {os.fspath(src)}: refusing to overwrite "
                                 f"an input (choose another output file)")
