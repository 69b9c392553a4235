"""The closed-form 2×2 / 3×3 kernels (``lago_cvx.stacks``) against ``numpy.linalg``: same inverses and
Cholesky factors on well- and ill-conditioned stacks, LAPACK's answer where the closed form breaks down
(overflow), and the same ``LinAlgError`` on a matrix that is not positive definite; and
``stacks.unique_sorted`` against ``numpy.unique``."""

from __future__ import annotations

import numpy as np
import pytest

from lago_cvx.stacks import cholesky, spd_inverse


def _stack(k, m=2000, seed=0):
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((m, k, k))
    A = M @ np.swapaxes(M, 1, 2) + 1e-3 * np.eye(k)
    A[0] = np.diag([1e-8, 1.0, 1e8][:k])          # a span of 1e16 (information of a pinned angle)
    A[1] = np.diag([1e300, 2e300, 3e300][:k])     # the cofactors overflow: LAPACK takes it
    A[2] = np.eye(k)
    return A


@pytest.mark.parametrize("k", [2, 3])
def test_inverse_and_cholesky_match_lapack(k):
    A = _stack(k)
    inv, ref = spd_inverse(A), np.linalg.inv(A)
    scale = np.abs(ref).max(axis=(1, 2))
    cond = np.linalg.cond(A)
    assert np.all(np.abs(inv - ref).max(axis=(1, 2)) <= 1e-15 * cond * scale)
    assert np.array_equal(inv, np.swapaxes(inv, 1, 2))
    assert np.array_equal(inv[2], np.eye(k))
    L, Lref = cholesky(A), np.linalg.cholesky(A)
    assert np.all(np.abs(L - Lref).max(axis=(1, 2)) <= 1e-13 * np.abs(Lref).max(axis=(1, 2)))
    assert np.array_equal(L, np.tril(L))


@pytest.mark.parametrize("k", [2, 3])
def test_not_positive_definite_raises_as_numpy_does(k):
    A = _stack(k, m=50)
    A[7] = -np.eye(k)
    with pytest.raises(np.linalg.LinAlgError):
        cholesky(A)
    A[7] = np.zeros((k, k))
    with pytest.raises(np.linalg.LinAlgError):
        spd_inverse(A)


def test_other_sizes_go_to_numpy():
    A = _stack(3, m=4)
    big = np.stack([np.kron(np.eye(2), a) for a in A])  # 6 × 6
    assert np.allclose(spd_inverse(big), np.linalg.inv(big))
    assert np.allclose(cholesky(big), np.linalg.cholesky(big))


def test_unique_sorted_is_numpys_unique():
    from lago_cvx.stacks import unique_sorted

    rng = np.random.default_rng(3)
    for a in (rng.integers(0, 50, 1000), rng.integers(0, 10**12, 5000), np.zeros(0, np.int64),
              np.array([7]), rng.integers(-5, 5, (20, 3))):
        assert np.array_equal(unique_sorted(a), np.unique(a))


def test_rotate_is_eq_9_written_with_rotation_matrices():
    """``stacks.rotate`` (the kernel of eq. (9), Δᵍ = R(θ̂_i)Δˡ, and of the position targets) gives the
    numbers of the equation written with the stacked 2×2 rotations, blocks of rows included."""
    from lago_cvx.posegraph import rot2
    from lago_cvx import stacks
    from lago_cvx.stacks import rotate

    rng = np.random.default_rng(4)
    for m in (0, 1, 7, stacks.BLOCK + 3):
        ang, v = rng.uniform(-40, 40, m), rng.standard_normal((m, 2)) * 10.0 ** rng.integers(-3, 4, (m, 1))
        ref = np.einsum("kab,kb->ka", rot2(ang), v)
        np.testing.assert_allclose(rotate(ang, v), ref, rtol=1e-15, atol=1e-15 * np.abs(v).max(initial=0.0))
