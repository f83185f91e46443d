"""The holding law through the ROS graph (docs/holding.md, "A law that
holds"): the controller's ``law`` parameter, the arm's shape in the contact state, the hold
(``kappa_ref``, ``hold_gain``) and the ``transition`` flag in the couple, the simulator applying
the hold in the state; a lock-step run with a free object pushed while held equals the core-only
loop bit for bit."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from contgrasp_core.control.hold_law import HoldController, ShapeHold
from contgrasp_core.holding.plan import PlannedHold
from contgrasp_core.rod.body import motion_summary
from contgrasp_core.scenario import Scenario

pytest.importorskip("contgrasp_msgs.msg")

from contgrasp_msgs.msg import ContactState, CoupleControl  # noqa: E402
from contgrasp_core.rod.session import run_sampled  # noqa: E402
from contgrasp_ros.bag.reader import iter_decoded, open_recording  # noqa: E402
from contgrasp_ros.launcher.graph import default_params_file, load_params  # noqa: E402
from contgrasp_ros.plumbing import topics  # noqa: E402
from contgrasp_ros.recordings.run_data import load_run  # noqa: E402

from conftest import Sink, fresh_domain_id  # noqa: E402

BIN = Path(sys.executable).parent
LIB = Path(sys.prefix) / "lib" / "contgrasp_ros"
PUSH_START, PUSH = 2.801, (0.02, 0.0, 0.0)  # (between two control steps: a stamp rounded to ns is on the same side)


class _Logged:
    """A law that notes, for every command, whether it was the hold and whether the law was
    still in transition afterwards (what the couple message carries)."""

    def __init__(self, law: HoldController) -> None:
        self.law, self.log = law, []  # type: list[tuple[bool, bool]]

    @property
    def holding(self) -> bool:
        return self.law.holding

    def command(self, *args: Any) -> Any:
        out = self.law.command(*args)
        self.log.append((isinstance(out, ShapeHold), not self.law.holding))
        return out



def launch_json(*args: str) -> dict[str, Any]:
    """``contgrasp-launch ARGS --json`` on a fresh domain, loopback only: its summary (exit 0 asserted)."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.run([str(BIN / "contgrasp-launch"), "--domain-id", str(fresh_domain_id()), *args, "--json"],
                          capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)  # type: ignore[no-any-return]


@pytest.mark.heavy
def test_the_holding_law_through_the_graph_equals_the_core_loop_bit_for_bit(tmp_path: Path) -> None:
    """``contgrasp-launch --law reactive --object-mode free``: the paper's arm (N = 100, 2 ms), the
    circle free, Coulomb friction 0.5, the dwell (H8) of 0.05 s (25 samples) and the depth regulation (H7) on
    (gain 10/s), and a 20 mN push along x from 2.801 s, once the hold is complete. Separate node processes in
    lock-step equal run_sampled of the same scenario bit for bit (arm, object pose and velocity),
    the friction given as ``--friction 0.5`` (stick-slip, as ``contgrasp simulate --friction``);
    the regulation has moved the hold's offset; the recording has the hold and the transition
    flag of every couple as the core law gave them, the arm's shape in every contact state, the
    push in the rod states; the held object moved under the push by less than a millimetre. (It
    is not yet at rest at 3.2 s: the regulation is still opening the offset, as it does for a few
    seconds after the squeeze; the rest it reaches is the core's test, in test_hold_law.py.)"""
    data = yaml.safe_load(default_params_file().read_text())
    data["rod_simulator"]["ros__parameters"].update(duration=3.2, disturbance_kind="step", disturbance_wrench=list(PUSH),
                                                    disturbance_start=PUSH_START)
    data["grasp_quality"]["ros__parameters"]["rate_hz"] = 0.0
    data["grasp_controller"]["ros__parameters"].update(hold_depth_gain=10.0, hold_dwell=0.05)
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    summary = launch_json("--params", str(params), "--law", "reactive", "--object-mode", "free", "--friction", "0.5",
                          "--bag", str(tmp_path / "bag"))
    assert summary["missed_deadlines"] == 0

    p = load_params(params)
    p["grasp_controller"]["law"], p["rod_simulator"]["object_mode"] = "reactive", "free"
    for node in ("rod_simulator", "grasp_controller"):
        p[node].update(friction=0.5, friction_model="stick")
    scenario = Scenario.from_ros_parameters(p)
    assert scenario.law == "reactive" and scenario.dynamics.mode == "free" and scenario.rod.friction == 0.5
    assert scenario.rod.friction_model == "stick"
    law = scenario.controller()
    assert isinstance(law, HoldController) and law.settings.depth_gain == 10.0 and law.settings.dwell == 0.05
    logged = _Logged(law)
    session = run_sampled(scenario, law=logged)  # type: ignore[arg-type]
    obs = session.observe()
    assert obs.body is not None and summary["steps"] == obs.k == 1600
    assert law.depth_offset != 0.0  # (the regulation acted)
    np.testing.assert_array_equal(summary["final"]["x"], obs.x[:, 0])
    np.testing.assert_array_equal(summary["final"]["y"], obs.x[:, 1])
    assert {k: summary[k] for k in ("object_displacement", "object_velocity")} == motion_summary(obs.body.q, obs.body.v)
    assert summary["law"] == "reactive" and summary["law_phase"] == law.phase == "hold"  # (the controller's status)

    rec = open_recording(tmp_path / "bag")
    couples = {int(m.step): (len(m.kappa_ref) > 0, bool(m.transition), float(m.hold_gain))
               for _, m in iter_decoded(rec, [topics.resolve(topics.COUPLE)])}
    assert [couples[k][:2] for k in range(obs.k)] == logged.log
    held = [k for k in range(obs.k) if couples[k][0]]
    assert held and held == list(range(held[0], obs.k)) and {couples[k][2] for k in held} == {3000.0}
    complete = next(k for k in range(obs.k) if not couples[k][1])
    assert held[0] < complete < PUSH_START / 0.002  # (the hold is complete before the push)
    run = load_run(tmp_path / "bag")
    assert run.rod.object is not None
    # the recorded holds, each applied at the recorded state it answers, made the effort the simulator reported
    from contgrasp_ros.recordings.recompute import peak_couple_recomputed

    assert peak_couple_recomputed(run) == pytest.approx(summary["peak_couple"], rel=1e-9)
    contact = {int(m.step): m for _, m in iter_decoded(rec, [topics.resolve(topics.CONTACT)])}
    rods = {int(m.step): m for _, m in iter_decoded(rec, [topics.resolve(topics.ROD_STATE)])}
    for i in (0, complete, obs.k - 1):
        np.testing.assert_array_equal(contact[i].theta, rods[i].theta)
        np.testing.assert_array_equal(contact[i].kappa, rods[i].kappa)
    assert scenario.disturbance is not None
    np.testing.assert_array_equal(run.rod.object.wrench, [scenario.disturbance.wrench_at(t) for t in run.rod.t])
    pushed = run.rod.object.wrench[:, 0] != 0.0
    assert np.all(run.rod.object.wrench[pushed] == PUSH) and abs(run.rod.t[np.argmax(pushed)] - PUSH_START) < 0.003
    at_push = run.rod.object.q[np.argmax(pushed)]
    moved = np.hypot(*(obs.body.q[:2] - at_push[:2]))
    assert 0.0 < moved < 1e-3, moved


def _wrapped_contact(model: Any, step: int, with_shape: bool = True) -> ContactState:
    """A contact state the holding law reads as an arm wrapped 4 rad around the object at its
    cage gap (rho = r + 5 mm, alpha = pi/2; not a sensed one: the controller does not check that)."""
    s = model.s_nodes
    n = len(s)
    theta = np.linspace(0.0, 4.0, n)
    kappa = np.append(np.diff(theta) / np.diff(s), 0.0)
    msg = ContactState(step=step, s=s.tolist(), rho=(model.radius(s) + 0.005).tolist(), alpha=[np.pi / 2] * n,
                       delta=[-0.005] * n, s_o=s.tolist(), shadow_x=[0.0] * n, shadow_y=[0.0] * n,
                       in_contact=[False] * n, contact_tolerance=0.0005,
                       theta=theta.tolist() if with_shape else [], kappa=kappa.tolist() if with_shape else [])
    msg.header.stamp.sec = 1 + step
    return msg


def test_the_controller_steps_the_holding_law_once_per_state_and_afresh_for_a_new_run(make) -> None:  # type: ignore[no-untyped-def]
    """law: reactive, a close so fast that the hold begins at the first state: the squeeze's
    progress grows by one control period per state (steps 0, 1 answer different rest curvatures,
    both in transition), the same state again is answered again without stepping the law, and
    step 0 again (the simulator's reset) starts a fresh law (the first answer again). A contact
    state without the arm's shape is dropped and counted."""
    from contgrasp_ros.nodes.grasp_controller import GraspController

    node = make(GraspController, law="reactive", hold_close_rate=10.0)
    node.pub = Sink(CoupleControl)
    first = _wrapped_contact(node.model, 0)
    for msg in (first, _wrapped_contact(node.model, 1), _wrapped_contact(node.model, 1), first):
        node.on_contact(msg)
    answers = node.pub.msgs
    assert [int(m.step) for m in answers] == [0, 1, 1, 0] and all(m.transition for m in answers)
    assert all(len(m.kappa_ref) == node.model.n_elements and m.hold_gain == 3000.0 and len(m.rho_ref) == 0 for m in answers)
    assert list(answers[0].kappa_ref) != list(answers[1].kappa_ref)
    assert list(answers[2].kappa_ref) == list(answers[1].kappa_ref)  # (the same state: the same answer)
    assert list(answers[3].kappa_ref) == list(answers[0].kappa_ref)  # (a new run: a fresh law)
    np.testing.assert_allclose(answers[0].u, -node.model.joint_ei * np.asarray(answers[0].kappa_ref), rtol=0, atol=0)
    node.on_contact(_wrapped_contact(node.model, 2, with_shape=False))
    assert node.drops.counts == {"/contgrasp/contact: no arm shape": 1} and len(node.pub.msgs) == 4


@pytest.mark.parametrize(("parameter", "message"), [
    ("law:=grip", "law: must be one of 'paper', 'hold', 'reactive', got 'grip'"),
    ("hold_plan_gain:=-1.0", "hold law plan_gain must be >= 0, got -1.0"),
    ("hold_plan_damping_time:=0.0", "hold law plan_damping_time must be > 0, got 0.0"),
    ("hold_close_gap:=0.01", "hold law close_gap must be in (0, clearance = 0.006) m, got 0.01"),
    ("hold_stiffness_gain:=-1.0", "hold law stiffness_gain must be >= 0, got -1.0"),
    ("hold_depth_gain:=-3.0", "hold law depth_gain must be >= 0, got -3.0"),
    ("hold_dwell:=-1.0", "hold law dwell must be >= 0, got -1.0"),
])
def test_bad_law_parameters_stop_the_controller_with_one_line(parameter: str, message: str) -> None:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(fresh_domain_id()))
    proc = subprocess.run([str(LIB / "grasp_controller"), "--ros-args", "-p", parameter], capture_output=True, text=True,
                          env=env, timeout=60)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and message in lines[0], proc.stderr


def test_the_launcher_refuses_an_unknown_law_in_one_line() -> None:
    proc = subprocess.run([str(BIN / "contgrasp-launch"), "--law", "grip"], capture_output=True, text=True, timeout=60)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and "--law: invalid choice: 'grip'" in lines[-1], proc.stderr


@pytest.mark.heavy
def test_bounded_muscles_through_the_graph_equal_the_core_loop_bit_for_bit() -> None:
    """``contgrasp-launch --law reactive --object-mode free --max-muscle-stress 20000``: the simulator
    saturates the couple as the core loop does (the same arm, object and effort to the bit); the
    couple never exceeds the muscles' bound; the summary reports the effort and the validity."""
    summary = launch_json("--law", "reactive", "--object-mode", "free", "--max-muscle-stress", "20000", "--duration", "0.8",
                          "--no-record")
    p = load_params(default_params_file())
    p["grasp_controller"]["law"], p["rod_simulator"]["object_mode"] = "reactive", "free"
    p["rod_simulator"].update(max_muscle_stress=20000.0, duration=0.8)
    p["grasp_controller"]["max_muscle_stress"] = 20000.0
    scenario = Scenario.from_ros_parameters(p)
    session = run_sampled(scenario)
    obs = session.observe()
    assert obs.body is not None and summary["steps"] == obs.k
    np.testing.assert_array_equal(summary["final"]["x"], obs.x[:, 0])
    np.testing.assert_array_equal(summary["final"]["y"], obs.x[:, 1])
    assert summary["object_displacement"] == motion_summary(obs.body.q, obs.body.v)["object_displacement"]
    effort = session.health.effort()
    assert summary["peak_couple"] == effort["peak_couple"] and summary["peak_couple_arclength"] == effort["peak_couple_arclength"]
    assert summary["peak_couple_ratio"] == effort["peak_couple_ratio"] and 0.99 < effort["peak_couple_ratio"] <= 1.0
    assert summary["validity"] == json.loads(json.dumps(session.health.validity()))
    bound = scenario.rod.muscle_bound
    assert bound is not None and effort["peak_couple"] <= bound[0]


SHARED_FACTS = ("object", "law", "law_phase", "object_displacement", "object_velocity", "settled", "settle_time_s", "sim_time_s",
                "steps", "validity", "peak_couple", "peak_couple_arclength", "peak_couple_sim_time_s", "peak_couple_ratio",
                "mean_abs_rho_ratio_minus_1_contact", "max_abs_rho_ratio_minus_1_contact",
                "mean_abs_alpha_minus_half_pi_contact", "max_abs_alpha_minus_half_pi_contact", "contact_nodes",
                "contact_length")
"""The facts ``contgrasp simulate --json`` and the launcher's summary (and ``analyze``) both report."""


@pytest.mark.heavy
def test_simulate_and_the_launcher_give_the_same_facts_the_same_keys() -> None:
    """``contgrasp simulate`` and ``contgrasp-launch`` on 0.4 s of the holding law with a free
    object, simulate stepping the sampled loop as the graph does (first-order hold at 2 ms):
    every fact both report is under the same key, with the same law, phase, steps and settling;
    the object's motion (``{x, y, angle}``) agrees to rounding (the two sense the object in
    different frames), and nothing else names it."""
    sim = json.loads(subprocess.run([str(BIN / "contgrasp"), "simulate", "--object-mode", "free", "--law", "reactive",
                                     "--duration", "0.4", "--control-period", "0.002", "--hold", "first-order", "--json"],
                                    capture_output=True, text=True, check=True, timeout=600).stdout)
    graph = launch_json("--law", "reactive", "--object-mode", "free", "--duration", "0.4", "--no-record")
    assert set(SHARED_FACTS) <= set(sim) & set(graph)
    assert sim["law"] == graph["law"] == "reactive" and sim["law_phase"] == graph["law_phase"] in ("cage", "close", "hold")
    assert sim["object"] == graph["object"] == "circle:0.025"
    for key in ("steps", "settled", "settle_time_s"):
        assert sim[key] == graph[key], key
    for key in ("object_displacement", "object_velocity"):
        assert sim[key].keys() == graph[key].keys() == {"x", "y", "angle"}
        np.testing.assert_allclose(list(graph[key].values()), list(sim[key].values()), rtol=1e-6, atol=1e-12)
    assert not {"object_q", "object_v"} & (set(graph) | set(graph["final"]) | set(sim) | set(sim["final"]))


@pytest.mark.heavy
@pytest.mark.parametrize(("friction", "duration", "phase"), [(None, 1.0, "plan"), (0.5, 3.2, "hold")])
def test_the_planned_hold_through_the_graph_equals_the_core_loop_bit_for_bit(friction: float | None, duration: float,
                                                                             phase: str) -> None:
    """``contgrasp-launch --law hold --object-mode free``: the controller plans on its copy of the
    simulator's object at start and plays the plan back; separate node processes in lock-step
    equal run_sampled of the same scenario bit for bit (arm, object); the controller reports the
    playback's phase. With ``--friction 0.5`` the controller plans with it and squeezes after the
    plan (P2): 3.2 s runs into the squeeze's ramp (the plan ends at 2.84 s)."""
    extra = () if friction is None else ("--friction", str(friction))
    summary = launch_json("--law", "hold", "--object-mode", "free", "--duration", str(duration), "--no-record", *extra)
    p = load_params(default_params_file())
    p["grasp_controller"]["law"], p["rod_simulator"]["object_mode"] = "hold", "free"
    p["rod_simulator"]["duration"] = duration
    if friction is not None:
        for node in ("rod_simulator", "grasp_controller"):
            p[node]["friction"], p[node]["friction_model"] = friction, "stick"
    scenario = Scenario.from_ros_parameters(p)
    law = scenario.controller()
    assert isinstance(law, PlannedHold) and (law.plan.squeeze is None) == (friction is None)
    session = run_sampled(scenario, law=law)
    obs = session.observe()
    assert obs.body is not None and summary["steps"] == obs.k == round(duration / 0.002)
    np.testing.assert_array_equal(summary["final"]["x"], obs.x[:, 0])
    np.testing.assert_array_equal(summary["final"]["y"], obs.x[:, 1])
    assert {k: summary[k] for k in ("object_displacement", "object_velocity")} == motion_summary(obs.body.q, obs.body.v)
    assert summary["law"] == "hold" and summary["law_phase"] == law.phase == phase  # (1 s: the plan still plays)
    assert summary["missed_deadlines"] == 0


@pytest.mark.heavy
def test_the_analysis_replays_the_settle_rule_of_a_law_in_transition(tmp_path: Path) -> None:
    """``contgrasp-launch --law hold --object-mode free`` recorded, then analysed: the settle rule
    replayed on the recorded states gives the simulator's settle time, to 1 ns, because the
    states after a couple of the law in transition (its plan still playing) do not count as
    quiet. Without the couples' ``transition`` the replay called the run settled 0.5 s early (the
    arm is quiet while the plan holds it, before the law is ready). Truth: the simulator's verdict."""
    from contgrasp_ros.recordings.recompute import settle_recomputed

    summary = launch_json("--law", "hold", "--object-mode", "free", "--bag", str(tmp_path / "bag"))
    assert summary["settled"] and summary["validity"]["valid"]
    run = load_run(tmp_path / "bag")
    assert run.transitions is not None and any(run.transitions.values())
    settled, settle_time = settle_recomputed(run)
    assert settled and settle_time == pytest.approx(summary["settle_time_s"], rel=0, abs=1e-9)
    run.transitions = {k: False for k in run.transitions}  # (the replay without the law's phases)
    assert settle_recomputed(run)[1] < summary["settle_time_s"] - 0.1
