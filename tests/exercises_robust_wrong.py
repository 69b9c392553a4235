"""Wrong answers for the checks of lectures 10–11 (``lago_cvx.exercises.robust``), merged into
``tests/test_exercises.py``'s ``WRONG``: the mistakes a student makes, each with the words its message must hold."""

from __future__ import annotations

import numpy as np

import lago_cvx as lc


def _tls_without_sqrt(r2, mu, c2):
    r2 = np.asarray(r2, float)
    with np.errstate(divide="ignore"):
        w = c2 / r2 * mu * (mu + 1) - mu
    return np.clip(np.where(r2 <= mu / (mu + 1) * c2, 1.0, np.where(r2 >= (mu + 1) / mu * c2, 0.0, w)), 0, 1)


def _every_chord(graph, tree_edges, f):
    return lc.spanning_tree(graph, np.asarray(tree_edges)).chords


def _no_turn(info_f, delta):
    return np.asarray(info_f).copy()


def _no_v_inverse(rel):
    return np.asarray(rel, float).copy()


WRONG_ROBUST = {
    "check_tls_weights": [(_tls_without_sqrt, "transition band")],
    "check_circuits_through": [(_every_chord, "does not contain edge")],
    "check_tail_information": [(_no_turn, "eᵀ Ω e against g2o's")],
    "check_se2_logmap": [(_no_v_inverse, "Exp(ξ)'s translation")],
}
