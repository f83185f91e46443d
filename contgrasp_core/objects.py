"""The paper's three test objects and the command-line way of naming an object.

Paper Sec. III-B: a circle of radius 5, an ellipse with semi-axes 8 and 4, and a deformed
circle of radius 5 (see :func:`contgrasp_core.boundary.deformed_circle` for its formula).
"""

from __future__ import annotations

from .boundary import Boundary, circle, deformed_circle, ellipse, from_points, load_points
from .errors import InvalidParameterError

__all__ = ["PAPER_OBJECTS", "paper_object", "make_object"]

PAPER_OBJECTS = ("circle", "ellipse", "deformed")


def paper_object(name: str) -> Boundary:
    """One of the paper's objects, centred at the origin: 'circle', 'ellipse' or 'deformed'."""
    if name == "circle":
        return circle(5.0)
    if name == "ellipse":
        return ellipse(8.0, 4.0)
    if name == "deformed":
        return deformed_circle(5.0)
    raise InvalidParameterError(f"unknown object {name!r}; choose one of {', '.join(PAPER_OBJECTS)}")


def make_object(name: str, *, outline: str | None = None, closed: bool = False, smoothing: float = 0.0) -> Boundary:
    """A paper object by name, or a user outline read from a CSV file (``name='points'``)."""
    if outline is not None:
        return from_points(load_points(outline), closed=closed, smoothing=smoothing)
    if name == "points":
        raise InvalidParameterError("object 'points' needs an outline file (--outline FILE.csv)")
    return paper_object(name)
