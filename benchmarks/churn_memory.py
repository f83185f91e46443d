"""Benchmark: memory of a long-lived node while its peers keep dying and coming back.

In the soak (docs/RELIABILITY.md) long-lived nodes' RSS rose in small steps after peers were
killed and restarted. Here one ``boundary_sensor`` runs while a peer that publishes rod states
and subscribes to contacts is started, matched and SIGKILLed ``--cycles`` times; the sensor's RSS
after each cycle (and in quiet phases before and after) gives the slope per cycle and per hour at
one restart every ``--per`` seconds.

Usage (from the repository root):
    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST ROS_LOG_DIR=/tmp/rl_bench AMENT_PREFIX_PATH=.venv \
        .venv/bin/python benchmarks/churn_memory.py [--cycles 150] [--write-results]
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from recorder import RESULTS, update_results_section  # noqa: E402

SECTION = "churn_memory"

PEER = """
import sys, rclpy
from contgrasp_msgs.msg import ContactState, RodState
from contgrasp_ros.plumbing import qos, topics
rclpy.init()
node = rclpy.create_node("churn_peer")
pub = node.create_publisher(RodState, topics.ROD_STATE, qos.STREAM)
node.create_subscription(ContactState, topics.CONTACT, lambda m: None, qos.STREAM)
while pub.get_subscription_count() < 1:
    rclpy.spin_once(node, timeout_sec=0.05)
print("matched", flush=True)
while True:
    rclpy.spin_once(node, timeout_sec=0.5)
"""


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError(f"no VmRSS for pid {pid}")


def slope(xs: list[float], ys: list[float]) -> float:
    return float(np.polyfit(np.asarray(xs, float), np.asarray(ys, float), 1)[0])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=150, help="peer start/kill cycles (default 150)")
    ap.add_argument("--quiet", type=float, default=60.0, help="seconds without churn before and after (default 60)")
    ap.add_argument("--per", type=float, default=45.0, help="restart period for the per-hour figure [s] (default 45)")
    ap.add_argument("--domain-id", type=int, default=210, help="ROS_DOMAIN_ID (default 210)")
    ap.add_argument("--write-results", action="store_true", help=f"write/replace the '## {SECTION}' section of {RESULTS.name}")
    args = ap.parse_args(argv)
    if args.cycles < 10 or args.quiet < 0 or args.per <= 0:
        ap.error("need --cycles >= 10, --quiet >= 0, --per > 0")
    env = dict(os.environ, ROS_DOMAIN_ID=str(args.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.setdefault("ROS_LOG_DIR", "/tmp/rl_bench")
    out: list[str] = []

    def say(line: str = "") -> None:
        print(line, flush=True)
        out.append(line)

    say(f"python {platform.python_version()}, cores {os.cpu_count()}, load average at start {os.getloadavg()[0]:.2f}; "
        f"{args.cycles} peer cycles, quiet phases {args.quiet:g} s")
    sensor = subprocess.Popen([sys.executable, "-m", "contgrasp_ros.nodes.boundary_sensor"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.monotonic()
    try:
        time.sleep(5.0)  # imports and start-up
        quiet_before = [(time.monotonic() - t0, rss_mb(sensor.pid))]
        while time.monotonic() - t0 < 5.0 + args.quiet:
            time.sleep(2.0)
            quiet_before.append((time.monotonic() - t0, rss_mb(sensor.pid)))
        cycles: list[float] = []
        for c in range(args.cycles):
            peer = subprocess.Popen([sys.executable, "-c", PEER], env=env, stdout=subprocess.PIPE, text=True)
            assert peer.stdout is not None
            line = peer.stdout.readline()
            if line.strip() != "matched":
                raise RuntimeError(f"cycle {c}: the peer did not match the sensor (got {line!r})")
            time.sleep(0.3)
            peer.send_signal(signal.SIGKILL)
            peer.wait(timeout=30)
            time.sleep(0.5)
            cycles.append(rss_mb(sensor.pid))
            if sensor.poll() is not None:
                raise RuntimeError(f"the sensor died with code {sensor.returncode}")
        churn_end = time.monotonic() - t0
        quiet_after = [(churn_end, rss_mb(sensor.pid))]
        while time.monotonic() - t0 < churn_end + args.quiet:
            time.sleep(2.0)
            quiet_after.append((time.monotonic() - t0, rss_mb(sensor.pid)))
    finally:
        sensor.send_signal(signal.SIGINT)
        try:
            sensor.wait(timeout=30)
        except subprocess.TimeoutExpired:
            sensor.kill()
            sensor.wait(timeout=30)
    n = len(cycles)
    half = n // 2
    idx = list(range(1, n + 1))
    first, second = slope(idx[:half], cycles[:half]), slope(idx[half:], cycles[half:])
    qb = [m for _, m in quiet_before]
    qa = [m for _, m in quiet_after]
    say(f"sensor RSS quiet before churn: {qb[0]:.2f} -> {qb[-1]:.2f} MB over {quiet_before[-1][0] - quiet_before[0][0]:.0f} s")
    say("| after cycle | RSS [MB] |")
    say("|---|---|")
    for c in sorted({1, *range(max(1, n // 10), n + 1, max(1, n // 10)), n}):
        say(f"| {c} | {cycles[c - 1]:.2f} |")
    say(f"sensor RSS quiet after churn: {qa[0]:.2f} -> {qa[-1]:.2f} MB over {quiet_after[-1][0] - quiet_after[0][0]:.0f} s")
    per_h = 3600.0 / args.per
    say(f"slope per peer cycle: first half {first * 1e3:.1f} kB, second half {second * 1e3:.1f} kB "
        f"(= {second * per_h:.2f} MB/h at one restart every {args.per:g} s); total rise over the churn "
        f"{cycles[-1] - qb[-1]:.2f} MB in {n} cycles; sensor exit code {sensor.returncode}")
    if args.write_results:
        cmd = " ".join(["python", "benchmarks/churn_memory.py", *(sys.argv[1:] if argv is None else argv)])
        body = (f"Command (from the repository root):\n\n    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/{cmd}\n\n"
                "RSS of one long-lived `boundary_sensor` while a peer node (publishing rod states, subscribing contact) "
                "is started, matched and killed with SIGKILL over and over (docs/RELIABILITY.md, soak memory).\n\n```\n"
                + "\n".join(out) + "\n```\n")
        update_results_section(RESULTS, SECTION, body)
        print(f"wrote section '## {SECTION}' of {RESULTS}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
