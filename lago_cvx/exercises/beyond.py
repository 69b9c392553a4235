"""The checks of lectures 05–09 (regularization, the experiment, variants, relaxations, space); see
``lago_cvx.exercises``. Each ``check_<name>(answer)`` returns a ``Feedback``."""

from __future__ import annotations

import numpy as np

import lago_cvx as lc
from lago_cvx.course import real
from lago_cvx.exercises.feedback import Wrong, array, call, close, exercise
from lago_cvx.posegraph import between, compose, wrap_angle

__all__ = ["check_fundamental_coordinates", "check_regularize", "check_relation_errors", "check_table_one",
           "check_anchor_torques", "check_strain", "check_truncation", "check_wrong_integers",
           "check_connection_laplacian", "check_bound_b", "check_chordal_weight", "check_tree_rotations",
           "anchored_case", "bound_case"]


# ----------------------------------------------------------------------------- lecture 05
@exercise("05, exercise 1 (coordinates in the fundamental basis)")
def check_fundamental_coordinates(answer) -> str:
    """``answer(C, basis_chords) -> X (l, l)``: the coordinates of the rows of ``C`` (cycle vectors, (l, m)) in the
    fundamental basis of a tree with chords ``basis_chords``, so that X · C_basis = C. Both ways between the
    odometric and the BFS basis of two worlds; exact (integers)."""
    # own world: two sizes, one with several laps
    for g in (lc.manhattan_world(300, seed=3).graph, lc.circle_world(90, laps=3, seed=1).graph):
        trees = {kind: lc.spanning_tree(g, kind) for kind in ("odometry", "bfs")}
        bases = {kind: lc.cycle_basis(g, t) for kind, t in trees.items()}
        for target, basis in (("bfs", "odometry"), ("odometry", "bfs")):
            C, B = bases[target], bases[basis]
            X = array(call(answer, "coordinates", C, trees[basis].chords), (C.shape[0], B.shape[0]),
                      f"the coordinates of the {target} circuits in the {basis} basis")
            if np.abs(X - np.round(X)).max() > 1e-9:
                raise Wrong("the coordinates are not integers: a cycle's coordinates are its own chord entries")
            if np.abs(X @ B - C).max() > 1e-9:
                raise Wrong(f"X · C_{basis} ≠ C_{target} on {g.name}: these are not the coordinates")
    return "each circuit = Σ (its chord entries) × the other tree's fundamental circuits, exactly, both ways"


def _per_edge_k(k, graph, tree, what):
    k = np.asarray(k)
    if k.shape == (tree.n_chords,):
        full = np.zeros(graph.n_edges)
        full[tree.chords] = k
        return full
    return array(k, (graph.n_edges,), what)


@exercise("05, exercise 2 (Theorem 3 from scratch)")
def check_regularize(answer) -> str:
    """``answer(graph, tree_edges) -> (k, delta_reg)``: Theorem 3's rounding along the spanning tree made of the
    edges ``tree_edges``; ``k`` per edge (m,) or per chord (l,, the chords in increasing edge order). Properties:
    δ_reg = δ + 2πk, k integer and zero on the tree, every chord's circuit residual (C δ_reg)_c in [−π, π]; where
    the rounding is unambiguous, k is the package's. On two worlds, and INTEL with the datasets."""
    # own world: a plain world and one whose headings go round five times
    cases = [lc.manhattan_world(800, seed=3, sigma_theta=0.05).graph,
             lc.circle_world(120, laps=5, seed=1, sigma_theta=0.02).graph]
    intel = real("carlone/INTEL_P_toro.graph")
    cases += [intel] if intel is not None else []
    corrected, table_i = 0, ""
    for g in cases:
        for kind in ("odometry", "bfs"):
            tree = lc.spanning_tree(g, kind)
            out = call(answer, "my_regularize", g, tree.tree_edges)
            if not isinstance(out, tuple) or len(out) != 2:
                raise Wrong("return the pair (k, delta_reg)")
            k = _per_edge_k(out[0], g, tree, "k")
            delta_reg = array(out[1], (g.n_edges,), "delta_reg")
            if np.abs(k - np.round(k)).max() > 0 or np.any(k[tree.tree_edges] != 0):
                raise Wrong(f"{g.name}, {kind} tree: k must be integers, and 0 on the tree edges (eq. (23))")
            close(delta_reg, g.delta + 2 * np.pi * k, f"{g.name}, {kind} tree: δ_reg against δ + 2πk", rtol=1e-12)
            residual = lc.cycle_basis(g, tree) @ delta_reg
            outside = np.abs(residual) > np.pi + 1e-9
            if outside.any():
                c = int(np.flatnonzero(outside)[0])
                raise Wrong(f"{g.name}, {kind} tree: chord {tree.chords[c]}'s circuit residual is {residual[c]:+.3f}, "
                            "outside [−π, π]: its k is off by a whole turn")
            pkg = lc.regularize(g, tree)
            clear = np.abs(np.abs(pkg.residual) - np.pi) > 1e-9
            if np.any(k[tree.chords][clear] != pkg.k[tree.chords][clear]):
                raise Wrong(f"{g.name}, {kind} tree: k differs from Theorem 3's rounding")
            corrected += int(np.count_nonzero(k))
            if g is intel and kind == "odometry":
                table_i = f"; INTEL's odometric tree: {int(np.count_nonzero(k))} chords corrected (Table I: 198)"
    return (f"δ_reg = δ + 2πk with every circuit residual in [−π, π] on {len(cases)} graphs and two trees "
            f"({corrected} corrections){table_i}")


# ----------------------------------------------------------------------------- lecture 06
def _reference_relation_errors(graph, poses, truth):
    d = between(between(truth[graph.tails], truth[graph.heads]), between(poses[graph.tails], poses[graph.heads]))
    return float(np.mean(np.sum(d[:, :2] ** 2, 1))), float(np.mean(wrap_angle(d[:, 2]) ** 2))


@exercise("06, exercise 1 (the metric needs no alignment)")
def check_relation_errors(answer) -> str:
    """``answer(graph, poses, truth) -> (ε_t, ε_θ)``: Table II's metric, the mean squared translation [m²] and
    rotation [rad²] error of the estimated relative poses over the edges. Compared with its definition, and
    unchanged by a rigid motion of the estimate."""
    # own world: any world with a known truth
    world = lc.manhattan_world(300, seed=4, sigma_theta=0.02)
    g, truth = world.graph, world.truth
    est = lc.lago(g, route="seed").poses
    mine = array(call(answer, "relation_errors", g, est, truth), (2,), "(ε_t, ε_θ)")
    close(mine, _reference_relation_errors(g, est, truth), "(ε_t, ε_θ)", rtol=1e-9)
    T = np.array([12.3, -4.5, 2.1])
    moved = array(call(answer, "relation_errors", g, compose(np.broadcast_to(T, est.shape), est), truth), (2,),
                  "(ε_t, ε_θ) of the moved estimate")
    close(moved, mine, "(ε_t, ε_θ) after a rigid motion of the estimate", rtol=1e-9)
    ate = lc.ate(compose(np.broadcast_to(T, est.shape), est), truth, align=False)
    return (f"ε = ({mine[0]:.3e} m², {mine[1]:.3e} rad²), unchanged by a rigid motion; the unaligned ATE becomes "
            f"{ate:.1f} m")


@exercise("06, exercise 2 (Table I for every graph)")
def check_table_one(answer) -> str:
    """``answer(graph, kind) -> (poses, odometric edges, loop closures, chords with k ≠ 0)`` for the spanning
    tree ``kind`` ("odometry" or "bfs"); on a synthetic world and, with the datasets, on INTEL (Table I)."""
    # own world: always present
    graphs = [lc.manhattan_world(500, seed=0).graph]
    intel = real("carlone/INTEL_P_toro.graph")
    graphs += [intel] if intel is not None else []
    for g in graphs:
        for kind in ("odometry", "bfs"):
            row = tuple(int(v) for v in array(call(answer, "table_one_row", g, kind), (4,), "the row"))
            expected = (g.n_poses, g.n_odometric, g.n_loop_closures,
                        lc.regularize(g, lc.spanning_tree(g, kind)).n_regularized)
            names = ("poses", "odometric edges", "loop closures", "chords with k ≠ 0")
            for name, a, b in zip(names, row, expected):
                if a != b:
                    raise Wrong(f"{g.name}, {kind} tree: {name} = {a}, the graph has {b}")
    return "the rows are right" + (" (INTEL: Table I, 198 corrections along the odometric tree)" if intel else "")


# ----------------------------------------------------------------------------- lecture 07
def anchored_case():
    """Lecture 07's exercises 1–2: (graph, anchors) — a 300-pose Manhattan world anchored at poses 0, 120 and
    250 at their true poses (``{id: (x, y, θ)}``)."""
    # own world: the one of section 1
    w = lc.manhattan_world(300, seed=3)
    return w.graph, {i: tuple(w.truth[i]) for i in (0, 120, 250)}


@exercise("07, exercise 1 (the forces balance)")
def check_anchor_torques(answer) -> str:
    """``answer(graph, anchors) -> ν (a,)``: phase 1's Lagrange multipliers of the anchored orientations (the
    anchors in increasing id). Compared with cvxpy's dual values (either sign convention); they sum to zero."""
    g, anchors = anchored_case()
    res, report = lc.compare_methods(g, anchors=anchors)
    nu = np.asarray(report["problems"]["phase1"].constraints[0].dual_value, dtype=float)
    mine = array(call(answer, "anchor_torques", g, anchors), (len(anchors),), "ν")
    sign = 1.0 if np.abs(mine - nu).max() <= np.abs(mine + nu).max() else -1.0
    close(sign * mine, nu, "the phase-1 multipliers of the anchors", rtol=1e-5)
    return f"ν = {np.round(mine, 3).tolist()}, sum {mine.sum():.1e}: the torques on the anchors balance"


@exercise("07, exercise 2 (the strain statistic)")
def check_strain(answer) -> str:
    """``answer(graph, anchors, anchor_id) -> float``: the cost drop of phase 1 when the orientation of anchor
    ``anchor_id`` is released, ν²/(4S). Compared with the package's ``strain`` for two anchors."""
    g, anchors = anchored_case()
    res = lc.lago(g, anchors=anchors)
    strain = {s.id: s.chi2_theta for s in res.strain}
    for a in (250, 120):
        mine = float(array(call(answer, "strain_statistic", g, anchors, a), (), f"the statistic of anchor {a}"))
        close(mine, strain[a], f"the strain statistic of anchor {a}", rtol=1e-5)
    return f"ν²/(4S) = the package's strain statistic ({strain[250]:.4f} for anchor 250, {strain[120]:.4f} for 120)"


@exercise("07, exercise 3 (where to truncate)")
def check_truncation(answer) -> str:
    """``answer(confidence) -> c̄²``: the truncation that keeps an inlier (whitened squared residual χ²₃) with
    probability ``confidence``."""
    from scipy.stats import chi2

    from lago_cvx.variants import RobustSettings

    for p in (0.9, 0.99, 0.999):
        close(float(array(call(answer, "truncation", p), (), f"truncation({p})")), chi2.ppf(p, 3),
              f"c̄² at confidence {p}", rtol=1e-6)
    return f"c̄² = the χ²₃ quantile; at 0.99 it is {chi2.ppf(0.99, 3):.3f}, the package's default {RobustSettings().c2:.3f}"


# ----------------------------------------------------------------------------- lecture 08
@exercise("08, exercise 1 (the rounding's failure probability)")
def check_wrong_integers(answer) -> str:
    """``answer(graph, tree) -> p (l,)``: the probability that Theorem 3's rounding picks the wrong integer on
    each chord of ``tree``, erfc(π / (√2 σ_c)) with σ_c² = (|C| P_δ)_c. Both trees of a noisy world."""
    from scipy.special import erfc

    # own world: heading noise that makes the rounding fail
    g = lc.manhattan_world(300, seed=0, sigma_theta=0.3).graph
    for kind in ("odometry", "bfs"):
        tree = lc.spanning_tree(g, kind)
        p = array(call(answer, "wrong_integer_probability", g, tree), (tree.n_chords,), "p")
        sigma_c = np.sqrt(abs(lc.cycle_basis(g, tree)) @ g.covariance[:, 2, 2])
        close(p, erfc(np.pi / (np.sqrt(2) * sigma_c)), f"p along the {kind} tree", rtol=1e-6)
    return "p_c = erfc(π/(√2 σ_c)) on both trees: (W) as derived"


@exercise("08, exercise 2 (the connection Laplacian)")
def check_connection_laplacian(answer) -> str:
    """``answer(graph, omega, anchor_index) -> z (n,) complex``: (G), z = L⁻¹u_a / (L⁻¹)_aa. Compared with the
    package's chordal relaxation for two anchors."""
    from lago_cvx.regularization.chordal import chordal_closed_form
    from lago_cvx.uncertainty import edge_uncertainty

    # own world: the one of section 2
    g = lc.manhattan_world(300, seed=0, sigma_theta=0.05).graph
    omega = edge_uncertainty(g).info_delta
    for a in (0, 150):
        z = array(call(answer, "chordal_from_laplacian", g, omega, a), (g.n_poses,), "z", dtype=complex)
        est = chordal_closed_form(g, omega, anchor=int(g.ids[a]))
        close(z, est.vectors[:, 0] + 1j * est.vectors[:, 1], f"z with anchor {a}", rtol=1e-7)
    return "(G) gives the chordal relaxation's vectors for both anchors"


def bound_case():
    """Lecture 08's exercise 3: (graph, raw, best) — a 30-pose world with heavy noise, LAGO's raw estimate and
    the certified minimum (SE-Sync's local solver after Gauss–Newton)."""
    from lago_cvx.certification import refine_sesync

    # own world: small and noisy, as in section 3
    g = lc.manhattan_world(30, seed=1, sigma_theta=0.2, sigma_xy=0.2).graph
    raw = lc.lago(g).poses
    return g, raw, refine_sesync(g, lc.refine(g, raw).poses).poses


@exercise("08, exercise 3 (the bound (B))")
def check_bound_b(answer) -> str:
    """``answer(graph, poses) -> float``: the lower bound of (B) on f*, Σ tr Λ_i + 2(n+1)·min(0, λ_min(S_Q)), at
    ``poses`` with optimal translations. Compared with ``certify``'s and never above f*."""
    from lago_cvx.certification import certify, optimal_translations

    g, raw, best = bound_case()
    f_star = certify(g, best).cost
    for a in (0.0, 0.5, 1.0):
        th = raw[:, 2] + a * (best[:, 2] - raw[:, 2])
        p = np.column_stack([optimal_translations(g, th), th])
        mine = float(array(call(answer, "lower_bound_b", g, p), (), "the bound"))
        if mine > f_star * (1 + 1e-6):
            raise Wrong(f"at α = {a} your bound {mine:.6g} is above the minimum f* = {f_star:.6g}: not a lower bound")
        close(mine, certify(g, p, full=False).lower_bound, f"the bound (B) at α = {a}", rtol=1e-6)
    return f"(B) as certify computes it, and tight at the minimum (f* = {f_star:.4f})"


# ----------------------------------------------------------------------------- lecture 09
@exercise("09, exercise 1 (the weights of (Q))")
def check_chordal_weight(answer) -> str:
    """``answer(Omega) -> W (3, 3)``: the weight with tr(W) I − W = Ω, so that ‖[φ]× S‖²_F = φᵀΩφ for S² = W.
    Tested by that equation on random Ω."""
    from lago_cvx.so3 import exp_so3

    rng = np.random.default_rng(5)
    for _ in range(20):
        Q = exp_so3(rng.normal(size=3))
        Omega = Q @ np.diag(rng.uniform(1, 10, 3)) @ Q.T
        W = array(call(answer, "chordal_weight", Omega), (3, 3), "W")
        close(np.trace(W) * np.eye(3) - W, Omega, "tr(W) I − W against Ω", rtol=1e-9)
    W_bad = array(call(answer, "chordal_weight", np.diag([1.0, 1.0, 10.0])), (3, 3), "W for Ω = diag(1, 1, 10)")
    diagonal = ", ".join(f"{w:g}" for w in np.diag(W_bad))
    return (f"tr(W) I − W = Ω; for Ω = diag(1, 1, 10) W = diag({diagonal}), not positive semidefinite: no S with "
            "S² = W")


@exercise("09, exercise 2 (exact on a tree)")
def check_tree_rotations(answer) -> str:
    """``answer(graph) -> (n, 3, 3)``: the rotations composed along the odometric path from R₀ = I. They must
    be rotations, satisfy R_j = R_i R̃_ij on every odometric edge, and equal the chordal relaxation of the
    odometric tree."""
    from lago_cvx.space import chordal_closed_form
    from lago_cvx.synthetic.space import sphere_world

    # own world: the one of section 2
    g = sphere_world(5, 12, seed=4, sigma_t=0.05, sigma_r=0.1).graph
    R = array(call(answer, "tree_rotations", g), (g.n_poses, 3, 3), "the rotations")
    close(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), "RᵢRᵢᵀ against I", rtol=1e-9)
    if np.any(np.linalg.det(R) < 0):
        raise Wrong("a matrix has determinant −1: a reflection, not a rotation")
    close(R[0], np.eye(3), "R₀ (the anchor)", rtol=1e-12)
    odo = g.is_odometric
    close(R[g.heads[odo]], R[g.tails[odo]] @ g.delta_R[odo], "R_j against R_i R̃_ij on the odometric edges", rtol=1e-9)
    relaxed = chordal_closed_form(g.subgraph_edges(odo)).relaxed
    close(R, relaxed, "your rotations against (C) on the tree", rtol=1e-8)
    return "composed along the tree, every residual of (C) is zero: (C) = 0 there and its solution is these rotations"
