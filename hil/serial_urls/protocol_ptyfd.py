"""pyserial handler for ``ptyfd://N``: a serial port on an already-open file descriptor.

A pty's master end has no path (opening ``/dev/ptmx`` or ``/proc/self/fd/N`` makes a new
pty), so an emulator that owns the master passes the fd to pymodbus through this URL.
The descriptor is duplicated; closing the port leaves the original open.

Fault injection: a :class:`hil.wire_faults.WireFaults` registered for fd ``N`` in
:data:`WIRE_FAULTS` rewrites every frame written to the port (the emulator's replies)
into the chunks it says, each after its delay, on the writing thread: an RS-485 line is
busy while a slave is late.
"""

from __future__ import annotations

import fcntl
import os
import termios
import time
from typing import Any

from serial import SerialException
from serial.serialposix import Serial as PosixSerial

#: Fault injectors by the fd of a ``ptyfd://`` URL (set by whoever serves on it).
WIRE_FAULTS: dict[int, Any] = {}


class Serial(PosixSerial):
    def open(self):
        if self.is_open:
            raise SerialException("Port is already open.")
        try:
            fd = int(str(self.portstr).split("://", 1)[1])
            self.source_fd = fd
            self.fd = os.dup(fd)
        except (ValueError, IndexError, OSError) as exc:
            raise SerialException(f"invalid ptyfd URL {self.portstr!r}: {exc}") from exc
        fcntl.fcntl(self.fd, fcntl.F_SETFL, fcntl.fcntl(self.fd, fcntl.F_GETFL) | os.O_NONBLOCK)
        self.pipe_abort_read_r, self.pipe_abort_read_w = os.pipe()
        self.pipe_abort_write_r, self.pipe_abort_write_w = os.pipe()
        fcntl.fcntl(self.pipe_abort_read_r, fcntl.F_SETFL, os.O_NONBLOCK)
        fcntl.fcntl(self.pipe_abort_write_r, fcntl.F_SETFL, os.O_NONBLOCK)
        self.is_open = True
        self._reconfigure_port(force_update=True)

    def _reconfigure_port(self, force_update=False):
        # Every pty master is an open of /dev/ptmx, so an exclusive flock on one conflicts
        # with every other process's master; the fd is private to this process anyway.
        self._exclusive = None
        try:
            super()._reconfigure_port(force_update)
        except termios.error:  # line settings on a master are best effort: no baud rate
            pass

    def write(self, data):
        faults = WIRE_FAULTS.get(getattr(self, "source_fd", -1))
        if faults is None:
            return super().write(data)
        for delay, chunk in faults.rtu_reply(bytes(data)):
            if delay > 0:
                time.sleep(delay)
            super().write(chunk)
        return len(data)

    def _update_dtr_state(self):  # no modem lines on a pty
        pass

    def _update_rts_state(self):
        pass
