"""The base class of the errors a user can fix (a bad input file, a refused model, an option out of
range).  The command line (host_tools.cli) prints them as one line ``hdrg <cmd>: error: ...`` with
exit code 2; any other exception is a bug and keeps its traceback.

Every user-facing error class of the project derives from :class:`HdrgError` and also from
ValueError (so ``except ValueError`` in callers keeps working).  :class:`UserError` is the plain one,
for a refusal that has no class of its own.
"""
from __future__ import annotations


class HdrgError(Exception):
    """An error the user can fix; its message says what and how."""


class UserError(HdrgError, ValueError):
    """A refused input or option that has no more specific error class."""
