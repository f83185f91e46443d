"""The Newton matrix of the rod's implicit step (paper eq. (17)) in the structure of its terms,
and its O(N^2) solve.

Every term of the matrix is a sum over the element centres of the centre Jacobian, so its
strictly upper triangle is rank 2 plus a superdiagonal band. :class:`ChainMatrix` keeps that
form (the lower triangle dense); Gaussian elimination without pivoting keeps it in the Schur
complements, so the factorisation and solves cost O(N^2)
(:func:`contgrasp_core.rod._kernels_jit.chain_solve`); a vanishing pivot falls back to LAPACK.
Derivation and accuracy: docs/rod.md, "Integrator" (Solve); measurements: benchmarks/RESULTS.md.
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
