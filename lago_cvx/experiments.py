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
"""

from __future__ import annotations

import logging
import time
from typing import Callable, Iterable

import numpy as np

from .lago import lago
from .posegraph import PoseGraph
from .refine import refine
from .synthetic import manhattan_world

__all__ = ["DEFAULT_REGULARIZERS", "true_cycle_integers", "rotation_noise_sweep", "format_sweep"]

log = logging.getLogger(__name__)

#: name → keyword arguments of ``lago`` (the regularizers compared by default).
DEFAULT_REGULARIZERS = {
    "tree (bfs)": {"spanning_tree": "bfs"},
    "tree (odometry)": {"spanning_tree": "odometry"},
    "chordal": {"regularization": "chordal"},
}


def true_cycle_integers(graph: PoseGraph, tree, truth: np.ndarray) -> np.ndarray:
    """Cycle integers (l,) implied by the true orientations: with k_e = round((θ_j − θ_i − δ_e)/2π) for
    every edge, C k = k[chords] − (tree path sums of k)[chords] (C = [I B], Corollary 2)."""
    th = np.asarray(truth, dtype=float)[:, 2]
    k = np.rint((th[graph.heads] - th[graph.tails] - graph.delta) / (2.0 * np.pi))
    return np.rint(k[tree.chords] - tree.path_sums(graph, k)[tree.chords]).astype(np.int64)


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
