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

``interactive(draw, name, **sliders)`` is a figure with sliders in a live Jupyter kernel that has ipywidgets (the
``course`` extra), and the same figure drawn once at the sliders' defaults everywhere else: a script, the tests,
and the rendered notebooks and site (``python lectures/render.py`` sets ``LAGO_CVX_STATIC=1``).
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
from lago_cvx import course_figures as _figures
from lago_cvx.progress import held_back
from lago_cvx.course_figures import *  # noqa: F401,F403 — the lectures' figures, named here for them
from lago_cvx.datasets import DatasetNotFound, dataset

__all__ = ["FULL", "S", "CLAIMS", "setup", "check", "show", "interactive", "real", "paper_lago", "figure_dir",
           "section_v_world", "running_example", "intuition_figure", "quiet", *_figures.__all__]

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
    itself) stay out of the output (``progress.held_back``: no logger's level changes). The helpers here that run the
    package (``paper_lago``, ``real``) use it; a lecture's own calls do not."""
    with held_back():
        yield


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
    """True in a Jupyter kernel: its shell is ipykernel's ZMQInteractiveShell or a subclass (Colab's)."""
    shell = sys.modules.get("IPython")
    ip = shell.get_ipython() if shell is not None and hasattr(shell, "get_ipython") else None
    if ip is None:
        return False
    zmqshell = sys.modules.get("ipykernel.zmqshell")
    return (zmqshell is not None and isinstance(ip, zmqshell.ZMQInteractiveShell)) or \
        ip.__class__.__name__ == "ZMQInteractiveShell"


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


def _static() -> bool:
    """True unless a live Jupyter kernel with ipywidgets runs the lecture and ``$LAGO_CVX_STATIC`` is unset or 0."""
    if os.environ.get("LAGO_CVX_STATIC", "") not in ("", "0") or not _in_notebook():
        return True
    try:
        import ipywidgets  # noqa: F401  (the ``course`` extra; the package itself does not need it)
    except ImportError:
        return True
    return False


def _slider_values(sliders: dict) -> dict:
    """The defaults of ``sliders`` (name → ``(low, high, step, default)``), after checking each spec."""
    from lago_cvx.errors import OptionError

    values = {}
    for key, spec in sliders.items():
        if not (isinstance(spec, tuple) and len(spec) == 4 and spec[0] <= spec[3] <= spec[1] and spec[2] > 0):
            raise OptionError(f"slider {key}={spec!r}: give (low, high, step, default) with low <= default <= high "
                              "and step > 0")
        values[key] = spec[3]
    return values


def _draw_once(draw, name, figsize, values) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=figsize)
    draw(ax, **values)
    fig.tight_layout()
    show(fig, name)


def _widget(draw, name, figsize, sliders):
    """The ipywidgets ``interactive`` of ``draw``: one slider per entry of ``sliders``, redrawn on release."""
    import ipywidgets as widgets

    controls = {}
    for key, (low, high, step, default) in sliders.items():
        integer = all(isinstance(v, (int, np.integer)) for v in (low, high, step, default))
        kind = widgets.IntSlider if integer else widgets.FloatSlider
        controls[key] = kind(min=low, max=high, step=step, value=default, description=key,
                             continuous_update=False, style={"description_width": "initial"})
    return widgets.interactive(lambda **values: _draw_once(draw, name, figsize, values), **controls)


def interactive(draw, name: str, /, *, figsize=(8.0, 4.5), **sliders) -> None:
    """A figure to play with: ``draw(ax, **values) -> ax`` draws on one matplotlib axes for the slider values.

    ``sliders``: name → ``(low, high, step, default)`` (integers throughout: an integer slider). In a live Jupyter
    kernel with ipywidgets, shows the sliders and the figure, redrawn when a slider is released; anywhere else (a
    script, the tests, ``python lectures/render.py``, which sets ``LAGO_CVX_STATIC=1``, hence the rendered notebook
    and the site) draws the figure once at the defaults with ``show(fig, name)``. Raises ``OptionError`` for a
    malformed slider."""
    values = _slider_values(sliders)
    if _static():
        _draw_once(draw, name, figsize, values)
        return
    from IPython.display import display

    display(_widget(draw, name, figsize, sliders))


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


def _intuition_04b(intel, fig, axes) -> None:
    """Lecture 4b's opening figure: INTEL at phase 3's ρ* (Theorem 1) and with θ* kept and the positions re-solved
    (eq. (14) at θ*). At the scale of the map the two look alike; what differs is where χ² (eq. (3)) sits, so every
    edge whose term e_ijᵀΩ_ij e_ij exceeds 1 is marked at its midpoint, coloured and sized by the term."""
    from matplotlib.colors import LogNorm

    from lago_cvx.positions import resolve_positions
    from lago_cvx.theorem1 import theorem1

    t = theorem1(intel, regularization="tree", information="marginal", positions="phase3")
    star = t.poses(t.x_star)
    again = resolve_positions(intel, star[:, 2], t.result.uncertainty).poses
    norm = LogNorm(1.0, 2e3)
    fig.set_size_inches(13, 5.6)
    for ax, (poses, name) in zip(axes, ((star, "phase 3's ρ*"), (again, "θ* kept, positions re-solved"))):
        terms = lc.whitened_errors(intel, poses) ** 2
        hot = np.flatnonzero(terms > 1.0)
        hot = hot[np.argsort(terms[hot])]                              # the largest drawn last, on top
        mid = 0.5 * (poses[intel.tails[hot], :2] + poses[intel.heads[hot], :2])
        _xy(ax, poses, "-", "estimate", color="0.55")
        points = ax.scatter(mid[:, 0], mid[:, 1], c=np.clip(terms[hot], 1.0, None), s=8 + 12 * np.log10(terms[hot] + 1),
                            cmap="inferno_r", norm=norm, zorder=3, label="edge with eᵀΩe > 1")
        top = terms.argsort()[::-1][:13]
        share = terms[top].sum() / terms.sum()
        ax.set(title=f"{name}: χ² = {terms.sum():.1f}\n{hot.size} edges with eᵀΩe > 1, the 13 largest carry "
                     f"{100 * share:.0f} % of χ²", xlabel="x [m]", ylabel="y [m]", aspect="equal")
        ax.title.set_fontsize(10)
        ax.legend(fontsize=8, loc="lower left")
    fig.colorbar(points, ax=axes, shrink=0.8, label="eᵀΩe of the edge (eq. (3))")
    fig.suptitle("INTEL: the same orientations, two ways to place the positions — where χ² sits")


def intuition_figure(lecture: str):
    """The figure a lecture opens with, on the running example (and INTEL for 04b, 06); returns the figure.

    ``lecture`` is the lecture's stem prefix: ``"01"``, ``"02"``, ``"03"``, ``"04a"``, ``"04b"``, ``"05"``, ``"06"``."""
    import matplotlib.pyplot as plt

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
            _intuition_04b(intel, fig, axes)
        else:
            best = lc.refine(intel, lc.lago(intel).poses).poses
            panels = ((lc.odometry_guess(intel), "odometry composed (dead reckoning)"),
                      (lc.lago(intel, route="seed").poses, "LAGO, the paper's procedure"))
            for ax, (poses, title) in zip(axes, panels):
                _xy(ax, best, "-", "minimum of χ²", color="0.6")
                _xy(ax, poses, "-", "estimate", color="tab:blue")
                ax.set(title=title, xlabel="x [m]", ylabel="y [m]", aspect="equal")
                ax.legend(fontsize=8, loc="lower left")
            fig.suptitle("INTEL")
    else:
        raise ValueError(f"no intuition figure for lecture {lecture!r}")
    if lecture != "04b":
        fig.tight_layout()
    return fig

