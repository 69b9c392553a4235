r"""Consistency of loop closures with the trusted odometry: the test of one loop closure against dead
reckoning, and the pairwise consistency of two (Mangelson, Dominic, Eustice, Vasudevan, ICRA 2018, PCM),
with the maximum clique of the pairwise-consistency graph.

Dead reckoning. With the odometric chain complete (``gnc.odometric_chain_complete``), composing its edges
in id order from pose 0 gives poses X_k = (p_k, θ_k); edge m of the chain (from chain position m to m+1,
measurement z_m = (Δˡ_m, δ_m), covariance Σ_m = Ω_m⁻¹ of eq. (3), its translation in the frame of m) is
reversed when the file gives it from m+1 to m.

First-order propagation. A perturbation ε_m = (ε_t, ε_θ) of z_m moves every pose after m rigidly:
δp_k = R(θ_m) ε_t + ε_θ S (p_k − p_{m+1}), δθ_k = ε_θ, S = [[0, −1], [1, 0]] — in world coordinates,
(δp_k; δθ_k) = H(p_k) B_m ε_m with H(p) = [[I, S p], [0, 1]], B_m = [[R(θ_m), −S p_{m+1}], [0, 1]]. The
independent ε_m of a stretch [u, v) of the chain move its end relative to its start by a rigid motion of
covariance (world coordinates, about the origin)

    Π(u, v) = Σ_{m=u}^{v−1} B_m Σ_m B_mᵀ = C_v − C_u,   C_k = Σ_{m<k} B_m Σ_m B_mᵀ (prefix sums, (n, 3, 3)),

and a rigid motion G = (R_G, t_G) carries such a covariance to G's coordinates by Ad_G = [[R_G, −S t_G], [0, 1]].

(a) One loop closure k, tail i, head j: its error e_k of eq. (3) at the dead-reckoning poses, against the
covariance J Π(u, v) Jᵀ + Σ_k (u, v the chain positions of i, j in order; J the Jacobian of e_k in the pose
of the later one): d²_k = e_kᵀ (J Π Jᵀ + Σ_k)⁻¹ e_k, O(1) per edge after the O(n) prefix sums.

(b) Two loop closures k = (a → b), l = (c → d): the cycle a →(z_k) b →(chain) d →(z_l⁻¹) c →(chain) a,
composed from X_a, returns to X̃_a; its error e_kl = [R_aᵀ(p̃_a − p_a); θ̃_a − θ_a] is zero when both agree
with the odometry between their ends. Its covariance is the sum of the rigid motions of z_k, z_l and the
chain edges (an edge in both stretches b–d and c–a moves the cycle through both, ±Ad_G1 B_m ± Ad_G2 B_m, signed
by the direction the cycle runs it) carried to the cycle's coordinates, seen at p_a:
K H(p_a) Σ_cycle H(p_a)ᵀ Kᵀ, K = blkdiag(R_aᵀ, 1); d²_kl = e_klᵀ (…)⁻¹ e_kl. The pair is consistent when
d²_kl ≤ the χ²₃ quantile; the largest set of pairwise consistent loop closures (a maximum clique) is PCM's
estimate of the inliers.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from ..posegraph import wrap_angle

__all__ = ["OdometryChain", "odometry_chain", "chain_consistency", "pairwise_consistency", "pairwise_matrix",
           "maximum_clique", "consistent_start"]

log = logging.getLogger("lago_cvx.variants")

_S = np.array([[0.0, -1.0], [1.0, 0.0]])


@dataclass(frozen=True)
class OdometryChain:
    """Dead reckoning on the odometric chain (module docstring): ``position`` (n,) each pose's place in id
    order; ``poses`` (n, 3) the dead-reckoning poses, pose-indexed, positions centred; ``prefix`` (n, 3, 3) C_k
    indexed by chain position; ``edges`` (n−1,) the chain edges used (the first of any duplicate)."""

    position: np.ndarray
    poses: np.ndarray
    prefix: np.ndarray
    edges: np.ndarray


def _rot(theta: np.ndarray) -> np.ndarray:
    """R(θ) (…, 2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def odometry_chain(graph) -> OdometryChain:
    """The ``OdometryChain`` of a graph whose odometric chain is complete (``gnc.odometric_chain_complete``)."""
    n = graph.n_poses
    order = np.argsort(graph.ids, kind="stable")
    pos = np.empty(n, np.int64)
    pos[order] = np.arange(n)
    odo = np.flatnonzero(graph.is_odometric)
    lower = np.minimum(pos[graph.tails[odo]], pos[graph.heads[odo]])
    _, first = np.unique(lower, return_index=True)
    used = odo[first][np.argsort(lower[first])]
    fwd = pos[graph.tails[used]] < pos[graph.heads[used]]
    dl, dt = graph.delta_l[used].copy(), graph.delta[used].copy()
    cov = np.linalg.inv(graph.information[used])
    # a reversed edge (m+1 → m): z⁻¹ = (−R(δ)ᵀΔˡ, −δ); its error in m's frame is −T e, T = [[R(δ)ᵀ, −R(δ)ᵀSΔˡ],[0,1]]
    r = ~fwd
    Rr = _rot(dt[r])
    Rt = np.swapaxes(Rr, -1, -2)
    T = np.zeros((int(r.sum()), 3, 3))
    T[:, :2, :2] = Rt
    T[:, :2, 2] = -np.einsum("kab,bc,kc->ka", Rt, _S, dl[r])
    T[:, 2, 2] = 1.0
    cov[r] = T @ cov[r] @ np.swapaxes(T, -1, -2)
    dl[r] = -np.einsum("kba,kb->ka", Rr, dl[r])
    dt[r] = -dt[r]
    P = np.zeros((n, 3))
    P[1:, 2] = np.cumsum(dt)
    P[1:, :2] = np.cumsum(np.einsum("kab,kb->ka", _rot(P[:-1, 2]), dl), axis=0)
    P[:, :2] -= P[:, :2].mean(0)
    B = np.zeros((n - 1, 3, 3))
    B[:, :2, :2] = _rot(P[:-1, 2])
    B[:, :2, 2] = -P[1:, :2] @ _S.T
    B[:, 2, 2] = 1.0
    C = np.zeros((n, 3, 3))
    C[1:] = np.cumsum(B @ cov @ np.swapaxes(B, -1, -2), axis=0)
    poses = np.empty((n, 3))
    poses[order] = P
    return OdometryChain(pos, poses, C, used)


def _H(p: np.ndarray) -> np.ndarray:
    """H(p) = [[I, S p], [0, 1]] (k, 3, 3) for positions p (k, 2)."""
    H = np.broadcast_to(np.eye(3), (p.shape[0], 3, 3)).copy()
    H[:, :2, 2] = p @ _S.T
    return H


def _stretch(chain: OdometryChain, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Π between chain positions u and v, in either order (k, 3, 3)."""
    lo, hi = np.minimum(u, v), np.maximum(u, v)
    return chain.prefix[hi] - chain.prefix[lo]


def _mahalanobis(e: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """eᵀ cov⁻¹ e per row (k,)."""
    return np.einsum("ka,ka->k", e, np.linalg.solve(cov, e[..., None])[..., 0])


def chain_consistency(graph, chain: OdometryChain, edges: np.ndarray) -> np.ndarray:
    """(a) d²_k (q,) of the ``edges`` (q,) against dead reckoning (module docstring)."""
    edges = np.asarray(edges, np.int64)
    t, h = graph.tails[edges], graph.heads[edges]
    pt, ph = chain.poses[t], chain.poses[h]
    Rt = _rot(pt[:, 2])
    d = ph[:, :2] - pt[:, :2]
    e = np.empty((edges.size, 3))
    e[:, :2] = np.einsum("kba,kb->ka", Rt, d) - graph.delta_l[edges]
    e[:, 2] = wrap_angle(ph[:, 2] - pt[:, 2] - graph.delta[edges])
    later_is_head = chain.position[h] > chain.position[t]
    pl = np.where(later_is_head[:, None], ph[:, :2], pt[:, :2])
    Pj = _H(pl) @ _stretch(chain, chain.position[t], chain.position[h]) @ np.swapaxes(_H(pl), -1, -2)
    J = np.zeros((edges.size, 3, 3))
    RtT = np.swapaxes(Rt, -1, -2)
    J[:, :2, :2] = np.where(later_is_head[:, None, None], RtT, -RtT)
    J[:, :2, 2] = np.where(later_is_head[:, None], 0.0, -np.einsum("kab,bc,kc->ka", RtT, _S, d))
    J[:, 2, 2] = np.where(later_is_head, 1.0, -1.0)
    cov = J @ Pj @ np.swapaxes(J, -1, -2) + np.linalg.inv(graph.information[edges])
    return _mahalanobis(e, cov)


def _ad(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Ad_G = [[R_G, −S t_G], [0, 1]] (k, 3, 3)."""
    A = np.zeros((R.shape[0], 3, 3))
    A[:, :2, :2] = R
    A[:, :2, 2] = -t @ _S.T
    A[:, 2, 2] = 1.0
    return A


def _sandwich(A: np.ndarray, X: np.ndarray) -> np.ndarray:
    return A @ X @ np.swapaxes(A, -1, -2)


def pairwise_consistency(graph, chain: OdometryChain, k: np.ndarray, l: np.ndarray) -> np.ndarray:
    """(b) d²_kl (p,) of the cycles of the edge pairs (k[s], l[s]) (module docstring)."""
    k, l = np.asarray(k, np.int64), np.asarray(l, np.int64)
    X = chain.poses
    a, b, c, d = graph.tails[k], graph.heads[k], graph.tails[l], graph.heads[l]
    Xa, Xb, Xc, Xd = X[a], X[b], X[c], X[d]
    Ra = _rot(Xa[:, 2])
    # X̃_b = X_a z_k, G1 = X̃_b X_b⁻¹, X̃_d = G1 X_d
    tb = Xa[:, 2] + graph.delta[k]
    pb = Xa[:, :2] + np.einsum("kab,kb->ka", Ra, graph.delta_l[k])
    R1 = _rot(tb - Xb[:, 2])
    t1 = pb - np.einsum("kab,kb->ka", R1, Xb[:, :2])
    pd = np.einsum("kab,kb->ka", R1, Xd[:, :2]) + t1
    td = Xd[:, 2] + tb - Xb[:, 2]
    # X̃_c = X̃_d z_l⁻¹, G2 = X̃_c X_c⁻¹, X̃_a' = G2 X_a
    tc = td - graph.delta[l]
    Rc = _rot(tc)
    pc = pd - np.einsum("kab,kb->ka", Rc, graph.delta_l[l])
    R2 = _rot(tc - Xc[:, 2])
    t2 = pc - np.einsum("kab,kb->ka", R2, Xc[:, :2])
    pa2 = np.einsum("kab,kb->ka", R2, Xa[:, :2]) + t2
    ta2 = Xa[:, 2] + tc - Xc[:, 2]
    e = np.empty((k.size, 3))
    e[:, :2] = np.einsum("kba,kb->ka", Ra, pa2 - Xa[:, :2])
    e[:, 2] = wrap_angle(ta2 - Xa[:, 2])
    pos = chain.position
    Bk = _ad(Ra, pb)  # z_k's noise: R(θ_a) ε_t + ε_θ S(p − p̃_b), i.e. [[R_a, −S p̃_b], [0, 1]]
    Bl = _ad(Rc, pd)
    # the two stretches share the chain edges of their overlap: there one ε_m moves the cycle through both
    A1, A2 = _ad(R1, t1), _ad(R2, t2)
    lo = np.maximum(np.minimum(pos[b], pos[d]), np.minimum(pos[c], pos[a]))
    hi = np.maximum(np.minimum(np.maximum(pos[b], pos[d]), np.maximum(pos[c], pos[a])), lo)
    both = _stretch(chain, lo, hi)
    s1 = np.where(pos[d] > pos[b], 1.0, -1.0)[:, None, None]  # + where the cycle runs the chain forward
    s2 = np.where(pos[a] > pos[c], 1.0, -1.0)[:, None, None]
    cyc = (_sandwich(Bk, np.linalg.inv(graph.information[k])) + _sandwich(Bl, np.linalg.inv(graph.information[l]))
           + _sandwich(A1, _stretch(chain, pos[b], pos[d]) - both) + _sandwich(A2, _stretch(chain, pos[c], pos[a]) - both)
           + _sandwich(s1 * A1 + s2 * A2, both))
    K = np.zeros((k.size, 3, 3))
    K[:, :2, :2] = np.swapaxes(Ra, -1, -2)
    K[:, 2, 2] = 1.0
    M = K @ _H(Xa[:, :2])
    return _mahalanobis(e, _sandwich(M, cyc))


def pairwise_matrix(graph, chain: OdometryChain, edges: np.ndarray) -> np.ndarray:
    """(b) for every pair of the ``edges`` (q,): the symmetric matrix (q, q) of d²_kl, 0 on the diagonal; q(q − 1)/2
    cycles, evaluated in blocks of bounded size."""
    edges = np.asarray(edges, np.int64)
    q = edges.size
    d2 = np.zeros((q, q))
    I, J = np.triu_indices(q, 1)
    for s in range(0, I.size, 200_000):  # bounded temporaries
        sl = slice(s, s + 200_000)
        d2[I[sl], J[sl]] = pairwise_consistency(graph, chain, edges[I[sl]], edges[J[sl]])
    return d2 + d2.T


def maximum_clique(adjacency: np.ndarray, *, time_limit: float = 2.0) -> np.ndarray:
    """A maximum clique (sorted vertex indices) of the undirected graph ``adjacency`` (q, q) bool, symmetric,
    by branch and bound with greedy-colouring bounds (Tomita & Seki's MCQ); past ``time_limit`` seconds the
    largest clique found so far (at least the greedy one)."""
    adj = np.asarray(adjacency, bool).copy()
    np.fill_diagonal(adj, False)
    q = adj.shape[0]
    if q == 0:
        return np.zeros(0, np.int64)
    nbrs = [set(np.flatnonzero(adj[v]).tolist()) for v in range(q)]
    deg = adj.sum(1)
    best: list = []
    # greedy seed: repeatedly the candidate of most neighbours among the candidates
    cand = set(range(q))
    while cand:
        v = max(cand, key=lambda u: (len(nbrs[u] & cand), -u))
        best.append(v)
        cand &= nbrs[v]
    deadline = time.perf_counter() + time_limit

    def colour_sort(P: list) -> tuple[list, list]:
        colours, order, bounds = [], [], []
        for v in P:
            for cls in colours:
                if not (nbrs[v] & cls):
                    cls.add(v)
                    break
            else:
                colours.append({v})
        for i, cls in enumerate(colours, 1):
            for v in cls:
                order.append(v)
                bounds.append(i)
        return order, bounds

    def expand(R: list, P: list) -> None:
        nonlocal best
        order, bounds = colour_sort(P)
        for idx in range(len(order) - 1, -1, -1):
            if len(R) + bounds[idx] <= len(best) or time.perf_counter() > deadline:
                return
            v = order[idx]
            newP = [u for u in order[:idx] if u in nbrs[v]]
            if newP:
                expand(R + [v], newP)
            elif len(R) + 1 > len(best):
                best = R + [v]

    expand([], sorted(range(q), key=lambda u: -deg[u]))
    return np.array(sorted(best), np.int64)


def consistent_start(graph, known: np.ndarray, c2: float, clique_seconds: float) -> np.ndarray:
    """Start weights (m,): 1 on the known inliers and on a maximum clique of pairwise-consistent loop closures
    (d²_kl ≤ c̄² = ``c2``; the clique search given ``clique_seconds``), 0 elsewhere; the odometric chain must be
    complete. GNC's start ``"pcm"`` (``gnc.RobustSettings``)."""
    t = time.perf_counter()
    free = np.flatnonzero(~known)
    adj = pairwise_matrix(graph, odometry_chain(graph), free) <= c2
    np.fill_diagonal(adj, False)
    clique = maximum_clique(adj, time_limit=clique_seconds)
    w = known.astype(float)
    w[free[clique]] = 1.0
    log.info("pairwise consistency: a clique of %d of %d loop closures (%.3f s)", clique.size, free.size,
             time.perf_counter() - t)
    return w
