"""Section ``clean`` of ``python benchmarks/run.py``: robust LAGO on the clean public graphs costs (almost) nothing.

The claim checked: on a graph without false loop closures, ``lago-cvx solve F --robust --refine`` ends within
0.1 % of the χ² of ``lago-cvx solve F --refine`` — GNC (graduated non-convexity, truncated least squares) should
reject no true edge, or only edges whose loss the refinement does not feel.

Protocol. Every file of the datasets folder (``lago_cvx.datasets``; the folder walked, planar and 3-D: g2o, TORO,
GTSAM's text files) that ``read_graph`` reads; a file it refuses is listed with its one-line reason. For each, two
whole processes, one after the other, each timed by its wall clock (imports and reading included; one run each):

    python -m lago_cvx solve F --refine --json -o plain.g2o
    python -m lago_cvx solve F --robust --refine --json -o robust.g2o

(``--clean-routes default seed``: both pairs, the second with ``--route seed`` in both processes.)

A run longer than ``--clean-timeout`` seconds (default 300) is stopped and reported as such. The estimates written
are read back (``read_graph(out).initial``) and both scored by ``lago_cvx.chi2`` over **every** edge of the file,
in the file's cost (``lago_cvx.conventions``): the robust run's own JSON χ² is over the edges it accepted only
(``"chi2_edges": "accepted"``), which would hide what a rejected true edge costs. Ratio = robust / plain; the
file passes when the ratio ≤ 1.001.

For a file that fails, the diagnosis: the rejected edges (JSON ``rejected_edges``, file order) split into
odometric (consecutive ids) and loop closures, their r² = eᵀΩe at the plain refined minimum against c̄² (the
χ² quantile GNC truncates at: 3 dof planar, 6 in 3-D, confidence 0.99), the χ² of the accepted and of the
rejected edges at both estimates, and the truncated cost Σ min(r², c̄²) over every edge at both (the cost GNC
minimizes locally: lower at the robust estimate means GNC did its job and the truncated cost itself prefers
rejecting those true edges).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import _bench
from lago_cvx import chi2, read_graph
from lago_cvx.datasets import datasets_dir
from lago_cvx.errors import LagoError
from lago_cvx.variants import RobustSettings
from lago_cvx.variants.gnc import edge_r2

HEAD = ["file", "dim", "poses", "edges", "rejected", "χ² plain refined", "χ² robust refined (all edges)",
        "robust / plain", "pass (≤ 1.001)", "plain [s]", "robust [s]"]
PASS_RATIO = 1.001


def add_arguments(group) -> None:
    group.add_argument("--clean-timeout", type=float, default=300.0, metavar="S",
                       help="clean section: stop a solve process after S seconds (default 300)")
    group.add_argument("--clean-routes", nargs="+", choices=["default", "seed"], default=["default"], metavar="ROUTE",
                       help="clean section: the routes both processes run by (--route; default: default only)")


def _files(folder: Path) -> list[Path]:
    """Every regular file under ``folder`` except documentation, sorted by relative path."""
    return sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() != ".md")


def _solve(path: Path, out: Path, timeout: float, *extra) -> tuple[float, dict | None, str | None]:
    """(wall s, the JSON, None) of ``python -m lago_cvx solve path --refine --json -o out *extra``; (wall s, None,
    why) when it ran out of time or failed."""
    argv = [sys.executable, "-m", "lago_cvx", "solve", str(path), "--refine", "--json", "-o", str(out), *extra]
    t = time.perf_counter()
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=timeout, env=os.environ.copy())
    except subprocess.TimeoutExpired:
        return time.perf_counter() - t, None, f"stopped after {timeout:.0f} s"
    wall = time.perf_counter() - t
    if done.returncode:
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        return wall, None, f"exit {done.returncode}: {last}"
    return wall, json.loads(done.stdout), None


def _poses(graph, out: Path):
    """The estimate written to ``out``, in the order of ``graph``'s poses."""
    written = read_graph(out)
    if not np.array_equal(written.ids, graph.ids):
        raise RuntimeError(f"{out}: the ids written differ from the input's")
    return written.initial


def _diagnosis(rel: str, graph, plain, robust, payload: dict) -> str:
    """The lines explaining a failure: which edges were rejected and how well they fit at the plain minimum."""
    c2 = RobustSettings().c2_for(graph.dim)
    rejected = np.asarray(payload.get("rejected_edges", []), dtype=int)
    r2 = edge_r2(graph, plain)
    odo = graph.is_odometric[rejected]
    rr = r2[rejected]
    lines = [f"* **{rel}** ({graph.dim}-D, c̄² = {c2:.4g}): {rejected.size} edges rejected — {int(odo.sum())} "
             f"odometric, {int((~odo).sum())} loop closures; GNC iterations {payload.get('robust_iterations')}."]
    if rejected.size:
        lines.append(f"  r² of the rejected edges at the plain refined minimum: min {rr.min():.4g}, median "
                     f"{np.median(rr):.4g}, max {rr.max():.4g}; {int((rr <= c2).sum())} of {rr.size} within c̄² "
                     f"(every edge: max r² {r2.max():.4g}, {int((r2 > c2).sum())} of {r2.size} above c̄²).")
        shown = ", ".join(f"{k} ({'odo' if o else 'loop'}, r² {v:.3g})" for k, o, v in zip(rejected[:12], odo, rr))
        lines.append(f"  Rejected edges (file order){' — the first 12' if rejected.size > 12 else ''}: {shown}.")
    r2_rob = edge_r2(graph, robust)
    kept = np.ones(graph.n_edges, dtype=bool)
    kept[rejected] = False
    lines.append(f"  χ² split, plain → robust estimate: accepted edges {r2[kept].sum():.6g} → {r2_rob[kept].sum():.6g}, "
                 f"rejected edges {r2[~kept].sum():.6g} → {r2_rob[~kept].sum():.6g}.")
    lines.append(f"  Truncated cost Σ min(r², c̄²) over every edge (what GNC lowers): plain {np.minimum(r2, c2).sum():.6g}, "
                 f"robust {np.minimum(r2_rob, c2).sum():.6g}.")
    return "\n".join(lines)


def _row(rel: str, path: Path, graph, work: Path, timeout: float, route: str = "default") -> tuple[list, str | None]:
    out_p, out_r = work / "out_plain.g2o", work / "out_robust.g2o"
    for out in (out_p, out_r):
        out.unlink(missing_ok=True)
    wall_p, js_p, why_p = _solve(path, out_p, timeout, "--route", route)
    wall_r, js_r, why_r = _solve(path, out_r, timeout, "--route", route, "--robust")
    head = [rel, graph.dim, graph.n_poses, graph.n_edges]
    if why_p or why_r:
        note = "; ".join(f"{k}: {w}" for k, w in (("plain", why_p), ("robust", why_r)) if w)
        rejected = "–" if js_r is None else js_r["n_rejected"]
        plain_chi = "–" if js_p is None else _bench.fmt(chi2(graph, _poses(graph, out_p)), ".8g")
        return head + [rejected, plain_chi, "–", "–", note, f"{wall_p:.1f}", f"{wall_r:.1f}"], None
    plain, robust = _poses(graph, out_p), _poses(graph, out_r)
    chi_p, chi_r = chi2(graph, plain), chi2(graph, robust)
    ratio = chi_r / chi_p
    ok = ratio <= PASS_RATIO
    row = head + [js_r["n_rejected"], _bench.fmt(chi_p, ".8g"), _bench.fmt(chi_r, ".8g"), f"{ratio:.6f}",
                  "yes" if ok else "**no**", f"{wall_p:.1f}", f"{wall_r:.1f}"]
    return row, None if ok else _diagnosis(rel, graph, plain, robust, js_r)


def run(args) -> str:
    title = "# Robust LAGO on the clean public graphs"
    skipped = _bench.datasets_skipped()
    if skipped:
        return f"{title}\n\n{skipped}"
    folder = datasets_dir()
    timeout = float(getattr(args, "clean_timeout", 300.0))
    routes = list(dict.fromkeys(getattr(args, "clean_routes", None) or ["default"]))
    parts, refused = [title, "", __doc__.split("\n\n", 1)[1].strip(), ""], []
    with tempfile.TemporaryDirectory() as tmp:
        for route in routes:
            rows, diagnoses = [], []
            for path in _files(folder):
                rel = path.relative_to(folder).as_posix()
                try:
                    graph = read_graph(path)
                except LagoError as exc:
                    if route == routes[0]:
                        refused.append(f"* `{rel}`: {str(exc).splitlines()[0]}")
                    continue
                print(f"  {rel} ({route} route)", flush=True)
                row, why = _row(rel, path, graph, Path(tmp), timeout, route)
                rows.append(row)
                if why:
                    diagnoses.append(why)
            n_pass = sum(r[8] == "yes" for r in rows)
            if route != "default":
                parts += [f"## The {route} route", "", f"Both processes with `--route {route}`.", ""]
            parts += [f"Result: {n_pass} of {len(rows)} files pass (robust / plain ≤ {PASS_RATIO}).", "",
                      _bench.table(HEAD, rows), "", "#" * (2 + (route != "default")) + " Failures", "",
                      *(diagnoses or ["None."]), ""]
    parts += ["## Files skipped", "", *(refused or ["None."])]
    return "\n".join(parts)
