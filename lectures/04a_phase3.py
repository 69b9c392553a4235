# %% [markdown]
# # Lecture 4a — Phase 3 and Theorem 1, as the paper states them
#
# *L. Carlone, R. Aragues, J. A. Castellanos, B. Bona, "A Linear Approximation for Graph-based
# Simultaneous Localization and Mapping", RSS 2011 {cite}`carlone2011rss` — Section IV-D, Remark 1.*
#
# **The idea in one paragraph.** Phase 1 fixed the orientations from the angles alone, and phase 2 turned
# every measured displacement into the global frame with them. Had the orientations been exact, the
# positions would now follow from a linear least-squares fit. They are not exact, and the loops say so: the
# turned displacements do not close. Phase 3 lets the orientations move a little to close them better,
# treating the turned displacements and the phase-1 orientations as one linear measurement of all poses.
# Like a network of springs, every edge pulls its two poses towards the measured displacement (section 1
# draws the springs). The figure below shows the step on the running example: from $\hat\rho$ to $\rho^*$. Theorem 1 says that this last, linear
# step is the first-order correction that leads the sub-optimal estimate of phase 1 towards a minimum of
# the cost. Lecture 4b measures that claim on real data.
#
# Phase 1 (lecture 2) estimated the orientations $\hat\theta$ with covariance $P_\theta$ (eq. (13)).
# Phase 2 (lecture 3) rotated every relative position into the global frame, $\Delta^g = R\,\Delta^l$ with
# $R = R(\hat\theta)$, and stacked $z = [\Delta^g;\ \hat\theta]$ with its first-order covariance $P_z$
# (eqs. (9)–(11)). Phase 3 estimates all positions and orientations together from $z$.
#
# **Learning goals.** After this lecture you can
#
# 1. write phase 3 — eqs. (12) and (15) — as a cvxpy problem built from named parameters, read its
#    multipliers as spring forces, and check it against the package's sparse closed form;
# 2. compute the sub-optimal estimate $\hat\rho = [\hat p;\hat\theta]$ of eq. (14) and say why the method
#    never needs it;
# 3. state Theorem 1 and follow its proof: $\theta^* = \hat\theta + \tilde\theta$ (eq. (16)),
#    $p^* = \hat p + \tilde p$ (eq. (17)), and the corrections as the minimiser of the first-order
#    expansion (18);
# 4. say what Remark 1 claims about the cost of the method, and measure it.
#
# **Notation** (lectures 1–3's, and):
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $A$, $A_2 = A\otimes I_2$ | the *reduced* incidence matrix ($n\times m$) and the paper's one of the positions ($2n\times 2m$) | `lc.reduced_incidence(graph)` (some docstrings: "A2") |
# | $\rho = [p;\ \theta] \in \mathbb R^{3n}$ | positions interleaved ($x_1, y_1, x_2, \dots$), then orientations | `x`, `x_star` |
# | $\hat\rho$, $\rho^*$ | the sub-optimal estimate of eq. (14); phase 3's, eq. (15) | `result.phase3.x_star` ($\rho^*$) |
# | $R$, $J$, $H$ | $\mathrm{blkdiag}_k R(\hat\theta_{i_k})$; $\partial(R\Delta^l)/\partial\theta$ ($2m\times n$); lecture 3's Jacobian $\begin{bmatrix}R & J\\ 0 & I_n\end{bmatrix}$ | `result.phase2.jac` ($J$) |
# | $P_{\Delta g}$ | $R P_{\Delta l} R^\top$, the covariance of $\Delta^g$ for known orientations | — |
# | $B$ | the matrix of eq. (12) — not the tree block of $C = [I_l\ B]$ (lecture 5) | `result.phase3` |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)

# %%
import time
import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np
import scipy.linalg as sla
import lago_cvx as lc
from lago_cvx import phases as P
from lago_cvx.metrics import relative_difference
from lago_cvx.posegraph import rot2
from lago_cvx.positions import resolve_positions
from lago_cvx.refinement import jacobian, odometry_guess
from lago_cvx.solvers import LEAST_SQUARES, ClarabelSettings
from lago_cvx.theorem1 import theorem1
from lago_cvx.course import (S, check, intuition_figure, paper_lago, real, remark1_figure, running_example,
                             setup, show, structure_figure)
setup("04a_phase3")

def solve_qp(problem):
    """Clarabel with static regularization 1e-7 (its default, 1e-8, fails on the running example's dense
    parameters: section 1), the package's tolerances 1e-12 and QDLDL. Returns the status."""
    kwargs = ClarabelSettings(static_regularization_constant=1e-7).over(LEAST_SQUARES).solver_kwargs()
    problem.solve(solver=cp.CLARABEL, direct_solve_method="qdldl", **kwargs)
    return problem.status

# %% tags=["remove-input"]
show(intuition_figure("04a"), "intuition")

# %% [markdown]
# ## 1. The phase-3 model, eq. (12), and its solution, eq. (15)
#
# **Eq. (12).** The unknowns are $\rho = [p;\ \theta]$. Given the orientations, the global relative
# positions are differences of positions, $\Delta^g_{ij} = p_j - p_i$, i.e. $\Delta^g = A_2^\top p$; and
# $\hat\theta$ measures $\theta$ directly. So $z$ is *linear* in $\rho$:
#
# $$ z = \begin{bmatrix}\Delta^g\\ \hat\theta\end{bmatrix}
#      = \begin{bmatrix} A_2^\top & 0\\ 0 & I_n\end{bmatrix}\begin{bmatrix} p\\ \theta\end{bmatrix}
#      = B^\top\rho \tag{12}$$
#
# (exactly, for exact data; with noise of covariance $P_z$ otherwise). In the package
# $B^\top$ = `phases.design_matrix(graph)`.
#
# **Eq. (15).** The best linear unbiased estimate and its covariance are
#
# $$ \rho^* = \begin{bmatrix} p^*\\ \theta^*\end{bmatrix} = (B P_z^{-1} B^\top)^{-1} B P_z^{-1} z,
#    \qquad P_{\rho^*} = (B P_z^{-1} B^\top)^{-1}. \tag{15}$$
#
# $P_z$ is dense (it contains $P_\theta$), but lecture 3 factored its inverse, $P_z^{-1} = W^\top W$ with a
# sparse $W$ ($3m\times(2m+n)$, `phase2.W`). Eq. (15) is therefore the weighted least squares
# $\min_\rho \lVert W(z - B^\top\rho)\rVert^2$. We write it in cvxpy with the residual named:
#
# $$ \min_{\rho,\,e}\ \lVert W e\rVert^2 \quad\text{subject to}\quad e = z - B^\top\rho .$$
#
# Naming $e$ keeps one parameter per product (cvxpy's "disciplined parametrized programming": changing a
# parameter's `.value` re-solves without rebuilding), and its multiplier has a meaning (below).
#
# **Which Clarabel call.** With Clarabel's defaults, `phase3.solve(solver=cp.CLARABEL)` may stop with a numerical
# error (cvxpy raises `SolverError`; the first line printed below says what happened here): the factorization of
# its KKT system with the dense parameter $B^\top$ needs a static regularization above the default $10^{-8}$.
# `phase3.solve(solver=cp.CLARABEL, static_regularization_constant=1e-7)` works; the lecture's `solve_qp`
# (defined at the top) makes the same call with the package's tolerances $10^{-12}$ and QDLDL.
#
# We work on the running example, whose information is block-diagonal — the paper's setting — with the
# paper's phases (`paper_lago`: tree rounding, $\mathrm{blkdiag}(P_\Delta, P_\delta)$, phase-3 poses).

# %%
world = running_example()
g = world.graph
res = paper_lago(g)
n, m = g.n_poses - 1, g.n_edges
print(f"{g!r}: n = {n}, m = {m}; ρ has 3n = {3 * n} entries, z has 2m + n = {2 * m + n}")

# eq. (12) on exact data: truth moved into the frame of pose 0
clean = lc.manhattan_world(60, seed=1, sigma_xy=0.0, sigma_theta=0.0)   # own world: the running example without noise
rc = paper_lago(clean.graph)
truth0 = lc.between(np.broadcast_to(clean.truth[0], clean.truth.shape), clean.truth)
truth0[:, 2] += 2 * np.pi * np.rint((rc.phase1.theta - truth0[:, 2]) / (2 * np.pi))  # θ̂'s branch of 2π
rho_true = np.concatenate([truth0[1:, :2].ravel(), truth0[1:, 2]])
e12 = np.abs(rc.phase2.z - P.design_matrix(clean.graph) @ rho_true).max()

# %% tags=["remove-input"]
check(e12 < 1e-9, f"eq. (12) on exact data: z = Bᵀρ_true (max deviation {e12:.1e})")

# %%
W = cp.Parameter(res.phase2.W.shape, name="W")            # WᵀW = P_z⁻¹ (lecture 3)
z = cp.Parameter(2 * m + n, name="z")                     # [Δᵍ; θ̂], eq. (9)
Bt = cp.Parameter((2 * m + n, 3 * n), name="Bᵀ")          # eq. (12)
rho = cp.Variable(3 * n, name="ρ")
e = cp.Variable(2 * m + n, name="e")
residual = e == z - Bt @ rho
phase3 = cp.Problem(cp.Minimize(cp.sum_squares(W @ e)), [residual])
print(phase3)
W.value, z.value, Bt.value = res.phase2.W.toarray(), res.phase2.z, P.design_matrix(g).toarray()
TOL = 1e-8   # accepted relative disagreement with the closed form, for an "optimal" status at 1e-12 gaps
try:
    phase3.solve(solver=cp.CLARABEL)                                    # Clarabel's defaults
    plain = phase3.status
except cp.error.SolverError as exc:
    plain = f"SolverError: {exc}"
print(f"phase3.solve(solver=cp.CLARABEL) → {plain}")
phase3.solve(solver=cp.CLARABEL, static_regularization_constant=1e-7)   # the call that works
status_1e7, e_1e7 = phase3.status, relative_difference(rho.value, res.phase3.x_star)
print(f"phase3.solve(solver=cp.CLARABEL, static_regularization_constant=1e-7) → {status_1e7}, "
      f"relative difference from the closed form {e_1e7:.1e}")
status = solve_qp(phase3)                                 # the same, with tolerances 1e-12 (top of the lecture)
P_z = res.phase2.covariance_z()                           # dense, for this small graph only
Bd = Bt.value.T                                           # B
info15 = Bd @ np.linalg.solve(P_z, Bd.T)                  # B P_z⁻¹ Bᵀ
rho15 = np.linalg.solve(info15, Bd @ np.linalg.solve(P_z, res.phase2.z))     # eq. (15), dense
e_cvx = relative_difference(rho.value, res.phase3.x_star)
e_dense = relative_difference(rho15, res.phase3.x_star)
e_info = np.abs(info15 - res.phase3.info.toarray()).max() / np.abs(info15).max()

# %% tags=["remove-input"]
check(status_1e7 == "optimal" and e_1e7 < TOL, f"static regularization 1e-7: Clarabel's default tolerances suffice ({e_1e7:.1e})")
check(status == "optimal" and e_cvx < TOL, f"cvxpy (Clarabel, {status}) = package closed form ({e_cvx:.1e})")
check(e_dense < 1e-9, f"eq. (15) with the dense P_z = package closed form ({e_dense:.1e})")
check(e_info < 1e-9, f"information B P_z⁻¹ Bᵀ = phase3.info ({e_info:.1e})")

# %% [markdown]
# **The multiplier is a force.** With the Lagrangian $\lVert We\rVert^2 + \lambda^\top(e - z + B^\top\rho)$,
# stationarity in $e$ gives $\lambda = -2P_z^{-1}(z - B^\top\rho^*)$ and stationarity in $\rho$ gives
# $B\lambda = 0$ — the normal equations of (15). Split $\lambda = [\lambda_\Delta;\ \lambda_\theta]$. Writing
# $P_z^{-1}$ with its factor $W$ (lecture 3) shows that the edge part is
#
# $$ \tfrac12\lambda_{\Delta,k} = f_k = P_{\Delta g,k}^{-1}\, d_k,\qquad
#    d_k = p^*_j - p^*_i - \Delta^g_k - J_k(\theta^* - \hat\theta),$$
#
# the force of a spring of stiffness $P_{\Delta g,k}^{-1}$ stretched by the linearised residual $d_k$ of
# edge $k$. Then $B\lambda = 0$ reads: $A_2\lambda_\Delta = 0$ — **the spring forces balance at every free
# pose** — and $\lambda_\theta = 0$, which unpacks to $J^\top f = P_\theta^{-1}(\theta^* - \hat\theta)$: the
# torque the springs exert on the orientations is balanced by a pull towards $\hat\theta$ of stiffness
# $P_\theta^{-1}$. Pose 0 needs no force at all: summing the balance over all poses, the net force on
# the anchor is zero — fixing it removes the free translation and rotation, it does not hold the graph.

# %%
lam = residual.dual_value
lam_D, lam_th = lam[:2 * m].reshape(m, 2), lam[2 * m:]
force = lam_D / 2
e_lam = np.abs(lam + 2 * np.linalg.solve(P_z, res.phase2.z - Bd.T @ rho.value)).max() / np.abs(lam).max()
p_s = np.vstack([[0.0, 0.0], rho.value[:2 * n].reshape(n, 2)])       # p* with pose 0 at the origin
th_s = np.concatenate([[0.0], rho.value[2 * n:]])
th_h = res.phase1.theta
dg = res.phase2.delta_g
d = p_s[g.heads] - p_s[g.tails] - dg - (dg @ S.T) * (th_s - th_h)[g.tails, None]   # J_k = S Δᵍ_k at the tail
Rk = rot2(th_h[g.tails])
P_dg_inv = Rk @ np.linalg.inv(res.uncertainty.cov_delta_l) @ np.swapaxes(Rk, 1, 2)
e_spring = np.abs(force - np.einsum("kab,kb->ka", P_dg_inv, d)).max() / np.abs(force).max()
net = lc.incidence_matrix(g) @ force                                   # net force on every pose, anchor included
J = res.phase2.jac.toarray()
e_torque = np.abs(J.T @ force.ravel() - res.phase1.info @ (rho.value[2 * n:] - res.phase1.theta_free)).max()

# %% tags=["remove-input"]
check(e_spring < 1e-6, f"λ_Δ/2 = P_Δg⁻¹ d_k: spring forces (rel. {e_spring:.1e}; largest |f| {np.abs(force).max():.2f})")
check(np.abs(net).max() < 1e-6 * np.abs(force).max(),
      f"forces balance at every pose, and the anchor feels none (max net {np.abs(net).max():.1e})")
check(e_lam < 1e-6, f"λ = −2 P_z⁻¹ (z − Bᵀρ*) (rel. {e_lam:.1e})")
check(np.abs(lam_th).max() < 1e-6 * np.abs(lam).max() and e_torque < 1e-6 * np.abs(J.T @ force.ravel()).max(),
      f"λ_θ = 0: torques balanced by P_θ⁻¹(θ* − θ̂) (max deviation {e_torque:.1e})")

# %% [markdown]
# The figure shows why the package never forms $P_z$: it is dense, while its factor $W$ and the
# information matrix $BP_z^{-1}B^\top$ are as sparse as the graph. On the right, the edges drawn at
# $p^*$, coloured by the tension $\lVert f_k\rVert$: the loops that disagree most pull hardest.

# %%
show(structure_figure([(P_z, "P_z (dense)"), (W.value, "W, WᵀW = P_z⁻¹"), (info15, "B P_z⁻¹ Bᵀ (information of ρ*)")],
                      g, p_s, force), "structure_and_forces")

# %% [markdown]
# The same cross-check on a real graph, with the package's own cvxpy problem (`phases.phase3_problem`,
# solved by Clarabel) against its closed form:

# %%
intel = real("carlone/INTEL_P_toro.graph")
if intel is not None:
    r_intel = paper_lago(intel)
    t0 = time.perf_counter()
    ph3_cvx, _ = P.phase3_from_problem(intel, r_intel.phase2)
    t_cvx = time.perf_counter() - t0
    e_real = relative_difference(ph3_cvx.x_star, r_intel.phase3.x_star)
    print(f"INTEL_P_toro: 3n = {ph3_cvx.x_star.size} unknowns; Clarabel {t_cvx:.2f} s, closed form "
          f"{1e3 * r_intel.timings['phase3']:.0f} ms")

# %% tags=["remove-input"]
if intel is not None:
    check(e_real < TOL, f"INTEL: cvxpy phase 3 = closed form ({e_real:.1e})")

# %% [markdown]
# ## 2. Eq. (14): the sub-optimal estimate $\hat\rho = [\hat p;\ \hat\theta]$
#
# Once the orientations are fixed at $\hat\theta$, the position equations $A_2^\top p = R(\hat\theta)\Delta^l$
# of the system (7) are linear in $p$, and their weighted least-squares solution is
#
# $$ \hat p = \big[A_2 (R P_{\Delta l} R^\top)^{-1} A_2^\top\big]^{-1} A_2 (R P_{\Delta l} R^\top)^{-1} R\,\Delta^l ,
#    \tag{14}$$
#
# unique because $A$, hence $A_2$, has full row rank on a connected graph (Proposition 1, the existence
# of the phase-1 solution). $\hat\rho = [\hat p;\ \hat\theta]$ is the paper's **sub-optimal** estimate: it
# ignores that the position equations also constrain the orientations. The three phases never compute
# it (Remark 1); the proof of Theorem 1 uses it. In cvxpy it is phase 3 with the orientations held
# at $\hat\theta$ — one more constraint on the same problem: at $\theta = \hat\theta$ the orientation part of the
# residual vanishes and what is left is the weighted least squares of eq. (14). The multiplier $\mu$ of the
# new constraint is the torque needed to hold the orientations there; $\mu \neq 0$ says that $\hat\rho$ is
# not phase 3's optimum.
#
# In the package: `positions.resolve_positions(graph, θ̂, ...)` (for block-diagonal information exactly
# eq. (14); for full information the exact minimiser of χ² over the positions) and
# `theorem1.theorem1(graph).x_hat`.

# %%
theta_hat = cp.Parameter(n, name="θ̂")
hold = rho[2 * n:] == theta_hat
eq14 = cp.Problem(phase3.objective, [residual, hold])
print(eq14)
W.value = res.phase2.W.toarray()
theta_hat.value = res.phase1.theta_free
status14 = solve_qp(eq14)
A = lc.reduced_incidence(g).toarray()                     # n × m (the package's "A2")
A2 = np.kron(A, np.eye(2))                                # the paper's A₂ = A ⊗ I₂, 2n × 2m
R = sla.block_diag(*rot2(th_h[g.tails]))
RDl = R @ g.delta_l.ravel()                               # RΔˡ = Δᵍ
P_dg = R @ sla.block_diag(*res.uncertainty.cov_delta_l) @ R.T
Pdg_inv = np.linalg.inv(P_dg)
P_phat = np.linalg.inv(A2 @ Pdg_inv @ A2.T)               # covariance of p̂
p_hat = P_phat @ A2 @ Pdg_inv @ RDl                       # eq. (14)
t1 = theorem1(g, result=res)
p_pkg = resolve_positions(g, th_h, res.uncertainty).poses[1:, :2].ravel()
grad_theta = (-2 * Bd @ np.linalg.solve(P_z, res.phase2.z - Bd.T @ rho.value))[2 * n:]   # ∇_θ of the cost at ρ̂

# %% tags=["remove-input"]
check(status14 == "optimal" and relative_difference(rho.value[:2 * n], p_hat) < TOL,
      f"cvxpy with θ = θ̂ gives eq. (14) ({relative_difference(rho.value[:2 * n], p_hat):.1e})")
check(relative_difference(p_pkg, p_hat) < 1e-9 and relative_difference(t1.x_hat[:2 * n], p_hat) < 1e-9,
      "resolve_positions(θ̂) = theorem1(...).x_hat = eq. (14)")
check(np.abs(np.abs(hold.dual_value) - np.abs(grad_theta)).max() < 1e-6 * np.abs(grad_theta).max(),
      f"|μ| = |∇_θ cost(ρ̂)|, largest {np.abs(grad_theta).max():.2f}: ρ̂ is not the phase-3 optimum")

# %% [markdown]
# ## 3. Theorem 1 and eq. (16): $\theta^* = \hat\theta + \tilde\theta$
#
# **Theorem 1** (the three phases approximate the solution of eq. (6)). The outcome of the three-phase
# procedure approximates the solution of the nonlinear problem (6); in particular, the third phase
# produces a local correction of the sub-optimal estimate $\hat\rho$ built on the first phase, "leading it
# towards a minimum of the cost function".
#
# The proof has two steps: (i) block inversion of eq. (15) writes $\rho^*$ as $\hat\rho$ plus explicit
# corrections — eq. (16) for the orientations, eq. (17) for the positions; (ii) those corrections are
# exactly the minimiser of the first-order expansion (18) of the cost around $\hat\rho$ (section 5).
# Sections 3–5 check each step; lecture 4b measures the claim itself on real data.
#
# **Step (i), orientations.** From eq. (11), the information of $\rho^*$ has the blocks (Exercise 1
# derives them)
#
# $$ P_{\rho^*}^{-1} = B P_z^{-1} B^\top = \begin{bmatrix} A_2 P_{\Delta g}^{-1} A_2^\top & -A_2 P_{\Delta g}^{-1} J\\
#    -J^\top P_{\Delta g}^{-1} A_2^\top & P_\theta^{-1} + J^\top P_{\Delta g}^{-1} J\end{bmatrix},$$
#
# and $P_{\hat p} = (A_2 P_{\Delta g}^{-1} A_2^\top)^{-1}$ is the covariance of $\hat p$. The Schur complement
# gives the orientation block of the covariance,
# $P_{\theta^*} = \big(P_\theta^{-1} + J^\top P_{\Delta g}^{-1} J - J^\top P_{\Delta g}^{-1} A_2^\top P_{\hat p} A_2 P_{\Delta g}^{-1} J\big)^{-1}$,
# and then
#
# $$ \theta^* = \underbrace{(A P_\delta^{-1} A^\top)^{-1} A P_\delta^{-1}\delta}_{\hat\theta,\ \text{eq. (13)}}
#    \;+\; \underbrace{P_{\theta^*} J^\top P_{\Delta g}^{-1}\big(A_2^\top P_{\hat p} A_2 P_{\Delta g}^{-1} - I_{2m}\big) R\Delta^l}_{\tilde\theta} .
#    \tag{16}$$
#
# The correction is driven by $(A_2^\top P_{\hat p} A_2 P_{\Delta g}^{-1} - I)R\Delta^l = A_2^\top\hat p - R\Delta^l$:
# the residual of the position equations at $\hat\rho$ — the part of the loops the positions alone could
# not close. We evaluate eq. (16) with dense matrices (δ is the regularized $\delta_{\rm reg}$ of lecture 5).

# %%
P_theta_inv = res.phase1.info.toarray()                   # A P_δ⁻¹ Aᵀ
P_th_star = np.linalg.inv(P_theta_inv + J.T @ Pdg_inv @ J - J.T @ Pdg_inv @ A2.T @ P_phat @ A2 @ Pdg_inv @ J)
theta_13 = np.linalg.solve(P_theta_inv, A @ (res.regularization.delta_reg / res.uncertainty.var_delta))
theta_tilde = P_th_star @ J.T @ Pdg_inv @ (A2.T @ P_phat @ A2 @ Pdg_inv - np.eye(2 * m)) @ RDl
theta_star = res.phase3.x_star[2 * n:]
e16 = relative_difference(theta_13 + theta_tilde, theta_star)

# %% tags=["remove-input"]
check(e16 < 1e-9, f"eq. (16): θ̂ + θ̃ = phase 3's θ* ({e16:.1e}); max|θ̃| = {np.abs(theta_tilde).max():.3f} rad")
check(relative_difference(theta_13, res.phase1.theta_free) < 1e-9, "the first summand of eq. (16) is θ̂ (eq. (13))")
check(relative_difference(t1.theta_correction, theta_tilde) < 1e-9, "θ̃ = theorem1(...).theta_correction")
check(np.allclose(P_th_star, np.linalg.inv(info15)[2 * n:, 2 * n:], rtol=1e-8, atol=0),
      "P_θ* is the orientation block of P_ρ* = (B P_z⁻¹ Bᵀ)⁻¹")

# %% [markdown]
# ## 4. Eq. (17): $p^* = \hat p + \tilde p$
#
# **Step (i), positions.** The same block inversion gives
#
# $$ p^* = \underbrace{\big[A_2 (R P_{\Delta l} R^\top)^{-1} A_2^\top\big]^{-1} A_2 (R P_{\Delta l} R^\top)^{-1} R\Delta^l}_{\hat p,\ \text{eq. (14)}}
#    \;+\; \underbrace{P_{\hat p} A_2 P_{\Delta g}^{-1} J\, P_{\theta^*} J^\top P_{\Delta g}^{-1}\big(A_2^\top P_{\hat p} A_2 P_{\Delta g}^{-1} - I_{2m}\big) R\Delta^l}_{\tilde p} ,
#    \tag{17}$$
#
# i.e. $\tilde p = P_{\hat p} A_2 P_{\Delta g}^{-1} J\,\tilde\theta$: the positions follow the orientation
# correction, each global relative position $\Delta^g_k$ turning by $J_k\tilde\theta$. Two consequences: if
# the orientations are certain ($P_\theta \to 0$) then $P_{\theta^*}\to 0$ and both corrections vanish
# (section 5 sweeps this); and on a graph without loops (a tree, $m = n$ — below, the running example's
# odometry alone) $A_2$ is square and invertible,
# the residual $A_2^\top\hat p - R\Delta^l$ is zero and $\rho^* = \hat\rho$.

# %%
p_tilde = P_phat @ A2 @ Pdg_inv @ J @ P_th_star @ J.T @ Pdg_inv @ (A2.T @ P_phat @ A2 @ Pdg_inv - np.eye(2 * m)) @ RDl
p_star = res.phase3.x_star[:2 * n]
e17 = relative_difference(p_hat + p_tilde, p_star)

# %% tags=["remove-input"]
check(e17 < 1e-9, f"eq. (17): p̂ + p̃ = phase 3's p* ({e17:.1e}); max|p̃| = {np.abs(p_tilde).max():.3f} m")

# %%
chain = running_example().graph
chain = chain.subgraph_edges(chain.is_odometric)           # the running example's odometry alone: a tree, m = n
t_tree = theorem1(chain, result=paper_lago(chain))
corr = np.abs(np.concatenate([t_tree.theta_correction, t_tree.position_correction])).max()

# %% tags=["remove-input"]
check(relative_difference(p_tilde, P_phat @ A2 @ Pdg_inv @ J @ theta_tilde) < 1e-9, "p̃ = P_p̂ A₂ P_Δg⁻¹ J θ̃")
check(relative_difference(t1.position_correction, p_tilde) < 1e-9 and t1.identity_error < 1e-9,
      f"p̃ = theorem1(...).position_correction; identity ρ* − ρ̂ = [p̃; θ̃] to {t1.identity_error:.1e}")
check(corr < 1e-12, f"on the running example's odometric tree the corrections vanish: ρ* = ρ̂ (max |correction| {corr:.1e})")

# %% [markdown]
# ## 5. Eq. (18): the corrections minimise the first-order expansion around $\hat\rho$
#
# **Step (ii).** Move away from $\hat\rho$ by displacements $\delta_p$, $\delta_\theta$ (the paper's symbols;
# not the measurements $\delta$). To first order $R(\hat\theta + \delta_\theta)\Delta^l \approx R\Delta^l + J\delta_\theta$,
# and with the weights kept at $\hat\theta$ the cost (6) becomes the quadratic
#
# $$ f \approx \big(A_2^\top\hat p + A_2^\top\delta_p - R\Delta^l - J\delta_\theta\big)^\top (R P_{\Delta l} R^\top)^{-1}
#    \big(\cdots\big) + \big(A^\top\hat\theta + A^\top\delta_\theta - \delta\big)^\top P_\delta^{-1}\big(\cdots\big). \tag{18}$$
#
# Setting its gradient to zero gives exactly $\delta_p = \tilde p$ and $\delta_\theta = \tilde\theta$: phase 3
# is one Gauss–Newton step from $\hat\rho$. We build eq. (18) in cvxpy from named parameters — the residuals at
# $\hat\rho$, the matrices and the weights, with $W_\Delta^\top W_\Delta = (RP_{\Delta l}R^\top)^{-1}$ and
# $w_\delta = P_\delta^{-1/2}$ — and check that its minimiser is $(\tilde p, \tilde\theta)$.

# %%
dp = cp.Variable(2 * n, name="δ_p")
dth = cp.Variable(n, name="δ_θ")
e_D = cp.Variable(2 * m, name="e_Δ")
e_d = cp.Variable(m, name="e_δ")
r_D = cp.Parameter(2 * m, name="(A₂ᵀp̂ − RΔˡ)")
r_d = cp.Parameter(m, name="(Aᵀθ̂ − δ)")
A2t = cp.Parameter((2 * m, 2 * n), name="A₂ᵀ")
At = cp.Parameter((m, n), name="Aᵀ")
Jp = cp.Parameter((2 * m, n), name="J")
W_D = cp.Parameter((2 * m, 2 * m), name="W_Δ")
w_d = cp.Parameter(m, nonneg=True, name="w_δ")
eq18 = cp.Problem(cp.Minimize(cp.sum_squares(W_D @ e_D) + cp.sum_squares(cp.multiply(w_d, e_d))),
                  [e_D == r_D + A2t @ dp - Jp @ dth, e_d == r_d + At @ dth])
print(eq18)

r_D.value = A2.T @ p_hat - RDl
r_d.value = A.T @ res.phase1.theta_free - res.regularization.delta_reg
A2t.value, At.value, Jp.value = A2.T, A.T, J
W_D.value = sla.block_diag(*(res.uncertainty.sqrt_info_delta_l @ np.swapaxes(rot2(th_h[g.tails]), 1, 2)))
w_d.value = res.uncertainty.sqrt_info_delta
status18 = solve_qp(eq18)
e18 = relative_difference(np.concatenate([dp.value, dth.value]), np.concatenate([p_tilde, theta_tilde]))

# %% tags=["remove-input"]
check(np.allclose(W_D.value.T @ W_D.value, Pdg_inv, rtol=0, atol=1e-9 * np.abs(Pdg_inv).max()),
      "W_Δᵀ W_Δ = (R P_Δˡ Rᵀ)⁻¹")

# %%
# (18) is a first-order expansion: the residuals' linearisation error falls like the square of the step
step = np.concatenate([p_tilde, theta_tilde])

def position_residual(x):
    """A₂ᵀp − R(θ)Δˡ at x = [p; θ] (pose 0 at the origin), the exact residual of eq. (6)'s first term."""
    th = np.concatenate([[0.0], x[2 * n:]])
    return A2.T @ x[:2 * n] - np.einsum("kab,kb->ka", rot2(th[g.tails]), g.delta_l).ravel()

x_hat = np.concatenate([p_hat, res.phase1.theta_free])
lin_err = [np.abs(position_residual(x_hat + t * step) - (r_D.value + t * (A2.T @ p_tilde - J @ theta_tilde))).max()
           for t in (1e-2, 1e-3)]

# %% tags=["remove-input"]
check(status18 == "optimal" and e18 < TOL, f"the minimiser of eq. (18) is (p̃, θ̃) ({e18:.1e})")
check(80 < lin_err[0] / lin_err[1] < 120,
      f"residual linearisation error ×{lin_err[0] / lin_err[1]:.0f} for a step 10× shorter: second order")

# %% [markdown]
# **A sweep without rebuilding.** Scale every $P_\delta$ — hence $P_\theta$ — by $s$ by changing only
# `w_δ.value` and re-solve. As $s\to 0$ the orientations become certain and the correction vanishes,
# $\rho^*\to\hat\rho$; as $s$ grows, phase 3 trusts the positions more and the correction saturates.

# %%
scales = np.logspace(-4, 4, 9)
sizes, times = [], []
for s in scales:
    w_d.value = res.uncertainty.sqrt_info_delta / np.sqrt(s)
    t0 = time.perf_counter()
    assert solve_qp(eq18) == "optimal"
    times.append(time.perf_counter() - t0)
    sizes.append((np.linalg.norm(dth.value), np.linalg.norm(dp.value)))
sizes = np.array(sizes)
w_d.value = res.uncertainty.sqrt_info_delta
print(f"9 re-solves: first {1e3 * times[0]:.0f} ms, the others {1e3 * np.mean(times[1:]):.0f} ms on average")
at1 = sizes[list(scales).index(1.0)]

# %% tags=["remove-input"]
check(np.allclose(at1, [np.linalg.norm(theta_tilde), np.linalg.norm(p_tilde)], rtol=1e-6),
      "s = 1 reproduces (p̃, θ̃)")

# %%
fig, ax = plt.subplots(figsize=(6.5, 4))
ax.loglog(scales, sizes[:, 0], "o-", label="‖θ̃‖ (rad), eq. (16)")
ax.loglog(scales, sizes[:, 1], "s-", label="‖p̃‖ (m), eq. (17)")
ax.axvline(1.0, color="k", linewidth=0.8, linestyle=":")
ax.set_xlabel("scale s of P_δ (and P_θ)")
ax.set_ylabel("size of the phase-3 correction")
ax.set_title("Phase 3 corrects ρ̂ less the more certain θ̂ is")
ax.legend()
ax.grid(True, which="both", alpha=0.3)
show(fig, "correction_sweep")

# %% tags=["remove-input"]
check(np.all(np.diff(sizes[:, 0]) > 0) and sizes[0, 0] < 1e-2 * at1[0],
      f"‖θ̃‖ grows with s and vanishes as s → 0 (‖θ̃‖ = {sizes[0, 0]:.1e} at s = 1e-4)")

# %% [markdown]
# ## 6. Remark 1 — what the three phases cost
#
# **Remark 1** (the cost of the method, and why it should be accurate). The paper's remark has two parts:
#
# * *cost* — "A direct (iterative) method […] would require solving $N$ linear problems of size $3n$ (in
#   which the iterations $N$ may increase arbitrarily, depending on the initial guess); our approach solves a
#   small problem (on robot orientations — size $n$) and a problem of the same size of a single step of the
#   direct method";
# * *accuracy* — "the first-order correction provided by the last phase of the proposed approach refines a
#   sub-optimal solution which, in practice, is already close to a global minimum. Therefore the approach is
#   expected to be accurate, while reducing the risk of being trapped in a local minimum. Furthermore, the
#   sub-optimal solution needs not be computed explicitly."
#
# The second part is a claim about $\hat\rho$ ("already close to a global minimum") and about the step
# from it; the running example, a Manhattan world of 2000 poses and INTEL below (and lecture 4b's real
# graphs) put numbers on both.
#
# Section 5 showed that phase 3 *is* one Gauss–Newton step from $\hat\rho$ (of the cost with the weights
# at $\hat\theta$). Here we count: the sizes and non-zeros of phase 1's and phase 3's normal matrices, those
# of one Gauss–Newton step on χ² (eq. (3), `lago_cvx.refinement`), and how many such steps Gauss–Newton
# needs from dead reckoning (`odometry_guess`) and from LAGO. Times are printed for orientation only.

# %%
manh = lc.manhattan_world(2000, seed=1, sigma_xy=0.05, sigma_theta=0.02).graph  # own world: cost shows at scale
cases = [("running example", running_example().graph), ("Manhattan world, 2000 poses", manh)]
if intel is not None:
    cases.append(("INTEL_P_toro (real)", intel))
runs, sizes = {}, {}
for label, gr in cases:
    t0 = time.perf_counter()
    r = paper_lago(gr, spanning_tree="odometry")
    t_lago = time.perf_counter() - t0
    gn_dr = lc.refine(gr, odometry_guess(gr), max_iterations=100)
    gn_lago = lc.refine(gr, r.poses, max_iterations=100)
    Jg = jacobian(gr, r.poses)
    JtJ = (Jg.T @ Jg).tocsr()                  # Gauss–Newton's normal matrix (not lecture 3's H)
    nn = gr.n_poses - 1
    runs[label] = (r, gn_dr, gn_lago)
    print(f"{label}: n = {nn}\n"
          f"  phase 1 normal matrix {r.phase1.info.shape}, nnz {r.phase1.info.nnz};  phase 3 {r.phase3.info.shape}, "
          f"nnz {r.phase3.info.nnz};  one Gauss–Newton step {JtJ.shape}, nnz {JtJ.nnz}\n"
          f"  LAGO {1e3 * t_lago:.0f} ms in all;  Gauss–Newton from dead reckoning: {gn_dr.iterations} steps, "
          f"{1e3 * gn_dr.log[-1]['time']:.0f} ms;  from LAGO: {gn_lago.iterations} steps")
    sizes[label] = (nn, JtJ.shape)

# %% tags=["remove-input"]
for label, (r, gn_dr, gn_lago) in runs.items():
    nn, H_shape = sizes[label]
    check(r.phase1.info.shape == (nn, nn) and r.phase3.info.shape == H_shape == (3 * nn, 3 * nn),
          "phase 1 has size n; phase 3 and one Gauss–Newton step have size 3n")
    check(gn_lago.iterations < gn_dr.iterations and relative_difference(gn_lago.chi2, gn_dr.chi2) < 1e-6,
          f"Gauss–Newton needs N = {gn_dr.iterations} steps from dead reckoning, {gn_lago.iterations} from LAGO, "
          "to the same χ²")

# %%
show(remark1_figure(runs), "remark1_cost")

# %% tags=["remove-input"]
for label in ("running example", "Manhattan world, 2000 poses"):
    r, gn_dr, gn_lago = runs[label]
    check(r.chi2 < 1.01 * gn_lago.chi2, f"{label}: LAGO's χ² is {r.chi2 / gn_lago.chi2:.4f}× the minimum")

# %%
if intel is not None:
    r, gn_dr, gn_lago = runs["INTEL_P_toro (real)"]

# %% tags=["remove-input"]
if intel is not None:
    check(r.chi2 > 10 * gn_lago.chi2, f"INTEL, the paper's procedure: LAGO's χ² is {r.chi2 / gn_lago.chi2:.0f}× the minimum")

# %% [markdown]
# LAGO's cost is that of about one Gauss–Newton step. What it buys depends on the graph: on the running
# example and the Manhattan world its estimate is already within a percent of the minimum; on INTEL, with the paper's
# procedure, its χ² is more than ten times the minimum (lecture 4b explains why), and still Gauss–Newton
# from it needs fewer steps than from dead reckoning.

# %% [markdown]
# ### Try it: phase 3's correction against the rotation noise
# Drag σ_θ on the running example: the correction $\tilde\theta$ of eq. (16) grows with the heading noise, and so does
# the drop of χ² from $\hat\rho$ to $\rho^*$.

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.phase3_correction, "try_phase3", sigma_theta=(0.01, 0.3, 0.01, 0.05))

# %% [markdown]
# **Summary.** Phase 3 is a linear least-squares problem: given $\hat\theta$ and the phase-2 vector $z$, eq. (12)
# makes $z$ linear in $\rho = [p;\ \theta]$ and eq. (15) is its best linear unbiased estimate, solved here by cvxpy
# (with an explicit Clarabel setting) and by the package's sparse closed form. Theorem 1 splits $\rho^*$ into the
# sub-optimal estimate of eq. (14) plus the corrections of eqs. (16)–(17), which minimise the first-order expansion
# eq. (18); Remark 1: the three phases cost about one Gauss–Newton step.

# %% [markdown]
# ## Exercise 1 — The information matrix of phase 3, block by block
#
# *Derive.* Starting from $P_z$ of eq. (11) (write it as $H\,\mathrm{blkdiag}(P_{\Delta l}, P_\theta)H^\top$ with
# $H = \begin{bmatrix} R & J\\ 0 & I_n\end{bmatrix}$, lecture 3's Jacobian), show that
# $BP_z^{-1}B^\top = \begin{bmatrix} A_2 P_{\Delta g}^{-1} A_2^\top & -A_2 P_{\Delta g}^{-1} J\\ -J^\top P_{\Delta g}^{-1} A_2^\top & P_\theta^{-1} + J^\top P_{\Delta g}^{-1} J\end{bmatrix}$
# (the matrix the paper inverts blockwise to obtain eqs. (16)–(17)), and that the Schur complement of its
# position block is $P_{\theta^*}^{-1}$. Write `phase3_information(result, graph)` from the blocks; the check
# compares it block by block with `phase3.info`.
#
# **Hint.** $H$ is block upper triangular, so $H^{-1} = \begin{bmatrix} R^\top & -R^\top J\\ 0 & I_n\end{bmatrix}$;
# form $H^{-1}B^\top$ first, and remember that $R$ is orthogonal.

# %%
# your solution here: fill in the body of phase3_information, then run the cell (check_phase3_information tests it)
from lago_cvx.exercises import check_phase3_information

def phase3_information(result, graph):
    """B P_z⁻¹ Bᵀ (3n, 3n), dense, from the blocks above (result: the paper's LAGO on graph)."""
    raise NotImplementedError

check_phase3_information(phase3_information)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. P_z⁻¹ = H⁻ᵀ blkdiag(P_Δl⁻¹, P_θ⁻¹) H⁻¹, H⁻¹Bᵀ = [[RᵀA₂ᵀ, −RᵀJ], [0, I]] and R P_Δl⁻¹ Rᵀ =
# P_Δg⁻¹ (R orthogonal) give the blocks. By block inversion the Schur complement of the position block is the
# inverse of P_θ*, the orientation block of P_ρ* (eqs. (16)–(17)).
import numpy as np
import scipy.linalg as sla
import lago_cvx as lc
from lago_cvx.exercises import check_phase3_information
from lago_cvx.posegraph import rot2

def phase3_information(result, graph):
    A2 = np.kron(lc.reduced_incidence(graph).toarray(), np.eye(2))
    R = sla.block_diag(*rot2(result.phase1.theta[graph.tails]))
    J = result.phase2.jac.toarray()
    Pdg_inv = np.linalg.inv(R @ sla.block_diag(*result.uncertainty.cov_delta_l) @ R.T)
    return np.block([[A2 @ Pdg_inv @ A2.T, -A2 @ Pdg_inv @ J],
                     [-J.T @ Pdg_inv @ A2.T, result.phase1.info.toarray() + J.T @ Pdg_inv @ J]])

check_phase3_information(phase3_information).require()

# %% [markdown]
# ## Exercise 2 — The springs of a single loop
#
# *Derive, then check.* Take a graph that is one cycle — poses $0,\dots,N-1$ on a circle, edge $k$ from pose
# $k$ to pose $k+1$ and the last one back to pose 0 — with noisy measurements and *unequal* information per
# edge (`single_loop()`). Using the force balance of section 1 ($A_2\lambda_\Delta = 0$), show that every edge
# carries the same spring force $f$. Write `spring_forces(result, graph)`; the check compares your forces with
# phase 3's. Do the springs also stretch by the same amount? Why not?
#
# **Hint.** Write the balance at pose $k+1$: exactly two edges touch it. Compute $f_k = P_{\Delta g,k}^{-1} d_k$ as
# in section 1 from `result.phase3.x_star`, `result.phase2.delta_g` and `result.uncertainty.cov_delta_l`.

# %%
# your solution here: fill in the body of spring_forces, then run the cell (check_spring_forces tests it)
from lago_cvx.exercises import check_spring_forces, single_loop
graph = single_loop()              # the data the check uses

def spring_forces(result, graph):
    """The spring force f_k (m, 2) of every edge at phase 3's optimum."""
    raise NotImplementedError

check_spring_forces(spring_forces)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. On one loop every pose has two edges, oriented along the loop; the balance
# A₂λ_Δ = 0 at pose k+1 reads f_k − f_{k+1} = 0: one force runs through the whole ring, and the misclosure is
# shared out in proportion to the compliances, d_k = P_Δg,k f — the soft springs stretch most.
import numpy as np
from lago_cvx.course import S
from lago_cvx.exercises import check_spring_forces
from lago_cvx.posegraph import rot2

def spring_forces(result, graph):
    n = graph.n_poses - 1
    x = result.phase3.x_star
    p = np.vstack([[0.0, 0.0], x[:2 * n].reshape(n, 2)])
    th_star, th_hat = np.concatenate([[0.0], x[2 * n:]]), result.phase1.theta
    dg = result.phase2.delta_g
    d = p[graph.heads] - p[graph.tails] - dg - (dg @ S.T) * (th_star - th_hat)[graph.tails, None]
    Rk = rot2(th_hat[graph.tails])
    P_dg_inv = Rk @ np.linalg.inv(result.uncertainty.cov_delta_l) @ np.swapaxes(Rk, 1, 2)
    return np.einsum("kab,kb->ka", P_dg_inv, d)

check_spring_forces(spring_forces).require()
