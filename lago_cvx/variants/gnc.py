r"""Outlier-robust LAGO by graduated non-convexity (GNC; Yang, Antonante, Tzoumas, Carlone, RA-L 2020).

False loop closures make least squares fail: one edge with an error of metres pulls the whole estimate.
GNC minimizes a robust cost Σ_k ρ(r_k) of the whitened residuals r_k² = e_kᵀ Ω_k e_k (eq. (3) per edge,
3 dof), with ρ the truncated least squares (TLS) ρ(r) = min(r², c̄²) or Geman–McClure (GM)
ρ(r) = c̄² r² / (c̄² + r²), through a sequence of surrogates ρ_μ that start convex and end at ρ. By
Black–Rangarajan duality each surrogate is minimized by alternating

  (a) the weighted problem   x ← argmin_x Σ_k w_k e_k(x)ᵀ Ω_k e_k(x)   — here a **weighted LAGO**: the
      graph with Ω_k replaced by w_k Ω_k, w_k ∈ [0, 1]; its 2kπ regularization (tree and chordal
      relaxation) is redone on every solve, on the edges with w_k > ``drop_below`` only (an edge of weight
      ~0 must not decide a cycle's integer; were that subgraph disconnected, the edges of a maximum-weight
      spanning tree are added back with their small weights);
  (b) the weights in closed form (Yang et al., eqs. (14), (12)):

      TLS:  w_k = 1                                if r_k² ≤ μ/(μ+1) c̄²,
            w_k = c̄/r_k · √(μ(μ+1)) − μ             if μ/(μ+1) c̄² < r_k² < (μ+1)/μ c̄²,
            w_k = 0                                if r_k² ≥ (μ+1)/μ c̄²;
            μ₀ = c̄² / (2 r_max² − c̄²), μ ← 1.4 μ (ρ_μ → TLS as μ → ∞);
      GM:   w_k = (μ c̄² / (r_k² + μ c̄²))²,
            μ₀ = 2 r_max² / c̄², μ ← max(1, μ / 1.4) (ρ_μ → GM at μ = 1);

  with r_max the largest residual of the first (unweighted) LAGO. c̄² is the χ² quantile of the edge's
  degrees of freedom (3 planar, 6 in 3-D) at ``confidence`` (0.99 → 11.34 planar, 16.81 in 3-D): an inlier's
  whitened residual exceeds it with probability 1 − confidence.
  GNC runs only where the unweighted LAGO shows evidence of an outlier: a free edge with r_k² above the χ² quantile
  at 1 − (1 − confidence)/q over its q free edges (``RobustSettings.alarm_for``: one of q inliers passes it with
  probability at most 1 − confidence; 27.3 for M3500's 1 954 loop closures). Below it the graph is returned as
  LAGO gives it: at c̄² itself about 1 % of a clean graph's true edges would trip GNC, and TLS then drops true edges
  whose removal relaxes the rest by more than c̄² each (manhattan.g2o: 14 loop closures, χ² of the file × 4.2).
  GNC stops when the weights no longer change (TLS: all binary, the same set twice; GM: μ = 1 and the
  weights moved by less than ``weight_tolerance``) or after ``max_iterations``. The rejected edges — TLS:
  final weight < ½; GM, whose weights never reach 0: r_k² > c̄² at GNC's estimate, where the GM weight
  at μ = 1 is below ¼ — leave, and LAGO runs once more, unweighted, on the accepted edges: the result.

In 3-D (a ``PoseGraph3D``, ``lago_cvx.space``) the same loop runs around ``lago3d``: r_k² = e_kᵀ Ω_k e_k with
e_k (6,) the error of the graph's cost (g2o's or GTSAM's, ``lago_cvx.conventions``), and the weighted solve is
``lago3d`` on the graph with w_k Ω_k. There is no 2kπ to redo; the weights reach every stage through the
information: the chordal relaxation's S_ij² (isotropic κ_ij = 3 / (2 tr Ω_rr⁻¹) scales by w_k, and so does the
anisotropic weight), the positions' Ω_tt and the joint step's Ω (``robust3d``). Pairwise consistency is planar
(a 3-D run logs that it starts from LAGO).

Known inliers. Odometric edges (between consecutive ids) are never false loop closures in the usual
protocol; ``trust_odometry=None`` holds their weight at 1 whenever the odometric chain 0–1–…–(n−1) is
complete (as robust front ends tell GNC, e.g. Kimera-RPGO), ``True`` always, ``False`` never.

Where GNC ends at a local minimum. GNC minimizes the TLS cost Σ_k min(r_k², c̄²) only locally: on MIT (20 true
loop closures, 807 odometric edges, 82 false ones) it rejects about half the true loop closures, at a truncated
cost above the clean classification's. Three aids, ``RobustSettings``:

* ``local_search`` (default on, planar; bounded above ``LOCAL_SEARCH_MAX_EDGES`` loop closures): moves after GNC
  that lower the truncated cost over every edge (``_local_search``), only where GNC ran; on MIT + 5 % (seeds 0–2)
  they take GNC's truncated costs 524–602 to the clean classification's 506.7;
* ``readmit`` (default κ = 9, every size): the rejected edges within κ c̄² of fitting tried back together, taken
  when the truncated cost falls (smallGrid3D + 10 % by the seed route: 11 true edges rejected by GNC, 1 after);
* ``start="pcm"`` / ``"best"``: GNC from the odometry and a maximum clique of pairwise-consistent loop closures
  (``consistency``; Mangelson et al., ICRA 2018), or from both starts, each with its local moves, the lower
  truncated cost kept.

The truncation itself, calibrated (``RobustSettings(calibrate=κ)``, ``calibrated``, planar, opt-in): GNC again at
c̄² = min(c̄², κ · the largest r² of the trusted odometric edges), the lower truncated cost at that c̄² kept.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import OptionError, check_choice, check_integer, check_real
from ..graph import connected_components, minimum_spanning_edges
from ..metrics import whitened_errors
from ..posegraph import PoseGraph
from ..progress import Stages
from ..progress import held_back as _quiet  # the inner runs' records below ERROR, this thread only
from ..result import AcceptedEdges, LagoResult
from .consistency import consistent_start
from .engine import VariantResult

__all__ = ["RobustSettings", "RobustResult", "RobustVariantResult", "ROBUST_LOSSES", "robust_settings", "gnc_lago", "gnc_threshold",
           "gnc_weights", "odometric_chain_complete", "edge_r2", "truncated_cost"]

log = logging.getLogger("lago_cvx.variants")

#: Pairwise consistency (``start="pcm"`` / ``"best"``) is tested over every pair of loop closures, q(q − 1)/2 cycles,
#: and the clique search grows faster still: above this many loop closures GNC starts from LAGO alone (logged).
PCM_MAX_EDGES = 1000

#: The local search after GNC (``RobustSettings.local_search``) runs on graphs with at most this many loop closures
#: (edges not held at weight 1): each of its moves is one LAGO run.
LOCAL_SEARCH_MAX_EDGES = 500

#: The names ``lago(graph, robust=...)`` accepts, and the loss each means.
ROBUST_LOSSES = {"gnc-tls": "tls", "gnc-gm": "gm"}


@dataclass(frozen=True)
class RobustSettings:
    """Settings of GNC (module docstring).

    loss — ``"tls"`` (truncated least squares, default) or ``"gm"`` (Geman–McClure);
    confidence — c̄² = the χ² quantile of 3 dof (3-D graphs: 6) at this probability (default 0.99 → 11.34; 3-D
      16.81);
    threshold — c̄² given directly (whitened, squared; overrides ``confidence``);
    trust_odometry — None: hold odometric edges at weight 1 when the odometric chain is complete; True / False;
    mu_factor — μ's factor per iteration (1.4, Yang et al.);
    max_iterations — outer iterations at most (100);
    drop_below — edges with a weight at or below this leave the weighted solve (its 2kπ regularization too);
    weight_tolerance — a weight within this of 0 or 1 counts as binary; the GM stopping tolerance;
    start — where GNC starts: ``"lago"`` (the unweighted LAGO of every edge, Yang et al.), ``"pcm"`` (LAGO on the
      trusted odometry and a maximum clique of pairwise-consistent loop closures, ``consistency``; needs the
      odometric chain complete and trusted, else ``"lago"``), ``"best"`` (both, each followed by its local
      search and readmission; the result of the lower truncated cost Σ_k min(r_k², c̄²) over every edge is kept);
    clique_seconds — time allowed to the exact maximum-clique search (then the largest clique found);
    local_search — after GNC, at most this many LAGO runs of moves that lower the truncated cost (one edge
      toggled, or an accepted edge swapped for a rejected one, each followed by a descent; ``_local_search``),
      0: none. Only where GNC ran, the odometric chain is complete and trusted, and there are at most
      ``LOCAL_SEARCH_MAX_EDGES`` loop closures;
      on other planar graphs where GNC ran, toggles of the ``BOUNDED_TRIALS`` accepted edges of the largest r_k² (at
      most ``BOUNDED_RUNS`` LAGO runs; M3500 + 30 %, seed 0: 26 true loop closures accepted back); planar graphs
      only (in 3-D single-edge moves, judged at LAGO's estimates, rejected more true edges);
    readmit — κ: after GNC (and the local search), the rejected edges with r_k² ≤ κ c̄² at the estimate are tried
      back **together** (``_readmit``; one or two LAGO runs per round), the move kept when it lowers the truncated
      cost; 0: never. A group of true loop closures that only fit together is out of reach of single-edge moves;
    calibrate — None (default), or κ > 0: planar, GNC again at c̄² = min(c̄², κ · the largest r_k² of the trusted
      odometric edges) and the classification of the lower truncated cost at that c̄² kept (``calibrated``; κ = 4.7
      fitted on benchmarks/separable.md's files).
    """

    loss: str = "tls"
    confidence: float = 0.99
    threshold: float | None = None
    trust_odometry: bool | None = None
    mu_factor: float = 1.4
    max_iterations: int = 100
    drop_below: float = 1e-3
    weight_tolerance: float = 1e-4
    start: str = "lago"
    clique_seconds: float = 2.0
    local_search: int = 2000
    readmit: float = 9.0
    calibrate: float | None = None

    def __post_init__(self):
        check_choice("robust loss", self.loss, ("tls", "gm"))
        check_choice("robust start", self.start, ("lago", "pcm", "best"))
        if not (self.trust_odometry is None or isinstance(self.trust_odometry, (bool, np.bool_))):
            raise OptionError(f"trust_odometry must be None, True or False, got {self.trust_odometry!r}")
        checked = dict(confidence=check_real("robust confidence", self.confidence, low=0.0, high=1.0),
                       threshold=check_real("robust threshold", self.threshold, optional=True, low=0.0),
                       mu_factor=check_real("mu_factor", self.mu_factor, low=1.0),
                       max_iterations=check_integer("max_iterations", self.max_iterations, low=1),
                       drop_below=check_real("drop_below", self.drop_below, low=0.0, open_low=False, high=0.5),
                       weight_tolerance=check_real("weight_tolerance", self.weight_tolerance, low=0.0, high=0.5),
                       clique_seconds=check_real("clique_seconds", self.clique_seconds, low=0.0),
                       local_search=check_integer("local_search", self.local_search, low=0),
                       readmit=check_real("readmit", self.readmit, low=0.0, open_low=False),
                       calibrate=check_real("calibrate", self.calibrate, optional=True, low=0.0),
                       trust_odometry=None if self.trust_odometry is None else bool(self.trust_odometry))
        for name, value in checked.items():  # plain floats, ints and bools (NumPy scalars accepted)
            object.__setattr__(self, name, value)

    @property
    def c2(self) -> float:
        """c̄², the squared whitened residual at which TLS truncates, for planar edges (3 dof)."""
        return self.c2_for(2)

    def alarm_for(self, dim: int, q: int) -> float:
        """The largest r² the unweighted LAGO may show on its q free edges with GNC not run at all: the χ² quantile
        at 1 − (1 − confidence)/q, which one of q inliers exceeds with probability at most 1 − confidence
        (Bonferroni); never below c̄². With ``threshold`` given, c̄² itself."""
        if self.threshold is not None:
            return float(self.threshold)
        return max(self.c2_for(dim), gnc_threshold(1.0 - (1.0 - self.confidence) / max(q, 1), 3 if dim == 2 else 6))

    def c2_for(self, dim: int) -> float:
        """c̄² for the edges of a ``dim``-dimensional graph: 3 dof planar, 6 in 3-D (``threshold`` when given)."""
        if self.threshold is not None:
            return float(self.threshold)
        return gnc_threshold(self.confidence, 3 if dim == 2 else 6)


def robust_settings(robust) -> RobustSettings | None:
    """``lago``'s ``robust=`` as settings: None / False → None (off); True → the defaults (GNC-TLS);
    ``"gnc-tls"`` / ``"gnc-gm"``; a ``RobustSettings`` as it is. ``OptionError`` otherwise."""
    if robust is None or robust is False:
        return None
    if robust is True:
        return RobustSettings()
    if isinstance(robust, RobustSettings):
        return robust
    if isinstance(robust, str) and robust in ROBUST_LOSSES:
        return RobustSettings(loss=ROBUST_LOSSES[robust])
    raise OptionError(f"robust must be None, False, True, one of {tuple(ROBUST_LOSSES)} or a RobustSettings, "
                      f"got {robust!r}")


def gnc_threshold(confidence: float, dof: int = 3) -> float:
    """c̄² = the χ² quantile of ``dof`` degrees of freedom at ``confidence`` (0.99, 3 → 11.345)."""
    from scipy.stats import chi2  # loaded only by a robust run

    return float(chi2.ppf(confidence, dof))


def gnc_weights(r2: np.ndarray, mu: float, c2: float, loss: str) -> np.ndarray:
    """The weights w (m,) minimizing the GNC surrogate at the squared residuals r2 (m,) (module
    docstring, Yang et al. eqs. (14) TLS and (12) GM)."""
    r2 = np.asarray(r2, dtype=float)
    if loss == "gm":
        return (mu * c2 / (r2 + mu * c2)) ** 2
    w = np.ones_like(r2)
    lo, hi = mu / (mu + 1.0) * c2, (mu + 1.0) / mu * c2
    mid = (r2 > lo) & (r2 < hi)
    w[r2 >= hi] = 0.0
    w[mid] = np.sqrt(c2 / r2[mid]) * math.sqrt(mu * (mu + 1.0)) - mu
    return np.clip(w, 0.0, 1.0)


def odometric_chain_complete(graph) -> bool:
    """True when the edges between consecutive ids link every pose: the chain 0–1–…–(n−1) of the ids."""
    odo = graph.is_odometric
    lower = np.minimum(graph.ids[graph.tails[odo]], graph.ids[graph.heads[odo]])
    return np.unique(lower).size == graph.n_poses - 1


@dataclass(eq=False, repr=False)  # repr: LagoResult's few lines, with the robust one (``_describe``)
class RobustResult(AcceptedEdges, LagoResult):
    """A ``LagoResult`` of LAGO on the **accepted** edges (``graph`` is that subgraph, so ``chi2`` is over
    them; the poses are indexed as in the input), plus the GNC record: ``input_graph`` the graph given;
    ``rejected_edges`` (r,) int64 indices into its edges (file order); ``weights`` (m,) the final GNC
    weights, 1 or 0 for an edge the moves after GNC re-classified; ``settings``; ``iterations`` (outer);
    ``known_inliers`` (m,) bool the edges held at weight 1; ``history`` one dict per iteration (μ, number of edges
    of weight < ½, seconds)."""

    input_graph: PoseGraph | None = None
    rejected_edges: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    settings: RobustSettings | None = None
    iterations: int = 0
    known_inliers: np.ndarray | None = None
    history: list = field(default_factory=list)


    def _describe(self) -> tuple[str, list[str]]:
        head, lines = super()._describe()
        return head, [self._robust_line(), *lines]

    def _summary_rows(self) -> list:
        return super()._summary_rows() + [
            ("n_rejected", "edges rejected", int(self.rejected_edges.size)),
            ("robust_iterations", "GNC iterations", self.iterations)]


def gnc_lago(graph: PoseGraph, settings: RobustSettings, *, solve: Callable, final_solve: Callable | None = None,
             progress=None) -> RobustResult:
    """GNC around a weighted LAGO (module docstring). ``solve(graph) -> LagoResult`` is LAGO with the
    caller's options (``lago_cvx.pipeline.lago`` without ``robust``); it is called on the weighted graphs
    (same poses, fewer edges, scaled information) and once on the accepted edges (``final_solve`` instead, when
    given, for the result: another route than the classification's). ``progress(stage, fraction)``: the GNC
    iterations, then the local moves, each counted in LAGO runs (``progress.Stages``; INFO records likewise).
    With ``settings.start`` ``"pcm"`` GNC starts from the odometry and the maximum clique of pairwise-consistent
    loop closures instead of the unweighted LAGO; ``"best"`` runs from both and keeps the result of the lower
    truncated cost Σ_k min(r_k², c̄²) over every edge (``RobustSettings``); ``calibrate``: ``calibrated``. Returns a
    ``RobustResult``."""
    if settings.calibrate is not None:
        from .calibrated import calibrated_gnc

        return calibrated_gnc(graph, settings, edge_r2=edge_r2,
                              gnc=lambda g, s: gnc_lago(g, s, solve=solve, final_solve=final_solve, progress=progress))
    t0 = time.perf_counter()
    stages, lago_run = Stages(f"robust GNC-{settings.loss.upper()}", callback=progress, logger=log), solve

    def solve(g):  # every LAGO run of the robust run, counted for its progress
        stages.step()
        return lago_run(g)

    m, c2 = graph.n_edges, settings.c2_for(graph.dim)
    trust = settings.trust_odometry
    if trust is None:
        trust = odometric_chain_complete(graph)
    known = graph.is_odometric.copy() if trust else np.zeros(m, bool)
    starts = {"lago": ("lago",), "pcm": ("pcm",), "best": ("lago", "pcm")}[settings.start]
    if "pcm" in starts and graph.dim == 3:
        log.info("GNC: pairwise consistency is planar: GNC on a 3-D graph starts from LAGO")
        starts = ("lago",)
    elif "pcm" in starts and not (trust and odometric_chain_complete(graph)):
        log.info("GNC: no complete trusted odometric chain, so no pairwise consistency: GNC starts from LAGO")
        starts = ("lago",)
    elif "pcm" in starts and int((~known).sum()) > PCM_MAX_EDGES:
        log.info("GNC: %d loop closures, more than PCM_MAX_EDGES = %d: GNC starts from LAGO", int((~known).sum()),
                 PCM_MAX_EDGES)
        starts = ("lago",)
    with _quiet():  # the unweighted LAGO: where no residual passes the alarm, nothing is rejected, from any start
        first = solve(graph)
    alarm = settings.alarm_for(graph.dim, int((~known).sum()))
    if (~known).any() and float(edge_r2(graph, first.poses)[~known].max()) <= alarm:
        starts = ("lago",)
    runs = []
    for start in starts:  # each start's GNC and local moves; "best" compares the costs where each run ends
        w0 = (None if start == "lago"
              else consistent_start(graph, known, settings.c2_for(graph.dim), settings.clique_seconds))
        stages.stage(f"GNC iterations (start {start})", settings.max_iterations + 1)
        w, gnc_keep, final, it, history, cost = _gnc_run(graph, settings, solve, known, w0,
                                                         first if start == "lago" else None)
        stages.stage("local moves", settings.local_search + 1)
        keep, final, cost, moves = _moves(graph, gnc_keep.copy(), final, cost, known, settings, solve, trust, it)
        stages.finish()
        w = np.where(keep == gnc_keep, w, keep.astype(float))  # an edge the moves re-classified: weight 1 or 0
        runs.append((w, keep, final, it, history, cost, start, moves))
    w, keep, final, it, history, cost, start, moves = min(runs, key=lambda r: r[5])
    if final_solve is not None:
        final = final_solve(graph.subgraph_edges(keep))
    rejected = np.flatnonzero(~keep).astype(np.int64)
    timings = dict(final.timings)
    timings["robust"] = timings["total"] = time.perf_counter() - t0  # GNC's run, the final LAGO included
    log.info("GNC-%s (start %s): %d of %d edges rejected after %d iterations and %d local moves (c̄² = %.4g, "
             "truncated cost %.6g), %.3f s", settings.loss.upper(), start, rejected.size, m, it, moves, c2, cost,
             timings["robust"])
    fields = {f: getattr(final, f) for f in final.__dataclass_fields__}
    fields.update(timings=timings)
    return _result_type(final)(**fields, input_graph=graph, rejected_edges=rejected, weights=w, settings=settings,
                               iterations=it, known_inliers=known, history=history)


def _moves(graph, keep, final, cost, known, settings, solve, trust, it):
    """After a GNC run of ``it`` iterations (none: nothing to move): the local search (planar) and the readmission
    of ``settings``. Returns (keep, final LagoResult, cost, moves taken)."""
    moves = 0
    if settings.local_search and it > 0 and graph.dim == 2:
        full = trust and odometric_chain_complete(graph) and int((~known).sum()) <= LOCAL_SEARCH_MAX_EDGES
        keep, final, cost, moves = _local_search(graph, keep, final, cost, known, settings, solve, full)
    if settings.readmit and it > 0:
        keep, final, cost, regained = _readmit(graph, keep, final, cost, known, settings, solve)
        moves += regained
    return keep, final, cost, moves


def _local_search(graph, keep, final, cost, known, settings, solve, full):
    """Moves on GNC's classification that lower the truncated cost Σ_k min(r_k², c̄²) over every edge, at the LAGO
    estimate of the accepted edges; each move ends in a descent (``_descend``), and is taken when the cost falls:

      toggle — one edge changes class (a rejected edge accepted, tried from the smallest r_k²; an accepted one not
        known rejected, from the largest) and is held there while the others re-classify;
      swap   — an accepted edge a rejected and, of the rejected edges, each of the ``SWAP_CANDIDATES`` that fit
        best at the estimate without a, accepted in its place (both held): a false loop closure that fits
        beside some true ones but not beside another (MIT + 5 %: 60→39 fits with 58→29, not with 338→61) is
        out of reach of one toggle.

    Toggles first; swaps when no toggle helps; after a move taken, toggles again. Until no move helps or
    ``settings.local_search`` LAGO runs are spent. Not ``full`` (graphs too large for these moves): toggles of the
    ``BOUNDED_TRIALS`` accepted edges of the largest r_k² only, no swap, at most ``BOUNDED_RUNS`` LAGO runs (M3500 +
    30 %, seed 0: two toggles bring 26 rejected true loop closures back). Returns (keep, final LagoResult, cost,
    moves taken)."""
    c2, moves = settings.c2_for(graph.dim), 0
    budget = [settings.local_search if full else min(settings.local_search, BOUNDED_RUNS)]
    keep, final, cost = _descend(graph, keep, final, cost, known, c2, solve, budget, held=[])
    while budget[0] > 0:
        r2 = edge_r2(graph, final.poses)
        rejected, accepted = np.flatnonzero(~keep), np.flatnonzero(keep & ~known)
        order = accepted[np.argsort(-r2[accepted], kind="stable")]
        order = np.r_[order, rejected[np.argsort(r2[rejected], kind="stable")]] if full else order[:BOUNDED_TRIALS]
        trials, found = [[k] for k in order] + ([None] if full else []), None  # then the swaps
        for held in trials:
            found = (_toggle(graph, keep, held, cost, known, c2, solve, budget) if held is not None
                     else _swap(graph, keep, final, cost, known, c2, solve, budget))
            if found is not None or budget[0] <= 0:
                break
        if found is None:
            break
        keep, final, cost = found
        moves += 1
    return keep, final, cost, moves


#: On planar graphs too large for the full local search: accepted edges toggled, LAGO runs at most; rejected
#: edges tried by a swap for each accepted edge taken out (those that fit best without it).
BOUNDED_TRIALS, BOUNDED_RUNS, SWAP_CANDIDATES = 5, 100, 1


def _toggle(graph, keep, held, cost, known, c2, solve, budget):
    """The edges ``held`` change class, then ``_descend``: (keep, LagoResult, cost) when the cost falls, else None."""
    trial = keep.copy()
    trial[held] = ~trial[held]
    return _lower(graph, trial, cost, known, c2, solve, budget, held)


def _swap(graph, keep, final, cost, known, c2, solve, budget):
    """The swap moves of ``_local_search`` (accepted edges from the largest r_k²): the first that lowers the cost, as
    (keep, LagoResult, cost), or None."""
    r2 = edge_r2(graph, final.poses)
    accepted = np.flatnonzero(keep & ~known)
    for a in accepted[np.argsort(-r2[accepted], kind="stable")]:
        if budget[0] <= 0:
            return None
        without = keep.copy()
        without[a] = False
        if connected_components(sub := graph.subgraph_edges(without))[0] > 1:
            continue
        with _quiet():
            res = solve(sub)
        budget[0] -= 1
        r2a = edge_r2(graph, res.poses)
        rejected = np.flatnonzero(~without)
        rejected = rejected[rejected != a]
        for b in rejected[np.argsort(r2a[rejected], kind="stable")][:SWAP_CANDIDATES]:
            trial = without.copy()
            trial[b] = True
            found = _lower(graph, trial, cost, known, c2, solve, budget, [a, b])
            if found is not None:
                return found
            if budget[0] <= 0:
                return None
    return None


def _lower(graph, trial, cost, known, c2, solve, budget, held):
    """LAGO on ``trial``, then ``_descend`` with ``held`` fixed, then without: (keep, LagoResult, cost) when the cost
    ends below ``cost``, else None (also when the edges of ``trial`` do not link every pose)."""
    if connected_components(sub := graph.subgraph_edges(trial))[0] > 1:
        return None
    with _quiet():
        res = solve(sub)
    budget[0] -= 1
    c = truncated_cost(graph, res.poses, c2)
    trial, res, c = _descend(graph, trial, res, c, known, c2, solve, budget, held)
    if not c < cost * (1.0 - 1e-12) and held:
        trial, res, c = _descend(graph, trial, res, c, known, c2, solve, budget, held=[])
    return (trial, res, c) if c < cost * (1.0 - 1e-12) else None


def _descend(graph, keep, res, cost, known, c2, solve, budget, held):
    """Alternate the two halves of min Σ_k min(r_k², c̄²): the classification at the estimate (accept r_k² ≤ c̄²,
    the known inliers and the ``held`` edges as they are) and LAGO on it, while the cost falls (at most 20 rounds,
    the accepted edges linking every pose). Returns (keep, LagoResult, cost)."""
    for _ in range(20):
        new = known | (edge_r2(graph, res.poses) <= c2)
        new[held] = keep[held]
        if (budget[0] <= 0 or np.array_equal(new, keep)
                or connected_components(sub := graph.subgraph_edges(new))[0] > 1):  # the subgraph built once
            break
        with _quiet():
            trial = solve(sub)
        budget[0] -= 1
        c = truncated_cost(graph, trial.poses, c2)
        if not c < cost:
            break
        keep, res, cost = new, trial, c
    return keep, res, cost


def _readmit(graph, keep, final, cost, known, settings, solve):
    """Rejected edges tried back together: C = {k rejected : r_k² ≤ κ c̄²} at the current estimate (κ =
    ``settings.readmit``); LAGO on the accepted edges and C, then, where some of C still do not fit (r_k² > c̄²),
    LAGO again on the accepted edges and those of C that fit. The move is kept when it lowers the truncated cost
    Σ_k min(r_k², c̄²) over every edge; rounds until none does (at most 10). Returns (keep, final LagoResult, cost,
    edges re-admitted)."""
    c2, gained = settings.c2_for(graph.dim), 0
    for _ in range(10):
        cand = ~keep & (edge_r2(graph, final.poses) <= settings.readmit * c2)
        if not cand.any():
            break
        with _quiet():
            trial_keep = keep | cand
            trial = solve(graph.subgraph_edges(trial_keep))
            fits = cand & (edge_r2(graph, trial.poses) <= c2)
            if not fits.any():
                break
            if not np.array_equal(fits, cand):
                trial_keep = keep | fits
                trial = solve(graph.subgraph_edges(trial_keep))
        c = truncated_cost(graph, trial.poses, c2)
        if not c < cost * (1.0 - 1e-12):
            break
        gained += int(trial_keep.sum() - keep.sum())
        keep, final, cost = trial_keep, trial, c
    if gained:
        log.info("GNC: %d rejected edges re-admitted together (truncated cost %.6g)", gained, cost)
    return keep, final, cost, gained


def edge_r2(graph, poses) -> np.ndarray:
    """r_k² = e_kᵀ Ω_k e_k (m,) of every edge at ``poses``: planar (n, 3), eq. (3)'s error in the graph's cost; 3-D
    (t (n, 3), R (n, 3, 3)), the 6-vector error of the graph's cost (``posegraph3d.edge_errors3d``)."""
    if graph.dim == 3:
        from ..posegraph3d import edge_errors3d

        e = edge_errors3d(graph, *poses)
        return np.einsum("ka,kab,kb->k", e, graph.information, e)
    return whitened_errors(graph, poses) ** 2


def truncated_cost(graph: PoseGraph, poses, c2: float) -> float:
    """The TLS cost Σ_k min(r_k², c̄²) of every edge at ``poses`` (``edge_r2``)."""
    return float(np.minimum(edge_r2(graph, poses), c2).sum())


def _gnc_run(graph, settings, solve, known, w0, first=None):
    """One GNC from the unweighted LAGO (``w0`` None; ``first`` that LAGO when already run) or from the weighted
    one with weights ``w0``: (w, keep, final LagoResult on the accepted edges, iterations, history, truncated
    cost at the final estimate)."""
    m, c2 = graph.n_edges, settings.c2_for(graph.dim)
    with _quiet():  # the inner runs' warnings (ambiguous 2kπ roundings of false edges) are not the result's
        res = first if first is not None else solve(graph if w0 is None else _weighted(graph, w0, settings.drop_below))
        r2 = edge_r2(graph, res.poses)
    free = ~known
    r_max2 = float(r2[free].max()) if free.any() else 0.0
    w = np.ones(m)
    history, it = [], 0
    if r_max2 > (settings.alarm_for(graph.dim, int(free.sum())) if w0 is None else c2):  # else: no outlier in sight
        if w0 is not None:  # from a consistent set: μ₀ of its own largest residual (never past 1, TLS)
            inner = free & (w0 > 0.5)
            r_start2 = float(r2[inner].max()) if inner.any() else r_max2
            mu = c2 / max(2.0 * r_start2 - c2, c2) if settings.loss == "tls" else max(1.0, 2.0 * r_start2 / c2)
        elif settings.loss == "tls":
            mu = c2 / max(2.0 * r_max2 - c2, 1e-12)
        else:
            mu = 2.0 * r_max2 / c2
        prev = None
        for it in range(1, settings.max_iterations + 1):
            t = time.perf_counter()
            w = gnc_weights(r2, mu, c2, settings.loss)
            w[known] = 1.0
            if _converged(w, prev, mu, settings):
                history.append(dict(mu=mu, n_outliers=int((w < 0.5).sum()), seconds=time.perf_counter() - t))
                break
            prev = w
            with _quiet():
                res = solve(_weighted(graph, w, settings.drop_below))
            r2 = edge_r2(graph, res.poses)
            history.append(dict(mu=mu, n_outliers=int((w < 0.5).sum()), seconds=time.perf_counter() - t))
            mu = mu * settings.mu_factor if settings.loss == "tls" else max(1.0, mu / settings.mu_factor)
        else:
            log.warning("GNC-%s stopped after max_iterations = %d without converging (weights still moving); "
                        "edges are classified by their last weights", settings.loss.upper(), settings.max_iterations)
    # TLS ends with binary weights; GM's never reach 0: an edge is rejected where its residual at GNC's
    # estimate exceeds c̄² (there GM's weight at μ = 1 has fallen below ¼)
    keep = (w >= 0.5) if settings.loss == "tls" else (r2 <= c2)
    keep[known] = True
    accepted = graph.subgraph_edges(keep)
    k, _ = connected_components(accepted)
    if k > 1:  # the accepted edges must still link every pose: add back a maximum-weight spanning tree
        keep[minimum_spanning_edges(graph, 1.0 - w)] = True
        accepted = graph.subgraph_edges(keep)
    final = solve(accepted)
    return w, keep, final, it, history, truncated_cost(graph, final.poses, c2)


def _converged(w: np.ndarray, prev: np.ndarray | None, mu: float, settings: RobustSettings) -> bool:
    """TLS: every weight binary and the same set as the previous iteration; GM: μ = 1 and the weights
    moved by less than the tolerance."""
    if prev is None:
        return False
    tol = settings.weight_tolerance
    if settings.loss == "tls":
        binary = np.all((w <= tol) | (w >= 1.0 - tol))
        return bool(binary and np.array_equal(w >= 0.5, prev >= 0.5))
    return mu <= 1.0 and float(np.max(np.abs(w - prev))) < tol


def _weighted(graph: PoseGraph, w: np.ndarray, drop_below: float) -> PoseGraph:
    """The graph of the weighted solve: edges with w_k > ``drop_below``, information w_k Ω_k; if they do
    not link every pose, a maximum-weight spanning tree is added back (weights floored at ``drop_below``,
    or 10⁻⁶ when that is 0)."""
    keep = w > drop_below
    sub = graph.subgraph_edges(keep)
    if connected_components(sub)[0] > 1:
        keep[minimum_spanning_edges(graph, 1.0 - w)] = True
    ww = np.maximum(w[keep], drop_below or 1e-6)
    sub = graph.subgraph_edges(keep)
    kept = {"given_information": None} if "given_information" in sub.OPTIONAL_MEASUREMENTS else {}
    return replace(sub, information=sub.information * ww[:, None, None], **kept)


@dataclass(eq=False, repr=False)
class RobustVariantResult(RobustResult, VariantResult):
    """A ``RobustResult`` whose inner runs were the variants engine's (``anchors=``): every field of a
    ``VariantResult`` (anchors, strain …) and of a ``RobustResult``."""


def _result_type(final) -> type:
    """``RobustVariantResult`` for a ``VariantResult``, ``Robust3DResult`` for a ``Lago3DResult``, else
    ``RobustResult``."""
    from .robust3d import Robust3DResult

    if getattr(final, "dim", 2) == 3:
        return Robust3DResult
    return RobustVariantResult if isinstance(final, VariantResult) else RobustResult
