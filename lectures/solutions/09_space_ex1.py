# Exercise 1 of lecture 9 — the chordal distance (D) and the weights (Q).
#
# (D). ‖R₂ − R₁‖²_F = tr(R₂ᵀR₂) + tr(R₁ᵀR₁) − 2 tr(R₁ᵀR₂) = 6 − 2 tr(R₁ᵀR₂), and a rotation of angle ψ has trace
# 1 + 2cos ψ (eigenvalues 1, e^{±iψ}), so ‖R₂ − R₁‖²_F = 6 − 2 − 4cos ψ = 4(1 − cos ψ) = 2ψ² − ψ⁴/6 + …
# (twice the squared angle near 0, as (Q) says for S = I: tr(I)I − I = 2I).
# (Q). ‖[φ]× S‖²_F = tr(S [φ]×ᵀ[φ]× S) = tr([φ]×ᵀ[φ]× W) with W = S², and [φ]×ᵀ[φ]× = ‖φ‖²I − φφᵀ, so
# ‖[φ]× S‖²_F = ‖φ‖² tr W − φᵀWφ = φᵀ(tr(W) I − W)φ.
# Second order. R Exp(φ) − R = R([φ]× + O(φ²)), and R is orthogonal, so ‖(R Exp(φ) − R) S‖²_F = ‖[φ]× S‖²_F + O(φ³).
# With W = ½tr(Ω)I − Ω: tr W = (3/2)tr Ω − tr Ω = ½ tr Ω, so tr(W)I − W = Ω: the cost is φᵀΩφ + O(φ³).
# When no PSD W exists. tr(W)I − W = Ω forces tr W = ½ tr Ω (take traces: 2 tr W = tr Ω), so W = ½tr(Ω)I − Ω is
# the only solution; its eigenvalues are ½(λ₁ + λ₂ + λ₃) − λ_k, negative when λ_k > the sum of the other two,
# e.g. Ω = diag(1, 1, 10): W = diag(5, 5, −4). No weight of the form (C) reproduces such an Ω_rr.
import numpy as np

from lago_cvx.course import check, setup
from lago_cvx.so3 import exp_so3, hat, log_so3

setup("09_space")
rng = np.random.default_rng(5)
R1, R2 = exp_so3(rng.normal(size=(200, 3))), exp_so3(rng.normal(size=(200, 3)))
psi = np.linalg.norm(log_so3(np.swapaxes(R1, 1, 2) @ R2), axis=1)
check(np.allclose(np.trace(np.swapaxes(R1, 1, 2) @ R2, axis1=1, axis2=2), 1 + 2 * np.cos(psi), atol=1e-12),
      "tr(R₁ᵀR₂) = 1 + 2cos ψ on 200 random pairs")
check(np.allclose(np.sum((R2 - R1) ** 2, axis=(1, 2)), 4 * (1 - np.cos(psi)), atol=1e-12), "(D) holds")
x = np.linspace(0.01, 0.3, 30)
check(np.allclose(8 * np.sin(x / 2) ** 2, 2 * x**2 - x**4 / 6, rtol=0, atol=x.max() ** 6 / 100),
      "(D)'s series: 4(1 − cos ψ) = 2ψ² − ψ⁴/6 + O(ψ⁶)")

errors = []
for _ in range(100):
    lam = rng.uniform(1, 10, 3)
    while lam.max() > lam.sum() - lam.max():                     # keep W ⪰ 0: λ_max ≤ sum of the others
        lam = rng.uniform(1, 10, 3)
    Q = exp_so3(rng.normal(size=3))
    Omega = Q @ np.diag(lam) @ Q.T
    W = 0.5 * np.trace(Omega) * np.eye(3) - Omega
    w, U = np.linalg.eigh(W)
    S = U @ np.diag(np.sqrt(w)) @ U.T
    phi = rng.normal(size=3)
    check_q = np.sum((hat(phi) @ S) ** 2) - phi @ (np.trace(W) * np.eye(3) - W) @ phi
    R = exp_so3(rng.normal(size=3))
    rel = []
    for eps in (1e-2, 1e-3):                                     # the relative error falls like ε: second order
        p = eps * phi
        rel.append(abs(np.sum(((R @ exp_so3(p) - R) @ S) ** 2) - p @ Omega @ p) / (p @ Omega @ p))
    errors.append((abs(check_q), rel))
check(max(e[0] for e in errors) < 1e-9, "(Q) holds for 100 random φ and S")
check(all(r[1] < 0.2 * r[0] and r[0] < 0.05 for _, r in errors),
      "with W = ½tr(Ω)I − Ω the chordal cost is φᵀΩφ to second order (relative error ∝ ε)")
bad = np.diag([1.0, 1.0, 10.0])
W_bad = 0.5 * np.trace(bad) * np.eye(3) - bad
print(f"Ω_rr = diag(1, 1, 10): the only W is diag({', '.join(f'{x:g}' for x in np.diag(W_bad))})")
check(np.linalg.eigvalsh(W_bad).min() < 0, "…which is not positive semidefinite: no S with S² = W exists")
