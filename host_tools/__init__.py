"""hdrg host tools.

Importing the package chooses where numba caches its compiled kernels (``cache=True``) before
numba is imported, so that the tool runs for any user, also from a read-only install with no
writable home (a service account with ``HOME=/nonexistent``), where numba's own choices (the
package's ``__pycache__``, then ``~/.cache``) fail with "cannot cache function ... no locator
available":

1. ``NUMBA_CACHE_DIR`` set by the user: kept;
2. the ``__pycache__`` directories next to every kernel module writable (host_tools' and the
   sibling package firmware_ref's): numba's default (nothing changes);
3. else the per-user cache ``$XDG_CACHE_HOME/hdrg/numba`` or ``~/.cache/hdrg/numba``, when it
   can be created and written;
4. else a private temporary directory ``<tmp>/hdrg-numba-<uid>`` (mode 0700, owned by the user);
5. else caching is disabled (the kernels compile at every run).

Cases 4 and 5 print one note on stderr.
"""
from __future__ import annotations

import os
import stat
import sys
import tempfile

_KERNEL_DIRS = ("golden", "fitting")      # the subpackages holding numba kernels with cache=True
_KERNEL_SIBLINGS = ("firmware_ref",)      # sibling packages (next to host_tools) holding such kernels too


def _writable_dir(path: str, create: bool) -> bool:
    """True when ``path`` is (or, with ``create``, can be made) a directory this process can write."""
    try:
        if create:
            os.makedirs(path, mode=0o700, exist_ok=True)
        elif not os.path.isdir(path):
            return os.access(os.path.dirname(path), os.W_OK | os.X_OK)
        return os.path.isdir(path) and os.access(path, os.W_OK | os.X_OK)
    except OSError:
        return False


def _private_tmp() -> str | None:
    """``<tmp>/hdrg-numba-<uid>``: created 0700, used only if it is a real directory of this user."""
    uid = os.getuid() if hasattr(os, "getuid") else 0
    path = os.path.join(tempfile.gettempdir(), f"hdrg-numba-{uid}")
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
        st = os.lstat(path)
    except OSError:
        return None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != uid or st.st_mode & 0o022 or not os.access(path, os.W_OK | os.X_OK):
        return None
    return path


def _disable_numba_cache() -> None:
    """Last resort: ``cache=True`` becomes a no-op (numba has no setting for this)."""
    from numba.core import dispatcher
    dispatcher.Dispatcher.enable_caching = lambda self: None


def choose_numba_cache(environ=os.environ, stderr=None) -> str:
    """Apply the rule of the module doc; returns which case applied: 'user', 'package', 'home',
    'tmp' or 'none' (and sets ``NUMBA_CACHE_DIR`` in ``environ`` for 'home' and 'tmp')."""
    if environ.get("NUMBA_CACHE_DIR"):
        return "user"
    config = sys.modules.get("numba.core.config")       # numba imported first: it re-reads the setting
    try:
        return _choose(environ, stderr)
    finally:
        if config is not None and environ is os.environ:
            config.reload_config()


def _choose(environ, stderr) -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    dirs = [os.path.join(here, sub) for sub in _KERNEL_DIRS]
    dirs += [d for d in (os.path.join(os.path.dirname(here), sib) for sib in _KERNEL_SIBLINGS) if os.path.isdir(d)]
    if all(_writable_dir(os.path.join(d, "__pycache__"), create=False) for d in dirs):
        return "package"
    stderr = sys.stderr if stderr is None else stderr
    bases = []
    xdg = environ.get("XDG_CACHE_HOME", "")
    if os.path.isabs(xdg):
        bases.append(xdg)
    home = environ.get("HOME") or os.path.expanduser("~")
    if os.path.isabs(home):
        bases.append(os.path.join(home, ".cache"))
    for base in bases:
        path = os.path.join(base, "hdrg", "numba")
        if _writable_dir(path, create=True):
            environ["NUMBA_CACHE_DIR"] = path
            return "home"
    tmp = _private_tmp()
    if tmp is not None:
        environ["NUMBA_CACHE_DIR"] = tmp
        print(f"hdrg: note: compiled kernels are cached in {tmp} (the install directory and the home "
              f"cache directory are not writable; set NUMBA_CACHE_DIR to choose)", file=stderr)
        return "tmp"
    print("hdrg: note: no writable directory for the compiled kernels' cache (install, home and temporary "
          "directories): caching is off, kernels compile at every run (set NUMBA_CACHE_DIR to a writable "
          "directory)", file=stderr)
    _disable_numba_cache()
    return "none"


choose_numba_cache()
