"""The C heap of a process that runs for months: large blocks straight from the system.

glibc serves a block under its mmap threshold from its heaps, and raises that threshold
(up to 32 MiB) each time a large mmapped block is freed.  A process that allocates frames
and arrays of a few MB now and then (a camera frame, a rendered sky, a month of SQLite
pages) soon has them all in its heaps, where small long-lived objects allocated between
them pin the pages: the heap keeps its high-water mark (the soak: 677 MB of heap, 540 of
it free, after one simulated day) and RSS rises in steps as fragmentation moves.  A
fixed threshold (which also stops glibc's adjustment) gives every large block its own
mapping, returned to the system when freed (the soak: 48 MB of heap, 3.5 free; RSS 292
MB against 323).  The price is a page fault per large allocation: ``heliotrack run`` and
the soak set it, the benchmarks of speed do not.
"""

from __future__ import annotations

import ctypes
import logging
import os

log = logging.getLogger(__name__)

#: ``mallopt`` parameter number of M_MMAP_THRESHOLD (glibc malloc.h).
_M_MMAP_THRESHOLD = -3
#: Blocks from this size up (bytes) are mapped on their own.
MMAP_THRESHOLD = 256 * 1024


def bound_heap(threshold: int = MMAP_THRESHOLD) -> bool:
    """Serve blocks of ``threshold`` bytes and more by ``mmap`` (glibc only).

    Returns True when set; False on another C library, or when the environment already
    sets ``MALLOC_MMAP_THRESHOLD_`` (the operator's choice stands).
    """
    if "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    ok = bool(mallopt(_M_MMAP_THRESHOLD, int(threshold)))
    if ok:
        log.debug("large blocks (>= %d bytes) mapped on their own", threshold)
    return ok
