# %% [markdown]
# # Lecture 7 — Beyond the paper: anchors, priors, convex constraints, robust losses
#
# Every phase of LAGO is a weighted linear least-squares problem, so every phase is also a convex program —
# and a convex program can be extended: poses known exactly, soft absolute measurements, convex limits on
# where the robot can be, losses that bound the pull of a false loop closure. None of this is in the paper
# (which fixes one reference pose, $p_0 = 0$); it is what `lago_cvx.variants` adds, and each extension is
# a small change to the cvxpy problem that lecture 2–4 built.
#
# **Learning goals.** After this lecture you can
#
# 1. solve a phase with several anchored coordinates both ways — known columns moved to the right-hand
#    side, or equality constraints in cvxpy — and check that they agree;
# 2. read the dual variables of the anchor constraints as the forces the measurements exert on the
#    anchors, check that they balance, and turn a force into the strain test of a suspicious anchor;
# 3. replace an anchor by a prior and watch it become the anchor as its information grows;
# 4. add convex constraints (a room) and read their multipliers as wall forces;
# 5. say what convex robust losses do against false loop closures and what they do not, and reject them by
#    graduated non-convexity around weighted LAGO runs.
#
# **Notation** (lectures 1–4a's, and):
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $A$ | the full incidence matrix, $(n+1)\times m$: below a phase is written over **all** $n+1$ poses | `lc.incidence_matrix` |
# | $K$, $U$ | the known (anchored) coordinates of a phase and the rest | `result.phase1.system.known` |
# | $\nu$ | the multipliers of the anchor constraints: forces (phase 3) and torques (phase 1) | the cvxpy constraints' `dual_value` |
# | $M = WB^\top$ | the whitened design of a phase (phase 1: eq. (13), over $\theta$; phase 3: eq. (15), over $x = [p; \theta]$) | `system.design()` |
# | $S$ | a Schur complement (section 3) — not lecture 3's 90° rotation | `result.strain` |
# | $\bar c^2$ | the truncation of graduated non-convexity (whitened, squared) | `RobustSettings().c2` |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)

# %%
import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np
from scipy import stats

import lago_cvx as lc
from lago_cvx.course import check, real, setup, show
from lago_cvx import variants as V
from lago_cvx.plotting import plot_edges, plot_trajectory
from lago_cvx.posegraph import wrap_angle
from lago_cvx.solvers import solve
from lago_cvx.uncertainty import edge_uncertainty

setup("07_variants")

# %% [markdown]
# ## 1. Several anchors, two ways
#
# Write a phase as **the anchored least-squares problem**
# $$\min_x\ \|W(z - B^\top x)\|^2 \quad\text{subject to}\quad x_K = \bar x_K, \tag{A1}$$
# with $W$ the sparse whitening and $B^\top$ the design of the phase (phase 1: $B^\top = A^\top$,
# $z = \delta_{\rm reg}$, $W = P_\delta^{-1/2}$). With $M = WB^\top$ split into the columns $M_U$, $M_K$, the
# known coordinates move to the right-hand side,
# $$x_U = (M_U^\top M_U)^{-1} M_U^\top\,(Wz - M_K \bar x_K), \tag{A2}$$
# which for a single anchor at the origin is eq. (13): deleting the anchor's row of $A$ is exactly moving its
# (zero) column to the right. cvxpy keeps one variable for all coordinates and states (A1) literally, with
# the anchors as one equality constraint. Anchors can be full poses, positions only, or orientations only; an
# anchored orientation is put on the branch of the regularized orientations by $2k\pi$, like a chord
# (lecture 5).
#
# A noiseless world, anchored with a full pose, a position, and an orientation given three turns off:

# %%
w0 = lc.manhattan_world(400, seed=11, sigma_xy=0.0, sigma_theta=0.0)
t0 = w0.truth
anchors = {80: tuple(t0[80]), 300: (t0[300, 0], t0[300, 1], None), 399: (None, None, t0[399, 2] + 6 * np.pi)}
recovered = {}
for method in ("closed_form", "cvxpy"):
    r = lc.lago(w0.graph, anchors=anchors, method=method)
    err_p = np.abs(r.poses[:, :2] - t0[:, :2]).max()
    err_t = np.abs(wrap_angle(r.poses[:, 2] - t0[:, 2])).max()
    recovered[method] = err_p, err_t
areg = r.anchor_regularization
i399 = list(areg.index).index(w0.graph.anchor_index(399))
print(f"anchored orientation of pose 399: given {areg.value[i399]:.3f} rad, corrected by k = {areg.k[i399]} to "
      f"{areg.corrected[i399]:.3f}, the branch of the unwrapped tree orientation {areg.theta_tree[399]:.3f}")
print("constraint of phase 3 in cvxpy:", r.problems["phase3"].constraints[0].__class__.__name__,
      r.problems["phase3"].constraints[0].shape, "—", int(r.phase3.system.known.sum()), "known coordinates")

fig, ax = plt.subplots(figsize=(6, 6))
plot_trajectory(ax, r.poses, color="tab:blue", linewidth=0.8, label="LAGO with anchors")
for pid, (marker, kind) in {80: ("s", "full pose"), 300: ("o", "position"), 399: ("^", "orientation (+3 turns)")}.items():
    ax.plot(*t0[pid, :2], marker, color="tab:red", ms=10, label=f"pose {pid}: {kind}")
ax.legend(loc="upper right", fontsize=8)
ax.set_title("three kinds of anchor, noiseless world: exact recovery")
show(fig, "anchors")

# %% tags=["remove-input"]
for method, (err_p, err_t) in recovered.items():
    check(err_p < 1e-9 and err_t < 1e-9, f"{method}: the truth comes back (position {err_p:.1e} m, "
          f"orientation {err_t:.1e} rad)")
check(abs(areg.residual[i399]) < 1e-9, "the anchor lands on the tree's branch exactly (noiseless world)")

# %% [markdown]
# ## 2. The multipliers of the anchors are forces
#
# Phase 1 with anchors, by hand, from named parts: the incidence matrix $A^\top$, the weights
# $w_\delta = P_\delta^{-1/2}$, the regularized measurements $\delta_{\rm reg}$, and the anchored values as a
# parameter $\bar\theta_K$ we will move.

# %%
w = lc.manhattan_world(300, seed=3)
truth = w.truth
K_ids = [0, 120, 250]
res = lc.lago(w.graph, anchors={i: tuple(truth[i]) for i in K_ids})      # the package, closed form
sys1 = res.phase1.system                                                 # its phase-1 data (V1)
K = np.flatnonzero(sys1.known)
theta = cp.Variable(w.graph.n_poses, name="θ")
At = cp.Constant(lc.incidence_matrix(w.graph).T, name="Aᵀ")
w_d = cp.Constant(edge_uncertainty(w.graph).sqrt_info_delta, name="w_δ")
d_reg = cp.Constant(sys1.z, name="δ_reg")
theta_K = cp.Parameter(K.size, name="θ̄_K")
anchor_c = theta[K] == theta_K
phase1 = cp.Problem(cp.Minimize(cp.sum_squares(cp.multiply(w_d, At @ theta - d_reg))), [anchor_c])
print(phase1)
theta_K.value = sys1.values[K]
solve(phase1)
err = np.abs(theta.value - res.phase1.theta).max()

# %% tags=["remove-input"]
check(err < 1e-8, f"by hand = the package's anchored phase 1 (closed form, eq. (A2)): {err:.1e} rad")

# %% [markdown]
# Think of every edge as a torsion spring between its two poses, with energy $w_e^2(\theta_j-\theta_i-\delta_e)^2$.
# At the optimum the free poses feel no net torque. The anchors do: the constraint holds them against the
# springs, and the Karush–Kuhn–Tucker condition $\nabla f(\theta) + E_K^\top\nu = 0$ says that the dual value
# $\nu_a$ of anchor $a$ equals $-\partial f/\partial\theta_a$, the net torque of the springs on it. Because
# every column of $A$ sums to zero, the torques on all poses add up to zero — so the torques on the anchors do
# too: the data push some anchors one way and the others the other way, never all the same way (with a single
# anchor, the torque is zero, as lecture 2 §5 found).

# %%
nu = np.asarray(anchor_c.dual_value, dtype=float)
r_e = w_d.value**2 * (lc.incidence_matrix(w.graph).T @ theta.value - sys1.z)   # w²·residual per edge
torque = -2 * (lc.incidence_matrix(w.graph) @ r_e)                               # −∂f/∂θ at every pose
print("dual values ν of the anchor constraint:", np.round(nu, 4), " net spring torque on the anchors:",
      np.round(torque[K], 4))

# %% tags=["remove-input"]
check(np.allclose(nu, torque[K], rtol=1e-6, atol=1e-8 * np.abs(r_e).max()),
      "ν = −∂f/∂θ_K: the dual value is the torque of the measurements on each anchor")
check(np.abs(torque[np.setdiff1d(np.arange(w.graph.n_poses), K)]).max() < 1e-6 * np.abs(r_e).max(),
      "the free poses feel no net torque")
check(abs(nu.sum()) < 1e-8 * np.abs(nu).max(), f"the torques on the anchors balance: Σν = {nu.sum():.1e}")

# %% [markdown]
# **Moving an anchor.** Turn anchor 250's orientation by $\varphi$ — change `θ̄_K.value`, no rebuild — and
# re-solve. The anchored cost $F(\varphi)$ is a quadratic in $\varphi$ (everything else re-optimizes), its
# slope is the force, $F'(\varphi) = -\nu_{250}(\varphi)$ (the envelope theorem), so the force is a straight
# line and $F$ a parabola. Its minimum is where anchor 250 would go if it were released, and the depth of the
# parabola below $F(0)$ is how much the cost drops on releasing it:
# $$\Delta\chi^2 = \frac{\nu^2}{4 S},\qquad S = \tfrac12 F'' = M_a^\top M_a - M_a^\top M_U (M_U^\top M_U)^{-1} M_U^\top M_a,$$
# the Lagrange-multiplier (score) statistic the package reports as the **strain** of an anchor.

# %%
a = list(K).index(w.graph.anchor_index(250))
phis = np.linspace(-0.1, 0.1, 9)
forces, costs = [], []
for phi in phis:
    theta_K.value = sys1.values[K] + phi * (np.arange(K.size) == a)
    solve(phase1)
    forces.append(float(anchor_c.dual_value[a]))
    costs.append(phase1.value)
theta_K.value = sys1.values[K]
slope, intercept = np.polyfit(phis, forces, 1)
c2, c1, c0 = np.polyfit(phis, costs, 2)
depth = c1**2 / (4 * c2)                       # F(0) − min_φ F(φ)
strain = {s.id: s for s in res.strain}[250]
print(f"force ν(φ) = {intercept:.4f} + ({slope:.2f})·φ; cost F(φ) = {c0:.4f} + {c1:.4f}·φ + {c2:.2f}·φ²")

# %% tags=["remove-input"]
check(np.abs(np.polyval([slope, intercept], phis) - forces).max() < 1e-6 * np.abs(forces).max(), "the force is linear in φ")

# %%
fig, axs = plt.subplots(1, 2, figsize=(11, 3.8))
axs[0].plot(phis, forces, "o-")
axs[0].axhline(0, color="k", lw=0.6)
axs[0].set(xlabel="φ: anchor 250 turned by [rad]", ylabel="ν₂₅₀: torque on the anchor", title="the force is linear")
axs[1].plot(phis, costs, "o-")
axs[1].axhline(c0 - depth, color="tab:red", ls="--", lw=1, label="released: cost − strain")
axs[1].set(xlabel="φ [rad]", ylabel="phase-1 cost F(φ)", title="the cost is a parabola")
axs[1].legend(fontsize=8)
for ax in axs:
    ax.set_xticks(np.linspace(phis[0], phis[-1], 5))
show(fig, "anchor_force")

# %% tags=["remove-input"]
check(abs(c1 + intercept) < 1e-6 * abs(intercept) and abs(2 * c2 + slope) < 1e-6 * abs(slope),
      "and it is the slope of the cost: F'(φ) = −ν(φ)")
check(abs(depth - strain.chi2_theta) < 1e-6 * strain.chi2_theta,
      f"depth of the parabola = the package's strain statistic of anchor 250 ({strain.chi2_theta:.4f})")

# %% [markdown]
# ## Exercise 1 — The forces balance
#
# Show that in phase 1 the multipliers of the anchor constraints always sum to zero, for any number of anchors,
# and that with a single anchor the multiplier is zero. Which property of the design does it use, and does the same
# hold for the position anchors of phase 3 (x and y separately)? Write `anchor_torques(graph, anchors)`, phase 1's
# multipliers $\nu$ of the anchored orientations (anchors in increasing id; `lc.compare_methods(..., anchors=...)`
# keeps the cvxpy problems and their duals); the check compares them with cvxpy's and sums them.
#
# **Hint.** Sum the stationarity conditions over all poses and use $\mathbf 1^\top A = 0$ (every column of the
# incidence matrix sums to zero).

# %%
# your solution here: fill in the body of anchor_torques, then run the cell (check_anchor_torques tests it)
from lago_cvx.exercises import check_anchor_torques, anchored_case
graph, anchors = anchored_case()   # three anchors: {id: (x, y, θ)}

def anchor_torques(graph, anchors):
    """Phase 1's multipliers ν (a,) of the anchored orientations."""
    raise NotImplementedError

check_anchor_torques(anchor_torques)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. Phase 1's gradient is ∇f = 2AW²(Aᵀθ − δ_reg), and 1ᵀA = 0 (one −1, one +1 per
# column), so 1ᵀ∇f = 0 for every θ. At the optimum ∇_U f = 0 on the free poses and ∇_K f + ν = 0 on the anchors:
# Σ_a ν_a = −1ᵀ∇f = 0. With one anchor ν = 0: a single reference only fixes the gauge. (The position forces
# of phase 3 balance the same way, x and y separately.)
import numpy as np
import lago_cvx as lc
from lago_cvx.exercises import check_anchor_torques

def anchor_torques(graph, anchors):
    _, report = lc.compare_methods(graph, anchors=anchors)
    return np.asarray(report["problems"]["phase1"].constraints[0].dual_value, dtype=float)

check_anchor_torques(anchor_torques).require()

# %% [markdown]
# ## 3. The strain test
#
# A hard anchor cannot compromise: if it disagrees with the measurements, the residuals absorb the
# disagreement and the estimate is bent. The strain statistic tells. When the anchor agrees with the
# measurements (both come from the same truth, up to the measurement noise), phase 1 is linear in the noise,
# so the orientation statistic is exactly $\chi^2$ with 1 degree of freedom; the position statistic of
# phase 3 is $\chi^2$ with 2 degrees of freedom to first order. An anchor whose p-value falls below
# `strain_level` ($10^{-3}$) is reported *strained*. We test both claims: a Monte Carlo over fresh worlds with
# anchors at the truth, then one anchor moved 5 m.

# %%
stat_theta, stat_pos, strain_fit = [], [], {}
N_WORLDS = 100
for seed in range(N_WORLDS):
    wm = lc.manhattan_world(100, seed=seed)
    rm = lc.lago(wm.graph, anchors={0: tuple(wm.truth[0]), 60: tuple(wm.truth[60]), 99: (None, None, wm.truth[99, 2])})
    s = {x.id: x for x in rm.strain}
    stat_theta += [s[60].chi2_theta, s[99].chi2_theta]
    stat_pos += [s[60].chi2_position]
for name, values, dof in (("orientation", stat_theta, 1), ("position", stat_pos, 2)):
    mean, se = np.mean(values), np.sqrt(2 * dof / len(values))
    p = stats.kstest(values, stats.chi2(dof).cdf).pvalue
    print(f"{name}: {len(values)} statistics, mean {mean:.3f} (χ²_{dof}: {dof}, standard error {se:.2f}), "
          f"Kolmogorov–Smirnov p = {p:.2f}")
    strain_fit[name] = (mean, se, p, dof)

# %% tags=["remove-input"]
for name, (mean, se, p, dof) in strain_fit.items():
    check(abs(mean - dof) < 4 * se and p > 1e-3, f"consistent anchors: the {name} strain is χ² with {dof} dof")

# %%
fig, axs = plt.subplots(1, 2, figsize=(11, 3.6))
for ax, (name, values, dof) in zip(axs, (("orientation", stat_theta, 1), ("position", stat_pos, 2))):
    ax.hist(values, bins=25, density=True, alpha=0.6, label="strain of anchors at the truth")
    xs = np.linspace(0.05, max(values), 200)
    ax.plot(xs, stats.chi2(dof).pdf(xs), "k", lw=1, label=f"χ² density, {dof} dof")
    ax.set(xlabel=f"{name} statistic", title=f"{name} anchors ({len(values)} in {N_WORLDS} worlds)")
    ax.legend(fontsize=8)
show(fig, "strain_distribution")

far = truth[250].copy()
far[:2] += 5.0 * (truth[250, :2] - truth[0, :2]) / np.linalg.norm(truth[250, :2] - truth[0, :2])
bad = lc.lago(w.graph, anchors={0: tuple(truth[0]), 250: tuple(far), 120: (None, None, truth[120, 2])})
for s in bad.strain:
    print(f"anchor {s.id:3d} ({s.kind:11s}): χ²_θ {s.chi2_theta if s.chi2_theta is not None else float('nan'):8.3f}  "
          f"χ²_p {s.chi2_position if s.chi2_position is not None else float('nan'):9.2f}  p = {s.p_value:.2g}  "
          f"strained: {s.strained}")

# %% tags=["remove-input"]
check(bad.strained == [0, 250], "the anchor moved 5 m is strained — and so is pose 0, which it pulls against")

# %%
released = lc.lago(w.graph, anchors={0: tuple(truth[0]), 250: (None, None, far[2]), 120: (None, None, truth[120, 2])})
drop = bad.phase3.system.cost(bad.phase3.solution.x) - released.phase3.system.cost(released.phase3.solution.x)
s250 = {s.id: s for s in bad.strain}[250]

# %% tags=["remove-input"]
check(abs(drop - s250.chi2_position) < 1e-6 * drop,
      f"its statistic is the cost drop of releasing its position ({drop:.2f})")

# %% [markdown]
# The test cannot say *which* of two disagreeing anchors is wrong: the force between them is mutual, so both
# poses 0 and 250 come out strained. Pose 120, anchored only in orientation, is not involved.

# %% [markdown]
# ## Exercise 2 — The strain statistic from the dual value
#
# For one orientation anchor $a$, compute $\Delta\chi^2 = \nu_a^2/(4S)$ yourself: $\nu_a$ from the cvxpy dual,
# $S$ the Schur complement of section 3 from $M = WB^\top$ of the package's phase-1 system (`result.phase1.system`).
# Write `strain_statistic(graph, anchors, anchor_id)`; the check compares it with the package's `chi2_theta` for two
# anchors. Why is it also the phase-1 cost drop when the anchor is released?
#
# **Hint.** $S$ is the Schur complement of the anchored orientation in $M^\top M$ of the phase-1 system without
# that anchor.

# %%
# your solution here: fill in the body of strain_statistic, then run the cell (check_strain tests it)
from lago_cvx.exercises import check_strain

def strain_statistic(graph, anchors, anchor_id):
    """ν_a² / (4S) for the anchor anchor_id (a float)."""
    raise NotImplementedError

check_strain(strain_statistic)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. With M the whitened design of phase 1 and a the anchored orientation, eliminating the
# free coordinates leaves F(θ̄_a) = F(0) + gφ + Sφ², S = M_aᵀM_a − M_aᵀM_U(M_UᵀM_U)⁻¹M_UᵀM_a (a Schur complement)
# and g = −ν_a. Releasing the anchor minimizes over φ: the cost drops by ν_a²/(4S), the Lagrange-multiplier test.
import numpy as np
import scipy.sparse.linalg as spla
import lago_cvx as lc
from lago_cvx.exercises import check_strain

def strain_statistic(graph, anchors, anchor_id):
    res, report = lc.compare_methods(graph, anchors=anchors)
    system = res.phase1.system
    K = list(np.flatnonzero(system.known))
    nu = np.asarray(report["problems"]["phase1"].constraints[0].dual_value, dtype=float)
    a = graph.anchor_index(anchor_id)
    M = system.design()
    MU, Ma = M[:, ~system.known], M[:, [a]]
    b = (MU.T @ Ma).toarray().ravel()
    schur = float((Ma.T @ Ma).toarray()[0, 0] - b @ spla.spsolve((MU.T @ MU).tocsc(), b))
    return nu[K.index(a)] ** 2 / (4 * schur)

check_strain(strain_statistic).require()

# %% [markdown]
# ## 4. Priors: soft anchors
#
# A prior on pose $q$ (mean $\mu_q$, $3\times3$ information $\Lambda_q$; GTSAM's `PriorFactor`) adds the term
# $e^\top\Lambda_q e$, $e = x_q - \mu_q$, to the cost. LAGO's split into phases is kept exactly by writing
# $$e^\top\Lambda e = (e_p + h e_\theta)^\top\Lambda_{pp}(e_p + h e_\theta) + e_\theta^2/\sigma_\theta^2,\qquad
# h = \Lambda_{pp}^{-1}\Lambda_{p\theta},\ \ \sigma_\theta^2 = (\Lambda^{-1})_{\theta\theta}:$$
# the marginal orientation part is one more row of phase 1, the conditional part two more rows of phase 3.
# As the information grows, the prior becomes the anchor.

# %%
vals = {0: truth[0], 100: truth[100], 299: truth[299] + [0.3, -0.2, 0.05]}
anchored = lc.lago(w.graph, anchors={i: tuple(v) for i, v in vals.items()})
infos = 10.0 ** np.arange(2, 13, 2)
diffs = []
for info in infos:
    rp = V.anchored_lago(w.graph, priors={i: (v, info * np.eye(3)) for i, v in vals.items()})
    diffs.append(lc.metrics.relative_difference(rp.poses, anchored.poses))
print("relative difference prior vs anchor:", dict(zip([f"{i:.0e}" for i in infos], [f"{d:.1e}" for d in diffs])))
fig, ax = plt.subplots(figsize=(5, 3.4))
ax.loglog(infos, diffs, "o-")
ax.set(xlabel="prior information (× I₃)", ylabel="relative difference to the anchored estimate",
       title="a prior is a soft anchor")
show(fig, "priors")

# %% tags=["remove-input"]
check(all(np.diff(np.log(diffs)) < 0) and diffs[-1] < 1e-6, "the prior converges to the anchor as its information grows")

# %% [markdown]
# ## 5. Convex constraints and their multipliers
#
# `V.constrained_lago(graph, constraints_fn)` solves phases 1 and 3 as cvxpy problems and adds the named
# convex constraints that `constraints_fn(pv)` returns for the affine pose expressions `pv.x`, `pv.y`,
# `pv.theta` (helpers: `box_constraint`, `polygon_constraint`, `halfplane_constraint`,
# `orientation_bounds`). Phase 3 with a box is the quadratic program
# $$\min_x \|W(z - B^\top x)\|^2 \quad\text{s.t.}\quad x_K = \bar x_K,\quad n_h^\top p_v \le c_h \ \ \text{for every pose } v
# \text{ and wall } h .$$
# The multiplier $\lambda_{v,h}\ge0$ of wall $h$ at pose $v$ is the force with which the wall holds the pose:
# it pushes along $-n_h$ (inward) with magnitude $\lambda_{v,h}$, and it is zero unless the pose touches the
# wall (complementary slackness, $\lambda_{v,h}(c_h - n_h^\top p_v) = 0$).
#
# **Example.** A robot explores an 8 m × 8 m room with few loop closures; LAGO lets part of the trajectory
# drift through the walls. Knowing the room is a convex constraint.

# %%
wr = lc.manhattan_world(300, seed=2, grid_extent=8, sigma_theta=0.05, p_loop_closure=0.1)
tr = wr.truth
lo, hi = tr[:, :2].min(0), tr[:, :2].max(0)
start = {0: tuple(tr[0])}

def room(pv):
    return [V.box_constraint(pv, xmin=lo[0], xmax=hi[0], ymin=lo[1], ymax=hi[1], name="room")]

plain = lc.lago(wr.graph, anchors=start, positions="phase3")
boxed = V.constrained_lago(wr.graph, room, anchors=start)
outside = int(((plain.poses[:, :2] < lo - 1e-9) | (plain.poses[:, :2] > hi + 1e-9)).any(1).sum())
print(f"{wr.graph.n_loop_closures} loop closures; LAGO puts {outside} of {wr.graph.n_poses} poses outside the room")
print(f"ATE: LAGO {lc.ate(plain.poses, tr):.3f} m → with the room {lc.ate(boxed.poses, tr):.3f} m; "
      f"χ² {plain.chi2:.1f} → {boxed.chi2:.1f}")

# %% tags=["remove-input"]
check(outside > 0 and lc.ate(boxed.poses, tr) < lc.ate(plain.poses, tr),
      "the room constraint brings the estimate closer to the truth (while χ² rises: the data alone prefer the drift)")

# %% [markdown]
# The same phase 3 by hand, on the package's phase-3 system (`V.system_problem` returns the problem, its
# variable and the anchor constraint), with the walls as one named inequality whose dual values we read:

# %%
problem, x, _ = V.system_problem(boxed.phase3.system)
pv = V.PoseVariables(wr.graph, 3, x, boxed.regularization.theta_tree)
walls = room(pv)[0].constraints[0]                       # n_hᵀ p_v ≤ c_h, 4 rows per pose (+x, −x, +y, −y)
by_hand = cp.Problem(problem.objective, problem.constraints + [walls])
status = solve(by_hand)

# %% tags=["remove-input"]
check(np.abs(x.value - boxed.phase3.x).max() < 1e-6, f"by hand ({status}) = constrained_lago's phase 3")

# %%
lam = np.asarray(walls.dual_value, dtype=float).reshape(-1, 4)            # (poses, walls)
px, py = x.value[0:2 * wr.graph.n_poses:2], x.value[1:2 * wr.graph.n_poses:2]
slack = np.array([hi[0], -lo[0], hi[1], -lo[1]]) - np.column_stack([px, -px, py, -py])   # c_h − n_hᵀp_v ≥ 0
normals = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], float)
wall_force = -lam @ normals                                               # the walls push inward
touching = lam.max(1) > 1e-6 * lam.max()
print(f"{int(touching.sum())} poses are held by a wall; largest force {np.linalg.norm(wall_force, axis=1).max():.1f}")

# %% tags=["remove-input"]
check(np.all(lam >= -1e-7 * lam.max()), "wall multipliers are ≥ 0")
check(np.abs(lam * slack).max() < 1e-6 * lam.max() * np.ptp(tr[:, :2]),
      "complementary slackness: a wall pushes only on the poses that touch it")

# %%
fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
for ax, resv, title in ((axes[0], plain, "LAGO"), (axes[1], boxed, "LAGO + room, with the wall forces")):
    plot_trajectory(ax, tr, color="0.6", linewidth=2.5, label="truth")
    plot_trajectory(ax, resv.poses, color="tab:blue", label=f"estimate (ATE {lc.ate(resv.poses, tr):.3f} m)")
    ax.add_patch(plt.Rectangle(lo, *(hi - lo), fill=False, edgecolor="tab:red", ls="--", lw=1.5, zorder=5))
    ax.set_title(title)
p_b = boxed.poses[touching, :2]
f_b = wall_force[touching]
axes[1].scatter(p_b[:, 0], p_b[:, 1], s=12, color="tab:red", zorder=6, label="poses held by a wall")
axes[1].quiver(p_b[:, 0], p_b[:, 1], f_b[:, 0], f_b[:, 1], color="tab:red", angles="xy", scale_units="xy",
               scale=np.linalg.norm(f_b, axis=1).max() / 1.5, width=0.006, zorder=6)   # longest arrow: 1.5 m
for ax in axes:
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, fontsize=8)
show(fig, "room")

# %% [markdown]
# **Infeasible constraints** raise `InfeasibleConstraintsError` naming the culprits: first the constraints
# that are infeasible on their own (with the anchors), otherwise an irreducible infeasible subset found by a
# deletion filter.

# %%
cases = {
    "alone": lambda pv: [room(pv)[0], V.box_constraint(pv, poses=[0], xmin=hi[0] + 1, name="start east of the room")],
    "jointly": lambda pv: [room(pv)[0], V.box_constraint(pv, poses=[50], xmax=0.0, name="west zone"),
                           V.box_constraint(pv, poses=[50], xmin=1.0, name="east zone")],
}
blamed = {}
for label, fn in cases.items():
    try:
        V.constrained_lago(wr.graph, fn, anchors=start)
        names = None
    except lc.InfeasibleConstraintsError as exc:
        names = exc.names
        print(f"{label:8s}: {exc}")
    expected = ["start east of the room"] if label == "alone" else ["west zone", "east zone"]
    blamed[label] = (names, expected)

# %% tags=["remove-input"]
for label, (names, expected) in blamed.items():
    check(names is not None and sorted(names) == sorted(expected), f"{label}: infeasibility blamed on {names}")

# %% [markdown]
# ## 6. Robust losses against false loop closures
#
# A false loop closure (perceptual aliasing) enters least squares with a pull proportional to its error. A
# convex robust loss bounds the pull: with $r_k$ the whitened residual rows of edge $k$ and a threshold $M$,
# $$\rho_{\rm huber}(r_k) = \begin{cases}\|r_k\|^2 & \|r_k\|\le M\\ 2M\|r_k\| - M^2 & \text{else}\end{cases}
# = \min_{v_k}\ \|r_k - v_k\|^2 + 2M\|v_k\|,\qquad \rho_{\ell_1}(r_k) = 2M\|r_k\|,$$
# both with gradient at most $2M$ in norm; every phase stays a cvxpy problem (`V.lago_variant(graph,
# loss="huber")`). Outliers also corrupt the $2k\pi$ regularization (a false loop closure can become a tree
# edge of a breadth-first tree), so the convex route below uses the odometric tree and re-rounds every edge
# against the robust phase-1 estimate.
#
# A non-convex loss can do what a convex one cannot: ignore an edge altogether. Truncated least squares,
# $\rho(r) = \min(r^2, \bar c^2)$ with $r^2 = e^\top\Omega e$ the whitened error of eq. (3), is minimized by **graduated non-convexity**
# (GNC; Yang, Antonante, Tzoumas, Carlone, RA-L 2020): a sequence of surrogates $\rho_\mu$, convex for small
# $\mu$ and TLS as $\mu\to\infty$, each minimized by alternating a *weighted* least-squares problem — here a
# weighted LAGO, the information of edge $k$ scaled by $w_k\in[0,1]$ and its $2k\pi$ regularization redone on
# the edges still weighted in — and the weights in closed form,
# $$w_k = 1 \text{ if } r_k^2 \le \tfrac{\mu}{\mu+1}\bar c^2,\quad
#   w_k = 0 \text{ if } r_k^2 \ge \tfrac{\mu+1}{\mu}\bar c^2,\quad
#   w_k = \frac{\bar c}{r_k}\sqrt{\mu(\mu+1)} - \mu \text{ in between},$$
# with $\mu \leftarrow 1.4\mu$ until the weights are binary. $\bar c^2 = 11.34$ is the $\chi^2_3$ quantile at
# 0.99; the odometric edges are trusted (weight 1). `lc.lago(graph, robust=True)`. The question: with 10 %
# false loop closures, which of them reaches the error of LAGO without them?

# %%
wo = lc.manhattan_world(500, seed=0, outlier_fraction=0.1)
go, to, om = wo.graph, wo.truth, wo.outlier_mask
convex = dict(method="cvxpy", spanning_tree="auto", regularization="tree", reround=True)
runs = {"LAGO without the false loop closures": lc.lago(wo.inlier_graph), "LAGO": lc.lago(go),
        "Huber (convex)": V.lago_variant(go, loss="huber", **convex),
        "ℓ1 (convex)": V.lago_variant(go, loss="l1", **convex),
        "GNC, truncated least squares": lc.lago(go, robust=True)}
ref_err = lc.ate(runs["LAGO without the false loop closures"].poses, to)
print(f"{om.sum()} false loop closures among {go.n_loop_closures}")
print(f"{'':38s} {'ATE [m]':>8s} {'× reference':>12s}")
ratio = {}
for name, rr in runs.items():
    ratio[name] = lc.ate(rr.poses, to) / ref_err
    print(f"{name:38s} {lc.ate(rr.poses, to):8.3f} {ratio[name]:12.1f}")
hub = runs["Huber (convex)"]
gnc = runs["GNC, truncated least squares"]
rejected = np.zeros(go.n_edges, bool)
rejected[gnc.rejected_edges] = True
print(f"GNC: {gnc.iterations} iterations, {rejected.sum()} edges rejected: {(rejected & om).sum()} of the "
      f"{om.sum()} false ones and {(rejected & ~om).sum()} true ones")

fig, axes = plt.subplots(1, 3, figsize=(16, 5.2))
for ax, name in zip(axes, ("LAGO", "Huber (convex)", "GNC, truncated least squares")):
    rr = runs[name]
    plot_edges(ax, go.subgraph_edges(om), rr.poses, which="all", color="tab:red", linewidth=0.6, alpha=0.5,
               label="false loop closures")
    plot_trajectory(ax, to, color="0.6", linewidth=2.5, label="truth")
    plot_trajectory(ax, rr.poses, color="tab:blue", label=f"estimate (ATE {lc.ate(rr.poses, to):.2f} m)")
    ax.set_title(name)
    ax.legend(loc="upper right", fontsize=8)
show(fig, "robust")

# %% tags=["remove-input"]
check(hub.robust["edge_weights"][om].max() < 0.5, "the convex loss detects every false loop closure (weight < 0.5)")
check(min(ratio["Huber (convex)"], ratio["ℓ1 (convex)"]) > 5 and ratio["LAGO"] > ratio["Huber (convex)"],
      "…but a bounded pull is not zero: the convex losses stay > 5× the reference error (plain LAGO is worse)")
check(ratio["GNC, truncated least squares"] < 1.05 and rejected[om].all() and rejected[~om].mean() < 0.01,
      "GNC rejects every false loop closure (and < 1 % of the true edges) and recovers the reference")

# %% [markdown]
# The convex losses find the false loop closures — their IRLS weights are small — but many bounded pulls still
# bend the loops that only a few true loop closures hold. Truncated least squares gives a false loop closure
# no pull at all once its residual exceeds $\bar c$; GNC gets there from the convex end, one weighted LAGO per
# step. It is a local method: when the false loop closures outnumber the true ones (MIT with 10 % false edges:
# 82 against 20) it can settle on a wrong set — `benchmarks/robust.md` measures it on real graphs.
#
# ## 7. Anchors on a real graph: closed form against cvxpy
#
# Three poses of the Intel graph (`carlone/input_INTEL_g2o.g2o`, whose information spans nine orders of
# magnitude) anchored at the minimum of eq. (3): the closed form (A2) and the cvxpy problems (A1) on the same
# inputs, estimates and multipliers compared.

# %%
gi = real("carlone/input_INTEL_g2o.g2o")
if gi is not None:
    opt = lc.refine(gi, lc.lago(gi).poses)
    n = gi.n_poses
    anc = {int(gi.ids[i]): tuple(opt.poses[i]) for i in (n // 3, 2 * n // 3, n - 1)}
    three, report = lc.compare_methods(gi, anchors=anc)
    print("largest relative difference, estimate:", {k: f"{v:.1e}" for k, v in report["max_rel_diff"].items()},
          "multipliers:", {k: f"{v:.1e}" for k, v in report["max_rel_diff_gradient"].items()})
    print(f"χ²: minimum {opt.chi2:.2f}, LAGO with the three anchors {three.chi2:.2f}")

# %% tags=["remove-input"]
if gi is not None:
    check(max(report["max_rel_diff"].values()) < 1e-8 and max(report["max_rel_diff_gradient"].values()) < 1e-6,
          "closed form = cvxpy on real data, estimates and anchor forces")
    check(not three.strained, f"anchors at the minimum are not strained (χ² {[round(s.chi2, 3) for s in three.strain]})")

# %% [markdown]
# ### Try it: how hard is a soft anchor?
# Drag the prior's information on pose 40 (mean 1.4 m off LAGO's estimate): from 10⁰ the estimate hardly moves, around
# 10² it is pulled half-way, from 10⁴ it sits within a centimetre of the hard anchor (section 4).

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.prior_weight, "try_prior", log10_information=(0.0, 8.0, 0.5, 2.0))

# %% [markdown]
# **Summary.** The linear phases take extra knowledge without losing their closed form: several anchors (whose
# multipliers are the forces the data exert on them, and whose strain tests whether they are consistent), priors as
# soft anchors, convex constraints with meaningful multipliers, and convex robust losses that bound the pull of
# false loop closures (section 6 measures how far that goes). On a real graph the closed forms and cvxpy agree.

# %% [markdown]
# ## Exercise 3 — Where should truncated least squares truncate?
#
# An inlier's whitened squared residual $e^\top\Omega e$ is $\chi^2_3$-distributed when the measurement is correctly
# modelled. Write `truncation(confidence)`, the $\bar c^2$ that keeps an inlier with that probability; the check
# compares it with the package's default. Then sweep $\bar c^2$ of GNC, `lc.lago(graph,
# robust=V.RobustSettings(threshold=c2))`, on the world of section 6, counting the false and the true edges rejected:
# what happens for very small and very large $\bar c^2$, and why?
#
# **Hint.** `scipy.stats.chi2.ppf`; `res.rejected_edges` and `wo.outlier_mask`; think of the largest $r^2$ a false
# loop closure can have.

# %%
# your solution here: fill in the body of truncation, then run the cell (check_truncation tests it)
from lago_cvx.exercises import check_truncation

def truncation(confidence):
    """c̄²: the χ²₃ quantile at confidence (a float)."""
    raise NotImplementedError

check_truncation(truncation)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. An inlier's whitened squared residual is χ²₃ when the model is right, so truncating at
# the χ²₃ quantile at 0.99 (11.34) rejects about 1 % of the true edges at most. A tiny c̄² rejects true edges by the
# hundred; a huge one accepts the false loop closures, and GNC is least squares again (the sweep below).
import numpy as np
from scipy.stats import chi2
import lago_cvx as lc
from lago_cvx import variants as V
from lago_cvx.exercises import check_truncation

def truncation(confidence):
    return float(chi2.ppf(confidence, 3))

wo = lc.manhattan_world(300, seed=0, outlier_fraction=0.1)
for c2 in (0.5, truncation(0.99), 1e4):
    res = lc.lago(wo.graph, robust=V.RobustSettings(threshold=c2))
    rejected = np.isin(np.arange(wo.graph.n_edges), res.rejected_edges)
    print(f"c̄² = {c2:8.2f}: false loop closures rejected {(rejected & wo.outlier_mask).sum()} of "
          f"{wo.outlier_mask.sum()}, true edges rejected {(rejected & ~wo.outlier_mask).sum()}")
check_truncation(truncation).require()
