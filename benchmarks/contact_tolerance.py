"""How the contact tolerance changes Q1..Q3 and the quality-map maxima (docs/quality.md).

Run: .venv/bin/python benchmarks/contact_tolerance.py [--psi-steps 24 --d-steps 6]
Prints a markdown table: per object and tolerance, the grid maximum of each metric and where it
is (psi in degrees, d).
"""

from __future__ import annotations

import argparse

import numpy as np

from contgrasp_core.quality_map import METRICS, MapSpec, quality_map


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--psi-steps", type=int, default=24)
    ap.add_argument("--d-steps", type=int, default=6)
    ap.add_argument("--tols", type=float, nargs="+", default=[0.0, 0.01, 0.05, 0.1, 0.2])
    args = ap.parse_args()
    print("| object | tol | " + " | ".join(f"max {m} (psi deg, d)" for m in METRICS) + " |")
    print("|---|---|" + "---|" * len(METRICS))
    for obj in ("circle", "ellipse", "deformed"):
        for tol in args.tols:
            qm = quality_map(MapSpec(obj, psi_steps=args.psi_steps, d_steps=args.d_steps, contact_tol=tol), optimise=False)
            cells = []
            for k in range(3):
                grid = np.where(qm.valid, qm.Q[k], -np.inf)
                i, j = np.unravel_index(int(np.argmax(grid)), grid.shape)
                cells.append(f"{grid[i, j]:.4g} ({np.degrees(qm.psi[i]):.0f}, {qm.d[j]:.0f})")
            print(f"| {obj} | {tol:g} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
