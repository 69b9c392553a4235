# %% [markdown]
# # Lecture 2 — Phase 1: the orientations as a linear estimation problem
#
# Section IV-B of the seed (Carlone, Aragues, Castellanos, Bona, RSS 2011). LAGO's first phase
# estimates the orientations $\theta$ of the poses **from the relative orientation measurements
# $\delta$ alone**, by a linear weighted least-squares problem. This lecture checks, with the package
# `lago_cvx`:
#
# 1. Lemma 1 (as formulated here): the relative orientations are a *linear* model in $\theta$,
#    $\delta_{\rm reg} = A_2^\top \theta + \epsilon_\delta$, once the $2k\pi$ ambiguity is removed;
# 2. Proposition 1: $\operatorname{rank} A = \operatorname{rank} A_2 = n$ iff the graph is connected;
# 3. the BLUE of eq. (13), as an explicit cvxpy problem and as a sparse closed form;
# 4. its information matrix $A_2 P_\delta^{-1} A_2^\top$ — a weighted graph Laplacian;
# 5. a Monte-Carlo check that $\hat\theta$ is unbiased with covariance $P_\theta = (A_2 P_\delta^{-1}
#    A_2^\top)^{-1}$.
#
# Notation as in Lecture 1: poses $0, \dots, n$ (package: `n_poses` $= n + 1$), anchor 0, $m$ edges,
# incidence matrix $A$ ($(n+1) \times m$), reduced incidence $A_2$ ($n \times m$, anchor row deleted),
# $P_\delta = \mathrm{diag}(P_{\delta,ij})$ the variances of the relative orientations.

# %%
import time


import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph

from _lecture import figure_saver, paper_lago
import lago_cvx as lc
from lago_cvx import phases as P
from lago_cvx.datasets import DatasetNotFound, dataset
from lago_cvx.solvers import solve
from lago_cvx.uncertainty import edge_uncertainty
from lago_cvx.graph import check_connected, connected_components, spanning_tree
from lago_cvx.metrics import relative_difference
from lago_cvx.errors import GraphError
from lago_cvx.posegraph import wrap_angle
from lago_cvx.regularization import regularize

save = figure_saver("02_phase1")

T_START = time.perf_counter()

try:
    INTEL = lc.read_graph(dataset("carlone/INTEL_P_toro.graph"))
    print("real graph:", INTEL)
except DatasetNotFound as exc:
    INTEL = None
    print(f"real datasets not found: skipping the real-data cells ({exc})")

# %% [markdown]
# ## 1. Lemma 1 — relative orientations are linear in $\theta$ (as formulated here)
#
# With the anchor's orientation fixed, $\theta_0 = 0$, the true relative orientation of edge
# $k = (i \to j)$ is $\theta_j - \theta_i = (A^\top \theta)_k = (A_2^\top \theta_{1:n})_k$. The
# measurement is $\delta_k = \theta_j - \theta_i + \epsilon_{\delta,k}$ **up to a multiple of
# $2\pi$**: a sensor reports angles in $[-\pi, \pi)$. The linear model is therefore stated for the
# *regularized* measurements $\delta_{\rm reg} = \delta + 2\pi k$ (Section IV-E, `lago_cvx.regularize`,
# Lecture 5):
#
# $$\delta_{\rm reg} = A_2^\top \theta + \epsilon_\delta, \qquad \epsilon_\delta \sim \mathcal N(0,
#   P_\delta), \tag{8}$$
#
# where $\theta \in \mathbb{R}^n$ are the orientations *lifted* to the branch chosen by the spanning
# tree: $\theta^\star_v \equiv \theta^{\rm true}_v - \theta^{\rm true}_0 \pmod{2\pi}$, with the integer
# multiple of $2\pi$ fixed by integrating $\delta$ along the tree. What we check:
#
# * **noiseless winding world** (a circle driven 3 times, θ up to $6\pi$): the raw $\delta$ violate
#   $\delta = A_2^\top \theta$ by multiples of $2\pi$; after regularization there is $\hat\theta$ (phase
#   1's output) with $A_2^\top \hat\theta = \delta_{\rm reg}$ to round-off and $\hat\theta \equiv
#   \theta^{\rm true} - \theta^{\rm true}_0 \pmod{2\pi}$;
# * **noisy world**: with $\theta^\star$ the lifted truth, the residual of the linear model is *exactly*
#   the wrapped measurement noise, $\delta_{\rm reg} - A^\top \theta^\star = \mathrm{wrap}(\delta -
#   A^\top\theta^{\rm true})$ for every edge (no stray $2\pi$), and standardised by $\sqrt{P_\delta}$ it
#   has mean ≈ 0 and standard deviation ≈ 1.

# %%
w0 = lc.circle_world(60, laps=3, seed=0, sigma_xy=0.0, sigma_theta=0.0)
g0 = w0.graph
tree0 = spanning_tree(g0, "odometry")
reg0 = regularize(g0, tree0)
unc0 = edge_uncertainty(g0)
ph0 = P.phase1_closed_form(g0, reg0.delta_reg, unc0)
A2_0 = lc.reduced_incidence(g0).toarray()
th_rel = w0.truth[:, 2] - w0.truth[0, 2]
raw = A2_0.T @ th_rel[1:] - g0.delta
print(g0)
print(f"raw δ: max |A2ᵀθ_true - δ| = {np.abs(raw).max():.4f} = {np.abs(raw).max() / np.pi:.3f} π; "
      f"edges off by 2πk: {np.sum(np.abs(raw) > 1)}")
print(f"regularized: {reg0.n_regularized} chords corrected; max |A2ᵀθ̂ - δ_reg| = "
      f"{np.abs(A2_0.T @ ph0.theta_free - reg0.delta_reg).max():.2e}")
print(f"max |θ̂ - (θ_true - θ_true,0)| = {np.abs(ph0.theta - th_rel).max():.2e} (no wrapping needed: the odometric "
      f"tree lifts θ̂ to the true branch, θ̂ spans [{ph0.theta.min():.2f}, {ph0.theta.max():.2f}] rad)")
assert np.abs(raw).max() > 6 and np.allclose(raw / (2 * np.pi), np.rint(raw / (2 * np.pi)), atol=1e-9)
assert np.abs(A2_0.T @ ph0.theta_free - reg0.delta_reg).max() < 1e-9
assert np.abs(ph0.theta - th_rel).max() < 1e-9

# %%
w1 = lc.circle_world(300, laps=4, seed=1, sigma_xy=0.05, sigma_theta=0.02)
g1 = w1.graph
reg1 = regularize(g1, spanning_tree(g1, "bfs"))
unc1 = edge_uncertainty(g1)
A1 = lc.incidence_matrix(g1)
th_true = w1.truth[:, 2] - w1.truth[0, 2]
th_star = th_true + 2 * np.pi * np.rint((reg1.theta_tree - th_true) / (2 * np.pi))   # lifted truth
eps = reg1.delta_reg - A1.T @ th_star
noise = wrap_angle(g1.delta - A1.T @ th_true)
z = eps / np.sqrt(unc1.var_delta)
print(g1)
print(f"max |(δ_reg - Aᵀθ*) - wrap(δ - Aᵀθ_true)| = {np.abs(eps - noise).max():.2e}")
print(f"standardised residual: mean {z.mean():+.3f}, std {z.std():.3f}, max |.| {np.abs(z).max():.2f} over m = {z.size}")
assert np.abs(eps - noise).max() < 1e-9
assert abs(z.mean()) < 4 / np.sqrt(z.size) and abs(z.std() - 1) < 0.1 and np.abs(z).max() < 5

# %% [markdown]
# ## 2. Proposition 1 — $\operatorname{rank} A = \operatorname{rank} A_2 = n$ iff the graph is connected
#
# *Derivation.* $\mathbf 1^\top A = 0$ (each column has one $+1$ and one $-1$), so
# $\operatorname{rank} A \le n$. More precisely, $A^\top v = 0$ means $v_i = v_j$ across every
# edge, so the left null space of $A$ is spanned by the indicator vectors of the connected components:
# $\operatorname{rank} A = (n+1) - c$ with $c$ the number of components. Deleting the anchor's row does
# not lower the rank (that row is minus the sum of the other rows of its component), so
# $\operatorname{rank} A_2 = \operatorname{rank} A = n + 1 - c$, which equals $n$ iff $c = 1$.
# Consequence: $A_2 P_\delta^{-1} A_2^\top$ is invertible — phase 1 has a unique solution — iff the
# graph is connected.
#
# We check $\operatorname{rank} A = \operatorname{rank} A_2 = $ `n_poses` $- c$ (dense SVD rank) on
# connected graphs with several anchors and on graphs made disconnected by deleting edges, with $c$
# from `lago_cvx.graph.connected_components`; `check_connected` must reject the disconnected ones.

# %%
def ranks(g, anchor=0):
    A = lc.incidence_matrix(g).toarray()
    A2 = lc.reduced_incidence(g, anchor).toarray()
    return np.linalg.matrix_rank(A), np.linalg.matrix_rank(A2), connected_components(g)[0]


cases = []
for seed in range(3):
    cases.append((f"random_graph(30, 50, seed={seed})", lc.random_graph(30, 50, seed=seed).graph, seed * 7))
circ = lc.circle_world(40, laps=2, seed=0).graph
cases.append(("circle_world(40, laps=2)", circ, 0))
rg = lc.random_graph(30, 50, seed=0).graph
cases.append(("random graph, edges of pose 7 removed", rg.subgraph_edges((rg.tails != 7) & (rg.heads != 7)), 0))
cases.append(("random graph, edges of the anchor removed", rg.subgraph_edges((rg.tails != 0) & (rg.heads != 0)), 0))
half = circ.tails < 20
cases.append(("circle world cut in two halves", circ.subgraph_edges(half == (circ.heads < 20)), 5))
chain = lc.random_graph(12, 11, seed=4, spanning="odometry").graph            # a path
cases.append(("path with 3 edges removed", chain.subgraph_edges(~np.isin(np.arange(11), [2, 5, 8])), 0))

print(f"{'graph':45s} n_poses  c  rank A  rank A2  connected?")
for name, g, anchor in cases:
    rA, rA2, c = ranks(g, anchor)
    try:
        check_connected(g)
        connected = True
    except GraphError:
        connected = False
    print(f"{name:45s} {g.n_poses:6d} {c:3d} {rA:6d} {rA2:7d}   {connected}")
    assert rA == rA2 == g.n_poses - c
    assert (rA2 == g.n_poses - 1) == (c == 1) == connected

# %% [markdown]
# On the real INTEL graph (1228 poses) a dense SVD is slow on this machine, so we use the equivalent
# statement $\operatorname{rank} A_2 = n \iff A_2 A_2^\top \succ 0$, tested by its smallest eigenvalue
# (sparse shift-invert Lanczos, `scipy.sparse.linalg.eigsh`)
# (together with $\mathbf 1^\top A = 0$ this gives $\operatorname{rank} A = n$ too). Cutting the graph
# into poses $< 600$ and $\ge 600$ makes $A_2 A_2^\top$ singular.

# %%
if INTEL is None:
    print("real datasets not found: skipping Proposition 1 on INTEL")
else:
    def lambda_min(g):
        """Smallest eigenvalue of the grounded Laplacian A2 A2ᵀ (sparse shift-invert Lanczos)."""
        L = (lc.reduced_incidence(g) @ lc.reduced_incidence(g).T).tocsc()
        return spla.eigsh(L, k=1, sigma=-1e-2, which="LM", return_eigenvectors=False)[0]
    cut = INTEL.subgraph_edges((INTEL.tails < 600) == (INTEL.heads < 600))
    lam, lam_cut = lambda_min(INTEL), lambda_min(cut)
    c, c_cut = connected_components(INTEL)[0], connected_components(cut)[0]
    print(f"INTEL:                 components {c}, λ_min(A2 A2ᵀ) = {lam:.2e}  -> rank A2 = n")
    print(f"INTEL cut at pose 600: components {c_cut}, λ_min(A2 A2ᵀ) = {lam_cut:.2e} -> rank A2 < n")
    assert c == 1 and lam > 1e-8
    assert c_cut == 2 and abs(lam_cut) < 1e-10

# %% [markdown]
# ## 3. The BLUE of eq. (13): cvxpy problem and closed form
#
# Model (8) is linear with Gaussian noise, so the best linear unbiased estimator (and maximum-likelihood
# estimator) is the weighted least-squares solution
#
# $$\hat\theta = \arg\min_\theta \big\|P_\delta^{-1/2}(A_2^\top \theta - \delta_{\rm reg})\big\|^2
#   = (A_2 P_\delta^{-1} A_2^\top)^{-1} A_2 P_\delta^{-1} \delta_{\rm reg}, \qquad
#   P_\theta = (A_2 P_\delta^{-1} A_2^\top)^{-1}. \tag{13}$$
#
# `lago_cvx.phases.phase1_problem` writes the left-hand form as a cvxpy problem (solved with Clarabel);
# `phase1_closed_form` the right-hand form (a sparse factorization of $A_2 P_\delta^{-1} A_2^\top$ with
# corrected semi-normal-equation refinement). We print the cvxpy problem of a 6-pose graph, then solve
# both ways on larger graphs and require agreement to $10^{-9}$ relative; we also compare with the
# dense formula and check the normal equations $A_2 P_\delta^{-1}(A_2^\top\hat\theta - \delta_{\rm reg}) = 0$.

# %%
tiny = lc.random_graph(6, 9, seed=0).graph
res_tiny = paper_lago(tiny)
prob_tiny, theta_var = P.phase1_problem(tiny, res_tiny.regularization.delta_reg, res_tiny.uncertainty)
print("cvxpy problem of phase 1 (6 poses, 9 edges; theta has", theta_var.shape[0], "entries):")
print(prob_tiny)
print("\nclosed form θ̂ =", np.round(res_tiny.phase1.theta_free, 6))
solve(prob_tiny)
print("cvxpy       θ̂ =", np.round(theta_var.value, 6))


def check_blue(g, label):
    res = paper_lago(g)
    d_reg, unc = res.regularization.delta_reg, res.uncertainty
    t = time.perf_counter()
    ph_cvx, _ = P.phase1_from_problem(g, d_reg, unc)
    t_cvx = time.perf_counter() - t
    t = time.perf_counter()
    ph_cf = P.phase1_closed_form(g, d_reg, unc)
    t_cf = time.perf_counter() - t
    diff = relative_difference(ph_cvx.theta_free, ph_cf.theta_free)
    A2 = lc.reduced_incidence(g)
    Wd = sp.diags(1.0 / unc.var_delta)
    grad = A2 @ Wd @ (A2.T @ ph_cf.theta_free - d_reg)
    line = (f"{label}: max|cvxpy - closed form| / max|closed form| = {diff:.1e} "
            f"(cvxpy {t_cvx * 1e3:.0f} ms, closed form {t_cf * 1e3:.0f} ms); "
            f"max |normal-equation residual| = {np.abs(grad).max():.1e}")
    if g.n_poses <= 400:
        N = (A2 @ Wd @ A2.T).toarray()
        dense = np.linalg.solve(N, A2 @ Wd @ d_reg)
        line += f"; vs dense formula {relative_difference(ph_cf.theta_free, dense):.1e}"
        assert relative_difference(ph_cf.theta_free, dense) < 1e-9
    print(line)
    assert diff < 1e-9
    assert np.abs(grad).max() < 1e-6 * np.abs(A2 @ Wd @ d_reg).max()
    return res


check_blue(tiny, "random_graph(6, 9)")
check_blue(lc.random_graph(50, 120, seed=2, information="full").graph, "random_graph(50, 120, full info)")
res_m = check_blue(lc.manhattan_world(300, seed=1).graph, "manhattan_world(300)")
res_intel = None
if INTEL is None:
    print("real datasets not found: skipping eq. (13) on INTEL")
else:
    res_intel = check_blue(INTEL, "INTEL (real)")

# %% [markdown]
# **Why "best".** Any other linear unbiased estimator $K\delta_{\rm reg}$ ($K A_2^\top = I$) has
# covariance $K P_\delta K^\top \succeq P_\theta$ (Gauss–Markov). Two examples on the 300-pose
# Manhattan world, whose orientation variances we make unequal (each edge's $P_\delta$ multiplied by a
# random factor between 0.1 and 10, otherwise all weights would be equal and unweighted least squares
# would coincide with the BLUE): integrating $\delta$ along the spanning tree (what dead reckoning
# does) and the unweighted least squares $K = (A_2A_2^\top)^{-1}A_2$. We check that both are unbiased
# ($KA_2^\top = I$) and that $K P_\delta K^\top - P_\theta$ has no negative eigenvalue.

# %%
g_m = res_m.graph
scale = 10.0 ** np.random.default_rng(5).uniform(-1, 1, g_m.n_edges)
info_het = g_m.information.copy()
info_het[:, 2, 2] /= scale
g_het = lc.PoseGraph(g_m.n_poses, g_m.tails, g_m.heads, g_m.delta_l, g_m.delta, info_het)
res_het = paper_lago(g_het)
A2m = lc.reduced_incidence(g_het).toarray()
Pd = res_het.uncertainty.var_delta
P_theta = np.linalg.inv(res_het.phase1.info.toarray())
K_tree = np.column_stack([res_het.tree.integrate(g_het, np.eye(g_het.n_edges)[k])[1:]
                          for k in range(g_het.n_edges)])
K_ls = np.linalg.solve(A2m @ A2m.T, A2m)
for name, K in [("tree integration", K_tree), ("unweighted LS", K_ls)]:
    unbiased = np.abs(K @ A2m.T - np.eye(A2m.shape[0])).max()
    C = (K * Pd) @ K.T
    lam = np.linalg.eigvalsh(C - P_theta)
    print(f"{name:17s}: max|K A2ᵀ - I| = {unbiased:.1e}; eig(K P_δ Kᵀ - P_θ) in [{lam.min():.1e}, {lam.max():.1e}]; "
          f"tr(K P_δ Kᵀ) / tr(P_θ) = {np.trace(C) / np.trace(P_theta):.2f}")
    assert unbiased < 1e-9 and lam.min() > -1e-10 * lam.max() and np.trace(C) > np.trace(P_theta)

# %% [markdown]
# ## 4. The information matrix $A_2 P_\delta^{-1} A_2^\top$ is a weighted graph Laplacian
#
# $(A P_\delta^{-1} A^\top)_{uv} = \sum_k A_{uk} A_{vk} / P_{\delta,k}$: on the diagonal the sum of the
# weights $w_k = 1/P_{\delta,k}$ of the edges at pose $u$, off the diagonal $-\sum$ of the weights of
# the edges joining $u$ and $v$ (zero if none). That is the Laplacian $L = D - W$ of the graph
# weighted by the orientation information; $\Omega_\theta = A_2 P_\delta^{-1} A_2^\top$ is $L$ with
# the anchor's row and column deleted (the *grounded* Laplacian). Hence it is as sparse as the graph
# itself ($n + 2\times$#adjacent pairs nonzeros), symmetric, with non-positive off-diagonal entries,
# diagonally dominant, and (Proposition 1) positive definite for a connected graph.
#
# We build $L$ independently from the weighted adjacency matrix with `scipy.sparse.csgraph.laplacian`
# and compare it with `Phase1.info`.

# %%
def check_laplacian(res, label):
    g, info = res.graph, res.phase1.info
    w = 1.0 / res.uncertainty.var_delta
    Wadj = sp.coo_matrix((w, (g.tails, g.heads)), shape=(g.n_poses,) * 2).tocsr()
    L = csgraph.laplacian((Wadj + Wadj.T).tocsr()).tocsr()
    keep = np.arange(1, g.n_poses)
    L2 = L[keep][:, keep]
    diff = abs(info - L2).max() / abs(L2).max()
    off = (info - sp.diags(info.diagonal())).tocsr()
    off.eliminate_zeros()
    rowsum = np.asarray(L.sum(axis=1)).ravel()
    pairs = np.unique(np.sort(np.column_stack([g.tails, g.heads]), axis=1), axis=0)
    n_free_pairs = int(np.sum(pairs.min(axis=1) > 0))
    print(f"{label}: max|info - grounded Laplacian| / max|L| = {diff:.1e}; largest stored off-diagonal entry = {off.data.max():.1e}; "
          f"max|row sums of L| / max|L| = {np.abs(rowsum).max() / abs(L).max():.1e}; "
          f"nnz(info) = {info.nnz} = d + 2·#pairs = {g.n_poses - 1 + 2 * n_free_pairs}; "
          f"density {info.nnz / (g.n_poses - 1) ** 2:.2%}")
    assert diff < 1e-12 and off.data.max() < 0 and np.abs(rowsum).max() < 1e-12 * abs(L).max()
    assert abs(info - info.T).max() == 0
    assert info.nnz == g.n_poses - 1 + 2 * n_free_pairs
    margin = info.diagonal() - np.asarray(abs(off).sum(axis=1)).ravel()
    assert margin.min() > -1e-9 * info.diagonal().max()                 # diagonally dominant
    np.linalg.cholesky(info.toarray())                                  # positive definite


check_laplacian(res_m, "manhattan_world(300)")
if res_intel is not None:
    check_laplacian(res_intel, "INTEL (real)")

# %%
panels = [(r"manhattan_world(300): $\Omega_\theta = A_2 P_\delta^{-1} A_2^\top$", res_m)]
if res_intel is not None:
    panels.append((r"INTEL (real): $\Omega_\theta = A_2 P_\delta^{-1} A_2^\top$", res_intel))
fig, axs = plt.subplots(1, len(panels), figsize=(6 * len(panels), 6), squeeze=False)
for ax, (title, res) in zip(axs[0], panels):
    info = res.phase1.info
    ax.spy(info, markersize=1.0 if info.shape[0] > 500 else 1.5, color="tab:blue")
    ax.set_title(f"{title}\n{info.shape[0]}×{info.shape[0]}, nnz = {info.nnz} "
                 f"({info.nnz / info.shape[0] ** 2:.2%})", fontsize=10)
    ax.set_xlabel("pose index (anchor removed)")
    ax.set_ylabel("pose index (anchor removed)")
fig.suptitle("Phase-1 information matrix: a grounded weighted Laplacian, as sparse as the graph\n"
             "(band = odometry chain, off-band dots = loop closures)", y=1.02)
save(fig, "information_spy")
plt.close(fig)

# %% [markdown]
# ## 5. Monte Carlo: $\hat\theta$ is unbiased with covariance $P_\theta = (A_2 P_\delta^{-1} A_2^\top)^{-1}$
#
# On a fixed 8-pose, 14-edge graph with true orientations in $\pm 3\pi$ and a *different* standard
# deviation $\sigma_k \in [0.005, 0.03]$ rad for every edge, we draw $N$ independent noise vectors
# $\epsilon_\delta \sim \mathcal N(0, P_\delta)$, form the measurements as a sensor would
# ($\delta = \mathrm{wrap}(\theta_j - \theta_i + \epsilon_\delta)$) in a new `PoseGraph`, regularize
# them along the fixed spanning tree (`regularize`) and run `phase1_closed_form`. Phase 1 is linear in
# $\delta_{\rm reg}$, so the only thing that could break unbiasedness is a wrong $2k\pi$ correction; at
# this noise level (cycle residuals of a few hundredths of a radian against a decision threshold of
# $\pi$) the regularization is trivially correct, and we verify it sample by sample: $\delta_{\rm reg} -
# A^\top\theta^\star$ must equal the drawn noise exactly, $\theta^\star$ being the truth lifted to the
# branch of the tree. Errors are compared modulo $2\pi$ (a tree edge near $\pm\pi$ may wrap
# differently from sample to sample, which shifts a whole subtree by $2\pi$ — the same orientations).
#
# Expected sampling error of a covariance estimated from $N$ Gaussian samples:
# $\mathbb E\|\hat S - P\|_F^2 \approx ((\operatorname{tr}P)^2 + \|P\|_F^2)/N$; we require the measured
# relative Frobenius error to be below 3 times that, and every component of the mean error within 4.5
# standard errors of 0.

# %%
base_w = lc.random_graph(8, 14, seed=3, sigma_xy=0.0, sigma_theta=0.0)
tails, heads, truth = base_w.graph.tails, base_w.graph.heads, base_w.truth
m_mc = tails.size
rng = np.random.default_rng(11)
sig = rng.uniform(0.005, 0.03, m_mc)
info_mc = np.zeros((m_mc, 3, 3))
info_mc[:, 0, 0] = info_mc[:, 1, 1] = 1 / 0.05**2
info_mc[:, 2, 2] = 1 / sig**2
d_true = truth[heads, 2] - truth[tails, 2]


def graph_with(delta):
    return lc.PoseGraph(8, tails, heads, base_w.graph.delta_l, delta, info_mc)


g_base = graph_with(wrap_angle(d_true))
tree_mc = spanning_tree(g_base, "bfs")
unc_mc = edge_uncertainty(g_base)
ph_base = P.phase1_closed_form(g_base, regularize(g_base, tree_mc).delta_reg, unc_mc)
theta_star = ph_base.theta_free                                   # noiseless phase 1 = lifted truth
assert np.abs(wrap_angle(ph_base.theta - (truth[:, 2] - truth[0, 2]))).max() < 1e-9
P_theta_mc = np.linalg.inv(ph_base.info.toarray())
A_mc = lc.incidence_matrix(g_base)
print(g_base, f"σ_δ from {sig.min():.3f} to {sig.max():.3f} rad; true θ in [{truth[:, 2].min():.2f}, {truth[:, 2].max():.2f}]")

N_MC = 2000
t_mc = time.perf_counter()
errs = np.empty((N_MC, 7))
reg_failures = 0
for s in range(N_MC):
    noise = sig * rng.standard_normal(m_mc)
    g_s = graph_with(wrap_angle(d_true + noise))
    reg = regularize(g_s, tree_mc)
    ph = P.phase1_closed_form(g_s, reg.delta_reg, unc_mc)
    lift = np.concatenate([[0.0], theta_star])
    lift = lift + 2 * np.pi * np.rint((reg.theta_tree - lift) / (2 * np.pi))
    reg_failures += np.abs(reg.delta_reg - A_mc.T @ lift - noise).max() > 1e-9
    errs[s] = wrap_angle(ph.theta_free - theta_star)
t_mc = time.perf_counter() - t_mc

mean = errs.mean(axis=0)
zscore = mean / np.sqrt(np.diag(P_theta_mc) / N_MC)
S = np.cov(errs, rowvar=False)
rel = np.linalg.norm(S - P_theta_mc) / np.linalg.norm(P_theta_mc)
expected = np.sqrt((np.trace(P_theta_mc) ** 2 + np.linalg.norm(P_theta_mc) ** 2) / N_MC) / np.linalg.norm(P_theta_mc)
print(f"{N_MC} samples in {t_mc:.1f} s; wrong 2kπ corrections: {reg_failures}")
print("mean error / standard error per pose:", np.round(zscore, 2))
print(f"‖S - P_θ‖_F / ‖P_θ‖_F = {rel:.3f} (expected sampling level ≈ {expected:.3f})")
print("sample std / predicted std per pose:", np.round(np.sqrt(np.diag(S) / np.diag(P_theta_mc)), 3))
assert reg_failures == 0
assert np.abs(zscore).max() < 4.5
assert rel < 3 * expected

# %% [markdown]
# **Summary.** Once the $2k\pi$ ambiguity is removed, the orientations obey a linear Gaussian model
# whose design matrix is the reduced incidence matrix; it has full rank exactly for connected graphs,
# and phase 1 is its BLUE — one sparse grounded-Laplacian solve, identical (to $10^{-9}$ and better)
# to the explicit cvxpy problem. Lecture 3 propagates $\hat\theta$ and its covariance $P_\theta$ to
# the relative positions (phase 2).

# %%
print(f"lecture 2 executed in {time.perf_counter() - T_START:.1f} s")
