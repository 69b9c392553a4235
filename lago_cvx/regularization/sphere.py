"""Exact integer least squares by Schnorr–Euchner sphere decoding (LAMBDA-style), no dependency.

Solves eq. (3) of ``lago_cvx.regularization.integer``, min_q ‖L⁻¹(r + 2πq)‖² over q ∈ ℤˡ inside the
exact box (6), by depth-first enumeration with the rounding as the first incumbent.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..errors import SearchLimitError
from ..progress import Progress
from ..rounding import TWO_PI

__all__ = ["enumerate_integers", "PROGRESS_NODES", "TIE_RTOL"]

log = logging.getLogger("lago_cvx.regularization.integer")

#: The enumeration logs its progress every this many nodes (seconds apart on M3500-sized problems).
PROGRESS_NODES = 200_000

#: Relative tolerance under which a candidate must beat the incumbent to replace it (ties keep the
#: rounding, so "equal to rounding" is decided by cost, not by floating-point noise).
TIE_RTOL = 1e-10


def _min_variance_cholesky(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pivoted Cholesky Q[p][:, p] = G Gᵀ (G lower) choosing at each step the remaining coordinate of
    smallest conditional variance. Returns (p (l,), G (l, l))."""
    l = Q.shape[0]
    A = Q.copy()
    p = np.arange(l)
    G = np.zeros_like(A)
    for i in range(l):
        j = i + int(np.argmin(np.diag(A)[i:]))
        if j != i:
            A[[i, j]] = A[[j, i]]
            A[:, [i, j]] = A[:, [j, i]]
            G[[i, j], :i] = G[[j, i], :i]
            p[[i, j]] = p[[j, i]]
        d = A[i, i]
        if not d > 0:
            raise np.linalg.LinAlgError("cycle covariance is not positive definite")
        g = math.sqrt(d)
        G[i, i] = g
        G[i + 1:, i] = A[i + 1:, i] / g
        A[i + 1:, i + 1:] -= np.outer(G[i + 1:, i], G[i + 1:, i])
    return p, G


def enumerate_integers(data, box: tuple[np.ndarray, np.ndarray], *, max_nodes: int = 2_000_000,
                       progress=None) -> tuple[np.ndarray, float, int]:
    """Exact minimiser of eq. (3) by Schnorr–Euchner sphere decoding (no dependency).

    In units of 2π: J(q) = (q − q̂)ᵀ Q⁻¹ (q − q̂), q̂ = −r/2π, Q = S/(2π)². With Q (permuted) = G Gᵀ,
    u_i = (q_i − c_i)/G_ii and c_i = q̂_i + Σ_{j<i} G_ij u_j, J = Σ_i u_i²: coordinates are fixed in
    order, each trying integers outward from its conditional centre c_i, and a branch is cut when its
    partial sum reaches the incumbent's cost. The incumbent starts as the rounding (radius J₀); a
    candidate replaces it only if cheaper by more than ``TIE_RTOL`` (ties keep the rounding). ``box`` =
    (lo, hi) (l,) bounds every coordinate (the exact box (6), ∩ |q − q_round| ≤ max_shift).
    ``data`` is a ``CycleData``; ``progress`` an optional ``lago_cvx.progress.ProgressCallback``, told
    ("integer search", nodes / max_nodes) — the share of the node budget used — at most once a second
    (and logged every ``PROGRESS_NODES`` nodes).

    Returns (q (l,) int64, J(q), nodes visited). Raises ``SearchLimitError`` after ``max_nodes`` nodes."""
    l = data.n_chords
    if l == 0:
        return np.zeros(0, np.int64), 0.0, 0
    lo, hi = box
    tracker = None if progress is None else Progress("integer search", callback=progress)
    qhat = -data.r / TWO_PI
    p, G = _min_variance_cholesky(data.S / TWO_PI**2)
    qh, lo_p, hi_p = qhat[p], lo[p], hi[p]
    best_q = data.k_round[p].astype(np.int64).copy()
    best = data.cost(data.k_round)
    diag = np.diag(G).copy()
    Gl = G.tolist()
    z = [0] * l
    u = [0.0] * l
    centre = [0.0] * l
    partial = [0.0] * (l + 1)
    step = [0] * l
    # per level: how many in-box candidates have been tried, out of (hi − lo + 1)
    tried = [0] * l
    span = (hi_p - lo_p + 1).tolist()
    lo_l, hi_l, qh_l, diag_l = lo_p.tolist(), hi_p.tolist(), qh.tolist(), diag.tolist()
    nodes = 0
    bound = best * (1.0 - TIE_RTOL)

    def start(i):
        row = Gl[i]
        c = qh_l[i] + sum(row[j] * u[j] for j in range(i))
        centre[i] = c
        zi = int(math.floor(c + 0.5))
        z[i] = zi
        step[i] = 1 if c >= zi else -1
        tried[i] = 0

    def advance(i):
        z[i] += step[i]
        step[i] = -step[i] - (1 if step[i] > 0 else -1)

    i = 0
    start(0)
    while True:
        zi = z[i]
        if zi < lo_l[i] or zi > hi_l[i]:
            # outside the box: the zig-zag continues on the other side until every in-box value is done
            dist = (zi - centre[i]) / diag_l[i]
            if tried[i] >= span[i] or partial[i] + dist * dist >= bound:
                i -= 1
                if i < 0:
                    break
                advance(i)
                continue
            advance(i)
            continue
        nodes += 1
        if nodes % PROGRESS_NODES == 0:  # long searches show progress (lago-cvx -v)
            log.info("integer enumeration: %d nodes (max_nodes %d), %d chords", nodes, max_nodes, l)
        if tracker is not None and nodes % 4096 == 0:
            tracker.update(nodes, max_nodes)
        if nodes > max_nodes:
            raise SearchLimitError(f"the integer enumeration stopped after {max_nodes} nodes ({l} chords): too "
                                   "many cycle integers are uncertain (large rotation noise); raise max_nodes, "
                                   "bound the search with max_shift, or use the chordal regularization")
        tried[i] += 1
        ui = (zi - centre[i]) / diag_l[i]
        cost = partial[i] + ui * ui
        if cost >= bound:  # Schnorr–Euchner: later siblings are farther, so the whole level is done
            i -= 1
            if i < 0:
                break
            advance(i)
            continue
        if i == l - 1:
            best, bound = cost, cost * (1.0 - TIE_RTOL)
            best_q = np.array(z, dtype=np.int64)
            advance(i)
            continue
        u[i] = ui
        partial[i + 1] = cost
        i += 1
        start(i)
    q = np.empty(l, np.int64)
    q[p] = best_q
    if tracker is not None:
        tracker.finish()
    return q, data.cost(q), nodes


