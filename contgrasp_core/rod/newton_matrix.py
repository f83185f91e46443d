"""The Newton matrix of the rod's implicit step (paper eq. (17)) in the structure of its terms,
and its O(N^2) solve.

In the element angles every term of the matrix (:mod:`contgrasp_core.rod.integrator`) is a
sum over the element centres of the centre Jacobian ``dc_i/dtheta_j = h w_ij b_j``
(:mod:`.chain`): the mass matrix ``h^2 W_jk a_j . a_k + diag(J)`` with ``W_jk = sum_i m_i w_ij
w_ik`` and the Gram forms ``sum_i w_ij w_ik left_j^T D_i right_k`` of drag and contact
(:func:`.chain.gram_form`) depend on ``k`` alone above the diagonal (``W_jk = W_{0k}``, ``sum_i
w_ij w_ik D_i = S_k + D_k/2`` for ``j < k``). With ``b_j . z = a_j . (z_1, -z_0)`` the whole
strictly upper triangle is therefore ``a_j . up_k`` (rank 2) except the bending stiffness and the
feedback couple's ``-du_{j+1, j+1}`` on the superdiagonal (``band_j``): the feedback couple at a
joint depends on the angles up to that joint only, so ``du`` is lower triangular.

:class:`ChainMatrix` keeps that form: the lower triangle and the diagonal as a dense array (the
feedback's ``du`` is a general lower triangle), the upper triangle as ``(a, up, band)``.
Gaussian elimination then keeps the Schur complements' upper triangles in the same form,
``(a_i - W_i) . up_k`` with one 2-vector ``W_i`` per row (plus the band entry's share in the
next column), so the factorisation and both triangular solves cost O(N^2) instead of LAPACK's
O(N^3) (:func:`contgrasp_core.rod._kernels_jit.chain_solve`; 13 us instead of 80 us at
N = 100). The elimination does not pivot: the matrix is the mass matrix (symmetric positive
definite) plus ``dt``-scaled stiffness, damping and feedback terms, close to diagonally dominant
(on the paper run's Newton matrices the multipliers stay below 78, median 0.3, and LAPACK's
partial pivoting itself keeps the diagonal in 428 of 431 sampled matrices); a non-finite result
(a vanishing pivot) falls back to LAPACK with pivoting. Backward stable in practice (backward
error <= 1.6e-16 on the paper run's sampled matrices, LAPACK's 2.2e-16); tests/test_newton_matrix.py
checks the solve against LAPACK's solve of the dense matrix on the paper run's Newton matrices
and on random states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contgrasp_core.rod import _kernels

__all__ = ["ChainMatrix", "dense", "solve"]


@dataclass(frozen=True)
class ChainMatrix:
    """An (N, N) matrix with the lower triangle and diagonal of ``lower`` (its strictly upper
    triangle is not read) and the upper triangle ``A_jk = left_j . up_k + [k = j+1] band_j``,
    ``k > j``; ``left``, ``up`` (N, 2), ``band`` (N,) (the last entry unused)."""

    lower: np.ndarray
    left: np.ndarray
    up: np.ndarray
    band: np.ndarray

    def dense(self) -> np.ndarray:
        """The matrix as an (N, N) array."""
        n = len(self.band)
        out = np.tril(self.lower)
        upper = np.triu_indices(n, 1)
        out[upper] = (self.left[:, 0, None] * self.up[:, 0] + self.left[:, 1, None] * self.up[:, 1])[upper]
        out[np.arange(n - 1), np.arange(1, n)] += self.band[:-1]
        return out

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^-1 rhs`` in O(N^2) (module docstring); LAPACK on :meth:`dense` if a pivot vanishes."""
        x = _kernels.chain_solve(self.lower, self.left, self.up, self.band, _kernels.f64(rhs))
        if np.isfinite(x).all():
            return x
        return np.linalg.solve(self.dense(), rhs)


def dense(matrix: np.ndarray | ChainMatrix) -> np.ndarray:
    """A Newton matrix as an (N, N) array."""
    return matrix.dense() if isinstance(matrix, ChainMatrix) else matrix


def solve(matrix: np.ndarray | ChainMatrix, rhs: np.ndarray) -> np.ndarray:
    """The Newton increment ``matrix^-1 rhs``: the structured solve of a :class:`ChainMatrix`,
    LAPACK for a dense matrix (the numpy reference path, a movable object, stick-slip friction)."""
    return matrix.solve(rhs) if isinstance(matrix, ChainMatrix) else np.linalg.solve(matrix, rhs)
