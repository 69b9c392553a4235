"""lago_cvx.section_v: the paper's Section V beyond Table I (Table II's two scenarios, Fig. 3, INTEL's χ² by edge),
as lecture 06 uses it."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx import section_v as sv
from lago_cvx.course import section_v_world

from conftest import dataset_path


@pytest.fixture(scope="module")
def world():
    return section_v_world(120, seed=3, noise="isotropic")


def test_paper_values_as_printed():
    """Fig. 3's drawn values are Table II's proportional column; Table II's LAGO row reads 0.91·10⁻² etc."""
    assert sv.PAPER_TABLE_II["LAGO"]["proportional"] == (0.91e-2, 2.25e-4)
    assert sv.PAPER_TABLE_II["TORO, 1000 iterations"]["P = I₃"] == (5.83e-4, 1.62e-4)
    assert sv.PAPER_FIG3["TORO"][100] == sv.PAPER_TABLE_II["TORO, 100 iterations"]["proportional"]
    assert sv.PAPER_FIG3["TORO"][1000] == sv.PAPER_TABLE_II["TORO, 1000 iterations"]["proportional"]
    for (lo, hi), (t, th) in zip(sv.PAPER_FIG3["ylim"], zip(*sv.PAPER_FIG3["TORO"].values())):
        assert lo == 0 and max(t, th) < hi                     # the printed values lie inside the figure's axes


def test_scenario_graph(world):
    g, _ = world
    assert sv.scenario_graph(g, "proportional") is g
    gi = sv.scenario_graph(g, "P = I₃")
    assert np.array_equal(gi.information, np.broadcast_to(np.eye(3), g.information.shape))
    assert np.array_equal(gi.delta_l, g.delta_l) and np.array_equal(gi.delta, g.delta)
    with pytest.raises(ValueError, match="scenario"):
        sv.scenario_graph(g, "identity")


def test_relation_errors_are_zero_at_the_truth_and_ignore_a_rigid_motion(world):
    g, truth = world
    assert sv.relation_errors(g, truth, truth) == (0.0, 0.0)
    est = lc.lago(g).poses
    moved = lc.compose(np.broadcast_to([3.0, -2.0, 0.7], est.shape), est)
    np.testing.assert_allclose(sv.relation_errors(g, moved, truth), sv.relation_errors(g, est, truth), rtol=1e-9)
    e_t, e_th = sv.relation_errors(g, est, truth)
    assert e_t > 0 and e_th > 0


def test_gauss_newton_path_is_the_uninterrupted_run(world):
    g, _ = world
    path = sv.gauss_newton_path(g, lc.odometry_guess(g))
    assert path.run.converged and len(path.poses) == path.run.iterations + 1
    np.testing.assert_allclose(path.chi2, [e["chi2"] for e in path.run.log[:len(path.chi2)]], rtol=1e-9)
    assert np.array_equal(path.at(10_000), path.poses[-1]) and np.array_equal(path.at(0), lc.odometry_guess(g))


def test_table_ii_world_rows_and_spread(world):
    g, truth = world
    table, curves = sv.table_ii_world(g, truth)
    assert set(table) == set(sv.SCENARIOS) == set(curves)
    for scenario, rows in table.items():
        k = len(curves[scenario]) - 1
        assert rows["odometry"] == tuple(curves[scenario][0])
        assert rows[f"Gauss–Newton, {sv.STOPS[-1]} it."] == tuple(curves[scenario][k])
        assert rows["minimum of χ² (from LAGO)"][0] < rows["odometry"][0]
    tables = {0: table, 1: table}
    s = sv.spread(tables)
    row = "LAGO, the paper's procedure"
    np.testing.assert_array_equal(s["P = I₃"][row], np.vstack([table["P = I₃"][row]] * 3))
    found = sv.findings(tables)
    paper, here = found["LAGO's ε_t, proportional P / P = I₃"]
    assert paper == pytest.approx(0.91e-2 / 3.36e-4) and here.shape == (2,)
    assert here[0] == pytest.approx(table["proportional"][row][0] / table["P = I₃"][row][0])
    assert "paper: LAGO" in sv.format_table_ii(s) and "as paper" in sv.format_findings(found)


def test_chi2_concentration_adds_up(world):
    g, _ = world
    poses = lc.lago(g, route="seed").poses
    c = sv.chi2_concentration(g, poses)
    assert c.terms.sum() == pytest.approx(lc.chi2(g, poses), rel=1e-10)
    assert np.all(np.diff(c.terms[c.order]) <= 0) and c.top(g.n_edges) == pytest.approx(1.0)
    assert c.top(1) == pytest.approx(c.terms.max() / c.terms.sum())
    np.testing.assert_allclose(c.sigma_minor ** -2, np.linalg.eigvalsh(g.information[:, :2, :2])[:, 1], rtol=1e-9)


def test_swept_grid_area_of_a_straight_segment():
    poses = np.column_stack([np.linspace(0, 10, 11), np.zeros(11), np.zeros(11)])
    grid, lo, area = sv.swept_grid(poses, resolution=0.1, radius=0.5)
    assert grid.dtype == bool and area == pytest.approx(grid.sum() * 0.01)
    assert 0.8 * 10 < area < 1.2 * (10 + np.pi * 0.5 ** 2)     # the stadium 10 m × 1 m, to the cells


def test_intel_both_scenarios_and_the_verdict():
    """INTEL in Table II's two scenarios: the paper's procedure is tens of times the minimum of the file's χ² and
    within 3 % of it with P = I₃; a few stiff edges carry most of the file's χ²; the map is centimetres away."""
    g = lc.read_graph(dataset_path("carlone/INTEL_P_toro.graph"))
    table, paths = sv.table_ii_intel(g)
    paper = "LAGO, the paper's procedure"
    assert table["proportional"][paper]["chi2_ratio"] > 50
    assert 1 < table["P = I₃"][paper]["chi2_ratio"] < 1.03
    for scenario in sv.SCENARIOS:
        assert table[scenario]["Gauss–Newton, 1000 it."]["chi2_ratio"] < 1 + 1e-6      # from odometry, both reach it
        assert table[scenario][paper]["ate"] < 0.05
    c = sv.chi2_concentration(g, lc.lago(g, route="seed").poses)
    assert c.top(13) > 0.5 and c.top(50) > 0.85 and c.sigma_minor[c.order[:13]].max() < 1e-3


def test_claim_row_on_a_world(world):
    g, _ = world
    row = sv.claim_row(g)
    assert row["ok"] and row["poses"] == g.n_poses and row["it_odo"] >= 0
    assert min(row["paper"], row["default"], row["rho_hat"], row["odo"]) >= 1 - 1e-9   # none below the minimum
    assert row["min"] == pytest.approx(lc.refine(g, lc.lago(g).poses).chi2)
    assert g.n_poses == int(sv.format_claim_rows({"w": row}).split("\n")[-1].split()[1])
