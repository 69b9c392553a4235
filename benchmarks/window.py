"""Section ``window`` of ``python benchmarks/run.py``: the truncations c̄² at which robust LAGO passes each 3-D file
with false loop closures, and where the χ² quantile lies among them.

The default truncation c̄² = χ²₆(0.99) = 16.81 reads each edge's information as the inverse covariance of its
noise: at the clean optimum the χ² per residual degree of freedom, χ² / (6 (m − n + 1)), is then near 1. A file
whose information is loose for its residuals (that ratio ≪ 1) leaves room for a false loop closure to bend the
estimate and fit below c̄²; the truncated cost then prefers keeping it ("the objective's choice" of ``robust``'s
3-D tables), and no search of that objective rejects it.

For each 3-D file (sphere2500, torus3D, parking-garage, smallGrid3D) with 10 % false loop closures (the protocol of
``robust``'s 3-D tables, seeds 0–2), robust LAGO runs at every c̄² of ``C2S`` (``RobustSettings(threshold=c̄²)``,
``lago-cvx solve F --robust --robust-threshold C2``), including χ²₆(0.99) and χ²₆(0.999). Each run is scored as
there: false loop closures kept, true edges rejected, χ² of the file's clean edges after ``refine3d`` on the
accepted edges over the clean refined χ², pass (every false edge rejected, at most 1 % of the true edges, ratio
≤ 1.001). Per file: the clean χ² per residual degree of freedom, the largest r² of a true edge at the clean
optimum, and the window, the c̄² of the grid at which every seed passes.

The window is measured against the truth, which a user does not have: it says which truncation the file's own
information calls for, not how to find it. ``--window-files`` chooses the files.
"""

from __future__ import annotations

import numpy as np

import _bench
import robust3d
from lago_cvx.variants import RobustSettings
from lago_cvx.variants.gnc import edge_r2

QUANTILES = {RobustSettings(confidence=c).c2_for(3): f"χ²₆({c:g})" for c in (0.99, 0.999)}
C2S = (0.02, 0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, *QUANTILES, 32.0, 64.0)
QUICK_FILES, QUICK_C2S = ("se-sync-3d/smallGrid3D.g2o",), (4.0, min(QUANTILES))


def add_arguments(group) -> None:
    group.add_argument("--window-files", nargs="+", default=list(robust3d.FILES3D), metavar="FILE",
                       help="window section: the 3-D files (default sphere2500, torus3D, parking-garage, smallGrid3D)")


def label(c2: float) -> str:
    """c̄² as printed, the χ² quantiles named."""
    return f"{c2:.2f} ({QUANTILES[c2]})" if c2 in QUANTILES else f"{c2:g}"


def window(passing: list) -> str:
    """The passing c̄² of the grid as ranges of consecutive grid values ("–" for none)."""
    runs, cur = [], []
    for c2, ok in passing:
        if ok:
            cur.append(c2)
        elif cur:
            runs.append(cur)
            cur = []
    runs += [cur] if cur else []
    return ", ".join(f"{label(r[0])} – {label(r[-1])}" if len(r) > 1 else label(r[0]) for r in runs) or "–"


def run(args) -> str:
    title = "# The truncation c̄² at which robust LAGO passes each 3-D file"
    skipped = _bench.datasets_skipped()
    if skipped:
        return f"{title}\n\n{skipped}"
    files, c2s = (QUICK_FILES, QUICK_C2S) if args.quick else (args.window_files, C2S)
    rows, summary = [], []
    for rel, graph, clean in robust3d._graphs(files):
        bad = [robust3d.corrupted(graph, seed, clean) for seed in robust3d.SEEDS]
        per_dof = clean.chi2 / (6 * (graph.n_edges - graph.n_poses + 1))
        r2_max = float(edge_r2(graph, (clean.t, clean.R)).max())
        passing = []
        for c2 in c2s:
            runs = [robust3d.one_run(graph, clean, b, RobustSettings(threshold=c2), why=False) for b in bad]
            passing.append((c2, all(r["ok"] for r in runs)))
            rows.append([rel, label(c2), *(f"{round((1 - r['recall']) * r['n_false'])} / {r['wrong']} / "
                                           f"{r['ratio']:.4g}" for r in runs),
                         f"{sum(r['ok'] for r in runs)} of {len(runs)}",
                         f"{np.median([r['seconds'] for r in runs]):.2f}"])
            print(" | ".join(map(str, rows[-1])), flush=True)
        summary.append([rel, f"{bad[0]['outliers'].size} (10%)", f"{per_dof:.3g}", f"{r2_max:.3g}", window(passing),
                        "yes" if dict(passing).get(min(QUANTILES)) else "no"])
    seeds = robust3d.SEEDS
    head = ["file", "c̄²", *(f"seed {s}: false kept / true rejected / χ² ratio" for s in seeds), "passing",
            "median time [s]"]
    return "\n".join([
        title, "", __doc__.split("\n\n", 1)[1].strip(), "",
        "## Summary", "",
        _bench.table(["file", "false edges", "clean χ² per residual dof", "largest true r² at the clean optimum",
                      "c̄² passing every seed", "χ²₆(0.99) passes"], summary),
        "", "## Every c̄²", "",
        f"Seeds {seeds[0]}–{seeds[-1]}; each cell: false loop closures kept / true edges rejected / χ² of the "
        "clean edges after the refinement over the clean refined χ².", "",
        _bench.table(head, rows)])
