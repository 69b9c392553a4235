"""Every error lago_cvx raises on purpose is a ``LagoError``.

The classes keep the built-in base they always had (``ValueError``, ``RuntimeError``, ``ImportError``,
``FileNotFoundError``, ``OSError``), so ``except ValueError`` in user code still catches a malformed file,
``except OSError`` an output that cannot be written, and one ``except LagoError`` catches everything the
package reports. Each class carries the exit status the command line uses for it (``exit_status``), so
the CLI maps errors to statuses in one place:

| class | built-in base | what happened | CLI exit |
|---|---|---|---|
| ``ParseError`` | ValueError | a file is malformed; the message starts with ``path:line:`` | 2 |
| ``OutputError`` | OSError | an output cannot be written (missing directory, permission, read-only file system, a failed write such as ENOSPC, a directory, socket or block device named as the output); one line naming the path as given and the reason | 2 |
| ``GraphError`` | ValueError | the graph is well-formed data but unusable (disconnected, broken odometric chain, unknown pose id) | 2 |
| ``NumericalError`` | GraphError | the least-squares system is numerically singular | 2 |
| ``NonFiniteError`` | NumericalError | an estimate or its χ² is not finite (the data overflow double precision) | 2 |
| ``OptionError`` | ValueError | a keyword argument or command-line option has a bad value | 2 |
| ``InfeasibleConstraintsError`` | ValueError | named convex constraints cannot all hold | 2 |
| ``DatasetNotFound`` | FileNotFoundError | a benchmark dataset is not where it was looked for | 2 |
| ``MissingSolverError`` | ImportError | an optional solver is not installed; the message names the pip extra | 2 |
| ``ResourceLimitError`` | RuntimeError | a search or time limit was reached on valid input | 4 |
| ``SearchLimitError`` | ResourceLimitError | the exact integer enumeration exceeded its node budget | 4 |
| ``SolverError`` | RuntimeError | a numerical solver failed (status not optimal) | 1 |
"""

from __future__ import annotations

import math
import numbers
import operator
import os

__all__ = [
    "LagoError", "ParseError", "OutputError", "GraphError", "NumericalError", "NonFiniteError", "OptionError",
    "InfeasibleConstraintsError", "PlanError",
    "DatasetNotFound", "MissingSolverError", "ResourceLimitError", "SearchLimitError", "SolverError",
    "check_choice",
]


class LagoError(Exception):
    """Base class of every error lago_cvx raises on purpose. ``exit_status`` is the CLI's status for it."""

    exit_status = 2


class ParseError(LagoError, ValueError):
    """A pose-graph file that cannot be read.

    Attributes: ``path`` (str, as given by the caller), ``line`` (1-based int, or None for whole-file
    problems) and ``problem`` (str). ``str(err)`` is the one-line ``"{path}:{line}: {problem}"``
    (``"{path}: {problem}"`` when ``line`` is None)."""

    def __init__(self, path, line: int | None, problem: str):
        super().__init__(path, line, problem)
        self.path = os.fspath(path) if isinstance(path, os.PathLike) else str(path)
        self.line = None if line is None else int(line)
        self.problem = " ".join(str(problem).split("\n"))

    def __str__(self) -> str:
        if self.line is None:
            return f"{self.path}: {self.problem}"
        return f"{self.path}:{self.line}: {self.problem}"


class OutputError(LagoError, OSError):
    """An output cannot be written. ``str(err)`` is one line, ``"cannot write {path}: {reason}"`` (or
    the like), naming the path as the caller gave it — never a temporary file. Attributes: ``path``
    (str or None) and ``errno`` (the operating system's error number, or None when the refusal is
    lago_cvx's own, e.g. a directory named as the output)."""

    def __init__(self, message: str, *, path=None, errno: int | None = None):
        super().__init__(message)
        self.message = " ".join(str(message).split("\n"))
        self.path = None if path is None else (os.fspath(path) if isinstance(path, os.PathLike) else str(path))
        self.errno = errno

    def __str__(self) -> str:
        return self.message

    def __reduce__(self):
        return _rebuild_output_error, (self.message, self.path, self.errno)


def _rebuild_output_error(message, path, errno):
    return OutputError(message, path=path, errno=errno)


class GraphError(LagoError, ValueError):
    """A graph that is well-formed as data but unusable for the requested operation (disconnected,
    broken odometric chain, unknown pose id, ...). The message says what and where."""


class NumericalError(GraphError):
    """The least-squares system is numerically singular (e.g. information spanning more than 1e16)."""


class NonFiniteError(NumericalError):
    """An estimate, or its χ², is not finite: the data overflow double precision (e.g. measurements of
    magnitude 1e200, whose squares are inf). Nothing is written."""


class PlanError(LagoError, ValueError):
    """A symbolic analysis handed to the sparse engine's compiled kernels is malformed — a parent pointer or an index
    out of range, a postorder that is not a permutation, pointers not increasing or beyond their arrays, a front too
    large for LAPACK's 32-bit sizes — found before any compiled code reads it (``lago_cvx.sparse.kernel_checks``)."""


class OptionError(LagoError, ValueError):
    """A keyword argument (or command-line option) has a value outside its documented choices."""


class InfeasibleConstraintsError(LagoError, ValueError):
    """The named convex constraints cannot all hold. ``names``: the constraints to blame (infeasible on
    their own, or an irreducible infeasible subset); ``phase``: "phase1" or "phase3"."""

    def __init__(self, message: str, names: list, phase: str):
        super().__init__(message)
        self.names = list(names)
        self.phase = phase


class DatasetNotFound(LagoError, FileNotFoundError):
    """The datasets folder, or a file in it, is absent; the message lists the places tried."""


class MissingSolverError(LagoError, ImportError):
    """An optional solver is not installed; the message names the pip extra that installs it."""


class ResourceLimitError(LagoError, RuntimeError):
    """A search or time limit was reached on valid input; the message names the option that raises it."""

    exit_status = 4


class SearchLimitError(ResourceLimitError):
    """The exact integer enumeration exceeded its node budget (too many uncertain cycle integers)."""


class SolverError(LagoError, RuntimeError):
    """A numerical solver (Clarabel, SCIP) did not reach an optimal status. ``status`` is the status it
    reported."""

    exit_status = 1

    def __init__(self, message: str, status: str | None = None):
        super().__init__(message)
        self.status = status


def check_choice(name: str, value, choices) -> None:
    """Raise ``OptionError`` unless ``value`` is one of ``choices`` (message names the option)."""
    if value not in choices:
        raise OptionError(f"unknown {name} {value!r}; expected one of {tuple(choices)}")


def check_real(name: str, value, *, optional: bool = False, low: float | None = None, open_low: bool = True,
               high: float | None = None, open_high: bool = True) -> float | None:
    """``value`` as a float when it is a finite real number (not a bool) within the bounds (open by default), None
    when ``optional`` and None; ``OptionError`` naming the option otherwise."""
    if value is None and optional:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise OptionError(f"{name} must be a finite number, got {value!r}")
    v = float(value)
    if (low is not None and (v <= low if open_low else v < low)) or \
            (high is not None and (v >= high if open_high else v > high)):
        span = (f"{'(' if open_low else '['}{'-inf' if low is None else f'{low:g}'}, "
                f"{'inf' if high is None else f'{high:g}'}{')' if open_high else ']'}")
        raise OptionError(f"{name} must be in {span}, got {value!r}")
    return v


def check_integer(name: str, value, *, low: int, optional: bool = False) -> int | None:
    """``value`` as an int when it is an integer (Python's or NumPy's, not a bool) ≥ ``low``, None when
    ``optional`` and None; ``OptionError`` naming the option otherwise."""
    if value is None and optional:
        return None
    try:
        v = None if isinstance(value, bool) else operator.index(value)
    except TypeError:
        v = None
    if v is None or v < low:
        raise OptionError(f"{name} must be an integer ≥ {low}, got {value!r}")
    return v
