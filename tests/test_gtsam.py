"""Side by side with GTSAM's LAGO (skipped when the optional ``gtsam`` extra is not installed; CI
installs it)."""

import pytest

from lago_cvx import chi2, lago, read_graph
from lago_cvx.peers import gtsam_lago

from conftest import dataset_path
from helpers import pose_error

pytest.importorskip("gtsam", reason="optional extra: pip install 'lago-cvx[gtsam]'")


@pytest.mark.parametrize("odometric", [True, False])
def test_toy_graph_matches_gtsam(odometric):
    g = read_graph(dataset_path("gtsam/noisyToyGraph.txt"))
    ours = lago(g, route="seed", spanning_tree="odometry" if odometric else "mst")  # GTSAM runs the seed's LAGO
    theirs, _ = gtsam_lago(g, odometric_path=odometric)
    assert pose_error(ours.poses, theirs) < 1e-6


@pytest.mark.parametrize("rel", ["carlone/input_M3500_g2o.g2o", "se-sync/city10000.g2o"])
def test_same_estimate_as_gtsam_on_diagonal_information(rel):
    """With diagonal information both solve the same problem: same χ² to 1e-6 relative."""
    g = read_graph(dataset_path(rel))
    ours = lago(g, route="seed")
    theirs, _ = gtsam_lago(g, odometric_path=True)
    a, b = ours.chi2, chi2(g, theirs)
    print(f"{rel}: chi2 ours {a:.9g}, GTSAM {b:.9g}")
    assert abs(a - b) <= 1e-6 * b
    assert pose_error(ours.poses, theirs) < 1e-3
