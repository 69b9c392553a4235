"""Section ``separable`` of ``python benchmarks/run.py``: can any threshold reject the false loop closures that
robust LAGO keeps, without rejecting true ones?

Robust LAGO (``lago(graph, robust=True)``: GNC with truncated least squares and the local search) keeps a false
loop closure when the truncated cost Σ_k min(r_k², c̄²) prefers it (section ``robust``: "the objective"). Every
test of one edge against the rest of the graph — a residual quantile, a threshold c̄² of any size, the cost change
on removal — sees that edge through how much it strains the others. This section measures that strain for the
false edges kept and for the true loop closures beside them.

Protocol. intel, M3500, CSAIL and MIT (``lago_cvx.synthetic.add_false_loop_closures``, as in ``robust``) at 10 % and
30 % false loop closures, seeds 0 to ``--separable-seeds`` − 1 (default 6: the three of ``robust`` and three
more). For each run:

* the default robust run, scored as in ``robust``: pass = every false edge rejected, at most 1 % of the true edges
  rejected, χ² of the clean edges after ``refine`` on the accepted edges within 0.1 % of the clean refined χ²;
* where it keeps a false edge and rejects no true one, on its accepted graph A: the leave-one-out cost change of
  every loop closure k, Δχ²_k = χ²(A) − χ²(A without k), χ² of LAGO's estimate
  (``lago_cvx.experiments.removal_costs``).
  The run is **separable** when every kept false edge's Δχ² exceeds every true loop closure's: then "reject the
  loop closures with Δχ² above t" removes the false edges and keeps the true ones for t in the window between.
  It is **not separable** when a kept false edge strains the graph less than some true loop closure does: any such
  test that rejects it rejects those true edges too (the column counts them);
* the same graph with ``RobustSettings(calibrate=κ)``, κ = ``--separable-kappa`` (default 4.7): GNC again at a
  per-file threshold from the trusted odometry, c̄² = min(11.34, κ · max r² of the odometric edges at the default
  run's estimate), and of the two classifications the one of the lower truncated cost at that c̄² kept
  (``lago_cvx.variants.calibrated``; on seeds 0–2 the κ that would fix every run whose false edges are separable is
  about 4.45–4.90). The column "c̄² calibrated" is the c̄² of the run kept ("–": the default run was kept, or GNC
  did not run).

The false edges are random (any rotation, 20 m box): a few land where the graph's own loop closures disagree by as
much, so they fit as well as true measurements do. Which ones is a matter of the seed.
"""

from __future__ import annotations

import time

import numpy as np

import _bench
from lago_cvx import lago, refine
from lago_cvx.experiments import removal_costs
from lago_cvx.metrics import chi2
from lago_cvx.synthetic import add_false_loop_closures
from lago_cvx.variants import RobustSettings

FILES = ("se-sync/intel.g2o", "carlone/input_M3500_g2o.g2o", "se-sync/CSAIL.g2o", "se-sync/MIT.g2o")
QUICK_FILES = ("se-sync/intel.g2o",)
FRACTIONS = (0.1, 0.3)
PASS_RATIO = 1.001
HEAD = ["file", "false edges", "seed", "default: false kept / true rejected", "χ² ratio", "pass",
        "kept false Δχ²", "true loop closures' largest Δχ²", "true loop closures with Δχ² ≥ a kept false edge's",
        "verdict", "c̄² calibrated", "calibrated: false kept / true rejected", "its χ² ratio", "its pass"]


def add_arguments(group) -> None:
    group.add_argument("--separable-seeds", type=int, default=6, metavar="N",
                       help="separable section: seeds 0..N-1 per file and fraction (default 6)")
    group.add_argument("--separable-kappa", type=float, default=4.7, metavar="K",
                       help="separable section: RobustSettings(calibrate=K) beside the default (default 4.7)")


def verdict(d_true: np.ndarray, d_false: np.ndarray) -> tuple[str, int]:
    """("separable" / "not separable", the number of true loop closures whose Δχ² is at least the smallest kept
    false edge's) from the Δχ² of the true loop closures and of the kept false edges."""
    above = int(np.sum(d_true >= d_false.min()))
    return ("not separable" if above else "separable"), above


def score(graph, idx, res, clean_chi2) -> tuple[int, int, float, bool]:
    """(false kept, true rejected, χ² of the clean edges after refine / clean refined χ², pass) of a robust run."""
    rejected = set(res.rejected_edges.tolist())
    kept_false = len(set(idx.tolist()) - rejected)
    wrong = len(rejected - set(idx.tolist()))
    ratio = chi2(graph, refine(res.graph, res.poses).poses) / clean_chi2
    return kept_false, wrong, ratio, kept_false == 0 and wrong <= 0.01 * graph.n_edges and ratio <= PASS_RATIO


def run(args) -> str:
    title = "# Which kept false loop closures a threshold could reject"
    skipped, files, fractions, seeds = _bench.corrupted_plan(args, FILES, QUICK_FILES, FRACTIONS, args.separable_seeds)
    if skipped:
        return f"{title}\n\n{skipped}"
    rows, tally = [], {}
    for rel, graph in _bench.each_dataset(files):
        clean_chi2 = refine(graph, lago(graph).poses).chi2
        for fraction in fractions:
            for seed in seeds:
                t = time.perf_counter()
                go, idx = add_false_loop_closures(graph, fraction, seed=seed)
                res = lago(go, robust=True)
                kept, wrong, ratio, ok = score(graph, idx, res, clean_chi2)
                d_false_s = d_true_max = above_s = "–"
                kind = "pass" if ok else "true edges rejected" if wrong else "false kept" if kept else "χ² ratio"
                if kept and not wrong:
                    d = removal_costs(res.graph)
                    acc = np.setdiff1d(np.arange(go.n_edges), res.rejected_edges)  # A's edges, in go's numbering
                    false_in_a = np.isin(acc, idx)
                    true_lc = ~res.graph.is_odometric & ~false_in_a
                    d_false = d[false_in_a]
                    kind, above = verdict(d[true_lc], d_false)
                    d_false_s = ", ".join(f"{x:.3g}" for x in np.sort(d_false))
                    d_true_max, above_s = f"{np.nanmax(d[true_lc]):.3g}", above
                cal = lago(go, robust=RobustSettings(calibrate=args.separable_kappa))
                c2 = cal.settings.c2 if cal.settings.threshold is not None else float("nan")
                kept_c, wrong_c, ratio_c, ok_c = score(graph, idx, cal, clean_chi2)
                rows.append([rel, f"{idx.size} ({fraction:.0%})", seed, f"{kept} / {wrong}", f"{ratio:.4g}",
                             "yes" if ok else "no", d_false_s, d_true_max, above_s, kind, _bench.fmt(c2, ".3g"),
                             f"{kept_c} / {wrong_c}", f"{ratio_c:.4g}", "yes" if ok_c else "no"])
                tally.setdefault(rel, []).append((ok, ok_c, kind))
                print(" | ".join(map(str, rows[-1])) + f"  ({time.perf_counter() - t:.1f} s)", flush=True)
    summary = [[rel, len(v), sum(a for a, _, _ in v), sum(b for _, b, _ in v),
                sum(k == "separable" for _, _, k in v), sum(k == "not separable" for _, _, k in v),
                sum(k == "true edges rejected" for _, _, k in v)] for rel, v in tally.items()]
    return "\n".join([
        title, "", __doc__.split("\n\n", 1)[1].strip(), "",
        "## Summary per file", "",
        _bench.table(["file", "runs", "default passes", f"calibrate={args.separable_kappa:g} passes",
                      "default keeps a false edge: separable", "… not separable", "default rejects true edges"],
                     summary),
        "", "## Every run", "", _bench.table(HEAD, rows)])
