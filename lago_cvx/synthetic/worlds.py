"""The world generators: a Manhattan grid walk, a multi-lap circle, a random graph (conventions in the
package docstring)."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from ..errors import OptionError
from ..posegraph import between
from .noise import (INFORMATION_KINDS, SyntheticWorld, add_noise, check_n, finish_world, inject_outliers,
                    resolve_sigmas, trajectory_world)

__all__ = ["manhattan_world", "circle_world", "random_graph"]


# ------------------------------------------------------------------------ Manhattan world
_DX = (1, 0, -1, 0)
_DY = (0, 1, 0, -1)


def _grid_step(x: int, y: int, d: int, s: int, turning: bool, half: int) -> tuple[int, int, int, int]:
    """One step of the grid walk from cell (x, y) heading d (quarter turns): the first move that stays in
    ``[−half, half]²`` of the preferred turn (``s`` = ±1 if ``turning``, else straight), the other turns
    (side ``s`` first, then straight), a U-turn. Returns the new cell, heading and the turn taken."""
    for turn in ((s, -s, 0, 2 * s) if turning else (0, s, -s, 2 * s)):
        dd = (d + turn) & 3
        nx, ny = x + _DX[dd], y + _DY[dd]
        if -half <= nx <= half and -half <= ny <= half:
            break
    return nx, ny, dd, turn


def _manhattan_walk(n: int, p_turn: float, half: int, rng: np.random.Generator):
    """Grid random walk: integer positions (n,), (n,) and cumulative turns (n,) in quarter turns.

    Pose 0 is at the grid origin heading +x. At each step the robot first turns (straight, or ±90°
    with probability ``p_turn``), then moves one cell along its new heading — so an odometric turn
    reads ``(0, ±1, ±π/2)`` like M3500's. A move that would leave ``[−half, half]²`` is replaced by
    the first feasible of: the other turns (random side first, then straight), then a U-turn (±π).

    Vectorized in blocks: the preferred turns of a block are composed by cumulative sums up to the
    first step that would leave the square; that step is resolved as above, and the next block starts
    after it (a few thousand such steps in a million). Same random numbers, same walk as a step-by-step
    loop."""
    u = rng.random(n - 1)
    side = np.where(rng.random(n - 1) < 0.5, 1, -1)
    preferred = np.where(u < p_turn, side, 0)
    dx, dy = np.array(_DX), np.array(_DY)
    xs, ys, ts = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    x = y = d = 0
    k, block = 0, 256  # steps done; size of the next block
    while k < n - 1:
        t = preferred[k:k + block]
        dirs = (d + np.cumsum(t)) & 3
        px, py = x + np.cumsum(dx[dirs]), y + np.cumsum(dy[dirs])
        outside = (np.abs(px) > half) | (np.abs(py) > half)
        j = int(np.argmax(outside)) if outside.any() else t.size
        xs[k + 1:k + 1 + j], ys[k + 1:k + 1 + j], ts[k + 1:k + 1 + j] = px[:j], py[:j], t[:j]
        if j:
            x, y, d = int(px[j - 1]), int(py[j - 1]), int(dirs[j - 1])
        k += j
        if j == t.size:
            block = min(2 * block, 1 << 16)
            continue
        # step k would leave the square: take it step by step
        x, y, d, turn = _grid_step(x, y, d, int(side[k]), bool(u[k] < p_turn), half)
        k += 1
        xs[k], ys[k], ts[k] = x, y, turn
        block = 256
    return xs, ys, np.cumsum(ts)


def _same_cell_pairs(cells: np.ndarray) -> np.ndarray:
    """All pairs (i, j), i < j, of indices with equal ``cells`` values, as an (k, 2) int64 array."""
    order = np.argsort(cells, kind="stable")
    sorted_cells = cells[order]
    starts = np.flatnonzero(np.r_[True, sorted_cells[1:] != sorted_cells[:-1]])
    ends = np.r_[starts[1:], cells.size]
    group_end = np.repeat(ends, ends - starts)         # for each sorted position, the end of its group
    later = group_end - np.arange(cells.size) - 1        # members after it in its group
    first = np.repeat(np.arange(cells.size), later)
    offset = np.arange(first.size) - np.repeat(np.cumsum(later) - later, later)
    return np.column_stack([order[first], order[first + 1 + offset]])


def _select_loop_closures(points, radius, min_separation, p_keep, max_per_pose, rng, cells=None):
    """Pairs (i, j), i < j, j − i ≥ min_separation, |p_i − p_j| ≤ radius; each kept with
    probability ``p_keep``, then at most ``max_per_pose`` (random ones) per head j.

    Returns (tails, heads) int64 sorted by (head, tail). KD-tree search, no O(n²); or, when ``cells``
    (integer ids of grid points) is given because the radius is below the grid spacing, the pairs of
    equal cells — the same set, found by one sort."""
    if cells is not None:
        pairs = _same_cell_pairs(cells)
    else:
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
    n = check_n(n_poses)
    if grid_extent is None:
        grid_extent = max(4, int(round(math.sqrt(n))))
    grid_extent = int(grid_extent)
    if grid_extent < 2:
        raise OptionError(f"grid_extent must be >= 2, got {grid_extent}")
    if not 0.0 <= p_turn <= 1.0 or not 0.0 <= p_loop_closure <= 1.0:
        raise OptionError("p_turn and p_loop_closure must be probabilities")
    if not step > 0:
        raise OptionError(f"step must be > 0, got {step}")
    if int(min_loop_separation) < 2:
        raise OptionError(f"min_loop_separation must be >= 2, got {min_loop_separation}")
    if max_loop_closures_per_pose is not None and int(max_loop_closures_per_pose) < 0:
        raise OptionError("max_loop_closures_per_pose must be >= 0 or None")
    resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta)
    if information not in INFORMATION_KINDS:
        raise OptionError(f"information must be one of {INFORMATION_KINDS}, got {information!r}")
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

    # Radius below the grid spacing (the default): only revisits of the same grid point qualify.
    h = grid_extent // 2
    cells = (gx + h) * (2 * h + 1) + (gy + h) if loop_closure_radius < step * (1 - 1e-9) else None
    lc_t, lc_h = _select_loop_closures(
        truth[:, :2], loop_closure_radius, int(min_loop_separation), p_loop_closure,
        None if max_loop_closures_per_pose is None else int(max_loop_closures_per_pose), rng, cells)
    return trajectory_world(f"manhattan(n={n}, seed={seed})", truth, lc_t, lc_h, rng, params,
                            outlier_separation=int(min_loop_separation), outlier_scale=3.0 * step)


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
    n = check_n(n_poses, 3)
    if not laps > 0 or not radius > 0:
        raise OptionError(f"laps and radius must be > 0, got laps={laps}, radius={radius}")
    resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta)
    if information not in INFORMATION_KINDS:
        raise OptionError(f"information must be one of {INFORMATION_KINDS}, got {information!r}")
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

    return trajectory_world(f"circle(n={n}, laps={laps}, seed={seed})", truth, lc_t, lc_h, rng, params,
                            outlier_separation=2, outlier_scale=radius)


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
    n = check_n(n_poses)
    m = int(n_edges)
    if m < n - 1:
        raise OptionError(f"a connected graph on {n} poses needs n_edges >= {n - 1}, got {n_edges}")
    if spanning not in ("tree", "chain", "odometry"):
        raise OptionError(f"spanning must be 'tree', 'chain' or 'odometry', got {spanning!r}")
    resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta)
    if information not in INFORMATION_KINDS:
        raise OptionError(f"information must be one of {INFORMATION_KINDS}, got {information!r}")
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
    tails, heads, meas, outliers = inject_outliers(
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
    return finish_world(f"random(n={n}, m={m}, seed={seed})", n, truth, tails, heads, meas, info, init,
                   params)


def _compose1(a, b):
    """Scalar a ⊕ b for two (3,) poses (``posegraph.compose`` without array overhead, for a loop)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2])
