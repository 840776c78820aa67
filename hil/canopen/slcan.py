"""An slcan (Lawicel ASCII) USB-CAN adapter, emulated on a pseudo-terminal.

The adapter bridges a pty to a python-can bus (normally the ``virtual`` channel the
emulated nodes live on).  Another process opens the pty's slave end exactly as it would a
USB-CAN adapter::

    can.Bus(interface="slcan", channel="/dev/pts/7", sleep_after_open=0)

Protocol (Lawicel CANUSB / CAN232): commands end with CR; success is answered with CR
(``z``/``Z`` + CR after a transmitted standard/extended frame), failure with BEL.
Implemented: ``O`` (open), ``L`` (listen only), ``C`` (close), ``S0``-``S8`` and ``sxxyy``
(bit rate; only while closed), ``t``/``T``/``r``/``R`` (transmit), ``V``/``v`` (version),
``N`` (serial number), ``F`` (status flags), ``Z0``/``Z1`` (time stamps), ``X``, ``W``,
``M``, ``m``, ``U``, ``Q`` (accepted and ignored).  Received frames are forwarded as
``tiiildd..`` / ``Tiiiiiiiildd..`` (+ ``ssss`` ms time stamp with ``Z1``) while open.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import select
import termios
import threading
import time
from typing import Self

import can

from hil.pty import PtyLink

log = logging.getLogger(__name__)

OK = b"\r"
ERROR = b"\a"
HW_VERSION = "01"
SW_VERSION = "10"
SERIAL = "HT01"
MAX_LINE = 64  # longest legal command is "T" + 8 + 1 + 16 = 26 chars; more is garbage


class SlcanAdapter:
    """Serve the slcan protocol on ``link``'s master end, bridged to ``bus``.

    Parameters
    ----------
    link : PtyLink
        The pty; clients open ``link.path``.
    bus : can.BusABC
        Where frames go to and come from (its own virtual-bus endpoint: a python-can
        virtual bus does not echo a sender's frames back to it).
    """

    def __init__(self, link: PtyLink, bus: can.BusABC):
        self.link = link
        self.bus = bus
        self.is_open = False
        self.listen_only = False
        self.timestamps = False
        self.bitrate_code = "6"
        self.rx_dropped = 0  # frames not delivered because nobody reads the pty
        self.bad_commands = 0
        self._fd = link.master_fd
        flags = fcntl.fcntl(self._fd, fcntl.F_GETFL)
        # Non-blocking writes: with no client reading, a full pty must drop frames (as a
        # real adapter's buffer overflows) rather than block the bridge.
        fcntl.fcntl(self._fd, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self._write_lock = threading.Lock()
        self._stop = threading.Event()
        self._threads = [
            threading.Thread(target=self._pty_loop, name="slcan-pty", daemon=True),
            threading.Thread(target=self._bus_loop, name="slcan-bus", daemon=True),
        ]

    # -- lifecycle ----------------------------------------------------------------------
    def start(self) -> Self:
        for t in self._threads:
            t.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(2)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- pty side -----------------------------------------------------------------------
    def _write(self, data: bytes) -> bool:
        with self._write_lock:
            try:
                os.write(self._fd, data)
                return True
            except BlockingIOError:
                return False
            except OSError as exc:
                if exc.errno in (errno.EIO, errno.EBADF):
                    return False
                raise

    def _pty_loop(self) -> None:
        buf = bytearray()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._fd], [], [], 0.1)
                if not ready:
                    continue
                chunk = os.read(self._fd, 4096)
            except BlockingIOError:
                continue
            except OSError:
                # EIO while no client has the slave open (cannot happen while PtyLink keeps
                # its slave fd, but a closed link must end the thread quietly).
                if self._stop.wait(0.1):
                    return
                continue
            buf.extend(chunk)
            while True:
                cut = min((i for i in (buf.find(b"\r"), buf.find(b"\n")) if i >= 0), default=-1)
                if cut < 0:
                    if len(buf) > MAX_LINE:  # garbage without terminator
                        buf.clear()
                        self.bad_commands += 1
                        self._write(ERROR)
                    break
                line = bytes(buf[:cut])
                del buf[: cut + 1]
                self._write(self.handle(line.decode("ascii", "replace")))

    def handle(self, cmd: str) -> bytes:
        """Execute one command line (without its CR); return the reply bytes."""
        if not cmd:
            return OK
        c, arg = cmd[0], cmd[1:]
        try:
            if c in "tTrR":
                return self._transmit(c, arg)
            if c == "O" or c == "L":
                if self.is_open:  # a second open: refused (BEL), nothing dropped
                    return ERROR
                self.is_open, self.listen_only = True, c == "L"
                return OK
            if c == "C":
                # Frames the closing client left unread are dropped here, so the next client
                # starts clean (python-can's client closes first when it sets the bit rate,
                # one that died open included).  Not on "O": python-can opens twice (after
                # the bit rate, then again), and a flush at the second "O" could take the
                # client's first frames between its reader's select and its read ("device
                # reports readiness to read but returned no data"): its reception stopped
                # for good, a full suite's flaky CANopen tests.
                self._flush_stale()
                self.is_open = False
                return OK
            if c == "S":
                if self.is_open or len(arg) != 1 or arg not in "012345678":
                    return ERROR
                self.bitrate_code = arg
                return OK
            if c == "s":
                if self.is_open or len(arg) != 4:
                    return ERROR
                int(arg, 16)
                return OK
            if c == "V":
                return f"V{HW_VERSION}{SW_VERSION}\r".encode()
            if c == "v":
                return f"v{SW_VERSION}\r".encode()
            if c == "N":
                return f"N{SERIAL}\r".encode()
            if c == "F":
                return b"F00\r"
            if c == "Z":
                if arg not in ("0", "1"):
                    return ERROR
                self.timestamps = arg == "1"
                return OK
            if c in "XWMmUQ":
                return OK
        except ValueError:
            pass
        self.bad_commands += 1
        return ERROR

    def _transmit(self, c: str, arg: str) -> bytes:
        if not self.is_open or self.listen_only:
            return ERROR
        ext = c in "TR"
        n_id = 8 if ext else 3
        if len(arg) < n_id + 1:
            raise ValueError("short frame")
        can_id = int(arg[:n_id], 16)
        dlc = int(arg[n_id], 16)
        if dlc > 8 or can_id > (0x1FFFFFFF if ext else 0x7FF):
            raise ValueError("bad id or dlc")
        remote = c in "rR"
        hexdata = arg[n_id + 1 :]
        if remote:
            data = b""
        else:
            if len(hexdata) != 2 * dlc:
                raise ValueError("data length does not match dlc")
            data = bytes.fromhex(hexdata)
        self.bus.send(
            can.Message(arbitration_id=can_id, is_extended_id=ext, data=data, dlc=dlc, is_remote_frame=remote)
        )
        return b"Z\r" if ext else b"z\r"

    def _flush_stale(self) -> None:
        """Drop frames a previous client left unread, so a new client starts clean."""
        try:
            termios.tcflush(self.link.slave_fd, termios.TCIFLUSH)
        except (termios.error, OSError):
            pass

    # -- bus side -----------------------------------------------------------------------
    def _bus_loop(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.1)
            if msg is None or not self.is_open or msg.is_error_frame or msg.is_fd:
                continue
            if not self._write(self.encode(msg)):
                self.rx_dropped += 1

    def encode(self, msg: can.Message) -> bytes:
        """A received frame as an slcan line."""
        if msg.is_extended_id:
            head = f"{'R' if msg.is_remote_frame else 'T'}{msg.arbitration_id:08X}{msg.dlc:d}"
        else:
            head = f"{'r' if msg.is_remote_frame else 't'}{msg.arbitration_id:03X}{msg.dlc:d}"
        body = "" if msg.is_remote_frame else bytes(msg.data).hex().upper()
        stamp = f"{int(time.monotonic() * 1000) % 60000:04X}" if self.timestamps else ""
        return f"{head}{body}{stamp}\r".encode()


def open_slcan_pty(channel: str) -> tuple[PtyLink, SlcanAdapter]:
    """A pty with an slcan adapter bridged to the python-can ``virtual`` ``channel``."""
    link = PtyLink.open()
    bus = can.Bus(interface="virtual", channel=channel)
    return link, SlcanAdapter(link, bus).start()
