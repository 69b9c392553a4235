"""The optional C kernels of the sparse engine (``lago_cvx.sparse._ckernels``, loaded by ``lago_cvx.sparse.c_kernels``
through ctypes). ``optional=True``: without a C compiler the install still succeeds and the engine factors by its
NumPy fallback, with a warning. Every other setting is in pyproject.toml."""

import sys

from setuptools import Extension, setup

# -ffp-contract=off: no fused multiply-add, so the C kernels give the same bits on every processor.
FLAGS = [] if sys.platform == "win32" else ["-O3", "-ffp-contract=off"]

setup(ext_modules=[Extension("lago_cvx.sparse._ckernels", ["lago_cvx/sparse/_ckernels.c"], optional=True,
                             extra_compile_args=FLAGS)])
