"""Array helpers where NumPy is slow.

* ``unique_sorted`` — ``numpy.unique`` of a plain integer array (no index, inverse or counts asked for) takes a hash-based path
in NumPy 2.4 that is far slower than sorting on large arrays of distinct keys such as the pose-pair keys of a
1 000 000-pose graph (``benchmarks/million.md``). ``unique_sorted`` sorts instead.
* ``row_blocks`` — per-edge arithmetic on (m, …) stacks done a block of rows at a time. NumPy makes a
  fresh temporary for every operation; on a whole 1 786 812-edge stack each is 14–130 MB, memory the
  kernel must hand over (and zero) anew, and in a virtual machine such first touches are slow
  (``benchmarks/million.md``). In blocks of ``BLOCK`` rows the temporaries fit in cache and are recycled by the
  allocator; only the outputs are new memory.
"""

from __future__ import annotations

import numpy as np

__all__ = ["unique_sorted", "row_blocks", "BLOCK"]

#: Rows per block of ``row_blocks`` (a (BLOCK, 3, 3) float stack is 1.2 MB).
BLOCK = 1 << 14


def unique_sorted(a) -> np.ndarray:
    """The distinct values of ``a`` (any shape, flattened), ascending: ``numpy.unique(a)`` by a sort."""
    v = np.sort(np.asarray(a).reshape(-1))
    if v.size:
        v = v[np.concatenate(([True], v[1:] != v[:-1]))]
    return v


def row_blocks(m: int, block: int | None = None):
    """Slices ``lo:hi`` covering ``range(m)`` in order, ``block`` rows each (default ``BLOCK``, read at
    the call; the last one shorter)."""
    block = BLOCK if block is None else int(block)
    for lo in range(0, m, block):
        yield slice(lo, min(lo + block, m))
