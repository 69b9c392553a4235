"""The cost a planar file means, checked against its owners' code: the χ² ``lago-cvx solve F [--refine] --json -o
est.g2o`` reports equals g2o's χ² of est.g2o (g2opy, first vertex fixed) and, with ``--cost gtsam``, GTSAM's
2·error() (``gtsam.readG2o``); neither peer's Levenberg–Marquardt lowers our refined χ². Skipped, with the reason,
when a peer (``pip install "lago-cvx[peers]"``) or a dataset is absent. The 3-D files: tests/test_peers_cost3d.py."""

from __future__ import annotations

import json

import pytest

from conftest import dataset_path
from lago_cvx import peers
from lago_cvx.cli import main

FILES = ["se-sync/MIT.g2o", "se-sync/CSAIL.g2o", "carlone/input_INTEL_g2o.g2o", "se-sync/manhattan.g2o",
         "se-sync/intel.g2o"]
REL = 1e-6  # the tolerance; measured agreement is 1e-12 or better (benchmarks/costs.md)


def _solve(capsys, tmp_path, rel, *extra):
    est = tmp_path / "est.g2o"
    assert main(["solve", str(dataset_path(rel)), "--json", "-o", str(est), *extra]) == 0
    return json.loads(capsys.readouterr().out), est


@pytest.mark.parametrize("rel", FILES)
def test_our_chi2_is_g2os(capsys, tmp_path, rel):
    if not peers.have_g2o():
        pytest.skip("g2opy (g2o's own bindings) not installed: pip install 'lago-cvx[peers]'")
    lago, est = _solve(capsys, tmp_path, rel)
    assert lago["cost"] == "g2o"
    assert peers.g2o_chi2(est)["chi2_at"] == pytest.approx(lago["chi2"], rel=REL)
    refined, est = _solve(capsys, tmp_path, rel, "--refine")
    g2o = peers.g2o_chi2(est, iterations=100)
    assert g2o["chi2_at"] == pytest.approx(refined["chi2_refined"], rel=REL)
    assert g2o["chi2_lm"] >= refined["chi2_refined"] * (1 - REL)  # g2o's own LM cannot go lower


@pytest.mark.parametrize("rel", FILES)
def test_our_gtsam_chi2_is_gtsams(capsys, tmp_path, rel):
    if not peers.have_gtsam():
        pytest.skip("gtsam not installed: pip install 'lago-cvx[peers]'")
    refined, est = _solve(capsys, tmp_path, rel, "--cost", "gtsam", "--refine")
    assert refined["cost"] == "gtsam"
    gt = peers.gtsam_chi2(est, iterations=100)
    assert gt["chi2_at"] == pytest.approx(refined["chi2_refined"], rel=REL)
    assert gt["chi2_lm"] >= refined["chi2_refined"] * (1 - REL)


@pytest.mark.parametrize("g2o_rel, toro_rel", [("se-sync/CSAIL.g2o", "carlone/CSAIL_P_toro.graph"),
                                               ("se-sync/manhattan.g2o", "carlone/M3500_P_toro.graph")])
def test_twins_give_one_chi2_and_one_estimate(capsys, tmp_path, g2o_rel, toro_rel):
    """A g2o file in g2o's cost and its TORO twin in eq. (3)'s: the same χ² and estimate (to the g2o file's 6
    printed digits); g2o's χ² of what we write from the TORO twin is ours."""
    import numpy as np

    from lago_cvx.io import read_graph

    a, ea = _solve(capsys, tmp_path, g2o_rel, "--refine")
    b, eb = _solve(capsys, tmp_path, toro_rel, "--refine")
    assert b["cost"] == "paper"
    assert a["chi2"] == pytest.approx(b["chi2"], rel=1e-4)
    assert a["chi2_refined"] == pytest.approx(b["chi2_refined"], rel=1e-4)
    pa, pb = read_graph(ea).initial, read_graph(eb).initial
    assert np.abs(pa[:, :2] - pb[:, :2]).max() < 1e-3
    if peers.have_g2o():
        assert peers.g2o_chi2(eb)["chi2_at"] == pytest.approx(b["chi2_refined"], rel=REL)
