# %% [markdown]
# # Lecture 6 — The experiment: Section V on the Intel Research Lab graph
#
# The paper {cite}`carlone2011rss` validates LAGO on one real graph, the Intel Research Lab data set, with two tables
# (Table I, Table II) and three figures (Fig. 1–3). This lecture re-runs that experiment with `lago_cvx` on
# `carlone/INTEL_P_toro.graph`, the Intel graph in TORO format; runs Table II's two covariance scenarios on a world
# with known truth; and then asks the question the abstract answers — is the linear estimate accurate enough that
# refinement is often unnecessary? — on every graph at hand.
#
# **The idea in one paragraph.** A robot drives around an office floor; odometry corrected by scan matching gives a
# trajectory that is right locally and drifts globally, and loop closures say where it came back to a place it had
# seen (Fig. 1, section 3). LAGO turns those measurements into a map in closed form, scored by the relations it
# predicts against true ones (Table II, which needs a truth) or by the χ² it leaves. The paper's scores say that the
# way each measurement's uncertainty is stated matters as much as the method. Below: INTEL's dead reckoning and the
# paper's LAGO, each against the minimum of χ² (grey).
#
# **Learning goals.** After this lecture you can
#
# 1. run the three steps of Section V (constraints → regularization → three phases) on a real graph and
#    reproduce Table I, knowing which of its numbers depend on the spanning tree;
# 2. draw Fig. 1 and Fig. 2(a), and say what Fig. 2(b) needs that the graph files do not contain;
# 3. compute the relative-relations metric of Table II (ε_t, ε_θ) on a world with ground truth, and compare
#    the closed-form estimate with an iterative solver iteration by iteration (Table II, Fig. 3);
# 4. test the abstract's claim "refinement is often unnecessary" on every real graph, and explain with
#    Theorem 1 why it fails on INTEL.
#
# **What cannot be reproduced here, and what replaces it.** The graph files hold no laser scans, so the occupancy grid
# of Fig. 2(b) cannot be drawn (section 4 draws the grid the robot's footprint swept instead). TORO, the iterative
# solver of Table II and Fig. 3, is not part of this package, and the benchmark's ground-truth relations are not
# available: sections 5–6 compute the same metric on a synthetic world with known truth and the paper's proportional
# uncertainty, Gauss–Newton standing in for TORO, beside the paper's values.
#
# **Notation** (lectures 1–5's, and):
#
# | symbol | meaning | in the package |
# |---|---|---|
# | χ² | the cost of eq. (3), $\sum_{ij} e_{ij}^\top \Omega_{ij} e_{ij}$, no factor ½ | `lago_cvx.metrics.chi2` |
# | $\varepsilon_t$, $\varepsilon_\theta$ | Table II's mean squared errors of the relative translations [m²] and rotations [rad²] | `relation_errors` (section 5) |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)
import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np
from dataclasses import replace
import lago_cvx as lc
from lago_cvx.course import FULL, check, intuition_figure, real, running_example, section_v_world, setup, show
from lago_cvx import phases, plotting
from lago_cvx.datasets import DATASET_FILES, REFERENCE_CHI2
from lago_cvx.posegraph import between, wrap_angle
from lago_cvx.solvers import solve
from lago_cvx.positions import resolve_positions
from lago_cvx.theorem1 import frozen_and_model, theorem1
from lago_cvx.uncertainty import edge_uncertainty
setup("06_experiment")
INTEL = real("carlone/INTEL_P_toro.graph")

# %% tags=["remove-input"]
show(intuition_figure("06"), "intuition")

# %% [markdown]
# ## 1. Table I — the Intel graph and its regularization
#
# Section V runs in three steps — the regularization steps (Section V): (i) odometric and loop-closing constraints are
# extracted from the sensor data — here they are given, as the file's edges; (ii) the relative orientations are
# regularized; (iii) the three phases run. Step (ii) rests on three results. Proposition 2 (the odometric edges form a
# spanning tree) and Corollary 3 (the loop closures are its chords) say that with the odometric tree every loop
# closure is exactly one chord, so the cycle basis matrix $C = [I_l\ B]$ of eq. (19) has one row per loop closure.
# Theorem 3 (existence of correction factors) then gives the correction of eq. (23),
# $v = [-(C\delta)^\top\ 0^\top]^\top$: only chords are corrected, and after rounding to the nearest multiple of $2\pi$ the correction of
# chord $c$ is $2\pi k_c$, $k_c = -\mathrm{round}((C\delta)_c / 2\pi)$. A chord "needs regularization" when $k_c \neq
# 0$ — the last column of Table I.
#
# We build $C$ (`lc.cycle_basis`) and count by hand — on INTEL and, beside it, on the running example — then
# compare with the paper's procedure as the package runs it, `lc.lago(graph, route="seed")`.

# %%
TABLE_I = {"nodes": 1228, "odometric constraints": 1227, "loop closing constraints": 278,
           "chords needing regularization": 198}            # the paper's Table I
def table_i(graph):
    """Table I's four numbers for ``graph``, the chords counted by hand; the odometric tree, Cδ and k."""
    tree = lc.spanning_tree(graph, "odometry")              # Proposition 2: the odometric edges
    r = lc.cycle_basis(graph, tree) @ graph.delta           # eq. (19), one row per chord: cycle residuals Cδ
    k = -np.rint(r / (2 * np.pi)).astype(int)               # eq. (23), rounded to 2kπ
    return dict(zip(TABLE_I, (graph.n_poses, graph.n_odometric, graph.n_loop_closures, np.count_nonzero(k)))), tree, r, k
run_row, _, _, run_k = table_i(running_example().graph)
run_paper = lc.lago(running_example().graph, route="seed")
ours = table_i(INTEL)[0] if INTEL is not None else {key: "–" for key in TABLE_I}
print(f"{'Table I':32s} {'paper':>7s} {'INTEL':>7s} {'running example':>16s}")
for key in TABLE_I:
    print(f"{key:32s} {TABLE_I[key]:7d} {ours[key]:>7} {run_row[key]:16d}")
if INTEL is not None:
    g = INTEL
    _, tree, r, k = table_i(g)
    paper = lc.lago(g, route="seed")                        # the paper's procedure
    bfs = lc.lago(g, route="seed", spanning_tree="bfs")
    print(f"the count depends on the tree: with a breadth-first tree only {bfs.regularization.n_regularized} "
          f"of {bfs.tree.n_chords} chords need k ≠ 0")
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.hist(r / (2 * np.pi), bins=np.arange(r.min() / (2 * np.pi) - 0.5, r.max() / (2 * np.pi) + 0.5, 0.05),
            color="tab:blue")
    ax.set(xlabel="cycle residual (Cδ)_c / 2π  [turns]", ylabel="chords",
           title="INTEL, odometric tree: cycle residuals cluster at whole turns")
    show(fig, "cycle_residuals")

# %% tags=["remove-input"]
check(np.array_equal(run_k, run_paper.regularization.k_chords) and run_row["chords needing regularization"] > 0,
      "running example: the hand count equals the package's regularization")
if INTEL is not None:
    check(np.array_equal(np.sort(tree.tree_edges), np.flatnonzero(g.is_odometric)),
          "Proposition 2: the odometric edges are a spanning tree")
    check(np.array_equal(tree.chords, np.flatnonzero(~g.is_odometric)),
          "Corollary 3: the loop closures are exactly its chords")
    check(np.array_equal(k, paper.regularization.k_chords) and paper.regularization.n_regularized == 198,
          "the hand count equals the regularization the package runs for the paper's procedure")
    after = r + 2 * np.pi * k
    check(np.abs(after).max() < np.pi - paper.regularization.margin and paper.regularization.ambiguous.size == 0,
          f"no chord is ambiguous: every corrected residual |C(δ+v)| stays {np.pi - np.abs(after).max():.2f} rad "
          f"away from ±π (ambiguity margin {paper.regularization.margin} rad)")
    check(ours == TABLE_I, "Table I reproduced: 1228 nodes, 1227 odometric, 278 loop closures, 198 chords with k ≠ 0")
    check(bfs.regularization.n_regularized < 198 and abs(bfs.chi2 - paper.chi2) < 1e-8 * paper.chi2,
          "…but the estimate does not: same χ² with either tree")

# %% [markdown]
# All four numbers of Table I come out exactly (the running example's column gives the scale of the course's
# own graph), and the histogram shows why the rounding is safe on INTEL: the cycle residuals cluster at whole
# numbers of turns (the robot's turns between the two ends of a loop closure), and none comes within the
# ambiguity margin of a half turn, where rounding would have to guess. The last number of Table I is a property of the tree, not of the data: a breadth-first tree has
# shorter paths that accumulate fewer turns, fewer chords need a correction, and the regularized
# orientations differ from the odometric tree's only by whole turns per pose — the estimate is the same.
#
# ## 2. Why step (ii) matters: phase 1 as a cvxpy problem
#
# Phase 1, eq. (13), is the weighted least-squares problem $\min_\theta \|P_\delta^{-1/2}(A^\top\theta -
# \delta)\|^2$ with the reference orientation fixed, $\theta_0 = 0$ (the paper deletes row 0 of $A$; here we
# keep all $n+1$ orientations and add the constraint). Built from named parameters, cvxpy prints the equation back:

# %%
if INTEL is not None:
    A = lc.incidence_matrix(g)                               # (n+1) × m
    theta = cp.Variable(g.n_poses, name="θ")
    delta = cp.Parameter(g.n_edges, name="δ")               # the data we will swap
    w = cp.Constant(edge_uncertainty(g).sqrt_info_delta, name="w_δ")   # P_δ^{-1/2}, per edge
    At = cp.Constant(A.T, name="Aᵀ")
    reference = theta[0] == 0
    phase1 = cp.Problem(cp.Minimize(cp.sum_squares(cp.multiply(w, At @ theta - delta))), [reference])
    print(phase1)                                           # (cvxpy writes sum_squares(x) as quad_over_lin(x, 1))
    delta.value = paper.regularization.delta_reg            # regularized: δ + v
    status = solve(phase1)
    theta_reg, cost_reg = theta.value.copy(), phase1.value
    err = np.abs(theta_reg - paper.phase1.theta).max()

# %% tags=["remove-input"]
if INTEL is not None:
    check(status == "optimal" and err < 1e-8, f"cvxpy ({status}) = the closed form of eq. (13): max |Δθ| = {err:.1e} rad")

# %% [markdown]
# Now the point of step (ii). Change the parameter to the raw measurements — no rebuild, just `.value` —
# and solve again: without the corrections $2\pi k$, the loop closures contradict the odometry by whole
# turns, which phase 1 cannot tell from noise, and spreads over the trajectory.

# %%
if INTEL is not None:
    delta.value = g.delta                                   # raw: no regularization
    solve(phase1)
    theta_raw, cost_raw = theta.value.copy(), phase1.value
    print(f"phase-1 cost: regularized {cost_reg:.1f}, raw {cost_raw:.4g} ({cost_raw / cost_reg:.0f}×)")
    unc = edge_uncertainty(g)
    ph2 = phases.phase2(g, theta_raw, unc, information="marginal", delta_reg=g.delta)
    raw_poses = phases.phase3_closed_form(g, ph2).poses    # phases 2–3 on the unregularized orientations
    print(f"χ² of the three phases: regularized {paper.chi2:.4g}, raw {lc.chi2(g, raw_poses):.4g}")
    fig, axs = plt.subplots(1, 2, figsize=(11, 5))
    for ax, poses, title in ((axs[0], paper.poses, "with the 2kπ corrections (Theorem 3)"),
                             (axs[1], raw_poses, "without them (raw δ)")):
        plotting.plot_trajectory(ax, poses, color="tab:blue", linewidth=0.8)
        ax.set_title(title)
    fig.suptitle("INTEL: the three phases with and without step (ii)")
    show(fig, "regularization_matters")

# %% tags=["remove-input"]
if INTEL is not None:
    check(cost_raw > 100 * cost_reg and lc.chi2(g, raw_poses) > 100 * paper.chi2,
          "without regularization phase 1 fits whole turns as noise: the result is meaningless")

# %% [markdown]
# ## 3. Fig. 1 — the odometric trajectory with the loop closures
#
# Fig. 1 shows the odometric trajectory (wheel odometry corrected by scan matching: the file's odometric
# edges) and, dotted, the loop closures. The trajectory is dead reckoning, the odometric measurements
# composed by eq. (1) from $p_0$ (`lc.odometry_guess`); it is also what the file's vertex lines hold.

# %%
if INTEL is not None:
    odo = lc.odometry_guess(g, spanning_tree="odometry")   # dead reckoning along the odometric tree
    dxy = np.abs(odo[:, :2] - g.initial[:, :2]).max()
    dth = np.abs(wrap_angle(odo[:, 2] - g.initial[:, 2])).max()
    fig, ax = plt.subplots(figsize=(7, 7))
    plotting.plot_trajectory(ax, odo, color="tab:blue", linewidth=0.9, label=f"odometric trajectory ({g.n_poses} poses)")
    odo_lc = np.flatnonzero(~g.is_odometric)
    for e in odo_lc:
        ax.plot(odo[[g.tails[e], g.heads[e]], 0], odo[[g.tails[e], g.heads[e]], 1], ":", color="tab:red",
                linewidth=0.7)
    ax.plot([], [], ":", color="tab:red", label=f"loop closures ({g.n_loop_closures})")
    ax.set_title("Fig. 1 — INTEL: odometric trajectory, loop closures dotted")
    ax.legend(loc="lower left")
    show(fig, "fig1")

# %% tags=["remove-input"]
if INTEL is not None:
    check(dxy < 1e-5 and dth < 1e-5, f"dead reckoning = the file's vertices to their 6 printed decimals "
          f"({dxy:.1e} m, {dth:.1e} rad)")

# %% [markdown]
# Scan matching keeps the trajectory locally consistent, but the drift accumulates: the loop closures, which
# join places visited twice, are long segments across the map.
#
# ## 4. Fig. 2 — (a) the estimated configuration, (b) the swept-footprint grid
#
# **(a)** is the estimate of the three-phase procedure, drawn beside the package's default route (beyond the
# paper: breadth-first tree, chordal regularization, full information, positions re-solved) and the minimum
# of eq. (3) found by Gauss–Newton.
#
# **(b)** in the paper is the occupancy grid built by placing the laser scans at the estimated poses. The graph file
# has **no laser scans**, so that map cannot be drawn. The closest honest substitute uses the poses alone: mark the
# cells of a grid that the robot's footprint (radius 0.3 m) swept along the estimated trajectory — the free space the
# robot itself proves. A globally consistent estimate lays a corridor driven twice on top of itself, so its swept area
# shrinks; walls and rooms the robot never entered cannot be recovered without the scans.

# %%
def swept_grid(poses, resolution=0.2, radius=0.3):
    """Boolean grid of the cells within ``radius`` of the trajectory (straight segments between poses),
    its origin, and the swept area [m²]."""
    xy = poses[:, :2]
    s = np.linspace(0.0, 1.0, 8)[:, None, None]
    pts = (xy[:-1] * (1 - s) + xy[1:] * s).reshape(-1, 2)
    r = int(np.ceil(radius / resolution))
    lo = pts.min(0) - (r + 1) * resolution                  # a margin: every cell index is ≥ 0
    idx = np.floor((pts - lo) / resolution).astype(int)
    disk = np.array([(i, j) for i in range(-r, r + 1) for j in range(-r, r + 1)
                     if (i * i + j * j) * resolution**2 <= radius**2])
    cells = (idx[:, None, :] + disk[None]).reshape(-1, 2)
    grid = np.zeros(cells.max(0) + 1, bool)
    grid[cells[:, 0], cells[:, 1]] = True
    return grid, lo, grid.sum() * resolution**2
if INTEL is not None:
    default = lc.lago(g)
    optimum = lc.refine(g, default.poses)
    fig, axs = plt.subplots(1, 3, figsize=(17, 5.8))
    for ax, poses, title in ((axs[0], paper.poses, f"(a) the paper's procedure, χ² = {paper.chi2:.0f}"),
                             (axs[1], default.poses, f"default route, χ² = {default.chi2:.1f}"),
                             (axs[2], optimum.poses, f"minimum of eq. (3), χ² = {optimum.chi2:.1f}")):
        plotting.plot_edges(ax, g, poses, which="loop_closures", color="tab:red", linewidth=0.5, label="loop closures")
        plotting.plot_trajectory(ax, poses, color="tab:blue", linewidth=0.8, label="estimate")
        ax.set_title(title)
    axs[0].legend(loc="lower left", fontsize=8)
    fig.suptitle("Fig. 2(a) — INTEL: estimated node configuration")
    show(fig, "fig2a")
    areas = {}
    fig, axs = plt.subplots(1, 2, figsize=(12, 5.8))
    for ax, (name, poses) in zip(axs, (("odometric trajectory", odo), ("the paper's procedure", paper.poses))):
        grid, lo, areas[name] = swept_grid(poses)
        ax.imshow(~grid.T, origin="lower", cmap="gray", extent=(lo[0], lo[0] + grid.shape[0] * 0.2,
                                                                 lo[1], lo[1] + grid.shape[1] * 0.2))
        ax.set(title=f"{name}: swept area {areas[name]:.0f} m²", xlabel="x [m]", ylabel="y [m]")
    fig.suptitle("Fig. 2(b), substitute — cells swept by a 0.3 m footprint (black); no laser scans in the file")
    show(fig, "fig2b_substitute")
    areas["minimum"] = swept_grid(optimum.poses)[2]
    print({k: f"{v:.1f} m²" for k, v in areas.items()})

# %% tags=["remove-input"]
if INTEL is not None:
    check(optimum.converged and abs(optimum.chi2 - REFERENCE_CHI2["carlone/INTEL_P_toro.graph"]) < 1e-5 * optimum.chi2,
          f"Gauss–Newton from LAGO reaches χ² = {optimum.chi2:.3f}, the lowest known for this file")
    check(areas["the paper's procedure"] < 0.7 * areas["odometric trajectory"]
          and abs(areas["the paper's procedure"] - areas["minimum"]) < 0.05 * areas["minimum"],
          "LAGO's corridors overlap where the robot drove twice: its swept area is the minimum's (±5 %), "
          "well below odometry's")

# %% [markdown]
# At the scale of the map the paper's estimate is hard to tell from the minimum, and its swept area is the
# minimum's. The χ² in the titles says otherwise; section 7 comes back to it.
#
# ## 5. Table II — the paper's two scenarios on a world with ground truth
#
# Table II scores estimates with the SLAM benchmark metric of Kümmerle et al. {cite}`kummerle2009measuring`: over a set of
# relations $(i,j)$ with known true relative pose $\delta^*_{ij}$, the estimate's relative pose
# $\hat\delta_{ij} = \hat p_j \ominus \hat p_i$ (eq. (1)) is compared with it,
# $$\varepsilon_t = \frac1N\sum_{(i,j)}\big\|\mathrm{trans}(\hat\delta_{ij}\ominus\delta^*_{ij})\big\|^2\ [\mathrm m^2],
# \qquad \varepsilon_\theta = \frac1N\sum_{(i,j)}\mathrm{rot}(\hat\delta_{ij}\ominus\delta^*_{ij})^2\ [\mathrm{rad}^2].$$
#
# **The paper's two scenarios.** In one, $P_{ij} = I_3$ for every edge. In the other, $P_{ij} =
# \mathrm{diag}(P_{\Delta l,ij}, P_{\delta,ij})$ with "the corresponding uncertainties […] assumed to be proportional
# to the respective measurements, e.g. bigger displacements correspond to higher uncertainty". The paper gives no
# constants; we take, per component of the measured relative pose, $\sigma = 0.1\,|\Delta l_x| + 1\,\mathrm{mm}$ (and
# the same for $y$) and $\sigma_\delta = 0.05\,|\delta| + 10^{-3}$ rad (`course.section_v_world`): a floor keeps the
# information finite on edges that do not move along an axis, as INTEL's file does (lecture 4b, section 2).
#
# **What replaces what is missing.** INTEL's benchmark relations (hand-checked scan alignments) are not available: the
# world is a 500-pose Manhattan world of its own (the running example's information is the same on every edge, not
# proportional), the relations its edges with their true relative poses. TORO is not available either. **Gauss–Newton
# on eq. (3), started from odometry, stands in for it** — the "direct (iterative) method" of Remark 1, the package's
# own (`lc.refine`). It is not TORO: TORO does stochastic gradient descent on a tree parametrization of the poses,
# takes hundreds of cheap steps, and is built to survive a poor initial guess; Gauss–Newton takes a few expensive
# steps and can stop in a local minimum. The minimum of χ² (Gauss–Newton from LAGO) is the best any iterative solver
# can reach.
#
# **Two worlds.** The paper's scenario as it is stated has noise that really is proportional to the
# displacement; then the proportional $P$ is the *true* covariance (world A). But on real data nobody
# knows the noise; the proportional $P$ may be only an assumption. World B draws isotropic noise
# ($\sigma_{xy} = 2$ cm, $\sigma_\theta = 0.01$ rad) and keeps the same proportional rule for $P$.

# %%
def relation_errors(graph, poses, truth):
    """(ε_t [m²], ε_θ [rad²]): mean squared translation and rotation error of the estimated relative poses
    over the edges of ``graph``, against the true relative poses."""
    est = between(poses[graph.tails], poses[graph.heads])
    ref = between(truth[graph.tails], truth[graph.heads])
    d = between(ref, est)                                   # δ̂ ⊖ δ*, in the frame of δ*
    return float(np.mean(np.sum(d[:, :2] ** 2, 1))), float(np.mean(wrap_angle(d[:, 2]) ** 2))
#: The paper's Table II (INTEL; ε_t [m²], ε_θ [rad²]) as far as its scan can be read: the scan prints one
#: line of exponents (−3, −4, −4, −4) between the two TORO rows, read here as applying to both.
PAPER_TABLE_II = {"TORO, 100 iterations": {"proportional": (2.60e-3, 2.30e-4), "P = I₃": (6.16e-4, 1.62e-4)},
                  "TORO, 1000 iterations": {"proportional": (1.90e-3, 2.18e-4), "P = I₃": (5.83e-4, 1.62e-4)},
                  "LAGO": {"proportional": (0.91e-2, 2.25e-4), "P = I₃": (3.36e-4, 2.00e-4)}}
STOPS = (1, 10, 100)

def table_ii(graph, truth):
    """The rows of Table II for both scenarios of ``graph`` (its own P, then P = I₃)."""
    table, runs = {}, {}
    identity = np.broadcast_to(np.eye(3), graph.information.shape).copy()
    for scenario, gs in (("proportional", graph), ("P = I₃", replace(graph, information=identity))):
        start = lc.odometry_guess(gs)
        rows = {"odometry": start}
        for stop in STOPS:
            rows[f"Gauss–Newton, {stop} it."] = lc.refine(gs, start, max_iterations=stop).poses
        runs[scenario] = lc.refine(gs, start, max_iterations=1000)
        rows["Gauss–Newton, converged"] = runs[scenario].poses
        default = lc.lago(gs)
        rows["minimum of χ² (from LAGO)"] = lc.refine(gs, default.poses).poses
        rows["LAGO, the paper's procedure"] = lc.lago(gs, route="seed").poses
        rows["LAGO, default route"] = default.poses
        table[scenario] = {row: relation_errors(graph, p, truth) for row, p in rows.items()}
    return table, runs

def print_table(title, table, runs):
    print(f"{title}\n{'':36s}{'proportional P':>26s}{'P = I₃':>26s}\n{'':36s}" + f"{'ε_t [m²]':>13s}{'ε_θ [rad²]':>13s}" * 2)
    for row in PAPER_TABLE_II:
        print(f"{'paper: ' + row:36s}" + "".join(f"{v[0]:13.2e}{v[1]:13.2e}" for v in PAPER_TABLE_II[row].values()))
    for row in table["proportional"]:
        print(f"{row:36s}" + "".join(f"{table[s][row][0]:13.2e}{table[s][row][1]:13.2e}" for s in table))
    print("Gauss–Newton converged after " + ", ".join(f"{r.iterations} iterations ({s})" for s, r in runs.items()))

def compare(table):
    """The paper's findings, each a ratio of two entries (row, scenario, column), in the paper and here; a
    finding agrees when both ratios lie on the same side of 1 (within 2 % of 1: no difference)."""
    it, lago, prop, iden = "Gauss–Newton, converged", "LAGO, the paper's procedure", "proportional", "P = I₃"
    paper_row = {lago: "LAGO", it: "TORO, 1000 iterations"}
    findings = [("P = I₃ lowers LAGO's ε_θ", (lago, prop, 1), (lago, iden, 1)),
                ("P = I₃ lowers the iterative solver's ε_θ", (it, prop, 1), (it, iden, 1)),
                ("LAGO's ε_t, proportional P / P = I₃", (lago, prop, 0), (lago, iden, 0)),
                ("the iterative solver's ε_t, proportional P / P = I₃", (it, prop, 0), (it, iden, 0)),
                ("proportional P: LAGO's ε_t / the iterative solver's", (lago, prop, 0), (it, prop, 0)),
                ("P = I₃: LAGO's ε_t / the iterative solver's", (lago, iden, 0), (it, iden, 0))]
    agree = {}
    print(f"{'finding (iterative: TORO 1000 it. in the paper, converged Gauss–Newton here)':70s} {'paper':>7s} {'here':>7s}")
    for name, (row, scn, col), (row2, scn2, col2) in findings:
        p = PAPER_TABLE_II[paper_row[row]][scn][col] / PAPER_TABLE_II[paper_row[row2]][scn2][col2]
        o = table[scn][row][col] / table[scn2][row2][col2]
        side = [0 if abs(np.log(r)) < np.log(1.02) else np.sign(np.log(r)) for r in (p, o)]
        agree[name] = side[0] == side[1]
        print(f"{name:70s} {p:7.2f} {o:7.2f}  {'agrees' if agree[name] else 'DISAGREES'}{'' if side[1] else ' (≈ 1)'}")
    return agree

world_a, truth_a = section_v_world(noise="proportional")   # own world: Table II needs truth and the proportional P
world_b, truth_b = section_v_world(noise="isotropic")
print(f"{world_a.n_poses} poses, {world_a.n_edges} relations (the edges, {world_a.n_loop_closures} loop closures)")
table_a, runs_a = table_ii(world_a, truth_a)
table_b, runs_b = table_ii(world_b, truth_b)
print_table("\nWorld A — noise proportional to the displacement (the proportional P is true)", table_a, runs_a)
agree_a = compare(table_a)
print_table("\nWorld B — isotropic noise, the proportional P assumed", table_b, runs_b)
agree_b = compare(table_b)

# %% tags=["remove-input"]
a, b, L, G = table_a, table_b, "LAGO, the paper's procedure", "Gauss–Newton, converged"
check(all(a["proportional"][r][c] < a["P = I₃"][r][c] for r in (L, G) for c in (0, 1)),
      "world A: the true (proportional) P gives both methods a lower ε_t and ε_θ than P = I₃ — the paper found the opposite")
check(all(agree_b[f] for f in list(agree_b)[:4]), "world B: P = I₃ lowers ε_t and ε_θ of both methods, as in the paper")
check(all(abs(t[s][L][0] / t[s][G][0] - 1) < 0.05 for t in (a, b) for s in t),
      "LAGO's ε_t is within 5 % of the converged iterative solver's in both worlds and both scenarios")
up = {r: 100 * (np.array(a["proportional"][r]) / a["proportional"]["minimum of χ² (from LAGO)"] - 1) for r in (L, "LAGO, default route")}
check(all(5 < up[r][1] < 20 for r in up) and up[L][0] < 5 < 15 < up["LAGO, default route"][0] < 40, "world A, proportional P, "
      "above the minimum's: " + "; ".join(f"{r[6:]} ε_t {up[r][0]:+.0f} %, ε_θ {up[r][1]:+.0f} %" for r in up))

# %% [markdown]
# **World A, the scenario as stated.** Here the proportional $P$ is the true covariance, and it helps: with it, both
# methods' $\varepsilon_\theta$ *and* $\varepsilon_t$ are lower than with $P = I_3$ — the **opposite** of the paper on
# its four scenario findings, where $P = I_3$ did better. Gauss–Newton from odometry reaches the minimum of χ²; LAGO's
# relations stay above the minimum's (the last check above): about 10 % in $\varepsilon_\theta$ on either route; in
# $\varepsilon_t$ a few per cent with the paper's procedure but over 20 % with the default route, whose joint step
# lowers χ², not these errors.
#
# **World B, the proportional $P$ assumed but not true.** Now the paper's pattern across the scenarios appears (the
# first four findings agree): $P = I_3$ lowers $\varepsilon_\theta$ of both methods about ten times and
# $\varepsilon_t$ about three times. What does not appear is the paper's gap between the methods: there LAGO loses
# $27\times$ in $\varepsilon_t$ to the proportional $P$ and TORO $3\times$; here LAGO and the converged iterative
# solver end within 3 % of each other in every case (≈ 1: within 2 %). So Table II's scenarios look like an *assumed*
# proportional $P$ — its $P = I_3$ doing better already suggests that INTEL's real errors were not proportional to the
# displacements — but its large LAGO penalty is not reproduced by these worlds, and where it comes from (TORO's 100 or
# 1000 iterations are not a converged solver; INTEL's own information, lecture 4b) cannot be told from them.
#
# ## 6. Fig. 3 — errors versus iterations
#
# Fig. 3 of the paper plots, for the proportional scenario, (a) $\varepsilon_t$ and (b) $\varepsilon_\theta$ of TORO
# over 0–1000 iterations (solid) against the level of the three-phase procedure (dashed); TORO ends below LAGO's line
# in $\varepsilon_t$. Here the solid line is Gauss–Newton from odometry, the stand-in of section 5, run one iteration
# at a time until it converges (Gauss–Newton keeps no state between iterations, so this is the same run — checked
# against the χ² log of the uninterrupted run), on both worlds. Gauss–Newton converges in well under 100 iterations:
# beyond that its line is flat, so 100 iterations show whether it crosses LAGO's line or not.

# %%
HORIZON = 100
curves, stepwise = {}, {}
for label, (world, truth, runs) in {"world A (proportional noise)": (world_a, truth_a, runs_a),
                                    "world B (isotropic noise)": (world_b, truth_b, runs_b)}.items():
    poses = lc.odometry_guess(world)
    chis, errs = [lc.chi2(world, poses)], [relation_errors(world, poses, truth)]
    for _ in range(runs["proportional"].iterations):
        poses = lc.refine(world, poses, max_iterations=1).poses
        chis.append(lc.chi2(world, poses))
        errs.append(relation_errors(world, poses, truth))
    stepwise[label] = (chis, runs)
    curves[label] = np.array(errs)

fig, axs = plt.subplots(2, 2, figsize=(11, 7.5))
for row, (label, errs) in enumerate(curves.items()):
    table = table_a if row == 0 else table_b
    for col, name in enumerate(("ε_t [m²]", "ε_θ [rad²]")):
        ax = axs[row, col]
        k = np.arange(errs.shape[0])
        ax.semilogy(k, errs[:, col], "-o", ms=3, color="tab:blue", label="Gauss–Newton from odometry")
        ax.semilogy([k[-1], HORIZON], [errs[-1, col]] * 2, ":", color="tab:blue", label="(converged: no change)")
        for route, style in (("LAGO, the paper's procedure", "--"), ("LAGO, default route", "-.")):
            ax.axhline(table["proportional"][route][col], color="k", linestyle=style, linewidth=1.0, label=route)
        ax.set(xlabel="iterations", ylabel=name, title=f"{label}: {'(a)' if col == 0 else '(b)'} {name}",
               xlim=(0, HORIZON))
        ax.grid(True, which="both", alpha=0.3)
axs[0, 0].legend(fontsize=8)
fig.suptitle("Fig. 3 — errors versus iterations, proportional P (Gauss–Newton standing in for TORO)")
fig.tight_layout()
show(fig, "fig3")

# %% tags=["remove-input"]
for label, (chis, runs) in stepwise.items():
    check(np.allclose(chis, [e["chi2"] for e in runs["proportional"].log], rtol=1e-9),
          f"{label}: one iteration at a time = the uninterrupted Gauss–Newton run")
for (label, errs), table in zip(curves.items(), (table_a, table_b)):
    lago = table["proportional"]["LAGO, the paper's procedure"][0]
    reach = next((i for i, v in enumerate(errs[:, 0]) if v <= lago), None)
    check(reach is not None and reach >= 2 and errs[-1, 0] > 0.9 * lago, f"{label}: Gauss–Newton from odometry first "
          f"reaches LAGO's ε_t after {reach} iterations, and ends at {errs[-1, 0] / lago:.3f} of it")

# %% [markdown]
# In both worlds the solid line crosses LAGO's dashed line in $\varepsilon_t$ and ends just below it (the
# ratios are printed above), where TORO in the paper ends almost five times below. In both, an iterative
# solver needs iterations where LAGO needs none: one Gauss–Newton iteration from odometry is far worse.
#
# ## 7. The abstract's claim on every real graph
#
# The abstract says that "the experimental analysis demonstrates that such refinement is often unnecessary, since the
# linear estimate is already accurate" (abstract: refinement often unnecessary). Without ground truth, accuracy is the
# cost the estimate leaves: χ² of eq. (3) — in the cost the file means — at LAGO's estimate over the minimum, found by
# Gauss–Newton from the default route and checked against the lowest χ² known for each file
# (`lago_cvx.datasets.REFERENCE_CHI2`). The first row is the running example, for comparison. Two columns diagnose a
# failure of the paper's procedure: the ambiguous chords of its regularization (cycle residuals within 0.5 rad of ±π,
# where the $2k\pi$ rounding may be wrong) and χ² at Theorem 1's sub-optimal estimate $\hat\rho = [\hat p; \hat\theta]$
# (the positions of eq. (14) for phase 1's orientations). Last, for the paper's other use — LAGO as an iterative
# solver's initial guess — Gauss–Newton's iterations from LAGO and from odometry.

# %%
FILES = [f for f in DATASET_FILES if f in REFERENCE_CHI2]
if not FULL:
    FILES = [f for f in FILES if f != "se-sync/city10000.g2o"]   # the largest graph: LAGO_CVX_FULL=1
rows = {}
for rel in ["running example"] + FILES:
    gr = running_example().graph if rel == "running example" else INTEL if "INTEL_P" in rel else real(rel)
    if gr is None:
        continue
    seed_route = lc.lago(gr, route="seed")                   # the paper's procedure
    t1r = theorem1(gr, seed_route)                           # ρ̂ of Theorem 1 for it
    default_route = lc.lago(gr)
    from_lago = lc.refine(gr, default_route.poses)
    low = from_lago.chi2
    rows[rel] = {"poses": gr.n_poses, "min": low, "paper": seed_route.chi2 / low, "default": default_route.chi2 / low,
                 "ambiguous": seed_route.regularization.ambiguous.size, "rho_hat": t1r.chi2_suboptimal / low,
                 "it_lago": from_lago.iterations, "odo": float("nan"), "it_odo": -1,
                 "ok": from_lago.converged and abs(low - REFERENCE_CHI2.get(rel, low)) <= 1e-5 * low}
    if FULL or gr.n_poses <= 2000:                           # from odometry: slow on the 3500-pose graphs
        from_odo = lc.refine(gr, lc.odometry_guess(gr), max_iterations=100)
        rows[rel].update(odo=from_odo.chi2 / low, it_odo=from_odo.iterations)
print(f"{'':48s} {'χ² / min':^34s} {'Gauss–Newton iterations':^30s}")
print(f"{'file':30s} {'poses':>6s} {'min χ²':>9s}  {'paper':>8s} {'default':>8s} {'ρ̂':>7s} {'ambig.':>7s}  "
      f"{'from LAGO':>10s} {'from odometry (→ /min)':>24s}")
for rel, r in rows.items():
    odo = f"{r['it_odo']:12d} (→ {r['odo']:.3g})" if r["it_odo"] >= 0 else f"{'(LAGO_CVX_FULL=1)':>20s}"
    print(f"{rel:30s} {r['poses']:6d} {r['min']:9.6g}  {r['paper']:8.5g} {r['default']:8.4f} {r['rho_hat']:7.3f} "
          f"{r['ambiguous']:7d}  {r['it_lago']:10d} {odo}")
files = {rel: r for rel, r in rows.items() if rel in REFERENCE_CHI2}   # the real graphs
if files:
    holds = sorted(rel for rel, r in files.items() if r["paper"] < 1.03)
    fails = sorted(rel for rel, r in files.items() if r["paper"] >= 1.03)
    print(f"paper's procedure within 3 % of the minimum on {len(holds)} of {len(files)} files: {holds}")
    print(f"above it on {len(fails)}: {fails}")
    trapped = sorted(rel for rel, r in files.items() if r["odo"] > 1.5)
    print(f"from odometry Gauss–Newton stops in a local minimum (> 1.5× the minimum) on {trapped}")

# %% tags=["remove-input"]
check(rows["running example"]["paper"] < 1.01, "running example: the paper's procedure within 1 % of the minimum")
if files:
    check(all(r["ok"] for r in rows.values()),
          "Gauss–Newton from LAGO (default route) converges to the lowest known χ² on every file")
    mild = sorted(f for f in fails if rows[f]["paper"] <= 5)
    check(2 * len(mild) < len(fails) and all(rows[f]["paper"] < 1.1 for f in mild), f"fails by > 5× but on {mild}")
    wrong_integers = [f for f in fails if rows[f]["ambiguous"] > 0]
    overshoot = [f for f in fails if rows[f]["ambiguous"] == 0]
    check(all(rows[f]["rho_hat"] > 1.1 for f in wrong_integers),
          f"with ambiguous chords ({wrong_integers}) already ρ̂ is far off: wrong 2kπ integers")
    check(all(rows[f]["rho_hat"] < 1.05 for f in overshoot),
          f"without them ({overshoot}) ρ̂ is within 5 % of the minimum: phase 3's step is what fails")
    check(all(r["default"] < 1.05 for r in rows.values()), "the default route is within 5 % of the minimum on every file")
    if "se-sync/MIT.g2o" in rows:
        check("se-sync/MIT.g2o" in trapped, "MIT: from odometry Gauss–Newton is trapped, from LAGO it is not")
    slow = sorted(rel for rel, r in rows.items() if r["it_lago"] > 10)          # input_INTEL: information 11 … 1e8
    check(max(r["it_lago"] for r in rows.values()) <= 40 and set(slow) <= {"carlone/input_INTEL_g2o.g2o"},
          f"from LAGO Gauss–Newton reaches the minimum on every file within 10 iterations but {slow or 'none'}")
if "carlone/INTEL_P_toro.graph" in rows:
    check(rows["carlone/INTEL_P_toro.graph"]["paper"] > 50,
          f"INTEL: the paper's procedure leaves {rows['carlone/INTEL_P_toro.graph']['paper']:.1f}× the minimum")

# %% [markdown]
# So the claim needs its qualifier. With the paper's procedure it holds — within a few per cent of the minimum — on the
# running example and on some of these graphs (the list is printed) and fails on the others, by large factors on most
# (the M3500 world with Olson's anisotropic information only by about 5 %): on INTEL itself, the graph of Section V, the
# paper's procedure leaves more than 50× the minimum χ² (the factor is printed above). The failures have two causes,
# which the two diagnostic columns tell apart. Where chords are ambiguous, the rounding of Theorem 3 along the odometric
# tree picks wrong integers and already $\hat\rho$ is far off (lecture 8 takes this up). Where no chord is ambiguous —
# INTEL among them — $\hat\rho$ is within a few per cent of the minimum and phase 3 itself makes it worse; the next
# section shows how. The other use holds everywhere: from LAGO, Gauss–Newton reaches the minimum on every file, in a few
# iterations on all but input_INTEL (information 11 to 1e8); from odometry it can stop in a local minimum.
#
# ## 8. Why INTEL fails: Theorem 1 measured
#
# Theorem 1 (the three phases approximate the solution of eq. (6); phase 3 is a local correction of the sub-optimal
# estimate $\hat\rho = [\hat p; \hat\theta]$ "leading it towards a minimum") has two parts: the identity $\rho^* =
# \hat\rho + $ the corrections of eqs. (16)–(17), and the claim that the correction lowers the cost. Lecture 4b
# measures both and explains the failure; here are INTEL's numbers for it, and the running example's. Phase 3 is the
# step from $\hat\rho$ ($\hat p$ of eq. (14)) that minimises the expansion of eq. (18), whose translational weights
# are frozen at $\hat\theta$. With those weights the step works. Its orientations $\theta^*$ are good, too: with the
# positions re-solved for them, $F(\theta^*)$, χ² is *lower* than at $\hat\theta$. They differ from the optimum's
# orientations by an almost constant angle — the map turned about pose 0 as a near-rigid body. But its positions $p^*$
# were weighed in the frames of $\hat\theta$, and INTEL's information is stiff by eight orders of magnitude across the
# direction of motion (lecture 4b, section 2: $\sigma = 0.1\lVert\Delta^l\rVert$ with a floor of 0.1 mm there, against
# 0.3 m along it). That is the paper's proportional scenario in one direction only, and it is exactly where frozen
# weights fail.

# %%
t_run = theorem1(running_example().graph, route="seed")    # isotropic translational information
print(f"running example: χ²(ρ̂) = {t_run.chi2_suboptimal:.2f} → χ²(ρ*) = {t_run.chi2_phase3:.2f}")
if INTEL is not None:
    t1 = theorem1(g, route="seed")
    ref = REFERENCE_CHI2["carlone/INTEL_P_toro.graph"]
    star = t1.poses(t1.x_star)
    frozen, _ = frozen_and_model(t1.result, star)
    F_hat = lc.chi2(g, resolve_positions(g, t1.result.phase1.theta, t1.result.uncertainty).poses)
    turn = wrap_angle(star[1:, 2] - optimum.poses[1:, 2])
    parts = {name: lc.chi2_parts(g, p) for name, p in (("phase 3 (ρ*)", star), ("minimum", optimum.poses))}
    print(f"identity ρ* = ρ̂ + corrections (eqs. (16)–(17)): relative error {t1.identity_error:.1e}")
    print(f"χ²(ρ̂) = {t1.chi2_suboptimal:.2f} ({t1.chi2_suboptimal / ref:.3f}× the minimum {ref:.2f}); χ²(ρ*) = "
          f"{t1.chi2_phase3:.2f} ({t1.chi2_phase3 / ref:.1f}×); with the weights frozen at θ̂, χ²(ρ*) = {frozen:.2f}")
    print(f"positions re-solved: F(θ̂) = {F_hat:.2f}, F(θ*) = {t1.chi2_resolved:.2f}")
    print(f"θ* − θ_opt: mean {turn.mean():+.4f} rad, spread {turn.std():.4f} rad")
    for name, p in parts.items():
        print(f"{name:14s} translational part of χ² {p['translation']:9.1f}, rotational {p['rotation']:7.1f}")

# %% tags=["remove-input"]
check(t_run.chi2_phase3 < t_run.chi2_suboptimal, "running example: the step lowers χ², as Theorem 1 says")
if INTEL is not None:
    check(t1.identity_error < 1e-9, "the identity of Theorem 1's proof holds")
    check(frozen < t1.chi2_suboptimal < 1.05 * ref < t1.chi2_phase3 / 50,
          "ρ̂ is within 5 % of the minimum; the step lowers χ² with frozen weights and raises it above 50× with the true ones")
    check(t1.chi2_resolved < F_hat and t1.chi2_resolved < 1.01 * ref,
          "F(θ*) < F(θ̂), within 1 % of the minimum: the orientations of phase 3 are not what fails")
    check(turn.std() < 0.1 * abs(turn.mean()), "θ* − θ_opt is a near-constant angle: a near-rigid turn")
    check(parts["phase 3 (ρ*)"]["translation"] - parts["minimum"]["translation"] > 0.99 * (t1.chi2_phase3 - ref),
          "the excess is in the positions: the translational part of χ²")

# %% [markdown]
# On the running example (isotropic translational information) frozen weights are the true ones and the step lowers
# χ². Re-solving the positions for phase 3's orientations, as the default route does, brings INTEL within 1 % of it.

# %% [markdown]
# **Summary.** Section V re-run: Table I, Figs. 1–3 and Table II's metric, the abstract's claim on every real graph.

# %% [markdown]
# ## Exercise 1 — The metric needs no alignment
#
# Write `relation_errors(graph, poses, truth)`, the $(\varepsilon_t, \varepsilon_\theta)$ of section 5: unlike the ATE it
# needs no alignment, $(T\oplus\hat p_i)^{-1}\oplus(T\oplus\hat p_j) = \hat p_i^{-1}\oplus \hat p_j$ for a rigid motion $T$
# (the check moves a LAGO estimate). **Hint.** Compare the estimated and true relative poses (`between`); wrap the angle.

# %%
# your solution here: fill in the body, then run the cell (check_relation_errors tests it)
from lago_cvx.exercises import check_relation_errors
def relation_errors(graph, poses, truth):  # (ε_t [m²], ε_θ [rad²])
    raise NotImplementedError
check_relation_errors(relation_errors)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. R(φ + θ_i)ᵀR(φ) = R(θ_i)ᵀ: relative poses, hence ε_t, ε_θ, do not see T; the ATE aligns first.
from lago_cvx.exercises import check_relation_errors
from lago_cvx.posegraph import between, wrap_angle
def relation_errors(graph, poses, truth):
    d = between(between(truth[graph.tails], truth[graph.heads]), between(poses[graph.tails], poses[graph.heads]))
    return float((d[:, :2] ** 2).sum(1).mean()), float((wrap_angle(d[:, 2]) ** 2).mean())
check_relation_errors(relation_errors).require()

# %% [markdown]
# ## Exercise 2 — Table I for every graph
#
# Write `table_one_row(graph, kind)` (poses, odometric edges, loop closures, chords with $k \ne 0$ along the tree `kind`)
# for every real graph: which tree needs fewer corrections, and is it a theorem? **Hint.** Section 1; `lc.regularize`.

# %%
# your solution here: fill in the body, then run the cell (check_table_one tests it)
from lago_cvx.exercises import check_table_one
def table_one_row(graph, kind):  # (poses, odometric, loop closures, k ≠ 0)
    raise NotImplementedError
check_table_one(table_one_row)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. The BFS tree's paths are shortest, so its cycles sum fewer turns: fewer k ≠ 0 (not a theorem).
import lago_cvx as lc
from lago_cvx.exercises import check_table_one
def table_one_row(graph, kind):
    k = lc.regularize(graph, lc.spanning_tree(graph, kind)).k
    return graph.n_poses, graph.n_odometric, graph.n_loop_closures, int((k != 0).sum())
check_table_one(table_one_row).require()
