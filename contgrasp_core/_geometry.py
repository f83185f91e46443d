"""Compiled closest-point kernels for :mod:`contgrasp_core.boundary` (numba, cached on disk).

:func:`ellipse_parameters`: the curve parameter ``t`` of the closest point of an axis-aligned
ellipse ``(e0 cos t, e1 sin t)`` to each query point, by D. Eberly's method ("Distance from a
point to an ellipse, an ellipsoid, or a hyperellipsoid", Geometric Tools, 2013): reflect the
query into the first quadrant, where the closest point is the unique root of a monotone function
of one variable, found by bisection to full double precision (no starting guess, no local
minima: the global closest point for every query, inside or outside, including the centre and
the axes). ``NUMBA_DISABLE_JIT=1`` runs it as plain Python.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["ellipse_parameters"]


@njit(cache=True)
def _root(r0: float, z0: float, z1: float, g: float) -> float:
    """The root ``s`` of ``(r0 z0 / (s + r0))^2 + (z1 / (s + 1))^2 = 1`` (bisection to rounding)."""
    n0 = r0 * z0
    s0 = z1 - 1.0
    s1 = 0.0 if g < 0 else math.hypot(n0, z1) - 1.0
    s = 0.5 * (s0 + s1)
    for _ in range(2100):  # at most ~1100 halvings separate two doubles
        s = 0.5 * (s0 + s1)
        if s == s0 or s == s1:
            break
        ratio0 = n0 / (s + r0)
        ratio1 = z1 / (s + 1.0)
        g = ratio0 * ratio0 + ratio1 * ratio1 - 1.0
        if g > 0:
            s0 = s
        elif g < 0:
            s1 = s
        else:
            break
    return s


@njit(cache=True)
def ellipse_parameters(q: np.ndarray, e0: float, e1: float) -> np.ndarray:
    """Parameters ``t`` in [0, 2 pi) of the closest points of the ellipse ``(e0 cos t, e1 sin t)``
    (centred, axis-aligned) to the points ``q`` (n, 2) given in the ellipse's frame."""
    n = q.shape[0]
    out = np.empty(n)
    swap = e0 < e1  # the method wants the first semi-axis the larger
    big = e1 if swap else e0
    small = e0 if swap else e1
    for i in range(n):
        u = q[i, 1] if swap else q[i, 0]
        v = q[i, 0] if swap else q[i, 1]
        y0 = abs(u)
        y1 = abs(v)
        if y1 > 0:
            if y0 > 0:
                z0 = y0 / big
                z1 = y1 / small
                g = z0 * z0 + z1 * z1 - 1.0
                if g != 0:
                    r0 = (big / small) ** 2
                    sbar = _root(r0, z0, z1, g)
                    x0 = r0 * y0 / (sbar + r0)
                    x1 = y1 / (sbar + 1.0)
                else:
                    x0 = y0
                    x1 = y1
            else:
                x0 = 0.0
                x1 = small
        else:
            numer0 = big * y0
            denom0 = big * big - small * small
            if numer0 < denom0:
                xde0 = numer0 / denom0
                x0 = big * xde0
                x1 = small * math.sqrt(max(1.0 - xde0 * xde0, 0.0))
            else:
                x0 = big
                x1 = 0.0
        x0 = math.copysign(x0, u)
        x1 = math.copysign(x1, v)
        fx = x1 if swap else x0  # the foot in the ellipse's frame
        fy = x0 if swap else x1
        t = math.atan2(fy / e1, fx / e0)
        if t < 0:
            t += 2.0 * math.pi
        if t >= 2.0 * math.pi:
            t = 0.0
        out[i] = t
    return out
