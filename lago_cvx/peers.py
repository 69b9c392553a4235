"""Side-by-side runs of peer implementations (optional extras, imported lazily).

GTSAM (``pip install 'lago-cvx[gtsam]'``, PyPI ``gtsam`` 4.x) ships LAGO as ``gtsam.lago.initialize``.
Differences to keep in mind when comparing:

* GTSAM's between factors take a noise *model*; we give it ``Diagonal.Sigmas`` built from the
  marginal standard deviations of each edge's covariance Ω⁻¹ (x, y, θ). Cross terms are dropped —
  GTSAM's LAGO accepts only diagonal models.
* GTSAM's final linear pose solve (``computePoses`` in gtsam/slam/lago.cpp) writes the relative-position
  residual in the *global* frame but weights it with the edge's noise model, which is defined in the
  *tail's* frame; eq. (10) of the seed rotates P_Δ by R(θ̂_i) first. With isotropic translational
  noise (σx = σy: city10000, input_M3500*.g2o, the GTSAM toy graphs) the two coincide and both
  implementations give the same estimate (tests/test_gtsam.py). With anisotropic noise they differ:
  on carlone/INTEL_P_toro.graph GTSAM's estimate has χ² ≈ 1.13e6 against our 16598 (lecture 06), and
  even given exactly GTSAM's diagonal input our LAGO lands at χ² 312.7 against GTSAM's 17787.
* GTSAM needs a prior on the anchor; we add ``PriorFactorPose2(anchor, Pose2(), tiny variances)``.
* ``useOdometricPath=True`` (GTSAM's default) integrates orientations along consecutive keys and fails on
  graphs without a complete odometric chain; ``False`` uses its minimum spanning tree.

Only ``gtsam.lago.initialize`` is timed; building the GTSAM factor graph (a Python loop over edges,
outside any hot path of ours) is not.
"""

from __future__ import annotations

import time

import numpy as np

from .errors import MissingSolverError
from .posegraph import PoseGraph

__all__ = ["have_gtsam", "gtsam_factor_graph", "gtsam_lago"]

#: Variances of the prior GTSAM needs on the anchor (x, y, θ).
GTSAM_PRIOR_VARIANCES = (1e-10, 1e-10, 1e-12)


def have_gtsam() -> bool:
    try:
        import gtsam  # noqa: F401
    except Exception:
        return False
    return True


def _gtsam():
    try:
        import gtsam
    except ImportError as exc:
        raise MissingSolverError("GTSAM comparisons need the optional extra: pip install 'lago-cvx[gtsam]'") from exc
    return gtsam


def gtsam_factor_graph(graph: PoseGraph, *, anchor=None):
    """GTSAM ``NonlinearFactorGraph`` of ``graph`` with diagonal noise models (marginal sigmas) and a
    prior on the anchor (a pose id, default the smallest). Keys are pose indices."""
    gtsam = _gtsam()
    a = graph.anchor_index(anchor)
    cov = graph.covariance
    sig = np.sqrt(np.stack([cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2]], axis=1))
    fg = gtsam.NonlinearFactorGraph()
    for k in range(graph.n_edges):
        fg.add(gtsam.BetweenFactorPose2(int(graph.tails[k]), int(graph.heads[k]),
                                        gtsam.Pose2(float(graph.delta_l[k, 0]), float(graph.delta_l[k, 1]),
                                                    float(graph.delta[k])),
                                        gtsam.noiseModel.Diagonal.Sigmas(sig[k])))
    fg.add(gtsam.PriorFactorPose2(a, gtsam.Pose2(),
                                  gtsam.noiseModel.Diagonal.Variances(np.array(GTSAM_PRIOR_VARIANCES))))
    return fg


def gtsam_lago(graph: PoseGraph, *, odometric_path: bool = True, anchor=None, repeat: int = 1,
               factor_graph=None) -> tuple[np.ndarray, float]:
    """Run ``gtsam.lago.initialize`` ``repeat`` times; return (poses (n, 3), median seconds)."""
    gtsam = _gtsam()
    fg = factor_graph if factor_graph is not None else gtsam_factor_graph(graph, anchor=anchor)
    times = []
    values = None
    for _ in range(max(1, repeat)):
        t = time.perf_counter()
        values = gtsam.lago.initialize(fg, odometric_path)
        times.append(time.perf_counter() - t)
    poses = np.array([[values.atPose2(i).x(), values.atPose2(i).y(), values.atPose2(i).theta()]
                      for i in range(graph.n_poses)])
    return poses, float(np.median(times))
