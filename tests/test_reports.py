"""Issue 30 — a short summary of a result: ``repr`` of every result is a few lines under 2 000 characters
whatever the graph's size (poses, χ², route, timings), and ``summary()`` is a dict of the numbers that
prints as a small table (``lago_cvx.reports``)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx.certification import certify, refine_sesync
from lago_cvx.refinement import refine
from lago_cvx.reports import REPR_LIMIT, WIDTH, Summary, refine_repr, refine_summary, short_repr
from lago_cvx.synthetic import manhattan_world


@pytest.fixture(scope="module")
def big():
    w = manhattan_world(5000, seed=2)
    return w, lc.lago(w.graph)


def _short(text: str, max_lines: int = 10) -> None:
    assert len(text) < REPR_LIMIT, len(text)
    lines = text.splitlines()
    assert 2 <= len(lines) <= max_lines and all(len(line) <= WIDTH + 2 for line in lines), text


def test_lago_result_repr_is_a_few_lines(big):
    w, res = big
    text = repr(res)
    _short(text)
    assert text.startswith("<LagoResult 5000 poses") and f"χ² = {res.chi2:.6g}" in text
    assert f"route {res.route}" in text and "time " in text and "phase3" in text
    assert str(res) == text  # print(result) too


def test_lago_result_summary_is_a_dict_and_a_table(big):
    w, res = big
    s = res.summary()
    assert isinstance(s, dict) and isinstance(s, Summary)
    assert s["n_poses"] == 5000 and s["chi2"] == pytest.approx(res.chi2) and s["route"] == res.route
    assert s["n_regularized"] == res.regularization.n_regularized and s["timings"] == res.timings
    table = str(s)
    lines = table.splitlines()
    assert len(table) < REPR_LIMIT and max(map(len, lines)) <= WIDTH
    assert any(line.startswith("poses:") and line.split()[1] == "5000" for line in lines)
    assert f"{res.chi2:.7g}" in table and "time: " in table
    back = pickle.loads(pickle.dumps(s))
    assert back == s and str(back) == table


def test_variant_result_repr_bounded_with_many_strained_anchors():
    w = manhattan_world(400, seed=5)
    t = w.truth.copy()
    ids = w.graph.ids
    rng = np.random.default_rng(0)
    anchors = {int(ids[k]): tuple(t[k] + [rng.normal(0, 5), rng.normal(0, 5), 0.0]) for k in range(0, 400, 8)}
    res = lc.lago(w.graph, anchors=anchors)
    text = repr(res)
    _short(text)
    assert text.startswith("<VariantResult") and f"{len(anchors)} anchors" in " ".join(text.split())
    flat = " ".join(text.split())
    assert len(res.strained) > 5 and f"({len(res.strained)} in all)" in flat  # the list is cut, its length said
    s = res.summary()  # the keys of a plain result's (a VariantResult is a LagoResult); anchors are in repr
    assert s["n_poses"] == 400 and max(map(len, str(s).splitlines())) <= WIDTH


def test_certificate_and_refinement_reprs(big):
    w, res = big
    g = w.graph
    ref = refine(g, res.poses, max_iterations=5)
    ses = refine_sesync(g, ref.poses, max_iterations=5)
    cert = certify(g, ses.poses, n_eigenvalues=1, full=False)
    for text in (refine_repr(ref), repr(ses), repr(cert)):
        _short(text)
    assert f"{ref.chi2:.10g}" in refine_repr(ref) and f"{ses.cost:.10g}" in repr(ses)
    assert ("CERTIFIED" if cert.certified else "NOT certified") in repr(cert)
    for s in (refine_summary(ref), ses.summary(), cert.summary()):
        assert len(str(s)) < REPR_LIMIT and max(map(len, str(s).splitlines())) <= WIDTH
    assert cert.summary()["f"] == cert.cost and refine_summary(ref)["chi2"] == ref.chi2


def test_short_repr_caps_the_length():
    text = short_repr("X", "head", ["word " * 1000])
    assert len(text) == REPR_LIMIT and text.endswith("…>")


def test_robust_and_3d_result_reprs_are_a_few_lines_and_results_hash_with_joblib():
    """Robust results (planar, anchored, 3-D) and 3-D results print as a few lines, the robust ones with what GNC
    rejected; every result goes through joblib's hasher (``joblib.Memory`` keys), factors included."""
    from lago_cvx import sphere_world
    from lago_cvx.synthetic import add_false_loop_closures
    from lago_cvx.variants import RobustSettings

    go, _ = add_false_loop_closures(manhattan_world(300, seed=1).graph, 0.1, seed=1)
    g3, _ = add_false_loop_closures(sphere_world(8, 10, seed=0).graph, 0.1, seed=0)
    quick = RobustSettings(local_search=0, readmit=0.0)
    results = {"RobustResult": lc.lago(go, robust=quick),
               "RobustVariantResult": lc.lago(go, robust=quick, anchors={3: (1.0, 2.0, 0.3)}),
               "Robust3DResult": lc.lago(g3, robust=True), "Lago3DResult": lc.lago(g3)}
    for kind, res in results.items():
        text = repr(res)
        _short(text)
        assert text.startswith(f"<{kind} ") and f"χ² = {res.chi2:.6g}" in text
        assert ("robust GNC-TLS" in text) == kind.startswith("Robust")
        if kind.startswith("Robust"):
            assert f"{res.rejected_edges.size} of {res.input_graph.n_edges} edges rejected" in " ".join(text.split())
    joblib = pytest.importorskip("joblib")
    plain = lc.lago(go)
    plain.pose_covariances()  # a factor inside: pickled as None
    for res in [plain, *results.values()]:
        back = pickle.loads(pickle.dumps(res))
        assert len(joblib.hash(res)) == 32 and joblib.hash(back) == joblib.hash(pickle.loads(pickle.dumps(back)))
