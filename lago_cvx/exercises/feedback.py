"""What a check of an exercise returns, and the small tools every check shares.

A check is ``check_<name>(answer)``: ``answer`` is the *function* the student wrote (its signature is given in
the lecture's stub cell), the check calls it on the exercise's data — and on other data where a property must
hold in general — and tests **properties** of what it returns (shapes, the residual of the defining equation,
an optimality condition, equality to the package's own computation up to the gauge and a tolerance), never one
stored array. It returns a ``Feedback``: ``✓ <what holds>`` or ``✗ <what is wrong>``.

Why a returned object and not a printed line: the package never prints (library code logs). A ``Feedback`` is
the cell's last expression, so Jupyter displays it (its ``repr`` is the one line); ``bool(feedback)`` is the
verdict for code and tests; ``feedback.require()`` raises ``WrongAnswer`` (a ``LagoError`` and an
``AssertionError``) when the answer is wrong, for scripts that must stop. A check never raises because of the
student's code: an exception inside the answer becomes a ``✗`` line that names it.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import numpy as np

from lago_cvx.errors import LagoError

__all__ = ["Feedback", "WrongAnswer", "exercise", "Wrong", "call", "array", "close"]

_log = logging.getLogger("lago_cvx.exercises")


class WrongAnswer(LagoError, AssertionError):
    """An exercise's answer does not hold (raised by ``Feedback.require``); the message says what is wrong."""


@dataclass(frozen=True)
class Feedback:
    """The verdict of a check: ``ok`` (bool), ``exercise`` (its title) and ``message`` (what holds, or what is
    wrong). Displayed in Jupyter as one line, ``✓ title: message`` or ``✗ title: message``."""

    ok: bool
    exercise: str
    message: str

    def __bool__(self) -> bool:
        return self.ok

    def __str__(self) -> str:
        return f"{'✓' if self.ok else '✗'} {self.exercise}: {self.message}"

    def __repr__(self) -> str:
        return str(self)

    def _repr_pretty_(self, printer, cycle) -> None:  # IPython's text/plain display
        printer.text(str(self))

    def require(self) -> "Feedback":
        """Return ``self`` when the answer holds; raise ``WrongAnswer`` with the message otherwise."""
        if not self.ok:
            raise WrongAnswer(str(self))
        return self


class Wrong(Exception):
    """Raised inside a check to stop with the message that names what is wrong."""


def exercise(title: str):
    """Decorate ``body(answer, **data) -> str`` (the praise) into a check returning a ``Feedback``; a ``Wrong``
    raised inside ``body`` becomes the ``✗`` message."""

    def wrap(body):
        @functools.wraps(body)
        def check(answer, **data) -> Feedback:
            try:
                praise = body(answer, **data)
            except Wrong as wrong:
                _log.debug("%s: %s", title, wrong)
                return Feedback(False, title, str(wrong))
            return Feedback(True, title, praise)

        check.title = title
        return check

    return wrap


def call(answer, name: str, *args, **kwargs):
    """``answer(*args, **kwargs)``; a missing body or an exception inside it becomes a ``Wrong`` naming it."""
    if not callable(answer):
        raise Wrong(f"pass the function {name} itself (not its result: got {type(answer).__name__})")
    try:
        return answer(*args, **kwargs)
    except NotImplementedError:
        raise Wrong(f"{name} is not written yet (its body raises NotImplementedError)") from None
    except Exception as exc:  # the student's code: its error is the feedback
        raise Wrong(f"{name} raised {type(exc).__name__}: {exc}") from None


def array(value, shape: tuple, what: str, *, dtype=float) -> np.ndarray:
    """``value`` as an array of ``shape`` (None in ``shape``: any length), or a ``Wrong`` naming ``what``."""
    if value is None:
        raise Wrong(f"{what} is None: return the array (the body has no `return`?)")
    try:
        out = np.asarray(value.toarray() if hasattr(value, "toarray") else value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise Wrong(f"{what} is not an array of numbers ({exc})") from None
    if out.ndim != len(shape) or any(s is not None and s != t for s, t in zip(shape, out.shape)):
        wanted = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise Wrong(f"{what} has shape {out.shape}, expected {wanted}")
    if np.issubdtype(out.dtype, np.number) and not np.all(np.isfinite(out)):
        raise Wrong(f"{what} holds NaN or infinite entries")
    return out


def close(mine, reference, what: str, *, rtol: float = 1e-8) -> float:
    """The relative difference max|mine − reference| / max(max|reference|, tiny); a ``Wrong`` when above
    ``rtol``, naming ``what`` and the first entry that differs."""
    mine, reference = np.asarray(mine), np.asarray(reference)
    scale = max(float(np.abs(reference).max(initial=0.0)), 1e-300)
    diff = np.abs(mine - reference)
    error = float(diff.max(initial=0.0)) / scale
    if not error <= rtol:
        where = np.unravel_index(int(np.argmax(diff)), diff.shape) if diff.ndim else ()
        entry = (f" (worst at index {tuple(int(i) for i in where)}: {mine[where]:.6g} instead of {reference[where]:.6g})"
                 if diff.ndim else f" ({mine:.6g} instead of {reference:.6g})")
        raise Wrong(f"{what} is off by {error:.1e} (relative){entry}")
    return error
