# %% [markdown]
# # Lecture 7 — Constrained variants: anchors, priors, convex constraints, robust losses
#
# *LAGO, Carlone, Aragues, Castellanos, Bona, RSS 2011 (the seed), extended; `lago_cvx.variants`.*
#
# Every LAGO phase is a linear least-squares problem, so every phase is also a convex program that
# can be **extended**: coordinates that are known exactly, soft absolute measurements, convex
# constraints on where the robot can be, and losses that bound the influence of false loop closures.
# This lecture walks through each variant with the equations of the modified phases:
#
# 1. **anchors** — several poses (or only positions, or only orientations) known exactly: the known
#    entries move to the right-hand side (closed form) or become equality constraints (cvxpy);
#    the 2kπ regularization of anchored orientations; the frame (gauge) decision;
# 2. **strain** — hard anchors cannot compromise; the Lagrange multipliers tell which ones are wrong;
# 3. **priors** — GTSAM-style soft absolute measurements, split exactly between phases 1 and 3;
# 4. **convex constraints** — a worked example (the room the robot never left), and infeasibility
#    diagnosed by name;
# 5. **robust losses** — Huber and ℓ1 against 10 % false loop closures, why the 2kπ regularization
#    needs care, what convex losses achieve and what it takes to match the outlier-free answer;
# 6. anchors on a real dataset.
#
# **Notation** (as in lectures 2–4): $n$ poses, $m$ edges, $A$ the $n\times m$ incidence matrix,
# $\delta_{reg}$ the regularized relative orientations, $P_\delta$, $P_\Delta$ the per-edge marginal
# covariances, $S=\begin{bmatrix}0&-1\\1&0\end{bmatrix}$. Here the phases are written over **all**
# coordinates — phase 1 over $\theta\in\mathbb{R}^n$, phase 3 over $x=[p;\theta]\in\mathbb{R}^{3n}$ —
# and a set $K$ of them is known, $U$ is the rest.

# %%
import time

_t_start = time.perf_counter()

import logging

import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np

from _lecture import figure_saver
import lago_cvx as lc
from lago_cvx import variants as V
from lago_cvx.datasets import DatasetNotFound, dataset
from lago_cvx.graph import spanning_tree
from lago_cvx.metrics import relative_difference
from lago_cvx.plotting import plot_edges, plot_trajectory
from lago_cvx.metrics import ate
from lago_cvx.refinement import refine

save = figure_saver("07_variants")

logging.getLogger("lago_cvx").setLevel(logging.ERROR)  # warnings are shown explicitly below
np.set_printoptions(linewidth=120, precision=4)

# %% [markdown]
# ## 1. Anchors: known coordinates
#
# Every phase of LAGO has the form
# $$\min_x \|W(z - B^\top x)\|^2 \qquad\text{subject to}\qquad x_K = \bar x_K, \tag{V1}$$
# with $W$ a sparse whitening and $B^\top$ the design. With $M = W B^\top$, the known columns move to the
# right-hand side — the reduced incidence matrix loses the anchored rows, exactly as the seed's $A_2$
# loses the anchor's row:
# $$x_U = \arg\min \|M_U x_U - (Wz - M_K\bar x_K)\|^2 = (M_U^\top M_U)^{-1}M_U^\top(Wz - M_K\bar x_K). \tag{V2}$$
# The cvxpy form keeps **one** variable for all coordinates and adds the anchors as one equality
# constraint `x[K] == x̄_K`.
#
# **Phase 1** (orientations): $B_1^\top = A^\top$, $z_1=\delta_{reg}$, $W_1 = P_\delta^{-1/2}$;
# anchored orientations are known coordinates.
#
# **Phase 2**: $z = [\Delta^g;\hat\theta_U]$ with $\Delta^g_{ij}=R(\hat\theta_i)\Delta^l_{ij}$, and the
# sparse square root of $P_z^{-1}$
# $$W=\begin{bmatrix}P_\Delta^{-1/2}R^\top & -P_\Delta^{-1/2}S\Delta^l e_i^\top\\ 0 & L\end{bmatrix},\qquad
# L = (W_1B_1^\top)_{:,U_\theta},\quad L^\top L = P_\theta^{-1}:$$
# an edge whose tail has a *known* orientation has no Jacobian block (θ_i carries no uncertainty).
#
# **Phase 3**: $x=[p;\theta]$, rows $\Delta^g - (A\otimes I_2)^\top p$ and $\hat\theta_U - \theta_U$;
# anchored positions and orientations are known coordinates.
#
# **Regularization.** The spanning tree is rooted at the reference pose; its integrated orientations are
# offset so that the first anchored orientation matches. Every other anchored orientation $\theta_a$
# acts like a **chord from the root**: $k_a = -\mathrm{round}((\theta_a-\theta_{tree}[a])/2\pi)$ and
# $\theta_a + 2\pi k_a$ is used, reported (and flagged ambiguous near $\pm\pi$) like a chord.
#
# **Frame.** Orientation is fixed by the anchored orientations (else priors; else, with ≥ 2 position
# anchors, by rotating a provisional LAGO onto them — 2-D Kabsch; else $\theta_{ref}=0$); position by
# the anchored positions (else priors; else $p_{ref}=0$). With `anchors={}` this is plain LAGO.
#
# Here: a noiseless Manhattan world, anchored with a full pose, a position only, and an orientation
# given **three turns off** — the truth comes back exactly.

# %%
w0 = lc.manhattan_world(400, seed=11, sigma_xy=0.0, sigma_theta=0.0)
t0 = w0.truth
anchors = {80: tuple(t0[80]), 300: (t0[300, 0], t0[300, 1], None), 399: (None, None, t0[399, 2] + 6 * np.pi)}
for method in ("closed_form", "cvxpy"):
    r = lc.lago(w0.graph, anchors=anchors, method=method)
    err_p = np.abs(r.poses[:, :2] - t0[:, :2]).max()
    err_t = np.abs(np.angle(np.exp(1j * (r.poses[:, 2] - t0[:, 2])))).max()
    print(f"{method:12s}: max position error {err_p:.1e} m, max orientation error {err_t:.1e} rad")
    assert err_p < 1e-9 and err_t < 1e-9
areg = r.anchor_regularization
print("anchored orientations: k =", areg.k, "residual before", areg.residual_before.round(4), "after",
      areg.residual.round(4), "| frame:", r.frame)

# %% [markdown]
# The cvxpy problems are ordinary problems you can print and extend; the anchors are one equality
# constraint on the phase variable:

# %%
print(r.problems["phase3"].constraints[0])
print("phase-3 variable:", r.problems["phase3"].variables()[0].shape, "— known coordinates:",
      int(r.phase3.system.known.sum()))

# %% [markdown]
# ## 2. Strain: hard anchors cannot compromise
#
# A hard anchor is never moved, so inconsistent anchors are absorbed by the *measurement* residuals.
# What tells is the gradient of the cost at the anchored coordinates,
# $g_K = 2M_K^\top(Mx - Wz)$ — the negated Lagrange multiplier of `x[K] == x̄_K` (cvxpy's dual value $\nu$
# satisfies $\nabla f + \nu = 0$). Releasing the coordinates $c$ of one anchor lowers the cost by
# $$\Delta\chi^2_c = \tfrac14 g_c^\top S_c^{+} g_c,\qquad S_c = M_c^\top M_c - M_c^\top M_U(M_U^\top M_U)^{-1}M_U^\top M_c,\tag{V3}$$
# the Lagrange-multiplier (score) test: $\chi^2$ with $|c|$ degrees of freedom when the anchor agrees with
# the measurements (orientation tested in phase 1, position in phase 3). An anchor whose p-value is below
# `strain_level` (1e-3) is reported *strained* and a warning names it.
#
# Below: a noisy world, anchors from the truth, then pose 250 moved 5 m farther from pose 0.

# %%
w = lc.manhattan_world(300, seed=3)
t = w.truth
good = lc.lago(w.graph, anchors={0: tuple(t[0]), 250: tuple(t[250])})
far = t[250].copy()
far[:2] += 5.0 * (t[250, :2] - t[0, :2]) / np.linalg.norm(t[250, :2] - t[0, :2])
records = []


class _Keep(logging.Handler):
    def emit(self, record):
        records.append(record.getMessage())


handler = _Keep(level=logging.WARNING)
vlog = logging.getLogger("lago_cvx.variants")
vlog.addHandler(handler)
vlog.setLevel(logging.WARNING)
bad = lc.lago(w.graph, anchors={0: tuple(t[0]), 250: tuple(far), 120: (None, None, t[120, 2])})
vlog.removeHandler(handler)
vlog.setLevel(logging.NOTSET)
print(f"{'anchor':>6} {'kind':>12} {'χ²_θ':>8} {'χ²_p':>9} {'dof':>4} {'p-value':>9}  strained")
for s in good.strain + bad.strain:
    print(f"{s.id:>6} {s.kind:>12} {s.chi2_theta if s.chi2_theta is not None else float('nan'):8.3f} "
          f"{s.chi2_position if s.chi2_position is not None else float('nan'):9.2f} {s.dof:>4} {s.p_value:9.2g}  {s.strained}")
print("logged:", records)
print(f"χ² of the full problem: consistent anchors {good.chi2:.1f}, inconsistent {bad.chi2:.1f} "
      f"(increase ≈ the strain {bad.strain[1].chi2_position:.0f})")
assert bad.strained == [0, 250] and not good.strained

# %% [markdown]
# The statistic is exactly the cost decrease of releasing the anchor (checked by re-solving with pose 250
# anchored in orientation only):

# %%
rel = lc.lago(w.graph, anchors={0: tuple(t[0]), 250: (None, None, far[2]), 120: (None, None, t[120, 2])})
drop = bad.phase3.system.cost(bad.phase3.solution.x) - rel.phase3.system.cost(rel.phase3.solution.x)
print(f"phase-3 cost decrease when releasing pose 250's position: {drop:.4f}; statistic {bad.strain[1].chi2_position:.4f}")
assert abs(drop - bad.strain[1].chi2_position) < 1e-6 * drop

# %% [markdown]
# ## 3. Priors
#
# A prior on pose $q$: mean $\mu_q$, $3\times3$ information $\Lambda_q$ (GTSAM's `PriorFactor`, g2o χ²
# convention $e^\top\Lambda e$, $e = x_q - \mu_q$). The phase split of LAGO is honoured **exactly**:
# $$e^\top\Lambda e = (e_p + h e_\theta)^\top\Lambda_{pp}(e_p + h e_\theta) + e_\theta^2/\sigma_\theta^2,
# \qquad h=\Lambda_{pp}^{-1}\Lambda_{p\theta},\ \sigma_\theta^2=(\Lambda^{-1})_{\theta\theta}. \tag{V8}$$
# The marginal θ part is an extra whitened row of phase 1 ($B_1^\top=[A^\top;E_Q]$,
# $z_1=[\delta_{reg};\tilde\mu_\theta]$, $W_1=\mathrm{diag}(P_\delta^{-1/2},\sigma_Q^{-1})$; the mean
# rounded by $2k\pi$ like an anchor) and reaches phase 3 through $\hat\theta$ and $L$; the conditional
# $(x,y,\theta)$ part is two extra rows of phase 3, whitened by $C_q$ ($C_q^\top C_q=\Lambda_{pp}$).
# Each prior is counted once. As the information grows, a prior becomes the anchor:

# %%
vals = {0: t[0], 100: t[100], 299: t[299] + [0.3, -0.2, 0.05]}
anchored = lc.lago(w.graph, anchors={k: tuple(v) for k, v in vals.items()})
for info in (1e2, 1e4, 1e6, 1e8, 1e10, 1e12):
    res = V.anchored_lago(w.graph, priors={k: (v, info * np.eye(3)) for k, v in vals.items()})
    print(f"prior information {info:7.0e}: relative difference to the anchored result "
          f"{relative_difference(res.poses, anchored.poses):.1e}; prior χ² {res.prior_chi2().round(3)}")
assert relative_difference(res.poses, anchored.poses) < 1e-6

# %% [markdown]
# ## 4. Convex constraints — a worked example
#
# `constrained_lago(graph, constraints_fn, ...)` solves phases 1 and 3 as cvxpy problems and calls
# `constraints_fn(pv)` for each, where `pv` (`PoseVariables`) exposes the affine expressions `pv.x`,
# `pv.y`, `pv.theta` of every pose (phase 1: only `pv.theta`). Helpers return **named** constraints:
#
# * `box_constraint(pv, xmin=…, xmax=…, ymin=…, ymax=…, poses=…)`;
# * `polygon_constraint(pv, vertices, poses=…)` — a convex polygon as half-planes $n_i^\top p\le n_i^\top v_i$
#   ($n_i$ the outward normal of side $v_i\to v_{i+1}$); `halfplane_constraint` for any set of them
#   (a corridor is two half-planes);
# * `orientation_bounds(pv, lower=…, upper=…, center=…)` — $\ell\le\theta_v - c_v\le u$, $c_v$ moved
#   onto the branch of the unwrapped θ (phases 1 and 3);
# * or `NamedConstraint("name", [any cvxpy constraint on pv.x, pv.y, pv.theta])`.
#
# Phase 3 with a box is the quadratic program
# $$\min_x \|W(z-B^\top x)\|^2\quad\text{s.t.}\quad x_K=\bar x_K,\ \ x_{min}\le p_{v,x}\le x_{max},\ \ y_{min}\le p_{v,y}\le y_{max}.$$
#
# **Example.** A robot explores an 8 m × 8 m room with few loop closures; LAGO lets a fifth of the poses
# drift through the walls. Knowing the room is a convex constraint:

# %%
wr = lc.manhattan_world(300, seed=2, grid_extent=8, sigma_theta=0.05, p_loop_closure=0.1)
tr = wr.truth
lo, hi = tr[:, :2].min(0), tr[:, :2].max(0)
start = {0: tuple(tr[0])}


def room(pv):
    return [V.box_constraint(pv, xmin=lo[0], xmax=hi[0], ymin=lo[1], ymax=hi[1], name="room")]


plain = lc.lago(wr.graph, anchors=start)
boxed = V.constrained_lago(wr.graph, room, anchors=start)
outside = int(((plain.poses[:, :2] < lo) | (plain.poses[:, :2] > hi)).any(1).sum())
print(f"{wr.graph.n_loop_closures} loop closures; LAGO puts {outside} of {wr.graph.n_poses} poses outside the room")
print(f"ATE: LAGO {ate(plain.poses, tr):.3f} m → with the room {ate(boxed.poses, tr):.3f} m; "
      f"χ² {plain.chi2:.1f} → {boxed.chi2:.1f} (the measurements alone prefer the drifted estimate)")
assert ate(boxed.poses, tr) < ate(plain.poses, tr)

fig, axes = plt.subplots(1, 2, figsize=(11, 5))
for ax, res, title in ((axes[0], plain, "LAGO"), (axes[1], boxed, "LAGO + room constraint")):
    plot_trajectory(ax, tr, color="0.6", linewidth=2.5, label="truth")
    plot_trajectory(ax, res.poses, color="tab:blue", label=f"estimate (ATE {ate(res.poses, tr):.3f} m)")
    ax.add_patch(plt.Rectangle(lo, *(hi - lo), fill=False, edgecolor="tab:red", linestyle="--", linewidth=1.5,
                               zorder=5, label="room"))
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
save(fig, "constraints")

# %% [markdown]
# The same by hand, on the returned phase-3 problem: `system_problem` builds
# `(problem, x, anchor_constraint)` for a phase's weighted system; add any cvxpy constraint and solve.

# %%
from lago_cvx.solvers import solve

problem, x, anchor_c = V.system_problem(boxed.phase3.system)
pv = V.PoseVariables(wr.graph, 3, x, boxed.regularization.theta_tree)
by_hand = cp.Problem(problem.objective, problem.constraints + room(pv)[0].constraints)
solve(by_hand)
print("minimize sum_squares(W @ (z − Bᵀ @ x)) subject to",
      [f"{type(c).__name__} {c.shape}" for c in by_hand.constraints], "(anchors, room)")
print(f"by hand vs constrained_lago, phase 3: max |Δx| = {np.abs(x.value - boxed.phase3.x).max():.1e}")
assert np.abs(x.value - boxed.phase3.x).max() < 1e-6

# %% [markdown]
# **Infeasible constraints** raise `InfeasibleConstraintsError` naming the culprits: first the constraints
# infeasible on their own (together with the anchors); otherwise an irreducible infeasible subset, found
# by a deletion filter (drop each constraint in turn; keep it only if the rest becomes feasible without it).

# %%
cases = {
    "alone": lambda pv: [room(pv)[0], V.box_constraint(pv, poses=[0], xmin=5.0, name="start east of 5 m")],
    "jointly": lambda pv: [room(pv)[0], V.box_constraint(pv, poses=[50], xmax=0.0, name="west wall"),
                           V.orientation_bounds(pv, poses=[7], lower=-10, upper=10, name="loose heading"),
                           V.box_constraint(pv, poses=[50], xmin=1.0, name="east zone")],
    "phase 1": lambda pv: [V.orientation_bounds(pv, poses=[0], lower=1.0, name="heading of pose 0")],
}
for label, fn in cases.items():
    try:
        V.constrained_lago(wr.graph, fn, anchors=start)
        raise AssertionError("should have been infeasible")
    except lc.InfeasibleConstraintsError as exc:
        print(f"{label:8s}: {exc}  → names {exc.names}")

# %% [markdown]
# ## 5. Robust loop closures
#
# A false loop closure (perceptual aliasing) enters least squares with a force proportional to its error,
# so one of them can bend the whole map. Convex robust losses bound that force. Let $r_k$ be the whitened
# residual rows of edge $k$ (phase 1: one row; phase 3: its two position rows and its θ row of $L$, grouped
# because an edge is an outlier as a whole). With threshold $M$ (whitened units, default 3):
# $$\rho_{huber}(r_k) = \begin{cases}\|r_k\|^2 & \|r_k\|\le M\\ 2M\|r_k\| - M^2 & \text{else}\end{cases}
# \;=\;\min_{v_k}\ \|r_k - v_k\|^2 + 2M\|v_k\|_2,\qquad \rho_{\ell_1}(r_k) = 2M\|r_k\|_2. \tag{V10}$$
# The Moreau-envelope form on the right is how phase 3 is written in cvxpy (phase 1 uses `cp.huber`
# directly); anchors stay hard and priors quadratic.
#
# **The 2kπ regularization needs care.** Outliers corrupt it twice: a BFS tree likes loop closures as
# shortcuts — so false ones become *tree* edges and shift θ_tree on a whole subtree — and every chord is
# then rounded against a wrong θ_tree. `robust_lago` therefore (a) uses the **odometric tree** when the
# odometric chain is complete (`spanning_tree="auto"`; false loop closures are never odometric), and
# (b) **re-rounds every edge** (tree edges included) against the robust phase-1 estimate,
# $k_e=-\mathrm{round}((\delta_e-(\theta_{rob,j}-\theta_{rob,i}))/2\pi)$, re-solving phase 1 until no $k$
# changes. Phase 2 then uses the robust phase-1 information $\mathrm{diag}(\sqrt w)L$, $w_k=\min(1,M/\|r_k\|)$.

# %%
wo = lc.manhattan_world(500, seed=0, outlier_fraction=0.1)
g, to, gi, om = wo.graph, wo.truth, wo.inlier_graph, wo.outlier_mask
bfs = spanning_tree(g, "bfs", anchor=0)
print(f"{om.sum()} false loop closures among {g.n_loop_closures}; {int(om[bfs.tree_edges].sum())} of them are "
      f"edges of the BFS tree (LAGO's default), none of the odometric tree")

# %% [markdown]
# The requirement we set ourselves: with 10 % false loop closures, the Huber variant within **2×** of the
# outlier-free LAGO error while plain LAGO is far worse. Measured:

# %%
runs = {
    "LAGO, inlier graph (reference)": lc.lago(gi),
    "plain LAGO": lc.lago(g),
    "Huber (convex)": V.robust_lago(g),
    "ℓ1 (convex)": V.robust_lago(g, loss="l1"),
    "Huber + gating": V.robust_lago(g, gate=V.GATE_THRESHOLD),
}
ref_err = ate(runs["LAGO, inlier graph (reference)"].poses, to)
print(f"{'':32s} {'ATE [m]':>8} {'× reference':>12} {'χ² of inliers':>14}")
for k, r in runs.items():
    e = ate(r.poses, to)
    print(f"{k:32s} {e:8.4f} {e / ref_err:12.1f} {lc.chi2(gi, r.poses):14.1f}")
hub = runs["Huber (convex)"]
print(f"convex Huber weights: false loop closures max {hub.robust['edge_weights'][om].max():.3f}; "
      f"true edges below 0.5: {int((hub.robust['edge_weights'][~om] < 0.5).sum())}")

# %% [markdown]
# **The convex losses do not meet the requirement** (here ~15×; on larger worlds worse — n = 2000 with
# 147 false loop closures: Huber 14.8 m against 0.36 m). They do *detect* every false loop closure (all
# weights ≪ 1), but a bounded force is not a zero force: 27 outliers each pulling with $2M$ in whitened
# units still bend loops that only a handful of true loop closures hold, and already phase 1 is off by
# ~0.1 rad (against 0.03 rad without outliers).
#
# **What does:** use the convex estimate only to *classify* the edges, then solve least squares on the
# accepted ones (`gate=`; V11). An edge whose whitened error $\sqrt{e^\top\Omega e}$ of eq. (3) exceeds
# τ (`GATE_THRESHOLD` = $\sqrt{\chi^2_3}$ at $1-10^{-6}$ ≈ 5.5) is rejected, except the edges of the
# trusted tree (the odometric one), which keep the graph connected; LAGO runs on the accepted edges; the
# classification is repeated at the new estimate until it no longer changes. Here it rejects all 27
# false loop closures and no true edge, and returns exactly the outlier-free LAGO. (With a BFS tree as
# the trusted structure this fails on larger worlds — the gating then has to fall back on a
# minimum-error tree at a biased estimate, which can thread through outliers; the odometric tree is
# what makes it reliable.)

# %%
gated = runs["Huber + gating"]
inl = gated.robust["inliers"]
print(f"gating: {gated.robust['gate_rounds']} round(s); rejected {int((~inl & om).sum())} of {om.sum()} false "
      f"loop closures and {int((~inl & ~om).sum())} true edges")
assert ate(gated.poses, to) <= 2 * ref_err < ate(runs["plain LAGO"].poses, to) / 5

fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
for ax, k in zip(axes, ("plain LAGO", "Huber (convex)", "Huber + gating")):
    r = runs[k]
    plot_edges(ax, g.subgraph_edges(om), r.poses, which="all", color="tab:red", linewidth=0.6,
               alpha=0.5, label="false loop closures")
    plot_trajectory(ax, to, color="0.6", linewidth=2.5, label="truth")
    plot_trajectory(ax, r.poses, color="tab:blue", label=f"estimate (ATE {ate(r.poses, to):.2f} m)")
    ax.set_title(k)
    ax.legend(loc="upper right", fontsize=8)
save(fig, "robust")

# %% [markdown]
# ## 6. Anchors on real data
#
# Three poses of the INTEL g2o graph (whose information spans 1e1…1e8) anchored at the refined optimum.
# LAGO with its single anchor lands ~8000× above the minimum; three correct anchors hold the loops' ends
# and bring it to ~180× — the linearization error along INTEL's loops remains (README) — and none of
# them is strained.

# %%
try:
    gint = lc.read_graph(dataset("carlone/input_INTEL_g2o.g2o"))
except DatasetNotFound as exc:
    gint = None
    print(f"real datasets not found: skipping the INTEL anchors example ({exc})")
if gint is not None:
    opt = refine(gint, lc.lago(gint).poses)
    n = gint.n_poses
    anc = {int(gint.ids[i]): tuple(opt.poses[i]) for i in (n // 3, 2 * n // 3, n - 1)}
    one = lc.lago(gint)
    three, report = lc.compare_methods(gint, anchors=anc)
    print(f"χ²: optimum {opt.chi2:.1f}; LAGO {one.chi2:.4g}; LAGO with anchors {list(anc)} {three.chi2:.1f}")
    print("cvxpy vs closed form (max relative difference):", {k: f"{v:.1e}" for k, v in report["max_rel_diff"].items()})
    print("strain:", [(s.id, round(s.chi2, 2), s.strained) for s in three.strain])

# %%
elapsed = time.perf_counter() - _t_start
print(f"lecture 7 executed in {elapsed:.1f} s")
