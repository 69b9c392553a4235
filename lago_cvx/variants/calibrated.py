r"""GNC with the truncation c̄² calibrated on the trusted odometry (``RobustSettings(calibrate=κ)``, planar).

Why. With c̄² = χ²₃(0.99) = 11.34, GNC keeps a false loop closure whose cost change on removal Δχ²_k is below
c̄² (for one edge at a time, rejecting k lowers Σ min(r², c̄²) when Δχ²_k > c̄²). On graphs whose information is
loose for their residuals (intel, M3500: the largest r² of a true edge at the optimum is 0.6 and 0.2) false edges
with Δχ² of 2.5–8 then fit; on others (MIT, CSAIL) true loop closures have Δχ² up to 5.5 and a small c̄² drops
them. The odometric edges are known inliers, and their largest r² measures the file's own scale:

    c̄²_cal = min(c̄², κ · max_{k odometric} r_k²)     at the estimate of the default run,

then GNC (with its local search and re-admission) runs again at c̄²_cal. The two classifications are judged by the
truncated cost at c̄²_cal over every edge, Σ_k min(r_k², c̄²_cal), and the lower one is returned: where GNC at the
smaller c̄² ends at a worse local minimum (MIT + 10 %, seed 3: 8 true loop closures rejected) the default run's
classification is kept.

Measured (``python benchmarks/run.py separable``: intel, M3500, CSAIL, MIT at 10 % and 30 %, seeds 0–5), κ = 4.7:
39 of 48 runs pass (every false edge rejected, ≤ 1 % of the true ones, χ² of the clean edges after refinement
within 0.1 %) against the default's 30 — intel 9 of 12 (6), M3500 12 (7), CSAIL 12 (12), MIT 6 (5). κ was chosen
on seeds 0–2, where it must lie in about 4.45–4.90 (MIT + 10 %, seed 2 passes only at c̄² ≥ 6.7; intel + 10 %,
seed 1 only at c̄² ≤ 2.66), so it is a value fitted to these four files, not a law (seeds 3–5, not used to choose
it: 18 of 24 runs pass against the default's 14). It runs GNC twice. In 3-D the rule does not pay: the false edges
GNC keeps on parking-garage bend the odometry itself, so its largest odometric r² is no scale. No false edge whose
Δχ² is below a true loop closure's can be rejected this way (``lago_cvx.experiments.removal_costs``). Needs trusted odometric edges (``trust_odometry``), and acts only where
GNC ran (the default run's alarm); otherwise the default run is returned. Planar graphs only (``OptionError`` in
3-D).
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace

import numpy as np

from ..errors import OptionError

log = logging.getLogger("lago_cvx.variants")


def calibrated_gnc(graph, settings, *, gnc, edge_r2):
    """``gnc(graph, settings)`` at the default c̄², then at c̄²_cal (module docstring); the result of the lower
    truncated cost at c̄²_cal (``edge_r2(graph, poses)``: r_k² (m,), ``gnc.edge_r2``). Its ``settings`` are those of
    the run returned (``threshold`` = c̄²_cal when the calibrated run wins); ``timings["robust"]`` covers both."""
    if graph.dim != 2:
        raise OptionError("RobustSettings(calibrate=...): planar graphs only (the 3-D truncation is χ²₆'s quantile)")
    t0 = time.perf_counter()
    base = gnc(graph, replace(settings, calibrate=None))
    known = base.known_inliers
    if base.iterations == 0 or not known.any():
        log.info("GNC calibration: %s, the default run is the result",
                 "GNC did not run (no alarm)" if base.iterations == 0 else "no trusted odometry")
        return base
    c2 = min(base.settings.c2_for(2), settings.calibrate * float(edge_r2(graph, base.poses)[known].max()))
    other = gnc(graph, replace(settings, calibrate=None, threshold=c2))
    costs = [float(np.minimum(edge_r2(graph, r.poses), c2).sum()) for r in (base, other)]  # Σ_k min(r_k², c̄²)
    pick = other if costs[1] <= costs[0] else base
    pick.timings["robust"] = pick.timings["total"] = time.perf_counter() - t0
    log.info("GNC calibration: c̄² = %.4g (κ = %g); truncated cost at it %.6g (default c̄²) against %.6g: the %s "
             "run kept, %d edges rejected", c2, settings.calibrate, *costs,
             "calibrated" if pick is other else "default", np.asarray(pick.rejected_edges).size)
    return pick
