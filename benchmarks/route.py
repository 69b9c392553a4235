"""Section ``route`` of ``python benchmarks/run.py``: which route the CLI and ``lago()`` take by default.

Candidates: the 2kπ regularization (tree rounding on the BFS tree, or the chordal regularizer) × the
positions (phase 3's, or re-solved: ``positions="resolve"``), with full information. For every dataset
and for synthetic Manhattan worlds with rising rotation noise (σ_θ up to 0.2 rad), each candidate's
χ² alone and after Gauss–Newton (``lago-cvx solve --refine``), relative to the optimum (datasets: the
reference minimum; synthetic: Gauss–Newton from the ground truth). The rule (issue "Trustworthy
command line"): the default is the route that after refinement is within 1 % of the optimum everywhere.
The seed's route (odometric tree, tree rounding, marginal information, phase-3 poses) is listed for
comparison.
"""

from __future__ import annotations

import numpy as np

import _bench
from lago_cvx import lago, manhattan_world, refine
from lago_cvx.datasets import REFERENCE_CHI2
from lago_cvx.errors import GraphError

CANDIDATES = {
    "tree/phase3": {"regularization": "tree", "positions": "phase3"},
    "tree/resolve": {"regularization": "tree", "positions": "resolve"},
    "chordal/phase3": {"regularization": "chordal", "positions": "phase3"},
    "chordal/resolve (default)": {"regularization": "chordal", "positions": "resolve"},
    "seed": {"route": "seed"},
}
SIGMAS = (0.02, 0.05, 0.1, 0.15, 0.2)
SIZES = (500, 1000, 3500)


def add_arguments(group) -> None:
    group.add_argument("--route-seeds", type=int, default=3, help="synthetic worlds per (size, σ_θ) (default 3)")


def _ratios(g, best):
    """{candidate: (χ²(LAGO)/best, χ²(GN from LAGO)/best)}; None where the route does not apply."""
    out = {}
    for name, kw in CANDIDATES.items():
        try:
            res = lago(g, **kw)
        except GraphError:  # the seed's odometric tree needs a complete odometric chain
            out[name] = None
            continue
        out[name] = (res.chi2 / best, refine(g, res.poses, max_iterations=100).chi2 / best)
    return out


def _cell(r):
    return "–" if r is None else f"{r[0]:.3f} → {r[1]:.4f}"


def run(args) -> str:
    out = ["# The default route", "",
           "Cells: χ²(LAGO)/optimum → χ²(Gauss–Newton from LAGO)/optimum; full information except `seed`.", ""]
    worst = {name: 1.0 for name in CANDIDATES}
    skipped = _bench.datasets_skipped()
    if skipped:
        out += [skipped, ""]
    else:
        rows = []
        for rel, g in _bench.each_dataset([f for f in _bench.FILES if f in REFERENCE_CHI2]):
            r = _ratios(g, REFERENCE_CHI2[rel])
            for name, v in r.items():
                if v is not None:
                    worst[name] = max(worst[name], v[1])
            rows.append([rel, *(_cell(r[name]) for name in CANDIDATES)])
            print(" | ".join(rows[-1]), flush=True)
        out += ["## Public datasets", "", _bench.table(["file", *CANDIDATES], rows), ""]
    seeds = range(1 if args.quick else args.route_seeds)
    sizes = SIZES[:2] if args.quick else SIZES
    rows = []
    for n in sizes:
        for sigma in SIGMAS:
            acc = {name: [] for name in CANDIDATES}
            for seed in seeds:
                w = manhattan_world(n, seed=seed, sigma_theta=sigma)
                best = refine(w.graph, w.truth, max_iterations=100).chi2
                for name, v in _ratios(w.graph, best).items():
                    if v is not None:
                        acc[name].append(v)
                        worst[name] = max(worst[name], v[1])
            rows.append([str(n), f"{sigma:g}", *(
                "–" if not acc[name] else
                f"{np.median([a for a, _ in acc[name]]):.3f} → max {max(b for _, b in acc[name]):.4f}"
                for name in CANDIDATES)])
            print(" | ".join(rows[-1]), flush=True)
    out += ["## Manhattan worlds with rising rotation noise", "",
            f"seeds 0–{len(seeds) - 1} per row; cells: median χ²(LAGO)/optimum → worst χ²(GN)/optimum; the "
            "optimum is Gauss–Newton from the ground truth.", "",
            _bench.table(["poses", "σ_θ (rad)", *CANDIDATES], rows), "",
            "## Worst χ²(GN from LAGO)/optimum over everything above", "",
            _bench.table(["route", "worst after refinement", "within 1 % everywhere"],
                         [[name, f"{v:.4f}", "yes" if v <= 1.01 else "no"] for name, v in worst.items()])]
    return "\n".join(out)
