"""Start-up of the ``lago-cvx`` process: NumPy submodules that SciPy touches but never runs, made lazy.

Importing ``scipy.sparse`` (SciPy 1.15+) builds SciPy's array-API namespace by cloning NumPy's: it looks
up every public name of ``numpy``, and each lookup of a lazily loaded submodule executes it. So a
process that only factors a sparse matrix pays for ``numpy.f2py`` (the Fortran wrapper generator, which
pulls in ``charset_normalizer``), ``numpy.testing`` (``unittest``, ``difflib``, ``subprocess``),
``numpy.ma``, ``numpy.random``, ``numpy.polynomial`` and ``numpy.ctypeslib``: a large share of a short
``lago-cvx solve`` (whole processes against ``LAGO_CVX_EAGER_IMPORTS=1``: ``benchmarks/endtoend.md``).

:func:`defer_unused_numpy_modules` registers those submodules with the standard library's
:class:`importlib.util.LazyLoader` before SciPy is imported. The clone then binds module objects whose
code runs on first attribute access, so a submodule that is used (``lago-cvx generate`` draws from
``numpy.random``; ``plot`` uses ``numpy.ma`` through matplotlib) loads exactly as before, only later.
Nothing else changes: the same code runs on the same data.

Only the console entry point calls it (``main()`` with ``argv=None``): it changes the import state of a
whole process, which is ours to change in the ``lago-cvx`` process and not in a user's interpreter.
``LAGO_CVX_EAGER_IMPORTS=1`` turns it off.
"""

from __future__ import annotations

import importlib.util
import os
import sys

#: NumPy submodules that ``import scipy.sparse`` executes only because it enumerates ``numpy``'s names.
DEFERRED_NUMPY_MODULES = ("numpy.f2py", "numpy.testing", "numpy.ma", "numpy.random", "numpy.polynomial",
                          "numpy.ctypeslib")


def defer_unused_numpy_modules(names=DEFERRED_NUMPY_MODULES) -> list[str]:
    """Register each not-yet-imported module in ``names`` as lazy; return the names deferred.

    A module already imported, or one this NumPy does not have, is left alone. Each deferred module is
    also bound as an attribute of ``numpy``, so that ``numpy.<name>`` finds it without running NumPy's
    own lazy ``__getattr__`` (which would import it for real).
    """
    if os.environ.get("LAGO_CVX_EAGER_IMPORTS", "") not in ("", "0"):
        return []
    import numpy

    deferred = []
    for name in names:
        if name in sys.modules:
            continue
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None:
            continue
        loader = importlib.util.LazyLoader(spec.loader)
        spec.loader = loader
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        loader.exec_module(module)  # arms the lazy module; its code runs on first attribute access
        setattr(numpy, name.rpartition(".")[2], module)
        deferred.append(name)
    return deferred
