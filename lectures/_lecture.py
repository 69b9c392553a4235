"""What every lecture shares: where figures go (and how they are written byte-for-byte reproducibly),
how a real benchmark graph is read (or skipped, saying so), quiet logging and print options.

Used as ``from _lecture import ...`` by the lectures (run from any working directory: Jupyter, a script,
the tests) and by their exercise solutions in ``solutions/``.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import matplotlib as mpl
import numpy as np

import lago_cvx as lc
from lago_cvx.datasets import DatasetNotFound, dataset

__all__ = ["ROOT", "FIG", "S", "real", "figure_saver", "quiet", "paper_lago"]

#: The project checkout, and the folder the lectures write their figures to (``figures/``; the tests point
#: ``LAGO_CVX_FIGURES`` at a temporary folder, so that running them changes no tracked file).
ROOT = Path(__file__).resolve().parents[1]
FIG = Path(os.environ.get("LAGO_CVX_FIGURES", ROOT / "figures"))

#: The 90° rotation S = [[0, −1], [1, 0]] (S Δ is Δ turned by +90°; ∂R(θ)/∂θ = S R(θ)).
S = np.array([[0.0, -1.0], [1.0, 0.0]])

# Reproducible figures: SVG ids from a fixed salt, no dates or tool versions in any file.
mpl.rcParams["svg.hashsalt"] = "lago-cvx"
_METADATA = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None}}


def paper_lago(graph, **options):
    """LAGO with the paper's phases — the tree rounding of Theorem 3, phases 2–3 with blkdiag(P_Δ, P_δ)
    (eqs. (9)–(15)) and phase 3's poses — on the BFS tree unless ``spanning_tree`` says otherwise
    (``route="seed"`` also takes the odometric tree, which not every graph has)."""
    return lc.lago(graph, **{"regularization": "tree", "information": "marginal", "positions": "phase3", **options})


def quiet() -> None:
    """Keep the package's warnings (e.g. ambiguous 2kπ roundings, which lectures count) out of the output;
    compact NumPy printing."""
    logging.getLogger("lago_cvx").setLevel(logging.ERROR)
    np.set_printoptions(precision=4, suppress=True, linewidth=110)


def real(rel: str):
    """Read a real benchmark graph (``rel`` inside the datasets folder), or return None and say so when
    the datasets are absent: the lecture then runs its synthetic cells only."""
    try:
        return lc.read_graph(dataset(rel))
    except DatasetNotFound as exc:
        print(f"real datasets not found: skipping the {rel} cells ({exc})")
        return None


def figure_saver(prefix: str):
    """``save(fig, name)`` writing ``figures/<prefix>_<name>.png`` and ``.svg`` (reproducible bytes)."""
    FIG.mkdir(exist_ok=True)

    def save(fig, name: str) -> list[Path]:
        paths = []
        for ext in ("png", "svg"):
            path = FIG / f"{prefix}_{name}.{ext}"
            fig.savefig(path, dpi=120, bbox_inches="tight", metadata=_METADATA[ext])
            paths.append(path)
        print("figure written:", ", ".join(f"figures/{p.name}" for p in paths))
        return paths

    return save
