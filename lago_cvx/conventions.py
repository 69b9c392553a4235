"""Conventions written once, for the reports of the library and the command line (no heavy imports:
``lago-cvx --help`` reads them).

* ``CHI2_CONVENTION`` — χ² of eq. (3) in the g2o convention, Σ eᵀΩe with no ½ (twice GTSAM's ``error()``).
* ``SESYNC_COST_CONVENTION`` — the cost the optimality certificate is about (``lago_cvx.certification``).
* ``CERTIFY_TOL`` — the largest proven relative suboptimality (f − f*_lower)/f called "certified".
"""

__all__ = ["CHI2_CONVENTION", "SESYNC_COST_CONVENTION", "CERTIFY_TOL"]

CHI2_CONVENTION = "g2o convention: sum e'Ωe, no 1/2"

#: One line stating which cost the certificate is about (eqs. (S1)–(S2) of ``certification/sesync.py``).
SESYNC_COST_CONVENTION = ("SE-Sync cost f = Σ κ‖R_j−R_iR̃‖²_F + τ‖t_j−t_i−R_i t̃‖² (no ½; κ = Ω_θθ, "
                          "τ = 2/tr(Ω_tt⁻¹)), not the g2o χ²")

#: The largest relative suboptimality bound (f − f*_lower)/f ``certify`` accepts as "certified" (default).
CERTIFY_TOL = 1e-3
