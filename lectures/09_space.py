# %% [markdown]
# # Lecture 9 — From the plane to space: 3-D pose graphs
#
# Most pose graphs built today are three-dimensional: drones, legged robots, a car on a multi-storey car
# park. LAGO's idea — first the rotations by a *linear* problem, then the positions at those rotations, then
# one correction — carries over, but its first phase does not: there is no angle to add up along a path in
# 3-D, and so no $2k\pi$ to decide. Carlone, Tron, Daniilidis and Dellaert {cite}`carlone2015icra` estimate the
# rotations instead by the **chordal relaxation**: a linear least-squares problem in the nine entries of each
# rotation matrix, projected back onto the rotations. This lecture derives it, writes it as a cvxpy problem
# beside its closed form, measures what the projection costs, compares the result with GTSAM's
# `InitializePose3` on the benchmark `sphere2500`, and certifies the final estimate with SE-Sync's test
# {cite}`rosen2019sesync`. The figure below is the whole story on a small sphere: composing the noisy
# odometry drifts away (orange); the chordal relaxation, the positions and one joint step (blue) land on the truth.
#
# **Learning goals.** After this lecture you can
#
# 1. say why the $2k\pi$ regularization of lectures 5 and 8 has no 3-D counterpart, and why the chordal
#    relaxation is a convex problem;
# 2. write the relaxation as a cvxpy problem and as one sparse system with three right-hand sides, and check
#    one against the other to the solver's accuracy;
# 3. measure what the projection onto SO(3) loses, and choose between isotropic and anisotropic weights;
# 4. place LAGO's 3-D estimate against GTSAM's `InitializePose3` on real data;
# 5. state what SE-Sync's certificate proves in 3-D, and what it does not.
#
# **Notation.**
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $T_i = (R_i, t_i)$ | the $n$ poses, $R_i\in SO(3)$, $t_i\in\mathbb R^3$; pose 0 the anchor, $R_0 = I$, $t_0 = 0$ | `result.t` $(n, 3)$, `result.R` $(n, 3, 3)$ |
# | $\tilde T_{ij} = (\tilde R_{ij}, \tilde t_{ij})$ | the measurement of edge $i\to j$ | `graph.delta_R`, `graph.delta_t` |
# | $\Omega_{ij}$; $\Omega_{tt}$, $\Omega_{rr}$ | its $6\times6$ information, order (translation, rotation); the diagonal blocks | `graph.information` |
# | $e_{ij}$, χ² | $\mathrm{Log}(\tilde T_{ij}^{-1}T_i^{-1}T_j)$; $\sum e_{ij}^\top\Omega_{ij}e_{ij}$, the 3-D eq. (3) | `lago_cvx.posegraph3d.chi2_3d`, `result.chi2` |
# | $[\varphi]_\times$, $\mathrm{Exp}$, $\mathrm{Log}$ | the cross-product matrix; the maps between $\mathbb R^3$ and $SO(3)$ | `lago_cvx.so3` |
# | $S_{ij}$, $W = S^2$ | the weight of edge $ij$ in (C) (section 3) — not lecture 3's rotation $S$ | `weighting=` |
# | $S_\Lambda = M - \Lambda$ | the certificate matrix (section 5) | `lc.certify3d` |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)

# %%
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse.linalg as spla

import lago_cvx as lc
from lago_cvx.course import check, real, setup, show
from lago_cvx.so3 import exp_so3, log_so3, project_so3
from lago_cvx.solvers import LEAST_SQUARES, solve
from lago_cvx.space import (chordal_closed_form, chordal_problem, lago3d, positions_closed_form,
                            positions_cvxpy, refine3d)
from lago_cvx.space.certify import sesync_cost3d
from lago_cvx.synthetic.space import cube_grid_world, sphere_world

setup("09_space")


def in_anchor_frame(t, R, a=0):
    """Poses (t (n, 3), R (n, 3, 3)) expressed in pose a's frame: the frame every estimate here uses."""
    Ra = R[a].T
    return (t - t[a]) @ Ra.T, Ra[None] @ R


def rotation_errors(R_true, R):
    """‖Log(R_trueᵢᵀ Rᵢ)‖ per pose [rad], (n,)."""
    return np.linalg.norm(log_so3(np.swapaxes(R_true, 1, 2) @ R), axis=1)


world = sphere_world(6, 16, seed=1, sigma_t=0.05, sigma_r=0.05)
truth = in_anchor_frame(*world.truth)
drift = in_anchor_frame(*world.graph.initial)
estimate = lago3d(world.graph)
fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
for ax, (u, v), name in zip(axes, ((0, 1), (0, 2)), ("top view (x, y)", "side view (x, z)")):
    ax.plot(truth[0][:, u], truth[0][:, v], "k-", lw=2, label="truth")
    ax.plot(drift[0][:, u], drift[0][:, v], "--", color="tab:orange", label="odometry composed")
    ax.plot(estimate.t[:, u], estimate.t[:, v], ".-", color="tab:blue", ms=3, label="LAGO in 3-D")
    ax.set(xlabel="xyz"[u] + " [m]", ylabel="xyz"[v] + " [m]", title=name, aspect="equal")
    ax.legend(fontsize=8, loc="lower right")
fig.suptitle("A 96-pose sphere in the anchor's frame (σ_r = 0.05 rad per edge)")
show(fig, "intuition")

# %% tags=["remove-input"]
err_lago, err_drift = rotation_errors(truth[1], estimate.R), rotation_errors(truth[1], drift[1])
check(np.median(err_lago) < 0.5 * np.median(err_drift),
      f"LAGO's rotations are closer to the truth than the odometry's (median {np.median(err_lago):.3f} "
      f"against {np.median(err_drift):.3f} rad)")

# %% [markdown]
# ## 1. Why the 2kπ regularization vanishes
#
# In the plane, an orientation is one number and composition is addition: $\theta_j = \theta_i + \delta_{ij}$, so
# LAGO's phase 1 (eq. (13)) is linear in $\theta$ — once each measured $\delta_{ij}$ is put on the right branch,
# $\delta_{ij} + 2k_{ij}\pi$. Choosing those integers is eq. (23) and Theorem 3, the one non-convex decision of
# LAGO (lectures 5 and 8).
#
# In space neither half of that argument survives. Rotations do not commute, so no vector of "angles" adds up
# along a path: $\mathrm{Log}(\mathrm{Exp}(a)\,\mathrm{Exp}(b)) \ne a + b$, and there is no linear phase 1 to
# regularize. What *is* linear is the rotation matrix: $R_j = R_i\tilde R_{ij}$ is a linear equation in the
# entries of $R_i$ and $R_j$. A matrix does not wrap — the axis–angle vectors $\varphi$ and
# $\varphi\,(1 + 2\pi/\|\varphi\|)$, a whole extra turn about the same axis, give the same matrix — so a residual
# written with matrices needs no integer. The chordal distance between two rotations depends only on the angle
# $\psi$ of $R_1^\top R_2$:
# $$\|R_2 - R_1\|_F^2 = 2\operatorname{tr}(I - R_1^\top R_2) = 4\,(1 - \cos\psi) \;=\; 2\psi^2 - \tfrac{\psi^4}{6} + O(\psi^6),\tag{D}$$
# smooth and $2\pi$-periodic in $\psi$. Near $\psi = 0$ it is *twice* the squared geodesic angle — the factor 2 of
# (Q) below at $S_{ij} = I$ ($\operatorname{tr}(I)I - I = 2I$), and of lecture 8's planar $4(1-\cos) \approx 2(a-b)^2$ —
# and it lies below $2\psi^2$ for every $\psi > 0$ (the figure). Keeping the residuals and dropping the constraint $R_i\in SO(3)$ gives
# $$\min_{R_1,\dots,R_{n-1}\in\mathbb R^{3\times3}}\ \sum_{ij}\big\|(R_j - R_i\tilde R_{ij})\,S_{ij}\big\|_F^2,
# \qquad R_0 = I,\tag{C}$$
# with $S_{ij}$ a weight (section 3): a sum of squares of linear functions of $9(n-1)$ unknowns, i.e. a convex,
# linear least-squares problem with no branch, no tree and no integer — every measurement enters at once, as
# in the planar chordal relaxation of lecture 8, but here it replaces phase 1 altogether.

# %%
rng = np.random.default_rng(0)
a, b = rng.normal(size=(2, 3))
axis_angle = rng.normal(size=(500, 3))
turned = axis_angle * (1 + 2 * np.pi / np.linalg.norm(axis_angle, axis=1, keepdims=True))
R1, R2 = exp_so3(rng.normal(size=(500, 3))), exp_so3(rng.normal(size=(500, 3)))
psi = np.linalg.norm(log_so3(np.swapaxes(R1, 1, 2) @ R2), axis=1)
chord = np.sum((R2 - R1) ** 2, axis=(1, 2))
print(f"Log(Exp(a) Exp(b)) − (a + b) = {log_so3(exp_so3(a) @ exp_so3(b)) - (a + b)}: rotations do not add")
print(f"largest change of Exp(φ) under one extra turn about its axis: {np.abs(exp_so3(turned) - exp_so3(axis_angle)).max():.1e}")

# %% tags=["remove-input"]
check(np.linalg.norm(log_so3(exp_so3(a) @ exp_so3(b)) - (a + b)) > 0.1, "composition in 3-D is not addition of axis–angle vectors")
check(np.abs(exp_so3(turned) - exp_so3(axis_angle)).max() < 1e-12, "a whole turn more about the axis: the same matrix")
check(np.abs(chord - 4 * (1 - np.cos(psi))).max() < 1e-12, "(D): the chordal distance is 4(1 − cos ψ) on 500 random pairs")
small_psi = np.linspace(0.01, 0.5, 50)
series_gap = 8 * np.sin(small_psi / 2) ** 2 - (2 * small_psi ** 2 - small_psi ** 4 / 6)   # 4(1 − cos ψ) without cancellation
check(np.all((0 <= series_gap) & (series_gap <= small_psi ** 6 / 180 * 1.0001)),
      "(D): 4(1 − cos ψ) = 2ψ² − ψ⁴/6 + O(ψ⁶) for ψ ≤ 0.5 (remainder ≤ ψ⁶/180)")
check(np.all(chord <= 2 * psi ** 2 + 1e-12), "4(1 − cos ψ) ≤ 2ψ²: the chordal cost lies below twice the squared angle")

# %%
fig, ax = plt.subplots(figsize=(6, 3.6))
grid = np.linspace(0, 3 * np.pi, 300)
ax.plot(grid, 2 * grid ** 2, "--", color="0.5", label="2ψ² (the geodesic cost, doubled; a branch to pick beyond π)")
ax.plot(grid, 4 * (1 - np.cos(grid)), color="tab:blue", label="4(1 − cos ψ) = ‖R₂ − R₁‖²_F")
ax.plot(psi, chord, ".", ms=2, color="tab:red", label="500 random pairs")
ax.set(xlabel="angle ψ of R₁ᵀR₂ [rad]", ylabel="cost", ylim=(0, 12), title="the chordal distance does not wrap; near 0 it is ≈ 2ψ²")
ax.legend(fontsize=8)
show(fig, "chordal_distance")

# %% [markdown]
# ## 2. The relaxation as a cvxpy problem, and one system with three right-hand sides
#
# Stack the unknowns as $X = [R_1^\top; \dots; R_{n-1}^\top]$ ($3(n-1)\times 3$). Row $k$ of the residual of edge $ij$ is
# $(r^k_j - r^k_i\tilde R_{ij})S_{ij}$, with $r^k_i$ the $k$-th row of $R_i$: it involves row $k$ of every rotation
# and nothing else. Transposed, edge $ij$ contributes the block row $S_{ij}(x_j - \tilde R_{ij}^\top x_i)$, and (C) is
# $$\min_X\ \|W(AX - B)\|_F^2,\qquad A \in\mathbb R^{3m\times 3(n-1)},\ W = \operatorname{blkdiag}(S_{ij}),\ B\in\mathbb R^{3m\times 3},\tag{C'}$$
# where $A$ has $I$ at the head's block and $-\tilde R_{ij}^\top$ at the tail's, and $B$ carries the anchor's known
# $R_0 = I$. The three columns of $X$ are three least-squares problems **with the same matrix**: one
# factorization of $N = A^\top W^\top WA$ ($3(n-1)\times3(n-1)$) and three solves,
# $$N X = A^\top W^\top W B.\tag{N}$$
# `chordal_problem` builds (C') from named constants, so cvxpy prints it as the equation; Clarabel solves it, the
# closed form `chordal_closed_form` solves (N) on the package's sparse engine, and a plain `scipy` factorization
# of $N$ with the three right-hand sides is the third opinion. (cvxpy prints $\|\cdot\|_F^2$ as `quad_over_lin(·, 1.0)`,
# its atom for a sum of squares.) A 27-pose cube grid:

# %%
small = cube_grid_world(3, seed=0, sigma_t=0.05, sigma_r=0.05)
g = small.graph
problem, X, (A, W, B) = chordal_problem(g)
print(problem)
print(f"A: {A.shape}, W: {W.shape}, B: {B.shape}  ({g.n_poses} poses, {g.n_edges} edges)")
status = solve(problem)
closed = chordal_closed_form(g)
WA = (W @ A).tocsc()
N = (WA.T @ WA).tocsc()
X_scipy = spla.splu(N).solve(np.asarray(WA.T @ (W @ B)))                       # (N): one LU, three columns
X_closed = np.swapaxes(closed.relaxed[1:], 1, 2).reshape(-1, 3)                # [R_iᵀ] of the free poses
f_cvx, f_closed = problem.value, closed.cost
# The solver's accuracy: Clarabel stops at a duality gap below tol_gap_abs + tol_gap_rel·f, so
# f(X_cvx) − f* is below that; and since X* minimizes (C'), f(X) − f* = ‖WA(X − X*)‖²_F ≥ λ_min(N)‖X − X*‖²_F.
gap = 10 * (LEAST_SQUARES.tol_gap_abs + LEAST_SQUARES.tol_gap_rel * f_closed)   # a factor 10 of margin
lam_min = np.linalg.eigvalsh(N.toarray())[0]
bound_X = np.sqrt(gap / lam_min)
print(f"Clarabel {status}: (C') = {f_cvx:.12g}; closed form {f_closed:.12g}; λ_min(N) = {lam_min:.3g}")
print(f"max |X_cvxpy − X_closed| = {np.abs(X.value - X_closed).max():.1e} (allowed by the gap: {bound_X:.1e}); "
      f"max |X_scipy − X_closed| = {np.abs(X_scipy - X_closed).max():.1e}")

# %% tags=["remove-input"]
check(status == "optimal" and f_cvx - f_closed <= gap, "Clarabel's (C') is the closed form's minimum to the solver's gap")
check(np.linalg.norm(X.value - X_closed) <= bound_X, "…and its X is the closed form's within √(gap / λ_min(N))")
check(np.abs(X_scipy - X_closed).max() < 1e-10 * np.abs(X_closed).max(),
      "one factorization of N, three right-hand sides: the same X")

# %%
fig, ax = plt.subplots(figsize=(5, 4.6))
ax.spy(N, markersize=1.5)
ax.set(xlabel="column of N (3 per free pose)", ylabel="row of N (3 per free pose)",
       title=f"N = AᵀWᵀWA, {N.shape[0]}×{N.shape[1]}: one matrix for all 3 rows")
show(fig, "normal_matrix")

# %% [markdown]
# ## 3. What the SVD projection loses
#
# The minimizer $\hat R_i$ of (C) is not a rotation. The nearest rotation in the Frobenius norm comes from the SVD
# $\hat R_i = U\Sigma V^\top$: $\Pi(\hat R_i) = U\operatorname{diag}(1, 1, \det UV^\top)V^\top$ (the sign keeps
# $\det = +1$), at distance $\|\hat R_i - \Pi(\hat R_i)\|_F = \|\Sigma - \operatorname{diag}(1,1,\pm1)\|$. Two honest
# measures of what the projection costs:
#
# * the **distance** of the relaxed matrices from SO(3), or their smallest singular value: how much the
#   relaxation had to bend the matrices to fit inconsistent cycles;
# * the **gap** of (C): the constrained minimum of (C) over rotations lies between (C) at $\hat R$ (a relaxation,
#   so a lower bound) and (C) at $\Pi(\hat R)$ (a feasible point). The ratio (C)$(\Pi\hat R)$ / (C)$(\hat R)$ bounds the **cost
#   suboptimality** of the projected rotations: (C) at $\Pi\hat R$ is at most that ratio times the best (C) over
#   rotations. It says nothing directly about how *far* $\Pi\hat R$ is from those best rotations.
#
# `project_so3` computes $\Pi$ without an SVD wherever $\det \hat R_i > 0$: there $\Pi(\hat R_i)$ is the orthogonal
# polar factor of $\hat R_i$, the limit of Newton's iteration $X \leftarrow \tfrac12(X + X^{-\top})$ from
# $X = \hat R_i$ {cite}`higham2008`, which converges quadratically and costs a few dozen vector operations per step
# over all poses at once. The SVD stays the definition, and the computation wherever $\det \hat R_i \le 0$.
#
# Then what χ² says: the two-step route (`route="seed"`: projected rotations, positions exact for them) against
# the minimum of χ²
# found by Gauss–Newton (`lc.refine`, the same in 2-D and 3-D), and the default route's joint step in between (section 4). A
# 160-pose sphere with rising rotation noise:

# %%
rows = []
for sigma_r in (0.01, 0.05, 0.1, 0.2, 0.3):
    w = sphere_world(8, 20, seed=3, sigma_t=0.05, sigma_r=sigma_r)
    ch = chordal_closed_form(w.graph)
    sv = np.linalg.svd(ch.relaxed, compute_uv=False)
    distance = np.linalg.norm(ch.relaxed - ch.rotations, axis=(1, 2))
    two, default = lago3d(w.graph, route="seed"), lago3d(w.graph)
    best = refine3d(w.graph, default.t, default.R)
    rows.append(dict(sigma=sigma_r, dist=np.median(distance), smin=sv.min(), C=ch.cost, C_proj=ch.cost_projected,
                     two=two.chi2, default=default.chi2, best=best.chi2, sv=sv, d_all=distance,
                     err=np.median(rotation_errors(in_anchor_frame(*w.truth)[1], ch.rotations))))
print(f"{'σ_r':>5s} {'median ‖R̂−ΠR̂‖':>15s} {'min σ(R̂)':>9s} {'(C) at R̂':>9s} {'(C) at ΠR̂':>10s} {'ratio':>6s} "
      f"{'median rot. error':>17s} {'χ² two-step/min':>16s} {'χ² default/min':>14s}")
for r in rows:
    print(f"{r['sigma']:5.2f} {r['dist']:15.3f} {r['smin']:9.3f} {r['C']:9.4g} {r['C_proj']:10.4g} "
          f"{r['C_proj'] / r['C']:6.2f} {r['err']:15.3f} rad {r['two'] / r['best']:16.3f} {r['default'] / r['best']:14.3f}")

# %% tags=["remove-input"]
check(all(np.allclose(r["d_all"], np.sqrt(np.sum((r["sv"] - 1) ** 2, axis=1)), atol=1e-9) for r in rows),
      "‖R̂ − ΠR̂‖_F = ‖Σ − I‖ at every pose (no reflection was needed)")
check(all(r["C"] <= r["C_proj"] for r in rows), "(C) at the relaxed matrices ≤ (C) at their projections, always")
U, _, Vt = np.linalg.svd(ch.relaxed)
U[:, :, 2] *= np.sign(np.linalg.det(U @ Vt))[:, None]
check(np.abs(project_so3(ch.relaxed) - U @ Vt).max() < 1e-12, "Newton's polar iteration gives the SVD's Π(R̂)")
ratios = [r["C_proj"] / r["C"] for r in rows]
check(all(x < y for x, y in zip(ratios, ratios[1:])) and ratios[0] < 1.1 < 3 < ratios[-1],
      f"the projection's gap grows with the noise: ratio {ratios[0]:.2f} … {ratios[-1]:.1f}")
per_sigma = [r["err"] / r["sigma"] for r in rows]
check(max(per_sigma) < 1.3 * min(per_sigma), f"the projected rotations' median error is ≈ {np.mean(per_sigma):.1f} σ_r "
      "at every noise level")
check(all(r["default"] <= r["two"] and r["default"] / r["best"] < r["two"] / r["best"] for r in rows),
      "the joint step takes back part of what the projection lost, at every noise level")

# %%
sig = [r["sigma"] for r in rows]
fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
axes[0].plot(sig, [r["dist"] for r in rows], "o-", label="median ‖R̂ − ΠR̂‖_F")
axes[0].plot(sig, [r["smin"] for r in rows], "s-", label="smallest singular value of any R̂")
axes[0].set(xlabel="rotation noise σ_r [rad]", ylabel="distance / singular value", title="how far from SO(3)")
axes[0].legend(fontsize=8)
axes[1].semilogy(sig, ratios, "o-", label="(C) at ΠR̂ / (C) at R̂")
axes[1].semilogy(sig, [r["two"] / r["best"] for r in rows], "s-", label="χ² two-step route / minimum")
axes[1].semilogy(sig, [r["default"] / r["best"] for r in rows], "^-", label="χ² default route / minimum")
axes[1].set(xlabel="rotation noise σ_r [rad]", ylabel="ratio", title="what the projection costs")
axes[1].legend(fontsize=8)
show(fig, "projection")

# %% [markdown]
# At low noise the relaxed matrices are almost rotations and the projection costs little. As the noise grows, the
# relaxation shrinks the matrices — exactly as the planar relaxed vectors of lecture 8 shrink away from the
# anchor — and the projection throws away most of what (C) had fitted. The projected rotations still degrade
# gracefully — their median error grows in proportion to the noise (about $2.8\,\sigma_r$ on this sphere) — and the
# joint step of section 4 recovers most of the χ² excess up to $\sigma_r = 0.1$.
#
# **The weights.** Near the optimum $R_j = R_i\tilde R_{ij}\mathrm{Exp}(\varphi)$, so $R_j - R_i\tilde R_{ij} \approx
# R_i\tilde R_{ij}[\varphi]_\times$ and, for symmetric $W = S^2$,
# $$\|[\varphi]_\times S\|_F^2 = \varphi^\top(\operatorname{tr}(W)\,I - W)\,\varphi.\tag{Q}$$
# SE-Sync's **isotropic** choice {cite}`rosen2019sesync` is $S = \sqrt\kappa I$ with
# $\kappa = 3/(2\operatorname{tr}\Omega_{rr}^{-1})$: then (C) $\approx \omega\|\varphi\|^2$, $\omega = 3/\operatorname{tr}\Omega_{rr}^{-1}$, the
# isotropic Gaussian closest to the edge's rotational noise. The **anisotropic** choice $W = \tfrac12\operatorname{tr}(\Omega_{rr})I - \Omega_{rr}$
# makes (Q) exactly $\varphi^\top\Omega_{rr}\varphi$ — but $W$ must be positive semidefinite, which holds only while
# the largest eigenvalue of $\Omega_{rr}$ is at most the sum of the other two; beyond, the package raises its
# negative eigenvalues to a floor and the edge's stiffest axis is under-weighted. A test of both regimes: the
# 160-pose sphere, with rotation noise $\sigma = (\sigma_x, \sigma_y, \sigma_z)$ drawn in each edge's frame and the
# matching information, three draws each.

# %%
def anisotropic_sphere(sigma_rot, seed, sigma_t=0.05):
    """The 160-pose sphere's truth, measured with rotation noise diag(sigma_rot²) (edge frame): (world, graph)."""
    base = sphere_world(8, 20, seed=seed)
    gb, (t, R) = base.graph, base.truth
    Rt = np.swapaxes(R[gb.tails], 1, 2)
    R_ij, t_ij = Rt @ R[gb.heads], np.einsum("kab,kb->ka", Rt, t[gb.heads] - t[gb.tails])
    sig6 = np.r_[np.full(3, sigma_t), sigma_rot]
    noise = np.random.default_rng(seed + 50).standard_normal((gb.n_edges, 6)) * sig6
    dR = R_ij @ exp_so3(noise[:, 3:])                       # T̃ = T_ij Exp(n), to first order in the translation
    dt = t_ij + np.einsum("kab,kb->ka", R_ij, noise[:, :3])
    info = np.broadcast_to(np.diag(sig6 ** -2.0), (gb.n_edges, 6, 6))
    return base, lc.PoseGraph3D(gb.n_poses, gb.tails, gb.heads, dt, dR, info)


cases = {"one noisy axis (0.01, 0.01, 0.1): W ⪰ 0": (0.01, 0.01, 0.1),
         "one precise axis (0.005, 0.05, 0.05): W floored": (0.005, 0.05, 0.05)}
rms = {}
for label, sigma_rot in cases.items():
    for s in range(3):
        base, ga = anisotropic_sphere(np.array(sigma_rot), s)
        R_true = in_anchor_frame(*base.truth)[1]
        for weighting in ("isotropic", "anisotropic"):
            e = rotation_errors(R_true, chordal_closed_form(ga, weighting=weighting).rotations)
            rms[label, s, weighting] = np.sqrt(np.mean(e ** 2))
    print(f"{label:48s} RMS rotation error, isotropic: "
          + ", ".join(f"{rms[label, s, 'isotropic']:.3f}" for s in range(3)) + "; anisotropic: "
          + ", ".join(f"{rms[label, s, 'anisotropic']:.3f}" for s in range(3)) + " rad")

# %% tags=["remove-input"]
first, second = cases
check(all(rms[first, s, "anisotropic"] < rms[first, s, "isotropic"] for s in range(3)),
      "W ⪰ 0: the anisotropic weights give better rotations in every draw")
check(all(rms[second, s, "anisotropic"] > rms[second, s, "isotropic"] for s in range(3)),
      "W floored: the isotropic weights are better in every draw")

# %% [markdown]
# On the real 3-D benchmark graphs the two weightings differ little, and not always in the same direction — the χ²
# of the two-step route in the two weightings, beside the default route and the minimum of χ² reached from it
# (Gauss–Newton, `lc.refine`), computed here. The files are read for GTSAM's cost (`cost="gtsam"`), the
# Logmap error this lecture derives with and the cost `InitializePose3` is measured in; their own cost is g2o's
# (`lago_cvx.conventions`: the rotational error is the vector part of the error's unit quaternion, ≈ φ/2), and
# `python benchmarks/run.py space` reports both.

# %%
GRAPHS_3D = ["se-sync-3d/tinyGrid3D.g2o", "se-sync-3d/smallGrid3D.g2o", "se-sync-3d/parking-garage.g2o",
             "se-sync-3d/sphere2500.g2o"]
TWO = "seed"                         # the package's name of the two-step route
table = {}
for rel in GRAPHS_3D:
    gr = real(rel)
    if gr is None:
        continue
    gr = gr.with_cost("gtsam")
    two = {w: lago3d(gr, route=TWO, weighting=w) for w in ("isotropic", "anisotropic")}
    dflt = lago3d(gr)
    table[rel] = dict(graph=gr, two=two["isotropic"], two_aniso=two["anisotropic"], default=dflt,
                      minimum=refine3d(gr, dflt.t, dflt.R))
print(f"{'graph':32s} {'two-step iso':>12s} {'two-step aniso':>14s} {'default iso':>11s} {'minimum':>10s}")
for rel, r in table.items():
    print(f"{rel.split('/')[-1]:32s} {r['two'].chi2:12.6g} {r['two_aniso'].chi2:14.6g} {r['default'].chi2:11.6g} "
          f"{r['minimum'].chi2:10.6g}")

# %% [markdown]
# ## Exercise 1 — The chordal distance and its weights
#
# Prove (D) and (Q). Then write `chordal_weight(Omega)`: the weight $W$ with $\operatorname{tr}(W)I - W = \Omega_{rr}$, which makes
# $\|(R\,\mathrm{Exp}(\varphi) - R)S\|_F^2 = \varphi^\top\Omega_{rr}\varphi$ to second order in $\varphi$ for $S^2 = W$; the check tests the
# defining equation on random $\Omega_{rr}$. Find an $\Omega_{rr}$ for which no symmetric positive-semidefinite $W$ can do that.
#
# **Hint.** $\operatorname{tr}(R_1^\top R_2) = 1 + 2\cos\psi$ and $[\varphi]_\times^\top[\varphi]_\times = \|\varphi\|^2I - \varphi\varphi^\top$;
# take the trace of $\operatorname{tr}(W)I - W = \Omega_{rr}$ first.

# %%
# your solution here: fill in the body of chordal_weight, then run the cell (check_chordal_weight tests it)
from lago_cvx.exercises import check_chordal_weight

def chordal_weight(Omega):
    """W (3, 3) with tr(W) I − W = Omega."""
    raise NotImplementedError

check_chordal_weight(chordal_weight)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. (D): ‖R₂ − R₁‖²_F = 6 − 2tr(R₁ᵀR₂) = 4(1 − cos ψ) = 2ψ² − ψ⁴/6 + …, twice the squared
# angle near 0. (Q): ‖[φ]×S‖²_F = tr([φ]×ᵀ[φ]× W) = φᵀ(tr(W)I − W)φ with W = S². Taking traces, tr(W)I − W = Ω
# forces tr W = ½tr Ω, so W = ½tr(Ω)I − Ω is the only solution; its eigenvalues ½(λ₁+λ₂+λ₃) − λ_k are negative
# when one λ_k exceeds the sum of the other two (Ω = diag(1, 1, 10)): then no weight S reproduces Ω_rr.
import numpy as np
from lago_cvx.exercises import check_chordal_weight

def chordal_weight(Omega):
    return 0.5 * np.trace(Omega) * np.eye(3) - Omega

check_chordal_weight(chordal_weight).require()

# %% [markdown]
# ## 4. Positions, the joint step, and GTSAM on sphere2500
#
# **Positions.** At fixed rotations the rotational part $\varphi_{ij} = \mathrm{Log}(\tilde R_{ij}^\top R_i^\top R_j)$ of
# each error is fixed, and its translational part is **affine** in the positions,
# $e_v = V(\varphi_{ij})^{-1}\tilde R_{ij}^\top\big(R_i^\top(t_j - t_i) - \tilde t_{ij}\big)$. With the full $6\times6$ information
# the cross term $\Omega_{tr}$ only shifts the target, so χ² over $t$ is a linear least-squares problem whose solution is
# the exact minimizer of χ² at those rotations — the 3-D counterpart of eq. (14) (`positions_closed_form`, and
# `positions_cvxpy` as a cvxpy problem). This is the two-step route of Carlone et al. {cite}`carlone2015icra`.
#
# **The joint step.** As the planar default route corrects θ̂ and the positions together (lecture 4a's phase 3), the
# 3-D default route takes one Gauss–Newton step $\delta = (\delta v, \delta\varphi)$ of χ² on all poses, moves the
# rotations to $R_i\mathrm{Exp}(\alpha\,\delta\varphi_i)$ and re-solves the positions exactly. The step is guarded: $\alpha$
# is halved until χ² does not exceed the two-step route's, so χ²(default) ≤ χ²(two-step) always. GTSAM's `InitializePose3` is the
# same chordal relaxation followed by one Gauss–Newton step, without the re-solve and without the guard.

# %%
two_small = lago3d(g, route="seed")
t_cvx, _ = positions_cvxpy(g, two_small.R)
t_cf, _ = positions_closed_form(g, two_small.R)
default_small = lago3d(g)
best_small = refine3d(g, default_small.t, default_small.R)
print(f"cube grid: χ² two-step {two_small.chi2:.3f} → default {default_small.chi2:.3f} (α = {default_small.alpha}) → "
      f"minimum {best_small.chi2:.3f}; positions cvxpy − closed form: {np.abs(t_cvx - t_cf).max():.1e} m")

# %% tags=["remove-input"]
check(np.abs(t_cvx - t_cf).max() <= 1e-6 * np.abs(t_cf).max(), "positions: cvxpy = closed form (relative 1e-6)")
check(best_small.chi2 <= default_small.chi2 <= two_small.chi2, "χ²: minimum ≤ default ≤ two-step")
shift = t_cf + 0.01 * np.random.default_rng(2).normal(size=t_cf.shape)
shift[0] = 0
check(lc.chi2_3d(g, t_cf, two_small.R) < lc.chi2_3d(g, shift, two_small.R),
      "the positions minimize χ² at the two-step route's rotations (a random nudge raises it)")

# %% [markdown]
# **The real graphs of section 3** (sphere2500: 2500 poses, 4949 edges). GTSAM's `InitializePose3` runs in this
# process when the Python package `gtsam` is installed, with a prior pinning the first pose as GTSAM requires; its χ²
# is GTSAM's `2·error()`, which we check equals our χ² of its estimate.

# %%
def initialize_pose3(rel, graph):
    """GTSAM's InitializePose3 on the file ``rel`` with the first pose pinned: (χ² = 2·error(), our χ² of it),
    or None when GTSAM cannot solve it."""
    from lago_cvx.datasets import dataset

    factors, _ = gtsam.readG2o(str(dataset(rel)), True)
    pinned = gtsam.NonlinearFactorGraph(factors)
    pinned.add(gtsam.PriorFactorPose3(int(graph.ids[0]), gtsam.Pose3(),
                                      gtsam.noiseModel.Diagonal.Variances(np.full(6, 1e-8))))
    try:
        init = gtsam.InitializePose3.initialize(pinned)
    except RuntimeError:
        return None
    t_g = np.array([init.atPose3(int(k)).translation() for k in graph.ids])
    R_g = np.array([init.atPose3(int(k)).rotation().matrix() for k in graph.ids])
    return 2 * factors.error(init), lc.chi2_3d(graph, t_g, R_g)


try:
    import gtsam
except ImportError:
    gtsam = None
    print("gtsam is not installed (pip install gtsam): the comparison with InitializePose3 is skipped")
gtsam_chi2 = {rel: initialize_pose3(rel, r["graph"]) for rel, r in table.items()} if gtsam is not None else {}
for rel, r in table.items():
    theirs = gtsam_chi2.get(rel)
    print(f"{rel.split('/')[-1]:20s} default / minimum = {r['default'].chi2 / r['minimum'].chi2:.4f}"
          + (f"; InitializePose3 χ² = {theirs[0]:.2f} (GTSAM's 2·error), {theirs[1]:.2f} (ours), "
             f"default / InitializePose3 = {r['default'].chi2 / theirs[0]:.3f}" if theirs else ""))
sphere = table.get("se-sync-3d/sphere2500.g2o", {}).get("graph")
if sphere is not None:
    ours = {"two": table["se-sync-3d/sphere2500.g2o"]["two"], "default": table["se-sync-3d/sphere2500.g2o"]["default"]}

# %% tags=["remove-input"]
solved = {rel: v for rel, v in gtsam_chi2.items() if v is not None}
check(all(abs(a - b) <= 1e-9 * a for a, b in solved.values()), "GTSAM's χ² and ours are the same function")
check(all(table[rel]["default"].chi2 < a for rel, (a, _) in solved.items()),
      f"LAGO's default route ends below InitializePose3 on all {len(solved)} graphs GTSAM solves")
if table:
    worst = max(r["default"].chi2 / r["minimum"].chi2 for r in table.values())
    check(worst < 1.01, f"the default route is within {100 * (worst - 1):.2f}% of the minimum on all {len(table)} graphs")

# %% [markdown]
# The two-step route (the chordal relaxation and exact positions) already ends well below `InitializePose3`; the joint
# step, re-solved and guarded, brings the estimate to within a fraction of a percent of the minimum (the checks
# above: within 1% of the minimum on each graph of section 3 and below `InitializePose3` wherever GTSAM succeeds). The difference with GTSAM is not the relaxation — both solve (C) — but what follows it.
#
# ## 5. The certificate in 3-D
#
# χ² is not the only cost one can minimize; SE-Sync {cite}`rosen2019sesync` minimizes, with the isotropic
# weights of section 3 and $\tau_{ij} = 3/\operatorname{tr}\Omega_{tt}^{-1}$,
# $$f(t, R) = \sum_{ij}\kappa_{ij}\|R_j - R_i\tilde R_{ij}\|_F^2 + \tau_{ij}\|t_j - t_i - R_i\tilde t_{ij}\|^2 .\tag{S1}$$
# In $Y = [t_0 \cdots t_{n-1}\,|\,R_0 \cdots R_{n-1}]$ ($3\times4n$; the same poses $0,\dots,n-1$ as above, the anchor
# included as column 0 and block 0, so $Y$ has $n$ blocks where (C) had $n-1$ unknowns) every residual is linear, so $f = \operatorname{tr}(YMY^\top)$ for a sparse
# $4n\times4n$ matrix $M$. At a critical point the multipliers of $R_i^\top R_i = I$ are
# $\Lambda_i = \operatorname{sym}(R_i^\top(YM)_{R_i})$, and $\sum_i\operatorname{tr}\Lambda_i = f$. If $S_\Lambda = M - \operatorname{blkdiag}(0, \Lambda_i)
# \succeq 0$, $\Lambda$ is feasible for the dual of the semidefinite relaxation, so $f^\star \ge \sum_i \operatorname{tr}\Lambda_i = f$:
# the point is a **global** minimum of (S1). `certify3d` first refines to a critical point of (S1), then counts the
# negative pivots of one sparse $LDL^\top$ of $S_{\Lambda,g} + \mu\hat I_R$ (Sylvester's law of inertia), where $S_{\Lambda,g}$ is $S_\Lambda$ with
# the anchor's translation row and column removed and $\hat I_R$ the identity on the $3n$ rotation coordinates. The
# shift $\mu$ allows for rounding: it starts at the floor $\eta = 10^{-12}\|M\|_\infty$ and, while a negative pivot
# remains, is **multiplied by 4** ($\mu = 4^k\eta$, $k = 0, 1, \dots$, the first with no negative pivot; `cert.shift`).
# $\Lambda_i - \mu I$ is then dual feasible, so the proven bound is $f^\star \ge \sum_i\operatorname{tr}\Lambda_i - 3n\mu$.
#
# What it proves: that no set of poses has a lower $f$ than the bound — a statement about (S1), with its
# isotropic weights, not about χ². The minimum of χ² is a different point (its full $6\times 6$ information weighs
# the residuals differently), so a certified $f$ says that the basin of the χ² estimate is the right one, not that
# χ² is at its global minimum. On the cube grid:

# %%
cert = lc.certify3d(g, default_small.t, default_small.R)
t_true, R_true = in_anchor_frame(*small.truth)
points = {"truth": (t_true, R_true), "LAGO (default)": (default_small.t, default_small.R),
          "χ² minimum": (best_small.t, best_small.R)}
print(cert.verdict)
print(f"f at the certified point {cert.cost:.6f}; proven f* ≥ {cert.lower_bound:.6f}; negative pivots {cert.n_negative}")
for name, (tp, Rp) in points.items():
    print(f"  {name:15s} f = {sesync_cost3d(g, tp, Rp):12.6f}   χ² = {lc.chi2_3d(g, tp, Rp):10.4f}")
print(f"  {'certified':15s} f = {cert.cost:12.6f}   χ² = {lc.chi2_3d(g, cert.t, cert.R):10.4f}")

# %% tags=["remove-input"]
check(cert.certified and cert.lower_bound <= cert.cost, "the cube grid's estimate is certified (bound ≤ f)")
k_shift = np.log(cert.shift / cert.eta) / np.log(4)
check(abs(k_shift - round(k_shift)) < 1e-9 and cert.lower_bound == cert.dual_value - 3 * g.n_poses * cert.shift,
      f"μ = 4^{round(k_shift)}·η = {cert.shift:.3g} and the bound is Σ tr Λ_i − 3nμ with n = {g.n_poses}")
check(all(sesync_cost3d(g, tp, Rp) >= cert.lower_bound for tp, Rp in points.values()),
      "every other point, the truth included, costs at least the proven bound")
check(sesync_cost3d(g, best_small.t, best_small.R) > cert.cost and lc.chi2_3d(g, cert.t, cert.R) > best_small.chi2,
      "the minimum of f and the minimum of χ² are different points: the certificate is about f")

# %%
if sphere is not None:
    cert_sphere = lc.certify3d(sphere, ours["default"].t, ours["default"].R)
    print(f"sphere2500: {cert_sphere.verdict} (f = {cert_sphere.cost:.6f}, proven f* ≥ {cert_sphere.lower_bound:.6f}, "
          f"{cert_sphere.times['total']:.1f} s)")

# %% tags=["remove-input"]
if sphere is not None:
    check(cert_sphere.certified, "sphere2500: LAGO's estimate, refined on f, is certified globally optimal")

# %% [markdown]
# | step | convex problem | what it gives |
# |---|---|---|
# | chordal relaxation (C) | linear least squares in the entries of $R_i$, 3 right-hand sides | rotations, no $2k\pi$ to choose |
# | projection $\Pi$ | SVD per pose | the nearest rotations; the gap of (C) bounds the loss |
# | positions | linear least squares, full $6\times6$ information | the exact χ² minimizer at fixed rotations |
# | joint step | one Gauss–Newton system, guarded | most of the χ² excess removed |
# | certificate | one sparse $LDL^\top$ of $S_\Lambda = M - \Lambda$ | a proof of global optimality for (S1), or a bound |

# %% [markdown]
# ### Try it: rotation noise and the projection's gap
# Drag σ_r on a 60-pose sphere: the singular values of the relaxed $\hat R_i$ leave 1 and the ratio (C)(ΠR̂)/(C)(R̂)
# of section 3 grows.

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.chordal_gap_3d, "try_gap", sigma_r=(0.01, 0.4, 0.01, 0.1))

# %% [markdown]
# **Summary.** In 3-D the orientations need no $2k\pi$: the chordal relaxation (C) is a linear least-squares problem
# in the rotation matrices (one factorization, three right-hand sides), projected onto SO(3); its near-0 cost is
# $2\psi^2$ (D). The positions are then exact for those rotations, one guarded joint step removes most of the
# remaining χ² excess, and SE-Sync's certificate proves global optimality of its own cost (S1), not of χ².

# %% [markdown]
# ## Exercise 2 — On a tree the relaxation is exact
#
# Keep only the odometry edges of a world with noise (a spanning tree). Show that (C) then has the value 0 at the
# rotations composed along the tree, so that the relaxed matrices are rotations and the projection loses nothing,
# whatever the noise. Write `tree_rotations(graph)`, the rotations composed along the odometry from $R_0 = I$; the
# check compares them with `chordal_closed_form` on the tree. Then add back the loop closures one at a time: which
# costs most, and why?
#
# **Hint.** Compose $R_{k+1} = R_k\tilde R_{k,k+1}$ along the odometric edges; `graph.subgraph_edges(mask)` keeps the
# edges of a boolean mask.

# %%
# your solution here: fill in the body of tree_rotations, then run the cell (check_tree_rotations tests it)
from lago_cvx.exercises import check_tree_rotations

def tree_rotations(graph):
    """The rotations (n, 3, 3) composed along the odometric edges, R_0 = I."""
    raise NotImplementedError

check_tree_rotations(tree_rotations)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. On a tree every pose is reached from the anchor by one path; composing R_{k+1} =
# R_k R̃_{k,k+1} makes every residual R_j − R_i R̃_ij of (C) zero, so (C) = 0 there: these rotations are its
# minimizer (unique: the tree's normal matrix is nonsingular), and the projection onto SO(3) changes nothing. A
# loop closure adds a residual the tree's rotations do not satisfy, and (C) shrinks the matrices to trade it.
import numpy as np
from lago_cvx.exercises import check_tree_rotations

def tree_rotations(graph):
    R = np.empty((graph.n_poses, 3, 3))
    R[0] = np.eye(3)
    for k in np.flatnonzero(graph.is_odometric):     # the odometry in order: i = k, j = k + 1
        R[graph.heads[k]] = R[graph.tails[k]] @ graph.delta_R[k]
    return R

check_tree_rotations(tree_rotations).require()
