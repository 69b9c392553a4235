"""Section ``perf`` of ``python benchmarks/run.py``: the LAGO step against GTSAM's ``lago.initialize``,
step by step, in one process, and the marginal covariances.

For se-sync/city10000.g2o and carlone/input_M3500_g2o.g2o: ``--repeat`` interleaved runs (ours default
route, ours seed route, GTSAM) and their medians — interleaving keeps the ratio meaningful on a machine
whose speed drifts. Then ``res.pose_covariances()`` (selected inversion on phase 3's factor, eq. (T) of
``lago_cvx.multifrontal``) on city10000 and on a 100 000-pose Manhattan world.
"""

from __future__ import annotations

import statistics
import time

import _bench
from lago_cvx import lago, manhattan_world
from lago_cvx.peers import gtsam_factor_graph, gtsam_lago, have_gtsam

FILES = ("se-sync/city10000.g2o", "carlone/input_M3500_g2o.g2o")
STEPS = ("tree", "regularization", "phase1", "phase2", "phase3", "positions", "total")
COV_WORLD = 100_000


def add_arguments(group) -> None:
    group.add_argument("--cov-poses", type=int, default=None,
                       help=f"poses of the synthetic world timed for pose_covariances (default {COV_WORLD})")


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
        "(Takahashi's recurrences on the multifrontal factor, `lago_cvx.multifrontal`), median of "
        f"{max(1, args.repeat // 2)} run(s) (the world: one run).", "",
        _bench.table(["graph", "poses", "pose_covariances [s]"], cov_rows),
    ])
