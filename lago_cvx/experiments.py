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

``removal_costs`` — how much each loop closure strains the rest of a graph: the leave-one-out change of LAGO's χ²
(lecture 10, ``python benchmarks/run.py separable``).

Beyond one machine. Each sweep is a list of independent trials, one per (σ_θ, seed), and each trial builds
its world from its own seed (never from a generator shared between trials), so its numbers do not
depend on where or in which order it runs. ``n_jobs`` hands the trials to joblib (``run_trials``):
``n_jobs=None`` or 1 runs them here, one after another, without importing joblib; ``n_jobs=2`` or ``-1``
runs them in worker processes (joblib's default backend, loky) — or on whatever backend is active, so
the same call runs on a Dask cluster inside ``joblib.parallel_config(backend="dask")`` (``docs/parallel.md``).
The rows are then aggregated here in trial order; every number except the wall-clock fields (``seconds``,
``time``) is identical whatever the backend (``tests/test_parallel.py``).
"""

from __future__ import annotations

import logging
import time
from typing import Callable, Iterable

import numpy as np

from .graph import connected_components
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

__all__ = ["DEFAULT_REGULARIZERS", "true_cycle_integers", "run_trials", "rotation_noise_sweep", "format_sweep",
           "integer_noise_sweep", "format_integer_sweep", "removal_costs"]

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


def run_trials(fn: Callable, tasks: list, *, n_jobs: int | None = None, progress: Callable | None = None) -> list:
    """``[fn(*task) for task in tasks]``, in the order of ``tasks``.

    ``n_jobs`` None or 1: here, one after another (joblib not needed). Otherwise ``joblib.Parallel(n_jobs)``
    on the active backend (loky processes by default; a Dask cluster inside
    ``joblib.parallel_config(backend="dask")``); ``fn`` and the tasks must then pickle (module-level
    functions, plain data). ``progress(done, total)`` is called as results arrive. Raises
    ``MissingSolverError`` (an ImportError) naming the extra when joblib is absent."""
    total = len(tasks)
    if n_jobs is None or n_jobs == 1:
        out = []
        for task in tasks:
            out.append(fn(*task))
            if progress is not None:
                progress(len(out), total)
        return out
    try:
        import joblib
    except ImportError:
        from .errors import MissingSolverError

        raise MissingSolverError(f"n_jobs={n_jobs} runs the trials through joblib, which is not installed: "
                                 "pip install joblib, or lago-cvx[dask] for a Dask cluster") from None
    gen = joblib.Parallel(n_jobs=n_jobs, return_as="generator")(joblib.delayed(fn)(*task) for task in tasks)
    out = []
    for value in gen:
        out.append(value)
        if progress is not None:
            progress(len(out), total)
    return out


def _rotation_trial(sigma: float, seed: int, n_poses: int, regularizers: dict, tolerance: float,
                    max_iterations: int, world: Callable, world_kwargs: dict) -> dict:
    """One trial of ``rotation_noise_sweep`` (module docstring, steps 1–3): ``{name: (optimal,
    correct_integers, ambiguous, χ²_GN / χ²_ref, seconds)}``. The world is built from ``seed`` alone."""
    w = world(n_poses, seed=seed, sigma_theta=sigma, **world_kwargs)
    g = w.graph
    ref = refine(g, w.truth, max_iterations=max_iterations).chi2
    out = {}
    for name, kw in regularizers.items():
        t = time.perf_counter()
        res = lago(g, **kw)
        gn = refine(g, res.poses, max_iterations=max_iterations)
        seconds = time.perf_counter() - t
        reg = res.regularization
        out[name] = (int(gn.chi2 <= ref * (1.0 + tolerance)),
                     int(np.array_equal(reg.cycle_k, true_cycle_integers(g, res.tree, w.truth))),
                     int(reg.ambiguous.size), float(gn.chi2 / ref), seconds)
    log.info("sweep: σ_θ = %g, seed %d done", sigma, seed)
    return out


def rotation_noise_sweep(sigmas: Iterable[float], *, seeds: Iterable[int] = range(8), n_poses: int = 300,
                         regularizers: dict | None = None, tolerance: float = 1e-6, max_iterations: int = 100,
                         world: Callable = manhattan_world, progress: Callable | None = None,
                         n_jobs: int | None = None, **world_kwargs) -> list[dict]:
    """Run the sweep described in the module docstring.

    sigmas — rotation noise levels σ_θ (rad); seeds — world seeds (one trial each); n_poses — poses per
    world; regularizers — ``{name: lago keyword arguments}`` (default ``DEFAULT_REGULARIZERS``);
    tolerance — relative χ² tolerance of "reached the reference optimum"; world — the generator
    (called as ``world(n_poses, seed=..., sigma_theta=..., **world_kwargs)``); progress — optional
    callback ``progress(done, total)``; n_jobs — where the trials run (``run_trials``: None or 1 here,
    else joblib, on a Dask cluster under ``joblib.parallel_config(backend="dask")``).

    Returns one dict per (σ_θ, regularizer): ``sigma_theta``, ``regularizer``, ``trials``,
    ``optimal`` (trials whose GN reached χ²_ref), ``correct_integers`` (trials whose cycle integers
    equal the true ones), ``ambiguous`` (mean number of ambiguous chords/edges reported),
    ``chi2_ratio_median`` (median of χ²_GN / χ²_ref), ``seconds`` (wall clock, summed over trials)."""
    regularizers = dict(DEFAULT_REGULARIZERS if regularizers is None else regularizers)
    sigmas, seeds = [float(s) for s in sigmas], [int(s) for s in seeds]
    tasks = [(sigma, seed, n_poses, regularizers, tolerance, max_iterations, world, world_kwargs)
             for sigma in sigmas for seed in seeds]
    trials = iter(run_trials(_rotation_trial, tasks, n_jobs=n_jobs, progress=progress))
    rows = []
    for sigma in sigmas:
        per = [next(trials) for _ in seeds]
        for name in regularizers:
            vals = [t[name] for t in per]
            ratios = [v[3] for v in vals]
            rows.append({"sigma_theta": sigma, "regularizer": name, "trials": len(seeds),
                         "optimal": sum(v[0] for v in vals), "correct_integers": sum(v[1] for v in vals),
                         "ambiguous": sum(v[2] for v in vals) / max(len(seeds), 1),
                         "chi2_ratio_median": float(np.median(ratios)) if ratios else float("nan"),
                         "seconds": sum(v[4] for v in vals)})
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


_INTEGER_KEYS = ("chords", "ip_eq_round", "ip_eq_true", "round_eq_true", "chords_differ", "ip_better", "gain",
                 "J_ip", "J_round", "J_true", "truth_above_ip", "chi2_ratio", "refined_ratio", "time", "not_optimal")


def _integer_trial(sigma: float, seed: int, n_poses: int, world: str, tree: str, search: IntegerSearch,
                   world_kwargs: dict, with_chi2: bool) -> dict | None:
    """One trial of ``integer_noise_sweep``: ``{key: value}`` (keys ``_INTEGER_KEYS``; ``chi2_ratio``,
    ``refined_ratio`` absent where IP and rounding agree), None when the world has no chords. The world
    is built from ``seed`` alone."""
    from .graph import spanning_tree

    gen = {"manhattan": manhattan_world, "circle": circle_world}[world]
    w = gen(n_poses, seed=int(seed), sigma_theta=float(sigma), **(world_kwargs or {}))
    g = w.graph
    t = spanning_tree(g, tree)
    unc = edge_uncertainty(g)
    data = cycle_data(g, t, unc=unc)
    if data.n_chords == 0:
        return None
    res = integer_regularization(g, t, search=search, unc=unc, data=data)
    q_true = true_cycle_integers(g, t, w.truth)
    J_true = data.cost(q_true)
    out = {"chords": data.n_chords, "ip_eq_round": res.n_differ == 0,
           "ip_eq_true": bool(np.array_equal(res.k_chords, q_true)),
           "round_eq_true": bool(np.array_equal(data.k_round, q_true)), "chords_differ": res.n_differ,
           "ip_better": res.objective < res.rounding_objective * (1 - 1e-9),
           "gain": res.improvement / max(res.objective, 1e-300), "J_ip": res.objective,
           "J_round": res.rounding_objective, "J_true": J_true, "truth_above_ip": J_true > res.objective * (1 + 1e-9),
           "time": res.solve_time, "not_optimal": res.status != "optimal"}
    if with_chi2 and res.n_differ:
        c_round, cr_round = _lago_chi2(g, t, data.rounding_edges * TWO_PI + g.delta, unc)
        c_ip, cr_ip = _lago_chi2(g, t, res.delta_reg, unc)
        out["chi2_ratio"] = c_round / c_ip
        out["refined_ratio"] = cr_round / cr_ip
    log.info("sweep σθ=%.3g seed=%s: l=%d, differ=%d, J_ip=%.4g, J_round=%.4g, J_true=%.4g, %.2f s",
             sigma, seed, data.n_chords, res.n_differ, res.objective, res.rounding_objective, J_true, res.solve_time)
    return out


def integer_noise_sweep(*, sigmas=(0.01, 0.05, 0.1, 0.15, 0.2, 0.3), seeds=range(5), n_poses: int = 100,
                        world: str = "manhattan", tree: str = "bfs", search: IntegerSearch | None = None,
                        world_kwargs: dict | None = None, with_chi2: bool = True,
                        n_jobs: int | None = None) -> list[dict]:
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
      rounding's start lands in a worse local minimum), ``time`` (mean solver seconds), ``not_optimal`` (count).
    ``n_jobs`` — where the trials run (``run_trials``)."""
    from .errors import OptionError

    search = IntegerSearch(solver="enumerate") if search is None else search
    if world not in ("manhattan", "circle"):
        raise OptionError(f"unknown world {world!r}; expected 'manhattan' or 'circle'")
    sigmas, seeds = [float(s) for s in sigmas], [int(s) for s in seeds]
    tasks = [(sigma, seed, n_poses, world, tree, search, world_kwargs, with_chi2) for sigma in sigmas for seed in seeds]
    trials = iter(run_trials(_integer_trial, tasks, n_jobs=n_jobs))
    rows = []
    for sigma in sigmas:
        acc = {k: [] for k in _INTEGER_KEYS}
        for _ in seeds:
            trial = next(trials)
            for k, v in (trial or {}).items():
                acc[k].append(v)
        n = len(acc["chords"])
        mean = (lambda v: float(np.mean(v)) if len(v) else float("nan"))
        rows.append({"sigma_theta": float(sigma), "cases": n, **{k: mean(acc[k]) for k in _INTEGER_KEYS[:-1]},
                     "not_optimal": int(np.sum(acc["not_optimal"]))})
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


def removal_costs(graph: PoseGraph, *, progress: Callable | None = None) -> np.ndarray:
    """Δχ²_k = χ²(graph) − χ²(graph without edge k) for every loop closure k, χ² of LAGO's estimate (each edge's
    leave-one-out cost change: what keeping it costs the rest); NaN for the odometric edges and for a loop closure
    whose removal disconnects the graph. Shape (m,); one LAGO run per loop closure. A test that rejects loop closures
    by their Δχ², at any threshold, cannot reject one without rejecting every one whose Δχ² is larger; the truncated
    cost Σ min(r², c̄²) is such a test for one edge at a time (rejecting edge k lowers it when Δχ²_k > c̄², up to
    LAGO's approximation of the minimum). ``progress``: called with (done, total) after each run."""
    base = lago(graph).chi2
    out = np.full(graph.n_edges, np.nan)
    loops = np.flatnonzero(~graph.is_odometric)
    for i, k in enumerate(loops):
        keep = np.ones(graph.n_edges, bool)
        keep[k] = False
        if connected_components(sub := graph.subgraph_edges(keep))[0] == 1:
            out[k] = base - lago(sub).chi2
        if progress is not None:
            progress(i + 1, loops.size)
    return out
