"""The checks of lectures 10–11 (false loop closures and graduated non-convexity; the costs of the file formats);
see ``lago_cvx.exercises``. Each ``check_<name>(answer)`` returns a ``Feedback``."""

from __future__ import annotations

import numpy as np

import lago_cvx as lc
from lago_cvx.exercises.feedback import Wrong, array, call, close, exercise

__all__ = ["check_tls_weights", "check_circuits_through", "check_tail_information", "check_se2_logmap"]


# ----------------------------------------------------------------------------- lecture 10
@exercise("10, exercise 1 (the weights of truncated least squares)")
def check_tls_weights(answer) -> str:
    """``answer(r2, mu, c2) -> w``: GNC's TLS weights (Yang et al. 2020, eq. (14)) at the squared whitened residuals
    ``r2`` (m,), for the surrogate of parameter μ and truncation c̄²; each weight is the minimizer over [0, 1] of
    w r² + μ c̄² (1 − w)/(μ + w). Compared with the closed form on residuals across the three regimes, for
    several μ and c̄²."""
    from lago_cvx.variants.gnc import gnc_weights

    r2 = np.concatenate([np.linspace(0.0, 40.0, 801), [1e-12, 1e3, 1e6]])
    for c2 in (11.345, 2.0):
        for mu in (0.01, 0.3, 1.0, 5.0, 100.0):
            w = array(call(answer, "tls_weights", r2.copy(), mu, c2), r2.shape, f"the weights at μ = {mu}")
            ref = gnc_weights(r2, mu, c2, "tls")
            if np.any(w < -1e-12) or np.any(w > 1 + 1e-12):
                raise Wrong(f"μ = {mu}, c̄² = {c2}: a weight outside [0, 1]")
            lo, hi = mu / (mu + 1) * c2, (mu + 1) / mu * c2
            for name, band in (("below μ/(μ+1)·c̄² (weight 1)", r2 <= lo), ("above (μ+1)/μ·c̄² (weight 0)", r2 >= hi),
                               ("in the transition band", (r2 > lo) & (r2 < hi))):
                if band.any():
                    close(w[band], ref[band], f"μ = {mu}, c̄² = {c2}: the weights {name}", rtol=1e-8)
    return "w = 1, c̄/r·√(μ(μ+1)) − μ, 0 in the three regimes, for every μ and c̄² tried"


@exercise("10, exercise 2 (which integers a tree edge decides)")
def check_circuits_through(answer) -> str:
    """``answer(graph, tree_edges, f) -> chords``: the edge indices of the chords whose fundamental circuit
    (Definition 1, the spanning tree made of ``tree_edges``) contains the tree edge ``f`` — the chords whose 2kπ a
    false tree edge f decides. Compared as a set with the column f of the cycle basis C (eq. (19)), on two trees and
    several edges."""
    # own world: a world with many loop closures, and one with several laps
    for g in (lc.manhattan_world(300, seed=3).graph, lc.circle_world(60, laps=3, seed=1).graph):
        for kind in ("odometry", "bfs"):
            tree = lc.spanning_tree(g, kind)
            C = lc.cycle_basis(g, tree)
            C = C.toarray() if hasattr(C, "toarray") else np.asarray(C)
            for f in tree.tree_edges[:: max(1, tree.tree_edges.size // 7)]:
                got = array(call(answer, "circuits_through", g, np.asarray(tree.tree_edges), int(f)), (None,),
                            "the chords", dtype=np.int64)
                want = np.sort(tree.chords[np.flatnonzero(C[:, f])])
                if np.unique(got).size != got.size:
                    raise Wrong(f"{g.name}, {kind} tree, edge {f}: a chord is listed twice")
                extra, missing = np.setdiff1d(got, want), np.setdiff1d(want, got)
                if extra.size:
                    raise Wrong(f"{g.name}, {kind} tree, edge {f}: chord {extra[0]}'s circuit does not contain edge {f}")
                if missing.size:
                    raise Wrong(f"{g.name}, {kind} tree, edge {f}: chord {missing[0]}'s circuit contains edge {f} too")
    return "the chords whose circuit runs through the edge, on two worlds and two trees"


# ----------------------------------------------------------------------------- lecture 11
@exercise("11, exercise 1 (g2o's information in eq. (3)'s frame)")
def check_tail_information(answer) -> str:
    """``answer(info_f, delta) -> info``: Ω = T Ω_f Tᵀ, T = blkdiag(R(δ), 1), for stacks (m, 3, 3) and (m,). Checked
    by its defining property: eq. (3)'s error weighed by Ω equals g2o's error weighed by Ω_f, at random poses."""
    rng = np.random.default_rng(11)
    m = 50
    L = rng.normal(size=(m, 3, 3))
    info_f = L @ np.swapaxes(L, 1, 2) + 0.1 * np.eye(3)
    delta = rng.uniform(-np.pi, np.pi, m)
    info = array(call(answer, "tail_information", info_f.copy(), delta.copy()), (m, 3, 3), "Ω")
    e = rng.normal(size=(m, 3))                                    # eq. (3)'s errors
    R = lc.posegraph.rot2(delta)
    e_g2o = np.concatenate([np.einsum("kba,kb->ka", R, e[:, :2]), e[:, 2:]], axis=1)   # R(δ)ᵀ e_t
    close(np.einsum("ka,kab,kb->k", e, info, e), np.einsum("ka,kab,kb->k", e_g2o, info_f, e_g2o),
          "eᵀ Ω e against g2o's e_g2oᵀ Ω_f e_g2o", rtol=1e-9)
    return "eᵀ(TΩ_fTᵀ)e = e_g2oᵀ Ω_f e_g2o on 50 random edges"


@exercise("11, exercise 2 (GTSAM's Logmap)")
def check_se2_logmap(answer) -> str:
    """``answer(rel) -> xi``: SE(2)'s Logmap of relative poses ``rel`` (m, 3) = (x, y, θ), θ in (−π, π]: ξ = (V(θ)⁻¹
    t, θ) (m, 3). Checked by its defining property, Exp(ξ) = rel, and against GTSAM's ``Pose2.Logmap`` when GTSAM
    is installed."""
    rng = np.random.default_rng(12)
    rel = np.column_stack([rng.normal(size=(200, 2)) * 3, rng.uniform(-3.1, 3.1, 200)])
    rel = np.vstack([rel, [[1.0, 2.0, 0.0], [0.5, -0.2, 1e-9]]])
    xi = array(call(answer, "se2_logmap", rel.copy()), rel.shape, "ξ")
    close(xi[:, 2], rel[:, 2], "the rotation part of ξ", rtol=1e-12)
    th = xi[:, 2]
    small = np.abs(th) < 1e-6
    ts = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th ** 2 / 6, np.sin(ts) / ts)          # V(θ) = [[a, −b], [b, a]]
    b = np.where(small, th / 2, (1 - np.cos(ts)) / ts)
    t = np.column_stack([a * xi[:, 0] - b * xi[:, 1], b * xi[:, 0] + a * xi[:, 1]])
    close(t, rel[:, :2], "Exp(ξ)'s translation V(θ)·ξ_t against the relative pose's", rtol=1e-9)
    return "Exp(Log(rel)) = rel on 202 relative poses, small angles included"
