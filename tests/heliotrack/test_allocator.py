"""heliotrack.allocator: large blocks mapped on their own, so freeing them returns them."""

import os
import subprocess
import sys

CHILD = r"""
import ctypes, sys
import numpy as np
from heliotrack.allocator import bound_heap
if sys.argv[1] == "bound":
    assert bound_heap()
class M(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]
f = ctypes.CDLL("libc.so.6").mallinfo2
f.restype = M
# a freed 8-MB block raises glibc's dynamic threshold; the 1-MB arrays of a peak then come
# from the heap, between small objects that outlive them and pin its pages
np.ones(1 << 20)
peak, keep = [], []
for _ in range(40):
    peak.append(np.ones(1 << 17))  # 1 MB
    keep.append(bytearray(600))
del peak
ctypes.CDLL("libc.so.6").malloc_trim(0)
print(f().arena >> 20)
"""


def heap_mb(mode: str) -> int:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run(
        [sys.executable, "-c", CHILD, mode], capture_output=True, text=True, env=env, check=True
    )
    return int(out.stdout.strip().splitlines()[-1])


def test_large_blocks_do_not_stay_in_the_heap():
    bound, default = heap_mb("bound"), heap_mb("default")
    assert default >= 40 and bound < 10, (bound, default)


def test_the_operators_setting_stands(monkeypatch):
    from heliotrack.allocator import bound_heap

    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "131072")
    assert bound_heap() is False
