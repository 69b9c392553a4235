"""How many threads the engine may use (``cores()``: its compiled subtrees, solves, background builds; ``workers=1``
runs it in the calling thread alone), and whether it may touch the process's BLAS thread count (``blas_limit()``:
only inside ``engine_threads(blas_threads=k)``, never by default, as the count is process-wide — OpenBLAS has no
thread-local count). Both are context variables, handed to the threads the engine starts (``spawn``).
"""

from __future__ import annotations

import contextlib
import contextvars
import operator
import os
import threading

from ..errors import OptionError

__all__ = ["cores", "engine_threads", "blas_limit", "spawn", "check_workers", "in_engine_threads", "Ahead",
           "thread_settings", "threads_option"]

_WORKERS: contextvars.ContextVar = contextvars.ContextVar("lago_cvx_workers", default=None)
_BLAS_LIMIT: contextvars.ContextVar = contextvars.ContextVar("lago_cvx_blas_threads", default=None)


def check_workers(value, name: str = "workers") -> int | None:
    """``value`` as a thread count (None, or an integer ≥ 1); OptionError otherwise."""
    if value is None:
        return None
    try:
        n = None if isinstance(value, bool) else operator.index(value)
    except TypeError:
        n = None
    if n is None or n < 1:
        raise OptionError(f"{name} must be None or an integer >= 1, not {value!r}")
    return n


def cores() -> int:
    """Threads the engine may run at once: the CPUs this process may run on (``os.sched_getaffinity``, else
    ``os.cpu_count()``), capped by ``LAGO_CVX_THREADS`` when set and by ``engine_threads(workers=…)`` (SciPy's name)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    cap = os.environ.get("LAGO_CVX_THREADS", "").strip()
    if cap.isdigit() and int(cap) >= 1:
        n = min(n, int(cap))
    w = _WORKERS.get()
    if w is not None:
        n = min(n, w)
    return max(1, n)


def thread_settings() -> tuple:
    """(workers, blas_threads) set in this context (None where unset)."""
    return _WORKERS.get(), _BLAS_LIMIT.get()


def blas_limit() -> int | None:
    """The BLAS thread count the engine may set in this context: None (leave the process's BLAS alone) unless
    ``engine_threads(blas_threads=k)`` asked for k."""
    return _BLAS_LIMIT.get()


@contextlib.contextmanager
def engine_threads(*, workers: int | None = None, blas_threads: int | None = None):
    """Run a block with the engine's own threads capped at ``workers`` (None: ``cores()``'s default) and, only
    when ``blas_threads`` is given, the process's BLAS held to at most that many threads while the engine's
    dense kernels run (None: the BLAS settings are left alone). Values given as None keep the enclosing
    block's. Raises OptionError for a count that is not an integer ≥ 1."""
    workers, blas_threads = check_workers(workers), check_workers(blas_threads, "blas_threads")
    tokens = []
    if workers is not None:
        tokens.append((_WORKERS, _WORKERS.set(workers)))
    if blas_threads is not None:
        tokens.append((_BLAS_LIMIT, _BLAS_LIMIT.set(blas_threads)))
    try:
        yield
    finally:
        for var, token in reversed(tokens):
            var.reset(token)


def spawn(target, *args, name: str | None = None, start: bool = True) -> threading.Thread:
    """A daemon thread running ``target(*args)`` in a copy of the caller's context (its ``workers`` and
    ``blas_threads``), started unless ``start`` is False."""
    ctx = contextvars.copy_context()
    t = threading.Thread(target=ctx.run, args=(target, *args), daemon=True, name=name)
    if start:
        t.start()
    return t


def threads_option(fn, settings=lambda args, kw: (kw.get("workers"), kw.get("blas_threads"))):
    """A function with the keyword-only options ``workers`` (and ``blas_threads`` where it has one), run inside
    ``engine_threads`` of them: every engine call it makes, in any thread the engine starts for it, sees them."""
    import functools

    @functools.wraps(fn)
    def run(*args, **kwargs):
        workers, blas = settings(args, kwargs)
        with engine_threads(workers=workers, blas_threads=blas):
            return fn(*args, **kwargs)

    return run


def in_engine_threads(method):
    """A method run inside ``engine_threads`` of its object's ``workers`` and ``blas_threads`` attributes."""
    return threads_option(method, lambda args, kw: (args[0].workers, args[0].blas_threads))


class Ahead:
    """``task(*args)``, run at most once: by the engine ahead of need (``run``), or by whoever first asks
    for the value (``result``, which returns it or raises the task's error — a background failure reaches
    the caller). A ``result()`` asked while another thread runs it waits for it; the task itself may start
    a factorization that runs the engine's queue, where it is skipped (it is under way)."""

    def __init__(self, task, *args):
        self._task, self._args = task, args
        self._context = contextvars.copy_context()  # run with its creator's workers and blas_threads
        self._lock = threading.RLock()
        self.done, self._running = False, False
        self._value, self._error = None, None

    def run(self) -> None:
        with self._lock:
            if self.done or self._running:
                return
            self._running = True
            try:
                self._value = self._context.run(self._task, *self._args)
            except BaseException as exc:  # kept for ``result``
                self._error = exc
            finally:
                self.done, self._running = True, False
                self._task = self._args = None

    def result(self):
        self.run()
        if self._error is not None:
            raise self._error
        return self._value
