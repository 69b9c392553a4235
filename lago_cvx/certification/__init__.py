r"""Certifiable planar pose-graph optimization (beyond the seed): the SE-Sync cost, a local solver for
it, the Lagrangian-dual optimality certificate, and the semidefinite relaxation as explicit cvxpy
problems (Clarabel).

Reference: Rosen, Carlone, Bandeira, Leonard, *SE-Sync: A certifiably correct algorithm for
synchronization over the special Euclidean group*, IJRR 38(2–3), 2019, specialised to d = 2 and written
with the translations kept in the variable (sparse) instead of eliminated. Equation labels (S1)–(S10)
are this package's own:

* ``sesync.py`` — the cost (S1)–(S2) and its quadratic form tr(Y M Yᵀ) (S4)–(S5), the multipliers
  (S6)–(S7);
* ``local.py`` — ``refine_sesync``, Gauss–Newton / Newton on (S1) (S3, S3');
* ``certificate.py`` — ``certify``: S = M − Λ̂ ⪰ 0 decided by one sparse LDLᵀ inertia count, and the
  lower bound (S8) when it fails;
* ``sdp.py`` — the SDP relaxation (S9) and its dual (S10), solved by Clarabel, rounded and bracketed;
* ``estimate.py`` — ``certify_estimate``: LAGO → χ² refinement → SE-Sync refinement → certificate.
"""

from .certificate import CERTIFY_TOL, Certificate, certify
from .estimate import SESYNC_COST_CONVENTION, certificate_fields, certify_estimate
from .local import SESYNC_METHODS, SesyncRefineResult, refine_sesync
from .sdp import SdpResult, round_solution, sdp_relaxation, solve_sdp
from .sesync import (certificate_matrix, data_matrix, multipliers, optimal_translations, poses_from_stacked,
                     reduced_certificate_matrix, sesync_cost, sesync_weights, stacked_variable)

__all__ = [
    "sesync_weights", "sesync_cost", "stacked_variable", "poses_from_stacked", "data_matrix", "multipliers",
    "certificate_matrix", "reduced_certificate_matrix", "optimal_translations",
    "SESYNC_METHODS", "SesyncRefineResult", "refine_sesync",
    "CERTIFY_TOL", "Certificate", "certify",
    "SdpResult", "sdp_relaxation", "round_solution", "solve_sdp",
    "SESYNC_COST_CONVENTION", "certificate_fields", "certify_estimate",
]
