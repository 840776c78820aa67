"""Virtual serial links: pseudo-terminals whose slave end looks like a USB-RS485 adapter."""

from __future__ import annotations

import os
import tty
from dataclasses import dataclass
from typing import Self

import serial

if "hil.serial_urls" not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append("hil.serial_urls")


@dataclass
class PtyLink:
    """A pty pair.  The emulator serves on :attr:`url` (the master end); masters open
    :attr:`path` (the slave end) as they would ``/dev/ttyUSB0``.

    The slave fd stays open for the link's lifetime so the master never sees EIO when a
    client closes and reopens the port.
    """

    master_fd: int
    slave_fd: int
    path: str

    @classmethod
    def open(cls) -> PtyLink:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation: Modbus RTU is binary
        return cls(master, slave, os.ttyname(slave))

    @property
    def url(self) -> str:
        """pyserial URL of the master end (the emulator's side)."""
        return f"ptyfd://{self.master_fd}"

    @property
    def slave_url(self) -> str:
        """pyserial URL of the slave end, for a master whose line settings a pty refuses:
        Linux rejects a parity bit on a pty (EINVAL), and ``ptyfd://`` applies line
        settings only as far as the pty allows, so the client opens with any settings."""
        return f"ptyfd://{self.slave_fd}"

    def close(self) -> None:
        for fd in (self.master_fd, self.slave_fd):
            try:
                os.close(fd)
            except OSError:
                pass

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
