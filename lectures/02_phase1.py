# %% [markdown]
# # Lecture 2 — Phase 1: the orientations as a linear estimation problem
#
# Section IV-B of Carlone, Aragues, Castellanos, Bona (RSS 2011). Lecture 1 ended with the system
# eq. (7), non-linear because of $R(\theta)$. Its second half does not contain $R$: the relative
# orientations alone determine the orientations, by *linear* weighted least squares. That is LAGO's
# phase 1.
#
# **The idea in one paragraph.** Headings add up: the heading of a pose is the heading of its
# neighbour plus the measured turn between them. Around a loop the measured turns should therefore sum to
# zero (once whole turns are accounted for), and where they do not, the disagreement is noise to be shared
# out. Sharing it out in the way that best respects how certain each turn is, is a linear least-squares
# problem in the headings alone — no positions involved. Its normal matrix is a weighted graph Laplacian,
# as sparse as the graph (figure of section 4). Below, the running example's headings: added up, the turns
# drift; shared out by phase 1, they follow the truth.
#
# **Learning goals.** After this lecture you can
#
# * state eq. (8), $A^\top\theta = \delta$, and explain why it is linear only after the $2k\pi$
#   ambiguity of measured angles has been removed;
# * prove Proposition 1 (a connected graph and one known orientation give a unique phase-1 solution)
#   from the rank of the reduced incidence matrix, and check it on real data;
# * write the BLUE of eq. (13) as a cvxpy problem with named parameters, re-solve it by changing a
#   parameter, and check it against the closed form;
# * read the information matrix $A P_\delta^{-1} A^\top$ as a weighted graph Laplacian;
# * interpret the dual variable of an anchor constraint as a force;
# * verify by Monte Carlo that $\hat\theta$ is unbiased with covariance $P_\theta$.
#
# **Notation** (lecture 1's, and):
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $A$ | the **reduced** incidence matrix, $n \times m$ (the row of pose 0 deleted) | `lc.reduced_incidence(graph)` (some docstrings: "A2") |
# | $\theta$ | the $n$ unknown orientations; $\theta_0 = 0$ (pose 0 the reference) | `result.phase1.theta` (with $\theta_0$) |
# | $\delta_{\rm reg}$ | the relative orientations after the $2k\pi$ regularization (lecture 5) | `regularize(...).delta_reg` |
# | $P_\delta$ | $\mathrm{diag}(P_{\delta,ij})$, the variances of the relative orientations | `edge_uncertainty(graph).var_delta` |
# | $P_\theta$ | the covariance of the estimate $\hat\theta$, eq. (13) | the inverse of `result.phase1.info` |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)

# %%
import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph
import lago_cvx as lc
from lago_cvx.course import check, intuition_figure, paper_lago, real, running_example, setup, show
from lago_cvx import phases
from lago_cvx.errors import GraphError
from lago_cvx.graph import spanning_tree
from lago_cvx.posegraph import wrap_angle
from lago_cvx.regularization import regularize
from lago_cvx.solvers import LEAST_SQUARES, solve
from lago_cvx.synthetic import add_noise
from lago_cvx.uncertainty import edge_uncertainty
setup("02_phase1")
INTEL = real("carlone/INTEL_P_toro.graph")

# %% tags=["remove-input"]
show(intuition_figure("02"), "intuition")

# %% [markdown]
# ## 1. Eq. (8): the orientations obey a linear model — once regularized
#
# The true relative orientation of edge $(i, j)$ is $\theta_j - \theta_i$, entry $k$ of $A^\top\theta$
# ($\theta \in \mathbb R^n$ the unknown orientations, $\theta_0 = 0$). Phase 1 solves the second
# equation of eq. (7) alone:
#
# $$A^\top \theta = \delta. \tag{8}$$
#
# There is a catch: a sensor reports $\delta_{ij}$ in $[-\pi, \pi)$, so $A^\top\theta = \delta$ holds
# only **modulo $2\pi$**. Before eq. (8) is a linear model, every measurement must be lifted to
# $\delta_{\rm reg} = \delta + 2k\pi$ consistent with the others — the regularization of Section IV-E
# (`lc.regularize`, lecture 5). After it, $\delta_{\rm reg} = A^\top\theta + \epsilon_\delta$ with
# $\epsilon_\delta \sim \mathcal N(0, P_\delta)$, a textbook linear Gaussian model. We call this the
# **linearity of the regularized orientation model**. (Do not confuse it with Lemma 1, which is about
# connectivity: Lemma 1 (the pose graph is connected) is what makes this model solvable, see §2.)
#
# Two checks. On a *noiseless* robot that drives three times around a circle, the raw $\delta$ violate
# eq. (8) by multiples of $2\pi$; regularized along the odometric path (the paper's choice) they satisfy
# it exactly, and the solution is the true (unwrapped) heading. On the running example (noisy, true
# headings up to $2.5\pi$, beyond a full turn, so that some raw $\delta$ miss $A^\top\theta^{\rm true}$ by
# $2\pi$) the residual $\delta_{\rm reg} - A^\top\theta^{\rm true}$ of the regularized model is exactly the
# measurement noise: no stray $2\pi$ left — in its own measurements and in 20 fresh noise draws on its
# poses and edges, whose standardized residuals together are standard normal.

# %%
def regularized(graph, tree="odometry"):
    """δ_reg by the paper's rounding along a spanning tree (the odometric path, as in the paper), and the
    per-edge uncertainty."""
    return regularize(graph, spanning_tree(graph, tree)), edge_uncertainty(graph)

# own world: noiseless, three laps — the raw δ miss eq. (8) by exact multiples of 2π
w0 = lc.circle_world(60, laps=3, seed=0, sigma_xy=0.0, sigma_theta=0.0)
g0 = w0.graph
reg0, unc0 = regularized(g0)
A0 = lc.reduced_incidence(g0).toarray()
theta_true0 = w0.truth[1:, 2] - w0.truth[0, 2]
raw = A0.T @ theta_true0 - g0.delta
ph0 = phases.phase1_closed_form(g0, reg0.delta_reg, unc0)
print(g0, f"| true headings up to {theta_true0.max() / np.pi:.1f}π")

# %% tags=["remove-input"]
check(np.abs(raw).max() > 6 and np.allclose(raw / (2 * np.pi), np.round(raw / (2 * np.pi)), atol=1e-9),
      f"raw δ violate eq. (8) by multiples of 2π ({np.sum(np.abs(raw) > 1)} edges, up to {np.abs(raw).max() / np.pi:.0f}π)")
check(np.abs(A0.T @ theta_true0 - reg0.delta_reg).max() < 1e-9, "the regularized δ satisfy eq. (8) exactly")
check(np.abs(ph0.theta_free - theta_true0).max() < 1e-9, "and phase 1 returns the true unwrapped headings")

# %%
world = running_example()
g1, truth1 = world.graph, world.truth
A1 = lc.reduced_incidence(g1)
theta_true1 = truth1[1:, 2] - truth1[0, 2]
draw_rng, graphs, exact, standardized = np.random.default_rng(1), [g1], 0.0, []
for _ in range(20):                                    # the same poses and edges, fresh noise
    meas, info = add_noise(truth1, g1.tails, g1.heads, sigma_xy=0.1, sigma_theta=0.05, rng=draw_rng)
    graphs.append(lc.PoseGraph(g1.n_poses, g1.tails, g1.heads, meas[:, :2], meas[:, 2], info))
for graph in graphs:
    reg1, unc1 = regularized(graph)
    eps = reg1.delta_reg - A1.T @ theta_true1
    exact = max(exact, np.abs(eps - wrap_angle(graph.delta - A1.T @ theta_true1)).max())
    standardized.append(eps / np.sqrt(unc1.var_delta))
standardized = np.concatenate(standardized)
print(g1, f"| true headings up to {theta_true1.max() / np.pi:.1f}π")
print(f"{len(graphs)} noise draws, {standardized.size} standardized residuals: mean {standardized.mean():+.3f}, "
      f"std {standardized.std():.3f}")

# %% tags=["remove-input"]
raw1 = g1.delta - A1.T @ theta_true1
check(theta_true1.max() > 2 * np.pi and np.abs(raw1).max() > np.pi,
      f"running example: true headings beyond a full turn; {np.sum(np.abs(raw1) > np.pi)} raw δ miss Aᵀθ_true by 2π")
check(exact < 1e-9, "δ_reg − Aᵀθ_true is exactly the wrapped measurement noise, in every draw")
check(abs(standardized.mean()) < 4 / np.sqrt(standardized.size) and abs(standardized.std() - 1) < 0.1,
      "and it is standard normal after scaling by P_δ^(−1/2)")

# %%
fig, axs = plt.subplots(1, 2, figsize=(11, 3.6))
axs[0].plot(raw / np.pi, ".", color="tab:red", label="raw δ")
axs[0].plot((A0.T @ theta_true0 - reg0.delta_reg) / np.pi, ".", color="tab:blue", label="regularized δ")
axs[0].set_xlabel("edge")
axs[0].set_ylabel("Aᵀθ_true − δ  [units of π]")
axs[0].set_title("noiseless circle, 3 laps: eq. (8) after regularization")
axs[0].legend(fontsize=8)
grid = np.linspace(-4, 4, 200)
axs[1].hist(standardized, bins=30, density=True, color="tab:blue", alpha=0.6, label="P_δ^(−1/2)(δ_reg − Aᵀθ_true)")
axs[1].plot(grid, np.exp(-grid**2 / 2) / np.sqrt(2 * np.pi), "k", label="standard normal")
axs[1].set_title(f"running example, {len(graphs)} noise draws: a linear Gaussian model")
axs[1].legend(fontsize=8)
show(fig, "linear_model")

# %% [markdown]
# ## 2. Proposition 1 — a unique phase-1 solution
#
# **Proposition 1 (existence of the phase-1 solution).** Phase 1 has a unique solution if the graph is
# connected and one orientation is known. *Proof.* Every column of the full incidence matrix has one
# $+1$ and one $-1$, so $\mathbf 1^\top A_{\rm full} = 0$: rank at most $n$. More precisely $A_{\rm
# full}^\top v = 0$ means $v_i = v_j$ across every edge, so $v$ is constant on each connected component:
# $\operatorname{rank} A_{\rm full} = (n + 1) - c$ with $c$ components. For a connected graph ($c = 1$,
# Lemma 1) the rank is $n$, and deleting the row of the known orientation leaves the $n$ remaining rows
# independent: the reduced $A$ has full rank $n$. Then for any $x \neq 0$,
# $x^\top A P_\delta^{-1} A^\top x = \|P_\delta^{-1/2} A^\top x\|^2 > 0$: $A P_\delta^{-1} A^\top$ is
# positive definite, hence invertible, and eq. (13) below has one solution.
#
# Both hypotheses matter. Without a known orientation, $A_{\rm full} P_\delta^{-1} A_{\rm full}^\top$
# is singular ($\theta + c\mathbf 1$ fits as well as $\theta$): the whole map may turn. Without
# connectivity, each component turns on its own. We check the ranks, the smallest eigenvalue of
# $A P_\delta^{-1} A^\top$ and what the package does, on the running example and on two disconnected
# graphs cut out of it.

# %%
def proposition1(graph):
    """(c, rank of the full A, rank of the reduced A, smallest eigenvalue of A P_δ⁻¹ Aᵀ, of the full one)."""
    full = lc.incidence_matrix(graph).toarray()
    reduced = lc.reduced_incidence(graph).toarray()
    w = 1.0 / edge_uncertainty(graph).var_delta
    return (lc.connected_components(graph)[0], np.linalg.matrix_rank(full), np.linalg.matrix_rank(reduced),
            np.linalg.eigvalsh((reduced * w) @ reduced.T).min(), np.linalg.eigvalsh((full * w) @ full.T).min())
base = running_example().graph
cases = {
    "running example": base,
    "running example, all edges of pose 7 removed": base.subgraph_edges((base.tails != 7) & (base.heads != 7)),
    "running example cut into poses 0–29 and 30–59": base.subgraph_edges((base.tails < 30) == (base.heads < 30)),
}
print(f"{'graph':46s} n+1  c  rank A_full  rank A  λ_min(A P⁻¹ Aᵀ)  λ_min(full)  lago()")
rows = []
for name, graph in cases.items():
    c, r_full, r_red, lam, lam_full = proposition1(graph)
    try:
        lc.lago(graph)
        verdict = "solved"
    except GraphError:
        verdict = "refused"
    print(f"{name:46s} {graph.n_poses:3d} {c:2d} {r_full:11d} {r_red:7d} {lam:16.2e} {lam_full:12.1e}  {verdict}")
    rows.append((graph.n_poses - 1, c, r_full, r_red, lam, lam_full, verdict))

# %% tags=["remove-input"]
for n, c, r_full, r_red, lam, lam_full, verdict in rows:
    check(r_full == n + 1 - c and r_red == n + 1 - c, f"rank A = n + 1 − c = {n + 1 - c}")
    check((lam > 1e-8) == (c == 1) == (verdict == "solved") and abs(lam_full) < 1e-8,
          "A P_δ⁻¹ Aᵀ ≻ 0 exactly when connected; never without a known orientation")

# %% [markdown]
# On a real graph, a dense rank is slow; the equivalent test is the smallest eigenvalue of the sparse
# matrix $A P_\delta^{-1} A^\top$ (shift-invert Lanczos). We also cut the Intel graph into the poses
# before and after the middle of the run, removing the edges between the two parts.

# %%
if INTEL is not None:
    def lambda_min(graph):
        A = lc.reduced_incidence(graph)
        info = (A @ sp.diags(1.0 / edge_uncertainty(graph).var_delta) @ A.T).tocsc()
        return spla.eigsh(info, k=1, sigma=-1.0, which="LM", return_eigenvectors=False)[0]
    half = INTEL.n_poses // 2
    cut = INTEL.subgraph_edges((INTEL.tails < half) == (INTEL.heads < half))
    lam, lam_cut = lambda_min(INTEL), lambda_min(cut)
    print(f"Intel: {lc.connected_components(INTEL)[0]} component, λ_min = {lam:.3e}; "
          f"cut at pose {half}: {lc.connected_components(cut)[0]} components, λ_min = {lam_cut:.1e}")

# %% tags=["remove-input"]
if INTEL is not None:
    check(lam > 0, "Proposition 1 on Intel: A P_δ⁻¹ Aᵀ is positive definite")
    check(abs(lam_cut) < 1e-6 * lam, "cut in two: singular")

# %% [markdown]
# ## 3. Eq. (13): the BLUE, as a cvxpy problem and in closed form
#
# Model eq. (8) is linear with Gaussian noise of covariance $P_\delta$, so its best linear unbiased
# estimator (BLUE, also the maximum-likelihood estimate) is the weighted least-squares solution, eq. (13):
#
# $$\hat\theta = \arg\min_\theta \big\|P_\delta^{-1/2}(A^\top\theta - \delta_{\rm reg})\big\|^2
#   = (A P_\delta^{-1} A^\top)^{-1} A P_\delta^{-1} \delta_{\rm reg}, \qquad
#   P_\theta = (A P_\delta^{-1} A^\top)^{-1}. \tag{13}$$
#
# We write the left-hand form in cvxpy, for the running example, with *named* objects: the variable `θ`,
# the data `Aᵀ` and `δ_reg`, and a **parameter** `w_δ` holding the weights $P_\delta^{-1/2}$, so that the
# printed problem reads like the equation (cvxpy prints `sum_squares(x)` as `quad_over_lin(x, 1.0)`, i.e.
# $\sum x^2 / 1$). Clarabel solves it; the package's `phase1_closed_form` computes the right-hand form
# with a sparse factorization.
#
# **How close should they be?** Clarabel stops when the duality gap is below
# `tol_gap_abs + tol_gap_rel·|f|` (the package's settings `lago_cvx.solvers.LEAST_SQUARES`). The cost
# is strongly convex with Hessian $2AP_\delta^{-1}A^\top$, so a cost excess $\Delta f$ means
# $\|\theta - \hat\theta\| \le \sqrt{\Delta f / \lambda_{\min}(AP_\delta^{-1}A^\top)}$: that bound, from
# the solver's own tolerances, is what we require.

# %%
world = running_example()
g = world.graph
reg, unc = regularized(g)
A = lc.reduced_incidence(g)
n, m = A.shape
θ = cp.Variable(n, name="θ")
w_δ = cp.Parameter(m, nonneg=True, name="w_δ")
At = cp.Constant(A.T.tocsr(), name="Aᵀ")
δ_reg = cp.Constant(reg.delta_reg, name="δ_reg")
phase1 = cp.Problem(cp.Minimize(cp.sum_squares(cp.multiply(w_δ, At @ θ - δ_reg))))
print(phase1)

def closed_form(weights):
    """Eq. (13) with dense algebra, for weights w = P_δ^(-1/2): θ̂ and P_θ⁻¹."""
    info = (A.multiply(weights**2) @ A.T).toarray()
    return np.linalg.solve(info, A @ (weights**2 * reg.delta_reg)), info

def agreement(theta_cvx, weights):
    """|θ_cvx − θ̂| and the bound the solver's gap tolerance allows (strong convexity)."""
    theta_hat, info = closed_form(weights)
    f_hat = np.sum((weights * (A.T @ theta_hat - reg.delta_reg)) ** 2)
    gap = LEAST_SQUARES.tol_gap_abs + LEAST_SQUARES.tol_gap_rel * f_hat
    return np.abs(theta_cvx - theta_hat).max(), np.sqrt(gap / np.linalg.eigvalsh(info)[0])
w_δ.value = np.sqrt(1.0 / unc.var_delta)
solve(phase1)
package = phases.phase1_closed_form(g, reg.delta_reg, unc)
err, bound = agreement(θ.value, w_δ.value)
print(g, f"| status {phase1.status}")

# %% tags=["remove-input"]
check(np.abs(package.theta_free - closed_form(w_δ.value)[0]).max() < 1e-9,
      "lago_cvx.phases.phase1_closed_form = eq. (13)")

# %%
pkg_problem, pkg_theta = phases.phase1_problem(g, reg.delta_reg, unc)
solve(pkg_problem)

# %% tags=["remove-input"]
check(phase1.is_dpp(), "the problem is DPP: changing w_δ.value re-solves without rebuilding it")
check(err <= bound, f"cvxpy = eq. (13) in closed form: |Δθ| = {err:.1e} ≤ {bound:.1e} (the solver's tolerance)")
check(np.abs(np.delete(pkg_theta.value, 0) - θ.value).max() <= 2 * bound, "and the package's own cvxpy builder, phase1_problem, agrees")

# %% [markdown]
# **A sweep without rebuilding.** How much should loop closures count? Multiply their weights by a
# factor $s$ (their standard deviation by $1/\sqrt{s}$... in weights, $w \to \sqrt{s}\,w$) and re-solve by
# changing `w_δ.value` only. At $s \to 0$ the loop closures are ignored and $\hat\theta$ is dead
# reckoning along the odometry; as $s$ grows they pull the trajectory into agreement. Each re-solve is
# checked against the closed form, and the uncertainty $\operatorname{tr} P_\theta$ drops as the loop
# closures gain weight.

# %%
loop = ~g.is_odometric
scales = [1e-6, 1e-4, 1e-2, 1.0, 1e2]
last, traces, agree = [], [], []
for s in scales:
    w_δ.value = np.sqrt(1.0 / unc.var_delta) * np.where(loop, np.sqrt(s), 1.0)
    solve(phase1)
    err, bound = agreement(θ.value, w_δ.value)
    agree.append((s, err, bound))
    last.append(θ.value[-1])
    traces.append(np.trace(np.linalg.inv(closed_form(w_δ.value)[1])))
odo = g.is_odometric
dead_reckoning = np.sum(np.where(g.heads > g.tails, 1.0, -1.0)[odo] * reg.delta_reg[odo])  # θ of the last pose
print("θ̂ of the last pose:", np.round(last, 4), f"| dead reckoning: {dead_reckoning:.4f}")

# %% tags=["remove-input"]
for s, err, bound in agree:
    check(err <= bound, f"s = {s:g}: cvxpy = closed form (|Δθ| = {err:.1e})")
check(all(np.diff(traces) < 0), "tr P_θ decreases as the loop closures gain weight")

# %%
fig, axs = plt.subplots(1, 2, figsize=(11, 3.6))
axs[0].semilogx(scales, last, "o-")
axs[0].axhline(dead_reckoning, color="0.5", ls="--", label="dead reckoning")
axs[0].axhline(world.truth[-1, 2] - world.truth[0, 2], color="k", ls=":", label="truth")
axs[0].set_xlabel("weight factor s of the loop closures")
axs[0].set_ylabel("θ̂ of the last pose [rad]")
axs[0].legend(fontsize=8)
axs[1].loglog(scales, traces, "o-", color="tab:red")
axs[1].set_xlabel("weight factor s of the loop closures")
axs[1].set_ylabel("tr P_θ [rad²]")
fig.suptitle(f"One cvxpy problem, {len(scales)} solves: only the parameter w_δ changed")
show(fig, "weight_sweep")
w_δ.value = np.sqrt(1.0 / unc.var_delta)

# %% tags=["remove-input"]
check(abs(last[0] - dead_reckoning) < 1e-2 * abs(dead_reckoning) + 0.01, "with s → 0 phase 1 is dead reckoning")

# %% [markdown]
# ## Exercise 1 — $P_\theta$ of a chain
#
# *Derive.* For a path $0 \to 1 \to \dots \to n$ (odometry only, variances $\sigma_1^2, \dots, \sigma_n^2$)
# anchored at pose 0, derive $P_\theta$ in closed form: show that $(P_\theta)_{ij} = \sum_{k \le
# \min(i, j)} \sigma_k^2$ (the orientation error is a random walk). Write your closed form as
# `chain_covariance(sigma)`; the check compares it with the inverse of $A P_\delta^{-1} A^\top$ on two chains.
#
# **Hint.** With pose 0 anchored, the reduced $A$ of a chain is bidiagonal and its inverse is triangular, full of
# ones.

# %%
# your solution here: fill in the body of chain_covariance, then run the cell (check_chain_covariance tests it)
from lago_cvx.exercises import check_chain_covariance

def chain_covariance(sigma):
    """P_θ (n, n) of the chain 0 → … → n whose edge k has standard deviation sigma[k]."""
    raise NotImplementedError
check_chain_covariance(chain_covariance)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. On the chain the reduced A is n × n upper bidiagonal, Aᵀθ = (θ_k − θ_{k−1})_k, so
# P_θ = (A P_δ⁻¹ Aᵀ)⁻¹ = A⁻ᵀ P_δ A⁻¹ with A⁻ᵀ the summation matrix (θ_i = Σ_{k≤i} δ_k, dead reckoning):
# (P_θ)_ij = Σ_{k ≤ min(i,j)} σ_k² — the heading error is a random walk along the path.
import numpy as np
from lago_cvx.exercises import check_chain_covariance

def chain_covariance(sigma):
    n = len(sigma)
    cum = np.cumsum(np.asarray(sigma) ** 2)
    return cum[np.minimum.outer(np.arange(n), np.arange(n))]
check_chain_covariance(chain_covariance).require()

# %% [markdown]
# ## 4. The information matrix is a weighted graph Laplacian
#
# $(A P_\delta^{-1} A^\top)_{uv} = \sum_k A_{uk}A_{vk}/P_{\delta,k}$: on the diagonal, the summed weights
# $1/P_{\delta,k}$ of the edges at pose $u$; off the diagonal, minus the weights of the edges joining
# $u$ and $v$ (zero if none). That is the Laplacian $L = D - W$ of the graph weighted by orientation
# information, with the row and column of pose 0 deleted (a *grounded* Laplacian). It is as sparse as
# the graph; its inverse $P_\theta$ is not (§4 of lecture 3 says exactly when it is full). We build $L$
# independently with `scipy.sparse.csgraph.laplacian` and compare with the package's `Phase1.info`.

# %%
def grounded_laplacian(graph, var_delta):
    weights = sp.coo_matrix((1.0 / var_delta, (graph.tails, graph.heads)), shape=(graph.n_poses,) * 2).tocsr()
    L = csgraph.laplacian((weights + weights.T).tocsr()).tocsr()
    return L[1:][:, 1:]

laplacian = grounded_laplacian(g, unc.var_delta)

# %% tags=["remove-input"]
check(abs(package.info - laplacian).max() < 1e-12 * abs(laplacian).max(),
      "Phase1.info = A P_δ⁻¹ Aᵀ = the grounded weighted Laplacian")

# %%
P_theta = np.linalg.inv(package.info.toarray())
density_info = package.info.nnz / n**2
density_cov = np.mean(np.abs(P_theta) > 1e-12 * np.abs(P_theta).max())

fig, axs = plt.subplots(1, 2, figsize=(11, 5.2))
axs[0].spy(package.info, markersize=1.5)
axs[0].set(xlabel="pose (column)", ylabel="pose (row)")
axs[0].set_title(f"information A P_δ⁻¹ Aᵀ\n{density_info:.1%} non-zero", pad=24)
im = axs[1].imshow(np.log10(np.abs(P_theta)), cmap="viridis")
axs[1].set(xlabel="pose (column)", ylabel="pose (row)")
axs[1].set_title(f"covariance P_θ, log₁₀ |entries|\n{density_cov:.0%} non-zero", pad=24)
fig.colorbar(im, ax=axs[1], shrink=0.8)
fig.suptitle(f"Phase 1 on the running example ({n + 1} poses, {m} edges)", y=1.04)
show(fig, "information")

# %% tags=["remove-input"]
check(density_info < 0.1 and density_cov > 0.9,
      f"information {density_info:.1%} non-zero, covariance P_θ {density_cov:.0%} non-zero")

# %% [markdown]
# ## 5. The anchor as a constraint, and what its dual variable means
#
# Deleting the row of pose 0 is one way to say "$\theta_0$ is known". Another keeps all $n + 1$
# orientations and adds the constraint $\theta_0 = 0$; its Lagrange multiplier is the *force* the anchor
# must exert. Think of each edge as a torsion spring of stiffness $1/P_{\delta,k}$ between two poses:
# the cost is twice the stored energy and its gradient with respect to $\theta_i$ is the net torque on
# pose $i$. With **one** anchor the springs can always relax completely in the free directions — the
# cost does not change if all orientations turn together ($\mathbf 1^\top A_{\rm full} = 0$) — so the
# anchor holds nothing: **its multiplier is zero**. It only fixes the gauge.
#
# With a **second** known orientation — say a compass tells $\theta_k = c$ — the springs are put under
# tension, and the two multipliers are equal and opposite (the torques balance, again because
# $\mathbf 1^\top A_{\rm full} = 0$). Sensitivity analysis says more: the multiplier of $\theta_k = c$ is
# the derivative of the optimal cost with respect to $c$ (up to cvxpy's sign convention, which the cell
# settles). We check it by re-solving with the parameter `c` moved by a small step.

# %%
A_full = cp.Constant(lc.incidence_matrix(g).T.tocsr(), name="A_fullᵀ")
θ_all = cp.Variable(n + 1, name="θ⁺")
k = n // 2
c = cp.Parameter(name="c")
anchor = θ_all[0] == 0
compass = θ_all[k] == c
spring = cp.sum_squares(cp.multiply(w_δ, A_full @ θ_all - δ_reg))
one_anchor = cp.Problem(cp.Minimize(spring), [anchor])
two_anchors = cp.Problem(cp.Minimize(spring), [anchor, compass])
print(two_anchors)

solve(one_anchor)
err, bound = agreement(θ_all.value[1:], w_δ.value)
one_anchor_force = float(anchor.dual_value)

theta_hat_k = θ_all.value[k]                                         # phase 1's θ̂_k (one anchor)
c_values = theta_hat_k + np.linspace(-0.05, 0.05, 9)
costs, forces = [], []
for value in c_values:
    c.value = value
    solve(two_anchors)
    costs.append(two_anchors.value)
    forces.append((float(anchor.dual_value), float(compass.dual_value)))
forces = np.array(forces)
slope = np.gradient(np.array(costs), c_values)
sign = np.sign(np.sum(slope[1:-1] * forces[1:-1, 1]))
print("c − θ̂_k:", np.round(c_values[::2] - theta_hat_k, 3), "| multipliers (anchor, compass):\n", np.round(forces[::2], 3))
print(f"cvxpy's sign convention here: d(optimal cost)/dc = {sign:+.0f} × (multiplier of θ_k = c)")

# %% tags=["remove-input"]
check(abs(one_anchor_force) < 1e-6 * np.abs(forces).max(), f"one anchor holds no force: multiplier {one_anchor_force:.1e}")
check(np.abs(forces.sum(axis=1)).max() < 1e-6 * np.abs(forces).max(), "the two anchors hold equal and opposite forces")
check(np.abs(np.abs(slope[1:-1]) - np.abs(forces[1:-1, 1])).max() < 1e-3 * np.abs(forces).max(),
      "|multiplier of θ_k = c| = |d(optimal cost)/dc|")
check(abs(forces[4, 1]) < 1e-3 * np.abs(forces).max(), "and it vanishes when c = θ̂_k: the compass agrees with phase 1")

# %%
fig, ax = plt.subplots(figsize=(6.5, 3.8))
ax.plot(c_values - theta_hat_k, costs, "o-", label="optimal cost with θ_k = c")
dc = np.array([-0.012, 0.012])
for value, cost, force in zip(c_values[::4], costs[::4], forces[::4, 1]):
    ax.plot(value - theta_hat_k + dc, cost + sign * force * dc, "r-", lw=2)
ax.plot([], [], "r-", lw=2, label="tangent with slope ± the compass multiplier")
ax.set_xlabel("c − θ̂_k [rad]")
ax.set_ylabel("optimal cost")
ax.set_title(f"A second known orientation (pose {k}): the dual variable is the force")
ax.legend(fontsize=8)
show(fig, "anchor_dual")

# %% tags=["remove-input"]
check(err <= bound, f"θ₀ = 0 as a constraint gives the same θ̂ as deleting the row (|Δθ| = {err:.1e})")

# %% [markdown]
# ## 6. Monte Carlo: $\hat\theta$ is unbiased with covariance $P_\theta$
#
# Eq. (13) is linear in $\delta_{\rm reg}$, so $\hat\theta$ is unbiased and has covariance exactly
# $P_\theta$ — provided the regularization picks the right $2k\pi$. We test the whole chain as a robot
# would meet it: on a fixed graph (8 poses, 14 edges, true orientations over several turns, a different
# standard deviation for every edge) we draw noise, wrap the measured angles to $[-\pi, \pi)$,
# regularize along a fixed spanning tree, and apply eq. (13) — with fixed weights a single matrix
# $K = (A P_\delta^{-1} A^\top)^{-1} A P_\delta^{-1}$, checked against `phase1_closed_form` — 2000 times. Errors are compared
# modulo $2\pi$ (a whole subtree may be lifted by $2\pi$ — the same orientations). A sample covariance
# of $N$ Gaussian draws has relative Frobenius error about $\sqrt{((\operatorname{tr}P)^2 +
# \|P\|_F^2)/N}/\|P\|_F$; we allow three times that, and 4.5 standard errors for the mean.

# %%
# own world: 8 poses, so that 2000 draws estimate the 7 × 7 covariance P_θ well
mc_world = lc.random_graph(8, 14, seed=3, sigma_xy=0.0, sigma_theta=0.0)
tails, heads, truth = mc_world.graph.tails, mc_world.graph.heads, mc_world.truth
mc_rng = np.random.default_rng(11)
sig = mc_rng.uniform(0.005, 0.03, tails.size)
info_mc = np.zeros((tails.size, 3, 3))
info_mc[:, 0, 0] = info_mc[:, 1, 1] = 1 / 0.05**2
info_mc[:, 2, 2] = 1 / sig**2
d_true = truth[heads, 2] - truth[tails, 2]

def graph_with(delta):
    return lc.PoseGraph(8, tails, heads, mc_world.graph.delta_l, delta, info_mc)

g_mc = graph_with(wrap_angle(d_true))
tree_mc, unc_mc = spanning_tree(g_mc, "bfs"), edge_uncertainty(g_mc)
ph_true = phases.phase1_closed_form(g_mc, regularize(g_mc, tree_mc).delta_reg, unc_mc)
P_theta_mc = np.linalg.inv(ph_true.info.toarray())
A_mc = lc.reduced_incidence(g_mc).toarray()
K = np.linalg.solve((A_mc / sig**2) @ A_mc.T, A_mc / sig**2)           # eq. (13) as a matrix: θ̂ = K δ_reg
N_MC = 2000
errs = np.empty((N_MC, 7))
for s in range(N_MC):
    g_s = graph_with(wrap_angle(d_true + sig * mc_rng.standard_normal(tails.size)))
    delta_reg = regularize(g_s, tree_mc).delta_reg
    errs[s] = wrap_angle(K @ delta_reg - ph_true.theta_free)
    if s == 0:
        fast_path = np.abs(K @ delta_reg - phases.phase1_closed_form(g_s, delta_reg, unc_mc).theta_free).max()
zscore = errs.mean(axis=0) / np.sqrt(np.diag(P_theta_mc) / N_MC)
S = np.cov(errs, rowvar=False)
rel = np.linalg.norm(S - P_theta_mc) / np.linalg.norm(P_theta_mc)
expected = np.sqrt((np.trace(P_theta_mc) ** 2 + np.linalg.norm(P_theta_mc) ** 2) / N_MC) / np.linalg.norm(P_theta_mc)
print(g_mc, f"| σ_δ from {sig.min():.3f} to {sig.max():.3f} rad")
print("mean error / standard error per pose:", np.round(zscore, 2))

# %% tags=["remove-input"]
check(np.abs(zscore).max() < 4.5, "θ̂ is unbiased (every mean error within 4.5 standard errors)")

# %%
fig, axs = plt.subplots(1, 2, figsize=(11, 4))
i1, i2 = 2, 5
axs[0].plot(errs[:, i1], errs[:, i2], ".", ms=2, color="0.5", label=f"{N_MC} samples")
C2 = P_theta_mc[np.ix_([i1, i2], [i1, i2])]
vals, vecs = np.linalg.eigh(C2)
t = np.linspace(0, 2 * np.pi, 200)
ellipse = 3 * vecs @ (np.sqrt(vals)[:, None] * np.vstack([np.cos(t), np.sin(t)]))
axs[0].plot(*ellipse, "tab:blue", label="3σ ellipse of P_θ")
axs[0].set_xlabel(f"error of θ̂ at pose {i1 + 1} [rad]")
axs[0].set_ylabel(f"error of θ̂ at pose {i2 + 1} [rad]")
axs[0].set_aspect("equal", adjustable="datalim")
axs[0].legend(fontsize=8)
axs[1].bar(np.arange(1, 8) - 0.2, np.sqrt(np.diag(S)), 0.4, label="sample std")
axs[1].bar(np.arange(1, 8) + 0.2, np.sqrt(np.diag(P_theta_mc)), 0.4, label="√diag P_θ, eq. (13)")
axs[1].set_xlabel("pose")
axs[1].set_ylabel("std of θ̂ [rad]")
axs[1].legend(fontsize=8)
fig.suptitle("Monte Carlo of phase 1 (noise → wrap → regularize → eq. (13))")
show(fig, "montecarlo")

# %% tags=["remove-input"]
check(fast_path < 1e-9, "the loop's θ̂ = K δ_reg is the package's phase1_closed_form")
check(rel < 3 * expected, f"sample covariance = P_θ: ‖S − P_θ‖/‖P_θ‖ = {rel:.3f} (sampling level {expected:.3f})")

# %% [markdown]
# ### Try it: the BLUE against the noise
# Drag σ_θ: phase 1's errors stay inside the band of Proposition 1's $P_\theta$ while dead reckoning drifts out of it;
# from σ_θ ≈ 0.2 rad, wrong $2k\pi$ corrections (lecture 5) throw the estimate out of its own band: the covariance
# assumes the integers right.

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.phase1_blue, "try_blue", sigma_theta=(0.01, 0.4, 0.01, 0.05))

# %% [markdown]
# **Summary.** After the $2k\pi$ regularization, the relative orientations obey the linear model
# eq. (8); connectivity and one known orientation make it uniquely solvable (Proposition 1); its BLUE
# eq. (13) is one sparse solve with a grounded weighted Laplacian. cvxpy states the same problem in a
# line, with parameters to re-solve and multipliers that are forces. Lecture 3 uses $\hat\theta$ and
# $P_\theta$ to bring the positions into the global frame.

# %% [markdown]
# ## Exercise 2 — A compass instead of an anchor
#
# *Implement.* Replace the anchor by absolute heading measurements (a compass) $c$ on the poses $K$, with
# variance $\sigma_c^2$: keep all $n + 1$ orientations as unknowns and minimize
# $\|P_\delta^{-1/2}(A^\top\theta^+ - \delta_{\rm reg})\|^2 + \|(\theta^+_K - c)/\sigma_c\|^2$ ($A$ the full incidence
# matrix here). Write `compass_orientations(...)` (closed form with an augmented design matrix, or cvxpy with a
# parameter for $c$); the check tests the optimality condition with one and with three readings. Why is one
# reading enough for a unique solution (Proposition 1 in another guise)?
#
# **Hint.** Each compass reading adds one row $e_i^\top$ to the design matrix, with weight $1/\sigma_c$.

# %%
# your solution here: fill in the body of compass_orientations, then run the cell (check_compass tests it)
from lago_cvx.exercises import check_compass, compass_case
graph, delta_reg, info_delta = compass_case()      # the data the check uses

def compass_orientations(graph, delta_reg, info_delta, K, c, sigma_c):
    """θ⁺ (n + 1,) minimizing the cost above; K a list of pose indices, c (len(K),) the readings."""
    raise NotImplementedError

check_compass(compass_orientations)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. Unknowns: all n + 1 orientations. With D = [A, E_K] (E_K the columns e_k, k ∈ K) and
# weights w = [P_δ⁻¹, 1/σ_c²], θ⁺ = (D diag(w) Dᵀ)⁻¹ D diag(w) [δ_reg; c]. D diag(w) Dᵀ is the graph's Laplacian
# plus Σ_k e_k e_kᵀ/σ_c²: positive definite for a connected graph with one reading or more — Proposition 1 with
# a soft known orientation instead of a hard anchor.
import numpy as np
import lago_cvx as lc
from lago_cvx.exercises import check_compass

def compass_orientations(graph, delta_reg, info_delta, K, c, sigma_c):
    D = np.hstack([lc.incidence_matrix(graph).toarray(), np.eye(graph.n_poses)[:, K]])
    w = np.concatenate([info_delta, np.full(len(K), 1 / sigma_c**2)])
    return np.linalg.solve((D * w) @ D.T, D @ (w * np.concatenate([delta_reg, c])))

check_compass(compass_orientations).require()

# %% [markdown]
# ## Exercise 3 — Which loop closure helps most?
#
# *Explore.* Start from the odometry alone and add one loop closure at a time: by how much does it reduce
# $\operatorname{tr} P_\theta$? Write `trace_drop(P0, e, variance)` — the drop when an edge with reduced incidence
# column $e$ and variance $\sigma^2$ is added to the information $P_0^{-1}$ — without inverting a new matrix; the
# check compares it with the exact drop for 15 loop closures of a 200-pose Manhattan world. Which loop
# closure helps most, and how does that relate to the length of the cycle it closes?
#
# **Hint.** Adding the edge is a rank-one update of the information: Sherman–Morrison.

# %%
# your solution here: fill in the body of trace_drop, then run the cell (check_trace_drop tests it)
from lago_cvx.exercises import check_trace_drop

def trace_drop(P0, e, variance):
    """tr P0 − tr (P0⁻¹ + e eᵀ / variance)⁻¹ (a float)."""
    raise NotImplementedError

check_trace_drop(trace_drop)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. Adding an edge e = e_j − e_i with variance σ² is a rank-one update of the information,
# so by Sherman–Morrison tr P_new = tr P₀ − ‖P₀e‖² / (σ² + eᵀP₀e). On a chain eᵀP₀e = Σ σ_k² over the
# odometric edges between i and j: long cycles help most — but ‖P₀e‖² also grows with the distance from the anchor.
import numpy as np
from lago_cvx.exercises import check_trace_drop

def trace_drop(P0, e, variance):
    Pe = P0 @ e
    return float(Pe @ Pe / (variance + e @ Pe))

check_trace_drop(trace_drop).require()
