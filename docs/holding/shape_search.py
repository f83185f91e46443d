"""How firmly can any rest shape of the paper's arm hold the paper's circle within 50 kPa muscles?
The ceiling (M5) of designed wraps, on the circle where it starts and moved by the escape distance
(half its radius) in 8 directions, the best of them refined (docs/holding.md, "Within the muscles",
"No rest shape holds the arm's weight at 50 kPa"). ``--no-refine`` skips the refinement,
``--nominal`` the moved circles (under a minute instead of about ten)."""

import argparse
import itertools
from dataclasses import replace

import numpy as np
from scipy.optimize import brentq, fsolve, minimize

from contgrasp_core.boundary import Boundary, circle
from contgrasp_core.holding import wrench_directions
from contgrasp_core.holding.ceiling import muscle_ceiling
from contgrasp_core.rod import chain
from contgrasp_core.scenario import PAPER

ROD = replace(PAPER.rod, max_muscle_stress=5e4)
CENTRE, R = np.array(PAPER.reference), PAPER.object.radius
N, H = ROD.n_elements, ROD.h
S_CENTRES = ROD.s_centres
WEIGHT = 0.24  # (N: the arm's own weight, what the hold is asked to carry)


def wrap(centre: np.ndarray, phi1: float, s1: float, sense: int, gap: float, s2: float) -> np.ndarray | None:
    """Element angles of a designed rest on the circle about ``centre``: from the clamp (heading 0,
    no bend) a reach whose curvature is quadratic in s, arriving at arclength ``s1`` tangent to
    the circle at polar angle ``phi1``; then on the parallel curve ``gap`` off the surface
    (``sense`` +1 anticlockwise about the centre, -1 clockwise) until ``s2``; straight beyond.
    None when no such reach exists."""
    k1, k2 = int(round(s1 / H)), int(round(s2 / H))
    target = centre + (R + ROD.r_centres[k1] + gap) * np.array([np.cos(phi1), np.sin(phi1)])
    heading = phi1 + sense * np.pi / 2
    s = S_CENTRES[:k1]

    def reach(p: np.ndarray, s: np.ndarray | float = s) -> np.ndarray:
        """The heading at arclength ``s`` (curvature ``p[0] + p[1] s + p[2] s^2``, heading 0 at the clamp)."""
        return np.asarray(p[0] * s + p[1] * s**2 / 2 + p[2] * s**3 / 3)

    def miss(p: np.ndarray) -> list[float]:
        th = reach(p)
        return [H * np.cos(th).sum() - target[0], H * np.sin(th).sum() - target[1], float(reach(p, k1 * H)) - heading]

    p, _, found, _ = fsolve(miss, [0.0, 0.0, 0.0], full_output=True)
    if found != 1:
        return None
    phi = phi1 + sense * np.cumsum(H / (R + ROD.r_centres[k1:] + gap))
    theta = np.concatenate([reach(p), phi + sense * np.pi / 2])
    theta[k2:] = theta[k2 - 1]
    return theta


def clearance(centre: np.ndarray, theta: np.ndarray) -> float:
    """The least distance (m) between the arm's surface and the circle about ``centre`` (< 0: inside)."""
    return float((np.linalg.norm(chain.centres(ROD, theta) - centre, axis=1) - R - ROD.r_centres).min())


def ceiling(centre: np.ndarray, theta: np.ndarray, stress: float = 5e4, mu: float = 0.5):
    """(M5) of the rest ``theta`` on the circle about ``centre``: forces through the centre every
    45 degrees from +x, then the two torques."""
    obj: Boundary = circle(R, (float(centre[0]), float(centre[1])))
    return muscle_ceiling(replace(ROD, max_muscle_stress=stress), obj, theta, mu=mu, directions=wrench_directions(8),
                          ref=(float(centre[0]), float(centre[1])), scale=R, tol=5e-4)


def weakest(centre: np.ndarray, theta: np.ndarray) -> float:
    """The objective: the weakest direction's ceiling at 50 kPa, mu = 0.5 (0 for a shape inside
    the circle by more than 0.1 mm or one its muscles cannot hold)."""
    c = ceiling(centre, theta)
    return float(c.capacity.min()) if clearance(centre, theta) >= -1e-4 and c.holds_shape else 0.0


def designed(centre: np.ndarray) -> tuple[int, int, np.ndarray, float]:
    """The designed rests on the circle about ``centre``: how many are clear of it, how many its
    muscles hold, the best and its weakest ceiling."""
    grid = itertools.product(np.linspace(-np.pi, np.pi, 24, endpoint=False), np.arange(0.058, 0.131, 0.006), (1, -1),
                             (1e-4, 3e-4), (0.16, 0.18, 0.2))
    shapes = [t for t in (wrap(centre, *g) for g in grid if g[4] > g[1] + 0.02)
              if t is not None and clearance(centre, t) >= -1e-4]
    scores = np.array([weakest(centre, t) for t in shapes])
    return len(shapes), int(np.count_nonzero(scores > 0)), shapes[int(np.argmax(scores))], float(scores.max())


def describe(name: str, centre: np.ndarray, theta: np.ndarray) -> None:
    """Print the rest's ceiling per direction and the joint binding its weakest."""
    c = ceiling(centre, theta)
    k = int(np.argmin(c.capacity))
    j = c.binding[k]
    print(f"{name}: weakest {c.capacity.min():.4f} N (direction {k}), its binding joint {j} at s = {j * H:.3f} m, "
          f"r = {ROD.radius(j * H) * 1e3:.1f} mm; all:", np.round(c.capacity, 3))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--no-refine", action="store_true", help="only the designed wraps")
    ap.add_argument("--nominal", action="store_true", help="only the circle where it starts")
    args = ap.parse_args()
    clear, held, best, score = designed(CENTRE)
    print(f"{clear} designed wraps clear of the circle; {held} held by their muscles")
    describe("best designed wrap", CENTRE, best)
    centre = CENTRE
    if not args.nominal:  # (a held object is within the escape distance: half its radius)
        for angle in range(0, 360, 45):
            moved = CENTRE + R / 2 * np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
            clear, held, shape, moved_score = designed(moved)
            print(f"moved {R / 2 * 1e3:g} mm towards {angle} degrees: {clear} clear, {held} held, best {moved_score:.4f} N")
            if moved_score > score:
                best, score, centre = shape, moved_score, moved
        describe(f"best of all, on the circle at ({centre[0]:.4f}, {centre[1]:.4f})", centre, best)
    if not args.no_refine:  # (Nelder-Mead on a piecewise-linear change of curvature, 12 knots)
        knots, joints = np.linspace(0, ROD.length, 12), np.arange(N) * H
        start = best

        def bent(a: np.ndarray) -> np.ndarray:
            return start + np.cumsum(np.interp(joints, knots, a) * ROD.joint_len)

        res = minimize(lambda a: -weakest(centre, bent(a)), np.zeros(12), method="Nelder-Mead",
                       options={"maxfev": 1500, "initial_simplex": np.vstack([np.zeros(12), 3 * np.eye(12)])})
        best = bent(res.x)
        describe("refined", centre, best)
    for mu in (0.5, 1.0):
        row = [f"{ceiling(centre, best, stress, mu).capacity.min():.3f}" for stress in (5e4, 1e5, 2e5, 4e5)]
        need = brentq(lambda st, mu=mu: ceiling(centre, best, st, mu).capacity.min() - WEIGHT, 5e4, 5e6, xtol=1e3)
        print(f"mu {mu}: weakest at 50, 100, 200, 400 kPa: {', '.join(row)} N; {WEIGHT} N at {need / 1e3:.0f} kPa")


if __name__ == "__main__":
    main()
