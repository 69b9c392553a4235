r"""Seeded 3-D worlds with ground truth, shaped like the 3-D benchmark graphs: a sphere (sphere2500), a cube
grid (smallGrid3D) and a torus (torus3D).

Every generator builds a path of true poses T_i = (R_i, t_i), odometry edges i → i+1 and loop closures between
poses that are neighbours in the world but not along the path, then measures each edge so that **the error of the
graph's cost at the truth is the drawn noise** (``cost``, :mod:`lago_cvx.posegraph3d`; the order (translation,
rotation)): χ²(truth) is then a χ² variable with 6m degrees of freedom in the cost the graph reports, and a world
written to a g2o file means what g2o computes of it.

* ``cost="g2o"`` (the default, the cost of g2o files, so that ``lago-cvx generate``'s files are consistent):
  n_ij = (n_t, n_q) ~ N(0, Σ), Σ = diag(σ_t² I₃, (σ_r/2)² I₃), Ω_ij = Σ⁻¹; E = (R(q), n_t) with q = (n_q, w),
  w = √(1 − ‖n_q‖²), and T̃_ij = T_i⁻¹T_j E⁻¹, so that g2o's error T̃⁻¹T_i⁻¹T_j = E gives e_ij = [n_t ; n_q]
  exactly. q_v ≈ φ/2, so σ_r is the rotation angle's standard deviation per axis, as in the other cost. (n_q is
  redrawn, never met at the worlds' σ_r, when ‖n_q‖ ≥ 1.)
* ``cost="gtsam"``: T̃_ij = T_i⁻¹ T_j Exp(n_ij), n_ij ~ N(0, Σ), Σ = diag(σ_t² I₃, σ_r² I₃), Ω_ij = Σ⁻¹; then
  e_ij = Log(T̃_ij⁻¹T_i⁻¹T_j) = −n_ij at the truth exactly.

Both information matrices weigh the Log error alike to first order (``posegraph3d.information_in_log_coordinates``).
The information is that of ``info_sigma_t`` / ``info_sigma_r`` (default: the noise's; with zero noise the planar
worlds' reference sigmas ``REFERENCE_SIGMA_XY`` / ``REFERENCE_SIGMA_THETA``, since a noise-free world still needs
finite information): a tiny noise measured with a realistic information gives a nearly noise-free graph (χ² ≪ 6m).
``graph.initial`` is the dead reckoning (the odometry composed from the true first pose). All randomness comes from
``np.random.default_rng(seed)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..conventions import check_cost
from ..errors import OptionError
from ..posegraph3d import PoseGraph3D
from ..so3 import exp_so3, quat_to_rot, v_inverse
from .noise import resolve_sigmas

__all__ = ["SyntheticWorld3D", "sphere_world", "cube_grid_world", "torus_world"]


@dataclass(frozen=True, eq=False)
class SyntheticWorld3D:
    """A 3-D pose graph with its truth: ``graph``, ``t`` (n, 3), ``R`` (n, 3, 3), ``params`` (the arguments)."""

    graph: PoseGraph3D
    t: np.ndarray
    R: np.ndarray
    params: dict

    @property
    def truth(self):
        return self.t, self.R


def _frames(t: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Rotations whose x axis is the path's direction and whose z axis is as close to ``up`` (n, 3) as allows."""
    d = np.diff(t, axis=0)
    d = np.vstack([d, d[-1:]])
    x = d / np.linalg.norm(d, axis=1, keepdims=True)
    z = up - np.einsum("ij,ij->i", up, x)[:, None] * x
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], axis=2)


def _exp_se3(xi: np.ndarray):
    """(R, t) = Exp(ξ) for ξ (k, 6) = (ρ, φ): R = Exp(φ), t = V(φ) ρ."""
    return exp_so3(xi[:, 3:]), np.linalg.solve(v_inverse(xi[:, 3:]), xi[:, :3, None])[..., 0]


def _g2o_noise(rng, m: int, sigma_t: float, sigma_r: float):
    """(R(q) (m, 3, 3), n_t (m, 3)) of g2o's error E = (R(q), n_t) with [n_t ; n_q] ~ N(0, diag(σ_t², (σ_r/2)²)),
    q = (n_q, √(1 − ‖n_q‖²)) (module docstring; a draw with ‖n_q‖ ≥ 1 is drawn again)."""
    noise = rng.standard_normal((m, 6)) * np.r_[np.full(3, sigma_t), np.full(3, 0.5 * sigma_r)]
    while True:
        far = np.flatnonzero(np.einsum("ki,ki->k", noise[:, 3:], noise[:, 3:]) >= 1.0)
        if far.size == 0:
            break
        noise[far, 3:] = rng.standard_normal((far.size, 3)) * 0.5 * sigma_r
    nq = noise[:, 3:]
    w = np.sqrt(1.0 - np.einsum("ki,ki->k", nq, nq))
    return quat_to_rot(np.column_stack([nq, w])), noise[:, :3]


def _world(name, t, R, lc_tails, lc_heads, *, sigma_t, sigma_r, seed, cost, params, info_sigma_t=None,
           info_sigma_r=None) -> SyntheticWorld3D:
    cost = check_cost(cost, dim=3)
    sigma_t, sigma_r, info_t, info_r = resolve_sigmas(sigma_t, sigma_r, info_sigma_t, info_sigma_r)
    n = t.shape[0]
    rng = np.random.default_rng(seed)
    tails = np.concatenate([np.arange(n - 1), lc_tails]).astype(np.int64)
    heads = np.concatenate([np.arange(1, n), lc_heads]).astype(np.int64)
    m = tails.size
    Ri = R[tails]
    Rt = np.swapaxes(Ri, 1, 2)
    Rij, tij = Rt @ R[heads], np.einsum("kij,kj->ki", Rt, t[heads] - t[tails])
    if cost == "g2o":  # T̃ = T_i⁻¹T_j E⁻¹, E⁻¹ = (R(q)ᵀ, −R(q)ᵀ n_t)
        Rq, nt = _g2o_noise(rng, m, sigma_t, sigma_r)
        En, et = np.swapaxes(Rq, 1, 2), -np.einsum("kji,kj->ki", Rq, nt)
        info_rot = 0.5 * info_r
    else:
        noise = rng.standard_normal((m, 6)) * np.r_[np.full(3, sigma_t), np.full(3, sigma_r)]
        En, et = _exp_se3(noise)
        info_rot = info_r
    dR, dt = Rij @ En, tij + np.einsum("kij,kj->ki", Rij, et)
    info = np.broadcast_to(np.diag(np.r_[np.full(3, info_t ** -2), np.full(3, info_rot ** -2)]), (m, 6, 6))
    it, iR = np.empty((n, 3)), np.empty((n, 3, 3))
    it[0], iR[0] = t[0], R[0]
    for k in range(n - 1):  # dead reckoning along the odometry
        iR[k + 1] = iR[k] @ dR[k]
        it[k + 1] = it[k] + iR[k] @ dt[k]
    g = PoseGraph3D(n, tails, heads, dt, dR, info, initial_t=it, initial_R=iR, name=name, cost=cost)
    return SyntheticWorld3D(g, t, R, {"generator": name, "seed": seed, "sigma_t": sigma_t, "sigma_r": sigma_r,
                                      "info_sigma_t": info_t, "info_sigma_r": info_r, "cost": cost, **params})


def sphere_world(n_rings: int = 10, per_ring: int = 20, *, radius: float = 10.0, seed: int = 0,
                 sigma_t: float = 0.05, sigma_r: float = 0.01, cost: str = "g2o", info_sigma_t: float | None = None,
                info_sigma_r: float | None = None) -> SyntheticWorld3D:
    """Poses on a sphere, ring after ring (as in sphere2500): each ring's poses are joined by odometry, and each pose
    to the pose of the ring above at the same longitude by a loop closure. n = n_rings · per_ring. ``cost``: the
    graph's, its noise drawn in that cost's coordinates (module docstring)."""
    if n_rings < 2 or per_ring < 3:
        raise OptionError("sphere_world needs n_rings >= 2 and per_ring >= 3")
    k = np.arange(n_rings * per_ring)
    ring, j = np.divmod(k, per_ring)
    polar = np.pi * (ring + 0.5 + j / per_ring) / (n_rings + 1)  # a slow spiral from pole to pole
    lon = 2 * np.pi * j / per_ring
    t = radius * np.column_stack([np.sin(polar) * np.cos(lon), np.sin(polar) * np.sin(lon), np.cos(polar)])
    R = _frames(t, t / radius)
    lc = k[per_ring:]
    return _world("sphere_world", t, R, lc - per_ring, lc, sigma_t=sigma_t, sigma_r=sigma_r, seed=seed, cost=cost,
                  info_sigma_t=info_sigma_t, info_sigma_r=info_sigma_r,
                  params={"n_rings": n_rings, "per_ring": per_ring, "radius": radius})


def torus_world(n_loops: int = 10, per_loop: int = 20, *, major: float = 10.0, minor: float = 3.0, seed: int = 0,
                sigma_t: float = 0.05, sigma_r: float = 0.01, cost: str = "g2o", info_sigma_t: float | None = None,
                info_sigma_r: float | None = None) -> SyntheticWorld3D:
    """Poses on a torus, one small loop (around the tube) after another; each pose is joined to the pose at the
    same place of the previous loop. n = n_loops · per_loop. ``cost``: the graph's, its noise drawn in
    that cost's coordinates (module docstring)."""
    if n_loops < 2 or per_loop < 3:
        raise OptionError("torus_world needs n_loops >= 2 and per_loop >= 3")
    k = np.arange(n_loops * per_loop)
    loop, j = np.divmod(k, per_loop)
    u = 2 * np.pi * (loop + j / per_loop) / n_loops
    v = 2 * np.pi * j / per_loop
    t = np.column_stack([(major + minor * np.cos(v)) * np.cos(u), (major + minor * np.cos(v)) * np.sin(u),
                         minor * np.sin(v)])
    centre = np.column_stack([major * np.cos(u), major * np.sin(u), np.zeros_like(u)])
    R = _frames(t, t - centre)
    lc = k[per_loop:]
    return _world("torus_world", t, R, lc - per_loop, lc, sigma_t=sigma_t, sigma_r=sigma_r, seed=seed, cost=cost,
                  info_sigma_t=info_sigma_t, info_sigma_r=info_sigma_r,
                  params={"n_loops": n_loops, "per_loop": per_loop, "major": major, "minor": minor})


def cube_grid_world(side: int = 5, *, spacing: float = 1.0, seed: int = 0, sigma_t: float = 0.05,
                    sigma_r: float = 0.01, cost: str = "g2o", info_sigma_t: float | None = None,
                    info_sigma_r: float | None = None, yaw_only: bool = False) -> SyntheticWorld3D:
    """A side³ lattice visited in a snake order (as smallGrid3D), each pose with a random orientation (with
    ``yaw_only`` a random rotation about z: gravity-aligned poses, R e₃ = e₃); every pair of lattice neighbours not
    consecutive along the path is a loop closure. ``cost``: the graph's, its noise drawn in that cost's coordinates
    (module docstring)."""
    if side < 2:
        raise OptionError("cube_grid_world needs side >= 2")
    cells = []
    for z in range(side):
        ys = range(side) if z % 2 == 0 else range(side - 1, -1, -1)
        for yi, y in enumerate(ys):
            xs = range(side) if (yi + z * side) % 2 == 0 else range(side - 1, -1, -1)
            cells += [(x, y, z) for x in xs]
    cells = np.array(cells)
    t = spacing * cells.astype(float)
    R = exp_so3(np.random.default_rng([seed, 1]).normal(size=(len(cells), 3)) * ([0, 0, 1] if yaw_only else 1))
    index = {tuple(c): i for i, c in enumerate(cells)}
    lt, lh = [], []
    for i, c in enumerate(cells):
        for axis in range(3):
            nb = c.copy()
            nb[axis] += 1
            j = index.get(tuple(nb))
            if j is not None and abs(i - j) != 1:
                lt.append(min(i, j))
                lh.append(max(i, j))
    return _world("cube_grid_world", t, R, np.array(lt, np.int64), np.array(lh, np.int64), sigma_t=sigma_t,
                  sigma_r=sigma_r, seed=seed, cost=cost, info_sigma_t=info_sigma_t, info_sigma_r=info_sigma_r,
                  params={"side": side, "spacing": spacing, "yaw_only": yaw_only})
