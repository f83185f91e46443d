"""Checks of an implicit step's Newton system shared by the rod tests: the matrix against
central differences of the residual, and quadratic convergence of the increments."""

from __future__ import annotations

from typing import Any

import numpy as np


def difference_matrix(system: Any, state: Any, z: np.ndarray, dt: float, loads: Any, frame: Any,
                      eps: float = 1e-6, self_frame: Any = None) -> np.ndarray:
    """Central differences of ``system.newton_system``'s residual in the unknowns ``z``."""
    fd = np.empty((len(z), len(z)))
    for j in range(len(z)):
        e = np.zeros_like(z)
        e[j] = eps
        fd[:, j] = (system.newton_system(state, z + e, dt, loads, frame, self_frame)[0]
                    - system.newton_system(state, z - e, dt, loads, frame, self_frame)[0]) / (2 * eps)
    return fd


def assert_quadratic_convergence(system: Any, state: Any, z: np.ndarray, dt: float, loads: Any, frame: Any) -> None:
    """Newton from ``z`` reaches round-off, each increment at most ten times the square of the
    previous one once they are small."""
    sizes = []
    for _ in range(12):
        res, jac, _ = system.newton_system(state, z, dt, loads, frame)
        dz = np.linalg.solve(jac, -res)
        z = z + dz
        sizes.append(np.abs(dz).max())
        if sizes[-1] < 1e-11:
            break
    assert sizes[-1] < 1e-11, sizes
    pairs = [(a, b) for a, b in zip(sizes[:-1], sizes[1:], strict=True) if 1e-6 < a < 1.0]
    assert len(pairs) >= 2 and all(b <= 10.0 * a**2 for a, b in pairs), sizes
