"""The measurement model of the synthetic worlds: noise, information, dead reckoning, false loop closures
(conventions in the package docstring)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import OptionError
from ..posegraph import PoseGraph, between, wrap_angle

__all__ = ["SyntheticWorld", "add_noise", "dead_reckoning", "REFERENCE_SIGMA_XY", "REFERENCE_SIGMA_THETA",
           "OUTLIER_MIN_CHI2"]

#: Translational sigma used for the information matrix of a world generated with ``sigma_xy=0``.
REFERENCE_SIGMA_XY = 0.05
#: Angular sigma (rad) used for the information matrix of a world generated with ``sigma_theta=0``.
REFERENCE_SIGMA_THETA = 0.02
#: A false loop closure's true error must have a Mahalanobis χ² of at least this much (≈ 10σ).
OUTLIER_MIN_CHI2 = 100.0

INFORMATION_KINDS = ("diagonal", "full")


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
def resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy, info_sigma_theta):
    """Check the noise sigmas and resolve the information sigmas (see the module docstring)."""
    for name, v in [("sigma_xy", sigma_xy), ("sigma_theta", sigma_theta)]:
        if not (np.isfinite(v) and v >= 0):
            raise OptionError(f"{name} must be finite and >= 0, got {v}")
    if info_sigma_xy is None:
        info_sigma_xy = sigma_xy if sigma_xy > 0 else REFERENCE_SIGMA_XY
    if info_sigma_theta is None:
        info_sigma_theta = sigma_theta if sigma_theta > 0 else REFERENCE_SIGMA_THETA
    for name, v in [("info_sigma_xy", info_sigma_xy), ("info_sigma_theta", info_sigma_theta)]:
        if not (np.isfinite(v) and v > 0):
            raise OptionError(f"{name} must be finite and > 0, got {v}")
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
    if information not in INFORMATION_KINDS:
        raise OptionError(f"information must be one of {INFORMATION_KINDS}, got {information!r}")
    sigma_xy, sigma_theta, isx, ist = resolve_sigmas(sigma_xy, sigma_theta, info_sigma_xy,
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


def inject_outliers(truth, tails, heads, meas, info, candidates, fraction, rng, *,
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
        raise OptionError(f"outlier_fraction must be in [0, 1], got {fraction}")
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


def finish_world(name, n, truth, tails, heads, meas, info, initial, params) -> SyntheticWorld:
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


def trajectory_world(name, truth, lc_tails, lc_heads, rng, params, *, outlier_separation: int,
                     outlier_scale: float) -> SyntheticWorld:
    """The world of a trajectory driven 0 → 1 → … → n−1: the odometric chain first, then the loop
    closures ``lc_tails → lc_heads``; measurements by ``add_noise`` with the sigmas and information kind
    of ``params``; a fraction ``params["outlier_fraction"]`` of the loop closures replaced by false ones
    (``inject_outliers``); vertices = the dead-reckoning guess along the chain."""
    n = truth.shape[0]
    tails = np.concatenate([np.arange(n - 1, dtype=np.int64), lc_tails])
    heads = np.concatenate([np.arange(1, n, dtype=np.int64), lc_heads])
    meas, info = add_noise(truth, tails, heads, sigma_xy=params["sigma_xy"], sigma_theta=params["sigma_theta"],
                           rng=rng, information=params["information"], info_sigma_xy=params["info_sigma_xy"],
                           info_sigma_theta=params["info_sigma_theta"])
    loop_closures = np.arange(n - 1, tails.size)
    tails, heads, meas, outliers = inject_outliers(truth, tails, heads, meas, info, loop_closures,
                                                   params["outlier_fraction"], rng,
                                                   min_separation=outlier_separation, scale=outlier_scale)
    initial = dead_reckoning(truth[0], meas[: n - 1])
    params.update(outliers=outliers, loop_closures=loop_closures)
    return finish_world(name, n, truth, tails, heads, meas, info, initial, params)


def check_n(n_poses, minimum=2):
    n = int(n_poses)
    if n != n_poses or n < minimum:
        raise OptionError(f"n_poses must be an integer >= {minimum}, got {n_poses}")
    return n
