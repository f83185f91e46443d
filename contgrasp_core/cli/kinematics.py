"""``contgrasp kinematics``: integrate the contact kinematics and check them against geometry.

From an initial contact state (rho0, alpha0, s_o0) the arm base pose is placed
(``r0 = gamma(s_o0) - rho0 n``), a curvature profile kappa(s) is integrated twice:
(1) through eq. (8) as an ODE in (rho, alpha, s_o), and (2) through eq. (1) to
the arm shape, which is then sensed geometrically (closest points, eq. (4)).
``max_discrepancy`` is the largest difference between the two, with lengths divided by the
arm length L and angles in radians.
"""

from __future__ import annotations

import argparse
import os
import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..arm import Arm, shape_from_curvature
from ..boundary import Boundary, wrap_arclength
from ..contact import base_pose, integrate_contact, offset_curvature, sense
from ..errors import InvalidParameterError
from ..objects import FIG2_SCALE
from .common import add_object_arguments, object_from_args

__all__ = ["add_parser", "curvature_profile", "run"]

DEFAULT_PROFILE = "parallel:0.01"



def _header_lines(path: str) -> int:
    """How many lines to skip before the numbers: through the first line that is neither a
    comment nor numbers (a header such as ``s,kappa``, as outline files may have), else none."""
    try:
        with open(path, encoding="utf-8") as fh:
            for n, line in enumerate(fh, start=1):
                fields = line.split("#", 1)[0].replace(",", " ").split()
                if not fields:
                    continue
                try:
                    [float(f) for f in fields]
                except ValueError:
                    return n
                return 0
    except (OSError, UnicodeDecodeError):
        return 0  # (np.loadtxt reports it)
    return 0


def curvature_profile(
    spec: str, boundary: Boundary, s: NDArray[np.float64], rho0: float, s_o0: float
) -> NDArray[np.float64]:
    """Curvature samples on ``s`` from a profile spec.

    * ``parallel[:A]`` - curvature of the curve parallel to the boundary at distance rho0
      (keeps rho = rho0 and alpha = pi/2 exactly when alpha0 = pi/2), plus ``A sin(2 pi s/L)``.
    * ``const:K`` - constant curvature K.
    * a path to a CSV/text file with columns ``s, kappa`` (linearly interpolated onto s) or a
      single column of kappa values on s.
    """
    length = float(s[-1])
    if spec.startswith("parallel"):
        _, _, amp_text = spec.partition(":")
        try:
            amp = float(amp_text) if amp_text else 0.0
        except ValueError as exc:
            raise InvalidParameterError(f"bad amplitude in profile {spec!r}; expected parallel:A") from exc
        if not np.isfinite(amp):
            raise InvalidParameterError(f"the amplitude must be finite, got {spec!r}")
        return offset_curvature(boundary, s, rho0, s_o0) + amp * np.sin(2.0 * np.pi * s / length)
    if spec.startswith("const:"):
        try:
            k = float(spec.split(":", 1)[1])
        except ValueError as exc:
            raise InvalidParameterError(f"bad constant in profile {spec!r}; expected const:K") from exc
        if not np.isfinite(k):
            raise InvalidParameterError(f"curvature must be finite, got {spec!r}")
        return np.full_like(s, k)
    if os.path.exists(spec):
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # an empty file is reported below, not warned about
                data = np.loadtxt(spec, delimiter=None if spec.endswith(".txt") else ",", comments="#", ndmin=2,
                                  skiprows=_header_lines(spec))
        except ValueError as exc:
            raise InvalidParameterError(f"cannot parse curvature file {spec!r}: {exc}") from exc
        except OSError as exc:
            raise InvalidParameterError(f"cannot read curvature file {spec!r}: {exc.strerror or exc}") from exc
        if data.size == 0:
            raise InvalidParameterError(f"curvature file {spec!r} holds no values")
        if not np.all(np.isfinite(data)):
            raise InvalidParameterError(f"curvature file {spec!r} contains NaN or infinite values")
        if data.shape[1] >= 2:
            if np.any(np.diff(data[:, 0]) <= 0.0) or data[0, 0] > s[0] or data[-1, 0] < s[-1]:
                raise InvalidParameterError(
                    f"curvature file {spec!r}: s must increase strictly and cover [0, {length:.6g}]"
                )
            return np.interp(s, data[:, 0], data[:, 1])
        if len(data) != len(s):
            raise InvalidParameterError(
                f"curvature file {spec!r} has {len(data)} values but the arm grid has {len(s)} nodes"
            )
        return data[:, 0].copy()
    raise InvalidParameterError(
        f"unknown curvature profile {spec!r}: use parallel[:A], const:K or an existing CSV file"
    )


def add_parser(sub: Any, parents: list[argparse.ArgumentParser]) -> None:
    """Register the ``kinematics`` subcommand."""
    p = sub.add_parser(
        "kinematics",
        parents=parents,
        help="integrate the contact kinematics (eq. (8)) and compare with geometric sensing",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_object_arguments(p, FIG2_SCALE)
    p.add_argument("--rho0", type=float, default=1.0, help="initial contact distance (> 0), default 1")
    p.add_argument("--alpha0", type=float, default=1.55, help="initial contact angle in (0, pi), default 1.55")
    p.add_argument("--s-o0", dest="s_o0", type=float, default=0.0, help="initial shadow arclength, default 0")
    p.add_argument("--length", type=float, help="arm length L (default L_o / 2)")
    p.add_argument("--nodes", type=int, default=401, help="arm grid nodes, default 401")
    p.add_argument(
        "--curvature",
        metavar="PROFILE",
        default=DEFAULT_PROFILE,
        help=f"parallel[:A] | const:K | FILE.csv (default {DEFAULT_PROFILE})",
    )
    p.add_argument("--tol", type=float, default=0.0, help="contact tolerance: in contact where delta >= -tol")
    p.add_argument("--plot", metavar="FILE", help="draw the arm, shadow points and rho/alpha to FILE (png/pdf/svg)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Execute ``contgrasp kinematics``; returns the JSON result (keys in docs/cli.md)."""
    if args.plot:
        from ..figures.draw import check_figure_path

        check_figure_path(args.plot)
    obj = object_from_args(args, FIG2_SCALE)
    boundary = obj.boundary()
    length = boundary.length / 2.0 if args.length is None else args.length
    arm = Arm.paper_tapered(length)
    s = arm.grid(args.nodes)
    base = base_pose(boundary, args.rho0, args.alpha0, args.s_o0)
    kappa = curvature_profile(args.curvature, boundary, s, args.rho0, args.s_o0)
    ode = integrate_contact(s, kappa, boundary, args.rho0, args.alpha0, args.s_o0)
    shape = shape_from_curvature(s, kappa, base)
    radius = arm.radius(s)
    geo = sense(shape, boundary, radius, tol=args.tol)
    d_rho = float(np.max(np.abs(ode.rho - geo.rho)))
    d_alpha = float(np.max(np.abs(ode.alpha - geo.alpha)))
    # arclengths on a closed curve are compared modulo its length (s_o = 0 and s_o = L_o are one point)
    d_so = float(np.max(np.abs(wrap_arclength(ode.s_o - geo.s_o, boundary.length))))
    if args.plot:
        from ..figures.draw import kinematics_figure, save

        title = (f"{obj.text()}: contact kinematics, eq. (8) against geometry\n"
                 f"max discrepancy {max(d_rho / length, d_alpha, d_so / length):.1e}")
        save(kinematics_figure(boundary, shape, radius, ode, geo, title=title), args.plot)
    return {
        "object": obj.text(),
        "object_length": boundary.length,
        "length": length,
        "nodes": int(args.nodes),
        "rho0": args.rho0,
        "alpha0": args.alpha0,
        "s_o0": args.s_o0,
        "curvature_profile": args.curvature,
        "max_discrepancy": max(d_rho / length, d_alpha, d_so / length),
        "discrepancy": {"rho": d_rho, "alpha": d_alpha, "s_o": d_so},
        "contact_fraction": float(np.mean(geo.in_contact)),
        "s": s.tolist(),
        "kappa": kappa.tolist(),
        "rho": ode.rho.tolist(),
        "alpha": ode.alpha.tolist(),
        "s_o": ode.s_o.tolist(),
        "x": shape.r[:, 0].tolist(),
        "y": shape.r[:, 1].tolist(),
        "theta": shape.theta.tolist(),
        "plot": args.plot,
    }
