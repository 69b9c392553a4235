"""The fast versions against plain references written here: ``is_spd`` (cofactors where safe) against
LAPACK's determinant, the block-vectorized Manhattan walk against the step-by-step loop, the same-cell
loop-closure pairs against the KD-tree, and ``write_graph``'s block formatting against one ``%r`` per
number."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from lago_cvx.io.writer import format_records
from lago_cvx.posegraph import is_spd
from lago_cvx.synthetic.worlds import _grid_step, _manhattan_walk, _same_cell_pairs


def _is_spd_reference(info, rtol=1e-9):
    """The former implementation: Sylvester's minors with np.linalg.det for the 3×3 one."""
    info = np.asarray(info, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.abs(info).max(axis=(1, 2))
        sym = np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2)) <= rtol * np.maximum(scale, 1e-300)
        s = 0.5 * (info + np.swapaxes(info, 1, 2))
        d2 = s[:, 0, 0] * s[:, 1, 1] - s[:, 0, 1] * s[:, 1, 0]
        d3 = np.linalg.det(s)
        finite = np.isfinite(s).all((1, 2)) & np.isfinite(d2) & np.isfinite(d3)
        return sym & (s[:, 0, 0] > 0) & (d2 > 0) & (d3 > 0) & finite


def _matrices(rng, m):
    a = rng.normal(size=(m, 3, 3))
    spd = a @ np.swapaxes(a, 1, 2)
    b = rng.normal(size=(m, 3, 2))
    rank2 = b @ np.swapaxes(b, 1, 2)
    yield spd
    yield a + np.swapaxes(a, 1, 2)                                                   # mostly indefinite
    yield rank2                                                                      # singular
    yield rank2 + np.eye(3) * 10.0 ** rng.uniform(-20, 0, (m, 1, 1))                 # nearly singular
    with np.errstate(over="ignore"):
        scaled = spd * 10.0 ** rng.uniform(-320, 308, (m, 1, 1))
    yield scaled                                                                     # every magnitude
    near = spd.copy()
    near[:, 0, 1] += 1e-9 * rng.normal(size=m) * np.abs(spd).max((1, 2))            # at the symmetry tolerance
    yield near
    odd = spd.copy()
    odd[rng.random(m) < 0.1, 1, 1] = np.nan
    odd[rng.random(m) < 0.1, 2, 0] = np.inf
    yield odd
    diag = np.zeros((m, 3, 3))
    diag[:, [0, 1, 2], [0, 1, 2]] = 10.0 ** rng.uniform(-200, 200, (m, 3))
    yield diag
    ints = rng.integers(-3, 4, (m, 3, 3)).astype(float)
    yield ints + np.swapaxes(ints, 1, 2)                                              # exact zeros of det


def test_is_spd_matches_lapack_determinant():
    rng = np.random.default_rng(2)
    n = 0
    for _ in range(4):
        for info in _matrices(rng, 20_000):
            assert np.array_equal(is_spd(info), _is_spd_reference(info))
            n += info.shape[0]
    assert n == 720_000


def _walk_reference(n, p_turn, half, rng):
    """The step-by-step loop: every step by the library's one-step rule ``_grid_step``."""
    u = rng.random(n - 1).tolist()
    side = np.where(rng.random(n - 1) < 0.5, 1, -1).tolist()
    x = y = d = 0
    xs, ys, ts = [0], [0], [0]
    for k in range(n - 1):
        x, y, d, t = _grid_step(x, y, d, side[k], u[k] < p_turn, half)
        xs.append(x)
        ys.append(y)
        ts.append(t)
    return np.array(xs), np.array(ys), np.cumsum(ts)


@pytest.mark.parametrize("state, expected", [
    ((0, 0, 0, 1, False, 2), (1, 0, 0, 0)),     # inside: straight on
    ((0, 0, 0, -1, True, 2), (0, -1, 3, -1)),   # inside: the preferred turn (right)
    ((2, 0, 0, 1, False, 2), (2, 1, 1, 1)),     # at the +x edge: straight leaves, side s (left) first
    ((2, 2, 0, 1, False, 2), (2, 1, 3, -1)),    # corner: straight and left leave, right
    ((2, 2, 0, 1, True, 2), (2, 1, 3, -1)),     # corner, turning left preferred: left leaves, right
    ((-1, 0, 2, 1, True, 1), (-1, -1, 3, 1)),   # at the −x edge heading −x: left (−y)
])
def test_grid_step_takes_the_first_move_that_stays_inside(state, expected):
    assert _grid_step(*state) == expected


@pytest.mark.parametrize("n, p_turn, half, seed", [(2, 0.3, 2, 0), (50, 1.0, 1, 1), (3000, 0.3, 27, 2),
                                                   (3000, 0.0, 1, 3), (20000, 0.9, 3, 4), (20000, 0.3, 70, 5)])
def test_walk_matches_step_by_step_loop(n, p_turn, half, seed):
    fast = _manhattan_walk(n, p_turn, half, np.random.default_rng(seed))
    slow = _walk_reference(n, p_turn, half, np.random.default_rng(seed))
    for a, b in zip(fast, slow):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("n, half, seed", [(1, 1, 0), (500, 3, 1), (5000, 20, 2), (5000, 1, 3)])
def test_same_cell_pairs_match_kd_tree(n, half, seed):
    xs, ys, _ = _walk_reference(n, 0.4, half, np.random.default_rng(seed))
    cells = (xs + half) * (2 * half + 1) + (ys + half)
    pairs = _same_cell_pairs(cells)
    ref = cKDTree(np.column_stack([xs, ys]).astype(float)).query_pairs(0.5, output_type="ndarray")
    canon = lambda p: np.unique(np.sort(p, axis=1), axis=0) if p.size else np.zeros((0, 2), np.int64)
    assert pairs.shape == ref.shape and np.array_equal(canon(pairs), canon(ref))
    assert (pairs[:, 0] != pairs[:, 1]).all() if pairs.size else True


def test_block_formatting_equals_repr_per_number():
    rng = np.random.default_rng(7)
    k = 3000
    ids = np.column_stack([rng.integers(-2 ** 62, 2 ** 62, k), np.arange(k)])
    values = np.column_stack([
        rng.normal(size=k) * 10.0 ** rng.integers(-30, 30, k),   # full precision, every magnitude
        np.round(rng.normal(size=k), 3),                          # short decimals
        rng.integers(-10 ** 6, 10 ** 6, k).astype(float),         # integral
        np.full(k, 400.0),                                        # constant
        np.full(k, -0.0),                                         # constant negative zero
        np.where(rng.random(k) < 0.5, 0.0, -0.0),                 # mixed zeros
        rng.choice([1e16, 9007199254740993.0, 1e15, 2.0 ** 60, 1e-320, 5e-324], k),  # edges of %d.0
    ])
    expected = "".join(("TAG" + " %d" * 2 + " %r" * values.shape[1] + "\n") % (*i, *v)
                       for i, v in zip(ids.tolist(), values.tolist()))
    assert format_records("TAG", ids, values) == expected.encode()
    constant_ids = np.zeros((4, 1), np.int64)
    assert format_records("V", constant_ids, np.ones((4, 1))) == b"V 0 1.0\n" * 4
    assert math.isclose(float(format_records("V", constant_ids[:1], np.array([[0.1]])).split()[-1]), 0.1)
