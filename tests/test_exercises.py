"""Every exercise's check accepts the lecture's own solution and rejects wrong answers with a message that names
what is wrong (``lago_cvx.exercises``).

The solutions are the lectures' "Solution and Discussion" cells (tagged ``solution``): each is executed alone,
in a fresh namespace, and must define the function its check takes; the check is then called on it here as
well. The wrong answers below are the mistakes a student makes (a factor forgotten, a wrap, a sign, a
block left out); each must be rejected and the message must name the culprit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx import exercises
from lago_cvx.exercises import Feedback, WrongAnswer

LECTURES = Path(__file__).resolve().parents[1] / "lectures"
SOURCES = sorted(LECTURES.glob("[0-9][0-9]*_*.py"))


def _solution_cells():
    jupytext = pytest.importorskip("jupytext")
    cells = []
    for src in SOURCES:
        for cell in jupytext.read(src).cells:
            if cell.cell_type == "code" and "solution" in cell.metadata.get("tags", []):
                cells.append((src.stem, cell.source))
    return cells


def _check_called(source: str):
    """The check a solution cell calls (``check_<name>(<function>)``): (check, function name)."""
    import ast

    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id.startswith("check_"):
            return getattr(exercises, node.func.id), node.args[0].id
    raise AssertionError("the solution cell calls no check_…")


SOLUTIONS = _solution_cells() if SOURCES else []


def test_every_check_has_a_solution_in_a_lecture():
    called = {_check_called(source)[0].__name__ for _, source in SOLUTIONS}
    every = {name for name in exercises.__all__ if name.startswith("check_")}
    assert called == every, f"checks without a solution cell: {sorted(every - called)}; unknown: {sorted(called - every)}"


@pytest.mark.parametrize("stem, source", SOLUTIONS, ids=[f"{s}-{_check_called(c)[1]}" for s, c in SOLUTIONS])
def test_the_solution_is_accepted(stem, source, monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace: dict = {"__name__": f"solution_{stem}"}
    exec(compile(source, f"<{stem} solution>", "exec"), namespace)      # its last line: check(...).require()
    check, name = _check_called(source)
    verdict = check(namespace[name])
    assert isinstance(verdict, Feedback) and verdict.ok, str(verdict)
    assert str(verdict).startswith("✓ ") and verdict.require() is verdict


# ----------------------------------------------------------------------------- wrong answers
def _refined_twice(graph, n_starts, rng):
    best = lc.refine(graph, lc.lago(graph).poses).poses
    return [best, best.copy()]


def _naive_theta_columns(graph):
    m, n = graph.n_edges, graph.n_poses - 1
    return np.arange(2 * m + n) < 2 * m


def _eq6_that_wraps(graph, poses):
    return lc.chi2(graph, poses)


def _phase3_without_prior(result, graph):
    info = result.phase3.info.toarray().copy()
    n = graph.n_poses - 1
    info[2 * n:, 2 * n:] -= result.phase1.info.toarray()
    return info


def _forces_unweighted(result, graph):
    from lago_cvx.exercises.basics import _spring_forces

    return _spring_forces(result, graph) * 2.0


def _scale_everything(graph, pick, factor, mode):
    from dataclasses import replace

    info = np.array(graph.information)
    info[:, :2, :2] *= factor
    return replace(graph, information=info)


def _regularize_wrong_sign(graph, tree_edges):
    k = -lc.regularize(graph, _tree_from_edges(graph, tree_edges)).k       # the rounding's sign flipped
    return k, graph.delta + 2 * np.pi * k


def _tree_from_edges(graph, tree_edges):
    for kind in ("odometry", "bfs"):
        tree = lc.spanning_tree(graph, kind)
        if np.array_equal(np.sort(tree.tree_edges), np.sort(tree_edges)):
            return tree
    raise AssertionError("unknown tree")


def _regularize_per_chord(graph, tree_edges):
    tree = _tree_from_edges(graph, tree_edges)
    pkg = lc.regularize(graph, tree)
    return pkg.k[tree.chords], pkg.delta_reg


def _polish_without_fallback(F, theta_hat, theta_star):
    f_hat, alpha = F(theta_hat), 1.0
    while F(theta_hat + alpha * (theta_star - theta_hat)) >= f_hat and alpha > 1e-3:
        alpha /= 2                                     # halves on and on instead of at most three times
    return alpha, F(theta_hat + alpha * (theta_star - theta_hat))


def _absolute_errors(graph, poses, truth):
    d = poses - truth
    return float(np.mean(np.sum(d[:, :2] ** 2, 1))), float(np.mean(d[:, 2] ** 2))


def _loop_closures_as_corrections(graph, kind):
    return graph.n_poses, graph.n_odometric, graph.n_loop_closures, graph.n_loop_closures


def _bound_without_eigenvalue(graph, poses):
    from lago_cvx.certification import certify

    return certify(graph, poses, full=False).dual_value


def _unnormalized_laplacian(graph, omega, anchor_index):
    ns: dict = {}
    source = next(s for _, s in SOLUTIONS if "def chordal_from_laplacian" in s)
    exec(source.split("check_connection_laplacian(chordal_from_laplacian)")[0], ns)
    return ns["chordal_from_laplacian"](graph, omega, anchor_index) * 2.0


WRONG = {
    "check_half_offset": [(lambda m: (3 * m / 2) / np.sqrt(3 * m), "half_offset(1)")],
    "check_cost_eq6": [(_eq6_that_wraps, "wraps the angular residual")],
    "check_minima": [(_refined_twice, "same cost"), (lambda g, n, rng: [lc.lago(g).poses], "not a local minimum")],
    "check_chain_covariance": [(lambda s: np.diag(np.cumsum(np.asarray(s) ** 2)), "P_θ of the 12-edge chain")],
    "check_compass": [(lambda g, d, w, K, c, s: np.zeros(g.n_poses), "gradient")],
    "check_trace_drop": [(lambda P0, e, var: float((P0 @ e) @ (P0 @ e) / (e @ P0 @ e)), "drop of tr P_θ")],
    "check_theta_columns": [(_naive_theta_columns, "misclassified")],
    "check_pz_times": [(lambda res, g, v: v, "differs from v")],
    "check_phase3_information": [(_phase3_without_prior, "orientation block")],
    "check_spring_forces": [(_forces_unweighted, "spring forces")],
    "check_guarded_polish": [(lambda F, th, ts: (1.0, F(ts)), "keeps α = 0.5"),
                             (_polish_without_fallback, "keeps α = 0.0")],
    "check_scale_information": [(_scale_everything, "information")],
    "check_fundamental_coordinates": [(lambda C, chords: C[:, chords].T, "not the coordinates")],
    "check_regularize": [(_regularize_wrong_sign, "outside [−π, π]")],
    "check_relation_errors": [(_absolute_errors, "(ε_t, ε_θ)")],
    "check_table_one": [(_loop_closures_as_corrections, "chords with k ≠ 0")],
    "check_anchor_torques": [(lambda g, a: np.ones(len(a)), "multipliers")],
    "check_strain": [(lambda g, a, i: 4 * lc.lago(g, anchors=a).strain[0].chi2_theta + 1.0, "strain statistic")],
    "check_truncation": [(lambda p: __import__("scipy.stats").stats.chi2.ppf(p, 1), "c̄² at confidence 0.9")],
    "check_wrong_integers": [(lambda g, t: np.full(t.n_chords, 0.01), "p along the odometry tree")],
    "check_connection_laplacian": [(_unnormalized_laplacian, "z with anchor 0")],
    "check_bound_b": [(_bound_without_eigenvalue, "above the minimum")],
    "check_chordal_weight": [(lambda Omega: Omega, "tr(W) I − W")],
    "check_tree_rotations": [(lambda g: np.broadcast_to(np.eye(3), (g.n_poses, 3, 3)).copy(), "R_j against R_i R̃_ij")],
}

from exercises_robust_wrong import WRONG_ROBUST  # noqa: E402  (lectures 10–11)

WRONG.update(WRONG_ROBUST)


def test_every_check_has_wrong_answers():
    assert set(WRONG) == {name for name in exercises.__all__ if name.startswith("check_")}


@pytest.mark.parametrize("name, wrong, named", [(n, w, m) for n, ws in WRONG.items() for w, m in ws],
                         ids=[f"{n}-{k}" for n, ws in WRONG.items() for k in range(len(ws))])
def test_a_wrong_answer_is_rejected_with_a_message(name, wrong, named):
    verdict = getattr(exercises, name)(wrong)
    assert isinstance(verdict, Feedback) and not verdict.ok, f"{name} accepted a wrong answer: {verdict}"
    assert str(verdict).startswith("✗ ") and named in verdict.message, f"{name}: the message {verdict.message!r} " \
                                                                       f"does not name {named!r}"
    with pytest.raises(WrongAnswer, match="✗"):
        verdict.require()


def test_05_exercise_2_accepts_a_per_chord_answer():
    """k given per chord (the chords in increasing edge order) is as right as k per edge."""
    verdict = exercises.check_regularize(_regularize_per_chord)
    assert verdict.ok, str(verdict)


@pytest.mark.parametrize("answer, named", [
    (lambda m: (_ for _ in ()).throw(NotImplementedError()), "not written yet"),
    (lambda m: 1 / 0, "ZeroDivisionError"),
    (lambda m: None, "is None"),
    (0.5, "pass the function half_offset itself"),
])
def test_a_broken_answer_becomes_a_message_not_a_traceback(answer, named):
    verdict = exercises.check_half_offset(answer)
    assert not verdict.ok and named in verdict.message, verdict.message


def test_checks_print_nothing(capsys):
    exercises.check_half_offset(lambda m: 0.0)
    exercises.check_chordal_weight(lambda Omega: 0.5 * np.trace(Omega) * np.eye(3) - Omega)
    assert capsys.readouterr() == ("", "")


def test_course_check_logs_and_shows_after_setup(capsys, caplog):
    """course.check prints nothing itself: it logs; the lecture's setup() shows the claims in the output."""
    import logging

    from lago_cvx import course

    handlers = list(course.CLAIMS.handlers)
    try:
        for h in handlers:
            course.CLAIMS.removeHandler(h)
        course.CLAIMS.propagate = True
        with caplog.at_level(logging.INFO, logger="lago_cvx.course"):
            course.check(True, "a claim")
        assert capsys.readouterr().out == "" and "✓ a claim" in caplog.text
        course.setup("test")
        course.check(True, "another claim")
        assert capsys.readouterr().out == "✓ another claim\n"
        with pytest.raises(AssertionError, match="✗ false"):
            course.check(False, "false")
    finally:
        for h in list(course.CLAIMS.handlers):
            course.CLAIMS.removeHandler(h)
        for h in handlers:
            course.CLAIMS.addHandler(h)
