# %% [markdown]
# # Lecture 5 — Regularization: cycles, the cycle basis and the $2k\pi$ corrections
#
# *L. Carlone, R. Aragues, J. A. Castellanos, B. Bona, "A Linear Approximation for Graph-based
# Simultaneous Localization and Mapping", RSS 2011 {cite}`carlone2011rss` — Section IV-E and the regularization
# steps of Section V; cycle bases as in {cite}`carlone2014ijrr`.*
#
# Phase 1 (lecture 2) treats the relative orientations $\delta$ as real numbers whose sums around every loop
# vanish up to noise. A sensor reports them only modulo $2\pi$: after a full turn the loop closure reads
# $\approx 0$, not $2\pi$. Each must first be corrected by the right multiple of $2\pi$: *regularization*.
# Below, phase 1 on the running example with and without the corrections.
#
# **Learning goals.** After this lecture you can
#
# 1. explain the wraparound problem, and the fundamental circuits of a spanning tree as a cycle basis
#    (Definition 1, Theorem 2, Corollaries 1–2, eq. (19));
# 2. state the zero-sum property (eqs. (20)–(21)) and prove Theorem 3 (eqs. (22)–(23));
# 3. use Proposition 2 and Corollary 3 to see why the paper corrects only loop closures, and reproduce Table I;
# 4. measure when the rounding finds the true $k$, and how the chordal regularizer (beyond the paper) helps.
#
# **Notation** (lecture 1's, and):
#
# | symbol | meaning | in the package |
# |---|---|---|
# | $A$ | the incidence matrix, $(n+1)\times m$ (column of edge $(i,j)$: $-1$ at $i$, $+1$ at $j$); reduced: without pose 0's row | `lc.incidence_matrix`, `lc.reduced_incidence` |
# | $T$, $l = m - n$ | a spanning tree and the number of its chords | `lc.spanning_tree(graph, kind)`, `tree.chords` |
# | $c^{(k)}$, $C = [I_l\ B]$ | the fundamental circuit of chord $k$; the cycle basis matrix, one row per chord (eq. (19)); this $B$ is not phase 3's (lecture 4a) | `lc.cycle_basis(graph, tree)` |
# | $\delta$, $k$, $\delta_{\rm reg}$ | the measured relative orientations; the integers; $\delta + 2\pi k$ (eq. (23)) | `regularize(...).k`, `.delta_reg` |

# %%
try:                                  # run alone (Colab, a fresh environment)? then install the package first
    import lago_cvx  # noqa: F401
except ImportError:
    import subprocess, sys; subprocess.run([sys.executable, "-m", "pip", "install", "lago-cvx[course]"], check=True)
import cvxpy as cp
import matplotlib.pyplot as plt
import numpy as np
import scipy.sparse as sp

import lago_cvx as lc
from lago_cvx import phases as P
from lago_cvx.datasets import REFERENCE_CHI2
from lago_cvx.plotting import plot_trajectory
from lago_cvx.regularization import regularize
from lago_cvx.uncertainty import edge_uncertainty
from lago_cvx.course import (FULL, check, circuit_sums_figure, circuits_figure, intuition_figure, noise_margin_figure,
                             paper_lago, quiet, real, running_example, setup, show, solve_qp, wraparound_figure)

setup("05_regularization")
TWO_PI = 2 * np.pi


# %% tags=["remove-input"]
show(intuition_figure("05"), "intuition")

# %% [markdown]
# ## 1. The wraparound problem
#
# The paper's example: a robot drives once around a circle, anticlockwise, and comes back to its start. Summing the
# relative orientations around the loop, each small and in $[-\pi,\pi)$, gives $2\pi$ — yet the loop closure links the
# last pose with the first one, whose orientation is 0 by convention: the data say both "one full turn" and "back to the
# same heading". Phase 1's linear model $A^\top\theta = \delta$ cannot recognise that $0$ and $2\pi$ are the same
# orientation: it tries to satisfy both, and spreads the contradiction over the loop.
#
# We write phase 1 (eq. (13)) as a cvxpy problem from named parameters — $A^\top$, the measurements $\delta$
# and the weights $w_\delta = P_\delta^{-1/2}$ — solve it once with the raw $\delta$ and once with the
# regularized $\delta_{\rm reg}$, changing only `δ.value`.

# %%
circle = lc.circle_world(8, laps=1, seed=0, sigma_xy=0.0, sigma_theta=0.0)   # own world: the paper's one-loop example
gc = circle.graph
odo = gc.is_odometric
print(f"{gc!r}\nodometric δ: {np.round(gc.delta[odo], 4)}\nloop closure {gc.tails[~odo][0]}→{gc.heads[~odo][0]}: "
      f"δ = {gc.delta[~odo][0]:.4f}")
turn = gc.delta[odo].sum() - gc.delta[~odo][0]                       # around the loop: the chord backwards

n8, m8 = gc.n_poses - 1, gc.n_edges
theta = cp.Variable(n8, name="θ")
e = cp.Variable(m8, name="e")
At = cp.Parameter((m8, n8), name="Aᵀ")
delta = cp.Parameter(m8, name="δ")
w = cp.Parameter(m8, nonneg=True, name="w_δ")
fit = e == At @ theta - delta
phase1 = cp.Problem(cp.Minimize(cp.sum_squares(cp.multiply(w, e))), [fit])
print(phase1)
At.value = lc.reduced_incidence(gc).toarray().T
w.value = edge_uncertainty(gc).sqrt_info_delta
truth_theta = circle.truth[1:, 2]
reg8 = regularize(gc, lc.spanning_tree(gc, "odometry"))
for label, value in (("raw δ", gc.delta), ("regularized δ_reg", reg8.delta_reg)):
    delta.value = value
    status = solve_qp(phase1)
    err = np.abs(theta.value - truth_theta).max()
    print(f"phase 1 with the {label}: max |θ − θ_true| = {err:.3f} rad ({status})")
lam = fit.dual_value

# %% tags=["remove-input"]
check(np.abs(theta.value - truth_theta).max() < 1e-8, "with δ_reg phase 1 recovers the true orientations")
check(abs(turn - TWO_PI) < 1e-12, f"around the loop the relative orientations add up to {turn:.6f} = 2π, not 0")
check(np.allclose(lam, -2 * w.value ** 2 * e.value, atol=1e-9) and np.abs(At.value.T @ lam).max() < 1e-8,
      "multipliers λ = −2 P_δ⁻¹ e balance at every pose: A λ = 0 (the normal equations of eq. (13))")

# %% [markdown]
# The same on a trajectory that winds four times: `circle_world(120, laps=4)`, noiseless. Without the
# correction, phase 1 spreads the four turns over the loops and phases 2–3 build the positions from wrong
# headings; with it, the estimate is exact.

# %%
w4 = lc.circle_world(120, laps=4, seed=0, sigma_xy=0.0, sigma_theta=0.0)   # own world: noiseless, four laps
g4 = w4.graph
unc4 = edge_uncertainty(g4)
raw1 = P.phase1_closed_form(g4, g4.delta, unc4)                       # phase 1 on the raw, wrapped δ
raw3 = P.phase3_closed_form(g4, P.phase2(g4, raw1.theta, unc4, information="marginal"))
res4 = paper_lago(g4)
err_raw = np.abs(raw3.poses[:, :2] - w4.truth[:, :2]).max()
err_reg = np.abs(res4.poses[:, :2] - w4.truth[:, :2]).max()
wrapped = np.count_nonzero(np.rint((w4.truth[g4.heads, 2] - w4.truth[g4.tails, 2] - g4.delta) / TWO_PI))
print(f"{g4!r}: {wrapped} measurements differ from the true orientation change by a multiple of 2π")

show(wraparound_figure(w4.truth, raw3.poses, res4.poses), "wraparound")
# %% tags=["remove-input"]
check(err_raw > 1.0, f"without regularization: max position error {err_raw:.2f} m")
check(err_reg < 1e-9, f"with regularization ({res4.regularization.n_regularized} chords corrected): "
      f"max position error {err_reg:.1e} m")

# %% [markdown]
# ## 2. Cycles and circuits
#
# The paper's definitions (cycle / circuit, Section IV-E): a **cycle** is a subgraph in which every node appears in an
# even number of edges; a **circuit** is a cycle in which every node appears in exactly two edges. A circuit is one
# closed walk without repeated nodes; a cycle may be several circuits glued together (a figure eight). A *directed*
# circuit is written as a vector $c\in\{-1,0,1\}^m$: $+1$ for an edge traversed from tail to head, $-1$ for one
# traversed backwards, $0$ for an edge not in it. Walking around it, every pose is entered as often as it is left, so
# $A c = 0$.
#
# A small graph that contains both: two loops sharing pose 3, odometry $0\to1\to\dots\to6$, loop
# closures $3\to0$, $6\to3$ and $2\to4$.

# %%
pos8 = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 2], [-1, 2], [-1, 1]], float)
th8 = np.array([0, 1, 2, 3, 4, 5, 6]) * np.pi / 2                      # the robot keeps turning left
truth8 = np.column_stack([pos8, th8])
tails8 = np.array([0, 1, 2, 3, 4, 5, 3, 6, 2])
heads8 = np.array([1, 2, 3, 4, 5, 6, 0, 3, 4])
meas8 = lc.between(truth8[tails8], truth8[heads8])
eight = lc.PoseGraph(7, tails8, heads8, meas8[:, :2], lc.wrap_angle(meas8[:, 2]), np.broadcast_to(np.eye(3), (9, 3, 3)))
A8 = lc.incidence_matrix(eight).toarray().astype(int)
print("edges:", [f"{i}→{j}" for i, j in zip(tails8, heads8)], "\nincidence matrix A:\n", A8)

def degrees(graph, c):
    """How many edges of the support of c meet each pose."""
    used = c != 0
    return np.bincount(np.concatenate([graph.tails[used], graph.heads[used]]), minlength=graph.n_poses)

loop_a = np.array([1, 1, 1, 0, 0, 0, 1, 0, 0])        # 0→1→2→3→0
loop_b = np.array([0, 0, 0, 1, 1, 1, 0, 1, 0])        # 3→4→5→6→3
eight_cycle = loop_a + loop_b
for name, c in (("loop 0-1-2-3", loop_a), ("loop 3-4-5-6", loop_b), ("both loops", eight_cycle)):
    deg = degrees(eight, c)
    kind = "circuit" if set(deg[deg > 0]) == {2} else "cycle, not a circuit"
    print(f"{name:13s}: degrees {deg}, A c = {A8 @ c} → {kind}")
# %% tags=["remove-input"]
check(np.all(A8 @ eight_cycle == 0) and degrees(eight, eight_cycle)[3] == 4 and np.all(degrees(eight, eight_cycle) % 2 == 0),
      "both loops together: every degree even, pose 3 has degree 4 — a cycle that is not a circuit")
check(all(set(degrees(eight, c)[degrees(eight, c) > 0]) == {2} and np.all(A8 @ c == 0) for c in (loop_a, loop_b)),
      "each loop alone is a circuit (every degree exactly 2) and A c = 0")

# %% [markdown]
# ## 3. Definition 1, Theorem 2 and Corollary 1 — fundamental circuits form a cycle basis
#
# A spanning tree $T$ has $n$ edges; the other $m - n$ edges are its **chords**.
#
# **Definition 1** (fundamental circuit). Given a directed graph $G$ and a spanning tree $T$, a fundamental
# circuit is the circuit made of a chord $(i,j)$ of $G$ with respect to $T$ and the unique path in $T$ joining
# $i$ and $j$.
#
# A **cycle basis** is a smallest set of circuits such that every cycle is a combination of them; they span
# the cycle space.
#
# **Theorem 2** (fundamental circuits form a cycle basis). *The fundamental circuits of a directed graph constitute a
# cycle basis.* The paper refers to graph-theory textbooks for the proof. The argument is short in vector form: each
# fundamental circuit contains exactly one chord, its own, so they are independent; and if $c$ is any cycle vector, $c'
# = c - \sum_{\text{chords } k} c_k\, c^{(k)}$ has no chord edge left and still satisfies $Ac' = 0$ — a cycle inside a
# tree, which can only be empty. So $c = \sum_k c_k\, c^{(k)}$: **the coefficients of a cycle in the fundamental basis
# are its own chord entries** (Exercise 1).
#
# **Corollary 1** (the dimension of the cycle space). *The cycle space of a connected graph has dimension
# $l = m - n$, the cyclomatic number.* (Also $m - \operatorname{rank} A$ with $\operatorname{rank}A = n$,
# Proposition 1.)
#
# `lc.spanning_tree(graph, kind)` builds the tree (`"odometry"`, the paper's; `"bfs"`, the package's
# default; `"mst"`) and `lc.cycle_basis(graph, tree)` the fundamental circuits, one row per chord.

# %%
tree8 = lc.spanning_tree(eight, "odometry")
C8 = lc.cycle_basis(eight, tree8).toarray().astype(int)
print("odometric tree edges:", tree8.tree_edges, " chords:", tree8.chords)
print("fundamental circuits, one row per chord (graph edge order):\n", C8)
coef = eight_cycle[tree8.chords]
show(circuits_figure(eight, truth8, eight_cycle, C8, tree8.chords), "circuits")
# %% tags=["remove-input"]
for row, k in zip(C8, tree8.chords):
    deg = degrees(eight, row)
    check(set(deg[deg > 0]) == {2} and np.all(A8 @ row == 0) and row[k] == 1 and np.all(row[tree8.chords[tree8.chords != k]] == 0),
          f"Definition 1: chord {tails8[k]}→{heads8[k]} + its tree path is a circuit, with no other chord")
check(C8.shape[0] == lc.cyclomatic_number(eight) == eight.n_edges - (eight.n_poses - 1),
      f"Corollary 1: l = m − n = {eight.n_edges} − {eight.n_poses - 1} = {C8.shape[0]}")
check(np.array_equal(C8.T @ coef, eight_cycle), f"Theorem 2: the figure-eight cycle = Σ (its chord entries {coef}) × circuits")

# %% [markdown]
# The same on larger graphs and every kind of tree — the running example, a random graph without odometry
# and INTEL: the rows are circuits, independent, as many as $m - n$, and any cycle — here random integer
# combinations of the circuits of *another* tree — has its own chord entries as coordinates.

# %%
intel = real("carlone/INTEL_P_toro.graph")
CASES = [("running example", running_example().graph, ("bfs", "odometry", "mst")),
         ("random 40 poses / 75 edges", lc.random_graph(40, 75, seed=3).graph, ("bfs", "mst"))]  # own world: no odometry
if intel is not None:
    CASES.append(("INTEL_P_toro (real)", intel, ("bfs", "odometry")))
rng, spanning = np.random.default_rng(0), []
print(f"{'graph':28s} {'tree':8s} {'m':>5s} {'n':>5s} {'l':>4s} {'rank C':>6s} {'max|A Cᵀ|':>9s} {'spans':>5s}")
for name, gr, kinds in CASES:
    C_other = lc.cycle_basis(gr, lc.spanning_tree(gr, kinds[-1]))
    cycles = (rng.integers(-2, 3, (5, C_other.shape[0])) @ C_other).astype(float)   # 5 random cycles
    for kind in kinds:
        tree = lc.spanning_tree(gr, kind)
        C = lc.cycle_basis(gr, tree)
        rank = np.linalg.matrix_rank(C.toarray())
        ACt = np.abs(lc.incidence_matrix(gr) @ C.T).max()
        spans = np.abs(cycles[:, tree.chords] @ C - cycles).max() == 0
        print(f"{name:28s} {kind:8s} {gr.n_edges:5d} {gr.n_poses - 1:5d} {C.shape[0]:4d} {rank:6d} {ACt:9.0f} {spans!s:>5s}")
        spanning.append((name, kind, C.shape[0] == rank == gr.n_edges - (gr.n_poses - 1) and ACt == 0 and spans))
# %% tags=["remove-input"]
for name, kind, holds in spanning:
    check(holds, f"{name}, {kind} tree: l = m − n independent circuits that span the cycles")

# %% [markdown]
# ## 4. Corollary 2 and eq. (19) — the cycle basis matrix $C = [I_l\ B]$
#
# **Corollary 2** (the cycle basis matrix). *Order the edges so that the $m - n$ chords come first and the
# $n$ tree edges last; then the matrix whose rows are the fundamental circuits is*
#
# $$ C = [\,I_l\ \ B\,], \qquad B\in\{-1,0,1\}^{l\times n}. \tag{19}$$
#
# Each fundamental circuit contains its own chord and no other (the identity), plus tree edges traversed either way
# ($B$). `SpanningTree.edge_order` is that order; `cycle_basis` keeps the graph's own edge order, and builds $B^\top =
# -A_T^{-1}A_C$ from the reduced incidence matrix split into tree and chord columns ($A_T$ is square and invertible: a
# tree is connected, Proposition 1).

# %%
print("C in the order [chords | tree edges] (eq. (19)):\n", C8[:, tree8.edge_order])
# %% tags=["remove-input"]
for name, gr, kinds in CASES:
    for kind in kinds:
        tree = lc.spanning_tree(gr, kind)
        C = lc.cycle_basis(gr, tree)[:, tree.edge_order]
        l = tree.n_chords
        check((C[:, :l] != sp.identity(l)).nnz == 0 and set(np.unique(C[:, l:].data)) <= {-1.0, 1.0},
              f"{name}, {kind} tree: C = [I_{l} B], B ∈ {{−1, 0, 1}}")

# %% [markdown]
# ## 5. The zero-sum property, eqs. (20)–(23), and Theorem 3
#
# **Why measured orientations sum to multiples of $2\pi$** (a lemma of this lecture, call it *the $2\pi$-multiple
# property*). Exact measurements are $\delta = A^\top\theta + 2\pi w$ for the true orientations $\theta$ and some
# integers $w$ (the wrap into $[-\pi,\pi)$). For a cycle vector $c$, $c^\top A^\top\theta = (Ac)^\top\theta = 0$, so
# $c^\top\delta = 2\pi\,c^\top w \in 2\pi\mathbb Z$.
#
# The paper asks for more: the **zero-sum property** — corrected measurements $\bar\delta$ sum to zero
# around every cycle. It suffices to ask it of a cycle basis, the fundamental circuits $c_i$ (the rows of $C$):
# eq. (20) for each of them, eq. (21) for all at once,
#
# $$ c_i^\top\bar\delta = 0\quad\forall c_i\in\mathcal C, \tag{20}$$
# $$ C\bar\delta = 0 . \tag{21}$$
#
# With $\bar\delta = \delta + v$ this is a linear system for the correction $v$, eq. (22):
#
# $$ C(\delta + v) = 0 \iff Cv = -C\delta . \tag{22}$$
#
# **Theorem 3** (existence of correction factors), which the paper states "under the assumption of noiseless
# angular measurements". *Given the relative orientation measurements $\delta$, there is a correction $v$
# such that $\delta + v$ satisfies the zero-sum property.* Proof: by eq. (19), in the
# order [chords, tree edges], the correction of eq. (23) solves eq. (22):
#
# $$ v = \begin{bmatrix} -C\delta\\ 0_n\end{bmatrix}\quad\Longrightarrow\quad Cv = [I_l\ B]\begin{bmatrix} -C\delta\\ 0_n\end{bmatrix} = -C\delta . \tag{23}$$
#
# Only the chords are corrected. The noiseless assumption is what makes $v$ harmless: then $C\delta\in
# 2\pi\mathbb Z^l$ (the $2\pi$-multiple property), so $v$ consists of multiples of $2\pi$ and does not change
# what the measurements say. With noise $C\delta$ is only close to multiples of $2\pi$, and the paper rounds: $v_c = 2\pi k_c$,
# $k_c = -\operatorname{round}((C\delta)_c/2\pi)$, so that $(C\delta_{\rm reg})_c\in(-\pi,\pi]$; the rest is noise,
# which phase 1 averages. `lago_cvx.regularization.regularize(graph, tree)` (the `"tree"` regularizer)
# does exactly this, computing $C\delta$ through tree path sums without forming $C$.

# %%
gn = g4                                                            # the noiseless 4-lap circle of section 1
tree = lc.spanning_tree(gn, "odometry")
C = lc.cycle_basis(gn, tree)
q = C @ gn.delta / TWO_PI
v = np.zeros(gn.n_edges)
v[tree.chords] = -(C @ gn.delta)                                   # eq. (23), in the graph's edge order
reg = regularize(gn, tree)
# %% tags=["remove-input"]
check(np.abs(q - np.rint(q)).max() < 1e-9, f"2π-multiple property: C δ / 2π integer on exact data "
      f"({np.count_nonzero(np.rint(q))} of {q.size} non-zero)")
check(np.abs(C @ v + C @ gn.delta).max() < 1e-9, "eq. (23) solves eq. (22): C v = −C δ")
check(np.abs(C @ (gn.delta + v)).max() < 1e-9 and np.abs(v / TWO_PI - np.rint(v / TWO_PI)).max() < 1e-9,
      "Theorem 3: δ + v has the zero-sum property (21), v = 2πk on the chords only")
check(np.allclose(reg.delta_reg, gn.delta + v, atol=1e-9) and np.all(reg.k[tree.tree_edges] == 0),
      "regularize(graph, tree) returns the same δ_reg")

# %% [markdown]
# **Eq. (22) has many solutions, and phase 1 picks one.** Eq. (23) puts each circuit's whole residual on its
# chord. Another solution spreads it over all edges, weighted by certainty: the smallest weighted correction,
#
# $$ \min_v\ \lVert P_\delta^{-1/2} v\rVert^2 \quad\text{subject to}\quad Cv = -C\delta .$$
#
# Since $\{x: Cx = 0\}$ is exactly the set of orientation differences $A^\top\theta$, this is phase 1 in
# disguise: $\delta + v^\star = A^\top\hat\theta$: regularization removes the integer part of $C\delta$ (chords
# only, eq. (23)), phase 1 the noise (all edges). The multipliers $\nu$ of the $l$ constraints are one per fundamental circuit — the
# "tension" of each loop, $\nu = 2(CP_\delta C^\top)^{-1}C\delta$. For correctly regularized measurements the
# weighted size of $v^\star$ is the phase-1 residual, a $\chi^2$ with $l$ degrees of freedom: about $l$. We solve it
# with $C\delta$ a parameter, first for the regularized and then for the raw measurements of the running example.

# %%
gq = running_example().graph                                       # noisy, true headings up to 2.5π (lecture 2)
tq = lc.spanning_tree(gq, "odometry")
Cq = lc.cycle_basis(gq, tq).toarray()
uq = edge_uncertainty(gq)
regq = regularize(gq, tq)
vv = cp.Variable(gq.n_edges, name="v")
Cp = cp.Parameter(Cq.shape, name="C")
Cd = cp.Parameter(Cq.shape[0], name="Cδ")
wq = cp.Parameter(gq.n_edges, nonneg=True, name="w_δ")
zero_sum = Cp @ vv == -Cd
smallest = cp.Problem(cp.Minimize(cp.sum_squares(cp.multiply(wq, vv))), [zero_sum])
print(smallest)
Cp.value, wq.value = Cq, uq.sqrt_info_delta
out = {}
for label, d in (("δ_reg", regq.delta_reg), ("raw δ", gq.delta)):
    Cd.value = Cq @ d
    status = solve_qp(smallest)
    out[label] = (vv.value.copy(), zero_sum.dual_value.copy(), smallest.value)
    print(f"{label:6s}: {status}; weighted size ‖P_δ^(-1/2) v*‖² = {smallest.value:10.1f} (l = {Cq.shape[0]} "
          f"circuits); largest |v| = {np.abs(vv.value).max():.3f} rad, largest |ν| = {np.abs(zero_sum.dual_value).max():.1f}")
v_reg, nu_reg, _ = out["δ_reg"]
ph1 = P.phase1_closed_form(gq, regq.delta_reg, uq)
diffs = lc.reduced_incidence(gq).T @ ph1.theta_free
e_ph1 = np.abs(regq.delta_reg + v_reg - diffs).max()
nu_formula = 2 * np.linalg.solve(Cq @ np.diag(uq.var_delta) @ Cq.T, Cq @ regq.delta_reg)
show(circuit_sums_figure(Cq @ gq.delta, Cq @ regq.delta_reg), "circuit_sums")
# %% tags=["remove-input"]
check(np.allclose(np.abs(nu_reg), np.abs(nu_formula), rtol=1e-6, atol=1e-9 * np.abs(nu_formula).max()),
      "|ν| = |2 (C P_δ Cᵀ)⁻¹ C δ_reg|: one tension per fundamental circuit")
check(e_ph1 < 1e-8, f"δ_reg + v* = Aᵀθ̂ of phase 1 ({e_ph1:.1e})")
check(out["δ_reg"][2] < 2 * Cq.shape[0] and out["raw δ"][2] > 10 * out["δ_reg"][2],
      f"after regularization the correction is noise-sized (weighted size {out['δ_reg'][2]:.0f}, about l); "
      f"without it {out['raw δ'][2] / out['δ_reg'][2]:.0f}× larger")
check(np.abs(Cq @ regq.delta_reg).max() < np.pi, f"after rounding every circuit sum lies in (−π, π] "
      f"(largest {np.abs(Cq @ regq.delta_reg).max():.3f} rad)")

# %% [markdown]
# ## 6. Proposition 2 and Corollary 3 — only the loop closures are corrected
#
# **Proposition 2** (the odometric edges form a spanning tree). *The edges of the odometric constraints
# constitute a spanning tree of the (connected) pose graph.* — the trajectory visits every pose once, in order.
#
# **Corollary 3** (loop closures are chords). *The loop-closing edges are the chords of the pose graph with
# respect to that tree.* With Theorem 3, regularization therefore corrects loop closures only, each by the
# number of full turns the robot made between the two poses it links.
#
# In the package, `spanning_tree(graph, "odometry")` is the chain of edges between consecutive ids
# (`graph.is_odometric`); among parallel edges it takes the most certain one, so a loop closure that
# duplicates an odometric pair could enter the tree — we check that it does not happen here.

# %%
reg4 = regularize(g4, lc.spanning_tree(g4, "odometry"))             # the 4-lap circle of section 1
turns = np.rint((w4.truth[g4.heads, 2] - w4.truth[g4.tails, 2] - g4.delta) / TWO_PI).astype(int)
# %% tags=["remove-input"]
for name, gr in [("circle 120 poses, 4 laps", g4), ("running example", running_example().graph)] + \
        ([("INTEL_P_toro (real)", intel)] if intel is not None else []):
    t_odo = lc.spanning_tree(gr, "odometry")
    check(np.array_equal(np.sort(t_odo.tree_edges), np.flatnonzero(gr.is_odometric))
          and t_odo.tree_edges.size == gr.n_poses - 1,
          f"{name}: Proposition 2 — the {gr.n_odometric} odometric edges are a spanning tree")
    check(np.array_equal(t_odo.chords, np.flatnonzero(~gr.is_odometric)),
          f"{name}: Corollary 3 — the {gr.n_loop_closures} loop closures are its chords")
check(np.array_equal(reg4.k, turns) and np.all(reg4.k[g4.is_odometric] == 0),
      f"4-lap circle: k = number of full turns between the two poses, on loop closures only "
      f"(k ∈ {sorted(set(reg4.k[~g4.is_odometric].tolist()))})")

# %% [markdown]
# ## 7. When does the rounding find the true $k$?
#
# This is a result of this lecture, not of the paper; call it **the circuit noise margin**. Write each
# measurement as $\delta = A^\top\theta + \nu + 2\pi w$: true orientation change, noise $\nu$ (each $|\nu_e| < \pi$),
# integer wrap $w$. The true correction makes $C\delta_{\rm reg} = C\nu$, i.e. $k^{\rm true} = -Cw$, and
#
# $$ k_c = k^{\rm true}_c \iff (C\nu)_c \in (-\pi, \pi] :$$
#
# the rounding is right exactly when the noise accumulated around the chord's fundamental circuit stays
# below $\pi$ (as $(C\delta)_c = (C\nu)_c - 2\pi k_c^{\rm true}$); long circuits accumulate more. The odometric tree of Proposition 2 makes circuits as long as the trajectory between two visits; a
# breadth-first tree (`"bfs"`, the package's default tree) keeps them short. We sweep the rotation noise on
# Manhattan worlds and count wrong circuits; the package also reports chords whose residual lies within a
# margin (`lago_cvx.rounding.AMBIGUITY_MARGIN`) of $\pm\pi$ as `ambiguous` (a warning, not a detector).

# %%
SIGMAS = [0.02, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4] + ([0.5, 0.6] if FULL else [])
SEEDS = range(6 if FULL else 3)
TREES = ("odometry", "bfs")
wrong = {kind: [] for kind in TREES + ("chordal",)}
ambiguous = {kind: [] for kind in TREES}
verified, margin_ok = 0, True
for sig in SIGMAS:
    counts = {kind: 0 for kind in wrong}
    amb = {kind: 0 for kind in TREES}
    for seed in SEEDS:
        wm = lc.manhattan_world(1000, seed=seed, sigma_theta=sig)         # own world: noise swept over many worlds
        gm = wm.graph
        t_true = wm.truth[gm.heads, 2] - wm.truth[gm.tails, 2]
        wrap = np.rint((gm.delta - t_true) / TWO_PI)
        nu = gm.delta - t_true - TWO_PI * wrap
        bfs = lc.spanning_tree(gm, "bfs")
        for kind in TREES + ("chordal",):
            tree = bfs if kind == "chordal" else lc.spanning_tree(gm, kind)
            with quiet():                      # the ambiguous chords are counted below, not logged
                rep = regularize(gm, tree, regularization="chordal" if kind == "chordal" else "tree")

            def circuit(x):                            # C x through tree path sums, without forming C
                return x[tree.chords] - tree.path_sums(gm, x)[tree.chords]

            k_true = -np.rint(circuit(wrap)).astype(int)
            bad = rep.cycle_k != k_true
            counts[kind] += int(bad.sum())
            if kind != "chordal":
                amb[kind] += rep.ambiguous.size
                margin_ok &= np.array_equal(bad, np.abs(circuit(nu)) > np.pi)
                verified += tree.n_chords
    for kind in wrong:
        wrong[kind].append(counts[kind] / len(SEEDS))
    for kind in TREES:
        ambiguous[kind].append(amb[kind] / len(SEEDS))
print(f"{'σ_θ':>5s} " + " ".join(f"{k + ': wrong':>16s}" for k in wrong) + " " +
      " ".join(f"{k + ': ambiguous':>20s}" for k in TREES) + "   (means per world)")
for i, sig in enumerate(SIGMAS):
    print(f"{sig:5.2f} " + " ".join(f"{wrong[k][i]:16.1f}" for k in wrong) + " " +
          " ".join(f"{ambiguous[k][i]:20.1f}" for k in TREES))
first_bad = {k: next((s for s, x in zip(SIGMAS, wrong[k]) if x > 0), np.inf) for k in wrong}
# %% tags=["remove-input"]
check(all(wrong[k][0] == 0 for k in wrong), f"σ_θ = {SIGMAS[0]}: every k right with every regularizer")
check(margin_ok, f"circuit noise margin: k wrong ⇔ |C ν| > π, verified on {verified} chords")
check(all(b <= o for b, o in zip(wrong["bfs"], wrong["odometry"])),
      "the BFS tree's short circuits are never worse than the odometric tree's")
check(first_bad["odometry"] <= first_bad["bfs"] < first_bad["chordal"] < np.inf,
      f"first noise level with a wrong circuit: odometric {first_bad['odometry']}, BFS {first_bad['bfs']}, "
      f"chordal {first_bad['chordal']}")

# %%
show(noise_margin_figure(SIGMAS, wrong, ambiguous, len(SEEDS)), "noise_margin")

# %% [markdown]
# ## 8. Ambiguous roundings, and the chordal regularizer
#
# A wrong $k$ is a gross error: it tells phase 1 that a loop is off by a full turn. The package's default regularizer
# (`regularization="chordal"`, beyond the paper) avoids tree paths altogether: it estimates all rotations at once by
# the chordal relaxation — each rotation written as a unit vector $r_i = (\cos\theta_i, \sin\theta_i)$, the measurement
# $r_j = R(\delta_e) r_i$ linear in them, $\lVert r_i\rVert = 1$ dropped, a sparse least squares
# (`regularization.chordal.chordal_problem` in cvxpy, `chordal_closed_form`) — and rounds every edge against that
# estimate. $\delta$ enters the relaxation only through $\cos\delta$ and $\sin\delta$: it ignores how the measurements
# were wrapped and accumulates no noise along a tree path. Section 7's sweep shows it keeps the right $k$ to a larger
# noise level than either tree — not to any.
#
# **Real data: M3500a** (`carlone/input_M3500a_g2o.g2o`, the M3500 world with extra rotation noise). No
# ground truth: we compare χ² with the reference minimum and count the circuits on which two
# regularizations disagree (two corrections are equivalent iff $C(\delta_{\rm reg}' - \delta_{\rm reg}) = 0$).

# %%
m3500a = real("carlone/input_M3500a_g2o.g2o")
if m3500a is not None:
    ref = REFERENCE_CHI2["carlone/input_M3500a_g2o.g2o"]
    runs = {"odometric tree": paper_lago(m3500a, spanning_tree="odometry"),
            "BFS tree": paper_lago(m3500a, spanning_tree="bfs"),
            "chordal (odometric tree)": paper_lago(m3500a, spanning_tree="odometry", regularization="chordal")}
    for label, r in runs.items():
        s = r.regularization.summary()
        print(f"M3500a, {label:26s}: {s['n_regularized']:4d} circuits corrected, {s['n_ambiguous']:3d} ambiguous, "
              f"χ² = {r.chi2:9.1f} ({r.chi2 / ref:.3f} × the minimum {ref})")
    C_odo = lc.cycle_basis(m3500a, runs["odometric tree"].tree)
    disagree = np.count_nonzero(np.rint(C_odo @ (runs["odometric tree"].regularization.delta_reg
                                               - runs["BFS tree"].regularization.delta_reg) / TWO_PI))
    agree_chordal = np.count_nonzero(np.rint(C_odo @ (runs["chordal (odometric tree)"].regularization.delta_reg
                                                    - runs["BFS tree"].regularization.delta_reg) / TWO_PI))
    print(f"odometric vs BFS: the corrections disagree on {disagree} circuits; chordal vs BFS on {agree_chordal}")
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.2))
    for ax, (label, r), color in zip(axes, runs.items(), ("tab:red", "tab:blue", "tab:green")):
        plot_trajectory(ax, r.poses, color=color, linewidth=0.4)
        ax.set_title(f"M3500a, {label}\n{r.regularization.ambiguous.size} ambiguous, χ² = {r.chi2 / ref:.2f} × min",
                     fontsize=10)
    fig.tight_layout()
    show(fig, "m3500a")
# %% tags=["remove-input"]
if m3500a is not None:
    check(runs["odometric tree"].regularization.ambiguous.size > 0 and disagree > 0
          and runs["odometric tree"].chi2 > 5 * ref,
          "odometric tree: ambiguous roundings, wrong circuits, χ² many times the minimum")
    check(disagree > runs["odometric tree"].regularization.ambiguous.size,
          f"more circuits are wrong ({disagree}) than chords flagged ambiguous "
          f"({runs['odometric tree'].regularization.ambiguous.size})")
    check(runs["BFS tree"].chi2 < 1.1 * ref and runs["chordal (odometric tree)"].chi2 < 1.1 * ref and agree_chordal == 0,
          "BFS tree and chordal regularizer: the same integers, χ² within 10 % of the minimum")

# %% [markdown]
# The `ambiguous` list is a warning, not a detector: a wrong $k$ can leave any residual in $(-\pi,\pi]$.
#
# ## 9. The regularization steps of Section V and Table I
#
# The regularization steps (Section V): (1) extract the odometric and loop-closing constraints — here they come in the
# file; (2) **regularize** the orientations with the cycle basis $C$ of the odometric tree and the correction $v =
# [-(C\delta)^\top\ 0^\top]^\top$ of eq. (23), rounded; (3) run the three phases. Table I (Intel Research Lab,
# `carlone/INTEL_P_toro.graph`): 1228 nodes, 1227 odometric constraints, 278 loop closing constraints, 198 chords
# needing a correction $2k\pi$, $k\neq 0$ — computed below.

# %%
TABLE_I = {"nodes": 1228, "odometric constraints": 1227, "loop closing constraints": 278,
           "chords needing regularization": 198}
if intel is not None:
    steps = lc.lago(intel, route="seed")                               # steps (2) and (3), the paper's route
    computed = {"nodes": intel.n_poses, "odometric constraints": intel.n_odometric,
                "loop closing constraints": intel.n_loop_closures,
                "chords needing regularization": steps.regularization.n_regularized}
    print(f"{'Table I':32s} {'paper':>6s} {'computed':>9s}")
    for key, value in TABLE_I.items():
        print(f"{key:32s} {value:6d} {computed[key]:9d}")
    bfs_reg = regularize(intel, lc.spanning_tree(intel, "bfs"))
    same = np.count_nonzero(np.rint(lc.cycle_basis(intel, steps.tree)
                                    @ (steps.regularization.delta_reg - bfs_reg.delta_reg) / TWO_PI))
    print(f"with the BFS tree {bfs_reg.n_regularized} chords need a correction instead; the two corrections "
          f"disagree on {same} circuits")

# %% tags=["remove-input"]
if intel is not None:
    check(np.all(steps.regularization.k[intel.is_odometric] == 0) and steps.tree.kind == "odometry",
          "the corrections sit on loop closures only (Corollary 3)")
    check(computed == TABLE_I, "Table I reproduced on INTEL_P_toro with the odometric tree")
    check(same == 0, "on INTEL the two trees' corrections are equivalent: the count depends on the tree, "
          "the regularized graph does not")

# %% [markdown]
# ### Try it: when the rounding fails
# Drag σ_θ: each point is one circuit's accumulated noise $(C\nu)_c$; the rounding is right inside the dashed band
# $(-\pi, \pi]$. The long circuits of the odometric tree leave it from σ_θ ≈ 0.15 rad, the BFS tree's short ones much
# later (section 7).

# %%
from lago_cvx import course, course_sliders
course.interactive(course_sliders.rounding_failure, "try_rounding", sigma_theta=(0.02, 0.6, 0.02, 0.2))

# %% [markdown]
# **Summary.** Measured angles are known only modulo $2\pi$, and phase 1 needs them on one branch: around every cycle
# the true relative orientations sum to a whole number of turns. A spanning tree gives a basis of the cycles, its
# fundamental circuits (Definition 1, Theorem 2, Corollaries 1–2), collected in $C = [I_l\ B]$ (eq. (19)); Theorem 3
# rounds each circuit sum to the nearest $2k\pi$ and puts the correction on the chord (eqs. (20)–(23)), so that with
# the odometric tree only loop closures change (Proposition 2, Corollary 3) — Table I's count on INTEL. The rounding
# is right while the noise around a circuit stays below $\pi$; the chordal regularizer (lecture 8) helps beyond.

# %% [markdown]
# ## Exercise 1 — Coordinates in the fundamental basis
#
# *Derive.* Show that a cycle vector $c$ ($Ac = 0$) equals $\sum_k c_k\,c^{(k)}$, the sum over the chords $k$ of $T$ of
# its chord entries times the fundamental circuits — hence that the fundamental circuits span the cycle space (Theorem
# 2). Then write `coordinates(C, basis_chords)`: the coordinates $X$ of the rows of $C$ in the fundamental basis of a
# tree with chords `basis_chords`, so that $X\,C_{\rm basis} = C$; the check goes both ways between the odometric and
# the BFS basis of two worlds.
#
# **Hint.** Subtract from $c$ the combination of fundamental circuits weighted by its chord entries: what is left
# lives on the tree and has $Ac = 0$.

# %%
# your solution here: fill in the body of coordinates, then run the cell (check_fundamental_coordinates tests it)
from lago_cvx.exercises import check_fundamental_coordinates

def coordinates(C, basis_chords):
    """X (l, l) with X · C_basis = C; C (l, m) holds cycle vectors as rows."""
    raise NotImplementedError

check_fundamental_coordinates(coordinates)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. For a cycle vector c (Ac = 0) put c' = c − Σ_k c_k c⁽ᵏ⁾ over the chords k. Then Ac' = 0
# and c' is zero on every chord: it lives on the tree, where a non-zero vector always has a leaf of its support
# with (Ac')_v = ±c'_e ≠ 0; so c' = 0 and c = Σ_k c_k c⁽ᵏ⁾. The coordinates are the chord entries: the
# fundamental circuits span the cycle space and, independent (C = [I_l B]), are a basis — Theorem 2.
from lago_cvx.exercises import check_fundamental_coordinates

def coordinates(C, basis_chords):
    return C[:, basis_chords]

check_fundamental_coordinates(coordinates).require()

# %% [markdown]
# ## Exercise 2 — The paper's regularization from scratch
#
# *Implement.* Without `regularize`, write `my_regularize(graph, tree_edges)`: integrate $\delta$ along the spanning
# tree made of the edges `tree_edges` from pose 0 (walk it in breadth-first order), compute each chord's circuit sum
# $(C\delta)_c = \delta_c - (\theta_j - \theta_i)$, round to $k_c$ with residuals in $(-\pi, \pi]$, and return $k$ (per
# edge, or per chord in increasing edge order) and $\delta_{\rm reg}$. The check tests the properties of Theorem 3 on
# two worlds and both trees; with the datasets, count the corrections on INTEL's odometric tree (Table I).
#
# **Hint.** In breadth-first order a tree edge $i\to j$ is reached from one end: $\theta_j = \theta_i + \delta_k$
# (or $\theta_i = \theta_j - \delta_k$ when reversed).

# %%
# your solution here: fill in the body of my_regularize, then run the cell (check_regularize tests it)
from lago_cvx.exercises import check_regularize

def my_regularize(graph, tree_edges):
    """(k, delta_reg): the integers (m,) or (l,) and δ + 2πk (m,)."""
    raise NotImplementedError

check_regularize(my_regularize)

# %% tags=["solution", "hide-cell"] jupyter={"source_hidden": true, "outputs_hidden": false} mystnb={"code_prompt_show": "Solution and Discussion", "code_prompt_hide": "Hide the solution"}
# Solution and Discussion. Integrate δ along the tree from pose 0 in breadth-first order (θ_child = θ_parent ±
# δ_edge); each chord's circuit sum is (Cδ)_c = δ_c − (θ_j − θ_i); round it to k_c so that (Cδ)_c + 2πk_c lies
# in (−π, π]; δ_reg = δ + 2πk on the chords, the tree edges keep δ (eq. (23)). With the odometric tree of INTEL,
# 198 chords need a correction (Table I).
from collections import deque
import numpy as np
from lago_cvx.exercises import check_regularize

def my_regularize(graph, tree_edges):
    adjacency = [[] for _ in range(graph.n_poses)]
    for e in tree_edges:
        adjacency[graph.tails[e]].append((e, graph.heads[e], +1.0))
        adjacency[graph.heads[e]].append((e, graph.tails[e], -1.0))
    theta = np.full(graph.n_poses, np.nan)
    theta[0], queue = 0.0, deque([0])
    while queue:
        u = queue.popleft()
        for e, v, sign in adjacency[u]:
            if np.isnan(theta[v]):
                theta[v] = theta[u] + sign * graph.delta[e]
                queue.append(v)
    chords = np.setdiff1d(np.arange(graph.n_edges), tree_edges)
    circuit = graph.delta[chords] - (theta[graph.heads[chords]] - theta[graph.tails[chords]])
    k = np.zeros(graph.n_edges, dtype=int)
    k[chords] = -np.ceil(circuit / (2 * np.pi) - 0.5).astype(int)
    return k, graph.delta + 2 * np.pi * k

check_regularize(my_regularize).require()
