"""Material and discretisation of the planar Kirchhoff rod (paper eq. (17), the rod dynamics; Appendix IV).

``N`` equal elements of length ``h = L/N``, the tangent angle ``theta_i`` at each centre (exactly
inextensible and unshearable), bending joints at ``s_k = k h`` (joint 0 the clamp; the free tip
carries no couple, eq. (18)); a circular cross-section tapering linearly from ``radius_base`` to
``radius_tip``. :class:`RodModel` holds the SI parameters: damping ``zeta``, quadratic drag,
penalty contact (stiffness, damping, Coulomb friction, ``"regularised"`` or ``"stick"``) and the
muscles' ``max_muscle_stress`` (0: unbounded). Their laws: docs/rod.md ("Model",
"Discretisation", "Muscles with limits"), :mod:`contgrasp_core.rod.loads`,
:mod:`contgrasp_core.rod.coupling`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from contgrasp_core.errors import InvalidParameterError

__all__ = ["RodModel", "FRICTION_MODELS"]

FRICTION_MODELS = ("regularised", "stick")
"""The contact's friction laws: smooth Coulomb (regularised over ``friction_velocity``) or stick-slip."""


def _pos(name: str, v: float, *, allow_zero: bool = False) -> float:
    v = float(v)
    ok = np.isfinite(v) and (v >= 0 if allow_zero else v > 0)
    if not ok:
        rng = ">= 0" if allow_zero else "> 0"
        raise InvalidParameterError(f"{name} must be finite and {rng}, got {v!r}")
    return v


@dataclass(frozen=True)
class RodModel:
    """A clamped-free planar rod: geometry, material, environment, discretisation (SI)."""

    length: float = 0.20
    n_elements: int = 100
    radius_base: float = 0.01
    radius_tip: float = 0.001
    density: float = 1042.0
    youngs_modulus: float = 1.0e4
    base_position: tuple[float, float] = (0.0, 0.0)
    base_angle: float = 0.0
    damping: float = 0.0
    drag_normal: float = 0.0
    drag_tangential: float = 0.0
    contact_stiffness: float = 2.0e3
    contact_damping: float = 0.05
    friction: float = 0.0
    friction_velocity: float = 1.0e-3
    friction_model: str = "regularised"
    max_muscle_stress: float = 0.0

    def __post_init__(self) -> None:
        _pos("length", self.length)
        if int(self.n_elements) != self.n_elements or self.n_elements < 2:
            raise InvalidParameterError(f"n_elements must be an integer >= 2, got {self.n_elements!r}")
        _pos("radius_base", self.radius_base)
        _pos("radius_tip", self.radius_tip)
        _pos("density", self.density)
        _pos("youngs_modulus", self.youngs_modulus)
        for name in ("damping", "drag_normal", "drag_tangential", "contact_stiffness",
                     "contact_damping", "friction", "max_muscle_stress"):
            _pos(name, getattr(self, name), allow_zero=True)
        _pos("friction_velocity", self.friction_velocity)
        if self.friction_model not in FRICTION_MODELS:
            raise InvalidParameterError(f"friction_model must be 'regularised' or 'stick', got {self.friction_model!r}")
        bp = np.asarray(self.base_position, dtype=float)
        if bp.shape != (2,) or not np.all(np.isfinite(bp)):
            raise InvalidParameterError(f"base_position must be two finite numbers, got {self.base_position!r}")
        if not np.isfinite(self.base_angle):
            raise InvalidParameterError("base_angle must be finite (radians)")
        if max(self.radius_base, self.radius_tip) >= 0.5 * self.length:
            raise InvalidParameterError("radii must be < length/2 for a slender rod")

    # ---- discretisation -------------------------------------------------------------------
    @property
    def h(self) -> float:
        """Element length ``L / N``."""
        return self.length / self.n_elements

    @cached_property
    def base(self) -> np.ndarray:
        """``base_position`` as an array (2,), for the compiled kernels."""
        return np.array(self.base_position, dtype=float)

    @cached_property
    def s_nodes(self) -> np.ndarray:
        """Node arclengths ``k h``, ``k = 0..N`` (N+1,)."""
        return np.linspace(0.0, self.length, self.n_elements + 1)

    @cached_property
    def s_centres(self) -> np.ndarray:
        """Element-centre arclengths ``(i + 1/2) h`` (N,)."""
        return (np.arange(self.n_elements) + 0.5) * self.h

    def radius(self, s: np.ndarray) -> np.ndarray:
        """Linearly tapered radius r(s) (m)."""
        s = np.asarray(s, dtype=float)
        return self.radius_base + (self.radius_tip - self.radius_base) * s / self.length

    def bending_stiffness(self, s: np.ndarray) -> np.ndarray:
        """``EI(s) = E pi r(s)^4 / 4`` (N m^2)."""
        return self.youngs_modulus * np.pi * self.radius(s) ** 4 / 4.0

    @cached_property
    def r_centres(self) -> np.ndarray:
        return self.radius(self.s_centres)

    @cached_property
    def mass(self) -> np.ndarray:
        """Element masses ``rho_m A h`` at the centres (N,)."""
        return self.density * np.pi * self.r_centres**2 * self.h

    @cached_property
    def rot_inertia(self) -> np.ndarray:
        """Element rotational inertias ``rho_m I h`` (N,)."""
        return self.density * np.pi * self.r_centres**4 / 4.0 * self.h

    @cached_property
    def weight_matrix(self) -> np.ndarray:
        """``W_jk = sum_i m_i w_ij w_ik`` with ``w_ij = 1`` (j < i), ``1/2`` (j = i), 0 else (N, N);
        see :mod:`contgrasp_core.rod.chain`."""
        n = self.n_elements
        w = np.tril(np.ones((n, n)), -1)
        w[np.diag_indices(n)] = 0.5
        return (w * self.mass[:, None]).T @ w

    @cached_property
    def joint_s(self) -> np.ndarray:
        """Joint arclengths: the clamp and the internal nodes, ``k h``, ``k = 0..N-1``."""
        return self.s_nodes[:-1]

    @cached_property
    def joint_ei(self) -> np.ndarray:
        """Bending stiffness at the joints (N,)."""
        return self.bending_stiffness(self.joint_s)

    @cached_property
    def joint_len(self) -> np.ndarray:
        """Distance between the angles a joint connects: ``h/2`` at the clamp, ``h`` inside (N,)."""
        d = np.full(self.n_elements, self.h)
        d[0] = 0.5 * self.h
        return d

    @cached_property
    def stiffness_matrix(self) -> np.ndarray:
        """Constant bending stiffness matrix ``K`` with ``U = 1/2 (theta - theta_b e0)^T K (...)``.

        With ``kappa_k = (theta_k - theta_{k-1}) / D_k`` (``theta_{-1} = theta_base``) the
        bending energy is ``sum 1/2 EI_k kappa_k^2 D_k``; ``K`` is tridiagonal (N, N).
        """
        n = self.n_elements
        c = self.joint_ei / self.joint_len  # EI_k / D_k
        k = np.zeros((n, n))
        idx = np.arange(n)
        k[idx, idx] += c
        k[idx[:-1], idx[:-1]] += c[1:]
        k[idx[1:], idx[:-1]] -= c[1:]
        k[idx[:-1], idx[1:]] -= c[1:]
        return k

    @cached_property
    def muscle_bound(self) -> np.ndarray | None:
        """The largest active couple at each joint (N,) in N m, ``2/3 sigma_max r^3`` (the whole
        half-section pulling at ``max_muscle_stress``: docs/rod.md); None when unbounded."""
        if self.max_muscle_stress == 0:
            return None
        return 2.0 / 3.0 * self.max_muscle_stress * self.radius(self.joint_s) ** 3

    def joint_curvature(self, theta: np.ndarray) -> np.ndarray:
        """Discrete curvature at the joints ``(theta_k - theta_{k-1}) / D_k`` (N,)."""
        prev = np.concatenate(([self.base_angle], theta[:-1]))
        return (theta - prev) / self.joint_len
