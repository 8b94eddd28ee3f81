"""A virtual device (host_tools.link.device) on a fresh pty, shared by the serial-link tests."""
from __future__ import annotations

from host_tools.link import device as D


class PtyDevice:
    """A virtual device on a fresh pty; ``name`` is the host's end.  As a context manager the
    device thread runs inside the block and must stop cleanly, without an error, at its end."""

    def __init__(self, log, table, **kw):
        kw.setdefault("speed", 0.0)
        master, slave, self.name = D.open_pty()
        self.link = D.FdLink(master, keep=(slave,), name=self.name)
        self.dev = D.VirtualDevice(self.link, D.DeviceRun.from_log(log), table, **kw)

    def __enter__(self):
        self.dev.start()
        return self

    def __exit__(self, *exc):
        assert self.dev.unplug(5.0), "device thread did not stop"
        self.close()
        assert self.dev.error is None, self.dev.error
        return False

    def close(self) -> None:
        """What the host holds open on the pty besides the device (nothing here)."""
