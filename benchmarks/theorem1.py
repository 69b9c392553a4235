"""Section ``theorem1`` of ``python benchmarks/run.py``: Theorem 1 measured on every dataset, and the
first-order optimality of the full-information phases.

For each file (``lago_cvx.theorem1``; the seed's phases — tree rounding on the BFS tree,
blkdiag(P_Δ, P_δ) — unless ``--theorem1-information full``): χ² of eq. (3) at the sub-optimal estimate
x̂ = [p̂ (eq. (14)); θ̂ (eq. (13))], at phase 3's x* = x̂ + [ρ̃; δ̃] (eqs. (15)–(17)), with the positions
re-solved exactly for θ*, and at the package's default LAGO (guarded polish); the reference minimum and
the relative error of the identity x* − x̂ = [ρ̃; δ̃]. Then, on random graphs with full 3×3 information,
χ²(LAGO)/χ²(min) − 1 with the same standardized noise at σ, σ/10, σ/100: full information against the
seed's marginal split.
"""

from __future__ import annotations

import _bench
from lago_cvx import lago, random_graph, refine
from lago_cvx.datasets import REFERENCE_CHI2
from lago_cvx.theorem1 import theorem1

HEAD = ["file", "χ²(x̂)", "χ²(x*) phase 3", "χ² positions for θ*", "χ² LAGO default", "χ² min",
        "x̂ / min", "x* / min", "resolved / min", "default / min", "identity error"]


def add_arguments(group) -> None:
    group.add_argument("--theorem1-information", default="marginal", choices=["marginal", "full"],
                       help="phases 2–3 of the measured LAGO (default marginal: the seed's)")


def dataset_table(information: str) -> str:
    rows = []
    for rel, g in _bench.each_dataset([f for f in _bench.FILES if f in REFERENCE_CHI2]):
        t = theorem1(g, regularization="tree", information=information)
        default = lago(g).chi2
        ref = REFERENCE_CHI2[rel]
        rows.append([rel, _bench.fmt(t.chi2_suboptimal), _bench.fmt(t.chi2_phase3), _bench.fmt(t.chi2_resolved),
                     _bench.fmt(default), ref, f"{t.chi2_suboptimal / ref:.3f}", f"{t.chi2_phase3 / ref:.3f}",
                     f"{t.chi2_resolved / ref:.4f}", f"{default / ref:.4f}", f"{t.identity_error:.1e}"])
        print(" | ".join(map(str, rows[-1])), flush=True)
    return _bench.table(HEAD, rows)


def first_order_table(seeds) -> str:
    scales = (1.0, 0.1, 0.01)
    rows = []
    for seed in seeds:
        cells = {"full": [], "marginal": []}
        for s in scales:
            w = random_graph(30, 70, seed=seed, information="full", sigma_xy=0.05 * s, sigma_theta=0.02 * s)
            best = refine(w.graph, w.truth, tolerance=1e-14, max_iterations=100).chi2
            for info in cells:
                cells[info].append(lago(w.graph, information=info, positions="phase3").chi2 / best - 1.0)
        rows.append([str(seed), *(f"{v:.2e}" for v in cells["full"]), *(f"{v:.2e}" for v in cells["marginal"])])
    head = ["seed", *(f"full, σ×{s:g}" for s in scales), *(f"marginal, σ×{s:g}" for s in scales)]
    return _bench.table(head, rows)


def run(args) -> str:
    out = ["# Theorem 1 measured", ""]
    skipped = _bench.datasets_skipped()
    if skipped:
        out += [skipped, ""]
    else:
        out += [f"LAGO with the tree rounding on the BFS tree and {args.theorem1_information} information "
                "(phases 2–3); χ² in each file's own cost (`lago_cvx.conventions`); minima from `lago_cvx.datasets.REFERENCE_CHI2`.", "",
                dataset_table(args.theorem1_information), "",
                "The identity x* = x̂ + [ρ̃; δ̃] of eqs. (16)–(17) holds to rounding on every file. The claim "
                "that phase 3 moves x̂ towards a minimum does not always: on both INTEL files and MIT χ²(x*) is "
                "many times χ²(x̂) (on CSAIL, in g2o's cost, it holds). Re-solving the positions for θ* "
                "(`lago_cvx.positions`) undoes it; the default route's guarded polish would keep θ̂ + α(θ* − θ̂) "
                "with the smallest χ² it tried, and keeps α = 1 on every file here.", ""]
    seeds = range(2 if args.quick else 5)
    out += ["## Full information is first-order optimal", "",
            "random_graph(30, 70, information='full'), σ_xy = 0.05·s, σ_θ = 0.02·s with the same standardized "
            "noise: χ²(LAGO, phase-3 poses)/χ²(min) − 1 (min: Gauss–Newton from the truth).", "",
            first_order_table(seeds), "",
            "With full information the excess falls like s² (first-order optimal); with the seed's marginal "
            "split it stays O(1)."]
    return "\n".join(out)
