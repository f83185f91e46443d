"""The planned hold on the object set (docs/holding.md, "The object set"): each object at the
default centre, free, 6 s, in the graph's loop (sampled at 2 ms, first-order hold: the graph
equals it bit for bit), frictionless and at mu = 0.5; or refused before simulating. Prints the
Markdown table (each cell on stderr as it ends). ``python docs/holding/object_set.py [--workers N]
[--max-muscle-stress PA]``."""

from __future__ import annotations

import argparse
import re
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from pathlib import Path

import numpy as np

from contgrasp_core.cli.simulate import summarize
from contgrasp_core.errors import InvalidParameterError
from contgrasp_core.holding.measure import cage_wrap, check_reach
from contgrasp_core.objects import ROD_SCALE, ObjectSpec
from contgrasp_core.rod.body import ObjectDynamics
from contgrasp_core.rod.session import record_sampled
from contgrasp_core.scenario import PAPER, Scenario

DATA = Path(__file__).resolve().parents[2] / "tests" / "data"
OBJECTS = {
    "circle 15 mm": ObjectSpec.parse("circle:0.015", ROD_SCALE),
    "circle 25 mm (the paper's)": ObjectSpec.parse("circle:0.025", ROD_SCALE),
    "circle 35 mm": ObjectSpec.parse("circle:0.035", ROD_SCALE),
    "ellipse 30 x 20 mm, 0": ObjectSpec.parse("ellipse:0.03,0.02", ROD_SCALE),
    "ellipse 30 x 20 mm, 45 deg": replace(ObjectSpec.parse("ellipse:0.03,0.02", ROD_SCALE), angle=float(np.pi / 4)),
    "deformed circle": ObjectSpec.parse("deformed", ROD_SCALE),
    "kidney": ObjectSpec.from_outline(DATA / "kidney_rod_outline.csv"),
    "rounded square": ObjectSpec.from_outline(DATA / "rounded_square_rod_outline.csv"),
}
DURATION, PERIOD = 6.0, 0.002
HELD = {"distance": 0.010, "angle": 0.2, "speed": 0.001}  # (held: these at the end, settled, valid)


def scenario(obj: ObjectSpec, mu: float, stress: float = 0.0) -> Scenario:
    """The planned hold on ``obj``, free, in the graph's loop, with Coulomb ``mu`` (stick-slip)
    and muscles of at most ``stress`` (Pa; 0: unbounded)."""
    rod = replace(PAPER.rod, max_muscle_stress=stress)
    rod = replace(rod, friction=mu, friction_model="stick") if mu > 0 else rod
    return PAPER.with_object(obj, rod=rod, law="hold", dynamics=ObjectDynamics(mode="free"),
                             loop=replace(PAPER.loop, duration=DURATION, control_period=PERIOD))


def run(name: str, mu: float, stress: float = 0.0) -> tuple[str, float, str]:
    """One cell: the outcome and the object's end state, or the refusal."""
    s = scenario(OBJECTS[name], mu, stress)
    try:
        check_reach(s)
        law = s.controller()  # (the plan: refused when its planner cannot reach the hold)
    except InvalidParameterError as err:
        return name, mu, f"refused: {err}"
    res = record_sampled(s, law=law)
    out = summarize(res, s.sensing.contact_tolerance, "first-order hold")
    d, v = out["object_displacement"], out["object_velocity"]
    dist, speed = float(np.hypot(d["x"], d["y"])), float(np.hypot(v["x"], v["y"]))
    near = dist < HELD["distance"] and abs(d["angle"]) < HELD["angle"] and speed < HELD["speed"]
    if not out["validity"]["valid"]:
        outcome = f"invalid (the arm {out['max_penetration_ratio']:.2f} of its radius in)"
    elif near and out["settled"]:
        outcome = "held"
    elif near:
        outcome = f"not settled (fastest point {1e3 * res.max_speed[-1]:.1f} mm/s)"
    else:
        outcome = "lost"
    return name, mu, f"{outcome}: {1e3 * dist:.1f} mm, {d['angle']:.3f} rad, {1e3 * speed:.2f} mm/s"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--max-muscle-stress", type=float, default=0.0, metavar="PA",
                        help="the muscles' largest stress, Pa (default 0: unbounded)")
    args = parser.parse_args()
    if args.workers < 1:
        parser.error(f"--workers must be >= 1, got {args.workers}")
    if not (np.isfinite(args.max_muscle_stress) and args.max_muscle_stress >= 0):
        parser.error(f"--max-muscle-stress must be a finite number >= 0, got {args.max_muscle_stress}")
    cells = [(name, mu, args.max_muscle_stress) for name in OBJECTS for mu in (0.0, 0.5)]
    results = {}
    start = time.monotonic()
    with ProcessPoolExecutor(args.workers) as pool:
        for done in as_completed([pool.submit(run, *cell) for cell in cells]):
            name, mu, text = done.result()
            results[name, mu] = text
            print(f"[{time.monotonic() - start:6.0f} s] {name}, mu = {mu:g}: {text}", file=sys.stderr, flush=True)
    print("| object | cage's wrap at rest (rad) | frictionless | mu = 0.5 |")
    print("|---|---|---|---|")
    for name, obj in OBJECTS.items():
        wrap = cage_wrap(scenario(obj, 0.0))
        a, b = (cell(results[name, mu]) for mu in (0.0, 0.5))
        if results[name, 0.0].startswith("refused: the holding law cannot close"):
            print(f"| {name} | {wrap:.2f} | refused before simulating (below wrap_angle {PAPER.hold_law.wrap_angle:.2f}) | |")
        else:
            print(f"| {name} | {wrap:.2f} | {a} | {b} |")


def cell(text: str) -> str:
    """A cell of the table: the outcome, or a plan refused (its planner's engine past its limit) in short."""
    failed = re.search(r"has no plan: .*by t = ([0-9.]+) s", text)
    return f"refused: no plan (the planner's rod engine past its iteration limit at t = {failed.group(1)} s)" if failed else text


if __name__ == "__main__":
    main()
