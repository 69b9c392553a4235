"""What every lecture shares: set-up, one-line checks, inline figures (written to disk, byte for byte
reproducibly, only when asked), real benchmark graphs (or a clear skip), and the paper's procedure.

Used as ``from _lecture import ...`` by the lectures (run from any working directory: Jupyter, a script,
the tests) and by their exercise solutions in ``solutions/``::

    from _lecture import setup, check, show, real, FULL
    setup("02_phase1")                   # quiet warnings, compact printing, figures named 02_phase1_*
    check(err < 1e-9, f"cvxpy = closed form ({err:.1e})")     # prints "✓ cvxpy = closed form (3.1e-16)"
    fig, ax = plt.subplots(); ...; show(fig, "laplacian")      # inline in Jupyter; saved only on request

Running a lecture changes no file: figures are displayed, and written to ``figures/`` only when the
environment variable ``LAGO_CVX_FIGURES`` names a folder (``python lectures/render.py`` sets it to the
project's ``figures/``; the tests set it to a temporary folder). ``LAGO_CVX_FULL=1`` turns on the
bigger sweeps that are skipped by default to keep every lecture under a minute.
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

import matplotlib as mpl
import numpy as np

import lago_cvx as lc
from lago_cvx.datasets import DatasetNotFound, dataset

__all__ = ["ROOT", "FULL", "S", "setup", "check", "show", "real", "paper_lago", "figure_dir"]

#: The project checkout.
ROOT = Path(__file__).resolve().parents[1]

#: Bigger sweeps (more seeds, sizes, noise levels) run only with ``LAGO_CVX_FULL=1``.
FULL = os.environ.get("LAGO_CVX_FULL", "") not in ("", "0")

#: The 90° rotation S = [[0, −1], [1, 0]] (S Δ is Δ turned by +90°; ∂R(θ)/∂θ = S R(θ)).
S = np.array([[0.0, -1.0], [1.0, 0.0]])

# Reproducible figure files: SVG ids from a fixed salt, no dates or tool versions in any file.
mpl.rcParams["svg.hashsalt"] = "lago-cvx"
mpl.rcParams["svg.fonttype"] = "path"
_METADATA = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None}}
_INLINE_DPI = 100  # the resolution of the figures shown inline (and stored in the rendered notebooks)

_PREFIX = ["lecture"]


def setup(prefix: str) -> None:
    """Start a lecture: figure files will be named ``<prefix>_<name>.{png,svg}``; the package's warnings
    (e.g. ambiguous 2kπ roundings, which lectures count themselves) stay out of the output; NumPy prints
    compactly."""
    _PREFIX[0] = prefix
    logging.getLogger("lago_cvx").setLevel(logging.ERROR)
    np.set_printoptions(precision=4, suppress=True, linewidth=110)


def check(condition, claim: str) -> None:
    """One quiet line per verified claim: prints ``✓ claim``, or raises ``AssertionError('✗ claim')``."""
    if not bool(condition):
        raise AssertionError(f"✗ {claim}")
    print(f"✓ {claim}")


def figure_dir() -> Path | None:
    """Where figures are written: ``$LAGO_CVX_FIGURES`` if set, else nowhere (None)."""
    target = os.environ.get("LAGO_CVX_FIGURES", "")
    return Path(target) if target else None


def _in_notebook() -> bool:
    shell = sys.modules.get("IPython")
    ip = shell.get_ipython() if shell is not None and hasattr(shell, "get_ipython") else None
    return ip is not None and ip.__class__.__name__ == "ZMQInteractiveShell"


def show(fig, name: str) -> None:
    """Display ``fig`` inline (in Jupyter, as a PNG), write ``<prefix>_<name>.png`` and ``.svg`` when
    ``$LAGO_CVX_FIGURES`` is set (identical bytes on every run), then close it."""
    import matplotlib.pyplot as plt

    target = figure_dir()
    if target is not None:
        target.mkdir(parents=True, exist_ok=True)
        for ext in ("png", "svg"):
            fig.savefig(target / f"{_PREFIX[0]}_{name}.{ext}", dpi=120, bbox_inches="tight",
                        metadata=_METADATA[ext])
    if _in_notebook():
        import base64
        import io

        from IPython.display import display

        # The PNG bytes are made here, without the "Software" stamp the inline backend adds, so that a
        # re-rendered notebook changes only where the figure does.
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=_INLINE_DPI, bbox_inches="tight", metadata=_METADATA["png"])
        display({"image/png": base64.b64encode(buffer.getvalue()).decode("ascii")}, raw=True)
    plt.close(fig)


def paper_lago(graph, **options):
    """LAGO with the paper's phases — the tree rounding of Theorem 3, phases 2–3 with blkdiag(P_Δ, P_δ)
    (eqs. (9)–(15)) and phase 3's poses — on the BFS tree unless ``spanning_tree`` says otherwise
    (``route="seed"`` also takes the odometric tree, which not every graph has)."""
    return lc.lago(graph, **{"regularization": "tree", "information": "marginal", "positions": "phase3", **options})


def real(rel: str):
    """Read a real benchmark graph (``rel`` inside the datasets folder, e.g. ``"carlone/INTEL_P_toro.graph"``),
    or return None and say so when the datasets are absent: the lecture then runs its synthetic cells only."""
    try:
        return lc.read_graph(dataset(rel))
    except DatasetNotFound as exc:
        print(f"real datasets not found: skipping the {rel} cells ({exc})")
        return None


def solve_qp(problem):
    """Solve a cvxpy ``problem`` with Clarabel as the package does (tolerances 1e-12, iterative refinement:
    ``solvers.LEAST_SQUARES``) but with Clarabel's default static regularization 1e-8 and its QDLDL
    factorization, which the lectures' equality-constrained forms with dense parameters need; returns the
    status."""
    import cvxpy as cp

    from lago_cvx.solvers import LEAST_SQUARES, ClarabelSettings

    kwargs = ClarabelSettings(static_regularization_constant=1e-8).over(LEAST_SQUARES).solver_kwargs()
    problem.solve(solver=cp.CLARABEL, direct_solve_method="qdldl", **kwargs)
    return problem.status
