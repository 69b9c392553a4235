"""What every lecture shares: set-up, one-line checks, inline figures (written to disk, byte for byte
reproducibly, only when asked), real benchmark graphs (or a clear skip), and the paper's procedure.

Used as ``from lago_cvx.course import ...`` by the lectures (run from any working directory, or alone: Jupyter,
Colab, a script, the tests) and by the exercises' checks (``lago_cvx.exercises``); it reads nothing from the
project's checkout::

    from lago_cvx.course import setup, check, show, real, FULL
    setup("02_phase1")                   # compact printing, figures named 02_phase1_*, claims shown
    check(err < 1e-9, f"cvxpy = closed form ({err:.1e})")     # shows "✓ cvxpy = closed form (3.1e-16)"
    fig, ax = plt.subplots(); ...; show(fig, "laplacian")      # inline in Jupyter; saved only on request

Running a lecture changes no file: figures are displayed — inline in Jupyter, in a window when a lecture
runs as a script with an interactive matplotlib backend (``cd lectures && python 02_phase1.py``; close the
window to go on) — and written to a folder only when the environment variable ``LAGO_CVX_FIGURES`` names it
(``LAGO_CVX_FIGURES=/tmp/figs python 02_phase1.py``; ``python lectures/render.py`` sets it to the project's
``figures/``; the tests set it to a temporary folder). ``LAGO_CVX_FULL=1`` turns on the
bigger sweeps that are skipped by default to keep every lecture under a minute.

Nothing here prints (library code logs): ``check`` logs its ``✓ claim`` on the logger ``lago_cvx.course`` at
level INFO, and ``setup`` — called by the lecture, the application — attaches the one handler that shows these
records as lines of the cell's output (the current ``sys.stdout``, which is the notebook cell's stream in
Jupyter). Code that does not call ``setup`` sees nothing unless it configures logging itself. The exercises'
checks (``lago_cvx.exercises``) return what they find instead: a ``Feedback`` the notebook displays.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from pathlib import Path

import matplotlib as mpl
import numpy as np

import lago_cvx as lc
from lago_cvx.datasets import DatasetNotFound, dataset

__all__ = ["FULL", "S", "CLAIMS", "setup", "check", "show", "real", "paper_lago", "figure_dir", "section_v_world",
           "running_example", "intuition_figure", "quiet", "compounding_figure", "incidence_figure",
           "two_minima_figure", "structure_figure", "remark1_figure", "wraparound_figure", "circuits_figure",
           "circuit_sums_figure", "noise_margin_figure"]

#: Bigger sweeps (more seeds, sizes, noise levels) run only with ``LAGO_CVX_FULL=1``.
FULL = os.environ.get("LAGO_CVX_FULL", "") not in ("", "0")

#: The 90° rotation S = [[0, −1], [1, 0]] (S Δ is Δ turned by +90°; ∂R(θ)/∂θ = S R(θ)).
S = np.array([[0.0, -1.0], [1.0, 0.0]])

# Reproducible figure files: SVG ids from a fixed salt, no dates or tool versions in any file.
mpl.rcParams["svg.hashsalt"] = "lago-cvx"
mpl.rcParams["svg.fonttype"] = "path"
_METADATA = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None}}
_INLINE_DPI = 100  # the resolution of the figures shown inline (and stored in the rendered notebooks)

_PREFIX = ["lecture"]

#: The logger of the lectures' verified claims (``check``).
CLAIMS = logging.getLogger("lago_cvx.course")


class _CellOutput(logging.Handler):
    """Shows a claim as one line of the running cell's output: the ``sys.stdout`` of the moment of the record
    (Jupyter swaps it per cell), not the one of the handler's creation."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stdout.write(self.format(record) + "\n")
        except Exception:  # a closed stream: logging's own policy
            self.handleError(record)


def setup(prefix: str) -> None:
    """Start a lecture: figure files will be named ``<prefix>_<name>.{png,svg}``; NumPy prints compactly; the
    claims ``check`` verifies are shown in the output (one handler on ``CLAIMS``, installed once).
    The package's warnings are left alone: a reader's own calls show them (``quiet`` silences a block)."""
    _PREFIX[0] = prefix
    np.set_printoptions(precision=4, suppress=True, linewidth=110)
    if not any(isinstance(h, _CellOutput) for h in CLAIMS.handlers):
        handler = _CellOutput()
        handler.setFormatter(logging.Formatter("%(message)s"))
        CLAIMS.addHandler(handler)
    CLAIMS.setLevel(logging.INFO)
    CLAIMS.propagate = False


@contextlib.contextmanager
def quiet():
    """Within the block only, the package's warnings (e.g. ambiguous 2kπ roundings, which a lecture counts
    itself) stay out of the output; the logger's level is restored afterwards. The helpers here that run the
    package (``paper_lago``, ``real``) use it; a lecture's own calls do not."""
    logger = logging.getLogger("lago_cvx")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        yield
    finally:
        logger.setLevel(level)


def check(condition, claim: str) -> None:
    """One quiet line per verified claim: logs ``✓ claim`` on ``CLAIMS`` (shown in the lecture's output after
    ``setup``), or raises ``AssertionError('✗ claim')``."""
    if not bool(condition):
        raise AssertionError(f"✗ {claim}")
    CLAIMS.info("✓ %s", claim)


def figure_dir() -> Path | None:
    """Where figures are written: ``$LAGO_CVX_FIGURES`` if set, else nowhere (None)."""
    target = os.environ.get("LAGO_CVX_FIGURES", "")
    return Path(target) if target else None


def _in_notebook() -> bool:
    shell = sys.modules.get("IPython")
    ip = shell.get_ipython() if shell is not None and hasattr(shell, "get_ipython") else None
    return ip is not None and ip.__class__.__name__ == "ZMQInteractiveShell"


def show(fig, name: str) -> None:
    """Display ``fig`` inline (in Jupyter, as a PNG) or in a window (a script with an interactive backend),
    write ``<prefix>_<name>.png`` and ``.svg`` when ``$LAGO_CVX_FIGURES`` is set (identical bytes on every
    run), then close it."""
    import matplotlib.pyplot as plt

    target = figure_dir()
    if target is not None:
        target.mkdir(parents=True, exist_ok=True)
        for ext in ("png", "svg"):
            fig.savefig(target / f"{_PREFIX[0]}_{name}.{ext}", dpi=120, bbox_inches="tight",
                        metadata=_METADATA[ext])
    if _in_notebook():
        import base64
        import io

        from IPython.display import display

        # The PNG bytes are made here, without the "Software" stamp the inline backend adds, so that a
        # re-rendered notebook changes only where the figure does.
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=_INLINE_DPI, bbox_inches="tight", metadata=_METADATA["png"])
        display({"image/png": base64.b64encode(buffer.getvalue()).decode("ascii")}, raw=True)
    elif _interactive_backend():
        plt.show()                     # a script with a GUI backend: the figure in a window
    plt.close(fig)


def _interactive_backend() -> bool:
    """True when matplotlib draws to a window (not Agg, a file format or the inline backend)."""
    import matplotlib.pyplot as plt

    backend = plt.get_backend().lower()
    return backend not in ("agg", "pdf", "ps", "svg", "pgf", "cairo", "template") and "inline" not in backend


def paper_lago(graph, **options):
    """LAGO with the paper's phases — the tree rounding of Theorem 3, phases 2–3 with blkdiag(P_Δ, P_δ)
    (eqs. (9)–(15)) and phase 3's poses — on the BFS tree unless ``spanning_tree`` says otherwise
    (``route="seed"`` also takes the odometric tree, which not every graph has)."""
    with quiet():
        return lc.lago(graph, **{"regularization": "tree", "information": "marginal", "positions": "phase3",
                                 **options})


def real(rel: str):
    """Read a real benchmark graph (``rel`` inside the datasets folder, e.g. ``"carlone/INTEL_P_toro.graph"``),
    or return None and say so when the datasets are absent: the lecture then runs its synthetic cells only."""
    try:
        with quiet():
            return lc.read_graph(dataset(rel))
    except DatasetNotFound as exc:
        CLAIMS.warning("real datasets not found: skipping the %s cells (%s)", rel, exc)
        return None


def solve_qp(problem):
    """Solve a cvxpy ``problem`` with Clarabel as the package does (tolerances 1e-12, iterative refinement:
    ``solvers.LEAST_SQUARES``) but with Clarabel's default static regularization 1e-8 and its QDLDL
    factorization, which the lectures' equality-constrained forms with dense parameters need; returns the
    status."""
    import cvxpy as cp

    from lago_cvx.solvers import LEAST_SQUARES, ClarabelSettings

    kwargs = ClarabelSettings(static_regularization_constant=1e-8).over(LEAST_SQUARES).solver_kwargs()
    problem.solve(solver=cp.CLARABEL, direct_solve_method="qdldl", **kwargs)
    return problem.status


#: The uncertainty rule of the Section V world: σ = k·|measured component| + floor, per component of the
#: relative pose in the tail's frame (x and y in metres, θ in radians).
SECTION_V_RULE = {"k_t": 0.1, "floor_t": 1e-3, "k_theta": 0.05, "floor_theta": 1e-3}


def section_v_world(n_poses=500, *, seed=1, noise="proportional", sigma_xy=0.02, sigma_theta=0.01):
    """The world of lecture 6's Table II: a Manhattan world (``lc.manhattan_world``, known truth) whose
    measurements carry the information of the paper's first scenario — uncertainty proportional to the
    measured displacement, ``σ = k·|measured| + floor`` per component (``SECTION_V_RULE``).

    ``noise="proportional"``: the noise is drawn from that rule (applied to the true displacement), so the
    information is the true one; ``noise="isotropic"``: the noise is drawn with constant ``sigma_xy``,
    ``sigma_theta`` and the proportional information is *assumed*, not true. Returns ``(graph, truth)``:
    a ``PoseGraph`` (m edges, information (m, 3, 3) diagonal) and the true poses (n, 3)."""
    base = lc.manhattan_world(n_poses, seed=seed, sigma_xy=0.0, sigma_theta=0.0)
    g0, truth = base.graph, base.truth
    exact = lc.between(truth[g0.tails], truth[g0.heads])          # true relative poses δ*_ij, (m, 3)
    exact[:, 2] = lc.posegraph.wrap_angle(exact[:, 2])             # a turn as the sensor reports it
    rule = SECTION_V_RULE
    k = np.array([rule["k_t"], rule["k_t"], rule["k_theta"]])
    floor = np.array([rule["floor_t"], rule["floor_t"], rule["floor_theta"]])
    rng = np.random.default_rng(seed + 100)
    if noise == "proportional":
        sigma = k * np.abs(exact) + floor
    elif noise == "isotropic":
        sigma = np.broadcast_to([sigma_xy, sigma_xy, sigma_theta], exact.shape)
    else:
        raise ValueError(f"noise must be 'proportional' or 'isotropic', got {noise!r}")
    measured = exact + rng.standard_normal(exact.shape) * sigma
    measured[:, 2] = lc.posegraph.wrap_angle(measured[:, 2])
    assumed = k * np.abs(measured) + floor                          # the paper's rule, from the measurements
    information = np.zeros((g0.n_edges, 3, 3))
    information[:, [0, 1, 2], [0, 1, 2]] = 1.0 / assumed**2
    graph = lc.PoseGraph(g0.n_poses, g0.tails, g0.heads, measured[:, :2], measured[:, 2], information)
    return graph, truth


def running_example():
    """The course's running example: a 60-pose Manhattan world with 26 loop closures whose true headings reach
    2.5π, beyond a full turn (``lc.manhattan_world(60, seed=1, sigma_xy=0.1, sigma_theta=0.05)``); the real
    graph that goes with it is INTEL (``carlone/INTEL_P_toro.graph``)."""
    return lc.manhattan_world(60, seed=1, sigma_xy=0.1, sigma_theta=0.05)


def _xy(ax, poses, style, label, **kw):
    ax.plot(poses[:, 0], poses[:, 1], style, label=label, markersize=3, linewidth=1.2, **kw)


def intuition_figure(lecture: str):
    """The figure a lecture opens with, on the running example (and INTEL for 04b, 06); returns the figure.

    ``lecture`` is the lecture's stem prefix: ``"01"``, ``"02"``, ``"03"``, ``"04a"``, ``"04b"``, ``"05"``, ``"06"``."""
    import matplotlib.pyplot as plt

    from lago_cvx.posegraph import wrap_angle
    from lago_cvx.theorem1 import theorem1

    world = running_example()
    g, truth = world.graph, world.truth
    if lecture == "01":
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
        for ax, poses, title in ((axes[0], truth, "the true poses and the measured edges"),
                                 (axes[1], lc.odometry_guess(g), "dead reckoning: odometry composed")):
            for k in range(g.n_edges):
                i, j = g.tails[k], g.heads[k]
                ax.plot(poses[[i, j], 0], poses[[i, j], 1], "-" if g.is_odometric[k] else ":",
                        color="tab:blue" if g.is_odometric[k] else "tab:red", linewidth=1.0)
            ax.plot([], [], "-", color="tab:blue", label="odometry")
            ax.plot([], [], ":", color="tab:red", label="loop closures")
            ax.set(title=title, xlabel="x [m]", ylabel="y [m]", aspect="equal")
            ax.legend(fontsize=8, loc="best")
        fig.suptitle("The running example: where is the robot, given only relative measurements?")
    elif lecture in ("02", "05"):
        res = lc.lago(g, route="seed")
        fig, ax = plt.subplots(figsize=(9, 4))
        k = np.arange(g.n_poses)
        ax.plot(k, truth[:, 2], "k-", linewidth=2, label="true heading")
        ax.plot(k, lc.odometry_guess(g)[:, 2], "--", color="tab:orange", label="turns added up (dead reckoning)")
        ax.plot(k, res.phase1.theta, ".", color="tab:blue", label="phase 1: loops shared out")
        if lecture == "05":
            raw = lc.phases.phase1_closed_form(g, g.delta, lc.uncertainty.edge_uncertainty(g)).theta
            ax.plot(k, raw, "x", color="tab:red", markersize=4, label="phase 1 without the 2kπ corrections")
        ax.set(xlabel="pose index", ylabel="heading θ [rad]",
               title="Headings of the running example" + (": whole turns matter" if lecture == "05" else ""))
        ax.legend(fontsize=8)
    elif lecture in ("03", "04a"):
        t = theorem1(g, regularization="tree", information="marginal", positions="phase3")
        fig, ax = plt.subplots(figsize=(6.5, 5.5))
        _xy(ax, truth, "k-", "truth")
        if lecture == "03":
            ph2 = t.result.phase2
            chain = np.vstack([[0.0, 0.0], np.cumsum(ph2.delta_g[g.is_odometric], axis=0)])
            _xy(ax, lc.odometry_guess(g), "--", "dead reckoning", color="tab:orange")
            _xy(ax, chain, ".-", "odometric Δᵍ turned by phase 1's θ̂, chained", color="tab:blue")
            ax.set_title("Phase 2: displacements turned into the map's frame")
        else:
            _xy(ax, t.poses(t.x_hat), ".-", "ρ̂: θ̂ of phase 1, positions of eq. (14)", color="tab:orange")
            _xy(ax, t.poses(t.x_star), ".-", "ρ*: phase 3", color="tab:blue")
            ax.set_title("Phase 3 corrects ρ̂ by one linear step")
        ax.set(xlabel="x [m]", ylabel="y [m]", aspect="equal")
        ax.legend(fontsize=8)
    elif lecture in ("04b", "06"):
        intel = real("carlone/INTEL_P_toro.graph")
        fig, axes = plt.subplots(1, 2, figsize=(11, 5))
        if intel is None:
            for ax in axes:
                ax.set(xlabel="x [m]", ylabel="y [m]", title="INTEL not available")
            return fig
        if lecture == "04b":
            t = theorem1(intel, regularization="tree", information="marginal", positions="phase3")
            best = lc.refine(intel, t.result.poses).poses
            star = t.poses(t.x_star)
            from lago_cvx.positions import resolve_positions
            again = resolve_positions(intel, star[:, 2], t.result.uncertainty).poses
            panels = ((star, f"phase 3's ρ*: χ² = {lc.chi2(intel, star):.0f}"),
                      (again, f"θ* kept, positions re-solved: χ² = {lc.chi2(intel, again):.1f}"))
        else:
            best = lc.refine(intel, lc.lago(intel).poses).poses
            panels = ((lc.odometry_guess(intel), "odometry composed (dead reckoning)"),
                      (lc.lago(intel, route="seed").poses, "LAGO, the paper's procedure"))
        for ax, (poses, title) in zip(axes, panels):
            _xy(ax, best, "-", "minimum of χ²", color="0.6")
            _xy(ax, poses, "-", "estimate", color="tab:blue")
            ax.set(title=title, xlabel="x [m]", ylabel="y [m]", aspect="equal")
            ax.legend(fontsize=8, loc="lower left")
        fig.suptitle("INTEL" + (": the same orientations, two ways to place the positions" if lecture == "04b" else ""))
    else:
        raise ValueError(f"no intuition figure for lecture {lecture!r}")
    fig.tight_layout()
    return fig


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
