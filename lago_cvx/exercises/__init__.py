"""The course's exercises that check the student: one ``check_<name>(answer)`` per exercise of every lecture.

The student fills in the body of a function whose signature the lecture's stub cell gives, then runs
``check_<name>(that_function)``. The check calls the function on the exercise's data (the ``*_case`` helpers
build it; the stub calls them too) and, where a property must hold in general, on more data; it tests
**properties** — shapes, the residual of the defining equation, an optimality condition, equality to the
package's own computation up to the gauge and a tolerance — so every correct answer passes, and says what is
wrong otherwise.

A check **returns** a ``Feedback`` and prints nothing (library code never prints): the notebook displays it as
the cell's value, ``✓ <exercise>: <what holds>`` or ``✗ <exercise>: <what is wrong>``; ``bool(feedback)`` is the
verdict; ``feedback.require()`` raises ``WrongAnswer`` when it is wrong (the solution cells call it, so an
executed notebook proves its solutions pass). An exception raised by the student's function becomes the ``✗``
message, never a traceback from here.

Layered with ``course`` (docs/ARCHITECTURE.md, layer 12): it uses the package and ``course``'s worlds, nothing
above. ``basics`` holds lectures 01–04b, ``beyond`` 05–09, ``robust`` 10–11, ``feedback`` the shared tools.
"""

from lago_cvx.exercises.basics import *  # noqa: F401,F403
from lago_cvx.exercises.basics import __all__ as _basics
from lago_cvx.exercises.beyond import *  # noqa: F401,F403
from lago_cvx.exercises.beyond import __all__ as _beyond
from lago_cvx.exercises.feedback import Feedback, WrongAnswer
from lago_cvx.exercises.robust import *  # noqa: F401,F403
from lago_cvx.exercises.robust import __all__ as _robust

__all__ = ["Feedback", "WrongAnswer", *_basics, *_beyond, *_robust]

#: Every check, by lecture: ``{"01": [check_half_offset, ...], ...}`` (the tests feed each its solution).
CHECKS = {}
for _name in __all__:
    if _name.startswith("check_"):
        _check = globals()[_name]
        CHECKS.setdefault(_check.title.split(",")[0], []).append(_check)
