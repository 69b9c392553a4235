"""lago_cvx — LAGO (Carlone, Aragues, Castellanos, Bona, RSS 2011), every step an explicit convex problem.

Public API::

    graph = read_graph("file.g2o")          # g2o or TORO, auto-detected
    result = lago(graph)                    # closed form; method="cvxpy" for the cvxpy problems
    result.poses, result.chi2               # (n, 3) estimate and its χ² (g2o convention)
    write_graph("out.g2o", graph, result.poses)

    lago(graph, regularization="chordal")   # 2kπ integers from the chordal relaxation (robust to rotation noise)
    lago(graph, regularization="integer")   # ... from the weighted integer program the rounding approximates
    from lago_cvx.certify import certify
    cert = certify(graph, refine_sesync(graph, refine(graph, result.poses).poses).poses)
    cert.certified, cert.cost              # SE-Sync optimality certificate (Lagrangian dual, sparse LDLᵀ)
"""

from .certify import refine_sesync, sesync_cost, solve_sdp  # certify(): lago_cvx.certify.certify (module name)
from .chordal import chordal_closed_form, chordal_problem
from .cost import chi2, chi2_parts, edge_errors, whitened_errors
from .io import ParseError, read_graph, write_graph
from .graph import (connected_components, cycle_basis, cyclomatic_number, incidence_matrix,
                    reduced_incidence, spanning_tree)
from .lago import LagoResult, compare_methods, lago
from .posegraph import GraphError, PoseGraph, between, compose, wrap_angle
from .refine import odometry_guess, refine
from .regularization import regularize
from .synthetic import circle_world, manhattan_world, random_graph

__version__ = "0.1.0"

__all__ = [
    "PoseGraph", "GraphError", "compose", "between", "wrap_angle",
    "read_graph", "write_graph", "ParseError",
    "incidence_matrix", "reduced_incidence", "connected_components", "cyclomatic_number",
    "spanning_tree", "cycle_basis", "regularize",
    "lago", "compare_methods", "LagoResult",
    "chi2", "chi2_parts", "edge_errors", "whitened_errors", "refine", "odometry_guess",
    "manhattan_world", "circle_world", "random_graph",
    "chordal_closed_form", "chordal_problem",
    "sesync_cost", "refine_sesync", "solve_sdp",
]

