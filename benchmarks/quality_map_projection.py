"""What the closed-form projections (circle: closed form; ellipse: Eberly's root bracketing) do
to ``contgrasp quality-map``: the full 72 x 11 map (serial executor, Nelder-Mead maxima
included), with ``Boundary.project`` as it is and patched back to the general closest-point
search (the path every shape took before), interleaved, in one process; medians and paired
ratios; load average at start and end. The maps must be equal (checked to 1e-8: every Q on the
grid and the maximal Q1..Q3). The maximiser's LOCATION is not compared: for the circle Q does
not depend on psi and the ellipse has two symmetric maxima, so Nelder-Mead's start (the grid's
argmax among values equal to rounding) and hence the reported pose moves with any
rounding-level change, with the same maximal value.

    python benchmarks/quality_map_projection.py [--objects circle,ellipse] [--repeats 2] [--no-optimise]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from contgrasp_core import boundary as bmod  # noqa: E402
from contgrasp_core.cli import main as cli  # noqa: E402

FAST = bmod.Boundary.project


def general(self, points, *, candidates=4):  # type: ignore[no-untyped-def]
    """Boundary.project through the general search whatever the shape."""
    kind = self.kind
    self.kind = "general"
    try:
        return FAST(self, points, candidates=candidates)
    finally:
        self.kind = kind


def numbers(out: object) -> list[float]:
    """Every number in the JSON result but the timings (for the equality check)."""
    if isinstance(out, dict):  # timings and the optimum's location excluded (see the module docstring)
        return [v for k in sorted(out) if "time" not in k and "second" not in k
                and k not in ("psi_opt", "d", "psi", "base", "x", "y", "evaluations") for v in numbers(out[k])]
    if isinstance(out, list):
        return [v for x in out for v in numbers(x)]
    return [float(out)] if isinstance(out, int | float) and not isinstance(out, bool) else []


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", default="circle,ellipse")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--no-optimise", action="store_true", help="the map only (no Nelder-Mead maxima)")
    args = ap.parse_args()
    print(f"load average at start {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    for obj in args.objects.split(","):
        walls: dict[str, list[float]] = {"general search": [], "closed form": []}
        results = {}
        for _ in range(args.repeats):
            for label, fn in (("general search", general), ("closed form", FAST)):
                bmod.Boundary.project = fn  # type: ignore[method-assign]
                buf = io.StringIO()
                t = time.perf_counter()
                try:
                    with contextlib.redirect_stdout(buf):
                        cli(["quality-map", "--object", obj, "--psi-steps", "72", "--d-steps", "11",
                             "--executor", "serial", "--json"] + (["--no-optimise"] if args.no_optimise else []))
                finally:
                    bmod.Boundary.project = FAST  # type: ignore[method-assign]
                walls[label].append(time.perf_counter() - t)
                results[label] = json.loads(buf.getvalue())
                print(f"  {obj:8s} {label:15s} {walls[label][-1]:6.2f} s (load {os.getloadavg()[0]:.2f})", flush=True)
        a, b = np.array(numbers(results["general search"])), np.array(numbers(results["closed form"]))
        same = a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-8, atol=1e-12, equal_nan=True))
        pair = np.median(np.array(walls["general search"]) / np.array(walls["closed form"]))
        print(f"{obj}: full 72 x 11 map {np.median(walls['general search']):.1f} s -> {np.median(walls['closed form']):.1f} s "
              f"(medians), paired ratio {pair:.2f}x; map and maxima {'equal' if same else 'DIFFERENT'} (1e-8)")
    print(f"load average at end {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
