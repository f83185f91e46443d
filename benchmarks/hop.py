"""The cost of one hop between two node processes, by executor (the graph's floor).

A pinger publishes a RodState of the paper's size (N = 100 elements) on ``/hop/ping``; an echo
process (this script with ``--echo``) republishes every message it takes on ``/hop/pong``; the
pinger waits for each echo before sending the next, as the lock-step loop does. For each
variant - rclpy's SingleThreadedExecutor, contgrasp's LeanExecutor (both ends alike), and the
LeanExecutor with serialized messages (``raw=True`` subscriptions and ``publish`` of the bytes,
as the loop's nodes do: contgrasp_ros.plumbing.cdr) - the round trip's median and the CPU time per
message of each end are reported, and the ratios in the same run. Everything stays on loopback with its own ROS_DOMAIN_ID.

    AMENT_PREFIX_PATH=.venv .venv/bin/python benchmarks/hop.py [--messages 3000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

EXECUTORS = ("rclpy", "lean", "lean-raw")
N_NODES = 101


def _executor(kind: str):  # type: ignore[no-untyped-def]
    from rclpy.executors import SingleThreadedExecutor

    from contgrasp_ros.plumbing.executor import LeanExecutor

    return SingleThreadedExecutor() if kind == "rclpy" else LeanExecutor()


def _message():  # type: ignore[no-untyped-def]
    from contgrasp_msgs.msg import RodState

    msg = RodState()
    for name in ("s", "x", "y", "theta", "radius", "vx", "vy"):
        setattr(msg, name, np.linspace(0.0, 1.0, N_NODES))
    return msg


def echo(kind: str) -> None:
    """Republish every ping as a pong until SIGINT/SIGTERM; print this process's CPU seconds
    and message count as JSON on the way out."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node

    from contgrasp_msgs.msg import RodState
    from contgrasp_ros.plumbing import qos

    rclpy.init()
    node = Node("hop_echo")
    pub = node.create_publisher(RodState, "/hop/pong", qos.STREAM)
    count = 0
    cpu0 = time.process_time()

    def on_ping(msg: RodState | bytes) -> None:
        nonlocal count, cpu0
        if count == 0:
            cpu0 = time.process_time()  # (from the first message: start-up is not a hop's cost)
        count += 1
        pub.publish(msg)

    node.create_subscription(RodState, "/hop/ping", on_ping, qos.STREAM, raw=kind.endswith("raw"))
    ex = _executor(kind)
    ex.add_node(node)
    try:
        while rclpy.ok():
            ex.spin_once(timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    print(json.dumps({"cpu_s": time.process_time() - cpu0, "messages": count}), flush=True)


def ping(kind: str, messages: int, domain: int) -> dict[str, float]:
    """Start an echo process, exchange ``messages`` ping-pongs, return the medians and CPU."""
    import rclpy
    from rclpy.node import Node
    from rclpy.serialization import serialize_message

    from contgrasp_msgs.msg import RodState
    from contgrasp_ros.plumbing import qos

    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    proc = subprocess.Popen([sys.executable, __file__, "--echo", kind], env=env, stdout=subprocess.PIPE, text=True)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    rclpy.init()
    try:
        node = Node("hop_ping")
        pub = node.create_publisher(RodState, "/hop/ping", qos.STREAM)
        got = [0]
        raw = kind.endswith("raw")
        node.create_subscription(RodState, "/hop/pong", lambda m: got.__setitem__(0, got[0] + 1), qos.STREAM, raw=raw)
        ex = _executor(kind)
        ex.add_node(node)
        deadline = time.monotonic() + 30.0
        while pub.get_subscription_count() < 1 or node.count_publishers("/hop/pong") < 1:
            ex.spin_once(timeout_sec=0.05)
            if time.monotonic() > deadline:
                raise RuntimeError("the echo process did not connect within 30 s")
        msg = serialize_message(_message()) if raw else _message()
        warm = 200
        trips = []
        cpu0 = 0.0
        for i in range(warm + messages):
            if i == warm:
                cpu0 = time.process_time()
            t0 = time.perf_counter()
            want = got[0] + 1
            pub.publish(msg)
            while got[0] < want:
                ex.spin_once(timeout_sec=1.0)
            if i >= warm:
                trips.append(time.perf_counter() - t0)
        cpu = time.process_time() - cpu0
        ex.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown()
        proc.terminate()
    out, _ = proc.communicate(timeout=30)
    echo_stats = json.loads(out.strip().splitlines()[-1])
    return {
        "round_trip_ms": 1e3 * statistics.median(trips),
        "ping_cpu_ms_per_message": 1e3 * cpu / messages,
        "echo_cpu_ms_per_message": 1e3 * echo_stats["cpu_s"] / max(echo_stats["messages"], 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--messages", type=int, default=3000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--echo", choices=EXECUTORS, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.echo:
        echo(args.echo)
        return
    print(f"load average at start: {os.getloadavg()}")
    base = 150 + os.getpid() % 50
    runs: dict[str, list[dict[str, float]]] = {k: [] for k in EXECUTORS}
    for r in range(args.repeat):
        for j, kind in enumerate(EXECUTORS):
            # (each measurement in its own process: one rclpy init per process)
            code = f"import json, sys; sys.path.insert(0, {os.path.dirname(__file__)!r}); import hop; " \
                   f"print(json.dumps(hop.ping({kind!r}, {args.messages}, {base + len(EXECUTORS) * r + j})))"
            res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
            if res.returncode != 0:
                raise SystemExit(res.stderr[-2000:])
            runs[kind].append(json.loads(res.stdout.strip().splitlines()[-1]))
    med = {k: {m: statistics.median(r[m] for r in v) for m in v[0]} for k, v in runs.items()}
    print(f"{'executor':<8} {'round trip ms':>14} {'ping CPU ms/msg':>16} {'echo CPU ms/msg':>16}   (medians of {args.repeat}, "
          f"{args.messages} messages each)")
    for k, m in med.items():
        print(f"{k:<8} {m['round_trip_ms']:>14.3f} {m['ping_cpu_ms_per_message']:>16.3f} {m['echo_cpu_ms_per_message']:>16.3f}")
    for m in ("round_trip_ms", "ping_cpu_ms_per_message", "echo_cpu_ms_per_message"):
        print(f"rclpy / lean {m}: {med['rclpy'][m] / med['lean'][m]:.2f}x; "
              f"lean / lean-raw: {med['lean'][m] / med['lean-raw'][m]:.2f}x")
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
