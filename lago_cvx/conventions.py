"""Conventions written once, for the reports of the library and the command line (no heavy imports:
``lago-cvx --help`` reads them).

The cost a file means
=====================
Every χ² lago_cvx reports is Σ_k e_kᵀ Ω_k e_k (no ½) for one of three named errors of an edge i → j with
measurement Z = (t̃, R̃) and information Ω as the file gives it (:data:`COSTS`):

* ``"g2o"`` — what g2o computes: e = t2v(Z⁻¹ · X_i⁻¹ X_j). Planar (``EDGE_SE2``):
  e = [R(δ)ᵀ(R_iᵀ(p_j − p_i) − Δˡ) ; wrap(θ_j − θ_i − δ)], the translational residual in the *measurement's*
  frame. 3-D (``EDGE_SE3:QUAT``): e = [translation of E ; x, y, z of E's unit quaternion, w ≥ 0],
  E = Z⁻¹X_i⁻¹X_j. The default for g2o files.
* ``"gtsam"`` — 2·``error()`` of GTSAM's ``BetweenFactor`` with the information read as ``gtsam.readG2o``
  reads it: e = Log(Z⁻¹X_i⁻¹X_j), GTSAM's local coordinates (SE(2) Logmap in the plane, SE(3) Logmap in 3-D).
* ``"paper"`` — the seed's eq. (3), e = [R_iᵀ(p_j − p_i) − Δˡ ; wrap(θ_j − θ_i − δ)], the translational
  residual in the frame of the tail i: what a TORO file's information is written for (the default for TORO
  files). Planar only.

* ``CHI2_CONVENTION`` — how χ² is summed (no ½; twice GTSAM's ``error()``).
* ``SESYNC_COST_CONVENTION`` — the cost the optimality certificate is about (``lago_cvx.certification``).
* ``CERTIFY_TOL`` — the largest proven relative suboptimality (f − f*_lower)/f called "certified".
* ``REFINE_METHOD``, ``REFINE_MAX_ITERATIONS``, ``REFINE_TOLERANCE`` — the defaults of ``refine``, the same for
  planar and 3-D graphs. Gauss–Newton, because refinement starts from LAGO's estimate, near the minimum, where the
  Gauss–Newton step is Levenberg–Marquardt's with λ → 0 and converges quadratically (a backtracking line search
  guards it; Levenberg–Marquardt stays a keyword away for far starts); a relative χ² decrease below 1e-9 ends it,
  because at quadratic convergence the χ² left to gain after such a step is of the order of its square, far below
  any difference a reader compares (the 3-D minima of ``benchmarks/space.md`` are reached to their 10 digits, in
  2 to 6 iterations); 50 iterations, ten times what the benchmark graphs need from LAGO's start. Where residuals
  are large Gauss–Newton converges only linearly, and a smaller ``tolerance`` (with more iterations) gets closer.
"""

__all__ = ["CHI2_CONVENTION", "SESYNC_COST_CONVENTION", "CERTIFY_TOL", "COSTS", "COSTS_3D", "COST_OF_FORMAT",
           "COST_DESCRIPTION", "check_cost", "REFINE_METHOD", "REFINE_MAX_ITERATIONS", "REFINE_TOLERANCE"]

CHI2_CONVENTION = "sum e'Ωe, no 1/2"

#: The named costs (module docstring), in the order the command line lists them.
COSTS = ("g2o", "gtsam", "paper")
#: The costs defined for 3-D graphs (the paper's eq. (3) is planar).
COSTS_3D = ("g2o", "gtsam")
#: The cost a file format means: its information matrices are written for that error.
COST_OF_FORMAT = {"g2o": "g2o", "toro": "paper"}
#: One line per cost, for reports and ``--help``.
COST_DESCRIPTION = {
    "g2o": "g2o's chi2: e = t2v(Z^-1 X_i^-1 X_j) (EDGE_SE2; EDGE_SE3:QUAT: translation, quaternion x,y,z)",
    "gtsam": "GTSAM's 2*error(): e = Logmap(Z^-1 X_i^-1 X_j) (BetweenFactor, information as readG2o reads it)",
    "paper": "the paper's eq. (3): e = [R_i'(p_j - p_i) - dl; wrap(th_j - th_i - d)] (TORO's information)",
}

#: One line stating which cost the certificate is about (eqs. (S1)–(S2) of ``certification/sesync.py``).
SESYNC_COST_CONVENTION = ("SE-Sync cost f = Σ κ‖R_j−R_iR̃‖²_F + τ‖t_j−t_i−R_i t̃‖² (no ½; κ = Ω_θθ, "
                          "τ = 2/tr(Ω_tt⁻¹)), not the χ²")

#: The largest relative suboptimality bound (f − f*_lower)/f ``certify`` accepts as "certified" (default).
CERTIFY_TOL = 1e-3

#: ``refine``'s defaults in every dimension (module docstring).
REFINE_METHOD = "gauss-newton"
REFINE_MAX_ITERATIONS = 50
REFINE_TOLERANCE = 1e-9


def check_cost(cost, *, dim: int = 2) -> str:
    """``cost`` as one of :data:`COSTS` (3-D: :data:`COSTS_3D`); ``OptionError`` naming the choices otherwise."""
    from .errors import OptionError

    allowed = COSTS if dim == 2 else COSTS_3D
    name = str(cost).lower() if isinstance(cost, str) else cost
    if name not in allowed:
        extra = " (the paper's eq. (3) is planar)" if dim == 3 and name == "paper" else ""
        raise OptionError(f"unknown cost {cost!r}{extra}; expected one of {allowed}")
    return name
