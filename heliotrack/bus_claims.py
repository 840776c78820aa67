"""One heliotrack process at a time on a shared bus: a Modbus TCP endpoint, a CAN channel.

pyserial holds an RS-485 port exclusively and the CANopen link holds an slcan adapter, so a
second process on those is refused by the device.  A Modbus TCP gateway or drive takes any
number of connections, and a SocketCAN channel any number of sockets: a trial ``run`` with
another ``--state``, or a ``check`` beside the service (it writes each drive's
configuration), would drive the same drives at once, each taking the other's writes for a
drive that does not keep its configuration.  So every process that drives them holds a
lock per bus for its life, in a machine-wide folder (``$HELIOTRACK_LOCK_DIR``, else
``/run/lock``, else the temporary folder): ``flock``, which the kernel lets go however the
process ends.  Containers on one host share a bus only through a folder they all mount,
named by ``HELIOTRACK_LOCK_DIR``.  A bus is named as
the configuration names it (``link.bus``: host and port as written; ``localhost`` and
``127.0.0.1`` are two names), so this guards one edge computer against itself, not two
computers against each other.
"""

from __future__ import annotations

import errno
import fcntl
import logging
import os
import re
import tempfile
from collections.abc import Iterable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from controller.drives.links import LinkConfig
from controller.errors import UserError

log = logging.getLogger(__name__)

#: Where the locks go: the first of these that is a writable folder.
LOCK_DIRS = (Path("/run/lock"), Path(tempfile.gettempdir()))
#: A folder named here holds the locks instead (created if missing).
LOCK_DIR_ENV = "HELIOTRACK_LOCK_DIR"


class Held(Exception):
    """Another process holds the lock; ``pid`` is what it wrote there ("unknown" if none)."""

    def __init__(self, pid: str):
        super().__init__(pid)
        self.pid = pid


def hold(fd: int, what: str) -> None:
    """Take an exclusive ``flock`` on ``fd`` and write this process's pid into it.

    Raises :class:`Held` when another process has it.  A file system without locks (some
    network mounts) is warned about and the lock is taken as held: ``what`` names it.
    """
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as exc:
        if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            log.warning("%s: not locked (%s): nothing stops a second process here", what, exc.strerror)
        else:
            raise Held(os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "unknown") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)


def shared_buses(links: Iterable[LinkConfig]) -> dict[tuple[str, ...], str]:
    """The buses of ``links`` that other processes could open too (Modbus TCP endpoints,
    CAN channels other than python-can's in-process ``virtual``), each with the name of
    the first link on it."""
    out: dict[tuple[str, ...], str] = {}
    for link in links:
        bus = link.bus
        if bus[0] == "tcp" or (bus[0] == "can" and bus[1] != "virtual"):
            out.setdefault(bus, link.name)
    return out


def lock_path(bus: tuple[str, ...]) -> Path:
    """The lock file of ``bus`` (``heliotrack-tcp-10.0.0.5-502.lock``)."""
    name = "heliotrack-" + "-".join(re.sub(r"[^A-Za-z0-9._]", "_", part) for part in bus) + ".lock"
    named = os.environ.get(LOCK_DIR_ENV)
    if named:
        return Path(named) / name
    folder = next((d for d in LOCK_DIRS if d.is_dir() and os.access(d, os.W_OK)), LOCK_DIRS[-1])
    return folder / name


@contextmanager
def claim_buses(links: Iterable[LinkConfig]) -> Iterator[None]:
    """Hold the lock of every shared bus of ``links`` for the block.

    Raises
    ------
    UserError
        Another heliotrack process drives one of them (the message names the link, the bus
        and the pid).
    """
    with ExitStack() as stack:
        for bus, name in shared_buses(links).items():
            path = lock_path(bus)
            try:
                path.parent.mkdir(parents=True, exist_ok=True)  # a HELIOTRACK_LOCK_DIR not made yet
                fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
            except OSError as exc:
                log.warning("%s: not locked (%s): nothing stops a second process here", path, exc.strerror)
                continue
            stack.callback(os.close, fd)
            try:
                hold(fd, str(path))
            except Held as held:
                where = ":".join(bus[1:]) if bus[0] == "tcp" else f"CAN channel {bus[1]}"
                raise UserError(
                    f"link {name!r}: {where} is driven by another heliotrack process (pid {held.pid}): "
                    "one run or check at a time on a bus; stop it first"
                ) from None
        yield
