"""The paper's Section V beyond Table I: Table II's two scenarios, Fig. 3, and what INTEL's χ² says.

Used by lecture 06 (sections 5, 6 and 8) and its tests. Everything here is a measurement; the lecture's
checks compare the numbers, nothing here decides what they mean.

**Table II** (Section V) scores estimates with the relative-relations metric of Kümmerle et al. (2009): over
relations (i, j) with reference relative pose δ*_ij,

    ε_t = (1/N) Σ ‖trans(δ̂_ij ⊖ δ*_ij)‖²  [m²],     ε_θ = (1/N) Σ rot(δ̂_ij ⊖ δ*_ij)²  [rad²],

δ̂_ij = p̂_j ⊖ p̂_i the estimate's relative pose (eq. (1)); ``relation_errors``. The paper runs it in two
scenarios of the measurement covariance: P_ij = diag(P_Δl,ij, P_δ,ij) "proportional to the respective
measurements", and P_ij = I₃ (``SCENARIOS``, ``scenario_graph``), TORO after 100 and 1000 iterations against
the three phases (``PAPER_TABLE_II``, as printed). Here the iterative solver is the package's Gauss–Newton on
eq. (3) from odometry (``refine``), recorded one iteration at a time (``gauss_newton_path``).

* On a generated world with known truth (``lago_cvx.course.section_v_world``) the reference is the truth:
  ``table_ii_world`` gives the rows of Table II for both scenarios; ``table_ii_sweep`` repeats it over several
  worlds, ``spread`` summarises them.
* On INTEL there is no truth (the benchmark's relations file is not public; README of the datasets). The
  reference is then the minimum of χ² of the same scenario: ``table_ii_intel`` reports, per row, χ²/min, the
  relations' ε against the minimum's and the aligned absolute trajectory error (ATE) to it.

**Fig. 3** plots, for the proportional scenario, ε_t and ε_θ of TORO over 0–1000 iterations against the level
of the three phases; ``PAPER_FIG3`` holds what the paper's text gives of it (Table II's values at 100 and
1000 iterations, and the axis ranges printed on the figure).

**Fig. 2(b)** needs laser scans, which the graph files do not hold; ``swept_grid`` draws what the poses alone
prove, the cells a robot's footprint swept.

**The abstract's claim** ("refinement is often unnecessary, since the linear estimate is already accurate"),
measured on a graph without truth (``claim_row``): χ² of the paper's procedure and of the default route over the
minimum, χ² at Theorem 1's ρ̂, the ambiguous chords of the regularization, and Gauss–Newton's iterations.

**The INTEL verdict** (``chi2_concentration``): the share of χ² carried by the edges with the largest terms
e_ijᵀ Ω_ij e_ij of eq. (3), and the smallest standard deviation each edge claims (the minor axis of its
translational covariance).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .metrics import ate, chi2, whitened_errors
from .pipeline import lago
from .posegraph import PoseGraph, between, wrap_angle
from .refinement import odometry_guess, refine

__all__ = ["SCENARIOS", "PAPER_TABLE_II", "PAPER_FIG3", "STOPS", "scenario_graph", "relation_errors",
           "GaussNewtonPath", "gauss_newton_path", "table_ii_world", "table_ii_sweep", "spread", "FINDINGS", "findings",
           "format_findings", "table_ii_intel",
           "format_table_ii_intel", "Concentration", "chi2_concentration", "format_table_ii", "swept_grid",
           "claim_row", "format_claim_rows", "plot_iterations"]

#: The two scenarios of Table II: the graph's own (proportional) information, and P_ij = I₃.
SCENARIOS = ("proportional", "P = I₃")

#: The paper's Table II (INTEL; (ε_t [m²], ε_θ [rad²])) as printed. The stored text of the scan prints the
#: exponents of the two TORO rows once, between them (−3, −4, −4, −4), read here as applying to both rows.
PAPER_TABLE_II = {"TORO, 100 iterations": {"proportional": (2.60e-3, 2.30e-4), "P = I₃": (6.16e-4, 1.62e-4)},
                  "TORO, 1000 iterations": {"proportional": (1.90e-3, 2.18e-4), "P = I₃": (5.83e-4, 1.62e-4)},
                  "LAGO": {"proportional": (0.91e-2, 2.25e-4), "P = I₃": (3.36e-4, 2.00e-4)}}

#: What the paper's text gives of Fig. 3 (the proportional scenario). The curves themselves cannot be read
#: from the stored text; Table II gives TORO's values at 100 and 1000 iterations and the level of the three
#: phases (dashed). The axis ranges are read from the figure's tick labels: (a) ε_t 0 … 0.03 m² in steps of
#: 0.005; (b) ε_θ 0 … 14·10⁻⁴ rad² in steps of 2·10⁻⁴; iterations 0 … 1000 in steps of 200 on both. The stored
#: text is a character recognition of the scan, which prints the two axis tops as "003" and "x10*": read as 0.03
#: and ×10⁻⁴ (the only reading that puts Table II's values inside the axes; ``ylim``).
PAPER_FIG3 = {"TORO": {100: PAPER_TABLE_II["TORO, 100 iterations"]["proportional"],
                       1000: PAPER_TABLE_II["TORO, 1000 iterations"]["proportional"]},
              "LAGO": PAPER_TABLE_II["LAGO"]["proportional"],
              "ylim": ((0.0, 0.03), (0.0, 14e-4)), "xlim": (0, 1000)}

#: The iteration counts of Table II's iterative rows here (the paper's 100 and 1000, and 1 and 10).
STOPS = (1, 10, 100, 1000)


def scenario_graph(graph: PoseGraph, scenario: str) -> PoseGraph:
    """``graph`` in one of Table II's scenarios: ``"proportional"`` keeps its information (m, 3, 3);
    ``"P = I₃"`` sets P_ij = Ω_ij = I₃ on every edge (and drops a file's given information)."""
    if scenario == "proportional":
        return graph
    if scenario != "P = I₃":
        raise ValueError(f"scenario must be one of {SCENARIOS}, got {scenario!r}")
    identity = np.broadcast_to(np.eye(3), graph.information.shape).copy()
    return replace(graph, information=identity, given_information=None)


def relation_errors(graph: PoseGraph, poses, truth) -> tuple[float, float]:
    """Table II's metric (ε_t [m²], ε_θ [rad²]) over the edges of ``graph`` as relations: mean squared
    translation and rotation of δ̂_ij ⊖ δ*_ij, δ̂ from ``poses`` (n, 3), δ* from ``truth`` (n, 3) (eq. (1))."""
    est = between(poses[graph.tails], poses[graph.heads])
    ref = between(truth[graph.tails], truth[graph.heads])
    d = between(ref, est)                                   # δ̂ ⊖ δ*, in the frame of δ*
    return float(np.mean(np.sum(d[:, :2] ** 2, 1))), float(np.mean(wrap_angle(d[:, 2]) ** 2))


@dataclass(frozen=True)
class GaussNewtonPath:
    """Gauss–Newton from ``start`` one iteration at a time: ``poses[k]`` after k iterations (k = 0 … K, K the
    iterations the uninterrupted run takes before its convergence test stops it), ``chi2[k]``, and that run
    (``run``: ``RefineResult``). Gauss–Newton keeps no state between iterations, so ``chi2`` equals the run's
    log; after K the iterate does not move, and ``at(k)`` for k > K is ``poses[K]``."""

    poses: tuple
    chi2: np.ndarray
    run: object

    def at(self, k: int) -> np.ndarray:
        return self.poses[min(k, len(self.poses) - 1)]


def gauss_newton_path(graph: PoseGraph, start, *, max_iterations: int = 1000) -> GaussNewtonPath:
    """Gauss–Newton on eq. (3) from ``start`` (n, 3) for at most ``max_iterations``, every iterate kept."""
    run = refine(graph, start, max_iterations=max_iterations)
    poses = [np.asarray(start, dtype=float)]
    for _ in range(run.iterations):
        poses.append(refine(graph, poses[-1], max_iterations=1).poses)
    return GaussNewtonPath(tuple(poses), np.array([chi2(graph, p) for p in poses]), run)


def _rows(graph: PoseGraph) -> tuple[dict, GaussNewtonPath]:
    """The estimates of Table II's rows for ``graph`` (one scenario) and Gauss–Newton's path from odometry."""
    path = gauss_newton_path(graph, odometry_guess(graph))
    default = lago(graph)
    rows = {"odometry": path.at(0)}
    rows.update({f"Gauss–Newton, {k} it.": path.at(k) for k in STOPS})
    rows["LAGO, the paper's procedure"] = lago(graph, route="seed").poses
    rows["LAGO, default route"] = default.poses
    rows["minimum of χ² (from LAGO)"] = refine(graph, default.poses).poses
    return rows, path


def table_ii_world(graph: PoseGraph, truth) -> tuple[dict, dict]:
    """Table II on a world with known ``truth`` (n, 3), both scenarios: ``table[scenario][row] = (ε_t, ε_θ)``,
    and ``curves[scenario]`` = (K+1, 2) array of (ε_t, ε_θ) after k = 0 … K Gauss–Newton iterations from
    odometry (Fig. 3; constant after K), with K+1 = its length."""
    table, curves = {}, {}
    for scenario in SCENARIOS:
        rows, path = _rows(scenario_graph(graph, scenario))
        table[scenario] = {row: relation_errors(graph, p, truth) for row, p in rows.items()}
        curves[scenario] = np.array([relation_errors(graph, p, truth) for p in path.poses])
    return table, curves


def plot_iterations(ax, curves: dict, column: int, *, color: str, label: str, horizon: int = 1000) -> None:
    """Fig. 3 on matplotlib axes ``ax``: for every world of ``curves`` (``table_ii_sweep``; the proportional
    scenario) ε_t (``column`` 0) or ε_θ (1) after k = 0 … ``horizon`` iterations — constant after the last iterate
    — as a thin line, and their median as a thick one labelled ``label``."""
    k = np.arange(horizon + 1)
    full = np.array([c["proportional"][np.minimum(k, len(c["proportional"]) - 1), column] for c in curves.values()])
    for line in full:
        ax.plot(k, line, color=color, linewidth=0.5, alpha=0.4)
    ax.plot(k, np.median(full, 0), color=color, linewidth=2, label=label)


def table_ii_sweep(world, draws) -> tuple[dict, dict]:
    """``table_ii_world`` on ``world(d)`` → (graph, truth) for every d in ``draws``: ``tables[d]``, ``curves[d]``."""
    tables, curves = {}, {}
    for d in draws:
        tables[d], curves[d] = table_ii_world(*world(d))
    return tables, curves


def spread(tables: dict) -> dict:
    """Per scenario, row and column the median, minimum and maximum over the worlds of ``tables``
    (``table_ii_sweep``): ``out[scenario][row] = array (3, 2)`` (rows median, min, max; columns ε_t, ε_θ)."""
    first = next(iter(tables.values()))
    out = {}
    for scenario, rows in first.items():
        out[scenario] = {}
        for row in rows:
            v = np.array([t[scenario][row] for t in tables.values()])      # (worlds, 2)
            out[scenario][row] = np.vstack([np.median(v, 0), v.min(0), v.max(0)])
    return out


#: The paper's findings of Table II as ratios of two entries (row, scenario, column ∈ {0: ε_t, 1: ε_θ}); the
#: iterative solver is TORO after 1000 iterations in the paper, Gauss–Newton from odometry here.
FINDINGS = {"LAGO's ε_θ, proportional P / P = I₃": (("LAGO", "proportional", 1), ("LAGO", "P = I₃", 1)),
            "iterative ε_θ, proportional P / P = I₃": (("iterative", "proportional", 1), ("iterative", "P = I₃", 1)),
            "LAGO's ε_t, proportional P / P = I₃": (("LAGO", "proportional", 0), ("LAGO", "P = I₃", 0)),
            "iterative ε_t, proportional P / P = I₃": (("iterative", "proportional", 0), ("iterative", "P = I₃", 0)),
            "proportional P: LAGO's ε_t / iterative": (("LAGO", "proportional", 0), ("iterative", "proportional", 0)),
            "P = I₃: LAGO's ε_t / iterative": (("LAGO", "P = I₃", 0), ("iterative", "P = I₃", 0))}


def findings(tables: dict) -> dict:
    """Each of ``FINDINGS`` in the paper and in every world of ``tables``: ``out[name] = (paper ratio, array
    of the ratios here, one per world)``."""
    here_row = {"LAGO": "LAGO, the paper's procedure", "iterative": f"Gauss–Newton, {STOPS[-1]} it."}
    paper_row = {"LAGO": "LAGO", "iterative": "TORO, 1000 iterations"}
    out = {}
    for name, ((r1, s1, c1), (r2, s2, c2)) in FINDINGS.items():
        paper = PAPER_TABLE_II[paper_row[r1]][s1][c1] / PAPER_TABLE_II[paper_row[r2]][s2][c2]
        here = np.array([t[s1][here_row[r1]][c1] / t[s2][here_row[r2]][c2] for t in tables.values()])
        out[name] = (paper, here)
    return out


def format_findings(found: dict, title: str = "") -> str:
    """``findings`` as text: the paper's ratio, the median and range here, and in how many worlds the ratio
    lies on the paper's side of 1, within 2 % of 1 (no difference), or on the other side."""
    lines = [title, f"{'finding':42s} {'paper':>7s} {'here: median [min, max]':>26s}  {'worlds: as paper / ≈ 1 / opposite'}"]
    for name, (paper, here) in found.items():
        near = np.abs(np.log(here)) < np.log(1.02)
        same = int(np.sum(~near & (np.sign(np.log(here)) == np.sign(np.log(paper)))))
        lines.append(f"{name:42s} {paper:7.2f} {np.median(here):8.2f} [{here.min():6.2f}, {here.max():6.2f}]"
                     f"  {same:8d} / {int(near.sum())} / {here.size - same - int(near.sum())}")
    return "\n".join(lines)


def table_ii_intel(graph: PoseGraph) -> tuple[dict, dict]:
    """Table II's rows on a real graph without truth, both scenarios. ``table[scenario][row]`` is a dict
    with ``chi2_ratio`` (χ² of the scenario over its minimum), ``eps_t``, ``eps_theta`` (the relations' ε
    against the minimum's relations) and ``ate`` (aligned, to the minimum) [m]; ``paths[scenario]`` is
    Gauss–Newton's path from odometry (``GaussNewtonPath``) and ``minimum``, the minimum's χ²."""
    table, paths = {}, {}
    for scenario in SCENARIOS:
        gs = scenario_graph(graph, scenario)
        rows, path = _rows(gs)
        best = rows["minimum of χ² (from LAGO)"]
        low = chi2(gs, best)
        table[scenario] = {row: dict(zip(("eps_t", "eps_theta"), relation_errors(graph, p, best)),
                                     chi2_ratio=chi2(gs, p) / low, ate=ate(p, best))
                           for row, p in rows.items()}
        paths[scenario] = (path, low)
    return table, paths


def format_table_ii_intel(table: dict, paths: dict) -> str:
    """``table_ii_intel`` as text, one block per scenario."""
    lines = []
    for scenario, rows in table.items():
        lines += [f"\nINTEL, {scenario}: minimum χ² {paths[scenario][1]:.4g}",
                  f"{'':34s} {'χ²/min':>10s} {'ε_t vs min [m²]':>16s} {'ε_θ vs min [rad²]':>18s} {'ATE to min [m]':>15s}"]
        lines += [f"{row:34s} {v['chi2_ratio']:10.4g} {v['eps_t']:16.2e} {v['eps_theta']:18.2e} {v['ate']:15.4f}"
                  for row, v in rows.items()]
    return "\n".join(lines)


@dataclass(frozen=True)
class Concentration:
    """Per-edge terms of χ² (eq. (3)) at one estimate: ``terms`` (m,) e_ijᵀΩ_ij e_ij, ``order`` the edges by
    decreasing term, ``share`` (m,) the cumulative share of χ² of the first k+1 edges of ``order``, and
    ``sigma_minor`` (m,) [m] the smallest standard deviation of each edge's translational covariance."""

    terms: np.ndarray
    order: np.ndarray
    share: np.ndarray
    sigma_minor: np.ndarray

    def top(self, k: int) -> float:
        """The share of χ² carried by the k edges with the largest terms."""
        return float(self.share[k - 1])


def chi2_concentration(graph: PoseGraph, poses) -> Concentration:
    """How χ² of ``poses`` (n, 3) is spread over the edges of ``graph`` (``Concentration``)."""
    terms = whitened_errors(graph, poses) ** 2
    order = np.argsort(terms)[::-1]
    share = np.cumsum(terms[order]) / terms.sum()
    sigma_minor = np.sqrt(np.linalg.eigvalsh(graph.covariance[:, :2, :2])[:, 0])
    return Concentration(terms, order, share, sigma_minor)


def format_table_ii(stats: dict, paper: dict = PAPER_TABLE_II, title: str = "") -> str:
    """Table II as text: the paper's rows, then ``stats[scenario][row]`` — a pair (ε_t, ε_θ), or the (3, 2)
    array of ``spread`` (printed as median [min, max])."""
    cols = "".join(f"{'ε_t [m²]':>24s}{'ε_θ [rad²]':>24s}" for _ in SCENARIOS)
    lines = [title, f"{'':34s}" + "".join(f"{s:^48s}" for s in SCENARIOS), f"{'':34s}{cols}"]
    for row, values in paper.items():
        lines.append(f"{'paper: ' + row:34s}" + "".join(f"{v:24.2e}" for s in SCENARIOS for v in values[s]))
    first = stats[SCENARIOS[0]]
    for row in first:
        cells = []
        for s in SCENARIOS:
            v = np.asarray(stats[s][row])
            cells += ([f"{v[0, c]:.1e} [{v[1, c]:.0e}, {v[2, c]:.0e}]" for c in (0, 1)] if v.ndim == 2 else
                      [f"{v[c]:24.2e}" for c in (0, 1)])
        lines.append(f"{row:34s}" + "".join(f"{c:>24s}" for c in cells))
    return "\n".join(lines)


def swept_grid(poses, resolution: float = 0.2, radius: float = 0.3):
    """Fig. 2(b)'s substitute: the boolean grid (cells of ``resolution`` metres) of the cells within ``radius``
    of the trajectory ``poses`` (n, 3) (straight segments between consecutive poses), the grid's origin (2,),
    and the swept area [m²]."""
    xy = np.asarray(poses, dtype=float)[:, :2]
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
    return grid, lo, float(grid.sum() * resolution**2)


def claim_row(graph: PoseGraph, reference: float | None = None, *, from_odometry: bool = True) -> dict:
    """The abstract's claim on one graph. The minimum ``min`` is Gauss–Newton's from the default route; ``ok`` says
    it converged to ``reference`` (the lowest χ² known, relative 1e-5; None: not compared). Ratios to it: ``paper``
    (the paper's procedure), ``default`` (the default route), ``rho_hat`` (χ² at Theorem 1's ρ̂ = [p̂; θ̂], eq. (14));
    ``ambiguous`` chords of the paper's regularization (Theorem 3's rounding within its margin of ±π);
    ``it_lago`` Gauss–Newton iterations from the default route; with ``from_odometry``, ``it_odo`` and ``odo`` (χ²
    over the minimum) from odometry, at most 100 iterations (else −1 and NaN)."""
    from .theorem1 import theorem1

    seed_route = lago(graph, route="seed")
    default_route = lago(graph)
    from_lago = refine(graph, default_route.poses)
    low = from_lago.chi2
    row = {"poses": graph.n_poses, "min": low, "paper": seed_route.chi2 / low, "default": default_route.chi2 / low,
           "ambiguous": seed_route.regularization.ambiguous.size,
           "rho_hat": theorem1(graph, seed_route).chi2_suboptimal / low, "it_lago": from_lago.iterations,
           "odo": float("nan"), "it_odo": -1,
           "ok": from_lago.converged and (reference is None or abs(low - reference) <= 1e-5 * low)}
    if from_odometry:
        from_odo = refine(graph, odometry_guess(graph), max_iterations=100)
        row.update(odo=from_odo.chi2 / low, it_odo=from_odo.iterations)
    return row


def format_claim_rows(rows: dict) -> str:
    """``claim_row`` of several graphs (name → row) as a table."""
    lines = [f"{'':48s} {'χ² / min':^34s} {'Gauss–Newton iterations':^30s}",
             f"{'file':30s} {'poses':>6s} {'min χ²':>9s}  {'paper':>8s} {'default':>8s} {'ρ̂':>7s} {'ambig.':>7s}  "
             f"{'from LAGO':>10s} {'from odometry (→ /min)':>24s}"]
    for name, r in rows.items():
        odo = f"{r['it_odo']:12d} (→ {r['odo']:.3g})" if r["it_odo"] >= 0 else f"{'(LAGO_CVX_FULL=1)':>20s}"
        lines.append(f"{name:30s} {r['poses']:6d} {r['min']:9.6g}  {r['paper']:8.5g} {r['default']:8.4f} "
                     f"{r['rho_hat']:7.3f} {r['ambiguous']:7d}  {r['it_lago']:10d} {odo}")
    return "\n".join(lines)
