"""Byte transports of the virtual device (host_tools.link.device): the master side of a
pseudo-terminal (:class:`FdLink`, :func:`open_pty`) or a pyserial port (:class:`PortLink`).  Both
offer ``read(timeout)``, ``write(data, stop, deadline)`` and ``close()``; every wait is bounded.
The pyserial ``serialposix`` role; framing is host_tools.link.frame.
"""
from __future__ import annotations

import errno
import os
import select
import threading
import time
import tty


class LinkClosed(Exception):
    """The other end went away (pty closed) or the link was closed."""


# -- links ------------------------------------------------------------------------------------------

class FdLink:
    """A file-descriptor link (the master side of a pty): non-blocking, select-based, every wait
    bounded.  ``keep`` fds (the pty's slave) are held open so a host may close and reopen the
    port, and closed with the link."""

    def __init__(self, fd: int, keep=(), name: str = ""):
        self.fd = fd
        self.keep = tuple(keep)
        self.name = name
        os.set_blocking(fd, False)
        self._closed = False

    def read(self, timeout: float) -> bytes:
        if self._closed:
            raise LinkClosed("link closed")
        r, _, _ = select.select([self.fd], [], [], max(0.0, timeout))
        if not r:
            return b""
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:
                raise LinkClosed("the other end closed the pty") from None
            raise
        if not data:
            raise LinkClosed("end of file")
        return data

    def write(self, data: bytes, stop: threading.Event, deadline: float | None = None) -> int:
        """Write ``data``; returns the bytes written: all of it, or fewer when ``stop`` is set, or 0
        when nothing could be written before ``deadline`` (once started, a frame is completed)."""
        view = memoryview(data)
        done = 0
        while done < len(data):
            if stop.is_set():
                return done
            wait = 0.05 if deadline is None or done else min(0.05, max(0.0, deadline - time.monotonic()))
            _, w, _ = select.select([], [self.fd], [], wait)
            if not w:
                if deadline is not None and done == 0 and time.monotonic() >= deadline:
                    return 0
                continue
            try:
                done += os.write(self.fd, view[done:])
            except BlockingIOError:
                continue
            except OSError as exc:
                if exc.errno == errno.EIO:
                    raise LinkClosed("the other end closed the pty") from None
                raise
        return done

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        for fd in (self.fd,) + self.keep:
            try:
                os.close(fd)
            except OSError:
                pass


class PortLink:
    """A pyserial port (``serial.serial_for_url``: loop://, a real port, a pty path) as a link."""

    def __init__(self, port):
        self.port = port
        self.name = getattr(port, "port", "") or ""

    def read(self, timeout: float) -> bytes:
        try:
            n = self.port.in_waiting
            if n:
                return self.port.read(n)
            if timeout > 0:
                time.sleep(min(timeout, 0.01))
            return b""
        except Exception as exc:  # serial.SerialException, OSError
            raise LinkClosed(str(exc)) from None

    def write(self, data: bytes, stop: threading.Event, deadline: float | None = None) -> int:
        try:
            return self.port.write(data) or len(data)
        except Exception as exc:
            if type(exc).__name__ == "SerialTimeoutException":
                return 0
            raise LinkClosed(str(exc)) from None

    def close(self) -> None:
        try:
            self.port.close()
        except Exception:  # pragma: no cover
            pass


def open_pty():
    """A raw pseudo-terminal pair: ``(master_fd, slave_fd, slave_name)``.  Both ends are raw (no
    echo, no line editing, 8-bit clean) before anything is written."""
    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    return master, slave, os.ttyname(slave)
