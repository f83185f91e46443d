"""Reference computations for the restructure: the paper run, the optimal grasps and quality maps.

``reference.json`` holds their results computed on main at commit 3a13851 (before the
restructure of the package layout), by

    .venv/bin/python tests/golden/cases.py      # writes tests/golden/reference.json

``tests/test_golden.py`` recomputes them with the current code and compares. Regenerate only when
a change of the numbers is intended, and say why in the commit.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
REFERENCE = HERE / "reference.json"
PAPER_OBJECTS = ("circle", "ellipse", "deformed")


def lockstep_paper_run() -> dict[str, Any]:
    """The ROS graph's paper scenario (packaged YAML, 2 ms control period, held expansion),
    stepped with the core functions only, as the nodes step it."""
    from contgrasp_core.rod import Obstacle, RodModel, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig
    from contgrasp_core.control import paper_gains
    from contgrasp_core.boundary import circle
    from contgrasp_core.contact import sense
    from contgrasp_core.rod.session import LoopSession
    from contgrasp_core.control import feedback_at_joints

    model = RodModel(length=0.20, n_elements=100, radius_base=0.01, radius_tip=0.001, density=1042.0,
                     youngs_modulus=1.0e4, damping=1.0, drag_normal=5110.0, drag_tangential=25.55,
                     contact_stiffness=1.0e5, contact_damping=1.0)
    boundary = circle(0.025, (0.08, 0.08))
    config = ClosedLoopConfig(duration=4.0, control_period=0.002, settle_speed=0.002, settle_hold=0.3, min_time=1.0)
    gains = paper_gains(model, 0.025)
    session = LoopSession(RodSystem(model, Obstacle(boundary)), config)
    while True:
        obs = session.observe()
        if session.finished:
            return {"k": obs.k, "t": obs.t, "settle_time": session.settle_time, "x": obs.x, "theta": obs.theta}
        c = sense(obs.shape, boundary, obs.radius, tol=0.0)
        session.advance(feedback_at_joints(model, gains, c.rho, c.alpha))


def closed_loop_continuous() -> dict[str, Any]:
    """Continuous implicit feedback, dt 10 ms, ``ClosedLoopConfig``'s default settle rule (what
    ``contgrasp simulate`` ran before it took the scenario's settle criterion)."""
    from contgrasp_core.boundary import circle
    from contgrasp_core.rod import Obstacle, RodSystem
    from contgrasp_core.rod.closed_loop import ClosedLoopConfig, run_closed_loop
    from contgrasp_core.control import paper_gains
    from contgrasp_core.scenario import PAPER

    model = PAPER.rod
    res = run_closed_loop(RodSystem(model, Obstacle(circle(0.025, (0.08, 0.08)))), paper_gains(model, 0.025),
                          ClosedLoopConfig(duration=10.0, dt=0.01))
    return {"steps": len(res.t), "settle_time": res.settle_time, "x": res.x[-1], "rho": res.rho[-1]}


def optimal_grasps() -> dict[str, Any]:
    """Fig. 2: the fast solver on the three paper objects; the forward-backward sweep, 300 iterations."""
    from contgrasp_core.optimal import paper_problem, solve, forward_backward

    out: dict[str, Any] = {}
    for name in PAPER_OBJECTS:
        res = solve(paper_problem(name, nodes=200))
        out[name] = {"cost": res.cost, "kappa": res.kappa, "rho": res.rho, "alpha": res.alpha}
    fb = forward_backward(paper_problem("circle", nodes=200), max_iterations=300)
    out["forward_backward_circle"] = {"cost": fb.cost, "kappa": fb.kappa}
    return out


def quality_maps() -> dict[str, Any]:
    """Fig. 3 on a coarse grid (6 x 3 poses) for the three paper objects, serial executor."""
    from contgrasp_core.quality_map import MapSpec, quality_map

    out: dict[str, Any] = {}
    for name in PAPER_OBJECTS:
        qm = quality_map(MapSpec(object=name, psi_steps=6, d_steps=3, nodes=100), executor="serial", optimise=False)
        out[name] = {"Q": qm.Q, "valid": qm.valid.astype(int)}
    return out


CASES = {"lockstep_paper_run": lockstep_paper_run, "closed_loop_continuous": closed_loop_continuous,
         "optimal_grasps": optimal_grasps, "quality_maps": quality_maps}


def jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray | np.generic):
        return jsonable(obj.tolist())
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


if __name__ == "__main__":
    REFERENCE.write_text(json.dumps({k: jsonable(f()) for k, f in CASES.items()}, indent=None) + "\n")
    print("wrote", REFERENCE)
