"""Recompute what the graph's nodes computed, from a recording's rod states, without ROS.

:func:`recompute` repeats the sensing (paper eqs. (4), (5), Definition 1) and the grasp quality
(Sec. IV) with the functions the nodes call, so a genuine recording agrees with its recorded
topics to rounding; :func:`settle_recomputed` replays the simulator's settle rule and
:func:`peak_couple_recomputed` the muscles' bound. docs/analysis.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from contgrasp_core.contact import sense
from contgrasp_core.errors import ContgraspError
from contgrasp_core.rod.closed_loop import SettleDetector
from contgrasp_core.scenario import PAPER, rod_from_parameters
from contgrasp_ros.launcher.summary import status_json
from contgrasp_ros.plumbing.convert import ContactArrays, HeldShape
from contgrasp_ros.plumbing.evaluate import contact_quality
from contgrasp_ros.recordings.run_data import SIMULATOR, Array, IntArray, RunData, node_default

__all__ = [
    "RECOMPUTE_BOUND",
    "Recomputation",
    "recompute",
    "recompute_parameters",
    "peak_couple_recomputed",
    "step_gaps",
    "settle_recomputed",
]


RECOMPUTE_BOUND = 1e-9
"""Largest recompute error of a genuine recording (in practice it is 0: the same functions on
the same float64 arrays)."""


def peak_couple_recomputed(run: RunData) -> float | None:
    """The largest |u| the recorded couples applied (N m), each at the state it answers, after
    the muscles' bound (:func:`contgrasp_core.rod.muscle.saturate`): the couple itself, or a
    hold's at the recorded state's angles. None without recorded couples, or when a hold
    answers a state that was not recorded (decimated)."""
    from contgrasp_core.rod.chain import element_angles
    from contgrasp_core.rod.muscle import saturate

    if not run.couples:
        return None
    model = rod_from_parameters({**PAPER.node_parameters(SIMULATOR), **(run.params or {}).get(SIMULATOR, {})})
    row = {int(k): i for i, k in enumerate(run.rod.step)}
    peak = 0.0
    for step, couple in run.couples.items():
        if isinstance(couple, HeldShape):
            if step not in row:
                return None
            hold = couple.hold(model)
            u = hold.couple + hold.couple_and_jacobian(element_angles(run.rod.theta[row[step]]), jacobian=False)[0]
        else:
            u = np.asarray(getattr(couple, "u", couple), dtype=float)
        peak = max(peak, float(np.abs(saturate(model, u)).max()))
    return peak


@dataclass
class Recomputation:
    """Recomputed contact and quality and their differences from the recorded topics."""

    parameters: dict[str, Any]
    errors: dict[str, float | None]
    contact_pairs: int
    quality_pairs: int
    in_contact_mismatches: int
    valid_mismatches: int
    failures: list[str]
    quality_index: IntArray  # indices into the QualitySeries that were recomputed
    quality: Array  # (len(quality_index), 3): recomputed Q1, Q2, Q3

    @property
    def max_error(self) -> float | None:
        vals = [v for k, v in self.errors.items() if v is not None and not k.endswith("_relative")]
        return max(vals) if vals else None


def _param(params: dict[str, dict[str, Any]] | None, node: str, key: str, default: float) -> float:
    if params is None:
        return default
    return float(params.get(node, {}).get(key, default))


def recompute_parameters(run: RunData) -> dict[str, Any]:
    """Sensor/quality tolerances and wrench reference the nodes ran with: the run's parameters
    (MCAP metadata) or, without them, what the recorded messages carry and the node defaults."""
    settle = {k: _param(run.params, SIMULATOR, k, node_default(SIMULATOR, k))
              for k in ("settle_speed", "settle_hold", "min_time")}  # the simulator's settle rule
    if run.params is not None:
        return {
            **settle,
            "source": "run parameters",
            "sensor_contact_tolerance": _param(run.params, "boundary_sensor", "contact_tolerance", node_default("boundary_sensor", "contact_tolerance")),
            # the quality node uses the contact states' own tolerance (-1); recordings made before
            # the run had one contact set carry the quality node's own
            "quality_contact_tolerance": _param(run.params, "grasp_quality", "contact_tolerance", -1.0),
            "reference": [_param(run.params, "grasp_quality", k, node_default("grasp_quality", k)) for k in ("reference_x", "reference_y")],
        }
    return {
        **settle,
        "source": "recorded messages and node defaults (no run parameters in the recording)",
        "sensor_contact_tolerance": float(run.contact.tol[0]) if run.contact is not None else node_default("boundary_sensor", "contact_tolerance"),
        "quality_contact_tolerance": float(run.quality.contact_tolerance[0]) if run.quality is not None else -1.0,
        "reference": [node_default("grasp_quality", "reference_x"), node_default("grasp_quality", "reference_y")],
    }


def _to_contact_arrays(step: int, t: float, state: Any) -> ContactArrays:
    """What the quality node reads from the sensor's message of ``state`` (float64 round trip)."""
    return ContactArrays(step, t, state.s, state.rho, state.alpha, state.delta, state.s_o, state.foot,
                         np.asarray(state.in_contact, dtype=bool), float(state.tol))


_CONTACT_KEYS = ("rho", "alpha", "delta", "s_o", "shadow")
_QUALITY_KEYS = ("W", "Q1", "Q2", "Q3", "contact_length")


def recompute(
    run: RunData,
    *,
    sensor_tolerance: float | None = None,
    quality_tolerance: float | None = None,
    reference: tuple[float, float] | None = None,
) -> Recomputation:
    """Recompute the contact state of every recorded rod state that has a recorded contact state
    of the same step (:func:`contgrasp_core.contact.sense`, as the boundary sensor; eqs.
    (4) and (5)), and the quality of every recorded quality step whose rod state was recorded
    (rod state -> sensing -> :func:`~contgrasp_ros.plumbing.evaluate.contact_quality`, Sec. IV,
    W = int_S G G^T ds); return the largest absolute differences per quantity.

    The keyword arguments override the run's parameters (e.g. to check that a wrong tolerance
    is noticed); ``quality_tolerance < 0`` means the sensor's tolerance, as in the node.
    """
    par = recompute_parameters(run)
    if sensor_tolerance is not None:
        par["sensor_contact_tolerance"] = float(sensor_tolerance)
    if quality_tolerance is not None:
        par["quality_contact_tolerance"] = float(quality_tolerance)
    if reference is not None:
        par["reference"] = [float(reference[0]), float(reference[1])]
    s_tol, q_tol, ref = par["sensor_contact_tolerance"], par["quality_contact_tolerance"], tuple(par["reference"])
    rod_at = {int(k): i for i, k in enumerate(run.rod.step)}
    err: dict[str, float] = {}
    failures: list[str] = []
    sensed: dict[int, Any] = {}

    def sensed_state(i: int) -> Any:
        if i not in sensed:
            rod = run.rod.arrays(i)
            sensed[i] = sense(rod.sensed_shape, run.boundary, rod.radius, tol=s_tol)
        return sensed[i]

    def bump(key: str, value: float) -> None:
        err[key] = max(err.get(key, 0.0), float(value))

    n_contact = in_contact_bad = 0
    c = run.contact
    if c is not None:
        for j, k in enumerate(c.step):
            i = rod_at.get(int(k))
            if i is None:
                continue
            try:
                st = sensed_state(i)
            except ContgraspError as exc:
                failures.append(f"contact at step {k}: {exc}")
                continue
            n_contact += 1
            if st.rho.shape != c.rho[j].shape:
                failures.append(f"contact at step {k}: {len(st.rho)} nodes recomputed, {len(c.rho[j])} recorded")
                continue
            bump("rho", np.max(np.abs(st.rho - c.rho[j])))
            bump("alpha", np.max(np.abs(st.alpha - c.alpha[j])))
            bump("delta", np.max(np.abs(st.delta - c.delta[j])))
            bump("s_o", np.max(np.abs(st.s_o - c.s_o[j])))
            bump("shadow", max(np.max(np.abs(st.foot[:, 0] - c.shadow_x[j])), np.max(np.abs(st.foot[:, 1] - c.shadow_y[j]))))
            in_contact_bad += int(np.count_nonzero(st.in_contact != c.in_contact[j]))

    q_idx: list[int] = []
    q_vals: list[tuple[float, float, float]] = []
    valid_bad = 0
    q = run.quality
    if q is not None:
        for j, k in enumerate(q.step):
            i = rod_at.get(int(k))
            if i is None:
                continue
            try:
                st = sensed_state(i)
                qq = contact_quality(_to_contact_arrays(int(k), float(run.rod.t[i]), st), run.boundary, q_tol, ref)
            except ContgraspError as exc:
                failures.append(f"quality at step {k}: {exc}")
                continue
            q_idx.append(j)
            q_vals.append((qq.Q1, qq.Q2, qq.Q3))
            bump("W", np.max(np.abs(np.asarray(qq.W, dtype=float).ravel() - q.w[j])))
            bump("Q1", abs(qq.Q1 - q.q1[j]))
            bump("Q2", abs(qq.Q2 - q.q2[j]))
            bump("Q3", abs(qq.Q3 - q.q3[j]))
            bump("contact_length", abs(qq.contact_length - q.contact_length[j]))
            scale = max(abs(q.q2[j]), abs(qq.Q2))
            bump("Q2_relative", abs(qq.Q2 - q.q2[j]) / scale if scale > 0 else 0.0)
            valid_bad += int(bool(qq.has_contact) != bool(q.valid[j]))

    errors: dict[str, float | None] = {k: err.get(k) for k in (*_CONTACT_KEYS, *_QUALITY_KEYS, "Q2_relative")}
    return Recomputation(
        parameters=par,
        errors=errors,
        contact_pairs=n_contact,
        quality_pairs=len(q_idx),
        in_contact_mismatches=in_contact_bad,
        valid_mismatches=valid_bad,
        failures=failures,
        quality_index=np.asarray(q_idx, dtype=np.int64),
        quality=np.asarray(q_vals, dtype=float).reshape(-1, 3),
    )


def step_gaps(run: RunData) -> dict[str, Any]:
    """Whether the recorded rod states are every step (a decimated recording is not)."""
    steps = run.rod.step
    d = np.diff(steps)
    return {
        "contiguous": bool(np.all(d == 1)),
        "first_step": int(steps[0]),
        "last_step": int(steps[-1]),
        "rod_states": len(steps),
        "missing_steps": max(int(steps[-1] - steps[0] + 1) - len(np.unique(steps)), 0),
        "max_step_gap": int(d.max()) if len(d) else 0,
        "monotonic": bool(np.all(d > 0)),
        "repeated_states": run.repeated_states,
    }


STAMP_RESOLUTION_S = 1e-9
"""A header stamp's resolution (builtin_interfaces/Time: integer nanoseconds)."""


def settle_recomputed(run: RunData) -> tuple[bool | None, float | None]:
    """(settled, settle time) by the simulator's rule fed every recorded state from step 0 at its
    stamp, the simulated time rounded to ns (the simulator's own float times reach /diagnostics
    only a few times per second): the rule's hold and minimum time are taken 1 ns short, so a
    run the simulator judged settled at the last step is so judged again, and the settle time
    agrees with the simulator's to 1 ns; the rule's parameters as :func:`recompute_parameters`
    finds them (the run's, else the node defaults: a run started by hand records none).

    As in the simulator, a state after a couple whose law was still in transition (the holding
    law before its hold: the couple's ``transition``) does not count as quiet, and a run that
    left the model's validity (its simulator's last status, ``validity.valid``) is not settled.
    (None, None) when the rod states are not complete, or when a law in transition was recorded
    but not the couple answering every state (its phases cannot be replayed)."""
    gaps = step_gaps(run)
    if not gaps["contiguous"] or gaps["first_step"] != 0:
        return None, None
    transitions = run.transitions or {}
    steps = run.rod.step
    if any(transitions.values()) and not all(int(k) in transitions for k in steps[:-1]):
        return None, None
    par = recompute_parameters(run)
    speed, hold, min_time = par["settle_speed"], par["settle_hold"], par["min_time"]
    det = SettleDetector(speed, hold - STAMP_RESOLUTION_S, min_time - STAMP_RESOLUTION_S)
    for k, t, v in zip(steps, run.rod.t, run.rod.max_speed, strict=True):
        det.update(float(t), float(v), ready=not transitions.get(int(k) - 1, False))
    if not (status_json(run.status, "validity") or {}).get("valid", True):  # (a status from before the verdict: none)
        return False, None
    return det.settled, det.settle_time
