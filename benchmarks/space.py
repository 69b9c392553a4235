"""3-D pose graphs: LAGO's initialization (``lago_cvx.space``) against GTSAM's ``InitializePose3``, and the minimum.

For every 3-D graph of the datasets (``se-sync-3d/*.g2o``, GTSAM's ``pose3example*.txt``) and three seeded synthetic
worlds: χ² in GTSAM's cost (Σ eᵀΩe, no ½, e = Log(Z⁻¹X_i⁻¹X_j): GTSAM's 2·error, the cost ``InitializePose3`` and its
LM are measured in; the graphs are read with ``cost="gtsam"`` and the worlds drawn in it) of

* our initialization, both routes (seed: chordal → positions; default: + the guarded joint step) and both weightings
  of the chordal relaxation (isotropic: SE-Sync's κ; anisotropic: the whole rotational block);
* GTSAM's ``InitializePose3.initialize`` (a prior pinning the first pose, as ``../shared/bench/gtsam_init3d.py``);
* the minimum found: our ``refine3d`` (Levenberg–Marquardt from the default route) and GTSAM's LM from
  InitializePose3 (relative tolerance 1e-10, as the script), the smaller of the two;

and the in-process times (median of ``REPEAT`` runs; reading the file excluded). Usage:
``python benchmarks/run.py space [--space-repeat N]`` → ``benchmarks/space.md`` (``python benchmarks/space.py``
prints the same tables).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


from lago_cvx.datasets import datasets_dir  # noqa: E402
from lago_cvx.io import read_graph, write_graph  # noqa: E402
from lago_cvx.space import lago3d, refine3d  # noqa: E402

#: The minimum column's refinement: Levenberg–Marquardt run to a 1e-12 relative decrease (not refine's defaults,
#: which reach the same minima to their 10 digits in fewer iterations).
REFINE_LM = {"method": "levenberg-marquardt", "tolerance": 1e-12, "max_iterations": 100}
from lago_cvx.synthetic.space import cube_grid_world, sphere_world, torus_world  # noqa: E402

FILES = ["se-sync-3d/tinyGrid3D.g2o", "se-sync-3d/smallGrid3D.g2o", "se-sync-3d/parking-garage.g2o",
         "se-sync-3d/sphere2500.g2o", "se-sync-3d/torus3D.g2o", "gtsam/pose3example-grid.txt",
         "gtsam/pose3example.txt", "gtsam/pose3example-offdiagonal.txt"]
WORLDS = {"synthetic sphere (20×40, seed 11)": lambda: sphere_world(20, 40, seed=11, cost="gtsam"),
          "synthetic torus (25×40, seed 12)": lambda: torus_world(25, 40, seed=12, cost="gtsam"),
          "synthetic grid (9³, seed 13)": lambda: cube_grid_world(9, seed=13, sigma_r=0.03, cost="gtsam")}


def _median(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def _gtsam(path: str, repeat: int):
    """(χ² InitializePose3, seconds, χ² LM from it, LM seconds) or Nones with the error message."""
    try:
        import gtsam
    except ImportError:
        return None, None, None, None, "gtsam not installed"
    graph, initial = gtsam.readG2o(path, True)
    g = gtsam.NonlinearFactorGraph(graph)
    first = min(initial.keys()) if initial.size() else 0
    g.add(gtsam.PriorFactorPose3(first, gtsam.Pose3(), gtsam.noiseModel.Diagonal.Variances(np.full(6, 1e-8))))
    try:
        t_init, est = _median(lambda: gtsam.InitializePose3.initialize(g), repeat)
    except RuntimeError as exc:
        text = " ".join(str(exc).split()) or type(exc).__name__
        return None, None, None, None, "GTSAM fails: " + (text[:60] + "…" if len(text) > 60 else text)
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(200)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    t = time.perf_counter()
    lm = gtsam.LevenbergMarquardtOptimizer(g, est, params).optimize()
    _ESTIMATES[path] = est
    return 2 * graph.error(est), t_init, 2 * graph.error(lm), time.perf_counter() - t, ""


#: InitializePose3's estimate per file (gtsam Values), for its χ² in g2o's cost.
_ESTIMATES = {}


def _g2o_row(name: str, path: str) -> dict:
    """The file in its own cost, g2o's: both routes, our refine3d, g2o's LM from it (g2opy: the minimum is the
    lower), and InitializePose3's estimate — every χ² g2o's own on the written file (``lago_cvx.peers``)."""
    import tempfile

    from lago_cvx import peers
    from lago_cvx.posegraph3d import chi2_3d

    graph = read_graph(path)
    seed, default = lago3d(graph, route="seed"), lago3d(graph)
    ref = refine3d(graph, default.t, default.R, **REFINE_LM)
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "est.g2o"
        write_graph(out, graph, ref)
        g2o = peers.g2o_chi2(out, iterations=100) if peers.have_g2o() else None
    est, init = _ESTIMATES.get(path), None
    if est is not None:
        keys = sorted(est.keys())
        t = np.array([est.atPose3(k).translation() for k in keys])
        R = np.array([est.atPose3(k).rotation().matrix() for k in keys])
        init = chi2_3d(graph, t, R)
    minimum = min(ref.chi2, g2o["chi2_lm"]) if g2o else ref.chi2
    return {"name": name, "seed": seed.chi2, "default": default.chi2, "refined": ref.chi2,
            "g2o_at": g2o["chi2_at"] if g2o else None, "g2o_lm": g2o["chi2_lm"] if g2o else None, "min": minimum,
            "init": init}


def _row(name, graph, path, repeat):
    ours = {}
    for route in ("seed", "default"):
        for w in ("isotropic", "anisotropic"):
            ours[route, w] = _median(lambda: lago3d(graph, route=route, weighting=w), repeat)
    best = ours["default", "isotropic"][1]
    t = time.perf_counter()
    ref = refine3d(graph, best.t, best.R, **REFINE_LM)
    t_ref = time.perf_counter() - t
    gi, gt, glm, glm_t, note = _gtsam(path, repeat)
    minimum = min(ref.chi2, glm) if glm is not None else ref.chi2
    return {"name": name, "n": graph.n_poses, "m": graph.n_edges, "ours": ours, "refined": ref.chi2, "refine_s": t_ref,
            "gtsam_init": gi, "gtsam_s": gt, "gtsam_lm": glm, "gtsam_lm_s": glm_t, "min": minimum, "note": note}


def _f(x, spec=".6g"):
    return "–" if x is None or not np.isfinite(x) else format(x, spec)


def render_g2o(rows) -> list[str]:
    lines = ["| graph | seed | default | InitializePose3 | refine3d (ours) / g2o's χ² of it / g2o's LM from it | "
             "minimum | default / min | default / InitializePose3 |\n|" + "---|" * 8]
    for r in rows:
        lines.append(f"| {r['name']} | {_f(r['seed'])} | **{_f(r['default'])}** | {_f(r['init'])} | "
                     f"{_f(r['refined'], '.10g')} / {_f(r['g2o_at'], '.10g')} / {_f(r['g2o_lm'], '.10g')} | "
                     f"{_f(r['min'])} | {_f(r['default'] / r['min'] if r['min'] > 1e-12 else None, '.4f')} | "
                     f"{_f(r['default'] / r['init'] if r['init'] else None, '.3f')} |")
    return lines


def render(rows, repeat, g2o_rows=()) -> str:
    head = ("| graph | poses | edges | seed iso | seed aniso | default iso | default aniso | InitializePose3 | "
            "minimum (ours / GTSAM LM) | default / min | default / InitializePose3 |\n|" + "---|" * 11)
    lines = [head]
    for r in rows:
        c = {k: v[1].chi2 for k, v in r["ours"].items()}
        d = c["default", "isotropic"]
        gi = r["gtsam_init"]
        lines.append(f"| {r['name']} | {r['n']} | {r['m']} | {_f(c['seed', 'isotropic'])} "
                     f"| {_f(c['seed', 'anisotropic'])} "
                     f"| **{_f(d)}** | {_f(c['default', 'anisotropic'])} | {_f(gi) if gi is not None else r['note']} | "
                     f"{_f(r['min'])} ({_f(r['refined'], '.10g')} / {_f(r['gtsam_lm'], '.10g')}) | "
                     f"{_f(d / r['min'] if r['min'] > 1e-12 else float('nan'), '.4f')} | "
                     f"{_f(d / gi if gi else None, '.3f')} |")
    times = ["| graph | seed iso | default iso | default aniso | InitializePose3 | ours / InitializePose3 (default) | "
             "refine3d (LM) | GTSAM LM |\n|" + "---|" * 8]
    for r in rows:
        o = r["ours"]
        gt = r["gtsam_s"]
        times.append(f"| {r['name']} | {o['seed', 'isotropic'][0]:.4f} | {o['default', 'isotropic'][0]:.4f} | "
                     f"{o['default', 'anisotropic'][0]:.4f} | {_f(gt, '.4f')} | "
                     f"{_f(o['default', 'isotropic'][0] / gt if gt else None, '.2f')} | {r['refine_s']:.3f} | "
                     f"{_f(r['gtsam_lm_s'], '.3f')} |")
    try:
        from importlib.metadata import version
        gv = version("gtsam")
    except Exception:
        gv = "not installed"
    return "\n".join([
        "# 3-D pose graphs: our initialization against GTSAM's InitializePose3",
        "",
        f"GTSAM {gv} (PyPI `gtsam`).",
        "",
        "χ² = Σ eᵀΩe with e = Log(T̃⁻¹T_i⁻¹T_j) (GTSAM's cost, no ½; exactly GTSAM's 2·error()). seed: chordal "
        "relaxation → exact positions; default: + one joint Gauss–Newton step, positions re-solved, guarded (χ² never "
        "above the seed's). iso / aniso: the chordal relaxation's weights (SE-Sync's κ, or the whole rotational "
        "information block). minimum: the smaller of our `refine3d` (LM from the default route) and GTSAM's LM from "
        "InitializePose3 (best found, not certified; the SE-Sync graphs' certificates: `lago-cvx certify`).",
        "",
        *lines,
        "",
        "## In the files' own cost, g2o's",
        "",
        "The same files read as they mean (`lago_cvx.conventions`: e = [translation of Z⁻¹X_i⁻¹X_j; x, y, z of its "
        "unit quaternion, w ≥ 0], g2o's `EDGE_SE3:QUAT`), default isotropic weighting. InitializePose3's estimate "
        "(above) measured in this cost; minimum: the lower of our `refine3d` and g2o's own Levenberg–Marquardt "
        "(g2opy, 100 iterations) from it; g2o's χ² of our written refined estimate beside ours.",
        "",
        *render_g2o(g2o_rows),
        "",
        f"## Times in process [s] (median of {repeat}; reading excluded)",
        "",
        *times,
        "",
    ])


def add_arguments(group) -> None:
    group.add_argument("--space-repeat", type=int, default=3, metavar="N",
                       help="timed runs per 3-D graph, median reported (default 3)")


def run(args) -> str:
    """Section ``space`` of benchmarks/run.py."""
    return measure(1 if args.quick else args.space_repeat)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    print(measure(args.repeat))
    return 0


def measure(repeat: int) -> str:
    args = argparse.Namespace(repeat=repeat)
    rows, g2o_rows = [], []
    root = datasets_dir()
    for rel in FILES:
        p = None if root is None else Path(root) / rel
        if p is None or not p.is_file():
            continue
        rows.append(_row(Path(rel).name, read_graph(p, cost="gtsam"), str(p), args.repeat))
        g2o_rows.append(_g2o_row(Path(rel).name, str(p)))
        print(rows[-1]["name"], file=sys.stderr)
    import tempfile
    for name, make in WORLDS.items():
        w = make()
        with tempfile.TemporaryDirectory() as d:
            p = Path(d) / "w.g2o"
            write_graph(p, w.graph)
            rows.append(_row(name, w.graph, str(p), args.repeat))
        print(name, file=sys.stderr)
    return render(rows, args.repeat, g2o_rows)


if __name__ == "__main__":
    raise SystemExit(main())
