"""How an object is named: one syntax for the built-in shapes and a user's outline.

Every entry point that takes an object (the ``contgrasp`` commands, ``contgrasp-launch``, the
simulator node, the scenario model) names it with an :class:`ObjectSpec`, written
``NAME[:P1,P2,...]`` (``circle``, ``ellipse``, ``deformed``: paper Sec. III-A) or
``outline:FILE.csv``. Omitted parameters take the caller's :class:`ObjectScale`
(:data:`FIG2_SCALE`, the paper's dimensionless examples, or :data:`ROD_SCALE`, the rod scenario
of Sec. V-C in metres); :meth:`ObjectSpec.text` is the one name every command prints and
``--object`` takes back. The table of names, parameters and defaults: docs/cli.md, "Objects: one
syntax everywhere".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .boundary import Boundary, circle, deformed_circle, ellipse, from_points, load_points
from .errors import InvalidParameterError

__all__ = ["SHAPES", "SYNTAX", "OUTLINE", "PAPER_OBJECTS", "ObjectScale", "FIG2_SCALE", "ROD_SCALE", "ObjectSpec", "outline_text",
           "paper_object"]

SHAPES: dict[str, tuple[str, ...]] = {
    "circle": ("R",),
    "ellipse": ("a", "b"),
    "deformed": ("R", "amplitude", "lobes", "phase"),
}
"""The built-in shapes and the names of their parameters, in the order the text syntax takes them."""

SYNTAX = ", ".join(f"{name}[:{','.join(names)}]" for name, names in SHAPES.items())
"""The built-in shapes' text syntax, for help and error messages."""

PAPER_OBJECTS = tuple(SHAPES)
"""The paper's three objects (Sec. III-A), by name."""

OUTLINE = "outline"
"""The name of a user's outline (``outline:FILE.csv``)."""


@dataclass(frozen=True)
class ObjectScale:
    """Defaults for a context's units: each shape's full parameter list and the object's centre."""

    name: str
    defaults: dict[str, tuple[float, ...]]
    center: tuple[float, float]


FIG2_SCALE = ObjectScale("paper Figs. 2-3 (dimensionless)",
                         {"circle": (5.0,), "ellipse": (8.0, 4.0), "deformed": (5.0, 0.15, 3.0, 0.0)}, (0.0, 0.0))
ROD_SCALE = ObjectScale("rod scenario (m)",
                        {"circle": (0.025,), "ellipse": (0.03, 0.02), "deformed": (0.025, 0.15, 3.0, 0.0)}, (0.08, 0.08))


@dataclass(frozen=True)
class ObjectSpec:
    """An object: a built-in ``shape`` with its full ``params``, placed at ``center`` and turned by
    ``angle`` (rad, ellipse only), or ``shape == "outline"`` with the outline's ``points`` (n, 2)
    and the ``source`` file it was read from.

    Build it with :meth:`parse` (text), :meth:`from_outline` (a CSV file) or directly; it is
    validated on construction (:meth:`boundary` is built once to check it) and converts to and
    from text (:meth:`text`) and plain dicts (:meth:`to_dict`, for ROS parameters, recordings and
    JSON).
    """

    shape: str
    params: tuple[float, ...] = ()
    center: tuple[float, float] = (0.0, 0.0)
    angle: float = 0.0
    points: tuple[tuple[float, float], ...] = ()
    source: str = ""
    _boundary: Boundary | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.shape != OUTLINE and self.shape not in SHAPES:
            raise InvalidParameterError(f"unknown object {self.shape!r}; use {SYNTAX}, or outline:FILE.csv "
                                        "(your own object: a CSV file of x, y rows; also --outline FILE.csv, "
                                        "or outline:=FILE.csv in a launch file)")
        object.__setattr__(self, "params", tuple(float(v) for v in self.params))
        object.__setattr__(self, "center", _pair("object centre", self.center))
        object.__setattr__(self, "angle", float(self.angle))
        object.__setattr__(self, "points", tuple(_pair("outline point", p) for p in self.points))
        if self.shape == OUTLINE:
            if self.params:
                raise InvalidParameterError("an outline takes no shape parameters")
        elif len(self.params) != len(SHAPES[self.shape]):
            raise InvalidParameterError(
                f"{self.shape} takes {len(SHAPES[self.shape])} parameters ({', '.join(SHAPES[self.shape])}), "
                f"got {len(self.params)}")
        elif self.points:
            raise InvalidParameterError(f"a {self.shape} takes no outline points")
        if self.shape == "deformed" and self.params[2] != int(self.params[2]):
            raise InvalidParameterError(f"deformed: lobes must be an integer, got {self.params[2]:g}")
        if self.angle and self.shape != "ellipse":
            raise InvalidParameterError(f"only an ellipse takes an angle; a {self.shape} was given {self.angle:g}")
        if not np.isfinite(self.angle):
            raise InvalidParameterError(f"object angle must be finite, got {self.angle}")
        object.__setattr__(self, "_boundary", self._build())

    # ------------------------------------------------------------------ construction
    @classmethod
    def parse(cls, text: str, scale: ObjectScale = FIG2_SCALE) -> ObjectSpec:
        """``NAME[:P1,P2,...]`` (see the module table) or ``outline:FILE.csv``, the inverse of
        :meth:`text`; omitted trailing parameters and the centre come from ``scale``."""
        if not isinstance(text, str) or not text.strip():
            raise InvalidParameterError(f"--object must be NAME[:PARAMS], got {text!r}")
        name, _, arg = text.strip().partition(":")
        if name == OUTLINE:
            if not arg.strip():
                raise InvalidParameterError("an outline names its CSV file of x, y rows: outline:FILE.csv "
                                            "(also --outline FILE.csv, or outline:=FILE.csv in a launch file)")
            return cls.from_outline(arg.strip())
        if name not in SHAPES:
            cls(name)  # raises the unknown-object error
        try:
            given = [float(v) for v in arg.split(",")] if arg.strip() else []
        except ValueError:
            raise InvalidParameterError(
                f"--object {text!r}: parameters must be numbers, {name}[:{','.join(SHAPES[name])}]") from None
        full = scale.defaults[name]
        if len(given) > len(full):
            raise InvalidParameterError(
                f"--object {text!r}: {name} takes at most {len(full)} parameters ({', '.join(SHAPES[name])})")
        return cls(name, tuple(given) + full[len(given):], center=scale.center)

    @classmethod
    def from_outline(cls, path: str | Path) -> ObjectSpec:
        """A user's outline from a CSV/whitespace file with two columns ``x, y`` (a header line is
        allowed); closed implicitly when the last row does not repeat the first."""
        pts = load_points(str(path))
        return cls(OUTLINE, points=tuple(map(tuple, pts.tolist())), source=str(path))

    @classmethod
    def from_cli(cls, obj: str | None, outline: str | None, scale: ObjectScale = FIG2_SCALE) -> ObjectSpec:
        """What the command line's ``--object NAME[:PARAMS]`` / ``--outline FILE.csv`` name (one of them;
        the default object is the scale's circle)."""
        if outline is not None:
            if obj is not None:
                raise InvalidParameterError("give either --object or --outline, not both")
            return cls.from_outline(outline)
        return cls.parse("circle" if obj is None else obj, scale)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ObjectSpec:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(data, dict) or "shape" not in data:
            raise InvalidParameterError(f"an object description needs a 'shape', got {data!r}")
        unknown = set(data) - {"shape", "params", "center", "angle", "points", "source"}
        if unknown:
            raise InvalidParameterError(f"unknown object fields {sorted(unknown)}")
        return cls(str(data["shape"]), tuple(data.get("params", ())), tuple(data.get("center", (0.0, 0.0))),
                   float(data.get("angle", 0.0)), tuple(map(tuple, data.get("points", ()))), str(data.get("source", "")))

    @classmethod
    def coerce(cls, value: ObjectSpec | str | dict[str, Any], scale: ObjectScale = FIG2_SCALE) -> ObjectSpec:
        """An :class:`ObjectSpec` as is, text (:meth:`parse`) or a dict (:meth:`from_dict`)."""
        if isinstance(value, ObjectSpec):
            return value
        if isinstance(value, str):
            return cls.parse(value, scale)
        if isinstance(value, dict):
            return cls.from_dict(value)
        raise InvalidParameterError(f"an object must be NAME[:PARAMS], an ObjectSpec or a dict, got {value!r}")

    def __reduce__(self) -> tuple[Any, ...]:
        # pickled by its fields (the boundary's curve is a closure): process pools and Dask workers
        return (ObjectSpec, (self.shape, self.params, self.center, self.angle, self.points, self.source))

    # ------------------------------------------------------------------ views
    def boundary(self) -> Boundary:
        """The object's :class:`~contgrasp_core.boundary.Boundary` (built once)."""
        assert self._boundary is not None
        return self._boundary

    def text(self) -> str:
        """The object's name, as every command prints it and as ``--object`` takes it back
        (:meth:`parse`): ``NAME:P1,...`` with every parameter, shortest exact numbers, for a
        built-in shape (centre and angle are the caller's scale's, not included);
        :func:`outline_text` of the file for an outline (``N points`` when it has no file)."""
        if self.shape == OUTLINE:
            return outline_text(self.source) if self.source else f"{OUTLINE}:{len(self.points)} points"
        return f"{self.shape}:{','.join(_number(v) for v in self.params)}"

    def to_dict(self) -> dict[str, Any]:
        """Plain types only (JSON, YAML, ROS parameters, recording metadata)."""
        out: dict[str, Any] = {"shape": self.shape, "center": list(self.center)}
        if self.shape == OUTLINE:
            out["points"] = [list(p) for p in self.points]
            out["source"] = self.source
        else:
            out["params"] = list(self.params)
            if self.angle:
                out["angle"] = self.angle
        return out

    @property
    def radius(self) -> float:
        """The object's nominal radius (the adaptive gain ``mu2`` of Appendix IV needs one): ``R``
        of a circle or deformed circle, ``sqrt(a b)`` of an ellipse, ``sqrt(area / pi)`` of an
        outline (the circle of the same area)."""
        if self.shape in ("circle", "deformed"):
            return self.params[0]
        if self.shape == "ellipse":
            return float(np.sqrt(self.params[0] * self.params[1]))
        _, pts = self.boundary().sample(720)
        x, y = pts[:, 0], pts[:, 1]
        area = 0.5 * abs(float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)))
        return float(np.sqrt(area / np.pi))

    @property
    def reference(self) -> tuple[float, float]:
        """Where the object's torques are taken (Q1, Q3 and Q_H depend on it, Q2 does not): a
        built-in shape's ``center``, an outline's centroid (its file's origin may lie anywhere)."""
        if self.shape != "outline":
            return self.center
        from .rod.body import mass_properties

        c = mass_properties(self.boundary())[1]
        return float(c[0]), float(c[1])

    def _build(self) -> Boundary:
        p, c = self.params, self.center
        if self.shape == "circle":
            return circle(p[0], c)
        if self.shape == "ellipse":
            return ellipse(p[0], p[1], c, self.angle)
        if self.shape == "deformed":
            return deformed_circle(p[0], p[1], int(p[2]), p[3], c)
        pts = np.asarray(self.points, dtype=float).reshape(-1, 2)
        closed = len(pts) > 1 and not np.array_equal(pts[0], pts[-1])
        return from_points(pts, closed=closed)


def outline_text(source: str) -> str:
    """The name of the outline read from the file ``source`` (as given): ``outline:<source>``;
    for a recording whose outline file may not be at hand (the name needs no file)."""
    return f"{OUTLINE}:{source}"


def _number(value: float) -> str:
    """``value`` as short as ``:g`` makes it when that reads back exactly, else its exact repr."""
    short = f"{value:g}"
    return short if float(short) == value else repr(value)


def _pair(what: str, value: Any) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{what} must be two numbers x, y, got {value!r}") from None
    if not (np.isfinite(x) and np.isfinite(y)):
        raise InvalidParameterError(f"{what} must be finite, got ({x}, {y})")
    return x, y


def paper_object(name: str) -> Boundary:
    """One of the paper's Fig. 2 objects by name ('circle', 'ellipse', 'deformed'), centred at the origin."""
    if name not in SHAPES:
        raise InvalidParameterError(f"unknown object {name!r}; choose one of {', '.join(PAPER_OBJECTS)}")
    return ObjectSpec.parse(name, FIG2_SCALE).boundary()
