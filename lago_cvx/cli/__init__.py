"""Command-line interface ``lago-cvx`` (also ``python -m lago_cvx``): argument parsing and printing only.

Sub-commands: ``info``, ``solve``, ``certify``, ``generate``, ``demo``, ``datasets``, ``plot``. Exit status:
0 success, 2 the user's input (unreadable or malformed file, unusable graph, bad option, an output that
cannot be written, an estimate that is not finite), 3 (``certify``) not certified, 4 a resource limit on
valid input, 1 internal error. Errors are one line ``lago-cvx: error: …`` on stderr, never a traceback
(``LAGO_CVX_DEBUG=1`` shows one). Modules: ``common`` (shared options, output targets, printing),
``solve`` (info, solve), ``certify``, ``worlds`` (generate, demo), ``data`` (datasets), ``plot``, ``main``,
``startup`` (the console process's start-up: NumPy submodules SciPy only enumerates are made lazy).
"""

from .common import EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_NOT_CERTIFIED, EXIT_OK, EXIT_RESOURCE, UsageError
from .main import build_parser, main
from .solve import parse_anchor_spec

__all__ = ["main", "build_parser", "parse_anchor_spec", "UsageError", "EXIT_OK", "EXIT_INTERNAL", "EXIT_BAD_INPUT",
           "EXIT_NOT_CERTIFIED", "EXIT_RESOURCE"]
