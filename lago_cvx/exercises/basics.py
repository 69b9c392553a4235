"""The checks of lectures 01–04b (the problem and the three phases); see ``lago_cvx.exercises``.

Each ``check_<name>(answer)`` calls the student's function on the exercise's data (built by the ``*_case``
functions here, which the lecture's stub cell calls too) and tests properties of the result; it returns a
``Feedback`` (``lago_cvx.exercises.feedback``)."""

from __future__ import annotations

import numpy as np

import lago_cvx as lc
from lago_cvx.course import S, paper_lago, running_example
from lago_cvx.exercises.feedback import Wrong, array, call, close, exercise
from lago_cvx.posegraph import rot2

__all__ = ["check_half_offset", "check_cost_eq6", "check_minima", "check_chain_covariance", "check_compass",
           "check_trace_drop", "check_theta_columns", "check_pz_times", "check_phase3_information",
           "check_spring_forces", "check_guarded_polish", "check_scale_information",
           "eq6_case", "minima_case", "compass_case", "single_loop", "polish_case"]


# ----------------------------------------------------------------------------- lecture 01
@exercise("01, exercise 1 (a factor ½)")
def check_half_offset(answer) -> str:
    """``answer(m) -> float``: how many standard deviations √(6m) of χ²(3m) the mean 3m/2 of a factor-½ cost
    sits below 3m (the sign is not graded). Tested on m = 1 … 2000."""
    first = None
    for m in (1, 2, 5, 23, 24, 85, 2000):
        value = float(array(call(answer, "half_offset", m), (), f"half_offset({m})"))
        exact = (3 * m - 1.5 * m) / np.sqrt(6 * m)
        if abs(abs(value) - exact) > 1e-9 * exact:
            raise Wrong(f"half_offset({m}) = {value:.4g}: the gap between the means 3m and 3m/2, in units of the "
                        f"standard deviation √(6m) of χ²(3m), is not that")
    for m in range(1, 200):
        if abs(call(answer, "half_offset", m)) >= 3:
            first = m
            break
    return f"the offset is √(3m/8) σ; it reaches 3σ from m = {first} edges on"


def eq6_case():
    """The data of lecture 01's exercise 2: (graph, poses) — the running example with pose 0 at the origin,
    poses (n + 1, 3) near the truth, and δ lifted to their branch so that no angular residual needs a wrap."""
    world = running_example()
    g = world.graph
    x = world.truth - world.truth[0]
    x[:, :2] = (world.truth[:, :2] - world.truth[0, :2]) @ rot2(world.truth[0, 2])
    x[1:] += 0.01 * np.random.default_rng(0).standard_normal((g.n_poses - 1, 3))
    turns = np.round((lc.incidence_matrix(g).T @ x[:, 2] - g.delta) / (2 * np.pi))
    return lc.PoseGraph(g.n_poses, g.tails, g.heads, g.delta_l, g.delta + 2 * np.pi * turns, g.information), x


@exercise("01, exercise 2 (eq. (6) in code)")
def check_cost_eq6(answer) -> str:
    """``answer(graph, poses) -> float``: eq. (6) with the reduced A, A₂ = A ⊗ I₂ and R(θ). It must equal
    ``lc.chi2`` where no residual wraps, and must not wrap (turning a pose by 2π changes eq. (6))."""
    graph, x = eq6_case()
    f6 = float(array(call(answer, "cost_eq6", graph, x), (), "cost_eq6(graph, poses)"))
    close(f6, lc.chi2(graph, x), "cost_eq6 near the truth, compared with lc.chi2", rtol=1e-8)
    turned = x.copy()
    turned[5, 2] += 2 * np.pi
    f_turned = float(array(call(answer, "cost_eq6", graph, turned), (), "cost_eq6 with pose 5 turned by 2π"))
    if not f_turned > 100 * f6:
        raise Wrong(f"with pose 5 turned by 2π your cost is {f_turned:.4g} (near the truth {f6:.4g}): it wraps the "
                    "angular residual, as lc.chi2 does; eq. (6) takes Aᵀθ − δ as it is")
    return f"eq. (6) = lc.chi2 = {f6:.4f} near the truth; turning pose 5 by 2π gives {f_turned:.3g}: eq. (6) does not wrap"


def minima_case():
    """The world of lecture 01's exercise 3: a 16-pose circle driven twice, heading noise 0.05 rad."""
    # own world: small enough for 30 Gauss–Newton runs
    return lc.circle_world(16, laps=2, seed=1, sigma_xy=0.05, sigma_theta=0.05).graph


@exercise("01, exercise 3 (how many minima)")
def check_minima(answer) -> str:
    """``answer(graph, n_starts, rng) -> list of (n + 1, 3) arrays``: the distinct local minima Gauss–Newton
    reaches from ``n_starts`` random starts. Each must be a local minimum (Gauss–Newton started there does not
    lower χ²), their costs pairwise distinct, and there must be more than one."""
    graph = minima_case()
    found = call(answer, "gauss_newton_minima", graph, 30, np.random.default_rng(0))
    if found is None or len(found) == 0:
        raise Wrong("gauss_newton_minima returned no minimum")
    costs = []
    for k, poses in enumerate(found):
        poses = array(poses, (graph.n_poses, 3), f"minimum {k}")
        f = lc.chi2(graph, poses)
        again = lc.refine(graph, poses, max_iterations=20)
        if again.chi2 < f * (1 - 1e-6) - 1e-9:
            raise Wrong(f"minimum {k} (χ² = {f:.6g}) is not a local minimum: Gauss–Newton from it goes on to "
                        f"{again.chi2:.6g}")
        costs.append(f)
    costs = np.sort(costs)
    if np.any(np.diff(costs) <= 1e-6 * costs[1:]):
        raise Wrong(f"two of the minima have the same cost ({costs.round(6).tolist()}): return each distinct one once")
    if costs.size < 2:
        raise Wrong("one minimum only: 30 random starts on this world reach several")
    best = lc.refine(graph, lc.lago(graph).poses, max_iterations=100).chi2
    verdict = "reaches" if best <= costs[0] * (1 + 1e-6) else "does not reach"
    return f"{costs.size} distinct local minima, χ² from {costs[0]:.4g} to {costs[-1]:.4g}; LAGO's start {verdict} the best"


# ----------------------------------------------------------------------------- lecture 02
@exercise("02, exercise 1 (P_θ of a chain)")
def check_chain_covariance(answer) -> str:
    """``answer(sigma) -> (n, n)``: P_θ of the chain 0 → 1 → … → n anchored at pose 0, edge k with standard
    deviation sigma[k]. Compared with (A P_δ⁻¹ Aᵀ)⁻¹ for two chains."""
    rng = np.random.default_rng(0)
    for n in (12, 5):
        sigma = rng.uniform(0.01, 0.05, n)
        mine = array(call(answer, "chain_covariance", sigma), (n, n), f"chain_covariance of a {n}-edge chain")
        info = np.zeros((n, 3, 3))
        info[:, 0, 0] = info[:, 1, 1] = 1.0
        info[:, 2, 2] = 1.0 / sigma**2
        chain = lc.PoseGraph(n + 1, np.arange(n), np.arange(1, n + 1), np.ones((n, 2)), np.zeros(n), info)
        A = lc.reduced_incidence(chain).toarray()
        close(mine, np.linalg.inv((A / sigma**2) @ A.T), f"P_θ of the {n}-edge chain", rtol=1e-9)
    return "(P_θ)_ij = Σ_{k ≤ min(i, j)} σ_k²: the heading error is a random walk along the chain"


def compass_case():
    """The data of lecture 02's exercise 2: (graph, delta_reg (m,), info_delta (m,)) for an 80-pose Manhattan
    world (odometric tree's regularization, the edges' P_δ⁻¹)."""
    from lago_cvx.uncertainty import edge_uncertainty

    # own world: the one of the exercise's statement
    g = lc.manhattan_world(80, seed=5, sigma_theta=0.03).graph
    reg = lc.regularize(g, lc.spanning_tree(g, "odometry"))
    return g, reg.delta_reg, edge_uncertainty(g).info_delta


@exercise("02, exercise 2 (a compass)")
def check_compass(answer) -> str:
    """``answer(graph, delta_reg, info_delta, K, c, sigma_c) -> θ⁺ (n + 1,)``: the minimizer of
    ‖P_δ^(−½)(Aᵀθ⁺ − δ_reg)‖² + ‖(θ⁺_K − c)/σ_c‖². Tested by the optimality condition (gradient zero)."""
    g, delta_reg, info_delta = compass_case()
    A = lc.incidence_matrix(g)
    rng = np.random.default_rng(3)
    for K in ([10], [10, 40, 70]):
        c = rng.uniform(-1, 1, len(K))
        theta = array(call(answer, "compass_orientations", g, delta_reg, info_delta, K, c, 0.05),
                      (g.n_poses,), f"θ⁺ with compass readings at {K}")
        gradient = A @ (info_delta * (A.T @ theta - delta_reg))
        gradient[K] += (theta[K] - c) / 0.05**2
        scale = np.abs(A @ (info_delta * delta_reg)).max() + np.abs(c).max() / 0.05**2
        if np.abs(gradient).max() > 1e-6 * scale:
            raise Wrong(f"with readings at {K} the gradient of the cost at your θ⁺ is {np.abs(gradient).max():.2e} "
                        f"(relative {np.abs(gradient).max() / scale:.1e}), not 0: θ⁺ is not the minimizer")
    return "the gradient vanishes at your θ⁺ with one and with three compass readings: it is the minimizer"


@exercise("02, exercise 3 (which loop closure helps)")
def check_trace_drop(answer) -> str:
    """``answer(P0, e, variance) -> float``: the drop of tr P_θ when an edge with reduced incidence column e and
    variance ``variance`` is added to information P0⁻¹. Compared with the exact inverse, loop closure by loop
    closure of a 200-pose Manhattan world's odometric path."""
    from lago_cvx.uncertainty import edge_uncertainty

    # own world: the one of the exercise's statement
    g = lc.manhattan_world(200, seed=2).graph
    unc, odo = edge_uncertainty(g), g.is_odometric
    A = lc.reduced_incidence(g).toarray()
    info0 = (A[:, odo] * unc.info_delta[odo]) @ A[:, odo].T
    P0 = np.linalg.inv(info0)
    for k in np.flatnonzero(~odo)[:15]:
        e = A[:, k]
        mine = float(array(call(answer, "trace_drop", P0, e, unc.var_delta[k]), (), f"trace_drop for edge {k}"))
        exact = np.trace(P0) - np.trace(np.linalg.inv(info0 + np.outer(e, e) * unc.info_delta[k]))
        close(mine, exact, f"the drop of tr P_θ for loop closure {k} ({g.tails[k]} → {g.heads[k]})", rtol=1e-8)
    return "your drop of tr P_θ is the exact one (Sherman–Morrison: ‖P₀e‖² / (σ² + eᵀP₀e)) on 15 loop closures"


# ----------------------------------------------------------------------------- lecture 03
@exercise("03, exercise 1 (W and θ̂)")
def check_theta_columns(answer) -> str:
    """``answer(graph) -> bool mask (2m + n,)``: the columns of phase 2's W that change with θ̂."""
    from lago_cvx import phases
    from lago_cvx.uncertainty import edge_uncertainty

    # own world: the one of the exercise's statement
    g = lc.random_graph(20, 35, seed=4).graph
    unc = edge_uncertainty(g)
    m, n = g.n_edges, g.n_poses - 1
    mask = array(call(answer, "theta_columns", g), (2 * m + n,), "the mask", dtype=bool)
    rng = np.random.default_rng(1)
    Ws = []
    for _ in range(3):
        theta = rng.uniform(-np.pi, np.pi, g.n_poses)
        theta[0] = 0.0
        Ws.append(phases.phase2(g, theta, unc, information="marginal").W.toarray())
    changes = np.any(np.abs(np.diff(np.array(Ws), axis=0)) > 1e-12, axis=(0, 1))
    if not np.array_equal(mask, changes):
        wrong = np.flatnonzero(mask != changes)
        raise Wrong(f"{wrong.size} columns misclassified, e.g. column {wrong[0]} "
                    f"({'changes' if changes[wrong[0]] else 'does not change'} with θ̂)")
    return (f"{int(changes.sum())} columns change with θ̂ (the blocks P_Δˡ^(−½)Rᵀ of edges not leaving pose 0), the "
            f"other {int((~changes).sum())} do not (RᵀSR = S)")


@exercise("03, exercise 2 (P_z v without P_z)")
def check_pz_times(answer) -> str:
    """``answer(result, graph, v) -> (2m + n,)``: P_z v, for the paper's LAGO ``result`` on ``graph``.
    Tested by WᵀW (P_z v) = v (P_z = (WᵀW)⁻¹) on the running example."""
    graph = running_example().graph
    res = paper_lago(graph)
    size = 2 * graph.n_edges + graph.n_poses - 1
    WtW = (res.phase2.W.T @ res.phase2.W).tocsr()
    rng = np.random.default_rng(0)
    worst = 0.0
    for k in range(3):
        v = rng.standard_normal(size)
        out = array(call(answer, "pz_times", res, graph, v.copy()), (size,), "pz_times(result, graph, v)")
        worst = max(worst, np.linalg.norm(WtW @ out - v) / np.linalg.norm(v))
        if worst > 1e-8:
            raise Wrong(f"WᵀW (pz_times(v)) differs from v by {worst:.1e} (relative): not P_z v")
    return f"WᵀW (P_z v) = v for 3 random v ({worst:.1e}), without forming P_z"


# ----------------------------------------------------------------------------- lecture 04a
@exercise("04a, exercise 1 (B P_z⁻¹ Bᵀ)")
def check_phase3_information(answer) -> str:
    """``answer(result, graph) -> (3n, 3n)``: phase 3's information B P_z⁻¹ Bᵀ from its blocks. Compared with
    the package's ``result.phase3.info`` block by block."""
    # own world: small enough for dense blocks
    g = lc.random_graph(20, 40, seed=3, sigma_xy=0.1, sigma_theta=0.05).graph
    res = paper_lago(g)
    n = g.n_poses - 1
    mine = array(call(answer, "phase3_information", res, g), (3 * n, 3 * n), "phase3_information")
    info = res.phase3.info.toarray()
    scale = np.abs(info).max()
    for name, rows, cols in (("position block", slice(0, 2 * n), slice(0, 2 * n)),
                             ("cross block", slice(0, 2 * n), slice(2 * n, None)),
                             ("orientation block", slice(2 * n, None), slice(2 * n, None))):
        if np.abs(mine[rows, cols] - info[rows, cols]).max() > 1e-9 * scale:
            raise Wrong(f"the {name} differs from the package's B P_z⁻¹ Bᵀ by "
                        f"{np.abs(mine[rows, cols] - info[rows, cols]).max() / scale:.1e} (relative)")
    if np.abs(mine - info).max() > 1e-9 * scale:
        raise Wrong("the lower-left block is not the transpose of the cross block")
    return "every block of B P_z⁻¹ Bᵀ is as derived"


def single_loop():
    """Lecture 04a's exercise 2: one loop of 12 poses, edge k from pose k to k + 1 (the last back to 0), unequal
    diagonal information."""
    rng = np.random.default_rng(7)
    N = 12
    angles = 2 * np.pi * np.arange(N) / N
    truth = np.column_stack([5 * np.cos(angles), 5 * np.sin(angles), angles + np.pi / 2])
    tails, heads = np.arange(N), (np.arange(N) + 1) % N
    rel = lc.between(truth[tails], truth[heads]) + rng.standard_normal((N, 3)) * [0.05, 0.05, 0.02]
    info = np.array([np.diag(rng.uniform([50, 50, 500], [400, 400, 3000])) for _ in range(N)])
    return lc.PoseGraph(N, tails, heads, rel[:, :2], lc.posegraph.wrap_angle(rel[:, 2]), info)


def _spring_forces(res, g):
    n = g.n_poses - 1
    x = res.phase3.x_star
    p = np.vstack([[0.0, 0.0], x[:2 * n].reshape(n, 2)])
    th_s, th_h = np.concatenate([[0.0], x[2 * n:]]), res.phase1.theta
    dg = res.phase2.delta_g
    d = p[g.heads] - p[g.tails] - dg - (dg @ S.T) * (th_s - th_h)[g.tails, None]
    Rk = rot2(th_h[g.tails])
    return np.einsum("kab,kb->ka", Rk @ np.linalg.inv(res.uncertainty.cov_delta_l) @ np.swapaxes(Rk, 1, 2), d)


@exercise("04a, exercise 2 (springs of a loop)")
def check_spring_forces(answer) -> str:
    """``answer(result, graph) -> (m, 2)``: the spring force f_k = P_Δg,k⁻¹ d_k of every edge at phase 3's
    optimum, on ``single_loop()``. Compared with the package's phase 3; on one loop they are all equal."""
    g = single_loop()
    res = paper_lago(g)
    mine = array(call(answer, "spring_forces", res, g), (g.n_edges, 2), "spring_forces")
    close(mine, _spring_forces(res, g), "the spring forces", rtol=1e-7)
    return f"every edge of the loop carries the same force {mine.mean(0).round(4)}"


# ----------------------------------------------------------------------------- lecture 04b
def polish_case():
    """Lecture 04b's exercise 1: CSAIL (or a synthetic world without the datasets) and the paper's LAGO on it."""
    from lago_cvx.course import real

    graph = real("se-sync/CSAIL.g2o")
    if graph is None:
        # own world: stands in for CSAIL without the datasets
        graph = lc.manhattan_world(500, seed=2, sigma_xy=0.05, sigma_theta=0.03).graph
    return graph, paper_lago(graph)


@exercise("04b, exercise 1 (the guarded polish)")
def check_guarded_polish(answer) -> str:
    """``answer(F, theta_hat, theta_star) -> (alpha, chi2)``: the guarded polish. Tested on four functions F along
    the step, one per outcome (α = 1, ½, ⅛, 0), then compared with the package's (``positions="resolve"``) on
    ``polish_case()``."""
    from lago_cvx.positions import resolve_positions

    graph, res = polish_case()

    def F(theta):
        return lc.chi2(graph, resolve_positions(graph, theta, res.uncertainty).poses)

    theta_hat, theta_star = res.phase1.theta, res.phase3.poses[:, 2]
    step = theta_star - theta_hat
    for s0, expected in ((0.7, 1.0), (0.3, 0.5), (0.1, 0.125), (0.01, 0.0)):   # F along the step: (s − s0)²
        def along(theta, s0=s0):
            return float((step @ (theta - theta_hat) / (step @ step) - s0) ** 2)

        out = call(answer, "guarded_polish", along, theta_hat, theta_star)
        alpha, value = (float(v) for v in array(out, (2,), "(alpha, chi2)"))
        if alpha != expected or abs(value - (expected - s0) ** 2) > 1e-12:
            raise Wrong(f"with F(θ̂ + s(θ* − θ̂)) = (s − {s0})² the guarded polish keeps α = {expected} "
                        f"(F = {(expected - s0) ** 2:.4g}); yours returned α = {alpha}, F = {value:.4g}")
    out = call(answer, "guarded_polish", F, theta_hat, theta_star)
    alpha, chi2 = (float(v) for v in array(out, (2,), "(alpha, chi2)"))
    pkg = paper_lago(graph, positions="resolve")
    if alpha != pkg.polish.alpha:
        raise Wrong(f"α = {alpha}, the package's guarded polish takes α = {pkg.polish.alpha}")
    close(chi2, pkg.chi2, "the polished χ²", rtol=1e-9)
    return f"α = {alpha}, χ² = {chi2:.4f}, as the package's guarded polish on {graph.name}"


@exercise("04b, exercise 2 (over-confident information)")
def check_scale_information(answer) -> str:
    """``answer(graph, pick, factor, mode) -> PoseGraph``: the graph with the translational information of the
    edges ``pick`` (bool (m,)) multiplied by ``factor``, ``mode="isotropic"`` (Ω_tt) or ``"x only"`` (Ω_xx);
    the measurements and every other entry unchanged."""
    g = running_example().graph
    pick = np.random.default_rng(0).random(g.n_edges) < 0.1
    for mode in ("isotropic", "x only"):
        out = call(answer, "scale_information", g, pick, 1e4, mode)
        if not isinstance(out, lc.PoseGraph):
            raise Wrong(f"scale_information returned {type(out).__name__}, not a PoseGraph")
        if not (np.array_equal(out.delta_l, g.delta_l) and np.array_equal(out.delta, g.delta)
                and np.array_equal(out.tails, g.tails) and np.array_equal(out.heads, g.heads)):
            raise Wrong("the measurements or the edges changed: only the information is scaled")
        expected = np.array(g.information)
        if mode == "isotropic":
            expected[pick, :2, :2] *= 1e4
        else:
            expected[pick, 0, 0] *= 1e4
        close(array(out.information, g.information.shape, "the information"), expected,
              f"the information ({mode})", rtol=1e-12)
    return "the picked edges' translational information is scaled (isotropic and along x), nothing else changed"
