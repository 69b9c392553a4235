"""Issue 30 — anchored covariances by selected inversion (``variants.engine.known_blocks``) equal the
blocks of the dense inverse of the anchored information, for every pose and every pattern of known
coordinates (full anchors, position-only, orientation-only, priors)."""

from __future__ import annotations

import numpy as np
import pytest

import lago_cvx as lc
from lago_cvx import variants as V
from lago_cvx.synthetic import manhattan_world, random_graph


def _dense_blocks(res) -> np.ndarray:
    """(n, 3, 3) blocks of the dense (M_UᵀM_U)⁻¹, zeros at known coordinates."""
    n = res.graph.n_poses
    known = res.phase3.system.known
    full = np.linalg.inv(res.phase3.info.toarray())
    upos = np.cumsum(~known) - 1
    out = np.zeros((n, 3, 3))
    for v in range(n):
        c = np.array([2 * v, 2 * v + 1, 2 * n + v])
        loc = np.flatnonzero(~known[c])
        out[v][np.ix_(loc, loc)] = full[np.ix_(upos[c[loc]], upos[c[loc]])]
    return out


def _dense_variances(res) -> np.ndarray:
    free = res.phase1.free
    var = np.zeros(res.graph.n_poses)
    var[free] = np.diag(np.linalg.inv(res.phase1.info.toarray()))
    return var


@pytest.mark.parametrize("case", ["mixed", "one_full", "priors"])
def test_anchored_covariances_equal_the_dense_inverse_everywhere(case):
    w = random_graph(60, 130, seed=4, information="full", sigma_xy=0.1, sigma_theta=0.05)
    t = w.truth
    if case == "mixed":
        res = lc.lago(w.graph, anchors={0: tuple(t[0]), 7: (t[7, 0], t[7, 1], None), 9: (None, None, t[9, 2]),
                                        40: tuple(t[40])})
    elif case == "one_full":
        res = lc.lago(w.graph, anchors={11: tuple(t[11])})
    else:
        res = V.anchored_lago(w.graph, priors={0: (t[0], 1e4 * np.eye(3)), 30: (t[30], np.diag([10., 20., 30.]))})
    cov = res.pose_covariances()
    ref = _dense_blocks(res)
    scale = np.abs(ref).max()
    np.testing.assert_allclose(cov, ref, rtol=1e-8, atol=1e-10 * scale)
    known = res.phase3.system.known
    n = w.graph.n_poses
    coord = np.stack([2 * np.arange(n), 2 * np.arange(n) + 1, 2 * n + np.arange(n)], 1)
    assert np.all(cov[known[coord]] == 0)  # rows of known coordinates are exactly zero
    assert np.all(np.diagonal(cov, axis1=1, axis2=2)[~known[coord]] > 0)
    var = res.phase1.variances()
    np.testing.assert_allclose(var, _dense_variances(res), rtol=1e-8, atol=1e-10 * np.abs(var).max())


def test_one_anchor_at_the_origin_has_plain_lagos_covariances():
    """One full anchor equal to the default frame: the anchored information is plain LAGO's phase-3
    information (the gauge), so the two selected inversions agree."""
    w = manhattan_world(300, seed=2)
    plain = lc.lago(w.graph, information="full")
    anch = lc.lago(w.graph, information="full", anchors={int(w.graph.ids[0]): (0.0, 0.0, 0.0)})
    a, b = plain.pose_covariances(), anch.pose_covariances()
    np.testing.assert_allclose(b, a, rtol=1e-7, atol=1e-9 * np.abs(a).max())
