"""Side-by-side runs of peer implementations (optional extras, imported lazily).

GTSAM (``pip install 'lago-cvx[gtsam]'``, PyPI ``gtsam`` 4.x) ships LAGO as ``gtsam.lago.initialize``.
Differences to keep in mind when comparing:

* GTSAM's between factors take a noise *model*, written for its error Log(Z⁻¹X_i⁻¹X_j), whose translation is
  in the *measurement's* frame (``lago_cvx.conventions``: the frame of g2o's information); we give it
  ``Diagonal.Sigmas`` built from the marginal standard deviations of each edge's covariance in that frame
  (the inverse of ``PoseGraph.information_in("measurement")``; x, y, θ). Cross terms are dropped — GTSAM's LAGO accepts only
  diagonal models.
* GTSAM's final linear pose solve (``computePoses`` in gtsam/slam/lago.cpp) writes the relative-position
  residual in the *global* frame but weights it with the edge's noise model unrotated; eq. (10) of the seed
  rotates P_Δ into the global frame first. With isotropic translational noise (σx = σy: city10000,
  input_M3500*.g2o, the GTSAM toy graphs) the two coincide and both implementations give the same estimate
  (tests/test_gtsam.py); with anisotropic noise they differ (benchmarks/datasets.md measures by how much:
  χ² of GTSAM's estimate on INTEL_P 1.30e6, on CSAIL 22 006, against 215.43 and 40.565 for LAGO's).
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
from .stacks import spd_inverse

__all__ = ["have_gtsam", "gtsam_factor_graph", "gtsam_lago", "have_g2o", "g2o_chi2", "gtsam_chi2"]

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
    """GTSAM ``NonlinearFactorGraph`` of ``graph`` with diagonal noise models (marginal sigmas in the
    measurement's frame, module docstring) and a prior on the anchor (a pose id, default the smallest). Keys are pose indices."""
    gtsam = _gtsam()
    a = graph.anchor_index(anchor)
    cov = spd_inverse(graph.information_in("measurement"))
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


# ------------------------------------------------------------------------------ the cost a file means, by its owners
def _is_3d(path) -> bool:
    """Whether the file's first record is a 3-D one, decided as ``lago_cvx.io.read_graph`` decides it."""
    from .io.careful import read_bytes
    from .io.space import first_tag, is_3d_tag

    return is_3d_tag(first_tag(read_bytes(path)) or "")


def have_g2o() -> bool:
    """True when g2o's own Python bindings (``pip install g2opy``, extra ``peers``) import."""
    try:
        import g2opy  # noqa: F401
    except Exception:
        return False
    return True


def g2o_chi2(path, *, iterations: int = 0) -> dict:
    """g2o's verdict on a g2o file, planar or 3-D, computed by g2o itself (g2opy): the file loaded, its first
    vertex fixed, ``chi2_at`` = g2o's χ² at the vertices as written and ``chi2_lm`` = its χ² after ``iterations``
    of g2o's Levenberg–Marquardt from there (``chi2_at`` when 0)."""
    try:
        import g2opy as g
    except ImportError as exc:
        raise MissingSolverError("g2o comparisons need the optional extra: pip install 'lago-cvx[peers]'") from exc
    threed = _is_3d(path)
    opt = g.SparseOptimizer()
    block = (g.BlockSolverSE3(g.LinearSolverEigenSE3()) if threed
             else g.BlockSolverSE2(g.LinearSolverEigenSE2()))
    opt.set_algorithm(g.OptimizationAlgorithmLevenberg(block))
    if not opt.load(str(path)):
        raise MissingSolverError(f"g2o could not load {path}")
    opt.vertex(min(opt.vertices().keys())).set_fixed(True)
    opt.initialize_optimization()
    opt.compute_active_errors()
    at = float(opt.chi2())
    if iterations > 0:
        opt.optimize(int(iterations))
        opt.compute_active_errors()
    return {"chi2_at": at, "chi2_lm": float(opt.chi2()) if iterations > 0 else at}


def gtsam_chi2(path, *, iterations: int = 0) -> dict:
    """GTSAM's verdict on a g2o file, planar or 3-D: ``gtsam.readG2o`` (its information, its Logmap error), the
    first pose fixed, ``chi2_at`` = 2·``error()`` at the vertices as written and ``chi2_lm`` = 2·``error()`` after
    ``iterations`` of GTSAM's Levenberg–Marquardt from there (``chi2_at`` when 0)."""
    gtsam = _gtsam()
    threed = _is_3d(path)
    fg, values = gtsam.readG2o(str(path), threed)
    first = min(values.keys())
    at = 2.0 * fg.error(values)
    if iterations <= 0:
        return {"chi2_at": at, "chi2_lm": at}
    pose = values.atPose3(first) if threed else values.atPose2(first)
    fg.add(gtsam.NonlinearEqualityPose3(first, pose) if threed else gtsam.NonlinearEqualityPose2(first, pose))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(iterations))
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    out = gtsam.LevenbergMarquardtOptimizer(fg, values, params).optimize()
    return {"chi2_at": at, "chi2_lm": 2.0 * fg.error(out)}
