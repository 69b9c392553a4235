"""The lectures' figures that are drawing, not mathematics: each takes what a lecture computed and returns a
matplotlib figure (the lecture shows it with ``lago_cvx.course.show``, which re-exports every name here)."""

from __future__ import annotations

import numpy as np

__all__ = ["compounding_figure", "incidence_figure", "two_minima_figure", "structure_figure", "remark1_figure",
           "wraparound_figure", "circuits_figure", "circuit_sums_figure", "noise_margin_figure",
           "tree_rounding_figure", "chordal_lengths_figure", "sweep_figure", "sdp_tightness_figure"]


# ----------------------------------------------------------------------------- lecture 01's figures
def compounding_figure(p_i, p_j):
    """Eq. (1) drawn: pose j (red) seen from pose i (blue), each pose (3,) with its axes; returns the figure."""
    import matplotlib.pyplot as plt

    from lago_cvx.posegraph import between, rot2

    rel = between(p_i, p_j)
    fig, ax = plt.subplots(figsize=(6, 4.6))
    for pose, color, name in [(p_i, "tab:blue", "i"), (p_j, "tab:red", "j")]:
        R = rot2(pose[2])
        for axis, style in [(R[:, 0], "-"), (R[:, 1], "--")]:
            ax.annotate("", pose[:2] + 0.9 * axis, pose[:2],
                        arrowprops=dict(arrowstyle="->", color=color, ls=style, lw=1.6))
        ax.plot(*pose[:2], "o", color=color)
        ax.annotate(f"pose {name}, θ$_{name}$ = {np.rad2deg(pose[2]):.0f}°", pose[:2], xytext=(10, -18),
                    textcoords="offset points", color=color)
    ax.annotate("", p_j[:2], p_i[:2], arrowprops=dict(arrowstyle="->", color="k", lw=1.2))
    ax.text(-0.3, 3.2, f"$p_j - p_i$ (black) written in the axes of i:\n"
            f"$\\Delta^l_{{ij}}$ = ({rel[0]:.2f}, {rel[1]:.2f}),  $\\delta_{{ij}}$ = {np.rad2deg(rel[2]):.0f}°")
    ax.set_aspect("equal")
    ax.set_xlim(-0.5, 4.8)
    ax.set_ylim(-0.3, 3.8)
    ax.set_title("Eq. (1): pose j seen from pose i (solid: x axis, dashed: y axis)")
    return fig


def incidence_figure(graph, truth, A):
    """A small graph drawn at its true poses (n + 1, 3) beside its incidence matrix A ((n + 1) × m, dense)."""
    import matplotlib.pyplot as plt

    from lago_cvx import plotting

    fig, axs = plt.subplots(1, 2, figsize=(11, 4.6), gridspec_kw={"width_ratios": [1, 1.25]})
    plotting.plot_trajectory(axs[0], truth, label="odometric edges", color="tab:blue", linewidth=1.5, style="-o",
                             markersize=4)
    plotting.plot_edges(axs[0], graph, truth, which="loop_closures", color="tab:red", linewidth=1.5, alpha=0.8,
                        label="loop closures")
    for i, (px, py) in enumerate(truth[:, :2]):
        axs[0].annotate(f"{i}" + (" (reference)" if i == 0 else ""), (px, py), textcoords="offset points",
                        xytext=(5, 5))
    axs[0].legend(loc="center", fontsize=8)
    axs[0].set_title(f"{graph.n_poses} poses, {graph.n_edges} edges (true positions)")
    axs[1].imshow(A, cmap="coolwarm", vmin=-1.5, vmax=1.5)
    axs[1].set_xticks(range(graph.n_edges), [f"{t}→{h}" for t, h in zip(graph.tails, graph.heads)], rotation=60,
                      fontsize=8)
    axs[1].set_yticks(range(graph.n_poses))
    axs[1].set(xlabel="edge (i → j)", ylabel="pose")
    axs[1].axhline(0.5, color="k", lw=1)
    axs[1].set_title("incidence matrix A (blue −1 at i, red +1 at j);\nthe reduced A drops row 0")
    return fig


def two_minima_figure(truth, from_dr, from_lago, t, segment, chord):
    """Two Gauss–Newton runs (refinement results) that end in two minima, and the cost on the segment between
    them (``segment`` at the parameters ``t``) against the ``chord``."""
    import matplotlib.pyplot as plt

    from lago_cvx import plotting

    fig, axs = plt.subplots(1, 2, figsize=(12, 4.8))
    plotting.plot_trajectory(axs[0], truth, color="0.7", linewidth=3, label="truth")
    plotting.plot_trajectory(axs[0], from_dr.poses, color="tab:red",
                             label=f"from dead reckoning, cost {from_dr.chi2:.0f}")
    plotting.plot_trajectory(axs[0], from_lago.poses, color="tab:blue", label=f"from LAGO, cost {from_lago.chi2:.1f}")
    axs[0].set_title("Gauss–Newton: two starts, two local minima")
    axs[0].legend(fontsize=8)
    axs[1].plot(t, segment, label="cost on the segment")
    axs[1].plot(t, chord, "k--", linewidth=1, label="chord")
    axs[1].set(yscale="log", xlabel="t (configuration (1 − t)·[from dead reckoning] + t·[from LAGO])",
               ylabel="cost eq. (3)", title="between the two minima the cost rises above the chord")
    axs[1].legend(fontsize=8)
    return fig


# ----------------------------------------------------------------------------- lecture 04a's figures
def structure_figure(matrices, graph, positions, force):
    """The sparsity of phase 3's matrices (``matrices``: [(dense array, title)], three of them) beside the edges
    of ``graph`` drawn at ``positions`` (n + 1, 2), coloured by the spring tension ‖f_k‖ (``force`` (m, 2))."""
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    fig, axes = plt.subplots(1, 4, figsize=(16, 4.2))
    for ax, (M, title) in zip(axes, matrices):
        nonzero = np.abs(M) > 1e-12 * np.abs(M).max()
        ax.spy(nonzero, markersize=1.2)
        ax.set(xlabel="column", ylabel="row")
        ax.set_title(f"{title}\n{M.shape[0]}×{M.shape[1]}, {np.mean(nonzero):.0%} non-zero", fontsize=9)
    segments = np.stack([positions[graph.tails], positions[graph.heads]], axis=1)
    lines = LineCollection(segments, array=np.linalg.norm(force, axis=1), cmap="viridis", linewidths=2)
    axes[3].add_collection(lines)
    axes[3].plot(positions[1:, 0], positions[1:, 1], "k.", markersize=4)
    axes[3].plot(0, 0, "r^", markersize=9, label="pose 0 (anchor)")
    axes[3].autoscale_view()
    axes[3].set_aspect("equal")
    axes[3].legend(fontsize=8, loc="lower left")
    fig.colorbar(lines, ax=axes[3], label="spring tension ‖f_k‖")
    axes[3].set(title="edges at p*, by tension", xlabel="x [m]", ylabel="y [m]")
    fig.tight_layout()
    return fig


def remark1_figure(runs):
    """χ² / minimum against the linear systems of size 3n solved: Gauss–Newton from dead reckoning, and LAGO
    then Gauss–Newton; ``runs`` is {label: (LAGO result, run from dead reckoning, run from LAGO)}."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(runs), figsize=(5.4 * len(runs), 4.2), squeeze=False)
    for ax, (label, (r, gn_dr, gn_lago)) in zip(axes[0], runs.items()):
        best = min(gn_dr.chi2, gn_lago.chi2)
        c_dr = np.array([entry["chi2"] for entry in gn_dr.log]) / best
        c_lago = np.array([entry["chi2"] for entry in gn_lago.log]) / best
        ax.semilogy(np.arange(c_dr.size), c_dr, "o-", label="Gauss–Newton from dead reckoning")
        ax.semilogy(1 + np.arange(c_lago.size), c_lago, "s-", label="LAGO (phase 3 = 1 step), then Gauss–Newton")
        ax.semilogy([1], [r.chi2 / best], "r*", markersize=14, label="LAGO: one n-size + one 3n-size solve")
        ax.set(xlabel="linear systems of size 3n solved", ylabel="χ² / minimum", title=label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- lecture 05's figures
def wraparound_figure(truth, raw, regularized):
    """Phases 1–3 on a noiseless four-lap circle: on the raw, wrapped δ (``raw`` poses) and on δ_reg."""
    import matplotlib.pyplot as plt

    from lago_cvx.plotting import plot_trajectory

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.4))
    for ax, poses, title in [(axes[0], raw, "phases 1–3 on the raw, wrapped δ"),
                             (axes[1], regularized, "phases 1–3 on the regularized δ_reg")]:
        plot_trajectory(ax, truth, label="ground truth (4 laps)", color="k", linewidth=3.0, alpha=0.25)
        plot_trajectory(ax, poses, label="estimate", color="tab:red", linewidth=1.0, style=".-", markersize=3)
        ax.set_title(f"circle world, {truth.shape[0]} poses, noiseless:\n{title}")
        ax.legend(fontsize=8, loc="upper right")
    inset = axes[0].inset_axes([0.3, 0.3, 0.4, 0.4])
    plot_trajectory(inset, raw, color="tab:red", linewidth=0.8, style=".-", markersize=2)
    inset.set_title("the estimate, enlarged", fontsize=8)
    inset.tick_params(labelsize=7)
    inset.set(xlabel="", ylabel="")
    fig.tight_layout()
    return fig


def circuits_figure(graph, truth, cycle, C, chords):
    """A cycle (edge vector (m,)) of a small graph and the fundamental circuits ``C`` (l × m) of its chords."""
    import matplotlib.pyplot as plt

    from lago_cvx.plotting import plot_edges

    fig, axes = plt.subplots(1, 1 + C.shape[0], figsize=(3.3 * (1 + C.shape[0]), 3.6))
    panels = [(axes[0], cycle, "a cycle (not a circuit)")] + [
        (ax, row, f"fundamental circuit of chord {graph.tails[k]}→{graph.heads[k]}") for ax, row, k in zip(axes[1:], C, chords)]
    for ax, c, title in panels:
        plot_edges(ax, graph, truth, which="all", color="0.8", linewidth=1.0, alpha=1.0)
        plot_edges(ax, graph.subgraph_edges(c != 0), truth, which="all", color="tab:red", linewidth=2.5, alpha=1.0)
        ax.plot(truth[:, 0], truth[:, 1], "ko", markersize=4)
        for i, (x, y) in enumerate(truth[:, :2]):
            ax.annotate(str(i), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=9)
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
        ax.margins(0.2)
    fig.tight_layout()
    return fig


def circuit_sums_figure(raw, regularized):
    """Histograms of the circuit sums C δ and C δ_reg (each (l,)), in turns."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 3.8))
    axes[0].hist(raw / (2 * np.pi), bins=30, color="tab:red")
    axes[0].set_title("C δ / 2π on the raw measurements: near integers")
    axes[1].hist(regularized / (2 * np.pi), bins=30, color="tab:blue")
    axes[1].set_title("C δ_reg / 2π after the rounding of eq. (23): near 0")
    for ax in axes:
        ax.set(xlabel="circuit sum / 2π", ylabel="fundamental circuits")
        ax.yaxis.get_major_locator().set_params(integer=True)
    fig.suptitle(f"the running example: {raw.size} fundamental circuits of the odometric tree")
    fig.tight_layout()
    return fig


def noise_margin_figure(sigmas, wrong, ambiguous, n_seeds):
    """Wrong and ambiguous corrections per world against the rotation noise: ``wrong`` {kind: counts} for the
    odometric and BFS trees and the chordal regularizer, ``ambiguous`` {kind: counts} for the trees."""
    import matplotlib.pyplot as plt

    from lago_cvx.rounding import AMBIGUITY_MARGIN

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
    styles = {"odometry": ("tab:red", "odometric tree (the paper's)"), "bfs": ("tab:blue", "BFS tree"),
              "chordal": ("tab:green", "chordal regularizer")}
    for kind, counts in wrong.items():
        axes[0].plot(sigmas, counts, "o-", color=styles[kind][0], label=styles[kind][1])
    for kind, counts in ambiguous.items():
        axes[1].plot(sigmas, counts, "o-", color=styles[kind][0], label=styles[kind][1])
    axes[0].set(ylabel="fundamental circuits with a wrong 2kπ (per world)",
                title=f"wrong corrections vs rotation noise\nManhattan worlds, 1000 poses, {n_seeds} seeds")
    axes[1].set(ylabel="chords reported ambiguous (per world)",
                title=f"the `ambiguous` warning (|C δ_reg| within {AMBIGUITY_MARGIN} rad of ±π)")
    for ax in axes:
        ax.set_xlabel("rotation noise σ_θ per measurement [rad]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- lecture 08's figures
def tree_rounding_figure(sigma_c, predicted, observed, draws):
    """P[wrong integer] per chord against σ_c (each (l,)): eq. (W) beside the frequency over ``draws`` draws."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    order = np.argsort(sigma_c)
    ax.plot(sigma_c[order], predicted[order], "-", label="(W): erfc(π / √2 σ_c)")
    ax.plot(sigma_c, observed, ".", ms=4, label=f"observed ({draws} noise draws)")
    ax.set(xlabel="σ_c = √(Σ P_δ around the cycle) [rad]", ylabel="P[wrong integer]",
           title="tree rounding fails when a cycle's noise nears π")
    ax.legend(fontsize=8)
    return fig


def chordal_lengths_figure(hops, profiles, norms_0, norms_last, last):
    """The relaxed lengths ‖r_i‖ against the hops from the anchor (``profiles`` {σ_θ: (n,)}), and for two anchors
    (pose 0 and pose ``last``) on one graph."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(12, 3.8))
    for sig, prof in profiles.items():
        axs[0].semilogy(hops, prof, ".", ms=3, label=f"σ_θ = {sig}")
    axs[0].set(xlabel="hops from the anchor (pose 0)", ylabel="‖r_i‖", title="relaxed lengths decay away from the anchor")
    axs[0].legend(fontsize=8, markerscale=3)
    axs[1].plot(norms_0, lw=0.8, label="anchor: pose 0")
    axs[1].plot(norms_last, lw=0.8, label=f"anchor: pose {last}")
    axs[1].set(xlabel="pose", ylabel="‖r_i‖", title="same data (σ_θ = 0.05), two anchors")
    axs[1].legend(fontsize=8)
    return fig


def sweep_figure(sigmas, regularizers, by):
    """The fraction of trials reaching the optimum against the rotation noise, per regularizer (``by``:
    {(σ_θ, name): row with "optimal" and "trials"})."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 3.6))
    for name, style in zip(regularizers, ("o--", "s:", "^-.", "D-")):
        ax.plot(sigmas, [by[(sg, name)]["optimal"] / by[(sg, name)]["trials"] for sg in sigmas], style, label=name)
    ax.set(xlabel="rotation noise σ_θ [rad]", ylabel="fraction reaching the optimum",
           title="Gauss–Newton from LAGO, by regularizer")
    ax.legend(fontsize=8)
    return fig


def sdp_tightness_figure(tight):
    """The SDP relaxation's gap against the rotation noise (``tight``: rows with sigma, gap, acc, f)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for t in tight:
        if t["gap"] <= t["acc"]:   # tight: the gap is below what the solve resolves; draw that level
            ax.semilogy(t["sigma"], t["acc"] / t["f"], "v", color="C2", ms=7)
        else:
            ax.semilogy(t["sigma"], t["gap"] / t["f"], "x", color="C3", ms=8)
    ax.plot([], [], "v", color="C2", label="tight: gap below the solve's accuracy (drawn)")
    ax.plot([], [], "x", color="C3", label="gap beyond the solve's accuracy")
    ax.set(xlabel="rotation noise σ_θ [rad]", ylabel="(f_local − f_SDP) / f_local", title="SDP relaxation, 30-pose worlds")
    ax.legend(fontsize=8)
    return fig
