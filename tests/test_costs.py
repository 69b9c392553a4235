"""The named costs (lago_cvx.conventions) on planar graphs: the frames of the information, GTSAM's Logmap error and
its Jacobian, with_cost, reading options (cost=, information="blocks", repair=) and their command-line spelling.
The peers' own code is compared in tests/test_peers_cost.py."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

import lago_cvx as lc
from conftest import dataset_path
from lago_cvx.cli import main
from lago_cvx.errors import OptionError, ParseError
from lago_cvx.posegraph import rot2, se2_v_inverse, to_measurement_frame, to_tail_frame
from lago_cvx.refinement import _Problem


def _world(information="full", seed=2):
    return lc.random_graph(40, 90, seed=seed, information=information, sigma_theta=0.1).graph


def test_v_inverse_is_the_inverse_of_se2s_left_jacobian():
    eps = np.array([-3.0, -1.0, -0.02, -0.01, -1e-3, 0.0, 1e-9, 5e-3, 0.0099, 0.0101, 0.3, 2.9])
    alpha, beta, dalpha = se2_v_inverse(eps)
    for e, a, b in zip(eps, alpha, beta):
        s, c = (np.sin(e) / e, 2 * np.sin(e / 2) ** 2 / e) if e else (1.0, 0.0)
        V = np.array([[s, -c], [c, s]])
        assert np.allclose(np.array([[a, b], [-b, a]]) @ V, np.eye(2), atol=1e-14)
    h = 1e-6  # α′ by central differences, on both sides of the series switch
    fd = (se2_v_inverse(eps + h)[0] - se2_v_inverse(eps - h)[0]) / (2 * h)
    assert np.allclose(dalpha, fd, atol=1e-8)


def test_gtsam_cost_jacobian_by_finite_differences():
    g = _world().with_cost("gtsam")
    x = lc.lago(g).poses + 0.2 * np.random.default_rng(1).standard_normal((g.n_poses, 3))
    prob = _Problem(g, 0)
    r, J = prob.linearize(x)
    free = np.flatnonzero(~prob.held.reshape(-1))
    fd = np.empty(J.shape)
    for c, f in enumerate(free):
        d = np.zeros(3 * g.n_poses)
        d[f] = 1e-6
        fd[:, c] = (prob.residuals(x + d.reshape(-1, 3)) - prob.residuals(x - d.reshape(-1, 3))).reshape(-1) / 2e-6
    assert np.abs(J.toarray() - fd).max() < 1e-6 * max(1.0, np.abs(fd).max())
    assert np.sum(r ** 2) == pytest.approx(lc.chi2(g, x), rel=1e-12)


def test_frames_are_exact_and_costs_agree_where_they_must():
    g = _world()
    assert g.cost == "paper"
    x = lc.lago(g).poses
    info = g.information
    # g2o's error blkdiag(R(δ)ᵀ, 1) e weighed by Tᵀ Ω T is eq. (3)'s e weighed by Ω, at every pose
    m = to_measurement_frame(info, g.delta)
    e = lc.edge_errors(g, x)
    e_g2o = np.column_stack([np.einsum("kba,kb->ka", rot2(g.delta), e[:, :2]), e[:, 2]])
    assert np.einsum("ka,kab,kb->", e_g2o, m, e_g2o) == pytest.approx(lc.chi2(g, x), rel=1e-12)
    assert np.allclose(to_tail_frame(m, g.delta), info, rtol=1e-13, atol=1e-13 * np.abs(info).max())
    # paper → g2o → paper reads the same matrices back, bit for bit; gtsam's cost is another function
    g2o = g.with_cost("g2o")
    assert g2o.with_cost("paper").equals(g.with_cost("g2o").with_cost("paper"))
    assert np.array_equal(g2o.given_information, info) and np.array_equal(g2o.with_cost("paper").information, info)
    gt = g2o.with_cost("gtsam")
    assert np.array_equal(gt.information, g2o.information) and not gt.equals(g2o)
    assert lc.chi2(gt, x) != lc.chi2(g2o, x)
    # at zero rotation residual, GTSAM's error is g2o's
    z = x.copy()
    z[g.heads[0], 2] = z[g.tails[0], 2] + g.delta[0]
    assert lc.edge_errors(gt, z)[0] == pytest.approx(lc.edge_errors(g2o, z)[0], rel=1e-15)
    with pytest.raises(OptionError, match="unknown cost 'ceres'"):
        g.with_cost("ceres")


def test_refine_minimises_the_cost_asked():
    g = _world()
    start = lc.lago(g).poses
    for cost in ("paper", "g2o", "gtsam"):
        ref = lc.refine(g, start, cost=cost, tolerance=1e-14)
        assert ref.cost == cost
        gc = g.with_cost(cost)
        assert ref.chi2 == pytest.approx(lc.chi2(gc, ref.poses), rel=1e-12)
        # stationary: no coordinate step lowers the cost
        for k in range(3, 3 * g.n_poses, 17):
            for h in (1e-5, -1e-5):
                x = ref.poses.copy().reshape(-1)
                x[k] += h
                assert lc.chi2(gc, x.reshape(-1, 3)) >= ref.chi2 * (1 - 1e-12)
    assert lc.lago(g, cost="gtsam").graph.cost == "gtsam"


def _file(tmp_path, info6: str, tag="EDGE_SE2", name="g.g2o"):
    vtag = "VERTEX_SE2" if tag == "EDGE_SE2" else "VERTEX2"
    lines = [f"{vtag} {k} {k}.0 0.0 0.0" for k in range(3)]
    lines += [f"{tag} 0 1 1.0 0.0 0.0 1 0 0 1 0 1", f"{tag} 1 2 1.0 0.0 0.5 {info6}",
              f"{tag} 0 2 2.0 0.0 0.5 1 0 0 1 0 1"]
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_blocks_drop_the_cross_terms_and_the_refusal_names_it(tmp_path, capsys):
    p = _file(tmp_path, "1 0 2 1 0 1")  # Ω_xθ = 2: indefinite, its blocks I₂ and 1 are positive definite
    with pytest.raises(ParseError) as ei:
        lc.read_graph(p)
    msg = str(ei.value)
    assert msg.startswith(f"{p}:5: information matrix is not positive definite") and "\n" not in msg
    assert "read_graph(path, information='blocks') (CLI: --information blocks)" in msg and "repair=True" in msg
    g = lc.read_graph(p, information="blocks")
    assert np.array_equal(g.given_information[1], np.eye(3))
    for cmd in (["solve", str(p), "--information", "blocks", "--refine", "--json"],
                ["info", str(p), "--information", "blocks", "--json"],
                ["certify", str(p), "--information", "blocks", "--json"]):
        assert main(cmd) == 0, cmd
        assert json.loads(capsys.readouterr().out)["cost"] == "g2o"
    assert main(["solve", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--information blocks" in err
    with pytest.raises(OptionError):
        lc.read_graph(p, information="diagonal")


def test_repair_takes_the_nearest_positive_definite_matrix(tmp_path, caplog):
    p = _file(tmp_path, "1 1.0000001 0 1 0 1")  # rank-one translation block, rounded below zero
    with pytest.raises(ParseError, match="repair=True"):
        lc.read_graph(p)
    with caplog.at_level(logging.WARNING, logger="lago_cvx.io"):
        g = lc.read_graph(p, repair=True)
    assert "1 information matrix(es) not positive definite replaced" in caplog.text and "line 5" in caplog.text
    fixed = g.given_information[1]
    lam = np.linalg.eigvalsh(fixed)
    assert lam.min() > 0 and lam.min() == pytest.approx(1e-8 * lam.max(), rel=1e-6)
    written = np.array([[1, 1.0000001, 0], [1.0000001, 1, 0], [0, 0, 1]])
    assert np.abs(fixed - written).max() < 1e-6  # Frobenius-nearest: only the negative eigenvalue moved
    assert np.array_equal(g.given_information[0], np.eye(3))  # the others as written
    assert lc.refine(g, lc.lago(g).poses).converged


def test_g2os_own_saved_file_reads_with_the_repair(tmp_path):
    g2o = pytest.importorskip("g2opy", reason="g2o's own bindings: pip install 'lago-cvx[peers]'")
    src = dataset_path("carlone/input_INTEL_g2o.g2o")
    opt = g2o.SparseOptimizer()
    opt.set_algorithm(g2o.OptimizationAlgorithmLevenberg(g2o.BlockSolverSE2(g2o.LinearSolverEigenSE2())))
    assert opt.load(str(src))
    opt.vertex(0).set_fixed(True)
    opt.initialize_optimization()
    opt.optimize(10)
    saved = tmp_path / "saved.g2o"
    assert opt.save(str(saved))
    with pytest.raises(ParseError, match=r"not positive definite .*repair=True\) \(CLI: --repair-information\)"):
        lc.read_graph(saved)
    g = lc.read_graph(saved, repair=True)
    assert g.n_edges == 1483
    ref = lc.refine(g, lc.lago(g).poses)
    assert ref.converged and ref.chi2 < 1.02 * lc.datasets.REFERENCE_CHI2["carlone/input_INTEL_g2o.g2o"]


def test_cli_cost_option(capsys):
    path = str(dataset_path("se-sync/MIT.g2o"))
    runs = {}
    for cost in ("g2o", "gtsam", "paper"):
        assert main(["solve", path, "--cost", cost, "--json", "--refine", "--anchor", "5"]) == 0
        runs[cost] = json.loads(capsys.readouterr().out)
        assert runs[cost]["cost"] == cost
    assert runs["g2o"]["chi2_refined"] == pytest.approx(lc.datasets.REFERENCE_CHI2["se-sync/MIT.g2o"], rel=1e-5)
    assert len({round(r["chi2_refined"], 6) for r in runs.values()}) == 3
    with pytest.raises(SystemExit) as ei:
        main(["solve", path, "--cost", "ceres"])
    assert ei.value.code == 2 and "invalid choice: 'ceres'" in capsys.readouterr().err
    assert main(["info", path, "--cost", "paper"]) == 0
    assert "cost paper" in capsys.readouterr().out


def test_write_graph_takes_any_result_of_either_dimension(tmp_path):
    import lago_cvx as lc
    from lago_cvx.space import lago3d, refine3d

    g3 = lc.read_graph(dataset_path("se-sync-3d/smallGrid3D.g2o"))
    r3 = lago3d(g3)
    f3 = refine3d(g3, r3.t, r3.R)
    back = lc.read_graph(lc.write_graph(tmp_path / "r3.g2o", g3, f3))
    assert lc.chi2_3d(back, *back.initial) == pytest.approx(f3.chi2, rel=1e-12)
    g2 = _world()
    r2 = lc.lago(g2)
    back2 = lc.read_graph(lc.write_graph(tmp_path / "r2.graph", g2, r2, format="toro"))
    assert np.allclose(back2.initial[:, :2], r2.poses[:, :2])
    with pytest.raises(OptionError, match="a 3-D graph's poses"):
        lc.write_graph(tmp_path / "x.g2o", g3, np.zeros((g3.n_poses, 3)))
    with pytest.raises(OptionError, match="a planar graph's poses"):
        lc.write_graph(tmp_path / "x.g2o", g2, (r3.t[:g2.n_poses], r3.R[:g2.n_poses]))
