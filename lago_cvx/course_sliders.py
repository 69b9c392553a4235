"""The lectures' interactive figures: one ``draw(ax, **values) -> ax`` per lecture, for ``course.interactive``.

Each draws on one matplotlib axes, on a small world (at most a few hundred poses), in well under a second, so that
it can be redrawn while a slider moves; the lecture names the slider ranges and defaults::

    from lago_cvx.course import interactive
    from lago_cvx.course_sliders import rounding_failure
    interactive(rounding_failure, "try_rounding", sigma_theta=(0.02, 0.5, 0.02, 0.2))

Every world a function draws is seeded by its arguments, so a figure depends on the slider values only.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

import lago_cvx as lc
from lago_cvx.course import quiet, running_example
from lago_cvx.posegraph import wrap_angle

__all__ = ["two_minima", "phase1_blue", "chain_covariance", "phase3_correction", "anisotropy_gap",
           "rounding_failure", "table_ii_noise", "prior_weight", "chordal_tightness", "chordal_gap_3d",
           "false_closures", "cost_minima"]

TWO_PI = 2 * np.pi


def _path(ax, poses, style="-", **kw):
    """A trajectory (n, 3) on ``ax``; the legends of the map figures stand to the right of the map."""
    ax.plot(poses[:, 0], poses[:, 1], style, **{"markersize": 3, "linewidth": 1.2, **kw})


def two_minima(ax, *, sigma_theta=0.2, draw=11):
    """Lecture 1: Gauss–Newton on eq. (3) from dead reckoning and from LAGO, on a 100-pose Manhattan world with
    heading noise ``sigma_theta`` [rad] (world number ``draw``): one minimum or two."""
    world = lc.manhattan_world(100, seed=int(draw), sigma_theta=sigma_theta, sigma_xy=0.05)
    g = world.graph
    with quiet():
        runs = {name: lc.refine(g, start, max_iterations=100)
                for name, start in (("dead reckoning", lc.odometry_guess(g)), ("LAGO", lc.lago(g).poses))}
    _path(ax, world.truth, color="0.75", linewidth=3, label="truth")
    for (name, run), color in zip(runs.items(), ("tab:red", "tab:blue")):
        _path(ax, run.poses, color=color, label=f"Gauss–Newton from {name}: χ² = {run.chi2:.1f}")
    costs = [run.chi2 for run in runs.values()]
    same = abs(costs[0] - costs[1]) < 1e-6 * max(costs)
    verdict = ("one minimum" if same else "two minima") if all(r.converged for r in runs.values()) else \
        "a run stopped after 100 steps"
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal", title=f"σ_θ = {sigma_theta:.2f} rad, world {draw}: {verdict}")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return ax


def phase1_blue(ax, *, sigma_theta=0.05):
    """Lecture 2: the heading errors of phase 1's BLUE (eq. (13)) and of dead reckoning along the running example's
    path, redrawn with heading noise ``sigma_theta`` [rad], within ±2√diag(P_θ) of Proposition 1's covariance."""
    world = lc.manhattan_world(60, seed=1, sigma_xy=0.1, sigma_theta=sigma_theta)
    g, truth = world.graph, world.truth
    with quiet():
        res = lc.lago(g, route="seed")
    k = np.arange(g.n_poses)
    blue = wrap_angle(res.phase1.theta - truth[:, 2])
    dead = wrap_angle(lc.odometry_guess(g)[:, 2] - truth[:, 2])
    band = np.zeros(g.n_poses)
    free = np.delete(k, res.phase1.anchor_index)
    band[free] = 2 * np.sqrt(np.diag(np.linalg.inv(res.phase1.info.toarray())))
    ax.fill_between(k, -band, band, color="tab:blue", alpha=0.2, label="±2 √diag P_θ (Proposition 1)")
    ax.plot(k, dead, "--", color="tab:orange", label="dead reckoning")
    ax.plot(k, blue, ".-", color="tab:blue", label="phase 1 (BLUE)")
    outside = np.mean(np.abs(blue) > band + 1e-12)
    ax.set(xlabel="pose index", ylabel="heading error [rad]",
           title=f"σ_θ = {sigma_theta:.3f} rad: {100 * outside:.0f} % of the poses outside the 2σ band")
    ax.legend(fontsize=8, loc="best")
    return ax


def chain_covariance(ax, *, sigma_theta=0.05, sigma_xy=0.05, n=15):
    """Lecture 3: positions chained along an odometric path of ``n`` unit steps turning 90° once (p_j = Σ R(θ_i) Δ_i,
    θ_i the summed turns), 300 noisy draws against the first-order 2σ ellipses (the Jacobians H, J of eq. (11)):
    the heading noise ``sigma_theta`` [rad] makes them grow along the chain and bend across it."""
    n = int(n)
    turns = np.zeros(n)
    turns[n // 2] = np.pi / 2
    steps = np.column_stack([np.ones(n), np.zeros(n)])                    # Δ_i in the frame of pose i, (n, 2)
    rng = np.random.default_rng(0)
    draws = 300
    th = np.cumsum(turns[None, :] + sigma_theta * rng.standard_normal((draws, n)), axis=1)
    th = np.concatenate([np.zeros((draws, 1)), th[:, :-1]], axis=1)       # θ_i before step i
    d = steps[None] + sigma_xy * rng.standard_normal((draws, n, 2))
    c, s = np.cos(th), np.sin(th)
    p = np.cumsum(np.stack([c * d[..., 0] - s * d[..., 1], s * d[..., 0] + c * d[..., 1]], -1), axis=1)
    th0 = np.concatenate([[0.0], np.cumsum(turns)[:-1]])                  # the noiseless headings
    g = np.column_stack([np.cos(th0), np.sin(th0)])                       # R(θ_i) Δ_i for Δ_i = (1, 0), (n, 2)
    mean = np.cumsum(g, axis=0)
    Sg = np.column_stack([-g[:, 1], g[:, 0]])                             # S R(θ_i) Δ_i: ∂/∂θ_i
    for j in range(n):
        # p_j depends on turn δ_t (t < j) through every later step i (t < i ≤ j): J_t = Σ_{i=t+1..j} S R(θ_i)Δ_i
        J = np.cumsum(Sg[: j + 1][::-1], axis=0)[::-1][1:]
        P = sigma_theta**2 * J.T @ J + sigma_xy**2 * (j + 1) * np.eye(2)
        w, V = np.linalg.eigh(P)
        a = np.linspace(0, TWO_PI, 60)
        ell = mean[j][:, None] + 2 * (V * np.sqrt(np.maximum(w, 0))) @ np.vstack([np.cos(a), np.sin(a)])
        ax.plot(*ell, color="tab:red", linewidth=0.8, label="first order, 2σ" if j == 0 else None)
    ax.scatter(p[:, :, 0].ravel(), p[:, :, 1].ravel(), s=1, color="tab:blue", alpha=0.25, label="300 draws")
    ax.plot(*np.vstack([[0, 0], mean]).T, "k.-", label="noiseless chain")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
           title=f"σ_θ = {sigma_theta:.2f} rad, σ_xy = {sigma_xy:.2f} m: covariance along the chain")
    ax.legend(fontsize=8, loc="upper left")
    return ax


def phase3_correction(ax, *, sigma_theta=0.05):
    """Lecture 4a: ρ̂ (θ̂ and the positions of eq. (14)) and phase 3's ρ* on the running example redrawn with
    heading noise ``sigma_theta`` [rad]; the correction θ̃ of eq. (16) and χ² before and after."""
    from lago_cvx.theorem1 import theorem1

    world = lc.manhattan_world(60, seed=1, sigma_xy=0.1, sigma_theta=sigma_theta)
    with quiet():
        t = theorem1(world.graph, regularization="tree", information="marginal", positions="phase3")
    _path(ax, world.truth, color="0.75", linewidth=3, label="truth")
    _path(ax, t.poses(t.x_hat), ".-", color="tab:orange", label=f"ρ̂: χ² = {t.chi2_suboptimal:.1f}")
    _path(ax, t.poses(t.x_star), ".-", color="tab:blue", label=f"ρ* (phase 3): χ² = {t.chi2_phase3:.1f}")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
           title=f"σ_θ = {sigma_theta:.2f} rad: max |θ̃| = {np.abs(t.theta_correction).max():.3f} rad")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return ax


def anisotropy_gap(ax, *, log10_ratio=2.0):
    """Lecture 4b: χ² along x̂ + α(x* − x̂) on the running example whose translational information is made
    anisotropic — Ω_tt = diag(1, ρ)/σ², ρ = 10^``log10_ratio``, in each edge's frame — against the minimum of χ²:
    Theorem 1's step lands on the minimum for ρ = 1 and above it as ρ grows (the frozen weights)."""
    from lago_cvx.theorem1 import theorem1

    g = running_example().graph
    ratio = 10.0 ** log10_ratio
    info = g.information.copy()
    scale = np.sqrt(info[:, 0, 0] * info[:, 1, 1])                       # keep the determinant of Ω_tt
    info[:, 0, 1] = info[:, 1, 0] = 0.0
    info[:, 0, 0], info[:, 1, 1] = scale / np.sqrt(ratio), scale * np.sqrt(ratio)
    g = replace(g, information=info, given_information=None)
    with quiet():
        t = theorem1(g, regularization="tree", information="marginal", positions="phase3")
        best = lc.refine(g, t.poses(t.x_star)).chi2
    alphas = np.linspace(-0.25, 1.5, 36)
    curve = [lc.chi2(g, t.poses(t.x_hat + a * (t.x_star - t.x_hat))) for a in alphas]
    ax.plot(alphas, curve, "-", color="tab:blue", label="χ² on the line through ρ̂ and ρ*")
    ax.plot([0, 1], [t.chi2_suboptimal, t.chi2_phase3], "o", color="tab:red", label="ρ̂ (α = 0), ρ* (α = 1)")
    ax.axhline(best, color="k", linestyle="--", linewidth=1, label="minimum of χ² (Gauss–Newton)")
    ax.set(xlabel="α", ylabel="χ² (eq. (3))", yscale="log",
           title=f"anisotropy ρ = {ratio:.3g}: χ²(ρ*) / minimum = {t.chi2_phase3 / best:.3f}")
    ax.legend(fontsize=8, loc="best")
    return ax


def rounding_failure(ax, *, sigma_theta=0.2):
    """Lecture 5: the noise accumulated around every fundamental circuit, (Cν)_c, on a 300-pose Manhattan world with
    heading noise ``sigma_theta`` [rad], for the odometric and the BFS tree; the rounding of eq. (22) finds the true
    k_c exactly when (Cν)_c ∈ (−π, π] — the points outside the band are its failures."""
    from lago_cvx.experiments import true_cycle_integers
    from lago_cvx.rounding import round_residual, tree_cycle_residuals

    world = lc.manhattan_world(300, seed=0, sigma_theta=sigma_theta)
    g = world.graph
    for kind, marker, color in (("odometry", "o", "tab:red"), ("bfs", "s", "tab:blue")):
        tree = lc.spanning_tree(g, kind)
        r = tree_cycle_residuals(g, tree)                                 # C δ, (l,)
        k_true = true_cycle_integers(g, tree, world.truth)
        circuit_noise = r + TWO_PI * k_true                              # (Cν)_c
        wrong = round_residual(r) != k_true
        ax.plot(np.arange(r.size), circuit_noise, marker, color=color, markersize=3, alpha=0.6,
                label=f"{kind} tree: k wrong on {wrong.sum()} of {r.size} circuits")
    for y in (-np.pi, np.pi):
        ax.axhline(y, color="k", linestyle="--", linewidth=1)
    ax.set(xlabel="loop closure (chord) c", ylabel="(Cν)_c [rad]",
           title=f"σ_θ = {sigma_theta:.2f} rad: the rounding is right inside (−π, π]")
    ax.legend(fontsize=8, loc="upper left")
    return ax


def table_ii_noise(ax, *, sigma_xy=0.02, sigma_theta=0.01):
    """Lecture 6: Table II's metric (ε_t, ε_θ; ``section_v.relation_errors``) over the minimum of χ², on a 150-pose
    Section V world whose measurements carry isotropic noise ``sigma_xy`` [m], ``sigma_theta`` [rad] while the
    paper's proportional information is assumed, for odometry, LAGO (the paper's procedure) and the default route."""
    from lago_cvx.course import section_v_world
    from lago_cvx.section_v import relation_errors

    g, truth = section_v_world(150, noise="isotropic", sigma_xy=sigma_xy, sigma_theta=sigma_theta)
    with quiet():
        default = lc.lago(g)
        rows = {"odometry": lc.odometry_guess(g), "LAGO, paper's": lc.lago(g, route="seed").poses,
                "LAGO, default": default.poses}
        best = relation_errors(g, lc.refine(g, default.poses).poses, truth)
    ratios = np.array([np.array(relation_errors(g, p, truth)) / best for p in rows.values()])
    x = np.arange(len(rows))
    ax.bar(x - 0.2, ratios[:, 0], 0.4, label="ε_t / ε_t(minimum)")
    ax.bar(x + 0.2, ratios[:, 1], 0.4, label="ε_θ / ε_θ(minimum)")
    ax.axhline(1.0, color="k", linewidth=1)
    ax.set_xticks(x, list(rows))
    ax.set(yscale="log", ylabel="error / error of the minimum",
           title=f"σ_xy = {sigma_xy:.3f} m, σ_θ = {sigma_theta:.3f} rad (isotropic noise)")
    ax.legend(fontsize=8, loc="best")
    return ax


def prior_weight(ax, *, log10_information=2.0):
    """Lecture 7: a prior (soft anchor) pulling pose 40 of the running example 1 m off its estimate, with
    information 10^``log10_information`` × I₃, beside pose 0 anchored; as the information grows the estimate goes
    from ignoring the prior to the hard anchor."""
    from lago_cvx import variants as V

    g = running_example().graph
    with quiet():
        free = lc.lago(g).poses
        target = free[40] + np.array([1.0, -1.0, 0.1])
        hard = lc.lago(g, anchors={0: tuple(free[0]), 40: tuple(target)}).poses
        soft = V.anchored_lago(g, priors={0: (free[0], 1e12 * np.eye(3)),
                                          40: (target, 10.0**log10_information * np.eye(3))}).poses
    _path(ax, free, color="0.75", linewidth=3, label="LAGO, pose 0 anchored only")
    _path(ax, hard, "--", color="tab:red", label="pose 40 anchored at the prior's mean")
    _path(ax, soft, color="tab:blue", label="pose 40 with a prior")
    ax.plot(*target[:2], "*", color="tab:red", markersize=12, label="the prior's mean")
    ax.plot(*soft[40, :2], "o", color="tab:blue")
    miss = np.linalg.norm(soft[40, :2] - target[:2])
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
           title=f"prior information 10^{log10_information:g}·I₃: pose 40 is {miss:.3f} m from the mean")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return ax


def chordal_tightness(ax, *, sigma_theta=0.1):
    """Lecture 8: the relaxed lengths ‖r_i‖ of the chordal relaxation (C) on a 100-pose Manhattan world with heading
    noise ``sigma_theta`` [rad] (1 everywhere when the relaxation is tight), and the cost ratio (C)(u)/(C)(r) of the
    unit vectors u_i = r_i/‖r_i‖ (the angles atan2 r_i) to the relaxed minimum: how much the projection loses."""
    from lago_cvx.regularization.chordal import chordal_closed_form
    from lago_cvx.uncertainty import edge_uncertainty

    g = lc.manhattan_world(100, seed=0, sigma_theta=sigma_theta).graph
    omega = edge_uncertainty(g).info_delta
    est = chordal_closed_form(g, omega)
    u = est.vectors / est.norms[:, None]
    c, s = np.cos(g.delta), np.sin(g.delta)
    ri, rj = u[g.tails], u[g.heads]
    residual = rj - np.column_stack([c * ri[:, 0] - s * ri[:, 1], s * ri[:, 0] + c * ri[:, 1]])
    projected = float(np.sum(omega * np.sum(residual**2, axis=1)))      # (C) at the unit vectors
    ax.plot(np.arange(g.n_poses), est.norms, ".-", color="tab:blue", markersize=3, label="‖r_i‖ (relaxed length)")
    ax.axhline(1.0, color="k", linestyle="--", linewidth=1, label="tight: ‖r_i‖ = 1")
    ax.set(xlabel="pose index", ylabel="‖r_i‖", ylim=(0, 1.05),
           title=f"σ_θ = {sigma_theta:.2f} rad: min ‖r_i‖ = {est.norms.min():.3f}, (C)(u) / (C)(r) = "
                 f"{projected / est.cost:.2f}")
    ax.legend(fontsize=8, loc="lower left")
    return ax


def chordal_gap_3d(ax, *, sigma_r=0.1):
    """Lecture 9: on a 60-pose sphere with rotation noise ``sigma_r`` [rad], the singular values of the relaxed
    matrices R̂_i of (C) (all 1 when tight) and the cost ratio (C)(ΠR̂)/(C)(R̂) that bounds the projection's
    suboptimality."""
    from lago_cvx.space import chordal_closed_form
    from lago_cvx.synthetic.space import sphere_world

    w = sphere_world(4, 15, seed=3, sigma_t=0.05, sigma_r=sigma_r)
    ch = chordal_closed_form(w.graph)
    sv = np.linalg.svd(ch.relaxed, compute_uv=False)                     # (n, 3), descending
    k = np.arange(sv.shape[0])
    for col, (label, color) in enumerate((("largest", "tab:blue"), ("middle", "tab:green"), ("smallest", "tab:red"))):
        ax.plot(k, sv[:, col], ".-", color=color, markersize=3, label=f"{label} singular value of R̂_i")
    ax.axhline(1.0, color="k", linestyle="--", linewidth=1)
    ax.set(xlabel="pose index", ylabel="singular value",
           title=f"σ_r = {sigma_r:.2f} rad: (C)(ΠR̂) / (C)(R̂) = {ch.cost_projected / ch.cost:.2f}")
    ax.legend(fontsize=8, loc="best")
    return ax


def false_closures(ax, *, fraction=0.1, draw=0):
    """Lecture 10: a 150-pose Manhattan world with ⌊fraction · m⌋ false loop closures appended
    (``add_false_loop_closures``, world and outliers seeded by ``draw``): plain LAGO against GNC-TLS
    (``lago(graph, robust="gnc-tls")``), with how many false edges GNC rejected and how many true ones with them."""
    world = lc.manhattan_world(150, seed=int(draw), sigma_xy=0.05, sigma_theta=0.01)
    g, false = lc.add_false_loop_closures(world.graph, fraction, seed=int(draw))
    with quiet():
        plain, robust = lc.lago(g), lc.lago(g, robust="gnc-tls")
    rejected = set(robust.rejected_edges.tolist())
    caught = len(rejected & set(false.tolist()))
    _path(ax, world.truth, color="0.75", linewidth=3, label="truth")
    _path(ax, plain.poses, color="tab:red", label=f"plain LAGO: ATE {lc.ate(plain.poses, world.truth):.2f} m")
    _path(ax, robust.poses, color="tab:blue",
          label=f"GNC-TLS: ATE {lc.ate(robust.poses, world.truth):.2f} m")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
           title=f"{false.size} false loop closures: {caught} rejected, {len(rejected) - caught} true edges with them")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return ax


def cost_minima(ax, *, log10_anisotropy=1.0):
    """Lecture 11: one 80-pose Manhattan world whose edges all carry the information diag(1/σ_x², 1/σ_y², 1/σ_θ²)
    with σ_y / σ_x = 10^``log10_anisotropy``, read in the three costs (``conventions``: the paper's eq. (3), g2o's,
    GTSAM's); each cost refined to its minimum from LAGO. With isotropic translational information (0) the paper's
    and g2o's minima are one; the more anisotropic, the farther apart."""
    world = lc.manhattan_world(80, seed=3, sigma_xy=0.05, sigma_theta=0.02)
    sx = 0.05
    sy = sx * 10.0 ** log10_anisotropy
    omega = np.diag([1 / sx**2, 1 / sy**2, 1 / 0.02**2])
    g = replace(world.graph, information=np.broadcast_to(omega, world.graph.information.shape).copy())
    minima = {}
    with quiet():
        for cost in ("paper", "g2o", "gtsam"):
            gc = g.with_cost(cost)
            minima[cost] = lc.refine(gc, lc.lago(gc).poses, max_iterations=100).poses
    d = np.sqrt(np.mean(np.sum((minima["g2o"][:, :2] - minima["paper"][:, :2]) ** 2, 1)))
    for (cost, poses), color, style in zip(minima.items(), ("tab:green", "tab:blue", "tab:orange"), ("-", "--", ":")):
        _path(ax, poses, style, color=color, label=f"minimum of {cost}'s cost")
    ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal",
           title=f"σ_y/σ_x = {sy / sx:.3g}: the paper's and g2o's minima {d:.3g} m apart (RMS)")
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    return ax
