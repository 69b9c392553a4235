# %% [markdown]
# # Lecture 1 — The problem: planar pose-graph optimization
#
# This lecture follows Section III of the seed — Carlone, Aragues, Castellanos, Bona, *A Linear
# Approximation for Graph-based Simultaneous Localization and Mapping* (RSS 2011) — and checks every
# statement numerically with the package `lago_cvx`.
#
# **Notation (the seed's, kept throughout the lectures).** Poses $x_i = (p_i, \theta_i)$,
# $p_i \in \mathbb{R}^2$, $i = 0, \dots, n$, pose $0$ the *anchor*. In the package a graph has
# `n_poses` $= n+1$ poses indexed `0 … n_poses−1`, and the anchor is index 0 by default.
# The graph has $m$ edges; edge $k$ goes from its *tail* $i$ to its *head* $j$ and carries the
# measurement $(\Delta^l_{ij}, \delta_{ij})$: the relative position $\Delta^l_{ij}$ of $j$ expressed in
# the frame of $i$, and the relative orientation $\delta_{ij}$, with covariances $P_{\Delta}$ and
# $P_\delta$.
#
# Contents:
# 1. pose compounding, eq. (1);
# 2. the likelihood and cost, eqs. (2)–(3), and the χ² convention of the package;
# 3. the graph, its incidence matrix $A$ and the reduced form, eqs. (6)–(7);
# 4. why the problem is non-convex;
# 5. why local (Gauss–Newton) methods depend on the initial guess.

# %%
import time


import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse.linalg as spla
from scipy.stats import multivariate_normal

from _lecture import figure_saver
import lago_cvx as lc
from lago_cvx import plotting
from lago_cvx.datasets import DatasetNotFound, dataset
from lago_cvx.phases import design_matrix
from lago_cvx.posegraph import between, compose, rot2, wrap_angle
from lago_cvx.refinement import jacobian, odometry_guess, refine, whitened_residuals
from lago_cvx.synthetic import add_noise

save = figure_saver("01_problem")

T_START = time.perf_counter()

# %% [markdown]
# ## 1. Pose compounding, eq. (1)
#
# A pose $x_i = (p_i, \theta_i)$ is a rigid motion of the plane. Composing the pose $x_i$ with a
# relative pose $t = (t_p, t_\theta)$ expressed in the frame of $x_i$ gives
#
# $$x_j = x_i \oplus t = \begin{bmatrix} p_i + R(\theta_i)\, t_p \\ \theta_i + t_\theta \end{bmatrix},
# \qquad R(\theta) = \begin{bmatrix}\cos\theta & -\sin\theta\\ \sin\theta & \cos\theta\end{bmatrix}
# \tag{1}$$
#
# and the inverse operation — "pose $j$ seen from pose $i$" — is
#
# $$\ominus x_i \oplus x_j = \begin{bmatrix} R(\theta_i)^\top (p_j - p_i) \\ \theta_j - \theta_i
# \end{bmatrix}.$$
#
# In `lago_cvx.posegraph` these are `compose(a, b)` $= a \oplus b$ and `between(a, b)` $= \ominus a
# \oplus b$. Angles are **not wrapped** (θ is a real number), so the following identities hold
# exactly, not only modulo $2\pi$:
#
# * `between` inverts `compose`: $\ominus a \oplus (a \oplus t) = t$ and $a \oplus (\ominus a \oplus b) = b$;
# * $\oplus$ is associative: $(a \oplus b) \oplus c = a \oplus (b \oplus c)$ (the composition of rigid motions);
# * the identity is $0$ and the inverse of $a$ is $\ominus a = $ `between(a, 0)`: $a \oplus (\ominus a) = 0$.
#
# We check them on 10 000 random triples of poses with θ far outside $[-\pi, \pi)$.

# %%
rng = np.random.default_rng(0)
N = 10_000


def random_poses(k):
    return np.column_stack([rng.uniform(-50, 50, (k, 2)), rng.uniform(-3 * np.pi, 3 * np.pi, k)])


a, b, c, t = random_poses(N), random_poses(N), random_poses(N), random_poses(N)
checks = {
    "between(a, compose(a, t)) - t": between(a, compose(a, t)) - t,
    "compose(a, between(a, b)) - b": compose(a, between(a, b)) - b,
    "(a+b)+c - a+(b+c)": compose(compose(a, b), c) - compose(a, compose(b, c)),
    "compose(a, inverse(a))": compose(a, between(a, np.zeros(3))),
    "between(a, b) - inverse(a)+b": between(a, b) - compose(between(a, np.zeros(3)), b),
}
for name, err in checks.items():
    print(f"max |{name}| = {np.abs(err).max():.2e}")
    assert np.abs(err).max() < 1e-10, name

# %% [markdown]
# ## 2. Measurements, likelihood and cost, eqs. (2)–(3)
#
# Each edge $i \to j$ measures pose $j$ in the frame of pose $i$:
#
# $$\Delta^l_{ij} = R(\theta_i)^\top (p_j - p_i) + \epsilon_\Delta, \qquad
#   \delta_{ij} = \theta_j - \theta_i + \epsilon_\delta \pmod{2\pi},$$
#
# with Gaussian noise of covariance $P_{ij}$ (the seed assumes $P_{ij} = \mathrm{blkdiag}(P_\Delta,
# P_\delta)$; real files give a full $3\times3$ information $\Omega_{ij} = P_{ij}^{-1}$). With the edge
# error $e_{ij}(x) = \big[R(\theta_i)^\top(p_j - p_i) - \Delta^l_{ij};\ \mathrm{wrap}(\theta_j -
# \theta_i - \delta_{ij})\big]$ the likelihood (2) is $\prod_{ij} \mathcal N(e_{ij}; 0, P_{ij})$ and
# maximising it is minimising the cost (3)
#
# $$x^\star = \arg\min_x \sum_{(i,j)} e_{ij}(x)^\top P_{ij}^{-1} e_{ij}(x).$$
#
# **The package's convention.** `lago_cvx.chi2(graph, poses)` returns
# $\chi^2 = \sum e^\top \Omega e$ — **no factor ½**. This is the χ² that g2o prints; GTSAM's
# `NonlinearFactorGraph.error()` is ½χ² (its factors carry ½‖·‖²); the SE-Sync objective is a
# different function (a chordal distance on rotations), so its optimal values are not comparable with
# ours. (The GTSAM and SE-Sync statements are conventions quoted from the package documentation; they
# are not re-derived here because neither library is used.) What we *can* check is the exact relation
# with the Gaussian log-likelihood:
#
# $$-2 \log \prod_{ij} \mathcal N(e_{ij}; 0, \Omega_{ij}^{-1}) = \chi^2 + \sum_{ij} \log\det(2\pi\,
# \Omega_{ij}^{-1}),$$
#
# computed independently with `scipy.stats.multivariate_normal` on a world with *full* information
# matrices (all cross terms non-zero). At the true poses the errors are the noise itself, so χ² follows
# a chi-square law with $3m$ degrees of freedom: mean $3m$, standard deviation $\sqrt{6m}$.

# %%
world = lc.manhattan_world(200, seed=0, information="full", sigma_xy=0.05, sigma_theta=0.02)
g = world.graph
print(g)
e = lc.edge_errors(g, world.truth)
chi2_truth = lc.chi2(g, world.truth)
cov = np.linalg.inv(g.information)
loglik = sum(multivariate_normal(mean=np.zeros(3), cov=cov[k]).logpdf(e[k]) for k in range(g.n_edges))
logdet = np.linalg.slogdet(2 * np.pi * cov)[1].sum()
gap = abs(-2 * loglik - (chi2_truth + logdet))
print(f"chi2 at the truth = {chi2_truth:.4f}")
print(f"|-2 log L - (chi2 + sum log det 2πΣ)| = {gap:.2e}  (relative {gap / abs(2 * loglik):.1e})")
assert gap < 1e-9 * abs(2 * loglik)

parts = lc.chi2_parts(g, world.truth)
print("chi2 parts:", {k: round(v, 4) for k, v in parts.items()})
assert abs(parts["translation"] + parts["rotation"] + parts["cross"] - chi2_truth) < 1e-9 * chi2_truth

m = g.n_edges
print(f"3m = {3 * m}, sqrt(6m) = {np.sqrt(6 * m):.1f}, (chi2 - 3m)/sqrt(6m) = {(chi2_truth - 3 * m) / np.sqrt(6 * m):+.2f}")
assert abs(chi2_truth - 3 * m) < 4 * np.sqrt(6 * m)   # would fail by ~20σ with a factor ½

# The angular error is wrapped: adding 2πk to any measurement leaves χ² unchanged.
k_shift = rng.integers(-3, 4, m)
g_shift = lc.PoseGraph(g.n_poses, g.tails, g.heads, g.delta_l, g.delta + 2 * np.pi * k_shift, g.information)
d = abs(lc.chi2(g_shift, world.truth) - chi2_truth)
print(f"|chi2(δ + 2πk) - chi2(δ)| = {d:.2e}")
assert d < 1e-9 * chi2_truth

# %% [markdown]
# ## 3. The graph, the incidence matrix $A$ and the reduced form, eqs. (6)–(7)
#
# We draw a small graph: a robot drives twice around a square (8 poses, θ accumulating to
# $7\pi/2$), with odometric edges $k \to k+1$ and four loop closures $k \to k+4$ between the two laps.
# Measurements are drawn by the package's own noise model (`lago_cvx.synthetic.add_noise`).
#
# The **incidence matrix** $A \in \mathbb{R}^{(n+1) \times m}$ (eq. (6)) has, in column $k$ (edge
# $i\to j$), $-1$ in row $i$ and $+1$ in row $j$. Hence $A^\top \theta$ is the vector of orientation
# differences $\theta_j - \theta_i$ and $(A^\top \otimes I_2) p$ the vector of position differences
# $p_j - p_i$. The **reduced incidence matrix** $A_2$ (eq. (7)) deletes the anchor's row. With the
# anchor at the origin ($p_0 = 0$, $\theta_0 = 0$) the unknowns are the $n$ free poses and the
# measurement model of Section 2 reads, stacked over edges (as formulated here),
#
# $$\delta = A_2^\top \theta + \epsilon_\delta \pmod{2\pi}, \qquad
#   \Delta^l = R(\theta)^\top (A_2^\top \otimes I_2)\, p + \epsilon_\Delta,$$
#
# with $R(\theta) = \mathrm{blkdiag}_k R(\theta_{i_k})$ the rotations of the tails. We build these
# matrices densely and check that they reproduce the per-edge errors of `lago_cvx.edge_errors` at random
# poses. `lago_cvx.phases.design_matrix` (used in phase 3) is $B^\top =
# \mathrm{blkdiag}(A_2^\top \otimes I_2, I)$; we check its first block too.

# %%
corner = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], float)
truth8 = np.zeros((8, 3))
truth8[:4, :2] = corner
truth8[4:, :2] = 1.0 + 0.6 * (corner - 1.0)          # the second lap is a smaller square
truth8[:, 2] = np.arange(8) * np.pi / 2               # heading towards the next corner
tails8 = np.array([0, 1, 2, 3, 4, 5, 6, 0, 1, 2, 3])
heads8 = np.array([1, 2, 3, 4, 5, 6, 7, 4, 5, 6, 7])
meas8, info8 = add_noise(truth8, tails8, heads8, sigma_xy=0.05, sigma_theta=0.02, rng=np.random.default_rng(1))
small = lc.PoseGraph(8, tails8, heads8, meas8[:, :2], meas8[:, 2], info8, name="two laps of a square")
print(small)
print("loop closures: true θ_j - θ_i =", np.round((truth8[heads8] - truth8[tails8])[7:, 2], 3),
      " measured δ (wrapped) =", np.round(small.delta[7:], 3))

A = lc.incidence_matrix(small).toarray()
A2 = lc.reduced_incidence(small, anchor=0).toarray()
print("A (rows = poses 0..7, columns = edges 0..10):")
print(A.astype(int))
assert np.all(A.sum(axis=0) == 0)                                  # one -1 and one +1 per column
assert np.array_equal(A2, np.delete(A, 0, axis=0))                 # A2 = A without the anchor row
th = truth8[:, 2]
assert np.allclose(A.T @ th, th[heads8] - th[tails8])              # Aᵀθ = θ_j - θ_i

# the reduced form reproduces edge_errors at random poses (anchor at the origin)
x = random_poses(8)
x[0] = 0.0
p_free = x[1:, :2].reshape(-1)                                     # interleaved x1, y1, x2, y2, ...
Rt = np.zeros((2 * small.n_edges, 2 * small.n_edges))
for k in range(small.n_edges):
    Rt[2 * k:2 * k + 2, 2 * k:2 * k + 2] = rot2(x[tails8[k], 2]).T
e_pos = Rt @ np.kron(A2.T, np.eye(2)) @ p_free - small.delta_l.reshape(-1)
e_rot = wrap_angle(A2.T @ x[1:, 2] - small.delta)
e_ref = lc.edge_errors(small, x)
err = max(np.abs(e_pos - e_ref[:, :2].reshape(-1)).max(), np.abs(e_rot - e_ref[:, 2]).max())
print(f"max |reduced-form error - edge_errors| = {err:.2e}")
assert err < 1e-10
Bt = design_matrix(small).toarray()
assert np.array_equal(Bt[:2 * small.n_edges, :2 * 7], np.kron(A2.T, np.eye(2)))
print("design_matrix(small)[:2m, :2n] == A2ᵀ ⊗ I2: True")

# %%
fig, ax = plt.subplots(figsize=(5.5, 5.5))
plotting.plot_trajectory(ax, truth8, label="odometric edges (k → k+1)", color="tab:blue", linewidth=1.5,
                         style="-o", markersize=4)
plotting.plot_edges(ax, small, truth8, which="loop_closures", color="tab:red", linewidth=1.5, alpha=0.8,
                    label="loop closures (k → k+4)")
ax.quiver(truth8[:, 0], truth8[:, 1], np.cos(truth8[:, 2]), np.sin(truth8[:, 2]), angles="xy",
          scale_units="xy", scale=4, width=0.006, color="k")
for i, (px, py) in enumerate(truth8[:, :2]):
    ax.annotate(f"{i}" + (" (anchor)" if i == 0 else ""), (px, py), textcoords="offset points",
                xytext=(6, 6), fontsize=11)
ax.set_title("A small pose graph: 8 poses, 11 edges\n(arrows: headings θ; true poses)")
ax.legend(loc="center", fontsize=9)
save(fig, "graph")
plt.close(fig)

# %% [markdown]
# ## 4. The problem is non-convex
#
# The cost depends on the orientations through $R(\theta_i)$ and through the wrapped angular error,
# so it is $2\pi$-periodic in every $\theta_i$. A convex function that is periodic along a line is
# constant on it; χ² is not constant, so **χ² is not convex**. Concretely, let $x^\star$ be a
# minimiser (here: Gauss–Newton, `lago_cvx.refine`, started at the truth of the small graph) and move
# along the straight line $x(\phi) = x^\star + \phi\, e_{\theta_2}$, rotating pose 2 only. Then
#
# * $x(2\pi)$ describes the *same* physical configuration: $\chi^2(x(2\pi)) = \chi^2(x^\star)$;
# * the midpoint $x(\pi)$ (pose 2 turned around) costs more, so Jensen's inequality
#   $\chi^2(\tfrac12 x^\star + \tfrac12 x(2\pi)) \le \tfrac12\chi^2(x^\star) + \tfrac12 \chi^2(x(2\pi))$ fails;
# * on $[-3\pi, 3\pi]$ the curve has (at least) three separate local minima.

# %%
x_star = refine(small, truth8 - truth8[0], tolerance=1e-15).poses
phi = np.linspace(-3 * np.pi, 3 * np.pi, 1201)
K_POSE = 2


def along(ph):
    x = x_star.copy()
    x[K_POSE, 2] += ph
    return x


curve = np.array([lc.chi2(small, along(ph)) for ph in phi])
f0, f2pi, fpi = lc.chi2(small, x_star), lc.chi2(small, along(2 * np.pi)), lc.chi2(small, along(np.pi))
print(f"chi2(x*) = {f0:.4f}, chi2(x* + 2π e) = {f2pi:.4f}, chi2(midpoint) = {fpi:.1f}")
assert abs(f2pi - f0) < 1e-9 * max(f0, 1.0)
assert fpi > 0.5 * (f0 + f2pi) + 1.0                                # Jensen's inequality violated
interior = (curve[1:-1] < curve[:-2]) & (curve[1:-1] < curve[2:])
minima = phi[1:-1][interior]
print("local minima of chi2 along the line at φ/π =", np.round(minima / np.pi, 3))
assert minima.size >= 3

fig, ax = plt.subplots(figsize=(7, 3.8))
ax.plot(phi / np.pi, curve, color="tab:blue", label=r"$\chi^2(x^\star + \phi\, e_{\theta_2})$")
ax.plot(minima / np.pi, curve[1:-1][interior], "o", color="tab:red", label="local minima")
ax.plot([0, 2], [f0, f2pi], "k--", linewidth=1, label="chord between two minima")
ax.set_yscale("log")
ax.set_xlabel(r"rotation $\phi$ of pose 2 [units of $\pi$]")
ax.set_ylabel("χ² (g2o convention)")
ax.set_title("χ² along a straight line in pose space: periodic, multi-modal, not convex")
ax.legend(fontsize=9, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
save(fig, "nonconvex_rotation")
plt.close(fig)

# %% [markdown]
# ## 5. Local methods depend on the initial guess
#
# Iterative solvers (Gauss–Newton, Levenberg–Marquardt) linearise the cost at the current guess and
# converge to a *local* minimum near it. We run the package's Gauss–Newton (`lago_cvx.refine.refine`)
# on a synthetic Manhattan world with rather noisy rotations ($\sigma_\theta = 0.1$ rad) from three
# guesses: dead reckoning along the odometry (`odometry_guess`), LAGO's estimate and the truth. We
# verify that each end point is a genuine local minimum — one more Gauss–Newton step is negligible
# ($\|dx\|_\infty$, the solution of $J^\top J\, dx = -J^\top r$) and 200 random perturbations of size
# $10^{-3}$ all increase χ² — and that the odometry start ends in a different, far worse minimum.
# For a convex function every local minimum is global, so two local minima with different values are a
# second proof of non-convexity; the cost along the segment between them rises above the chord.

# %%
mw = lc.manhattan_world(200, seed=0, sigma_theta=0.1, sigma_xy=0.05)
gm = mw.graph
print(gm)
starts = {"dead reckoning": odometry_guess(gm), "LAGO": lc.lago(gm).poses, "truth": mw.truth.copy()}
runs = {name: refine(gm, x0, max_iterations=200, tolerance=1e-15) for name, x0 in starts.items()}
free = np.arange(1, gm.n_poses)
rng_p = np.random.default_rng(2)
for name, r in runs.items():
    res_w = whitened_residuals(gm, r.poses).reshape(-1)
    J = jacobian(gm, r.poses)
    dx = spla.spsolve((J.T @ J).tocsc(), -(J.T @ res_w))
    rises = []
    for _ in range(200):
        pert = r.poses.copy()
        pert[free] += 1e-3 * rng_p.standard_normal((free.size, 3))
        rises.append(lc.chi2(gm, pert) - r.chi2)
    print(f"GN from {name:15s}: chi2 {r.chi2_initial:12.1f} -> {r.chi2:9.3f} in {r.iterations:2d} steps; "
          f"next GN step |dx|max = {np.abs(dx).max():.1e}; min chi2 rise under perturbation = {min(rises):.3f}")
    assert np.abs(dx).max() < 1e-5 and min(rises) > 0
chi_dr, chi_lago, chi_true = (runs[k].chi2 for k in ("dead reckoning", "LAGO", "truth"))
assert abs(chi_lago - chi_true) < 1e-6 * chi_true                  # same (best known) minimum
assert chi_dr > 10 * chi_lago                                      # a different, much worse one

xa, xb = runs["dead reckoning"].poses, runs["LAGO"].poses
tt = np.linspace(0, 1, 201)
seg = np.array([lc.chi2(gm, (1 - s) * xa + s * xb) for s in tt])
chord = (1 - tt) * seg[0] + tt * seg[-1]
print(f"max over the segment of chi2 - chord = {np.max(seg - chord):.1f} (> 0: not convex)")
assert np.max(seg - chord) > 0

fig, axs = plt.subplots(1, 2, figsize=(12, 5))
plotting.plot_trajectory(axs[0], mw.truth, color="0.7", linewidth=3, label="truth")
plotting.plot_trajectory(axs[0], xa, color="tab:red", label=f"GN from dead reckoning, χ²={chi_dr:.0f}")
plotting.plot_trajectory(axs[0], xb, color="tab:blue", label=f"GN from LAGO, χ²={chi_lago:.1f}")
axs[0].set_title("Gauss–Newton: two starts, two local minima")
axs[0].legend(fontsize=9)
axs[1].plot(tt, seg, label="χ² on the segment")
axs[1].plot(tt, chord, "k--", linewidth=1, label="chord")
axs[1].set_yscale("log")
axs[1].set_xlabel("t  (x = (1−t)·x_deadreckoning-GN + t·x_LAGO-GN)")
axs[1].set_ylabel("χ² (g2o convention)")
axs[1].set_title("χ² between the two minima rises above the chord")
axs[1].legend(fontsize=9)
save(fig, "local_minima")
plt.close(fig)

# %% [markdown]
# ### The same on a real graph
#
# MIT (`se-sync/MIT.g2o`, 808 poses): Gauss–Newton from dead reckoning stops in a local minimum
# far above the one reached from LAGO's estimate (the reference minimum of the datasets README is
# χ² = 39.6013).

# %%
try:
    mit = lc.read_graph(dataset("se-sync/MIT.g2o"))
except DatasetNotFound as exc:
    print(f"real datasets not found: skipping the MIT example ({exc})")
else:
    print(mit)
    r_dr = refine(mit, odometry_guess(mit), max_iterations=100)
    r_lg = refine(mit, lc.lago(mit).poses, max_iterations=100)
    print(f"GN from dead reckoning: chi2 {r_dr.chi2_initial:.4g} -> {r_dr.chi2:.3f} ({r_dr.reason})")
    print(f"GN from LAGO:           chi2 {r_lg.chi2_initial:.4g} -> {r_lg.chi2:.3f} ({r_lg.reason})")
    assert r_dr.chi2 > 5 * r_lg.chi2
    assert abs(r_lg.chi2 - 39.6013) < 1e-3 * 39.6013

# %% [markdown]
# **Summary.** The maximum-likelihood problem is a non-linear least-squares problem on poses whose
# cost is periodic in every orientation, hence non-convex with many local minima; where a local solver
# ends depends on where it starts. LAGO (Lectures 2–3 and on) builds a good starting point by solving
# *linear* problems only: first the orientations (phase 1), then the positions (phases 2–3).

# %%
print(f"lecture 1 executed in {time.perf_counter() - T_START:.1f} s")
