"""The 3-D part of section ``robust`` (``--robust-3d``): false loop closures on the 3-D files, rejected by
graduated non-convexity around ``lago3d`` (``lago(graph3d, robust=True)``, ``lago_cvx.variants.robust3d``), against
GTSAM's GNC (``../shared/bench/gtsam_gnc.py``: InitializePose3, then GncLMOptimizer with truncated least squares
and the odometric edges as known inliers).

Protocol (``lago_cvx.synthetic.add_false_loop_closures`` on a ``PoseGraph3D``): ⌊0.1 · m⌋ false loop closures
appended to the file's m edges — random pairs of poses (never consecutive ids), the translation uniform in a 20 m
cube, the rotation uniform on SO(3), the 6×6 information of a real edge — seeds 0–2. For each corrupted graph:

* precision and recall of the rejected edges, and the number of true edges rejected;
* ATE [m] (RMS position error after the best rigid 3-D alignment) against the clean solution — LAGO on the file's
  edges refined by Levenberg–Marquardt (``refine3d``) — of plain LAGO on the corrupted graph and of the robust
  estimate refined on its accepted edges (``refine3d``, as ``lago-cvx solve --robust --refine``);
* χ² (g2o's cost, the files' own) of the file's clean edges at that refined estimate over the clean refined χ²;
* seconds of the robust run (GNC, every inner ``lago3d`` and the final one);
* pass: every false edge rejected, at most 1 % of the true edges rejected, χ² ratio ≤ 1.001.

GTSAM's side runs as a whole process on the same written graph (``--robust-3d-gtsam-seeds``, each run stopped after
``--robust-3d-gtsam-timeout`` seconds), beside the whole process of ours on it
(``python -m lago_cvx solve IN --robust --refine -o OUT``). GTSAM reads the files' information as the information of
its own error (Log of SE(3)): its χ² ratio is taken in that cost (``graph.with_cost("gtsam")``) against the clean
graph refined in that cost, so that each optimizer is measured in the cost it minimizes.
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
from lago_cvx import lago
from lago_cvx.io import read_graph, write_graph
from lago_cvx.posegraph3d import chi2_3d
from lago_cvx.space import refine3d
from lago_cvx.synthetic import add_false_loop_closures

FILES3D = ("se-sync-3d/sphere2500.g2o", "se-sync-3d/torus3D.g2o", "se-sync-3d/parking-garage.g2o",
           "se-sync-3d/smallGrid3D.g2o")
FRACTION = 0.1
SEEDS = (0, 1, 2)
GTSAM_SCRIPT = _bench.HERE.parent.parent / "shared" / "bench" / "gtsam_gnc.py"

HEAD = ["file", "false edges", "seed", "precision", "recall", "true rejected", "ATE LAGO [m]", "ATE robust [m]",
        "χ² clean edges / clean χ²", "GNC iterations", "time [s]", "pass"]
HEAD_GTSAM = ["file", "false edges", "seed", "precision", "recall", "true rejected", "ATE [m]",
              "χ² clean edges / clean χ² (GTSAM's cost)", "GNC [s]", "process [s]", "our process [s]",
              "GTSAM process / ours"]


def add_arguments(group) -> None:
    group.add_argument("--robust-3d", action="store_true",
                       help="also the 3-D files (sphere2500, torus3D, parking-garage, smallGrid3D) at 10 %%, seeds 0-2")
    group.add_argument("--robust-3d-only", action="store_true",
                       help="run only the 3-D part and keep the planar tables of the existing robust.md")
    group.add_argument("--robust-3d-files", nargs="*", default=list(FILES3D), metavar="FILE")
    group.add_argument("--robust-3d-gtsam-seeds", nargs="*", type=int, default=[], metavar="SEED",
                       help="seeds on which GTSAM's GNC runs too (default none)")
    group.add_argument("--robust-3d-keep", action="store_true",
                       help="keep the 3-D rows of the existing robust.md for the files not in --robust-3d-files (one "
                            "file's runs at a time; each kept row as it was measured)")
    group.add_argument("--robust-3d-gtsam-timeout", type=float, default=1800.0, metavar="S",
                       help="seconds after which a GTSAM run is stopped (reported as such)")


def ate3d(estimate: np.ndarray, truth: np.ndarray) -> float:
    """RMS of ‖R p_est + t − p_truth‖ over the poses (positions (n, 3)) after the best rigid alignment (Kabsch)."""
    a, b = estimate - estimate.mean(0), truth - truth.mean(0)
    U, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    return float(np.sqrt(np.mean(np.sum((a @ R.T - b) ** 2, axis=1))))


def scores(rejected, outliers) -> tuple[float, float, int]:
    rej, out = set(np.asarray(rejected).tolist()), set(np.asarray(outliers).tolist())
    hit = len(rej & out)
    return (hit / len(rej) if rej else 1.0), hit / max(len(out), 1), len(rej - out)


def one_run(graph, clean, seed) -> dict:
    go, idx = add_false_loop_closures(graph, FRACTION, seed=seed)
    plain = lago(go)
    t = time.perf_counter()
    res = lago(go, robust=True)
    seconds = time.perf_counter() - t
    ref = refine3d(res.graph, res.t, res.R)
    precision, recall, wrong = scores(res.rejected_edges, idx)
    ratio = chi2_3d(graph, ref.t, ref.R) / clean.chi2
    return dict(n_false=int(idx.size), precision=precision, recall=recall, wrong=wrong, ratio=ratio,
                ok=recall == 1.0 and wrong <= 0.01 * graph.n_edges and ratio <= 1.001,
                ate_lago=ate3d(plain.t, clean.t), ate_robust=ate3d(ref.t, clean.t), iterations=res.iterations,
                seconds=seconds, graph=go, outliers=idx)


def gtsam_run(go, idx, graph, clean, clean_gtsam, timeout) -> dict:
    """GTSAM's GNC on the written corrupted graph (a child process), and our whole process on the same file."""
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "in.g2o", Path(tmp) / "out.g2o"
        write_graph(src, go)
        ours = _bench.run_child([sys.executable, "-m", "lago_cvx", "solve", str(src), "--robust", "--refine",
                                 "-o", str(Path(tmp) / "ours.g2o")])[0]
        t = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, str(GTSAM_SCRIPT), str(src), str(out)], capture_output=True,
                                  text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return dict(n_false=int(idx.size), timeout=True, seconds=time.perf_counter() - t, ours=ours)
        wall = time.perf_counter() - t
        if proc.returncode:
            print(f"GTSAM's GNC failed: {proc.stderr[-300:]}", file=sys.stderr, flush=True)
            return dict(n_false=int(idx.size), failed=True, seconds=wall, ours=ours)
        rep = json.loads(proc.stdout.strip().splitlines()[-1])
        t_est, R_est = read_graph(out).initial
    precision, recall, wrong = scores(rep["rejected"], idx)
    return dict(n_false=int(idx.size), precision=precision, recall=recall, wrong=wrong, ate=ate3d(t_est, clean.t),
                ratio=chi2_3d(graph.with_cost("gtsam"), t_est, R_est) / clean_gtsam, seconds=wall,
                gnc_s=rep["gnc_s"], ours=ours)


def kept_rows(folder: Path, files) -> dict:
    """The rows of the 3-D tables of ``folder``/robust.md whose file is not in ``files`` (``--robust-3d-keep``):
    ``{"summary": [...], "runs": [...], "gtsam": [...]}``, each row its list of cells."""
    kept = {"summary": [], "runs": [], "gtsam": []}
    path = Path(folder) / "robust.md"
    text = path.read_text(encoding="utf-8") if path.is_file() else ""
    if "\n## 3-D graphs" not in text:
        return kept
    key = None
    for line in text.split("\n## 3-D graphs", 1)[1].splitlines():
        if line.startswith("### "):
            key = next((k for head, k in (("### Summary", "summary"), ("### Every run", "runs"), ("### GTSAM", "gtsam"))
                        if line.startswith(head)), None)
        elif line.startswith("## "):
            break
        elif key and line.startswith("| ") and not line.startswith("| file "):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if cells[0] not in files:
                kept[key].append(cells)
    return kept


def section(args) -> str:
    """The 3-D tables (module docstring) as Markdown."""
    rows, gtsam_rows, summary = [], [], []
    gtsam_skipped = _bench.gtsam_script_skipped(GTSAM_SCRIPT) if args.robust_3d_gtsam_seeds else None
    for rel in args.robust_3d_files:
        path = _bench.find(rel)
        if path is None:
            continue
        graph = read_graph(path)
        first = lago(graph)
        clean = refine3d(graph, first.t, first.R)
        clean_gtsam = None
        runs = []
        for seed in SEEDS:
            r = one_run(graph, clean, seed)
            runs.append(r)
            rows.append([rel, f"{r['n_false']} ({FRACTION:.0%})", seed, f"{r['precision']:.3f}", f"{r['recall']:.3f}",
                         r["wrong"], f"{r['ate_lago']:.3g}", f"{r['ate_robust']:.3g}", f"{r['ratio']:.6g}",
                         r["iterations"], f"{r['seconds']:.2f}", "yes" if r["ok"] else "no"])
            print(" | ".join(map(str, rows[-1])), flush=True)
            if gtsam_skipped is None and seed in args.robust_3d_gtsam_seeds:
                if clean_gtsam is None:
                    gg = graph.with_cost("gtsam")
                    clean_gtsam = refine3d(gg, clean.t, clean.R).chi2
                g = gtsam_run(r["graph"], r["outliers"], graph, clean, clean_gtsam, args.robust_3d_gtsam_timeout)
                if g.get("timeout") or g.get("failed"):
                    what = (f"stopped after {g['seconds']:.0f} s" if g.get("timeout") else "failed")
                    gtsam_rows.append([rel, f"{g['n_false']} ({FRACTION:.0%})", seed, what, "–", "–", "–", "–", "–",
                                       f"> {g['seconds']:.0f}" if g.get("timeout") else "–", f"{g['ours']:.2f}",
                                       f"> {g['seconds'] / g['ours']:.0f}" if g.get("timeout") else "–"])
                else:
                    gtsam_rows.append([rel, f"{g['n_false']} ({FRACTION:.0%})", seed, f"{g['precision']:.3f}",
                                       f"{g['recall']:.3f}", g["wrong"], f"{g['ate']:.3g}", f"{g['ratio']:.6g}",
                                       f"{g['gnc_s']:.2f}", f"{g['seconds']:.2f}", f"{g['ours']:.2f}",
                                       f"{g['seconds'] / g['ours']:.1f}"])
                print("GTSAM: " + " | ".join(map(str, gtsam_rows[-1])), flush=True)
        summary.append([rel, f"{FRACTION:.0%}", sum(r["ok"] for r in runs), sum(r["recall"] == 1.0 for r in runs),
                        len(runs), sum(r["wrong"] for r in runs), f"{max(r['ate_robust'] for r in runs):.3g}",
                        f"{max(r['ratio'] for r in runs):.6g}", f"{np.median([r['seconds'] for r in runs]):.2f}"])
    # read at the end: a run of the other files may have written the file meanwhile
    old = kept_rows(args.out, args.robust_3d_files) if args.robust_3d_keep else {"summary": [], "runs": [], "gtsam": []}
    rows, gtsam_rows, summary = old["runs"] + rows, old["gtsam"] + gtsam_rows, old["summary"] + summary
    kept_files = sorted({r[0] for r in rows + gtsam_rows + summary} - set(args.robust_3d_files))
    text = ["## 3-D graphs", "", __doc__.split("\n\n", 1)[1].strip(), "",
            "Robust LAGO in 3-D: `lago(graph3d, robust=True)` — GNC-TLS around `lago3d` (chordal relaxation, positions,",
            "joint step, each weighted by w_k Ω_k), c̄² = χ²₆(0.99) = 16.81, μ × 1.4 per iteration, odometric edges",
            "trusted (complete chains in every file here); no local search after GNC (planar only).", "",
            *([f"The rows of {', '.join(kept_files)} were measured by an earlier run of this section "
               "(`--robust-3d-files` naming them) and kept (`--robust-3d-keep`).", ""] if kept_files else []),
            "### Summary per file", "",
            _bench.table(["file", "false edges", "runs passing", "runs with recall 1", "runs",
                          "true edges rejected (all runs)", "worst ATE robust [m]", "worst χ² clean edges / clean χ²",
                          "median time [s]"], summary),
            "", "### Every run", "", _bench.table(HEAD, rows)]
    if gtsam_rows:
        text += ["", "### GTSAM's GNC on the same corrupted graphs", "",
                 "On the seeds of `--robust-3d-gtsam-seeds` of the files shown; a run still going after its time "
                 "limit (`--robust-3d-gtsam-timeout`) is stopped and shown as such.", "",
                 _bench.table(HEAD_GTSAM, gtsam_rows)]
    elif args.robust_3d_gtsam_seeds:
        text += ["", f"GTSAM's GNC: {gtsam_skipped or 'failed'}."]
    return "\n".join(text)


def kept_planar(folder: Path) -> str:
    """The planar part of the existing ``robust.md`` in ``folder`` (``--robust-3d-only``): its header turned into a
    sentence about the planar tables, its old 3-D part dropped."""
    path = Path(folder) / "robust.md"
    if not path.is_file():
        return "# False loop closures: robust LAGO by graduated non-convexity\n\n(no planar tables: run without " \
               "--robust-3d-only)"
    text = path.read_text(encoding="utf-8")
    text = text.split("\n## 3-D graphs", 1)[0].rstrip()
    head, body = text.split("\n", 1) if text.startswith("Generated by") else ("", text)
    if head.startswith("Generated by"):
        head = "The planar tables were g" + head[1:]
    body = body.replace("\nSection time:", "\nPlanar section time:")
    while body.startswith("\n"):
        body = body[1:]
    if body.startswith("# "):
        title, rest = body.split("\n", 1)
        return f"{title}\n\n{head}\n{rest}".rstrip()
    return f"{head}\n\n{body}".rstrip()
