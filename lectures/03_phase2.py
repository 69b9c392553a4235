# %% [markdown]
# # Lecture 3 — Phase 2: relative positions in the global frame, and their covariance
#
# Section IV-C of Carlone, Aragues, Castellanos, Bona (RSS 2011). Phase 1 (lecture 2) gave the
# orientations $\hat\theta$ with covariance $P_\theta = (A P_\delta^{-1} A^\top)^{-1}$. Once the
# orientations are fixed, the first equation of eq. (7), $A_2^\top p = R(\theta)\Delta^l$, is linear in
# the positions. Phase 2 prepares it: it rotates every relative position $\Delta^l_{ij}$ (measured in the
# frame of pose $i$) into the global frame with $\hat\theta_i$, and propagates the uncertainty of both
# $\Delta^l$ and $\hat\theta$ to first order. No optimization happens here.
#
# **The idea in one paragraph.** With the headings from phase 1, each measured displacement — recorded in
# the robot's own frame — can be turned into the map's frame. The turned displacement inherits two
# uncertainties: that of the measurement itself, and that of the heading used to turn it, which swings the
# displacement sideways like a lever, more the longer it is. Phase 2 does the turning and adds up both
# uncertainties to first order; the covariance it produces is dense, but its inverse is as sparse as the
# graph (figure of section 5), which is what makes phase 3 cheap. Below, the running example's odometric
# displacements turned by phase 1's headings and chained: far better than dead reckoning, yet the loops
# still do not close — that is left to phase 3.
#
# **Learning goals.** After this lecture you can
#
# * build the phase-2 vector $z$ of eq. (9) and the Jacobians $H$, $J$ of eq. (11);
# * derive the first-order covariance $P_z$ of eq. (10) and its explicit blocks;
# * state exactly when $P_\theta$ — and so $P_z$ — is entrywise non-zero, and build a counterexample;
# * explain why $P_z$ is dense while $P_z^{-1}$ has a sparse square root $W$, the matrix the package
#   hands to phase 3;
# * test a first-order covariance by Monte Carlo, and see where first order stops being exact.
#
# **Notation** (lecture 1's and 2's, and):
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $A$, $A_2 = A \otimes I_2$ | the reduced incidence matrices ($n\times m$, $2n\times 2m$) | `lc.reduced_incidence` |
# | $P_{\Delta^l}$, $P_\delta$ | $\mathrm{blkdiag}_k P_{\Delta^l,k}$ ($2\times2$, in the tail's frame), $\mathrm{diag}_k P_{\delta,k}$ | `result.uncertainty.cov_delta_l`, `.var_delta` |
# | $R = R(\hat\theta)$ | block-diagonal, the rotations of the edges' tails | `rot2(theta[graph.tails])` |
# | $S$ | $\begin{bmatrix}0&-1\\1&0\end{bmatrix}$: $\tfrac{d}{d\theta}R(\theta) = S R(\theta)$, commutes with every rotation | `lago_cvx.course.S` |
# | $z$, $P_z$ | the phase-2 vector $[\Delta^g; \hat\theta]$ and its covariance, eqs. (9)–(10) | `result.phase2` |
# | $H$, $J$ | the Jacobian of eq. (11) and its block $\partial(R\Delta^l)/\partial\theta$ | `result.phase2.jac` ($J$) |
# | $W$ | the sparse square root of $P_z^{-1}$ (section 5) | `result.phase2.W` |
#
# The paper's phase 2 is `lago_cvx.phases.phase2(..., information=
# "marginal")`; the package's default (`"full"`) goes beyond the paper and is not used here.

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)

# %%
import matplotlib.pyplot as plt
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

import lago_cvx as lc
from lago_cvx.course import S, check, intuition_figure, paper_lago, real, running_example, setup, show
from lago_cvx import phases, plotting
from lago_cvx.graph import spanning_tree
from lago_cvx.posegraph import between, rot2, wrap_angle
from lago_cvx.regularization import regularize
from lago_cvx.synthetic import add_noise
from lago_cvx.uncertainty import edge_uncertainty

setup("03_phase2")

# %% tags=["remove-input"]
show(intuition_figure("03"), "intuition")

# %% [markdown]
# ## 1. The phase-2 vector $z$, eq. (9)
#
# Phase 2 stacks the relative positions rotated into the global frame and the phase-1 orientations:
#
# $$z = \begin{bmatrix} R & 0 \\ 0 & I_n\end{bmatrix} \begin{bmatrix}\Delta^l \\ \hat\theta\end{bmatrix}
#     = \begin{bmatrix} g_1(\Delta^l, \hat\theta) \\ g_2(\hat\theta) \end{bmatrix}, \qquad
#     g_1 = R(\hat\theta)\Delta^l = \Delta^g, \quad g_2 = \hat\theta. \tag{9}$$
#
# $z$ has $2m + n$ entries: for every edge $(i, j)$, $\Delta^g_{ij} = R(\hat\theta_i)\Delta^l_{ij}$, an
# estimate of $p_j - p_i$. Keeping $\hat\theta$ inside $z$ is the trick that preserves the correlation
# between the rotated positions and the orientations. We run the paper's phases 1–2 on the running
# example and rebuild $z$ from eq. (9) by hand.

# %%
world = running_example()
g = world.graph
res = paper_lago(g)
ph2 = res.phase2
theta_hat = res.phase1.theta                                        # n + 1 entries, θ̂₀ = 0
m, n = g.n_edges, g.n_poses - 1
R = sla.block_diag(*rot2(theta_hat[g.tails]))
z_eq9 = np.concatenate([R @ g.delta_l.ravel(), theta_hat[1:]])
print(g, f"→ z has 2m + n = {ph2.z.size} entries")

# %% tags=["remove-input"]
check(ph2.information == "marginal" and np.abs(ph2.z - z_eq9).max() < 1e-12,
      f"the package's phase 2 (the paper's form) returns z of eq. (9) (max difference {np.abs(ph2.z - z_eq9).max():.0e})")

# %% [markdown]
# ## 2. The Jacobians $H$ and $J$, eq. (11)
#
# $z$ is a non-linear function of $(\Delta^l, \hat\theta)$, through $R(\hat\theta)$. Its Jacobian is
#
# $$H = \frac{\partial z}{\partial(\Delta^l, \hat\theta)} = \begin{bmatrix} R & J \\ 0 & I_n\end{bmatrix},
#   \qquad J = \frac{\partial (R\Delta^l)}{\partial\theta}. \tag{11}$$
#
# $\Delta^g_{ij}$ depends on the orientations only through its tail $i$, so $J$ ($2m \times n$) has one
# non-zero $2\times1$ block per edge — in the column of the tail, none when the tail is pose 0:
# $J_{k,i} = \tfrac{\partial}{\partial\theta_i}R(\theta_i)\Delta^l_{ij} = S R(\hat\theta_i)\Delta^l_{ij}
# = S\Delta^g_{ij}$ (the global relative position turned by 90°). We compare the package's `jac` with
# central finite differences of the package's own phase 2.

# %%
J = ph2.jac.toarray()
step = 1e-6
J_fd = np.zeros((2 * m, n))
for col in range(n):
    plus, minus = theta_hat.copy(), theta_hat.copy()
    plus[col + 1] += step
    minus[col + 1] -= step
    J_fd[:, col] = (phases.phase2(g, plus, res.uncertainty, information="marginal").delta_g
                    - phases.phase2(g, minus, res.uncertainty, information="marginal").delta_g).ravel() / (2 * step)
J_blocks = np.zeros((2 * m, n))
for k, i in enumerate(g.tails):
    if i != 0:
        J_blocks[2 * k:2 * k + 2, i - 1] = S @ ph2.delta_g[k]

# %% tags=["remove-input"]
check(np.abs(J - J_fd).max() < 1e-7 * np.abs(J).max(), f"J = ∂(RΔˡ)/∂θ (finite differences agree to {np.abs(J - J_fd).max():.0e})")
check(np.array_equal(J != 0, J_blocks != 0) and np.abs(J - J_blocks).max() < 1e-12,
      f"one block SΔᵍ per edge, in the tail's column: nnz(J) = {ph2.jac.nnz} = 2 × (edges not leaving pose 0)")

# %%
H = np.block([[R, J], [np.zeros((n, 2 * m)), np.eye(n)]])

# %% [markdown]
# ## 3. The first-order covariance $P_z$, eq. (10)
#
# Write $\Delta^l = \bar\Delta^l + \epsilon_{\Delta}$ and $\hat\theta = \bar\theta + \epsilon_\theta$. To
# first order $z - \bar z \approx H\,[\epsilon_\Delta;\ \epsilon_\theta]$. Phase 1 used $\delta$ only,
# and the paper's noise model makes $\Delta^l$ and $\delta$ independent, so $\epsilon_\Delta$ and
# $\epsilon_\theta$ are independent and
#
# $$P_z = H \begin{bmatrix} P_{\Delta^l} & 0 \\ 0 & P_\theta\end{bmatrix} H^\top, \tag{10}$$
#
# which written out (the explicit form in eq. (11)) is
#
# $$P_z = \begin{bmatrix} R P_{\Delta^l} R^\top + J P_\theta J^\top & J P_\theta \\
#                         P_\theta J^\top & P_\theta\end{bmatrix}.$$
#
# We build both forms densely and compare; and we count how much of $P_z$ is non-zero.

# %%
def dense_pz(graph, result):
    """P_z of eq. (10) from its definition (small graphs only), with H and P_θ."""
    unc, th = result.uncertainty, result.phase1.theta
    mm, nn = graph.n_edges, graph.n_poses - 1
    Rg = sla.block_diag(*rot2(th[graph.tails]))
    Jg = result.phase2.jac.toarray()
    Hg = np.block([[Rg, Jg], [np.zeros((nn, 2 * mm)), np.eye(nn)]])
    P_theta = np.linalg.inv(result.phase1.info.toarray())
    return Hg @ sla.block_diag(*unc.cov_delta_l, P_theta) @ Hg.T, Hg, P_theta

Pz, _, P_theta = dense_pz(g, res)
P_dl = sla.block_diag(*res.uncertainty.cov_delta_l)
explicit = np.block([[R @ P_dl @ R.T + J @ P_theta @ J.T, J @ P_theta], [P_theta @ J.T, P_theta]])
fill = np.mean(np.abs(Pz) > 1e-12 * np.abs(Pz).max())

# %% tags=["remove-input"]
check(np.abs(Pz - explicit).max() < 1e-12 * np.abs(Pz).max(), "H diag(P_Δˡ, P_θ) Hᵀ = the explicit blocks of eq. (11)")
check(fill > 0.8, f"P_z is dense: {fill:.0%} of its {Pz.size} entries are non-zero")

# %% [markdown]
# ## 4. When is $P_\theta$ entrywise positive?
#
# $P_z$ is dense because $P_\theta$ is: $J P_\theta J^\top$ couples every pair of edges whose tails have
# correlated orientations. It is tempting to say "$P_\theta$ is the inverse of a Laplacian, hence
# entrywise positive". That needs a condition. $P_\theta^{-1} = A P_\delta^{-1} A^\top$ is the Laplacian
# with the row and column of pose 0 deleted. Remove pose 0 and its edges from the graph: if what is left
# splits into components $V_1, \dots, V_r$, no edge joins two of them, so (after reordering) the
# grounded Laplacian is **block-diagonal** with one block per component, and so is its inverse. Each
# block is an irreducible non-singular M-matrix (its component is connected, and it touches pose 0), and
# the inverse of such a matrix is entrywise positive. Hence:
#
# > $(P_\theta)_{uv} > 0$ exactly when $u$ and $v$ are joined by a path that avoids pose 0, and
# > $(P_\theta)_{uv} = 0$ otherwise. $P_\theta$ is entrywise positive **if and only if the graph minus the
# > reference pose is connected** (pose 0 is not a cut vertex).
#
# For a single robot whose reference is the *first* pose this always holds — the odometric path
# $1 \to 2 \to \dots \to n$ of Lemma 1 survives the removal of pose 0. It fails as soon as the reference
# is a cut vertex, e.g. a pose in the middle of a corridor when the reference is chosen there (the
# package's `anchor=` option), or a hub that several robots' trajectories only share. The
# counterexample below is a "lollipop": a corridor of poses leading into a loop, with the reference at
# the pose where the corridor meets the loop. Orientation errors on the two sides are then independent.

# %%
def p_theta(graph, anchor):
    result = phases.phase1_closed_form(graph, regularize(graph, spanning_tree(graph, "bfs", anchor=anchor)).delta_reg,
                                       edge_uncertainty(graph), anchor=anchor)
    return np.linalg.inv(result.info.toarray()), result.anchor_index

def same_side(graph, anchor_index):
    """(u, v) → True when u and v are connected without passing through the reference (free poses)."""
    away = graph.subgraph_edges((graph.tails != anchor_index) & (graph.heads != anchor_index))
    _, label = lc.connected_components(away)
    label = np.delete(label, anchor_index)
    return label[:, None] == label[None, :], len(set(label))

corridor, loop = 5, 8                                                # poses 0–4 corridor, 5–12 loop
truth_l = np.zeros((corridor + loop, 3))
truth_l[:corridor, 0] = np.arange(corridor) - corridor
angles = np.linspace(0, 2 * np.pi, loop, endpoint=False)
truth_l[corridor:, :2] = np.column_stack([2 * np.sin(angles), 2 - 2 * np.cos(angles)])
truth_l[corridor:, 2] = angles
tails_l = np.concatenate([np.arange(corridor + loop - 1), [corridor + loop - 1, corridor]])
heads_l = np.concatenate([np.arange(1, corridor + loop), [corridor, corridor + 3]])
meas_l, info_l = add_noise(truth_l, tails_l, heads_l, sigma_xy=0.05, sigma_theta=0.02, rng=np.random.default_rng(5))
lollipop = lc.PoseGraph(corridor + loop, tails_l, heads_l, meas_l[:, :2], meas_l[:, 2], info_l, name="lollipop")
print(lollipop)
pattern, predicted = {}, {}
for anchor in (0, corridor):
    P_t, a = p_theta(lollipop, anchor)
    side, parts = same_side(lollipop, a)
    positive = P_t > 1e-12 * P_t.max()
    pattern[anchor] = (P_t, parts)
    print(f"reference pose {anchor}: graph minus it has {parts} component(s); "
          f"P_θ has {np.sum(~positive)} zero entries of {P_t.size}")
    predicted[anchor] = np.array_equal(positive, side) and np.all(np.abs(P_t[~side]) < 1e-12 * P_t.max())

# %% tags=["remove-input"]
for anchor, holds in predicted.items():
    check(holds, f"reference {anchor}: (P_θ)_uv > 0 exactly when u, v connect avoiding the reference")
check(pattern[0][1] == 1 and pattern[corridor][1] == 2, "entrywise positive with the first pose as reference, not with the cut vertex")

# %% [markdown]
# The same on the running example, which has no cut vertex among the references tried — $P_\theta$ is
# entrywise positive whichever of them is the reference — and on sparse random graphs (34 edges on 30
# poses), where some of the references tried are cut vertices (the checks print the components) and the
# components of the graph minus the reference predict the zero pattern exactly. On
# a real graph, MIT, with the reference at the cut vertex nearest to the middle of the run, the entries of
# $P_\theta$ between the two sides vanish (the cell prints how many).

# %%
graphs_4 = {"running example": running_example().graph}
for index in range(3):
    # own world: 34 edges on 30 poses leave many cut vertices, hence zero blocks in P_θ
    graphs_4[f"random graph {index}"] = lc.random_graph(30, 34, seed=index).graph
random_patterns = []
for label, rg in graphs_4.items():
    for anchor in (0, 7, 15):
        P_t, a = p_theta(rg, anchor)
        side, parts = same_side(rg, a)
        random_patterns.append((label, anchor, parts, np.array_equal(P_t > 1e-12 * P_t.max(), side), P_t.min() > 0))
mit = real("se-sync/MIT.g2o")
if mit is not None:
    by_distance = sorted(range(1, mit.n_poses - 1), key=lambda i: abs(i - mit.n_poses // 2))
    middle = next(i for i in by_distance if same_side(mit, i)[1] > 1)     # the cut vertex nearest the middle
    P_t, a = p_theta(mit, int(mit.ids[middle]))
    side, parts = same_side(mit, a)
    zero = np.mean(P_t <= 1e-12 * P_t.max())
    print(f"MIT, reference at pose {middle} (of {mit.n_poses}): the graph minus it has {parts} components; "
          f"{zero:.0%} of P_θ is zero")
    mit_predicted = parts > 1 and np.array_equal(P_t > 1e-12 * P_t.max(), side)

fig, axs = plt.subplots(1, 3, figsize=(15, 4.4))
plotting.plot_trajectory(axs[0], truth_l, style="-o", markersize=3, label="odometric path")
plotting.plot_edges(axs[0], lollipop, truth_l, which="loop_closures", color="tab:red", linewidth=1.2, label="loop closures")
for anchor, color in [(0, "tab:green"), (corridor, "tab:purple")]:
    axs[0].plot(*truth_l[anchor, :2], "s", ms=10, color=color, label=f"reference pose {anchor}")
axs[0].legend(fontsize=8)
axs[0].set_title("a lollipop: corridor + loop")
for ax, anchor in zip(axs[1:], (0, corridor)):
    P_t, parts = pattern[anchor]
    im = ax.imshow(np.log10(np.maximum(np.abs(P_t), 1e-16 * P_t.max())), cmap="viridis",
                   vmin=np.log10(P_t.max()) - 6)
    ax.set_title(f"log₁₀ |P_θ|, reference pose {anchor}\n(graph minus the reference: {parts} component(s))")
    ax.set_xlabel("free pose")
    fig.colorbar(im, ax=ax, shrink=0.8)
show(fig, "ptheta_positivity")

# %% tags=["remove-input"]
for label, anchor, parts, holds, positive in random_patterns:
    check(holds, f"{label}, reference {anchor}: {parts} component(s) without it, zero pattern predicted")
    if label == "running example":
        check(parts == 1 and positive, f"the running example minus pose {anchor} is connected: P_θ is entrywise positive")
tried = [parts for label, _, parts, _, _ in random_patterns if label != "running example"]
check(sum(p > 1 for p in tried) > 0, f"{sum(p > 1 for p in tried)} of the {len(tried)} references tried on the random "
      "graphs are cut vertices")
if mit is not None:
    check(mit_predicted, "MIT: the zero pattern of P_θ is the predicted one")

# %% [markdown]
# ## 5. $P_z$ is dense, $P_z^{-1}$ has a sparse square root $W$
#
# Phase 3 needs $P_z^{-1}$, not the dense $P_z$ of eq. (10). $H$ is block upper-triangular with
# invertible diagonal blocks ($R$ is orthogonal), so
#
# $$H^{-1} = \begin{bmatrix} R^\top & -R^\top J \\ 0 & I\end{bmatrix}, \qquad
#   P_z^{-1} = H^{-\top} \begin{bmatrix} P_{\Delta^l}^{-1} & 0 \\ 0 & P_\theta^{-1}\end{bmatrix} H^{-1}.$$
#
# Both diagonal blocks have sparse square roots: $P_{\Delta^l}^{-1} = U^\top U$ with $U$ block-diagonal
# (the upper Cholesky factor of each $P_{\Delta^l,k}^{-1}$, written $P_{\Delta^l}^{-1/2}$), and — the key
# point — $P_\theta^{-1} = A P_\delta^{-1} A^\top = L^\top L$ with $L = P_\delta^{-1/2} A^\top$
# ($m \times n$, two non-zeros per row): **no inverse needed**. Hence $P_z^{-1} = W^\top W$ with
#
# $$W = \begin{bmatrix} U & 0 \\ 0 & L\end{bmatrix} H^{-1}
#     = \begin{bmatrix} P_{\Delta^l}^{-1/2} R^\top & -P_{\Delta^l}^{-1/2} R^\top J \\ 0 & P_\delta^{-1/2} A^\top
#       \end{bmatrix} \qquad (3m \times (2m + n)).$$
#
# $R^\top J$ has the blocks $R(\hat\theta_i)^\top S R(\hat\theta_i)\Delta^l_{ij} = S\Delta^l_{ij}$ — it
# does not even depend on $\hat\theta$. Per edge $W$ has at most 8 non-zeros, while $P_z$ has
# $(2m + n)^2$ entries. `Phase2.W` is this $W$; we check it against the dense construction, check
# $W^\top W P_z = I$, and count non-zeros on the running example — and on INTEL, where $P_z$ is never
# formed.

# %%
def w_facts(graph, result):
    """(P_z, max |W − W_ref|, max |W_ref|, max |WᵀW P_z − I|, nnz(W), 8m) for Phase 2 on ``graph``."""
    Pz_g, Hg, _ = dense_pz(graph, result)
    mm, nn = graph.n_edges, graph.n_poses - 1
    U = sla.block_diag(*result.uncertainty.sqrt_info_delta_l)
    L = result.uncertainty.sqrt_info_delta[:, None] * lc.reduced_incidence(graph).toarray().T
    W_ref = sla.block_diag(U, L) @ np.linalg.inv(Hg)
    W = result.phase2.W.toarray()
    inverse = np.abs(W.T @ W @ Pz_g - np.eye(2 * mm + nn)).max()
    return Pz_g, np.abs(W - W_ref).max(), np.abs(W_ref).max(), inverse, result.phase2.W.nnz, 8 * mm

mw = running_example().graph
res_m = paper_lago(mw)
facts_w = {"running example": w_facts(mw, res_m)}
Pz_m = facts_w["running example"][0]
WtW_m = (res_m.phase2.W.T @ res_m.phase2.W).tocsr()

intel = real("carlone/INTEL_P_toro.graph")
if intel is not None:
    W_i = paper_lago(intel).phase2.W
    size_i, WtW_i = 2 * intel.n_edges + intel.n_poses - 1, W_i.T @ W_i
    print(f"INTEL (m = {intel.n_edges}, n = {intel.n_poses - 1}): P_z would have {size_i**2:,} entries; "
          f"W has {W_i.nnz:,} non-zeros (8m = {8 * intel.n_edges:,}); WᵀW is {WtW_i.nnz / size_i**2:.3%} non-zero")

fig, axs = plt.subplots(1, 3, figsize=(15, 5))
nonzero = np.abs(Pz_m) > 1e-12 * np.abs(Pz_m).max()
axs[0].spy(nonzero, markersize=0.6, color="tab:red")
axs[0].set_title(f"$P_z$ (eq. 10): {nonzero.mean():.0%} non-zero")
axs[1].spy(WtW_m, markersize=0.6, color="tab:blue")
axs[1].set_title(f"$P_z^{{-1}} = W^\\top W$: {WtW_m.nnz / Pz_m.size:.1%} non-zero")
axs[2].spy(res_m.phase2.W, markersize=0.6, color="tab:green", aspect="auto")
axs[2].set_title(f"$W$ ({res_m.phase2.W.shape[0]}×{res_m.phase2.W.shape[1]}): {res_m.phase2.W.nnz} non-zeros")
for ax in axs:
    ax.set_xlabel("entry of z = [Δᵍ (2m); θ̂ (n)]")
    ax.set_ylabel("row")
fig.suptitle(f"Phase 2 on the running example (m = {mw.n_edges}, n = {mw.n_poses - 1}): dense covariance, sparse inverse", y=1.02)
show(fig, "spy")

# %% tags=["remove-input"]
for label, (Pz_g, w_error, w_scale, inverse, nnz, bound) in facts_w.items():
    check(w_error < 1e-10 * w_scale, f"{label}: Phase2.W = blkdiag(P_Δˡ^(−1/2), P_δ^(−1/2)Aᵀ) H⁻¹")
    check(inverse < 1e-8, f"{label}: WᵀW P_z = I (max deviation {inverse:.0e})")
    check(nnz <= bound, f"{label}: nnz(W) = {nnz} ≤ 8m = {bound}; P_z has {Pz_g.size} entries")
check(WtW_m.nnz < 0.1 * Pz_m.size, "the information P_z⁻¹ = WᵀW is sparse")
if intel is not None:
    check(W_i.nnz <= 8 * intel.n_edges and WtW_i.nnz < 1e-3 * size_i**2, "INTEL: nnz(W) ≤ 8m, and WᵀW is sparser than 0.1 %")

# %% [markdown]
# ## Exercise 1 — Why $W$ hardly depends on $\hat\theta$
#
# *Derive.* Show that $R(\theta)^\top S R(\theta) = S$ for every $\theta$, and conclude that the block
# $-P_{\Delta^l}^{-1/2} R^\top J$ of $W$ does not depend on $\hat\theta$: only the rotations in its first block
# column do. Write `theta_columns(graph)`, the mask of the columns of $W$ that change with $\hat\theta$; the check
# runs phase 2 at several orientation vectors and compares. (Careful with the edges that leave pose 0.)
#
# **Hint.** Write $R(\theta) = \cos\theta\, I + \sin\theta\, S$: $S$ commutes with every rotation.

# %%
# your solution here: fill in the body of theta_columns, then run the cell (check_theta_columns tests it)
from lago_cvx.exercises import check_theta_columns

def theta_columns(graph):
    """A bool mask (2m + n,): True for the columns of W that change with θ̂."""
    raise NotImplementedError

check_theta_columns(theta_columns)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. R(θ)ᵀ S R(θ) = S: plane rotations commute. The block of edge k of RᵀJ is
# R(θ̂_i)ᵀ S R(θ̂_i) Δˡ_k = S Δˡ_k whatever θ̂, so in W = [[P_Δˡ^(−½)Rᵀ, −P_Δˡ^(−½)RᵀJ], [0, P_δ^(−½)Aᵀ]] only
# the first block column changes with θ̂ — except the blocks of the edges leaving pose 0, whose θ̂₀ = 0 is fixed.
import numpy as np
from lago_cvx.exercises import check_theta_columns

def theta_columns(graph):
    n = graph.n_poses - 1
    return np.concatenate([np.repeat(graph.tails != 0, 2), np.zeros(n, bool)])

check_theta_columns(theta_columns).require()

# %% [markdown]
# ## 6. Monte Carlo: the first-order covariance, and where first order stops being exact
#
# Phase 1 is linear in $\delta$, phase 2 is not: $\Delta^g = R(\hat\theta_i)\Delta^l$ is non-linear in
# $\hat\theta$. The first-order $P_z$ is exact only in the limit of small noise; its relative error is of
# order $\sigma_\theta^2$ (e.g. $\mathrm{Var}(\sin\epsilon) = \sigma^2 - \sigma^4 + \dots$ for
# $\epsilon \sim \mathcal N(0, \sigma^2)$).
#
# On a fixed graph (7 poses, 11 edges, relative positions up to ~20 m, so the lever arm $J$ matters) we
# draw measurements as a sensor would — noise on $\Delta^l$ and $\delta$, $\delta$ wrapped — and run
# `regularize` (fixed tree), then phases 1–2 (eqs. (13) and (9) with the weights fixed, one matrix
# product each; the first draw checks them against the package's `phase1_closed_form` and `phase2`). The sample covariance $\hat S_z$ of
# $z$ is compared with the first-order $P_z$ at the true values, at two noise levels ten times apart,
# with the *same* standard-normal draws (common random numbers). To separate sampling noise from
# non-linearity we also form, from the same draws, the linearized samples $\bar z + H[\epsilon_\Delta;
# \hat\theta - \bar\theta]$, whose covariance is $P_z$ in expectation. All errors are relative Frobenius
# norms: the *sampling floor* $\|\hat S_{\rm lin} - P_z\|$ is the same at both levels; the
# *non-linearity* $\|\hat S_z - \hat S_{\rm lin}\|$ shrinks when $\sigma$ does.

# %%
# own world: 7 poses up to ~20 m apart — long lever arms, and a z small enough for 1000 draws
base = lc.random_graph(7, 11, seed=6, spread=10.0, sigma_xy=0.0, sigma_theta=0.0)
tails, heads, truth = base.graph.tails, base.graph.heads, base.truth
true_rel = between(truth[tails], truth[heads])
m_mc, n_mc = tails.size, 6
N_MC = 1000
xi = np.random.default_rng(7).standard_normal((N_MC, m_mc, 3))    # common random numbers

def graph_at(meas, sxy, sth):
    info = np.broadcast_to(np.diag([1 / sxy**2, 1 / sxy**2, 1 / sth**2]), (m_mc, 3, 3))
    return lc.PoseGraph(7, tails, heads, meas[:, :2], wrap_angle(meas[:, 2]), info)

def monte_carlo(sxy, sth):
    g_true = graph_at(true_rel, sxy, sth)
    tree, unc = spanning_tree(g_true, "bfs"), edge_uncertainty(g_true)
    ph1_t = phases.phase1_closed_form(g_true, regularize(g_true, tree).delta_reg, unc)
    ph2_t = phases.phase2(g_true, ph1_t.theta, unc, information="marginal")
    Pz_t = ph2_t.covariance_z()
    Rt, Jt = sla.block_diag(*rot2(ph1_t.theta[tails])), ph2_t.jac.toarray()
    A_mc = lc.reduced_incidence(g_true).toarray()
    K = np.linalg.solve((A_mc * unc.info_delta) @ A_mc.T, A_mc * unc.info_delta)   # eq. (13): θ̂ = K δ_reg
    scale = np.array([sxy, sxy, sth])
    dz, dz_lin = np.empty((N_MC, 2 * m_mc + n_mc)), np.empty((N_MC, 2 * m_mc + n_mc))
    for s in range(N_MC):
        eps = xi[s] * scale
        g_s = graph_at(true_rel + eps, sxy, sth)
        delta_reg = regularize(g_s, tree).delta_reg
        theta_s = np.concatenate([[0.0], K @ delta_reg])
        z_s = np.einsum("kab,kb->ka", rot2(theta_s[tails]), g_s.delta_l).ravel()            # eq. (9)
        if s == 0:                                       # the fast path is the package's phases 1–2
            ph1 = phases.phase1_closed_form(g_s, delta_reg, unc)
            ph2_s = phases.phase2(g_s, ph1.theta, unc, information="marginal")
            fast_path_error = np.abs(ph2_s.z - np.concatenate([z_s, theta_s[1:]])).max()
        d_th = wrap_angle(theta_s[1:] - ph1_t.theta_free)
        dz[s] = np.concatenate([z_s - ph2_t.z[:2 * m_mc], d_th])
        dz_lin[s] = np.concatenate([Rt @ eps[:, :2].ravel() + Jt @ d_th, d_th])
    S_z, S_lin = np.cov(dz, rowvar=False), np.cov(dz_lin, rowvar=False)
    norm = np.linalg.norm(Pz_t)
    return dict(total=np.linalg.norm(S_z - Pz_t) / norm, floor=np.linalg.norm(S_lin - Pz_t) / norm,
                nonlin=np.linalg.norm(S_z - S_lin) / norm, dz=dz, Pz=Pz_t, z_true=ph2_t.z, fast=fast_path_error)

levels = {"large": (0.1, 0.3), "small": (0.01, 0.03)}
mc = {name: monte_carlo(*sig) for name, sig in levels.items()}
print(base.graph, f"| largest |Δˡ| = {np.abs(true_rel[:, :2]).max():.1f} m | {N_MC} samples per level")
for name, (sxy, sth) in levels.items():
    r = mc[name]
    print(f"σ_xy = {sxy:4.2f} m, σ_θ = {sth:4.2f} rad: ‖S_z − P_z‖ = {r['total']:.4f}; "
          f"sampling floor {r['floor']:.4f}; non-linearity {r['nonlin']:.2e}")
large, small_noise = mc["large"], mc["small"]

k_edge = int(np.argmax(np.where(tails != 0, np.linalg.norm(true_rel[:, :2], axis=1), 0)))   # a long lever arm
fig, axs = plt.subplots(1, 3, figsize=(16, 5))
for ax, name in zip(axs[:2], levels):
    r = mc[name]
    centre = r["z_true"][2 * k_edge:2 * k_edge + 2]
    pts = centre + r["dz"][:, 2 * k_edge:2 * k_edge + 2]
    ax.plot(pts[:, 0], pts[:, 1], ".", markersize=2, color="0.5", label=f"{N_MC} Monte-Carlo samples")
    block = r["Pz"][2 * k_edge:2 * k_edge + 2, 2 * k_edge:2 * k_edge + 2][None]
    plotting.plot_covariances(ax, np.array([[centre[0], centre[1], 0.0]]), block, n_sigma=3.0, color="tab:blue", alpha=0.25)
    ax.plot([], [], "s", color="tab:blue", alpha=0.4, label="first-order 3σ ellipse of $P_z$")
    sxy, sth = levels[name]
    ax.set_title(f"$\\Delta^g$ of edge {tails[k_edge]}→{heads[k_edge]}, σ_xy = {sxy} m, σ_θ = {sth} rad")
    ax.set_xlabel("Δᵍ_x [m]")
    ax.set_ylabel("Δᵍ_y [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8, loc="lower right")
keys = ["total", "floor", "nonlin"]
for offset, name, color in [(-0.19, "large", "tab:red"), (0.19, "small", "tab:green")]:
    axs[2].bar(np.arange(3) + offset, [mc[name][key] for key in keys], 0.38, color=color, label=f"σ_θ = {levels[name][1]} rad")
axs[2].set_xticks(np.arange(3), ["‖S_z − P_z‖", "sampling floor", "non-linearity"])
axs[2].set_yscale("log")
axs[2].set_ylabel("relative Frobenius error")
axs[2].set_title("sample covariance against the first-order $P_z$")
axs[2].legend()
show(fig, "montecarlo")

# %% tags=["remove-input"]
check(max(large["fast"], small_noise["fast"]) < 1e-9, "the Monte-Carlo loop computes exactly the package's phases 1–2")
check(abs(large["floor"] - small_noise["floor"]) < 1e-6 * large["floor"], "same draws, same sampling floor at both levels")
check(small_noise["nonlin"] < large["nonlin"] / 10,
      f"the non-linearity shrinks {large['nonlin'] / small_noise['nonlin']:.0f}× when σ shrinks 10×")
check(abs(small_noise["total"] - small_noise["floor"]) < 0.1 * small_noise["floor"],
      "at small noise the first-order P_z is exact up to sampling error")
check(large["nonlin"] > 0.5 * large["floor"], "at σ_θ = 0.3 rad the non-linearity is visible above the sampling noise")

# %% [markdown]
# ### Try it: the covariance grows along the chain
# Drag σ_θ and σ_xy: position noise alone grows the ellipses as √j; heading noise stretches them across the path, more
# after the turn; from σ_θ ≈ 0.2 rad the draws bend into bananas that the first-order ellipses of eq. (10) no longer
# follow (section 6).

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.chain_covariance, "try_chain", sigma_theta=(0.0, 0.4, 0.01, 0.05), sigma_xy=(0.0, 0.2, 0.01, 0.05), n=(4, 30, 1, 15))

# %% [markdown]
# **Summary.** Phase 2 is a change of variables, not an optimization: it rotates the relative positions
# into the global frame with phase 1's orientations (eq. (9)) and propagates the uncertainty to first
# order (eqs. (10)–(11)). The covariance $P_z$ contains $P_\theta$, which is entrywise positive exactly
# when the graph minus the reference pose is connected; its inverse always has the explicit sparse
# square root $W$, which is what phase 3 (lecture 4a) uses as the weight of its least-squares problem.
# First order is exact as the noise vanishes; at $\sigma_\theta = 0.3$ rad its error is already visible.

# %% [markdown]
# ## Exercise 2 — $P_z$ times a vector, without $P_z$
#
# *Implement.* On a graph of a thousand poses $P_z$ has millions of entries. Write `pz_times(result, graph, v)`,
# which applies $P_z = H\,\mathrm{diag}(P_{\Delta^l}, P_\theta)\,H^\top$ to a vector with sparse matrices only
# (use phase 1's factorization of $A P_\delta^{-1} A^\top$ for $P_\theta x$); the check verifies
# $W^\top W (P_z v) = v$ for random vectors $v$.
#
# **Hint.** Apply $H^\top$, then the blocks ($P_\theta x$ is a solve with phase 1's factor,
# `result.phase1.factor.solve`), then $H$ — each a sparse product.

# %%
# your solution here: fill in the body of pz_times, then run the cell (check_pz_times tests it)
from lago_cvx.exercises import check_pz_times

def pz_times(result, graph, v):
    """P_z v (2m + n,) for the paper's LAGO result on graph, without forming P_z."""
    raise NotImplementedError

check_pz_times(pz_times)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. P_z = H blkdiag(P_Δˡ, P_θ) Hᵀ with H = [[R, J], [0, I]]. For v = [a; b]: Hᵀv =
# [Rᵀa; Jᵀa + b], then [P_Δˡ Rᵀa; P_θ(Jᵀa + b)] = [s₁; s₂], then H[s₁; s₂] = [R s₁ + J s₂; s₂]. P_θ x is one solve
# with phase 1's factorization of A P_δ⁻¹ Aᵀ: no dense matrix anywhere (on INTEL P_z would have 10⁷ entries).
import numpy as np
import scipy.sparse as sp
from lago_cvx.exercises import check_pz_times
from lago_cvx.posegraph import rot2

def pz_times(result, graph, v):
    m = graph.n_edges
    R = sp.block_diag(rot2(result.phase1.theta[graph.tails]), format="csr")
    P_dl = sp.block_diag(result.uncertainty.cov_delta_l, format="csr")
    J, a, b = result.phase2.jac, v[:2 * m], v[2 * m:]
    s1, s2 = P_dl @ (R.T @ a), result.phase1.factor.solve(J.T @ a + b)
    return np.concatenate([R @ s1 + J @ s2, s2])

check_pz_times(pz_times).require()
