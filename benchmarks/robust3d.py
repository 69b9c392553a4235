"""The 3-D part of section ``robust`` (``--robust-3d``): false loop closures on the 3-D files, rejected by
graduated non-convexity around ``lago3d`` (``lago(graph3d, robust=True)``, ``lago_cvx.variants.robust3d``), against
GTSAM's GNC (``../shared/bench/gtsam_gnc.py``: InitializePose3, then GncLMOptimizer with truncated least squares
and the odometric edges as known inliers).

Protocol (``lago_cvx.synthetic.add_false_loop_closures`` on a ``PoseGraph3D``): ⌊0.1 · m⌋ false loop closures
appended to the file's m edges — random pairs of poses (never consecutive ids), the translation uniform in a 20 m
cube, the rotation uniform on SO(3), the 6×6 information of a real edge — seeds 0–2, each corrupted graph solved at
every confidence of ``--robust-3d-confidence`` (default 0.99 and 0.999: ``RobustSettings(confidence=c)``, c̄² = χ²₆(c)
= 16.81 and 22.46). For each corrupted graph and confidence:

* precision and recall of the rejected edges, and the number of true edges rejected;
* ATE [m] (RMS position error after the best rigid 3-D alignment) against the clean solution — LAGO on the file's
  edges refined by Levenberg–Marquardt (``refine3d``) — of plain LAGO on the corrupted graph and of the robust
  estimate refined on its accepted edges (``refine3d``, as ``lago-cvx solve --robust --refine``);
* χ² (g2o's cost, the files' own) of the file's clean edges at that refined estimate over the clean refined χ²;
* seconds of the robust run (GNC, every inner ``lago3d`` and the final one);
* pass: every false edge rejected, at most 1 % of the true edges rejected, χ² ratio ≤ 1.001.

Robust LAGO in 3-D (``lago(graph3d, robust=RobustSettings(confidence=c))``): GNC-TLS around ``lago3d``, then the
rejected edges within 9 c̄² of fitting tried back together (``RobustSettings.readmit``); the single-edge local search
after GNC stays planar. Where true edges are rejected, "Why the true edges are rejected" weighs them: with A the
accepted edges and T the q rejected true ones, the truncated cost Σ_k min(r_k², c̄²) over every edge of the corrupted
graph at ``refine3d``'s minimum on A and at its minimum on A ∪ T, the rise Δχ² of the χ² of the chosen set from A to
A ∪ T (each at its minimum), the χ²₆q quantile at 0.99 and Δχ²'s p-value (``scipy.stats.chi2.sf``): a p-value
below 0.01 says the q edges are inconsistent with the accepted ones at the 1 % level.

GTSAM's side runs as a whole process on the same written graph (``--robust-3d-gtsam-seeds``, once per seed, each run
stopped after ``--robust-3d-gtsam-timeout`` seconds), beside the whole process of ours on it at the default confidence
(``python -m lago_cvx solve IN --robust --refine -o OUT``). GTSAM reads the files' information as the information of
its own error (Log of SE(3)): its χ² ratio is taken in that cost (``graph.with_cost("gtsam")``) against the clean
graph refined in that cost, so that each optimizer is measured in the cost it minimizes.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2 as chi2_dist

import _bench
from lago_cvx import lago
from lago_cvx.io import read_graph, write_graph
from lago_cvx.posegraph3d import chi2_3d
from lago_cvx.space import refine3d
from lago_cvx.synthetic import add_false_loop_closures
from lago_cvx.variants import RobustSettings
from lago_cvx.variants.gnc import truncated_cost

FILES3D = ("se-sync-3d/sphere2500.g2o", "se-sync-3d/torus3D.g2o", "se-sync-3d/parking-garage.g2o",
           "se-sync-3d/smallGrid3D.g2o")
FRACTION = 0.1
SEEDS = (0, 1, 2)
CONFIDENCES = (0.99, 0.999)
SWEEP = (0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5)
GTSAM_SCRIPT = _bench.HERE.parent.parent / "shared" / "bench" / "gtsam_gnc.py"

HEAD = ["file", "false edges", "c̄²", "seed", "precision", "recall", "true rejected", "ATE LAGO [m]", "ATE robust [m]",
        "χ² clean edges / clean χ²", "GNC iterations", "time [s]", "pass"]
HEAD_GTSAM = ["file", "false edges", "seed", "precision", "recall", "true rejected", "ATE [m]",
              "χ² clean edges / clean χ² (GTSAM's cost)", "GNC [s]", "process [s]", "our process [s]",
              "GTSAM process / ours"]
HEAD_SUMMARY = ["file", "false edges", "c̄²", "runs passing", "runs with recall 1", "runs",
                "true edges rejected (all runs)", "worst ATE robust [m]", "worst χ² clean edges / clean χ²",
                "median time [s]"]
HEAD_WHY = ["file", "c̄²", "seed", "true rejected q", "truncated cost, A", "truncated cost, A ∪ T", "Δχ² (A → A ∪ T)",
            "χ²₆q(0.99)", "p-value"]


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
    group.add_argument("--robust-3d-confidence", nargs="*", type=float, default=list(CONFIDENCES), metavar="P",
                       help="confidences of the 3-D runs (RobustSettings(confidence=P), c̄² = χ²₆(P); default "
                            "0.99 0.999): every run is made at each")
    group.add_argument("--robust-3d-gtsam-timeout", type=float, default=1800.0, metavar="S",
                       help="seconds after which a GTSAM run is stopped (reported as such)")
    group.add_argument("--robust-3d-sweep", nargs="*", default=None, metavar="FILE",
                       help="raise the fraction of false edges (2 %%-50 %%, seeds 0-2) on each FILE (default: the "
                            "four 3-D files) at each --robust-3d-confidence until a run fails")


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


def corrupted(graph, seed, clean, fraction: float = FRACTION) -> dict:
    """The corrupted graph of ``seed`` (module docstring), its false edges and plain LAGO's ATE on it."""
    go, idx = add_false_loop_closures(graph, fraction, seed=seed)
    plain = lago(go)
    return dict(graph=go, outliers=idx, ate_lago=ate3d(plain.t, clean.t))


def one_run(graph, clean, bad: dict, settings: RobustSettings, *, why: bool = True) -> dict:
    """Every number of one row (module docstring): robust LAGO with ``settings`` on the corrupted graph ``bad``
    (``corrupted``), refined on its accepted edges; ``why`` the numbers of ``why_rejected`` when true edges are
    rejected (``why=False``: None)."""
    go, idx = bad["graph"], bad["outliers"]
    t = time.perf_counter()
    res = lago(go, robust=settings)
    seconds = time.perf_counter() - t
    ref = refine3d(res.graph, res.t, res.R)
    precision, recall, wrong = scores(res.rejected_edges, idx)
    ratio = chi2_3d(graph, ref.t, ref.R) / clean.chi2
    why = why_rejected(go, res, ref, idx, settings.c2_for(3)) if wrong and why else None
    return dict(n_false=int(idx.size), precision=precision, recall=recall, wrong=wrong, ratio=ratio,
                ok=recall == 1.0 and wrong <= 0.01 * graph.n_edges and ratio <= 1.001,
                ate_lago=bad["ate_lago"], ate_robust=ate3d(ref.t, clean.t), iterations=res.iterations,
                seconds=seconds, why=why, **tls_costs(go, (ref.t, ref.R), (clean.t, clean.R), settings.c2_for(3)))


def why_rejected(go, res, ref, outliers, c2: float) -> dict:
    """Whether the q rejected true edges T fit with the accepted edges A (module docstring): the truncated cost
    Σ_k min(r_k², c̄²) over every edge of ``go`` at ``refine3d``'s minimum on A (``ref``, refined from ``res``) and on
    A ∪ T (refined from ``ref``); Δχ² = χ²_{A∪T} − χ²_A at the two minima, the χ² quantile of 6q dof at 0.99 and
    Δχ²'s p-value (the upper tail of χ²_{6q})."""
    true_rejected = np.setdiff1d(res.rejected_edges, outliers)
    q = int(true_rejected.size)
    both = np.union1d(res.accepted_edges, true_rejected)
    ref_both = refine3d(go.subgraph_edges(both), ref.t, ref.R)
    d_chi2 = ref_both.chi2 - ref.chi2
    return dict(q=q, cost_a=truncated_cost(go, (ref.t, ref.R), c2),
                cost_both=truncated_cost(go, (ref_both.t, ref_both.R), c2), chi2_a=ref.chi2, chi2_both=ref_both.chi2,
                d_chi2=d_chi2, quantile=float(chi2_dist.ppf(0.99, 6 * q)), p=float(chi2_dist.sf(d_chi2, 6 * q)))


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
    ``{"summary": [...], "runs": [...], "gtsam": [...], "why": [...]}``, each row its list of cells; rows of another
    layout than the current headers (an older table) are left out."""
    kept = {"summary": [], "runs": [], "gtsam": [], "why": []}
    width = {"summary": len(HEAD_SUMMARY), "runs": len(HEAD), "gtsam": len(HEAD_GTSAM), "why": len(HEAD_WHY)}
    path = Path(folder) / "robust.md"
    text = path.read_text(encoding="utf-8") if path.is_file() else ""
    if "\n## 3-D graphs" not in text:
        return kept
    key = None
    for line in text.split("\n## 3-D graphs", 1)[1].splitlines():
        if line.startswith("### "):
            key = next((k for head, k in (("### Summary", "summary"), ("### Every run", "runs"), ("### GTSAM", "gtsam"),
                                          ("### Why", "why")) if line.startswith(head)), None)
        elif line.startswith("## "):
            break
        elif key and line.startswith("| ") and not line.startswith("| file "):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if cells[0] not in files and len(cells) == width[key]:
                kept[key].append(cells)
    return kept


def section(args) -> str:
    """The 3-D tables (module docstring) as Markdown."""
    rows, gtsam_rows, summary, why_rows = [], [], [], []
    confidences = list(args.robust_3d_confidence)
    c2s = {c: RobustSettings(confidence=c).c2_for(3) for c in confidences}
    gtsam_skipped = _bench.gtsam_script_skipped(GTSAM_SCRIPT) if args.robust_3d_gtsam_seeds else None
    for rel, graph, clean in _graphs(args.robust_3d_files):
        clean_gtsam = None
        bad = {seed: corrupted(graph, seed, clean) for seed in SEEDS}
        for seed in (s for s in SEEDS if gtsam_skipped is None and s in args.robust_3d_gtsam_seeds):
            if clean_gtsam is None:
                clean_gtsam = refine3d(graph.with_cost("gtsam"), clean.t, clean.R).chi2
            g = gtsam_run(bad[seed]["graph"], bad[seed]["outliers"], graph, clean, clean_gtsam,
                          args.robust_3d_gtsam_timeout)
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
        for confidence in confidences:
            c2 = f"{c2s[confidence]:.2f}"
            runs = []
            for seed in SEEDS:
                r = one_run(graph, clean, bad[seed], RobustSettings(confidence=confidence))
                runs.append(r)
                rows.append([rel, f"{r['n_false']} ({FRACTION:.0%})", c2, seed, f"{r['precision']:.3f}",
                             f"{r['recall']:.3f}", r["wrong"], f"{r['ate_lago']:.3g}", f"{r['ate_robust']:.3g}",
                             f"{r['ratio']:.6g}", r["iterations"], f"{r['seconds']:.2f}", "yes" if r["ok"] else "no"])
                print(" | ".join(map(str, rows[-1])), flush=True)
                w = r["why"]
                if w is not None:
                    why_rows.append([rel, c2, seed, w["q"], f"{w['cost_a']:.2f}", f"{w['cost_both']:.2f}",
                                     f"{w['d_chi2']:.1f}", f"{w['quantile']:.1f}", f"{w['p']:.2g}"])
                    print("why: " + " | ".join(map(str, why_rows[-1])), flush=True)
            summary.append([rel, f"{FRACTION:.0%}", c2, sum(r["ok"] for r in runs),
                            sum(r["recall"] == 1.0 for r in runs), len(runs), sum(r["wrong"] for r in runs),
                            f"{max(r['ate_robust'] for r in runs):.3g}", f"{max(r['ratio'] for r in runs):.6g}",
                            f"{np.median([r['seconds'] for r in runs]):.2f}"])
    # read at the end: a run of the other files may have written the file meanwhile
    old = (kept_rows(args.out, args.robust_3d_files) if args.robust_3d_keep
           else {"summary": [], "runs": [], "gtsam": [], "why": []})
    rows, gtsam_rows, summary = old["runs"] + rows, old["gtsam"] + gtsam_rows, old["summary"] + summary
    why_rows = old["why"] + why_rows
    kept_files = sorted({r[0] for r in rows + gtsam_rows + summary} - set(args.robust_3d_files))
    quantiles = " and ".join(f"χ²₆({c:g}) = {c2s[c]:.2f}" for c in confidences)
    text = ["## 3-D graphs", "", __doc__.split("\n\n", 1)[1].strip(), "",
            f"Settings: c̄² = {quantiles}; each inner `lago3d` (chordal relaxation, positions, joint step) weighted",
            "by w_k Ω_k, μ × 1.4 per GNC iteration, odometric edges trusted (complete chains in every file here),",
            "readmission κ = 9 (`RobustSettings.readmit`).", "",
            *([f"The rows of {', '.join(kept_files)} were measured by an earlier run of this section"
               f"{_kept_by(args.out)} and kept (`--robust-3d-keep`).", ""] if kept_files else []),
            "### Summary per file and c̄²", "", _bench.table(HEAD_SUMMARY, summary),
            "", "### Every run", "", _bench.table(HEAD, rows)]
    if why_rows:
        text += ["", "### Why the true edges are rejected", "",
                 "A: the accepted edges, T: the q rejected true edges; truncated cost Σ min(r², c̄²) over every edge "
                 "of the corrupted graph at `refine3d`'s minimum on A and on A ∪ T; Δχ²: the rise of the χ² of the "
                 "chosen set from A to A ∪ T (each at its minimum); p-value: P(χ²₆q > Δχ²).", "",
                 _bench.table(HEAD_WHY, why_rows)]
    if gtsam_rows:
        text += ["", "### GTSAM's GNC on the same corrupted graphs", "",
                 "Once per seed of `--robust-3d-gtsam-seeds` of the files shown (our process beside it: "
                 "`lago-cvx solve --robust --refine`, the default confidence 0.99); a run still going after its time "
                 "limit (`--robust-3d-gtsam-timeout`) is stopped and shown as such.", "",
                 _bench.table(HEAD_GTSAM, gtsam_rows)]
    elif args.robust_3d_gtsam_seeds:
        text += ["", f"GTSAM's GNC: {gtsam_skipped or 'failed'}."]
    if args.robust_3d_sweep is not None:
        text += ["", "### The fraction at which robust LAGO first fails in 3-D", "",
                 f"Fractions {', '.join(f'{f:.0%}' for f in SWEEP)}, seeds {SEEDS[0]}–{SEEDS[-1]}, at each confidence; "
                 "a run passes as above (every false edge rejected, at most 1 % of the true edges, χ² ratio ≤ 1.001); "
                 "the sweep of a file ends at the first fraction where a run fails.", "",
                 sweep(args.robust_3d_sweep or list(FILES3D), confidences, c2s)]
    return "\n".join(text)


def sweep(files, confidences, c2s) -> str:
    """The table of ``--robust-3d-sweep``: for each file and confidence the largest fraction of ``SWEEP`` at which every
    seed passes and the first at which one fails (``first_failure``)."""
    out = []
    for rel, graph, clean in _graphs(files):
        for confidence in confidences:
            found = first_failure(f"{rel} {confidence:g}", "ratio", lambda fraction: [
                one_run(graph, clean, corrupted(graph, seed, clean, fraction), RobustSettings(confidence=confidence))
                for seed in SEEDS])
            out.append([rel, f"{c2s[confidence]:.2f}", *found])
    return _bench.table(["file", "c̄²", "largest fraction passing (all seeds)", "first failing fraction",
                         "failing runs"], out)


def _graphs(files):
    """(file, graph, clean solution: LAGO refined by ``refine3d``) of each of ``files`` found in the datasets."""
    for rel in files:
        path = _bench.find(rel)
        if path is not None:
            graph = read_graph(path)
            first = lago(graph)
            yield rel, graph, refine3d(graph, first.t, first.R)


def first_failure(label: str, ratio: str, runs_at) -> list:
    """The sweep over ``SWEEP`` shared by the planar and 3-D tables: ``runs_at(fraction)`` gives one run per seed
    (dicts with ``ok``, ``recall``, ``n_false``, ``wrong`` and the χ² ratio under the key ``ratio``); returns the
    cells [largest fraction where every seed passes, first fraction where one fails, its failing runs]."""
    passed, failed, detail = None, None, ""
    for fraction in SWEEP:
        runs = runs_at(fraction)
        print(f"sweep {label} {fraction:.0%}: " + ", ".join(
            f"seed {s}: missed {round((1 - r['recall']) * r['n_false'])}, true rejected {r['wrong']}, "
            f"χ² ratio {r[ratio]:.6g}" for s, r in zip(SEEDS, runs)), flush=True)
        if all(r["ok"] for r in runs):
            passed = fraction
            continue
        failed = fraction
        detail = "; ".join(f"seed {s}: {round((1 - r['recall']) * r['n_false'])} false kept, {r['wrong']} true "
                           f"rejected, χ² ratio {r[ratio]:.4g}, {verdict(r)}" for s, r in zip(SEEDS, runs) if not r["ok"])
        break
    return ["–" if passed is None else f"{passed:.0%}", "none up to 50 %" if failed is None else f"{failed:.0%}",
            detail]


def tls_costs(go, ours, clean, c2: float) -> dict:
    """The truncated cost Σ_k min(r_k², c̄²) over every edge of the corrupted graph ``go`` at our refined estimate
    (``ours``) and at the clean solution (``clean``; planar poses or (t, R)): where ours is the lower, the clean
    solution is not the minimum of the objective GNC minimizes, and no solver of it returns the clean one."""
    return dict(tls_ours=truncated_cost(go, ours, c2), tls_clean=truncated_cost(go, clean, c2))


def verdict(r: dict) -> str:
    """A failing run's cause from ``tls_costs``: the objective's choice, or a search that ended above the clean cost."""
    word = "the objective's choice" if r["tls_ours"] < r["tls_clean"] else "a search failure"
    return f"truncated cost {r['tls_ours']:.1f} against the clean solution's {r['tls_clean']:.1f}: {word}"


#: the header line of a result file (``_bench.header``) and its form kept for the planar tables
_GENERATED, _PLANAR = "Generated by ", "The planar tables were generated by "


def _kept_by(folder: Path) -> str:
    """`` (`command`, version)`` of the run that measured the 3-D rows of ``folder``/robust.md: the command its kept-rows
    sentence names, else its header's when that ran the 3-D part; '' when the file records neither."""
    path = Path(folder) / "robust.md"
    text = path.read_text(encoding="utf-8") if path.is_file() else ""
    found = re.search(r"were measured by an earlier run of this section \((`[^`]+`[^)]*)\)", text)
    if found:
        return f" ({found.group(1)})"
    head = text.split("\n", 1)[0]
    if head.startswith(_GENERATED) and "--robust-3d" in _command(head):
        return f" (`{_command(head)}`{head.split('`')[2].split(' on ')[0].rstrip(',')})"
    return ""


def _command(line: str) -> str:
    """The command quoted (between the first two backticks) in a header line, '' if none."""
    parts = line.split("`")
    return parts[1] if len(parts) > 2 else ""


def kept_planar(folder: Path) -> str:
    """The planar part of the existing ``robust.md`` in ``folder`` (``--robust-3d-only``), its old 3-D part dropped.

    The line naming the planar tables' command: the file's first line ("Generated by …") turned into "The planar
    tables were generated by …" when its command is not a ``--robust-3d-only`` one (a run that wrote planar tables);
    otherwise the first existing "The planar tables were generated by …" line whose command is not one either. Lines
    of that form naming a ``--robust-3d-only`` command are dropped (they never described the planar tables)."""
    path = Path(folder) / "robust.md"
    if not path.is_file():
        return "# False loop closures: robust LAGO by graduated non-convexity\n\n(no planar tables: run without " \
               "--robust-3d-only)"
    text = path.read_text(encoding="utf-8")
    text = text.split("\n## 3-D graphs", 1)[0].rstrip()
    head, body = text.split("\n", 1) if text.startswith(_GENERATED) else ("", text)
    lines = body.split("\n")
    named = [line for line in ([_PLANAR + head[len(_GENERATED):]] if head else []) +
             [line for line in lines if line.startswith(_PLANAR)] if "--robust-3d-only" not in _command(line).split()]
    lines = [line for line in lines if not line.startswith(_PLANAR)]
    body = "\n".join(lines).replace("\nSection time:", "\nPlanar section time:")
    body = re.sub(r"\n{3,}", "\n\n", body).strip("\n")
    planar = named[0] if named else "The command of the planar tables is not recorded."
    if body.startswith("# "):
        title, rest = (body.split("\n", 1) + [""])[:2]
        return f"{title}\n\n{planar}\n\n{rest.lstrip(chr(10))}".rstrip()
    return f"{planar}\n\n{body}".rstrip()
