"""How many threads the engine may use: the cores of this process's CPU affinity, read when asked.

No count is fixed: a process pinned to one core (``taskset``, a Dask worker with one thread, a batch
scheduler's cgroup) gets one thread, a 64-core workstation gets more. ``LAGO_CVX_THREADS`` caps it (an
integer ≥ 1), for users who share a machine.
"""

from __future__ import annotations

import os

__all__ = ["cores"]


def cores() -> int:
    """Threads the engine may run at once: the CPUs this process may run on (``os.sched_getaffinity``;
    ``os.cpu_count()`` where affinity is unknown), capped by ``LAGO_CVX_THREADS`` when it is set."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    cap = os.environ.get("LAGO_CVX_THREADS", "").strip()
    if cap.isdigit() and int(cap) >= 1:
        n = min(n, int(cap))
    return max(1, n)
