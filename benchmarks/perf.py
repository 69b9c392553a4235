"""Section ``perf`` of ``python benchmarks/run.py``: the LAGO step against GTSAM's ``lago.initialize``,
step by step, in one process, and the marginal covariances.

For se-sync/city10000.g2o, carlone/input_M3500_g2o.g2o and the ≈1 000-pose graphs MIT, CSAIL and
input_INTEL (where a fixed cost would show): ``--repeat`` interleaved runs (ours default
route, ours seed route, GTSAM) and their medians — interleaving keeps the ratio meaningful on a machine
whose speed drifts. Then ``res.pose_covariances()`` (selected inversion on phase 3's factor, eq. (T) of
``lago_cvx.sparse.multifrontal``) on city10000 and on a 100 000-pose Manhattan world. Last, phase 3's solve
(factor, refined solve; the engine's symbolic analysis included) by the engine's one factorization in C, by its
NumPy fallback and by ``qdldl.Solver`` (QDLDL after its own AMD of the scalar matrix) on city10000 and on
Manhattan worlds up to 1 000 000 poses.
"""

from __future__ import annotations

import statistics
import time

import _bench
import numpy as np

from lago_cvx import lago, manhattan_world
from lago_cvx.sparse import compiled
from lago_cvx.sparse.normal_equations import GraphElimination
from lago_cvx.peers import gtsam_factor_graph, gtsam_lago, have_gtsam

FILES = ("se-sync/city10000.g2o", "carlone/input_M3500_g2o.g2o", "se-sync/MIT.g2o", "se-sync/CSAIL.g2o",
         "carlone/input_INTEL_g2o.g2o")
STEPS = ("tree", "regularization", "phase1", "phase2", "phase3", "positions", "total")
COV_WORLD = 100_000
ENGINE_WORLDS = (30_000, 100_000, 300_000, 1_000_000)


def add_arguments(group) -> None:
    group.add_argument("--cov-poses", type=int, default=None,
                       help=f"poses of the synthetic world timed for pose_covariances (default {COV_WORLD})")
    group.add_argument("--engine-poses", type=int, nargs="*", default=None,
                       help="Manhattan worlds on which phase 3's solve is timed by the engine (C and NumPy) and "
                            f"multifrontal engine (default {' '.join(map(str, ENGINE_WORLDS))})")


def _have_cholmod() -> bool:
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def _cholmod_blas() -> str:
    """The BLAS the loaded CHOLMOD uses, as threadpoolctl sees it: a BLAS library loaded from outside
    NumPy's and SciPy's wheels (the system's, which SuiteSparse links to)."""
    from threadpoolctl import threadpool_info

    libs = [f"{i['internal_api']} {i.get('version') or ''} ({i['filepath']})"
            for i in threadpool_info() if i["user_api"] == "blas" and ".libs" not in i["filepath"]]
    return "; ".join(libs) or "no optimized BLAS threadpoolctl recognizes (Debian's reference BLAS?)"


def phase3_cholmod(system, repeat: int) -> float:
    """Seconds of the same solve by CHOLMOD (the ``cholmod`` extra): MᵀM formed, factored (supernodal,
    its default ordering) and refined by ``linalg.solve_least_squares``; median of ``repeat``."""
    from lago_cvx.sparse.linalg import solve_least_squares

    M = system.sparse()
    c = system.c.reshape(-1)
    return _bench.median_time(lambda: solve_least_squares(M, c, backend="cholmod"), repeat)[0]


#: Largest world whose phase 3 is also timed through ``qdldl.Solver`` and the NumPy fallback: above it they take
#: minutes and decide nothing.
SOLVER_MAX_POSES = 300_000


def phase3_solvers(graph, repeat: int, *, cholmod: bool) -> tuple[float, float, float, float, float]:
    """Seconds of phase 3's solve (eq. (15), seed route) by the engine in C (fresh symbolic analysis each run: plan,
    layout, assembler), by its NumPy fallback and by ``qdldl.Solver`` on MᵀM (nan above ``SOLVER_MAX_POSES``), by
    CHOLMOD (nan unless ``cholmod``), medians of ``repeat``; and the largest difference of the C and ``qdldl.Solver``
    solutions relative to ‖x‖∞. One LAGO run provides the system all of them solve."""
    import qdldl
    import scipy.sparse as sp

    from lago_cvx.sparse.linalg import refine_normal_equations

    res = lago(graph, route="seed")
    system = res.phase2.edges
    a = res.anchor_index
    out, xs = {}, {}
    small = graph.n_poses <= SOLVER_MAX_POSES
    for mode in ["c"] + (["numpy", "solver"] if small else []):
        def once():
            if mode == "solver":
                M = system.sparse()
                c = system.c.reshape(-1)
                t = time.perf_counter()
                f = qdldl.Solver(sp.triu(M.T @ M, format="csc"), upper=True)
                x = refine_normal_equations(f.solve, M.dot, M.T.dot, c)[0]
                return time.perf_counter() - t, x.reshape(-1, 3)
            el = GraphElimination(graph, a)
            t = time.perf_counter()
            x, _, _ = el.solve(system)
            return time.perf_counter() - t, x
        saved = list(compiled._C_KERNELS)
        if mode == "numpy":
            compiled._C_KERNELS[:] = [None]  # as after an install without a C compiler
        try:
            runs = [once() for _ in range(repeat)]
        finally:
            compiled._C_KERNELS[:] = saved
        out[mode] = statistics.median(r[0] for r in runs)
        xs[mode] = runs[-1][1]
    diff = float(np.abs(xs["c"] - xs["solver"]).max() / np.abs(xs["solver"]).max()) if small else float("nan")
    tc = phase3_cholmod(system, repeat) if cholmod else float("nan")
    return out["c"], out.get("numpy", float("nan")), out.get("solver", float("nan")), tc, diff


def run(args) -> str:
    skipped = _bench.datasets_skipped()
    _bench.warm_up()
    gt = have_gtsam()
    rows, cov_rows = [], []
    for rel, g in ([] if skipped else _bench.each_dataset(FILES)):
        fg = gtsam_factor_graph(g) if gt else None
        ours, seed, gtsam = {}, [], []
        lago(g), lago(g, route="seed")
        for _ in range(args.repeat):
            res = lago(g)
            for k in STEPS:
                ours.setdefault(k, []).append(res.timings[k])
            t = time.perf_counter()
            lago(g, route="seed")
            seed.append(time.perf_counter() - t)
            if gt:
                gtsam.append(gtsam_lago(g, factor_graph=fg)[1])
        med = {k: 1e3 * statistics.median(v) for k, v in ours.items()}
        tg = 1e3 * statistics.median(gtsam) if gt else float("nan")
        rows.append([rel, *(f"{med[k]:.1f}" for k in STEPS), f"{1e3 * statistics.median(seed):.1f}",
                     _bench.fmt(tg, ".1f"), _bench.fmt(med["total"] / tg, ".2f"),
                     _bench.fmt(1e3 * statistics.median(seed) / tg, ".2f"), f"{res.chi2:.6g}"])
        print("  " + " | ".join(rows[-1]), flush=True)
        if rel == FILES[0]:
            t, _ = _bench.median_time(res.pose_covariances, max(1, args.repeat // 2))
            cov_rows.append([rel, g.n_poses, f"{t:.3f}"])
    n = args.cov_poses or (10_000 if args.quick else COV_WORLD)
    w = manhattan_world(n, seed=0).graph
    res = lago(w)
    t, _ = _bench.median_time(res.pose_covariances, 1)
    cov_rows.append([f"manhattan_world({n}, seed=0)", n, f"{t:.3f}"])
    print("  " + " | ".join(map(str, cov_rows[-1])), flush=True)
    eng_rows = []
    cholmod = _have_cholmod()
    blas = _cholmod_blas() if cholmod else "CHOLMOD not installed"
    graphs = [] if skipped else [(rel, g) for rel, g in _bench.each_dataset(FILES[:1])]
    sizes = args.engine_poses if args.engine_poses is not None else ((10_000, 30_000) if args.quick else ENGINE_WORLDS)
    graphs += [(f"manhattan_world({n}, seed=0)", None, n) for n in sizes]
    for item in graphs:
        name, g = item[0], item[1]
        if g is None:
            g = manhattan_world(item[2], seed=0).graph
        reps = args.repeat if g.n_poses <= 100_000 else 1
        tc_, tn, ts, tc, diff = phase3_solvers(g, reps, cholmod=cholmod)
        eng_rows.append([name, g.n_poses, 3 * (g.n_poses - 1), f"{tc_:.3f}", _bench.fmt(tn, ".3f"),
                         _bench.fmt(ts, ".3f"), _bench.fmt(tc, ".3f"), _bench.fmt(tc_ / ts, ".2f"),
                         _bench.fmt(diff, ".1e")])
        print("  " + " | ".join(map(str, eng_rows[-1])), flush=True)
        del g
    head = ["file", *(f"{k} [ms]" for k in STEPS), "seed route [ms]", "GTSAM initialize [ms]", "default / GTSAM",
            "seed / GTSAM", "χ² default"]
    return "\n".join([
        "# LAGO against GTSAM's lago.initialize, in process", "",
        f"Medians of {args.repeat} interleaved runs (ours default route, ours seed route, GTSAM), wall clock, "
        "file reading excluded; GTSAM gets diagonal noise models and a prior (`lago_cvx.peers`), only "
        "`initialize` is timed. phase1 includes the pose-level analysis shared by every system (AMD and the "
        "factorization of Ω_θ).", "",
        skipped or _bench.table(head, rows), "",
        "## Marginal covariances", "",
        "`res.pose_covariances()`: every 3×3 pose block of phase 3's (Ω*)⁻¹ by selected inversion "
        "(Takahashi's recurrences on phase 3's own multifrontal factor, `lago_cvx.sparse.block_factor`), median of "
        f"{max(1, args.repeat // 2)} run(s) (the world: one run).", "",
        _bench.table(["graph", "poses", "pose_covariances [s]"], cov_rows), "",
        "## Phase 3's solve: the engine against qdldl.Solver", "",
        "Phase 3 of the seed route (eq. (15), 3(n − 1) unknowns): factorization and refined solve by the engine's "
        "one factorization in C (`lago_cvx.sparse.compiled`; its symbolic analysis — plan, layout, assembler — "
        "timed too), by its NumPy fallback (`lago_cvx.sparse.block_factor`, an install without a C compiler) and by "
        f"`qdldl.Solver` on MᵀM (QDLDL after its own AMD; both – above {SOLVER_MAX_POSES:,} poses), median of "
        f"{args.repeat} runs up to 100 000 poses, one run above. rel. diff = ‖x_C − x_qdldl‖∞ / ‖x_qdldl‖∞. CHOLMOD "
        "(the optional "
        "`cholmod` extra, `backend=\"cholmod\"`: MᵀM formed, supernodal factorization, the same refinement; "
        "– when scikit-sparse is not installed) runs on whatever BLAS the system's SuiteSparse is linked "
        "to: on Debian that is the reference BLAS unless an optimized one is installed "
        f"(`apt-get install libopenblas0-pthread`). In this run: {blas}.", "",
        _bench.table(["graph", "poses", "unknowns", "engine, C [s]", "engine, NumPy [s]", "qdldl.Solver [s]",
                      "CHOLMOD [s]", "C / qdldl.Solver", "rel. diff"], eng_rows),
    ])
