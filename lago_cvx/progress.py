"""Progress of long computations: one callback protocol and one throttle.

Whatever can run longer than a few seconds (the factorizations and solves of LAGO at scale, the selected
inversion behind ``pose_covariances``, the integer search, the certification loops) reports its progress
in two ways:

* an INFO record on its module's logger (``lago_cvx.<module>``), at most once per ``interval`` seconds
  (default 1 s) and never for a computation that finishes within the first interval;
* a call ``progress(stage, fraction)`` of the optional keyword-only ``progress=`` argument, a
  ``ProgressCallback``: ``stage`` a short human-readable name (e.g. ``"phase 3: factorization"``),
  ``fraction`` in [0, 1]. The callback is called once with 0.0 when the stage starts, at most once per
  ``interval`` seconds while it runs, and once with 1.0 when it ends.

Nothing is printed: drawing a bar is the caller's business (e.g. the command line's).

``held_back()`` keeps the package's records below ERROR out of the log within a block, in the calling thread
only (the inner runs of an iterative method such as graduated non-convexity, whose warnings are not the
result's). It changes no logger's level: another thread's records, and a process forked meanwhile, are untouched.

    def show(stage, fraction):
        print(f"\\r{stage}: {100 * fraction:5.1f} %", end="")
    res = lago_cvx.lago(graph, progress=show)
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import logging
import time
from pathlib import Path
from typing import Callable, Optional

__all__ = ["ProgressCallback", "Progress", "PROGRESS_INTERVAL", "Stages", "held_back"]

#: ``progress(stage, fraction)``: ``stage`` a short name of the running step, ``fraction`` in [0, 1].
ProgressCallback = Callable[[str, float], None]

#: Seconds between two reports of the same stage (log records and callback calls).
PROGRESS_INTERVAL = 1.0


class Progress:
    """Throttled reporter of one stage.

    ``Progress(stage, callback=None, logger=None, interval=PROGRESS_INTERVAL, clock=time.monotonic)``;
    ``update(done, total)`` (or ``update(fraction)``) reports when ``interval`` has passed since the last
    report; ``finish()`` reports 1.0 to the callback (and to the log when the stage took longer than
    ``interval``). Cheap enough to call in every iteration of a loop. Use as a context manager to get
    ``finish()`` on exit."""

    def __init__(self, stage: str, *, callback: Optional[ProgressCallback] = None,
                 logger: Optional[logging.Logger] = None, interval: float = PROGRESS_INTERVAL,
                 clock: Callable[[], float] = time.monotonic, extra: Optional[dict] = None):
        self.stage = stage
        self.extra = extra  # the log records' extra attributes (``Stages``: logged inside ``held_back`` too)
        self.callback = callback
        self.logger = logger
        self.interval = float(interval)
        self.clock = clock
        self.start = self.last = clock()
        self.logged = False
        self.finished = False
        if callback is not None:
            callback(stage, 0.0)

    def update(self, done: float, total: float | None = None) -> None:
        """Report ``done / total`` (or ``done`` as a fraction when ``total`` is None) if the throttle
        allows."""
        now = self.clock()
        if now - self.last < self.interval:
            return
        fraction = float(done) if total is None else (float(done) / float(total) if total else 1.0)
        fraction = min(max(fraction, 0.0), 1.0)
        self.last = now
        if self.callback is not None:
            self.callback(self.stage, fraction)
        if self.logger is not None and self.logger.isEnabledFor(logging.INFO):
            self.logger.info("%s: %.0f %% (%.1f s)", self.stage, 100.0 * fraction, now - self.start, extra=self.extra)
            self.logged = True

    def finish(self) -> None:
        """Report the end of the stage (once)."""
        if self.finished:
            return
        self.finished = True
        now = self.clock()
        if self.callback is not None:
            self.callback(self.stage, 1.0)
        if self.logger is not None and (self.logged or now - self.start >= self.interval):
            self.logger.info("%s: done in %.1f s", self.stage, now - self.start, extra=self.extra)

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.finish()


class Stages:
    """Progress of an iterative method in named stages of counted steps (graduated non-convexity: its GNC
    iterations, then its local moves, each step one inner LAGO run). ``stage(name, total)`` starts a stage of at most
    ``total`` steps (and finishes the previous one), ``step()`` counts one, ``finish()`` ends the last. Reported as
    ``Progress`` reports, "{prefix}: {name}", its log records kept even inside ``held_back()``."""

    def __init__(self, prefix: str, *, callback: Optional[ProgressCallback] = None,
                 logger: Optional[logging.Logger] = None, interval: float = PROGRESS_INTERVAL):
        self.prefix, self.callback, self.logger, self.interval = prefix, callback, logger, interval
        self.current, self.total, self.done = None, 1, 0

    def stage(self, name: str, total: int) -> None:
        self.finish()
        self.current = Progress(f"{self.prefix}: {name}", callback=self.callback, logger=self.logger,
                                interval=self.interval, extra={_OWN: True})
        self.total, self.done = max(int(total), 1), 0

    def step(self) -> None:
        if self.current is not None:
            self.done += 1
            self.current.update(min(self.done, self.total), self.total)

    def finish(self) -> None:
        if self.current is not None:
            self.current.finish()
            self.current = None


#: The attribute that lets a ``Stages`` record through ``held_back()``.
_OWN = "lago_cvx_stages"

#: True inside ``held_back()``, per thread (and per asyncio task): a context variable, not a global.
_HELD_BACK = contextvars.ContextVar("lago_cvx_held_back", default=False)


class _HoldBack(logging.Filter):
    """Drops a record below ERROR while its thread is inside ``held_back()``."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.ERROR or not _HELD_BACK.get() or getattr(record, _OWN, False)


_FILTER = _HoldBack()


@functools.lru_cache(maxsize=1)
def _package_loggers() -> tuple[str, ...]:
    """The names of the package's modules and packages (``lago_cvx``, ``lago_cvx.variants.gnc`` …), from its files:
    the names its loggers take. Nothing is imported."""
    root = Path(__file__).resolve().parent
    names = {"lago_cvx"}
    for path in root.rglob("*.py"):
        parts = path.relative_to(root).with_suffix("").parts
        names.add(".".join(("lago_cvx", *parts[:-1], *(() if parts[-1] == "__init__" else parts[-1:]))))
    return tuple(sorted(names))


@functools.lru_cache(maxsize=1)
def _install_filter() -> None:
    """The filter on the logger of every module and package name, once per process (a forked child inherits it)."""
    for name in _package_loggers():
        logger = logging.getLogger(name)
        if _FILTER not in logger.filters:
            logger.addFilter(_FILTER)


@contextlib.contextmanager
def held_back():
    """Within the block, the package's log records below ERROR from the calling thread are dropped (module
    docstring). The filter sits on every ``lago_cvx`` logger (a logger's filters see only its own records) and does
    nothing outside such a block. Every module's logger (``__name__``, or the name of its package) is made on the
    first block, so that a module imported inside one is held back too."""
    _install_filter()
    token = _HELD_BACK.set(True)
    try:
        yield
    finally:
        _HELD_BACK.reset(token)
