"""Compiled kernels (numba ``@njit(cache=True)``) of the rod engine's hot paths.

:func:`newton_system` computes the residual and the exact Newton matrix of
:meth:`contgrasp_core.rod.integrator.RodSystem._evaluate` without temporaries, the matrix in its
structured form (:class:`contgrasp_core.rod.newton_matrix.ChainMatrix`), and :func:`chain_solve`
solves it in O(N^2); results equal the numpy path to rounding (tests/test_kernels.py).
``CONTGRASP_KERNELS=0`` (or :data:`ENABLED` = False) selects the numpy path. The compiled
functions live in :mod:`._kernels_jit`, imported on first use, so importing the package does not
import numba. Caching, debugging and measurements: docs/design.md, "Compiled kernels".
"""

from __future__ import annotations

import importlib
import os
from typing import Any

import numpy as np

__all__ = ["ENABLED", "f64", "load"]  # and, loaded on first use, the kernels of _kernels_jit

ENABLED: bool = os.environ.get("CONTGRASP_KERNELS", "1").strip().lower() not in ("0", "false", "no", "off")
"""Use the kernels (True) or the numpy reference code (False). Read at every call, so it can be
switched at run time (the benchmarks compare both in one process)."""


def f64(x: object) -> np.ndarray:
    """``x`` as a C-contiguous, writeable float64 array (a copy only when it is not one already):
    the kernels are compiled for exactly that array type, so a read-only or strided argument
    (e.g. a view of a message buffer) does not trigger a second compilation."""
    if isinstance(x, np.ndarray) and x.dtype == np.float64 and x.flags.c_contiguous and x.flags.writeable:
        return x  # (the common case, ~6x cheaper than np.require's checks; some 47 calls per step)
    return np.require(x, dtype=np.float64, requirements=("C", "W"))


_JIT_NAMES = ("frames_nodes", "kinetic_energy", "newton_system", "chain_solve", "circle_projection",
              "circle_shadow_geometry", "circle_sense", "joint_couple_jacobian", "self_contact_pairs")


def load() -> None:
    """Import the compiled kernels now (numba and its on-disk cache; idempotent, cheap once
    loaded). :class:`~contgrasp_core.rod.integrator.RodSystem` calls it when it is created, so a
    simulation pays this in its set-up rather than in its first time step."""
    if ENABLED and "newton_system" not in globals():
        __getattr__("newton_system")


def __getattr__(name: str) -> Any:
    """The compiled kernels, loaded (numba imported, cache read) on first access."""
    if name in _JIT_NAMES:
        mod = importlib.import_module("contgrasp_core.rod._kernels_jit")
        for n in _JIT_NAMES:
            globals()[n] = getattr(mod, n)
        return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
