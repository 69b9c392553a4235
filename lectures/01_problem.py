# %% [markdown]
# # Lecture 1 — The problem: planar pose-graph SLAM as a least-squares problem
#
# Section III of Carlone, Aragues, Castellanos, Bona, *A Linear Approximation for Graph-based
# Simultaneous Localization and Mapping* (RSS 2011) {cite}`carlone2011rss`, derived step by step and checked
# numerically with the package `lago_cvx`.
#
# **The idea in one paragraph.** A robot that drives and looks around measures only *relative* motions:
# how far it moved and turned between two poses, and, when it recognises a place, where it is relative to
# an earlier pose. Each measurement is an edge of a graph whose nodes are the poses. The map is the set of
# poses that agrees best with all edges at once — a weighted least-squares problem. It would be linear if
# the headings were known, because a relative position is measured in the frame of the robot and must be
# turned into the map's frame by the unknown heading: that rotation is the one non-linearity of the
# problem, and the rest of the course is about getting around it. The figure below is the course's running
# example, a 60-pose Manhattan world: the truth with its edges, and what composing the odometry alone gives.
#
# **Learning goals.** After this lecture you can
#
# * compute a relative pose with the compounding of eq. (1), and say what the package's `between` and
#   `compose` do;
# * derive the cost eq. (3) from the likelihood eq. (2), and tell the χ² convention of the package (no
#   factor ½) from others by a computation, not by a footnote;
# * write the cost with the split residual of eq. (4), with incidence matrices as in eqs. (5)–(6), and
#   recognise when the block-diagonal noise of eq. (5) is an approximation (Remark 2);
# * explain why the system eq. (7) *looks* linear and is not;
# * build the incidence matrices $A$, $A_2 = A \otimes I_2$ and their reduced forms, and map them to the
#   package;
# * argue, with Lemma 1, that every single-robot pose graph is connected;
# * show that the cost is non-convex and that a local solver lands in different minima from different
#   starts.
#
# **Notation (the paper's, used in every lecture).**
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $n + 1$, $m$ | poses $p_0, \dots, p_n$ (pose 0 the reference, $p_0 = [0\ 0\ 0]^\top$); edges | `graph.n_poses`, `graph.n_edges` |
# | $p_i = [p_i^\top\ \theta_i]^\top$ | pose $i$: position $p_i \in \mathbb R^2$, heading $\theta_i$ | row $i$ of `poses`, $(n+1)\times3$ |
# | $(i, j)$, $k$ | edge $k$ from its tail $i$ to its head $j$ | `graph.tails[k]`, `graph.heads[k]` |
# | $\xi_{ij} = [\Delta^{l\top}_{ij}\ \delta_{ij}]^\top$ | its measurement: $j$'s position in the *local* frame of $i$, the relative orientation | `graph.delta_l[k]`, `graph.delta[k]` |
# | $\Delta^l$, $\delta$ | the measurements stacked over the edges | `graph.delta_l` $(m, 2)$, `graph.delta` $(m,)$ |
# | $P_{ij}$, $P_{ij}^{-1}$ | the edge's covariance and information, $3\times3$ | `graph.covariance`, `graph.information` |
# | $R(\theta)$; $A$, $A_2 = A\otimes I_2$ | a rotation; the incidence matrices (section 3) | `rot2`; `lc.incidence_matrix`, `lc.reduced_incidence` |
# | $f$ | the cost eq. (3), χ² without a factor ½ | `lc.chi2` |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)

# %%
import matplotlib.pyplot as plt
import numpy as np
from scipy.stats import chi2 as chi2_law
from scipy.stats import multivariate_normal
import lago_cvx as lc
from lago_cvx.course import (S, check, compounding_figure, incidence_figure, intuition_figure, real,
                             running_example, setup, show, two_minima_figure)
from lago_cvx.datasets import REFERENCE_CHI2
from lago_cvx.errors import GraphError
from lago_cvx.phases import design_matrix
from lago_cvx.posegraph import between, compose, rot2, wrap_angle
from lago_cvx.refinement import odometry_guess, refine
from lago_cvx.synthetic import add_noise
setup("01_problem")
rng = np.random.default_rng(0)

# %% tags=["remove-input"]
show(intuition_figure("01"), "intuition")

# %% [markdown]
# ## 1. Pose compounding, eq. (1)
#
# A pose is a rigid motion of the plane. Pose $j$ seen from pose $i$ — what a sensor on the robot at
# $i$ measures — is the pose compounding of eq. (1):
#
# $$p_j \ominus p_i = \begin{bmatrix} R_i^\top (p_j - p_i) \\ \theta_j - \theta_i \end{bmatrix},
# \qquad R_i = R(\theta_i) = \begin{bmatrix}\cos\theta_i & -\sin\theta_i\\ \sin\theta_i & \cos\theta_i\end{bmatrix}.
# \tag{1}$$
#
# Its inverse operation puts a relative pose $t = [t_p^\top\ t_\theta]^\top$ back on top of pose $i$:
# $p_i \oplus t = [p_i + R_i t_p;\ \theta_i + t_\theta]$. In `lago_cvx.posegraph`, `between(a, b)` is
# $b \ominus a$ and `compose(a, t)` is $a \oplus t$. Angles are real numbers, never wrapped inside these
# functions, so the identities below hold exactly, not only modulo $2\pi$:
#
# * `between` undoes `compose`: $(p_i \oplus t) \ominus p_i = t$, and $p_i \oplus (p_j \ominus p_i) = p_j$;
# * relative poses chain: $(p_k \ominus p_i) = (p_j \ominus p_i) \oplus (p_k \ominus p_j)$ — this is
#   why the measurements along a path can be composed into a trajectory (dead reckoning).
#
# We check eq. (1) against `between` and the identities on 10 000 random triples of poses whose angles
# range over several turns.

# %%
N = 10_000

def random_poses(k):
    return np.column_stack([rng.uniform(-50, 50, (k, 2)), rng.uniform(-3 * np.pi, 3 * np.pi, k)])
pi_, pj_, pk_, t_ = random_poses(N), random_poses(N), random_poses(N), random_poses(N)
eq1 = np.column_stack([np.einsum("kba,kb->ka", rot2(pi_[:, 2]), pj_[:, :2] - pi_[:, :2]), pj_[:, 2] - pi_[:, 2]])
errors = {
    "between(p_i, p_j) = eq. (1)": between(pi_, pj_) - eq1,
    "(p_i ⊕ t) ⊖ p_i = t": between(pi_, compose(pi_, t_)) - t_,
    "p_i ⊕ (p_j ⊖ p_i) = p_j": compose(pi_, between(pi_, pj_)) - pj_,
    "p_k ⊖ p_i = (p_j ⊖ p_i) ⊕ (p_k ⊖ p_j)": between(pi_, pk_) - compose(between(pi_, pj_), between(pj_, pk_)),
}

# %% tags=["remove-input"]
for claim, err in errors.items():
    check(np.abs(err).max() < 1e-9, f"{claim}   (max error {np.abs(err).max():.1e} over {N} triples)")

# %% [markdown]
# The figure shows one measurement: pose $j$ (red) seen from pose $i$ (blue). The relative position
# $\Delta^l_{ij} = R_i^\top (p_j - p_i)$ is the same arrow $p_j - p_i$, written in the axes of $i$.

# %%
p_i, p_j = np.array([1.0, 0.5, np.deg2rad(35)]), np.array([3.2, 2.4, np.deg2rad(110)])
rel = between(p_i, p_j)
show(compounding_figure(p_i, p_j), "compounding")

# %% tags=["remove-input"]
check(abs(np.linalg.norm(rel[:2]) - np.linalg.norm(p_j[:2] - p_i[:2])) < 1e-12,
      "a rotation keeps lengths: |Δˡ_ij| = |p_j − p_i|")

# %% [markdown]
# ## 2. Likelihood and cost, eqs. (2)–(3)
#
# The measurements are $\xi_{ij} = (p_j \ominus p_i) + \epsilon_{ij}$ with independent Gaussian noise
# $\epsilon_{ij} \sim \mathcal N(0, P_{ij})$. Independence makes the log-likelihood of a configuration
# $P = \{p_0, \dots, p_n\}$ a sum over the edges, eq. (2):
#
# $$\ln \mathcal L(P \mid Z) = \sum_{(i,j)} \ln \pi(\xi_{ij} \mid P)
#   = -\tfrac12 \sum_{(i,j)} (p_j \ominus p_i - \xi_{ij})^\top P_{ij}^{-1} (p_j \ominus p_i - \xi_{ij})
#     - \tfrac12 \sum_{(i,j)} \ln\det(2\pi P_{ij}),$$
#
# and maximizing it is minimizing the cost of eq. (3),
#
# $$f(P) = \sum_{(i,j)} (p_j \ominus p_i - \xi_{ij})^\top P_{ij}^{-1} (p_j \ominus p_i - \xi_{ij}). \tag{3}$$
#
# The full SLAM problem is $\min f$. The angular part of each residual is defined modulo $2\pi$; the
# package wraps it to $[-\pi, \pi)$. **`lago_cvx.chi2` is $f$ exactly — no factor ½** (the convention of
# g2o; GTSAM's `error()` is $f/2$). We check $-2\ln\mathcal L = f + \sum \ln\det(2\pi P_{ij})$ against
# `scipy.stats.multivariate_normal` on the running example, its measurements redrawn with full $3\times3$
# covariances (random correlations between $x$, $y$ and $\theta$), and that adding $2\pi k$ to a measured
# angle does not change $f$.

# %%
world = running_example()
edges = world.graph
meas, info = add_noise(world.truth, edges.tails, edges.heads, sigma_xy=0.1, sigma_theta=0.05, rng=rng, information="full")
g = lc.PoseGraph(edges.n_poses, edges.tails, edges.heads, meas[:, :2], meas[:, 2], info, name="running example, full P_ij")
m = g.n_edges
print(g)
e = lc.edge_errors(g, world.truth)
f_truth = lc.chi2(g, world.truth)
cov = g.covariance
log_l = sum(multivariate_normal(mean=np.zeros(3), cov=cov[k]).logpdf(e[k]) for k in range(m))
gap = abs(-2 * log_l - (f_truth + np.linalg.slogdet(2 * np.pi * cov)[1].sum()))
shifted = lc.PoseGraph(g.n_poses, g.tails, g.heads, g.delta_l, g.delta + 2 * np.pi * rng.integers(-3, 4, m),
                       g.information)

# %% tags=["remove-input"]
check(gap < 1e-9 * abs(log_l), f"−2 ln L = f + Σ ln det(2πP_ij)   (difference {gap:.1e}; f at the truth = {f_truth:.2f})")
check(abs(lc.chi2(shifted, world.truth) - f_truth) < 1e-9 * f_truth, "f is unchanged by δ + 2πk")

# %% [markdown]
# **Which convention? Let the data decide.** At the true poses the residuals are the noise itself, so
# $f(\text{truth})$ is a sum of $3m$ squared standard normals: a χ² variable with $3m$ degrees of
# freedom, mean $3m$ and standard deviation $\sqrt{6m}$. A cost with a factor ½ would have mean $3m/2$
# instead: it would sit $(3m/2)/\sqrt{6m} = \sqrt{3m/8}$ standard deviations below $3m$. For the running
# example ($m = 85$) that is about 5.6σ — the cell computes it. We redraw the noise 400 times on the same
# graph (fixed truth and edges, fresh noise and covariances) and compare the histogram of $f(\text{truth})$
# with the χ² law.

# %%
sigmas_half = np.sqrt(3 * m / 8)
z_f = (f_truth - 3 * m) / np.sqrt(6 * m)
z_half = (f_truth / 2 - 3 * m) / np.sqrt(6 * m)
print(f"m = {m}: 3m = {3 * m}, √(6m) = {np.sqrt(6 * m):.1f}; f(truth) = {f_truth:.1f} → {z_f:+.2f}σ; "
      f"f/2 → {z_half:+.2f}σ; predicted offset of a factor ½: −√(3m/8) = {-sigmas_half:.2f}σ")
draws = []
for _ in range(400):
    meas, info = add_noise(world.truth, g.tails, g.heads, sigma_xy=0.1, sigma_theta=0.05, rng=rng, information="full")
    draws.append(lc.chi2(lc.PoseGraph(g.n_poses, g.tails, g.heads, meas[:, :2], meas[:, 2], info), world.truth))
draws = np.array(draws)
mean_z = (draws.mean() - 3 * m) / (np.sqrt(6 * m) / np.sqrt(draws.size))
print(f"400 draws: mean f = {draws.mean():.1f} (3m = {3 * m}), std = {draws.std(ddof=1):.1f} (√(6m) = {np.sqrt(6 * m):.1f})")

# %% tags=["remove-input"]
check(abs(mean_z) < 4 and abs(draws.std(ddof=1) / np.sqrt(6 * m) - 1) < 0.15,
      "the mean and spread of f(truth) over 400 draws match the χ²(3m) law")

# %%
fig, ax = plt.subplots(figsize=(7.5, 3.8))
grid = np.linspace(draws.min() / 2 - 60, draws.max() + 60, 400)
ax.hist(draws, bins=30, density=True, color="tab:blue", alpha=0.5, label="f(truth), 400 noise draws")
ax.hist(draws / 2, bins=30, density=True, color="tab:red", alpha=0.5, label="f(truth)/2 (a factor-½ convention)")
ax.plot(grid, chi2_law.pdf(grid, 3 * m), "k", label=f"χ² law with 3m = {3 * m} degrees of freedom")
ax.set_xlabel("cost at the true poses")
ax.set_title(f"Eq. (3) at the truth follows χ²(3m); a factor ½ lands {abs(z_half):.0f}σ away")
ax.legend(fontsize=8)
show(fig, "chi2_law")

# %% tags=["remove-input"]
check(abs(z_f) < 3, f"f(truth) is within 3σ of 3m ({z_f:+.2f}σ): the package's χ² has no factor ½")
check(z_half < -4 and abs(z_half + sigmas_half) < 1.5,
      f"a factor-½ convention would miss by about √(3m/8) σ ({z_half:+.2f}σ; −√(3m/8) = {-sigmas_half:.2f}σ)")

# %% [markdown]
# ## Exercise 1 — How far off is a factor ½?
#
# *Derive.* At the true poses $f$ follows a χ² law with $3m$ degrees of freedom. Show that a cost with a
# factor ½ sits $\sqrt{3m/8}$ standard deviations below $3m$ on average, and find the smallest number of
# edges $m$ for which that offset reaches 3σ. Write it as `half_offset(m)`; the check tries many $m$.
#
# **Hint.** At the true poses $f$ has mean $3m$ and variance $6m$; the cost with a factor ½ has mean $3m/2$. Divide
# the offset by the standard deviation.

# %%
# your solution here: fill in the body of half_offset, then run the cell (check_half_offset tests it)
from lago_cvx.exercises import check_half_offset

def half_offset(m):
    """The offset of a factor-½ cost below 3m, in standard deviations √(6m) (a float)."""
    raise NotImplementedError
check_half_offset(half_offset)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. At the true poses f is a sum of 3m squared standard normals: mean 3m, variance 6m.
# A cost with a factor ½ has mean 3m/2, so it sits (3m − 3m/2)/√(6m) = √(3m/8) standard deviations below 3m;
# √(3m/8) ≥ 3 ⟺ m ≥ 24: from 24 edges on, a wrong convention is a 3σ event on average.
import numpy as np
from lago_cvx.exercises import check_half_offset

def half_offset(m):
    return (3 * m - 3 * m / 2) / np.sqrt(6 * m)
check_half_offset(half_offset).require()

# %% [markdown]
# ## 3. The split residual, eq. (4), and block-diagonal noise, eq. (5)
#
# A measurement has two parts of different nature: a relative position $\Delta^l_{ij}$ (a vector) and a
# relative orientation $\delta_{ij}$ (a scalar). Eq. (3) with the residual split accordingly is eq. (4):
#
# $$f = \sum_{(i,j)} \begin{bmatrix} R_i^\top (p_j - p_i) - \Delta^l_{ij} \\ (\theta_j - \theta_i) - \delta_{ij}\end{bmatrix}^\top
#   P_{ij}^{-1} \begin{bmatrix} R_i^\top (p_j - p_i) - \Delta^l_{ij} \\ (\theta_j - \theta_i) - \delta_{ij}\end{bmatrix}. \tag{4}$$
#
# The paper then *assumes* that the two parts are independent, $P_{ij} = \mathrm{diag}(P_{\Delta^l,ij},
# P_{\delta,ij})$. The cost splits into a position term and an orientation term, and with the
# incidence matrix $A$ ($(n+1) \times m$; column of edge $(i,j)$: $-1$ in row $i$, $+1$ in row $j$),
# $A_2 = A \otimes I_2$, the stacked poses $p^+ = [p_0^\top \dots p_n^\top]^\top$,
# $\theta^+ = [\theta_0 \dots \theta_n]^\top$, $P_{\Delta^l} = \mathrm{blkdiag}(P_{\Delta^l,ij})$,
# $P_\delta = \mathrm{diag}(P_{\delta,ij})$ and $R = R(\theta)$ the block-diagonal matrix whose block
# $k$ is the rotation of the tail of edge $k$, it reads (eq. (5))
#
# $$f = (A_2^\top p^+ - R\Delta^l)^\top (R P_{\Delta^l} R^\top)^{-1} (A_2^\top p^+ - R\Delta^l)
#     + (A^\top \theta^+ - \delta)^\top P_\delta^{-1} (A^\top \theta^+ - \delta). \tag{5}$$
#
# The position residual is now in the *global* frame: $R_i^\top(p_j - p_i) - \Delta^l_{ij}$ times $R_i$ is
# $(p_j - p_i) - R_i\Delta^l_{ij}$, and its covariance rotates with it, to $R_i P_{\Delta^l,ij} R_i^\top$.
# We evaluate eq. (4) and eq. (5) with explicit dense matrices ($2m \times 2m = 170 \times 170$) on the
# running example (block-diagonal information) and compare with `lago_cvx.chi2`, near the truth.

# %%
world = running_example()
gs, truth_s = world.graph, world.truth
x = truth_s + 0.05 * rng.standard_normal(truth_s.shape)          # some configuration near the truth
A_full = lc.incidence_matrix(gs).toarray()
A2_full = np.kron(A_full, np.eye(2))
Rblk = np.zeros((2 * gs.n_edges, 2 * gs.n_edges))
for k, i in enumerate(gs.tails):
    Rblk[2 * k:2 * k + 2, 2 * k:2 * k + 2] = rot2(x[i, 2])
cov_s = gs.covariance
P_dl = np.zeros_like(Rblk)
for k in range(gs.n_edges):
    P_dl[2 * k:2 * k + 2, 2 * k:2 * k + 2] = cov_s[k, :2, :2]
P_delta = np.diag(cov_s[:, 2, 2])
r_pos = A2_full.T @ x[:, :2].ravel() - Rblk @ gs.delta_l.ravel()
r_rot = A_full.T @ x[:, 2] - gs.delta
r_rot -= 2 * np.pi * np.round(r_rot / (2 * np.pi))                  # δ is measured modulo 2π
f_eq5 = r_pos @ np.linalg.solve(Rblk @ P_dl @ Rblk.T, r_pos) + r_rot @ np.linalg.solve(P_delta, r_rot)
res4 = np.column_stack([between(x[gs.tails], x[gs.heads])[:, :2] - gs.delta_l, r_rot])
f_eq4 = np.einsum("ka,kab,kb->", res4, gs.information, res4)
print(gs, f"| block-diagonal information: {np.abs(gs.information[:, :2, 2]).max() == 0}")

# %% tags=["remove-input"]
check(abs(f_eq4 - lc.chi2(gs, x)) < 1e-9 * f_eq4, f"eq. (4) = lago_cvx.chi2 ({f_eq4:.4f})")

# %% tags=["remove-input"]
check(abs(f_eq5 - lc.chi2(gs, x)) < 1e-9 * f_eq5, f"eq. (5) with A, A₂ = A ⊗ I₂, R(θ) = lago_cvx.chi2 ({f_eq5:.4f})")

# %% [markdown]
# **Remark 2 (block-diagonal noise holds for holonomic platforms, only approximately otherwise).** A
# robot that can move sideways (holonomic) can have independent position and heading errors. A car-like
# (non-holonomic) robot cannot: its heading error turns into a lateral position error, so its odometry
# correlates $x$–$\theta$ or $y$–$\theta$. Real data shows it: in the Intel data set as distributed with
# SE-Sync (`se-sync/intel.g2o`) every edge carries position–orientation cross information, mostly between
# the heading and the lateral position $y$ (in the robot's frame). We measure the
# correlations, and what the block-diagonal approximation costs: we replace every covariance by
# $\mathrm{diag}(P_{\Delta^l,ij}, P_{\delta,ij})$ (same marginals, correlation dropped), minimize *that*
# cost with Gauss–Newton, and evaluate the true cost eq. (3) at the result.

# %%
intel_full = real("se-sync/intel.g2o")
if intel_full is not None:
    cov_i = intel_full.covariance
    corr = cov_i[:, :2, 2] / np.sqrt(cov_i[:, [0, 1], [0, 1]] * cov_i[:, 2:3, 2])
    crossed = np.abs(intel_full.information[:, :2, 2]).max(axis=1) > 0
    blockdiag = cov_i.copy()
    blockdiag[:, :2, 2] = blockdiag[:, 2, :2] = 0.0
    approx = lc.PoseGraph(intel_full.n_poses, intel_full.tails, intel_full.heads, intel_full.delta_l,
                          intel_full.delta, np.linalg.inv(blockdiag))
    start = lc.lago(intel_full).poses
    exact_opt = refine(intel_full, start, max_iterations=50)
    approx_opt = refine(approx, start, max_iterations=50)
    f_exact, f_at_approx = exact_opt.chi2, lc.chi2(intel_full, approx_opt.poses)
    print(intel_full)
    print(f"edges with x–θ or y–θ cross information: {crossed.sum()} of {intel_full.n_edges}; "
          f"|correlation| median {np.median(np.abs(corr)):.3f}, largest {np.abs(corr).max():.3f}")
    print(f"minimum of the true cost: {f_exact:.4f} (reference minimum {REFERENCE_CHI2['se-sync/intel.g2o']}); "
          f"true cost at the minimum of the block-diagonal cost: {f_at_approx:.4f} "
          f"(+{100 * (f_at_approx / f_exact - 1):.2f} %), positions moved by {lc.ate(approx_opt.poses, exact_opt.poses):.3f} m RMS")
    lateral, forward = np.median(np.abs(corr[:, 1])), np.median(np.abs(corr[:, 0]))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for c, name in ((0, "x"), (1, "y")):
        ax.hist(corr[:, c], bins=40, alpha=0.6, label=f"corr({name}, θ)")
    ax.set(xlabel="correlation coefficient of the measurement noise, per edge", ylabel="edges",
           title="Remark 2 on real data: se-sync/intel.g2o is not block-diagonal")
    ax.legend()
    show(fig, "remark2_correlations")

# %% tags=["remove-input"]
if intel_full is not None:
    check(crossed.all() and np.abs(corr).max() > 0.5, "every edge of se-sync/intel.g2o has x–θ cross information")
    check(lateral > 2 * forward, f"the lateral (y–θ) correlation dominates: median |corr| {lateral:.2f} against "
          f"{forward:.2f} for x–θ — a heading error becomes a sideways position error")
    check(abs(f_exact - REFERENCE_CHI2["se-sync/intel.g2o"]) < 1e-3 * f_exact, "Gauss–Newton reaches the reference minimum")
    check(f_at_approx > f_exact, "the block-diagonal approximation of Remark 2 misses the minimum of the true cost")

# %% [markdown]
# ## 4. The reduced problem, eq. (6), and the system eq. (7)
#
# The reference frame is pose 0: $p_0 = 0$, $\theta_0 = 0$. Deleting pose 0 from the unknowns deletes
# its row from $A$ (and its two rows from $A_2$): the *reduced* incidence matrices, $n \times m$ and
# $2n \times 2m$. With $p \in \mathbb R^{2n}$, $\theta \in \mathbb R^n$ the remaining unknowns, eq. (5)
# becomes eq. (6):
#
# $$f(p, \theta) = (A_2^\top p - R\Delta^l)^\top (R P_{\Delta^l} R^\top)^{-1} (A_2^\top p - R\Delta^l)
#   + (A^\top\theta - \delta)^\top P_\delta^{-1} (A^\top\theta - \delta). \tag{6}$$
#
# Minimizing eq. (6) is solving, in the weighted least-squares sense, the system eq. (7):
#
# $$\begin{cases} A_2^\top p = R(\theta)\,\Delta^l \\ A^\top \theta = \delta \end{cases} \tag{7}$$
#
# It looks linear: incidence matrices times unknowns equal measurements. **It is not**: $R(\theta)$
# multiplies the data by trigonometric functions of the unknown orientations, and with $\theta$ unknown
# the first equation is bilinear. (Only the second equation is linear in $\theta$ — lecture 2 builds on
# that.) In the package:
#
# | paper | `lago_cvx` |
# |---|---|
# | $A$, $(n+1)\times m$ | `lc.incidence_matrix(graph)` |
# | reduced $A$, $n \times m$ | `lc.reduced_incidence(graph)` (some package docstrings call it "A2") |
# | reduced $A_2^\top = A^\top \otimes I_2$ | the first block of `lago_cvx.phases.design_matrix(graph)` |
# | $n + 1$ | `graph.n_poses` |
#
# We build them for a small graph — a robot that drives twice around a square, 8 poses, with four loop
# closures between the two laps — and check: one $-1$ and one $+1$ per column; $A^\top\theta^+$ is the
# vector of orientation differences; the reduced matrices and the package agree; and the residual of
# eq. (7) is not linear in $\theta$: superposition fails.

# %%
corner = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
truth8 = np.zeros((8, 3))
truth8[:4, :2] = corner
truth8[4:, :2] = 1.0 + 0.6 * (corner - 1.0)          # the second lap is a smaller square
truth8[:, 2] = np.arange(8) * np.pi / 2               # heading towards the next corner
tails8 = np.array([0, 1, 2, 3, 4, 5, 6, 0, 1, 2, 3])
heads8 = np.array([1, 2, 3, 4, 5, 6, 7, 4, 5, 6, 7])
meas8, info8 = add_noise(truth8, tails8, heads8, sigma_xy=0.05, sigma_theta=0.02, rng=np.random.default_rng(1))
square = lc.PoseGraph(8, tails8, heads8, meas8[:, :2], meas8[:, 2], info8, name="two laps of a square")
n8, m8 = square.n_poses - 1, square.n_edges
A8 = lc.incidence_matrix(square).toarray()
A8_red = lc.reduced_incidence(square).toarray()
A2_8_red = np.kron(A8_red, np.eye(2))
print(square, f"→ n = {n8}, m = {m8}")
print("A (rows: poses 0…7; columns: edges 0…10):\n", A8.astype(int))

# %% tags=["remove-input"]
check(np.all(A8.sum(axis=0) == 0) and np.all(np.abs(A8).sum(axis=0) == 2), "each column of A holds one −1 and one +1")
check(np.allclose(A8.T @ truth8[:, 2], truth8[heads8, 2] - truth8[tails8, 2]), "Aᵀθ⁺ = (θ_j − θ_i) for every edge")
check(np.array_equal(A8_red, np.delete(A8, 0, axis=0)), "lc.reduced_incidence = A without the row of pose 0")
check(np.array_equal(design_matrix(square).toarray()[:2 * m8, :2 * n8], A2_8_red.T),
      "design_matrix's first block = reduced A₂ᵀ = (A ⊗ I₂)ᵀ without pose 0")

# %%
def residual_7(p, theta):
    """Residual of the first equation of eq. (7), A₂ᵀp − R(θ)Δˡ, pose 0 at the origin."""
    th_all = np.concatenate([[0.0], theta])
    return A2_8_red.T @ p - np.einsum("kab,kb->ka", rot2(th_all[tails8]), square.delta_l).ravel()
p_rand, t1, t2 = rng.normal(size=2 * n8), rng.normal(size=n8), rng.normal(size=n8)
superposition = residual_7(p_rand, t1 + t2) - residual_7(p_rand, t1) - residual_7(p_rand, t2) + residual_7(p_rand, 0 * t1)
p_lin = residual_7(2 * p_rand, t1) - 2 * residual_7(p_rand, t1) + residual_7(0 * p_rand, t1)

# %% tags=["remove-input"]
check(np.abs(p_lin).max() < 1e-12, "for fixed θ the first equation of eq. (7) is affine in p")

# %%
show(incidence_figure(square, truth8, A8), "incidence")

# %% tags=["remove-input"]
check(np.abs(superposition).max() > 0.1, f"but not in θ: superposition fails by {np.abs(superposition).max():.2f}")

# %% [markdown]
# ## Exercise 2 — The reduced cost of eq. (6) in code
#
# *Implement.* Write `cost_eq6(graph, poses)`: eq. (6) for a graph with block-diagonal information, from the
# reduced $A$, the reduced $A_2 = A \otimes I_2$ and $R(\theta)$ as sparse matrices, for any configuration with
# pose 0 at the origin. The check compares it with `lago_cvx.chi2` on the running example near the truth
# (`eq6_case()`), then turns one pose by $2\pi$: explain why the two then differ.
#
# **Hint.** Eq. (6) takes the angular residual $A^\top\theta - \delta$ as it is; `lc.chi2` wraps every angular
# residual into $[-\pi, \pi)$.

# %%
# your solution here: fill in the body of cost_eq6, then run the cell (check_cost_eq6 tests it)
from lago_cvx.exercises import check_cost_eq6, eq6_case
graph, poses = eq6_case()          # the data the check uses

def cost_eq6(graph, poses):
    """Eq. (6) at poses (n + 1, 3), pose 0 at the origin (a float)."""
    raise NotImplementedError
check_cost_eq6(cost_eq6)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. Eq. (6) with sparse matrices: position residual A₂ᵀp − RΔˡ weighted by (R P_Δˡ Rᵀ)⁻¹,
# orientation residual Aᵀθ − δ by P_δ⁻¹. It equals lc.chi2 while every angular residual lies in [−π, π); the
# package wraps that residual, eq. (6) does not: turn a pose by 2π and eq. (6) jumps, χ² does not.
import numpy as np
import scipy.sparse as sp
import lago_cvx as lc
from lago_cvx.exercises import check_cost_eq6
from lago_cvx.posegraph import rot2

def cost_eq6(graph, poses):
    A = lc.reduced_incidence(graph)
    A2 = sp.kron(A, sp.identity(2)).tocsr()
    theta, cov = poses[:, 2], graph.covariance
    R = sp.block_diag(rot2(theta[graph.tails]), format="csr")
    r_pos = A2.T @ poses[1:, :2].ravel() - R @ graph.delta_l.ravel()
    weight = (R @ sp.block_diag(cov[:, :2, :2]) @ R.T).tocsc()
    r_rot = A.T @ theta[1:] - graph.delta
    return float(r_pos @ sp.linalg.spsolve(weight, r_pos) + np.sum(r_rot**2 / cov[:, 2, 2]))

check_cost_eq6(cost_eq6).require()

# %% [markdown]
# ## 5. Lemma 1 — the pose graph is connected
#
# **Lemma 1 (connectivity of the pose graph).** A pose graph built from a robot's odometric and
# loop-closing constraints is connected. *Proof:* the odometric edges join the poses taken at consecutive
# instants, so they form a path through all poses — the trajectory the robot travelled.
#
# Connectivity is what every later step needs: a disconnected graph leaves the relative placement of its
# components undetermined. We check the lemma's proof on real graphs (the odometric edges alone — edges
# between consecutive ids — join all $n + 1$ poses: one component) and show what breaks when its
# hypothesis fails: two robots that never observed each other — two copies of the running example — give
# two components, and LAGO refuses them.

# %%
lemma1 = {}
for rel in ["carlone/INTEL_P_toro.graph", "se-sync/MIT.g2o"]:
    graph = real(rel)
    if graph is None:
        continue
    odometric = graph.subgraph_edges(graph.is_odometric)
    parts, _ = lc.connected_components(odometric)
    print(f"{rel}: n + 1 = {graph.n_poses} poses, {graph.n_odometric} odometric edges, {graph.n_loop_closures} loop closures")
    lemma1[rel] = graph.n_odometric == graph.n_poses - 1 and parts == 1

# %% tags=["remove-input"]
for rel, holds in lemma1.items():
    check(holds, f"Lemma 1 on {rel}: the odometric path alone connects all poses")

# %%
two_robots = running_example().graph
offset = two_robots.n_poses
union = lc.PoseGraph(2 * offset, np.concatenate([two_robots.tails, two_robots.tails + offset]),
                     np.concatenate([two_robots.heads, two_robots.heads + offset]),
                     np.vstack([two_robots.delta_l] * 2), np.concatenate([two_robots.delta] * 2),
                     np.concatenate([two_robots.information] * 2))
try:
    lc.lago(union)
    refused = ""
except GraphError as exc:
    refused = str(exc)
print("two robots, no common observation:", refused)

# %% tags=["remove-input"]
check(lc.connected_components(union)[0] == 2 and refused != "", "without Lemma 1's odometric path: 2 components, refused")

# %% [markdown]
# ## 6. The cost is non-convex, with local minima
#
# The cost eq. (3) depends on the orientations through $R(\theta_i)$ and through the angular residual,
# which is defined modulo $2\pi$: $f$ is $2\pi$-periodic in every $\theta_i$. A convex function that is
# periodic along a line is constant on it; $f$ is not constant, so **$f$ is not convex**. Concretely: let
# $x^\star$ be a minimizer for the square graph (Gauss–Newton, `lago_cvx.refine`, started at the truth)
# and turn pose 2 alone by $\phi$. At $\phi = 2\pi$ the configuration is the same, the cost too, while
# the midpoint $\phi = \pi$ costs more — Jensen's inequality fails — and on $[-3\pi, 3\pi]$ the curve has
# several separate local minima.

# %%
x_star = refine(square, truth8 - truth8[0], tolerance=1e-15).poses
phi = np.linspace(-3 * np.pi, 3 * np.pi, 1201)

def turned(angle, pose=2):
    y = x_star.copy()
    y[pose, 2] += angle
    return y

curve = np.array([lc.chi2(square, turned(a)) for a in phi])
f0, f2pi, fpi = (lc.chi2(square, turned(a)) for a in (0.0, 2 * np.pi, np.pi))
inner = (curve[1:-1] < curve[:-2]) & (curve[1:-1] < curve[2:])
minima = phi[1:-1][inner]
print(f"f(x*) = {f0:.4f}, f(x* turned by 2π) = {f2pi:.4f}, f(midpoint) = {fpi:.1f}; "
      f"local minima at φ/π = {np.round(minima / np.pi, 3)}")

fig, ax = plt.subplots(figsize=(7.5, 3.8))
ax.plot(phi / np.pi, curve, color="tab:blue", label=r"$f(x^\star$ with pose 2 turned by $\phi)$")
ax.plot(minima / np.pi, curve[1:-1][inner], "o", color="tab:red", label="local minima")
ax.plot([0, 2], [f0, f2pi], "k--", linewidth=1, label="chord between two minima")
ax.set_yscale("log")
ax.set_xlabel(r"$\phi$ [units of $\pi$]")
ax.set_ylabel("cost eq. (3)")
ax.set_title("Along one line in pose space the cost is periodic and multi-modal")
ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
show(fig, "nonconvex_rotation")

# %% tags=["remove-input"]
check(abs(f2pi - f0) < 1e-9 * max(f0, 1.0), "f is 2π-periodic in θ₂")
check(fpi > 0.5 * (f0 + f2pi), "Jensen's inequality fails at the midpoint: f is not convex")
check(minima.size >= 3, f"{minima.size} local minima along one line")

# %% [markdown]
# **Local solvers land where they start.** Gauss–Newton linearizes the cost at the current guess and
# converges to a *local* minimum near it. On the running example the headings are measured too well for
# a trap: from dead reckoning (the odometry composed along the path, `odometry_guess`) and from LAGO's
# estimate (the subject of lectures 2–6) it reaches one minimum. With four times the heading noise (0.2 rad),
# on a larger Manhattan world, the two runs can stop in two different minima (the cell draws worlds from
# `DRAW` on until they do, and says how many it tried), and the cost between them rises above the chord — a second proof of non-convexity. On a real graph (MIT) the same happens.

# %%
ex = running_example().graph
one_minimum = [refine(ex, start, max_iterations=200) for start in (odometry_guess(ex), lc.lago(ex).poses)]
print("running example, Gauss–Newton from dead reckoning and from LAGO: cost", [f"{r.chi2:.4f}" for r in one_minimum])
DRAW = 0   # change it and rerun: the draws from DRAW on are tried until the two starts end in two minima
for draw in range(DRAW, DRAW + 40):       # about one draw in four traps Gauss–Newton at this noise
    # own world: heading noise that traps Gauss–Newton
    mw = lc.manhattan_world(200, seed=draw, sigma_theta=0.2, sigma_xy=0.05)
    gm = mw.graph
    from_dr = refine(gm, odometry_guess(gm), max_iterations=200)
    from_lago = refine(gm, lc.lago(gm).poses, max_iterations=200)
    from_truth = refine(gm, mw.truth, max_iterations=200)
    if (from_dr.converged and from_lago.converged and from_dr.chi2 > 1.01 * from_lago.chi2
            and abs(from_lago.chi2 - from_truth.chi2) < 1e-6 * from_truth.chi2):
        break
print(f"Manhattan world, draw {draw} ({draw - DRAW + 1} tried): two starts, two minima")
for name, run in [("dead reckoning", from_dr), ("LAGO", from_lago), ("the truth", from_truth)]:
    print(f"Gauss–Newton from {name:15s}: cost {run.chi2_initial:12.1f} → {run.chi2:9.3f} in {run.iterations:2d} steps ({run.reason})")
tt = np.linspace(0, 1, 101)
segment = np.array([lc.chi2(gm, (1 - s) * from_dr.poses + s * from_lago.poses) for s in tt])
chord = (1 - tt) * segment[0] + tt * segment[-1]

mit = real("se-sync/MIT.g2o")
if mit is not None:
    mit_dr = refine(mit, odometry_guess(mit), max_iterations=100)
    mit_lago = refine(mit, lc.lago(mit).poses, max_iterations=100)
    print(f"MIT: from dead reckoning cost {mit_dr.chi2:.2f}; from LAGO {mit_lago.chi2:.4f} "
          f"(reference minimum {REFERENCE_CHI2['se-sync/MIT.g2o']})")

show(two_minima_figure(mw.truth, from_dr, from_lago, tt, segment, chord), "local_minima")

# %% tags=["remove-input"]
if mit is not None:
    check(mit_dr.chi2 > 5 * mit_lago.chi2 and abs(mit_lago.chi2 - REFERENCE_CHI2["se-sync/MIT.g2o"]) < 1e-3 * mit_lago.chi2,
          "MIT: dead reckoning leads Gauss–Newton to a far worse minimum, LAGO to the reference one")
check(abs(one_minimum[0].chi2 - one_minimum[1].chi2) < 1e-6 * one_minimum[1].chi2, "running example: one minimum from both starts")
check(from_dr.converged and from_lago.converged, "both runs converged")
check(from_dr.chi2 > 1.01 * from_lago.chi2, f"from dead reckoning: a different minimum, {from_dr.chi2 / from_lago.chi2:.1f}× worse")
check(abs(from_lago.chi2 - from_truth.chi2) < 1e-6 * from_truth.chi2, "from LAGO: the same minimum as from the truth")
check(np.max(segment - chord) > 0, f"the cost rises {np.max(segment - chord):.0f} above the chord between them")

# %% [markdown]
# ### Try it: noise and the two minima
# Drag the heading noise σ_θ and the world: at small σ_θ both starts of Gauss–Newton end in one minimum, as on the
# running example; as it grows, dead reckoning's start more and more often ends in a worse one.

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.two_minima, "try_minima", sigma_theta=(0.02, 0.4, 0.02, 0.2), draw=(0, 20, 1, 11))

# %% [markdown]
# **Summary.** Maximum likelihood on a pose graph is the non-linear least-squares problem eq. (3); with
# independent position and orientation noise it splits as eqs. (5)–(6), and it is the least-squares form
# of the system eq. (7), whose only non-linearity is $R(\theta)$. The graph is connected (Lemma 1), but
# the cost is periodic in every orientation, hence non-convex, and local solvers depend on their start.
# LAGO avoids the start altogether by solving linear problems only: the orientations first (lecture 2),
# then the positions (lectures 3–4).

# %% [markdown]
# ## Exercise 3 — How many minima does Gauss–Newton find?
#
# *Explore.* Write `gauss_newton_minima(graph, n_starts, rng)`: start Gauss–Newton (`lc.refine`) from
# `n_starts` random configurations (positions and headings drawn at random) and return the distinct local
# minima it reaches, one pose array each. The check runs it on a 16-pose circle world (`minima_case()`).
# Does LAGO's start reach the best of them? Rerun with more heading noise: does the count grow?
#
# **Hint.** Keep a run's poses when it converged and its χ² (rounded to a few significant digits) is new.

# %%
# your solution here: fill in the body of gauss_newton_minima, then run the cell (check_minima tests it)
from lago_cvx.exercises import check_minima, minima_case
graph = minima_case()              # the world the check uses

def gauss_newton_minima(graph, n_starts, rng):
    """The distinct local minima reached from n_starts random starts: a list of (n + 1, 3) arrays."""
    raise NotImplementedError

check_minima(gauss_newton_minima)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. Random starts (positions in the box of the graph's dead reckoning, headings uniform)
# end in several local minima; their number does not simply grow with the noise (with very certain headings
# the landscape is steep and the runs scatter most). LAGO's estimate, used as a start, reaches the best found.
import numpy as np
import lago_cvx as lc
from lago_cvx.exercises import check_minima

def gauss_newton_minima(graph, n_starts, rng):
    guess = lc.odometry_guess(graph)
    lo, hi = guess[:, :2].min(axis=0), guess[:, :2].max(axis=0)
    minima = {}
    for _ in range(n_starts):
        start = np.column_stack([rng.uniform(lo, hi, (graph.n_poses, 2)), rng.uniform(-np.pi, np.pi, graph.n_poses)])
        run = lc.refine(graph, start, max_iterations=100)
        if run.converged:
            minima.setdefault(round(float(np.log10(run.chi2)), 4), run.poses)
    return list(minima.values())

check_minima(gauss_newton_minima).require()
