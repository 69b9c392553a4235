"""lago_cvx — LAGO (Carlone, Aragues, Castellanos, Bona, RSS 2011), every step an explicit convex problem.

Public API::

    graph = read_graph("file.g2o")          # g2o or TORO, auto-detected
    result = lago(graph)                    # closed form; method="cvxpy" for the cvxpy problems
    result.poses, result.chi2               # (n, 3) estimate and its χ² (the file's own cost)
    write_graph("out.g2o", graph, result.poses)

    lago(graph, regularization="chordal")   # 2kπ integers from the chordal relaxation (robust to rotation noise)
    lago(graph, regularization="integer")   # ... from the weighted integer program the rounding approximates
    cert = certify(graph, refine_sesync(graph, refine(graph, result.poses).poses).poses)
    cert.certified, cert.cost              # SE-Sync optimality certificate (Lagrangian dual, sparse LDLᵀ)

    graph = read_graph("sphere2500.g2o")    # VERTEX_SE3:QUAT / EDGE_SE3:QUAT: a PoseGraph3D (graph.dim == 3)
    result = lago(graph)                    # = lago3d(graph): chordal relaxation, positions, joint step
    refine(graph, result)                   # Gauss–Newton on SE(3): the same refine, keywords and defaults

The names below are loaded on first use (PEP 562), so ``import lago_cvx`` is cheap, and cvxpy is
imported only by the routes that build a cvxpy problem. The layers of the package and where each step
of the paper lives: ``docs/ARCHITECTURE.md``.
"""

from __future__ import annotations

import importlib

from ._version import __version__

#: public name → the module that defines it
_EXPORTS = {
    "errors": ["LagoError", "ParseError", "OutputError", "GraphError", "NumericalError", "OptionError", "SolverError",
               "InfeasibleConstraintsError", "MissingSolverError", "ResourceLimitError", "SearchLimitError",
               "DatasetNotFound"],
    "solvers": ["ClarabelSettings", "IntegerSearch"],
    "posegraph": ["PoseGraph", "compose", "between", "wrap_angle"],
    "io": ["read_graph", "write_graph"],
    "graph": ["incidence_matrix", "reduced_incidence", "connected_components", "cyclomatic_number",
              "spanning_tree", "cycle_basis"],
    "metrics": ["chi2", "chi2_parts", "edge_errors", "whitened_errors", "ate", "rpe", "rotation_error"],
    "regularization": ["regularize"],
    "regularization.chordal": ["chordal_closed_form", "chordal_problem"],
    "result": ["LagoResult"],
    "pipeline": ["lago", "compare_methods"],
    "refinement": ["refine", "odometry_guess"],
    "variants": ["anchored_lago", "constrained_lago", "RobustSettings"],
    "certification": ["certify", "refine_sesync", "sesync_cost", "solve_sdp", "certify_estimate"],
    "synthetic": ["manhattan_world", "circle_world", "random_graph", "add_false_loop_closures"],
    "posegraph3d": ["PoseGraph3D", "chi2_3d"],
    "space": ["lago3d", "refine3d", "pose_covariances3d", "Lago3DResult", "Refine3DResult", "gravity_aligned"],
    "space.certify": ["certify3d"],
    "synthetic.space": ["sphere_world", "torus_world", "cube_grid_world"],
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = ["__version__", *_WHERE]


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        try:  # a submodule asked for as an attribute (``lago_cvx.phases``)
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":  # the submodule exists but a package it needs is missing
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))

