"""Section ``robust`` of ``python benchmarks/run.py``: false loop closures on real graphs, rejected by
graduated non-convexity around weighted LAGO runs (``lago(graph, robust=True)``, ``lago_cvx.variants.gnc``).

Protocol (``lago_cvx.synthetic.add_false_loop_closures``): ⌊fraction · m⌋ false loop closures appended to the
file's m edges — random pairs of poses (never consecutive ids), a relative pose drawn uniformly (translation
in a 20 m square, any rotation), the information of a real edge — for fractions 10 % and 30 % and seeds 0–2
(``--robust-city``: city10000 too, at 10 % and 30 %, seed 0).
For each corrupted graph:

* precision and recall of the rejected edges (recall: false edges rejected / false edges; precision: false
  edges among the rejected), and the number of true edges rejected;
* ATE [m] (RMS position error after the best rigid alignment) of plain LAGO on the corrupted graph and of the
  robust estimate refined on its accepted edges (Gauss–Newton, as ``lago-cvx solve --robust --refine``),
  both against the clean solution: LAGO on the file's edges refined by Gauss–Newton;
* χ² of the file's own (clean) edges at that refined robust estimate, divided by the clean refined χ²
  (1 when the clean optimum is recovered);
* the truncated cost Σ_k min(r_k², c̄²) over every edge of the corrupted graph at that refined estimate, minus the
  same at the clean solution: below 0, the clean solution is not the minimum of the objective GNC minimizes (a
  false edge that fits, or true ones that do not), and no solver of that objective returns it; above 0, the
  search ended above the clean solution's cost (each failing run of the sweep says which);
* seconds of the robust run (GNC, every inner LAGO and the final one);
* pass: every false edge rejected, at most 1 % of the true edges rejected, and χ² of the clean edges after
  the refinement within 0.1 % of the clean refined χ² (the three targets together).

``--robust-sweep`` raises the fraction (2 %, 5 %, 10 %, 20 %, 30 %, 40 %, 50 %; seeds 0–2, c̄² = 11.34) on each file
until a run fails: the fraction at which robust LAGO first fails. ``--robust-best`` adds the rows of
``RobustSettings(start="best")``: GNC from the unweighted LAGO and from the odometry with a maximum clique of
pairwise-consistent loop closures (PCM), the result of the lower truncated cost kept.

``--robust-gtsam`` also runs GTSAM's GNC (``../shared/bench/gtsam_gnc.py``: GTSAM's LAGO, then GncLMOptimizer
with truncated least squares and the odometric edges as known inliers) once on each file of
``--robust-gtsam-files`` at 10 %, seed 0 (on the files of ``--robust-gtsam-every``: at every fraction and seed of the
table), as a whole process on the same written graph, beside the whole process of ours on it
(``python -m lago_cvx solve IN --robust --refine -o OUT``).

``--robust-3d`` adds the 3-D files (``robust3d``: sphere2500, torus3D, parking-garage, smallGrid3D at 10 %, seeds
0–2, each at the confidences of ``--robust-3d-confidence`` (default 0.99 and 0.999), GTSAM's GNC on
``--robust-3d-gtsam-seeds``); ``--robust-3d-only`` runs only them and keeps the planar tables of the existing result
file.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import _bench
import robust3d
from lago_cvx import lago, refine
from lago_cvx.io import read_graph, write_graph
from lago_cvx.metrics import ate, chi2
from lago_cvx.synthetic import add_false_loop_closures
from lago_cvx.variants import RobustSettings

FILES = ("se-sync/intel.g2o", "carlone/input_M3500_g2o.g2o", "se-sync/CSAIL.g2o", "se-sync/MIT.g2o")
CITY = "se-sync/city10000.g2o"
QUICK_FILES = ("se-sync/MIT.g2o", "se-sync/intel.g2o")
FRACTIONS = (0.1, 0.3)
SWEEP = robust3d.SWEEP
SEEDS = (0, 1, 2)
GTSAM_SCRIPT = _bench.HERE.parent.parent / "shared" / "bench" / "gtsam_gnc.py"
GTSAM_FILES = ("se-sync/intel.g2o", "carlone/input_M3500_g2o.g2o", "se-sync/CSAIL.g2o", "se-sync/MIT.g2o")

#: The truncations compared: the default (χ²₃ quantile at 0.99) and GTSAM's default inlier threshold
#: (GncParams barcSq = 1 on GTSAM's error ½ r², i.e. r² ≤ 2).
SETTINGS = (("11.34", RobustSettings()), ("2", RobustSettings(threshold=2.0)))

SETTING_BEST = ("11.34, start best", RobustSettings(start="best"))

HEAD = ["file", "false edges", "c̄²", "seed", "precision", "recall", "true rejected", "ATE LAGO [m]",
        "ATE robust [m]", "χ² clean edges / clean χ²", "truncated cost, ours − clean", "GNC iterations", "time [s]",
        "pass"]


def add_arguments(group) -> None:
    robust3d.add_arguments(group)
    group.add_argument("--robust-gtsam", action="store_true",
                       help="also run GTSAM's GNC (../shared/bench/gtsam_gnc.py) at 10 %%, seed 0, on each file of "
                            "--robust-gtsam-files")
    group.add_argument("--robust-city", action="store_true",
                       help="also city10000 at 10 %%, seed 0 (its false loop closures join far-apart poses: the "
                            "factorizations of the first GNC iterations fill in, seconds to minutes each)")
    group.add_argument("--robust-sweep", action="store_true",
                       help="raise the fraction of false edges on each file until robust LAGO first fails")
    group.add_argument("--robust-best", action="store_true",
                       help="also RobustSettings(start='best') (GNC from LAGO and from a PCM clique, lower cost kept)")
    group.add_argument("--robust-gtsam-every", nargs="*", default=[], metavar="FILE",
                       help="files of --robust-gtsam-files on which GTSAM's GNC runs at every fraction and seed of the "
                            "table, not only at 10 %%, seed 0 (GTSAM's GNC on M3500 + 30 %% ran over seven minutes on one seed)")
    group.add_argument("--robust-gtsam-files", nargs="*", default=list(GTSAM_FILES), metavar="FILE",
                       help=f"files for --robust-gtsam (default {' '.join(GTSAM_FILES)})")


def scores(rejected, outliers) -> tuple[float, float, int]:
    """(precision, recall, true edges rejected) of the rejected edge indices against the false ones."""
    rej, out = set(np.asarray(rejected).tolist()), set(np.asarray(outliers).tolist())
    hit = len(rej & out)
    return (hit / len(rej) if rej else 1.0), hit / max(len(out), 1), len(rej - out)


def one_run(graph, clean_poses, clean_chi2, fraction, seed, settings: RobustSettings) -> dict:
    """Every number of one row (module docstring) for ``graph`` with ``fraction`` false edges, ``seed``, GNC
    with ``settings``."""
    go, idx = add_false_loop_closures(graph, fraction, seed=seed)
    plain = lago(go)
    t = time.perf_counter()
    res = lago(go, robust=settings)
    seconds = time.perf_counter() - t
    ref = refine(res.graph, res.poses)
    precision, recall, wrong = scores(res.rejected_edges, idx)
    ok = recall == 1.0 and wrong <= 0.01 * graph.n_edges and chi2(graph, ref.poses) <= 1.001 * clean_chi2
    return dict(n_false=int(idx.size), precision=precision, recall=recall, wrong=wrong, ok=ok,
                ate_lago=ate(plain.poses, clean_poses), ate_robust=ate(ref.poses, clean_poses),
                chi2_ratio=chi2(graph, ref.poses) / clean_chi2, iterations=res.iterations, seconds=seconds,
                graph=go, outliers=idx, **robust3d.tls_costs(go, ref.poses, clean_poses, settings.c2))


def gtsam_run(go, idx, graph, clean_poses, clean_chi2) -> dict | None:
    """GTSAM's GNC on the written corrupted graph (a child process); None when it cannot run."""
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "in.g2o", Path(tmp) / "out.g2o"
        write_graph(src, go)
        t = time.perf_counter()
        proc = subprocess.run([sys.executable, str(GTSAM_SCRIPT), str(src), str(out)], capture_output=True, text=True)
        wall = time.perf_counter() - t
        if proc.returncode:
            print(f"GTSAM's GNC failed: {proc.stderr[-300:]}", file=sys.stderr, flush=True)
            return None
        rep = json.loads(proc.stdout.strip().splitlines()[-1])
        est = read_graph(out).initial
        ours = _bench.run_child([sys.executable, "-m", "lago_cvx", "solve", str(src), "--robust", "--refine",
                                 "-o", str(Path(tmp) / "ours.g2o")])[0]
    precision, recall, wrong = scores(rep["rejected"], idx)
    return dict(n_false=int(idx.size), precision=precision, recall=recall, wrong=wrong, ate_robust=ate(est, clean_poses),
                chi2_ratio=chi2(graph, est) / clean_chi2, seconds=wall, gnc_s=rep["gnc_s"], ours=ours)


def run(args) -> str:
    skipped = _bench.datasets_skipped()
    if skipped:
        return f"# False loop closures: robust LAGO by graduated non-convexity\n\n{skipped}"
    if getattr(args, "robust_3d_only", False):
        return robust3d.kept_planar(args.out) + "\n\n" + robust3d.section(args)
    text = _planar(args)
    if getattr(args, "robust_3d", False):
        text += "\n\n" + robust3d.section(args)
    return text


def _planar(args) -> str:
    files = QUICK_FILES if args.quick else FILES
    fractions = FRACTIONS[:1] if args.quick else FRACTIONS
    seeds = SEEDS[:1] if args.quick else SEEDS
    settings_all = SETTINGS + ((SETTING_BEST,) if getattr(args, "robust_best", False) else ())
    plan = [(rel, fractions, seeds, settings_all) for rel in files]
    if getattr(args, "robust_city", False) and not args.quick:
        plan.append((CITY, FRACTIONS, SEEDS[:1], SETTINGS[:1]))
    rows, summary, gtsam_rows = [], [], []
    gtsam_skipped = _bench.gtsam_script_skipped(GTSAM_SCRIPT) if args.robust_gtsam else None
    for rel, fractions, seeds, settings in plan:
        path = _bench.find(rel)
        if path is None:
            continue
        graph = read_graph(path)
        clean = refine(graph, lago(graph).poses)
        for fraction, (c2, setting) in ((f, s) for f in fractions for s in settings):
            runs = []
            for seed in seeds:
                r = one_run(graph, clean.poses, clean.chi2, fraction, seed, setting)
                runs.append(r)
                rows.append([rel, f"{r['n_false']} ({fraction:.0%})", c2, seed, f"{r['precision']:.3f}",
                             f"{r['recall']:.3f}", r["wrong"], f"{r['ate_lago']:.3g}", f"{r['ate_robust']:.3g}",
                             f"{r['chi2_ratio']:.6g}", f"{r['tls_ours'] - r['tls_clean']:.2f}", r["iterations"],
                             f"{r['seconds']:.2f}", "yes" if r["ok"] else "no"])
                print(" | ".join(map(str, rows[-1])), flush=True)
                first = fraction == FRACTIONS[0] and seed == SEEDS[0]
                if (args.robust_gtsam and gtsam_skipped is None and (first or rel in getattr(args, "robust_gtsam_every", []))
                        and setting is SETTINGS[0][1] and rel in args.robust_gtsam_files):
                    g = gtsam_run(r["graph"], r["outliers"], graph, clean.poses, clean.chi2)
                    if g is not None:
                        gtsam_rows.append([rel, f"{g['n_false']} ({fraction:.0%})", seed, f"{g['precision']:.3f}",
                                           f"{g['recall']:.3f}", g["wrong"], f"{g['ate_robust']:.3g}",
                                           f"{g['chi2_ratio']:.6g}", f"{g['gnc_s']:.2f}", f"{g['seconds']:.2f}",
                                           f"{g['ours']:.2f}", f"{g['seconds'] / g['ours']:.1f}"])
                        print("GTSAM: " + " | ".join(map(str, gtsam_rows[-1])), flush=True)
            summary.append([rel, f"{fraction:.0%}", c2, sum(r["ok"] for r in runs), sum(r["recall"] == 1.0 for r in runs), len(runs),
                            sum(r["wrong"] for r in runs), f"{max(r['ate_robust'] for r in runs):.3g}",
                            f"{max(r['chi2_ratio'] for r in runs):.6g}",
                            f"{np.median([r['seconds'] for r in runs]):.2f}"])
    text = [
        "# False loop closures: robust LAGO by graduated non-convexity",
        "",
        __doc__.split("\n\n", 1)[1].strip(),
        "",
        "Robust LAGO: `lago(graph, robust=True)` — GNC with truncated least squares, c̄² = χ²₃(0.99) = 11.34,",
        "μ × 1.4 per iteration, odometric edges trusted (the odometric chain is complete in every file here), then",
        "moves that lower the truncated cost Σ min(r², c̄²) — one edge toggled, or an accepted edge swapped for a",
        "rejected one, each followed by a descent (`RobustSettings.local_search`, on graphs with at most 500 loop",
        "closures: MIT and CSAIL here);",
        "and with c̄² = 2, `RobustSettings(threshold=2.0)`, GTSAM's default inlier threshold (GncParams barcSq = 1",
        "on its error ½ r²). These files' information is loose for their residuals (χ² per edge ≪ 3 at the optimum),",
        "so the χ²₃ quantile leaves room for a false loop closure to bend the estimate a little and fit.",
        "",
        "## Summary per file and fraction",
        "",
        _bench.table(["file", "false edges", "c̄²", "runs passing", "runs with recall 1", "runs", "true edges rejected (all runs)",
                      "worst ATE robust [m]", "worst χ² clean edges / clean χ²", "median time [s]"], summary),
        "",
        "## Every run",
        "",
        _bench.table(HEAD, rows),
    ]
    if gtsam_rows:
        text += ["", "## GTSAM's GNC on the same corrupted graphs",
                 "", "`python ../shared/bench/gtsam_gnc.py IN OUT` (GTSAM's LAGO, GncLMOptimizer, TLS, odometric "
                 "edges and the prior as known inliers); its estimate (not refined further) against the same clean "
                 "solution; GNC seconds as the script reports them, and the whole process.", "",
                 _bench.table(["file", "false edges", "seed", "precision", "recall", "true rejected",
                               "ATE [m]", "χ² clean edges / clean χ²", "GNC [s]", "process [s]",
                               "our process [s]", "GTSAM process / ours"], gtsam_rows)]
    elif args.robust_gtsam:
        text += ["", f"GTSAM's GNC: {gtsam_skipped or 'failed (its error went to standard error)'}."]
    if getattr(args, "robust_sweep", False) and not args.quick:
        text += ["", "## The fraction at which robust LAGO first fails", "",
                 "Fractions 2 %, 5 %, 10 %, 20 %, 30 %, 40 %, 50 %, seeds 0–2, c̄² = 11.34, start LAGO (the default); "
                 "a run passes when every false edge is rejected, at most 1 % of the true edges are, and χ² of the "
                 "clean edges after the refinement is within 0.1 % of the clean refined χ². The sweep ends at the "
                 "first fraction where a run fails.", "", sweep(files)]
    return "\n".join(text)


def sweep(files) -> str:
    """The table of ``--robust-sweep`` (module docstring)."""
    rows = []
    for rel in files:
        path = _bench.find(rel)
        if path is None:
            continue
        graph = read_graph(path)
        clean = refine(graph, lago(graph).poses)
        rows.append([rel, *robust3d.first_failure(rel, "chi2_ratio", lambda fraction: [
            one_run(graph, clean.poses, clean.chi2, fraction, seed, SETTINGS[0][1]) for seed in SEEDS])])
    return _bench.table(["file", "largest fraction passing (all seeds)", "first failing fraction", "failing runs"],
                        rows)
