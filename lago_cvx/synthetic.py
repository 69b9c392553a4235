"""Seeded synthetic pose-graph worlds with ground truth.

These are the project's embedded data: demos and most tests run on them, so no real dataset is
needed. Every generator

* takes a ``seed`` and draws all randomness from one ``np.random.default_rng(seed)``, so the same
  arguments give bit-identical arrays (on the same NumPy version);
* is vectorized (the Manhattan random walk is a tight scalar loop over pre-drawn random numbers;
  loop-closure search uses ``scipy.spatial.cKDTree``), so 100 000 poses build in well under a
  couple of seconds;
* returns a :class:`SyntheticWorld`: the :class:`~lago_cvx.posegraph.PoseGraph` (measurements as a
  real front end would report them) plus the true poses and the generator parameters.

Measurement conventions (shared by all generators, see :func:`add_noise`)
-----------------------------------------------------------------------
An edge ``i → j`` (tail ``i``, head ``j``) measures pose ``j`` in the frame of pose ``i``:
``z = between(truth[i], truth[j]) + n`` with ``n ~ N(0, Σ)`` added to ``(Δx, Δy, δ)`` in the frame of
the tail, and the orientation ``δ`` is then **wrapped to [−π, π)** — for odometry and loop closures
alike, exactly like a real sensor. (The true unwrapped θ_j − θ_i of a loop closure can be e.g.
4π + π/2; only its wrapped value is stored. This is what makes LAGO's 2kπ regularization
necessary.) The information matrix is ``Ω = Σ_info⁻¹``:

* ``information="diagonal"`` (default): ``Ω = diag(1/σx², 1/σx², 1/σθ²)``;
* ``information="full"``: each edge gets its own seeded random correlation matrix ``C`` (all
  cross terms x–y, x–θ, y–θ non-zero) and ``Σ = S C S`` with ``S = diag(σx, σx, σθ)``; the noise is
  drawn with exactly that covariance.

The information uses ``info_sigma_xy`` / ``info_sigma_theta``, which default to the noise sigmas.
A noiseless world (``sigma_xy=0`` and/or ``sigma_theta=0``, giving *exactly* noiseless
measurements) still needs finite information: the reference sigmas :data:`REFERENCE_SIGMA_XY` =
0.05 and :data:`REFERENCE_SIGMA_THETA` = 0.02 are used then. The standardized noise draws do not
depend on the sigmas, so worlds that differ only in their sigmas have the same graph and noise
scaled proportionally.

``graph.initial`` is the dead-reckoning guess: the noisy (wrapped) measurements of a spanning path
or tree composed from the true pose of its root — exactly what a real dataset's VERTEX lines look
like. Edge order: the odometric chain ``i → i+1`` first (``edges 0 … n−2``), then the loop closures
sorted by (head, tail); :func:`random_graph` shuffles its edges.

``params`` always holds every generator argument (defaults resolved), ``"generator"``, and the
edge-index arrays ``"outliers"`` (false loop closures, see ``outlier_fraction``) and
``"loop_closures"`` (for :func:`random_graph`: the non-spanning edges, plus ``"spanning_edges"``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .posegraph import PoseGraph, between, wrap_angle

__all__ = [
    "SyntheticWorld",
    "manhattan_world",
    "circle_world",
    "random_graph",
    "add_noise",
    "dead_reckoning",
    "REFERENCE_SIGMA_XY",
    "REFERENCE_SIGMA_THETA",
]

#: Translational sigma used for the information matrix of a world generated with ``sigma_xy=0``.
REFERENCE_SIGMA_XY = 0.05
#: Angular sigma (rad) used for the information matrix of a world generated with ``sigma_theta=0``.
REFERENCE_SIGMA_THETA = 0.02
#: A false loop closure's true error must have a Mahalanobis χ² of at least this much (≈ 10σ).
OUTLIER_MIN_CHI2 = 100.0

_INFORMATION_KINDS = ("diagonal", "full")


# ------------------------------------------------------------------------------ the world
@dataclass(frozen=True, eq=False)
class SyntheticWorld:
    """A synthetic pose graph with its ground truth.

    Attributes:
        graph: the :class:`PoseGraph`; ``graph.initial`` is the dead-reckoning guess (n, 3).
        truth: (n, 3) true poses ``(x, y, θ)``, θ **unwrapped** (cumulative), read-only.
        params: every generator parameter (defaults resolved) for provenance, plus
            ``"generator"`` (function name), ``"outliers"`` (int64 edge indices of the false loop
            closures, possibly empty) and ``"loop_closures"`` (int64 edge indices of the
            non-odometric / non-spanning edges).
    """

    graph: PoseGraph
    truth: np.ndarray
    params: dict

    @property
    def n_poses(self) -> int:
        return self.graph.n_poses

    @property
    def n_edges(self) -> int:
        return self.graph.n_edges

    @property
    def outlier_mask(self) -> np.ndarray:
        """Boolean (m,): edge is a false loop closure."""
        mask = np.zeros(self.graph.n_edges, bool)
        mask[self.params["outliers"]] = True
        return mask

    @property
    def inlier_graph(self) -> PoseGraph:
        """The graph without its false loop closures."""
        return self.graph.subgraph_edges(~self.outlier_mask)

    def __repr__(self) -> str:
        return (f"<SyntheticWorld {self.params.get('generator', '?')}: {self.graph!r}, "
                f"{len(self.params['outliers'])} outliers>")


# ------------------------------------------------------------------------ shared helpers
def _resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta):
    """Check the noise sigmas and resolve the information sigmas (see the module docstring)."""
    for name, v in [("sigma_xy", sigma_xy), ("sigma_theta", sigma_theta)]:
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be finite and >= 0, got {v}")
    if info_sigma_xy is None:
        info_sigma_xy = sigma_xy if sigma_xy > 0 else REFERENCE_SIGMA_XY
    if info_sigma_theta is None:
        info_sigma_theta = sigma_theta if sigma_theta > 0 else REFERENCE_SIGMA_THETA
    for name, v in [("info_sigma_xy", info_sigma_xy), ("info_sigma_theta", info_sigma_theta)]:
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be finite and > 0, got {v}")
    return float(sigma_xy), float(sigma_theta), float(info_sigma_xy), float(info_sigma_theta)


def _random_correlations(m: int, rng: np.random.Generator) -> np.ndarray:
    """(m, 3, 3) random correlation matrices, well conditioned, all off-diagonals non-zero a.s.

    ``C = normalize(A Aᵀ + 0.5 I)`` with ``A`` (m, 3, 4) standard normal: correlations spread over
    roughly (−0.9, 0.9), smallest eigenvalue bounded away from 0."""
    a = rng.standard_normal((m, 3, 4))
    s = a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(3)
    d = 1.0 / np.sqrt(np.einsum("kii->ki", s))
    return s * d[:, :, None] * d[:, None, :]


def add_noise(truth, tails, heads, *, sigma_xy, sigma_theta, rng, information="diagonal",
              info_sigma_xy=None, info_sigma_theta=None):
    """Noisy relative-pose measurements of the edges ``tails[k] → heads[k]``, and their information.

    Args:
        truth: (n, 3) true poses (θ may be unwrapped).
        tails, heads: (m,) int pose indices.
        sigma_xy, sigma_theta: noise standard deviations (≥ 0; 0 gives exactly noiseless values).
        rng: the ``np.random.Generator`` to draw from. Always draws ``(m, 3)`` standard normals
            (plus, for ``information="full"``, the correlation matrices) whatever the sigmas, so
            the random stream does not depend on them.
        information: ``"diagonal"`` or ``"full"`` (per-edge random correlation, see the module
            docstring).
        info_sigma_xy, info_sigma_theta: sigmas of the information matrix (default: the noise
            sigmas, or the reference sigmas when those are 0).

    Returns:
        ``(measurements, info)``: (m, 3) ``[Δx, Δy, δ]`` with δ wrapped to [−π, π), and the
        (m, 3, 3) symmetric positive definite information matrices.
    """
    if information not in _INFORMATION_KINDS:
        raise ValueError(f"information must be one of {_INFORMATION_KINDS}, got {information!r}")
    sigma_xy, sigma_theta, isx, ist = _resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy,
                                                      info_sigma_theta)
    truth = np.asarray(truth, dtype=float)
    tails = np.asarray(tails, dtype=np.int64)
    heads = np.asarray(heads, dtype=np.int64)
    m = tails.shape[0]
    true_rel = between(truth[tails], truth[heads])
    z = rng.standard_normal((m, 3))
    s_noise = np.array([sigma_xy, sigma_xy, sigma_theta])
    s_info = np.array([isx, isx, ist])
    if information == "diagonal":
        noise = z * s_noise
        info = np.zeros((m, 3, 3))
        info[:, [0, 1, 2], [0, 1, 2]] = 1.0 / s_info**2
    else:
        corr = _random_correlations(m, rng)
        chol = np.linalg.cholesky(corr)
        noise = np.einsum("kij,kj->ki", chol, z) * s_noise  # cov = S C S
        cov_info = corr * s_info[:, None] * s_info[None, :]
        info = np.linalg.inv(cov_info)
        info = 0.5 * (info + np.swapaxes(info, 1, 2))
    meas = true_rel + noise
    meas[:, 2] = wrap_angle(meas[:, 2])
    return meas, info


def dead_reckoning(start, measurements) -> np.ndarray:
    """Compose a chain of relative measurements: pose ``k+1 = pose k ⊕ measurements[k]``.

    Args:
        start: (3,) the first pose.
        measurements: (m, 3) ``[Δx, Δy, δ]`` of the edges ``k → k+1``.

    Returns:
        (m + 1, 3) poses (θ cumulative, not wrapped). Vectorized (cumulative sums).
    """
    start = np.asarray(start, dtype=float).reshape(3)
    meas = np.asarray(measurements, dtype=float).reshape(-1, 3)
    theta = start[2] + np.concatenate([[0.0], np.cumsum(meas[:, 2])])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    dx = c * meas[:, 0] - s * meas[:, 1]
    dy = s * meas[:, 0] + c * meas[:, 1]
    x = start[0] + np.concatenate([[0.0], np.cumsum(dx)])
    y = start[1] + np.concatenate([[0.0], np.cumsum(dy)])
    return np.column_stack([x, y, theta])


def _chi2(truth, tails, heads, meas, info) -> np.ndarray:
    """(m,) Mahalanobis χ² of the true errors ``meas − between(truth)`` (angle wrapped)."""
    e = meas - between(truth[tails], truth[heads])
    e[:, 2] = wrap_angle(e[:, 2])
    return np.einsum("ki,kij,kj->k", e, info, e)


def _inject_outliers(truth, tails, heads, meas, info, candidates, fraction, rng, *,
                     min_separation, scale, max_rounds=50):
    """Replace ``round(fraction · len(candidates))`` of the ``candidates`` edges by false ones.

    Half (at random) become *wrong pose pairs* (perceptual aliasing: the tail is kept, the head is
    moved to a random pose ``≥ tail + min_separation``, the measurement is kept); the others — and
    those where no such head exists — get a *random measurement* (Δ uniform in the square
    ``[−scale, scale]²``, δ uniform in [−π, π)). Any false edge whose true χ² is below
    :data:`OUTLIER_MIN_CHI2` is redrawn as a random measurement (up to ``max_rounds`` times).

    Returns ``(tails, heads, meas, outliers)`` — new arrays, ``outliers`` sorted int64 edge indices.
    """
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"outlier_fraction must be in [0, 1], got {fraction}")
    candidates = np.asarray(candidates, dtype=np.int64)
    k = int(round(fraction * candidates.size))
    if k == 0:
        return tails, heads, meas, np.zeros(0, np.int64)
    tails, heads, meas = tails.copy(), heads.copy(), meas.copy()
    n = truth.shape[0]
    out = np.sort(rng.choice(candidates, size=k, replace=False))
    lo = tails[out] + min_separation
    wrong_pair = (rng.random(k) < 0.5) & (lo <= n - 1)
    u = rng.random(k)
    new_head = lo + np.floor(u * np.maximum(n - lo, 1)).astype(np.int64)
    heads[out[wrong_pair]] = new_head[wrong_pair]
    redo = out[~wrong_pair]
    for _ in range(max_rounds):
        if redo.size:
            meas[redo, :2] = rng.uniform(-scale, scale, (redo.size, 2))
            meas[redo, 2] = rng.uniform(-np.pi, np.pi, redo.size)
        chi2 = _chi2(truth, tails[out], heads[out], meas[out], info[out])
        redo = out[chi2 < OUTLIER_MIN_CHI2]
        if redo.size == 0:
            break
    return tails, heads, meas, out


def _finish(name, n, truth, tails, heads, meas, info, initial, params) -> SyntheticWorld:
    truth = np.ascontiguousarray(truth, dtype=float)
    truth.setflags(write=False)
    for key in ("outliers", "loop_closures", "spanning_edges"):
        if key in params:
            arr = np.ascontiguousarray(params[key], dtype=np.int64)
            arr.setflags(write=False)
            params[key] = arr
    graph = PoseGraph(n_poses=n, tails=tails, heads=heads, delta_l=meas[:, :2], delta=meas[:, 2],
                      information=info, initial=initial, name=name)
    return SyntheticWorld(graph=graph, truth=truth, params=params)


def _check_n(n_poses, minimum=2):
    n = int(n_poses)
    if n != n_poses or n < minimum:
        raise ValueError(f"n_poses must be an integer >= {minimum}, got {n_poses}")
    return n


# ------------------------------------------------------------------------ Manhattan world
_DX = (1, 0, -1, 0)
_DY = (0, 1, 0, -1)


def _manhattan_walk(n: int, p_turn: float, half: int, rng: np.random.Generator):
    """Grid random walk: integer positions (n,), (n,) and cumulative turns (n,) in quarter turns.

    Pose 0 is at the grid origin heading +x. At each step the robot first turns (straight, or ±90°
    with probability ``p_turn``), then moves one cell along its new heading — so an odometric turn
    reads ``(0, ±1, ±π/2)`` like M3500's. A move that would leave ``[−half, half]²`` is replaced by
    the first feasible of: the other turns (random side first, then straight), then a U-turn (±π)."""
    u = rng.random(n - 1).tolist()
    side = np.where(rng.random(n - 1) < 0.5, 1, -1).tolist()
    x = y = d = 0
    xs, ys, ts = [0], [0], [0]
    dxs, dys = _DX, _DY
    for k in range(n - 1):
        s = side[k]
        cands = (s, -s, 0, 2 * s) if u[k] < p_turn else (0, s, -s, 2 * s)
        for t in cands:
            dd = (d + t) & 3
            nx = x + dxs[dd]
            ny = y + dys[dd]
            if -half <= nx <= half and -half <= ny <= half:
                break
        x, y, d = nx, ny, dd
        xs.append(x)
        ys.append(y)
        ts.append(t)
    return (np.array(xs, np.int64), np.array(ys, np.int64), np.cumsum(np.array(ts, np.int64)))


def _select_loop_closures(points, radius, min_separation, p_keep, max_per_pose, rng):
    """Pairs (i, j), i < j, j − i ≥ min_separation, |p_i − p_j| ≤ radius; each kept with
    probability ``p_keep``, then at most ``max_per_pose`` (random ones) per head j.

    Returns (tails, heads) int64 sorted by (head, tail). KD-tree search, no O(n²)."""
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray").astype(np.int64)
    if pairs.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i = np.minimum(pairs[:, 0], pairs[:, 1])
    j = np.maximum(pairs[:, 0], pairs[:, 1])
    sel = j - i >= min_separation
    i, j = i[sel], j[sel]
    order = np.lexsort((i, j))  # canonical order: the KD-tree's output order is not relied on
    i, j = i[order], j[order]
    keep = rng.random(i.size) < p_keep
    priority = rng.random(i.size)
    i, j, priority = i[keep], j[keep], priority[keep]
    if max_per_pose is not None and i.size:
        order = np.lexsort((priority, j))
        i, j = i[order], j[order]
        starts = np.r_[0, np.flatnonzero(np.diff(j)) + 1]
        group = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, j.size]))
        rank = np.arange(j.size) - starts[group]
        sel = rank < max_per_pose
        i, j = i[sel], j[sel]
        order = np.lexsort((i, j))
        i, j = i[order], j[order]
    return i, j


def manhattan_world(n_poses=500, *, seed=0, sigma_xy=0.05, sigma_theta=0.02, step=1.0, p_turn=0.3,
                    grid_extent=None, loop_closure_radius=0.5, p_loop_closure=0.75,
                    min_loop_separation=10, max_loop_closures_per_pose=5, outlier_fraction=0.0,
                    information="diagonal", info_sigma_xy=None, info_sigma_theta=None
                    ) -> SyntheticWorld:
    """A Manhattan world in the style of Olson's M3500.

    The robot walks on a square grid of spacing ``step``, starting at the origin heading +x
    (``truth[0] = (0, 0, 0)``). At each step it turns ±90° with probability ``p_turn`` (else goes
    straight) and moves one cell along its new heading, staying inside the square
    ``[−h, h]²·step`` with ``h = grid_extent // 2`` (it turns away, or back, at the border).

    Edges: the odometry ``i → i+1`` for every i, then loop closures ``i → j`` (tail = the earlier
    pose) for every pair with ``j − i ≥ min_loop_separation`` whose true positions are within
    ``loop_closure_radius`` (default: revisits of the same grid point), each kept with probability
    ``p_loop_closure``, at most ``max_loop_closures_per_pose`` per head pose j (None: no cap).

    Args:
        n_poses: number of poses n (≥ 2).
        seed: seed of ``np.random.default_rng``.
        sigma_xy, sigma_theta, information, info_sigma_xy, info_sigma_theta: noise and
            information, see :func:`add_noise`.
        step: grid spacing (length of an odometric move).
        p_turn: probability of a ±90° turn at each step.
        grid_extent: side of the square region, in cells (≥ 2). Default ``max(4, round(√n))``
            (59 for n = 3500, 316 for n = 100 000): small enough that the robot keeps revisiting
            places, and growing like √n so the mean number of visits per cell (hence the
            edge/pose ratio) does not grow with n.
        loop_closure_radius: search radius for loop closures (same units as ``step``).
        p_loop_closure: probability of keeping each candidate loop closure.
        min_loop_separation: minimum ``j − i`` of a loop closure (≥ 2, so that a loop closure is
            never counted as odometric by ``PoseGraph.is_odometric``).
        max_loop_closures_per_pose: cap of loop closures per head pose, or None.
        outlier_fraction: fraction of the loop closures replaced by false ones (see
            ``params["outliers"]``; half wrong pose pairs, half random measurements).

    Returns:
        :class:`SyntheticWorld` with ``n`` poses and ``n − 1 + n_lc`` edges. The defaults are
        tuned on M3500 (3500 poses, 5453 edges, 1954 loop closures; loop closures per head pose
        0/1/2/3/4/5: 2126/925/342/86/18/3): ``manhattan_world(3500, seed=0)`` has 5430 edges,
        1931 loop closures, per head pose 2177/878/321/95/19/10. How much a bounded random walk
        revisits varies with the seed: over seeds 0–9 the n = 3500 loop-closure count ranges
        1598–3427 (mean ≈ 0.57 per pose); larger n gives somewhat more per pose (≈ 0.7 at 100 000).
        (M3500 also links *neighbouring* grid points — loop closures up to ≈ 4.5 cells apart, with
        ``j − i`` as small as 4; use ``loop_closure_radius=1.5`` or more and a smaller
        ``min_loop_separation`` to mimic that.)
    """
    n = _check_n(n_poses)
    if grid_extent is None:
        grid_extent = max(4, int(round(math.sqrt(n))))
    grid_extent = int(grid_extent)
    if grid_extent < 2:
        raise ValueError(f"grid_extent must be >= 2, got {grid_extent}")
    if not 0.0 <= p_turn <= 1.0 or not 0.0 <= p_loop_closure <= 1.0:
        raise ValueError("p_turn and p_loop_closure must be probabilities")
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    if int(min_loop_separation) < 2:
        raise ValueError(f"min_loop_separation must be >= 2, got {min_loop_separation}")
    if max_loop_closures_per_pose is not None and int(max_loop_closures_per_pose) < 0:
        raise ValueError("max_loop_closures_per_pose must be >= 0 or None")
    _resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta)
    if information not in _INFORMATION_KINDS:
        raise ValueError(f"information must be one of {_INFORMATION_KINDS}, got {information!r}")
    params = dict(generator="manhattan_world", n_poses=n, seed=seed, sigma_xy=sigma_xy,
                  sigma_theta=sigma_theta, step=step, p_turn=p_turn, grid_extent=grid_extent,
                  loop_closure_radius=loop_closure_radius, p_loop_closure=p_loop_closure,
                  min_loop_separation=int(min_loop_separation),
                  max_loop_closures_per_pose=max_loop_closures_per_pose,
                  outlier_fraction=outlier_fraction, information=information,
                  info_sigma_xy=info_sigma_xy, info_sigma_theta=info_sigma_theta)
    rng = np.random.default_rng(seed)

    gx, gy, quarter_turns = _manhattan_walk(n, p_turn, grid_extent // 2, rng)
    truth = np.column_stack([gx * step, gy * step, quarter_turns * (np.pi / 2)])

    lc_t, lc_h = _select_loop_closures(
        truth[:, :2], loop_closure_radius, int(min_loop_separation), p_loop_closure,
        None if max_loop_closures_per_pose is None else int(max_loop_closures_per_pose), rng)
    tails = np.concatenate([np.arange(n - 1, dtype=np.int64), lc_t])
    heads = np.concatenate([np.arange(1, n, dtype=np.int64), lc_h])
    meas, info = add_noise(truth, tails, heads, sigma_xy=sigma_xy, sigma_theta=sigma_theta, rng=rng,
                           information=information, info_sigma_xy=info_sigma_xy,
                           info_sigma_theta=info_sigma_theta)
    loop_closures = np.arange(n - 1, tails.size)
    tails, heads, meas, outliers = _inject_outliers(
        truth, tails, heads, meas, info, loop_closures, outlier_fraction, rng,
        min_separation=int(min_loop_separation), scale=3.0 * step)
    initial = dead_reckoning(truth[0], meas[: n - 1])
    params.update(outliers=outliers, loop_closures=loop_closures)
    return _finish(f"manhattan(n={n}, seed={seed})", n, truth, tails, heads, meas, info, initial,
                   params)


# --------------------------------------------------------------------------- circle world
def circle_world(n_poses=100, *, laps=1.0, radius=10.0, seed=0, sigma_xy=0.05, sigma_theta=0.01,
                 loop_closures=True, p_loop_closure=1.0, outlier_fraction=0.0,
                 information="diagonal", info_sigma_xy=None, info_sigma_theta=None
                 ) -> SyntheticWorld:
    """The robot drives ``laps`` turns counter-clockwise around a circle.

    Pose k is at polar angle ``φ_k = 2π·laps·k/n`` on a circle of ``radius`` centred at
    ``(0, radius)``, heading along the tangent: ``truth[k] = (R sin φ_k, R − R cos φ_k, φ_k)``, so
    ``truth[0] = (0, 0, 0)`` and the true θ increases by ``2π·laps·(n−1)/n`` in total (unwrapped;
    ``laps`` may exceed 1 — a trajectory that winds several full turns).

    Edges: odometry ``k → k+1``; if ``loop_closures``: for each pose j and each earlier lap q ≥ 1
    the pose ``i = round(j − q·n/laps)`` at the same place (when ``i ≥ 0`` and ``j − i ≥ 2``), and,
    when ``laps`` is an integer, the edge ``0 → n−1`` closing the circle (pose 0 is one step ahead
    of pose n−1). Each loop closure is kept with probability ``p_loop_closure``.

    Args:
        n_poses: number of poses n (≥ 3).
        laps: number of turns (> 0, any real).
        radius: circle radius R.
        seed, sigma_xy, sigma_theta, information, info_sigma_xy, info_sigma_theta,
        outlier_fraction: as in :func:`manhattan_world`.
        loop_closures: add the loop closures at all.
        p_loop_closure: probability of keeping each loop closure.

    Returns:
        :class:`SyntheticWorld`.
    """
    n = _check_n(n_poses, 3)
    if not laps > 0 or not radius > 0:
        raise ValueError(f"laps and radius must be > 0, got laps={laps}, radius={radius}")
    _resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta)
    if information not in _INFORMATION_KINDS:
        raise ValueError(f"information must be one of {_INFORMATION_KINDS}, got {information!r}")
    params = dict(generator="circle_world", n_poses=n, laps=laps, radius=radius, seed=seed,
                  sigma_xy=sigma_xy, sigma_theta=sigma_theta, loop_closures=loop_closures,
                  p_loop_closure=p_loop_closure, outlier_fraction=outlier_fraction,
                  information=information, info_sigma_xy=info_sigma_xy,
                  info_sigma_theta=info_sigma_theta)
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    phi = 2.0 * np.pi * laps * k / n
    truth = np.column_stack([radius * np.sin(phi), radius - radius * np.cos(phi), phi])

    lc_t = [np.zeros(0, np.int64)]
    lc_h = [np.zeros(0, np.int64)]
    if loop_closures:
        per_lap = n / laps
        for q in range(1, int(math.ceil(laps)) + 1):
            i = np.rint(k - q * per_lap).astype(np.int64)
            ok = (i >= 0) & (k - i >= 2)
            lc_t.append(i[ok])
            lc_h.append(k[ok])
        if float(laps).is_integer():
            lc_t.append(np.array([0]))
            lc_h.append(np.array([n - 1]))
    lc_t = np.concatenate(lc_t)
    lc_h = np.concatenate(lc_h)
    pairs = np.unique(np.column_stack([lc_h, lc_t]), axis=0)  # sorted by (head, tail), no dups
    keep = rng.random(pairs.shape[0]) < p_loop_closure
    lc_h, lc_t = pairs[keep, 0], pairs[keep, 1]

    tails = np.concatenate([np.arange(n - 1, dtype=np.int64), lc_t])
    heads = np.concatenate([np.arange(1, n, dtype=np.int64), lc_h])
    meas, info = add_noise(truth, tails, heads, sigma_xy=sigma_xy, sigma_theta=sigma_theta, rng=rng,
                           information=information, info_sigma_xy=info_sigma_xy,
                           info_sigma_theta=info_sigma_theta)
    lcs = np.arange(n - 1, tails.size)
    tails, heads, meas, outliers = _inject_outliers(
        truth, tails, heads, meas, info, lcs, outlier_fraction, rng, min_separation=2,
        scale=radius)
    initial = dead_reckoning(truth[0], meas[: n - 1])
    params.update(outliers=outliers, loop_closures=lcs)
    return _finish(f"circle(n={n}, laps={laps}, seed={seed})", n, truth, tails, heads, meas, info,
                   initial, params)


# --------------------------------------------------------------------------- random graph
def random_graph(n_poses, n_edges, *, seed=0, sigma_xy=0.05, sigma_theta=0.02, spread=10.0,
                 theta_range=3 * np.pi, spanning="tree", p_reverse=0.5, outlier_fraction=0.0,
                 information="diagonal", info_sigma_xy=None, info_sigma_theta=None
                 ) -> SyntheticWorld:
    """A random connected pose graph with random true poses, for property tests.

    True poses: ``x, y`` uniform in ``[−spread, spread]``, θ uniform in
    ``[−theta_range, theta_range]`` (default ±3π: far outside [−π, π)).

    Edges: a spanning structure of ``n − 1`` edges — ``spanning="tree"`` (random recursive tree
    over a random permutation of the poses), ``"chain"`` (a path through a random permutation) or
    ``"odometry"`` (the path ``0 → 1 → … → n−1``) — plus ``n_edges − (n − 1)`` extra edges between
    uniformly random distinct poses (parallel edges possible). Every edge of a tree/chain, and every
    extra edge, has a random direction (reversed with probability ``p_reverse``; ``"odometry"``
    edges always point ``i → i+1``). The edge order is shuffled; ``params["spanning_edges"]`` and
    ``params["loop_closures"]`` give the indices of the spanning and extra edges.

    ``graph.initial`` is the dead reckoning along the spanning structure from the true pose of its
    root (the first pose of the permutation; pose 0 for ``"odometry"``).

    Args:
        n_poses: number of poses n (≥ 2).
        n_edges: number of edges m (≥ n − 1).
        spread, theta_range: ranges of the true poses.
        spanning: ``"tree"``, ``"chain"`` or ``"odometry"``.
        p_reverse: probability of reversing a (non-odometry) edge.
        outlier_fraction: fraction of the *extra* edges replaced by false ones.
        seed, sigma_xy, sigma_theta, information, info_sigma_xy, info_sigma_theta: as in
            :func:`manhattan_world`.

    Returns:
        :class:`SyntheticWorld`.
    """
    n = _check_n(n_poses)
    m = int(n_edges)
    if m < n - 1:
        raise ValueError(f"a connected graph on {n} poses needs n_edges >= {n - 1}, got {n_edges}")
    if spanning not in ("tree", "chain", "odometry"):
        raise ValueError(f"spanning must be 'tree', 'chain' or 'odometry', got {spanning!r}")
    _resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta)
    if information not in _INFORMATION_KINDS:
        raise ValueError(f"information must be one of {_INFORMATION_KINDS}, got {information!r}")
    params = dict(generator="random_graph", n_poses=n, n_edges=m, seed=seed, sigma_xy=sigma_xy,
                  sigma_theta=sigma_theta, spread=spread, theta_range=theta_range, spanning=spanning,
                  p_reverse=p_reverse, outlier_fraction=outlier_fraction, information=information,
                  info_sigma_xy=info_sigma_xy, info_sigma_theta=info_sigma_theta)
    rng = np.random.default_rng(seed)
    truth = np.column_stack([rng.uniform(-spread, spread, (n, 2)),
                             rng.uniform(-theta_range, theta_range, n)])

    # spanning structure: parent[perm[k]] is in perm[:k]
    perm = np.arange(n) if spanning == "odometry" else rng.permutation(n)
    if spanning == "tree":
        parent_pos = np.floor(rng.random(n - 1) * np.arange(1, n)).astype(np.int64)
    else:
        parent_pos = np.arange(n - 1)
    sp_parent = perm[parent_pos]
    sp_child = perm[1:]
    n_extra = m - (n - 1)
    ex_a = rng.integers(0, n, n_extra)
    ex_b = rng.integers(0, n - 1, n_extra)
    ex_b = ex_b + (ex_b >= ex_a)  # distinct from ex_a
    a = np.concatenate([sp_parent, ex_a])
    b = np.concatenate([sp_child, ex_b])
    rev = rng.random(m) < p_reverse
    if spanning == "odometry":
        rev[: n - 1] = False
    tails = np.where(rev, b, a).astype(np.int64)
    heads = np.where(rev, a, b).astype(np.int64)
    order = rng.permutation(m)
    tails, heads = tails[order], heads[order]
    where = np.empty(m, np.int64)
    where[order] = np.arange(m)  # where[e] = new index of old edge e
    spanning_edges = np.sort(where[: n - 1])
    extra_edges = np.sort(where[n - 1:])

    meas, info = add_noise(truth, tails, heads, sigma_xy=sigma_xy, sigma_theta=sigma_theta, rng=rng,
                           information=information, info_sigma_xy=info_sigma_xy,
                           info_sigma_theta=info_sigma_theta)
    tails, heads, meas, outliers = _inject_outliers(
        truth, tails, heads, meas, info, extra_edges, outlier_fraction, rng, min_separation=1,
        scale=spread)

    # dead reckoning along the spanning structure, in permutation order (parents first)
    init = np.empty((n, 3))
    init[perm[0]] = truth[perm[0]]
    sp_new = where[: n - 1]  # new index of the spanning edge reaching perm[k + 1]
    fwd = tails[sp_new] == sp_parent
    rel = meas[sp_new].copy()
    inv = between(rel, np.zeros(3))
    rel = np.where(fwd[:, None], rel, inv)
    for k in range(n - 1):
        init[sp_child[k]] = _compose1(init[sp_parent[k]], rel[k])
    params.update(outliers=outliers, loop_closures=extra_edges, spanning_edges=spanning_edges)
    return _finish(f"random(n={n}, m={m}, seed={seed})", n, truth, tails, heads, meas, info, init,
                   params)


def _compose1(a, b):
    """Scalar a ⊕ b for two (3,) poses (``posegraph.compose`` without array overhead, for a loop)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])
