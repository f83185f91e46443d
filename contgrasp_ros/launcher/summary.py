"""The summary of one graph run: one type, built by one function, for the launcher and ``analyze``.

``contgrasp-launch`` builds it from what its monitor received over the topics during the run,
``contgrasp analyze`` from a recording of the same topics; both call :func:`build_summary` with
the same plain values (the simulator's last ``/diagnostics`` status, the last rod state, contact
state and grasp quality as arrays), so the two agree key for key and value for value on the
same run. Each caller adds its own entries to :meth:`RunSummary.to_dict` (the launcher: restarts,
faults, the recording's ``bag`` block, exit codes; ``analyze``: the recomputation checks).

Times are suffixed with their unit and say which clock: ``sim_time_s`` is simulated time (the
simulator's clock), ``wall_time_s``/``loop_wall_time_s`` are wall-clock seconds (only the
launcher measures them; ``None`` from a recording). Nothing here imports rclpy.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from contgrasp_core.rod.body import motion_summary
from contgrasp_core.tracking import ContactStats, contact_stats

__all__ = ["status_json", "FinalState", "FinalQuality", "ContactStats", "RunSummary", "contact_stats", "build_summary"]

FloatSeq = Sequence[float] | np.ndarray


@dataclass(frozen=True)
class FinalState:
    """The last rod state: its ``step``, stamp ``t`` (sim time, s) and per-node arrays."""

    step: int
    t: float
    s: list[float]
    x: list[float]
    y: list[float]
    theta: list[float]

    @classmethod
    def of(cls, step: int, t: float, s: FloatSeq, x: FloatSeq, y: FloatSeq, theta: FloatSeq) -> FinalState:
        """From per-node arrays (numpy or message sequences), as plain floats."""
        def floats(v: FloatSeq) -> list[float]:
            out: list[float] = np.asarray(v, dtype=float).tolist()
            return out

        return cls(int(step), float(t), floats(s), floats(x), floats(y), floats(theta))


@dataclass(frozen=True)
class FinalQuality:
    """The last grasp quality (paper Sec. IV): Q1 = lambda_min(W), Q2 = det W, Q3 = lambda_min /
    lambda_max, whether it is valid (the arm touches the object), the contact length (m) and
    the ``step`` it was evaluated at (the quality node runs at ``rate_hz`` of simulated time, so
    this is usually an earlier step than ``final``'s and the contact statistics')."""

    Q1: float  # (the paper's names, and the JSON keys)
    Q2: float
    Q3: float
    valid: bool
    contact_length: float
    step: int | None = None

    @classmethod
    def of(cls, q1: float, q2: float, q3: float, valid: bool, contact_length: float, step: int | None = None) -> FinalQuality:
        """From message fields or numpy scalars, as plain floats and a bool."""
        return cls(float(q1), float(q2), float(q3), bool(valid), float(contact_length), None if step is None else int(step))


@dataclass(frozen=True)
class RunSummary:
    """What a graph run did. The JSON keys (:meth:`to_dict`) are the field names.

    ``simulator_state``, ``law`` and ``law_phase`` (the controller's last ``/diagnostics`` status:
    the law that ran and, under the holding law, its phase, ``None`` under the paper's law or when
    the controller never reported), ``settled``, ``settle_time_s`` (sim time, ``None`` if not settled),
    ``sim_time_s``, ``steps``, ``missed_deadlines`` (lock-step timeouts that applied the
    fallback couple; free-running: control periods lost behind the wall clock),
    ``late_couples`` (free-running steps that went on without the couple answering their state,
    :class:`~contgrasp_ros.nodes.lockstep.CoupleWait`; 0 in lock-step), ``max_penetration`` (m),
    ``validity`` (what broke the model, :class:`~contgrasp_core.rod.validity.RunHealth`; ``None``
    from an older recording) and the muscles' effort (``peak_couple`` N m, at ``peak_couple_arclength``
    m and ``peak_couple_sim_time_s`` s, ``peak_couple_ratio`` to the bound, ``None`` when unbounded) are
    the simulator's last ``/diagnostics`` status, except that ``sim_time_s`` and ``steps`` are the
    last rod state's when it is newer (the status goes out at most every 0.2 s of wall time and at
    a change of state, so a run stopped by Ctrl-C ends with a status some steps old); ``final``,
    ``final_quality``, a movable object's ``object_displacement`` and ``object_velocity`` (``{x, y,
    angle}``, ``None`` while it is fixed: :func:`~contgrasp_core.rod.body.motion_summary`, the keys
    of ``contgrasp simulate``) and the contact statistics
    (:class:`~contgrasp_core.tracking.ContactStats`: mean and max tracking errors over the
    ``contact_nodes`` nodes in contact, ``contact_length`` m) the last rod state, grasp
    quality and contact state; ``wall_time_s`` (the whole launcher run) and ``loop_wall_time_s``
    (from resuming the simulator to its end) are wall-clock seconds, ``None`` from a recording;
    from them ``real_time_factor`` (simulated seconds per wall second of the loop) and
    ``step_wall_ms`` (wall milliseconds per control step).
    """

    simulator_state: str
    law: str | None
    law_phase: str | None
    settled: bool
    settle_time_s: float | None
    sim_time_s: float | None
    steps: int
    missed_deadlines: int
    late_couples: int
    max_penetration: float | None
    validity: dict[str, Any] | None
    peak_couple: float | None
    peak_couple_arclength: float | None
    peak_couple_sim_time_s: float | None
    peak_couple_ratio: float | None
    final: FinalState | None
    object_displacement: dict[str, float] | None
    object_velocity: dict[str, float] | None
    final_quality: FinalQuality | None
    mean_abs_rho_ratio_minus_1_contact: float | None
    max_abs_rho_ratio_minus_1_contact: float | None
    mean_abs_alpha_minus_half_pi_contact: float | None
    max_abs_alpha_minus_half_pi_contact: float | None
    contact_nodes: int | None
    contact_length: float | None
    wall_time_s: float | None = None
    loop_wall_time_s: float | None = None
    real_time_factor: float | None = None
    step_wall_ms: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The summary as JSON-ready values (nested dicts for ``final`` and ``final_quality``)."""
        return asdict(self)


def _num(status: Mapping[str, str], key: str) -> float | None:
    try:
        return float(status[key])
    except (KeyError, ValueError):
        return None


def status_json(status: Mapping[str, str], key: str) -> dict[str, Any] | None:
    """The JSON object a status value holds (``validity``), or None when it holds none."""
    try:
        value = json.loads(status[key])
    except (KeyError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def build_summary(
    status: Mapping[str, str],
    *,
    final: FinalState | None,
    final_quality: FinalQuality | None,
    contact: ContactStats,
    controller: Mapping[str, str] | None = None,
    object_q: FloatSeq | None = None,
    object_v: FloatSeq | None = None,
    wall_time_s: float | None = None,
    loop_wall_time_s: float | None = None,
) -> RunSummary:
    """The :class:`RunSummary` of a run from the simulator's last ``/diagnostics`` key/values
    (``state``, ``settled``, ``settle_time_s``, ``sim_time_s``, ``step``, ``missed_deadlines``,
    ``late_couples``, ``max_penetration``; missing or unparsable ones give ``None``/0; the step and
    time of ``final`` when it is newer), the controller's last key/values (``law``, ``law_phase``;
    ``None``: none received), the last rod state, a movable object's displacement ``object_q`` and
    velocity ``object_v`` (None or empty: fixed) and quality, and the contact statistics of the
    last contact state (:func:`contact_stats`)."""
    sim_time, steps = _num(status, "sim_time_s"), int(_num(status, "step") or 0)
    if final is not None and final.step > steps:  # (a run stopped between two statuses: its last state is newer)
        sim_time, steps = final.t, final.step
    motion = motion_summary(object_q, object_v)
    loop = loop_wall_time_s if loop_wall_time_s is not None and loop_wall_time_s > 0 else None
    return RunSummary(
        simulator_state=status.get("state", "unknown"),
        law=(controller or {}).get("law") or None,
        law_phase=(controller or {}).get("law_phase") or None,
        settled=status.get("settled") == "true",
        settle_time_s=_num(status, "settle_time_s"),
        sim_time_s=sim_time,
        steps=steps,
        missed_deadlines=int(_num(status, "missed_deadlines") or 0),
        late_couples=int(_num(status, "late_couples") or 0),
        max_penetration=_num(status, "max_penetration"),
        validity=status_json(status, "validity"),
        peak_couple=_num(status, "peak_couple"),
        peak_couple_arclength=_num(status, "peak_couple_arclength"),
        peak_couple_sim_time_s=_num(status, "peak_couple_sim_time_s"),
        peak_couple_ratio=_num(status, "peak_couple_ratio"),
        final=final,
        object_displacement=motion["object_displacement"],
        object_velocity=motion["object_velocity"],
        final_quality=final_quality,
        mean_abs_rho_ratio_minus_1_contact=contact.mean_abs_rho_ratio_minus_1_contact,
        max_abs_rho_ratio_minus_1_contact=contact.max_abs_rho_ratio_minus_1_contact,
        mean_abs_alpha_minus_half_pi_contact=contact.mean_abs_alpha_minus_half_pi_contact,
        max_abs_alpha_minus_half_pi_contact=contact.max_abs_alpha_minus_half_pi_contact,
        contact_nodes=contact.contact_nodes,
        contact_length=contact.contact_length,
        wall_time_s=wall_time_s,
        loop_wall_time_s=loop_wall_time_s,
        real_time_factor=None if loop is None or sim_time is None else sim_time / loop,
        step_wall_ms=None if loop is None or steps == 0 else 1e3 * loop / steps,
    )
