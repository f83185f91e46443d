"""Benchmark: the floor of the lock-step loop through rclpy - the paper run with nodes that do
nothing but the loop's own work.

Three bare rclpy nodes (lean executor, serialized messages) advance the rod, sense it and answer
with the law, without validation, diagnostics or observers' streams, grouped into one, two or
three processes; each must end in the core loop's final state bit for bit. It tells how fast the
real graph could become by trimming its nodes' Python alone (the real graph: ros_loop.py;
results: benchmarks/RESULTS.md).

Usage: AMENT_PREFIX_PATH=.venv .venv/bin/python benchmarks/ros_floor.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

import numpy as np

ROLES = ("sim", "sensor", "controller")
GROUPINGS = {"one process": ("sim,sensor,controller",), "two processes": ("sensor,controller", "sim"),
             "three processes": ("sensor", "controller", "sim")}
STOP = 2**63  # (the step of the message that ends the helper processes)


def node_main(roles: list[str]) -> None:
    """Run the named bare nodes in this process; with the simulator, print 'WALL STEPS X...'."""
    import rclpy
    from builtin_interfaces.msg import Time
    from rclpy.node import Node
    from std_msgs.msg import Header

    from contgrasp_core.arm import ArmShape
    from contgrasp_core.contact import load_sensing, sense
    from contgrasp_core.control import FeedbackExpansion, feedback_at_joints
    from contgrasp_core.rod.session import LoopSession, preload
    from contgrasp_core.scenario import PAPER
    from contgrasp_msgs.msg import ContactState, CoupleControl, RodState
    from contgrasp_ros.plumbing import qos
    from contgrasp_ros.plumbing.cdr import Codec
    from contgrasp_ros.plumbing.executor import LeanExecutor

    rclpy.init()
    ex = LeanExecutor()
    state_codec, contact_codec, couple_codec = Codec(RodState), Codec(ContactState), Codec(CoupleControl)
    stopped = [False]

    def node(name: str) -> Node:
        n = Node(f"floor_{name}")
        ex.add_node(n)
        return n

    if "sensor" in roles:
        sensor = node("sensor")
        boundary = PAPER.object.boundary()
        load_sensing()  # (as the boundary sensor node: not at the run's first state)
        contact_pub = sensor.create_publisher(ContactState, "floor/contact", qos.STREAM)

        def on_state(data: bytes) -> None:
            m = state_codec.decode(data)
            if m.step == STOP:
                stopped[0] = True
                contact_pub.publish(contact_codec.encode({"step": STOP}))
                return
            c = sense(ArmShape(s=m.s, r=np.stack([m.x, m.y], -1), theta=m.theta), boundary, m.radius,
                      tol=PAPER.sensing.contact_tolerance)
            contact_pub.publish(contact_codec.encode({"header": m.header, "step": m.step, "s": c.s, "rho": c.rho,
                                                      "alpha": c.alpha, "delta": c.delta, "s_o": c.s_o,
                                                      "shadow_x": c.foot[:, 0], "shadow_y": c.foot[:, 1],
                                                      "in_contact": c.in_contact}))

        sensor.create_subscription(RodState, "floor/state", on_state, qos.STREAM, raw=True)
    if "controller" in roles:
        controller = node("controller")
        couple_pub = controller.create_publisher(CoupleControl, "floor/couple", qos.STREAM)

        def on_contact(data: bytes) -> None:
            m = contact_codec.decode(data)
            if m.step == STOP:
                stopped[0] = True
                return
            u = feedback_at_joints(PAPER.rod, PAPER.feedback_gains, m.rho, m.alpha)
            couple_pub.publish(couple_codec.encode({"header": m.header, "step": m.step, "s": PAPER.rod.joint_s, "u": u.u,
                                                    "rho_ref": u.rho_ref, "alpha_ref": u.alpha_ref, "du_drho": u.g_rho,
                                                    "du_dalpha": u.g_alpha}))

        controller.create_subscription(ContactState, "floor/contact", on_contact, qos.STREAM, raw=True)
    if "sim" not in roles:
        while not stopped[0]:
            ex.spin_once(1.0)
        return
    sim = node("sim")
    system = PAPER.system()
    session = LoopSession(system, PAPER.loop)
    preload(system, PAPER.loop)
    state_pub = sim.create_publisher(RodState, "floor/state", qos.STREAM)

    def publish() -> None:
        o = session.observe()
        sec = int(o.t)
        header = Header(stamp=Time(sec=sec, nanosec=int((o.t - sec) * 1e9)), frame_id="world")
        state_pub.publish(state_codec.encode({"header": header, "step": o.k, "s": o.s, "x": o.x[:, 0], "y": o.x[:, 1],
                                              "theta": o.theta, "kappa": o.kappa, "radius": o.radius, "vx": o.v[:, 0],
                                              "vy": o.v[:, 1], "kinetic_energy": o.kinetic_energy,
                                              "max_penetration": o.penetration}))

    def on_couple(data: bytes) -> None:
        m = couple_codec.decode(data)
        if not session.finished:
            session.advance(FeedbackExpansion(u=m.u, rho_ref=m.rho_ref, alpha_ref=m.alpha_ref, g_rho=m.du_drho,
                                              g_alpha=m.du_dalpha))
            publish()

    sim.create_subscription(CoupleControl, "floor/couple", on_couple, qos.STREAM, raw=True)
    while state_pub.get_subscription_count() < 1 or sim.count_publishers("floor/couple") < 1:
        ex.spin_once(0.01)
    time.sleep(0.5)  # (the rest of discovery settles)
    t0 = time.perf_counter()
    publish()
    while not session.finished:
        ex.spin_once(1.0)
    wall = time.perf_counter() - t0
    state_pub.publish(state_codec.encode({"step": STOP}))
    time.sleep(0.3)
    x = session.observe().x
    print("RESULT", wall, session.k, " ".join(repr(float(v)) for v in x.ravel()), flush=True)


def run(groups: tuple[str, ...], env: dict[str, str]) -> tuple[float, int, np.ndarray]:
    helpers = [subprocess.Popen([sys.executable, __file__, "--node", g], env=env) for g in groups[:-1]]
    try:
        out = subprocess.run([sys.executable, __file__, "--node", groups[-1]], env=env, capture_output=True, text=True,
                             timeout=600, check=True).stdout
    finally:
        for p in helpers:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
    _, wall, steps, *xs = next(line for line in out.splitlines() if line.startswith("RESULT")).split()
    return float(wall), int(steps), np.array([float(v) for v in xs]).reshape(-1, 2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="runs of each grouping (medians reported)")
    ap.add_argument("--node", help=argparse.SUPPRESS)  # (a helper process: the roles it runs)
    args = ap.parse_args()
    if args.repeat < 1:
        ap.error(f"--repeat must be at least 1, got {args.repeat}")
    if args.node:
        node_main(args.node.split(","))
        return
    from contgrasp_core.rod.session import run_sampled
    from contgrasp_core.scenario import PAPER

    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(150 + os.getpid() % 80))
    print(f"python {sys.version.split()[0]}, cores {os.cpu_count()}, load average at start {os.getloadavg()[0]:.2f}, "
          f"{args.repeat} run(s) each, ROS_DOMAIN_ID {env['ROS_DOMAIN_ID']}")
    run_sampled(PAPER)  # (compiled kernels loaded)
    core = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        session = run_sampled(PAPER)
        core.append((time.perf_counter() - t0) / session.k)
    x_core = session.observe().x
    core_ms = 1e3 * statistics.median(core)
    period = PAPER.loop.control_period
    print(f"{'core loop':18s} {core_ms:6.3f} ms/step  RTF {period / (core_ms / 1e3):5.2f}")
    for name, groups in GROUPINGS.items():
        per_step = []
        for _ in range(args.repeat):
            wall, steps, x = run(groups, env)
            if not np.array_equal(x, x_core):
                raise SystemExit(f"{name}: the final state differs from the core loop's")
            per_step.append(wall / steps)
        ms = 1e3 * statistics.median(per_step)
        print(f"{name:18s} {ms:6.3f} ms/step  RTF {period / (ms / 1e3):5.2f}  {ms / core_ms:4.2f}x core  "
              f"(runs: {', '.join(f'{1e3 * v:.3f}' for v in per_step)}; bitwise equal to the core loop)")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
