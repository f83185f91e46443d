"""Fast closest-point queries against a fixed object boundary, for the rod's inner loop.

:meth:`contgrasp_core.boundary.Boundary.project` is exact but costs milliseconds per call;
:class:`Obstacle` wraps any boundary with an analytic projection for circles and, for every other
boundary, a table of samples, a KD-tree and one Newton step on the osculating circle (checked
against ``Boundary.project`` in the tests). It returns the paper's sensing quantities (eq. (4)):
foot, object arclength, tangent angle, curvature and the signed distance. :meth:`Obstacle.moved`
is the same object displaced rigidly (:mod:`contgrasp_core.rod.body`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from contgrasp_core.boundary import Boundary
from contgrasp_core.rod import _kernels
from contgrasp_core.rod.body import rotation, to_object_frame, to_world
from contgrasp_core.errors import InvalidParameterError

__all__ = ["Obstacle", "ObstacleProjection"]


@dataclass(frozen=True)
class ObstacleProjection:
    """Closest boundary points: ``foot`` (n,2), ``s_o`` (n,), ``phi`` (n,) tangent angle,
    ``kappa_o`` (n,), ``signed_distance`` (n,) (> 0 outside the object), ``normal_out`` (n,2)
    the outward unit normal at the foot."""

    foot: np.ndarray
    s_o: np.ndarray
    phi: np.ndarray
    kappa_o: np.ndarray
    signed_distance: np.ndarray
    normal_out: np.ndarray


class Obstacle:
    """A fixed rigid object with a smooth boundary, as seen by the rod engine."""

    def __init__(self, boundary: Boundary, *, samples: int = 8192) -> None:
        if not isinstance(boundary, Boundary):
            raise InvalidParameterError(f"boundary must be a contgrasp_core.boundary.Boundary, got {type(boundary)!r}")
        if int(samples) < 64:
            raise InvalidParameterError(f"samples must be >= 64, got {samples!r}")
        self.boundary = boundary
        self.length = float(boundary.length)
        self._circle = None
        if boundary.kind == "circle":
            self._circle = (float(boundary.params["R"]), np.asarray(boundary.params["center"], dtype=float))
            return
        from scipy.spatial import cKDTree  # (only for tabulated objects: a circle's simulator starts without it)

        s, pts = boundary.sample(int(samples))
        self._s = s
        self._pts = pts
        self._phi = boundary.tangent_angle(s)
        self._kap = boundary.curvature(s)
        self._tree = cKDTree(pts)

    @property
    def compiled_circle(self) -> tuple[float, float, float] | None:
        """``(R, cx, cy)`` when the projection is the compiled closed form of a circle (a fixed
        circle, kernels enabled), else None."""
        if self._circle is None or not _kernels.ENABLED:
            return None
        R, c = self._circle
        return R, float(c[0]), float(c[1])

    def project(self, points: np.ndarray) -> ObstacleProjection:
        """Closest boundary point of each of ``points`` (n, 2) (vectorised)."""
        q = np.asarray(points, dtype=float)
        if self._circle is not None and _kernels.ENABLED:
            R, c = self._circle
            return ObstacleProjection(*_kernels.circle_projection(_kernels.f64(q), R, float(c[0]), float(c[1])))
        if self._circle is not None:
            R, c = self._circle
            d = q - c
            dist_c = np.hypot(d[:, 0], d[:, 1])
            ang = np.arctan2(d[:, 1], d[:, 0])
            safe = np.where(dist_c > 0, dist_c, 1.0)
            n_out = np.where(dist_c[:, None] > 0, d / safe[:, None], np.array([1.0, 0.0]))
            foot = c + R * n_out
            s_o = np.mod(ang, 2 * np.pi) * R
            return ObstacleProjection(foot=foot, s_o=s_o, phi=ang + 0.5 * np.pi,
                                      kappa_o=np.full(len(q), 1.0 / R),
                                      signed_distance=dist_c - R, normal_out=n_out)
        _, i = self._tree.query(q)
        p, phi, k = self._pts[i], self._phi[i], self._kap[i]
        t = np.stack([np.cos(phi), np.sin(phi)], axis=1)
        n_in = np.stack([-t[:, 1], t[:, 0]], axis=1)
        rel = q - p
        along = np.sum(rel * t, axis=1)
        off = np.sum(rel * n_in, axis=1)
        ds = along / (1.0 - k * off)  # Newton step on the osculating circle
        foot = p + ds[:, None] * t + 0.5 * (k * ds**2)[:, None] * n_in
        phi_f = phi + k * ds
        n_out = -np.stack([-np.sin(phi_f), np.cos(phi_f)], axis=1)
        sd = np.sum((q - foot) * n_out, axis=1)
        return ObstacleProjection(foot=foot, s_o=np.mod(self._s[i] + ds, self.length), phi=phi_f,
                                  kappa_o=k, signed_distance=sd, normal_out=n_out)

    def moved(self, q: np.ndarray, centroid: np.ndarray) -> Obstacle:
        """This object displaced by ``q = (dx, dy, dpsi)`` from its start pose (a translation of
        ``centroid`` and a rotation about it; :func:`contgrasp_core.rod.body.to_world`)."""
        return _MovedObstacle(self, q, centroid)


class _MovedObstacle(Obstacle):
    """An :class:`Obstacle` displaced rigidly; shares the start pose's tables."""

    def __init__(self, base: Obstacle, q: np.ndarray, centroid: np.ndarray) -> None:  # (no table to build)
        self.boundary, self.length = base.boundary, base.length
        self._base = base
        self._circle = None  # (its projection is the start pose's, moved)
        self._q = np.array(q, dtype=float)
        self._centroid = np.array(centroid, dtype=float)

    def project(self, points: np.ndarray) -> ObstacleProjection:
        q, c = self._q, self._centroid
        pr = self._base.project(to_object_frame(np.asarray(points, dtype=float), q, c))
        return ObstacleProjection(foot=to_world(pr.foot, q, c), s_o=pr.s_o, phi=pr.phi + q[2], kappa_o=pr.kappa_o,
                                  signed_distance=pr.signed_distance, normal_out=pr.normal_out @ rotation(q[2]).T)

    def moved(self, q: np.ndarray, centroid: np.ndarray) -> Obstacle:
        return self._base.moved(q, centroid)
