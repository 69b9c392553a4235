"""glibc's allocator told to keep freed memory for reuse: opt-in for a process that runs LAGO many times.

LAGO's closed forms allocate many arrays of a few hundred KiB to tens of MiB (patterns, edge systems,
factors) and free them a few milliseconds later. By default glibc serves blocks of that size with fresh
``mmap`` pages, or gives the top of its heap back to the kernel once more than a few MiB of it is free.
The next array then lands on pages the kernel must fault in and zero again. On the 2-core VM these
notes are measured on, a first touch costs about 3 ms per MiB, and one LAGO on se-sync/city10000.g2o
allocates several hundred MiB in total.

``keep_freed_memory()`` raises two thresholds through ``mallopt``:

* ``M_MMAP_THRESHOLD`` (default here 16 MiB): smaller blocks come from the heap, whose freed pages are
  reused, not from fresh ``mmap`` pages;
* ``M_TRIM_THRESHOLD`` (default here 64 MiB): the heap keeps up to that much free memory at its top
  instead of returning it to the kernel.

The price is memory that stays mapped after it is freed: at most about ``trim_threshold`` per heap (the
main one and one per thread arena). Setting either threshold also switches off glibc's own adaptive
threshold. The ``lago-cvx`` command calls this for its own process. A library user decides for their
process; nothing in ``import lago_cvx`` or ``lago()`` changes the allocator.

Measured (``python benchmarks/run.py perf``, whose process calls this; ``README.md``, "Performance"):
se-sync/city10000.g2o, LAGO's default route in process, 135–150 ms against 156–167 ms with glibc's
defaults; GTSAM's ``lago.initialize`` in the same process was not affected (237–250 against 242–253 ms).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

__all__ = ["keep_freed_memory", "MMAP_THRESHOLD", "TRIM_THRESHOLD"]

log = logging.getLogger(__name__)

#: Blocks below this size come from the heap (``M_MMAP_THRESHOLD``, bytes).
MMAP_THRESHOLD = 16 << 20
#: The heap keeps up to this much free memory at its top (``M_TRIM_THRESHOLD``, bytes).
TRIM_THRESHOLD = 64 << 20

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's <malloc.h>
_APPLIED: dict = {}


def keep_freed_memory(*, mmap_threshold: int = MMAP_THRESHOLD, trim_threshold: int = TRIM_THRESHOLD) -> bool:
    """Tell glibc's allocator to serve blocks below ``mmap_threshold`` bytes from its heap and to keep up to
    ``trim_threshold`` bytes of freed memory for reuse (module docstring). Returns True when glibc took
    both values, False where there is no glibc (macOS, Windows, musl) or it refused them; nothing is
    changed then. Calling it again with the same values does nothing more."""
    key = (int(mmap_threshold), int(trim_threshold))
    if key in _APPLIED:
        return _APPLIED[key]
    ok = False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = getattr(libc, "mallopt", None)
        if mallopt is not None and hasattr(libc, "gnu_get_libc_version"):
            mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
            mallopt.restype = ctypes.c_int
            ok = bool(mallopt(_M_MMAP_THRESHOLD, key[0])) and bool(mallopt(_M_TRIM_THRESHOLD, key[1]))
    except (OSError, AttributeError, ctypes.ArgumentError) as exc:
        log.debug("allocator left as it is (%s)", exc)
    log.debug("glibc allocator: mmap threshold %d, trim threshold %d: %s", *key, "set" if ok else "not set")
    _APPLIED[key] = ok
    return ok
