"""LAGO's idea in space: 3-D pose graphs (:class:`~lago_cvx.posegraph3d.PoseGraph3D`).

* ``chordal`` — the rotations by the chordal relaxation (Carlone et al., ICRA 2015), as a cvxpy problem and as one
  sparse factorization with three right-hand sides, projected onto SO(3); SE-Sync's isotropic weights or the whole
  rotational information;
* ``positions`` — the positions at fixed rotations, exactly in the graph's cost (the full 6×6 information), cvxpy and
  closed form;
* ``gauss_newton`` — the Jacobians of both 3-D errors (g2o's and GTSAM's, ``posegraph3d``), Gauss–Newton /
  Levenberg–Marquardt with a right retraction (``refine3d(..., cost=)``);
* ``pipeline`` — ``lago3d``: the seed route (chordal → positions) and the default route (then one joint
  linearized step, positions re-solved, guarded), and the result type;
* ``certify`` — SE-Sync's optimality certificate in 3-D (SE-Sync's cost, weights from the information as written);
* ``covariance`` — the poses' first-order covariances from the factor of JᵀΩJ (selected inversion);
* ``fixed`` — the routes with several poses known exactly (``lago3d(graph, fixed={id: (t, R)})``);
* ``constraints`` — linear constraints on rotations, R_i a = b (gravity-aligned poses), and the projection that
  keeps them;
* ``refine`` — Gauss–Newton / Levenberg–Marquardt with anchors, priors and rotation constraints (what
  ``lago_cvx.refine`` runs on a 3-D graph; ``refine3d`` its old name), and the covariances of the refined problem.
"""

from .chordal import WEIGHTINGS, chordal_closed_form, chordal_cvxpy, chordal_problem
from .covariance import pose_covariances3d
from .pipeline import ROUTES3D, Lago3DResult, compare_methods3d, lago3d
from .positions import position_problem, positions_closed_form, positions_cvxpy
from .refine import REFINE_METHODS, Refine3DResult, Refined3D, refine3d
from .constraints import gravity_aligned

__all__ = ["WEIGHTINGS", "chordal_closed_form", "chordal_cvxpy", "chordal_problem", "REFINE_METHODS", "Refined3D",
           "refine3d", "ROUTES3D", "Lago3DResult", "compare_methods3d", "lago3d", "position_problem",
           "positions_closed_form", "positions_cvxpy", "pose_covariances3d", "Refine3DResult", "gravity_aligned"]
