"""Bounded, strict reading of the JSON files hdrg reads back (model, table.json, vectors manifest).

:func:`read_json` ``(path, what, max_bytes, max_depth)`` and :func:`parse_json` ``(text, source,
what, max_depth)`` return the parsed document or raise :class:`InputFileError` (a ValueError
whose message starts with the file name) for:

* a path that is not a regular file (a directory, a FIFO, a device such as /dev/zero: refused
  before it is opened for reading, so nothing blocks or fills memory);
* a file larger than ``max_bytes`` (checked on the size and again on what is read);
* bytes that are not UTF-8 (a leading BOM is allowed), text that is not JSON (line and column);
* a key repeated in one object (JSON leaves it undefined; Python would keep the last silently);
* nesting deeper than ``max_depth`` arrays/objects (no RecursionError, whatever the depth);
* a number Python cannot hold (an integer of more than 4300 digits).

Callers wrap the error in their own type (ModelError, TableError, VectorsError) and check the
document's fields themselves.  :func:`check_regular` (the special-file refusal alone) also guards
the commands' other inputs (host_tools.cli.options.regular_input).
"""
from __future__ import annotations

import json
import os
import stat
from host_tools.errors import HdrgError

DEFAULT_MAX_BYTES = 16 << 20          # 16 MiB: a model is ~5 kB, a table.json ~20 kB
DEFAULT_MAX_DEPTH = 64                # every hdrg document nests less than 12 deep


class InputFileError(HdrgError, ValueError):
    """An input file that cannot be read (special file, too large, not UTF-8 or JSON, repeated key, too
    deep): the message names the file and the problem."""


def _refuse_duplicates(pairs):
    out = {}
    for key, value in pairs:
        if key in out:
            raise InputFileError(f"duplicated key {key!r} in one object (JSON does not say which one counts)")
        out[key] = value
    return out


def _depth_over(doc, limit: int) -> bool:
    """True when ``doc`` nests more than ``limit`` arrays/objects deep (iterative: no recursion)."""
    stack = [(doc, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, (dict, list)):
            if d > limit:
                return True
            stack.extend((v, d + 1) for v in (node.values() if isinstance(node, dict) else node))
    return False


def parse_json(text: str, source: str, what: str = "JSON", max_depth: int = DEFAULT_MAX_DEPTH):
    """The document of ``text`` (see the module doc); ``what`` names the document in messages."""
    try:
        doc = json.loads(text, object_pairs_hook=_refuse_duplicates)
    except json.JSONDecodeError as exc:
        raise InputFileError(f"{source}: not valid JSON (line {exc.lineno} column {exc.colno}: {exc.msg})") from None
    except InputFileError as exc:
        raise InputFileError(f"{source}: {exc}") from None
    except RecursionError:
        raise InputFileError(f"{source}: {what} nested too deep (more than {max_depth} levels of arrays/objects)") \
            from None
    except ValueError as exc:          # e.g. an integer literal over Python's digit limit
        raise InputFileError(f"{source}: not a usable {what}: {exc}") from None
    if _depth_over(doc, max_depth):
        raise InputFileError(f"{source}: {what} nested too deep (more than {max_depth} levels of arrays/objects)")
    return doc


def check_regular(path, role: str = "input") -> None:
    """InputFileError unless ``path`` is a regular file (an existing FIFO, device, socket or
    directory is refused: reading one blocks or never ends).  A missing path is left to open()."""
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except OSError:
        return
    if stat.S_ISDIR(st.st_mode):
        raise InputFileError(f"{path}: is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" if stat.S_ISCHR(st.st_mode) or
                stat.S_ISBLK(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a regular file")
        raise InputFileError(f"{path}: is {kind}, not a regular file (the {role} must be a file)")


def read_text(path, what: str = "file", max_bytes: int = DEFAULT_MAX_BYTES) -> str:
    """The UTF-8 text of the regular file ``path`` (a leading BOM dropped), at most ``max_bytes``."""
    source = os.fspath(path)
    check_regular(source, what)
    with open(source, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        if size > max_bytes:
            raise InputFileError(f"{source}: {size} bytes, more than the {max_bytes}-byte limit of a {what}")
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputFileError(f"{source}: more than the {max_bytes}-byte limit of a {what}")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{source}: not a text file (UTF-8 decoding failed at byte {exc.start})") from None


def read_json(path, what: str = "JSON", max_bytes: int = DEFAULT_MAX_BYTES, max_depth: int = DEFAULT_MAX_DEPTH):
    """The document of the file ``path`` (see the module doc)."""
    return parse_json(read_text(path, what, max_bytes), os.fspath(path), what, max_depth)

