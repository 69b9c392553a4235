"""Reproducible experiments shared by the benchmarks, the lectures and the tests.

``rotation_noise_sweep`` — the issue-8 experiment: on synthetic Manhattan worlds with rising rotation
noise σ_θ, does Gauss–Newton started from LAGO reach the optimum that a ground-truth start reaches,
with each regularizer? Per trial:

    1. world = manhattan_world(n_poses, seed, sigma_theta=σ_θ, ...)            (ground truth known)
    2. χ²_ref = χ² reached by Gauss–Newton started from the ground truth       (the reference optimum)
    3. for every regularizer: LAGO → Gauss–Newton → χ²; *optimal* when χ² ≤ χ²_ref (1 + tolerance);
       *correct integers* when its cycle integers C k equal those implied by the true orientations
       (k_true,e = round((θ_j − θ_i − δ_e)/2π) on every edge, then C k_true).

Rows are plain dicts (one per σ_θ and regularizer) so they print as a table (``format_sweep``).

``integer_noise_sweep`` — the integer program of the cycle integers against the seed's rounding over
rising rotation noise (``format_integer_sweep`` prints it; ``python benchmarks/run.py integer``).
"""

from __future__ import annotations

import logging
import time
from typing import Callable, Iterable

import numpy as np

from .metrics import chi2
from .phases import phase1_closed_form, phase2, phase3_closed_form
from .pipeline import lago
from .posegraph import PoseGraph
from .refinement import refine
from .regularization.integer import cycle_data, cycle_integers, integer_regularization
from .rounding import TWO_PI, edge_integers
from .solvers import IntegerSearch
from .synthetic import circle_world, manhattan_world
from .uncertainty import EdgeUncertainty, edge_uncertainty

__all__ = ["DEFAULT_REGULARIZERS", "true_cycle_integers", "rotation_noise_sweep", "format_sweep",
           "integer_noise_sweep", "format_integer_sweep"]

log = logging.getLogger(__name__)

#: name → keyword arguments of ``lago`` (the regularizers compared by default).
DEFAULT_REGULARIZERS = {
    "tree (bfs)": {"spanning_tree": "bfs", "regularization": "tree"},
    "tree (odometry)": {"spanning_tree": "odometry", "regularization": "tree"},
    "chordal": {"spanning_tree": "bfs", "regularization": "chordal"},
}


def true_cycle_integers(graph: PoseGraph, tree, truth: np.ndarray) -> np.ndarray:
    """Cycle integers (l,) implied by the true poses ``truth`` (n, 3): with the per-edge integers that put
    δ on the branch of the true orientations (``rounding.edge_integers``), C k (C = [I B], Corollary 2)."""
    return cycle_integers(graph, tree, edge_integers(graph, np.asarray(truth, dtype=float)[:, 2]))


def rotation_noise_sweep(sigmas: Iterable[float], *, seeds: Iterable[int] = range(8), n_poses: int = 300,
                         regularizers: dict | None = None, tolerance: float = 1e-6, max_iterations: int = 100,
                         world: Callable = manhattan_world, progress: Callable | None = None,
                         **world_kwargs) -> list[dict]:
    """Run the sweep described in the module docstring.

    sigmas — rotation noise levels σ_θ (rad); seeds — world seeds (one trial each); n_poses — poses per
    world; regularizers — ``{name: lago keyword arguments}`` (default ``DEFAULT_REGULARIZERS``);
    tolerance — relative χ² tolerance of "reached the reference optimum"; world — the generator
    (called as ``world(n_poses, seed=..., sigma_theta=..., **world_kwargs)``); progress — optional
    callback ``progress(done, total)``.

    Returns one dict per (σ_θ, regularizer): ``sigma_theta``, ``regularizer``, ``trials``,
    ``optimal`` (trials whose GN reached χ²_ref), ``correct_integers`` (trials whose cycle integers
    equal the true ones), ``ambiguous`` (mean number of ambiguous chords/edges reported),
    ``chi2_ratio_median`` (median of χ²_GN / χ²_ref), ``seconds``."""
    regularizers = dict(DEFAULT_REGULARIZERS if regularizers is None else regularizers)
    sigmas, seeds = list(sigmas), list(seeds)
    total, done = len(sigmas) * len(seeds), 0
    rows = []
    for sigma in sigmas:
        acc = {name: {"optimal": 0, "correct_integers": 0, "ambiguous": 0, "ratios": [], "seconds": 0.0}
               for name in regularizers}
        for seed in seeds:
            w = world(n_poses, seed=seed, sigma_theta=sigma, **world_kwargs)
            g = w.graph
            ref = refine(g, w.truth, max_iterations=max_iterations).chi2
            for name, kw in regularizers.items():
                t = time.perf_counter()
                res = lago(g, **kw)
                gn = refine(g, res.poses, max_iterations=max_iterations)
                a = acc[name]
                a["seconds"] += time.perf_counter() - t
                a["optimal"] += int(gn.chi2 <= ref * (1.0 + tolerance))
                reg = res.regularization
                a["correct_integers"] += int(np.array_equal(reg.cycle_k, true_cycle_integers(g, res.tree, w.truth)))
                a["ambiguous"] += int(reg.ambiguous.size)
                a["ratios"].append(gn.chi2 / ref)
            done += 1
            if progress is not None:
                progress(done, total)
            log.info("sweep: σ_θ = %g, seed %d done (%d/%d)", sigma, seed, done, total)
        for name, a in acc.items():
            rows.append({"sigma_theta": float(sigma), "regularizer": name, "trials": len(seeds),
                         "optimal": a["optimal"], "correct_integers": a["correct_integers"],
                         "ambiguous": a["ambiguous"] / max(len(seeds), 1),
                         "chi2_ratio_median": float(np.median(a["ratios"])) if a["ratios"] else float("nan"),
                         "seconds": a["seconds"]})
    return rows


def format_sweep(rows: list[dict]) -> str:
    """Markdown table of ``rotation_noise_sweep`` rows: one line per σ_θ, "optimal/trials (correct
    integers)" per regularizer."""
    names = list(dict.fromkeys(r["regularizer"] for r in rows))
    sigmas = list(dict.fromkeys(r["sigma_theta"] for r in rows))
    by = {(r["sigma_theta"], r["regularizer"]): r for r in rows}
    head = "| σ_θ (rad) | " + " | ".join(f"{n}: GN optimal (integers right)" for n in names) + " |"
    lines = [head, "|---" * (len(names) + 1) + "|"]
    for s in sigmas:
        cells = []
        for n in names:
            r = by[(s, n)]
            cells.append(f"{r['optimal']}/{r['trials']} ({r['correct_integers']})")
        lines.append(f"| {s:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


# --------------------------------------------------------------------------- integer program vs rounding
def _lago_chi2(graph: PoseGraph, tree, delta_reg: np.ndarray, unc: EdgeUncertainty) -> tuple[float, float]:
    """χ² of LAGO's phases 1–3 (closed form) run on a given δ_reg, anchored at the tree's root, and χ²
    after Gauss–Newton refinement (``lago_cvx.refinement.refine``) from that estimate."""
    a = int(graph.ids[tree.root])
    ph1 = phase1_closed_form(graph, delta_reg, unc, anchor=a)
    ph3 = phase3_closed_form(graph, phase2(graph, ph1.theta, unc, anchor=a, delta_reg=delta_reg))
    return chi2(graph, ph3.poses), chi2(graph, refine(graph, ph3.poses).poses)


def integer_noise_sweep(*, sigmas=(0.01, 0.05, 0.1, 0.15, 0.2, 0.3), seeds=range(5), n_poses: int = 100,
                        world: str = "manhattan", tree: str = "bfs", search: IntegerSearch | None = None,
                        world_kwargs: dict | None = None, with_chi2: bool = True) -> list[dict]:
    """Integer program against rounding over rising rotation noise σ_θ on seeded synthetic worlds.

    For every σ_θ and seed: build ``manhattan_world`` / ``circle_world`` (``world_kwargs`` passed on),
    its tree, the rounding and the IP (``search``, default the exact enumeration); the ground truth is
    ``true_cycle_integers``. One row per σ_θ:
      ``cases``, ``chords`` (mean l), ``ip_eq_round`` / ``ip_eq_true`` / ``round_eq_true`` (fraction of
      cases whose cycle integers coincide, all chords), ``chords_differ`` (mean chords IP ≠ rounding),
      ``ip_better`` (fraction with J_IP < J_round by > 1e-9 relative), ``gain`` (mean (J_round − J_IP)/J_IP),
      ``J_ip``, ``J_round``, ``J_true`` (means), ``truth_above_ip`` (fraction with J_true > J_IP: the
      weighted optimum itself disagrees with the truth), ``chi2_ratio`` (mean of χ²(LAGO on rounding) /
      χ²(LAGO on IP) over the cases where the two differ, if ``with_chi2``; nan if none),
      ``refined_ratio`` (the same after Gauss–Newton refinement of each LAGO estimate: > 1 means the
      rounding's start lands in a worse local minimum), ``time`` (mean solver seconds), ``not_optimal`` (count)."""
    from .errors import OptionError
    from .graph import spanning_tree

    search = IntegerSearch(solver="enumerate") if search is None else search
    gen = {"manhattan": manhattan_world, "circle": circle_world}.get(world)
    if gen is None:
        raise OptionError(f"unknown world {world!r}; expected 'manhattan' or 'circle'")
    rows = []
    for sigma in sigmas:
        acc = {k: [] for k in ("chords", "ip_eq_round", "ip_eq_true", "round_eq_true", "chords_differ",
                               "ip_better", "gain", "J_ip", "J_round", "J_true", "truth_above_ip",
                               "chi2_ratio", "refined_ratio", "time", "not_optimal")}
        for seed in seeds:
            w = gen(n_poses, seed=int(seed), sigma_theta=float(sigma), **(world_kwargs or {}))
            g = w.graph
            t = spanning_tree(g, tree)
            unc = edge_uncertainty(g)
            data = cycle_data(g, t, unc=unc)
            if data.n_chords == 0:
                continue
            res = integer_regularization(g, t, search=search, unc=unc, data=data)
            q_true = true_cycle_integers(g, t, w.truth)
            J_true = data.cost(q_true)
            acc["chords"].append(data.n_chords)
            acc["ip_eq_round"].append(res.n_differ == 0)
            acc["ip_eq_true"].append(bool(np.array_equal(res.k_chords, q_true)))
            acc["round_eq_true"].append(bool(np.array_equal(data.k_round, q_true)))
            acc["chords_differ"].append(res.n_differ)
            acc["ip_better"].append(res.objective < res.rounding_objective * (1 - 1e-9))
            acc["gain"].append(res.improvement / max(res.objective, 1e-300))
            acc["J_ip"].append(res.objective)
            acc["J_round"].append(res.rounding_objective)
            acc["J_true"].append(J_true)
            acc["truth_above_ip"].append(J_true > res.objective * (1 + 1e-9))
            acc["time"].append(res.solve_time)
            acc["not_optimal"].append(res.status != "optimal")
            if with_chi2 and res.n_differ:
                c_round, cr_round = _lago_chi2(g, t, data.rounding_edges * TWO_PI + g.delta, unc)
                c_ip, cr_ip = _lago_chi2(g, t, res.delta_reg, unc)
                acc["chi2_ratio"].append(c_round / c_ip)
                acc["refined_ratio"].append(cr_round / cr_ip)
            log.info("sweep σθ=%.3g seed=%s: l=%d, differ=%d, J_ip=%.4g, J_round=%.4g, J_true=%.4g, %.2f s",
                     sigma, seed, data.n_chords, res.n_differ, res.objective, res.rounding_objective, J_true,
                     res.solve_time)
        n = len(acc["chords"])
        mean = (lambda v: float(np.mean(v)) if len(v) else float("nan"))
        rows.append({"sigma_theta": float(sigma), "cases": n, "chords": mean(acc["chords"]),
                     "ip_eq_round": mean(acc["ip_eq_round"]), "ip_eq_true": mean(acc["ip_eq_true"]),
                     "round_eq_true": mean(acc["round_eq_true"]), "chords_differ": mean(acc["chords_differ"]),
                     "ip_better": mean(acc["ip_better"]), "gain": mean(acc["gain"]),
                     "J_ip": mean(acc["J_ip"]), "J_round": mean(acc["J_round"]), "J_true": mean(acc["J_true"]),
                     "truth_above_ip": mean(acc["truth_above_ip"]),
                     "chi2_ratio": mean(acc["chi2_ratio"]), "refined_ratio": mean(acc["refined_ratio"]),
                     "time": mean(acc["time"]), "not_optimal": int(np.sum(acc["not_optimal"]))})
    return rows


def format_integer_sweep(rows: list[dict]) -> str:
    """Markdown table of ``integer_noise_sweep`` rows."""
    head = ("| σθ | cases | chords | IP = round | IP = truth | round = truth | chords IP≠round | IP cheaper | "
            "mean gain | J_IP | J_round | J_truth | J_truth > J_IP | χ² round / χ² IP (where ≠) | "
            "refined χ² round / IP (where ≠) | IP s | not optimal |")
    sep = "|" + "---|" * 17
    lines = [head, sep]
    for r in rows:
        lines.append(
            f"| {r['sigma_theta']:g} | {r['cases']} | {r['chords']:.1f} | {r['ip_eq_round']:.2f} | "
            f"{r['ip_eq_true']:.2f} | {r['round_eq_true']:.2f} | {r['chords_differ']:.2f} | "
            f"{r['ip_better']:.2f} | {r['gain']:.3g} | {r['J_ip']:.4g} | {r['J_round']:.4g} | "
            f"{r['J_true']:.4g} | {r['truth_above_ip']:.2f} | {r['chi2_ratio']:.4g} | {r['refined_ratio']:.4g} | "
            f"{r['time']:.2f} | "
            f"{r['not_optimal']} |")
    return "\n".join(lines)
